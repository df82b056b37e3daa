//! Tempo from MIDI clock: 24 ticks per quarter note from a DAW, drum machine or DJ software.

/// Ticks of MIDI clock per quarter note.
pub const TICKS_PER_BEAT: usize = 24;

/// A silence between ticks longer than this (µs) means the clock stopped.
pub const MAX_TICK_GAP_US: u64 = 1_000_000;

/// Ticks kept: three beats, so one span of a beat can be measured 48 times.
const HISTORY: usize = 3 * TICKS_PER_BEAT;

/// Smoothed tempo from clock ticks.
///
/// Tick timestamps jitter by a millisecond or more (USB polling, ALSA scheduling), which is ±5 %
/// of a tick at 120 BPM. So the tempo is measured over whole beats: the median, over the ticks
/// kept, of the time a beat (24 ticks) took. Jitter then shrinks 24-fold and a late or lost tick
/// moves only a few of the spans, not the median.
#[derive(Clone, Debug)]
pub struct MidiClockTempo {
    ticks: [u64; HISTORY],
    /// Ticks stored (up to HISTORY); the newest is at `(head + HISTORY - 1) % HISTORY`.
    count: usize,
    head: usize,
    bpm: Option<f32>,
}

impl Default for MidiClockTempo {
    fn default() -> Self {
        Self {
            ticks: [0; HISTORY],
            count: 0,
            head: 0,
            bpm: None,
        }
    }
}

impl MidiClockTempo {
    /// A tempo tracker that has heard nothing.
    pub fn new() -> Self {
        Self::default()
    }

    /// Forgets everything (on Start, Stop, or a clock source change).
    pub fn reset(&mut self) {
        *self = Self::default();
    }

    /// Feeds one clock tick at `timestamp_us` (any monotonic microsecond clock); returns the
    /// tempo once a beat's worth of ticks has arrived.
    pub fn tick(&mut self, timestamp_us: u64) -> Option<f32> {
        if let Some(last) = self.last_tick() {
            // Out-of-order or long-gap ticks start a fresh measurement rather than poison it.
            if timestamp_us < last || timestamp_us - last > MAX_TICK_GAP_US {
                self.reset();
            }
        }
        self.ticks[self.head] = timestamp_us;
        self.head = (self.head + 1) % HISTORY;
        self.count = (self.count + 1).min(HISTORY);
        self.bpm = self.estimate();
        self.bpm
    }

    /// The tempo at `now_us`: `None` before a beat of ticks, after [`MidiClockTempo::reset`], or
    /// when the last tick is more than a second old.
    pub fn bpm(&self, now_us: u64) -> Option<f32> {
        let last = self.last_tick()?;
        if now_us.saturating_sub(last) > MAX_TICK_GAP_US {
            return None;
        }
        self.bpm
    }

    fn last_tick(&self) -> Option<u64> {
        (self.count > 0).then(|| self.ticks[(self.head + HISTORY - 1) % HISTORY])
    }

    fn estimate(&self) -> Option<f32> {
        if self.count <= TICKS_PER_BEAT {
            return None;
        }
        let oldest = (self.head + HISTORY - self.count) % HISTORY;
        let at = |i: usize| self.ticks[(oldest + i) % HISTORY];
        let mut spans = [0u64; HISTORY];
        let n = self.count - TICKS_PER_BEAT;
        for (i, span) in spans.iter_mut().enumerate().take(n) {
            *span = at(i + TICKS_PER_BEAT) - at(i);
        }
        let spans = &mut spans[..n];
        spans.sort_unstable();
        let median = if n % 2 == 1 {
            spans[n / 2] as f64
        } else {
            (spans[n / 2 - 1] + spans[n / 2]) as f64 / 2.0
        };
        if median <= 0.0 {
            return None;
        }
        let bpm = (60_000_000.0 / median) as f32;
        bpm.is_finite().then_some(bpm)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A tiny deterministic generator, so the jitter test is reproducible.
    fn lcg(state: &mut u64) -> f64 {
        *state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (*state >> 11) as f64 / (1u64 << 53) as f64
    }

    #[test]
    fn steady_120_bpm_with_one_ms_jitter_reads_120() {
        let mut c = MidiClockTempo::new();
        let mut rng = 7u64;
        let tick_us = 60_000_000.0 / 120.0 / 24.0;
        let mut last = None;
        for i in 0..24 * 16 {
            let jitter = (lcg(&mut rng) * 2.0 - 1.0) * 1000.0;
            let t = (1_000_000.0 + i as f64 * tick_us + jitter) as u64;
            let bpm = c.tick(t);
            if i < 24 {
                assert_eq!(bpm, None, "tick {i}: not a beat of ticks yet");
            } else {
                let bpm = bpm.unwrap();
                assert!((bpm - 120.0).abs() < 0.5, "tick {i}: {bpm}");
            }
            last = Some(t);
        }
        let last = last.unwrap();
        assert!(c.bpm(last + 500_000).is_some());
        assert_eq!(c.bpm(last + 1_500_000), None, "clock stopped");
    }

    #[test]
    fn follows_a_tempo_change_and_ignores_a_late_tick() {
        let mut c = MidiClockTempo::new();
        let mut t = 0u64;
        for _ in 0..24 * 4 {
            t += 25_000; // 100 BPM
            c.tick(t);
        }
        assert!((c.bpm(t).unwrap() - 100.0).abs() < 0.01);
        // One tick 8 ms late, the next on time: the median does not move.
        c.tick(t + 25_000 + 8_000);
        t += 50_000;
        assert!((c.tick(t).unwrap() - 100.0).abs() < 0.01);
        for _ in 0..24 * 3 {
            t += 20_833; // ~120 BPM
            c.tick(t);
        }
        assert!((c.bpm(t).unwrap() - 120.0).abs() < 0.01);
    }

    #[test]
    fn gaps_and_reset_start_over() {
        let mut c = MidiClockTempo::new();
        let mut t = 0;
        for _ in 0..30 {
            t += 20_000;
            c.tick(t);
        }
        assert!(c.bpm(t).is_some());
        t += 2_000_000;
        assert_eq!(c.tick(t), None, "a 2 s gap forgets the old ticks");
        c.reset();
        assert_eq!(c.bpm(t), None);
        assert_eq!(c.tick(5), None);
        assert_eq!(c.tick(1), None, "time going backwards starts over");
    }
}
