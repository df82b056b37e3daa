//! Our own OSC layout: one bundle per frame with float and int arguments only, because
//! TouchDesigner's OSC In CHOP turns only those into channels.

use crate::address::normalise_prefix;
use crate::error::ProtocolError;
use crate::finite;
use crate::frame::{AnalysisEvent, BodyFrame};
use crate::osc_writer::OscWriter;
use crate::timetag::osc_time;

/// The address prefix used when none is configured.
pub const DEFAULT_NATIVE_PREFIX: &str = "/danced";

/// Encodes frames and analysis events in danced's native OSC layout (see the crate README).
#[derive(Clone, Debug)]
pub struct NativeEncoder {
    prefix: String,
    buf: Vec<u8>,
    replaced_non_finite: u64,
    clamped_values: u64,
}

impl Default for NativeEncoder {
    fn default() -> Self {
        Self {
            prefix: DEFAULT_NATIVE_PREFIX.to_string(),
            buf: Vec::with_capacity(4096),
            replaced_non_finite: 0,
            clamped_values: 0,
        }
    }
}

impl NativeEncoder {
    /// An encoder whose addresses start with `prefix` (e.g. "/danced"; "/" for none).
    pub fn with_prefix(prefix: &str) -> Result<Self, ProtocolError> {
        Ok(Self {
            prefix: normalise_prefix(prefix)?,
            ..Self::default()
        })
    }

    /// The normalised prefix, without a trailing '/'.
    pub fn prefix(&self) -> &str {
        &self.prefix
    }

    /// How many poses, times or values had a non-finite number replaced so far.
    pub fn replaced_non_finite(&self) -> u64 {
        self.replaced_non_finite
    }

    /// How many integers were beyond int32 and sent as `i32::MAX` (beat index, beats per bar).
    pub fn clamped_values(&self) -> u64 {
        self.clamped_values
    }

    /// The frame's bundle encoded; the slice borrows a buffer reused by the next call.
    pub fn encode_frame(&mut self, frame: &BodyFrame) -> &[u8] {
        let mut buf = std::mem::take(&mut self.buf);
        self.write_frame(frame, &mut buf);
        self.buf = buf;
        &self.buf
    }

    /// The event's message encoded; the slice borrows a buffer reused by the next call.
    pub fn encode_event(&mut self, event: &AnalysisEvent) -> &[u8] {
        let mut buf = std::mem::take(&mut self.buf);
        self.write_event(event, &mut buf);
        self.buf = buf;
        &self.buf
    }

    /// The frame as one OSC bundle timetagged with `frame.timetag`, replacing `buf`'s contents;
    /// allocates only when `buf` must grow.
    pub fn write_frame(&mut self, frame: &BodyFrame, buf: &mut Vec<u8>) {
        buf.clear();
        let time = self.checked64(frame.audio_time_s);
        let (root_p, root_q) = self.checked_pose(frame.root_position, frame.root_rotation);
        let prefix = self.prefix.as_str();
        let mut w = OscWriter::new(buf);
        w.bundle_header(osc_time(frame.timetag));
        let e = w.begin_element();
        // i32 is all the CHOP reads; wrapping at 2^31 frames is years away at 60 fps.
        w.string(&[prefix, "/frame"])
            .string(&[",if"])
            .int((frame.frame_index & 0x7fff_ffff) as i32)
            .float(time);
        w.end_element(e);
        let e = w.begin_element();
        w.string(&[prefix, "/root"])
            .string(&[POSE_TAGS])
            .floats(&pose_args(root_p, root_q));
        w.end_element(e);
        for bone in &frame.bones {
            // Each half checked on its own: only these two halves go out.
            let (p, _) = checked_pose(
                &mut self.replaced_non_finite,
                bone.world_position,
                glam::Quat::IDENTITY,
            );
            let (_, q) = checked_pose(
                &mut self.replaced_non_finite,
                glam::Vec3::ZERO,
                bone.local_rotation,
            );
            let e = w.begin_element();
            w.string(&[prefix, "/joint/", bone.bone])
                .string(&[POSE_TAGS])
                .floats(&pose_args(p, q));
            w.end_element(e);
        }
    }

