//! `mpiexec -n N dextrain train …` (issue 37, `--features mpi`): what each rank of a data-parallel
//! run does differently.
//!
//! Every rank simulates `sim.num_envs` envs of its own and runs the same learner; the learner
//! averages its gradients over the ranks (and the KL, the observation normalisers' and the
//! advantages' statistics: `learn::ppo`, `crate::dist`) and starts from rank 0's parameters, so every
//! rank holds the same policy. Rank r draws its envs and its action noise from the seed `seed + r`
//! (rsl_rl seeds its ranks the same way). Rank 0 writes the run directory as a one-process run
//! does; rank r ≥ 1 writes a run directory of its own inside it, `ranks/<r>/` (its config with its
//! seed, its metrics and its checkpoints: its envs, RNG positions, normalisers), so that
//! `mpiexec -n N dextrain train --resume RUN` resumes every rank from its own checkpoint. Only PPO
//! runs on several ranks so far.

use std::path::Path;

use anyhow::{Result, bail};

use super::runner::{LoadedRun, TrainArgs};
use crate::config::{AlgorithmChoice, Config};
use crate::dist;

/// The folder of a run directory that holds ranks 1… of a data-parallel run.
pub const RANKS_DIR: &str = "ranks";

/// This rank's arguments for resuming the run `args.resume` (the arguments as they are for a new
/// run): rank 0 resumes the run directory, rank r ≥ 1 its own `ranks/<r>/` in it; the number of
/// ranks must be the one the run was trained with.
pub fn resume_args(args: &TrainArgs) -> Result<TrainArgs> {
    let mut out = args.clone();
    if let Some(dir) = &args.resume {
        check_world_size(dir, dist::size())?;
        if dist::rank() > 0 {
            out.resume = Some(dir.join(RANKS_DIR).join(dist::rank().to_string()));
            out.quiet = true;
        }
    }
    Ok(out)
}

/// This rank's arguments and config for a new run (`args`, with `loaded` from them): rank 0's
/// unchanged but for the run name, which every rank takes from rank 0; rank r ≥ 1's its own run
/// directory `ranks/<r>/` of that run, and the seed `seed + r`. With one rank, `args` as they are.
pub fn new_run_args(args: &TrainArgs, loaded: &mut LoadedRun) -> Result<TrainArgs> {
    let (rank, size) = (dist::rank(), dist::size());
    let mut out = args.clone();
    if size == 1 {
        return Ok(out);
    }
    check_algorithm(&loaded.cfg)?;
    if args.resume.is_some() {
        return Ok(out);
    }
    let path = args.config.as_deref().unwrap_or(Path::new("run"));
    let name = dist::broadcast_string(&args.name.clone().unwrap_or_else(|| crate::run_dir::default_name(path)));
    if rank == 0 {
        out.name = Some(name);
    } else {
        out.runs_dir = args.runs_dir.join(&name).join(RANKS_DIR);
        out.name = Some(rank.to_string());
        // rank 0 replaced an old run of that name already (and its ranks/ with it)
        out.force = true;
        out.quiet = true;
        loaded.cfg.seed += rank as u32;
    }
    Ok(out)
}

/// Only PPO averages its gradients over ranks so far.
fn check_algorithm(cfg: &Config) -> Result<()> {
    if cfg.train.algorithm != AlgorithmChoice::Ppo {
        let name = format!("{:?}", cfg.train.algorithm).to_lowercase();
        bail!("{}: train.algorithm = \"{name}\" runs on one rank only so far; with {} ranks (mpiexec -n {}) expected \"ppo\"", cfg.source.display(), dist::size(), dist::size());
    }
    Ok(())
}

/// A run resumes with the number of ranks it was trained with: its `ranks/` folder holds one
/// run directory per rank after the first.
fn check_world_size(dir: &Path, size: usize) -> Result<()> {
    let ranks = dir.join(RANKS_DIR);
    let trained = 1 + match std::fs::read_dir(&ranks) {
        Ok(rd) => rd.filter_map(|e| e.ok()).filter(|e| e.path().join("config.toml").is_file()).count(),
        Err(_) => 0,
    };
    if trained != size {
        bail!("{}: the run was trained with {trained} rank(s) and is resumed with {size}; expected `mpiexec -n {trained} dextrain train --resume {}`", dir.display(), dir.display());
    }
    Ok(())
}
