//! The crate's error type.

use std::io;
use std::path::{Path, PathBuf};

use model::ModelError;

/// Everything that can go wrong in work on files: an audio file decoded or analysed, the data
/// set read, a dance built, a result written. Every message names the file or the dance.
#[derive(Debug, thiserror::Error)]
pub enum OfflineError {
    /// The audio file does not exist.
    #[error("audio file {} not found", path.display())]
    NotFound {
        /// The file that was asked for.
        path: PathBuf,
    },
    /// The audio file exists but could not be read.
    #[error("cannot read audio file {}: {error}", path.display())]
    Io {
        /// The file that failed.
        path: PathBuf,
        /// The underlying I/O error.
        error: io::Error,
    },
    /// The container or codec is not one symphonia can decode (or the file is not audio at all).
    #[error("unsupported audio format in {}: {reason}", path.display())]
    Unsupported {
        /// The file that failed.
        path: PathBuf,
        /// What was not supported.
        reason: String,
    },
    /// The file holds no audio frames (a 0-byte file, or a header declaring none).
    #[error("audio file {} contains no audio", path.display())]
    Empty {
        /// The file that failed.
        path: PathBuf,
    },
    /// The file looked like audio, but decoding failed before any audio came out.
    #[error("corrupt audio file {}: {reason}", path.display())]
    Corrupt {
        /// The file that failed.
        path: PathBuf,
        /// The last decoder or demuxer complaint.
        reason: String,
    },
    /// The analysis chain refused the audio's format.
    #[error("{path}: {source}")]
    Analysis {
        /// The file (or what the samples are, for audio in memory).
        path: String,
        /// What the analyzer said.
        source: dsp::DspError,
    },
    /// A dance of the data set could not be read, its points could not be fitted to the rig,
    /// or its fitted motion is not one the metrics take (not finite): the model crate's error,
    /// whose variant tells which.
    #[error(transparent)]
    Model(#[from] ModelError),
    /// The data set's folder could not be listed.
    #[error("reading {}", path.display())]
    DataSetFolder {
        /// The folder (`DATA/tang2018`).
        path: PathBuf,
        /// Why.
        source: ModelError,
    },
    /// A dance's reference beats could not be read.
    #[error("no reference beats ({}: {error})", path.display())]
    ReferenceBeats {
        /// The beat file.
        path: PathBuf,
        /// The underlying I/O error.
        error: io::Error,
    },
    /// A dance was to be built at a speed that is not a positive number.
    #[error("{dance}: speed {speed} is not positive")]
    Speed {
        /// The dance.
        dance: String,
        /// The speed asked for.
        speed: f64,
    },
    /// Building a dance gave nothing.
    #[error("{dance}: nothing built")]
    NothingBuilt {
        /// The dance.
        dance: String,
    },
    /// A file could not be written (or moved into place).
    #[error("{}: {error}", path.display())]
    Write {
        /// The file.
        path: PathBuf,
        /// The underlying I/O error.
        error: io::Error,
    },
    /// A folder could not be listed.
    #[error("cannot read the folder {}: {error}", path.display())]
    Folder {
        /// The folder.
        path: PathBuf,
        /// The underlying I/O error.
        error: io::Error,
    },
    /// A folder of dances holds no BVH file.
    #[error("{}: no .bvh file in the folder", .0.display())]
    NoDances(PathBuf),
    /// A dance file could not be read or put on the rig.
    #[error("{}: {source}", path.display())]
    Dance {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        source: ModelError,
    },
    /// A joint map file could not be read.
    #[error("joint map {}: {reason}", path.display())]
    JointMap {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// The data set's arrays could not be put into its `.npz` file.
    #[error("{reason}")]
    Npz {
        /// What ndarray or ndarray-npy said.
        reason: String,
    },
}

impl OfflineError {
    /// The file this error is about, where it is about one.
    pub fn path(&self) -> Option<&Path> {
        match self {
            OfflineError::NotFound { path }
            | OfflineError::Io { path, .. }
            | OfflineError::Unsupported { path, .. }
            | OfflineError::Empty { path }
            | OfflineError::Corrupt { path, .. }
            | OfflineError::DataSetFolder { path, .. }
            | OfflineError::ReferenceBeats { path, .. }
            | OfflineError::Write { path, .. }
            | OfflineError::Folder { path, .. }
            | OfflineError::NoDances(path)
            | OfflineError::Dance { path, .. }
            | OfflineError::JointMap { path, .. } => Some(path),
            OfflineError::Analysis { .. }
            | OfflineError::Model(_)
            | OfflineError::Speed { .. }
            | OfflineError::NothingBuilt { .. }
            | OfflineError::Npz { .. } => None,
        }
    }
}
