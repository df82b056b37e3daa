//! Wire protocols for danced: avatar frames out over OSC (our native layout, VMC, VRChat
//! trackers) and live control in (OSC and MIDI).
//!
//! This crate knows nothing about audio or the dance model: it takes the plain data types of
//! [`frame`] and [`control`] and turns them into bytes on a socket, or bytes from a socket or a
//! MIDI port into [`ControlEvent`]s. It owns no threads; the daemon decides where each piece runs.
//!
//! Bad input (packets, MIDI bytes, TOML) gives a clear error or a counted ignore, never a panic,
//! and no encoder ever puts a NaN on the wire.

#![warn(missing_docs)]

pub mod address;
pub mod clock_grid;
pub mod control;
pub mod control_receiver;
pub mod error;
pub mod finite;
pub mod frame;
pub mod human_bones;
pub mod midi;
pub mod midi_clock;
pub mod midi_input;
pub mod midi_map;
pub mod midi_output;
pub mod native;
mod osc_writer;
pub mod output_counters;
pub mod packet_pool;
pub mod sender;
pub mod tap_tempo;
pub mod timetag;
pub mod vmc;
pub mod vrchat;

pub use clock_grid::ClockGrid;
pub use control::{ControlEvent, ControlParser, Quantize};
pub use control_receiver::{ControlReceiver, DEFAULT_CONTROL_PORT};
pub use error::ProtocolError;
pub use frame::{AnalysisEvent, BodyFrame, BoneSample};
pub use midi::{MidiMessage, MidiParser};
pub use midi_clock::{MidiClockFollower, MidiClockLeader};
pub use midi_input::{MidiConnection, MidiInputs, MidiPacket};
pub use midi_map::MidiMap;
pub use midi_output::MidiOutConnection;
pub use native::{DEFAULT_NATIVE_PREFIX, NativeEncoder};
pub use output_counters::OutputCounters;
pub use packet_pool::PacketPool;
pub use sender::{OscOutput, OscTarget, TargetKind, parse_target};
pub use tap_tempo::TapTempo;
pub use vmc::VmcEncoder;
pub use vrchat::{
    VrchatEncoder, VrchatTrackerMap, unity_euler_degrees, unity_quat_from_euler_degrees,
};
