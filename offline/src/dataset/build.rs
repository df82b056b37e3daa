//! `danced dataset build`: every dance fitted, aligned and featurised at 25 fps, as the neural
//! dancer learns it, with its augmentation (sped-up songs, quiet passages, beat retiming), and
//! the `.npz` and manifest the training set is written as.

use std::path::{Path, PathBuf};

use model::metrics::JointTrack;
use model::rig::JOINT_COUNT;
use model::tang_fit::fit_dance;
use model::tang2018::{TANG_FPS, TangDance, load_dance};

use super::{align, dances_with_split};
use crate::analysis::{AnalyzeOptions, analyze_file_at_speed};
use crate::error::OfflineError;

/// Version of the `dataset build` file layout; bump it when an array or its meaning changes
/// (2: music is predicted over the data horizon, as a live dancer hears it).
pub const DATASET_VERSION: u32 = 2;

/// The dances a build took, in order: each one's name and what became of it (a dance that
/// could not be read or built carries the reason).
pub type BuiltDances = Vec<(String, Result<BuiltDance, OfflineError>)>;

/// One dance as it enters the training set.
#[derive(Clone, Debug)]
pub struct BuiltDance {
    /// Dance name.
    pub name: String,
    /// Style letter (C, R, T, W).
    pub style: char,
    /// Train or validation.
    pub validation: bool,
    /// Motion features, `[frames][MOTION_FEATURE_DIM]`.
    pub motion: Vec<model::motion::MotionFeatures>,
    /// Music features of the same frames, `[frames][FEATURE_DIM]` (empty for motion-only dances).
    pub music: Vec<[f32; dsp::feature::FEATURE_DIM]>,
    /// Song time of the first kept frame, seconds (when there is music).
    pub start_s: Option<f64>,
    /// Rig fit error, cm.
    pub fit_error_cm: f64,
    /// Rest height of the fitted rig's hips, metres (the dancer's size).
    pub hip_height_m: f32,
    /// Quiet passages written into it (see [`super::quiet_passage`]), frames `[start, end)`.
    pub quiet: Vec<(usize, usize)>,
}

impl BuiltDance {
    /// The motion as poses on [`Skeleton::default_adult`](model::rig::Skeleton::default_adult),
    /// root from the origin, floor at y = 0: the root path is scaled by the ratio of hip heights
    /// and shifted so the floor found under the toes is at 0, so clips of different dances
    /// neither float, sink nor jump when played in turn.
    pub fn poses_on_default_rig(&self) -> Vec<model::rig::Pose> {
        self.default_rig_poses()
    }

    /// Motion features of [`BuiltDance::poses_on_default_rig`]: what the neural dancer learns,
    /// so its hips stay at the character's height instead of the captures' drifting floor.
    pub fn motion_on_default_rig(&self) -> Vec<model::motion::MotionFeatures> {
        let mut out = Vec::with_capacity(self.motion.len());
        model::motion::encode(&self.default_rig_poses(), &mut out);
        out
    }

    fn default_rig_poses(&self) -> Vec<model::rig::Pose> {
        use model::rig::{Joint, Skeleton};
        let mut poses = Vec::new();
        model::motion::decode(&self.motion, model::motion::RootState::ORIGIN, &mut poses);
        let skeleton = Skeleton::default_adult();
        let scale = if self.hip_height_m.is_finite() && self.hip_height_m > 0.1 {
            skeleton.hip_height() / self.hip_height_m
        } else {
            1.0
        };
        for p in &mut poses {
            p.root_position *= scale;
        }
        // The floor under each frame: the lower toe's height, its minimum over ±0.5 s, then
        // averaged over ±0.5 s. The captures' vertical drifts slowly (tens of cm over a dance),
        // which a single floor per dance leaves in; the window keeps a dancer's bounce and dips.
        let positions = skeleton.trajectory(&poses);
        let lower: Vec<f32> = positions
            .chunks_exact(JOINT_COUNT)
            .map(|f| {
                f[Joint::LeftToes.index()]
                    .y
                    .min(f[Joint::RightToes.index()].y)
            })
            .collect();
        let half = (0.5 * TANG_FPS) as usize;
        let window = |i: usize| i.saturating_sub(half)..(i + half + 1).min(lower.len());
        let minimum: Vec<f32> = (0..lower.len())
            .map(|i| {
                lower[window(i)]
                    .iter()
                    .copied()
                    .fold(f32::INFINITY, f32::min)
            })
            .collect();
        let floor: Vec<f32> = (0..lower.len())
            .map(|i| {
                let w = &minimum[window(i)];
                w.iter().sum::<f32>() / w.len() as f32
            })
            .collect();
        for (p, f) in poses.iter_mut().zip(&floor) {
            if f.is_finite() {
                p.root_position.y -= f;
            }
        }
        poses
    }
}

