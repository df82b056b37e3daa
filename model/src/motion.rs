//! Motion features: the per-frame vector the dance model reads and writes.
//!
//! # Layout (version [`MOTION_LAYOUT_VERSION`], [`MOTION_FEATURE_DIM`] = 136 values)
//!
//! | index | value | unit |
//! | --- | --- | --- |
//! | 0 ([`ROOT_DX`]) | hips displacement since the previous frame, along the previous frame's heading-frame X (the character's left) | m per frame |
//! | 1 ([`ROOT_DZ`]) | the same along the previous heading's forward (+Z) | m per frame |
//! | 2 ([`ROOT_Y`]) | hips height above the floor (world Y) | m |
//! | 3 ([`ROOT_DFACING`]) | change of heading since the previous frame, about +Y, in `[−π, π)`; positive turns left | rad per frame |
//! | 4 + 6·j … 4 + 6·j + 5 ([`rotation_offset`]) | joint `j`'s local rotation in 6D ([`quat_to_6d`]: the images of +X then +Y) | unitless |
//!
//! Joints are in [`Joint::ALL`] order (`j` = [`Joint::index`]). For `Hips` the rotation is its
//! world rotation with the heading removed (`yaw(−heading) · q_hips`), so a frame's features do
//! not depend on where the dancer stands or faces: only displacements, height and turns are
//! kept, and decoding integrates them from a chosen start ([`RootState`]).
//!
//! The *heading* ([`heading`]) is the angle about +Y of the direction the pelvis faces on the
//! ground: the hips' forward axis (+Z) projected on the floor, plus their up axis projected and
//! weighted by `−f·|f|` with `f` the forward axis' Y, so the heading stays defined and smooth
//! when bending over or lying back (every heading has a singularity somewhere; this one is at a
//! pelvis pitch of ~124°, upside down).
//! "Heading frame" = rotation about +Y by the heading, at the hips' ground projection.
//!
//! Displacements and turns are per frame, so features depend on the frame rate (the model's is
//! 30 Hz). The first frame of a sequence has no previous frame: its displacement and turn are 0.
//! A turn of more than π in one frame cannot be represented (it wraps). Root integration runs
//! in f64, but poses hold f32 positions, whose resolution (~8 µm at 100 m from the origin)
//! bounds how exactly displacements re-encoded from decoded poses match far from the origin.

use glam::{Quat, Vec3};

use crate::rig::{JOINT_COUNT, Joint, Pose};
use crate::rotation::{normalize_or_identity, quat_to_6d, sixd_to_quat, twist_angle};

/// Version of the feature layout; bump on any change to it.
pub const MOTION_LAYOUT_VERSION: u32 = 1;
/// Index of the root's sideways displacement (m per frame, + = the character's left).
pub const ROOT_DX: usize = 0;
/// Index of the root's forward displacement (m per frame).
pub const ROOT_DZ: usize = 1;
/// Index of the hips' height (m).
pub const ROOT_Y: usize = 2;
/// Index of the heading change (rad per frame, + = turning left).
pub const ROOT_DFACING: usize = 3;
/// Index of the first rotation value (`Hips`' 6D).
pub const ROTATIONS: usize = 4;
/// Number of values per joint rotation.
pub const ROTATION_DIM: usize = 6;
/// Number of values per motion frame.
pub const MOTION_FEATURE_DIM: usize = ROTATIONS + ROTATION_DIM * JOINT_COUNT;

/// One frame of motion features (layout in the module doc).
pub type MotionFeatures = [f32; MOTION_FEATURE_DIM];

/// Index of the first of `joint`'s six rotation values.
#[inline]
pub const fn rotation_offset(joint: Joint) -> usize {
    ROTATIONS + ROTATION_DIM * joint.index()
}

/// A short name for feature `index` (`"root_dx"`, `"LeftHand.6d3"`, …), `None` past the end.
pub fn feature_name(index: usize) -> Option<String> {
    match index {
        ROOT_DX => Some("root_dx".into()),
        ROOT_DZ => Some("root_dz".into()),
        ROOT_Y => Some("root_y".into()),
        ROOT_DFACING => Some("root_dfacing".into()),
        _ => {
            let k = index.checked_sub(ROTATIONS)?;
            let joint = Joint::from_index(k / ROTATION_DIM)?;
            Some(format!("{joint}.6d{}", k % ROTATION_DIM))
        }
    }
}

