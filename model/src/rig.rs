//! The humanoid rig: joints, rest skeleton, poses and forward kinematics.
//!
//! # Conventions
//!
//! - Right-handed coordinates, **+Y up**, lengths in **metres**.
//! - The character **faces +Z**; its **left is +X** (so its right is −X).
//! - The rest pose is a **T-pose with identity local rotations**: arms straight out along ±X,
//!   legs straight down −Y, spine and neck straight up +Y, toes pointing forward (+Z). A joint's
//!   local rotation is relative to its parent's frame, and all frames are axis-aligned with the
//!   world at rest, so a local rotation of identity means "as in the T-pose".
//! - A joint's rotation turns the bones of its *children*: rotating `LeftUpperArm` swings the
//!   elbow (`LeftLowerArm`) and everything below it.
//! - Joint names are exactly Unity's `HumanBodyBones` names (VMC sends bone names as those
//!   strings), so sending a pose over VMC is a renaming, not a retargeting.
//!
//! # Unity (and VMC) coordinates
//!
//! Unity is left-handed with +Y up, +Z forward and +X to the character's *right*. Our +X is the
//! character's left, so going to Unity is the reflection `M = diag(−1, 1, 1)`:
//!
//! - positions and offsets: `(x, y, z) → (−x, y, z)` ([`to_unity_position`]);
//! - rotations: `(x, y, z, w) → (x, −y, −z, w)`, the same rotation as `(−x, y, z, −w)`
//!   ([`to_unity_rotation`]).
//!
//! Why: a rotation `R` of our space is `M R M` in Unity's. For a unit quaternion `(v, w)`,
//! `R p = p + 2w (v × p) + 2 v × (v × p)`, and a reflection flips cross products
//! (`M(a × b) = −(Ma × Mb)`), so `M R M` is the quaternion `(−Mv, w)`. Rotations about X keep
//! their quaternion (nodding forward is nodding forward in both), rotations about Y and Z flip
//! their angle (turning left is a positive yaw here, a negative one in Unity). The map is its
//! own inverse and commutes with composition, so local rotations convert one by one, and the
//! left/right bone names need no swapping: our `LeftHand` at +X lands at Unity's −X, the
//! character's left there too. A VMC sender sends, per bone, `to_unity_position(offset)` and
//! `to_unity_rotation(local_rotation)`; it assumes the avatar's bones are "normalised" (identity
//! rest rotations in T-pose, as UniVRM's normalised humanoid), like ours.

use std::fmt;
use std::str::FromStr;

use glam::{Quat, Vec3};

use crate::ModelError;

/// Number of joints in the rig.
pub const JOINT_COUNT: usize = 22;

/// A bone of the humanoid rig, named and parented as Unity's `HumanBodyBones`.
///
/// The discriminants are indices into per-joint arrays; every parent comes before its
/// children, so one pass in index order is a valid forward-kinematics order.
#[repr(usize)]
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Joint {
    /// Pelvis; the root of the hierarchy.
    Hips = 0,
    /// Lower spine, child of `Hips`.
    Spine,
    /// Middle spine, child of `Spine`.
    Chest,
    /// Upper spine, child of `Chest`; parent of the neck and both shoulders.
    UpperChest,
    /// Base of the neck, child of `UpperChest`.
    Neck,
    /// Base of the skull, child of `Neck`.
    Head,
    /// Left clavicle, child of `UpperChest`.
    LeftShoulder,
    /// Left shoulder joint, child of `LeftShoulder`.
    LeftUpperArm,
    /// Left elbow, child of `LeftUpperArm`.
    LeftLowerArm,
    /// Left wrist, child of `LeftLowerArm`.
    LeftHand,
    /// Right clavicle, child of `UpperChest`.
    RightShoulder,
    /// Right shoulder joint, child of `RightShoulder`.
    RightUpperArm,
    /// Right elbow, child of `RightUpperArm`.
    RightLowerArm,
    /// Right wrist, child of `RightLowerArm`.
    RightHand,
    /// Left hip joint, child of `Hips`.
    LeftUpperLeg,
    /// Left knee, child of `LeftUpperLeg`.
    LeftLowerLeg,
    /// Left ankle, child of `LeftLowerLeg`.
    LeftFoot,
    /// Left ball of the foot, child of `LeftFoot`.
    LeftToes,
    /// Right hip joint, child of `Hips`.
    RightUpperLeg,
    /// Right knee, child of `RightUpperLeg`.
    RightLowerLeg,
    /// Right ankle, child of `RightLowerLeg`.
    RightFoot,
    /// Right ball of the foot, child of `RightFoot`.
    RightToes,
}

