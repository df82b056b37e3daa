//! The neural dancer: a causal transformer over (previous pose, look-ahead music, key pose)
//! tokens whose output conditions a normalizing flow over the next pose.
//!
//! Training runs on burn (autodiff over the `flex` CPU backend): [`net::Net`] scores whole
//! sequences at once (teacher forcing, exact NLL). Live sampling does not use burn: the same
//! weights run through [`runtime::Runtime`], plain Rust with a key/value cache and preallocated
//! buffers, because `MotionSource::step` must not allocate and must cost well under 2 ms.
//! Both sides read one weight set ([`tensors::NamedTensors`]), so a test can hold them equal.

pub mod config;
pub mod dancer;
pub mod file;
pub mod flow;
pub mod layers;
pub mod lu;
pub mod net;
pub mod rng;
pub mod runtime;
pub mod tensors;
pub mod token;
pub mod train;
pub mod transformer;

/// The burn device every neural computation here runs on (the `flex` CPU backend).
pub fn cpu_device() -> burn::tensor::Device {
    burn::tensor::Device::flex()
}

/// The device training runs on, with gradients enabled: the CPU, or with the `wgpu` feature
/// the default GPU adapter.
pub fn training_device() -> burn::tensor::Device {
    #[cfg(feature = "wgpu")]
    let device = burn::tensor::Device::wgpu(burn::tensor::DeviceKind::DefaultDevice);
    #[cfg(not(feature = "wgpu"))]
    let device = cpu_device();
    device.autodiff()
}
