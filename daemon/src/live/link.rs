//! Ableton Link (the Link SDK through `rusty_link`, GPL-2.0-or-later: built with the `link`
//! feature only). A thread of its own joins the session and, every couple of milliseconds,
//! either hands the session's grid to the clock desk (when the grid follows Link) or proposes
//! the grid followed — the beats heard, a MIDI clock, taps — to the session, tempo and bar
//! phase, so the room's visuals lock to the music danced to. Link's own calls may lock; this
//! thread is not one of the real-time ones.

/// Whether this build can join a Link session.
pub const AVAILABLE: bool = cfg!(feature = "link");

/// A proposed phase this close to the session's (ms) is left alone: Link broadcasts each
/// change to every peer.
pub const LEAD_PHASE_TOLERANCE_MS: f64 = 1.0;

/// A proposed tempo this close to the session's (BPM) is left alone.
pub const LEAD_TEMPO_TOLERANCE_BPM: f64 = 0.01;

#[cfg(feature = "link")]
pub use session::spawn;

#[cfg(feature = "link")]
mod session {
    use std::sync::atomic::Ordering;
    use std::thread::JoinHandle;
    use std::time::Duration;

    use protocols::ClockGrid;
    use rusty_link::{AblLink, SessionState};

    use super::super::clock::{ClockDesk, ClockSource};
    use super::super::context::LiveContext;
    use super::{LEAD_PHASE_TOLERANCE_MS, LEAD_TEMPO_TOLERANCE_BPM};

    /// How often the session is looked at.
    const POLL: Duration = Duration::from_millis(2);

    /// Joins the Link session until the run stops. `led` is the grid followed, on the run's
    /// wall clock, from the analysis thread.
    pub fn spawn(
        desk: ClockDesk,
        led: triple_buffer::Output<Option<ClockGrid>>,
        ctx: &LiveContext,
    ) -> std::io::Result<JoinHandle<()>> {
        let ctx = ctx.clone();
        std::thread::Builder::new()
            .name("danced-link".into())
            .spawn(move || run(desk, led, ctx))
    }

    fn run(desk: ClockDesk, mut led: triple_buffer::Output<Option<ClockGrid>>, ctx: LiveContext) {
        let link = AblLink::new(120.0);
        link.enable(true);
        let mut state = SessionState::new();
        // Link's host clock and the run's epoch are both the monotonic clock: one offset.
        let link_minus_epoch = link.clock_micros() as f64 - desk.now_us();
        let mut last_peers = u64::MAX;
        while !ctx.stop.load(Ordering::Relaxed) {
            link.capture_app_session_state(&mut state);
            let peers = link.num_peers();
            let now_link = link.clock_micros();
            if desk.source() == ClockSource::Link {
                let quantum = f64::from(desk.beats_per_bar());
                let grid = (peers > 0)
                    .then(|| {
                        ClockGrid::new(
                            now_link as f64 - link_minus_epoch,
                            state.beat_at_time(now_link, quantum),
                            state.tempo(),
                            quantum as u32,
                        )
                    })
                    .flatten();
                desk.set_link(grid, peers as u32);
                last_peers = peers;
            } else {
                if peers != last_peers {
                    desk.set_link(None, peers as u32);
                    last_peers = peers;
                }
                if let Some(g) = *led.read() {
                    lead(&link, &mut state, &g, link_minus_epoch);
                }
            }
            std::thread::sleep(POLL);
        }
        link.enable(false);
    }

    /// Proposes `grid` (on the run's clock) to the session: its tempo, and its bar phase at
    /// its next beat.
    fn lead(link: &AblLink, state: &mut SessionState, grid: &ClockGrid, link_minus_epoch: f64) {
        let quantum = f64::from(grid.beats_per_bar.max(1));
        let at = (grid.anchor_us + link_minus_epoch) as i64;
        let tempo = grid.tempo_bpm();
        let mut changed = false;
        if (state.tempo() - tempo).abs() > LEAD_TEMPO_TOLERANCE_BPM {
            state.set_tempo(tempo, at);
            changed = true;
        }
        let session_beat = state.beat_at_time(at, quantum);
        // The session's beat at `at` with the grid's place in the bar: the nearest such.
        let target =
            grid.anchor_beat + quantum * ((session_beat - grid.anchor_beat) / quantum).round();
        if (target - session_beat).abs() * grid.period_us > LEAD_PHASE_TOLERANCE_MS * 1e3 {
            // Forcing is what the SDK offers a peer that syncs the session to an outside
            // timeline: here, the music in the room.
            state.force_beat_at_time(target, at, quantum);
            changed = true;
        }
        if changed {
            link.commit_app_session_state(state);
        }
    }
}
