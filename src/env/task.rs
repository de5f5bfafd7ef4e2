//! The task layer: the lift task (DESIGN §5) on top of an [`EnvBatch`], on both backends.
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
use glam::{Vec3, Vec4};
use rayon::prelude::*;

use super::common::{quat_error, quat_from_axis_angle, quat_mul, quat_normalize, quat_rotate, rand_uniform};
use super::cpu::CpuEnvBatch;
use super::layout::*;
use super::physics::{Model, Scratch, hand_kinematics};
use super::{EnvBatch, SimModel};
use crate::config::{Config, LIFT_TERMS};
use crate::hand::MAX_JOINTS;

/// RNG purpose of the observation noise (keep in sync with task.wgsl; reset.rs uses 1 and 2).
pub const PURPOSE_OBS_NOISE: u32 = 3;
/// Noise draws of one env step: draw k of obs entry i at step s has key s · OBS_KEY_STRIDE + 2i + k.
pub const OBS_KEY_STRIDE: u32 = 4096;
/// Number of reward terms (`config::LIFT_TERMS`).
pub const N_TERMS: usize = 6;
/// Offsets in the per-env output record (after the obs and priv obs sections of the GPU's output
/// buffer; keep in sync with task.wgsl `OUT_*`): reward, the weighted terms, terminated, time_out,
/// success, lift height, max hand–object penetration; `OUT_MISC` floats in all.
pub const OUT_REWARD: usize = 0;
pub const OUT_TERMS: usize = 1;
pub const OUT_TERMINATED: usize = 7;
pub const OUT_TIME_OUT: usize = 8;
pub const OUT_SUCCESS: usize = 9;
pub const OUT_LIFT: usize = 10;
pub const OUT_MAX_PEN: usize = 11;
pub const OUT_MISC: usize = 12;

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
}

