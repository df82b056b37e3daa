//! Training of the downbeat network ([`dsp::downbeat_net`]) with burn: a small fully connected
//! network over windows of beat-synchronous features, with a cross-entropy against the bar
//! position of each tracked beat that lies on an annotated beat.

use burn::module::Module;
use burn::nn::{Initializer, Linear, LinearConfig};
use burn::optim::{AdamConfig, GradientsParams, ModuleOptimizer};
use burn::tensor::activation::{log_softmax, relu};
use burn::tensor::{Tensor, TensorData};
use dsp::bar_class::{BarClass, CLASS_COUNT, Level, class_index};
use dsp::downbeat_net::{
    BeatWindow, DOWNBEAT_INPUT_DIM as I, DenseWeights, DownbeatNetEnsemble, DownbeatNetWeights,
};
use dsp::{BarFeatures, BarPointerParams, DownbeatClassifier};

use crate::device::training_device;
use crate::layers::{fan_in_uniform, values};
use dsp::metrics::BEAT_TOLERANCE_S;
use model::neural::rng::Rng;

/// Training examples: network inputs `[n][DOWNBEAT_INPUT_DIM]` (flat) and a class per row.
#[derive(Clone, Debug, Default)]
pub struct DownbeatExamples {
    /// Inputs, as the analysis computes them.
    pub inputs: Vec<f32>,
    /// Bar position class of each row.
    pub classes: Vec<usize>,
}

impl DownbeatExamples {
    /// Rows.
    pub fn len(&self) -> usize {
        self.classes.len()
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.classes.is_empty()
    }

    /// Adds one song: the bar features of its tracked beats, in order, labelled against the
    /// annotated beats `(time, position in the bar)` of a bar of `meter` beats. Tracked beats
    /// on no annotated beat (nor halfway between two, at double time) teach nothing but stay
    /// in the windows, as they do live.
    pub fn add_song(&mut self, features: &[BarFeatures], reference: &[(f64, usize)], meter: usize) {
        // The window the analysis keeps, restarting where it does.
        let mut window = BeatWindow::new(BarPointerParams::default().tempo_jump);
        let mut row = [0.0f32; I];
        let times: Vec<f64> = features.iter().map(|f| f.beat_time_s).collect();
        for (k, f) in features.iter().enumerate() {
            window.push(&f.values);
            let Some(class) = label(&times, k, reference, meter) else {
                continue;
            };
            window.inputs(&mut row);
            self.inputs.extend_from_slice(&row);
            self.classes.push(class);
        }
    }

    /// How often each class occurs, summing to 1 (every class at least a little).
    pub fn class_frequencies(&self) -> [f32; CLASS_COUNT] {
        let mut n = [1.0f32; CLASS_COUNT];
        for &c in &self.classes {
            n[c] += 1.0;
        }
        let total: f32 = n.iter().sum();
        n.map(|x| x / total)
    }
}

/// The mean interval around item `k` of the increasing times `t`.
fn local_interval(t: &[f64], k: usize) -> Option<f64> {
    let before = k.checked_sub(1).and_then(|i| t.get(i)).copied();
    let after = t.get(k + 1).copied();
    match (before, after) {
        (Some(a), Some(b)) => Some((b - a) / 2.0),
        (Some(a), None) => Some(t[k] - a),
        (None, Some(b)) => Some(b - t[k]),
        (None, None) => None,
    }
}

