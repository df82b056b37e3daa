//! What every part of a live run shares: the clock epoch, the counters and the stop flag, and
//! the audio ring each run starts from. The audio, analysis, motion and sender threads take a
//! [`LiveContext`]; the pipeline that starts them hands it out.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use super::ring::{RingReader, RingWriter, audio_ring};
use super::stats::Stats;

/// Interleaved samples the audio ring holds (≈ 2.7 s of 48 kHz stereo).
pub const RING_SAMPLES: usize = 1 << 18;
/// Blocks (markers) the audio ring holds.
pub const RING_BLOCKS: usize = 4096;

/// What every part of a run shares: the clock epoch, the counters and the stop flag.
#[derive(Clone)]
pub struct LiveContext {
    /// Zero of every wall time in the run (ns offsets from it are stored in atomics).
    pub epoch: Instant,
    /// The run's counters.
    pub stats: Arc<Stats>,
    /// Set to stop every thread.
    pub stop: Arc<AtomicBool>,
}

impl Default for LiveContext {
    fn default() -> Self {
        Self::new()
    }
}

impl LiveContext {
    /// A fresh context starting now.
    pub fn new() -> Self {
        Self {
            epoch: Instant::now(),
            stats: Arc::new(Stats::new()),
            stop: Arc::new(AtomicBool::new(false)),
        }
    }

    /// A new audio ring for this run.
    pub fn ring(&self) -> (RingWriter, RingReader) {
        audio_ring(RING_SAMPLES, RING_BLOCKS, self.epoch, self.stats.clone())
    }

    /// Whether the run was asked to stop.
    pub fn stopped(&self) -> bool {
        self.stop.load(Ordering::Relaxed)
    }
}
