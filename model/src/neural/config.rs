//! The network's architecture: its sizes, stored in the model file so a file rebuilds the exact
//! network, and the fixed constants that training and the live runtime must share.

use serde::{Deserialize, Serialize};

use crate::ModelError;
use crate::motion::MOTION_FEATURE_DIM;
use crate::neural::token::{KEY_CONDITION_DIM, TOKEN_DIM};

/// Added to the coupling's raw scale before the sigmoid, so a fresh coupling scales by
/// sigmoid(2) ≈ 0.88 and scales stay in (0, 1): bounded, so training cannot explode them.
pub const COUPLING_SCALE_OFFSET: f32 = 2.0;

/// Epsilon of every layer norm (training and the live runtime use the same).
pub const LN_EPS: f32 = 1e-5;

/// Base of the rotary frequencies.
pub const ROPE_BASE: f64 = 10_000.0;

/// Rotation frequency of pair `i` of `half` pairs, radians per token.
pub fn rope_frequency(i: usize, half: usize) -> f64 {
    ROPE_BASE.powf(-(i as f64) / half as f64)
}

/// Sizes of the conditional flow.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct FlowConfig {
    /// Dimension of the modelled vector.
    pub dim: usize,
    /// Dimension of the context vector.
    pub context: usize,
    /// Hidden width of each coupling's MLP.
    pub hidden: usize,
    /// Flow steps (actnorm, invertible linear, affine coupling).
    pub steps: usize,
}

impl FlowConfig {
    /// Width of the half passed through unchanged by a coupling (conditions the other half).
    pub fn half(&self) -> usize {
        self.dim / 2
    }

    /// Width of the half a coupling transforms.
    pub fn rest(&self) -> usize {
        self.dim - self.half()
    }
}

/// Sizes of the whole network: the causal transformer and its flow head.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct NetConfig {
    /// Width of the transformer's residual stream (also the flow's context size).
    pub d_model: usize,
    /// Attention heads (`d_model` must divide evenly; the head size must be even for rotary positions).
    pub heads: usize,
    /// Transformer blocks.
    pub layers: usize,
    /// Hidden width of each feed-forward block.
    pub ff: usize,
    /// Attention window in tokens (= frames); also the training sequence length.
    pub window: usize,
    /// Music look-ahead in frames: token t carries the music of frame t + lookahead.
    pub lookahead: usize,
    /// Flow steps.
    pub flow_steps: usize,
    /// Hidden width of the flow's coupling MLPs.
    pub flow_hidden: usize,
    /// Dance styles the network is conditioned on (a learned vector per style added to every
    /// token's embedding, `embed.style`); 0 = no style input (models before issue 21).
    #[serde(default)]
    pub styles: usize,
    /// The flow also reads each token's key conditioning ([`crate::neural::token::key_condition`]:
    /// the key pose's distance from the previous pose, the count-down, the flag) beside the
    /// context; false in models before it (they condition on the key through the transformer only).
    #[serde(default)]
    pub key_to_flow: bool,
    /// The flow also reads each token's relative level ([`crate::neural::token::LEVEL_AT`], the
    /// music heard below its recent peak) beside the context, after the key conditioning;
    /// false in models before it.
    #[serde(default)]
    pub level_to_flow: bool,
}

impl Default for NetConfig {
    /// The shipped size: 3 × 128-wide blocks over a 2.56 s window, no look-ahead (the music
    /// is predicted to each frame's time instead, see `dsp::predicted_stream`), 8 flow steps,
    /// no style input (the shipped recipe's first stage builds this; its second gives the flow
    /// the key pose).
    fn default() -> Self {
        NetConfig {
            d_model: 128,
            heads: 4,
            layers: 3,
            ff: 256,
            window: 64,
            lookahead: 0,
            flow_steps: 8,
            flow_hidden: 192,
            styles: 0,
            key_to_flow: false,
            level_to_flow: false,
        }
    }
}

impl NetConfig {
    /// A tiny network for tests.
    pub fn tiny() -> Self {
        NetConfig {
            d_model: 16,
            heads: 2,
            layers: 2,
            ff: 24,
            window: 8,
            lookahead: 2,
            flow_steps: 2,
            flow_hidden: 16,
            styles: crate::style::DanceStyle::COUNT,
            key_to_flow: false,
            level_to_flow: false,
        }
    }

    /// Where the key conditioning starts in the flow's context (after the transformer's).
    pub fn key_condition_at(&self) -> usize {
        self.d_model
    }

    /// Where the relative level sits in the flow's context (after the key conditioning).
    pub fn level_condition_at(&self) -> usize {
        self.key_condition_at()
            + if self.key_to_flow {
                KEY_CONDITION_DIM
            } else {
                0
            }
    }

    /// Size of one attention head.
    pub fn head_dim(&self) -> usize {
        self.d_model / self.heads
    }

    /// The flow head's sizes.
    pub fn flow(&self) -> FlowConfig {
        FlowConfig {
            dim: MOTION_FEATURE_DIM,
            context: self.level_condition_at() + usize::from(self.level_to_flow),
            hidden: self.flow_hidden,
            steps: self.flow_steps,
        }
    }

    /// Input width of a token.
    pub fn token_dim(&self) -> usize {
        TOKEN_DIM
    }

    /// Why this configuration cannot build a network, if it cannot ([`ModelError::BadNetConfig`]).
    pub fn check(&self) -> Result<(), ModelError> {
        if self.d_model == 0 || self.heads == 0 || self.layers == 0 || self.window == 0 {
            return Err(ModelError::BadNetConfig("zero-sized network".into()));
        }
        if !self.d_model.is_multiple_of(self.heads) || !self.head_dim().is_multiple_of(2) {
            return Err(ModelError::BadNetConfig(format!(
                "d_model {} is not an even head size times {} heads",
                self.d_model, self.heads
            )));
        }
        if self.flow_steps == 0 || self.flow_hidden == 0 || self.ff == 0 {
            return Err(ModelError::BadNetConfig(
                "zero-sized flow or feed-forward".into(),
            ));
        }
        if self.window > 4096
            || self.d_model > 4096
            || self.ff > 16384
            || self.lookahead > 250
            || self.styles > 64
        {
            return Err(ModelError::BadNetConfig("implausibly large network".into()));
        }
        Ok(())
    }
}
