//! What MIDI input means to the dancer, loaded from a TOML file (format in the crate README).

use crate::control::{
    BEAT_ACCENT_RANGE, ControlEvent, KEY_ROUTE_NUMBERS, NUDGE_MS_MAX, Quantize, STYLE_NUMBERS,
    TEMPERATURE_RANGE, TEMPO_HINT_RANGE,
};
use crate::error::ProtocolError;
use crate::midi::{MidiMessage, MidiParser};
use crate::midi_clock::{MidiClockFollower, TICKS_PER_BEAT};
use crate::midi_input::MidiPacket;
use serde::Deserialize;
use std::path::Path;
use std::time::Instant;

/// A tempo hint is re-sent only when the clock's tempo moved at least this much (BPM).
const TEMPO_HINT_STEP: f32 = 0.1;

/// What a controller (CC) sets.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum CcTarget {
    /// Dancer temperature.
    Temperature,
    /// Transition length in beats.
    Transition,
    /// Depth of the beat accent.
    Accent,
    /// Dance style: the controller's travel in five equal zones, auto, cha-cha, rumba, tango,
    /// waltz (`min` and `max` are not used).
    Style,
    /// Where key poses go: the controller's lower half the overlay, its upper half the
    /// network (a toggle sending 0 / 127 switches them; `min` and `max` are not used).
    #[serde(rename = "key_route")]
    KeyRoute,
}

/// One note → key pose rule as written in the file.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NoteRule {
    /// MIDI note number 0..=127 (60 is middle C).
    pub note: u8,
    /// Key pose name in the pose bank.
    pub pose: String,
    /// When the pose is reached; the map's `default_quantize` when absent.
    pub quantize: Option<Quantize>,
    /// Channel 1..=16 this rule listens to; the map's `channel` when absent.
    pub channel: Option<u8>,
}

/// One note → set of moves rule as written in the file (`[[moves]]`).
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MovesRule {
    /// MIDI note number 0..=127.
    pub note: u8,
    /// The set of moves' name, or its number from 0 (as text).
    pub moves: String,
    /// When the switch lands: `beat` or `bar` (the default).
    pub quantize: Option<Quantize>,
    /// Channel 1..=16 this rule listens to; the map's `channel` when absent.
    pub channel: Option<u8>,
}

/// What a note does to the followed clock.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ClockAction {
    /// A tap of tap tempo.
    Tap,
    /// The beat heard nearest now is the first of its bar.
    One,
    /// Every beat `ms` earlier.
    Earlier,
    /// Every beat `ms` later.
    Later,
}

/// One note → clock rule as written in the file (`[[clock]]`).
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ClockRule {
    /// MIDI note number 0..=127.
    pub note: u8,
    /// What the note does.
    pub action: ClockAction,
    /// The nudge of `earlier` and `later`, milliseconds (10 when absent).
    #[serde(default = "default_nudge_ms")]
    pub ms: f32,
    /// Channel 1..=16 this rule listens to; the map's `channel` when absent.
    pub channel: Option<u8>,
}

fn default_nudge_ms() -> f32 {
    10.0
}

/// One controller → parameter rule as written in the file.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CcRule {
    /// Controller number 0..=127.
    pub controller: u8,
    /// The parameter it sets.
    pub target: CcTarget,
    /// Value at controller value 0 (0 when absent, as a `style` rule leaves it).
    #[serde(default)]
    pub min: f32,
    /// Value at controller value 127 (may be below `min` to invert the knob; 0 when absent).
    #[serde(default)]
    pub max: f32,
    /// Channel 1..=16 this rule listens to; the map's `channel` when absent.
    pub channel: Option<u8>,
}

