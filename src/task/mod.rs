//! The task layer: the lift task and the reference-following kinds (`track`, `residual_joint`,
//! `residual_task`; docs/design.md §5) on top of an [`EnvBatch`], on both backends.
//!
//! The sections below describe the lift task (`task.kind = "lift"`). The reference kinds share the
//! contract and the order of the kernels; their actions, observations, rewards, success and
//! resets are documented on [`residual_targets`], [`task_act`], [`tracking_terms`],
//! [`task_reward`], [`task_init`] and [`observe_reference`], and in docs/tasks.md ("The
//! reference-following tasks"). Their per-env reference cursor lives in [`TaskState::cursor`]
//! (`task::reference`), their bank in bindings 13–15.
//!
//! # The task contract
//!
//! A [`TaskBatch`] turns the env batch into what a learner steps: actions in, observations, rewards
//! and dones out ([`StepBatch`], on the host, row-major `[N, dim]`).
//!
//! - [`TaskBatch::reset_all`] starts episode 0 of every env and returns the first observations
//!   (reward, terms and flags all 0).
//! - [`TaskBatch::step`] takes `[N, action_dim]` actions, clipped to [−1, 1], and runs, per env, in
//!   this order (the GPU dispatches one kernel per line; the CPU runs the twins below with rayon):
//!   1. `task_act`: actions → targets (kept in the env's [`TaskState`] between steps);
//!   2. the physics: one control step toward the targets ([`EnvBatch::step`]);
//!   3. `task_reward`: reward terms, terminations and time-outs on the post-step, pre-reset state;
//!   4. the reset of every done env (its next episode, drawn as [`EnvBatch::reset`] does) — before
//!      it, with [`TaskBatch::set_final_observations`], `task_observe_final` observes the ending
//!      envs' final states;
//!   5. `task_observe`: the task state of every env that was just reset is initialised, then every
//!      env is observed. So `obs` of a done env is the first observation of its next episode
//!      (rsl_rl / Isaac Lab auto-reset).
//!
//! **Actions** (`6 + actuated joints`, names in [`TaskSpec::action_names`]): wrist translation
//! (`wrist_dx/dy/dz`, world): the wrist position target moves by `a · wrist_pos_scale` and is clipped
//! to the box `[wrist_pos_min, wrist_pos_max]`; wrist rotation (`wrist_rx/ry/rz`, a world rotation
//! vector): target ← exp(a · wrist_rot_scale) ⊗ target, then at most `wrist_rot_limit` away from the
//! initial wrist orientation (clamped along the same axis); then one action per actuated joint
//! ([`EnvSpec::actuated`](super::EnvSpec::actuated) order): `absolute`: target = lower + (a + 1)/2 · (upper − lower) (a
//! continuous joint: default + a·π), `delta`: target = clamp(target + a · finger_delta_scale, lower,
//! upper). At a reset the targets are the model's default targets ([`SimModel::default_targets`]).
//!
//! **Reward** (computed after the physics step on the pre-reset state; `terms[k]` = w_k · raw_k in
//! `config::LIFT_TERMS` order, `reward` = Σ_k terms[k]):
//! `reaching` = 1 − tanh(reach_alpha · ‖p_palm − p_obj‖) with p_palm = p_wrist + R_wrist · palm_offset;
//! `lifting` = clamp(h, 0, success_height) · 100 (h = object centre z − its z right after the reset,
//! in cm); `contact` = 1 when the thumb's fingertip force and at least one other fingertip's force
//! exceed `contact_force`; `success` = 1 when h ≥ success_height; `action_rate` = Σ (a_t − a_{t−1})²;
//! `action_magnitude` = Σ a_t² (clipped actions). An env whose state went bad during the physics step
//! was already reset by the physics: its reaching/lifting/contact/success terms, `success` and
//! `lift_height` are 0 for that step.
//!
//! **Dones**: `terminated` = object centre below `drop_height`, |x| or |y| of the object beyond
//! `table_half_extent`, palm farther than `max_hand_distance` from the object, or a bad-state reset
//! by the physics. `time_out` = not terminated and `EnvState::step` ≥ `episode_length`.
//!
//! **Actor observations** (`obs_dim` = 3·J + 26 + 3·T for J actuated joints and T fingertips), in order:
//! `q.<joint>` (J, noise `joint_pos`), `qd.<joint>` (J, noise `joint_vel`), `prev_action.<action>`
//! (the action just applied, 0 after a reset), `wrist_pos.x/y/z` (noise `hand_pos`),
//! `wrist_rot.qx/qy/qz/qw`, `tip_pos.<tip>.x/y/z` (world, from the hand's kinematics; noise
//! `hand_pos`), `obj_pos.x/y/z` (noise `object_pos`), `obj_rot.qx/qy/qz/qw` (noise `object_rot` on
//! each component, then renormalised), `goal.x/y/z` (the rest position raised by `success_height`),
//! `obj_rel.x/y/z` = p_obj − p_palm (the actor's computed from its noisy object and wrist positions).
//! Noise is Gaussian with the configured standard deviation, drawn by Box–Muller from the counter
//! hash (seed, env, episode, [`PURPOSE_OBS_NOISE`], step · 4096 + 2 · entry + {0, 1}), so both
//! backends draw the same numbers.
//!
//! **Critic observations** (`priv_dim` = `obs_dim` + 17 + 2·T + L for L hand links): the clean
//! actor observations, then `obj_vel.x/y/z`, `obj_angvel.x/y/z`, `wrist_vel.x/y/z`,
//! `wrist_angvel.x/y/z`, `tip_contact.<tip>` (1 when its force > contact_force), `tip_force.<tip>`
//! (N, the step's average), `link_contact.<link>` (1 when a collider of the link pushed on the
//! object in a substep: `StepStats::link_contact`), `obj_mass`, `obj_friction`, `obj_scale`,
//! `obj_restitution`, `added_gravity` (the env's drawn parameters).
//!
//! # Where things are
//!
//! - [`spec`]: THE observation spec and the reward-term tables; [`TaskSpec`] (names, sizes, layouts).
//! - [`setup`]: the config and the hand → [`TaskSetup`] (spec, constants, references), both backends.
//! - [`task`](self::task): the CPU twin of `shaders/task.wgsl` (same names, same order, same
//!   arithmetic; tests/suite/shaders.rs checks the order, tests/suite/task.rs the results).
//! - [`cpu`] and [`gpu`]: the two [`TaskBatch`] backends.

