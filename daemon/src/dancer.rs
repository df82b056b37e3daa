//! The motion source the live pipeline dances with. For now a procedural stand-in (the hips bob
//! on the beat, the arms and spine sway over the bar); the merge swaps in the shipped retrieval
//! dancer here, and only here.

use dsp::feature::{FEATURE_DIM, FeatureLayout};
use glam::{Quat, Vec3};
use model::rig::{JOINT_COUNT, Joint, Pose, Skeleton};
use model::source::{Controls, MotionSource};

/// Frame rate of the stand-in dancer (the retrieval dancer's rate, so timing behaves the same).
pub const STUB_FPS: f64 = 25.0;

/// The motion source `danced run` uses.
pub fn default_source(seed: u64) -> anyhow::Result<Box<dyn MotionSource + Send>> {
    let mut s = ProceduralDancer::new();
    s.reset(seed);
    Ok(Box::new(s))
}

/// Bobs and sways to the beat and bar phases of the features; keeps a 2 Hz clock of its own
/// when no beat is heard, so the character never freezes.
#[derive(Clone, Debug)]
pub struct ProceduralDancer {
    own_phase: f32,
    sway_sign: f32,
    hip_height: f32,
}

impl Default for ProceduralDancer {
    fn default() -> Self {
        Self::new()
    }
}

impl ProceduralDancer {
    /// A dancer on the default adult rig.
    pub fn new() -> Self {
        Self {
            own_phase: 0.0,
            sway_sign: 1.0,
            hip_height: Skeleton::default_adult().hip_height(),
        }
    }
}

impl MotionSource for ProceduralDancer {
    fn frame_rate(&self) -> f64 {
        STUB_FPS
    }

    fn lookahead_frames(&self) -> usize {
        0
    }

    fn step(&mut self, music: &[[f32; FEATURE_DIM]], controls: &Controls, out: &mut Pose) {
        use std::f32::consts::TAU;
        let f = music.first().copied().unwrap_or([0.0; FEATURE_DIM]);
        let tempo = f[FeatureLayout::TEMPO];
        self.own_phase = (self.own_phase + 2.0 / STUB_FPS as f32).fract();
        let (beat, bar) = if tempo > 0.0 && f.iter().all(|v| v.is_finite()) {
            (
                f[FeatureLayout::BEAT_SIN].atan2(f[FeatureLayout::BEAT_COS]),
                f[FeatureLayout::BAR_SIN].atan2(f[FeatureLayout::BAR_COS]),
            )
        } else {
            (TAU * self.own_phase, TAU * self.own_phase / 4.0)
        };
        let amp = 1.0 + controls.temperature.clamp(0.0, 2.0);
        let mut pose = Pose::rest();
        // Lowest on the beat (phase 0), highest between beats.
        pose.root_position = Vec3::new(
            0.0,
            self.hip_height - 0.03 * amp * (0.5 + 0.5 * beat.cos()),
            0.0,
        );
        let sway = self.sway_sign * 0.12 * amp * (2.0 * bar).sin();
        pose.set_rotation(Joint::Hips, Quat::from_rotation_y(0.5 * sway));
        pose.set_rotation(Joint::Spine, Quat::from_rotation_z(0.5 * sway));
        pose.set_rotation(Joint::Chest, Quat::from_rotation_z(0.3 * sway));
        let arm = 0.25 * amp * beat.sin();
        pose.set_rotation(Joint::LeftUpperArm, Quat::from_rotation_z(-1.1 + arm));
        pose.set_rotation(Joint::RightUpperArm, Quat::from_rotation_z(1.1 + arm));
        pose.set_rotation(Joint::LeftLowerArm, Quat::from_rotation_y(0.4 + 0.3 * arm));
        pose.set_rotation(
            Joint::RightLowerArm,
            Quat::from_rotation_y(-0.4 - 0.3 * arm),
        );
        let knee = 0.15 * amp * (0.5 + 0.5 * beat.cos());
        pose.set_rotation(Joint::LeftLowerLeg, Quat::from_rotation_x(knee));
        pose.set_rotation(Joint::RightLowerLeg, Quat::from_rotation_x(knee));
        if let Some(key) = &controls.key_pose {
            // Ramp into the key pose over the last 12 frames, exactly on it at frames_to_go 0.
            let w = (1.0 - key.frames_to_go as f32 / 12.0).clamp(0.0, 1.0);
            for i in 0..JOINT_COUNT {
                pose.local_rotations[i] = pose.local_rotations[i]
                    .slerp(key.rotations[i], w)
                    .normalize();
            }
        }
        *out = pose;
    }

    fn reset(&mut self, seed: u64) {
        self.own_phase = 0.0;
        // The seed picks the sway direction: enough to make seeds visibly different.
        self.sway_sign = if seed.is_multiple_of(2) { 1.0 } else { -1.0 };
    }
}
