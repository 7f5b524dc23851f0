//! The deadline-miss report: `deadline-misses.json` and `deadline-misses.txt` in the run
//! directory, written once the loop has ended (never from the cycle).
//!
//! It holds the period and the scheduling in force, log-bucketed histograms and
//! percentiles (p50/p90/p99/p99.9/max) of wake-up lateness, compute time and publish time,
//! the count of misses by cause, *every* miss (cycle, time, source line, block, lateness,
//! cause), the runs of consecutive missed cycles, and how the run's wake-up lateness
//! compares with this machine's floor as `cnc latency-test` measured it. Under the
//! simulated clock nothing was measured and both files say so.

use crate::rt::latency::{self, us, LatencyResult};
use crate::rt::sched::words as sched_words;
use crate::rt::sched::SchedReport;
use crate::summary::MissEntry;
use crate::timing::{Bucket, Histogram, Miss, MissCause, Percentiles, Timing};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Format tag of `deadline-misses.json`.
pub const FORMAT: &str = "cnc deadline-misses v1";
pub const JSON_FILE: &str = "deadline-misses.json";
pub const TEXT_FILE: &str = "deadline-misses.txt";

/// One measured quantity: percentiles, min, mean and the non-empty histogram buckets.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct Figure {
    pub percentiles: Percentiles,
    pub min_ns: u64,
    pub mean_ns: f64,
    pub histogram: Vec<Bucket>,
}

impl Figure {
    pub fn of(h: &Histogram) -> Figure {
        Figure {
            percentiles: h.percentiles(),
            min_ns: h.min_ns(),
            mean_ns: h.mean_ns(),
            histogram: h.buckets(),
        }
    }
}

/// Consecutive missed cycles.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq)]
pub struct MissRun {
    pub start_cycle: u64,
    pub length: u64,
}

/// This machine's floor as `cnc latency-test` left it.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct Floor {
    pub file: String,
    pub unix_time_s: u64,
    pub period_ns: u64,
    pub seconds: f64,
    pub policy: String,
    pub wake_late_ns: Percentiles,
    pub verdict: String,
}

/// The whole report.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct DeadlineReport {
    pub format: String,
    /// False under the simulated clock: nothing below was measured.
    pub measured: bool,
    pub clock: String,
    pub period_ns: u64,
    pub cycles: u64,
    pub sched: Option<SchedReport>,
    /// Why nothing was measured, when so.
    pub not_measured: Option<String>,
    pub wake_late_ns: Option<Figure>,
    pub compute_ns: Option<Figure>,
    pub publish_ns: Option<Figure>,
    /// Every miss counted; equal to `report.json`'s `misses`.
    pub misses: Option<u64>,
    /// Misses per cause id, in the order of [`MissCause::ALL`] (`late_wake`,
    /// `long_compute`, `publish_stall`, `downstream_lag`, `preempted`).
    pub misses_by_cause: Vec<(String, u64)>,
    /// Misses whose record was lost (the drain fell a whole ring behind); `miss_list` has
    /// `misses − lost` entries.
    pub lost: u64,
    /// Every miss recorded, in cycle order.
    pub miss_list: Vec<MissEntry>,
    /// Every run of two or more consecutive missed cycles, in cycle order.
    pub runs: Vec<MissRun>,
    /// The longest run (a single miss is a run of 1).
    pub longest_run: Option<MissRun>,
    pub floor: Option<Floor>,
    /// The run's wake-up lateness against the floor, in words (or why there is none).
    pub vs_floor: String,
    /// The line `cnc run` prints.
    pub summary: String,
}

/// Runs of consecutive cycles in `misses` (in cycle order): all, and the longest.
pub fn runs_of(misses: &[Miss]) -> (Vec<MissRun>, Option<MissRun>) {
    let mut all: Vec<MissRun> = Vec::new();
    let mut cur: Option<MissRun> = None;
    let mut longest: Option<MissRun> = None;
    for m in misses {
        cur = match cur {
            Some(r) if r.start_cycle + r.length == m.cycle => Some(MissRun {
                length: r.length + 1,
                ..r
            }),
            Some(r) if r.start_cycle + r.length > m.cycle => Some(r), // a repeat: ignore
            prev => {
                if let Some(r) = prev.filter(|r| r.length >= 2) {
                    all.push(r);
                }
                Some(MissRun {
                    start_cycle: m.cycle,
                    length: 1,
                })
            }
        };
        if let Some(r) = cur {
            if longest.is_none_or(|l| r.length > l.length) {
                longest = Some(r);
            }
        }
    }
    if let Some(r) = cur.filter(|r| r.length >= 2) {
        all.push(r);
    }
    (all, longest)
}

