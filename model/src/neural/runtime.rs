//! Live inference in plain Rust: the network that training's `Net` scores in batches, run one token at
//! a time with a key/value cache over the last `window` tokens, and the flow inverted for one
//! sample. Every buffer is allocated in [`Runtime::new`]; [`Runtime::push`] and
//! [`Runtime::sample`] never allocate, so they can run on a real-time thread, and each costs
//! O(window · d_model) per layer, not a re-encode of the window.

use crate::ModelError;
use crate::neural::config::{COUPLING_SCALE_OFFSET, LN_EPS, NetConfig, rope_frequency};
use crate::neural::lu;
use crate::neural::tensors::{NamedTensors, STYLE_EMBEDDING};
use crate::neural::token::{FLAG_AT, LEVEL_AT, key_condition};

#[derive(Clone)]
struct Dense {
    w: Vec<f32>,
    b: Vec<f32>,
}

impl Dense {
    fn load(t: &NamedTensors, name: &str, i: usize, o: usize) -> Result<Self, ModelError> {
        Ok(Dense {
            w: t.get(&format!("{name}.w"), &[i, o])?.to_vec(),
            b: t.get(&format!("{name}.b"), &[o])?.to_vec(),
        })
    }

    /// out = x · w + b (row-major w, inner loop over contiguous outputs so it vectorises).
    #[inline]
    fn apply(&self, x: &[f32], out: &mut [f32]) {
        let o = self.b.len();
        out[..o].copy_from_slice(&self.b);
        for (i, &xi) in x.iter().enumerate() {
            let row = &self.w[i * o..(i + 1) * o];
            for (acc, &w) in out[..o].iter_mut().zip(row) {
                *acc += xi * w;
            }
        }
    }
}

#[derive(Clone)]
struct Norm {
    g: Vec<f32>,
    b: Vec<f32>,
}

impl Norm {
    fn load(t: &NamedTensors, name: &str, d: usize) -> Result<Self, ModelError> {
        Ok(Norm {
            g: t.get(&format!("{name}.g"), &[d])?.to_vec(),
            b: t.get(&format!("{name}.b"), &[d])?.to_vec(),
        })
    }

    fn apply(&self, x: &[f32], out: &mut [f32]) {
        let n = x.len() as f32;
        let mean = x.iter().sum::<f32>() / n;
        let var = x.iter().map(|v| (v - mean) * (v - mean)).sum::<f32>() / n;
        let inv = 1.0 / (var + LN_EPS).sqrt();
        for i in 0..x.len() {
            out[i] = (x[i] - mean) * inv * self.g[i] + self.b[i];
        }
    }
}

#[derive(Clone)]
struct Block {
    ln1: Norm,
    qkv: Dense,
    out: Dense,
    ln2: Norm,
    ff1: Dense,
    ff2: Dense,
    /// Cached keys (already rotated to their position) and values, `[window][d_model]` rings.
    keys: Vec<f32>,
    values: Vec<f32>,
}

#[derive(Clone)]
struct FlowStep {
    an_bias: Vec<f32>,
    /// exp(−actnorm log-scale), precomputed.
    an_inv_scale: Vec<f32>,
    /// W⁻¹, row-major.
    w_inv: Vec<f32>,
    c1: Dense,
    c2: Dense,
}

/// The streaming network.
#[derive(Clone)]
pub struct Runtime {
    config: NetConfig,
    embed: Dense,
    none: Vec<f32>,
    /// `[styles, d]`, empty for a model without a style input.
    style_table: Vec<f32>,
    /// Row of `style_table` added to every token, if any.
    style: Option<usize>,
    blocks: Vec<Block>,
    final_ln: Norm,
    steps: Vec<FlowStep>,
    /// Tokens in the cache (≤ window).
    filled: usize,
    /// Ring slot the next token goes to.
    slot: usize,
    /// Absolute position of the next token (rotary angles are computed from it in f64, so
    /// hours of frames keep full precision).
    position: u64,
    x: Vec<f32>,
    h: Vec<f32>,
    qkv: Vec<f32>,
    o: Vec<f32>,
    tmp: Vec<f32>,
    ff: Vec<f32>,
    scores: Vec<f32>,
    cos: Vec<f32>,
    sin: Vec<f32>,
    ctx: Vec<f32>,
    coupling_in: Vec<f32>,
    coupling_hidden: Vec<f32>,
    coupling_out: Vec<f32>,
    flow_tmp: Vec<f32>,
}

