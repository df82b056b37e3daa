//! `danced`: the command line.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use clap::{Parser, Subcommand, ValueEnum};
use indicatif::{ProgressBar, ProgressStyle};
use tracing_subscriber::EnvFilter;

use daemon::bench;
use daemon::offline::{AnalyzeOptions, analyze_file, analyze_samples};
use daemon::output::{beats_text, features_npy, features_sidecar, onsets_text, write_atomic};
use dsp::BeatTrackerKind;

/// Listens to music and makes a 3D character dance to it, live.
#[derive(Parser, Debug)]
#[command(name = "danced", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Analyse an audio file with the streaming analysis (beats, onsets, tempo, features).
    Analyze(AnalyzeArgs),
    /// Measure the analysis on the annotated data sets.
    Bench {
        #[command(subcommand)]
        what: BenchCommand,
    },
}

#[derive(Subcommand, Debug)]
enum BenchCommand {
    /// Beat tracking accuracy and speed: native and aubio on synth-beats, tang2018, madmom-tests.
    Beats(BenchBeatsArgs),
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
    let cli = Cli::parse();
    match cli.command {
        Command::Analyze(args) => analyze(args),
        Command::Bench {
            what: BenchCommand::Beats(args),
        } => bench_beats(args),
    }
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

fn analyze(args: AnalyzeArgs) -> Result<()> {
    let started = Instant::now();
    let pb = progress_bar(false);
    let options = AnalyzeOptions {
        tracker: args.beat_tracker.into(),
        model_rate: args.features_out.as_ref().map(|_| args.rate),
        keep_hops: args.plot.is_some(),
        beat_params: Default::default(),
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
    let pb = ProgressBar::new(total as u64);
    pb.set_style(
        ProgressStyle::with_template("{bar:40} {pos}/{len} {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
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
