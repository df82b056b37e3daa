//! The beat of a dance found from its motion alone: a tempo and phase fitted through its
//! kinematic beats, and its bars where the motion shows them.
//!
//! A dance without its music still carries the music's pulse: dancers stop, turn and land on
//! the beat, so the summed speed of the joints dips there (FACT's kinematic beats are these
//! dips; [`crate::metrics::kinematic_beats`]). The grid is fitted offline, over the whole dance:
//!
//! 1. the *dip strength* at each frame: how far the joint speed, lightly smoothed, falls below
//!    its mean over the surrounding beat-length window (zero where it does not), so a deep stop
//!    counts more than a wobble;
//! 2. the tempo: the autocorrelation of the dip strength at each beat period of
//!    [`MIN_TEMPO_BPM`]–[`MAX_TEMPO_BPM`] and its first multiples, weighted by a log-normal prior
//!    around [`PRIOR_TEMPO_BPM`] (the metrical level dancers step at);
//! 3. the beats: dynamic programming over the dip strength (Ellis, "Beat tracking by dynamic
//!    programming", 2007), which trades landing on dips against keeping the period, so missed
//!    dips are bridged and extra dips between beats are passed over;
//! 4. the confidence: the share of the grid's beats with a kinematic beat within
//!    [`MATCH_FRACTION`] of a beat of them;
//! 5. bars: the poses a whole number of beats apart are compared; where poses 3 or 4 beats
//!    apart (or 6 or 8) are clearly more alike than poses 1 or 2 apart, that is the bar, and
//!    its first beat is the one the dance moves hardest into (dancers accent the one).

use glam::Vec3;

use crate::ModelError;
use crate::metrics::{JointTrack, kinematic_beats, summed_joint_speed};

/// Slowest beat the grid looks for, BPM.
pub const MIN_TEMPO_BPM: f64 = 55.0;
/// Fastest beat the grid looks for, BPM.
pub const MAX_TEMPO_BPM: f64 = 190.0;
/// Centre of the tempo prior, BPM.
pub const PRIOR_TEMPO_BPM: f64 = 110.0;
/// Width of the tempo prior, octaves (standard deviation of log2 tempo).
const PRIOR_OCTAVES: f64 = 0.7;
/// How strongly the dynamic programme holds the period: cost per squared log ratio of an
/// interval to the period, in units of the mean dip strength.
const TIGHTNESS: f64 = 20.0;
/// A grid beat counts as seen when a kinematic beat is within this fraction of a beat of it.
pub const MATCH_FRACTION: f64 = 0.15;
/// Shortest dance a grid is fitted to, seconds.
pub const MIN_SECONDS: f64 = 4.0;
/// How much more alike poses a bar apart must be than poses a beat or two apart for the bar to
/// count (ratio of mean pose distances).
const BAR_CONTRAST: f64 = 0.8;

/// A dance's beat grid, as found from its motion.
#[derive(Clone, Debug, PartialEq)]
pub struct MotionBeatGrid {
    /// Beat times, seconds from the first frame, increasing.
    pub beats_s: Vec<f64>,
    /// Tempo, BPM (60 over the median interval).
    pub tempo_bpm: f64,
    /// Share of the beats a kinematic beat confirms, [0, 1].
    pub confidence: f64,
    /// Beats in a bar when the motion shows bars (2, 3 or 4), else `None`.
    pub beats_per_bar: Option<usize>,
    /// Index into `beats_s` of a first beat of a bar (0 without bars).
    pub first_downbeat: usize,
    /// How clearly the motion repeats at the bar: 1 − (distance a bar apart) / (distance a
    /// beat or two apart), 0 without bars.
    pub bar_confidence: f64,
}

impl MotionBeatGrid {
    /// Beat phase at `t` seconds, [0, 1): 0 on a beat; `None` outside the grid.
    pub fn beat_phase(&self, t: f64) -> Option<f64> {
        let k = self.beats_s.partition_point(|&b| b <= t);
        if k == 0 || k >= self.beats_s.len() {
            return None;
        }
        let (a, b) = (self.beats_s[k - 1], self.beats_s[k]);
        Some(((t - a) / (b - a)).clamp(0.0, 1.0 - 1e-9))
    }

