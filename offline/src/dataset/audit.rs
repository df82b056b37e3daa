//! `danced dataset audit`: one row per tang2018 dance — length, rig fit, measured music offset,
//! tempo, and the ground truth's own BeatAlign and beat offset (the bar every model is held to).

use std::path::Path;

use model::alignment::measure_offset_within_beat;
use model::metrics::{JointTrack, beat_align, beat_offset};
use model::rig::{JOINT_COUNT, Joint};
use model::tang_fit::fit_dance;
use model::tang2018::{TANG_FPS, TangDance, load_dance};

use super::{align, dances_with_split};
use crate::analysis::{AnalyzeOptions, analyze_file};
use crate::error::OfflineError;
use crate::files::read_times;

/// One dance in the audit table.
#[derive(Clone, Debug, Default)]
pub struct AuditRow {
    /// Dance name.
    pub name: String,
    /// Motion frames.
    pub frames: usize,
    /// Motion seconds.
    pub seconds: f64,
    /// Mean per-joint position error of the rig fit, cm.
    pub fit_error_cm: f64,
    /// Bone-length spread of the raw points (see `model::tang_fit`).
    pub bone_spread: f64,
    /// Whether the song is available.
    pub has_audio: bool,
    /// Measured correction of the nominal start, seconds.
    pub offset_s: Option<f64>,
    /// Tempo heard by the native tracker over the danced span, BPM.
    pub tempo_bpm: Option<f64>,
    /// Ground-truth BeatAlign against the reference beats, at the measured start.
    pub beat_align: Option<f64>,
    /// Ground-truth beat offset (mean, sd), seconds.
    pub beat_offset: Option<(f64, f64)>,
    /// BeatAlign of the same motion against other songs' beats (the chance level).
    pub mismatched_beat_align: Option<f64>,
    /// Why the row is incomplete, if it is.
    pub problem: Option<String>,
}

fn audit_dance(dance: &TangDance, data: &Path) -> AuditRow {
    let mut row = AuditRow {
        name: dance.name.clone(),
        frames: dance.frames(),
        seconds: dance.seconds(),
        has_audio: dance.audio.is_some(),
        ..Default::default()
    };
    let fit = match fit_dance(dance) {
        Ok(f) => f,
        Err(e) => {
            row.problem = Some(format!("fit failed: {e}"));
            return row;
        }
    };
    row.fit_error_cm = fit.mean_error_cm;
    row.bone_spread = fit.bone_length_spread;
    let positions = fit.skeleton.trajectory(&fit.poses);
    let Ok(track) = JointTrack::new(&positions, JOINT_COUNT, fit.fps) else {
        row.problem = Some("fitted motion is not finite".into());
        return row;
    };
    if dance.audio.is_none() {
        // Motion only: the data set has no song for this dance, so no music-side numbers.
        return row;
    }
    let (music, est) = match align(dance, &track, data) {
        Ok(a) => (a.music_beats, a.estimate),
        Err(e) => {
            row.problem = Some(e.to_string());
            return row;
        }
    };
    row.offset_s = Some(est.offset_s);
    // Music beats in motion time, for the metrics.
    let local: Vec<f64> = music
        .iter()
        .map(|b| b - est.start_s)
        .filter(|b| *b >= 0.0)
        .collect();
    row.beat_align = Some(beat_align(&track, &local));
    row.beat_offset = beat_offset(&track, Joint::Hips.index(), &local)
        .ok()
        .map(|o| (o.mean_s, o.sd_s));
    // Chance level: the same motion against three other songs' beats, each aligned by the same
    // search as the true song (so the search itself earns neither side anything).
    let others: Vec<f64> = other_songs(data, &dance.name, 3)
        .iter()
        .map(|beats| {
            let first = beats.first().copied().unwrap_or(0.0);
            let other = measure_offset_within_beat(&track, beats, first);
            let shifted: Vec<f64> = beats
                .iter()
                .map(|b| b - other.start_s)
                .filter(|b| *b >= 0.0)
                .collect();
            beat_align(&track, &shifted)
        })
        .collect();
    if !others.is_empty() {
        row.mismatched_beat_align = Some(others.iter().sum::<f64>() / others.len() as f64);
    }
    if let Some(audio) = &dance.audio {
        let opts = AnalyzeOptions::native(None);
        match analyze_file(audio, opts, &mut |_, _| {}) {
            Ok(a) => {
                let end = est.start_s + dance.seconds();
                let mut t: Vec<f64> = a
                    .beats
                    .iter()
                    .filter(|b| b.time_s >= est.start_s && b.time_s <= end && b.tempo_bpm > 0.0)
                    .map(|b| b.tempo_bpm)
                    .collect();
                t.sort_by(f64::total_cmp);
                row.tempo_bpm = t.get(t.len() / 2).copied();
            }
            Err(e) => row.problem = Some(e.to_string()),
        }
    }
    row
}

