//! The task layer: the lift task and the reference-following kinds (`track`, `residual_joint`,
//! `residual_task`; DESIGN §5) on top of an [`EnvBatch`], on both backends.
//!
//! The sections below describe the lift task (`task.kind = "lift"`). The reference kinds share the
//! contract and the order of the kernels; their actions, observations, rewards, success and
//! resets are documented on [`residual_targets`], [`task_act`], [`tracking_terms`],
//! [`task_reward`], [`task_init`] and [`observe_reference`], and in the README ("The
//! reference-following tasks"). Their per-env reference cursor lives in [`TaskState::cursor`]
//! (`env::reference`), their bank in bindings 13–15.
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
//!   4. the reset of every done env (its next episode, drawn as [`EnvBatch::reset`] does);
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
//! **Critic observations** (`priv_dim` = `obs_dim` + 15 + 2·T): the clean actor observations, then
//! `obj_vel.x/y/z`, `obj_angvel.x/y/z`, `wrist_vel.x/y/z`, `wrist_angvel.x/y/z`, `tip_contact.<tip>`
//! (1 when its force > contact_force), `tip_force.<tip>` (N, the step's average), `obj_mass`,
//! `obj_friction`, `obj_scale` (the env's drawn parameters).
//!
//! The functions after [`make_task_batch`] are the CPU twin of `shaders/task.wgsl`: same names, same
//! order, same arithmetic (tests/shaders.rs checks the order, tests/task.rs the results).

use anyhow::{Result, bail, ensure};
use glam::{Vec2, Vec3, Vec4};
use rayon::prelude::*;

use super::common::{quat_error, quat_from_axis_angle, quat_mul, quat_normalize, quat_rotate, rand_uniform};
use super::cpu::CpuEnvBatch;
use super::layout::*;
use super::physics::{Model, Scratch, hand_kinematics, v3};
use super::{EnvBatch, SimModel};
use super::ik::{IkParams, ik_solve, ik_tip_positions, IkScratch};
use super::reference::{RefFrame, RefGlobals, RefModel, ref_begin, ref_object_start, ref_sample};
use crate::config::{Config, TASK_KINDS, task_terms};
use crate::traj::bank::RefBank;
use crate::hand::{MAX_JOINTS, MAX_TIPS};

/// RNG purpose of the observation noise (keep in sync with task.wgsl; reset.rs uses 1 and 2).
pub const PURPOSE_OBS_NOISE: u32 = 3;
/// Noise draws of one env step: draw k of obs entry i at step s has key s · OBS_KEY_STRIDE + 2i + k.
pub const OBS_KEY_STRIDE: u32 = 4096;
/// Task kinds (`TaskGlobals::kind`; keep in sync with task.wgsl).
pub const KIND_LIFT: u32 = 0;
pub const KIND_TRACK: u32 = 1;
pub const KIND_RESIDUAL_JOINT: u32 = 2;
pub const KIND_RESIDUAL_TASK: u32 = 3;
/// Most reward terms of a kind (the output record's term slots).
pub const MAX_TERMS: usize = 8;
/// Offsets in the per-env output record (after the obs and priv obs sections of the GPU's output
/// buffer; keep in sync with task.wgsl `OUT_*`): reward, the weighted terms (`MAX_TERMS` slots,
/// the kind's first), terminated, time_out, success, lift height, max hand–object penetration, the
/// object's position (m) and orientation (rad) error against its reference (reference kinds);
/// `OUT_MISC` floats in all.
pub const OUT_REWARD: usize = 0;
pub const OUT_TERMS: usize = 1;
pub const OUT_TERMINATED: usize = 9;
pub const OUT_TIME_OUT: usize = 10;
pub const OUT_SUCCESS: usize = 11;
pub const OUT_LIFT: usize = 12;
pub const OUT_MAX_PEN: usize = 13;
pub const OUT_OBJ_POS_ERR: usize = 14;
pub const OUT_OBJ_ROT_ERR: usize = 15;
pub const OUT_MISC: usize = 16;
/// The env step that `ref_sample` clamps to the reference's last frame (its final pose).
pub const REF_END_STEP: u32 = 1 << 30;

/// Names and sizes of a task batch.
#[derive(Clone, Debug)]
pub struct TaskSpec {
    /// Number of envs N.
    pub num_envs: usize,
    /// Actor observation length.
    pub obs_dim: usize,
    /// Critic observation length: the clean (noise-free) actor obs, then privileged extras.
    pub priv_dim: usize,
    /// 6 + number of actuated joints.
    pub action_dim: usize,
    /// One name per actor obs entry (see the module documentation).
    pub obs_names: Vec<String>,
    /// One name per critic obs entry.
    pub priv_names: Vec<String>,
    /// One name per action: `wrist_dx`, `wrist_dy`, `wrist_dz`, `wrist_rx`, `wrist_ry`, `wrist_rz`,
    /// then `q.<joint>` per actuated joint.
    pub action_names: Vec<String>,
    /// The reward terms (`config::LIFT_TERMS`, in that order).
    pub term_names: Vec<String>,
    /// Env steps per episode (`task.episode_length`).
    pub episode_length: u32,
    /// Seconds per env step (`sim.dt · sim.decimation`).
    pub control_dt: f32,
    /// `task.kind`.
    pub kind: String,
}

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
    }
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
    fn gpu_context(&self) -> Option<&crate::env::gpu::GpuContext>;
    /// Starts episode 0 of every env; returns the first observations (reward/terms 0, no dones).
    fn reset_all(&mut self) -> Result<&StepBatch>;
    /// actions: `[N, action_dim]` (clipped to [−1, 1] inside; must be finite). Maps actions to
    /// targets, steps the physics, computes reward terms / terminations / time-outs on the post-step
    /// state, resets the done envs (next episode), then observes every env.
    fn step(&mut self, actions: &[f32]) -> Result<&StepBatch>;
    /// The wrist and joint targets of every env's last step (for an env that was just reset: the
    /// default targets its next step starts from).
    fn targets(&mut self) -> Result<Vec<Targets>>;
    /// Reference kinds: env `env`'s (augmented) reference at its current env step (the frame its
    /// tracking error is measured against); `None` for the lift task.
    fn reference_now(&mut self, env: usize) -> Result<Option<RefFrame>>;
    /// Everything that decides the envs' future (env states, parameters, task states), as bytes for
    /// a checkpoint; [`TaskBatch::load_state`] restores it.
    fn save_state(&mut self) -> Result<Vec<u8>>;
    /// Restores what `save_state` returned (same hand and `num_envs`; either backend may load it).
    fn load_state(&mut self, state: &[u8]) -> Result<()>;
}

const SNAPSHOT_MAGIC: &[u8; 8] = b"DXTASK01";

/// Serialises a task batch's state: magic, N and the struct sizes (u32 LE), then the env states,
/// parameters and task states as their Pod bytes.
pub(crate) fn encode_snapshot(states: &[EnvState], params: &[EnvParams], task: &[TaskState]) -> Vec<u8> {
    let mut out = Vec::with_capacity(24 + std::mem::size_of_val(states) + std::mem::size_of_val(params) + std::mem::size_of_val(task));
    out.extend_from_slice(SNAPSHOT_MAGIC);
    for v in [states.len(), std::mem::size_of::<EnvState>(), std::mem::size_of::<EnvParams>(), std::mem::size_of::<TaskState>()] {
        out.extend_from_slice(&(v as u32).to_le_bytes());
    }
    out.extend_from_slice(bytemuck::cast_slice(states));
    out.extend_from_slice(bytemuck::cast_slice(params));
    out.extend_from_slice(bytemuck::cast_slice(task));
    out
}

