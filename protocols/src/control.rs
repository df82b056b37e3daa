//! Live control changes and the OSC control-in parser that produces them.

use crate::address::normalise_prefix;
use crate::error::ProtocolError;
use rosc::{OscMessage, OscPacket, OscType};

/// The address prefix of control messages when none is configured.
pub const DEFAULT_CONTROL_PREFIX: &str = "/danced/control";

/// Deepest bundle nesting accepted; deeper packets are malformed (bounds the decoder's recursion).
pub const MAX_BUNDLE_DEPTH: usize = 8;

/// Largest "beats:N" / in-N-beats accepted, so a typo cannot park a pose minutes away.
pub const MAX_QUANTIZE_BEATS: u32 = 64;

/// Temperature range the model accepts; values outside are clamped.
pub const TEMPERATURE_RANGE: (f32, f32) = (0.0, 2.0);

/// Tempo hints outside this range (BPM) are rejected as nonsense.
pub const TEMPO_HINT_RANGE: (f32, f32) = (30.0, 300.0);

/// Largest single nudge of the followed clock, milliseconds either way.
pub const NUDGE_MS_MAX: f32 = 250.0;

/// Range a beat accent depth is clamped to.
pub const BEAT_ACCENT_RANGE: (f32, f32) = (0.0, 0.9);

/// Transition lengths into key poses, beats: above the lower bound (0 is no transition at
/// all), up to the upper one.
pub const TRANSITION_BEATS_RANGE: (f32, f32) = (0.0, MAX_QUANTIZE_BEATS as f32);

// These ranges are the only definition: the OSC parser, the MIDI map, the daemon's
// configuration and its control path all read them.

/// Whether `beats` is a usable transition length: finite, above the lower bound of
/// [`TRANSITION_BEATS_RANGE`] and at most its upper one.
pub fn valid_transition_beats(beats: f32) -> bool {
    beats.is_finite() && beats > TRANSITION_BEATS_RANGE.0 && beats <= TRANSITION_BEATS_RANGE.1
}

/// When a key pose should be reached.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Deserialize)]
#[serde(try_from = "String")]
pub enum Quantize {
    /// As soon as possible.
    Now,
    /// On the next beat.
    NextBeat,
    /// On the next downbeat.
    NextBar,
    /// N beats from now.
    InBeats(u32),
}

impl Quantize {
    /// Parses "now", "beat", "bar" or "beats:N" (1 ≤ N ≤ [`MAX_QUANTIZE_BEATS`]), case-insensitive.
    pub fn parse(s: &str) -> Option<Quantize> {
        let s = s.trim().to_ascii_lowercase();
        match s.as_str() {
            "now" => Some(Quantize::Now),
            "beat" => Some(Quantize::NextBeat),
            "bar" => Some(Quantize::NextBar),
            _ => {
                let n: u32 = s.strip_prefix("beats:")?.trim().parse().ok()?;
                Quantize::in_beats(i64::from(n))
            }
        }
    }

    /// `InBeats(n)` when 1 ≤ n ≤ [`MAX_QUANTIZE_BEATS`].
    pub fn in_beats(n: i64) -> Option<Quantize> {
        (1..=i64::from(MAX_QUANTIZE_BEATS))
            .contains(&n)
            .then_some(Quantize::InBeats(n as u32))
    }
}

impl TryFrom<String> for Quantize {
    type Error = String;

    fn try_from(s: String) -> Result<Self, Self::Error> {
        Quantize::parse(&s).ok_or_else(|| {
            format!("bad quantize {s:?}: expected \"now\", \"beat\", \"bar\" or \"beats:N\" (1..={MAX_QUANTIZE_BEATS})")
        })
    }
}

/// What `/style N` and a MIDI style target's values 0–4 name.
pub const STYLE_NUMBERS: [&str; 5] = ["auto", "cha-cha", "rumba", "tango", "waltz"];

/// What `/keypose/route N` and a MIDI key-route target's two halves name.
pub const KEY_ROUTE_NUMBERS: [&str; 2] = ["overlay", "network"];

