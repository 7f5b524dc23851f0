//! `cnc latency-test`: this machine's own wake-up jitter, measured with the cycle's sleep
//! and scheduling code ([`sched::setup`], [`sleep_until_ns`]) but no work, as LinuxCNC's
//! latency-test and cyclictest do. The result is written where later runs find it
//! ([`default_path`]) and their deadline report compares its lateness with this floor.
//!
//! While it runs, the measuring thread keeps its figures in a [`Tally`]: the exact
//! histogram of the result and, stored into atomics each wake-up ([`Live`]), the running
//! min, mean, max, count and a coarse histogram that the calling thread reads and shows
//! ([`measure_live`], drawn by [`crate::latency_screen`]). It never prints, locks or
//! allocates for them.

use crate::rt::sched::{self, words as sched_words, SchedMode, SchedReport};
use crate::timing::{Bucket, Histogram, Percentiles};
use serde::{Deserialize, Serialize};
use shared::clock::{now_ns, sleep_until_ns};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

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

/// Upper edges (ns) of the live histogram's bins; the last bin is open. The edges fall on
/// LinuxCNC's bands (20, 50, 500 µs), so each bin lies in one band.
pub const LIVE_EDGES_NS: [u64; 10] = [
    5_000, 10_000, 20_000, 50_000, 100_000, 200_000, 500_000, 1_000_000, 2_000_000, 5_000_000,
];
/// Bins of the live histogram.
pub const LIVE_BINS: usize = LIVE_EDGES_NS.len() + 1;

/// The live bin holding `ns`.
#[inline]
pub fn live_bin(ns: u64) -> usize {
    LIVE_EDGES_NS
        .iter()
        .position(|e| ns < *e)
        .unwrap_or(LIVE_EDGES_NS.len())
}

/// `[lo, hi)` of live bin `i` in ns; `hi` is `None` for the open last bin.
pub fn live_bin_bounds(i: usize) -> (u64, Option<u64>) {
    let lo = i
        .checked_sub(1)
        .and_then(|j| LIVE_EDGES_NS.get(j))
        .copied()
        .unwrap_or(0);
    (lo, LIVE_EDGES_NS.get(i).copied())
}

/// The running figures, shared by the measuring thread (the only writer) with the display
/// thread. Atomics with relaxed loads and stores: the measuring thread never waits, locks
/// or allocates for them, and the display may read one figure a wake-up older than
/// another, which a live view does not mind.
#[derive(Debug, Default)]
pub struct Live {
    wakeups: AtomicU64,
    /// Read only once there is a wake-up.
    min_ns: AtomicU64,
    max_ns: AtomicU64,
    sum_ns: AtomicU64,
    later: AtomicU64,
    bins: [AtomicU64; LIVE_BINS],
}

/// What the display shows: a snapshot of [`Live`].
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct LiveFigures {
    pub wakeups: u64,
    pub min_ns: u64,
    pub max_ns: u64,
    pub mean_ns: f64,
    pub later_than_period: u64,
    pub bins: [u64; LIVE_BINS],
}

impl Live {
    /// The figures now.
    pub fn snapshot(&self) -> LiveFigures {
        let wakeups = self.wakeups.load(Ordering::Acquire);
        let sum = self.sum_ns.load(Ordering::Relaxed);
        LiveFigures {
            wakeups,
            min_ns: if wakeups == 0 {
                0
            } else {
                self.min_ns.load(Ordering::Relaxed)
            },
            max_ns: self.max_ns.load(Ordering::Relaxed),
            mean_ns: if wakeups == 0 {
                0.0
            } else {
                sum as f64 / wakeups as f64
            },
            later_than_period: self.later.load(Ordering::Relaxed),
            bins: std::array::from_fn(|i| self.bins[i].load(Ordering::Relaxed)),
        }
    }
}

/// What the measuring loop keeps, one [`Tally::record`] per wake-up: the exact histogram
/// of the result and the live figures. Everything is allocated before the loop.
pub struct Tally {
    period_ns: u64,
    hist: Histogram,
    later: u64,
    min_ns: u64,
    max_ns: u64,
    sum_ns: u64,
    live: Arc<Live>,
}

impl Tally {
    pub fn new(period_ns: u64, live: Arc<Live>) -> Tally {
        Tally {
            period_ns,
            hist: Histogram::new(),
            later: 0,
            min_ns: u64::MAX,
            max_ns: 0,
            sum_ns: 0,
            live,
        }
    }

