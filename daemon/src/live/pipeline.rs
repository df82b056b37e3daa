//! The live pipeline: analysis, motion and sender threads around the audio ring, started
//! together and stopped together (one stop flag for Ctrl-C, `--duration` and tests).

use std::sync::atomic::Ordering;
use std::thread::JoinHandle;
use std::time::Instant;

use anyhow::{Context, Result, anyhow};
use model::source::MotionSource;

use super::analysis::{self, AnalysisQueues, AnalysisSettings};
use super::clock::ClockWiring;
use super::context::LiveContext;
use super::control_queue::ControlHub;
use super::motion::{self, MotionQueues, MotionSettings};
use super::ring::RingReader;
use super::scheduler::{self, SchedulerSettings, SenderQueues};
use super::sink::FrameSink;
use super::stats::{Stats, StatsReport, process_cpu_s};

/// Feature frames the analysis → motion queue holds (40 s at 25 fps).
pub const FEATURE_QUEUE: usize = 1024;
/// Analysis events the analysis → sender queue holds.
pub const EVENT_QUEUE: usize = 4096;
/// Audio-clock anchors the analysis → sender queue holds (20 s of 256-frame blocks).
pub const ANCHOR_QUEUE: usize = 4096;
/// Poses the motion → sender queue holds (10 s at 25 fps).
pub const POSE_QUEUE: usize = 256;

/// Settings of a pipeline run.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PipelineSettings {
    /// Frames sent per second.
    pub rate_hz: f64,
    /// Audio seconds per wall second (1 live; the replay speed otherwise).
    pub speed: f64,
    /// Delivery margin the poses are made ahead by (capture blocks, hand-offs), wall ms; it
    /// lengthens the prediction horizon and adds no delay.
    pub margin_ms: f64,
    /// How far ahead of the heard music the shown pose is, wall ms (cancels a renderer's
    /// display latency; may be negative).
    pub lead_ms: f64,
    /// Initial temperature.
    pub temperature: f32,
    /// Initial transition length for immediate key poses, beats.
    pub transition_beats: f32,
    /// Initial beat accent (None: the source's own).
    pub beat_accent: Option<f32>,
    /// Initial dance style (auto by default).
    pub style: model::style::StyleRequest,
    /// Wall time without audio after which silence is analysed instead, seconds.
    pub silence_after_s: f64,
    /// Run the threads at real-time priority where the system allows it.
    pub realtime: bool,
}

impl Default for PipelineSettings {
    /// 60 Hz, real time, 15 ms margin, lead 0, temperature 0.5, one-beat transitions,
    /// real-time threads.
    fn default() -> Self {
        Self {
            rate_hz: 60.0,
            speed: 1.0,
            margin_ms: model::horizon::DEFAULT_MARGIN_S * 1e3,
            lead_ms: 0.0,
            temperature: 0.5,
            transition_beats: 1.0,
            beat_accent: None,
            style: model::style::StyleRequest::Auto,
            silence_after_s: 0.25,
            realtime: true,
        }
    }
}

/// Everything the pipeline is built from besides the audio.
pub struct PipelineParts {
    /// The dancer.
    pub source: Box<dyn MotionSource + Send>,
    /// Where frames and events go.
    pub sink: Box<dyn FrameSink>,
    /// The control path (its senders already handed to the OSC/MIDI inputs and tests), with
    /// the key poses they resolve names to.
    pub controls: ControlHub,
    /// The clocks the grid may follow (`None`: the heard beats only).
    pub clock: Option<ClockWiring>,
}

