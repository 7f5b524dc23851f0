//! The log every process of the stack writes: `tracing` to stderr, `warn` and worse
//! unless `RUST_LOG` says otherwise (`RUST_LOG=info`, `debug`, or per module), and
//! colour only where stderr is a terminal, so that a file or a pipe gets plain text.
//!
//! What each level holds (the README's section on `RUST_LOG`): `info` each process's
//! start-up with the scheduling it got, the machine file in force
//! ([`crate::machine::log_in_force`]) and how it ended; `warn`/`error` faults, each naming
//! its cause; `debug` the services opened and every block published and received. None
//! of it from inside a real-time loop: the interpolator's received blocks reach the log
//! through a ring and a thread of their own.

use std::io::IsTerminal;

/// Sets up the process's log; call once, first thing in `main`.
pub fn init() {
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env().unwrap_or_else(|_| "warn".into()),
        )
        .with_ansi(std::io::stderr().is_terminal())
        .with_writer(std::io::stderr)
        // A log nobody reads any more (`cnc run … 2>&1 | head -1`, a closed terminal)
        // loses its lines, and the process goes on: by default tracing reports a failed
        // write on stderr itself, and that second write, failing too, panics and aborts
        // a process of the stack over its log.
        .log_internal_errors(false)
        .init();
}
