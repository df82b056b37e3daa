//! Fréchet distance between Gaussians fitted to feature sets, and Transflower's FPD / FMD.

use nalgebra::{DMatrix, DVector, SymmetricEigen};

use super::JointTrack;
use crate::ModelError;

/// Samples are accumulated in blocks of this many rows so that one matrix product per block,
/// not one rank-1 update per sample, builds the scatter matrix.
const BLOCK_ROWS: usize = 256;

/// A multivariate Gaussian: the mean and covariance of a feature distribution.
#[derive(Debug, Clone, PartialEq)]
pub struct Gaussian {
    mean: DVector<f64>,
    cov: DMatrix<f64>,
}

impl Gaussian {
    /// A Gaussian with the given mean and row-major covariance (symmetrised; should be PSD).
    pub fn new(mean: Vec<f64>, cov_row_major: Vec<f64>) -> Result<Self, ModelError> {
        let d = mean.len();
        if cov_row_major.len() != d * d {
            return Err(ModelError::DimensionMismatch {
                expected: d * d,
                found: cov_row_major.len(),
            });
        }
        if let Some(dim) = mean.iter().position(|v| !v.is_finite()) {
            return Err(ModelError::NonFiniteFeature { sample: 0, dim });
        }
        if let Some(dim) = cov_row_major.iter().position(|v| !v.is_finite()) {
            return Err(ModelError::NonFiniteFeature { sample: 1, dim });
        }
        Ok(Self {
            mean: DVector::from_vec(mean),
            cov: symmetrised(DMatrix::from_row_slice(d, d, &cov_row_major)),
        })
    }

    /// Mean and unbiased covariance (`np.cov`'s `ddof=1`, as FID uses) of `samples`, one
    /// feature vector per sample; needs at least two samples of equal, finite dimension.
    pub fn fit(samples: &[Vec<f64>]) -> Result<Self, ModelError> {
        let Some(first) = samples.first() else {
            return Err(ModelError::TooShort {
                what: "samples",
                needed: 2,
                found: 0,
            });
        };
        let mut acc = Moments::new(first.len());
        for s in samples {
            acc.push(s)?;
        }
        acc.finish()
    }

    /// Feature dimension.
    pub fn dim(&self) -> usize {
        self.mean.len()
    }

    /// The mean vector.
    pub fn mean(&self) -> &[f64] {
        self.mean.as_slice()
    }

    /// The covariance, row-major.
    pub fn covariance(&self) -> Vec<f64> {
        self.cov.transpose().as_slice().to_vec()
    }
}

/// Streaming mean / scatter accumulator.
///
/// Samples are shifted by the first one before summing so that features with a large common
/// offset (positions far from the origin) do not lose their variance to cancellation.
struct Moments {
    dim: usize,
    n: usize,
    shift: Vec<f64>,
    sum: DVector<f64>,
    scatter: DMatrix<f64>,
    block: Vec<f64>,
    rows: usize,
}

impl Moments {
    fn new(dim: usize) -> Self {
        Self {
            dim,
            n: 0,
            shift: Vec::new(),
            sum: DVector::zeros(dim),
            scatter: DMatrix::zeros(dim, dim),
            block: Vec::with_capacity(dim * BLOCK_ROWS),
            rows: 0,
        }
    }

    fn push(&mut self, x: &[f64]) -> Result<(), ModelError> {
        if x.len() != self.dim {
            return Err(ModelError::DimensionMismatch {
                expected: self.dim,
                found: x.len(),
            });
        }
        if let Some(dim) = x.iter().position(|v| !v.is_finite()) {
            return Err(ModelError::NonFiniteFeature {
                sample: self.n,
                dim,
            });
        }
        if self.n == 0 {
            self.shift = x.to_vec();
        }
        self.block
            .extend(x.iter().zip(&self.shift).map(|(v, s)| v - s));
        self.rows += 1;
        self.n += 1;
        if self.rows == BLOCK_ROWS {
            self.flush();
        }
        Ok(())
    }

