//! `danced`: the command line.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use clap::{Parser, Subcommand, ValueEnum};
use indicatif::{ProgressBar, ProgressStyle};
use tracing_subscriber::EnvFilter;

use daemon::bench;
use daemon::dancer::{SourceKind, SourceSettings};
use daemon::live::config::Config;
use daemon::live_cli::{AudioSource, RunMode, run_live, summary};
use daemon::offline::{AnalyzeOptions, analyze_file, analyze_samples};
use daemon::output::{beats_text, features_npy, features_sidecar, onsets_text, write_atomic};
use daemon::progress::count_bar;
use dsp::BeatTrackerKind;

// Counts allocations in the audio callback path (see `daemon::alloc_counter`).
#[global_allocator]
static ALLOCATOR: daemon::alloc_counter::CountingAllocator =
    daemon::alloc_counter::CountingAllocator;

/// Listens to music and makes a 3D character dance to it, live.
#[derive(Parser, Debug)]
#[command(name = "danced", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Train the neural dancer on the tang2018 dances.
    Train(daemon::neural::TrainArgs),
    /// Train the learned beat activation on songs with exact beats (e.g. rendered ones).
    TrainBeats(daemon::beat_training::TrainBeatsArgs),
    /// Analyse an audio file with the streaming analysis (beats, onsets, tempo, features).
    Analyze(AnalyzeArgs),
    /// Measure the analysis on the annotated data sets.
    Bench {
        #[command(subcommand)]
        what: BenchCommand,
    },
    /// Dance to a song offline through the streaming analysis and write the motion as BVH.
    Generate(GenerateArgs),
    /// Export a tang2018 dance, fitted to the rig, as BVH.
    Bvh {
        /// Dance folder name, e.g. DANCE_W_1.
        #[arg(long)]
        dance: String,
        /// Output BVH file.
        #[arg(long)]
        out: PathBuf,
        /// The shared data folder.
        #[arg(long, default_value = "../shared/data")]
        data: PathBuf,
    },
    /// Dance metrics of a BVH motion against a song's beats (BeatAlign, beat offset, kinetic
    /// features, freezes, foot skating).
    Metrics {
        /// The motion (any BVH rig with recognisable joint names).
        bvh: PathBuf,
        /// The song the motion dances to.
        #[arg(long)]
        audio: PathBuf,
        /// Song time of the motion's first frame, seconds.
        #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
        offset: f64,
    },
    /// Dance live to the sound card (or a replayed file) and send the motion.
    Run(RunArgs),
    /// Dance live to the built-in demo song (no sound card, no files needed).
    Demo {
        /// Stop after this many seconds (runs until Ctrl-C otherwise).
        #[arg(long)]
        duration: Option<f64>,
        /// Frames sent per second.
        #[arg(long)]
        rate: Option<f64>,
        /// Write the run's stats as JSON here.
        #[arg(long)]
        stats_json: Option<PathBuf>,
        #[command(flatten)]
        dancer: SourceArgs,
    },
    /// List the audio inputs.
    Devices,
    /// The tang2018 training data: audit it.
    Dataset {
        #[command(subcommand)]
        what: DatasetCommand,
    },
    /// Score the motion sources on the validation dances' music: BeatAlign, beat offset, FPD,
    /// FMD, FID_k, Dist_k, freezes, foot skating, next to the ground truth.
    Eval {
        /// The shared data folder (holds tang2018/ and tang2018-beats/).
        #[arg(long, default_value = "../shared/data")]
        data: PathBuf,
        /// Clip library of the retrieval rows (default: the built-in one).
        #[arg(long)]
        library: Option<PathBuf>,
        /// Also score the retrieval dancer on the full library cut from the training split.
        #[arg(long)]
        full_library: bool,
        /// Neural model of the neural rows (default: the built-in one).
        #[arg(long)]
        model: Option<PathBuf>,
        /// Only the table of the validation dances (no key poses, unseen songs or long runs).
        #[arg(long)]
        quick: bool,
        /// Random seed of the generated rows.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Worker threads for loading.
        #[arg(long, default_value_t = 2)]
        jobs: usize,
    },
    /// The retrieval dancer's clip library.
    Library {
        #[command(subcommand)]
        what: LibraryCommand,
    },
}

#[derive(Subcommand, Debug)]
enum LibraryCommand {
    /// Pick the key-pose bank from the shipped clip library: the poses farthest apart, written
    /// as a BVH plus a TOML naming its frames (the shipped one is configs/poses/).
    Poses {
        /// Output folder (bank.bvh and bank.toml are written there).
        #[arg(long)]
        out: PathBuf,
        /// How many poses.
        #[arg(long, default_value_t = 16)]
        count: usize,
    },
    /// Cut the clip library from the tang2018 training split and write it (the shipped one is
    /// configs/clips/tang2018-train.danclips).
    Build {
        /// The shared data folder (holds tang2018/ and tang2018-beats/).
        #[arg(long, default_value = "../shared/data")]
        data: PathBuf,
        /// Output file.
        #[arg(long)]
        out: PathBuf,
        /// Keep at most this many poses, in runs of clips spread over the library.
        #[arg(long, default_value_t = daemon::dancer::DEFAULT_MAX_POSES)]
        max_poses: usize,
        /// Worker threads.
        #[arg(long, default_value_t = 2)]
        jobs: usize,
    },
}

