//! Command-line arguments of the interpolator process (also used by `cnc`, which starts
//! this process as a role of itself).

use crate::rt::cycle::{self, Config};
use crate::rt::sched::SchedMode;
use shared::clock::ClockMode;
use std::path::PathBuf;
use std::time::Duration;

#[derive(Debug, Clone, clap::Args)]
pub struct Args {
    /// Service-name prefix of the stack to join.
    #[arg(long)]
    pub prefix: String,
    /// Run directory to write setpoints.csv and interpolator.json into.
    #[arg(long)]
    pub out: PathBuf,
    /// Interpolation period in µs (100..=10000).
    #[arg(long, default_value_t = 1000, value_parser = clap::value_parser!(u64).range(100..=10_000))]
    pub period_us: u64,
    /// Machine file (TOML); the built-in default machine when absent.
    #[arg(long)]
    pub machine: Option<PathBuf>,
    /// Scheduling: `auto` tries SCHED_FIFO and falls back with a warning.
    #[arg(long, value_enum, default_value_t = SchedMode::Auto)]
    pub sched: SchedMode,
    /// SCHED_FIFO priority (1..=99) when real-time scheduling is granted.
    #[arg(long, default_value_t = crate::rt::sched::DEFAULT_PRIORITY, value_parser = clap::value_parser!(i32).range(1..=99))]
    pub rt_priority: i32,
    /// `real` (wall time) or `sim` (as fast as the drives answer, same set-points).
    #[arg(long, default_value_t = ClockMode::Real)]
    pub clock: ClockMode,
    /// Test aid: every Nth cycle computes for 1.5 periods of its own CPU time (a long
    /// compute, reported as a miss of cause `long_compute`). Also taken from
    /// `CNC_INJECT_LONG_COMPUTE=N`, which `cnc run` passes on to this process.
    #[arg(long, hide = true)]
    pub inject_long_compute: Option<u64>,
    /// Test aid: every Nth cycle is preempted in its compute phase for 1.5 periods by a
    /// thread at a higher SCHED_FIFO priority on its CPU (reported as a miss of cause
    /// `preempted`); needs SCHED_FIFO. Also taken from `CNC_INJECT_PREEMPTION=N`.
    #[arg(long, hide = true)]
    pub inject_preemption: Option<u64>,
}

/// The environment variable that injects long computes (see [`Args::inject_long_compute`]).
pub const INJECT_ENV: &str = "CNC_INJECT_LONG_COMPUTE";
/// The environment variable that injects preemptions (see [`Args::inject_preemption`]).
pub const PREEMPT_ENV: &str = "CNC_INJECT_PREEMPTION";

/// A test aid's count: the argument, else the environment variable.
fn hook_arg(arg: Option<u64>, env: &str) -> Option<u64> {
    arg.or_else(|| std::env::var(env).ok().and_then(|v| v.trim().parse().ok()))
}

/// `cnc latency-test`: this machine's wake-up jitter with the cycle's own sleep and
/// scheduling, no work.
#[derive(Debug, Clone, clap::Args)]
pub struct LatencyArgs {
    /// Period in µs (100..=10000), as `cnc run --period-us`.
    #[arg(long, default_value_t = 1000, value_parser = clap::value_parser!(u64).range(100..=10_000))]
    pub period_us: u64,
    /// How long to measure, in seconds.
    #[arg(long, default_value_t = 10.0)]
    pub seconds: f64,
    /// Scheduling, as `cnc run --sched`.
    #[arg(long, value_enum, default_value_t = SchedMode::Auto)]
    pub sched: SchedMode,
    /// SCHED_FIFO priority (1..=99), as `cnc run --rt-priority`.
    #[arg(long, default_value_t = crate::rt::sched::DEFAULT_PRIORITY, value_parser = clap::value_parser!(i32).range(1..=99))]
    pub rt_priority: i32,
    /// Where to write the result [default: $CNC_LATENCY_FILE, else runs/latency-test.json];
    /// runs look for it there and compare their wake-up lateness with it.
    #[arg(long)]
    pub out: Option<PathBuf>,
}

/// Runs the latency test, showing the running figures while it measures
/// ([`crate::latency_screen`]), prints the result and writes it where runs find it.
pub fn latency_test(args: &LatencyArgs) -> anyhow::Result<()> {
    if !(args.seconds > 0.0 && args.seconds <= 86_400.0) {
        anyhow::bail!(
            "--seconds {}: give a time between 0 and 86400",
            args.seconds
        );
    }
    println!(
        "cnc latency-test: measuring wake-up lateness for {} s at a {} µs period (no work per cycle)...",
        args.seconds, args.period_us
    );
    // The running figures while it measures: redrawn in place on a terminal, a plain
    // line a second into a pipe or a file.
    use std::io::IsTerminal;
    let stdout = std::io::stdout();
    let terminal = stdout.is_terminal();
    let mut screen = crate::latency_screen::Screen::new(
        stdout.lock(),
        terminal,
        args.period_us * 1000,
        args.seconds,
    );
    let r = crate::rt::latency::measure_live(
        args.period_us * 1000,
        args.seconds,
        args.sched,
        args.rt_priority,
        screen.every(),
        |f| screen.show(f),
    )?;
    drop(screen);
    print!("{}", r.text());
    let path = args
        .out
        .clone()
        .unwrap_or_else(crate::rt::latency::default_path);
    r.write(&path)
        .map_err(|e| anyhow::anyhow!("writing {}: {e}", path.display()))?;
    println!(
        "written to {} (runs from this directory compare their wake-up lateness with it)",
        path.display()
    );
    Ok(())
}

/// Runs the interpolator process; the error names what went wrong.
pub fn run(args: &Args) -> anyhow::Result<()> {
    shared::stop::install_handler();
    let machine = shared::machine::load(args.machine.as_deref()).map_err(anyhow::Error::msg)?;
    shared::machine::log_in_force("interpolator", args.machine.as_deref(), &machine);
    let cfg = Config {
        prefix: args.prefix.clone(),
        out_dir: args.out.clone(),
        period_ns: args.period_us * 1000,
        machine,
        sched: args.sched,
        rt_priority: args.rt_priority,
        clock: args.clock,
        start_timeout: Duration::from_secs(20),
    };
    let hooks = cycle::Hooks {
        long_compute_every: hook_arg(args.inject_long_compute, INJECT_ENV),
        preempt_every: hook_arg(args.inject_preemption, PREEMPT_ENV),
    };
    let summary = cycle::run_with::<iceoryx2::prelude::ipc::Service>(&cfg, hooks)?;
    match summary.fault {
        Some(f) => anyhow::bail!("fault: {f}"),
        None => Ok(()),
    }
}
