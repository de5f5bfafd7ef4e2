//! PPO's device-resident rollout bookkeeping as kernels of ours (`ppo/device.rs`): each env step's
//! learner reward and done flag (shaders/ppo_step_reward.wgsl, one kernel where the tensor ops were
//! seven), and GAE over the whole rollout (shaders/gae.wgsl, one kernel where the backward loop of
//! `[N, 1]` tensor ops launched ~9 per env step). The kernels make the tensor ops' f32 operations
//! in their order (a hardware driver may still contract a product and a sum into one rounding), so
//! on lavapipe the rollout's numbers are those of before; every run repeats bit for bit.

use anyhow::{Context, Result, anyhow};
use burn::backend::Cube;
use burn::backend::ops::FloatTensorOps;
use burn::backend::tensor::FloatTensor;
use burn::prelude::Tensor;
use burn::tensor::{FloatDType, Shape};

use super::wgsl_kernel::{WgslKernel, launch, plain_primitive};

/// shaders/ppo_step_reward.wgsl and shaders/gae.wgsl.
const SHADER_STEP_REWARD: &str = include_str!("../../../shaders/ppo_step_reward.wgsl");
const SHADER_GAE: &str = include_str!("../../../shaders/gae.wgsl");
/// Invocations per workgroup (one per env).
const WORKGROUP: u32 = 64;

/// The step-reward kernel's module (one variant).
pub fn step_reward_source(_: ()) -> String {
    SHADER_STEP_REWARD.to_string()
}

/// The GAE kernel's module (one variant).
pub fn gae_source(_: ()) -> String {
    SHADER_GAE.to_string()
}

/// `t`'s primitive on burn's wgpu device (the autodiff wrapper, if any, dropped), checked to be a
/// contiguous f32 `shape` tensor.
fn cube(t: &Tensor<2>, shape: [usize; 2], what: &str) -> Result<FloatTensor<Cube>> {
    plain_primitive(&t.clone().inner(), shape).with_context(|| format!("PPO's device-resident rollout: {what}"))
}

/// One workgroup per 64 envs, on a 1-D grid.
fn groups(envs: usize) -> Result<u32> {
    u32::try_from(envs.div_ceil(WORKGROUP as usize)).ok().filter(|&g| g <= 65_535).ok_or_else(|| anyhow!("PPO's device-resident rollout: {envs} envs are more than one kernel's grid"))
}

/// `out` as a tensor on the kind of device of `like` (with autodiff where `like` has it).
fn like(out: FloatTensor<Cube>, like: &Tensor<2>) -> Tensor<2> {
    let t = Tensor::from_primitive::<Cube>(out);
    if like.device().is_autodiff() { t.autodiff() } else { t }
}

/// `[r', done]` `[N, 2]` of one env step from the env's rewards, terminated and time-out flags and
/// the critic's values `V(s_t)`, each `[N, 1]`: `done = max(terminated, time-out)`,
/// `r' = scale · r + (γ V(s_t)) · (done − terminated)`.
pub fn step_reward(rewards: &Tensor<2>, terminated: &Tensor<2>, time_outs: &Tensor<2>, values: &Tensor<2>, scale: f64, gamma: f64) -> Result<Tensor<2>> {
    let n = rewards.dims()[0];
    let shape = [n, 1];
    let (r, te, to, v) = (cube(rewards, shape, "the rewards")?, cube(terminated, shape, "the terminated flags")?, cube(time_outs, shape, "the time-out flags")?, cube(values, shape, "the values")?);
    let out = Cube::float_empty(Shape::new([n, 2]), &r.device, FloatDType::F32); // written whole below
    let kernel = WgslKernel { name: "dextrain_ppo_step_reward", key: (), source: step_reward_source, entry_point: "ppo_step_reward", workgroup: [WORKGROUP, 1] };
    launch(kernel, [groups(n)?, 1, 1], &[&r, &te, &to, &v, &out], &[n as u32, 0, (scale as f32).to_bits(), (gamma as f32).to_bits()]);
    Ok(like(out, values))
}

/// The advantages `[T · N, 1]` of a rollout of `steps` env steps of N envs from each step's
/// `[r', done]` `[T · N, 2]`, the values `[T · N, 1]` and the value of the state after the last
/// step `[N, 1]` (rows `t · N + i`).
pub fn gae(reward_done: &Tensor<2>, values: &Tensor<2>, last_values: &Tensor<2>, steps: usize, gamma: f64, lam: f64) -> Result<Tensor<2>> {
    let n = last_values.dims()[0];
    let rd = cube(reward_done, [steps * n, 2], "the rewards and done flags")?;
    let (v, last) = (cube(values, [steps * n, 1], "the values")?, cube(last_values, [n, 1], "the last values")?);
    let adv = Cube::float_empty(Shape::new([steps * n, 1]), &v.device, FloatDType::F32); // written whole below
    let kernel = WgslKernel { name: "dextrain_gae", key: (), source: gae_source, entry_point: "gae", workgroup: [WORKGROUP, 1] };
    let constants = [n as u32, steps as u32, (gamma as f32).to_bits(), ((gamma * lam) as f32).to_bits()];
    launch(kernel, [groups(n)?, 1, 1], &[&rd, &v, &last, &adv], &constants);
    Ok(like(adv, values))
}
