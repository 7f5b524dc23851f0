//! A list of fixed-size records of `f64`s kept in a temporary file rather than in memory
//! (the points of a circle run of a long run are millions, a trace's rows for the page
//! too), read back in order as often as needed. The file is removed as soon as it is
//! made: it lives as long as the [`Spill`] (or the [`Spilled`] it becomes) and never
//! outlives the process.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::os::unix::fs::FileExt;

/// Records of `N` numbers each, appended then read back in order.
pub struct Spill<const N: usize> {
    out: BufWriter<File>,
    len: usize,
}

impl<const N: usize> Spill<N> {
    /// An empty list in a new temporary file.
    pub fn new() -> std::io::Result<Self> {
        use std::sync::atomic::{AtomicU64, Ordering};
        static NEXT: AtomicU64 = AtomicU64::new(0);
        let path = std::env::temp_dir().join(format!(
            "cnc-spill-{}-{}",
            std::process::id(),
            NEXT.fetch_add(1, Ordering::Relaxed)
        ));
        let f = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .create_new(true)
            .open(&path)?;
        // Unlinked at once: the open file stays readable until it is dropped.
        let _ = std::fs::remove_file(&path);
        Ok(Spill {
            out: BufWriter::with_capacity(1 << 16, f),
            len: 0,
        })
    }

    /// Appends one record.
    pub fn push(&mut self, rec: [f64; N]) -> std::io::Result<()> {
        for x in rec {
            self.out.write_all(&x.to_le_bytes())?;
        }
        self.len += 1;
        Ok(())
    }

    /// How many records there are.
    pub fn len(&self) -> usize {
        self.len
    }

    /// Calls `f` with every record, in the order they were pushed.
    pub fn for_each(&mut self, mut f: impl FnMut([f64; N])) -> std::io::Result<()> {
        self.out.flush()?;
        let mut recs = Records::<N>::new(self.out.get_ref(), self.len);
        for r in &mut recs {
            f(r);
        }
        recs.err.map_or(Ok(()), Err)
    }

    /// The list, complete: read-only from now on, and readable through a shared
    /// reference (by several readers at once).
    pub fn finish(mut self) -> std::io::Result<Spilled<N>> {
        self.out.flush()?;
        let len = self.len;
        let file = self.out.into_inner().map_err(|e| e.into_error())?;
        Ok(Spilled { file, len })
    }
}

/// A complete [`Spill`].
#[derive(Debug)]
pub struct Spilled<const N: usize> {
    file: File,
    len: usize,
}

impl<const N: usize> Spilled<N> {
    /// How many records there are.
    pub fn len(&self) -> usize {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The records in order. A read that fails ends them early: [`Records::failed`]
    /// says so.
    pub fn records(&self) -> Records<'_, N> {
        Records::new(&self.file, self.len)
    }
}

/// The records of a spill file, read a block at a time at their own offset (readers of
/// the same file do not disturb each other).
pub struct Records<'a, const N: usize> {
    file: &'a File,
    /// Records not yet read from the file.
    left: usize,
    at: u64,
    buf: Vec<u8>,
    pos: usize,
    err: Option<std::io::Error>,
}

impl<'a, const N: usize> Records<'a, N> {
    /// Records per read.
    const BLOCK: usize = 4096;

    fn new(file: &'a File, len: usize) -> Self {
        Records {
            file,
            left: len,
            at: 0,
            buf: Vec::new(),
            pos: 0,
            err: None,
        }
    }

    /// Why the records ended early, if they did.
    pub fn failed(&self) -> Option<&std::io::Error> {
        self.err.as_ref()
    }
}

impl<const N: usize> Iterator for Records<'_, N> {
    type Item = [f64; N];

    fn next(&mut self) -> Option<[f64; N]> {
        if self.pos == self.buf.len() {
            if self.left == 0 || self.err.is_some() {
                return None;
            }
            let n = self.left.min(Self::BLOCK);
            self.buf.resize(8 * N * n, 0);
            if let Err(e) = self.file.read_exact_at(&mut self.buf, self.at) {
                self.err = Some(e);
                self.buf.clear();
                self.pos = 0;
                return None;
            }
            self.at += self.buf.len() as u64;
            self.left -= n;
            self.pos = 0;
        }
        let mut rec = [0.0; N];
        for (x, b) in rec
            .iter_mut()
            .zip(self.buf[self.pos..self.pos + 8 * N].chunks_exact(8))
        {
            *x = f64::from_le_bytes(b.try_into().expect("8 bytes"));
        }
        self.pos += 8 * N;
        Some(rec)
    }
}

#[cfg(test)]
mod tests {
    use super::Spill;

    #[test]
    fn records_come_back_in_order_every_pass() {
        let mut s = Spill::<2>::new().unwrap();
        for i in 0..100_000 {
            s.push([i as f64, -(i as f64) * 0.5]).unwrap();
        }
        for _ in 0..2 {
            let mut n = 0;
            s.for_each(|r| {
                assert_eq!(r, [n as f64, -(n as f64) * 0.5]);
                n += 1;
            })
            .unwrap();
            assert_eq!(n, 100_000);
        }
        s.push([7.0, 8.0]).unwrap();
        let mut last = [0.0; 2];
        s.for_each(|r| last = r).unwrap();
        assert_eq!((s.len(), last), (100_001, [7.0, 8.0]));
        // Finished, two readers side by side.
        let done = s.finish().unwrap();
        let pairs = done.records().zip(done.records().skip(1)).count();
        assert_eq!(pairs, 100_000);
        assert!(done.records().zip(done.records()).all(|(a, b)| a == b));
        assert_eq!(done.records().last(), Some([7.0, 8.0]));
    }
}
