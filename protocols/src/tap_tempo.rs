//! Tap tempo, as DJs and VJs set a grid by hand: the beats fall where the taps fell, the first
//! tap of a run on a bar's first beat.

use crate::clock_grid::ClockGrid;
use crate::control::TEMPO_HINT_RANGE;

/// A pause longer than this (µs) after a tap starts a new run.
pub const TAP_RUN_GAP_US: u64 = 2_000_000;

/// Taps closer than this (µs) are one tap (a bouncing button, a doubled message).
pub const TAP_DEBOUNCE_US: u64 = 100_000;

/// Taps a tempo is fitted through: the newest of the run.
const TAPS_KEPT: usize = 8;

/// Taps before a run gives a grid (two intervals).
pub const TAPS_FOR_GRID: usize = 3;

/// Turns taps into a beat grid: a straight line through the run's newest taps (so one tap a
/// little early or late moves the beats a fraction of that), counted from the run's first
/// tap. The grid is kept after the run ends, so the clock runs on by itself.
#[derive(Clone, Debug, Default)]
pub struct TapTempo {
    /// (tap number in the run, time µs), the newest last.
    taps: [(u32, u64); TAPS_KEPT],
    kept: usize,
    /// Taps in the current run.
    run: u32,
    grid: Option<ClockGrid>,
    ignored: u64,
}

impl TapTempo {
    /// No taps yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// A tap at `t_us` (any monotonic µs clock); returns the grid when this tap changed it.
    /// Taps that bounce, or come back in time, are ignored (counted in [`TapTempo::ignored`]).
    pub fn tap(&mut self, t_us: u64, beats_per_bar: u32) -> Option<ClockGrid> {
        if let Some(&(_, last)) = self.taps[..self.kept].last() {
            if t_us < last + TAP_DEBOUNCE_US {
                self.ignored += 1;
                return None;
            }
            if t_us - last > TAP_RUN_GAP_US {
                self.kept = 0;
                self.run = 0;
            }
        }
        if self.kept == TAPS_KEPT {
            self.taps.copy_within(1.., 0);
            self.kept -= 1;
        }
        self.taps[self.kept] = (self.run, t_us);
        self.kept += 1;
        self.run += 1;
        if self.kept < TAPS_FOR_GRID {
            return None;
        }
        let grid = self.fit(beats_per_bar)?;
        self.grid = Some(grid);
        Some(grid)
    }

    /// The newest grid the taps gave (kept after the run ends).
    pub fn grid(&self) -> Option<ClockGrid> {
        self.grid
    }

    /// Taps in the current run.
    pub fn run(&self) -> u32 {
        self.run
    }

    /// Taps ignored so far.
    pub fn ignored(&self) -> u64 {
        self.ignored
    }

    /// Least squares of tap time against tap number.
    fn fit(&self, beats_per_bar: u32) -> Option<ClockGrid> {
        let taps = &self.taps[..self.kept];
        let n = taps.len() as f64;
        let t0 = taps[0].1 as f64;
        let mean_x = taps.iter().map(|&(k, _)| f64::from(k)).sum::<f64>() / n;
        let mean_y = taps.iter().map(|&(_, t)| t as f64 - t0).sum::<f64>() / n;
        let (mut sxx, mut sxy) = (0.0, 0.0);
        for &(k, t) in taps {
            let (dx, dy) = (f64::from(k) - mean_x, t as f64 - t0 - mean_y);
            sxx += dx * dx;
            sxy += dx * dy;
        }
        let period = sxy / sxx;
        let tempo = 60e6 / period;
        if !(f64::from(TEMPO_HINT_RANGE.0)..=f64::from(TEMPO_HINT_RANGE.1)).contains(&tempo) {
            return None;
        }
        // Beat k of the run falls at t0 + mean_y + (k − mean_x)·period; anchor at the mean.
        ClockGrid::new(t0 + mean_y, mean_x, tempo, beats_per_bar)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn three_taps_make_a_grid_whose_first_tap_begins_a_bar() {
        let mut t = TapTempo::new();
        assert!(t.tap(1_000_000, 4).is_none());
        assert!(t.tap(1_500_000, 4).is_none());
        let g = t.tap(2_000_000, 4).unwrap();
        assert!((g.tempo_bpm() - 120.0).abs() < 1e-9);
        assert!((g.time_of(0.0) - 1_000_000.0).abs() < 1e-6);
        assert_eq!(g.index_in_bar(4), 1);
        assert_eq!(t.grid(), Some(g));
    }

    #[test]
    fn uneven_taps_average_and_a_pause_starts_a_new_run() {
        let mut t = TapTempo::new();
        // 128 BPM, taps ±15 ms off.
        let period = 60e6 / 128.0;
        let offsets = [
            0.0, 15_000.0, -15_000.0, 10_000.0, -5_000.0, 15_000.0, -10_000.0, 0.0,
        ];
        for (k, o) in offsets.iter().enumerate() {
            t.tap((1e6 + k as f64 * period + o) as u64, 4);
        }
        let g = t.grid().unwrap();
        assert!((g.tempo_bpm() - 128.0).abs() < 1.0, "{}", g.tempo_bpm());
        assert!((g.time_of(7.0) - (1e6 + 7.0 * period)).abs() < 10_000.0);
        // Taps stop; the grid runs on. Three seconds later a new run at 100 BPM.
        let start = 1e6 + 8.0 * period + 3e6;
        for k in 0..4 {
            t.tap((start + k as f64 * 600_000.0) as u64, 3);
        }
        let g = t.grid().unwrap();
        assert!((g.tempo_bpm() - 100.0).abs() < 1e-6);
        assert!(
            (g.time_of(0.0) - start).abs() < 1.0,
            "the new run's first tap is beat 0"
        );
        assert_eq!(g.beats_per_bar, 3);
        assert_eq!(t.run(), 4);
    }

    #[test]
    fn bounces_and_time_going_back_are_ignored() {
        let mut t = TapTempo::new();
        t.tap(1_000_000, 4);
        assert!(t.tap(1_040_000, 4).is_none());
        assert!(t.tap(900_000, 4).is_none());
        assert_eq!(t.ignored(), 2);
        assert_eq!(t.run(), 1);
    }

    #[test]
    fn taps_give_a_grid_only_at_a_tempo_someone_plays() {
        let mut slow = TapTempo::new();
        // 1.9 s apart: 31.6 BPM, inside the tempo range.
        for k in 0..3 {
            slow.tap(k * 1_900_000, 4);
        }
        assert!(
            slow.grid()
                .is_some_and(|g| (g.tempo_bpm() - 31.58).abs() < 0.01)
        );
        let mut fast = TapTempo::new();
        // 150 ms apart = 400 BPM: a drum roll, not a beat.
        for k in 0..4 {
            assert!(fast.tap(k * 150_000, 4).is_none());
        }
        assert!(fast.grid().is_none());
    }
}
