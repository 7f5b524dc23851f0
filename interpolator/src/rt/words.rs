//! The interpolator's fault as its summary says it, after the run (never in the cycle):
//! in words a machinist reads, with what the controlled stop did. A stop request says who
//! asked ([`shared::stop::Request`]); silence of a live servo-sim says that the machine
//! was too loaded and what to try.

use crate::engine::Fault;
use crate::summary::FaultInfo;
use shared::stop::Request;

/// What the controlled stop did, from the fault's figures.
fn braked(info: Option<&FaultInfo>) -> String {
    match info {
        Some(i) => format!(
            "the interpolator braked on the path from {:.1} mm/min and was at rest in cycle {}",
            i.speed_at_fault_mm_per_min, i.stopped_cycle
        ),
        None => "the interpolator braked on the path to rest".into(),
    }
}

/// The `kind` a fault is reported under: a stop because the launcher died is
/// `launcher_gone`, told apart from an operator's (`stop_requested`).
pub fn kind(f: &Fault, request: Option<Request>) -> &'static str {
    match (f, request) {
        (Fault::StopRequested, Some(Request::LauncherGone)) => "launcher_gone",
        _ => f.kind(),
    }
}

/// The fault in words. `request` is the stop request received (if any), `servo_dead`
/// whether the servo-sim's process was found gone, `silence_ms` how long the servo-sim
/// may be silent before it is a fault.
pub fn fault_text(
    f: &Fault,
    info: Option<&FaultInfo>,
    request: Option<Request>,
    servo_dead: bool,
    silence_ms: u64,
    period_ns: u64,
) -> String {
    let (cycle, line) = info.map_or((0, 0), |i| (i.cycle, i.line));
    match f {
        Fault::StopRequested => match request {
            Some(Request::LauncherGone) => format!(
                "stopped: the launcher (cnc run) died at cycle {cycle} (line {line}); {}",
                braked(info)
            ),
            Some(Request::Interrupt) => format!(
                "stopped by the operator (SIGINT) at line {line}, cycle {cycle}: {}",
                braked(info)
            ),
            _ => format!(
                "stopped on request (SIGTERM) at line {line}, cycle {cycle}: {}",
                braked(info)
            ),
        },
        Fault::PeerSilent { cycle } if !servo_dead => format!(
            "cycle {cycle}: the servo-sim did not answer the set-point within {silence_ms} ms although its process is alive: it was starved of CPU time (this machine is too loaded for a {} µs period) or suspended; {}. Check the machine with `cnc latency-test`, or run with `--clock sim`",
            period_ns / 1000,
            braked(info)
        ),
        Fault::PeerSilent { cycle } => format!(
            "cycle {cycle}: the servo-sim did not answer the set-point (its process is gone); {}",
            braked(info)
        ),
        other => other.to_string(),
    }
}

/// How a run ended, for [`log_end`].
pub struct End<'a> {
    pub fault: Option<&'a Fault>,
    /// The fault's kind as reported ([`kind`]).
    pub kind: Option<&'a str>,
    /// The fault in words ([`fault_text`]).
    pub text: Option<&'a str>,
    pub cycles: u64,
    pub period_ns: u64,
    pub blocks: u64,
    /// Deadline misses; `None` under the simulated clock, which measures none.
    pub misses: Option<u64>,
    pub starvations: u64,
}

/// The end of the run in the log, after the loop: the program end and a stop someone
/// asked for (operator, launcher) at `info`, any other fault at `error`, each naming its
/// cause; running out of blocks on the way at `warn`.
pub fn log_end(e: &End) {
    let machining_s = (e.cycles * e.period_ns) as f64 * 1e-9;
    let text = e.text.unwrap_or("");
    match e.fault {
        None => tracing::info!(
            cycles = e.cycles,
            machining_time_s = %format_args!("{machining_s:.3}"),
            blocks = e.blocks,
            misses = e.misses,
            "interpolator stopped: program end reached"
        ),
        Some(Fault::StopRequested) => tracing::info!(
            kind = e.kind.map(tracing::field::display),
            cycles = e.cycles,
            blocks = e.blocks,
            "interpolator stopped: {text}"
        ),
        Some(_) => tracing::error!(
            kind = e.kind.map(tracing::field::display),
            cycles = e.cycles,
            blocks = e.blocks,
            "interpolator fault: {text}"
        ),
    }
    if e.starvations > 0 {
        tracing::warn!(
            starvations = e.starvations,
            "the interpolator ran out of blocks: it stopped on the path and waited for the interpreter"
        );
    }
}
