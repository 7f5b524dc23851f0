//! What the interpolator reports at the end of a run (`interpolator.json`), which the
//! launcher folds into the run's `report.json`.

use crate::engine::{axis_name, Engine, Fault, Tick};
use crate::rt::cycle::Config;
use crate::rt::sched::SchedReport;
use crate::timing::{Miss, MissCause, Percentiles, Timing};
use serde::{Deserialize, Serialize};

/// Path figures accumulated from the set-points, cycle by cycle.
#[derive(Debug, Clone, Copy, Default)]
pub struct FeedStats {
    last: Option<[f64; 3]>,
    pub path_length_mm: f64,
    pub feed_length_mm: f64,
    pub feed_moving_ns: u64,
    pub peak_speed_mm_per_s: f64,
}

impl FeedStats {
    /// Figures of a path that starts at `start_mm`.
    pub fn starting_at(start_mm: [f64; 3]) -> Self {
        FeedStats {
            last: Some(start_mm),
            ..FeedStats::default()
        }
    }

    #[inline]
    pub fn add(&mut self, t: &Tick, period_ns: u64) {
        if let Some(p) = self.last {
            let d =
                shared::path::norm([t.pos_mm[0] - p[0], t.pos_mm[1] - p[1], t.pos_mm[2] - p[2]]);
            self.path_length_mm += d;
            if d > 0.0 && !t.rapid {
                self.feed_length_mm += d;
                self.feed_moving_ns += period_ns;
                self.peak_speed_mm_per_s =
                    self.peak_speed_mm_per_s.max(d / (period_ns as f64 * 1e-9));
            }
        }
        self.last = Some(t.pos_mm);
    }
}

/// One deadline miss as the JSON files list it (`deadline-misses.json`, and the first
/// [`REPORT_MISSES`] of them in `report.json`'s `miss_list`).
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct MissEntry {
    pub cycle: u64,
    /// The cycle's release time since the first cycle's, in ns (`cycle × period`).
    #[serde(default)]
    pub t_ns: u64,
    pub line: u32,
    /// Sequence number of the block being run.
    #[serde(default)]
    pub block_seq: u64,
    /// `late_wake`, `long_compute`, `preempted`, `publish_stall` or `downstream_lag` (the
    /// rule: [`crate::timing::MissCause`]).
    pub cause: String,
    pub wake_late_ns: u64,
    pub compute_ns: u64,
    pub publish_ns: u64,
    /// How late: the set-point's finish minus its deadline (downstream: how long the
    /// drives' answer is overdue, at least).
    pub overrun_ns: u64,
    /// Set-points sent and not yet answered by the drives when the cycle woke.
    #[serde(default)]
    pub unanswered: u64,
    /// The interpolator thread's own CPU time from the end of the previous cycle's compute
    /// to the end of this one's (it sleeps in between); null when it could not be read,
    /// and in files older than it.
    #[serde(default)]
    pub cpu_ns: Option<u64>,
    /// How long the compute phase was off the CPU, at least: `compute_ns − cpu_ns` when
    /// positive, else 0. The cause is `preempted` when this is the largest part of the
    /// cycle.
    #[serde(default)]
    pub preempted_ns: u64,
}

/// How many misses `report.json` lists in full; `deadline-misses.json` has them all.
pub const REPORT_MISSES: usize = 4096;

impl MissEntry {
    pub fn new(m: &Miss, period_ns: u64) -> Self {
        MissEntry {
            cycle: m.cycle,
            t_ns: m.cycle * period_ns,
            line: m.source_line,
            block_seq: m.block_seq,
            cause: m.cause.id().into(),
            wake_late_ns: m.wake_late_ns,
            compute_ns: m.compute_ns,
            publish_ns: m.publish_ns,
            overrun_ns: m.late_ns,
            unanswered: m.unanswered,
            cpu_ns: m.cpu_ns,
            preempted_ns: m.preempted_ns(),
        }
    }
}