/// Fits, aligns and featurises one dance at the motion's frame rate (25 fps): motion features
/// from the fitted rig, music features from the *streaming* analysis of the whole song (the
/// same code the daemon runs) as a live dancer hears them (predicted over the data horizon,
/// `model::horizon`), frame i of the motion paired with the music frame at song time
/// `start + i / 25`. Frames outside the song are dropped.
pub fn build_dance(
    dance: &TangDance,
    data: &Path,
    validation: bool,
) -> Result<BuiltDance, OfflineError> {
    build_dance_augmented(dance, data, validation, &[1.0], 0.0)?
        .pop()
        .ok_or_else(|| OfflineError::NothingBuilt {
            dance: dance.name.clone(),
        })
}

/// [`build_dance`] once per entry of `speeds`: the dance and its song played that many times
/// as fast together (the song varispeed, its features from the streaming analysis of the
/// sped-up audio; the poses interpolated), so a dance of 87 BPM also teaches 70 and 130 BPM.
/// A sped-up dance is named `NAME@SPEED` (its style letter stays). The rig is fitted once.
/// With `quiet_per_minute` > 0, about that many quiet passages a minute are written into each
/// built dance ([`super::quiet_passage`]): its song turned down and darkened there before the
/// streaming analysis hears it, its motion slowed to half time there; each dance's passages
/// drawn from a seed of its name (speed included).
pub fn build_dance_augmented(
    dance: &TangDance,
    data: &Path,
    validation: bool,
    speeds: &[f64],
    quiet_per_minute: f64,
) -> Result<Vec<BuiltDance>, OfflineError> {
    let fit = fit_dance(dance)?;
    let mut motion = Vec::new();
    model::motion::encode(&fit.poses, &mut motion);
    let built = BuiltDance {
        name: dance.name.clone(),
        style: dance.style,
        validation,
        motion,
        music: Vec::new(),
        start_s: None,
        fit_error_cm: fit.mean_error_cm,
        hip_height_m: fit.skeleton.hip_height(),
        quiet: Vec::new(),
    };
    let Some(audio) = &dance.audio else {
        return Ok(vec![built]);
    };
    let positions = fit.skeleton.trajectory(&fit.poses);
    let track = JointTrack::new(&positions, JOINT_COUNT, fit.fps)?;
    let start_s = align(dance, &track, data)?.estimate.start_s;
    let mut out = Vec::with_capacity(speeds.len());
    for &speed in speeds {
        if !(speed.is_finite() && speed > 0.0) {
            return Err(OfflineError::Speed {
                dance: dance.name.clone(),
                speed,
            });
        }
        let mut b = built.clone();
        if speed != 1.0 {
            b.name = format!("{}@{speed}", dance.name);
            let poses = resample_poses(&fit.poses, speed);
            b.motion.clear();
            model::motion::encode(&poses, &mut b.motion);
        }
        let opts = AnalyzeOptions::native(Some(TANG_FPS));
        let a = analyze_file_at_speed(audio, opts, speed, &mut |_, _| {})?;
        // What a live dancer hears at each frame: the analysis of a few frames earlier, its
        // beat grid extrapolated to the frame.
        let heard = dsp::predicted_stream(&a.features, model::horizon::data_horizon(TANG_FPS));
        let first = (start_s / speed * TANG_FPS).round() as i64;
        let mut keep_from = None;
        for i in 0..b.motion.len() {
            let k = first + i as i64;
            if k < 0 {
                continue;
            }
            let Some(frame) = heard.get(k as usize) else {
                break;
            };
            keep_from.get_or_insert(i);
            b.music.push(*frame);
        }
        let from = keep_from.unwrap_or(b.motion.len());
        b.motion = b.motion[from..from + b.music.len()].to_vec();
        b.start_s = Some((first + from as i64) as f64 / TANG_FPS);
        if quiet_per_minute > 0.0 {
            add_quiet_passages(
                &mut b,
                audio,
                speed,
                quiet_per_minute,
                (first + from as i64) as usize,
            )?;
        }
        out.push(b);
    }
    Ok(out)
}

