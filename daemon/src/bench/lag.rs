//! The motion lag, measured from outside the pipeline: how far the dancer a receiver sees
//! trails the music a listener hears. A song is replayed in real time; its motion is received
//! over UDP (native OSC) and put on the replay clock (when each sample would have been heard);
//! the same song is danced offline at temperature 0 (frame i shows the music at i / rate); the
//! lag is the shift that best aligns the two, by cross-correlating the joints' positions.

use std::net::UdpSocket;
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};
use glam::Vec3;
use model::rig::{Joint, Pose};
use model::source::{Controls, MotionSource};

use crate::frame::FrameBuilder;
use crate::live::config::Config;
use crate::live::context::LiveContext;
use crate::live::control_queue::ControlHub;
use crate::live::io::OscSink;
use crate::live::pipeline::{Pipeline, PipelineParts, PipelineSettings};
use crate::live::replay::{self, ReplayAudio, ReplaySettings};
use crate::live::sink::MemoryPoseBank;
use crate::live::wire::ControlEvent;
use crate::offline_dance::dance_stream;

/// Joint positions of one frame relative to the hips (Unity coordinates, metres).
pub type BodyShape = Vec<Vec3>;

/// The best alignment of received motion with the offline reference.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LagEstimate {
    /// How far the received motion trails the heard music, seconds (negative: ahead).
    pub lag_s: f64,
    /// Correlation of the two at that lag (1 = identical motion).
    pub correlation: f64,
    /// Received frames compared.
    pub frames: usize,
}

/// The offline reference for a live run at `lead_ms`: `features` (the song's analysis) danced
/// by `source` at temperature 0 through the music predicted over the horizon that run uses,
/// for at most `frames` frames, as body shapes (frame i at i / the source's rate).
pub fn offline_reference(
    source: &mut dyn MotionSource,
    features: &[dsp::FeatureFrame],
    lead_ms: f64,
    frames: usize,
) -> Vec<BodyShape> {
    let horizon =
        model::horizon::source_horizon(&*source, lead_ms * 1e-3, model::horizon::DEFAULT_MARGIN_S);
    let music = dsp::predicted_stream(features, horizon);
    let poses = dance_stream(source, &music, horizon, frames, |_| Controls::default());
    body_shapes(&poses)
}

/// Every frame's body shape (joint positions relative to the hips) as the sender would send it.
pub fn body_shapes(poses: &[Pose]) -> Vec<BodyShape> {
    let mut builder = FrameBuilder::new();
    poses
        .iter()
        .map(|p| shape_of(&builder.build(0, 0.0, p, 0.0).bones))
        .collect()
}

fn shape_of(bones: &[protocols::BoneSample]) -> BodyShape {
    let hips = bones
        .iter()
        .find(|b| b.bone == Joint::Hips.name())
        .map_or(Vec3::ZERO, |b| b.world_position);
    bones.iter().map(|b| b.world_position - hips).collect()
}

/// Linear interpolation of `reference` (frame i at i / rate) at `t_s`; None outside it.
fn sample(reference: &[BodyShape], rate: f64, t_s: f64, out: &mut [Vec3]) -> Option<()> {
    let x = t_s * rate;
    if x.is_nan() || x < 0.0 {
        return None;
    }
    let i = x.floor() as usize;
    let (a, b) = (reference.get(i)?, reference.get(i + 1)?);
    let w = (x - i as f64) as f32;
    for ((o, p), q) in out.iter_mut().zip(a).zip(b) {
        *o = p.lerp(*q, w);
    }
    Some(())
}