/// A fault in figures: what it was, when it was noticed, and the controlled stop after it.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct FaultInfo {
    /// `following_error`, `peer_gone`, `peer_silent`, `bad_block`, `bad_feedback`,
    /// `stop_requested` (the operator: Ctrl-C or SIGTERM), `launcher_gone` (`cnc run`
    /// died), `stalled`, `step_too_large` or `out_of_travel`.
    pub kind: String,
    /// The cycle the fault is about: for a following error the cycle whose set-point the
    /// drives answered with it, otherwise the cycle in which the interpolator noticed.
    pub cycle: u64,
    /// The source line that cycle ran.
    pub line: u32,
    /// Following error, a step too large or out of travel: the axis (`X`, `Y`, `Z`).
    pub axis: Option<String>,
    /// Dead or silent peer: `interpreter` or `servo-sim`.
    pub peer: Option<String>,
    /// The last cycle the drives had answered when the fault was noticed.
    pub last_feedback_cycle: Option<u64>,
    /// The cycle in which the controlled stop began (the fault was acted on).
    pub stop_from_cycle: u64,
    /// Path speed when the stop began.
    pub speed_at_fault_mm_per_min: f64,
    /// The cycle of the last set-point: the machine at rest on the path.
    pub stopped_cycle: u64,
}

/// A fault as the cycle notes it: plain data, no allocation (the text comes later).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FaultRecord {
    pub fault: Fault,
    /// The cycle in which the stop began.
    pub now: u64,
    /// The source line being run then.
    pub line: u32,
    pub speed_mm_per_s: f64,
    pub last_feedback_cycle: Option<u64>,
}

impl FaultRecord {
    /// The fault `f`, acted on in cycle `now` with the engine as it is.
    #[inline]
    pub fn at(f: Fault, now: u64, engine: &Engine, last_feedback_cycle: Option<u64>) -> Self {
        FaultRecord {
            fault: f,
            now,
            line: engine.source_line(),
            speed_mm_per_s: engine.speed_mm_per_s(),
            last_feedback_cycle,
        }
    }
}

impl FaultInfo {
    /// The report form of a fault record; `stopped_cycle` is the run's last cycle.
    pub fn new(r: &FaultRecord, stopped_cycle: u64) -> Self {
        let (cycle, line, axis, peer) = match r.fault {
            Fault::FollowingError {
                cycle, axis, line, ..
            } => (cycle, line, Some(axis_name(axis).to_string()), None),
            Fault::PeerGone { peer, cycle } => (cycle, r.line, None, Some(peer.name().into())),
            Fault::PeerSilent { cycle } => (cycle, r.line, None, Some("servo-sim".into())),
            Fault::StepTooLarge { line, axis, .. } => {
                (r.now, line, Some(axis_name(axis).to_string()), None)
            }
            Fault::OutOfTravel { line, err, .. } => {
                (r.now, line, Some(axis_name(err.axis).to_string()), None)
            }
            _ => (r.now, r.line, None, None),
        };
        FaultInfo {
            kind: r.fault.kind().into(),
            cycle,
            line,
            axis,
            peer,
            last_feedback_cycle: r.last_feedback_cycle,
            stop_from_cycle: r.now,
            speed_at_fault_mm_per_min: r.speed_mm_per_s * 60.0,
            stopped_cycle,
        }
    }
}

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct Summary {
    pub outcome: String,
    pub fault: Option<String>,
    pub pid: u32,
    pub period_ns: u64,
    /// "real" or "sim".
    pub clock: String,
    pub cycles: u64,
    /// Timing figures are `None` (null) under the simulated clock: not measured.
    pub misses: Option<u64>,
    pub wake_late_ns: Option<Percentiles>,
    pub compute_ns: Option<Percentiles>,
    pub publish_ns: Option<Percentiles>,
    /// Every miss up to the first [`REPORT_MISSES`], in cycle order (all of them are in
    /// `deadline-misses.json`).
    pub miss_list: Vec<MissEntry>,
    /// Misses per cause id, every miss counted (as `deadline-misses.json`'s, in the order
    /// of [`crate::timing::MissCause::ALL`]); empty under the simulated clock.
    #[serde(default)]
    pub misses_by_cause: Vec<(String, u64)>,
    pub path_length_mm: f64,
    pub time_s: f64,
    /// Feed moves only: cutting length over the time spent moving at feed.
    pub avg_feed_mm_per_min: f64,
    pub peak_feed_mm_per_min: f64,
    /// The largest following error the interpolator saw in feedback.
    pub max_following_error_um: f64,
    pub sched: SchedReport,
    /// Set-point trace records lost because the writer fell a whole ring behind.
    pub trace_dropped: u64,
    /// Times the interpolator ran out of blocks mid-program, decelerated and waited at a
    /// stop on the path for the interpreter (real clock only: the simulated clock waits
    /// for late blocks without moving time on).
    #[serde(default)]
    pub starvations: u64,
    /// The fault in figures, when there was one.
    #[serde(default)]
    pub fault_info: Option<FaultInfo>,
    /// Feed fluctuation (seed 001): the chord each set-point step actually covered against
    /// the step the speed profile planned, `|chord / planned - 1|`, largest and RMS over
    /// the moving cycles that stay inside one block.
    #[serde(default)]
    pub feed_fluctuation_max: f64,
    #[serde(default)]
    pub feed_fluctuation_rms: f64,
}

