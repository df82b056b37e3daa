//! VRChat OSC trackers (<https://docs.vrchat.com/docs/osc-trackers>): up to eight body trackers
//! plus the head, each a world position and Unity Euler angles.

use crate::error::ProtocolError;
use crate::finite;
use crate::frame::{BodyFrame, BoneSample};
use crate::human_bones::canonical_bone;
use crate::osc_writer::OscWriter;
use crate::packet_pool::PacketPool;
use glam::{EulerRot, Quat, Vec3};

/// VRChat accepts trackers 1..=8.
pub const MAX_TRACKERS: usize = 8;

/// The key of the head tracker in a numbered map.
pub const HEAD_KEY: &str = "head";

const DEFAULT_TRACKERS: [&str; MAX_TRACKERS] = [
    "Hips",
    "Chest",
    "LeftFoot",
    "RightFoot",
    "LeftLowerLeg",
    "RightLowerLeg",
    "LeftLowerArm",
    "RightLowerArm",
];
const DEFAULT_HEAD: &str = "Head";

/// Which bone feeds each VRChat tracker; valid by construction (at most 8 trackers, every bone a
/// `HumanBodyBones` name, spelled as Unity spells it).
#[derive(Clone, Debug, PartialEq, Eq, serde::Deserialize)]
#[serde(try_from = "RawTrackerMap")]
pub struct VrchatTrackerMap {
    trackers: Vec<&'static str>,
    head: Option<&'static str>,
}

/// The map as written in TOML, before validation.
#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
struct RawTrackerMap {
    trackers: Vec<String>,
    head: Option<String>,
}

impl Default for RawTrackerMap {
    fn default() -> Self {
        Self {
            trackers: DEFAULT_TRACKERS.iter().map(|s| s.to_string()).collect(),
            head: Some(DEFAULT_HEAD.to_string()),
        }
    }
}

impl TryFrom<RawTrackerMap> for VrchatTrackerMap {
    type Error = ProtocolError;

    fn try_from(raw: RawTrackerMap) -> Result<Self, ProtocolError> {
        Self::new(&raw.trackers, raw.head.as_deref())
    }
}

impl Default for VrchatTrackerMap {
    fn default() -> Self {
        Self {
            trackers: DEFAULT_TRACKERS.to_vec(),
            head: Some(DEFAULT_HEAD),
        }
    }
}

impl VrchatTrackerMap {
    /// Bones for trackers 1, 2, ... in order (fewer than 8 leaves the rest unsent) and for the
    /// head (`None` leaves VRChat's own head alone); an error for more than 8 trackers or a name
    /// that is not a `HumanBodyBones` bone (case is forgiven and corrected).
    pub fn new<S: AsRef<str>>(trackers: &[S], head: Option<&str>) -> Result<Self, ProtocolError> {
        if trackers.len() > MAX_TRACKERS {
            return Err(ProtocolError::TooManyTrackers(trackers.len()));
        }
        let trackers = trackers
            .iter()
            .enumerate()
            .map(|(i, bone)| bone_for(&(i + 1).to_string(), bone.as_ref()))
            .collect::<Result<_, _>>()?;
        let head = head.map(|bone| bone_for(HEAD_KEY, bone)).transpose()?;
        Ok(Self { trackers, head })
    }

    /// The map from numbered entries as `[output.vrchat.trackers]` writes them: keys "1" to "8"
    /// numbered densely from 1 and "head" (the head stays on `Head` when not given).
    ///
    /// Errors name the entry at fault: a key that is not a number or "head", a leading zero
    /// ("01"), a number outside 1..8, a key given twice, a gap (1, 2, 4), an unknown bone.
    pub fn from_numbered<K, V>(
        entries: impl IntoIterator<Item = (K, V)>,
    ) -> Result<Self, ProtocolError>
    where
        K: AsRef<str>,
        V: AsRef<str>,
    {
        let mut numbered: [Option<&'static str>; MAX_TRACKERS] = [None; MAX_TRACKERS];
        let mut head = None;
        for (key, bone) in entries {
            let (key, bone) = (key.as_ref(), bone.as_ref());
            let slot = if key == HEAD_KEY {
                &mut head
            } else {
                &mut numbered[tracker_index(key)?]
            };
            if slot.is_some() {
                return Err(ProtocolError::TrackerDuplicate(key.to_string()));
            }
            *slot = Some(bone_for(key, bone)?);
        }
        let count = numbered.iter().filter(|b| b.is_some()).count();
        if let Some(missing) = numbered[..count].iter().position(Option::is_none) {
            let highest = numbered
                .iter()
                .rposition(Option::is_some)
                .map_or(0, |i| i + 1);
            return Err(ProtocolError::TrackerGap {
                missing: missing + 1,
                highest,
            });
        }
        Ok(Self {
            trackers: numbered.iter().map_while(|b| *b).collect(),
            head: Some(head.unwrap_or(DEFAULT_HEAD)),
        })
    }

    /// Bones for trackers 1, 2, ..., in order.
    pub fn trackers(&self) -> &[&'static str] {
        &self.trackers
    }

    /// Bone for `/tracking/trackers/head`, if sent.
    pub fn head(&self) -> Option<&'static str> {
        self.head
    }
}

