//! The Performer side of the Virtual Motion Capture protocol (<https://protocol.vmc.info/english>):
//! root and bone poses that VSeeFace, VMC, Warudo and friends apply to their avatar.

use crate::finite;
use crate::frame::BodyFrame;
use crate::osc_writer::{BUNDLE_HEADER_BYTES, ELEMENT_HEADER_BYTES, OscWriter, string_len};
use crate::packet_pool::PacketPool;
use crate::timetag::osc_time;
use rosc::OscTime;

/// Largest encoded bundle when splitting: fits an Ethernet MTU with IPv4/IPv6 and UDP headers.
pub const MAX_SPLIT_BUNDLE_BYTES: usize = 1400;

const ROOT_ADDR: &str = "/VMC/Ext/Root/Pos";
const BONE_ADDR: &str = "/VMC/Ext/Bone/Pos";
const POSE_TAGS: &str = ",sfffffff";
const OK_ADDR: &str = "/VMC/Ext/OK";
const TIME_ADDR: &str = "/VMC/Ext/T";

/// Encodes frames as VMC Performer bundles.
#[derive(Clone, Debug, Default)]
pub struct VmcEncoder {
    /// Emit several bundles of at most [`MAX_SPLIT_BUNDLE_BYTES`] instead of one, so that one lost
    /// IP fragment on Wi-Fi does not lose the whole frame.
    pub split_bundles: bool,
    replaced_non_finite: u64,
}

impl VmcEncoder {
    /// An encoder that sends one bundle per frame, or size-limited bundles when `split_bundles`.
    pub fn new(split_bundles: bool) -> Self {
        Self {
            split_bundles,
            ..Self::default()
        }
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
    pub fn write_frame(&mut self, frame: &BodyFrame, pool: &mut PacketPool) {
        pool.clear();
        let mut bundles = Bundles {
            pool,
            timetag: osc_time(frame.timetag),
            split: self.split_bundles,
        };
        // The avatar root stays at the origin: the Hips bone's local transform already carries
        // the dancer's world position and rotation, and receivers (EVMC4U, VSeeFace, ...) apply
        // Root and Hips both, so sending the travel in Root too would count it twice.
        let _ = (frame.root_position, frame.root_rotation);
        bundles.pose(ROOT_ADDR, "root", &[0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0]);
        for bone in &frame.bones {
            let (p, q) = self.pose(bone.local_position, bone.local_rotation);
            bundles.pose(BONE_ADDR, bone.bone, &[p.x, p.y, p.z, q.x, q.y, q.z, q.w]);
        }
        bundles.element(string_len(&[OK_ADDR]) + string_len(&[",i"]) + 4, |w| {
            w.string(&[OK_ADDR]).string(&[",i"]).int(1);
        });
        let t = finite::scalar64(frame.audio_time_s);
        if !(frame.audio_time_s as f32).is_finite() {
            self.replaced_non_finite += 1;
        }
        bundles.element(string_len(&[TIME_ADDR]) + string_len(&[",f"]) + 4, |w| {
            w.string(&[TIME_ADDR]).string(&[",f"]).float(t);
        });
    }

    fn pose(&mut self, p: glam::Vec3, q: glam::Quat) -> (glam::Vec3, glam::Quat) {
        if !finite::is_finite_pose(p, q) {
            self.replaced_non_finite += 1;
        }
        (finite::vec3(p), finite::quat(q))
    }
}

/// One frame's bundles being written into a pool.
struct Bundles<'a> {
    pool: &'a mut PacketPool,
    timetag: OscTime,
    split: bool,
}

