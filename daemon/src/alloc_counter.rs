//! The counting global allocator (the `counting-alloc` crate, shared with the allocation tests
//! of every crate): counts allocations and frees made while the current thread runs real-time
//! code, per real-time thread ([`RtThread`]), so the live stats can prove every real-time loop
//! allocates nothing.
//!
//! Install it with `#[global_allocator] static A: CountingAllocator = CountingAllocator;`.
//! Without it installed, the counts stay 0 and [`is_installed`] is false.

pub use counting_alloc::*;
