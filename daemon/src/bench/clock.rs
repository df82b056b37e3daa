//! The show's clock, measured: an incoming MIDI clock followed from jittered timestamps (tempo,
//! phase, bar), the MIDI clock danced sends (tick spacing, and what a receiver reads back),
//! and, in builds with Link, a Link session followed and led, each against a separate Link
//! peer (`link-peer`, the SDK alone) in a network namespace of the bench's own.

use std::sync::atomic::Ordering;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use anyhow::Result;
use protocols::{ClockGrid, MidiClockFollower, MidiMessage};
use serde::Serialize;

use crate::live::context::LiveContext;
use crate::live::midi_clock_out::{self, ClockPort};

/// A tiny deterministic generator for timestamp jitter.
fn lcg(state: &mut u64) -> f64 {
    *state = state
        .wrapping_mul(6364136223846793005)
        .wrapping_add(1442695040888963407);
    (*state >> 11) as f64 / (1u64 << 53) as f64
}

/// Quantile `q` of `v` (sorted here); NaN when empty.
pub fn quantile(v: &[f64], q: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    s[((s.len() - 1) as f64 * q).round() as usize]
}

/// How well an incoming MIDI clock is followed at one tempo.
#[derive(Clone, Debug, Serialize)]
pub struct MidiInRow {
    /// The clock's tempo, BPM.
    pub bpm: f64,
    /// Timestamp jitter, ± µs (uniform).
    pub jitter_us: f64,
    /// |tempo read − true|, BPM: median and largest, from two beats after Continue.
    pub tempo_error_p50: f64,
    /// See `tempo_error_p50`.
    pub tempo_error_max: f64,
    /// |predicted time of the next beat − true|, ms: median and 95th percentile.
    pub phase_error_ms_p50: f64,
    /// See `phase_error_ms_p50`.
    pub phase_error_ms_p95: f64,
    /// Share of beats whose place in the bar (from Start and Song Position Pointer) is right.
    pub bar_right: f64,
}

/// Follows `seconds` of MIDI clock at `bpm` whose stamps jitter by ± `jitter_us`, started by a
/// Song Position Pointer (bar 3) and Continue: after every tick from two beats on (the
/// follower has heard half its window), the tempo read and the next beat predicted are
/// compared with the truth.
pub fn midi_clock_in(bpm: f64, jitter_us: f64, seconds: f64, seed: u64) -> MidiInRow {
    let mut f = MidiClockFollower::new();
    let mut rng = seed;
    let tick_us = 60e6 / bpm / 24.0;
    let t0 = 1e6;
    // Bar 3 (0-based beat 8): sixteenth 32.
    f.message(t0 as u64 - 10_000, &MidiMessage::SongPosition(32));
    f.message(t0 as u64 - 5_000, &MidiMessage::Continue);
    let (mut tempo_err, mut phase_err) = (Vec::new(), Vec::new());
    let (mut bars, mut bars_right) = (0u32, 0u32);
    let ticks = (seconds * 1e6 / tick_us) as u64;
    for k in 0..ticks {
        let t = t0 + k as f64 * tick_us;
        let stamp = (t + (lcg(&mut rng) * 2.0 - 1.0) * jitter_us) as u64;
        f.message(stamp, &MidiMessage::Clock);
        if k < 48 {
            continue;
        }
        let Some(g) = f.grid(stamp, 4) else { continue };
        tempo_err.push((g.tempo_bpm() - bpm).abs());
        // The next beat after this tick, as predicted, against its true time.
        let next = g.beat_at(t).floor() + 1.0;
        let true_next = t0 + (next - 8.0) * 24.0 * tick_us;
        phase_err.push((g.time_of(next) - true_next).abs() * 1e-3);
        if k % 24 == 0 {
            bars += 1;
            let beat = 8 + (k / 24) as i64;
            bars_right += u32::from(g.index_in_bar(beat) == (beat % 4) as u32 + 1);
        }
    }
    MidiInRow {
        bpm,
        jitter_us,
        tempo_error_p50: quantile(&tempo_err, 0.5),
        tempo_error_max: tempo_err.iter().copied().fold(0.0, f64::max),
        phase_error_ms_p50: quantile(&phase_err, 0.5),
        phase_error_ms_p95: quantile(&phase_err, 0.95),
        bar_right: f64::from(bars_right) / f64::from(bars.max(1)),
    }
}

/// What the MIDI clock danced sends looks like at one tempo.
#[derive(Clone, Debug, Serialize)]
pub struct MidiOutRow {
    /// The grid's tempo, BPM.
    pub bpm: f64,
    /// Ticks sent.
    pub ticks: usize,
    /// |tick spacing − period|, ms: median, 99th percentile, largest.
    pub spacing_jitter_ms_p50: f64,
    /// See `spacing_jitter_ms_p50`.
    pub spacing_jitter_ms_p99: f64,
    /// See `spacing_jitter_ms_p50`.
    pub spacing_jitter_ms_max: f64,
    /// |send time − the nearest tick of the grid|, ms, 99th percentile.
    pub lateness_ms_p99: f64,
    /// |tempo a receiver reads − the grid's|, BPM, from one beat on: median and largest.
    pub receiver_tempo_error_p50: f64,
    /// See `receiver_tempo_error_p50`.
    pub receiver_tempo_error_max: f64,
    /// Transport restarts (a stall longer than a quarter beat).
    pub restarts: u64,
    /// Whether the first tick fell on a bar's first beat.
    pub started_on_a_bar: bool,
    /// Whether Stop went out when the thread ended.
    pub stopped_at_end: bool,
}

