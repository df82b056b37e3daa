//! `danced bench moves`: a clip library cut from a folder of dances, and the built-in one,
//! danced to annotated songs they never heard.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use model::retrieval::{RETRIEVAL_FPS, RetrievalDancer};
use model::rig::Skeleton;
use model::source::{Controls, MotionSource};
use offline::analysis::{AnalyzeOptions, analyze_file};

use crate::bench::moves::{
    MovesRow, SongScore, SwitchScore, judge, moves_table, skating, switch_table,
};
use crate::bench::sets::{SynthSongInfo, median_tempo_bpm};

/// Options of `danced bench moves`.
#[derive(clap::Args, Debug, Clone)]
pub struct BenchMovesArgs {
    /// The library to measure (`danced library build --bvh DIR` writes them).
    #[arg(long)]
    pub library: PathBuf,
    /// The folder of dances it was cut from (its skating, and the judge's examples of it).
    #[arg(long, value_name = "DIR")]
    pub bvh: PathBuf,
    /// How those dance files' joints and axes are read.
    #[command(flatten)]
    pub import: super::import_args::ImportArgs,
    /// Songs with exact beats (a folder of `synth_beats.py` renders: audio and .beats files).
    #[arg(long)]
    pub songs: PathBuf,
    /// Dance at most this many seconds of each song.
    #[arg(long)]
    pub seconds: Option<f64>,
    /// The shared data folder (tang2018, for the built-in library's row and the judge).
    #[arg(long, default_value = "../shared/data")]
    pub data: PathBuf,
    /// Sampling temperature.
    #[arg(long, default_value_t = 0.5)]
    pub temperature: f32,
    /// Random seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Worker threads.
    #[arg(long, default_value_t = 2)]
    pub jobs: usize,
    /// Where on the floor the libraries dance: bounded (the default stage, 1.5 m), in_place or
    /// free (their own motion, untouched).
    #[arg(long, default_value = "bounded", value_parser = crate::command::source::parse_stage_mode)]
    pub stage: String,
}

/// Runs `danced bench moves`.
pub fn bench_moves(args: BenchMovesArgs) -> Result<()> {
    let skeleton = Skeleton::default_adult();
    let set = crate::bench::sets::rendered_set("songs", &args.songs);
    if set.items.is_empty() {
        bail!(
            "no annotated songs (audio with .beats) in {}",
            args.songs.display()
        );
    }
    let read = offline::moves::read_moves_folder(&args.bvh, &args.import.settings()?, args.jobs)?;
    let source: Vec<Vec<glam::Vec3>> = read
        .iter()
        .filter_map(|(_, r)| r.as_ref().ok())
        .map(|d| skeleton.trajectory(&d.poses))
        .collect();
    let source_skating = mean(source.iter().filter_map(|p| skating(p).ok()));
    let eval = crate::eval::EvalSet::load(&args.data, args.jobs)?;
    let tang = eval.training_positions();
    let tang_skating = mean(tang.iter().filter_map(|p| skating(p).ok()));
    let judge = judge(tang, eval.training_styles(), &source);

    let (own, _) = crate::dancer::load_library(Some(&args.library))?;
    let (built_in, _) = crate::dancer::load_library(None)?;
    let mut both = crate::dancer::on_stage(
        RetrievalDancer::with_libraries(vec![built_in.clone(), own.clone()], args.seed)?,
        model::stage::StageSettings::default(),
    );
    let mut switches = Vec::new();
    let mut normal = (0.0f64, 0.0f64);
    let name = args
        .library
        .file_stem()
        .map_or("library".into(), |s| s.to_string_lossy().into_owned());
    let mut rows = vec![
        MovesRow {
            library: name,
            own_class: 1,
            songs: Vec::new(),
            source_skating,
        },
        MovesRow {
            library: "built-in (tang2018)".into(),
            own_class: 0,
            songs: Vec::new(),
            source_skating: tang_skating,
        },
    ];
    let stage = crate::command::source::stage_in_mode(&args.stage);
    println!(
        "on a {} stage, temperature {}, seed {}",
        args.stage, args.temperature, args.seed
    );
    let mut dancers = [
        crate::dancer::on_stage(RetrievalDancer::new(own, args.seed)?, stage),
        crate::dancer::on_stage(RetrievalDancer::new(built_in, args.seed)?, stage),
    ];
    for item in &set.items {
        let a = analyze_file(
            &item.audio,
            AnalyzeOptions::native(Some(RETRIEVAL_FPS)),
            &mut |_, _| {},
        )
        .with_context(|| format!("analysing {}", item.audio.display()))?;
        let music: Vec<[f32; dsp::feature::FEATURE_DIM]> =
            dsp::predicted_stream(&a.features, model::horizon::data_horizon(RETRIEVAL_FPS));
        let bpm = SynthSongInfo::read(&item.audio)
            .map_or_else(|| median_tempo_bpm(&item.beats), |i| i.bpm);
        let limit = args
            .seconds
            .map_or(usize::MAX, |s| (s * RETRIEVAL_FPS) as usize);
        for (row, dancer) in rows.iter_mut().zip(dancers.iter_mut()) {
            let poses = crate::eval::dance_to(
                &mut **dancer,
                &music,
                limit,
                args.temperature,
                args.seed,
                &[],
                0,
            );
            let positions = skeleton.trajectory(&poses);
            row.songs
                .push(SongScore::of(&positions, &item.beats, bpm, judge.as_ref())?);
        }
        if let Some(downbeats) = &item.downbeats {
            let limit = limit.min(music.len());
            let (s, (root, joint)) =
                dance_switches(&mut *both, &music, limit, &item.beats, downbeats, &args)?;
            switches.extend(s);
            normal = (normal.0.max(root), normal.1.max(joint));
        }
        eprintln!("{}: {bpm:.0} BPM danced", item.name);
    }
    print!("{}", moves_table(&rows));
    println!(
        "\nSwitches between the built-in library and this one, cued every 8 beats at a random point of a beat (the bounded stage):\n"
    );
    print!("{}", switch_table(&switches, normal));
    Ok(())
}

