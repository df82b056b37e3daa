//! Learned causal beat activation: a small dilated causal convolution network (a temporal
//! convolutional network) that reads grouped onset flux and spectral levels and says, at every
//! hop, how likely that hop is a beat. It looks at the past only (about 3 s of it), so it runs
//! live; the beat tracker uses it as a second observation beside the raw onset strength.
//!
//! The network is trained with burn by `danced-train beats` on rendered songs with exact beats
//! (`../shared/tools/synth_beats.py`, seeds from 1000 up); its weights ship inside the binary.

use crate::DspError;
use crate::net_file::{NetFileReader, NetFileWriter};
use crate::onset::{FLUX_GROUPS, OnsetDetector};

/// Inputs per hop: the onset flux of each group of bands relative to its recent mean,
/// `ln(1 + flux / mean)`. Relative flux does not depend on the level or the timbre of a
/// recording, which keeps a network trained on rendered songs usable on real ones (with the
/// bands' absolute levels as further inputs it fitted the rendered songs better and real
/// ballroom recordings worse).
pub const BEAT_INPUT_DIM: usize = FLUX_GROUPS;
/// Time constant of the flux average the inputs are taken against, seconds.
const MEAN_SECONDS: f64 = 3.0;
/// Floor of the flux average, so silence does not turn faint noise into strong inputs.
const MEAN_FLOOR: f32 = 1e-2;
/// Magic bytes of a beat activation weight file.
const MAGIC: &[u8; 4] = b"DNBA";
/// Version of the weight file layout.
const VERSION: u32 = 1;

/// Builds the network's input vector from the onset detector, one hop at a time.
#[derive(Clone, Debug)]
pub struct BeatInput {
    flux_mean: [f32; FLUX_GROUPS],
    alpha: f32,
}

impl BeatInput {
    /// An input builder for hops at `frame_rate` per second.
    pub fn new(frame_rate: f64) -> Self {
        Self {
            flux_mean: [0.0; FLUX_GROUPS],
            alpha: (1.0 / (MEAN_SECONDS * frame_rate)) as f32,
        }
    }

    /// Writes this hop's [`BEAT_INPUT_DIM`] inputs into `out` from the detector's last frame.
    pub fn process(&mut self, detector: &OnsetDetector, out: &mut [f32; BEAT_INPUT_DIM]) {
        for ((mean, &f), o) in self
            .flux_mean
            .iter_mut()
            .zip(detector.group_flux())
            .zip(out.iter_mut())
        {
            let f = if f.is_finite() { f.max(0.0) } else { 0.0 };
            *mean += self.alpha * (f - *mean);
            *o = (f / (*mean + MEAN_FLOOR)).ln_1p();
        }
    }
}

/// What a beat activation weight file is called in errors.
const KIND: &str = "beat activation";

/// Weights of the beat activation network.
#[derive(Clone, Debug, PartialEq)]
pub struct BeatNetWeights {
    /// Channels of every hidden layer.
    pub channels: usize,
    /// Kernel size of the dilated convolutions.
    pub kernel: usize,
    /// Dilation of each convolution layer.
    pub dilations: Vec<usize>,
    /// Mean of each input over the training data.
    pub input_mean: Vec<f32>,
    /// Standard deviation of each input over the training data.
    pub input_std: Vec<f32>,
    /// Input projection `[channels][BEAT_INPUT_DIM]`.
    pub input_weight: Vec<f32>,
    /// Input projection bias `[channels]`.
    pub input_bias: Vec<f32>,
    /// Convolution weights, per layer `[channels][channels][kernel]`.
    pub conv_weight: Vec<Vec<f32>>,
    /// Convolution biases, per layer `[channels]`.
    pub conv_bias: Vec<Vec<f32>>,
    /// Output projection `[channels]`.
    pub output_weight: Vec<f32>,
    /// Output bias.
    pub output_bias: f32,
}

impl BeatNetWeights {
    /// Frames of past the network sees (its receptive field).
    pub fn receptive_field(&self) -> usize {
        1 + self
            .dilations
            .iter()
            .map(|d| d * (self.kernel - 1))
            .sum::<usize>()
    }

