//! Pitch-class profile (chroma) from a long-window magnitude spectrum, tuned to A = 440 Hz.

/// Lowest frequency folded into chroma (about C2).
const FMIN: f32 = 60.0;
/// Highest frequency folded into chroma (about C7): above it harmonics blur the classes.
const FMAX: f32 = 2_100.0;

/// Maps FFT bins onto the 12 pitch classes, index 0 = C, with a triangular weight that peaks on
/// the equal-tempered semitone.
pub struct ChromaFilterbank {
    bins: Vec<(usize, usize, f32)>,
}

impl ChromaFilterbank {
    /// Builds the map for an FFT of `fft_len` samples at `sample_rate`.
    pub fn new(fft_len: usize, sample_rate: u32) -> Self {
        let bin_hz = sample_rate as f32 / fft_len as f32;
        let mut bins = Vec::new();
        let first = (FMIN / bin_hz).ceil() as usize;
        let last = ((FMAX / bin_hz).floor() as usize).min(fft_len / 2);
        for k in first..=last {
            let midi = 69.0 + 12.0 * (k as f32 * bin_hz / 440.0).log2();
            let nearest = midi.round();
            let weight = 1.0 - (midi - nearest).abs() * 2.0;
            if weight > 0.0 {
                bins.push((k, (nearest as i64).rem_euclid(12) as usize, weight));
            }
        }
        Self { bins }
    }

    /// Writes the chroma of `magnitude` into `out`, normalised to a maximum of 1 (all zeros when
    /// there is no energy).
    pub fn apply(&self, magnitude: &[f32], out: &mut [f32; 12]) {
        *out = [0.0; 12];
        for &(k, pc, w) in &self.bins {
            out[pc] += w * magnitude[k] * magnitude[k];
        }
        let max = out.iter().fold(0.0f32, |m, &v| m.max(v));
        if max > 1e-10 {
            for v in out.iter_mut() {
                *v /= max;
            }
        } else {
            *out = [0.0; 12];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stft::Stft;

    fn chroma_of(freqs: &[f32]) -> [f32; 12] {
        let n = 4096;
        let frame: Vec<f32> = (0..n)
            .map(|i| {
                freqs
                    .iter()
                    .map(|f| (2.0 * std::f32::consts::PI * f * i as f32 / 22_050.0).sin())
                    .sum::<f32>()
                    * 0.2
            })
            .collect();
        let mut stft = Stft::new(n);
        let mut mag = vec![0.0; stft.bins()];
        stft.magnitude(&frame, &mut mag);
        let mut out = [0.0; 12];
        ChromaFilterbank::new(n, 22_050).apply(&mag, &mut out);
        out
    }

    #[test]
    fn a440_is_pitch_class_nine() {
        let c = chroma_of(&[440.0]);
        assert_eq!(c[9], 1.0);
        assert!(
            c.iter()
                .enumerate()
                .filter(|(i, _)| *i != 9)
                .all(|(_, v)| *v < 0.1),
            "{c:?}"
        );
    }

    #[test]
    fn c_major_triad_lights_c_e_g() {
        let c = chroma_of(&[261.63, 329.63, 392.0]);
        for pc in [0, 4, 7] {
            assert!(c[pc] > 0.5, "{c:?}");
        }
        for pc in [1, 3, 6, 10] {
            assert!(c[pc] < 0.15, "{c:?}");
        }
    }

    #[test]
    fn silence_is_all_zero() {
        let mut out = [1.0; 12];
        ChromaFilterbank::new(4096, 22_050).apply(&vec![0.0; 2049], &mut out);
        assert_eq!(out, [0.0; 12]);
    }
}