/// The floor at `path`, if a latency test left one there.
pub fn floor_at(path: &Path) -> Result<LatencyResult, String> {
    LatencyResult::load(path)
}

/// The run's lateness against the floor, in words.
fn compare(run: &Percentiles, period_ns: u64, policy: &str, floor: &LatencyResult) -> String {
    let f = &floor.wake_late_ns;
    let ratio = |a: u64, b: u64| {
        if b == 0 {
            String::from("—")
        } else {
            format!("{:.1}×", a as f64 / b as f64)
        }
    };
    let mut s = format!(
        "wake-up lateness p99 {} and max {} against this machine's floor of p99 {} and max {} ({} the floor's p99, {} its max; floor verdict: {})",
        us(run.p99),
        us(run.max),
        us(f.p99),
        us(f.max),
        ratio(run.p99, f.p99),
        ratio(run.max, f.max),
        floor.verdict_text
    );
    let near = run.p99 as f64 <= f.p99 as f64 * 1.5 + 5_000.0;
    s.push_str(if near {
        ": the run woke about as punctually as the machine allows"
    } else {
        ": the run woke later than the machine's floor (other load during the run, or the stack's own processes competing for the cores)"
    });
    if floor.period_ns != period_ns {
        s.push_str(&format!(
            "; note: the floor was measured at a {} µs period, the run used {} µs",
            floor.period_ns / 1000,
            period_ns / 1000
        ));
    }
    if floor.sched.policy != policy {
        s.push_str(&format!(
            "; note: the floor ran {}, the run {}",
            floor.sched.policy, policy
        ));
    }
    s
}

impl DeadlineReport {
    /// The report of a real-clock run: `misses` is everything the miss log drained, in
    /// cycle order; `floor` is where a latency test may have left its result.
    pub fn measured(
        period_ns: u64,
        cycles: u64,
        sched: &SchedReport,
        timing: &Timing,
        misses: &[Miss],
        floor_path: &Path,
    ) -> DeadlineReport {
        let (runs, longest_run) = runs_of(misses);
        let wake = timing.wake_late.percentiles();
        let (floor, vs_floor) = match floor_at(floor_path) {
            Ok(f) => (
                Some(Floor {
                    file: floor_path.display().to_string(),
                    unix_time_s: f.unix_time_s,
                    period_ns: f.period_ns,
                    seconds: f.seconds,
                    policy: f.sched.policy.clone(),
                    wake_late_ns: f.wake_late_ns,
                    verdict: f.verdict.clone(),
                }),
                compare(&wake, period_ns, &sched.policy, &f),
            ),
            Err(_) if !floor_path.exists() => (
                None,
                format!(
                    "no latency test measured on this machine (none at {}): run `cnc latency-test` to measure the floor this run's lateness can be compared with",
                    floor_path.display()
                ),
            ),
            Err(e) => (None, format!("the latency-test result is unusable: {e}")),
        };
        let misses_by_cause = MissCause::ALL
            .iter()
            .zip(timing.by_cause)
            .map(|(c, n)| (c.id().to_string(), n))
            .collect();
        let mut r = DeadlineReport {
            format: FORMAT.into(),
            measured: true,
            clock: "real".into(),
            period_ns,
            cycles,
            sched: Some(sched.clone()),
            not_measured: None,
            wake_late_ns: Some(Figure::of(&timing.wake_late)),
            compute_ns: Some(Figure::of(&timing.compute)),
            publish_ns: Some(Figure::of(&timing.publish)),
            misses: Some(timing.misses),
            misses_by_cause,
            lost: timing.lost,
            miss_list: misses
                .iter()
                .map(|m| MissEntry::new(m, period_ns))
                .collect(),
            runs,
            longest_run,
            floor,
            vs_floor,
            summary: String::new(),
        };
        r.summary = r.summary_line();
        r
    }

    /// The report of a run whose timing was not measured (the simulated clock).
    pub fn not_measured(clock: &str, period_ns: u64, cycles: u64) -> DeadlineReport {
        let why = format!(
            "timing not measured: the {clock} clock runs each cycle as soon as the drives have answered the cycles a few before it, without sleeping, so wake-up lateness, compute time and deadlines mean nothing; run with --clock real to measure them"
        );
        DeadlineReport {
            format: FORMAT.into(),
            measured: false,
            clock: clock.into(),
            period_ns,
            cycles,
            sched: None,
            not_measured: Some(why),
            wake_late_ns: None,
            compute_ns: None,
            publish_ns: None,
            misses: None,
            misses_by_cause: Vec::new(),
            lost: 0,
            miss_list: Vec::new(),
            runs: Vec::new(),
            longest_run: None,
            floor: None,
            vs_floor: "not compared: nothing was measured".into(),
            summary: format!("not measured ({clock} clock)"),
        }
    }

