//! The body shape of poses given as the network's normalised rotation features, with its
//! gradient: joint positions relative to the hips, heading removed, on the default rig — what
//! `danced eval` scores a key pose by (`model::body_shape::key_pose_error_cm`). A distance in
//! normalised rotations weighs every feature alike, so the wrists', the head's and the toes'
//! own rotations (which move no joint) count as much as the hips' (which move all of them).

use burn::tensor::{Device, Tensor, TensorData};
use glam::Vec3;

use model::motion::{ROTATION_DIM, ROTATIONS};
use model::neural::token::{KEY_ROT_DIM, Normalizer};
use model::rig::{JOINT_COUNT, Joint, Skeleton};

/// Forward kinematics of normalised rotation features onto the default adult rig.
#[derive(Clone, Debug)]
pub struct BodyShape {
    /// Means of the rotation features, `[1, KEY_ROT_DIM]`.
    mean: Tensor<2>,
    /// Standard deviations of the rotation features, `[1, KEY_ROT_DIM]`.
    std: Tensor<2>,
    /// Each joint's offset from its parent, metres.
    offsets: [Vec3; JOINT_COUNT],
}

impl BodyShape {
    /// The body shape of features normalised by `norm`'s pose statistics (which the key pose
    /// shares), on the default adult rig.
    pub fn new(norm: &Normalizer, device: &Device) -> Self {
        let row = |v: &[f32]| {
            Tensor::from_data(
                TensorData::new(
                    v[ROTATIONS..ROTATIONS + KEY_ROT_DIM].to_vec(),
                    [1, KEY_ROT_DIM],
                ),
                device,
            )
        };
        BodyShape {
            mean: row(&norm.pose_mean),
            std: row(&norm.pose_std),
            offsets: Skeleton::default_adult().offsets,
        }
    }

    /// Joint positions relative to the hips, metres, `[n, JOINT_COUNT, 3]`, of `rotations`
    /// `[n, KEY_ROT_DIM]` (normalised 6D features, the hips' heading already removed).
    pub fn positions(&self, rotations: Tensor<2>) -> Tensor<3> {
        let [n, _] = rotations.dims();
        let device = rotations.device();
        let raw = (rotations * self.std.clone() + self.mean.clone()).reshape([
            n,
            JOINT_COUNT,
            ROTATION_DIM,
        ]);
        let mut world: Vec<Tensor<3>> = Vec::with_capacity(JOINT_COUNT);
        let mut at: Vec<Tensor<2>> = Vec::with_capacity(JOINT_COUNT);
        for joint in Joint::ALL {
            let i = joint.index();
            let local = matrix_of_6d(raw.clone().narrow(1, i, 1).reshape([n, ROTATION_DIM]));
            match joint.parent() {
                Some(p) => {
                    let p = p.index();
                    let o = self.offsets[i];
                    let column = |c: usize| world[p].clone().narrow(2, c, 1).reshape([n, 3]);
                    let moved = column(0).mul_scalar(o.x)
                        + column(1).mul_scalar(o.y)
                        + column(2).mul_scalar(o.z);
                    at.push(at[p].clone() + moved);
                    world.push(world[p].clone().matmul(local));
                }
                None => {
                    at.push(Tensor::zeros([n, 3], &device));
                    world.push(local);
                }
            }
        }
        Tensor::stack(at, 1)
    }

    /// Per row `[n]`, the mean distance over the joints, cm, between the body shapes of `a`
    /// and `b` (both `[n, KEY_ROT_DIM]`, normalised).
    pub fn distance_cm(&self, a: Tensor<2>, b: Tensor<2>) -> Tensor<1> {
        let [n, _] = a.dims();
        // Not squared: as with the normalised distance, its gradient keeps a unit scale
        // however far the free run strayed; the epsilon keeps it finite on the key itself.
        (self.positions(a) - self.positions(b))
            .powi_scalar(2)
            .sum_dim(2)
            .add_scalar(1e-8)
            .sqrt()
            .reshape([n, JOINT_COUNT])
            .mean_dim(1)
            .reshape([n])
            .mul_scalar(100.0)
    }

