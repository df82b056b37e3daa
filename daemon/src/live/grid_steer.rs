//! The beat grid a run dances to, chosen on the analysis thread for every feature frame: the
//! grid heard in the music, or an external clock's (MIDI, Link, taps) moved onto the stream's
//! time axis; then the performer's nudge and "beat one is now". While an external clock is
//! followed, the heard beats are compared with it: the offset is reported and, if asked, the
//! clock's phase is trimmed toward what is heard. Allocates nothing.

use dsp::BeatGrid;
use protocols::ClockGrid;

use super::clock::{ClockSnapshot, ClockSource};

/// Heard beats the offset is the median of.
const OFFSET_SAMPLES: usize = 16;
/// Heard beats before the offset is reported (and trimmed toward).
const OFFSET_MIN_SAMPLES: usize = 4;
/// How far the heard tempo may be from the clock's for its beats to be compared, as a ratio.
const SAME_TEMPO: f64 = 0.04;
/// Share of the remaining offset a trim takes per heard beat.
const TRIM_RATE: f64 = 0.2;

/// The stream clock against the wall clock at the newest audio block.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WallMap {
    /// Stream time of the block's last sample, seconds.
    pub audio_end_s: f64,
    /// When it entered the ring, ns since the epoch.
    pub wall_ns: u64,
    /// Audio seconds per wall second.
    pub speed: f64,
}

impl WallMap {
    /// The stream time whose audio entered the ring at `wall_us` (µs since the epoch).
    pub fn stream_at(&self, wall_us: f64) -> f64 {
        self.audio_end_s + (wall_us * 1e3 - self.wall_ns as f64) * 1e-9 * self.speed
    }

    /// When the audio of stream time `stream_s` entered (or will enter) the ring, µs.
    pub fn wall_us_at(&self, stream_s: f64) -> f64 {
        (self.wall_ns as f64 + (stream_s - self.audio_end_s) / self.speed * 1e9) * 1e-3
    }
}

/// The grid chosen for one frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Steered {
    /// On the stream clock: what the dancer and the beat messages follow.
    pub grid: BeatGrid,
    /// The same beats on the wall clock (µs since the epoch), counted on without jumps, for
    /// the clocks danced leads (MIDI clock out, Link); `None` while no beat is followed.
    pub wall: Option<ClockGrid>,
    /// The external clock chosen had no grid, so the heard one stood in.
    pub fallback: bool,
    /// A new heard-against-clock offset was measured on this frame: the median, ms (positive:
    /// the music is heard later than the clock puts its beats).
    pub new_offset_ms: Option<f32>,
}

/// Chooses and corrects the grid, frame by frame.
#[derive(Clone, Copy, Debug)]
pub struct GridSteer {
    offsets_ms: [f32; OFFSET_SAMPLES],
    offsets: usize,
    offsets_pos: usize,
    last_heard_beat_s: f64,
    trim_s: f64,
    rotation: u32,
    rotation_for: (ClockSource, u32),
    beat_one_seen: u32,
    /// (next beat's stream time, its number) of the last wall grid given out.
    counted: Option<(f64, i64)>,
    offset_ms: Option<f32>,
}

impl Default for GridSteer {
    fn default() -> Self {
        Self {
            offsets_ms: [0.0; OFFSET_SAMPLES],
            offsets: 0,
            offsets_pos: 0,
            last_heard_beat_s: f64::NEG_INFINITY,
            trim_s: 0.0,
            rotation: 0,
            rotation_for: (ClockSource::Audio, 0),
            beat_one_seen: 0,
            counted: None,
            offset_ms: None,
        }
    }
}

impl GridSteer {
    /// A steer that has seen nothing.
    pub fn new() -> Self {
        Self::default()
    }

    /// The newest offset of the heard beats from the followed clock's, ms (median of the last
    /// heard beats); `None` while the audio is followed or the two do not share a tempo.
    pub fn offset_ms(&self) -> Option<f32> {
        self.offset_ms
    }

    /// How far the clock's phase has been trimmed toward the heard beats, ms.
    pub fn trim_ms(&self) -> f32 {
        (self.trim_s * 1e3) as f32
    }