/// A running pipeline.
pub struct Pipeline {
    ctx: LiveContext,
    analysis: Option<JoinHandle<Result<(), String>>>,
    motion: Option<JoinHandle<()>>,
    sender: Option<JoinHandle<Box<dyn FrameSink>>>,
    cpu_start_s: f64,
    started: Instant,
    horizon_frames: usize,
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
        if !(settings.lead_ms.is_finite() && settings.lead_ms.abs() <= 1000.0) {
            return Err(anyhow!(
                "lead {} ms is not in -1000..=1000",
                settings.lead_ms
            ));
        }
        let model_rate = parts.source.frame_rate();
        // Audio seconds: the lead and the margin are wall times.
        let horizon = model::horizon::source_horizon(
            &*parts.source,
            settings.lead_ms * 1e-3 * settings.speed,
            settings.margin_ms * 1e-3 * settings.speed,
        );
        // Wait-free SPSC queues, deep enough that only a stalled thread can fill one (counted).
        let (features_tx, features_rx) = rtrb::RingBuffer::new(FEATURE_QUEUE);
        let (events_tx, events_rx) = rtrb::RingBuffer::new(EVENT_QUEUE);
        let (anchors_tx, anchors_rx) = rtrb::RingBuffer::new(ANCHOR_QUEUE);
        let (poses_tx, poses_rx) = rtrb::RingBuffer::new(POSE_QUEUE);
        let spawn_err = |what: &str| format!("starting the {what} thread");
        let realtime = settings.realtime;
        let promote = move |priority: i32, stats: &Stats| {
            if realtime && super::priority::promote_current_thread(priority) {
                stats.realtime_threads.fetch_add(1, Ordering::Relaxed);
            }
        };
        let PipelineParts {
            source,
            sink,
            controls,
            clock,
        } = parts;
        let (clock, led) = match clock {
            Some(w) => (Some(w.feed), w.led),
            None => (None, Vec::new()),
        };
        let motion = {
            let ctx = ctx.clone();
            let s = MotionSettings {
                temperature: settings.temperature,
                transition_beats: settings.transition_beats,
                beat_accent: settings.beat_accent,
                style: settings.style,
                horizon_frames: horizon,
            };
            let (receiver, table) = controls.into_receiver();
            let queues = MotionQueues {
                features: features_rx,
                controls: receiver,
                poses: poses_tx,
            };
            ctx.stats.temperature.set(s.temperature);
            ctx.stats.beat_accent.set(s.beat_accent.unwrap_or(f32::NAN));
            std::thread::Builder::new()
                .name("danced-motion".into())
                .spawn(move || {
                    promote(super::priority::MOTION_PRIORITY, &ctx.stats);
                    motion::run(source, table, s, ctx, queues)
                })
                .with_context(|| spawn_err("motion"))?
        };
        let analysis = {
            let ctx = ctx.clone();
            let s = AnalysisSettings {
                model_rate,
                silence_after_s: settings.silence_after_s,
                speed: settings.speed,
            };
            let queues = AnalysisQueues {
                features: features_tx,
                events: events_tx,
                anchors: anchors_tx,
                motion_thread: motion.thread().clone(),
                clock,
                led,
            };
            std::thread::Builder::new()
                .name("danced-analysis".into())
                .spawn(move || {
                    promote(super::priority::ANALYSIS_PRIORITY, &ctx.stats);
                    analysis::run(reader, s, ctx, queues)
                })
                .with_context(|| spawn_err("analysis"))?
        };
        let sender = {
            let ctx = ctx.clone();
            let s = SchedulerSettings {
                rate_hz: settings.rate_hz,
                lead_s: settings.lead_ms * 1e-3,
                speed: settings.speed,
            };
            let queues = SenderQueues {
                anchors: anchors_rx,
                poses: poses_rx,
                events: events_rx,
            };
            std::thread::Builder::new()
                .name("danced-send".into())
                .spawn(move || {
                    promote(super::priority::SENDER_PRIORITY, &ctx.stats);
                    scheduler::run(sink, s, ctx, queues)
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
            horizon_frames: horizon,
        })
    }

    /// Model frames past the newest analysed frame each pose is made for (`model::horizon`).
    pub fn horizon_frames(&self) -> usize {
        self.horizon_frames
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
        let mut report = self.ctx.stats.report(wall, cpu);
        report.horizon_frames = self.horizon_frames as u64;
        Ok((report, sink))
    }
}
