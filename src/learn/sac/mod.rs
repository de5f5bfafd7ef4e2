//! Soft Actor-Critic (Haarnoja et al. 2018) as the massively parallel off-policy learners build it
//! (FastTD3, FastSAC: thousands of envs, large batches, several gradient steps per env step),
//! top to bottom in one file.
//!
//! - Actor: an MLP on the normalised actor observation ŝ whose `2|A|` outputs are the mean μ and a
//!   pre-activation of log σ, squashed into `[log_std_min, log_std_max]`; actions
//!   `a = tanh(μ + σ ε)`, ε ~ N(0, I) (the squashed Gaussian). Deterministic action: `tanh(μ)`.
//! - `num_critics` Q networks `Q_j(ĉ, a)` on the normalised critic observation (asymmetric), each
//!   with a target network `θ̄_j ← τ θ_j + (1 − τ) θ̄_j` after every critic update.
//! - Critic loss `Σ_j mean((Q_j(ĉ, a) − y)²)` with the n-step target
//!   `y = R + β (red_j Q̄_j(ĉ', a') − α log π(a'|s'))`, a' ~ π(·|s'), `red` = min or mean
//!   (`sac.q_reduction`), R and β from the replay buffer (`buffer.rs`: β = γᵐ, 0 after a termination).
//! - Actor loss `mean(α log π(ã|s) − red_j Q_j(ĉ, ã))`, ã ~ π(·|s) (reparameterised), every
//!   `policy_frequency`-th critic update; the critics are constants in it.
//! - Temperature: `L(log α) = −mean(log α · (log π(ã|s) + H̄))`, H̄ = `target_entropy_scale` × (−|A|):
//!   α grows while the entropy −log π is below H̄.
//! - Adam (AdamW with `weight_decay`) per network group, optional gradient-norm clipping.
//!
//! The batch draws come from one host `Rng`, the random actions and the action noise from the
//! counter hash (`learn::noise`: draw number `noise_draw`; one draw per env step, two per gradient
//! step), so the host and the device draw the same numbers. Saved in checkpoints with the networks,
//! targets, optimisers, log α, normalisers, counters and (`sac.checkpoint_buffer`) the replay
//! buffer: a resumed run continues bit for bit (on the CPU).
//!
//! `device.rs`: the same learner with the replay buffer and the env loop's tensors on the learner
//! device (the envs and the learner on one GPU: `run/device_loop.rs`).

pub mod buffer;
pub mod device;

use anyhow::{Result, ensure};
use burn::prelude::*;

use self::buffer::{ReplayBuffer, Sample, Transitions};
use super::adam::Adam;
use super::kernels::sac_loss::{SacLoss, sac_loss_fused};
use super::kernels::squashed::squashed_sample_fused;
use super::nets::{self, Activation, MlpLayout, to_host, to_tensor};
use super::noise::{host_normals_from_row, host_uniforms_from_row};
use super::normalizer::Normalizer;
use super::ppo::Dims;
use crate::rng::Rng;
use super::state::{LearnerState, TensorValues};
use crate::config::{PolicyConfig, QReduction, SacConfig};

/// The state file of the policy and critics (and normalisers): `model.safetensors`.
pub const MODEL_FILE: &str = "model";
/// The state file of the optimisers' moments: `optimizer.safetensors`.
pub const OPTIMIZER_FILE: &str = "optimizer";
/// The state file of the replay buffer: `replay.safetensors`.
pub const BUFFER_FILE: &str = "replay";

const LN_2PI: f64 = 1.837_877_066_409_345_3; // ln(2π)
const LN_2: f64 = std::f64::consts::LN_2;

/// log σ squashed into [lo, hi]: `lo + ½ (hi − lo)(tanh(x) + 1)`.
pub fn squash_log_std(x: Tensor<2>, lo: f64, hi: f64) -> Tensor<2> {
    x.tanh().add_scalar(1.0).mul_scalar(0.5 * (hi - lo)).add_scalar(lo)
}

/// A squashed-Gaussian sample `a = tanh(u)`, `u = μ + σ ε`, and its log-probability [B, 1]:
/// `log π(a|s) = Σ_k [−½ ε_k² − log σ_k − ½ ln 2π − log(1 − tanh² u_k)]`, with the correction
/// written stably as `log(1 − tanh² u) = 2 (ln 2 − u − softplus(−2u))`.
pub fn squashed_sample(mu: Tensor<2>, log_std: Tensor<2>, eps: Tensor<2>) -> (Tensor<2>, Tensor<2>) {
    let [_, a] = mu.dims();
    let u = mu + log_std.clone().exp() * eps.clone(); // u = μ + σ ε
    let gauss = eps.square().mul_scalar(-0.5) - log_std; // −½ ε² − log σ
    let x = u.clone().mul_scalar(-2.0);
    let softplus = burn::tensor::activation::relu(x.clone()) + x.abs().neg().exp().log1p(); // max(x, 0) + ln(1 + e^{−|x|})
    let log_det = (u.clone().neg().add_scalar(LN_2) - softplus).mul_scalar(2.0); // log(1 − tanh² u)
    let log_prob = (gauss - log_det).sum_dim(1).sub_scalar(0.5 * a as f64 * LN_2PI); // [B, 1]
    (u.tanh(), log_prob)
}

