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

use model::style::{DanceStyle, StyleRequest};
use std::path::Path;

use anyhow::{Context, Result};
use glam::Quat;
use model::body_shape::key_pose_error_cm;
use model::metrics::{
    ContactParams, FreezeParams, JointTrack, beat_align, beat_offset, detect_freezes, dist_k,
    fid_k, fmd, foot_skating, fpd, kinetic_features, toe_floor_y,
};
use model::retrieval::{ClipLibrary, RetrievalDancer};
use model::rig::{JOINT_COUNT, Joint, Pose, Skeleton};
use model::source::{Controls, MotionSource};
use model::tang2018::TANG_FPS;
use offline::files::read_times;

use crate::offline_dance::{KeyCue, target_at};

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
    /// BeatAlign on the song's beats minus on the same beats shifted half a beat (0 is chance;
    /// the music table's beat measure, here on the validation dances).
    pub on_minus_off: f64,
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
    /// Joint speed in the songs' quiet phrases over that elsewhere ([`QUIET_PHRASE_DB`]; mean
    /// over the dances with a second of them): the ground truth's row says whether the
    /// captured dancers calm down when their music does.
    pub quiet_phrase_speed_ratio: f64,
    /// Dances with a quiet phrase.
    pub quiet_phrase_dances: usize,
    /// Seconds of motion scored.
    pub seconds: f64,
}

/// Which dances' songs are danced to and scored.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ScoredDances {
    /// The validation dances (every table of `danced eval`).
    Validation,
    /// The training dances: a score a checkpoint can be picked by without the validation
    /// dances seeing the pick.
    Training,
}

/// The data the evaluation runs on: the scored dances (validation, unless said) and the
/// training reference.
pub struct EvalSet {
    validation: Vec<EvalDance>,
    /// Training ground-truth world positions, one Vec per dance.
    train_positions: Vec<Vec<glam::Vec3>>,
    /// Each training dance's style ([`STYLES`] index), where its name says it.
    train_styles: Vec<Option<usize>>,
    /// Training kinetic features (5 s windows).
    train_kinetic: Vec<Vec<f64>>,
    /// Training kinetic features of [`TRANSITION_S`] windows.
    train_kinetic_short: Vec<Vec<f64>>,
    /// The style classifier fit on the training dances.
    styles: Option<StyleClassifier>,
}

/// The tang2018 styles' names, in [`DanceStyle`] index order.
pub const STYLES: [&str; 4] = [
    DanceStyle::ChaCha.name(),
    DanceStyle::Rumba.name(),
    DanceStyle::Tango.name(),
    DanceStyle::Waltz.name(),
];

/// Length of the windows the style classifier names, seconds.
pub const STYLE_WINDOW_S: f64 = 10.0;

/// The style index of a tang2018 dance by its name (`DANCE_W_3` is a waltz).
pub fn style_of(dance: &str) -> Option<usize> {
    DanceStyle::of_tang_dance(dance).map(DanceStyle::index)
}

/// Nearest centroid on standardised kinetic features of [`STYLE_WINDOW_S`] windows, fit on
/// the training dances: a simple, fixed judge of which style a motion looks like.
pub struct StyleClassifier {
    norm: model::metrics::FeatureNormaliser,
    centroids: Vec<(usize, Vec<f64>)>,
}

impl StyleClassifier {
    /// Fits the centroids of `windows` (class, kinetic features): one per class present.
    pub fn fit(windows: &[(usize, Vec<f64>)]) -> Option<Self> {
        let all: Vec<Vec<f64>> = windows.iter().map(|w| w.1.clone()).collect();
        let norm = model::metrics::FeatureNormaliser::fit(&all).ok()?;
        let mut centroids = Vec::new();
        let classes = windows.iter().map(|w| w.0 + 1).max().unwrap_or(0);
        for style in 0..classes {
            let members: Vec<Vec<f64>> = windows
                .iter()
                .filter(|w| w.0 == style)
                .filter_map(|w| norm.apply(&w.1).ok())
                .collect();
            if let Some(first) = members.first() {
                let mut c = vec![0.0; first.len()];
                for m in &members {
                    for (c, x) in c.iter_mut().zip(m) {
                        *c += x / members.len() as f64;
                    }
                }
                centroids.push((style, c));
            }
        }
        (!centroids.is_empty()).then_some(Self { norm, centroids })
    }

    /// The style `features` are nearest to.
    pub fn classify(&self, features: &[f64]) -> Option<usize> {
        let x = self.norm.apply(features).ok()?;
        self.centroids
            .iter()
            .map(|(s, c)| {
                let d: f64 = c.iter().zip(&x).map(|(a, b)| (a - b).powi(2)).sum();
                (*s, d)
            })
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .map(|(s, _)| s)
    }

    /// Styles in the classifier (those with training windows).
    pub fn styles(&self) -> Vec<usize> {
        self.centroids.iter().map(|c| c.0).collect()
    }
}

/// Length of the windows before a key pose whose kinetics are compared with free dancing, s.
pub const TRANSITION_S: f64 = 2.0;

/// Passes over the validation songs that [`EvalSet::transition_fid`] pools: one pass gives 64
/// windows of each kind, fewer than the kinetic features' 72 dimensions, and its FID_k ratio
/// moved from 3.0 to 7.5 between two noise seeds of one dancer.
pub const TRANSITION_PASSES: usize = 10;

