//! The crate's error type: a kind, for code that reacts, and a message, for the person who
//! reads it (as cpal's errors are).

/// What went wrong, in kinds a caller can react to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TrainingErrorKind {
    /// A recipe file cannot be read, is not valid TOML, or names an unknown or out-of-range
    /// setting.
    Recipe,
}

/// An error of training, with its kind and a message that names the file or setting.
#[derive(Debug, thiserror::Error)]
#[error("{message}")]
pub struct TrainingError {
    /// What kind of error it is.
    pub kind: TrainingErrorKind,
    /// What happened, for a person.
    pub message: String,
}

impl TrainingError {
    /// A recipe error.
    pub fn recipe(message: impl Into<String>) -> Self {
        Self {
            kind: TrainingErrorKind::Recipe,
            message: message.into(),
        }
    }
}
