//! `danced eval`: every motion source on the validation dances' music, scored with the motion
//! metrics next to the ground truth and the ground truth against other songs' beats.
//!
//! Protocol (fixed so numbers stay comparable between sessions):
//! - Validation dances with music (the dataset split), music features from the streaming
//!   analysis at 25 fps, aligned as `danced dataset build` aligns them.
//! - Music beats: the pseudo-reference beats in `tang2018-beats/`, shifted to motion time.
//! - Every motion is posed on `Skeleton::default_adult` (ground truth included), so rig
//!   proportions do not count.
//! - BeatAlign and beat offset per dance, averaged over dances. "vs other songs" scores the same
//!   motion against the beats of the next three validation songs (each from its own dance
//!   start): the chance level that proves the music, not luck, placed the kinematic beats.
//! - FPD, FMD, FID_k and Dist_k against the *training* dances' ground truth, so the ground
//!   truth row measures the gap between unseen real dances and the training set. Kinetic
//!   features are computed on 5 s windows (hop 5 s) to give the covariances enough samples.
//! - Freezes: the default freeze detector, summed over dances. Foot skating: mean toe speed in
//!   contact, the floor of each dance at the 5th percentile of its toes' heights.

use std::path::Path;

use anyhow::{Context, Result};
use glam::Quat;
use model::metrics::{
    ContactParams, FreezeParams, JointTrack, beat_align, beat_offset, detect_freezes, dist_k,
    fid_k, fmd, foot_skating, fpd, kinetic_features, toe_floor_y,
};
use model::retrieval::{ClipLibrary, RetrievalDancer};
use model::rig::{JOINT_COUNT, Joint, Pose, Skeleton};
use model::source::{Controls, MotionSource};
use model::tang2018::TANG_FPS;

use crate::key_cue::{KeyCue, key_pose_error_cm, target_at};
use crate::output::read_times;

/// Length of the windows kinetic features are computed on, frames (5 s at 25 fps).
const KINETIC_WINDOW_FRAMES: usize = 125;

/// One validation dance with what every row needs.
struct EvalDance {
    name: String,
    /// Ground-truth poses (root from the origin).
    poses: Vec<Pose>,
    /// Music features, one per motion frame.
    music: Vec<[f32; dsp::feature::FEATURE_DIM]>,
    /// Reference beats in motion time, seconds.
    beats: Vec<f64>,
}

/// What a row reports (means over dances unless said otherwise).
#[derive(Clone, Debug, Default)]
pub struct EvalRow {
    /// What produced the motion.
    pub system: String,
    /// BeatAlign against the song's reference beats.
    pub beat_align: f64,
    /// BeatAlign of the same motion against other songs' beats.
    pub beat_align_other: f64,
    /// Transflower beat offset, mean over dances of the per-dance mean, seconds.
    pub beat_offset_s: f64,
    /// Fréchet pose distance to the training dances.
    pub fpd: f64,
    /// Fréchet movement distance to the training dances.
    pub fmd: f64,
    /// FID_k against the training dances (5 s windows).
    pub fid_k: f64,
    /// Dist_k (diversity of 5 s windows, standardised by the training dances).
    pub dist_k: f64,
    /// Freezes, summed over dances.
    pub freezes: usize,
    /// Foot skating, m/s while in contact.
    pub foot_skate_mps: f64,
    /// Seconds of motion scored.
    pub seconds: f64,
}

/// The data the evaluation runs on: validation dances and the training reference.
pub struct EvalSet {
    validation: Vec<EvalDance>,
    /// Training ground-truth world positions, one Vec per dance.
    train_positions: Vec<Vec<glam::Vec3>>,
    /// Training kinetic features (5 s windows).
    train_kinetic: Vec<Vec<f64>>,
}

/// Kinetic features of every whole 5 s window of a track's positions.
fn window_kinetics(positions: &[glam::Vec3]) -> Vec<Vec<f64>> {
    positions
        .chunks_exact(KINETIC_WINDOW_FRAMES * JOINT_COUNT)
        .filter_map(|w| {
            let t = JointTrack::new(w, JOINT_COUNT, TANG_FPS).ok()?;
            kinetic_features(&t).ok()
        })
        .collect()
}

