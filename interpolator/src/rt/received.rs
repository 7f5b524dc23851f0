//! The blocks the cycle takes from the interpreter, logged off the cycle.
//!
//! The cycle may not log, format or allocate, so it only notes each block it receives
//! (sequence number, kind, source line, length, feed and the cycle it came in) into a
//! preallocated wait-free ring ([`Receipts::note`]); a thread of its own
//! ([`ReceiptLog`]) takes them out every few milliseconds and writes one `debug` line per
//! block. It is started only when that level is enabled for this module (`RUST_LOG=debug`):
//! otherwise the cycle's side is [`Receipts::off`] and noting is a branch on `None`.
//! Should the thread ever fall a whole ring behind, the notes that did not fit are
//! counted, and the count is logged at the end: never a silent gap, never a stall.

use shared::protocol::{BlockKind, CommandBlock};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

/// Notes the ring holds: 64 block queues' worth, far more than the interpolator can take
/// in one drain interval even under the simulated clock.
pub const RECEIPT_RING: usize = 4096;

/// How often the log thread empties the ring.
const DRAIN_EVERY: Duration = Duration::from_millis(5);

/// One received block, as the cycle notes it: plain data, `Copy`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Receipt {
    pub seq: u64,
    /// The [`BlockKind`] code.
    pub kind: u32,
    pub source_line: u32,
    pub length_mm: f64,
    pub feed_mm_per_min: f64,
    /// The cycle in which the interpolator took the block.
    pub cycle: u64,
}

impl Receipt {
    pub fn of(b: &CommandBlock, cycle: u64) -> Receipt {
        Receipt {
            seq: b.seq,
            kind: b.kind,
            source_line: b.source_line,
            length_mm: b.length_mm,
            feed_mm_per_min: b.feed_mm_per_min,
            cycle,
        }
    }
}

/// The cycle's side: notes go into the ring, or nowhere when logging is off.
pub struct Receipts {
    ring: Option<rtrb::Producer<Receipt>>,
    /// Notes that found the ring full.
    lost: u64,
}

impl Receipts {
    /// Nothing is noted (the debug level is off).
    pub fn off() -> Receipts {
        Receipts {
            ring: None,
            lost: 0,
        }
    }

    /// Notes one received block. Wait-free and allocation-free: on the cycle.
    #[inline]
    pub fn note(&mut self, b: &CommandBlock, cycle: u64) {
        if let Some(ring) = &mut self.ring {
            if ring.push(Receipt::of(b, cycle)).is_err() {
                self.lost += 1;
            }
        }
    }

    /// Notes that did not fit into the ring.
    pub fn lost(&self) -> u64 {
        self.lost
    }
}

/// The thread that turns notes into log lines.
pub struct ReceiptLog {
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<u64>>,
}

/// Starts the log thread and returns the cycle's side with it.
pub fn start() -> std::io::Result<(Receipts, ReceiptLog)> {
    let (producer, mut consumer) = rtrb::RingBuffer::<Receipt>::new(RECEIPT_RING);
    let stop = Arc::new(AtomicBool::new(false));
    let stopping = stop.clone();
    let thread = std::thread::Builder::new()
        .name("block-log".into())
        .spawn(move || {
            let mut logged = 0u64;
            loop {
                // Read the flag first: what the cycle pushed before it was set is drained.
                let last_round = stopping.load(Ordering::Acquire);
                while let Ok(r) = consumer.pop() {
                    log_receipt(&r);
                    logged += 1;
                }
                if last_round {
                    return logged;
                }
                std::thread::sleep(DRAIN_EVERY);
            }
        })?;
    Ok((
        Receipts {
            ring: Some(producer),
            lost: 0,
        },
        ReceiptLog {
            stop,
            thread: Some(thread),
        },
    ))
}

/// The cycle's side and its log thread when `debug` is enabled for this module, else
/// [`Receipts::off`] and no thread. A thread that cannot be started costs the log, not
/// the run.
pub fn start_if_logged() -> (Receipts, Option<ReceiptLog>) {
    if !tracing::enabled!(tracing::Level::DEBUG) {
        return (Receipts::off(), None);
    }
    match start() {
        Ok((r, log)) => (r, Some(log)),
        Err(e) => {
            tracing::warn!("received blocks will not be logged: no thread for it ({e})");
            (Receipts::off(), None)
        }
    }
}

fn log_receipt(r: &Receipt) {
    let kind = BlockKind::from_code(r.kind).map_or("unknown", BlockKind::name);
    tracing::debug!(
        seq = r.seq,
        kind = %kind,
        line = r.source_line,
        length_mm = r.length_mm,
        feed_mm_per_min = r.feed_mm_per_min,
        cycle = r.cycle,
        "block received"
    );
}

impl ReceiptLog {
    /// Drains what is left, ends the thread and logs any notes the ring could not take;
    /// returns the blocks logged.
    pub fn finish(mut self, receipts: &Receipts) -> u64 {
        self.stop.store(true, Ordering::Release);
        let logged = self.thread.take().map_or(0, |t| t.join().unwrap_or(0));
        if receipts.lost() > 0 {
            tracing::debug!(
                not_logged = receipts.lost(),
                "some received blocks were not logged: the log thread fell a whole ring of {RECEIPT_RING} behind"
            );
        }
        logged
    }
}

impl Drop for ReceiptLog {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Release);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_note_reaches_the_log_thread_and_an_off_side_notes_nothing() {
        let (mut r, log) = start().unwrap();
        for seq in 0..100 {
            r.note(&CommandBlock::empty(BlockKind::Motion, seq, 3), seq * 10);
        }
        assert_eq!(log.finish(&r), 100);
        assert_eq!(r.lost(), 0);
        let mut off = Receipts::off();
        off.note(&CommandBlock::empty(BlockKind::Dwell, 0, 1), 0);
        assert_eq!(off.lost(), 0);
    }

    #[test]
    fn a_full_ring_counts_what_it_could_not_take() {
        let (producer, _consumer) = rtrb::RingBuffer::<Receipt>::new(2);
        let mut r = Receipts {
            ring: Some(producer),
            lost: 0,
        };
        for seq in 0..5 {
            r.note(&CommandBlock::empty(BlockKind::Motion, seq, 1), 0);
        }
        assert_eq!(r.lost(), 3);
    }
}
