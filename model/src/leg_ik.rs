//! [`reach_with_leg`]: analytic two-bone inverse kinematics of a leg (hip, knee, ankle), so that
//! a planted foot can stay where it was put while the body above it travels.

use glam::{DVec3, Quat, Vec3};

use crate::rig::{JOINT_COUNT, Joint, Pose, Skeleton};

/// Shortest bone-to-target distance the solver aims for, m (a target on the hip joint has no
/// direction).
const NEAREST_M: f32 = 1e-3;

/// Moves the ankle of the leg whose hip joint is `upper` (`LeftUpperLeg` or `RightUpperLeg`) by
/// `shift` (world, metres) by turning the hip and knee, and keeps the foot's world rotation, so
/// the toes move by the same `shift` where the leg can reach. `positions` and `rotations` are
/// `pose`'s forward kinematics on `skeleton` and are updated for the leg's joints.
/// Returns false (the pose untouched) where the solution is not finite.
pub fn reach_with_leg(
    skeleton: &Skeleton,
    pose: &mut Pose,
    positions: &mut [Vec3; JOINT_COUNT],
    rotations: &mut [Quat; JOINT_COUNT],
    upper: Joint,
    shift: Vec3,
) -> bool {
    let Some((lower, foot, toes)) = leg_below(upper) else {
        return false;
    };
    let (hip, knee, ankle) = (
        positions[upper.index()],
        positions[lower.index()],
        positions[foot.index()],
    );
    let target = ankle + shift;
    let (thigh, shin) = ((knee - hip).length(), (ankle - knee).length());
    if thigh < NEAREST_M || shin < NEAREST_M {
        return false;
    }
    // In f64: near a straight knee the angles are acos of numbers near 1, where f32 loses
    // millimetres.
    let (h, k, a, t) = (
        hip.as_dvec3(),
        knee.as_dvec3(),
        ankle.as_dvec3(),
        target.as_dvec3(),
    );
    let (thigh, shin) = (f64::from(thigh), f64::from(shin));
    let nearest = f64::from(NEAREST_M);
    let reach = (t - h).length().clamp(nearest, thigh + shin - nearest);
    let angle = |u: DVec3, v: DVec3| {
        u.normalize_or_zero()
            .dot(v.normalize_or_zero())
            .clamp(-1.0, 1.0)
            .acos()
    };
    // The triangle hip-knee-ankle now and at the target's distance (law of cosines).
    let at_hip_now = angle(a - h, k - h);
    let at_knee_now = angle(h - k, a - k);
    let cosine = |x: f64, y: f64, opposite: f64| {
        ((x * x + y * y - opposite * opposite) / (2.0 * x * y))
            .clamp(-1.0, 1.0)
            .acos()
    };
    let at_hip = cosine(thigh, reach, shin);
    let at_knee = cosine(thigh, shin, reach);
    // The knee bends about the leg plane's normal; a straight leg has none, so it bends the way
    // its thigh's frame bends a knee (about the thigh's −x: the knee goes forward).
    let mut bend_axis = (a - h).cross(k - h);
    if bend_axis.length_squared() < 1e-12 {
        bend_axis = (rotations[upper.index()] * Vec3::NEG_X).as_dvec3();
    }
    let bend_axis = bend_axis.normalize().as_vec3();
    // Open the hip and the knee in the leg's plane to the target's distance, then swing the
    // opened leg at the hip onto the target (world rotations, in that order, so both are exact).
    let open_hip = Quat::from_axis_angle(bend_axis, (at_hip - at_hip_now) as f32);
    let open_knee = Quat::from_axis_angle(bend_axis, (at_knee - at_knee_now) as f32);
    let opened = open_hip * (knee - hip) + open_hip * open_knee * (ankle - knee);
    let swing = Quat::from_rotation_arc(opened.normalize(), (target - hip).normalize());
    let new_hip_world = (swing * open_hip * rotations[upper.index()]).normalize();
    let new_knee_world = (swing * open_hip * open_knee * rotations[lower.index()]).normalize();
    let parent = upper
        .parent()
        .map_or(Quat::IDENTITY, |p| rotations[p.index()]);
    let foot_world = rotations[foot.index()];
    let hip_local = (parent.inverse() * new_hip_world).normalize();
    let knee_local = (new_hip_world.inverse() * new_knee_world).normalize();
    let foot_local = (new_knee_world.inverse() * foot_world).normalize();
    if !(hip_local.is_finite() && knee_local.is_finite() && foot_local.is_finite()) {
        return false;
    }
    pose.local_rotations[upper.index()] = hip_local;
    pose.local_rotations[lower.index()] = knee_local;
    pose.local_rotations[foot.index()] = foot_local;
    rotations[upper.index()] = new_hip_world;
    rotations[lower.index()] = new_knee_world;
    rotations[foot.index()] = new_knee_world * foot_local;
    positions[lower.index()] = hip + new_hip_world * skeleton.offsets[lower.index()];
    positions[foot.index()] =
        positions[lower.index()] + new_knee_world * skeleton.offsets[foot.index()];
    positions[toes.index()] =
        positions[foot.index()] + rotations[foot.index()] * skeleton.offsets[toes.index()];
    true
}

