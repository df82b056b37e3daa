//! Link followed and led, against peers that are the SDK alone (`link-peer`): a live replay
//! whose beat grid follows a session another peer leads (the `/danced/beat` messages received
//! over OSC against the session's beats, as a second peer reads them), and a replay of an
//! annotated song whose heard beats danced leads the session with (the session's beats against
//! the song's). Run inside [`super::private_network`]: Link talks on every interface.

use std::io::{BufRead, BufReader};
use std::net::UdpSocket;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};
use serde::Serialize;

use super::clock::{monotonic_us, quantile};
use crate::live::clock::ClockDesk;
use crate::live::config::Config;
use crate::live::context::LiveContext;
use crate::live::control_queue::ControlHub;
use crate::live::io::OscSink;
use crate::live::pipeline::{Pipeline, PipelineParts, PipelineSettings};
use crate::live::replay::{self, ReplayAudio, ReplaySettings};
use crate::live::sink::MemoryPoseBank;

/// Received beats within this of the session's count as locked, ms.
const LOCKED_MS: f64 = 5.0;

/// A `link-peer` process and what it prints.
struct Peer {
    child: Child,
}

impl Peer {
    fn start(exe: &Path, args: &[String]) -> Result<Self> {
        let child = Command::new(exe)
            .args(args)
            .stdout(Stdio::piped())
            .spawn()
            .with_context(|| format!("starting {}", exe.display()))?;
        Ok(Peer { child })
    }

    /// Waits for it to end; its lines.
    fn lines(mut self) -> Result<Vec<String>> {
        let out = self.child.stdout.take().context("the peer's output")?;
        let lines: Vec<String> = BufReader::new(out).lines().map_while(|l| l.ok()).collect();
        self.child.wait().context("waiting for the Link peer")?;
        Ok(lines)
    }
}

/// `beat N MONO_US TEMPO PEERS` lines: (mono µs, tempo).
fn session_beats(lines: &[String]) -> Vec<(f64, f64)> {
    lines
        .iter()
        .filter_map(|l| {
            let f: Vec<&str> = l.split_whitespace().collect();
            (f.first() == Some(&"beat") && f.len() >= 4)
                .then(|| Some((f[2].parse().ok()?, f[3].parse().ok()?)))
                .flatten()
        })
        .collect()
}

/// What a live replay with the clocks of `config` sent, on CLOCK_MONOTONIC.
struct Replayed {
    /// Arrival of every `/danced/beat`, mono µs.
    beats: Vec<f64>,
    /// When the replay's first sample was heard, mono µs.
    origin_us: f64,
    /// The run's clock summary.
    clock: crate::live::stats::ClockReport,
    /// Allocations counted on the real-time threads during the run.
    rt_allocations: u64,
}

fn replay_with_clocks(mut config: Config, audio: &ReplayAudio, seconds: f64) -> Result<Replayed> {
    let socket = UdpSocket::bind("127.0.0.1:0").context("binding the receiver")?;
    socket.set_read_timeout(Some(Duration::from_millis(5)))?;
    config.output.osc = vec![socket.local_addr()?.to_string()];
    let sink = OscSink::from_config(&config)?;
    let ctx = LiveContext::new();
    let epoch_mono_us = monotonic_us() - ctx.epoch.elapsed().as_secs_f64() * 1e6;
    let (desk, feed) = ClockDesk::new(crate::live::run::clock_settings(&config), ctx.epoch);
    let (wiring, threads) = crate::live::run::start_clocks(&config, &desk, feed, &ctx)?;
    let (writer, reader) = ctx.ring();
    let hub = ControlHub::new(&MemoryPoseBank::new(), ctx.stats.clone()).with_clock(desk);
    let allocations_before = crate::live::stats::ThreadAllocations::now().total();
    let pipeline = Pipeline::start(
        &ctx,
        PipelineSettings::default(),
        PipelineParts {
            source: Box::new(model::source::Standing),
            sink: Box::new(sink),
            controls: hub,
            clock: Some(wiring),
        },
        reader,
    )?;
    let replay = replay::spawn(
        audio.clone(),
        ReplaySettings {
            speed: 1.0,
            looped: false,
            duration_s: Some(seconds),
        },
        writer,
        &ctx,
    )?;
    let mut beats = Vec::new();
    let mut buf = vec![0u8; 2048];
    let limit = Instant::now() + Duration::from_secs_f64(seconds + 30.0);
    while !ctx.stopped() && !pipeline.failed() && Instant::now() < limit {
        let Ok(n) = socket.recv(&mut buf) else {
            continue;
        };
        let at = monotonic_us();
        if let Ok((_, rosc::OscPacket::Message(m))) = rosc::decoder::decode_udp(&buf[..n])
            && m.addr == "/danced/beat"
        {
            beats.push(at);
        }
    }
    let origin_ns = ctx.stats.replay_origin_ns.load(Ordering::Relaxed);
    let (report, _) = pipeline.stop()?;
    for t in threads {
        if t.join().is_err() {
            bail!("a clock thread panicked");
        }
    }
    if replay.join().is_err() {
        bail!("the replay thread panicked");
    }
    Ok(Replayed {
        beats,
        origin_us: epoch_mono_us + origin_ns as f64 * 1e-3,
        rt_allocations: report.allocations.total() - allocations_before,
        clock: report.clock,
    })
}

