//! Beat- and onset-tracking evaluation metrics that reproduce mir_eval's definitions exactly.
//!
//! Checked numerically against mir_eval 0.8.2 (`mir_eval.beat.f_measure`, `.continuity`,
//! `.trim_beats`, `.evaluate`, `mir_eval.onset.f_measure`): every score agreed to 1e-9 (in fact
//! bit for bit) on random, structured and degenerate sequences. The floating-point operations
//! (hit-window bounds, `np.interp` midpoints, phase/period ratios) are written in the same order
//! as mir_eval's so that knife-edge comparisons fall the same way.
//!
//! Deliberate differences, none of which affect valid mir_eval input: times need not be sorted
//! (they are sorted here, where mir_eval raises), non-finite times are dropped (mir_eval lets NaN
//! through validation and then produces arbitrary results), and times above 30000 s are accepted
//! (mir_eval raises).

/// Hit window of the beat F-measure in seconds (mir_eval's `f_measure_threshold`).
pub const BEAT_TOLERANCE_S: f64 = 0.07;
/// Hit window of the onset F-measure in seconds (mir_eval's onset `window`).
pub const ONSET_TOLERANCE_S: f64 = 0.05;
/// Beats before this time are ignored by [`evaluate_beats`], as in `mir_eval.beat.evaluate`.
pub const MIN_BEAT_TIME_S: f64 = 5.0;

/// mir_eval's `continuity_phase_threshold` default.
const CONTINUITY_PHASE_THRESHOLD: f64 = 0.175;
/// mir_eval's `continuity_period_threshold` default.
const CONTINUITY_PERIOD_THRESHOLD: f64 = 0.175;

/// Continuity-based beat scores (`mir_eval.beat.continuity`).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Continuity {
    /// Correct metric level, longest continuously correct run.
    pub cmlc: f64,
    /// Correct metric level, total fraction correct.
    pub cmlt: f64,
    /// Any metric level, longest continuously correct run.
    pub amlc: f64,
    /// Any metric level, total fraction correct.
    pub amlt: f64,
}

/// The subset of `mir_eval.beat.evaluate` scores computed by [`evaluate_beats`].
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct BeatScores {
    /// Beat F-measure with a ±[`BEAT_TOLERANCE_S`] window.
    pub f_measure: f64,
    /// Correct metric level, continuous.
    pub cmlc: f64,
    /// Correct metric level, total.
    pub cmlt: f64,
    /// Any metric level, continuous.
    pub amlc: f64,
    /// Any metric level, total.
    pub amlt: f64,
}

/// Onset detection scores (`mir_eval.onset.f_measure`).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct OnsetScores {
    /// Harmonic mean of precision and recall.
    pub f_measure: f64,
    /// Matched estimates over all estimates.
    pub precision: f64,
    /// Matched references over all references.
    pub recall: f64,
}

/// Drops beats earlier than `min_time` (`mir_eval.beat.trim_beats`); the result is sorted.
pub fn trim_beats(beats: &[f64], min_time: f64) -> Vec<f64> {
    let mut trimmed = sorted_finite(beats);
    trimmed.retain(|&t| t >= min_time);
    trimmed
}

/// Beat F-measure with a ±`tolerance` window (`mir_eval.beat.f_measure`).
pub fn beat_f_measure(reference: &[f64], estimated: &[f64], tolerance: f64) -> f64 {
    let reference = sorted_finite(reference);
    let estimated = sorted_finite(estimated);
    if reference.is_empty() || estimated.is_empty() {
        return 0.0;
    }
    let matched = match_count(&reference, &estimated, tolerance) as f64;
    f1(
        matched / estimated.len() as f64,
        matched / reference.len() as f64,
    )
}

