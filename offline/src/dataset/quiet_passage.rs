//! Quiet passages written into training dances (issue 21's dynamics): a few bars of the song
//! turned down and darkened, and the paired motion slowed to half time there.
//!
//! tang2018 teaches no calm: its songs do fall quiet (up to 29 % of a song sits 8 dB below its
//! recent peak), but the captured dancers keep their pace there (1.12–1.15 of it elsewhere, as
//! `danced eval` measures), so a network trained on it cannot learn to calm down when the music
//! does. A passage takes whole bars; the audio is
//! attenuated and low-passed (the drums' attacks fade, as in a breakdown) before the *streaming*
//! analysis hears it, so the features are what live would deliver; the motion runs at about
//! half pace there and falls behind its song by exactly half the passage's bars, so after it
//! the dance is on the beat and on the bar again (one bar of every two is left out).

use dsp::feature::{FEATURE_DIM, FeatureLayout, phase_of};
use model::neural::rng::Rng;

/// Frames over which the pace glides into and out of half time, in beats.
const PACE_EDGE_BEATS: f64 = 1.0;
/// Seconds over which the audio glides into and out of the passage's level and tone.
const AUDIO_EDGE_S: f64 = 0.25;
/// The longest passage, seconds (a breakdown of a few bars, as the synthetic songs have).
const LONGEST_S: f64 = 9.0;
/// Least time between two passages, and after the last one to the dance's end, seconds.
const GAP_S: f64 = 6.0;

/// One quiet passage of a dance, in its frames (at the motion's rate).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct QuietPassage {
    /// First frame of the passage (a bar's first beat).
    pub start_frame: usize,
    /// Frame after the passage.
    pub end_frame: usize,
    /// Beat position (beats from the dance's first frame) where the passage starts.
    pub start_beat: f64,
    /// Length of the passage in beats (whole bars).
    pub beats: f64,
    /// Beats the motion falls behind over the passage (half its bars).
    pub deficit_beats: f64,
    /// Level change of the audio, dB (negative).
    pub gain_db: f32,
    /// Corner of the low-pass the audio goes through, Hz.
    pub lowpass_hz: f32,
}

/// Each frame's position in beats from the first frame, from the beat phase the analysis
/// delivers (never going back: a phase that steps back holds the position).
pub fn beat_positions(music: &[[f32; FEATURE_DIM]]) -> Vec<f64> {
    let mut out = Vec::with_capacity(music.len());
    let mut position = 0.0;
    let mut last = music.first().map_or(0.0, beat_phase);
    for m in music {
        let f = beat_phase(m);
        let step = (f - last + 0.5).rem_euclid(1.0) - 0.5;
        position += step.max(0.0);
        last = f;
        out.push(position);
    }
    out
}

fn beat_phase(m: &[f32; FEATURE_DIM]) -> f64 {
    f64::from(phase_of(m[FeatureLayout::BEAT_SIN], m[FeatureLayout::BEAT_COS]).unwrap_or(0.0))
}

fn bar_phase(m: &[f32; FEATURE_DIM]) -> f32 {
    phase_of(m[FeatureLayout::BAR_SIN], m[FeatureLayout::BAR_COS]).unwrap_or(0.0)
}

/// Frames where a bar starts: the bar phase wraps (from its last quarter to its first).
fn bar_starts(music: &[[f32; FEATURE_DIM]]) -> Vec<usize> {
    (1..music.len())
        .filter(|&i| bar_phase(&music[i - 1]) > 0.75 && bar_phase(&music[i]) < 0.25)
        .collect()
}

