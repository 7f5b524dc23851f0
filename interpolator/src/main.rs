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
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| "warn".into()),
        )
        .with_writer(std::io::stderr)
        .init();
    interpolator::cli::run(&Cli::parse().args)
}