/// The class of tracked beat `k` (at `tracked[k]`) against the annotation, if it has one.
fn label(tracked: &[f64], k: usize, reference: &[(f64, usize)], meter: usize) -> Option<usize> {
    let t = tracked[k];
    let annotated: Vec<f64> = reference.iter().map(|r| r.0).collect();
    let j = (0..reference.len()).min_by(|&a, &b| {
        (reference[a].0 - t)
            .abs()
            .total_cmp(&(reference[b].0 - t).abs())
    })?;
    let ratio = local_interval(tracked, k)? / local_interval(&annotated, j)?;
    let on_beat = (reference[j].0 - t).abs() <= BEAT_TOLERANCE_S;
    let position = reference[j].1;
    let class = |level, position| {
        class_index(BarClass {
            level,
            meter,
            position,
        })
    };
    if (0.8..=1.25).contains(&ratio) && on_beat {
        class(Level::Beat, position)
    } else if (0.4..=0.625).contains(&ratio) {
        if on_beat {
            return class(Level::Double, 2 * position - 1);
        }
        // Halfway between the annotated beat before and the one after.
        let before = reference.iter().rposition(|r| r.0 < t)?;
        let after = reference.get(before + 1)?;
        let mid = (reference[before].0 + after.0) / 2.0;
        ((mid - t).abs() <= BEAT_TOLERANCE_S)
            .then_some(())
            .and_then(|_| class(Level::Double, 2 * reference[before].1))
    } else if (1.6..=2.5).contains(&ratio) && on_beat {
        class(Level::Half, position)
    } else {
        None
    }
}

/// Shape and schedule of a training run.
#[derive(Clone, Debug)]
pub struct DownbeatTrainConfig {
    /// Width of each hidden layer.
    pub hidden: Vec<usize>,
    /// Rows per batch.
    pub batch: usize,
    /// Optimiser steps.
    pub steps: usize,
    /// Adam learning rate.
    pub learning_rate: f64,
    /// Standard deviation of Gaussian noise added to the inputs (regularisation).
    pub input_noise: f32,
    /// Seed of batches and initial weights.
    pub seed: u64,
}

impl Default for DownbeatTrainConfig {
    fn default() -> Self {
        Self {
            hidden: vec![64, 64],
            batch: 256,
            steps: 3000,
            learning_rate: 1e-3,
            input_noise: 0.1,
            seed: 1,
        }
    }
}

/// The network in burn form.
#[derive(Module, Debug)]
pub struct DownbeatNet {
    layers: Vec<Linear>,
}

impl DownbeatNet {
    /// A freshly initialised network, its weights drawn from `rng`.
    pub fn new(c: &DownbeatTrainConfig, rng: &mut Rng, device: &burn::tensor::Device) -> Self {
        let mut widths = vec![I];
        widths.extend(&c.hidden);
        widths.push(CLASS_COUNT);
        Self {
            layers: widths
                .windows(2)
                .map(|w| {
                    let mut layer = LinearConfig::new(w[0], w[1])
                        .with_initializer(Initializer::Zeros)
                        .init(device);
                    layer.weight = fan_in_uniform([w[0], w[1]], w[0], rng, device);
                    layer.bias = Some(fan_in_uniform([w[1]], w[0], rng, device));
                    layer
                })
                .collect(),
        }
    }

    /// Class logits `[n, CLASS_COUNT]` for inputs `[n, DOWNBEAT_INPUT_DIM]`.
    pub fn forward(&self, mut x: Tensor<2>) -> Tensor<2> {
        let last = self.layers.len() - 1;
        for (i, l) in self.layers.iter().enumerate() {
            x = l.forward(x);
            if i < last {
                x = relu(x);
            }
        }
        x
    }

    /// The weights in the analysis' format (`[outputs][inputs]`; burn stores `[inputs][outputs]`).
    pub fn export(&self) -> DownbeatNetWeights {
        DownbeatNetWeights {
            layers: self
                .layers
                .iter()
                .map(|l| {
                    let [inputs, outputs] = l.weight.val().dims();
                    DenseWeights {
                        inputs,
                        outputs,
                        weight: values(l.weight.val().transpose()),
                        bias: l
                            .bias
                            .as_ref()
                            .map(|b| values(b.val()))
                            .unwrap_or_else(|| vec![0.0; outputs]),
                    }
                })
                .collect(),
        }
    }
}

/// Mean cross-entropy of `logits` against one-hot `targets`.
fn cross_entropy(logits: Tensor<2>, targets: Tensor<2>) -> Tensor<1> {
    (log_softmax(logits, 1) * targets).sum_dim(1).neg().mean()
}

fn one_hot(classes: impl Iterator<Item = usize>) -> Vec<f32> {
    classes
        .flat_map(|c| (0..CLASS_COUNT).map(move |k| if k == c { 1.0 } else { 0.0 }))
        .collect()
}

