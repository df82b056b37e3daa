//! MIDI clock, both ways: following a DAW's, drum machine's or DJ software's 24 ticks a beat
//! (tempo, beat phase, and the bar from Start and Song Position Pointer), and leading one from
//! a beat grid (the ticks, Start and Stop a receiver needs, each with the time it is due).

use crate::clock_grid::{CLOCK_TEMPO_RANGE, ClockGrid};
use crate::midi::MidiMessage;

/// Ticks of MIDI clock per quarter note.
pub const TICKS_PER_BEAT: usize = 24;

/// Ticks per Song Position Pointer unit (a sixteenth note).
pub const TICKS_PER_SIXTEENTH: u64 = 6;

/// A silence between ticks longer than this (µs) means the clock stopped.
pub const MAX_TICK_GAP_US: u64 = 1_000_000;

/// Ticks the line is fitted through: four beats, so 1 ms of timestamp jitter moves the tempo
/// by a few hundredths of a BPM and the phase by a tenth of a millisecond.
const HISTORY: usize = 4 * TICKS_PER_BEAT;

/// A tick this far (µs) from where the fitted line puts it, twice in a row, means the tempo
/// changed: the fit restarts from the newest ticks instead of averaging over the change.
const CHANGE_US: f64 = 3_000.0;

/// Ticks kept after a tempo change is detected (the fit needs two).
const AFTER_CHANGE: usize = 3;

/// Ticks the line must run through before a tick off it counts as a tempo change: fewer
/// predict the next tick no better than the jitter.
const CHANGE_AFTER_TICKS: usize = 12;

/// Follows an incoming MIDI clock: a straight line through the last ticks' timestamps gives
/// the tempo and where each tick (so each beat) falls; Start (the next tick is the song's
/// first beat) or Song Position Pointer then Continue give the beat count, so the bar.
///
/// Tick timestamps jitter by a millisecond or more (USB polling, ALSA scheduling), ±5 % of a
/// tick at 120 BPM; a least-squares line over two beats of ticks averages that away.
#[derive(Clone, Debug)]
pub struct MidiClockFollower {
    /// (song position in ticks, timestamp µs), a ring; the newest at `head − 1`.
    ticks: [(u64, u64); HISTORY],
    count: usize,
    head: usize,
    /// Song position (ticks) of the next tick to arrive.
    position: u64,
    /// Whether the transport runs (Start or Continue seen, no Stop since).
    running: bool,
    /// Whether `position` is the song's (Start or a Song Position Pointer was seen).
    position_known: bool,
    /// Consecutive ticks off the fitted line.
    off_line: u32,
    /// Tempo changes detected so far.
    tempo_changes: u64,
}

impl Default for MidiClockFollower {
    fn default() -> Self {
        Self {
            ticks: [(0, 0); HISTORY],
            count: 0,
            head: 0,
            position: 0,
            running: false,
            position_known: false,
            off_line: 0,
            tempo_changes: 0,
        }
    }
}

impl MidiClockFollower {
    /// A follower that has heard nothing.
    pub fn new() -> Self {
        Self::default()
    }

    /// Feeds one message received at `timestamp_us` (any monotonic µs clock); returns whether
    /// it was a clock or transport message (the others are not its business).
    pub fn message(&mut self, timestamp_us: u64, message: &MidiMessage) -> bool {
        match *message {
            MidiMessage::Clock => self.tick(timestamp_us),
            MidiMessage::Start => {
                self.position = 0;
                self.position_known = true;
                self.running = true;
                self.forget_ticks();
            }
            MidiMessage::Continue => {
                self.running = true;
                self.forget_ticks();
            }
            MidiMessage::Stop => {
                self.running = false;
            }
            MidiMessage::SongPosition(sixteenths) => {
                self.position = u64::from(sixteenths) * TICKS_PER_SIXTEENTH;
                self.position_known = true;
                self.forget_ticks();
            }
            _ => return false,
        }
        true
    }

    /// Whether the transport runs.
    pub fn running(&self) -> bool {
        self.running
    }

    /// Tempo changes seen so far (each restarted the fit).
    pub fn tempo_changes(&self) -> u64 {
        self.tempo_changes
    }

    /// The tempo at `now_us`, BPM: `None` before three ticks or when the last tick is more
    /// than [`MAX_TICK_GAP_US`] old.
    pub fn tempo_bpm(&self, now_us: u64) -> Option<f64> {
        self.line(now_us)
            .map(|(_, slope)| 60e6 / (slope * TICKS_PER_BEAT as f64))
    }

