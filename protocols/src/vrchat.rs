//! VRChat OSC trackers (<https://docs.vrchat.com/docs/osc-trackers>): up to eight body trackers
//! plus the head, each a world position and Unity Euler angles.

use crate::finite;
use crate::frame::{BodyFrame, BoneSample};
use glam::{EulerRot, Quat, Vec3};
use rosc::{OscMessage, OscPacket, OscType};

/// Which bone feeds each VRChat tracker.
#[derive(Clone, Debug, PartialEq, Eq, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct VrchatTrackerMap {
    /// Bone names (`HumanBodyBones`) for trackers 1..=8, in order; fewer than 8 leaves the rest
    /// unsent.
    pub trackers: Vec<String>,
    /// Bone for `/tracking/trackers/head`, or none to leave VRChat's own head alone.
    pub head: Option<String>,
}

impl Default for VrchatTrackerMap {
    fn default() -> Self {
        let trackers = [
            "Hips",
            "Chest",
            "LeftFoot",
            "RightFoot",
            "LeftLowerLeg",
            "RightLowerLeg",
            "LeftLowerArm",
            "RightLowerArm",
        ];
        Self {
            trackers: trackers.iter().map(|s| s.to_string()).collect(),
            head: Some("Head".to_string()),
        }
    }
}

/// VRChat accepts trackers 1..=8.
pub const MAX_TRACKERS: usize = 8;

/// Encodes frames as VRChat tracker messages, one UDP packet per message.
#[derive(Clone, Debug)]
pub struct VrchatEncoder {
    map: VrchatTrackerMap,
    // (address of position, address of rotation, bone) per tracker, built once.
    addresses: Vec<(String, String, String)>,
    missing_bones: u64,
    replaced_non_finite: u64,
}

impl Default for VrchatEncoder {
    fn default() -> Self {
        Self::new(VrchatTrackerMap::default())
    }
}

impl VrchatEncoder {
    /// An encoder for the given tracker assignment; trackers beyond the eighth are ignored.
    pub fn new(map: VrchatTrackerMap) -> Self {
        let mut addresses: Vec<(String, String, String)> = map
            .trackers
            .iter()
            .take(MAX_TRACKERS)
            .enumerate()
            .map(|(i, bone)| {
                (
                    format!("/tracking/trackers/{}/position", i + 1),
                    format!("/tracking/trackers/{}/rotation", i + 1),
                    bone.clone(),
                )
            })
            .collect();
        if let Some(head) = &map.head {
            addresses.push((
                "/tracking/trackers/head/position".into(),
                "/tracking/trackers/head/rotation".into(),
                head.clone(),
            ));
        }
        Self {
            map,
            addresses,
            missing_bones: 0,
            replaced_non_finite: 0,
        }
    }

    /// The tracker assignment in use.
    pub fn map(&self) -> &VrchatTrackerMap {
        &self.map
    }

    /// Trackers skipped so far because their bone was not in the frame.
    pub fn missing_bones(&self) -> u64 {
        self.missing_bones
    }

    /// How many poses had a non-finite number replaced so far.
    pub fn replaced_non_finite(&self) -> u64 {
        self.replaced_non_finite
    }

    /// The frame's packets, freshly allocated.
    pub fn encode_frame(&mut self, frame: &BodyFrame) -> Vec<Vec<u8>> {
        let mut out = Vec::new();
        self.encode_frame_into(frame, &mut out);
        out
    }

    /// The frame's packets written into `out`, whose inner buffers are reused.
    ///
    /// Separate messages rather than a bundle: VRChat applies them on arrival anyway, and some
    /// relays in between (OSC routers) do not forward bundles.
    pub fn encode_frame_into(&mut self, frame: &BodyFrame, out: &mut Vec<Vec<u8>>) {
        let mut used = 0;
        for i in 0..self.addresses.len() {
            let bone = &self.addresses[i].2;
            let Some(sample) = find_bone(&frame.bones, bone) else {
                self.missing_bones += 1;
                continue;
            };
            let (p, q) = (sample.world_position, sample.world_rotation);
            if !finite::is_finite_pose(p, q) {
                self.replaced_non_finite += 1;
            }
            let p = finite::vec3(p);
            let e = unity_euler_degrees(q);
            let (pos_addr, rot_addr, _) = &self.addresses[i];
            write_message(out, &mut used, pos_addr, [p.x, p.y, p.z]);
            write_message(out, &mut used, rot_addr, [e.x, e.y, e.z]);
        }
        out.truncate(used);
    }
}

