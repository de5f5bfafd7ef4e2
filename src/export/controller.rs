//! A robot's controller built from an export alone: `policy.json` and `policy.onnx`. It assembles
//! the model's inputs from observation fields by name, keeps the history window, runs the ONNX
//! model (tract) and turns its output into wrist and joint targets with the constants and
//! formulas of `action_mapping` — what a robot's control loop does. `dextrain play` drives the
//! simulator with it; nothing here reads a checkpoint or the learner's settings.
//!
//! What the controller takes from the simulator is what a robot has: the measured observation
//! fields (by name), the reference the deployment follows (reference kinds: its frame at the end
//! of the step, which the mapping adds to), and the hand's URDF (its kinematics, for
//! residual_task's fingertip IK; its hash must be the contract's). Its own memory — the previous
//! action, residual_task's smoothed and integrated residual, the delta-mode targets and the
//! history window — it keeps itself, and it writes the `prev_action` and `residual` fields of the
//! model's input from that memory, as a robot must.

use anyhow::{Context, Result, ensure};
use glam::{Vec3, Vec4};

use super::contract::{ActionMapping, FieldContract, PolicyContract, StartTargets};
use super::onnx::OnnxRunner;
use crate::config::FingerMode;
use crate::env::SimModel;
use crate::env::common::{quat_error, quat_from_axis_angle, quat_mul, quat_normalize};
use crate::gpu::layout::Targets;
use crate::task::ik::{IkParams, IkScratch, ik_solve, ik_tip_positions};
use crate::task::reference::RefFrame;
use crate::hand::MAX_TIPS;
use crate::task::TaskSpec;
use crate::task::spec::ObsSlot;

/// The fields of the model's input that the controller computes from its own memory.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Own {
    /// `prev_action`: the previous step's clipped actions (0 at episode start).
    PrevAction,
    /// `residual`: residual_task's Δa over its clamps.
    Residual,
}

/// Where one input field's numbers come from in the simulator's observation row, or which of the
/// controller's own quantities fills it.
#[derive(Clone, Debug)]
struct Gather {
    /// First index in the simulator's row (actor or critic observation).
    from: usize,
    size: usize,
    own: Option<Own>,
}

/// One joint as the contract describes it.
#[derive(Clone, Debug)]
struct Joint {
    lower: Option<f32>,
    upper: Option<f32>,
    default: f32,
}

/// The controller's memory of one env (reset at each episode start).
#[derive(Clone, Debug)]
struct Memory {
    prev_action: Vec<f32>,
    targets: Targets,
    /// residual_task: ũ and Δa.
    ema: Vec<f32>,
    delta: Vec<f32>,
}

/// A controller for `n` envs, bound to a simulated world (see the module documentation).
pub struct Controller {
    pub contract: PolicyContract,
    runner: OnnxRunner,
    n: usize,
    /// The simulator's actor and critic observation sizes.
    obs_dim: usize,
    priv_dim: usize,
    obs: Vec<Gather>,
    privileged: Vec<Gather>,
    history: Vec<Gather>,
    /// H and D of the history window, and the windows `[n, H, D]`, oldest first.
    hist_len: usize,
    hist_dim: usize,
    window: Vec<f32>,
    joints: Vec<Joint>,
    /// Joint index (URDF order) of each actuated joint, in action order.
    actuated: Vec<usize>,
    memory: Vec<Memory>,
    /// The hand model (residual_task's IK).
    model: SimModel,
    ik: IkParams,
}

/// The indices of the contract's fields in the simulator's layout: same names, same entries.
fn gather(fields: &[FieldContract], layout: &[ObsSlot], what: &str, own_ok: bool) -> Result<Vec<Gather>> {
    fields
        .iter()
        .map(|f| {
            let slot = layout.iter().find(|s| s.name == f.name).with_context(|| format!("field `{what}`: {:?} is not an observation of this world", f.name))?;
            ensure!(slot.entries == f.entries, "field `{what}` ({:?}): entries {:?}, but the world's are {:?}", f.name, f.entries, slot.entries);
            let own = match f.name.as_str() {
                "prev_action" if own_ok => Some(Own::PrevAction),
                "residual" if own_ok => Some(Own::Residual),
                _ => None,
            };
            Ok(Gather { from: slot.offset, size: slot.size, own })
        })
        .collect()
}

