//! The log every process of the stack writes: `tracing` to stderr, `warn` and worse
//! unless `RUST_LOG` says otherwise (`RUST_LOG=info`, `debug`, or per module), and
//! colour only where stderr is a terminal, so that a file or a pipe gets plain text.

use std::io::IsTerminal;

/// Sets up the process's log; call once, first thing in `main`.
pub fn init() {
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| "warn".into()),
        )
        .with_ansi(std::io::stderr().is_terminal())
        .with_writer(std::io::stderr)
        .init();
}
