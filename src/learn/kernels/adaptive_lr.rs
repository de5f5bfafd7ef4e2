//! PPO's adaptive learning rate from a minibatch's KL as one kernel of ours on the GPU
//! (shaders/adaptive_lr.wgsl), where the tensor ops of `ppo::adapt_learning_rate` launch ~14
//! kernels on a `[1, 1]` tensor every minibatch. The kernel makes the same f32 comparisons and
//! arithmetic as the tensor ops, so the learning rate is the same bit for bit.

use burn::backend::Cube;
use burn::backend::ops::FloatTensorOps;
use burn::prelude::Tensor;
use burn::tensor::{FloatDType, Shape};

use super::wgsl_kernel::{WgslKernel, launch, plain_primitive};

/// shaders/adaptive_lr.wgsl.
const SHADER: &str = include_str!("../../../shaders/adaptive_lr.wgsl");

/// The schedule's thresholds and bounds (f32, as the tensor ops compare them).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AdaptiveLr {
    /// The rate falls (÷ 1.5) above this KL (2 × desired_kl).
    pub above: f32,
    /// The rate rises (× 1.5) below this positive KL (desired_kl / 2).
    pub below: f32,
    /// The rate's floor.
    pub min: f32,
    /// The rate's ceiling.
    pub max: f32,
}

/// The kernel's module (one variant).
pub fn adaptive_lr_source(_: ()) -> String {
    SHADER.to_string()
}

/// The adapted learning rate `[1, 1]` from `lr` `[1, 1]` and the KL at `column` of `kl_row`
/// `[1, n]`, as one kernel, where both are contiguous f32 tensors of burn's wgpu device; None
/// elsewhere (the caller's tensor ops then run).
pub fn adapt_on_gpu(lr: &Tensor<2>, kl_row: &Tensor<2>, column: usize, s: AdaptiveLr) -> Option<Tensor<2>> {
    let n = kl_row.dims()[1];
    if column >= n {
        return None;
    }
    let (lr_p, kl_p) = (plain_primitive(lr, [1, 1]).ok()?, plain_primitive(kl_row, [1, n]).ok()?);
    let out = Cube::float_empty(Shape::new([1, 1]), &lr_p.device, FloatDType::F32); // written whole below
    let constants = [column as u32, s.above.to_bits(), s.below.to_bits(), s.min.to_bits(), s.max.to_bits(), 0];
    let kernel = WgslKernel { name: "dextrain_adaptive_lr", key: (), source: adaptive_lr_source, entry_point: "adaptive_lr", workgroup: [1, 1] };
    launch(kernel, [1, 1, 1], &[&lr_p, &kl_p, &out], &constants);
    Some(Tensor::from_primitive::<Cube>(out))
}
