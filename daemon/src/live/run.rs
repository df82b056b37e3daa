//! The `danced run`, `danced demo`, `danced bench live` and `danced devices` commands: the
//! binary's edge of the live pipeline (config + flags → threads → status line → stats).

use std::path::PathBuf;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};

use super::capture::{self, CaptureSettings};
use super::clock::{ClockDesk, ClockSettings, ClockSource, ClockWiring};
use super::config::Config;
use super::context::LiveContext;
use super::control_queue::ControlHub;
use super::io::{ControlInputs, OscSink};
use super::pipeline::{Pipeline, PipelineParts, PipelineSettings};
use super::replay::{self, ReplayAudio, ReplaySettings};
use super::sink::FrameSink;
use super::stats::StatsReport;
use super::status::StatusPrinter;
use crate::view::assets::Assets;
use crate::view::{LiveFeed, SinkPair, ViewHello, ViewServer};

/// Where the audio comes from.
#[derive(Clone, Debug, PartialEq)]
pub enum AudioSource {
    /// The sound card (device name substring, or the default input).
    Capture(Option<String>),
    /// A file replayed in real time (or faster).
    File(PathBuf),
    /// The built-in demo song, looped.
    Demo,
}

/// How a run presents itself.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RunMode {
    /// Status line on stderr, summary at the end.
    Interactive,
    /// No status line (benchmarks, tests).
    Quiet,
}