/// Chooses about `per_minute` quiet passages a minute for a dance whose music (the features as
/// heard, frame for frame, at `rate` frames a second, its [`beat_positions`] in `beats`) has
/// `beats_per_bar` beats to the bar:
/// each of 2 or 4 bars (2 when 4 would outlast [`LONGEST_S`]) from a bar's start, where the beat
/// runs steadily, at least [`GAP_S`] apart and from the end. May be the dance's first bar (a
/// quiet intro).
pub fn plan(
    music: &[[f32; FEATURE_DIM]],
    beats: &[f64],
    rate: f64,
    beats_per_bar: usize,
    per_minute: f64,
    rng: &mut Rng,
) -> Vec<QuietPassage> {
    let starts = bar_starts(music);
    let minutes = music.len() as f64 / rate / 60.0;
    let wanted = (per_minute * minutes + rng.uniform()).floor().max(0.0) as usize;
    let gap = (GAP_S * rate) as usize;
    let mut out: Vec<QuietPassage> = Vec::new();
    let mut tries = 0;
    while out.len() < wanted && tries < 50 * wanted.max(1) && !starts.is_empty() {
        tries += 1;
        let start = starts[rng.below(starts.len())];
        let bars = if rng.uniform() < 0.5 { 2 } else { 4 };
        let Some(p) = passage_at(beats, start, bars, beats_per_bar, rate, gap, rng) else {
            continue;
        };
        let clear = out
            .iter()
            .all(|q| p.end_frame + gap <= q.start_frame || q.end_frame + gap <= p.start_frame);
        if clear {
            out.push(p);
        }
    }
    out.sort_by_key(|p| p.start_frame);
    out
}

fn passage_at(
    beats: &[f64],
    start: usize,
    bars: usize,
    beats_per_bar: usize,
    rate: f64,
    gap: usize,
    rng: &mut Rng,
) -> Option<QuietPassage> {
    let mut bars = bars;
    loop {
        let length = (bars * beats_per_bar) as f64;
        let end_beat = beats[start] + length;
        let end = start + beats[start..].iter().position(|&b| b >= end_beat)?;
        if end + gap > beats.len() {
            return None;
        }
        if (end - start) as f64 / rate > LONGEST_S {
            if bars > 2 {
                bars = 2;
                continue;
            }
            return None;
        }
        // A steady beat only: every half-second advances by about as much as the passage's mean.
        let mean = length / (end - start) as f64;
        let half = ((0.5 * rate) as usize).max(1);
        let steady = (start..end.saturating_sub(half)).step_by(half).all(|i| {
            let advance = (beats[i + half] - beats[i]) / half as f64;
            (0.7 * mean..=1.3 * mean).contains(&advance)
        });
        if !steady {
            return None;
        }
        return Some(QuietPassage {
            start_frame: start,
            end_frame: end,
            start_beat: beats[start],
            beats: length,
            deficit_beats: (bars / 2 * beats_per_bar) as f64,
            gain_db: -(6.0 + 8.0 * rng.uniform()) as f32,
            lowpass_hz: (500.0 + 1000.0 * rng.uniform()) as f32,
        });
    }
}

/// Beats the motion has fallen behind at beat position `b`: over each passage the pace runs
/// at 1 − c inside a trapezoid (edges [`PACE_EDGE_BEATS`] long), c chosen so the whole
/// passage loses its `deficit_beats`.
fn deficit_at(passages: &[QuietPassage], b: f64) -> f64 {
    passages
        .iter()
        .map(|p| {
            let x = (b - p.start_beat).clamp(0.0, p.beats);
            let e = PACE_EDGE_BEATS.min(p.beats / 2.0);
            let plateau = p.beats - e;
            // Area under the trapezoid (height 1) up to x.
            let area = if x <= e {
                0.5 * x * x / e
            } else if x <= p.beats - e {
                0.5 * e + (x - e)
            } else {
                let y = p.beats - x;
                plateau - 0.5 * y * y / e
            };
            p.deficit_beats * area / plateau
        })
        .sum()
}

/// The source frame of each of `frames` frames of a dance slowed in its quiet passages: frame i
/// shows the motion at the beat position `beats[i]` less the deficit there (interpolated
/// between frames; frame i itself outside and before every passage).
pub fn warp_times(beats: &[f64], passages: &[QuietPassage]) -> Vec<f64> {
    beats
        .iter()
        .enumerate()
        .map(|(i, &b)| {
            let d = deficit_at(passages, b);
            if d <= 0.0 {
                return i as f64;
            }
            let target = b - d;
            // The last frame at or before the target, then linear between it and the next.
            let j = beats[..=i]
                .partition_point(|&x| x <= target)
                .saturating_sub(1);
            let (b0, b1) = (beats[j], beats.get(j + 1).copied().unwrap_or(beats[j]));
            if b1 > b0 {
                j as f64 + ((target - b0) / (b1 - b0)).clamp(0.0, 1.0)
            } else {
                j as f64
            }
        })
        .collect()
}

