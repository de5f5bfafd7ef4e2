//! PPO (Schulman et al. 2017) with rsl_rl's conventions, top to bottom in one file.
//!
//! - Gaussian actor `π(a|s) = N(μ_θ(ŝ), diag(exp(2 log σ)))` with a learned, state-independent
//!   log-std; a separate critic `V_φ(ĉ)` on the privileged critic observation (asymmetric
//!   actor–critic); `ŝ`, `ĉ` are empirically normalised (`normalizer.rs`).
//! - Rollouts: [`Ppo::act`] samples actions for N envs, [`Ppo::process_step`] records rewards and
//!   dones; on a time-out the reward gets `γ V(s_t)` (returns bootstrap through time-outs, not
//!   through terminations). After `T` steps, [`Ppo::update`] computes GAE and runs `epochs` passes of
//!   `minibatches` minibatches over the shuffled rollout.
//! - Loss per minibatch: clipped surrogate + `value_loss_coef` × clipped value loss − `entropy_coef`
//!   × entropy; gradients clipped to a global norm; Adam; the learning rate adapts to the KL between
//!   the acting policy and the current one (÷1.5 above 2× the target, ×1.5 below ½×, clamped).
//!
//! The minibatch shuffles come from one host `Rng`; the action noise from the counter hash
//! (`learn::noise`: draw number `noise_draw`), so the host and the device draw the same numbers.
//! [`Ppo::state`] / [`Ppo::load_state`] hand the whole learner to `checkpoint.rs` as named tensors
//! (file `model`: the networks and normalisers; file `optimizer`: Adam's moments) and scalars
//! (`learning_rate`, `adam_step`, `rng_state`, `noise_seed`, `noise_draw`).
//!
//! `device.rs`: the same rollouts and update with everything on the learner device (the envs and
//! the learner on one GPU: `run/device_loop.rs`).

pub mod device;
pub mod storage;

use crate::gpu::profile::around_burn;
use anyhow::{Context, Result, ensure};
use burn::prelude::*;
use burn::tensor::{Int, TensorData};

use self::storage::RolloutStorage;
use super::adam::Adam;
use super::kernels::adaptive_lr::{self, AdaptiveLr};
use super::kernels::ppo_loss::{self, LossCoefs};
use super::nets::{self, Activation, init_mlp, mlp_forward, mlp_shapes, to_host, to_tensor};
use super::noise::host_normals_from_row;
use super::normalizer::Normalizer;
use crate::rng::Rng;
use super::state::{LearnerState, TensorValues};
use crate::config::{LrSchedule, PolicyConfig, PpoConfig};

/// The state file of the policy (networks + normalisers): `model.safetensors`.
pub const MODEL_FILE: &str = "model";
/// The state file of the optimiser (Adam's moments): `optimizer.safetensors`.
pub const OPTIMIZER_FILE: &str = "optimizer";

const LN_2PI: f64 = 1.837_877_066_409_345_3; // ln(2π)

/// The critic-observation entries that `policy.encoder.inputs` name in the task `spec`, in order
/// (empty without an encoder).
pub fn encoder_index(policy: &PolicyConfig, spec: &crate::task::TaskSpec) -> Result<Vec<usize>> {
    match &policy.encoder {
        Some(e) => crate::task::spec::field_indices(&spec.priv_layout, &e.inputs).map_err(|m| anyhow::anyhow!("policy.encoder.inputs: {m}")),
        None => Ok(Vec::new()),
    }
}

/// Sizes of the learner's inputs and outputs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Dims {
    /// Actor observation size O.
    pub obs: usize,
    /// Critic (privileged) observation size P.
    pub priv_obs: usize,
    /// Action size A.
    pub act: usize,
}

/// Actor and critic parameters: `[actor layers…, log_std, critic layers…, encoder layers…]` (see
/// `nets.rs`). With a privileged encoder the actor's input is `[ŝ; μ(ê)]`, ê the normalised critic
/// observation's entries at `encoder_index`.
pub struct ActorCritic {
    /// Input and output sizes.
    pub dims: Dims,
    /// Hidden-layer activation.
    pub activation: Activation,
    /// Shapes of the actor's layers `[w0, b0, …]`.
    pub actor_shapes: Vec<[usize; 2]>,
    /// Shapes of the critic's layers.
    pub critic_shapes: Vec<[usize; 2]>,
    /// Shapes of the privileged encoder's layers (empty: no encoder).
    pub encoder_shapes: Vec<[usize; 2]>,
    /// The encoder's hidden activation.
    pub encoder_activation: Activation,
    /// The critic-observation entries the encoder reads, in order.
    pub encoder_index: Vec<usize>,
    /// Autodiff leaves on the learner device.
    pub params: Vec<Tensor<2>>,
}

impl ActorCritic {
    /// Fresh networks (torch's Linear initialisation from `rng`, log σ = ln init_std).
    /// `encoder_index`: the critic-observation entries of `policy.encoder`'s inputs (empty without
    /// an encoder; `task::spec::field_indices`).
    pub fn new(dims: Dims, cfg: &PolicyConfig, encoder_index: &[usize], device: &Device, rng: &mut Rng) -> Result<ActorCritic> {
        let activation = cfg.activation;
        ensure!(cfg.encoder.is_some() != encoder_index.is_empty(), "policy.encoder: {} encoder inputs resolved for {} encoder", encoder_index.len(), if cfg.encoder.is_some() { "an" } else { "no" });
        ensure!(encoder_index.iter().all(|&i| i < dims.priv_obs), "policy.encoder: an input index beyond the critic observation ({})", dims.priv_obs);
        let latent = cfg.encoder.as_ref().map(|e| e.latent).unwrap_or(0);
        let encoder_shapes = match &cfg.encoder {
            Some(e) => mlp_shapes(encoder_index.len(), &e.hidden, e.latent),
            None => Vec::new(),
        };
        let encoder_activation = cfg.encoder.as_ref().map(|e| e.activation).unwrap_or(activation);
        let actor_shapes = mlp_shapes(dims.obs + latent, &cfg.actor_hidden, dims.act);
        let critic_shapes = mlp_shapes(dims.priv_obs, &cfg.critic_hidden, 1);
        let mut values = init_mlp(&actor_shapes, rng);
        if cfg.zero_init_output {
            // the last layer's weight and bias: μ(s) = 0 for every s at the start
            let n = values.len();
            for v in &mut values[n - 2..] {
                v.fill(0.0);
            }
        }
        values.push(vec![cfg.init_std.ln(); dims.act]);
        values.extend(init_mlp(&critic_shapes, rng));
        // (drawn last: a policy without an encoder draws what it always drew)
        values.extend(init_mlp(&encoder_shapes, rng));
        let mut ac = ActorCritic { dims, activation, actor_shapes, critic_shapes, encoder_shapes, encoder_activation, encoder_index: encoder_index.to_vec(), params: Vec::new() };
        ac.set_values(values, device)?;
        Ok(ac)
    }

