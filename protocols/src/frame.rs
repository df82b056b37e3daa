//! The data the daemon hands to the output side: one avatar frame, musical events.

use glam::{Quat, Vec3};
use std::time::SystemTime;

/// One bone of the avatar, all in Unity coordinates (left-handed, Y up, metres).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BoneSample {
    /// Unity `HumanBodyBones` name, e.g. "LeftUpperArm".
    pub bone: &'static str,
    /// Position relative to the parent bone.
    pub local_position: Vec3,
    /// Rotation relative to the parent, relative to the T-pose.
    pub local_rotation: Quat,
    /// Position in the avatar's world.
    pub world_position: Vec3,
    /// Rotation in the avatar's world.
    pub world_rotation: Quat,
}

/// One output frame of the avatar.
#[derive(Clone, Debug, PartialEq)]
pub struct BodyFrame {
    /// Running count of frames since the daemon started.
    pub frame_index: u64,
    /// Time in the audio stream this frame belongs to, in seconds.
    pub audio_time_s: f64,
    /// Wall-clock time the frame should be shown at (becomes the OSC bundle timetag).
    pub timetag: SystemTime,
    /// Root (avatar origin) position in the world, metres.
    pub root_position: Vec3,
    /// Root rotation in the world.
    pub root_rotation: Quat,
    /// Every bone, any order.
    pub bones: Vec<BoneSample>,
}

/// Musical events from the analysis.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum AnalysisEvent {
    /// A beat, with its place in the bar.
    Beat {
        /// Audio stream time of the beat, seconds.
        time_s: f64,
        /// Position of the beat in its bar, 1 = downbeat.
        index_in_bar: u32,
        /// Beats in the current bar.
        beats_per_bar: u32,
        /// Tempo at this beat.
        tempo_bpm: f32,
        /// Probability the bar tracker gives this count, in [0, 1].
        bar_confidence: f32,
    },
    /// The beat after the one just shown, announced ahead so effects can be scheduled on it.
    NextBeat {
        /// Audio stream time of the beat, seconds.
        time_s: f64,
        /// Wall seconds from when the message is sent until the beat is shown.
        in_s: f32,
        /// Position of the beat in its bar, 1 = downbeat.
        index_in_bar: u32,
        /// Beats in the current bar.
        beats_per_bar: u32,
        /// Tempo the prediction assumes.
        tempo_bpm: f32,
    },
    /// A note or drum onset.
    Onset {
        /// Audio stream time of the onset, seconds.
        time_s: f64,
        /// Onset strength (detector units, ≥ 0).
        strength: f32,
    },
    /// A tempo estimate.
    Tempo {
        /// Beats per minute.
        bpm: f32,
        /// Confidence in 0..1.
        confidence: f32,
    },
    /// A chroma vector (pitch-class energy, C first).
    Chroma {
        /// Audio stream time, seconds.
        time_s: f64,
        /// Energy per pitch class C, C#, ..., B.
        chroma: [f32; 12],
    },
    /// Loudness.
    Energy {
        /// Audio stream time, seconds.
        time_s: f64,
        /// Level in dB (full scale).
        db: f32,
    },
    /// How far the music is heard from the external clock followed: the median over the last
    /// heard beats of each one's offset from the clock's nearest beat.
    ClockOffset {
        /// Milliseconds; positive when the music is heard after the clock's beats.
        ms: f32,
    },
    /// How far the music sits below its own recent loudest (`dsp::LevelFollower`): 0 dB in
    /// steady music, the drop's depth in a breakdown, whatever the mastering.
    RelativeLevel {
        /// Audio stream time, seconds.
        time_s: f64,
        /// Level below the recent peak in dB (≤ 0).
        db: f32,
    },
}
