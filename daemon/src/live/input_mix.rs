//! What the capture callback does with each block a sound card delivers: converts any PCM
//! sample format to f32 and keeps only the channels the analysis listens to (at most two, so
//! the ring and the analysis cost the same on a 64-input interface as on a stereo one), in
//! preallocated chunks, into the audio ring. Every callback size and channel count is handled
//! without allocating and without panicking; what cannot be read is counted.

use cpal::{FromSample, I24, Sample, SampleFormat, U24};
use thiserror::Error;

use super::ring::RingWriter;

/// The most input channels a capture device may have.
pub const MAX_INPUT_CHANNELS: u16 = 64;
/// Frames converted per ring write (a callback of any size is cut into such chunks).
const CHUNK_FRAMES: usize = 1024;

/// A channel selection that does not fit the device.
#[derive(Debug, Error, PartialEq)]
pub enum InputMixError {
    /// The device has no channels, or more than [`MAX_INPUT_CHANNELS`].
    #[error("a device with {0} input channels (danced reads 1 to {MAX_INPUT_CHANNELS})")]
    ChannelCount(u16),
    /// A selected channel is not on the device (channels count from 1).
    #[error("input channel {channel} does not exist (the device has {channels})")]
    NoSuchChannel {
        /// The channel asked for (1-based).
        channel: u16,
        /// Channels the device has.
        channels: u16,
    },
    /// The selection is empty or names a channel twice.
    #[error("the input channel list {0:?} must name one or more distinct channels")]
    BadSelection(Vec<u16>),
}

/// Which device channels the analysis hears, and how they reach the ring.
#[derive(Clone, Debug, PartialEq)]
pub struct InputMix {
    device_channels: usize,
    /// 0-based device channels kept, in order.
    selected: [usize; MAX_INPUT_CHANNELS as usize],
    selected_len: usize,
    /// Channels written to the ring: the selection itself when it has one or two channels,
    /// else 1 (their average).
    out_channels: usize,
    scratch: Vec<f32>,
}

impl InputMix {
    /// A mix for a device with `device_channels` inputs. `selection` lists 1-based channels
    /// to hear; `None` hears channels 1 and 2 (or the only one), the main pair of an interface.
    pub fn new(device_channels: u16, selection: Option<&[u16]>) -> Result<Self, InputMixError> {
        if device_channels == 0 || device_channels > MAX_INPUT_CHANNELS {
            return Err(InputMixError::ChannelCount(device_channels));
        }
        let default = [1, 2];
        let wanted: &[u16] = match selection {
            Some(s) => s,
            None => &default[..usize::from(device_channels.min(2))],
        };
        let mut selected = [0usize; MAX_INPUT_CHANNELS as usize];
        if wanted.is_empty() || wanted.len() > usize::from(MAX_INPUT_CHANNELS) {
            return Err(InputMixError::BadSelection(wanted.to_vec()));
        }
        for (i, &c) in wanted.iter().enumerate() {
            if c == 0 || c > device_channels {
                return Err(InputMixError::NoSuchChannel {
                    channel: c,
                    channels: device_channels,
                });
            }
            if wanted[..i].contains(&c) {
                return Err(InputMixError::BadSelection(wanted.to_vec()));
            }
            selected[i] = usize::from(c - 1);
        }
        let out_channels = if wanted.len() <= 2 { wanted.len() } else { 1 };
        Ok(Self {
            device_channels: usize::from(device_channels),
            selected,
            selected_len: wanted.len(),
            out_channels,
            scratch: vec![0.0; CHUNK_FRAMES * 2],
        })
    }

    /// Channels of each frame written to the ring (1 or 2).
    pub fn ring_channels(&self) -> u16 {
        self.out_channels as u16
    }

