//! Fits the rig to tang2018's 23 noisy points per frame: bone lengths, per-frame local
//! rotations, a small zero-phase smoothing, and the fit error.
//!
//! # Which point is what
//!
//! Read off the upstream drawing code and checked against bone-length statistics over all 43
//! dances (median length and IQR/median of each candidate pair):
//!
//! | data | meaning | rig joint |
//! | --- | --- | --- |
//! | 0, 1 | head pair, 11 cm apart side by side (ears or temples) | `Head` = their midpoint; its X axis along 1 → 0 |
//! | 2 | lower spine, 12–17 cm above the hip midpoint | `Spine` |
//! | 3, 12 | shoulder joints, 26–32 cm apart | `LeftUpperArm`, `RightUpperArm`; `Neck` = midpoint |
//! | 4, 13 | elbows (27–33 cm from the shoulder) | `LeftLowerArm`, `RightLowerArm` |
//! | 5, 14 | a point 10–15 cm down the forearm, not a joint | unused |
//! | 6, 15 | wrists (22–30 cm from the elbow; shoulder–elbow–wrist 50–58 cm, an arm) | `LeftHand`, `RightHand` |
//! | 22, 21 | extra hand points: 22 by the wrist, 3–4 cm off the forearm axis; 21 by point 14, 1–2 cm off it (cha-cha, rumba) or 7 cm (waltz) | forearm roll |
//! | 7, 16 | hip joints, 20–22 cm apart | `LeftUpperLeg`, `RightUpperLeg`; `Hips` = midpoint |
//! | 8, 17 | knees | `LeftLowerLeg`, `RightLowerLeg` |
//! | 9, 18 | ankles (31–38 cm from the knee, the most rigid pair in the legs) | `LeftFoot`, `RightFoot` |
//! | 10, 19 | heels: behind the ankle, 11–14 cm off the ankle–toe line | foot roll |
//! | 11, 20 | toes: ahead of the ankle, 14–19 cm from it (upstream draws the foot to them) | `LeftToes`, `RightToes` |
//!
//! `Chest` and `UpperChest` split the line from 2 to the shoulder midpoint in thirds, and
//! `Neck`, `LeftShoulder` and `RightShoulder` all start at the shoulder midpoint (the clavicles
//! are the half shoulder lines), so the torso has no invented geometry. Mapped joints with no
//! point of their own (`Neck`, `Head`, `Hips`) take midpoints of observed pairs.
//!
//! # Left and right (the data is mirrored)
//!
//! *Facing* is unambiguous. With `f = (p16 − p7) × up`, in every one of the 43 dances the toes
//! 11 and 20 are ahead of their ankles along `f` (medians +9 to +13 cm), the heels 10 and 19
//! behind (−3 to −10 cm), the knees ahead of the hip–ankle midpoints (+1 to +14 cm) and the
//! elbows behind or level with the shoulder–wrist midpoints (0 to −12 cm): the dancer faces `f`.
//!
//! *Sides* then depend on the data's handedness, which geometry alone cannot tell (a mirror
//! image is an equally valid body). Read as right-handed like our rig, `p16 − p7` would point
//! to the dancer's left. The ballroom hold says otherwise. In all 31 waltzes and the tango the
//! head pair 0 → 1 is turned 21–38° (median ≈ 30°) about +Y relative to the shoulder line
//! 3 → 12, *towards the 3/7 side*; the head sits 6–10 cm behind the shoulders; the 12-side hand
//! is the extended one (39–44 cm beyond its shoulder along the shoulder line, 6–17 cm above
//! it) and the 3-side hand rests ~30 cm in front. In closed hold both partners turn the head
//! to their own *left*, and the follower's head goes back while her *right* hand is the
//! extended one. Every cue agrees if 3/7 is the left; with 12/16 as the left the dancer would
//! look right, against the convention of both partners (the cha-chas and rumbas also turn the
//! head the same way, by 4–7°). So the data is left-handed (upstream built its 3D demo in
//! Unity, which is): we mirror it, `x → −x`, before fitting. Then 0, 3–6, 7–11 and 22 are the
//! left side, and the fitted dancer faces the mirrored `f`, which is the rig's +Z of its
//! `Hips` (a dancer seen facing +Z has an identity `Hips` yaw).
//!
//! # The fit
//!
//! - Bone lengths: per-bone medians over every usable frame of the dance, left and right
//!   pooled (one median of both sides' samples). The rig drives a symmetric avatar, and the
//!   data's left/right differences (~2 cm, e.g. the thighs of the waltzes) are marker
//!   placement more than anatomy. Per-side medians would fit the points a little closer
//!   (median error over the data set 1.56 cm instead of 1.73 cm) with rotations made for a
//!   lopsided body that the avatar does not have.
//!   Bone directions are the rig's T-pose ones (spine straight up, limbs along ±X and −Y, the
//!   toes the default adult's, within 2–6° of the data's flat-footed ankle–toe pitch).
//! - `Hips`: X along the hip line (left minus right hip), Y towards point 2.
//! - Spine: the thorax frame (Y from `Spine` towards the shoulder midpoint, X along the shoulder
//!   line) relative to the hips, as swing × twist about Y; `Spine` takes the swing and a third
//!   of the twist, `Chest` and `UpperChest` a third each, so the shoulder-line twist is spread
//!   over the spine and every spine joint stays on the observed line.
//! - Clavicles and neck: shortest arc onto the observed direction. `Head`: X along the head
//!   pair, Y as close to the neck direction as that allows (no nodding information exists).
//! - Arms and legs, from the fitted shoulder/hip joint: in the plane of the observed three
//!   points, the upper bone's angle between aiming at the elbow/knee and exact IK onto the
//!   wrist/ankle that minimises `|middle error|² + 2 |end error|²`, the lower bone aimed at the
//!   wrist/ankle. (Over the data set exact IK gives 1.9 cm mean error with the knees off by
//!   5 cm, pure aiming 1.7 cm with the ankles off by 3 cm, this 1.7 cm with both in between.)
//!   The upper bone is twisted so the lower joint bends about its anatomical hinge (elbow:
//!   −Y/+Y left/right in the palms-down T-pose; knee: +X). Below ~10–25° of bend the bend
//!   plane is noise, so it blends towards a fallback: the toes' direction for the knee (knees
//!   point over the toes), the untwisted swing for the elbow. Forearm roll: the extra hand
//!   point's side of the forearm axis is taken to be the back of the hand (+Y in the
//!   palms-down T-pose), an assumption: nothing in the data fixes where on the hand it sits. A
//!   point too close to the axis to tell (21 in the cha-cha and rumba recordings) gives no
//!   roll. Feet: ankle → toe direction and the heel's side of that line. Hands and toes keep
//!   identity rotations.
//! - Smoothing: a Gaussian, σ = 1 frame (40 ms), over each joint's quaternions made
//!   sign-continuous, and over the root; zero-phase (the fit is offline). It costs ~0.1 cm of
//!   error against the raw points.
//! - Frames with non-finite or collapsed points hold the previous pose (the next good one at
//!   the start) and are counted; they do not enter the error.
//!
//! Over the 43 dances the mean error is 0.9–2.9 cm per dance (median 1.7 cm), largest at the
//! knees and elbows, and it follows [`TangFit::bone_length_spread`] (0.016–0.14): fixed
//! lengths cannot follow points whose distances change from frame to frame.