impl Runtime {
    /// Builds the runtime from named tensors (the flow's linear maps are inverted here).
    pub fn new(t: &NamedTensors, c: &NetConfig) -> Result<Self, ModelError> {
        c.check()
            .map_err(|e| ModelError::WeightMissing(format!("(bad config: {e})")))?;
        let d = c.d_model;
        let f = c.flow();
        let blocks = (0..c.layers)
            .map(|l| {
                let p = format!("layer{l}");
                Ok(Block {
                    ln1: Norm::load(t, &format!("{p}.ln1"), d)?,
                    qkv: Dense::load(t, &format!("{p}.qkv"), d, 3 * d)?,
                    out: Dense::load(t, &format!("{p}.out"), d, d)?,
                    ln2: Norm::load(t, &format!("{p}.ln2"), d)?,
                    ff1: Dense::load(t, &format!("{p}.ff1"), d, c.ff)?,
                    ff2: Dense::load(t, &format!("{p}.ff2"), c.ff, d)?,
                    keys: vec![0.0; c.window * d],
                    values: vec![0.0; c.window * d],
                })
            })
            .collect::<Result<_, ModelError>>()?;
        let steps = (0..f.steps)
            .map(|k| {
                let p = format!("flow.{k}");
                let n = f.dim;
                let perm = t.permutation(&format!("{p}.perm"), n)?;
                let w = lu::weight(
                    &perm,
                    t.get(&format!("{p}.lower"), &[n, n])?,
                    t.get(&format!("{p}.upper"), &[n, n])?,
                    t.get(&format!("{p}.log_s"), &[n])?,
                );
                let w_inv = lu::inverse(&w, n)
                    .ok_or_else(|| ModelError::WeightNotFinite(format!("{p} (singular)")))?;
                Ok(FlowStep {
                    an_bias: t.get(&format!("{p}.an_bias"), &[n])?.to_vec(),
                    an_inv_scale: t
                        .get(&format!("{p}.an_logs"), &[n])?
                        .iter()
                        .map(|l| (-l).exp())
                        .collect(),
                    w_inv,
                    c1: Dense::load(t, &format!("{p}.c1"), f.half() + f.context, f.hidden)?,
                    c2: Dense::load(t, &format!("{p}.c2"), f.hidden, 2 * f.rest())?,
                })
            })
            .collect::<Result<_, ModelError>>()?;
        let half = c.head_dim() / 2;
        Ok(Runtime {
            config: *c,
            embed: Dense::load(t, "embed", c.token_dim(), d)?,
            none: t.get("embed.none", &[d])?.to_vec(),
            style_table: if c.styles > 0 {
                t.get(STYLE_EMBEDDING, &[c.styles, d])?.to_vec()
            } else {
                Vec::new()
            },
            style: None,
            blocks,
            final_ln: Norm::load(t, "final_ln", d)?,
            steps,
            filled: 0,
            slot: 0,
            position: 0,
            x: vec![0.0; d],
            h: vec![0.0; d],
            qkv: vec![0.0; 3 * d],
            o: vec![0.0; d],
            tmp: vec![0.0; d],
            ff: vec![0.0; c.ff],
            scores: vec![0.0; c.window],
            cos: vec![0.0; half],
            sin: vec![0.0; half],
            ctx: vec![0.0; f.context],
            coupling_in: vec![0.0; f.half() + f.context],
            coupling_hidden: vec![0.0; f.hidden],
            coupling_out: vec![0.0; 2 * f.rest()],
            flow_tmp: vec![0.0; f.dim],
        })
    }

    /// The network's configuration.
    pub fn config(&self) -> &NetConfig {
        &self.config
    }

    /// Conditions every token pushed from now on on style `index` (None, or a model without a
    /// style input: unconditioned); an index past the model's styles is ignored.
    pub fn set_style(&mut self, index: Option<usize>) {
        self.style = index.filter(|&i| i < self.config.styles);
    }

    /// Forgets every cached token.
    pub fn reset(&mut self) {
        self.filled = 0;
        self.slot = 0;
        self.position = 0;
    }