    /// Shapes of every parameter, in order.
    pub fn shapes(&self) -> Vec<[usize; 2]> {
        let mut s = self.actor_shapes.clone();
        s.push([1, self.dims.act]);
        s.extend(self.critic_shapes.iter().copied());
        s.extend(self.encoder_shapes.iter().copied());
        s
    }

    /// Names of every parameter, in order (for checkpoints): actor.0.weight, …, log_std, critic.…
    pub fn names(&self) -> Vec<String> {
        let layer = |prefix: &str, i: usize| format!("{prefix}.{}.{}", i / 2, if i % 2 == 0 { "weight" } else { "bias" });
        let mut n: Vec<String> = (0..self.actor_shapes.len()).map(|i| layer("actor", i)).collect();
        n.push("log_std".into());
        n.extend((0..self.critic_shapes.len()).map(|i| layer("critic", i)));
        n.extend((0..self.encoder_shapes.len()).map(|i| layer("encoder", i)));
        n
    }

    /// Replaces every parameter with host values (same order and shapes as `shapes()`).
    pub fn set_values(&mut self, values: Vec<Vec<f32>>, device: &Device) -> Result<()> {
        let shapes = self.shapes();
        ensure!(values.len() == shapes.len(), "expected {} parameter tensors, got {}", shapes.len(), values.len());
        let mut params = Vec::with_capacity(values.len());
        for (v, s) in values.into_iter().zip(&shapes) {
            ensure!(v.len() == s[0] * s[1], "a parameter of shape {s:?} got {} values", v.len());
            params.push(to_tensor(v, *s, device).autodiff().require_grad());
        }
        self.params = params;
        Ok(())
    }

    /// Gives every rank of a data-parallel job (`crate::dist`) rank 0's parameters: one flat
    /// broadcast (nothing with one rank).
    pub fn broadcast_from_root(&mut self, device: &Device) -> Result<()> {
        if crate::dist::size() == 1 {
            return Ok(());
        }
        let values = self.values()?;
        let mut flat: Vec<f32> = values.iter().flatten().copied().collect();
        crate::dist::broadcast_f32(&mut flat);
        let mut at = 0;
        let split = values
            .iter()
            .map(|v| {
                let part = flat[at..at + v.len()].to_vec();
                at += v.len();
                part
            })
            .collect();
        self.set_values(split, device)
    }

    /// Every parameter's values on the host.
    pub fn values(&self) -> Result<Vec<Vec<f32>>> {
        self.params.iter().map(|p| to_host(p.clone().inner())).collect()
    }

    fn n_actor(&self) -> usize {
        self.actor_shapes.len()
    }

    /// Policy mean: ŝ [B, O] (and, with an encoder, the normalised critic observation ĉ [B, P])
    /// → μ [B, A].
    pub fn actor(&self, params: &[Tensor<2>], obs: Tensor<2>, priv_obs: Tensor<2>) -> Tensor<2> {
        let x = match self.latent(params, priv_obs) {
            // [ŝ; ẑ] [B, O + L]
            Some(z) => Tensor::cat(vec![obs, z], 1),
            None => obs,
        };
        mlp_forward(&params[..self.n_actor()], x, self.activation)
    }

    /// The encoder's latent ẑ = μ(ê) [B, L] (ê = ĉ's entries at `encoder_index`), `None` without
    /// an encoder.
    pub fn latent(&self, params: &[Tensor<2>], priv_obs: Tensor<2>) -> Option<Tensor<2>> {
        if self.encoder_shapes.is_empty() {
            return None;
        }
        let device = priv_obs.device();
        let idx: Vec<i64> = self.encoder_index.iter().map(|&i| i as i64).collect();
        let n = idx.len();
        let idx = Tensor::<1, Int>::from_data(TensorData::new(idx, [n]), &device);
        let e = priv_obs.select(1, idx); // [B, E]
        let start = self.n_actor() + 1 + self.critic_shapes.len();
        Some(mlp_forward(&params[start..], e, self.encoder_activation))
    }

    /// log σ [1, A].
    pub fn log_std(&self, params: &[Tensor<2>]) -> Tensor<2> {
        params[self.n_actor()].clone()
    }

    /// Value: ĉ [B, P] → V [B, 1].
    pub fn critic(&self, params: &[Tensor<2>], priv_obs: Tensor<2>) -> Tensor<2> {
        let start = self.n_actor() + 1;
        mlp_forward(&params[start..start + self.critic_shapes.len()], priv_obs, self.activation)
    }

    /// The parameters without autodiff (for acting).
    pub fn inference_params(&self) -> Vec<Tensor<2>> {
        self.params.iter().map(|p| p.clone().inner()).collect()
    }
}

/// One minibatch on the learner device (rows = transitions).
pub struct Batch {
    pub obs: Tensor<2>,       // [B, O]
    pub priv_obs: Tensor<2>,  // [B, P]
    pub actions: Tensor<2>,   // [B, A]
    pub old_log_prob: Tensor<2>, // [B, 1]
    pub old_mu: Tensor<2>,    // [B, A]
    pub old_sigma: Tensor<2>, // [1, A]: the acting policy's σ (state-independent, fixed over a rollout)
    pub advantages: Tensor<2>, // [B, 1]
    pub returns: Tensor<2>,   // [B, 1]
    pub old_values: Tensor<2>, // [B, 1]
}