    /// Appends this network's shape and weights.
    fn write_to(&self, w: &mut NetFileWriter) {
        for v in [
            BEAT_INPUT_DIM,
            self.channels,
            self.kernel,
            self.dilations.len(),
        ] {
            w.u32(v);
        }
        for &d in &self.dilations {
            w.u32(d);
        }
        w.floats(&self.input_mean);
        w.floats(&self.input_std);
        w.floats(&self.input_weight);
        w.floats(&self.input_bias);
        for (k, bias) in self.conv_weight.iter().zip(&self.conv_bias) {
            w.floats(k);
            w.floats(bias);
        }
        w.floats(&self.output_weight);
        w.floats(&[self.output_bias]);
    }

    /// Reads one network written by [`Self::write_to`]; checks every size and value.
    fn read_from(r: &mut NetFileReader) -> Result<Self, DspError> {
        let inputs = r.u32()?;
        if inputs != BEAT_INPUT_DIM {
            return Err(r.malformed(format!(
                "{inputs} inputs, this build computes {BEAT_INPUT_DIM}"
            )));
        }
        let channels = r.u32_in(1..=256, "channel count")?;
        let kernel = r.u32_in(1..=16, "kernel size")?;
        let layers = r.u32_in(0..=32, "layer count")?;
        let mut dilations = Vec::with_capacity(layers);
        for _ in 0..layers {
            dilations.push(r.u32_in(1..=1024, "dilation")?);
        }
        let (c, k, i) = (channels, kernel, inputs);
        let input_mean = r.floats(i)?;
        let input_std = r.floats(i)?;
        if input_std.iter().any(|&s| s <= 0.0) {
            return Err(r.malformed("input std ≤ 0"));
        }
        let input_weight = r.floats(c * i)?;
        let input_bias = r.floats(c)?;
        let (mut conv_weight, mut conv_bias) = (Vec::new(), Vec::new());
        for _ in 0..layers {
            conv_weight.push(r.floats(c * c * k)?);
            conv_bias.push(r.floats(c)?);
        }
        let output_weight = r.floats(c)?;
        let output_bias = r.floats(1)?[0];
        Ok(Self {
            channels,
            kernel,
            dilations,
            input_mean,
            input_std,
            input_weight,
            input_bias,
            conv_weight,
            conv_bias,
            output_weight,
            output_bias,
        })
    }
}

/// Several independently trained networks whose activations are averaged (an ensemble is
/// steadier on music unlike the training songs than any one of its members).
#[derive(Clone, Debug, PartialEq)]
pub struct BeatNetEnsemble {
    /// The member networks.
    pub nets: Vec<BeatNetWeights>,
}

impl BeatNetEnsemble {
    /// The networks shipped with danced (trained on rendered songs, see the module docs).
    pub fn builtin() -> Self {
        Self::from_bytes(include_bytes!("../assets/beat_activation.dnba"))
            .expect("the shipped beat activation weights parse (checked by a test)")
    }

    /// Serialises the ensemble (little-endian, versioned).
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut w = NetFileWriter::new(MAGIC, VERSION);
        w.u32(self.nets.len());
        for net in &self.nets {
            net.write_to(&mut w);
        }
        w.into_bytes()
    }

    /// Parses an ensemble written by [`Self::to_bytes`]; checks every size and value.
    pub fn from_bytes(bytes: &[u8]) -> Result<Self, DspError> {
        let mut r = NetFileReader::open(bytes, KIND, MAGIC, VERSION)?;
        let count = r.u32_in(1..=16, "network count")?;
        let mut nets = Vec::with_capacity(count);
        for _ in 0..count {
            nets.push(BeatNetWeights::read_from(&mut r)?);
        }
        r.finish()?;
        Ok(Self { nets })
    }

    /// Hops of past the widest member sees.
    pub fn receptive_field(&self) -> usize {
        self.nets
            .iter()
            .map(BeatNetWeights::receptive_field)
            .max()
            .unwrap_or(1)
    }
}

