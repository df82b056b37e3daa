//! How the dancer's beat comes back after a sudden tempo change. The dancer moves on the beat
//! grid predicted `horizon` frames ahead (`model::horizon`); when the music changes tempo the
//! prediction is wrong until the tracker hears the new tempo. For every heard beat this finds
//! where the dancer's grid put it, and the recovery time is how long after the change every
//! beat lands within the tolerance again.

use dsp::FeatureFrame;
use model::rig::{JOINT_COUNT, Pose, Skeleton};
use offline::decode::mono_mix;

/// Two songs joined on a beat: the first up to `cut_s`, then the second from one of its beats.
#[derive(Clone, Debug)]
pub struct Splice {
    /// Mono samples.
    pub samples: Vec<f32>,
    /// Their rate, Hz.
    pub sample_rate: u32,
    /// Every beat of the result, seconds.
    pub beats: Vec<f64>,
    /// Where the second song starts, seconds.
    pub cut_s: f64,
}

/// The beat of `beats` nearest `t_s`.
fn nearest(beats: &[f64], t_s: f64) -> Option<f64> {
    beats
        .iter()
        .copied()
        .min_by(|a, b| (a - t_s).abs().total_cmp(&(b - t_s).abs()))
}

/// Song `a` up to its beat nearest `cut_near_s`, then song `b` from its beat nearest
/// `resume_near_s`: the beat stays on time across the join, the tempo jumps. Both songs at
/// `rate`; None if either has no beat there.
#[allow(clippy::too_many_arguments)]
pub fn splice(
    a: (&[f32], u16, &[f64]),
    b: (&[f32], u16, &[f64]),
    rate: u32,
    cut_near_s: f64,
    resume_near_s: f64,
) -> Option<Splice> {
    let (a_mono, b_mono) = (mono_mix(a.0, a.1), mono_mix(b.0, b.1));
    let cut = nearest(a.2, cut_near_s)?;
    let resume = nearest(b.2, resume_near_s)?;
    let r = f64::from(rate);
    let cut_i = ((cut * r).round() as usize).min(a_mono.len());
    let resume_i = ((resume * r).round() as usize).min(b_mono.len());
    let cut_s = cut_i as f64 / r;
    let mut samples = a_mono[..cut_i].to_vec();
    samples.extend_from_slice(&b_mono[resume_i..]);
    let offset = cut_s - resume_i as f64 / r;
    let mut beats: Vec<f64> = a.2.iter().copied().filter(|&t| t < cut_s - 1e-3).collect();
    beats.extend(
        b.2.iter()
            .map(|t| t + offset)
            .filter(|&t| t >= cut_s - 1e-3),
    );
    Some(Splice {
        samples,
        sample_rate: rate,
        beats,
        cut_s,
    })
}

/// Where the dancer's grid puts each heard beat, seconds (positive: late). The pose shown at
/// a beat's frame was made from the analysis `horizon` frames earlier; `None` while that grid
/// hears no beat.
pub fn dancer_beat_errors(
    frames: &[FeatureFrame],
    horizon: usize,
    rate: f64,
    beats: &[f64],
) -> Vec<(f64, Option<f64>)> {
    beats
        .iter()
        .map(|&b| {
            let j = (b * rate).round().max(0.0) as usize;
            let err = frames
                .get(j.saturating_sub(horizon))
                .and_then(|f| {
                    let g = f.grid;
                    g.beat_after(b - 0.5 * g.period_s)
                })
                .map(|p| p.time_s - b);
            (b, err)
        })
        .collect()
}

/// Beats in a row within the tolerance that count as back on the beat.
pub const SETTLED_BEATS: usize = 8;

/// Seconds from `cut_s` until the dancer is back on the beat: the first beat from which
/// [`SETTLED_BEATS`] beats in a row land within `tolerance_s`; None if that never happens.
pub fn recovery_s(errors: &[(f64, Option<f64>)], cut_s: f64, tolerance_s: f64) -> Option<f64> {
    let after: Vec<&(f64, Option<f64>)> = errors.iter().filter(|(b, _)| *b >= cut_s).collect();
    after
        .windows(SETTLED_BEATS)
        .find(|w| {
            w.iter()
                .all(|(_, e)| e.is_some_and(|e| e.abs() <= tolerance_s))
        })
        .map(|w| w[0].0 - cut_s)
}

/// The largest step any joint takes between two frames in `[from_s, to_s)`, metres.
pub fn largest_step_m(poses: &[Pose], rate: f64, from_s: f64, to_s: f64) -> f64 {
    let skeleton = Skeleton::default_adult();
    let p = skeleton.trajectory(poses);
    let first = ((from_s * rate).max(1.0)) as usize;
    let last = ((to_s * rate) as usize).min(poses.len());
    (first..last)
        .flat_map(|i| {
            (0..JOINT_COUNT).map({
                let p = &p;
                move |j| p[i * JOINT_COUNT + j].distance(p[(i - 1) * JOINT_COUNT + j])
            })
        })
        .fold(0.0f32, f32::max) as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recovery_is_the_first_beat_of_the_settled_run() {
        let e = |b: f64, err: f64| (b, Some(err));
        let mut errors = vec![
            e(9.5, 0.0),
            e(10.0, 0.08),
            e(10.5, 0.05),
            (11.0, None),
            e(11.5, 0.03),
        ];
        errors
            .extend((0..SETTLED_BEATS).map(|k| e(12.0 + 0.5 * k as f64, 0.015 - 0.004 * k as f64)));
        assert_eq!(recovery_s(&errors, 10.0, 0.02), Some(2.0));
        assert_eq!(recovery_s(&errors[..errors.len() - 1], 10.0, 0.02), None);
    }

    #[test]
    fn splice_keeps_the_beat_across_the_join() {
        let rate = 100;
        let a: Vec<f32> = vec![1.0; 2000];
        let b: Vec<f32> = vec![-1.0; 2000];
        let a_beats: Vec<f64> = (0..40).map(|k| 0.5 * k as f64).collect();
        let b_beats: Vec<f64> = (0..50).map(|k| 0.1 + 0.4 * k as f64).collect();
        let s = splice((&a, 1, &a_beats), (&b, 1, &b_beats), rate, 10.2, 4.0).unwrap();
        assert_eq!(s.cut_s, 10.0);
        assert_eq!(s.samples[999], 1.0);
        assert_eq!(s.samples[1000], -1.0);
        // b's beat at 4.1 s lands on the cut; the next one 0.4 s later.
        let after: Vec<f64> = s
            .beats
            .iter()
            .copied()
            .filter(|&t| t >= 9.9)
            .take(3)
            .collect();
        assert!(
            (after[0] - 10.0).abs() < 1e-9 && (after[1] - 10.4).abs() < 1e-9,
            "{after:?}"
        );
    }
}