/// The critics' values [B, 1] combined: the smallest or the mean.
fn reduce(qs: Vec<Tensor<2>>, how: QReduction) -> Tensor<2> {
    let k = qs.len();
    let mut it = qs.into_iter();
    let first = it.next().expect("at least one critic");
    match how {
        QReduction::Min => it.fold(first, |acc, q| acc.min_pair(q)),
        QReduction::Mean => it.fold(first, |acc, q| acc + q).div_scalar(k as f64),
    }
}

/// What the gradient steps of one iteration did (means over them).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SacStats {
    /// Σ_j mean((Q_j − y)²).
    pub critic_loss: f64,
    /// mean(α log π − Q).
    pub actor_loss: f64,
    /// The temperature α after the last step.
    pub alpha: f64,
    /// −mean log π(ã|s) over the actor's batches (the policy's entropy estimate).
    pub entropy: f64,
    /// mean Q_j(ĉ, a) over the critics and the batch.
    pub q_mean: f64,
    /// Gradient steps (critic updates) in this iteration.
    pub updates: u64,
    /// Transitions in the replay buffer.
    pub buffer_transitions: u64,
}

/// Sums behind [`SacStats`].
#[derive(Clone, Debug, Default)]
struct StatSums {
    /// Σ [critic loss, mean Q] over the critic steps `[1, 2]` (on the learner device: read by
    /// `take_stats`, not by each gradient step).
    critic: Option<Tensor<2>>,
    critic_steps: u64,
    /// Σ [actor loss, entropy estimate] over the actor steps `[1, 2]`.
    actor: Option<Tensor<2>>,
    actor_steps: u64,
}

/// `acc + row`, or `row` for the first.
fn accumulate(acc: Option<Tensor<2>>, row: Tensor<2>) -> Option<Tensor<2>> {
    Some(match acc {
        Some(a) => a + row,
        None => row,
    })
}

/// The first half of a transition, kept from `act` to `observe`.
struct Pending {
    obs: Vec<f32>,
    priv_obs: Vec<f32>,
    actions: Vec<f32>,
}

/// The SAC learner: actor, critics and targets, optimisers, temperature, normalisers, replay buffer, RNG.
pub struct Sac {
    /// The `[sac]` settings.
    pub cfg: SacConfig,
    /// The learner device.
    pub device: Device,
    /// Input and output sizes.
    pub dims: Dims,
    /// Hidden activation (`policy.activation`).
    pub activation: Activation,
    /// The actor: ŝ [B, O] → [μ, x] [B, 2A].
    pub actor_layout: MlpLayout,
    /// Each critic: [ĉ, a] [B, P + A] → Q [B, 1].
    pub critic_layout: MlpLayout,
    /// The actor's parameters (autodiff leaves).
    pub actor: Vec<Tensor<2>>,
    /// Each critic's parameters (autodiff leaves).
    pub critics: Vec<Vec<Tensor<2>>>,
    /// Each target critic's parameters (no autodiff).
    pub targets: Vec<Vec<Tensor<2>>>,
    /// log α [1, 1] (autodiff leaf).
    pub log_alpha: Tensor<2>,
    /// The actor's optimiser.
    pub actor_adam: Adam,
    /// The critics' optimiser (all critics' parameters in one list).
    pub critic_adam: Adam,
    /// log α's optimiser.
    pub alpha_adam: Adam,
    /// Whether observations are normalised (`policy.obs_normalization`).
    pub normalize: bool,
    /// Actor observation normaliser.
    pub obs_norm: Normalizer,
    /// Critic observation normaliser.
    pub priv_norm: Normalizer,
    /// The replay buffer.
    pub buffer: ReplayBuffer,
    /// Batch draws.
    pub rng: Rng,
    /// Env steps of every env taken so far (transitions pushed).
    pub env_steps: u64,
    /// Critic updates so far.
    pub critic_updates: u64,
    /// The target entropy H̄.
    pub target_entropy: f64,
    pending: Option<Pending>,
    sums: StatSums,
    /// The random actions' and the action noise's stream (`learn::noise`): from the seed.
    noise_seed: u32,
    /// Draws so far (saved in checkpoints).
    noise_draw: u32,
    /// Global id of this learner's first env (rank r of a data-parallel job: r · num_envs): its
    /// acting noise is its envs' rows of the job's draw; 0 with one rank.
    env_offset: u32,
    /// The first row of this rank's batch noise (r · batch_size): every rank's batch draws rows
    /// of its own of the job's draw, as one batch of ranks × batch_size would; 0 with one rank.
    batch_first_row: u32,
    /// The device-resident loop's state, once [`Sac::start_device_rollouts`] made it (`device.rs`).
    pub(crate) on_device: Option<device::DeviceSac>,
    /// The critics', the actor's and the temperature's learning rates `[1, 1]` on the learner device.
    learning_rates: [Tensor<2>; 3],
}

/// One gradient step's inputs on the learner device: normalised observations and the next ones
/// `[B, O]` / `[B, P]`, actions `[B, A]`, the n-step return and bootstrap factor `[B, 1]`, and the
/// noise of the actor's and the target's actions `[B, A]`.
struct GradBatch {
    obs: Tensor<2>,
    next_obs: Tensor<2>,
    priv_obs: Tensor<2>,
    next_priv: Tensor<2>,
    actions: Tensor<2>,
    returns: Tensor<2>,
    bootstrap: Tensor<2>,
    eps_actor: Tensor<2>,
    eps_next: Tensor<2>,
}

