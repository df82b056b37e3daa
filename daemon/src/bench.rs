//! `danced bench beats`: the native and aubio trackers side by side on three annotated sets.

use std::fmt::Write as _;
use std::fs;
use std::path::{Path, PathBuf};

use dsp::BeatTrackerKind;
use dsp::metrics::{self, BEAT_TOLERANCE_S, ONSET_TOLERANCE_S};

use offline::analysis::{AnalyzeOptions, FileAnalysis, analyze_file};
use offline::files::{read_beat_positions, read_times};

/// A beat counts only if the tracker committed to it no later than this after it happened.
pub const MAX_DECISION_LAG_S: f64 = 0.05;
/// tang2018 music frames per second (for `config.json` spans).
const TANG_FPS: f64 = 25.0;

/// One annotated recording.
#[derive(Clone, Debug)]
pub struct BenchItem {
    /// Short name for tables.
    pub name: String,
    /// The audio file.
    pub audio: PathBuf,
    /// Reference beat times, seconds.
    pub beats: Vec<f64>,
    /// Span scored, seconds (times are shifted to start at its beginning).
    pub span: Option<(f64, f64)>,
    /// Reference onset times, if annotated.
    pub onsets: Option<Vec<f64>>,
    /// Reference downbeat times, where the annotation gives positions in the bar.
    pub downbeats: Option<Vec<f64>>,
    /// Seconds at the start left unscored (mir_eval skips 5 s; a clip shorter than that can't).
    pub skip_s: f64,
    /// Beats per bar, where the annotation gives positions in the bar (the largest position).
    pub meter: Option<usize>,
}

/// A named list of recordings.
#[derive(Clone, Debug)]
pub struct BenchSet {
    /// Name in the table.
    pub name: String,
    /// Its recordings.
    pub items: Vec<BenchItem>,
}

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

fn sorted_dir(dir: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = fs::read_dir(dir)
        .map(|r| r.flatten().map(|e| e.path()).collect())
        .unwrap_or_default();
    v.sort();
    v
}

/// What a rendered song's JSON (written beside it by `synth_beats.py`) says of it.
#[derive(Clone, Debug, PartialEq)]
pub struct SynthSongInfo {
    /// Tempo at the start, BPM.
    pub bpm: f64,
    /// Whether the tempo stays constant.
    pub constant: bool,
    /// Bars before the drums come in.
    pub drumless_intro_bars: f64,
    /// Time of the first beat, seconds.
    pub first_beat_s: f64,
    /// Beats in a bar.
    pub beats_per_bar: f64,
    /// The quiet section, seconds, if any.
    pub quiet: Option<(f64, f64)>,
    /// Where the tempo jumps, for songs that have a jump.
    pub tempo_change_s: Option<f64>,
}

impl SynthSongInfo {
    /// Reads the JSON beside `audio` (`None` if it is missing or says no tempo).
    pub fn read(audio: &Path) -> Option<Self> {
        let json = std::fs::read_to_string(audio.with_extension("json")).ok()?;
        let v: serde_json::Value = serde_json::from_str(&json).ok()?;
        let q = &v["quiet_section"];
        Some(Self {
            bpm: v["tempo_start_bpm"].as_f64()?,
            constant: v["tempo_curve"].as_str() == Some("constant"),
            drumless_intro_bars: v["drumless_intro_bars"].as_f64().unwrap_or(0.0),
            first_beat_s: v["first_beat_s"].as_f64().unwrap_or(0.0),
            beats_per_bar: v["beats_per_bar"].as_f64().unwrap_or(4.0),
            quiet: q["start_s"].as_f64().zip(q["end_s"].as_f64()),
            tempo_change_s: v["tempo_change_s"].as_f64(),
        })
    }

    /// Whether it starts without drums.
    pub fn has_intro(&self) -> bool {
        self.drumless_intro_bars > 0.0
    }

    /// Its drumless intro, seconds from the start, if any.
    pub fn intro(&self) -> Option<(f64, f64)> {
        self.has_intro().then(|| {
            let bars_s = self.drumless_intro_bars * self.beats_per_bar * 60.0 / self.bpm;
            (0.0, self.first_beat_s + bars_s)
        })
    }
}

/// The rendered songs with exact beats in `data/synth-beats`.
pub fn synth_set(data: &Path) -> BenchSet {
    rendered_set("synth-beats", &data.join("synth-beats"))
}

