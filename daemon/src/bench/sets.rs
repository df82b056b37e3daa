//! The annotated recordings the benches and the evaluation measure on: songs rendered with
//! exact beats and bars (`data/synth-beats`), the tang2018 songs against their reference beats,
//! and the hand-annotated madmom recording.

use std::fs;
use std::path::{Path, PathBuf};

use dsp::metrics;
use offline::files::{read_beat_positions, read_times};

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
    /// Genre, where the set names one.
    pub genre: Option<String>,
}

/// A named list of recordings.
#[derive(Clone, Debug)]
pub struct BenchSet {
    /// Name in the table.
    pub name: String,
    /// Its recordings.
    pub items: Vec<BenchItem>,
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
    let items = sorted_dir(dir)
        .into_iter()
        .filter(|p| p.extension().is_some_and(|e| e == "flac"))
        .filter_map(|p| counted_item(&p))
        .collect();
    BenchSet {
        name: name.to_string(),
        items,
    }
}

/// A recording whose `.beats` file gives `time  position-in-bar` per line (or times alone).
fn counted_item(audio: &Path) -> Option<BenchItem> {
    let beats_file = audio.with_extension("beats");
    let beats = read_times(&beats_file).ok()?;
    let stem = audio
        .file_stem()
        .unwrap_or_default()
        .to_string_lossy()
        .into_owned();
    let positions = read_beat_positions(&beats_file);
    let meter = positions
        .as_ref()
        .and_then(|v| v.iter().map(|&(_, p)| p).max());
    let downbeats = positions.map(|v| {
        v.into_iter()
            .filter(|&(_, p)| p == 1)
            .map(|(t, _)| t)
            .collect()
    });
    Some(BenchItem {
        name: stem,
        audio: audio.to_path_buf(),
        beats,
        span: None,
        onsets: None,
        downbeats,
        skip_s: metrics::MIN_BEAT_TIME_S,
        meter,
        genre: None,
    })
}

/// The real recordings of `data/real-music` against their offline-tracker references, in two
/// sets: `real-music`, the sources no network trains on ([`offline::real_music`]), and
/// `real-music-train`, the rest.
pub fn real_music_sets(data: &Path) -> [BenchSet; 2] {
    let dir = data.join("real-music");
    let genres: Vec<(String, String)> = fs::read_to_string(dir.join("tracks.tsv"))
        .unwrap_or_default()
        .lines()
        .skip(1)
        .filter_map(|l| {
            let cols: Vec<&str> = l.split('\t').collect();
            Some((cols.first()?.to_string(), cols.get(3)?.to_string()))
        })
        .collect();
    let (mut held_out, mut train) = (Vec::new(), Vec::new());
    for p in sorted_dir(&dir)
        .into_iter()
        .filter(|p| p.extension().is_some_and(|e| e == "flac"))
    {
        let Some(mut item) = counted_item(&p) else {
            continue;
        };
        item.genre = genres
            .iter()
            .find(|(n, _)| *n == item.name)
            .map(|(_, g)| g.clone());
        if offline::real_music::is_held_out(&p) {
            held_out.push(item);
        } else {
            train.push(item);
        }
    }
    [
        BenchSet {
            name: "real-music".into(),
            items: held_out,
        },
        BenchSet {
            name: "real-music-train".into(),
            items: train,
        },
    ]
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
            genre: None,
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
            genre: None,
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

/// The set's songs with annotated downbeats, with their reference tempo (from the median beat
/// interval), slowest first.
pub fn by_reference_tempo(set: &BenchSet) -> Vec<(f64, &BenchItem)> {
    let mut songs: Vec<(f64, &BenchItem)> = set
        .items
        .iter()
        .filter(|i| i.downbeats.is_some() && i.beats.len() > 2)
        .map(|i| (median_tempo_bpm(&i.beats), i))
        .collect();
    songs.sort_by(|a, b| a.0.total_cmp(&b.0));
    songs
}

/// Tempo of a beat sequence from its median beat interval, BPM (0 for fewer than two beats).
pub fn median_tempo_bpm(beats: &[f64]) -> f64 {
    let mut ibi: Vec<f64> = beats.windows(2).map(|w| w[1] - w[0]).collect();
    if ibi.is_empty() {
        return 0.0;
    }
    ibi.sort_by(f64::total_cmp);
    60.0 / ibi[ibi.len() / 2]
}
