//! A rhythm track for a dance that has no music, rendered on the beat grid found from its
//! motion: a kick on every beat, a backbeat, hi-hats between, a bass whose root changes on the
//! bar lines (bars are heard by their harmony as much as by their accents), everything louder
//! and busier where the dance moves harder. A few sounds and a chord progression are drawn
//! from a seed, so dances do not all sound alike. Listening to it beside the dance (`danced view
//! DANCE.bvh --audio TRACK.wav`) shows whether the beat found is the one danced; heard through
//! the streaming analysis, it is music a dancer can be trained on.

use std::f64::consts::TAU;

use model::motion_beat::MotionBeatGrid;

/// Sample rate of the tracks, Hz (the analysis' own rate).
pub const ACCOMPANIMENT_RATE: u32 = 22_050;

/// Chord roots (MIDI notes) of the progressions a track draws from, one a bar.
const PROGRESSIONS: [[u8; 4]; 4] = [
    [36, 43, 45, 41],
    [38, 41, 36, 43],
    [33, 41, 36, 43],
    [40, 45, 38, 43],
];

/// The sounds of one track, drawn from its seed.
#[derive(Clone, Copy, Debug)]
struct Kit {
    kick_hz: f64,
    kick_decay_s: f64,
    snare_tone_hz: f64,
    hat_decay_s: f64,
    progression: [u8; 4],
}

impl Kit {
    fn drawn(rng: &mut Rng) -> Self {
        Kit {
            kick_hz: 45.0 + 20.0 * rng.unit(),
            kick_decay_s: 0.09 + 0.08 * rng.unit(),
            snare_tone_hz: 160.0 + 80.0 * rng.unit(),
            hat_decay_s: 0.008 + 0.012 * rng.unit(),
            progression: PROGRESSIONS
                [(rng.unit() * PROGRESSIONS.len() as f64) as usize % PROGRESSIONS.len()],
        }
    }
}

/// A small deterministic generator (the same seed, the same track).
#[derive(Clone, Copy, Debug)]
struct Rng(u64);

