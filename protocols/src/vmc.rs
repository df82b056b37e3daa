//! The Performer side of the Virtual Motion Capture protocol (<https://protocol.vmc.info/english>):
//! root and bone poses that VSeeFace, VMC, Warudo and friends apply to their avatar.

use crate::finite;
use crate::frame::BodyFrame;
use crate::timetag::osc_time;
use rosc::{OscBundle, OscMessage, OscPacket, OscTime, OscType};

/// Largest encoded bundle when splitting: fits an Ethernet MTU with IPv4/IPv6 and UDP headers.
pub const MAX_SPLIT_BUNDLE_BYTES: usize = 1400;

/// Bytes of a bundle before its elements: "#bundle\0" and the timetag.
const BUNDLE_HEADER_BYTES: usize = 16;
/// Bytes in front of each element of a bundle: its size.
const ELEMENT_HEADER_BYTES: usize = 4;

/// Encodes frames as VMC Performer bundles.
#[derive(Clone, Debug, Default)]
pub struct VmcEncoder {
    /// Emit several bundles of at most [`MAX_SPLIT_BUNDLE_BYTES`] instead of one, so that one lost
    /// IP fragment on Wi-Fi does not lose the whole frame.
    pub split_bundles: bool,
    messages: Vec<(OscPacket, usize)>,
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
        let mut out = Vec::new();
        self.encode_frame_into(frame, &mut out);
        out
    }

    /// The frame's packets written into `out`, whose inner buffers are reused; `out` ends up
    /// holding exactly this frame's packets.
    pub fn encode_frame_into(&mut self, frame: &BodyFrame, out: &mut Vec<Vec<u8>>) {
        self.collect_messages(frame);
        let timetag = osc_time(frame.timetag);
        let mut used = 0;
        if !self.split_bundles {
            let content = self.messages.drain(..).map(|(m, _)| m).collect();
            write_bundle(out, &mut used, timetag, content);
        } else {
            // Greedy packing keeps message order, so Root stays first and OK/T stay last, which
            // receivers that apply on /VMC/Ext/OK rely on.
            let mut content = Vec::new();
            let mut size = BUNDLE_HEADER_BYTES;
            for (message, len) in self.messages.drain(..) {
                let element = ELEMENT_HEADER_BYTES + len;
                if !content.is_empty() && size + element > MAX_SPLIT_BUNDLE_BYTES {
                    write_bundle(out, &mut used, timetag, std::mem::take(&mut content));
                    size = BUNDLE_HEADER_BYTES;
                }
                content.push(message);
                size += element;
            }
            if !content.is_empty() {
                write_bundle(out, &mut used, timetag, content);
            }
        }
        out.truncate(used);
    }

    fn collect_messages(&mut self, frame: &BodyFrame) {
        self.messages.clear();
        // The avatar root stays at the origin: the Hips bone's local transform already carries
        // the dancer's world position and rotation, and receivers (EVMC4U, VSeeFace, ...) apply
        // Root and Hips both, so sending the travel in Root too would count it twice.
        let _ = (frame.root_position, frame.root_rotation);
        self.push(
            "/VMC/Ext/Root/Pos",
            "root",
            &[0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0],
        );
        for bone in &frame.bones {
            let (p, q) = self.pose(bone.local_position, bone.local_rotation);
            self.push(
                "/VMC/Ext/Bone/Pos",
                bone.bone,
                &[p.x, p.y, p.z, q.x, q.y, q.z, q.w],
            );
        }
        self.push_message(OscMessage {
            addr: "/VMC/Ext/OK".into(),
            args: vec![OscType::Int(1)],
        });
        let t = finite::scalar64(frame.audio_time_s);
        if !(frame.audio_time_s as f32).is_finite() {
            self.replaced_non_finite += 1;
        }
        self.push_message(OscMessage {
            addr: "/VMC/Ext/T".into(),
            args: vec![OscType::Float(t)],
        });
    }

    fn pose(&mut self, p: glam::Vec3, q: glam::Quat) -> (glam::Vec3, glam::Quat) {
        if !finite::is_finite_pose(p, q) {
            self.replaced_non_finite += 1;
        }
        (finite::vec3(p), finite::quat(q))
    }

    fn push(&mut self, addr: &str, name: &str, values: &[f32; 7]) {
        let mut args = Vec::with_capacity(8);
        args.push(OscType::String(name.to_string()));
        args.extend(values.iter().map(|&v| OscType::Float(v)));
        self.push_message(OscMessage {
            addr: addr.to_string(),
            args,
        });
    }

    fn push_message(&mut self, message: OscMessage) {
        let len = message_len(&message);
        self.messages.push((OscPacket::Message(message), len));
    }
}

/// Encoded size of a message: padded address, padded type tags, arguments.
fn message_len(m: &OscMessage) -> usize {
    let padded = |n: usize| (n + 4) & !3;
    let mut len = padded(m.addr.len()) + padded(1 + m.args.len());
    for a in &m.args {
        len += match a {
            OscType::String(s) => padded(s.len()),
            OscType::Int(_) | OscType::Float(_) => 4,
            // Only the above are produced here; the rest are sized by actually encoding.
            other => rosc::encoder::encode(&OscPacket::Message(OscMessage {
                addr: "/".into(),
                args: vec![other.clone()],
            }))
            .map(|b| b.len() - 8)
            .unwrap_or(0),
        };
    }
    len
}

fn write_bundle(
    out: &mut Vec<Vec<u8>>,
    used: &mut usize,
    timetag: OscTime,
    content: Vec<OscPacket>,
) {
    if *used == out.len() {
        out.push(Vec::new());
    }
    let buf = &mut out[*used];
    buf.clear();
    // Encoding into a Vec<u8> cannot fail (its error type is Infallible).
    let _ = rosc::encoder::encode_into(&OscPacket::Bundle(OscBundle { timetag, content }), buf);
    *used += 1;
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame::BoneSample;
    use glam::{Quat, Vec3};
    use rosc::decoder::decode_udp;
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
        let mut out = vec![vec![1, 2, 3]; 9];
        let f = frame(55);
        enc.encode_frame_into(&f, &mut out);
        assert!(out.len() > 1, "55 bones cannot fit one 1400-byte bundle");
        for p in &out {
            assert!(p.len() <= MAX_SPLIT_BUNDLE_BYTES, "{} bytes", p.len());
        }
        let split = decode_all(&out);
        let whole = decode_all(&VmcEncoder::new(false).encode_frame(&f));
        assert_eq!(split, whole);
        let first = out.len();
        enc.encode_frame_into(&frame(2), &mut out);
        assert_eq!(out.len(), 1);
        assert!(first > 1);
    }

    #[test]
    fn computed_message_sizes_match_rosc() {
        let mut enc = VmcEncoder::default();
        enc.collect_messages(&frame(20));
        for (m, len) in &enc.messages {
            assert_eq!(rosc::encoder::encode(m).unwrap().len(), *len);
        }
    }
}