/// Copies one input row: each field from the simulator's row, or from the controller's memory.
fn fill(out: &mut Vec<f32>, fields: &[Gather], row: &[f32], mem: &Memory, clamps: &[f32]) {
    for g in fields {
        match g.own {
            None => out.extend_from_slice(&row[g.from..g.from + g.size]),
            Some(Own::PrevAction) => out.extend_from_slice(&mem.prev_action),
            // Δa_c / max(clamp_c, 1e-9)
            Some(Own::Residual) => out.extend(mem.delta.iter().zip(clamps).map(|(d, c)| d / c.max(1e-9))),
        }
    }
}

impl Controller {
    /// Reads the export `contract_path` (`policy.json`, the ONNX file beside it, its hash checked)
    /// and binds it to the world `spec`/`model` for `n` envs: every field, joint and action must
    /// be the world's, and the hand's URDF must be the one the contract names.
    pub fn load(contract_path: &std::path::Path, urdf_bytes: &[u8], spec: &TaskSpec, model: &SimModel, n: usize) -> Result<Controller> {
        let c = PolicyContract::read(contract_path)?;
        let file = contract_path.display();
        let dir = contract_path.parent().unwrap_or(std::path::Path::new("."));
        let onnx_path = dir.join(&c.model.file);
        let bytes = std::fs::read(&onnx_path).with_context(|| format!("cannot read the policy model {} (field `model.file` of {file})", onnx_path.display()))?;
        let hash = super::contract::hex(crate::learn::checkpoint::xxh64(&bytes, 0));
        ensure!(hash == c.model.xxh64, "{}: XXH64 {hash}, but field `model.xxh64` of {file} says {}: the model is not the one the contract describes", onnx_path.display(), c.model.xxh64);
        let urdf_hash = super::contract::hex(crate::learn::checkpoint::xxh64(urdf_bytes, 0));
        ensure!(urdf_hash == c.hand.urdf_xxh64, "{file}: field `hand.urdf_xxh64` is {}, but this world's hand URDF hashes to {urdf_hash}: another hand", c.hand.urdf_xxh64);
        ensure!(c.task.kind == spec.kind, "{file}: field `task.kind` is {}, this world's task is {}", c.task.kind, spec.kind);
        ensure!(c.actions.names == spec.action_names, "{file}: field `actions.names` differs from this world's actions ({})", spec.action_names.join(", "));
        ensure!(c.control.control_dt == spec.control_dt, "{file}: field `control.control_dt` is {} s, this world steps {} s", c.control.control_dt, spec.control_dt);
        let names: Vec<&str> = model.hand.joints.iter().map(|j| j.name.as_str()).collect();
        let theirs: Vec<&str> = c.hand.joints.iter().map(|j| j.name.as_str()).collect();
        ensure!(names == theirs, "{file}: field `hand.joints` names {theirs:?}, this world's hand has {names:?}");
        let actuated = c
            .hand
            .actuated
            .iter()
            .map(|a| c.hand.joints.iter().position(|j| &j.name == a).with_context(|| format!("{file}: field `hand.actuated`: no joint {a:?}")))
            .collect::<Result<Vec<usize>>>()?;
        let joints = c.hand.joints.iter().map(|j| Joint { lower: j.lower, upper: j.upper, default: j.default }).collect();
        let with_file = |r: Result<Vec<Gather>>| r.with_context(|| file.to_string());
        let obs = with_file(gather(&c.observation.fields, &spec.obs_layout, "observation.fields", true))?;
        let privileged = match &c.privileged {
            Some(l) => with_file(gather(&l.fields, &spec.priv_layout, "privileged.fields", false))?,
            None => Vec::new(),
        };
        let (history, hist_len, hist_dim) = match &c.history {
            Some(h) => (with_file(gather(&h.step.fields, &spec.obs_layout, "history.step.fields", true))?, h.length, h.step.size),
            None => (Vec::new(), 0, 0),
        };
        let ik = match &c.action_mapping {
            ActionMapping::ResidualTask { ik, .. } => {
                // the solver's fixed constants are this build's (src/task/ik.rs): they must be the exporter's
                use crate::task::ik::*;
                let ours = (IK_DAMPING_DIST, IK_DAMPING_FLOOR, IK_DAMPING_CURV, IK_BIAS, IK_LOCK_ROUNDS, IK_ERR_CLAMP);
                let theirs = (ik.damping_dist, ik.damping_floor, ik.damping_curvature, ik.midrange_bias, ik.lock_rounds, ik.residual_clamp);
                ensure!(ours == theirs, "{file}: field `action_mapping.ik`: the solver constants {theirs:?} are not this dextrain's {ours:?}");
                IkParams { iters: ik.iters, damping: ik.damping, max_step: ik.max_step, tol: ik.tol }
            }
            _ => IkParams::default(),
        };
        let inputs = |name: &str| -> Result<usize> {
            Ok(match name {
                "obs" => c.observation.size,
                "priv_obs" => c.privileged.as_ref().map_or(0, |l| l.size),
                _ => hist_len * hist_dim,
            })
        };
        let runner = OnnxRunner::new(&bytes, n.max(1), inputs).with_context(|| onnx_path.display().to_string())?;
        let mut want = vec!["obs"];
        if c.privileged.is_some() {
            want.push("priv_obs");
        }
        if c.history.is_some() {
            want.push("history");
        }
        ensure!(runner.input_names() == want, "{}: inputs {:?}, but {file} describes {want:?}", onnx_path.display(), runner.input_names());
        let mut ctl = Controller {
            runner,
            n,
            obs_dim: spec.obs_dim,
            priv_dim: spec.priv_dim,
            obs,
            privileged,
            history,
            hist_len,
            hist_dim,
            window: vec![0.0; n * hist_len * hist_dim],
            joints,
            actuated,
            memory: Vec::new(),
            model: model.clone(),
            ik,
            contract: c,
        };
        let fresh = ctl.fresh_memory(None);
        ctl.memory = vec![fresh; n];
        Ok(ctl)
    }