/// A live control change from OSC or MIDI.
#[derive(Clone, Debug, PartialEq)]
pub enum ControlEvent {
    /// Sampling temperature of the dancer, in [0, 2].
    Temperature(f32),
    /// Depth of the dancer's beat accent (how much it slows into each beat), in [0, 0.9].
    BeatAccent(f32),
    /// Reach the named key pose at the given musical time.
    KeyPose {
        /// Pose name in the pose bank.
        name: String,
        /// When to reach it.
        quantize: Quantize,
    },
    /// Forget the pending or held key pose.
    ClearKeyPose,
    /// Length of transitions into key poses, in beats (> 0).
    TransitionBeats(f32),
    /// Seed of the dancer's style randomness.
    StyleSeed(u64),
    /// The dance style to dance, by name (`auto`, `cha-cha`, `rumba`, `tango`, `waltz`;
    /// lower-cased here, resolved and counted by the receiver), or a number: 0 = auto, 1–4 =
    /// those styles in that order.
    DanceStyle(String),
    /// Where key poses go, by name (`overlay`: shown over the dance; `network`: danced to by
    /// the network itself; lower-cased here, resolved and counted by the receiver), or a
    /// number: 0 = overlay, 1 = network.
    KeyPoseRoute(String),
    /// Freeze the dance.
    Pause,
    /// Unfreeze the dance.
    Resume,
    /// The tempo the music is known to have, BPM in [30, 300].
    TempoHint(f32),
    /// Dance another set of moves (a clip library the dancer holds): its name, or its number
    /// from 0 in the order they were given (as decimal digits); resolved and counted by the
    /// receiver.
    Moves {
        /// Name or number.
        choice: String,
        /// When the switch lands (on a beat, or a bar's first beat).
        quantize: Quantize,
    },
    /// A tap of tap tempo: the tap clock's beats are where the performer taps (the first tap
    /// of a run is a bar's first beat).
    Tap,
    /// The beat heard nearest now is the first of its bar (on whichever clock is followed).
    BeatOne,
    /// Move every beat of the followed clock later by this many milliseconds (earlier when
    /// negative), at most [`NUDGE_MS_MAX`] at a time.
    Nudge(f32),
    /// Follow another clock, by name (`audio`, `midi`, `link`, `tap`; lower-cased here,
    /// resolved and counted by the receiver).
    Clock(String),
}

/// Parses OSC control packets into [`ControlEvent`]s, counting what it could not use.
#[derive(Clone, Debug)]
pub struct ControlParser {
    prefix: String,
    accepted: u64,
    malformed: u64,
    unknown_address: u64,
    bad_arguments: u64,
}

impl Default for ControlParser {
    fn default() -> Self {
        Self {
            prefix: DEFAULT_CONTROL_PREFIX.to_string(),
            accepted: 0,
            malformed: 0,
            unknown_address: 0,
            bad_arguments: 0,
        }
    }
}

/// Why a message did not become an event.
enum Reject {
    UnknownAddress,
    BadArguments,
}

impl ControlParser {
    /// A parser for addresses under `prefix` (e.g. "/danced/control").
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

    /// Messages understood (a button release counts, though it yields no event).
    pub fn accepted(&self) -> u64 {
        self.accepted
    }

    /// Packets that are not valid OSC (or nest bundles deeper than [`MAX_BUNDLE_DEPTH`]).
    pub fn malformed(&self) -> u64 {
        self.malformed
    }

    /// Messages whose address is not one of ours.
    pub fn unknown_address(&self) -> u64 {
        self.unknown_address
    }

    /// Messages to one of our addresses with missing, mistyped or out-of-range arguments.
    pub fn bad_arguments(&self) -> u64 {
        self.bad_arguments
    }

    /// Everything it did not take: malformed packets, unknown addresses and bad arguments.
    pub fn ignored(&self) -> u64 {
        self.malformed + self.unknown_address + self.bad_arguments
    }

    /// Appends the events in one UDP datagram to `out`; returns how many were appended.
    pub fn parse(&mut self, packet: &[u8], out: &mut Vec<ControlEvent>) -> usize {
        let before = out.len();
        if !bundle_depth_ok(packet, MAX_BUNDLE_DEPTH) {
            self.malformed += 1;
            return 0;
        }
        match rosc::decoder::decode_udp(packet) {
            Ok((_, packet)) => self.packet(&packet, out),
            Err(_) => self.malformed += 1,
        }
        out.len() - before
    }

