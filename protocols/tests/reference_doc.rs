//! The book's reference pages checked against the code, both ways: every address, argument
//! list and MIDI target the code has is documented, and everything documented is what the code
//! sends or accepts.
//!
//! - `docs/src/outputs-and-control.md`: the native, VMC and VRChat addresses (from what the
//!   encoders actually send, with their type tags), the OSC control addresses (from the
//!   parser's source, and each documented one fed through the parser with arguments of the
//!   documented types), the MIDI map's controller targets and file keys (the documented example
//!   map must load).
//! - `docs/src/configuration.md`: every key of `configs/danced.toml`, and nothing else.

use std::collections::{BTreeMap, BTreeSet};
use std::time::UNIX_EPOCH;

use glam::{Quat, Vec3};
use protocols::control::DEFAULT_CONTROL_PREFIX;
use protocols::{
    AnalysisEvent, BodyFrame, BoneSample, ControlParser, MidiMap, NativeEncoder, VmcEncoder,
    VrchatEncoder, VrchatTrackerMap,
};
use rosc::{OscMessage, OscPacket, OscType};

const REFERENCE: &str = "outputs-and-control.md";
const CONFIGURATION: &str = "configuration.md";

fn doc(name: &str) -> String {
    let path = format!("{}/../docs/src/{name}", env!("CARGO_MANIFEST_DIR"));
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("reading {path}: {e}"))
}

/// The text under the heading line `heading` (exactly, e.g. "## OSC out: native") up to the
/// next heading of the same or a higher level; headings inside code fences do not count.
fn section<'a>(text: &'a str, heading: &str) -> &'a str {
    let level = heading.chars().take_while(|&c| c == '#').count();
    let mut start = None;
    let mut offset = 0;
    let mut fenced = false;
    for line in text.split_inclusive('\n') {
        let trimmed = line.trim_end();
        if trimmed.starts_with("```") {
            fenced = !fenced;
        } else if !fenced && trimmed.starts_with('#') {
            let this = trimmed.chars().take_while(|&c| c == '#').count();
            match start {
                None if trimmed == heading => start = Some(offset + line.len()),
                Some(s) if this <= level => return &text[s..offset],
                _ => {}
            }
        }
        offset += line.len();
    }
    match start {
        Some(s) => &text[s..],
        None => panic!("the reference has no heading {heading:?}"),
    }
}

/// The cells of every table row in `text`, header and separator rows left out.
fn table_rows(text: &str) -> Vec<Vec<String>> {
    let mut rows = Vec::new();
    let mut header_seen = false;
    for line in text.lines() {
        let line = line.trim();
        if !line.starts_with('|') {
            header_seen = false;
            continue;
        }
        let cells: Vec<String> = line
            .trim_matches('|')
            .split('|')
            .map(|c| c.trim().to_string())
            .collect();
        if !header_seen {
            header_seen = true; // the header row
            continue;
        }
        if cells
            .iter()
            .all(|c| c.chars().all(|ch| ch == '-' || ch == ':'))
        {
            continue; // the separator row
        }
        rows.push(cells);
    }
    rows
}

/// The text between the first pair of backticks in `cell`.
fn code_span(cell: &str) -> String {
    let mut parts = cell.split('`');
    parts.next();
    parts
        .next()
        .unwrap_or_else(|| panic!("no `code` in the table cell {cell:?}"))
        .to_string()
}

/// One documented argument: its type tag and whether it is optional (in `[...]`).
#[derive(Clone, Copy, Debug, PartialEq)]
struct Arg {
    tag: char,
    optional: bool,
}

/// An argument group being read: tag, optional, names seen, explicit count ("× 12").
type Pending = (char, bool, usize, Option<usize>);

/// Appends the group being read, one argument per name (or its explicit count).
fn flush(current: &mut Option<Pending>, args: &mut Vec<Arg>) {
    if let Some((tag, optional, names, count)) = current.take() {
        let n = count.unwrap_or(names.max(1));
        args.extend(std::iter::repeat_n(Arg { tag, optional }, n));
    }
}

