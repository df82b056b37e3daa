//! Following an external clock, end to end in process: a click track replayed through the live
//! pipeline while a MIDI clock (stamped on a driver clock of its own, with a millisecond of
//! jitter) comes in through the MIDI map, as the MIDI thread feeds it; `/danced/beat` received
//! over OSC on a local socket must land on the clock's beats, not the heard ones.

use std::net::UdpSocket;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use daemon::live::clock::{ClockDesk, ClockSettings, ClockSource, ClockWiring, MidiClockInput};
use daemon::live::config::Config;
use daemon::live::context::LiveContext;
use daemon::live::control_queue::ControlHub;
use daemon::live::io::OscSink;
use daemon::live::pipeline::{Pipeline, PipelineParts, PipelineSettings};
use daemon::live::replay::{self, ReplayAudio, ReplaySettings};
use daemon::live::sink::MemoryPoseBank;
use daemon::live::wire::ControlEvent;
use protocols::{MidiMap, MidiMessage};

#[global_allocator]
static ALLOCATOR: daemon::alloc_counter::CountingAllocator =
    daemon::alloc_counter::CountingAllocator;

const RATE: u32 = 44_100;
const CLICK_BPM: f64 = 120.0;

/// A tiny deterministic generator for the stamps' jitter.
fn lcg(state: &mut u64) -> f64 {
    *state = state
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    (*state >> 11) as f64 / (1u64 << 53) as f64
}

/// Beats the clock plays: (time on the run's clock µs, position in the bar).
type Beats = Vec<(f64, u32)>;

/// What came back.
struct Followed {
    /// Every `/danced/beat`: arrival on the run's clock (µs) and its place in the bar.
    received: Vec<(f64, u32)>,
    /// The clock's true beats.
    truth: Beats,
    /// The run's clock summary.
    report: daemon::live::stats::ClockReport,
    /// When the replay's first sample was heard, on the run's clock (µs).
    origin_us: f64,
}

/// How the clock plays.
struct Clock<'a> {
    /// (from beat, BPM), in order.
    tempi: &'a [(u32, f64)],
    /// When Start's first beat falls, µs on the run's clock.
    start_us: f64,
    /// Trim the clock toward the beats heard.
    trim: bool,
}

impl<'a> Clock<'a> {
    fn at(tempi: &'a [(u32, f64)]) -> Self {
        Clock {
            tempi,
            start_us: 1e6,
            trim: false,
        }
    }
}