impl Joint {
    /// Every joint in index order (parents before children).
    pub const ALL: [Joint; JOINT_COUNT] = [
        Joint::Hips,
        Joint::Spine,
        Joint::Chest,
        Joint::UpperChest,
        Joint::Neck,
        Joint::Head,
        Joint::LeftShoulder,
        Joint::LeftUpperArm,
        Joint::LeftLowerArm,
        Joint::LeftHand,
        Joint::RightShoulder,
        Joint::RightUpperArm,
        Joint::RightLowerArm,
        Joint::RightHand,
        Joint::LeftUpperLeg,
        Joint::LeftLowerLeg,
        Joint::LeftFoot,
        Joint::LeftToes,
        Joint::RightUpperLeg,
        Joint::RightLowerLeg,
        Joint::RightFoot,
        Joint::RightToes,
    ];

    /// This joint's index into per-joint arrays.
    #[inline]
    pub const fn index(self) -> usize {
        self as usize
    }

    /// The joint with index `index`, or `None` past the last joint.
    #[inline]
    pub const fn from_index(index: usize) -> Option<Joint> {
        if index < JOINT_COUNT {
            Some(Joint::ALL[index])
        } else {
            None
        }
    }

    /// The parent joint, `None` for the root (`Hips`).
    pub const fn parent(self) -> Option<Joint> {
        use Joint::*;
        match self {
            Hips => None,
            Spine => Some(Hips),
            Chest => Some(Spine),
            UpperChest => Some(Chest),
            Neck => Some(UpperChest),
            Head => Some(Neck),
            LeftShoulder | RightShoulder => Some(UpperChest),
            LeftUpperArm => Some(LeftShoulder),
            LeftLowerArm => Some(LeftUpperArm),
            LeftHand => Some(LeftLowerArm),
            RightUpperArm => Some(RightShoulder),
            RightLowerArm => Some(RightUpperArm),
            RightHand => Some(RightLowerArm),
            LeftUpperLeg | RightUpperLeg => Some(Hips),
            LeftLowerLeg => Some(LeftUpperLeg),
            LeftFoot => Some(LeftLowerLeg),
            LeftToes => Some(LeftFoot),
            RightLowerLeg => Some(RightUpperLeg),
            RightFoot => Some(RightLowerLeg),
            RightToes => Some(RightFoot),
        }
    }