/// An "Arguments" cell as type-tag lists, one per alternative ("`s` name or `i` N"): each
/// "`t` a b c" is three arguments of type t, "`f` × 12" twelve, "(none)" none, "[...]" optional.
fn documented_args(cell: &str) -> Vec<Vec<Arg>> {
    if cell.trim() == "(none)" {
        return vec![Vec::new()];
    }
    cell.split(" or ")
        .map(|alternative| {
            let mut args = Vec::new();
            let mut optional = false;
            // (tag, optional, names seen, explicit count)
            let mut current: Option<Pending> = None;
            let mut times = false;
            for (i, piece) in alternative.split('`').enumerate() {
                let in_code = i % 2 == 1;
                if in_code && matches!(piece, "i" | "f" | "s") {
                    flush(&mut current, &mut args);
                    current = Some((piece.chars().next().unwrap(), optional, 0, None));
                    continue;
                }
                for word in piece.split(|c: char| c.is_whitespace() || c == ',') {
                    for ch in word.chars() {
                        match ch {
                            '[' => optional = true,
                            ']' => optional = false,
                            _ => {}
                        }
                    }
                    let word = word.trim_matches(|c| c == '[' || c == ']');
                    if word.is_empty() {
                        continue;
                    }
                    if let Some(c) = current.as_mut() {
                        if word == "×" {
                            times = true;
                        } else if times {
                            c.3 = Some(word.parse().expect("a count after ×"));
                            times = false;
                        } else {
                            c.2 += 1;
                        }
                    }
                }
            }
            flush(&mut current, &mut args);
            assert!(!args.is_empty(), "no arguments read from {cell:?}");
            args
        })
        .collect()
}

fn tags(args: &[Arg]) -> String {
    args.iter().map(|a| a.tag).collect()
}

/// The addresses and argument types documented in a table of `heading`.
fn documented_messages(heading: &str) -> BTreeMap<String, Vec<String>> {
    let text = doc(REFERENCE);
    let mut out: BTreeMap<String, Vec<String>> = BTreeMap::new();
    for row in table_rows(section(&text, heading)) {
        let types = documented_args(&row[1])
            .iter()
            .map(|alt| tags(alt))
            .collect::<Vec<_>>();
        out.entry(code_span(&row[0])).or_default().extend(types);
    }
    assert!(!out.is_empty(), "no addresses under {heading:?}");
    out
}

fn messages(packet: OscPacket, out: &mut Vec<OscMessage>) {
    match packet {
        OscPacket::Message(m) => out.push(m),
        OscPacket::Bundle(b) => b.content.into_iter().for_each(|p| messages(p, out)),
    }
}

fn decode(bytes: &[u8]) -> Vec<OscMessage> {
    let (_, packet) = rosc::decoder::decode_udp(bytes).expect("our output decodes");
    let mut out = Vec::new();
    messages(packet, &mut out);
    out
}

fn type_tags(m: &OscMessage) -> String {
    m.args
        .iter()
        .map(|a| match a {
            OscType::Int(_) => 'i',
            OscType::Float(_) => 'f',
            OscType::String(_) => 's',
            other => panic!("{}: an argument of unexpected type {other:?}", m.addr),
        })
        .collect()
}

/// What the code sends, address (with a bone or tracker number generalised as the reference
/// writes it) → type tags.
fn sent(msgs: &[OscMessage], generalise: impl Fn(&str) -> String) -> BTreeMap<String, String> {
    let mut out = BTreeMap::new();
    for m in msgs {
        let addr = generalise(&m.addr);
        let tags = type_tags(m);
        if let Some(previous) = out.insert(addr.clone(), tags.clone()) {
            assert_eq!(previous, tags, "{addr} is sent with two argument lists");
        }
    }
    out
}

