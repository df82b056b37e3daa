//! Named weight tensors: the one representation shared by training (burn), live sampling
//! (plain Rust) and the model file.

use std::collections::BTreeMap;

use crate::ModelError;
use crate::neural::config::{FlowConfig, NetConfig};
use crate::neural::rng::Rng;

/// Name of the lowest value of every pose feature in the training data.
pub const POSE_MIN: &str = "range.pose_min";
/// Name of the highest value of every pose feature in the training data.
pub const POSE_MAX: &str = "range.pose_max";
/// Name of the seed clip's motion tensor.
pub const SEED_MOTION: &str = "seed.motion";
/// Name of the seed clip's music tensor.
pub const SEED_MUSIC: &str = "seed.music";
/// Name of the style embedding `[styles, d_model]` (one row per [`crate::style::DanceStyle`]).
pub const STYLE_EMBEDDING: &str = "embed.style";

/// A tensor's shape and row-major values.
#[derive(Clone, Debug, PartialEq)]
pub struct Tensor {
    /// Dimensions, outermost first.
    pub shape: Vec<usize>,
    /// Row-major values.
    pub data: Vec<f32>,
}

/// Weight tensors by name.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct NamedTensors {
    /// The tensors, in name order.
    pub map: BTreeMap<String, Tensor>,
}

impl NamedTensors {
    /// Adds or replaces a tensor.
    pub fn insert(&mut self, name: impl Into<String>, shape: &[usize], data: Vec<f32>) {
        debug_assert_eq!(shape.iter().product::<usize>(), data.len());
        self.map.insert(
            name.into(),
            Tensor {
                shape: shape.to_vec(),
                data,
            },
        );
    }

    /// The values of `name`, checked to have `shape` and finite values.
    pub fn get(&self, name: &str, shape: &[usize]) -> Result<&[f32], ModelError> {
        let t = self
            .map
            .get(name)
            .ok_or_else(|| ModelError::WeightMissing(name.into()))?;
        if t.shape != shape || t.data.len() != shape.iter().product::<usize>() {
            return Err(ModelError::WeightShape {
                name: name.into(),
                found: t.shape.clone(),
                expected: shape.to_vec(),
            });
        }
        if t.data.iter().any(|v| !v.is_finite()) {
            return Err(ModelError::WeightNotFinite(name.into()));
        }
        Ok(&t.data)
    }

    /// A permutation of `0..n` stored as floats under `name`.
    pub fn permutation(&self, name: &str, n: usize) -> Result<Vec<usize>, ModelError> {
        let raw = self.get(name, &[n])?;
        let mut seen = vec![false; n];
        let mut p = Vec::with_capacity(n);
        for &v in raw {
            let i = v as usize;
            if v < 0.0 || v.fract() != 0.0 || i >= n || seen[i] {
                return Err(ModelError::WeightNotPermutation(name.into()));
            }
            seen[i] = true;
            p.push(i);
        }
        Ok(p)
    }

    /// Total number of values.
    pub fn parameter_count(&self) -> usize {
        self.map.values().map(|t| t.data.len()).sum()
    }

    /// Adds Gaussian noise of standard deviation `scale` to every non-permutation tensor
    /// (tests use it to move away from the identity-like initialisation).
    pub fn perturb(&mut self, seed: u64, scale: f32) {
        let mut rng = Rng::new(seed);
        for (name, t) in self.map.iter_mut() {
            if name.ends_with(".perm") || name.starts_with("norm.") {
                continue;
            }
            for v in t.data.iter_mut() {
                *v += scale * rng.normal();
            }
        }
    }
}

