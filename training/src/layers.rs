//! Small burn building blocks (dense layer, layer norm) loaded from and stored to
//! [`NamedTensors`], so training weights and live weights are the same numbers.

use burn::module::{Module, Param, ParamId};
use burn::tensor::{Device, Tensor, TensorData};

use model::ModelError;
use model::neural::config::LN_EPS;
use model::neural::rng::Rng;
use model::neural::tensors::NamedTensors;

/// A trainable parameter from the named tensor `name` of shape `[n]`.
pub fn param1(
    t: &NamedTensors,
    name: &str,
    n: usize,
    device: &Device,
) -> Result<Param<Tensor<1>>, ModelError> {
    let v = t.get(name, &[n])?.to_vec();
    Ok(Param::from_tensor(Tensor::from_data(
        TensorData::new(v, [n]),
        device,
    )))
}

/// A trainable parameter from the named tensor `name` of shape `[r, c]`.
pub fn param2(
    t: &NamedTensors,
    name: &str,
    r: usize,
    c: usize,
    device: &Device,
) -> Result<Param<Tensor<2>>, ModelError> {
    let v = t.get(name, &[r, c])?.to_vec();
    Ok(Param::from_tensor(Tensor::from_data(
        TensorData::new(v, [r, c]),
        device,
    )))
}

/// A trainable parameter of `shape` drawn uniformly in ±1/√`fan_in` (burn's default for dense
/// and convolution layers) from `rng`: burn's own generator is one per process, so a network
/// initialised from it comes out different whenever another thread draws at the same time.
pub fn fan_in_uniform<const D: usize>(
    shape: [usize; D],
    fan_in: usize,
    rng: &mut Rng,
    device: &Device,
) -> Param<Tensor<D>> {
    let bound = 1.0 / (fan_in.max(1) as f64).sqrt();
    let n = shape.iter().product();
    let v: Vec<f32> = (0..n)
        .map(|_| ((2.0 * rng.uniform() - 1.0) * bound) as f32)
        .collect();
    Param::from_tensor(Tensor::from_data(TensorData::new(v, shape), device))
}

/// A constant (non-trainable) matrix.
pub fn constant2(v: Vec<f32>, r: usize, c: usize, device: &Device) -> Tensor<2> {
    Tensor::from_data(TensorData::new(v, [r, c]), device)
}

/// The values of a tensor (empty if they cannot be read as f32, which later fails validation).
pub fn values<const D: usize>(t: Tensor<D>) -> Vec<f32> {
    t.into_data()
        .convert::<f32>()
        .try_to_vec::<f32>()
        .unwrap_or_default()
}

/// Rows of a weight matrix `[inputs, outputs]`: those that multiply the inputs `rows`.
#[derive(Clone, Debug)]
pub struct WeightRows {
    /// The weight matrix.
    pub param: ParamId,
    /// The rows (inputs) meant.
    pub rows: std::ops::Range<usize>,
}

/// Stores a parameter under `name`.
pub fn store<const D: usize>(t: &mut NamedTensors, name: &str, p: &Param<Tensor<D>>) {
    let v = p.val();
    let shape = v.dims().to_vec();
    t.insert(name, &shape, values(v));
}

/// `x · w + b` with `w` of shape `[inputs, outputs]`.
#[derive(Module, Debug)]
pub struct Dense {
    /// Weights `[inputs, outputs]`.
    pub w: Param<Tensor<2>>,
    /// Bias `[outputs]`.
    pub b: Param<Tensor<1>>,
}

impl Dense {
    /// Loads `name.w`, `name.b`.
    pub fn load(
        t: &NamedTensors,
        name: &str,
        i: usize,
        o: usize,
        device: &Device,
    ) -> Result<Self, ModelError> {
        Ok(Dense {
            w: param2(t, &format!("{name}.w"), i, o, device)?,
            b: param1(t, &format!("{name}.b"), o, device)?,
        })
    }

    /// Stores `name.w`, `name.b`.
    pub fn store(&self, t: &mut NamedTensors, name: &str) {
        store(t, &format!("{name}.w"), &self.w);
        store(t, &format!("{name}.b"), &self.b);
    }

    /// Applies the layer to rows `[n, inputs]`.
    pub fn forward(&self, x: Tensor<2>) -> Tensor<2> {
        x.matmul(self.w.val()) + self.b.val().unsqueeze::<2>()
    }
}

/// Layer normalisation over the last dimension with gain and bias.
#[derive(Module, Debug)]
pub struct LayerNorm {
    /// Gain.
    pub g: Param<Tensor<1>>,
    /// Bias.
    pub b: Param<Tensor<1>>,
}

impl LayerNorm {
    /// Loads `name.g`, `name.b`.
    pub fn load(
        t: &NamedTensors,
        name: &str,
        d: usize,
        device: &Device,
    ) -> Result<Self, ModelError> {
        Ok(LayerNorm {
            g: param1(t, &format!("{name}.g"), d, device)?,
            b: param1(t, &format!("{name}.b"), d, device)?,
        })
    }

    /// Stores `name.g`, `name.b`.
    pub fn store(&self, t: &mut NamedTensors, name: &str) {
        store(t, &format!("{name}.g"), &self.g);
        store(t, &format!("{name}.b"), &self.b);
    }

    /// Normalises rows `[n, d]`.
    pub fn forward(&self, x: Tensor<2>) -> Tensor<2> {
        let mean = x.clone().mean_dim(1);
        let centred = x - mean;
        let var = centred.clone().powi_scalar(2).mean_dim(1);
        centred / var.add_scalar(LN_EPS).sqrt() * self.g.val().unsqueeze::<2>()
            + self.b.val().unsqueeze::<2>()
    }
}
