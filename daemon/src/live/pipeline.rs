//! The live pipeline: analysis, motion and sender threads around the audio ring, started
//! together and stopped together (one stop flag for Ctrl-C, `--duration` and tests).

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Instant;

use anyhow::{Context, Result, anyhow};
use crossbeam_channel::Receiver;
use model::source::MotionSource;

use super::analysis::{self, AnalysisSettings};
use super::motion::{self, MotionSettings};
use super::ring::{RingReader, RingWriter, audio_ring};
use super::scheduler::{self, SchedulerSettings};
use super::sink::{FrameSink, PoseBank};
use super::stats::{Stats, StatsReport, process_cpu_s};
use super::timeline::Timeline;
use super::wire::ControlEvent;

/// Interleaved samples the audio ring holds (≈ 2.7 s of 48 kHz stereo).
pub const RING_SAMPLES: usize = 1 << 18;
/// Blocks (markers) the audio ring holds.
pub const RING_BLOCKS: usize = 4096;

/// Settings of a pipeline run.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PipelineSettings {
    /// Frames sent per second.
    pub rate_hz: f64,
    /// Audio seconds per wall second (1 live; the replay speed otherwise).
    pub speed: f64,
    /// Safety margin added to the declared look-ahead before a pose is shown, ms.
    pub margin_ms: f64,
    /// Initial temperature.
    pub temperature: f32,
    /// Initial transition length for immediate key poses, beats.
    pub transition_beats: f32,
    /// Initial beat accent (None: the source's own).
    pub beat_accent: Option<f32>,
    /// Wall time without audio after which silence is analysed instead, seconds.
    pub silence_after_s: f64,
    /// Run the threads at real-time priority where the system allows it.
    pub realtime: bool,
}

impl Default for PipelineSettings {
    /// 60 Hz, real time, 8 ms margin, temperature 0.5, one-beat transitions, real-time threads.
    fn default() -> Self {
        Self {
            rate_hz: 60.0,
            speed: 1.0,
            margin_ms: 8.0,
            temperature: 0.5,
            transition_beats: 1.0,
            beat_accent: None,
            silence_after_s: 0.25,
            realtime: true,
        }
    }
}

/// What every part of a run shares: the clock epoch, the counters and the stop flag.
#[derive(Clone)]
pub struct LiveContext {
    /// Zero of every wall time in the run (ns offsets from it are stored in atomics).
    pub epoch: Instant,
    /// The run's counters.
    pub stats: Arc<Stats>,
    /// Set to stop every thread.
    pub stop: Arc<AtomicBool>,
}

impl Default for LiveContext {
    fn default() -> Self {
        Self::new()
    }
}

impl LiveContext {
    /// A fresh context starting now.
    pub fn new() -> Self {
        Self {
            epoch: Instant::now(),
            stats: Arc::new(Stats::new()),
            stop: Arc::new(AtomicBool::new(false)),
        }
    }

    /// A new audio ring for this run.
    pub fn ring(&self) -> (RingWriter, RingReader) {
        audio_ring(RING_SAMPLES, RING_BLOCKS, self.epoch, self.stats.clone())
    }

    /// Whether the run was asked to stop.
    pub fn stopped(&self) -> bool {
        self.stop.load(Ordering::Relaxed)
    }
}

/// Everything the pipeline is built from besides the audio.
pub struct PipelineParts {
    /// The dancer.
    pub source: Box<dyn MotionSource + Send>,
    /// Where frames and events go.
    pub sink: Box<dyn FrameSink>,
    /// Live controls (OSC/MIDI receivers and tests send into it).
    pub controls: Receiver<ControlEvent>,
    /// Key poses by name.
    pub poses: Box<dyn PoseBank + Send>,
}

/// A running pipeline.
pub struct Pipeline {
    ctx: LiveContext,
    analysis: Option<JoinHandle<Result<(), String>>>,
    motion: Option<JoinHandle<()>>,
    sender: Option<JoinHandle<Box<dyn FrameSink>>>,
    cpu_start_s: f64,
    started: Instant,
    declared_lookahead_s: f64,
}

/// The declared look-ahead of a source at `model_rate` with `lookahead` frames, audio seconds:
/// look-ahead frames plus one (interpolation), half a short window plus the resampler delay,
/// and one analysis hop (see `stats`).
pub fn declared_lookahead_s(model_rate: f64, lookahead: usize, input_rate: u32) -> f64 {
    let resampler_delay = if input_rate == dsp::ANALYSIS_RATE {
        0.0
    } else {
        0.006
    };
    (lookahead as f64 + 1.0) / model_rate
        + (dsp::SHORT_WINDOW / 2 + dsp::HOP) as f64 / f64::from(dsp::ANALYSIS_RATE)
        + resampler_delay
}

