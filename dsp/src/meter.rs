//! Bar position and meter (3/4 or 4/4) from beat-synchronous evidence.
//!
//! Downbeats tend to carry a harmonic change (chords move on bar lines) and a bass or kick
//! attack. At every beat the tracker scores both cues and accumulates them per bar position
//! for each meter hypothesis; the hypothesis whose positions differ most wins, with hysteresis
//! so the count does not flap.

/// Meters considered, in beats per bar.
const METERS: [usize; 2] = [3, 4];
/// Weight of a new beat in the per-position averages.
const POSITION_ALPHA: f32 = 0.2;
/// A new (meter, downbeat) hypothesis must beat the current one by this factor.
const SWITCH_MARGIN: f32 = 1.25;
/// Frames of bass flux looked back over at a beat.
const BASS_FRAMES: usize = 4;
/// Frames after a reported beat whose bass flux still counts for it: the beat is reported
/// within a frame or two of its onset, and a bass note's flux can peak just after that.
const BASS_FRAMES_AFTER: u32 = 3;

/// Causal bar tracker driven by beat events and per-frame chroma and bass flux.
pub struct MeterTracker {
    chroma_acc: [f32; 12],
    chroma_frames: u32,
    prev_chroma: [f32; 12],
    bass: [f32; BASS_FRAMES],
    bass_pos: usize,
    mean_change: f32,
    mean_bass: f32,
    pending_bass: f32,
    frames_since_beat: u32,
    scores: [[f32; 4]; 2],
    beat_count: usize,
    current: (usize, usize),
    beats_per_bar: usize,
    beat_in_bar: usize,
}

impl Default for MeterTracker {
    fn default() -> Self {
        Self::new()
    }
}

impl MeterTracker {
    /// A tracker that assumes 4/4 until the evidence says otherwise.
    pub fn new() -> Self {
        Self {
            chroma_acc: [0.0; 12],
            chroma_frames: 0,
            prev_chroma: [0.0; 12],
            bass: [0.0; BASS_FRAMES],
            bass_pos: 0,
            mean_change: 1e-3,
            mean_bass: 1e-3,
            pending_bass: 0.0,
            frames_since_beat: u32::MAX,
            scores: [[0.0; 4]; 2],
            beat_count: 0,
            current: (1, 0),
            beats_per_bar: 4,
            beat_in_bar: 1,
        }
    }

    /// Feeds one analysis frame's chroma and bass onset strength.
    pub fn frame(&mut self, chroma: &[f32; 12], bass_flux: f32) {
        for (a, &c) in self.chroma_acc.iter_mut().zip(chroma) {
            *a += c;
        }
        self.chroma_frames += 1;
        let bass = bass_flux.max(0.0);
        self.bass[self.bass_pos] = bass;
        if self.frames_since_beat < BASS_FRAMES_AFTER {
            self.pending_bass = self.pending_bass.max(bass);
        }
        self.frames_since_beat = self.frames_since_beat.saturating_add(1);
        self.bass_pos = (self.bass_pos + 1) % BASS_FRAMES;
    }

    /// Registers a beat; returns its position in the bar (1 = downbeat) and the beats per bar.
    ///
    /// The chroma of the beat span that just ended tells whether the *previous* beat began a new
    /// chord, so the evidence is booked one beat late; the count itself is never delayed.
    pub fn beat(&mut self) -> (usize, usize) {
        let n = self.chroma_frames.max(1) as f32;
        let mut mean = [0.0f32; 12];
        for (m, a) in mean.iter_mut().zip(&self.chroma_acc) {
            *m = a / n;
        }
        let change = cosine_distance(&mean, &self.prev_chroma);
        self.prev_chroma = mean;
        self.chroma_acc = [0.0; 12];
        self.chroma_frames = 0;
        let bass_now = self.bass.iter().fold(0.0f32, |m, &v| m.max(v));
        let index = self.beat_count;
        self.beat_count += 1;
        if index >= 2 {
            self.mean_change += 0.1 * (change - self.mean_change);
            self.mean_bass += 0.1 * (self.pending_bass - self.mean_bass);
            let evidence =
                change / self.mean_change.max(1e-3) + self.pending_bass / self.mean_bass.max(1e-3);
            for (mi, &m) in METERS.iter().enumerate() {
                let p = (index - 1) % m;
                self.scores[mi][p] += POSITION_ALPHA * (evidence - self.scores[mi][p]);
            }
        }
        self.pending_bass = bass_now;
        self.frames_since_beat = 0;
        // Wait for a couple of bars before trusting any hypothesis.
        if index >= 8 {
            let (best, best_c) = self.best_hypothesis();
            let cur_c = self.contrast(self.current.0, self.current.1);
            if best != self.current && best_c > cur_c * SWITCH_MARGIN + 0.05 {
                self.current = best;
            }
        }
        let (mi, pos) = self.current;
        let m = METERS[mi];
        self.beats_per_bar = m;
        self.beat_in_bar = (index + m - pos % m) % m + 1;
        (self.beat_in_bar, m)
    }