/// The heading of a hips rotation: its facing direction's angle about +Y, radians, 0 = +Z.
///
/// Equivariant under yaw: `heading(yaw(a) · q) = heading(q) + a` (mod 2π).
pub fn heading(hips: Quat) -> f32 {
    let q = normalize_or_identity(hips);
    let forward = q * Vec3::Z;
    let up = q * Vec3::Y;
    // Pitching forward tilts `forward` down and `up` forward by the same amount; adding the
    // latter keeps the direction defined (and smooth) through ±90° pitch, where `forward`
    // alone has no horizontal part. Weighting it by sin² of the pitch rather than sin keeps
    // the usual, nearly upright case close to plain forward projection.
    let w = -forward.y * forward.y.abs();
    let dx = forward.x + w * up.x;
    let dz = forward.z + w * up.z;
    if dx * dx + dz * dz > 1e-10 {
        dx.atan2(dz)
    } else {
        // Only near a ~128° tilt; the twist about Y is still yaw-equivariant there.
        twist_angle(q, Vec3::Y)
    }
}

/// The rotation by `angle` radians about +Y (a heading as a rotation).
#[inline]
pub fn yaw(angle: f32) -> Quat {
    Quat::from_rotation_y(angle)
}

/// Where the root is on the floor and where it faces: the state root integration carries.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RootState {
    /// World X of the hips, metres.
    pub x: f32,
    /// World Z of the hips, metres.
    pub z: f32,
    /// Heading, radians about +Y (0 = facing +Z).
    pub heading: f32,
}

impl RootState {
    /// At the origin, facing +Z.
    pub const ORIGIN: RootState = RootState {
        x: 0.0,
        z: 0.0,
        heading: 0.0,
    };

    /// The root state of `pose`: hips' ground position and heading.
    pub fn of_pose(pose: &Pose) -> RootState {
        RootState {
            x: pose.root_position.x,
            z: pose.root_position.z,
            heading: heading(pose.rotation(Joint::Hips)),
        }
    }
}

impl Default for RootState {
    fn default() -> Self {
        Self::ORIGIN
    }
}

/// `angle` wrapped into `[−π, π)`.
#[inline]
fn wrap(angle: f64) -> f64 {
    use std::f64::consts::{PI, TAU};
    let a = (angle + PI).rem_euclid(TAU) - PI;
    if a >= PI { a - TAU } else { a }
}

/// Streaming encoder: poses in, feature frames out, one at a time, no allocation.
#[derive(Clone, Debug, Default)]
pub struct MotionEncoder {
    /// Previous frame's ground position and heading. f64 so that long sequences far from the
    /// origin keep sub-micrometre displacements.
    previous: Option<(f64, f64, f64)>,
}

impl MotionEncoder {
    /// An encoder whose next frame is the first of a sequence.
    pub fn new() -> Self {
        Self::default()
    }

    /// Forgets the previous frame: the next one starts a new sequence.
    pub fn reset(&mut self) {
        self.previous = None;
    }

    /// Encodes `pose`, the frame after the previous call's, into `out`.
    ///
    /// Non-finite values in `pose` give non-finite features; check [`Pose::is_finite`] first
    /// where that matters.
    pub fn encode_frame(&mut self, pose: &Pose, out: &mut MotionFeatures) {
        let hips = normalize_or_identity(pose.rotation(Joint::Hips));
        let h = heading(hips) as f64;
        let x = pose.root_position.x as f64;
        let z = pose.root_position.z as f64;
        let (dx, dz, dfacing) = match self.previous {
            Some((px, pz, ph)) => {
                let (wx, wz) = (x - px, z - pz);
                let (s, c) = ph.sin_cos();
                // World displacement into the previous heading frame: yaw(−ph) applied to it.
                (wx * c - wz * s, wx * s + wz * c, wrap(h - ph))
            }
            None => (0.0, 0.0, 0.0),
        };
        self.previous = Some((x, z, h));

        out[ROOT_DX] = dx as f32;
        out[ROOT_DZ] = dz as f32;
        out[ROOT_Y] = pose.root_position.y;
        out[ROOT_DFACING] = dfacing as f32;
        for joint in Joint::ALL {
            let q = match joint {
                Joint::Hips => yaw(-h as f32) * hips,
                _ => pose.rotation(joint),
            };
            let o = rotation_offset(joint);
            out[o..o + ROTATION_DIM].copy_from_slice(&quat_to_6d(q));
        }
    }
}