impl Pipeline {
    /// Starts the threads reading `reader`.
    pub fn start(
        ctx: &LiveContext,
        settings: PipelineSettings,
        parts: PipelineParts,
        reader: RingReader,
    ) -> Result<Self> {
        if !(settings.rate_hz.is_finite() && (1.0..=1000.0).contains(&settings.rate_hz)) {
            return Err(anyhow!(
                "output rate {} Hz is not in 1..=1000",
                settings.rate_hz
            ));
        }
        if !(settings.speed.is_finite() && settings.speed > 0.0) {
            return Err(anyhow!("speed {} must be positive", settings.speed));
        }
        let model_rate = parts.source.frame_rate();
        let declared = declared_lookahead_s(model_rate, parts.source.lookahead_frames(), 0);
        let timeline = Arc::new(Mutex::new(Timeline::new(settings.speed)));
        // Deep queues: seconds of frames, so a stalled thread loses nothing.
        let (ftx, frx) = crossbeam_channel::bounded(1024);
        let (etx, erx) = crossbeam_channel::bounded(4096);
        let spawn_err = |what: &str| format!("starting the {what} thread");
        let realtime = settings.realtime;
        let promote = move |priority: i32, stats: &Stats| {
            if realtime && super::priority::promote_current_thread(priority) {
                stats.realtime_threads.fetch_add(1, Ordering::Relaxed);
            }
        };
        let analysis = {
            let (tl, stats, stop, epoch) = (
                timeline.clone(),
                ctx.stats.clone(),
                ctx.stop.clone(),
                ctx.epoch,
            );
            let s = AnalysisSettings {
                model_rate,
                silence_after_s: settings.silence_after_s,
            };
            std::thread::Builder::new()
                .name("danced-analysis".into())
                .spawn(move || {
                    promote(super::priority::ANALYSIS_PRIORITY, &stats);
                    analysis::run(reader, s, epoch, tl, stats, stop, ftx, etx)
                })
                .with_context(|| spawn_err("analysis"))?
        };
        let motion = {
            let (tl, stats, stop, epoch) = (
                timeline.clone(),
                ctx.stats.clone(),
                ctx.stop.clone(),
                ctx.epoch,
            );
            let s = MotionSettings {
                temperature: settings.temperature,
                transition_beats: settings.transition_beats,
                beat_accent: settings.beat_accent,
            };
            let PipelineParts {
                source,
                controls,
                poses,
                ..
            } = parts;
            std::thread::Builder::new()
                .name("danced-motion".into())
                .spawn(move || {
                    promote(super::priority::MOTION_PRIORITY, &stats);
                    motion::run(source, poses, s, epoch, tl, stats, stop, frx, controls)
                })
                .with_context(|| spawn_err("motion"))?
        };
        let sender = {
            let (tl, stats, stop, epoch) =
                (timeline, ctx.stats.clone(), ctx.stop.clone(), ctx.epoch);
            let s = SchedulerSettings {
                rate_hz: settings.rate_hz,
                declared_lookahead_s: declared,
                margin_s: settings.margin_ms * 1e-3,
                speed: settings.speed,
            };
            let sink = parts.sink;
            std::thread::Builder::new()
                .name("danced-send".into())
                .spawn(move || {
                    promote(super::priority::SENDER_PRIORITY, &stats);
                    scheduler::run(sink, s, epoch, tl, stats, stop, erx)
                })
                .with_context(|| spawn_err("sender"))?
        };
        Ok(Self {
            ctx: ctx.clone(),
            analysis: Some(analysis),
            motion: Some(motion),
            sender: Some(sender),
            cpu_start_s: process_cpu_s(),
            started: Instant::now(),
            declared_lookahead_s: declared,
        })
    }

    /// The declared look-ahead this run pays, audio seconds.
    pub fn declared_lookahead_s(&self) -> f64 {
        self.declared_lookahead_s
    }

    /// Whether any thread has ended on its own (an error), which stops the run.
    pub fn failed(&self) -> bool {
        self.analysis.as_ref().is_some_and(|h| h.is_finished())
            || self.motion.as_ref().is_some_and(|h| h.is_finished())
            || self.sender.as_ref().is_some_and(|h| h.is_finished())
    }

    /// Stops every thread, waits for them and returns the run's report (and the sink).
    pub fn stop(mut self) -> Result<(StatsReport, Box<dyn FrameSink>)> {
        self.ctx.stop.store(true, Ordering::Relaxed);
        let wall = self.started.elapsed().as_secs_f64();
        let cpu = process_cpu_s() - self.cpu_start_s;
        let analysis = self.analysis.take().map(|h| h.join());
        let motion = self.motion.take().map(|h| h.join());
        let sink = match self.sender.take().map(|h| h.join()) {
            Some(Ok(s)) => s,
            _ => return Err(anyhow!("the sender thread panicked")),
        };
        if let Some(Ok(Err(e))) = analysis {
            return Err(anyhow!(e)).context("the analysis thread failed");
        }
        if matches!(analysis, Some(Err(_))) {
            return Err(anyhow!("the analysis thread panicked"));
        }
        if matches!(motion, Some(Err(_))) {
            return Err(anyhow!("the motion thread panicked"));
        }
        Ok((self.ctx.stats.report(wall, cpu), sink))
    }
}
