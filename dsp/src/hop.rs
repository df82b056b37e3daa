//! What the analysis knows about one hop, as handed to sinks and the feature framer.

use crate::bar_features::BarFeatures;
use crate::beat_activation::BEAT_INPUT_DIM;

/// Everything known about one analysis hop (11.6 ms). Slices borrow the analyzer's buffers.
#[derive(Clone, Copy, Debug)]
pub struct HopFrame<'a> {
    /// Hop number from the start of the stream.
    pub index: u64,
    /// Audio time described (centre of the short window), in seconds.
    pub time_s: f64,
    /// Stream time at which this hop was computed, in seconds.
    pub decided_at_s: f64,
    /// Log-mel power spectrum, [`crate::mel::MEL_BANDS`] values in dB.
    pub mel_db: &'a [f32],
    /// RMS energy of the short window in dBFS (≥ −120).
    pub energy_db: f32,
    /// Onset strength (SuperFlux).
    pub onset_strength: f32,
    /// Onset strength in the bass bands.
    pub bass_onset_strength: f32,
    /// Inputs of the learned beat activation (zeros with a tracker that does not use it).
    pub beat_input: &'a [f32; BEAT_INPUT_DIM],
    /// Learned beat activation in [0, 1] (0 with a tracker that does not use it).
    pub beat_activation: f32,
    /// Chroma, index 0 = C.
    pub chroma: &'a [f32; 12],
    /// Tempo in BPM (0 while no beat is heard).
    pub tempo_bpm: f64,
    /// Confidence of the tempo in [0, 1].
    pub tempo_confidence: f64,
    /// Position in the beat in [0, 1).
    pub beat_phase: f64,
    /// Predicted time of the next beat, in seconds.
    pub next_beat_s: f64,
    /// Position in the bar in [0, 1).
    pub bar_phase: f64,
    /// Position of the current beat in its bar (1 = downbeat).
    pub beat_in_bar: usize,
    /// Beats per bar (3 or 4).
    pub beats_per_bar: usize,
    /// Probability the bar tracker gives the current count, in [0, 1].
    pub bar_confidence: f32,
    /// On a hop that reported a beat: the features of the beat before it, which the bar
    /// tracker just completed and classified (kept for training the downbeat network).
    pub bar_features: Option<&'a BarFeatures>,
    /// Whether a beat is heard.
    pub locked: bool,
}