    /// Bar phase at `t` seconds, [0, 1): 0 on a bar's first beat; counted in fours from the
    /// first beat when the motion shows no bars. `None` outside the grid.
    pub fn bar_phase(&self, t: f64) -> Option<f64> {
        let beat = self.beat_phase(t)?;
        let k = self.beats_s.partition_point(|&b| b <= t) - 1;
        let per_bar = self.beats_per_bar.unwrap_or(4);
        let in_bar =
            (k + per_bar * (self.first_downbeat / per_bar + 1) - self.first_downbeat) % per_bar;
        Some((in_bar as f64 + beat) / per_bar as f64)
    }
}

/// The vertex of the parabola through `(−1, l)`, `(0, c)`, `(1, r)`, as an offset from the
/// middle sample in [−0.5, 0.5]; 0 unless `c` is a peak.
fn parabolic_offset(l: f64, c: f64, r: f64) -> f64 {
    let denom = l - 2.0 * c + r;
    if denom < 0.0 {
        (0.5 * (l - r) / denom).clamp(-0.5, 0.5)
    } else {
        0.0
    }
}

/// Mean of `x` over `i − half ..= i + half` (clamped to the ends), for every `i`.
fn moving_mean(x: &[f64], half: usize) -> Vec<f64> {
    let mut prefix = Vec::with_capacity(x.len() + 1);
    prefix.push(0.0);
    for v in x {
        prefix.push(prefix.last().copied().unwrap_or(0.0) + v);
    }
    (0..x.len())
        .map(|i| {
            let a = i.saturating_sub(half);
            let b = (i + half + 1).min(x.len());
            (prefix[b] - prefix[a]) / (b - a) as f64
        })
        .collect()
}

/// The dip strength of step 1 (module documentation), normalised to mean 1 where non-zero.
fn dip_strength(speed: &[f64], fps: f64) -> Vec<f64> {
    let smooth = moving_mean(speed, 1);
    // A window about one beat at the prior tempo wide.
    let half = ((60.0 / PRIOR_TEMPO_BPM) * fps * 0.5).round().max(1.0) as usize;
    let local = moving_mean(&smooth, half);
    // The ends' windows are cut short, which fakes dips there: none within two samples.
    let n = smooth.len();
    let dips: Vec<f64> = smooth
        .iter()
        .zip(&local)
        .enumerate()
        .map(|(i, (s, m))| {
            if i < 2 || i + 2 >= n {
                0.0
            } else {
                (m - s).max(0.0)
            }
        })
        .collect();
    let mean = dips.iter().sum::<f64>() / dips.len().max(1) as f64;
    if mean <= 0.0 {
        return dips;
    }
    dips.iter().map(|d| d / mean).collect()
}

/// The beat period, frames, of step 2 (module documentation).
fn period_frames(dips: &[f64], fps: f64) -> Option<f64> {
    let mean = dips.iter().sum::<f64>() / dips.len() as f64;
    let x: Vec<f64> = dips.iter().map(|d| d - mean).collect();
    let shortest = (60.0 / MAX_TEMPO_BPM * fps).floor().max(2.0) as usize;
    let longest = (60.0 / MIN_TEMPO_BPM * fps).ceil() as usize;
    if longest + 2 >= x.len() {
        return None;
    }
    let acf = |lag: usize| -> f64 {
        (0..x.len() - lag).map(|i| x[i] * x[i + lag]).sum::<f64>() / (x.len() - lag) as f64
    };
    let values: Vec<f64> = (0..=longest + 1)
        .map(|l| if l == 0 { 0.0 } else { acf(l) })
        .collect();
    let prior = |lag: f64| {
        let bpm = 60.0 * fps / lag;
        let octaves = (bpm / PRIOR_TEMPO_BPM).log2() / PRIOR_OCTAVES;
        (-0.5 * octaves * octaves).exp()
    };
    // The pulse and its multiples: a beat period also explains the repeats a bar apart, which
    // is what sets a slow-quick-quick step pattern's beat apart from its mean step rate.
    let salience = |lag: usize| -> f64 {
        (1..=4)
            .filter_map(|m| {
                let l = lag * m;
                (l + 1 < x.len()).then(|| acf(l) / m as f64)
            })
            .sum::<f64>()
    };
    let sal: Vec<f64> = (0..=longest + 1)
        .map(|l| if l < shortest { 0.0 } else { salience(l) })
        .collect();
    let best = (shortest..=longest)
        .max_by(|&a, &b| (sal[a] * prior(a as f64)).total_cmp(&(sal[b] * prior(b as f64))))?;
    if values[best] <= 0.0 {
        return None;
    }
    Some(best as f64 + parabolic_offset(values[best - 1], values[best], values[best + 1]))
}

