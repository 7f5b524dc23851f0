//! The servo-sim process. Usually started by `cnc run`; see `servo-sim --help`.
use clap::Parser;

#[derive(Parser)]
#[command(
    about = "CNC servo simulation: axis loops and dynamics, answers each set-point with feedback"
)]
struct Cli {
    #[command(flatten)]
    args: servo_sim::cli::Args,
}

fn main() -> anyhow::Result<()> {
    shared::logging::init();
    let cli = Cli::parse();
    let machine = shared::machine::load(cli.args.machine.as_deref()).map_err(anyhow::Error::msg)?;
    servo_sim::cli::run(&cli.args, machine)
}
