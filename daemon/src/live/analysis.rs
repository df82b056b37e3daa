//! The analysis thread: pops audio blocks from the ring, runs the streaming `dsp::Analyzer`,
//! records when each block arrived (the audio clock), and passes feature frames to the motion
//! thread and analysis events to the sender. When no audio arrives for a while (no device,
//! end of file) it analyses silence on its own clock so the dancer keeps moving.

use std::sync::atomic::Ordering;
use std::thread::Thread;
use std::time::Duration;

use dsp::{AnalysisSink, Analyzer, AnalyzerConfig, BeatEvent, FeatureFrame, HopFrame, OnsetEvent};

use super::clock::ClockSnapshot;
use super::context::LiveContext;
use super::grid_steer::{GridSteer, WallMap};
use super::ring::{BlockMarker, RingReader};
use super::stats::Stats;
use super::timeline::Anchor;
use super::wire::AnalysisEvent;
use crate::alloc_counter::{CountGuard, RtThread, uncounted};

/// One feature frame on its way to the motion thread.
#[derive(Clone, Copy, Debug)]
pub struct FeatureMsg {
    /// The frame, its times and beat grid on the run's stream clock.
    pub frame: FeatureFrame,
    /// Wall time (ns since the epoch) the block that completed this frame entered the ring.
    pub ingest_wall_ns: u64,
}

/// Frames of silence analysed per step while no audio arrives.
const SILENCE_BLOCK: usize = 256;
/// Samples of the preallocated silence buffer (256 frames of 32 channels).
const SILENCE_SAMPLES: usize = SILENCE_BLOCK * 32;
/// Format assumed for silence before any audio has been seen.
const DEFAULT_RATE: u32 = 48_000;
/// Hops between Tempo/Energy/Chroma events (86 hops/s → ~9.6 Hz).
const SLOW_EVENT_HOPS: u64 = 9;
/// Feature frames between RelativeLevel events (at 25–30 frames/s → 8–10 Hz, as Energy).
const LEVEL_EVENT_FRAMES: u64 = 3;

/// Settings of the analysis thread.
#[derive(Clone, Copy, Debug)]
pub struct AnalysisSettings {
    /// Model frame rate (the motion source's), Hz.
    pub model_rate: f64,
    /// Wall time without audio after which silence is analysed instead, seconds.
    pub silence_after_s: f64,
    /// Audio seconds per wall second (1 live; the replay speed otherwise).
    pub speed: f64,
}

/// The analysis thread's ends of its queues.
pub struct AnalysisQueues {
    /// Feature frames to the motion thread.
    pub features: rtrb::Producer<FeatureMsg>,
    /// Analysis events to the sender thread.
    pub events: rtrb::Producer<AnalysisEvent>,
    /// The audio clock (one anchor per block) to the sender thread.
    pub anchors: rtrb::Producer<Anchor>,
    /// The motion thread, woken after each feature frame.
    pub motion_thread: Thread,
    /// The clocks and the performer's corrections (`None`: the heard beats, as they are).
    pub clock: Option<triple_buffer::Output<ClockSnapshot>>,
    /// The grid followed, on the wall clock, to each clock danced leads (MIDI clock out, Link).
    pub led: Vec<triple_buffer::Input<Option<protocols::ClockGrid>>>,
}

struct Out<'a> {
    queues: &'a mut AnalysisQueues,
    stats: &'a Stats,
    base_time_s: f64,
    ingest_wall_ns: u64,
    steer: GridSteer,
    /// The stream clock at the newest block.
    map: WallMap,
}

impl Out<'_> {
    fn event(&mut self, e: AnalysisEvent) {
        if self.queues.events.push(e).is_err() {
            self.stats.events_dropped.fetch_add(1, Ordering::Relaxed);
        }
    }

    fn anchor(&mut self, a: Anchor) {
        self.map.audio_end_s = a.audio_end_s;
        self.map.wall_ns = a.wall_ns;
        if self.queues.anchors.push(a).is_err() {
            self.stats.anchors_dropped.fetch_add(1, Ordering::Relaxed);
        }
    }
}

impl AnalysisSink for Out<'_> {
    fn hop(&mut self, hop: &HopFrame) {
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

    fn beat(&mut self, _beat: &BeatEvent) {
        // Beats go out from the sender, on the grid of the pose it shows (one clock for the
        // dancer and the beat messages), not when the tracker decides them.
    }

    fn feature(&mut self, frame: &FeatureFrame) {
        if frame.index.is_multiple_of(LEVEL_EVENT_FRAMES) {
            self.event(AnalysisEvent::RelativeLevel {
                time_s: self.base_time_s + frame.time_s,
                db: frame.values[dsp::FeatureLayout::RELATIVE_LEVEL],
            });
        }
        let mut frame = *frame;
        frame.time_s += self.base_time_s;
        frame.decided_at_s += self.base_time_s;
        frame.grid = frame.grid.shifted(self.base_time_s);
        self.choose_grid(&mut frame);
        let msg = FeatureMsg {
            frame,
            ingest_wall_ns: self.ingest_wall_ns,
        };
        // The queue holds seconds of frames: full means the motion thread stalled.
        if self.queues.features.push(msg).is_err() {
            self.stats.features_dropped.fetch_add(1, Ordering::Relaxed);
        }
        self.queues.motion_thread.unpark();
    }
}