/// Beat frames by Ellis's dynamic programme over `dips` at `period` frames.
fn beat_frames(dips: &[f64], period: f64) -> Vec<usize> {
    let n = dips.len();
    let mut score = vec![0.0f64; n];
    let mut back = vec![usize::MAX; n];
    let lo = (period * 0.5).round().max(1.0) as usize;
    let hi = (period * 2.0).round() as usize;
    for t in 0..n {
        let mut best = 0.0;
        let mut from = usize::MAX;
        for gap in lo..=hi.min(t) {
            let prev = t - gap;
            let penalty = TIGHTNESS * (gap as f64 / period).ln().powi(2);
            let s = score[prev] - penalty;
            if from == usize::MAX || s > best {
                best = s;
                from = prev;
            }
        }
        score[t] = dips[t]
            + if from == usize::MAX {
                0.0
            } else {
                best.max(0.0)
            };
        back[t] = if from != usize::MAX && best > 0.0 {
            from
        } else {
            usize::MAX
        };
    }
    // End on the best-scoring frame within the last period.
    let tail = n.saturating_sub(period.ceil() as usize);
    let Some(mut t) = (tail..n).max_by(|&a, &b| score[a].total_cmp(&score[b])) else {
        return Vec::new();
    };
    let mut beats = vec![t];
    while back[t] != usize::MAX {
        t = back[t];
        beats.push(t);
    }
    beats.reverse();
    // Ends the programme reached without a dip under them are bridges to nothing.
    while beats.last().is_some_and(|&b| dips[b] <= 0.0) {
        beats.pop();
    }
    let start = beats.iter().take_while(|&&b| dips[b] <= 0.0).count();
    beats.drain(..start);
    beats
}

/// The period of the straight line through `beats` (least squares), each beat numbered by the
/// whole periods since the one before (`median` interval apart); frame rounding and single
/// bridged beats average out.
fn grid_period(beats: &[f64], median: f64) -> f64 {
    let mut index = 0.0f64;
    let mut points = vec![(0.0f64, beats[0])];
    for w in beats.windows(2) {
        index += ((w[1] - w[0]) / median).round().max(1.0);
        points.push((index, w[1]));
    }
    let n = points.len() as f64;
    let mx = points.iter().map(|p| p.0).sum::<f64>() / n;
    let my = points.iter().map(|p| p.1).sum::<f64>() / n;
    let sxy: f64 = points.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    let sxx: f64 = points.iter().map(|p| (p.0 - mx) * (p.0 - mx)).sum();
    if sxx > 0.0 && sxy > 0.0 {
        sxy / sxx
    } else {
        median
    }
}

