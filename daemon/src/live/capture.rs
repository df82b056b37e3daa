//! Sound card capture (cpal): the stream callback only converts and copies the heard channels
//! into the preallocated audio ring ([`InputMix`]); a supervisor thread owns the stream and
//! rebuilds it, on the same device, when the device goes away or stops delivering.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;

use cpal::traits::{DeviceTrait, HostTrait, StreamTrait};
use cpal::{
    BufferSize, ErrorKind, SampleFormat, StreamConfig, SupportedBufferSize, SupportedStreamConfig,
    SupportedStreamConfigRange,
};
use thiserror::Error;

use super::context::LiveContext;
use super::input_mix::{InputMix, MAX_INPUT_CHANNELS};
use super::ring::RingWriter;
use crate::alloc_counter::in_callback;

/// Why capture could not start.
#[derive(Debug, Error)]
pub enum CaptureError {
    /// The host lists no input device at all.
    #[error("no audio inputs (use --input FILE or `danced demo`)")]
    NoDevices,
    /// No input device name contains the requested text.
    #[error("no audio input matches {0:?} (see `danced devices`)")]
    NoMatch(String),
    /// The device offers no format danced can read.
    #[error("audio input {device:?} offers no usable format: {reason}")]
    NoConfig {
        /// Device name.
        device: String,
        /// What the backend said.
        reason: String,
    },
    /// The backend refused to build or start the stream.
    #[error("audio input {device:?}: {reason}")]
    Stream {
        /// Device name.
        device: String,
        /// What the backend said.
        reason: String,
    },
}

/// Which input to capture from.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CaptureSettings {
    /// Case-insensitive substring of the device name; the default input when `None`.
    pub device: Option<String>,
    /// Device channels to hear, 1-based (see [`InputMix::new`]); inputs 1 and 2 when `None`.
    pub channels: Option<Vec<u16>>,
}

/// A device's display name (cpal 0.18: `description().name()`, else its `Display`).
pub fn device_name(device: &cpal::Device) -> String {
    device
        .description()
        .map(|d| d.name().to_string())
        .unwrap_or_else(|_| device.to_string())
}

fn find_device(host: &cpal::Host, wanted: Option<&str>) -> Result<cpal::Device, CaptureError> {
    match wanted {
        None => host.default_input_device().ok_or(CaptureError::NoDevices),
        Some(w) => {
            let w = w.to_lowercase();
            let devices: Vec<_> = host
                .input_devices()
                .map_err(|_| CaptureError::NoDevices)?
                .collect();
            if devices.is_empty() {
                return Err(CaptureError::NoDevices);
            }
            devices
                .into_iter()
                .find(|d| device_name(d).to_lowercase().contains(&w))
                .ok_or_else(|| CaptureError::NoMatch(w.clone()))
        }
    }
}

/// Preference of a sample format: floats and wide integers first, 64-bit integers (rarely
/// native, converted by the driver) last; DSD is not PCM and cannot be read.
fn format_rank(f: SampleFormat) -> Option<u8> {
    Some(match f {
        SampleFormat::F32 => 9,
        SampleFormat::I32 => 8,
        SampleFormat::I24 => 7,
        SampleFormat::I16 => 6,
        SampleFormat::F64 => 5,
        SampleFormat::U32 | SampleFormat::U24 | SampleFormat::U16 => 4,
        SampleFormat::I8 | SampleFormat::U8 => 3,
        SampleFormat::I64 | SampleFormat::U64 => 2,
        _ => return None,
    })
}

