//! Retargeting a BVH onto our rig by joint names and world rotations relative to each rig's rest.
//!
//! # Method
//!
//! Let `C` map the file's world axes to ours ([`RetargetOptions::axes`]) and `S_j(t) = C G_j(t) C⁻¹`
//! be source joint `j`'s world rotation in frame `t`, in our axes. For every mapped joint `J`
//! (driven by source joint `j`) a constant *rest alignment* `A_J` is the world rotation that
//! turns the source's zero pose (all channels 0) into its T-pose at that joint, and
//!
//! ```text
//! our world rotation   W_J(t) = S_j(t) · A_J⁻¹
//! our local rotation   L_J(t) = W_parent(J)(t)⁻¹ · W_J(t)     (identity for unmapped joints)
//! ```
//!
//! so a source in its T-pose (`S_j = A_J`) gives our T-pose (every `W_J` = identity), and any
//! world-space turn of a source bone (an arm raised 90°) turns ours by the same world rotation.
//!
//! `A_J` comes from the rest geometry: it takes the direction from `j` to its nearest mapped
//! descendant in the zero pose onto our direction from `J` to the matching joint in our T-pose
//! (the shortest arc), then turns about that bone:
//!
//! - joints with several mapped branches (hips: spine and both legs; chest: neck and both
//!   shoulders) turn so the other branches best match ours, so the hips and chest face the way
//!   the geometry says;
//! - joints with no mapped descendant (head, hands, toes) start from their parent's alignment
//!   (the zero pose has them in line with the parent bone) and turn about their bone only;
//! - how far single-bone and end joints turn about their bone (twist) depends on the zero pose.
//!   If it is a T-pose (every mapped bone within 60° of ours: our export, Mixamo, CMU, A-poses),
//!   its joint frames are the rest frames and there is no extra twist. Otherwise the file bakes
//!   its rest orientations into the channels (Bandai Namco: every bone along its joint's local
//!   X, the hips' X up), the zero-pose frames say nothing about twist, and each joint's twist
//!   is the one that makes our local rotation least twisted on average over the clip (the
//!   circular mean), rounded to a quarter turn where the rest frame and our bone are
//!   axis-aligned (within 5°), as in rigs built with axis-aligned joint frames. On the Bandai
//!   Namco files this puts knees and elbows on clean hinge axes (our X and Y).
//!
//! Bone directions are thus always right (joint positions follow the source's pose exactly, up
//! to bone lengths); only twist about single bones rests on the assumptions above.
//!
//! # Units and root
//!
//! The unit is guessed from the source's T-pose leg length (hips to ankles) as metres,
//! centimetres or millimetres, whichever is nearest ours ([`Retargeted::metres_per_unit`]).
//! The source hips' world position, in our axes, is scaled by our leg length over the source's
//! ([`Retargeted::root_scale`], metres per file unit), so a source standing straight has our
//! hips at our standing height and steps are as long relative to the legs: feet neither float
//! nor slide (Unity's humanoid animation scales root motion by its hip-height "human scale"
//! the same way).
//!
//! # Axes
//!
//! Bandai Namco Research's data is Y up, right-handed, in centimetres, with the character's left
//! at +X when it faces +Z, like ours (its walks go forward along +Z with the toes pointing +Z
//! and the left hand at +X), so [`RetargetOptions::default`]'s identity `axes` fits it;
//! its zero pose is not a T-pose (every bone lies along its joint's local X), which the rest
//! alignment handles. For a Z-up file use [`RetargetOptions::z_up`].

use glam::{Mat3, Quat, Vec3};

use super::Bvh;
use crate::ModelError;
use crate::rig::{JOINT_COUNT, Joint, Pose, Skeleton};
use crate::rotation::{normalize_or_identity, rotation_between, twist_angle};

/// How to put a BVH on our rig.
#[derive(Clone, Debug, PartialEq)]
pub struct RetargetOptions {
    /// Maps the file's world coordinates to ours (+Y up, character's left +X when facing +Z);
    /// must be orthogonal (a reflection is allowed, for left-handed files).
    pub axes: Mat3,
    /// Extra source joint names and the joints they drive, tried before the built-in table
    /// (ASCII case-insensitive, namespace prefixes such as `mixamorig:` ignored).
    pub names: Vec<(String, Joint)>,
    /// Metres per file unit; `None` guesses it from the leg length.
    pub metres_per_unit: Option<f32>,
    /// Scale the root's translation by our leg length over the source's (true), or only convert
    /// it to metres and shift it up or down by the difference in leg length (false).
    pub scale_root_to_legs: bool,
}