    fn summary_line(&self) -> String {
        let Some(n) = self.misses else {
            return format!("not measured ({} clock)", self.clock);
        };
        let pct = if self.cycles > 0 {
            100.0 * n as f64 / self.cycles as f64
        } else {
            0.0
        };
        let mut s = format!("{n} deadline misses in {} cycles ({pct:.3} %)", self.cycles);
        let causes: Vec<String> = self
            .misses_by_cause
            .iter()
            .filter(|(_, k)| *k > 0)
            .map(|(c, k)| format!("{k} {}", cause_words(c)))
            .collect();
        if !causes.is_empty() {
            s.push_str(&format!(": {}", causes.join(", ")));
        }
        if let Some(r) = self.longest_run.filter(|r| r.length > 1) {
            s.push_str(&format!(
                "; longest run {} cycles from cycle {}",
                r.length, r.start_cycle
            ));
        }
        if let Some(w) = &self.wake_late_ns {
            s.push_str(&format!(
                "; wake-up late p99 {} max {}",
                us(w.percentiles.p99),
                us(w.percentiles.max)
            ));
        }
        match &self.floor {
            Some(f) => s.push_str(&format!(
                " (machine floor p99 {} max {})",
                us(f.wake_late_ns.p99),
                us(f.wake_late_ns.max)
            )),
            None => s.push_str(" (no latency test to compare with)"),
        }
        if self.lost > 0 {
            s.push_str(&format!("; {} miss records lost", self.lost));
        }
        s
    }

    /// `deadline-misses.txt`: the same content for people.
    pub fn text(&self) -> String {
        let mut s = String::from("Deadline-miss report\n====================\n\n");
        let line = |s: &mut String, k: &str, v: &str| s.push_str(&format!("{k:<13} {v}\n"));
        line(
            &mut s,
            "period",
            &format!(
                "{} µs ({} Hz), {} cycles, {} clock",
                self.period_ns as f64 / 1000.0,
                1e9 / self.period_ns.max(1) as f64,
                self.cycles,
                self.clock
            ),
        );
        if let Some(why) = &self.not_measured {
            line(&mut s, "timing", why);
            return s;
        }
        if let Some(sched) = &self.sched {
            line(&mut s, "scheduling", &sched_words(sched));
            for w in &sched.warnings {
                line(&mut s, "warning", w);
            }
        }
        line(&mut s, "summary", &self.summary);
        for cause in MissCause::ALL {
            let seen = self
                .misses_by_cause
                .iter()
                .any(|(id, n)| id == cause.id() && *n > 0);
            if seen {
                line(
                    &mut s,
                    "cause",
                    &format!("{}: {}", cause.words(), cause.explanation()),
                );
            }
        }
        line(&mut s, "floor", &self.vs_floor);
        s.push_str(&format!(
            "\n{:<16}{:>10}{:>10}{:>10}{:>10}{:>10}{:>10}{:>10}\n",
            "(µs)", "min", "mean", "p50", "p90", "p99", "p99.9", "max"
        ));
        for (name, f) in self.figures() {
            let p = f.percentiles;
            let c = |ns: u64| format!("{:.1}", ns as f64 / 1000.0);
            s.push_str(&format!(
                "{:<16}{:>10}{:>10.1}{:>10}{:>10}{:>10}{:>10}{:>10}\n",
                name,
                c(f.min_ns),
                f.mean_ns / 1000.0,
                c(p.p50),
                c(p.p90),
                c(p.p99),
                c(p.p999),
                c(p.max)
            ));
        }
        for (name, f) in self.figures() {
            s.push_str(&format!(
                "\n{name}: cycles per bin (the JSON has 16 buckets per octave)\n"
            ));
            histogram_text(&mut s, &f.histogram, self.period_ns);
        }
        s.push_str(&format!(
            "\nruns of consecutive misses: {}\n",
            if self.runs.is_empty() {
                "none".to_string()
            } else {
                self.runs.len().to_string()
            }
        ));
        for r in &self.runs {
            s.push_str(&format!(
                "  from cycle {:>10}  {:>6} cycles\n",
                r.start_cycle, r.length
            ));
        }
        s.push_str(&format!(
            "\nevery miss ({} recorded{})\n",
            self.miss_list.len(),
            if self.lost > 0 {
                format!(", {} lost: the drain fell a whole ring behind", self.lost)
            } else {
                String::new()
            }
        ));
        if !self.miss_list.is_empty() {
            s.push_str(&format!(
                "{:>10} {:>12} {:>6} {:>7}  {:<25} {:>10} {:>10} {:>12} {:>10} {:>10} {:>4}\n",
                "cycle",
                "time (s)",
                "line",
                "block",
                "cause",
                "wake (µs)",
                "comp (µs)",
                "preempt (µs)",
                "pub (µs)",
                "late (µs)",
                "lag"
            ));
        }
        for m in &self.miss_list {
            s.push_str(&format!(
                "{:>10} {:>12.6} {:>6} {:>7}  {:<25} {:>10.1} {:>10.1} {:>12.1} {:>10.1} {:>10.1} {:>4}\n",
                m.cycle,
                m.t_ns as f64 * 1e-9,
                m.line,
                m.block_seq,
                cause_words(&m.cause),
                m.wake_late_ns as f64 / 1000.0,
                m.compute_ns as f64 / 1000.0,
                m.preempted_ns as f64 / 1000.0,
                m.publish_ns as f64 / 1000.0,
                m.overrun_ns as f64 / 1000.0,
                m.unanswered
            ));
        }
        s
    }

