//! Sound card capture (cpal): the stream callback only copies (converting integer samples) into
//! the preallocated audio ring; a supervisor thread owns the stream and rebuilds it with
//! exponential backoff when the device goes away.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;

use cpal::traits::{DeviceTrait, HostTrait, StreamTrait};
use cpal::{ErrorKind, SampleFormat, StreamConfig, SupportedStreamConfig};
use thiserror::Error;

use super::pipeline::LiveContext;
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

fn format_rank(f: SampleFormat) -> Option<u8> {
    match f {
        SampleFormat::F32 => Some(3),
        SampleFormat::I32 => Some(2),
        SampleFormat::I16 => Some(1),
        SampleFormat::U16 => Some(0),
        _ => None,
    }
}

/// Picks a readable format: f32 before i32/i16/u16, 48 or 44.1 kHz when offered.
pub fn choose_config(device: &cpal::Device) -> Result<SupportedStreamConfig, CaptureError> {
    let no_config = |reason: String| CaptureError::NoConfig {
        device: device_name(device),
        reason,
    };
    let ranges = device
        .supported_input_configs()
        .map_err(|e| no_config(e.to_string()))?;
    ranges
        .filter_map(|r| Some((format_rank(r.sample_format())?, r)))
        .filter_map(|(rank, r)| {
            let preferred = [48_000, 44_100].into_iter().find(|&s| r.contains_rate(s));
            let config = match preferred {
                Some(s) => r.with_sample_rate(s),
                None => r.with_max_sample_rate(),
            };
            let rate_ok =
                (dsp::MIN_INPUT_RATE..=dsp::MAX_INPUT_RATE).contains(&config.sample_rate());
            rate_ok.then_some(((rank, preferred.is_some()), config))
        })
        .max_by(|a, b| a.0.cmp(&b.0))
        .map(|(_, c)| c)
        .ok_or_else(|| no_config("no f32/i32/i16/u16 format at 8–192 kHz".into()))
}

/// Shared with the callback; `try_lock` only, so the callback never waits (nobody else holds
/// it while a stream runs: the supervisor drops a stream before building the next).
type SharedWriter = Arc<Mutex<RingWriter>>;

fn build_stream(
    device: &cpal::Device,
    config: &SupportedStreamConfig,
    writer: SharedWriter,
    ctx: &LiveContext,
    broken: Arc<AtomicBool>,
) -> Result<cpal::Stream, CaptureError> {
    let stream_config: StreamConfig = config.config();
    let rate = stream_config.sample_rate;
    let channels = stream_config.channels;
    let stats = ctx.stats.clone();
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
    // Conversion scratch, allocated here, reused by every callback.
    let mut scratch = vec![0.0f32; 16_384];
    let stream = match config.sample_format() {
        SampleFormat::F32 => device.build_input_stream::<f32, _, _>(
            stream_config,
            move |data: &[f32], _: &cpal::InputCallbackInfo| {
                in_callback(|| {
                    if let Ok(mut w) = writer.try_lock() {
                        w.write(data, rate, channels);
                    }
                })
            },
            on_error,
            None,
        ),
        SampleFormat::I32 => device.build_input_stream::<i32, _, _>(
            stream_config,
            move |data: &[i32], _: &cpal::InputCallbackInfo| {
                in_callback(|| {
                    if let Ok(mut w) = writer.try_lock() {
                        w.write_converted(
                            data,
                            &mut scratch,
                            |s| s as f32 / 2_147_483_648.0,
                            rate,
                            channels,
                        );
                    }
                })
            },
            on_error,
            None,
        ),
        SampleFormat::I16 => device.build_input_stream::<i16, _, _>(
            stream_config,
            move |data: &[i16], _: &cpal::InputCallbackInfo| {
                in_callback(|| {
                    if let Ok(mut w) = writer.try_lock() {
                        w.write_converted(
                            data,
                            &mut scratch,
                            |s| f32::from(s) / 32_768.0,
                            rate,
                            channels,
                        );
                    }
                })
            },
            on_error,
            None,
        ),
        SampleFormat::U16 => device.build_input_stream::<u16, _, _>(
            stream_config,
            move |data: &[u16], _: &cpal::InputCallbackInfo| {
                in_callback(|| {
                    if let Ok(mut w) = writer.try_lock() {
                        w.write_converted(
                            data,
                            &mut scratch,
                            |s| (f32::from(s) - 32_768.0) / 32_768.0,
                            rate,
                            channels,
                        );
                    }
                })
            },
            on_error,
            None,
        ),
        other => {
            return Err(CaptureError::NoConfig {
                device: device_name(device),
                reason: format!("sample format {other:?}"),
            });
        }
    }
    .map_err(err)?;
    stream.play().map_err(err)?;
    Ok(stream)
}

fn open(
    settings: &CaptureSettings,
    writer: &SharedWriter,
    ctx: &LiveContext,
    broken: &Arc<AtomicBool>,
) -> Result<(cpal::Stream, String), CaptureError> {
    let host = cpal::default_host();
    let device = find_device(&host, settings.device.as_deref())?;
    let config = choose_config(&device)?;
    broken.store(false, Ordering::Relaxed);
    let stream = build_stream(&device, &config, writer.clone(), ctx, broken.clone())?;
    let desc = format!(
        "{} ({} Hz, {} ch, {:?})",
        device_name(&device),
        config.sample_rate(),
        config.channels(),
        config.sample_format()
    );
    Ok((stream, desc))
}

/// Opens the input and starts the supervisor thread that keeps it open until the run stops.
/// Fails cleanly (no panic) when there is no usable input; returns the device description.
pub fn spawn(
    settings: CaptureSettings,
    writer: RingWriter,
    ctx: &LiveContext,
) -> Result<(JoinHandle<()>, String), CaptureError> {
    let writer: SharedWriter = Arc::new(Mutex::new(writer));
    let (tx, rx) = crossbeam_channel::bounded(1);
    let ctx = ctx.clone();
    let handle = std::thread::Builder::new()
        .name("danced-capture".into())
        .spawn(move || {
            let broken = Arc::new(AtomicBool::new(false));
            // The stream is owned by this thread for its whole life (cpal streams need not be Send).
            let mut stream = match open(&settings, &writer, &ctx, &broken) {
                Ok((s, desc)) => {
                    let _ = tx.send(Ok(desc));
                    Some(s)
                }
                Err(e) => {
                    let _ = tx.send(Err(e));
                    return;
                }
            };
            let mut backoff = Duration::from_millis(100);
            while !ctx.stopped() {
                std::thread::sleep(Duration::from_millis(50));
                if !broken.load(Ordering::Relaxed) && stream.is_some() {
                    continue;
                }
                // Lost: drop the stream (the pipeline analyses silence meanwhile), then retry.
                stream = None;
                let mut waited = Duration::ZERO;
                while waited < backoff && !ctx.stopped() {
                    std::thread::sleep(Duration::from_millis(50));
                    waited += Duration::from_millis(50);
                }
                match open(&settings, &writer, &ctx, &broken) {
                    Ok((s, desc)) => {
                        tracing::info!("audio input back: {desc}");
                        ctx.stats.reconnects.fetch_add(1, Ordering::Relaxed);
                        stream = Some(s);
                        backoff = Duration::from_millis(100);
                    }
                    Err(e) => {
                        tracing::warn!("audio input still gone ({e}); retrying in {backoff:?}");
                        backoff = (backoff * 2).min(Duration::from_secs(5));
                    }
                }
            }
            drop(stream);
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