/// Correlation of `received` (heard time, shape) with `reference` shifted by `lag_s`: the
/// received frame heard at h is compared with the reference at h − lag.
fn correlation_at(
    received: &[(f64, BodyShape)],
    reference: &[BodyShape],
    rate: f64,
    lag_s: f64,
) -> Option<(f64, usize)> {
    let joints = reference.first()?.len();
    let mut r = vec![Vec3::ZERO; joints];
    let mut pairs: Vec<(&BodyShape, BodyShape)> = Vec::with_capacity(received.len());
    for (h, shape) in received {
        if shape.len() == joints && sample(reference, rate, h - lag_s, &mut r).is_some() {
            pairs.push((shape, r.clone()));
        }
    }
    if pairs.len() < 10 {
        return None;
    }
    // Each joint coordinate centred on its own mean over the compared span.
    let n = pairs.len() as f64;
    let mut mean_a = vec![glam::DVec3::ZERO; joints];
    let mut mean_b = vec![glam::DVec3::ZERO; joints];
    for (a, b) in &pairs {
        for j in 0..joints {
            mean_a[j] += a[j].as_dvec3() / n;
            mean_b[j] += b[j].as_dvec3() / n;
        }
    }
    let (mut ab, mut aa, mut bb) = (0.0, 0.0, 0.0);
    for (a, b) in &pairs {
        for j in 0..joints {
            let x = a[j].as_dvec3() - mean_a[j];
            let y = b[j].as_dvec3() - mean_b[j];
            ab += x.dot(y);
            aa += x.dot(x);
            bb += y.dot(y);
        }
    }
    let c = ab / (aa * bb).sqrt().max(1e-12);
    Some((c, pairs.len()))
}

/// The lag within ±`max_lag_s` that best aligns `received` with `reference`: a 2 ms scan,
/// then 0.1 ms steps around the best.
pub fn estimate_lag(
    received: &[(f64, BodyShape)],
    reference: &[BodyShape],
    rate: f64,
    max_lag_s: f64,
) -> Option<LagEstimate> {
    let scan = |from: f64, to: f64, step: f64| {
        let mut best: Option<LagEstimate> = None;
        let mut lag = from;
        while lag <= to + 1e-12 {
            if let Some((c, n)) = correlation_at(received, reference, rate, lag)
                && best.is_none_or(|b| c > b.correlation)
            {
                best = Some(LagEstimate {
                    lag_s: lag,
                    correlation: c,
                    frames: n,
                });
            }
            lag += step;
        }
        best
    };
    let coarse = scan(-max_lag_s, max_lag_s, 0.002)?;
    scan(coarse.lag_s - 0.002, coarse.lag_s + 0.002, 0.0001)
}

/// Decodes one native-OSC frame bundle into its body shape (None for anything else).
pub fn decode_shape(datagram: &[u8]) -> Option<BodyShape> {
    let (_, packet) = rosc::decoder::decode_udp(datagram).ok()?;
    let rosc::OscPacket::Bundle(bundle) = packet else {
        return None;
    };
    let mut hips = None;
    let mut joints = Vec::new();
    for p in &bundle.content {
        let rosc::OscPacket::Message(m) = p else {
            continue;
        };
        let Some(bone) = m.addr.rsplit_once("/joint/").map(|(_, b)| b) else {
            continue;
        };
        let f = |i: usize| match m.args.get(i) {
            Some(rosc::OscType::Float(x)) => Some(*x),
            _ => None,
        };
        let p = Vec3::new(f(0)?, f(1)?, f(2)?);
        if bone == Joint::Hips.name() {
            hips = Some(p);
        }
        joints.push(p);
    }
    let hips = hips?;
    Some(joints.into_iter().map(|p| p - hips).collect())
}

/// The stream time of a `/danced/beat` message, if `datagram` is one.
pub fn decode_beat(datagram: &[u8]) -> Option<f64> {
    let (_, packet) = rosc::decoder::decode_udp(datagram).ok()?;
    let rosc::OscPacket::Message(m) = packet else {
        return None;
    };
    if !m.addr.ends_with("/beat") {
        return None;
    }
    match m.args.get(3) {
        Some(rosc::OscType::Float(t)) => Some(f64::from(*t)),
        _ => None,
    }
}

/// One live measurement: the dancer's lag behind the heard music over a real-time replay.
#[derive(Clone, Debug)]
pub struct LiveLag {
    /// The alignment found.
    pub estimate: LagEstimate,
    /// For every `/danced/beat` received after the settling time: how long after the dancer
    /// showed that beat it arrived (heard time at arrival + lead − the beat's time), seconds.
    pub beat_message_delays_s: Vec<f64>,
    /// Frames the sender had to hold (motion late).
    pub late_frames: u64,
    /// Times the replay fell behind and restarted its clock (the heard axis is then unsure).
    pub replay_rebases: u64,
}