/// The audio treatment of a dance's quiet passages, sample by sample: inside a passage (song
/// seconds, edges gliding over [`AUDIO_EDGE_S`]) the sound goes through a two-pole low-pass
/// and is turned down.
#[derive(Debug)]
pub struct QuietShaper {
    /// (start s, end s, gain, low-pass corner Hz) of each passage.
    spans: Vec<(f64, f64, f32, f32)>,
    /// Low-pass state, two poles per channel.
    state: Vec<[f32; 2]>,
}

impl QuietShaper {
    /// A shaper for `passages` of a dance whose frame 0 sits at `start_s` of the song, at
    /// `rate` frames a second.
    pub fn new(passages: &[QuietPassage], start_s: f64, rate: f64) -> Self {
        let spans = passages
            .iter()
            .map(|p| {
                (
                    start_s + p.start_frame as f64 / rate,
                    start_s + p.end_frame as f64 / rate,
                    10f32.powf(p.gain_db / 20.0),
                    p.lowpass_hz,
                )
            })
            .collect();
        Self {
            spans,
            state: Vec::new(),
        }
    }

    /// How far into a passage's treatment song time `t` is (0 outside, 1 inside), with that
    /// passage's gain and corner.
    fn depth(&self, t: f64) -> (f32, f32, f32) {
        for &(a, b, gain, corner) in &self.spans {
            if t >= a && t < b {
                let x = ((t - a) / AUDIO_EDGE_S)
                    .min((b - t) / AUDIO_EDGE_S)
                    .min(1.0);
                let w = 0.5 - 0.5 * (std::f64::consts::PI * x).cos();
                return (w as f32, gain, corner);
            }
        }
        (0.0, 1.0, 0.0)
    }

