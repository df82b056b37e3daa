//! `danced bench beats`: the native and aubio trackers side by side on three annotated sets.

use std::fmt::Write as _;

use dsp::BeatTrackerKind;
use dsp::metrics::{self, BEAT_TOLERANCE_S, ONSET_TOLERANCE_S};
use offline::analysis::{AnalyzeOptions, FileAnalysis, analyze_file};

use super::sets::{BenchItem, BenchSet, median_tempo_bpm};

/// A beat counts only if the tracker committed to it no later than this after it happened.
pub const MAX_DECISION_LAG_S: f64 = 0.05;

/// Scores of one tracker on one recording.
#[derive(Clone, Debug, Default)]
pub struct ItemScore {
    /// Recording name.
    pub name: String,
    /// Beat F-measure over beats decided in time.
    pub f_measure: f64,
    /// CMLt over the same beats.
    pub cmlt: f64,
    /// AMLt over the same beats.
    pub amlt: f64,
    /// Onset F-measure, where onsets are annotated.
    pub onset_f: Option<f64>,
    /// Downbeat F-measure (±70 ms), where downbeats are annotated.
    pub downbeat_f: Option<f64>,
    /// Beats dropped for being decided too late.
    pub late_beats: usize,
    /// Beats emitted.
    pub beats: usize,
    /// Median decision lag of the beats, seconds.
    pub median_lag_s: f64,
    /// Median reported tempo, BPM.
    pub tempo_bpm: f64,
    /// Metrical level of the beats against the reference's.
    pub level: MetricalLevel,
    /// Signed time of every timely beat within the tolerance of a reference beat, minus that
    /// beat's time, seconds (negative: early).
    pub offsets_s: Vec<f64>,
    /// Beats per bar most often reported over the scored span.
    pub meter: usize,
    /// Share of the timely beats after the first four annotated bars that report the
    /// annotated meter, where it is annotated.
    pub meter_right: Option<f64>,
    /// Mean bar confidence the tracker reported over those beats.
    pub bar_confidence: f64,
    /// Audio seconds.
    pub duration_s: f64,
    /// Analyzer seconds.
    pub analysis_s: f64,
    /// Error text if the file failed.
    pub error: Option<String>,
}

/// How the tempo of the beats relates to the reference's.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum MetricalLevel {
    /// The same tempo (within 8 %).
    #[default]
    Same,
    /// Half the reference's tempo.
    Half,
    /// Twice the reference's tempo.
    Double,
    /// Any other relation (a third, two thirds, no steady tempo).
    Other,
}

impl MetricalLevel {
    /// The level of beats at `tempo` against a reference at `reference` BPM.
    pub fn of(tempo: f64, reference: f64) -> Self {
        let r = tempo / reference;
        let near = |x: f64| (r / x - 1.0).abs() < 0.08;
        if !r.is_finite() {
            Self::Other
        } else if near(1.0) {
            Self::Same
        } else if near(0.5) {
            Self::Half
        } else if near(2.0) {
            Self::Double
        } else {
            Self::Other
        }
    }
}

/// For each estimated beat within `tolerance` of a reference beat, its signed offset to the
/// nearest one.
fn offsets(reference: &[f64], estimated: &[f64], tolerance: f64) -> Vec<f64> {
    estimated
        .iter()
        .filter_map(|e| {
            let i = reference.partition_point(|r| r < e);
            [i.checked_sub(1), Some(i)]
                .into_iter()
                .flatten()
                .filter_map(|j| reference.get(j))
                .map(|r| e - r)
                .min_by(|a, b| a.abs().total_cmp(&b.abs()))
                .filter(|d| d.abs() <= tolerance)
        })
        .collect()
}

/// Median of `values` (0 for none).
pub fn median(values: &[f64]) -> f64 {
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(0.0)
}

fn in_span(times: &[f64], span: Option<(f64, f64)>) -> Vec<f64> {
    match span {
        None => times.to_vec(),
        Some((a, b)) => times
            .iter()
            .filter(|&&t| t >= a && t <= b)
            .map(|t| t - a)
            .collect(),
    }
}

