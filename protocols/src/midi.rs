//! MIDI 1.0 byte streams to messages.

/// One MIDI message; channels are 0-based as on the wire (what a device calls channel 10 is 9).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum MidiMessage {
    /// A key or pad pressed (velocity 1..=127; velocity 0 arrives as [`MidiMessage::NoteOff`]).
    NoteOn {
        /// Channel 0..=15.
        channel: u8,
        /// Note number 0..=127.
        note: u8,
        /// Velocity 1..=127.
        velocity: u8,
    },
    /// A key or pad released.
    NoteOff {
        /// Channel 0..=15.
        channel: u8,
        /// Note number 0..=127.
        note: u8,
        /// Release velocity 0..=127 (0 when sent as a note-on with velocity 0).
        velocity: u8,
    },
    /// Polyphonic key pressure.
    PolyPressure {
        /// Channel 0..=15.
        channel: u8,
        /// Note number 0..=127.
        note: u8,
        /// Pressure 0..=127.
        pressure: u8,
    },
    /// A knob, fader or switch.
    ControlChange {
        /// Channel 0..=15.
        channel: u8,
        /// Controller number 0..=127.
        controller: u8,
        /// Value 0..=127.
        value: u8,
    },
    /// A program (preset) change.
    ProgramChange {
        /// Channel 0..=15.
        channel: u8,
        /// Program 0..=127.
        program: u8,
    },
    /// Channel pressure (aftertouch).
    ChannelPressure {
        /// Channel 0..=15.
        channel: u8,
        /// Pressure 0..=127.
        pressure: u8,
    },
    /// Pitch bend, centred on 0.
    PitchBend {
        /// Channel 0..=15.
        channel: u8,
        /// Bend -8192..=8191.
        value: i16,
    },
    /// MIDI time code quarter frame (the raw data byte).
    TimeCodeQuarterFrame(u8),
    /// Song position in sixteenth notes since the start.
    SongPosition(u16),
    /// Song select.
    SongSelect(u8),
    /// Tune request.
    TuneRequest,
    /// Timing clock: 24 per quarter note.
    Clock,
    /// Start playing from the beginning.
    Start,
    /// Continue playing from the current position.
    Continue,
    /// Stop playing.
    Stop,
    /// Active sensing keep-alive.
    ActiveSensing,
    /// System reset.
    Reset,
}

impl MidiMessage {
    /// The message as bytes (with its status byte); returns the bytes and how many are used.
    pub fn to_bytes(&self) -> ([u8; 3], usize) {
        let ch = |status: u8, channel: u8| status | (channel & 0x0f);
        let d = |x: u8| x & 0x7f;
        match *self {
            MidiMessage::NoteOff {
                channel,
                note,
                velocity,
            } => ([ch(0x80, channel), d(note), d(velocity)], 3),
            MidiMessage::NoteOn {
                channel,
                note,
                velocity,
            } => ([ch(0x90, channel), d(note), d(velocity)], 3),
            MidiMessage::PolyPressure {
                channel,
                note,
                pressure,
            } => ([ch(0xa0, channel), d(note), d(pressure)], 3),
            MidiMessage::ControlChange {
                channel,
                controller,
                value,
            } => ([ch(0xb0, channel), d(controller), d(value)], 3),
            MidiMessage::ProgramChange { channel, program } => {
                ([ch(0xc0, channel), d(program), 0], 2)
            }
            MidiMessage::ChannelPressure { channel, pressure } => {
                ([ch(0xd0, channel), d(pressure), 0], 2)
            }
            MidiMessage::PitchBend { channel, value } => {
                let v = (i32::from(value).clamp(-8192, 8191) + 8192) as u16;
                ([ch(0xe0, channel), (v & 0x7f) as u8, (v >> 7) as u8], 3)
            }
            MidiMessage::TimeCodeQuarterFrame(x) => ([0xf1, d(x), 0], 2),
            MidiMessage::SongPosition(p) => {
                let p = p & 0x3fff;
                ([0xf2, (p & 0x7f) as u8, (p >> 7) as u8], 3)
            }
            MidiMessage::SongSelect(s) => ([0xf3, d(s), 0], 2),
            MidiMessage::TuneRequest => ([0xf6, 0, 0], 1),
            MidiMessage::Clock => ([0xf8, 0, 0], 1),
            MidiMessage::Start => ([0xfa, 0, 0], 1),
            MidiMessage::Continue => ([0xfb, 0, 0], 1),
            MidiMessage::Stop => ([0xfc, 0, 0], 1),
            MidiMessage::ActiveSensing => ([0xfe, 0, 0], 1),
            MidiMessage::Reset => ([0xff, 0, 0], 1),
        }
    }

