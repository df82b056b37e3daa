//! Training of the learned beat activation ([`dsp::beat_activation`]) with burn: the same
//! dilated causal convolution network the analysis runs hop by hop, trained on whole sequences
//! at once with a binary cross-entropy against beat targets.

use burn::module::Module;
use burn::nn::conv::{Conv1d, Conv1dConfig};
use burn::nn::{Initializer, PaddingConfig1d};
use burn::optim::{AdamConfig, GradientsParams, ModuleOptimizer};
use burn::tensor::activation::relu;
use burn::tensor::{Device, Tensor, TensorData};
use dsp::beat_activation::{BEAT_INPUT_DIM as I, BeatNetWeights};

use crate::device::{cpu_device, training_device};
use crate::layers::{fan_in_uniform, values};
use model::neural::rng::Rng;

/// One song's network inputs (`[frames][BEAT_INPUT_DIM]`, flat) and beat targets (`[frames]`).
#[derive(Clone, Debug, Default)]
pub struct BeatSong {
    /// Inputs per hop, as the analysis computes them.
    pub inputs: Vec<f32>,
    /// Target per hop: 1 on the hop nearest a beat, 0.5 beside it, 0 elsewhere.
    pub targets: Vec<f32>,
}

impl BeatSong {
    /// Hops in the song.
    pub fn frames(&self) -> usize {
        self.targets.len()
    }

    /// Builds targets for `frames` hops at `frame_rate` from beat times in seconds.
    pub fn targets_from_beats(beats_s: &[f64], frames: usize, frame_rate: f64) -> Vec<f32> {
        let mut t = vec![0.0f32; frames];
        for &b in beats_s {
            let centre = (b * frame_rate).round() as i64;
            for (d, v) in [(-1, 0.5f32), (0, 1.0), (1, 0.5)] {
                let i = centre + d;
                if (0..frames as i64).contains(&i) {
                    t[i as usize] = t[i as usize].max(v);
                }
            }
        }
        t
    }
}

/// Shape and schedule of a training run.
#[derive(Clone, Debug)]
pub struct BeatTrainConfig {
    /// Hidden channels.
    pub channels: usize,
    /// Convolution kernel size.
    pub kernel: usize,
    /// Dilation per layer.
    pub dilations: Vec<usize>,
    /// Sequences per batch.
    pub batch: usize,
    /// Hops per training sequence.
    pub sequence: usize,
    /// Optimiser steps.
    pub steps: usize,
    /// Adam learning rate.
    pub learning_rate: f64,
    /// Seed of crops and initial weights.
    pub seed: u64,
}

impl Default for BeatTrainConfig {
    fn default() -> Self {
        Self {
            channels: 24,
            kernel: 3,
            dilations: vec![1, 2, 4, 8, 16, 32, 64],
            batch: 16,
            sequence: 512,
            steps: 1500,
            learning_rate: 2e-3,
            seed: 1,
        }
    }
}

/// The network in burn form.
#[derive(Module, Debug)]
pub struct BeatNet {
    input: Conv1d,
    convs: Vec<Conv1d>,
    output: Conv1d,
}

impl BeatNet {
    /// A freshly initialised network, its weights drawn from `rng`.
    pub fn new(c: &BeatTrainConfig, rng: &mut Rng, device: &Device) -> Self {
        let mut net = Self::zeroed(c, device);
        for conv in std::iter::once(&mut net.input)
            .chain(&mut net.convs)
            .chain(std::iter::once(&mut net.output))
        {
            let [out, inputs, kernel] = conv.weight.val().dims();
            let fan_in = inputs * kernel;
            conv.weight = fan_in_uniform([out, inputs, kernel], fan_in, rng, device);
            conv.bias = Some(fan_in_uniform([out], fan_in, rng, device));
        }
        net
    }

    /// The network's layers with every weight zero, to be drawn or loaded.
    fn zeroed(c: &BeatTrainConfig, device: &Device) -> Self {
        let conv = |inputs, outputs, kernel| {
            Conv1dConfig::new(inputs, outputs, kernel).with_initializer(Initializer::Zeros)
        };
        let convs = c
            .dilations
            .iter()
            .map(|&d| {
                conv(c.channels, c.channels, c.kernel)
                    .with_dilation(d)
                    .with_padding(PaddingConfig1d::Explicit((c.kernel - 1) * d, 0))
                    .init(device)
            })
            .collect();
        Self {
            input: conv(I, c.channels, 1).init(device),
            convs,
            output: conv(c.channels, 1, 1).init(device),
        }
    }