fn find_bone<'a>(bones: &'a [BoneSample], name: &str) -> Option<&'a BoneSample> {
    bones.iter().find(|b| b.bone == name)
}

fn write_message(out: &mut Vec<Vec<u8>>, used: &mut usize, addr: &str, v: [f32; 3]) {
    if *used == out.len() {
        out.push(Vec::new());
    }
    let buf = &mut out[*used];
    buf.clear();
    let packet = OscPacket::Message(OscMessage {
        addr: addr.to_string(),
        args: v.iter().map(|&x| OscType::Float(x)).collect(),
    });
    // Encoding into a Vec<u8> cannot fail (its error type is Infallible).
    let _ = rosc::encoder::encode_into(&packet, buf);
    *used += 1;
}

/// Unity's Euler angles of a rotation in degrees (x, y, z), each in (-180, 180]: the rotation is
/// about Z, then X, then Y (q = qY · qX · qZ), as `Transform.eulerAngles`. Non-finite input gives
/// zeros.
pub fn unity_euler_degrees(q: Quat) -> Vec3 {
    let q = finite::quat(q);
    let (y, x, z) = q.to_euler(EulerRot::YXZ);
    let e = Vec3::new(x, y, z) * (180.0 / std::f32::consts::PI);
    finite::vec3(e)
}