use glam::{Mat3, Quat, Vec3, Vec4};

use crate::ModelError;
use crate::rig::{JOINT_COUNT, Joint, Pose, Skeleton};
use crate::rotation::{normalize_or_identity, rotation_between, swing_twist, twist_angle};
use crate::tang2018::{TANG_FPS, TANG_POINTS, TangDance};

/// Fewest frames [`fit_dance`] accepts.
pub const MIN_FRAMES: usize = 5;

/// Joints compared to an observed point in the fit error (`Hips` is left out: the root is
/// placed on the hip midpoint, so its error is zero by construction).
pub const MAPPED_JOINTS: [Joint; 17] = [
    Joint::Spine,
    Joint::Neck,
    Joint::Head,
    Joint::LeftUpperArm,
    Joint::LeftLowerArm,
    Joint::LeftHand,
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

// Data point indices, named for the side they are on after mirroring (see the module docs).
const EAR_L: usize = 0;
const EAR_R: usize = 1;
const SPINE: usize = 2;
const SHOULDER_L: usize = 3;
const ELBOW_L: usize = 4;
const WRIST_L: usize = 6;
const HIP_L: usize = 7;
const KNEE_L: usize = 8;
const ANKLE_L: usize = 9;
const HEEL_L: usize = 10;
const TOE_L: usize = 11;
const SHOULDER_R: usize = 12;
const ELBOW_R: usize = 13;
const WRIST_R: usize = 15;
const HIP_R: usize = 16;
const KNEE_R: usize = 17;
const ANKLE_R: usize = 18;
const HEEL_R: usize = 19;
const TOE_R: usize = 20;
const HAND_MARK_R: usize = 21;
const HAND_MARK_L: usize = 22;

/// Gaussian smoothing width, frames; 1 frame at 25 fps keeps motion below ~4 Hz intact.
const SMOOTH_SIGMA: f32 = 1.0;
const SMOOTH_RADIUS: usize = 3;

/// How much more an arm's or leg's end (wrist, ankle) counts than its middle joint when the
/// fixed bone lengths cannot reach both: hands and feet are what the eye follows, and the
/// feet's contact with the floor.
const END_WEIGHT: f32 = 2.0;

/// Heel direction from the ankle in the foot's rest frame; only its side of the ankle–toe
/// line matters (down and back, in the sagittal plane).
const HEEL_REST: Vec3 = Vec3::new(0.0, -0.7, -0.5);

/// A dance fitted to the rig.
#[derive(Clone, Debug)]
pub struct TangFit {
    /// The dancer's skeleton: the rig's T-pose directions with the dance's median bone lengths.
    pub skeleton: Skeleton,
    /// One pose per data frame, in our coordinates (metres, +Y up, the mirrored data).
    pub poses: Vec<Pose>,
    /// Frames per second of `poses`.
    pub fps: f64,
    /// Mean over usable frames and [`MAPPED_JOINTS`] of the distance between the fitted joint
    /// and its observed point, cm.
    pub mean_error_cm: f64,
    /// The same mean per joint, cm; 0 for joints not in [`MAPPED_JOINTS`].
    pub per_joint_error_cm: [f64; JOINT_COUNT],
    /// How far the data is from rigid: for each measured bone (hip and shoulder widths, lower
    /// spine, torso, neck, and each side's upper arm, forearm, thigh, shin, foot) the IQR of
    /// its per-frame length over its median, and the median of those over the bones.
    pub bone_length_spread: f64,
    /// Frames with non-finite or collapsed points, which hold a neighbouring pose.
    pub repaired_frames: usize,
}

/// Where the data puts each rig joint in one frame, in our coordinates (mirrored, metres,
/// centre added); `None` for joints without an observed point (`Chest`, `UpperChest`, the
/// clavicles). `Hips` is the hip midpoint.
pub fn target_positions(points: &[Vec3; TANG_POINTS], center: Vec3) -> [Option<Vec3>; JOINT_COUNT] {
    target_positions_rig(&to_rig_frame(points, center))
}

fn target_positions_rig(p: &[Vec3; TANG_POINTS]) -> [Option<Vec3>; JOINT_COUNT] {
    use Joint::*;
    let mut t = [None; JOINT_COUNT];
    let mut set = |j: Joint, v: Vec3| t[j.index()] = Some(v);
    set(Hips, (p[HIP_L] + p[HIP_R]) * 0.5);
    set(Spine, p[SPINE]);
    set(Neck, (p[SHOULDER_L] + p[SHOULDER_R]) * 0.5);
    set(Head, (p[EAR_L] + p[EAR_R]) * 0.5);
    set(LeftUpperArm, p[SHOULDER_L]);
    set(LeftLowerArm, p[ELBOW_L]);
    set(LeftHand, p[WRIST_L]);
    set(RightUpperArm, p[SHOULDER_R]);
    set(RightLowerArm, p[ELBOW_R]);
    set(RightHand, p[WRIST_R]);
    set(LeftUpperLeg, p[HIP_L]);
    set(LeftLowerLeg, p[KNEE_L]);
    set(LeftFoot, p[ANKLE_L]);
    set(LeftToes, p[TOE_L]);
    set(RightUpperLeg, p[HIP_R]);
    set(RightLowerLeg, p[KNEE_R]);
    set(RightFoot, p[ANKLE_R]);
    set(RightToes, p[TOE_R]);
    t
}

/// Data (cm, relative to the centre, left-handed) to our world coordinates (metres).
fn to_rig_frame(points: &[Vec3; TANG_POINTS], center: Vec3) -> [Vec3; TANG_POINTS] {
    points.map(|p| {
        let w = p + center;
        Vec3::new(-w.x, w.y, w.z) * 0.01
    })
}

/// Bone lengths in metres, the dancer's proportions.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Lengths {
    hip_width: f32,
    spine: f32,
    /// Point 2 to the shoulder midpoint; `Chest`, `UpperChest` and `Neck` get a third each.
    torso: f32,
    /// Shoulder midpoint to the head pair's midpoint.
    neck: f32,
    shoulder_width: f32,
    upper_arm: f32,
    forearm: f32,
    thigh: f32,
    shin: f32,
    foot: f32,
}

fn skeleton_from(l: &Lengths) -> Skeleton {
    use Joint::*;
    let mut o = [Vec3::ZERO; JOINT_COUNT];
    let toe_dir = Skeleton::default_adult().offsets[LeftToes.index()].normalize();
    let third = Vec3::new(0.0, l.torso / 3.0, 0.0);
    let mut set = |j: Joint, v: Vec3| o[j.index()] = v;
    // Standing with straight legs and the toes on the floor.
    set(Hips, Vec3::Y * (l.thigh + l.shin - toe_dir.y * l.foot));
    set(Spine, Vec3::Y * l.spine);
    set(Chest, third);
    set(UpperChest, third);
    set(Neck, third);
    set(Head, Vec3::Y * l.neck);
    set(LeftShoulder, third);
    set(RightShoulder, third);
    for (s, upper, lower, hand, hip, knee, ankle, toes) in [
        (
            1.0,
            LeftUpperArm,
            LeftLowerArm,
            LeftHand,
            LeftUpperLeg,
            LeftLowerLeg,
            LeftFoot,
            LeftToes,
        ),
        (
            -1.0,
            RightUpperArm,
            RightLowerArm,
            RightHand,
            RightUpperLeg,
            RightLowerLeg,
            RightFoot,
            RightToes,
        ),
    ] {
        set(upper, Vec3::X * (s * l.shoulder_width / 2.0));
        set(lower, Vec3::X * (s * l.upper_arm));
        set(hand, Vec3::X * (s * l.forearm));
        set(hip, Vec3::X * (s * l.hip_width / 2.0));
        set(knee, Vec3::NEG_Y * l.thigh);
        set(ankle, Vec3::NEG_Y * l.shin);
        set(toes, toe_dir * l.foot);
    }
    Skeleton { offsets: o }
}

