//! Cycle timing: a log-bucketed histogram per measured quantity (wake-up lateness, compute
//! time, publish time) and every deadline miss, with its cause (the rule is at
//! [`MissCause`]: the thread's own CPU time tells a slow compute from a preempted one).
//!
//! Inside the cycle, [`Timing::record`] does O(1) work on storage allocated before the loop:
//! three histogram increments and, for a miss, one push of a small [`Miss`] record into a
//! pre-allocated wait-free ring. A [`MissLog`] thread drains that ring outside the cycle
//! into a list that may grow for as long as the run lasts, so *every* miss is kept; only if
//! the drain falls a whole ring behind (16 384 misses, seconds of them) are records lost,
//! and then they are counted ([`Timing::lost`]), never silently dropped.
//!
//! Vocabulary: a cycle is *released* at `t0 + k·period`; its *wake-up lateness* is when it
//! actually woke minus that; it *misses* its deadline when the set-point is out after
//! `release + period`, or when the drives have not yet answered the set-point sent two
//! cycles earlier (downstream not consuming).
#![deny(
    clippy::indexing_slicing,
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic
)]

use serde::{Deserialize, Serialize};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

/// Sub-buckets per power of two: bucket widths are 1/16 of an octave (about 4 %), so a
/// percentile read from a bucket bound is at most ~6 % pessimistic.
const SUB_BITS: u32 = 4;
const SUB: u64 = 1 << SUB_BITS;
/// Values below `2·SUB` ns get one bucket each (exact).
const LINEAR: u64 = 2 * SUB;
/// The largest octave kept: [2^40, 2^41) ns, up to 36 minutes. Larger values land in the
/// last bucket (the exact maximum is kept separately).
const TOP_OCTAVE: u32 = 40;
/// Number of buckets.
pub const BUCKETS: usize = (LINEAR + (TOP_OCTAVE - SUB_BITS) as u64 * SUB) as usize;

/// A histogram of durations in ns with log-scaled buckets (HDR-histogram-like: 16 linear
/// sub-buckets per power of two). Recording is O(1) and allocation-free.
#[derive(Debug, Clone)]
pub struct Histogram {
    counts: Vec<u64>,
    n: u64,
    min_ns: u64,
    max_ns: u64,
    sum_ns: u64,
}

/// Percentiles of a histogram, in ns: bucket upper bounds (never above the true maximum),
/// so at most one bucket width (~6 %) pessimistic.
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize, PartialEq)]
pub struct Percentiles {
    pub p50: u64,
    #[serde(default)]
    pub p90: u64,
    pub p99: u64,
    #[serde(default)]
    pub p999: u64,
    pub max: u64,
}

/// One bucket of a histogram: `count` values in `[lo_ns, hi_ns)`.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq)]
pub struct Bucket {
    pub lo_ns: u64,
    pub hi_ns: u64,
    pub count: u64,
}

impl Default for Histogram {
    fn default() -> Self {
        Self::new()
    }
}

impl Histogram {
    pub fn new() -> Self {
        Histogram {
            counts: vec![0; BUCKETS],
            n: 0,
            min_ns: u64::MAX,
            max_ns: 0,
            sum_ns: 0,
        }
    }

    /// The bucket holding `ns`.
    #[inline]
    pub fn bucket_of(ns: u64) -> usize {
        if ns < LINEAR {
            return ns as usize;
        }
        let octave = 63 - ns.leading_zeros(); // >= SUB_BITS + 1
        if octave > TOP_OCTAVE {
            return BUCKETS - 1;
        }
        let sub = (ns >> (octave - SUB_BITS)) - SUB; // 0..SUB
        (LINEAR + (octave - SUB_BITS - 1) as u64 * SUB + sub) as usize
    }

    /// `[lo, hi)` of bucket `i`, in ns.
    pub fn bounds(i: usize) -> (u64, u64) {
        let i = i as u64;
        if i < LINEAR {
            return (i, i + 1);
        }
        let octave = (i - LINEAR) / SUB + SUB_BITS as u64 + 1;
        let sub = (i - LINEAR) % SUB;
        let width = 1u64 << (octave - SUB_BITS as u64);
        let lo = (SUB + sub) * width;
        (lo, lo + width)
    }

    #[inline]
    pub fn record(&mut self, ns: u64) {
        if let Some(c) = self.counts.get_mut(Self::bucket_of(ns)) {
            *c = c.saturating_add(1);
        }
        self.n += 1;
        self.min_ns = self.min_ns.min(ns);
        self.max_ns = self.max_ns.max(ns);
        self.sum_ns = self.sum_ns.saturating_add(ns);
    }