/// The inverse of [`encode_snapshot`] for a batch of `n` envs.
pub(crate) fn decode_snapshot(bytes: &[u8], n: usize) -> Result<(Vec<EnvState>, Vec<EnvParams>, Vec<TaskState>)> {
    ensure!(bytes.len() >= 24 && &bytes[..8] == SNAPSHOT_MAGIC, "not a dextrain task snapshot");
    let word = |i: usize| u32::from_le_bytes([bytes[8 + 4 * i], bytes[9 + 4 * i], bytes[10 + 4 * i], bytes[11 + 4 * i]]) as usize;
    let sizes = [std::mem::size_of::<EnvState>(), std::mem::size_of::<EnvParams>(), std::mem::size_of::<TaskState>()];
    ensure!(word(0) == n, "the snapshot holds {} envs, this batch has {n} (sim.num_envs)", word(0));
    ensure!([word(1), word(2), word(3)] == sizes, "the snapshot's state layout {:?} differs from this build's {sizes:?}", [word(1), word(2), word(3)]);
    let (a, b, c) = (n * sizes[0], n * sizes[1], n * sizes[2]);
    ensure!(bytes.len() == 24 + a + b + c, "the snapshot is {} bytes, expected {}", bytes.len(), 24 + a + b + c);
    let body = &bytes[24..];
    Ok((bytemuck::pod_collect_to_vec(&body[..a]), bytemuck::pod_collect_to_vec(&body[a..a + b]), bytemuck::pod_collect_to_vec(&body[a + b..])))
}

/// Builds the task on the backend the config asks for (`cfg.backend()`, the rules of
/// [`super::make_env_batch`]: `auto` = a hardware GPU adapter if there is one, else the CPU).
pub fn make_task_batch(cfg: &Config, model: SimModel) -> Result<Box<dyn TaskBatch>> {
    match super::sim_gpu_context(cfg)? {
        Some(ctx) => Ok(Box::new(super::task_gpu::GpuTaskBatch::new(cfg, ctx, model)?)),
        None => Ok(Box::new(CpuTaskBatch::new(cfg, model)?)),
    }
}

/// Everything both backends build a task from: names and sizes, the constants, and (reference
/// kinds) the reference bank and its constants.
pub struct TaskSetup {
    pub spec: TaskSpec,
    pub tc: TaskGlobals,
    /// The references (`task.reference.files`); `None` for the lift task.
    pub bank: Option<RefBank>,
    /// The reference layer's constants (zeroed for the lift task).
    pub rg: RefGlobals,
}

/// The reference files of `task.reference.files`, resolved against the config's directory; a
/// directory stands for every `.mcap` and `.csv` file in it, sorted by name.
pub fn reference_paths(cfg: &Config) -> Result<Vec<std::path::PathBuf>> {
    let mut out = Vec::new();
    for f in &cfg.task.reference.files {
        let p = cfg.resolve(f);
        if p.is_dir() {
            let mut inside: Vec<std::path::PathBuf> = std::fs::read_dir(&p)
                .map_err(|e| anyhow::anyhow!("{}: key `task.reference.files`: cannot list {}: {e}", cfg.source.display(), p.display()))?
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|q| q.extension().is_some_and(|x| x == "mcap" || x == "csv"))
                .collect();
            if inside.is_empty() {
                bail!("{}: key `task.reference.files`: the directory {} holds no .mcap or .csv reference", cfg.source.display(), p.display());
            }
            inside.sort();
            out.extend(inside);
        } else {
            out.push(p);
        }
    }
    Ok(out)
}

/// `task.kind` → `TaskGlobals::kind`.
pub fn kind_index(kind: &str) -> Option<u32> {
    match kind {
        "lift" => Some(KIND_LIFT),
        "track" => Some(KIND_TRACK),
        "residual_joint" => Some(KIND_RESIDUAL_JOINT),
        "residual_task" => Some(KIND_RESIDUAL_TASK),
        _ => None,
    }
}