    /// The memory at episode start; `first`: the reference's first frame (reference kinds).
    fn fresh_memory(&self, first: Option<&RefFrame>) -> Memory {
        let c = &self.contract;
        let a = c.actions.size;
        let mut targets = Targets::default();
        let h = &c.hand;
        targets.wrist_pos = [h.init_wrist_pos[0], h.init_wrist_pos[1], h.init_wrist_pos[2], 0.0];
        targets.wrist_rot = h.init_wrist_rot;
        for (j, joint) in self.joints.iter().enumerate() {
            targets.q[j] = joint.default;
        }
        if let (ActionMapping::Direct { start: StartTargets::ReferenceFirstFrame, .. }, Some(f)) = (&c.action_mapping, first) {
            targets = Targets { wrist_pos: f.wrist_pos, wrist_rot: f.wrist_rot, q: f.q };
        }
        Memory { prev_action: vec![0.0; a], targets, ema: vec![0.0; a], delta: vec![0.0; a] }
    }

    /// The clamps that `residual` divides by (residual_task), one per action.
    fn residual_clamps(&self) -> Vec<f32> {
        match &self.contract.action_mapping {
            ActionMapping::ResidualTask { clamp_wrist_pos, clamp_wrist_rot, clamp_tips, .. } => {
                (0..self.contract.actions.size).map(|k| if k < 3 { *clamp_wrist_pos } else if k < 6 { *clamp_wrist_rot } else { *clamp_tips }).collect()
            }
            _ => vec![1.0; self.contract.actions.size],
        }
    }

