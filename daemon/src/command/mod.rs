//! The `danced` commands, one module each; `main.rs` only parses and dispatches.

pub mod analyze;
pub mod bench_beats;
pub mod bench_clock;
pub mod bench_cues;
pub mod bench_lag;
pub mod bench_live;
pub mod bench_model;
pub mod bench_motion_beats;
pub mod bench_moves;
pub mod bench_stage;
pub mod bvh_export;
pub mod clock_args;
pub mod dataset;
pub mod demo;
pub mod devices;
pub mod eval;
pub mod generate;
pub mod import_args;
pub mod library;
pub mod metrics;
pub mod moved;
pub mod run;
pub mod source;
pub mod tracker;
pub mod view;
pub mod view_flag;