/// Dances `dancer` (holding two libraries) to `music`, cueing a switch to the other library
/// every 8 beats at a random point of a beat, alternately for the next bar and the next beat;
/// scores each switch against the song's `beats` and `downbeats`, and returns the largest root
/// step per 60 Hz frame and joint step per model frame away from the switches.
fn dance_switches(
    dancer: &mut dyn MotionSource,
    music: &[[f32; dsp::feature::FEATURE_DIM]],
    frames: usize,
    beats: &[f64],
    downbeats: &[f64],
    args: &BenchMovesArgs,
) -> Result<(Vec<SwitchScore>, (f64, f64))> {
    use model::source::MovesSwitch;
    let skeleton = Skeleton::default_adult();
    dancer.reset(args.seed);
    let controls = Controls {
        temperature: args.temperature,
        ..Controls::default()
    };
    let mut rng = args.seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
    let mut random = || {
        rng ^= rng << 13;
        rng ^= rng >> 7;
        rng ^= rng << 17;
        (rng >> 11) as f64 / (1u64 << 53) as f64
    };
    // Cue times: every 8 beats from the 4th, at a random point of the beat.
    let mut cues: Vec<(f64, bool)> = Vec::new();
    let mut k = 4;
    while k + 1 < beats.len() {
        let t = beats[k] + random() * (beats[k + 1] - beats[k]);
        cues.push((t, cues.len().is_multiple_of(2)));
        k += 8;
    }
    let mut poses = Vec::with_capacity(frames);
    let mut out = model::rig::Pose::rest();
    let mut cue = 0;
    let mut waiting: Option<(f64, bool, usize)> = None;
    let mut landed: Vec<(usize, f64, bool)> = Vec::new();
    for (i, m) in music.iter().enumerate().take(frames) {
        let t = i as f64 / RETRIEVAL_FPS;
        if waiting.is_none() && cue < cues.len() && t >= cues[cue].0 {
            let (_, on_bar) = cues[cue];
            // A cue that waited for the last switch to land is sent now.
            let at = t;
            let target = 1 - dancer.report().moves.map_or(0, |m| m.active);
            let when = if on_bar {
                MovesSwitch::NextBar
            } else {
                MovesSwitch::NextBeat
            };
            if dancer.select_moves(target, when) {
                waiting = Some((at, on_bar, target));
            }
            cue += 1;
        }
        dancer.step(std::slice::from_ref(m), &controls, &mut out);
        poses.push(out);
        if let Some((at, on_bar, target)) = waiting
            && dancer.report().moves.is_some_and(|m| m.active == target)
        {
            landed.push((i, at, on_bar));
            waiting = None;
        }
    }
    let positions = skeleton.trajectory(&poses);
    let joint_step = |i: usize| -> f64 {
        (0..model::rig::JOINT_COUNT)
            .map(|j| {
                f64::from(
                    (positions[i * model::rig::JOINT_COUNT + j]
                        - positions[(i - 1) * model::rig::JOINT_COUNT + j])
                        .length(),
                )
            })
            .fold(0.0, f64::max)
    };
    let root_step =
        |i: usize| f64::from((poses[i].root_position - poses[i - 1].root_position).length());
    // What the sender puts out at 60 Hz: the model frames interpolated, so each model frame's
    // step is spread over 60/25 frames sent.
    let sent = |i: usize| root_step(i) * RETRIEVAL_FPS / 60.0;
    let near_switch = |i: usize| landed.iter().any(|&(f, _, _)| i + 3 >= f && i <= f + 8);
    let away: Vec<usize> = (1..poses.len()).filter(|&i| !near_switch(i)).collect();
    let normal = (
        away.iter().map(|&i| sent(i)).fold(0.0, f64::max),
        away.iter().map(|&i| joint_step(i)).fold(0.0, f64::max),
    );
    let scores = landed
        .into_iter()
        .filter(|&(f, _, _)| f >= 3 && f + 8 < poses.len())
        .filter_map(|(f, at, on_bar)| {
            let grid = if on_bar { downbeats } else { beats };
            let t = f as f64 / RETRIEVAL_FPS;
            // The beat or bar it landed on: the nearest of the song's; which one after the cue.
            let nearest = grid
                .iter()
                .copied()
                .min_by(|a, b| (a - t).abs().total_cmp(&(b - t).abs()))?;
            let after_cue = grid.iter().filter(|&&b| b > at && b <= nearest).count();
            Some(SwitchScore {
                landing_s: t - nearest,
                on_bar,
                beats_after_cue: after_cue,
                root_step_m: (f - 2..f + 8).map(root_step).fold(0.0, f64::max),
                root_step_60_m: (f - 2..f + 8).map(sent).fold(0.0, f64::max),
                joint_step_m: (f - 2..f + 8).map(joint_step).fold(0.0, f64::max),
            })
        })
        .collect();
    Ok((scores, normal))
}

/// Mean of `values` (0 when empty).
fn mean(values: impl Iterator<Item = f64>) -> f64 {
    let (sum, n) = values.fold((0.0, 0usize), |(s, n), v| (s + v, n + 1));
    if n == 0 { 0.0 } else { sum / n as f64 }
}