    fn figures(&self) -> Vec<(&'static str, &Figure)> {
        [
            ("wake-up late", self.wake_late_ns.as_ref()),
            ("compute", self.compute_ns.as_ref()),
            ("publish", self.publish_ns.as_ref()),
        ]
        .into_iter()
        .filter_map(|(n, f)| f.map(|f| (n, f)))
        .collect()
    }

    /// Writes both files into `dir`.
    pub fn write(&self, dir: &Path) -> std::io::Result<()> {
        let json = serde_json::to_string_pretty(self).map_err(std::io::Error::other)?;
        std::fs::write(dir.join(JSON_FILE), json)?;
        std::fs::write(dir.join(TEXT_FILE), self.text())
    }

    pub fn load(dir: &Path) -> Result<DeadlineReport, String> {
        let path = dir.join(JSON_FILE);
        let text =
            std::fs::read_to_string(&path).map_err(|e| format!("{}: {e}", path.display()))?;
        serde_json::from_str(&text).map_err(|e| format!("{}: {e}", path.display()))
    }
}

/// The summary line of the run directory's deadline report, if it has one.
pub fn summary_line(dir: &Path) -> Option<String> {
    DeadlineReport::load(dir).ok().map(|r| r.summary)
}

/// A cause id in words (ids from older runs too).
pub fn cause_words(id: &str) -> &str {
    match id {
        "late_wake" => MissCause::LateWake.words(),
        "long_compute" | "compute" => MissCause::LongCompute.words(),
        "publish_stall" | "publish" => MissCause::PublishStall.words(),
        "downstream_lag" => MissCause::DownstreamLag.words(),
        "preempted" => MissCause::Preempted.words(),
        other => other,
    }
}

/// The 1-2-5 bin (in ns, from 100 ns) that a value falls in: `[lo, hi)`.
fn bin_125(ns: u64) -> (u64, u64) {
    let mut lo = 0u64;
    let mut hi = 100u64;
    while ns >= hi {
        lo = hi;
        let first = hi.to_string().as_bytes().first().copied();
        hi = if first == Some(b'2') {
            hi / 2 * 5
        } else {
            hi * 2
        };
    }
    (lo, hi)
}

/// Histogram buckets summed into 1-2-5 bins, as text bars on a log scale of the count
/// (so a single late cycle still shows), with the period marked.
fn histogram_text(s: &mut String, buckets: &[Bucket], period_ns: u64) {
    let mut bins: Vec<(u64, u64, u64)> = Vec::new();
    for b in buckets {
        let (lo, hi) = bin_125(b.lo_ns);
        match bins.last_mut() {
            Some(o) if o.0 == lo => o.2 += b.count,
            _ => bins.push((lo, hi, b.count)),
        }
    }
    let top = bins.iter().map(|o| o.2).max().unwrap_or(1).max(2);
    for (lo, hi, n) in bins {
        let bar = 1 + ((n as f64).ln() / (top as f64).ln() * 39.0) as usize;
        let mark = if lo <= period_ns && period_ns < hi {
            "  <- the period"
        } else if lo > period_ns {
            "  (past the period)"
        } else {
            ""
        };
        s.push_str(&format!(
            "  {:>9} – {:<9} {:>10}  {}{mark}\n",
            us(lo),
            us(hi),
            n,
            "#".repeat(bar)
        ));
    }
}