/// Writes quiet passages into `b` (built from `audio` at `speed`, its frame 0 at the song's
/// analysis frame `first`): plans them on the beat and bar the analysis heard, analyses the song
/// again with the passages treated, and slows the motion there.
fn add_quiet_passages(
    b: &mut BuiltDance,
    audio: &Path,
    speed: f64,
    per_minute: f64,
    first: usize,
) -> Result<(), OfflineError> {
    use super::quiet_passage::{QuietShaper, beat_positions, plan, warp_times};
    let seed = b.name.bytes().fold(0xcbf2_9ce4_8422_2325_u64, |h, c| {
        (h ^ u64::from(c)).wrapping_mul(0x100_0000_01b3)
    });
    let mut rng = model::neural::rng::Rng::new(seed);
    let beats_per_bar = if b.style == 'W' { 3 } else { 4 };
    let beats = beat_positions(&b.music);
    let passages = plan(
        &b.music,
        &beats,
        TANG_FPS,
        beats_per_bar,
        per_minute,
        &mut rng,
    );
    if passages.is_empty() {
        return Ok(());
    }
    let mut shaper = QuietShaper::new(&passages, first as f64 / TANG_FPS, TANG_FPS);
    let opts = AnalyzeOptions::native(Some(TANG_FPS));
    let a = crate::analysis::analyze_file_shaped(
        audio,
        opts,
        speed,
        &mut |samples, first_sample, rate, channels| {
            shaper.process(samples, first_sample, rate, channels);
        },
        &mut |_, _| {},
    )?;
    let heard = dsp::predicted_stream(&a.features, model::horizon::data_horizon(TANG_FPS));
    let kept = heard.len().saturating_sub(first).min(b.music.len());
    b.music = heard[first.min(heard.len())..][..kept].to_vec();
    let times = warp_times(&beats[..kept], &passages);
    let mut poses = Vec::new();
    model::motion::decode(&b.motion, model::motion::RootState::ORIGIN, &mut poses);
    let warped = warp_poses(&poses, &times);
    b.motion.clear();
    model::motion::encode(&warped, &mut b.motion);
    b.quiet = passages
        .iter()
        .map(|p| (p.start_frame, p.end_frame))
        .collect();
    Ok(())
}

/// `poses` (at any fixed rate) played `speed` times as fast at the same rate: frame j shows
/// the original at frame j·speed, interpolated (root lerp, rotations slerp).
pub fn resample_poses(poses: &[model::rig::Pose], speed: f64) -> Vec<model::rig::Pose> {
    if poses.is_empty() || !(speed.is_finite() && speed > 0.0) {
        return poses.to_vec();
    }
    let last = poses.len() - 1;
    let frames = (last as f64 / speed).floor() as usize + 1;
    let times: Vec<f64> = (0..frames).map(|j| j as f64 * speed).collect();
    warp_poses(poses, &times)
}

/// Frame j shows `poses` at fractional frame `times[j]` (clamped to the dance; root lerp,
/// rotations slerp).
pub fn warp_poses(poses: &[model::rig::Pose], times: &[f64]) -> Vec<model::rig::Pose> {
    let Some(last) = poses.len().checked_sub(1) else {
        return Vec::new();
    };
    let mut pose = model::rig::Pose::rest();
    times
        .iter()
        .map(|&x| {
            let x = if x.is_finite() {
                x.clamp(0.0, last as f64)
            } else {
                0.0
            };
            let a = (x.floor() as usize).min(last);
            let b = (a + 1).min(last);
            let w = (x - a as f64) as f32;
            if w == 0.0 {
                return poses[a];
            }
            model::rig::blend(&poses[a], &poses[b], w, &mut pose);
            pose
        })
        .collect()
}