impl Out<'_> {
    /// Puts the followed clock's grid, nudged and with its bar as the performer set it, on the
    /// frame; reports the clock and hands its beats to the clocks danced leads.
    fn choose_grid(&mut self, frame: &mut FeatureFrame) {
        let snapshot = match self.queues.clock.as_mut() {
            Some(feed) => *feed.read(),
            None => ClockSnapshot::default(),
        };
        let steered = self
            .steer
            .steer(&snapshot, &frame.grid, frame.time_s, &self.map);
        frame.grid = steered.grid;
        let c = &self.stats.clock;
        c.source.store(snapshot.source.index(), Ordering::Relaxed);
        c.tempo_bpm.set(steered.grid.tempo_bpm() as f32);
        c.nudge_ms.set(snapshot.nudge_ms);
        c.trim_ms.set(self.steer.trim_ms());
        c.peers.store(snapshot.peers, Ordering::Relaxed);
        c.offset_ms.set(self.steer.offset_ms().unwrap_or(f32::NAN));
        if steered.fallback {
            c.fallback_frames.fetch_add(1, Ordering::Relaxed);
        }
        if let Some(ms) = steered.new_offset_ms {
            self.event(AnalysisEvent::ClockOffset { ms });
        }
        for led in &mut self.queues.led {
            led.write(steered.wall);
        }
    }
}

