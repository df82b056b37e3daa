//! Motion for danced: the humanoid rig, forward kinematics, rotation conversions, motion
//! features, importers and the dance metrics every later evaluation uses.
//!
//! Like `dsp`, this crate knows nothing of threads, sockets or audio devices.

#![warn(missing_docs)]

pub mod alignment;
pub mod body_shape;
pub mod bvh;
pub mod clip_file;
pub mod error;
pub mod foot_lock;
pub mod horizon;
pub mod key_overlay;
pub mod leg_ik;
pub mod metrics;
pub mod motion;
pub mod motion_beat;
pub mod neural;
pub mod phase_follower;
pub mod retrieval;
pub mod rig;
pub mod rotation;
pub mod source;
pub mod stage;
pub mod style;
pub mod tang2018;
pub mod tang_fit;

pub use error::ModelError;
