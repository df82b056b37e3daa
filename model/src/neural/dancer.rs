//! [`NeuralDancer`]: the trained network as a [`MotionSource`]. Each frame pushes one token
//! (the previous output pose, the music `lookahead` frames ahead, the key pose if any) through
//! the cached transformer, draws z ~ N(0, T²I), inverts the flow and decodes the features into
//! a pose with the streaming [`MotionDecoder`]. A non-finite or exploding output is never
//! passed on: the last good pose is held and the frame counted.

use dsp::feature::FEATURE_DIM;

use crate::motion::{MOTION_FEATURE_DIM, MotionDecoder, RootState};
use crate::neural::file::{FRAME_RATE, ModelFileError, NeuralModel};
use crate::neural::rng::Rng;
use crate::neural::runtime::Runtime;
use crate::neural::token::{self, KEY_ROT_DIM, Normalizer, TOKEN_DIM};
use crate::rig::Pose;
use crate::source::{Controls, MotionSource};

/// A normalised output beyond this many standard deviations counts as exploding.
pub const EXPLODED_SIGMAS: f32 = 50.0;

/// The neural motion source.
pub struct NeuralDancer {
    runtime: Runtime,
    norm: Normalizer,
    seed_pose: Vec<f32>,
    decoder: MotionDecoder,
    rng: Rng,
    previous: Vec<f32>,
    token: Vec<f32>,
    music: Vec<f32>,
    key_raw: Vec<f32>,
    key: Vec<f32>,
    z: Vec<f32>,
    sample: Vec<f32>,
    features: [f32; MOTION_FEATURE_DIM],
    last_good: Pose,
    bad_frames: u64,
}

impl NeuralDancer {
    /// A dancer running `model` (validated already if it came from [`NeuralModel::load`]).
    pub fn new(model: &NeuralModel) -> Result<Self, ModelFileError> {
        let runtime = Runtime::new(&model.tensors, &model.config)?;
        let norm = model.normalizer()?;
        let mut seed_pose = vec![0.0; MOTION_FEATURE_DIM];
        norm.pose(
            model.tensors.get("seed.pose", &[MOTION_FEATURE_DIM])?,
            &mut seed_pose,
        );
        let mut d = NeuralDancer {
            runtime,
            norm,
            previous: seed_pose.clone(),
            seed_pose,
            decoder: MotionDecoder::new(RootState::ORIGIN),
            rng: Rng::new(0),
            token: vec![0.0; TOKEN_DIM],
            music: vec![0.0; FEATURE_DIM],
            key_raw: vec![0.0; KEY_ROT_DIM],
            key: vec![0.0; KEY_ROT_DIM],
            z: vec![0.0; MOTION_FEATURE_DIM],
            sample: vec![0.0; MOTION_FEATURE_DIM],
            features: [0.0; MOTION_FEATURE_DIM],
            last_good: Pose::rest(),
            bad_frames: 0,
        };
        d.reset(0);
        Ok(d)
    }

    /// Replaces the seed pose (raw motion features of the frame before the first): the
    /// "motion prompt" the dance starts from. Takes effect at the next reset.
    pub fn set_seed_pose(&mut self, features: &[f32; MOTION_FEATURE_DIM]) {
        self.norm.pose(features, &mut self.seed_pose);
    }

    /// The last flow sample, normalised features (for diagnostics: a held frame's culprit).
    pub fn last_sample(&self) -> &[f32] {
        &self.sample
    }

    /// Frames since the last reset whose output was non-finite or exploding (the last good
    /// pose was held instead).
    pub fn bad_frames(&self) -> u64 {
        self.bad_frames
    }
}

impl MotionSource for NeuralDancer {
    fn frame_rate(&self) -> f64 {
        FRAME_RATE
    }

    fn lookahead_frames(&self) -> usize {
        self.runtime.config().lookahead
    }

