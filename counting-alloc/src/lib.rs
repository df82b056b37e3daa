//! The counting global allocator of the workspace, the one both the `danced` binary and every
//! allocation test install: it counts allocator calls (allocations, reallocations and frees)
//! made while the current thread runs real-time code, per real-time thread ([`RtThread`]), so
//! the live stats can prove every real-time loop allocates nothing; and per OS thread
//! ([`thread_allocations`], [`count_here`]), so a test measures its own thread undisturbed by
//! tests running beside it.
//!
//! Install it with `#[global_allocator] static A: CountingAllocator = CountingAllocator;`.
//! Without it installed, the counts stay 0 and [`is_installed`] is false.

#![warn(missing_docs)]

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

/// The real-time threads of the live pipeline, each counted on its own.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RtThread {
    /// The audio input: the cpal callback, or the replay thread's ring writes.
    Capture = 0,
    /// The analysis thread.
    Analysis = 1,
    /// The motion thread.
    Motion = 2,
    /// The sender thread.
    Sender = 3,
    /// The thread that sends MIDI clock, tick by tick.
    ClockOut = 4,
}

const NOT_COUNTED: u8 = u8::MAX;
static COUNTS: [AtomicU64; 5] = [const { AtomicU64::new(0) }; 5];
static INSTALLED: AtomicBool = AtomicBool::new(false);

thread_local! {
    // `const` init: no lazy allocation the first time the flag is touched on a real-time path.
    static COUNTING: Cell<u8> = const { Cell::new(NOT_COUNTED) };
    // This thread's counted calls, whatever its role.
    static THREAD_COUNT: Cell<u64> = const { Cell::new(0) };
}

/// The system allocator, counting calls made inside [`counted`] or under a [`CountGuard`].
pub struct CountingAllocator;

// SAFETY: every call is forwarded unchanged to the system allocator; counting only touches
// atomics and const-initialised thread-locals, which never allocate.
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
    let role = COUNTING.try_with(Cell::get).unwrap_or(NOT_COUNTED);
    if let Some(c) = COUNTS.get(usize::from(role)) {
        c.fetch_add(1, Ordering::Relaxed);
        let _ = THREAD_COUNT.try_with(|n| n.set(n.get() + 1));
    }
}

/// Runs `f` as real-time code of `thread`: every allocation (or free) it makes is counted.
#[inline]
pub fn counted<R>(thread: RtThread, f: impl FnOnce() -> R) -> R {
    let before = COUNTING.try_with(|c| c.replace(thread as u8)).ok();
    let r = f();
    if let Some(b) = before {
        let _ = COUNTING.try_with(|c| c.set(b));
    }
    r
}

/// Runs `f` as the audio callback's code (counted as [`RtThread::Capture`]).
#[inline]
pub fn in_callback<R>(f: impl FnOnce() -> R) -> R {
    counted(RtThread::Capture, f)
}

/// Runs `f` uncounted inside a counted loop: set-up that a loop redoes on rare events (a new
/// audio format rebuilds the analyzer), which is allowed to allocate.
#[inline]
pub fn uncounted<R>(f: impl FnOnce() -> R) -> R {
    let before = COUNTING.try_with(|c| c.replace(NOT_COUNTED)).ok();
    let r = f();
    if let Some(b) = before {
        let _ = COUNTING.try_with(|c| c.set(b));
    }
    r
}

/// Counts this thread's allocations as `thread`'s until dropped (a real-time loop's body).
pub struct CountGuard {
    before: u8,
}

impl CountGuard {
    /// Starts counting the current thread as `thread`.
    pub fn new(thread: RtThread) -> Self {
        let before = COUNTING
            .try_with(|c| c.replace(thread as u8))
            .unwrap_or(NOT_COUNTED);
        Self { before }
    }
}

impl Drop for CountGuard {
    fn drop(&mut self) {
        let _ = COUNTING.try_with(|c| c.set(self.before));
    }
}

/// Allocations (and frees) counted for `thread` since the process started.
pub fn allocations(thread: RtThread) -> u64 {
    COUNTS[thread as usize].load(Ordering::Relaxed)
}

/// Allocations (and frees) counted on the current thread since it started, whatever the role
/// it ran as.
pub fn thread_allocations() -> u64 {
    THREAD_COUNT.try_with(Cell::get).unwrap_or(0)
}

/// Runs `f` as real-time code of `thread` (see [`counted`]) and returns its result with the
/// allocator calls it made on the current thread: other threads, counted or not, do not add
/// to it (a test measuring itself while other tests run).
#[inline]
pub fn count_here<R>(thread: RtThread, f: impl FnOnce() -> R) -> (R, u64) {
    let before = thread_allocations();
    let r = counted(thread, f);
    (r, thread_allocations() - before)
}

/// Allocations counted inside the audio callback since the process started.
pub fn callback_allocations() -> u64 {
    allocations(RtThread::Capture)
}

/// Declares that the counting allocator is the global allocator (call once from `main`).
pub fn mark_installed() {
    INSTALLED.store(true, Ordering::Relaxed);
}

/// Whether [`mark_installed`] was called, i.e. whether the counts mean anything.
pub fn is_installed() -> bool {
    INSTALLED.load(Ordering::Relaxed)
}