/// Runs the live pipeline until Ctrl-C, the configured duration, or a failure.
pub fn run_live(config: &Config, audio: AudioSource, mode: RunMode) -> Result<StatsReport> {
    let ctx = LiveContext::new();
    let (writer, reader) = ctx.ring();
    let mut replay_handle = None;
    let mut capture_handle = None;
    let what = match &audio {
        AudioSource::File(path) => {
            let a = ReplayAudio::from_file(path)?;
            let name = a.name.clone();
            replay_handle = Some(replay::spawn(
                a,
                replay_settings(config, config.audio.looped),
                writer,
                &ctx,
            )?);
            name
        }
        AudioSource::Demo => {
            let a = ReplayAudio::demo(32.0 * 60.0 / crate::demo_track::DEMO_BPM * 4.0);
            let name = a.name.clone();
            replay_handle = Some(replay::spawn(
                a,
                replay_settings(config, true),
                writer,
                &ctx,
            )?);
            name
        }
        AudioSource::Capture(device) => {
            let (h, desc) = capture::spawn(
                CaptureSettings {
                    device: device.clone(),
                    channels: config.audio.channels.clone(),
                },
                writer,
                &ctx,
            )
            .context("opening the audio input")?;
            capture_handle = Some(h);
            desc
        }
    };
    let kind = crate::dancer::SourceKind::parse(&config.dancer.source)
        .with_context(|| format!("unknown motion source {:?}", config.dancer.source))?;
    let (source, moves) = crate::dancer::open_source_named(
        kind,
        &crate::dancer::SourceSettings {
            network_only: false,
            model: config.dancer.model.as_deref(),
            libraries: &config.dancer.libraries,
            // Live, the accent travels with the controls (set from the configuration at start).
            beat_accent: None,
            foot_plant: Some(config.dancer.foot_plant),
            key_route: Some(config.dancer.key_pose_route()),
            stage: config.stage.settings(),
        },
        config.dancer.seed,
    )?;
    crate::dancer::check_style(source.as_ref(), config.dancer.style_request())?;
    let poses = match &config.control.poses {
        Some(p) => crate::pose_bank::PoseBank::load(p)?,
        None => crate::pose_bank::PoseBank::shipped()?,
    };
    let osc = OscSink::from_config(config)?;
    let targets = osc.describe();
    let _ = ctx.stats.moves_names.set(moves.clone());
    let (desk, feed) = ClockDesk::new(clock_settings(config), ctx.epoch);
    let (clock, clock_threads) = start_clocks(config, &desk, feed, &ctx)?;
    let mut hub = ControlHub::new(&poses, ctx.stats.clone())
        .honouring(source.controls())
        .with_moves(moves.clone())
        .with_clock(desk.clone());
    let controls = ControlInputs::start(config, &mut hub, &desk, ctx.stop.clone())?;
    let mut sink: Box<dyn FrameSink> = Box::new(osc);
    let view = if config.view.enabled {
        let hello = ViewHello {
            mode: "live",
            dancer: kind.name().to_string(),
            poses: hub.pose_names(),
            rate_hz: config.output.rate_hz,
            model_rate_hz: source.frame_rate(),
            lead_ms: config.output.lead_ms,
            controls: source.controls(),
            stage: Some(config.stage.settings().sanitized()),
            moves: if source.controls().moves {
                moves.clone()
            } else {
                Vec::new()
            },
            clocks: ClockSource::ALL
                .into_iter()
                .filter(|c| match c {
                    ClockSource::Midi => config.control.midi_port.is_some(),
                    ClockSource::Link => config.clock.link,
                    ClockSource::Audio | ClockSource::Tap => true,
                })
                .map(ClockSource::name)
                .collect(),
            ..ViewHello::default()
        };
        let feed = LiveFeed {
            stats: ctx.stats.clone(),
            controls: hub.sender(),
        };
        let (server, view_sink) = ViewServer::start(
            &config.view.addr,
            Assets::page(&model::rig::Skeleton::default_adult()),
            hello,
            Some(feed),
            ctx.stop.clone(),
        )?;
        if let Some(v) = view_sink {
            sink = Box::new(SinkPair::new(sink, Box::new(v)));
        }
        Some(server)
    } else {
        None
    };
    let settings = PipelineSettings {
        rate_hz: config.output.rate_hz,
        speed: if matches!(audio, AudioSource::Capture(_)) {
            1.0
        } else {
            config.audio.speed
        },
        margin_ms: config.output.margin_ms,
        lead_ms: config.output.lead_ms,
        temperature: config.dancer.temperature,
        transition_beats: config.dancer.transition_beats,
        beat_accent: Some(config.dancer.beat_accent),
        style: config.dancer.style_request(),
        realtime: config.output.realtime,
        ..PipelineSettings::default()
    };
    let pipeline = Pipeline::start(
        &ctx,
        settings,
        PipelineParts {
            source,
            sink,
            controls: hub,
            clock: Some(clock),
        },
        reader,
    )?;
    let stop = ctx.stop.clone();
    if let Err(e) = ctrlc::set_handler(move || stop.store(true, Ordering::Relaxed)) {
        tracing::warn!("Ctrl-C handler not installed: {e}");
    }
    if mode == RunMode::Interactive {
        eprintln!(
            "{} dancer dancing to {what}; {} Hz out to {targets}; showing the music heard {:+.0} ms from now (poses made {} frames ahead of the analysis); Ctrl-C stops",
            kind.name(),
            settings.rate_hz,
            settings.lead_ms,
            pipeline.horizon_frames()
        );
        if let Some(v) = &view {
            eprintln!("view: open {} in a browser", v.url());
        }
        if let Some(a) = controls.osc_addr {
            eprintln!("OSC control on {a} (/danced/control/...)");
        }
        if let Some(p) = &controls.midi_port {
            eprintln!("MIDI control from {p}");
        }
        if config.clock.source() != ClockSource::Audio {
            eprintln!("beat grid from the {} clock", config.clock.source().name());
        }
        if config.clock.link {
            eprintln!("joined the Link session on every network interface");
        }
    }
    let started = Instant::now();
    // Capture has no audio clock of its own to end on: --duration is wall time there.
    let wall_limit = match audio {
        AudioSource::Capture(_) => config.audio.duration.map(Duration::from_secs_f64),
        _ => None,
    };
    let mut status = StatusPrinter::new();
    // Memory is sampled from 1 s on (after start-up) while the input still runs: a finished
    // replay frees its audio, which would fake a shrinking process.
    let mut next_rss = Duration::from_secs(1);
    while !ctx.stopped() && !pipeline.failed() {
        std::thread::sleep(status.interval());
        let elapsed = started.elapsed();
        if elapsed >= next_rss && !ctx.stopped() {
            ctx.stats.sample_rss(elapsed.as_secs_f64());
            next_rss += Duration::from_secs(1);
        }
        if mode == RunMode::Interactive {
            status.tick(&ctx.stats);
        }
        if wall_limit.is_some_and(|l| elapsed >= l) {
            ctx.stop.store(true, Ordering::Relaxed);
        }
    }
    status.finish();
    let (mut report, _sink) = pipeline.stop()?;
    report.view = view.map(ViewServer::stop);
    let counters = controls.counters.clone();
    controls.join();
    for t in clock_threads {
        if t.join().is_err() {
            bail!("a clock thread panicked");
        }
    }
    report.osc_control_accepted = counters.osc_accepted.load(Ordering::Relaxed);
    report.osc_control_ignored = counters.osc_ignored.load(Ordering::Relaxed);
    report.midi_events = counters.midi_events.load(Ordering::Relaxed);
    report.midi_bytes_dropped = counters.midi_dropped.load(Ordering::Relaxed);
    report.midi_skipped = counters.midi_skipped.load(Ordering::Relaxed);
    report.osc_control_refused_sources = counters.osc_refused_sources.load(Ordering::Relaxed);
    report.midi_queue_full = counters.midi_queue_full.load(Ordering::Relaxed);
    for h in [replay_handle, capture_handle].into_iter().flatten() {
        if h.join().is_err() {
            bail!("the audio input thread panicked");
        }
    }
    if let Some(path) = &config.stats_json {
        let json = serde_json::to_string_pretty(&report).context("encoding the stats")?;
        offline::files::write_atomic(path, json.as_bytes())
            .with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(report)
}

/// The clock desk's settings from `config`.
pub fn clock_settings(config: &Config) -> ClockSettings {
    ClockSettings {
        source: config.clock.source(),
        beats_per_bar: config.clock.beats_per_bar,
        trim: config.clock.trim,
        midi: config.control.midi_port.is_some(),
        link: config.clock.link,
    }
}

/// The clocks danced leads (MIDI clock out, Link), each a thread fed the grid followed; and
/// the analysis thread's ends.
pub fn start_clocks(
    config: &Config,
    desk: &ClockDesk,
    feed: triple_buffer::Output<super::clock::ClockSnapshot>,
    ctx: &LiveContext,
) -> Result<(ClockWiring, Vec<std::thread::JoinHandle<()>>)> {
    let mut led = Vec::new();
    let mut threads = Vec::new();
    if let Some(port) = &config.clock.midi_out {
        let out = protocols::MidiOutConnection::connect(port)
            .with_context(|| format!("opening MIDI output {port:?} for the clock"))?;
        let (input, output) = triple_buffer::triple_buffer(&None);
        led.push(input);
        threads.push(
            super::midi_clock_out::spawn(Box::new(out), output, ctx, config.output.realtime)
                .context("starting the MIDI clock thread")?,
        );
    }
    if config.clock.link {
        #[cfg(feature = "link")]
        {
            let (input, output) = triple_buffer::triple_buffer(&None);
            led.push(input);
            threads.push(
                super::link::spawn(desk.clone(), output, ctx)
                    .context("starting the Link thread")?,
            );
        }
        #[cfg(not(feature = "link"))]
        bail!("this build has no Ableton Link (build with --features link)");
    }
    let _ = desk;
    Ok((ClockWiring { feed, led }, threads))
}

fn replay_settings(config: &Config, looped: bool) -> ReplaySettings {
    ReplaySettings {
        speed: config.audio.speed,
        looped,
        duration_s: config.audio.duration,
    }
}

/// The end-of-run summary, one fact per line; every loss counter appears, zero or not.
pub fn summary(r: &StatsReport) -> String {
    let mb = |b: u64| b as f64 / 1_048_576.0;
    let a = &r.allocations;
    format!(
        "ran          {:.1} s, {} frames sent ({:.1} Hz), {} model frames made {} frames ahead of the analysis, {} late, {} sender stalls\n\
         latency      p50 {:.2} ms, p99 {:.2} ms, max {:.2} ms (added: sent later than the heard music plus the lead)\n\
         processing   p50 {:.2} ms, p99 {:.2} ms, max {:.2} ms (audio in → pose ready)\n\
         tick to sent p50 {:.3} ms, p99 {:.3} ms, max {:.3} ms (scheduled tick → send_to returned)\n\
         jitter       p50 {:.3} ms, p99 {:.3} ms, max {:.3} ms (frame spacing − period, at send_to)\n\
         cpu          {:.1} % of one core, {} threads at real-time priority\n\
         memory       RSS start {:.1} MiB, end {:.1} MiB, max {:.1} MiB (first minute max {:.1}, last minute max {:.1})\n\
         allocations  capture {}, analysis {}, motion {}, sender {}, MIDI clock {}{}\n\
         audio        {} frames dropped, {} stream errors, {} stalls, {} reconnects ({} failed tries), {} blocks contended, {} old streams stuck, {} frames of silence inserted\n\
         queues       {} feature frames, {} clock anchors, {} poses, {} events dropped\n\
         packets      {} sent, {} send errors, {} non-finite values replaced, {} VRChat trackers without a bone\n\
         controls     {} applied, {} rejected, {} not honoured by the dancer, {} coalesced, {} rate-limited, {} dropped (queue full)\n\
         control in   OSC {} accepted, {} ignored, {} from refused sources; MIDI {} events, {} bytes dropped, {} skipped, {} lost (queue full)\n\
         clock        {}{}{}{}{}",
        r.wall_s,
        r.frames_sent,
        r.frames_sent as f64 / r.wall_s.max(1e-9),
        r.model_frames,
        r.horizon_frames,
        r.late_frames,
        r.sender_stalls,
        r.latency_ms_p50,
        r.latency_ms_p99,
        r.latency_ms_max,
        r.processing_ms_p50,
        r.processing_ms_p99,
        r.processing_ms_max,
        r.tick_to_sent_ms_p50,
        r.tick_to_sent_ms_p99,
        r.tick_to_sent_ms_max,
        r.jitter_ms_p50,
        r.jitter_ms_p99,
        r.jitter_ms_max,
        r.cpu_percent,
        r.realtime_threads,
        mb(r.rss_start),
        mb(r.rss_end),
        mb(r.rss_max),
        mb(r.rss_first_minute_max),
        mb(r.rss_last_minute_max),
        a.capture,
        a.analysis,
        a.motion,
        a.sender,
        a.clock_out,
        if r.allocation_counting {
            ""
        } else {
            " (not counted: no counting allocator)"
        },
        r.drops,
        r.stream_errors,
        r.capture_stalls,
        r.reconnects,
        r.reconnect_failures,
        r.capture_contended,
        r.capture_streams_stuck,
        r.silence_frames,
        r.features_dropped,
        r.anchors_dropped,
        r.poses_dropped,
        r.events_dropped,
        r.packets_sent,
        r.send_errors,
        r.non_finite_replaced,
        r.vrchat_missing_bones,
        r.controls_accepted,
        r.controls_rejected,
        r.controls_unsupported,
        r.controls_coalesced,
        r.controls_rate_limited,
        r.controls_dropped,
        r.osc_control_accepted,
        r.osc_control_ignored,
        r.osc_control_refused_sources,
        r.midi_events,
        r.midi_bytes_dropped,
        r.midi_skipped,
        r.midi_queue_full,
        clock_summary(&r.clock),
        r.safety_nets
            .map(|c| format!("\nsafety nets  {}", c.summary()))
            .unwrap_or_default(),
        r.stage
            .map(|c| format!(
                "\nstage        of {} frames {} steered, {} glided back, {} clamped; turning at most {:.0}°/s",
                c.frames, c.steered, c.glided, c.clamped, c.max_turn_deg_per_s
            ))
            .unwrap_or_default(),
        r.moves
            .as_ref()
            .map(|m| format!("\nmoves        {m} at the end, {} switches", r.moves_switches))
            .unwrap_or_default(),
        r.view
            .map(|v| view_summary(&v, r.wall_s))
            .unwrap_or_default(),
    )
}

/// The clock's line of the summary.
fn clock_summary(c: &super::stats::ClockReport) -> String {
    let offset = c
        .offset_ms
        .map(|o| format!(", heard {o:+.1} ms from it"))
        .unwrap_or_default();
    format!(
        "{} at {:.1} BPM{offset}, trimmed {:+.1} ms, nudged {:+.1} ms, {} frames on the heard beats for want of it, {} Link peers; MIDI clock out {} ticks, {} restarts after a jump, {} refused",
        c.source,
        c.tempo_bpm,
        c.trim_ms,
        c.nudge_ms,
        c.fallback_frames,
        c.peers,
        c.midi_ticks_sent,
        c.midi_restarts,
        c.midi_send_errors,
    )
}

/// The view's line of the summary.
fn view_summary(v: &crate::view::ViewReport, wall_s: f64) -> String {
    format!(
        "\nview         {} browsers ({} dropped for falling behind, {} refused), {} frames forwarded, {} skipped, {} replaced in the slot, {} events dropped; {} files served, {} HTTP errors; controls {} accepted, {} ignored; view thread {:.2} % of one core",
        v.clients_accepted,
        v.clients_dropped_slow,
        v.clients_refused,
        v.frames_forwarded,
        v.frames_skipped,
        v.frames_replaced,
        v.events_dropped,
        v.http_served,
        v.http_errors,
        v.controls_accepted,
        v.controls_ignored,
        v.thread_cpu_us as f64 * 1e-4 / wall_s.max(1e-9),
    )
}
