//! The wire types shared with the `protocols` crate (exact copies; replaced by
//! `use protocols::...` when the branches merge, so do not change them here).

/// One bone of a sent frame, in Unity coordinates.
#[derive(Clone, Debug, PartialEq)]
pub struct BoneSample {
    /// Unity HumanBodyBones name.
    pub bone: &'static str,
    /// Offset from the parent bone, in the parent's frame (metres).
    pub local_position: glam::Vec3,
    /// Rotation relative to the parent bone.
    pub local_rotation: glam::Quat,
    /// Position in the world (metres).
    pub world_position: glam::Vec3,
    /// Rotation in the world.
    pub world_rotation: glam::Quat,
}

/// One pose sent to the renderers, stamped with the audio time it depicts.
#[derive(Clone, Debug, PartialEq)]
pub struct BodyFrame {
    /// Sequence number of the frame, from 0.
    pub frame_index: u64,
    /// Audio time this pose depicts, seconds of stream time.
    pub audio_time_s: f64,
    /// Wall-clock time at which the frame was built for sending.
    pub timetag: std::time::SystemTime,
    /// World position of the hips (Unity coordinates, metres).
    pub root_position: glam::Vec3,
    /// World rotation of the hips (Unity coordinates).
    pub root_rotation: glam::Quat,
    /// Every bone of the rig.
    pub bones: Vec<BoneSample>,
}

/// Something the analysis heard, forwarded to the outputs.
#[derive(Clone, Debug, PartialEq)]
pub enum AnalysisEvent {
    /// A beat.
    Beat {
        /// When the beat happened, stream seconds.
        time_s: f64,
        /// Position in the bar (1 = downbeat).
        index_in_bar: u32,
        /// Beats per bar.
        beats_per_bar: u32,
        /// Tempo at the beat.
        tempo_bpm: f32,
    },
    /// An onset.
    Onset {
        /// When the onset happened, stream seconds.
        time_s: f64,
        /// Its strength.
        strength: f32,
    },
    /// Current tempo estimate.
    Tempo {
        /// Beats per minute (0 while no beat is heard).
        bpm: f32,
        /// Confidence in [0, 1].
        confidence: f32,
    },
    /// Current chroma.
    Chroma {
        /// Audio time described, stream seconds.
        time_s: f64,
        /// Pitch-class energies, index 0 = C.
        chroma: [f32; 12],
    },
    /// Current loudness.
    Energy {
        /// Audio time described, stream seconds.
        time_s: f64,
        /// RMS level in dBFS.
        db: f32,
    },
}

/// When a control takes effect.
#[derive(Clone, Debug, PartialEq)]
pub enum Quantize {
    /// Immediately.
    Now,
    /// On the next beat.
    NextBeat,
    /// On the next downbeat.
    NextBar,
    /// On the n-th beat from now.
    InBeats(u32),
}

/// A live control from the performer (OSC, MIDI, tests).
#[derive(Clone, Debug, PartialEq)]
pub enum ControlEvent {
    /// Sets the sampling temperature.
    Temperature(f32),
    /// Reach a named key pose at a quantised moment.
    KeyPose {
        /// Name in the pose bank.
        name: String,
        /// When the pose must be reached.
        quantize: Quantize,
    },
    /// Cancels a pending key pose.
    ClearKeyPose,
    /// Length of transitions, in beats.
    TransitionBeats(f32),
    /// Restarts the dancer with this seed.
    StyleSeed(u64),
    /// Holds the current pose.
    Pause,
    /// Dances again after a pause.
    Resume,
    /// The performer's idea of the tempo, BPM.
    TempoHint(f32),
}