impl Default for RetargetOptions {
    fn default() -> Self {
        RetargetOptions {
            axes: Mat3::IDENTITY,
            names: Vec::new(),
            metres_per_unit: None,
            scale_root_to_legs: true,
        }
    }
}

impl RetargetOptions {
    /// Options for a right-handed Z-up file whose character faces −Y (Blender's convention).
    pub fn z_up() -> Self {
        // (x, y, z) → (x, z, −y): up becomes +Y and Blender's forward (−Y) becomes +Z.
        RetargetOptions {
            axes: Mat3::from_cols(Vec3::X, -Vec3::Z, Vec3::Y),
            ..Self::default()
        }
    }
}

/// A BVH put on our rig.
#[derive(Clone, Debug, PartialEq)]
pub struct Retargeted {
    /// One pose per BVH frame.
    pub poses: Vec<Pose>,
    /// Frames per second (the BVH's).
    pub fps: f64,
    /// For each of our joints (index order), the source joint driving it; `None` means its
    /// local rotation is the identity.
    pub source_joints: [Option<usize>; JOINT_COUNT],
    /// The guessed (or given) metres per file unit.
    pub metres_per_unit: f32,
    /// Metres of our root translation per file unit of the source hips' position.
    pub root_scale: f32,
    /// Whether bone twists were estimated from the motion (the file's zero pose is not a
    /// T-pose) rather than taken from the zero pose.
    pub twists_from_motion: bool,
}

/// Built-in names (lower case, namespace removed): Bandai Namco Research and Mixamo.
const NAME_TABLE: &[(&str, Joint)] = &[
    // Bandai Namco Research motion datasets.
    ("shoulder_l", Joint::LeftShoulder),
    ("upperarm_l", Joint::LeftUpperArm),
    ("lowerarm_l", Joint::LeftLowerArm),
    ("hand_l", Joint::LeftHand),
    ("upperleg_l", Joint::LeftUpperLeg),
    ("lowerleg_l", Joint::LeftLowerLeg),
    ("foot_l", Joint::LeftFoot),
    ("toes_l", Joint::LeftToes),
    ("shoulder_r", Joint::RightShoulder),
    ("upperarm_r", Joint::RightUpperArm),
    ("lowerarm_r", Joint::RightLowerArm),
    ("hand_r", Joint::RightHand),
    ("upperleg_r", Joint::RightUpperLeg),
    ("lowerleg_r", Joint::RightLowerLeg),
    ("foot_r", Joint::RightFoot),
    ("toes_r", Joint::RightToes),
    // Mixamo (after removing "mixamorig:").
    ("spine1", Joint::Chest),
    ("spine2", Joint::UpperChest),
    ("leftarm", Joint::LeftUpperArm),
    ("leftforearm", Joint::LeftLowerArm),
    ("leftupleg", Joint::LeftUpperLeg),
    ("leftleg", Joint::LeftLowerLeg),
    ("lefttoebase", Joint::LeftToes),
    ("rightarm", Joint::RightUpperArm),
    ("rightforearm", Joint::RightLowerArm),
    ("rightupleg", Joint::RightUpperLeg),
    ("rightleg", Joint::RightLowerLeg),
    ("righttoebase", Joint::RightToes),
];

/// `name` without a namespace prefix (`mixamorig:Hips` → `Hips`) and surrounding space.
fn strip_namespace(name: &str) -> &str {
    let name = name.trim();
    name.rsplit_once(':').map_or(name, |(_, n)| n)
}

/// The joint of our rig a source joint name drives, from our own (`HumanBodyBones`) names and
/// the Bandai Namco and Mixamo names (ASCII case-insensitive); `None` if unknown.
pub fn joint_for_name(name: &str) -> Option<Joint> {
    let name = strip_namespace(name);
    Joint::from_name(name).or_else(|| {
        NAME_TABLE
            .iter()
            .find(|(n, _)| n.eq_ignore_ascii_case(name))
            .map(|&(_, j)| j)
    })
}

