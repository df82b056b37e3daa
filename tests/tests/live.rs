//! The live pipeline end to end, in process: a synthesised 120 BPM click track replayed
//! through the ring, analysis, a test dancer and the paced sender into a channel.

use std::sync::atomic::Ordering;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use crossbeam_channel::{Receiver, unbounded};
use daemon::live::context::LiveContext;
use daemon::live::control_queue::ControlHub;
use daemon::live::pipeline::{Pipeline, PipelineParts, PipelineSettings};
use daemon::live::replay::{self, ReplayAudio, ReplaySettings};
use daemon::live::sink::{ChannelSink, FrameSink, MemoryPoseBank, SinkItem};
use daemon::live::stats::StatsReport;
use daemon::live::wire::{AnalysisEvent, BodyFrame, ControlEvent, Quantize};
use dsp::feature::FEATURE_DIM;
use glam::Quat;
use model::rig::{JOINT_COUNT, Joint, Pose};
use model::source::{Controls, MotionSource};

#[global_allocator]
static ALLOCATOR: daemon::alloc_counter::CountingAllocator =
    daemon::alloc_counter::CountingAllocator;

const RATE: u32 = 44_100;
const BPM: f64 = 120.0;
const FIRST_CLICK_S: f64 = 0.25;
const FPS: f64 = 25.0;

/// Stereo clicks (short decaying noise bursts with a low thump) every beat.
fn click_track(seconds: f64) -> ReplayAudio {
    let (samples, _) = daemon::demo_track::click_track(seconds, BPM, FIRST_CLICK_S, RATE);
    ReplayAudio {
        samples,
        sample_rate: RATE,
        channels: 2,
        name: "click track".into(),
    }
}

/// What the test dancer saw on each step.
#[derive(Clone, Copy, Debug)]
struct Seen {
    step: u64,
    frames_to_go: Option<u32>,
}

/// Echoes the temperature into the hips' yaw and the beat accent (if set) into the spine's
/// yaw (radians), and records key-pose countdowns.
struct EchoSource {
    steps: u64,
    seen: Arc<Mutex<Vec<Seen>>>,
}

impl MotionSource for EchoSource {
    fn frame_rate(&self) -> f64 {
        FPS
    }
    fn lookahead_frames(&self) -> usize {
        2
    }
    fn step(&mut self, music: &[[f32; FEATURE_DIM]], controls: &Controls, out: &mut Pose) {
        assert_eq!(music.len(), 3);
        *out = Pose::rest();
        out.set_rotation(Joint::Hips, Quat::from_rotation_y(controls.temperature));
        if let Some(a) = controls.beat_accent {
            out.set_rotation(Joint::Spine, Quat::from_rotation_y(a));
        }
        if let Ok(mut s) = self.seen.lock() {
            s.push(Seen {
                step: self.steps,
                frames_to_go: controls.key_pose.map(|k| k.frames_to_go),
            });
        }
        self.steps += 1;
    }
    fn reset(&mut self, _seed: u64) {}
    fn reseed(&mut self, _seed: u64) {}
}

struct Run {
    report: StatsReport,
    frames: Vec<(BodyFrame, std::time::Instant)>,
    events: Vec<AnalysisEvent>,
    seen: Vec<Seen>,
    /// Model frames past the newest analysed frame the poses were made for.
    horizon: usize,
}

/// Replays `seconds` of clicks at `speed`; `controls` are sent at the given wall offsets.
fn run(seconds: f64, speed: f64, controls: Vec<(f64, ControlEvent)>) -> Run {
    run_until(seconds, speed, controls, None)
}