/// FID_k of the motion leading into key poses, of the motion leaving them and of free dancing,
/// on [`TRANSITION_S`] windows against the training dances' windows of that length.
#[derive(Clone, Copy, Debug, Default)]
pub struct TransitionFid {
    /// The windows ending on a key pose's target frame (announced [`TRANSITION_S`] ahead).
    pub before_key: f64,
    /// The windows starting on the frame after a key pose's target frame.
    pub after_key: f64,
    /// The windows ending on the same frames as `before_key`, of the same songs danced with the
    /// same noise and no key pose at all.
    pub free: f64,
    /// Mean joint speed over the `before_key` windows, m/s.
    pub before_key_speed: f64,
    /// Mean joint speed over the `free` windows, m/s.
    pub free_speed: f64,
    /// Windows of each kind.
    pub windows: usize,
}

/// Kinetic features of every whole 5 s window of a track's positions.
fn window_kinetics(positions: &[glam::Vec3]) -> Vec<Vec<f64>> {
    windows_of(positions, KINETIC_WINDOW_FRAMES)
}

/// Kinetic features of every whole window of `frames` frames of a track's positions.
pub fn windows_of(positions: &[glam::Vec3], frames: usize) -> Vec<Vec<f64>> {
    positions
        .chunks_exact(frames * JOINT_COUNT)
        .filter_map(|w| {
            let t = JointTrack::new(w, JOINT_COUNT, TANG_FPS).ok()?;
            kinetic_features(&t).ok()
        })
        .collect()
}

impl EvalSet {
    /// Builds every dance under `data` (as `dataset build` does) with `jobs` threads; the
    /// validation dances are scored.
    pub fn load(data: &Path, jobs: usize) -> Result<EvalSet> {
        Self::load_scoring(data, jobs, ScoredDances::Validation)
    }

