//! PPO's device-resident rollouts (README "The GPU loop"): with the envs and burn's wgpu learner on
//! one wgpu device, observations arrive as tensors ([`crate::task::TaskBatch::step_on_device`]) and
//! everything the host path does with them happens on the device instead:
//! - the empirical normalisers (`normalizer::DeviceNormalizers`: the Chan merge in f32 tensors;
//!   the host keeps only the count, which it knows);
//! - the action noise ([`crate::learn::noise::DeviceNoise`]: the host path's draws, drawn by a
//!   shader), the actions, their log-probabilities and the values;
//! - the rollout storage (one record of tensors per env step) and GAE, a backward loop of
//!   `[N, 1]` tensor ops over the rollout's steps, then the advantage normalisation;
//! - the update: the host path's [`Ppo::optimise`], on the concatenated records.
//!
//! What still crosses: the minibatch indices (from the learner RNG on the host, as the host path
//! draws them), four loss scalars and the gradient norm per minibatch (the adaptive learning rate
//! decides on the host, as rsl_rl's does), σ after the update, and 16 bytes of noise parameters
//! per env step. The normalisers and the parameters come to the host when a checkpoint is taken.

use anyhow::{Result, ensure};
use burn::prelude::*;

use super::{Batch, LN_2PI, Ppo, UpdateStats};
use crate::env::gpu::GpuContext;
use crate::learn::noise::DeviceNoise;
use crate::learn::normalizer::DeviceNormalizers;

/// One env step of the rollout, every tensor `[N, ·]` (the host storage's rows of that step).
struct StepRecord {
    /// Normalised actor / critic observations.
    obs: Tensor<2>,
    priv_obs: Tensor<2>,
    /// Sampled actions, the policy mean and σ (`[N, A]`).
    actions: Tensor<2>,
    mu: Tensor<2>,
    sigma: Tensor<2>,
    /// log π(a|s) and V(s) `[N, 1]`.
    log_prob: Tensor<2>,
    values: Tensor<2>,
    /// The learner's reward (time-outs bootstrapped) and the done flags `[N, 1]`, once observed.
    rewards: Option<Tensor<2>>,
    dones: Option<Tensor<2>>,
}

