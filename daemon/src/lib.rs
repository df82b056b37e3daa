//! danced: listens to music and makes a character dance to it, live.
//!
//! This crate wires the `dsp` analysis to files, commands and the live pipeline.

#![warn(missing_docs)]

pub mod alloc_counter;
pub mod bench;
pub mod command;
pub mod dancer;
pub mod demo_track;
pub mod eval;
pub mod frame;
pub mod live;
pub mod offline_dance;
pub mod pose_bank;
pub mod view;