impl Summary {
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        cfg: &Config,
        cycles: u64,
        timing: Option<(&Timing, &[Miss])>,
        feed: &FeedStats,
        fault: Option<String>,
        sched: SchedReport,
        trace_dropped: u64,
        max_ferr_mm: f64,
    ) -> Self {
        let avg = if feed.feed_moving_ns > 0 {
            feed.feed_length_mm / (feed.feed_moving_ns as f64 * 1e-9) * 60.0
        } else {
            0.0
        };
        Summary {
            outcome: if fault.is_some() { "fault" } else { "done" }.into(),
            fault,
            pid: std::process::id(),
            period_ns: cfg.period_ns,
            clock: cfg.clock.name().into(),
            cycles,
            misses: timing.map(|(t, _)| t.misses),
            wake_late_ns: timing.map(|(t, _)| t.wake_late.percentiles()),
            compute_ns: timing.map(|(t, _)| t.compute.percentiles()),
            publish_ns: timing.map(|(t, _)| t.publish.percentiles()),
            miss_list: timing
                .map(|(_, list)| {
                    list.iter()
                        .take(REPORT_MISSES)
                        .map(|m| MissEntry::new(m, cfg.period_ns))
                        .collect()
                })
                .unwrap_or_default(),
            misses_by_cause: timing
                .map(|(t, _)| {
                    MissCause::ALL
                        .iter()
                        .zip(t.by_cause)
                        .map(|(c, n)| (c.id().to_string(), n))
                        .collect()
                })
                .unwrap_or_default(),
            path_length_mm: feed.path_length_mm,
            time_s: (cycles * cfg.period_ns) as f64 * 1e-9,
            avg_feed_mm_per_min: avg,
            peak_feed_mm_per_min: feed.peak_speed_mm_per_s * 60.0,
            max_following_error_um: max_ferr_mm * 1000.0,
            sched,
            trace_dropped,
            starvations: 0,
            fault_info: None,
            feed_fluctuation_max: 0.0,
            feed_fluctuation_rms: 0.0,
        }
    }

    /// Adds the engine's feed fluctuation figures.
    pub fn with_fluctuation(mut self, f: crate::engine::Fluctuation) -> Self {
        self.feed_fluctuation_max = f.max;
        self.feed_fluctuation_rms = f.rms;
        self
    }

    /// Adds the fault figures and the starvation count.
    pub fn with_faults(mut self, fault_info: Option<FaultInfo>, starvations: u64) -> Self {
        self.fault_info = fault_info;
        self.starvations = starvations;
        self
    }

    pub fn write(&self, path: &std::path::Path) -> std::io::Result<()> {
        let text = serde_json::to_string_pretty(self).map_err(std::io::Error::other)?;
        std::fs::write(path, text)
    }
}
