//! The interpreter process on its own (normally `cnc run` starts it as a role of itself).
use clap::Parser;
use std::path::PathBuf;

#[derive(Parser)]
#[command(
    about = "CNC interpreter: reads, checks, plans and publishes an NC program's command blocks"
)]
struct Cli {
    #[command(flatten)]
    common: servo_sim::cli::Args,
    /// The NC program; the built-in demo when absent.
    #[arg(long)]
    program: Option<PathBuf>,
}

fn main() -> std::process::ExitCode {
    shared::logging::init();
    let cli = Cli::parse();
    interpreter::cli::run_interpreter(&cli.common, cli.program, None, None, false)
}