    /// The Unity `HumanBodyBones` name, e.g. `"LeftUpperArm"`.
    pub const fn name(self) -> &'static str {
        use Joint::*;
        match self {
            Hips => "Hips",
            Spine => "Spine",
            Chest => "Chest",
            UpperChest => "UpperChest",
            Neck => "Neck",
            Head => "Head",
            LeftShoulder => "LeftShoulder",
            LeftUpperArm => "LeftUpperArm",
            LeftLowerArm => "LeftLowerArm",
            LeftHand => "LeftHand",
            RightShoulder => "RightShoulder",
            RightUpperArm => "RightUpperArm",
            RightLowerArm => "RightLowerArm",
            RightHand => "RightHand",
            LeftUpperLeg => "LeftUpperLeg",
            LeftLowerLeg => "LeftLowerLeg",
            LeftFoot => "LeftFoot",
            LeftToes => "LeftToes",
            RightUpperLeg => "RightUpperLeg",
            RightLowerLeg => "RightLowerLeg",
            RightFoot => "RightFoot",
            RightToes => "RightToes",
        }
    }

    /// The joint with this `HumanBodyBones` name (ASCII case-insensitive), `None` if unknown.
    pub fn from_name(name: &str) -> Option<Joint> {
        // Other VMC senders and hand-written files are not always careful with case.
        Joint::ALL
            .into_iter()
            .find(|j| j.name().eq_ignore_ascii_case(name.trim()))
    }

    /// The same joint on the other side of the body (`LeftHand` ↔ `RightHand`); itself on the midline.
    pub const fn mirror(self) -> Joint {
        use Joint::*;
        match self {
            LeftShoulder => RightShoulder,
            LeftUpperArm => RightUpperArm,
            LeftLowerArm => RightLowerArm,
            LeftHand => RightHand,
            RightShoulder => LeftShoulder,
            RightUpperArm => LeftUpperArm,
            RightLowerArm => LeftLowerArm,
            RightHand => LeftHand,
            LeftUpperLeg => RightUpperLeg,
            LeftLowerLeg => RightLowerLeg,
            LeftFoot => RightFoot,
            LeftToes => RightToes,
            RightUpperLeg => LeftUpperLeg,
            RightLowerLeg => LeftLowerLeg,
            RightFoot => LeftFoot,
            RightToes => LeftToes,
            midline => midline,
        }
    }
}

impl fmt::Display for Joint {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Joint {
    type Err = ModelError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Joint::from_name(s).ok_or_else(|| ModelError::UnknownJoint(s.to_owned()))
    }
}

/// Converts a position or offset from our coordinates to Unity's (and back: it is an involution).
#[inline]
pub fn to_unity_position(p: Vec3) -> Vec3 {
    Vec3::new(-p.x, p.y, p.z)
}

/// Converts a rotation from our coordinates to Unity's (and back: it is an involution).
#[inline]
pub fn to_unity_rotation(q: Quat) -> Quat {
    Quat::from_xyzw(q.x, -q.y, -q.z, q.w)
}

/// Rest offsets of [`Skeleton::default_adult`], indexed by joint.
///
/// Proportions of a ~1.70 m adult: hips at 0.95 m, shoulder joints at 1.42 m, 0.36 m apart,
/// head joint (base of the skull) at 1.57 m with the top of the head ~0.13 m above it.
const DEFAULT_ADULT_OFFSETS: [Vec3; JOINT_COUNT] = [
    Vec3::new(0.0, 0.95, 0.0),    // Hips: rest position above the origin
    Vec3::new(0.0, 0.10, 0.0),    // Spine
    Vec3::new(0.0, 0.12, 0.0),    // Chest
    Vec3::new(0.0, 0.12, 0.0),    // UpperChest
    Vec3::new(0.0, 0.18, 0.0),    // Neck
    Vec3::new(0.0, 0.10, 0.0),    // Head
    Vec3::new(0.03, 0.13, 0.0),   // LeftShoulder
    Vec3::new(0.15, 0.0, 0.0),    // LeftUpperArm
    Vec3::new(0.27, 0.0, 0.0),    // LeftLowerArm
    Vec3::new(0.24, 0.0, 0.0),    // LeftHand
    Vec3::new(-0.03, 0.13, 0.0),  // RightShoulder
    Vec3::new(-0.15, 0.0, 0.0),   // RightUpperArm
    Vec3::new(-0.27, 0.0, 0.0),   // RightLowerArm
    Vec3::new(-0.24, 0.0, 0.0),   // RightHand
    Vec3::new(0.09, -0.05, 0.0),  // LeftUpperLeg
    Vec3::new(0.0, -0.42, 0.0),   // LeftLowerLeg
    Vec3::new(0.0, -0.40, 0.0),   // LeftFoot
    Vec3::new(0.0, -0.06, 0.12),  // LeftToes
    Vec3::new(-0.09, -0.05, 0.0), // RightUpperLeg
    Vec3::new(0.0, -0.42, 0.0),   // RightLowerLeg
    Vec3::new(0.0, -0.40, 0.0),   // RightFoot
    Vec3::new(0.0, -0.06, 0.12),  // RightToes
];