    /// Whether this is a one-byte real-time message, which may appear between any two bytes.
    pub fn is_realtime(&self) -> bool {
        matches!(
            self,
            MidiMessage::Clock
                | MidiMessage::Start
                | MidiMessage::Continue
                | MidiMessage::Stop
                | MidiMessage::ActiveSensing
                | MidiMessage::Reset
        )
    }
}

/// Streaming MIDI byte parser: feed bytes in any chunking, get whole messages.
///
/// Handles running status, real-time bytes interleaved anywhere, and skips system exclusive.
/// Truncated messages and data bytes with no status are dropped and counted.
#[derive(Clone, Debug, Default)]
pub struct MidiParser {
    /// Status of the message being collected (channel status persists as running status).
    status: Option<u8>,
    data: [u8; 2],
    len: usize,
    /// The status byte arrived explicitly and no data has completed a message with it yet.
    fresh: bool,
    in_sysex: bool,
    dropped: u64,
    sysex_skipped: u64,
}

/// Data bytes that follow a status byte, or `None` for an undefined status.
fn data_len(status: u8) -> Option<usize> {
    match status {
        0x80..=0xbf | 0xe0..=0xef => Some(2),
        0xc0..=0xdf => Some(1),
        0xf1 | 0xf3 => Some(1),
        0xf2 => Some(2),
        0xf6 => Some(0),
        _ => None,
    }
}

impl MidiParser {
    /// A parser with no running status.
    pub fn new() -> Self {
        Self::default()
    }

    /// Truncated messages, stray data bytes and undefined status bytes dropped so far.
    pub fn dropped(&self) -> u64 {
        self.dropped
    }

    /// System exclusive messages skipped so far.
    pub fn sysex_skipped(&self) -> u64 {
        self.sysex_skipped
    }

    /// Parses `bytes`, appending complete messages to `out`.
    pub fn parse(&mut self, bytes: &[u8], out: &mut Vec<MidiMessage>) {
        out.extend(bytes.iter().filter_map(|&b| self.push(b)));
    }

    /// Feeds one byte; returns a message when this byte completes one.
    pub fn push(&mut self, byte: u8) -> Option<MidiMessage> {
        if byte >= 0xf8 {
            // Real-time bytes leave everything else (running status, sysex) untouched.
            return match byte {
                0xf8 => Some(MidiMessage::Clock),
                0xfa => Some(MidiMessage::Start),
                0xfb => Some(MidiMessage::Continue),
                0xfc => Some(MidiMessage::Stop),
                0xfe => Some(MidiMessage::ActiveSensing),
                0xff => Some(MidiMessage::Reset),
                _ => {
                    self.dropped += 1;
                    None
                }
            };
        }
        if byte >= 0x80 {
            return self.status_byte(byte);
        }
        if self.in_sysex {
            return None;
        }
        let Some(status) = self.status else {
            self.dropped += 1;
            return None;
        };
        self.data[self.len] = byte;
        self.len += 1;
        let needed = data_len(status).unwrap_or(0);
        if self.len < needed {
            return None;
        }
        self.len = 0;
        self.fresh = false;
        if status >= 0xf0 {
            // System common messages do not set running status.
            self.status = None;
        }
        Some(decode(status, self.data))
    }

    fn status_byte(&mut self, byte: u8) -> Option<MidiMessage> {
        if self.in_sysex {
            // Any status ends a sysex; F7 is the proper end, anything else cut it short.
            self.in_sysex = false;
            self.sysex_skipped += 1;
            if byte == 0xf7 {
                return None;
            }
        } else if self.len > 0 || self.fresh {
            self.dropped += 1;
        }
        self.len = 0;
        self.fresh = false;
        self.status = None;
        match byte {
            0xf0 => {
                self.in_sysex = true;
                None
            }
            0xf7 => {
                self.dropped += 1;
                None
            }
            0xf6 => Some(MidiMessage::TuneRequest),
            _ => match data_len(byte) {
                Some(_) => {
                    self.status = Some(byte);
                    self.fresh = true;
                    None
                }
                None => {
                    self.dropped += 1;
                    None
                }
            },
        }
    }
}