/// Replays `seconds` of clicks (120 BPM, the first at 0.25 s) while a MIDI clock plays;
/// `controls` go through the control path at wall offsets.
fn follow(seconds: f64, clock: Clock<'_>, controls: Vec<(f64, ControlEvent)>) -> Followed {
    let ctx = LiveContext::new();
    let (writer, reader) = ctx.ring();
    let socket = UdpSocket::bind("127.0.0.1:0").unwrap();
    socket
        .set_read_timeout(Some(Duration::from_millis(5)))
        .unwrap();
    let mut config = Config::default();
    config.output.osc = vec![socket.local_addr().unwrap().to_string()];
    let sink = OscSink::from_config(&config).unwrap();
    let (desk, feed) = ClockDesk::new(
        ClockSettings {
            source: ClockSource::Midi,
            midi: true,
            trim: clock.trim,
            ..ClockSettings::default()
        },
        ctx.epoch,
    );
    let mut hub =
        ControlHub::new(&MemoryPoseBank::new(), ctx.stats.clone()).with_clock(desk.clone());
    let mut control = hub.sender();
    let pipeline = Pipeline::start(
        &ctx,
        PipelineSettings::default(),
        PipelineParts {
            source: Box::new(model::source::Standing),
            sink: Box::new(sink),
            controls: hub,
            clock: Some(ClockWiring {
                feed,
                led: Vec::new(),
            }),
        },
        reader,
    )
    .unwrap();
    let (samples, _) = daemon::demo_track::click_track(seconds + 1.0, CLICK_BPM, 0.25, RATE);
    let replay = replay::spawn(
        ReplayAudio {
            samples,
            sample_rate: RATE,
            channels: 2,
            name: "clicks".into(),
        },
        ReplaySettings {
            speed: 1.0,
            looped: false,
            duration_s: Some(seconds),
        },
        writer,
        &ctx,
    )
    .unwrap();
    // The MIDI clock: ticks on a driver clock 5 s ahead of the run's, each stamp ±1 ms off.
    let done = Arc::new(AtomicBool::new(false));
    let clock_thread = {
        let (desk, done, tempi) = (desk.clone(), done.clone(), clock.tempi.to_vec());
        let start = clock.start_us;
        let epoch = ctx.epoch;
        std::thread::spawn(move || {
            let mut map = MidiMap::from_toml_str("").unwrap();
            let mut input = MidiClockInput::new(4);
            let mut events = Vec::new();
            let mut rng = 17u64;
            let now_us = || epoch.elapsed().as_secs_f64() * 1e6;
            let stamp = |t: f64, rng: &mut u64| (t + 5e6 + (lcg(rng) * 2.0 - 1.0) * 1e3) as u64;
            let mut truth = Vec::new();
            let (mut t, mut tick) = (start, 0u32);
            while now_us() < start - 5e3 {
                std::thread::sleep(Duration::from_millis(1));
            }
            let s = stamp(start - 5e3, &mut rng);
            map.map_at(s, &MidiMessage::Start, &mut events);
            input.packet(&map, 0xfa, s, &desk);
            while !done.load(Ordering::Relaxed) {
                let beat = tick / 24;
                let bpm = tempi
                    .iter()
                    .rev()
                    .find(|(from, _)| *from <= beat)
                    .map_or(120.0, |&(_, b)| b);
                if tick.is_multiple_of(24) {
                    truth.push((t, beat % 4 + 1));
                }
                while now_us() < t {
                    std::thread::sleep(Duration::from_micros(200));
                }
                let s = stamp(t, &mut rng);
                map.map_at(s, &MidiMessage::Clock, &mut events);
                input.packet(&map, 0xf8, s, &desk);
                t += 60e6 / bpm / 24.0;
                tick += 1;
            }
            truth
        })
    };
    let started = Instant::now();
    let mut received = Vec::new();
    let mut buf = [0u8; 1536];
    let mut pending = controls;
    while !ctx.stopped() {
        let elapsed = started.elapsed().as_secs_f64();
        assert!(elapsed < seconds + 20.0, "the replay never ended");
        pending.retain(|(at, c)| {
            if *at <= elapsed {
                control.send(c.clone()).unwrap();
                false
            } else {
                true
            }
        });
        let Ok(n) = socket.recv(&mut buf) else {
            continue;
        };
        let arrived = ctx.epoch.elapsed().as_secs_f64() * 1e6;
        let Ok((_, rosc::OscPacket::Message(m))) = rosc::decoder::decode_udp(&buf[..n]) else {
            continue;
        };
        if m.addr == "/danced/beat"
            && let Some(rosc::OscType::Int(index)) = m.args.first()
        {
            received.push((arrived, *index as u32));
        }
    }
    let (report, _) = pipeline.stop().unwrap();
    let origin_us = ctx.stats.replay_origin_ns.load(Ordering::Relaxed) as f64 * 1e-3;
    replay.join().unwrap();
    done.store(true, Ordering::Relaxed);
    let truth = clock_thread.join().unwrap();
    Followed {
        received,
        truth,
        report: report.clock,
        origin_us,
    }
}

