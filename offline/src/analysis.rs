//! Offline analysis of a file through the same streaming code the live daemon runs.

use std::path::Path;
use std::time::{Duration, Instant};

use dsp::{
    AnalysisSink, Analyzer, AnalyzerConfig, BeatEvent, BeatTrackerKind, FeatureFrame, HopFrame,
    OnsetEvent,
};

use crate::decode::AudioFileReader;
use crate::error::OfflineError;

/// Frames handed to the analyzer per call, as a sound card would (256 frames ≈ 5.8 ms at 44.1 kHz).
pub const BLOCK_FRAMES: usize = 256;

/// What one analysis hop looked like, kept for plots and summaries.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HopSummary {
    /// Audio time, seconds.
    pub time_s: f64,
    /// Onset strength.
    pub onset_strength: f32,
    /// Learned beat activation in [0, 1].
    pub beat_activation: f32,
    /// Tempo in BPM (0 when no beat is heard).
    pub tempo_bpm: f64,
    /// Beat phase in [0, 1).
    pub beat_phase: f64,
    /// Bar phase in [0, 1).
    pub bar_phase: f64,
    /// Confidence of the bar count in [0, 1].
    pub bar_confidence: f32,
    /// RMS energy in dBFS.
    pub energy_db: f32,
}

/// Everything `danced analyze` learns about a file.
#[derive(Debug, Default)]
pub struct FileAnalysis {
    /// Beats in order.
    pub beats: Vec<BeatEvent>,
    /// Onsets in order.
    pub onsets: Vec<OnsetEvent>,
    /// Feature frames at the model rate (empty when none were asked for).
    pub features: Vec<FeatureFrame>,
    /// Per-hop summaries (empty unless asked for).
    pub hops: Vec<HopSummary>,
    /// Per-hop inputs of the learned beat activation, flat `[hops][BEAT_INPUT_DIM]` (empty
    /// unless asked for).
    pub beat_inputs: Vec<f32>,
    /// The bar features of every tracked beat, in order (empty unless asked for).
    pub bar_features: Vec<dsp::BarFeatures>,
    /// Time of the first hop, seconds (hops follow at `dsp::hop_rate()`).
    pub first_hop_s: Option<f64>,
    /// Length of the audio, seconds.
    pub duration_s: f64,
    /// Input sample rate, Hz.
    pub sample_rate: u32,
    /// Input channels.
    pub channels: u16,
    /// Time spent decoding.
    pub decode_time: Duration,
    /// Time spent in the analyzer.
    pub analysis_time: Duration,
    /// Packets the decoder had to skip.
    pub skipped_packets: usize,
}

impl FileAnalysis {
    /// Median tempo over the beats, BPM (0 without beats).
    pub fn median_tempo(&self) -> f64 {
        let mut t: Vec<f64> = self
            .beats
            .iter()
            .map(|b| b.tempo_bpm)
            .filter(|t| *t > 0.0)
            .collect();
        if t.is_empty() {
            return 0.0;
        }
        t.sort_by(f64::total_cmp);
        t[t.len() / 2]
    }

    /// Analysis speed as a multiple of real time (analyzer only, decoding excluded).
    pub fn realtime_factor(&self) -> f64 {
        self.duration_s / self.analysis_time.as_secs_f64().max(1e-9)
    }
}

/// Options for [`analyze_file`]. The default is the native tracker, no features, no hops.
#[derive(Clone, Copy, Debug, Default)]
pub struct AnalyzeOptions {
    /// Beat tracker.
    pub tracker: BeatTrackerKind,
    /// Model frame rate for features, Hz (`None`: no features).
    pub model_rate: Option<f64>,
    /// Keep per-hop summaries (for plots).
    pub keep_hops: bool,
    /// Keep per-hop beat activation inputs (for training it).
    pub keep_beat_inputs: bool,
    /// Tuning of the native beat tracker.
    pub beat_params: dsp::beat::BeatTrackerParams,
    /// Tuning of the bar pointer.
    pub bar_params: dsp::BarPointerParams,
    /// Keep each tracked beat's bar features (for training the downbeat network).
    pub keep_bar_features: bool,
    /// Song time the analysis starts at, seconds: earlier audio is decoded and skipped, as if
    /// the stream had begun there (all times are then counted from it).
    pub start_s: f64,
    /// The learned networks (default: the shipped ones).
    pub networks: dsp::AnalysisNetworks,
}