/// Both ways: every address sent is documented with its types, every documented one is sent.
fn assert_documented(heading: &str, sent: &BTreeMap<String, String>) {
    let documented = documented_messages(heading);
    for (addr, tags) in sent {
        let Some(types) = documented.get(addr) else {
            panic!("{addr} is sent but not documented under {heading:?} in docs/src/{REFERENCE}");
        };
        assert!(
            types.contains(tags),
            "{addr}: sent with types {tags:?}, documented as {types:?}"
        );
    }
    for addr in documented.keys() {
        assert!(
            sent.contains_key(addr),
            "{addr} is documented under {heading:?} but the code does not send it"
        );
    }
}

/// Every bone of the default VRChat map plus two more, at distinct places.
fn frame() -> BodyFrame {
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
        "LeftUpperArm",
    ];
    let bones = names
        .iter()
        .enumerate()
        .map(|(i, &bone)| BoneSample {
            bone,
            local_position: Vec3::new(0.0, 0.1 * i as f32, 0.0),
            local_rotation: Quat::from_rotation_y(0.1 * i as f32),
            world_position: Vec3::new(0.01 * i as f32, 1.0, 0.0),
            world_rotation: Quat::from_rotation_x(0.05 * i as f32),
        })
        .collect();
    BodyFrame {
        frame_index: 7,
        audio_time_s: 12.5,
        timetag: UNIX_EPOCH,
        root_position: Vec3::new(0.0, 1.0, 0.0),
        root_rotation: Quat::IDENTITY,
        bones,
    }
}

/// One event of every kind the analysis sends.
fn events() -> Vec<AnalysisEvent> {
    let events = vec![
        AnalysisEvent::Beat {
            time_s: 1.0,
            index_in_bar: 1,
            beats_per_bar: 4,
            tempo_bpm: 120.0,
            bar_confidence: 0.9,
        },
        AnalysisEvent::NextBeat {
            time_s: 1.5,
            in_s: 0.5,
            index_in_bar: 2,
            beats_per_bar: 4,
            tempo_bpm: 120.0,
        },
        AnalysisEvent::Onset {
            time_s: 1.0,
            strength: 2.0,
        },
        AnalysisEvent::Tempo {
            bpm: 120.0,
            confidence: 0.8,
        },
        AnalysisEvent::Chroma {
            time_s: 1.0,
            chroma: [0.5; 12],
        },
        AnalysisEvent::Energy {
            time_s: 1.0,
            db: -12.0,
        },
        AnalysisEvent::RelativeLevel {
            time_s: 1.0,
            db: -3.0,
        },
        AnalysisEvent::ClockOffset { ms: 4.5 },
    ];
    // A new kind of event fails to compile here: add it above, and to the reference.
    for e in &events {
        match e {
            AnalysisEvent::Beat { .. }
            | AnalysisEvent::NextBeat { .. }
            | AnalysisEvent::Onset { .. }
            | AnalysisEvent::Tempo { .. }
            | AnalysisEvent::Chroma { .. }
            | AnalysisEvent::Energy { .. }
            | AnalysisEvent::RelativeLevel { .. }
            | AnalysisEvent::ClockOffset { .. } => {}
        }
    }
    events
}

#[test]
fn the_native_addresses_are_the_documented_ones() {
    let mut enc = NativeEncoder::default();
    let mut msgs = decode(enc.encode_frame(&frame()));
    for e in events() {
        msgs.extend(decode(enc.encode_event(&e)));
    }
    let joint = "/danced/joint/";
    let sent = sent(&msgs, |a| match a.strip_prefix(joint) {
        Some(_) => format!("{joint}<Bone>"),
        None => a.to_string(),
    });
    assert_documented("## OSC out: native", &sent);
}

#[test]
fn the_vmc_addresses_are_the_documented_ones() {
    for split in [false, true] {
        let mut enc = VmcEncoder::new(split);
        let msgs: Vec<OscMessage> = enc
            .encode_frame(&frame())
            .iter()
            .flat_map(|p| decode(p))
            .collect();
        assert_documented("## OSC out: VMC", &sent(&msgs, str::to_string));
    }
}