/// The PPO loss of one minibatch.
pub struct Losses {
    /// Where the gradient starts (`root.backward()`): the total loss `[1, 1]` (the tensor ops of
    /// [`ppo_losses`]), or the fused loss's whole `[1, 5]` (`kernels::ppo_loss`: only its first
    /// column, the total, carries a gradient).
    pub root: Tensor<2>,
    /// `[total, surrogate, value, entropy, KL]` `[1, 5]` without gradient (the KL is
    /// KL(π_old ‖ π_new), the minibatch's mean).
    pub row: Tensor<2>,
}

impl Losses {
    /// The losses from the fused loss's `[total, surrogate, value, entropy, KL]` `[1, 5]`.
    pub fn from_fused(out: Tensor<2>) -> Losses {
        Losses { row: out.clone().detach().inner(), root: out }
    }
}

/// Where the KL sits in [`Losses::row`].
pub const KL_COLUMN: usize = 4;

/// The PPO losses for policy output `mu` [B, A], `log_std` [1, A] and values `v` [B, 1]:
/// - ratio `ρ = exp(log π(a|s) − log π_old(a|s))`,
///   surrogate `mean(max(−Â ρ, −Â clip(ρ, 1 − ε, 1 + ε)))`;
/// - value `mean(max((V − R)², (V_old + clip(V − V_old, −ε, ε) − R)²))` (or `mean((V − R)²)` unclipped);
/// - entropy `Σ_a (½ + ½ ln 2π + log σ_a)`;
/// - `total = surrogate + c_v · value − c_e · entropy`;
/// - `kl = mean Σ_a [ln(σ/σ_old) + (σ_old² + (μ_old − μ)²) / (2σ²) − ½]`.
pub fn ppo_losses(mu: Tensor<2>, log_std: Tensor<2>, v: Tensor<2>, b: &Batch, cfg: &PpoConfig) -> Losses {
    let [rows, a] = mu.dims();
    let sigma = log_std.clone().exp(); // [1, A]
    // log π(a|s) = −½ Σ ((a − μ)/σ)² − Σ log σ − ½ A ln 2π          [B, 1]
    // (σ and Σ log σ meet the rows through nets::batch_row: on a GPU their gradients are two-stage sums)
    let z = (b.actions.clone() - mu.clone()) / nets::batch_row(sigma.clone(), rows);
    let log_prob = z.square().sum_dim(1).mul_scalar(-0.5) - nets::batch_row(log_std.clone().sum_dim(1), rows);
    let log_prob = log_prob.sub_scalar(0.5 * a as f64 * LN_2PI);
    let ratio = (log_prob - b.old_log_prob.clone()).exp(); // [B, 1]
    let eps = cfg.clip_param as f64;
    let surr = -(b.advantages.clone() * ratio.clone());
    let surr_clipped = -(b.advantages.clone() * ratio.clamp(1.0 - eps, 1.0 + eps));
    let surrogate = nets::mean_all(surr.max_pair(surr_clipped));
    let value = if cfg.clipped_value_loss {
        let v_clipped = b.old_values.clone() + (v.clone() - b.old_values.clone()).clamp(-eps, eps);
        let l1 = (v - b.returns.clone()).square();
        let l2 = (v_clipped - b.returns.clone()).square();
        nets::mean_all(l1.max_pair(l2))
    } else {
        nets::mean_all((v - b.returns.clone()).square())
    };
    let entropy = log_std.clone().sum_dim(1).add_scalar(0.5 * a as f64 * (1.0 + LN_2PI)).reshape([1]); // [1]
    let total = surrogate.clone() + value.clone().mul_scalar(cfg.value_loss_coef as f64) - entropy.clone().mul_scalar(cfg.entropy_coef as f64);
    // KL of diagonal Gaussians, per row, then the mean
    let mu_d = mu.detach();
    let ls_d = log_std.detach();
    let sig_d = sigma.detach();
    let kl_rows = (ls_d - b.old_sigma.clone().log())
        + (b.old_sigma.clone().square() + (b.old_mu.clone() - mu_d).square()) / (sig_d.square().mul_scalar(2.0))
        - 0.5; // [B, A]
    let kl = nets::mean_all(kl_rows.sum_dim(1));
    let row = Tensor::cat(vec![total.clone().detach().inner(), surrogate.detach().inner(), value.detach().inner(), entropy.detach().inner(), kl.inner()], 0).reshape([1, 5]);
    Losses { root: total.reshape([1, 1]), row }
}

/// What one update did (means over its minibatches; `lr` after the update).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct UpdateStats {
    /// Clipped surrogate loss.
    pub surrogate: f64,
    /// (Clipped) value loss.
    pub value: f64,
    /// Entropy of the policy.
    pub entropy: f64,
    /// KL(π_old ‖ π_new).
    pub kl: f64,
    /// Learning rate after the update.
    pub lr: f64,
    /// Global gradient norm before clipping.
    pub grad_norm: f64,
    /// Mean policy standard deviation σ.
    pub mean_std: f64,
}

/// The PPO learner: networks, optimiser, normalisers, rollout storage, learning rate and RNG.
pub struct Ppo {
    /// The `[ppo]` settings.
    pub cfg: PpoConfig,
    /// The learner device.
    pub device: Device,
    /// Actor and critic parameters.
    pub net: ActorCritic,
    /// The optimiser.
    pub adam: Adam,
    /// Whether observations are normalised (`policy.obs_normalization`).
    pub normalize: bool,
    /// Actor observation normaliser.
    pub obs_norm: Normalizer,
    /// Critic observation normaliser.
    pub priv_norm: Normalizer,
    /// The current rollout.
    pub storage: RolloutStorage,
    /// Current learning rate (adaptive).
    pub lr: f64,
    /// Minibatch shuffles.
    pub rng: Rng,
    /// Env steps recorded in the current rollout.
    step: usize,
    /// The action noise's stream (`learn::noise`): from the seed.
    noise_seed: u32,
    /// Action draws so far (the noise's draw number; saved in checkpoints).
    noise_draw: u32,
    /// Global id of this learner's first env: in a data-parallel job (`crate::dist`) rank r's
    /// envs are `[r·E, (r+1)·E)` of the job's `size·E`, and its noise rows and minibatch rows are
    /// those envs' rows of what one process with every env would draw; 0 with one rank.
    env_offset: usize,
    /// Envs over every rank of the job (`num_envs` with one rank).
    job_envs: usize,
    /// The device-resident rollout, once [`Ppo::start_device_rollouts`] made it (`device.rs`).
    pub(crate) on_device: Option<device::DeviceRollout>,
}

