//! `[train]`, `[ppo]` and `[policy]`: the learner's device, the run's length and checkpoints, PPO's
//! hyper-parameters (docs/design.md §6, rsl_rl's names and defaults) and the networks.

use anyhow::Result;
use serde::{Deserialize, Serialize};

use super::{BackendChoice, Check};

/// `[train]`
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TrainConfig {
    /// The learning algorithm: `"ppo"` (default, `[ppo]`), `"sac"` (Soft Actor-Critic, `[sac]`) or
    /// `"distill"` (a student distilled from a teacher run by online DAgger, `[distill]`).
    pub algorithm: AlgorithmChoice,
    /// Learner device, chosen like `sim.backend`: `"auto"`, `"cpu"` (burn's flex backend), `"gpu"` or
    /// `"gpu:NAME"` (burn's wgpu backend; on the simulator's own device when the simulator is on the GPU).
    pub device: BackendChoice,
    /// Iterations (each: `steps_per_env` env steps of every env, then PPO's update; SAC takes its
    /// gradient steps after every env step and writes one metrics row per iteration).
    pub iterations: u32,
    /// Env steps per env per iteration (PPO's rollout length).
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
    /// With the envs and the learner on one GPU (`sim.backend` and `train.device` the same wgpu
    /// device), PPO or SAC: keep the rollouts on the device — observations, actions, rewards, PPO's
    /// rollout storage and GAE, SAC's replay buffer and the metrics' sums never cross to the host
    /// during an iteration (docs/gpu.md "The GPU loop"). `false`: observations are read back and
    /// uploaded to the learner every env step (the host path, for comparisons). Ignored elsewhere
    /// (the host path is the only one).
    pub device_rollouts: bool,
}

/// `train.algorithm`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum AlgorithmChoice {
    /// PPO (`[ppo]`, `[policy]`).
    Ppo,
    /// Soft Actor-Critic (`[sac]`, `[policy]`).
    Sac,
    /// Online DAgger from a teacher run (`[distill]`).
    Distill,
}

/// `distill.dataset`: what a distillation update learns from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DatasetMode {
    /// The iteration's rollout only, used for `epochs` and dropped (rsl_rl's `Distillation`).
    Once,
    /// The last `max_rollouts` rollouts together (classic DAgger's aggregation).
    Aggregate,
}

/// `distill.adaptation`: the student's adaptation module φ(x_{t−H+1:t}) → z.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum AdaptationModule {
    /// A GRU over the window, its last hidden state through a linear layer (DexRefine).
    Gru,
    /// A temporal convolution (HORA / RMA): each step embedded by two ReLU layers to
    /// `tcn_channels`, then 1-D convolutions over time (`tcn_layers`, ReLU after each), the result
    /// flattened through a linear layer.
    Tcn,
}

/// `distill.actor`: the student's main actor (copied from the teacher's at the start).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StudentActor {
    /// Trained by the action loss with the adaptation module.
    Finetune,
    /// Kept as the teacher's.
    Frozen,
}

