//! Errors raised when an analysis chain is configured.

/// Why an analysis component could not be built (the per-block path itself never fails).
#[derive(Debug, thiserror::Error)]
pub enum DspError {
    /// The input sample rate is outside what the analysis accepts.
    #[error("unsupported sample rate {0} Hz (accepted: {min}–{max} Hz)", min = crate::MIN_INPUT_RATE, max = crate::MAX_INPUT_RATE)]
    SampleRate(u32),
    /// The input has no channels.
    #[error("audio input must have at least one channel")]
    NoChannels,
    /// The model frame rate is not usable.
    #[error("model frame rate {0} Hz is outside 1–{max} Hz", max = crate::hop_rate() as u32)]
    FrameRate(f64),
    /// The resampler refused the rate pair.
    #[error("cannot build a resampler from {from} Hz: {reason}")]
    Resampler {
        /// Input rate in Hz.
        from: u32,
        /// What rubato said.
        reason: String,
    },
    /// The selected beat tracker is not compiled into this build.
    #[error("beat tracker '{0}' is not available in this build (rebuild with `--features aubio`)")]
    TrackerUnavailable(&'static str),
    /// The aubio library refused to build one of its objects.
    #[error("aubio: {0}")]
    Aubio(String),
    /// A tuning override list (`name=value, ...`) holds an item that is not `name=value`, a
    /// value that is not a number or out of range, or a name the component does not have.
    #[error("{0}")]
    Tuning(String),
}