impl Rng {
    fn unit(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// A rendered track and the beats it plays.
#[derive(Clone, Debug)]
pub struct Accompaniment {
    /// Mono samples at [`ACCOMPANIMENT_RATE`], peak 0.7.
    pub samples: Vec<f32>,
    /// The beats played: time (s) and place in the bar (1 = its first beat).
    pub beats: Vec<(f64, usize)>,
}

/// How hard the dance moves over each beat of `grid`, 0..1 by rank among its beats (so a calm
/// dance and a wild one both span the range): the mean of `speed` (summed joint speed per
/// frame at `fps`) over the beat.
pub fn beat_intensity(grid: &MotionBeatGrid, speed: &[f64], fps: f64) -> Vec<f64> {
    let beats = &grid.beats_s;
    let means: Vec<f64> = beats
        .iter()
        .enumerate()
        .map(|(k, &t)| {
            let end = beats.get(k + 1).copied().unwrap_or(t + 0.5);
            let (a, b) = (
                (t * fps) as usize,
                ((end * fps) as usize).max((t * fps) as usize + 1),
            );
            let span = &speed[a.min(speed.len())..b.min(speed.len())];
            if span.is_empty() {
                0.0
            } else {
                span.iter().sum::<f64>() / span.len() as f64
            }
        })
        .collect();
    let mut order: Vec<usize> = (0..means.len()).collect();
    order.sort_by(|&a, &b| means[a].total_cmp(&means[b]));
    let mut rank = vec![0.0; means.len()];
    let n = means.len().max(2) - 1;
    for (r, &i) in order.iter().enumerate() {
        rank[i] = r as f64 / n as f64;
    }
    rank
}

/// Renders `seconds` of accompaniment on `grid` (bars of its `beats_per_bar`, 4 when the motion
/// shows none, counted from its `first_downbeat`), each beat as loud and busy as `intensity`
/// (0..1 per beat, [`beat_intensity`]) says; `seed` draws the sounds.
pub fn accompany(
    grid: &MotionBeatGrid,
    intensity: &[f64],
    seconds: f64,
    seed: u64,
) -> Accompaniment {
    let rate = f64::from(ACCOMPANIMENT_RATE);
    let n = (seconds.max(0.0) * rate) as usize;
    let mut out = vec![0.0f64; n];
    let mut rng = Rng(seed ^ 0x9e37_79b9_7f4a_7c15);
    let kit = Kit::drawn(&mut rng);
    let per_bar = grid.beats_per_bar.unwrap_or(4).max(1);
    let mut beats = Vec::with_capacity(grid.beats_s.len());
    let mut add = |start: f64, len: f64, f: &mut dyn FnMut(f64) -> f64| {
        let s = (start.max(0.0) * rate) as usize;
        let e = ((start + len) * rate) as usize;
        for (i, v) in out.iter_mut().enumerate().take(e.min(n)).skip(s) {
            *v += f(i as f64 / rate - start);
        }
    };
    for (k, &t) in grid.beats_s.iter().enumerate() {
        if t >= seconds {
            break;
        }
        let next = grid.beats_s.get(k + 1).copied().unwrap_or(t + 0.5);
        let period = (next - t).clamp(0.2, 2.0);
        let pos = (k + per_bar * 8 - grid.first_downbeat % per_bar) % per_bar;
        beats.push((t, pos + 1));
        let energy = intensity.get(k).copied().unwrap_or(0.5).clamp(0.0, 1.0);
        let level = 0.45 + 0.55 * energy;
        let accent = if pos == 0 { 1.25 } else { 1.0 };
        let kit_ = kit;
        add(t, 0.3, &mut |x| {
            let f = kit_.kick_hz + 90.0 * (-x / 0.03).exp();
            0.8 * level * accent * (TAU * f * x).sin() * (-x / kit_.kick_decay_s).exp()
        });
        // The backbeat: 2 and 4 in four, 2 and 3 in three, the second in two.
        let backbeat = match per_bar {
            3 => pos != 0,
            4 => pos % 2 == 1,
            _ => pos % 2 == 1,
        };
        if backbeat {
            let mut noise = rng;
            add(t, 0.2, &mut |x| {
                level
                    * (0.35 * (noise.unit() * 2.0 - 1.0) * (-x / 0.05).exp()
                        + 0.2 * (TAU * kit_.snare_tone_hz * x).sin() * (-x / 0.04).exp())
            });
            rng.unit();
        }
        // Hats: eighths, sixteenths where the dance is busiest, none where it is calmest.
        let hats: &[f64] = if energy > 0.75 {
            &[0.0, 0.25, 0.5, 0.75]
        } else if energy > 0.2 {
            &[0.0, 0.5]
        } else {
            &[]
        };
        for &h in hats {
            let mut noise = rng;
            add(t + h * period, 0.05, &mut |x| {
                0.08 * level * (noise.unit() * 2.0 - 1.0) * (-x / kit_.hat_decay_s).exp()
            });
            rng.unit();
        }
        // The bass: the bar's root, on every beat.
        let bar = (k + per_bar * 8 - grid.first_downbeat % per_bar) / per_bar;
        let root = kit.progression[bar % 4];
        let hz = 440.0 * 2f64.powf((f64::from(root) - 69.0) / 12.0);
        add(t, period * 0.9, &mut |x| {
            0.3 * level * (TAU * hz * x).sin() * (-x / 0.35).exp()
        });
    }
    let peak = out.iter().fold(0.0f64, |m, v| m.max(v.abs())).max(1e-9);
    let gain = 0.7 / peak;
    Accompaniment {
        samples: out.iter().map(|&v| (v * gain) as f32).collect(),
        beats,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analysis::{AnalyzeOptions, analyze_samples};

    /// A dance's grid: `bpm` with a slow wobble (a dancer is no drum machine), bars of
    /// `per_bar` from beat 1.
    fn grid(bpm: f64, per_bar: usize, seconds: f64) -> MotionBeatGrid {
        let mut beats = Vec::new();
        let mut t = 0.4;
        let mut k = 0.0f64;
        while t < seconds {
            beats.push(t);
            t += 60.0 / bpm * (1.0 + 0.015 * (k * 0.3).sin());
            k += 1.0;
        }
        MotionBeatGrid {
            beats_s: beats,
            tempo_bpm: bpm,
            confidence: 0.8,
            beats_per_bar: Some(per_bar),
            first_downbeat: 1,
            bar_confidence: 0.5,
        }
    }

    #[test]
    fn the_analysis_hears_the_dances_beats_and_bars_in_its_track() {
        for (bpm, per_bar, seed) in [(96.0, 4, 1), (128.0, 4, 2), (150.0, 3, 3)] {
            let seconds = 40.0;
            let g = grid(bpm, per_bar, seconds);
            let intensity: Vec<f64> = (0..g.beats_s.len())
                .map(|k| (k % 16) as f64 / 15.0)
                .collect();
            let track = accompany(&g, &intensity, seconds, seed);
            assert_eq!(track.samples.len(), (seconds * 22_050.0) as usize);
            assert!(
                track
                    .samples
                    .iter()
                    .all(|s| s.is_finite() && s.abs() <= 0.7001)
            );
            // Beat 1 (index 1) is the first downbeat.
            assert_eq!(track.beats[1].1, 1);
            assert_eq!(track.beats[0].1, per_bar);
            let heard = analyze_samples(
                "accompaniment",
                &track.samples,
                ACCOMPANIMENT_RATE,
                1,
                AnalyzeOptions::native(None),
            )
            .unwrap();
            // Scored as mir_eval does: ±70 ms, the first 5 s left out.
            let score = |truth: &[f64], heard: &[f64]| {
                dsp::metrics::beat_f_measure(
                    &dsp::metrics::trim_beats(truth, 5.0),
                    &dsp::metrics::trim_beats(heard, 5.0),
                    0.07,
                )
            };
            let heard_beats: Vec<f64> = heard.beats.iter().map(|b| b.time_s).collect();
            let truth: Vec<f64> = track.beats.iter().map(|b| b.0).collect();
            let f = score(&truth, &heard_beats);
            let downbeats: Vec<f64> = track
                .beats
                .iter()
                .filter(|b| b.1 == 1)
                .map(|b| b.0)
                .collect();
            let heard_down: Vec<f64> = heard
                .beats
                .iter()
                .filter(|b| b.beat_in_bar == 1)
                .map(|b| b.time_s)
                .collect();
            let fd = score(&downbeats, &heard_down);
            eprintln!("{bpm} BPM in {per_bar}: beat F {f:.3}, downbeat F {fd:.3}");
            assert!(f >= 0.9, "{bpm} BPM: beat F {f:.3}");
            assert!(fd >= 0.8, "{bpm} BPM: downbeat F {fd:.3}");
        }
    }

    #[test]
    fn intensity_ranks_the_beats_by_how_hard_the_dance_moves() {
        let g = grid(120.0, 4, 10.0);
        // Speed rises through the dance at 30 frames a second.
        let speed: Vec<f64> = (0..300).map(f64::from).collect();
        let r = beat_intensity(&g, &speed, 30.0);
        assert_eq!(r.len(), g.beats_s.len());
        assert!(r.windows(2).all(|w| w[1] >= w[0]), "{r:?}");
        assert_eq!(r[0], 0.0);
        assert_eq!(*r.last().unwrap(), 1.0);
    }
}