#[derive(clap::Args, Debug)]
struct GenerateArgs {
    /// The song.
    #[arg(long)]
    audio: PathBuf,
    /// Output BVH file.
    #[arg(long)]
    out: PathBuf,
    #[command(flatten)]
    dancer: SourceArgs,
    /// Stop after this many seconds of audio.
    #[arg(long)]
    seconds: Option<f64>,
    /// Sampling temperature (0: always the best-matching clip).
    #[arg(long, default_value_t = 0.5)]
    temperature: f32,
    /// Random seed.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Retrieval source: cut the full clip library from this data folder's tang2018 training
    /// split instead of using a library file.
    #[arg(long, conflicts_with = "library")]
    data: Option<PathBuf>,
    /// Neural source: start from this bank pose (the "motion prompt") instead of the model's seed.
    #[arg(long)]
    seed_pose: Option<String>,
    /// Reach a key pose of the bank at a time: NAME@SECONDS (repeatable), e.g. pose-3@12.5.
    #[arg(long = "keypose")]
    key_poses: Vec<String>,
    /// Key-pose bank (TOML; default: the built-in configs/poses/bank.toml).
    #[arg(long)]
    poses: Option<PathBuf>,
    /// How long before its moment a key pose is announced to the dancer, seconds.
    #[arg(long, default_value_t = 2.0)]
    keypose_lead: f64,
}

#[derive(Subcommand, Debug)]
enum DatasetCommand {
    /// Every dance → motion features on the rig plus the streaming music features of its song,
    /// aligned, at 25 fps, split by dance into train/validation; one .npz + a .json manifest.
    Build {
        /// The shared data folder (holds tang2018/ and tang2018-beats/).
        #[arg(long, default_value = "../shared/data")]
        data: PathBuf,
        /// Output .npz file (a .json manifest is written beside it).
        #[arg(long)]
        out: PathBuf,
        /// Worker threads.
        #[arg(long, default_value_t = 2)]
        jobs: usize,
    },
    /// One row per dance: frames, seconds, rig fit error, bone-length spread, measured music
    /// offset, tempo, and the ground truth's BeatAlign and beat offset.
    Audit {
        /// The shared data folder (holds tang2018/ and tang2018-beats/).
        #[arg(long, default_value = "../shared/data")]
        data: PathBuf,
        /// Worker threads.
        #[arg(long, default_value_t = 2)]
        jobs: usize,
    },
}

#[derive(Subcommand, Debug)]
enum BenchCommand {
    /// Beat tracking accuracy and speed: native and aubio on synth-beats, tang2018, madmom-tests.
    Beats(BenchBeatsArgs),
    /// The live pipeline at 1× on a replayed file: latency, jitter, CPU, memory, drops.
    Live {
        /// Audio file (the built-in demo song, looped, without one).
        #[arg(long)]
        input: Option<PathBuf>,
        /// Seconds to run.
        #[arg(long, default_value_t = 60.0)]
        seconds: f64,
        /// Frames sent per second.
        #[arg(long, default_value_t = 60.0)]
        rate: f64,
        /// Write the stats as JSON here.
        #[arg(long)]
        stats_json: Option<PathBuf>,
        #[command(flatten)]
        dancer: SourceArgs,
    },
    /// Per-frame sampling time of the neural dancer on one thread (p50, p99).
    Model(daemon::neural::BenchModelArgs),
}

#[derive(clap::Args, Debug)]
struct RunArgs {
    /// Configuration file (see configs/danced.toml); flags override it.
    #[arg(long)]
    config: Option<PathBuf>,
    /// Replay this audio file instead of capturing.
    #[arg(long, conflicts_with = "device")]
    input: Option<PathBuf>,
    /// Capture from the first input whose name contains this text.
    #[arg(long)]
    device: Option<String>,
    /// Replay speed (audio seconds per wall second).
    #[arg(long)]
    speed: Option<f64>,
    /// Replay in a loop.
    #[arg(long = "loop")]
    looped: bool,
    /// Stop after this many seconds of audio.
    #[arg(long)]
    duration: Option<f64>,
    /// Plain OSC target host:port (repeatable).
    #[arg(long)]
    osc: Vec<String>,
    /// Send VMC to host:port.
    #[arg(long)]
    vmc: Option<String>,
    /// Send VRChat OSC trackers to host:port.
    #[arg(long)]
    vrchat: Option<String>,
    /// MIDI input port (name substring).
    #[arg(long)]
    midi: Option<String>,
    /// UDP port of the OSC control receiver.
    #[arg(long)]
    control_port: Option<u16>,
    /// Write the run's stats as JSON here.
    #[arg(long)]
    stats_json: Option<PathBuf>,
    /// Frames sent per second.
    #[arg(long)]
    rate: Option<f64>,
    /// Initial temperature (0 = the most likely motion).
    #[arg(long)]
    temperature: Option<f32>,
    /// Random seed of the dancer.
    #[arg(long)]
    seed: Option<u64>,
    /// Key-pose bank (TOML; default: the built-in configs/poses/bank.toml).
    #[arg(long)]
    poses: Option<PathBuf>,
    #[command(flatten)]
    dancer: SourceArgs,
    /// MIDI map (TOML; default: the built-in configs/midi/generic.toml).
    #[arg(long)]
    midi_map: Option<PathBuf>,
}

/// Which dancer, and from which files.
#[derive(clap::Args, Debug, Clone, Default)]
struct SourceArgs {
    /// Motion source (default: the configuration's, else the built-in default).
    #[arg(long, value_enum)]
    source: Option<SourceKind>,
    /// Neural model file (default: the built-in configs/models/default.dnn).
    #[arg(long)]
    model: Option<PathBuf>,
    /// Clip library file of the retrieval source (default: the built-in one).
    #[arg(long)]
    library: Option<PathBuf>,
    /// Depth of the neural dancer's beat accent, 0–0.9 (0: the network's own timing).
    #[arg(long)]
    beat_accent: Option<f32>,
}

