//! The causal transformer (burn, trainable): pre-norm blocks with rotary positions and a
//! windowed causal mask, one output context vector per token. Rotary positions make attention
//! depend only on token distance, so a live sliding window sees exactly what training saw.

use burn::module::{Module, Param};
use burn::tensor::{Device, Tensor, TensorData, activation};

use crate::layers::{Dense, LayerNorm, WeightRows, param1, param2, store};
use model::ModelError;
use model::neural::config::{NetConfig, rope_frequency};
use model::neural::tensors::{NamedTensors, STYLE_EMBEDDING};
use model::neural::token::FLAG_AT;

/// One pre-norm block: windowed causal self-attention, then a ReLU feed-forward.
#[derive(Module, Debug)]
pub struct Block {
    ln1: LayerNorm,
    qkv: Dense,
    out: Dense,
    ln2: LayerNorm,
    ff1: Dense,
    ff2: Dense,
}

/// The token embedding, the blocks and the final norm.
#[derive(Module, Debug)]
pub struct Transformer {
    embed: Dense,
    none: Param<Tensor<1>>,
    /// `[styles, d]`; None for a network without a style input.
    style: Option<Param<Tensor<2>>>,
    blocks: Vec<Block>,
    final_ln: LayerNorm,
    #[module(skip)]
    config: NetConfig,
}

fn rope(x: Tensor<4>, cos: &Tensor<4>, sin: &Tensor<4>) -> Tensor<4> {
    let dh = x.dims()[3];
    let a = x.clone().narrow(3, 0, dh / 2);
    let b = x.narrow(3, dh / 2, dh / 2);
    Tensor::cat(
        vec![
            a.clone() * cos.clone() - b.clone() * sin.clone(),
            a * sin.clone() + b * cos.clone(),
        ],
        3,
    )
}

impl Block {
    fn forward(
        &self,
        x: Tensor<2>,
        b: usize,
        s: usize,
        heads: usize,
        rot: &(Tensor<4>, Tensor<4>),
        mask: &Tensor<4>,
    ) -> Tensor<2> {
        let d = x.dims()[1];
        let dh = d / heads;
        let qkv = self
            .qkv
            .forward(self.ln1.forward(x.clone()))
            .reshape([b, s, 3 * d]);
        let split = |i: usize| {
            qkv.clone()
                .narrow(2, i * d, d)
                .reshape([b, s, heads, dh])
                .swap_dims(1, 2)
        };
        let q = rope(split(0), &rot.0, &rot.1);
        let k = rope(split(1), &rot.0, &rot.1);
        let v = split(2);
        let scores = q
            .matmul(k.swap_dims(2, 3))
            .mul_scalar(1.0 / (dh as f32).sqrt())
            + mask.clone();
        let att = activation::softmax(scores, 3);
        let o = att.matmul(v).swap_dims(1, 2).reshape([b * s, d]);
        let x = x + self.out.forward(o);
        let h = self.ff2.forward(activation::relu(
            self.ff1.forward(self.ln2.forward(x.clone())),
        ));
        x + h
    }
}

impl Transformer {
    /// Loads the transformer's weights.
    pub fn load(t: &NamedTensors, c: &NetConfig, device: &Device) -> Result<Self, ModelError> {
        let d = c.d_model;
        let blocks = (0..c.layers)
            .map(|l| {
                let p = format!("layer{l}");
                Ok(Block {
                    ln1: LayerNorm::load(t, &format!("{p}.ln1"), d, device)?,
                    qkv: Dense::load(t, &format!("{p}.qkv"), d, 3 * d, device)?,
                    out: Dense::load(t, &format!("{p}.out"), d, d, device)?,
                    ln2: LayerNorm::load(t, &format!("{p}.ln2"), d, device)?,
                    ff1: Dense::load(t, &format!("{p}.ff1"), d, c.ff, device)?,
                    ff2: Dense::load(t, &format!("{p}.ff2"), c.ff, d, device)?,
                })
            })
            .collect::<Result<_, ModelError>>()?;
        Ok(Transformer {
            embed: Dense::load(t, "embed", c.token_dim(), d, device)?,
            none: param1(t, "embed.none", d, device)?,
            style: if c.styles > 0 {
                Some(param2(t, STYLE_EMBEDDING, c.styles, d, device)?)
            } else {
                None
            },
            blocks,
            final_ln: LayerNorm::load(t, "final_ln", d, device)?,
            config: *c,
        })
    }

