//! The sender thread: on a fixed grid (default 60 Hz) of a monotonic clock, it picks the audio
//! time to show — the music heard now, plus the output lead (which cancels a renderer's display
//! latency) — interpolates the poses around it (made ahead of time from predicted music),
//! builds a [`BodyFrame`](super::wire::BodyFrame) in Unity coordinates stamped with when it should be shown, and hands
//! it to the sink with any pending analysis events. A beat ([`BeatClock`]) goes out when the
//! shown time reaches it: the thread wakes for it between frames, so a receiver triggering on
//! `/danced/beat` is not a frame period late.

use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use model::rig::{Pose, blend};

use super::beat_clock::BeatClock;
use super::context::LiveContext;
use super::sink::FrameSink;
use super::timeline::{Anchor, TimedPose, Timeline};
use super::wire::AnalysisEvent;
use crate::alloc_counter::{CountGuard, RtThread};
use crate::frame::FrameBuilder;

/// How long before a deadline the thread stops sleeping and spins (sleep overshoot margin).
const SPIN_BEFORE: Duration = Duration::from_micros(400);
/// How far the audio clock may be extrapolated past the newest audio block, audio seconds.
const MAX_EXTRAPOLATION_S: f64 = 0.1;

/// Settings of the sender thread.
#[derive(Clone, Copy, Debug)]
pub struct SchedulerSettings {
    /// Frames sent per second.
    pub rate_hz: f64,
    /// How far ahead of the heard music the shown pose is, wall seconds (may be negative).
    pub lead_s: f64,
    /// Audio seconds per wall second.
    pub speed: f64,
}

/// Sleeps until `deadline`: a coarse sleep, then a short spin for precision.
fn wait_until(deadline: Instant) {
    let now = Instant::now();
    if deadline > now + SPIN_BEFORE {
        std::thread::sleep(deadline - now - SPIN_BEFORE);
    }
    while Instant::now() < deadline {
        std::hint::spin_loop();
    }
}

/// The sender thread's ends of its queues.
pub struct SenderQueues {
    /// The audio clock from the analysis thread.
    pub anchors: rtrb::Consumer<Anchor>,
    /// Poses from the motion thread.
    pub poses: rtrb::Consumer<TimedPose>,
    /// Analysis events from the analysis thread.
    pub events: rtrb::Consumer<AnalysisEvent>,
}