    fn flush(&mut self) {
        if self.rows == 0 {
            return;
        }
        // Column-major dim × rows: each sample is a column.
        let x = DMatrix::from_column_slice(self.dim, self.rows, &self.block);
        self.sum += x.column_sum();
        self.scatter.gemm(1.0, &x, &x.transpose(), 1.0);
        self.block.clear();
        self.rows = 0;
    }

    fn finish(mut self) -> Result<Gaussian, ModelError> {
        self.flush();
        if self.n < 2 {
            return Err(ModelError::TooShort {
                what: "samples",
                needed: 2,
                found: self.n,
            });
        }
        let n = self.n as f64;
        let m = &self.sum / n;
        let cov = (&self.scatter - &m * m.transpose() * n) / (n - 1.0);
        Ok(Gaussian {
            mean: m + DVector::from_vec(self.shift),
            cov: symmetrised(cov),
        })
    }
}

/// (M + Mᵀ) / 2: rounding leaves products like S·B·S a few ulps asymmetric.
fn symmetrised(m: DMatrix<f64>) -> DMatrix<f64> {
    (&m + m.transpose()) * 0.5
}

/// Eigendecomposition of a symmetric matrix, as an error rather than a hang if it stalls.
fn eigen(m: DMatrix<f64>) -> Result<SymmetricEigen<f64, nalgebra::Dyn>, ModelError> {
    let max_iter = 1000 * m.nrows().max(1);
    SymmetricEigen::try_new(m, f64::EPSILON, max_iter).ok_or(ModelError::EigenFailed)
}

/// Squared Fréchet (2-Wasserstein) distance between two Gaussians, the quantity FID reports:
/// ‖μ₁ − μ₂‖² + tr Σ₁ + tr Σ₂ − 2 tr (Σ₁ Σ₂)^½.
///
/// Unlike `scipy.linalg.sqrtm(Σ₁ Σ₂)` (pytorch-fid, FACT), the trace term is taken as
/// tr (S Σ₂ S)^½ with S = Σ₁^½: S Σ₂ S is similar to Σ₁ Σ₂ yet symmetric, so both square roots
/// come from symmetric eigendecompositions, whose slightly negative rounding eigenvalues are
/// clamped to zero. Singular covariances (fewer samples than dimensions, constant features)
/// therefore need no ε-regularisation, nothing turns complex, and the result is never NaN; it
/// is clamped at 0 against rounding.
pub fn frechet_distance_gaussians(a: &Gaussian, b: &Gaussian) -> Result<f64, ModelError> {
    if a.dim() != b.dim() {
        return Err(ModelError::DimensionMismatch {
            expected: a.dim(),
            found: b.dim(),
        });
    }
    if a.dim() == 0 {
        return Ok(0.0);
    }
    let ea = eigen(a.cov.clone())?;
    let root = ea.eigenvalues.map(|l| l.max(0.0).sqrt());
    let s = &ea.eigenvectors * DMatrix::from_diagonal(&root) * ea.eigenvectors.transpose();
    let m = symmetrised(&s * &b.cov * &s);
    let trace_sqrt: f64 = eigen(m)?
        .eigenvalues
        .iter()
        .map(|l| l.max(0.0).sqrt())
        .sum();
    let d2 = (&a.mean - &b.mean).norm_squared() + a.cov.trace() + b.cov.trace() - 2.0 * trace_sqrt;
    if d2.is_finite() {
        Ok(d2.max(0.0))
    } else {
        Err(ModelError::EigenFailed)
    }
}

/// Squared Fréchet distance between Gaussians fitted ([`Gaussian::fit`]) to two feature sets
/// (one `Vec` per sample); each set needs at least two samples.
pub fn frechet_distance(a: &[Vec<f64>], b: &[Vec<f64>]) -> Result<f64, ModelError> {
    frechet_distance_gaussians(&Gaussian::fit(a)?, &Gaussian::fit(b)?)
}