/// A dense layer `[inputs, outputs]` with Glorot-uniform weights and zero bias.
fn dense(
    t: &mut NamedTensors,
    rng: &mut Rng,
    name: &str,
    inputs: usize,
    outputs: usize,
    zero: bool,
) {
    let limit = (6.0 / (inputs + outputs) as f64).sqrt();
    let w = (0..inputs * outputs)
        .map(|_| {
            if zero {
                0.0
            } else {
                ((rng.uniform() * 2.0 - 1.0) * limit) as f32
            }
        })
        .collect();
    t.insert(format!("{name}.w"), &[inputs, outputs], w);
    t.insert(format!("{name}.b"), &[outputs], vec![0.0; outputs]);
}

fn layer_norm(t: &mut NamedTensors, name: &str, dim: usize) {
    t.insert(format!("{name}.g"), &[dim], vec![1.0; dim]);
    t.insert(format!("{name}.b"), &[dim], vec![0.0; dim]);
}

/// Initial flow weights under `prefix`: actnorm identity (data-dependent init comes later),
/// each invertible linear a random permutation (L = I, U = I), and couplings whose output layer
/// is zero so every step starts as a fixed scaling.
pub fn init_flow(t: &mut NamedTensors, rng: &mut Rng, prefix: &str, c: &FlowConfig) {
    let d = c.dim;
    for k in 0..c.steps {
        let p = format!("{prefix}.{k}");
        t.insert(format!("{p}.an_bias"), &[d], vec![0.0; d]);
        t.insert(format!("{p}.an_logs"), &[d], vec![0.0; d]);
        let perm = rng.permutation(d).into_iter().map(|i| i as f32).collect();
        t.insert(format!("{p}.perm"), &[d], perm);
        t.insert(format!("{p}.lower"), &[d, d], vec![0.0; d * d]);
        t.insert(format!("{p}.upper"), &[d, d], vec![0.0; d * d]);
        t.insert(format!("{p}.log_s"), &[d], vec![0.0; d]);
        dense(
            t,
            rng,
            &format!("{p}.c1"),
            c.half() + c.context,
            c.hidden,
            false,
        );
        dense(t, rng, &format!("{p}.c2"), c.hidden, 2 * c.rest(), true);
    }
}

/// Initial weights of the whole network (normalisation statistics start as identity).
pub fn init_net(c: &NetConfig, seed: u64) -> NamedTensors {
    use crate::motion::MOTION_FEATURE_DIM as P;
    use dsp::feature::FEATURE_DIM as M;
    let mut rng = Rng::new(seed);
    let mut t = NamedTensors::default();
    t.insert("norm.pose_mean", &[P], vec![0.0; P]);
    t.insert("norm.pose_std", &[P], vec![1.0; P]);
    t.insert("norm.music_mean", &[M], vec![0.0; M]);
    t.insert("norm.music_std", &[M], vec![1.0; M]);
    t.insert(POSE_MIN, &[P], vec![-1e6; P]);
    t.insert(POSE_MAX, &[P], vec![1e6; P]);
    t.insert(SEED_MOTION, &[c.window, P], vec![0.0; c.window * P]);
    t.insert(SEED_MUSIC, &[c.window, M], vec![0.0; c.window * M]);
    let d = c.d_model;
    dense(&mut t, &mut rng, "embed", c.token_dim(), d, false);
    t.insert("embed.none", &[d], vec![0.0; d]);
    if c.styles > 0 {
        t.insert(STYLE_EMBEDDING, &[c.styles, d], vec![0.0; c.styles * d]);
    }
    for l in 0..c.layers {
        let p = format!("layer{l}");
        layer_norm(&mut t, &format!("{p}.ln1"), d);
        dense(&mut t, &mut rng, &format!("{p}.qkv"), d, 3 * d, false);
        dense(&mut t, &mut rng, &format!("{p}.out"), d, d, false);
        layer_norm(&mut t, &format!("{p}.ln2"), d);
        dense(&mut t, &mut rng, &format!("{p}.ff1"), d, c.ff, false);
        dense(&mut t, &mut rng, &format!("{p}.ff2"), c.ff, d, false);
    }
    layer_norm(&mut t, "final_ln", d);
    init_flow(&mut t, &mut rng, "flow", &c.flow());
    t
}