    fn step(&mut self, music: &[[f32; FEATURE_DIM]], controls: &Controls, out: &mut Pose) {
        // Short music (the stream's end) repeats its last frame; none at all reads as the mean.
        match music.get(self.lookahead_frames()).or(music.last()) {
            Some(frame) => self.norm.music(frame, &mut self.music),
            None => self.music.fill(0.0),
        }
        for v in self.music.iter_mut() {
            if !v.is_finite() {
                *v = 0.0;
            }
        }
        let key = controls.key_pose.map(|k| {
            token::key_rotations(&k.rotations, &mut self.key_raw);
            self.norm.key(&self.key_raw, &mut self.key);
            k.frames_to_go
        });
        token::fill(
            &mut self.token,
            &self.previous,
            &self.music,
            key.map(|f| (&self.key[..], f)),
        );
        self.runtime.push(&self.token);
        let t = if controls.temperature.is_finite() {
            controls.temperature.max(0.0)
        } else {
            0.0
        };
        for z in self.z.iter_mut() {
            *z = t * self.rng.normal();
        }
        self.runtime.sample(&self.z, &mut self.sample);
        let good = self
            .sample
            .iter()
            .all(|v| v.is_finite() && v.abs() < EXPLODED_SIGMAS);
        if good {
            self.norm.unpose(&self.sample, &mut self.features);
            self.decoder.decode_frame(&self.features, out);
            self.last_good = *out;
            self.previous.copy_from_slice(&self.sample);
        } else {
            self.bad_frames += 1;
            *out = self.last_good;
        }
    }

    fn reset(&mut self, seed: u64) {
        self.runtime.reset();
        self.rng = Rng::new(seed);
        self.decoder = MotionDecoder::new(RootState::ORIGIN);
        self.previous.copy_from_slice(&self.seed_pose);
        self.norm.unpose(&self.seed_pose, &mut self.features);
        let mut probe = MotionDecoder::new(RootState::ORIGIN);
        probe.decode_frame(&self.features, &mut self.last_good);
        self.bad_frames = 0;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::neural::config::NetConfig;
    use crate::neural::file::TrainingSummary;
    use crate::neural::tensors::init_net;
    use crate::source::KeyPoseTarget;
    use glam::Quat;

    fn dancer(noise: f32) -> NeuralDancer {
        let c = NetConfig::tiny();
        let mut tensors = init_net(&c, 1);
        tensors.perturb(2, noise);
        NeuralDancer::new(&NeuralModel {
            config: c,
            tensors,
            training: TrainingSummary::default(),
        })
        .unwrap()
    }

    #[test]
    fn is_deterministic_per_seed_and_finite() {
        let mut d = dancer(0.05);
        let music = vec![[0.1f32; FEATURE_DIM]; 3];
        let controls = Controls {
            temperature: 0.7,
            key_pose: Some(KeyPoseTarget {
                rotations: [Quat::IDENTITY; 22],
                frames_to_go: 12,
            }),
        };
        let run = |d: &mut NeuralDancer| {
            d.reset(5);
            let mut pose = Pose::rest();
            let mut out = Vec::new();
            for _ in 0..40 {
                d.step(&music, &controls, &mut pose);
                out.push(pose);
            }
            out
        };
        let a = run(&mut d);
        let b = run(&mut d);
        assert_eq!(a, b);
        assert!(a.iter().all(|p| p.is_finite()));
        assert_eq!(d.lookahead_frames(), 2);
    }

    #[test]
    fn exploding_output_holds_the_last_good_pose() {
        // A saturated coupling scale makes the flow's inverse overflow: every frame must be caught.
        let c = NetConfig::tiny();
        let mut tensors = init_net(&c, 1);
        let rest = c.flow().rest();
        let mut b = vec![-300.0; rest];
        b.extend(vec![0.0; rest]);
        tensors.insert("flow.0.c2.b", &[2 * rest], b);
        let model = NeuralModel {
            config: c,
            tensors,
            training: TrainingSummary::default(),
        };
        let mut d = NeuralDancer::new(&model).unwrap();
        d.reset(1);
        let mut pose = Pose::rest();
        let controls = Controls {
            temperature: 1.0,
            key_pose: None,
        };
        for _ in 0..10 {
            d.step(&[[0.0; FEATURE_DIM]], &controls, &mut pose);
            assert!(pose.is_finite());
        }
        assert_eq!(d.bad_frames(), 10);
    }
}
