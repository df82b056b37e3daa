//! [`NeuralDancer`]: the trained network as a [`MotionSource`]. Each frame pushes one token
//! (the previous output pose, the music `lookahead` frames ahead, the key pose if any) through
//! the cached transformer, draws z ~ N(0, T²I), inverts the flow and decodes the features into
//! a pose with the streaming [`MotionDecoder`]. A non-finite or exploding output is never
//! passed on: the last good pose is held and the frame counted.
//!
//! The dance starts from a seed clip (Transflower's "motion prompt": a window of real motion
//! with its music, stored in the model file) pushed through the cache at reset, so the first
//! sampled frame already has a full window of in-distribution context: a single seed pose
//! drifted out of the data's range within a few frames.

use dsp::feature::FEATURE_DIM;

use crate::motion::{MOTION_FEATURE_DIM, MotionDecoder, ROTATIONS, RootState};
use crate::neural::file::{FRAME_RATE, ModelFileError, NeuralModel};
use crate::neural::rng::Rng;
use crate::neural::runtime::Runtime;
use crate::neural::token::{self, KEY_ROT_DIM, Normalizer, TOKEN_DIM};
use crate::rig::Pose;
use crate::source::{Controls, MotionSource};

/// A normalised output beyond this many standard deviations counts as exploding.
pub const EXPLODED_SIGMAS: f32 = 50.0;

/// Samples are clamped to the training data's range widened by this fraction of it on each
/// side: beyond the data the network extrapolates, and its own extrapolations fed back run
/// away (hips drifting up by a metre within seconds, measured before the clamp).
pub const RANGE_MARGIN: f32 = 0.05;

/// Frames before a key pose's deadline over which the sampled rotations are pulled onto it
/// (smoothstep), as the retrieval dancer does: the performer's cue lands even where the
/// network alone would arrive late or near. 0 turns it off.
pub const KEY_BLEND_FRAMES: u32 = 25;

/// After this many held frames in a row the dancer restarts from its seed clip (keeping its
/// place on the floor) rather than stand still.
pub const RESTART_AFTER_HELD: u32 = 25;

/// The neural motion source.
pub struct NeuralDancer {
    runtime: Runtime,
    norm: Normalizer,
    seed_motion: Vec<f32>,
    seed_music: Vec<f32>,
    low: Vec<f32>,
    high: Vec<f32>,
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
    held_in_a_row: u32,
    restarts: u64,
    key_blend_frames: u32,
}

impl NeuralDancer {
    /// A dancer running `model` (validated already if it came from [`NeuralModel::load`]).
    pub fn new(model: &NeuralModel) -> Result<Self, ModelFileError> {
        let runtime = Runtime::new(&model.tensors, &model.config)?;
        let norm = model.normalizer()?;
        let (motion, music) = model.seed_clip()?;
        let mut seed_motion = vec![0.0; motion.len()];
        for (raw, out) in motion
            .chunks_exact(MOTION_FEATURE_DIM)
            .zip(seed_motion.chunks_exact_mut(MOTION_FEATURE_DIM))
        {
            norm.pose(raw, out);
        }
        let mut seed_music = vec![0.0; music.len()];
        for (raw, out) in music
            .chunks_exact(FEATURE_DIM)
            .zip(seed_music.chunks_exact_mut(FEATURE_DIM))
        {
            norm.music(raw, out);
        }
        let (lo, hi) = model.pose_range()?;
        let (mut low, mut high) = (vec![0.0; MOTION_FEATURE_DIM], vec![0.0; MOTION_FEATURE_DIM]);
        let (mut l, mut h) = (vec![0.0; MOTION_FEATURE_DIM], vec![0.0; MOTION_FEATURE_DIM]);
        for i in 0..MOTION_FEATURE_DIM {
            let margin = RANGE_MARGIN * (hi[i] - lo[i]);
            l[i] = lo[i] - margin;
            h[i] = hi[i] + margin;
        }
        norm.pose(&l, &mut low);
        norm.pose(&h, &mut high);
        let mut d = NeuralDancer {
            runtime,
            norm,
            low,
            high,
            previous: vec![0.0; MOTION_FEATURE_DIM],
            seed_motion,
            seed_music,
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
            held_in_a_row: 0,
            restarts: 0,
            key_blend_frames: KEY_BLEND_FRAMES,
        };
        d.reset(0);
        Ok(d)
    }

    /// Replaces the seed clip's motion by standing still in one pose (raw motion features):
    /// the "motion prompt" the dance starts from. Takes effect at the next reset.
    pub fn set_seed_pose(&mut self, features: &[f32; MOTION_FEATURE_DIM]) {
        for row in self.seed_motion.chunks_exact_mut(MOTION_FEATURE_DIM) {
            self.norm.pose(features, row);
        }
    }

    /// Sets the frames over which a key pose is blended in before its deadline (0: the
    /// network's own arrival, unaided).
    pub fn set_key_blend_frames(&mut self, frames: u32) {
        self.key_blend_frames = frames;
    }

    /// Restarts since the last reset (after [`RESTART_AFTER_HELD`] held frames in a row).
    pub fn restarts(&self) -> u64 {
        self.restarts
    }