    pub fn count(&self) -> u64 {
        self.n
    }

    pub fn max_ns(&self) -> u64 {
        self.max_ns
    }

    /// The smallest value recorded (0 when empty).
    pub fn min_ns(&self) -> u64 {
        if self.n == 0 {
            0
        } else {
            self.min_ns
        }
    }

    pub fn mean_ns(&self) -> f64 {
        if self.n == 0 {
            0.0
        } else {
            self.sum_ns as f64 / self.n as f64
        }
    }

    /// The `q` quantile (0..=1) as a bucket upper bound, capped at the maximum.
    pub fn quantile(&self, q: f64) -> u64 {
        if self.n == 0 {
            return 0;
        }
        let rank = ((q * self.n as f64).ceil() as u64).clamp(1, self.n);
        let mut seen = 0u64;
        for (i, c) in self.counts.iter().enumerate() {
            seen += *c;
            if seen >= rank {
                return Self::bounds(i).1.min(self.max_ns);
            }
        }
        self.max_ns
    }

    pub fn percentiles(&self) -> Percentiles {
        Percentiles {
            p50: self.quantile(0.50),
            p90: self.quantile(0.90),
            p99: self.quantile(0.99),
            p999: self.quantile(0.999),
            max: self.max_ns,
        }
    }

    /// The buckets that hold anything, in rising order.
    pub fn buckets(&self) -> Vec<Bucket> {
        self.counts
            .iter()
            .enumerate()
            .filter(|(_, c)| **c > 0)
            .map(|(i, c)| {
                let (lo_ns, hi_ns) = Self::bounds(i);
                Bucket {
                    lo_ns,
                    hi_ns,
                    count: *c,
                }
            })
            .collect()
    }
}

/// What made a cycle miss its deadline.
///
/// The rule. A cycle *finishes late* when its time from release to the set-point being
/// out, `wake_late + compute + publish`, exceeds the period; that time is cut into four
/// parts, and the cause is the largest part (on a tie, the first in this order):
///
/// 1. the wake-up lateness: [`MissCause::LateWake`];
/// 2. the compute phase *on* the CPU, `compute − off`: [`MissCause::LongCompute`];
/// 3. the compute phase *off* the CPU, `off = compute − cpu` (0 when negative or when the
///    thread's CPU time could not be read): [`MissCause::Preempted`];
/// 4. the publish: [`MissCause::PublishStall`].
///
/// `cpu` is the interpolator thread's own CPU time (CLOCK_THREAD_CPUTIME_ID) from the end
/// of the previous cycle's compute to the end of this one's: one read a cycle, since the
/// thread sleeps between cycles and sleeping takes no CPU time. That window holds this
/// cycle's whole compute phase plus the previous cycle's publish and this cycle's wake-up,
/// so `cpu` is never less than the compute phase's own CPU time and `off` is never more
/// than the time the compute phase really spent off the CPU: a cycle is called preempted
/// only on evidence, and only when that time strictly exceeds the time it ran.
///
/// A cycle that finishes in time but whose drives lag is [`MissCause::DownstreamLag`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MissCause {
    /// The OS woke the loop late (scheduling latency, preemption before the cycle ran);
    /// the wake-up lateness was the largest part of the cycle.
    LateWake,
    /// Stepping and evaluating the path took too long: the thread itself was running for
    /// the largest part of the cycle.
    LongCompute,
    /// Handing the set-point to shared memory took too long.
    PublishStall,
    /// The cycle itself was on time, but the drives had not answered the set-point sent
    /// two cycles earlier: the servo-sim is not consuming set-points in time.
    DownstreamLag,
    /// The compute phase was long by the wall clock, but the thread ran for only a small
    /// part of it: the OS took the CPU away in the middle (a task at the same or a higher
    /// real-time priority on this CPU, threaded interrupt handlers, RT throttling, or the
    /// hypervisor, whose stolen time the guest leaves out of the thread's CPU time when
    /// built with CONFIG_PARAVIRT_TIME_ACCOUNTING, as the project's VMs are). Not slow
    /// path evaluation: the machine's real-time set-up (priorities, isolated CPUs) is what
    /// let the cycle down. Hard and soft interrupts that run on the thread's time are
    /// charged to it unless the kernel has CONFIG_IRQ_TIME_ACCOUNTING (these VMs do not),
    /// so those still count as compute.
    Preempted,
}

