//! The `danced-train` subcommands, one module each.

pub mod beats;
pub mod dancer;
pub mod downbeats;
