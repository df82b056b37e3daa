//! `danced analyze`: one file (or the demo song) through the streaming analysis, to text, `.npy`
//! and a plot.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result};
use clap::ValueEnum;
use offline::analysis::{AnalyzeOptions, analyze_file, analyze_samples};
use offline::files::{beats_text, features_npy, features_sidecar, onsets_text, write_atomic};
use offline::progress::audio_bar;

use crate::bench::beats::MAX_DECISION_LAG_S;
use crate::command::tracker::TrackerArg;

pub mod plot;

#[derive(clap::Args, Debug)]
/// Options of `danced analyze`.
pub struct AnalyzeArgs {
    /// Audio file (wav, mp3, ogg/vorbis, flac, m4a/aac). Without one, the built-in demo song
    /// (30 s, 124 BPM, 4/4, synthesised in code) is analysed.
    pub audio: Option<PathBuf>,
    /// Beat and onset tracker.
    #[arg(long, value_enum, default_value_t = TrackerArg::Native)]
    pub beat_tracker: TrackerArg,
    /// Write beats here: `time_s<TAB>beat_in_bar<TAB>decided_at_s` per line.
    #[arg(long)]
    pub beats_out: Option<PathBuf>,
    /// Write onsets here: one time in seconds per line.
    #[arg(long)]
    pub onsets_out: Option<PathBuf>,
    /// Write model features here as float32 .npy [frames, 84] (+ a .json sidecar with the layout).
    #[arg(long)]
    pub features_out: Option<PathBuf>,
    /// Model frame rate for --features-out, Hz.
    #[arg(long, default_value_t = 30.0)]
    pub rate: f64,
    /// Draw onset strength, onsets, beats with decision lag, tempo and bar phase to a PNG.
    #[arg(long)]
    pub plot: Option<PathBuf>,
}

/// Runs `danced analyze`.
pub fn analyze(args: AnalyzeArgs) -> Result<()> {
    let started = Instant::now();
    let pb = audio_bar();
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
            crate::demo_track::DEMO_BPM
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
            let demo = crate::demo_track::demo_track(30.0);
            analyze_samples(
                &name,
                &demo.samples,
                crate::demo_track::DEMO_RATE,
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
        plot::plot_analysis(&a, &title, p)?;
    }

    let late = a
        .beats
        .iter()
        .filter(|b| b.decided_at_s - b.time_s > MAX_DECISION_LAG_S)
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
