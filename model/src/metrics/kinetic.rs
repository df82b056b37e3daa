//! fairmotion's kinetic features as AIST++ computes them, and FACT's FID_k / Dist_k.

use super::{JointTrack, frechet::frechet_distance};
use crate::ModelError;

/// Half-width in seconds of the window velocities and accelerations are averaged over.
///
/// fairmotion's `KineticFeatures` averages over `sliding_window=2` frames either side, and
/// AIST++ feeds it 60 fps keypoints (`frame_time=1./60`); 2 / 60 s keeps that smoothing at other
/// frame rates. The window in frames is this times fps, rounded, at least 1 (at 60 fps: 2,
/// exactly AIST++'s). Bailando's copy runs the same code on 30 fps data, i.e. 1/15 s.
pub const KINETIC_WINDOW_S: f64 = 2.0 / 60.0;

/// Added to each feature's standard deviation before normalising, as FACT does (`+ 1e-10`).
///
/// A feature constant in the reference set therefore blows any difference in the other set up
/// by 10¹⁰; that is FACT's behaviour and is kept so that numbers stay comparable.
pub const FEATURE_STD_EPSILON: f64 = 1e-10;

/// Window half-width in frames for this frame rate.
fn window_frames(fps: f64) -> usize {
    ((KINETIC_WINDOW_S * fps).round() as usize).max(1)
}

/// fairmotion's kinetic feature vector (AIST++'s `extract_kinetic_features`), 3 per joint.
///
/// For each joint, in joint order: mean horizontal kinetic energy, mean vertical kinetic energy
/// (both per unit mass and without the ½: the mean of squared window-averaged speed, m²/s²),
/// and mean "energy expenditure", the mean norm of the window-averaged acceleration (m/s²).
/// Horizontal is the x–z plane (Y up, as AIST++'s `up_vec="y"`). Each of frames `1..n` averages
/// the frame-to-frame velocities / second differences within [`KINETIC_WINDOW_S`] of it that
/// exist (windows shrink at the ends exactly as fairmotion's do), and the means divide by
/// `n − 1`. With 24 SMPL joints this is FACT's 72-d feature. Needs at least three frames.
pub fn kinetic_features(track: &JointTrack<'_>) -> Result<Vec<f64>, ModelError> {
    let n = track.frames();
    if n < 3 {
        return Err(ModelError::TooShort {
            what: "frames",
            needed: 3,
            found: n,
        });
    }
    let fps = track.fps();
    let w = window_frames(fps);
    let mut out = Vec::with_capacity(3 * track.joints());
    for j in 0..track.joints() {
        let pos: Vec<_> = (0..n).map(|f| track.pos(f, j)).collect();
        let (mut horizontal, mut vertical, mut accel) = (0.0, 0.0, 0.0);
        for i in 1..n {
            // fairmotion: p[i+j] - p[i+j-1] for j in -w..=w where both frames exist.
            let (lo, hi) = (i.saturating_sub(w + 1), (i + w - 1).min(n - 2));
            let v = (lo..=hi).map(|k| pos[k + 1] - pos[k]).sum::<glam::DVec3>() * fps
                / (hi - lo + 1) as f64;
            horizontal += v.x * v.x + v.z * v.z;
            vertical += v.y * v.y;
            // fairmotion: second differences centred on i+j, where i+j-1 and i+j+1 exist.
            let (lo, hi) = (i.saturating_sub(w).max(1), (i + w).min(n - 2));
            let a = (lo..=hi)
                .map(|m| pos[m + 1] - 2.0 * pos[m] + pos[m - 1])
                .sum::<glam::DVec3>()
                * (fps * fps)
                / (hi - lo + 1) as f64;
            accel += a.length();
        }
        let norm = (n - 1) as f64;
        out.extend([horizontal / norm, vertical / norm, accel / norm]);
    }
    Ok(out)
}

/// Per-feature standardisation fitted on a reference set, as FACT applies before FID.
#[derive(Debug, Clone, PartialEq)]
pub struct FeatureNormaliser {
    mean: Vec<f64>,
    std: Vec<f64>,
}