/// Per-frame lengths of the measured bones, in [`Lengths`] order with both sides of each limb
/// bone: hip width, spine, torso, neck, shoulder width, then (left, right) upper arm, forearm,
/// thigh, shin, foot.
const MEASURED: usize = 15;

fn measure(p: &[Vec3; TANG_POINTS]) -> [f32; MEASURED] {
    let d = |a: Vec3, b: Vec3| (a - b).length();
    let hip_mid = (p[HIP_L] + p[HIP_R]) * 0.5;
    let shoulder_mid = (p[SHOULDER_L] + p[SHOULDER_R]) * 0.5;
    let ear_mid = (p[EAR_L] + p[EAR_R]) * 0.5;
    [
        d(p[HIP_L], p[HIP_R]),
        d(p[SPINE], hip_mid),
        d(shoulder_mid, p[SPINE]),
        d(ear_mid, shoulder_mid),
        d(p[SHOULDER_L], p[SHOULDER_R]),
        d(p[SHOULDER_L], p[ELBOW_L]),
        d(p[SHOULDER_R], p[ELBOW_R]),
        d(p[ELBOW_L], p[WRIST_L]),
        d(p[ELBOW_R], p[WRIST_R]),
        d(p[HIP_L], p[KNEE_L]),
        d(p[HIP_R], p[KNEE_R]),
        d(p[KNEE_L], p[ANKLE_L]),
        d(p[KNEE_R], p[ANKLE_R]),
        d(p[ANKLE_L], p[TOE_L]),
        d(p[ANKLE_R], p[TOE_R]),
    ]
}

/// Whether a frame can be fitted: finite and on a human scale, with a hip line and a torso to
/// orient by.
fn usable(p: &[Vec3; TANG_POINTS]) -> bool {
    // Beyond 10 km a coordinate is corrupt, and squaring it would overflow f32.
    if !p
        .iter()
        .all(|v| v.is_finite() && v.abs().max_element() < 1e4)
    {
        return false;
    }
    let m = measure(p);
    // 1 cm is far below a real hip width (20 cm) or torso (30 cm): the points have collapsed.
    m[0] > 0.01 && m[2] > 0.01
}

fn quantile(sorted: &[f32], q: f64) -> f64 {
    let pos = q * (sorted.len() - 1) as f64;
    let lo = pos.floor() as usize;
    let hi = pos.ceil() as usize;
    let t = pos - lo as f64;
    sorted[lo] as f64 * (1.0 - t) + sorted[hi] as f64 * t
}

fn sorted(mut v: Vec<f32>) -> Vec<f32> {
    v.sort_by(f32::total_cmp);
    v
}

/// Median lengths (sides pooled) and the median relative IQR over the measured bones.
fn estimate_lengths(name: &str, samples: &[[f32; MEASURED]]) -> Result<(Lengths, f64), ModelError> {
    let column = |i: usize| sorted(samples.iter().map(|s| s[i]).collect());
    let pooled = |i: usize| sorted(samples.iter().flat_map(|s| [s[i], s[i + 1]]).collect());
    let median = |v: &[f32]| quantile(v, 0.5) as f32;
    let mut spreads: Vec<f32> = (0..MEASURED)
        .map(|i| {
            let c = column(i);
            let m = quantile(&c, 0.5);
            if m > 0.0 {
                ((quantile(&c, 0.75) - quantile(&c, 0.25)) / m) as f32
            } else {
                0.0
            }
        })
        .collect();
    spreads.sort_by(f32::total_cmp);
    let l = Lengths {
        hip_width: median(&column(0)),
        spine: median(&column(1)),
        torso: median(&column(2)),
        neck: median(&column(3)),
        shoulder_width: median(&column(4)),
        upper_arm: median(&pooled(5)),
        forearm: median(&pooled(7)),
        thigh: median(&pooled(9)),
        shin: median(&pooled(11)),
        foot: median(&pooled(13)),
    };
    let all = [
        ("hip width", l.hip_width),
        ("lower spine", l.spine),
        ("torso", l.torso),
        ("neck", l.neck),
        ("shoulder width", l.shoulder_width),
        ("upper arm", l.upper_arm),
        ("forearm", l.forearm),
        ("thigh", l.thigh),
        ("shin", l.shin),
        ("foot", l.foot),
    ];
    if let Some((bone, len)) = all
        .iter()
        .find(|(_, v)| v.is_nan() || *v <= 1e-3 || v.is_infinite())
    {
        return Err(ModelError::FitDegenerate {
            name: name.to_owned(),
            reason: format!("median {bone} length is {len} m"),
        });
    }
    Ok((l, quantile(&spreads, 0.5)))
}

