//! `[sac]`: Soft Actor-Critic as the massively parallel off-policy learners build it (FastTD3,
//! FastSAC; docs/design.md §6). The networks' widths, activation, observation normalisation and
//! `zero_init_output` come from `[policy]`; the iteration length (env steps of every env per metrics
//! row) is `train.steps_per_env`.

use anyhow::Result;
use serde::{Deserialize, Serialize};

use super::Check;

/// How the Q critics' values are combined into the target and the actor's objective (`sac.q_reduction`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum QReduction {
    /// The smallest of the critics' values (clipped double-Q: SAC, TD3).
    Min,
    /// Their mean (FastSAC; with many critics, REDQ-like ensembles use it too).
    Mean,
}

/// `[sac]`
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SacConfig {
    /// Discount γ.
    pub gamma: f32,
    /// n of the n-step return `Σ_{k<n} γᵏ r_{t+k} + γⁿ V(s_{t+n})`, cut at an episode's end: a
    /// termination ends it without bootstrap, a time-out bootstraps from the episode's true final
    /// observation. 1 is the textbook target; FastTD3 uses 3 on dexterous tasks.
    pub n_step: u32,
    /// Polyak factor τ of the target critics: `θ̄ ← τ θ + (1 − τ) θ̄` after every critic update
    /// (τ = 1 copies).
    pub tau: f32,
    /// Transitions per gradient step (thousands to tens of thousands with thousands of envs).
    pub batch_size: u32,
    /// Gradient steps (critic updates) per env step of all envs (the update-to-data ratio).
    pub updates_per_step: u32,
    /// The actor and the temperature are updated on every this-many-th critic update (TD3's delayed
    /// policy update; 1 = every one).
    pub policy_frequency: u32,
    /// Env steps of every env before the first gradient step.
    pub learning_starts: u32,
    /// Env steps of every env, from the start of the run, with actions drawn uniformly in [−1, 1]
    /// instead of from the policy.
    pub random_steps: u32,
    /// Transitions kept per env (per-env ring buffers `[N_env, capacity]`: the buffer holds
    /// `sim.num_envs × buffer_capacity` transitions; `train` prints its size before it starts).
    pub buffer_capacity: u32,
    /// Store the actor's observations in the buffer. `false` keeps only what the critics need: the
    /// actor learns from the clean actor observation at the head of the critic observation
    /// (without the actor's noise and delays) and each transition takes 2·obs_dim floats less.
    pub store_actor_obs: bool,
    /// Write the replay buffer into checkpoints, so that `--resume` continues exactly. `false`
    /// keeps checkpoints small: a resumed run then starts with an empty buffer (and says that it is
    /// not an exact resume).
    pub checkpoint_buffer: bool,
    /// Adam's learning rate of the actor.
    pub actor_learning_rate: f32,
    /// Adam's learning rate of the critics.
    pub critic_learning_rate: f32,
    /// Adam's learning rate of log α.
    pub alpha_learning_rate: f32,
    /// Decoupled weight decay of the actor's and critics' optimisers (AdamW; 0 = Adam; FastTD3: 0.1).
    pub weight_decay: f32,
    /// Clip of the global gradient norm of each network's update (0 = no clipping).
    pub max_grad_norm: f32,
    /// Number of Q critics (each with its target network).
    pub num_critics: u32,
    /// `"min"` (clipped double-Q) or `"mean"` over the critics, for the target and the actor's loss.
    pub q_reduction: QReduction,
    /// Learn the temperature α (on log α) toward the target entropy; `false` keeps α = `init_alpha`.
    pub learn_alpha: bool,
    /// The temperature α at the start.
    pub init_alpha: f32,
    /// The target entropy is `target_entropy_scale × (−|A|)` (|A| = action size): 1 is SAC's
    /// heuristic −|A|; smaller scales ask for less randomness (FastSAC scales it).
    pub target_entropy_scale: f32,
    /// The lower end of the actor's state-dependent log σ (the network's output is squashed into
    /// `[log_std_min, log_std_max]` by `min + ½ (max − min)(tanh(x) + 1)`).
    pub log_std_min: f32,
    /// The upper end of log σ.
    pub log_std_max: f32,
    /// LayerNorm after every hidden layer of the critics (before the activation).
    pub critic_layer_norm: bool,
    /// LayerNorm after every hidden layer of the actor.
    pub actor_layer_norm: bool,
    /// Factor on the rewards before the critics' targets (logged rewards are unscaled).
    pub reward_scale: f32,
    /// The most bytes of one piece of a device-resident replay array (0: the adapter's largest
    /// storage binding). An array larger than that is stored as several pieces of whole slots
    /// (every env's transitions of a step stay in one piece), so a buffer of any size starts on any
    /// adapter; a smaller value only forces the split (the tests do, on lavapipe).
    pub device_piece_bytes: u64,
}

