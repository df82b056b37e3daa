//! A performer's own moves: dances without their music, from a folder of BVH files.
//!
//! Each file is put on the default rig by the one import every command uses ([`read_dance`]:
//! joint names by convention, by their parts or by the user's map; up axis and handedness found
//! from the motion; feet on the floor), its beat grid is found from its motion alone
//! ([`model::motion_beat`]), and the retrieval dancer's one-beat clips are cut on that grid
//! ([`library`]). With no music under them, the clips' loudness is the dance's own intensity:
//! the calmest moves stand for the quietest music of the tang2018 songs (their 10th
//! percentile), the most energetic for the loudest (their 90th), so loud music still asks for
//! big moves.

use std::path::{Path, PathBuf};

use model::bvh::{AxisHints, Bvh, RetargetOptions, Retargeted, describe_axes, import};
use model::metrics::JointTrack;
use model::motion_beat::{MotionBeatGrid, motion_beat_grid};
use model::retrieval::{ClipLibrary, FrameCue, RETRIEVAL_FPS};
use model::rig::{JOINT_COUNT, Joint, Pose, Skeleton};

use crate::OfflineError;

/// Loudness, dBFS, the calmest moves of a library stand for (tang2018's songs' 10th percentile).
pub const QUIET_DBFS: f32 = -25.0;
/// Loudness, dBFS, the most energetic moves stand for (tang2018's songs' 90th percentile).
pub const LOUD_DBFS: f32 = -11.0;
/// Seconds over which a dance's intensity is averaged for its loudness.
const INTENSITY_WINDOW_S: f64 = 2.0;
/// Least share of a dance's grid beats its motion must confirm for it to be cut.
pub const MIN_CONFIDENCE: f64 = 0.3;

/// How dance files are read: what the user said about their joints and axes.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ImportSettings {
    /// Source joint names and the joints of ours they drive, tried first.
    pub joint_map: Vec<(String, Joint)>,
    /// The file's up axis and handedness where the user gave them.
    pub hints: AxisHints,
}

impl ImportSettings {
    /// The retargeting options these settings mean.
    pub fn retarget_options(&self) -> RetargetOptions {
        RetargetOptions {
            names: self.joint_map.clone(),
            hints: self.hints,
            ..RetargetOptions::default()
        }
    }
}

/// Reads a joint map: a TOML file whose `[joints]` table maps the file's joint names to ours
/// (`"lfemur" = "LeftUpperLeg"`; our names are Unity's `HumanBodyBones`).
pub fn read_joint_map(path: &Path) -> Result<Vec<(String, Joint)>, OfflineError> {
    let bad = |reason: String| OfflineError::JointMap {
        path: path.to_path_buf(),
        reason,
    };
    let text = std::fs::read_to_string(path).map_err(|e| bad(e.to_string()))?;
    let table: toml::Table = text
        .parse()
        .map_err(|e: toml::de::Error| bad(e.to_string()))?;
    let Some(joints) = table.get("joints").and_then(|j| j.as_table()) else {
        return Err(bad("no [joints] table".into()));
    };
    let mut out = Vec::new();
    for (source, ours) in joints {
        let Some(name) = ours.as_str() else {
            return Err(bad(format!("{source}: the joint must be a string")));
        };
        let Some(joint) = Joint::from_name(name) else {
            let known: Vec<&str> = Joint::ALL.iter().map(|j| j.name()).collect();
            return Err(bad(format!(
                "{source} = {name:?}: not one of our joints ({})",
                known.join(", ")
            )));
        };
        out.push((source.clone(), joint));
    }
    Ok(out)
}

/// Reads one dance file and puts it on the default rig: the import every command uses.
pub fn read_dance(path: &Path, settings: &ImportSettings) -> Result<Retargeted, OfflineError> {
    let wrap = |e: model::ModelError| OfflineError::Dance {
        path: path.to_path_buf(),
        source: e,
    };
    let bvh = Bvh::read(path).map_err(wrap)?;
    import(
        &bvh,
        &Skeleton::default_adult(),
        &settings.retarget_options(),
    )
    .map_err(wrap)
}

