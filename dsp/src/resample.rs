//! Downmix and resample any input stream to the analysis rate, block by block.

use rubato::audioadapter_buffers::direct::InterleavedSlice;
use rubato::{Fft, FixedSync, Resampler};

use crate::{ANALYSIS_RATE, DspError, MAX_INPUT_RATE, MIN_INPUT_RATE};

/// Largest sample magnitude passed on (+18 dBFS): beyond it a driver is sending garbage, and
/// squaring such values would overflow the energy to infinity.
const MAX_SAMPLE: f32 = 8.0;

/// Input frames gathered before each resampler call: small, because the wait adds latency.
const CHUNK_HINT: usize = 256;

/// Turns interleaved PCM of any channel count and rate into mono samples at [`ANALYSIS_RATE`].
///
/// Non-finite input samples are replaced by silence and huge ones clamped, so that one bad sample from a driver cannot
/// poison every later feature.
pub struct StreamResampler {
    channels: usize,
    input_rate: u32,
    resampler: Option<Fft<f32>>,
    chunk: Vec<f32>,
    filled: usize,
    out: Vec<f32>,
    consumed_frames: u64,
}

impl StreamResampler {
    /// Builds a resampler for `channels` interleaved channels at `input_rate` Hz.
    pub fn new(input_rate: u32, channels: u16) -> Result<Self, DspError> {
        if !(MIN_INPUT_RATE..=MAX_INPUT_RATE).contains(&input_rate) {
            return Err(DspError::SampleRate(input_rate));
        }
        if channels == 0 {
            return Err(DspError::NoChannels);
        }
        let (resampler, chunk_len, out_len) = if input_rate == ANALYSIS_RATE {
            (None, CHUNK_HINT, CHUNK_HINT)
        } else {
            let r = Fft::<f32>::new(
                input_rate as usize,
                ANALYSIS_RATE as usize,
                CHUNK_HINT,
                1,
                FixedSync::Input,
            )
            .map_err(|e| DspError::Resampler {
                from: input_rate,
                reason: e.to_string(),
            })?;
            let chunk_len = r.input_frames_max();
            let out_len = r.output_frames_max();
            (Some(r), chunk_len, out_len)
        };
        Ok(Self {
            channels: channels as usize,
            input_rate,
            resampler,
            chunk: vec![0.0; chunk_len],
            filled: 0,
            out: vec![0.0; out_len],
            consumed_frames: 0,
        })
    }

    /// The input sample rate in Hz.
    pub fn input_rate(&self) -> u32 {
        self.input_rate
    }

    /// The input channel count.
    pub fn channels(&self) -> usize {
        self.channels
    }

    /// How many output samples lag behind the input they represent (the resampler's own delay).
    pub fn delay_samples(&self) -> usize {
        self.resampler.as_ref().map_or(0, |r| r.output_delay())
    }

    /// Input frames consumed so far (the stream clock, in input samples).
    pub fn consumed_frames(&self) -> u64 {
        self.consumed_frames
    }

    /// Feeds interleaved samples; `emit` receives each finished run of mono analysis-rate samples
    /// together with the input time (seconds) consumed when it was produced.
    ///
    /// A trailing partial frame (fewer samples than channels) is ignored.
    pub fn push(&mut self, interleaved: &[f32], emit: &mut impl FnMut(&[f32], f64)) {
        let ch = self.channels;
        let norm = 1.0 / ch as f32;
        for frame in interleaved.chunks_exact(ch) {
            let mut s = 0.0f32;
            for &x in frame {
                s += if x.is_finite() {
                    x.clamp(-MAX_SAMPLE, MAX_SAMPLE)
                } else {
                    0.0
                };
            }
            self.chunk[self.filled] = s * norm;
            self.filled += 1;
            self.consumed_frames += 1;
            if self.filled == self.chunk.len() {
                self.flush_chunk(emit);
            }
        }
        // Without resampling there is nothing to wait for: hand over what this block brought.
        if self.resampler.is_none() && self.filled > 0 {
            self.flush_chunk(emit);
        }
    }

