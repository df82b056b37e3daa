//! Replays decoded audio into the audio ring from a thread, as a sound card would: 256-frame
//! blocks paced against a monotonic clock (or `speed` times faster), optionally looped, for
//! `danced run --input`, `danced demo` and `danced bench live`.

use std::path::Path;
use std::sync::atomic::Ordering;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};

use super::context::LiveContext;
use super::ring::RingWriter;
use crate::alloc_counter::in_callback;

/// Frames per replayed block (5.8 ms at 44.1 kHz), as a sound card period.
pub const REPLAY_BLOCK: usize = 256;

/// Decoded audio to replay.
#[derive(Clone, Debug)]
pub struct ReplayAudio {
    /// Interleaved samples.
    pub samples: Vec<f32>,
    /// Sample rate, Hz.
    pub sample_rate: u32,
    /// Interleaved channels.
    pub channels: u16,
    /// What it is, for messages.
    pub name: String,
}

impl ReplayAudio {
    /// Decodes a whole file (any format `danced analyze` reads).
    pub fn from_file(path: &Path) -> Result<Self> {
        let a = offline::decode::decode_file(path)
            .with_context(|| format!("decoding {}", path.display()))?;
        if a.frames() == 0 {
            bail!("{} holds no audio", path.display());
        }
        Ok(Self {
            samples: a.samples,
            sample_rate: a.sample_rate,
            channels: a.channels,
            name: path.display().to_string(),
        })
    }

    /// The built-in demo song (`seconds` long, looped by the caller if wanted).
    pub fn demo(seconds: f64) -> Self {
        let d = crate::demo_track::demo_track(seconds);
        Self {
            samples: d.samples,
            sample_rate: crate::demo_track::DEMO_RATE,
            channels: 2,
            name: format!(
                "built-in demo song ({} BPM, 4/4)",
                crate::demo_track::DEMO_BPM
            ),
        }
    }

    /// Length in seconds.
    pub fn duration_s(&self) -> f64 {
        self.samples.len() as f64 / f64::from(self.channels.max(1)) / f64::from(self.sample_rate)
    }
}

/// How to replay.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ReplaySettings {
    /// Audio seconds per wall second.
    pub speed: f64,
    /// Start again at the end.
    pub looped: bool,
    /// Stop the whole run after this many seconds of audio.
    pub duration_s: Option<f64>,
}

/// Starts the replay thread. It ends at the end of the audio (the pipeline then analyses
/// silence), or sets the run's stop flag once `duration_s` of audio has been replayed.
pub fn spawn(
    audio: ReplayAudio,
    settings: ReplaySettings,
    mut writer: RingWriter,
    ctx: &LiveContext,
) -> Result<JoinHandle<()>> {
    if !(settings.speed.is_finite() && settings.speed > 0.0) {
        bail!("replay speed {} must be positive", settings.speed);
    }
    let ctx = ctx.clone();
    std::thread::Builder::new()
        .name("danced-replay".into())
        .spawn(move || {
            let ch = usize::from(audio.channels.max(1));
            let block_s = REPLAY_BLOCK as f64 / f64::from(audio.sample_rate) / settings.speed;
            let limit = settings
                .duration_s
                .map(|d| (d * f64::from(audio.sample_rate)) as u64);
            let mut start = Instant::now();
            // The replay clock, for measurements against what a listener would hear.
            let publish = |start: Instant| {
                let ns = start.saturating_duration_since(ctx.epoch).as_nanos() as u64;
                ctx.stats.replay_origin_ns.store(ns, Ordering::Relaxed);
            };
            publish(start);
            let mut k = 0u64;
            let mut pos = 0usize;
            let mut replayed = 0u64;
            while !ctx.stopped() {
                if pos >= audio.samples.len() {
                    if !settings.looped {
                        return;
                    }
                    pos = 0;
                }
                let end = (pos + REPLAY_BLOCK * ch).min(audio.samples.len());
                let block = &audio.samples[pos..end];
                // A block "arrives" once its last sample would have been captured.
                let deadline = start + Duration::from_secs_f64(block_s * (k + 1) as f64);
                let now = Instant::now();
                if deadline > now {
                    std::thread::sleep(deadline - now);
                } else if now - deadline > Duration::from_millis(200) {
                    // Stalled (machine busy): carry on from now instead of bursting.
                    start = now - Duration::from_secs_f64(block_s * (k + 1) as f64);
                    publish(start);
                    ctx.stats.replay_rebases.fetch_add(1, Ordering::Relaxed);
                }
                in_callback(|| writer.write(block, audio.sample_rate, audio.channels));
                pos = end;
                k += 1;
                replayed += (block.len() / ch) as u64;
                if limit.is_some_and(|l| replayed >= l) {
                    ctx.stop.store(true, Ordering::Relaxed);
                    return;
                }
            }
        })
        .context("starting the replay thread")
}
