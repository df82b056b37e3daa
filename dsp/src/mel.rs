//! Triangular mel filterbank over a magnitude spectrum.

/// Number of mel bands in the published features.
pub const MEL_BANDS: usize = 64;
/// Lowest mel band edge in Hz.
pub const MEL_FMIN: f32 = 30.0;
/// Highest mel band edge in Hz.
pub const MEL_FMAX: f32 = 11_000.0;

fn hz_to_mel(f: f32) -> f32 {
    2595.0 * (1.0 + f / 700.0).log10()
}

fn mel_to_hz(m: f32) -> f32 {
    700.0 * (10f32.powf(m / 2595.0) - 1.0)
}

/// Sparse triangular filters (HTK mel scale), each stored as its first bin and weights.
pub struct MelFilterbank {
    starts: Vec<usize>,
    weights: Vec<Vec<f32>>,
    band_hz: Vec<f32>,
}

impl MelFilterbank {
    /// Builds `bands` filters between `fmin` and `fmax` for an FFT of `fft_len` at `sample_rate`.
    ///
    /// Each filter has unit peak; bands narrower than one FFT bin still get their nearest bin,
    /// so no band is ever identically zero.
    pub fn new(bands: usize, fmin: f32, fmax: f32, fft_len: usize, sample_rate: u32) -> Self {
        let bins = fft_len / 2 + 1;
        let bin_hz = sample_rate as f32 / fft_len as f32;
        let (mlo, mhi) = (hz_to_mel(fmin), hz_to_mel(fmax));
        let edges: Vec<f32> = (0..bands + 2)
            .map(|i| mel_to_hz(mlo + (mhi - mlo) * i as f32 / (bands + 1) as f32))
            .collect();
        let mut starts = Vec::with_capacity(bands);
        let mut weights = Vec::with_capacity(bands);
        for b in 0..bands {
            let (lo, c, hi) = (edges[b], edges[b + 1], edges[b + 2]);
            let mut w = Vec::new();
            let first = ((lo / bin_hz).floor() as usize).min(bins - 1);
            let last = ((hi / bin_hz).ceil() as usize).min(bins - 1);
            for k in first..=last {
                let f = k as f32 * bin_hz;
                let v = if f <= c {
                    (f - lo) / (c - lo)
                } else {
                    (hi - f) / (hi - c)
                };
                w.push(v.clamp(0.0, 1.0));
            }
            if w.iter().all(|&v| v == 0.0) {
                let nearest = ((c / bin_hz).round() as usize).clamp(first, last);
                w[nearest - first] = 1.0;
            }
            starts.push(first);
            weights.push(w);
        }
        Self {
            starts,
            weights,
            band_hz: edges[1..=bands].to_vec(),
        }
    }

    /// Number of bands.
    pub fn bands(&self) -> usize {
        self.starts.len()
    }

    /// Centre frequency of each band in Hz.
    pub fn centres_hz(&self) -> &[f32] {
        &self.band_hz
    }

    /// Applies the filters to `spectrum` (magnitude or power), writing one value per band.
    pub fn apply(&self, spectrum: &[f32], out: &mut [f32]) {
        for ((o, &s), w) in out.iter_mut().zip(&self.starts).zip(&self.weights) {
            *o = w.iter().zip(&spectrum[s..]).map(|(a, b)| a * b).sum();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_tone_lights_the_band_around_its_frequency() {
        let fb = MelFilterbank::new(MEL_BANDS, MEL_FMIN, MEL_FMAX, 1024, 22_050);
        let mut spec = vec![0.0; 513];
        let bin = (1000.0f32 / (22_050.0 / 1024.0)).round() as usize;
        spec[bin] = 1.0;
        let mut out = vec![0.0; MEL_BANDS];
        fb.apply(&spec, &mut out);
        let best = out
            .iter()
            .enumerate()
            .max_by(|a, b| a.1.total_cmp(b.1))
            .unwrap()
            .0;
        let centre = fb.centres_hz()[best];
        assert!((centre - 1000.0).abs() < 100.0, "band centre {centre}");
        assert!(out.iter().all(|v| v.is_finite()));
    }

    #[test]
    fn every_band_sees_some_bin() {
        let fb = MelFilterbank::new(MEL_BANDS, MEL_FMIN, MEL_FMAX, 1024, 22_050);
        let spec = vec![1.0; 513];
        let mut out = vec![0.0; MEL_BANDS];
        fb.apply(&spec, &mut out);
        assert!(out.iter().all(|&v| v > 0.0));
    }
}
