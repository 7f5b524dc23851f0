//! A program file read by mapping it into memory (`cnc check`): the text is the kernel's
//! own cached copy of the file, not copied into a buffer of ours.
//!
//! Read into a buffer, a long program costs twice: the buffer's pages are zeroed when
//! first touched, then the file is copied over them (`read`). On 200 000 lines of CAM
//! output (5.7 MB) that was about a twentieth of `cnc check`'s time. Mapped, the file's
//! pages are only entered into the process's page table, all at once
//! (`MAP_POPULATE`) for a file of up to 64 MiB. A longer one is read page by page, and
//! the pages read are given back as the reading goes ([`MappedText::release`]): a
//! program of ten million lines is never resident whole.
//!
//! The text must be UTF-8 and must not change while it is read, as for any program read:
//! a file that is not UTF-8, not a regular file or empty is not mapped, and the caller
//! reads it the usual way ([`crate::process::Source::load`]). A file truncated by
//! another program while it is being checked ends the check with `SIGBUS`.

use std::path::Path;

/// Files up to this size are mapped whole at once (`MAP_POPULATE`); longer ones page by
/// page as they are read, and given back behind ([`MappedText::release`]).
const POPULATE_MAX_BYTES: usize = 64 << 20;

/// How much of a file is checked for UTF-8 at a time.
const VALIDATE_STRETCH: usize = 4 << 20;

/// A whole file mapped read-only, valid UTF-8.
pub struct MappedText {
    ptr: *const u8,
    len: usize,
}

impl MappedText {
    /// The file at `path` mapped, or `None` where it cannot be (see the page above).
    #[cfg(unix)]
    pub fn open(path: &Path) -> Option<MappedText> {
        use std::os::fd::AsRawFd;
        // Looked at before it is opened: a named pipe opened here and closed again
        // would lose its writer, and the caller's own open would then wait for ever.
        if !std::fs::metadata(path).is_ok_and(|m| m.is_file()) {
            return None;
        }
        let file = std::fs::File::open(path).ok()?;
        let meta = file.metadata().ok()?;
        let len = usize::try_from(meta.len()).ok()?;
        if !meta.is_file() || len == 0 {
            return None;
        }
        // SAFETY: a new private read-only mapping of the whole of an open file; the
        // kernel picks its address. On failure nothing is mapped.
        let ptr = unsafe {
            libc::mmap(
                std::ptr::null_mut(),
                len,
                libc::PROT_READ,
                libc::MAP_PRIVATE
                    | if len <= POPULATE_MAX_BYTES {
                        populate()
                    } else {
                        0
                    },
                file.as_raw_fd(),
                0,
            )
        };
        if ptr == libc::MAP_FAILED {
            return None;
        }
        let mapped = MappedText {
            ptr: ptr.cast::<u8>(),
            len,
        };
        // Validated once here; `as_str` relies on it. A stretch at a time, each given
        // back behind: a long file is never resident whole.
        let bytes = mapped.bytes();
        let mut at = 0;
        // Given back up to here (in 64 KiB, whole pages of every page size in use).
        let mut released = 0;
        while at < len {
            let end = (at + VALIDATE_STRETCH).min(len);
            match std::str::from_utf8(&bytes[at..end]) {
                Ok(_) => at = end,
                // A character cut by the stretch's end: from its start, with the next.
                Err(e) if e.error_len().is_none() && end < len => at += e.valid_up_to(),
                Err(_) => return None,
            }
            if len > POPULATE_MAX_BYTES {
                mapped.release(released, at);
                released = at & !0xffff;
            }
        }
        Some(mapped)
    }

    #[cfg(not(unix))]
    pub fn open(_path: &Path) -> Option<MappedText> {
        None
    }

    /// The text's [`crate::checked::digest`], a long file's pages given back behind as
    /// when it was opened.
    pub fn digest(&self) -> u64 {
        let long = self.len > POPULATE_MAX_BYTES;
        crate::checked::digest(self.bytes(), &mut |from, to| {
            if long {
                self.release(from, to);
            }
        })
    }

    fn bytes(&self) -> &[u8] {
        // SAFETY: `len` readable bytes at `ptr`, mapped for as long as `self` lives.
        unsafe { std::slice::from_raw_parts(self.ptr, self.len) }
    }

    /// The file's text.
    pub fn as_str(&self) -> &str {
        // SAFETY: checked to be UTF-8 by `open`, and read-only to this process.
        unsafe { std::str::from_utf8_unchecked(self.bytes()) }
    }
}

// SAFETY: the mapping is read-only and private and nothing writes it; `release` only
// lets pages go, which come back unchanged when next read, from any thread.
unsafe impl Send for MappedText {}
unsafe impl Sync for MappedText {}

impl MappedText {
    /// Lets the kernel take back the pages of bytes `from..to` of the text (whole
    /// pages within them) from this process's memory: they stay the file's, and are
    /// read again from the kernel's cache if touched again. A long program read in
    /// windows is then never resident whole, whatever its size.
    #[cfg(unix)]
    pub fn release(&self, from: usize, to: usize) {
        // SAFETY: `sysconf` has no preconditions.
        let page = usize::try_from(unsafe { libc::sysconf(libc::_SC_PAGESIZE) }).unwrap_or(4096);
        let start = from.div_ceil(page) * page;
        let end = if to >= self.len {
            self.len
        } else {
            to / page * page
        };
        if end <= start {
            return;
        }
        // SAFETY: a range of whole pages within the mapping `open` made (page-aligned,
        // as the mapping's start is). The mapping is private, read-only and never
        // written: the pages come back as the file's bytes, unchanged, when next read.
        unsafe {
            libc::madvise(
                self.ptr.add(start) as *mut libc::c_void,
                end - start,
                libc::MADV_DONTNEED,
            );
        }
    }

    #[cfg(not(unix))]
    pub fn release(&self, _from: usize, _to: usize) {}
}

#[cfg(unix)]
impl Drop for MappedText {
    fn drop(&mut self) {
        // SAFETY: the mapping `open` made, unmapped once; no reference into it outlives
        // `self` (`as_str` borrows it).
        unsafe {
            libc::munmap(self.ptr as *mut libc::c_void, self.len);
        }
    }
}

/// Map every page at once rather than at its first touch, where the kernel can.
#[cfg(target_os = "linux")]
fn populate() -> libc::c_int {
    libc::MAP_POPULATE
}

#[cfg(all(unix, not(target_os = "linux")))]
fn populate() -> libc::c_int {
    0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn maps_what_read_reads() {
        let dir = std::env::temp_dir().join(format!("cnc-mapped-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let text = "G1 X1 Y2 (é)\nM2\n";
        let file = dir.join("p.ngc");
        std::fs::write(&file, text).unwrap();
        let m = MappedText::open(&file).unwrap();
        assert_eq!(m.as_str(), text);
        // Released, the pages are read again from the file.
        m.release(0, text.len());
        assert_eq!(m.as_str(), text);
        drop(m);
        // Not UTF-8, empty, a directory, missing: read the usual way.
        std::fs::write(&file, b"G1 X1 \xff\n").unwrap();
        assert!(MappedText::open(&file).is_none());
        std::fs::write(&file, b"").unwrap();
        assert!(MappedText::open(&file).is_none());
        assert!(MappedText::open(&dir).is_none());
        assert!(MappedText::open(&dir.join("missing.ngc")).is_none());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
