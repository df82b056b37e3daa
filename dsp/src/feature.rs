//! The feature vector the dance model consumes, resampled from analysis hops to the model rate.
//!
//! Layout version 2 (`FEATURE_DIM` = 84 values per frame, all finite; version 1 had the first
//! 83):
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
//! | 83 | level below the recent peak ([`LevelFollower`], from index 81) | dB, [−60, 0] | short window, smoothed over 0.4 s |
//!
//! "Short window" means the feature describes audio centred half a short window (23 ms) before
//! the frame's stream time; "long window" means 93 ms before. Both add the resampler's delay
//! (0 at 22 050 Hz input). A frame's `time_s` is the audio time it describes.
//!
//! A dancer does not wait for the frame of the time it shows: it is handed
//! [`FeatureFrame::predicted_at`] of the newest frame, which extrapolates the beat grid to the
//! shown time and keeps everything else at its newest value. [`predicted_stream`] is the same
//! for a whole song, so offline generation and training data see exactly what live delivers.

use crate::grid::BeatGrid;
use crate::hop::HopFrame;
use crate::level_follower::LevelFollower;
use crate::mel::MEL_BANDS;

/// Version of the layout below; bump it whenever an index or a unit changes.
pub const FEATURE_LAYOUT_VERSION: u32 = 2;
/// Values per feature frame.
pub const FEATURE_DIM: usize = 84;
/// Values per frame in layout version 1 (everything before [`FeatureLayout::RELATIVE_LEVEL`]).
pub const FEATURE_DIM_V1: usize = 83;

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
    /// Level below the recent peak in dB ([`LevelFollower`]).
    pub const RELATIVE_LEVEL: usize = Self::TEMPO + 1;

    /// Names of every value, in order (for headers and documentation).
    pub fn names() -> Vec<String> {
        let mut v: Vec<String> = (0..MEL_BANDS).map(|i| format!("mel{i:02}")).collect();
        v.extend(["onset", "beat_sin", "beat_cos", "bar_sin", "bar_cos"].map(String::from));
        const PC: [&str; 12] = [
            "C", "Db", "D", "Eb", "E", "F", "Gb", "G", "Ab", "A", "Bb", "B",
        ];
        v.extend(PC.iter().map(|p| format!("chroma_{p}")));
        v.extend(["energy_db", "tempo_bpm", "relative_level_db"].map(String::from));
        v
    }
}

const _: () = assert!(FeatureLayout::RELATIVE_LEVEL + 1 == FEATURE_DIM);
const _: () = assert!(FeatureLayout::RELATIVE_LEVEL == FEATURE_DIM_V1);

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
    /// The beat grid known when the frame was made (stream seconds).
    pub grid: BeatGrid,
}

impl FeatureFrame {
    /// The features this frame predicts for the frame at `t_s`: beat and bar phase from the beat
    /// grid extrapolated to `t_s` (exact while the tempo holds), everything else at this frame's
    /// value (the newest known). Unlocked, the frame's own phases are kept.
    pub fn predicted_at(&self, t_s: f64) -> [f32; FEATURE_DIM] {
        let mut v = self.values;
        if let (Some(beat), Some(bar)) = (self.grid.beat_phase_at(t_s), self.grid.bar_phase_at(t_s))
        {
            let (bs, bc) = (std::f64::consts::TAU * beat).sin_cos();
            let (rs, rc) = (std::f64::consts::TAU * bar).sin_cos();
            v[FeatureLayout::BEAT_SIN] = bs as f32;
            v[FeatureLayout::BEAT_COS] = bc as f32;
            v[FeatureLayout::BAR_SIN] = rs as f32;
            v[FeatureLayout::BAR_COS] = rc as f32;
        }
        v
    }
}