pub mod bank;
pub mod cpu;
pub mod gpu;
pub mod ik;
pub mod layout;
pub mod reference;
pub mod setup;
pub mod shaders;
pub mod spec;
#[allow(clippy::module_inception)]
pub mod task;

use anyhow::{Result, bail, ensure};

use crate::config::Config;
use crate::gpu::layout::{EnvParams, EnvState, Targets};
use layout::TaskState;
use crate::task::reference::RefFrame;
use crate::env::{EnvBatch, SimModel};

pub use cpu::CpuTaskBatch;
pub use gpu::GpuTaskBatch;
pub use setup::{TaskSetup, ref_model, reference_paths, task_setup};
pub use spec::TaskSpec;
use task::*;

/// Everything the learner needs from one control step, on the host. Row-major `[N, dim]` arrays.
#[derive(Clone, Debug, Default)]
pub struct StepBatch {
    /// `[N, obs_dim]` actor obs (with noise) of the state after the step and after any reset.
    pub obs: Vec<f32>,
    /// `[N, priv_dim]` critic obs, same instant, no noise.
    pub priv_obs: Vec<f32>,
    /// `[N]` Σ_k w_k · term_k of this step (on the pre-reset state).
    pub reward: Vec<f32>,
    /// `[N, n_terms]` the weighted terms w_k · term_k (their sum is `reward`).
    pub terms: Vec<f32>,
    /// `[N]` object dropped or off the table, hand too far, or a bad-state reset by the physics.
    pub terminated: Vec<bool>,
    /// `[N]` the episode reached `episode_length` env steps (and did not terminate).
    pub time_out: Vec<bool>,
    /// `[N]` object centre ≥ `success_height` above its rest height at this step (pre-reset).
    pub success: Vec<bool>,
    /// `[N]` object centre height above its rest height at this step (m, pre-reset).
    pub lift_height: Vec<f32>,
    /// `[N]` deepest hand–object penetration during this step (m).
    pub max_pen: Vec<f32>,
    /// `[N]` the object's distance (m) and angle (rad) from its reference at this step (pre-reset;
    /// 0 for the lift task).
    pub obj_pos_err: Vec<f32>,
    pub obj_rot_err: Vec<f32>,
    /// `[N]` the physics reset this env during the step because its state went bad (non-finite, or
    /// a speed or distance beyond `sim.max_speed` / `sim.max_distance`); `terminated` is set too.
    pub bad_reset: Vec<bool>,
    /// `[N, obs_dim]` / `[N, priv_dim]`, only after [`TaskBatch::set_final_observations`]`(true)`:
    /// for an env whose episode ended in this step by a time-out or a termination, the
    /// observations of the state it ended in (before its reset; `obs` holds its next episode's
    /// first); rows of other envs, and of envs reset for a bad state, are left as they were. An
    /// off-policy learner bootstraps a time-out's value from these.
    pub final_obs: Vec<f32>,
    pub final_priv_obs: Vec<f32>,
    /// Reward terms per env (the kind's).
    pub n_terms: usize,
}