/// CMLc, CMLt, AMLc and AMLt with mir_eval's default thresholds (`mir_eval.beat.continuity`).
pub fn continuity(reference: &[f64], estimated: &[f64]) -> Continuity {
    let reference = sorted_finite(reference);
    let estimated = sorted_finite(estimated);
    // mir_eval needs an interval on both sides and returns all zeros otherwise.
    if reference.len() <= 1 || estimated.len() <= 1 {
        return Continuity::default();
    }
    let mut continuous = [0.0; 5];
    let mut total = [0.0; 5];
    for (i, variation) in reference_variations(&reference).iter().enumerate() {
        (continuous[i], total[i]) = continuity_against(variation, &estimated);
    }
    Continuity {
        cmlc: continuous[0],
        cmlt: total[0],
        amlc: continuous.iter().copied().fold(0.0, f64::max),
        amlt: total.iter().copied().fold(0.0, f64::max),
    }
}

/// Trims both sequences at [`MIN_BEAT_TIME_S`] and scores them, as `mir_eval.beat.evaluate` does.
pub fn evaluate_beats(reference: &[f64], estimated: &[f64]) -> BeatScores {
    let reference = trim_beats(reference, MIN_BEAT_TIME_S);
    let estimated = trim_beats(estimated, MIN_BEAT_TIME_S);
    let c = continuity(&reference, &estimated);
    BeatScores {
        f_measure: beat_f_measure(&reference, &estimated, BEAT_TOLERANCE_S),
        cmlc: c.cmlc,
        cmlt: c.cmlt,
        amlc: c.amlc,
        amlt: c.amlt,
    }
}

/// Onset F-measure, precision and recall with a ±`window` window (`mir_eval.onset.f_measure`).
pub fn onset_f_measure(reference: &[f64], estimated: &[f64], window: f64) -> OnsetScores {
    let reference = sorted_finite(reference);
    let estimated = sorted_finite(estimated);
    if reference.is_empty() || estimated.is_empty() {
        return OnsetScores::default();
    }
    let matched = match_count(&reference, &estimated, window) as f64;
    let precision = matched / estimated.len() as f64;
    let recall = matched / reference.len() as f64;
    OnsetScores {
        f_measure: f1(precision, recall),
        precision,
        recall,
    }
}

fn sorted_finite(times: &[f64]) -> Vec<f64> {
    let mut sorted: Vec<f64> = times.iter().copied().filter(|t| t.is_finite()).collect();
    sorted.sort_unstable_by(f64::total_cmp);
    sorted
}

/// `mir_eval.util.f_measure` with beta = 1, same operation order.
fn f1(precision: f64, recall: f64) -> f64 {
    if precision == 0.0 && recall == 0.0 {
        return 0.0;
    }
    2.0 * precision * recall / (precision + recall)
}

/// Size of a maximum matching between sorted `reference` and sorted `estimated`, where a pair
/// may match when `est - window <= ref <= est + window` (the exact float bounds that
/// `mir_eval.util._fast_hit_windows` searches with).
///
/// Each estimate's window `[lo_j, hi_j]` has both ends non-decreasing in `j` (rounding is
/// monotone), which makes the graph convex and lets a greedy pass find a maximum matching:
/// visiting windows by increasing right end and giving each the smallest free reference inside
/// it is optimal by the usual exchange argument (Glover 1967). A reference skipped for lying
/// below `lo_j` lies below every later window too, so one forward pointer finds that smallest
/// free reference. The tests check this against an augmenting-path matcher.
fn match_count(reference: &[f64], estimated: &[f64], window: f64) -> usize {
    // With finite times only a NaN window can make a bound NaN, and it hits nothing.
    if window.is_nan() {
        return 0;
    }
    let mut next = 0;
    let mut matched = 0;
    for &est in estimated {
        let lo = est - window;
        let hi = est + window;
        while next < reference.len() && reference[next] < lo {
            next += 1;
        }
        if next < reference.len() && reference[next] <= hi {
            matched += 1;
            next += 1;
        }
    }
    matched
}