    /// The beat grid the clock gives at `now_us`: beats counted from the song's start, bars of
    /// `beats_per_bar` from its first beat. `None` while stopped, before three ticks, when the
    /// ticks stopped coming, or before Start or a Song Position Pointer said where the song is.
    pub fn grid(&self, now_us: u64, beats_per_bar: u32) -> Option<ClockGrid> {
        if !self.running || !self.position_known {
            return None;
        }
        let (anchor_us, slope) = self.line(now_us)?;
        let (newest_position, _) = self.newest()?;
        let tempo = 60e6 / (slope * TICKS_PER_BEAT as f64);
        ClockGrid::new(
            anchor_us,
            newest_position as f64 / TICKS_PER_BEAT as f64,
            tempo,
            beats_per_bar,
        )
    }

    /// The fitted time of the newest tick and µs per tick.
    fn line(&self, now_us: u64) -> Option<(f64, f64)> {
        let (_, last) = self.newest()?;
        if self.count < 3 || now_us.saturating_sub(last) > MAX_TICK_GAP_US {
            return None;
        }
        let (intercept, slope) = self.fit()?;
        let slope_ok = (CLOCK_TEMPO_RANGE.0..=CLOCK_TEMPO_RANGE.1)
            .contains(&(60e6 / (slope * TICKS_PER_BEAT as f64)));
        slope_ok.then_some((intercept, slope))
    }

    fn tick(&mut self, timestamp_us: u64) {
        if let Some((_, last)) = self.newest()
            && (timestamp_us < last || timestamp_us - last > MAX_TICK_GAP_US)
        {
            // Out-of-order or long-gap ticks start a fresh measurement rather than poison it.
            self.forget_ticks();
        }
        if self.count >= CHANGE_AFTER_TICKS
            && let Some((newest_fit, slope)) = self.fit()
        {
            let expected = newest_fit + slope;
            if (timestamp_us as f64 - expected).abs() > CHANGE_US {
                self.off_line += 1;
            } else {
                self.off_line = 0;
            }
            if self.off_line >= 2 {
                self.keep_newest(AFTER_CHANGE - 1);
                self.tempo_changes += 1;
                self.off_line = 0;
            }
        }
        self.ticks[self.head] = (self.position, timestamp_us);
        self.head = (self.head + 1) % HISTORY;
        self.count = (self.count + 1).min(HISTORY);
        if self.running {
            self.position += 1;
        }
    }

    fn newest(&self) -> Option<(u64, u64)> {
        (self.count > 0).then(|| self.ticks[(self.head + HISTORY - 1) % HISTORY])
    }

    fn forget_ticks(&mut self) {
        self.count = 0;
        self.off_line = 0;
    }

    fn keep_newest(&mut self, n: usize) {
        self.count = self.count.min(n);
    }

    /// Least squares of timestamp against tick number over the ticks kept: the fitted time of
    /// the newest tick and the µs per tick. Tick numbers are counted by arrival (a stopped
    /// transport's ticks keep their spacing but not the song position).
    fn fit(&self) -> Option<(f64, f64)> {
        let n = self.count;
        if n < 2 {
            return None;
        }
        let oldest = (self.head + HISTORY - n) % HISTORY;
        let t0 = self.ticks[oldest].1 as f64;
        let (mut sx, mut sy, mut sxx, mut sxy) = (0.0, 0.0, 0.0, 0.0);
        for i in 0..n {
            let x = i as f64;
            let y = self.ticks[(oldest + i) % HISTORY].1 as f64 - t0;
            sx += x;
            sy += y;
            sxx += x * x;
            sxy += x * y;
        }
        let nf = n as f64;
        let den = nf * sxx - sx * sx;
        if den <= 0.0 {
            return None;
        }
        let slope = (nf * sxy - sx * sy) / den;
        let intercept = (sy - slope * sx) / nf;
        (slope > 0.0 && slope.is_finite()).then_some((t0 + intercept + slope * (nf - 1.0), slope))
    }
}

/// Ticks a leader may fall behind (a stalled machine) and still catch up by sending the
/// missed ones at once: a quarter of a beat. Further behind, or a grid moved further back, the
/// transport restarts.
pub const CATCH_UP_TICKS: f64 = 6.0;

