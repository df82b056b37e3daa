//! The analysis thread: pops audio blocks from the ring, runs the streaming `dsp::Analyzer`,
//! records when each block arrived (the audio clock), and passes feature frames to the motion
//! thread and analysis events to the sender. When no audio arrives for a while (no device,
//! end of file) it analyses silence on its own clock so the dancer keeps moving.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use crossbeam_channel::Sender;
use dsp::feature::FEATURE_DIM;
use dsp::{AnalysisSink, Analyzer, AnalyzerConfig, BeatEvent, FeatureFrame, HopFrame, OnsetEvent};

use super::ring::{BlockMarker, RingReader};
use super::stats::Stats;
use super::timeline::{Anchor, Timeline};
use super::wire::AnalysisEvent;

/// The beat grid as known at one moment, for quantising controls.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct BeatGrid {
    /// Predicted time of the next beat, stream seconds.
    pub next_beat_s: f64,
    /// Beat period, seconds (0 while no beat is heard).
    pub period_s: f64,
    /// Position in the bar of the beat at `next_beat_s` (1 = downbeat).
    pub next_index_in_bar: u32,
    /// Beats per bar.
    pub beats_per_bar: u32,
    /// Whether a beat is heard.
    pub locked: bool,
}

/// One feature frame on its way to the motion thread.
#[derive(Clone, Copy, Debug)]
pub struct FeatureMsg {
    /// Audio time the frame describes, stream seconds.
    pub time_s: f64,
    /// The values (layout of `dsp::feature`).
    pub values: [f32; FEATURE_DIM],
    /// Wall time (ns since the epoch) the block that completed this frame entered the ring.
    pub ingest_wall_ns: u64,
    /// The beat grid when the frame was made.
    pub grid: BeatGrid,
}

/// Frames of silence analysed per step while no audio arrives.
const SILENCE_BLOCK: usize = 256;
/// Format assumed for silence before any audio has been seen.
const DEFAULT_RATE: u32 = 48_000;
/// Hops between Tempo/Energy/Chroma events (86 hops/s → ~9.6 Hz).
const SLOW_EVENT_HOPS: u64 = 9;

/// Settings of the analysis thread.
#[derive(Clone, Copy, Debug)]
pub struct AnalysisSettings {
    /// Model frame rate (the motion source's), Hz.
    pub model_rate: f64,
    /// Wall time without audio after which silence is analysed instead, seconds.
    pub silence_after_s: f64,
}

struct Out<'a> {
    features: &'a Sender<FeatureMsg>,
    events: &'a Sender<AnalysisEvent>,
    stats: &'a Stats,
    base_time_s: f64,
    ingest_wall_ns: u64,
    grid: BeatGrid,
}

impl Out<'_> {
    fn event(&self, e: AnalysisEvent) {
        if self.events.try_send(e).is_err() {
            self.stats.events_dropped.fetch_add(1, Ordering::Relaxed);
        }
    }
}

impl AnalysisSink for Out<'_> {
    fn hop(&mut self, hop: &HopFrame) {
        let period = if hop.tempo_bpm > 0.0 {
            60.0 / hop.tempo_bpm
        } else {
            0.0
        };
        let bpb = hop.beats_per_bar.max(1) as u32;
        self.grid = BeatGrid {
            next_beat_s: self.base_time_s + hop.next_beat_s,
            period_s: period,
            next_index_in_bar: (hop.beat_in_bar as u32 % bpb) + 1,
            beats_per_bar: bpb,
            locked: hop.locked && period > 0.0,
        };
        self.stats.tempo_bpm.set(hop.tempo_bpm as f32);
        self.stats.beat_phase.set(hop.beat_phase as f32);
        if hop.index.is_multiple_of(SLOW_EVENT_HOPS) {
            let time_s = self.base_time_s + hop.time_s;
            self.event(AnalysisEvent::Tempo {
                bpm: hop.tempo_bpm as f32,
                confidence: hop.tempo_confidence as f32,
            });
            self.event(AnalysisEvent::Energy {
                time_s,
                db: hop.energy_db,
            });
            self.event(AnalysisEvent::Chroma {
                time_s,
                chroma: *hop.chroma,
            });
        }
    }

    fn onset(&mut self, onset: &OnsetEvent) {
        self.event(AnalysisEvent::Onset {
            time_s: self.base_time_s + onset.time_s,
            strength: onset.strength,
        });
    }

    fn beat(&mut self, beat: &BeatEvent) {
        self.event(AnalysisEvent::Beat {
            time_s: self.base_time_s + beat.time_s,
            index_in_bar: beat.beat_in_bar as u32,
            beats_per_bar: beat.beats_per_bar as u32,
            tempo_bpm: beat.tempo_bpm as f32,
        });
    }

    fn feature(&mut self, frame: &FeatureFrame) {
        let msg = FeatureMsg {
            time_s: self.base_time_s + frame.time_s,
            values: frame.values,
            ingest_wall_ns: self.ingest_wall_ns,
            grid: self.grid,
        };
        // The motion thread holds seconds of backlog; a full channel means it is gone.
        let _ = self.features.try_send(msg);
    }
}

