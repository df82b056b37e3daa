//! The tang2018 training data: which dances are held out for validation ([`is_validation`]),
//! the audit of every dance (`danced dataset audit`: length, rig fit, measured music offset,
//! tempo, and the ground truth's own BeatAlign and beat offset, the bar every model is held
//! to), and the build of the training set (`danced dataset build`, `danced-train`): motion
//! features on the rig paired with the streaming music features of its song, augmented with
//! sped-up songs and quiet passages ([`quiet_passage`]).

use std::path::{Path, PathBuf};

use model::alignment::measure_offset_within_beat;
use model::metrics::JointTrack;
use model::tang2018::{TANG_FPS, TangDance, dance_dirs};

use crate::error::OfflineError;
use crate::files::read_times;

mod audit;
mod build;
pub mod quiet_passage;

pub use audit::{AuditRow, audit, audit_table};
pub use build::{
    BuiltDance, BuiltDances, DATASET_VERSION, beat_retime_times, build_all, build_all_augmented,
    build_dance, build_dance_augmented, build_dances, build_dances_augmented, resample_poses,
    warp_poses, write_dataset,
};

/// Where a dance sits in its song: the reference beats and the measured start.
struct Alignment {
    music_beats: Vec<f64>,
    estimate: model::alignment::OffsetEstimate,
}

/// Reads the dance's reference beats and measures its start within half a beat of the nominal
/// `start_position` (both `dataset audit` and `dataset build` use exactly this alignment).
fn align(
    dance: &TangDance,
    track: &JointTrack<'_>,
    data: &Path,
) -> Result<Alignment, OfflineError> {
    let reference = data
        .join("tang2018-beats")
        .join(format!("{}.beats", dance.name));
    let music_beats = read_times(&reference).map_err(|error| OfflineError::ReferenceBeats {
        path: reference.clone(),
        error,
    })?;
    let nominal = dance.music_span.map_or(0.0, |s| s.0 / TANG_FPS);
    let estimate = measure_offset_within_beat(track, &music_beats, nominal);
    Ok(Alignment {
        music_beats,
        estimate,
    })
}

/// Every dance folder under `data/tang2018` with its name and whether it is in the validation
/// split, in name order.
pub fn dances_with_split(data: &Path) -> Result<Vec<(PathBuf, String, bool)>, OfflineError> {
    let dirs = dance_dirs(&data.join("tang2018"))?;
    let names: Vec<String> = dirs
        .iter()
        .map(|d| {
            d.file_name()
                .unwrap_or_default()
                .to_string_lossy()
                .into_owned()
        })
        .collect();
    Ok(dirs
        .into_iter()
        .zip(&names)
        .map(|(dir, name)| (dir, name.clone(), is_validation(name, &names)))
        .collect())
}

/// Deterministic split by dance, stratified by style: within each style, dances sorted by name,
/// every fifth one from the third (indices 2, 7, 12, …) goes to validation. Styles with fewer
/// than three dances stay in training.
pub fn is_validation(name: &str, all_names: &[String]) -> bool {
    let style = model::tang2018::style_letter;
    let mut same: Vec<&String> = all_names
        .iter()
        .filter(|n| style(n) == style(name))
        .collect();
    same.sort();
    same.iter()
        .position(|n| n.as_str() == name)
        .is_some_and(|i| i % 5 == 2)
}