/// As [`run`], but the audio ends after `seconds` while the run goes on until `wall_stop_s`.
fn run_until(
    seconds: f64,
    speed: f64,
    controls: Vec<(f64, ControlEvent)>,
    wall_stop_s: Option<f64>,
) -> Run {
    let ctx = LiveContext::new();
    let (writer, reader) = ctx.ring();
    let (tx, rx): (_, Receiver<SinkItem>) = unbounded();
    // Preallocated: the echo dancer records on the motion thread, whose allocations count.
    let seen = Arc::new(Mutex::new(Vec::with_capacity(10_000)));
    let mut bank = MemoryPoseBank::new();
    bank.insert("up", [Quat::from_rotation_x(0.3); JOINT_COUNT]);
    let mut hub = ControlHub::new(&bank, ctx.stats.clone());
    let mut ctx_tx = hub.sender();
    let pipeline = Pipeline::start(
        &ctx,
        PipelineSettings {
            speed,
            temperature: 0.1,
            ..PipelineSettings::default()
        },
        PipelineParts {
            source: Box::new(EchoSource {
                steps: 0,
                seen: seen.clone(),
            }),
            sink: Box::new(ChannelSink::new(tx)),
            controls: hub,
            clock: None,
        },
        reader,
    )
    .unwrap();
    let replay = replay::spawn(
        click_track(if wall_stop_s.is_some() {
            seconds
        } else {
            seconds + 1.0
        }),
        ReplaySettings {
            speed,
            looped: false,
            duration_s: wall_stop_s.is_none().then_some(seconds),
        },
        writer,
        &ctx,
    )
    .unwrap();
    let started = std::time::Instant::now();
    let mut pending = controls;
    while !ctx.stop.load(Ordering::Relaxed) {
        std::thread::sleep(Duration::from_millis(5));
        let t = started.elapsed().as_secs_f64();
        pending.retain(|(at, c)| {
            if *at <= t {
                // Refusals are counted in the report, which the tests check.
                let _ = ctx_tx.send(c.clone());
                false
            } else {
                true
            }
        });
        if wall_stop_s.is_some_and(|w| t >= w) {
            ctx.stop.store(true, Ordering::Relaxed);
        }
        assert!(t < 30.0, "the replay never ended");
    }
    let horizon = pipeline.horizon_frames();
    let (report, _) = pipeline.stop().unwrap();
    replay.join().unwrap();
    let mut frames = Vec::new();
    let mut events = Vec::new();
    for item in rx.try_iter() {
        match item {
            SinkItem::Frame(f, at) => frames.push((f, at)),
            SinkItem::Event(e) => events.push(e),
        }
    }
    let seen = seen.lock().unwrap().clone();
    Run {
        report,
        frames,
        events,
        seen,
        horizon,
    }
}

fn hips_yaw(f: &BodyFrame) -> f32 {
    let hips = &f.bones[Joint::Hips.index()];
    assert_eq!(hips.bone, "Hips");
    // Unity mirrors x, so a yaw of a in our frame is −a there.
    let (axis, angle) = hips.local_rotation.to_axis_angle();
    angle * axis.y.signum()
}