    /// Beat logits `[b, 1, t]` for normalised inputs `[b, BEAT_INPUT_DIM, t]`.
    pub fn forward(&self, x: Tensor<3>) -> Tensor<3> {
        let mut h = relu(self.input.forward(x));
        for conv in &self.convs {
            h = h.clone() + relu(conv.forward(h));
        }
        self.output.forward(h)
    }

    /// The weights in the analysis' streaming format.
    pub fn export(&self, c: &BeatTrainConfig, mean: &[f32], std: &[f32]) -> BeatNetWeights {
        let bias = |conv: &Conv1d| {
            conv.bias
                .as_ref()
                .map(|b| values(b.val()))
                .unwrap_or_default()
        };
        BeatNetWeights {
            channels: c.channels,
            kernel: c.kernel,
            dilations: c.dilations.clone(),
            input_mean: mean.to_vec(),
            input_std: std.to_vec(),
            input_weight: values(self.input.weight.val()),
            input_bias: bias(&self.input),
            conv_weight: self.convs.iter().map(|k| values(k.weight.val())).collect(),
            conv_bias: self.convs.iter().map(bias).collect(),
            output_weight: values(self.output.weight.val()),
            output_bias: bias(&self.output).first().copied().unwrap_or(0.0),
        }
    }
}

/// Songs drawn from together, with their share of the batches.
#[derive(Clone, Debug, Default)]
pub struct SongPool {
    /// The songs.
    pub songs: Vec<BeatSong>,
    /// Relative share of batch sequences cut from these songs.
    pub share: f64,
}

/// Per-input mean and standard deviation over every hop of the pools' songs.
pub fn input_statistics(pools: &[SongPool]) -> (Vec<f32>, Vec<f32>) {
    let (mut sum, mut sq, mut n) = (vec![0.0f64; I], vec![0.0f64; I], 0usize);
    for s in pools.iter().flat_map(|p| &p.songs) {
        for row in s.inputs.chunks_exact(I) {
            for (j, &x) in row.iter().enumerate() {
                sum[j] += x as f64;
                sq[j] += (x as f64) * (x as f64);
            }
            n += 1;
        }
    }
    let n = n.max(1) as f64;
    let mean: Vec<f32> = sum.iter().map(|s| (s / n) as f32).collect();
    let std = sq
        .iter()
        .zip(&sum)
        .map(|(q, s)| ((q / n - (s / n).powi(2)).max(0.0).sqrt() as f32).max(1e-3))
        .collect();
    (mean, std)
}

/// Writes hop-major input rows (`[hops][I]`), normalised, into `out` laid out input-major
/// (`[I][out.len() / I]`, the layout burn's `Conv1d` reads); hops past the rows stay as they
/// are (zero padding).
fn normalise_channels_first(rows: &[f32], mean: &[f32], std: &[f32], out: &mut [f32]) {
    let stride = out.len() / I;
    for (t, row) in rows.chunks_exact(I).enumerate() {
        for j in 0..I {
            out[j * stride + t] = (row[j] - mean[j]) / std[j];
        }
    }
}

/// Draws a pool by share, then a song of it.
fn draw_song<'a>(pools: &'a [SongPool], rng: &mut Rng) -> &'a BeatSong {
    // A lone pool draws no share, so a one-pool recipe cuts the batches the trainer cut before
    // there were pools (the shipped activation's recipe is one pool).
    if let [pool] = pools {
        return &pool.songs[rng.below(pool.songs.len())];
    }
    let total: f64 = pools.iter().map(|p| p.share).sum();
    let mut pick = rng.uniform() * total;
    let pool = pools
        .iter()
        .find(|p| {
            pick -= p.share;
            pick < 0.0
        })
        .unwrap_or(&pools[pools.len() - 1]);
    &pool.songs[rng.below(pool.songs.len())]
}

