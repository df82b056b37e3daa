//! The crate's error type: errors raised when an analysis chain is configured or a weight file
//! is read.

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
    /// A weight file ([`crate::net_file`]) does not start with its kind's magic.
    #[error("not a {kind} weight file (bad magic)")]
    NetFileMagic {
        /// What kind of file was expected.
        kind: &'static str,
    },
    /// A weight file's layout version is not this build's.
    #[error("{kind} weight file version {found} (this build reads {supported})")]
    NetFileVersion {
        /// What kind of file it is.
        kind: &'static str,
        /// The version in the file.
        found: u32,
        /// The version this build reads.
        supported: u32,
    },
    /// A weight file is shorter or longer than its header says, or holds implausible values.
    #[error("{kind} weight file is malformed: {reason}")]
    NetFileMalformed {
        /// What kind of file it is.
        kind: &'static str,
        /// What is wrong.
        reason: String,
    },
}
