//! PPO's part of the runner (rsl_rl's `OnPolicyRunner`): collect `train.steps_per_env` env steps of
//! every env into the rollout storage, then update. The loop itself is `runner.rs`.

use anyhow::Result;
use burn::prelude::Tensor;

use super::algorithm::{Algorithm, DeviceOutcome, StepOutcome};
use crate::gpu::context::GpuContext;
use super::runner::RunContext;
use crate::learn::ppo::{Dims, Ppo, UpdateStats};
use crate::learn::state::LearnerState;
use crate::metrics::columns;

/// The metrics columns of a PPO update, in [`stat_values`] order.
pub const STAT_COLUMNS: [&str; 7] = ["loss/surrogate", "loss/value", columns::LOSS_ENTROPY, columns::KL, columns::LR, columns::GRAD_NORM, columns::POLICY_STD];

/// An update's stats in [`STAT_COLUMNS`] order.
pub fn stat_values(u: &UpdateStats) -> Vec<f64> {
    vec![u.surrogate, u.value, u.entropy, u.kl, u.lr, u.grad_norm, u.mean_std]
}

/// PPO for the run described by `ctx`.
pub fn make(ctx: &RunContext) -> Result<Box<dyn Algorithm>> {
    let dims = Dims { obs: ctx.dims[0], priv_obs: ctx.dims[1], act: ctx.dims[2] };
    let steps = ctx.cfg.train.steps_per_env as usize;
    let ppo = Ppo::new(dims, ctx.num_envs, steps, &ctx.cfg.ppo, &ctx.cfg.policy, &ctx.encoder_index, ctx.device.clone(), ctx.cfg.seed as u64)?;
    Ok(Box::new(ppo))
}

impl Algorithm for Ppo {
    fn name(&self) -> &str {
        "ppo"
    }

    fn steps_per_iteration(&self) -> usize {
        self.storage.steps
    }

    fn stat_columns(&self) -> Vec<String> {
        STAT_COLUMNS.iter().map(|s| s.to_string()).collect()
    }

    fn max_rank_deviation(&self) -> Result<f32> {
        // the parameters, and the normalisers' statistics (merged from every rank's observations):
        // the policy file, as SAC's
        let mut state = LearnerState::default();
        self.save_policy(&mut state)?;
        Ok(crate::dist::max_deviation_from_root(&state.flat_values()))
    }

    fn act(&mut self, obs: &[f32], priv_obs: &[f32]) -> Result<Vec<f32>> {
        Ppo::act(self, obs, priv_obs)
    }

    fn observe(&mut self, step: &StepOutcome<'_>) -> Result<()> {
        self.process_step(step.reward, step.terminated, step.time_out);
        Ok(())
    }

    fn update(&mut self, _obs: &[f32], priv_obs: &[f32]) -> Result<Vec<f64>> {
        // GAE bootstraps from the critic's value of the observation after the last step
        Ok(stat_values(&Ppo::update(self, priv_obs)?))
    }

    fn can_run_on_device(&self) -> bool {
        true
    }

    fn start_device_rollouts(&mut self, ctx: &GpuContext) -> Result<()> {
        Ppo::start_device_rollouts(self, ctx)
    }

    fn act_device(&mut self, obs: &Tensor<2>, priv_obs: &Tensor<2>) -> Result<Tensor<2>> {
        Ppo::act_device(self, obs, priv_obs)
    }

    fn observe_device(&mut self, step: &DeviceOutcome<'_>) -> Result<()> {
        self.process_step_device(step.reward, step.terminated, step.time_out)
    }

    fn update_device(&mut self, _obs: &Tensor<2>, priv_obs: &Tensor<2>) -> Result<Vec<f64>> {
        Ok(stat_values(&Ppo::update_device(self, priv_obs)?))
    }

    fn state(&self) -> Result<LearnerState> {
        Ppo::state(self)
    }

    fn load_state(&mut self, state: &LearnerState) -> Result<()> {
        Ppo::load_state(self, state)
    }
}