    /// One control step of every env: `obs` `[n, obs_dim]` and `priv_obs` `[n, priv_dim]` as the
    /// simulator observes them, `start[i]`: env i begins an episode at this step, `first`/`next`:
    /// each env's reference frame at its episode's start and at the end of this step (reference
    /// kinds). Returns the actions `[n, A]` (the model's raw output) and the targets.
    pub fn act(&mut self, obs: &[f32], priv_obs: &[f32], start: &[bool], first: Option<&[RefFrame]>, next: Option<&[RefFrame]>) -> Result<(Vec<f32>, Vec<Targets>)> {
        let n = self.n;
        ensure!(obs.len() == n * self.obs_dim && priv_obs.len() == n * self.priv_dim && start.len() == n, "the controller was built for {n} envs");
        for i in 0..n {
            if start[i] {
                self.memory[i] = self.fresh_memory(first.map(|f| &f[i]));
            }
        }
        let clamps = self.residual_clamps();
        let (mut x, mut p) = (Vec::new(), Vec::new());
        let (h, d) = (self.hist_len, self.hist_dim);
        for i in 0..n {
            let row = &obs[i * self.obs_dim..(i + 1) * self.obs_dim];
            fill(&mut x, &self.obs, row, &self.memory[i], &clamps);
            fill(&mut p, &self.privileged, &priv_obs[i * self.priv_dim..(i + 1) * self.priv_dim], &self.memory[i], &clamps);
            if h > 0 {
                // x_t of this step; the window starts as H copies of the episode's first step
                let mut step = Vec::with_capacity(d);
                fill(&mut step, &self.history, row, &self.memory[i], &clamps);
                let w = &mut self.window[i * h * d..(i + 1) * h * d];
                if start[i] {
                    for r in w.chunks_mut(d) {
                        r.copy_from_slice(&step);
                    }
                } else {
                    w.copy_within(d.., 0);
                    w[(h - 1) * d..].copy_from_slice(&step);
                }
            }
        }
        let actions = self.runner.run(&x, &p, &self.window)?;
        let a_dim = self.contract.actions.size;
        ensure!(actions.len() == n * a_dim, "the model gave {} numbers for {n} envs × {a_dim} actions", actions.len());
        let mut targets = Vec::with_capacity(n);
        for i in 0..n {
            let a: Vec<f32> = actions[i * a_dim..(i + 1) * a_dim].iter().map(|v| v.clamp(-1.0, 1.0)).collect();
            let f = next.map(|f| &f[i]);
            targets.push(self.map(i, &a, f)?);
            self.memory[i].prev_action = a;
        }
        Ok((actions, targets))
    }