/// The source times of a dance retimed within each beat, as the neural dancer's beat accent
/// retimes it live: time runs at pace 1 − depth·cos(beat phase) of the music heard at each
/// frame (`music`, frame for frame), slowest on the beat, fastest between beats. Over a whole
/// beat the pace averages 1, so the dance keeps its place in the song (within depth/2π of a
/// beat). Ends where the source runs out (`frames` source frames).
pub fn beat_retime_times(
    music: &[[f32; dsp::feature::FEATURE_DIM]],
    frames: usize,
    depth: f64,
) -> Vec<f64> {
    let last = frames.saturating_sub(1) as f64;
    let mut times = Vec::with_capacity(music.len().min(frames));
    let mut t = 0.0;
    for m in music.iter().take(frames) {
        if t > last {
            break;
        }
        times.push(t);
        let cos = f64::from(m[dsp::feature::FeatureLayout::BEAT_COS]).clamp(-1.0, 1.0);
        let cos = if cos.is_finite() { cos } else { 0.0 };
        t += 1.0 - depth * cos;
    }
    times
}

impl BuiltDance {
    /// This dance retimed within each beat by [`beat_retime_times`] (its motion as it is,
    /// on whichever rig; music unchanged, cut to the retimed length): training data whose
    /// speed dips on the beat, so the network learns the accent from its beat input.
    pub fn beat_retimed(&self, depth: f64) -> BuiltDance {
        let mut poses = Vec::new();
        model::motion::decode(&self.motion, model::motion::RootState::ORIGIN, &mut poses);
        let times = beat_retime_times(&self.music, poses.len(), depth);
        let warped = warp_poses(&poses, &times);
        let mut out = self.clone();
        out.motion.clear();
        model::motion::encode(&warped, &mut out.motion);
        // The retimed motion is never longer than the music (`beat_retime_times` stops at it).
        out.music.truncate(out.motion.len());
        out
    }
}

/// Every dance under `data/tang2018` that `wanted` accepts, built by [`build_dances`] with
/// `jobs` threads, behind a progress bar on stderr when `bar` is set.
pub fn build_all(
    data: &Path,
    jobs: usize,
    wanted: impl Fn(&TangDance, bool) -> bool + Sync,
    bar: bool,
) -> Result<BuiltDances, OfflineError> {
    build_all_augmented(data, jobs, &[1.0], 0.0, wanted, bar)
}

/// [`build_all`], every training dance also at each of `speeds` and with about
/// `quiet_per_minute` quiet passages a minute ([`build_dances_augmented`]; validation dances
/// stay as they are).
pub fn build_all_augmented(
    data: &Path,
    jobs: usize,
    speeds: &[f64],
    quiet_per_minute: f64,
    wanted: impl Fn(&TangDance, bool) -> bool + Sync,
    bar: bool,
) -> Result<BuiltDances, OfflineError> {
    let dances = dances_with_split(data).map_err(|e| match e {
        OfflineError::Model(source) => OfflineError::DataSetFolder {
            path: data.join("tang2018"),
            source,
        },
        e => e,
    })?;
    let pb = if bar {
        crate::progress::count_bar(dances.len() as u64)
    } else {
        indicatif::ProgressBar::hidden()
    };
    let built = build_dances_augmented(
        data,
        &dances,
        jobs,
        speeds,
        quiet_per_minute,
        wanted,
        |name| {
            pb.set_message(name.to_string());
            pb.inc(1);
        },
    );
    pb.finish_and_clear();
    Ok(built)
}

/// Loads and builds ([`build_dance`]) the `dances` (as [`dances_with_split`] lists them) that
/// `wanted` accepts (given the loaded dance and whether it is in the validation split), with
/// `jobs` threads; `progress` hears each dance's name once it is done. One `(name, result)` per
/// dance taken, in order; a dance that cannot be read or built carries the reason.
pub fn build_dances(
    data: &Path,
    dances: &[(PathBuf, String, bool)],
    jobs: usize,
    wanted: impl Fn(&TangDance, bool) -> bool + Sync,
    progress: impl Fn(&str) + Sync,
) -> BuiltDances {
    build_dances_augmented(data, dances, jobs, &[1.0], 0.0, wanted, progress)
}