/// What the import made of a file, for people.
#[derive(Clone, Debug, PartialEq)]
pub struct ImportSummary {
    /// The naming convention that matched.
    pub convention: &'static str,
    /// Up axis and handedness (`"Z up, right-handed"`), and whether they were found or given.
    pub axes: String,
    /// The unit, as metres per file unit.
    pub metres_per_unit: f32,
    /// The file's joints that drive none of ours.
    pub unmapped: Vec<String>,
    /// Mean limb and spine bone-direction error, degrees.
    pub bone_error_deg: f32,
    /// Mean girdle offset difference (the rigs' shapes), degrees.
    pub girdle_error_deg: f32,
    /// How far the floor fit moved the dance up, metres.
    pub floor_shift_m: f32,
}

impl ImportSummary {
    /// The summary of one import.
    pub fn of(r: &Retargeted) -> ImportSummary {
        ImportSummary {
            convention: r.convention,
            axes: format!(
                "{}{}",
                describe_axes(&r.axes),
                if r.axes_detected { "" } else { " (given)" }
            ),
            metres_per_unit: r.metres_per_unit,
            unmapped: r.unmapped.clone(),
            bone_error_deg: r.bone_error_deg,
            girdle_error_deg: r.girdle_error_deg,
            floor_shift_m: r.floor_shift_m,
        }
    }

    /// The unit as people name it.
    pub fn unit(&self) -> &'static str {
        if (self.metres_per_unit - 1.0).abs() < 1e-3 {
            "m"
        } else if (self.metres_per_unit - 0.01).abs() < 1e-5 {
            "cm"
        } else if (self.metres_per_unit - 0.001).abs() < 1e-6 {
            "mm"
        } else {
            "given"
        }
    }
}

/// One dance of a moves folder, ready to cut.
#[derive(Clone, Debug)]
pub struct MovesDance {
    /// File name without extension.
    pub name: String,
    /// The file.
    pub path: PathBuf,
    /// Length, seconds.
    pub seconds: f64,
    /// The dance on the default rig at the library's rate ([`RETRIEVAL_FPS`]).
    pub poses: Vec<Pose>,
    /// Its beat grid, found from its motion.
    pub grid: MotionBeatGrid,
    /// What the import made of the file.
    pub import: ImportSummary,
}

/// Reads one dance and finds its beat grid.
pub fn read_moves_dance(
    path: &Path,
    settings: &ImportSettings,
) -> Result<MovesDance, OfflineError> {
    let imported = read_dance(path, settings)?;
    let wrap = |e: model::ModelError| OfflineError::Dance {
        path: path.to_path_buf(),
        source: e,
    };
    let skeleton = Skeleton::default_adult();
    let positions = skeleton.trajectory(&imported.poses);
    let track = JointTrack::new(&positions, JOINT_COUNT, imported.fps).map_err(wrap)?;
    let grid = motion_beat_grid(&track).map_err(wrap)?;
    Ok(MovesDance {
        name: path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default(),
        path: path.to_path_buf(),
        seconds: track.duration_s(),
        // At the library's rate: played `fps / RETRIEVAL_FPS` times as fast, a frame at a time.
        poses: crate::dataset::resample_poses(&imported.poses, imported.fps / RETRIEVAL_FPS),
        grid,
        import: ImportSummary::of(&imported),
    })
}

/// The BVH files directly in `dir`, in name order.
pub fn bvh_files(dir: &Path) -> Result<Vec<PathBuf>, OfflineError> {
    let entries = std::fs::read_dir(dir).map_err(|error| OfflineError::Folder {
        path: dir.to_path_buf(),
        error,
    })?;
    let mut files: Vec<PathBuf> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.is_file()
                && p.extension()
                    .is_some_and(|x| x.to_string_lossy().eq_ignore_ascii_case("bvh"))
        })
        .collect();
    files.sort();
    Ok(files)
}

/// Each file of a folder and its dance, or why it could not be read.
pub type MovesFolder = Vec<(PathBuf, Result<MovesDance, OfflineError>)>;

