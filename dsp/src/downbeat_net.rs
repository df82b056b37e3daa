//! Learned bar position: a small network that reads the features of the last
//! [`BAR_WINDOW`] tracked beats ([`crate::bar_features`]) and says where in a 4/4 or a 3/4 bar
//! the newest of them stands ([`crate::bar_class`]: 4/4 or 3/4, tracked at the counted beat, twice it
//! or half of it). It runs once per beat, so it costs nothing beside the per-hop
//! analysis.
//!
//! Each feature but the tempo is standardised over the window (its mean and spread across
//! those beats removed), so what the network reads is the pattern of accents and chord changes
//! from beat to beat, not the level or the timbre of a recording. It is trained with burn by
//! `danced-train downbeats` on rendered songs (`../shared/tools/synth_beats.py`, seeds from
//! 1000 up), from the features the live analysis computed at the beats it tracked; its weights
//! ship inside the binary.

use crate::DspError;
use crate::bar_class::CLASS_COUNT;
use crate::bar_features::{BAR_FEATURE_DIM, TEMPO_FEATURE};
use crate::net_file::{NetFileReader, NetFileWriter};

/// Beats the network reads, the newest last: three bars of 4/4, four of 3/4.
pub const BAR_WINDOW: usize = 12;
/// Inputs of the network.
pub const DOWNBEAT_INPUT_DIM: usize = BAR_WINDOW * BAR_FEATURE_DIM;
/// Floor of a feature's spread over the window, so a steady feature does not turn its noise
/// into strong inputs.
const STD_FLOOR: f32 = 0.1;
/// Magic bytes of a downbeat weight file.
const MAGIC: &[u8; 4] = b"DNDB";
/// Version of the weight file layout.
const VERSION: u32 = 1;
/// What a downbeat weight file is called in errors.
const KIND: &str = "downbeat";
/// Widest hidden layer a file may declare.
const MAX_WIDTH: usize = 1024;

/// Writes the network's inputs for a window of beat features (oldest first, exactly
/// [`BAR_WINDOW`] of them, read from the ring `window` starting at `oldest`).
pub fn window_inputs(
    window: &[[f32; BAR_FEATURE_DIM]; BAR_WINDOW],
    oldest: usize,
    out: &mut [f32; DOWNBEAT_INPUT_DIM],
) {
    let n = BAR_WINDOW as f32;
    for j in 0..BAR_FEATURE_DIM {
        if j == TEMPO_FEATURE {
            for k in 0..BAR_WINDOW {
                out[k * BAR_FEATURE_DIM + j] = window[(oldest + k) % BAR_WINDOW][j];
            }
            continue;
        }
        let mean = window.iter().map(|b| b[j]).sum::<f32>() / n;
        let var = window.iter().map(|b| (b[j] - mean).powi(2)).sum::<f32>() / n;
        let scale = 1.0 / var.sqrt().max(STD_FLOOR);
        for k in 0..BAR_WINDOW {
            let x = window[(oldest + k) % BAR_WINDOW][j];
            out[k * BAR_FEATURE_DIM + j] = (x - mean) * scale;
        }
    }
}

/// One fully connected layer, `y = W·x + b` with `W` stored `[outputs][inputs]`.
#[derive(Clone, Debug, PartialEq)]
pub struct DenseWeights {
    /// Inputs.
    pub inputs: usize,
    /// Outputs.
    pub outputs: usize,
    /// Weights, row-major `[outputs][inputs]`.
    pub weight: Vec<f32>,
    /// Biases `[outputs]`.
    pub bias: Vec<f32>,
}

/// One network: dense layers with ReLU between them, a softmax over [`CLASS_COUNT`] at the end.
#[derive(Clone, Debug, PartialEq)]
pub struct DownbeatNetWeights {
    /// The layers, input first.
    pub layers: Vec<DenseWeights>,
}

/// Several networks whose class probabilities are averaged, and how often each class was
/// seen in training (the bar pointer divides it out).
#[derive(Clone, Debug, PartialEq)]
pub struct DownbeatNetEnsemble {
    /// The member networks.
    pub nets: Vec<DownbeatNetWeights>,
    /// Frequency of each class in the training beats, summing to 1.
    pub class_prior: [f32; CLASS_COUNT],
}

impl DownbeatNetEnsemble {
    /// The networks shipped with danced (trained on rendered songs, see the module docs).
    pub fn builtin() -> Self {
        Self::from_bytes(include_bytes!("../assets/downbeat.dndb"))
            .expect("the shipped downbeat weights parse (checked by a test)")
    }