/// Runs the sender thread until `stop` is set; gives the sink back at the end.
pub fn run(
    mut sink: Box<dyn FrameSink>,
    settings: SchedulerSettings,
    ctx: LiveContext,
    mut queues: SenderQueues,
) -> Box<dyn FrameSink> {
    let LiveContext { epoch, stats, stop } = ctx;
    // Tighter timer slack makes the coarse sleep land closer to its deadline (Linux only).
    #[cfg(target_os = "linux")]
    // SAFETY: PR_SET_TIMERSLACK only changes this thread's timer slack.
    unsafe {
        libc::prctl(libc::PR_SET_TIMERSLACK, 50_000 as libc::c_ulong);
    }
    let period = Duration::from_secs_f64(1.0 / settings.rate_hz);
    let lead_s = if settings.lead_s.is_finite() {
        settings.lead_s
    } else {
        0.0
    };
    let lead_audio_s = lead_s * settings.speed;
    // The clock and the pose history are this thread's own: the other threads only queue.
    let mut timeline = Timeline::new(settings.speed);
    let mut builder = FrameBuilder::new();
    let mut beats = BeatClock::default();
    let mut pose = Pose::rest();
    let mut index = 0u64;
    let mut last_t = f64::NEG_INFINITY;
    // Shown time up to which beats have gone out, and the next beat due before the next frame.
    let mut beats_until = f64::NEG_INFINITY;
    let mut due_beat: Option<(Instant, f64, dsp::BeatGrid)> = None;
    let mut last_sent: Option<Instant> = None;
    sink.prepare(builder.build(0, 0.0, &pose, 0.0));
    let mut deadline = Instant::now() + period;
    let _counting = CountGuard::new(RtThread::Sender);
    while !stop.load(Ordering::Relaxed) {
        if let Some((at, beat_s, grid)) = due_beat.take() {
            wait_until(at);
            beats.advance(&grid, beats_until, beat_s, settings.speed, |e| {
                sink.send_event(&e)
            });
            beats_until = beats_until.max(beat_s);
        }
        wait_until(deadline);
        let woke = Instant::now();
        while let Ok(a) = queues.anchors.pop() {
            timeline.anchors.push(a);
        }
        while let Ok(p) = queues.poses.pop() {
            timeline.poses.push(p);
        }
        let now_ns = woke.duration_since(epoch).as_nanos() as u64;
        let picked = (|| {
            let tl = &timeline;
            // The music heard now, and the lead on top.
            let heard = tl.audio_time_at(now_ns, MAX_EXTRAPOLATION_S)?;
            let mut t = heard + lead_audio_s;
            if t <= last_t {
                // The clock stalls when audio stops; frames still need increasing times.
                t = last_t + 1e-6;
            }
            let (a, b, w, late) = tl.bracket(t)?;
            blend(&a.pose, &b.pose, w, &mut pose);
            let shown = if late { b.time_s } else { t };
            let ingest = tl.ingest_wall_ns(shown)?;
            Some((t, late, ingest, b.grid))
        })();
        if let Some((t, late, ingest_ns, grid)) = picked {
            let frame = builder.build(index, t, &pose, lead_s);
            sink.send_frame(frame);
            beats.advance(&grid, beats_until, t, settings.speed, |e| {
                sink.send_event(&e)
            });
            beats_until = beats_until.max(t);
            last_t = t;
            // The next beat, if the shown time reaches it before the next frame: sent then.
            if let Some(b) = grid.beat_after(beats_until) {
                let wait_s = ((b.time_s - t) / settings.speed).max(0.0);
                let at = woke + Duration::from_secs_f64(wait_s.min(1.0));
                if at < deadline + period {
                    // Just past the beat, so the clock counts it crossed.
                    due_beat = Some((at, b.time_s + 1e-9, grid));
                }
            }
            // Stamped when the last send_to has returned: what a receiver can see.
            let sent = Instant::now();
            let done_ns = sent.duration_since(epoch).as_nanos() as u64;
            index += 1;
            stats.frames_sent.fetch_add(1, Ordering::Relaxed);
            if late {
                stats.late_frames.fetch_add(1, Ordering::Relaxed);
            }
            // How much later than intended it left: a frame showing audio heard at `ingest`
            // is due `lead` before it.
            let latency = (done_ns as f64 - ingest_ns as f64) * 1e-9 + lead_s;
            stats.latency.record_s(latency);
            stats
                .tick_to_sent
                .record_s(sent.saturating_duration_since(deadline).as_secs_f64());
            if let Some(prev) = last_sent {
                let spacing = sent.duration_since(prev).as_secs_f64();
                stats
                    .jitter
                    .record_s((spacing - period.as_secs_f64()).abs());
            }
            last_sent = Some(sent);
        }
        while let Ok(e) = queues.events.pop() {
            sink.send_event(&e);
        }
        stats
            .packets_sent
            .store(sink.packets_sent(), Ordering::Relaxed);
        let losses = sink.losses();
        stats
            .send_errors
            .store(losses.send_errors, Ordering::Relaxed);
        stats
            .non_finite_replaced
            .store(losses.non_finite_replaced, Ordering::Relaxed);
        stats
            .vrchat_missing_bones
            .store(losses.vrchat_missing_bones, Ordering::Relaxed);
        deadline += period;
        let now = Instant::now();
        if now > deadline + period {
            // Fell more than a tick behind (machine stalled): rejoin the grid instead of bursting.
            let behind = (now - deadline).as_nanos() / period.as_nanos();
            deadline += period * behind as u32;
            // The spacing across the stall is not jitter of the steady stream.
            last_sent = None;
            stats.sender_stalls.fetch_add(1, Ordering::Relaxed);
        }
    }
    sink
}