impl SourceArgs {
    /// Applies the flags to `config`; a model file implies the neural source and a library
    /// the retrieval source unless a source is named.
    fn apply(&self, config: &mut Config) {
        let implied = match (&self.model, &self.library) {
            (Some(_), None) => Some(SourceKind::Neural),
            (None, Some(_)) => Some(SourceKind::Retrieval),
            _ => None,
        };
        if let Some(k) = self.source.or(implied) {
            config.dancer.source = k.name().into();
            if self.source.is_some() || implied.is_some() {
                // Files of the other source from the configuration no longer apply.
                match k {
                    SourceKind::Neural => config.dancer.library = None,
                    SourceKind::Retrieval => config.dancer.model = None,
                }
            }
        }
        if self.model.is_some() {
            config.dancer.model = self.model.clone();
        }
        if self.library.is_some() {
            config.dancer.library = self.library.clone();
        }
        if let Some(a) = self.beat_accent {
            config.dancer.beat_accent = a;
        }
    }
}

#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
enum TrackerArg {
    /// Built-in beat-pointer HMM over SuperFlux onsets.
    Native,
    /// aubio tempo/onset (GPL-3.0; needs a build with `--features aubio`).
    Aubio,
}

impl From<TrackerArg> for BeatTrackerKind {
    fn from(t: TrackerArg) -> Self {
        match t {
            TrackerArg::Native => BeatTrackerKind::Native,
            TrackerArg::Aubio => BeatTrackerKind::Aubio,
        }
    }
}

#[derive(clap::Args, Debug)]
struct AnalyzeArgs {
    /// Audio file (wav, mp3, ogg/vorbis, flac, m4a/aac). Without one, the built-in demo song
    /// (30 s, 124 BPM, 4/4, synthesised in code) is analysed.
    audio: Option<PathBuf>,
    /// Beat and onset tracker.
    #[arg(long, value_enum, default_value_t = TrackerArg::Native)]
    beat_tracker: TrackerArg,
    /// Write beats here: `time_s<TAB>beat_in_bar<TAB>decided_at_s` per line.
    #[arg(long)]
    beats_out: Option<PathBuf>,
    /// Write onsets here: one time in seconds per line.
    #[arg(long)]
    onsets_out: Option<PathBuf>,
    /// Write model features here as float32 .npy [frames, 83] (+ a .json sidecar with the layout).
    #[arg(long)]
    features_out: Option<PathBuf>,
    /// Model frame rate for --features-out, Hz.
    #[arg(long, default_value_t = 30.0)]
    rate: f64,
    /// Draw onset strength, onsets, beats with decision lag, tempo and bar phase to a PNG.
    #[arg(long)]
    plot: Option<PathBuf>,
}

#[derive(clap::Args, Debug)]
struct BenchBeatsArgs {
    /// The shared data folder.
    #[arg(long, default_value = "../shared/data")]
    data: PathBuf,
    /// Trackers to compare (default: native, plus aubio when built in).
    #[arg(long, value_enum)]
    tracker: Vec<TrackerArg>,
    /// Only these sets (synth-beats, tang2018, madmom-tests).
    #[arg(long)]
    set: Vec<String>,
    /// Worker threads (each file is analysed on one thread).
    #[arg(long, default_value_t = 2)]
    jobs: usize,
    /// Print a row per file.
    #[arg(long)]
    verbose: bool,
    /// Override native tracker tuning, e.g. `observation_beta=1.5,prior_octaves=0.8` (for tuning).
    #[arg(long, default_value = "")]
    beat_params: String,
}

fn main() -> Result<()> {
    tracing_subscriber::fmt()
        .with_env_filter(
            EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new("warn")),
        )
        .with_writer(std::io::stderr)
        .init();
    daemon::alloc_counter::mark_installed();
    let cli = Cli::parse();
    match cli.command {
        Command::Analyze(args) => analyze(args),
        Command::Train(args) => daemon::neural::train(&args),
        Command::TrainBeats(args) => daemon::beat_training::train_beats(&args),
        Command::Bench {
            what: BenchCommand::Model(args),
        } => daemon::neural::bench_model(&args),
        Command::Bench {
            what: BenchCommand::Beats(args),
        } => bench_beats(args),
        Command::Dataset {
            what: DatasetCommand::Audit { data, jobs },
        } => dataset_audit(&data, jobs),
        Command::Dataset {
            what: DatasetCommand::Build { data, out, jobs },
        } => dataset_build(&data, &out, jobs),
        Command::Bvh { dance, out, data } => export_dance(&data, &dance, &out),
        Command::Generate(args) => generate(&args),
        Command::Metrics { bvh, audio, offset } => motion_metrics(&bvh, &audio, offset),
        Command::Eval {
            data,
            library,
            full_library,
            model,
            quick,
            seed,
            jobs,
        } => eval(&EvalOptions {
            data: &data,
            library: library.as_deref(),
            model: model.as_deref(),
            full_library,
            quick,
            seed,
            jobs,
        }),
        Command::Library {
            what:
                LibraryCommand::Build {
                    data,
                    out,
                    max_poses,
                    jobs,
                },
        } => library_build(&data, &out, max_poses, jobs),
        Command::Library {
            what: LibraryCommand::Poses { out, count },
        } => library_poses(&out, count),
        Command::Run(args) => run(args),
        Command::Demo {
            duration,
            rate,
            stats_json,
            dancer,
        } => {
            let mut config = Config::default();
            dancer.apply(&mut config);
            config.audio.duration = duration;
            config.stats_json = stats_json;
            if let Some(r) = rate {
                config.output.rate_hz = r;
            }
            config.validate("command line")?;
            let report = run_live(&config, AudioSource::Demo, RunMode::Interactive)?;
            println!("{}", summary(&report));
            Ok(())
        }
        Command::Devices => {
            println!("audio inputs:");
            for line in daemon::live::devices::list_inputs() {
                println!("  {line}");
            }
            println!("MIDI inputs:");
            for line in daemon::live::devices::list_midi() {
                println!("  {line}");
            }
            Ok(())
        }
        Command::Bench {
            what:
                BenchCommand::Live {
                    input,
                    seconds,
                    rate,
                    stats_json,
                    dancer,
                },
        } => {
            let mut config = Config::default();
            dancer.apply(&mut config);
            config.audio.duration = Some(seconds);
            config.audio.looped = true;
            config.output.rate_hz = rate;
            config.stats_json = stats_json;
            // A benchmark takes no control and must not hold the performer's control port.
            config.control.osc_port = 0;
            config.validate("command line")?;
            let audio = input.map_or(AudioSource::Demo, AudioSource::File);
            eprintln!("running the live pipeline at 1× for {seconds} s...");
            let report = run_live(&config, audio, RunMode::Quiet)?;
            println!("{}", summary(&report));
            Ok(())
        }
    }
}