impl AnalyzeOptions {
    /// The native tracker with default tuning, producing feature frames at `model_rate` if given.
    pub fn native(model_rate: Option<f64>) -> Self {
        Self {
            model_rate,
            ..Self::default()
        }
    }
}

struct Collector<'a> {
    result: &'a mut FileAnalysis,
    keep_hops: bool,
    keep_beat_inputs: bool,
    keep_bar_features: bool,
}

impl AnalysisSink for Collector<'_> {
    fn hop(&mut self, hop: &HopFrame) {
        self.result.first_hop_s.get_or_insert(hop.time_s);
        if self.keep_bar_features
            && let Some(f) = hop.bar_features
        {
            self.result.bar_features.push(*f);
        }
        if self.keep_beat_inputs {
            self.result.beat_inputs.extend_from_slice(hop.beat_input);
        }
        if self.keep_hops {
            self.result.hops.push(HopSummary {
                time_s: hop.time_s,
                onset_strength: hop.onset_strength,
                beat_activation: hop.beat_activation,
                tempo_bpm: hop.tempo_bpm,
                beat_phase: hop.beat_phase,
                bar_phase: hop.bar_phase,
                bar_confidence: hop.bar_confidence,
                energy_db: hop.energy_db,
            });
        }
    }
    fn onset(&mut self, onset: &OnsetEvent) {
        self.result.onsets.push(*onset);
    }
    fn beat(&mut self, beat: &BeatEvent) {
        self.result.beats.push(*beat);
    }
    fn feature(&mut self, frame: &FeatureFrame) {
        self.result.features.push(*frame);
    }
}

/// Decodes `path` packet by packet and streams it through the analyzer in [`BLOCK_FRAMES`]
/// blocks; `progress` hears the seconds of audio done so far (and the total, when known).
pub fn analyze_file(
    path: &Path,
    options: AnalyzeOptions,
    progress: &mut dyn FnMut(f64, Option<f64>),
) -> Result<FileAnalysis, OfflineError> {
    analyze_file_at_speed(path, options, 1.0, progress)
}

/// [`analyze_file`] of the song played `speed` times as fast (varispeed, as a turntable's
/// pitch fader or a tape does: tempo and pitch move together), by declaring its samples at
/// `speed` times their rate; times in the result are the sped-up song's.
pub fn analyze_file_at_speed(
    path: &Path,
    options: AnalyzeOptions,
    speed: f64,
    progress: &mut dyn FnMut(f64, Option<f64>),
) -> Result<FileAnalysis, OfflineError> {
    analyze_file_shaped(path, options, speed, &mut |_, _, _, _| {}, progress)
}

/// Changes decoded samples on their way into the analysis: hears a block of interleaved
/// samples, the index of its first sample frame, the sample rate and the channel count.
pub type SampleShaper<'a> = dyn FnMut(&mut [f32], u64, u32, usize) + 'a;

/// [`analyze_file_at_speed`] of the song reshaped on its way in: `shape` hears each decoded
/// block (interleaved samples), the index of its first sample frame, the sample rate (the
/// sped-up song's) and the channel count, and may change the samples (training data's quiet
/// passages).
pub fn analyze_file_shaped(
    path: &Path,
    options: AnalyzeOptions,
    speed: f64,
    shape: &mut SampleShaper<'_>,
    progress: &mut dyn FnMut(f64, Option<f64>),
) -> Result<FileAnalysis, OfflineError> {
    let decode_start = Instant::now();
    let mut reader = AudioFileReader::open(path)?;
    let open_time = decode_start.elapsed();
    let speed = if speed.is_finite() && speed > 0.0 {
        speed
    } else {
        1.0
    };
    let rate = (reader.sample_rate() as f64 * speed).round().max(1.0) as u32;
    let channels = reader.channels();
    let total_s = reader.total_frames().map(|f| f as f64 / rate as f64);
    let mut decoded = 0u64;
    let mut result = stream(
        path.display().to_string(),
        rate,
        channels,
        options,
        total_s,
        progress,
        &mut |out| {
            let n = reader.read_block(out)?;
            let ch = usize::from(channels.max(1));
            shape(&mut out[..n * ch], decoded, rate, ch);
            decoded += n as u64;
            Ok(n)
        },
    )?;
    result.decode_time += open_time;
    result.skipped_packets = reader.skipped_packets();
    if result.duration_s == 0.0 {
        return Err(OfflineError::Empty {
            path: path.to_path_buf(),
        });
    }
    Ok(result)
}

