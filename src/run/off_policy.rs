//! SAC's part of the runner (an off-policy runner in the FastTD3 shape): every env step of all envs
//! pushes one transition per env into the replay buffer and takes `sac.updates_per_step` gradient
//! steps; an iteration is `train.steps_per_env` env steps and writes one metrics row with the
//! means of its gradient steps. The loop itself is `runner.rs` (`device_loop.rs` when the envs and
//! the learner share a GPU: the replay buffer then lives on the device).

use anyhow::Result;
use burn::prelude::Tensor;

use super::algorithm::{Algorithm, DeviceOutcome, StepOutcome};
use crate::gpu::context::GpuContext;
use super::runner::RunContext;
use crate::console;
use crate::learn::ppo::Dims;
use crate::learn::sac::{Sac, SacStats};
use crate::learn::state::LearnerState;
use crate::metrics::columns;

/// The metrics columns of SAC's iterations, in [`stat_values`] order.
pub const STAT_COLUMNS: [&str; 7] = ["loss/critic", "loss/actor", "alpha", columns::POLICY_ENTROPY, "q/mean", "updates", "buffer/transitions"];

/// An iteration's stats in [`STAT_COLUMNS`] order.
pub fn stat_values(s: &SacStats) -> Vec<f64> {
    vec![s.critic_loss, s.actor_loss, s.alpha, s.entropy, s.q_mean, s.updates as f64, s.buffer_transitions as f64]
}

/// SAC's check before a run directory is made ([`super::runner::Preflight`]): that its replay
/// buffer fits ([`check_buffer`]).
pub fn preflight(cfg: &crate::config::Config, spec: &crate::task::TaskSpec) -> Result<()> {
    check_buffer(cfg, spec).map(|_| ())
}

/// The replay buffer's size for the run's config and task: (bytes per transition, total bytes).
/// A buffer larger than the memory available, or a critic observation that does not begin with
/// the actor's when `sac.store_actor_obs = false`, is a one-line error naming the key.
pub fn check_buffer(cfg: &crate::config::Config, spec: &crate::task::TaskSpec) -> Result<(u64, u64)> {
    let sac = &cfg.sac;
    let file = cfg.source.display();
    if !sac.store_actor_obs {
        // the actor then reads the head of the critic observation: it must be the actor's fields
        let head: Vec<&str> = spec.priv_layout.iter().map(|s| s.name.as_str()).take(spec.obs_layout.len()).collect();
        let actor: Vec<&str> = spec.obs_layout.iter().map(|s| s.name.as_str()).collect();
        anyhow::ensure!(head == actor, "{file}: key `sac.store_actor_obs` = false: the {} task's critic observation does not begin with its actor observation; expected true", cfg.task.kind);
    }
    let per = sac.bytes_per_transition(spec.obs_dim, spec.priv_dim, spec.action_dim);
    let total = per * spec.num_envs as u64 * sac.buffer_capacity as u64;
    if let Some(avail) = available_memory() {
        anyhow::ensure!(
            total < avail,
            "{file}: key `sac.buffer_capacity` = {}: the replay buffer needs {per} B per transition × {} envs × {} = {:.2} GiB, but {:.2} GiB of memory are available; expected a smaller sac.buffer_capacity or sim.num_envs, or sac.store_actor_obs = false",
            sac.buffer_capacity,
            spec.num_envs,
            sac.buffer_capacity,
            gib(total),
            gib(avail)
        );
    }
    Ok((per, total))
}

fn gib(b: u64) -> f64 {
    b as f64 / (1u64 << 30) as f64
}

/// SAC for the run described by `ctx` (prints the replay buffer's size; see [`check_buffer`]).
pub fn make(ctx: &RunContext) -> Result<Box<dyn Algorithm>> {
    let dims = Dims { obs: ctx.dims[0], priv_obs: ctx.dims[1], act: ctx.dims[2] };
    let cfg = &ctx.cfg.sac;
    let (per, total) = check_buffer(&ctx.cfg, &ctx.spec)?;
    console::status(&format!(
        "replay buffer: {per} B per transition × {} envs × {} per env = {:.3} GiB (host memory, or device memory when the envs and the learner share a GPU){}",
        ctx.num_envs,
        cfg.buffer_capacity,
        gib(total),
        if cfg.checkpoint_buffer { "" } else { "; not written into checkpoints (sac.checkpoint_buffer = false): a resume is not exact" }
    ));
    let sac = Sac::new(dims, ctx.num_envs, cfg, &ctx.cfg.policy, ctx.device.clone(), ctx.cfg.seed as u64)?;
    Ok(Box::new(OffPolicy { sac, steps: ctx.cfg.train.steps_per_env as usize, learn_seconds: 0.0 }))
}

