//! The one place that builds a trained policy from a checkpoint directory (its `model.safetensors`):
//! eval, export, `play`'s checks and distillation's teacher all load through here, and the run's
//! `train.algorithm` decides, in [`load_policy`] alone, which learner is built.

use std::path::Path;

use anyhow::{Context, Result};
use burn::prelude::Device;

use super::ppo::Dims;
use super::checkpoint;
use super::distill::StudentPolicy;
use super::ppo::{Ppo, encoder_index};
use super::sac::Sac;
use crate::config::{AlgorithmChoice, Config};
use crate::task::TaskSpec;

/// A run's trained policy, as its algorithm made it.
pub enum LoadedPolicy {
    /// A PPO run's actor (and critic, normalisers, encoder).
    Ppo(Box<Ppo>),
    /// A SAC run's actor, critics and normalisers.
    Sac(Box<Sac>),
    /// A distillation run's student.
    Student(Box<StudentPolicy>),
}

/// The dimensions of a task's policy.
pub fn dims_of(spec: &TaskSpec) -> Dims {
    Dims { obs: spec.obs_dim, priv_obs: spec.priv_dim, act: spec.action_dim }
}

/// The PPO policy of `cfg` (a PPO run's resolved config) in checkpoint `ckpt`, for `n` envs on
/// `device`; `seed` seeds the learner's own random numbers (its sampled actions).
pub fn load_ppo(cfg: &Config, spec: &TaskSpec, ckpt: &Path, n: usize, device: Device, seed: u64) -> Result<Ppo> {
    let encoder = encoder_index(&cfg.policy, spec).with_context(|| cfg.source.display().to_string())?;
    let mut ppo = Ppo::new(dims_of(spec), n, 1, &cfg.ppo, &cfg.policy, &encoder, device, seed)?;
    checkpoint::load_model(&ckpt.join("model.safetensors"), &mut ppo).with_context(|| format!("cannot load the policy of {}", ckpt.display()))?;
    Ok(ppo)
}

/// The policy of run config `cfg` in checkpoint `ckpt`, for `n` envs on `device`: PPO's or SAC's
/// (SAC's parameters are autodiff leaves: it loads on `device`'s autodiff form), or a
/// distillation run's student (`spec.obs_dim` wide).
pub fn load_policy(cfg: &Config, spec: &TaskSpec, ckpt: &Path, n: usize, device: Device) -> Result<LoadedPolicy> {
    Ok(match cfg.train.algorithm {
        AlgorithmChoice::Ppo => LoadedPolicy::Ppo(Box::new(load_ppo(cfg, spec, ckpt, n, device, cfg.seed as u64)?)),
        AlgorithmChoice::Sac => LoadedPolicy::Sac(Box::new(Sac::from_checkpoint(dims_of(spec), n, cfg, ckpt, device.autodiff())?)),
        AlgorithmChoice::Distill => LoadedPolicy::Student(Box::new(StudentPolicy::load(ckpt, spec.obs_dim, &device)?)),
    })
}
