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
    #[test]
    fn ticks_go_out_evenly_from_a_start_on_the_bar_and_stop_at_the_end() {
        // The thread on a fixed grid into a recorder (the bench's measurement, shortened).
        let row = crate::bench::clock::midi_clock_out(150.0, 2.0, false).unwrap();
        assert!(row.ticks >= 100, "{row:?}");
        assert!(row.started_on_a_bar && row.stopped_at_end, "{row:?}");
        assert!(row.spacing_jitter_ms_p50 < 1.0, "{row:?}");
        assert!(row.receiver_tempo_error_p50 < 0.1, "{row:?}");
        assert_eq!(row.restarts, 0, "{row:?}");
    }
}