impl StepBatch {
    /// A zeroed batch for `spec`.
    pub fn new(spec: &TaskSpec) -> StepBatch {
        let n = spec.num_envs;
        StepBatch {
            obs: vec![0.0; n * spec.obs_dim],
            priv_obs: vec![0.0; n * spec.priv_dim],
            reward: vec![0.0; n],
            terms: vec![0.0; n * spec.term_names.len()],
            terminated: vec![false; n],
            time_out: vec![false; n],
            success: vec![false; n],
            lift_height: vec![0.0; n],
            max_pen: vec![0.0; n],
            obj_pos_err: vec![0.0; n],
            obj_rot_err: vec![0.0; n],
            bad_reset: vec![false; n],
            final_obs: vec![0.0; n * spec.obs_dim],
            final_priv_obs: vec![0.0; n * spec.priv_dim],
            n_terms: spec.term_names.len(),
        }
    }

    /// Whether env `i`'s episode ended at this step (terminated or timed out).
    pub fn done(&self, i: usize) -> bool {
        self.terminated[i] || self.time_out[i]
    }

    /// Reward, terms and flags from the per-env output records `[N, OUT_MISC]`.
    pub(crate) fn fill_misc(&mut self, misc: &[f32]) {
        for (i, r) in misc.chunks_exact(OUT_MISC).enumerate() {
            self.reward[i] = r[OUT_REWARD];
            let nt = self.n_terms;
            self.terms[i * nt..(i + 1) * nt].copy_from_slice(&r[OUT_TERMS..OUT_TERMS + nt]);
            self.terminated[i] = r[OUT_TERMINATED] != 0.0;
            self.time_out[i] = r[OUT_TIME_OUT] != 0.0;
            self.success[i] = r[OUT_SUCCESS] != 0.0;
            self.lift_height[i] = r[OUT_LIFT];
            self.max_pen[i] = r[OUT_MAX_PEN];
            self.obj_pos_err[i] = r[OUT_OBJ_POS_ERR];
            self.obj_rot_err[i] = r[OUT_OBJ_ROT_ERR];
            self.bad_reset[i] = r[OUT_BAD_RESET] != 0.0;
        }
    }