    /// The grid for the frame at stream time `t_s`, given the clocks' snapshot and the grid
    /// the analysis heard.
    pub fn steer(
        &mut self,
        snapshot: &ClockSnapshot,
        heard: &BeatGrid,
        t_s: f64,
        map: &WallMap,
    ) -> Steered {
        // `Some(None)`: an external clock chosen that has no grid to give.
        let external = match snapshot.source {
            ClockSource::Audio => None,
            _ => Some(snapshot.grid),
        };
        let mut new_offset_ms = None;
        let mut grid = match external {
            None | Some(None) => {
                self.forget_offsets();
                *heard
            }
            Some(Some(clock)) => {
                let raw = on_stream(&clock, t_s, map);
                new_offset_ms = self.compare(heard, &raw);
                if snapshot.trim {
                    if let Some(m) = new_offset_ms.filter(|_| self.offsets >= OFFSET_MIN_SAMPLES) {
                        self.trim_s += TRIM_RATE * (f64::from(m) * 1e-3 - self.trim_s);
                    }
                } else {
                    self.trim_s = 0.0;
                }
                raw.shifted(self.trim_s * map.speed)
            }
        };
        let fallback = matches!(external, Some(None));
        grid = grid.shifted(f64::from(snapshot.nudge_ms) * 1e-3 * map.speed);
        self.beat_one(snapshot, &grid, map);
        if grid.locked && self.rotation != 0 {
            let bpb = grid.beats_per_bar.max(1);
            grid.next_index_in_bar = (grid.next_index_in_bar - 1 + self.rotation) % bpb + 1;
        }
        let wall = self.on_wall(&grid, map);
        Steered {
            grid,
            wall,
            fallback,
            new_offset_ms,
        }
    }

    fn forget_offsets(&mut self) {
        self.offsets = 0;
        self.offset_ms = None;
        self.trim_s = 0.0;
    }

    /// On each new heard beat at the clock's tempo, its offset from the clock's nearest beat.
    fn compare(&mut self, heard: &BeatGrid, clock: &BeatGrid) -> Option<f32> {
        if !heard.locked || heard.period_s <= 0.0 {
            return None;
        }
        if (heard.period_s / clock.period_s - 1.0).abs() > SAME_TEMPO {
            self.offsets = 0;
            self.offset_ms = None;
            return None;
        }
        let beat = heard.next_beat_s;
        if (beat - self.last_heard_beat_s).abs() < 0.5 * heard.period_s {
            return None;
        }
        self.last_heard_beat_s = beat;
        let nearest = clock.beat_after(beat - 0.5 * clock.period_s)?.time_s;
        self.offsets_ms[self.offsets_pos] = ((beat - nearest) * 1e3) as f32;
        self.offsets_pos = (self.offsets_pos + 1) % OFFSET_SAMPLES;
        self.offsets = (self.offsets + 1).min(OFFSET_SAMPLES);
        let mut sorted = self.offsets_ms;
        let kept = &mut sorted[..self.offsets];
        kept.sort_unstable_by(f32::total_cmp);
        let n = kept.len();
        let median = if n % 2 == 1 {
            kept[n / 2]
        } else {
            0.5 * (kept[n / 2 - 1] + kept[n / 2])
        };
        self.offset_ms = (n >= OFFSET_MIN_SAMPLES).then_some(median);
        self.offset_ms
    }

    /// A new "beat one is now": the beat nearest that moment becomes its bar's first.
    fn beat_one(&mut self, snapshot: &ClockSnapshot, grid: &BeatGrid, map: &WallMap) {
        let key = (snapshot.source, grid.beats_per_bar.max(1));
        if key != self.rotation_for {
            // Another clock or another metre: the old correction means nothing to it.
            self.rotation = 0;
            self.rotation_for = key;
        }
        if snapshot.beat_one_requests == self.beat_one_seen || !grid.locked {
            return;
        }
        self.beat_one_seen = snapshot.beat_one_requests;
        let at = map.stream_at(snapshot.beat_one_at_us);
        let Some(nearest) = grid.beat_after(at - 0.5 * grid.period_s) else {
            return;
        };
        let bpb = key.1;
        // The rotation that takes its place in the bar to 1.
        self.rotation = (bpb + 1 - nearest.index_in_bar.clamp(1, bpb)) % bpb;
    }

