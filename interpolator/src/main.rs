//! The interpolator process. Usually started by `cnc run`; see `interpolator --help`.
use clap::Parser;

#[derive(Parser)]
#[command(
    about = "CNC interpolator: owns the period, steps along the command blocks, publishes set-points"
)]
struct Cli {
    #[command(flatten)]
    args: interpolator::cli::Args,
}

fn main() -> anyhow::Result<()> {
    shared::logging::init();
    interpolator::cli::run(&Cli::parse().args)
}