/// Index 0..8 of a tracker number key "1".."8".
fn tracker_index(key: &str) -> Result<usize, ProtocolError> {
    if key.is_empty() || !key.bytes().all(|b| b.is_ascii_digit()) {
        return Err(ProtocolError::TrackerBadKey(key.to_string()));
    }
    if key.len() > 1 && key.starts_with('0') {
        return Err(ProtocolError::TrackerLeadingZero(key.to_string()));
    }
    match key.parse::<usize>() {
        Ok(n) if (1..=MAX_TRACKERS).contains(&n) => Ok(n - 1),
        _ => Err(ProtocolError::TrackerOutOfRange(key.to_string())),
    }
}

fn bone_for(key: &str, bone: &str) -> Result<&'static str, ProtocolError> {
    canonical_bone(bone).ok_or_else(|| ProtocolError::TrackerUnknownBone {
        key: key.to_string(),
        bone: bone.to_string(),
    })
}

/// Encodes frames as VRChat tracker messages, one UDP packet per message.
#[derive(Clone, Debug)]
pub struct VrchatEncoder {
    map: VrchatTrackerMap,
    // (address of position, address of rotation, bone) per tracker, built once.
    addresses: Vec<(String, String, &'static str)>,
    missing_bones: u64,
    replaced_non_finite: u64,
}

impl Default for VrchatEncoder {
    fn default() -> Self {
        Self::new(VrchatTrackerMap::default())
    }
}

impl VrchatEncoder {
    /// An encoder for the given tracker assignment.
    pub fn new(map: VrchatTrackerMap) -> Self {
        let mut addresses: Vec<(String, String, &'static str)> = map
            .trackers
            .iter()
            .enumerate()
            .map(|(i, &bone)| {
                (
                    format!("/tracking/trackers/{}/position", i + 1),
                    format!("/tracking/trackers/{}/rotation", i + 1),
                    bone,
                )
            })
            .collect();
        if let Some(head) = map.head {
            addresses.push((
                "/tracking/trackers/head/position".into(),
                "/tracking/trackers/head/rotation".into(),
                head,
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
        let mut pool = PacketPool::new();
        self.write_frame(frame, &mut pool);
        pool.into_packets()
    }

    /// The frame's packets, replacing the pool's; allocates only while the pool grows.
    ///
    /// Separate messages rather than a bundle: VRChat applies them on arrival anyway, and some
    /// relays in between (OSC routers) do not forward bundles.
    pub fn write_frame(&mut self, frame: &BodyFrame, pool: &mut PacketPool) {
        pool.clear();
        for (pos_addr, rot_addr, bone) in &self.addresses {
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
            write_message(pool.next_packet(), pos_addr, [p.x, p.y, p.z]);
            write_message(pool.next_packet(), rot_addr, [e.x, e.y, e.z]);
        }
    }
}

fn find_bone<'a>(bones: &'a [BoneSample], name: &str) -> Option<&'a BoneSample> {
    bones.iter().find(|b| b.bone == name)
}

fn write_message(buf: &mut Vec<u8>, addr: &str, v: [f32; 3]) {
    OscWriter::new(buf)
        .string(&[addr])
        .string(&[",fff"])
        .floats(&v);
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
    use rosc::{OscMessage, OscPacket, OscType};
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
        let mut pool = PacketPool::from(packets);
        let mut f2 = frame.clone();
        f2.bones.retain(|b| !b.bone.ends_with("Foot"));
        enc.write_frame(&f2, &mut pool);
        assert_eq!(pool.packets().len(), 14);
        assert_eq!(enc.missing_bones(), 2);
    }

    #[test]
    fn tracker_map_deserialises_from_toml() {
        let m: VrchatTrackerMap =
            toml::from_str("trackers = [\"Hips\", \"Head\"]\nhead = \"Neck\"").unwrap();
        assert_eq!(m.trackers(), ["Hips", "Head"]);
        assert_eq!(m.head(), Some("Neck"));
        let d: VrchatTrackerMap = toml::from_str("").unwrap();
        assert_eq!(d, VrchatTrackerMap::default());
        assert!(toml::from_str::<VrchatTrackerMap>("trackerz = []").is_err());
    }

    #[test]
    fn numbered_maps_read_as_the_config_writes_them() {
        let m = VrchatTrackerMap::from_numbered([("2", "chest"), ("1", "Hips"), ("head", "Neck")])
            .unwrap();
        assert_eq!(
            m.trackers(),
            ["Hips", "Chest"],
            "in number order, spelled as Unity does"
        );
        assert_eq!(m.head(), Some("Neck"));
        let default: Vec<(String, String)> = VrchatTrackerMap::default()
            .trackers()
            .iter()
            .enumerate()
            .map(|(i, b)| ((i + 1).to_string(), b.to_string()))
            .collect();
        assert_eq!(
            VrchatTrackerMap::from_numbered(default).unwrap(),
            VrchatTrackerMap::default(),
            "the head stays on Head when not given"
        );
        let empty = VrchatTrackerMap::from_numbered(std::iter::empty::<(&str, &str)>()).unwrap();
        assert!(empty.trackers().is_empty());
    }

    #[test]
    fn bad_numbered_maps_are_errors_that_name_the_entry() {
        let err = |entries: &[(&str, &str)]| match VrchatTrackerMap::from_numbered(
            entries.iter().copied(),
        ) {
            Err(e) => e,
            Ok(map) => panic!("{entries:?}: {map:?}"),
        };
        use ProtocolError::*;
        assert!(matches!(err(&[("0", "Hips")]), TrackerOutOfRange(k) if k == "0"));
        assert!(matches!(err(&[("9", "Hips")]), TrackerOutOfRange(k) if k == "9"));
        assert!(matches!(
            err(&[("99999999999999999999999", "Hips")]),
            TrackerOutOfRange(k) if k == "99999999999999999999999"
        ));
        assert!(matches!(
            err(&[("1", "Hips"), ("2", "Chest"), ("4", "Head")]),
            TrackerGap {
                missing: 3,
                highest: 4
            }
        ));
        assert!(matches!(
            err(&[("2", "Chest")]),
            TrackerGap {
                missing: 1,
                highest: 2
            }
        ));
        assert!(matches!(
            err(&[("1", "Hips"), ("1", "Chest")]),
            TrackerDuplicate(k) if k == "1"
        ));
        assert!(matches!(
            err(&[("head", "Head"), ("head", "Neck")]),
            TrackerDuplicate(k) if k == "head"
        ));
        assert!(matches!(err(&[("01", "Hips")]), TrackerLeadingZero(k) if k == "01"));
        for key in ["one", "", " 1", "-1", "Head", "1.0", "+1"] {
            assert!(
                matches!(err(&[(key, "Hips")]), TrackerBadKey(ref k) if k == key),
                "{key:?}"
            );
        }
        assert!(matches!(
            err(&[("1", "Hips"), ("2", "Tail")]),
            TrackerUnknownBone { key, bone } if key == "2" && bone == "Tail"
        ));
        assert!(matches!(
            err(&[("head", "")]),
            TrackerUnknownBone { key, bone } if key == "head" && bone.is_empty()
        ));
        let message = VrchatTrackerMap::from_numbered([("1", "Hips"), ("3", "Chest")])
            .unwrap_err()
            .to_string();
        assert!(
            message.contains("tracker 2 is missing") && message.contains("tracker 3"),
            "{message}"
        );
    }

    #[test]
    fn listed_maps_are_validated_too() {
        assert!(matches!(
            VrchatTrackerMap::new(&["Hips"; 9], None),
            Err(ProtocolError::TooManyTrackers(9))
        ));
        assert!(matches!(
            VrchatTrackerMap::new(&["Hips", "Hipz"], None),
            Err(ProtocolError::TrackerUnknownBone { .. })
        ));
        let m = VrchatTrackerMap::new(&["hips"], None).unwrap();
        assert_eq!((m.trackers(), m.head()), (&["Hips"][..], None));
        let e = toml::from_str::<VrchatTrackerMap>("trackers = [\"Hips\", \"Knee\"]")
            .unwrap_err()
            .to_string();
        assert!(e.contains("Knee"), "{e}");
    }

    #[test]
    fn messages_are_byte_identical_to_the_rosc_encoding() {
        let bones = vec![
            sample("Hips", 0.5, Quat::from_rotation_y(0.3)),
            sample("Head", f32::NAN, Quat::from_rotation_x(0.2)),
        ];
        let frame = BodyFrame {
            frame_index: 0,
            audio_time_s: 0.0,
            timetag: UNIX_EPOCH,
            root_position: Vec3::ZERO,
            root_rotation: Quat::IDENTITY,
            bones,
        };
        let mut enc = VrchatEncoder::default();
        let got = enc.encode_frame(&frame);
        let msg = |addr: &str, v: Vec3| {
            rosc::encoder::encode(&OscPacket::Message(OscMessage {
                addr: addr.into(),
                args: vec![
                    OscType::Float(v.x),
                    OscType::Float(v.y),
                    OscType::Float(v.z),
                ],
            }))
            .unwrap()
        };
        let want = vec![
            msg("/tracking/trackers/1/position", Vec3::new(0.5, 1.0, 2.0)),
            msg(
                "/tracking/trackers/1/rotation",
                unity_euler_degrees(Quat::from_rotation_y(0.3)),
            ),
            msg("/tracking/trackers/head/position", Vec3::ZERO),
            msg(
                "/tracking/trackers/head/rotation",
                unity_euler_degrees(Quat::from_rotation_x(0.2)),
            ),
        ];
        assert_eq!(got, want);
        assert_eq!(enc.missing_bones(), 7);
        assert_eq!(enc.replaced_non_finite(), 1);
    }
}
