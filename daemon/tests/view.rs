//! The browser view with a real browser (Debian's headless Chromium, WebGL through SwiftShader):
//! the page loads from danced alone, frames arrive, key-pose buttons reach the dancer through
//! the control path, and the VRM avatar's bones land where our forward kinematics puts them —
//! which checks our VMC convention on a real VRM loaded by three-vrm.

use std::path::PathBuf;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use daemon::live::clock::{ClockDesk, ClockSettings, ClockSource, ClockWiring};
use daemon::live::context::LiveContext;
use daemon::live::control_queue::ControlHub;
use daemon::live::pipeline::{Pipeline, PipelineParts, PipelineSettings};
use daemon::live::replay::{self, ReplayAudio, ReplaySettings};
use daemon::live::sink::{MemoryPoseBank, PoseBank};
use daemon::view::assets::Assets;
use daemon::view::{LiveFeed, ViewHello, ViewServer};
use dsp::feature::FEATURE_DIM;
use glam::Vec3;
use model::rig::{JOINT_COUNT, Joint, Pose, Skeleton};
use model::source::{Controls, MotionSource};

mod browser;
mod common;

/// Where the test dancer keeps its hips: off the origin, so the hips' travel is checked too.
const ROOT: Vec3 = Vec3::new(0.21, 0.93, -0.17);
/// The bones compared (the list: shoulders, elbows, wrists, hips, knees, ankles, head).
const BONES: [Joint; 13] = [
    Joint::Hips,
    Joint::Head,
    Joint::LeftUpperArm,
    Joint::RightUpperArm,
    Joint::LeftLowerArm,
    Joint::RightLowerArm,
    Joint::LeftHand,
    Joint::RightHand,
    Joint::LeftLowerLeg,
    Joint::RightLowerLeg,
    Joint::LeftFoot,
    Joint::RightFoot,
    Joint::LeftUpperLeg,
];
/// Largest distance allowed between our FK and the VRM's bone, metres.
const TOLERANCE_M: f32 = 0.02;

/// Takes the key pose it is asked for at once and holds it (so the page can be read at rest).
struct PoseHolder {
    pose: Pose,
}

impl MotionSource for PoseHolder {
    fn frame_rate(&self) -> f64 {
        25.0
    }
    fn lookahead_frames(&self) -> usize {
        0
    }
    fn step(&mut self, _music: &[[f32; FEATURE_DIM]], controls: &Controls, out: &mut Pose) {
        if let Some(k) = controls.key_pose {
            self.pose.local_rotations = k.rotations;
        }
        self.pose.root_position = ROOT;
        *out = self.pose;
    }
    fn reset(&mut self, _seed: u64) {}
    fn reseed(&mut self, _seed: u64) {}
}

fn expected(rotations: &[glam::Quat; JOINT_COUNT]) -> [Vec3; JOINT_COUNT] {
    let pose = Pose {
        root_position: ROOT,
        local_rotations: *rotations,
    };
    let mut out = [Vec3::ZERO; JOINT_COUNT];
    Skeleton::default_adult().world_positions(&pose, &mut out);
    out
}

fn target_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../target")
}

