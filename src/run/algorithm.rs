//! The seam between the runner and a learning algorithm.
//!
//! The runner ([`super::runner`]) owns the env loop, the metrics, checkpoints, Ctrl-C and resume; an
//! [`Algorithm`] owns the networks and how they learn. Per iteration the runner calls, for each of
//! [`Algorithm::steps_per_iteration`] env steps, [`Algorithm::act`] then (after stepping the envs)
//! [`Algorithm::observe`]; then [`Algorithm::update`] once, whose values become the metrics row's
//! learner columns. This fits the three learners `learn/` is built for:
//! - on-policy (PPO, `on_policy.rs`): `observe` stores the transition in the rollout, `update` runs
//!   GAE and the epochs;
//! - off-policy (SAC, `off_policy.rs`): `observe` pushes into the replay buffer and takes the
//!   gradient steps of that env step (its stats accumulate), `update` only reports them;
//! - distillation (DAgger): `act` runs the student (the teacher labels the same observations),
//!   `observe` stores the labels, `update` fits the student.

use anyhow::{Result, bail};
use burn::prelude::Tensor;

use crate::gpu::context::GpuContext;
use crate::learn::state::LearnerState;

/// What one env step of all N envs gave, for the step that the last [`Algorithm::act`] started.
pub struct StepOutcome<'a> {
    /// The task's rewards [N] (unscaled).
    pub reward: &'a [f32],
    /// Envs whose episode ended by a termination [N] (no bootstrap through it).
    pub terminated: &'a [bool],
    /// Envs whose episode ended by a time-out [N] (bootstrap through it).
    pub time_out: &'a [bool],
    /// Raw actor observations after the step [N, O] (a done env's are its new episode's first).
    pub obs: &'a [f32],
    /// Raw critic observations after the step [N, P].
    pub priv_obs: &'a [f32],
    /// Envs whose episode ended with success [N].
    pub success: &'a [bool],
    /// Raw actor / critic observations of the state each ended episode ended in ([N, O] / [N, P];
    /// rows of envs that did not end are stale). Filled only for an algorithm whose
    /// [`Algorithm::wants_final_observations`] is true.
    pub final_obs: &'a [f32],
    pub final_priv_obs: &'a [f32],
}

/// What one env step of all N envs gave, left on the device (device-resident rollouts): `[N, 1]`
/// columns (flags 0 or 1) and the observations after the step.
pub struct DeviceOutcome<'a> {
    /// The task's rewards (unscaled).
    pub reward: &'a Tensor<2>,
    /// 1 where the episode ended by a termination.
    pub terminated: &'a Tensor<2>,
    /// 1 where it ended by a time-out.
    pub time_out: &'a Tensor<2>,
    /// Raw actor / critic observations after the step `[N, O]` / `[N, P]`.
    pub obs: &'a Tensor<2>,
    pub priv_obs: &'a Tensor<2>,
    /// With [`Algorithm::wants_final_observations`]: the observations each ended episode ended in
    /// (`[N, O]` / `[N, P]`; rows of the other envs are stale).
    pub final_obs: Option<&'a Tensor<2>>,
    pub final_priv_obs: Option<&'a Tensor<2>>,
}

/// A learning algorithm that the runner drives.
pub trait Algorithm {
    /// Short name for the run's banner, e.g. "ppo".
    fn name(&self) -> &str;

    /// Env steps of every env per iteration (one `update` and one metrics row each).
    fn steps_per_iteration(&self) -> usize;

    /// Whether `observe` needs the final observations of ended episodes (an off-policy learner
    /// bootstraps a time-out from them); the runner then asks the task for them.
    fn wants_final_observations(&self) -> bool {
        false
    }

    /// Seconds spent learning inside `act`/`observe` since the last call (SAC's gradient steps);
    /// the runner counts them in `time/learn_s` instead of `time/collect_s`.
    fn take_learn_seconds(&mut self) -> f64 {
        0.0
    }

    /// The names of the values `update` returns, in order: metrics.csv columns after the env's.
    fn stat_columns(&self) -> Vec<String>;

    /// Training actions [N, A] for raw observations `obs` [N, O] and `priv_obs` [N, P].
    fn act(&mut self, obs: &[f32], priv_obs: &[f32]) -> Result<Vec<f32>>;

    /// The outcome of the step that the last `act` started.
    fn observe(&mut self, step: &StepOutcome<'_>) -> Result<()>;

    /// The iteration's end (`obs`/`priv_obs`: the current observations); returns one value per
    /// [`Algorithm::stat_columns`] entry.
    fn update(&mut self, obs: &[f32], priv_obs: &[f32]) -> Result<Vec<f64>>;

    /// Whether the algorithm can keep its rollouts on the device ([`Algorithm::act_device`] and the
    /// two after it); the runner then uses them when the envs and the learner share a GPU.
    fn can_run_on_device(&self) -> bool {
        false
    }

    /// Switches to device-resident rollouts on the simulator's wgpu context `ctx` (between
    /// iterations).
    fn start_device_rollouts(&mut self, _ctx: &GpuContext) -> Result<()> {
        bail!("{} has no device-resident rollouts", self.name())
    }

    /// As [`Algorithm::act`] with the observations on the device; the actions stay there.
    fn act_device(&mut self, _obs: &Tensor<2>, _priv_obs: &Tensor<2>) -> Result<Tensor<2>> {
        bail!("{} has no device-resident rollouts", self.name())
    }

    /// As [`Algorithm::observe`] on the device.
    fn observe_device(&mut self, _step: &DeviceOutcome<'_>) -> Result<()> {
        bail!("{} has no device-resident rollouts", self.name())
    }

    /// As [`Algorithm::update`] with the current observations on the device.
    fn update_device(&mut self, _obs: &Tensor<2>, _priv_obs: &Tensor<2>) -> Result<Vec<f64>> {
        bail!("{} has no device-resident rollouts", self.name())
    }

    /// The largest difference of any parameter (or normaliser statistic) from rank 0's over the
    /// ranks of an MPI job (a collective: every rank calls it; 0 with one rank).
    fn max_rank_deviation(&self) -> Result<f32> {
        Ok(0.0)
    }

    /// Everything that a resumed run needs to continue exactly (taken between iterations).
    fn state(&self) -> Result<LearnerState>;

    /// Restores what [`Algorithm::state`] gave.
    fn load_state(&mut self, state: &LearnerState) -> Result<()>;
}
