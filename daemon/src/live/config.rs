//! `configs/danced.toml`: every setting of `danced run`, with command-line flags on top.
//! Unknown keys are errors (a typo must not silently fall back to a default), and every error
//! names the file and the key.

use model::source::KeyPoseRoute;
use model::stage::{MIN_RADIUS_M, StageMode, StageSettings};
use model::style::StyleRequest;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use protocols::control::{
    BEAT_ACCENT_RANGE, TEMPERATURE_RANGE, TRANSITION_BEATS_RANGE, valid_transition_beats,
};
use serde::Deserialize;
use thiserror::Error;

/// A configuration that cannot be used.
#[derive(Debug, Error)]
pub enum ConfigError {
    /// The file could not be read.
    #[error("reading {path}: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The TOML is malformed, has an unknown key or a value of the wrong type.
    #[error("{path}: {message}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// toml's message (it names the key, line and column).
        message: String,
    },
    /// A value is out of range.
    #[error("{origin}: `{key}` {problem}")]
    Invalid {
        /// The file, or "command line".
        origin: String,
        /// Dotted key, e.g. `output.rate_hz`.
        key: &'static str,
        /// What is wrong with it.
        problem: String,
    },
}

/// The whole configuration.
#[derive(Clone, Debug, Default, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct Config {
    /// Audio input.
    pub audio: AudioConfig,
    /// Outputs.
    pub output: OutputConfig,
    /// Control inputs.
    pub control: ControlConfig,
    /// The dancer.
    pub dancer: DancerConfig,
    /// Where on the floor it dances.
    pub stage: StageConfig,
    /// The browser view.
    pub view: ViewConfig,
    /// Where the beat grid comes from, and the clocks danced leads.
    pub clock: ClockConfig,
    /// Write the run's stats here as JSON when it ends.
    pub stats_json: Option<PathBuf>,
}

/// `[audio]`.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct AudioConfig {
    /// Substring of the capture device's name (default input when absent).
    pub device: Option<String>,
    /// Replay this file instead of capturing.
    pub input: Option<PathBuf>,
    /// Replay speed (audio seconds per wall second).
    pub speed: f64,
    /// Replay in a loop.
    #[serde(rename = "loop")]
    pub looped: bool,
    /// Stop after this many seconds of audio.
    pub duration: Option<f64>,
    /// Capture channels to hear, 1-based (inputs 1 and 2 when absent; more than two are
    /// averaged to mono).
    pub channels: Option<Vec<u16>>,
}

impl Default for AudioConfig {
    fn default() -> Self {
        Self {
            device: None,
            input: None,
            speed: 1.0,
            looped: false,
            duration: None,
            channels: None,
        }
    }
}

/// `[output]`.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct OutputConfig {
    /// Frames sent per second.
    pub rate_hz: f64,
    /// Delivery margin poses are made ahead by (capture blocks, thread hand-offs), ms: it
    /// lengthens the prediction horizon and adds no delay.
    pub margin_ms: f64,
    /// How far ahead of the heard music the shown pose is, ms: sends poses early to cancel a
    /// renderer's or LED wall's display latency (may be negative). Frames' bundle timetags say
    /// when they should be shown.
    pub lead_ms: f64,
    /// Run the pipeline threads at real-time priority where the system allows it.
    pub realtime: bool,
    /// Plain OSC targets (host:port).
    pub osc: Vec<String>,
    /// VMC protocol output.
    pub vmc: VmcConfig,
    /// VRChat OSC trackers output.
    pub vrchat: VrchatConfig,
}

impl Default for OutputConfig {
    fn default() -> Self {
        Self {
            rate_hz: 60.0,
            margin_ms: model::horizon::DEFAULT_MARGIN_S * 1e3,
            lead_ms: 0.0,
            realtime: true,
            osc: vec!["127.0.0.1:10000".into()],
            vmc: VmcConfig::default(),
            vrchat: VrchatConfig::default(),
        }
    }
}