#[test]
fn the_page_shows_the_live_dancer_on_a_vrm_where_our_kinematics_puts_it() {
    if !browser::require_chromium() {
        return;
    }
    // The bank: the T-pose, arms up and three poses of the shipped bank.
    let builtin = MemoryPoseBank::builtin();
    let shipped = daemon::pose_bank::PoseBank::shipped().unwrap();
    let mut bank = MemoryPoseBank::new();
    for name in ["tpose", "arms_up"] {
        bank.insert(name, builtin.get(name).unwrap());
    }
    for name in ["pose-2", "pose-7", "pose-12"] {
        bank.insert(name, PoseBank::get(&shipped, name).unwrap());
    }

    let ctx = LiveContext::new();
    let (writer, reader) = ctx.ring();
    let moves = vec!["first".to_string(), "second".to_string()];
    let (desk, clock_feed) = ClockDesk::new(ClockSettings::default(), ctx.epoch);
    let mut hub = ControlHub::new(&bank, ctx.stats.clone())
        .with_moves(moves.clone())
        .with_clock(desk);
    let poses = hub.pose_names();
    let feed = LiveFeed {
        stats: ctx.stats.clone(),
        controls: hub.sender(),
    };
    let hello = ViewHello {
        mode: "live",
        dancer: "pose holder".into(),
        poses: poses.clone(),
        rate_hz: 60.0,
        model_rate_hz: 25.0,
        moves,
        clocks: vec!["audio", "tap"],
        ..ViewHello::default()
    };
    let (server, sink) = ViewServer::start(
        "127.0.0.1:0",
        Assets::page(&Skeleton::default_adult()),
        hello,
        Some(feed),
        ctx.stop.clone(),
    )
    .unwrap();
    let pipeline = Pipeline::start(
        &ctx,
        PipelineSettings {
            realtime: false,
            ..PipelineSettings::default()
        },
        PipelineParts {
            source: Box::new(PoseHolder { pose: Pose::rest() }),
            sink: Box::new(sink.unwrap()),
            controls: hub,
            clock: Some(ClockWiring {
                feed: clock_feed,
                led: Vec::new(),
            }),
        },
        reader,
    )
    .unwrap();
    let replay = replay::spawn(
        ReplayAudio::demo(60.0),
        ReplaySettings {
            speed: 1.0,
            looped: true,
            duration_s: None,
        },
        writer,
        &ctx,
    )
    .unwrap();

    let started = Instant::now();
    let chrome = browser::Browser::launch(800, 600).unwrap();
    let page = chrome.open(&server.url()).unwrap();
    let ready = page.wait_for(
        "window.danced && window.danced.ready && window.danced.socketOpen \
         && window.danced.framesApplied > 10 && window.danced.webgl",
        Duration::from_secs(30),
    );
    assert!(ready.is_ok(), "{ready:?}\nconsole: {:?}", page.console());
    eprintln!(
        "page up with frames after {:.1} s",
        started.elapsed().as_secs_f64()
    );
    let webgl = page.eval("window.danced.webgl").unwrap();
    assert!(
        webgl["version"].as_str().unwrap_or("").contains("WebGL 2"),
        "{webgl}"
    );

    // Frames per second as received by the page.
    let count = || {
        page.eval("window.danced.framesReceived")
            .unwrap()
            .as_f64()
            .unwrap()
    };
    // Over the time 120 frames take to come (2 s at 60 Hz), waited for with a deadline.
    let (n0, t0) = (count(), Instant::now());
    let mut n = n0;
    testkit::wait_until(Duration::from_secs(30), || {
        n = count();
        n - n0 >= 120.0
    });
    let fps = (n - n0) / t0.elapsed().as_secs_f64();
    eprintln!("frames received by the page: {fps:.1}/s");
    assert!(fps >= 30.0, "{fps:.1} frames/s");

    // Every pose through the page's own button, as a performer would press it.
    let mut worst = 0.0f32;
    for pose in ["arms_up", "pose-2", "pose-7", "pose-12", "tpose"] {
        let pressed = page
            .eval(&format!(
                "document.getElementById('quantize').value = 'now'; \
                 [...document.querySelectorAll('#poses button')] \
                   .find((b) => b.textContent === '{pose}').click(); true"
            ))
            .unwrap();
        assert_eq!(pressed, serde_json::Value::Bool(true));
        let want = expected(&bank.get(pose).unwrap());
        // The pose lands within a second or so (the control path, a model frame, the 60 Hz
        // interpolation); then the page must hold it within the tolerance.
        worst = worst.max(wait_for_pose(&page, pose, &want));
    }
    eprintln!(
        "worst bone error over the five poses: {:.3} cm",
        worst * 100.0
    );

    // The HUD: the key pose is reported reached by name, beats flash, the status comes in.
    let hud = page.wait_for(
        "window.danced.status && window.danced.status.key_pose === 'reached' \
         && window.danced.status.key_pose_name === 'tpose' && window.danced.beats > 0 \
         && window.danced.status.frames_sent > 0 \
         && document.getElementById('key').textContent === 'tpose reached'",
        Duration::from_secs(15),
    );
    assert!(
        hud.is_ok(),
        "{hud:?} status {:?}",
        page.eval("[window.danced.status, window.danced.beats]")
    );

    // The style selector, as a performer would change it.
    let chosen = page
        .eval(
            "const s = document.getElementById('styleSelect'); s.value = 'rumba'; \
             s.dispatchEvent(new Event('change')); true",
        )
        .unwrap();
    assert_eq!(chosen, serde_json::Value::Bool(true));
    // And the key route's (the pose holder has none to switch: it is only counted).
    let routed = page
        .eval(
            "const r = document.getElementById('routeSelect'); r.value = 'network'; \
             r.dispatchEvent(new Event('change')); true",
        )
        .unwrap();
    assert_eq!(routed, serde_json::Value::Bool(true));
    // And the moves: offered (two sets), switched on the next bar.
    let moved = page
        .eval(
            "const m = document.getElementById('movesSelect');              const shown = !document.body.classList.contains('no-moves') && m.options.length === 2;              m.value = 'second'; m.dispatchEvent(new Event('change')); shown",
        )
        .unwrap();
    assert_eq!(moved, serde_json::Value::Bool(true));
    testkit::wait_until(Duration::from_secs(20), || {
        ctx.stats.controls_accepted.load(Ordering::Relaxed) >= 8
    });

    // The presses went through the control path (validated and counted like OSC's).
    let applied = ctx.stats.controls_accepted.load(Ordering::Relaxed);
    assert_eq!(applied, 8, "controls applied");
    assert_eq!(server.report().controls_accepted, 8);
    assert_eq!(server.report().controls_ignored, 0);

    // The clock: four taps 0.4 s apart (150 BPM), the tap clock chosen, beat one, a nudge
    // later; the HUD names the clock followed.
    page.eval(
        "(async () => { const t = document.getElementById('tap'); \
           for (let i = 0; i < 4; i++) { t.dispatchEvent(new Event('pointerdown')); \
             await new Promise((r) => setTimeout(r, 400)); } \
           const c = document.getElementById('clockSelect'); c.value = 'tap'; \
           c.dispatchEvent(new Event('change')); \
           document.getElementById('one').click(); document.getElementById('later').click(); })(); true",
    )
    .unwrap();
    let followed = testkit::wait_until(Duration::from_secs(20), || {
        let c = &ctx.stats.clock;
        c.source() == ClockSource::Tap
            && c.nudge_ms.get() == 10.0
            && (c.tempo_bpm.get() - 150.0).abs() < 3.0
    });
    assert!(followed, "{:?}", ctx.stats.clock.report());
    let hud = page.wait_for(
        "document.getElementById('clock').textContent.startsWith('tap 1') \
         && document.getElementById('clock').textContent.includes('nudged +10 ms') \
         && document.getElementById('clockSelect').options.length === 2",
        Duration::from_secs(10),
    );
    assert!(
        hud.is_ok(),
        "{:?}",
        page.eval("document.getElementById('clock').textContent")
    );

    let png = page.screenshot_png().unwrap();
    assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n");
    let shot = target_dir().join("view-test.png");
    std::fs::write(&shot, &png).unwrap();
    eprintln!("screenshot: {}", shot.display());

    // Nothing but loopback was asked for.
    let requests = page.requests();
    assert!(
        requests.iter().any(|r| r.ends_with("/vendor.js")),
        "{requests:?}"
    );
    for r in &requests {
        assert!(
            r.starts_with("http://127.0.0.1:") || r.starts_with("blob:") || r.starts_with("data:"),
            "the page asked for {r}"
        );
    }
    let errors = page.eval("window.danced.errors").unwrap();
    assert_eq!(errors, serde_json::json!([]), "page errors");

    drop(page);
    drop(chrome);
    let (report, _) = pipeline.stop().unwrap();
    let view = server.stop();
    let _ = replay.join();
    eprintln!("{view:?}");
    assert_eq!(view.clients_accepted, 1);
    assert_eq!(view.clients_dropped_slow, 0);
    assert!(view.frames_forwarded as f64 > 0.5 * report.frames_sent as f64);
}

