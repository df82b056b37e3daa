//! The audio ring between the input (sound card callback or file replay) and the analysis
//! thread: interleaved f32 samples plus one [`BlockMarker`] per block, which tells the reader
//! the block's format and the wall time it entered the ring (what latency is measured from).
//!
//! Both halves are lock-free SPSC rings (`ringbuf`), allocated once in [`audio_ring`]; the
//! writer never blocks or allocates: a block that does not fit is dropped whole and counted,
//! and the next marker carries the dropped length so stream time stays continuous.

use std::sync::Arc;
use std::time::Instant;

use ringbuf::HeapRb;
use ringbuf::traits::{Consumer, Observer, Producer, Split};

use super::stats::Stats;

/// Describes one block written into the ring.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BlockMarker {
    /// Frames (samples per channel) of this block in the sample ring.
    pub frames: u32,
    /// Frames dropped (ring full) just before this block; the reader inserts that much silence.
    pub dropped_before: u32,
    /// Sample rate of the block, Hz.
    pub sample_rate: u32,
    /// Interleaved channels of the block.
    pub channels: u16,
    /// Wall time the block entered the ring, nanoseconds since the pipeline's epoch.
    pub wall_ns: u64,
}

/// The writing half: owned by the capture callback or the replay thread.
pub struct RingWriter {
    samples: ringbuf::HeapProd<f32>,
    markers: ringbuf::HeapProd<BlockMarker>,
    epoch: Instant,
    dropped_pending: u32,
    stats: Arc<Stats>,
}

/// The reading half: owned by the analysis thread.
pub struct RingReader {
    samples: ringbuf::HeapCons<f32>,
    markers: ringbuf::HeapCons<BlockMarker>,
}

/// Builds a ring holding `capacity_samples` interleaved samples and `capacity_blocks` markers.
pub fn audio_ring(
    capacity_samples: usize,
    capacity_blocks: usize,
    epoch: Instant,
    stats: Arc<Stats>,
) -> (RingWriter, RingReader) {
    let (sp, sc) = HeapRb::<f32>::new(capacity_samples).split();
    let (mp, mc) = HeapRb::<BlockMarker>::new(capacity_blocks).split();
    (
        RingWriter {
            samples: sp,
            markers: mp,
            epoch,
            dropped_pending: 0,
            stats,
        },
        RingReader {
            samples: sc,
            markers: mc,
        },
    )
}

impl RingWriter {
    /// Writes one interleaved block (never blocks, never allocates); returns false when it was
    /// dropped because the reader is behind.
    pub fn write(&mut self, interleaved: &[f32], sample_rate: u32, channels: u16) -> bool {
        let channels_n = usize::from(channels.max(1));
        let frames = (interleaved.len() / channels_n) as u32;
        let whole = &interleaved[..frames as usize * channels_n];
        if frames == 0 {
            return true;
        }
        if self.samples.vacant_len() < whole.len() || self.markers.vacant_len() < 1 {
            self.dropped_pending = self.dropped_pending.saturating_add(frames);
            self.stats.add_dropped_frames(u64::from(frames));
            return false;
        }
        self.samples.push_slice(whole);
        let marker = BlockMarker {
            frames,
            dropped_before: self.dropped_pending,
            sample_rate,
            channels,
            wall_ns: self.epoch.elapsed().as_nanos() as u64,
        };
        // Cannot fail: vacancy was checked above and only this half pushes.
        let _ = self.markers.try_push(marker);
        self.dropped_pending = 0;
        true
    }

    /// Converts integer samples on the fly through `scratch` (preallocated by the caller).
    pub fn write_converted<T: Copy>(
        &mut self,
        data: &[T],
        scratch: &mut [f32],
        convert: impl Fn(T) -> f32,
        sample_rate: u32,
        channels: u16,
    ) {
        let ch = usize::from(channels.max(1));
        // Whole frames per chunk so each marker describes complete frames.
        let chunk = (scratch.len() / ch).max(1) * ch;
        for part in data.chunks(chunk) {
            let n = part.len().min(scratch.len());
            for (d, &s) in scratch[..n].iter_mut().zip(part) {
                *d = convert(s);
            }
            self.write(&scratch[..n], sample_rate, channels);
        }
    }
}

impl RingReader {
    /// Takes the next block's marker, if its samples are all in the ring.
    pub fn next_marker(&mut self) -> Option<BlockMarker> {
        self.markers.try_pop()
    }

    /// Pops up to `out.len()` samples; returns how many.
    pub fn pop(&mut self, out: &mut [f32]) -> usize {
        self.samples.pop_slice(out)
    }

    /// Samples waiting in the ring.
    pub fn pending_samples(&self) -> usize {
        self.samples.occupied_len()
    }
}
