//! The learners, on burn tensors (CPU `flex` backend or burn's wgpu backend).
//!
//! Shared by every algorithm:
//! - `kernels/`: the numerical building blocks, apart from the algorithms (see its `mod.rs`):
//!   dense layers, LayerNorm and ELU as single ops with their own gradients, the GPU's matrix
//!   products and sums, our WGSL kernels on burn's stream, the fused optimiser and normalisers,
//!   the CPU's vector kernels;
//! - `nets.rs`: MLPs as flat lists of `Tensor<2>`;
//! - `adam.rs`: Adam and global gradient-norm clipping;
//! - `normalizer.rs`: empirical observation normalisation;
//! - `noise.rs`: the learners' action noise (the counter hash, on the host or the device);
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
pub mod device;
pub mod kernels;
pub mod distill;
pub mod gru;
pub mod nets;
pub mod policy;
pub mod noise;
pub mod normalizer;
pub mod ppo;
pub mod sac;
pub mod state;
pub mod tcn;