impl EvalSet {
    /// Builds every dance under `data` (as `dataset build` does) with `jobs` threads.
    pub fn load(data: &Path, jobs: usize) -> Result<EvalSet> {
        let built = crate::dataset::build_all(data, jobs, |d, _| d.audio.is_some(), false)?;
        let skeleton = Skeleton::default_adult();
        let mut set = EvalSet {
            validation: Vec::new(),
            train_positions: Vec::new(),
            train_kinetic: Vec::new(),
        };
        for b in built.into_iter().filter_map(|(_, r)| r.ok()) {
            let poses = b.poses_on_default_rig();
            if !b.validation {
                let p = skeleton.trajectory(&poses);
                set.train_kinetic.extend(window_kinetics(&p));
                set.train_positions.push(p);
                continue;
            }
            let Some(start) = b.start_s else { continue };
            let path = data
                .join("tang2018-beats")
                .join(format!("{}.beats", b.name));
            let beats = read_times(&path).with_context(|| format!("reading {}", path.display()))?;
            set.validation.push(EvalDance {
                name: b.name.clone(),
                poses,
                music: b.music,
                beats: beats
                    .iter()
                    .map(|t| t - start)
                    .filter(|t| *t >= 0.0)
                    .collect(),
            });
        }
        anyhow::ensure!(
            !set.validation.is_empty() && set.train_positions.len() >= 2,
            "the evaluation needs validation and training dances with music under {}",
            data.display()
        );
        Ok(set)
    }

    /// Names of the validation dances scored.
    pub fn validation_names(&self) -> Vec<String> {
        self.validation.iter().map(|d| d.name.clone()).collect()
    }

    /// Scores one motion per validation dance (same order as [`EvalSet::validation_names`]).
    pub fn score(&self, system: &str, motions: &[Vec<Pose>]) -> Result<EvalRow> {
        let skeleton = Skeleton::default_adult();
        let positions: Vec<Vec<glam::Vec3>> =
            motions.iter().map(|m| skeleton.trajectory(m)).collect();
        let tracks: Vec<JointTrack<'_>> = positions
            .iter()
            .map(|p| JointTrack::new(p, JOINT_COUNT, TANG_FPS))
            .collect::<Result<_, _>>()?;
        let train: Vec<JointTrack<'_>> = self
            .train_positions
            .iter()
            .map(|p| JointTrack::new(p, JOINT_COUNT, TANG_FPS))
            .collect::<Result<_, _>>()?;
        let n = self.validation.len();
        let mut row = EvalRow {
            system: system.to_string(),
            ..Default::default()
        };
        let toes = [Joint::LeftToes.index(), Joint::RightToes.index()];
        for (i, (track, dance)) in tracks.iter().zip(&self.validation).enumerate() {
            row.seconds += track.duration_s();
            row.beat_align += beat_align(track, &dance.beats) / n as f64;
            let others: Vec<f64> = (1..=3.min(n - 1))
                .map(|k| beat_align(track, &self.validation[(i + k) % n].beats))
                .collect();
            row.beat_align_other +=
                others.iter().sum::<f64>() / others.len().max(1) as f64 / n as f64;
            if let Ok(o) = beat_offset(track, Joint::Hips.index(), &dance.beats) {
                row.beat_offset_s += o.mean_s / n as f64;
            }
            row.freezes += detect_freezes(track, FreezeParams::default())?.freezes;
            let ground_y_m = toe_floor_y(track, &toes)?;
            let s = foot_skating(
                track,
                &toes,
                ContactParams {
                    ground_y_m,
                    ..ContactParams::default()
                },
            )?;
            row.foot_skate_mps += s.mean_speed_mps / n as f64;
        }
        let root = Joint::Hips.index();
        row.fpd = fpd(&train, &tracks, root)?;
        row.fmd = fmd(&train, &tracks, root)?;
        let kinetic: Vec<Vec<f64>> = positions.iter().flat_map(|p| window_kinetics(p)).collect();
        row.fid_k = fid_k(&self.train_kinetic, &kinetic)?;
        row.dist_k = dist_k(&self.train_kinetic, &kinetic)?;
        Ok(row)
    }

    /// The ground truth's own motion for every validation dance.
    pub fn ground_truth(&self) -> Vec<Vec<Pose>> {
        self.validation.iter().map(|d| d.poses.clone()).collect()
    }

    /// Runs `source` over every validation dance's music (reset with `seed` before each), at
    /// temperature `t`; returns the motions and the mean step time in µs.
    pub fn generate(
        &self,
        source: &mut dyn MotionSource,
        temperature: f32,
        seed: u64,
    ) -> (Vec<Vec<Pose>>, f64) {
        let started = std::time::Instant::now();
        let mut steps = 0usize;
        let motions: Vec<Vec<Pose>> = self
            .validation
            .iter()
            .map(|d| {
                let m = dance_to(source, &d.music, d.music.len(), temperature, seed, &[], 0);
                steps += m.len();
                m
            })
            .collect();
        (
            motions,
            started.elapsed().as_secs_f64() * 1e6 / steps.max(1) as f64,
        )
    }

