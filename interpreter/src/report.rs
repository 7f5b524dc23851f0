//! `report.json`: one file per run that other tools and tests read, folded together from
//! what each process wrote (`interpreter.json`, `interpolator.json`, `servo.json`).

use interpolator::summary::Summary as InterpSummary;
use interpolator::timing::Percentiles;
use serde::{Deserialize, Serialize};
use servo_sim::run::Summary as ServoSummary;
use shared::clock::ClockMode;
use std::path::Path;

/// What the interpreter process reports.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct InterpreterSummary {
    pub outcome: String,
    pub fault: Option<String>,
    pub pid: u32,
    pub program: String,
    pub blocks: usize,
    pub messages: Vec<(u32, String)>,
    /// Set when a damaged command log was salvaged: what was wrong, what ran.
    #[serde(default)]
    pub salvaged: Option<String>,
}

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct Process {
    pub role: String,
    pub pid: u32,
    /// Exit code, or the signal that ended it, in words.
    pub exit: String,
}

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct Report {
    pub outcome: String,
    pub fault: Option<String>,
    pub program: String,
    /// "real" or "sim". Under "sim" the timing figures below are null: not measured.
    pub clock: String,
    pub period_ns: u64,
    pub cycles: u64,
    pub misses: Option<u64>,
    pub wake_late_ns: Option<Percentiles>,
    pub compute_ns: Option<Percentiles>,
    pub publish_ns: Option<Percentiles>,
    pub path_length_mm: f64,
    pub time_s: f64,
    pub avg_feed_mm_per_min: f64,
    pub peak_feed_mm_per_min: f64,
    pub max_following_error_um: f64,
    pub max_following_error_axis_um: [f64; 3],
    pub lost_setpoints: u64,
    pub blocks: usize,
    /// Replays of a damaged log (`--salvage`): what was wrong and what ran.
    pub salvaged: Option<String>,
    pub sched: Option<interpolator::rt::sched::SchedReport>,
    pub miss_list: Vec<interpolator::summary::MissEntry>,
    pub processes: Vec<Process>,
}

fn read<T: for<'de> Deserialize<'de>>(path: &Path) -> Option<T> {
    serde_json::from_str(&std::fs::read_to_string(path).ok()?).ok()
}

/// Folds the per-process summaries of `dir` into a report. Missing parts (a process that
/// died before writing its summary) leave their figures at zero and are named in `fault`.
pub fn assemble(
    dir: &Path,
    program: &str,
    clock: ClockMode,
    period_ns: u64,
    processes: Vec<Process>,
    launcher_fault: Option<String>,
) -> Report {
    let interp: Option<InterpreterSummary> = read(&dir.join("interpreter.json"));
    let ipol: Option<InterpSummary> = read(&dir.join("interpolator.json"));
    let servo: Option<ServoSummary> = read(&dir.join("servo.json"));
    let mut faults: Vec<String> = Vec::new();
    if let Some(f) = launcher_fault {
        faults.push(f);
    }
    for (role, outcome) in [
        ("interpreter", interp.as_ref().map(|s| s.fault.clone())),
        ("interpolator", ipol.as_ref().map(|s| s.fault.clone())),
        ("servo-sim", servo.as_ref().map(|s| s.fault.clone())),
    ] {
        match outcome {
            None => faults.push(format!("{role} wrote no summary")),
            Some(Some(f)) => faults.push(format!("{role}: {f}")),
            Some(None) => {}
        }
    }
    faults.dedup();
    let fault = (!faults.is_empty()).then(|| faults.join("; "));
    let i = ipol.as_ref();
    Report {
        outcome: if fault.is_some() { "fault" } else { "done" }.into(),
        fault,
        program: program.to_string(),
        clock: clock.name().into(),
        period_ns,
        cycles: i.map_or(0, |s| s.cycles),
        misses: i.and_then(|s| s.misses),
        wake_late_ns: i.and_then(|s| s.wake_late_ns),
        compute_ns: i.and_then(|s| s.compute_ns),
        publish_ns: i.and_then(|s| s.publish_ns),
        path_length_mm: i.map_or(0.0, |s| s.path_length_mm),
        time_s: i.map_or(0.0, |s| s.time_s),
        avg_feed_mm_per_min: i.map_or(0.0, |s| s.avg_feed_mm_per_min),
        peak_feed_mm_per_min: i.map_or(0.0, |s| s.peak_feed_mm_per_min),
        max_following_error_um: servo.as_ref().map_or(0.0, |s| s.max_following_error_um),
        max_following_error_axis_um: servo
            .as_ref()
            .map_or([0.0; 3], |s| s.max_following_error_axis_um),
        lost_setpoints: servo.as_ref().map_or(0, |s| s.lost_setpoints),
        blocks: interp.as_ref().map_or(0, |s| s.blocks),
        salvaged: interp.as_ref().and_then(|s| s.salvaged.clone()),
        sched: i.map(|s| s.sched.clone()),
        miss_list: i.map(|s| s.miss_list.clone()).unwrap_or_default(),
        processes,
    }
}

impl Report {
    pub fn write(&self, path: &Path) -> std::io::Result<()> {
        std::fs::write(
            path,
            serde_json::to_string_pretty(self).map_err(std::io::Error::other)?,
        )
    }

    /// The short summary `cnc run` prints.
    pub fn summary_text(&self, dir: &Path) -> String {
        let timing = match (self.misses, self.wake_late_ns, self.compute_ns) {
            (Some(m), Some(w), Some(c)) => format!(
                "{m} misses, wake-up late p50 {} µs p99 {} µs max {} µs, compute p99 {} µs",
                w.p50 / 1000,
                w.p99 / 1000,
                w.max / 1000,
                c.p99 / 1000
            ),
            _ => format!("not measured ({} clock)", self.clock),
        };
        let mut s = format!(
            "{}: {}\n  program      {}\n  period       {} µs, {} cycles, {:.3} s machining ({} clock)\n  path         {:.3} mm, average feed {:.1} mm/min, peak {:.1} mm/min\n  servo        max following error {:.2} µm\n  timing       {timing}\n  run dir      {}\n",
            self.outcome,
            self.fault.as_deref().unwrap_or("program completed"),
            self.program,
            self.period_ns / 1000,
            self.cycles,
            self.time_s,
            self.clock,
            self.path_length_mm,
            self.avg_feed_mm_per_min,
            self.peak_feed_mm_per_min,
            self.max_following_error_um,
            dir.display()
        );
        if let Some(note) = &self.salvaged {
            s.push_str(&format!("  warning      {note}\n"));
        }
        if let Some(sched) = &self.sched {
            for w in &sched.warnings {
                s.push_str(&format!("  warning      {w}\n"));
            }
        }
        s
    }
}