    /// Reward, terms and flags all 0 (the batch `reset_all` returns).
    pub(crate) fn clear_misc(&mut self) {
        self.reward.fill(0.0);
        self.terms.fill(0.0);
        self.terminated.fill(false);
        self.time_out.fill(false);
        self.success.fill(false);
        self.lift_height.fill(0.0);
        self.max_pen.fill(0.0);
        self.obj_pos_err.fill(0.0);
        self.obj_rot_err.fill(0.0);
        self.bad_reset.fill(false);
    }
}

/// One env step's outputs left on the device ([`TaskBatch::step_on_device`]): tensors of burn's
/// wgpu learner, on the simulator's own device.
pub struct DeviceStep {
    /// `[N, obs_dim]` actor obs, as [`StepBatch::obs`].
    pub obs: burn::prelude::Tensor<2>,
    /// `[N, priv_dim]` critic obs, as [`StepBatch::priv_obs`].
    pub priv_obs: burn::prelude::Tensor<2>,
    /// `[N, OUT_MISC]` the per-env output records: reward, terms and flags at the columns
    /// `task::OUT_*` (what [`StepBatch`] unpacks on the host; flags are 0 or 1).
    pub misc: burn::prelude::Tensor<2>,
    /// With [`TaskBatch::set_final_observations`] on: `[N, obs_dim]` / `[N, priv_dim]`, the
    /// observations of the state each env that ended in this step ended in (rows of the other envs
    /// are stale: select them by the done flags), as [`StepBatch::final_obs`].
    pub final_obs: Option<burn::prelude::Tensor<2>>,
    pub final_priv_obs: Option<burn::prelude::Tensor<2>>,
}