/// Bone offsets of a rig in its rest T-pose.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Skeleton {
    /// Each joint's rest offset from its parent in the parent's frame, metres; for `Hips`, its
    /// rest position above the origin (standing height), which FK ignores in favour of
    /// [`Pose::root_position`].
    pub offsets: [Vec3; JOINT_COUNT],
}

impl Default for Skeleton {
    fn default() -> Self {
        Self::default_adult()
    }
}

impl Skeleton {
    /// A ~1.70 m adult in T-pose, hips at 0.95 m.
    pub const fn default_adult() -> Self {
        Skeleton {
            offsets: DEFAULT_ADULT_OFFSETS,
        }
    }

    /// The default adult's bone directions with these lengths (metres, indexed by joint;
    /// `lengths[Hips]` is the standing hip height).
    pub fn with_bone_lengths(lengths: &[f32; JOINT_COUNT]) -> Result<Self, ModelError> {
        let mut skeleton = Self::default_adult();
        for joint in Joint::ALL {
            skeleton.set_bone_length(joint, lengths[joint.index()])?;
        }
        Ok(skeleton)
    }

    /// Scales the bone ending at `joint` to `length` metres, keeping its direction (for `Hips`,
    /// sets the standing hip height).
    pub fn set_bone_length(&mut self, joint: Joint, length: f32) -> Result<(), ModelError> {
        if !length.is_finite() || length < 0.0 {
            return Err(ModelError::InvalidBoneLength { joint, length });
        }
        let i = joint.index();
        // A bone shrunk to zero has lost its direction; the default adult's is the T-pose one.
        let direction = self.offsets[i]
            .try_normalize()
            .unwrap_or_else(|| DEFAULT_ADULT_OFFSETS[i].normalize());
        self.offsets[i] = direction * length;
        Ok(())
    }

    /// This skeleton with every offset (so every length and the hip height) times `factor`;
    /// a negative or non-finite `factor` is an error.
    pub fn scaled(&self, factor: f32) -> Result<Self, ModelError> {
        if !factor.is_finite() || factor < 0.0 {
            return Err(ModelError::InvalidBoneLength {
                joint: Joint::Hips,
                length: self.offsets[0].length() * factor,
            });
        }
        Ok(Skeleton {
            offsets: self.offsets.map(|o| o * factor),
        })
    }

    /// Length of the bone from `joint`'s parent to `joint`, metres; 0 for `Hips`.
    #[inline]
    pub fn bone_length(&self, joint: Joint) -> f32 {
        if joint.parent().is_none() {
            0.0
        } else {
            self.offsets[joint.index()].length()
        }
    }

    /// The standing hip height (the `Hips` rest offset's length), metres.
    #[inline]
    pub fn hip_height(&self) -> f32 {
        self.offsets[Joint::Hips.index()].length()
    }

    /// The T-pose with the hips at their rest position, feet on the floor for the default adult.
    pub fn rest_pose(&self) -> Pose {
        Pose {
            root_position: self.offsets[Joint::Hips.index()],
            ..Pose::rest()
        }
    }

    /// World rotation of every joint (parent's world rotation times the local one).
    pub fn world_rotations(&self, pose: &Pose, out: &mut [Quat; JOINT_COUNT]) {
        for joint in Joint::ALL {
            let i = joint.index();
            let local = pose.local_rotations[i];
            out[i] = match joint.parent() {
                Some(p) => out[p.index()] * local,
                None => local,
            };
        }
    }

    /// World position of every joint, metres.
    pub fn world_positions(&self, pose: &Pose, out: &mut [Vec3; JOINT_COUNT]) {
        let mut rotations = [Quat::IDENTITY; JOINT_COUNT];
        self.forward_kinematics(pose, out, &mut rotations);
    }