impl FeatureNormaliser {
    /// Mean and population standard deviation (`np.std`, `ddof=0`) + [`FEATURE_STD_EPSILON`]
    /// of each feature over `reference` (at least one sample of equal, finite dimension).
    pub fn fit(reference: &[Vec<f64>]) -> Result<Self, ModelError> {
        let dim = check_set(reference, 1)?;
        let n = reference.len() as f64;
        let mut mean = vec![0.0; dim];
        for r in reference {
            for (m, v) in mean.iter_mut().zip(r) {
                *m += v / n;
            }
        }
        let mut var = vec![0.0; dim];
        for r in reference {
            for ((s, v), m) in var.iter_mut().zip(r).zip(&mean) {
                *s += (v - m).powi(2) / n;
            }
        }
        let std = var
            .into_iter()
            .map(|v| v.sqrt() + FEATURE_STD_EPSILON)
            .collect();
        Ok(Self { mean, std })
    }

    /// `(x − mean) / std` for one feature vector.
    pub fn apply(&self, x: &[f64]) -> Result<Vec<f64>, ModelError> {
        if x.len() != self.mean.len() {
            return Err(ModelError::DimensionMismatch {
                expected: self.mean.len(),
                found: x.len(),
            });
        }
        Ok(x.iter()
            .zip(&self.mean)
            .zip(&self.std)
            .map(|((v, m), s)| (v - m) / s)
            .collect())
    }

    /// [`apply`](Self::apply) to every sample of a set.
    pub fn apply_all(&self, set: &[Vec<f64>]) -> Result<Vec<Vec<f64>>, ModelError> {
        set.iter().map(|x| self.apply(x)).collect()
    }
}

/// Common dimension of a set with at least `needed` samples, all finite.
fn check_set(set: &[Vec<f64>], needed: usize) -> Result<usize, ModelError> {
    if set.len() < needed {
        return Err(ModelError::TooShort {
            what: "samples",
            needed,
            found: set.len(),
        });
    }
    let dim = set.first().map_or(0, Vec::len);
    for (sample, r) in set.iter().enumerate() {
        if r.len() != dim {
            return Err(ModelError::DimensionMismatch {
                expected: dim,
                found: r.len(),
            });
        }
        if let Some(d) = r.iter().position(|v| !v.is_finite()) {
            return Err(ModelError::NonFiniteFeature { sample, dim: d });
        }
    }
    Ok(dim)
}

/// FACT's FID_k: squared Fréchet distance after standardising both sets by `real`'s statistics.
///
/// Mirrors `calculate_frechet_feature_distance` in google-research/mint: mean / std from the
/// real set only ([`FeatureNormaliser`]), then [`frechet_distance`] (unbiased covariances).
/// Feed it [`kinetic_features`] for FID_k; it serves FID_g on geometric features just as well.
/// Each set needs two samples or more.
pub fn fid_k(real: &[Vec<f64>], generated: &[Vec<f64>]) -> Result<f64, ModelError> {
    let norm = FeatureNormaliser::fit(real)?;
    frechet_distance(&norm.apply_all(real)?, &norm.apply_all(generated)?)
}

/// FACT's Dist_k: [`mean_pairwise_distance`] of `generated` after standardising it by `real`'s
/// statistics, as mint's `calculate_frechet_feature_distance` computes its `avg_dist`.
pub fn dist_k(real: &[Vec<f64>], generated: &[Vec<f64>]) -> Result<f64, ModelError> {
    let norm = FeatureNormaliser::fit(real)?;
    mean_pairwise_distance(&norm.apply_all(generated)?)
}

