//! Bar pointer: a hidden Markov model over the position of each tracked beat in its bar, for a
//! 4/4 and a 3/4 bar at once, filtered forward one beat at a time (the bar-pointer idea of
//! Whiteley, Cemgil & Godsill 2006, on a beat grid as in Krebs et al. 2016). Each beat moves
//! the pointer one position on; with a small probability it jumps anywhere (a missed or extra
//! beat, a meter change, a fill the count lost). Observations are the downbeat network's class
//! probabilities divided by how often each class was seen in training.
//!
//! The count reported to users is a committed hypothesis that advances with every beat and is
//! replaced only when another is clearly more probable, so the count does not flip back and
//! forth on one ambiguous bar.

use crate::bar_class::{CLASS_COUNT, CLASSES, Level, beat_class_index, successor};

/// How the bar pointer weighs its evidence.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BarPointerParams {
    /// Probability per beat that the count jumps to another position or meter at the same
    /// level.
    pub jump: f32,
    /// Probability per beat that the count jumps to another level (double or half time).
    pub level_jump: f32,
    /// Exponent applied to each observation (below 1 trusts one beat less).
    pub observation_power: f32,
    /// Probability a new hypothesis needs over the committed one's, as a ratio.
    pub switch_ratio: f32,
    /// Probability of 4/4 before any evidence.
    pub prior_four: f32,
    /// Probability before any evidence that the tracker follows twice or half the counted beat.
    pub prior_other_level: f32,
    /// Weight of the half-time hypothesis (1: as the network says, 0: never).
    pub half_time: f32,
    /// Weight of the double-time hypothesis (1: as the network says, 0: never).
    pub double_time: f32,
    /// Tempo ratio between consecutive beats beyond which (either way) the tracker changed
    /// metrical level and the count starts afresh from its prior (0: never).
    pub tempo_jump: f32,
}

impl Default for BarPointerParams {
    fn default() -> Self {
        Self {
            jump: 0.02,
            level_jump: 0.0005,
            observation_power: 0.7,
            switch_ratio: 2.0,
            prior_four: 0.6,
            prior_other_level: 0.1,
            half_time: 0.05,
            double_time: 0.3,
            tempo_jump: 1.3,
        }
    }
}

impl BarPointerParams {
    /// These parameters with `name=value` overrides applied (comma-separated, for tuning).
    pub fn with_overrides(mut self, spec: &str) -> Result<Self, crate::DspError> {
        for (name, v) in crate::tuning::overrides(spec)? {
            let v = v as f32;
            let slot = match name {
                "jump" => &mut self.jump,
                "level_jump" => &mut self.level_jump,
                "observation_power" => &mut self.observation_power,
                "switch_ratio" => &mut self.switch_ratio,
                "prior_four" => &mut self.prior_four,
                "prior_other_level" => &mut self.prior_other_level,
                "half_time" => &mut self.half_time,
                "double_time" => &mut self.double_time,
                "tempo_jump" => &mut self.tempo_jump,
                other => {
                    return Err(crate::DspError::Tuning(format!(
                        "unknown bar pointer parameter '{other}'"
                    )));
                }
            };
            if !v.is_finite() || v < 0.0 {
                return Err(crate::DspError::Tuning(format!(
                    "{name} must be a finite number ≥ 0"
                )));
            }
            *slot = v;
        }
        Ok(self)
    }
}

/// The filtered bar position of the last observed beat, and the committed count.
#[derive(Clone, Debug)]
pub struct BarPointer {
    params: BarPointerParams,
    /// Probability of each class for the last beat the count was told about.
    belief: [f32; CLASS_COUNT],
    /// Committed class of the last beat the count was told about.
    committed: usize,
    /// The belief before any evidence.
    prior: [f32; CLASS_COUNT],
}

impl BarPointer {
    /// A pointer with no evidence: 4/4 at the tracked beat more likely, and the first beat
    /// counted as a downbeat.
    pub fn new(params: BarPointerParams) -> Self {
        let four = params.prior_four.clamp(0.01, 0.99);
        let other = params.prior_other_level.clamp(0.0, 0.99);
        let classes_of = |level: Level, meter: usize| {
            CLASSES
                .iter()
                .filter(|c| c.level == level && c.meter == meter)
                .count() as f32
        };
        let mut belief = [0.0; CLASS_COUNT];
        for (b, c) in belief.iter_mut().zip(&CLASSES) {
            let level = match c.level {
                Level::Beat => 1.0 - other,
                Level::Double => other / 2.0,
                // There is no 3/4 class at half time: its share goes to the 4/4 ones.
                Level::Half => other / 2.0 / four,
            };
            let meter = if c.meter == 4 { four } else { 1.0 - four };
            *b = level * meter / classes_of(c.level, c.meter);
        }
        // The "last" beat before the first one is the bar's last, so the first counts as 1.
        let last = beat_class_index(4, 4).unwrap_or(0);
        Self {
            params,
            belief,
            committed: last,
            prior: belief,
        }
    }