/// Picks the format `run` opens among a device's offered ranges: a mono or stereo config
/// before a wider one (an interface's plug layer often offers both), 48 or 44.1 kHz before
/// other rates, then the best sample format. `None` when nothing is readable (1–64 channels,
/// PCM, 8–192 kHz).
pub fn choose_from(
    ranges: impl IntoIterator<Item = SupportedStreamConfigRange>,
) -> Option<SupportedStreamConfig> {
    ranges
        .into_iter()
        .filter(|r| (1..=MAX_INPUT_CHANNELS).contains(&r.channels()))
        .filter_map(|r| Some((format_rank(r.sample_format())?, r)))
        .filter_map(|(rank, r)| {
            let preferred = [48_000, 44_100].into_iter().find(|&s| r.contains_rate(s));
            let config = match preferred {
                Some(s) => r.with_sample_rate(s),
                None => r.with_max_sample_rate(),
            };
            let rate_ok =
                (dsp::MIN_INPUT_RATE..=dsp::MAX_INPUT_RATE).contains(&config.sample_rate());
            let narrow = config.channels() <= 2;
            // Among equals, stereo before mono (no driver downmix), fewer channels before more.
            let width = u16::MAX - config.channels().abs_diff(2);
            rate_ok.then_some(((narrow, preferred.is_some(), rank, width), config))
        })
        .max_by(|a, b| a.0.cmp(&b.0))
        .map(|(_, c)| c)
}

/// Picks the format `run` opens on `device` (see [`choose_from`]).
pub fn choose_config(device: &cpal::Device) -> Result<SupportedStreamConfig, CaptureError> {
    let no_config = |reason: String| CaptureError::NoConfig {
        device: device_name(device),
        reason,
    };
    let ranges = device
        .supported_input_configs()
        .map_err(|e| no_config(e.to_string()))?;
    choose_from(ranges).ok_or_else(|| {
        no_config(format!(
            "no PCM format with 1–{MAX_INPUT_CHANNELS} channels at 8–192 kHz"
        ))
    })
}

/// The ring writer, shared by the streams a run builds one after another. Only the newest
/// stream's callback may write (its generation is the current one); a stream being torn down
/// — or one stuck in its driver after a sound server crashed — is ignored. The callback only
/// ever `try_lock`s (an old and a new callback can overlap for a block; the loser's block is
/// counted in `capture_contended`), and nothing else locks it while a run is live.
struct SharedWriter {
    writer: Mutex<RingWriter>,
    generation: AtomicU64,
}

/// What the stream callback owns.
struct CallbackState {
    shared: Arc<SharedWriter>,
    generation: u64,
    mix: InputMix,
    rate: u32,
    last_callback_ns: Arc<AtomicU64>,
    epoch: std::time::Instant,
    stats: Arc<super::stats::Stats>,
}

impl CallbackState {
    fn on_block(&mut self, data: &cpal::Data) {
        in_callback(|| {
            if self.shared.generation.load(Ordering::Acquire) != self.generation {
                return;
            }
            let now = (self.epoch.elapsed().as_nanos() as u64).max(1);
            self.last_callback_ns.store(now, Ordering::Relaxed);
            match self.shared.writer.try_lock() {
                Ok(mut w) => {
                    self.mix.write(data, self.rate, &mut w);
                }
                Err(_) => {
                    self.stats.capture_contended.fetch_add(1, Ordering::Relaxed);
                }
            }
        })
    }
}

/// Drops a stream on a thread of its own: tearing one down joins cpal's worker, which a
/// crashed sound server can leave stuck in its driver forever (seen with ALSA's pulse plugin
/// when PulseAudio is killed). The supervisor never waits for it; `capture_streams_stuck`
/// counts those not yet gone.
fn retire(stream: cpal::Stream, stats: &Arc<super::stats::Stats>) {
    stats.capture_streams_stuck.fetch_add(1, Ordering::Relaxed);
    let stats = stats.clone();
    let spawned = std::thread::Builder::new()
        .name("danced-capture-retire".into())
        .spawn(move || {
            drop(stream);
            stats.capture_streams_stuck.fetch_sub(1, Ordering::Relaxed);
        });
    if spawned.is_err() {
        tracing::warn!("could not start a thread to close the old audio stream; leaving it open");
    }
}