#[test]
fn fast_replay_frames_beats_and_controls() {
    let speed = 4.0;
    let seconds = 16.0;
    let r = run(
        seconds,
        speed,
        vec![
            (1.5, ControlEvent::Temperature(0.8)),
            (1.6, ControlEvent::BeatAccent(0.4)),
            (
                2.0,
                ControlEvent::KeyPose {
                    name: "up".into(),
                    quantize: Quantize::NextBeat,
                },
            ),
            (
                2.2,
                ControlEvent::KeyPose {
                    name: "nope".into(),
                    quantize: Quantize::Now,
                },
            ),
        ],
    );
    // Frames at ~60 Hz of wall time, strictly increasing audio times and timetags.
    let wall = r.report.wall_s;
    let rate = r.frames.len() as f64 / wall;
    assert!((50.0..=62.0).contains(&rate), "{rate} Hz over {wall} s");
    for w in r.frames.windows(2) {
        assert!(w[1].0.audio_time_s > w[0].0.audio_time_s);
        assert!(w[1].0.timetag > w[0].0.timetag);
        assert_eq!(w[1].0.frame_index, w[0].0.frame_index + 1);
    }
    assert_eq!(r.frames[0].0.bones.len(), JOINT_COUNT);

    // Beats near the clicks once locked (after 4 s of audio).
    let beats: Vec<f64> = r
        .events
        .iter()
        .filter_map(|e| match e {
            AnalysisEvent::Beat { time_s, .. } => Some(*time_s),
            _ => None,
        })
        .filter(|t| *t > 4.0)
        .collect();
    assert!(beats.len() >= 12, "only {} beats after 4 s", beats.len());
    for b in &beats {
        let k = ((b - FIRST_CLICK_S) * BPM / 60.0).round();
        let click = FIRST_CLICK_S + k * 60.0 / BPM;
        assert!(
            (b - click).abs() < 0.07,
            "beat at {b:.3} s, click at {click:.3} s"
        );
    }
    assert!(
        r.events
            .iter()
            .any(|e| matches!(e, AnalysisEvent::Tempo { .. }))
    );

    // The temperature reached the dancer: the hips' yaw echoes it in the last frames.
    let last = &r.frames[r.frames.len() - 1].0;
    assert!(
        (hips_yaw(last).abs() - 0.8).abs() < 1e-3,
        "{}",
        hips_yaw(last)
    );
    let first = &r.frames[0].0;
    assert!((hips_yaw(first).abs() - 0.1).abs() < 1e-3);
    // So did the beat accent, which the first frames did not have.
    let spine_yaw = |f: &BodyFrame| {
        f.bones[Joint::Spine.index()]
            .local_rotation
            .to_axis_angle()
            .1
    };
    assert!((spine_yaw(last) - 0.4).abs() < 1e-3, "{}", spine_yaw(last));
    assert!(spine_yaw(first) < 1e-3);

    // The key pose counted down by one per frame to 0, on a click.
    let countdown: Vec<Seen> = r
        .seen
        .iter()
        .filter(|s| s.frames_to_go.is_some())
        .copied()
        .collect();
    assert!(!countdown.is_empty(), "no key pose reached the dancer");
    for w in countdown.windows(2) {
        assert_eq!(w[1].frames_to_go.unwrap() + 1, w[0].frames_to_go.unwrap());
        assert_eq!(w[1].step, w[0].step + 1);
    }
    let hit = countdown.last().unwrap();
    assert_eq!(hit.frames_to_go, Some(0));
    // Step s makes the pose of frame s + horizon: the first window is full once frame 2 (the
    // look-ahead) is analysed, and frames are predicted `horizon` ahead, look-ahead included.
    let t = (hit.step + r.horizon as u64) as f64 / FPS;
    let k = ((t - FIRST_CLICK_S) * BPM / 60.0).round();
    let click = FIRST_CLICK_S + k * 60.0 / BPM;
    assert!(
        (t - click).abs() < 0.07,
        "key pose at {t:.3} s, click at {click:.3} s"
    );
    assert_eq!(r.report.controls_accepted, 3);
    assert_eq!(r.report.controls_rejected, 1);
}

#[test]
fn real_time_run_has_no_drops_and_no_callback_allocations() {
    let r = run(3.0, 1.0, Vec::new());
    assert_eq!(r.report.drops, 0);
    // This file's allocator counts; the capture, analysis and motion loops allocate nothing
    // (the test sink clones every frame on the sender thread: `tests/realtime.rs` proves the
    // sender with the real OSC outputs).
    let a = r.report.allocations;
    assert_eq!((a.capture, a.analysis, a.motion), (0, 0, 0), "{a:?}");
    assert!(r.report.model_frames > 50);
    assert!(
        r.report.frames_sent > 120,
        "{} frames",
        r.report.frames_sent
    );
    // Only gross stalls: this runs beside the other pipelines of this file on a shared 2-core
    // machine, where their real-time sender threads compete; `danced bench live` measures jitter.
    assert!(r.report.jitter_ms_p99 < 20.0, "{}", r.report.jitter_ms_p99);
}