/// Fits the beat grid of one dance (module documentation). Errors if the dance is shorter than
/// [`MIN_SECONDS`] or shows no periodic motion in the tempo range.
pub fn motion_beat_grid(track: &JointTrack<'_>) -> Result<MotionBeatGrid, ModelError> {
    let fps = track.fps();
    if track.duration_s() < MIN_SECONDS {
        return Err(ModelError::TooShort {
            what: "frames for a beat grid",
            needed: (MIN_SECONDS * fps).ceil() as usize,
            found: track.frames(),
        });
    }
    // FACT's kinematic-beat envelope. (Taking the hips' travel out, or reading the feet alone,
    // found the music's tempo on fewer of the tang2018 dances: 16 and 14 of 38 against 24.)
    let speed = summed_joint_speed(track);
    let dips = dip_strength(&speed, fps);
    let period = period_frames(&dips, fps).ok_or(ModelError::NoPulse)?;
    let frames = beat_frames(&dips, period);
    if frames.len() < 4 {
        return Err(ModelError::NoPulse);
    }
    // Each beat at the dip's bottom, interpolated between frames; speed sample i sits at
    // (i + 0.5) / fps.
    let beats_s: Vec<f64> = frames
        .iter()
        .map(|&i| {
            let shift = parabolic_offset(
                dips[i.saturating_sub(1)],
                dips[i],
                dips[(i + 1).min(dips.len() - 1)],
            );
            (i as f64 + 0.5 + shift) / fps
        })
        .collect();
    let mut intervals: Vec<f64> = beats_s.windows(2).map(|w| w[1] - w[0]).collect();
    intervals.sort_by(f64::total_cmp);
    let median = intervals[intervals.len() / 2];
    let tempo_bpm = 60.0 / grid_period(&beats_s, median);

    let kinematic = kinematic_beats(track);
    let seen = beats_s
        .iter()
        .filter(|&&b| {
            let k = kinematic.partition_point(|&x| x < b);
            [k.checked_sub(1), Some(k)]
                .into_iter()
                .flatten()
                .filter_map(|i| kinematic.get(i))
                .any(|&x| (x - b).abs() <= MATCH_FRACTION * median)
        })
        .count();
    let confidence = seen as f64 / beats_s.len() as f64;

    let (beats_per_bar, first_downbeat, bar_confidence) = bars(track, &beats_s, &speed);
    Ok(MotionBeatGrid {
        beats_s,
        tempo_bpm,
        confidence,
        beats_per_bar,
        first_downbeat,
        bar_confidence,
    })
}

/// The pose at `t` seconds as joint positions relative to the first joint (the hips), turned
/// so the body's left–right axis (joints 14 and 18: the upper legs) lies along +X.
fn body_shape(track: &JointTrack<'_>, t: f64) -> Vec<Vec3> {
    let f = ((t * track.fps()).round() as usize).min(track.frames() - 1);
    let frame = track.frame(f);
    let root = frame[0];
    let across = if frame.len() > 18 {
        frame[14] - frame[18]
    } else {
        Vec3::X
    };
    let angle = across.z.atan2(across.x);
    let turn = glam::Quat::from_rotation_y(angle);
    frame.iter().map(|&p| turn * (p - root)).collect()
}

