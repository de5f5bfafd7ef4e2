//! The learners' numerical building blocks, apart from the algorithms that use them (`ppo/`,
//! `sac/`, `distill.rs`): each an operation on burn tensors with its own gradient, or a kernel of
//! ours, on the CPU (burn flex) and the GPU (burn's wgpu backend) alike.
//!
//! - `affine.rs`: a dense layer `x W + b` (and with its ELU) as one operation with its own gradient
//!   (no copies on the CPU; one kernel of ours on the GPU);
//! - `layer_norm.rs`: LayerNorm over the features as one operation with its own gradient (one pass
//!   per row on the CPU; a kernel of ours each way on the GPU, shaders/layer_norm*.wgsl);
//! - `elu.rs`: ELU as one operation with its own gradient (vectorised on the CPU; one kernel of
//!   ours each way on the GPU, shaders/elu_forward.wgsl and shaders/elu_backward.wgsl);
//! - `sgemm.rs`: dextrain's own AVX2 + FMA matrix product; `isa.rs`: which vector instruction set
//!   the CPU kernels run (`DEXTRAIN_SIMD`);
//! - `gpu_matmul.rs`: the routine of the GPU learner's products (chosen by measurement,
//!   `DEXTRAIN_GPU_MATMUL`); `wgsl_matmul.rs`: the tiled product of our own (shaders/matmul.wgsl),
//!   the default routine; `matmul_tuning.rs`: its tile shape per product timed on the adapter
//!   (`dextrain_tuned`, the same numbers whichever wins); `wgsl_kernel.rs`: how our own WGSL kernels launch on burn's command stream;
//! - `squashed.rs`: SAC's squashed-Gaussian sample and its log-probability as one operation with
//!   its own gradient (a kernel of ours each way on the GPU, shaders/squashed_sample*.wgsl);
//! - `ppo_loss.rs`, `sac_loss.rs`: PPO's loss of a minibatch and SAC's critic and actor losses as
//!   one operation each with its own gradient (kernels of ours on the GPU, tensor ops elsewhere);
//!   `adaptive_lr.rs`: PPO's adaptive learning rate as one kernel on the GPU; `standardize.rs`: a
//!   GPU learner's host-path observations standardised by one kernel; `ppo_rollout.rs`: PPO's
//!   device-resident step reward and GAE as kernels of ours; `replay_sample.rs`: SAC's
//!   device-resident batch (the rings' rows gathered and normalised, the n-step windows) as kernels
//!   of ours;
//! - `mlp_forward.rs`: an MLP's forward pass for acting as one kernel on the GPU
//!   (shaders/mlp_forward.wgsl; the per-layer products' values bit for bit);
//! - `row_sums.rs`: sums over the batch's rows in two stages on the GPU (losses, ∂b, ∂ log σ);
//! - `cat_rows.rs`: row blocks stacked into one tensor (a PPO rollout's steps) in a few kernels of
//!   ours on the GPU (shaders/cat_rows.wgsl), where burn's cat launches one per block;
//! - `fused_adam.rs`: Adam with global-norm clipping as kernels of ours on the GPU
//!   (shaders/adam.wgsl); `fused_normalizer.rs`: the device-resident observation normalisers
//!   (shaders/normalizer.wgsl).

pub mod adaptive_lr;
pub mod affine;
pub mod cat_rows;
pub mod elu;
pub mod fused_adam;
pub mod fused_normalizer;
pub mod gpu_matmul;
pub mod isa;
pub mod layer_norm;
pub mod matmul_tuning;
pub mod mlp_forward;
pub mod ppo_loss;
pub mod ppo_rollout;
pub mod replay_sample;
pub mod row_sums;
pub mod sac_loss;
pub mod sgemm;
pub mod squashed;
pub mod standardize;
pub mod wgsl_kernel;
pub mod wgsl_matmul;

use burn::backend::tensor::FloatTensor;
use burn::backend::{Backend, TensorMetadata};

/// Columns `[from, to)` of a `[B, n]` tensor of `B` (the fused ops' tensor-op twins).
pub(crate) fn columns<B: Backend>(t: FloatTensor<B>, from: usize, to: usize) -> FloatTensor<B> {
    let rows = t.shape()[0];
    B::float_slice(t, &[burn::tensor::Slice::from(0..rows), burn::tensor::Slice::from(from..to)])
}

/// The mean of a `[B, 1]` tensor of `B` as `[1, 1]`.
pub(crate) fn mean_11<B: Backend>(t: FloatTensor<B>) -> FloatTensor<B> {
    B::float_reshape(B::float_mean(t), burn::tensor::Shape::new([1, 1]))
}