    /// Appends one token (`TOKEN_DIM` values) and returns its context vector (the transformer's;
    /// a `key_to_flow` network's flow also reads the token's key conditioning, a
    /// `level_to_flow` one its relative level).
    pub fn push(&mut self, token: &[f32]) -> &[f32] {
        let c = self.config;
        let (d, heads, dh) = (c.d_model, c.heads, c.head_dim());
        let half = dh / 2;
        self.embed.apply(token, &mut self.x);
        let no_key = 1.0 - token[FLAG_AT];
        for (x, n) in self.x.iter_mut().zip(&self.none) {
            *x += no_key * n;
        }
        if let Some(i) = self.style {
            for (x, s) in self.x.iter_mut().zip(&self.style_table[i * d..(i + 1) * d]) {
                *x += s;
            }
        }
        for k in 0..half {
            let (s, co) = (self.position as f64 * rope_frequency(k, half)).sin_cos();
            self.cos[k] = co as f32;
            self.sin[k] = s as f32;
        }
        let slot = self.slot;
        let count = (self.filled + 1).min(c.window);
        let scale = 1.0 / (dh as f32).sqrt();
        for b in self.blocks.iter_mut() {
            b.ln1.apply(&self.x, &mut self.h);
            b.qkv.apply(&self.h, &mut self.qkv);
            // Rotate q and k in place, per head.
            for part in 0..2 {
                for hd in 0..heads {
                    let base = part * d + hd * dh;
                    for k in 0..half {
                        let a = self.qkv[base + k];
                        let bb = self.qkv[base + half + k];
                        self.qkv[base + k] = a * self.cos[k] - bb * self.sin[k];
                        self.qkv[base + half + k] = a * self.sin[k] + bb * self.cos[k];
                    }
                }
            }
            b.keys[slot * d..(slot + 1) * d].copy_from_slice(&self.qkv[d..2 * d]);
            b.values[slot * d..(slot + 1) * d].copy_from_slice(&self.qkv[2 * d..3 * d]);
            // The softmax is order-free, so the ring's slots need no unrolling.
            for hd in 0..heads {
                let q = &self.qkv[hd * dh..(hd + 1) * dh];
                let mut max = f32::NEG_INFINITY;
                for j in 0..count {
                    let k = &b.keys[j * d + hd * dh..j * d + (hd + 1) * dh];
                    let s = q.iter().zip(k).map(|(a, b)| a * b).sum::<f32>() * scale;
                    self.scores[j] = s;
                    max = max.max(s);
                }
                let mut total = 0.0;
                for s in &mut self.scores[..count] {
                    *s = (*s - max).exp();
                    total += *s;
                }
                let o = &mut self.o[hd * dh..(hd + 1) * dh];
                o.fill(0.0);
                for j in 0..count {
                    let p = self.scores[j] / total;
                    let v = &b.values[j * d + hd * dh..j * d + (hd + 1) * dh];
                    for (acc, &vv) in o.iter_mut().zip(v) {
                        *acc += p * vv;
                    }
                }
            }
            b.out.apply(&self.o, &mut self.tmp);
            for (x, t) in self.x.iter_mut().zip(&self.tmp) {
                *x += t;
            }
            b.ln2.apply(&self.x, &mut self.h);
            b.ff1.apply(&self.h, &mut self.ff);
            for v in self.ff.iter_mut() {
                *v = v.max(0.0);
            }
            b.ff2.apply(&self.ff, &mut self.tmp);
            for (x, t) in self.x.iter_mut().zip(&self.tmp) {
                *x += t;
            }
        }
        self.filled = count;
        self.slot = (slot + 1) % c.window;
        self.position += 1;
        self.final_ln.apply(&self.x, &mut self.ctx[..d]);
        if c.key_to_flow {
            key_condition(token, &mut self.ctx[c.key_condition_at()..]);
        }
        if c.level_to_flow {
            self.ctx[c.level_condition_at()] = token[LEVEL_AT];
        }
        &self.ctx[..d]
    }

    /// The flow's inverse at the last pushed token's context: `z` → normalised pose in `out`.
    pub fn sample(&mut self, z: &[f32], out: &mut [f32]) {
        let f = self.config.flow();
        let (n, half, rest) = (f.dim, f.half(), f.rest());
        out[..n].copy_from_slice(&z[..n]);
        for s in self.steps.iter().rev() {
            self.coupling_in[..half].copy_from_slice(&out[..half]);
            self.coupling_in[half..].copy_from_slice(&self.ctx);
            s.c1.apply(&self.coupling_in, &mut self.coupling_hidden);
            for v in self.coupling_hidden.iter_mut() {
                *v = v.max(0.0);
            }
            s.c2.apply(&self.coupling_hidden, &mut self.coupling_out);
            for j in 0..rest {
                // 1 / sigmoid(a) = 1 + e^(−a).
                let a = self.coupling_out[j] + COUPLING_SCALE_OFFSET;
                out[half + j] = out[half + j] * (1.0 + (-a).exp()) - self.coupling_out[rest + j];
            }
            for i in 0..n {
                let row = &s.w_inv[i * n..(i + 1) * n];
                self.flow_tmp[i] = row.iter().zip(&out[..n]).map(|(w, y)| w * y).sum();
            }
            for (i, o) in out[..n].iter_mut().enumerate() {
                *o = self.flow_tmp[i] * s.an_inv_scale[i] - s.an_bias[i];
            }
        }
    }
}