fn build_stream(
    device: &cpal::Device,
    config: &SupportedStreamConfig,
    mix: InputMix,
    shared: &Arc<SharedWriter>,
    ctx: &LiveContext,
    health: &StreamHealth,
) -> Result<cpal::Stream, CaptureError> {
    let mut stream_config: StreamConfig = config.config();
    // A short period where the device lets us choose: the backend's default can be hundreds
    // of milliseconds (ALSA's pulse plugin), which the dancer would pay as latency.
    if let SupportedBufferSize::Range { min, max } = *config.buffer_size() {
        stream_config.buffer_size = BufferSize::Fixed(CALLBACK_FRAMES.clamp(min, max));
    }
    let stats = ctx.stats.clone();
    let broken = health.broken.clone();
    let on_error = move |e: cpal::Error| {
        stats.stream_errors.fetch_add(1, Ordering::Relaxed);
        if matches!(
            e.kind(),
            ErrorKind::DeviceNotAvailable
                | ErrorKind::StreamInvalidated
                | ErrorKind::HostUnavailable
        ) {
            broken.store(true, Ordering::Relaxed);
        }
    };
    let err = |e: cpal::Error| CaptureError::Stream {
        device: device_name(device),
        reason: e.to_string(),
    };
    // 0 until the first callback: a stream gets longer to start than to keep delivering.
    health.last_callback_ns.store(0, Ordering::Relaxed);
    health
        .started_ns
        .store(ctx.epoch.elapsed().as_nanos() as u64, Ordering::Relaxed);
    let mut state = CallbackState {
        shared: shared.clone(),
        // This stream's callbacks write; every older stream's are ignored from now on.
        generation: shared.generation.fetch_add(1, Ordering::AcqRel) + 1,
        mix,
        rate: stream_config.sample_rate,
        last_callback_ns: health.last_callback_ns.clone(),
        epoch: ctx.epoch,
        stats: ctx.stats.clone(),
    };
    let stream = device
        .build_input_stream_raw(
            stream_config,
            config.sample_format(),
            move |data: &cpal::Data, _: &cpal::InputCallbackInfo| state.on_block(data),
            on_error,
            None,
        )
        .map_err(err)?;
    stream.play().map_err(err)?;
    Ok(stream)
}

/// What the supervisor watches: the backend's error flag and the time of the last callback.
struct StreamHealth {
    broken: Arc<AtomicBool>,
    last_callback_ns: Arc<AtomicU64>,
    started_ns: AtomicU64,
}

impl StreamHealth {
    /// Whether the stream has stopped delivering: no callback for [`STALL_AFTER`] once it
    /// has started, or none at all within [`START_WITHIN`] of being built.
    fn stalled(&self, now_ns: u64) -> bool {
        let last = self.last_callback_ns.load(Ordering::Relaxed);
        if last == 0 {
            let started = self.started_ns.load(Ordering::Relaxed);
            now_ns.saturating_sub(started) > START_WITHIN.as_nanos() as u64
        } else {
            now_ns.saturating_sub(last) > STALL_AFTER.as_nanos() as u64
        }
    }
}

/// How a stream was opened, for the banner and `danced devices`.
fn describe(device: &str, config: &SupportedStreamConfig, mix: &InputMix) -> String {
    let heard: Vec<String> = mix.heard().map(|c| c.to_string()).collect();
    format!(
        "{device} ({} Hz, {} ch, {:?}; hearing input {})",
        config.sample_rate(),
        config.channels(),
        config.sample_format(),
        heard.join("+")
    )
}