    /// Pushes the seed clip through the cache; the next frame continues it.
    fn prime(&mut self) {
        self.runtime.reset();
        let n = self.seed_motion.len() / MOTION_FEATURE_DIM;
        for f in 1..n {
            token::fill(
                &mut self.token,
                &self.seed_motion[(f - 1) * MOTION_FEATURE_DIM..f * MOTION_FEATURE_DIM],
                &self.seed_music[f * FEATURE_DIM..(f + 1) * FEATURE_DIM],
                None,
            );
            self.runtime.push(&self.token);
        }
        self.previous
            .copy_from_slice(&self.seed_motion[(n - 1) * MOTION_FEATURE_DIM..]);
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
            for ((s, lo), hi) in self.sample.iter_mut().zip(&self.low).zip(&self.high) {
                *s = s.clamp(*lo, *hi);
            }
            if let Some(ftg) = key.filter(|&f| f < self.key_blend_frames) {
                let x = 1.0 - ftg as f32 / self.key_blend_frames as f32;
                let w = x * x * (3.0 - 2.0 * x);
                // Both are heading-free 6D rotations in the same normalisation; the decoder
                // re-orthonormalises the blend. Fed back too, so the network sees itself arrive.
                for (s, k) in self.sample[ROTATIONS..ROTATIONS + KEY_ROT_DIM]
                    .iter_mut()
                    .zip(&self.key)
                {
                    *s += w * (k - *s);
                }
            }
            self.norm.unpose(&self.sample, &mut self.features);
            self.decoder.decode_frame(&self.features, out);
            self.last_good = *out;
            self.previous.copy_from_slice(&self.sample);
            self.held_in_a_row = 0;
        } else {
            self.bad_frames += 1;
            self.held_in_a_row += 1;
            *out = self.last_good;
            if self.held_in_a_row >= RESTART_AFTER_HELD {
                // A rare, one-frame cost (a window of tokens) instead of a frozen dancer.
                self.prime();
                self.restarts += 1;
                self.held_in_a_row = 0;
            }
        }
    }

    fn reset(&mut self, seed: u64) {
        self.prime();
        self.rng = Rng::new(seed);
        self.decoder = MotionDecoder::new(RootState::ORIGIN);
        self.norm.unpose(&self.previous, &mut self.features);
        let mut probe = MotionDecoder::new(RootState::ORIGIN);
        probe.decode_frame(&self.features, &mut self.last_good);
        self.bad_frames = 0;
        self.held_in_a_row = 0;
        self.restarts = 0;
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
    fn samples_stay_within_the_training_range() {
        let c = NetConfig::tiny();
        let mut tensors = init_net(&c, 1);
        tensors.perturb(3, 0.05);
        let mut model = NeuralModel {
            config: c,
            tensors,
            training: TrainingSummary::default(),
        };
        // A narrow range: every height between 0.9 and 1.0 m, every other feature in ±0.5.
        let mut lo = [-0.5f32; MOTION_FEATURE_DIM];
        let mut hi = [0.5f32; MOTION_FEATURE_DIM];
        lo[crate::motion::ROOT_Y] = 0.9;
        hi[crate::motion::ROOT_Y] = 1.0;
        model.set_pose_range(&[lo, hi]);
        let mut d = NeuralDancer::new(&model).unwrap();
        d.reset(4);
        let mut pose = Pose::rest();
        let controls = Controls {
            temperature: 1.0,
            key_pose: None,
        };
        let margin = RANGE_MARGIN * 0.1 + 1e-4;
        let mut sampled = 0;
        for _ in 0..100 {
            let held = d.bad_frames();
            d.step(&[[0.3; FEATURE_DIM]; 3], &controls, &mut pose);
            if d.bad_frames() > held {
                continue;
            }
            sampled += 1;
            assert!(
                (0.9 - margin..=1.0 + margin).contains(&pose.root_position.y),
                "hips at {}",
                pose.root_position.y
            );
        }
        assert!(sampled > 50, "{sampled} frames sampled");
    }

    #[test]
    fn a_key_pose_is_reached_at_its_deadline() {
        let mut d = dancer(0.05);
        d.reset(2);
        let target = Quat::from_rotation_x(0.8);
        let mut rotations = [Quat::IDENTITY; 22];
        for r in rotations.iter_mut().skip(1) {
            *r = target;
        }
        // Counts down to the key pose from 40 frames; returns the pose at the deadline.
        let arrive = |d: &mut NeuralDancer| {
            let mut pose = Pose::rest();
            let music = [[0.1f32; FEATURE_DIM]; 3];
            for ftg in (0..=40u32).rev() {
                let controls = Controls {
                    temperature: 0.5,
                    key_pose: Some(KeyPoseTarget {
                        rotations,
                        frames_to_go: ftg,
                    }),
                };
                d.step(&music, &controls, &mut pose);
            }
            pose
        };
        let pose = arrive(&mut d);
        assert_eq!(d.bad_frames(), 0);
        for j in 1..22 {
            let a = pose.local_rotations[j].angle_between(target);
            assert!(a < 0.02, "joint {j} is {a} rad off");
        }
        // Without the blend the untrained network lands anywhere.
        d.set_key_blend_frames(0);
        d.reset(2);
        let pose = arrive(&mut d);
        let worst = (1..22)
            .map(|j| pose.local_rotations[j].angle_between(target))
            .fold(0.0f32, f32::max);
        assert!(worst > 0.1, "{worst}");
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
        for _ in 0..2 * RESTART_AFTER_HELD {
            d.step(&[[0.0; FEATURE_DIM]], &controls, &mut pose);
            assert!(pose.is_finite());
        }
        assert_eq!(d.bad_frames(), 2 * RESTART_AFTER_HELD as u64);
        assert_eq!(d.restarts(), 2);
    }
}