    /// The device channels heard, 1-based.
    pub fn heard(&self) -> impl Iterator<Item = u16> + '_ {
        self.selected[..self.selected_len]
            .iter()
            .map(|&c| c as u16 + 1)
    }

    /// Whether the callback can read `format` (every PCM format; not DSD bitstreams).
    pub fn reads(format: SampleFormat) -> bool {
        !matches!(
            format,
            SampleFormat::DsdU8 | SampleFormat::DsdU16 | SampleFormat::DsdU32
        )
    }

    /// Writes one callback's block; returns the frames written. A trailing partial frame (which
    /// no backend delivers) is ignored, a block in a format the mix cannot read writes nothing.
    pub fn write(&mut self, data: &cpal::Data, sample_rate: u32, ring: &mut RingWriter) -> usize {
        macro_rules! typed {
            ($t:ty) => {
                data.as_slice::<$t>()
                    .map_or(0, |s| self.write_samples(s, sample_rate, ring))
            };
        }
        match data.sample_format() {
            SampleFormat::F32 => typed!(f32),
            SampleFormat::F64 => typed!(f64),
            SampleFormat::I8 => typed!(i8),
            SampleFormat::I16 => typed!(i16),
            SampleFormat::I24 => typed!(I24),
            SampleFormat::I32 => typed!(i32),
            SampleFormat::I64 => typed!(i64),
            SampleFormat::U8 => typed!(u8),
            SampleFormat::U16 => typed!(u16),
            SampleFormat::U24 => typed!(U24),
            SampleFormat::U32 => typed!(u32),
            SampleFormat::U64 => typed!(u64),
            _ => 0,
        }
    }

    /// Writes interleaved device samples of any PCM type; returns the frames written.
    pub fn write_samples<T>(&mut self, data: &[T], sample_rate: u32, ring: &mut RingWriter) -> usize
    where
        T: Sample,
        f32: FromSample<T>,
    {
        let ch = self.device_channels;
        let selected = &self.selected[..self.selected_len];
        let norm = 1.0 / self.selected_len as f32;
        let mut written = 0;
        for chunk in data.chunks(CHUNK_FRAMES * ch) {
            let frames = chunk.len() / ch;
            let out = &mut self.scratch[..frames * self.out_channels];
            for (f, frame) in chunk.chunks_exact(ch).enumerate() {
                if self.out_channels == 1 {
                    let mut s = 0.0f32;
                    for &c in selected {
                        s += f32::from_sample(frame[c]);
                    }
                    out[f] = s * norm;
                } else {
                    out[2 * f] = f32::from_sample(frame[selected[0]]);
                    out[2 * f + 1] = f32::from_sample(frame[selected[1]]);
                }
            }
            if frames > 0 && ring.write(out, sample_rate, self.out_channels as u16) {
                written += frames;
            }
        }
        written
    }
}

