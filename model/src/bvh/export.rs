//! Export of motion on our rig as BVH.
//!
//! # The file
//!
//! - Joints are ours, named as [`Joint::name`] (`HumanBodyBones`), in our hierarchy; `Hips` is
//!   the root.
//! - Lengths are in **centimetres** (the usual BVH unit: MotionBuilder, Mixamo and the Bandai
//!   Namco data use it). Blender imports it 100× too large unless its importer's scale is set to
//!   0.01; that only matters for viewing.
//! - Axes are ours: +Y up, the character faces +Z with its left at +X at rest. `OFFSET`s are the
//!   skeleton's rest offsets, so all channels at 0 is our T-pose.
//! - `Hips` has `Xposition Yposition Zposition Zrotation Xrotation Yrotation` (the position is
//!   the hips' world position, replacing the root's `OFFSET`, which holds the rest position);
//!   every other joint has `Zrotation Xrotation Yrotation`, so its local rotation is
//!   `Rz · Rx · Ry` of the written angles (degrees).
//! - `Head`, the hands and the toes have an `End Site`: the top of the head, the fingertips and
//!   the tip of the toes, so viewers draw those bones with a length.

use glam::{DMat3, Quat, Vec3};

use super::{Bvh, BvhJoint, Channel};
use crate::rig::{JOINT_COUNT, Joint, Pose, Skeleton};
use crate::rotation::normalize_or_identity;

/// Centimetres per metre: the file's unit over ours.
const CM_PER_M: f32 = 100.0;

/// `poses` on `skeleton` as a BVH at `fps` frames per second (see the module documentation for
/// the layout).
///
/// A non-finite or non-positive `fps` is written as 30; non-finite rotations as the identity and
/// a non-finite root position as the skeleton's rest position, so the file always parses.
pub fn export(skeleton: &Skeleton, poses: &[Pose], fps: f64) -> Bvh {
    let fps = if fps.is_finite() && fps > 0.0 {
        fps
    } else {
        30.0
    };
    let rotation_channels = vec![Channel::Zrotation, Channel::Xrotation, Channel::Yrotation];
    let mut joints = Vec::with_capacity(JOINT_COUNT);
    for joint in Joint::ALL {
        let i = joint.index();
        let mut channels = rotation_channels.clone();
        if joint.parent().is_none() {
            channels.splice(
                0..0,
                [Channel::Xposition, Channel::Yposition, Channel::Zposition],
            );
        }
        joints.push(BvhJoint {
            name: joint.name().to_owned(),
            parent: joint.parent().map(Joint::index),
            offset: finite_or_zero(skeleton.offsets[i]) * CM_PER_M,
            channels,
            end_site: end_site(skeleton, joint).map(|e| e * CM_PER_M),
        });
    }
    let rest_root = finite_or_zero(skeleton.offsets[Joint::Hips.index()]);
    let frames = poses
        .iter()
        .map(|pose| {
            let mut values = Vec::with_capacity(3 + 3 * JOINT_COUNT);
            let root = if pose.root_position.is_finite() {
                pose.root_position
            } else {
                rest_root
            };
            values.extend((root * CM_PER_M).to_array());
            for q in pose.local_rotations {
                values.extend(zxy_degrees(q));
            }
            values
        })
        .collect();
    Bvh {
        joints,
        frame_time_s: 1.0 / fps,
        frames,
    }
}

/// [`export`] written as BVH text.
pub fn export_to_string(skeleton: &Skeleton, poses: &[Pose], fps: f64) -> String {
    export(skeleton, poses, fps).to_string()
}

fn finite_or_zero(v: Vec3) -> Vec3 {
    if v.is_finite() { v } else { Vec3::ZERO }
}

/// The end of the bone that starts at `joint`, from it, metres; `None` if another joint
/// continues the chain.
fn end_site(skeleton: &Skeleton, joint: Joint) -> Option<Vec3> {
    let default = Skeleton::default_adult();
    // A zero-length bone has no direction; the default adult's is the T-pose one.
    let direction = |j: Joint| {
        finite_or_zero(skeleton.offsets[j.index()])
            .try_normalize()
            .unwrap_or_else(|| default.offsets[j.index()].normalize())
    };
    let length = |j: Joint| {
        let l = skeleton.bone_length(j);
        if l.is_finite() { l } else { 0.0 }
    };
    // Proportions of the default adult: top of the head 0.13 m above the head joint (1.3×
    // the neck-to-head bone), fingertips 0.08 m past the wrist (a third of the forearm), tip
    // of the toes 0.05 m ahead of their joint.
    match joint {
        Joint::Head => Some(direction(Joint::Head) * length(Joint::Head) * 1.3),
        Joint::LeftHand | Joint::RightHand => Some(direction(joint) * length(joint) / 3.0),
        Joint::LeftToes | Joint::RightToes => Some(Vec3::Z * length(joint) * 0.37),
        _ => None,
    }
}

/// Angles `(z, x, y)` in degrees with `Rz(z) · Rx(x) · Ry(y) = q`.
///
/// In f64, and `y` is solved from what `z` and `x` leave, so the three compose back to `q` even
/// at gimbal lock (`x = ±90°`), where `z` and `y` alone are ill-conditioned.
pub(crate) fn zxy_degrees(q: Quat) -> [f32; 3] {
    let m = DMat3::from_quat(normalize_or_identity(q).as_dquat());
    // Rz·Rx·Ry has row 2 = [−cx·sy, sx, cx·cy] and column 1 = [−sz·cx, cz·cx, sx].
    let (m01, m11, m21) = (m.y_axis.x, m.y_axis.y, m.y_axis.z);
    let x = m21.atan2(m01.hypot(m11));
    // At gimbal lock m01 = m11 = 0 and any z will do: y takes up the rest.
    let z = (-m01).atan2(m11);
    let ry = DMat3::from_rotation_x(-x) * DMat3::from_rotation_z(-z) * m;
    let y = ry.z_axis.x.atan2(ry.x_axis.x);
    // + 0.0 turns −0 into 0, which reads better in the file.
    [
        z.to_degrees() as f32 + 0.0,
        x.to_degrees() as f32 + 0.0,
        y.to_degrees() as f32 + 0.0,
    ]
}