    /// Serialises the ensemble (little-endian, versioned).
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut w = NetFileWriter::new(MAGIC, VERSION);
        w.floats(&self.class_prior);
        w.u32(self.nets.len());
        for net in &self.nets {
            w.u32(net.layers.len());
            for l in &net.layers {
                w.u32(l.inputs);
                w.u32(l.outputs);
                w.floats(&l.weight);
                w.floats(&l.bias);
            }
        }
        w.into_bytes()
    }

    /// Parses an ensemble written by [`Self::to_bytes`]; checks every size and value.
    pub fn from_bytes(bytes: &[u8]) -> Result<Self, DspError> {
        let mut r = NetFileReader::open(bytes, KIND, MAGIC, VERSION)?;
        let prior = r.floats(CLASS_COUNT)?;
        if prior.iter().any(|&p| p <= 0.0) {
            return Err(r.malformed("class prior ≤ 0"));
        }
        let mut class_prior = [0.0; CLASS_COUNT];
        class_prior.copy_from_slice(&prior);
        let count = r.u32_in(1..=16, "network count")?;
        let mut nets = Vec::with_capacity(count);
        for _ in 0..count {
            let n = r.u32_in(1..=8, "layer count")?;
            let mut layers: Vec<DenseWeights> = Vec::with_capacity(n);
            for l in 0..n {
                let inputs = r.u32_in(1..=DOWNBEAT_INPUT_DIM.max(MAX_WIDTH), "layer inputs")?;
                let outputs = r.u32_in(1..=MAX_WIDTH, "layer outputs")?;
                let expected_in = layers.last().map_or(DOWNBEAT_INPUT_DIM, |p| p.outputs);
                if inputs != expected_in || (l + 1 == n && outputs != CLASS_COUNT) {
                    return Err(r.malformed(format!(
                        "layer {l} maps {inputs} to {outputs} values; expected {expected_in} in{}",
                        if l + 1 == n {
                            format!(" and {CLASS_COUNT} out")
                        } else {
                            String::new()
                        }
                    )));
                }
                let weight = r.floats(inputs * outputs)?;
                let bias = r.floats(outputs)?;
                layers.push(DenseWeights {
                    inputs,
                    outputs,
                    weight,
                    bias,
                });
            }
            nets.push(DownbeatNetWeights { layers });
        }
        r.finish()?;
        Ok(Self { nets, class_prior })
    }
}

/// The features of the last [`BAR_WINDOW`] beats the network reads, as live and in training:
/// a ring that starts afresh, as at a song's start, when the tracked tempo changes metrical
/// level (its beats would be another kind of beat).
#[derive(Clone, Debug)]
pub struct BeatWindow {
    beats: [[f32; BAR_FEATURE_DIM]; BAR_WINDOW],
    /// Where the next beat goes; the oldest beat is here too.
    next: usize,
    /// Tempo change between consecutive beats beyond which the level changed, octaves
    /// (infinite: never).
    jump_octaves: f32,
    /// Tempo feature of the newest beat.
    last_tempo: Option<f32>,
    restarted: bool,
}

impl BeatWindow {
    /// An empty window that restarts when the tempo changes by more than `tempo_jump` times
    /// (either way) from one beat to the next; never when `tempo_jump` ≤ 1.
    pub fn new(tempo_jump: f32) -> Self {
        Self {
            beats: [[0.0; BAR_FEATURE_DIM]; BAR_WINDOW],
            next: 0,
            jump_octaves: if tempo_jump > 1.0 {
                tempo_jump.log2()
            } else {
                f32::INFINITY
            },
            last_tempo: None,
            restarted: false,
        }
    }

    /// Adds the features of the newest beat, first emptying the window if the tempo changed
    /// level since the beat before.
    pub fn push(&mut self, features: &[f32; BAR_FEATURE_DIM]) {
        let tempo = features[TEMPO_FEATURE];
        self.restarted = self
            .last_tempo
            .is_some_and(|last| (tempo - last).abs() > self.jump_octaves);
        if self.restarted {
            self.beats = [[0.0; BAR_FEATURE_DIM]; BAR_WINDOW];
            self.next = 0;
        }
        self.last_tempo = Some(tempo);
        self.beats[self.next] = *features;
        self.next = (self.next + 1) % BAR_WINDOW;
    }

    /// Whether the last push emptied the window first.
    pub fn restarted(&self) -> bool {
        self.restarted
    }

    /// Writes the network's inputs for the window ([`window_inputs`]).
    pub fn inputs(&self, out: &mut [f32; DOWNBEAT_INPUT_DIM]) {
        window_inputs(&self.beats, self.next, out);
    }
}

/// The ensemble run once per beat: allocates in [`DownbeatClassifier::new`] only.
#[derive(Clone, Debug)]
pub struct DownbeatClassifier {
    ensemble: DownbeatNetEnsemble,
    window: BeatWindow,
    input: [f32; DOWNBEAT_INPUT_DIM],
    /// Two activation buffers as wide as the widest layer.
    a: Vec<f32>,
    b: Vec<f32>,
    probabilities: [f32; CLASS_COUNT],
}

