//! Training for danced, on burn: the neural dancer's trainable network and training loop, the
//! learned beat activation's and the downbeat network's, and the `danced-train` commands that run them.
//!
//! Everything here writes files the live binary reads (`.dnn` models, `.dnba` beat networks);
//! nothing here is linked into `danced`, so the live binary carries no ML framework.

#![warn(missing_docs)]

pub mod analysis_recipe;
pub mod beat_training;
pub mod body_shape;
pub mod command;
pub mod device;
pub mod downbeat_training;
pub mod error;
pub mod flow;
pub mod layers;
pub mod net;
pub mod recipe;
pub mod song_files;
pub mod train;
pub mod transformer;
