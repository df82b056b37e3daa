//! The body shape of a pose, which is what a key pose fixes, and the distance a key pose is
//! scored by (`danced eval`, the key-pose loss of `danced-train`).

use glam::{Quat, Vec3};

use crate::motion::{heading, yaw};
use crate::rig::{JOINT_COUNT, Joint, Pose, Skeleton};

/// A pose's body shape: joint positions relative to the hips with the heading removed, on the
/// default rig (what a key pose fixes; where the dancer stands and faces is not part of it).
pub fn body_shape(rotations: &[Quat; JOINT_COUNT]) -> [Vec3; JOINT_COUNT] {
    let mut pose = Pose::rest();
    pose.local_rotations = *rotations;
    let h = heading(pose.local_rotations[0]);
    pose.local_rotations[0] = (yaw(-h) * pose.local_rotations[0]).normalize();
    pose.root_position = Vec3::ZERO;
    let mut w = [Vec3::ZERO; JOINT_COUNT];
    Skeleton::default_adult().world_positions(&pose, &mut w);
    let hips = w[Joint::Hips.index()];
    w.map(|p| p - hips)
}

/// Mean joint position error between a pose and a key pose, cm (body shape only: where the
/// dancer stands and which way it faces are not part of a key pose).
pub fn key_pose_error_cm(pose: &Pose, target: &[Quat; JOINT_COUNT]) -> f64 {
    let (a, b) = (body_shape(&pose.local_rotations), body_shape(target));
    100.0
        * a.iter()
            .zip(&b)
            .map(|(x, y)| x.distance(*y) as f64)
            .sum::<f64>()
        / JOINT_COUNT as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn error_ignores_heading_and_sees_an_arm() {
        let rest = [Quat::IDENTITY; JOINT_COUNT];
        let mut turned = Pose::rest();
        turned.local_rotations[0] = Quat::from_rotation_y(1.3);
        assert!(key_pose_error_cm(&turned, &rest) < 1e-3);
        let mut arm = Pose::rest();
        arm.set_rotation(Joint::LeftUpperArm, Quat::from_rotation_z(1.0));
        let e = key_pose_error_cm(&arm, &rest);
        // Elbow, hand move by tens of cm; averaged over 22 joints it is a few cm.
        assert!(e > 1.0 && e < 10.0, "{e}");
    }
}
