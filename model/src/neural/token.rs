//! The layout of one input token: token t carries the pose of frame t − 1, the music of frame
//! t + look-ahead and the key-pose conditioning (target rotations, a count-down embedding of
//! the frames left, a flag). With no key pose the key part is zero, the flag is 0 and the
//! network adds a learned "none" vector instead.

use glam::Quat;

use crate::motion::{MOTION_FEATURE_DIM, ROTATION_DIM, ROTATIONS, heading, yaw};
use crate::rig::{JOINT_COUNT, Joint};
use crate::rotation::quat_to_6d;
use dsp::feature::FEATURE_DIM;

/// Width of the key pose's rotations (6D per joint).
pub const KEY_ROT_DIM: usize = ROTATION_DIM * JOINT_COUNT;
/// Width of the frames-to-go embedding.
pub const FTG_DIM: usize = 16;
/// Offset of the previous pose in a token.
pub const POSE_AT: usize = 0;
/// Offset of the music frame in a token.
pub const MUSIC_AT: usize = MOTION_FEATURE_DIM;
/// Offset of the key pose's rotations in a token.
pub const KEY_AT: usize = MUSIC_AT + FEATURE_DIM;
/// Offset of the frames-to-go embedding in a token.
pub const FTG_AT: usize = KEY_AT + KEY_ROT_DIM;
/// Offset of the key-pose flag (1 = a key pose is set).
pub const FLAG_AT: usize = FTG_AT + FTG_DIM;
/// Width of a token.
pub const TOKEN_DIM: usize = FLAG_AT + 1;
/// Where a token holds the relative level (the music heard below its recent peak,
/// normalised), which a `level_to_flow` network's flow reads directly.
pub const LEVEL_AT: usize = MUSIC_AT + dsp::feature::FeatureLayout::RELATIVE_LEVEL;
/// Width of the key conditioning a flow reads directly ([`key_condition`]): how far each
/// rotation feature is from the key pose, the count-down and the flag.
pub const KEY_CONDITION_DIM: usize = KEY_ROT_DIM + FTG_DIM + 1;
/// The key pose's distance per normalised rotation feature is clamped to ± this: a key pose
/// far outside the data (a feature the data holds constant has a floored deviation of 0.01)
/// must not drive the flow's couplings off their trained range.
pub const KEY_CONDITION_CLAMP: f32 = 8.0;
/// Frames-to-go beyond this are embedded as this (10 s at 25 fps): the count-down only needs
/// to be precise near the target.
pub const MAX_FRAMES_TO_GO: u32 = 250;

/// Sinusoidal embedding of the frames left until the key pose, periods from 2 to ~1000 frames.
pub fn frames_to_go_embedding(frames_to_go: u32, out: &mut [f32]) {
    let f = frames_to_go.min(MAX_FRAMES_TO_GO) as f64;
    let pairs = FTG_DIM / 2;
    for i in 0..pairs {
        let period = 2.0 * 500f64.powf(i as f64 / (pairs - 1) as f64);
        let (s, c) = (std::f64::consts::TAU * f / period).sin_cos();
        out[2 * i] = s as f32;
        out[2 * i + 1] = c as f32;
    }
}

/// A key pose's rotations in motion-feature form (6D, the hips' heading removed exactly as
/// [`crate::motion::MotionEncoder`] removes it), un-normalised.
pub fn key_rotations(rotations: &[Quat; JOINT_COUNT], out: &mut [f32]) {
    for joint in Joint::ALL {
        let q = rotations[joint.index()];
        let q = if q.is_finite() && q.length_squared() > 1e-12 {
            q.normalize()
        } else {
            Quat::IDENTITY
        };
        let q = match joint {
            Joint::Hips => yaw(-heading(q)) * q,
            _ => q,
        };
        let o = (joint.index()) * ROTATION_DIM;
        out[o..o + ROTATION_DIM].copy_from_slice(&quat_to_6d(q));
    }
}