impl Sac {
    /// A fresh learner for `num_envs` envs.
    pub fn new(dims: Dims, num_envs: usize, cfg: &SacConfig, policy: &PolicyConfig, device: Device, seed: u64) -> Result<Sac> {
        ensure!(policy.encoder.is_none(), "SAC has no privileged encoder ([policy.encoder] is PPO's)");
        let mut rng = Rng::new(seed, 0x5341_4321);
        let actor_layout = MlpLayout { input: dims.obs, hidden: policy.actor_hidden.clone(), output: 2 * dims.act, layer_norm: cfg.actor_layer_norm };
        let critic_layout = MlpLayout { input: dims.priv_obs + dims.act, hidden: policy.critic_hidden.clone(), output: 1, layer_norm: cfg.critic_layer_norm };
        let mut actor_values = actor_layout.init(&mut rng);
        if policy.zero_init_output {
            // the output layer: μ(s) = 0 (a = tanh(σ ε) around the reference) and log σ at the middle of its range
            let k = actor_values.len();
            for v in &mut actor_values[k - 2..] {
                v.fill(0.0);
            }
        }
        // data-parallel (issue 37): every rank starts from rank 0's parameters
        for v in &mut actor_values {
            crate::dist::broadcast_f32(v);
        }
        let actor = leaves(actor_values, &actor_layout.shapes(), &device)?;
        let (mut critics, mut targets) = (Vec::new(), Vec::new());
        for _ in 0..cfg.num_critics {
            let mut values = critic_layout.init(&mut rng);
            for v in &mut values {
                crate::dist::broadcast_f32(v);
            }
            // the targets start as copies in memory of their own: on a GPU the optimiser writes
            // the critics in place (fused_adam.rs), which must not move the targets
            let target: Vec<Tensor<2>> = values.iter().zip(critic_layout.shapes()).map(|(v, s)| to_tensor(v.clone(), s, &device).inner()).collect();
            critics.push(leaves(values, &critic_layout.shapes(), &device)?);
            targets.push(target);
        }
        let log_alpha = to_tensor(vec![cfg.init_alpha.ln()], [1, 1], &device).require_grad();
        let critic_shapes: Vec<[usize; 2]> = (0..cfg.num_critics).flat_map(|_| critic_layout.shapes()).collect();
        let mut actor_adam = Adam::new(&actor_layout.shapes(), &device);
        let mut critic_adam = Adam::new(&critic_shapes, &device);
        actor_adam.weight_decay = cfg.weight_decay as f64;
        critic_adam.weight_decay = cfg.weight_decay as f64;
        let mut alpha_adam = Adam::new(&[[1, 1]], &device);
        for adam in [&mut actor_adam, &mut critic_adam, &mut alpha_adam] {
            adam.report_norm = false; // SAC reads no gradient norm (on a GPU: no norm kernels unless it clips)
        }
        let stored_obs = if cfg.store_actor_obs { dims.obs } else { 0 };
        let rank = crate::dist::rank();
        if rank > 0 {
            // each rank samples its own replay buffer with a batch stream of its own (rank 0 keeps
            // the one-process stream)
            rng = Rng::new(seed, 0x5341_4321 + rank as u64);
        }
        Ok(Sac {
            cfg: cfg.clone(),
            dims,
            activation: policy.activation,
            actor_layout,
            critic_layout,
            actor,
            critics,
            targets,
            log_alpha,
            actor_adam,
            critic_adam,
            alpha_adam,
            normalize: policy.obs_normalization,
            obs_norm: Normalizer::new(dims.obs),
            priv_norm: Normalizer::new(dims.priv_obs),
            buffer: ReplayBuffer::new(num_envs, cfg.buffer_capacity as usize, stored_obs, dims.priv_obs, dims.act),
            rng,
            env_steps: 0,
            critic_updates: 0,
            target_entropy: -(cfg.target_entropy_scale as f64) * dims.act as f64,
            pending: None,
            learning_rates: [cfg.critic_learning_rate, cfg.actor_learning_rate, cfg.alpha_learning_rate].map(|lr| to_tensor(vec![lr], [1, 1], &device.clone().inner())),
            sums: StatSums::default(),
            noise_seed: (seed ^ (seed >> 32)) as u32 ^ 0x5AC0_0A5E,
            noise_draw: 0,
            env_offset: (rank * num_envs) as u32,
            batch_first_row: (rank * cfg.batch_size as usize) as u32,
            on_device: None,
            device,
        })
    }

    /// Names of the critics' parameters, in `critic_adam`'s order (`q0.0.weight`, …).
    pub fn critic_names(&self) -> Vec<String> {
        (0..self.critics.len()).flat_map(|j| self.critic_layout.names(&format!("q{j}"))).collect()
    }

    fn critic_shapes(&self) -> Vec<[usize; 2]> {
        (0..self.critics.len()).flat_map(|_| self.critic_layout.shapes()).collect()
    }

    /// The temperature α = exp(log α).
    pub fn alpha(&self) -> Result<f64> {
        Ok(to_host(self.log_alpha.clone().inner())?[0].exp() as f64)
    }


