//! Memory for the long lists a check fills once: a move and a block for every line of a
//! program, 10 MB each for 100 000 lines of CAM output.
//!
//! The kernel hands such a list over 4 KiB at a time, on first touch, each page a fault
//! (charged, zeroed, mapped): for `cnc check` on a long program, about as much time as
//! reading and planning it. A list that asks for transparent huge pages gets 2 MiB at a
//! fault instead, where the kernel allows them (`/sys/kernel/mm/transparent_hugepage`
//! set to `madvise` or `always`); elsewhere the advice is ignored and nothing changes.
//! Only whole 2 MiB pages inside the list's allocation are advised, so a small list, or
//! the ends of a large one, stay as they are. Where the kernel's `defrag` setting is
//! `madvise` (as on the development VM), such a fault may compact memory to find a huge
//! page, or fall back to small ones: a possible pause of the interpreter, never of the
//! interpolator's cycle, which is another process and holds none of these lists.

/// The size of a transparent huge page on x86-64 and most arm64 kernels.
const HUGE_PAGE: usize = 2 << 20;

/// Asks the kernel to back the whole huge pages inside `v`'s allocation (its capacity,
/// used or not) with huge pages. Call it once the capacity is reserved, before the list
/// is filled: pages already touched stay small until the kernel collapses them.
pub(crate) fn prefer_huge_pages<T>(v: &Vec<T>) {
    let bytes = v.capacity().saturating_mul(std::mem::size_of::<T>());
    let start = v.as_ptr() as usize;
    let begin = start.div_ceil(HUGE_PAGE) * HUGE_PAGE;
    let end = start.saturating_add(bytes) / HUGE_PAGE * HUGE_PAGE;
    if end > begin {
        advise(begin, end - begin);
    }
}

#[cfg(target_os = "linux")]
fn advise(begin: usize, len: usize) {
    // SAFETY: advice about whole pages that lie inside one allocation of ours; it
    // changes how the kernel backs them, never their contents, and a refusal (a kernel
    // without transparent huge pages) leaves them as they were, so its result is ignored.
    unsafe {
        libc::madvise(begin as *mut libc::c_void, len, libc::MADV_HUGEPAGE);
    }
}

#[cfg(not(target_os = "linux"))]
fn advise(_begin: usize, _len: usize) {}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn advised_lists_keep_their_contents() {
        let mut v: Vec<u64> = Vec::with_capacity(3 * HUGE_PAGE / 8);
        prefer_huge_pages(&v);
        v.extend(0..v.capacity() as u64);
        assert!(v.iter().enumerate().all(|(i, x)| *x == i as u64));
        // Small and empty lists: nothing to advise.
        let small: Vec<u8> = vec![1; 100];
        prefer_huge_pages(&small);
        prefer_huge_pages(&Vec::<u8>::new());
        assert_eq!(small, vec![1; 100]);
    }
}