impl StepBatch {
    /// A zeroed batch for `spec`.
    pub fn new(spec: &TaskSpec) -> StepBatch {
        let n = spec.num_envs;
        StepBatch {
            obs: vec![0.0; n * spec.obs_dim],
            priv_obs: vec![0.0; n * spec.priv_dim],
            reward: vec![0.0; n],
            terms: vec![0.0; n * N_TERMS],
            terminated: vec![false; n],
            time_out: vec![false; n],
            success: vec![false; n],
            lift_height: vec![0.0; n],
            max_pen: vec![0.0; n],
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
            self.terms[i * N_TERMS..(i + 1) * N_TERMS].copy_from_slice(&r[OUT_TERMS..OUT_TERMS + N_TERMS]);
            self.terminated[i] = r[OUT_TERMINATED] != 0.0;
            self.time_out[i] = r[OUT_TIME_OUT] != 0.0;
            self.success[i] = r[OUT_SUCCESS] != 0.0;
            self.lift_height[i] = r[OUT_LIFT];
            self.max_pen[i] = r[OUT_MAX_PEN];
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

/// The task's spec and constants from the config's `[task]` and the hand (both backends).
pub fn task_setup(cfg: &Config, model: &SimModel) -> Result<(TaskSpec, TaskGlobals)> {
    let file = cfg.source.display();
    let t = &cfg.task;
    let es = &model.spec;
    let hand = model.hand.source.display();
    let joint_names = &es.joint_names;
    let tips = &es.tip_names;
    let n_actuated = es.actuated.len();
    let action_dim = 6 + n_actuated;
    if action_dim > MAX_ACTIONS || n_actuated > MAX_JOINTS {
        bail!(
            "{file}: the hand {hand} has {n_actuated} actuated joints, so the lift task would have {action_dim} actions; at most {MAX_ACTIONS} (MAX_ACTIONS) are supported"
        );
    }
    if tips.is_empty() {
        bail!("{file}: the lift task needs fingertips, but the hand {hand} has none: name them in `hand.fingertips`");
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
        if !LIFT_TERMS.contains(&name.as_str()) {
            bail!("{file}: key `task.rewards.{name}`: expected a term of the lift task: {}", LIFT_TERMS.join(", "));
        }
    }

    let xyz = ["x", "y", "z"];
    let quat = ["qx", "qy", "qz", "qw"];
    let mut action_names: Vec<String> = ["wrist_dx", "wrist_dy", "wrist_dz", "wrist_rx", "wrist_ry", "wrist_rz"].iter().map(|s| s.to_string()).collect();
    action_names.extend(es.actuated.iter().map(|&j| format!("q.{}", joint_names[j])));
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
    obs_names.extend(xyz.iter().map(|c| format!("goal.{c}")));
    obs_names.extend(xyz.iter().map(|c| format!("obj_rel.{c}")));
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
    for (k, name) in LIFT_TERMS.iter().enumerate() {
        weights[k / 4][k % 4] = t.rewards.get(*name).copied().unwrap_or(0.0);
    }
    let mut actuated = [[0u32; 4]; MAX_JOINTS / 4];
    for (i, &j) in es.actuated.iter().enumerate() {
        actuated[i / 4][i % 4] = j as u32;
    }
    let a = &t.action;
    let l = &t.lift;
    let n = &t.obs_noise;
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
    };
    let spec = TaskSpec {
        num_envs: es.num_envs,
        obs_dim,
        priv_dim,
        action_dim,
        obs_names,
        priv_names,
        action_names,
        term_names: LIFT_TERMS.iter().map(|s| s.to_string()).collect(),
        episode_length: t.episode_length,
        control_dt: es.dt * es.decimation as f32,
    };
    Ok((spec, tc))
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

fn v3(a: [f32; 4]) -> Vec3 {
    Vec3::new(a[0], a[1], a[2])
}

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

/// exp(rv) ⊗ rot, then at most `wrist_rot_limit` from the initial orientation: exp(e·limit/|e|) ⊗ init.
pub fn wrist_rot_target(g: &Globals, tc: &TaskGlobals, rot: Vec4, rv: Vec3) -> Vec4 {
    let mut r = rot;
    let angle = rv.length();
    if angle > 1e-9 {
        r = quat_normalize(quat_mul(quat_from_axis_angle(rv / angle, angle), rot));
    }
    let init = Vec4::from_array(g.init_wrist_rot);
    let e = quat_error(r, init);
    let d = e.length();
    if d > tc.wrist_rot_limit {
        r = quat_normalize(quat_mul(quat_from_axis_angle(e / d, tc.wrist_rot_limit), init));
    }
    r
}

/// Maps one env's actions (`[n_act]`, clipped here) to its targets; records the action terms and the
/// action in `ts`. Returns the targets the physics steps toward.
pub fn task_act(actions: &[f32], ts: &mut TaskState, m: &Model, tc: &TaskGlobals) -> Targets {
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

/// Reward terms, terminated and time-out of one env on its post-step state; writes the env's output
/// record `out` (`[OUT_MISC]`) and the step's fingertip forces and done flag into `ts`. Returns the
/// env's reset request (1 = reset to the next episode; a bad-state env was reset by the physics).
pub fn task_reward(st: &EnvState, stats: &StepStats, ts: &mut TaskState, m: &Model, tc: &TaskGlobals, out: &mut [f32]) -> u32 {
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
    let mut raw = [0.0f32; N_TERMS];
    // reaching 1 − tanh(α d) (tanh saturates at 20: some GPUs' tanh overflows beyond)
    raw[0] = 1.0 - (tc.reach_alpha * dist).min(20.0).tanh();
    // lifting: h in cm, capped at the success height
    raw[1] = h.max(0.0).min(tc.success_height) * 100.0;
    raw[2] = if thumb && other { 1.0 } else { 0.0 };
    raw[3] = if h >= tc.success_height { 1.0 } else { 0.0 };
    raw[4] = ts.act_rate;
    raw[5] = ts.act_mag;
    let mut lift = h;
    if bad {
        // the physics already reset this env: its state says nothing about the step
        raw[0] = 0.0;
        raw[1] = 0.0;
        raw[2] = 0.0;
        raw[3] = 0.0;
        lift = 0.0;
    }
    let mut terminated = bad || obj.z < tc.drop_height || obj.x.abs() > tc.table_half_extent || obj.y.abs() > tc.table_half_extent;
    terminated = terminated || dist > tc.max_hand_distance;
    let time_out = !terminated && st.step >= tc.episode_length;
    let mut reward = 0.0f32;
    for k in 0..N_TERMS {
        // term_k = w_k · raw_k, reward = Σ_k term_k
        let wk = tc.weights[k / 4][k % 4] * raw[k];
        out[OUT_TERMS + k] = wk;
        reward += wk;
    }
    out[OUT_REWARD] = reward;
    out[OUT_TERMINATED] = if terminated { 1.0 } else { 0.0 };
    out[OUT_TIME_OUT] = if time_out { 1.0 } else { 0.0 };
    out[OUT_SUCCESS] = raw[3];
    out[OUT_LIFT] = lift;
    out[OUT_MAX_PEN] = stats.max_pen_ho;
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
/// position of the object.
pub fn task_init(st: &EnvState, m: &Model) -> TaskState {
    let mut ts = TaskState::default();
    ts.targets.wrist_pos = m.g.init_wrist_pos;
    ts.targets.wrist_rot = m.g.init_wrist_rot;
    for j in 0..m.g.n_joints as usize {
        ts.targets.q[j] = m.joints[j].default_q;
    }
    ts.rest_pos = [st.obj_pos[0], st.obj_pos[1], st.obj_pos[2], 0.0];
    ts
}

/// Observes one env (initialising its task state first when it was just reset: `reset_req` ≠ 0 or
/// `ts.done`), writing its actor row `obs` and critic row `privo`.
#[allow(clippy::too_many_arguments)]
pub fn task_observe(env: u32, st: &EnvState, p: &EnvParams, ts: &mut TaskState, reset_req: u32, m: &Model, tc: &TaskGlobals, obs: &mut [f32], privo: &mut [f32]) {
    if reset_req != 0 || ts.done != 0 {
        *ts = task_init(st, m);
    }
    let mut s = Scratch::default();
    hand_kinematics(st, m, &mut s);
    let mut o = ObsOut { seed: m.g.seed, env, episode: st.episode, step: st.step, obs, privo };
    let mut k = 0u32;
    for i in 0..tc.n_actuated {
        let v = st.q[actuated_joint(tc, i)];
        let nv = noisy(&o, k, v, tc.noise_joint_pos);
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
        for c in 0..3 {
            let nv = noisy(&o, k, tp[c], tc.noise_hand_pos);
            put_obs(&mut o, k, tp[c], nv);
            k += 1;
        }
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

/// The task on the CPU: a [`CpuEnvBatch`] and the twins above, rayon over envs, in the GPU's order.
pub struct CpuTaskBatch {
    env: CpuEnvBatch,
    spec: TaskSpec,
    tc: TaskGlobals,
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
        let (spec, tc) = task_setup(cfg, &model)?;
        let n = spec.num_envs;
        let targets = vec![model.default_targets(); n];
        let batch = StepBatch::new(&spec);
        let mut b = CpuTaskBatch {
            env: CpuEnvBatch::new(model),
            spec,
            tc,
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

    /// `task_observe` for every env with reset requests `self.mask`.
    fn observe(&mut self) {
        let model = self.env.model();
        let m = model.view();
        let tc = &self.tc;
        let (od, pd) = (self.spec.obs_dim, self.spec.priv_dim);
        let (states, params) = (self.env.states_ref(), self.env.params_ref());
        self.task
            .par_iter_mut()
            .zip(self.batch.obs.par_chunks_mut(od))
            .zip(self.batch.priv_obs.par_chunks_mut(pd))
            .enumerate()
            .for_each(|(i, ((ts, obs), privo))| task_observe(i as u32, &states[i], &params[i], ts, self.mask[i], &m, tc, obs, privo));
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
            let m = self.env.model().view();
            let tc = &self.tc;
            self.task
                .par_iter_mut()
                .zip(self.targets.par_iter_mut())
                .zip(actions.par_chunks(na))
                .for_each(|((ts, t), a)| *t = task_act(a, ts, &m, tc));
        }
        self.env.step(&self.targets)?;
        {
            let m = self.env.model().view();
            let tc = &self.tc;
            let (states, stats) = (self.env.states_ref(), self.env.stats_ref());
            self.task
                .par_iter_mut()
                .zip(self.misc.par_chunks_mut(OUT_MISC))
                .zip(self.mask.par_iter_mut())
                .enumerate()
                .for_each(|(i, ((ts, out), mask))| *mask = task_reward(&states[i], &stats[i], ts, &m, tc, out));
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
