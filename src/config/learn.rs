//! `[train]`, `[ppo]` and `[policy]`: the learner's device, the run's length and checkpoints, PPO's
//! hyper-parameters (DESIGN §6, rsl_rl's names and defaults) and the networks.

use anyhow::Result;
use serde::{Deserialize, Serialize};

use super::{BackendChoice, Check};

/// `[train]`
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TrainConfig {
    /// Learner device, chosen like `sim.backend`: `"auto"`, `"cpu"` (burn's flex backend), `"gpu"` or
    /// `"gpu:NAME"` (burn's wgpu backend; on the simulator's own device when the simulator is on the GPU).
    pub device: BackendChoice,
    /// PPO iterations (each: `steps_per_env` env steps of every env, then one update).
    pub iterations: u32,
    /// Env steps per env per iteration (rollout length).
    pub steps_per_env: u32,
    /// Write a checkpoint every this many iterations (and always after the last one).
    pub save_interval: u32,
    /// Keep only the newest this many checkpoints (0 = keep all).
    pub keep_checkpoints: u32,
    /// Redraw the learning-curve PNGs every this many iterations (0 = only at the end).
    pub plot_interval: u32,
    /// Start each env's first episode at a random step count in [0, episode_length), so that the
    /// envs' episodes do not all end in the same iteration (rsl_rl's `init_at_random_ep_len`).
    /// The lift task only: a reference kind's episodes start at their reference's first frame
    /// (`task.reference.time_scale` spreads their ends).
    pub init_at_random_ep_len: bool,
}

/// How PPO's learning rate changes between updates (`ppo.schedule`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LrSchedule {
    /// From the KL of each minibatch: ÷1.5 above 2× `desired_kl`, ×1.5 below ½× (rsl_rl).
    Adaptive,
    /// `learning_rate` throughout.
    Fixed,
}

/// `[ppo]` (DESIGN §6; rsl_rl's names and defaults)
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PpoConfig {
    /// Initial learning rate of Adam.
    pub learning_rate: f32,
    /// `"adaptive"` (from the KL: ÷1.5 above 2× `desired_kl`, ×1.5 below ½×) or `"fixed"`.
    pub schedule: LrSchedule,
    /// Target KL divergence between the old and the new policy per update.
    pub desired_kl: f32,
    /// Lower bound of the adaptive learning rate.
    pub min_learning_rate: f32,
    /// Upper bound of the adaptive learning rate.
    pub max_learning_rate: f32,
    /// Discount γ.
    pub gamma: f32,
    /// GAE λ.
    pub lam: f32,
    /// Clip range ε of the surrogate (and of the value loss).
    pub clip_param: f32,
    /// Weight of the value loss.
    pub value_loss_coef: f32,
    /// Clip the value loss around the old values (rsl_rl's `use_clipped_value_loss`).
    pub clipped_value_loss: bool,
    /// Weight of the entropy bonus.
    pub entropy_coef: f32,
    /// Passes over the rollout per update.
    pub epochs: u32,
    /// Minibatches per pass.
    pub minibatches: u32,
    /// Clip of the global gradient norm (actor and critic together).
    pub max_grad_norm: f32,
    /// Factor on the rewards before the value targets and advantages (rl_games' `scale_value`);
    /// logged rewards and returns are unscaled. The clipped value loss moves each value by at most
    /// `clip_param` per update, so with large per-step rewards (DexRefine's weights sum to ~45 per
    /// step, returns of thousands) the critic needs many updates to follow; 0.01–0.1 brings the
    /// returns back to O(10–100).
    pub reward_scale: f32,
}

/// Hidden-layer activation of the actor and critic MLPs (`policy.activation`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Activation {
    /// ELU(x) = x for x > 0, eˣ − 1 below.
    Elu,
    /// ReLU(x) = max(x, 0).
    Relu,
    /// tanh(x).
    Tanh,
}

/// `[policy]`
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PolicyConfig {
    /// Hidden layer widths of the actor MLP.
    pub actor_hidden: Vec<usize>,
    /// Hidden layer widths of the critic MLP.
    pub critic_hidden: Vec<usize>,
    /// Hidden activation: `"elu"`, `"relu"` or `"tanh"`.
    pub activation: Activation,
    /// Initial standard deviation of the Gaussian policy (its log is learned, one per action).
    pub init_std: f32,
    /// Normalise observations with running mean and variance (saved with the model).
    pub obs_normalization: bool,
    /// Start the actor's output layer at zero, so that the initial policy mean is 0: a residual
    /// policy then starts as the reference it corrects (residual RL's usual initialisation).
    pub zero_init_output: bool,
    /// `[policy.encoder]`: a privileged encoder (DexRefine's teacher). Absent: none.
    pub encoder: Option<EncoderConfig>,
}

/// `[policy.encoder]`: an MLP `μ(ê) → ẑ` over privileged inputs (critic-observation fields, each
/// normalised as the critic sees it) whose output is concatenated with the actor's observation
/// before the actor MLP: the actor's input is `[ŝ; ẑ]`. Trained by PPO with the rest.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct EncoderConfig {
    /// The privileged inputs, by critic-observation field name (`dextrain check` lists them): e.g.
    /// object physics `obj_mass`, `obj_friction`, `obj_scale`, the object's `obj_pos`, `obj_rot`,
    /// `obj_vel`, `obj_angvel`, contacts `tip_contact`.
    pub inputs: Vec<String>,
    /// Hidden layer widths.
    pub hidden: Vec<usize>,
    /// Hidden activation.
    pub activation: Activation,
    /// Size of the latent ẑ.
    pub latent: usize,
}

