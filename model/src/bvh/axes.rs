//! Which way a BVH's world is up, which way its character faces and whether its axes are
//! right- or left-handed, found from the motion.
//!
//! BVH does not say. Up is the mean direction from the hips to the head over the motion (a
//! dancer is upright most of the time, whatever the file's rest pose: AMASS's re-exports keep a
//! Y-up skeleton and turn it Z-up with the root's rotation); left is the mean direction from the
//! right hip (or shoulder) to the left one; each is snapped to the nearest file axis. Forward is
//! then fixed by the body, not by the axes: the toes point forward from the ankles, and bent
//! knees point forward from the line between hip and ankle. When left × up points forward the
//! file is right-handed, as ours is; when it points backward, it is left-handed and the map to
//! our axes is a reflection.

use glam::{Mat3, Vec3};

use super::Bvh;
use crate::rig::{JOINT_COUNT, Joint};
use crate::rotation::rotation_between;

/// Most frames read to find the axes.
const SAMPLE_FRAMES: usize = 240;
/// Joints above the hips that say where up is, the first mapped one used.
pub(crate) const ABOVE_HIPS: [Joint; 4] =
    [Joint::Head, Joint::Neck, Joint::UpperChest, Joint::Chest];
/// Left–right pairs that say where the body's left is.
const LEFT_RIGHT: [(Joint, Joint); 3] = [
    (Joint::LeftUpperLeg, Joint::RightUpperLeg),
    (Joint::LeftUpperArm, Joint::RightUpperArm),
    (Joint::LeftShoulder, Joint::RightShoulder),
];

/// The file's axes as found, and how sure the finding is.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DetectedAxes {
    /// Maps file coordinates to ours (+Y up, character's left +X, facing +Z); orthogonal.
    pub axes: Mat3,
    /// Mean cosine between the hips-to-head direction and the chosen up axis, [−1, 1].
    pub up_agreement: f32,
    /// Whether the character's facing decided the handedness (toes or knees were mapped and
    /// pointed clearly one way); otherwise the file is taken to be right-handed.
    pub facing_seen: bool,
}

/// The signed file axis nearest `v` (unit), or `None` for a zero vector.
fn snap(v: Vec3) -> Option<Vec3> {
    let a = v.abs();
    if a.max_element() <= 1e-9 || !v.is_finite() {
        return None;
    }
    Some(if a.x >= a.y && a.x >= a.z {
        Vec3::new(v.x.signum(), 0.0, 0.0)
    } else if a.y >= a.z {
        Vec3::new(0.0, v.y.signum(), 0.0)
    } else {
        Vec3::new(0.0, 0.0, v.z.signum())
    })
}

/// The orthogonal map taking `left` to +X, `up` to +Y and `forward` to +Z (all unit, pairwise
/// perpendicular).
pub(crate) fn map_to_ours(left: Vec3, up: Vec3, forward: Vec3) -> Mat3 {
    Mat3::from_cols(left, up, forward).transpose()
}

/// What a user says of a file's axes; what is left `None` is found from the motion.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct AxisHints {
    /// The file axis that is up (a signed unit axis, e.g. +Z).
    pub up: Option<Vec3>,
    /// Whether the file is left-handed.
    pub left_handed: Option<bool>,
}

impl AxisHints {
    /// Parses an up axis as users write it: `y`, `z`, `-z`, `+x`, … (case-insensitive).
    pub fn parse_up(text: &str) -> Option<Vec3> {
        let t = text.trim().to_ascii_lowercase();
        let (sign, axis) = match t.strip_prefix('-') {
            Some(rest) => (-1.0, rest),
            None => (1.0, t.strip_prefix('+').unwrap_or(&t)),
        };
        let v = match axis {
            "x" => Vec3::X,
            "y" => Vec3::Y,
            "z" => Vec3::Z,
            _ => return None,
        };
        Some(v * sign)
    }
}

