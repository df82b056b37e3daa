//! The text and array files of analysis results, and the beat files read back. Every file is
//! written atomically: a temporary file beside the target, then a rename, so a crash never
//! leaves half a file behind.

use std::fs;
use std::io::{self, Write};
use std::path::{Path, PathBuf};

use dsp::feature::{FEATURE_DIM, FEATURE_LAYOUT_VERSION};
use dsp::{BeatEvent, FeatureFrame, FeatureLayout, OnsetEvent};

fn temp_path(path: &Path) -> PathBuf {
    let mut name = path
        .file_name()
        .map(|n| n.to_os_string())
        .unwrap_or_default();
    name.push(format!(".tmp{}", std::process::id()));
    path.with_file_name(name)
}

/// Writes `bytes` to `path` atomically.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> io::Result<()> {
    let tmp = temp_path(path);
    let result = (|| {
        let mut f = fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        fs::rename(&tmp, path)
    })();
    if result.is_err() {
        let _ = fs::remove_file(&tmp);
    }
    result
}

/// Beats as `time_s<TAB>beat_in_bar<TAB>decided_at_s`, one per line.
pub fn beats_text(beats: &[BeatEvent]) -> String {
    beats
        .iter()
        .map(|b| {
            format!(
                "{:.4}\t{}\t{:.4}\n",
                b.time_s, b.beat_in_bar, b.decided_at_s
            )
        })
        .collect()
}

/// Onsets as one time in seconds per line.
pub fn onsets_text(onsets: &[OnsetEvent]) -> String {
    onsets
        .iter()
        .map(|o| format!("{:.4}\n", o.time_s))
        .collect()
}

/// Features as a little-endian float32 `.npy` array of shape `[frames, FEATURE_DIM]`.
pub fn features_npy(frames: &[FeatureFrame]) -> Vec<u8> {
    let data: Vec<f32> = frames.iter().flat_map(|f| f.values).collect();
    let array = ndarray::Array2::from_shape_vec((frames.len(), FEATURE_DIM), data)
        .expect("frames × FEATURE_DIM values by construction");
    let mut bytes = Vec::new();
    ndarray_npy::WriteNpyExt::write_npy(&array, &mut bytes).expect("writing to memory cannot fail");
    bytes
}

/// Sidecar JSON describing a features file: layout version, rate, names and latencies.
pub fn features_sidecar(
    rate: f64,
    frames: usize,
    short_latency_s: f64,
    long_latency_s: f64,
) -> String {
    let names: Vec<String> = FeatureLayout::names()
        .iter()
        .map(|n| format!("\"{n}\""))
        .collect();
    format!(
        "{{\n  \"layout_version\": {FEATURE_LAYOUT_VERSION},\n  \"frame_rate_hz\": {rate},\n  \"frames\": {frames},\n  \"dim\": {FEATURE_DIM},\n  \"short_window_latency_s\": {short_latency_s:.4},\n  \"chroma_latency_s\": {long_latency_s:.4},\n  \"names\": [{}]\n}}\n",
        names.join(", ")
    )
}

/// Reads a beat file: the first column of each non-empty line, in seconds.
pub fn read_times(path: &Path) -> io::Result<Vec<f64>> {
    let text = fs::read_to_string(path)?;
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let Some(first) = line.split_whitespace().next() else {
            continue;
        };
        if first.starts_with('#') {
            continue;
        }
        let t: f64 = first.parse().map_err(|_| {
            io::Error::new(
                io::ErrorKind::InvalidData,
                format!("{}: line {}: not a time: {first:?}", path.display(), i + 1),
            )
        })?;
        out.push(t);
    }
    Ok(out)
}

/// Beats with their position in the bar (1 = downbeat) from a beat file whose second column
/// is that position; `None` if the file has no such column.
pub fn read_beat_positions(path: &Path) -> Option<Vec<(f64, usize)>> {
    let text = fs::read_to_string(path).ok()?;
    let mut out = Vec::new();
    for line in text.lines().filter(|l| !l.trim_start().starts_with('#')) {
        let mut cols = line.split_whitespace();
        let (Some(t), Some(p)) = (cols.next(), cols.next()) else {
            continue;
        };
        let position = p.parse::<f64>().ok()?;
        if !(position >= 1.0 && position.fract() == 0.0) {
            return None;
        }
        out.push((t.parse().ok()?, position as usize));
    }
    (!out.is_empty()).then_some(out)
}

/// Mono float samples as a 16-bit PCM WAV file's bytes (clipped to ±1).
pub fn wav_mono_16(samples: &[f32], rate: u32) -> Vec<u8> {
    let spec = hound::WavSpec {
        channels: 1,
        sample_rate: rate,
        bits_per_sample: 16,
        sample_format: hound::SampleFormat::Int,
    };
    let mut bytes = io::Cursor::new(Vec::with_capacity(44 + 2 * samples.len()));
    // Writing to memory cannot fail but for sizes beyond a WAV's 4 GB.
    if let Ok(mut w) = hound::WavWriter::new(&mut bytes, spec) {
        for &s in samples {
            let _ = w.write_sample((s.clamp(-1.0, 1.0) * 32767.0).round() as i16);
        }
        let _ = w.finalize();
    }
    bytes.into_inner()
}