/// Signed offset of each of `times` after `from_us` from the nearest of `reference`, ms.
fn offsets_ms(times: &[f64], reference: &[f64], from_us: f64) -> Vec<(f64, f64)> {
    times
        .iter()
        .filter(|&&t| t >= from_us)
        .filter_map(|&t| {
            let nearest = reference
                .iter()
                .min_by(|a, b| (*a - t).abs().total_cmp(&(*b - t).abs()))?;
            Some((t, (t - nearest) * 1e-3))
        })
        .collect()
}

/// Following a session another peer leads.
#[derive(Clone, Debug, Serialize)]
pub struct LinkFollow {
    /// The leader's tempo, then its new one, BPM.
    pub bpm: (f64, f64),
    /// Beats received while the tempo held (from 4 s in).
    pub beats: usize,
    /// |received − session beat|, ms: median and 95th percentile.
    pub offset_ms_p50: f64,
    /// See `offset_ms_p50`.
    pub offset_ms_p95: f64,
    /// From the leader's tempo change to the first beat from which every beat is within
    /// [`LOCKED_MS`] again, in beats of the new tempo (`None`: never).
    pub lock_after_change_beats: Option<f64>,
    /// Beats received after the change that were further than [`LOCKED_MS`] from the
    /// session's (before it locked again).
    pub beats_off_after_change: usize,
    /// Allocations on the real-time threads during the run (must be 0).
    pub rt_allocations: u64,
    /// The tempo the run followed at its end, BPM.
    pub tempo_at_end: f32,
    /// Link peers danced saw at its end.
    pub peers: u32,
}

/// Replays the demo song for `seconds` while a `link-peer` leads a session at `bpm`, changing
/// to `to_bpm` halfway; danced follows it.
pub fn follow(peer: &Path, seconds: f64, bpm: f64, to_bpm: f64) -> Result<LinkFollow> {
    let change_s = seconds / 2.0;
    let leader = Peer::start(
        peer,
        &[
            "lead".into(),
            bpm.to_string(),
            (seconds + 4.0).to_string(),
            (change_s + 1.0).to_string(),
            to_bpm.to_string(),
        ],
    )?;
    let reader = Peer::start(
        peer,
        &["read".into(), "4".into(), (seconds + 3.0).to_string()],
    )?;
    // The leader's session is up before danced joins.
    std::thread::sleep(Duration::from_secs(1));
    let mut config = Config::default();
    config.clock.link = true;
    config.clock.source = "link".into();
    let run = replay_with_clocks(config, &ReplayAudio::demo(seconds + 1.0), seconds)?;
    let session = session_beats(&reader.lines()?);
    let leader_lines = leader.lines()?;
    let change_us = leader_lines
        .iter()
        .find_map(|l| {
            l.strip_prefix("tempo ")?
                .split(" at ")
                .nth(1)?
                .parse::<f64>()
                .ok()
        })
        .context("the leader never changed tempo")?;
    let times: Vec<f64> = session.iter().map(|s| s.0).collect();
    let all = offsets_ms(&run.beats, &times, run.origin_us + 4e6);
    let steady: Vec<f64> = all
        .iter()
        .filter(|(t, _)| *t < change_us)
        .map(|(_, o)| o.abs())
        .collect();
    let after: Vec<(f64, f64)> = all
        .iter()
        .copied()
        .filter(|(t, _)| *t >= change_us)
        .collect();
    // The first beat after the change from which every later one is locked.
    let locked_from =
        (0..after.len()).find(|&i| after[i..].iter().all(|(_, o)| o.abs() <= LOCKED_MS));
    let lock = locked_from.map(|i| (after[i].0 - change_us) * 1e-6 * to_bpm / 60.0);
    Ok(LinkFollow {
        bpm: (bpm, to_bpm),
        beats: steady.len(),
        offset_ms_p50: quantile(&steady, 0.5),
        offset_ms_p95: quantile(&steady, 0.95),
        lock_after_change_beats: lock,
        beats_off_after_change: locked_from.unwrap_or(after.len()),
        rt_allocations: run.rt_allocations,
        tempo_at_end: run.clock.tempo_bpm,
        peers: run.clock.peers,
    })
}

