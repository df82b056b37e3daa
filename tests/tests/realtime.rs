//! The proof behind "no allocation on the real-time path": a live run of the whole pipeline,
//! as `danced demo` runs it, with every output (native OSC, VMC with split bundles, VRChat
//! trackers) and OSC control traffic arriving on the control port, counted by a counting
//! global allocator per real-time thread. One test in this binary, so nothing else counts.

use std::net::{SocketAddr, UdpSocket};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::thread::JoinHandle;
use std::time::Duration;

use daemon::alloc_counter::{self, RtThread};
use daemon::live::config::Config;
use daemon::live::run::{AudioSource, RunMode, run_live};
use daemon::live::stats::{StatsReport, ThreadAllocations};
use rosc::{OscMessage, OscPacket, OscType};

#[global_allocator]
static ALLOCATOR: alloc_counter::CountingAllocator = alloc_counter::CountingAllocator;

/// Audio seconds of each run; the counted part (from the pipeline's start, after the
/// dancer has loaded) must last at least [`COUNTED_S`].
const RUN_S: f64 = 23.0;
/// Wall seconds the counted loops must have run.
const COUNTED_S: f64 = 20.0;

/// A UDP receiver counting datagrams on a thread of its own.
struct Receiver {
    addr: SocketAddr,
    datagrams: Arc<AtomicU64>,
    thread: JoinHandle<()>,
}

fn receiver(stop: &Arc<AtomicBool>) -> Receiver {
    let socket = UdpSocket::bind("127.0.0.1:0").unwrap();
    socket
        .set_read_timeout(Some(Duration::from_millis(50)))
        .unwrap();
    let addr = socket.local_addr().unwrap();
    let datagrams = Arc::new(AtomicU64::new(0));
    let (count, stop) = (datagrams.clone(), stop.clone());
    let thread = std::thread::spawn(move || {
        let mut buf = [0u8; 65_536];
        while !stop.load(Ordering::Relaxed) {
            if socket.recv(&mut buf).is_ok() {
                count.fetch_add(1, Ordering::Relaxed);
            }
        }
    });
    Receiver {
        addr,
        datagrams,
        thread,
    }
}