/// The file's contents, before validation.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MidiMapConfig {
    /// Only this channel (1..=16) is listened to, unless a rule names its own; all when absent.
    pub channel: Option<u8>,
    /// Quantize of notes that do not name one.
    #[serde(default = "default_quantize")]
    pub default_quantize: Quantize,
    /// Releasing the note that set the current key pose clears it (hold-to-pose pads).
    #[serde(default)]
    pub release_clears: bool,
    /// Program change N sets style seed N.
    #[serde(default)]
    pub program_change_seed: bool,
    /// MIDI clock sets the tempo hint.
    #[serde(default)]
    pub clock_tempo: bool,
    /// Start/Continue resume the dance, Stop pauses it.
    #[serde(default)]
    pub transport: bool,
    /// Note rules.
    #[serde(default, rename = "note")]
    pub notes: Vec<NoteRule>,
    /// Note → set of moves rules.
    #[serde(default)]
    pub moves: Vec<MovesRule>,
    /// Controller rules.
    #[serde(default, rename = "cc")]
    pub ccs: Vec<CcRule>,
    /// Note → clock rules (tap tempo, beat one, nudges).
    #[serde(default)]
    pub clock: Vec<ClockRule>,
}

fn default_quantize() -> Quantize {
    Quantize::NextBeat
}

/// Turns MIDI messages into control events according to a loaded map.
#[derive(Clone, Debug)]
pub struct MidiMap {
    config: MidiMapConfig,
    clock: MidiClockFollower,
    ticks_since_hint: usize,
    last_hint: Option<f32>,
    /// (channel, note) of the note that set the current key pose.
    held: Option<(u8, u8)>,
    epoch: Instant,
}

impl MidiMap {
    /// A map from TOML text.
    pub fn from_toml_str(text: &str) -> Result<Self, ProtocolError> {
        let config: MidiMapConfig = toml::from_str(text)?;
        Self::from_config(config)
    }

    /// A map from a TOML file.
    pub fn load(path: &Path) -> Result<Self, ProtocolError> {
        let text = std::fs::read_to_string(path).map_err(|source| ProtocolError::MapRead {
            path: path.to_path_buf(),
            source,
        })?;
        Self::from_toml_str(&text)
    }

    /// A map from an already parsed config, validated.
    pub fn from_config(config: MidiMapConfig) -> Result<Self, ProtocolError> {
        validate(&config).map_err(ProtocolError::MapInvalid)?;
        Ok(Self {
            config,
            clock: MidiClockFollower::new(),
            ticks_since_hint: 0,
            last_hint: None,
            held: None,
            epoch: Instant::now(),
        })
    }

    /// The incoming MIDI clock, followed on the timestamps the messages came with.
    pub fn clock(&self) -> &MidiClockFollower {
        &self.clock
    }

    /// The validated rules.
    pub fn config(&self) -> &MidiMapConfig {
        &self.config
    }

    /// Maps a message received now; MIDI clock is timed by this process's clock. Prefer
    /// [`MidiMap::map_at`] with the driver's timestamp, which does not include scheduling delay.
    pub fn map(&mut self, message: &MidiMessage, out: &mut Vec<ControlEvent>) {
        let now_us = self.epoch.elapsed().as_micros() as u64;
        self.map_at(now_us, message, out);
    }