/// One dilated causal convolution with its input history.
#[derive(Clone, Debug)]
struct CausalLayer {
    dilation: usize,
    span: usize,
    /// The layer's weights reordered `[tap][out][in]`, so each output is a contiguous dot product.
    taps: Vec<f32>,
    history: Vec<f32>,
    pos: usize,
}

/// One network run one hop at a time.
#[derive(Clone, Debug)]
struct StreamingNet {
    weights: BeatNetWeights,
    layers: Vec<CausalLayer>,
    input: Vec<f32>,
    hidden: Vec<f32>,
    conv_out: Vec<f32>,
}

impl StreamingNet {
    fn new(weights: BeatNetWeights) -> Self {
        let c = weights.channels;
        let k = weights.kernel;
        let layers = weights
            .dilations
            .iter()
            .zip(&weights.conv_weight)
            .map(|(&d, w)| {
                let span = (k - 1) * d + 1;
                let mut taps = vec![0.0; k * c * c];
                for o in 0..c {
                    for i in 0..c {
                        for tap in 0..k {
                            taps[(tap * c + o) * c + i] = w[(o * c + i) * k + tap];
                        }
                    }
                }
                CausalLayer {
                    dilation: d,
                    span,
                    taps,
                    history: vec![0.0; span * c],
                    pos: 0,
                }
            })
            .collect();
        Self {
            layers,
            input: vec![0.0; BEAT_INPUT_DIM],
            hidden: vec![0.0; c],
            conv_out: vec![0.0; c],
            weights,
        }
    }

    fn process(&mut self, input: &[f32; BEAT_INPUT_DIM]) -> f32 {
        let w = &self.weights;
        let c = w.channels;
        let k = w.kernel;
        for (j, x) in self.input.iter_mut().enumerate() {
            *x = (input[j] - w.input_mean[j]) / w.input_std[j];
        }
        for (o, h) in self.hidden.iter_mut().enumerate() {
            let row = &w.input_weight[o * BEAT_INPUT_DIM..(o + 1) * BEAT_INPUT_DIM];
            let z = w.input_bias[o] + row.iter().zip(&self.input).map(|(a, b)| a * b).sum::<f32>();
            *h = z.max(0.0);
        }
        for (l, layer) in self.layers.iter_mut().enumerate() {
            layer.history[layer.pos * c..(layer.pos + 1) * c].copy_from_slice(&self.hidden);
            self.conv_out.copy_from_slice(&w.conv_bias[l]);
            for tap in 0..k {
                let back = (k - 1 - tap) * layer.dilation;
                let slot = (layer.pos + layer.span - back) % layer.span;
                let past = &layer.history[slot * c..(slot + 1) * c];
                let rows = &layer.taps[tap * c * c..(tap + 1) * c * c];
                for (out, row) in self.conv_out.iter_mut().zip(rows.chunks_exact(c)) {
                    *out += row.iter().zip(past).map(|(a, b)| a * b).sum::<f32>();
                }
            }
            self.conv_out.iter_mut().for_each(|z| *z = z.max(0.0));
            layer.pos = (layer.pos + 1) % layer.span;
            for (h, y) in self.hidden.iter_mut().zip(&self.conv_out) {
                *h += y;
            }
        }
        let z = w.output_bias
            + w.output_weight
                .iter()
                .zip(&self.hidden)
                .map(|(a, b)| a * b)
                .sum::<f32>();
        let a = 1.0 / (1.0 + (-z).exp());
        if a.is_finite() { a } else { 0.0 }
    }
}

/// The ensemble run one hop at a time: allocates in [`BeatActivation::new`] only.
#[derive(Clone, Debug)]
pub struct BeatActivation {
    nets: Vec<StreamingNet>,
}

impl BeatActivation {
    /// Streaming networks with these weights and an empty (silent) past.
    pub fn new(ensemble: BeatNetEnsemble) -> Self {
        Self {
            nets: ensemble.nets.into_iter().map(StreamingNet::new).collect(),
        }
    }