    /// (μ [B, A], log σ [B, A]) of the actor with parameters `params` on normalised observations.
    fn policy(&self, params: &[Tensor<2>], obs_n: Tensor<2>) -> (Tensor<2>, Tensor<2>) {
        let a = self.dims.act;
        let out = self.actor_layout.forward(params, obs_n, self.activation); // [B, 2A]
        let mu = out.clone().narrow(1, 0, a);
        let log_std = squash_log_std(out.narrow(1, a, a), self.cfg.log_std_min as f64, self.cfg.log_std_max as f64);
        (mu, log_std)
    }

    /// A squashed-Gaussian sample `a = tanh(μ + σ ε)` [B, A] of the actor with parameters `params`
    /// on normalised observations, and its log-probability [B, 1] ([`squashed_sample`]). On a GPU
    /// one operation of ours with its own gradient (`kernels::squashed`: a kernel each way where
    /// the tensor ops launch ~25 forward and ~35 backward); on the CPU the tensor ops.
    fn sample(&self, params: &[Tensor<2>], obs_n: Tensor<2>, eps: Tensor<2>) -> (Tensor<2>, Tensor<2>) {
        if nets::is_gpu(&self.device) {
            let head = self.actor_layout.forward(params, obs_n, self.activation); // [B, 2A]
            return squashed_sample_fused(head, eps, self.cfg.log_std_min as f64, self.cfg.log_std_max as f64);
        }
        let (mu, log_std) = self.policy(params, obs_n);
        squashed_sample(mu, log_std, eps)
    }

    /// Deterministic actions `tanh(μ(ŝ))` [N, A] for raw observations `obs` [N, O]; statistics unchanged.
    pub fn act_mean(&self, obs: &[f32]) -> Result<Vec<f32>> {
        let d = self.dims;
        let n = obs.len() / d.obs.max(1);
        ensure!(obs.len() == n * d.obs, "observation sizes do not match the learner");
        let x = to_tensor(self.obs_norm.normalized(obs, self.normalize), [n, d.obs], &self.device);
        let params: Vec<Tensor<2>> = self.actor.iter().map(|p| p.clone().inner()).collect();
        let (mu, _) = self.policy(&params, x);
        to_host(mu.tanh())
    }

    /// Training actions [N, A] for raw observations `obs` [N, O] / `priv_obs` [N, P]: uniform in
    /// [−1, 1] for the first `random_steps` env steps, then `tanh(μ + σ ε)`. Updates the
    /// normalisers first and keeps the transition's first half for [`Sac::observe`].
    pub fn act(&mut self, obs: &[f32], priv_obs: &[f32]) -> Result<Vec<f32>> {
        let d = self.dims;
        let n = self.buffer.envs;
        ensure!(obs.len() == n * d.obs && priv_obs.len() == n * d.priv_obs, "observation sizes do not match the learner");
        if self.normalize {
            self.obs_norm.update(obs);
            self.priv_norm.update(priv_obs);
        }
        ensure!(self.on_device.is_none(), "act() in a device-resident run (act_device)");
        let draw = self.noise_draw;
        self.noise_draw = draw.wrapping_add(1);
        let actions: Vec<f32> = if self.env_steps < self.cfg.random_steps as u64 {
            host_uniforms_from_row(self.noise_seed, draw, self.env_offset, n, d.act) // a ~ U[−1, 1)
        } else {
            let x = to_tensor(self.obs_norm.normalized(obs, self.normalize), [n, d.obs], &self.device);
            let params: Vec<Tensor<2>> = self.actor.iter().map(|p| p.clone().inner()).collect();
            let (mu, log_std) = self.policy(&params, x);
            let (mu, log_std) = (to_host(mu)?, to_host(log_std)?);
            let eps = host_normals_from_row(self.noise_seed, draw, self.env_offset, n, d.act); // ε ~ N(0, 1) [N, A]
            (0..n * d.act).map(|k| (mu[k] + log_std[k].exp() * eps[k]).tanh()).collect() // a = tanh(μ + σ ε)
        };
        self.pending = Some(Pending { obs: obs.to_vec(), priv_obs: priv_obs.to_vec(), actions: actions.clone() });
        Ok(actions)
    }

    /// The outcome of the step that the last `act` started: pushes every env's transition (with
    /// `final_obs`/`final_priv_obs` as the next observation of an env whose episode ended), then,
    /// once `learning_starts` env steps are in, takes `updates_per_step` gradient steps.
    #[allow(clippy::too_many_arguments)]
    pub fn observe(&mut self, rewards: &[f32], terminated: &[bool], time_outs: &[bool], next_obs: &[f32], next_priv_obs: &[f32], final_obs: &[f32], final_priv_obs: &[f32]) -> Result<()> {
        let p = self.pending.take().ok_or_else(|| anyhow::anyhow!("observe() without act()"))?;
        let d = self.dims;
        let n = self.buffer.envs;
        ensure!(rewards.len() == n && terminated.len() == n && time_outs.len() == n, "step outcome sizes do not match the learner");
        ensure!(final_obs.len() == n * d.obs && final_priv_obs.len() == n * d.priv_obs && next_obs.len() == n * d.obs && next_priv_obs.len() == n * d.priv_obs, "next-observation sizes do not match the learner");
        let done: Vec<bool> = (0..n).map(|i| terminated[i] || time_outs[i]).collect();
        // the observation after the step: an ended episode's final one, else the next step's
        let pick = |next: &[f32], fin: &[f32], dim: usize| -> Vec<f32> {
            let mut out = next.to_vec();
            for i in (0..n).filter(|&i| done[i]) {
                out[i * dim..(i + 1) * dim].copy_from_slice(&fin[i * dim..(i + 1) * dim]);
            }
            out
        };
        let next_p = pick(next_priv_obs, final_priv_obs, d.priv_obs);
        let next_o = if self.cfg.store_actor_obs { pick(next_obs, final_obs, d.obs) } else { Vec::new() };
        let scaled: Vec<f32> = rewards.iter().map(|r| r * self.cfg.reward_scale).collect();
        let actor_obs: &[f32] = if self.cfg.store_actor_obs { &p.obs } else { &[] };
        self.buffer.push(&Transitions {
            obs: actor_obs,
            priv_obs: &p.priv_obs,
            actions: &p.actions,
            rewards: &scaled,
            done: &done,
            terminated,
            next_obs: &next_o,
            next_priv_obs: &next_p,
        })?;
        self.env_steps += 1;
        if self.env_steps >= self.cfg.learning_starts.max(1) as u64 {
            for _ in 0..self.cfg.updates_per_step {
                self.gradient_step()?;
            }
        }
        Ok(())
    }