/// Runs the analysis thread until `stop` is set; returns a message on a fatal analyzer error.
#[allow(clippy::too_many_arguments)]
pub fn run(
    mut reader: RingReader,
    settings: AnalysisSettings,
    epoch: Instant,
    timeline: Arc<Mutex<Timeline>>,
    stats: Arc<Stats>,
    stop: Arc<AtomicBool>,
    features: Sender<FeatureMsg>,
    events: Sender<AnalysisEvent>,
) -> Result<(), String> {
    let mut scratch = vec![0.0f32; 16_384];
    let silence = vec![0.0f32; SILENCE_BLOCK * 32];
    let mut analyzer: Option<(Analyzer, u32, u16)> = None;
    let mut stream_s = 0.0f64;
    // Silence only after `silence_after_s` of this thread's own life without audio.
    let mut last_wall_ns = epoch.elapsed().as_nanos() as u64;
    let mut out = Out {
        features: &features,
        events: &events,
        stats: &stats,
        base_time_s: 0.0,
        ingest_wall_ns: 0,
        grid: BeatGrid::default(),
    };
    let silence_after_ns = (settings.silence_after_s * 1e9) as u64;
    let build = |rate: u32, channels: u16| {
        Analyzer::new(AnalyzerConfig {
            sample_rate: rate,
            channels,
            model_rate: Some(settings.model_rate),
            tracker: dsp::BeatTrackerKind::Native,
            beat_params: Default::default(),
        })
        .map_err(|e| format!("analysis of {rate} Hz, {channels} ch audio: {e}"))
    };
    while !stop.load(Ordering::Relaxed) {
        let mut worked = false;
        while let Some(m) = reader.next_marker() {
            worked = true;
            let BlockMarker {
                frames,
                dropped_before,
                sample_rate,
                channels,
                wall_ns,
            } = m;
            let ch = usize::from(channels.max(1));
            if analyzer
                .as_ref()
                .is_none_or(|(_, r, c)| (*r, *c) != (sample_rate, channels))
            {
                // A new device or format: a fresh analyzer, continuing the stream clock.
                analyzer = Some((build(sample_rate, channels)?, sample_rate, channels));
                out.base_time_s = stream_s;
            }
            let Some((an, _, _)) = analyzer.as_mut() else {
                continue;
            };
            let total = frames as usize + dropped_before as usize;
            stream_s += total as f64 / f64::from(sample_rate);
            last_wall_ns = wall_ns;
            if let Ok(mut t) = timeline.lock() {
                t.anchors.push(Anchor {
                    audio_end_s: stream_s,
                    wall_ns,
                });
            }
            out.ingest_wall_ns = wall_ns;
            let mut gap = dropped_before as usize * ch;
            while gap > 0 {
                let n = gap.min(silence.len() / ch * ch);
                an.process(&silence[..n], &mut out);
                gap -= n;
            }
            let mut left = frames as usize * ch;
            while left > 0 {
                let want = left.min(scratch.len() / ch * ch);
                let got = reader.pop(&mut scratch[..want]);
                if got == 0 {
                    break; // cannot happen: the marker follows its samples
                }
                an.process(&scratch[..got], &mut out);
                left -= got;
            }
        }
        if !worked {
            let now_ns = epoch.elapsed().as_nanos() as u64;
            if now_ns.saturating_sub(last_wall_ns) > silence_after_ns {
                // No audio: analyse silence, back-dated block by block so the clock stays smooth.
                if analyzer.is_none() {
                    analyzer = Some((build(DEFAULT_RATE, 1)?, DEFAULT_RATE, 1));
                    out.base_time_s = stream_s;
                }
                if let Some((an, rate, channels)) = analyzer.as_mut() {
                    let ch = usize::from(*channels);
                    let block_ns = (SILENCE_BLOCK as f64 / f64::from(*rate) * 1e9) as u64;
                    let mut wall = last_wall_ns.max(now_ns.saturating_sub(silence_after_ns));
                    while wall + block_ns <= now_ns && !stop.load(Ordering::Relaxed) {
                        wall += block_ns;
                        stream_s += SILENCE_BLOCK as f64 / f64::from(*rate);
                        if let Ok(mut t) = timeline.lock() {
                            t.anchors.push(Anchor {
                                audio_end_s: stream_s,
                                wall_ns: wall,
                            });
                        }
                        out.ingest_wall_ns = wall;
                        an.process(&silence[..SILENCE_BLOCK * ch], &mut out);
                        stats
                            .silence_frames
                            .fetch_add(SILENCE_BLOCK as u64, Ordering::Relaxed);
                    }
                    last_wall_ns = wall;
                }
            }
            std::thread::sleep(Duration::from_millis(1));
        }
    }
    Ok(())
}