    fn packet(&mut self, packet: &OscPacket, out: &mut Vec<ControlEvent>) {
        match packet {
            OscPacket::Message(m) => match self.message(m, out) {
                Ok(()) => self.accepted += 1,
                Err(Reject::UnknownAddress) => self.unknown_address += 1,
                Err(Reject::BadArguments) => self.bad_arguments += 1,
            },
            // Timetags are ignored: control changes apply on arrival, quantised musically.
            OscPacket::Bundle(b) => {
                for p in &b.content {
                    self.packet(p, out);
                }
            }
        }
    }

    fn message(&self, m: &OscMessage, out: &mut Vec<ControlEvent>) -> Result<(), Reject> {
        let suffix = m
            .addr
            .strip_prefix(self.prefix.as_str())
            .ok_or(Reject::UnknownAddress)?;
        let args = &m.args;
        let event = match suffix {
            "/temperature" => {
                let t = one_float(args)?;
                ControlEvent::Temperature(t.clamp(TEMPERATURE_RANGE.0, TEMPERATURE_RANGE.1))
            }
            "/accent" => {
                let a = one_float(args)?;
                ControlEvent::BeatAccent(a.clamp(BEAT_ACCENT_RANGE.0, BEAT_ACCENT_RANGE.1))
            }
            "/keypose" => {
                let name = match args.first() {
                    Some(OscType::String(s)) if !s.trim().is_empty() => s.trim().to_string(),
                    _ => return Err(Reject::BadArguments),
                };
                let quantize = match args.get(1) {
                    None => Quantize::NextBeat,
                    Some(OscType::String(s)) => Quantize::parse(s).ok_or(Reject::BadArguments)?,
                    Some(a) => Quantize::in_beats(as_int(a)?).ok_or(Reject::BadArguments)?,
                };
                if args.len() > 2 {
                    return Err(Reject::BadArguments);
                }
                ControlEvent::KeyPose { name, quantize }
            }
            "/keypose/clear" | "/pause" | "/resume" | "/tap" | "/clock/one" => {
                // Buttons in TouchOSC and TouchDesigner send 1 on press and 0 on release;
                // only the press is the command.
                if args.first().is_some_and(is_zero) {
                    return Ok(());
                }
                match suffix {
                    "/pause" => ControlEvent::Pause,
                    "/resume" => ControlEvent::Resume,
                    "/tap" => ControlEvent::Tap,
                    "/clock/one" => ControlEvent::BeatOne,
                    _ => ControlEvent::ClearKeyPose,
                }
            }
            "/clock/nudge" => {
                let ms = one_float(args)?;
                if !ms.is_finite() || ms.abs() > NUDGE_MS_MAX {
                    return Err(Reject::BadArguments);
                }
                ControlEvent::Nudge(ms)
            }
            "/clock" => match args.as_slice() {
                [OscType::String(s)] if !s.trim().is_empty() => {
                    ControlEvent::Clock(s.trim().to_ascii_lowercase())
                }
                _ => return Err(Reject::BadArguments),
            },
            "/style" => ControlEvent::DanceStyle(name_or_number(args, &STYLE_NUMBERS)?),
            "/moves" => {
                let choice = match args.first() {
                    Some(OscType::String(s)) if !s.trim().is_empty() => s.trim().to_string(),
                    Some(a) => {
                        let n = as_int(a)?;
                        if n < 0 {
                            return Err(Reject::BadArguments);
                        }
                        n.to_string()
                    }
                    None => return Err(Reject::BadArguments),
                };
                let quantize = match args.get(1) {
                    None => Quantize::NextBar,
                    Some(OscType::String(s)) => match Quantize::parse(s) {
                        Some(q @ (Quantize::NextBeat | Quantize::NextBar)) => q,
                        _ => return Err(Reject::BadArguments),
                    },
                    Some(_) => return Err(Reject::BadArguments),
                };
                if args.len() > 2 {
                    return Err(Reject::BadArguments);
                }
                ControlEvent::Moves { choice, quantize }
            }
            "/keypose/route" => {
                ControlEvent::KeyPoseRoute(name_or_number(args, &KEY_ROUTE_NUMBERS)?)
            }
            "/transition" => {
                let beats = one_float(args)?;
                if !valid_transition_beats(beats) {
                    return Err(Reject::BadArguments);
                }
                ControlEvent::TransitionBeats(beats)
            }
            "/seed" => {
                let [arg] = args.as_slice() else {
                    return Err(Reject::BadArguments);
                };
                ControlEvent::StyleSeed(as_seed(arg)?)
            }
            "/tempo" => {
                let bpm = one_float(args)?;
                if !(TEMPO_HINT_RANGE.0..=TEMPO_HINT_RANGE.1).contains(&bpm) {
                    return Err(Reject::BadArguments);
                }
                ControlEvent::TempoHint(bpm)
            }
            _ => return Err(Reject::UnknownAddress),
        };
        out.push(event);
        Ok(())
    }
}