/// The task's spec, constants and references from the config's `[task]` and the hand (both backends).
pub fn task_setup(cfg: &Config, model: &SimModel) -> Result<TaskSetup> {
    let file = cfg.source.display();
    let t = &cfg.task;
    let es = &model.spec;
    let hand = model.hand.source.display();
    let joint_names = &es.joint_names;
    let tips = &es.tip_names;
    let kind = kind_index(&t.kind).ok_or_else(|| anyhow::anyhow!("{file}: key `task.kind` = {:?}: expected one of {}", t.kind, TASK_KINDS.join(", ")))?;
    let terms = task_terms(&t.kind);
    let n_actuated = es.actuated.len();
    let n_res = 6 + 3 * tips.len();
    let action_dim = if kind == KIND_RESIDUAL_TASK { n_res } else { 6 + n_actuated };
    if action_dim > MAX_ACTIONS || n_actuated > MAX_JOINTS {
        bail!(
            "{file}: the hand {hand} has {n_actuated} actuated joints, so the {} task would have {action_dim} actions; at most {MAX_ACTIONS} (MAX_ACTIONS) are supported",
            t.kind
        );
    }
    if tips.is_empty() {
        bail!("{file}: the {} task needs fingertips, but the hand {hand} has none: name them in `hand.fingertips`", t.kind);
    }
    let thumb = if t.lift.thumb.is_empty() {
        tips.iter().position(|n| n.to_lowercase().starts_with("th")).ok_or_else(|| {
            anyhow::anyhow!(
                "{file}: key `task.lift.thumb` = \"\": no fingertip of the hand {hand} has a name starting with \"th\"; expected the thumb's fingertip, one of: {}",
                tips.join(", ")
            )
        })?
    } else {
        tips.iter().position(|n| *n == t.lift.thumb).ok_or_else(|| {
            anyhow::anyhow!(
                "{file}: key `task.lift.thumb` = {:?}: expected one of the hand's fingertips: {}",
                t.lift.thumb,
                tips.join(", ")
            )
        })?
    };
    let finger_mode = match t.action.finger_mode.as_str() {
        "absolute" => 0,
        "delta" => 1,
        other => bail!("{file}: key `task.action.finger_mode` = {other:?}: expected \"absolute\" or \"delta\""),
    };
    for name in t.rewards.keys() {
        if !terms.contains(&name.as_str()) {
            bail!("{file}: key `task.rewards.{name}`: expected a term of the {} task: {}", t.kind, terms.join(", "));
        }
    }
    let (bank, rg) = if kind == KIND_LIFT {
        (None, RefGlobals::default())
    } else {
        let paths = reference_paths(cfg)?;
        let bank = RefBank::load(&paths, model, thumb).map_err(|e| anyhow::anyhow!("{file}: key `task.reference.files`: {e:#}"))?;
        let mut rg = bank.globals();
        t.reference.fill(&mut rg);
        (Some(bank), rg)
    };

    let xyz = ["x", "y", "z"];
    let quat = ["qx", "qy", "qz", "qw"];
    let mut action_names: Vec<String> = ["wrist_dx", "wrist_dy", "wrist_dz", "wrist_rx", "wrist_ry", "wrist_rz"].iter().map(|s| s.to_string()).collect();
    if kind == KIND_RESIDUAL_TASK {
        for tip in tips {
            action_names.extend(xyz.iter().map(|c| format!("tip.{tip}.{c}")));
        }
    } else {
        action_names.extend(es.actuated.iter().map(|&j| format!("q.{}", joint_names[j])));
    }
    let mut obs_names = Vec::new();
    obs_names.extend(es.actuated.iter().map(|&j| format!("q.{}", joint_names[j])));
    obs_names.extend(es.actuated.iter().map(|&j| format!("qd.{}", joint_names[j])));
    obs_names.extend(action_names.iter().map(|a| format!("prev_action.{a}")));
    obs_names.extend(xyz.iter().map(|c| format!("wrist_pos.{c}")));
    obs_names.extend(quat.iter().map(|c| format!("wrist_rot.{c}")));
    for tip in tips {
        obs_names.extend(xyz.iter().map(|c| format!("tip_pos.{tip}.{c}")));
    }
    obs_names.extend(xyz.iter().map(|c| format!("obj_pos.{c}")));
    obs_names.extend(quat.iter().map(|c| format!("obj_rot.{c}")));
    if kind == KIND_LIFT {
        obs_names.extend(xyz.iter().map(|c| format!("goal.{c}")));
        obs_names.extend(xyz.iter().map(|c| format!("obj_rel.{c}")));
    } else {
        for i in 0..=t.track.lookahead {
            let r = format!("ref{i}");
            obs_names.extend(xyz.iter().map(|c| format!("{r}.wrist_pos.{c}")));
            obs_names.extend(xyz.iter().map(|c| format!("{r}.wrist_rot.{c}")));
            obs_names.extend(es.actuated.iter().map(|&j| format!("{r}.q.{}", joint_names[j])));
            obs_names.extend(xyz.iter().map(|c| format!("{r}.obj_pos.{c}")));
            obs_names.extend(xyz.iter().map(|c| format!("{r}.obj_rot.{c}")));
            for tip in tips {
                obs_names.extend(xyz.iter().map(|c| format!("{r}.tip_pos.{tip}.{c}")));
            }
        }
        obs_names.push("phase".into());
        if kind == KIND_RESIDUAL_TASK {
            obs_names.extend(action_names.iter().map(|a| format!("residual.{a}")));
        }
    }
    let mut priv_names = obs_names.clone();
    for v in ["obj_vel", "obj_angvel", "wrist_vel", "wrist_angvel"] {
        priv_names.extend(xyz.iter().map(|c| format!("{v}.{c}")));
    }
    priv_names.extend(tips.iter().map(|tip| format!("tip_contact.{tip}")));
    priv_names.extend(tips.iter().map(|tip| format!("tip_force.{tip}")));
    priv_names.extend(["obj_mass", "obj_friction", "obj_scale"].iter().map(|s| s.to_string()));
    let (obs_dim, priv_dim) = (obs_names.len(), priv_names.len());
    if 2 * priv_dim >= OBS_KEY_STRIDE as usize {
        bail!("{}: {priv_dim} observations, at most {} are supported", hand, OBS_KEY_STRIDE / 2 - 1);
    }

    let mut weights = [[0.0f32; 4]; 2];
    for (k, name) in terms.iter().enumerate() {
        weights[k / 4][k % 4] = t.rewards.get(*name).copied().unwrap_or(0.0);
    }
    let mut actuated = [[0u32; 4]; MAX_JOINTS / 4];
    for (i, &j) in es.actuated.iter().enumerate() {
        actuated[i / 4][i % 4] = j as u32;
    }
    let a = &t.action;
    let l = &t.lift;
    let n = &t.obs_noise;
    let k = &t.track;
    let r = &t.residual;
    let control_dt = es.dt * es.decimation as f32;
    let v4 = |v: [f32; 3]| [v[0], v[1], v[2], 0.0];
    let tc = TaskGlobals {
        wrist_pos_min: v4(a.wrist_pos_min),
        wrist_pos_max: v4(a.wrist_pos_max),
        palm_offset: v4(l.palm_offset),
        weights,
        actuated,
        n_actuated: n_actuated as u32,
        n_act: action_dim as u32,
        obs_dim: obs_dim as u32,
        priv_dim: priv_dim as u32,
        episode_length: t.episode_length,
        finger_mode,
        thumb: thumb as u32,
        _pad0: 0,
        wrist_pos_scale: a.wrist_pos_scale,
        wrist_rot_scale: a.wrist_rot_scale,
        wrist_rot_limit: a.wrist_rot_limit,
        finger_delta_scale: a.finger_delta_scale,
        reach_alpha: l.reach_alpha,
        success_height: l.success_height,
        contact_force: l.contact_force,
        drop_height: l.drop_height,
        table_half_extent: l.table_half_extent,
        max_hand_distance: l.max_hand_distance,
        noise_joint_pos: n.joint_pos,
        noise_joint_vel: n.joint_vel,
        noise_hand_pos: n.hand_pos,
        noise_object_pos: n.object_pos,
        noise_object_rot: n.object_rot,
        _pad1: 0.0,
        kind,
        n_terms: terms.len() as u32,
        start_mode: (k.start == "config") as u32,
        lookahead: k.lookahead,
        lookahead_stride: k.lookahead_stride,
        n_res: n_res as u32,
        open_loop: t.open_loop as u32,
        track_action: (k.action == "reference") as u32,
        beta_joint: k.beta_joint,
        beta_wrist_pos: k.beta_wrist_pos,
        beta_wrist_rot: k.beta_wrist_rot,
        alpha_joint: k.alpha_joint,
        alpha_wrist_pos: k.alpha_wrist_pos,
        alpha_wrist_rot: k.alpha_wrist_rot,
        alpha_object_pos: k.alpha_object_pos,
        alpha_object_rot: k.alpha_object_rot,
        success_pos_tol: k.success_pos_tol,
        success_rot_tol: k.success_rot_tol,
        max_object_error: k.max_object_error,
        res_alpha: r.alpha,
        res_wrist_pos_alpha: r.wrist_pos_alpha,
        res_wrist_rot_alpha: r.wrist_rot_alpha,
        res_obj_pos_coef: r.obj_pos_coef,
        res_obj_rot_coef: r.obj_rot_coef,
        res_ema: r.ema,
        res_scale_wrist_pos: r.scale_wrist_pos,
        res_scale_wrist_rot: r.scale_wrist_rot,
        res_scale_tips: r.scale_tips,
        res_clamp_wrist_pos: r.clamp_wrist_pos,
        res_clamp_wrist_rot: r.clamp_wrist_rot,
        res_clamp_tips: r.clamp_tips,
        control_dt,
        rw_obj_pos: r.reward_obj_pos,
        rw_obj_rot: r.reward_obj_rot,
        rw_tips: r.reward_tips,
        rw_wrist_pos: r.reward_wrist_pos,
        rw_wrist_rot: r.reward_wrist_rot,
        _pad3: [0.0; 3],
        ik: IkParams::default(),
    };
    // episode length for the learner's random initial episode lengths: the longest reference
    let episode_length = match (&bank, t.episode_length) {
        (Some(b), 0) => b.info.iter().map(|i| i.n_frames.saturating_sub(1)).max().unwrap_or(1).max(1),
        _ => t.episode_length,
    };
    let spec = TaskSpec {
        num_envs: es.num_envs,
        obs_dim,
        priv_dim,
        action_dim,
        obs_names,
        priv_names,
        action_names,
        term_names: terms.iter().map(|s| s.to_string()).collect(),
        episode_length,
        control_dt,
        kind: t.kind.clone(),
    };
    Ok(TaskSetup { spec, tc, bank, rg })
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

// ---------------------------------------------------------------------------------------------
// CPU twin of shaders/task.wgsl (same function names, same order, same arithmetic)
// ---------------------------------------------------------------------------------------------

/// The observation cursor of one env (the shader's `ob_*` / `pr_base` private variables): where
/// its actor and critic rows go and the counters its noise is drawn from.
pub struct ObsOut<'a> {
    pub seed: u32,
    pub env: u32,
    pub episode: u32,
    pub step: u32,
    /// The env's actor obs row `[obs_dim]`.
    pub obs: &'a mut [f32],
    /// The env's critic obs row `[priv_dim]`.
    pub privo: &'a mut [f32],
}