    /// One wake-up, `late_ns` after its release. Allocation-free and wait-free: the live
    /// figures are plain stores (this thread is their only writer).
    #[inline]
    pub fn record(&mut self, late_ns: u64) {
        self.hist.record(late_ns);
        self.later += u64::from(late_ns > self.period_ns);
        self.min_ns = self.min_ns.min(late_ns);
        self.max_ns = self.max_ns.max(late_ns);
        self.sum_ns = self.sum_ns.saturating_add(late_ns);
        let live = &*self.live;
        if let Some(bin) = live.bins.get(live_bin(late_ns)) {
            bin.store(bin.load(Ordering::Relaxed) + 1, Ordering::Relaxed);
        }
        live.min_ns.store(self.min_ns, Ordering::Relaxed);
        live.max_ns.store(self.max_ns, Ordering::Relaxed);
        live.sum_ns.store(self.sum_ns, Ordering::Relaxed);
        live.later.store(self.later, Ordering::Relaxed);
        live.wakeups.store(self.hist.count(), Ordering::Release);
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
    measure_live(period_ns, seconds, mode, priority, Duration::MAX, |_| {})
}

/// [`measure`], showing the running figures while it runs: `show` is called on this
/// (the calling) thread about every `every`, and once more with the final figures. The
/// measuring thread only stores its figures into atomics ([`Tally`]); this thread reads
/// them, so nothing it does (printing, a slow terminal) can delay a wake-up.
pub fn measure_live(
    period_ns: u64,
    seconds: f64,
    mode: SchedMode,
    priority: i32,
    every: Duration,
    mut show: impl FnMut(&LiveFigures),
) -> std::io::Result<LatencyResult> {
    let period_ns = period_ns.max(1);
    let cycles = ((seconds * 1e9) / period_ns as f64).ceil().max(1.0) as u64;
    let live = Arc::new(Live::default());
    let mut tally = Tally::new(period_ns, live.clone());
    let handle = std::thread::Builder::new()
        .name("latency-test".into())
        .spawn(move || {
            let sched = sched::setup(mode, priority);
            // The very loop of the cycle, with nothing to do: release, sleep, measure.
            let t0 = now_ns() + period_ns;
            for k in 0..cycles {
                let release = t0 + k * period_ns;
                sleep_until_ns(release);
                tally.record(now_ns().saturating_sub(release));
            }
            (sched, tally)
        })?;
    // Look often enough to notice the end soon, show only every `every`.
    let look = every.min(Duration::from_millis(50));
    let mut shown = Instant::now();
    while !handle.is_finished() {
        std::thread::sleep(look);
        if shown.elapsed() >= every && !handle.is_finished() {
            shown = Instant::now();
            show(&live.snapshot());
        }
    }
    let (sched, tally) = handle
        .join()
        .map_err(|_| std::io::Error::other("the latency-test thread failed"))?;
    show(&live.snapshot());
    let h = &tally.hist;
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
        later_than_period: tally.later,
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

    #[test]
    fn live_bins_follow_their_edges() {
        assert_eq!(live_bin(0), 0);
        assert_eq!(live_bin(4_999), 0);
        assert_eq!(live_bin(5_000), 1);
        assert_eq!(live_bin(49_999), 3);
        assert_eq!(live_bin(50_000), 4);
        assert_eq!(live_bin(u64::MAX), LIVE_BINS - 1);
        assert_eq!(live_bin_bounds(0), (0, Some(5_000)));
        assert_eq!(live_bin_bounds(LIVE_BINS - 1), (5_000_000, None));
    }

    #[test]
    fn the_live_figures_are_the_tallys() {
        let live = Arc::new(Live::default());
        assert_eq!(live.snapshot(), LiveFigures::default());
        let mut t = Tally::new(1_000_000, live.clone());
        for ns in [3_000, 30_000, 1_500_000, 7_000] {
            t.record(ns);
        }
        let f = live.snapshot();
        assert_eq!(f.wakeups, 4);
        assert_eq!((f.min_ns, f.max_ns), (3_000, 1_500_000));
        assert_eq!(f.mean_ns, 385_000.0);
        assert_eq!(f.later_than_period, 1);
        assert_eq!(f.bins[0] + f.bins[1] + f.bins[3] + f.bins[8], 4);
        assert_eq!(f.bins.iter().sum::<u64>(), 4);
    }

    #[test]
    fn a_watched_measurement_shows_its_final_figures() {
        let mut seen = Vec::new();
        let r = measure_live(
            1_000_000,
            0.02,
            SchedMode::Other,
            sched::DEFAULT_PRIORITY,
            Duration::from_millis(5),
            |f| seen.push(*f),
        )
        .unwrap();
        let last = seen.last().unwrap();
        assert_eq!(last.wakeups, r.cycles);
        assert_eq!(last.max_ns, r.wake_late_ns.max);
        assert_eq!(last.later_than_period, r.later_than_period);
    }
}