/// The single argument as a name (trimmed, lower-cased; resolved by the receiver) or a number
/// N naming `numbers[N]`.
fn name_or_number(args: &[OscType], numbers: &[&str]) -> Result<String, Reject> {
    match args {
        [OscType::String(s)] if !s.trim().is_empty() => Ok(s.trim().to_lowercase()),
        [a] => usize::try_from(as_int(a)?)
            .ok()
            .and_then(|n| numbers.get(n))
            .map(|name| name.to_string())
            .ok_or(Reject::BadArguments),
        _ => Err(Reject::BadArguments),
    }
}

/// The single argument as a finite float (ints and doubles accepted).
fn one_float(args: &[OscType]) -> Result<f32, Reject> {
    let [arg] = args else {
        return Err(Reject::BadArguments);
    };
    let x = match *arg {
        OscType::Float(f) => f,
        OscType::Double(d) => d as f32,
        OscType::Int(i) => i as f32,
        OscType::Long(l) => l as f32,
        _ => return Err(Reject::BadArguments),
    };
    if x.is_finite() {
        Ok(x)
    } else {
        Err(Reject::BadArguments)
    }
}

/// An integer argument; floats only when they hold a whole number.
fn as_int(arg: &OscType) -> Result<i64, Reject> {
    let whole = |x: f64| {
        if x.is_finite() && x.fract() == 0.0 && x.abs() < 9.0e15 {
            Ok(x as i64)
        } else {
            Err(Reject::BadArguments)
        }
    };
    match *arg {
        OscType::Int(i) => Ok(i64::from(i)),
        OscType::Long(l) => Ok(l),
        OscType::Float(f) => whole(f64::from(f)),
        OscType::Double(d) => whole(d),
        _ => Err(Reject::BadArguments),
    }
}

/// A seed: 32- and 64-bit ints keep their bits (so any random int works), floats must be whole
/// and non-negative.
fn as_seed(arg: &OscType) -> Result<u64, Reject> {
    match *arg {
        OscType::Int(i) => Ok(u64::from(i as u32)),
        OscType::Long(l) => Ok(l as u64),
        _ => u64::try_from(as_int(arg)?).map_err(|_| Reject::BadArguments),
    }
}

fn is_zero(arg: &OscType) -> bool {
    match *arg {
        OscType::Int(i) => i == 0,
        OscType::Long(l) => l == 0,
        OscType::Float(f) => f == 0.0,
        OscType::Double(d) => d == 0.0,
        OscType::Bool(b) => !b,
        _ => false,
    }
}