/// Normalisation statistics of poses and music (features are fed as (x − mean) / std).
#[derive(Clone, Debug, PartialEq)]
pub struct Normalizer {
    /// Pose feature means.
    pub pose_mean: Vec<f32>,
    /// Pose feature standard deviations.
    pub pose_std: Vec<f32>,
    /// Music feature means.
    pub music_mean: Vec<f32>,
    /// Music feature standard deviations.
    pub music_std: Vec<f32>,
}

impl Normalizer {
    /// Statistics of the given frames; standard deviations are floored so constant features
    /// do not blow up.
    pub fn fit(poses: &[[f32; MOTION_FEATURE_DIM]], music: &[[f32; FEATURE_DIM]]) -> Self {
        fn stats<const N: usize>(rows: &[[f32; N]]) -> (Vec<f32>, Vec<f32>) {
            let n = rows.len().max(1) as f64;
            let mut mean = vec![0f64; N];
            let mut sq = vec![0f64; N];
            for r in rows {
                for i in 0..N {
                    mean[i] += r[i] as f64;
                    sq[i] += (r[i] as f64).powi(2);
                }
            }
            let m: Vec<f32> = mean.iter().map(|s| (s / n) as f32).collect();
            let s = (0..N)
                .map(|i| ((sq[i] / n - (mean[i] / n).powi(2)).max(0.0).sqrt() as f32).max(1e-2))
                .collect();
            (m, s)
        }
        let (pose_mean, pose_std) = stats(poses);
        let (music_mean, music_std) = stats(music);
        Normalizer {
            pose_mean,
            pose_std,
            music_mean,
            music_std,
        }
    }

    /// Identity statistics (mean 0, std 1).
    pub fn identity() -> Self {
        Normalizer {
            pose_mean: vec![0.0; MOTION_FEATURE_DIM],
            pose_std: vec![1.0; MOTION_FEATURE_DIM],
            music_mean: vec![0.0; FEATURE_DIM],
            music_std: vec![1.0; FEATURE_DIM],
        }
    }

    /// Writes the normalised pose `raw` into `out`.
    pub fn pose(&self, raw: &[f32], out: &mut [f32]) {
        for i in 0..MOTION_FEATURE_DIM {
            out[i] = (raw[i] - self.pose_mean[i]) / self.pose_std[i];
        }
    }

    /// Writes the un-normalised pose of `norm` into `out`.
    pub fn unpose(&self, norm: &[f32], out: &mut [f32]) {
        for i in 0..MOTION_FEATURE_DIM {
            out[i] = norm[i] * self.pose_std[i] + self.pose_mean[i];
        }
    }

    /// Writes the normalised music frame `raw` into `out`.
    pub fn music(&self, raw: &[f32], out: &mut [f32]) {
        for i in 0..FEATURE_DIM {
            out[i] = (raw[i] - self.music_mean[i]) / self.music_std[i];
        }
    }

    /// Writes the normalised key rotations `raw` (from [`key_rotations`]) into `out`: they share
    /// the statistics of the pose's rotation features.
    pub fn key(&self, raw: &[f32], out: &mut [f32]) {
        for i in 0..KEY_ROT_DIM {
            out[i] = (raw[i] - self.pose_mean[ROTATIONS + i]) / self.pose_std[ROTATIONS + i];
        }
    }
}

/// Fills `token` from normalised parts; `key` is the normalised key rotations and the frames
/// left, or None.
pub fn fill(token: &mut [f32], pose: &[f32], music: &[f32], key: Option<(&[f32], u32)>) {
    token[POSE_AT..POSE_AT + MOTION_FEATURE_DIM].copy_from_slice(&pose[..MOTION_FEATURE_DIM]);
    token[MUSIC_AT..MUSIC_AT + FEATURE_DIM].copy_from_slice(&music[..FEATURE_DIM]);
    match key {
        Some((rot, ftg)) => {
            token[KEY_AT..KEY_AT + KEY_ROT_DIM].copy_from_slice(&rot[..KEY_ROT_DIM]);
            frames_to_go_embedding(ftg, &mut token[FTG_AT..FTG_AT + FTG_DIM]);
            token[FLAG_AT] = 1.0;
        }
        None => {
            token[KEY_AT..FLAG_AT].fill(0.0);
            token[FLAG_AT] = 0.0;
        }
    }
}

