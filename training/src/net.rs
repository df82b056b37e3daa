//! The whole trainable network: transformer context → flow over the next pose. One forward
//! pass scores every position of a batch of sequences (teacher forcing).

use burn::module::Module;
use burn::tensor::{Device, Tensor};

use crate::flow::Flow;
use crate::transformer::Transformer;
use model::motion::MOTION_FEATURE_DIM;
use model::neural::config::NetConfig;
use model::neural::tensors::{NamedTensors, WeightError};

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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::device::cpu_device;
    use crate::layers::values;
    use burn::tensor::TensorData;
    use model::motion::MOTION_FEATURE_DIM;
    use model::neural::config::NetConfig;
    use model::neural::rng::Rng;
    use model::neural::runtime::Runtime;
    use model::neural::tensors::init_net;
    use model::neural::token::{FLAG_AT, TOKEN_DIM};

    #[test]
    fn streaming_matches_the_batched_network_across_the_window() {
        let c = NetConfig::tiny();
        let mut t = init_net(&c, 7);
        t.perturb(8, 0.1);
        let device = cpu_device();
        let net = Net::load(&t, &c, &device).unwrap();
        let mut rt = Runtime::new(&t, &c).unwrap();
        // 2.5 windows, so the sliding window (and the ring wrapping) is exercised.
        let s = c.window * 5 / 2;
        let mut r = Rng::new(1);
        let mut tokens: Vec<f32> = (0..s * TOKEN_DIM).map(|_| r.normal()).collect();
        for i in 0..s {
            tokens[i * TOKEN_DIM + FLAG_AT] = (i % 3 == 0) as u8 as f32;
        }
        let tt =
            Tensor::<3>::from_data(TensorData::new(tokens.clone(), [1, s, TOKEN_DIM]), &device);
        let batched = values(net.transformer.forward(tt));
        let mut worst = 0f32;
        let mut last_ctx = Vec::new();
        for i in 0..s {
            let ctx = rt.push(&tokens[i * TOKEN_DIM..(i + 1) * TOKEN_DIM]);
            for j in 0..c.d_model {
                worst = worst.max((ctx[j] - batched[i * c.d_model + j]).abs());
            }
            last_ctx = ctx.to_vec();
        }
        assert!(
            worst < 1e-3,
            "streaming vs batched context differ by {worst}"
        );
        // The flow inverse agrees with burn's.
        let z: Vec<f32> = (0..MOTION_FEATURE_DIM).map(|_| r.normal()).collect();
        let mut x = vec![0.0; MOTION_FEATURE_DIM];
        rt.sample(&z, &mut x);
        let ctx = Tensor::<2>::from_data(TensorData::new(last_ctx, [1, c.d_model]), &device);
        let zt = Tensor::<2>::from_data(TensorData::new(z, [1, MOTION_FEATURE_DIM]), &device);
        let xb = values(net.flow.inverse(zt, ctx).unwrap());
        let err = x
            .iter()
            .zip(&xb)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f32::max);
        assert!(err < 1e-3, "flow inverse differs by {err}");
    }
}