    /// Drops the evidence gathered so far (the tracker changed level): the belief returns to
    /// the prior, the committed count carries on until the new evidence overrules it.
    pub fn forget(&mut self) {
        self.belief = self.prior;
    }

    fn level_weight(&self, level: Level) -> f32 {
        match level {
            Level::Beat => 1.0,
            Level::Double => self.params.double_time,
            Level::Half => self.params.half_time,
        }
    }

    /// The distribution one beat later.
    fn advance(&self, p: &[f32; CLASS_COUNT]) -> [f32; CLASS_COUNT] {
        let jump = self.params.jump.clamp(0.0, 0.5);
        let level_jump = self.params.level_jump.clamp(0.0, 0.5);
        let mut out = [0.0; CLASS_COUNT];
        for (c, &q) in p.iter().enumerate() {
            if q == 0.0 {
                continue;
            }
            let next = successor(c);
            let level = CLASSES[c].level;
            let same = CLASSES.iter().filter(|k| k.level == level).count() - 1;
            let other = CLASS_COUNT - 1 - same;
            for (k, o) in out.iter_mut().enumerate() {
                *o += q * if k == next {
                    1.0 - jump - level_jump
                } else if CLASSES[k].level == level {
                    jump / same as f32
                } else {
                    level_jump / other as f32
                };
            }
        }
        out
    }