/// `[output.vmc]`.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct VmcConfig {
    /// Send VMC.
    pub enabled: bool,
    /// Where to (host:port).
    pub target: String,
    /// Split each frame into bundles under 1400 bytes (for lossy networks).
    pub split_bundles: bool,
}

impl Default for VmcConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            target: "127.0.0.1:39539".into(),
            split_bundles: false,
        }
    }
}

/// `[output.vrchat]`.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct VrchatConfig {
    /// Send VRChat OSC trackers.
    pub enabled: bool,
    /// Where to (host:port).
    pub target: String,
    /// Tracker number (1–8, from 1 without gaps) or "head" → bone name (Unity HumanBodyBones).
    pub trackers: BTreeMap<String, String>,
}

impl Default for VrchatConfig {
    fn default() -> Self {
        // protocols' default assignment, numbered from 1 as VRChat numbers its trackers.
        let trackers = protocols::VrchatTrackerMap::default()
            .trackers()
            .iter()
            .enumerate()
            .map(|(i, bone)| ((i + 1).to_string(), bone.to_string()))
            .collect();
        Self {
            enabled: false,
            target: "127.0.0.1:9000".into(),
            trackers,
        }
    }
}

/// `[control]`.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct ControlConfig {
    /// UDP port of the OSC control receiver (0 = off).
    pub osc_port: u16,
    /// Address the OSC control receiver binds to.
    pub bind: String,
    /// Source addresses allowed to send control (empty: anyone who can reach the port).
    pub allow: Vec<std::net::IpAddr>,
    /// Substring of the MIDI input port's name (off when absent).
    pub midi_port: Option<String>,
    /// MIDI mapping file (default: the built-in generic map, `configs/midi/generic.toml`).
    pub midi_map: Option<PathBuf>,
    /// Key-pose bank (default: the built-in `configs/poses/bank.toml`).
    pub poses: Option<PathBuf>,
}

impl Default for ControlConfig {
    fn default() -> Self {
        Self {
            osc_port: 9010,
            bind: "127.0.0.1".into(),
            allow: Vec::new(),
            midi_port: None,
            midi_map: None,
            poses: None,
        }
    }
}

/// `[clock]`.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct ClockConfig {
    /// Where the beat grid comes from: `audio` (the beats heard), `midi` (the MIDI clock on
    /// `control.midi_port`), `link` (the Link session; needs `link = true`) or `tap`.
    pub source: String,
    /// Beats per bar of a MIDI clock or tapped beats (they do not say).
    pub beats_per_bar: u32,
    /// Pull an external clock's phase toward the beats heard.
    pub trim: bool,
    /// Join an Ableton Link session: followed with `source = "link"`, led otherwise.
    pub link: bool,
    /// Send MIDI clock from the grid followed to the output port whose name contains this.
    pub midi_out: Option<String>,
}

impl Default for ClockConfig {
    fn default() -> Self {
        Self {
            source: "audio".into(),
            beats_per_bar: 4,
            trim: false,
            link: false,
            midi_out: None,
        }
    }
}

impl ClockConfig {
    /// The clock followed (a validated configuration always names one).
    pub fn source(&self) -> super::clock::ClockSource {
        super::clock::ClockSource::parse(&self.source).unwrap_or_default()
    }
}

/// `[view]`.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct ViewConfig {
    /// Serve the browser view.
    pub enabled: bool,
    /// host:port it listens on (loopback unless told otherwise).
    pub addr: String,
}

impl Default for ViewConfig {
    fn default() -> Self {
        Self {
            enabled: false,
            addr: crate::view::DEFAULT_VIEW_ADDR.into(),
        }
    }
}

/// `[stage]`.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct StageConfig {
    /// `bounded` (the hips stay within `radius_m` of the centre: the dance turns back before
    /// the edge), `in_place` (the hips' travel removed) or `free` (wherever the dance goes).
    pub mode: String,
    /// Radius of the stage, metres.
    pub radius_m: f32,
    /// Centre of the stage on the floor, metres: [x (sideways), z (towards the audience)].
    pub centre: [f32; 2],
    /// Direction the audience is in, degrees about the vertical: 0 = +z (towards the view's
    /// camera and an avatar app's default), 90 = +x.
    pub facing_deg: f32,
}