/// What to measure.
pub struct LagRun<'a> {
    /// The song.
    pub audio: &'a ReplayAudio,
    /// Seconds of it to replay.
    pub seconds: f64,
    /// Seconds at the start left out of the comparison (the tracker locking on).
    pub settle_s: f64,
    /// Output lead, ms.
    pub lead_ms: f64,
    /// Output rate, Hz.
    pub rate_hz: f64,
}

/// What a receiver got from one real-time replay, on the heard clock.
pub struct Received {
    /// Every frame's body shape with the heard time it arrived at, seconds.
    pub frames: Vec<(f64, BodyShape)>,
    /// Every `/danced/beat` with the heard time it arrived at and the beat's own time.
    pub beats: Vec<(f64, f64)>,
    /// Frames the sender had to hold (motion late).
    pub late_frames: u64,
    /// Times the replay fell behind and restarted its clock (the heard axis is then unsure).
    pub replay_rebases: u64,
}

/// Replays `run.audio` through the live pipeline with `source` at temperature 0 and receives
/// its native OSC on a local socket; `cues` are sent through the control path when the heard
/// time reaches theirs (pose names refer to `bank`).
pub fn replay_and_receive(
    run: &LagRun<'_>,
    source: Box<dyn MotionSource + Send>,
    bank: &MemoryPoseBank,
    cues: &[(f64, ControlEvent)],
) -> Result<Received> {
    let socket = UdpSocket::bind("127.0.0.1:0").context("binding the receiver")?;
    socket.set_read_timeout(Some(Duration::from_millis(5)))?;
    let mut config = Config::default();
    config.output.osc = vec![socket.local_addr()?.to_string()];
    config.output.rate_hz = run.rate_hz;
    let sink = OscSink::from_config(&config)?;
    let ctx = LiveContext::new();
    let (writer, reader) = ctx.ring();
    let mut hub = ControlHub::new(bank, ctx.stats.clone());
    let mut control = hub.sender();
    let pipeline = Pipeline::start(
        &ctx,
        PipelineSettings {
            rate_hz: run.rate_hz,
            temperature: 0.0,
            lead_ms: run.lead_ms,
            ..PipelineSettings::default()
        },
        PipelineParts {
            source,
            sink: Box::new(sink),
            controls: hub,
            clock: None,
        },
        reader,
    )?;
    let replay = replay::spawn(
        run.audio.clone(),
        ReplaySettings {
            speed: 1.0,
            looped: false,
            duration_s: Some(run.seconds),
        },
        writer,
        &ctx,
    )?;
    let epoch = ctx.epoch;
    let heard = |at: Instant, origin_ns: u64| {
        (at.duration_since(epoch).as_nanos() as f64 - origin_ns as f64) * 1e-9
    };
    let mut got: Vec<(Instant, BodyShape)> = Vec::with_capacity((run.seconds * 70.0) as usize);
    let mut beats: Vec<(Instant, f64)> = Vec::new();
    let mut pending = cues.iter();
    let mut next_cue = pending.next();
    let mut buf = vec![0u8; 65_536];
    let limit = Instant::now() + Duration::from_secs_f64(run.seconds + 30.0);
    while !ctx.stopped() && !pipeline.failed() && Instant::now() < limit {
        let origin_ns = ctx.stats.replay_origin_ns.load(Ordering::Relaxed);
        while let Some((at_s, cue)) = next_cue {
            if origin_ns == u64::MAX || heard(Instant::now(), origin_ns) < *at_s {
                break;
            }
            // A refused cue is counted in the run's stats like any other control.
            let _ = control.send(cue.clone());
            next_cue = pending.next();
        }
        if let Ok(n) = socket.recv(&mut buf) {
            let at = Instant::now();
            if let Some(shape) = decode_shape(&buf[..n]) {
                got.push((at, shape));
            } else if let Some(t) = decode_beat(&buf[..n]) {
                beats.push((at, t));
            }
        }
    }
    let origin_ns = ctx.stats.replay_origin_ns.load(Ordering::Relaxed);
    let replay_rebases = ctx.stats.replay_rebases.load(Ordering::Relaxed);
    let (report, _) = pipeline.stop()?;
    if replay.join().is_err() {
        bail!("the replay thread panicked");
    }
    if origin_ns == u64::MAX {
        bail!("the replay never started");
    }
    Ok(Received {
        frames: got
            .into_iter()
            .map(|(at, s)| (heard(at, origin_ns), s))
            .collect(),
        beats: beats
            .into_iter()
            .map(|(at, t)| (heard(at, origin_ns), t))
            .collect(),
        late_frames: report.late_frames,
        replay_rebases,
    })
}