/// `[distill]`: a student that sees only what a robot measures, distilled by online DAgger from a
/// frozen teacher run with a privileged encoder (DexRefine). The student is the teacher's main actor
/// fed by an adaptation module `φ(x_{t−H+1:t}) → z` (a GRU over a window of the history fields,
/// then a linear layer to the latent) instead of the encoder; the teacher labels every state the
/// student visits with its action u and latent ẑ; loss `λ1‖û − u‖² + λ2‖z − ẑ‖²`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DistillConfig {
    /// The teacher's run directory (relative to the config file, or absolute).
    pub teacher: String,
    /// The teacher's checkpoint: `"latest"` or an iteration number.
    pub checkpoint: String,
    /// H: env steps in the history window.
    pub history_len: u32,
    /// x_t: the actor-observation fields each history step holds (proprioception by default).
    pub history_fields: Vec<String>,
    /// The actor-observation fields the student's actor may read (empty: all of them; the actor
    /// observation holds no simulator-only field). The teacher's first-layer weights of the others
    /// are dropped.
    pub student_obs: Vec<String>,
    /// The adaptation module: `"gru"` (default, DexRefine) or `"tcn"` (HORA's temporal convolution).
    pub adaptation: AdaptationModule,
    /// The GRU's hidden size.
    pub gru_hidden: usize,
    /// The TCN's channels (the step embedding's width and every convolution's).
    pub tcn_channels: usize,
    /// The TCN's convolutions over time, in order: `[kernel, stride]` each (HORA's for H = 30:
    /// [[9, 2], [5, 1], [5, 1]], which leave 3 steps of the 30).
    pub tcn_layers: Vec<[u32; 2]>,
    /// λ1: weight of the action loss ‖û − u‖².
    pub lambda_action: f32,
    /// λ2: weight of the latent loss ‖z − ẑ‖².
    pub lambda_latent: f32,
    /// β at the first iteration: the probability that an env's episode is driven by the teacher
    /// (drawn per env at each episode start). Default 1 → 0 over 20 iterations: the new student's
    /// latent is noise, so the teacher first keeps the envs where grasps happen; then β → 0 makes it
    /// DAgger on the student's own states (rsl_rl uses β = 0 throughout).
    pub beta_start: f32,
    /// β after `beta_iterations` (linear in between).
    pub beta_end: f32,
    /// Iterations over which β goes from `beta_start` to `beta_end`.
    pub beta_iterations: u32,
    /// `"once"` (default: each rollout used for `epochs` then dropped) or `"aggregate"`.
    pub dataset: DatasetMode,
    /// Rollouts kept with `dataset = "aggregate"`.
    pub max_rollouts: u32,
    /// `"finetune"` (default) or `"frozen"`.
    pub actor: StudentActor,
    /// Adam's learning rate.
    pub learning_rate: f32,
    /// Passes over the data per update, and minibatches per pass.
    pub epochs: u32,
    pub minibatches: u32,
    /// Global gradient-norm clip.
    pub max_grad_norm: f32,
    /// Every this many iterations (0: never), the student as it is and its teacher each drive the
    /// same `eval_episodes` episodes (eval's seeds: the run's seed + 1000003; the policy means, eval's
    /// rules) and metrics.csv gets both results side by side (`distill/eval_*`; `nan` in the rows
    /// between). The frozen teacher's episodes are run once and reused.
    pub eval_interval: u32,
    /// Episodes of that side-by-side evaluation (one env each).
    pub eval_episodes: u32,
}

impl Default for DistillConfig {
    fn default() -> Self {
        DistillConfig {
            teacher: String::new(),
            checkpoint: "latest".into(),
            history_len: 30,
            history_fields: vec!["q".into(), "prev_action".into()],
            student_obs: Vec::new(),
            adaptation: AdaptationModule::Gru,
            gru_hidden: 64,
            tcn_channels: 32,
            tcn_layers: vec![[9, 2], [5, 1], [5, 1]],
            lambda_action: 0.1,
            lambda_latent: 1.0,
            beta_start: 1.0,
            beta_end: 0.0,
            beta_iterations: 20,
            dataset: DatasetMode::Once,
            max_rollouts: 4,
            actor: StudentActor::Finetune,
            learning_rate: 1e-3,
            epochs: 5,
            minibatches: 4,
            max_grad_norm: 1.0,
            eval_interval: 25,
            eval_episodes: 32,
        }
    }
}

/// The steps left of a `steps`-long window after the convolutions `(kernel, stride)`: T' = ⌊(T − k)
/// / s⌋ + 1 per layer; None when a kernel is longer than its input.
pub fn tcn_steps_out(steps: usize, convs: &[(usize, usize)]) -> Option<usize> {
    convs.iter().try_fold(steps, |t, &(k, s)| (k >= 1 && s >= 1 && k <= t).then(|| (t - k) / s + 1))
}

impl DistillConfig {
    /// The steps the TCN's convolutions leave of the history window (None: a kernel longer than
    /// its input): T' = ⌊(T − k) / s⌋ + 1 per layer.
    pub fn tcn_steps_out(&self) -> Option<usize> {
        tcn_steps_out(self.history_len as usize, &self.tcn_convs())
    }

    /// `tcn_layers` as (kernel, stride) pairs.
    pub fn tcn_convs(&self) -> Vec<(usize, usize)> {
        self.tcn_layers.iter().map(|&[k, s]| (k as usize, s as usize)).collect()
    }

