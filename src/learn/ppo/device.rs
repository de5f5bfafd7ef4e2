//! PPO's device-resident rollouts (docs/gpu.md "The GPU loop"): with the envs and burn's wgpu learner on
//! one wgpu device, observations arrive as tensors ([`crate::task::TaskBatch::step_on_device`]) and
//! everything the host path does with them happens on the device instead:
//! - the empirical normalisers (`normalizer::DeviceNormalizers`: the Chan merge in f32 tensors;
//!   the host keeps only the count, which it knows);
//! - the action noise ([`crate::learn::noise::DeviceNoise`]: the host path's draws, drawn by a
//!   shader, the whole rollout's at its first step), the actions, their log-probabilities and the
//!   values;
//! - the rollout storage (one record of tensors per env step; each step's learner reward and done
//!   flag one kernel of ours) and GAE (one kernel of ours over the rollout, `kernels::ppo_rollout`),
//!   then the advantage normalisation;
//! - the update: the host path's [`Ppo::optimise`], on the concatenated records.
//!
//! What still crosses: the minibatch indices (from the learner RNG on the host, as the host path
//! draws them: one upload per update), the learning rate up and, once per update, the sums of the
//! losses, KL and gradient norms, the learning rate and log σ back (the adaptive learning rate
//! changes on the device: `adapt_learning_rate`), and the noise kernel's 32 bytes of parameters
//! per rollout. The normalisers and the parameters come to the host when a checkpoint is taken.

use anyhow::{Result, ensure};
use burn::prelude::*;

use super::{Batch, LN_2PI, Ppo, UpdateStats};
use crate::gpu::context::GpuContext;
use crate::learn::kernels::mlp_forward::{ActionNoise, forward_acting};
use crate::learn::kernels::ppo_rollout;
use crate::learn::noise::DeviceNoise;
use crate::learn::normalizer::DeviceNormalizers;

/// One env step of the rollout, every tensor `[N, ·]` (the host storage's rows of that step).
struct StepRecord {
    /// Normalised actor / critic observations.
    obs: Tensor<2>,
    priv_obs: Tensor<2>,
    /// Sampled actions and the policy mean (`[N, A]`), σ (`[1, A]`: the same for every env).
    actions: Tensor<2>,
    mu: Tensor<2>,
    sigma: Tensor<2>,
    /// log π(a|s) and V(s) `[N, 1]`.
    log_prob: Tensor<2>,
    values: Tensor<2>,
    /// The learner's reward (time-outs bootstrapped) and the done flag `[N, 2]`, once observed.
    reward_done: Option<Tensor<2>>,
}

/// A block of a rollout's action noise: ε `[K · N, A]` for env steps `first .. first + K` (rows
/// `k · N ..` are step `first + k`'s draw), σ `[1, A]` and the log-probabilities of the actions
/// it makes `[K · N, 1]`. K is the whole rollout unless its noise would not fit one binding of the
/// adapter.
struct RolloutNoise {
    first: usize,
    steps: usize,
    eps: Tensor<2>,
    sigma: Tensor<2>,
    log_prob: Tensor<2>,
}

/// What a device-resident rollout holds beside [`Ppo`]'s networks.
pub struct DeviceRollout {
    noise: DeviceNoise,
    /// The rollout's action noise and what follows from it, made at its first step (in blocks of
    /// `block_steps` env steps).
    noise_block: Option<RolloutNoise>,
    block_steps: usize,
    /// The observation normalisers.
    pub(crate) norms: DeviceNormalizers,
    steps: Vec<StepRecord>,
}

impl Ppo {
    /// From now on the rollouts stay on the learner device, which must be burn's wgpu runtime on
    /// `ctx`'s device (the simulator's): [`Ppo::act_device`], [`Ppo::process_step_device`] and
    /// [`Ppo::update_device`] replace `act`, `process_step` and `update`. Between iterations only.
    pub fn start_device_rollouts(&mut self, ctx: &GpuContext) -> Result<()> {
        ensure!(self.step == 0, "device-resident rollouts must start between iterations");
        ensure!(crate::learn::nets::is_gpu(&self.device), "device-resident rollouts need burn's wgpu learner (train.device = gpu)");
        // a rollout's noise in as few kernels as one storage binding of the adapter allows
        let per_step = (self.storage.envs * self.dims().act).max(1);
        let limit = ctx.device.limits().max_storage_buffer_binding_size as usize / 4;
        let block_steps = (limit / per_step).clamp(1, self.storage.steps.max(1));
        let noise = DeviceNoise::new(ctx, &self.device, block_steps * per_step)?;
        let norms = DeviceNormalizers::from_host(&self.obs_norm, &self.priv_norm, &self.device);
        self.on_device = Some(DeviceRollout { noise, noise_block: None, block_steps, norms, steps: Vec::with_capacity(self.storage.steps) });
        Ok(())
    }