/// Cuts a batch of normalised crops: inputs `[b, I, s]` and targets `[b, 1, s]`, flat.
fn batch(
    pools: &[SongPool],
    c: &BeatTrainConfig,
    mean: &[f32],
    std: &[f32],
    rng: &mut Rng,
) -> (Vec<f32>, Vec<f32>) {
    let s = c.sequence;
    let mut x = vec![0.0f32; c.batch * I * s];
    let mut y = vec![0.0f32; c.batch * s];
    for b in 0..c.batch {
        let song = draw_song(pools, rng);
        let start = rng.below(song.frames().saturating_sub(s) + 1);
        let len = s.min(song.frames() - start);
        let rows = &song.inputs[start * I..(start + len) * I];
        normalise_channels_first(rows, mean, std, &mut x[b * I * s..(b + 1) * I * s]);
        y[b * s..b * s + len].copy_from_slice(&song.targets[start..start + len]);
    }
    (x, y)
}

/// Mean binary cross-entropy of `logits` against `targets` (numerically stable form).
fn bce(logits: Tensor<3>, targets: Tensor<3>) -> Tensor<1> {
    let softplus = logits.clone().clamp_min(0.0) + (logits.clone().abs().neg().exp() + 1.0).log();
    (softplus - targets * logits).mean()
}

/// Trains a network on the pools' songs, scoring `valid` every `report_every` steps through `report`
/// (step, training loss, validation loss); returns the weights in streaming form.
pub fn train_beat_activation(
    train: &[SongPool],
    valid: &[BeatSong],
    c: &BeatTrainConfig,
    report_every: usize,
    mut report: impl FnMut(usize, f32, Option<f32>),
) -> BeatNetWeights {
    let device = training_device();
    let (mean, std) = input_statistics(train);
    let mut rng = Rng::new(c.seed);
    let mut net = BeatNet::new(c, &mut rng, &device);
    let mut optim: ModuleOptimizer = AdamConfig::new().init();
    for step in 1..=c.steps {
        let (x, y) = batch(train, c, &mean, &std, &mut rng);
        let x = Tensor::from_data(TensorData::new(x, [c.batch, I, c.sequence]), &device);
        let y = Tensor::from_data(TensorData::new(y, [c.batch, 1, c.sequence]), &device);
        let loss = bce(net.forward(x), y);
        let value = values(loss.clone()).first().copied().unwrap_or(f32::NAN);
        if value.is_finite() {
            let grads = GradientsParams::from_grads(loss.backward(), &net);
            // Cosine decay to a tenth of the rate.
            let progress = step as f64 / c.steps as f64;
            let lr = c.learning_rate * (0.55 + 0.45 * (std::f64::consts::PI * progress).cos());
            net = optim.step(lr, net, grads);
        }
        let val = (step % report_every == 0 || step == c.steps)
            .then(|| validation_loss(&net.export(c, &mean, &std), valid, c));
        report(step, value, val.flatten());
    }
    net.export(c, &mean, &std)
}

/// Mean cross-entropy of exported weights over whole validation songs, on the CPU.
fn validation_loss(w: &BeatNetWeights, valid: &[BeatSong], c: &BeatTrainConfig) -> Option<f32> {
    if valid.is_empty() {
        return None;
    }
    let device = cpu_device();
    let net = BeatNet::zeroed(c, &device).load_weights(w, &device);
    let (mut sum, mut n) = (0.0f64, 0usize);
    for s in valid {
        let t = s.frames();
        let mut x = vec![0.0f32; I * t];
        normalise_channels_first(&s.inputs, &w.input_mean, &w.input_std, &mut x);
        let x = Tensor::from_data(TensorData::new(x, [1, I, t]), &device);
        let y = Tensor::from_data(TensorData::new(s.targets.clone(), [1, 1, t]), &device);
        let l = values(bce(net.forward(x), y))
            .first()
            .copied()
            .unwrap_or(f32::NAN);
        sum += l as f64 * t as f64;
        n += t;
    }
    Some((sum / n.max(1) as f64) as f32)
}