/// Leads a MIDI clock from a beat grid: which message is due next, and when. The caller
/// sleeps until then and sends it. Start goes out just before a bar's first beat (the tick
/// after Start is the song's first beat), then a tick every 24th of a beat; a grid that is
/// lost stops the transport.
///
/// A receiver counts ticks to know where in the song it is, so none is ever dropped: ticks a
/// stall left behind go out at once (up to [`CATCH_UP_TICKS`]). A grid that jumps further — a
/// nudge, "beat one is now", a new phase — would leave a counting receiver a fraction of a beat
/// off for good: the transport restarts instead (Stop, then Start before the grid's next bar),
/// counted in [`MidiClockLeader::restarts`].
#[derive(Clone, Copy, Debug, Default)]
pub struct MidiClockLeader {
    /// Tick number (24ths of the grid's beats) of the next tick, once started.
    next_tick: Option<i64>,
    restarts: u64,
}

impl MidiClockLeader {
    /// A leader that has sent nothing.
    pub fn new() -> Self {
        Self::default()
    }

    /// Restarts after a jump of the grid.
    pub fn restarts(&self) -> u64 {
        self.restarts
    }

    /// Whether Start has gone out (and Stop not since).
    pub fn started(&self) -> bool {
        self.next_tick.is_some()
    }