#[inline]
fn smoothstep(x: f32, lo: f32, hi: f32) -> f32 {
    let t = ((x - lo) / (hi - lo)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// `v` without its component along the unit vector `axis`.
#[inline]
fn perp(v: Vec3, axis: Vec3) -> Vec3 {
    v - axis * axis.dot(v)
}

/// The rotation taking `rest_a` exactly onto `obs_a` and `rest_b` as close as possible to
/// `obs_b`; where `obs_b` is (nearly) parallel to `obs_a`, the shortest arc for `a`.
fn align(rest_a: Vec3, rest_b: Vec3, obs_a: Vec3, obs_b: Vec3) -> Quat {
    let ra = rest_a.normalize();
    let rb = perp(rest_b, ra).normalize();
    let Some(oa) = obs_a.try_normalize() else {
        return Quat::IDENTITY;
    };
    let ob_perp = perp(obs_b, oa);
    // Within ~0.5° of parallel the secondary direction is rounding noise.
    let ob = if ob_perp.length_squared() > 1e-4 * obs_b.length_squared() {
        ob_perp.normalize()
    } else {
        rotation_between(ra, oa) * rb
    };
    let rest = Mat3::from_cols(ra, rb, ra.cross(rb));
    let obs = Mat3::from_cols(oa, ob, oa.cross(ob));
    normalize_or_identity(Quat::from_mat3(&(obs * rest.transpose())))
}

/// The minimum of a unimodal `f` on `[lo, hi]` by golden-section search (to ~0.01°).
fn golden_min(f: impl Fn(f32) -> f32, mut lo: f32, mut hi: f32) -> f32 {
    const R: f32 = 0.618_034;
    let mut a = hi - R * (hi - lo);
    let mut b = lo + R * (hi - lo);
    let (mut fa, mut fb) = (f(a), f(b));
    while hi - lo > 2e-4 {
        if fa <= fb {
            hi = b;
            b = a;
            fb = fa;
            a = hi - R * (hi - lo);
            fa = f(a);
        } else {
            lo = a;
            a = b;
            fa = fb;
            b = lo + R * (hi - lo);
            fb = f(b);
        }
    }
    0.5 * (lo + hi)
}

/// Angle about the unit `axis` from `from` to `to` (both roughly perpendicular to it).
#[inline]
fn signed_angle(from: Vec3, to: Vec3, axis: Vec3) -> f32 {
    from.cross(to).dot(axis).atan2(from.dot(to))
}

/// One arm or leg: its joints, rest bone direction and hinge axis.
struct Limb {
    upper: Joint,
    lower: Joint,
    end: Joint,
    /// Rest direction of both bones.
    dir: Vec3,
    /// Axis, in the upper bone's rest frame, about which the lower bone flexes.
    hinge: Vec3,
}

const LEFT_ARM: Limb = Limb {
    upper: Joint::LeftUpperArm,
    lower: Joint::LeftLowerArm,
    end: Joint::LeftHand,
    dir: Vec3::X,
    hinge: Vec3::NEG_Y,
};
const RIGHT_ARM: Limb = Limb {
    upper: Joint::RightUpperArm,
    lower: Joint::RightLowerArm,
    end: Joint::RightHand,
    dir: Vec3::NEG_X,
    hinge: Vec3::Y,
};
const LEFT_LEG: Limb = Limb {
    upper: Joint::LeftUpperLeg,
    lower: Joint::LeftLowerLeg,
    end: Joint::LeftFoot,
    dir: Vec3::NEG_Y,
    hinge: Vec3::X,
};
const RIGHT_LEG: Limb = Limb {
    upper: Joint::RightUpperLeg,
    lower: Joint::RightLowerLeg,
    end: Joint::RightFoot,
    dir: Vec3::NEG_Y,
    hinge: Vec3::X,
};

/// Forward kinematics filled in joint by joint as the solve walks down the hierarchy.
struct Chain<'a> {
    skeleton: &'a Skeleton,
    local: [Quat; JOINT_COUNT],
    world: [Quat; JOINT_COUNT],
    pos: [Vec3; JOINT_COUNT],
}

impl Chain<'_> {
    /// Places `joint` from its (already solved) parent and returns its position.
    fn place(&mut self, joint: Joint) -> Vec3 {
        let i = joint.index();
        if let Some(p) = joint.parent() {
            self.pos[i] = self.pos[p.index()] + self.world[p.index()] * self.skeleton.offsets[i];
        }
        self.pos[i]
    }

    fn parent_world(&self, joint: Joint) -> Quat {
        joint
            .parent()
            .map_or(Quat::IDENTITY, |p| self.world[p.index()])
    }

    fn set_local(&mut self, joint: Joint, local: Quat) {
        let i = joint.index();
        let local = normalize_or_identity(local);
        self.local[i] = local;
        self.world[i] = normalize_or_identity(self.parent_world(joint) * local);
    }

    fn set_world(&mut self, joint: Joint, world: Quat) {
        let local = self.parent_world(joint).conjugate() * world;
        self.set_local(joint, local);
    }

    /// Solves an arm or leg onto its observed middle and end points (see the module docs),
    /// bending towards `mid_obs`'s side of the root–end line, or, while the limb is too
    /// straight to say, towards `pole_hint` (its part perpendicular to the limb) or else the
    /// untwisted swing's hinge side.
    fn solve_limb(&mut self, limb: &Limb, mid_obs: Vec3, end_obs: Vec3, pole_hint: Option<Vec3>) {
        let parent_w = self.parent_world(limb.upper);
        let root = self.place(limb.upper);
        let l1 = self.skeleton.offsets[limb.lower.index()].length();
        let l2 = self.skeleton.offsets[limb.end.index()].length();
        let to_end = end_obs - root;
        let dir = to_end
            .try_normalize()
            .unwrap_or_else(|| parent_w * limb.dir);
        let swing_w = parent_w * rotation_between(limb.dir, parent_w.conjugate() * dir);
        let pole_swing = dir.cross(swing_w * limb.hinge).normalize_or_zero();
        let pole_fallback = pole_hint
            .and_then(|h| {
                let along = perp(h, dir);
                let w = smoothstep(along.length() / h.length().max(1e-9), 0.2, 0.5);
                (w * along.normalize_or_zero() + (1.0 - w) * pole_swing).try_normalize()
            })
            .unwrap_or(pole_swing);
        // A bend under ~10° is within the noise of these points; above ~25° it is real.
        let bend = (mid_obs - root).angle_between(end_obs - mid_obs);
        let w = if bend.is_finite() {
            smoothstep(bend, 10f32.to_radians(), 25f32.to_radians())
        } else {
            0.0
        };
        let observed = perp(mid_obs - root, dir).normalize_or_zero();
        let pole = (w * observed + (1.0 - w) * pole_fallback)
            .try_normalize()
            .unwrap_or(pole_fallback);
        let reach = to_end
            .length()
            .clamp((l1 - l2).abs() + 1e-4, (l1 + l2).max(1e-4));
        let along = (l1 * l1 - l2 * l2 + reach * reach) / (2.0 * reach);
        let out = (l1 * l1 - along * along).max(0.0).sqrt();
        // The upper bone's angle from `dir` towards `pole`: exact IK puts the end on its point
        // but, with fixed lengths on a nearly straight limb, swings the middle joint far off
        // its point; aiming at the middle point does the opposite. Take the angle between
        // the two that minimises both errors, the end's counted END_WEIGHT times.
        let ik = out.atan2(along);
        let rel = mid_obs - root;
        let aim = rel.dot(pole).atan2(rel.dot(dir));
        let pose_at = |angle: f32| {
            let mid = root + (dir * angle.cos() + pole * angle.sin()) * l1;
            let f = (end_obs - mid).try_normalize().unwrap_or(dir);
            (mid, mid + f * l2)
        };
        let cost = |angle: f32| {
            let (mid, end) = pose_at(angle);
            (mid - mid_obs).length_squared() + END_WEIGHT * (end - end_obs).length_squared()
        };
        let angle = if aim.is_finite() {
            golden_min(cost, ik.min(aim), ik.max(aim))
        } else {
            ik
        };
        let (mid, end) = pose_at(angle);
        let hinge_axis = pole.cross(dir);
        let upper_w = align(limb.dir, limb.hinge, mid - root, hinge_axis);
        self.set_world(limb.upper, upper_w);
        self.place(limb.lower);
        let lower = rotation_between(limb.dir, upper_w.conjugate() * (end - mid));
        self.set_local(limb.lower, lower);
        self.place(limb.end);
    }

    /// Rolls the forearm about its axis so its back (+Y at rest) faces the extra hand point.
    fn roll_forearm(&mut self, limb: &Limb, elbow_obs: Vec3, wrist_obs: Vec3, mark: Vec3) {
        let i = limb.lower.index();
        let axis = (self.world[i] * limb.dir).normalize();
        let obs_axis = (wrist_obs - elbow_obs).try_normalize().unwrap_or(axis);
        let off = perp(mark - wrist_obs, obs_axis);
        // Closer than ~1 cm to the axis the point's side is noise; from 2.5 cm on it is clear.
        let w = smoothstep(off.length(), 0.01, 0.025);
        let back = self.world[i] * Vec3::Y;
        let target = w * perp(off, axis).normalize_or_zero() + (1.0 - w) * back;
        if target.length_squared() < 1e-12 {
            return;
        }
        let angle = signed_angle(back, target, axis);
        let local = self.local[i] * Quat::from_axis_angle(limb.dir, angle);
        self.set_local(limb.lower, local);
    }
}

