//! A stop request from outside (SIGTERM or SIGINT), as a flag every loop can poll: an
//! atomic load, so it is allowed in the real-time cycle. The launcher sends SIGTERM to the
//! surviving processes when one of them fails; each then stops the machine its own way
//! (the interpolator holds position, the drives hold theirs), writes its summary and
//! exits, so nothing already measured is lost.

use std::sync::atomic::{AtomicBool, Ordering};

static STOP: AtomicBool = AtomicBool::new(false);

extern "C" fn on_signal(_signal: libc::c_int) {
    STOP.store(true, Ordering::SeqCst);
}

/// Routes SIGTERM and SIGINT to the stop flag (call once, in a process's `main`).
pub fn install_handler() {
    let handler = on_signal as extern "C" fn(libc::c_int);
    // SAFETY: the handler only stores to an atomic, which is async-signal-safe.
    unsafe {
        libc::signal(libc::SIGTERM, handler as libc::sighandler_t);
        libc::signal(libc::SIGINT, handler as libc::sighandler_t);
    }
}

/// True once a stop was requested.
#[inline]
pub fn requested() -> bool {
    STOP.load(Ordering::Relaxed)
}
