//! `danced run`: dance live to the sound card (or a replayed file) and send the motion.

use std::path::PathBuf;

use anyhow::Result;

use crate::command::clock_args::ClockArgs;
use crate::command::source::SourceArgs;
use crate::command::view_flag::ViewFlag;
use crate::live::config::Config;
use crate::live::run::{AudioSource, RunMode, run_live, summary};

#[derive(clap::Args, Debug)]
/// Options of `danced run`.
pub struct RunArgs {
    /// Configuration file (see configs/danced.toml); flags override it.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Replay this audio file instead of capturing.
    #[arg(long, conflicts_with = "device")]
    pub input: Option<PathBuf>,
    /// Capture from the first input whose name contains this text.
    #[arg(long)]
    pub device: Option<String>,
    /// Capture inputs to hear, 1-based, e.g. `1,2` or `3-4` (default 1 and 2; more than two
    /// are averaged to mono).
    #[arg(long)]
    pub channels: Option<String>,
    /// Replay speed (audio seconds per wall second).
    #[arg(long)]
    pub speed: Option<f64>,
    /// Replay in a loop.
    #[arg(long = "loop")]
    pub looped: bool,
    /// Stop after this many seconds of audio.
    #[arg(long)]
    pub duration: Option<f64>,
    /// Plain OSC target host:port (repeatable).
    #[arg(long)]
    pub osc: Vec<String>,
    /// Send VMC to host:port.
    #[arg(long)]
    pub vmc: Option<String>,
    /// Send VRChat OSC trackers to host:port.
    #[arg(long)]
    pub vrchat: Option<String>,
    /// MIDI input port (name substring).
    #[arg(long)]
    pub midi: Option<String>,
    /// UDP port of the OSC control receiver.
    #[arg(long)]
    pub control_port: Option<u16>,
    /// Write the run's stats as JSON here.
    #[arg(long)]
    pub stats_json: Option<PathBuf>,
    /// Frames sent per second.
    #[arg(long)]
    pub rate: Option<f64>,
    /// Show the dancer this many ms ahead of the heard music, to cancel a renderer's or LED
    /// wall's display latency (may be negative; default 0).
    #[arg(long, allow_hyphen_values = true)]
    pub lead_ms: Option<f64>,
    /// Initial temperature (0 = the most likely motion).
    #[arg(long)]
    pub temperature: Option<f32>,
    /// Random seed of the dancer.
    #[arg(long)]
    pub seed: Option<u64>,
    /// Key-pose bank (TOML; default: the built-in configs/poses/bank.toml).
    #[arg(long)]
    pub poses: Option<PathBuf>,
    /// The dancer.
    #[command(flatten)]
    pub dancer: SourceArgs,
    /// Where the browser view is served, if anywhere.
    #[command(flatten)]
    pub view: ViewFlag,
    /// Where the beat grid comes from, and the clocks danced leads.
    #[command(flatten)]
    pub clock: ClockArgs,
    /// MIDI map (TOML; default: the built-in configs/midi/generic.toml).
    #[arg(long)]
    pub midi_map: Option<PathBuf>,
}

/// Runs `danced run`.
pub fn run(args: RunArgs) -> Result<()> {
    let mut config = match &args.config {
        Some(p) => Config::load(p)?,
        None => Config::default(),
    };
    if let Some(i) = args.input {
        config.audio.input = Some(i);
        config.audio.device = None;
    }
    if let Some(d) = args.device {
        config.audio.device = Some(d);
        config.audio.input = None;
    }
    if let Some(c) = &args.channels {
        let list = crate::live::input_mix::parse_channel_list(c).map_err(anyhow::Error::msg)?;
        config.audio.channels = Some(list);
    }
    if let Some(s) = args.speed {
        config.audio.speed = s;
    }
    config.audio.looped |= args.looped;
    if args.duration.is_some() {
        config.audio.duration = args.duration;
    }
    if !args.osc.is_empty() {
        config.output.osc = args.osc;
    }
    if let Some(v) = args.vmc {
        config.output.vmc.enabled = true;
        config.output.vmc.target = v;
    }
    if let Some(v) = args.vrchat {
        config.output.vrchat.enabled = true;
        config.output.vrchat.target = v;
    }
    if args.midi.is_some() {
        config.control.midi_port = args.midi;
    }
    if let Some(p) = args.control_port {
        config.control.osc_port = p;
    }
    if args.stats_json.is_some() {
        config.stats_json = args.stats_json;
    }
    if let Some(r) = args.rate {
        config.output.rate_hz = r;
    }
    if let Some(l) = args.lead_ms {
        config.output.lead_ms = l;
    }
    if let Some(t) = args.temperature {
        config.dancer.temperature = t;
    }
    if let Some(s) = args.seed {
        config.dancer.seed = s;
    }
    if args.poses.is_some() {
        config.control.poses = args.poses;
    }
    if args.midi_map.is_some() {
        config.control.midi_map = args.midi_map;
    }
    args.dancer.apply(&mut config);
    args.view.apply(&mut config);
    args.clock.apply(&mut config);
    config.validate("command line")?;
    let audio = match (&config.audio.input, &config.audio.device) {
        (Some(i), _) => AudioSource::File(i.clone()),
        (None, d) => AudioSource::Capture(d.clone()),
    };
    let report = run_live(&config, audio, RunMode::Interactive)?;
    println!("{}", summary(&report));
    Ok(())
}
