//! Sound-card capture through real ALSA devices, no hardware needed: a 64-channel PCM (ALSA's
//! `file` plugin over a `multi` of the `null` plugin, which delivers as fast as it is read),
//! and a paced PulseAudio server (`.ci/run` starts one) whose null sink's monitor is captured
//! through ALSA's pulse plugin while `paplay` plays a click track into it; then the server is
//! killed and restarted mid-run.

use std::net::UdpSocket;
use std::path::Path;
use std::process::{Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use rosc::{OscPacket, OscType};

mod common;
use common::{click_track, danced, receive_while, scratch, write_wav};

const RATE: u32 = 44_100;
const BPM: f64 = 120.0;
const FIRST_CLICK_S: f64 = 0.5;

/// Analysis events among received packets: (wall arrival, address, `time_s`).
fn events(packets: &[(Instant, Vec<u8>)]) -> Vec<(Instant, String, f32)> {
    packets
        .iter()
        .filter_map(|(at, bytes)| {
            // Frames come in bundles; events are plain messages.
            let Ok((_, OscPacket::Message(m))) = rosc::decoder::decode_udp(bytes) else {
                return None;
            };
            // Beats carry time_s fourth (then bar_confidence or in_s); other events carry it last.
            let time = if m.addr.starts_with("/danced/beat") {
                match m.args.get(3) {
                    Some(OscType::Float(f)) => *f,
                    _ => return None,
                }
            } else {
                m.args.iter().rev().find_map(|a| match a {
                    OscType::Float(f) => Some(*f),
                    _ => None,
                })?
            };
            Some((*at, m.addr.clone(), time))
        })
        .collect()
}

fn stats(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

#[test]
fn a_64_channel_alsa_device_is_captured_without_a_panic() {
    // The first real capture (a 64-channel interface) panicked the analysis thread.
    let dir = scratch("capture-64ch");
    let raw = dir.join("in64.raw");
    // 2 s of 64-channel float audio: a click on channel 1 every 0.5 s.
    let mut bytes = Vec::with_capacity(96_000 * 64 * 4);
    for i in 0..96_000usize {
        for c in 0..64 {
            let v = if c == 0 && i % 24_000 < 200 {
                0.8f32
            } else {
                0.0
            };
            bytes.extend_from_slice(&v.to_le_bytes());
        }
    }
    std::fs::write(&raw, bytes).unwrap();
    let bindings: String = (0..64)
        .map(|i| format!("    bindings.{i} {{ slave a channel {i} }}\n"))
        .collect();
    let asoundrc = format!(
        "pcm.danced64 {{\n    type file\n    slave.pcm \"danced64multi\"\n    file \"/dev/null\"\n    \
         infile \"{}\"\n    format \"raw\"\n    hint {{ show on description \"danced 64-channel test input\" }}\n}}\n\
         pcm.danced64multi {{\n    type multi\n    slaves.a {{ pcm \"null\" channels 64 }}\n{bindings}}}\n",
        raw.display()
    );
    std::fs::write(dir.join(".asoundrc"), asoundrc).unwrap();
    let stats_path = dir.join("stats.json");
    let out = danced()
        .env("HOME", &dir)
        .args(["run", "--device", "danced 64-channel", "--duration", "3"])
        .args([
            "--control-port",
            "0",
            "--osc",
            "127.0.0.1:9",
            "--stats-json",
        ])
        .arg(&stats_path)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    if err.contains("no audio input matches") || err.contains("no audio inputs") {
        testkit::skip(format_args!(
            "this ALSA build does not list the test PCM ({err})"
        ));
        return;
    }
    assert!(out.status.success(), "{err}");
    assert!(err.contains("64 ch"), "opened as: {err}");
    let s = stats(&stats_path);
    // The null plugin delivers as fast as it is read: most blocks find the ring full, which
    // is counted; the dancer keeps dancing at the full rate regardless.
    assert!(s["frames_sent"].as_u64().unwrap() > 120, "{s}");
    assert!(s["model_frames"].as_u64().unwrap() > 40, "{s}");
    assert!(
        s["drops"].as_u64().unwrap() > 0,
        "the overflow is counted: {s}"
    );
    assert_eq!(s["allocations"]["capture"], 0, "{s}");
}

fn pactl(args: &[&str]) -> Option<String> {
    let out = Command::new("pactl").args(args).output().ok()?;
    out.status
        .success()
        .then(|| String::from_utf8_lossy(&out.stdout).into_owned())
}

/// Starts a PulseAudio server with a null sink named `sink` (as `.ci/run` does).
fn start_pulse(sink: &str) {
    let _ = Command::new("pulseaudio")
        .args(["--daemonize=yes", "--exit-idle-time=-1", "-n"])
        .arg("--load=module-native-protocol-unix")
        .arg(format!("--load=module-null-sink sink_name={sink}"))
        .stderr(Stdio::null())
        .status();
}

#[test]
fn paced_capture_hears_the_clicks_and_survives_a_server_restart() {
    if pactl(&["info"]).is_none() {
        testkit::skip(
            "no PulseAudio server (apt-get install pulseaudio pulseaudio-utils \
             libasound2-plugins; `.ci/run` starts one, see its comments)",
        );
        return;
    }
    let sink = "danced_clicks";
    if !pactl(&["list", "short", "sinks"]).is_some_and(|s| s.contains(sink)) {
        pactl(&[
            "load-module",
            "module-null-sink",
            &format!("sink_name={sink}"),
        ])
        .unwrap();
    }
    let dir = scratch("capture-pulse");
    let (samples, _) = click_track(8.0, BPM, FIRST_CLICK_S, RATE);
    let wav = dir.join("clicks.wav");
    write_wav(&wav, &samples, RATE, 2);
    let native = UdpSocket::bind("127.0.0.1:0").unwrap();
    let port = native.local_addr().unwrap().port();
    let stats_path = dir.join("stats.json");
    let start = Instant::now();
    // The run ends on Ctrl-C once the second playback is over, however long the server took
    // to come back; --duration only guards against a run that never stops.
    let listening = Arc::new(AtomicBool::new(true));
    let rx = receive_while(native, listening.clone());
    let mut child = danced()
        .env("PULSE_SOURCE", format!("{sink}.monitor"))
        .args(["run", "--device", "pulseaudio", "--duration", "60"])
        .args(["--control-port", "0", "--osc", &format!("127.0.0.1:{port}")])
        .arg("--stats-json")
        .arg(&stats_path)
        .stdout(Stdio::null())
        .stderr(std::fs::File::create(dir.join("stderr.txt")).unwrap())
        .spawn()
        .unwrap();
    // Until danced records from the server (its ALSA plug-in stream is a source output).
    let recording =
        || pactl(&["list", "short", "source-outputs"]).is_some_and(|s| !s.trim().is_empty());
    assert!(
        testkit::wait_until(Duration::from_secs(30), recording),
        "danced never started recording from PulseAudio"
    );
    // Returns when the playback started and when it was over.
    let play = || {
        let from = Instant::now();
        let status = Command::new("paplay")
            .args(["--device", sink])
            .arg(&wav)
            .status()
            .unwrap();
        assert!(status.success());
        (from, Instant::now())
    };
    let (played, _) = play();
    // Device loss: the server goes away mid-run and comes back a second later.
    let _ = Command::new("pulseaudio").arg("-k").status();
    // (`pulseaudio --check`, not a client, which might autospawn a server.)
    let server_up = || {
        Command::new("pulseaudio")
            .arg("--check")
            .status()
            .is_ok_and(|s| s.success())
    };
    assert!(
        testkit::wait_until(Duration::from_secs(30), || !server_up()),
        "the PulseAudio server did not go away"
    );
    let killed = Instant::now();
    std::thread::sleep(Duration::from_secs(1));
    start_pulse(sink);
    let restarted = Instant::now();
    // Until danced records from the new server.
    assert!(
        testkit::wait_until(Duration::from_secs(30), recording),
        "danced never recorded from the restarted server"
    );
    let (replayed, replay_over) = play();
    std::thread::sleep(Duration::from_millis(500));
    let _ = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status();
    // A stuck teardown must fail the test, not hang it.
    let mut status = None;
    while start.elapsed() < Duration::from_secs(70) && status.is_none() {
        status = child.try_wait().unwrap();
        std::thread::sleep(Duration::from_millis(50));
    }
    let err = std::fs::read_to_string(dir.join("stderr.txt")).unwrap_or_default();
    let Some(status) = status else {
        let _ = child.kill();
        let _ = child.wait();
        panic!("danced did not stop on Ctrl-C: {err}");
    };
    listening.store(false, Ordering::Relaxed);
    assert!(status.success(), "{err}");
    let got = events(&rx.join().unwrap());
    let s = stats(&stats_path);
    eprintln!("{s}");

    // Beats against the clicks, on the stream clock: the first onset of each playback is its
    // first click; from 2 s into it (the tracker relocks after the outage), every beat lies
    // within 70 ms of a click.
    let mut worst = Vec::new();
    for (from, to) in [(played, killed), (replayed, replay_over)] {
        let onsets: Vec<f32> = got
            .iter()
            .filter(|(at, addr, _)| *at > from && *at < to && addr == "/danced/onset")
            .map(|e| e.2)
            .collect();
        let Some(&first) = onsets.first() else {
            panic!("no onsets heard from the playback at {:?}", from - start);
        };
        let period = 60.0 / BPM as f32;
        let beats: Vec<f32> = got
            .iter()
            .filter(|(at, addr, _)| *at > from && *at < to && addr == "/danced/beat")
            .map(|e| e.2)
            .filter(|t| *t > first + 1.9 && *t < first + 4.9)
            .collect();
        let all: Vec<String> = got
            .iter()
            .filter(|(at, addr, _)| *at > from && *at < to && addr == "/danced/beat")
            .map(|e| format!("{:.2}", e.2 - first))
            .collect();
        eprintln!(
            "beats after the first onset ({first:.2} s): {}",
            all.join(" ")
        );
        assert!(
            beats.len() >= 5,
            "{} beats after {:?}",
            beats.len(),
            from - start
        );
        let off = beats
            .iter()
            .map(|t| {
                let k = ((t - first) / period).round();
                (t - first - k * period).abs()
            })
            .fold(0.0f32, f32::max);
        worst.push(off);
    }
    eprintln!(
        "beats vs clicks: worst {:.0} / {:.0} ms (before / after the restart)",
        worst[0] * 1e3,
        worst[1] * 1e3
    );
    assert!(worst.iter().all(|w| *w <= 0.070), "{worst:?}");
    // The dancer never stopped, the device came back, and both are counted.
    let frames = s["frames_sent"].as_u64().unwrap();
    let wall_s = s["wall_s"].as_f64().unwrap();
    assert!(
        frames as f64 > 55.0 * (wall_s - 2.0),
        "{frames} frames in {wall_s:.1} s"
    );
    assert!(s["reconnects"].as_u64().unwrap() >= 1, "{s}");
    assert!(s["silence_frames"].as_u64().unwrap() > 0, "{s}");
    let back = got
        .iter()
        .find(|(at, addr, _)| *at > restarted && addr == "/danced/onset")
        .map(|e| e.0 - restarted);
    // While the input is gone the analysis dances on silence (after 0.25 s without audio):
    // the silence inserted measures the outage as the pipeline saw it.
    let outage_s = s["silence_frames"].as_f64().unwrap() / 48_000.0 + 0.25;
    eprintln!(
        "server down {:.2} s; audio missing {outage_s:.2} s, so back {:.2} s after the server; \
         first onset {back:?} after the restart (playback resumed {:.2} s after it)",
        (restarted - killed).as_secs_f64(),
        outage_s - (restarted - killed).as_secs_f64(),
        (replayed - restarted).as_secs_f64()
    );
}