/// Streaming decoder: feature frames in, poses out, integrating the root; no allocation.
#[derive(Clone, Debug)]
pub struct MotionDecoder {
    /// Ground position and heading of the last decoded frame (the start before the first).
    x: f64,
    z: f64,
    heading: f64,
    /// Falls back to the last good height when a frame's is not finite.
    last_height: f32,
}

impl MotionDecoder {
    /// A decoder whose first frame starts from `start` (it lands there if its displacement is 0).
    pub fn new(start: RootState) -> Self {
        let finite = |v: f32| if v.is_finite() { v as f64 } else { 0.0 };
        MotionDecoder {
            x: finite(start.x),
            z: finite(start.z),
            heading: wrap(finite(start.heading)),
            last_height: 0.0,
        }
    }

    /// The root state after the last decoded frame.
    pub fn state(&self) -> RootState {
        RootState {
            x: self.x as f32,
            z: self.z as f32,
            heading: self.heading as f32,
        }
    }

    /// Decodes the next frame into `out`, advancing the root.
    ///
    /// Never produces NaN: non-finite displacements and turns count as 0, a non-finite height
    /// repeats the last one (so one bad network output cannot poison the integrated root), and
    /// rotations go through [`sixd_to_quat`].
    pub fn decode_frame(&mut self, features: &MotionFeatures, out: &mut Pose) {
        let finite = |v: f32| if v.is_finite() { v as f64 } else { 0.0 };
        let dx = finite(features[ROOT_DX]);
        let dz = finite(features[ROOT_DZ]);
        let dfacing = finite(features[ROOT_DFACING]);
        let (s, c) = self.heading.sin_cos();
        // yaw(heading) applied to the heading-frame displacement.
        self.x += dx * c + dz * s;
        self.z += -dx * s + dz * c;
        // Wrapping keeps the heading's precision over arbitrarily many turns.
        self.heading = wrap(self.heading + dfacing);
        // Absurd displacements can leave f32's range; restart at the origin rather than emit inf.
        if !(self.x as f32).is_finite() || !(self.z as f32).is_finite() {
            self.x = 0.0;
            self.z = 0.0;
        }
        let y = features[ROOT_Y];
        if y.is_finite() {
            self.last_height = y;
        }

        out.root_position = Vec3::new(self.x as f32, self.last_height, self.z as f32);
        for joint in Joint::ALL {
            let o = rotation_offset(joint);
            let mut d = [0.0; ROTATION_DIM];
            d.copy_from_slice(&features[o..o + ROTATION_DIM]);
            let q = sixd_to_quat(d);
            out.local_rotations[joint.index()] = match joint {
                Joint::Hips => yaw(self.heading as f32) * q,
                _ => q,
            };
        }
    }
}

/// Encodes a sequence of poses (consecutive frames) into `out`, replacing its contents.
pub fn encode(frames: &[Pose], out: &mut Vec<MotionFeatures>) {
    out.clear();
    out.reserve(frames.len());
    let mut encoder = MotionEncoder::new();
    for pose in frames {
        let mut f = [0.0; MOTION_FEATURE_DIM];
        encoder.encode_frame(pose, &mut f);
        out.push(f);
    }
}

/// Decodes a sequence of feature frames into `out` (replacing its contents), integrating the
/// root from `start`.
pub fn decode(features: &[MotionFeatures], start: RootState, out: &mut Vec<Pose>) {
    out.clear();
    out.reserve(features.len());
    let mut decoder = MotionDecoder::new(start);
    for f in features {
        let mut pose = Pose::rest();
        decoder.decode_frame(f, &mut pose);
        out.push(pose);
    }
}