    /// The grid on the wall clock, its beats numbered on from the last one given out (so a
    /// leader's count never jumps by more than the bar needs).
    fn on_wall(&mut self, grid: &BeatGrid, map: &WallMap) -> Option<ClockGrid> {
        if !grid.locked || grid.period_s <= 0.0 {
            self.counted = None;
            return None;
        }
        let bpb = i64::from(grid.beats_per_bar.max(1));
        let index = i64::from(grid.next_index_in_bar.max(1)) - 1;
        let mut number = match self.counted {
            Some((at_s, n)) => n + ((grid.next_beat_s - at_s) / grid.period_s).round() as i64,
            None => index,
        };
        // Keep the count on the grid's bar: the nearest number with the right place in it.
        let off = (index - number).rem_euclid(bpb);
        number += if off * 2 > bpb { off - bpb } else { off };
        self.counted = Some((grid.next_beat_s, number));
        let mut wall = ClockGrid::new(
            map.wall_us_at(grid.next_beat_s),
            number as f64,
            60.0 / (grid.period_s / map.speed),
            grid.beats_per_bar,
        )?;
        wall.bar_known = true;
        Some(wall)
    }
}

/// An external clock's grid as the dancer needs it at stream time `t_s`.
fn on_stream(clock: &ClockGrid, t_s: f64, map: &WallMap) -> BeatGrid {
    let next = clock.beat_at(map.wall_us_at(t_s)).floor() + 1.0;
    BeatGrid {
        next_beat_s: map.stream_at(clock.time_of(next)),
        period_s: clock.period_us * 1e-6 * map.speed,
        next_index_in_bar: clock.index_in_bar(next as i64),
        beats_per_bar: clock.beats_per_bar.max(1),
        bar_confidence: 1.0,
        locked: true,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MAP: WallMap = WallMap {
        audio_end_s: 10.0,
        wall_ns: 20_000_000_000,
        speed: 1.0,
    };

    fn heard(next_beat_s: f64, bpm: f64, index: u32) -> BeatGrid {
        BeatGrid {
            next_beat_s,
            period_s: 60.0 / bpm,
            next_index_in_bar: index,
            beats_per_bar: 4,
            bar_confidence: 0.9,
            locked: true,
        }
    }

    fn following(source: ClockSource, grid: Option<ClockGrid>) -> ClockSnapshot {
        ClockSnapshot {
            source,
            grid,
            ..ClockSnapshot::default()
        }
    }

    #[test]
    fn the_wall_and_stream_clocks_map_both_ways() {
        assert_eq!(MAP.stream_at(20_000_000.0), 10.0);
        assert!((MAP.stream_at(20_500_000.0) - 10.5).abs() < 1e-12);
        assert!((MAP.wall_us_at(9.0) - 19_000_000.0).abs() < 1e-6);
        let fast = WallMap { speed: 2.0, ..MAP };
        assert!((fast.stream_at(21_000_000.0) - 12.0).abs() < 1e-12);
        assert!((fast.wall_us_at(12.0) - 21_000_000.0).abs() < 1e-6);
    }

    #[test]
    fn the_audio_clock_passes_the_heard_grid_through() {
        let mut s = GridSteer::new();
        let h = heard(10.2, 120.0, 3);
        let out = s.steer(&ClockSnapshot::default(), &h, 10.0, &MAP);
        assert_eq!(out.grid, h);
        assert!(!out.fallback);
        let wall = out.wall.unwrap();
        assert!((wall.time_of(wall.anchor_beat) - 20_200_000.0).abs() < 1e-3);
        assert_eq!(wall.index_in_bar(wall.anchor_beat as i64), 3);
    }

    #[test]
    fn an_external_clock_replaces_the_heard_grid_on_the_stream_axis() {
        // Beat 0 (a downbeat) at wall 20.1 s, 128 BPM.
        let clock = ClockGrid::new(20_100_000.0, 0.0, 128.0, 4).unwrap();
        let mut s = GridSteer::new();
        let snap = following(ClockSource::Midi, Some(clock));
        let out = s.steer(&snap, &heard(10.3, 90.0, 2), 10.0, &MAP);
        assert!((out.grid.next_beat_s - 10.1).abs() < 1e-9);
        assert_eq!(out.grid.next_index_in_bar, 1);
        assert!((out.grid.tempo_bpm() - 128.0).abs() < 1e-9);
        assert!(!out.fallback);
        // The MIDI clock stopped: the heard beats stand in, flagged.
        let out = s.steer(
            &following(ClockSource::Midi, None),
            &heard(10.3, 90.0, 2),
            10.0,
            &MAP,
        );
        assert!(out.fallback);
        assert_eq!(out.grid.next_beat_s, 10.3);
    }

    #[test]
    fn the_offset_of_heard_beats_is_measured_and_trimmed_toward_when_asked() {
        let clock = ClockGrid::new(20_000_000.0, 0.0, 120.0, 4).unwrap();
        let mut snap = following(ClockSource::Link, Some(clock));
        let mut s = GridSteer::new();
        // The music is heard 12 ms after the clock's beats.
        let mut last = None;
        for k in 0..8 {
            let beat = 10.0 + 0.5 * f64::from(k) + 0.012;
            let out = s.steer(&snap, &heard(beat, 120.0, 1), beat - 0.25, &MAP);
            last = out.new_offset_ms.or(last);
            assert!((out.grid.next_beat_s - (10.0 + 0.5 * f64::from(k))).abs() < 1e-9);
        }
        assert!((last.unwrap() - 12.0).abs() < 0.01, "{last:?}");
        snap.trim = true;
        let mut shifted = 0.0;
        for k in 8..40 {
            let beat = 10.0 + 0.5 * f64::from(k) + 0.012;
            let out = s.steer(&snap, &heard(beat, 120.0, 1), beat - 0.25, &MAP);
            shifted = out.grid.next_beat_s - (10.0 + 0.5 * f64::from(k));
        }
        assert!((shifted - 0.012).abs() < 0.001, "trimmed by {shifted}");
        assert!((s.trim_ms() - 12.0).abs() < 1.0);
        // At half the clock's tempo the heard beats are not compared.
        let mut s = GridSteer::new();
        for k in 0..8 {
            let beat = 10.0 + f64::from(k);
            assert_eq!(
                s.steer(&snap, &heard(beat, 60.0, 1), beat - 0.5, &MAP)
                    .new_offset_ms,
                None
            );
        }
    }

    #[test]
    fn a_nudge_moves_every_beat_and_beat_one_rotates_the_bar() {
        let mut s = GridSteer::new();
        let h = heard(10.5, 120.0, 3);
        let mut snap = ClockSnapshot {
            nudge_ms: 20.0,
            ..ClockSnapshot::default()
        };
        let out = s.steer(&snap, &h, 10.0, &MAP);
        assert!((out.grid.next_beat_s - 10.52).abs() < 1e-9);
        assert_eq!(out.grid.next_index_in_bar, 3);
        // "One" pressed at stream 10.99 s: the beat at 11.02 (index 4) is the bar's first.
        snap.beat_one_requests = 1;
        snap.beat_one_at_us = 20_990_000.0;
        let out = s.steer(&snap, &h, 10.0, &MAP);
        assert_eq!(
            out.grid.next_index_in_bar, 4,
            "10.52 is now the bar's last beat"
        );
        let b = out.grid.beat_after(11.0).unwrap();
        assert_eq!((b.index_in_bar, (b.time_s * 100.0).round()), (1, 1102.0));
        // It stays until another clock is chosen.
        let out = s.steer(&snap, &heard(11.02, 120.0, 4), 10.6, &MAP);
        assert_eq!(out.grid.next_index_in_bar, 1);
        snap.source = ClockSource::Tap;
        snap.grid = ClockGrid::new(20_000_000.0, 0.0, 120.0, 4);
        let out = s.steer(&snap, &h, 10.0, &MAP);
        assert_eq!(
            out.grid.next_index_in_bar, 2,
            "beat 1 at 10.0, so 10.5 is beat 2"
        );
    }

    #[test]
    fn the_wall_count_runs_on_across_frames_and_follows_a_new_bar_by_the_shortest_way() {
        let mut s = GridSteer::new();
        let first = s.steer(
            &ClockSnapshot::default(),
            &heard(10.5, 120.0, 1),
            10.0,
            &MAP,
        );
        let n0 = first.wall.unwrap().anchor_beat;
        assert_eq!(n0, 0.0);
        let next = s.steer(
            &ClockSnapshot::default(),
            &heard(11.0, 120.0, 2),
            10.6,
            &MAP,
        );
        assert_eq!(next.wall.unwrap().anchor_beat, 1.0);
        // The tracker moves the bar by one beat: the count moves by one, not three.
        let moved = s.steer(
            &ClockSnapshot::default(),
            &heard(11.5, 120.0, 4),
            11.1,
            &MAP,
        );
        assert_eq!(moved.wall.unwrap().anchor_beat, 3.0);
        let lost = s.steer(&ClockSnapshot::default(), &BeatGrid::default(), 11.2, &MAP);
        assert_eq!(lost.wall, None);
    }
}
