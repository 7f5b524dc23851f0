//! `commands.log`: every command block exactly as it was sent.
//!
//! Format (version 0, little-endian; a later issue hardens it with checksums):
//! * header: magic `b"CNCCMDv0"`, `u32` protocol version, `u32` block size in bytes;
//! * then one record per block: the block's bytes, exactly as written into shared memory.

use crate::protocol::{CommandBlock, PROTOCOL_VERSION};
use std::fs::File;
use std::io::{BufWriter, Read, Write};
use std::path::Path;

pub const MAGIC: &[u8; 8] = b"CNCCMDv0";
const BLOCK_SIZE: usize = core::mem::size_of::<CommandBlock>();

fn bytes(b: &CommandBlock) -> &[u8] {
    // SAFETY: CommandBlock is `repr(C)`, `Copy`, made only of u32/i32/u64/f64 fields laid
    // out without padding (checked by `no_padding` below); viewing it as bytes is sound.
    unsafe { core::slice::from_raw_parts((b as *const CommandBlock).cast::<u8>(), BLOCK_SIZE) }
}

pub struct CommandLog {
    out: BufWriter<File>,
}

impl CommandLog {
    pub fn create(path: &Path) -> std::io::Result<Self> {
        let mut out = BufWriter::new(File::create(path)?);
        out.write_all(MAGIC)?;
        out.write_all(&PROTOCOL_VERSION.to_le_bytes())?;
        out.write_all(&(BLOCK_SIZE as u32).to_le_bytes())?;
        Ok(CommandLog { out })
    }

    pub fn append(&mut self, b: &CommandBlock) -> std::io::Result<()> {
        self.out.write_all(bytes(b))
    }

    /// Flushes and syncs to disk.
    pub fn finish(mut self) -> std::io::Result<()> {
        self.out.flush()?;
        self.out.get_ref().sync_all()
    }
}

/// Reads a log back; every block is validated as a receiver would.
pub fn read(path: &Path) -> Result<Vec<CommandBlock>, String> {
    let mut data = Vec::new();
    File::open(path)
        .and_then(|mut f| f.read_to_end(&mut data))
        .map_err(|e| format!("{}: {e}", path.display()))?;
    if data.len() < 16 || &data[..8] != MAGIC {
        return Err(format!("{}: not a command log (bad magic)", path.display()));
    }
    let size = u32::from_le_bytes([data[12], data[13], data[14], data[15]]) as usize;
    if size != BLOCK_SIZE {
        return Err(format!(
            "{}: block size {size}, this build uses {BLOCK_SIZE}",
            path.display()
        ));
    }
    let body = &data[16..];
    if body.len() % BLOCK_SIZE != 0 {
        return Err(format!(
            "{}: truncated record at byte {}",
            path.display(),
            16 + body.len() / BLOCK_SIZE * BLOCK_SIZE
        ));
    }
    let mut out = Vec::with_capacity(body.len() / BLOCK_SIZE);
    for (i, chunk) in body.chunks_exact(BLOCK_SIZE).enumerate() {
        // SAFETY: every bit pattern is a valid CommandBlock (integers and floats only);
        // read_unaligned because the buffer has no alignment guarantee.
        let b: CommandBlock = unsafe { core::ptr::read_unaligned(chunk.as_ptr().cast()) };
        b.validate()
            .map_err(|e| format!("{}: record {i}: {e}", path.display()))?;
        out.push(b);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::protocol::{BlockKind, Helix};

    #[test]
    fn no_padding() {
        // Sum of the field sizes equals the struct size: no uninitialised padding bytes.
        let fields = 4
            + 4
            + 8
            + 4
            + 4
            + 4
            + 4
            + 8 * 4
            + 8
            + core::mem::size_of::<Helix>()
            + 8 * crate::nurbs::MAX_KNOTS
            + 32 * crate::nurbs::MAX_CTRL;
        assert_eq!(fields, BLOCK_SIZE);
        assert_eq!(core::mem::size_of::<Helix>(), 4 + 4 + 24 + 8 * 3);
    }

    #[test]
    fn round_trip() {
        let dir = std::env::temp_dir().join(format!("cnc-log-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("commands.log");
        let mut log = CommandLog::create(&p).unwrap();
        let mut b = CommandBlock::empty(BlockKind::Dwell, 0, 3);
        b.dwell_ns = 5;
        log.append(&b).unwrap();
        log.append(&CommandBlock::empty(BlockKind::ProgramEnd, 1, 4))
            .unwrap();
        log.finish().unwrap();
        let back = read(&p).unwrap();
        assert_eq!(back.len(), 2);
        assert_eq!(back[0].dwell_ns, 5);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
