//! What the browser view did and lost, counted where it happens and reported with the run.

use std::sync::atomic::{AtomicU64, Ordering};

use serde::Serialize;

/// The view's counters, shared by the sender thread, the view thread and the HTTP handlers.
#[derive(Debug, Default)]
pub struct ViewCounters {
    /// Frames the sender put in the slot before the view thread took the previous one.
    pub frames_replaced: AtomicU64,
    /// Events lost because the sender → view queue was full.
    pub events_dropped: AtomicU64,
    /// Frames written to browsers (one per client per frame).
    pub frames_forwarded: AtomicU64,
    /// Frames a client missed because it had not taken the earlier ones yet.
    pub frames_skipped: AtomicU64,
    /// WebSocket clients accepted.
    pub clients_accepted: AtomicU64,
    /// Clients disconnected for falling behind for too long.
    pub clients_dropped_slow: AtomicU64,
    /// WebSocket upgrades refused (another site's page, too many clients, a bad handshake).
    pub clients_refused: AtomicU64,
    /// Files served over HTTP.
    pub http_served: AtomicU64,
    /// HTTP requests answered with an error (unknown path, bad request, I/O failure).
    pub http_errors: AtomicU64,
    /// Control messages from the page that the control parser accepted.
    pub controls_accepted: AtomicU64,
    /// Control messages from the page it ignored (malformed, unknown address, bad arguments).
    pub controls_ignored: AtomicU64,
    /// CPU time of the view thread, µs.
    pub thread_cpu_us: AtomicU64,
}

/// The view's counters at the end of a run (in the stats JSON).
#[derive(Clone, Copy, Debug, Default, Serialize, PartialEq, Eq)]
pub struct ViewReport {
    /// See [`ViewCounters::frames_replaced`].
    pub frames_replaced: u64,
    /// See [`ViewCounters::events_dropped`].
    pub events_dropped: u64,
    /// See [`ViewCounters::frames_forwarded`].
    pub frames_forwarded: u64,
    /// See [`ViewCounters::frames_skipped`].
    pub frames_skipped: u64,
    /// See [`ViewCounters::clients_accepted`].
    pub clients_accepted: u64,
    /// See [`ViewCounters::clients_dropped_slow`].
    pub clients_dropped_slow: u64,
    /// See [`ViewCounters::clients_refused`].
    pub clients_refused: u64,
    /// See [`ViewCounters::http_served`].
    pub http_served: u64,
    /// See [`ViewCounters::http_errors`].
    pub http_errors: u64,
    /// See [`ViewCounters::controls_accepted`].
    pub controls_accepted: u64,
    /// See [`ViewCounters::controls_ignored`].
    pub controls_ignored: u64,
    /// See [`ViewCounters::thread_cpu_us`].
    pub thread_cpu_us: u64,
}

impl ViewCounters {
    /// The counters now.
    pub fn report(&self) -> ViewReport {
        let g = |a: &AtomicU64| a.load(Ordering::Relaxed);
        ViewReport {
            frames_replaced: g(&self.frames_replaced),
            events_dropped: g(&self.events_dropped),
            frames_forwarded: g(&self.frames_forwarded),
            frames_skipped: g(&self.frames_skipped),
            clients_accepted: g(&self.clients_accepted),
            clients_dropped_slow: g(&self.clients_dropped_slow),
            clients_refused: g(&self.clients_refused),
            http_served: g(&self.http_served),
            http_errors: g(&self.http_errors),
            controls_accepted: g(&self.controls_accepted),
            controls_ignored: g(&self.controls_ignored),
            thread_cpu_us: g(&self.thread_cpu_us),
        }
    }
}