#[test]
fn bad_config_names_the_key() {
    use daemon::live::config::Config;
    let e = Config::parse("[audio]\nspeeed = 2.0\n", std::path::Path::new("bad.toml")).unwrap_err();
    let msg = e.to_string();
    assert!(msg.contains("speeed") && msg.contains("bad.toml"), "{msg}");
}

#[test]
fn keeps_dancing_when_the_audio_stops() {
    // 1 s of clicks at 4× (0.25 s of wall time), then nothing for 1.75 s.
    let r = run_until(1.0, 4.0, Vec::new(), Some(2.0));
    assert!(r.report.silence_frames > 0);
    let last = r.frames.last().unwrap().1;
    let first = r.frames[0].1;
    // Frames keep flowing at the full rate to the very end.
    let span = (last - first).as_secs_f64();
    assert!(span > 1.7, "frames stopped after {span:.2} s");
    let late_rate = r
        .frames
        .iter()
        .filter(|(_, at)| (*at - first).as_secs_f64() > 1.0)
        .count() as f64
        / (span - 1.0);
    assert!(late_rate > 50.0, "{late_rate} Hz without audio");
    assert!(
        r.seen.len() as f64 > 1.5 * FPS,
        "{} model frames",
        r.seen.len()
    );
}

/// Passes everything on, but blocks for `stall` on its first frame (a sender thread that
/// lost the CPU, a wedged network stack).
struct StallingSink {
    inner: ChannelSink,
    stall: Option<Duration>,
}

impl FrameSink for StallingSink {
    fn send_frame(&mut self, frame: &BodyFrame) {
        if let Some(d) = self.stall.take() {
            std::thread::sleep(d);
        }
        self.inner.send_frame(frame);
    }
    fn send_event(&mut self, event: &AnalysisEvent) {
        self.inner.send_event(event);
    }
    fn packets_sent(&self) -> u64 {
        self.inner.packets_sent()
    }
}

#[test]
fn a_stalled_sender_is_counted_and_its_full_pose_queue_too() {
    // 12 s of audio at 8×: 300 model frames in 1.5 s of wall time, while the sender is stuck
    // for 2 s in its first frame; the pose queue (256) overflows and the sender rejoins its
    // grid afterwards instead of bursting.
    let ctx = LiveContext::new();
    let (writer, reader) = ctx.ring();
    let (tx, rx): (_, Receiver<SinkItem>) = unbounded();
    let seen = Arc::new(Mutex::new(Vec::with_capacity(10_000)));
    let bank = MemoryPoseBank::new();
    let hub = ControlHub::new(&bank, ctx.stats.clone());
    let pipeline = Pipeline::start(
        &ctx,
        PipelineSettings {
            speed: 8.0,
            ..PipelineSettings::default()
        },
        PipelineParts {
            source: Box::new(EchoSource { steps: 0, seen }),
            sink: Box::new(StallingSink {
                inner: ChannelSink::new(tx),
                stall: Some(Duration::from_secs(2)),
            }),
            controls: hub,
            clock: None,
        },
        reader,
    )
    .unwrap();
    let replay = replay::spawn(
        click_track(12.0),
        ReplaySettings {
            speed: 8.0,
            looped: false,
            duration_s: Some(12.0),
        },
        writer,
        &ctx,
    )
    .unwrap();
    // Until the sender is back from its stall and has rejoined its grid, with a generous
    // deadline (the stall alone takes 2 s).
    let stats = &ctx.stats;
    testkit::wait_until(Duration::from_secs(30), || {
        stats.poses_dropped.load(Ordering::Relaxed) > 0
            && stats.sender_stalls.load(Ordering::Relaxed) >= 1
            && !rx.is_empty()
    });
    let (report, _) = pipeline.stop().unwrap();
    ctx.stop.store(true, Ordering::Relaxed);
    replay.join().unwrap();
    assert!(report.poses_dropped > 0, "{report:?}");
    assert!(report.sender_stalls >= 1, "{report:?}");
    assert!(rx.try_iter().count() > 0);
}
