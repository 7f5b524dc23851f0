//! `cnc latency-test`: this machine's own wake-up jitter, measured with the cycle's sleep
//! and scheduling code ([`sched::setup`], [`sleep_until_ns`]) but no work, as LinuxCNC's
//! latency-test and cyclictest do. The result is written where later runs find it
//! ([`default_path`]) and their deadline report compares its lateness with this floor.

use crate::rt::sched::{self, words as sched_words, SchedMode, SchedReport};
use crate::timing::{Bucket, Histogram, Percentiles};
use serde::{Deserialize, Serialize};
use shared::clock::{now_ns, sleep_until_ns};
use std::path::{Path, PathBuf};

/// Format tag of the result file.
pub const FORMAT: &str = "cnc latency-test v1";

/// Where the result goes and where runs look for it: `$CNC_LATENCY_FILE` when set, else
/// `runs/latency-test.json` under the current directory (beside the default run
/// directories).
pub fn default_path() -> PathBuf {
    std::env::var_os("CNC_LATENCY_FILE")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from("runs").join("latency-test.json"))
}

/// LinuxCNC's bands for the worst wake-up lateness (its "max jitter").
pub fn verdict(max_ns: u64) -> (&'static str, &'static str) {
    match max_ns {
        0..20_000 => ("very_good", "very good (< 20 µs)"),
        20_000..50_000 => ("good", "good (20–50 µs)"),
        50_000..500_000 => ("needs_care", "needs care (50–500 µs)"),
        _ => ("unusable", "unusable for hard timing (> 500 µs)"),
    }
}

/// The bands in one line, for the printed result.
pub const BANDS: &str =
    "LinuxCNC's bands for the max: < 20 µs very good, 20–50 good, 50–500 needs care, > 500 unusable";

/// What `cnc latency-test` measured.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct LatencyResult {
    pub format: String,
    /// When it was measured (Unix time, s).
    pub unix_time_s: u64,
    pub period_ns: u64,
    pub seconds: f64,
    /// Wake-ups measured.
    pub cycles: u64,
    pub sched: SchedReport,
    pub wake_late_ns: Percentiles,
    pub min_ns: u64,
    pub mean_ns: f64,
    /// Wake-ups later than a whole period: with any work at all, a missed deadline.
    pub later_than_period: u64,
    pub histogram: Vec<Bucket>,
    /// `very_good`, `good`, `needs_care` or `unusable` (from the max).
    pub verdict: String,
    pub verdict_text: String,
}

impl LatencyResult {
    pub fn load(path: &Path) -> Result<LatencyResult, String> {
        let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
        let r: LatencyResult =
            serde_json::from_str(&text).map_err(|e| format!("{}: {e}", path.display()))?;
        if r.format != FORMAT {
            return Err(format!(
                "{}: format `{}`, expected `{FORMAT}`",
                path.display(),
                r.format
            ));
        }
        Ok(r)
    }

    pub fn write(&self, path: &Path) -> std::io::Result<()> {
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir)?;
        }
        let text = serde_json::to_string_pretty(self).map_err(std::io::Error::other)?;
        std::fs::write(path, text)
    }

    /// The printed result, a few lines.
    pub fn text(&self) -> String {
        let p = &self.wake_late_ns;
        let mut s = format!(
            "{} wake-ups at a {} µs period over {:.1} s, {}\n",
            self.cycles,
            self.period_ns / 1000,
            self.seconds,
            sched_words(&self.sched)
        );
        s.push_str(&format!(
            "wake-up lateness  min {}  p50 {}  p90 {}  p99 {}  p99.9 {}  max {}\n",
            us(self.min_ns),
            us(p.p50),
            us(p.p90),
            us(p.p99),
            us(p.p999),
            us(p.max)
        ));
        s.push_str(&format!(
            "later than the period: {} of {}\n",
            self.later_than_period, self.cycles
        ));
        s.push_str(&format!("verdict  {}\n({BANDS})\n", self.verdict_text));
        for w in &self.sched.warnings {
            s.push_str(&format!("warning  {w}\n"));
        }
        s
    }
}

/// A duration for people: µs with a decimal when small, ms when large.
pub fn us(ns: u64) -> String {
    if ns < 10_000 {
        format!("{:.1} µs", ns as f64 / 1000.0)
    } else if ns < 10_000_000 {
        format!("{} µs", (ns + 500) / 1000)
    } else {
        format!("{:.1} ms", ns as f64 / 1e6)
    }
}

/// Measures wake-up lateness for `seconds` at `period_ns` on a thread of its own, with the
/// scheduling the interpolator would get (`mode`).
pub fn measure(
    period_ns: u64,
    seconds: f64,
    mode: SchedMode,
    priority: i32,
) -> std::io::Result<LatencyResult> {
    let period_ns = period_ns.max(1);
    let cycles = ((seconds * 1e9) / period_ns as f64).ceil().max(1.0) as u64;
    let handle = std::thread::Builder::new()
        .name("latency-test".into())
        .spawn(move || {
            let sched = sched::setup(mode, priority);
            let mut h = Histogram::new();
            let mut later = 0u64;
            // The very loop of the cycle, with nothing to do: release, sleep, measure.
            let t0 = now_ns() + period_ns;
            for k in 0..cycles {
                let release = t0 + k * period_ns;
                sleep_until_ns(release);
                let late = now_ns().saturating_sub(release);
                h.record(late);
                later += u64::from(late > period_ns);
            }
            (sched, h, later)
        })?;
    let (sched, h, later) = handle
        .join()
        .map_err(|_| std::io::Error::other("the latency-test thread failed"))?;
    let p = h.percentiles();
    let (v, words) = verdict(p.max);
    Ok(LatencyResult {
        format: FORMAT.into(),
        unix_time_s: std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_secs()),
        period_ns,
        seconds: (cycles * period_ns) as f64 * 1e-9,
        cycles,
        sched,
        wake_late_ns: p,
        min_ns: h.min_ns(),
        mean_ns: h.mean_ns(),
        later_than_period: later,
        histogram: h.buckets(),
        verdict: v.into(),
        verdict_text: words.into(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn verdict_bands_are_linuxcncs() {
        assert_eq!(verdict(19_999).0, "very_good");
        assert_eq!(verdict(20_000).0, "good");
        assert_eq!(verdict(49_999).0, "good");
        assert_eq!(verdict(50_000).0, "needs_care");
        assert_eq!(verdict(500_000).0, "unusable");
    }

    #[test]
    fn a_short_measurement_round_trips_through_its_file() {
        let r = measure(1_000_000, 0.05, SchedMode::Other, sched::DEFAULT_PRIORITY).unwrap();
        assert_eq!(r.cycles, 50);
        assert_eq!(r.histogram.iter().map(|b| b.count).sum::<u64>(), 50);
        let path = std::env::temp_dir().join(format!("cnc-latency-{}.json", std::process::id()));
        r.write(&path).unwrap();
        assert_eq!(LatencyResult::load(&path).unwrap(), r);
        let _ = std::fs::remove_file(&path);
        assert!(r.text().contains("verdict"));
    }
}
