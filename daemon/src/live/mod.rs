//! The live pipeline: audio in (sound card or file replay) → ring → analysis → motion →
//! paced sender → [`sink::FrameSink`], with live controls, stats and a status line; [`run`]
//! wires a whole run (config, audio, dancer, outputs, view) for the commands that dance live.

pub mod analysis;
pub mod beat_clock;
pub mod capture;
pub mod clock;
pub mod config;
pub mod context;
pub mod control_queue;
pub mod devices;
pub mod grid_steer;
pub mod input_mix;
pub mod io;
pub mod link;
pub mod midi_clock_out;
pub mod motion;
pub mod pipeline;
pub mod priority;
pub mod replay;
pub mod ring;
pub mod run;
pub mod scheduler;
pub mod sink;
pub mod stats;
pub mod status;
pub mod timeline;
pub mod wire;
