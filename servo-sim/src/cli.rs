//! Command-line arguments of the servo-sim process (also a role of `cnc`).

use crate::run::{self, Config, ServoClock};
use interpolator::rt::sched::{servo_priority, SchedMode, DEFAULT_PRIORITY};
use shared::clock::ClockMode;
use std::path::PathBuf;
use std::time::Duration;

#[derive(Debug, Clone, clap::Args)]
pub struct Args {
    /// Service-name prefix of the stack to join.
    #[arg(long)]
    pub prefix: String,
    /// Run directory to write feedback.csv and servo.json into.
    #[arg(long)]
    pub out: PathBuf,
    /// Interpolation period in µs (the time one set-point stands for).
    #[arg(long, default_value_t = 1000, value_parser = clap::value_parser!(u64).range(100..=10_000))]
    pub period_us: u64,
    /// Machine file (TOML); the built-in default machine when absent.
    #[arg(long)]
    pub machine: Option<PathBuf>,
    /// `real` or `sim`: under the simulated clock the drives answer as fast as they can.
    #[arg(long, default_value_t = ClockMode::Real)]
    pub clock: ClockMode,
    /// Who paces the drives: `lockstep` (one step per set-point, deterministic) or `own`
    /// (the drives' own period; a late set-point is held, as real drives do).
    #[arg(long, value_enum, default_value_t = ServoClock::Lockstep)]
    pub servo_clock: ServoClock,
    /// Scheduling of the drive loop (real clock): `auto` tries SCHED_FIFO and locked
    /// memory as the interpolator does, and falls back with a warning.
    #[arg(long, value_enum, default_value_t = SchedMode::Auto)]
    pub sched: SchedMode,
    /// SCHED_FIFO priority (1..=99) of the drive loop; `cnc run` gives it ten below the
    /// interpolator's (see `interpolator::rt::sched::servo_priority`).
    #[arg(long, default_value_t = servo_priority(DEFAULT_PRIORITY), value_parser = clap::value_parser!(i32).range(1..=99))]
    pub rt_priority: i32,
}

pub fn run(args: &Args, machine: shared::Machine) -> anyhow::Result<()> {
    shared::stop::install_handler();
    shared::machine::log_in_force("servo-sim", args.machine.as_deref(), &machine);
    let cfg = Config {
        prefix: args.prefix.clone(),
        out_dir: args.out.clone(),
        period_ns: args.period_us * 1000,
        machine,
        clock: args.clock,
        servo_clock: args.servo_clock,
        sched: args.sched,
        rt_priority: args.rt_priority,
        start_timeout: Duration::from_secs(30),
        // Set-points come every period under the real clock: 100 ms of silence means the
        // interpolator is gone. The simulated clock may pause while blocks are late.
        idle_timeout: match args.clock {
            ClockMode::Real => Duration::from_millis(100),
            ClockMode::Sim => Duration::from_secs(5),
        },
    };
    let summary = run::run::<iceoryx2::prelude::ipc::Service>(&cfg)?;
    match summary.fault {
        Some(f) => anyhow::bail!("fault: {f}"),
        None => Ok(()),
    }
}