    /// As [`Ppo::act`] on the device: samples actions `[N, A]` for raw observations `obs` `[N, O]`
    /// and `priv_obs` `[N, P]` (the normalisers merge them first) and records the first half of the
    /// transition.
    pub fn act_device(&mut self, obs: &Tensor<2>, priv_obs: &Tensor<2>) -> Result<Tensor<2>> {
        let d = self.dims();
        let n = self.storage.envs;
        ensure!(obs.dims() == [n, d.obs] && priv_obs.dims() == [n, d.priv_obs], "observation sizes do not match the learner");
        ensure!(self.step < self.storage.steps, "rollout storage is full: call update_device()");
        let (seed, draw, normalize) = (self.noise_seed, self.noise_draw, self.normalize);
        let r = self.on_device.as_mut().ok_or_else(|| anyhow::anyhow!("act_device() before start_device_rollouts()"))?;
        let (obs_n, priv_n) = r.norms.update_and_normalize(obs, priv_obs, normalize)?; // merged first, then applied
        let params = self.net.inference_params();
        let t = self.step;
        if r.noise_block.as_ref().is_none_or(|b| t < b.first || t >= b.first + b.steps) {
            // what the parameters fix for the rollout, once (per block): every step's noise in one
            // kernel (draws draw, draw + 1, …: the host path draws the same numbers one step at a
            // time), σ, and every step's log-probability, which depends on ε and σ only:
            // log π(a|s) = −½ Σ ε² − (Σ log σ + ½ A ln 2π)             [K · N, 1]
            let k = r.block_steps.min(self.storage.steps - t);
            let block = r.noise.normals_block(seed, draw, k, n, d.act)?; // ε ~ N(0, 1) [K · N, A]
            let log_std = self.net.log_std(&params); // [1, A]
            let norm_const = log_std.clone().sum_dim(1).add_scalar(0.5 * d.act as f64 * LN_2PI); // [1, 1]
            let log_prob = block.clone().square().sum_dim(1).mul_scalar(-0.5) - norm_const;
            r.noise_block = Some(RolloutNoise { first: t, steps: k, eps: block, sigma: log_std.exp(), log_prob });
        }
        let noise = r.noise_block.as_ref().ok_or_else(|| anyhow::anyhow!("act_device(): the rollout's noise was not drawn"))?;
        let row = (t - noise.first) * n;
        let log_prob = noise.log_prob.clone().narrow(0, row, n); // [N, 1]
        let sigma = noise.sigma.clone(); // [1, A]
        self.noise_draw = draw.wrapping_add(1);
        // μ [N, A] and a = μ + σ ε: without an encoder the actor's one kernel writes both (where it
        // applies), else the actor's forward pass and two tensor ops
        let n_actor = self.net.n_actor();
        let step_noise = ActionNoise { sigma: &noise.sigma, eps: &noise.eps, first_row: row };
        let fused = if self.net.encoder_shapes.is_empty() { forward_acting(&params[..n_actor], &obs_n, self.net.activation, Some(step_noise)) } else { None };
        let (mu, actions) = match fused {
            Some((mu, Some(actions))) => (mu, actions),
            _ => {
                let mu = self.net.actor(&params, obs_n.clone(), priv_n.clone()); // [N, A]
                let eps = noise.eps.clone().narrow(0, row, n); // this step's ε [N, A]
                let actions = mu.clone() + sigma.clone() * eps; // a = μ + σ ε
                (mu, actions)
            }
        };
        let values = self.net.critic(&params, priv_n.clone()); // [N, 1]
        r.steps.push(StepRecord {
            obs: obs_n,
            priv_obs: priv_n,
            actions: actions.clone(),
            mu,
            sigma,
            log_prob,
            values,
            reward_done: None,
        });
        Ok(actions)
    }