    /// Per sequence, the kinetic features `danced eval` compares dances by (fairmotion's, as
    /// `model::metrics::kinetic` computes them, without its 2-frame window averaging) of the
    /// body shape over `poses` `[b, n, MOTION_FEATURE_DIM]` (normalised motion features, n ≥ 3,
    /// `fps` frames a second): per joint the mean squared horizontal and vertical speed
    /// (m²/s²) and the mean acceleration norm (m/s²), `[b, JOINT_COUNT, 3]`. Relative to the
    /// hips, so the root's travel is left out.
    pub fn kinetic(&self, poses: Tensor<3>, fps: f32) -> Tensor<3> {
        let [b, n, p] = poses.dims();
        let rotations = poses.reshape([b * n, p]).narrow(1, ROTATIONS, KEY_ROT_DIM);
        let at = self.positions(rotations).reshape([b, n, JOINT_COUNT, 3]);
        let velocity = (at.clone().narrow(1, 1, n - 1) - at.narrow(1, 0, n - 1)).mul_scalar(fps);
        let squared = velocity.clone().powi_scalar(2);
        let horizontal = (squared.clone().narrow(3, 0, 1) + squared.clone().narrow(3, 2, 1))
            .mean_dim(1)
            .reshape([b, JOINT_COUNT, 1]);
        let vertical = squared
            .narrow(3, 1, 1)
            .mean_dim(1)
            .reshape([b, JOINT_COUNT, 1]);
        let acceleration = (velocity.clone().narrow(1, 1, n - 2) - velocity.narrow(1, 0, n - 2))
            .mul_scalar(fps)
            .powi_scalar(2)
            .sum_dim(3)
            .add_scalar(1e-8)
            .sqrt()
            .mean_dim(1)
            .reshape([b, JOINT_COUNT, 1]);
        Tensor::cat(vec![horizontal, vertical, acceleration], 2)
    }
}

/// Rotation matrices `[n, 3, 3]` (columns the images of +X, +Y, +Z) of 6D features `[n, 6]`
/// (the first two columns, Gram–Schmidt-orthonormalised as Zhou et al. read them back).
fn matrix_of_6d(six: Tensor<2>) -> Tensor<3> {
    let [n, _] = six.dims();
    let unit = |v: Tensor<2>| {
        let norm = v.clone().powi_scalar(2).sum_dim(1).add_scalar(1e-12).sqrt();
        v / norm
    };
    let x = unit(six.clone().narrow(1, 0, 3));
    let y = six.narrow(1, 3, 3);
    let along = (x.clone() * y.clone()).sum_dim(1);
    let y = unit(y - x.clone() * along);
    let z = cross(x.clone(), y.clone());
    Tensor::stack::<3>(vec![x, y, z], 2).reshape([n, 3, 3])
}