impl Default for SacConfig {
    fn default() -> Self {
        SacConfig {
            gamma: 0.99,
            n_step: 1,
            tau: 0.005,
            batch_size: 4096,
            updates_per_step: 1,
            policy_frequency: 1,
            learning_starts: 10,
            random_steps: 0,
            buffer_capacity: 1024,
            store_actor_obs: true,
            checkpoint_buffer: true,
            actor_learning_rate: 3e-4,
            critic_learning_rate: 3e-4,
            alpha_learning_rate: 3e-4,
            weight_decay: 0.0,
            max_grad_norm: 0.0,
            num_critics: 2,
            q_reduction: QReduction::Min,
            learn_alpha: true,
            init_alpha: 0.2,
            target_entropy_scale: 1.0,
            log_std_min: -5.0,
            log_std_max: 2.0,
            critic_layer_norm: false,
            actor_layer_norm: false,
            reward_scale: 1.0,
            device_piece_bytes: 0,
        }
    }
}

impl SacConfig {
    /// Checks `[sac]` (`num_envs`: sim.num_envs).
    pub fn validate(&self, c: &Check, num_envs: u64) -> Result<()> {
        c.in_range("sac.gamma", self.gamma, 0.0, 1.0, "a discount in [0, 1]")?;
        if !(1..=64).contains(&self.n_step) {
            return Err(c.err("sac.n_step", self.n_step, "an integer in [1, 64]"));
        }
        c.in_range("sac.tau", self.tau, 1e-9, 1.0, "a Polyak factor in (0, 1]")?;
        if !(1..=1 << 22).contains(&self.batch_size) {
            return Err(c.err("sac.batch_size", self.batch_size, "an integer in [1, 4194304]"));
        }
        if !(1..=1000).contains(&self.updates_per_step) {
            return Err(c.err("sac.updates_per_step", self.updates_per_step, "an integer in [1, 1000] (gradient steps per env step)"));
        }
        if !(1..=1000).contains(&self.policy_frequency) {
            return Err(c.err("sac.policy_frequency", self.policy_frequency, "an integer in [1, 1000]"));
        }
        if self.buffer_capacity < self.n_step.max(2) {
            return Err(c.err("sac.buffer_capacity", self.buffer_capacity, &format!("an integer >= max(2, sac.n_step = {}) (transitions kept per env)", self.n_step)));
        }
        if num_envs.checked_mul(self.buffer_capacity as u64).is_none_or(|t| t > 1 << 40) {
            return Err(c.err("sac.buffer_capacity", self.buffer_capacity, &format!("sim.num_envs ({num_envs}) × sac.buffer_capacity at most 2^40 transitions")));
        }
        c.in_range("sac.actor_learning_rate", self.actor_learning_rate, 1e-9, 1.0, "a learning rate in (0, 1]")?;
        c.in_range("sac.critic_learning_rate", self.critic_learning_rate, 1e-9, 1.0, "a learning rate in (0, 1]")?;
        c.in_range("sac.alpha_learning_rate", self.alpha_learning_rate, 1e-9, 1.0, "a learning rate in (0, 1]")?;
        c.in_range("sac.weight_decay", self.weight_decay, 0.0, 10.0, "a weight decay in [0, 10]")?;
        c.non_neg("sac.max_grad_norm", self.max_grad_norm)?;
        if !(1..=16).contains(&self.num_critics) {
            return Err(c.err("sac.num_critics", self.num_critics, "an integer in [1, 16]"));
        }
        c.in_range("sac.init_alpha", self.init_alpha, 1e-12, 1e6, "a temperature > 0")?;
        c.in_range("sac.target_entropy_scale", self.target_entropy_scale, -100.0, 100.0, "a factor in [-100, 100]")?;
        c.in_range("sac.log_std_min", self.log_std_min, -20.0, 5.0, "a log standard deviation in [-20, 5]")?;
        c.in_range("sac.log_std_max", self.log_std_max, self.log_std_min + 1e-3, 5.0, "a log standard deviation in (sac.log_std_min, 5]")?;
        c.in_range("sac.reward_scale", self.reward_scale, 1e-9, 1e9, "a factor > 0")?;
        Ok(())
    }

    /// Bytes that one transition takes in the replay buffer for observation sizes `obs`, `priv_obs`
    /// and `act` actions: f32 observations (before and after the step), action and reward, and two
    /// flag bytes (episode ended, terminated).
    pub fn bytes_per_transition(&self, obs: usize, priv_obs: usize, act: usize) -> u64 {
        let actor = if self.store_actor_obs { 2 * obs } else { 0 };
        (4 * (actor + 2 * priv_obs + act + 1) + 2) as u64
    }
}