    /// As [`Ppo::process_step`] on the device: rewards, terminations and time-outs `[N, 1]` (flags
    /// 0 or 1) of the step the last `act_device` started.
    pub fn process_step_device(&mut self, rewards: &Tensor<2>, terminated: &Tensor<2>, time_outs: &Tensor<2>) -> Result<()> {
        let (scale, gamma) = (self.cfg.reward_scale as f64, self.cfg.gamma as f64);
        let r = self.on_device.as_mut().ok_or_else(|| anyhow::anyhow!("process_step_device() before start_device_rollouts()"))?;
        let rec = r.steps.last_mut().filter(|s| s.reward_done.is_none()).ok_or_else(|| anyhow::anyhow!("process_step_device() without act_device()"))?;
        // flags 0 or 1: done = max(terminated, time-out); a time-out that is not a termination is
        // done − terminated. r = scale · r_env + γ V(s_t) on it (bootstrap through the time-out);
        // one kernel of ours
        rec.reward_done = Some(ppo_rollout::step_reward(rewards, terminated, time_outs, &rec.values, scale, gamma)?);
        self.step += 1;
        self.storage.len = self.step * self.storage.envs;
        Ok(())
    }

    /// As [`Ppo::update`] on the device: GAE from the critic's value of `last_priv_obs` (raw,
    /// `[N, P]`), the advantage normalisation, then the epochs of minibatches.
    pub fn update_device(&mut self, last_priv_obs: &Tensor<2>) -> Result<UpdateStats> {
        ensure!(self.rollout_full(), "update_device() before the rollout is full ({} of {} steps)", self.step, self.storage.steps);
        let (gamma, lam, normalize) = (self.cfg.gamma as f64, self.cfg.lam as f64, self.normalize);
        let r = self.on_device.as_mut().ok_or_else(|| anyhow::anyhow!("update_device() before start_device_rollouts()"))?;
        let steps = std::mem::take(&mut r.steps);
        r.noise_block = None;
        let priv_n = r.norms.priv_obs.normalized(last_priv_obs.clone(), normalize);
        let last_values = self.net.critic(&self.net.inference_params(), priv_n); // [N, 1]
        // GAE backwards in time (storage.rs's `gae`), one kernel of ours over the whole rollout:
        // δ_t = r_t + γ V(s_{t+1}) (1 − d_t) − V(s_t), A_t = δ_t + γλ (1 − d_t) A_{t+1}, R_t = A_t + V(s_t)
        let t_len = steps.len();
        // the steps' tensors stacked: a few kernels of ours per tensor (kernels::cat_rows) where
        // burn's cat launches one per step
        let stack = crate::learn::nets::stack_rows;
        let cat = |f: &dyn Fn(&StepRecord) -> Tensor<2>| stack(steps.iter().map(f).collect());
        let reward_done = steps
            .iter()
            .enumerate()
            .map(|(t, s)| s.reward_done.clone().ok_or_else(|| anyhow::anyhow!("update_device(): step {t} of the rollout was never observed")))
            .collect::<Result<Vec<_>>>()?;
        let reward_done = stack(reward_done); // [T·N, 2]
        let values = cat(&|s| s.values.clone()); // [T·N, 1]
        let adv = ppo_rollout::gae(&reward_done, &values, &last_values, t_len, gamma, lam)?; // [T·N, 1]
        let returns = adv.clone() + values.clone();
        // normalised over the rollout: zero mean, unit (unbiased, as torch's .std()) std
        let total = adv.dims()[0];
        let mean = crate::learn::nets::mean_all(adv.clone());
        let centred = adv - mean.unsqueeze::<2>();
        let var = crate::learn::nets::sum_all(centred.clone().square()).div_scalar((total as f64 - 1.0).max(1.0));
        let advantages = centred / var.sqrt().add_scalar(1e-8).unsqueeze::<2>();
        let all = Batch {
            obs: cat(&|s| s.obs.clone()),
            priv_obs: cat(&|s| s.priv_obs.clone()),
            actions: cat(&|s| s.actions.clone()),
            old_log_prob: cat(&|s| s.log_prob.clone()),
            old_mu: cat(&|s| s.mu.clone()),
            old_sigma: steps.first().map(|s| s.sigma.clone()).ok_or_else(|| anyhow::anyhow!("update_device(): an empty rollout"))?, // [1, A]: the parameters did not change during the rollout
            advantages,
            returns,
            old_values: values,
        };
        drop(steps);
        self.storage.clear();
        self.optimise(all, total)
    }
}