#[test]
fn the_vrchat_addresses_are_the_documented_ones() {
    let mut enc = VrchatEncoder::new(VrchatTrackerMap::default());
    let msgs: Vec<OscMessage> = enc
        .encode_frame(&frame())
        .iter()
        .flat_map(|p| decode(p))
        .collect();
    let sent = sent(&msgs, |a| {
        a.split('/')
            .map(|part| {
                if !part.is_empty() && part.chars().all(|c| c.is_ascii_digit()) {
                    "N"
                } else {
                    part
                }
            })
            .collect::<Vec<_>>()
            .join("/")
    });
    assert_documented("## OSC out: VRChat", &sent);
}

/// The suffixes (`/temperature`, ...) the control parser matches, read from its source.
fn parser_suffixes() -> BTreeSet<String> {
    let source = include_str!("../src/control.rs");
    let start = source
        .find("fn message(")
        .expect("ControlParser's message function");
    let end = start
        + source[start..]
            .find("\nfn ")
            .expect("a function after the message function");
    let body = &source[start..end];
    let mut out = BTreeSet::new();
    let mut rest = body;
    while let Some(i) = rest.find("\"/") {
        let literal = &rest[i + 1..];
        let close = literal.find('"').expect("a closing quote");
        out.insert(literal[..close].to_string());
        rest = &literal[close + 1..];
    }
    assert!(
        out.len() >= 5,
        "too few addresses read from control.rs: {out:?}"
    );
    out
}

/// A value of the documented type that every control accepts: a float inside every range
/// (temperature and accent clamp, transition ≤ 64 beats, tempo 30..300), an int every count
/// and number takes, a string that is a quantize, a name and a style alike to the parser.
fn plausible(tag: char) -> OscType {
    match tag {
        'f' => OscType::Float(60.0),
        'i' => OscType::Int(1),
        's' => OscType::String("bar".into()),
        _ => unreachable!(),
    }
}

fn encode(addr: &str, args: Vec<OscType>) -> Vec<u8> {
    rosc::encoder::encode(&OscPacket::Message(OscMessage {
        addr: addr.into(),
        args,
    }))
    .expect("encodes")
}

#[test]
fn every_control_address_the_parser_takes_is_documented() {
    let documented = documented_messages("## OSC in: control");
    for suffix in parser_suffixes() {
        let addr = format!("{DEFAULT_CONTROL_PREFIX}{suffix}");
        assert!(
            documented.contains_key(&addr),
            "the control parser takes {addr}, but docs/src/{REFERENCE} does not document it"
        );
    }
}

#[test]
fn every_documented_control_message_is_accepted_by_the_parser() {
    let text = doc(REFERENCE);
    let rows = table_rows(section(&text, "## OSC in: control"));
    assert!(rows.len() >= 5, "too few control rows: {rows:?}");
    let suffixes = parser_suffixes();
    for row in rows {
        let addr = code_span(&row[0]);
        let suffix = addr
            .strip_prefix(DEFAULT_CONTROL_PREFIX)
            .unwrap_or_else(|| panic!("{addr} is not under {DEFAULT_CONTROL_PREFIX}"));
        assert!(
            suffixes.contains(suffix),
            "{addr} is documented but the parser has no such address"
        );
        for alternative in documented_args(&row[1]) {
            let full: Vec<OscType> = alternative.iter().map(|a| plausible(a.tag)).collect();
            let required: Vec<OscType> = alternative
                .iter()
                .filter(|a| !a.optional)
                .map(|a| plausible(a.tag))
                .collect();
            for args in [full, required] {
                let mut parser = ControlParser::default();
                let mut events = Vec::new();
                parser.parse(&encode(&addr, args.clone()), &mut events);
                assert_eq!(
                    (parser.accepted(), parser.ignored()),
                    (1, 0),
                    "{addr} {args:?} (documented as {:?}) was not accepted",
                    row[1]
                );
                assert_eq!(events.len(), 1, "{addr} {args:?} gave no event");
            }
        }
    }
    // The check can fail: an address nobody documented is refused.
    let mut parser = ControlParser::default();
    parser.parse(
        &encode("/danced/control/no-such-control", vec![]),
        &mut Vec::new(),
    );
    assert_eq!(parser.unknown_address(), 1);
}