    /// Maps a message received at `timestamp_us` (any monotonic µs clock), appending its events.
    pub fn map_at(
        &mut self,
        timestamp_us: u64,
        message: &MidiMessage,
        out: &mut Vec<ControlEvent>,
    ) {
        match *message {
            MidiMessage::NoteOn {
                channel,
                note,
                velocity: _,
            } => {
                if let Some(rule) =
                    self.config.clock.iter().find(|r| {
                        r.note == note && listens(r.channel, self.config.channel, channel)
                    })
                {
                    out.push(match rule.action {
                        ClockAction::Tap => ControlEvent::Tap,
                        ClockAction::One => ControlEvent::BeatOne,
                        ClockAction::Earlier => ControlEvent::Nudge(-rule.ms),
                        ClockAction::Later => ControlEvent::Nudge(rule.ms),
                    });
                } else if let Some(rule) = self.note_rule(channel, note) {
                    out.push(ControlEvent::KeyPose {
                        name: rule.pose.clone(),
                        quantize: rule.quantize.unwrap_or(self.config.default_quantize),
                    });
                    self.held = Some((channel, note));
                } else if let Some(rule) =
                    self.config.moves.iter().find(|r| {
                        r.note == note && listens(r.channel, self.config.channel, channel)
                    })
                {
                    out.push(ControlEvent::Moves {
                        choice: rule.moves.trim().to_string(),
                        quantize: rule.quantize.unwrap_or(Quantize::NextBar),
                    });
                }
            }
            MidiMessage::NoteOff { channel, note, .. }
                if self.config.release_clears && self.held == Some((channel, note)) =>
            {
                out.push(ControlEvent::ClearKeyPose);
                self.held = None;
            }
            MidiMessage::ControlChange {
                channel,
                controller,
                value,
            } => {
                let rule = self.config.ccs.iter().find(|r| {
                    r.controller == controller && listens(r.channel, self.config.channel, channel)
                });
                if let Some(rule) = rule {
                    let x = rule.min + (rule.max - rule.min) * f32::from(value.min(127)) / 127.0;
                    out.push(match rule.target {
                        CcTarget::Temperature => ControlEvent::Temperature(
                            x.clamp(TEMPERATURE_RANGE.0, TEMPERATURE_RANGE.1),
                        ),
                        CcTarget::Transition => ControlEvent::TransitionBeats(x),
                        CcTarget::Accent => ControlEvent::BeatAccent(
                            x.clamp(BEAT_ACCENT_RANGE.0, BEAT_ACCENT_RANGE.1),
                        ),
                        CcTarget::Style => {
                            let zone = usize::from(value.min(127)) * STYLE_NUMBERS.len() / 128;
                            ControlEvent::DanceStyle(STYLE_NUMBERS[zone].to_string())
                        }
                        CcTarget::KeyRoute => ControlEvent::KeyPoseRoute(
                            KEY_ROUTE_NUMBERS[usize::from(value.min(127) >= 64)].to_string(),
                        ),
                    });
                }
            }
            MidiMessage::ProgramChange { channel, program }
                if self.config.program_change_seed
                    && listens(None, self.config.channel, channel) =>
            {
                out.push(ControlEvent::StyleSeed(u64::from(program)));
            }
            MidiMessage::Clock => self.clock_tick(timestamp_us, out),
            MidiMessage::SongPosition(_) => {
                self.clock.message(timestamp_us, message);
            }
            MidiMessage::Start | MidiMessage::Continue | MidiMessage::Stop => {
                self.clock.message(timestamp_us, message);
                self.ticks_since_hint = 0;
                if self.config.transport {
                    out.push(if *message == MidiMessage::Stop {
                        ControlEvent::Pause
                    } else {
                        ControlEvent::Resume
                    });
                }
            }
            _ => {}
        }
    }

    /// Maps a packet from [`crate::MidiInputs::connect`] through `parser` (which keeps running
    /// status between packets), appending its events; allocates nothing beyond `out`.
    pub fn map_packet(
        &mut self,
        parser: &mut MidiParser,
        packet: &MidiPacket,
        out: &mut Vec<ControlEvent>,
    ) {
        let (timestamp_us, bytes, len) = *packet;
        for &b in &bytes[..usize::from(len).min(3)] {
            if let Some(message) = parser.push(b) {
                self.map_at(timestamp_us, &message, out);
            }
        }
    }

    fn note_rule(&self, channel: u8, note: u8) -> Option<&NoteRule> {
        self.config
            .notes
            .iter()
            .find(|r| r.note == note && listens(r.channel, self.config.channel, channel))
    }

    fn clock_tick(&mut self, timestamp_us: u64, out: &mut Vec<ControlEvent>) {
        self.clock.message(timestamp_us, &MidiMessage::Clock);
        if !self.config.clock_tempo {
            return;
        }
        let bpm = self.clock.tempo_bpm(timestamp_us).map(|b| b as f32);
        self.ticks_since_hint += 1;
        // At most one hint a beat: the clock's 24 ticks a beat would flood the dancer.
        if self.ticks_since_hint < TICKS_PER_BEAT {
            return;
        }
        let Some(bpm) = bpm else { return };
        self.ticks_since_hint = 0;
        let in_range = (TEMPO_HINT_RANGE.0..=TEMPO_HINT_RANGE.1).contains(&bpm);
        let moved = self
            .last_hint
            .is_none_or(|last| (bpm - last).abs() >= TEMPO_HINT_STEP);
        if in_range && moved {
            out.push(ControlEvent::TempoHint(bpm));
            self.last_hint = Some(bpm);
        }
    }
}

