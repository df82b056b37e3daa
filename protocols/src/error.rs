//! The crate's error type.

use std::path::PathBuf;

/// Everything that can go wrong when setting up a protocol endpoint or loading a map.
#[derive(Debug, thiserror::Error)]
pub enum ProtocolError {
    /// An OSC target string is not `host:port` or does not resolve.
    #[error("bad OSC target {input:?}: {reason} (expected host:port, e.g. 127.0.0.1:39539)")]
    BadTarget {
        /// The string as given.
        input: String,
        /// What is wrong with it.
        reason: String,
    },
    /// An OSC address prefix is not usable (must start with '/', no spaces or OSC pattern characters).
    #[error(
        "bad OSC address prefix {0:?}: it must start with '/' and contain no spaces or any of #*,?[]{{}}"
    )]
    BadPrefix(String),
    /// A socket could not be bound.
    #[error("cannot bind UDP socket on {addr}: {source}")]
    Bind {
        /// The address we tried.
        addr: String,
        /// The operating system's reason.
        source: std::io::Error,
    },
    /// Any other socket error while setting up.
    #[error("socket error: {0}")]
    Io(#[from] std::io::Error),
    /// A MIDI map file could not be read.
    #[error("cannot read MIDI map {path}: {source}")]
    MapRead {
        /// The file.
        path: PathBuf,
        /// The operating system's reason.
        source: std::io::Error,
    },
    /// A MIDI map is not valid TOML or has unknown or mistyped fields.
    #[error("MIDI map is not valid: {0}")]
    MapParse(#[from] toml::de::Error),
    /// A MIDI map parses but says something impossible (note > 127, min not finite, ...).
    #[error("MIDI map is not valid: {0}")]
    MapInvalid(String),
    /// No MIDI system on this machine (e.g. no /dev/snd/seq).
    #[error("MIDI is not available on this system: {0}")]
    MidiUnavailable(String),
    /// No MIDI input port matches the requested name.
    #[error("no MIDI input port contains {wanted:?}; available: {available:?}")]
    MidiPortNotFound {
        /// The substring asked for.
        wanted: String,
        /// The ports that exist.
        available: Vec<String>,
    },
    /// A VRChat tracker map (`[output.vrchat.trackers]`) key that is neither a tracker number
    /// nor "head".
    #[error("VRChat tracker map is not valid: key {0:?} is not a tracker number 1..8 or \"head\"")]
    TrackerBadKey(String),
    /// A VRChat tracker number written with a leading zero ("01"), which would read as a
    /// different key.
    #[error(
        "VRChat tracker map is not valid: key {0:?}: write tracker numbers without leading zeros"
    )]
    TrackerLeadingZero(String),
    /// A tracker number VRChat does not have.
    #[error("VRChat tracker map is not valid: key {0:?}: VRChat has trackers 1..8 only")]
    TrackerOutOfRange(String),
    /// More trackers than VRChat has.
    #[error("VRChat tracker map is not valid: {0} trackers: VRChat has 8 at most")]
    TooManyTrackers(usize),
    /// The same tracker given twice in a VRChat tracker map.
    #[error("VRChat tracker map is not valid: tracker {0:?} is given twice")]
    TrackerDuplicate(String),
    /// A tracker number missing below a higher one: VRChat numbers its trackers densely from 1.
    #[error(
        "VRChat tracker map is not valid: tracker {missing} is missing but tracker {highest} is given (number them 1, 2, 3, ... without gaps)"
    )]
    TrackerGap {
        /// The lowest number not given.
        missing: usize,
        /// The highest number given.
        highest: usize,
    },
    /// A VRChat tracker map bone name that is not a Unity `HumanBodyBones` name.
    #[error(
        "VRChat tracker map is not valid: {key} = {bone:?}: not a Unity HumanBodyBones name (e.g. \"Hips\", \"LeftFoot\")"
    )]
    TrackerUnknownBone {
        /// The tracker key it is given for.
        key: String,
        /// The name as given.
        bone: String,
    },
    /// The MIDI port exists but connecting failed.
    #[error("cannot connect to MIDI input {port:?}: {reason}")]
    MidiConnect {
        /// The port's full name.
        port: String,
        /// midir's reason.
        reason: String,
    },
}