/// Mean Euclidean distance over all unordered pairs of samples (diversity); needs two or more.
pub fn mean_pairwise_distance(set: &[Vec<f64>]) -> Result<f64, ModelError> {
    check_set(set, 2)?;
    let mut total = 0.0;
    for (i, a) in set.iter().enumerate() {
        for b in &set[i + 1..] {
            total += a
                .iter()
                .zip(b)
                .map(|(x, y)| (x - y).powi(2))
                .sum::<f64>()
                .sqrt();
        }
    }
    let n = set.len() as f64;
    Ok(total / (n * (n - 1.0) / 2.0))
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    fn track_of(f: impl Fn(f64) -> Vec3, fps: f64, frames: usize) -> Vec<Vec3> {
        (0..frames).map(|i| f(i as f64 / fps)).collect()
    }

    #[test]
    fn still_track_has_zero_features() {
        let p = vec![Vec3::new(0.1, 1.0, 0.2); 2 * 30];
        let t = JointTrack::new(&p, 2, 30.0).unwrap();
        assert_eq!(kinetic_features(&t).unwrap(), vec![0.0; 6]);
    }

    #[test]
    fn constant_velocity_energies() {
        for fps in [30.0, 60.0, 120.0] {
            // 0.5 m/s along x and 0.3 m/s up: energies v² per axis, no acceleration.
            let p = track_of(|t| Vec3::new(0.5 * t as f32, 0.3 * t as f32, 0.0), fps, 100);
            let f = kinetic_features(&JointTrack::new(&p, 1, fps).unwrap()).unwrap();
            assert_eq!(f.len(), 3);
            assert!((f[0] - 0.25).abs() < 1e-4, "{fps}: {f:?}");
            assert!((f[1] - 0.09).abs() < 1e-4, "{fps}: {f:?}");
            assert!(f[2] < 0.05, "{fps}: {f:?}");
        }
    }

    #[test]
    fn constant_acceleration_expenditure() {
        // y = ½ a t² with a = 2 m/s²: every second difference is a · dt².
        let p = track_of(|t| Vec3::new(0.0, (t * t) as f32, 0.0), 60.0, 61);
        let f = kinetic_features(&JointTrack::new(&p, 1, 60.0).unwrap()).unwrap();
        assert!((f[2] - 2.0).abs() < 0.02, "{f:?}");
        assert_eq!(f[0], 0.0);
    }

    #[test]
    fn kinetic_features_need_three_frames() {
        let p = vec![Vec3::ZERO; 2];
        let t = JointTrack::new(&p, 1, 60.0).unwrap();
        assert!(kinetic_features(&t).is_err());
        let e = JointTrack::new(&[], 1, 60.0).unwrap();
        assert!(kinetic_features(&e).is_err());
        let p = vec![Vec3::ZERO, Vec3::X, Vec3::ZERO];
        let f = kinetic_features(&JointTrack::new(&p, 1, 60.0).unwrap()).unwrap();
        assert!(f.iter().all(|v| v.is_finite()));
    }

    #[test]
    fn fid_dist_and_diversity() {
        let set: Vec<Vec<f64>> = (0..20)
            .map(|i| {
                let x = i as f64;
                vec![x, (x * 0.7).sin(), x * x * 0.01]
            })
            .collect();
        assert!(fid_k(&set, &set).unwrap().abs() < 1e-9);
        let shifted: Vec<Vec<f64>> = set.iter().map(|r| vec![r[0] + 5.0, r[1], r[2]]).collect();
        // Same covariance, mean moved 5 along a feature whose population std is √33.25:
        // (5 / √33.25)² in normalised units.
        let d = fid_k(&set, &shifted).unwrap();
        assert!((d - 25.0 / 33.25).abs() < 1e-6, "{d}");
        // Identical samples have no diversity.
        let same = vec![vec![1.0, 2.0, 3.0]; 5];
        assert_eq!(mean_pairwise_distance(&same).unwrap(), 0.0);
        assert_eq!(dist_k(&set, &same).unwrap(), 0.0);
        // (0,0), (3,4), (0,0): pair distances 5, 0, 5.
        let tri = vec![vec![0.0, 0.0], vec![3.0, 4.0], vec![0.0, 0.0]];
        assert!((mean_pairwise_distance(&tri).unwrap() - 10.0 / 3.0).abs() < 1e-12);
        // Normalised by the real set's mean 1 and std 1: {1, 3} → {0, 2}.
        let real = vec![vec![0.0], vec![2.0]];
        let gen_ = vec![vec![1.0], vec![3.0]];
        assert!((dist_k(&real, &gen_).unwrap() - 2.0).abs() < 1e-9);
    }

    #[test]
    fn fid_dist_bad_inputs() {
        let one = vec![vec![1.0]];
        assert!(mean_pairwise_distance(&one).is_err());
        assert!(mean_pairwise_distance(&[]).is_err());
        assert!(fid_k(&one, &one).is_err());
        assert!(fid_k(&[], &one).is_err());
        assert!(dist_k(&one, &[vec![1.0, 2.0], vec![1.0, 2.0]]).is_err());
        assert!(FeatureNormaliser::fit(&[vec![f64::INFINITY]]).is_err());
    }
}
