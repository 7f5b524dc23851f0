//! Real-time set-up of the cycle thread: SCHED_FIFO, locked memory, tight timer slack.
//! Each step is tried; what the system refuses is reported, never fatal (without root,
//! SCHED_FIFO is refused with EPERM on most desktops and CI machines).

use serde::Serialize;

/// What the process actually got.
#[derive(Debug, Clone, Serialize, serde::Deserialize, PartialEq)]
pub struct SchedReport {
    /// "fifo" or "other".
    pub policy: String,
    pub priority: i32,
    pub memory_locked: bool,
    /// The CPU the cycle thread is pinned to, if pinning was possible.
    #[serde(default)]
    pub cpu: Option<usize>,
    pub warnings: Vec<String>,
}

/// The scheduling in force, in words.
pub fn words(s: &SchedReport) -> String {
    let mut t = match s.policy.as_str() {
        "fifo" => format!("SCHED_FIFO priority {}", s.priority),
        "other" => "SCHED_OTHER (not real-time)".to_string(),
        p => p.to_string(),
    };
    t.push_str(if s.memory_locked {
        ", memory locked"
    } else {
        ", memory not locked"
    });
    if let Some(cpu) = s.cpu {
        t.push_str(&format!(", pinned to CPU {cpu}"));
    }
    t
}

/// Which scheduling to ask for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum, Default)]
pub enum SchedMode {
    /// SCHED_FIFO if allowed, else SCHED_OTHER with a warning.
    #[default]
    Auto,
    /// Plain SCHED_OTHER (timer slack still tightened).
    Other,
}

fn errno_text() -> String {
    std::io::Error::last_os_error().to_string()
}

/// SCHED_FIFO priority of the cycle thread unless configured (`--rt-priority`): above
/// the threaded IRQ handlers (50) and most kernel threads, below the watchdogs (99).
pub const DEFAULT_PRIORITY: i32 = 80;

/// SCHED_FIFO priority of the servo-sim's drive loop for an interpolator at `priority`:
/// ten below it (70 by default). The interpolator owns the clock: a drive step must never
/// delay the set-point being computed, and the servo-sim has the rest of the period to
/// answer. Still above the threaded IRQ handlers (50), so that a loaded desktop cannot
/// starve the drives (a 416 s job was once aborted at 229 s because the servo-sim ran
/// SCHED_OTHER). Never below 1.
pub fn servo_priority(priority: i32) -> i32 {
    (priority - 10).max(1)
}

/// The real-time set-up of the interpolator's cycle thread (pinned to the last CPU).
pub fn setup(mode: SchedMode, priority: i32) -> SchedReport {
    setup_with(mode, priority, true)
}

/// The real-time set-up of the calling thread: locked memory, 1 ns timer slack, and in
/// `Auto` mode SCHED_FIFO at `priority`, pinned to the last allowed CPU when `pin`. The
/// servo-sim takes it unpinned: it may run on any CPU the interpolator leaves free.
pub fn setup_with(mode: SchedMode, priority: i32, pin: bool) -> SchedReport {
    let mut rep = SchedReport {
        policy: "other".into(),
        priority: 0,
        memory_locked: false,
        cpu: None,
        warnings: vec![],
    };
    // SAFETY: plain syscalls with valid arguments.
    unsafe {
        // MCL_CURRENT only: everything the cycle touches is allocated before the loop.
        // MCL_FUTURE would make any later allocation fail outright once a non-root
        // RLIMIT_MEMLOCK (often 8 MiB) is used up.
        if mode == SchedMode::Other {
            // Plain mode takes nothing from the system beyond the timer slack.
        } else if libc::mlockall(libc::MCL_CURRENT) == 0 {
            rep.memory_locked = true;
        } else {
            rep.warnings.push(format!(
                "mlockall refused ({}); page faults may delay cycles",
                errno_text()
            ));
        }
        // 1 ns slack: without it SCHED_OTHER sleeps overshoot by ~50 µs.
        libc::prctl(libc::PR_SET_TIMERSLACK, 1 as libc::c_ulong, 0, 0, 0);
        if mode == SchedMode::Auto {
            let param = libc::sched_param {
                sched_priority: priority,
            };
            if libc::sched_setscheduler(0, libc::SCHED_FIFO, &param) == 0 {
                rep.policy = "fifo".into();
                rep.priority = priority;
                // Pin the cycle to the last CPU: no migrations, warm caches. The other
                // processes stay free to use every CPU.
                let size = core::mem::size_of::<libc::cpu_set_t>();
                let mut allowed: libc::cpu_set_t = core::mem::zeroed();
                if pin
                    && libc::sched_getaffinity(0, size, &mut allowed) == 0
                    && libc::CPU_COUNT(&allowed) > 1
                {
                    // The highest CPU this process may use (containers restrict the set).
                    let max = 8 * size;
                    if let Some(cpu) = (0..max).rev().find(|&c| libc::CPU_ISSET(c, &allowed)) {
                        let mut one: libc::cpu_set_t = core::mem::zeroed();
                        libc::CPU_SET(cpu, &mut one);
                        if libc::sched_setaffinity(0, size, &one) == 0 {
                            rep.cpu = Some(cpu);
                        } else {
                            rep.warnings
                                .push(format!("pinning to CPU {cpu} refused ({})", errno_text()));
                        }
                    }
                }
            } else {
                rep.warnings.push(format!(
                    "SCHED_FIFO refused ({}); running SCHED_OTHER, expect more deadline misses",
                    errno_text()
                ));
            }
        }
    }
    rep
}