impl Ppo {
    /// A fresh learner for `num_envs` envs and rollouts of `steps` env steps.
    /// `encoder_index`: [`encoder_index`] of the task (empty without `policy.encoder`).
    #[allow(clippy::too_many_arguments)]
    pub fn new(dims: Dims, num_envs: usize, steps: usize, cfg: &PpoConfig, policy: &PolicyConfig, encoder_index: &[usize], device: Device, seed: u64) -> Result<Ppo> {
        let mut rng = Rng::new(seed, 0x5050_4f21);
        let mut net = ActorCritic::new(dims, policy, encoder_index, &device, &mut rng)?;
        // data-parallel (issue 37): every rank starts from rank 0's parameters
        net.broadcast_from_root(&device)?;
        let adam = Adam::new(&net.shapes(), &device);
        Ok(Ppo {
            cfg: cfg.clone(),
            device,
            net,
            adam,
            normalize: policy.obs_normalization,
            obs_norm: Normalizer::new(dims.obs),
            priv_norm: Normalizer::new(dims.priv_obs),
            storage: RolloutStorage::new(steps, num_envs, dims.obs, dims.priv_obs, dims.act),
            lr: cfg.learning_rate as f64,
            rng,
            step: 0,
            noise_seed: (seed ^ (seed >> 32)) as u32 ^ 0xAC71_0A5E,
            noise_draw: 0,
            env_offset: crate::dist::rank() * num_envs,
            job_envs: crate::dist::size() * num_envs,
            on_device: None,
        })
    }

    /// The learner's input and output sizes.
    pub fn dims(&self) -> Dims {
        self.net.dims
    }

    /// Writes the policy into file [`MODEL_FILE`] of `state`: every parameter (`actor.0.weight`
    /// [in, out], …, `log_std` [1, A], `critic.…`, f32), the normalisers (`obs_norm.*`,
    /// `priv_norm.*`, f64) and the JSON metadata (format, dims, activation).
    pub fn save_policy(&self, state: &mut LearnerState) -> Result<()> {
        let names = self.net.names();
        let shapes = self.net.shapes();
        for ((n, s), v) in names.iter().zip(&shapes).zip(self.net.values()?) {
            state.push_tensor(MODEL_FILE, n, s.to_vec(), TensorValues::F32(v));
        }
        let (obs_norm, priv_norm) = self.normalizers()?;
        obs_norm.save("obs_norm", state, MODEL_FILE);
        priv_norm.save("priv_norm", state, MODEL_FILE);
        let d = self.dims();
        let info = serde_json::json!({
            "format": "dextrain.policy.v1",
            "obs_dim": d.obs,
            "priv_dim": d.priv_obs,
            "action_dim": d.act,
            "activation": format!("{:?}", self.net.activation).to_lowercase(),
            "obs_normalization": self.normalize,
        });
        state.set_info(MODEL_FILE, info.to_string());
        Ok(())
    }

    /// Loads the policy (parameters and normalisers) that [`Ppo::save_policy`] wrote (same config).
    pub fn load_policy(&mut self, state: &LearnerState) -> Result<()> {
        let names = self.net.names();
        let shapes = self.net.shapes();
        let mut values = Vec::with_capacity(names.len());
        for (n, s) in names.iter().zip(&shapes) {
            values.push(state.f32s(MODEL_FILE, n, Some(s[0] * s[1]))?);
        }
        let device = self.device.clone();
        self.net.set_values(values, &device)?;
        let d = self.dims();
        self.obs_norm = Normalizer::load("obs_norm", d.obs, state, MODEL_FILE)?;
        self.priv_norm = Normalizer::load("priv_norm", d.priv_obs, state, MODEL_FILE)?;
        if let Some(r) = &mut self.on_device {
            r.norms = super::normalizer::DeviceNormalizers::from_host(&self.obs_norm, &self.priv_norm, &self.device);
        }
        Ok(())
    }

    /// The observation normalisers as they stand (read from the device in a device-resident run).
    pub fn normalizers(&self) -> Result<(Normalizer, Normalizer)> {
        match &self.on_device {
            Some(r) => r.norms.to_host(),
            None => Ok((self.obs_norm.clone(), self.priv_norm.clone())),
        }
    }

    /// Everything a resumed run needs: the policy, Adam (moments in [`OPTIMIZER_FILE`], `adam_step`),
    /// the learning rate (`learning_rate`, exact), the RNG (`rng_state`) and the noise's stream and
    /// draw number (`noise_seed`, `noise_draw`). The rollout storage is
    /// not saved: checkpoints are taken between iterations, when it is empty.
    pub fn state(&self) -> Result<LearnerState> {
        let mut state = LearnerState::default();
        self.save_policy(&mut state)?;
        self.adam.save(&self.net.names(), &self.net.shapes(), &mut state, OPTIMIZER_FILE)?;
        state.set_f64("learning_rate", self.lr);
        state.set_bits("rng_state", self.rng.state);
        state.set_bits("noise_seed", self.noise_seed as u64);
        state.set_bits("noise_draw", self.noise_draw as u64);
        Ok(state)
    }

    /// Restores what [`Ppo::state`] gave.
    pub fn load_state(&mut self, state: &LearnerState) -> Result<()> {
        ensure!(self.step == 0, "load_state() in the middle of a rollout");
        self.load_policy(state)?;
        let device = self.device.clone();
        self.adam.load(&self.net.names(), &self.net.shapes(), state, OPTIMIZER_FILE, &device)?;
        self.lr = state.f64("learning_rate")?;
        self.rng.state = state.bits("rng_state")?;
        self.noise_seed = state.bits("noise_seed")? as u32;
        self.noise_draw = state.bits("noise_draw")? as u32;
        Ok(())
    }


