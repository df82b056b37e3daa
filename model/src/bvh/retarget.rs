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
//! # Axes and floor
//!
//! Unless given ([`RetargetOptions::axes`]), the file's up axis and handedness are found from the
//! motion ([`super::detect_axes`]): Bandai Namco's Y-up files, Blender's Z-up ones and AMASS's
//! (a Y-up skeleton stood up in a Z-up world by its root's rotation) all come out standing and
//! facing +Z. The zero pose is turned upright before it is compared with our T-pose, so a T-pose
//! skeleton lying in its file is still read as a T-pose. With [`RetargetOptions::floor`] the
//! motion is then moved up or down so its feet are on the floor ([`Retargeted::floor_shift_m`]).
//!
//! # Names
//!
//! Which source joint drives which of ours: the user's map, the tables of the common naming
//! conventions, the names' parts and the hierarchy, in that order (see `names.rs`).

use glam::{Mat3, Quat, Vec3};

use super::Bvh;
use super::axes::{ABOVE_HIPS, detect_axes, upright};
use super::names::{NameMatch, match_joints};
use crate::ModelError;
use crate::rig::{JOINT_COUNT, Joint, Pose, Skeleton};
use crate::rotation::{normalize_or_identity, rotation_between, twist_angle};

/// How to put a BVH on our rig.
#[derive(Clone, Debug, PartialEq)]
pub struct RetargetOptions {
    /// Maps the file's world coordinates to ours (+Y up, character's left +X when facing +Z);
    /// must be orthogonal (a reflection is allowed, for left-handed files). `None` finds it
    /// from the motion ([`super::detect_axes`]).
    pub axes: Option<Mat3>,
    /// What the user said of the axes when `axes` is `None`; the rest is found.
    pub hints: super::AxisHints,
    /// Extra source joint names and the joints they drive, tried before the built-in tables
    /// (ASCII case-insensitive, namespace prefixes such as `mixamorig:` ignored).
    pub names: Vec<(String, Joint)>,
    /// Metres per file unit; `None` guesses it from the leg length.
    pub metres_per_unit: Option<f32>,
    /// Scale the root's translation by our leg length over the source's (true), or only convert
    /// it to metres and shift it up or down by the difference in leg length (false).
    pub scale_root_to_legs: bool,
    /// Shift the motion up or down so its lowest point, in the frames where it is lowest (the
    /// tenth percentile of each frame's lowest joint), is as high above the floor as our rest
    /// pose's lowest joint: feet on the floor whatever height the file's origin is at.
    pub floor: bool,
}

impl Default for RetargetOptions {
    fn default() -> Self {
        RetargetOptions {
            axes: None,
            hints: super::AxisHints::default(),
            names: Vec::new(),
            metres_per_unit: None,
            scale_root_to_legs: true,
            floor: true,
        }
    }
}