    /// The next message and when it is due (µs, on the grid's clock), given the grid now
    /// (`None`: no beat to lead) at `now_us`. Call again after sending it.
    pub fn next(&mut self, grid: Option<&ClockGrid>, now_us: f64) -> Option<(f64, MidiMessage)> {
        let Some(grid) = grid else {
            return self.next_tick.take().map(|_| (now_us, MidiMessage::Stop));
        };
        let per_tick = grid.period_us / TICKS_PER_BEAT as f64;
        match self.next_tick {
            None => {
                // Start half a tick before the first beat of the next whole bar (or beat) that
                // leaves time for it; asked again before it is due, the answer stays.
                let step = if grid.bar_known {
                    i64::from(grid.beats_per_bar.max(1))
                } else {
                    1
                };
                let after = grid.beat_at(now_us + 0.5 * per_tick);
                let first = (after / step as f64).ceil() as i64 * step;
                self.next_tick = Some(first * TICKS_PER_BEAT as i64);
                Some((
                    grid.time_of(first as f64) - 0.5 * per_tick,
                    MidiMessage::Start,
                ))
            }
            Some(tick) => {
                let due = grid.time_of(tick as f64 / TICKS_PER_BEAT as f64);
                let behind = (now_us - due) / per_tick;
                // Normally the next tick is due within a tick from now.
                let ahead = (due - now_us) / per_tick - 1.0;
                if behind > CATCH_UP_TICKS || ahead > CATCH_UP_TICKS {
                    self.next_tick = None;
                    self.restarts += 1;
                    return Some((now_us, MidiMessage::Stop));
                }
                self.next_tick = Some(tick + 1);
                Some((due, MidiMessage::Clock))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A tiny deterministic generator, so the jitter tests are reproducible.
    fn lcg(state: &mut u64) -> f64 {
        *state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (*state >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Feeds `beats` beats of clock at `bpm` from `start_us`, each tick ± `jitter_us`
    /// (uniform); returns the true time of the next tick.
    fn feed(
        f: &mut MidiClockFollower,
        start_us: f64,
        bpm: f64,
        ticks: usize,
        jitter_us: f64,
        rng: &mut u64,
    ) -> f64 {
        let tick_us = 60e6 / bpm / TICKS_PER_BEAT as f64;
        for i in 0..ticks {
            let t = start_us + i as f64 * tick_us + (lcg(rng) * 2.0 - 1.0) * jitter_us;
            f.message(t as u64, &MidiMessage::Clock);
        }
        start_us + ticks as f64 * tick_us
    }

    #[test]
    fn one_ms_of_jitter_leaves_tempo_within_a_fifth_of_a_bpm_and_phase_within_5_ms() {
        for (seed, bpm) in [(1u64, 128.0), (2, 90.0), (3, 174.0)] {
            let mut rng = seed;
            let mut f = MidiClockFollower::new();
            f.message(999_000, &MidiMessage::Start);
            let start = 1_000_000.0;
            let mut worst = (0.0f64, 0.0f64);
            let tick_us = 60e6 / bpm / TICKS_PER_BEAT as f64;
            // After 2 to 31 beats of clock, each heard from Start by a fresh follower.
            for beat in 2..32 {
                let end = feed(&mut f, start, bpm, beat * TICKS_PER_BEAT, 1_000.0, &mut rng);
                let now = (end - 1.0) as u64;
                let g = f.grid(now, 4).expect("a grid");
                let tempo_err = (g.tempo_bpm() - bpm).abs();
                // Beat `beat` (0-based) truly falls at start + beat × period.
                let true_time = start + beat as f64 * 24.0 * tick_us;
                let phase_err = (g.time_of(beat as f64) - true_time).abs();
                worst = (worst.0.max(tempo_err), worst.1.max(phase_err));
                f = MidiClockFollower::new();
                f.message(999_000, &MidiMessage::Start);
            }
            assert!(worst.0 < 0.2, "{bpm} BPM: tempo off by {:.3}", worst.0);
            assert!(
                worst.1 < 5_000.0,
                "{bpm} BPM: phase off by {:.0} µs",
                worst.1
            );
        }
    }

    #[test]
    fn the_first_tick_after_start_is_beat_one_of_bar_one() {
        let mut f = MidiClockFollower::new();
        let mut rng = 9;
        assert!(f.grid(0, 4).is_none());
        f.message(500_000, &MidiMessage::Start);
        let end = feed(&mut f, 1_000_000.0, 120.0, 24 * 6 + 3, 0.0, &mut rng);
        let g = f.grid(end as u64, 4).unwrap();
        assert!((g.time_of(0.0) - 1_000_000.0).abs() < 1.0);
        assert!((g.time_of(4.0) - 3_000_000.0).abs() < 1.0);
        assert_eq!(g.index_in_bar(4), 1);
        assert_eq!(g.index_in_bar(6), 3);
        assert!(g.bar_known);
    }

    #[test]
    fn song_position_then_continue_sets_the_bar() {
        let mut f = MidiClockFollower::new();
        let mut rng = 4;
        // Ticks while stopped give a tempo but no grid.
        let end = feed(&mut f, 0.0, 100.0, 30, 0.0, &mut rng);
        assert!((f.tempo_bpm(end as u64).unwrap() - 100.0).abs() < 1e-6);
        assert!(f.grid(end as u64, 4).is_none(), "stopped");
        // Bar 3, beat 2 = sixteenth 4·(2·4 + 1) = 36.
        f.message(end as u64, &MidiMessage::SongPosition(36));
        f.message(end as u64 + 10, &MidiMessage::Continue);
        let t0 = end + 100_000.0;
        let end = feed(&mut f, t0, 100.0, 24 * 2, 0.0, &mut rng);
        let g = f.grid(end as u64, 4).unwrap();
        // The first tick after Continue is beat 9 (0-based): bar 3, beat 2.
        assert!((g.time_of(9.0) - t0).abs() < 1.0, "{}", g.time_of(9.0) - t0);
        assert_eq!(g.index_in_bar(9), 2);
        f.message(end as u64, &MidiMessage::Stop);
        assert!(f.grid(end as u64, 4).is_none());
    }

    #[test]
    fn a_tempo_change_is_followed_within_a_beat() {
        let mut f = MidiClockFollower::new();
        let mut rng = 5;
        f.message(0, &MidiMessage::Start);
        let end = feed(&mut f, 10_000.0, 128.0, 24 * 8, 1_000.0, &mut rng);
        assert_eq!(f.tempo_changes(), 0, "jitter alone is not a tempo change");
        let end = feed(&mut f, end, 140.0, 24, 1_000.0, &mut rng);
        let bpm = f.tempo_bpm(end as u64).unwrap();
        assert!((bpm - 140.0).abs() < 0.5, "{bpm}");
        assert_eq!(f.tempo_changes(), 1);
    }

    #[test]
    fn gaps_and_time_running_backwards_start_over() {
        let mut f = MidiClockFollower::new();
        let mut rng = 6;
        f.message(0, &MidiMessage::Start);
        let end = feed(&mut f, 0.0, 120.0, 30, 0.0, &mut rng);
        assert!(f.grid(end as u64, 4).is_some());
        assert!(
            f.tempo_bpm(end as u64 + 2_000_000).is_none(),
            "the clock stopped"
        );
        f.message(end as u64 + 2_000_000, &MidiMessage::Clock);
        assert!(
            f.tempo_bpm(end as u64 + 2_000_000).is_none(),
            "one tick is no tempo"
        );
        f.message(5, &MidiMessage::Clock);
        assert!(f.tempo_bpm(5).is_none(), "time going backwards starts over");
        assert!(!f.message(0, &MidiMessage::ActiveSensing));
    }

    #[test]
    fn the_leader_starts_on_a_bar_ticks_evenly_and_stops_when_the_grid_goes() {
        let grid = ClockGrid::new(0.0, 0.0, 120.0, 4).unwrap();
        let mut lead = MidiClockLeader::new();
        // At 0.3 s (beat 0.6) the next bar starts at beat 4 = 2 s.
        let (due, m) = lead.next(Some(&grid), 300_000.0).unwrap();
        assert_eq!(m, MidiMessage::Start);
        let tick_us = 500_000.0 / 24.0;
        assert!((due - (2_000_000.0 - 0.5 * tick_us)).abs() < 1e-6);
        let mut prev: Option<f64> = None;
        let mut now = due;
        for i in 0..48 {
            // Each asked for when the one before went out.
            let (due, m) = lead.next(Some(&grid), now).unwrap();
            now = due;
            assert_eq!(m, MidiMessage::Clock);
            assert!((due - (2_000_000.0 + i as f64 * tick_us)).abs() < 1e-6);
            if let Some(p) = prev {
                assert!((due - p - tick_us).abs() < 1e-6);
            }
            prev = Some(due);
        }
        // A receiver following these ticks reads the grid's tempo and bar back.
        let mut f = MidiClockFollower::new();
        f.message(1_990_000, &MidiMessage::Start);
        for i in 0..48 {
            f.message(
                (2_000_000.0 + i as f64 * tick_us) as u64,
                &MidiMessage::Clock,
            );
        }
        let back = f.grid(3_000_000, 4).unwrap();
        assert!((back.tempo_bpm() - 120.0).abs() < 0.1);
        assert!((back.time_of(0.0) - 2_000_000.0).abs() < 2.0);
        assert_eq!(
            lead.next(None, 3_000_000.0),
            Some((3_000_000.0, MidiMessage::Stop))
        );
        assert_eq!(lead.next(None, 3_000_000.0), None);
        assert!(!lead.started());
        // Planned again just before it is due, Start keeps its bar.
        for now in [1_000_000.0, 1_900_000.0, 1_989_000.0] {
            let mut plan = lead;
            let (due, m) = plan.next(Some(&grid), now).unwrap();
            assert_eq!(m, MidiMessage::Start);
            assert!(
                (due - (2_000_000.0 - 0.5 * tick_us)).abs() < 1e-6,
                "at {now}: {due}"
            );
        }
    }

    #[test]
    fn the_leader_catches_up_after_a_stall_and_restarts_after_a_jump() {
        let grid = ClockGrid::new(0.0, 0.0, 120.0, 4).unwrap();
        let tick_us = 500_000.0 / 24.0;
        let mut lead = MidiClockLeader::new();
        let (mut due, _) = lead.next(Some(&grid), 0.0).unwrap();
        for _ in 0..10 {
            due = lead.next(Some(&grid), due).unwrap().0;
        }
        // A 3-tick stall: the missed ticks are due in the past and go out at once, in order.
        let now = due + 3.0 * tick_us;
        let mut sent = Vec::new();
        for _ in 0..4 {
            let (d, m) = lead.next(Some(&grid), now).unwrap();
            assert_eq!(m, MidiMessage::Clock);
            sent.push(d);
        }
        assert!(
            sent.windows(2)
                .all(|w| (w[1] - w[0] - tick_us).abs() < 1e-6)
        );
        assert_eq!(lead.restarts(), 0);
        // Half a beat earlier (12 ticks): Stop, then Start before the next bar.
        let jumped = grid.delayed(-250_000.0);
        let now = sent[3] + tick_us;
        assert_eq!(
            lead.next(Some(&jumped), now),
            Some((now, MidiMessage::Stop))
        );
        assert_eq!(lead.restarts(), 1);
        let (start_due, m) = lead.next(Some(&jumped), now).unwrap();
        assert_eq!(m, MidiMessage::Start);
        let bar = jumped.beat_at(start_due + 0.5 * tick_us);
        assert!(
            (bar / 4.0 - (bar / 4.0).round()).abs() < 1e-9,
            "Start before a bar: {bar}"
        );
        // A grid moved back by half a beat restarts too.
        let mut lead = MidiClockLeader::new();
        let (mut due, _) = lead.next(Some(&grid), 0.0).unwrap();
        for _ in 0..5 {
            due = lead.next(Some(&grid), due).unwrap().0;
        }
        let back = grid.delayed(250_000.0);
        assert_eq!(lead.next(Some(&back), due), Some((due, MidiMessage::Stop)));
    }
}