/// The frame of the mirror-image dance: left and right swapped, as if seen in a mirror facing
/// the dancer (the reflection x → −x of our coordinates). Sideways steps and turns change
/// sign; each joint's rotation `R` becomes `M R M` (`M` = diag(−1, 1, 1)) on the opposite
/// joint, which on a 6D rotation (the images of +X and +Y) is `(x, −y, −z)` for the first
/// column and `(−x, y, z)` for the second. Data augmentation: a mirrored dance is a dance.
pub fn mirror_features(f: &MotionFeatures) -> MotionFeatures {
    let mut out = *f;
    out[ROOT_DX] = -f[ROOT_DX];
    out[ROOT_DFACING] = -f[ROOT_DFACING];
    for joint in Joint::ALL {
        let from = rotation_offset(joint);
        let to = rotation_offset(joint.mirror());
        let c = &f[from..from + ROTATION_DIM];
        out[to..to + ROTATION_DIM].copy_from_slice(&[c[0], -c[1], -c[2], -c[3], c[4], c[5]]);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rotation::expmap_to_quat;
    use proptest::prelude::*;
    use std::f32::consts::{PI, TAU};

    const EPS: f32 = 1e-5;
    const DT: f32 = 1.0 / 30.0;

    /// splitmix64: a deterministic generator for test motions, seeded by proptest.
    struct Rng(u64);

    impl Rng {
        fn next_u64(&mut self) -> u64 {
            self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = self.0;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            z ^ (z >> 31)
        }

        fn uniform(&mut self, lo: f32, hi: f32) -> f32 {
            let u = (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32;
            lo + (hi - lo) * u
        }

        fn vec3(&mut self, amplitude: f32) -> Vec3 {
            Vec3::new(
                self.uniform(-amplitude, amplitude),
                self.uniform(-amplitude, amplitude),
                self.uniform(-amplitude, amplitude),
            )
        }
    }

    /// A random smooth dance: walking along a turning path with a swaying pelvis and every
    /// joint oscillating, far enough from the origin to exercise precision.
    fn random_motion(seed: u64, frames: usize) -> Vec<Pose> {
        let mut rng = Rng(seed);
        let start = Vec3::new(rng.uniform(-20.0, 20.0), 0.0, rng.uniform(-20.0, 20.0));
        let h0 = rng.uniform(-PI, PI);
        let turn_rate = rng.uniform(-2.5, 2.5); // rad/s
        let turn_wobble = (rng.uniform(0.0, 1.0), rng.uniform(0.5, 6.0));
        let speed = rng.uniform(0.0, 1.5); // m/s forward
        let side = rng.uniform(-0.5, 0.5); // m/s sideways
        let bounce = (rng.uniform(0.0, 0.08), rng.uniform(1.0, 10.0));
        let tilt = (rng.vec3(0.4), rng.vec3(0.3), rng.uniform(0.5, 8.0));
        let joints: Vec<(Vec3, Vec3, f32, f32)> = (0..JOINT_COUNT)
            .map(|_| {
                (
                    rng.vec3(0.6),
                    rng.vec3(1.0),
                    rng.uniform(0.3, 12.0),
                    rng.uniform(0.0, TAU),
                )
            })
            .collect();

        let mut position = start;
        let mut out = Vec::with_capacity(frames);
        for i in 0..frames {
            let t = i as f32 * DT;
            let h = h0 + turn_rate * t + turn_wobble.0 * (turn_wobble.1 * t).sin();
            if i > 0 {
                let step = yaw(h) * Vec3::new(side * (2.0 * t).cos(), 0.0, speed) * DT;
                position += step;
            }
            position.y = 0.95 + bounce.0 * (bounce.1 * t).sin();
            let mut pose = Pose::rest();
            pose.root_position = position;
            for (joint, &(base, amp, freq, phase)) in Joint::ALL.into_iter().zip(&joints) {
                let local = expmap_to_quat(base + amp * (freq * t + phase).sin());
                pose.set_rotation(joint, local);
            }
            let sway = expmap_to_quat(tilt.0 + tilt.1 * (tilt.2 * t).sin());
            pose.set_rotation(Joint::Hips, yaw(h) * sway);
            out.push(pose);
        }
        out
    }

    use crate::rotation::tests::same_rotation;

    fn assert_poses_close(a: &[Pose], b: &[Pose]) {
        assert_eq!(a.len(), b.len());
        for (i, (p, q)) in a.iter().zip(b).enumerate() {
            let d = (p.root_position - q.root_position).abs().max_element();
            assert!(
                d <= EPS,
                "frame {i}: root {} vs {}",
                p.root_position,
                q.root_position
            );
            for joint in Joint::ALL {
                let (r, s) = (p.rotation(joint), q.rotation(joint));
                assert!(
                    r.dot(s).abs() >= 1.0 - EPS && same_rotation(r, s, EPS),
                    "frame {i} {joint}: {r} vs {s}"
                );
            }
        }
    }

    fn assert_features_close(a: &[MotionFeatures], b: &[MotionFeatures]) {
        assert_eq!(a.len(), b.len());
        for (i, (f, g)) in a.iter().zip(b).enumerate() {
            for k in 0..MOTION_FEATURE_DIM {
                assert!(
                    (f[k] - g[k]).abs() <= EPS,
                    "frame {i} {}: {} vs {}",
                    feature_name(k).unwrap(),
                    f[k],
                    g[k]
                );
            }
        }
    }

    #[test]
    fn layout() {
        assert_eq!(MOTION_FEATURE_DIM, 136);
        assert_eq!(rotation_offset(Joint::Hips), 4);
        assert_eq!(rotation_offset(Joint::RightToes) + 6, MOTION_FEATURE_DIM);
        assert_eq!(feature_name(0).as_deref(), Some("root_dx"));
        assert_eq!(feature_name(3).as_deref(), Some("root_dfacing"));
        assert_eq!(feature_name(4).as_deref(), Some("Hips.6d0"));
        assert_eq!(feature_name(135).as_deref(), Some("RightToes.6d5"));
        assert_eq!(feature_name(136), None);
    }

    #[test]
    fn heading_follows_yaw_and_survives_pitch() {
        for a in [-3.0f32, -1.0, 0.0, 0.5, 2.0, 3.1] {
            assert!((heading(yaw(a)) - a).abs() < 1e-6);
            // Bending far forward or back, or rolling, keeps the heading.
            for (pitch, roll) in [
                (-1.5f32, 0.0f32),
                (-0.7, 0.0),
                (0.3, 0.0),
                (1.5707964, 0.0),
                (2.0, 0.0),
                (0.0, 0.8),
                (0.0, -1.5),
            ] {
                let q = yaw(a) * Quat::from_rotation_x(pitch) * Quat::from_rotation_z(roll);
                let h = heading(q);
                assert!(
                    crate::rotation::wrap_angle(h - a).abs() < 1e-5,
                    "yaw {a} pitch {pitch}: heading {h}"
                );
            }
        }
        assert!(heading(Quat::from_xyzw(f32::NAN, 0.0, 0.0, 1.0)).is_finite());
    }

    proptest! {
        #[test]
        fn heading_is_yaw_equivariant(
            v in prop::array::uniform3(-1.0f32..1.0),
            a in -PI..PI,
        ) {
            let q = expmap_to_quat(Vec3::from_array(v));
            let d = crate::rotation::wrap_angle(heading(yaw(a) * q) - heading(q) - a);
            prop_assert!(d.abs() < 1e-4, "{d}");
        }
    }

    #[test]
    fn rest_motion_encodes_to_rest_features() {
        let frames = vec![Pose::rest(); 3];
        let mut f = Vec::new();
        encode(&frames, &mut f);
        for frame in &f {
            assert_eq!(frame[..ROTATIONS], [0.0; 4]);
            for joint in Joint::ALL {
                let o = rotation_offset(joint);
                assert_eq!(frame[o..o + 6], [1.0, 0.0, 0.0, 0.0, 1.0, 0.0]);
            }
        }
    }

    #[test]
    fn walking_in_a_circle_gives_constant_features() {
        let (radius, omega, center) = (2.0f32, 0.8f32, Vec3::new(3.0, 0.0, -1.0));
        // Leaning into the turn: a roll keeps the pelvis' forward axis and so the heading.
        let lean = Quat::from_rotation_z(-0.15);
        let frames: Vec<Pose> = (0..300)
            .map(|i| {
                let h = omega * i as f32 * DT;
                let mut pose = Pose::rest();
                pose.root_position = center + Vec3::new(-radius * h.cos(), 0.93, radius * h.sin());
                pose.set_rotation(Joint::Hips, yaw(h) * lean);
                pose
            })
            .collect();
        let mut f = Vec::new();
        encode(&frames, &mut f);
        let step = omega * DT;
        for frame in &f[1..] {
            assert!(
                (frame[ROOT_DFACING] - step).abs() < EPS,
                "{}",
                frame[ROOT_DFACING]
            );
            assert!((frame[ROOT_DZ] - radius * step.sin()).abs() < EPS);
            assert!((frame[ROOT_DX] - radius * (1.0 - step.cos())).abs() < EPS);
            assert!((frame[ROOT_Y] - 0.93).abs() < EPS);
            assert_features_close(&[*frame], &[f[1]]);
        }
    }

    #[test]
    fn features_ignore_where_the_dancer_faces() {
        let frames = random_motion(7, 90);
        let (turn, shift) = (yaw(2.2), Vec3::new(-4.0, 0.0, 9.0));
        let moved: Vec<Pose> = frames
            .iter()
            .map(|p| {
                let mut m = *p;
                m.root_position = turn * p.root_position + shift;
                m.set_rotation(Joint::Hips, turn * p.rotation(Joint::Hips));
                m
            })
            .collect();
        let (mut a, mut b) = (Vec::new(), Vec::new());
        encode(&frames, &mut a);
        encode(&moved, &mut b);
        assert_features_close(&a, &b);
    }

    #[test]
    fn bad_features_decode_to_finite_poses() {
        let mut f = [f32::NAN; MOTION_FEATURE_DIM];
        f[ROOT_DX] = f32::INFINITY;
        let g = [f32::MAX; MOTION_FEATURE_DIM];
        let mut poses = Vec::new();
        decode(&[f, g, g, f], RootState::ORIGIN, &mut poses);
        assert!(poses.iter().all(Pose::is_finite));
        let mut decoder = MotionDecoder::new(RootState {
            x: f32::NAN,
            z: 1.0,
            heading: f32::INFINITY,
        });
        let mut pose = Pose::rest();
        decoder.decode_frame(&f, &mut pose);
        assert!(pose.is_finite());
        assert_eq!(
            decoder.state(),
            RootState {
                x: 0.0,
                z: 1.0,
                heading: 0.0
            }
        );
    }

    #[test]
    fn streaming_matches_batch_and_resumes() {
        let frames = random_motion(11, 60);
        let mut f = Vec::new();
        encode(&frames, &mut f);
        let start = RootState::of_pose(&frames[0]);
        let mut all = Vec::new();
        decode(&f, start, &mut all);
        // Decoding the second half from the state where the first half ended gives the same.
        let mut first = Vec::new();
        decode(&f[..30], start, &mut first);
        let mut decoder = MotionDecoder::new(start);
        let mut pose = Pose::rest();
        for g in &f[..30] {
            decoder.decode_frame(g, &mut pose);
        }
        assert_eq!(pose, first[29]);
        for (i, g) in f[30..].iter().enumerate() {
            decoder.decode_frame(g, &mut pose);
            assert_eq!(pose, all[30 + i]);
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(24))]

        #[test]
        fn motion_features_motion(seed in any::<u64>()) {
            let frames = random_motion(seed, 240);
            let mut f = Vec::new();
            encode(&frames, &mut f);
            let mut back = Vec::new();
            decode(&f, RootState::of_pose(&frames[0]), &mut back);
            assert_poses_close(&frames, &back);
        }

        #[test]
        fn features_motion_features(
            seed in any::<u64>(),
            x in -50.0f32..50.0,
            z in -50.0f32..50.0,
            h in -PI..PI,
        ) {
            let frames = random_motion(seed, 240);
            let mut f = Vec::new();
            encode(&frames, &mut f);
            // Features carry no absolute position or facing: any start reproduces them.
            let mut motion = Vec::new();
            decode(&f, RootState { x, z, heading: h }, &mut motion);
            let mut again = Vec::new();
            encode(&motion, &mut again);
            assert_features_close(&f, &again);
        }
    }

    #[test]
    fn mirrored_features_are_the_features_of_the_mirrored_dance() {
        use crate::rig::to_unity_rotation;
        let mut rng = 7u64;
        let mut next = || {
            rng = rng
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((rng >> 33) as f32 / (1u64 << 31) as f32) - 0.5
        };
        let mut poses = Vec::new();
        let mut pose = Pose::rest();
        for f in 0..20 {
            pose.root_position =
                glam::Vec3::new(0.1 * f as f32 + next(), 0.9 + 0.1 * next(), next());
            for j in Joint::ALL {
                let axis = glam::Vec3::new(next(), next(), next()).normalize_or_zero();
                pose.set_rotation(j, Quat::from_axis_angle(axis, 2.0 * next()));
            }
            poses.push(pose);
        }
        // The mirror image: x → −x, each rotation conjugated by the reflection, sides swapped.
        let mirrored: Vec<Pose> = poses
            .iter()
            .map(|p| {
                let mut m = *p;
                m.root_position.x = -p.root_position.x;
                for j in Joint::ALL {
                    m.set_rotation(j.mirror(), to_unity_rotation(p.rotation(j)));
                }
                m
            })
            .collect();
        let (mut a, mut b) = (Vec::new(), Vec::new());
        encode(&poses, &mut a);
        encode(&mirrored, &mut b);
        for (i, (fa, fb)) in a.iter().zip(&b).enumerate() {
            let m = mirror_features(fa);
            for k in 0..MOTION_FEATURE_DIM {
                assert!(
                    (m[k] - fb[k]).abs() < 1e-4,
                    "frame {i} feature {k}: {} vs {}",
                    m[k],
                    fb[k]
                );
            }
            assert_eq!(mirror_features(&m), *fa, "an involution");
        }
    }
}