/// Share of rows whose most probable class is right, for exported weights on the CPU path the
/// analysis runs.
pub fn accuracy(ensemble: &DownbeatNetEnsemble, examples: &DownbeatExamples) -> f64 {
    if examples.is_empty() {
        return 0.0;
    }
    // Scores ready-made rows: the classifier's own window goes unused.
    let mut classifier = DownbeatClassifier::new(ensemble.clone(), 0.0);
    let mut right = 0usize;
    for (row, &class) in examples.inputs.chunks_exact(I).zip(&examples.classes) {
        let Ok(row) = <&[f32; I]>::try_from(row) else {
            continue;
        };
        let p = classifier.classify(row);
        let best = (0..CLASS_COUNT).max_by(|&a, &b| p[a].total_cmp(&p[b]));
        right += usize::from(best == Some(class));
    }
    right as f64 / examples.len() as f64
}

/// Trains one network on `train`, reporting (step, training loss) every `report_every` steps.
pub fn train_downbeat_net(
    train: &DownbeatExamples,
    c: &DownbeatTrainConfig,
    report_every: usize,
    mut report: impl FnMut(usize, f32, &DownbeatNetWeights),
) -> DownbeatNetWeights {
    let device = training_device();
    let mut rng = Rng::new(c.seed);
    let mut net = DownbeatNet::new(c, &mut rng, &device);
    let mut optim: ModuleOptimizer = AdamConfig::new().init();
    let n = train.len().max(1);
    for step in 1..=c.steps {
        let rows: Vec<usize> = (0..c.batch).map(|_| rng.below(n)).collect();
        let mut x = Vec::with_capacity(c.batch * I);
        for &r in &rows {
            x.extend(
                train.inputs[r * I..(r + 1) * I]
                    .iter()
                    .map(|v| v + c.input_noise * rng.normal()),
            );
        }
        let y = one_hot(rows.iter().map(|&r| train.classes[r]));
        let x = Tensor::from_data(TensorData::new(x, [c.batch, I]), &device);
        let y = Tensor::from_data(TensorData::new(y, [c.batch, CLASS_COUNT]), &device);
        let loss = cross_entropy(net.forward(x), y);
        let value = values(loss.clone()).first().copied().unwrap_or(f32::NAN);
        if value.is_finite() {
            let grads = GradientsParams::from_grads(loss.backward(), &net);
            let progress = step as f64 / c.steps as f64;
            let lr = c.learning_rate * (0.55 + 0.45 * (std::f64::consts::PI * progress).cos());
            net = optim.step(lr, net, grads);
        }
        if step % report_every == 0 || step == c.steps {
            report(step, value, &net.export());
        }
    }
    net.export()
}

#[cfg(test)]
mod tests {
    use super::*;
    use dsp::bar_class::beat_class_index;
    use dsp::bar_features::{BAR_FEATURE_DIM as F, TEMPO_FEATURE};

    fn features(k: usize, meter: usize, rng: &mut Rng) -> BarFeatures {
        let mut values = [0.0f32; F];
        for v in values.iter_mut() {
            *v = rng.uniform() as f32;
        }
        // A steady 120 BPM, as the beat times say.
        values[TEMPO_FEATURE] = 0.0;
        // Feature 3 is loud on downbeats, feature 7 on the middle of a 4/4 bar.
        if k.is_multiple_of(meter) {
            values[3] += 2.0;
        }
        if meter == 4 && k % 4 == 2 {
            values[7] += 1.0;
        }
        BarFeatures {
            beat_time_s: k as f64 * 0.5,
            values,
        }
    }

    fn song(meter: usize, beats: usize, rng: &mut Rng) -> (Vec<BarFeatures>, Vec<(f64, usize)>) {
        let f: Vec<BarFeatures> = (0..beats).map(|k| features(k, meter, rng)).collect();
        let r = (0..beats)
            .map(|k| (k as f64 * 0.5, k % meter + 1))
            .collect();
        (f, r)
    }

