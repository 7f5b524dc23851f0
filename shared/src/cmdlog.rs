//! `commands.log`: every command block exactly as it was sent, for replay and inspection.
//!
//! # Format (version 1, all integers little-endian)
//!
//! Header:
//!
//! | bytes | field |
//! | --- | --- |
//! | 8 | magic `b"CNCLOG\r\n"` (the CR LF catches text-mode mangling) |
//! | 4 | format version (`u32`, this is 1) |
//! | 4 | protocol version of the blocks (`u32`, [`PROTOCOL_VERSION`]) |
//! | 4 | block size in bytes (`u32`, `size_of::<CommandBlock>()`) |
//! | 8 | interpolation period in ns (`u64`) |
//! | 8 | machine hash (`u64`): FNV-1a 64 of the machine file's canonical TOML |
//! | 2 | length `n` of the program name (`u16`, at most 1024) |
//! | n | program name, UTF-8 |
//! | 4 | CRC-32C of all header bytes before it |
//!
//! Then one record per block, in sending order:
//!
//! | bytes | field |
//! | --- | --- |
//! | 4 | payload length `m` (`u32`, equal to the block size) |
//! | 4 | CRC-32C of the payload |
//! | m | the block's bytes, exactly as written into shared memory |
//!
//! The interpreter appends a record as each block is delivered, handing it to the kernel
//! at once (so a killed interpreter loses nothing it sent), and syncs at the end. A reader stops at the first record that is truncated, has a wrong length
//! or checksum, or holds a block that fails validation, and names its record number and
//! byte offset; everything before it is intact and can be salvaged.

use crate::protocol::{BlockKind, CommandBlock, PROTOCOL_VERSION};
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;

pub const MAGIC: &[u8; 8] = b"CNCLOG\r\n";
pub const FORMAT_VERSION: u32 = 1;
const BLOCK_SIZE: usize = core::mem::size_of::<CommandBlock>();
const MAX_NAME: usize = 1024;

/// CRC-32C (Castagnoli, reflected polynomial 0x82F63B78), bytewise with a table.
pub fn crc32c(data: &[u8]) -> u32 {
    const TABLE: [u32; 256] = {
        let mut t = [0u32; 256];
        let mut i = 0;
        while i < 256 {
            let mut c = i as u32;
            let mut k = 0;
            while k < 8 {
                c = if c & 1 != 0 {
                    (c >> 1) ^ 0x82F6_3B78
                } else {
                    c >> 1
                };
                k += 1;
            }
            t[i] = c;
            i += 1;
        }
        t
    };
    let mut crc = !0u32;
    for &b in data {
        crc = TABLE[((crc ^ b as u32) & 0xff) as usize] ^ (crc >> 8);
    }
    !crc
}

/// FNV-1a, 64 bit: the machine file's fingerprint in the header.
pub fn fnv1a64(data: &[u8]) -> u64 {
    data.iter().fold(0xcbf2_9ce4_8422_2325u64, |h, &b| {
        (h ^ b as u64).wrapping_mul(0x0100_0000_01b3)
    })
}

fn bytes(b: &CommandBlock) -> &[u8] {
    // SAFETY: CommandBlock is `repr(C)`, `Copy`, made only of u32/i32/u64/f64 fields laid
    // out without padding (checked by `no_padding` below); viewing it as bytes is sound.
    unsafe { core::slice::from_raw_parts((b as *const CommandBlock).cast::<u8>(), BLOCK_SIZE) }
}

/// Whether two blocks are the same bit for bit (every field, NaNs and signed zeros
/// included): what a log records of each.
pub fn same_bits(a: &CommandBlock, b: &CommandBlock) -> bool {
    bytes(a) == bytes(b)
}

/// What the header says about the run that wrote the log.
#[derive(Debug, Clone, PartialEq)]
pub struct Header {
    pub format_version: u32,
    pub protocol_version: u32,
    pub period_ns: u64,
    pub machine_hash: u64,
    pub program: String,
}