/// Runs the analysis thread until `stop` is set; returns a message on a fatal analyzer error.
pub fn run(
    mut reader: RingReader,
    settings: AnalysisSettings,
    ctx: LiveContext,
    mut queues: AnalysisQueues,
) -> Result<(), String> {
    let LiveContext { epoch, stats, stop } = ctx;
    let mut scratch = vec![0.0f32; 16_384];
    let silence = vec![0.0f32; SILENCE_SAMPLES];
    let mut analyzer: Option<(Analyzer, u32, u16)> = None;
    let mut stream_s = 0.0f64;
    // Silence only after `silence_after_s` of this thread's own life without audio.
    let mut last_wall_ns = epoch.elapsed().as_nanos() as u64;
    let mut out = Out {
        queues: &mut queues,
        stats: &stats,
        base_time_s: 0.0,
        ingest_wall_ns: 0,
        steer: GridSteer::new(),
        map: WallMap {
            audio_end_s: 0.0,
            wall_ns: last_wall_ns,
            speed: settings.speed,
        },
    };
    let silence_after_ns = (settings.silence_after_s * 1e9) as u64;
    let build = |rate: u32, channels: u16| {
        // A new format is set-up, even inside the loop: it may allocate.
        uncounted(|| Analyzer::new(live_config(rate, channels, settings.model_rate)))
            .map_err(|e| format!("analysis of {rate} Hz, {channels} ch audio: {e}"))
    };
    let _counting = CountGuard::new(RtThread::Analysis);
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
                let fresh = build(sample_rate, channels)?;
                uncounted(|| analyzer = Some((fresh, sample_rate, channels)));
                out.base_time_s = stream_s;
            }
            let Some((an, _, _)) = analyzer.as_mut() else {
                continue;
            };
            let total = frames as usize + dropped_before as usize;
            stream_s += total as f64 / f64::from(sample_rate);
            last_wall_ns = wall_ns;
            out.anchor(Anchor {
                audio_end_s: stream_s,
                wall_ns,
            });
            out.ingest_wall_ns = wall_ns;
            process_silence(an, &silence, dropped_before as usize, ch, &mut out);
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
                    let fresh = build(DEFAULT_RATE, 1)?;
                    uncounted(|| analyzer = Some((fresh, DEFAULT_RATE, 1)));
                    out.base_time_s = stream_s;
                }
                if let Some((an, rate, channels)) = analyzer.as_mut() {
                    let ch = usize::from((*channels).max(1));
                    let block_ns = (SILENCE_BLOCK as f64 / f64::from(*rate) * 1e9) as u64;
                    let mut wall = last_wall_ns.max(now_ns.saturating_sub(silence_after_ns));
                    while wall + block_ns <= now_ns && !stop.load(Ordering::Relaxed) {
                        wall += block_ns;
                        stream_s += SILENCE_BLOCK as f64 / f64::from(*rate);
                        out.anchor(Anchor {
                            audio_end_s: stream_s,
                            wall_ns: wall,
                        });
                        out.ingest_wall_ns = wall;
                        process_silence(an, &silence, SILENCE_BLOCK, ch, &mut out);
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

/// The analysis the live pipeline runs on `rate` Hz, `channels`-channel audio for a dancer
/// stepping at `model_rate` Hz.
fn live_config(rate: u32, channels: u16, model_rate: f64) -> AnalyzerConfig {
    AnalyzerConfig {
        sample_rate: rate,
        channels,
        model_rate: Some(model_rate),
        tracker: dsp::BeatTrackerKind::Native,
        beat_params: Default::default(),
        bar_params: Default::default(),
        networks: Default::default(),
    }
}

/// Analyses `frames` frames of silence of `channels` channels, in whole-frame pieces of the
/// preallocated `silence` buffer (so any channel count fits).
fn process_silence(
    an: &mut Analyzer,
    silence: &[f32],
    frames: usize,
    channels: usize,
    out: &mut Out<'_>,
) {
    let per_piece = (silence.len() / channels.max(1)).max(1);
    let mut left = frames;
    while left > 0 {
        let n = left.min(per_piece);
        let samples = (n * channels).min(silence.len());
        an.process(&silence[..samples], out);
        left -= n;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The far ends of the analysis queues (kept alive so pushes are not to an abandoned ring).
    type Consumers = (
        rtrb::Consumer<FeatureMsg>,
        rtrb::Consumer<AnalysisEvent>,
        rtrb::Consumer<Anchor>,
    );

    /// Analysis queues of the given capacities (features, events, anchors) and their far ends.
    fn queues(features: usize, events: usize, anchors: usize) -> (AnalysisQueues, Consumers) {
        let (features, features_rx) = rtrb::RingBuffer::new(features);
        let (events, events_rx) = rtrb::RingBuffer::new(events);
        let (anchors, anchors_rx) = rtrb::RingBuffer::new(anchors);
        let queues = AnalysisQueues {
            features,
            events,
            anchors,
            motion_thread: std::thread::current(),
            clock: None,
            led: Vec::new(),
        };
        (queues, (features_rx, events_rx, anchors_rx))
    }

    fn out<'a>(queues: &'a mut AnalysisQueues, stats: &'a Stats) -> Out<'a> {
        Out {
            queues,
            stats,
            base_time_s: 0.0,
            ingest_wall_ns: 0,
            steer: GridSteer::new(),
            map: WallMap {
                audio_end_s: 0.0,
                wall_ns: 0,
                speed: 1.0,
            },
        }
    }

    #[test]
    fn silence_for_any_channel_count_fits_the_buffer() {
        // The first 64-channel capture panicked here: 256 frames × 64 ch > the silence buffer.
        let silence = vec![0.0f32; SILENCE_SAMPLES];
        let stats = Stats::new();
        for channels in [1u16, 2, 33, 64, 1000] {
            let (mut queues, (feature_rx, _events, _anchors)) = queues(1024, 4096, 16);
            let mut an = Analyzer::new(live_config(48_000, channels, 25.0)).unwrap();
            let mut out = out(&mut queues, &stats);
            process_silence(&mut an, &silence, 48_000, usize::from(channels), &mut out);
            // One second of audio: 25 model frames, less the analysis's own latency.
            let frames = feature_rx.slots();
            assert!(
                (20..=25).contains(&frames),
                "{channels} ch: {frames} frames"
            );
        }
    }

    #[test]
    fn full_queues_drop_the_newest_and_count_it() {
        let stats = Stats::new();
        let (mut queues, _consumers) = queues(4, 1, 1);
        let mut out = out(&mut queues, &stats);
        for i in 0..3 {
            out.anchor(Anchor {
                audio_end_s: f64::from(i),
                wall_ns: 0,
            });
        }
        let mut an = Analyzer::new(live_config(48_000, 1, 25.0)).unwrap();
        let silence = vec![0.0f32; SILENCE_SAMPLES];
        process_silence(&mut an, &silence, 48_000, 1, &mut out);
        let n = |c: &std::sync::atomic::AtomicU64| c.load(Ordering::Relaxed);
        // A second of audio makes ~24 feature frames and tens of slow events.
        assert!(
            n(&stats.features_dropped) >= 18,
            "{}",
            n(&stats.features_dropped)
        );
        assert!(
            n(&stats.events_dropped) >= 10,
            "{}",
            n(&stats.events_dropped)
        );
        assert_eq!(n(&stats.anchors_dropped), 2);
    }
}