/// Beat (or bar) phase in [0, 1) from its sine and cosine (as [`FeatureLayout`] carries it);
/// `None` when not finite or undefined (both near 0).
pub fn phase_of(sin: f32, cos: f32) -> Option<f32> {
    if !sin.is_finite() || !cos.is_finite() || sin * sin + cos * cos < 1e-6 {
        return None;
    }
    let p = (sin.atan2(cos) / std::f32::consts::TAU).rem_euclid(1.0);
    // rem_euclid can return exactly 1.0 for tiny negative inputs.
    Some(if p >= 1.0 { 0.0 } else { p })
}

/// The music a dancer hears, frame by frame, when each frame is predicted from the analysis
/// `horizon` frames earlier: element j is `frames[j − horizon].predicted_at(frames[j].time_s)`
/// (from the first frame while j < horizon). This is what the live pipeline hands a dancer
/// generating `horizon` frames ahead of the analysis.
pub fn predicted_stream(frames: &[FeatureFrame], horizon: usize) -> Vec<[f32; FEATURE_DIM]> {
    frames
        .iter()
        .enumerate()
        .map(|(j, f)| frames[j.saturating_sub(horizon)].predicted_at(f.time_s))
        .collect()
}

/// Resamples analysis hops (86.13 Hz) to frames at the model rate: means for spectra and energy,
/// the maximum for onset strength (so no attack falls between frames), the latest value for
/// phases and tempo; the relative level follows the framed energy.
pub struct FeatureFramer {
    rate: f64,
    level: LevelFollower,
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
            level: LevelFollower::new(rate),
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
        values[FeatureLayout::RELATIVE_LEVEL] = self.level.next(values[FeatureLayout::ENERGY]);
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
            grid: BeatGrid::from_hop(hop),
        };
        self.next_index += 1;
        self.sum = [0.0; FEATURE_DIM];
        self.onset_max = 0.0;
        self.hops = 0;
        Some(frame)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(index: u64, grid: BeatGrid) -> FeatureFrame {
        let mut values = [0.0; FEATURE_DIM];
        values[FeatureLayout::ENERGY] = index as f32;
        FeatureFrame {
            index,
            time_s: index as f64 / 25.0,
            decided_at_s: index as f64 / 25.0 + 0.03,
            values,
            grid,
        }
    }

    #[test]
    fn stream_predicts_phases_and_keeps_the_newest_spectra() {
        // 120 BPM, a downbeat at 1.0 s in 4/4.
        let grid = BeatGrid {
            next_beat_s: 1.0,
            period_s: 0.5,
            next_index_in_bar: 1,
            beats_per_bar: 4,
            bar_confidence: 1.0,
            locked: true,
        };
        let frames: Vec<FeatureFrame> = (0..60).map(|i| frame(i, grid)).collect();
        let stream = predicted_stream(&frames, 3);
        // Frame 25 (1.0 s) is predicted from frame 22: its energy, the grid's downbeat phase.
        let f = &stream[25];
        assert_eq!(f[FeatureLayout::ENERGY], 22.0);
        assert!((f[FeatureLayout::BEAT_COS] - 1.0).abs() < 1e-6);
        assert!((f[FeatureLayout::BAR_COS] - 1.0).abs() < 1e-6);
        // A quarter beat later (1.125 s is not a frame; 1.12 s is frame 28): phase 0.24.
        let f = &stream[28];
        let phase =
            f64::from(f[FeatureLayout::BEAT_SIN]).atan2(f64::from(f[FeatureLayout::BEAT_COS]));
        assert!(
            (phase / std::f64::consts::TAU - 0.24).abs() < 1e-5,
            "{phase}"
        );
        assert_eq!(stream[1][FeatureLayout::ENERGY], 0.0);
        // Unlocked, the frame's own phases stay.
        let mut lost = frame(5, BeatGrid::default());
        lost.values[FeatureLayout::BEAT_SIN] = 0.5;
        assert_eq!(lost.predicted_at(9.0)[FeatureLayout::BEAT_SIN], 0.5);
    }
}