impl DownbeatClassifier {
    /// A classifier with these weights and an empty past, whose window restarts at a tempo
    /// change of more than `tempo_jump` times ([`BeatWindow::new`]).
    pub fn new(ensemble: DownbeatNetEnsemble, tempo_jump: f32) -> Self {
        let width = ensemble
            .nets
            .iter()
            .flat_map(|n| n.layers.iter().map(|l| l.outputs.max(l.inputs)))
            .max()
            .unwrap_or(DOWNBEAT_INPUT_DIM);
        Self {
            ensemble,
            window: BeatWindow::new(tempo_jump),
            input: [0.0; DOWNBEAT_INPUT_DIM],
            a: vec![0.0; width],
            b: vec![0.0; width],
            probabilities: [0.0; CLASS_COUNT],
        }
    }

    /// How often each class was seen in training.
    pub fn class_prior(&self) -> &[f32; CLASS_COUNT] {
        &self.ensemble.class_prior
    }

    /// Adds the features of the newest beat; returns the probability of each bar position
    /// for it (averaged over the ensemble).
    pub fn push(&mut self, features: &[f32; BAR_FEATURE_DIM]) -> &[f32; CLASS_COUNT] {
        self.window.push(features);
        self.window.inputs(&mut self.input);
        self.classify_input()
    }

    /// Whether the last push began a new window (the tracked tempo changed level).
    pub fn restarted(&self) -> bool {
        self.window.restarted()
    }

    /// The probability of each bar position for ready-made network inputs (as
    /// [`window_inputs`] writes them), averaged over the ensemble; the beat window is untouched.
    pub fn classify(&mut self, input: &[f32; DOWNBEAT_INPUT_DIM]) -> &[f32; CLASS_COUNT] {
        self.input = *input;
        self.classify_input()
    }

