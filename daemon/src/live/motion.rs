//! The motion thread: one `MotionSource::step` per analysed feature frame, for the model frame
//! `horizon` frames past it (the newest frame predicted to that time, `dsp::FeatureFrame::
//! predicted_at`), so the pose for the music heard now exists before it is shown; with the
//! performer's controls applied (key poses quantised to the beat grid the analysis predicts).

use std::sync::atomic::Ordering;
use std::time::Duration;

use dsp::BeatGrid;
use dsp::feature::FEATURE_DIM;
use glam::Quat;
use model::rig::{JOINT_COUNT, Pose};
use model::source::{Controls, KeyPoseTarget, MotionSource};

use super::analysis::FeatureMsg;
use super::context::LiveContext;
use super::control_queue::{ControlReceiver, MotionCommand};
use super::stats::{KEY_POSE_NONE, KEY_POSE_PENDING, KEY_POSE_REACHED};
use super::timeline::TimedPose;
use super::wire::Quantize;
use crate::alloc_counter::{CountGuard, RtThread};

/// Beat period assumed when neither the analysis nor a tempo hint gives one (120 BPM).
const FALLBACK_PERIOD_S: f64 = 0.5;

/// The audio time at which a control quantised with `q` takes effect, seen from model time
/// `now_s`, given the latest beat grid, a tempo hint (BPM, 0 = none) and the transition length
/// used by [`Quantize::Now`].
pub fn quantize_target(
    q: &Quantize,
    now_s: f64,
    grid: &BeatGrid,
    tempo_hint_bpm: f32,
    transition_beats: f32,
    model_rate: f64,
) -> f64 {
    let period = if grid.locked && grid.period_s > 0.0 {
        grid.period_s
    } else if tempo_hint_bpm > 0.0 {
        60.0 / f64::from(tempo_hint_bpm)
    } else {
        FALLBACK_PERIOD_S
    };
    // The first beat at least half a model frame ahead (a beat "now" is too late to reach).
    let earliest = now_s + 0.5 / model_rate;
    let (first, index) = match grid.beat_after(earliest) {
        Some(b) if grid.locked && grid.period_s > 0.0 => (b.time_s, b.index_in_bar),
        _ => (now_s + period, 1),
    };
    match q {
        Quantize::Now => now_s + f64::from(transition_beats.max(0.0)) * period,
        Quantize::NextBeat => first,
        Quantize::InBeats(0) => now_s,
        Quantize::InBeats(n) => first + f64::from(n - 1) * period,
        Quantize::NextBar => {
            let bpb = grid.beats_per_bar.max(1);
            let to_downbeat = (bpb + 1 - index.min(bpb)) % bpb;
            first + f64::from(to_downbeat) * period
        }
    }
}

/// Settings of the motion thread.
#[derive(Clone, Copy, Debug)]
pub struct MotionSettings {
    /// Initial temperature.
    pub temperature: f32,
    /// Initial transition length (beats) for `Quantize::Now` key poses.
    pub transition_beats: f32,
    /// Initial beat accent (None: the source's own).
    pub beat_accent: Option<f32>,
    /// Initial dance style.
    pub style: model::style::StyleRequest,
    /// Model frames past the newest analysed frame each pose is made for (at least the
    /// source's look-ahead; see `model::horizon`).
    pub horizon_frames: usize,
}

struct KeyPose {
    pose: u16,
    target_s: f64,
}

struct State {
    controls: Controls,
    transition_beats: f32,
    tempo_hint: f32,
    paused: bool,
    key: Option<KeyPose>,
}

/// The motion thread's ends of its queues.
pub struct MotionQueues {
    /// Feature frames from the analysis thread (which unparks this thread after each).
    pub features: rtrb::Consumer<FeatureMsg>,
    /// The performer's controls.
    pub controls: ControlReceiver,
    /// Poses to the sender thread.
    pub poses: rtrb::Producer<TimedPose>,
}

