//! The neural dancer: a causal transformer over (previous pose, look-ahead music, key pose)
//! tokens whose output conditions a normalizing flow over the next pose.
//!
//! Training runs on burn in the `training` crate, which scores whole sequences at once
//! (teacher forcing, exact NLL). Live sampling does not use burn: the same weights run through
//! [`runtime::Runtime`], plain Rust with a key/value cache and preallocated buffers, because
//! `MotionSource::step` must not allocate and must cost well under 2 ms. Both sides read one
//! weight set ([`tensors::NamedTensors`]) and one architecture ([`config`]), so a test there can
//! hold them equal.

pub mod config;
pub mod dancer;
pub mod file;
pub mod lu;
pub mod music_layout;
pub mod rng;
pub mod runtime;
pub mod safety;
pub mod tensors;
pub mod token;
