//! The beat tracker as the command line names it.

use clap::ValueEnum;
use dsp::BeatTrackerKind;

/// The `--beat-tracker` / `--tracker` choice.
#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum TrackerArg {
    /// Built-in beat-pointer HMM over SuperFlux onsets.
    Native,
    /// aubio tempo/onset (GPL-3.0; needs a build with `--features aubio`).
    Aubio,
}

impl From<TrackerArg> for BeatTrackerKind {
    fn from(t: TrackerArg) -> Self {
        match t {
            TrackerArg::Native => BeatTrackerKind::Native,
            TrackerArg::Aubio => BeatTrackerKind::Aubio,
        }
    }
}