impl MissCause {
    /// Every cause, in the order of [`Timing::by_cause`] and of the report's
    /// `misses_by_cause`. `Preempted` came last and stays last, so every older cause keeps
    /// its place in those lists.
    pub const ALL: [MissCause; 5] = [
        MissCause::LateWake,
        MissCause::LongCompute,
        MissCause::PublishStall,
        MissCause::DownstreamLag,
        MissCause::Preempted,
    ];

    /// The name in the JSON files.
    pub fn id(self) -> &'static str {
        match self {
            MissCause::LateWake => "late_wake",
            MissCause::LongCompute => "long_compute",
            MissCause::PublishStall => "publish_stall",
            MissCause::DownstreamLag => "downstream_lag",
            MissCause::Preempted => "preempted",
        }
    }

    /// What the cause means and where to look, for the text report.
    pub fn explanation(self) -> &'static str {
        match self {
            MissCause::LateWake => {
                "the OS woke the cycle late: scheduling latency of this machine (compare with `cnc latency-test`)"
            }
            MissCause::LongCompute => {
                "the interpolator thread itself computed for most of the cycle: path stepping and evaluation are too slow for the period"
            }
            MissCause::PublishStall => "handing the set-point over to shared memory took most of the cycle",
            MissCause::DownstreamLag => {
                "the cycle was on time, but the drives (servo-sim) had not answered the set-point of two cycles before"
            }
            MissCause::Preempted => {
                "the compute phase lost its CPU for most of the cycle (the thread's own CPU time was far below its wall time): not slow path evaluation but the machine's real-time set-up; check priorities, isolated CPUs and other real-time tasks on the interpolator's CPU"
            }
        }
    }

    /// The cause in words.
    pub fn words(self) -> &'static str {
        match self {
            MissCause::LateWake => "late wake-up",
            MissCause::LongCompute => "long compute",
            MissCause::PublishStall => "publish stall",
            MissCause::DownstreamLag => "downstream not consuming",
            MissCause::Preempted => "preempted mid-compute",
        }
    }
}

/// At the start of a cycle, this many set-points sent and not yet answered by the drives
/// make the cycle a miss (cause [`MissCause::DownstreamLag`]): the answer to the set-point
/// of two cycles ago is more than a period overdue.
pub const DOWNSTREAM_LAG_CYCLES: u64 = 2;

/// One cycle's measurements, as the loop hands them to [`Timing::record`].
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct CycleTimes {
    pub cycle: u64,
    pub block_seq: u64,
    pub source_line: u32,
    pub wake_late_ns: u64,
    pub compute_ns: u64,
    pub publish_ns: u64,
    /// Set-points already sent that the drives had not answered when the cycle woke.
    pub unanswered: u64,
    /// The thread's CPU time from the end of the previous cycle's compute to the end of
    /// this one's (see [`MissCause`]); `None` when it could not be read.
    pub cpu_ns: Option<u64>,
}

impl CycleTimes {
    /// How long the compute phase was off the CPU, at least (see [`MissCause`]).
    #[inline]
    pub fn preempted_ns(&self) -> u64 {
        off_cpu_ns(self.compute_ns, self.cpu_ns)
    }
}

/// Wall compute minus the thread's CPU time, 0 when that is negative or unknown.
#[inline]
fn off_cpu_ns(compute_ns: u64, cpu_ns: Option<u64>) -> u64 {
    cpu_ns.map_or(0, |cpu| compute_ns.saturating_sub(cpu))
}

/// One deadline miss. Small and `Copy`: it travels through the ring as is.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Miss {
    pub cycle: u64,
    /// The block being run and its source line.
    pub block_seq: u64,
    pub source_line: u32,
    pub wake_late_ns: u64,
    pub compute_ns: u64,
    pub publish_ns: u64,
    /// How late: the set-point's finish minus the deadline; for a downstream miss, how
    /// long the oldest unanswered set-point's answer is overdue (at least).
    pub late_ns: u64,
    /// Set-points sent and not answered when the cycle woke.
    pub unanswered: u64,
    pub cause: MissCause,
    /// The thread's CPU time over the cycle, as in [`CycleTimes::cpu_ns`].
    pub cpu_ns: Option<u64>,
}

impl Miss {
    /// How long the compute phase was off the CPU, at least (see [`MissCause`]).
    pub fn preempted_ns(&self) -> u64 {
        off_cpu_ns(self.compute_ns, self.cpu_ns)
    }
}