fn run(args: RunArgs) -> Result<()> {
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
    config.validate("command line")?;
    let audio = match (&config.audio.input, &config.audio.device) {
        (Some(i), _) => AudioSource::File(i.clone()),
        (None, d) => AudioSource::Capture(d.clone()),
    };
    let report = run_live(&config, audio, RunMode::Interactive)?;
    println!("{}", summary(&report));
    Ok(())
}

fn progress_bar(hidden: bool) -> ProgressBar {
    if hidden {
        return ProgressBar::hidden();
    }
    let pb = ProgressBar::new(0);
    pb.set_style(
        ProgressStyle::with_template("{spinner} [{bar:40}] {pos}/{len} s of audio ({eta})")
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    pb
}

/// A bar counting finished items, with the current one's name as its message.
fn analyze(args: AnalyzeArgs) -> Result<()> {
    let started = Instant::now();
    let pb = progress_bar(false);
    let options = AnalyzeOptions {
        tracker: args.beat_tracker.into(),
        model_rate: args.features_out.as_ref().map(|_| args.rate),
        keep_hops: args.plot.is_some(),
        ..AnalyzeOptions::default()
    };
    let name = match &args.audio {
        Some(p) => p.display().to_string(),
        None => format!(
            "built-in demo song ({} BPM, 4/4)",
            daemon::demo_track::DEMO_BPM
        ),
    };
    let result = match &args.audio {
        Some(path) => analyze_file(path, options, &mut |done, total| {
            // Only long files get a visible bar: a short one is done before it would be read.
            if let Some(total) = total
                && total > 60.0
            {
                pb.set_length(total as u64);
                pb.set_position(done as u64);
            }
        }),
        None => {
            let demo = daemon::demo_track::demo_track(30.0);
            analyze_samples(
                &name,
                &demo.samples,
                daemon::demo_track::DEMO_RATE,
                2,
                options,
            )
        }
    };
    pb.finish_and_clear();
    let a = result.with_context(|| format!("analysing {name}"))?;

    if let Some(p) = &args.beats_out {
        write_atomic(p, beats_text(&a.beats).as_bytes())
            .with_context(|| format!("writing {}", p.display()))?;
    }
    if let Some(p) = &args.onsets_out {
        write_atomic(p, onsets_text(&a.onsets).as_bytes())
            .with_context(|| format!("writing {}", p.display()))?;
    }
    if let Some(p) = &args.features_out {
        write_atomic(p, &features_npy(&a.features))
            .with_context(|| format!("writing {}", p.display()))?;
        let sidecar = p.with_extension("json");
        let short = dsp::SHORT_WINDOW as f64 / 2.0 / dsp::ANALYSIS_RATE as f64;
        let long = dsp::LONG_WINDOW as f64 / 2.0 / dsp::ANALYSIS_RATE as f64;
        write_atomic(
            &sidecar,
            features_sidecar(args.rate, a.features.len(), short, long).as_bytes(),
        )
        .with_context(|| format!("writing {}", sidecar.display()))?;
    }
    if let Some(p) = &args.plot {
        let title = format!(
            "{name} — {}",
            args.beat_tracker
                .to_possible_value()
                .map(|v| v.get_name().to_string())
                .unwrap_or_default()
        );
        daemon::plot::plot_analysis(&a, &title, p)?;
    }

    let late = a
        .beats
        .iter()
        .filter(|b| b.decided_at_s - b.time_s > bench::MAX_DECISION_LAG_S)
        .count();
    let downbeats = a.beats.iter().filter(|b| b.beat_in_bar == 1).count();
    let meter = a.beats.last().map(|b| b.beats_per_bar).unwrap_or(0);
    println!("audio file  {name}");
    println!(
        "audio       {:.1} s, {} Hz, {} ch",
        a.duration_s, a.sample_rate, a.channels
    );
    println!(
        "tempo       {:.1} BPM (median over beats)",
        a.median_tempo()
    );
    println!(
        "beats       {} ({} downbeats, {}/4 at the end, {} decided > 50 ms late)",
        a.beats.len(),
        downbeats,
        meter,
        late
    );
    println!("onsets      {}", a.onsets.len());
    if args.features_out.is_some() {
        println!(
            "features    {} frames at {} Hz, layout v{}",
            a.features.len(),
            args.rate,
            dsp::feature::FEATURE_LAYOUT_VERSION
        );
    }
    println!(
        "speed       {:.0}× real time (analysis), {:.0}× (decode), {:.2} s wall",
        a.realtime_factor(),
        a.duration_s / a.decode_time.as_secs_f64().max(1e-9),
        started.elapsed().as_secs_f64()
    );
    if a.skipped_packets > 0 {
        println!(
            "warning     {} undecodable packets were skipped",
            a.skipped_packets
        );
    }
    Ok(())
}

fn bench_beats(args: BenchBeatsArgs) -> Result<()> {
    if !args.data.is_dir() {
        bail!(
            "data folder {} not found (pass --data DIR; see the README's Data section)",
            args.data.display()
        );
    }
    let trackers: Vec<BeatTrackerKind> = if args.tracker.is_empty() {
        let mut v = vec![BeatTrackerKind::Native];
        if cfg!(feature = "aubio") {
            v.push(BeatTrackerKind::Aubio);
        }
        v
    } else {
        args.tracker.iter().map(|&t| t.into()).collect()
    };
    let sets: Vec<bench::BenchSet> = [
        bench::synth_set(&args.data),
        bench::tang_set(&args.data),
        bench::madmom_set(&args.data),
    ]
    .into_iter()
    .filter(|s| args.set.is_empty() || args.set.iter().any(|n| n == s.name))
    .filter(|s| !s.items.is_empty())
    .collect();
    if sets.is_empty() {
        bail!("no annotated audio found under {}", args.data.display());
    }
    let params = dsp::beat::BeatTrackerParams::default()
        .with_overrides(&args.beat_params)
        .map_err(anyhow::Error::msg)?;
    let total: usize = sets.iter().map(|s| s.items.len()).sum::<usize>() * trackers.len();
    let pb = count_bar(total as u64);
    let mut rows = Vec::new();
    let mut details = String::new();
    for &tracker in &trackers {
        let mut row = vec![tracker.name().to_string()];
        let mut all = Vec::new();
        for set in &sets {
            let scores = bench::run_set(set, tracker, params, args.jobs, &|name| {
                pb.set_message(name.to_string());
                pb.inc(1);
            });
            for s in scores.iter().filter(|s| s.error.is_some()) {
                pb.println(format!(
                    "{} {}: {}",
                    set.name,
                    s.name,
                    s.error.as_deref().unwrap_or("")
                ));
            }
            let mut extra = String::new();
            if scores.iter().any(|s| s.downbeat_f.is_some()) {
                extra += &format!(
                    ", downbeat F {:.3}",
                    bench::mean(&scores, |s| s.downbeat_f.unwrap_or(0.0))
                );
            }
            if scores.iter().any(|s| s.onset_f.is_some()) {
                extra += &format!(
                    ", onset F {:.3}",
                    bench::mean(&scores, |s| s.onset_f.unwrap_or(0.0))
                );
            }
            row.push(format!(
                "{:.3} / {:.3} / {:.3}{extra}",
                bench::mean(&scores, |s| s.f_measure),
                bench::mean(&scores, |s| s.cmlt),
                bench::mean(&scores, |s| s.amlt)
            ));
            if args.verbose {
                details.push_str(&bench::detail_table(set, tracker, &scores));
            }
            all.extend(scores);
        }
        row.push(format!("{:.0}", bench::speed(&all)));
        rows.push(row);
    }
    pb.finish_and_clear();
    print!("{details}");
    println!();
    println!(
        "Beats decided ≤ {:.0} ms after they happen; mean F / CMLt / AMLt (±70 ms, first 5 s skipped).",
        bench::MAX_DECISION_LAG_S * 1000.0
    );
    let header: Vec<String> = sets
        .iter()
        .map(|s| format!("{} ({} files)", s.name, s.items.len()))
        .collect();
    println!(
        "| tracker | {} | × real time (one core) |",
        header.join(" | ")
    );
    println!("|---{}|---|", "|---".repeat(sets.len()));
    for row in rows {
        println!("| {} |", row.join(" | "));
    }
    Ok(())
}

fn dataset_audit(data: &std::path::Path, jobs: usize) -> Result<()> {
    if !data.join("tang2018").is_dir() {
        bail!(
            "{} not found (pass --data DIR; see the README's Data section)",
            data.join("tang2018").display()
        );
    }
    let pb = count_bar(
        model::tang2018::dance_dirs(&data.join("tang2018")).map_or(0, |d| d.len() as u64),
    );
    let started = Instant::now();
    let rows = daemon::dataset::audit(data, jobs, &|name| {
        pb.set_message(name.to_string());
        pb.inc(1);
    })
    .with_context(|| format!("reading {}", data.display()))?;
    pb.finish_and_clear();
    print!("{}", daemon::dataset::audit_table(&rows));
    for r in rows.iter().filter(|r| r.problem.is_some() && r.frames > 0) {
        eprintln!("{}: {}", r.name, r.problem.as_deref().unwrap_or(""));
    }
    eprintln!(
        "audited {} dances in {:.1} s",
        rows.len(),
        started.elapsed().as_secs_f64()
    );
    Ok(())
}

fn export_dance(data: &std::path::Path, dance: &str, out: &std::path::Path) -> Result<()> {
    let dir = data.join("tang2018").join(dance);
    let d = model::tang2018::load_dance(&dir)
        .with_context(|| format!("reading dance {}", dir.display()))?;
    let fit =
        model::tang_fit::fit_dance(&d).with_context(|| format!("fitting the rig to {dance}"))?;
    let bvh = model::bvh::export(&fit.skeleton, &fit.poses, fit.fps);
    bvh.write(out)
        .with_context(|| format!("writing {}", out.display()))?;
    println!(
        "{dance}: {} frames at {} fps, fit error {:.2} cm → {}",
        fit.poses.len(),
        fit.fps,
        fit.mean_error_cm,
        out.display()
    );
    Ok(())
}

fn motion_metrics(bvh_path: &std::path::Path, audio: &std::path::Path, offset: f64) -> Result<()> {
    use model::metrics::{ContactParams, FreezeParams, JointTrack};
    use model::rig::{JOINT_COUNT, Joint, Skeleton};
    let bvh = model::bvh::Bvh::read(bvh_path)?;
    let skeleton = Skeleton::default_adult();
    let motion = model::bvh::retarget(&bvh, &skeleton, &Default::default())
        .with_context(|| format!("retargeting {} onto the rig", bvh_path.display()))?;
    let positions = skeleton.trajectory(&motion.poses);
    let track = JointTrack::new(&positions, JOINT_COUNT, motion.fps)?;
    let opts = AnalyzeOptions::native(None);
    let a = analyze_file(audio, opts, &mut |_, _| {})
        .with_context(|| format!("analysing {}", audio.display()))?;
    let beats: Vec<f64> = a
        .beats
        .iter()
        .map(|b| b.time_s - offset)
        .filter(|t| *t >= 0.0)
        .collect();
    println!(
        "motion      {} ({} frames at {:.2} fps, {:.1} s)",
        bvh_path.display(),
        track.frames(),
        track.fps(),
        track.duration_s()
    );
    println!(
        "music       {} ({} beats in the motion's span, {:.1} BPM)",
        audio.display(),
        beats.iter().filter(|t| **t <= track.duration_s()).count(),
        a.median_tempo()
    );
    println!(
        "BeatAlign   {:.3}",
        model::metrics::beat_align(&track, &beats)
    );
    match model::metrics::beat_offset(&track, Joint::Hips.index(), &beats) {
        Ok(o) => println!("beat offset {:.3} ± {:.3} s", o.mean_s, o.sd_s),
        Err(e) => println!("beat offset – ({e})"),
    }
    let kinetic = model::metrics::kinetic_features(&track)?;
    let energy: f64 = kinetic.iter().sum::<f64>() / kinetic.len().max(1) as f64;
    println!(
        "kinetic     mean feature {energy:.4} over {} values",
        kinetic.len()
    );
    let f = model::metrics::detect_freezes(&track, FreezeParams::default())?;
    println!(
        "freezes     {} ({:.1} s frozen of {:.1} s)",
        f.freezes, f.frozen_s, f.analysed_s
    );
    let toes = [Joint::LeftToes.index(), Joint::RightToes.index()];
    let ground_y_m = model::metrics::toe_floor_y(&track, &toes)?;
    let s = model::metrics::foot_skating(
        &track,
        &toes,
        ContactParams {
            ground_y_m,
            ..ContactParams::default()
        },
    )?;
    println!(
        "foot skate  {:.3} m/s while in contact ({:.0} % of the time; floor at {ground_y_m:.3} m)",
        s.mean_speed_mps,
        100.0 * s.contact_fraction
    );
    Ok(())
}

fn dataset_build(data: &std::path::Path, out: &std::path::Path, jobs: usize) -> Result<()> {
    let started = Instant::now();
    let results = daemon::dataset::build_all(data, jobs, |_, _| true, true)?;
    let mut built = Vec::new();
    let mut skipped = Vec::new();
    for (name, r) in results {
        match r {
            Ok(d) => built.push(d),
            Err(e) => skipped.push(format!("{name}: {e}")),
        }
    }
    if built.is_empty() {
        bail!(
            "no dance could be built from {}",
            data.join("tang2018").display()
        );
    }
    daemon::dataset::write_dataset(out, &built).map_err(anyhow::Error::msg)?;
    let frames = |v: bool| {
        built
            .iter()
            .filter(|d| d.validation == v)
            .map(|d| d.motion.len())
            .sum::<usize>()
    };
    let with_music = built.iter().filter(|d| !d.music.is_empty()).count();
    println!(
        "wrote {} ({} dances, {} with music; train {} frames, validation {} frames: {}) in {:.1} s",
        out.display(),
        built.len(),
        with_music,
        frames(false),
        frames(true),
        built
            .iter()
            .filter(|d| d.validation)
            .map(|d| d.name.as_str())
            .collect::<Vec<_>>()
            .join(" "),
        started.elapsed().as_secs_f64()
    );
    for s in &skipped {
        eprintln!("skipped {s}");
    }
    Ok(())
}

/// What `danced eval` scores.
struct EvalOptions<'a> {
    data: &'a std::path::Path,
    library: Option<&'a std::path::Path>,
    model: Option<&'a std::path::Path>,
    full_library: bool,
    quick: bool,
    seed: u64,
    jobs: usize,
}

