//! Off-cycle recording: the real-time loop pushes plain records into a preallocated
//! wait-free ring; a background thread formats them into a CSV file. Pushing never
//! allocates, locks or blocks. If the writer ever falls a whole ring behind, the record is
//! counted as dropped (and the run report says so) instead of stalling the cycle.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

/// How a record becomes one CSV line (without the newline).
pub type FormatFn<T> = fn(&T, &mut String);

pub struct TraceWriter<T: Copy + Send + 'static> {
    producer: rtrb::Producer<T>,
    dropped: u64,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<std::io::Result<u64>>>,
}

impl<T: Copy + Send + 'static> TraceWriter<T> {
    /// Creates `path`, writes `header`, and starts the writer thread. `capacity` records
    /// are buffered (allocated here, once). With `sync_at_end` the file is synced to the
    /// disk when the writer ends. The real clock's traces record a machine's motion:
    /// synced. Under the simulated clock they need not be: the run is a computation that
    /// can be made again, the launcher reads the trace from the page cache a moment later,
    /// and a sync of the butterfly's 4–6 MB traces waits 10–20 ms for this VM's disk at the
    /// very end of the run.
    pub fn create(
        path: &Path,
        header: &str,
        capacity: usize,
        format: FormatFn<T>,
        sync_at_end: bool,
    ) -> std::io::Result<Self> {
        let mut out = BufWriter::with_capacity(1 << 16, File::create(path)?);
        writeln!(out, "{header}")?;
        let (producer, mut consumer) = rtrb::RingBuffer::new(capacity);
        let stop = Arc::new(AtomicBool::new(false));
        let stop2 = stop.clone();
        let thread = std::thread::Builder::new()
            .name("trace-writer".into())
            .spawn(move || {
                let mut line = String::with_capacity(256);
                let mut written = 0u64;
                loop {
                    let stopping = stop2.load(Ordering::Acquire);
                    while let Ok(rec) = consumer.pop() {
                        line.clear();
                        format(&rec, &mut line);
                        line.push('\n');
                        out.write_all(line.as_bytes())?;
                        written += 1;
                    }
                    if stopping {
                        break;
                    }
                    // Hand what we have to the kernel every round: if this process is
                    // killed, at most the last few milliseconds of records are lost.
                    out.flush()?;
                    // `finish` unparks it: the loop's end is not kept waiting a round.
                    std::thread::park_timeout(Duration::from_millis(5));
                }
                out.flush()?;
                if sync_at_end {
                    out.get_ref().sync_all()?;
                }
                Ok(written)
            })?;
        Ok(TraceWriter {
            producer,
            dropped: 0,
            stop,
            thread: Some(thread),
        })
    }

    /// Queues one record. Wait-free and allocation-free.
    #[inline]
    pub fn push(&mut self, rec: T) {
        if self.producer.push(rec).is_err() {
            self.dropped += 1;
        }
    }

    /// Records queued and not yet taken by the writer.
    pub fn queued(&self) -> usize {
        self.producer.buffer().capacity() - self.producer.slots()
    }

    /// Records that could not be queued because the writer was a whole ring behind.
    pub fn dropped(&self) -> u64 {
        self.dropped
    }

    /// Drains the ring, flushes (and, if asked at creation, syncs) the file; returns the
    /// records written.
    pub fn finish(mut self) -> std::io::Result<u64> {
        self.stop.store(true, Ordering::Release);
        match self.thread.take() {
            Some(t) => {
                t.thread().unpark();
                t.join()
                    .unwrap_or_else(|_| Err(std::io::Error::other("trace writer panicked")))
            }
            None => Ok(0),
        }
    }
}

impl<T: Copy + Send + 'static> Drop for TraceWriter<T> {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Release);
        if let Some(t) = self.thread.take() {
            t.thread().unpark();
            let _ = t.join();
        }
    }
}