pub struct CommandLog {
    out: BufWriter<File>,
    /// Blocks appended so far.
    blocks: u64,
}

impl CommandLog {
    /// Creates the log and writes its header.
    pub fn create(
        path: &Path,
        period_ns: u64,
        machine_hash: u64,
        program: &str,
    ) -> std::io::Result<Self> {
        let mut out = BufWriter::new(File::create(path)?);
        let name = truncate_utf8(program, MAX_NAME);
        let mut h = Vec::with_capacity(40 + name.len());
        h.extend_from_slice(MAGIC);
        h.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
        h.extend_from_slice(&PROTOCOL_VERSION.to_le_bytes());
        h.extend_from_slice(&(BLOCK_SIZE as u32).to_le_bytes());
        h.extend_from_slice(&period_ns.to_le_bytes());
        h.extend_from_slice(&machine_hash.to_le_bytes());
        h.extend_from_slice(&(name.len() as u16).to_le_bytes());
        h.extend_from_slice(name.as_bytes());
        let crc = crc32c(&h);
        h.extend_from_slice(&crc.to_le_bytes());
        out.write_all(&h)?;
        out.flush()?;
        Ok(CommandLog { out, blocks: 0 })
    }

    pub fn append(&mut self, b: &CommandBlock) -> std::io::Result<()> {
        let payload = bytes(b);
        self.out.write_all(&(BLOCK_SIZE as u32).to_le_bytes())?;
        self.out.write_all(&crc32c(payload).to_le_bytes())?;
        self.out.write_all(payload)?;
        // Handed to the kernel at once: a killed interpreter loses no block it sent.
        self.out.flush()?;
        self.blocks += 1;
        Ok(())
    }

    /// How many blocks have been appended (each block is appended as it is sent, so this
    /// is the count sent, also when the sending ended in an error).
    pub fn blocks(&self) -> u64 {
        self.blocks
    }

    /// Flushes and syncs to disk.
    pub fn finish(mut self) -> std::io::Result<()> {
        self.out.flush()?;
        self.out.get_ref().sync_all()
    }
}

fn truncate_utf8(s: &str, max: usize) -> &str {
    let mut end = s.len().min(max);
    while !s.is_char_boundary(end) {
        end -= 1;
    }
    &s[..end]
}

/// Why a log (or part of it) cannot be used.
#[derive(Debug, Clone, PartialEq)]
pub enum LogError {
    /// The header itself is unusable: nothing can be replayed.
    Header { offset: u64, reason: String },
    /// Record `record` (0-based) at byte `offset` is bad; records before it are intact.
    Record {
        record: u64,
        offset: u64,
        reason: String,
    },
}

impl core::fmt::Display for LogError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            LogError::Header { offset, reason } => write!(f, "header, byte {offset}: {reason}"),
            LogError::Record {
                record,
                offset,
                reason,
            } => {
                write!(f, "record {record} at byte {offset}: {reason}")
            }
        }
    }
}

/// A log as read: its header, the intact blocks, and the first problem if there was one.
#[derive(Debug, Clone)]
pub struct Parsed {
    pub header: Header,
    pub blocks: Vec<CommandBlock>,
    /// `None` when every record was intact and the log ends with the program end.
    pub damage: Option<LogError>,
}

fn u32_at(d: &[u8], at: usize) -> Option<u32> {
    d.get(at..at + 4)
        .map(|s| u32::from_le_bytes([s[0], s[1], s[2], s[3]]))
}

fn u64_at(d: &[u8], at: usize) -> Option<u64> {
    d.get(at..at + 8).map(|s| {
        let mut b = [0u8; 8];
        b.copy_from_slice(s);
        u64::from_le_bytes(b)
    })
}

