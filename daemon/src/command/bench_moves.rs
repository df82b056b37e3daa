//! `danced bench moves`: a clip library cut from a folder of dances, and the built-in one,
//! danced to annotated songs they never heard.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use model::retrieval::{RETRIEVAL_FPS, RetrievalDancer};
use model::rig::Skeleton;
use model::source::{Controls, MotionSource};
use offline::analysis::{AnalyzeOptions, analyze_file};

use crate::bench::moves::{MovesRow, SongScore, judge, moves_table, skating};
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
    let stage = model::stage::StageSettings {
        mode: model::stage::StageMode::parse(&args.stage).unwrap_or_default(),
        ..Default::default()
    };
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
            let look = dancer.lookahead_frames();
            dancer.reset(args.seed);
            let frames = limit.min(music.len().saturating_sub(look));
            let poses =
                crate::offline_dance::dance_stream(&mut **dancer, &music, 0, frames, |_| {
                    Controls {
                        temperature: args.temperature,
                        ..Controls::default()
                    }
                });
            let positions = skeleton.trajectory(&poses);
            row.songs
                .push(SongScore::of(&positions, &item.beats, bpm, judge.as_ref())?);
        }
        eprintln!("{}: {bpm:.0} BPM danced", item.name);
    }
    print!("{}", moves_table(&rows));
    Ok(())
}

/// Mean of `values` (0 when empty).
fn mean(values: impl Iterator<Item = f64>) -> f64 {
    let (sum, n) = values.fold((0.0, 0usize), |(s, n), v| (s + v, n + 1));
    if n == 0 { 0.0 } else { sum / n as f64 }
}