    fn flush_chunk(&mut self, emit: &mut impl FnMut(&[f32], f64)) {
        let now = self.consumed_frames as f64 / self.input_rate as f64;
        let filled = self.filled;
        self.filled = 0;
        match self.resampler.as_mut() {
            None => emit(&self.chunk[..filled], now),
            Some(r) => {
                let n_in = self.chunk.len();
                let n_out = self.out.len();
                let (Ok(input), Ok(mut output)) = (
                    InterleavedSlice::new(&self.chunk[..], 1, n_in),
                    InterleavedSlice::new_mut(&mut self.out[..], 1, n_out),
                ) else {
                    return;
                };
                // Sizes come from the resampler itself, so an error here means a rubato bug;
                // dropping one chunk is better than stopping the analysis.
                if let Ok((_, produced)) = r.process_into_buffer(&input, &mut output, None) {
                    emit(&self.out[..produced], now);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(rate: u32, channels: u16, seconds: f64, freq: f64) -> (Vec<f32>, usize) {
        let mut r = StreamResampler::new(rate, channels).unwrap();
        let n = (rate as f64 * seconds) as usize;
        let mut input = Vec::with_capacity(n * channels as usize);
        for i in 0..n {
            let x = (2.0 * std::f64::consts::PI * freq * i as f64 / rate as f64).sin() as f32 * 0.5;
            for _ in 0..channels {
                input.push(x);
            }
        }
        let mut out = Vec::new();
        for block in input.chunks(333 * channels as usize) {
            r.push(block, &mut |s, _| out.extend_from_slice(s));
        }
        (out, r.delay_samples())
    }

    #[test]
    fn resamples_48k_stereo_sine_to_analysis_rate() {
        let (out, delay) = run(48_000, 2, 2.0, 440.0);
        let expected = 2.0 * ANALYSIS_RATE as f64;
        assert!(
            (out.len() as f64 - expected).abs() < 2000.0,
            "len {}",
            out.len()
        );
        // Amplitude and frequency survive: count zero crossings in the steady part.
        let steady = &out[delay + 2000..out.len() - 2000];
        let peak = steady.iter().fold(0.0f32, |m, x| m.max(x.abs()));
        assert!((peak - 0.5).abs() < 0.02, "peak {peak}");
        let crossings = steady
            .windows(2)
            .filter(|w| w[0] < 0.0 && w[1] >= 0.0)
            .count();
        let secs = steady.len() as f64 / ANALYSIS_RATE as f64;
        assert!((crossings as f64 / secs - 440.0).abs() < 3.0);
    }

    #[test]
    fn passes_through_at_analysis_rate_and_downmixes() {
        let mut r = StreamResampler::new(ANALYSIS_RATE, 2).unwrap();
        let input: Vec<f32> = (0..2048)
            .flat_map(|i| {
                let x = (i % 100) as f32 / 100.0;
                [x, 1.0 - x]
            })
            .collect();
        let mut out = Vec::new();
        r.push(&input, &mut |s, _| out.extend_from_slice(s));
        assert_eq!(out.len(), 2048);
        assert!(out.iter().all(|&x| (x - 0.5).abs() < 1e-6));
    }

    #[test]
    fn non_finite_input_becomes_silence() {
        let mut r = StreamResampler::new(44_100, 1).unwrap();
        let input = vec![f32::NAN; 44_100];
        let mut out = Vec::new();
        r.push(&input, &mut |s, _| out.extend_from_slice(s));
        assert!(!out.is_empty());
        assert!(out.iter().all(|x| *x == 0.0));
    }

    #[test]
    fn rejects_bad_configuration() {
        assert!(matches!(
            StreamResampler::new(1000, 1),
            Err(DspError::SampleRate(1000))
        ));
        assert!(matches!(
            StreamResampler::new(44_100, 0),
            Err(DspError::NoChannels)
        ));
    }
}