/// Capacity of the miss ring between the cycle and the [`MissLog`] thread.
pub const MISS_RING: usize = 1 << 14;

/// All timing of a run, as the cycle records it.
pub struct Timing {
    pub period_ns: u64,
    pub wake_late: Histogram,
    pub compute: Histogram,
    pub publish: Histogram,
    /// Every miss, counted.
    pub misses: u64,
    /// Misses by cause, in the order of [`MissCause::ALL`].
    pub by_cause: [u64; MissCause::ALL.len()],
    /// Misses whose record could not be queued (the drain was a whole ring behind).
    pub lost: u64,
    ring: rtrb::Producer<Miss>,
}

impl Timing {
    /// Timing for a loop of period `period_ns`, and the log that collects its misses
    /// (start it with [`MissLog::start`]).
    pub fn new(period_ns: u64, ring: usize) -> (Timing, MissLog) {
        let (producer, consumer) = rtrb::RingBuffer::new(ring.max(1));
        (
            Timing {
                period_ns,
                wake_late: Histogram::new(),
                compute: Histogram::new(),
                publish: Histogram::new(),
                misses: 0,
                by_cause: [0; MissCause::ALL.len()],
                lost: 0,
                ring: producer,
            },
            MissLog {
                consumer: Some(consumer),
                list: Vec::new(),
                thread: None,
                stop: Arc::new(AtomicBool::new(false)),
            },
        )
    }

    /// What made a cycle with these times late, if it was, and by how much (the rule is
    /// at [`MissCause`]).
    #[inline]
    pub fn classify(&self, t: &CycleTimes) -> Option<(MissCause, u64)> {
        let used = t.wake_late_ns + t.compute_ns + t.publish_ns;
        if used > self.period_ns {
            let off = t.preempted_ns();
            let parts = [
                (t.wake_late_ns, MissCause::LateWake),
                (t.compute_ns - off, MissCause::LongCompute),
                (off, MissCause::Preempted),
                (t.publish_ns, MissCause::PublishStall),
            ];
            // Strictly larger replaces: a tie stays with the earlier part.
            let (_, cause) = parts.into_iter().fold((0, MissCause::LateWake), |best, p| {
                if p.0 > best.0 {
                    p
                } else {
                    best
                }
            });
            Some((cause, used - self.period_ns))
        } else if t.unanswered >= DOWNSTREAM_LAG_CYCLES {
            let overdue = (t.unanswered - (DOWNSTREAM_LAG_CYCLES - 1)) * self.period_ns;
            Some((MissCause::DownstreamLag, overdue + t.wake_late_ns))
        } else {
            None
        }
    }

    /// Records one cycle. O(1), allocation-free, lock-free.
    #[inline]
    pub fn record(&mut self, t: &CycleTimes) {
        self.wake_late.record(t.wake_late_ns);
        self.compute.record(t.compute_ns);
        self.publish.record(t.publish_ns);
        if let Some((cause, late_ns)) = self.classify(t) {
            self.misses += 1;
            let i = MissCause::ALL.iter().position(|c| *c == cause).unwrap_or(0);
            if let Some(n) = self.by_cause.get_mut(i) {
                *n += 1;
            }
            let miss = Miss {
                cycle: t.cycle,
                block_seq: t.block_seq,
                source_line: t.source_line,
                wake_late_ns: t.wake_late_ns,
                compute_ns: t.compute_ns,
                publish_ns: t.publish_ns,
                late_ns,
                unanswered: t.unanswered,
                cause,
                cpu_ns: t.cpu_ns,
            };
            if self.ring.push(miss).is_err() {
                self.lost += 1;
            }
        }
    }
}

/// The misses drained from the cycle's ring, off the cycle.
pub struct MissLog {
    consumer: Option<rtrb::Consumer<Miss>>,
    list: Vec<Miss>,
    thread: Option<JoinHandle<(rtrb::Consumer<Miss>, Vec<Miss>)>>,
    stop: Arc<AtomicBool>,
}

/// How often the drain thread empties the ring: at a 100 µs period even a run of nothing
/// but misses fills only 100 of the 16 384 slots in this time.
const DRAIN_EVERY: Duration = Duration::from_millis(10);