/// Joint index of actuated joint `i`.
pub fn actuated_joint(tc: &TaskGlobals, i: u32) -> usize {
    tc.actuated[(i / 4) as usize][(i % 4) as usize] as usize
}

/// Finger joint target from action `a`: absolute `lower + (a + 1)/2 (upper − lower)` (unlimited
/// joints: `default + a π`), delta `clamp(prev + a · finger_delta_scale, lower, upper)`.
pub fn finger_target(tc: &TaskGlobals, mode: u32, jd: &JointDesc, a: f32, prev: f32) -> f32 {
    if mode == 0 {
        if jd.lower <= -1e29 || jd.upper >= 1e29 {
            return jd.default_q + a * std::f32::consts::PI;
        }
        return jd.lower + 0.5 * (a + 1.0) * (jd.upper - jd.lower);
    }
    // WGSL clamp(e, lo, hi) = min(max(e, lo), hi)
    (prev + a * tc.finger_delta_scale).max(jd.lower).min(jd.upper)
}

/// `exp(rv) ⊗ rot`, normalised; `rot` itself (bit for bit) when the rotation is below 1e-9 rad.
pub fn rotate_by(rot: Vec4, rv: Vec3) -> Vec4 {
    let angle = rv.length();
    if angle > 1e-9 {
        return quat_normalize(quat_mul(quat_from_axis_angle(rv / angle, angle), rot));
    }
    rot
}

/// exp(rv) ⊗ rot, then at most `wrist_rot_limit` from the initial orientation: exp(e·limit/|e|) ⊗ init.
pub fn wrist_rot_target(g: &Globals, tc: &TaskGlobals, rot: Vec4, rv: Vec3) -> Vec4 {
    let mut r = rotate_by(rot, rv);
    let init = Vec4::from_array(g.init_wrist_rot);
    let e = quat_error(r, init);
    let d = e.length();
    if d > tc.wrist_rot_limit {
        r = quat_normalize(quat_mul(quat_from_axis_angle(e / d, tc.wrist_rot_limit), init));
    }
    r
}

/// Targets that follow a reference frame exactly (what `dextrain replay` drives).
pub fn nominal_targets(f: &RefFrame) -> Targets {
    Targets { wrist_pos: f.wrist_pos, wrist_rot: f.wrist_rot, q: f.q }
}

/// Residual kinds (and track with `task.track.action = "reference"`): the targets of this step from
/// the nominal frame `f` (the reference at the end of the step) and the clipped actions `a`;
/// records ‖δ‖² (and, residual_task, ũ and Δa) in `ts`. residual_joint and track:
/// `p* = p̄ + α_p a[0..3]`, `R* = exp(α_r a[3..6]) ⊗ R̄`, `q*_j = clamp(q̄_j + α a_j, lower, upper)`. residual_task: `ũ = ema·a + (1 − ema)·ũ`, `Δa = clamp(Δa + s ⊙ ũ Δt, ±c)`
/// (per component), `p* = p̄ + Δa[0..3]`, `R* = exp(Δa[3..6]) ⊗ R̄`, and the finger joints from IK
/// of the fingertips `FK(q̄) + Δa_tip` (wrist frame), seeded at q̄ (q̄ itself when every Δa_tip is 0).
pub fn residual_targets(a: &[f32; MAX_ACTIONS], f: &RefFrame, ts: &mut TaskState, m: &Model, tc: &TaskGlobals) -> Targets {
    let mut t = nominal_targets(f);
    let mut sq = 0.0f32;
    if tc.kind != KIND_RESIDUAL_TASK {
        // residual_joint, and track with `task.track.action = "reference"`
        let dp = Vec3::new(a[0], a[1], a[2]) * tc.res_wrist_pos_alpha;
        let dr = Vec3::new(a[3], a[4], a[5]) * tc.res_wrist_rot_alpha;
        t.wrist_pos = [f.wrist_pos[0] + dp.x, f.wrist_pos[1] + dp.y, f.wrist_pos[2] + dp.z, 0.0];
        t.wrist_rot = rotate_by(Vec4::from_array(f.wrist_rot), dr).to_array();
        // ‖δ‖² = Σ δ_i² over every component
        sq = dp.dot(dp) + dr.dot(dr);
        for i in 0..tc.n_actuated {
            let j = actuated_joint(tc, i);
            let jd = &m.joints[j];
            let d = a[6 + i as usize] * tc.res_alpha;
            t.q[j] = (f.q[j] + d).max(jd.lower).min(jd.upper);
            sq += d * d;
        }
    } else {
        let mut tips_moved = false;
        for c in 0..tc.n_res as usize {
            // ũ_t = ema·u_t + (1 − ema)·ũ_{t−1}
            ts.res_ema[c] = tc.res_ema * a[c] + (1.0 - tc.res_ema) * ts.res_ema[c];
            let (scale, lim) = if c < 3 {
                (tc.res_scale_wrist_pos, tc.res_clamp_wrist_pos)
            } else if c < 6 {
                (tc.res_scale_wrist_rot, tc.res_clamp_wrist_rot)
            } else {
                (tc.res_scale_tips, tc.res_clamp_tips)
            };
            // Δa_t = clamp(Δa_{t−1} + s ũ_t Δt, −c, c)
            ts.res_delta[c] = (ts.res_delta[c] + scale * ts.res_ema[c] * tc.control_dt).max(-lim).min(lim);
            sq += ts.res_delta[c] * ts.res_delta[c];
            if c >= 6 && ts.res_delta[c] != 0.0 {
                tips_moved = true;
            }
        }
        let d = &ts.res_delta;
        t.wrist_pos = [f.wrist_pos[0] + d[0], f.wrist_pos[1] + d[1], f.wrist_pos[2] + d[2], 0.0];
        t.wrist_rot = rotate_by(Vec4::from_array(f.wrist_rot), Vec3::new(d[3], d[4], d[5])).to_array();
        if tips_moved {
            let mut s = IkScratch::default();
            let base = ik_tip_positions(m, &f.q, &mut s);
            let mut goal = [Vec3::ZERO; MAX_TIPS];
            for k in 0..m.g.n_tips as usize {
                goal[k] = base[k] + Vec3::new(d[6 + 3 * k], d[7 + 3 * k], d[8 + 3 * k]);
            }
            let mask = (1u32 << m.g.n_tips) - 1;
            t.q = ik_solve(m, &f.q, &goal, mask, &tc.ik);
        }
    }
    ts.res_sq = sq;
    t
}