    /// Deterministic action (the policy mean) for raw observations `obs` [N, O] and `priv_obs`
    /// [N, P] (read only by a privileged encoder); statistics unchanged.
    pub fn act_mean(&self, obs: &[f32], priv_obs: &[f32]) -> Result<Vec<f32>> {
        let (x, p) = self.inference_inputs(obs, priv_obs)?;
        to_host(self.net.actor(&self.net.inference_params(), x, p))
    }

    /// The actor's inputs for raw observations `obs` [N, O] / `priv_obs` [N, P], normalised: x
    /// [N, O], and the critic observation [N, P] for a privileged encoder (the actor reads it for
    /// nothing else: without one, x stands in for it and it does not go up). On a GPU the raw rows
    /// go up with the statistics and are normalised there, on the CPU on the host
    /// (`Normalizer::normalized_tensor`).
    fn inference_inputs(&self, obs: &[f32], priv_obs: &[f32]) -> Result<(Tensor<2>, Tensor<2>)> {
        let d = self.dims();
        let n = obs.len() / d.obs;
        ensure!(obs.len() == n * d.obs && priv_obs.len() == n * d.priv_obs, "observation sizes do not match the learner");
        let x = self.obs_norm.normalized_tensor(obs, n, &self.device, self.normalize);
        let p = if self.net.encoder_shapes.is_empty() { x.clone() } else { self.priv_norm.normalized_tensor(priv_obs, n, &self.device, self.normalize) };
        Ok((x, p))
    }

    /// [`Ppo::act_mean`]'s phases timed apart (ms), each ended by a wait for the device: the
    /// inputs made and uploaded (normalised on the device on a GPU), the actor's forward pass,
    /// the actions read back; and, for comparison, the host's f64 normalisation of `obs` alone
    /// (what the inputs cost the host before they were normalised on the GPU). `dextrain bench
    /// --ppo` reports them.
    pub fn act_mean_phases_ms(&self, obs: &[f32], priv_obs: &[f32]) -> Result<[f64; 4]> {
        let ms = |t: std::time::Instant| 1e3 * t.elapsed().as_secs_f64();
        let t = std::time::Instant::now();
        std::hint::black_box(self.obs_norm.normalized(obs, self.normalize));
        let host_normalize = ms(t);
        let t = std::time::Instant::now();
        let (x, p) = self.inference_inputs(obs, priv_obs)?;
        crate::gpu::io::sync(&self.device)?;
        let inputs = ms(t);
        let t = std::time::Instant::now();
        let mu = self.net.actor(&self.net.inference_params(), x, p);
        crate::gpu::io::sync(&self.device)?;
        let forward = ms(t);
        let t = std::time::Instant::now();
        std::hint::black_box(to_host(mu)?);
        Ok([host_normalize, inputs, forward, ms(t)])
    }

    /// Samples actions [N, A] for raw observations `obs` [N, O] / `priv_obs` [N, P], updating the
    /// normalisers first (training), and records the first half of the transition.
    pub fn act(&mut self, obs: &[f32], priv_obs: &[f32]) -> Result<Vec<f32>> {
        let d = self.dims();
        let n = self.storage.envs;
        ensure!(obs.len() == n * d.obs && priv_obs.len() == n * d.priv_obs, "observation sizes do not match the learner");
        ensure!(self.step < self.storage.steps, "rollout storage is full: call update()");
        if self.normalize {
            self.obs_norm.update(obs);
            self.priv_norm.update(priv_obs);
        }
        let obs_n = self.obs_norm.normalized(obs, self.normalize);
        let priv_n = self.priv_norm.normalized(priv_obs, self.normalize);
        let params = self.net.inference_params();
        let priv_t = to_tensor(priv_n.clone(), [n, d.priv_obs], &self.device);
        let mu = self.net.actor(&params, to_tensor(obs_n.clone(), [n, d.obs], &self.device), priv_t.clone()); // [N, A]
        let values = self.net.critic(&params, priv_t); // [N, 1]
        let log_std = self.net.log_std(&params); // [1, A]
        // one read: rows [μ | V] [N, A + 1], then [log σ | 0] [1, A + 1]
        let last = Tensor::cat(vec![log_std.clone(), log_std.zeros_like().narrow(1, 0, 1)], 1);
        let read = to_host(Tensor::cat(vec![Tensor::cat(vec![mu, values], 1), last], 0))?;
        let w = d.act + 1;
        let mu: Vec<f32> = read[..n * w].chunks(w).flat_map(|r| r[..d.act].iter().copied()).collect(); // [N, A]
        let values: Vec<f32> = read[..n * w].chunks(w).map(|r| r[d.act]).collect(); // [N]
        let log_std: Vec<f32> = read[n * w..n * w + d.act].to_vec(); // [A]
        let sigma: Vec<f32> = log_std.iter().map(|l| l.exp()).collect();
        let sum_log_std: f64 = log_std.iter().map(|&l| l as f64).sum();
        ensure!(self.on_device.is_none(), "act() in a device-resident run (act_device)");
        // ε ~ N(0, 1) [N, A]: this rank's envs' rows of the job's draw
        let eps = host_normals_from_row(self.noise_seed, self.noise_draw, self.env_offset as u32, n, d.act);
        self.noise_draw = self.noise_draw.wrapping_add(1);
        let t = self.step;
        let s = &mut self.storage;
        let mut actions = vec![0.0f32; n * d.act];
        for i in 0..n {
            let row = t * n + i;
            let mut sq = 0.0f64;
            for k in 0..d.act {
                let a = mu[i * d.act + k] + sigma[k] * eps[i * d.act + k]; // a = μ + σ ε
                actions[i * d.act + k] = a;
                sq += (eps[i * d.act + k] as f64).powi(2);
                s.mu[row * d.act + k] = mu[i * d.act + k];
                s.sigma[row * d.act + k] = sigma[k];
            }
            // log π(a|s) = −½ Σ ε² − Σ log σ − ½ A ln 2π
            s.log_prob[row] = (-0.5 * sq - sum_log_std - 0.5 * d.act as f64 * LN_2PI) as f32;
            s.values[row] = values[i];
        }
        s.obs[t * n * d.obs..(t + 1) * n * d.obs].copy_from_slice(&obs_n);
        s.priv_obs[t * n * d.priv_obs..(t + 1) * n * d.priv_obs].copy_from_slice(&priv_n);
        s.actions[t * n * d.act..(t + 1) * n * d.act].copy_from_slice(&actions);
        Ok(actions)
    }

