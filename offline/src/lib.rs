//! danced's work on files: audio files decoded and analysed by the same streaming code the live
//! daemon runs, the text and array files of analysis results, and the tang2018 training data
//! set built (and augmented) from them. Both binaries stand on it: `danced` (analyse, bench,
//! evaluate, audit the data) and `danced-train` (train on the data set).
//!
//! Like `dsp` and `model`, this crate knows nothing of sound cards, sockets or the live
//! pipeline's threads.

#![warn(missing_docs)]

pub mod accompaniment;
pub mod analysis;
pub mod dataset;
pub mod decode;
pub mod error;
pub mod files;
pub mod moves;
pub mod pool;
pub mod progress;
pub mod real_music;
pub mod recording_condition;

pub use error::OfflineError;