/// Maps one env's actions (`[n_act]`, clipped here) to its targets; records the action terms and the
/// action in `ts`. Returns the targets the physics steps toward. lift and track with
/// `task.track.action = "free"`: the wrist and finger mapping of `[task.action]`; residual kinds and
/// track with `"reference"`: [`residual_targets`] around the reference at the end of this step; the
/// open-loop baseline: that reference itself.
pub fn task_act(actions: &[f32], st: &EnvState, ts: &mut TaskState, m: &Model, tc: &TaskGlobals, r: &RefModel) -> Targets {
    let mut a = [0.0f32; MAX_ACTIONS];
    let mut rate = 0.0f32;
    let mut mag = 0.0f32;
    for i in 0..tc.n_act as usize {
        let ai = actions[i].clamp(-1.0, 1.0);
        let d = ai - ts.prev_action[i];
        // Σ (a_t − a_{t−1})², Σ a_t²
        rate += d * d;
        mag += ai * ai;
        a[i] = ai;
        ts.prev_action[i] = ai;
    }
    ts.act_rate = rate;
    ts.act_mag = mag;
    if tc.kind != KIND_LIFT && (tc.open_loop != 0 || tc.kind != KIND_TRACK || tc.track_action != 0) {
        // the reference at the end of this step: replay's targets for control step `st.step`
        let f = ref_sample(r, &ts.cursor, st.step, 1);
        if tc.open_loop != 0 {
            ts.targets = nominal_targets(&f);
            ts.res_sq = 0.0;
        } else {
            ts.targets = residual_targets(&a, &f, ts, m, tc);
        }
        return ts.targets;
    }
    let wp = v3(ts.targets.wrist_pos) + Vec3::new(a[0], a[1], a[2]) * tc.wrist_pos_scale;
    let wp = wp.max(v3(tc.wrist_pos_min)).min(v3(tc.wrist_pos_max));
    ts.targets.wrist_pos = [wp.x, wp.y, wp.z, 0.0];
    let rot = wrist_rot_target(m.g, tc, Vec4::from_array(ts.targets.wrist_rot), Vec3::new(a[3], a[4], a[5]) * tc.wrist_rot_scale);
    ts.targets.wrist_rot = rot.to_array();
    for i in 0..tc.n_actuated {
        let j = actuated_joint(tc, i);
        ts.targets.q[j] = finger_target(tc, tc.finger_mode, &m.joints[j], a[6 + i as usize], ts.targets.q[j]);
    }
    ts.targets
}

/// p_palm = p_wrist + R_wrist · palm_offset.
pub fn palm_position(tc: &TaskGlobals, wrist_pos: Vec3, wrist_rot: Vec4) -> Vec3 {
    wrist_pos + quat_rotate(wrist_rot, v3(tc.palm_offset))
}

/// The tracking reward terms (raw, the kind's order) of one env on its post-step state against the
/// reference frame `f` of this instant; `e` = the object's position and angle error against `f`,
/// `fin` = whether the object is within the success tolerance of the reference's final pose,
/// `contact` = the thumb and another fingertip touch the object, `h` = the lift height (m).
#[allow(clippy::too_many_arguments)]
pub fn tracking_terms(st: &EnvState, p: &EnvParams, ts: &TaskState, f: &RefFrame, e: Vec2, fin: bool, contact: bool, h: f32, m: &Model, tc: &TaskGlobals) -> [f32; MAX_TERMS] {
    let mut raw = [0.0f32; MAX_TERMS];
    let wp = v3(st.wrist_pos);
    let wr = Vec4::from_array(st.wrist_rot);
    let e_wp = (wp - v3(f.wrist_pos)).length();
    let e_wr = quat_error(Vec4::from_array(f.wrist_rot), wr).length();
    let ended = f.ended != 0;
    if tc.kind == KIND_TRACK {
        let mut dq = 0.0f32;
        for i in 0..tc.n_actuated {
            let j = actuated_joint(tc, i);
            let d = st.q[j] - f.q[j];
            dq += d * d;
        }
        // R_f = β1 (1 − tanh(α1‖q − q̂‖)) + β2 (1 − tanh(α2‖x − x̂‖)) + β3 (1 − tanh(α3 φ))
        let rj = 1.0 - (tc.alpha_joint * dq.sqrt()).min(20.0).tanh();
        let rx = 1.0 - (tc.alpha_wrist_pos * e_wp).min(20.0).tanh();
        let rr = 1.0 - (tc.alpha_wrist_rot * e_wr).min(20.0).tanh();
        raw[0] = tc.beta_joint * rj + tc.beta_wrist_pos * rx + tc.beta_wrist_rot * rr;
        // R_o = exp(−α4‖T − T̂‖) + exp(−α5‖log(q̂⁻¹ ⊗ q)‖)
        raw[1] = (-tc.alpha_object_pos * e.x).exp() + (-tc.alpha_object_rot * e.y).exp();
        // contact while the reference grasps
        raw[2] = if contact && f.grasp > 0.5 { 1.0 } else { 0.0 };
        raw[3] = if fin && ended { 1.0 } else { 0.0 };
        raw[4] = h.max(0.0).min(tc.success_height) * 100.0;
        raw[5] = ts.act_rate;
        raw[6] = ts.act_mag;
    } else if tc.kind == KIND_RESIDUAL_JOINT {
        // w_p exp(−k_p e_p) + w_r exp(−k_r e_R) − λ_a ‖δ‖²
        raw[0] = (-tc.res_obj_pos_coef * e.x).exp();
        raw[1] = (-tc.res_obj_rot_coef * e.y).exp();
        raw[2] = ts.res_sq;
        raw[3] = if fin && ended { 1.0 } else { 0.0 };
    } else {
        let mut s = Scratch::default();
        hand_kinematics(st, m, &mut s);
        let mut e_tips = 0.0f32;
        for t in 0..m.g.n_tips as usize {
            e_tips += (tip_position(m, &s, t) - v3(f.tips[t])).length();
        }
        e_tips /= m.g.n_tips.max(1) as f32;
        // object exp(−a_p e_p − a_R e_R), gated by contact or the object being on its reference
        let gate = contact || e.x <= tc.success_pos_tol;
        raw[0] = if gate { (-tc.rw_obj_pos * e.x - tc.rw_obj_rot * e.y).exp() } else { 0.0 };
        raw[1] = (-tc.rw_tips * e_tips).exp();
        raw[2] = (-tc.rw_wrist_pos * e_wp - tc.rw_wrist_rot * e_wr).exp();
        raw[3] = if contact && f.grasp > 0.5 { 1.0 } else { 0.0 };
        let mut vel = 0.0f32;
        let mut torque = 0.0f32;
        let mut work = 0.0f32;
        for i in 0..tc.n_actuated {
            let j = actuated_joint(tc, i);
            let jd = &m.joints[j];
            let qd = st.qd[j];
            // the servo's torque: clamp(kp (clamp(q*, lo, hi) − q) − kd q̇, ±effort)
            let goal = ts.targets.q[j].clamp(jd.lower * p.limit_scale, jd.upper * p.limit_scale);
            let tau = (jd.kp * p.kp_scale * (goal - st.q[j]) - jd.kd * p.kd_scale * qd).clamp(-jd.effort, jd.effort);
            vel += qd * qd;
            torque += tau * tau;
            work += (tau * qd).abs();
        }
        raw[4] = vel;
        raw[5] = torque;
        raw[6] = work;
        let mut table = false;
        for c in 0..m.g.n_colliders as usize {
            if st.anchor_ht[c][3] > 0.0 {
                table = true;
            }
        }
        raw[7] = if table { 1.0 } else { 0.0 };
    }
    raw
}