/// Whether `ancestor` is `joint` or above it in our hierarchy.
fn is_ancestor_or_self(ancestor: Joint, mut joint: Joint) -> bool {
    loop {
        if joint == ancestor {
            return true;
        }
        match joint.parent() {
            Some(p) => joint = p,
            None => return false,
        }
    }
}

/// Applies the axis map to a rotation: `C R C⁻¹` (a proper rotation even for a reflection `C`).
fn convert_rotation(axes: &Mat3, identity_axes: bool, q: Quat) -> Quat {
    if identity_axes {
        return q;
    }
    normalize_or_identity(Quat::from_mat3(
        &(*axes * Mat3::from_quat(q) * axes.transpose()),
    ))
}

/// Puts `bvh`'s motion on `skeleton`: one [`Pose`] per frame at the file's frame rate.
///
/// Errors if the file fails [`Bvh::validate`], no joint drives `Hips`, `options.axes` is not
/// orthogonal, or the mapped joints' hierarchy contradicts ours (a mapped joint whose nearest
/// mapped ancestor drives a joint that is not above its own in our rig).
pub fn retarget(
    bvh: &Bvh,
    skeleton: &Skeleton,
    options: &RetargetOptions,
) -> Result<Retargeted, ModelError> {
    bvh.validate()?;
    let axes = options.axes;
    let orthogonal = (axes * axes.transpose()).abs_diff_eq(Mat3::IDENTITY, 1e-4)
        && (axes.determinant().abs() - 1.0).abs() < 1e-4;
    if !orthogonal {
        return Err(ModelError::BvhInvalid(format!(
            "axes {axes} are not an orthogonal map"
        )));
    }
    let identity_axes = axes == Mat3::IDENTITY;
    let n = bvh.joints.len();

    // Which of our joints each source joint drives; the first source joint for a name wins.
    let mut driven: Vec<Option<Joint>> = vec![None; n];
    let mut source_joints: [Option<usize>; JOINT_COUNT] = [None; JOINT_COUNT];
    for (i, joint) in bvh.joints.iter().enumerate() {
        let name = strip_namespace(&joint.name);
        let ours = options
            .names
            .iter()
            .find(|(n, _)| strip_namespace(n).eq_ignore_ascii_case(name))
            .map(|&(_, j)| j)
            .or_else(|| joint_for_name(name));
        if let Some(j) = ours
            && source_joints[j.index()].is_none()
        {
            source_joints[j.index()] = Some(i);
            driven[i] = Some(j);
        }
    }
    if source_joints[Joint::Hips.index()].is_none() {
        let names: Vec<&str> = bvh.joints.iter().map(|j| j.name.as_str()).collect();
        return Err(ModelError::BvhInvalid(format!(
            "no joint drives Hips (joints: {})",
            names.join(", ")
        )));
    }

    // Nearest mapped ancestor of each source joint (not itself).
    let mut mapped_ancestor: Vec<Option<usize>> = vec![None; n];
    for i in 0..n {
        if let Some(p) = bvh.joints[i].parent {
            mapped_ancestor[i] = if driven[p].is_some() {
                Some(p)
            } else {
                mapped_ancestor[p]
            };
        }
    }
    for i in 0..n {
        let Some(ours) = driven[i] else { continue };
        match mapped_ancestor[i].and_then(|a| driven[a]) {
            Some(above) if ours != above && is_ancestor_or_self(above, ours) => {}
            None if ours == Joint::Hips => {}
            other => {
                return Err(ModelError::BvhInvalid(format!(
                    "joint {:?} drives {ours} but its nearest mapped ancestor drives {}",
                    bvh.joints[i].name,
                    other.map_or("nothing".to_owned(), |j| j.to_string()),
                )));
            }
        }
    }

    // Rest geometry: the source's zero pose in our axes, our T-pose.
    let zero: Vec<Vec3> = bvh.rest_positions().iter().map(|&p| axes * p).collect();
    let mut ours_rest = [Vec3::ZERO; JOINT_COUNT];
    skeleton.world_positions(&skeleton.rest_pose(), &mut ours_rest);

    let (alignment, twists_from_motion) =
        rest_alignment(bvh, &axes, &driven, &mapped_ancestor, &zero, &ours_rest);

    // Source T-pose positions (our axes, file units): each joint turned by the alignment of
    // itself or its nearest mapped ancestor.
    let mut t_pose = vec![Vec3::ZERO; n];
    for i in 0..n {
        let joint = &bvh.joints[i];
        t_pose[i] = match joint.parent {
            Some(p) => {
                let turn = match driven[p] {
                    Some(_) => alignment[p],
                    None => mapped_ancestor[p].map_or(Quat::IDENTITY, |a| alignment[a]),
                };
                t_pose[p] + turn * (axes * joint.offset)
            }
            None => axes * joint.offset,
        };
    }
    let (source_size, our_size) = body_size(&source_joints, &t_pose, &ours_rest);
    let metres_per_unit = options.metres_per_unit.unwrap_or_else(|| {
        [1.0f32, 0.01, 0.001]
            .into_iter()
            .min_by(|&a, &b| {
                let da = (source_size * a / our_size).ln().abs();
                let db = (source_size * b / our_size).ln().abs();
                da.total_cmp(&db)
            })
            .unwrap_or(1.0)
    });
    let (root_scale, root_shift) = if options.scale_root_to_legs {
        (our_size / source_size, 0.0)
    } else {
        (metres_per_unit, our_size - source_size * metres_per_unit)
    };
    if !(root_scale.is_finite() && root_scale > 0.0 && root_shift.is_finite()) {
        return Err(ModelError::BvhInvalid(format!(
            "cannot scale the root: source size {source_size}, ours {our_size}"
        )));
    }

    let hips_source = source_joints[Joint::Hips.index()].expect("checked above");
    let inverse_alignment: Vec<Quat> = alignment.iter().map(|a| a.conjugate()).collect();
    let mut rotations = Vec::with_capacity(n);
    let mut positions = Vec::with_capacity(n);
    let mut poses = Vec::with_capacity(bvh.frames.len());
    for frame in 0..bvh.frames.len() {
        bvh.world_transforms(frame, &mut rotations, &mut positions);
        let mut world = [Quat::IDENTITY; JOINT_COUNT];
        let mut pose = Pose::rest();
        for joint in Joint::ALL {
            let i = joint.index();
            world[i] = match source_joints[i] {
                Some(s) => {
                    let source = convert_rotation(&axes, identity_axes, rotations[s]);
                    // f64: two products per joint, and errors would add up down the chains.
                    (source.as_dquat() * inverse_alignment[s].as_dquat())
                        .normalize()
                        .as_quat()
                }
                None => joint.parent().map_or(Quat::IDENTITY, |p| world[p.index()]),
            };
            let local = match joint.parent() {
                Some(p) => (world[p.index()].as_dquat().conjugate() * world[i].as_dquat())
                    .normalize()
                    .as_quat(),
                None => world[i],
            };
            pose.local_rotations[i] = normalize_or_identity(local);
        }
        let hips = axes * positions[hips_source];
        pose.root_position = hips * root_scale + Vec3::new(0.0, root_shift, 0.0);
        if !pose.is_finite() {
            return Err(ModelError::BvhInvalid(format!(
                "frame {frame} gives a non-finite pose (values too large?)"
            )));
        }
        poses.push(pose);
    }

    Ok(Retargeted {
        poses,
        fps: bvh.fps(),
        source_joints,
        metres_per_unit,
        root_scale,
        twists_from_motion,
    })
}