    /// The actor observations of a sample's rows (`next`: after the window): stored, or the clean
    /// actor observation at the head of the critic observation.
    fn actor_rows(&self, s: &Sample, next: bool) -> Vec<f32> {
        let (o, p) = (self.dims.obs, self.dims.priv_obs);
        match (self.cfg.store_actor_obs, next) {
            (true, false) => s.obs.clone(),
            (true, true) => s.next_obs.clone(),
            (false, nx) => {
                let src = if nx { &s.next_priv_obs } else { &s.priv_obs };
                src.chunks(p).flat_map(|r| r[..o].iter().copied()).collect()
            }
        }
    }

    /// One gradient step: a critic update and its Polyak step, and every `policy_frequency`-th
    /// time an actor and temperature update.
    pub fn gradient_step(&mut self) -> Result<()> {
        // two noise draws: the target's actions, then the actor's
        let draws = (self.noise_draw, self.noise_draw.wrapping_add(1));
        self.noise_draw = self.noise_draw.wrapping_add(2);
        let batch = match self.on_device {
            Some(_) => self.device_batch(draws)?,
            None => self.host_batch(draws)?,
        };
        self.gradient_step_on(batch)
    }

    /// A gradient step's batch from the host buffer (noise draws `draws`: the target's, the actor's).
    fn host_batch(&mut self, draws: (u32, u32)) -> Result<GradBatch> {
        let d = self.dims;
        let b = self.cfg.batch_size as usize;
        let s = self.buffer.sample(b, self.cfg.n_step as usize, self.cfg.gamma, &mut self.rng)?;
        let dev = self.device.clone();
        // the observations normalised: on the host (the CPU learner), or on a GPU learner's device
        // (the rows go up with the statistics; the host's f64 pass over the batch cost a GPU
        // learner more than its gradient step's kernels)
        let up = |norm: &Normalizer, rows: &[f32]| norm.normalized_tensor(rows, b, &dev, self.normalize);
        Ok(GradBatch {
            obs: up(&self.obs_norm, &self.actor_rows(&s, false)),
            next_obs: up(&self.obs_norm, &self.actor_rows(&s, true)),
            priv_obs: up(&self.priv_norm, &s.priv_obs),
            next_priv: up(&self.priv_norm, &s.next_priv_obs),
            actions: to_tensor(s.actions.clone(), [b, d.act], &dev),
            returns: to_tensor(s.returns.clone(), [b, 1], &dev).inner(),
            bootstrap: to_tensor(s.bootstrap.clone(), [b, 1], &dev).inner(),
            eps_actor: to_tensor(host_normals_from_row(self.noise_seed, draws.1, self.batch_first_row, b, d.act), [b, d.act], &dev),
            eps_next: to_tensor(host_normals_from_row(self.noise_seed, draws.0, self.batch_first_row, b, d.act), [b, d.act], &dev).inner(),
        })
    }

