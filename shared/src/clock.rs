//! Monotonic time as integer nanoseconds, and absolute sleeps on it.

/// Now on CLOCK_MONOTONIC, in ns.
#[inline]
pub fn now_ns() -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid, writable timespec; CLOCK_MONOTONIC always exists on Linux.
    unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
}

/// The calling thread's own CPU time (user and system) on CLOCK_THREAD_CPUTIME_ID, in ns;
/// `None` if the kernel refuses the clock (then nothing can be said about preemption).
///
/// Unlike CLOCK_MONOTONIC this clock has no vDSO fast path: every read is a system call.
/// Measured on the 2-vCPU VM (`cargo bench -p interpolator --bench cycle -- clock/`):
/// 0.53 µs a read, against 0.024 µs for [`now_ns`]; so the cycle reads it once.
#[inline]
pub fn thread_cpu_ns() -> Option<u64> {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid, writable timespec.
    let r = unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) };
    (r == 0).then(|| ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64)
}

/// Sleeps until the absolute CLOCK_MONOTONIC time `t_ns` (returns at once if it is past).
#[inline]
pub fn sleep_until_ns(t_ns: u64) {
    let ts = libc::timespec {
        tv_sec: (t_ns / 1_000_000_000) as libc::time_t,
        tv_nsec: (t_ns % 1_000_000_000) as libc::c_long,
    };
    loop {
        // SAFETY: valid timespec, null remainder is allowed with TIMER_ABSTIME.
        let r = unsafe {
            libc::clock_nanosleep(
                libc::CLOCK_MONOTONIC,
                libc::TIMER_ABSTIME,
                &ts,
                core::ptr::null_mut(),
            )
        };
        if r != libc::EINTR {
            break;
        }
    }
}

/// Which clock drives the interpolator.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ClockMode {
    /// Wall time: cycle k starts at `t0 + k·period` (absolute sleeps); timing is measured.
    #[default]
    Real,
    /// Simulated time: cycle k is still stamped `k·period`, but the next cycle starts as
    /// soon as the drives have answered the cycle a few before it (the interpolator runs
    /// a bounded few cycles ahead of them). Same set-points, faster than real time;
    /// timing is not measured (it would mean nothing).
    Sim,
}

impl ClockMode {
    pub fn name(self) -> &'static str {
        match self {
            ClockMode::Real => "real",
            ClockMode::Sim => "sim",
        }
    }
}

impl core::str::FromStr for ClockMode {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "real" => Ok(ClockMode::Real),
            "sim" => Ok(ClockMode::Sim),
            other => Err(format!("unknown clock `{other}`: use `real` or `sim`")),
        }
    }
}

impl core::fmt::Display for ClockMode {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(self.name())
    }
}

/// Waits for `ready()` by polling (yielding the core in between) for up to `spin_ns` (a peer on the other core answers
/// within microseconds), then by calling `block(remaining)` until `timeout_ns` has passed.
/// Returns whether `ready()` became true.
pub fn spin_then_block(
    spin_ns: u64,
    timeout_ns: u64,
    mut ready: impl FnMut() -> bool,
    mut block: impl FnMut(core::time::Duration),
) -> bool {
    let start = now_ns();
    loop {
        if ready() {
            return true;
        }
        let waited = now_ns() - start;
        if waited >= timeout_ns {
            return false;
        }
        if waited < spin_ns {
            // Yield rather than burn: on a busy machine the peer may need this very core.
            std::thread::yield_now();
        } else {
            block(core::time::Duration::from_nanos(
                (timeout_ns - waited).min(1_000_000),
            ));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn thread_cpu_time_counts_running_not_sleeping() {
        let start = thread_cpu_ns().unwrap();
        std::thread::sleep(core::time::Duration::from_millis(50));
        let slept = thread_cpu_ns().unwrap() - start;
        // A sleep costs microseconds of CPU, whatever else the machine does.
        assert!(slept < 10_000_000, "{slept} ns of CPU in a 50 ms sleep");
        // Spinning does count (bounded by wall time, in case the clock stands still).
        // The wall interval is read around the CPU one, so it holds it.
        let (wall0, cpu0) = (now_ns(), thread_cpu_ns().unwrap());
        while thread_cpu_ns().unwrap() < cpu0 + 5_000_000 && now_ns() < wall0 + 10_000_000_000 {
            core::hint::spin_loop();
        }
        let (cpu, wall) = (thread_cpu_ns().unwrap() - cpu0, now_ns() - wall0);
        assert!(
            cpu >= 5_000_000,
            "{cpu} ns of CPU after {wall} ns of spinning"
        );
        assert!(
            wall >= cpu,
            "the thread cannot run longer than the wall clock"
        );
    }
}