/// Row-wise cross product of `[n, 3]` vectors.
fn cross(a: Tensor<2>, b: Tensor<2>) -> Tensor<2> {
    let c = |v: &Tensor<2>, i: usize| v.clone().narrow(1, i, 1);
    Tensor::cat(
        vec![
            c(&a, 1) * c(&b, 2) - c(&a, 2) * c(&b, 1),
            c(&a, 2) * c(&b, 0) - c(&a, 0) * c(&b, 2),
            c(&a, 0) * c(&b, 1) - c(&a, 1) * c(&b, 0),
        ],
        1,
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::device::cpu_device;
    use crate::layers::values;
    use glam::Quat;
    use model::body_shape::body_shape;
    use model::motion::MOTION_FEATURE_DIM;
    use model::neural::rng::Rng;
    use model::neural::token::key_rotations;

    fn random_rotations(rng: &mut Rng) -> [Quat; JOINT_COUNT] {
        std::array::from_fn(|_| {
            Quat::from_xyzw(rng.normal(), rng.normal(), rng.normal(), rng.normal()).normalize()
        })
    }

    fn normalizer(rng: &mut Rng) -> Normalizer {
        let mut n = Normalizer::identity();
        for i in 0..MOTION_FEATURE_DIM {
            n.pose_mean[i] = 0.3 * rng.normal();
            n.pose_std[i] = 0.2 + rng.normal().abs();
        }
        n
    }

    fn features(norm: &Normalizer, rotations: &[Quat; JOINT_COUNT]) -> Vec<f32> {
        let mut raw = [0.0; KEY_ROT_DIM];
        key_rotations(rotations, &mut raw);
        let mut out = vec![0.0; KEY_ROT_DIM];
        norm.key(&raw, &mut out);
        out
    }

    /// Rows of normalised key features as a tensor `[rows, KEY_ROT_DIM]`.
    fn rows(features: Vec<f32>, device: &Device) -> Tensor<2> {
        let n = features.len() / KEY_ROT_DIM;
        Tensor::from_data(TensorData::new(features, [n, KEY_ROT_DIM]), device)
    }

    #[test]
    fn the_body_shape_distance_is_the_rigs_mean_joint_distance_in_cm() {
        let device = cpu_device();
        let mut rng = Rng::new(7);
        let norm = normalizer(&mut rng);
        let shape = BodyShape::new(&norm, &device);
        let (mut a, mut b, mut expected) = (Vec::new(), Vec::new(), Vec::new());
        for _ in 0..5 {
            let (qa, qb) = (random_rotations(&mut rng), random_rotations(&mut rng));
            a.extend(features(&norm, &qa));
            b.extend(features(&norm, &qb));
            // What `danced eval` scores a key pose by.
            let (sa, sb) = (body_shape(&qa), body_shape(&qb));
            let mean: f32 =
                sa.iter().zip(&sb).map(|(x, y)| x.distance(*y)).sum::<f32>() / JOINT_COUNT as f32;
            expected.push(100.0 * mean);
        }
        let got = values(shape.distance_cm(rows(a.clone(), &device), rows(b, &device)));
        for (g, e) in got.iter().zip(&expected) {
            assert!(e > &5.0, "random poses {e} cm apart");
            assert!(
                (g - e).abs() < 1e-3 * e.max(1.0),
                "{got:?} against {expected:?}"
            );
        }
        // A pose is no distance from itself (the epsilon aside).
        let same = values(shape.distance_cm(rows(a.clone(), &device), rows(a, &device)));
        assert!(same.iter().all(|d| *d < 0.02), "{same:?}");
    }

    #[test]
    fn the_kinetic_features_are_those_of_the_rigs_joint_positions() {
        let device = cpu_device();
        let mut rng = Rng::new(11);
        let norm = normalizer(&mut rng);
        let shape = BodyShape::new(&norm, &device);
        let (frames, fps) = (5, 25.0);
        let mut poses = Vec::new();
        let mut at = Vec::new();
        let mut q = random_rotations(&mut rng);
        for _ in 0..frames {
            for r in q.iter_mut() {
                *r = (Quat::from_rotation_y(0.1 * rng.normal())
                    * Quat::from_rotation_x(0.1 * rng.normal())
                    * *r)
                    .normalize();
            }
            let mut pose = vec![0.0; MOTION_FEATURE_DIM];
            pose[ROTATIONS..ROTATIONS + KEY_ROT_DIM].copy_from_slice(&features(&norm, &q));
            poses.extend(pose);
            at.push(body_shape(&q));
        }
        let got = values(
            shape
                .kinetic(
                    Tensor::<3>::from_data(
                        TensorData::new(poses, [1, frames, MOTION_FEATURE_DIM]),
                        &device,
                    ),
                    fps,
                )
                .reshape([JOINT_COUNT * 3]),
        );
        for j in 0..JOINT_COUNT {
            let v: Vec<Vec3> = (1..frames)
                .map(|f| (at[f][j] - at[f - 1][j]) * fps)
                .collect();
            let horizontal = v.iter().map(|v| v.x * v.x + v.z * v.z).sum::<f32>() / 4.0;
            let vertical = v.iter().map(|v| v.y * v.y).sum::<f32>() / 4.0;
            let accel = (1..4)
                .map(|f| ((v[f] - v[f - 1]) * fps).length())
                .sum::<f32>()
                / 3.0;
            for (k, e) in [horizontal, vertical, accel].into_iter().enumerate() {
                let g = got[3 * j + k];
                assert!(
                    (g - e).abs() <= 1e-3 * e.max(1.0),
                    "joint {j} feature {k}: {g} against {e}"
                );
            }
        }
        // The hips are where the body is measured from: they do not move.
        assert!(got[..3].iter().all(|v| *v < 1e-3), "{:?}", &got[..3]);
        assert!(got[3..].iter().any(|v| *v > 0.1), "{got:?}");
    }

    #[test]
    fn the_leaves_own_rotations_move_no_joint() {
        let device = cpu_device();
        let mut rng = Rng::new(3);
        let norm = normalizer(&mut rng);
        let shape = BodyShape::new(&norm, &device);
        let q = random_rotations(&mut rng);
        let mut turned = q;
        for leaf in [Joint::Head, Joint::LeftHand, Joint::RightHand] {
            turned[leaf.index()] = Quat::from_rotation_x(1.0) * q[leaf.index()];
        }
        let mut hips = q;
        hips[0] = Quat::from_rotation_x(0.3) * q[0];
        let row = |r: &[Quat; JOINT_COUNT]| rows(features(&norm, r), &device);
        let leaves = values(shape.distance_cm(row(&q), row(&turned)))[0];
        let tilted = values(shape.distance_cm(row(&q), row(&hips)))[0];
        assert!(leaves < 0.02, "{leaves} cm");
        assert!(tilted > 5.0, "{tilted} cm");
    }
}