fn decode(status: u8, d: [u8; 2]) -> MidiMessage {
    let channel = status & 0x0f;
    match status & 0xf0 {
        0x80 => MidiMessage::NoteOff {
            channel,
            note: d[0],
            velocity: d[1],
        },
        0x90 if d[1] == 0 => MidiMessage::NoteOff {
            channel,
            note: d[0],
            velocity: 0,
        },
        0x90 => MidiMessage::NoteOn {
            channel,
            note: d[0],
            velocity: d[1],
        },
        0xa0 => MidiMessage::PolyPressure {
            channel,
            note: d[0],
            pressure: d[1],
        },
        0xb0 => MidiMessage::ControlChange {
            channel,
            controller: d[0],
            value: d[1],
        },
        0xc0 => MidiMessage::ProgramChange {
            channel,
            program: d[0],
        },
        0xd0 => MidiMessage::ChannelPressure {
            channel,
            pressure: d[0],
        },
        0xe0 => MidiMessage::PitchBend {
            channel,
            value: ((u16::from(d[1]) << 7 | u16::from(d[0])) as i16) - 8192,
        },
        _ => match status {
            0xf1 => MidiMessage::TimeCodeQuarterFrame(d[0]),
            0xf2 => MidiMessage::SongPosition(u16::from(d[1]) << 7 | u16::from(d[0])),
            _ => MidiMessage::SongSelect(d[0]),
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn parse(bytes: &[u8]) -> (Vec<MidiMessage>, MidiParser) {
        let mut p = MidiParser::new();
        let mut out = Vec::new();
        p.parse(bytes, &mut out);
        (out, p)
    }

    #[test]
    fn parses_channel_messages_and_running_status() {
        let (out, p) = parse(&[
            0x99, 36, 100, 40, 90, 36, 0, 0xb0, 1, 64, 74, 127, 0xc2, 5, 7,
        ]);
        assert_eq!(
            out,
            vec![
                MidiMessage::NoteOn {
                    channel: 9,
                    note: 36,
                    velocity: 100
                },
                MidiMessage::NoteOn {
                    channel: 9,
                    note: 40,
                    velocity: 90
                },
                MidiMessage::NoteOff {
                    channel: 9,
                    note: 36,
                    velocity: 0
                },
                MidiMessage::ControlChange {
                    channel: 0,
                    controller: 1,
                    value: 64
                },
                MidiMessage::ControlChange {
                    channel: 0,
                    controller: 74,
                    value: 127
                },
                MidiMessage::ProgramChange {
                    channel: 2,
                    program: 5
                },
                MidiMessage::ProgramChange {
                    channel: 2,
                    program: 7
                },
            ]
        );
        assert_eq!(p.dropped(), 0);
        let (out, _) = parse(&[0xe0, 0, 0x40, 0xe1, 0, 0, 0xe1, 0x7f, 0x7f]);
        assert_eq!(
            out,
            vec![
                MidiMessage::PitchBend {
                    channel: 0,
                    value: 0
                },
                MidiMessage::PitchBend {
                    channel: 1,
                    value: -8192
                },
                MidiMessage::PitchBend {
                    channel: 1,
                    value: 8191
                },
            ]
        );
    }

    #[test]
    fn realtime_bytes_inside_messages_and_sysex() {
        let (out, p) = parse(&[0x90, 0xf8, 60, 0xfa, 100, 0xf0, 1, 2, 0xf8, 3, 0xf7, 0xfc]);
        assert_eq!(
            out,
            vec![
                MidiMessage::Clock,
                MidiMessage::Start,
                MidiMessage::NoteOn {
                    channel: 0,
                    note: 60,
                    velocity: 100
                },
                MidiMessage::Clock,
                MidiMessage::Stop,
            ]
        );
        assert_eq!((p.dropped(), p.sysex_skipped()), (0, 1));
    }

    #[test]
    fn drops_and_counts_truncated_and_stray_bytes() {
        // Stray data; a note-on cut short by a CC; a bare status cut by another; F7 alone;
        // undefined F4 and F9; running status is cleared by sysex.
        let (out, p) = parse(&[
            5, 6, 0x90, 60, 0xb0, 7, 100, 0x80, 0x90, 0xf7, 0xf4, 0xf9, 0xf0, 1, 0xf7, 60, 1,
        ]);
        assert_eq!(
            out,
            vec![MidiMessage::ControlChange {
                channel: 0,
                controller: 7,
                value: 100
            }]
        );
        assert_eq!(p.dropped(), 2 + 1 + 1 + 1 + 1 + 1 + 1 + 2);
        assert_eq!(p.sysex_skipped(), 1);
    }

    #[test]
    fn system_common_does_not_become_running_status() {
        let (out, p) = parse(&[0xf2, 0x10, 0x01, 0x20, 0xf6, 0xf3, 4]);
        assert_eq!(
            out,
            vec![
                MidiMessage::SongPosition(0x90),
                MidiMessage::TuneRequest,
                MidiMessage::SongSelect(4)
            ]
        );
        assert_eq!(p.dropped(), 1);
    }

    fn channel_message() -> impl Strategy<Value = MidiMessage> {
        let c = 0u8..16;
        let d = 0u8..128;
        prop_oneof![
            (c.clone(), d.clone(), 1u8..128).prop_map(|(channel, note, velocity)| {
                MidiMessage::NoteOn {
                    channel,
                    note,
                    velocity,
                }
            }),
            (c.clone(), d.clone(), d.clone()).prop_map(|(channel, note, velocity)| {
                MidiMessage::NoteOff {
                    channel,
                    note,
                    velocity,
                }
            }),
            (c.clone(), d.clone(), d.clone()).prop_map(|(channel, note, pressure)| {
                MidiMessage::PolyPressure {
                    channel,
                    note,
                    pressure,
                }
            }),
            (c.clone(), d.clone(), d.clone()).prop_map(|(channel, controller, value)| {
                MidiMessage::ControlChange {
                    channel,
                    controller,
                    value,
                }
            }),
            (c.clone(), d.clone())
                .prop_map(|(channel, program)| MidiMessage::ProgramChange { channel, program }),
            (c.clone(), d.clone())
                .prop_map(|(channel, pressure)| MidiMessage::ChannelPressure { channel, pressure }),
            (c, -8192i16..8192)
                .prop_map(|(channel, value)| MidiMessage::PitchBend { channel, value }),
            d.clone().prop_map(MidiMessage::TimeCodeQuarterFrame),
            (0u16..0x4000).prop_map(MidiMessage::SongPosition),
            d.prop_map(MidiMessage::SongSelect),
            Just(MidiMessage::TuneRequest),
        ]
    }

    #[derive(Clone, Debug)]
    enum Item {
        Message(MidiMessage),
        Sysex(Vec<u8>),
    }

    fn realtime() -> impl Strategy<Value = MidiMessage> {
        prop::sample::select(vec![
            MidiMessage::Clock,
            MidiMessage::Start,
            MidiMessage::Continue,
            MidiMessage::Stop,
            MidiMessage::ActiveSensing,
            MidiMessage::Reset,
        ])
    }

    proptest! {
        #[test]
        fn arbitrary_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..300)) {
            let (out, _) = parse(&bytes);
            for m in out {
                let (b, n) = m.to_bytes();
                prop_assert!(n >= 1 && b[0] >= 0x80);
            }
        }

        #[test]
        fn encoded_messages_with_realtime_sprinkled_in_parse_back_exactly(
            items in prop::collection::vec(
                prop_oneof![
                    8 => channel_message().prop_map(Item::Message),
                    1 => prop::collection::vec(0u8..128, 0..8).prop_map(Item::Sysex),
                ],
                0..40,
            ),
            sprinkles in prop::collection::vec(
                prop::option::weighted(0.2, realtime()), 0..400),
            running_status in any::<bool>(),
            chunk in 1usize..8,
        ) {
            let mut bytes = Vec::new();
            let mut expected = Vec::new();
            let mut sprinkle = sprinkles.into_iter().chain(std::iter::repeat(None));
            let mut last_status = None;
            let mut put = |b: u8, bytes: &mut Vec<u8>, expected: &mut Vec<MidiMessage>| {
                if let Some(rt) = sprinkle.next().flatten() {
                    bytes.push(rt.to_bytes().0[0]);
                    expected.push(rt);
                }
                bytes.push(b);
            };
            for item in &items {
                match item {
                    Item::Message(m) => {
                        let (b, n) = m.to_bytes();
                        let skip_status = running_status && b[0] < 0xf0 && last_status == Some(b[0]);
                        for (i, &x) in b[..n].iter().enumerate() {
                            if i == 0 && skip_status {
                                continue;
                            }
                            put(x, &mut bytes, &mut expected);
                        }
                        last_status = (b[0] < 0xf0).then_some(b[0]);
                        expected.push(*m);
                    }
                    Item::Sysex(data) => {
                        put(0xf0, &mut bytes, &mut expected);
                        for &x in data {
                            put(x, &mut bytes, &mut expected);
                        }
                        put(0xf7, &mut bytes, &mut expected);
                        last_status = None;
                    }
                }
            }
            let mut p = MidiParser::new();
            let mut out = Vec::new();
            for c in bytes.chunks(chunk) {
                p.parse(c, &mut out);
            }
            prop_assert_eq!(out, expected);
            prop_assert_eq!(p.dropped(), 0);
        }
    }
}