    fn contrast(&self, mi: usize, pos: usize) -> f32 {
        let m = METERS[mi];
        let s = &self.scores[mi][..m];
        let others = (s.iter().sum::<f32>() - s[pos]) / (m - 1) as f32;
        s[pos] - others
    }

    fn best_hypothesis(&self) -> ((usize, usize), f32) {
        let mut best = ((1, 0), f32::MIN);
        for (mi, &m) in METERS.iter().enumerate() {
            for pos in 0..m {
                let c = self.contrast(mi, pos);
                if c > best.1 {
                    best = ((mi, pos), c);
                }
            }
        }
        best
    }

    /// Beats per bar of the current hypothesis.
    pub fn beats_per_bar(&self) -> usize {
        self.beats_per_bar
    }

    /// Position of the last beat in its bar (1 = downbeat).
    pub fn beat_in_bar(&self) -> usize {
        self.beat_in_bar
    }

    /// Position in the bar in [0, 1) given the position in the current beat.
    pub fn bar_phase(&self, beat_phase: f64) -> f64 {
        ((self.beat_in_bar - 1) as f64 + beat_phase.clamp(0.0, 1.0)) / self.beats_per_bar as f64
    }
}

fn cosine_distance(a: &[f32; 12], b: &[f32; 12]) -> f32 {
    let dot: f32 = a.iter().zip(b).map(|(x, y)| x * y).sum();
    let na: f32 = a.iter().map(|x| x * x).sum::<f32>().sqrt();
    let nb: f32 = b.iter().map(|x| x * x).sum::<f32>().sqrt();
    if na < 1e-6 || nb < 1e-6 {
        0.0
    } else {
        1.0 - dot / (na * nb)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Beat b sounds the chord of its bar from b to b+1; the bass hits on downbeats land in
    /// the frames just before the tracker reports the beat.
    fn run(meter: usize, downbeat_offset: usize) -> Vec<(usize, usize)> {
        let chords = [
            [1.0, 0., 0., 0., 1., 0., 0., 1., 0., 0., 0., 0.],
            [0., 0., 1., 0., 0., 1., 0., 0., 0., 1., 0., 0.],
            [0., 0., 0., 0., 1., 0., 0., 0., 0., 0., 0., 1.],
        ];
        let bar_of = |b: usize| (b + meter * 10 - downbeat_offset) / meter;
        let mut mt = MeterTracker::new();
        let mut out = Vec::new();
        for beat in 0..64usize {
            let is_down = (beat + meter - downbeat_offset).is_multiple_of(meter);
            let span_chord = if beat == 0 {
                [0.0; 12]
            } else {
                chords[bar_of(beat - 1) % 3]
            };
            for f in 0..40 {
                let bass = if is_down && f == 39 { 3.0 } else { 0.2 };
                mt.frame(&span_chord, bass);
            }
            out.push(mt.beat());
        }
        out
    }

    /// No chords, only a bass hit on each downbeat that peaks `late` frames after the tracker
    /// reported that beat (a bass note's flux can peak after the beat is called).
    fn run_bass_after(meter: usize, downbeat_offset: usize, late: usize) -> Vec<(usize, usize)> {
        let mut mt = MeterTracker::new();
        let mut out = Vec::new();
        let mut was_down = false;
        for beat in 0..64usize {
            for f in 0..40 {
                let bass = if was_down && f == late { 3.0 } else { 0.2 };
                mt.frame(&[0.5; 12], bass);
            }
            out.push(mt.beat());
            was_down = (beat + meter - downbeat_offset).is_multiple_of(meter);
        }
        out
    }

    /// For 3/4 and 4/4 and every downbeat offset, the count `run` gives after 32 beats is
    /// the true one.
    fn assert_counts(run: impl Fn(usize, usize) -> Vec<(usize, usize)>) {
        for meter in [3, 4] {
            for offset in 0..meter {
                let out = run(meter, offset);
                for (beat, &(in_bar, per_bar)) in out.iter().enumerate().skip(32) {
                    assert_eq!(per_bar, meter, "meter {meter} offset {offset}");
                    // Beat index `beat` was counted as beat number beat+1 by the tracker.
                    let expected = (beat + meter - offset) % meter + 1;
                    assert_eq!(
                        in_bar, expected,
                        "meter {meter} offset {offset} beat {beat}"
                    );
                }
            }
        }
    }

    #[test]
    fn a_bass_hit_just_after_the_reported_beat_marks_the_downbeat() {
        assert_counts(|meter, offset| run_bass_after(meter, offset, 1));
        // Far after the beat (half a beat), the hit no longer counts for it: no meter is heard
        // and the count keeps its 4/4 default.
        let out = run_bass_after(3, 0, 20);
        assert!(out.iter().skip(32).all(|&(_, per_bar)| per_bar == 4));
    }

    #[test]
    fn finds_three_four_and_four_four_with_their_downbeats() {
        assert_counts(run);
    }
}
