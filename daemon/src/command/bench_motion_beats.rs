//! `danced bench motion-beats`: the beat grid found from a dance's motion alone, against the
//! music's reference beats, on the tang2018 dances captured with their songs.

use std::path::PathBuf;

use anyhow::{Context, Result};
use model::metrics::JointTrack;
use model::motion_beat::motion_beat_grid;
use model::rig::{JOINT_COUNT, Skeleton};

use crate::bench::sets::median_tempo_bpm;

/// Tempo within this fraction of the music's counts as the same tempo.
pub const TEMPO_TOLERANCE: f64 = 0.04;
/// A grid whose median offset from the music's beats is within this counts as in phase, s.
pub const PHASE_TOLERANCE_S: f64 = 0.08;

/// Options of `danced bench motion-beats`.
#[derive(clap::Args, Debug, Clone)]
pub struct BenchMotionBeatsArgs {
    /// The shared data folder (holds tang2018/ and tang2018-beats/).
    #[arg(long, default_value = "../shared/data")]
    pub data: PathBuf,
    /// Threads building the dances.
    #[arg(long, default_value_t = 2)]
    pub jobs: usize,
}

/// How a grid's tempo relates to the music's.
fn level(ratio: f64) -> &'static str {
    if (ratio - 1.0).abs() <= TEMPO_TOLERANCE {
        "same"
    } else if (ratio - 2.0).abs() <= 2.0 * TEMPO_TOLERANCE {
        "double"
    } else if (ratio - 0.5).abs() <= 0.5 * TEMPO_TOLERANCE {
        "half"
    } else {
        "other"
    }
}

/// Median signed offset, seconds, of each of `grid`'s beats from the nearest of `music`.
fn median_offset(grid: &[f64], music: &[f64]) -> Option<f64> {
    let mut offsets: Vec<f64> = grid
        .iter()
        .filter_map(|&b| {
            let k = music.partition_point(|&x| x < b);
            [k.checked_sub(1), Some(k)]
                .into_iter()
                .flatten()
                .filter_map(|i| music.get(i))
                .map(|&m| b - m)
                .min_by(|x, y| x.abs().total_cmp(&y.abs()))
        })
        .collect();
    offsets.sort_by(f64::total_cmp);
    offsets.get(offsets.len() / 2).copied()
}

/// Runs `danced bench motion-beats`.
pub fn bench_motion_beats(args: BenchMotionBeatsArgs) -> Result<()> {
    let built =
        offline::dataset::build_all(&args.data, args.jobs, |d, _| d.audio.is_some(), false)?;
    let skeleton = Skeleton::default_adult();
    println!(
        "| dance | music tempo | motion tempo | level | phase (median offset) | confidence | bar | in tempo and phase |"
    );
    println!("| --- | --- | --- | --- | --- | --- | --- | --- |");
    let (mut same, mut other_level, mut total) = (0, 0, 0);
    for (name, built) in built {
        let Ok(dance) = built else { continue };
        let Some(start) = dance.start_s else { continue };
        let positions = skeleton.trajectory(&dance.poses_on_default_rig());
        let track = JointTrack::new(&positions, JOINT_COUNT, model::retrieval::RETRIEVAL_FPS)?;
        let path = args
            .data
            .join("tang2018-beats")
            .join(format!("{name}.beats"));
        let music: Vec<f64> = offline::files::read_times(&path)
            .with_context(|| format!("reading {}", path.display()))?
            .into_iter()
            .map(|t| t - start)
            .filter(|t| (0.0..=track.duration_s()).contains(t))
            .collect();
        let music_bpm = median_tempo_bpm(&music);
        total += 1;
        match motion_beat_grid(&track) {
            Ok(grid) => {
                let lvl = level(grid.tempo_bpm / music_bpm);
                let offset = median_offset(&grid.beats_s, &music).unwrap_or(f64::NAN);
                let in_phase = offset.abs() <= PHASE_TOLERANCE_S;
                let pass = match lvl {
                    "same" if in_phase => {
                        same += 1;
                        "yes"
                    }
                    "half" | "double" if in_phase => {
                        other_level += 1;
                        "at half or double"
                    }
                    _ => "no",
                };
                println!(
                    "| {name} | {music_bpm:.1} | {:.1} | {lvl} | {:+.0} ms | {:.2} | {} | {pass} |",
                    grid.tempo_bpm,
                    offset * 1000.0,
                    grid.confidence,
                    grid.beats_per_bar.map_or("–".into(), |b| b.to_string()),
                );
            }
            Err(e) => println!("| {name} | {music_bpm:.1} | – | – | – | – | – | no ({e}) |"),
        }
    }
    println!(
        "\nin tempo (within {:.0} %) and phase (within {:.0} ms): {same} of {total} dances ({:.0} %); at half or double tempo, in phase: {other_level}",
        100.0 * TEMPO_TOLERANCE,
        1000.0 * PHASE_TOLERANCE_S,
        100.0 * same as f64 / total.max(1) as f64
    );
    Ok(())
}