    /// Records the outcome of the step started by the last `act`: rewards [N], and which envs
    /// terminated or timed out (then reset). The rewards are scaled by `ppo.reward_scale`; a
    /// time-out adds `γ V(s_t)` (on that scale) to the reward.
    pub fn process_step(&mut self, rewards: &[f32], terminated: &[bool], time_outs: &[bool]) {
        let n = self.storage.envs;
        let t = self.step;
        let gamma = self.cfg.gamma;
        let s = &mut self.storage;
        for i in 0..n {
            let row = t * n + i;
            // the learner's reward: ppo.reward_scale × the env's
            let mut r = rewards[i] * self.cfg.reward_scale;
            if time_outs[i] && !terminated[i] {
                r += gamma * s.values[row]; // bootstrap through the time-out
            }
            s.rewards[row] = r;
            s.dones[row] = (terminated[i] || time_outs[i]) as u8 as f32;
        }
        self.step += 1;
        s.len = self.step * n;
    }

    /// Whether `steps` transitions per env have been recorded.
    pub fn rollout_full(&self) -> bool {
        self.step == self.storage.steps
    }

    /// GAE from the critic's value of `last_priv_obs` (raw, [N, P]), then `epochs` × `minibatches`
    /// gradient steps. Clears the storage.
    pub fn update(&mut self, last_priv_obs: &[f32]) -> Result<UpdateStats> {
        ensure!(self.rollout_full(), "update() before the rollout is full ({} of {} steps)", self.step, self.storage.steps);
        let d = self.dims();
        let n = self.storage.envs;
        let priv_n = self.priv_norm.normalized(last_priv_obs, self.normalize);
        let last_values = to_host(self.net.critic(&self.net.inference_params(), to_tensor(priv_n, [n, d.priv_obs], &self.device)))?;
        self.storage.compute_returns(&last_values, self.cfg.gamma, self.cfg.lam);

        let s = &self.storage;
        let total = s.capacity();
        let dev = &self.device;
        // the rollout goes up copied once (`nets::upload`)
        let col = |v: &[f32]| nets::upload(v, [total, 1], dev);
        let all = Batch {
            obs: nets::upload(&s.obs, [total, d.obs], dev)?,
            priv_obs: nets::upload(&s.priv_obs, [total, d.priv_obs], dev)?,
            actions: nets::upload(&s.actions, [total, d.act], dev)?,
            old_log_prob: col(&s.log_prob)?,
            old_mu: nets::upload(&s.mu, [total, d.act], dev)?,
            old_sigma: to_tensor(s.sigma[..d.act].to_vec(), [1, d.act], dev), // every row's σ is the first's
            advantages: col(&s.advantages)?,
            returns: col(&s.returns)?,
            old_values: col(&s.values)?,
        };
        self.storage.clear();
        self.optimise(all, total)
    }