fn eval(o: &EvalOptions<'_>) -> Result<()> {
    use daemon::eval::{KEY_HORIZONS_S, LONG_RUN_S};
    const NO_ACCENT: &str = "neural, no beat accent";
    const FRESH_NOISE: &str = "neural, independent noise";
    const NO_FOOT_LOCK: &str = "neural, no foot lock";
    use model::source::MotionSource;
    let started = Instant::now();
    let set = daemon::eval::EvalSet::load(o.data, o.jobs)?;
    eprintln!(
        "validation dances: {} (loaded in {:.1} s)",
        set.validation_names().join(" "),
        started.elapsed().as_secs_f64()
    );
    let gt = set.ground_truth();
    let mut rows = vec![set.score("ground truth", &gt)?];
    let mut libraries = vec![("retrieval", daemon::dancer::load_library(o.library)?.0)];
    if o.full_library {
        libraries.push((
            "retrieval, full library",
            daemon::dancer::training_library(o.data, o.jobs)?.0,
        ));
    }
    let temperatures = [0.0f32, 0.5, 1.0];
    let mut sources: Vec<(String, Box<dyn MotionSource>)> = Vec::new();
    for (name, lib) in libraries {
        sources.push((name.to_string(), Box::new(daemon::eval::retrieval(lib)?)));
    }
    let model = daemon::dancer::load_model(o.model)?;
    sources.push((
        "neural".into(),
        Box::new(daemon::dancer::neural_dancer(&model, o.seed)?),
    ));
    // Ablations: the network's own timing, a fresh noise draw every frame, free feet.
    let mut own_timing = daemon::dancer::neural_dancer(&model, o.seed)?;
    own_timing.set_beat_accent(0.0);
    sources.push((NO_ACCENT.into(), Box::new(own_timing)));
    let mut fresh_noise = daemon::dancer::neural_dancer(&model, o.seed)?;
    fresh_noise.set_noise_correlation(0.0);
    sources.push((FRESH_NOISE.into(), Box::new(fresh_noise)));
    let mut free_feet = daemon::dancer::neural_dancer(&model, o.seed)?;
    free_feet.set_foot_lock(0.0);
    sources.push((NO_FOOT_LOCK.into(), Box::new(free_feet)));
    let ablation = |name: &str| [NO_ACCENT, FRESH_NOISE, NO_FOOT_LOCK].contains(&name);
    for (name, dancer) in sources.iter_mut() {
        for t in temperatures {
            let (motions, us) = set.generate(dancer.as_mut(), t, o.seed);
            let label = format!("{name} T={t}");
            eprintln!("{label}: {us:.1} µs per frame");
            rows.push(set.score(&label, &motions)?);
        }
    }
    print!("{}", daemon::eval::table(&rows));
    if o.quick {
        eprintln!("eval took {:.1} s", started.elapsed().as_secs_f64());
        return Ok(());
    }
    // Key poses: mean joint error at the target frame against the transition length.
    let bank: Vec<_> = daemon::pose_bank::PoseBank::shipped()?
        .poses()
        .iter()
        .map(|p| p.rotations)
        .collect();
    let mut key_table =
        String::from("\n| system (key-pose error at the target frame, cm), announced");
    for h in KEY_HORIZONS_S {
        key_table += &format!(" | {h} s ahead");
    }
    key_table += " | cues |\n| --- |";
    key_table += &" --- |".repeat(KEY_HORIZONS_S.len() + 1);
    key_table += "\n";
    let mut unaided = daemon::dancer::neural_dancer(&model, o.seed)?;
    unaided.set_key_blend_frames(0);
    let mut key_sources: Vec<(String, &mut dyn MotionSource)> = sources
        .iter_mut()
        .filter(|(n, _)| !n.contains("full") && !ablation(n))
        .map(|(n, d)| (n.clone(), d.as_mut() as &mut dyn MotionSource))
        .collect();
    key_sources.push(("neural without the final blend".into(), &mut unaided));
    for (name, dancer) in key_sources {
        for t in [0.0f32, 0.5] {
            key_table += &format!("| {name} T={t} |");
            let mut cues = 0;
            for h in KEY_HORIZONS_S {
                let (e, n) = set.key_pose_error(&mut *dancer, t, o.seed, &bank, h);
                key_table += &format!(" {e:.2} |");
                cues = n;
            }
            key_table += &format!(" {cues} |\n");
        }
    }
    print!("{key_table}");
    // Long runs: no freeze over five minutes on any song.
    println!(
        "\n| system | freezes in {:.0} min on each validation song (looped) | songs with a freeze |\n| --- | --- | --- |",
        LONG_RUN_S / 60.0
    );
    for (name, dancer) in sources
        .iter_mut()
        .filter(|(n, _)| !n.contains("full") && !ablation(n))
    {
        for t in temperatures {
            let r = set.long_run_freezes(dancer.as_mut(), t, o.seed)?;
            println!(
                "| {name} T={t} | {} | {} of {} |",
                r.freezes,
                r.songs_with_freezes,
                set.validation_names().len()
            );
        }
    }
    // Songs in no training dance, with exact beats: the music-side metrics only.
    match daemon::eval::MusicSet::load(o.data) {
        Ok(music) => {
            let mut music_rows = Vec::new();
            for (name, dancer) in sources.iter_mut().filter(|(n, _)| !n.contains("full")) {
                for t in temperatures {
                    music_rows.push(music.score(
                        &format!("{name} T={t}"),
                        dancer.as_mut(),
                        t,
                        o.seed,
                    )?);
                }
            }
            println!(
                "\nsynth-beats ({} songs in no training dance, exact beats):",
                music_rows.first().map_or(0, |r| r.songs)
            );
            print!("{}", daemon::eval::music_table(&music_rows));
        }
        Err(e) => eprintln!("synth-beats skipped: {e:#}"),
    }
    eprintln!("eval took {:.1} s", started.elapsed().as_secs_f64());
    Ok(())
}