impl Default for StageConfig {
    fn default() -> Self {
        let s = StageSettings::default();
        Self {
            mode: s.mode.name().into(),
            radius_m: s.radius_m,
            centre: s.centre,
            facing_deg: s.facing_deg,
        }
    }
}

impl StageConfig {
    /// The stage asked for (a validated configuration always names a mode; anything else
    /// reads as bounded).
    pub fn settings(&self) -> StageSettings {
        StageSettings {
            mode: StageMode::parse(&self.mode).unwrap_or_default(),
            radius_m: self.radius_m,
            centre: self.centre,
            facing_deg: self.facing_deg,
        }
    }
}

/// `[dancer]`.
#[derive(Clone, Debug, Deserialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct DancerConfig {
    /// Motion source (`neural` or `retrieval`).
    pub source: String,
    /// Neural model file (default: the built-in one).
    pub model: Option<PathBuf>,
    /// Clip libraries of the retrieval source, switched live by `/danced/control/moves`
    /// (default: the built-in one).
    pub libraries: Vec<crate::dancer::LibraryChoice>,
    /// Initial temperature (0 = most likely motion).
    pub temperature: f32,
    /// Random seed.
    pub seed: u64,
    /// Transition length of immediate key poses, beats.
    pub transition_beats: f32,
    /// Depth of the neural dancer's beat accent (0: the network's own timing).
    pub beat_accent: f32,
    /// Share of a planted foot's slide the neural dancer's stance leg holds, 0–1.
    pub foot_plant: f32,
    /// Dance style: `auto` (from the music's meter and tempo), `cha-cha`, `rumba`, `tango` or
    /// `waltz` (models trained before issue 21 have no style input and ignore it).
    pub style: String,
    /// Where the neural dancer sends a key pose: `overlay` (shown over the dance, blended onto
    /// the key by its deadline) or `network` (the network reads it and dances there itself;
    /// the end blend still closes what it leaves).
    pub key_route: String,
}

impl Default for DancerConfig {
    fn default() -> Self {
        Self {
            source: crate::dancer::SourceKind::DEFAULT.name().into(),
            model: None,
            libraries: Vec::new(),
            temperature: 0.5,
            seed: 1,
            transition_beats: 1.0,
            beat_accent: model::neural::dancer::BEAT_ACCENT,
            foot_plant: model::foot_lock::DEFAULT_PLANT,
            style: "auto".into(),
            key_route: KeyPoseRoute::Overlay.name().into(),
        }
    }
}

impl DancerConfig {
    /// The key-pose route asked for (a validated configuration always names one; anything
    /// else reads as the overlay).
    pub fn key_pose_route(&self) -> KeyPoseRoute {
        KeyPoseRoute::parse(&self.key_route).unwrap_or(KeyPoseRoute::Overlay)
    }

    /// The style asked for (a validated configuration always names one; anything else reads
    /// as auto).
    pub fn style_request(&self) -> StyleRequest {
        StyleRequest::parse(&self.style).unwrap_or_default()
    }
}

impl Config {
    /// Parses TOML text; `origin` names it in errors.
    pub fn parse(text: &str, origin: &Path) -> Result<Self, ConfigError> {
        let config: Config = toml::from_str(text).map_err(|e| ConfigError::Parse {
            path: origin.to_path_buf(),
            message: e.to_string(),
        })?;
        config.validate(&origin.display().to_string())?;
        Ok(config)
    }