/// The controller targets the MIDI map accepts, read from `CcTarget` in its source.
fn midi_targets_in_code() -> BTreeSet<String> {
    let source = include_str!("../src/midi_map.rs");
    let start = source.find("pub enum CcTarget {").expect("enum CcTarget");
    assert!(
        source[..start]
            .lines()
            .rev()
            .take(3)
            .any(|l| l.contains("rename_all = \"lowercase\"")),
        "CcTarget's names are no longer its variants lower-cased: update this test"
    );
    let body = &source[start..start + source[start..].find("\n}").expect("the enum's end")];
    let mut out = BTreeSet::new();
    let mut rename = None;
    for line in body.lines().skip(1) {
        let line = line.trim();
        if let Some(r) = line.strip_prefix("#[serde(rename = \"") {
            rename = Some(r.split('"').next().unwrap().to_string());
        } else if let Some(variant) = line.strip_suffix(',')
            && !variant.is_empty()
            && variant.chars().all(|c| c.is_ascii_alphanumeric())
        {
            out.insert(
                rename
                    .take()
                    .unwrap_or_else(|| variant.to_ascii_lowercase()),
            );
        }
    }
    assert!(
        out.len() >= 3,
        "too few targets read from midi_map.rs: {out:?}"
    );
    out
}

fn midi_map_with_target(target: &str) -> Result<MidiMap, protocols::ProtocolError> {
    MidiMap::from_toml_str(&format!(
        "[[cc]]\ncontroller = 1\ntarget = \"{target}\"\nmin = 0.5\nmax = 0.8\n"
    ))
}

#[test]
fn the_midi_targets_are_the_documented_ones() {
    let text = doc(REFERENCE);
    let documented: BTreeSet<String> = table_rows(section(&text, "### Controller targets"))
        .iter()
        .map(|row| code_span(&row[0]))
        .collect();
    let code = midi_targets_in_code();
    for target in &code {
        assert!(
            documented.contains(target),
            "MIDI target {target:?} is in the code but not in docs/src/{REFERENCE}"
        );
    }
    for target in &documented {
        assert!(
            midi_map_with_target(target).is_ok(),
            "documented MIDI target {target:?} is refused by the MIDI map"
        );
    }
    assert!(midi_map_with_target("no-such-target").is_err());
}

/// The keys of one struct of `midi_map.rs` as a TOML file spells them.
fn struct_keys(source: &str, name: &str) -> Vec<String> {
    let start = source
        .find(&format!("pub struct {name} {{"))
        .unwrap_or_else(|| panic!("struct {name}"));
    let body = &source[start..start + source[start..].find("\n}").expect("the struct's end")];
    let mut keys = Vec::new();
    let mut rename = None;
    for line in body.lines().skip(1) {
        let line = line.trim();
        if line.starts_with("#[serde(")
            && let Some(i) = line.find("rename = \"")
        {
            rename = Some(line[i + 10..].split('"').next().unwrap().to_string());
        } else if let Some(field) = line.strip_prefix("pub ")
            && let Some((field, _)) = field.split_once(':')
        {
            keys.push(rename.take().unwrap_or_else(|| field.trim().to_string()));
        }
    }
    assert!(!keys.is_empty(), "no fields read from {name}");
    keys
}