    /// The analysis event as one OSC message (no bundle: events are not scheduled), replacing
    /// `buf`'s contents; allocates only when `buf` must grow.
    pub fn write_event(&mut self, event: &AnalysisEvent, buf: &mut Vec<u8>) {
        buf.clear();
        match *event {
            AnalysisEvent::Beat {
                time_s,
                index_in_bar,
                beats_per_bar,
                tempo_bpm,
                bar_confidence,
            } => {
                let index = self.clamp_i32(index_in_bar);
                let per_bar = self.clamp_i32(beats_per_bar);
                let tempo = self.checked(tempo_bpm);
                let time = self.checked64(time_s);
                let confidence = self.checked(bar_confidence);
                OscWriter::new(buf)
                    .string(&[&self.prefix, "/beat"])
                    .string(&[",iifff"])
                    .int(index)
                    .int(per_bar)
                    .float(tempo)
                    .float(time)
                    .float(confidence);
            }
            AnalysisEvent::NextBeat {
                time_s,
                in_s,
                index_in_bar,
                beats_per_bar,
                tempo_bpm,
            } => {
                let index = self.clamp_i32(index_in_bar);
                let per_bar = self.clamp_i32(beats_per_bar);
                let tempo = self.checked(tempo_bpm);
                let time = self.checked64(time_s);
                let in_s = self.checked(in_s);
                OscWriter::new(buf)
                    .string(&[&self.prefix, "/beat/next"])
                    .string(&[",iifff"])
                    .int(index)
                    .int(per_bar)
                    .float(tempo)
                    .float(time)
                    .float(in_s);
            }
            AnalysisEvent::Onset { time_s, strength } => {
                let args = [self.checked(strength), self.checked64(time_s)];
                self.write_floats(buf, "/onset", &args);
            }
            AnalysisEvent::Tempo { bpm, confidence } => {
                let args = [self.checked(bpm), self.checked(confidence)];
                self.write_floats(buf, "/tempo", &args);
            }
            AnalysisEvent::Chroma { chroma, .. } => {
                let mut values = [0.0f32; 12];
                for (v, c) in values.iter_mut().zip(chroma) {
                    *v = self.checked(c);
                }
                self.write_floats(buf, "/chroma", &values);
            }
            AnalysisEvent::Energy { db, .. } => {
                let args = [self.checked(db)];
                self.write_floats(buf, "/energy", &args);
            }
            AnalysisEvent::RelativeLevel { db, .. } => {
                let args = [self.checked(db)];
                self.write_floats(buf, "/relative_level", &args);
            }
            AnalysisEvent::ClockOffset { ms } => {
                let args = [self.checked(ms)];
                self.write_floats(buf, "/clock/offset_ms", &args);
            }
        }
    }

    fn write_floats(&self, buf: &mut Vec<u8>, suffix: &str, values: &[f32]) {
        const TAGS: &str = ",ffffffffffff";
        // Only events with 1..=12 float arguments come here.
        let tags = TAGS.get(..1 + values.len()).unwrap_or(TAGS);
        OscWriter::new(buf)
            .string(&[&self.prefix, suffix])
            .string(&[tags])
            .floats(values);
    }

    fn checked(&mut self, x: f32) -> f32 {
        if !x.is_finite() {
            self.replaced_non_finite += 1;
        }
        finite::scalar(x)
    }

    fn checked64(&mut self, x: f64) -> f32 {
        let y = finite::scalar64(x);
        if !(x as f32).is_finite() {
            self.replaced_non_finite += 1;
        }
        y
    }

    fn checked_pose(&mut self, p: glam::Vec3, q: glam::Quat) -> (glam::Vec3, glam::Quat) {
        checked_pose(&mut self.replaced_non_finite, p, q)
    }

    fn clamp_i32(&mut self, x: u32) -> i32 {
        i32::try_from(x).unwrap_or_else(|_| {
            self.clamped_values += 1;
            i32::MAX
        })
    }
}

/// Type tags of a position and a rotation.
const POSE_TAGS: &str = ",fffffff";

fn pose_args(p: glam::Vec3, q: glam::Quat) -> [f32; 7] {
    [p.x, p.y, p.z, q.x, q.y, q.z, q.w]
}

