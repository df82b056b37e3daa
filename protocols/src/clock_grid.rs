//! A beat grid on a wall clock, as an external clock (MIDI clock, Ableton Link, tapped beats)
//! publishes it: beat `b` falls at `anchor_us + (b − anchor_beat) × period_us`.

/// Tempi outside this range (BPM) are not a usable grid.
pub const CLOCK_TEMPO_RANGE: (f64, f64) = (20.0, 999.0);

/// A straight beat grid on some microsecond clock.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ClockGrid {
    /// A moment on the clock, µs.
    pub anchor_us: f64,
    /// The beat position at that moment (beats since the song or session began).
    pub anchor_beat: f64,
    /// Microseconds per beat.
    pub period_us: f64,
    /// Beats per bar.
    pub beats_per_bar: u32,
    /// Whether beat 0 (and every `beats_per_bar`-th beat from it) begins a bar.
    pub bar_known: bool,
}

impl ClockGrid {
    /// A grid at `tempo_bpm` whose beat position at `anchor_us` is `anchor_beat`; `None` when
    /// the tempo is outside [`CLOCK_TEMPO_RANGE`] or a value is not finite.
    pub fn new(
        anchor_us: f64,
        anchor_beat: f64,
        tempo_bpm: f64,
        beats_per_bar: u32,
    ) -> Option<Self> {
        let ok = anchor_us.is_finite()
            && anchor_beat.is_finite()
            && (CLOCK_TEMPO_RANGE.0..=CLOCK_TEMPO_RANGE.1).contains(&tempo_bpm);
        ok.then(|| ClockGrid {
            anchor_us,
            anchor_beat,
            period_us: 60e6 / tempo_bpm,
            beats_per_bar: beats_per_bar.max(1),
            bar_known: true,
        })
    }

    /// Tempo, BPM.
    pub fn tempo_bpm(&self) -> f64 {
        60e6 / self.period_us
    }

    /// The beat position at `t_us`.
    pub fn beat_at(&self, t_us: f64) -> f64 {
        self.anchor_beat + (t_us - self.anchor_us) / self.period_us
    }

    /// When beat position `beat` falls, µs.
    pub fn time_of(&self, beat: f64) -> f64 {
        self.anchor_us + (beat - self.anchor_beat) * self.period_us
    }

    /// Position in the bar (1 = its first beat) of whole beat `beat`.
    pub fn index_in_bar(&self, beat: i64) -> u32 {
        beat.rem_euclid(i64::from(self.beats_per_bar.max(1))) as u32 + 1
    }

    /// The same grid `by_us` later (a positive nudge delays every beat).
    pub fn delayed(self, by_us: f64) -> Self {
        ClockGrid {
            anchor_us: self.anchor_us + by_us,
            ..self
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn beats_and_times_invert_and_bars_count_from_beat_zero() {
        let g = ClockGrid::new(1_000_000.0, 8.0, 120.0, 4).unwrap();
        assert_eq!(g.period_us, 500_000.0);
        assert_eq!(g.beat_at(1_250_000.0), 8.5);
        assert_eq!(g.time_of(10.0), 2_000_000.0);
        assert_eq!(g.index_in_bar(8), 1);
        assert_eq!(g.index_in_bar(11), 4);
        assert_eq!(g.index_in_bar(-1), 4);
        assert_eq!(g.delayed(10_000.0).time_of(10.0), 2_010_000.0);
        assert!((g.tempo_bpm() - 120.0).abs() < 1e-12);
    }

    #[test]
    fn refuses_tempi_no_one_plays_and_non_finite_values() {
        assert!(ClockGrid::new(0.0, 0.0, 10.0, 4).is_none());
        assert!(ClockGrid::new(0.0, 0.0, 2000.0, 4).is_none());
        assert!(ClockGrid::new(f64::NAN, 0.0, 120.0, 4).is_none());
        assert!(ClockGrid::new(0.0, 0.0, f64::INFINITY, 4).is_none());
    }
}