fn library_poses(out: &std::path::Path, count: usize) -> Result<()> {
    use daemon::pose_bank::{bank_toml, pick_diverse_poses};
    let (library, _) = daemon::dancer::load_library(None)?;
    let poses = pick_diverse_poses(&library, count);
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let skeleton = model::rig::Skeleton::default_adult();
    let bvh = out.join("bank.bvh");
    model::bvh::export(&skeleton, &poses, 1.0)
        .write(&bvh)
        .with_context(|| format!("writing {}", bvh.display()))?;
    let toml = out.join("bank.toml");
    write_atomic(&toml, bank_toml(&poses, "bank.bvh").as_bytes())
        .with_context(|| format!("writing {}", toml.display()))?;
    for (i, p) in poses.iter().enumerate() {
        println!("pose-{}: {}", i + 1, daemon::pose_bank::describe(p));
    }
    Ok(())
}

fn library_build(
    data: &std::path::Path,
    out: &std::path::Path,
    max_poses: usize,
    jobs: usize,
) -> Result<()> {
    let started = Instant::now();
    let (full, names) = daemon::dancer::training_library(data, jobs)?;
    let library = full.subset(max_poses);
    let meta = daemon::dancer::library_metadata(&library, &names, full.poses.len());
    let bytes = library.to_bytes(&meta);
    write_atomic(out, &bytes).with_context(|| format!("writing {}", out.display()))?;
    println!(
        "{}: {} clips, {} poses ({:.2} MB) from {} training dances (full library {} clips, {} poses) in {:.1} s",
        out.display(),
        library.clips.len(),
        library.poses.len(),
        bytes.len() as f64 / 1e6,
        names.len(),
        full.clips.len(),
        full.poses.len(),
        started.elapsed().as_secs_f64()
    );
    Ok(())
}