fn checked_pose(replaced: &mut u64, p: glam::Vec3, q: glam::Quat) -> (glam::Vec3, glam::Quat) {
    if !finite::is_finite_pose(p, q) {
        *replaced += 1;
    }
    (finite::vec3(p), finite::quat(q))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame::BoneSample;
    use glam::{Quat, Vec3};
    use rosc::decoder::decode_udp;
    use rosc::{OscBundle, OscMessage, OscPacket, OscType};
    use std::time::{Duration, UNIX_EPOCH};

    fn floats(values: &[f32]) -> Vec<OscType> {
        values.iter().map(|&v| OscType::Float(v)).collect()
    }

    /// The frame as the rosc-based encoder this one replaced built it.
    fn rosc_frame(prefix: &str, frame: &BodyFrame) -> Vec<u8> {
        let pose = |p: Vec3, q: Quat| {
            let (p, q) = (finite::vec3(p), finite::quat(q));
            floats(&[p.x, p.y, p.z, q.x, q.y, q.z, q.w])
        };
        let mut content = vec![
            OscMessage {
                addr: format!("{prefix}/frame"),
                args: vec![
                    OscType::Int((frame.frame_index & 0x7fff_ffff) as i32),
                    OscType::Float(finite::scalar64(frame.audio_time_s)),
                ],
            },
            OscMessage {
                addr: format!("{prefix}/root"),
                args: pose(frame.root_position, frame.root_rotation),
            },
        ];
        for b in &frame.bones {
            content.push(OscMessage {
                addr: format!("{prefix}/joint/{}", b.bone),
                args: pose(b.world_position, b.local_rotation),
            });
        }
        rosc::encoder::encode(&OscPacket::Bundle(OscBundle {
            timetag: osc_time(frame.timetag),
            content: content.into_iter().map(OscPacket::Message).collect(),
        }))
        .unwrap()
    }

    #[test]
    fn frames_are_byte_identical_to_the_rosc_encoding() {
        let mut f = frame();
        for prefix in ["/danced", "/a/b", "/"] {
            let mut enc = NativeEncoder::with_prefix(prefix).unwrap();
            let want = rosc_frame(enc.prefix(), &f);
            assert_eq!(enc.encode_frame(&f), &want[..], "prefix {prefix:?}");
        }
        f.frame_index = u64::MAX;
        f.audio_time_s = f64::INFINITY;
        f.root_rotation = Quat::from_xyzw(0.0, 0.0, 0.0, 0.0);
        f.bones[1].world_position.z = f32::NAN;
        f.bones.push(BoneSample {
            bone: "RightToes",
            ..f.bones[0]
        });
        let mut enc = NativeEncoder::default();
        let mut buf = vec![1, 2, 3];
        enc.write_frame(&f, &mut buf);
        assert_eq!(buf, rosc_frame("/danced", &f));
    }

    #[test]
    fn events_are_byte_identical_to_the_rosc_encoding() {
        let mut enc = NativeEncoder::default();
        let mut chroma = [0.25; 12];
        chroma[3] = f32::NAN;
        let cases = [
            (
                AnalysisEvent::Beat {
                    time_s: 3.0,
                    index_in_bar: 2,
                    beats_per_bar: u32::MAX,
                    tempo_bpm: 128.0,
                    bar_confidence: 0.75,
                },
                "/danced/beat",
                vec![
                    OscType::Int(2),
                    OscType::Int(i32::MAX),
                    OscType::Float(128.0),
                    OscType::Float(3.0),
                    OscType::Float(0.75),
                ],
            ),
            (
                AnalysisEvent::NextBeat {
                    time_s: 3.5,
                    in_s: 0.25,
                    index_in_bar: 3,
                    beats_per_bar: 4,
                    tempo_bpm: 120.0,
                },
                "/danced/beat/next",
                vec![
                    OscType::Int(3),
                    OscType::Int(4),
                    OscType::Float(120.0),
                    OscType::Float(3.5),
                    OscType::Float(0.25),
                ],
            ),
            (
                AnalysisEvent::Onset {
                    time_s: 1e300,
                    strength: 0.75,
                },
                "/danced/onset",
                floats(&[0.75, 0.0]),
            ),
            (
                AnalysisEvent::Chroma {
                    time_s: 0.0,
                    chroma,
                },
                "/danced/chroma",
                floats(&chroma.map(finite::scalar)),
            ),
        ];
        for (event, addr, args) in cases {
            let want = rosc::encoder::encode(&OscPacket::Message(OscMessage {
                addr: addr.into(),
                args,
            }))
            .unwrap();
            assert_eq!(enc.encode_event(&event), &want[..], "{event:?}");
        }
        assert_eq!(enc.clamped_values(), 1);
        assert_eq!(enc.replaced_non_finite(), 2);
    }

    pub(crate) fn frame() -> BodyFrame {
        let bone = |name, x: f32| BoneSample {
            bone: name,
            local_position: Vec3::new(0.0, x, 0.0),
            local_rotation: Quat::from_rotation_y(0.5),
            world_position: Vec3::new(x, 1.0, 0.25),
            world_rotation: Quat::from_rotation_x(0.25),
        };
        BodyFrame {
            frame_index: 42,
            audio_time_s: 12.5,
            timetag: UNIX_EPOCH + Duration::from_secs(1_700_000_000),
            root_position: Vec3::new(0.5, 0.0, -1.0),
            root_rotation: Quat::from_rotation_y(std::f32::consts::FRAC_PI_2),
            bones: vec![bone("Hips", 0.9), bone("LeftUpperArm", 0.3)],
        }
    }

    fn messages(packet: OscPacket) -> (rosc::OscTime, Vec<OscMessage>) {
        match packet {
            OscPacket::Bundle(b) => (
                b.timetag,
                b.content
                    .into_iter()
                    .map(|p| match p {
                        OscPacket::Message(m) => m,
                        OscPacket::Bundle(_) => panic!("nested bundle"),
                    })
                    .collect(),
            ),
            OscPacket::Message(_) => panic!("expected a bundle"),
        }
    }

    #[test]
    fn frame_round_trips_through_rosc_decoder() {
        let mut enc = NativeEncoder::default();
        let bytes = enc.encode_frame(&frame()).to_vec();
        let (rest, packet) = decode_udp(&bytes).unwrap();
        assert!(rest.is_empty());
        let (tag, msgs) = messages(packet);
        assert_eq!(tag.seconds, 1_700_000_000 + 2_208_988_800);
        assert_eq!(msgs.len(), 4);
        assert_eq!(msgs[0].addr, "/danced/frame");
        assert_eq!(msgs[0].args, vec![OscType::Int(42), OscType::Float(12.5)]);
        assert_eq!(msgs[1].addr, "/danced/root");
        let s = std::f32::consts::FRAC_1_SQRT_2;
        let want = [0.5, 0.0, -1.0, 0.0, s, 0.0, s];
        for (arg, w) in msgs[1].args.iter().zip(want) {
            assert!((arg.clone().float().unwrap() - w).abs() < 1e-6);
        }
        assert_eq!(msgs[2].addr, "/danced/joint/Hips");
        assert_eq!(msgs[3].addr, "/danced/joint/LeftUpperArm");
        let a: Vec<f32> = msgs[3]
            .args
            .iter()
            .map(|a| a.clone().float().unwrap())
            .collect();
        assert_eq!(&a[..3], &[0.3, 1.0, 0.25]);
        assert!(
            (a[4] - 0.25f32.sin()).abs() < 1e-6,
            "local rotation about Y: {a:?}"
        );
        assert!((a[6] - 0.25f32.cos()).abs() < 1e-6);
    }

    #[test]
    fn non_finite_values_are_replaced_and_counted() {
        let mut enc = NativeEncoder::with_prefix("/x/").unwrap();
        let mut f = frame();
        f.root_position.x = f32::NAN;
        f.bones[0].local_rotation = Quat::from_xyzw(f32::INFINITY, 0.0, 0.0, 1.0);
        f.audio_time_s = f64::NAN;
        let (_, packet) = decode_udp(enc.encode_frame(&f)).unwrap();
        let (_, msgs) = messages(packet);
        assert_eq!(msgs[0].addr, "/x/frame");
        assert_eq!(msgs[0].args[1], OscType::Float(0.0));
        assert_eq!(msgs[1].args[0], OscType::Float(0.0));
        assert_eq!(msgs[2].args[6], OscType::Float(1.0), "identity rotation");
        assert_eq!(enc.replaced_non_finite(), 3);
    }

    #[test]
    fn events_encode_with_documented_arguments() {
        let mut enc = NativeEncoder::default();
        let cases = [
            (
                AnalysisEvent::Beat {
                    time_s: 3.0,
                    index_in_bar: 2,
                    beats_per_bar: 4,
                    tempo_bpm: 128.0,
                    bar_confidence: 0.5,
                },
                "/danced/beat",
                vec![
                    OscType::Int(2),
                    OscType::Int(4),
                    OscType::Float(128.0),
                    OscType::Float(3.0),
                    OscType::Float(0.5),
                ],
            ),
            (
                AnalysisEvent::Onset {
                    time_s: 1.5,
                    strength: 0.75,
                },
                "/danced/onset",
                floats(&[0.75, 1.5]),
            ),
            (
                AnalysisEvent::Tempo {
                    bpm: 99.5,
                    confidence: f32::NAN,
                },
                "/danced/tempo",
                floats(&[99.5, 0.0]),
            ),
            (
                AnalysisEvent::Energy {
                    time_s: 0.0,
                    db: -12.0,
                },
                "/danced/energy",
                floats(&[-12.0]),
            ),
            (
                AnalysisEvent::RelativeLevel {
                    time_s: 0.0,
                    db: -9.5,
                },
                "/danced/relative_level",
                floats(&[-9.5]),
            ),
        ];
        for (event, addr, args) in cases {
            let (_, packet) = decode_udp(enc.encode_event(&event)).unwrap();
            assert_eq!(
                packet,
                OscPacket::Message(OscMessage {
                    addr: addr.into(),
                    args
                })
            );
        }
        let mut chroma = [0.0; 12];
        chroma[9] = 1.0;
        let (_, packet) = decode_udp(enc.encode_event(&AnalysisEvent::Chroma {
            time_s: 0.0,
            chroma,
        }))
        .unwrap();
        let OscPacket::Message(m) = packet else {
            panic!()
        };
        assert_eq!(m.addr, "/danced/chroma");
        assert_eq!(m.args.len(), 12);
        assert_eq!(m.args[9], OscType::Float(1.0));
    }
}