/// Knee, ankle and toes below a hip joint.
fn leg_below(upper: Joint) -> Option<(Joint, Joint, Joint)> {
    use Joint::*;
    match upper {
        LeftUpperLeg => Some((LeftLowerLeg, LeftFoot, LeftToes)),
        RightUpperLeg => Some((RightLowerLeg, RightFoot, RightToes)),
        _ => None,
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    fn fk(skeleton: &Skeleton, pose: &Pose) -> ([Vec3; JOINT_COUNT], [Quat; JOINT_COUNT]) {
        let mut p = [Vec3::ZERO; JOINT_COUNT];
        let mut r = [Quat::IDENTITY; JOINT_COUNT];
        skeleton.forward_kinematics(pose, &mut p, &mut r);
        (p, r)
    }

    /// Bends both knees a little (thighs forward 0.3 rad, shins back 0.6 rad): a leg that
    /// can reach a target a few centimetres off in any direction.
    pub(crate) fn bend_knees(pose: &mut Pose) {
        for (upper, lower) in [
            (Joint::LeftUpperLeg, Joint::LeftLowerLeg),
            (Joint::RightUpperLeg, Joint::RightLowerLeg),
        ] {
            pose.set_rotation(upper, Quat::from_rotation_x(-0.3));
            pose.set_rotation(lower, Quat::from_rotation_x(0.6));
        }
    }

    /// A standing pose with both knees a little bent, the hips turned `yaw`.
    fn bent(skeleton: &Skeleton, yaw: f32) -> Pose {
        let mut pose = skeleton.rest_pose();
        pose.set_rotation(Joint::Hips, Quat::from_rotation_y(yaw));
        bend_knees(&mut pose);
        pose
    }

    #[test]
    fn the_toes_follow_a_reachable_shift_and_the_foot_keeps_its_turn() {
        let skeleton = Skeleton::default_adult();
        for (yaw, shift) in [
            (0.0, Vec3::new(0.05, 0.0, 0.0)),
            (0.7, Vec3::new(-0.04, 0.0, 0.06)),
            (-2.0, Vec3::new(0.0, 0.0, -0.08)),
            (1.0, Vec3::new(0.03, 0.02, 0.0)),
        ] {
            let mut pose = bent(&skeleton, yaw);
            let (mut p, mut r) = fk(&skeleton, &pose);
            let (toes_before, foot_turn) = (p[Joint::LeftToes.index()], r[Joint::LeftFoot.index()]);
            let right_before = p[Joint::RightToes.index()];
            assert!(reach_with_leg(
                &skeleton,
                &mut pose,
                &mut p,
                &mut r,
                Joint::LeftUpperLeg,
                shift
            ));
            let (p2, r2) = fk(&skeleton, &pose);
            let moved = p2[Joint::LeftToes.index()] - toes_before;
            assert!(
                (moved - shift).length() < 1e-4,
                "{yaw}: {moved} for {shift}"
            );
            assert!(r2[Joint::LeftFoot.index()].dot(foot_turn).abs() > 1.0 - 1e-6);
            assert!((p2[Joint::RightToes.index()] - right_before).length() < 1e-6);
            // The returned kinematics are the pose's.
            for j in Joint::ALL {
                assert!((p2[j.index()] - p[j.index()]).length() < 1e-4, "{j:?}");
            }
        }
    }

    #[test]
    fn a_straight_leg_bends_its_knee_forward_and_an_unreachable_target_straightens_it() {
        let skeleton = Skeleton::default_adult();
        // Rest: the legs are straight. Pull the ankle 10 cm up: the knee must come forward (+z).
        let mut pose = skeleton.rest_pose();
        let (mut p, mut r) = fk(&skeleton, &pose);
        let up = Vec3::new(0.0, 0.1, 0.0);
        let ankle = p[Joint::RightFoot.index()];
        assert!(reach_with_leg(
            &skeleton,
            &mut pose,
            &mut p,
            &mut r,
            Joint::RightUpperLeg,
            up
        ));
        assert!((p[Joint::RightFoot.index()] - (ankle + up)).length() < 1e-3);
        assert!(
            p[Joint::RightLowerLeg.index()].z > 0.05,
            "{}",
            p[Joint::RightLowerLeg.index()]
        );
        // Far out of reach: finite, the leg straight towards it, no further than the leg.
        let far = Vec3::new(2.0, -1.0, 0.0);
        assert!(reach_with_leg(
            &skeleton,
            &mut pose,
            &mut p,
            &mut r,
            Joint::RightUpperLeg,
            far
        ));
        assert!(pose.is_finite());
        let hip = p[Joint::RightUpperLeg.index()];
        let leg =
            skeleton.bone_length(Joint::RightLowerLeg) + skeleton.bone_length(Joint::RightFoot);
        let reach = (p[Joint::RightFoot.index()] - hip).length();
        assert!(
            reach <= leg + 1e-4 && reach > leg - 0.01,
            "{reach} of {leg}"
        );
        assert!(!reach_with_leg(
            &skeleton,
            &mut pose,
            &mut p,
            &mut r,
            Joint::Hips,
            up
        ));
    }
}
