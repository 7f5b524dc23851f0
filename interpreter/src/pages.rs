//! Memory for the long lists a check fills once: a move and a block for every line of a
//! program, 10 MB each for 100 000 lines of CAM output, and the program's lines.
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
//!
//! What is left in small pages (the ends of a list, all of a list where huge pages are
//! not to be had) is mapped at once, in one call (`MADV_POPULATE_WRITE`, Linux 5.14):
//! the same zeroed pages the first touch of each would fault in, without a fault each
//! (on `plain_g1`, 2 680 faults for the `cnc check` process, 1 000 of them these lists,
//! about a tenth of its time). A list's whole capacity is mapped so, used or not: these
//! lists are sized to what they will hold (the move list at a move a line, which
//! programs of CAM output about fill). Older kernels refuse the call and nothing
//! changes.

/// The size of a transparent huge page on x86-64 and most arm64 kernels.
const HUGE_PAGE: usize = 2 << 20;

/// The size of a page.
const PAGE: usize = 4096;

/// Asks the kernel to back the whole huge pages inside `v`'s allocation (its capacity,
/// used or not) with huge pages, and maps its whole small pages around them at once.
/// Call it once the capacity is reserved, before the list is filled: pages already
/// touched stay small until the kernel collapses them.
pub(crate) fn prefer_huge_pages<T>(v: &Vec<T>) {
    let bytes = v.capacity().saturating_mul(std::mem::size_of::<T>());
    let start = v.as_ptr() as usize;
    let whole = |size: usize| {
        let begin = start.div_ceil(size) * size;
        let end = start.saturating_add(bytes) / size * size;
        (end > begin).then(|| (begin, end - begin))
    };
    let Some((first, len)) = whole(PAGE) else {
        return;
    };
    let last = first + len;
    // The huge pages fault in 2 MiB at a time by themselves: only the small pages
    // around them are mapped at once (mapping again what a list reused from the
    // allocator already has costs a walk over its pages).
    let (huge_begin, huge_end) = match whole(HUGE_PAGE) {
        Some((begin, len)) => {
            advise(begin, len, MADV_HUGEPAGE);
            (begin, begin + len)
        }
        None => (last, last),
    };
    if huge_begin > first {
        advise(first, huge_begin - first, MADV_POPULATE_WRITE);
    }
    if last > huge_end {
        advise(huge_end, last - huge_end, MADV_POPULATE_WRITE);
    }
}

/// A list of `n` copies of `value` in memory as [`prefer_huge_pages`] leaves it.
pub(crate) fn filled<T: Clone>(n: usize, value: T) -> Vec<T> {
    let mut v = Vec::with_capacity(n);
    prefer_huge_pages(&v);
    v.resize(n, value);
    v
}

#[cfg(target_os = "linux")]
use libc::{MADV_HUGEPAGE, MADV_POPULATE_WRITE};
#[cfg(not(target_os = "linux"))]
const MADV_HUGEPAGE: i32 = 0;
#[cfg(not(target_os = "linux"))]
const MADV_POPULATE_WRITE: i32 = 0;

#[cfg(target_os = "linux")]
fn advise(begin: usize, len: usize, advice: libc::c_int) {
    // SAFETY: advice about whole pages that lie inside one allocation of ours; it
    // changes how the kernel backs them (huge pages, or mapped now rather than at their
    // first touch), never their contents, and a refusal (a kernel without transparent
    // huge pages or too old to populate) leaves them as they were, so its result is
    // ignored.
    unsafe {
        libc::madvise(begin as *mut libc::c_void, len, advice);
    }
}

#[cfg(not(target_os = "linux"))]
fn advise(_begin: usize, _len: usize, _advice: i32) {}

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
        // Contents already there stay as they are.
        let mut w: Vec<u64> = Vec::with_capacity(HUGE_PAGE);
        w.extend(0..1000);
        prefer_huge_pages(&w);
        assert!(w.iter().enumerate().all(|(i, x)| *x == i as u64));
        assert_eq!(
            filled(3 * HUGE_PAGE / 8 + 5, 7u64),
            vec![7u64; 3 * HUGE_PAGE / 8 + 5]
        );
    }
}