/// The pose that puts the rig on one frame's points (our coordinates, metres).
fn solve_frame(skeleton: &Skeleton, p: &[Vec3; TANG_POINTS]) -> Pose {
    use Joint::*;
    let mut c = Chain {
        skeleton,
        local: [Quat::IDENTITY; JOINT_COUNT],
        world: [Quat::IDENTITY; JOINT_COUNT],
        pos: [Vec3::ZERO; JOINT_COUNT],
    };
    let root = (p[HIP_L] + p[HIP_R]) * 0.5;
    c.pos[Hips.index()] = root;
    let hips = align(Vec3::X, Vec3::Y, p[HIP_L] - p[HIP_R], p[SPINE] - root);
    c.set_local(Hips, hips);

    let spine = c.place(Spine);
    let shoulder_mid = (p[SHOULDER_L] + p[SHOULDER_R]) * 0.5;
    let thorax = align(
        Vec3::Y,
        Vec3::X,
        shoulder_mid - spine,
        p[SHOULDER_L] - p[SHOULDER_R],
    );
    let rel = hips.conjugate() * thorax;
    let (swing, _) = swing_twist(rel, Vec3::Y);
    let third = Quat::from_rotation_y(twist_angle(rel, Vec3::Y) / 3.0);
    c.set_local(Spine, swing * third);
    c.place(Chest);
    c.set_local(Chest, third);
    c.place(UpperChest);
    c.set_local(UpperChest, third);
    let chest_w = c.world[UpperChest.index()];

    let ear_mid = (p[EAR_L] + p[EAR_R]) * 0.5;
    let neck = c.place(Neck);
    c.set_local(
        Neck,
        rotation_between(Vec3::Y, chest_w.conjugate() * (ear_mid - neck)),
    );
    c.place(Head);
    c.set_world(
        Head,
        align(Vec3::X, Vec3::Y, p[EAR_L] - p[EAR_R], ear_mid - neck),
    );

    for (clavicle, dir, shoulder) in [
        (LeftShoulder, Vec3::X, p[SHOULDER_L]),
        (RightShoulder, Vec3::NEG_X, p[SHOULDER_R]),
    ] {
        let at = c.place(clavicle);
        c.set_local(
            clavicle,
            rotation_between(dir, chest_w.conjugate() * (shoulder - at)),
        );
    }
    for (limb, elbow, wrist, mark) in [
        (&LEFT_ARM, p[ELBOW_L], p[WRIST_L], p[HAND_MARK_L]),
        (&RIGHT_ARM, p[ELBOW_R], p[WRIST_R], p[HAND_MARK_R]),
    ] {
        c.solve_limb(limb, elbow, wrist, None);
        c.roll_forearm(limb, elbow, wrist, mark);
    }
    for (limb, knee, ankle, heel, toe, toes) in [
        (
            &LEFT_LEG, p[KNEE_L], p[ANKLE_L], p[HEEL_L], p[TOE_L], LeftToes,
        ),
        (
            &RIGHT_LEG, p[KNEE_R], p[ANKLE_R], p[HEEL_R], p[TOE_R], RightToes,
        ),
    ] {
        c.solve_limb(limb, knee, ankle, Some(toe - heel));
        let foot = limb.end;
        let at = c.pos[foot.index()];
        let toe_rest = skeleton.offsets[toes.index()];
        c.set_world(foot, align(toe_rest, HEEL_REST, toe - at, heel - at));
    }
    Pose {
        root_position: root,
        local_rotations: c.local,
    }
}

/// Zero-phase Gaussian smoothing of every joint's rotation (sign-continuous) and the root.
///
/// The ends are padded by odd reflection (`2·x₀ − x_k`, and `q₀ q_k⁻¹ q₀` for rotations), so
/// a dance that starts or ends mid-movement keeps its first and last frames instead of being
/// pulled towards the inside, as a truncated kernel would.
fn smooth(poses: &mut [Pose]) {
    let n = poses.len();
    let r = SMOOTH_RADIUS.min(n.saturating_sub(1));
    let weights: Vec<f32> = (0..=r)
        .map(|k| (-0.5 * (k as f32 / SMOOTH_SIGMA).powi(2)).exp())
        .collect();
    let total: f32 = weights[0] + 2.0 * weights[1..].iter().sum::<f32>();
    // `padded[t + r]` is frame t.
    fn filter<T: Copy + std::ops::Mul<f32, Output = T> + std::iter::Sum<T>>(
        padded: &[T],
        weights: &[f32],
        t: usize,
    ) -> T {
        let r = weights.len() - 1;
        (0..=2 * r)
            .map(|k| padded[t + k] * weights[k.abs_diff(r)])
            .sum()
    }
    for j in 0..JOINT_COUNT {
        let mut q: Vec<Quat> = poses.iter().map(|p| p.local_rotations[j]).collect();
        for t in 1..n {
            if q[t].dot(q[t - 1]) < 0.0 {
                q[t] = -q[t];
            }
        }
        let reflect = |end: Quat, inner: Quat| {
            let m = end * inner.conjugate() * end;
            if m.dot(end) < 0.0 { -m } else { m }
        };
        let padded: Vec<Vec4> = (1..=r)
            .rev()
            .map(|k| reflect(q[0], q[k]))
            .chain(q.iter().copied())
            .chain((1..=r).map(|k| reflect(q[n - 1], q[n - 1 - k])))
            .map(Vec4::from)
            .collect();
        for (t, pose) in poses.iter_mut().enumerate() {
            let sum = filter(&padded, &weights, t);
            pose.local_rotations[j] = normalize_or_identity(Quat::from_vec4(sum));
        }
    }
    let x: Vec<Vec3> = poses.iter().map(|p| p.root_position).collect();
    let padded: Vec<Vec3> = (1..=r)
        .rev()
        .map(|k| 2.0 * x[0] - x[k])
        .chain(x.iter().copied())
        .chain((1..=r).map(|k| 2.0 * x[n - 1] - x[n - 1 - k]))
        .collect();
    for (t, pose) in poses.iter_mut().enumerate() {
        pose.root_position = filter(&padded, &weights, t) / total;
    }
}