/// Songs rendered by `synth_beats.py` (exact beats and bar positions) in `dir`, as a set named
/// `name`.
pub fn rendered_set(name: &str, dir: &Path) -> BenchSet {
    let mut items = Vec::new();
    for p in sorted_dir(dir) {
        if p.extension().is_some_and(|e| e == "flac")
            && let Ok(beats) = read_times(&p.with_extension("beats"))
        {
            let stem = p
                .file_stem()
                .unwrap_or_default()
                .to_string_lossy()
                .into_owned();
            let positions = read_beat_positions(&p.with_extension("beats"));
            let meter = positions
                .as_ref()
                .and_then(|v| v.iter().map(|&(_, p)| p).max());
            let downbeats = positions.map(|v| {
                v.into_iter()
                    .filter(|&(_, p)| p == 1)
                    .map(|(t, _)| t)
                    .collect()
            });
            items.push(BenchItem {
                name: stem,
                audio: p,
                beats,
                span: None,
                onsets: None,
                downbeats,
                skip_s: metrics::MIN_BEAT_TIME_S,
                meter,
            });
        }
    }
    BenchSet {
        name: name.to_string(),
        items,
    }
}

fn json_number(text: &str, key: &str) -> Option<f64> {
    let at = text.find(&format!("\"{key}\""))?;
    let rest = text[at + key.len() + 2..]
        .trim_start()
        .strip_prefix(':')?
        .trim_start();
    let end = rest
        .find(|c: char| !(c.is_ascii_digit() || c == '.' || c == '-'))
        .unwrap_or(rest.len());
    rest[..end].parse().ok()
}

/// The tang2018 songs against the offline reference beats, scored within each danced span.
pub fn tang_set(data: &Path) -> BenchSet {
    let mut items = Vec::new();
    for dir in sorted_dir(&data.join("tang2018")) {
        let name = dir
            .file_name()
            .unwrap_or_default()
            .to_string_lossy()
            .into_owned();
        let audio = dir.join("audio.mp3");
        let reference = data.join("tang2018-beats").join(format!("{name}.beats"));
        let (Ok(beats), true) = (read_times(&reference), audio.exists()) else {
            continue;
        };
        let span = fs::read_to_string(dir.join("config.json"))
            .ok()
            .and_then(|t| {
                Some((
                    json_number(&t, "start_position")? / TANG_FPS,
                    json_number(&t, "end_position")? / TANG_FPS,
                ))
            });
        items.push(BenchItem {
            name,
            audio,
            beats,
            span,
            onsets: None,
            downbeats: None,
            skip_s: metrics::MIN_BEAT_TIME_S,
            meter: None,
        });
    }
    BenchSet {
        name: "tang2018".into(),
        items,
    }
}

/// The hand-annotated madmom test recording (beats and onsets).
pub fn madmom_set(data: &Path) -> BenchSet {
    let dir = data.join("madmom-tests");
    let mut items = Vec::new();
    if let Ok(beats) = read_times(&dir.join("sample.beats")) {
        items.push(BenchItem {
            name: "sample".into(),
            audio: dir.join("sample.wav"),
            beats,
            span: None,
            onsets: read_times(&dir.join("sample.onsets")).ok(),
            downbeats: read_downbeats(&dir.join("sample.beats")),
            skip_s: 0.0,
            meter: None,
        });
    }
    BenchSet {
        name: "madmom-tests".into(),
        items,
    }
}

/// Downbeats from a beat file whose second column is the position in the bar (1 = downbeat).
fn read_downbeats(path: &Path) -> Option<Vec<f64>> {
    Some(
        read_beat_positions(path)?
            .into_iter()
            .filter(|&(_, p)| p == 1)
            .map(|(t, _)| t)
            .collect(),
    )
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
        "| file | F | CMLt | AMLt | downbeat F | meter | meter right | bar confidence | tempo | beats | late | lag p50 ms |"
    );
    let _ = writeln!(
        out,
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"
    );
    for s in scores {
        if let Some(e) = &s.error {
            let _ = writeln!(out, "| {} | error: {e} |", s.name);
            continue;
        }
        let _ = writeln!(
            out,
            "| {} | {:.3} | {:.3} | {:.3} | {} | {} | {} | {:.2} | {:.1} | {} | {} | {:.0} |",
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
            s.beats,
            s.late_beats,
            s.median_lag_s * 1000.0
        );
    }
    out
}

/// The set's constant-tempo songs without a drumless intro, 70–170 BPM, slowest first.
pub fn steady_songs(set: &BenchSet) -> Vec<(f64, &BenchItem)> {
    let mut steady: Vec<(f64, &BenchItem)> = set
        .items
        .iter()
        .filter_map(|i| {
            let info = SynthSongInfo::read(&i.audio)?;
            (info.constant && !info.has_intro() && (70.0..=170.0).contains(&info.bpm))
                .then_some((info.bpm, i))
        })
        .collect();
    steady.sort_by(|a, b| a.0.total_cmp(&b.0));
    steady
}