impl RetargetOptions {
    /// Options for a right-handed Z-up file whose character faces −Y (Blender's convention).
    pub fn z_up() -> Self {
        // (x, y, z) → (x, z, −y): up becomes +Y and Blender's forward (−Y) becomes +Z.
        RetargetOptions {
            axes: Some(Mat3::from_cols(Vec3::X, -Vec3::Z, Vec3::Y)),
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
    /// The map from file axes to ours that was used.
    pub axes: Mat3,
    /// Whether `axes` was found from the motion (not given).
    pub axes_detected: bool,
    /// The naming convention that matched most joint names.
    pub convention: &'static str,
    /// Names of the source joints that drive none of ours (end bones, fingers, helpers).
    pub unmapped: Vec<String>,
    /// Metres the floor fit moved the motion up (negative: down); 0 without it.
    pub floor_shift_m: f32,
    /// Mean angle, degrees, between each of our limb and spine bones (a mapped joint to the
    /// next mapped joint down its chain) and the source's bone between the same joints, over
    /// the frames.
    pub bone_error_deg: f32,
    /// The same for the girdles' fixed offsets (hips to hip joints, chest to clavicles): how
    /// differently the two rigs are shaped there, constant over the motion.
    pub girdle_error_deg: f32,
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
    retarget_matched(bvh, skeleton, options, match_joints(bvh, &options.names))
}

/// [`retarget`] of a validated `bvh` whose joints `names` has read.
fn retarget_matched(
    bvh: &Bvh,
    skeleton: &Skeleton,
    options: &RetargetOptions,
    names: NameMatch,
) -> Result<Retargeted, ModelError> {
    let n = bvh.joints.len();
    // Which of our joints each source joint drives.
    let driven = names.driven;
    let mut source_joints: [Option<usize>; JOINT_COUNT] = [None; JOINT_COUNT];
    for (i, d) in driven.iter().enumerate() {
        if let Some(j) = d {
            source_joints[j.index()] = Some(i);
        }
    }
    if source_joints[Joint::Hips.index()].is_none() {
        let names: Vec<&str> = bvh.joints.iter().map(|j| j.name.as_str()).collect();
        return Err(ModelError::BvhInvalid(format!(
            "no joint drives Hips (joints: {})",
            names.join(", ")
        )));
    }

    let (axes, axes_detected) = match options.axes {
        Some(axes) => (axes, false),
        None => match detect_axes(bvh, &source_joints, &options.hints) {
            Some(found) => (found.axes, true),
            None => (Mat3::IDENTITY, false),
        },
    };
    let orthogonal = (axes * axes.transpose()).abs_diff_eq(Mat3::IDENTITY, 1e-4)
        && (axes.determinant().abs() - 1.0).abs() < 1e-4;
    if !orthogonal {
        return Err(ModelError::BvhInvalid(format!(
            "axes {axes} are not an orthogonal map"
        )));
    }
    let identity_axes = axes == Mat3::IDENTITY;

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

    // Rest geometry: the source's zero pose in our axes, turned upright, and our T-pose.
    let zero: Vec<Vec3> = bvh.rest_positions().iter().map(|&p| axes * p).collect();
    let turn_upright = upright(&zero, &source_joints);
    let zero: Vec<Vec3> = zero.iter().map(|&p| turn_upright * p).collect();
    let mut ours_rest = [Vec3::ZERO; JOINT_COUNT];
    skeleton.world_positions(&skeleton.rest_pose(), &mut ours_rest);

    let (alignment, twists_from_motion) = rest_alignment(
        bvh,
        &axes,
        turn_upright,
        &driven,
        &mapped_ancestor,
        &zero,
        &ours_rest,
    );

    // Source T-pose positions (our axes, file units): each joint turned by the alignment of
    // itself or its nearest mapped ancestor.
    let mut t_pose = vec![Vec3::ZERO; n];
    for i in 0..n {
        let joint = &bvh.joints[i];
        t_pose[i] = match joint.parent {
            Some(p) => {
                let turn = match driven[p] {
                    Some(_) => alignment[p],
                    None => mapped_ancestor[p].map_or(turn_upright, |a| alignment[a]),
                };
                t_pose[p] + turn * (axes * joint.offset)
            }
            None => turn_upright * (axes * joint.offset),
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

    let floor_shift_m = if options.floor {
        fit_floor(skeleton, &mut poses, &ours_rest)
    } else {
        0.0
    };
    let (bone_error_deg, girdle_error_deg) =
        bone_error_deg(bvh, skeleton, &axes, &source_joints, &poses);
    let unmapped = bvh
        .joints
        .iter()
        .zip(&driven)
        .filter(|(_, d)| d.is_none())
        .map(|(j, _)| j.name.clone())
        .collect();

    Ok(Retargeted {
        poses,
        fps: bvh.fps(),
        source_joints,
        metres_per_unit,
        root_scale,
        twists_from_motion,
        axes,
        axes_detected,
        convention: names.convention,
        unmapped,
        floor_shift_m,
        bone_error_deg,
        girdle_error_deg,
    })
}

/// Most frames read for the floor fit and the bone-direction error.
const CHECK_FRAMES: usize = 600;

/// Frames `0..n` thinned to at most [`CHECK_FRAMES`], evenly.
fn checked_frames(n: usize) -> impl Iterator<Item = usize> {
    let count = n.min(CHECK_FRAMES);
    (0..count).map(move |k| k * n / count)
}

/// Moves `poses` up or down so the tenth percentile of each frame's lowest joint is at the
/// height of our rest pose's lowest joint; returns the shift, metres.
fn fit_floor(skeleton: &Skeleton, poses: &mut [Pose], ours_rest: &[Vec3; JOINT_COUNT]) -> f32 {
    if poses.is_empty() {
        return 0.0;
    }
    let rest_low = ours_rest.iter().map(|p| p.y).fold(f32::MAX, f32::min);
    let mut world = [Vec3::ZERO; JOINT_COUNT];
    let mut lows: Vec<f32> = checked_frames(poses.len())
        .map(|f| {
            skeleton.world_positions(&poses[f], &mut world);
            world.iter().map(|p| p.y).fold(f32::MAX, f32::min)
        })
        .collect();
    lows.sort_by(f32::total_cmp);
    let shift = rest_low - lows[lows.len() / 10];
    if !shift.is_finite() {
        return 0.0;
    }
    for pose in poses.iter_mut() {
        pose.root_position.y += shift;
    }
    shift
}

/// Mean angles, degrees, between our bones and the source's between the same joints: the
/// limbs' and spine's, and the girdles'; see [`Retargeted::bone_error_deg`] and
/// [`Retargeted::girdle_error_deg`].
fn bone_error_deg(
    bvh: &Bvh,
    skeleton: &Skeleton,
    axes: &Mat3,
    source_joints: &[Option<usize>; JOINT_COUNT],
    poses: &[Pose],
) -> (f32, f32) {
    // Each mapped joint and its nearest mapped ancestor in our hierarchy.
    let bones: Vec<(usize, usize)> = Joint::ALL
        .into_iter()
        .filter(|j| source_joints[j.index()].is_some())
        .filter_map(|j| {
            let mut p = j.parent()?;
            loop {
                if source_joints[p.index()].is_some() {
                    return Some((p.index(), j.index()));
                }
                p = p.parent()?;
            }
        })
        .collect();
    let (mut rotations, mut positions) = (Vec::new(), Vec::new());
    let mut ours = [Vec3::ZERO; JOINT_COUNT];
    // A bone from a joint with several mapped branches to one that is not its main chain (the
    // hips to a hip joint, the chest to a clavicle) is a fixed offset within one rigid segment:
    // its angle is the two rigs' shape, the same in every frame.
    let girdle = |a: usize, b: usize| {
        let main = bones
            .iter()
            .filter(|&&(p, _)| p == a)
            .map(|&(_, c)| c)
            .min();
        bones.iter().filter(|&&(p, _)| p == a).count() > 1 && main != Some(b)
    };
    let (mut sum, mut count) = ([0.0f64; 2], [0usize; 2]);
    for f in checked_frames(poses.len().min(bvh.frames.len())) {
        bvh.world_transforms(f, &mut rotations, &mut positions);
        skeleton.world_positions(&poses[f], &mut ours);
        for &(a, b) in &bones {
            let (Some(sa), Some(sb)) = (source_joints[a], source_joints[b]) else {
                continue;
            };
            let theirs = (*axes * (positions[sb] - positions[sa])).try_normalize();
            let mine = (ours[b] - ours[a]).try_normalize();
            if let (Some(t), Some(m)) = (theirs, mine) {
                let e = f64::from(t.dot(m).clamp(-1.0, 1.0).acos().to_degrees());
                let k = usize::from(girdle(a, b));
                sum[k] += e;
                count[k] += 1;
            }
        }
    }
    let mean = |k: usize| {
        if count[k] == 0 {
            0.0
        } else {
            (sum[k] / count[k] as f64) as f32
        }
    };
    (mean(0), mean(1))
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
    turn_upright: Quat,
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
    let upright_inverse = turn_upright.conjugate();
    let samples: Vec<Vec<Quat>> = if from_motion {
        let identity_axes = *axes == Mat3::IDENTITY;
        let count = bvh.frames.len().min(TWIST_SAMPLE_FRAMES);
        let (mut rotations, mut positions) = (Vec::new(), Vec::new());
        (0..count)
            .map(|k| {
                bvh.world_transforms(k * bvh.frames.len() / count, &mut rotations, &mut positions);
                // The world rotations of a source whose zero pose is the upright one.
                rotations
                    .iter()
                    .map(|&q| convert_rotation(axes, identity_axes, q) * upright_inverse)
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
    // Found for the upright zero pose; the file's own zero pose is turned upright first.
    for (i, a) in alignment.iter_mut().enumerate() {
        if driven[i].is_some() {
            *a = normalize_or_identity(*a * turn_upright);
        }
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

/// Our joints every imported dance must drive: without them there is no body to dance.
pub const REQUIRED_JOINTS: [Joint; 9] = [
    Joint::Hips,
    Joint::LeftUpperLeg,
    Joint::LeftLowerLeg,
    Joint::RightUpperLeg,
    Joint::RightLowerLeg,
    Joint::LeftUpperArm,
    Joint::LeftLowerArm,
    Joint::RightUpperArm,
    Joint::RightLowerArm,
];

/// A dance file put on our rig, as every command that reads one does: [`retarget`], then a
/// [`ModelError::BvhUnmapped`] naming the body parts nothing drives (of [`REQUIRED_JOINTS`], and
/// a head, neck or chest) and how to map them.
pub fn import(
    bvh: &Bvh,
    skeleton: &Skeleton,
    options: &RetargetOptions,
) -> Result<Retargeted, ModelError> {
    bvh.validate()?;
    let names = match_joints(bvh, &options.names);
    let driven = |j: Joint| names.driven.contains(&Some(j));
    let mut missing: Vec<Joint> = REQUIRED_JOINTS
        .into_iter()
        .filter(|&j| !driven(j))
        .collect();
    if !ABOVE_HIPS.into_iter().any(driven) {
        missing.push(Joint::Head);
    }
    if !missing.is_empty() {
        let unused: Vec<&str> = bvh
            .joints
            .iter()
            .zip(&names.driven)
            .filter(|(_, d)| d.is_none())
            .map(|(j, _)| j.name.as_str())
            .collect();
        let example = missing
            .iter()
            .enumerate()
            .map(|(k, j)| {
                let source = unused.get(k).copied().unwrap_or("their name");
                format!("\"{source}\" = \"{j}\"")
            })
            .collect::<Vec<_>>()
            .join("\n");
        return Err(ModelError::BvhUnmapped {
            missing: missing
                .iter()
                .map(|j| j.to_string())
                .collect::<Vec<_>>()
                .join(", "),
            unused: if unused.is_empty() {
                "none".to_owned()
            } else {
                unused.join(", ")
            },
            example,
        });
    }
    retarget_matched(bvh, skeleton, options, names)
}