/// Leading the session from a song's heard beats.
#[derive(Clone, Debug, Serialize)]
pub struct LinkLead {
    /// The song.
    pub song: String,
    /// Its tempo, BPM.
    pub bpm: f64,
    /// Session beats compared (from `settle_s` in).
    pub beats: usize,
    /// |session beat − the song's beat, as heard|, ms: median and 95th percentile.
    pub offset_ms_p50: f64,
    /// See `offset_ms_p50`.
    pub offset_ms_p95: f64,
    /// Median signed offset, ms (positive: the session's beats after the song's).
    pub bias_ms: f64,
    /// |session tempo − the song's|, BPM, median over the beats compared.
    pub tempo_error_bpm: f64,
    /// Allocations on the real-time threads during the run (must be 0).
    pub rt_allocations: u64,
}

/// Replays `audio` (whose beats fall at `beats_s`) for `seconds` with Link joined and the beat
/// grid from the music heard, while a `link-peer` reads the session.
pub fn lead(
    peer: &Path,
    name: &str,
    audio: &ReplayAudio,
    beats_s: &[f64],
    seconds: f64,
    settle_s: f64,
) -> Result<LinkLead> {
    // Only while the song plays: after its end the session runs on by itself.
    let length_s = audio.samples.len() as f64
        / f64::from(audio.channels.max(1))
        / f64::from(audio.sample_rate.max(1));
    let seconds = seconds.min(length_s);
    let reader = Peer::start(
        peer,
        &["read".into(), "4".into(), (seconds + 3.0).to_string()],
    )?;
    let mut config = Config::default();
    config.clock.link = true;
    let run = replay_with_clocks(config, audio, seconds)?;
    let session = session_beats(&reader.lines()?);
    let song: Vec<f64> = beats_s
        .iter()
        .filter(|&&b| b <= seconds)
        .map(|b| run.origin_us + b * 1e6)
        .collect();
    let times: Vec<f64> = session.iter().map(|s| s.0).collect();
    let offsets = offsets_ms(&times, &song, run.origin_us + settle_s * 1e6);
    let offsets: Vec<f64> = offsets
        .into_iter()
        .filter(|(t, _)| *t <= run.origin_us + seconds * 1e6)
        .map(|(_, o)| o)
        .collect();
    let bpm = super::sets::median_tempo_bpm(beats_s);
    let tempi: Vec<f64> = session
        .iter()
        .filter(|s| s.0 >= run.origin_us + settle_s * 1e6)
        .map(|s| (s.1 - bpm).abs())
        .collect();
    let abs: Vec<f64> = offsets.iter().map(|o| o.abs()).collect();
    Ok(LinkLead {
        song: name.to_string(),
        bpm,
        beats: offsets.len(),
        offset_ms_p50: quantile(&abs, 0.5),
        offset_ms_p95: quantile(&abs, 0.95),
        bias_ms: quantile(&offsets, 0.5),
        tempo_error_bpm: quantile(&tempi, 0.5),
        rt_allocations: run.rt_allocations,
    })
}