    /// Consumes one hop's inputs; returns the members' mean beat activation in [0, 1].
    pub fn process(&mut self, input: &[f32; BEAT_INPUT_DIM]) -> f32 {
        let sum: f32 = self.nets.iter_mut().map(|n| n.process(input)).sum();
        sum / self.nets.len().max(1) as f32
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One channel, kernel 2, dilation 2: the hidden value is input 0 (its mean 1 and std 2
    /// removed), and the layer adds relu(0.5·h[t−2] + 1·h[t]).
    fn tiny() -> BeatNetWeights {
        let mut input_weight = vec![0.0; BEAT_INPUT_DIM];
        input_weight[0] = 1.0;
        BeatNetWeights {
            channels: 1,
            kernel: 2,
            dilations: vec![2],
            input_mean: vec![1.0; BEAT_INPUT_DIM],
            input_std: vec![2.0; BEAT_INPUT_DIM],
            input_weight,
            input_bias: vec![0.0],
            conv_weight: vec![vec![0.5, 1.0]],
            conv_bias: vec![vec![0.0]],
            output_weight: vec![1.0],
            output_bias: -1.0,
        }
    }

    #[test]
    fn streaming_network_matches_hand_computation() {
        let mut net = BeatActivation::new(BeatNetEnsemble { nets: vec![tiny()] });
        let xs = [3.0f32, 5.0, 1.0, 7.0, 9.0];
        let h: Vec<f32> = xs.iter().map(|x| ((x - 1.0) / 2.0).max(0.0)).collect();
        for (t, &x) in xs.iter().enumerate() {
            let mut input = [0.0; BEAT_INPUT_DIM];
            input[0] = x;
            let past = if t >= 2 { h[t - 2] } else { 0.0 };
            let z = h[t] + (0.5 * past + h[t]).max(0.0) - 1.0;
            let expected = 1.0 / (1.0 + (-z).exp());
            let got = net.process(&input);
            assert!((got - expected).abs() < 1e-6, "t={t}: {got} vs {expected}");
        }
        assert_eq!(tiny().receptive_field(), 3);
    }

    #[test]
    fn weights_round_trip_and_bad_files_are_named_errors() {
        let mut other = tiny();
        other.output_bias = 0.5;
        let w = BeatNetEnsemble {
            nets: vec![tiny(), other],
        };
        let bytes = w.to_bytes();
        assert_eq!(BeatNetEnsemble::from_bytes(&bytes).unwrap(), w);
        assert!(matches!(
            BeatNetEnsemble::from_bytes(b"XXXX"),
            Err(DspError::NetFileMagic { .. })
        ));
        let mut v2 = bytes.clone();
        v2[4] = 9;
        assert!(matches!(
            BeatNetEnsemble::from_bytes(&v2),
            Err(DspError::NetFileVersion { found: 9, .. })
        ));
        let mut extra = bytes.clone();
        extra.push(0);
        assert!(matches!(
            BeatNetEnsemble::from_bytes(&extra),
            Err(DspError::NetFileMalformed { .. })
        ));
        for cut in [6, 10, 20, bytes.len() / 2, bytes.len() - 1] {
            assert!(
                matches!(
                    BeatNetEnsemble::from_bytes(&bytes[..cut]),
                    Err(DspError::NetFileMalformed { .. })
                ),
                "cut at {cut}"
            );
        }
        let mut nan = bytes.clone();
        let last = nan.len() - 4;
        nan[last..].copy_from_slice(&f32::NAN.to_le_bytes());
        assert!(matches!(
            BeatNetEnsemble::from_bytes(&nan),
            Err(DspError::NetFileMalformed { .. })
        ));
    }

    #[test]
    fn shipped_weights_parse_and_give_finite_activations() {
        let w = BeatNetEnsemble::builtin();
        assert!(w.receptive_field() >= 1 && !w.nets.is_empty());
        let mut net = BeatActivation::new(w);
        for t in 0..500 {
            let mut input = [0.0; BEAT_INPUT_DIM];
            input
                .iter_mut()
                .for_each(|x| *x = ((t * 7) % 13) as f32 * 0.3);
            let a = net.process(&input);
            assert!(a.is_finite() && (0.0..=1.0).contains(&a), "{a}");
        }
    }
}
