//! Onset strength (SuperFlux, Böck & Widmer 2013) and online onset peak picking.

use crate::mel::MelFilterbank;

/// Bands of the log-frequency filterbank the flux is computed on.
pub const FLUX_BANDS: usize = 96;
/// Gain inside `log10(1 + gain·|X|)`: with our spectrum scale (full-scale sine → 1) this matches
/// SuperFlux's compression of an unnormalised FFT.
const LOG_GAIN: f32 = 500.0;
/// Highest band centre counted as "low" (kick and bass) in [`OnsetDetector::low_flux`].
const LOW_BAND_HZ: f32 = 160.0;
/// Groups of adjacent flux bands summarised for the learned beat activation.
pub const FLUX_GROUPS: usize = 24;

/// Log-filtered spectral flux with a maximum filter across frequency on the reference frame,
/// which suppresses vibrato and tremolo while keeping attacks.
pub struct OnsetDetector {
    filterbank: MelFilterbank,
    bands: Vec<f32>,
    previous: Vec<f32>,
    low_bands: usize,
    flux: f32,
    low_flux: f32,
    group_flux: [f32; FLUX_GROUPS],
    primed: bool,
}

impl OnsetDetector {
    /// Builds a detector for magnitude spectra of an FFT of `fft_len` samples at `sample_rate`.
    pub fn new(fft_len: usize, sample_rate: u32) -> Self {
        let filterbank = MelFilterbank::new(FLUX_BANDS, 30.0, 11_000.0, fft_len, sample_rate);
        let low_bands = filterbank
            .centres_hz()
            .iter()
            .take_while(|&&c| c <= LOW_BAND_HZ)
            .count();
        Self {
            filterbank,
            bands: vec![0.0; FLUX_BANDS],
            previous: vec![0.0; FLUX_BANDS],
            low_bands,
            flux: 0.0,
            low_flux: 0.0,
            group_flux: [0.0; FLUX_GROUPS],
            primed: false,
        }
    }

    /// Consumes one magnitude spectrum and returns the onset strength of this frame.
    pub fn process(&mut self, magnitude: &[f32]) -> f32 {
        self.filterbank.apply(magnitude, &mut self.bands);
        for b in self.bands.iter_mut() {
            *b = (1.0 + LOG_GAIN * *b).log10();
        }
        let (mut flux, mut low) = (0.0, 0.0);
        let per_group = FLUX_BANDS / FLUX_GROUPS;
        self.group_flux = [0.0; FLUX_GROUPS];
        if self.primed {
            let n = self.bands.len();
            for b in 0..n {
                let lo = b.saturating_sub(1);
                let hi = (b + 1).min(n - 1);
                let reference = self.previous[lo..=hi]
                    .iter()
                    .fold(f32::MIN, |m, &v| m.max(v));
                let d = (self.bands[b] - reference).max(0.0);
                flux += d;
                self.group_flux[b / per_group] += d;
                if b < self.low_bands {
                    low += d;
                }
            }
        }
        self.primed = true;
        self.previous.copy_from_slice(&self.bands);
        self.flux = flux;
        self.low_flux = low;
        flux
    }

    /// Onset strength of the last frame (all bands).
    pub fn flux(&self) -> f32 {
        self.flux
    }

    /// Onset strength of the last frame in the bass bands only (kick drums, bass notes).
    pub fn low_flux(&self) -> f32 {
        self.low_flux
    }

    /// Onset strength of the last frame in [`FLUX_GROUPS`] groups of adjacent bands, low to high.
    pub fn group_flux(&self) -> &[f32; FLUX_GROUPS] {
        &self.group_flux
    }
}

/// An onset must exceed the mean strength of the last 100 ms by this factor (plus a margin).
const ONSET_MEAN_RATIO: f32 = 2.0;

/// Below this onset contrast (mean absolute deviation over mean) the signal is steady noise.
const MIN_CONTRAST: f32 = 0.3;

/// Online peak picking: a frame is an onset when it is the maximum of the recent past, rises
/// clearly above the recent mean, and is not too close to the previous onset. It looks at no
/// future frame, so an onset is reported on the frame where it is detected.
pub struct OnsetPeakPicker {
    history: Vec<f32>,
    pos: usize,
    pre_max: usize,
    pre_avg: usize,
    combine: usize,
    since_last: usize,
    level: f32,
    level_decay: f32,
    long_mean: f32,
    contrast: f32,
    long_alpha: f32,
    contrast_alpha: f32,
}

impl OnsetPeakPicker {
    /// Builds a picker for onset strengths arriving at `frame_rate` frames per second.
    pub fn new(frame_rate: f64) -> Self {
        let frames = |s: f64| ((s * frame_rate).round() as usize).max(1);
        let pre_avg = frames(0.10);
        Self {
            history: vec![0.0; pre_avg + 1],
            pos: 0,
            pre_max: frames(0.03),
            pre_avg,
            combine: frames(0.03),
            since_last: usize::MAX / 2,
            level: 0.0,
            level_decay: (-1.0 / (2.0 * frame_rate)).exp() as f32,
            long_mean: 0.0,
            // Until the signal has shown itself steady, assume it is music: the first attack of
            // a song must not be lost.
            contrast: 1.0,
            long_alpha: (1.0 / (2.0 * frame_rate)) as f32,
            contrast_alpha: (1.0 / (0.5 * frame_rate)) as f32,
        }
    }

    /// Feeds one onset strength; returns true when this frame is an onset.
    pub fn process(&mut self, strength: f32) -> bool {
        let n = self.history.len();
        self.history[self.pos] = strength;
        let at = |k: usize| self.history[(self.pos + n - k) % n];
        let is_max = (1..=self.pre_max).all(|k| strength >= at(k));
        let mean = (1..=self.pre_avg).map(at).sum::<f32>() / self.pre_avg as f32;
        // Slowly-decaying level of the strength so thresholds follow loudness; the absolute floor
        // keeps noise in near-silence from firing.
        self.level =
            self.level.max(strength) * self.level_decay + strength * (1.0 - self.level_decay);
        // Relative to the local mean, so the steady flux of noise never reads as an attack.
        let threshold = ONSET_MEAN_RATIO * mean + (0.1 * self.level).max(0.5);
        // Stationary noise has a steady flux: its deviation from the long mean stays small.
        self.long_mean += self.long_alpha * (strength - self.long_mean);
        let z = strength / (self.long_mean + 1e-3);
        self.contrast += self.contrast_alpha * ((z - 1.0).abs().min(4.0) - self.contrast);
        self.pos = (self.pos + 1) % n;
        self.since_last = self.since_last.saturating_add(1);
        if is_max
            && strength > threshold
            && self.since_last > self.combine
            && self.contrast > MIN_CONTRAST
        {
            self.since_last = 0;
            true
        } else {
            false
        }
    }
}