    /// One gradient step on `batch` (see [`Sac::gradient_step`]).
    fn gradient_step_on(&mut self, batch: GradBatch) -> Result<()> {
        let GradBatch { obs, next_obs, priv_obs, next_priv, actions, returns, bootstrap, eps_actor, eps_next } = batch;
        let log_alpha = self.log_alpha.clone().inner(); // [1, 1]
        let alpha = log_alpha.clone().exp();

        // critics: y = R + β (red_j Q̄_j(ĉ', a') − α log π(a'|s')), a' ~ π(·|s')
        let actor_now: Vec<Tensor<2>> = self.actor.iter().map(|p| p.clone().inner()).collect();
        let (a_next, logp_next) = self.sample(&actor_now, next_obs.inner(), eps_next);
        let next_in = Tensor::cat(vec![next_priv.inner(), a_next], 1); // [ĉ', a'], once for every target
        let q_next: Vec<Tensor<2>> = self.targets.iter().map(|t| self.critic_layout.forward(t, next_in.clone(), self.activation)).collect();
        let soft_v = reduce(q_next, self.cfg.q_reduction) - logp_next * alpha.clone(); // [B, 1]
        let y = (returns + bootstrap * soft_v).detach(); // [B, 1]
        let y = y.autodiff();
        let critic_in = Tensor::cat(vec![priv_obs.clone(), actions], 1); // [ĉ, a], once for every critic
        // on a GPU each critic's loss and mean Q is one operation of ours (kernels::sac_loss: two
        // kernels forward, one backward, where the tensor ops launch ~13); the CPU keeps the tensor ops
        let on_gpu = nets::is_gpu(&self.device);
        let log_alpha_c = log_alpha.clone().autodiff(); // a constant in the critics' and the actor's losses
        let critic_scale = SacLoss::Critic { q_scale: 1.0 / self.critics.len() as f64 };
        let mut critic_loss: Option<Tensor<2>> = None; // Σ_j mean((Q_j − y)²) [1, 1], or with the GPU's Σ_j mean Q_j / K beside it [1, 2]
        let mut q_sum: Option<Tensor<1>> = None;
        for c in &self.critics {
            let q = self.critic_layout.forward(c, critic_in.clone(), self.activation); // Q_j(ĉ, a) [B, 1]
            let l = if on_gpu {
                sac_loss_fused(q, y.clone(), log_alpha_c.clone(), critic_scale)
            } else {
                let qm = nets::mean_all(q.clone().detach());
                q_sum = Some(match q_sum { Some(acc) => acc + qm, None => qm });
                nets::mean_all((q - y.clone()).square()).reshape([1, 1]) // mean((Q_j − y)²)
            };
            critic_loss = Some(match critic_loss { Some(acc) => acc + l, None => l });
        }
        let critic_loss = critic_loss.expect("at least one critic");
        // [critic loss, mean Q] [1, 2]
        let critic_row = match q_sum {
            Some(q_sum) => Tensor::cat(vec![critic_loss.clone().detach().inner(), q_sum.div_scalar(self.critics.len() as f64).inner().reshape([1, 1])], 1),
            None => critic_loss.clone().detach().inner(),
        };
        let all: Vec<Tensor<2>> = self.critics.iter().flatten().cloned().collect();
        let grads = critic_loss.clone().backward();
        let [critic_lr, actor_lr, alpha_lr] = self.learning_rates.clone();
        let (tau, max_norm) = (self.cfg.tau as f64, self.cfg.max_grad_norm as f64);
        let updated = if tau >= 1.0 {
            self.critic_adam.step_clipped(&all, &grads, max_norm, &critic_lr)?.0
        } else {
            // Polyak: θ̄ ← τ θ + (1 − τ) θ̄, in the optimiser's kernels on a GPU
            let mut targets: Vec<Tensor<2>> = self.targets.iter().flatten().cloned().collect();
            let out = self.critic_adam.step_clipped_polyak(&all, &grads, max_norm, &critic_lr, &mut targets, tau)?.0;
            let mut moved = targets.into_iter();
            for tp in self.targets.iter_mut().flatten() {
                *tp = moved.next().expect("one target per critic parameter");
            }
            out
        };
        let mut updated = updated.into_iter();
        for c in &mut self.critics {
            for p in c.iter_mut() {
                *p = updated.next().expect("one updated tensor per critic parameter");
            }
        }
        if tau >= 1.0 {
            // (τ = 1: the target shares the critic's memory, which the next optimiser step writes
            // in place on a GPU — after the step's targets were read: the same values)
            for (t, c) in self.targets.iter_mut().zip(&self.critics) {
                for (tp, p) in t.iter_mut().zip(c) {
                    *tp = p.clone().inner();
                }
            }
        }
        self.critic_updates += 1;
        self.sums.critic = accumulate(self.sums.critic.take(), critic_row);
        self.sums.critic_steps += 1;

        // actor and temperature
        let actor_turn = self.critic_updates % self.cfg.policy_frequency as u64 == 0;
        if actor_turn {
            let (a_new, logp) = self.sample(&self.actor, obs, eps_actor);
            let frozen: Vec<Vec<Tensor<2>>> = self.critics.iter().map(|c| c.iter().map(|p| p.clone().inner().autodiff()).collect()).collect();
            // the critic's first layer as ĉ W_c + a W_a + b: its input gradient is only a's columns
            let qs: Vec<Tensor<2>> = frozen.iter().map(|c| self.critic_layout.forward_split_input(c, priv_obs.clone(), a_new.clone(), self.activation)).collect();
            let q_pi = reduce(qs, self.cfg.q_reduction);
            // [actor loss mean(α log π − Q), entropy estimate −mean log π] [1, 2]: on a GPU one
            // operation of ours (kernels::sac_loss), the loss its first entry
            let (root, row) = if on_gpu {
                let out = sac_loss_fused(logp.clone(), q_pi, log_alpha_c.clone(), SacLoss::Actor);
                (out.clone(), out.detach().inner())
            } else {
                let actor_loss = nets::mean_all(logp.clone() * alpha.clone().autodiff() - q_pi); // mean(α log π − Q)
                let entropy = nets::mean_all(logp.clone().detach().inner()).neg();
                (actor_loss.clone().reshape([1, 1]), Tensor::cat(vec![actor_loss.detach().inner(), entropy], 0).reshape([1, 2]))
            };
            let grads = root.backward();
            self.actor = self.actor_adam.step_clipped(&self.actor, &grads, self.cfg.max_grad_norm as f64, &actor_lr)?.0;
            if self.cfg.learn_alpha {
                // L = −mean(log α · (log π + H̄)): ∂L/∂log α = −mean(log π + H̄) = (−mean log π) − H̄
                let coef = if on_gpu {
                    row.clone().narrow(1, 1, 1).sub_scalar(self.target_entropy).autodiff()
                } else {
                    nets::mean_all(logp.detach().inner().add_scalar(self.target_entropy)).neg().reshape([1, 1]).autodiff()
                };
                let alpha_loss = (self.log_alpha.clone() * coef).sum();
                let grads = alpha_loss.backward();
                self.log_alpha = self.alpha_adam.step_clipped(std::slice::from_ref(&self.log_alpha), &grads, 0.0, &alpha_lr)?.0.remove(0);
            }
            self.sums.actor = accumulate(self.sums.actor.take(), row);
            self.sums.actor_steps += 1;
        }
        Ok(())
    }