    /// `epochs` × `minibatches` gradient steps over the rollout `all` (`total` rows), shuffled by
    /// the learner RNG; ends the rollout.
    ///
    /// Nothing is read back inside the minibatch loop: the minibatches' rows are one upload (every
    /// epoch's permutation, drawn as before), the adaptive learning rate is a `[1, 1]` tensor that
    /// [`adapt_learning_rate`] changes from each minibatch's KL on the device, and each
    /// minibatch's losses, KL and gradient norm stay on the device; the update reads them, the
    /// learning rate and log σ once at its end and adds them up in the order the device did.
    pub(crate) fn optimise(&mut self, all: Batch, total: usize) -> Result<UpdateStats> {
        let dev = &self.device.clone();
        let inner = dev.clone().inner();
        let on_gpu = super::nets::is_gpu(dev);
        let (epochs, minibatches) = (self.cfg.epochs as usize, self.cfg.minibatches as usize);
        ensure!(total == self.storage.steps * self.storage.envs, "a rollout of {total} rows for {} steps × {} envs", self.storage.steps, self.storage.envs);
        let plan = minibatch_rows(&mut self.rng, epochs, minibatches, self.storage.steps, self.storage.envs, self.env_offset, self.job_envs);
        if on_gpu {
            crate::host_traffic::add(4 * plan.rows.len() as u64);
            crate::gpu_counts::add(crate::gpu_counts::Event::Upload, "burn:from_data (minibatch indices)");
        }
        let n_rows = plan.rows.len();
        let rows = Tensor::<1, Int>::from_data(TensorData::new(plan.rows, [n_rows]), dev);
        let mut lr = to_tensor(vec![self.lr as f32], [1, 1], &inner);
        // each minibatch's [total, surrogate, value, entropy, KL] [1, 5] and ‖g‖ [1, 1], read once
        let (mut loss_rows, mut norms) = (Vec::with_capacity(epochs * minibatches), Vec::with_capacity(epochs * minibatches));
        let count = epochs * minibatches;
        let data_parallel = crate::dist::size() > 1;
        // on a GPU the loss is one operation of ours, two kernels each way (kernels::ppo_loss,
        // where the tensor ops of `ppo_losses` launch ~110), reading the rollout's per-row columns
        // side by side: one gather per minibatch picks them
        let columns = on_gpu.then(|| ppo_loss::loss_columns(all.actions.clone(), all.old_mu.clone(), all.old_log_prob.clone(), all.advantages.clone(), all.returns.clone(), all.old_values.clone()));
        let coefs = LossCoefs { clip: self.cfg.clip_param as f64, value_coef: self.cfg.value_loss_coef as f64, entropy_coef: self.cfg.entropy_coef as f64, clipped_value: self.cfg.clipped_value_loss };
        // `train --gpu-profile` (gpu::profile): each minibatch's forward pass with its loss, and its
        // backward pass, as spans of their own (inside the update's)
        let profile_ctx = crate::learn::device::gpu_context_of(dev);
        let profile_ctx = profile_ctx.as_ref();
        // on a GPU each epoch's rows of the observations, the critic's and the loss's columns are
        // gathered once (a select each) and a minibatch is a row range of them: a view of that
        // memory, no kernel, where every range of the epoch starts and ends on the device's binding
        // alignment (else burn's slice copies it, and each minibatch is gathered apart as before:
        // a select per tensor and minibatch)
        let alignment = columns.as_ref().and_then(|_| view_alignment(&all.obs));
        // the current epoch's first row in `plan.rows` and its gathered rows (None: gathered per
        // minibatch), decided and gathered at the epoch's first minibatch
        let mut epoch_rows: Option<(usize, [Tensor<2>; 3])> = None;
        for k in 0..count {
            let (from, len) = (plan.starts[k], plan.starts[k + 1] - plan.starts[k]);
            // the minibatch's rows, taken where a tensor is gathered per minibatch
            let idx = std::cell::OnceCell::new();
            let pick = |t: &Tensor<2>| t.clone().select(0, idx.get_or_init(|| rows.clone().narrow(0, from, len)).clone());
            if k % minibatches == 0 {
                let epoch = k / minibatches;
                let (e_from, e_to) = (plan.starts[epoch * minibatches], plan.starts[((epoch + 1) * minibatches).min(count)]);
                epoch_rows = match (&columns, alignment) {
                    (Some(cols), Some(align)) => {
                        let widths = [all.obs.dims()[1], all.priv_obs.dims()[1], cols.dims()[1]];
                        // bytes from the epoch's first row and to its last, on the alignment for every width
                        let on_alignment = |row_count: usize| widths.iter().all(|w| ((row_count * w * 4) as u64).is_multiple_of(align));
                        let ranges_aligned = (epoch * minibatches..((epoch + 1) * minibatches).min(count)).all(|j| on_alignment(plan.starts[j] - e_from) && on_alignment(e_to - plan.starts[j + 1]));
                        ranges_aligned.then(|| {
                            let epoch_idx = rows.clone().narrow(0, e_from, e_to - e_from);
                            (e_from, [&all.obs, &all.priv_obs, cols].map(|t| t.clone().select(0, epoch_idx.clone())))
                        })
                    }
                    _ => None,
                };
            }
            let from_epoch = epoch_rows.as_ref().map(|(e_from, g)| g.clone().map(|t| t.narrow(0, from - e_from, len)));
            let (obs, priv_obs, picked_columns) = match from_epoch {
                Some([o, p, c]) => (o, p, Some(c)),
                None => (pick(&all.obs), pick(&all.priv_obs), None),
            };
            let params = &self.net.params;
            let losses = around_burn(profile_ctx, dev, "ppo forward and loss", || {
                let mu = self.net.actor(params, obs.clone(), priv_obs.clone());
                let v = self.net.critic(params, priv_obs.clone());
                Ok(match &columns {
                    Some(columns) => {
                        let cols = picked_columns.clone().unwrap_or_else(|| pick(columns));
                        Losses::from_fused(ppo_loss::ppo_loss_fused(mu, self.net.log_std(params), v, all.old_sigma.clone(), cols, coefs))
                    }
                    None => {
                        let b = Batch {
                            obs,
                            priv_obs,
                            actions: pick(&all.actions),
                            old_log_prob: pick(&all.old_log_prob),
                            old_mu: pick(&all.old_mu),
                            old_sigma: all.old_sigma.clone(), // [1, A]: σ is the same for every row of a rollout
                            advantages: pick(&all.advantages),
                            returns: pick(&all.returns),
                            old_values: pick(&all.old_values),
                        };
                        ppo_losses(mu, self.net.log_std(params), v, &b, &self.cfg)
                    }
                })
            })?;
            // with several ranks the loss and the KL are this rank's rows' means weighted by its
            // share of the minibatch (`MinibatchRows::weights`), so that their means over the ranks
            // are the job's minibatch's means
            let w = plan.weights[k];
            if self.cfg.schedule == LrSchedule::Adaptive {
                lr = if data_parallel {
                    let kl = losses.row.clone().narrow(1, KL_COLUMN, 1).reshape([1]).mul_scalar(w);
                    adapt_learning_rate(lr, &kl_over_ranks(kl)?.reshape([1, 1]), 0, &self.cfg)
                } else {
                    adapt_learning_rate(lr, &losses.row, KL_COLUMN, &self.cfg)
                };
            }
            let root = if data_parallel { losses.root.mul_scalar(w) } else { losses.root };
            let grads = around_burn(profile_ctx, dev, "ppo backward", || Ok(root.backward()))?;
            let (new_params, norm) = self.adam.step_clipped(params, &grads, self.cfg.max_grad_norm as f64, &lr)?;
            let norm = norm.context("PPO's optimiser reports its gradient norm")?.inner();
            self.net.params = new_params;
            loss_rows.push(losses.row);
            norms.push(norm.reshape([1, 1]));
        }
        self.step = 0;
        // the update's one read: every minibatch's losses and gradient norm (stacked rows: on a GPU
        // a kernel of ours each, where adding them up on the device launched two a minibatch), the
        // learning rate, log σ
        let log_std = self.net.log_std(&self.net.inference_params()); // [1, A]
        let mut parts = vec![lr];
        if count > 0 {
            parts.push(nets::stack_rows(loss_rows).reshape([1, 5 * count])); // [count, 5] as one row
            parts.push(nets::stack_rows(norms).reshape([1, count]));
        }
        parts.push(log_std);
        let v = to_host(Tensor::cat(parts, 1))?;
        self.lr = v[0] as f64;
        // [surrogate, value, entropy, KL, ‖g‖] summed over the minibatches in order, in f32: the
        // additions the device made before, the same bits (the total is not reported)
        let mut s = [0.0f32; 5];
        for j in 0..count {
            for (c, sum) in s[..4].iter_mut().enumerate() {
                *sum += v[1 + 5 * j + 1 + c];
            }
            s[4] += v[1 + 5 * count + j];
        }
        let log_std = &v[1 + 6 * count..];
        let c = count.max(1) as f64;
        Ok(UpdateStats {
            surrogate: s[0] as f64 / c,
            value: s[1] as f64 / c,
            entropy: s[2] as f64 / c,
            kl: s[3] as f64 / c,
            grad_norm: s[4] as f64 / c,
            lr: self.lr,
            mean_std: log_std.iter().map(|l| (*l as f64).exp()).sum::<f64>() / log_std.len().max(1) as f64,
        })
    }
}