/// Finds the device: by substring the first time, by exact name on every reconnect, so a
/// lost interface is never silently replaced by another.
fn open(
    settings: &CaptureSettings,
    exact_name: Option<&str>,
    shared: &Arc<SharedWriter>,
    ctx: &LiveContext,
    health: &StreamHealth,
) -> Result<(cpal::Stream, String, String), CaptureError> {
    let host = cpal::default_host();
    let device = match exact_name {
        Some(name) => host
            .input_devices()
            .map_err(|_| CaptureError::NoDevices)?
            .find(|d| device_name(d) == name)
            .ok_or_else(|| CaptureError::NoMatch(name.to_string()))?,
        None => find_device(&host, settings.device.as_deref())?,
    };
    let name = device_name(&device);
    let config = choose_config(&device)?;
    let mix = InputMix::new(config.channels(), settings.channels.as_deref()).map_err(|e| {
        CaptureError::NoConfig {
            device: name.clone(),
            reason: e.to_string(),
        }
    })?;
    let desc = describe(&name, &config, &mix);
    health.broken.store(false, Ordering::Relaxed);
    let stream = build_stream(&device, &config, mix, shared, ctx, health)?;
    Ok((stream, name, desc))
}

/// Frames per callback asked of devices that let us choose (10.7 ms at 48 kHz).
pub const CALLBACK_FRAMES: u32 = 512;

/// A stream silent this long is taken as stalled and rebuilt.
pub const STALL_AFTER: Duration = Duration::from_millis(400);
/// A new stream that has not called back this long after being built is rebuilt (a sound
/// server that has just come back can take a second to start a stream).
pub const START_WITHIN: Duration = Duration::from_millis(2000);