/// Records when each message was handed to the port, µs since the run's epoch.
struct Recorder {
    epoch: Instant,
    sent: Arc<Mutex<Vec<(f64, u8)>>>,
}

impl ClockPort for Recorder {
    fn send(&mut self, bytes: &[u8]) -> bool {
        let t = self.epoch.elapsed().as_secs_f64() * 1e6;
        if let Ok(mut v) = self.sent.lock() {
            v.push((t, bytes[0]));
        }
        true
    }
}

/// Runs the MIDI clock thread on a fixed grid at `bpm` for `seconds` into a recorder: when each
/// tick went out, and what a follower of those ticks reads.
pub fn midi_clock_out(bpm: f64, seconds: f64, realtime: bool) -> Result<MidiOutRow> {
    let ctx = LiveContext::new();
    let ticks_wanted = (seconds * bpm / 60.0 * 24.0) as usize;
    let sent = Arc::new(Mutex::new(Vec::with_capacity(ticks_wanted + 64)));
    let (mut input, output) = triple_buffer::triple_buffer(&None);
    let grid = ClockGrid::new(200_000.0, 0.0, bpm, 4).expect("a tempo in range");
    input.write(Some(grid));
    let port = Recorder {
        epoch: ctx.epoch,
        sent: sent.clone(),
    };
    let handle = midi_clock_out::spawn(Box::new(port), output, &ctx, realtime)?;
    let deadline = Instant::now() + Duration::from_secs_f64(seconds + 10.0);
    while (ctx.stats.clock.midi_ticks_sent.load(Ordering::Relaxed) as usize) < ticks_wanted
        && Instant::now() < deadline
    {
        std::thread::sleep(Duration::from_millis(20));
    }
    ctx.stop.store(true, Ordering::Relaxed);
    if handle.join().is_err() {
        anyhow::bail!("the MIDI clock thread panicked");
    }
    let sent = sent.lock().map(|v| v.clone()).unwrap_or_default();
    let ticks: Vec<f64> = sent.iter().filter(|s| s.1 == 0xf8).map(|s| s.0).collect();
    let period = grid.period_us / 24.0;
    let spacing: Vec<f64> = ticks
        .windows(2)
        .map(|w| ((w[1] - w[0]) - period).abs() * 1e-3)
        .collect();
    let first_beat = ticks
        .first()
        .map(|&t| grid.beat_at(t).round())
        .unwrap_or(0.0);
    let lateness: Vec<f64> = ticks
        .iter()
        .map(|&t| {
            let nearest = (grid.beat_at(t) * 24.0).round() / 24.0;
            (t - grid.time_of(nearest)).abs() * 1e-3
        })
        .collect();
    let mut follower = MidiClockFollower::new();
    let mut receiver_errors = Vec::with_capacity(ticks.len());
    for &(t, status) in &sent {
        let message = match status {
            0xfa => MidiMessage::Start,
            0xfc => MidiMessage::Stop,
            _ => MidiMessage::Clock,
        };
        follower.message(t as u64, &message);
        if let Some(b) = follower.tempo_bpm(t as u64)
            && follower.running()
        {
            receiver_errors.push((b - bpm).abs());
        }
    }
    // From one beat of ticks on.
    let receiver_errors = receiver_errors.get(24..).unwrap_or(&[]);
    Ok(MidiOutRow {
        bpm,
        ticks: ticks.len(),
        spacing_jitter_ms_p50: quantile(&spacing, 0.5),
        spacing_jitter_ms_p99: quantile(&spacing, 0.99),
        spacing_jitter_ms_max: spacing.iter().copied().fold(0.0, f64::max),
        lateness_ms_p99: quantile(&lateness, 0.99),
        receiver_tempo_error_p50: quantile(receiver_errors, 0.5),
        receiver_tempo_error_max: receiver_errors.iter().copied().fold(0.0, f64::max),
        restarts: ctx.stats.clock.midi_restarts.load(Ordering::Relaxed),
        started_on_a_bar: sent.first().is_some_and(|s| s.1 == 0xfa)
            && (first_beat as i64).rem_euclid(4) == 0,
        stopped_at_end: sent.last().is_some_and(|s| s.1 == 0xfc),
    })
}

/// CLOCK_MONOTONIC now, µs (the clock Link peers on this machine compare on).
pub fn monotonic_us() -> f64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: clock_gettime only writes the struct we pass.
    unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    ts.tv_sec as f64 * 1e6 + ts.tv_nsec as f64 * 1e-3
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_jittered_midi_clock_is_read_within_the_targets() {
        for bpm in [90.0, 128.0, 174.0] {
            let r = midi_clock_in(bpm, 1_000.0, 20.0, 3);
            assert!(r.tempo_error_max < 0.2, "{r:?}");
            assert!(r.phase_error_ms_p95 < 5.0, "{r:?}");
            assert_eq!(r.bar_right, 1.0, "{r:?}");
        }
    }
}