/// [`build_dances`] with every training dance also built at each of `speeds` and with about
/// `quiet_per_minute` quiet passages a minute (see [`build_dance_augmented`]; validation dances
/// are built as they are): one entry per dance and speed, the dance itself first.
pub fn build_dances_augmented(
    data: &Path,
    dances: &[(PathBuf, String, bool)],
    jobs: usize,
    speeds: &[f64],
    quiet_per_minute: f64,
    wanted: impl Fn(&TangDance, bool) -> bool + Sync,
    progress: impl Fn(&str) + Sync,
) -> BuiltDances {
    let results = crate::pool::parallel_map(dances, jobs.max(1), |(dir, name, validation)| {
        let mut all = vec![1.0];
        if !*validation {
            all.extend(speeds.iter().copied().filter(|&s| s != 1.0));
        }
        let r = match load_dance(dir) {
            Ok(d) if !wanted(&d, *validation) => None,
            Ok(d) => Some(
                match build_dance_augmented(
                    &d,
                    data,
                    *validation,
                    &all,
                    if *validation { 0.0 } else { quiet_per_minute },
                ) {
                    Ok(built) => built.into_iter().map(|b| (b.name.clone(), Ok(b))).collect(),
                    Err(e) => vec![(name.clone(), Err(e))],
                },
            ),
            Err(e) => Some(vec![(name.clone(), Err(e.into()))]),
        };
        progress(name);
        r
    });
    results.into_iter().flatten().flatten().collect()
}