/// Finds the axes of `bvh` from its motion, given the source joint driving each of ours and
/// what the user said (`hints`); `None` when the hips, a joint above them and a left–right pair
/// are not all mapped.
pub fn detect_axes(
    bvh: &Bvh,
    source_joints: &[Option<usize>; JOINT_COUNT],
    hints: &AxisHints,
) -> Option<DetectedAxes> {
    let s = |j: Joint| source_joints[j.index()];
    let hips = s(Joint::Hips)?;
    let top = ABOVE_HIPS.into_iter().find_map(s)?;
    let pairs: Vec<(usize, usize)> = LEFT_RIGHT
        .into_iter()
        .filter_map(|(l, r)| Some((s(l)?, s(r)?)))
        .collect();
    if pairs.is_empty() {
        return None;
    }
    let frames = bvh.frames.len();
    let count = frames.clamp(1, SAMPLE_FRAMES);
    let positions: Vec<Vec<Vec3>> = if frames == 0 {
        vec![bvh.rest_positions()]
    } else {
        let (mut rotations, mut p) = (Vec::new(), Vec::new());
        (0..count)
            .map(|k| {
                bvh.world_transforms(k * frames / count, &mut rotations, &mut p);
                p.clone()
            })
            .collect()
    };

    let mean_direction = |f: &dyn Fn(&[Vec3]) -> Vec3| -> Vec3 {
        positions
            .iter()
            .map(|p| f(p).normalize_or_zero())
            .sum::<Vec3>()
    };
    let up_sum = mean_direction(&|p| p[top] - p[hips]);
    let up = match hints.up {
        Some(up) => up,
        None => snap(up_sum)?,
    };
    let up_agreement = up_sum.dot(up) / positions.len() as f32;
    let left_sum = mean_direction(&|p| {
        pairs
            .iter()
            .map(|&(l, r)| (p[l] - p[r]).normalize_or_zero())
            .sum::<Vec3>()
    });
    let left = snap(left_sum - up * left_sum.dot(up))?;

    // Forward as the body shows it: toes ahead of ankles, bent knees ahead of the hip–ankle line.
    let mut forward_sum = Vec3::ZERO;
    for (foot, toes) in [
        (Joint::LeftFoot, Joint::LeftToes),
        (Joint::RightFoot, Joint::RightToes),
    ] {
        if let (Some(f), Some(t)) = (s(foot), s(toes)) {
            forward_sum += mean_direction(&|p| p[t] - p[f]);
        }
    }
    for (hip, knee, ankle) in [
        (Joint::LeftUpperLeg, Joint::LeftLowerLeg, Joint::LeftFoot),
        (Joint::RightUpperLeg, Joint::RightLowerLeg, Joint::RightFoot),
    ] {
        if let (Some(h), Some(k), Some(a)) = (s(hip), s(knee), s(ankle)) {
            forward_sum += mean_direction(&|p| p[k] - (p[h] + p[a]) * 0.5) * 0.5;
        }
    }
    // Left × up is forward in a right-handed file.
    let facing = forward_sum.dot(left.cross(up)) / positions.len() as f32;
    // Less than a tenth of a unit vector on average says nothing.
    let facing_seen = facing.abs() > 0.1;
    // The least turn that stands the file up keeps its headings; a left-handed file is
    // mirrored left to right as well.
    let stand_up = Mat3::from_quat(rotation_between(up, Vec3::Y));
    let left_handed = hints.left_handed.unwrap_or(facing_seen && facing < 0.0);
    let mirror = if left_handed {
        Mat3::from_diagonal(Vec3::new(-1.0, 1.0, 1.0))
    } else {
        Mat3::IDENTITY
    };
    let axes = round_to_axes(mirror * stand_up);
    Some(DetectedAxes {
        axes,
        up_agreement,
        facing_seen,
    })
}

/// `m` with every entry rounded to −1, 0 or 1 (a signed permutation, as snapped axes give).
fn round_to_axes(m: Mat3) -> Mat3 {
    Mat3::from_cols_array(&m.to_cols_array().map(f32::round))
}

/// A short description of `axes` for people: which file axis is up and the handedness
/// (`"Z up, right-handed"`).
pub fn describe_axes(axes: &Mat3) -> String {
    // The file axis that becomes +Y is the second row of the map.
    let up = axes.row(1);
    let name = if up.x.abs() > 0.5 {
        if up.x > 0.0 { "X" } else { "−X" }
    } else if up.y.abs() > 0.5 {
        if up.y > 0.0 { "Y" } else { "−Y" }
    } else if up.z > 0.0 {
        "Z"
    } else {
        "−Z"
    };
    let handed = if axes.determinant() > 0.0 {
        "right-handed"
    } else {
        "left-handed"
    };
    format!("{name} up, {handed}")
}

/// The rotation turning a zero pose (hips, a joint above them and left–right pairs at
/// `positions`, already in our axes) upright: its up to +Y and its left to +X, each snapped to
/// an axis, so a T-pose lying in the file (a Y-up skeleton in a Z-up world) is judged as the
/// T-pose it is. Identity when the pose does not say.
pub(crate) fn upright(
    positions: &[Vec3],
    source_joints: &[Option<usize>; JOINT_COUNT],
) -> glam::Quat {
    let s = |j: Joint| source_joints[j.index()];
    let Some(hips) = s(Joint::Hips) else {
        return glam::Quat::IDENTITY;
    };
    let Some(top) = ABOVE_HIPS.into_iter().find_map(s) else {
        return glam::Quat::IDENTITY;
    };
    let Some(up) = snap(positions[top] - positions[hips]) else {
        return glam::Quat::IDENTITY;
    };
    let left_sum: Vec3 = LEFT_RIGHT
        .into_iter()
        .filter_map(|(l, r)| Some((positions[s(l)?] - positions[s(r)?]).normalize_or_zero()))
        .sum();
    match snap(left_sum - up * left_sum.dot(up)) {
        Some(left) if left.dot(up).abs() < 0.5 => {
            glam::Quat::from_mat3(&map_to_ours(left, up, left.cross(up))).normalize()
        }
        _ => rotation_between(up, Vec3::Y),
    }
}
