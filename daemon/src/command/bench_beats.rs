//! `danced bench beats`: beat tracking accuracy and speed on the annotated data sets.

use std::path::PathBuf;

use anyhow::{Result, bail};
use dsp::BeatTrackerKind;
use offline::progress::count_bar;

use crate::bench::{beats, sets};
use crate::command::tracker::TrackerArg;

#[derive(clap::Args, Debug)]
/// Options of `danced bench beats`.
pub struct BenchBeatsArgs {
    /// The shared data folder.
    #[arg(long, default_value = "../shared/data")]
    pub data: PathBuf,
    /// Trackers to compare (default: native, plus aubio when built in).
    #[arg(long, value_enum)]
    pub tracker: Vec<TrackerArg>,
    /// Only these sets (synth-beats, tang2018, real-music, real-music-train, madmom-tests).
    #[arg(long)]
    pub set: Vec<String>,
    /// Worker threads (each file is analysed on one thread).
    #[arg(long, default_value_t = 2)]
    pub jobs: usize,
    /// Print a row per file.
    #[arg(long)]
    pub verbose: bool,
    /// Override native tracker tuning, e.g. `observation_beta=1.5,prior_octaves=0.8` (for tuning).
    #[arg(long, default_value = "")]
    pub beat_params: String,
    /// Override bar pointer tuning, e.g. `jump=0.05,switch_ratio=3` (for tuning).
    #[arg(long, default_value = "")]
    pub bar_params: String,
    /// Beat activation weights to measure in place of the shipped ones (`danced-train beats`).
    #[arg(long)]
    pub beat_net: Option<PathBuf>,
    /// Downbeat network weights to measure in place of the shipped ones
    /// (`danced-train downbeats`).
    #[arg(long)]
    pub downbeat_net: Option<PathBuf>,
    /// Further folders of songs rendered by `synth_beats.py`, each scored as a set named after
    /// the folder.
    #[arg(long, num_args = 1..)]
    pub songs: Vec<PathBuf>,
}

/// A song's meter counts as right when at least this share of its beats after the first four
/// bars report it.
const METER_RIGHT_SHARE: f64 = 0.9;

/// Runs `danced bench beats`.
pub fn bench_beats(args: BenchBeatsArgs) -> Result<()> {
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
    let extra = args.songs.iter().map(|dir| {
        let name = dir.file_name().map_or_else(
            || dir.display().to_string(),
            |n| n.to_string_lossy().into_owned(),
        );
        sets::rendered_set(&name, dir)
    });
    let [real, real_train] = sets::real_music_sets(&args.data);
    let sets: Vec<sets::BenchSet> = [
        sets::synth_set(&args.data),
        sets::tang_set(&args.data),
        real,
        real_train,
        sets::madmom_set(&args.data),
    ]
    .into_iter()
    .chain(extra)
    .filter(|s| args.set.is_empty() || args.set.contains(&s.name))
    .filter(|s| !s.items.is_empty())
    .collect();
    if sets.is_empty() {
        bail!("no annotated audio found under {}", args.data.display());
    }
    let beat_params = dsp::beat::BeatTrackerParams::default().with_overrides(&args.beat_params)?;
    let bar_params = dsp::BarPointerParams::default().with_overrides(&args.bar_params)?;
    let networks = offline::analysis::networks_from_files(
        args.beat_net.as_deref(),
        args.downbeat_net.as_deref(),
    )?;
    let total: usize = sets.iter().map(|s| s.items.len()).sum::<usize>() * trackers.len();
    let pb = count_bar(total as u64);
    let mut rows = Vec::new();
    let mut details = String::new();
    for &tracker in &trackers {
        let mut row = vec![tracker.name().to_string()];
        let mut all = Vec::new();
        for set in &sets {
            let options = offline::analysis::AnalyzeOptions {
                tracker,
                beat_params,
                bar_params,
                networks,
                ..Default::default()
            };
            let scores = beats::run_set(set, options, args.jobs, &|name| {
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
                    beats::mean(&scores, |s| s.downbeat_f.unwrap_or(0.0))
                );
                let weak = scores
                    .iter()
                    .filter(|s| s.f_measure >= 0.9 && s.downbeat_f.is_some_and(|f| f < 0.5))
                    .count();
                extra += &format!(" ({weak} below 0.5 with beat F ≥ 0.9)");
            }
            if scores.iter().any(|s| s.meter_right.is_some()) {
                let right = scores
                    .iter()
                    .filter(|s| s.meter_right.is_some_and(|m| m >= METER_RIGHT_SHARE))
                    .count();
                extra += &format!(
                    ", meter right on {right} of {} songs ({:.1} % of beats)",
                    scores.len(),
                    100.0 * beats::mean(&scores, |s| s.meter_right.unwrap_or(0.0))
                );
            }
            if scores.iter().any(|s| s.onset_f.is_some()) {
                extra += &format!(
                    ", onset F {:.3}",
                    beats::mean(&scores, |s| s.onset_f.unwrap_or(0.0))
                );
            }
            extra += &beats::level_and_timing(&scores);
            row.push(format!(
                "{:.3} / {:.3} / {:.3}{extra}",
                beats::mean(&scores, |s| s.f_measure),
                beats::mean(&scores, |s| s.cmlt),
                beats::mean(&scores, |s| s.amlt)
            ));
            if args.verbose {
                details.push_str(&beats::detail_table(set, tracker, &scores));
            }
            details.push_str(&beats::genre_table(set, &scores));
            all.extend(scores);
        }
        row.push(format!("{:.0}", beats::speed(&all)));
        rows.push(row);
    }
    pb.finish_and_clear();
    print!("{details}");
    println!();
    println!(
        "Beats decided ≤ {:.0} ms after they happen; mean F / CMLt / AMLt (±70 ms, first 5 s skipped).",
        beats::MAX_DECISION_LAG_S * 1000.0
    );
    println!(
        "A song's meter is right when ≥ {:.0} % of its beats after the first four bars report it.",
        METER_RIGHT_SHARE * 100.0
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