/// `mir_eval.beat._get_reference_beat_variations`: original, off-beat, double, half-odd,
/// half-even. Needs at least two beats.
fn reference_variations(reference: &[f64]) -> [Vec<f64>; 5] {
    // np.interp at indices 0, 0.5, ..., n-1: exact knots are returned as-is and midpoints are
    // `slope * 0.5 + left` with slope = (right - left) / 1.0, which is what numpy computes.
    let double: Vec<f64> = (0..2 * reference.len() - 1)
        .map(|k| {
            let left = reference[k / 2];
            if k % 2 == 0 {
                left
            } else {
                (reference[k / 2 + 1] - left) * 0.5 + left
            }
        })
        .collect();
    let off_beat = double.iter().skip(1).step_by(2).copied().collect();
    let half_odd = reference.iter().step_by(2).copied().collect();
    let half_even = reference.iter().skip(1).step_by(2).copied().collect();
    [reference.to_vec(), off_beat, double, half_odd, half_even]
}

/// One iteration of mir_eval's continuity loop: (continuous accuracy, total accuracy) of
/// `estimated` (≥ 2 beats) against one non-empty reference variation.
fn continuity_against(reference: &[f64], estimated: &[f64]) -> (f64, f64) {
    let mut used = vec![false; reference.len()];
    let mut longest = 0usize;
    let mut run = 0usize;
    let mut correct = 0usize;
    for (m, &est) in estimated.iter().enumerate() {
        let nearest = nearest_index(reference, est);
        let min_difference = (est - reference[nearest]).abs();
        let mut success = false;
        if !used[nearest] {
            let (phase, period) = if m == 0 || nearest == 0 {
                // At the start mir_eval looks forward; at the end of either sequence it falls
                // back to the previous interval using Python's index -1, which wraps to the
                // last element, so a one-beat variation gets a zero interval.
                let reference_interval = if nearest + 1 < reference.len() {
                    reference[nearest + 1] - reference[nearest]
                } else {
                    reference[nearest] - reference[wrapping_prev(nearest, reference.len())]
                };
                let estimated_interval = if m + 1 < estimated.len() {
                    estimated[m + 1] - est
                } else {
                    est - estimated[wrapping_prev(m, estimated.len())]
                };
                if reference_interval == 0.0 {
                    let phase = if min_difference == 0.0 {
                        1.0
                    } else {
                        f64::INFINITY
                    };
                    let period = if estimated_interval == 0.0 {
                        0.0
                    } else {
                        f64::INFINITY
                    };
                    (phase, period)
                } else {
                    (
                        (min_difference / reference_interval).abs(),
                        (1.0 - estimated_interval / reference_interval).abs(),
                    )
                }
            } else {
                // A zero interval here gives inf or NaN, and either fails the comparison below,
                // exactly as numpy's division does.
                let reference_interval = reference[nearest] - reference[nearest - 1];
                let estimated_interval = est - estimated[m - 1];
                (
                    (min_difference / reference_interval).abs(),
                    (1.0 - estimated_interval / reference_interval).abs(),
                )
            };
            if phase < CONTINUITY_PHASE_THRESHOLD && period < CONTINUITY_PERIOD_THRESHOLD {
                used[nearest] = true;
                success = true;
            }
        }
        if success {
            correct += 1;
            run += 1;
            longest = longest.max(run);
        } else {
            run = 0;
        }
    }
    // mir_eval's success array is as long as the longer sequence, so surplus reference beats
    // count as failures.
    let n = reference.len().max(estimated.len()) as f64;
    (longest as f64 / n, correct as f64 / n)
}

fn wrapping_prev(index: usize, len: usize) -> usize {
    index.checked_sub(1).unwrap_or(len - 1)
}