/// Polls the page until its bones are within [`TOLERANCE_M`] of `want` (5 s at most), prints
/// the conformance table and asserts; returns the largest error, metres.
/// The view's URL as `what` (a spawned danced with its stderr piped) prints it, and that
/// stderr, to keep open while the child runs (closed, its next line would kill it).
fn printed_url(
    child: &mut std::process::Child,
    what: &str,
) -> (String, std::io::BufReader<std::process::ChildStderr>) {
    let mut stderr = std::io::BufReader::new(child.stderr.take().unwrap());
    let mut line = String::new();
    loop {
        line.clear();
        assert!(
            std::io::BufRead::read_line(&mut stderr, &mut line).unwrap() > 0,
            "{what} printed no URL"
        );
        if let Some(at) = line.find("http://") {
            return (
                line[at..].split_whitespace().next().unwrap().to_string(),
                stderr,
            );
        }
    }
}

fn wait_for_pose(page: &browser::Page, pose: &str, want: &[Vec3; JOINT_COUNT]) -> f32 {
    let names: Vec<String> = BONES.iter().map(|j| j.name().to_string()).collect();
    let names_js = serde_json::to_string(&names).unwrap();
    let deadline = Instant::now() + Duration::from_secs(5);
    let mut table = Vec::new();
    loop {
        let got = page
            .eval(&format!("window.danced.boneWorldPositions({names_js})"))
            .unwrap();
        table.clear();
        for j in BONES {
            let v = &got[j.name()];
            let c = |i: usize| v[i].as_f64().unwrap_or(f64::NAN) as f32;
            let vrm = Vec3::new(c(0), c(1), c(2));
            let ours = want[j.index()];
            let err = ours.distance(vrm);
            table.push((
                j,
                ours,
                vrm,
                if err.is_finite() { err } else { f32::INFINITY },
            ));
        }
        let max = table.iter().map(|r| r.3).fold(0.0f32, f32::max);
        if max <= TOLERANCE_M || Instant::now() > deadline {
            break;
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    eprintln!("{pose}: | bone | our FK (m) | VRM (m) | error (mm) |");
    for (j, ours, vrm, err) in &table {
        eprintln!(
            "| {j} | {:.3} {:.3} {:.3} | {:.3} {:.3} {:.3} | {:.3} |",
            ours.x,
            ours.y,
            ours.z,
            vrm.x,
            vrm.y,
            vrm.z,
            err * 1000.0
        );
    }
    let max = table.iter().map(|r| r.3).fold(0.0f32, f32::max);
    assert!(
        max <= TOLERANCE_M,
        "{pose}: a bone is {:.1} cm from our FK",
        max * 100.0
    );
    max
}

#[test]
fn danced_view_plays_a_dance_file_with_its_song() {
    if !browser::require_chromium() {
        return;
    }
    // Three seconds of one held pose, off the origin, and a click track to go with it.
    let dir = common::scratch("view-playback");
    let shipped = daemon::pose_bank::PoseBank::shipped().unwrap();
    let pose = Pose {
        root_position: ROOT,
        local_rotations: PoseBank::get(&shipped, "pose-7").unwrap(),
    };
    let skeleton = Skeleton::default_adult();
    let bvh = dir.join("held.bvh");
    model::bvh::export(&skeleton, &[pose; 75], 25.0)
        .write(&bvh)
        .unwrap();
    let song = dir.join("clicks.wav");
    let (samples, _) = common::click_track(3.0, 120.0, 0.25, 44_100);
    common::write_wav(&song, &samples, 44_100, 2);
    let mut child = common::danced()
        .args([
            "view",
            bvh.to_str().unwrap(),
            "--audio",
            song.to_str().unwrap(),
        ])
        .args(["--addr", "127.0.0.1:0", "--duration", "60"])
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let (url, _stderr) = printed_url(&mut child, "danced view");
    let chrome = browser::Browser::launch(640, 480).unwrap();
    let page = chrome.open(&url).unwrap();
    let playing = page.wait_for(
        "window.danced && window.danced.ready && window.danced.playbackFrames \
         && window.danced.framesApplied > 0 && window.danced.playbackTime > 0.5",
        Duration::from_secs(30),
    );
    assert!(
        playing.is_ok(),
        "{playing:?}\nconsole: {:?}",
        page.console()
    );
    // 3 s at the view's 60 frames a second.
    assert_eq!(page.eval("window.danced.playbackFrames").unwrap(), 180);
    assert_eq!(page.eval("window.danced.hello.audio").unwrap(), true);
    let requests = page.requests();
    assert!(
        requests.iter().any(|r| r.ends_with("/audio")),
        "{requests:?}"
    );
    assert!(
        requests.iter().any(|r| r.ends_with("/dance.vmc")),
        "{requests:?}"
    );
    eprintln!(
        "audio clock in the page: {}",
        page.eval("window.danced.audioTime").unwrap()
    );
    // The file as danced reads it: the held pose, put on the floor (ROOT floats it).
    let read = offline::moves::read_dance(&bvh, &Default::default()).unwrap();
    assert!(
        (read.poses[0].root_position - pose.root_position - Vec3::Y * read.floor_shift_m).length()
            < 1e-3
    );
    let mut want = [Vec3::ZERO; JOINT_COUNT];
    skeleton.world_positions(&read.poses[0], &mut want);
    wait_for_pose(&page, "pose-7 from the file", &want);
    drop(page);
    drop(chrome);
    let _ = child.kill();
    let _ = child.wait();
}

/// `danced demo --view` on its default stage: the whole mannequin is in the picture at every
/// look, every 5 s (30 s here; `DANCED_FRAMING_S` sets a longer watch).
#[test]
fn the_demo_keeps_the_whole_mannequin_in_the_picture() {
    if !browser::require_chromium() {
        return;
    }
    let watch_s: u64 = std::env::var("DANCED_FRAMING_S")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(30);
    let mut child = common::danced()
        .args(["demo", "--view", "127.0.0.1:0", "--duration"])
        .arg((watch_s + 30).to_string())
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let (url, _stderr) = printed_url(&mut child, "danced demo");
    let chrome = browser::Browser::launch(800, 600).unwrap();
    let page = chrome.open(&url).unwrap();
    let ready = page.wait_for(
        "window.danced && window.danced.ready && window.danced.framesApplied > 10",
        Duration::from_secs(30),
    );
    assert!(ready.is_ok(), "{ready:?}\nconsole: {:?}", page.console());
    let stage = page.eval("window.danced.stage").unwrap();
    assert_eq!(stage["mode"], "bounded", "{stage}");
    let dir = target_dir();
    let start = Instant::now();
    let mut looks = 0;
    while looks * 5 <= watch_s {
        let at = Duration::from_secs(looks * 5);
        // Poll to the moment of the look (the page renders on its own meanwhile).
        testkit::wait_until(
            at.saturating_sub(start.elapsed()) + Duration::from_millis(10),
            || start.elapsed() >= at,
        );
        let framing = page.eval("window.danced.framing()").unwrap();
        let png = page.screenshot_png().unwrap();
        let shot = dir.join(format!("view-framing-{:02}s.png", looks * 5));
        std::fs::write(&shot, &png).unwrap();
        assert_eq!(
            framing["inside"],
            serde_json::Value::Bool(true),
            "at {} s the mannequin leaves the picture: {framing} ({})",
            looks * 5,
            shot.display()
        );
        looks += 1;
    }
    eprintln!(
        "{looks} looks, the last: {}",
        dir.join(format!("view-framing-{:02}s.png", (looks - 1) * 5))
            .display()
    );
    child.kill().ok();
    child.wait().ok();
}