/// Writes the dances as one `.npz` (arrays `<name>/motion` and, with music, `<name>/music`,
/// float32) plus a `.json` manifest beside it, both atomically.
pub fn write_dataset(path: &Path, dances: &[BuiltDance]) -> Result<(), OfflineError> {
    let tmp = path.with_extension(format!("npz.tmp{}", std::process::id()));
    let npz_error = |e: &dyn std::fmt::Display| OfflineError::Npz {
        reason: e.to_string(),
    };
    let write = || -> Result<(), OfflineError> {
        let file = std::fs::File::create(&tmp).map_err(|error| OfflineError::Write {
            path: tmp.clone(),
            error,
        })?;
        let mut npz = ndarray_npy::NpzWriter::new(file);
        for d in dances {
            let m: Vec<f32> = d.motion.iter().flatten().copied().collect();
            let m = ndarray::Array2::from_shape_vec(
                (d.motion.len(), model::motion::MOTION_FEATURE_DIM),
                m,
            )
            .map_err(|e| npz_error(&e))?;
            npz.add_array(format!("{}/motion", d.name), &m)
                .map_err(|e| npz_error(&e))?;
            if !d.music.is_empty() {
                let x: Vec<f32> = d.music.iter().flatten().copied().collect();
                let x =
                    ndarray::Array2::from_shape_vec((d.music.len(), dsp::feature::FEATURE_DIM), x)
                        .map_err(|e| npz_error(&e))?;
                npz.add_array(format!("{}/music", d.name), &x)
                    .map_err(|e| npz_error(&e))?;
            }
        }
        let file = npz.finish().map_err(|e| npz_error(&e))?;
        file.sync_all().map_err(|e| npz_error(&e))?;
        std::fs::rename(&tmp, path).map_err(|error| OfflineError::Write {
            path: path.to_path_buf(),
            error,
        })
    };
    if let Err(e) = write() {
        let _ = std::fs::remove_file(&tmp);
        return Err(e);
    }
    let entries: Vec<String> = dances
        .iter()
        .map(|d| {
            format!(
                "    {{\"name\": \"{}\", \"style\": \"{}\", \"split\": \"{}\", \"frames\": {}, \"music\": {}, \"start_s\": {}, \"fit_error_cm\": {:.3}}}",
                d.name,
                d.style,
                if d.validation { "validation" } else { "train" },
                d.motion.len(),
                !d.music.is_empty(),
                d.start_s.map_or("null".to_string(), |s| format!("{s:.3}")),
                d.fit_error_cm
            )
        })
        .collect();
    let manifest = format!(
        "{{\n  \"dataset_version\": {DATASET_VERSION},\n  \"source\": \"tang2018 (Tang, Jia & Mao 2018)\",\n  \"fps\": {TANG_FPS},\n  \"motion_layout_version\": {},\n  \"motion_dim\": {},\n  \"music_layout_version\": {},\n  \"music_dim\": {},\n  \"dances\": [\n{}\n  ]\n}}\n",
        model::motion::MOTION_LAYOUT_VERSION,
        model::motion::MOTION_FEATURE_DIM,
        dsp::feature::FEATURE_LAYOUT_VERSION,
        dsp::feature::FEATURE_DIM,
        entries.join(",\n")
    );
    let json = path.with_extension("json");
    crate::files::write_atomic(&json, manifest.as_bytes())
        .map_err(|error| OfflineError::Write { path: json, error })
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{Quat, Vec3};
    use model::rig::{Joint, Pose};

    fn walk(frames: usize) -> Vec<Pose> {
        (0..frames)
            .map(|i| {
                let mut p = Pose::rest();
                p.root_position = Vec3::new(0.1 * i as f32, 0.9, 0.0);
                p.set_rotation(Joint::LeftUpperArm, Quat::from_rotation_x(0.05 * i as f32));
                p
            })
            .collect()
    }

    #[test]
    fn resampled_poses_play_the_dance_faster_or_slower_with_interpolation() {
        let poses = walk(11);
        let fast = resample_poses(&poses, 2.0);
        assert_eq!(fast.len(), 6);
        for (j, p) in fast.iter().enumerate() {
            assert_eq!(*p, poses[2 * j]);
        }
        let slow = resample_poses(&poses, 0.5);
        assert_eq!(slow.len(), 21);
        // Frame 3 of the slow dance is halfway between frames 1 and 2.
        assert!((slow[3].root_position.x - 0.15).abs() < 1e-6);
        let angle = slow[3]
            .rotation(Joint::LeftUpperArm)
            .angle_between(Quat::IDENTITY);
        assert!((angle - 0.075).abs() < 1e-4, "{angle}");
        assert_eq!(resample_poses(&poses, 1.0), poses);
        assert_eq!(resample_poses(&poses, f64::NAN), poses);
        assert!(resample_poses(&[], 1.5).is_empty());
    }

    #[test]
    fn beat_retime_slows_on_the_beat_and_keeps_its_place() {
        use dsp::feature::{FEATURE_DIM, FeatureLayout};
        // A 20-frame beat: the music's beat phase at every frame.
        let frames = 200;
        let music: Vec<[f32; FEATURE_DIM]> = (0..frames)
            .map(|i| {
                let mut m = [0.0; FEATURE_DIM];
                let phase = std::f64::consts::TAU * i as f64 / 20.0;
                m[FeatureLayout::BEAT_COS] = phase.cos() as f32;
                m
            })
            .collect();
        let times = beat_retime_times(&music, frames, 0.3);
        // On the beat time runs at 0.7, half a beat later at 1.3.
        assert!((times[1] - times[0] - 0.7).abs() < 1e-6);
        assert!((times[11] - times[10] - 1.3).abs() < 1e-6);
        // After whole beats the dance is back in its place; in between within depth/2π of a
        // beat and a frame's step.
        assert!((times[100] - 100.0).abs() < 1e-3, "{}", times[100]);
        let drift = times.iter().enumerate().map(|(i, t)| (t - i as f64).abs());
        let drift = drift.fold(0.0, f64::max);
        assert!(
            drift > 0.8 && drift <= 0.3 * (20.0 / std::f64::consts::TAU + 1.0),
            "{drift}"
        );
        assert!(*times.last().unwrap() <= (frames - 1) as f64);
        // A steady walk retimed moves slowest on the beat.
        let poses = walk(frames);
        let warped = warp_poses(&poses, &times);
        let step = |i: usize| warped[i + 1].root_position.x - warped[i].root_position.x;
        assert!((step(40) - 0.07).abs() < 1e-4, "{}", step(40));
        assert!((step(50) - 0.13).abs() < 1e-4, "{}", step(50));
        // Out-of-range and non-finite times are clamped, not read past the end.
        let clamped = warp_poses(&poses, &[-1.0, f64::NAN, 1e9]);
        assert_eq!(clamped, vec![poses[0], poses[0], poses[frames - 1]]);
        assert!(warp_poses(&[], &[0.0]).is_empty());
    }
}