/// Reward terms, terminated and time-out of one env on its post-step state; writes the env's output
/// record `out` (`[OUT_MISC]`) and the step's fingertip forces and done flag into `ts`. Returns the
/// env's reset request (1 = reset to the next episode; a bad-state env was reset by the physics).
#[allow(clippy::too_many_arguments)]
pub fn task_reward(st: &EnvState, p: &EnvParams, stats: &StepStats, ts: &mut TaskState, m: &Model, tc: &TaskGlobals, r: &RefModel, out: &mut [f32]) -> u32 {
    let bad = stats.bad_reset != 0;
    let obj = v3(st.obj_pos);
    let dist = (obj - palm_position(tc, v3(st.wrist_pos), Vec4::from_array(st.wrist_rot))).length();
    // lifted height of the centre above its rest height (m)
    let h = obj.z - ts.rest_pos[2];
    let mut other = false;
    for i in 0..m.g.n_tips as usize {
        ts.tip_force[i] = stats.tip_force[i];
        if i as u32 != tc.thumb && stats.tip_force[i] > tc.contact_force {
            other = true;
        }
    }
    let thumb = stats.tip_force[tc.thumb as usize] > tc.contact_force;
    let mut raw = [0.0f32; MAX_TERMS];
    let mut terminated = bad || obj.z < tc.drop_height || obj.x.abs() > tc.table_half_extent || obj.y.abs() > tc.table_half_extent;
    terminated = terminated || dist > tc.max_hand_distance;
    let mut time_out;
    let mut success;
    let mut err = Vec2::ZERO;
    if tc.kind == KIND_LIFT {
        // reaching 1 − tanh(α d) (tanh saturates at 20: some GPUs' tanh overflows beyond)
        raw[0] = 1.0 - (tc.reach_alpha * dist).min(20.0).tanh();
        // lifting: h in cm, capped at the success height
        raw[1] = h.max(0.0).min(tc.success_height) * 100.0;
        raw[2] = if thumb && other { 1.0 } else { 0.0 };
        raw[3] = if h >= tc.success_height { 1.0 } else { 0.0 };
        raw[4] = ts.act_rate;
        raw[5] = ts.act_mag;
        success = raw[3];
        time_out = !terminated && st.step >= tc.episode_length;
        if bad {
            // the physics already reset this env: its state says nothing about the step
            raw[0] = 0.0;
            raw[1] = 0.0;
            raw[2] = 0.0;
            raw[3] = 0.0;
            success = 0.0;
        }
    } else {
        let f = ref_sample(r, &ts.cursor, st.step, 0);
        let fin_ref = ref_sample(r, &ts.cursor, REF_END_STEP, 0);
        let orot = Vec4::from_array(st.obj_rot);
        // the object's error against its reference now (m, rad) and against the final pose
        err = Vec2::new((obj - v3(f.obj_pos)).length(), quat_error(Vec4::from_array(f.obj_rot), orot).length());
        let fin_p = (obj - v3(fin_ref.obj_pos)).length();
        let fin_r = quat_error(Vec4::from_array(fin_ref.obj_rot), orot).length();
        let fin = fin_p <= tc.success_pos_tol && fin_r <= tc.success_rot_tol;
        raw = tracking_terms(st, p, ts, &f, err, fin, thumb && other, h, m, tc);
        success = if fin { 1.0 } else { 0.0 };
        terminated = terminated || (tc.max_object_error > 0.0 && err.x > tc.max_object_error);
        time_out = !terminated && if tc.episode_length > 0 { st.step >= tc.episode_length } else { f.ended != 0 };
        if bad {
            raw = [0.0; MAX_TERMS];
            success = 0.0;
            err = Vec2::ZERO;
        }
    }
    let lift = if bad { 0.0 } else { h };
    let mut reward = 0.0f32;
    for k in 0..MAX_TERMS {
        // term_k = w_k · raw_k, reward = Σ_k term_k
        let wk = tc.weights[k / 4][k % 4] * raw[k];
        out[OUT_TERMS + k] = wk;
        reward += wk;
    }
    time_out = time_out && !terminated;
    out[OUT_REWARD] = reward;
    out[OUT_TERMINATED] = if terminated { 1.0 } else { 0.0 };
    out[OUT_TIME_OUT] = if time_out { 1.0 } else { 0.0 };
    out[OUT_SUCCESS] = success;
    out[OUT_LIFT] = lift;
    out[OUT_MAX_PEN] = stats.max_pen_ho;
    out[OUT_OBJ_POS_ERR] = err.x;
    out[OUT_OBJ_ROT_ERR] = err.y;
    let done = terminated || time_out;
    ts.done = done as u32;
    // a bad-state env was already reset by the physics
    (done && !bad) as u32
}

/// Standard normal draw for obs entry `k` (Box–Muller: √(−2 ln u1) cos(2π u2), u1 ∈ (0, 1]).
pub fn obs_noise(o: &ObsOut, k: u32) -> f32 {
    let key = o.step.wrapping_mul(OBS_KEY_STRIDE).wrapping_add(2 * k);
    let u1 = 1.0 - rand_uniform(o.seed, o.env, o.episode, PURPOSE_OBS_NOISE, key);
    let u2 = rand_uniform(o.seed, o.env, o.episode, PURPOSE_OBS_NOISE, key.wrapping_add(1));
    // 2π as the shader's 6.2831853 (the same f32)
    (-2.0 * u1.ln()).sqrt() * (std::f32::consts::TAU * u2).cos()
}

/// `v + σ · N(0, 1)` for obs entry `k` (`v` itself when σ = 0).
pub fn noisy(o: &ObsOut, k: u32, v: f32, sigma: f32) -> f32 {
    if sigma > 0.0 {
        return v + sigma * obs_noise(o, k);
    }
    v
}

/// Actor obs entry `k` (noisy) and the same entry of the critic obs (clean).
pub fn put_obs(o: &mut ObsOut, k: u32, clean: f32, noisy_v: f32) {
    o.obs[k as usize] = noisy_v;
    o.privo[k as usize] = clean;
}

/// Critic-only entry `k` (k ≥ obs_dim).
pub fn put_priv(o: &mut ObsOut, k: u32, v: f32) {
    o.privo[k as usize] = v;
}

/// World position of fingertip `t` (after `hand_kinematics`).
pub fn tip_position(m: &Model, s: &Scratch, t: usize) -> Vec3 {
    let tip = &m.tips[t];
    let l = tip.link as usize;
    s.link_pos[l] + quat_rotate(s.link_rot[l], v3(tip.pos))
}

/// The task state of an env that was just reset: default targets, no previous action, the rest
/// position of the object. Reference kinds also begin the episode's reference ([`ref_begin`]) and,
/// with `task.track.start = "reference"`, place the hand at the reference's first frame at rest
/// (followers from their leaders) and, unless the reference is re-grounded, the object at the
/// reference's first object pose, as `dextrain replay` starts; the targets are then that frame's.
pub fn task_init(env: u32, st: &mut EnvState, m: &Model, tc: &TaskGlobals, r: &RefModel) -> TaskState {
    let mut ts = TaskState::default();
    ts.targets.wrist_pos = m.g.init_wrist_pos;
    ts.targets.wrist_rot = m.g.init_wrist_rot;
    for j in 0..m.g.n_joints as usize {
        ts.targets.q[j] = m.joints[j].default_q;
    }
    if tc.kind != KIND_LIFT {
        ts.cursor = ref_begin(r, env, st.episode, st);
        if tc.start_mode == 0 {
            let f0 = ref_sample(r, &ts.cursor, 0, 0);
            st.wrist_pos = f0.wrist_pos;
            st.wrist_rot = f0.wrist_rot;
            st.wrist_vel = [0.0; 4];
            st.wrist_angvel = [0.0; 4];
            for j in 0..m.g.n_joints as usize {
                let jd = &m.joints[j];
                st.q[j] = f0.q[j];
                st.qd[j] = 0.0;
                if jd.mimic_leader != NO_JOINT {
                    st.q[j] = jd.mimic_mult * f0.q[jd.mimic_leader as usize] + jd.mimic_offset;
                }
            }
            if r.rg.reground == 0 {
                let (p, q) = ref_object_start(r, &ts.cursor);
                st.obj_pos = [p.x, p.y, p.z, 0.0];
                st.obj_rot = q.to_array();
                st.obj_vel = [0.0; 4];
                st.obj_angvel = [0.0; 4];
            }
            ts.targets = nominal_targets(&f0);
        }
    }
    ts.rest_pos = [st.obj_pos[0], st.obj_pos[1], st.obj_pos[2], 0.0];
    ts
}