/// Parses a channel list such as `1,2` or `3-4` or `1,5-8` (1-based, as interfaces label them).
pub fn parse_channel_list(s: &str) -> Result<Vec<u16>, String> {
    let mut out = Vec::new();
    for part in s.split(',').map(str::trim) {
        let num = |t: &str| {
            t.trim()
                .parse::<u16>()
                .map_err(|_| format!("{t:?} in the channel list {s:?} is not a channel number"))
        };
        match part.split_once('-') {
            Some((a, b)) => {
                let (a, b) = (num(a)?, num(b)?);
                if a > b {
                    return Err(format!("the channel range {part:?} runs backwards"));
                }
                out.extend(a..=b);
            }
            None => out.push(num(part)?),
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::live::ring::{BlockMarker, audio_ring};
    use crate::live::stats::Stats;
    use std::sync::Arc;
    use std::time::Instant;

    fn drain(reader: &mut crate::live::ring::RingReader) -> (Vec<BlockMarker>, Vec<f32>) {
        let (mut markers, mut samples) = (Vec::new(), Vec::new());
        while let Some(m) = reader.next_marker() {
            let mut buf = vec![0.0; m.frames as usize * usize::from(m.channels)];
            assert_eq!(reader.pop(&mut buf), buf.len());
            samples.extend(buf);
            markers.push(m);
        }
        (markers, samples)
    }

    #[test]
    fn every_channel_count_and_callback_size_reaches_the_ring_as_the_chosen_channels() {
        let stats = Arc::new(Stats::new());
        for channels in 1..=MAX_INPUT_CHANNELS {
            for frames in [1usize, 63, 256, 1024, 1025, 4096, 16_384] {
                // Ring big enough for the largest block (as the pipeline's is for ≤ 2 channels).
                let (mut w, mut r) = audio_ring(1 << 16, 256, Instant::now(), stats.clone());
                let mut mix = InputMix::new(channels, None).unwrap();
                // Channel c carries the value c / 100 in every frame.
                let data: Vec<f32> = (0..frames * usize::from(channels))
                    .map(|i| (i % usize::from(channels) + 1) as f32 / 100.0)
                    .collect();
                assert_eq!(mix.write_samples(&data, 48_000, &mut w), frames);
                let (markers, samples) = drain(&mut r);
                let ring_ch = usize::from(channels.min(2));
                assert!(markers.iter().all(|m| usize::from(m.channels) == ring_ch));
                assert_eq!(
                    markers.iter().map(|m| m.frames as usize).sum::<usize>(),
                    frames
                );
                assert_eq!(samples.len(), frames * ring_ch);
                assert!((samples[0] - 0.01).abs() < 1e-6);
                if ring_ch == 2 {
                    assert!((samples[1] - 0.02).abs() < 1e-6, "{channels} ch");
                }
            }
        }
    }

    #[test]
    fn a_selection_of_more_than_two_channels_is_averaged_to_mono() {
        let (mut w, mut r) = audio_ring(1 << 12, 16, Instant::now(), Arc::new(Stats::new()));
        let mut mix = InputMix::new(8, Some(&[3, 5, 7])).unwrap();
        assert_eq!(mix.ring_channels(), 1);
        assert_eq!(mix.heard().collect::<Vec<_>>(), vec![3, 5, 7]);
        let data: Vec<i16> = (0..8 * 10).map(|i| (i % 8) as i16 * 1000).collect();
        assert_eq!(mix.write_samples(&data, 44_100, &mut w), 10);
        let (_, samples) = drain(&mut r);
        // Channels 3, 5, 7 hold 2000, 4000, 6000 → mean 4000 / 32768.
        assert!(
            (samples[0] - 4000.0 / 32768.0).abs() < 1e-5,
            "{}",
            samples[0]
        );
    }

    #[test]
    fn every_pcm_format_converts_to_full_scale_floats() {
        let (mut w, mut r) = audio_ring(1 << 12, 64, Instant::now(), Arc::new(Stats::new()));
        let mut mix = InputMix::new(1, None).unwrap();
        let mut check = |written: usize, want: f32| {
            assert_eq!(written, 2);
            let (_, s) = drain(&mut r);
            assert!((s[0] - want).abs() < 1e-3, "{} vs {want}", s[0]);
        };
        check(mix.write_samples(&[0.5f64, 0.0], 48_000, &mut w), 0.5);
        check(mix.write_samples(&[-64i8, 0], 48_000, &mut w), -0.5);
        check(mix.write_samples(&[i32::MIN / 2, 0], 48_000, &mut w), -0.5);
        check(mix.write_samples(&[i64::MAX / 2, 0], 48_000, &mut w), 0.5);
        check(mix.write_samples(&[192u8, 128], 48_000, &mut w), 0.5);
        check(mix.write_samples(&[49_152u16, 32_768], 48_000, &mut w), 0.5);
        check(
            mix.write_samples(&[u32::MAX / 4 * 3, 0], 48_000, &mut w),
            0.5,
        );
        check(mix.write_samples(&[u64::MAX / 4, 0], 48_000, &mut w), -0.5);
        let i24 = I24::new(1 << 22).unwrap();
        check(mix.write_samples(&[i24, i24], 48_000, &mut w), 0.5);
        let u24 = U24::new((1 << 23) + (1 << 22)).unwrap();
        check(mix.write_samples(&[u24, u24], 48_000, &mut w), 0.5);
        assert!(!InputMix::reads(SampleFormat::DsdU8));
        assert!(InputMix::reads(SampleFormat::I24));
    }

    #[test]
    fn impossible_selections_are_errors_not_panics() {
        assert_eq!(
            InputMix::new(0, None).unwrap_err(),
            InputMixError::ChannelCount(0)
        );
        assert_eq!(
            InputMix::new(65, None).unwrap_err(),
            InputMixError::ChannelCount(65)
        );
        assert!(matches!(
            InputMix::new(2, Some(&[3])).unwrap_err(),
            InputMixError::NoSuchChannel { channel: 3, .. }
        ));
        assert!(matches!(
            InputMix::new(4, Some(&[1, 1])).unwrap_err(),
            InputMixError::BadSelection(_)
        ));
        assert!(InputMix::new(4, Some(&[])).is_err());
        assert_eq!(parse_channel_list("1,2").unwrap(), vec![1, 2]);
        assert_eq!(parse_channel_list("1, 5-7").unwrap(), vec![1, 5, 6, 7]);
        assert!(parse_channel_list("2-1").is_err());
        assert!(parse_channel_list("x").is_err());
    }
}