#[test]
fn the_documented_midi_map_loads_and_shows_every_key() {
    let text = doc(REFERENCE);
    let format = section(&text, "### MIDI map format");
    let example = format
        .split("```toml\n")
        .nth(1)
        .and_then(|rest| rest.split("```").next())
        .expect("a ```toml example under \"### MIDI map format\"");
    if let Err(e) = MidiMap::from_toml_str(example) {
        panic!("the documented MIDI map does not load: {e}");
    }
    let source = include_str!("../src/midi_map.rs");
    for name in ["MidiMapConfig", "NoteRule", "CcRule"] {
        for key in struct_keys(source, name) {
            let shown = example.lines().any(|line| {
                let line = line.trim_start();
                line.starts_with(&format!("[[{key}]]"))
                    || line
                        .strip_prefix(key.as_str())
                        .is_some_and(|rest| rest.trim_start().starts_with('='))
            });
            assert!(
                shown,
                "MIDI map key {key:?} ({name}) is not in the documented example map"
            );
        }
    }
}

/// Every key of `configs/danced.toml`, commented-out ones included, dotted with its table
/// (`output.vmc.target`); tracker numbers written `N`.
fn shipped_config_keys() -> BTreeSet<String> {
    let path = format!("{}/../configs/danced.toml", env!("CARGO_MANIFEST_DIR"));
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("reading {path}: {e}"));
    let mut table = String::new();
    let mut keys = BTreeSet::new();
    for line in text.lines() {
        let line = line.trim();
        if let Some(name) = line.strip_prefix('[').and_then(|l| l.strip_suffix(']')) {
            table = name.trim().to_string();
            continue;
        }
        let setting = line.strip_prefix('#').map_or(line, str::trim_start);
        let Some((key, value)) = setting.split_once('=') else {
            continue;
        };
        let key = key.trim();
        if key.is_empty()
            || value.trim().is_empty()
            || !key.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
        {
            continue;
        }
        // Prose in a comment is not a setting: a setting's value is TOML (a comment may go on
        // after it: `head = "Head" picks the bone ...`).
        let first = value.split_whitespace().next().unwrap_or("");
        let is_toml = |t: &str| toml::from_str::<toml::Table>(t).is_ok();
        if line.starts_with('#') && !is_toml(setting) && !is_toml(&format!("{key} = {first}")) {
            continue;
        }
        let key = if key.chars().all(|c| c.is_ascii_digit()) {
            "N"
        } else {
            key
        };
        keys.insert(if table.is_empty() {
            key.to_string()
        } else {
            format!("{table}.{key}")
        });
    }
    assert!(keys.len() >= 20, "too few keys read from {path}: {keys:?}");
    keys
}

#[test]
fn every_configuration_key_is_documented_and_nothing_else() {
    let text = doc(CONFIGURATION);
    let documented: BTreeSet<String> = table_rows(&text)
        .iter()
        .map(|row| code_span(&row[0]))
        .collect();
    let shipped = shipped_config_keys();
    for key in &shipped {
        assert!(
            documented.contains(key),
            "configs/danced.toml has `{key}`, docs/src/{CONFIGURATION} does not document it"
        );
    }
    for key in &documented {
        assert!(
            shipped.contains(key),
            "docs/src/{CONFIGURATION} documents `{key}`, configs/danced.toml has no such key"
        );
    }
}

#[test]
fn the_argument_reader_reads_the_reference_notation() {
    let a = |tag, optional| Arg { tag, optional };
    assert_eq!(documented_args("(none)"), vec![vec![]]);
    assert_eq!(
        documented_args("`f` px py pz, `f` qx qy qz qw"),
        vec![vec![a('f', false); 7]]
    );
    assert_eq!(documented_args("`f` × 12"), vec![vec![a('f', false); 12]]);
    assert_eq!(
        documented_args("`s` name [`s` when]"),
        vec![vec![a('s', false), a('s', true)]]
    );
    assert_eq!(
        documented_args("`s` name or `i` N"),
        vec![vec![a('s', false)], vec![a('i', false)]]
    );
    assert_eq!(
        documented_args("`s` \"root\", `f` px py pz, `f` qx qy qz qw"),
        vec![[vec![a('s', false)], vec![a('f', false); 7]].concat()]
    );
}
