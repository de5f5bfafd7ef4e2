//! Online DAgger's part of the runner (`train.algorithm = "distill"`): every env step the teacher
//! labels the states and each episode's driver acts; after `train.steps_per_env` steps the student
//! learns from the labels. The learner is `learn::distill`; the loop is `runner.rs`.
//!
//! Every `distill.eval_interval` iterations the student as it is and its teacher also drive the same
//! `distill.eval_episodes` episodes (eval's seeds and rules, [`crate::eval`]'s episode loop), and the
//! metrics row gets both results side by side (the `distill/eval_*` columns): the training
//! columns `distill/student_*` and `distill/teacher_*` split the training episodes by who drove them,
//! so they compare different episodes, and once β = 0 the teacher drives none.

use anyhow::{Context, Result};

use super::algorithm::{Algorithm, StepOutcome};
use super::runner::RunContext;
use crate::config::Config;
use crate::metrics::columns;
use crate::eval::{Driver, EvalArgs, PolicySource, Summary, run_episodes};
use crate::learn::distill::{Distill, STAT_COLUMNS, StudentPolicy};
use crate::learn::state::LearnerState;

/// The side-by-side evaluation's metrics columns, after [`STAT_COLUMNS`].
pub const EVAL_COLUMNS: [&str; 5] = [
    columns::DISTILL_EVAL_STUDENT_SUCCESS,
    columns::DISTILL_EVAL_TEACHER_SUCCESS,
    "distill/eval_student_return",
    "distill/eval_teacher_return",
    "distill/eval_latent_error",
];

/// The distillation learner of a run, and its side-by-side evaluation.
pub struct DistillRun {
    pub learner: Distill,
    /// The run's config (the evaluation's world).
    cfg: Config,
    /// The frozen teacher's evaluation episodes, run at the first evaluation and reused.
    teacher_eval: Option<Summary>,
}

/// The distillation learner for the run described by `ctx`.
pub fn make(ctx: &RunContext) -> Result<Box<dyn Algorithm>> {
    let learner = Distill::new(&ctx.cfg, &ctx.spec, ctx.num_envs, ctx.device.clone())?;
    Ok(Box::new(DistillRun { learner, cfg: ctx.cfg.clone(), teacher_eval: None }))
}

impl DistillRun {
    /// [`EVAL_COLUMNS`]' values: the student and the teacher on the same episodes. It reads the
    /// learner and draws nothing from its RNG, so training goes on exactly as without it.
    fn side_by_side(&mut self) -> Result<[f64; 5]> {
        let mut c = self.cfg.clone();
        // eval's seeds (`dextrain eval`'s default: the run's seed + 1000003)
        c.seed = c.seed.wrapping_add(1_000_003);
        // (the world's eval batch is smaller than training's: the learners' minibatch counts, checked
        // against sim.num_envs × train.steps_per_env, play no part in it)
        c.distill.minibatches = 1;
        c.ppo.minibatches = 1;
        let episodes = self.cfg.distill.eval_episodes as usize;
        let args = EvalArgs { run: self.cfg.source.clone(), checkpoint: "latest".into(), episodes, max_envs: episodes, seed: None, record: None, backend: None, baseline: None, video: Default::default(), live: Default::default() };
        let student = StudentPolicy::of_learner(&self.learner);
        let source = PolicySource::Distilling { student: &student, teacher: &self.learner.teacher.ppo };
        if self.teacher_eval.is_none() {
            self.teacher_eval = Some(run_episodes(&c, source, &args, Driver::Teacher).context("the side-by-side evaluation (distill.eval_interval): the teacher's episodes")?.0);
        }
        let (s, _, _) = run_episodes(&c, source, &args, Driver::Policy).context("the side-by-side evaluation (distill.eval_interval): the student's episodes")?;
        let t = self.teacher_eval.as_ref().context("no teacher evaluation")?;
        let latent = s.latent_error.as_ref().map(|m| m.mean).unwrap_or(f64::NAN);
        Ok([s.success_rate, t.success_rate, s.episode_return.mean, t.episode_return.mean, latent])
    }
}

impl Algorithm for DistillRun {
    fn name(&self) -> &str {
        "distill (online DAgger)"
    }

    fn steps_per_iteration(&self) -> usize {
        self.learner.steps
    }

    fn stat_columns(&self) -> Vec<String> {
        STAT_COLUMNS.iter().chain(&EVAL_COLUMNS).map(|s| s.to_string()).collect()
    }

    fn act(&mut self, obs: &[f32], priv_obs: &[f32]) -> Result<Vec<f32>> {
        self.learner.act(obs, priv_obs)
    }

    fn observe(&mut self, step: &StepOutcome<'_>) -> Result<()> {
        self.learner.observe(step.reward, step.terminated, step.time_out, step.success);
        Ok(())
    }

    fn update(&mut self, _obs: &[f32], _priv_obs: &[f32]) -> Result<Vec<f64>> {
        let mut stats = self.learner.update()?;
        let every = self.cfg.distill.eval_interval as u64;
        // after the update: the student that the iteration's checkpoint holds
        let eval = if every > 0 && self.learner.iteration % every == 0 { self.side_by_side()? } else { [f64::NAN; 5] };
        stats.extend(eval);
        Ok(stats)
    }

    fn state(&self) -> Result<LearnerState> {
        self.learner.state()
    }

    fn max_rank_deviation(&self) -> Result<f32> {
        Ok(crate::dist::max_deviation_from_root(&self.learner.student_values()?))
    }

    fn load_state(&mut self, state: &LearnerState) -> Result<()> {
        self.learner.load_state(state)
    }
}