/// Parses a whole log held in memory. Never panics, whatever the bytes.
pub fn parse(data: &[u8]) -> Result<Parsed, LogError> {
    let hdr = |offset: usize, reason: &str| LogError::Header {
        offset: offset as u64,
        reason: reason.into(),
    };
    if data.get(..8) != Some(MAGIC.as_slice()) {
        return Err(hdr(0, "not a command log (bad magic)"));
    }
    let format_version = u32_at(data, 8).ok_or_else(|| hdr(8, "truncated"))?;
    if format_version != FORMAT_VERSION {
        return Err(hdr(
            8,
            &format!("format version {format_version}, this build reads {FORMAT_VERSION}"),
        ));
    }
    let protocol_version = u32_at(data, 12).ok_or_else(|| hdr(12, "truncated"))?;
    if protocol_version != PROTOCOL_VERSION {
        return Err(hdr(
            12,
            &format!("protocol version {protocol_version}, this build speaks {PROTOCOL_VERSION}"),
        ));
    }
    let size = u32_at(data, 16).ok_or_else(|| hdr(16, "truncated"))? as usize;
    if size != BLOCK_SIZE {
        return Err(hdr(
            16,
            &format!("block size {size}, this build uses {BLOCK_SIZE}"),
        ));
    }
    let period_ns = u64_at(data, 20).ok_or_else(|| hdr(20, "truncated"))?;
    let machine_hash = u64_at(data, 28).ok_or_else(|| hdr(28, "truncated"))?;
    let name_len = data
        .get(36..38)
        .map(|s| u16::from_le_bytes([s[0], s[1]]) as usize)
        .ok_or_else(|| hdr(36, "truncated"))?;
    if name_len > MAX_NAME {
        return Err(hdr(36, "program name longer than 1024 bytes"));
    }
    let name_end = 38 + name_len;
    let name = data.get(38..name_end).ok_or_else(|| hdr(38, "truncated"))?;
    let crc = u32_at(data, name_end).ok_or_else(|| hdr(name_end, "truncated"))?;
    if crc != crc32c(&data[..name_end]) {
        return Err(hdr(name_end, "header checksum mismatch"));
    }
    if period_ns == 0 {
        return Err(hdr(20, "period of 0 ns"));
    }
    let header = Header {
        format_version,
        protocol_version,
        period_ns,
        machine_hash,
        program: String::from_utf8_lossy(name).into_owned(),
    };
    let mut blocks = Vec::new();
    let mut at = name_end + 4;
    let mut damage = None;
    while at < data.len() {
        let record = blocks.len() as u64;
        let bad = |reason: String| LogError::Record {
            record,
            offset: at as u64,
            reason,
        };
        let (Some(len), Some(crc)) = (u32_at(data, at), u32_at(data, at + 4)) else {
            damage = Some(bad("truncated record header".into()));
            break;
        };
        if len as usize != BLOCK_SIZE {
            damage = Some(bad(format!("record length {len}, expected {BLOCK_SIZE}")));
            break;
        }
        let Some(payload) = data.get(at + 8..at + 8 + BLOCK_SIZE) else {
            damage = Some(bad(format!(
                "truncated: {} of {BLOCK_SIZE} bytes",
                data.len() - (at + 8).min(data.len())
            )));
            break;
        };
        if crc32c(payload) != crc {
            damage = Some(bad("checksum mismatch".into()));
            break;
        }
        // SAFETY: every bit pattern is a valid CommandBlock (integers and floats only);
        // read_unaligned because the buffer has no alignment guarantee.
        let b: CommandBlock = unsafe { core::ptr::read_unaligned(payload.as_ptr().cast()) };
        if let Err(e) = b.validate() {
            damage = Some(bad(e.to_string()));
            break;
        }
        if b.seq != record {
            damage = Some(bad(format!(
                "sequence number {} where {record} was due",
                b.seq
            )));
            break;
        }
        blocks.push(b);
        at += 8 + BLOCK_SIZE;
    }
    let ended = blocks
        .last()
        .is_some_and(|b| b.kind == BlockKind::ProgramEnd as u32);
    if damage.is_none() && !ended {
        damage = Some(LogError::Record {
            record: blocks.len() as u64,
            offset: at as u64,
            reason: "the log ends before the program end block (the run was cut short)".into(),
        });
    }
    Ok(Parsed {
        header,
        blocks,
        damage,
    })
}