fn free_port() -> u16 {
    UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// A controller: every 40 ms a temperature or accent move, every second a key pose, every
/// 1.5 s a new seed, now and then a pause, a tempo hint, an unknown pose and garbage.
fn controller(port: u16, stop: Arc<AtomicBool>) -> JoinHandle<u64> {
    std::thread::spawn(move || {
        let socket = UdpSocket::bind("127.0.0.1:0").unwrap();
        let to = SocketAddr::from(([127, 0, 0, 1], port));
        let send = |addr: &str, args: Vec<OscType>| {
            let packet = OscPacket::Message(OscMessage {
                addr: format!("/danced/control/{addr}"),
                args,
            });
            let _ = socket.send_to(&rosc::encoder::encode(&packet).unwrap(), to);
        };
        let mut sent = 0u64;
        let mut i = 0u64;
        while !stop.load(Ordering::Relaxed) {
            std::thread::sleep(Duration::from_millis(40));
            i += 1;
            let x = (i % 50) as f32 / 50.0;
            send("temperature", vec![OscType::Float(0.2 + x)]);
            send("accent", vec![OscType::Float(0.5 * x)]);
            sent += 2;
            if i.is_multiple_of(25) {
                let pose = format!("pose-{}", 1 + (i / 25) % 16);
                let when = ["beat", "bar", "now"][(i / 25 % 3) as usize];
                send(
                    "keypose",
                    vec![OscType::String(pose), OscType::String(when.into())],
                );
                send("transition", vec![OscType::Float(1.0 + x)]);
                sent += 2;
            }
            if i.is_multiple_of(37) {
                send("seed", vec![OscType::Int(i as i32)]);
                send("tempo", vec![OscType::Float(120.0)]);
                send("keypose", vec![OscType::String("no-such-pose".into())]);
                let _ = socket.send_to(b"not osc", to);
                sent += 4;
            }
            if i.is_multiple_of(30) {
                // A switch of moves every 1.2 s, alternately on the next bar and beat.
                let which = (i / 30) % 2;
                let when = if which == 0 { "bar" } else { "beat" };
                send(
                    "moves",
                    vec![OscType::Int(which as i32), OscType::String(when.into())],
                );
                sent += 1;
            }
            // The clock: taps every 0.48 s (125 BPM), nudges, beat one, and the grid switched
            // between the tapped beats and the heard ones.
            if i.is_multiple_of(12) {
                send("tap", vec![]);
                sent += 1;
            }
            if i.is_multiple_of(75) {
                let ms = if (i / 75).is_multiple_of(2) {
                    5.0
                } else {
                    -5.0
                };
                send("clock/nudge", vec![OscType::Float(ms)]);
                send("clock/one", vec![]);
                sent += 2;
            }
            if i.is_multiple_of(125) {
                let which = if (i / 125) % 2 == 1 { "tap" } else { "audio" };
                send("clock", vec![OscType::String(which.into())]);
                sent += 1;
            }
            if i.is_multiple_of(150) {
                send("pause", vec![]);
                send("resume", vec![]);
                send("keypose/clear", vec![]);
                sent += 3;
            }
        }
        sent
    })
}

struct LiveRun {
    report: StatsReport,
    received: [u64; 3],
    control_sent: u64,
}

fn live_run(source: &'static str) -> JoinHandle<LiveRun> {
    std::thread::spawn(move || {
        let stop = Arc::new(AtomicBool::new(false));
        let receivers = [receiver(&stop), receiver(&stop), receiver(&stop)];
        let mut config = Config::default();
        config.output.osc = vec![receivers[0].addr.to_string()];
        config.output.vmc.target = receivers[1].addr.to_string();
        config.output.vmc.split_bundles = true;
        config.output.vrchat.enabled = true;
        config.output.vrchat.target = receivers[2].addr.to_string();
        config.control.osc_port = free_port();
        config.audio.duration = Some(RUN_S);
        config.dancer.source = source.into();
        if source == "retrieval" {
            // Two libraries, so the switches of moves run on the motion thread too.
            let clips = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("../configs/clips/tang2018-train.danclips");
            config.dancer.libraries = ["first", "second"]
                .map(|name| daemon::dancer::LibraryChoice {
                    path: clips.clone(),
                    name: Some(name.into()),
                })
                .to_vec();
        }
        // The smallest stage, so its steering, glide and clamp all run on the motion thread.
        config.stage.radius_m = model::stage::MIN_RADIUS_M;
        // The browser view too: the sender hands it every frame and event.
        config.view.enabled = true;
        config.view.addr = "127.0.0.1:0".into();
        let control = controller(config.control.osc_port, stop.clone());
        let report = run_live(&config, AudioSource::Demo, RunMode::Quiet).unwrap();
        stop.store(true, Ordering::Relaxed);
        let control_sent = control.join().unwrap();
        let received = receivers.map(|r| {
            r.thread.join().unwrap();
            r.datagrams.load(Ordering::Relaxed)
        });
        LiveRun {
            report,
            received,
            control_sent,
        }
    })
}

#[test]
fn no_real_time_thread_allocates_in_a_live_run_with_every_output_and_control_traffic() {
    alloc_counter::mark_installed();
    // First: the counter counts. A deliberate allocation in each thread's role is seen.
    let before = ThreadAllocations::now();
    for role in [
        RtThread::Capture,
        RtThread::Analysis,
        RtThread::Motion,
        RtThread::Sender,
        RtThread::ClockOut,
    ] {
        alloc_counter::counted(role, || {
            std::hint::black_box(Vec::<u8>::with_capacity(10));
        });
    }
    // Allocations outside a counted region are not counted.
    std::hint::black_box(Vec::<u8>::with_capacity(10));
    let after = ThreadAllocations::now();
    for (b, a) in [
        (before.capture, after.capture),
        (before.analysis, after.analysis),
        (before.motion, after.motion),
        (before.sender, after.sender),
        (before.clock_out, after.clock_out),
    ] {
        assert_eq!(a - b, 2, "one allocation and its free, counted once each");
    }

    // Then: two live runs at once, the neural and the retrieval dancer, over 20 s each, and
    // beside them the MIDI clock sender ticking for 3 s (into a recorder: no MIDI port here).
    let handles = [live_run("neural"), live_run("retrieval")];
    let ticking = daemon::bench::clock::midi_clock_out(150.0, 3.0, false).unwrap();
    assert!(ticking.ticks >= 150, "{ticking:?}");
    let runs = handles.map(|h| h.join().unwrap());
    let counted = ThreadAllocations::now();
    let during = ThreadAllocations {
        capture: counted.capture - after.capture,
        analysis: counted.analysis - after.analysis,
        motion: counted.motion - after.motion,
        sender: counted.sender - after.sender,
        clock_out: counted.clock_out - after.clock_out,
    };
    for (run, source) in runs.iter().zip(["neural", "retrieval"]) {
        let r = &run.report;
        // The report carries the same per-thread counts (process-wide, so they include the
        // deliberate allocations above).
        assert_eq!(
            r.allocations.total() - after.total(),
            0,
            "{:?}",
            r.allocations
        );
        assert!(r.allocation_counting);
        assert!(
            r.wall_s >= COUNTED_S && r.frames_sent as f64 > 55.0 * (r.wall_s - 1.0),
            "{} frames in {:.1} s",
            r.frames_sent,
            r.wall_s
        );
        assert!(
            r.model_frames as f64 > 20.0 * (r.wall_s - 1.0),
            "{} steps",
            r.model_frames
        );
        // Every output got datagrams: native bundles and events, VMC split into several
        // bundles a frame, VRChat one message per tracker and value.
        assert!(run.received[0] > r.frames_sent, "native {:?}", run.received);
        assert!(
            run.received[1] >= 2 * r.frames_sent,
            "vmc {:?}",
            run.received
        );
        assert!(
            run.received[2] > 10 * r.frames_sent,
            "vrchat {:?}",
            run.received
        );
        // The neural dancer's safety nets are reported (the retrieval dancer has none).
        match (source, r.safety_nets) {
            ("neural", Some(c)) => assert!(c.frames as f64 > 20.0 * (r.wall_s - 1.0), "{c:?}"),
            ("retrieval", None) => {}
            (s, c) => panic!("{s}: safety nets {c:?}"),
        }
        // The retrieval dancer switched its moves; the neural one refused, counted.
        match source {
            "retrieval" => assert!(
                r.moves_switches >= 5 && r.moves.is_some(),
                "{:?} {}",
                r.moves,
                r.moves_switches
            ),
            _ => assert!(r.controls_unsupported > 0 && r.moves.is_none(), "{r:?}"),
        }
        // The stage placed every frame, and had to work at it.
        let stage = r.stage.expect("the stage reports");
        assert!(stage.frames as f64 > 20.0 * (r.wall_s - 1.0), "{stage:?}");
        assert!(stage.steered > 0 && stage.glided > 0, "{stage:?}");
        // The view took the frames (no browser connected: taken from the slot, not sent).
        let view = r.view.expect("the view ran");
        assert_eq!(view.events_dropped, 0, "{view:?}");
        // The clock controls reached the grid: a tapped tempo followed at times.
        assert!(r.clock.tempo_bpm > 0.0, "{:?}", r.clock);
        // The control traffic went through the real path.
        assert!(r.osc_control_accepted > run.control_sent / 2, "{r:?}");
        assert!(
            r.controls_accepted > 100 && r.controls_rejected > 0,
            "{r:?}"
        );
        assert_eq!(
            (
                r.drops,
                r.features_dropped,
                r.anchors_dropped,
                r.poses_dropped
            ),
            (0, 0, 0, 0),
            "{r:?}"
        );
    }
    assert_eq!(
        during,
        ThreadAllocations::default(),
        "allocations during the runs"
    );
}