    /// Treats one block of interleaved samples, its first sample frame being `first` of the
    /// song at `sample_rate`.
    pub fn process(&mut self, samples: &mut [f32], first: u64, sample_rate: u32, channels: usize) {
        let channels = channels.max(1);
        if self.state.len() != channels {
            self.state = vec![[0.0; 2]; channels];
        }
        let rate = f64::from(sample_rate.max(1));
        for (n, frame) in samples.chunks_mut(channels).enumerate() {
            let (w, gain, corner) = self.depth((first + n as u64) as f64 / rate);
            if w <= 0.0 {
                // Outside a passage the filter follows the signal, so it has settled when one
                // begins.
                for (x, s) in frame.iter().zip(&mut self.state) {
                    *s = [*x, *x];
                }
                continue;
            }
            let c = 1.0 - (-std::f64::consts::TAU * f64::from(corner) / rate).exp() as f32;
            for (x, s) in frame.iter_mut().zip(&mut self.state) {
                s[0] += c * (*x - s[0]);
                s[1] += c * (s[0] - s[1]);
                *x = (1.0 - w) * *x + w * gain * s[1];
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Music frames at 25 fps with a steady beat of `bpm`, `beats_per_bar` to the bar.
    fn steady(frames: usize, bpm: f64, beats_per_bar: usize) -> Vec<[f32; FEATURE_DIM]> {
        (0..frames)
            .map(|i| {
                let beat = i as f64 / 25.0 * bpm / 60.0;
                let bar = beat / beats_per_bar as f64;
                let mut m = [0.0; FEATURE_DIM];
                let tau = std::f64::consts::TAU;
                m[FeatureLayout::BEAT_SIN] = (tau * beat).sin() as f32;
                m[FeatureLayout::BEAT_COS] = (tau * beat).cos() as f32;
                m[FeatureLayout::BAR_SIN] = (tau * bar).sin() as f32;
                m[FeatureLayout::BAR_COS] = (tau * bar).cos() as f32;
                m
            })
            .collect()
    }

    #[test]
    fn a_passage_runs_at_half_time_and_leaves_the_dance_on_the_bar() {
        let music = steady(25 * 90, 120.0, 4);
        let mut rng = Rng::new(3);
        let beats = beat_positions(&music);
        let passages = plan(&music, &beats, 25.0, 4, 2.0, &mut rng);
        assert!(!passages.is_empty(), "no passage planned");
        let times = warp_times(&beats, &passages);
        let frames_per_beat = 25.0 * 60.0 / 120.0;
        let p = passages[0];
        assert!(p.beats == 8.0 || p.beats == 16.0, "{p:?}");
        assert_eq!(p.deficit_beats, p.beats / 2.0);
        // Before the passage: the dance as it was.
        for (i, &t) in times.iter().enumerate().take(p.start_frame) {
            assert_eq!(t, i as f64);
        }
        // Inside, between the edges: under half pace (the edges run faster).
        let (a, b) = (
            p.start_frame + frames_per_beat as usize + 1,
            p.end_frame - frames_per_beat as usize - 1,
        );
        let pace = (times[b] - times[a]) / (b - a) as f64;
        assert!((0.38..0.48).contains(&pace), "pace {pace}");
        // After it (and before the next): behind by whole bars, so on the beat and the bar.
        let after = p.end_frame + 10;
        let behind = (after as f64 - times[after]) / frames_per_beat;
        assert!(
            (behind - p.deficit_beats).abs() < 0.05,
            "behind {behind} beats"
        );
        assert_eq!(behind.round() as usize % 4, 0);
        // The source never goes back.
        assert!(times.windows(2).all(|w| w[1] >= w[0]));
    }

    #[test]
    fn passages_are_whole_bars_apart_from_each_other_and_the_end() {
        let music = steady(25 * 120, 87.0, 3);
        let mut rng = Rng::new(9);
        let passages = plan(&music, &beat_positions(&music), 25.0, 3, 3.0, &mut rng);
        assert!(passages.len() >= 3, "{passages:?}");
        for w in passages.windows(2) {
            assert!(w[0].end_frame + 150 <= w[1].start_frame, "{w:?}");
        }
        for p in &passages {
            assert!(p.beats == 6.0 || p.beats == 12.0, "{p:?}");
            assert!((p.end_frame - p.start_frame) as f64 / 25.0 <= LONGEST_S);
            assert!(p.end_frame + 150 <= music.len());
            assert!((-14.0..=-6.0).contains(&p.gain_db));
        }
    }

    #[test]
    fn the_shaper_turns_down_and_darkens_only_the_passage() {
        let p = QuietPassage {
            start_frame: 50,
            end_frame: 150,
            start_beat: 0.0,
            beats: 8.0,
            deficit_beats: 4.0,
            gain_db: -12.0,
            lowpass_hz: 800.0,
        };
        let rate = 8000.0;
        let mut shaper = QuietShaper::new(&[p], 1.0, 25.0);
        // A 3 kHz tone: well above the corner, so the passage takes it down by far more than
        // the gain alone.
        let tone: Vec<f32> = (0..(10.0 * rate) as usize)
            .map(|n| (std::f64::consts::TAU * 3000.0 * n as f64 / rate).sin() as f32)
            .collect();
        let mut out = tone.clone();
        for (k, block) in out.chunks_mut(1000).enumerate() {
            shaper.process(block, k as u64 * 1000, rate as u32, 1);
        }
        let rms = |a: f64, b: f64| {
            let s = &out[(a * rate) as usize..(b * rate) as usize];
            (s.iter().map(|x| x * x).sum::<f32>() / s.len() as f32).sqrt()
        };
        let full = rms(0.2, 2.8);
        assert!((full - 0.707).abs() < 0.01, "outside {full}");
        let inside = rms(3.5, 6.5);
        assert!(inside < 0.707 * 0.25 * 0.3, "inside {inside}");
        assert!((rms(7.5, 9.5) - 0.707).abs() < 0.01);
    }
}