/// Reads a log file; see [`parse`].
pub fn read(path: &Path) -> Result<Parsed, String> {
    let data = std::fs::read(path).map_err(|e| format!("{}: {e}", path.display()))?;
    parse(&data).map_err(|e| format!("{}: {e}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::protocol::Helix;
    use proptest::prelude::*;

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
            + 8 * 2
            + 8
            + core::mem::size_of::<Helix>()
            + 8 * crate::nurbs::MAX_KNOTS
            + 32 * crate::nurbs::MAX_CTRL
            + core::mem::size_of::<crate::protocol::SurfacePass>();
        assert_eq!(fields, BLOCK_SIZE);
        assert_eq!(
            core::mem::size_of::<crate::protocol::SurfacePass>(),
            4 + 4 + 16 + 16 + 8 + 8 + 32
        );
        assert_eq!(core::mem::size_of::<Helix>(), 4 + 4 + 24 + 8 * 3);
    }

    #[test]
    fn crc32c_check_value() {
        // The standard check value of CRC-32C.
        assert_eq!(crc32c(b"123456789"), 0xE306_9283);
    }

    fn sample_log() -> Vec<u8> {
        let dir = std::env::temp_dir().join(format!(
            "cnc-log-{}-{:?}",
            std::process::id(),
            std::thread::current().id()
        ));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("commands.log");
        let mut log = CommandLog::create(&p, 1_000_000, 42, "part.ngc").unwrap();
        let mut b = CommandBlock::empty(BlockKind::Dwell, 0, 3);
        b.dwell_ns = 5;
        log.append(&b).unwrap();
        log.append(&CommandBlock::empty(BlockKind::ProgramEnd, 1, 4))
            .unwrap();
        log.finish().unwrap();
        let data = std::fs::read(&p).unwrap();
        std::fs::remove_dir_all(&dir).unwrap();
        data
    }

    #[test]
    fn round_trip() {
        let back = parse(&sample_log()).unwrap();
        assert_eq!(back.header.program, "part.ngc");
        assert_eq!(back.header.period_ns, 1_000_000);
        assert_eq!(back.header.machine_hash, 42);
        assert_eq!(back.blocks.len(), 2);
        assert_eq!(back.blocks[0].dwell_ns, 5);
        assert!(back.damage.is_none());
    }

    #[test]
    fn damage_names_record_and_offset() {
        let data = sample_log();
        let header_len = 38 + "part.ngc".len() + 4;
        let rec = 8 + BLOCK_SIZE;
        // Flip a byte inside the second record's payload.
        let mut bad = data.clone();
        bad[header_len + rec + 8 + 20] ^= 0x40;
        let p = parse(&bad).unwrap();
        assert_eq!(p.blocks.len(), 1);
        assert_eq!(
            p.damage,
            Some(LogError::Record {
                record: 1,
                offset: (header_len + rec) as u64,
                reason: "checksum mismatch".into()
            })
        );
        // Cut in the middle of the first record.
        let p = parse(&data[..header_len + 100]).unwrap();
        assert!(p.blocks.is_empty());
        assert!(
            matches!(p.damage, Some(LogError::Record { record: 0, offset, .. }) if offset == header_len as u64)
        );
        // A broken header is refused outright.
        let mut bad = data.clone();
        bad[24] ^= 1;
        assert!(matches!(parse(&bad), Err(LogError::Header { .. })));
    }

    proptest! {
        #[test]
        fn random_bytes_never_panic(data in proptest::collection::vec(any::<u8>(), 0..4096)) {
            let _ = parse(&data);
        }

        #[test]
        fn mutated_logs_never_panic(pos in 0usize..4000, byte in any::<u8>(), cut in 0usize..4000) {
            let mut data = sample_log();
            let n = data.len();
            data[pos % n] = byte;
            data.truncate(cut.max(1) % (n + 1));
            if let Ok(p) = parse(&data) {
                prop_assert!(p.blocks.iter().all(|b| b.validate().is_ok()));
            }
        }
    }
}
