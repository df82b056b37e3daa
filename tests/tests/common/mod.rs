//! Helpers shared by the end-to-end tests.

use model::rig::{JOINT_COUNT, Pose};

/// Frames at which any joint of `x` and `y` differs by more than the rotation whose quaternion
/// dot product is `dot` (e.g. 0.999 ≈ 5°).
pub fn frames_differing(x: &[Pose], y: &[Pose], dot: f32) -> usize {
    x.iter()
        .zip(y)
        .filter(|(p, q)| {
            (0..JOINT_COUNT).any(|j| p.local_rotations[j].dot(q.local_rotations[j]).abs() < dot)
        })
        .count()
}