/// Scores one analysis against one item.
pub fn score(item: &BenchItem, analysis: &FileAnalysis) -> ItemScore {
    let timely: Vec<f64> = analysis
        .beats
        .iter()
        .filter(|b| b.decided_at_s - b.time_s <= MAX_DECISION_LAG_S)
        .map(|b| b.time_s)
        .collect();
    let mut lags: Vec<f64> = analysis
        .beats
        .iter()
        .map(|b| b.decided_at_s - b.time_s)
        .collect();
    lags.sort_by(f64::total_cmp);
    let reference = in_span(&item.beats, item.span);
    let estimated = in_span(&timely, item.span);
    let reference = metrics::trim_beats(&reference, item.skip_s);
    let estimated = metrics::trim_beats(&estimated, item.skip_s);
    let f_measure = metrics::beat_f_measure(&reference, &estimated, BEAT_TOLERANCE_S);
    let level = MetricalLevel::of(median_tempo_bpm(&estimated), median_tempo_bpm(&reference));
    let offsets_s = offsets(&reference, &estimated, BEAT_TOLERANCE_S);
    let c = metrics::continuity(&reference, &estimated);
    let downbeat_f = item.downbeats.as_ref().map(|r| {
        let est: Vec<f64> = analysis
            .beats
            .iter()
            .filter(|b| b.beat_in_bar == 1 && b.decided_at_s - b.time_s <= MAX_DECISION_LAG_S)
            .map(|b| b.time_s)
            .collect();
        let r = metrics::trim_beats(&in_span(r, item.span), item.skip_s);
        let e = metrics::trim_beats(&in_span(&est, item.span), item.skip_s);
        metrics::beat_f_measure(&r, &e, BEAT_TOLERANCE_S)
    });
    // The meter counts from the fifth annotated bar on.
    let meter_from_s = item
        .meter
        .and_then(|m| item.beats.get(4 * m).copied())
        .unwrap_or(f64::INFINITY);
    let counted: Vec<&dsp::BeatEvent> = analysis
        .beats
        .iter()
        .filter(|b| b.decided_at_s - b.time_s <= MAX_DECISION_LAG_S && b.time_s >= meter_from_s)
        .collect();
    let meter_right = item.meter.map(|m| {
        let right = counted.iter().filter(|b| b.beats_per_bar == m).count();
        right as f64 / counted.len().max(1) as f64
    });
    let bar_confidence = counted
        .iter()
        .map(|b| f64::from(b.bar_confidence))
        .sum::<f64>()
        / counted.len().max(1) as f64;
    let onset_f = item.onsets.as_ref().map(|r| {
        let est: Vec<f64> = analysis.onsets.iter().map(|o| o.time_s).collect();
        metrics::onset_f_measure(r, &est, ONSET_TOLERANCE_S).f_measure
    });
    ItemScore {
        name: item.name.clone(),
        f_measure,
        cmlt: c.cmlt,
        amlt: c.amlt,
        onset_f,
        downbeat_f,
        late_beats: analysis.beats.len() - timely.len(),
        beats: analysis.beats.len(),
        median_lag_s: lags.get(lags.len() / 2).copied().unwrap_or(0.0),
        tempo_bpm: analysis.median_tempo(),
        level,
        offsets_s,
        meter: {
            let threes = analysis
                .beats
                .iter()
                .filter(|b| b.beats_per_bar == 3)
                .count();
            if analysis.beats.is_empty() {
                0
            } else if 2 * threes > analysis.beats.len() {
                3
            } else {
                4
            }
        },
        meter_right,
        bar_confidence,
        duration_s: analysis.duration_s,
        analysis_s: analysis.analysis_time.as_secs_f64(),
        error: None,
    }
}

/// Runs one tracker over a set with `jobs` worker threads (each analysis runs on one thread).
pub fn run_set(
    set: &BenchSet,
    options: AnalyzeOptions,
    jobs: usize,
    progress: &(dyn Fn(&str) + Sync),
) -> Vec<ItemScore> {
    offline::pool::parallel_map(&set.items, jobs, |item| {
        let r = match analyze_file(&item.audio, options, &mut |_, _| {}) {
            Ok(a) => score(item, &a),
            Err(e) => ItemScore {
                name: item.name.clone(),
                error: Some(e.to_string()),
                ..Default::default()
            },
        };
        progress(&item.name);
        r
    })
}

/// Mean of a field over the scores that did not fail.
pub fn mean(scores: &[ItemScore], f: impl Fn(&ItemScore) -> f64) -> f64 {
    let ok: Vec<f64> = scores.iter().filter(|s| s.error.is_none()).map(f).collect();
    if ok.is_empty() {
        0.0
    } else {
        ok.iter().sum::<f64>() / ok.len() as f64
    }
}