    #[test]
    fn a_change_of_level_starts_the_window_afresh_as_live() {
        let mut rng = Rng::new(3);
        let (mut f, r) = song(4, 40, &mut rng);
        // From beat 20 on, the tracker reports twice the tempo (a jump to another level).
        for b in &mut f[20..] {
            b.values[TEMPO_FEATURE] = 1.0;
        }
        let mut whole = DownbeatExamples::default();
        whole.add_song(&f, &r, 4);
        let mut fresh = DownbeatExamples::default();
        fresh.add_song(&f[20..], &r, 4);
        assert_eq!(whole.len(), 40);
        assert_eq!(fresh.len(), 20);
        // The rows from the jump on see only the beats since it, like a song that began there.
        assert_eq!(&whole.inputs[20 * I..], &fresh.inputs[..]);
        assert_ne!(&whole.inputs[19 * I..20 * I], &fresh.inputs[..I]);
    }

    #[test]
    fn learns_meter_and_position_from_accents_and_streams_the_same() {
        let mut rng = Rng::new(5);
        let mut train = DownbeatExamples::default();
        for i in 0..12 {
            let meter = if i % 3 == 0 { 3 } else { 4 };
            let (f, r) = song(meter, 60, &mut rng);
            train.add_song(&f, &r, meter);
        }
        assert_eq!(train.len(), 12 * 60);
        let c = DownbeatTrainConfig {
            hidden: vec![16],
            steps: 300,
            learning_rate: 3e-3,
            ..DownbeatTrainConfig::default()
        };
        let w = train_downbeat_net(&train, &c, 1000, |_, _, _| {});
        let ensemble = DownbeatNetEnsemble {
            nets: vec![w],
            class_prior: train.class_frequencies(),
        };
        let mut valid = DownbeatExamples::default();
        let (f4, r4) = song(4, 60, &mut rng);
        valid.add_song(&f4, &r4, 4);
        let (f3, r3) = song(3, 60, &mut rng);
        valid.add_song(&f3, &r3, 3);
        let acc = accuracy(&ensemble, &valid);
        assert!(acc > 0.8, "validation accuracy {acc}");
        // The streaming classifier computes the same probabilities from the raw features.
        let mut stream =
            DownbeatClassifier::new(ensemble.clone(), BarPointerParams::default().tempo_jump);
        let mut right = 0;
        for (k, f) in f4.iter().enumerate() {
            let p = stream.push(&f.values);
            let best = (0..CLASS_COUNT)
                .max_by(|&a, &b| p[a].total_cmp(&p[b]))
                .unwrap();
            right += usize::from(best == beat_class_index(4, k % 4 + 1).unwrap());
        }
        assert!(right as f64 / 60.0 > 0.8, "{right} of 60");
    }

    #[test]
    fn tracked_beats_off_the_annotation_teach_nothing() {
        let mut rng = Rng::new(1);
        let (mut f, r) = song(4, 20, &mut rng);
        f[5].beat_time_s += 0.15;
        let mut ex = DownbeatExamples::default();
        ex.add_song(&f, &r, 4);
        assert_eq!(ex.len(), 19);
        assert_eq!(ex.classes[4], beat_class_index(4, 1).unwrap());
        assert_eq!(ex.classes[5], beat_class_index(4, 3).unwrap());
    }

    #[test]
    fn double_and_half_time_are_labelled_as_such() {
        let reference: Vec<(f64, usize)> = (0..40).map(|k| (k as f64 * 0.5, k % 4 + 1)).collect();
        let at = |times: Vec<f64>| -> Vec<usize> {
            let f: Vec<BarFeatures> = times
                .iter()
                .map(|&t| BarFeatures {
                    beat_time_s: t,
                    values: [0.0; F],
                })
                .collect();
            let mut ex = DownbeatExamples::default();
            ex.add_song(&f, &reference, 4);
            ex.classes
        };
        let class = |level, position| {
            class_index(BarClass {
                level,
                meter: 4,
                position,
            })
            .unwrap()
        };
        let double = at((0..20).map(|k| 1.0 + k as f64 * 0.25).collect());
        let d = |p| class(Level::Double, p);
        assert_eq!(&double[..4], &[d(5), d(6), d(7), d(8)]);
        let half = at((0..8).map(|k| 2.5 + k as f64 * 1.0).collect());
        let h = |p| class(Level::Half, p);
        assert_eq!(&half[..3], &[h(2), h(4), h(2)]);
    }
}
