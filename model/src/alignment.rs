//! Music–motion alignment: where in the song a captured dance really starts.
//!
//! tang2018's `start_position` is approximate (the motion's frame count does not even match the
//! span). A dancer's kinematic beats (minima of summed joint speed) fall on the music's beats, so
//! the offset that maximises BeatAlign between the motion's kinematic beats and the song's beats,
//! searched around the nominal start, is the measured alignment.

use crate::metrics::{BEAT_ALIGN_SIGMA_S, JointTrack, kinematic_beats};

/// Step of the offset search, in seconds.
pub const OFFSET_STEP_S: f64 = 0.005;

/// The measured alignment of one dance.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OffsetEstimate {
    /// Song time of the motion's first frame, in seconds.
    pub start_s: f64,
    /// Correction applied to the nominal start, in seconds (positive: the motion starts later).
    pub offset_s: f64,
    /// BeatAlign at the measured start.
    pub score: f64,
    /// BeatAlign at the nominal start, for comparison.
    pub nominal_score: f64,
    /// Kinematic beats the estimate rests on.
    pub kinematic_beats: usize,
}

fn align_score(kinematic: &[f64], music: &[f64], start_s: f64) -> f64 {
    if kinematic.is_empty() || music.is_empty() {
        return 0.0;
    }
    let two_sigma_sq = 2.0 * BEAT_ALIGN_SIGMA_S * BEAT_ALIGN_SIGMA_S;
    let mut sum = 0.0;
    for &k in kinematic {
        let t = start_s + k;
        let i = music.partition_point(|&m| m < t);
        let d = [i.checked_sub(1), Some(i)]
            .into_iter()
            .flatten()
            .filter_map(|j| music.get(j))
            .map(|m| (m - t).abs())
            .fold(f64::INFINITY, f64::min);
        sum += (-d * d / two_sigma_sq).exp();
    }
    sum / kinematic.len() as f64
}

/// Searches `nominal_start_s ± search_s` for the song time of the motion's first frame that best
/// puts its kinematic beats on `music_beats_s` (sorted, seconds).
///
/// A search window shorter than half a beat keeps the estimate from jumping a whole beat.
pub fn measure_offset(
    track: &JointTrack<'_>,
    music_beats_s: &[f64],
    nominal_start_s: f64,
    search_s: f64,
) -> OffsetEstimate {
    let kinematic = kinematic_beats(track);
    let nominal_score = align_score(&kinematic, music_beats_s, nominal_start_s);
    let steps = (search_s.max(0.0) / OFFSET_STEP_S).round() as i64;
    let mut best: (f64, f64) = (0.0, nominal_score);
    for k in -steps..=steps {
        let off = k as f64 * OFFSET_STEP_S;
        let s = align_score(&kinematic, music_beats_s, nominal_start_s + off);
        // Ties go to the smaller correction, so a flat score keeps the nominal start.
        if s > best.1 + 1e-12 || (s >= best.1 - 1e-12 && off.abs() < best.0.abs()) {
            best = (off, s);
        }
    }
    OffsetEstimate {
        start_s: nominal_start_s + best.0,
        offset_s: best.0,
        score: best.1,
        nominal_score,
        kinematic_beats: kinematic.len(),
    }
}

/// [`measure_offset`] searching less than half a beat either side of the nominal start (0.45 of
/// the median inter-beat interval): beats alone cannot tell one beat from the next, so the
/// nominal start must settle which beat, and the measurement settles the phase.
pub fn measure_offset_within_beat(
    track: &JointTrack<'_>,
    music_beats_s: &[f64],
    nominal_start_s: f64,
) -> OffsetEstimate {
    let mut ibis: Vec<f64> = music_beats_s
        .windows(2)
        .map(|w| w[1] - w[0])
        .filter(|d| *d > 0.0)
        .collect();
    ibis.sort_by(f64::total_cmp);
    let period = ibis.get(ibis.len() / 2).copied().unwrap_or(0.5);
    measure_offset(track, music_beats_s, nominal_start_s, 0.45 * period)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    /// Two joints bobbing so their speed is lowest exactly on a 120 BPM grid starting at `phase`.
    fn bouncing(fps: f64, seconds: f64, phase: f64) -> Vec<Vec3> {
        let n = (fps * seconds) as usize;
        let mut v = Vec::with_capacity(2 * n);
        for i in 0..n {
            let t = i as f64 / fps;
            // Speed ∝ |cos(2π(t − phase)/0.5 ... )|: position a sine of period 1 s has speed
            // minima every 0.5 s, at the turning points t = phase + k/2.
            let y = (std::f64::consts::TAU * (t - phase) + std::f64::consts::FRAC_PI_2).sin() * 0.1;
            v.push(Vec3::new(0.0, 1.0 + y as f32, 0.0));
            v.push(Vec3::new(0.3, 1.0 + y as f32, 0.0));
        }
        v
    }

    #[test]
    fn recovers_a_known_shift() {
        let fps = 25.0;
        let music: Vec<f64> = (0..400).map(|k| 3.0 + k as f64 * 0.5).collect();
        // The motion's minima sit at 0.13 + k/2 in motion time; with the song's beats at 3 + k/2,
        // the true song time of frame 0 is 2.87 + m/2; the nominal start is off by 0.12 s.
        let pos = bouncing(fps, 30.0, 0.13);
        let track = JointTrack::new(&pos, 2, fps).unwrap();
        let est = measure_offset(&track, &music, 10.87 + 0.12, 0.2);
        assert!(
            (est.start_s - 10.87).abs() <= 0.011,
            "start {}",
            est.start_s
        );
        assert!(est.score > 0.95 && est.nominal_score < 0.2, "{est:?}");
    }

    #[test]
    fn no_beats_keeps_the_nominal_start() {
        let pos = vec![Vec3::ZERO; 200];
        let track = JointTrack::new(&pos, 2, 25.0).unwrap();
        let est = measure_offset(&track, &[1.0, 2.0], 5.0, 0.3);
        assert_eq!(est.offset_s, 0.0);
        assert_eq!(est.score, 0.0);
    }
}
