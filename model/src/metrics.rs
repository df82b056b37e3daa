//! Dance-quality metrics from the literature, computed on world joint positions.
//!
//! * [`beat_align`]: AI Choreographer's (FACT, Li et al. 2021) Beat Alignment Score.
//! * [`beat_offset`]: Transflower's (Valle-Pérez et al. 2021) music-to-kinematic beat offset.
//! * [`frechet_distance`], [`fpd`], [`fmd`]: Fréchet distances between Gaussians fitted to
//!   feature sets, and Transflower's pose / movement distances built on them.
//! * [`kinetic_features`], [`fid_k`], [`dist_k`]: fairmotion's kinetic features as AIST++ uses
//!   them, FACT's FID_k and its diversity Dist_k.
//! * [`detect_freezes`], [`foot_skating`]: artefact detectors of our own (no paper defines them).
//!
//! Conventions shared by every metric here: positions are in metres in a Y-up world (the rig's
//! convention and AIST++'s `up_vec="y"`), the ground is the plane y = 0 unless a parameter says
//! otherwise, frame `i` of a track sits at `i / fps` seconds and music beats are given in seconds
//! on that same clock. Every computation runs in `f64` even though positions arrive as `f32`.
//! A speed computed from frames `i` and `i + 1` belongs to the instant halfway between them,
//! `(i + 0.5) / fps`; FACT files it under frame `i + 1`, which makes its beats half a frame late.

mod beats;
mod frechet;
mod kinetic;
mod quality;

pub use beats::{
    BEAT_ALIGN_SIGMA_S, BEAT_MINIMA_HALF_WINDOW_S, BeatOffset, beat_align, beat_offset, hips_beats,
    kinematic_beats, summed_joint_speed,
};
pub use frechet::{Gaussian, fmd, fpd, frechet_distance, frechet_distance_gaussians};
pub use kinetic::{
    FEATURE_STD_EPSILON, FeatureNormaliser, KINETIC_WINDOW_S, dist_k, fid_k, kinetic_features,
    mean_pairwise_distance,
};
pub use quality::{
    ContactParams, FootSkating, FreezeParams, FreezeReport, detect_freezes, foot_skating,
    toe_floor_y,
};

use glam::{DVec3, Vec3};

use crate::ModelError;

/// World joint positions of one motion: frames × joints, row-major, metres, Y up.
///
/// Validated on construction (whole frames, finite positions, positive frame rate) so that no
/// metric has to guard against NaN input. Zero frames is allowed; metrics then return zero or
/// [`ModelError::TooShort`].
#[derive(Debug, Clone, Copy)]
pub struct JointTrack<'a> {
    positions: &'a [Vec3],
    joints: usize,
    fps: f64,
}

impl<'a> JointTrack<'a> {
    /// Wraps `positions` (frame-major: all joints of frame 0, then frame 1, …) sampled at `fps`.
    pub fn new(positions: &'a [Vec3], joints: usize, fps: f64) -> Result<Self, ModelError> {
        if joints == 0 {
            return Err(ModelError::NoJoints);
        }
        if !positions.len().is_multiple_of(joints) {
            return Err(ModelError::RaggedTrack {
                len: positions.len(),
                joints,
            });
        }
        if !(fps.is_finite() && fps > 0.0) {
            return Err(ModelError::BadFrameRate(fps));
        }
        if let Some(index) = positions.iter().position(|p| !p.is_finite()) {
            return Err(ModelError::NonFinitePosition { index });
        }
        Ok(Self {
            positions,
            joints,
            fps,
        })
    }

    /// The flat, frame-major position slice.
    pub fn positions(&self) -> &'a [Vec3] {
        self.positions
    }

    /// Joints per frame.
    pub fn joints(&self) -> usize {
        self.joints
    }

    /// Frames per second.
    pub fn fps(&self) -> f64 {
        self.fps
    }

    /// Number of frames.
    pub fn frames(&self) -> usize {
        self.positions.len() / self.joints
    }

    /// Time from the first to the last frame in seconds (0 for fewer than two frames).
    pub fn duration_s(&self) -> f64 {
        self.frames().saturating_sub(1) as f64 / self.fps
    }

    /// All joints of one frame.
    pub fn frame(&self, frame: usize) -> &'a [Vec3] {
        &self.positions[frame * self.joints..(frame + 1) * self.joints]
    }

    /// One joint position in double precision.
    fn pos(&self, frame: usize, joint: usize) -> DVec3 {
        self.positions[frame * self.joints + joint].as_dvec3()
    }

    /// Fails unless `joint` indexes this track.
    fn check_joint(&self, joint: usize) -> Result<(), ModelError> {
        if joint < self.joints {
            Ok(())
        } else {
            Err(ModelError::JointOutOfRange {
                joint,
                joints: self.joints,
            })
        }
    }
}