/// The key conditioning of `token` (a filled token) into `out` (`KEY_CONDITION_DIM` values):
/// the key rotations minus the previous pose's, clamped to ±[`KEY_CONDITION_CLAMP`] (zero
/// without a key), then the count-down embedding and the flag. Fed beside the transformer's
/// context to the flow of a network built with `key_to_flow`, so the next pose can be drawn
/// towards the key directly instead of through a context shared with 63 other tokens.
pub fn key_condition(token: &[f32], out: &mut [f32]) {
    let flag = token[FLAG_AT];
    let pose = &token[POSE_AT + ROTATIONS..POSE_AT + ROTATIONS + KEY_ROT_DIM];
    let key = &token[KEY_AT..KEY_AT + KEY_ROT_DIM];
    for ((o, k), p) in out[..KEY_ROT_DIM].iter_mut().zip(key).zip(pose) {
        *o = (flag * (k - p)).clamp(-KEY_CONDITION_CLAMP, KEY_CONDITION_CLAMP);
    }
    out[KEY_ROT_DIM..KEY_CONDITION_DIM].copy_from_slice(&token[FTG_AT..TOKEN_DIM]);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn key_condition_is_the_key_minus_the_pose_and_zero_without_a_key() {
        let pose: Vec<f32> = (0..MOTION_FEATURE_DIM).map(|i| i as f32 * 0.01).collect();
        let music = [0.5; FEATURE_DIM];
        let mut key = [0.0; KEY_ROT_DIM];
        key[0] = 1.0;
        key[1] = 100.0;
        let mut token = [0.0; TOKEN_DIM];
        let mut out = [1.0; KEY_CONDITION_DIM];
        fill(&mut token, &pose, &music, Some((&key, 7)));
        key_condition(&token, &mut out);
        assert!(
            (out[0] - (1.0 - pose[ROTATIONS])).abs() < 1e-6,
            "{}",
            out[0]
        );
        assert_eq!(out[1], KEY_CONDITION_CLAMP);
        assert!((out[2] + pose[ROTATIONS + 2]).abs() < 1e-6);
        let mut ftg = [0.0; FTG_DIM];
        frames_to_go_embedding(7, &mut ftg);
        assert_eq!(&out[KEY_ROT_DIM..KEY_ROT_DIM + FTG_DIM], &ftg);
        assert_eq!(out[KEY_CONDITION_DIM - 1], 1.0);
        fill(&mut token, &pose, &music, None);
        key_condition(&token, &mut out);
        assert!(out.iter().all(|&v| v == 0.0), "{out:?}");
    }

    #[test]
    fn embedding_distinguishes_nearby_counts() {
        let mut a = [0.0; FTG_DIM];
        let mut b = [0.0; FTG_DIM];
        frames_to_go_embedding(10, &mut a);
        frames_to_go_embedding(11, &mut b);
        let d: f32 = a.iter().zip(&b).map(|(x, y)| (x - y).powi(2)).sum();
        assert!(d > 0.1, "{d}");
        // Unit pairs: every sin/cos pair has norm 1.
        assert!((a[0].powi(2) + a[1].powi(2) - 1.0).abs() < 1e-6);
    }

    #[test]
    fn key_rotations_of_rest_pose_are_identity_6d() {
        let mut out = [0.0; KEY_ROT_DIM];
        key_rotations(&[Quat::IDENTITY; JOINT_COUNT], &mut out);
        assert_eq!(&out[..6], &quat_to_6d(Quat::IDENTITY));
    }
}