impl BeatNet {
    /// Replaces the weights with streaming-format ones (the shapes must match `self`).
    pub fn load_weights(mut self, w: &BeatNetWeights, device: &Device) -> Self {
        let c = w.channels;
        let set = |conv: &mut Conv1d, weight: &[f32], shape: [usize; 3], bias: &[f32]| {
            conv.weight = burn::module::Param::from_tensor(Tensor::from_data(
                TensorData::new(weight.to_vec(), shape),
                device,
            ));
            conv.bias = Some(burn::module::Param::from_tensor(Tensor::from_data(
                TensorData::new(bias.to_vec(), [shape[0]]),
                device,
            )));
        };
        set(&mut self.input, &w.input_weight, [c, I, 1], &w.input_bias);
        for (l, conv) in self.convs.iter_mut().enumerate() {
            set(conv, &w.conv_weight[l], [c, c, w.kernel], &w.conv_bias[l]);
        }
        set(
            &mut self.output,
            &w.output_weight,
            [1, c, 1],
            &[w.output_bias],
        );
        self
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use dsp::beat_activation::{BeatActivation, BeatNetEnsemble};

    fn streaming(w: BeatNetWeights) -> BeatActivation {
        BeatActivation::new(BeatNetEnsemble { nets: vec![w] })
    }

    fn small() -> BeatTrainConfig {
        BeatTrainConfig {
            channels: 6,
            dilations: vec![1, 2, 4],
            batch: 4,
            sequence: 256,
            steps: 150,
            learning_rate: 1e-2,
            ..BeatTrainConfig::default()
        }
    }

    #[test]
    fn exported_weights_stream_exactly_what_burn_computes() {
        let c = small();
        let device = cpu_device();
        let net = BeatNet::new(&c, &mut Rng::new(5), &device);
        let (mean, std) = (vec![0.5; I], vec![2.0; I]);
        let w = net.export(&c, &mean, &std);
        let t = 60;
        let mut rng = Rng::new(7);
        let raw: Vec<f32> = (0..t * I).map(|_| rng.normal() + 0.5).collect();
        let mut x = vec![0.0f32; I * t];
        for k in 0..t {
            for j in 0..I {
                x[j * t + k] = (raw[k * I + j] - 0.5) / 2.0;
            }
        }
        let logits = values(net.forward(Tensor::from_data(TensorData::new(x, [1, I, t]), &device)));
        let mut stream = streaming(w);
        for k in 0..t {
            let input: [f32; I] = raw[k * I..(k + 1) * I].try_into().unwrap();
            let got = stream.process(&input);
            let want = 1.0 / (1.0 + (-logits[k]).exp());
            assert!((got - want).abs() < 1e-4, "frame {k}: {got} vs {want}");
        }
    }

    #[test]
    fn training_learns_a_beat_marked_in_one_input() {
        // On one thread: the backend's parallel sums add in an order that depends on how the
        // work was stolen, so on a loaded machine the same seed trained another network (one
        // run in four ended with the beats at 0.26).
        rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap()
            .install(learns_a_beat_marked_in_one_input);
    }

    fn learns_a_beat_marked_in_one_input() {
        // Input 3 carries a spike on every beat (period 40 hops) among noise on all inputs.
        let mut rng = Rng::new(3);
        let mut song = |frames: usize, phase: usize| {
            let mut inputs = vec![0.0f32; frames * I];
            let mut beats = Vec::new();
            for k in 0..frames {
                for j in 0..I {
                    inputs[k * I + j] = rng.uniform() as f32;
                }
                if k % 40 == phase {
                    inputs[k * I + 3] += 3.0;
                    beats.push(k as f64);
                }
            }
            BeatSong {
                targets: BeatSong::targets_from_beats(&beats, frames, 1.0),
                inputs,
            }
        };
        let train = vec![SongPool {
            songs: (0..6).map(|i| song(1000, i * 5)).collect(),
            share: 1.0,
        }];
        let valid = vec![song(800, 17)];
        let mut first = None;
        let mut last = None;
        let w = train_beat_activation(&train, &valid, &small(), 10, |_, _, v| {
            if let Some(v) = v {
                first.get_or_insert(v);
                last = Some(v);
            }
        });
        let (first, last) = (first.unwrap(), last.unwrap());
        assert!(last < 0.8 * first, "validation loss {first} -> {last}");
        // The streaming network fires on the validation song's beats and not between them.
        let mut net = streaming(w);
        let (mut on, mut off) = (Vec::new(), Vec::new());
        for k in 0..valid[0].frames() {
            let input: [f32; I] = valid[0].inputs[k * I..(k + 1) * I].try_into().unwrap();
            let a = net.process(&input);
            if k % 40 == 17 {
                on.push(a);
            } else if valid[0].targets[k] == 0.0 {
                off.push(a);
            }
        }
        let mean = |v: &[f32]| v.iter().sum::<f32>() / v.len() as f32;
        assert!(
            mean(&on) > 0.5 && mean(&off) < 0.1,
            "on {} off {}",
            mean(&on),
            mean(&off)
        );
    }
}
