//! The feature vector the dance model consumes, resampled from analysis hops to the model rate.
//!
//! Layout version 1 (`FEATURE_DIM` = 83 values per frame, all finite):
//!
//! | index | name | unit, range | declared latency |
//! | --- | --- | --- | --- |
//! | 0–63 | log-mel power, 64 HTK-mel bands 30 Hz–11 kHz (1024-sample window) | dB, ≥ −120 | short window |
//! | 64 | onset strength (SuperFlux, max over the frame's hops) | ≥ 0 | short window |
//! | 65, 66 | beat phase sin, cos (phase 0 = on the beat) | [−1, 1] | short window |
//! | 67, 68 | bar phase sin, cos (phase 0 = downbeat) | [−1, 1] | short window |
//! | 69–80 | chroma, index 0 = C, A = 440 Hz, max-normalised | [0, 1] | long window |
//! | 81 | RMS energy | dBFS, ≥ −120 | short window |
//! | 82 | tempo (0 while no beat is heard) | BPM | short window |
//!
//! "Short window" means the feature describes audio centred half a short window (23 ms) before
//! the frame's stream time; "long window" means 93 ms before. Both add the resampler's delay
//! (0 at 22 050 Hz input). A frame's `time_s` is the audio time it describes.

use crate::hop::HopFrame;
use crate::mel::MEL_BANDS;

/// Version of the layout below; bump it whenever an index or a unit changes.
pub const FEATURE_LAYOUT_VERSION: u32 = 1;
/// Values per feature frame.
pub const FEATURE_DIM: usize = 83;

/// Where each named feature lives in a [`FeatureFrame`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FeatureLayout;

impl FeatureLayout {
    /// First log-mel value.
    pub const MEL: usize = 0;
    /// Onset strength.
    pub const ONSET: usize = MEL_BANDS;
    /// Beat phase sine.
    pub const BEAT_SIN: usize = Self::ONSET + 1;
    /// Beat phase cosine.
    pub const BEAT_COS: usize = Self::ONSET + 2;
    /// Bar phase sine.
    pub const BAR_SIN: usize = Self::ONSET + 3;
    /// Bar phase cosine.
    pub const BAR_COS: usize = Self::ONSET + 4;
    /// First chroma value (C).
    pub const CHROMA: usize = Self::ONSET + 5;
    /// RMS energy in dBFS.
    pub const ENERGY: usize = Self::CHROMA + 12;
    /// Tempo in BPM.
    pub const TEMPO: usize = Self::ENERGY + 1;

    /// Names of every value, in order (for headers and documentation).
    pub fn names() -> Vec<String> {
        let mut v: Vec<String> = (0..MEL_BANDS).map(|i| format!("mel{i:02}")).collect();
        v.extend(["onset", "beat_sin", "beat_cos", "bar_sin", "bar_cos"].map(String::from));
        const PC: [&str; 12] = [
            "C", "Db", "D", "Eb", "E", "F", "Gb", "G", "Ab", "A", "Bb", "B",
        ];
        v.extend(PC.iter().map(|p| format!("chroma_{p}")));
        v.extend(["energy_db", "tempo_bpm"].map(String::from));
        v
    }
}

const _: () = assert!(FeatureLayout::TEMPO + 1 == FEATURE_DIM);

/// One model frame of features.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FeatureFrame {
    /// Frame number at the model rate, from 0.
    pub index: u64,
    /// Audio time this frame describes, in seconds (`index / rate`).
    pub time_s: f64,
    /// Stream time at which the frame became available, in seconds.
    pub decided_at_s: f64,
    /// The values, laid out as in [`FeatureLayout`].
    pub values: [f32; FEATURE_DIM],
}

/// Resamples analysis hops (86.13 Hz) to frames at the model rate: means for spectra and energy,
/// the maximum for onset strength (so no attack falls between frames), the latest value for
/// phases and tempo.
pub struct FeatureFramer {
    rate: f64,
    next_index: u64,
    sum: [f32; FEATURE_DIM],
    onset_max: f32,
    hops: u32,
}

impl FeatureFramer {
    /// A framer emitting `rate` frames per second (at most one per hop).
    pub fn new(rate: f64) -> Self {
        Self {
            rate,
            next_index: 0,
            sum: [0.0; FEATURE_DIM],
            onset_max: 0.0,
            hops: 0,
        }
    }

    /// The model frame rate in Hz.
    pub fn rate(&self) -> f64 {
        self.rate
    }

    /// Adds one hop; returns a finished frame when this hop reaches the next frame time.
    pub fn push(&mut self, hop: &HopFrame) -> Option<FeatureFrame> {
        for (s, &m) in self.sum[FeatureLayout::MEL..].iter_mut().zip(hop.mel_db) {
            *s += m;
        }
        for (s, &c) in self.sum[FeatureLayout::CHROMA..].iter_mut().zip(hop.chroma) {
            *s += c;
        }
        self.sum[FeatureLayout::ENERGY] += hop.energy_db;
        self.onset_max = self.onset_max.max(hop.onset_strength);
        self.hops += 1;

        let frame_time = self.next_index as f64 / self.rate;
        if hop.time_s + 1e-9 < frame_time {
            return None;
        }
        let n = self.hops as f32;
        let mut values = [0.0f32; FEATURE_DIM];
        for i in 0..MEL_BANDS {
            values[FeatureLayout::MEL + i] = self.sum[FeatureLayout::MEL + i] / n;
        }
        for i in 0..12 {
            values[FeatureLayout::CHROMA + i] = self.sum[FeatureLayout::CHROMA + i] / n;
        }
        values[FeatureLayout::ENERGY] = self.sum[FeatureLayout::ENERGY] / n;
        values[FeatureLayout::ONSET] = self.onset_max;
        let beat = std::f64::consts::TAU * hop.beat_phase;
        let bar = std::f64::consts::TAU * hop.bar_phase;
        values[FeatureLayout::BEAT_SIN] = beat.sin() as f32;
        values[FeatureLayout::BEAT_COS] = beat.cos() as f32;
        values[FeatureLayout::BAR_SIN] = bar.sin() as f32;
        values[FeatureLayout::BAR_COS] = bar.cos() as f32;
        values[FeatureLayout::TEMPO] = hop.tempo_bpm as f32;
        let frame = FeatureFrame {
            index: self.next_index,
            time_s: frame_time,
            decided_at_s: hop.decided_at_s,
            values,
        };
        self.next_index += 1;
        self.sum = [0.0; FEATURE_DIM];
        self.onset_max = 0.0;
        self.hops = 0;
        Some(frame)
    }
}
