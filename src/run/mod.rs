//! `dextrain train`: the runner and the algorithms' parts of it.
//!
//! - `runner.rs`: the env loop, logging, checkpoint cadence, Ctrl-C and resume, for any algorithm;
//! - `algorithm.rs`: the [`Algorithm`] trait, the seam between the runner and a learner;
//! - `on_policy.rs`: PPO's part (rollouts of `train.steps_per_env` steps, then an update);
//! - `off_policy.rs`: SAC's part (every env step into the replay buffer, gradient steps after each);
//! - `device_loop.rs`: the env loop with the rollouts on the device (envs and learner on one GPU);
//! - `distill.rs`: online DAgger's part (the student and teacher act, then the student learns);
//! - `ranks.rs`: what each rank of an MPI job (`mpiexec -n N`) does differently;
//!
//! Each implements [`Algorithm`]; none copies the loop.

pub mod algorithm;
pub mod device_loop;
pub mod distill;
pub mod off_policy;
pub mod on_policy;
pub mod ranks;
pub mod runner;

use std::path::PathBuf;

use anyhow::Result;

pub use algorithm::{Algorithm, DeviceOutcome, StepOutcome};
pub use runner::TrainArgs;

/// Runs (or resumes) a training run with the config's `train.algorithm`; returns its directory.
/// The config is loaded once (a resumed run's is its config.toml), and this match is where the
/// algorithm is chosen: its constructor and its check before a run directory is made.
pub fn train(args: &TrainArgs) -> Result<PathBuf> {
    let args = &ranks::resume_args(args)?;
    let loaded = runner::load(args)?;
    let args = &ranks::new_run_args(args)?;
    let (make, preflight): (runner::MakeAlgorithm, runner::Preflight) = match loaded.cfg.train.algorithm {
        crate::config::AlgorithmChoice::Ppo => (on_policy::make, runner::no_preflight),
        crate::config::AlgorithmChoice::Sac => (off_policy::make, off_policy::preflight),
        crate::config::AlgorithmChoice::Distill => (distill::make, runner::no_preflight),
    };
    runner::run(args, loaded, make, preflight)
}
