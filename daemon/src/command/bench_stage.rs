//! `danced bench stage`: how far each dancer wanders on each stage mode, song by song, and
//! what keeping it on the stage costs (clamp, turn, foot skating).

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use model::source::{Controls, MotionSource};
use model::stage::{StageMode, StageSettings};
use offline::analysis::{AnalyzeOptions, analyze_file};

use crate::bench::stage::{Wander, WanderRow, wander_table};
use crate::dancer::{SourceKind, SourceSettings, open_source};

/// Options of `danced bench stage`.
#[derive(clap::Args, Debug, Clone)]
pub struct BenchStageArgs {
    /// Songs to dance to: audio files, or folders whose audio files are all danced to.
    #[arg(long = "songs", required_unless_present = "validation")]
    pub songs: Vec<PathBuf>,
    /// Also the tang2018 validation songs (and the captured dances' own wander beside them).
    #[arg(long)]
    pub validation: bool,
    /// The shared data folder (for --validation).
    #[arg(long, default_value = "../shared/data")]
    pub data: PathBuf,
    /// Dance at most this many seconds of each song.
    #[arg(long)]
    pub seconds: Option<f64>,
    /// Stage radius, metres.
    #[arg(long, default_value_t = model::stage::DEFAULT_RADIUS_M)]
    pub radius: f32,
    /// Sampling temperature.
    #[arg(long, default_value_t = 0.5)]
    pub temperature: f32,
    /// Random seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Threads building the validation dances.
    #[arg(long, default_value_t = 2)]
    pub jobs: usize,
}

/// The audio files `paths` name (folders: their audio files, sorted).
fn song_files(paths: &[PathBuf]) -> Result<Vec<PathBuf>> {
    let mut files = Vec::new();
    for p in paths {
        if p.is_dir() {
            let mut inside: Vec<PathBuf> = std::fs::read_dir(p)
                .with_context(|| format!("reading {}", p.display()))?
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|f| offline::decode::is_audio_file(f))
                .collect();
            inside.sort();
            files.extend(inside);
        } else {
            files.push(p.clone());
        }
    }
    Ok(files)
}

/// Dances `kind` on `stage` to `music` (a song's analysis at 25 fps, handed over as `danced
/// eval` hands it) and measures the wander.
fn dance(
    kind: SourceKind,
    stage: StageSettings,
    music: &[[f32; dsp::feature::FEATURE_DIM]],
    frames: usize,
    args: &BenchStageArgs,
) -> Result<Wander> {
    let settings = SourceSettings {
        stage,
        ..SourceSettings::default()
    };
    let mut dancer = open_source(kind, &settings, args.seed)?;
    let look = dancer.lookahead_frames();
    let frames = frames.min(music.len().saturating_sub(look));
    let poses = crate::offline_dance::dance_stream(&mut *dancer, music, 0, frames, |_| Controls {
        temperature: args.temperature,
        ..Controls::default()
    });
    Wander::of(&poses, dancer.frame_rate(), &stage, dancer.report().stage)
}

/// Runs `danced bench stage`.
pub fn bench_stage(args: BenchStageArgs) -> Result<()> {
    let fps = model::retrieval::RETRIEVAL_FPS;
    let modes = [StageMode::Free, StageMode::Bounded, StageMode::InPlace];
    let dancers = [SourceKind::Neural, SourceKind::Retrieval];
    let stage = |mode| StageSettings {
        mode,
        radius_m: args.radius,
        ..StageSettings::default()
    };
    let mut songs: Vec<(String, Vec<[f32; dsp::feature::FEATURE_DIM]>)> = Vec::new();
    for file in song_files(&args.songs)? {
        let a = analyze_file(&file, AnalyzeOptions::native(Some(fps)), &mut |_, _| {})
            .with_context(|| format!("analysing {}", file.display()))?;
        let name = file
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        songs.push((name, a.features.iter().map(|f| f.values).collect()));
    }
    let mut rows = Vec::new();
    if args.validation {
        let set = crate::eval::EvalSet::load(&args.data, args.jobs)?;
        for (name, poses, music) in set.scored_dances() {
            rows.push(WanderRow {
                song: name.into(),
                dancer: "captured".into(),
                mode: "(its floor)".into(),
                wander: Wander::of(poses, fps, &stage(StageMode::Free), None)?,
            });
            songs.push((name.into(), music.to_vec()));
        }
    }
    if songs.is_empty() {
        bail!("no songs to dance to");
    }
    let limit = args.seconds.map_or(usize::MAX, |s| (s * fps) as usize);
    for (name, music) in &songs {
        for kind in dancers {
            for mode in modes {
                let wander = dance(kind, stage(mode), music, limit, &args)?;
                eprintln!(
                    "{name}, {} dancer, {}: {:.1} s, at most {:.2} m out",
                    kind.name(),
                    mode.name(),
                    wander.seconds,
                    wander.max_distance_m
                );
                rows.push(WanderRow {
                    song: name.clone(),
                    dancer: kind.name().into(),
                    mode: mode.name().into(),
                    wander,
                });
            }
        }
    }
    print!("{}", wander_table(&rows, args.radius));
    Ok(())
}