/// Where runs look for the latency-test result (see [`latency::default_path`]).
pub fn floor_path() -> std::path::PathBuf {
    latency::default_path()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::timing::CycleTimes;

    fn miss(cycle: u64) -> Miss {
        Miss {
            cycle,
            block_seq: 0,
            source_line: 1,
            wake_late_ns: 0,
            compute_ns: 0,
            publish_ns: 0,
            late_ns: 0,
            unanswered: 0,
            cause: MissCause::LateWake,
            cpu_ns: None,
        }
    }

    #[test]
    fn text_bins_go_1_2_5() {
        assert_eq!(bin_125(50), (0, 100));
        assert_eq!(bin_125(100), (100, 200));
        assert_eq!(bin_125(450), (200, 500));
        assert_eq!(bin_125(13_000), (10_000, 20_000));
        assert_eq!(bin_125(1_000_000), (1_000_000, 2_000_000));
    }

    #[test]
    fn runs_are_consecutive_cycles() {
        let list: Vec<Miss> = [3, 4, 5, 9, 20, 21, 40].into_iter().map(miss).collect();
        let (runs, longest) = runs_of(&list);
        let got: Vec<(u64, u64)> = runs.iter().map(|r| (r.start_cycle, r.length)).collect();
        assert_eq!(got, [(3, 3), (20, 2)]);
        assert_eq!(longest.map(|r| (r.start_cycle, r.length)), Some((3, 3)));
        assert_eq!(runs_of(&[miss(7)]).1.map(|r| r.length), Some(1));
        assert!(runs_of(&[]).1.is_none());
    }

    #[test]
    fn a_report_lists_every_miss_and_agrees_with_its_count() {
        let (mut t, log) = Timing::new(1_000_000, 64);
        for c in 0..1000u64 {
            let compute = if c % 50 == 49 { 1_500_000 } else { 20_000 };
            // Every other long cycle ran only 30 µs of its compute: preempted.
            let cpu = if c % 100 == 49 {
                30_000
            } else {
                compute + 5_000
            };
            t.record(&CycleTimes {
                cycle: c,
                block_seq: c / 300,
                source_line: 5 + (c / 300) as u32,
                wake_late_ns: 10_000,
                compute_ns: compute,
                publish_ns: 1_000,
                unanswered: 0,
                cpu_ns: Some(cpu),
            });
        }
        let list = log.finish();
        let sched = crate::rt::sched::SchedReport {
            policy: "other".into(),
            priority: 0,
            memory_locked: false,
            cpu: None,
            warnings: vec![],
        };
        let nowhere = std::env::temp_dir().join("cnc-no-such-latency-test.json");
        let r = DeadlineReport::measured(1_000_000, 1000, &sched, &t, &list, &nowhere);
        assert_eq!(r.misses, Some(20));
        assert_eq!(r.miss_list.len(), 20);
        for m in &r.miss_list {
            let (cause, off) = if m.cycle % 100 == 49 {
                ("preempted", 1_470_000)
            } else {
                ("long_compute", 0)
            };
            assert_eq!((m.cause.as_str(), m.preempted_ns), (cause, off), "{m:?}");
        }
        assert_eq!(r.miss_list[0].t_ns, 49_000_000);
        assert_eq!(r.misses_by_cause.last(), Some(&("preempted".into(), 10)));
        assert!(r.summary.starts_with(
            "20 deadline misses in 1000 cycles (2.000 %): 10 long compute, 10 preempted mid-compute"
        ));
        assert!(r.vs_floor.starts_with("no latency test measured"));
        let text = r.text();
        assert!(text.contains("every miss (20 recorded)"));
        assert!(text.contains("long compute"));
        assert!(text.contains("preempted mid-compute") && text.contains("preempt (µs)"));
        assert!(
            text.contains("cause         preempted mid-compute: the compute phase lost its CPU")
        );
        assert!(text.contains("cause         long compute: the interpolator thread itself"));
        assert!(!text.contains("cause         late wake-up"));
        // The JSON carries both the CPU time and the time off the CPU.
        let json = serde_json::to_value(&r).unwrap();
        assert_eq!(json["miss_list"][0]["cpu_ns"], 30_000);
        assert_eq!(json["miss_list"][0]["preempted_ns"], 1_470_000);
        let n = r
            .compute_ns
            .as_ref()
            .map_or(0, |f| f.histogram.iter().map(|b| b.count).sum());
        assert_eq!(n, 1000);
        let sim = DeadlineReport::not_measured("sim", 1_000_000, 1000);
        assert!(sim.text().contains("timing not measured"));
    }
}
