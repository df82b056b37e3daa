//! The interface between the analyzer and a beat and onset tracker: one hop's decisions and the
//! time shift every tracker's events share.

/// Shift applied to onset and beat times relative to the short window's centre, in seconds.
///
/// A log-compressed flux rises as soon as an attack enters the newest part of the window, so the
/// detection frame's centre lies after the attack; measured on click tracks (see the tests).
pub const EVENT_TIME_OFFSET_S: f64 = 0.016;

/// Onset and beat decisions for one hop, from whichever tracker is selected.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct TrackerOutput {
    pub(crate) onset: Option<f64>,
    pub(crate) beat: Option<f64>,
    pub(crate) tempo_bpm: f64,
    pub(crate) tempo_confidence: f64,
    pub(crate) beat_phase: f64,
    pub(crate) frames_to_next_beat: f64,
    pub(crate) locked: bool,
}