/// The set's metrical-level errors, timing bias and late beats, as a table cell's tail.
pub fn level_and_timing(scores: &[ItemScore]) -> String {
    let ok: Vec<&ItemScore> = scores.iter().filter(|s| s.error.is_none()).collect();
    let count = |l| ok.iter().filter(|s| s.level == l).count();
    let offsets: Vec<f64> = ok
        .iter()
        .flat_map(|s| s.offsets_s.iter().copied())
        .collect();
    let late: usize = ok.iter().map(|s| s.late_beats).sum();
    let all: usize = ok.iter().map(|s| s.beats).sum();
    format!(
        "; half / double / other tempo on {} / {} / {} of {}, beats {:+.0} ms from the reference (median), {:.1} % decided late",
        count(MetricalLevel::Half),
        count(MetricalLevel::Double),
        count(MetricalLevel::Other),
        ok.len(),
        1000.0 * median(&offsets),
        100.0 * late as f64 / all.max(1) as f64
    )
}

/// Mean beat F / CMLt / AMLt and downbeat F per genre, where the set names genres (the first
/// word of each, e.g. `electronic` of `electronic: techno`).
pub fn genre_table(set: &BenchSet, scores: &[ItemScore]) -> String {
    let family = |g: &str| {
        g.split([':', '/', ' '])
            .next()
            .unwrap_or(g)
            .trim()
            .to_string()
    };
    let mut families: Vec<String> = set
        .items
        .iter()
        .filter_map(|i| i.genre.as_deref().map(family))
        .collect();
    families.sort();
    families.dedup();
    let mut out = String::new();
    if families.is_empty() {
        return out;
    }
    let _ = writeln!(out, "\n{} by genre", set.name);
    let _ = writeln!(out, "| genre | files | F | CMLt | AMLt | downbeat F |");
    let _ = writeln!(out, "| --- | --- | --- | --- | --- | --- |");
    for fam in families {
        let picked: Vec<ItemScore> = set
            .items
            .iter()
            .zip(scores)
            .filter(|(i, _)| i.genre.as_deref().map(family).as_deref() == Some(fam.as_str()))
            .map(|(_, s)| s.clone())
            .collect();
        let _ = writeln!(
            out,
            "| {fam} | {} | {:.3} | {:.3} | {:.3} | {:.3} |",
            picked.len(),
            mean(&picked, |s| s.f_measure),
            mean(&picked, |s| s.cmlt),
            mean(&picked, |s| s.amlt),
            mean(&picked, |s| s.downbeat_f.unwrap_or(0.0))
        );
    }
    out
}

/// Audio seconds per analyzer second over the scores.
pub fn speed(scores: &[ItemScore]) -> f64 {
    let a: f64 = scores.iter().map(|s| s.analysis_s).sum();
    let d: f64 = scores.iter().map(|s| s.duration_s).sum();
    d / a.max(1e-9)
}

/// A per-file table of one tracker on one set.
pub fn detail_table(set: &BenchSet, tracker: BeatTrackerKind, scores: &[ItemScore]) -> String {
    let mut out = String::new();
    let _ = writeln!(out, "\n{} — {}", set.name, tracker.name());
    let _ = writeln!(
        out,
        "| file | F | CMLt | AMLt | downbeat F | meter | meter right | bar confidence | tempo | level | offset p50 ms | beats | late | lag p50 ms |"
    );
    let _ = writeln!(
        out,
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"
    );
    for s in scores {
        if let Some(e) = &s.error {
            let _ = writeln!(out, "| {} | error: {e} |", s.name);
            continue;
        }
        let _ = writeln!(
            out,
            "| {} | {:.3} | {:.3} | {:.3} | {} | {} | {} | {:.2} | {:.1} | {:?} | {:+.0} | {} | {} | {:.0} |",
            s.name,
            s.f_measure,
            s.cmlt,
            s.amlt,
            s.downbeat_f.map_or("–".to_string(), |f| format!("{f:.3}")),
            s.meter,
            s.meter_right
                .map_or("–".to_string(), |f| format!("{:.0} %", 100.0 * f)),
            s.bar_confidence,
            s.tempo_bpm,
            s.level,
            1000.0 * median(&s.offsets_s),
            s.beats,
            s.late_beats,
            s.median_lag_s * 1000.0
        );
    }
    out
}
