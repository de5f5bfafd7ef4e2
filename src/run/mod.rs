//! `dextrain train`: the runner and the algorithms' parts of it.
//!
//! - `runner.rs`: the env loop, logging, checkpoint cadence, Ctrl-C and resume, for any algorithm;
//! - `algorithm.rs`: the [`Algorithm`] trait, the seam between the runner and a learner;
//! - `on_policy.rs`: PPO's part (rollouts of `train.steps_per_env` steps, then an update);
//!
//! An off-policy runner (SAC) and a distillation runner go beside `on_policy.rs`, implementing
//! [`Algorithm`]; none copies the loop.

pub mod algorithm;
pub mod on_policy;
pub mod runner;

use std::path::PathBuf;

use anyhow::Result;

pub use algorithm::{Algorithm, StepOutcome};
pub use runner::TrainArgs;

/// Runs (or resumes) a training run (PPO, the only algorithm so far); returns its directory.
pub fn train(args: &TrainArgs) -> Result<PathBuf> {
    runner::run(args, on_policy::make)
}
