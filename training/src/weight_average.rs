//! An exponential moving average of the weights over training (Polyak averaging), written in
//! place of the last step's weights: one update's noise — a rollout that pulled hard, a batch
//! of one style — is averaged out of the dancer that ships.

use model::neural::tensors::NamedTensors;

/// The running average of every trainable tensor, `average ← d·average + (1 − d)·weights`
/// after each update; a layer's permutation is copied, not averaged (it never trains, and an
/// averaged index need not be a whole number).
#[derive(Clone, Debug)]
pub struct WeightAverage {
    decay: f32,
    average: NamedTensors,
    updates: u64,
}

/// Whether `name` is a tensor the optimiser moves (a permutation is fixed at initialisation).
fn averaged(name: &str) -> bool {
    !name.ends_with(".perm")
}

impl WeightAverage {
    /// Starts the average at `start` (the weights before the first update) with decay `decay`
    /// (clamped to 0..1; about `1 / (1 − decay)` updates carry most of the weight).
    pub fn new(decay: f64, start: &NamedTensors) -> Self {
        WeightAverage {
            decay: decay.clamp(0.0, 1.0) as f32,
            average: start.clone(),
            updates: 0,
        }
    }

    /// Folds the weights after one update into the average. A tensor the average lacks or
    /// holds in another shape starts over from `weights`; a non-finite value is not folded in
    /// (the trainer skips such updates; the average keeps its last finite value).
    pub fn update(&mut self, weights: &NamedTensors) {
        let d = self.decay;
        for (name, w) in &weights.map {
            match self.average.map.get_mut(name) {
                Some(a) if a.shape == w.shape && a.data.len() == w.data.len() => {
                    if !averaged(name) {
                        a.data.clone_from(&w.data);
                        continue;
                    }
                    for (a, &w) in a.data.iter_mut().zip(&w.data) {
                        if w.is_finite() {
                            *a = d * *a + (1.0 - d) * w;
                        }
                    }
                }
                _ => {
                    self.average.map.insert(name.clone(), w.clone());
                }
            }
        }
        self.updates += 1;
    }

    /// The averaged weights (the tensors the average was started from, no others).
    pub fn weights(&self) -> &NamedTensors {
        &self.average
    }

    /// Updates folded in so far.
    pub fn updates(&self) -> u64 {
        self.updates
    }

    /// Writes the averaged weights over their names in `tensors` (normalisation, seed clips
    /// and anything else the average does not hold are left as they are).
    pub fn apply_to(&self, tensors: &mut NamedTensors) {
        for (name, a) in &self.average.map {
            tensors.map.insert(name.clone(), a.clone());
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn one(name: &str, v: &[f32]) -> NamedTensors {
        let mut t = NamedTensors::default();
        t.insert(name, &[v.len()], v.to_vec());
        t
    }

    #[test]
    fn the_average_follows_the_weights_with_the_decay() {
        let mut avg = WeightAverage::new(0.9, &one("w", &[0.0, 10.0]));
        avg.update(&one("w", &[1.0, 0.0]));
        let mut out = NamedTensors::default();
        avg.apply_to(&mut out);
        let a = out.get("w", &[2]).unwrap();
        assert!(
            (a[0] - 0.1).abs() < 1e-6 && (a[1] - 9.0).abs() < 1e-5,
            "{a:?}"
        );
        // Held weights draw the average onto them: 0.9^n of the gap is left after n updates.
        for _ in 0..99 {
            avg.update(&one("w", &[1.0, 0.0]));
        }
        avg.apply_to(&mut out);
        let a = out.get("w", &[2]).unwrap();
        let left = 0.9f32.powi(100);
        assert!((a[0] - (1.0 - left)).abs() < 1e-4, "{a:?}");
        assert!((a[1] - 10.0 * left).abs() < 1e-4, "{a:?}");
        assert_eq!(avg.updates(), 100);
    }

    #[test]
    fn an_alternating_weight_averages_to_its_middle() {
        let mut avg = WeightAverage::new(0.99, &one("w", &[0.0]));
        for i in 0..2000 {
            avg.update(&one("w", &[if i % 2 == 0 { 1.0 } else { -1.0 }]));
        }
        let mut out = NamedTensors::default();
        avg.apply_to(&mut out);
        let a = out.get("w", &[1]).unwrap()[0];
        assert!(a.abs() < 0.02, "{a}");
    }

    #[test]
    fn permutations_are_copied_and_other_tensors_kept() {
        let mut start = one("flow.0.perm", &[2.0, 0.0, 1.0]);
        start.insert("w", &[1], vec![0.0]);
        let mut avg = WeightAverage::new(0.5, &start);
        let mut now = one("flow.0.perm", &[1.0, 2.0, 0.0]);
        now.insert("w", &[1], vec![f32::NAN]);
        now.insert("new", &[1], vec![3.0]);
        avg.update(&now);
        let mut out = one("seed.motion", &[7.0]);
        avg.apply_to(&mut out);
        assert_eq!(out.permutation("flow.0.perm", 3).unwrap(), vec![1, 2, 0]);
        // A non-finite weight is not folded in; a new tensor starts at its value.
        assert_eq!(out.get("w", &[1]).unwrap(), &[0.0]);
        assert_eq!(out.get("new", &[1]).unwrap(), &[3.0]);
        assert_eq!(out.get("seed.motion", &[1]).unwrap(), &[7.0]);
    }
}