/// Local minima as `scipy.signal.argrelextrema(x, np.less, order, mode="clip")` finds them,
/// returned as (fractional) sample indices.
///
/// One deliberate extension: a run of exactly equal samples counts as one minimum at its centre
/// when it is strictly below `order` samples on either side. scipy finds nothing there, yet a
/// motion symmetric about a frame produces exactly such a two-sample run of equal speeds at its
/// turning point, and the turning point is the beat. As in scipy, a run touching either end of
/// the signal is never a minimum (clip mode compares the end sample with itself), and
/// neighbourhoods reaching past an end are clipped to the end sample.
fn local_minima(x: &[f64], order: usize) -> Vec<f64> {
    let n = x.len();
    let mut out = Vec::new();
    let mut start = 0;
    while start < n {
        let mut end = start;
        while end + 1 < n && x[end + 1] == x[start] {
            end += 1;
        }
        if start > 0 && end + 1 < n {
            let v = x[start];
            let is_min = (1..=order).all(|d| {
                let left = x[start.saturating_sub(d)];
                let right = x[(end + d).min(n - 1)];
                v < left && v < right
            });
            if is_min {
                out.push((start + end) as f64 / 2.0);
            }
        }
        start = end + 1;
    }
    out
}

/// Finite beat times within `[-tol, duration + tol]`, sorted ascending.
fn beats_within(beats_s: &[f64], duration_s: f64, tol_s: f64) -> Vec<f64> {
    let mut b: Vec<f64> = beats_s
        .iter()
        .copied()
        .filter(|t| t.is_finite() && *t >= -tol_s && *t <= duration_s + tol_s)
        .collect();
    b.sort_by(f64::total_cmp);
    b
}

/// Distance from `t` to the nearest element of the sorted, non-empty `sorted`.
fn nearest_distance(sorted: &[f64], t: f64) -> f64 {
    let i = sorted.partition_point(|&x| x < t);
    let after = sorted.get(i).map_or(f64::INFINITY, |&x| x - t);
    let before = i.checked_sub(1).map_or(f64::INFINITY, |j| t - sorted[j]);
    after.min(before)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn track_validation() {
        let p = vec![Vec3::ZERO; 6];
        assert!(JointTrack::new(&p, 3, 60.0).is_ok());
        assert!(matches!(
            JointTrack::new(&p, 4, 60.0).unwrap_err(),
            ModelError::RaggedTrack { len: 6, joints: 4 }
        ));
        assert!(matches!(
            JointTrack::new(&p, 0, 60.0).unwrap_err(),
            ModelError::NoJoints
        ));
        assert!(JointTrack::new(&p, 3, 0.0).is_err());
        assert!(JointTrack::new(&p, 3, f64::NAN).is_err());
        let mut q = p.clone();
        q[4].y = f32::NAN;
        assert!(matches!(
            JointTrack::new(&q, 3, 60.0).unwrap_err(),
            ModelError::NonFinitePosition { index: 4 }
        ));
        let t = JointTrack::new(&p, 3, 60.0).unwrap();
        assert_eq!(t.frames(), 2);
        assert!((t.duration_s() - 1.0 / 60.0).abs() < 1e-12);
        let empty = JointTrack::new(&[], 3, 60.0).unwrap();
        assert_eq!(empty.frames(), 0);
        assert_eq!(empty.duration_s(), 0.0);
    }

    #[test]
    fn minima_match_argrelextrema_and_plateaus() {
        // scipy: argrelextrema([3,1,3,2,2,5,0,4], np.less, order=1) -> [1, 6]; the plateau at
        // 3..=4 is our extension.
        let x = [3.0, 1.0, 3.0, 2.0, 2.0, 5.0, 0.0, 4.0];
        assert_eq!(local_minima(&x, 1), vec![1.0, 3.5, 6.0]);
        // order 2: index 1 compares with x[0] (clipped) and x[3]; 6 with x[4], x[7] (clipped).
        assert_eq!(local_minima(&x, 2), vec![1.0, 6.0]);
        assert!(local_minima(&[1.0, 1.0, 1.0], 1).is_empty());
        assert!(local_minima(&[0.0, 1.0], 1).is_empty());
        assert!(local_minima(&[], 3).is_empty());
    }

    #[test]
    fn nearest_distance_picks_closest_side() {
        let s = [0.0, 1.0, 2.0];
        for (t, d) in [(0.2, 0.2), (0.9, 0.1), (1.0, 0.0), (5.0, 3.0), (-1.0, 1.0)] {
            assert!((nearest_distance(&s, t) - d).abs() < 1e-12, "{t}");
        }
    }
}