/// Hips-to-ankle drop of the source's T-pose (file units) and ours (metres), or, without
/// mapped legs, the height span of the mapped joints.
fn body_size(
    source_joints: &[Option<usize>; JOINT_COUNT],
    t_pose: &[Vec3],
    ours_rest: &[Vec3; JOINT_COUNT],
) -> (f32, f32) {
    let hips = Joint::Hips.index();
    let hips_source = source_joints[hips].expect("hips are mapped");
    for pair in [
        [Joint::LeftFoot, Joint::RightFoot],
        [Joint::LeftLowerLeg, Joint::RightLowerLeg],
    ] {
        let mut source = 0.0;
        let mut ours = 0.0;
        let mut count = 0;
        for joint in pair {
            if let Some(s) = source_joints[joint.index()] {
                source += t_pose[hips_source].y - t_pose[s].y;
                ours += ours_rest[hips].y - ours_rest[joint.index()].y;
                count += 1;
            }
        }
        if count > 0 && source > 0.0 && ours > 0.0 {
            return (source / count as f32, ours / count as f32);
        }
    }
    let (mut lo_s, mut hi_s, mut lo_o, mut hi_o) = (f32::MAX, f32::MIN, f32::MAX, f32::MIN);
    for joint in Joint::ALL {
        if let Some(s) = source_joints[joint.index()] {
            lo_s = lo_s.min(t_pose[s].y);
            hi_s = hi_s.max(t_pose[s].y);
            lo_o = lo_o.min(ours_rest[joint.index()].y);
            hi_o = hi_o.max(ours_rest[joint.index()].y);
        }
    }
    if hi_s - lo_s > 0.0 && hi_o - lo_o > 0.0 {
        (hi_s - lo_s, hi_o - lo_o)
    } else {
        // Only the hips: nothing to measure; no scaling.
        (1.0, 1.0)
    }
}