/// `np.argmin(np.abs(x - sorted))`: the first index of the smallest distance, found by binary
/// search. Float distances are non-increasing left of `x` and non-decreasing right of it
/// (rounding is monotone), so the minimum sits at the boundary and ties only extend leftwards
/// through the run of equal distances just below `x`. `sorted` must be non-empty.
fn nearest_index(sorted: &[f64], x: f64) -> usize {
    let above = sorted.partition_point(|&r| r <= x);
    if above == 0 {
        return 0;
    }
    let below_distance = (x - sorted[above - 1]).abs();
    if above < sorted.len() && (x - sorted[above]).abs() < below_distance {
        return above;
    }
    let mut first = above - 1;
    while first > 0 && (x - sorted[first - 1]).abs() == below_distance {
        first -= 1;
    }
    first
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// Beats every `period` seconds from `start` up to (excluding) `end`.
    fn grid(start: f64, end: f64, period: f64) -> Vec<f64> {
        let n = ((end - start) / period).ceil() as usize;
        (0..n).map(|i| start + i as f64 * period).collect()
    }

    fn shifted(beats: &[f64], by: f64) -> Vec<f64> {
        beats.iter().map(|b| b + by).collect()
    }

    fn assert_close(actual: f64, expected: f64) {
        assert!((actual - expected).abs() < 1e-12, "{actual} != {expected}");
    }

    /// Kuhn's augmenting-path maximum matching over the same hit predicate as `match_count`.
    fn brute_force_matching(reference: &[f64], estimated: &[f64], window: f64) -> usize {
        fn augment(
            e: usize,
            adjacency: &[Vec<usize>],
            seen: &mut [bool],
            owner: &mut [Option<usize>],
        ) -> bool {
            for &r in &adjacency[e] {
                if !seen[r] {
                    seen[r] = true;
                    if owner[r].is_none_or(|o| augment(o, adjacency, seen, owner)) {
                        owner[r] = Some(e);
                        return true;
                    }
                }
            }
            false
        }
        let adjacency: Vec<Vec<usize>> = estimated
            .iter()
            .map(|&e| {
                (0..reference.len())
                    .filter(|&r| reference[r] >= e - window && reference[r] <= e + window)
                    .collect()
            })
            .collect();
        let mut owner = vec![None; reference.len()];
        (0..estimated.len())
            .filter(|&e| augment(e, &adjacency, &mut vec![false; reference.len()], &mut owner))
            .count()
    }

    #[test]
    fn identical_sequences_score_one() {
        let beats = grid(5.0, 30.0, 0.5);
        let s = evaluate_beats(&beats, &beats);
        assert_eq!(
            s,
            BeatScores {
                f_measure: 1.0,
                cmlc: 1.0,
                cmlt: 1.0,
                amlc: 1.0,
                amlt: 1.0
            }
        );
        let o = onset_f_measure(&beats, &beats, ONSET_TOLERANCE_S);
        assert_eq!(
            o,
            OnsetScores {
                f_measure: 1.0,
                precision: 1.0,
                recall: 1.0
            }
        );
    }

    #[test]
    fn shift_of_60ms_hits_and_80ms_misses() {
        let beats = grid(10.0, 40.0, 0.5);
        assert_eq!(
            beat_f_measure(&beats, &shifted(&beats, 0.06), BEAT_TOLERANCE_S),
            1.0
        );
        assert_eq!(
            beat_f_measure(&beats, &shifted(&beats, -0.06), BEAT_TOLERANCE_S),
            1.0
        );
        assert_eq!(
            beat_f_measure(&beats, &shifted(&beats, 0.08), BEAT_TOLERANCE_S),
            0.0
        );
        assert_eq!(
            beat_f_measure(&beats, &shifted(&beats, -0.08), BEAT_TOLERANCE_S),
            0.0
        );
    }

    #[test]
    fn off_beat_estimate_is_wrong_metric_level_but_any_level_correct() {
        let reference = grid(5.0, 30.0, 0.5);
        let estimated = shifted(&reference[..reference.len() - 1], 0.25);
        let c = continuity(&reference, &estimated);
        assert_eq!((c.cmlc, c.cmlt), (0.0, 0.0));
        assert_eq!((c.amlc, c.amlt), (1.0, 1.0));
    }

    #[test]
    fn double_tempo_estimate_scores_on_any_metric_level_only() {
        let reference = grid(5.0, 30.0, 0.5);
        let estimated = grid(5.0, 29.6, 0.25);
        let c = continuity(&reference, &estimated);
        assert_eq!((c.cmlc, c.cmlt), (0.0, 0.0));
        assert!(c.amlt > 0.95 && c.amlc > 0.95, "{c:?}");
    }

    #[test]
    fn half_tempo_estimate_scores_on_any_metric_level_only() {
        let reference = grid(5.0, 30.0, 0.5);
        let estimated: Vec<f64> = reference.iter().step_by(2).copied().collect();
        let c = continuity(&reference, &estimated);
        assert_eq!((c.cmlc, c.cmlt), (0.0, 0.0));
        assert_eq!((c.amlc, c.amlt), (1.0, 1.0));
    }

    #[test]
    fn half_the_beats_missing_gives_two_thirds() {
        let reference = grid(5.0, 30.0, 0.5);
        let estimated: Vec<f64> = reference.iter().step_by(2).copied().collect();
        assert_close(
            beat_f_measure(&reference, &estimated, BEAT_TOLERANCE_S),
            2.0 / 3.0,
        );
        assert_close(
            beat_f_measure(&estimated, &reference, BEAT_TOLERANCE_S),
            2.0 / 3.0,
        );
    }

    #[test]
    fn empty_and_single_beat_inputs_score_zero() {
        let beats = grid(5.0, 30.0, 0.5);
        for (reference, estimated) in [
            (&[][..], &beats[..]),
            (&beats[..], &[][..]),
            (&[][..], &[][..]),
        ] {
            assert_eq!(evaluate_beats(reference, estimated), BeatScores::default());
            assert_eq!(
                onset_f_measure(reference, estimated, 0.05),
                OnsetScores::default()
            );
        }
        assert_eq!(continuity(&beats, &[10.0]), Continuity::default());
        assert_eq!(continuity(&[10.0], &beats), Continuity::default());
        // Everything before 5 s is trimmed away.
        assert_eq!(
            evaluate_beats(&[1.0, 2.0, 3.0], &[1.0, 2.0, 3.0]),
            BeatScores::default()
        );
    }

    #[test]
    fn trim_drops_beats_before_min_time() {
        assert_eq!(
            trim_beats(&[6.0, 1.0, 5.0, 4.999, f64::NAN], 5.0),
            vec![5.0, 6.0]
        );
    }

    #[test]
    fn onsets_within_window_hit_and_outside_miss() {
        let reference = [1.0, 2.0, 3.0, 4.0];
        let estimated = [1.04, 1.96, 3.06, 3.9, 5.0];
        let o = onset_f_measure(&reference, &estimated, ONSET_TOLERANCE_S);
        assert_close(o.precision, 2.0 / 5.0);
        assert_close(o.recall, 2.0 / 4.0);
        assert_close(o.f_measure, 2.0 * 0.4 * 0.5 / 0.9);
    }

    #[test]
    fn one_estimate_between_two_references_matches_once() {
        let o = onset_f_measure(&[1.0, 1.06], &[1.03], ONSET_TOLERANCE_S);
        assert_close(o.precision, 1.0);
        assert_close(o.recall, 0.5);
    }

    #[test]
    fn unsorted_input_is_sorted_first() {
        let reference = grid(5.0, 20.0, 0.5);
        let estimated = shifted(&reference, 0.02);
        let mut scrambled = estimated.clone();
        scrambled.reverse();
        scrambled.swap(0, 7);
        assert_eq!(
            evaluate_beats(&reference, &scrambled),
            evaluate_beats(&reference, &estimated)
        );
    }

    #[test]
    fn one_beat_variation_never_matches() {
        // With two reference beats the half-tempo variations have one beat each, whose interval
        // mir_eval computes as zero via index -1.
        let c = continuity(&[10.0, 10.5], &[10.0, 10.5]);
        assert_eq!(
            c,
            Continuity {
                cmlc: 1.0,
                cmlt: 1.0,
                amlc: 1.0,
                amlt: 1.0
            }
        );
        // A half-tempo estimate would match the one-beat half-odd variation [10.0] exactly,
        // but its zero interval makes the phase 1.0.
        assert_eq!(
            continuity(&[10.0, 10.5], &[10.0, 11.0]),
            Continuity::default()
        );
        let c = continuity(&[10.0, 10.5], &[10.0, 10.25]);
        assert_eq!((c.cmlt, c.amlc, c.amlt), (0.0, 2.0 / 3.0, 2.0 / 3.0));
    }

    fn finite_times() -> impl Strategy<Value = Vec<f64>> {
        prop::collection::vec(
            prop_oneof![
                8 => 0.0..60.0f64,
                1 => -1e300..1e300f64,
                1 => prop::num::f64::NORMAL | prop::num::f64::SUBNORMAL | prop::num::f64::ZERO,
            ],
            0..40,
        )
    }

    /// Sorted beat-like times on a 1/1024 s grid, so no distance lands on a window edge.
    fn dyadic_times() -> impl Strategy<Value = Vec<f64>> {
        prop::collection::vec(0u32..40_000, 0..60).prop_map(|mut ticks| {
            ticks.sort_unstable();
            ticks.into_iter().map(|t| f64::from(t) / 1024.0).collect()
        })
    }

    /// Sorted multiples of 0.1 with many duplicates, so that nearest-beat ties are common.
    fn tenths() -> impl Strategy<Value = Vec<f64>> {
        prop::collection::vec(prop_oneof![0u8..8u8, Just(3u8)], 1..20).prop_map(|v| {
            sorted_finite(
                &v.into_iter()
                    .map(|x| f64::from(x) * 0.1)
                    .collect::<Vec<_>>(),
            )
        })
    }

    proptest! {
        #[test]
        fn scores_are_in_unit_interval_and_never_nan(
            reference in finite_times(),
            estimated in finite_times(),
            window in prop_oneof![
                Just(0.07), 0.0..1.0f64, Just(f64::MAX), Just(f64::NAN), Just(-0.1)
            ],
        ) {
            let b = evaluate_beats(&reference, &estimated);
            let c = continuity(&reference, &estimated);
            let o = onset_f_measure(&reference, &estimated, window);
            let f = beat_f_measure(&reference, &estimated, window);
            for s in [b.f_measure, b.cmlc, b.cmlt, b.amlc, b.amlt, c.cmlc, c.cmlt, c.amlc, c.amlt,
                      o.f_measure, o.precision, o.recall, f] {
                prop_assert!((0.0..=1.0).contains(&s), "{s}");
            }
            prop_assert!(c.cmlc <= c.cmlt && c.amlc <= c.amlt);
            prop_assert!(c.cmlt <= c.amlt && c.cmlc <= c.amlc);
        }

        #[test]
        fn f_measure_is_symmetric(reference in dyadic_times(), estimated in dyadic_times()) {
            prop_assert_eq!(
                beat_f_measure(&reference, &estimated, BEAT_TOLERANCE_S),
                beat_f_measure(&estimated, &reference, BEAT_TOLERANCE_S)
            );
            let forward = onset_f_measure(&reference, &estimated, ONSET_TOLERANCE_S);
            let backward = onset_f_measure(&estimated, &reference, ONSET_TOLERANCE_S);
            prop_assert_eq!(forward.f_measure, backward.f_measure);
            prop_assert_eq!(forward.precision, backward.recall);
        }

        #[test]
        fn greedy_matching_is_maximum(
            reference in prop::collection::vec(0.0..3.0f64, 0..25),
            estimated in prop::collection::vec(0.0..3.0f64, 0..25),
            window in 0.0..0.5f64,
        ) {
            let reference = sorted_finite(&reference);
            let estimated = sorted_finite(&estimated);
            prop_assert_eq!(
                match_count(&reference, &estimated, window),
                brute_force_matching(&reference, &estimated, window)
            );
        }

        #[test]
        fn nearest_index_is_first_argmin(
            sorted in tenths(),
            x in prop_oneof![-1.0..2.0f64, (0u8..8).prop_map(|x| f64::from(x) * 0.1 + 0.05)],
        ) {
            let mut linear = 0;
            for (i, r) in sorted.iter().enumerate() {
                if (x - r).abs() < (x - sorted[linear]).abs() {
                    linear = i;
                }
            }
            prop_assert_eq!(nearest_index(&sorted, x), linear);
        }
    }
}
