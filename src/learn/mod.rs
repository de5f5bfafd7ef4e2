//! The learners, on burn tensors (CPU `flex` backend or burn's wgpu backend).
//!
//! Shared by every algorithm:
//! - `nets.rs`: MLPs as flat lists of `Tensor<2>`;
//! - `affine.rs`: a dense layer `x W + b` as one operation with its own gradient (no copies on the CPU);
//! - `layer_norm.rs`: LayerNorm over the features as one operation with its own gradient;
//! - `elu.rs`: ELU as one operation with its own gradient (a vectorised one on the CPU);
//! - `gpu_matmul.rs`: the matmul routine of the GPU learner's products (chosen by measurement);
//!   `wgsl_matmul.rs`: a tiled product of our own (shaders/matmul.wgsl), the default routine;
//!   `wgsl_kernel.rs`: how our own WGSL kernels are launched on burn's command stream;
//! - `row_sums.rs`: sums over the batch's rows in two stages on the GPU (losses, ∂b, ∂ log σ);
//! - `adam.rs`: Adam and global gradient-norm clipping;
//! - `normalizer.rs`: empirical observation normalisation;
//! - the host RNG is `crate::rng` (one `u64` of state, saved in checkpoints; base layer);
//! - `device.rs`: choosing the learner device (`train.device`);
//! - `state.rs`: a learner's checkpoint state (named tensors and exact scalars); `checkpoint.rs`:
//!   checkpoint directories on disk (atomic writes, manifests, finding the latest);
//! - `policy.rs`: the one loader of a trained policy from a checkpoint (PPO, SAC or a student);
//! - `gru.rs`: a GRU on flat tensors (the student's adaptation module; ONNX's GRU formulation).
//! - `tcn.rs`: a temporal convolution on flat tensors (the student's other adaptation module; ONNX's Conv).
//!
//! One room per algorithm: `ppo/` (rollout storage, GAE, PPO), `sac/` (replay buffer, SAC),
//! `distill.rs` (the student and online DAgger from a teacher run); the loop that drives them is
//! `run/`. A burn tensor's wgpu buffer is reached through `crate::gpu::io`.

pub mod adam;
pub mod checkpoint;
pub mod affine;
pub mod device;
pub mod distill;
pub mod elu;
pub mod fused_adam;
pub mod fused_normalizer;
pub mod gpu_matmul;
pub mod gru;
pub mod isa;
pub mod layer_norm;
pub mod nets;
pub mod policy;
pub mod noise;
pub mod normalizer;
pub mod ppo;
pub mod row_sums;
pub mod sac;
pub mod sgemm;
pub mod state;
pub mod tcn;
pub mod wgsl_kernel;
pub mod wgsl_matmul;
