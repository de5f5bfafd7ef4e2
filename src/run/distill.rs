//! Online DAgger's part of the runner (`train.algorithm = "distill"`): every env step the teacher
//! labels the states and each episode's driver acts; after `train.steps_per_env` steps the student
//! learns from the labels. The learner is `learn::distill`; the loop is `runner.rs`.

use anyhow::Result;

use super::algorithm::{Algorithm, StepOutcome};
use super::runner::RunContext;
use crate::learn::distill::{Distill, STAT_COLUMNS};
use crate::learn::state::LearnerState;

/// The distillation learner for the run described by `ctx`.
pub fn make(ctx: &RunContext) -> Result<Box<dyn Algorithm>> {
    Ok(Box::new(Distill::new(&ctx.cfg, &ctx.spec, ctx.num_envs, ctx.device.clone())?))
}

impl Algorithm for Distill {
    fn name(&self) -> &str {
        "distill (online DAgger)"
    }

    fn steps_per_iteration(&self) -> usize {
        self.steps
    }

    fn stat_columns(&self) -> Vec<String> {
        STAT_COLUMNS.iter().map(|s| s.to_string()).collect()
    }

    fn act(&mut self, obs: &[f32], priv_obs: &[f32]) -> Result<Vec<f32>> {
        Distill::act(self, obs, priv_obs)
    }

    fn observe(&mut self, step: &StepOutcome<'_>) -> Result<()> {
        Distill::observe(self, step.reward, step.terminated, step.time_out, step.success);
        Ok(())
    }

    fn update(&mut self, _obs: &[f32], _priv_obs: &[f32]) -> Result<Vec<f64>> {
        Distill::update(self)
    }

    fn state(&self) -> Result<LearnerState> {
        Distill::state(self)
    }

    fn load_state(&mut self, state: &LearnerState) -> Result<()> {
        Distill::load_state(self, state)
    }
}