/// Largest angle between a source bone in the zero pose and ours in the T-pose for the zero pose
/// to count as a T-pose (an A-pose's arms are 45° off).
const T_POSE_TOLERANCE_RAD: f32 = std::f32::consts::FRAC_PI_3;
/// Most frames sampled to estimate twists from the motion.
const TWIST_SAMPLE_FRAMES: usize = 1000;
/// How far from axis-aligned a rest frame or bone may be and still count as axis-aligned.
const QUARTER_TURN_TOLERANCE_RAD: f32 = 5.0 * std::f32::consts::PI / 180.0;

/// The rest alignment of every mapped source joint (identity for unmapped ones) and whether
/// twists came from the motion; see the module documentation.
fn rest_alignment(
    bvh: &Bvh,
    axes: &Mat3,
    driven: &[Option<Joint>],
    mapped_ancestor: &[Option<usize>],
    zero: &[Vec3],
    ours_rest: &[Vec3; JOINT_COUNT],
) -> (Vec<Quat>, bool) {
    let n = bvh.joints.len();
    // Nearest mapped descendants of each joint, in file order.
    let mut branches: Vec<Vec<usize>> = vec![Vec::new(); n];
    for i in 0..n {
        if driven[i].is_some()
            && let Some(a) = mapped_ancestor[i]
        {
            branches[a].push(i);
        }
    }

    #[derive(Clone, Copy, PartialEq)]
    enum Kind {
        Unmapped,
        /// Twist fixed by several branches.
        Fixed,
        /// One bone direction (our bone's, unit); the twist is to be chosen.
        Bone(Vec3),
        /// No mapped descendant.
        Leaf,
    }
    let mut kind = vec![Kind::Unmapped; n];
    let mut alignment = vec![Quat::IDENTITY; n];
    let mut zero_is_t_pose = true;
    for i in 0..n {
        let Some(ours) = driven[i] else { continue };
        // (source direction, our direction, our joint index) per usable branch.
        let mut pairs: Vec<(Vec3, Vec3, usize)> = branches[i]
            .iter()
            .filter_map(|&k| {
                let theirs = driven[k].expect("branches are mapped");
                let e = (zero[k] - zero[i]).try_normalize()?;
                let f = (ours_rest[theirs.index()] - ours_rest[ours.index()]).try_normalize()?;
                Some((e, f, theirs.index()))
            })
            .collect();
        // Our first child in index order is the main chain (spine over legs, neck over arms).
        pairs.sort_by_key(|p| p.2);
        let Some(&(e, f, _)) = pairs.first() else {
            kind[i] = Kind::Leaf;
            continue;
        };
        if e.dot(f) < T_POSE_TOLERANCE_RAD.cos() {
            zero_is_t_pose = false;
        }
        let base = rotation_between(e, f);
        let (mut s, mut c) = (0.0f32, 0.0f32);
        for &(e2, f2, _) in &pairs[1..] {
            let a = base * e2;
            let a = a - f * f.dot(a);
            let b = f2 - f * f.dot(f2);
            s += f.dot(a.cross(b));
            c += a.dot(b);
        }
        if s * s + c * c > 1e-6 {
            alignment[i] = (Quat::from_axis_angle(f, s.atan2(c)) * base).normalize();
            kind[i] = Kind::Fixed;
        } else {
            alignment[i] = base;
            kind[i] = Kind::Bone(f);
        }
    }

    // A file whose zero pose is not a T-pose bakes its rest orientations into the channels,
    // and its zero-pose joint frames say nothing about twist; the motion does.
    let from_motion = !zero_is_t_pose && !bvh.frames.is_empty();
    let samples: Vec<Vec<Quat>> = if from_motion {
        let identity_axes = *axes == Mat3::IDENTITY;
        let count = bvh.frames.len().min(TWIST_SAMPLE_FRAMES);
        let (mut rotations, mut positions) = (Vec::new(), Vec::new());
        (0..count)
            .map(|k| {
                bvh.world_transforms(k * bvh.frames.len() / count, &mut rotations, &mut positions);
                rotations
                    .iter()
                    .map(|&q| convert_rotation(axes, identity_axes, q))
                    .collect()
            })
            .collect()
    } else {
        Vec::new()
    };

    // Parents first, so that a parent's alignment is final when its child's twist is chosen.
    for i in 0..n {
        let parent = mapped_ancestor[i];
        let (base, axis) = match kind[i] {
            Kind::Bone(axis) => (alignment[i], axis),
            Kind::Leaf => {
                let ours = driven[i].expect("leaves are mapped");
                let axis = ours_rest_offset_direction(ours, ours_rest);
                (parent.map_or(Quat::IDENTITY, |a| alignment[a]), axis)
            }
            Kind::Fixed | Kind::Unmapped => continue,
        };
        let twist = match parent {
            Some(p) if from_motion => {
                let mean = mean_twist(&samples, p, i, alignment[p], base, axis);
                let axis_aligned = axis.abs().max_element() >= QUARTER_TURN_TOLERANCE_RAD.cos();
                if is_quarter_turn(base) && axis_aligned {
                    // Rigs built with axis-aligned joint frames (Bandai Namco's) differ from
                    // the twist-free frame by quarter turns; rounding keeps a clip that holds
                    // a twist (a toe-out stance) from tilting the hinge axes.
                    let quarter = std::f32::consts::FRAC_PI_2;
                    (mean / quarter).round() * quarter
                } else {
                    mean
                }
            }
            _ => 0.0,
        };
        alignment[i] = normalize_or_identity(Quat::from_axis_angle(axis, twist) * base);
    }
    (alignment, from_motion)
}

