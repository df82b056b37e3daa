//! The whole trainable network: transformer context → flow over the next pose. One forward
//! pass scores every position of a batch of sequences (teacher forcing).

use burn::module::Module;
use burn::tensor::{Device, Tensor};

use crate::motion::MOTION_FEATURE_DIM;
use crate::neural::config::NetConfig;
use crate::neural::flow::Flow;
use crate::neural::tensors::{NamedTensors, WeightError};
use crate::neural::transformer::Transformer;

/// Transformer plus flow head.
#[derive(Module, Debug)]
pub struct Net {
    /// The causal transformer.
    pub transformer: Transformer,
    /// The flow over the next pose's normalised features.
    pub flow: Flow,
}

impl Net {
    /// Builds the network from named tensors.
    pub fn load(t: &NamedTensors, c: &NetConfig, device: &Device) -> Result<Self, WeightError> {
        c.check()
            .map_err(|e| WeightError::Missing(format!("(bad config: {e})")))?;
        Ok(Net {
            transformer: Transformer::load(t, c, device)?,
            flow: Flow::load(t, "flow", &c.flow(), device)?,
        })
    }

    /// Writes the trainable weights into `t` (normalisation and seed entries are left as they are).
    pub fn store(&self, t: &mut NamedTensors) {
        self.transformer.store(t);
        self.flow.store(t, "flow");
    }

    /// Negative log-likelihood of each target `[b, s, MOTION_FEATURE_DIM]` given its token
    /// `[b, s, TOKEN_DIM]`, nats per frame, shape `[b·s]`.
    pub fn nll(&self, tokens: Tensor<3>, targets: Tensor<3>) -> Tensor<1> {
        let [b, s, _] = targets.dims();
        let ctx = self.transformer.forward(tokens);
        self.flow
            .log_prob(targets.reshape([b * s, MOTION_FEATURE_DIM]), ctx)
            .neg()
    }

    /// Data-dependent initialisation of the flow's actnorms from one batch.
    pub fn data_init(self, tokens: Tensor<3>, targets: Tensor<3>) -> Self {
        let [b, s, _] = targets.dims();
        let ctx = self.transformer.forward(tokens);
        let flow = self
            .flow
            .data_init(targets.reshape([b * s, MOTION_FEATURE_DIM]), ctx);
        Net {
            transformer: self.transformer,
            flow,
        }
    }
}