    /// Mean joint error (cm) at the target frame of key poses announced `horizon_s` ahead:
    /// on every validation song, a pose of `bank` (in turn) is due every
    /// [`KEY_CUE_SPACING_S`] from [`KEY_CUE_SPACING_S`] / 2 on. Returns the error and the cue count.
    pub fn key_pose_error(
        &self,
        source: &mut dyn MotionSource,
        temperature: f32,
        seed: u64,
        bank: &[[Quat; JOINT_COUNT]],
        horizon_s: f64,
    ) -> (f64, usize) {
        let lead = (horizon_s * TANG_FPS).round() as usize;
        let spacing = (KEY_CUE_SPACING_S * TANG_FPS).round() as usize;
        let (mut sum, mut count) = (0.0, 0usize);
        for (i, d) in self.validation.iter().enumerate() {
            let frames = d.music.len().saturating_sub(source.lookahead_frames());
            let cues: Vec<KeyCue> = (0..)
                .map(|k| spacing / 2 + k * spacing)
                .take_while(|&f| f < frames)
                .enumerate()
                .map(|(k, frame)| KeyCue {
                    name: String::new(),
                    rotations: bank[(i * 5 + k) % bank.len()],
                    frame,
                })
                .collect();
            let motion = dance_to(source, &d.music, frames, temperature, seed, &cues, lead);
            for c in &cues {
                if let Some(p) = motion.get(c.frame) {
                    sum += key_pose_error_cm(p, &c.rotations);
                    count += 1;
                }
            }
        }
        (sum / count.max(1) as f64, count)
    }

    /// Freezes in [`LONG_RUN_S`] of dancing to every validation song, its music looped.
    pub fn long_run_freezes(
        &self,
        source: &mut dyn MotionSource,
        temperature: f32,
        seed: u64,
    ) -> Result<LongRun> {
        let frames = (LONG_RUN_S * TANG_FPS) as usize;
        let skeleton = Skeleton::default_adult();
        let mut run = LongRun::default();
        for d in &self.validation {
            let music: Vec<_> = d.music.iter().cycle().take(frames + 8).copied().collect();
            let motion = dance_to(source, &music, frames, temperature, seed, &[], 0);
            let p = skeleton.trajectory(&motion);
            let track = JointTrack::new(&p, JOINT_COUNT, TANG_FPS)?;
            let f = detect_freezes(&track, FreezeParams::default())?.freezes;
            run.freezes += f;
            run.songs_with_freezes += usize::from(f > 0);
            run.seconds += track.duration_s();
        }
        Ok(run)
    }
}

/// Seconds between key poses in the key-pose evaluation.
pub const KEY_CUE_SPACING_S: f64 = 8.0;

/// Key-pose horizons scored by `danced eval`, seconds.
pub const KEY_HORIZONS_S: [f64; 4] = [0.5, 1.0, 2.0, 4.0];

/// Length of the long runs `danced eval` checks for freezes, seconds (5 minutes).
pub const LONG_RUN_S: f64 = 300.0;

/// Freezes over long runs.
#[derive(Clone, Debug, Default)]
pub struct LongRun {
    /// Freezes, summed over songs.
    pub freezes: usize,
    /// Songs with at least one freeze.
    pub songs_with_freezes: usize,
    /// Seconds danced.
    pub seconds: f64,
}

/// Runs `source` (reset with `seed`) over `frames` frames of `music` at `temperature`, with the
/// key poses `cues` announced `lead` frames ahead; every step sees its frame and the source's
/// look-ahead, as the live pipeline hands them over.
pub fn dance_to(
    source: &mut dyn MotionSource,
    music: &[[f32; dsp::feature::FEATURE_DIM]],
    frames: usize,
    temperature: f32,
    seed: u64,
    cues: &[KeyCue],
    lead: usize,
) -> Vec<Pose> {
    let look = source.lookahead_frames();
    source.reset(seed);
    let frames = frames.min(music.len().saturating_sub(look));
    crate::motion_lag::dance_stream(source, music, 0, frames, |i| Controls {
        temperature,
        key_pose: target_at(cues, i, lead),
        beat_accent: None,
    })
}

