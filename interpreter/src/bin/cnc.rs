//! `cnc`: run, check and inspect NC programs on the three-process stack. See `cnc --help`.
fn main() -> std::process::ExitCode {
    interpreter::cli::main()
}