/// Opens the input and starts the supervisor thread that keeps it open until the run stops:
/// a stream the backend reports lost, or one that stops calling back for [`STALL_AFTER`], is
/// dropped and rebuilt on the same device, with backoff while the device is gone (the
/// pipeline dances on silence meanwhile). Fails cleanly (no panic) when there is no usable
/// input; returns the device description.
pub fn spawn(
    settings: CaptureSettings,
    writer: RingWriter,
    ctx: &LiveContext,
) -> Result<(JoinHandle<()>, String), CaptureError> {
    let shared = Arc::new(SharedWriter {
        writer: Mutex::new(writer),
        generation: AtomicU64::new(0),
    });
    let (tx, rx) = crossbeam_channel::bounded(1);
    let ctx = ctx.clone();
    let handle = std::thread::Builder::new()
        .name("danced-capture".into())
        .spawn(move || {
            let health = StreamHealth {
                broken: Arc::new(AtomicBool::new(false)),
                last_callback_ns: Arc::new(AtomicU64::new(0)),
                started_ns: AtomicU64::new(0),
            };
            // The stream is owned by this thread for its whole life (cpal streams need not be Send).
            let (mut stream, name) = match open(&settings, None, &shared, &ctx, &health) {
                Ok((s, name, desc)) => {
                    let _ = tx.send(Ok(desc));
                    (Some(s), name)
                }
                Err(e) => {
                    let _ = tx.send(Err(e));
                    return;
                }
            };
            let mut backoff = Duration::from_millis(100);
            while !ctx.stopped() {
                std::thread::sleep(Duration::from_millis(50));
                let now = ctx.epoch.elapsed().as_nanos() as u64;
                let stalled = stream.is_some() && health.stalled(now);
                if stalled {
                    ctx.stats.capture_stalls.fetch_add(1, Ordering::Relaxed);
                    tracing::warn!(
                        "audio input {name:?} stopped delivering; rebuilding the stream"
                    );
                }
                if !health.broken.load(Ordering::Relaxed) && stream.is_some() && !stalled {
                    continue;
                }
                if let Some(lost) = stream.take() {
                    // Lost: the pipeline analyses silence meanwhile; retry right away once.
                    retire(lost, &ctx.stats);
                    backoff = Duration::from_millis(100);
                } else {
                    let mut waited = Duration::ZERO;
                    while waited < backoff && !ctx.stopped() {
                        std::thread::sleep(Duration::from_millis(50));
                        waited += Duration::from_millis(50);
                    }
                }
                match open(&settings, Some(&name), &shared, &ctx, &health) {
                    Ok((s, _, desc)) => {
                        tracing::info!("audio input back: {desc}");
                        ctx.stats.reconnects.fetch_add(1, Ordering::Relaxed);
                        stream = Some(s);
                        backoff = Duration::from_millis(100);
                    }
                    Err(e) => {
                        ctx.stats.reconnect_failures.fetch_add(1, Ordering::Relaxed);
                        tracing::warn!("audio input still gone ({e}); retrying in {backoff:?}");
                        backoff = (backoff * 2).min(Duration::from_secs(2));
                    }
                }
            }
            if let Some(s) = stream {
                retire(s, &ctx.stats);
            }
        })
        .map_err(|e| CaptureError::Stream {
            device: "capture thread".into(),
            reason: e.to_string(),
        })?;
    match rx.recv() {
        Ok(Ok(desc)) => Ok((handle, desc)),
        Ok(Err(e)) => {
            let _ = handle.join();
            Err(e)
        }
        Err(_) => {
            let _ = handle.join();
            Err(CaptureError::NoDevices)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn range(channels: u16, min: u32, max: u32, f: SampleFormat) -> SupportedStreamConfigRange {
        SupportedStreamConfigRange::new(channels, min, max, SupportedBufferSize::Unknown, f)
    }

    #[test]
    fn prefers_stereo_at_48_or_44k_over_a_wide_float_config() {
        // A 64-channel interface behind a plug layer: 64 ch F32 native, 1–2 ch I16 converted.
        let offered = vec![
            range(64, 8_000, 192_000, SampleFormat::F32),
            range(1, 8_000, 192_000, SampleFormat::I16),
            range(2, 8_000, 192_000, SampleFormat::I16),
        ];
        let c = choose_from(offered).unwrap();
        assert_eq!((c.channels(), c.sample_rate()), (2, 48_000));
        assert_eq!(c.sample_format(), SampleFormat::I16);
        // Only wide configs: the 64-channel one, at 44.1 kHz when 48 kHz is not offered.
        let c = choose_from(vec![range(64, 44_100, 44_100, SampleFormat::I32)]).unwrap();
        assert_eq!((c.channels(), c.sample_rate()), (64, 44_100));
        // Float beats integer among stereo configs; a preferred rate beats a better format.
        let c = choose_from(vec![
            range(2, 96_000, 96_000, SampleFormat::F32),
            range(2, 48_000, 48_000, SampleFormat::I24),
        ])
        .unwrap();
        assert_eq!(
            (c.sample_rate(), c.sample_format()),
            (48_000, SampleFormat::I24)
        );
    }

    #[test]
    fn unreadable_configs_are_refused() {
        assert!(choose_from(vec![range(65, 48_000, 48_000, SampleFormat::F32)]).is_none());
        assert!(choose_from(vec![range(2, 48_000, 48_000, SampleFormat::DsdU8)]).is_none());
        assert!(choose_from(vec![range(2, 4_000, 4_000, SampleFormat::F32)]).is_none());
        assert!(choose_from(vec![range(0, 48_000, 48_000, SampleFormat::F32)]).is_none());
        // Every PCM format at every channel count 1–64 is accepted.
        for f in [
            SampleFormat::I8,
            SampleFormat::I16,
            SampleFormat::I24,
            SampleFormat::I32,
            SampleFormat::I64,
            SampleFormat::U8,
            SampleFormat::U16,
            SampleFormat::U24,
            SampleFormat::U32,
            SampleFormat::U64,
            SampleFormat::F32,
            SampleFormat::F64,
        ] {
            for ch in 1..=MAX_INPUT_CHANNELS {
                let c = choose_from(vec![range(ch, 48_000, 48_000, f)]).unwrap();
                assert!(InputMix::new(c.channels(), None).is_ok() && InputMix::reads(f));
            }
        }
    }
}