/// The backend-independent task contract (see the module documentation).
pub trait TaskBatch: Send {
    /// Names and sizes.
    fn spec(&self) -> &TaskSpec;
    /// Human-readable backend, as [`EnvBatch::backend_name`].
    fn backend_name(&self) -> String;
    /// The env batch underneath (to read states for recordings; do not step it directly).
    fn env(&mut self) -> &mut dyn EnvBatch;
    /// The wgpu context when the envs run on a GPU (the learner may share the device), else None.
    fn gpu_context(&self) -> Option<&crate::gpu::context::GpuContext>;
    /// Starts episode 0 of every env; returns the first observations (reward/terms 0, no dones).
    fn reset_all(&mut self) -> Result<&StepBatch>;
    /// actions: `[N, action_dim]` (clipped to [−1, 1] inside; must be finite). Maps actions to
    /// targets, steps the physics, computes reward terms / terminations / time-outs on the post-step
    /// state, resets the done envs (next episode), then observes every env.
    fn step(&mut self, actions: &[f32]) -> Result<&StepBatch>;
    /// Bytes of device memory the env batch's and the task's buffers hold; 0 on the CPU.
    fn device_bytes(&self) -> u64 {
        0
    }
    /// Whether [`TaskBatch::step_on_device`] works here (the GPU backend).
    fn can_step_on_device(&self) -> bool {
        false
    }
    /// As [`TaskBatch::step`] without the host: `actions` `[N, action_dim]` is a tensor of burn's
    /// wgpu learner on this task's own wgpu device (`device`), copied into the task's action buffer
    /// on the device; the outputs come back as fresh tensors on `device`, copied there on the
    /// device. No bytes cross to the host. Actions are clipped to [−1, 1] as in `step` but not
    /// checked for finiteness (the caller counts non-finite actions on the device).
    fn step_on_device(&mut self, _actions: &burn::prelude::Tensor<2>, _device: &burn::prelude::Device) -> Result<DeviceStep> {
        bail!("the {} backend cannot step with device-resident tensors (only the GPU backend can)", self.backend_name())
    }
    /// From now on, [`TaskBatch::step`] also observes every env whose episode ends, on the state it
    /// ended in, into [`StepBatch::final_obs`] / [`StepBatch::final_priv_obs`] (between the reward
    /// and the resets: `task_observe_final`); off by default (it costs a dispatch and a larger
    /// readback on the GPU).
    fn set_final_observations(&mut self, on: bool) -> Result<()>;
    /// As [`TaskBatch::step`], but the physics steps toward `targets` (`[N]`) instead of the
    /// targets the task maps the actions to: a controller outside the simulator (`dextrain play`)
    /// applies the action mapping itself. The task still records the actions as `step` does (the
    /// previous action, the action terms, residual_task's smoothed and integrated residual), and
    /// `targets` become the envs' current targets.
    fn step_with_targets(&mut self, actions: &[f32], targets: &[Targets]) -> Result<&StepBatch>;
    /// Reference kinds: every env's (augmented) reference `k` control steps after its current
    /// env step (`k = 1`: the frame the action mapping adds to); `None` for the lift task.
    fn reference_frames(&mut self, k: u32) -> Result<Option<Vec<RefFrame>>>;
    /// The wrist and joint targets of every env's last step (for an env that was just reset: the
    /// default targets its next step starts from).
    fn targets(&mut self) -> Result<Vec<Targets>>;
    /// The first `k` envs' targets (the GPU batch reads only those back).
    fn first_targets(&mut self, k: usize) -> Result<Vec<Targets>> {
        let mut t = self.targets()?;
        t.truncate(k);
        Ok(t)
    }
    /// Reference kinds: env `env`'s (augmented) reference at its current env step (the frame its
    /// tracking error is measured against); `None` for the lift task.
    fn reference_now(&mut self, env: usize) -> Result<Option<RefFrame>>;
    /// Everything that decides the envs' future (env states, parameters, task states), as bytes for
    /// a checkpoint; [`TaskBatch::load_state`] restores it.
    fn save_state(&mut self) -> Result<Vec<u8>>;
    /// Restores what `save_state` returned (same hand and `num_envs`; either backend may load it).
    fn load_state(&mut self, state: &[u8]) -> Result<()>;
}

const SNAPSHOT_MAGIC: &[u8; 8] = b"DXTASK03";
/// Header of a snapshot: the magic, then N, the three struct sizes and the springs per env (u32 LE).
const SNAPSHOT_HEADER: usize = 8 + 5 * 4;

/// The env batch's part of a snapshot: what [`encode_snapshot`] writes next to the task states.
pub(crate) struct EnvSnapshot {
    pub states: Vec<EnvState>,
    /// `[N, springs_per_env]` contact springs.
    pub springs: Vec<[f32; 4]>,
    pub params: Vec<EnvParams>,
}

/// Serialises a task batch's state: the header (magic, N, the struct sizes, the contact springs
/// per env), then the env states, contact springs, parameters and task states as their Pod bytes.
pub(crate) fn encode_snapshot(states: &[EnvState], springs: &[[f32; 4]], params: &[EnvParams], task: &[TaskState]) -> Vec<u8> {
    let body = std::mem::size_of_val(states) + std::mem::size_of_val(springs) + std::mem::size_of_val(params) + std::mem::size_of_val(task);
    let mut out = Vec::with_capacity(SNAPSHOT_HEADER + body);
    out.extend_from_slice(SNAPSHOT_MAGIC);
    let per_env = springs.len().checked_div(states.len()).unwrap_or(0);
    for v in [states.len(), std::mem::size_of::<EnvState>(), std::mem::size_of::<EnvParams>(), std::mem::size_of::<TaskState>(), per_env] {
        out.extend_from_slice(&(v as u32).to_le_bytes());
    }
    out.extend_from_slice(bytemuck::cast_slice(states));
    out.extend_from_slice(bytemuck::cast_slice(springs));
    out.extend_from_slice(bytemuck::cast_slice(params));
    out.extend_from_slice(bytemuck::cast_slice(task));
    out
}

