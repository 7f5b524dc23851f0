//! A stop request from outside, as flags every loop can poll: atomic loads, so they are
//! allowed in the real-time cycle.
//!
//! Three ways a stop is asked for, told apart by the signal that brought it:
//!
//! * SIGINT (Ctrl-C) and SIGTERM: the operator, through `cnc run`, which passes the
//!   signal on to the interpolator alone, or the launcher stopping what is left after a
//!   failure. The interpolator brakes on the path; the drives and the interpreter follow
//!   it to its last set-point and are not stopped by a SIGINT of their own (a terminal's
//!   Ctrl-C reaches every process of its group at once, and drives that stop following
//!   while the interpolator brakes would leave set-points unanswered).
//! * [`LAUNCHER_DEATH_SIGNAL`] (SIGUSR1): the kernel's parent-death signal, which `cnc
//!   run` asks for in each process it starts ([`die_with_parent`]): the launcher is gone
//!   (killed, crashed), so no one supervises the run any more. The interpolator brakes on
//!   the path as for an operator stop, the others follow it and write their summaries.

use std::sync::atomic::{AtomicI32, Ordering};

/// The signal the kernel sends a process `cnc run` started when `cnc run` dies.
pub const LAUNCHER_DEATH_SIGNAL: libc::c_int = libc::SIGUSR1;

/// The first stop signal received (0: none).
static SIGNAL: AtomicI32 = AtomicI32::new(0);

extern "C" fn on_signal(signal: libc::c_int) {
    // The first one is the cause; a later Ctrl-C does not rename a launcher's death.
    let _ = SIGNAL.compare_exchange(0, signal, Ordering::SeqCst, Ordering::SeqCst);
}

/// Routes SIGTERM, SIGINT and the launcher's death signal to the stop flag (call once,
/// in a process's `main`).
pub fn install_handler() {
    let handler = on_signal as extern "C" fn(libc::c_int);
    // SAFETY: the handler only does an atomic compare-exchange, which is
    // async-signal-safe.
    unsafe {
        libc::signal(libc::SIGTERM, handler as libc::sighandler_t);
        libc::signal(libc::SIGINT, handler as libc::sighandler_t);
        libc::signal(LAUNCHER_DEATH_SIGNAL, handler as libc::sighandler_t);
    }
}

/// Why a stop was asked for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Request {
    /// SIGINT: the operator (Ctrl-C), directly or passed on by `cnc run`.
    Interrupt,
    /// SIGTERM: the operator's `kill`, passed on by `cnc run`, or `cnc run` stopping the
    /// processes left after a failure.
    Terminate,
    /// The launcher (`cnc run`) died: the kernel's parent-death signal.
    LauncherGone,
}

impl Request {
    fn of(signal: libc::c_int) -> Option<Request> {
        match signal {
            0 => None,
            libc::SIGINT => Some(Request::Interrupt),
            LAUNCHER_DEATH_SIGNAL => Some(Request::LauncherGone),
            _ => Some(Request::Terminate),
        }
    }

    /// The signal's name (`SIGINT`, `SIGTERM`, `SIGUSR1`).
    pub fn signal_name(self) -> &'static str {
        match self {
            Request::Interrupt => "SIGINT",
            Request::Terminate => "SIGTERM",
            Request::LauncherGone => "SIGUSR1",
        }
    }
}

/// True once any stop was requested.
#[inline]
pub fn requested() -> bool {
    SIGNAL.load(Ordering::Relaxed) != 0
}

/// The stop requested, if any (the first signal received).
#[inline]
pub fn request() -> Option<Request> {
    Request::of(SIGNAL.load(Ordering::Relaxed))
}

/// True once SIGTERM asked this process to stop now. The drives and the interpreter act
/// on this alone: a SIGINT or the launcher's death is the interpolator's to act on, and
/// they follow it.
#[inline]
pub fn terminate_requested() -> bool {
    request() == Some(Request::Terminate)
}

/// True once the launcher that started this process has died.
#[inline]
pub fn launcher_gone() -> bool {
    request() == Some(Request::LauncherGone)
}

/// For `Command::pre_exec` in the launcher, i.e. in the child between fork and exec:
/// asks the kernel for [`LAUNCHER_DEATH_SIGNAL`] when the parent (`parent`, the
/// launcher's pid) dies, which survives the exec. If the parent died before the request
/// was made, no signal would ever come: the child has been re-parented already, so it
/// checks `getppid()` after asking and refuses to start. Only async-signal-safe calls.
pub fn die_with_parent(parent: libc::pid_t) -> std::io::Result<()> {
    // SAFETY: prctl(2) and getppid(2), both async-signal-safe, with valid arguments.
    unsafe {
        if libc::prctl(
            libc::PR_SET_PDEATHSIG,
            LAUNCHER_DEATH_SIGNAL as libc::c_ulong,
            0,
            0,
            0,
        ) != 0
        {
            return Err(std::io::Error::last_os_error());
        }
        // The launcher died before this process started. No message is built here:
        // between fork and exec an allocation may deadlock on a lock another thread of
        // the launcher held at the fork.
        if libc::getppid() != parent {
            return Err(std::io::Error::from_raw_os_error(libc::ESRCH));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn signals_name_their_request() {
        assert_eq!(Request::of(0), None);
        assert_eq!(Request::of(libc::SIGINT), Some(Request::Interrupt));
        assert_eq!(Request::of(libc::SIGTERM), Some(Request::Terminate));
        assert_eq!(Request::of(libc::SIGUSR1), Some(Request::LauncherGone));
    }
}