/// Whether a rule (own channel, else the map's) listens to wire channel `channel` (0-based).
fn listens(rule_channel: Option<u8>, map_channel: Option<u8>, channel: u8) -> bool {
    rule_channel
        .or(map_channel)
        .is_none_or(|c| c == channel + 1)
}

fn validate(c: &MidiMapConfig) -> Result<(), String> {
    let channel_ok = |ch: Option<u8>, what: &str| match ch {
        Some(ch) if !(1..=16).contains(&ch) => {
            Err(format!("{what}: channel {ch} is not in 1..=16"))
        }
        _ => Ok(()),
    };
    channel_ok(c.channel, "map")?;
    // Every rule a note triggers, in one list: each note means one thing on its channel.
    let mut keyed: Vec<(String, u8, Option<u8>)> = Vec::new();
    for (i, r) in c.notes.iter().enumerate() {
        let what = format!("note rule {} (note {})", i + 1, r.note);
        if r.pose.trim().is_empty() {
            return Err(format!("{what}: pose name is empty"));
        }
        keyed.push((what, r.note, r.channel));
    }
    for (i, r) in c.moves.iter().enumerate() {
        let what = format!("moves rule {} (note {})", i + 1, r.note);
        if r.moves.trim().is_empty() {
            return Err(format!("{what}: the moves' name is empty"));
        }
        if matches!(r.quantize, Some(Quantize::Now | Quantize::InBeats(_))) {
            return Err(format!("{what}: quantize is \"beat\" or \"bar\""));
        }
        keyed.push((what, r.note, r.channel));
    }
    for (i, r) in c.clock.iter().enumerate() {
        let what = format!("clock rule {} (note {})", i + 1, r.note);
        if !r.ms.is_finite() || r.ms <= 0.0 || r.ms > NUDGE_MS_MAX {
            return Err(format!(
                "{what}: ms must be in (0, {NUDGE_MS_MAX}], got {}",
                r.ms
            ));
        }
        keyed.push((what, r.note, r.channel));
    }
    for (i, (what, note, channel)) in keyed.iter().enumerate() {
        if *note > 127 {
            return Err(format!("{what}: note is not in 0..=127"));
        }
        channel_ok(*channel, what)?;
        let ch = channel.or(c.channel);
        if keyed[..i]
            .iter()
            .any(|(_, n, o)| n == note && o.or(c.channel) == ch)
        {
            return Err(format!("{what}: note mapped twice on the same channel"));
        }
    }
    for (i, r) in c.ccs.iter().enumerate() {
        let what = format!("cc rule {} (controller {})", i + 1, r.controller);
        if r.controller > 127 {
            return Err(format!("{what}: controller is not in 0..=127"));
        }
        if !r.min.is_finite() || !r.max.is_finite() {
            return Err(format!("{what}: min and max must be finite numbers"));
        }
        channel_ok(r.channel, &what)?;
        let (lo, hi) = (r.min.min(r.max), r.min.max(r.max));
        match r.target {
            CcTarget::Temperature if lo < TEMPERATURE_RANGE.0 || hi > TEMPERATURE_RANGE.1 => {
                return Err(format!(
                    "{what}: temperature range {lo}..{hi} is outside {}..{}",
                    TEMPERATURE_RANGE.0, TEMPERATURE_RANGE.1
                ));
            }
            CcTarget::Accent if lo < BEAT_ACCENT_RANGE.0 || hi > BEAT_ACCENT_RANGE.1 => {
                return Err(format!(
                    "{what}: accent range {lo}..{hi} is outside {}..{}",
                    BEAT_ACCENT_RANGE.0, BEAT_ACCENT_RANGE.1
                ));
            }
            CcTarget::Transition if lo <= 0.0 => {
                return Err(format!("{what}: transition beats must be > 0, got {lo}"));
            }
            _ => {}
        }
        let ch = r.channel.or(c.channel);
        if c.ccs[..i]
            .iter()
            .any(|o| o.controller == r.controller && o.channel.or(c.channel) == ch)
        {
            return Err(format!(
                "{what}: controller mapped twice on the same channel"
            ));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::PathBuf;

    fn configs() -> PathBuf {
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../configs/midi")
    }

    fn map(m: &mut MidiMap, msg: MidiMessage) -> Vec<ControlEvent> {
        let mut out = Vec::new();
        m.map_at(0, &msg, &mut out);
        out
    }

    fn key(name: &str, quantize: Quantize) -> ControlEvent {
        ControlEvent::KeyPose {
            name: name.into(),
            quantize,
        }
    }

    #[test]
    fn notes_switch_the_sets_of_moves() {
        let mut m = MidiMap::from_toml_str(
            "[[moves]]\nnote = 48\nmoves = \"salsa\"\n[[moves]]\nnote = 49\nmoves = \"1\"\nquantize = \"beat\"\n",
        )
        .unwrap();
        let on = |note| MidiMessage::NoteOn {
            channel: 1,
            note,
            velocity: 90,
        };
        assert_eq!(
            map(&mut m, on(48)),
            vec![ControlEvent::Moves {
                choice: "salsa".into(),
                quantize: Quantize::NextBar
            }]
        );
        assert_eq!(
            map(&mut m, on(49)),
            vec![ControlEvent::Moves {
                choice: "1".into(),
                quantize: Quantize::NextBeat
            }]
        );
        assert!(map(&mut m, on(50)).is_empty());
        for bad in [
            "[[moves]]\nnote = 48\nmoves = \" \"\n",
            "[[moves]]\nnote = 48\nmoves = \"a\"\nquantize = \"now\"\n",
            "[[note]]\nnote = 48\npose = \"x\"\n[[moves]]\nnote = 48\nmoves = \"a\"\n",
        ] {
            assert!(MidiMap::from_toml_str(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn generic_map_drives_poses_temperature_and_transition() {
        let mut m = MidiMap::load(&configs().join("generic.toml")).unwrap();
        let on = |note| MidiMessage::NoteOn {
            channel: 3,
            note,
            velocity: 100,
        };
        assert_eq!(map(&mut m, on(60)), vec![key("pose-1", Quantize::NextBeat)]);
        assert_eq!(
            map(&mut m, on(75)),
            vec![key("pose-16", Quantize::NextBeat)]
        );
        assert!(map(&mut m, on(59)).is_empty());
        let cc = |controller, value| MidiMessage::ControlChange {
            channel: 0,
            controller,
            value,
        };
        assert_eq!(map(&mut m, cc(1, 0)), vec![ControlEvent::Temperature(0.0)]);
        assert_eq!(
            map(&mut m, cc(1, 127)),
            vec![ControlEvent::Temperature(1.5)]
        );
        let ControlEvent::TransitionBeats(b) = map(&mut m, cc(74, 64))[0] else {
            panic!()
        };
        assert!((b - (0.25 + 3.75 * 64.0 / 127.0)).abs() < 1e-6);
        assert_eq!(map(&mut m, cc(71, 0)), vec![ControlEvent::BeatAccent(0.0)]);
        assert_eq!(
            map(&mut m, cc(71, 127)),
            vec![ControlEvent::BeatAccent(0.6)]
        );
        // CC 75 picks the style in five zones: auto at the bottom, waltz at the top.
        let style = |name: &str| vec![ControlEvent::DanceStyle(name.into())];
        assert_eq!(map(&mut m, cc(75, 0)), style("auto"));
        assert_eq!(map(&mut m, cc(75, 25)), style("auto"));
        assert_eq!(map(&mut m, cc(75, 26)), style("cha-cha"));
        assert_eq!(map(&mut m, cc(75, 64)), style("rumba"));
        assert_eq!(map(&mut m, cc(75, 90)), style("tango"));
        assert_eq!(map(&mut m, cc(75, 127)), style("waltz"));
        // CC 80, a switch: off shows key poses over the dance, on hands them to the network.
        let route = |name: &str| vec![ControlEvent::KeyPoseRoute(name.into())];
        assert_eq!(map(&mut m, cc(80, 0)), route("overlay"));
        assert_eq!(map(&mut m, cc(80, 63)), route("overlay"));
        assert_eq!(map(&mut m, cc(80, 64)), route("network"));
        assert_eq!(map(&mut m, cc(80, 127)), route("network"));
        assert!(map(&mut m, cc(7, 64)).is_empty());
        assert_eq!(
            map(
                &mut m,
                MidiMessage::ProgramChange {
                    channel: 0,
                    program: 9
                }
            ),
            vec![ControlEvent::StyleSeed(9)]
        );
    }

    #[test]
    fn akai_mpd218_map_listens_to_pads_on_channel_10() {
        let mut m = MidiMap::load(&configs().join("akai-mpd218.toml")).unwrap();
        let pad = |channel, note| MidiMessage::NoteOn {
            channel,
            note,
            velocity: 127,
        };
        assert_eq!(
            map(&mut m, pad(9, 36)),
            vec![key("pose-1", Quantize::NextBeat)]
        );
        assert_eq!(
            map(&mut m, pad(9, 51)),
            vec![key("pose-16", Quantize::NextBeat)]
        );
        assert!(
            map(&mut m, pad(0, 36)).is_empty(),
            "channel 1 is not the pads"
        );
        assert!(map(&mut m, pad(9, 52)).is_empty(), "bank B is unmapped");
        let knob = |controller, value| MidiMessage::ControlChange {
            channel: 0,
            controller,
            value,
        };
        assert_eq!(
            map(&mut m, knob(3, 127)),
            vec![ControlEvent::Temperature(1.5)]
        );
        assert_eq!(
            map(&mut m, knob(9, 0)),
            vec![ControlEvent::TransitionBeats(0.25)]
        );
        assert_eq!(
            map(&mut m, knob(12, 127)),
            vec![ControlEvent::BeatAccent(0.6)]
        );
    }

    #[test]
    fn release_clears_only_for_the_note_holding_the_pose() {
        let mut m = MidiMap::from_toml_str(
            "release_clears = true\n[[note]]\nnote = 1\npose = \"a\"\nquantize = \"now\"\n\
             [[note]]\nnote = 2\npose = \"b\"\n",
        )
        .unwrap();
        let on = |note| MidiMessage::NoteOn {
            channel: 0,
            note,
            velocity: 1,
        };
        let off = |note| MidiMessage::NoteOff {
            channel: 0,
            note,
            velocity: 0,
        };
        assert_eq!(map(&mut m, on(1)), vec![key("a", Quantize::Now)]);
        assert_eq!(map(&mut m, on(2)), vec![key("b", Quantize::NextBeat)]);
        assert!(map(&mut m, off(1)).is_empty(), "a no longer holds the pose");
        assert_eq!(map(&mut m, off(2)), vec![ControlEvent::ClearKeyPose]);
    }

    #[test]
    fn clock_gives_one_tempo_hint_per_beat_when_it_moves() {
        let mut m = MidiMap::from_toml_str("clock_tempo = true\ntransport = true").unwrap();
        let mut out = Vec::new();
        m.map_at(0, &MidiMessage::Start, &mut out);
        assert_eq!(out, vec![ControlEvent::Resume]);
        out.clear();
        let tick = 60_000_000 / 125 / 24; // 125 BPM
        for i in 1..=24 * 8 {
            m.map_at(i * tick, &MidiMessage::Clock, &mut out);
        }
        assert_eq!(
            out.len(),
            1,
            "steady tempo: one hint, not one per beat: {out:?}"
        );
        let ControlEvent::TempoHint(bpm) = out[0] else {
            panic!()
        };
        assert!((bpm - 125.0).abs() < 0.01, "{bpm}");
        out.clear();
        m.map_at(24 * 8 * tick + 1, &MidiMessage::Stop, &mut out);
        assert_eq!(out, vec![ControlEvent::Pause]);
    }

    #[test]
    fn notes_tap_the_tempo_set_beat_one_and_nudge_the_clock() {
        let mut m = MidiMap::from_toml_str(
            "[[clock]]\nnote = 36\naction = \"tap\"\n[[clock]]\nnote = 37\naction = \"one\"\n\
             [[clock]]\nnote = 38\naction = \"earlier\"\n[[clock]]\nnote = 39\naction = \"later\"\nms = 2.5\n",
        )
        .unwrap();
        let on = |note| MidiMessage::NoteOn {
            channel: 0,
            note,
            velocity: 100,
        };
        assert_eq!(map(&mut m, on(36)), vec![ControlEvent::Tap]);
        assert_eq!(map(&mut m, on(37)), vec![ControlEvent::BeatOne]);
        assert_eq!(map(&mut m, on(38)), vec![ControlEvent::Nudge(-10.0)]);
        assert_eq!(map(&mut m, on(39)), vec![ControlEvent::Nudge(2.5)]);
    }

    #[test]
    fn the_incoming_clock_is_followed_whether_or_not_it_hints_the_tempo() {
        let mut m = MidiMap::from_toml_str("").unwrap();
        let mut out = Vec::new();
        m.map_at(0, &MidiMessage::Start, &mut out);
        let tick = 60_000_000 / 125 / 24;
        for i in 1..=24 * 2 {
            m.map_at(i * tick, &MidiMessage::Clock, &mut out);
        }
        assert!(out.is_empty(), "no hints asked for: {out:?}");
        let g = m.clock().grid(24 * 2 * tick, 4).unwrap();
        assert!((g.tempo_bpm() - 125.0).abs() < 0.01);
        assert!((g.time_of(0.0) - tick as f64).abs() < 1.0);
    }

    #[test]
    fn packets_from_the_input_go_through_parser_and_map() {
        let mut m = MidiMap::load(&configs().join("generic.toml")).unwrap();
        let mut parser = MidiParser::new();
        let mut out = Vec::new();
        m.map_packet(&mut parser, &(10, [0x90, 61, 100], 3), &mut out);
        // Running status carried over from the previous packet.
        m.map_packet(&mut parser, &(20, [62, 100, 0], 2), &mut out);
        m.map_packet(&mut parser, &(30, [0xb0, 1, 127], 9), &mut out);
        assert_eq!(
            out,
            vec![
                key("pose-2", Quantize::NextBeat),
                key("pose-3", Quantize::NextBeat),
                ControlEvent::Temperature(1.5)
            ]
        );
    }

    #[test]
    fn invalid_maps_give_clear_errors() {
        let cases = [
            ("channel = 17", "channel 17"),
            ("[[note]]\nnote = 200\npose = \"a\"", "note"),
            ("[[note]]\nnote = 1\npose = \"\"", "pose name is empty"),
            (
                "[[note]]\nnote = 1\npose = \"a\"\n[[note]]\nnote = 1\npose = \"b\"",
                "twice",
            ),
            (
                "[[note]]\nnote = 1\npose = \"a\"\nquantize = \"soon\"",
                "bad quantize",
            ),
            (
                "[[cc]]\ncontroller = 1\ntarget = \"temperature\"\nmin = 0\nmax = 3",
                "outside",
            ),
            (
                "[[cc]]\ncontroller = 1\ntarget = \"transition\"\nmin = 0\nmax = 3",
                "> 0",
            ),
            (
                "[[cc]]\ncontroller = 1\ntarget = \"accent\"\nmin = 0\nmax = 1",
                "accent range",
            ),
            (
                "[[cc]]\ncontroller = 1\ntarget = \"tempo\"\nmin = 0\nmax = 3",
                "tempo",
            ),
            (
                "[[cc]]\ncontroller = 1\ntarget = \"temperature\"\nmin = nan\nmax = 1",
                "finite",
            ),
            (
                "[[note]]\nnote = 5\npose = \"a\"\n[[clock]]\nnote = 5\naction = \"tap\"",
                "clock rule 1 (note 5): note mapped twice",
            ),
            (
                "[[clock]]\nnote = 5\naction = \"later\"\nms = 0",
                "ms must be",
            ),
            (
                "[[clock]]\nnote = 5\naction = \"sooner\"",
                "unknown variant",
            ),
            ("colour = \"red\"", "colour"),
            ("not toml [", "MIDI map"),
        ];
        for (text, want) in cases {
            let e = MidiMap::from_toml_str(text).unwrap_err().to_string();
            assert!(e.contains(want), "{text:?}: {e}");
        }
        let e = MidiMap::load(Path::new("/nonexistent/map.toml"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("/nonexistent/map.toml"), "{e}");
    }
}