/// The rows of every minibatch of an update, in order, as [`minibatch_rows`] draws them.
pub struct MinibatchRows {
    /// This rank's rows (indices into its rollout) of every minibatch, one after another.
    pub rows: Vec<i32>,
    /// Where minibatch k's rows start in `rows` (`epochs · minibatches + 1` entries).
    pub starts: Vec<usize>,
    /// Each minibatch's weight on this rank: its rows' count × ranks ÷ the job's minibatch size
    /// (1 with one rank; 0 for a minibatch with none of this rank's rows, which then holds one row
    /// as a stand-in so that its loss is finite).
    pub weights: Vec<f32>,
}

/// The minibatches of an update over a rollout of `steps × envs` rows (row `t·E + i`: env i at step
/// t) of this rank's `E = envs` envs, the job's envs `[env_offset, env_offset + E)` of `job_envs`
/// (a multiple of E): each epoch draws one permutation of the job's `steps · job_envs` rows from
/// `rng` (the same on every rank) and cuts it into `minibatches` minibatches of
/// `⌊steps · job_envs / minibatches⌋` rows; a rank takes the rows of each that are its own. So N
/// ranks × E envs pick the minibatches one process with N·E envs picks, and with one rank this is
/// the rollout's permutation cut into minibatches, as rsl_rl cuts it.
pub fn minibatch_rows(rng: &mut Rng, epochs: usize, minibatches: usize, steps: usize, envs: usize, env_offset: usize, job_envs: usize) -> MinibatchRows {
    let job_total = steps * job_envs;
    let mb_size = job_total / minibatches.max(1);
    let ranks = job_envs / envs.max(1);
    let mut out = MinibatchRows { rows: Vec::with_capacity(epochs * minibatches * mb_size / ranks.max(1)), starts: vec![0], weights: Vec::new() };
    for _epoch in 0..epochs {
        let perm = rng.permutation(job_total);
        for b in 0..minibatches {
            let start = out.rows.len();
            for &g in &perm[b * mb_size..(b + 1) * mb_size] {
                // the job's row g is its env g % job_envs at step g / job_envs
                let (t, e) = (g / job_envs, g % job_envs);
                if (env_offset..env_offset + envs).contains(&e) {
                    out.rows.push((t * envs + e - env_offset) as i32);
                }
            }
            let mine = out.rows.len() - start;
            out.weights.push((mine * ranks) as f32 / mb_size.max(1) as f32);
            if mine == 0 {
                out.rows.push(0);
            }
            out.starts.push(out.rows.len());
        }
    }
    out
}

/// The byte alignment at which burn's wgpu runtime binds a range of a tensor's memory as a view
/// (burn's slice copies a range whose first or last byte is off it), or None off that runtime.
fn view_alignment(t: &Tensor<2>) -> Option<u64> {
    let p = t.clone().inner().try_into_primitive::<burn::backend::Cube>().ok()?;
    Some(p.client.properties().memory.alignment)
}

/// A minibatch's KL `[1]`, averaged over the ranks of a data-parallel job (one read and one
/// all-reduce of a number; with one rank the tensor as it is, no read): every rank adapts its
/// learning rate alike.
pub fn kl_over_ranks(kl: Tensor<1>) -> Result<Tensor<1>> {
    if crate::dist::size() == 1 {
        return Ok(kl);
    }
    let device = kl.device();
    let mut v = to_host(kl)?;
    crate::dist::mean_f32(&mut v);
    let n = v.len();
    Ok(Tensor::from_data(TensorData::new(v, [n]), &device))
}

/// rsl_rl's adaptive learning rate from a minibatch's KL, the entry `column` of `kl_row` `[1, n]`,
/// without a host read: `lr / 1.5` (at least `min_learning_rate`) when `kl > 2 · desired_kl`,
/// `lr · 1.5` (at most `max_learning_rate`) when `0 < kl < desired_kl / 2`, else unchanged (a
/// non-finite KL too). On a GPU one kernel of ours (`kernels::adaptive_lr`), elsewhere `[1, 1]`
/// tensor ops; the same f32 arithmetic either way.
pub fn adapt_learning_rate(lr: Tensor<2>, kl_row: &Tensor<2>, column: usize, cfg: &PpoConfig) -> Tensor<2> {
    let target = cfg.desired_kl as f64;
    let schedule = AdaptiveLr { above: (2.0 * target) as f32, below: (0.5 * target) as f32, min: cfg.min_learning_rate, max: cfg.max_learning_rate };
    if let Some(adapted) = adaptive_lr::adapt_on_gpu(&lr, kl_row, column, schedule) {
        return adapted;
    }
    let kl: Tensor<2> = kl_row.clone().narrow(1, column, 1); // [1, 1]
    let finite = kl.clone().is_finite();
    let down = kl.clone().greater_elem(schedule.above).bool_and(finite.clone());
    let up = kl.clone().lower_elem(schedule.below).bool_and(kl.greater_elem(0.0)).bool_and(finite);
    let lower = lr.clone().div_scalar(1.5).clamp_min(schedule.min);
    let higher = lr.clone().mul_scalar(1.5).clamp_max(schedule.max);
    lr.mask_where(down, lower).mask_where(up, higher)
}