    /// The means of the gradient steps since the last call (NaN where none was taken), and resets them.
    /// One read of the device: the sums of the gradient steps and log α.
    pub fn take_stats(&mut self) -> Result<SacStats> {
        let s = std::mem::take(&mut self.sums);
        let dev = self.device.clone().inner();
        let sums = |t: Option<Tensor<2>>| t.unwrap_or_else(|| Tensor::zeros([1, 2], &dev));
        let v = to_host(Tensor::cat(vec![sums(s.critic), sums(s.actor), self.log_alpha.clone().inner()], 1))?;
        let per = |x: f32, k: u64| if k > 0 { x as f64 / k as f64 } else { f64::NAN };
        Ok(SacStats {
            critic_loss: per(v[0], s.critic_steps),
            actor_loss: per(v[2], s.actor_steps),
            alpha: v[4].exp() as f64,
            entropy: per(v[3], s.actor_steps),
            q_mean: per(v[1], s.critic_steps),
            updates: s.critic_steps,
            buffer_transitions: self.buffer.transitions() as u64,
        })
    }

    /// Writes the actor, critics, targets, log α and normalisers into [`MODEL_FILE`] of `state`,
    /// with the JSON metadata. The actor's tensors are `actor.<layer>.weight|bias` (its last layer
    /// [h, 2A]: μ in the first A columns) as PPO's are, so that eval and export read both alike.
    pub fn save_policy(&self, state: &mut LearnerState) -> Result<()> {
        push_all(state, &self.actor_layout.names("actor"), &self.actor_layout.shapes(), &self.actor)?;
        push_all(state, &self.critic_names(), &self.critic_shapes(), &self.critics.concat())?;
        let target_names: Vec<String> = (0..self.targets.len()).flat_map(|j| self.critic_layout.names(&format!("q{j}_target"))).collect();
        push_all(state, &target_names, &self.critic_shapes(), &self.targets.concat())?;
        state.push_tensor(MODEL_FILE, "log_alpha", vec![1, 1], TensorValues::F32(to_host(self.log_alpha.clone().inner())?));
        let (obs_norm, priv_norm) = self.normalizers()?;
        obs_norm.save("obs_norm", state, MODEL_FILE);
        priv_norm.save("priv_norm", state, MODEL_FILE);
        let d = self.dims;
        let info = serde_json::json!({
            "format": "dextrain.policy.v1",
            "algorithm": "sac",
            "obs_dim": d.obs,
            "priv_dim": d.priv_obs,
            "action_dim": d.act,
            "activation": format!("{:?}", self.activation).to_lowercase(),
            "obs_normalization": self.normalize,
            "actor_layer_norm": self.actor_layout.layer_norm,
            "action": "tanh of the first action_dim outputs of the actor",
        });
        state.set_info(MODEL_FILE, info.to_string());
        Ok(())
    }

    /// The policy of a SAC run's checkpoint directory `ckpt` (its `model.safetensors`), for `n`
    /// envs: what eval and export need (the actor, critics and normalisers; a replay buffer of
    /// the smallest size, fresh optimisers).
    pub fn from_checkpoint(dims: Dims, n: usize, run: &crate::config::Config, ckpt: &std::path::Path, device: Device) -> Result<Sac> {
        use anyhow::Context;
        let cfg = SacConfig { buffer_capacity: run.sac.n_step.max(2), ..run.sac.clone() };
        let mut sac = Sac::new(dims, n, &cfg, &run.policy, device, run.seed as u64)?;
        let state = crate::learn::checkpoint::read_learner_file(&ckpt.join("model.safetensors"), MODEL_FILE)?;
        sac.load_policy(&state).with_context(|| format!("cannot load the policy of {}", ckpt.display()))?;
        Ok(sac)
    }

    /// Loads what [`Sac::save_policy`] wrote (same config).
    pub fn load_policy(&mut self, state: &LearnerState) -> Result<()> {
        self.actor = load_all(state, &self.actor_layout.names("actor"), &self.actor_layout.shapes(), &self.device)?;
        let per = self.critic_layout.shapes().len();
        let critics = load_all(state, &self.critic_names(), &self.critic_shapes(), &self.device)?;
        self.critics = critics.chunks(per).map(|c| c.to_vec()).collect();
        let target_names: Vec<String> = (0..self.critics.len()).flat_map(|j| self.critic_layout.names(&format!("q{j}_target"))).collect();
        let targets = load_all(state, &target_names, &self.critic_shapes(), &self.device)?;
        self.targets = targets.chunks(per).map(|c| c.iter().map(|p| p.clone().inner()).collect()).collect();
        self.log_alpha = to_tensor(state.f32s(MODEL_FILE, "log_alpha", Some(1))?, [1, 1], &self.device).require_grad();
        self.obs_norm = Normalizer::load("obs_norm", self.dims.obs, state, MODEL_FILE)?;
        self.priv_norm = Normalizer::load("priv_norm", self.dims.priv_obs, state, MODEL_FILE)?;
        if let Some(dv) = &mut self.on_device {
            dv.norms = super::normalizer::DeviceNormalizers::from_host(&self.obs_norm, &self.priv_norm, &self.device);
        }
        Ok(())
    }

