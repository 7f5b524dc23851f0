//! A counting global allocator for the tests that prove a piece of code never allocates
//! (the real-time cycle, the evaluators). It counts only on threads that have armed it,
//! so the test harness and helper threads (a trace writer) allocate freely beside it.
//!
//! ```ignore
//! #[global_allocator]
//! static GLOBAL: shared::alloc_count::Counting = shared::alloc_count::Counting;
//!
//! shared::alloc_count::arm(true);
//! work();
//! shared::alloc_count::arm(false);
//! assert_eq!(shared::alloc_count::count(), 0);
//! ```

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicU64, Ordering};

/// The system allocator, counting allocations, reallocations and frees made on armed
/// threads.
pub struct Counting;

static EVENTS: AtomicU64 = AtomicU64::new(0);

thread_local! {
    static ARMED: Cell<bool> = const { Cell::new(false) };
}

fn note() {
    // `try_with`: during thread teardown the flag may be gone; that is not measured work.
    if ARMED.try_with(|a| a.get()).unwrap_or(false) {
        EVENTS.fetch_add(1, Ordering::Relaxed);
    }
}

// SAFETY: every call is passed unchanged to the system allocator.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        note();
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        note();
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        note();
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

/// Starts (`true`) or stops counting on the calling thread.
pub fn arm(on: bool) {
    ARMED.with(|a| a.set(on));
}

/// Allocator calls counted so far on armed threads, since the process started.
pub fn count() -> u64 {
    EVENTS.load(Ordering::Relaxed)
}
