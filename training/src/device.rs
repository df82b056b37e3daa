//! The burn devices: where batched scoring and training run.

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