    /// The observation normalisers as they stand (read from the device in a device-resident run).
    pub fn normalizers(&self) -> Result<(Normalizer, Normalizer)> {
        match &self.on_device {
            Some(dv) => dv.norms.to_host(),
            None => Ok((self.obs_norm.clone(), self.priv_norm.clone())),
        }
    }

    /// Everything a resumed run needs: the policy file, the three optimisers (moments in
    /// [`OPTIMIZER_FILE`], steps `actor_adam_step` / `critic_adam_step` / `alpha_adam_step`), the
    /// RNG, the noise's stream and draw number, the counters and (with `sac.checkpoint_buffer`)
    /// the replay buffer ([`BUFFER_FILE`]; read from the device in a device-resident run).
    pub fn state(&self) -> Result<LearnerState> {
        ensure!(self.pending.is_none(), "state() between act() and observe()");
        let mut state = LearnerState::default();
        self.save_policy(&mut state)?;
        self.actor_adam.save_as(&self.actor_layout.names("actor"), &self.actor_layout.shapes(), &mut state, OPTIMIZER_FILE, "actor_adam_step")?;
        self.critic_adam.save_as(&self.critic_names(), &self.critic_shapes(), &mut state, OPTIMIZER_FILE, "critic_adam_step")?;
        self.alpha_adam.save_as(&["log_alpha".to_string()], &[[1, 1]], &mut state, OPTIMIZER_FILE, "alpha_adam_step")?;
        state.set_bits("rng_state", self.rng.state);
        state.set_bits("noise_seed", self.noise_seed as u64);
        state.set_bits("noise_draw", self.noise_draw as u64);
        state.set_u64("sac_env_steps", self.env_steps);
        state.set_u64("sac_critic_updates", self.critic_updates);
        if self.cfg.checkpoint_buffer {
            match &self.on_device {
                Some(dv) => dv.buffer_on_host(&self.buffer)?.save(&mut state, BUFFER_FILE),
                None => self.buffer.save(&mut state, BUFFER_FILE),
            }
        }
        Ok(state)
    }

    /// Restores what [`Sac::state`] gave. Returns whether the replay buffer was restored (false: a
    /// checkpoint written without it; the buffer starts empty and the run does not continue exactly).
    pub fn load_state(&mut self, state: &LearnerState) -> Result<bool> {
        self.load_policy(state)?;
        let dev = self.device.clone();
        self.actor_adam.load_as(&self.actor_layout.names("actor"), &self.actor_layout.shapes(), state, OPTIMIZER_FILE, &dev, "actor_adam_step")?;
        self.critic_adam.load_as(&self.critic_names(), &self.critic_shapes(), state, OPTIMIZER_FILE, &dev, "critic_adam_step")?;
        self.alpha_adam.load_as(&["log_alpha".to_string()], &[[1, 1]], state, OPTIMIZER_FILE, &dev, "alpha_adam_step")?;
        self.rng.state = state.bits("rng_state")?;
        self.noise_seed = state.bits("noise_seed")? as u32;
        self.noise_draw = state.bits("noise_draw")? as u32;
        self.env_steps = state.u64("sac_env_steps")?;
        self.critic_updates = state.u64("sac_critic_updates")?;
        self.pending = None;
        self.sums = StatSums::default();
        let restored = if state.file(BUFFER_FILE).is_some() {
            self.buffer.load(state, BUFFER_FILE)?;
            true
        } else {
            self.buffer.clear();
            false
        };
        if let Some(dv) = &mut self.on_device {
            dv.load_buffer(&self.buffer)?;
        }
        Ok(restored)
    }
}

/// Host values → autodiff leaves of `shapes`.
fn leaves(values: Vec<Vec<f32>>, shapes: &[[usize; 2]], device: &Device) -> Result<Vec<Tensor<2>>> {
    ensure!(values.len() == shapes.len(), "expected {} parameter tensors, got {}", shapes.len(), values.len());
    values
        .into_iter()
        .zip(shapes)
        .map(|(v, s)| {
            ensure!(v.len() == s[0] * s[1], "a parameter of shape {s:?} got {} values", v.len());
            Ok(to_tensor(v, *s, device).require_grad())
        })
        .collect()
}

fn push_all(state: &mut LearnerState, names: &[String], shapes: &[[usize; 2]], params: &[Tensor<2>]) -> Result<()> {
    for ((n, s), p) in names.iter().zip(shapes).zip(params) {
        state.push_tensor(MODEL_FILE, n, s.to_vec(), TensorValues::F32(to_host(p.clone().inner())?));
    }
    Ok(())
}

fn load_all(state: &LearnerState, names: &[String], shapes: &[[usize; 2]], device: &Device) -> Result<Vec<Tensor<2>>> {
    let values = names.iter().zip(shapes).map(|(n, s)| state.f32s(MODEL_FILE, n, Some(s[0] * s[1]))).collect::<Result<Vec<_>>>()?;
    leaves(values, shapes, device)
}