/// Runs the motion thread until the analysis thread is gone or `stop` is set. `table` holds
/// the key poses by the indices the control path resolved names to.
pub fn run(
    mut source: Box<dyn MotionSource + Send>,
    table: Vec<[Quat; JOINT_COUNT]>,
    settings: MotionSettings,
    ctx: LiveContext,
    mut queues: MotionQueues,
) {
    let LiveContext { epoch, stats, stop } = ctx;
    let rate = source.frame_rate();
    let look = source.lookahead_frames();
    let need = look + 1;
    // The pose for `times[0]` is made once its look-ahead has been predicted too.
    let ahead_s = settings.horizon_frames.max(look) as f64 / rate;
    let mut window: Vec<[f32; FEATURE_DIM]> = Vec::with_capacity(need);
    let mut times: Vec<f64> = Vec::with_capacity(need);
    let mut pose = Pose::rest();
    let mut grid = BeatGrid::default();
    let mut st = State {
        controls: Controls {
            temperature: settings.temperature,
            key_pose: None,
            beat_accent: settings.beat_accent,
            style: settings.style,
            key_route: None,
        },
        transition_beats: settings.transition_beats,
        tempo_hint: 0.0,
        paused: false,
        key: None,
    };
    let mut next_time = 0.0f64;
    // Everything above is set-up; from here on nothing may allocate.
    let _counting = CountGuard::new(RtThread::Motion);
    while !stop.load(Ordering::Relaxed) {
        let now_s = times.first().copied().unwrap_or(next_time);
        queues.controls.poll(|c| {
            apply(&mut st, c, &mut *source, now_s, &grid, rate);
        });
        stats.temperature.set(st.controls.temperature);
        stats
            .beat_accent
            .set(st.controls.beat_accent.unwrap_or(f32::NAN));
        stats.paused.store(u32::from(st.paused), Ordering::Relaxed);
        let report = source.report();
        stats.set_key_route(report.key_route);
        stats.set_style_danced(
            report.style,
            st.controls.style == model::style::StyleRequest::Auto,
        );
        let msg = match queues.features.pop() {
            Ok(m) => m,
            Err(_) if queues.features.is_abandoned() => break,
            Err(_) => {
                // Woken by the analysis thread as soon as a frame is queued.
                std::thread::park_timeout(Duration::from_millis(5));
                continue;
            }
        };
        grid = msg.frame.grid;
        let predicted_s = msg.frame.time_s + ahead_s;
        window.push(msg.frame.predicted_at(predicted_s));
        times.push(predicted_s);
        if window.len() < need {
            continue;
        }
        let t = times[0];
        st.controls.key_pose = st.key.as_ref().and_then(|k| {
            Some(KeyPoseTarget {
                rotations: *table.get(usize::from(k.pose))?,
                frames_to_go: ((k.target_s - t) * rate).round().max(0.0) as u32,
            })
        });
        if let Some(k) = &st.key {
            stats
                .key_pose_index
                .store(u32::from(k.pose), Ordering::Relaxed);
        }
        match st.controls.key_pose {
            Some(k) => {
                stats
                    .key_pose_state
                    .store(KEY_POSE_PENDING, Ordering::Relaxed);
                stats
                    .key_pose_frames_to_go
                    .store(k.frames_to_go, Ordering::Relaxed);
            }
            None if stats.key_pose_state.load(Ordering::Relaxed) == KEY_POSE_PENDING => {
                stats.key_pose_state.store(KEY_POSE_NONE, Ordering::Relaxed);
            }
            None => {}
        }
        if !st.paused {
            source.step(&window, &st.controls, &mut pose);
        }
        if st.controls.key_pose.is_some_and(|k| k.frames_to_go == 0) {
            // A key pose is a one-shot hit: reached on this frame, then the dance goes on.
            st.key = None;
            stats
                .key_pose_state
                .store(KEY_POSE_REACHED, Ordering::Relaxed);
        }
        if queues
            .poses
            .push(TimedPose {
                time_s: t,
                pose,
                grid,
            })
            .is_err()
        {
            stats.poses_dropped.fetch_add(1, Ordering::Relaxed);
        }
        let now_ns = epoch.elapsed().as_nanos() as u64;
        stats
            .processing
            .record_s(now_ns.saturating_sub(msg.ingest_wall_ns) as f64 * 1e-9);
        stats.model_frames.fetch_add(1, Ordering::Relaxed);
        let report = source.report();
        if let Some(c) = report.safety {
            stats.safety.store(&c);
        }
        if let Some(c) = report.stage {
            stats.stage.store(&c);
        }
        if let Some(m) = report.moves {
            stats.moves.store(1 + m.active as u32, Ordering::Relaxed);
            stats.moves_switches.store(m.switches, Ordering::Relaxed);
        }
        next_time = t + 1.0 / rate;
        window.remove(0);
        times.remove(0);
    }
}

/// Applies one control (already validated and resolved by the control path).
fn apply(
    st: &mut State,
    command: MotionCommand,
    source: &mut dyn MotionSource,
    now_s: f64,
    grid: &BeatGrid,
    rate: f64,
) {
    match command {
        MotionCommand::Temperature(t) => st.controls.temperature = t,
        MotionCommand::BeatAccent(a) => st.controls.beat_accent = Some(a),
        MotionCommand::KeyPose { pose, quantize } => {
            let target_s = quantize_target(
                &quantize,
                now_s,
                grid,
                st.tempo_hint,
                st.transition_beats,
                rate,
            );
            st.key = Some(KeyPose { pose, target_s });
        }
        MotionCommand::ClearKeyPose => st.key = None,
        MotionCommand::TransitionBeats(b) => st.transition_beats = b,
        MotionCommand::StyleSeed(seed) => source.reseed(seed),
        MotionCommand::DanceStyle(style) => st.controls.style = style,
        MotionCommand::KeyPoseRoute(route) => st.controls.key_route = Some(route),
        MotionCommand::Pause => st.paused = true,
        MotionCommand::Resume => st.paused = false,
        MotionCommand::TempoHint(bpm) => st.tempo_hint = bpm,
        MotionCommand::Moves { index, at } => {
            // The control path only passes on sets the dancer holds.
            source.select_moves(usize::from(index), at);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid() -> BeatGrid {
        // Beats every 0.5 s at …, 10.0, 10.5 (index 2 of 4 at 10.0).
        BeatGrid {
            next_beat_s: 10.0,
            period_s: 0.5,
            next_index_in_bar: 2,
            beats_per_bar: 4,
            bar_confidence: 1.0,
            locked: true,
        }
    }

    #[test]
    fn quantises_to_beats_and_bars() {
        let g = grid();
        let q = |q: Quantize, now| quantize_target(&q, now, &g, 0.0, 1.0, 25.0);
        assert!((q(Quantize::NextBeat, 9.2) - 9.5).abs() < 1e-9);
        assert!((q(Quantize::NextBeat, 9.99) - 10.5).abs() < 1e-9);
        assert!((q(Quantize::InBeats(3), 9.2) - 10.5).abs() < 1e-9);
        // 9.5 is beat 1 (10.0 is beat 2), so the next downbeat after 9.6 is 11.5.
        assert!((q(Quantize::NextBar, 9.6) - 11.5).abs() < 1e-9);
        assert!((q(Quantize::NextBar, 9.2) - 9.5).abs() < 1e-9);
        assert!((q(Quantize::Now, 9.2) - 9.7).abs() < 1e-9);
    }
}
