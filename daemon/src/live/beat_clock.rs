//! The beats a receiver is told of, on the dancer's clock: `/danced/beat` when the shown time
//! crosses a beat of the grid the shown pose was made with, then `/danced/beat/next` announcing
//! the one after it. Visuals keyed to them and the dancer's own beats cannot drift apart: both
//! come from one grid at one shown time.

use dsp::BeatGrid;

use super::wire::AnalysisEvent;

/// Tracks which beats have gone out; owned by the sender thread, never allocates.
#[derive(Clone, Copy, Debug)]
pub struct BeatClock {
    last_beat_s: f64,
    announced_s: f64,
}

impl Default for BeatClock {
    fn default() -> Self {
        Self {
            last_beat_s: f64::NEG_INFINITY,
            announced_s: f64::NEG_INFINITY,
        }
    }
}

impl BeatClock {
    /// The shown time moved from `from_s` to `shown_s` (stream seconds) on `grid`: emits the
    /// beat it crossed, if any, and announces the next beat once (again if the grid moves it
    /// by more than half a beat). `speed` is audio seconds per wall second.
    pub fn advance(
        &mut self,
        grid: &BeatGrid,
        from_s: f64,
        shown_s: f64,
        speed: f64,
        mut emit: impl FnMut(AnalysisEvent),
    ) {
        if !grid.locked || !shown_s.is_finite() {
            return;
        }
        let half = 0.5 * grid.period_s;
        // A beat a corrected grid puts again within half a beat of the last one is the same beat.
        let after = if from_s.is_finite() { from_s } else { shown_s }.max(self.last_beat_s + half);
        let tempo_bpm = grid.tempo_bpm() as f32;
        if let Some(b) = grid.beat_after(after)
            && b.time_s <= shown_s
        {
            emit(AnalysisEvent::Beat {
                time_s: b.time_s,
                index_in_bar: b.index_in_bar,
                beats_per_bar: grid.beats_per_bar,
                tempo_bpm,
                bar_confidence: grid.bar_confidence,
            });
            self.last_beat_s = b.time_s;
        }
        let Some(next) = grid.beat_after(shown_s.max(self.last_beat_s + half)) else {
            return;
        };
        if (next.time_s - self.announced_s).abs() > half {
            emit(AnalysisEvent::NextBeat {
                time_s: next.time_s,
                in_s: ((next.time_s - shown_s) / speed) as f32,
                index_in_bar: next.index_in_bar,
                beats_per_bar: grid.beats_per_bar,
                tempo_bpm,
            });
            self.announced_s = next.time_s;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_beat_once_when_crossed_and_announced_ahead() {
        let grid = BeatGrid {
            next_beat_s: 1.0,
            period_s: 0.5,
            next_index_in_bar: 1,
            beats_per_bar: 4,
            bar_confidence: 1.0,
            locked: true,
        };
        let mut clock = BeatClock::default();
        let mut got = Vec::new();
        let mut t: f64 = 0.8;
        let mut prev = f64::NEG_INFINITY;
        while t < 3.0 {
            // A grid that wobbles by 10 ms still gives one beat per beat.
            let g = BeatGrid {
                next_beat_s: grid.next_beat_s + 0.01 * (t * 7.0).sin(),
                ..grid
            };
            clock.advance(&g, prev, t, 1.0, |e| got.push((t, e)));
            prev = t;
            t += 1.0 / 60.0;
        }
        let beats: Vec<(f64, f64, u32)> = got
            .iter()
            .filter_map(|(t, e)| match *e {
                AnalysisEvent::Beat {
                    time_s,
                    index_in_bar,
                    ..
                } => Some((*t, time_s, index_in_bar)),
                _ => None,
            })
            .collect();
        assert_eq!(beats.len(), 4, "{beats:?}");
        for (k, (sent_at, time_s, index)) in beats.iter().enumerate() {
            let due = 1.0 + 0.5 * k as f64;
            assert!((time_s - due).abs() <= 0.011, "{beats:?}");
            // Sent on the first tick at or past the beat.
            assert!(*sent_at >= *time_s && sent_at - time_s < 1.0 / 60.0 + 1e-9);
            assert_eq!(*index, (k % 4) as u32 + 1);
        }
        let next: Vec<(f64, f64, f32)> = got
            .iter()
            .filter_map(|(t, e)| match *e {
                AnalysisEvent::NextBeat { time_s, in_s, .. } => Some((*t, time_s, in_s)),
                _ => None,
            })
            .collect();
        // One announcement before the first beat, one after each beat.
        assert_eq!(next.len(), 5, "{next:?}");
        assert!((next[0].1 - 1.0).abs() < 0.011 && (next[0].2 - 0.2).abs() < 0.011);
        assert!((next[1].1 - 1.5).abs() < 0.011);
    }

    #[test]
    fn unlocked_grid_sends_nothing() {
        let mut clock = BeatClock::default();
        let mut n = 0;
        clock.advance(&BeatGrid::default(), 0.0, 1.0, 1.0, |_| n += 1);
        assert_eq!(n, 0);
    }
}