    /// World positions of every joint for a whole motion, frame after frame (`poses.len() ×
    /// JOINT_COUNT` values), the layout the dance metrics take.
    pub fn trajectory(&self, poses: &[Pose]) -> Vec<Vec3> {
        let mut out = Vec::with_capacity(poses.len() * JOINT_COUNT);
        let mut frame = [Vec3::ZERO; JOINT_COUNT];
        for pose in poses {
            self.world_positions(pose, &mut frame);
            out.extend_from_slice(&frame);
        }
        out
    }

    /// The mean distance the joints of a [`Skeleton::trajectory`] travel from frame `f − 1`
    /// to frame `f` (`f` ≥ 1), in metres: the dance metrics' joint speed, per frame.
    pub fn mean_joint_step(track: &[Vec3], f: usize) -> f64 {
        let (now, before) = (&track[f * JOINT_COUNT..], &track[(f - 1) * JOINT_COUNT..]);
        (0..JOINT_COUNT)
            .map(|j| f64::from(now[j].distance(before[j])))
            .sum::<f64>()
            / JOINT_COUNT as f64
    }

    /// World positions and rotations of every joint in one pass.
    pub fn forward_kinematics(
        &self,
        pose: &Pose,
        positions: &mut [Vec3; JOINT_COUNT],
        rotations: &mut [Quat; JOINT_COUNT],
    ) {
        for joint in Joint::ALL {
            let i = joint.index();
            let local = pose.local_rotations[i];
            match joint.parent() {
                Some(p) => {
                    let p = p.index();
                    positions[i] = positions[p] + rotations[p] * self.offsets[i];
                    rotations[i] = rotations[p] * local;
                }
                None => {
                    positions[i] = pose.root_position;
                    rotations[i] = local;
                }
            }
        }
    }
}

/// One frame of motion: where the hips are and how every joint is rotated.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pose {
    /// World position of the `Hips` joint, metres.
    pub root_position: Vec3,
    /// Each joint's rotation relative to its parent (unit quaternions); `Hips`' is its world rotation.
    pub local_rotations: [Quat; JOINT_COUNT],
}

impl Default for Pose {
    fn default() -> Self {
        Self::rest()
    }
}

impl Pose {
    /// The T-pose with the hips at the origin (see [`Skeleton::rest_pose`] to stand on the floor).
    pub const fn rest() -> Self {
        Pose {
            root_position: Vec3::ZERO,
            local_rotations: [Quat::IDENTITY; JOINT_COUNT],
        }
    }

    /// The local rotation of `joint`.
    #[inline]
    pub fn rotation(&self, joint: Joint) -> Quat {
        self.local_rotations[joint.index()]
    }

    /// Sets the local rotation of `joint`.
    #[inline]
    pub fn set_rotation(&mut self, joint: Joint, rotation: Quat) {
        self.local_rotations[joint.index()] = rotation;
    }

    /// Whether every number in the pose is finite (imported files can hold NaNs).
    pub fn is_finite(&self) -> bool {
        self.root_position.is_finite() && self.local_rotations.iter().all(|q| q.is_finite())
    }
}