/// For each received beat after `from_us`: its offset from the nearest true beat (µs) and
/// whether its place in the bar is that beat's.
fn offsets(f: &Followed, from_us: f64, to_us: f64) -> Vec<(f64, bool)> {
    f.received
        .iter()
        .filter(|(t, _)| (from_us..to_us).contains(t))
        .filter_map(|&(t, index)| {
            let nearest = f
                .truth
                .iter()
                .min_by(|a, b| (a.0 - t).abs().total_cmp(&(b.0 - t).abs()))?;
            Some((t - nearest.0, nearest.1 == index))
        })
        .collect()
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

#[test]
fn beats_follow_a_midi_clock_and_its_bar_not_the_music_heard() {
    // The clicks are at 120 BPM; the clock plays 128, then 140 from its 16th beat.
    let f = follow(12.0, Clock::at(&[(0, 128.0), (16, 140.0)]), Vec::new());
    let change_us = f.truth[16].0;
    let steady = offsets(&f, 3e6, change_us);
    assert!(
        steady.len() >= 8,
        "{} beats before the change",
        steady.len()
    );
    let m = median(steady.iter().map(|o| o.0.abs()).collect());
    eprintln!(
        "128 BPM: median |offset| {:.2} ms over {} beats",
        m * 1e-3,
        steady.len()
    );
    assert!(
        m < 5_000.0,
        "beats {:.1} ms from the clock's (median)",
        m * 1e-3
    );
    assert!(
        steady.iter().all(|o| o.1),
        "the bar is the clock's: {steady:?}"
    );
    // One beat after the change, the beats are the new tempo's.
    let after = offsets(&f, f.truth[17].0 - 20_000.0, f64::INFINITY);
    assert!(after.len() >= 8, "{} beats after the change", after.len());
    let worst = after.iter().map(|o| o.0.abs()).fold(0.0, f64::max);
    eprintln!(
        "140 BPM from one beat after the change: worst |offset| {:.2} ms",
        worst * 1e-3
    );
    assert!(
        worst < 10_000.0,
        "a beat {:.1} ms off after the change",
        worst * 1e-3
    );
    assert!(after.iter().all(|o| o.1));
    assert_eq!(f.report.source, "midi");
    assert!(
        (f.report.tempo_bpm - 140.0).abs() < 0.2,
        "{}",
        f.report.tempo_bpm
    );
    assert_eq!(
        f.report.offset_ms, None,
        "the heard 120 BPM is not the clock's tempo"
    );
}

#[test]
fn nudge_and_beat_one_move_the_followed_clock() {
    // The clock at 120 BPM; at 4.1 s "beat one" (the beat nearest is the clock's beat 13, its
    // bar's second), at 6 s a nudge of 30 ms later.
    let f = follow(
        9.0,
        Clock::at(&[(0, 120.0)]),
        vec![
            (4.1, ControlEvent::BeatOne),
            (6.0, ControlEvent::Nudge(30.0)),
        ],
    );
    let before = offsets(&f, 2.5e6, 4.0e6);
    assert!(before.iter().all(|o| o.1), "before: the clock's bar");
    let rotated: Vec<_> = f
        .received
        .iter()
        .filter(|(t, _)| (4.7e6..5.9e6).contains(t))
        .collect();
    assert!(rotated.len() >= 2);
    for &&(t, index) in &rotated {
        let k = f
            .truth
            .iter()
            .position(|b| (b.0 - t).abs() < 250_000.0)
            .unwrap();
        // Beat one was pressed 0.1 s after the clock's beat 6 (at 4.0 s): that beat is now 1.
        let want = ((k as i64 - 6).rem_euclid(4) + 1) as u32;
        assert_eq!(index, want, "beat {k} at {:.2} s", t * 1e-6);
    }
    let nudged = offsets(&f, 6.8e6, f64::INFINITY);
    assert!(nudged.len() >= 3);
    let m = median(nudged.iter().map(|o| o.0).collect());
    assert!(
        (m - 30_000.0).abs() < 5_000.0,
        "nudged by {:.1} ms",
        m * 1e-3
    );
    assert!((f.report.nudge_ms - 30.0).abs() < 1e-3);
}

#[test]
fn the_heard_offset_is_reported_and_trimmed_toward_when_asked() {
    // The clock at the clicks' tempo, its beats 60 ms before the clicks are heard (a DJ's
    // clock ahead of the speakers): 0.25 s into the replay the first click, so the clock's
    // first beat at 0.19 s past a whole second of replay.
    let (tempi, seconds) = ([(0, 120.0)], 10.0);
    for trim in [false, true] {
        let clock = Clock {
            tempi: &tempi,
            start_us: 1.19e6,
            trim,
        };
        let f = follow(seconds, clock, Vec::new());
        // The clock started on the run's clock, the replay a few ms after the epoch.
        let clicks_minus_clock_ms = (f.origin_us + 0.25e6 - 1.19e6) * 1e-3 + 500.0 * 2.0;
        let expected = (clicks_minus_clock_ms + 250.0).rem_euclid(500.0) - 250.0;
        let measured = f.report.offset_ms.expect("an offset");
        eprintln!("trim {trim}: heard {measured:+.1} ms from the clock (clicks {expected:+.1})");
        assert!(
            (measured - expected as f32).abs() < 15.0,
            "{measured} vs {expected}"
        );
        let clicks: Vec<(f64, u32)> = (0..40)
            .map(|k| (f.origin_us + 0.25e6 + 0.5e6 * f64::from(k), 0))
            .collect();
        let late = Followed {
            received: f.received.clone(),
            truth: clicks,
            report: f.report.clone(),
            origin_us: f.origin_us,
        };
        let m = median(
            offsets(&late, 7e6, f64::INFINITY)
                .iter()
                .map(|o| o.0)
                .collect(),
        );
        if trim {
            // Trimmed: the beats sent are where the clicks are heard (the tracker's own error).
            assert!(m.abs() < 15_000.0, "{:.1} ms from the clicks", m * 1e-3);
            assert!((f.report.trim_ms - measured).abs() < 10.0);
        } else {
            assert!(
                (m * 1e-3 + expected).abs() < 5.0,
                "{:.1} ms from the clicks",
                m * 1e-3
            );
            assert_eq!(f.report.trim_ms, 0.0);
        }
    }
}