/// Reference beats of up to `n` other songs, taken in name order after `name` (wrapping).
fn other_songs(data: &Path, name: &str, n: usize) -> Vec<Vec<f64>> {
    let dir = data.join("tang2018-beats");
    let mut names: Vec<String> = std::fs::read_dir(&dir)
        .map(|r| {
            r.flatten()
                .filter_map(|e| {
                    e.file_name()
                        .to_str()?
                        .strip_suffix(".beats")
                        .map(String::from)
                })
                .collect()
        })
        .unwrap_or_default();
    names.sort();
    let start = names.iter().position(|x| x.as_str() > name).unwrap_or(0);
    names
        .iter()
        .cycle()
        .skip(start)
        .take(names.len())
        .filter(|x| x.as_str() != name)
        .take(n)
        .filter_map(|x| read_times(&dir.join(format!("{x}.beats"))).ok())
        .collect()
}

/// Audits every dance under `data/tang2018` with `jobs` threads; `progress` hears each name.
pub fn audit(
    data: &Path,
    jobs: usize,
    progress: &(dyn Fn(&str) + Sync),
) -> Result<Vec<AuditRow>, OfflineError> {
    let dances = dances_with_split(data)?;
    Ok(crate::pool::parallel_map(&dances, jobs, |(dir, _, _)| {
        let row = match load_dance(dir) {
            Ok(d) => audit_dance(&d, data),
            Err(e) => AuditRow {
                name: dir
                    .file_name()
                    .unwrap_or_default()
                    .to_string_lossy()
                    .into_owned(),
                problem: Some(e.to_string()),
                ..Default::default()
            },
        };
        progress(&row.name);
        row
    }))
}

fn opt(v: Option<f64>, digits: usize) -> String {
    v.map_or("–".to_string(), |x| format!("{x:.digits$}"))
}

/// The audit as a Markdown table with totals.
pub fn audit_table(rows: &[AuditRow]) -> String {
    let mut s = String::from(
        "| dance | frames | s | fit err cm | bone spread | offset s | tempo BPM | GT BeatAlign | GT vs other songs | GT beat offset s (mean ± sd) |\n|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for r in rows {
        if let Some(p) = &r.problem
            && r.frames == 0
        {
            s += &format!("| {} | error: {p} |\n", r.name);
            continue;
        }
        s += &format!(
            "| {} | {} | {:.1} | {:.2} | {:.3} | {} | {} | {} | {} | {} |\n",
            r.name,
            r.frames,
            r.seconds,
            r.fit_error_cm,
            r.bone_spread,
            opt(r.offset_s, 3),
            opt(r.tempo_bpm, 1),
            opt(r.beat_align, 3),
            opt(r.mismatched_beat_align, 3),
            r.beat_offset
                .map_or("–".into(), |(m, sd)| format!("{m:.3} ± {sd:.3}")),
        );
    }
    let ok: Vec<&AuditRow> = rows.iter().filter(|r| r.frames > 0).collect();
    let mean = |f: &dyn Fn(&AuditRow) -> Option<f64>| {
        let v: Vec<f64> = ok.iter().filter_map(|r| f(r)).collect();
        if v.is_empty() {
            None
        } else {
            Some(v.iter().sum::<f64>() / v.len() as f64)
        }
    };
    let frames: usize = ok.iter().map(|r| r.frames).sum();
    s += &format!(
        "| **all {} dances** ({} with audio) | {} | {:.1} min | {} | {} | | | {} | {} | {} |\n",
        ok.len(),
        ok.iter().filter(|r| r.has_audio).count(),
        frames,
        frames as f64 / TANG_FPS / 60.0,
        opt(mean(&|r| Some(r.fit_error_cm)), 2),
        opt(mean(&|r| Some(r.bone_spread)), 3),
        opt(mean(&|r| r.beat_align), 3),
        opt(mean(&|r| r.mismatched_beat_align), 3),
        opt(mean(&|r| r.beat_offset.map(|o| o.0)), 3),
    );
    s
}