/// The twist about `axis` (our bone, in the joint's rest frame) to add to `base`, the alignment
/// of source joint `j`, that makes our local rotation of `j` (below `p`, aligned by
/// `parent_alignment`) least twisted on average over `samples` (world rotations per frame).
fn mean_twist(
    samples: &[Vec<Quat>],
    p: usize,
    j: usize,
    parent_alignment: Quat,
    base: Quat,
    axis: Vec3,
) -> f32 {
    let (mut s, mut c) = (0.0f64, 0.0f64);
    let parent_alignment = parent_alignment.as_dquat();
    let base_inverse = base.as_dquat().conjugate();
    for world in samples {
        let parent_world = world[p].as_dquat() * parent_alignment.conjugate();
        let local = (parent_world.conjugate() * world[j].as_dquat() * base_inverse).as_quat();
        // With the extra twist θ, the local rotation is local · R(axis, −θ): its twist is
        // this one minus θ, so the best θ is the circular mean of these.
        let t = f64::from(twist_angle(local, axis));
        s += t.sin();
        c += t.cos();
    }
    if s * s + c * c < 1e-12 {
        0.0
    } else {
        s.atan2(c) as f32
    }
}

/// Whether `q` takes each axis to within [`QUARTER_TURN_TOLERANCE_RAD`] of an axis.
fn is_quarter_turn(q: Quat) -> bool {
    let cos = QUARTER_TURN_TOLERANCE_RAD.cos();
    [Vec3::X, Vec3::Y, Vec3::Z]
        .into_iter()
        .all(|a| (q * a).abs().max_element() >= cos)
}

/// Direction of `joint`'s rest offset from its parent in our T-pose (unit; +Y if zero).
fn ours_rest_offset_direction(joint: Joint, ours_rest: &[Vec3; JOINT_COUNT]) -> Vec3 {
    joint
        .parent()
        .and_then(|p| (ours_rest[joint.index()] - ours_rest[p.index()]).try_normalize())
        .unwrap_or(Vec3::Y)
}