impl Bundles<'_> {
    /// A `s name, f × 7` message.
    fn pose(&mut self, addr: &str, name: &str, values: &[f32; 7]) {
        let len = string_len(&[addr]) + string_len(&[POSE_TAGS]) + string_len(&[name]) + 28;
        self.element(len, |w| {
            w.string(&[addr])
                .string(&[POSE_TAGS])
                .string(&[name])
                .floats(values);
        });
    }

    /// A message of `len` encoded bytes, appended to the last bundle or, when splitting and it
    /// would overflow that one, to a new bundle.
    fn element(&mut self, len: usize, write: impl FnOnce(&mut OscWriter)) {
        // Greedy packing keeps message order, so Root stays first and OK/T stay last, which
        // receivers that apply on /VMC/Ext/OK rely on. A bundle always takes one message, even
        // one too big for the limit on its own.
        let start_new = match self.pool.last_packet() {
            None => true,
            Some(b) => {
                self.split
                    && b.len() > BUNDLE_HEADER_BYTES
                    && b.len() + ELEMENT_HEADER_BYTES + len > MAX_SPLIT_BUNDLE_BYTES
            }
        };
        if start_new {
            OscWriter::new(self.pool.next_packet()).bundle_header(self.timetag);
        }
        if let Some(buf) = self.pool.last_packet() {
            let mut w = OscWriter::new(buf);
            let e = w.begin_element();
            write(&mut w);
            w.end_element(e);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame::BoneSample;
    use glam::{Quat, Vec3};
    use rosc::decoder::decode_udp;
    use rosc::{OscBundle, OscMessage, OscPacket, OscType};
    use std::time::{Duration, UNIX_EPOCH};

    const BONES: [&str; 20] = [
        "Hips",
        "Spine",
        "Chest",
        "UpperChest",
        "Neck",
        "Head",
        "LeftShoulder",
        "LeftUpperArm",
        "LeftLowerArm",
        "LeftHand",
        "RightShoulder",
        "RightUpperArm",
        "RightLowerArm",
        "RightHand",
        "LeftUpperLeg",
        "LeftLowerLeg",
        "LeftFoot",
        "RightUpperLeg",
        "RightLowerLeg",
        "RightFoot",
    ];

    fn frame(n: usize) -> BodyFrame {
        BodyFrame {
            frame_index: 7,
            audio_time_s: 3.25,
            timetag: UNIX_EPOCH + Duration::from_secs(1_800_000_000),
            root_position: Vec3::new(1.0, 0.0, 2.0),
            root_rotation: Quat::IDENTITY,
            bones: (0..n)
                .map(|i| BoneSample {
                    bone: BONES[i % BONES.len()],
                    local_position: Vec3::new(0.0, 0.1 * i as f32, 0.0),
                    local_rotation: Quat::from_rotation_z(0.1 * i as f32),
                    world_position: Vec3::ZERO,
                    world_rotation: Quat::IDENTITY,
                })
                .collect(),
        }
    }

    fn decode_all(packets: &[Vec<u8>]) -> Vec<OscMessage> {
        let mut msgs = Vec::new();
        for p in packets {
            let (rest, packet) = decode_udp(p).unwrap();
            assert!(rest.is_empty());
            let OscPacket::Bundle(b) = packet else {
                panic!("expected bundle")
            };
            assert_eq!(b.timetag.seconds, 1_800_000_000 + 2_208_988_800);
            for c in b.content {
                let OscPacket::Message(m) = c else {
                    panic!("nested")
                };
                msgs.push(m);
            }
        }
        msgs
    }

    #[test]
    fn one_bundle_holds_root_bones_ok_and_time() {
        let mut enc = VmcEncoder::default();
        let packets = enc.encode_frame(&frame(20));
        assert_eq!(packets.len(), 1);
        let msgs = decode_all(&packets);
        assert_eq!(msgs.len(), 23);
        assert_eq!(msgs[0].addr, "/VMC/Ext/Root/Pos");
        assert_eq!(msgs[0].args[0], OscType::String("root".into()));
        // Root at the origin: the travel is in the Hips bone (never counted twice).
        assert_eq!(msgs[0].args[1], OscType::Float(0.0));
        assert_eq!(msgs[0].args[3], OscType::Float(0.0));
        assert_eq!(msgs[0].args[7], OscType::Float(1.0));
        assert_eq!(msgs[8].addr, "/VMC/Ext/Bone/Pos");
        assert_eq!(msgs[8].args[0], OscType::String("LeftUpperArm".into()));
        assert_eq!(msgs[8].args[2], OscType::Float(0.1 * 7.0));
        let qz = msgs[8].args[6].clone().float().unwrap();
        assert!((qz - (0.35f32).sin()).abs() < 1e-6);
        assert_eq!(msgs[21].addr, "/VMC/Ext/OK");
        assert_eq!(msgs[21].args, vec![OscType::Int(1)]);
        assert_eq!(msgs[22].addr, "/VMC/Ext/T");
        assert_eq!(msgs[22].args, vec![OscType::Float(3.25)]);
    }

    #[test]
    fn split_bundles_stay_under_the_limit_and_keep_every_message_in_order() {
        let mut enc = VmcEncoder::new(true);
        let mut pool = PacketPool::from(vec![vec![1, 2, 3]; 9]);
        let f = frame(55);
        enc.write_frame(&f, &mut pool);
        let out = pool.packets();
        assert!(out.len() > 1, "55 bones cannot fit one 1400-byte bundle");
        for p in out {
            assert!(p.len() <= MAX_SPLIT_BUNDLE_BYTES, "{} bytes", p.len());
        }
        let split = decode_all(out);
        let whole = decode_all(&VmcEncoder::new(false).encode_frame(&f));
        assert_eq!(split, whole);
        let first = out.len();
        enc.write_frame(&frame(2), &mut pool);
        assert_eq!(pool.packets().len(), 1);
        assert!(first > 1);
    }

    /// The frame as the rosc-based encoder this one replaced built it (message by message,
    /// greedily packed when splitting).
    fn rosc_frame(frame: &BodyFrame, split: bool) -> Vec<Vec<u8>> {
        let pose = |name: &str, p: glam::Vec3, q: glam::Quat| {
            let (p, q) = (finite::vec3(p), finite::quat(q));
            let mut args = vec![OscType::String(name.into())];
            args.extend([p.x, p.y, p.z, q.x, q.y, q.z, q.w].map(OscType::Float));
            args
        };
        let mut msgs = vec![OscMessage {
            addr: ROOT_ADDR.into(),
            args: pose("root", Vec3::ZERO, Quat::IDENTITY),
        }];
        for b in &frame.bones {
            msgs.push(OscMessage {
                addr: BONE_ADDR.into(),
                args: pose(b.bone, b.local_position, b.local_rotation),
            });
        }
        msgs.push(OscMessage {
            addr: OK_ADDR.into(),
            args: vec![OscType::Int(1)],
        });
        msgs.push(OscMessage {
            addr: TIME_ADDR.into(),
            args: vec![OscType::Float(finite::scalar64(frame.audio_time_s))],
        });
        let timetag = osc_time(frame.timetag);
        let encode = |content: Vec<OscPacket>| {
            rosc::encoder::encode(&OscPacket::Bundle(OscBundle { timetag, content })).unwrap()
        };
        if !split {
            return vec![encode(msgs.into_iter().map(OscPacket::Message).collect())];
        }
        let mut out = Vec::new();
        let mut content = Vec::new();
        let mut size = 16;
        for m in msgs {
            let len = 4 + rosc::encoder::encode(&OscPacket::Message(m.clone()))
                .unwrap()
                .len();
            if !content.is_empty() && size + len > MAX_SPLIT_BUNDLE_BYTES {
                out.push(encode(std::mem::take(&mut content)));
                size = 16;
            }
            content.push(OscPacket::Message(m));
            size += len;
        }
        out.push(encode(content));
        out
    }

    #[test]
    fn computed_message_sizes_match_rosc() {
        // Byte for byte what the rosc-based encoder sent, whole and split, NaNs included, and
        // so the same split points.
        let mut f = frame(55);
        f.bones[3].local_rotation.x = f32::NAN;
        f.bones[4].local_position.y = f32::INFINITY;
        for n in [0, 1, 20, 55] {
            let mut f = f.clone();
            f.bones.truncate(n);
            for split in [false, true] {
                let got = VmcEncoder::new(split).encode_frame(&f);
                assert_eq!(got, rosc_frame(&f, split), "{n} bones, split {split}");
            }
        }
        let mut enc = VmcEncoder::new(true);
        let mut pool = PacketPool::new();
        enc.write_frame(&f, &mut pool);
        assert_eq!(pool.packets(), &rosc_frame(&f, true)[..]);
        assert_eq!(enc.replaced_non_finite(), 2);
    }

    #[test]
    fn a_message_too_big_for_a_split_bundle_gets_one_of_its_own() {
        let mut f = frame(3);
        let long: &'static str = Box::leak("x".repeat(1500).into_boxed_str());
        f.bones[1].bone = long;
        let packets = VmcEncoder::new(true).encode_frame(&f);
        assert_eq!(packets, rosc_frame(&f, true));
        assert_eq!(packets.len(), 3);
        assert!(packets[1].len() > MAX_SPLIT_BUNDLE_BYTES);
    }
}
