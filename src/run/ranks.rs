//! `mpiexec -n N dextrain train …` (issue 37, `--features mpi`): what each rank of a data-parallel
//! run does differently.
//!
//! Every rank simulates `sim.num_envs` = E envs of its own, the job's envs `[r·E, (r+1)·E)`, and
//! runs the same learner; the learner averages its gradients over the ranks (and the KL, the
//! observation normalisers' and the advantages' statistics: `learn::ppo`, `crate::dist`) and starts
//! from rank 0's parameters, so every rank holds the same policy. Every rank keeps the config's
//! seed: the counter hash keys each env's draws (its randomisation, its observation noise, its
//! action noise) by its global id (`Globals::env_offset`), and the minibatches are cut from one
//! permutation of the job's rows that every rank draws alike (`learn::ppo::minibatch_rows`), so
//! N ranks × E envs compute the update one process with N·E envs computes (to float rounding).
//! rsl_rl instead seeds rank r with `seed + r` and shuffles each rank's rows on its own. Rank 0
//! writes the run directory as a one-process run does; rank r ≥ 1 writes a run directory of its own
//! inside it, `ranks/<r>/` (its config, its metrics and its checkpoints: its envs, RNG positions,
//! normalisers), so that `mpiexec -n N dextrain train --resume RUN` resumes every rank from its own
//! checkpoint. PPO, SAC and distillation run on several ranks alike (`docs/mpi.md`).

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};

use super::runner::TrainArgs;
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

/// The checkpoint this rank resumes from, given its newest valid one `latest` in its run directory
/// `dir`: the newest iteration that every rank holds. A rank killed mid-run ends the job (the
/// launcher stops the others), possibly while another rank had written a checkpoint it had not:
/// the ranks then step back to the iteration they share (every rank checkpoints the same
/// iterations, so the one before is there unless `train.keep_checkpoints` = 1 pruned it). With
/// one rank, `latest`. A collective: every rank of a resumed job calls it.
pub fn common_checkpoint(dir: &Path, latest: PathBuf) -> Result<PathBuf> {
    if dist::size() == 1 {
        return Ok(latest);
    }
    let mine = crate::learn::checkpoint::read_state(&latest)?.iteration;
    let all = dist::gather_f64(mine as f64);
    let common = all.iter().copied().fold(f64::INFINITY, f64::min) as u64;
    if common == mine {
        return Ok(latest);
    }
    let ckpt = crate::learn::checkpoint::find(dir, &common.to_string()).with_context(|| {
        format!("{}: rank {} resumes from iteration {common}, the newest checkpoint every rank holds (its own newest is {mine})", dir.display(), dist::rank())
    })?;
    crate::console::warn(&format!("warning: rank {} resumes from iteration {common}, the newest checkpoint every rank holds (its own newest is {mine})", dist::rank()));
    Ok(ckpt)
}

/// This rank's arguments for a new run (`args`): rank 0's
/// unchanged but for the run name, which every rank takes from rank 0; rank r ≥ 1's its own run
/// directory `ranks/<r>/` of that run. With one rank, `args` as they are.
pub fn new_run_args(args: &TrainArgs) -> Result<TrainArgs> {
    let (rank, size) = (dist::rank(), dist::size());
    let mut out = args.clone();
    if size == 1 {
        return Ok(out);
    }
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
    }
    Ok(out)
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