/// The rotation Unity's `Quaternion.Euler(x, y, z)` makes from degrees: qY · qX · qZ.
pub fn unity_quat_from_euler_degrees(e: Vec3) -> Quat {
    let r = e * (std::f32::consts::PI / 180.0);
    Quat::from_rotation_y(r.y) * Quat::from_rotation_x(r.x) * Quat::from_rotation_z(r.z)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use rosc::decoder::decode_udp;
    use std::time::UNIX_EPOCH;

    fn close(a: Vec3, b: Vec3, tol: f32) -> bool {
        (a - b).abs().max_element() < tol
    }

    #[test]
    fn euler_of_single_axis_rotations() {
        let deg = std::f32::consts::PI / 180.0;
        let e = unity_euler_degrees(Quat::from_rotation_y(90.0 * deg));
        assert!(close(e, Vec3::new(0.0, 90.0, 0.0), 1e-3), "{e}");
        let e = unity_euler_degrees(Quat::from_rotation_x(30.0 * deg));
        assert!(close(e, Vec3::new(30.0, 0.0, 0.0), 1e-3), "{e}");
        let e = unity_euler_degrees(Quat::from_rotation_z(-45.0 * deg));
        assert!(close(e, Vec3::new(0.0, 0.0, -45.0), 1e-3), "{e}");
        assert_eq!(
            unity_euler_degrees(Quat::from_xyzw(f32::NAN, 0.0, 0.0, 1.0)),
            Vec3::ZERO
        );
    }

    #[test]
    fn euler_order_is_z_then_x_then_y() {
        let q = unity_quat_from_euler_degrees(Vec3::new(20.0, 40.0, 60.0));
        let deg = std::f32::consts::PI / 180.0;
        // Applied to a vector: Z first, so it is the right-most factor.
        let manual = Quat::from_rotation_y(40.0 * deg)
            * Quat::from_rotation_x(20.0 * deg)
            * Quat::from_rotation_z(60.0 * deg);
        assert!(q.abs_diff_eq(manual, 1e-6));
        let e = unity_euler_degrees(q);
        assert!(close(e, Vec3::new(20.0, 40.0, 60.0), 1e-3), "{e}");
        // Z then X: +X tipped 60° towards +Y, then pitched about X, then yawed.
        let v = q * Vec3::X;
        let want = Quat::from_rotation_y(40.0 * deg)
            * (Quat::from_rotation_x(20.0 * deg) * (Quat::from_rotation_z(60.0 * deg) * Vec3::X));
        assert!(close(v, want, 1e-5));
    }

    proptest! {
        #[test]
        fn euler_round_trips_through_quaternions(
            x in -89.0f32..89.0, y in -179.0f32..179.0, z in -179.0f32..179.0
        ) {
            let q = unity_quat_from_euler_degrees(Vec3::new(x, y, z));
            let back = unity_quat_from_euler_degrees(unity_euler_degrees(q));
            // Same rotation (q and -q are one rotation).
            prop_assert!(q.dot(back).abs() > 1.0 - 1e-5, "{q} vs {back}");
        }
    }

    fn sample(bone: &'static str, x: f32, rot: Quat) -> BoneSample {
        BoneSample {
            bone,
            local_position: Vec3::ZERO,
            local_rotation: Quat::IDENTITY,
            world_position: Vec3::new(x, 1.0, 2.0),
            world_rotation: rot,
        }
    }

    #[test]
    fn default_map_sends_eight_trackers_and_the_head() {
        let names = [
            "Hips",
            "Chest",
            "LeftFoot",
            "RightFoot",
            "LeftLowerLeg",
            "RightLowerLeg",
            "LeftLowerArm",
            "RightLowerArm",
            "Head",
        ];
        let bones = names
            .iter()
            .enumerate()
            .map(|(i, n)| {
                sample(
                    n,
                    i as f32,
                    Quat::from_rotation_y(std::f32::consts::FRAC_PI_2),
                )
            })
            .collect();
        let frame = BodyFrame {
            frame_index: 0,
            audio_time_s: 0.0,
            timetag: UNIX_EPOCH,
            root_position: Vec3::ZERO,
            root_rotation: Quat::IDENTITY,
            bones,
        };
        let mut enc = VrchatEncoder::new(VrchatTrackerMap::default());
        let packets = enc.encode_frame(&frame);
        assert_eq!(packets.len(), 18);
        let decoded: Vec<OscMessage> = packets
            .iter()
            .map(|p| match decode_udp(p).unwrap().1 {
                OscPacket::Message(m) => m,
                OscPacket::Bundle(_) => panic!(),
            })
            .collect();
        assert_eq!(decoded[4].addr, "/tracking/trackers/3/position");
        assert_eq!(
            decoded[4].args,
            vec![
                OscType::Float(2.0),
                OscType::Float(1.0),
                OscType::Float(2.0)
            ]
        );
        assert_eq!(decoded[5].addr, "/tracking/trackers/3/rotation");
        let y = decoded[5].args[1].clone().float().unwrap();
        assert!((y - 90.0).abs() < 1e-3);
        assert_eq!(decoded[16].addr, "/tracking/trackers/head/position");
        assert_eq!(decoded[16].args[0], OscType::Float(8.0));
        assert_eq!(decoded[17].addr, "/tracking/trackers/head/rotation");
        assert_eq!(enc.missing_bones(), 0);

        // A frame without feet: those trackers are skipped and counted.
        let mut out = packets;
        let mut f2 = frame.clone();
        f2.bones.retain(|b| !b.bone.ends_with("Foot"));
        enc.encode_frame_into(&f2, &mut out);
        assert_eq!(out.len(), 14);
        assert_eq!(enc.missing_bones(), 2);
    }

    #[test]
    fn tracker_map_deserialises_from_toml() {
        let m: VrchatTrackerMap =
            toml::from_str("trackers = [\"Hips\", \"Head\"]\nhead = \"Neck\"").unwrap();
        assert_eq!(m.trackers, vec!["Hips", "Head"]);
        assert_eq!(m.head.as_deref(), Some("Neck"));
        let d: VrchatTrackerMap = toml::from_str("").unwrap();
        assert_eq!(d, VrchatTrackerMap::default());
        assert!(toml::from_str::<VrchatTrackerMap>("trackerz = []").is_err());
    }
}
