use std::path::PathBuf;

use glam::{Mat3, Quat, Vec3};
use proptest::prelude::*;

use super::export::zxy_degrees;
use super::*;
use crate::motion::{heading, yaw};
use crate::rig::{JOINT_COUNT, Joint, Pose, Skeleton};
use crate::rotation::quat_to_expmap;

/// Angle between two rotations, radians.
fn angle_between(a: Quat, b: Quat) -> f32 {
    quat_to_expmap(a.conjugate() * b).length()
}

fn fk(skeleton: &Skeleton, pose: &Pose) -> ([Vec3; JOINT_COUNT], [Quat; JOINT_COUNT]) {
    let mut p = [Vec3::ZERO; JOINT_COUNT];
    let mut r = [Quat::IDENTITY; JOINT_COUNT];
    skeleton.forward_kinematics(pose, &mut p, &mut r);
    (p, r)
}

/// The shared Bandai Namco BVH files, when present.
fn bandai_dir() -> Option<PathBuf> {
    Some(testkit::shared_data().join("bandai-namco-1")).filter(|dir| dir.is_dir())
}

fn temp_dir(tag: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("danced-bvh-{tag}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

const SMALL: &str = "HIERARCHY
ROOT root
{
  OFFSET 1 2 3
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT a b
  {
    OFFSET 0 10 0
    CHANNELS 3 Yrotation Xrotation Zrotation
    End Site
    {
      OFFSET 0 5 0
    }
  }
  JOINT c {
    OFFSET 10 0 0
    CHANNELS 2 Yposition Xrotation
    End Site
    {
      OFFSET 1 0 0
    }
  }
}
MOTION
Frames: 2
Frame Time: 0.04
0 0 0 0 0 0 0 0 0 0 0
5 6 7 90 0 0 10 -90 0 4 30
";

#[test]
fn parses_any_channel_order_and_subset() {
    let bvh = Bvh::parse(SMALL).unwrap();
    assert_eq!(bvh.joints.len(), 3);
    assert_eq!(bvh.joints[1].name, "a b", "names keep their spaces");
    assert_eq!(bvh.joints[1].parent, Some(0));
    assert_eq!(bvh.joints[2].parent, Some(0));
    assert_eq!(bvh.joints[1].end_site, Some(Vec3::new(0.0, 5.0, 0.0)));
    assert_eq!(
        bvh.joints[2].channels,
        [Channel::Yposition, Channel::Xrotation]
    );
    assert_eq!(bvh.channel_count(), 11);
    assert!((bvh.fps() - 25.0).abs() < 1e-9);
    assert_eq!(bvh.frames.len(), 2);

    // Frame 0: zero pose; positions replace the offset's components.
    let p = bvh.world_positions(0);
    assert_eq!(
        p[0],
        Vec3::ZERO,
        "root position channels replace its OFFSET"
    );
    assert_eq!(p[1], Vec3::new(0.0, 10.0, 0.0));
    assert_eq!(p[2], Vec3::new(10.0, 0.0, 0.0));

    // Frame 1: root turned 90° about Z (Rz·Rx·Ry with x = y = 0), at (5, 6, 7).
    let root = bvh.local_rotation(1, 0);
    assert!(angle_between(root, Quat::from_rotation_z(90f32.to_radians())) < 1e-6);
    // "Yrotation Xrotation Zrotation" = Ry · Rx · Rz.
    let a = bvh.local_rotation(1, 1);
    let expected =
        Quat::from_rotation_y(10f32.to_radians()) * Quat::from_rotation_x(-90f32.to_radians());
    assert!(angle_between(a, expected) < 1e-6);
    // Only Y is animated on c: X and Z keep the OFFSET's.
    assert_eq!(bvh.local_translation(1, 2), Vec3::new(10.0, 4.0, 0.0));
    let p = bvh.world_positions(1);
    assert!(p[0].abs_diff_eq(Vec3::new(5.0, 6.0, 7.0), 1e-5));
    // Root turned +90° about Z takes +Y to −X.
    assert!(
        p[1].abs_diff_eq(Vec3::new(-5.0, 6.0, 7.0), 1e-4),
        "{}",
        p[1]
    );
    assert!(
        p[2].abs_diff_eq(Vec3::new(1.0, 16.0, 7.0), 1e-4),
        "{}",
        p[2]
    );
}

#[test]
fn text_round_trips_exactly() {
    let bvh = Bvh::parse(SMALL).unwrap();
    let again = Bvh::parse(&bvh.to_string()).unwrap();
    assert_eq!(again, bvh);
    // Windows line ends and a byte-order mark are fine too.
    let crlf = format!("\u{feff}{}", SMALL.replace('\n', "\r\n"));
    assert_eq!(Bvh::parse(&crlf).unwrap(), bvh);
}

#[test]
fn writes_channels_in_hierarchy_order_whatever_the_joint_order() {
    // Joints listed breadth-first: the text must list motion values depth-first.
    let joint = |name: &str, parent, offset| BvhJoint {
        name: name.into(),
        parent,
        offset,
        channels: vec![Channel::Zrotation],
        end_site: None,
    };
    let bvh = Bvh {
        joints: vec![
            joint("r", None, Vec3::ZERO),
            joint("a", Some(0), Vec3::X),
            joint("b", Some(0), Vec3::Y),
            joint("a1", Some(1), Vec3::X),
        ],
        frame_time_s: 0.1,
        frames: vec![vec![10.0, 20.0, 30.0, 40.0]],
    };
    let again = Bvh::parse(&bvh.to_string()).unwrap();
    for (i, j) in bvh.joints.iter().enumerate() {
        let k = again.joint_index(&j.name).unwrap();
        assert_eq!(again.local_rotation(0, k), bvh.local_rotation(0, i));
    }
}

#[test]
fn malformed_input_gives_line_numbers() {
    let cases: Vec<(String, usize, &str)> = vec![
        (String::new(), 1, "HIERARCHY"),
        ("HIERARCHY\nROOT r\n{\n".into(), 3, "file ends"),
        (SMALL.replacen("HIERARCHY", "HIERARCH", 1), 1, "HIERARCHY"),
        (
            SMALL.replacen("  {\n    OFFSET 0 10 0", "    OFFSET 0 10 0", 1),
            7,
            "expected \"{\"",
        ),
        (
            SMALL.replacen("CHANNELS 3 Y", "CHANNELS 4 Y", 1),
            9,
            "followed by 3",
        ),
        (
            SMALL.replacen("CHANNELS 3 Y", "CHANNELS x Y", 1),
            9,
            "not a number",
        ),
        (
            SMALL.replacen("Yrotation Xrotation Z", "Yrotation Yrotation Z", 1),
            9,
            "twice",
        ),
        (
            SMALL.replacen("Yrotation Xrotation Z", "Yrotation Wrotation Z", 1),
            9,
            "unknown channel",
        ),
        (
            SMALL.replacen("OFFSET 0 10 0", "OFFSET 0 ten 0", 1),
            8,
            "not a finite number",
        ),
        (
            SMALL.replacen("OFFSET 0 10 0", "OFFSET 0 NaN 0", 1),
            8,
            "not a finite number",
        ),
        (
            SMALL.replacen("OFFSET 0 10 0", "OFFSET 0 1e39 0", 1),
            8,
            "not a finite number",
        ),
        (
            SMALL.replacen("\n}\nMOTION", "\nMOTION", 1),
            23,
            "missing }",
        ),
        (SMALL.replacen("MOTION", "}\nMOTION", 1), 24, "unmatched }"),
        (
            SMALL.replacen("    OFFSET 10 0 0\n", "", 1),
            21,
            "no OFFSET",
        ),
        (
            SMALL.replacen("Frames: 2", "Frames: -2", 1),
            25,
            "frame count",
        ),
        (
            SMALL.replacen("Frame Time: 0.04", "Frame Time: 0", 1),
            26,
            "frame time",
        ),
        (
            SMALL.replacen("Frame Time: 0.04", "Frame Time: nan", 1),
            26,
            "frame time",
        ),
        (
            SMALL.replacen("0 0 0 0 0 0 0 0 0 0 0", "0 0 0 0 0 0 0 0 0 0", 1),
            27,
            "has 10 values",
        ),
        (
            SMALL.replacen("0 0 0 0 0 0 0 0 0 0 0", "0 0 0 0 0 0 0 0 0 0 0 0", 1),
            27,
            "has 12 values",
        ),
        (
            SMALL.replacen("10 -90 0 4 30", "10 -90 0 4 inf", 1),
            28,
            "\"inf\"",
        ),
        (
            SMALL.replacen("10 -90 0 4 30", "10 -90 0 4 NaN", 1),
            28,
            "\"NaN\"",
        ),
        (
            SMALL.replacen("10 -90 0 4 30", "10 -90 0 4 3o", 1),
            28,
            "\"3o\"",
        ),
        (
            format!("{SMALL}1 2 3 4 5 6 7 8 9 10 11\n"),
            29,
            "more frames",
        ),
        (
            SMALL.replacen("Frames: 2", "Frames: 3", 1),
            28,
            "after 2 of the 3",
        ),
        (
            SMALL.replacen("Frames: 2", "Frames: 18446744073709551615", 1),
            28,
            "after 2 of the",
        ),
        (SMALL.replacen("JOINT a b", "ROOT a b", 1), 6, "ROOT inside"),
        (
            SMALL.replacen(
                "    End Site\n    {\n      OFFSET 0 5 0\n    }\n",
                "    End Site\n    {\n    }\n",
                1,
            ),
            12,
            "OFFSET",
        ),
        (
            SMALL.replacen("MOTION", "SPLINE", 1),
            24,
            "unexpected \"SPLINE\"",
        ),
    ];
    for (text, line, fragment) in cases {
        match Bvh::parse(&text) {
            Err(ModelError::BvhSyntax { line: l, message }) => {
                assert!(
                    l == line && message.contains(fragment),
                    "expected line {line} with {fragment:?}, got line {l}: {message}\n{text}"
                );
                let shown = ModelError::BvhSyntax { line: l, message }.to_string();
                assert!(shown.starts_with(&format!("line {line}: ")), "{shown}");
            }
            other => panic!("expected a syntax error at line {line} ({fragment}), got {other:?}"),
        }
    }
}

#[test]
fn deep_hierarchies_do_not_overflow_the_stack() {
    // Too many joints: an error, not a stack overflow.
    let deep: String = "HIERARCHY\n".to_owned() + &"JOINT j\n{\nOFFSET 0 1 0\n".repeat(20_000);
    let deep = deep.replacen("JOINT", "ROOT", 1);
    let err = Bvh::parse(&deep).unwrap_err().to_string();
    assert!(err.contains("more than"), "{err}");

    // A valid 5000-deep chain parses and prints.
    let n = 5000;
    let mut text = "HIERARCHY\nROOT j\n{\nOFFSET 0 0 0\nCHANNELS 1 Zrotation\n".to_owned();
    for _ in 1..n {
        text.push_str("JOINT j\n{\nOFFSET 0 1 0\nCHANNELS 1 Zrotation\n");
    }
    text.push_str(&"}\n".repeat(n));
    text.push_str("MOTION\nFrames: 1\nFrame Time: 0.1\n");
    text.push_str(&vec!["1"; n].join(" "));
    let bvh = Bvh::parse(&text).unwrap();
    assert_eq!(bvh.joints.len(), n);
    assert_eq!(Bvh::parse(&bvh.to_string()).unwrap(), bvh);
}

#[test]
fn read_and_write_name_the_file() {
    let dir = temp_dir("io");
    let missing = dir.join("missing.bvh");
    let err = Bvh::read(&missing).unwrap_err().to_string();
    assert!(err.contains("missing.bvh"), "{err}");

    let bad = dir.join("bad.bvh");
    std::fs::write(&bad, SMALL.replacen("OFFSET 0 10 0", "OFFSET 0 x 0", 1)).unwrap();
    let err = Bvh::read(&bad).unwrap_err().to_string();
    assert!(err.contains("bad.bvh") && err.contains("line 8"), "{err}");

    let binary = dir.join("binary.bvh");
    std::fs::write(&binary, b"HIERARCHY\n\xff\xfe").unwrap();
    let err = Bvh::read(&binary).unwrap_err().to_string();
    assert!(
        err.contains("binary.bvh") && err.contains("line 2"),
        "{err}"
    );

    let good = dir.join("good.bvh");
    let bvh = Bvh::parse(SMALL).unwrap();
    bvh.write(&good).unwrap();
    assert_eq!(Bvh::read(&good).unwrap(), bvh);
    let left: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .filter(|n| n.ends_with(".tmp"))
        .collect();
    assert!(left.is_empty(), "temporary files left: {left:?}");
    let err = bvh
        .write(dir.join("no/such/dir/x.bvh"))
        .unwrap_err()
        .to_string();
    assert!(err.contains("x.bvh"), "{err}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn euler_extraction_handles_gimbal_lock() {
    let bvh_rotation = |q: Quat| {
        let [z, x, y] = zxy_degrees(q);
        Quat::from_rotation_z(z.to_radians())
            * Quat::from_rotation_x(x.to_radians())
            * Quat::from_rotation_y(y.to_radians())
    };
    for x in [90.0f32, -90.0, 89.9999, -89.99999] {
        for (z, y) in [(0.0f32, 0.0f32), (30.0, -50.0), (170.0, 120.0)] {
            let q = Quat::from_rotation_z(z.to_radians())
                * Quat::from_rotation_x(x.to_radians())
                * Quat::from_rotation_y(y.to_radians());
            assert!(angle_between(bvh_rotation(q), q) < 1e-5, "{z} {x} {y}");
        }
    }
    assert_eq!(zxy_degrees(Quat::IDENTITY), [0.0, 0.0, 0.0]);
    let [z, x, y] = zxy_degrees(Quat::from_xyzw(f32::NAN, 0.0, 0.0, 1.0));
    assert_eq!([z, x, y], [0.0, 0.0, 0.0]);
}

/// Rotations up to `max` radians about random axes.
fn rotation(max: f32) -> impl Strategy<Value = Quat> {
    (prop::array::uniform3(-1.0f32..1.0), 0.0f32..1.0).prop_map(move |(a, t)| {
        let axis = Vec3::from_array(a).try_normalize().unwrap_or(Vec3::Y);
        Quat::from_axis_angle(axis, t * max)
    })
}

fn pose(max: f32) -> impl Strategy<Value = Pose> {
    (
        prop::array::uniform22(rotation(max)),
        prop::array::uniform3(-3.0f32..3.0),
    )
        .prop_map(|(local_rotations, root)| Pose {
            root_position: Vec3::from_array(root),
            local_rotations,
        })
}

/// Options that put a file's motion on our rig exactly as given: its axes as ours, no floor fit.
fn exact() -> RetargetOptions {
    RetargetOptions {
        axes: Some(Mat3::IDENTITY),
        floor: false,
        ..RetargetOptions::default()
    }
}

/// Export → write → read → retarget onto the same skeleton.
fn round_trip(skeleton: &Skeleton, poses: &[Pose], fps: f64) -> Retargeted {
    let dir = temp_dir("roundtrip");
    let path = dir.join("motion.bvh");
    export(skeleton, poses, fps).write(&path).unwrap();
    let bvh = Bvh::read(&path).unwrap();
    std::fs::remove_dir_all(&dir).unwrap();
    retarget(&bvh, skeleton, &exact()).unwrap()
}

fn assert_same_motion(skeleton: &Skeleton, expected: &[Pose], got: &[Pose], tolerance: f32) {
    assert_eq!(expected.len(), got.len());
    for (f, (a, b)) in expected.iter().zip(got).enumerate() {
        assert!(b.is_finite(), "frame {f}");
        let (pa, _) = fk(skeleton, a);
        let (pb, _) = fk(skeleton, b);
        for joint in Joint::ALL {
            let i = joint.index();
            let d = (pa[i] - pb[i]).abs().max_element();
            assert!(
                d < tolerance,
                "frame {f} {joint}: {} vs {} ({d})",
                pa[i],
                pb[i]
            );
            let dot = a.local_rotations[i].dot(b.local_rotations[i]).abs();
            let angle = angle_between(a.local_rotations[i], b.local_rotations[i]);
            assert!(
                dot > 1.0 - 1e-6 && angle < tolerance,
                "frame {f} {joint}: |dot| {dot}, {angle} rad"
            );
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    #[test]
    fn export_import_round_trip(
        poses in prop::collection::vec(pose(std::f32::consts::PI), 1..6),
        lengths in prop::array::uniform22(0.02f32..0.6),
        hips in 0.5f32..1.3,
        default_skeleton in any::<bool>(),
    ) {
        let skeleton = if default_skeleton {
            Skeleton::default_adult()
        } else {
            let mut l = lengths;
            l[0] = hips;
            Skeleton::with_bone_lengths(&l).unwrap()
        };
        let result = round_trip(&skeleton, &poses, 30.0);
        prop_assert!((result.fps - 30.0).abs() < 1e-9);
        prop_assert!((result.metres_per_unit - 0.01).abs() < 1e-9);
        prop_assert!(!result.twists_from_motion);
        assert_same_motion(&skeleton, &poses, &result.poses, 1e-4);
    }
}

#[test]
fn export_layout() {
    let skeleton = Skeleton::default_adult();
    let mut pose = skeleton.rest_pose();
    pose.set_rotation(Joint::LeftUpperArm, Quat::from_rotation_z(0.5));
    let bvh = export(&skeleton, &[pose, Pose::rest()], 60.0);
    assert_eq!(bvh.joints.len(), JOINT_COUNT);
    assert!((bvh.fps() - 60.0).abs() < 1e-9);
    for (joint, b) in Joint::ALL.into_iter().zip(&bvh.joints) {
        assert_eq!(b.name, joint.name());
        assert_eq!(b.parent, joint.parent().map(Joint::index));
        assert!(
            b.offset
                .abs_diff_eq(skeleton.offsets[joint.index()] * 100.0, 1e-4)
        );
        let expected_end = matches!(
            joint,
            Joint::Head | Joint::LeftHand | Joint::RightHand | Joint::LeftToes | Joint::RightToes
        );
        assert_eq!(b.end_site.is_some(), expected_end, "{joint}");
        if let Some(e) = b.end_site {
            assert!(e.length() > 3.0, "{joint}: {e}");
        }
    }
    assert_eq!(
        bvh.joints[0].channels,
        [
            Channel::Xposition,
            Channel::Yposition,
            Channel::Zposition,
            Channel::Zrotation,
            Channel::Xrotation,
            Channel::Yrotation
        ]
    );
    let text = bvh.to_string();
    assert!(text.contains("ROOT Hips\n{\n  OFFSET 0 95 0\n"), "{text}");
    assert!(text.contains("CHANNELS 3 Zrotation Xrotation Yrotation"));
    assert!(text.contains("Frames: 2\nFrame Time: 0.016666666666666666\n0 95 0 0 0 0 "));
    // Non-finite input still gives a file that parses.
    let mut bad = Pose::rest();
    bad.root_position.x = f32::NAN;
    bad.local_rotations[3] = Quat::from_xyzw(f32::INFINITY, 0.0, 0.0, 1.0);
    let bvh = export(&skeleton, &[bad], f64::NAN);
    assert!((bvh.fps() - 30.0).abs() < 1e-9);
    assert!(Bvh::parse(&bvh.to_string()).is_ok());
}

/// A sample export for `scripts/blender_bvh_check.sh`: 3 s of a made-up dance at 30 fps, written
/// to the temporary directory (its path is printed with `--nocapture`).
#[test]
fn writes_a_sample_export() {
    let skeleton = Skeleton::default_adult();
    let poses: Vec<Pose> = (0..90)
        .map(|f| {
            let t = f as f32 / 30.0;
            let beat = (t * std::f32::consts::TAU * 2.0).sin();
            let mut pose = skeleton.rest_pose();
            pose.root_position.y -= 0.05 * beat.abs();
            pose.root_position.x = 0.1 * (t * 2.0).sin();
            pose.set_rotation(Joint::Hips, Quat::from_rotation_y(0.4 * (t * 1.5).sin()));
            pose.set_rotation(Joint::LeftUpperArm, Quat::from_rotation_z(1.2 * beat));
            pose.set_rotation(Joint::RightUpperArm, Quat::from_rotation_z(1.2 * beat));
            pose.set_rotation(Joint::LeftLowerArm, Quat::from_rotation_y(-0.8));
            pose.set_rotation(Joint::Head, Quat::from_rotation_x(0.2 * beat));
            pose.set_rotation(
                Joint::LeftUpperLeg,
                Quat::from_rotation_x(-0.3 * beat.max(0.0)),
            );
            pose.set_rotation(
                Joint::LeftLowerLeg,
                Quat::from_rotation_x(0.6 * beat.max(0.0)),
            );
            pose
        })
        .collect();
    let path = std::env::temp_dir().join("danced-export-sample.bvh");
    export(&skeleton, &poses, 30.0).write(&path).unwrap();
    let back = Bvh::read(&path).unwrap();
    assert_eq!((back.joints.len(), back.frames.len()), (JOINT_COUNT, 90));
    println!("wrote {}", path.display());
}

/// How a synthetic source rig differs from ours.
struct SourceRig {
    /// Source name per our joint; `None`: the joint is absent (its rotation must be identity).
    names: [Option<&'static str>; JOINT_COUNT],
    /// Each joint's world rotation in the source's T-pose, in the source's axes.
    orient: [Quat; JOINT_COUNT],
    /// Source axes → ours.
    axes: Mat3,
    /// File units per metre.
    units_per_metre: f32,
}

const BANDAI_NAMES: [Option<&str>; JOINT_COUNT] = [
    Some("Hips"),
    Some("Spine"),
    Some("Chest"),
    None,
    Some("Neck"),
    Some("Head"),
    Some("Shoulder_L"),
    Some("UpperArm_L"),
    Some("LowerArm_L"),
    Some("Hand_L"),
    Some("Shoulder_R"),
    Some("UpperArm_R"),
    Some("LowerArm_R"),
    Some("Hand_R"),
    Some("UpperLeg_L"),
    Some("LowerLeg_L"),
    Some("Foot_L"),
    Some("Toes_L"),
    Some("UpperLeg_R"),
    Some("LowerLeg_R"),
    Some("Foot_R"),
    Some("Toes_R"),
];

const MIXAMO_NAMES: [Option<&str>; JOINT_COUNT] = [
    Some("mixamorig:Hips"),
    Some("mixamorig:Spine"),
    Some("mixamorig:Spine1"),
    Some("mixamorig:Spine2"),
    Some("mixamorig:Neck"),
    Some("mixamorig:Head"),
    Some("mixamorig:LeftShoulder"),
    Some("mixamorig:LeftArm"),
    Some("mixamorig:LeftForeArm"),
    Some("mixamorig:LeftHand"),
    Some("mixamorig:RightShoulder"),
    Some("mixamorig:RightArm"),
    Some("mixamorig:RightForeArm"),
    Some("mixamorig:RightHand"),
    Some("mixamorig:LeftUpLeg"),
    Some("mixamorig:LeftLeg"),
    Some("mixamorig:LeftFoot"),
    Some("mixamorig:LeftToeBase"),
    Some("mixamorig:RightUpLeg"),
    Some("mixamorig:RightLeg"),
    Some("mixamorig:RightFoot"),
    Some("mixamorig:RightToeBase"),
];

fn convert(m: &Mat3, q: Quat) -> Quat {
    Quat::from_mat3(&(*m * Mat3::from_quat(q) * m.transpose())).normalize()
}

/// `poses` of `skeleton` as a BVH of another rig: different names, rest orientations baked into
/// the channels (zero pose ≠ T-pose), other axes and units, an unmapped `joint_Root` above the
/// hips, Bandai Namco's channel layout. Returned as text, to go through the parser.
fn source_bvh(skeleton: &Skeleton, rig: &SourceRig, poses: &[Pose]) -> String {
    let to_source = rig.axes.transpose();
    let mut rest = [Vec3::ZERO; JOINT_COUNT];
    skeleton.world_positions(&skeleton.rest_pose(), &mut rest);
    let present = |j: Joint| rig.names[j.index()].is_some();
    let source_parent = |j: Joint| {
        let mut p = j.parent();
        while let Some(q) = p {
            if present(q) {
                break;
            }
            p = q.parent();
        }
        p
    };
    let six = vec![
        Channel::Xposition,
        Channel::Yposition,
        Channel::Zposition,
        Channel::Zrotation,
        Channel::Xrotation,
        Channel::Yrotation,
    ];
    let mut joints = vec![BvhJoint {
        name: "joint_Root".into(),
        parent: None,
        offset: Vec3::ZERO,
        channels: six.clone(),
        end_site: None,
    }];
    let mut index = [usize::MAX; JOINT_COUNT];
    for joint in Joint::ALL.into_iter().filter(|&j| present(j)) {
        let i = joint.index();
        let (parent, offset) = match source_parent(joint) {
            Some(p) => {
                let v = to_source * (rest[i] - rest[p.index()]) * rig.units_per_metre;
                (index[p.index()], rig.orient[p.index()].conjugate() * v)
            }
            None => (0, to_source * rest[i] * rig.units_per_metre),
        };
        index[i] = joints.len();
        let leaf = !Joint::ALL.iter().any(|c| c.parent() == Some(joint));
        joints.push(BvhJoint {
            name: rig.names[i].unwrap().into(),
            parent: Some(parent),
            offset,
            channels: if joint == Joint::Hips {
                six.clone()
            } else {
                six[3..].to_vec()
            },
            end_site: leaf.then_some(Vec3::ZERO),
        });
    }
    let frames = poses
        .iter()
        .map(|pose| {
            let (_, world) = fk(skeleton, pose);
            let mut values = vec![0.0; 6];
            for joint in Joint::ALL.into_iter().filter(|&j| present(j)) {
                let g = |j: Joint| convert(&to_source, world[j.index()]) * rig.orient[j.index()];
                let local = match source_parent(joint) {
                    Some(p) => g(p).conjugate() * g(joint),
                    None => g(joint),
                };
                if joint == Joint::Hips {
                    values
                        .extend((to_source * pose.root_position * rig.units_per_metre).to_array());
                }
                values.extend(zxy_degrees(local));
            }
            values
        })
        .collect();
    Bvh {
        joints,
        frame_time_s: 1.0 / 30.0,
        frames,
    }
    .to_string()
}

/// The 24 rotations taking axes to axes.
fn quarter_turns() -> Vec<Quat> {
    let h = std::f32::consts::FRAC_PI_2;
    let mut all: Vec<Quat> = Vec::new();
    for a in 0..4 {
        for b in 0..4 {
            for c in 0..4 {
                let q = Quat::from_rotation_z(a as f32 * h)
                    * Quat::from_rotation_x(b as f32 * h)
                    * Quat::from_rotation_y(c as f32 * h);
                if !all.iter().any(|r| r.dot(q).abs() > 0.999) {
                    all.push(q);
                }
            }
        }
    }
    assert_eq!(all.len(), 24);
    all
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    /// Whatever the source's rest orientations, axes and units, bone directions come through:
    /// every joint lands where the original motion put it.
    #[test]
    fn retargets_any_rest_orientation(
        orient in prop::array::uniform22(rotation(std::f32::consts::PI)),
        poses in prop::collection::vec(pose(1.0), 1..5),
        z_up in any::<bool>(),
        metres in any::<bool>(),
    ) {
        let skeleton = Skeleton::default_adult();
        let rig = SourceRig {
            names: MIXAMO_NAMES,
            orient,
            axes: if z_up { RetargetOptions::z_up().axes.unwrap() } else { Mat3::IDENTITY },
            units_per_metre: if metres { 1.0 } else { 100.0 },
        };
        let bvh = Bvh::parse(&source_bvh(&skeleton, &rig, &poses)).unwrap();
        let options = RetargetOptions { axes: Some(rig.axes), floor: false, ..RetargetOptions::default() };
        let result = retarget(&bvh, &skeleton, &options).unwrap();
        prop_assert!((result.metres_per_unit - 1.0 / rig.units_per_metre).abs() < 1e-6);
        prop_assert!(result.source_joints.iter().all(Option::is_some));
        for (f, (a, b)) in poses.iter().zip(&result.poses).enumerate() {
            let (pa, ra) = fk(&skeleton, a);
            let (pb, rb) = fk(&skeleton, b);
            for joint in Joint::ALL {
                let i = joint.index();
                prop_assert!(pa[i].abs_diff_eq(pb[i], 1e-4), "frame {} {}: {} vs {}", f, joint, pa[i], pb[i]);
            }
            // Hips and chest have several branches: their whole rotation is determined.
            for joint in [Joint::Hips, Joint::UpperChest] {
                let i = joint.index();
                prop_assert!(angle_between(ra[i], rb[i]) < 1e-4, "{}", joint);
            }
        }
    }
}

/// A Bandai-Namco-like rig (rest orientations that are quarter turns, names, no UpperChest,
/// centimetres): its T-pose is our T-pose and raising its arm 90° raises ours 90°.
#[test]
fn t_pose_and_raised_arm_come_through() {
    let skeleton = Skeleton::default_adult();
    let turns = quarter_turns();
    let mut rng = 12345u64;
    let mut pick = || {
        rng = rng
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        turns[(rng >> 33) as usize % turns.len()]
    };
    let mut orient = [Quat::IDENTITY; JOINT_COUNT];
    for joint in Joint::ALL {
        orient[joint.index()] = pick();
    }
    // Like Bandai Namco's: the hips' local X (their bone) is up, so the zero pose is no T-pose.
    orient[0] = Quat::from_rotation_z(std::f32::consts::FRAC_PI_2);
    // End joints differ from their parent by a twist about their bone only (the assumption
    // for joints with nothing below them to measure).
    let h = std::f32::consts::FRAC_PI_2;
    for (joint, quarters) in [
        (Joint::Head, 1.0),
        (Joint::LeftHand, 2.0),
        (Joint::RightHand, -1.0),
        (Joint::LeftToes, 1.0),
        (Joint::RightToes, 0.0),
    ] {
        let axis = skeleton.offsets[joint.index()].normalize();
        let parent = orient[joint.parent().unwrap().index()];
        orient[joint.index()] = Quat::from_axis_angle(axis, quarters * h) * parent;
    }
    let rig = SourceRig {
        names: BANDAI_NAMES,
        orient,
        axes: Mat3::IDENTITY,
        units_per_metre: 100.0,
    };

    let t_pose = skeleton.rest_pose();
    let mut raised = t_pose;
    // Left arm straight up: +X turned 90° about +Z.
    raised.set_rotation(Joint::LeftUpperArm, Quat::from_rotation_z(h));
    raised.set_rotation(Joint::RightUpperArm, Quat::from_rotation_z(-h));
    // Some everyday motion too, as twists are estimated from the motion.
    let mut poses = vec![t_pose, raised];
    let mut rng2 = 99u64;
    let mut uniform = || {
        rng2 = rng2
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (rng2 >> 40) as f32 / (1u64 << 24) as f32 * 2.0 - 1.0
    };
    for _ in 0..20 {
        let mut pose = t_pose;
        for joint in Joint::ALL {
            if joint == Joint::UpperChest {
                continue;
            }
            let axis = Vec3::new(uniform(), uniform(), uniform()).normalize();
            pose.set_rotation(joint, Quat::from_axis_angle(axis, 0.5 * uniform()));
        }
        poses.push(pose);
    }

    let bvh = Bvh::parse(&source_bvh(&skeleton, &rig, &poses)).unwrap();
    assert_eq!(bvh.joints.len(), 22, "joint_Root + 21 joints");
    let result = retarget(&bvh, &skeleton, &exact()).unwrap();
    assert!(result.twists_from_motion);
    assert_eq!(result.source_joints[Joint::UpperChest.index()], None);
    assert!((result.root_scale - 0.01).abs() < 1e-7);

    let (rest, _) = fk(&skeleton, &t_pose);
    // Every joint's rotation but the feet's (whose bones are not along an axis, so their
    // rest twist is no quarter turn) comes through; all positions do.
    let checked = |j: Joint| !matches!(j, Joint::LeftFoot | Joint::RightFoot);
    for (f, (expected, got)) in poses.iter().zip(&result.poses).enumerate() {
        let (pe, _) = fk(&skeleton, expected);
        let (pg, _) = fk(&skeleton, got);
        for joint in Joint::ALL {
            let i = joint.index();
            assert!(pe[i].abs_diff_eq(pg[i], 1e-4), "frame {f} {joint}");
            if checked(joint) && joint.parent().is_none_or(checked) {
                let a = angle_between(expected.local_rotations[i], got.local_rotations[i]);
                assert!(a < 1e-3, "frame {f} {joint}: {a} rad");
            }
        }
    }
    // Frame 0: our T-pose; frame 1: elbows straight above the shoulders.
    let (p, _) = fk(&skeleton, &result.poses[0]);
    for joint in Joint::ALL {
        assert!(
            p[joint.index()].abs_diff_eq(rest[joint.index()], 1e-4),
            "{joint}"
        );
    }
    let (p, r) = fk(&skeleton, &result.poses[1]);
    for (shoulder, elbow) in [
        (Joint::LeftUpperArm, Joint::LeftLowerArm),
        (Joint::RightUpperArm, Joint::RightLowerArm),
    ] {
        let up = (p[elbow.index()] - p[shoulder.index()]).normalize();
        assert!(up.abs_diff_eq(Vec3::Y, 1e-4), "{shoulder}: {up}");
    }
    let raised_by = angle_between(Quat::IDENTITY, r[Joint::LeftUpperArm.index()]);
    assert!((raised_by - h).abs() < 1e-4, "{raised_by}");
}

#[test]
fn a_t_pose_source_with_other_proportions_maps_to_our_t_pose() {
    // Mixamo-like: zero pose is the T-pose, centimetres, longer legs and arms.
    let ours = Skeleton::default_adult();
    let theirs = ours.scaled(1.1).unwrap();
    let rig = SourceRig {
        names: MIXAMO_NAMES,
        orient: [Quat::IDENTITY; JOINT_COUNT],
        axes: Mat3::IDENTITY,
        units_per_metre: 100.0,
    };
    let mut step = theirs.rest_pose();
    step.root_position.z += 0.55;
    let bvh = Bvh::parse(&source_bvh(&theirs, &rig, &[theirs.rest_pose(), step])).unwrap();
    let result = retarget(&bvh, &ours, &exact()).unwrap();
    assert!(!result.twists_from_motion);
    for pose in &result.poses {
        for q in pose.local_rotations.iter().skip(1) {
            assert!(angle_between(*q, Quat::IDENTITY) < 1e-5);
        }
    }
    // Standing: our hips at our height; a step scaled to our legs.
    let root = result.poses[0].root_position;
    assert!(root.abs_diff_eq(ours.offsets[0], 1e-5), "{root}");
    let moved = result.poses[1].root_position - root;
    assert!(moved.abs_diff_eq(Vec3::new(0.0, 0.0, 0.5), 1e-5), "{moved}");

    // Without scaling to the legs: metres, shifted by the difference in hips-to-ankle drop.
    let options = RetargetOptions {
        scale_root_to_legs: false,
        ..exact()
    };
    let result = retarget(&bvh, &ours, &options).unwrap();
    let drop = |s: &Skeleton| {
        let (p, _) = fk(s, &s.rest_pose());
        p[0].y - p[Joint::LeftFoot.index()].y
    };
    let root = result.poses[0].root_position;
    let expected = theirs.offsets[0] - Vec3::Y * (drop(&theirs) - drop(&ours));
    assert!(root.abs_diff_eq(expected, 1e-5), "{root} vs {expected}");
    let moved = result.poses[1].root_position - root;
    assert!(
        moved.abs_diff_eq(Vec3::new(0.0, 0.0, 0.55), 1e-5),
        "{moved}"
    );
}

#[test]
fn names_map_case_insensitively() {
    for (name, joint) in [
        ("Hips", Joint::Hips),
        ("HIPS", Joint::Hips),
        ("chest", Joint::Chest),
        ("UpperArm_L", Joint::LeftUpperArm),
        ("toes_r", Joint::RightToes),
        ("mixamorig:LeftArm", Joint::LeftUpperArm),
        ("mixamorig:Spine2", Joint::UpperChest),
        ("LeftUpperLeg", Joint::LeftUpperLeg),
        (" LowerLeg_R ", Joint::RightLowerLeg),
    ] {
        assert_eq!(joint_for_name(name), Some(joint), "{name}");
    }
    for name in ["joint_Root", "", "Tail", "LeftEye"] {
        assert_eq!(joint_for_name(name), None, "{name}");
    }

    // Extra names come first; without any joint for the hips, a clear error.
    let text = SMALL.replace("ROOT root", "ROOT blob");
    let bvh = Bvh::parse(&text).unwrap();
    let err = retarget(
        &bvh,
        &Skeleton::default_adult(),
        &RetargetOptions::default(),
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("Hips") && err.contains("blob"), "{err}");
    let options = RetargetOptions {
        names: vec![("BLOB".into(), Joint::Hips)],
        ..RetargetOptions::default()
    };
    let result = retarget(&bvh, &Skeleton::default_adult(), &options).unwrap();
    assert_eq!(result.source_joints[0], Some(0));
    assert_eq!(result.poses.len(), 2);
    assert!(result.poses.iter().all(Pose::is_finite));

    // A hierarchy that contradicts ours: a spine below a hand.
    let good = SMALL
        .replace("ROOT root", "ROOT Hips")
        .replace("JOINT a b", "JOINT LeftHand")
        .replace("JOINT c", "JOINT Head");
    let bvh = Bvh::parse(&good).unwrap();
    assert!(
        retarget(
            &bvh,
            &Skeleton::default_adult(),
            &RetargetOptions::default()
        )
        .is_ok()
    );
    let bad = good.replace(
        "    End Site\n    {\n      OFFSET 0 5 0\n    }\n",
        "    JOINT Spine\n    {\n      OFFSET 0 1 0\n      CHANNELS 0\n    }\n",
    );
    let err = retarget(
        &Bvh::parse(&bad).unwrap(),
        &Skeleton::default_adult(),
        &RetargetOptions::default(),
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("Spine") && err.contains("LeftHand"), "{err}");

    let options = RetargetOptions {
        axes: Some(Mat3::from_diagonal(Vec3::new(2.0, 1.0, 1.0))),
        ..RetargetOptions::default()
    };
    let err = retarget(&bvh, &Skeleton::default_adult(), &options)
        .unwrap_err()
        .to_string();
    assert!(err.contains("orthogonal"), "{err}");
}

/// Joint count and frame count as the file's header states them.
fn header_counts(text: &str) -> (usize, usize) {
    let joints = text
        .lines()
        .filter(|l| {
            let w = l.split_whitespace().next().unwrap_or("");
            w == "ROOT" || w == "JOINT"
        })
        .count();
    let frames = text
        .lines()
        .find_map(|l| l.trim().strip_prefix("Frames:"))
        .and_then(|n| n.trim().parse().ok())
        .unwrap();
    (joints, frames)
}

#[test]
fn bandai_namco_files_parse_and_retarget() {
    let Some(dir) = testkit::require_shared("bandai-namco-1").map(|d| d.join("bandai-namco-1"))
    else {
        return;
    };
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "bvh"))
        .collect();
    files.sort();
    assert!(!files.is_empty());
    let skeleton = Skeleton::default_adult();
    for path in &files {
        let text = std::fs::read_to_string(path).unwrap();
        let (joints, frames) = header_counts(&text);
        let bvh = Bvh::read(path).unwrap();
        assert_eq!(
            (bvh.joints.len(), bvh.frames.len()),
            (joints, frames),
            "{path:?}"
        );
        assert_eq!(bvh.joints.len(), 22, "{path:?}");
        assert!((bvh.fps() - 30.0).abs() < 1e-3, "{path:?}: {}", bvh.fps());
        // Exactly what was read is written back.
        assert_eq!(Bvh::parse(&bvh.to_string()).unwrap(), bvh);

        let result = retarget(&bvh, &skeleton, &RetargetOptions::default()).unwrap();
        let name = path.file_name().unwrap().to_string_lossy();
        assert_eq!(result.poses.len(), frames);
        assert_eq!(result.metres_per_unit, 0.01, "{name}: centimetres");
        assert!(result.twists_from_motion);
        // Everything but UpperChest has a source joint.
        for joint in Joint::ALL {
            assert_eq!(
                result.source_joints[joint.index()].is_some(),
                joint != Joint::UpperChest,
                "{joint}"
            );
        }

        let mut hips = Vec::new();
        let mut lowest_foot = Vec::new();
        let mut knee_off_axis = 0.0f32;
        let mut knee_total = 0.0f32;
        for pose in &result.poses {
            assert!(pose.is_finite(), "{name}");
            let (p, _) = fk(&skeleton, pose);
            hips.push(p[0].y);
            let feet = [
                Joint::LeftFoot,
                Joint::RightFoot,
                Joint::LeftToes,
                Joint::RightToes,
            ];
            lowest_foot.push(feet.iter().map(|j| p[j.index()].y).fold(f32::MAX, f32::min));
            for knee in [Joint::LeftLowerLeg, Joint::RightLowerLeg] {
                let e = quat_to_expmap(pose.rotation(knee));
                knee_off_axis += e.y.abs() + e.z.abs();
                knee_total += e.length();
            }
        }
        hips.sort_by(f32::total_cmp);
        lowest_foot.sort_by(f32::total_cmp);
        let median_hips = hips[hips.len() / 2];
        assert!(
            (0.8..1.1).contains(&median_hips),
            "{name}: hips {median_hips}"
        );
        // One foot is on the floor nearly all the time (the dances jump a little).
        let p90 = lowest_foot[lowest_foot.len() * 9 / 10];
        assert!(
            lowest_foot[0] > -0.03 && p90 < 0.12,
            "{name}: feet {} … {p90}",
            lowest_foot[0]
        );
        // Knees bend about their hinge (our X): the legs' twists are right.
        assert!(
            knee_off_axis < 0.05 * knee_total,
            "{name}: knees {knee_off_axis} of {knee_total}"
        );

        // The left hand is on the character's left (+X in its heading frame) on average, the
        // left shoulder always.
        let (mut left, mut right) = (Vec3::ZERO, Vec3::ZERO);
        for (f, pose) in result.poses.iter().enumerate() {
            let (p, _) = fk(&skeleton, pose);
            let to_character = yaw(-heading(pose.rotation(Joint::Hips)));
            left += to_character * (p[Joint::LeftHand.index()] - p[0]);
            right += to_character * (p[Joint::RightHand.index()] - p[0]);
            let shoulders =
                to_character * (p[Joint::LeftUpperArm.index()] - p[Joint::RightUpperArm.index()]);
            assert!(shoulders.x > 0.1, "{name} frame {f}: {shoulders}");
        }
        let n = result.poses.len() as f32;
        let (left, right) = (left / n, right / n);
        assert!(
            left.x > 0.0 && right.x < 0.0 && left.x - right.x > 0.15,
            "{name}: {left} {right}"
        );
        // Toes point forward, on average over the clip.
        let mut toes = Vec3::ZERO;
        for pose in &result.poses {
            let (p, _) = fk(&skeleton, pose);
            let to_character = yaw(-heading(pose.rotation(Joint::Hips)));
            for (foot, tip) in [
                (Joint::LeftFoot, Joint::LeftToes),
                (Joint::RightFoot, Joint::RightToes),
            ] {
                toes += to_character * (p[tip.index()] - p[foot.index()]);
            }
        }
        toes /= 2.0 * result.poses.len() as f32;
        assert!(
            toes.z > 0.02 && toes.z > toes.x.abs(),
            "{name}: toes point forward, {toes}"
        );

        // Walking forward goes along the character's forward (+Z), backward along −Z.
        let forward = |f: usize| {
            let pose = &result.poses[f];
            (yaw(-heading(pose.rotation(Joint::Hips)))
                * (result.poses[f + 10].root_position - pose.root_position))
                .z
        };
        if name.contains("walk_") {
            assert!(forward(0) > 0.1, "{name}: {}", forward(0));
        }
        if name.contains("walk-back") {
            assert!(forward(0) < -0.1, "{name}: {}", forward(0));
        }
    }
}

/// Small edits of a real file (or an export, without the data): never a panic, in the parser
/// or in retargeting whatever parses.
fn mutation_base() -> String {
    if let Some(dir) = bandai_dir() {
        let text = std::fs::read_to_string(dir.join("dataset-1_bow_musical_001.bvh")).unwrap();
        // The hierarchy and 12 frames keep each case fast.
        let motion = text.find("MOTION").unwrap();
        let mut lines: Vec<&str> = text[motion..].lines().take(15).collect();
        lines[1] = "Frames: 12";
        format!("{}{}\n", &text[..motion], lines.join("\n"))
    } else {
        let poses = vec![Skeleton::default_adult().rest_pose(); 12];
        export_to_string(&Skeleton::default_adult(), &poses, 30.0)
    }
}

#[derive(Clone, Debug)]
enum Mutation {
    ReplaceWord(usize, &'static str),
    DeleteLine(usize),
    DuplicateLine(usize),
    Truncate(usize),
    InsertByte(usize, u8),
}

fn apply(text: &str, m: &Mutation) -> String {
    match *m {
        Mutation::ReplaceWord(i, with) => {
            let words: Vec<(usize, &str)> = text
                .split_ascii_whitespace()
                .map(|w| (w.as_ptr() as usize - text.as_ptr() as usize, w))
                .collect();
            let (at, w) = words[i % words.len()];
            format!("{}{with}{}", &text[..at], &text[at + w.len()..])
        }
        Mutation::DeleteLine(i) | Mutation::DuplicateLine(i) => {
            let mut lines: Vec<&str> = text.lines().collect();
            let i = i % lines.len();
            if matches!(m, Mutation::DeleteLine(_)) {
                lines.remove(i);
            } else {
                lines.insert(i, lines[i]);
            }
            lines.join("\n")
        }
        Mutation::Truncate(i) => {
            let mut at = i % (text.len() + 1);
            while !text.is_char_boundary(at) {
                at -= 1;
            }
            text[..at].to_owned()
        }
        Mutation::InsertByte(i, b) => {
            let mut at = i % (text.len() + 1);
            while !text.is_char_boundary(at) {
                at -= 1;
            }
            format!("{}{}{}", &text[..at], b as char, &text[at..])
        }
    }
}

fn mutation() -> impl Strategy<Value = Mutation> {
    let words = prop::sample::select(vec![
        "{",
        "}",
        "NaN",
        "inf",
        "1e40",
        "-",
        "JOINT",
        "ROOT",
        "End",
        "Site",
        "CHANNELS",
        "OFFSET",
        "MOTION",
        "Frames:",
        "7",
        "0",
        "-1",
        "",
        "x",
        "Xrotation",
        "Zposition",
        "1e-40",
        "99999",
    ]);
    prop_oneof![
        (any::<usize>(), words).prop_map(|(i, w)| Mutation::ReplaceWord(i, w)),
        any::<usize>().prop_map(Mutation::DeleteLine),
        any::<usize>().prop_map(Mutation::DuplicateLine),
        any::<usize>().prop_map(Mutation::Truncate),
        (
            any::<usize>(),
            prop::sample::select(b"{} \n\t0.-e:#\0".to_vec())
        )
            .prop_map(|(i, b)| Mutation::InsertByte(i, b)),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(384))]

    #[test]
    fn mutated_files_never_panic(mutations in prop::collection::vec(mutation(), 1..4)) {
        thread_local! {
            static BASE: String = mutation_base();
        }
        let text = BASE.with(|b| mutations.iter().fold(b.clone(), |t, m| apply(&t, m)));
        if let Ok(bvh) = Bvh::parse(&text) {
            prop_assert!(bvh.validate().is_ok());
            let again = Bvh::parse(&bvh.to_string()).ok();
            prop_assert_eq!(again.as_ref(), Some(&bvh));
            if let Ok(result) = retarget(&bvh, &Skeleton::default_adult(), &RetargetOptions::default()) {
                prop_assert!(result.poses.iter().all(Pose::is_finite));
            }
        }
    }
}

/// A few seconds of a figure bobbing on bent knees and swaying its arms while stepping along
/// +X, facing +Z: enough of a body to show up, left and forward.
fn bobbing(skeleton: &Skeleton) -> Vec<Pose> {
    (0..60)
        .map(|f| {
            let t = f as f32 / 30.0;
            let bend = 0.3 + 0.2 * (t * 6.0).sin();
            let mut pose = skeleton.rest_pose();
            pose.root_position += Vec3::new(0.2 * t, -0.05 - 0.05 * (t * 6.0).sin(), 0.0);
            for (hip, knee, ankle) in [
                (Joint::LeftUpperLeg, Joint::LeftLowerLeg, Joint::LeftFoot),
                (Joint::RightUpperLeg, Joint::RightLowerLeg, Joint::RightFoot),
            ] {
                pose.set_rotation(hip, Quat::from_rotation_x(-bend));
                pose.set_rotation(knee, Quat::from_rotation_x(2.0 * bend));
                pose.set_rotation(ankle, Quat::from_rotation_x(-bend));
            }
            pose.set_rotation(
                Joint::LeftUpperArm,
                Quat::from_rotation_z(-1.2 + 0.3 * t.sin()),
            );
            pose.set_rotation(
                Joint::RightUpperArm,
                Quat::from_rotation_z(1.2 - 0.3 * t.sin()),
            );
            pose
        })
        .collect()
}

/// Y-up and Z-up files, right- and left-handed, in metres and centimetres, and a Y-up skeleton
/// stood up in a Z-up world by its root (as AMASS's re-exports are): each stands up the way
/// it was captured, its left on its left, feet on the floor even when the file's floor is not
/// at 0.
#[test]
fn axes_handedness_and_floor_are_found_from_the_motion() {
    let skeleton = Skeleton::default_adult();
    let poses = bobbing(&skeleton);
    let mirror_x = Mat3::from_diagonal(Vec3::new(-1.0, 1.0, 1.0));
    let z_up = RetargetOptions::z_up().axes.unwrap();
    // A joint's T-pose orientation that lays a Y-up skeleton into a Z-up file's axes.
    let lying = Quat::from_mat3(&z_up.transpose());
    // How far the motion as given is lifted to stand on the floor.
    let own_floor = {
        let bvh = Bvh::parse(&source_bvh(
            &skeleton,
            &SourceRig {
                names: MIXAMO_NAMES,
                orient: [Quat::IDENTITY; JOINT_COUNT],
                axes: Mat3::IDENTITY,
                units_per_metre: 1.0,
            },
            &poses,
        ))
        .unwrap();
        retarget(&bvh, &skeleton, &RetargetOptions::default())
            .unwrap()
            .floor_shift_m
    };
    for (label, axes, orient, units, expected) in [
        (
            "Y up",
            Mat3::IDENTITY,
            Quat::IDENTITY,
            100.0,
            "Y up, right-handed",
        ),
        ("Z up", z_up, Quat::IDENTITY, 1.0, "Z up, right-handed"),
        (
            "Y up, left-handed",
            mirror_x,
            Quat::IDENTITY,
            1.0,
            "Y up, left-handed",
        ),
        (
            "Z up, left-handed",
            mirror_x * z_up,
            Quat::IDENTITY,
            100.0,
            "Z up, left-handed",
        ),
        (
            "Y-up skeleton in a Z-up world",
            z_up,
            lying,
            1.0,
            "Z up, right-handed",
        ),
    ] {
        let rig = SourceRig {
            names: MIXAMO_NAMES,
            orient: [orient; JOINT_COUNT],
            axes,
            units_per_metre: units,
        };
        // The file's floor 0.3 m below its origin.
        let lowered: Vec<Pose> = poses
            .iter()
            .map(|p| {
                let mut p = *p;
                p.root_position.y -= 0.3;
                p
            })
            .collect();
        let bvh = Bvh::parse(&source_bvh(&skeleton, &rig, &lowered)).unwrap();
        let result = retarget(&bvh, &skeleton, &RetargetOptions::default()).unwrap();
        assert!(result.axes_detected, "{label}");
        assert_eq!(describe_axes(&result.axes), expected, "{label}");
        assert!(
            result.axes.abs_diff_eq(axes, 1e-5),
            "{label}: {} vs {axes}",
            result.axes
        );
        assert!(
            !result.twists_from_motion,
            "{label}: the zero pose is a T-pose"
        );
        assert!(
            (result.floor_shift_m - 0.3 - own_floor).abs() < 1e-3,
            "{label}: {} against {own_floor} + 0.3",
            result.floor_shift_m
        );
        assert!(
            result.bone_error_deg < 0.1,
            "{label}: {}",
            result.bone_error_deg
        );
        let lift = Vec3::Y * own_floor;
        for (f, (a, b)) in poses.iter().zip(&result.poses).enumerate() {
            let (pa, _) = fk(&skeleton, a);
            let (pb, _) = fk(&skeleton, b);
            for joint in Joint::ALL {
                let d = (pa[joint.index()] + lift - pb[joint.index()]).length();
                assert!(d < 1e-3, "{label} frame {f} {joint}: {d} m");
            }
        }
    }
}