/// Reference kinds: the reference frames `ref0 … refK` (the current step and the look-ahead steps
/// `i · lookahead_stride`), each relative to the env's state — wrist position and rotation error
/// (rotation vector), actuated joints, object position and rotation error, fingertips — then the
/// phase, and (residual_task) the integrated residual over its clamps. Actor entries are relative
/// to the noisy state (`wn`, `qn`, `on`, `rn`, `tn`), critic entries to the clean one.
#[allow(clippy::too_many_arguments)]
pub fn observe_reference(o: &mut ObsOut, k0: u32, st: &EnvState, ts: &TaskState, s: &Scratch, noisy_state: &NoisyState, m: &Model, tc: &TaskGlobals, r: &RefModel) -> u32 {
    let mut k = k0;
    let wp = v3(st.wrist_pos);
    let wr = Vec4::from_array(st.wrist_rot);
    let op = v3(st.obj_pos);
    let orot = Vec4::from_array(st.obj_rot);
    for i in 0..=tc.lookahead {
        let f = ref_sample(r, &ts.cursor, st.step, i * tc.lookahead_stride);
        let d = v3(f.wrist_pos) - wp;
        let dn = v3(f.wrist_pos) - noisy_state.wrist;
        for c in 0..3 {
            put_obs(o, k, d[c], dn[c]);
            k += 1;
        }
        let e = quat_error(Vec4::from_array(f.wrist_rot), wr);
        for c in 0..3 {
            put_obs(o, k, e[c], e[c]);
            k += 1;
        }
        for a in 0..tc.n_actuated {
            let j = actuated_joint(tc, a);
            put_obs(o, k, f.q[j] - st.q[j], f.q[j] - noisy_state.q[a as usize]);
            k += 1;
        }
        let d = v3(f.obj_pos) - op;
        let dn = v3(f.obj_pos) - noisy_state.obj;
        for c in 0..3 {
            put_obs(o, k, d[c], dn[c]);
            k += 1;
        }
        let e = quat_error(Vec4::from_array(f.obj_rot), orot);
        let en = quat_error(Vec4::from_array(f.obj_rot), noisy_state.obj_rot);
        for c in 0..3 {
            put_obs(o, k, e[c], en[c]);
            k += 1;
        }
        for t in 0..m.g.n_tips as usize {
            let d = v3(f.tips[t]) - tip_position(m, s, t);
            let dn = v3(f.tips[t]) - noisy_state.tips[t];
            for c in 0..3 {
                put_obs(o, k, d[c], dn[c]);
                k += 1;
            }
        }
    }
    // phase: the reference's progress, 0 at its first frame, 1 from its end on
    let info = &r.info[ts.cursor.ref_id as usize];
    let phase = (st.step as f32 * ts.cursor.speed / (info.n_frames.max(2) - 1) as f32).min(1.0);
    put_obs(o, k, phase, phase);
    k += 1;
    if tc.kind == KIND_RESIDUAL_TASK {
        for c in 0..tc.n_res as usize {
            let lim = if c < 3 {
                tc.res_clamp_wrist_pos
            } else if c < 6 {
                tc.res_clamp_wrist_rot
            } else {
                tc.res_clamp_tips
            };
            let v = ts.res_delta[c] / lim.max(1e-9);
            put_obs(o, k, v, v);
            k += 1;
        }
    }
    k
}

/// The actor's (noisy) view of the state that the reference observations are relative to.
#[derive(Clone, Copy)]
pub struct NoisyState {
    pub wrist: Vec3,
    pub obj: Vec3,
    pub obj_rot: Vec4,
    /// Actuated joints in `TaskGlobals::actuated` order.
    pub q: [f32; MAX_JOINTS],
    pub tips: [Vec3; MAX_TIPS],
}

/// Observes one env (initialising its task state first when it was just reset: `reset_req` ≠ 0 or
/// `ts.done`; reference kinds may then move the hand and object, see [`task_init`]), writing its
/// actor row `obs` and critic row `privo`.
#[allow(clippy::too_many_arguments)]
pub fn task_observe(env: u32, st: &mut EnvState, p: &EnvParams, ts: &mut TaskState, reset_req: u32, m: &Model, tc: &TaskGlobals, r: &RefModel, obs: &mut [f32], privo: &mut [f32]) {
    if reset_req != 0 || ts.done != 0 {
        *ts = task_init(env, st, m, tc, r);
    }
    let st: &EnvState = st;
    let mut s = Scratch::default();
    hand_kinematics(st, m, &mut s);
    let mut o = ObsOut { seed: m.g.seed, env, episode: st.episode, step: st.step, obs, privo };
    let mut ns = NoisyState { wrist: Vec3::ZERO, obj: Vec3::ZERO, obj_rot: Vec4::W, q: [0.0; MAX_JOINTS], tips: [Vec3::ZERO; MAX_TIPS] };
    let mut k = 0u32;
    for i in 0..tc.n_actuated {
        let v = st.q[actuated_joint(tc, i)];
        let nv = noisy(&o, k, v, tc.noise_joint_pos);
        ns.q[i as usize] = nv;
        put_obs(&mut o, k, v, nv);
        k += 1;
    }
    for i in 0..tc.n_actuated {
        let v = st.qd[actuated_joint(tc, i)];
        let nv = noisy(&o, k, v, tc.noise_joint_vel);
        put_obs(&mut o, k, v, nv);
        k += 1;
    }
    for i in 0..tc.n_act as usize {
        put_obs(&mut o, k, ts.prev_action[i], ts.prev_action[i]);
        k += 1;
    }
    let wp = v3(st.wrist_pos);
    let mut wn = wp;
    for c in 0..3 {
        wn[c] = noisy(&o, k, wp[c], tc.noise_hand_pos);
        put_obs(&mut o, k, wp[c], wn[c]);
        k += 1;
    }
    for c in 0..4 {
        put_obs(&mut o, k, st.wrist_rot[c], st.wrist_rot[c]);
        k += 1;
    }
    for t in 0..m.g.n_tips as usize {
        let tp = tip_position(m, &s, t);
        let mut tn = tp;
        for c in 0..3 {
            tn[c] = noisy(&o, k, tp[c], tc.noise_hand_pos);
            put_obs(&mut o, k, tp[c], tn[c]);
            k += 1;
        }
        ns.tips[t] = tn;
    }
    let op = v3(st.obj_pos);
    let mut on = op;
    for c in 0..3 {
        on[c] = noisy(&o, k, op[c], tc.noise_object_pos);
        put_obs(&mut o, k, op[c], on[c]);
        k += 1;
    }
    let oq = Vec4::from_array(st.obj_rot);
    let mut qn = oq;
    for c in 0..4 {
        qn[c] = noisy(&o, k + c as u32, oq[c], tc.noise_object_rot);
    }
    if tc.noise_object_rot > 0.0 {
        qn = quat_normalize(qn);
    }
    for c in 0..4 {
        put_obs(&mut o, k, oq[c], qn[c]);
        k += 1;
    }
    if tc.kind == KIND_LIFT {
        // goal: the rest position raised by the success height
        let goal = Vec3::new(ts.rest_pos[0], ts.rest_pos[1], ts.rest_pos[2] + tc.success_height);
        for c in 0..3 {
            put_obs(&mut o, k, goal[c], goal[c]);
            k += 1;
        }
        // p_obj − p_palm (the actor's from the noisy object and wrist positions)
        let wrot = Vec4::from_array(st.wrist_rot);
        let rel = op - palm_position(tc, wp, wrot);
        let rel_n = on - palm_position(tc, wn, wrot);
        for c in 0..3 {
            put_obs(&mut o, k, rel[c], rel_n[c]);
            k += 1;
        }
    } else {
        ns.wrist = wn;
        ns.obj = on;
        ns.obj_rot = qn;
        k = observe_reference(&mut o, k, st, ts, &s, &ns, m, tc, r);
    }
    // privileged extras
    for v in [st.obj_vel, st.obj_angvel, st.wrist_vel, st.wrist_angvel] {
        for &x in &v[..3] {
            put_priv(&mut o, k, x);
            k += 1;
        }
    }
    for t in 0..m.g.n_tips as usize {
        put_priv(&mut o, k, if ts.tip_force[t] > tc.contact_force { 1.0 } else { 0.0 });
        k += 1;
    }
    for t in 0..m.g.n_tips as usize {
        put_priv(&mut o, k, ts.tip_force[t]);
        k += 1;
    }
    put_priv(&mut o, k, p.obj_inertia[3]);
    put_priv(&mut o, k + 1, p.obj_friction);
    put_priv(&mut o, k + 2, p.obj_scale);
}

