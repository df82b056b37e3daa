//! The crate's error type: one enum whose variants are the kinds of failure, each carrying what
//! its message names (as symphonia's errors are).
//!
//! The variants are grouped by what failed: a file named by path, the tang2018 data set, fitting
//! a dance to the rig, BVH, the clip library file, the model file and its weights, retrieval,
//! the rig, and the dance metrics. Match on a variant to react to one kind; print the error for
//! a person (every message names the file, dance, weight or value at fault).

use std::path::PathBuf;

use crate::rig::Joint;

/// Everything that can go wrong in this crate.
#[derive(Debug, thiserror::Error)]
pub enum ModelError {
    // ---- Files named by path (the data set's files, BVH files) ----
    /// A file could not be opened, read or written.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// What the OS said.
        source: std::io::Error,
    },

    // ---- The tang2018 data set ([`crate::tang2018`]) ----
    /// A data set file was read but its content is not what the data set holds.
    #[error("{}: {reason}", path.display())]
    DataSetMalformed {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// A dance's folder has neither `skeletons.npy` + `center.npy` nor `skeletons.json`.
    #[error("{}: no skeletons.npy/center.npy or skeletons.json", .0.display())]
    DataSetNoMotion(PathBuf),

    // ---- Fitting a dance to the rig ([`crate::tang_fit`]) ----
    /// The dance is too short to estimate bone lengths from.
    #[error("{name}: {frames} frames, need at least {min}")]
    FitTooFewFrames {
        /// The dance.
        name: String,
        /// Frames it has (or usable frames, when the rest are degenerate).
        frames: usize,
        /// Frames needed.
        min: usize,
    },
    /// `points` and `center` disagree on the number of frames.
    #[error("{name}: {points} frames of points but {centers} of centre")]
    FitLengthMismatch {
        /// The dance.
        name: String,
        /// Frames of points.
        points: usize,
        /// Frames of centre.
        centers: usize,
    },
    /// The points do not describe a body (e.g. a bone of median length zero).
    #[error("{name}: degenerate data: {reason}")]
    FitDegenerate {
        /// The dance.
        name: String,
        /// What is wrong.
        reason: String,
    },

    // ---- BVH ([`crate::bvh`]) ----
    /// The text is not valid BVH; `line` is 1-based.
    #[error("line {line}: {message}")]
    BvhSyntax {
        /// 1-based line number where the problem was found.
        line: usize,
        /// What is wrong.
        message: String,
    },
    /// A BVH file's contents were rejected; names the file.
    #[error("{}: {source}", path.display())]
    BvhInFile {
        /// The file.
        path: PathBuf,
        /// What is wrong with it.
        source: Box<ModelError>,
    },
    /// A BVH file over [`crate::bvh::MAX_FILE_BYTES`].
    #[error("{}: {bytes} bytes, more than the {max} accepted", path.display(), max = crate::bvh::MAX_FILE_BYTES)]
    BvhTooLarge {
        /// The file.
        path: PathBuf,
        /// Its size.
        bytes: u64,
    },
    /// A [`crate::bvh::Bvh`] value that breaks the format's rules, or a file that cannot be put
    /// on our rig.
    #[error("{0}")]
    BvhInvalid(String),
    /// A BVH whose joint names leave a body part without a joint to drive it.
    #[error(
        "no joint of the file drives {missing} (the file's joints it could not place: {unused}); \
         name them in a joint map, a TOML file given with --joint-map:\n\n[joints]\n{example}"
    )]
    BvhUnmapped {
        /// Our joints nothing drives, comma-separated.
        missing: String,
        /// The file's joints that drive nothing, comma-separated.
        unused: String,
        /// Lines of a map for the missing joints, `"source name" = "OurJoint"`.
        example: String,
    },

    // ---- The clip library file ([`crate::clip_file`]) ----
    /// Not a clip library (wrong magic).
    #[error("not a danced clip library (the file does not start with DANCLIPS)")]
    ClipBadMagic,
    /// A clip library written by a newer or older layout.
    #[error("clip library format version {found}, this build reads version {supported}", supported = crate::clip_file::CLIP_FILE_VERSION)]
    ClipVersion {
        /// The version in the file.
        found: u32,
    },
    /// The clip library file ends early.
    #[error("the clip library is truncated ({what} missing)")]
    ClipTruncated {
        /// What was being read.
        what: &'static str,
    },
    /// The clip library's checksum does not match: the file is corrupted.
    #[error("the clip library is corrupted (checksum mismatch)")]
    ClipChecksum,
    /// The clip library's content is inconsistent (a clip outside the poses, non-finite
    /// values, …).
    #[error("the clip library is invalid: {0}")]
    ClipInvalid(String),

    // ---- The model file ([`crate::neural::file`]) and its network ----
    /// Reading or writing a model file failed (`?` on an I/O error gives this kind).
    #[error("model file I/O: {0}")]
    ModelFileIo(#[from] std::io::Error),
    /// The file does not start with the model magic.
    #[error("not a danced model file (bad magic)")]
    ModelFileBadMagic,
    /// The model file ends early.
    #[error("model file is truncated")]
    ModelFileTruncated,
    /// The model file's checksum does not match the content.
    #[error("model file is corrupted (checksum mismatch)")]
    ModelFileChecksum,
    /// A model file format version this build cannot read.
    #[error("model file format version {found}, this build reads {supported}", supported = crate::neural::file::FORMAT_VERSION)]
    ModelFileVersion {
        /// Version in the file.
        found: u32,
    },
    /// The model's metadata is not valid JSON of the expected shape.
    #[error("model metadata: {0}")]
    ModelFileMetadata(String),
    /// The model was made for different features, rig, rate or music layout.
    #[error("model mismatch: {0}")]
    ModelFileMismatch(String),
    /// A network configuration that cannot build a network
    /// ([`crate::neural::config::NetConfig::check`]); the message is the reason alone.
    #[error("{0}")]
    BadNetConfig(String),
    /// The weight set lacks a tensor the network needs.
    #[error("weight `{0}` is missing")]
    WeightMissing(String),
    /// A tensor's shape is not the one the configuration implies.
    #[error("weight `{name}` has shape {found:?}, expected {expected:?}")]
    WeightShape {
        /// Tensor name.
        name: String,
        /// Shape found.
        found: Vec<usize>,
        /// Shape expected.
        expected: Vec<usize>,
    },
    /// A weight holds a NaN or infinite value.
    #[error("weight `{0}` holds a non-finite value")]
    WeightNotFinite(String),
    /// A permutation tensor is not a permutation.
    #[error("weight `{0}` is not a permutation")]
    WeightNotPermutation(String),

    // ---- Retrieval ([`crate::retrieval`]) ----
    /// No dance yielded a usable one-beat clip.
    #[error("the clip library is empty: no dance had two beat-phase wraps with finite poses")]
    EmptyClipLibrary,

    // ---- The rig ([`crate::rig`]) ----
    /// A bone length was negative, infinite or NaN.
    #[error("invalid length {length} for bone {joint}: must be finite and non-negative")]
    InvalidBoneLength {
        /// The bone (named by its child joint).
        joint: Joint,
        /// The rejected length in metres.
        length: f32,
    },
    /// A name is not one of the rig's `HumanBodyBones` names.
    #[error("unknown joint name {0:?}")]
    UnknownJoint(String),

    // ---- The dance metrics ([`crate::metrics`]) ----
    /// A track was declared with zero joints per frame.
    #[error("a joint track needs at least one joint per frame")]
    NoJoints,
    /// The position count is not a whole number of frames.
    #[error("{len} positions are not a whole number of {joints}-joint frames")]
    RaggedTrack {
        /// Number of positions given.
        len: usize,
        /// Declared joints per frame.
        joints: usize,
    },
    /// The frame rate is zero, negative or not finite.
    #[error("frame rate {0} is not a positive finite number")]
    BadFrameRate(f64),
    /// A joint position is NaN or infinite.
    #[error("joint position {index} (row-major) is not finite")]
    NonFinitePosition {
        /// Index into the flat position slice.
        index: usize,
    },
    /// A joint index does not exist in the track.
    #[error("joint {joint} is out of range for a {joints}-joint track")]
    JointOutOfRange {
        /// The index asked for.
        joint: usize,
        /// Joints per frame in the track.
        joints: usize,
    },
    /// Tracks or feature vectors that must agree in size do not.
    #[error("expected dimension {expected}, found {found}")]
    DimensionMismatch {
        /// Size of the first track or vector.
        expected: usize,
        /// Size of the offending one.
        found: usize,
    },
    /// A motion shows no beat: no periodic stops between the slowest and fastest tempo looked
    /// for.
    #[error("the motion shows no beat between 55 and 190 BPM")]
    NoPulse,
    /// Too little data for the statistic (e.g. one sample has no covariance).
    #[error("need at least {needed} {what}, got {found}")]
    TooShort {
        /// What was counted ("frames", "samples").
        what: &'static str,
        /// Minimum required.
        needed: usize,
        /// What was given.
        found: usize,
    },
    /// A feature value or Gaussian parameter is NaN or infinite.
    #[error("feature value {dim} of sample {sample} is not finite")]
    NonFiniteFeature {
        /// Sample (row) index.
        sample: usize,
        /// Dimension (column) index.
        dim: usize,
    },
    /// The motion has no kinematic beat to measure against.
    #[error("no kinematic beats were found in the track")]
    NoKinematicBeats,
    /// No finite music beat falls within the track's time span.
    #[error("no music beats fall within the track's time span")]
    NoMusicBeats,
    /// A tuning parameter is out of its valid range.
    #[error("parameter {name} = {value} is out of range")]
    BadParameter {
        /// Parameter name.
        name: &'static str,
        /// Value given.
        value: f64,
    },
    /// The eigendecomposition did not converge (should not happen on finite input).
    #[error("symmetric eigendecomposition did not converge")]
    EigenFailed,
}