/// The inverse of [`encode_snapshot`] for a batch of `n` envs with `springs_per_env` contact
/// springs each.
pub(crate) fn decode_snapshot(bytes: &[u8], n: usize, springs_per_env: usize) -> Result<(EnvSnapshot, Vec<TaskState>)> {
    ensure!(bytes.len() >= SNAPSHOT_HEADER && &bytes[..8] == SNAPSHOT_MAGIC, "not a dextrain task snapshot of this version (DXTASK03)");
    let word = |i: usize| u32::from_le_bytes([bytes[8 + 4 * i], bytes[9 + 4 * i], bytes[10 + 4 * i], bytes[11 + 4 * i]]) as usize;
    let sizes = [std::mem::size_of::<EnvState>(), std::mem::size_of::<EnvParams>(), std::mem::size_of::<TaskState>()];
    ensure!(word(0) == n, "the snapshot holds {} envs, this batch has {n} (sim.num_envs)", word(0));
    ensure!([word(1), word(2), word(3)] == sizes, "the snapshot's state layout {:?} differs from this build's {sizes:?}", [word(1), word(2), word(3)]);
    ensure!(word(4) == springs_per_env, "the snapshot has {} contact springs per env, this hand and object have {springs_per_env}", word(4));
    let (a, sp, b, c) = (n * sizes[0], n * springs_per_env * 16, n * sizes[1], n * sizes[2]);
    ensure!(bytes.len() == SNAPSHOT_HEADER + a + sp + b + c, "the snapshot is {} bytes, expected {}", bytes.len(), SNAPSHOT_HEADER + a + sp + b + c);
    let body = &bytes[SNAPSHOT_HEADER..];
    let env = EnvSnapshot {
        states: bytemuck::pod_collect_to_vec(&body[..a]),
        springs: bytemuck::pod_collect_to_vec(&body[a..a + sp]),
        params: bytemuck::pod_collect_to_vec(&body[a + sp..a + sp + b]),
    };
    Ok((env, bytemuck::pod_collect_to_vec(&body[a + sp + b..])))
}

/// Builds the task on the backend the config asks for (`cfg.backend()`, the rules of
/// [`crate::env::make_env_batch`]: `auto` = a hardware GPU adapter if there is one, else the CPU).
pub fn make_task_batch(cfg: &Config, model: SimModel) -> Result<Box<dyn TaskBatch>> {
    match crate::env::sim_gpu_context(cfg)? {
        Some(ctx) => Ok(Box::new(GpuTaskBatch::new(cfg, ctx, model)?)),
        None => Ok(Box::new(CpuTaskBatch::new(cfg, model)?)),
    }
}

/// Checks that a controller gives one target per env, with finite values.
pub(crate) fn check_targets(spec: &TaskSpec, targets: &[Targets]) -> Result<()> {
    ensure!(targets.len() == spec.num_envs, "{} targets for {} envs", targets.len(), spec.num_envs);
    for (i, t) in targets.iter().enumerate() {
        let finite = t.wrist_pos.iter().chain(&t.wrist_rot).chain(&t.q).all(|v| v.is_finite());
        ensure!(finite, "the targets of env {i} are not finite");
    }
    Ok(())
}

/// Checks the length and finiteness of a step's actions.
pub(crate) fn check_actions(spec: &TaskSpec, actions: &[f32]) -> Result<()> {
    ensure!(
        actions.len() == spec.num_envs * spec.action_dim,
        "{} actions for {} envs × {} actions per env",
        actions.len(),
        spec.num_envs,
        spec.action_dim
    );
    if let Some(i) = actions.iter().position(|a| !a.is_finite()) {
        bail!("action {} of env {} is {} (actions must be finite)", i % spec.action_dim, i / spec.action_dim, actions[i]);
    }
    Ok(())
}