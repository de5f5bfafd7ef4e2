//! The learner: PPO on burn tensors (CPU `flex` backend or burn's wgpu backend).
//!
//! - `rng.rs`: the host RNG (one `u64` of state, saved in checkpoints);
//! - `normalizer.rs`: empirical observation normalisation;
//! - `storage.rs`: rollout storage and GAE;
//! - `nets.rs`: MLPs as flat lists of `Tensor<2>`, Adam, global gradient-norm clipping;
//! - `ppo.rs`: the algorithm;
//! - `device.rs`: choosing the learner device (`train.device`).

pub mod device;
pub mod nets;
pub mod normalizer;
pub mod ppo;
pub mod rng;
pub mod storage;