/// Bars from poses a whole number of beats apart (step 5 of the module documentation):
/// `(beats per bar, index of a first beat, confidence)`.
fn bars(track: &JointTrack<'_>, beats_s: &[f64], speed: &[f64]) -> (Option<usize>, usize, f64) {
    let shapes: Vec<Vec<Vec3>> = beats_s.iter().map(|&t| body_shape(track, t)).collect();
    let distance = |lag: usize| -> Option<f64> {
        if shapes.len() <= lag + 4 {
            return None;
        }
        let sum: f64 = (0..shapes.len() - lag)
            .map(|k| {
                shapes[k]
                    .iter()
                    .zip(&shapes[k + lag])
                    .map(|(a, b)| f64::from((*a - *b).length()))
                    .sum::<f64>()
            })
            .sum();
        Some(sum / (shapes.len() - lag) as f64)
    };
    let Some(near) = [distance(1), distance(2)]
        .into_iter()
        .flatten()
        .reduce(f64::min)
    else {
        return (None, 0, 0.0);
    };
    // The bar is the shortest of 3 and 4 whose poses (or twice as far apart) repeat best.
    let repeat = |m: usize| {
        [distance(m), distance(2 * m)]
            .into_iter()
            .flatten()
            .reduce(f64::min)
    };
    let candidates: Vec<(usize, f64)> = [3usize, 4]
        .into_iter()
        .filter_map(|m| Some((m, repeat(m)?)))
        .collect();
    let Some(&(per_bar, d)) = candidates.iter().min_by(|a, b| a.1.total_cmp(&b.1)) else {
        return (None, 0, 0.0);
    };
    if near <= 0.0 || d > BAR_CONTRAST * near {
        return (None, 0, 0.0);
    }
    // The one: the beat position the dance moves hardest into over the half beat after it.
    let fps = track.fps();
    let mut push = vec![0.0f64; per_bar];
    for (k, w) in beats_s.windows(2).enumerate() {
        let a = (w[0] * fps) as usize;
        let b = (((w[0] + w[1]) * 0.5) * fps) as usize;
        let energy: f64 = speed
            .get(a..b.min(speed.len()))
            .map_or(0.0, |s| s.iter().sum());
        push[k % per_bar] += energy;
    }
    let first = (0..per_bar)
        .max_by(|&a, &b| push[a].total_cmp(&push[b]))
        .unwrap_or(0);
    (Some(per_bar), first, 1.0 - d / near)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A track of two joints: a hip still and a hand visiting four points in turn, one a
    /// beat, easing in and out so it stops on each beat, the longest move out of the first
    /// point (the bar's one), at `bpm`, the first beat at `phase_s`.
    fn swinging(bpm: f64, phase_s: f64, seconds: f64, fps: f64) -> Vec<Vec3> {
        let points = [
            Vec3::new(0.4, 1.0, 0.0),
            Vec3::new(0.0, 1.2, 0.0),
            Vec3::new(-0.2, 1.0, 0.0),
            Vec3::new(0.0, 0.9, 0.0),
        ];
        let frames = (seconds * fps) as usize;
        let period = 60.0 / bpm;
        let mut out = Vec::new();
        for i in 0..frames {
            let beats = (i as f64 / fps - phase_s) / period;
            let k = beats.floor().rem_euclid(4.0) as usize;
            let f = beats - beats.floor();
            let ease = (0.5 - 0.5 * (std::f64::consts::PI * f).cos()) as f32;
            out.push(Vec3::ZERO);
            out.push(points[k].lerp(points[(k + 1) % 4], ease));
        }
        out
    }

    #[test]
    fn the_grid_lands_on_the_stops_at_the_dance_tempo() {
        for (bpm, phase) in [(72.0, 0.31), (96.0, 0.05), (120.0, 0.2), (150.0, 0.12)] {
            let p = swinging(bpm, phase, 30.0, 30.0);
            let track = JointTrack::new(&p, 2, 30.0).unwrap();
            let grid = motion_beat_grid(&track).unwrap();
            assert!(
                (grid.tempo_bpm / bpm - 1.0).abs() < 0.02,
                "{bpm}: {}",
                grid.tempo_bpm
            );
            let period = 60.0 / bpm;
            // The file's first and last beats have half a window of motion around them.
            let inner = &grid.beats_s[1..grid.beats_s.len() - 1];
            assert!(
                inner.len() as f64 > 28.0 / period,
                "{bpm}: {} beats",
                inner.len()
            );
            for &b in inner {
                let off = ((b - phase) / period).round() * period + phase - b;
                assert!(off.abs() < 0.04, "{bpm}: beat at {b} is {off} s off");
            }
            assert!(grid.confidence > 0.9, "{bpm}: {}", grid.confidence);
            assert_eq!(grid.beats_per_bar, Some(4), "{bpm}");
            let one = grid.beats_s[grid.first_downbeat];
            let bars = (one - phase) / (4.0 * period);
            assert!(
                (bars - bars.round()).abs() < 0.05,
                "{bpm}: the one at {one}"
            );
        }
    }

    #[test]
    fn motion_without_a_pulse_or_too_short_is_refused() {
        let still = vec![Vec3::ZERO; 2 * 300];
        let track = JointTrack::new(&still, 2, 30.0).unwrap();
        assert!(motion_beat_grid(&track).is_err());
        let p = swinging(120.0, 0.0, 2.0, 30.0);
        let track = JointTrack::new(&p, 2, 30.0).unwrap();
        assert!(matches!(
            motion_beat_grid(&track),
            Err(ModelError::TooShort { .. })
        ));
    }
}