/// SAC and the iteration length.
pub struct OffPolicy {
    /// The learner.
    pub sac: Sac,
    /// Env steps of every env per iteration (`train.steps_per_env`).
    pub steps: usize,
    /// Seconds in `observe` (the buffer push and the gradient steps) since the runner last asked.
    pub learn_seconds: f64,
}

/// The memory the kernel says is available (`MemAvailable` of /proc/meminfo), in bytes.
fn available_memory() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}

impl Algorithm for OffPolicy {
    fn name(&self) -> &str {
        "sac"
    }

    fn steps_per_iteration(&self) -> usize {
        self.steps
    }

    fn take_learn_seconds(&mut self) -> f64 {
        std::mem::take(&mut self.learn_seconds)
    }

    fn stat_columns(&self) -> Vec<String> {
        STAT_COLUMNS.iter().map(|s| s.to_string()).collect()
    }

    fn wants_final_observations(&self) -> bool {
        true
    }

    fn act(&mut self, obs: &[f32], priv_obs: &[f32]) -> Result<Vec<f32>> {
        self.sac.act(obs, priv_obs)
    }

    fn observe(&mut self, step: &StepOutcome<'_>) -> Result<()> {
        // (the push is part of this time too: it is the learner's bookkeeping)
        let t0 = std::time::Instant::now();
        let r = self.sac.observe(step.reward, step.terminated, step.time_out, step.obs, step.priv_obs, step.final_obs, step.final_priv_obs);
        self.learn_seconds += t0.elapsed().as_secs_f64();
        r
    }

    fn update(&mut self, _obs: &[f32], _priv_obs: &[f32]) -> Result<Vec<f64>> {
        Ok(stat_values(&self.sac.take_stats()?))
    }

    fn max_rank_deviation(&self) -> Result<f32> {
        // the actor, critics, targets, log α and the normalisers' statistics
        let mut state = LearnerState::default();
        self.sac.save_policy(&mut state)?;
        Ok(crate::dist::max_deviation_from_root(&state.flat_values()))
    }

    fn can_run_on_device(&self) -> bool {
        true
    }

    fn start_device_rollouts(&mut self, ctx: &GpuContext) -> Result<()> {
        let bytes = self.sac.start_device_rollouts(ctx)?;
        console::status(&format!("replay buffer: on the device ({:.3} GiB of device memory; the host keeps its counters)", gib(bytes)));
        Ok(())
    }

    fn act_device(&mut self, obs: &Tensor<2>, priv_obs: &Tensor<2>) -> Result<Tensor<2>> {
        self.sac.act_device(obs, priv_obs)
    }

    fn observe_device(&mut self, step: &DeviceOutcome<'_>) -> Result<()> {
        let (Some(fo), Some(fp)) = (step.final_obs, step.final_priv_obs) else {
            anyhow::bail!("SAC's device-resident step needs the final observations");
        };
        let t0 = std::time::Instant::now();
        let r = self.sac.observe_device(step.reward, step.terminated, step.time_out, step.obs, step.priv_obs, fo, fp);
        self.learn_seconds += t0.elapsed().as_secs_f64();
        r
    }

    fn update_device(&mut self, _obs: &Tensor<2>, _priv_obs: &Tensor<2>) -> Result<Vec<f64>> {
        Ok(stat_values(&self.sac.take_stats()?))
    }

    fn state(&self) -> Result<LearnerState> {
        self.sac.state()
    }

    fn load_state(&mut self, state: &LearnerState) -> Result<()> {
        if !self.sac.load_state(state)? {
            console::warn("warning: the checkpoint holds no replay buffer (sac.checkpoint_buffer = false): training goes on with an empty buffer, so this resume is not exact");
        }
        Ok(())
    }
}
