//! A list of fixed-size records of `f64`s kept in a temporary file rather than in memory
//! (the points of a circle run of a long run are millions), read back in order as often
//! as needed. The file is removed as soon as it is made: it lives as long as the
//! [`Spill`] and never outlives the process.

use std::fs::File;
use std::io::{BufReader, BufWriter, Read, Seek, SeekFrom, Write};

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
        let mut file = self.out.get_ref().try_clone()?;
        file.seek(SeekFrom::Start(0))?;
        let mut input = BufReader::with_capacity(1 << 16, file);
        let mut buf = vec![0u8; 8 * N];
        for _ in 0..self.len {
            input.read_exact(&mut buf)?;
            let mut rec = [0.0; N];
            for (x, b) in rec.iter_mut().zip(buf.chunks_exact(8)) {
                *x = f64::from_le_bytes(b.try_into().expect("8 bytes"));
            }
            f(rec);
        }
        // The next push goes at the end (the clone shares the file offset).
        self.out.get_mut().seek(SeekFrom::End(0))?;
        Ok(())
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
    }
}
