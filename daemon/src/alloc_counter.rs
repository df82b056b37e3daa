//! A counting global allocator for the `danced` binary (and tests): counts allocations made
//! while the current thread is inside a real-time callback ([`in_callback`]), so the live stats
//! can prove the audio path allocates nothing.
//!
//! Install it with `#[global_allocator] static A: CountingAllocator = CountingAllocator;`.
//! Without it installed, [`callback_allocations`] stays 0 and [`is_installed`] is false.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

static CALLBACK_ALLOCATIONS: AtomicU64 = AtomicU64::new(0);
static INSTALLED: AtomicBool = AtomicBool::new(false);

thread_local! {
    // `const` init: no lazy allocation the first time the flag is touched inside a callback.
    static IN_CALLBACK: Cell<bool> = const { Cell::new(false) };
}

/// The system allocator, counting calls made inside [`in_callback`].
pub struct CountingAllocator;

unsafe impl GlobalAlloc for CountingAllocator {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        count();
        unsafe { System.alloc(layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        count();
        unsafe { System.alloc_zeroed(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        count();
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        count();
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[inline]
fn count() {
    // try_with: during thread teardown the TLS slot may be gone; those frees are not ours.
    if IN_CALLBACK.try_with(Cell::get).unwrap_or(false) {
        CALLBACK_ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
    }
}

/// Runs `f` as real-time callback code: every allocation (or free) it makes is counted.
#[inline]
pub fn in_callback<R>(f: impl FnOnce() -> R) -> R {
    let _ = IN_CALLBACK.try_with(|c| c.set(true));
    let r = f();
    let _ = IN_CALLBACK.try_with(|c| c.set(false));
    r
}

/// Allocations (and frees) counted inside callbacks since the process started.
pub fn callback_allocations() -> u64 {
    CALLBACK_ALLOCATIONS.load(Ordering::Relaxed)
}

/// Declares that the counting allocator is the global allocator (call once from `main`).
pub fn mark_installed() {
    INSTALLED.store(true, Ordering::Relaxed);
}

/// Whether [`mark_installed`] was called, i.e. whether [`callback_allocations`] means anything.
pub fn is_installed() -> bool {
    INSTALLED.load(Ordering::Relaxed)
}
