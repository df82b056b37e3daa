//! The MIDI clock danced sends: a thread of its own that reads the grid followed (on the wall
//! clock, from the analysis thread) and sends Start, a tick every 24th of a beat and Stop, each
//! when it is due. It sleeps to within half a millisecond of a tick and spins the rest, as the
//! sender thread does, so the ticks' spacing is as even as the machine allows.

use std::sync::atomic::Ordering;
use std::thread::JoinHandle;
use std::time::Duration;

use protocols::{ClockGrid, MidiClockLeader, MidiMessage};

use super::context::LiveContext;
use crate::alloc_counter::{CountGuard, RtThread};

/// How long before a message is due the thread stops sleeping and spins.
const SPIN_BEFORE_US: f64 = 1500.0;
/// Longest nap between looks at the grid, µs (a new grid is seen within this).
const MAX_NAP_US: f64 = 5_000.0;

/// Where the clock's bytes go: a MIDI output port, or a test's recorder.
pub trait ClockPort: Send {
    /// Sends one message; false when it could not go out.
    fn send(&mut self, bytes: &[u8]) -> bool;
}

impl ClockPort for protocols::MidiOutConnection {
    fn send(&mut self, bytes: &[u8]) -> bool {
        protocols::MidiOutConnection::send(self, bytes)
    }
}

/// Starts the thread; it ends when the run stops (sending Stop if it had started).
pub fn spawn(
    port: Box<dyn ClockPort>,
    grid: triple_buffer::Output<Option<ClockGrid>>,
    ctx: &LiveContext,
    realtime: bool,
) -> std::io::Result<JoinHandle<()>> {
    let ctx = ctx.clone();
    std::thread::Builder::new()
        .name("danced-midi-clock".into())
        .spawn(move || {
            if realtime && super::priority::promote_current_thread(super::priority::SENDER_PRIORITY)
            {
                ctx.stats.realtime_threads.fetch_add(1, Ordering::Relaxed);
            }
            run(port, grid, ctx)
        })
}

fn run(
    mut port: Box<dyn ClockPort>,
    mut grid: triple_buffer::Output<Option<ClockGrid>>,
    ctx: LiveContext,
) {
    let LiveContext { epoch, stats, stop } = ctx;
    #[cfg(target_os = "linux")]
    // SAFETY: PR_SET_TIMERSLACK only changes this thread's timer slack.
    unsafe {
        libc::prctl(libc::PR_SET_TIMERSLACK, 50_000 as libc::c_ulong);
    }
    let now_us = || epoch.elapsed().as_secs_f64() * 1e6;
    let mut leader = MidiClockLeader::new();
    let send = |port: &mut Box<dyn ClockPort>, m: MidiMessage| {
        let (bytes, n) = m.to_bytes();
        let c = &stats.clock;
        if !port.send(&bytes[..n]) {
            c.midi_send_errors.fetch_add(1, Ordering::Relaxed);
        } else if m == MidiMessage::Clock {
            c.midi_ticks_sent.fetch_add(1, Ordering::Relaxed);
        }
    };
    let _counting = CountGuard::new(RtThread::ClockOut);
    while !stop.load(Ordering::Relaxed) {
        let g = *grid.read();
        // Planned on a copy: until it is due, a newer grid re-plans it.
        let mut plan = leader;
        let now = now_us();
        let Some((due, message)) = plan.next(g.as_ref(), now) else {
            std::thread::sleep(Duration::from_micros(MAX_NAP_US as u64));
            continue;
        };
        let wait = due - now;
        if wait > SPIN_BEFORE_US {
            let nap = (wait - SPIN_BEFORE_US).min(MAX_NAP_US);
            std::thread::sleep(Duration::from_micros(nap as u64));
            if wait - nap > SPIN_BEFORE_US {
                continue;
            }
        }
        while now_us() < due {
            std::hint::spin_loop();
        }
        send(&mut port, message);
        leader = plan;
        stats
            .clock
            .midi_restarts
            .store(leader.restarts(), Ordering::Relaxed);
    }
    if leader.started() {
        send(&mut port, MidiMessage::Stop);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::{Arc, Mutex};

    /// Records when each message went out, µs since the run's epoch.
    struct Recorder {
        epoch: std::time::Instant,
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

    #[test]
    fn ticks_go_out_evenly_from_a_start_on_the_bar_and_stop_at_the_end() {
        let ctx = LiveContext::new();
        let sent = Arc::new(Mutex::new(Vec::with_capacity(1000)));
        let (mut input, output) = triple_buffer::triple_buffer(&None);
        // 150 BPM, beat 0 at 0.1 s.
        let grid = ClockGrid::new(100_000.0, 0.0, 150.0, 4).unwrap();
        input.write(Some(grid));
        let port = Recorder {
            epoch: ctx.epoch,
            sent: sent.clone(),
        };
        let handle = spawn(Box::new(port), output, &ctx, false).unwrap();
        let deadline = std::time::Instant::now() + Duration::from_secs(10);
        while ctx.stats.clock.midi_ticks_sent.load(Ordering::Relaxed) < 96 {
            assert!(std::time::Instant::now() < deadline, "ticks stopped coming");
            std::thread::sleep(Duration::from_millis(10));
        }
        ctx.stop.store(true, Ordering::Relaxed);
        handle.join().unwrap();
        let sent = sent.lock().unwrap().clone();
        assert_eq!(sent[0].1, 0xfa, "Start first");
        assert_eq!(sent.last().unwrap().1, 0xfc, "Stop last");
        let ticks: Vec<f64> = sent.iter().filter(|s| s.1 == 0xf8).map(|s| s.0).collect();
        // The first tick is the first beat of the first bar not yet begun: beat 0 at 0.1 s.
        assert!(
            (ticks[0] - grid.time_of(0.0)).abs() < 2_000.0,
            "{}",
            ticks[0]
        );
        let period = grid.period_us / 24.0;
        let mut errors: Vec<f64> = ticks
            .iter()
            .enumerate()
            .map(|(i, t)| (t - grid.time_of(i as f64 / 24.0)).abs())
            .collect();
        errors.sort_by(f64::total_cmp);
        let p50 = errors[errors.len() / 2];
        assert!(
            p50 < 1_000.0,
            "median tick {p50:.0} µs from due (tick every {period:.0} µs)"
        );
        assert_eq!(
            crate::alloc_counter::allocations(RtThread::ClockOut),
            0,
            "the tick loop allocated"
        );
    }
}