/// Fits the rig to a tang2018 dance; see the module docs for the mapping and the method.
pub fn fit_dance(dance: &TangDance) -> Result<TangFit, ModelError> {
    let name = &dance.name;
    let frames = dance.points.len();
    if dance.center.len() != frames {
        return Err(ModelError::FitLengthMismatch {
            name: name.clone(),
            points: frames,
            centers: dance.center.len(),
        });
    }
    if frames < MIN_FRAMES {
        return Err(ModelError::FitTooFewFrames {
            name: name.clone(),
            frames,
            min: MIN_FRAMES,
        });
    }
    let world: Vec<[Vec3; TANG_POINTS]> = dance
        .points
        .iter()
        .zip(&dance.center)
        .map(|(p, c)| to_rig_frame(p, *c))
        .collect();
    let good: Vec<bool> = world.iter().map(usable).collect();
    let samples: Vec<[f32; MEASURED]> = world
        .iter()
        .zip(&good)
        .filter(|(_, g)| **g)
        .map(|(p, _)| measure(p))
        .collect();
    if samples.len() < MIN_FRAMES {
        return Err(ModelError::FitTooFewFrames {
            name: name.clone(),
            frames: samples.len(),
            min: MIN_FRAMES,
        });
    }
    let (lengths, spread) = estimate_lengths(name, &samples)?;
    let skeleton = skeleton_from(&lengths);

    let mut poses: Vec<Option<Pose>> = world
        .iter()
        .zip(&good)
        .map(|(p, g)| {
            g.then(|| solve_frame(&skeleton, p))
                .filter(|pose| pose.is_finite())
        })
        .collect();
    let repaired_frames = poses.iter().filter(|p| p.is_none()).count();
    let first =
        poses
            .iter()
            .flatten()
            .next()
            .copied()
            .ok_or_else(|| ModelError::FitDegenerate {
                name: name.clone(),
                reason: "no frame could be fitted".into(),
            })?;
    let mut held = first;
    for pose in poses.iter_mut() {
        match pose {
            Some(p) => held = *p,
            None => *pose = Some(held),
        }
    }
    let mut poses: Vec<Pose> = poses.into_iter().flatten().collect();
    smooth(&mut poses);

    let mut sums = [0.0f64; JOINT_COUNT];
    let mut counted = 0usize;
    let mut fk = [Vec3::ZERO; JOINT_COUNT];
    for ((pose, p), g) in poses.iter().zip(&world).zip(&good) {
        if !g {
            continue;
        }
        skeleton.world_positions(pose, &mut fk);
        let targets = target_positions_rig(p);
        for j in MAPPED_JOINTS {
            if let Some(t) = targets[j.index()] {
                sums[j.index()] += 100.0 * (fk[j.index()] - t).length() as f64;
            }
        }
        counted += 1;
    }
    let per_joint_error_cm = sums.map(|s| s / counted.max(1) as f64);
    let mean_error_cm = MAPPED_JOINTS
        .iter()
        .map(|j| per_joint_error_cm[j.index()])
        .sum::<f64>()
        / MAPPED_JOINTS.len() as f64;
    Ok(TangFit {
        skeleton,
        poses,
        fps: TANG_FPS,
        mean_error_cm,
        per_joint_error_cm,
        bone_length_spread: spread,
        repaired_frames,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tang2018::load_dance;
    use std::path::PathBuf;

    fn truth_lengths() -> Lengths {
        Lengths {
            hip_width: 0.21,
            spine: 0.17,
            torso: 0.30,
            neck: 0.16,
            shoulder_width: 0.30,
            upper_arm: 0.30,
            forearm: 0.25,
            thigh: 0.46,
            shin: 0.36,
            foot: 0.18,
        }
    }

    fn angle_deg(a: Quat, b: Quat) -> f32 {
        let d = a.conjugate() * b;
        2.0 * d.w.abs().min(1.0).acos().to_degrees()
    }

    fn mirror(v: Vec3) -> Vec3 {
        Vec3::new(-v.x, v.y, v.z)
    }

    /// A pose the fit's conventions can represent exactly: spine bend in `Spine` with equal
    /// twist thirds, twist-free clavicles and neck, a yaw-and-roll head, hinge elbows and knees
    /// bent past the blending range, identity hands and toes.
    fn truth_pose(t: f32) -> Pose {
        use Joint::*;
        let s = |f: f32, ph: f32| (f * t + ph).sin();
        let mut pose = Pose::rest();
        pose.root_position = Vec3::new(
            0.4 * s(0.4, 0.0),
            0.95 + 0.04 * s(2.0, 1.0),
            0.3 * s(0.25, 2.0),
        );
        let mut set = |j: Joint, q: Quat| pose.set_rotation(j, q);
        set(
            Hips,
            Quat::from_rotation_y(1.2 * s(0.3, 0.0))
                * Quat::from_rotation_x(0.12 * s(1.1, 1.0))
                * Quat::from_rotation_z(0.08 * s(0.9, 2.0)),
        );
        let third = Quat::from_rotation_y(0.15 * s(0.8, 0.1));
        let bend = rotation_between(
            Vec3::Y,
            Vec3::new(0.25 * s(0.7, 0.3), 1.0, 0.3 * s(0.5, 1.2)),
        );
        set(Spine, bend * third);
        set(Chest, third);
        set(UpperChest, third);
        set(
            Neck,
            rotation_between(
                Vec3::Y,
                Vec3::new(0.15 * s(0.9, 0.2), 1.0, 0.2 * s(0.6, 2.1)),
            ),
        );
        set(
            Head,
            Quat::from_rotation_y(0.5 * s(0.6, 0.4)) * Quat::from_rotation_z(0.2 * s(1.2, 0.9)),
        );
        for (side, limb, clavicle) in [
            (1.0, &LEFT_ARM, LeftShoulder),
            (-1.0, &RIGHT_ARM, RightShoulder),
        ] {
            // The data has one point for the neck and the shoulder midpoint, and the shoulder
            // line sets the chest's twist, so the clavicles can only tilt the shoulder line.
            set(
                clavicle,
                rotation_between(limb.dir, side * Vec3::new(1.0, 0.15 * s(1.3, 0.0), 0.0)),
            );
            let ph = if side > 0.0 { 0.0 } else { 1.7 };
            set(
                limb.upper,
                Quat::from_rotation_z(side * (-1.0 + 0.5 * s(0.5, ph)))
                    * Quat::from_rotation_y(0.4 * s(0.8, ph))
                    * Quat::from_rotation_x(0.6 * s(0.6, ph)),
            );
            set(
                limb.lower,
                Quat::from_axis_angle(limb.hinge, 1.1 + 0.4 * s(1.7, ph))
                    * Quat::from_axis_angle(limb.dir, 0.7 * s(0.9, ph)),
            );
        }
        for (side, limb) in [(1.0, &LEFT_LEG), (-1.0, &RIGHT_LEG)] {
            let ph = if side > 0.0 { 0.5 } else { 2.5 };
            set(
                limb.upper,
                Quat::from_rotation_x(-0.3 + 0.3 * s(0.9, ph))
                    * Quat::from_rotation_z(side * 0.1 * s(0.6, ph))
                    * Quat::from_rotation_y(0.3 * s(0.4, ph)),
            );
            set(limb.lower, Quat::from_rotation_x(0.9 + 0.35 * s(1.3, ph)));
            set(
                limb.end,
                Quat::from_rotation_x(0.25 * s(1.1, ph))
                    * Quat::from_rotation_y(0.2 * s(0.7, ph))
                    * Quat::from_rotation_z(0.1 * s(0.5, ph)),
            );
        }
        pose
    }

    /// The 23 points of a pose, laid out like the data (cm, left-handed, relative to a centre).
    fn points_of(
        skeleton: &Skeleton,
        pose: &Pose,
        center_rig: Vec3,
    ) -> ([Vec3; TANG_POINTS], Vec3) {
        use Joint::*;
        let mut x = [Vec3::ZERO; JOINT_COUNT];
        let mut w = [Quat::IDENTITY; JOINT_COUNT];
        skeleton.forward_kinematics(pose, &mut x, &mut w);
        let at = |j: Joint| x[j.index()];
        let rot = |j: Joint| w[j.index()];
        let mut p = [Vec3::ZERO; TANG_POINTS];
        p[EAR_L] = at(Head) + rot(Head) * Vec3::new(0.055, 0.0, 0.0);
        p[EAR_R] = at(Head) + rot(Head) * Vec3::new(-0.055, 0.0, 0.0);
        p[SPINE] = at(Spine);
        p[SHOULDER_L] = at(LeftUpperArm);
        p[ELBOW_L] = at(LeftLowerArm);
        p[5] = (at(LeftLowerArm) + at(LeftHand)) * 0.5;
        p[WRIST_L] = at(LeftHand);
        p[HAND_MARK_L] = at(LeftHand) + rot(LeftLowerArm) * Vec3::new(0.01, 0.035, 0.0);
        p[SHOULDER_R] = at(RightUpperArm);
        p[ELBOW_R] = at(RightLowerArm);
        p[14] = (at(RightLowerArm) + at(RightHand)) * 0.5;
        p[WRIST_R] = at(RightHand);
        p[HAND_MARK_R] = at(RightLowerArm) + rot(RightLowerArm) * Vec3::new(-0.12, 0.03, 0.0);
        for (hip, knee, ankle, heel, toe, upper, lower, foot, toes) in [
            (
                HIP_L,
                KNEE_L,
                ANKLE_L,
                HEEL_L,
                TOE_L,
                LeftUpperLeg,
                LeftLowerLeg,
                LeftFoot,
                LeftToes,
            ),
            (
                HIP_R,
                KNEE_R,
                ANKLE_R,
                HEEL_R,
                TOE_R,
                RightUpperLeg,
                RightLowerLeg,
                RightFoot,
                RightToes,
            ),
        ] {
            p[hip] = at(upper);
            p[knee] = at(lower);
            p[ankle] = at(foot);
            p[heel] = at(foot) + rot(foot) * Vec3::new(0.0, -0.07, -0.05);
            p[toe] = at(toes);
        }
        let center = mirror(center_rig) * 100.0;
        (p.map(|v| mirror(v) * 100.0 - center), center)
    }

    struct Synthetic {
        dance: TangDance,
        skeleton: Skeleton,
        poses: Vec<Pose>,
    }

    /// `frames` of [`truth_pose`] at 25 fps, with uniform noise of ±`noise_cm` per coordinate.
    fn synthetic(frames: usize, noise_cm: f32) -> Synthetic {
        let skeleton = skeleton_from(&truth_lengths());
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut noise = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            ((state >> 40) as f32 / (1u64 << 24) as f32 * 2.0 - 1.0) * noise_cm
        };
        let mut points = Vec::new();
        let mut center = Vec::new();
        let mut poses = Vec::new();
        for f in 0..frames {
            let pose = truth_pose(f as f32 / TANG_FPS as f32);
            let c = pose.root_position + Vec3::new(0.02, -0.05, 0.01);
            let (mut p, c) = points_of(&skeleton, &pose, c);
            for v in &mut p {
                *v += Vec3::new(noise(), noise(), noise());
            }
            points.push(p);
            center.push(c);
            poses.push(pose);
        }
        Synthetic {
            dance: TangDance {
                name: "synthetic".into(),
                style: 'S',
                points,
                center,
                music_span: None,
                audio: None,
            },
            skeleton,
            poses,
        }
    }

    /// Per joint, the mean and the largest angle between fitted and true local rotations.
    fn rotation_errors(fit: &TangFit, truth: &[Pose]) -> [(f32, f32); JOINT_COUNT] {
        let mut out = [(0.0f32, 0.0f32); JOINT_COUNT];
        for (a, b) in fit.poses.iter().zip(truth) {
            for (j, o) in out.iter_mut().enumerate() {
                let e = angle_deg(a.local_rotations[j], b.local_rotations[j]);
                o.0 += e / truth.len() as f32;
                o.1 = o.1.max(e);
            }
        }
        out
    }

    #[test]
    fn synthetic_dance_is_recovered() {
        let s = synthetic(400, 0.0);
        let fit = fit_dance(&s.dance).unwrap();
        assert_eq!(fit.poses.len(), 400);
        assert_eq!(fit.repaired_frames, 0);
        assert_eq!(fit.fps, 25.0);
        for j in Joint::ALL {
            let (a, b) = (
                fit.skeleton.offsets[j.index()],
                s.skeleton.offsets[j.index()],
            );
            assert!(a.abs_diff_eq(b, 1e-4), "{j}: {a} vs {b}");
        }
        eprintln!(
            "synthetic: mean error {:.3} cm, spread {:.4}",
            fit.mean_error_cm, fit.bone_length_spread
        );
        assert!(fit.mean_error_cm < 0.5, "{}", fit.mean_error_cm);
        assert!(fit.bone_length_spread < 1e-3);
        let errors = rotation_errors(&fit, &s.poses);
        let worst = errors.iter().map(|e| e.1).fold(0.0, f32::max);
        eprintln!("synthetic: largest rotation error {worst:.3}°");
        for (j, (mean, max)) in errors.into_iter().enumerate() {
            let joint = Joint::ALL[j];
            assert!(
                mean < 1.0 && max < 3.0,
                "{joint}: mean {mean:.2}°, max {max:.2}°"
            );
        }
        for (a, b) in fit.poses.iter().zip(&s.poses) {
            assert!(a.root_position.abs_diff_eq(b.root_position, 2e-3));
        }
    }

    #[test]
    fn noisy_synthetic_dance_is_close() {
        let s = synthetic(400, 0.5);
        let fit = fit_dance(&s.dance).unwrap();
        eprintln!("noisy synthetic: mean error {:.3} cm", fit.mean_error_cm);
        assert!(fit.mean_error_cm < 1.0, "{}", fit.mean_error_cm);
        let errors = rotation_errors(&fit, &s.poses);
        for (j, (mean, max)) in errors.into_iter().enumerate() {
            eprintln!(
                "  {:14} mean {mean:5.2}°  max {max:5.2}°",
                Joint::ALL[j].name()
            );
        }
        for (j, (mean, _)) in errors.into_iter().enumerate() {
            assert!(mean < 6.0, "{}: mean {mean:.2}°", Joint::ALL[j]);
        }
    }

    #[test]
    fn broken_frames_are_held_and_counted() {
        let mut s = synthetic(60, 0.0);
        s.dance.points[0][3] = Vec3::NAN;
        s.dance.points[10][7] = Vec3::INFINITY;
        s.dance.center[11] = Vec3::NAN;
        // Both hips on one spot: no hip line to orient by.
        s.dance.points[30][16] = s.dance.points[30][7];
        // Finite but absurd: squaring it would overflow.
        s.dance.points[40][3] = Vec3::splat(1e30);
        let fit = fit_dance(&s.dance).unwrap();
        assert_eq!(fit.repaired_frames, 5);
        assert!(fit.poses.iter().all(Pose::is_finite));
        assert!(fit.mean_error_cm.is_finite() && fit.mean_error_cm < 0.5);
        assert!(fit.per_joint_error_cm.iter().all(|e| e.is_finite()));

        // Collapsed limbs and coincident points are fitted without NaN.
        let mut s = synthetic(20, 0.0);
        for p in &mut s.dance.points {
            p[4] = p[3];
            p[6] = p[3];
            p[22] = p[3];
            p[8] = p[7];
            p[9] = p[7];
            p[10] = p[7];
            p[11] = p[7];
            p[0] = p[1];
        }
        let fit = fit_dance(&s.dance).unwrap();
        assert!(fit.poses.iter().all(Pose::is_finite));
        assert!(fit.mean_error_cm.is_finite());
    }

    #[test]
    fn unusable_dances_are_errors() {
        let s = synthetic(MIN_FRAMES - 1, 0.0);
        assert!(matches!(
            fit_dance(&s.dance),
            Err(ModelError::FitTooFewFrames { frames: 4, .. })
        ));
        let mut s = synthetic(10, 0.0);
        s.dance.center.pop();
        let e = fit_dance(&s.dance).unwrap_err();
        assert!(matches!(e, ModelError::FitLengthMismatch { .. }));
        assert!(e.to_string().contains("synthetic"), "{e}");
        let mut s = synthetic(10, 0.0);
        for p in &mut s.dance.points[2..] {
            p[0] = Vec3::NAN;
        }
        assert!(matches!(
            fit_dance(&s.dance),
            Err(ModelError::FitTooFewFrames { frames: 2, .. })
        ));
        let mut s = synthetic(10, 0.0);
        for p in &mut s.dance.points {
            p[12] = p[13];
            p[3] = p[4];
        }
        let e = fit_dance(&s.dance).unwrap_err();
        assert!(matches!(e, ModelError::FitDegenerate { .. }), "{e}");
        assert!(e.to_string().contains("upper arm"), "{e}");
    }

    #[test]
    fn targets_follow_the_mapping() {
        let mut points = [Vec3::ZERO; TANG_POINTS];
        for (i, p) in points.iter_mut().enumerate() {
            *p = Vec3::new(i as f32, 2.0 * i as f32, -(i as f32));
        }
        let t = target_positions(&points, Vec3::new(100.0, 0.0, 0.0));
        let rig = |i: usize| Vec3::new(-(i as f32 + 100.0), 2.0 * i as f32, -(i as f32)) * 0.01;
        assert_eq!(t[Joint::LeftHand.index()], Some(rig(6)));
        assert_eq!(t[Joint::RightToes.index()], Some(rig(20)));
        assert_eq!(t[Joint::Chest.index()], None);
        assert!(
            t[Joint::Head.index()]
                .unwrap()
                .abs_diff_eq((rig(0) + rig(1)) * 0.5, 1e-6)
        );
        for j in MAPPED_JOINTS {
            assert!(t[j.index()].is_some(), "{j}");
        }
    }

    /// The shared tang2018 data set, or `None` when absent (the test skips, see `testkit`).
    #[track_caller]
    fn data_root() -> Option<PathBuf> {
        testkit::require_shared("tang2018").map(|data| data.join("tang2018"))
    }

    /// Median over frames of `f`, for convention checks on fitted dances.
    fn median_over(
        fit: &TangFit,
        f: impl Fn(&[Vec3; JOINT_COUNT], &[Quat; JOINT_COUNT]) -> f32,
    ) -> f32 {
        let mut x = [Vec3::ZERO; JOINT_COUNT];
        let mut w = [Quat::IDENTITY; JOINT_COUNT];
        let v = fit
            .poses
            .iter()
            .map(|p| {
                fit.skeleton.forward_kinematics(p, &mut x, &mut w);
                f(&x, &w)
            })
            .collect();
        quantile(&sorted(v), 0.5) as f32
    }

    /// Bounds from the measurement over all 43 dances (`fit_all`): per-dance mean errors are
    /// 0.9–2.9 cm (median 1.7) and grow with the data's own non-rigidity (C_2, R_5, W_10: 1.8,
    /// 1.8, 0.9 cm at length spreads 0.05, 0.06, 0.02). In C_2 alone the hip–knee distance's
    /// IQR is 2 cm, so ~2 cm is the floor for fixed bone lengths; 2.5 cm leaves room for noise
    /// in the method, not for a mismapped point (a swapped or wrong point costs ≥ 10 cm on its
    /// joint, hence the 6 cm bound per joint; the largest measured is a knee, 4.5 cm).
    #[test]
    fn real_dances_fit_within_bounds() {
        use Joint::*;
        let Some(root) = data_root() else { return };
        for name in ["DANCE_C_2", "DANCE_R_5", "DANCE_W_10"] {
            let dance = load_dance(&root.join(name)).unwrap();
            let fit = fit_dance(&dance).unwrap();
            let worst = MAPPED_JOINTS
                .into_iter()
                .max_by(|a, b| {
                    fit.per_joint_error_cm[a.index()].total_cmp(&fit.per_joint_error_cm[b.index()])
                })
                .unwrap();
            eprintln!(
                "{name}: mean error {:.2} cm (worst joint {worst} {:.2} cm), bone length spread \
                 {:.3}, {} repaired",
                fit.mean_error_cm,
                fit.per_joint_error_cm[worst.index()],
                fit.bone_length_spread,
                fit.repaired_frames
            );
            assert!(fit.mean_error_cm < 2.5, "{name}: {}", fit.mean_error_cm);
            assert!(
                fit.per_joint_error_cm[worst.index()] < 6.0,
                "{name}: {worst}"
            );
            assert!(fit.poses.iter().all(Pose::is_finite));
            assert_eq!(fit.poses.len(), dance.frames());

            // Facing: toes ahead of the ankles, in the hips' +Z.
            let toes_ahead = median_over(&fit, |x, w| {
                let fwd = w[Hips.index()] * Vec3::Z;
                (x[LeftToes.index()] - x[LeftFoot.index()]).dot(fwd)
                    + (x[RightToes.index()] - x[RightFoot.index()]).dot(fwd)
            });
            assert!(toes_ahead > 0.1, "{name}: toes {toes_ahead}");
            // Knees bend forwards: the knee is ahead of the hip–ankle line.
            let knees_ahead = median_over(&fit, |x, w| {
                let fwd = w[Hips.index()] * Vec3::Z;
                let knee = |h: Joint, k: Joint, a: Joint| {
                    (x[k.index()] - (x[h.index()] + x[a.index()]) * 0.5).dot(fwd)
                };
                knee(LeftUpperLeg, LeftLowerLeg, LeftFoot)
                    + knee(RightUpperLeg, RightLowerLeg, RightFoot)
            });
            assert!(knees_ahead > 0.0, "{name}: knees {knees_ahead}");
            if name.contains("_W_") {
                // Closed hold: the head turns to the dancer's left (+Y) from the chest.
                let yaw = median_over(&fit, |_, w| {
                    twist_angle(w[UpperChest.index()].conjugate() * w[Head.index()], Vec3::Y)
                });
                assert!(
                    yaw.to_degrees() > 10.0,
                    "{name}: head yaw {}°",
                    yaw.to_degrees()
                );
            }
        }
    }
}