impl MissLog {
    /// Starts the thread that drains the ring while the cycle runs. Without it the ring is
    /// only drained by [`MissLog::drain`] and [`MissLog::finish`].
    pub fn start(&mut self) -> std::io::Result<()> {
        let Some(mut consumer) = self.consumer.take() else {
            return Ok(());
        };
        let stop = self.stop.clone();
        let mut list = std::mem::take(&mut self.list);
        let handle = std::thread::Builder::new()
            .name("miss-log".into())
            .spawn(move || {
                loop {
                    let stopping = stop.load(Ordering::Acquire);
                    while let Ok(m) = consumer.pop() {
                        list.push(m);
                    }
                    if stopping {
                        break;
                    }
                    std::thread::sleep(DRAIN_EVERY);
                }
                (consumer, list)
            })?;
        self.thread = Some(handle);
        Ok(())
    }

    /// Drains the ring now (when no thread does).
    pub fn drain(&mut self) {
        if let Some(c) = self.consumer.as_mut() {
            while let Ok(m) = c.pop() {
                self.list.push(m);
            }
        }
    }

    /// Every miss drained, in cycle order (stops the thread; call after the loop).
    pub fn finish(mut self) -> Vec<Miss> {
        self.stop.store(true, Ordering::Release);
        if let Some(h) = self.thread.take() {
            if let Ok((consumer, list)) = h.join() {
                self.consumer = Some(consumer);
                self.list = list;
            }
        }
        self.drain();
        self.list
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::indexing_slicing, clippy::panic)]
mod tests {
    use super::*;

    #[test]
    fn buckets_tile_the_line() {
        let mut prev_hi = 0;
        for i in 0..BUCKETS {
            let (lo, hi) = Histogram::bounds(i);
            assert_eq!(lo, prev_hi, "bucket {i}");
            assert!(hi > lo);
            assert_eq!(Histogram::bucket_of(lo), i);
            assert_eq!(Histogram::bucket_of(hi - 1), i);
            // Log-scaled: a bucket is at most 1/16 of its lower bound wide (past the
            // exact ones).
            if lo >= LINEAR {
                assert!((hi - lo) * SUB <= lo);
            }
            prev_hi = hi;
        }
        assert_eq!(Histogram::bucket_of(u64::MAX), BUCKETS - 1);
    }

    #[test]
    fn percentiles_of_known_samples() {
        let mut h = Histogram::new();
        for i in 1..=1000u64 {
            h.record(i * 1_000);
        }
        let p = h.percentiles();
        let near = |got: u64, want: u64| {
            assert!(
                got >= want && got as f64 <= want as f64 * 1.07,
                "{got} vs {want}"
            )
        };
        near(p.p50, 500_000);
        near(p.p90, 900_000);
        near(p.p99, 990_000);
        near(p.p999, 999_000);
        assert_eq!(p.max, 1_000_000);
        assert_eq!(h.min_ns(), 1_000);
        assert_eq!(h.buckets().iter().map(|b| b.count).sum::<u64>(), 1000);
    }

    fn times(cycle: u64, wake: u64, compute: u64, publish: u64, unanswered: u64) -> CycleTimes {
        CycleTimes {
            cycle,
            block_seq: cycle / 10,
            source_line: 12,
            wake_late_ns: wake,
            compute_ns: compute,
            publish_ns: publish,
            unanswered,
            cpu_ns: None,
        }
    }

    /// A cycle of the 1 ms loop with the thread's CPU time known.
    fn with_cpu(wake: u64, compute: u64, cpu: u64, publish: u64) -> CycleTimes {
        CycleTimes {
            cpu_ns: Some(cpu),
            ..times(1, wake, compute, publish, 0)
        }
    }