    /// The network's sizes.
    pub fn config(&self) -> &NetConfig {
        &self.config
    }

    /// The width of its context vectors (`d_model`).
    pub fn width(&self) -> usize {
        self.config.d_model
    }

    /// Stores the transformer's weights.
    pub fn store(&self, t: &mut NamedTensors) {
        self.embed.store(t, "embed");
        store(t, "embed.none", &self.none);
        if let Some(style) = &self.style {
            store(t, STYLE_EMBEDDING, style);
        }
        for (l, b) in self.blocks.iter().enumerate() {
            let p = format!("layer{l}");
            b.ln1.store(t, &format!("{p}.ln1"));
            b.qkv.store(t, &format!("{p}.qkv"));
            b.out.store(t, &format!("{p}.out"));
            b.ln2.store(t, &format!("{p}.ln2"));
            b.ff1.store(t, &format!("{p}.ff1"));
            b.ff2.store(t, &format!("{p}.ff2"));
        }
        self.final_ln.store(t, "final_ln");
    }

    /// The embedding weight's rows that read the token inputs `inputs`.
    pub fn embedding_rows(&self, inputs: std::ops::Range<usize>) -> WeightRows {
        WeightRows {
            param: self.embed.w.id,
            rows: inputs,
        }
    }

    /// The style embedding's rows, one per style (None: a network without a style input).
    pub fn style_rows(&self) -> Option<WeightRows> {
        self.style.as_ref().map(|s| WeightRows {
            param: s.id,
            rows: 0..self.config.styles,
        })
    }

    /// Context vectors `[b·s, d_model]` for tokens `[b, s, TOKEN_DIM]`; row b·s + t sees
    /// tokens t − window + 1 ..= t of its sequence. `styles` is one row per token `[b·s,
    /// styles]` (one-hot, or zeros: unconditioned), ignored by a network without a style input.
    pub fn forward(&self, tokens: Tensor<3>, styles: Option<Tensor<2>>) -> Tensor<2> {
        let [b, s, i] = tokens.dims();
        let device = tokens.device();
        let c = &self.config;
        let x2 = tokens.reshape([b * s, i]);
        let no_key = x2.clone().narrow(1, FLAG_AT, 1).neg().add_scalar(1.0);
        let mut x = self.embed.forward(x2) + no_key * self.none.val().unsqueeze::<2>();
        if let (Some(table), Some(onehot)) = (&self.style, styles) {
            x = x + onehot.matmul(table.val());
        }
        let half = c.head_dim() / 2;
        let mut cos = vec![0.0f32; s * half];
        let mut sin = vec![0.0f32; s * half];
        for p in 0..s {
            for k in 0..half {
                let (sn, cs) = (p as f64 * rope_frequency(k, half)).sin_cos();
                cos[p * half + k] = cs as f32;
                sin[p * half + k] = sn as f32;
            }
        }
        let table =
            |v: Vec<f32>| Tensor::<4>::from_data(TensorData::new(v, [1, 1, s, half]), &device);
        let rot = (table(cos), table(sin));
        let mut mask = vec![0.0f32; s * s];
        for q in 0..s {
            for k in 0..s {
                if k > q || q - k >= c.window {
                    mask[q * s + k] = -1e9;
                }
            }
        }
        let mask = Tensor::<4>::from_data(TensorData::new(mask, [1, 1, s, s]), &device);
        for block in &self.blocks {
            x = block.forward(x, b, s, c.heads, &rot, &mask);
        }
        self.final_ln.forward(x)
    }
}