fn generate(args: &GenerateArgs) -> Result<()> {
    use model::source::{Controls, MotionSource};
    let GenerateArgs {
        audio,
        out,
        dancer: source_args,
        seconds,
        temperature,
        seed,
        data,
        key_poses,
        poses: bank_path,
        keypose_lead,
        seed_pose,
    } = args;
    let (seconds, temperature, seed) = (*seconds, *temperature, *seed);
    let fps = model::retrieval::RETRIEVAL_FPS;
    let needs_bank = !key_poses.is_empty() || seed_pose.is_some();
    let bank = match (needs_bank, bank_path) {
        (false, _) => daemon::pose_bank::PoseBank::default(),
        (true, Some(p)) => daemon::pose_bank::PoseBank::load(p)?,
        (true, None) => daemon::pose_bank::PoseBank::shipped()?,
    };
    let bank_pose = |name: &str| -> Result<&daemon::pose_bank::NamedPose> {
        bank.get(name).with_context(|| {
            let names: Vec<&str> = bank.poses().iter().map(|p| p.name.as_str()).collect();
            format!(
                "key pose {name:?} is not in the bank (it has {})",
                names.join(", ")
            )
        })
    };
    let mut cues = Vec::new();
    for spec in key_poses {
        let (name, at) = daemon::key_cue::parse_cue_spec(spec)?;
        let rotations = bank_pose(&name)?.rotations;
        cues.push(daemon::key_cue::KeyCue {
            name,
            rotations,
            frame: (at * fps).round() as usize,
        });
    }
    let lead_frames = (keypose_lead.max(0.0) * fps).round() as usize;
    let mut config = Config::default();
    source_args.apply(&mut config);
    let kind = if data.is_some() {
        SourceKind::Retrieval
    } else {
        SourceKind::parse(&config.dancer.source).unwrap_or(SourceKind::DEFAULT)
    };
    if seed_pose.is_some() && kind != SourceKind::Neural {
        bail!("--seed-pose is for the neural source");
    }
    let started = Instant::now();
    let mut dancer: Box<dyn MotionSource> = match (kind, data) {
        // The full library, cut from the training split now (slow, needs ../shared).
        (SourceKind::Retrieval, Some(data)) => Box::new(
            model::retrieval::RetrievalDancer::new(
                daemon::dancer::training_library(data, 2)?.0,
                seed,
            )
            .context("starting the retrieval dancer")?,
        ),
        (SourceKind::Neural, _) if seed_pose.is_some() => {
            let model = daemon::dancer::load_model(config.dancer.model.as_deref())?;
            let mut d = daemon::dancer::neural_dancer(&model, seed)?;
            d.set_beat_accent(config.dancer.beat_accent);
            if let Some(name) = seed_pose {
                d.set_seed_pose(&daemon::dancer::standing_features(
                    &bank_pose(name)?.rotations,
                ));
                d.reset(seed);
            }
            Box::new(d)
        }
        _ => daemon::dancer::open_source(
            kind,
            &SourceSettings {
                model: config.dancer.model.as_deref(),
                library: config.dancer.library.as_deref(),
                beat_accent: Some(config.dancer.beat_accent),
            },
            seed,
        )?,
    };
    let load_s = started.elapsed().as_secs_f64();
    let opts = AnalyzeOptions::native(Some(dancer.frame_rate()));
    let a = analyze_file(audio, opts, &mut |_, _| {})
        .with_context(|| format!("analysing {}", audio.display()))?;
    let limit = seconds.map_or(usize::MAX, |s| (s * dancer.frame_rate()) as usize);
    let music: Vec<[f32; dsp::feature::FEATURE_DIM]> =
        a.features.iter().map(|f| f.values).collect();
    let look = dancer.lookahead_frames();
    let mut pose = model::rig::Pose::rest();
    let mut poses = Vec::with_capacity(music.len().min(limit));
    let step_start = Instant::now();
    for i in 0..music.len().min(limit) {
        let controls = Controls {
            temperature,
            key_pose: daemon::key_cue::target_at(&cues, i, lead_frames),
            beat_accent: None,
        };
        // The frame and its look-ahead, as the live pipeline hands them over (shorter at the end).
        let window = &music[i..(i + look + 1).min(music.len())];
        dancer.step(window, &controls, &mut pose);
        poses.push(pose);
    }
    let step_s = step_start.elapsed().as_secs_f64();
    for c in &cues {
        match poses.get(c.frame) {
            Some(p) => println!(
                "key pose {} at {:.2} s: mean joint error {:.2} cm",
                c.name,
                c.frame as f64 / fps,
                daemon::key_cue::key_pose_error_cm(p, &c.rotations)
            ),
            None => println!("key pose {} lies after the end of the motion", c.name),
        }
    }
    let skeleton = model::rig::Skeleton::default_adult();
    model::bvh::export(&skeleton, &poses, dancer.frame_rate())
        .write(out)
        .with_context(|| format!("writing {}", out.display()))?;
    println!(
        "{}: {} frames ({:.1} s) at {} fps by the {} dancer → {} (loaded in {:.1} s, {:.1} µs per frame)",
        audio.display(),
        poses.len(),
        poses.len() as f64 / dancer.frame_rate(),
        dancer.frame_rate(),
        kind.name(),
        out.display(),
        load_s,
        1e6 * step_s / poses.len().max(1) as f64
    );
    Ok(())
}
