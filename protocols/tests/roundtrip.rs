//! Property tests: whatever numbers a frame holds, every encoder's output decodes with rosc,
//! carries no NaN or infinity, and finite inputs come back exactly.

use glam::{Quat, Vec3};
use proptest::prelude::*;
use protocols::{AnalysisEvent, BodyFrame, BoneSample, NativeEncoder, VmcEncoder, VrchatEncoder};
use rosc::{OscPacket, OscType};
use std::time::{Duration, UNIX_EPOCH};

const NAMES: [&str; 8] = [
    "Hips",
    "Chest",
    "LeftFoot",
    "RightFoot",
    "LeftLowerLeg",
    "RightLowerLeg",
    "LeftLowerArm",
    "Head",
];

fn any_f32() -> impl Strategy<Value = f32> {
    prop_oneof![
        8 => -100.0f32..100.0,
        1 => Just(f32::NAN),
        1 => Just(f32::INFINITY),
        1 => any::<f32>(),
    ]
}

fn vec3() -> impl Strategy<Value = Vec3> {
    (any_f32(), any_f32(), any_f32()).prop_map(|(x, y, z)| Vec3::new(x, y, z))
}

fn quat() -> impl Strategy<Value = Quat> {
    (any_f32(), any_f32(), any_f32(), any_f32())
        .prop_map(|(x, y, z, w)| Quat::from_xyzw(x, y, z, w))
}

fn bone() -> impl Strategy<Value = BoneSample> {
    (
        prop::sample::select(NAMES.to_vec()),
        vec3(),
        quat(),
        vec3(),
        quat(),
    )
        .prop_map(
            |(bone, local_position, local_rotation, world_position, world_rotation)| BoneSample {
                bone,
                local_position,
                local_rotation,
                world_position,
                world_rotation,
            },
        )
}

fn frame() -> impl Strategy<Value = BodyFrame> {
    (
        any::<u64>(),
        prop_oneof![0.0f64..1e5, Just(f64::NAN)],
        0u64..2_000_000_000,
        vec3(),
        quat(),
        prop::collection::vec(bone(), 0..60),
    )
        .prop_map(
            |(frame_index, audio_time_s, secs, root_position, root_rotation, bones)| BodyFrame {
                frame_index,
                audio_time_s,
                timetag: UNIX_EPOCH + Duration::from_secs(secs),
                root_position,
                root_rotation,
                bones,
            },
        )
}

/// Every message in a packet, bundles flattened.
fn messages(packet: OscPacket, out: &mut Vec<rosc::OscMessage>) {
    match packet {
        OscPacket::Message(m) => out.push(m),
        OscPacket::Bundle(b) => b.content.into_iter().for_each(|p| messages(p, out)),
    }
}

fn decode(bytes: &[u8]) -> Vec<rosc::OscMessage> {
    let (rest, packet) = rosc::decoder::decode_udp(bytes).expect("rosc decodes our output");
    assert!(rest.is_empty());
    let mut out = Vec::new();
    messages(packet, &mut out);
    out
}

fn all_finite(msgs: &[rosc::OscMessage]) -> bool {
    msgs.iter().flat_map(|m| &m.args).all(|a| match a {
        OscType::Float(f) => f.is_finite(),
        _ => true,
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(128))]

    #[test]
    fn native_frames_decode_finite_and_exact(f in frame()) {
        let mut enc = NativeEncoder::default();
        let msgs = decode(enc.encode_frame(&f));
        prop_assert_eq!(msgs.len(), 2 + f.bones.len());
        prop_assert!(all_finite(&msgs));
        for (m, b) in msgs[2..].iter().zip(&f.bones) {
            prop_assert_eq!(&m.addr, &format!("/danced/joint/{}", b.bone));
            if b.world_position.is_finite() {
                let p = b.world_position;
                prop_assert_eq!(&m.args[..3], &[OscType::Float(p.x), OscType::Float(p.y), OscType::Float(p.z)][..]);
            }
        }
    }

    #[test]
    fn vmc_frames_decode_finite_whole_or_split(f in frame(), split in any::<bool>()) {
        let packets = VmcEncoder::new(split).encode_frame(&f);
        let msgs: Vec<_> = packets.iter().flat_map(|p| decode(p)).collect();
        prop_assert_eq!(msgs.len(), 3 + f.bones.len());
        prop_assert!(all_finite(&msgs));
        if split {
            prop_assert!(packets.iter().all(|p| p.len() <= 1400));
        } else {
            prop_assert_eq!(packets.len(), 1);
        }
    }

    #[test]
    fn vrchat_frames_decode_finite(f in frame()) {
        for p in VrchatEncoder::default().encode_frame(&f) {
            let msgs = decode(&p);
            prop_assert!(all_finite(&msgs));
            prop_assert_eq!(msgs[0].args.len(), 3);
        }
    }

    #[test]
    fn native_events_decode_finite(
        t in prop_oneof![0.0f64..1e4, Just(f64::NAN)], x in any_f32(), y in any_f32(),
        chroma in prop::array::uniform12(any_f32()),
    ) {
        let mut enc = NativeEncoder::default();
        let events = [
            AnalysisEvent::Beat { time_s: t, index_in_bar: 1, beats_per_bar: 4, tempo_bpm: x, bar_confidence: y },
            AnalysisEvent::Onset { time_s: t, strength: x },
            AnalysisEvent::Tempo { bpm: x, confidence: y },
            AnalysisEvent::Chroma { time_s: t, chroma },
            AnalysisEvent::Energy { time_s: t, db: y },
            AnalysisEvent::RelativeLevel { time_s: t, db: y },
        ];
        for e in &events {
            let msgs = decode(enc.encode_event(e));
            prop_assert!(all_finite(&msgs));
        }
    }
}