    #[test]
    fn the_largest_part_names_the_cause_with_compute_cut_on_and_off_the_cpu() {
        let (t, _log) = Timing::new(1_000_000, 4);
        let cause = |c: CycleTimes| t.classify(&c).map(|(cause, _)| cause);
        use MissCause::*;
        // Preempted: 1.5 ms of wall compute, of which the thread ran 60 µs.
        let c = with_cpu(10_000, 1_500_000, 60_000, 5_000);
        assert_eq!(t.classify(&c), Some((Preempted, 515_000)));
        assert_eq!(c.preempted_ns(), 1_440_000);
        // The same cycle without a CPU reading blames nothing on preemption.
        assert_eq!(cause(CycleTimes { cpu_ns: None, ..c }), Some(LongCompute));
        // The thread ran the whole compute: the window of its CPU time is wider than the
        // compute phase (it holds the previous publish too), so off is 0, not negative.
        let c = with_cpu(10_000, 1_500_000, 1_520_000, 5_000);
        assert_eq!((cause(c), c.preempted_ns()), (Some(LongCompute), 0));
        // On against off: a tie stays a long compute; 1 ns more off makes it preempted.
        assert_eq!(cause(with_cpu(0, 1_200_000, 600_000, 0)), Some(LongCompute));
        assert_eq!(cause(with_cpu(0, 1_200_000, 599_999, 0)), Some(Preempted));
        // Off against a late wake-up: a tie is the late wake-up's.
        assert_eq!(cause(with_cpu(700_000, 700_000, 0, 0)), Some(LateWake));
        assert_eq!(cause(with_cpu(699_999, 700_000, 0, 0)), Some(Preempted));
        // Off against the publish: a tie is the preemption's.
        assert_eq!(cause(with_cpu(0, 600_000, 0, 600_000)), Some(Preempted));
        assert_eq!(cause(with_cpu(0, 600_000, 0, 600_001)), Some(PublishStall));
        // However preempted, a cycle that finishes by its deadline is no miss ...
        assert_eq!(cause(with_cpu(0, 999_000, 1_000, 1_000)), None);
        assert_eq!(cause(with_cpu(0, 999_001, 1_000, 1_000)), Some(Preempted));
        // ... unless its drives lag, which preemption does not change.
        let lag = CycleTimes {
            unanswered: 2,
            ..with_cpu(10_000, 900_000, 1_000, 1_000)
        };
        assert_eq!(t.classify(&lag), Some((DownstreamLag, 1_010_000)));
    }

    #[test]
    fn a_preempted_miss_is_counted_and_keeps_its_cpu_time() {
        let (mut t, log) = Timing::new(1_000_000, 4);
        t.record(&with_cpu(10_000, 1_500_000, 60_000, 5_000));
        t.record(&with_cpu(10_000, 1_500_000, 1_500_000, 5_000));
        assert_eq!(t.by_cause, [0, 1, 0, 0, 1]);
        let list = log.finish();
        assert_eq!(list[0].cause, MissCause::Preempted);
        assert_eq!(list[0].cpu_ns, Some(60_000));
        assert_eq!(list[0].preempted_ns(), 1_440_000);
        assert_eq!(list[1].cause, MissCause::LongCompute);
        assert_eq!(list[1].preempted_ns(), 0);
        let ids: Vec<_> = MissCause::ALL.iter().map(|c| c.id()).collect();
        assert_eq!(
            ids,
            [
                "late_wake",
                "long_compute",
                "publish_stall",
                "downstream_lag",
                "preempted"
            ]
        );
    }

    #[test]
    fn each_miss_is_named_by_its_cause() {
        let (mut t, log) = Timing::new(1_000_000, 4);
        t.record(&times(7, 900_000, 200_000, 1_000, 0));
        t.record(&times(8, 10_000, 20_000, 1_000, 1));
        t.record(&times(9, 10_000, 1_500_000, 1_000, 0));
        t.record(&times(10, 10_000, 20_000, 990_000, 0));
        t.record(&times(11, 10_000, 20_000, 1_000, 3));
        assert_eq!(t.misses, 4);
        assert_eq!(t.by_cause, [1, 1, 1, 1, 0]);
        let list = log.finish();
        let causes: Vec<_> = list.iter().map(|m| (m.cycle, m.cause)).collect();
        assert_eq!(
            causes,
            [
                (7, MissCause::LateWake),
                (9, MissCause::LongCompute),
                (10, MissCause::PublishStall),
                (11, MissCause::DownstreamLag)
            ]
        );
        assert_eq!(list[0].late_ns, 101_000);
        assert_eq!(list[3].late_ns, 2 * 1_000_000 + 10_000);
        assert_eq!(list[1].block_seq, 0);
    }

    #[test]
    fn a_full_ring_counts_what_it_loses() {
        let (mut t, log) = Timing::new(1_000, 4);
        for c in 0..10 {
            t.record(&times(c, 0, 5_000, 0, 0));
        }
        assert_eq!((t.misses, t.lost), (10, 6));
        assert_eq!(log.finish().len(), 4);
    }

    #[test]
    fn the_drain_thread_keeps_every_miss() {
        let (mut t, mut log) = Timing::new(1_000, 64);
        log.start().unwrap();
        for c in 0..20_000 {
            t.record(&times(c, 0, 5_000, 0, 0));
            if c % 50 == 0 {
                std::thread::sleep(Duration::from_micros(200));
            }
        }
        let list = log.finish();
        assert_eq!(list.len() as u64 + t.lost, 20_000);
        assert!(list.windows(2).all(|w| w[0].cycle < w[1].cycle));
    }
}
