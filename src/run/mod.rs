//! `dextrain train`: the runner and the algorithms' parts of it.
//!
//! - `runner.rs`: the env loop, logging, checkpoint cadence, Ctrl-C and resume, for any algorithm;
//! - `algorithm.rs`: the [`Algorithm`] trait, the seam between the runner and a learner;
//! - `on_policy.rs`: PPO's part (rollouts of `train.steps_per_env` steps, then an update);
//! - `off_policy.rs`: SAC's part (every env step into the replay buffer, gradient steps after each);
//! - `device_loop.rs`: the env loop with the rollouts on the device (envs and learner on one GPU);
//! - `distill.rs`: online DAgger's part (the student and teacher act, then the student learns);
//!
//! Each implements [`Algorithm`]; none copies the loop.

pub mod algorithm;
mod device_loop;
pub mod distill;
pub mod off_policy;
pub mod on_policy;
pub mod runner;

use std::path::PathBuf;

use anyhow::Result;

pub use algorithm::{Algorithm, DeviceOutcome, StepOutcome};
pub use runner::TrainArgs;

/// Runs (or resumes) a training run with the config's `train.algorithm`; returns its directory.
pub fn train(args: &TrainArgs) -> Result<PathBuf> {
    // the algorithm is the config's (a resumed run's is in its config.toml)
    let cfg = match (&args.resume, &args.config) {
        (Some(dir), _) => crate::config::Config::load(&dir.join("config.toml"))?,
        (None, Some(path)) => crate::config::Config::load_with_overrides(path, &args.sets)?,
        (None, None) => anyhow::bail!("a config file or --resume is needed"),
    };
    match cfg.train.algorithm {
        crate::config::AlgorithmChoice::Ppo => runner::run(args, on_policy::make),
        crate::config::AlgorithmChoice::Sac => runner::run(args, off_policy::make),
        crate::config::AlgorithmChoice::Distill => runner::run(args, distill::make),
    }
}