/// Streams interleaved samples already in memory through the analyzer in [`BLOCK_FRAMES`]
/// blocks (the built-in demo song, tests).
pub fn analyze_samples(
    name: &str,
    samples: &[f32],
    rate: u32,
    channels: u16,
    options: AnalyzeOptions,
) -> Result<FileAnalysis, OfflineError> {
    let mut chunks = samples.chunks(BLOCK_FRAMES * 16 * channels.max(1) as usize);
    stream(
        name.to_string(),
        rate,
        channels,
        options,
        None,
        &mut |_, _| {},
        &mut |out| {
            out.clear();
            if let Some(c) = chunks.next() {
                out.extend_from_slice(c);
            }
            Ok(out.len() / channels.max(1) as usize)
        },
    )
}

fn stream(
    name: String,
    rate: u32,
    channels: u16,
    options: AnalyzeOptions,
    total_s: Option<f64>,
    progress: &mut dyn FnMut(f64, Option<f64>),
    next: &mut dyn FnMut(&mut Vec<f32>) -> Result<usize, OfflineError>,
) -> Result<FileAnalysis, OfflineError> {
    let mut analyzer = Analyzer::new(AnalyzerConfig {
        sample_rate: rate,
        channels,
        model_rate: options.model_rate,
        tracker: options.tracker,
        beat_params: options.beat_params,
        bar_params: options.bar_params,
        networks: options.networks,
    })
    .map_err(|source| OfflineError::Analysis { path: name, source })?;
    let mut result = FileAnalysis {
        sample_rate: rate,
        channels,
        ..Default::default()
    };
    let mut decode_time = Duration::ZERO;
    let mut analysis_time = Duration::ZERO;
    let mut packet = Vec::new();
    let mut frames_total = 0u64;
    let block = BLOCK_FRAMES * channels as usize;
    let mut last_report = 0.0;
    let ch = channels.max(1) as usize;
    let mut skip = (options.start_s.max(0.0) * f64::from(rate)).round() as u64;
    loop {
        let t = Instant::now();
        let mut n = next(&mut packet)?;
        decode_time += t.elapsed();
        if n == 0 {
            break;
        }
        if skip > 0 {
            let drop = (n as u64).min(skip) as usize;
            skip -= drop as u64;
            packet.drain(..drop * ch);
            n -= drop;
            if n == 0 {
                continue;
            }
        }
        frames_total += n as u64;
        let t = Instant::now();
        let mut sink = Collector {
            result: &mut result,
            keep_hops: options.keep_hops,
            keep_beat_inputs: options.keep_beat_inputs,
            keep_bar_features: options.keep_bar_features,
        };
        for chunk in packet[..n * channels as usize].chunks(block) {
            analyzer.process(chunk, &mut sink);
        }
        analysis_time += t.elapsed();
        let done = frames_total as f64 / rate as f64;
        if done - last_report >= 1.0 {
            progress(done, total_s);
            last_report = done;
        }
    }
    result.duration_s = frames_total as f64 / rate as f64;
    result.decode_time = decode_time;
    result.analysis_time = analysis_time;
    progress(result.duration_s, total_s);
    Ok(result)
}

/// The analysis networks with weights read from these files in place of the shipped ones
/// (`None`: shipped). They live as long as the process: an analysis is configured by value.
pub fn networks_from_files(
    beat: Option<&Path>,
    downbeat: Option<&Path>,
) -> Result<dsp::AnalysisNetworks, OfflineError> {
    let read = |path: &Path| {
        std::fs::read(path).map_err(|error| OfflineError::Io {
            path: path.to_path_buf(),
            error,
        })
    };
    let refused = |path: &Path, source| OfflineError::Analysis {
        path: path.display().to_string(),
        source,
    };
    let mut networks = dsp::AnalysisNetworks::default();
    if let Some(p) = beat {
        let ensemble = dsp::BeatNetEnsemble::from_bytes(&read(p)?).map_err(|e| refused(p, e))?;
        networks.beat = Some(Box::leak(Box::new(ensemble)));
    }
    if let Some(p) = downbeat {
        let ensemble =
            dsp::DownbeatNetEnsemble::from_bytes(&read(p)?).map_err(|e| refused(p, e))?;
        networks.downbeat = Some(Box::leak(Box::new(ensemble)));
    }
    Ok(networks)
}