/// Gaussian of per-frame features: frames `i - context ..= i + context` of every joint,
/// all relative to the root joint at frame `i` (dimension 3 · joints · (2 · context + 1)).
fn pose_gaussian(
    tracks: &[JointTrack<'_>],
    joints: usize,
    root_joint: usize,
    context: usize,
) -> Result<Gaussian, ModelError> {
    let mut acc = Moments::new(3 * joints * (2 * context + 1));
    let mut feature = Vec::with_capacity(acc.dim);
    for track in tracks {
        if track.joints() != joints {
            return Err(ModelError::DimensionMismatch {
                expected: joints,
                found: track.joints(),
            });
        }
        track.check_joint(root_joint)?;
        let n = track.frames();
        for i in context..n.saturating_sub(context) {
            let root = track.pos(i, root_joint);
            feature.clear();
            for f in i - context..=i + context {
                for j in 0..joints {
                    let p = track.pos(f, j) - root;
                    feature.extend([p.x, p.y, p.z]);
                }
            }
            acc.push(&feature)?;
        }
    }
    acc.finish()
}

/// Shared body of [`fpd`] and [`fmd`].
fn pose_distance(
    real: &[JointTrack<'_>],
    generated: &[JointTrack<'_>],
    root_joint: usize,
    context: usize,
) -> Result<f64, ModelError> {
    let Some(joints) = real.first().or(generated.first()).map(|t| t.joints()) else {
        return Err(ModelError::TooShort {
            what: "samples",
            needed: 2,
            found: 0,
        });
    };
    frechet_distance_gaussians(
        &pose_gaussian(real, joints, root_joint, context)?,
        &pose_gaussian(generated, joints, root_joint, context)?,
    )
}

/// Transflower's Fréchet pose distance (squared) between the frames of two sets of tracks.
///
/// Each frame's pose is every joint's position minus the root's (3 · joints values, the root's
/// own three always zero), in metres: Transflower used its raw pose features without
/// normalisation, and ours are positions, made root-relative so that where on the floor a
/// dancer stands does not count. All frames of all tracks in a set are pooled; each set needs
/// two frames or more, and every track the same joint count.
pub fn fpd(
    real: &[JointTrack<'_>],
    generated: &[JointTrack<'_>],
    root_joint: usize,
) -> Result<f64, ModelError> {
    pose_distance(real, generated, root_joint, 0)
}

/// Transflower's Fréchet movement distance (squared): as [`fpd`] on three consecutive poses.
///
/// The feature of frame `i` concatenates frames `i − 1`, `i`, `i + 1` (9 · joints values), all
/// relative to the root at frame `i`, so it carries velocity and acceleration, the root's own
/// included, but not position on the floor. Tracks shorter than three frames add nothing.
pub fn fmd(
    real: &[JointTrack<'_>],
    generated: &[JointTrack<'_>],
    root_joint: usize,
) -> Result<f64, ModelError> {
    pose_distance(real, generated, root_joint, 1)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;
    use proptest::prelude::*;

    /// Deterministic pseudo-random samples (xorshift), uniform in [-1, 1).
    fn samples(n: usize, dim: usize, seed: u64) -> Vec<Vec<f64>> {
        let mut s = seed.max(1);
        let mut next = move || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 11) as f64 / (1u64 << 52) as f64 - 1.0
        };
        (0..n).map(|_| (0..dim).map(|_| next()).collect()).collect()
    }

    #[test]
    fn identical_sets_are_zero() {
        let a = samples(500, 6, 7);
        let d = frechet_distance(&a, &a).unwrap();
        assert!(d.abs() < 1e-9, "{d}");
        // Far from the origin: the shifted accumulation must keep the variance.
        let b: Vec<Vec<f64>> = a
            .iter()
            .map(|r| r.iter().map(|v| v + 1e6).collect())
            .collect();
        let d = frechet_distance(&b, &b).unwrap();
        assert!(d.abs() < 1e-6, "{d}");
    }

    #[test]
    fn closed_form_values() {
        // 1-D: (0 - 3)² + 1 + 4 - 2·√(1·4) = 10.
        let a = Gaussian::new(vec![0.0], vec![1.0]).unwrap();
        let b = Gaussian::new(vec![3.0], vec![4.0]).unwrap();
        assert!((frechet_distance_gaussians(&a, &b).unwrap() - 10.0).abs() < 1e-12);
        // Commuting diagonal covariances: ‖(1, -2)‖² + (1 + 4) + (9 + 1) - 2 (3 + 2) = 10.
        let a = Gaussian::new(vec![0.0, 0.0], vec![1.0, 0.0, 0.0, 4.0]).unwrap();
        let b = Gaussian::new(vec![1.0, -2.0], vec![9.0, 0.0, 0.0, 1.0]).unwrap();
        assert!((frechet_distance_gaussians(&a, &b).unwrap() - 10.0).abs() < 1e-12);
        // Non-commuting 2×2: tr (AB)^½ = √(tr AB + 2 √det AB) as AB has positive eigenvalues.
        let (ca, cb): ([f64; 4], [f64; 4]) = ([2.0, 1.0, 1.0, 1.0], [1.0, -0.5, -0.5, 3.0]);
        let ab = [
            ca[0] * cb[0] + ca[1] * cb[2],
            ca[0] * cb[1] + ca[1] * cb[3],
            ca[2] * cb[0] + ca[3] * cb[2],
            ca[2] * cb[1] + ca[3] * cb[3],
        ];
        let tr_ab = ab[0] + ab[3];
        let det_ab = ab[0] * ab[3] - ab[1] * ab[2];
        let expected = 0.25 + 1.0 + (ca[0] + ca[3]) + (cb[0] + cb[3])
            - 2.0 * (tr_ab + 2.0 * det_ab.sqrt()).sqrt();
        let a = Gaussian::new(vec![0.5, 0.0], ca.to_vec()).unwrap();
        let b = Gaussian::new(vec![0.0, 1.0], cb.to_vec()).unwrap();
        let d = frechet_distance_gaussians(&a, &b).unwrap();
        assert!((d - expected).abs() < 1e-12, "{d} vs {expected}");
        // Symmetric in its arguments.
        let d2 = frechet_distance_gaussians(&b, &a).unwrap();
        assert!((d - d2).abs() < 1e-12);
    }

    #[test]
    fn fitted_sets_match_closed_form() {
        // (±1, ±1): mean 0, covariance 4/3 · I (ddof = 1). Scaled by 2, shifted by (3, 0):
        // 9 + 2·4/3 + 2·16/3 - 2·2·8/3 = 9 + 8/3.
        let a: Vec<Vec<f64>> = [[-1.0, -1.0], [-1.0, 1.0], [1.0, -1.0], [1.0, 1.0]]
            .iter()
            .map(|r| r.to_vec())
            .collect();
        let b: Vec<Vec<f64>> = a
            .iter()
            .map(|r| vec![2.0 * r[0] + 3.0, 2.0 * r[1]])
            .collect();
        let g = Gaussian::fit(&a).unwrap();
        assert_eq!(g.mean(), &[0.0, 0.0]);
        let cov = g.covariance();
        assert!((cov[0] - 4.0 / 3.0).abs() < 1e-12 && cov[1].abs() < 1e-12);
        let d = frechet_distance(&a, &b).unwrap();
        assert!((d - (9.0 + 8.0 / 3.0)).abs() < 1e-9, "{d}");
    }

    #[test]
    fn singular_covariances_stay_finite() {
        // 3 samples in 10 dimensions, and a constant feature: rank-deficient covariances.
        let mut a = samples(3, 10, 3);
        for r in &mut a {
            r[4] = 2.0;
        }
        let b = samples(3, 10, 4);
        let d = frechet_distance(&a, &b).unwrap();
        assert!(d.is_finite() && d > 0.0, "{d}");
        let d = frechet_distance(&a, &a).unwrap();
        assert!(d.abs() < 1e-7, "{d}");
        // All-constant sets: zero covariance, distance is the squared mean difference.
        let c = vec![vec![1.0, 1.0]; 4];
        let z = vec![vec![0.0, 0.0]; 4];
        assert!((frechet_distance(&c, &z).unwrap() - 2.0).abs() < 1e-12);
    }

    #[test]
    fn bad_inputs_are_errors() {
        let a = samples(4, 3, 1);
        assert!(matches!(
            frechet_distance(&a, &a[..1]).unwrap_err(),
            ModelError::TooShort {
                what: "samples",
                needed: 2,
                found: 1
            }
        ));
        assert!(frechet_distance(&[], &a).is_err());
        assert!(frechet_distance(&a, &samples(4, 2, 1)).is_err());
        let mut bad = a.clone();
        bad[2][1] = f64::NAN;
        assert!(matches!(
            frechet_distance(&a, &bad).unwrap_err(),
            ModelError::NonFiniteFeature { sample: 2, dim: 1 }
        ));
        assert!(Gaussian::new(vec![0.0, 0.0], vec![1.0]).is_err());
        // Zero-dimensional features: nothing to tell apart.
        let e = vec![Vec::new(); 3];
        assert_eq!(frechet_distance(&e, &e).unwrap(), 0.0);
    }

    /// A 3-joint track at 30 fps: root bobbing and drifting, two limbs swinging `amp` metres
    /// at `speed` rad/s.
    fn dancer(frames: usize, speed: f32, amp: f32, offset: Vec3) -> Vec<Vec3> {
        let mut p = Vec::with_capacity(frames * 3);
        for i in 0..frames {
            let t = i as f32 / 30.0;
            let root = Vec3::new(0.2 * t, 0.9 + 0.05 * (3.0 * t).sin(), 0.0) + offset;
            p.push(root);
            p.push(root + Vec3::new((speed * t).sin() * amp, 0.4, 0.0));
            p.push(root + Vec3::new(0.0, -0.5, (speed * t).cos() * amp));
        }
        p
    }

    fn track(p: &[Vec3]) -> [JointTrack<'_>; 1] {
        [JointTrack::new(p, 3, 30.0).unwrap()]
    }

    #[test]
    fn fpd_and_fmd() {
        let a = dancer(600, 2.0 * std::f32::consts::PI, 0.5, Vec3::ZERO);
        let moved = dancer(
            600,
            2.0 * std::f32::consts::PI,
            0.5,
            Vec3::new(5.0, 0.0, -3.0),
        );
        let wide = dancer(600, 2.0 * std::f32::consts::PI, 0.6, Vec3::ZERO);
        let fast = dancer(600, 4.0 * std::f32::consts::PI, 0.5, Vec3::ZERO);
        let (ta, tm, tw, tf) = (track(&a), track(&moved), track(&wide), track(&fast));
        for f in [fpd, fmd] {
            assert!(f(&ta, &ta, 0).unwrap() < 1e-9);
            // Root-relative features ignore where the dancer stands.
            assert!(f(&ta, &tm, 0).unwrap() < 1e-6);
        }
        // Larger swings: the poses differ. x and z each go from variance 0.125 to 0.18 m²,
        // so FPD = 2 (√0.18 − √0.125)² ≈ 0.010 m².
        let d = fpd(&ta, &tw, 0).unwrap();
        assert!(
            (d - 2.0 * (0.18f64.sqrt() - 0.125f64.sqrt()).powi(2)).abs() < 5e-4,
            "{d}"
        );
        // Same poses twice as fast (whole cycles in both): FPD ≈ 0, FMD sees the speed.
        assert!(fpd(&ta, &tf, 0).unwrap() < 1e-3);
        assert!(fmd(&ta, &tf, 0).unwrap() > 1e-2);
        assert!(fpd(&ta, &ta, 3).is_err());
        let two = [JointTrack::new(&a[..6], 3, 30.0).unwrap()];
        assert!(fmd(&ta, &two, 0).is_err());
        assert!(fpd(&[], &[], 0).is_err());
    }

    proptest! {
        #[test]
        fn frechet_is_finite_symmetric_and_non_negative(
            seed_a in 1u64..u64::MAX, seed_b in 1u64..u64::MAX,
            n_a in 2usize..12, n_b in 2usize..12, dim in 1usize..6, scale in 1e-6f64..1e3,
        ) {
            let s = |n, seed| -> Vec<Vec<f64>> {
                samples(n, dim, seed).into_iter().map(|r| r.into_iter().map(|v| v * scale).collect()).collect()
            };
            let (a, b) = (s(n_a, seed_a), s(n_b, seed_b));
            let ab = frechet_distance(&a, &b).unwrap();
            let ba = frechet_distance(&b, &a).unwrap();
            prop_assert!(ab.is_finite() && ab >= 0.0);
            prop_assert!((ab - ba).abs() <= 1e-6 * scale * scale * dim as f64);
        }
    }
}