/// Reads every BVH file in `dir` on `jobs` threads; each file's dance or why it could not be
/// read, in name order.
pub fn read_moves_folder(
    dir: &Path,
    settings: &ImportSettings,
    jobs: usize,
) -> Result<MovesFolder, OfflineError> {
    let files = bvh_files(dir)?;
    if files.is_empty() {
        return Err(OfflineError::NoDances(dir.to_path_buf()));
    }
    let results = crate::pool::parallel_map(&files, jobs, |p| read_moves_dance(p, settings));
    Ok(files.into_iter().zip(results).collect())
}

/// Each frame's cue for the clip cutter: beat and bar phase and tempo from the grid, loudness
/// from the dance's intensity rank (`intensity_rank`: per frame, [0, 1]).
fn cues(dance: &MovesDance, intensity_rank: &[f32]) -> Vec<FrameCue> {
    (0..dance.poses.len())
        .map(|j| {
            let t = j as f64 / RETRIEVAL_FPS;
            let rank = intensity_rank.get(j).copied().unwrap_or(0.5);
            FrameCue {
                beat_phase: dance.grid.beat_phase(t).map(|p| p as f32),
                bar_phase: dance.grid.bar_phase(t).unwrap_or(0.0) as f32,
                tempo: dance.grid.tempo_bpm as f32,
                energy: QUIET_DBFS + (LOUD_DBFS - QUIET_DBFS) * rank,
            }
        })
        .collect()
}

/// Each frame's intensity: the summed joint speed averaged over [`INTENSITY_WINDOW_S`].
fn intensity(poses: &[Pose]) -> Vec<f64> {
    let skeleton = Skeleton::default_adult();
    let p = skeleton.trajectory(poses);
    let n = poses.len();
    let speed: Vec<f64> = (0..n)
        .map(|i| {
            let (a, b) = (i.saturating_sub(1), (i + 1).min(n - 1));
            if a == b {
                return 0.0;
            }
            (0..JOINT_COUNT)
                .map(|j| f64::from((p[b * JOINT_COUNT + j] - p[a * JOINT_COUNT + j]).length()))
                .sum::<f64>()
                / (b - a) as f64
        })
        .collect();
    let half = (INTENSITY_WINDOW_S * RETRIEVAL_FPS * 0.5) as usize;
    (0..n)
        .map(|i| {
            let (a, b) = (i.saturating_sub(half), (i + half + 1).min(n));
            speed[a..b].iter().sum::<f64>() / (b - a) as f64
        })
        .collect()
}

/// Cuts the dances whose grids their motion confirms (confidence ≥ [`MIN_CONFIDENCE`]) into one
/// library; also returns how many clips each dance gave (0 for a dance left out).
pub fn library(dances: &[MovesDance]) -> (ClipLibrary, Vec<usize>) {
    let intensities: Vec<Vec<f64>> = dances.iter().map(|d| intensity(&d.poses)).collect();
    let mut all: Vec<f64> = intensities.iter().flatten().copied().collect();
    all.sort_by(f64::total_cmp);
    let rank = |v: f64| -> f32 {
        if all.len() < 2 {
            return 0.5;
        }
        all.partition_point(|&x| x < v) as f32 / (all.len() - 1) as f32
    };
    let kept: Vec<usize> = (0..dances.len())
        .filter(|&i| dances[i].grid.confidence >= MIN_CONFIDENCE)
        .collect();
    let cued: Vec<(Vec<Pose>, Vec<FrameCue>)> = kept
        .iter()
        .map(|&i| {
            let ranks: Vec<f32> = intensities[i]
                .iter()
                .map(|&v| rank(v).clamp(0.0, 1.0))
                .collect();
            (dances[i].poses.clone(), cues(&dances[i], &ranks))
        })
        .collect();
    let (library, kept_counts) = ClipLibrary::from_cues_counted(&cued);
    let mut counts = vec![0; dances.len()];
    for (&i, c) in kept.iter().zip(kept_counts) {
        counts[i] = c;
    }
    (library, counts)
}
