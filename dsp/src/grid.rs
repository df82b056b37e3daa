//! The beat grid as the tracker knows it at one moment — the next beat, the period, the place
//! in the bar — and its extrapolation to any later time. While the tempo holds, the grid
//! predicts every beat phase exactly, which is what lets the dancer show the music of *now*
//! (and of a display latency ahead) instead of waiting for the analysis to hear it.

use crate::hop::HopFrame;

/// The beat grid known at one hop: beats at `next_beat_s + n · period_s`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct BeatGrid {
    /// Predicted time of the next beat, stream seconds.
    pub next_beat_s: f64,
    /// Beat period, seconds (0 while no beat is heard).
    pub period_s: f64,
    /// Position in the bar of the beat at `next_beat_s` (1 = downbeat).
    pub next_index_in_bar: u32,
    /// Beats per bar.
    pub beats_per_bar: u32,
    /// Probability the bar tracker gives this count, in [0, 1].
    pub bar_confidence: f32,
    /// Whether a beat is heard (the grid predicts nothing otherwise).
    pub locked: bool,
}

/// One beat of a grid.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GridBeat {
    /// Its time, stream seconds.
    pub time_s: f64,
    /// Its position in the bar (1 = downbeat).
    pub index_in_bar: u32,
}

impl BeatGrid {
    /// The grid a hop reports.
    pub fn from_hop(hop: &HopFrame) -> Self {
        let period_s = if hop.tempo_bpm > 0.0 {
            60.0 / hop.tempo_bpm
        } else {
            0.0
        };
        let bpb = hop.beats_per_bar.max(1) as u32;
        BeatGrid {
            next_beat_s: hop.next_beat_s,
            period_s,
            next_index_in_bar: (hop.beat_in_bar as u32 % bpb) + 1,
            beats_per_bar: bpb,
            bar_confidence: hop.bar_confidence,
            locked: hop.locked && period_s > 0.0 && hop.next_beat_s.is_finite(),
        }
    }

    /// The same grid with every time moved by `offset_s` (a stream clock that restarted).
    pub fn shifted(self, offset_s: f64) -> Self {
        BeatGrid {
            next_beat_s: self.next_beat_s + offset_s,
            ..self
        }
    }

    /// Tempo in BPM (0 when unlocked).
    pub fn tempo_bpm(&self) -> f64 {
        if self.locked {
            60.0 / self.period_s
        } else {
            0.0
        }
    }

    /// Beats from the grid's next beat to `t_s` (negative before it).
    fn beats_to(&self, t_s: f64) -> f64 {
        (t_s - self.next_beat_s) / self.period_s
    }

    /// Position in the beat at `t_s`, in [0, 1) (0 = on a beat); None when unlocked.
    pub fn beat_phase_at(&self, t_s: f64) -> Option<f64> {
        self.locked.then(|| self.beats_to(t_s).rem_euclid(1.0))
    }

    /// Position in the bar at `t_s`, in [0, 1) (0 = on a downbeat); None when unlocked.
    pub fn bar_phase_at(&self, t_s: f64) -> Option<f64> {
        self.locked.then(|| {
            let bpb = f64::from(self.beats_per_bar.max(1));
            let beats = f64::from(self.next_index_in_bar.max(1) - 1) + self.beats_to(t_s);
            (beats / bpb).rem_euclid(1.0)
        })
    }

    /// The first beat strictly after `t_s`; None when unlocked.
    pub fn beat_after(&self, t_s: f64) -> Option<GridBeat> {
        if !self.locked {
            return None;
        }
        let n = self.beats_to(t_s).floor() + 1.0;
        let bpb = i64::from(self.beats_per_bar.max(1));
        let index = (i64::from(self.next_index_in_bar.max(1)) - 1 + n as i64).rem_euclid(bpb) + 1;
        Some(GridBeat {
            time_s: self.next_beat_s + n * self.period_s,
            index_in_bar: index as u32,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid() -> BeatGrid {
        // Beats every 0.5 s at …, 9.5, 10.0 (beat 2 of 4), 10.5 (beat 3), …
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
    fn extrapolates_phases_across_beats_and_bars() {
        let g = grid();
        assert!((g.beat_phase_at(10.125).unwrap() - 0.25).abs() < 1e-9);
        assert!((g.beat_phase_at(9.875).unwrap() - 0.75).abs() < 1e-9);
        // 9.5 is a downbeat: a bar (2 s) later, 11.5 is one too.
        assert!(g.bar_phase_at(9.5).unwrap().abs() < 1e-9);
        assert!(g.bar_phase_at(11.5).unwrap().abs() < 1e-9);
        assert!((g.bar_phase_at(10.0).unwrap() - 0.25).abs() < 1e-9);
        let b = g.beat_after(10.0).unwrap();
        assert_eq!((b.time_s, b.index_in_bar), (10.5, 3));
        let b = g.beat_after(11.2).unwrap();
        assert_eq!((b.time_s, b.index_in_bar), (11.5, 1));
        let b = g.beat_after(8.9).unwrap();
        assert_eq!((b.time_s, b.index_in_bar), (9.0, 4));
        assert_eq!(g.tempo_bpm(), 120.0);
    }

    #[test]
    fn unlocked_grid_predicts_nothing() {
        let g = BeatGrid::default();
        assert_eq!(g.beat_phase_at(1.0), None);
        assert_eq!(g.beat_after(1.0), None);
        assert_eq!(g.tempo_bpm(), 0.0);
    }
}