    /// `action_mapping` for env `i`: clipped actions `a`, the reference frame `f` at the end of the
    /// step (reference mappings).
    fn map(&mut self, i: usize, a: &[f32], f: Option<&RefFrame>) -> Result<Targets> {
        let need_ref = || f.context("the action mapping adds to the reference, but this world has none");
        match self.contract.action_mapping.clone() {
            ActionMapping::Direct { wrist_pos_scale, wrist_pos_min, wrist_pos_max, wrist_rot_scale, wrist_rot_limit, finger_mode, finger_delta_scale, .. } => {
                let mem = &mut self.memory[i];
                let t = &mut mem.targets;
                // p* = clamp(p*_prev + scale · a[0..3], min, max)
                let wp = Vec3::new(t.wrist_pos[0], t.wrist_pos[1], t.wrist_pos[2]) + Vec3::new(a[0], a[1], a[2]) * wrist_pos_scale;
                let wp = wp.max(Vec3::from(wrist_pos_min)).min(Vec3::from(wrist_pos_max));
                t.wrist_pos = [wp.x, wp.y, wp.z, 0.0];
                // R* = exp(scale · a[3..6]) ⊗ R*_prev, at most wrist_rot_limit from R0
                let init = Vec4::from_array(self.contract.hand.init_wrist_rot);
                let mut r = rotate(Vec4::from_array(t.wrist_rot), Vec3::new(a[3], a[4], a[5]) * wrist_rot_scale);
                let e = quat_error(r, init);
                let angle = e.length();
                if angle > wrist_rot_limit {
                    r = quat_normalize(quat_mul(quat_from_axis_angle(e / angle, wrist_rot_limit), init));
                }
                t.wrist_rot = r.to_array();
                for (k, &j) in self.actuated.iter().enumerate() {
                    let joint = &self.joints[j];
                    let ak = a[6 + k];
                    t.q[j] = match (finger_mode, joint.lower, joint.upper) {
                        // lower + (a + 1)/2 · (upper − lower)
                        (FingerMode::Absolute, Some(lo), Some(hi)) => lo + 0.5 * (ak + 1.0) * (hi - lo),
                        // a continuous joint: default + a π
                        (FingerMode::Absolute, _, _) => joint.default + ak * std::f32::consts::PI,
                        (FingerMode::Delta, lo, hi) => clamp_opt(t.q[j] + ak * finger_delta_scale, lo, hi),
                    };
                }
                Ok(*t)
            }
            ActionMapping::ResidualJoint { joint_alpha, wrist_pos_alpha, wrist_rot_alpha, .. } => {
                let f = need_ref()?;
                let mut t = Targets { wrist_pos: f.wrist_pos, wrist_rot: f.wrist_rot, q: f.q };
                let dp = Vec3::new(a[0], a[1], a[2]) * wrist_pos_alpha;
                t.wrist_pos = [f.wrist_pos[0] + dp.x, f.wrist_pos[1] + dp.y, f.wrist_pos[2] + dp.z, 0.0];
                t.wrist_rot = rotate(Vec4::from_array(f.wrist_rot), Vec3::new(a[3], a[4], a[5]) * wrist_rot_alpha).to_array();
                for (k, &j) in self.actuated.iter().enumerate() {
                    let joint = &self.joints[j];
                    t.q[j] = clamp_opt(f.q[j] + a[6 + k] * joint_alpha, joint.lower, joint.upper);
                }
                self.memory[i].targets = t;
                Ok(t)
            }
            ActionMapping::ResidualTask { ema, scale_wrist_pos, scale_wrist_rot, scale_tips, clamp_wrist_pos, clamp_wrist_rot, clamp_tips, dt, .. } => {
                let f = need_ref()?;
                let mem = &mut self.memory[i];
                let mut tips_moved = false;
                for c in 0..a.len() {
                    // ũ = ema·a + (1 − ema)·ũ
                    mem.ema[c] = ema * a[c] + (1.0 - ema) * mem.ema[c];
                    let (s, lim) = if c < 3 {
                        (scale_wrist_pos, clamp_wrist_pos)
                    } else if c < 6 {
                        (scale_wrist_rot, clamp_wrist_rot)
                    } else {
                        (scale_tips, clamp_tips)
                    };
                    // Δa = clamp(Δa + s ũ dt, −clamp, clamp)
                    mem.delta[c] = (mem.delta[c] + s * mem.ema[c] * dt).max(-lim).min(lim);
                    tips_moved |= c >= 6 && mem.delta[c] != 0.0;
                }
                let d = &mem.delta;
                let mut t = Targets { wrist_pos: f.wrist_pos, wrist_rot: f.wrist_rot, q: f.q };
                t.wrist_pos = [f.wrist_pos[0] + d[0], f.wrist_pos[1] + d[1], f.wrist_pos[2] + d[2], 0.0];
                t.wrist_rot = rotate(Vec4::from_array(f.wrist_rot), Vec3::new(d[3], d[4], d[5])).to_array();
                if tips_moved {
                    // fingertip goals FK(q̄) + Δa_tip (wrist frame), IK seeded at q̄
                    let m = self.model.view();
                    let n_tips = self.contract.hand.fingertips.len();
                    ensure!(n_tips <= MAX_TIPS && a.len() == 6 + 3 * n_tips, "the actions do not hold 3 per fingertip");
                    let mut s = IkScratch::default();
                    let base = ik_tip_positions(&m, &f.q, &mut s);
                    let mut goal = [Vec3::ZERO; MAX_TIPS];
                    for k in 0..n_tips {
                        goal[k] = base[k] + Vec3::new(d[6 + 3 * k], d[7 + 3 * k], d[8 + 3 * k]);
                    }
                    t.q = ik_solve(&m, &f.q, &goal, (1u32 << n_tips) - 1, &self.ik);
                }
                mem.targets = t;
                Ok(t)
            }
        }
    }
}

/// exp(rv) ⊗ q, normalised; q itself below 1e-9 rad.
fn rotate(q: Vec4, rv: Vec3) -> Vec4 {
    let angle = rv.length();
    if angle > 1e-9 {
        return quat_normalize(quat_mul(quat_from_axis_angle(rv / angle, angle), q));
    }
    q
}

/// clamp(v, lower, upper) for the limits a joint has (max then min, as the simulator clamps).
fn clamp_opt(v: f32, lower: Option<f32>, upper: Option<f32>) -> f32 {
    let v = lower.map_or(v, |lo| v.max(lo));
    upper.map_or(v, |hi| v.min(hi))
}
