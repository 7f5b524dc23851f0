//! Cycle timing: a fixed-resolution histogram per measured quantity and the list of
//! deadline misses. Everything is allocated before the loop starts; recording is O(1)
//! and allocation-free.
#![deny(
    clippy::indexing_slicing,
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic
)]

use serde::Serialize;

/// 1 µs buckets up to 100 ms; larger values land in the last bucket (the exact maximum is
/// kept separately).
const BUCKETS: usize = 100_000;
const BUCKET_NS: u64 = 1_000;

pub struct Histogram {
    counts: Vec<u32>,
    n: u64,
    max_ns: u64,
}

/// Percentiles of a histogram, in ns (bucket upper bounds, so at most 1 µs pessimistic).
#[derive(Debug, Clone, Copy, Default, Serialize, serde::Deserialize, PartialEq)]
pub struct Percentiles {
    pub p50: u64,
    pub p99: u64,
    pub max: u64,
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
            max_ns: 0,
        }
    }

    #[inline]
    pub fn record(&mut self, ns: u64) {
        let i = ((ns / BUCKET_NS) as usize).min(BUCKETS - 1);
        if let Some(c) = self.counts.get_mut(i) {
            *c = c.saturating_add(1);
        }
        self.n += 1;
        self.max_ns = self.max_ns.max(ns);
    }

    pub fn count(&self) -> u64 {
        self.n
    }

    fn quantile(&self, q: f64) -> u64 {
        if self.n == 0 {
            return 0;
        }
        let rank = ((q * self.n as f64).ceil() as u64).max(1);
        let mut seen = 0u64;
        for (i, c) in self.counts.iter().enumerate() {
            seen += *c as u64;
            if seen >= rank {
                return ((i as u64 + 1) * BUCKET_NS).min(self.max_ns);
            }
        }
        self.max_ns
    }

    pub fn percentiles(&self) -> Percentiles {
        Percentiles {
            p50: self.quantile(0.50),
            p99: self.quantile(0.99),
            max: self.max_ns,
        }
    }
}

/// What made a cycle late: the largest of its three parts.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum MissCause {
    /// The OS woke the loop late (scheduling latency, preemption before the cycle ran).
    LateWake,
    /// Stepping and evaluating the path took too long (or was preempted while doing it).
    Compute,
    /// Handing the set-point to shared memory took too long.
    Publish,
}

/// One deadline miss: the cycle finished after `release + period`.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Miss {
    pub cycle: u64,
    pub source_line: u32,
    pub wake_late_ns: u64,
    pub compute_ns: u64,
    pub publish_ns: u64,
    /// Finish time minus deadline.
    pub overrun_ns: u64,
    pub cause: MissCause,
}

/// All timing of a run.
pub struct Timing {
    pub period_ns: u64,
    pub wake_late: Histogram,
    pub compute: Histogram,
    pub publish: Histogram,
    pub misses: u64,
    /// The first `capacity` misses in full; later ones are only counted.
    pub miss_log: Vec<Miss>,
}

impl Timing {
    pub fn new(period_ns: u64, miss_capacity: usize) -> Self {
        Timing {
            period_ns,
            wake_late: Histogram::new(),
            compute: Histogram::new(),
            publish: Histogram::new(),
            misses: 0,
            miss_log: Vec::with_capacity(miss_capacity),
        }
    }

    /// Records one cycle. `release_ns` is when it was due to start; `finish_ns` when the
    /// set-point was out. Allocation-free: the miss log never grows past its capacity.
    #[inline]
    pub fn record(
        &mut self,
        cycle: u64,
        source_line: u32,
        wake_late_ns: u64,
        compute_ns: u64,
        publish_ns: u64,
    ) {
        self.wake_late.record(wake_late_ns);
        self.compute.record(compute_ns);
        self.publish.record(publish_ns);
        let used = wake_late_ns + compute_ns + publish_ns;
        if used > self.period_ns {
            self.misses += 1;
            let cause = if wake_late_ns >= compute_ns && wake_late_ns >= publish_ns {
                MissCause::LateWake
            } else if compute_ns >= publish_ns {
                MissCause::Compute
            } else {
                MissCause::Publish
            };
            if self.miss_log.len() < self.miss_log.capacity() {
                self.miss_log.push(Miss {
                    cycle,
                    source_line,
                    wake_late_ns,
                    compute_ns,
                    publish_ns,
                    overrun_ns: used - self.period_ns,
                    cause,
                });
            }
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::indexing_slicing, clippy::panic)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_of_known_samples() {
        let mut h = Histogram::new();
        for i in 1..=100u64 {
            h.record(i * 1_000 - 500);
        }
        let p = h.percentiles();
        assert_eq!(p.p50, 50_000);
        assert_eq!(p.p99, 99_000);
        assert_eq!(p.max, 99_500);
    }

    #[test]
    fn a_miss_names_its_largest_part() {
        let mut t = Timing::new(1_000_000, 4);
        t.record(7, 12, 900_000, 200_000, 1_000);
        t.record(8, 12, 10_000, 20_000, 1_000);
        t.record(9, 13, 10_000, 1_500_000, 1_000);
        assert_eq!(t.misses, 2);
        assert_eq!(t.miss_log[0].cause, MissCause::LateWake);
        assert_eq!(t.miss_log[0].overrun_ns, 101_000);
        assert_eq!(t.miss_log[1].cause, MissCause::Compute);
    }
}