    /// A new beat was tracked; `observation` holds the class probabilities of the beat before
    /// it, where known, and `prior` their training frequencies. Returns the committed class
    /// of the new beat and the probability the filter gives it.
    pub fn beat(
        &mut self,
        observation: Option<(&[f32; CLASS_COUNT], &[f32; CLASS_COUNT])>,
    ) -> (usize, f32) {
        if let Some((q, prior)) = observation {
            // The belief was about the beat before the previous one: move it on, then weigh.
            let mut b = self.advance(&self.belief);
            for (((v, &q), &p), c) in b.iter_mut().zip(q).zip(prior).zip(&CLASSES) {
                let like = (q.max(1e-6) / p.max(1e-6)).powf(self.params.observation_power);
                *v *= if like.is_finite() { like } else { 1.0 } * self.level_weight(c.level);
            }
            let s: f32 = b.iter().sum();
            if s > 0.0 && s.is_finite() {
                b.iter_mut().for_each(|v| *v /= s);
                self.belief = b;
            }
        } else {
            self.belief = self.advance(&self.belief);
        }
        let now = self.advance(&self.belief);
        self.committed = successor(self.committed);
        let (best, p_best) = now
            .iter()
            .copied()
            .enumerate()
            .fold((0, f32::MIN), |m, (c, p)| if p > m.1 { (c, p) } else { m });
        if best != self.committed && p_best > now[self.committed] * self.params.switch_ratio {
            self.committed = best;
        }
        (self.committed, now[self.committed])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bar_class::{BarClass, class_index};

    const UNIFORM: [f32; CLASS_COUNT] = [1.0 / CLASS_COUNT as f32; CLASS_COUNT];

    /// A noisy observation that favours `truth` with probability `p`.
    fn observe(truth: usize, p: f32) -> [f32; CLASS_COUNT] {
        let mut q = [(1.0 - p) / (CLASS_COUNT - 1) as f32; CLASS_COUNT];
        q[truth] = p;
        q
    }

    /// Counts `beats` tracked beats whose true classes `truth` gives, observing each previous
    /// beat with probability `p` on its class (and on a wrong one every `wrong_every`th).
    fn count(truth: impl Fn(usize) -> usize, p: f32, wrong_every: usize) -> Vec<(usize, usize)> {
        count_with(BarPointerParams::default(), truth, p, wrong_every)
    }

    fn count_with(
        params: BarPointerParams,
        truth: impl Fn(usize) -> usize,
        p: f32,
        wrong_every: usize,
    ) -> Vec<(usize, usize)> {
        let mut bp = BarPointer::new(params);
        let mut out = Vec::new();
        for k in 0..48 {
            let seen = (k > 0).then(|| {
                let t = if wrong_every > 0 && k % wrong_every == 0 {
                    successor(truth(k - 1))
                } else {
                    truth(k - 1)
                };
                observe(t, p)
            });
            let (class, _) = bp.beat(seen.as_ref().map(|q| (q, &UNIFORM)));
            out.push((class, truth(k)));
        }
        out
    }

    #[test]
    fn locks_to_meter_and_downbeat_within_two_bars_and_holds_through_errors() {
        for meter in [3, 4] {
            for offset in 0..meter {
                let truth =
                    |k: usize| beat_class_index(meter, (k + meter - offset) % meter + 1).unwrap();
                for (k, (got, want)) in count(truth, 0.5, 5)
                    .into_iter()
                    .enumerate()
                    .skip(2 * meter + 1)
                {
                    assert_eq!(
                        CLASSES[got], CLASSES[want],
                        "meter {meter} offset {offset} beat {k}"
                    );
                }
            }
        }
    }

    #[test]
    fn finds_double_and_half_time_and_needs_more_evidence_for_them() {
        let even = BarPointerParams {
            half_time: 1.0,
            double_time: 1.0,
            ..BarPointerParams::default()
        };
        for (level, cycle) in [(Level::Double, 8), (Level::Half, 4)] {
            let first = class_index(BarClass {
                level,
                meter: 4,
                position: 2,
            })
            .unwrap();
            let truth = |k: usize| (0..k).fold(first, |c, _| successor(c));
            // The first beat from which the count is right for good.
            let locked =
                |out: &[(usize, usize)]| out.iter().rposition(|(g, w)| g != w).map_or(0, |k| k + 1);
            // Weighed like the tracked level, the evidence of one bar and a beat suffices.
            let even_lock = locked(&count_with(even, truth, 0.5, 0));
            assert!(even_lock <= cycle + 1, "{level:?}: {even_lock}");
            // By default weak evidence for another level does not move the count off the
            // tracked beat; clear evidence does.
            let weak = count(truth, 0.1, 0);
            assert!(
                weak.iter().all(|(g, _)| CLASSES[*g].level == Level::Beat),
                "{level:?}"
            );
            let clear_lock = locked(&count(truth, 0.9, 0));
            assert!(clear_lock <= 24, "{level:?}: {clear_lock}");
        }
    }

    #[test]
    fn without_evidence_the_count_keeps_going_in_four() {
        let mut bp = BarPointer::new(BarPointerParams::default());
        let seq: Vec<usize> = (0..9).map(|_| CLASSES[bp.beat(None).0].position).collect();
        assert_eq!(seq, [1, 2, 3, 4, 1, 2, 3, 4, 1]);
    }

    /// 24 beats of 4/4, then 3/4 from position `from` on.
    fn four_then_three(k: usize, from: usize) -> usize {
        if k < 24 {
            beat_class_index(4, k % 4 + 1).unwrap()
        } else {
            beat_class_index(3, (k - 24 + from - 1) % 3 + 1).unwrap()
        }
    }

    #[test]
    fn follows_a_meter_change() {
        let truth = |k: usize| four_then_three(k, 1);
        let out = count(truth, 0.6, 0);
        assert!(out[36..].iter().all(|(g, w)| g == w), "{out:?}");
    }

    #[test]
    fn forgetting_at_a_level_change_relocks_as_fast_as_a_fresh_start() {
        // 24 beats of 4/4 evidence, then weak 3/4 evidence (the tracker switched level
        // mid-song): the old belief holds out 4 beats, a forgotten one 2.
        let truth = |k: usize| four_then_three(k, 3);
        let relock = |forget: bool| {
            let mut bp = BarPointer::new(BarPointerParams::default());
            let mut last_wrong = 0;
            for k in 0..48 {
                if forget && k == 24 {
                    bp.forget();
                }
                let seen = (k > 0).then(|| observe(truth(k - 1), 0.3));
                let (class, _) = bp.beat(seen.as_ref().map(|q| (q, &UNIFORM)));
                if class != truth(k) {
                    last_wrong = k;
                }
            }
            last_wrong + 1 - 24
        };
        let (kept, forgot) = (relock(false), relock(true));
        assert!(forgot <= 2, "relocked {forgot} beats after the change");
        assert!(forgot < kept, "forgetting {forgot} vs keeping {kept} beats");
    }

    #[test]
    fn overrides_parse_and_reject_nonsense() {
        let p = BarPointerParams::default()
            .with_overrides("jump=0.05, switch_ratio=3")
            .unwrap();
        assert_eq!((p.jump, p.switch_ratio), (0.05, 3.0));
        assert!(
            BarPointerParams::default()
                .with_overrides("jump=-1")
                .is_err()
        );
        assert!(
            BarPointerParams::default()
                .with_overrides("wobble=1")
                .is_err()
        );
    }
}
