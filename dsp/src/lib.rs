//! Streaming, causal music analysis for danced.
//!
//! Every type here is a plain struct that allocates when it is built and never again: the
//! per-block path (`Analyzer::process`) only touches preallocated buffers, so the same code runs
//! in a live audio pipeline, in `danced analyze` and in training-data extraction.
//!
//! Signal flow: interleaved PCM → [`StreamResampler`] (downmix, resample to [`ANALYSIS_RATE`]) →
//! [`Stft`] (hop [`HOP`]) → [`MelFilterbank`], [`ChromaFilterbank`], [`OnsetDetector`] →
//! [`BeatTracker`] → [`MeterTracker`] (beat-synchronous features, the downbeat network, the bar
//! pointer) → [`FeatureFramer`] at the model's frame rate.

#![warn(missing_docs)]

pub mod analyzer;
#[cfg(feature = "aubio")]
pub mod aubio_tracker;
pub mod bar_class;
pub mod bar_features;
pub mod bar_pointer;
pub mod beat;
pub mod beat_activation;
pub mod beat_counter;
pub mod chroma;
pub mod downbeat_net;
pub mod error;
pub mod feature;
pub mod grid;
pub mod hop;
pub mod level_follower;
pub mod mel;
pub mod meter;
pub mod metrics;
pub mod net_file;
pub mod onset;
pub mod resample;
pub mod stft;
pub mod tracker;
pub mod tuning;

pub use analyzer::{
    AnalysisNetworks, AnalysisSink, Analyzer, AnalyzerConfig, BeatEvent, BeatTrackerKind,
    OnsetEvent,
};
pub use bar_class::{BarClass, Level};
pub use bar_features::{BAR_FEATURE_DIM, BarFeatures};
pub use bar_pointer::BarPointerParams;
pub use beat::{BeatTracker, BeatTrackerParams};
pub use beat_activation::{
    BEAT_INPUT_DIM, BeatActivation, BeatInput, BeatNetEnsemble, BeatNetWeights,
};
pub use chroma::ChromaFilterbank;
pub use downbeat_net::{BeatWindow, DownbeatClassifier, DownbeatNetEnsemble};
pub use error::DspError;
pub use feature::{FeatureFrame, FeatureFramer, FeatureLayout, predicted_stream};
pub use grid::{BeatGrid, GridBeat};
pub use hop::HopFrame;
pub use level_follower::LevelFollower;
pub use mel::MelFilterbank;
pub use meter::MeterTracker;
pub use onset::{OnsetDetector, OnsetPeakPicker};
pub use resample::StreamResampler;
pub use stft::Stft;

/// Sample rate every input is resampled to before analysis, in Hz.
pub const ANALYSIS_RATE: u32 = 22_050;
/// Analysis hop in samples at [`ANALYSIS_RATE`] (11.6 ms, 86.13 hops per second).
pub const HOP: usize = 256;
/// Window of the short STFT (mel, energy, onsets), in samples: 46 ms.
pub const SHORT_WINDOW: usize = 1024;
/// Window of the long STFT (chroma), in samples: 186 ms, for semitone resolution in the bass.
pub const LONG_WINDOW: usize = 4096;
/// Lowest accepted input sample rate, in Hz.
pub const MIN_INPUT_RATE: u32 = 8_000;
/// Highest accepted input sample rate, in Hz.
pub const MAX_INPUT_RATE: u32 = 192_000;

/// Analysis hops per second.
pub fn hop_rate() -> f64 {
    ANALYSIS_RATE as f64 / HOP as f64
}