/// Replays `run.audio` through the live pipeline with `source` at temperature 0, receives its
/// native OSC on a local socket, and aligns that with `reference` (the same song danced
/// offline, frame i at i / `reference_rate`: [`offline_reference`]).
pub fn measure_live_lag(
    run: &LagRun<'_>,
    source: Box<dyn MotionSource + Send>,
    reference: &[BodyShape],
    reference_rate: f64,
) -> Result<LiveLag> {
    let got = replay_and_receive(run, source, &MemoryPoseBank::new(), &[])?;
    let received: Vec<(f64, BodyShape)> = got
        .frames
        .into_iter()
        .filter(|(h, _)| *h >= run.settle_s)
        .collect();
    let beat_message_delays_s = got
        .beats
        .into_iter()
        .filter(|(_, t)| *t >= run.settle_s)
        .map(|(h, t)| h + run.lead_ms * 1e-3 - t)
        .collect();
    let estimate = estimate_lag(&received, reference, reference_rate, 0.5)
        .context("too few frames received to align")?;
    Ok(LiveLag {
        estimate,
        beat_message_delays_s,
        late_frames: got.late_frames,
        replay_rebases: got.replay_rebases,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A moving body: three joints on circles of different speeds.
    fn shape(t: f64) -> BodyShape {
        (0..3)
            .map(|j| {
                let w = 2.0 + j as f64;
                Vec3::new(
                    (w * t).sin() as f32,
                    (w * t * 1.3).cos() as f32,
                    0.1 * j as f32,
                )
            })
            .collect()
    }

    #[test]
    fn finds_a_known_lag_between_frame_grids() {
        let rate = 25.0;
        let reference: Vec<BodyShape> = (0..500).map(|i| shape(i as f64 / rate)).collect();
        for lag in [-0.05, 0.0, 0.0173, 0.24] {
            // Received at 60 Hz: what was heard at h shows the music of h − lag.
            let received: Vec<(f64, BodyShape)> = (0..900)
                .map(|k| {
                    let h = 1.0 + k as f64 / 60.0;
                    (h, shape(h - lag))
                })
                .collect();
            let e = estimate_lag(&received, &reference, rate, 0.5).unwrap();
            assert!((e.lag_s - lag).abs() < 0.001, "{lag}: {e:?}");
            assert!(e.correlation > 0.99);
        }
    }

    #[test]
    fn stream_starts_at_the_horizon_and_holds_before() {
        struct Counter(u32);
        impl MotionSource for Counter {
            fn frame_rate(&self) -> f64 {
                25.0
            }
            fn lookahead_frames(&self) -> usize {
                0
            }
            fn step(
                &mut self,
                _: &[[f32; dsp::feature::FEATURE_DIM]],
                _: &Controls,
                out: &mut Pose,
            ) {
                self.0 += 1;
                out.root_position.x = self.0 as f32;
            }
            fn reset(&mut self, _: u64) {}
            fn reseed(&mut self, _: u64) {}
        }
        let music = vec![[0.0; dsp::feature::FEATURE_DIM]; 10];
        let poses = dance_stream(&mut Counter(0), &music, 3, 10, |_| Controls::default());
        let x: Vec<f32> = poses.iter().map(|p| p.root_position.x).collect();
        assert_eq!(x, [1.0, 1.0, 1.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0]);
    }
}