// ---------------------------------------------------------------------------------------------
// The CPU backend
// ---------------------------------------------------------------------------------------------

/// The reference layer's view of a task's bank (an empty one for the lift task).
pub fn ref_model<'a>(model: &'a SimModel, bank: Option<&'a RefBank>, rg: &'a RefGlobals) -> RefModel<'a> {
    match bank {
        Some(b) => RefModel::new(model, b, rg),
        None => RefModel { g: &model.globals, joints: &model.joints, rg, info: &[], frames: &[] },
    }
}

/// The task on the CPU: a [`CpuEnvBatch`] and the twins above, rayon over envs, in the GPU's order.
pub struct CpuTaskBatch {
    env: CpuEnvBatch,
    spec: TaskSpec,
    tc: TaskGlobals,
    bank: Option<RefBank>,
    rg: RefGlobals,
    task: Vec<TaskState>,
    targets: Vec<Targets>,
    /// `[N, OUT_MISC]` output records of the last step.
    misc: Vec<f32>,
    /// Reset request per env (the GPU's reset_mask).
    mask: Vec<u32>,
    mask_bool: Vec<bool>,
    batch: StepBatch,
}

impl CpuTaskBatch {
    /// Builds the env batch and the task, with every env at the start of episode 0 (`reset_all`
    /// returns the first observations).
    pub fn new(cfg: &Config, model: SimModel) -> Result<CpuTaskBatch> {
        let TaskSetup { spec, tc, bank, rg } = task_setup(cfg, &model)?;
        let n = spec.num_envs;
        let targets = vec![model.default_targets(); n];
        let batch = StepBatch::new(&spec);
        let mut b = CpuTaskBatch {
            env: CpuEnvBatch::new(model),
            spec,
            tc,
            bank,
            rg,
            task: vec![TaskState::default(); n],
            targets,
            misc: vec![0.0; n * OUT_MISC],
            mask: vec![0; n],
            mask_bool: vec![false; n],
            batch,
        };
        b.reset_all()?;
        Ok(b)
    }

    /// The task constants (as uploaded to the GPU by the GPU backend).
    pub fn task_globals(&self) -> &TaskGlobals {
        &self.tc
    }

    /// The per-env task states.
    pub fn task_states(&self) -> &[TaskState] {
        &self.task
    }

    /// The reference bank (reference kinds).
    pub fn bank(&self) -> Option<&RefBank> {
        self.bank.as_ref()
    }

    /// Reference kinds: env `env`'s (augmented) reference at env step `step + k` of its episode.
    pub fn reference_frame(&self, env: usize, step: u32, k: u32) -> Option<RefFrame> {
        let bank = self.bank.as_ref()?;
        let r = RefModel::new(self.env.model(), bank, &self.rg);
        Some(ref_sample(&r, &self.task[env].cursor, step, k))
    }

    /// `task_observe` for every env with reset requests `self.mask`.
    fn observe(&mut self) {
        let (model, states, params) = self.env.parts_mut();
        let m = model.view();
        let r = ref_model(model, self.bank.as_ref(), &self.rg);
        let tc = &self.tc;
        let mask = &self.mask;
        let (od, pd) = (self.spec.obs_dim, self.spec.priv_dim);
        self.task
            .par_iter_mut()
            .zip(states.par_iter_mut())
            .zip(self.batch.obs.par_chunks_mut(od))
            .zip(self.batch.priv_obs.par_chunks_mut(pd))
            .enumerate()
            .for_each(|(i, (((ts, st), obs), privo))| task_observe(i as u32, st, &params[i], ts, mask[i], &m, tc, &r, obs, privo));
    }
}

impl TaskBatch for CpuTaskBatch {
    fn spec(&self) -> &TaskSpec {
        &self.spec
    }

    fn backend_name(&self) -> String {
        self.env.backend_name()
    }

    fn env(&mut self) -> &mut dyn EnvBatch {
        &mut self.env
    }

    fn gpu_context(&self) -> Option<&crate::env::gpu::GpuContext> {
        None
    }

    fn reset_all(&mut self) -> Result<&StepBatch> {
        self.env.reset_all()?;
        // the GPU's reset_mask after reset_all: 2 (episode 0) everywhere
        self.mask.fill(2);
        self.observe();
        self.batch.clear_misc();
        Ok(&self.batch)
    }

    fn step(&mut self, actions: &[f32]) -> Result<&StepBatch> {
        check_actions(&self.spec, actions)?;
        let na = self.spec.action_dim;
        {
            let model = self.env.model();
            let m = model.view();
            let r = ref_model(model, self.bank.as_ref(), &self.rg);
            let tc = &self.tc;
            let states = self.env.states_ref();
            self.task
                .par_iter_mut()
                .zip(self.targets.par_iter_mut())
                .zip(actions.par_chunks(na))
                .enumerate()
                .for_each(|(i, ((ts, t), a))| *t = task_act(a, &states[i], ts, &m, tc, &r));
        }
        self.env.step(&self.targets)?;
        {
            let model = self.env.model();
            let m = model.view();
            let r = ref_model(model, self.bank.as_ref(), &self.rg);
            let tc = &self.tc;
            let (states, params, stats) = (self.env.states_ref(), self.env.params_ref(), self.env.stats_ref());
            self.task
                .par_iter_mut()
                .zip(self.misc.par_chunks_mut(OUT_MISC))
                .zip(self.mask.par_iter_mut())
                .enumerate()
                .for_each(|(i, ((ts, out), mask))| *mask = task_reward(&states[i], &params[i], &stats[i], ts, &m, tc, &r, out));
        }
        for (b, &m) in self.mask_bool.iter_mut().zip(&self.mask) {
            *b = m != 0;
        }
        if self.mask_bool.iter().any(|&b| b) {
            self.env.reset(&self.mask_bool)?;
        }
        self.observe();
        self.batch.fill_misc(&self.misc);
        Ok(&self.batch)
    }

    fn targets(&mut self) -> Result<Vec<Targets>> {
        Ok(self.task.iter().map(|t| t.targets).collect())
    }

    fn reference_now(&mut self, env: usize) -> Result<Option<RefFrame>> {
        let step = self.env.states_ref()[env].step;
        Ok(self.reference_frame(env, step, 0))
    }

    fn save_state(&mut self) -> Result<Vec<u8>> {
        Ok(encode_snapshot(self.env.states_ref(), self.env.params_ref(), &self.task))
    }

    fn load_state(&mut self, state: &[u8]) -> Result<()> {
        let (states, params, task) = decode_snapshot(state, self.spec.num_envs)?;
        self.env.set_states(&states)?;
        self.env.set_params(&params)?;
        self.task.copy_from_slice(&task);
        Ok(())
    }
}