/// Songs with exact beats that are in no training dance (`synth-beats`): only the music-side
/// metrics apply (no ground-truth motion).
pub struct MusicSet {
    songs: Vec<(String, Vec<[f32; dsp::feature::FEATURE_DIM]>, Vec<f64>)>,
}

/// A music-side row: how the motion follows songs the model never saw.
#[derive(Clone, Debug, Default)]
pub struct MusicRow {
    /// What produced the motion.
    pub system: String,
    /// BeatAlign against the song's exact beats.
    pub beat_align: f64,
    /// BeatAlign against the next three songs' beats.
    pub beat_align_other: f64,
    /// Transflower beat offset, seconds.
    pub beat_offset_s: f64,
    /// Freezes, summed over songs.
    pub freezes: usize,
    /// Songs scored.
    pub songs: usize,
}

impl MusicSet {
    /// Analyses every song of `data/synth-beats` with the streaming analysis at 25 fps.
    pub fn load(data: &Path) -> Result<MusicSet> {
        let set = crate::bench::synth_set(data);
        anyhow::ensure!(
            !set.items.is_empty(),
            "no songs under {}",
            data.join("synth-beats").display()
        );
        let mut songs = Vec::new();
        for item in set.items {
            let a = crate::offline::analyze_file(
                &item.audio,
                crate::offline::AnalyzeOptions::native(Some(TANG_FPS)),
                &mut |_, _| {},
            )
            .with_context(|| format!("analysing {}", item.audio.display()))?;
            songs.push((
                item.name,
                dsp::predicted_stream(&a.features, crate::horizon::data_horizon(TANG_FPS)),
                item.beats,
            ));
        }
        Ok(MusicSet { songs })
    }

    /// Dances `source` to every song and scores the motion against the beats.
    pub fn score(
        &self,
        system: &str,
        source: &mut dyn MotionSource,
        temperature: f32,
        seed: u64,
    ) -> Result<MusicRow> {
        let skeleton = Skeleton::default_adult();
        let n = self.songs.len();
        let mut row = MusicRow {
            system: system.into(),
            songs: n,
            ..MusicRow::default()
        };
        for (i, (_, music, beats)) in self.songs.iter().enumerate() {
            let motion = dance_to(source, music, music.len(), temperature, seed, &[], 0);
            let p = skeleton.trajectory(&motion);
            let track = JointTrack::new(&p, JOINT_COUNT, TANG_FPS)?;
            row.beat_align += beat_align(&track, beats) / n as f64;
            let others: Vec<f64> = (1..=3.min(n - 1))
                .map(|k| beat_align(&track, &self.songs[(i + k) % n].2))
                .collect();
            row.beat_align_other +=
                others.iter().sum::<f64>() / others.len().max(1) as f64 / n as f64;
            if let Ok(o) = beat_offset(&track, Joint::Hips.index(), beats) {
                row.beat_offset_s += o.mean_s / n as f64;
            }
            row.freezes += detect_freezes(&track, FreezeParams::default())?.freezes;
        }
        Ok(row)
    }
}

/// The music-side table of `danced eval`.
pub fn music_table(rows: &[MusicRow]) -> String {
    let mut s = String::from(
        "| system | BeatAlign ↑ | vs other songs | beat offset s ↓ | freezes |\n| --- | --- | --- | --- | --- |\n",
    );
    for r in rows {
        s += &format!(
            "| {} | {:.3} | {:.3} | {:.3} | {} |\n",
            r.system, r.beat_align, r.beat_align_other, r.beat_offset_s, r.freezes
        );
    }
    s
}

/// The retrieval dancer on `library`, for rows.
pub fn retrieval(library: ClipLibrary) -> Result<RetrievalDancer> {
    RetrievalDancer::new(library, 1).context("starting the retrieval dancer")
}

/// The table `danced eval` prints.
pub fn table(rows: &[EvalRow]) -> String {
    let mut s = String::from(
        "| system | BeatAlign ↑ | vs other songs | beat offset s ↓ | FPD ↓ | FMD ↓ | FID_k ↓ | Dist_k | freezes | foot skate m/s ↓ |\n| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |\n",
    );
    for r in rows {
        s += &format!(
            "| {} | {:.3} | {:.3} | {:.3} | {:.2} | {:.2} | {:.1} | {:.2} | {} | {:.3} |\n",
            r.system,
            r.beat_align,
            r.beat_align_other,
            r.beat_offset_s,
            r.fpd,
            r.fmd,
            r.fid_k,
            r.dist_k,
            r.freezes,
            r.foot_skate_mps
        );
    }
    s
}
