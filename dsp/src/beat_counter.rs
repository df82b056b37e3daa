//! Counted beats from tracked ones: the beat tracker follows whatever pulse it locks to; the
//! bar tracker says how that pulse relates to the beat a musician counts ([`Level`]) and where
//! in the bar it stands. This turns the tracker's beats, tempo and phase into the counted
//! beat's: at double time every other tracked beat is dropped and the tempo halved; at half
//! time a beat is added halfway between two tracked ones, on the tracker's own grid (so it is
//! reported as promptly as a tracked beat) and the tempo doubled.

use crate::bar_class::{BarClass, Level};

/// What the counted beat looks like at one hop.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CountedHop {
    /// A counted beat completed on this hop: its time and its position in the bar.
    pub beat: Option<(f64, usize)>,
    /// Counted beats per minute (0 while no beat is heard).
    pub tempo_bpm: f64,
    /// Position in the counted beat, [0, 1).
    pub beat_phase: f64,
    /// Hops until the next counted beat.
    pub frames_to_next_beat: f64,
    /// Position of the last counted beat in its bar (1 = downbeat).
    pub beat_in_bar: usize,
    /// Counted beats per bar.
    pub beats_per_bar: usize,
}

/// Turns tracked beats into counted ones. Allocates nothing.
#[derive(Clone, Copy, Debug)]
pub struct BeatCounter {
    class: BarClass,
    /// A beat to add between two tracked ones at half time: its time and position.
    pending: Option<(f64, usize)>,
}

impl Default for BeatCounter {
    fn default() -> Self {
        Self {
            class: BarClass {
                level: Level::Beat,
                meter: 4,
                position: 1,
            },
            pending: None,
        }
    }
}

impl BeatCounter {
    /// One hop. `now_s` is the event time this hop describes, `tracked` the tracked beat it
    /// reported (its time and bar class), and `tempo_bpm`, `beat_phase` and
    /// `frames_to_next_beat` the tracker's, for hops at `hop_rate` per second.
    pub fn hop(
        &mut self,
        now_s: f64,
        tracked: Option<(f64, BarClass)>,
        tempo_bpm: f64,
        beat_phase: f64,
        frames_to_next_beat: f64,
        hop_rate: f64,
    ) -> CountedHop {
        let period_s = if tempo_bpm > 0.0 {
            60.0 / tempo_bpm
        } else {
            0.0
        };
        let mut beat = None;
        if let Some((time_s, class)) = tracked {
            // A beat to add that the next tracked beat overtook (the tempo rose) is dropped.
            self.pending = None;
            self.class = class;
            beat = class.counted_position().map(|p| (time_s, p));
            if class.level == Level::Half && period_s > 0.0 {
                self.pending = Some((time_s + period_s / 2.0, class.position % class.meter + 1));
            }
        } else if let Some((time_s, position)) = self.pending
            && now_s >= time_s
        {
            beat = Some((time_s, position));
            self.pending = None;
        }
        let c = self.class;
        let phase = beat_phase.clamp(0.0, 1.0);
        let period_frames = period_s * hop_rate;
        let (beat_phase, frames_to_next_beat, beat_in_bar) = match c.level {
            Level::Beat => (phase, frames_to_next_beat, c.position),
            Level::Double if c.counted_position().is_some() => (
                phase / 2.0,
                frames_to_next_beat + period_frames,
                c.last_counted_position(),
            ),
            Level::Double => (
                (1.0 + phase) / 2.0,
                frames_to_next_beat,
                c.last_counted_position(),
            ),
            Level::Half if phase < 0.5 => (
                2.0 * phase,
                (frames_to_next_beat - period_frames / 2.0).max(0.0),
                c.position,
            ),
            Level::Half => (
                2.0 * phase - 1.0,
                frames_to_next_beat,
                c.position % c.meter + 1,
            ),
        };
        CountedHop {
            beat,
            tempo_bpm: tempo_bpm * c.counted_per_tracked(),
            beat_phase: beat_phase.clamp(0.0, 1.0 - 1e-9),
            frames_to_next_beat,
            beat_in_bar,
            beats_per_bar: c.meter,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Tracked beats every 0.5 s (120 BPM) over 4 s, hops of 10 ms; each tracked beat `k` gets
    /// class `class(k)`. Returns the counted beats and the hops.
    fn run(class: impl Fn(usize) -> BarClass) -> (Vec<(f64, usize)>, Vec<CountedHop>) {
        let mut counter = BeatCounter::default();
        let (mut beats, mut hops) = (Vec::new(), Vec::new());
        for i in 0..400usize {
            let t = i as f64 * 0.01;
            let k = i / 50;
            let tracked = (i % 50 == 0).then(|| (t, class(k)));
            let phase = (i % 50) as f64 / 50.0;
            let h = counter.hop(t, tracked, 120.0, phase, (50 - i % 50) as f64, 100.0);
            beats.extend(h.beat);
            hops.push(h);
        }
        (beats, hops)
    }

    fn class(level: Level, position: usize) -> BarClass {
        BarClass {
            level,
            meter: 4,
            position,
        }
    }

    #[test]
    fn at_the_tracked_beat_everything_passes_through() {
        let (beats, hops) = run(|k| class(Level::Beat, k % 4 + 1));
        assert_eq!(beats.len(), 8);
        assert_eq!(beats[5], (2.5, 2));
        assert_eq!((hops[60].tempo_bpm, hops[60].beat_in_bar), (120.0, 2));
        assert!((hops[60].beat_phase - 0.2).abs() < 1e-9);
    }

    #[test]
    fn double_time_drops_the_off_beats_and_halves_the_tempo() {
        let (beats, hops) = run(|k| class(Level::Double, k % 8 + 1));
        let times: Vec<f64> = beats.iter().map(|b| b.0).collect();
        assert_eq!(times, [0.0, 1.0, 2.0, 3.0]);
        assert_eq!(beats.iter().map(|b| b.1).collect::<Vec<_>>(), [1, 2, 3, 4]);
        // 0.75 s: tracked beat 1 (an off-beat) was a quarter of a beat ago.
        let h = hops[75];
        assert_eq!((h.tempo_bpm, h.beat_in_bar), (60.0, 1));
        assert!((h.beat_phase - 0.75).abs() < 1e-9);
        assert!((h.frames_to_next_beat - 25.0).abs() < 1e-9);
        // 0.25 s: on the counted beat 1, the next counted beat is 75 hops away.
        assert!((hops[25].frames_to_next_beat - 75.0).abs() < 1e-9);
    }

    #[test]
    fn half_time_adds_a_beat_on_the_grid_between_tracked_ones() {
        let (beats, hops) = run(|k| class(Level::Half, if k % 2 == 0 { 1 } else { 3 }));
        assert_eq!(beats.len(), 16);
        assert_eq!(beats[1], (0.25, 2));
        assert_eq!(beats[3], (0.75, 4));
        let h = hops[30];
        assert_eq!((h.tempo_bpm, h.beat_in_bar), (240.0, 2));
        assert!((h.beat_phase - 0.2).abs() < 1e-9);
        assert!((h.frames_to_next_beat - 20.0).abs() < 1e-9);
    }
}