/// Blends two poses: root lerped, rotations slerped.
pub fn blend(a: &Pose, b: &Pose, w: f32, out: &mut Pose) {
    out.root_position = a.root_position.lerp(b.root_position, w);
    for i in 0..JOINT_COUNT {
        out.local_rotations[i] = a.local_rotations[i].slerp(b.local_rotations[i], w);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use std::f32::consts::FRAC_PI_2;

    const EPS: f32 = 1e-5;

    #[test]
    fn the_mean_joint_step_is_how_far_the_joints_travel_on_average() {
        let mut track = vec![Vec3::ZERO; 2 * JOINT_COUNT];
        // One joint 0.3 m, one 0.1 m further: the mean of 22 joints, the others still.
        track[JOINT_COUNT] = Vec3::new(0.3, 0.0, 0.0);
        track[JOINT_COUNT + 5] = Vec3::new(0.0, 0.0, -0.1);
        let step = Skeleton::mean_joint_step(&track, 1);
        assert!((step - 0.4 / JOINT_COUNT as f64).abs() < 1e-7, "{step}");
    }

    fn close(a: Vec3, b: Vec3, eps: f32) -> bool {
        (a - b).abs().max_element() <= eps
    }

    #[test]
    fn parents_come_before_children_and_indices_match() {
        for (i, joint) in Joint::ALL.into_iter().enumerate() {
            assert_eq!(joint.index(), i);
            assert_eq!(Joint::from_index(i), Some(joint));
            match joint.parent() {
                Some(p) => assert!(p.index() < i, "{joint}'s parent {p} comes later"),
                None => assert_eq!(joint, Joint::Hips),
            }
        }
        assert_eq!(Joint::from_index(JOINT_COUNT), None);
    }

    #[test]
    fn names_round_trip_and_are_unique() {
        for joint in Joint::ALL {
            assert_eq!(Joint::from_name(joint.name()), Some(joint));
            assert_eq!(joint.name().parse::<Joint>().ok(), Some(joint));
            assert_eq!(joint.to_string(), joint.name());
        }
        assert_eq!(Joint::from_name("lefthand"), Some(Joint::LeftHand));
        assert_eq!(Joint::from_name("LeftEye"), None);
        assert_eq!(Joint::from_name(""), None);
        assert!(matches!(
            "Tail".parse::<Joint>(),
            Err(ModelError::UnknownJoint(_))
        ));
    }

    #[test]
    fn hierarchy_is_unitys() {
        use Joint::*;
        assert_eq!(LeftShoulder.parent(), Some(UpperChest));
        assert_eq!(RightShoulder.parent(), Some(UpperChest));
        assert_eq!(Neck.parent(), Some(UpperChest));
        assert_eq!(LeftUpperLeg.parent(), Some(Hips));
        assert_eq!(RightToes.parent(), Some(RightFoot));
    }

    #[test]
    fn mirror_swaps_sides_and_is_an_involution() {
        for joint in Joint::ALL {
            let m = joint.mirror();
            assert_eq!(m.mirror(), joint);
            let name = joint.name();
            if let Some(rest) = name.strip_prefix("Left") {
                assert_eq!(m.name(), format!("Right{rest}"));
            } else if let Some(rest) = name.strip_prefix("Right") {
                assert_eq!(m.name(), format!("Left{rest}"));
            } else {
                assert_eq!(m, joint);
            }
            assert_eq!(m.parent(), joint.parent().map(Joint::mirror));
        }
    }

    #[test]
    fn default_adult_is_a_plausible_t_pose() {
        let skeleton = Skeleton::default_adult();
        let mut p = [Vec3::ZERO; JOINT_COUNT];
        skeleton.world_positions(&skeleton.rest_pose(), &mut p);
        let at = |j: Joint| p[j.index()];
        assert!((at(Joint::Hips).y - 0.95).abs() < 1e-6);
        // Top of the head is ~0.13 m above the head joint.
        let height = at(Joint::Head).y + 0.13;
        assert!((1.65..1.75).contains(&height), "height {height}");
        for (foot, toes) in [
            (Joint::LeftFoot, Joint::LeftToes),
            (Joint::RightFoot, Joint::RightToes),
        ] {
            assert!((0.05..0.12).contains(&at(foot).y));
            assert!(at(toes).y >= 0.0 && at(toes).z > 0.05, "toes point forward");
        }
        // Arms straight out along ±X at one height; the character's left is +X.
        for (side, joints) in [
            (
                1.0,
                [Joint::LeftUpperArm, Joint::LeftLowerArm, Joint::LeftHand],
            ),
            (
                -1.0,
                [Joint::RightUpperArm, Joint::RightLowerArm, Joint::RightHand],
            ),
        ] {
            for w in joints.windows(2) {
                let d = at(w[1]) - at(w[0]);
                assert!(d.x * side > 0.2 && d.y == 0.0 && d.z == 0.0);
            }
        }
        // Legs straight down.
        let leg = at(Joint::LeftFoot) - at(Joint::LeftUpperLeg);
        assert!(leg.x == 0.0 && leg.z == 0.0 && leg.y < -0.8);
        // Left and right mirror each other.
        for joint in Joint::ALL {
            let m = to_unity_position(at(joint));
            assert!(close(m, at(joint.mirror()), 1e-6), "{joint}");
        }
    }

    #[test]
    fn bone_lengths_can_be_set() {
        let mut lengths = [0.0; JOINT_COUNT];
        for joint in Joint::ALL {
            lengths[joint.index()] = 0.1 + joint.index() as f32 * 0.01;
        }
        let skeleton = Skeleton::with_bone_lengths(&lengths).unwrap();
        for joint in Joint::ALL.into_iter().skip(1) {
            assert!((skeleton.bone_length(joint) - lengths[joint.index()]).abs() < 1e-6);
            let default_dir = DEFAULT_ADULT_OFFSETS[joint.index()].normalize();
            assert!(close(
                skeleton.offsets[joint.index()].normalize(),
                default_dir,
                1e-6
            ));
        }
        assert_eq!(skeleton.bone_length(Joint::Hips), 0.0);
        assert!((skeleton.hip_height() - 0.1).abs() < 1e-6);

        let mut s = Skeleton::default_adult();
        s.set_bone_length(Joint::LeftLowerArm, 0.0).unwrap();
        s.set_bone_length(Joint::LeftLowerArm, 0.3).unwrap();
        assert!(close(
            s.offsets[Joint::LeftLowerArm.index()],
            Vec3::new(0.3, 0.0, 0.0),
            1e-6
        ));
        for bad in [-0.1, f32::NAN, f32::INFINITY] {
            assert!(s.set_bone_length(Joint::Head, bad).is_err());
            lengths[3] = bad;
            assert!(Skeleton::with_bone_lengths(&lengths).is_err());
            assert!(s.scaled(bad).is_err());
        }
        let half = Skeleton::default_adult().scaled(0.5).unwrap();
        assert!((half.hip_height() - 0.475).abs() < 1e-6);
    }

    #[test]
    fn forward_kinematics_turns_children() {
        let skeleton = Skeleton::default_adult();
        let mut pose = skeleton.rest_pose();
        // Bend the left elbow 90° forward: rotating +X (the forearm) about −Y by 90° gives +Z.
        pose.set_rotation(Joint::LeftLowerArm, Quat::from_rotation_y(-FRAC_PI_2));
        let mut p = [Vec3::ZERO; JOINT_COUNT];
        let mut r = [Quat::IDENTITY; JOINT_COUNT];
        skeleton.forward_kinematics(&pose, &mut p, &mut r);
        let forearm = p[Joint::LeftHand.index()] - p[Joint::LeftLowerArm.index()];
        assert!(close(forearm, Vec3::new(0.0, 0.0, 0.24), EPS), "{forearm}");

        // Turning the hips 90° left (+Y) makes the character face +X.
        pose.set_rotation(Joint::Hips, Quat::from_rotation_y(FRAC_PI_2));
        skeleton.forward_kinematics(&pose, &mut p, &mut r);
        let toes = p[Joint::LeftToes.index()] - p[Joint::LeftFoot.index()];
        assert!(close(toes, Vec3::new(0.12, -0.06, 0.0), EPS), "{toes}");
        let hand_r = r[Joint::LeftHand.index()];
        let expected = Quat::from_rotation_y(FRAC_PI_2) * Quat::from_rotation_y(-FRAC_PI_2);
        assert!(hand_r.dot(expected).abs() > 1.0 - 1e-6);

        let mut only_p = [Vec3::ZERO; JOINT_COUNT];
        let mut only_r = [Quat::IDENTITY; JOINT_COUNT];
        skeleton.world_positions(&pose, &mut only_p);
        skeleton.world_rotations(&pose, &mut only_r);
        assert_eq!(only_p, p);
        assert_eq!(only_r, r);
    }

    /// Rotation about each axis, checked against the reflection `M R M` it must equal.
    #[test]
    fn unity_mapping_reflects_rotations() {
        let m = |v: Vec3| to_unity_position(v);
        let probes = [Vec3::X, Vec3::Y, Vec3::Z, Vec3::new(0.3, -1.2, 0.7)];
        for axis in [
            Vec3::X,
            Vec3::Y,
            Vec3::Z,
            Vec3::new(1.0, 2.0, -0.5).normalize(),
        ] {
            for angle in [FRAC_PI_2, -0.3, 2.5] {
                let q = Quat::from_axis_angle(axis, angle);
                let u = to_unity_rotation(q);
                for v in probes {
                    assert!(close(m(q * v), u * m(v), EPS), "axis {axis} angle {angle}");
                }
                assert_eq!(to_unity_rotation(u), q);
            }
        }
        // Nodding forward is +X in both; turning left is +Y here and −Y in Unity; rolling
        // towards the character's right is +Z here and −Z in Unity.
        let s = FRAC_PI_2 / 2.0;
        let x90 = to_unity_rotation(Quat::from_rotation_x(FRAC_PI_2));
        let y90 = to_unity_rotation(Quat::from_rotation_y(FRAC_PI_2));
        let z90 = to_unity_rotation(Quat::from_rotation_z(FRAC_PI_2));
        assert!(x90.abs_diff_eq(Quat::from_xyzw(s.sin(), 0.0, 0.0, s.cos()), 1e-6));
        assert!(y90.abs_diff_eq(Quat::from_xyzw(0.0, -s.sin(), 0.0, s.cos()), 1e-6));
        assert!(z90.abs_diff_eq(Quat::from_xyzw(0.0, 0.0, -s.sin(), s.cos()), 1e-6));
        // The "(−x, y, z, −w)" form is the same rotation.
        let q = Quat::from_xyzw(0.1, 0.2, 0.3, 0.9).normalize();
        let alt = Quat::from_xyzw(-q.x, q.y, q.z, -q.w);
        assert!(to_unity_rotation(q).dot(alt).abs() > 1.0 - 1e-6);
        // Our left hand (+X) is at Unity's −X: the character's left there as well.
        assert!(m(Vec3::X).x < 0.0);
    }

    fn unit_quat() -> impl Strategy<Value = Quat> {
        prop::array::uniform4(-1.0f32..1.0)
            .prop_filter("non-degenerate", |a| {
                a.iter().map(|x| x * x).sum::<f32>() > 1e-3
            })
            .prop_map(|a| Quat::from_array(a).normalize())
    }

    proptest! {
        #[test]
        fn forward_kinematics_keeps_bone_lengths(
            rotations in prop::array::uniform22(unit_quat()),
            root in prop::array::uniform3(-5.0f32..5.0),
        ) {
            let skeleton = Skeleton::default_adult();
            let pose = Pose { root_position: Vec3::from_array(root), local_rotations: rotations };
            let mut p = [Vec3::ZERO; JOINT_COUNT];
            skeleton.world_positions(&pose, &mut p);
            prop_assert!(close(p[0], pose.root_position, 0.0));
            for joint in Joint::ALL.into_iter().skip(1) {
                let parent = joint.parent().unwrap();
                let d = (p[joint.index()] - p[parent.index()]).length();
                prop_assert!((d - skeleton.bone_length(joint)).abs() < EPS);
            }
        }

        #[test]
        fn unity_mapping_commutes_with_composition(a in unit_quat(), b in unit_quat()) {
            let lhs = to_unity_rotation(a * b);
            let rhs = to_unity_rotation(a) * to_unity_rotation(b);
            prop_assert!(lhs.dot(rhs).abs() > 1.0 - 1e-5);
        }
    }
}
