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
    /// `real` (wall time) or `sim` (as fast as the drives answer, same set-points).
    #[arg(long, default_value_t = ClockMode::Real)]
    pub clock: ClockMode,
}

/// Runs the interpolator process; the error names what went wrong.
pub fn run(args: &Args) -> anyhow::Result<()> {
    shared::stop::install_handler();
    let cfg = Config {
        prefix: args.prefix.clone(),
        out_dir: args.out.clone(),
        period_ns: args.period_us * 1000,
        machine: shared::machine::load(args.machine.as_deref()).map_err(anyhow::Error::msg)?,
        sched: args.sched,
        clock: args.clock,
        start_timeout: Duration::from_secs(20),
    };
    let summary = cycle::run::<iceoryx2::prelude::ipc::Service>(&cfg)?;
    match summary.fault {
        Some(f) => anyhow::bail!("fault: {f}"),
        None => Ok(()),
    }
}