impl Default for EncoderConfig {
    fn default() -> Self {
        EncoderConfig {
            inputs: ["obj_mass", "obj_friction", "obj_scale", "obj_pos", "obj_rot", "obj_vel", "obj_angvel", "tip_contact"].iter().map(|s| s.to_string()).collect(),
            hidden: vec![128, 64],
            activation: Activation::Relu,
            latent: 16,
        }
    }
}

impl Default for TrainConfig {
    fn default() -> Self {
        TrainConfig {
            device: BackendChoice::Cpu,
            iterations: 100,
            steps_per_env: 32,
            save_interval: 50,
            keep_checkpoints: 0,
            plot_interval: 50,
            init_at_random_ep_len: true,
        }
    }
}

impl Default for PpoConfig {
    fn default() -> Self {
        PpoConfig {
            learning_rate: 5e-4,
            schedule: LrSchedule::Adaptive,
            desired_kl: 0.01,
            min_learning_rate: 1e-5,
            max_learning_rate: 1e-2,
            gamma: 0.99,
            lam: 0.95,
            clip_param: 0.2,
            value_loss_coef: 1.0,
            clipped_value_loss: true,
            entropy_coef: 0.005,
            epochs: 5,
            minibatches: 4,
            max_grad_norm: 1.0,
            reward_scale: 1.0,
        }
    }
}

impl Default for PolicyConfig {
    fn default() -> Self {
        PolicyConfig {
            actor_hidden: vec![256, 128, 64],
            critic_hidden: vec![256, 128, 64],
            activation: Activation::Elu,
            init_std: 1.0,
            obs_normalization: true,
            zero_init_output: false,
            encoder: None,
        }
    }
}

impl TrainConfig {
    /// Checks `[train]`.
    pub fn validate(&self, c: &Check) -> Result<()> {
        if self.iterations == 0 {
            return Err(c.err("train.iterations", "0", "an integer >= 1"));
        }
        if !(1..=100_000).contains(&self.steps_per_env) {
            return Err(c.err("train.steps_per_env", self.steps_per_env, "an integer in [1, 100000]"));
        }
        if self.save_interval == 0 {
            return Err(c.err("train.save_interval", "0", "an integer >= 1 (iterations between checkpoints)"));
        }
        Ok(())
    }
}

impl PpoConfig {
    /// Checks `[ppo]`; `batch` = sim.num_envs × train.steps_per_env (the minibatches split it).
    pub fn validate(&self, c: &Check, batch: u64) -> Result<()> {
        c.in_range("ppo.learning_rate", self.learning_rate, 1e-9, 1.0, "a learning rate in (0, 1]")?;
        c.in_range("ppo.min_learning_rate", self.min_learning_rate, 0.0, 1.0, "a learning rate in [0, 1]")?;
        c.in_range("ppo.max_learning_rate", self.max_learning_rate, self.min_learning_rate, 1.0, "a learning rate in [ppo.min_learning_rate, 1]")?;
        c.in_range("ppo.desired_kl", self.desired_kl, 1e-9, 10.0, "a KL divergence in (0, 10]")?;
        c.in_range("ppo.gamma", self.gamma, 0.0, 1.0, "a discount in [0, 1]")?;
        c.in_range("ppo.lam", self.lam, 0.0, 1.0, "a GAE λ in [0, 1]")?;
        c.in_range("ppo.clip_param", self.clip_param, 1e-6, 10.0, "a clip range in (0, 10]")?;
        c.non_neg("ppo.value_loss_coef", self.value_loss_coef)?;
        c.non_neg("ppo.entropy_coef", self.entropy_coef)?;
        c.in_range("ppo.max_grad_norm", self.max_grad_norm, 1e-9, 1e9, "a gradient norm > 0")?;
        c.in_range("ppo.reward_scale", self.reward_scale, 1e-9, 1e9, "a factor > 0")?;
        if !(1..=1000).contains(&self.epochs) {
            return Err(c.err("ppo.epochs", self.epochs, "an integer in [1, 1000]"));
        }
        if self.minibatches == 0 || self.minibatches as u64 > batch {
            return Err(c.err("ppo.minibatches", self.minibatches, &format!("an integer in [1, sim.num_envs × train.steps_per_env = {batch}]")));
        }
        Ok(())
    }
}

impl PolicyConfig {
    /// Checks `[policy]`.
    pub fn validate(&self, c: &Check) -> Result<()> {
        for (key, layers) in [("policy.actor_hidden", &self.actor_hidden), ("policy.critic_hidden", &self.critic_hidden)] {
            if layers.is_empty() || layers.iter().any(|&w| w == 0 || w > 65536) {
                return Err(c.err(key, format!("{layers:?}"), "a non-empty list of layer widths in [1, 65536]"));
            }
        }
        c.in_range("policy.init_std", self.init_std, 1e-6, 100.0, "a standard deviation in (0, 100]")?;
        if let Some(e) = &self.encoder {
            if e.hidden.iter().any(|&w| w == 0 || w > 65536) {
                return Err(c.err("policy.encoder.hidden", format!("{:?}", e.hidden), "a list of layer widths in [1, 65536]"));
            }
            if !(1..=4096).contains(&e.latent) {
                return Err(c.err("policy.encoder.latent", e.latent, "an integer in [1, 4096]"));
            }
            if e.inputs.is_empty() {
                return Err(c.err("policy.encoder.inputs", "[]", "a non-empty list of critic-observation field names"));
            }
        }
        Ok(())
    }
}