    fn classify_input(&mut self) -> &[f32; CLASS_COUNT] {
        self.probabilities = [0.0; CLASS_COUNT];
        let members = self.ensemble.nets.len().max(1) as f32;
        for net in &self.ensemble.nets {
            self.a[..DOWNBEAT_INPUT_DIM].copy_from_slice(&self.input);
            let last = net.layers.len() - 1;
            for (i, l) in net.layers.iter().enumerate() {
                for (o, y) in self.b[..l.outputs].iter_mut().enumerate() {
                    let row = &l.weight[o * l.inputs..(o + 1) * l.inputs];
                    let z = l.bias[o]
                        + row
                            .iter()
                            .zip(&self.a[..l.inputs])
                            .map(|(w, x)| w * x)
                            .sum::<f32>();
                    *y = if i < last { z.max(0.0) } else { z };
                }
                std::mem::swap(&mut self.a, &mut self.b);
            }
            let logits = &self.a[..CLASS_COUNT];
            let top = logits.iter().fold(f32::MIN, |m, &z| m.max(z));
            let sum: f32 = logits.iter().map(|z| (z - top).exp()).sum();
            for (p, z) in self.probabilities.iter_mut().zip(logits) {
                let q = (z - top).exp() / sum;
                *p += if q.is_finite() { q } else { 0.0 } / members;
            }
        }
        &self.probabilities
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One linear layer whose class-0 logit is input 0 of the newest beat.
    fn linear() -> DownbeatNetEnsemble {
        let mut weight = vec![0.0; CLASS_COUNT * DOWNBEAT_INPUT_DIM];
        weight[(BAR_WINDOW - 1) * BAR_FEATURE_DIM] = 1.0;
        DownbeatNetEnsemble {
            nets: vec![DownbeatNetWeights {
                layers: vec![DenseWeights {
                    inputs: DOWNBEAT_INPUT_DIM,
                    outputs: CLASS_COUNT,
                    weight,
                    bias: vec![0.0; CLASS_COUNT],
                }],
            }],
            class_prior: [1.0 / CLASS_COUNT as f32; CLASS_COUNT],
        }
    }

    #[test]
    fn window_inputs_standardise_each_feature_over_the_window() {
        let mut window = [[0.0; BAR_FEATURE_DIM]; BAR_WINDOW];
        for (k, b) in window.iter_mut().enumerate() {
            b[0] = if k % 4 == 0 { 5.0 } else { 1.0 };
            b[1] = 2.0;
        }
        let mut out = [0.0; DOWNBEAT_INPUT_DIM];
        window_inputs(&window, 0, &mut out);
        // Feature 0: mean 2, std √3; a steady feature is all zeros.
        assert!((out[0] - 3.0 / 3f32.sqrt()).abs() < 1e-5);
        assert!((out[BAR_FEATURE_DIM] + 1.0 / 3f32.sqrt()).abs() < 1e-5);
        assert!(
            out.iter()
                .skip(1)
                .step_by(BAR_FEATURE_DIM)
                .all(|&x| x == 0.0)
        );
        // Read from the ring starting at 1, the first input is beat 1's.
        window_inputs(&window, 1, &mut out);
        assert!((out[0] + 1.0 / 3f32.sqrt()).abs() < 1e-5);
        // The tempo passes as it is.
        window[3][TEMPO_FEATURE] = 0.5;
        window_inputs(&window, 0, &mut out);
        assert_eq!(out[3 * BAR_FEATURE_DIM + TEMPO_FEATURE], 0.5);
    }

    #[test]
    fn the_window_restarts_at_a_change_of_level_only() {
        // Tempo features in octaves from 120 BPM.
        let beat = |bpm: f32| {
            let mut f = [0.5; BAR_FEATURE_DIM];
            f[TEMPO_FEATURE] = (bpm / 120.0).log2();
            f
        };
        let restarts = |tempo_jump: f32, bpms: &[f32]| -> Vec<bool> {
            let mut w = BeatWindow::new(tempo_jump);
            bpms.iter()
                .map(|&b| {
                    w.push(&beat(b));
                    w.restarted()
                })
                .collect()
        };
        // Double and half time, and a 3/4 bar tracked two beats to the bar, restart it; a
        // tempo ramp and the first beat do not; 0 turns it off.
        let bpms = [120.0, 126.0, 252.0, 126.0, 109.0, 72.7, 74.0];
        assert_eq!(
            restarts(1.3, &bpms),
            [false, false, true, true, false, true, false]
        );
        assert!(restarts(0.0, &bpms).iter().all(|r| !r));
        // After a restart the window reads like a song that began at that beat.
        let mut jumped = BeatWindow::new(1.3);
        for b in [120.0, 120.0, 120.0, 240.0, 240.0] {
            jumped.push(&beat(b));
        }
        let mut fresh = BeatWindow::new(1.3);
        for b in [240.0, 240.0] {
            fresh.push(&beat(b));
        }
        let (mut a, mut b) = ([0.0; DOWNBEAT_INPUT_DIM], [0.0; DOWNBEAT_INPUT_DIM]);
        jumped.inputs(&mut a);
        fresh.inputs(&mut b);
        assert_eq!(a, b);
    }

    #[test]
    fn an_accent_on_the_newest_beat_raises_class_zero() {
        let mut c = DownbeatClassifier::new(linear(), 0.0);
        let mut f = [1.0; BAR_FEATURE_DIM];
        for _ in 0..BAR_WINDOW - 1 {
            c.push(&f);
        }
        f[0] = 4.0;
        let p = *c.push(&f);
        assert!((p.iter().sum::<f32>() - 1.0).abs() < 1e-5);
        assert!(p[0] > 0.5 && p[1..].iter().all(|&q| q < 0.1), "{p:?}");
    }

    #[test]
    fn weights_round_trip_and_bad_files_are_named_errors() {
        let w = linear();
        let bytes = w.to_bytes();
        assert_eq!(DownbeatNetEnsemble::from_bytes(&bytes).unwrap(), w);
        assert!(matches!(
            DownbeatNetEnsemble::from_bytes(b"DNBA\x01\0\0\0"),
            Err(DspError::NetFileMagic { .. })
        ));
        for cut in [6, 10, 40, bytes.len() / 2, bytes.len() - 1] {
            assert!(
                matches!(
                    DownbeatNetEnsemble::from_bytes(&bytes[..cut]),
                    Err(DspError::NetFileMalformed { .. })
                ),
                "cut at {cut}"
            );
        }
        let mut nan = bytes.clone();
        let last = nan.len() - 4;
        nan[last..].copy_from_slice(&f32::NAN.to_le_bytes());
        assert!(DownbeatNetEnsemble::from_bytes(&nan).is_err());
        // A last layer with the wrong number of classes is refused.
        let mut wrong = w.clone();
        wrong.nets[0].layers[0].outputs = 3;
        wrong.nets[0].layers[0]
            .weight
            .truncate(3 * DOWNBEAT_INPUT_DIM);
        wrong.nets[0].layers[0].bias.truncate(3);
        assert!(matches!(
            DownbeatNetEnsemble::from_bytes(&wrong.to_bytes()),
            Err(DspError::NetFileMalformed { .. })
        ));
    }

    #[test]
    fn shipped_weights_parse_and_give_probabilities() {
        let mut c = DownbeatClassifier::new(DownbeatNetEnsemble::builtin(), 0.0);
        for k in 0..40 {
            let mut f = [0.3; BAR_FEATURE_DIM];
            f[k % BAR_FEATURE_DIM] = (k % 4) as f32;
            let p = c.push(&f);
            assert!((p.iter().sum::<f32>() - 1.0).abs() < 1e-4, "{p:?}");
        }
    }
}