    /// As [`EvalSet::load`], scoring the `scored` dances (the reference is always the
    /// training dances).
    pub fn load_scoring(data: &Path, jobs: usize, scored: ScoredDances) -> Result<EvalSet> {
        let built = offline::dataset::build_all(data, jobs, |d, _| d.audio.is_some(), false)?;
        let skeleton = Skeleton::default_adult();
        let mut set = EvalSet {
            validation: Vec::new(),
            train_positions: Vec::new(),
            train_styles: Vec::new(),
            train_kinetic: Vec::new(),
            train_kinetic_short: Vec::new(),
            styles: None,
        };
        let mut style_windows = Vec::new();
        let style_frames = (STYLE_WINDOW_S * TANG_FPS) as usize;
        for b in built.into_iter().filter_map(|(_, r)| r.ok()) {
            let poses = b.poses_on_default_rig();
            if !b.validation {
                let p = skeleton.trajectory(&poses);
                set.train_kinetic.extend(window_kinetics(&p));
                set.train_kinetic_short
                    .extend(windows_of(&p, (TRANSITION_S * TANG_FPS) as usize));
                if let Some(style) = style_of(&b.name) {
                    style_windows
                        .extend(windows_of(&p, style_frames).into_iter().map(|w| (style, w)));
                }
                set.train_positions.push(p);
                set.train_styles.push(style_of(&b.name));
            }
            if b.validation != (scored == ScoredDances::Validation) {
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
        set.styles = StyleClassifier::fit(&style_windows);
        anyhow::ensure!(
            !set.validation.is_empty() && set.train_positions.len() >= 2,
            "the evaluation needs validation and training dances with music under {}",
            data.display()
        );
        Ok(set)
    }

    /// Each dance scored: its name, its captured poses and its music frames.
    pub fn scored_dances(
        &self,
    ) -> impl Iterator<Item = (&str, &[Pose], &[[f32; dsp::feature::FEATURE_DIM]])> {
        self.validation
            .iter()
            .map(|d| (d.name.as_str(), d.poses.as_slice(), d.music.as_slice()))
    }

    /// World joint positions of every training dance (25 fps, [`JOINT_COUNT`] a frame).
    pub fn training_positions(&self) -> &[Vec<glam::Vec3>] {
        &self.train_positions
    }

    /// Each training dance's style ([`STYLES`] index), in [`EvalSet::training_positions`] order.
    pub fn training_styles(&self) -> &[Option<usize>] {
        &self.train_styles
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
        for (i, (track, dance)) in tracks.iter().zip(&self.validation).enumerate() {
            row.seconds += track.duration_s();
            let on = beat_align(track, &dance.beats);
            row.beat_align += on / n as f64;
            row.on_minus_off += (on - beat_align(track, &half_beat_later(&dance.beats))) / n as f64;
            let others: Vec<f64> = (1..=3.min(n - 1))
                .map(|k| beat_align(track, &self.validation[(i + k) % n].beats))
                .collect();
            row.beat_align_other +=
                others.iter().sum::<f64>() / others.len().max(1) as f64 / n as f64;
            if let Ok(o) = beat_offset(track, Joint::Hips.index(), &dance.beats) {
                row.beat_offset_s += o.mean_s / n as f64;
            }
            row.freezes += detect_freezes(track, FreezeParams::default())?.freezes;
            row.foot_skate_mps += foot_skating_mps(track)? / n as f64;
            if let Some(r) = quiet_phrase_ratio(&positions[i], &dance.music) {
                row.quiet_phrase_speed_ratio += r;
                row.quiet_phrase_dances += 1;
            }
        }
        row.quiet_phrase_speed_ratio /= row.quiet_phrase_dances.max(1) as f64;
        let root = Joint::Hips.index();
        row.fpd = fpd(&train, &tracks, root)?;
        row.fmd = fmd(&train, &tracks, root)?;
        let kinetic: Vec<Vec<f64>> = positions.iter().flat_map(|p| window_kinetics(p)).collect();
        row.fid_k = fid_k(&self.train_kinetic, &kinetic)?;
        row.dist_k = dist_k(&self.train_kinetic, &kinetic)?;
        Ok(row)
    }

    /// The ground truth retimed within each beat of its music by `depth`, as
    /// `danced-train dancer --beat-retime` retimes the training dances.
    pub fn ground_truth_beat_retimed(&self, depth: f64) -> Vec<Vec<Pose>> {
        self.validation
            .iter()
            .map(|d| {
                let times = offline::dataset::beat_retime_times(&d.music, d.poses.len(), depth);
                offline::dataset::warp_poses(&d.poses, &times)
            })
            .collect()
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
        let (mut sum, mut count) = (0.0, 0usize);
        for (i, d) in self.validation.iter().enumerate() {
            let frames = d.music.len().saturating_sub(source.lookahead_frames());
            let cues = key_cues(i, frames, bank);
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

    /// How the motion leading into key poses (announced [`TRANSITION_S`] ahead) and out of
    /// them compares with free dancing: FID_k of the three kinds of window, over
    /// [`TRANSITION_PASSES`] passes of every validation song, each with its own noise seed, cue
    /// times and key poses. Free dancing is the same pass danced with no cue, so it is neither
    /// the approach to a key pose nor the way out of one.
    pub fn transition_fid(
        &self,
        source: &mut dyn MotionSource,
        temperature: f32,
        seed: u64,
        bank: &[[Quat; JOINT_COUNT]],
    ) -> Result<TransitionFid> {
        let len = (TRANSITION_S * TANG_FPS).round() as usize;
        let skeleton = Skeleton::default_adult();
        let (mut before, mut after, mut free) = (Vec::new(), Vec::new(), Vec::new());
        let mut speeds = (0.0, 0.0);
        for pass in 0..TRANSITION_PASSES {
            let pass_seed = seed.wrapping_add(pass as u64);
            for (i, d) in self.validation.iter().enumerate() {
                let frames = d.music.len().saturating_sub(source.lookahead_frames());
                let cues = key_cues_of_pass(i, frames, bank, pass);
                let cued = dance_to(source, &d.music, frames, temperature, pass_seed, &cues, len);
                let uncued = dance_to(source, &d.music, frames, temperature, pass_seed, &[], 0);
                let (cued, uncued) = (skeleton.trajectory(&cued), skeleton.trajectory(&uncued));
                let window = |p: &[glam::Vec3], from: usize| {
                    let w = p.get(from * JOINT_COUNT..(from + len) * JOINT_COUNT)?;
                    kinetic_features(&JointTrack::new(w, JOINT_COUNT, TANG_FPS).ok()?).ok()
                };
                for c in cues.iter().filter(|c| c.frame + 1 >= len) {
                    let start = c.frame + 1 - len;
                    let windows = (
                        window(&cued, start),
                        window(&cued, c.frame + 1),
                        window(&uncued, start),
                    );
                    if let (Some(b), Some(a), Some(f)) = windows {
                        before.push(b);
                        after.push(a);
                        free.push(f);
                        speeds.0 += window_speed(&cued, start, start + len);
                        speeds.1 += window_speed(&uncued, start, start + len);
                    }
                }
            }
        }
        Ok(TransitionFid {
            before_key: fid_k(&self.train_kinetic_short, &before)?,
            after_key: fid_k(&self.train_kinetic_short, &after)?,
            free: fid_k(&self.train_kinetic_short, &free)?,
            before_key_speed: speeds.0 / before.len().max(1) as f64,
            free_speed: speeds.1 / before.len().max(1) as f64,
            windows: before.len(),
        })
    }

    /// The style classifier's names for every [`STYLE_WINDOW_S`] window of `motions` (one per
    /// validation dance): `confusion[song's style][named style]`, windows counted.
    pub fn style_confusion(&self, motions: &[Vec<Pose>]) -> Option<[[usize; 4]; 4]> {
        let classifier = self.styles.as_ref()?;
        let skeleton = Skeleton::default_adult();
        let mut confusion = [[0usize; 4]; 4];
        for (m, d) in motions.iter().zip(&self.validation) {
            if let Some(style) = style_of(&d.name) {
                tally_windows(classifier, &skeleton, m, &mut confusion[style]);
            }
        }
        Some(confusion)
    }

    /// What the style judge reads, by the song's style: over every [`STYLE_WINDOW_S`] window
    /// of `motions` (one per validation dance), the kinetic features averaged over the joints.
    pub fn style_kinetics(&self, motions: &[Vec<Pose>]) -> [Option<KineticProfile>; 4] {
        let skeleton = Skeleton::default_adult();
        let mut windows: [Vec<Vec<f64>>; 4] = Default::default();
        for (m, d) in motions.iter().zip(&self.validation) {
            if let Some(style) = style_of(&d.name) {
                let p = skeleton.trajectory(m);
                windows[style].extend(windows_of(&p, (STYLE_WINDOW_S * TANG_FPS) as usize));
            }
        }
        windows.map(|w| KineticProfile::of(&w))
    }

    /// The style classifier's names for every [`STYLE_WINDOW_S`] window of `source` dancing
    /// every validation song with each style requested in turn: `confusion[requested][named]`.
    pub fn requested_style_confusion(
        &self,
        source: &mut dyn MotionSource,
        temperature: f32,
        seed: u64,
    ) -> Option<[[usize; 4]; 4]> {
        let classifier = self.styles.as_ref()?;
        let skeleton = Skeleton::default_adult();
        let mut confusion = [[0usize; 4]; 4];
        for style in DanceStyle::ALL {
            for d in &self.validation {
                let m = dance_with(source, &d.music, d.music.len(), seed, |_| Controls {
                    temperature,
                    style: StyleRequest::Style(style),
                    ..Controls::default()
                });
                tally_windows(classifier, &skeleton, &m, &mut confusion[style.index()]);
            }
        }
        Some(confusion)
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

/// The key-pose cues of validation song `song` (`frames` long): a pose of `bank`, in turn,
/// every [`KEY_CUE_SPACING_S`] from [`KEY_CUE_SPACING_S`] / 2 on.
fn key_cues(song: usize, frames: usize, bank: &[[Quat; JOINT_COUNT]]) -> Vec<KeyCue> {
    key_cues_of_pass(song, frames, bank, 0)
}

/// The cues of pass `pass` of [`TRANSITION_PASSES`]: those of [`key_cues`] moved later by
/// `pass` / [`TRANSITION_PASSES`] of their spacing, and each pass takes its own bank poses.
fn key_cues_of_pass(
    song: usize,
    frames: usize,
    bank: &[[Quat; JOINT_COUNT]],
    pass: usize,
) -> Vec<KeyCue> {
    let spacing = (KEY_CUE_SPACING_S * TANG_FPS).round() as usize;
    let first = spacing / 2 + pass * spacing / TRANSITION_PASSES;
    (0..)
        .map(|k| first + k * spacing)
        .take_while(|&f| f < frames)
        .enumerate()
        .map(|(k, frame)| KeyCue {
            name: String::new(),
            rotations: bank[(song * 5 + k + pass * 53) % bank.len()],
            frame,
        })
        .collect()
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
    dance_with(source, music, frames, seed, |i| Controls {
        temperature,
        key_pose: target_at(cues, i, lead),
        beat_accent: None,
        style: StyleRequest::Auto,
        key_route: None,
    })
}

/// Runs `source` (reset with `seed`) over `frames` frames of `music` (fewer where its
/// look-ahead runs past the end) with the controls `controls` gives each frame.
fn dance_with(
    source: &mut dyn MotionSource,
    music: &[[f32; dsp::feature::FEATURE_DIM]],
    frames: usize,
    seed: u64,
    controls: impl FnMut(usize) -> Controls,
) -> Vec<Pose> {
    let look = source.lookahead_frames();
    source.reset(seed);
    let frames = frames.min(music.len().saturating_sub(look));
    crate::offline_dance::dance_stream(source, music, 0, frames, controls)
}

/// Adds the style `classifier` names for each [`STYLE_WINDOW_S`] window of `motion` to `row`.
fn tally_windows(
    classifier: &StyleClassifier,
    skeleton: &Skeleton,
    motion: &[Pose],
    row: &mut [usize; 4],
) {
    let p = skeleton.trajectory(motion);
    for w in windows_of(&p, (STYLE_WINDOW_S * TANG_FPS) as usize) {
        if let Some(named) = classifier.classify(&w) {
            row[named] += 1;
        }
    }
}

/// Foot skating of a track (our rig's joints): the toes' horizontal speed while planted, m/s,
/// with the floor under the toes.
pub fn foot_skating_mps(track: &JointTrack<'_>) -> Result<f64> {
    let toes = [Joint::LeftToes.index(), Joint::RightToes.index()];
    let ground_y_m = toe_floor_y(track, &toes)?;
    let s = foot_skating(
        track,
        &toes,
        ContactParams {
            ground_y_m,
            ..ContactParams::default()
        },
    )?;
    Ok(s.mean_speed_mps)
}

/// The midpoints between consecutive beats: where a dancer at chance is as often as on the beat.
pub fn half_beat_later(beats: &[f64]) -> Vec<f64> {
    beats.windows(2).map(|w| 0.5 * (w[0] + w[1])).collect()
}

/// Tempo bands of the music-side table, BPM (lower bound inclusive).
pub const TEMPO_BANDS: [(f64, f64); 3] = [(60.0, 100.0), (100.0, 130.0), (130.0, 180.0)];

/// One song of the [`MusicSet`].
struct MusicSong {
    features: Vec<[f32; dsp::feature::FEATURE_DIM]>,
    beats: Vec<f64>,
    /// The same beats half a beat later: where a dancer at chance is as often as on the beat.
    off_beats: Vec<f64>,
    bpm: f64,
    /// The quiet section, seconds, if any.
    section: Option<(f64, f64)>,
    /// The drumless intro, seconds, if any.
    intro: Option<(f64, f64)>,
}

/// Songs with exact beats that are in no training dance (`synth-beats`): only the music-side
/// metrics apply (no ground-truth motion).
pub struct MusicSet {
    songs: Vec<MusicSong>,
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
    /// BeatAlign on the beats minus on the beats shifted half a beat, per [`TEMPO_BANDS`]
    /// (mean over the band's songs; 0 is chance).
    pub on_minus_off: [f64; 3],
    /// Songs in each band.
    pub band_songs: [usize; 3],
    /// Mean joint speed in quiet sections and drumless intros over that in the rest (mean over
    /// the songs that have them).
    pub quiet_speed_ratio: f64,
    /// Songs with a quiet part.
    pub quiet_songs: usize,
    /// The same in quiet sections alone (against the rest: neither section nor intro).
    pub section_speed_ratio: f64,
    /// Songs with a quiet section.
    pub section_songs: usize,
    /// The same in drumless intros alone.
    pub intro_speed_ratio: f64,
    /// Songs with a drumless intro.
    pub intro_songs: usize,
    /// Transflower beat offset, seconds.
    pub beat_offset_s: f64,
    /// Freezes, summed over songs.
    pub freezes: usize,
    /// Songs scored.
    pub songs: usize,
}

/// The mean speed of the joints of `track` (positions, [`JOINT_COUNT`] a frame) from frame
/// `f − 1` to frame `f`, m/s.
fn joint_speed(track: &[glam::Vec3], f: usize) -> f64 {
    model::rig::Skeleton::mean_joint_step(track, f) * TANG_FPS
}

/// The mean joint speed of `track` over frames `from + 1 .. to` (each against the one before),
/// m/s; 0 for fewer than two frames.
fn window_speed(track: &[glam::Vec3], from: usize, to: usize) -> f64 {
    let to = to.min(track.len() / JOINT_COUNT);
    let steps = to.saturating_sub(from + 1);
    (from + 1..to).map(|f| joint_speed(track, f)).sum::<f64>() / steps.max(1) as f64
}

/// Mean joint speed (m/s) of a joint `track` at 25 fps (as [`Skeleton::trajectory`] lays it
/// out) in frames inside `spans` (seconds) and outside them, skipping the first 2 s.
pub fn speed_inside_and_out(track: &[glam::Vec3], spans: &[(f64, f64)]) -> (f64, f64) {
    let (inside, outside) = speed_split(track, |f| {
        let t = f as f64 / TANG_FPS;
        spans.iter().any(|&(a, b)| (a..b).contains(&t))
    });
    (inside.0, outside.0)
}

/// The mean joint speed of `track` (m/s) within `span` (seconds) as [`speed_split`] counts
/// it; None where no frame is scored there (an intro within the first 2 s).
fn speed_within(track: &[glam::Vec3], span: (f64, f64)) -> Option<f64> {
    let ((speed, frames), _) =
        speed_split(track, |f| (span.0..span.1).contains(&(f as f64 / TANG_FPS)));
    (frames > 0).then_some(speed)
}

/// The mean joint speed of `track` (m/s) and its frame count where `inside(frame)` holds and
/// where it does not, skipping the first 2 s (the dancer settling in).
fn speed_split(
    track: &[glam::Vec3],
    inside: impl Fn(usize) -> bool,
) -> ((f64, usize), (f64, usize)) {
    let frames = track.len() / JOINT_COUNT;
    let (mut yes, mut no) = ((0.0, 0usize), (0.0, 0usize));
    for f in (2.0 * TANG_FPS) as usize..frames {
        let acc = if inside(f) { &mut yes } else { &mut no };
        acc.0 += joint_speed(track, f);
        acc.1 += 1;
    }
    let mean = |(sum, n): (f64, usize)| (sum / n.max(1) as f64, n);
    (mean(yes), mean(no))
}

/// How far below its recent peak ([`dsp::LevelFollower`]) the music must sit for a frame to
/// count as a quiet phrase, dB: the synth songs' quiet sections sit 8–25 dB below.
pub const QUIET_PHRASE_DB: f32 = 8.0;

/// Joint speed where the music heard sits [`QUIET_PHRASE_DB`] or more below its recent peak
/// over that elsewhere; None with less than a second of such frames.
fn quiet_phrase_ratio(
    track: &[glam::Vec3],
    music: &[[f32; dsp::feature::FEATURE_DIM]],
) -> Option<f64> {
    let level = dsp::FeatureLayout::RELATIVE_LEVEL;
    let ((quiet, frames), (rest, _)) = speed_split(track, |f| {
        music.get(f).is_some_and(|m| m[level] <= -QUIET_PHRASE_DB)
    });
    (frames as f64 >= TANG_FPS && rest > 0.0).then(|| quiet / rest)
}

impl MusicSet {
    /// Analyses every song of `data/synth-beats` with the streaming analysis at 25 fps.
    pub fn load(data: &Path) -> Result<MusicSet> {
        let set = crate::bench::sets::synth_set(data);
        anyhow::ensure!(
            !set.items.is_empty(),
            "no songs under {}",
            data.join("synth-beats").display()
        );
        let mut songs = Vec::new();
        for item in set.items {
            let a = offline::analysis::analyze_file(
                &item.audio,
                offline::analysis::AnalyzeOptions::native(Some(TANG_FPS)),
                &mut |_, _| {},
            )
            .with_context(|| format!("analysing {}", item.audio.display()))?;
            let info = crate::bench::sets::SynthSongInfo::read(&item.audio);
            let bpm = info.as_ref().map_or(0.0, |i| i.bpm);
            let off_beats = half_beat_later(&item.beats);
            songs.push(MusicSong {
                features: dsp::predicted_stream(
                    &a.features,
                    model::horizon::data_horizon(TANG_FPS),
                ),
                beats: item.beats,
                off_beats,
                bpm,
                section: info.as_ref().and_then(|i| i.quiet),
                intro: info.as_ref().and_then(|i| i.intro()),
            });
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
        for (i, song) in self.songs.iter().enumerate() {
            let music = &song.features;
            let motion = dance_to(source, music, music.len(), temperature, seed, &[], 0);
            let p = skeleton.trajectory(&motion);
            let track = JointTrack::new(&p, JOINT_COUNT, TANG_FPS)?;
            let on = beat_align(&track, &song.beats);
            row.beat_align += on / n as f64;
            let others: Vec<f64> = (1..=3.min(n - 1))
                .map(|k| beat_align(&track, &self.songs[(i + k) % n].beats))
                .collect();
            row.beat_align_other +=
                others.iter().sum::<f64>() / others.len().max(1) as f64 / n as f64;
            if let Some(b) = TEMPO_BANDS
                .iter()
                .position(|&(lo, hi)| (lo..hi).contains(&song.bpm))
            {
                row.on_minus_off[b] += on - beat_align(&track, &song.off_beats);
                row.band_songs[b] += 1;
            }
            let parts: Vec<(f64, f64)> = song.section.into_iter().chain(song.intro).collect();
            let (quiet, rest) = speed_inside_and_out(&p, &parts);
            if !parts.is_empty() && rest > 0.0 {
                row.quiet_speed_ratio += quiet / rest;
                row.quiet_songs += 1;
                if let Some(speed) = song.section.and_then(|s| speed_within(&p, s)) {
                    row.section_speed_ratio += speed / rest;
                    row.section_songs += 1;
                }
                if let Some(speed) = song.intro.and_then(|s| speed_within(&p, s)) {
                    row.intro_speed_ratio += speed / rest;
                    row.intro_songs += 1;
                }
            }
            if let Ok(o) = beat_offset(&track, Joint::Hips.index(), &song.beats) {
                row.beat_offset_s += o.mean_s / n as f64;
            }
            row.freezes += detect_freezes(&track, FreezeParams::default())?.freezes;
        }
        for (d, k) in row.on_minus_off.iter_mut().zip(row.band_songs) {
            *d /= k.max(1) as f64;
        }
        row.quiet_speed_ratio /= row.quiet_songs.max(1) as f64;
        row.section_speed_ratio /= row.section_songs.max(1) as f64;
        row.intro_speed_ratio /= row.intro_songs.max(1) as f64;
        Ok(row)
    }
}

/// The music-side table of `danced eval`.
pub fn music_table(rows: &[MusicRow]) -> String {
    let bands = rows.first().map_or([0; 3], |r| r.band_songs);
    let mut s = format!(
        "| system | BeatAlign ↑ | vs other songs | on − half-beat-shifted beats, 60–100 / 100–130 / 130–180 BPM ({} / {} / {} songs) ↑ | joint speed quiet / rest ({} songs) ↓ | of which quiet sections ({}); drumless intros ({}) | beat offset s ↓ | freezes |\n| --- | --- | --- | --- | --- | --- | --- | --- |\n",
        bands[0],
        bands[1],
        bands[2],
        rows.first().map_or(0, |r| r.quiet_songs),
        rows.first().map_or(0, |r| r.section_songs),
        rows.first().map_or(0, |r| r.intro_songs)
    );
    for r in rows {
        s += &format!(
            "| {} | {:.3} | {:.3} | {:+.3} / {:+.3} / {:+.3} | {:.2} | {:.2}; {:.2} | {:.3} | {} |\n",
            r.system,
            r.beat_align,
            r.beat_align_other,
            r.on_minus_off[0],
            r.on_minus_off[1],
            r.on_minus_off[2],
            r.quiet_speed_ratio,
            r.section_speed_ratio,
            r.intro_speed_ratio,
            r.beat_offset_s,
            r.freezes
        );
    }
    s
}

/// The retrieval dancer on `library`, for rows.
pub fn retrieval(library: ClipLibrary) -> Result<RetrievalDancer> {
    RetrievalDancer::new(library, 1).context("starting the retrieval dancer")
}

/// The kinetic features the style judge reads, averaged over the joints and a style's windows.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct KineticProfile {
    /// Mean squared horizontal speed, m²/s².
    pub horizontal: f64,
    /// Mean squared vertical speed, m²/s².
    pub vertical: f64,
    /// Mean acceleration, m/s².
    pub acceleration: f64,
    /// Windows averaged.
    pub windows: usize,
}

impl KineticProfile {
    /// The mean over `windows` (kinetic feature vectors, three per joint) and their joints;
    /// `None` without a window.
    pub fn of(windows: &[Vec<f64>]) -> Option<Self> {
        let mean = |k: usize| {
            windows
                .iter()
                .map(|w| {
                    let joints = (w.len() / 3).max(1) as f64;
                    w.iter().skip(k).step_by(3).sum::<f64>() / joints
                })
                .sum::<f64>()
                / windows.len() as f64
        };
        (!windows.is_empty()).then(|| KineticProfile {
            horizontal: mean(0),
            vertical: mean(1),
            acceleration: mean(2),
            windows: windows.len(),
        })
    }
}

/// Kinetic profiles by the song's style, one row per system and style, as a table.
pub fn kinetics_table(rows: &[(String, [Option<KineticProfile>; 4])]) -> String {
    let mut s = String::from(
        "| system | song's style | horizontal speed² m²/s² | vertical speed² m²/s² | acceleration m/s² | windows |\n| --- | --- | --- | --- | --- | --- |\n",
    );
    for (system, profiles) in rows {
        for (style, p) in profiles.iter().enumerate() {
            if let Some(p) = p {
                s += &format!(
                    "| {system} | {} | {:.3} | {:.3} | {:.2} | {} |\n",
                    STYLES[style], p.horizontal, p.vertical, p.acceleration, p.windows
                );
            }
        }
    }
    s
}

/// A style confusion matrix as a table, with the share named right.
pub fn style_table(system: &str, confusion: &[[usize; 4]; 4]) -> String {
    style_table_of(system, "song's style", confusion)
}

/// [`style_table`] with its rows named `rows` (the song's style, or the style requested).
pub fn style_table_of(system: &str, rows: &str, confusion: &[[usize; 4]; 4]) -> String {
    let mut s = format!(
        "| {system}: {rows} ↓, named → | {} | named right |\n| --- |{}\n",
        STYLES.join(" | "),
        " --- |".repeat(STYLES.len() + 1)
    );
    for (style, row) in confusion.iter().enumerate() {
        let total: usize = row.iter().sum();
        if total == 0 {
            continue;
        }
        s += &format!(
            "| {} | {} | {:.0} % |\n",
            STYLES[style],
            row.map(|n| n.to_string()).join(" | "),
            100.0 * row[style] as f64 / total as f64
        );
    }
    s
}

/// The table `danced eval` prints.
pub fn table(rows: &[EvalRow]) -> String {
    let mut s = format!(
        "| system | BeatAlign ↑ | vs other songs | on − half-beat-shifted ↑ | beat offset s ↓ | FPD ↓ | FMD ↓ | FID_k ↓ | Dist_k | freezes | foot skate m/s ↓ | speed ≥ {QUIET_PHRASE_DB} dB below the recent peak / rest ({} dances) |\n| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |\n",
        rows.first().map_or(0, |r| r.quiet_phrase_dances)
    );
    for r in rows {
        s += &format!(
            "| {} | {:.3} | {:.3} | {:+.3} | {:.3} | {:.2} | {:.2} | {:.1} | {:.2} | {} | {:.3} | {:.2} |\n",
            r.system,
            r.beat_align,
            r.beat_align_other,
            r.on_minus_off,
            r.beat_offset_s,
            r.fpd,
            r.fmd,
            r.fid_k,
            r.dist_k,
            r.freezes,
            r.foot_skate_mps,
            r.quiet_phrase_speed_ratio
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn training_songs_are_scored_without_a_validation_dance() {
        let Some(data) = testkit::require_shared("tang2018") else {
            return;
        };
        let split = offline::dataset::dances_with_split(&data).unwrap();
        let validation: Vec<&String> = split.iter().filter(|d| d.2).map(|d| &d.1).collect();
        let set = EvalSet::load_scoring(&data, 2, ScoredDances::Training).unwrap();
        let scored = set.validation_names();
        // Every training dance with its song (tang2018 lacks five songs), none of validation.
        assert!(scored.len() >= 25, "{scored:?}");
        assert!(
            scored.iter().all(|n| !validation.contains(&n)),
            "{scored:?}"
        );
        assert_eq!(set.train_positions.len(), scored.len());
        let gt = set.score("ground truth", &set.ground_truth()).unwrap();
        // The training dances scored against themselves: the very same windows.
        assert!(gt.fid_k.abs() < 1e-3, "{}", gt.fid_k);
    }

    #[test]
    fn each_transition_pass_moves_its_cues_and_takes_its_own_key_poses() {
        let bank: Vec<[Quat; JOINT_COUNT]> = (0..16)
            .map(|i| [Quat::from_rotation_x(i as f32 * 0.01); JOINT_COUNT])
            .collect();
        let frames = 1_200;
        let spacing = (KEY_CUE_SPACING_S * TANG_FPS).round() as usize;
        assert_eq!(
            key_cues(2, frames, &bank),
            key_cues_of_pass(2, frames, &bank, 0)
        );
        let first = key_cues_of_pass(2, frames, &bank, 0);
        assert_eq!(first[0].frame, spacing / 2);
        assert_eq!(first[1].frame - first[0].frame, spacing);
        for pass in 1..TRANSITION_PASSES {
            let cues = key_cues_of_pass(2, frames, &bank, pass);
            // Moved by a tenth of the spacing a pass: the passes tile the gap between cues.
            // (16 poses, as the shipped bank holds.)
            assert_eq!(
                cues[0].frame,
                spacing / 2 + pass * spacing / TRANSITION_PASSES
            );
            assert!(cues.iter().all(|c| c.frame < frames));
            assert!(
                cues.iter()
                    .zip(&first)
                    .all(|(c, f)| c.rotations != f.rotations),
                "pass {pass}"
            );
        }
    }

    #[test]
    fn a_windows_joint_speed_is_the_joints_mean_speed_over_it() {
        // Every joint still for 10 frames, then moving 4 cm a frame (1 m/s at 25 fps) along x.
        let track: Vec<glam::Vec3> = (0..30usize)
            .flat_map(|f| {
                let x = 0.04 * f.saturating_sub(10) as f32;
                (0..JOINT_COUNT).map(move |j| glam::Vec3::new(x, j as f32 * 0.1, 0.0))
            })
            .collect();
        assert_eq!(window_speed(&track, 0, 10), 0.0);
        assert!((window_speed(&track, 10, 30) - 1.0).abs() < 1e-5);
        // Half still, half moving: the mean of the steps.
        assert!((window_speed(&track, 5, 16) - 0.5).abs() < 1e-5);
        // A window running past the track is cut at its end.
        assert!((window_speed(&track, 20, 40) - 1.0).abs() < 1e-5);
    }

    #[test]
    fn quiet_phrases_are_where_the_music_sits_8_db_below_its_peak() {
        // 200 frames moving 4 cm a frame, except 2 cm a frame over frames 100..150, where the
        // music sits 10 dB below its peak (and 7 dB below over 150..200: not quiet enough).
        let step = |f: usize| if (100..150).contains(&f) { 0.02 } else { 0.04 };
        let mut x = 0.0f32;
        let track: Vec<glam::Vec3> = (0..200usize)
            .flat_map(|f| {
                x += step(f);
                (0..JOINT_COUNT).map(move |j| glam::Vec3::new(x, j as f32 * 0.1, 0.0))
            })
            .collect();
        let mut music = vec![[0.0f32; dsp::feature::FEATURE_DIM]; 200];
        for (f, m) in music.iter_mut().enumerate() {
            m[dsp::FeatureLayout::RELATIVE_LEVEL] = match f {
                100..150 => -10.0,
                150.. => -7.0,
                _ => 0.0,
            };
        }
        let ratio = quiet_phrase_ratio(&track, &music).expect("2 s of quiet phrase");
        assert!((ratio - 0.5).abs() < 1e-5, "{ratio}");
        // Less than a second of it gives no ratio.
        for m in &mut music[124..150] {
            m[dsp::FeatureLayout::RELATIVE_LEVEL] = 0.0;
        }
        assert_eq!(quiet_phrase_ratio(&track, &music), None);
    }

    #[test]
    fn styles_come_from_the_dance_names() {
        assert_eq!(style_of("DANCE_C_2"), Some(0));
        assert_eq!(style_of("DANCE_W_31"), Some(3));
        assert_eq!(style_of("DANCE_T_5").map(|s| STYLES[s]), Some("tango"));
        assert_eq!(style_of("DANCE_X_1"), None);
        assert_eq!(style_of("song"), None);
    }

    #[test]
    fn a_kinetic_profile_averages_the_joints_and_the_windows() {
        // Two joints over 10 s: one walks along x at 1 m/s, one bobs up and down; a second
        // window has both still.
        let frames = (STYLE_WINDOW_S * TANG_FPS) as usize;
        let walk_and_bob: Vec<glam::Vec3> = (0..frames)
            .flat_map(|f| {
                let t = f as f32 / TANG_FPS as f32;
                [
                    glam::Vec3::new(t, 0.0, 0.0),
                    glam::Vec3::new(0.0, 0.1 * (std::f32::consts::TAU * t).sin(), 0.0),
                ]
            })
            .collect();
        let features =
            |p: &[glam::Vec3]| kinetic_features(&JointTrack::new(p, 2, TANG_FPS).unwrap()).unwrap();
        let moving = features(&walk_and_bob);
        let still = features(&vec![glam::Vec3::ZERO; 2 * frames]);
        let p = KineticProfile::of(&[moving.clone(), still]).unwrap();
        assert_eq!(p.windows, 2);
        // Horizontal: the walker's 1 m²/s², halved over two joints and again over two windows.
        assert!((p.horizontal - 0.25).abs() < 1e-3, "{p:?}");
        // Vertical: the bobbing joint's mean squared speed, (0.1·2π)²/2 ≈ 0.197 (smoothed a
        // little by the kinetic window), over two joints and two windows.
        assert!(
            (p.vertical - (moving[1] + moving[4]) / 4.0).abs() < 1e-9,
            "{p:?}"
        );
        assert!((0.045..0.05).contains(&p.vertical), "{p:?}");
        // Acceleration: the bob's mean |a|, 0.1·(2π)²·2/π ≈ 2.51 m/s², over four.
        assert!(
            (p.acceleration - (moving[2] + moving[5]) / 4.0).abs() < 1e-9,
            "{p:?}"
        );
        assert!((0.58..0.64).contains(&p.acceleration), "{p:?}");
        assert!(KineticProfile::of(&[]).is_none());
    }

    #[test]
    fn the_style_judge_names_the_nearest_centroid() {
        // Two styles far apart on the first feature, close on the second.
        let windows: Vec<(usize, Vec<f64>)> = (0..10)
            .flat_map(|i| {
                let j = i as f64 * 0.01;
                [(1, vec![0.0 + j, 1.0 - j]), (3, vec![5.0 + j, 1.0 + j])]
            })
            .collect();
        let c = StyleClassifier::fit(&windows).unwrap();
        assert_eq!(c.styles(), vec![1, 3]);
        assert_eq!(c.classify(&[0.4, 1.0]), Some(1));
        assert_eq!(c.classify(&[4.2, 1.05]), Some(3));
        // Standardised: the tight second feature outweighs the spread first one.
        assert_eq!(c.classify(&[4.2, 0.93]), Some(1));
        let mut confusion = [[0usize; 4]; 4];
        confusion[3] = [0, 2, 0, 6];
        let t = style_table("x", &confusion);
        assert!(t.contains("| waltz | 0 | 2 | 0 | 6 | 75 % |"), "{t}");
        assert!(!t.lines().any(|l| l.starts_with("| cha-cha |")), "{t}");
    }
}