    /// Checks `[distill]`; `batch` = sim.num_envs × train.steps_per_env.
    pub fn validate(&self, c: &Check, batch: u64) -> Result<()> {
        if self.teacher.trim().is_empty() {
            return Err(c.err("distill.teacher", "\"\"", "the teacher's run directory (train.algorithm = \"distill\" needs one)"));
        }
        if self.checkpoint != "latest" && self.checkpoint.parse::<u64>().is_err() {
            return Err(c.err("distill.checkpoint", &self.checkpoint, "\"latest\" or an iteration number"));
        }
        if !(1..=1000).contains(&self.history_len) {
            return Err(c.err("distill.history_len", self.history_len, "an integer in [1, 1000]"));
        }
        if self.history_fields.is_empty() {
            return Err(c.err("distill.history_fields", "[]", "a non-empty list of actor-observation field names"));
        }
        if !(1..=4096).contains(&self.gru_hidden) {
            return Err(c.err("distill.gru_hidden", self.gru_hidden, "an integer in [1, 4096]"));
        }
        if self.adaptation == AdaptationModule::Tcn {
            if !(1..=4096).contains(&self.tcn_channels) {
                return Err(c.err("distill.tcn_channels", self.tcn_channels, "an integer in [1, 4096]"));
            }
            let shown = format!("{:?}", self.tcn_layers);
            if self.tcn_layers.is_empty() || self.tcn_layers.iter().any(|&[k, s]| k == 0 || s == 0) {
                return Err(c.err("distill.tcn_layers", &shown, "a non-empty list of [kernel, stride] pairs, each >= 1"));
            }
            if self.tcn_steps_out().is_none() {
                return Err(c.err("distill.tcn_layers", &shown, &format!("convolutions that fit in distill.history_len = {} steps (each kernel at most the steps left by the layers before it)", self.history_len)));
            }
        }
        c.non_neg("distill.lambda_action", self.lambda_action)?;
        c.non_neg("distill.lambda_latent", self.lambda_latent)?;
        c.in_range("distill.beta_start", self.beta_start, 0.0, 1.0, "a probability in [0, 1]")?;
        c.in_range("distill.beta_end", self.beta_end, 0.0, 1.0, "a probability in [0, 1]")?;
        if self.max_rollouts == 0 {
            return Err(c.err("distill.max_rollouts", 0, "an integer >= 1"));
        }
        c.in_range("distill.learning_rate", self.learning_rate, 1e-9, 1.0, "a learning rate in (0, 1]")?;
        c.in_range("distill.max_grad_norm", self.max_grad_norm, 1e-9, 1e9, "a gradient norm > 0")?;
        if !(1..=1000).contains(&self.epochs) {
            return Err(c.err("distill.epochs", self.epochs, "an integer in [1, 1000]"));
        }
        if self.minibatches == 0 || self.minibatches as u64 > batch {
            return Err(c.err("distill.minibatches", self.minibatches, &format!("an integer in [1, sim.num_envs × train.steps_per_env = {batch}]")));
        }
        if !(1..=65536).contains(&self.eval_episodes) {
            return Err(c.err("distill.eval_episodes", self.eval_episodes, "an integer in [1, 65536]"));
        }
        Ok(())
    }
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

/// `[ppo]` (docs/design.md §6; rsl_rl's names and defaults)
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
    /// object physics `obj_mass`, `obj_friction`, `obj_restitution`, `obj_scale`, the object's
    /// `obj_pos`, `obj_rot`, `obj_vel`, `obj_angvel`, contacts `link_contact` (per hand link) or
    /// `tip_contact` / `tip_force` (per fingertip), `added_gravity`. Default: DexRefine's set,
    /// every one of those but the fingertip contacts.
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
            inputs: ["obj_mass", "obj_friction", "obj_restitution", "obj_scale", "obj_pos", "obj_rot", "obj_vel", "obj_angvel", "link_contact", "added_gravity"].iter().map(|s| s.to_string()).collect(),
            hidden: vec![128, 64],
            activation: Activation::Relu,
            latent: 16,
        }
    }
}

impl Default for TrainConfig {
    fn default() -> Self {
        TrainConfig {
            algorithm: AlgorithmChoice::Ppo,
            device: BackendChoice::Cpu,
            iterations: 100,
            steps_per_env: 32,
            save_interval: 50,
            keep_checkpoints: 0,
            plot_interval: 50,
            init_at_random_ep_len: true,
            device_rollouts: true,
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