/// Whether bundles in `packet` nest at most `max_depth` deep; walks sizes only, no decoding, so
/// a hostile packet cannot drive rosc's recursive decoder into a stack overflow.
fn bundle_depth_ok(packet: &[u8], max_depth: usize) -> bool {
    const TAG: &[u8] = b"#bundle\0";
    if !packet.starts_with(TAG) {
        return true;
    }
    if max_depth == 0 {
        return false;
    }
    let mut rest = packet.get(16..).unwrap_or(&[]);
    while rest.len() >= 4 {
        let size = i32::from_be_bytes([rest[0], rest[1], rest[2], rest[3]]);
        let Ok(size) = usize::try_from(size) else {
            return true; // The decoder rejects it; depth is not the problem.
        };
        let Some(element) = rest.get(4..4 + size) else {
            return true;
        };
        if !bundle_depth_ok(element, max_depth - 1) {
            return false;
        }
        rest = &rest[4 + size..];
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use rosc::{OscBundle, OscTime};

    fn msg(addr: &str, args: Vec<OscType>) -> Vec<u8> {
        rosc::encoder::encode(&OscPacket::Message(OscMessage {
            addr: addr.into(),
            args,
        }))
        .unwrap()
    }

    fn parse_one(p: &mut ControlParser, bytes: &[u8]) -> Vec<ControlEvent> {
        let mut out = Vec::new();
        p.parse(bytes, &mut out);
        out
    }

    fn s(x: &str) -> OscType {
        OscType::String(x.into())
    }

    #[test]
    fn parses_every_address() {
        let mut p = ControlParser::default();
        let cases: Vec<(Vec<u8>, ControlEvent)> = vec![
            (
                msg("/danced/control/temperature", vec![OscType::Float(0.7)]),
                ControlEvent::Temperature(0.7),
            ),
            (
                msg("/danced/control/temperature", vec![OscType::Float(5.0)]),
                ControlEvent::Temperature(2.0),
            ),
            (
                msg("/danced/control/temperature", vec![OscType::Int(-1)]),
                ControlEvent::Temperature(0.0),
            ),
            (
                msg("/danced/control/temperature", vec![OscType::Double(1.25)]),
                ControlEvent::Temperature(1.25),
            ),
            (
                msg("/danced/control/accent", vec![OscType::Float(0.3)]),
                ControlEvent::BeatAccent(0.3),
            ),
            (
                msg("/danced/control/accent", vec![OscType::Int(4)]),
                ControlEvent::BeatAccent(0.9),
            ),
            (
                msg("/danced/control/accent", vec![OscType::Float(-1.0)]),
                ControlEvent::BeatAccent(0.0),
            ),
            (
                msg("/danced/control/keypose", vec![s("arms-up")]),
                ControlEvent::KeyPose {
                    name: "arms-up".into(),
                    quantize: Quantize::NextBeat,
                },
            ),
            (
                msg("/danced/control/keypose", vec![s("a"), s("now")]),
                ControlEvent::KeyPose {
                    name: "a".into(),
                    quantize: Quantize::Now,
                },
            ),
            (
                msg("/danced/control/keypose", vec![s("a"), s("BAR")]),
                ControlEvent::KeyPose {
                    name: "a".into(),
                    quantize: Quantize::NextBar,
                },
            ),
            (
                msg("/danced/control/keypose", vec![s("a"), s("beats:3")]),
                ControlEvent::KeyPose {
                    name: "a".into(),
                    quantize: Quantize::InBeats(3),
                },
            ),
            (
                msg("/danced/control/keypose", vec![s("a"), OscType::Int(8)]),
                ControlEvent::KeyPose {
                    name: "a".into(),
                    quantize: Quantize::InBeats(8),
                },
            ),
            (
                msg("/danced/control/keypose", vec![s("a"), OscType::Float(2.0)]),
                ControlEvent::KeyPose {
                    name: "a".into(),
                    quantize: Quantize::InBeats(2),
                },
            ),
            (
                msg("/danced/control/keypose/clear", vec![]),
                ControlEvent::ClearKeyPose,
            ),
            (
                msg("/danced/control/transition", vec![OscType::Float(1.5)]),
                ControlEvent::TransitionBeats(1.5),
            ),
            (
                msg("/danced/control/transition", vec![OscType::Int(2)]),
                ControlEvent::TransitionBeats(2.0),
            ),
            (
                msg(
                    "/danced/control/style",
                    vec![OscType::String(" Cha-Cha ".into())],
                ),
                ControlEvent::DanceStyle("cha-cha".into()),
            ),
            (
                msg("/danced/control/style", vec![OscType::Int(4)]),
                ControlEvent::DanceStyle("waltz".into()),
            ),
            (
                msg("/danced/control/style", vec![OscType::Float(0.0)]),
                ControlEvent::DanceStyle("auto".into()),
            ),
            (
                msg("/danced/control/keypose/route", vec![s(" Network ")]),
                ControlEvent::KeyPoseRoute("network".into()),
            ),
            (
                msg("/danced/control/keypose/route", vec![OscType::Int(0)]),
                ControlEvent::KeyPoseRoute("overlay".into()),
            ),
            (
                msg("/danced/control/keypose/route", vec![OscType::Float(1.0)]),
                ControlEvent::KeyPoseRoute("network".into()),
            ),
            (
                msg("/danced/control/seed", vec![OscType::Int(1234)]),
                ControlEvent::StyleSeed(1234),
            ),
            (
                msg("/danced/control/seed", vec![OscType::Int(-1)]),
                ControlEvent::StyleSeed(0xffff_ffff),
            ),
            (
                msg("/danced/control/seed", vec![OscType::Long(1 << 40)]),
                ControlEvent::StyleSeed(1 << 40),
            ),
            (
                msg("/danced/control/seed", vec![OscType::Float(7.0)]),
                ControlEvent::StyleSeed(7),
            ),
            (msg("/danced/control/pause", vec![]), ControlEvent::Pause),
            (
                msg("/danced/control/pause", vec![OscType::Float(1.0)]),
                ControlEvent::Pause,
            ),
            (
                msg("/danced/control/resume", vec![OscType::Int(1)]),
                ControlEvent::Resume,
            ),
            (
                msg("/danced/control/tempo", vec![OscType::Float(128.0)]),
                ControlEvent::TempoHint(128.0),
            ),
            (
                msg("/danced/control/tempo", vec![OscType::Int(90)]),
                ControlEvent::TempoHint(90.0),
            ),
            (
                msg("/danced/control/moves", vec![s(" Salsa ")]),
                ControlEvent::Moves {
                    choice: "Salsa".into(),
                    quantize: Quantize::NextBar,
                },
            ),
            (
                msg("/danced/control/moves", vec![OscType::Int(2), s("beat")]),
                ControlEvent::Moves {
                    choice: "2".into(),
                    quantize: Quantize::NextBeat,
                },
            ),
            (msg("/danced/control/tap", vec![]), ControlEvent::Tap),
            (
                msg("/danced/control/tap", vec![OscType::Float(1.0)]),
                ControlEvent::Tap,
            ),
            (
                msg("/danced/control/clock/one", vec![]),
                ControlEvent::BeatOne,
            ),
            (
                msg("/danced/control/clock/nudge", vec![OscType::Float(-12.5)]),
                ControlEvent::Nudge(-12.5),
            ),
            (
                msg("/danced/control/clock/nudge", vec![OscType::Int(10)]),
                ControlEvent::Nudge(10.0),
            ),
            (
                msg("/danced/control/clock", vec![s(" MIDI ")]),
                ControlEvent::Clock("midi".into()),
            ),
        ];
        let n = cases.len() as u64;
        for (bytes, want) in cases {
            assert_eq!(parse_one(&mut p, &bytes), vec![want.clone()], "{want:?}");
        }
        assert_eq!(p.accepted(), n);
        assert_eq!(
            (p.malformed(), p.unknown_address(), p.bad_arguments()),
            (0, 0, 0)
        );
    }

    #[test]
    fn button_release_is_accepted_without_an_event() {
        let mut p = ControlParser::default();
        assert!(
            parse_one(
                &mut p,
                &msg("/danced/control/pause", vec![OscType::Float(0.0)])
            )
            .is_empty()
        );
        assert!(
            parse_one(
                &mut p,
                &msg("/danced/control/keypose/clear", vec![OscType::Int(0)])
            )
            .is_empty()
        );
        assert_eq!(p.accepted(), 2);
    }

    #[test]
    fn counts_bad_arguments_unknown_addresses_and_garbage() {
        let mut p = ControlParser::default();
        let bad = [
            msg(
                "/danced/control/temperature",
                vec![OscType::Float(f32::NAN)],
            ),
            msg(
                "/danced/control/temperature",
                vec![OscType::Float(f32::INFINITY)],
            ),
            msg("/danced/control/temperature", vec![]),
            msg("/danced/control/temperature", vec![s("hot")]),
            msg(
                "/danced/control/temperature",
                vec![OscType::Float(1.0), OscType::Float(1.0)],
            ),
            msg("/danced/control/keypose", vec![]),
            msg("/danced/control/keypose", vec![s("  ")]),
            msg("/danced/control/keypose", vec![s("a"), s("soon")]),
            msg("/danced/control/keypose", vec![s("a"), s("beats:0")]),
            msg("/danced/control/keypose", vec![s("a"), OscType::Int(1000)]),
            msg("/danced/control/keypose", vec![s("a"), OscType::Float(1.5)]),
            msg("/danced/control/keypose", vec![s("a"), s("bar"), s("x")]),
            msg("/danced/control/transition", vec![OscType::Float(0.0)]),
            msg("/danced/control/transition", vec![OscType::Float(-1.0)]),
            msg("/danced/control/style", vec![]),
            msg("/danced/control/style", vec![OscType::Int(5)]),
            msg("/danced/control/moves", vec![]),
            msg("/danced/control/moves", vec![OscType::Int(-1)]),
            msg("/danced/control/moves", vec![s("a"), s("now")]),
            msg("/danced/control/moves", vec![s("a"), s("bar"), s("x")]),
            msg("/danced/control/style", vec![s(" ")]),
            msg("/danced/control/keypose/route", vec![]),
            msg("/danced/control/keypose/route", vec![OscType::Int(2)]),
            msg("/danced/control/keypose/route", vec![s("")]),
            msg("/danced/control/seed", vec![OscType::Float(-3.0)]),
            msg("/danced/control/seed", vec![OscType::Float(0.5)]),
            msg("/danced/control/tempo", vec![OscType::Float(20.0)]),
            msg("/danced/control/tempo", vec![OscType::Float(400.0)]),
            msg("/danced/control/clock/nudge", vec![OscType::Float(300.0)]),
            msg("/danced/control/clock/nudge", vec![]),
            msg("/danced/control/clock", vec![s(" ")]),
            msg("/danced/control/clock", vec![OscType::Int(1)]),
        ];
        for b in &bad {
            assert!(parse_one(&mut p, b).is_empty());
        }
        assert_eq!(p.bad_arguments(), bad.len() as u64);
        parse_one(&mut p, &msg("/danced/control/dance", vec![]));
        parse_one(
            &mut p,
            &msg("/other/temperature", vec![OscType::Float(1.0)]),
        );
        parse_one(
            &mut p,
            &msg("/danced/controltemperature", vec![OscType::Float(1.0)]),
        );
        assert_eq!(p.unknown_address(), 3);
        parse_one(&mut p, b"not osc at all");
        parse_one(&mut p, &[]);
        assert_eq!(p.malformed(), 2);
        assert_eq!(p.accepted(), 0);
    }

    #[test]
    fn nested_bundles_are_walked_and_custom_prefix_works() {
        let mut p = ControlParser::with_prefix("/dj/").unwrap();
        let m = |addr: &str, args| {
            OscPacket::Message(OscMessage {
                addr: addr.into(),
                args,
            })
        };
        let inner = OscPacket::Bundle(OscBundle {
            timetag: OscTime::from((0, 1)),
            content: vec![m("/dj/pause", vec![]), m("/dj/nope", vec![])],
        });
        let outer = OscPacket::Bundle(OscBundle {
            timetag: OscTime::from((0, 1)),
            content: vec![m("/dj/seed", vec![OscType::Int(5)]), inner],
        });
        let bytes = rosc::encoder::encode(&outer).unwrap();
        let mut out = Vec::new();
        assert_eq!(p.parse(&bytes, &mut out), 2);
        assert_eq!(out, vec![ControlEvent::StyleSeed(5), ControlEvent::Pause]);
        assert_eq!((p.accepted(), p.unknown_address()), (2, 1));
    }

    #[test]
    fn bundles_nested_too_deep_are_malformed_not_a_stack_overflow() {
        let mut packet = msg("/danced/control/pause", vec![]);
        for _ in 0..(MAX_BUNDLE_DEPTH + 1) {
            let mut b = b"#bundle\0\0\0\0\0\0\0\0\x01".to_vec();
            b.extend((packet.len() as i32).to_be_bytes());
            b.extend(&packet);
            packet = b;
        }
        let mut p = ControlParser::default();
        assert!(parse_one(&mut p, &packet).is_empty());
        assert_eq!(p.malformed(), 1);
        // Deep nesting in a huge datagram would blow rosc's stack without the guard.
        let mut deep = Vec::new();
        for i in 0..4000usize {
            deep.extend(b"#bundle\0\0\0\0\0\0\0\0\x01");
            deep.extend(((4000 - i - 1) as i32 * 20).to_be_bytes());
        }
        assert!(parse_one(&mut p, &deep).is_empty());
        assert_eq!(p.malformed(), 2);
    }

    #[test]
    fn quantize_deserialises_from_strings() {
        #[derive(serde::Deserialize)]
        struct T {
            q: Quantize,
        }
        let t: T = toml::from_str("q = \"beats:4\"").unwrap();
        assert_eq!(t.q, Quantize::InBeats(4));
        let e = toml::from_str::<T>("q = \"later\"")
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("bad quantize"), "{e}");
    }

    proptest! {
        #[test]
        fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..512)) {
            let mut p = ControlParser::default();
            let mut out = Vec::new();
            p.parse(&bytes, &mut out);
            for e in out {
                let finite = match e {
                    ControlEvent::Temperature(x) | ControlEvent::TransitionBeats(x) | ControlEvent::TempoHint(x) => x.is_finite(),
                    _ => true,
                };
                prop_assert!(finite);
            }
        }

        #[test]
        fn any_arguments_at_our_addresses_are_counted_once_and_never_nan(
            suffix in prop::sample::select(vec![
                "/temperature", "/keypose", "/keypose/clear", "/transition", "/seed", "/pause",
                "/resume", "/tempo", "/tap", "/clock", "/clock/one", "/clock/nudge", "/nope",
            ]),
            args in prop::collection::vec(prop_oneof![
                any::<i32>().prop_map(OscType::Int),
                any::<f32>().prop_map(OscType::Float),
                any::<f64>().prop_map(OscType::Double),
                any::<i64>().prop_map(OscType::Long),
                "[a-z:0-9 ]{0,10}".prop_map(OscType::String),
                any::<bool>().prop_map(OscType::Bool),
            ], 0..4),
        ) {
            let mut p = ControlParser::default();
            let mut out = Vec::new();
            p.parse(&msg(&format!("/danced/control{suffix}"), args), &mut out);
            prop_assert_eq!(p.accepted() + p.unknown_address() + p.bad_arguments(), 1);
            prop_assert!(out.len() <= 1);
            for e in out {
                match e {
                    ControlEvent::Temperature(x) => prop_assert!((0.0..=2.0).contains(&x)),
                    ControlEvent::TransitionBeats(x) => prop_assert!(x.is_finite() && x > 0.0),
                    ControlEvent::TempoHint(x) => prop_assert!((30.0..=300.0).contains(&x)),
                    ControlEvent::Nudge(x) => prop_assert!(x.is_finite() && x.abs() <= NUDGE_MS_MAX),
                    ControlEvent::KeyPose { name, quantize } => {
                        prop_assert!(!name.trim().is_empty());
                        if let Quantize::InBeats(n) = quantize {
                            prop_assert!((1..=MAX_QUANTIZE_BEATS).contains(&n));
                        }
                    }
                    _ => {}
                }
            }
        }

        #[test]
        fn temperature_of_any_float_is_finite_and_in_range(x in any::<f32>()) {
            let mut p = ControlParser::default();
            let mut out = Vec::new();
            p.parse(&msg("/danced/control/temperature", vec![OscType::Float(x)]), &mut out);
            for e in out {
                let ControlEvent::Temperature(t) = e else { panic!() };
                prop_assert!((0.0..=2.0).contains(&t));
            }
        }
    }
}