    /// Reads and checks a file.
    pub fn load(path: &Path) -> Result<Self, ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Read {
            path: path.to_path_buf(),
            source,
        })?;
        Self::parse(&text, path)
    }

    /// Checks every range; `origin` names the file (or "command line") in errors.
    pub fn validate(&self, origin: &str) -> Result<(), ConfigError> {
        let bad = |key: &'static str, problem: String| ConfigError::Invalid {
            origin: origin.to_string(),
            key,
            problem,
        };
        let r = self.output.rate_hz;
        if !(r.is_finite() && (1.0..=1000.0).contains(&r)) {
            return Err(bad("output.rate_hz", format!("= {r}: must be in 1..=1000")));
        }
        let m = self.output.margin_ms;
        if !(m.is_finite() && (0.0..=1000.0).contains(&m)) {
            return Err(bad(
                "output.margin_ms",
                format!("= {m}: must be in 0..=1000"),
            ));
        }
        let l = self.output.lead_ms;
        if !(l.is_finite() && (-1000.0..=1000.0).contains(&l)) {
            return Err(bad(
                "output.lead_ms",
                format!("= {l}: must be in -1000..=1000"),
            ));
        }
        let s = self.audio.speed;
        if !(s.is_finite() && s > 0.0 && s <= 100.0) {
            return Err(bad("audio.speed", format!("= {s}: must be in (0, 100]")));
        }
        if let Some(d) = self.audio.duration
            && !(d.is_finite() && d > 0.0)
        {
            return Err(bad("audio.duration", format!("= {d}: must be positive")));
        }
        if self.view.addr.parse::<std::net::SocketAddr>().is_err() {
            return Err(bad(
                "view.addr",
                format!(
                    "= {:?}: must be host:port, e.g. 127.0.0.1:8080",
                    self.view.addr
                ),
            ));
        }
        if self.audio.input.is_some() && self.audio.device.is_some() {
            return Err(bad("audio.input", "and audio.device are exclusive".into()));
        }
        // The same ranges as the live controls (OSC, MIDI): one definition, in `protocols`.
        let (t, (lo, hi)) = (self.dancer.temperature, TEMPERATURE_RANGE);
        if !(t.is_finite() && (lo..=hi).contains(&t)) {
            return Err(bad(
                "dancer.temperature",
                format!("= {t}: must be in {lo}..={hi}"),
            ));
        }
        let (b, (lo, hi)) = (self.dancer.transition_beats, TRANSITION_BEATS_RANGE);
        if !valid_transition_beats(b) {
            return Err(bad(
                "dancer.transition_beats",
                format!("= {b}: must be above {lo} and at most {hi}"),
            ));
        }
        let (a, (lo, hi)) = (self.dancer.beat_accent, BEAT_ACCENT_RANGE);
        if !(a.is_finite() && (lo..=hi).contains(&a)) {
            return Err(bad(
                "dancer.beat_accent",
                format!("= {a}: must be in {lo}..={hi}"),
            ));
        }
        let p = self.dancer.foot_plant;
        if !(p.is_finite() && (0.0..=1.0).contains(&p)) {
            return Err(bad("dancer.foot_plant", format!("= {p}: must be in 0..=1")));
        }
        if KeyPoseRoute::parse(&self.dancer.key_route).is_none() {
            return Err(bad(
                "dancer.key_route",
                format!("= {:?}: must be overlay or network", self.dancer.key_route),
            ));
        }
        if model::style::StyleRequest::parse(&self.dancer.style).is_none() {
            return Err(bad(
                "dancer.style",
                format!(
                    "= {:?}: must be auto, cha-cha, rumba, tango or waltz",
                    self.dancer.style
                ),
            ));
        }
        if StageMode::parse(&self.stage.mode).is_none() {
            return Err(bad(
                "stage.mode",
                format!("= {:?}: must be bounded, in_place or free", self.stage.mode),
            ));
        }
        let r = self.stage.radius_m;
        if !(r.is_finite() && (MIN_RADIUS_M..=100.0).contains(&r)) {
            return Err(bad(
                "stage.radius_m",
                format!("= {r}: must be in {MIN_RADIUS_M}..=100 m"),
            ));
        }
        if !self
            .stage
            .centre
            .iter()
            .all(|c| c.is_finite() && c.abs() <= 1000.0)
        {
            return Err(bad(
                "stage.centre",
                format!(
                    "= {:?}: must be two finite metres within ±1000",
                    self.stage.centre
                ),
            ));
        }
        let f = self.stage.facing_deg;
        if !(f.is_finite() && (-360.0..=360.0).contains(&f)) {
            return Err(bad(
                "stage.facing_deg",
                format!("= {f}: must be in -360..=360 degrees"),
            ));
        }
        use super::clock::ClockSource;
        match ClockSource::parse(&self.clock.source) {
            None => {
                return Err(bad(
                    "clock.source",
                    format!(
                        "= {:?}: available: {}",
                        self.clock.source,
                        ClockSource::NAMES
                    ),
                ));
            }
            Some(ClockSource::Midi) if self.control.midi_port.is_none() => {
                return Err(bad(
                    "clock.source",
                    "= \"midi\" needs control.midi_port (the port the clock comes in on)".into(),
                ));
            }
            Some(ClockSource::Link) if !self.clock.link => {
                return Err(bad(
                    "clock.source",
                    "= \"link\" needs clock.link = true".into(),
                ));
            }
            Some(_) => {}
        }
        let b = self.clock.beats_per_bar;
        if !(1..=16).contains(&b) {
            return Err(bad(
                "clock.beats_per_bar",
                format!("= {b}: must be in 1..=16"),
            ));
        }
        if self.clock.link && !super::link::AVAILABLE {
            return Err(bad(
                "clock.link",
                "= true: this build has no Ableton Link (build with --features link)".into(),
            ));
        }
        if let Some(list) = &self.audio.channels {
            let max = super::input_mix::MAX_INPUT_CHANNELS;
            let mut seen = std::collections::BTreeSet::new();
            if list.is_empty() || list.iter().any(|&c| c == 0 || c > max || !seen.insert(c)) {
                return Err(bad(
                    "audio.channels",
                    format!("= {list:?}: must list distinct input channels in 1..={max}"),
                ));
            }
        }
        match crate::dancer::SourceKind::parse(&self.dancer.source) {
            None => {
                return Err(bad(
                    "dancer.source",
                    format!(
                        "= {:?}: available: {}",
                        self.dancer.source,
                        crate::dancer::SourceKind::NAMES
                    ),
                ));
            }
            Some(crate::dancer::SourceKind::Neural) if !self.dancer.libraries.is_empty() => {
                return Err(bad(
                    "dancer.libraries",
                    "is for the retrieval source; dancer.source is \"neural\"".into(),
                ));
            }
            Some(crate::dancer::SourceKind::Retrieval) if self.dancer.model.is_some() => {
                return Err(bad(
                    "dancer.model",
                    "is for the neural source; dancer.source is \"retrieval\"".into(),
                ));
            }
            Some(_) => {}
        }
        // Numbering, duplicates and HumanBodyBones names are protocols' to judge; whether the
        // rig has the bone (so it is ever in a frame) is ours.
        protocols::VrchatTrackerMap::from_numbered(&self.output.vrchat.trackers)
            .map_err(|e| bad("output.vrchat.trackers", e.to_string()))?;
        for (n, bone) in &self.output.vrchat.trackers {
            if model::rig::Joint::from_name(bone).is_none() {
                return Err(bad(
                    "output.vrchat.trackers",
                    format!("{n} = {bone:?}: unknown bone"),
                ));
            }
        }
        for t in self
            .output
            .osc
            .iter()
            .chain([&self.output.vmc.target, &self.output.vrchat.target])
        {
            if t.rsplit_once(':')
                .is_none_or(|(_, p)| p.parse::<u16>().is_err())
            {
                return Err(bad("output", format!("target {t:?} is not host:port")));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use model::style::DanceStyle;

    #[test]
    fn shipped_config_parses_to_the_defaults() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../configs/danced.toml");
        let c = Config::load(&path).unwrap();
        assert_eq!(c.output, OutputConfig::default());
        assert_eq!(c.dancer, DancerConfig::default());
        assert_eq!(c.control, ControlConfig::default());
        assert_eq!(c.view, ViewConfig::default());
    }

    #[test]
    fn errors_name_the_key() {
        let e = Config::parse("[output]\nrate_hzz = 30\n", Path::new("x.toml")).unwrap_err();
        assert!(e.to_string().contains("rate_hzz"), "{e}");
        let e = Config::parse("[output]\nrate_hz = 0\n", Path::new("x.toml")).unwrap_err();
        assert!(e.to_string().contains("output.rate_hz"), "{e}");
        let e =
            Config::parse("[dancer]\ntemperature = \"hot\"\n", Path::new("x.toml")).unwrap_err();
        assert!(e.to_string().contains("temperature"), "{e}");
    }

    #[test]
    fn a_clock_needs_its_input_and_a_bar() {
        let parse = |t: &str| Config::parse(t, Path::new("x.toml")).map_err(|e| e.to_string());
        let e = parse("[clock]\nsource = \"midi\"\n").unwrap_err();
        assert!(
            e.contains("clock.source") && e.contains("control.midi_port"),
            "{e}"
        );
        let c = parse("[control]\nmidi_port = \"x\"\n[clock]\nsource = \"MIDI\"\n").unwrap();
        assert_eq!(c.clock.source(), super::super::clock::ClockSource::Midi);
        let e = parse("[clock]\nsource = \"link\"\n").unwrap_err();
        assert!(e.contains("clock.link = true"), "{e}");
        let e = parse("[clock]\nsource = \"vinyl\"\n").unwrap_err();
        assert!(e.contains("audio, midi, link, tap"), "{e}");
        let e = parse("[clock]\nbeats_per_bar = 0\n").unwrap_err();
        assert!(e.contains("clock.beats_per_bar"), "{e}");
        assert!(parse("[clock]\nsource = \"tap\"\nbeats_per_bar = 3\n").is_ok());
        let link = parse("[clock]\nlink = true\n");
        if super::super::link::AVAILABLE {
            assert!(link.is_ok(), "{link:?}");
        } else {
            assert!(link.unwrap_err().contains("--features link"));
        }
    }

    #[test]
    fn vrchat_tracker_gaps_are_errors() {
        let toml = "[output.vrchat.trackers]\n1 = \"Hips\"\n3 = \"Chest\"\n";
        let e = Config::parse(toml, Path::new("x.toml"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("output.vrchat.trackers") && e.contains("tracker 2 is missing"),
            "{e}"
        );
        let toml = "[output.vrchat.trackers]\n1 = \"Hips\"\nhead = \"Neck\"\n";
        assert!(Config::parse(toml, Path::new("x.toml")).is_ok());
    }

    #[test]
    fn dancer_source_and_its_files_are_checked() {
        let c = Config::parse(
            "[dancer]\nsource = \"neural\"\nmodel = \"m.dnn\"\n",
            Path::new("x.toml"),
        )
        .unwrap();
        assert_eq!(c.dancer.source, "neural");
        assert_eq!(c.dancer.model.as_deref(), Some(Path::new("m.dnn")));
        let e = Config::parse("[dancer]\nsource = \"puppet\"\n", Path::new("x.toml")).unwrap_err();
        assert!(e.to_string().contains("neural, retrieval"), "{e}");
        let e = Config::parse(
            "[dancer]\nsource = \"retrieval\"\nmodel = \"m.dnn\"\n",
            Path::new("x.toml"),
        )
        .unwrap_err();
        assert!(e.to_string().contains("dancer.model"), "{e}");
        // Several libraries, as an inline array or as tables; names optional.
        for text in [
            "[dancer]\nsource = \"retrieval\"\nlibraries = [{ path = \"a.danclips\" }, { path = \"b.danclips\", name = \"breaking\" }]\n",
            "[dancer]\nsource = \"retrieval\"\n[[dancer.libraries]]\npath = \"a.danclips\"\n[[dancer.libraries]]\npath = \"b.danclips\"\nname = \"breaking\"\n",
        ] {
            let c = Config::parse(text, Path::new("x.toml")).unwrap();
            assert_eq!(
                c.dancer.libraries,
                vec![
                    crate::dancer::LibraryChoice::file("a.danclips"),
                    crate::dancer::LibraryChoice {
                        path: "b.danclips".into(),
                        name: Some("breaking".into())
                    }
                ]
            );
        }
        let e = Config::parse(
            "[dancer]\nsource = \"neural\"\nlibraries = [{ path = \"a.danclips\" }]\n",
            Path::new("x.toml"),
        )
        .unwrap_err();
        assert!(e.to_string().contains("dancer.libraries"), "{e}");
    }

    #[test]
    fn key_route_is_checked() {
        let c = Config::parse("[dancer]\nkey_route = \"Network\"\n", Path::new("x.toml")).unwrap();
        assert_eq!(c.dancer.key_pose_route(), KeyPoseRoute::Network);
        assert_eq!(
            Config::default().dancer.key_pose_route(),
            KeyPoseRoute::Overlay
        );
        let e = Config::parse("[dancer]\nkey_route = \"both\"\n", Path::new("x.toml")).unwrap_err();
        assert!(e.to_string().contains("dancer.key_route"), "{e}");
    }

    #[test]
    fn stage_is_checked() {
        let c = Config::parse(
            "[stage]\nmode = \"in-place\"\nradius_m = 2.5\ncentre = [1.0, -2.0]\nfacing_deg = 90\n",
            Path::new("x.toml"),
        )
        .unwrap();
        let s = c.stage.settings();
        assert_eq!(s.mode, StageMode::InPlace);
        assert_eq!(
            (s.radius_m, s.centre, s.facing_deg),
            (2.5, [1.0, -2.0], 90.0)
        );
        assert_eq!(Config::default().stage.settings(), StageSettings::default());
        for (bad, key) in [
            ("mode = \"roam\"", "stage.mode"),
            ("radius_m = 0.1", "stage.radius_m"),
            ("radius_m = nan", "stage.radius_m"),
            ("centre = [0.0, inf]", "stage.centre"),
            ("facing_deg = 720", "stage.facing_deg"),
        ] {
            let e = Config::parse(&format!("[stage]\n{bad}\n"), Path::new("x.toml")).unwrap_err();
            assert!(e.to_string().contains(key), "{bad}: {e}");
        }
    }

    #[test]
    fn style_is_checked() {
        let c = Config::parse("[dancer]\nstyle = \"Rumba\"\n", Path::new("x.toml")).unwrap();
        assert_eq!(
            c.dancer.style_request(),
            StyleRequest::Style(DanceStyle::Rumba)
        );
        assert_eq!(Config::default().dancer.style_request(), StyleRequest::Auto);
        let e = Config::parse("[dancer]\nstyle = \"polka\"\n", Path::new("x.toml")).unwrap_err();
        assert!(e.to_string().contains("dancer.style"), "{e}");
    }

    #[test]
    fn foot_plant_is_checked() {
        let c = Config::parse("[dancer]\nfoot_plant = 0.3\n", Path::new("x.toml")).unwrap();
        assert_eq!(c.dancer.foot_plant, 0.3);
        for bad in ["-0.1", "1.5", "nan"] {
            let e = Config::parse(
                &format!("[dancer]\nfoot_plant = {bad}\n"),
                Path::new("x.toml"),
            )
            .unwrap_err();
            assert!(e.to_string().contains("dancer.foot_plant"), "{bad}: {e}");
        }
    }

    #[test]
    fn beat_accent_is_checked() {
        let c = Config::parse("[dancer]\nbeat_accent = 0.4\n", Path::new("x.toml")).unwrap();
        assert_eq!(c.dancer.beat_accent, 0.4);
        for bad in ["-0.1", "0.95", "nan"] {
            let e = Config::parse(
                &format!("[dancer]\nbeat_accent = {bad}\n"),
                Path::new("x.toml"),
            )
            .unwrap_err();
            assert!(e.to_string().contains("dancer.beat_accent"), "{bad}: {e}");
        }
    }
}