/// What a device-resident rollout holds beside [`Ppo`]'s networks.
pub struct DeviceRollout {
    noise: DeviceNoise,
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
        let noise = DeviceNoise::new(ctx, &self.device, self.storage.envs * self.dims().act)?;
        let norms = DeviceNormalizers::from_host(&self.obs_norm, &self.priv_norm, &self.device);
        self.on_device = Some(DeviceRollout { noise, norms, steps: Vec::with_capacity(self.storage.steps) });
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
        if normalize {
            r.norms.obs.update(obs);
            r.norms.priv_obs.update(priv_obs);
        }
        let obs_n = r.norms.obs.normalized(obs.clone(), normalize);
        let priv_n = r.norms.priv_obs.normalized(priv_obs.clone(), normalize);
        let params = self.net.inference_params();
        let mu = self.net.actor(&params, obs_n.clone(), priv_n.clone()); // [N, A]
        let values = self.net.critic(&params, priv_n.clone()); // [N, 1]
        let log_std = self.net.log_std(&params); // [1, A]
        let sigma = log_std.clone().exp(); // [1, A]
        let eps = r.noise.normals(seed, draw, n, d.act)?; // ε ~ N(0, 1) [N, A]
        self.noise_draw = draw.wrapping_add(1);
        let actions = mu.clone() + sigma.clone() * eps.clone(); // a = μ + σ ε
        // log π(a|s) = −½ Σ ε² − Σ log σ − ½ A ln 2π            [N, 1]
        let log_prob = eps.square().sum_dim(1).mul_scalar(-0.5) - log_std.sum_dim(1);
        let log_prob = log_prob.sub_scalar(0.5 * d.act as f64 * LN_2PI);
        r.steps.push(StepRecord {
            obs: obs_n,
            priv_obs: priv_n,
            actions: actions.clone(),
            mu,
            sigma: sigma.repeat_dim(0, n),
            log_prob,
            values,
            rewards: None,
            dones: None,
        });
        Ok(actions)
    }

    /// As [`Ppo::process_step`] on the device: rewards, terminations and time-outs `[N, 1]` (flags
    /// 0 or 1) of the step the last `act_device` started.
    pub fn process_step_device(&mut self, rewards: &Tensor<2>, terminated: &Tensor<2>, time_outs: &Tensor<2>) -> Result<()> {
        let (scale, gamma) = (self.cfg.reward_scale as f64, self.cfg.gamma as f64);
        let r = self.on_device.as_mut().ok_or_else(|| anyhow::anyhow!("process_step_device() before start_device_rollouts()"))?;
        let rec = r.steps.last_mut().filter(|s| s.rewards.is_none()).ok_or_else(|| anyhow::anyhow!("process_step_device() without act_device()"))?;
        // r = scale · r_env + γ V(s_t) on a time-out that is not a termination (bootstrap through it)
        let timeout_only = time_outs.clone() * terminated.ones_like().sub(terminated.clone());
        rec.rewards = Some(rewards.clone().mul_scalar(scale) + rec.values.clone().mul_scalar(gamma) * timeout_only);
        rec.dones = Some((terminated.clone() + time_outs.clone()).clamp(0.0, 1.0));
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
        let priv_n = r.norms.priv_obs.normalized(last_priv_obs.clone(), normalize);
        let last_values = self.net.critic(&self.net.inference_params(), priv_n); // [N, 1]
        // GAE backwards in time (storage.rs's `gae`, as [N, 1] tensor ops):
        // δ_t = r_t + γ V(s_{t+1}) (1 − d_t) − V(s_t), A_t = δ_t + γλ (1 − d_t) A_{t+1}, R_t = A_t + V(s_t)
        let t_len = steps.len();
        let mut advantages: Vec<Tensor<2>> = Vec::with_capacity(t_len);
        let mut next_adv: Option<Tensor<2>> = None;
        for t in (0..t_len).rev() {
            let s = &steps[t];
            let (rew, done) = match (&s.rewards, &s.dones) {
                (Some(r), Some(d)) => (r.clone(), d.clone()),
                _ => anyhow::bail!("update_device(): step {t} of the rollout was never observed"),
            };
            let next_value = if t + 1 == t_len { last_values.clone() } else { steps[t + 1].values.clone() };
            let not_done = done.ones_like() - done;
            let delta = rew + next_value.mul_scalar(gamma) * not_done.clone() - s.values.clone(); // δ
            let adv = match next_adv {
                Some(a) => delta + a.mul_scalar(gamma * lam) * not_done, // A = δ + γλ (1 − d) A'
                None => delta,
            };
            advantages.push(adv.clone());
            next_adv = Some(adv);
        }
        advantages.reverse();
        let cat = |f: &dyn Fn(&StepRecord) -> Tensor<2>| Tensor::cat(steps.iter().map(f).collect(), 0);
        let values = cat(&|s| s.values.clone()); // [T·N, 1]
        let adv = Tensor::cat(advantages, 0); // [T·N, 1]
        let returns = adv.clone() + values.clone();
        // normalised over the rollout: zero mean, unit (unbiased, as torch's .std()) std
        let total = adv.dims()[0];
        let mean = adv.clone().mean();
        let centred = adv - mean.unsqueeze::<2>();
        let var = crate::learn::nets::sum_all(centred.clone().square()).div_scalar((total as f64 - 1.0).max(1.0));
        let advantages = centred / var.sqrt().add_scalar(1e-8).unsqueeze::<2>();
        let all = Batch {
            obs: cat(&|s| s.obs.clone()),
            priv_obs: cat(&|s| s.priv_obs.clone()),
            actions: cat(&|s| s.actions.clone()),
            old_log_prob: cat(&|s| s.log_prob.clone()),
            old_mu: cat(&|s| s.mu.clone()),
            old_sigma: cat(&|s| s.sigma.clone()),
            advantages,
            returns,
            old_values: values,
        };
        drop(steps);
        self.storage.clear();
        self.optimise(all, total)
    }
}
