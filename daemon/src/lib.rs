//! danced: listens to music and makes a character dance to it, live.
//!
//! The body of the `danced` binary: the live pipeline ([`live`]) and the browser view
//! ([`view`]), the shipped dancers ([`dancer`]), dancing a whole song offline
//! ([`offline_dance`]), the measurements ([`bench`](mod@bench), [`eval`]), and one module per
//! command ([`command`]). The work on files (decoding, offline analysis, the training data) is
//! the `offline` crate's, shared with `danced-train`.

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
