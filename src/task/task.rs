//! The CPU twin of `shaders/task.wgsl`: the same constants, the same function names in the same
//! order, the same arithmetic (tests/suite/shaders.rs checks the order and the constants,
//! tests/suite/task.rs and track.rs the results on both backends). What the functions compute is
//! documented in [`super`] (the lift task) and on each function (the reference kinds).

use glam::{Vec2, Vec3, Vec4};

use super::spec::{LIFT_TERMS, RESIDUAL_JOINT_TERMS, RESIDUAL_TASK_TERMS, TRACK_TERMS, term_index};
use crate::config::TaskKind;
use crate::env::common::{quat_error, quat_from_axis_angle, quat_mul, quat_normalize, quat_rotate, rand_uniform};
use crate::gpu::layout::*;
use super::layout::*;
use crate::task::ik::{IkScratch, ik_solve, ik_tip_positions};
use crate::env::physics::{Model, Scratch, hand_kinematics, v3};
use crate::task::reference::{RefFrame, RefModel, ref_begin, ref_object_end, ref_object_start, ref_sample};
use crate::hand::{MAX_JOINTS, MAX_TIPS};

/// RNG purpose of the observation noise (keep in sync with task.wgsl; reset.rs uses 1 and 2).
pub const PURPOSE_OBS_NOISE: u32 = 3;
/// RNG purpose of the object-pose latency draw (reference.rs uses 4).
pub const PURPOSE_OBJ_DELAY: u32 = 5;
/// Noise draws of one env step: draw k of obs entry i at step s has key s · OBS_KEY_STRIDE + 2i + k.
pub const OBS_KEY_STRIDE: u32 = 4096;
/// Task kinds (`TaskGlobals::kind`; keep in sync with task.wgsl).
pub const KIND_LIFT: u32 = TaskKind::Lift as u32;
pub const KIND_TRACK: u32 = TaskKind::Track as u32;
pub const KIND_RESIDUAL_JOINT: u32 = TaskKind::ResidualJoint as u32;
pub const KIND_RESIDUAL_TASK: u32 = TaskKind::ResidualTask as u32;
/// Most reward terms of a kind (the output record's term slots).
pub const MAX_TERMS: usize = 12;
/// The slot of each reward term in its kind's output: the position of its name in the tables of
/// [`super::spec`] (task.wgsl's `T_*` constants; tests/suite/shaders.rs checks them).
pub const T_LIFT_REACHING: usize = term_index(&LIFT_TERMS, "reaching");
pub const T_LIFT_LIFTING: usize = term_index(&LIFT_TERMS, "lifting");
pub const T_LIFT_CONTACT: usize = term_index(&LIFT_TERMS, "contact");
pub const T_LIFT_SUCCESS: usize = term_index(&LIFT_TERMS, "success");
pub const T_LIFT_ACTION_RATE: usize = term_index(&LIFT_TERMS, "action_rate");
pub const T_LIFT_ACTION_MAGNITUDE: usize = term_index(&LIFT_TERMS, "action_magnitude");
pub const T_TRACK_HAND_FOLLOWING: usize = term_index(&TRACK_TERMS, "hand_following");
pub const T_TRACK_OBJECT_FOLLOWING: usize = term_index(&TRACK_TERMS, "object_following");
pub const T_TRACK_CONTACT: usize = term_index(&TRACK_TERMS, "contact");
pub const T_TRACK_SUCCESS: usize = term_index(&TRACK_TERMS, "success");
pub const T_TRACK_LIFTING: usize = term_index(&TRACK_TERMS, "lifting");
pub const T_TRACK_ACTION_RATE: usize = term_index(&TRACK_TERMS, "action_rate");
pub const T_TRACK_ACTION_MAGNITUDE: usize = term_index(&TRACK_TERMS, "action_magnitude");
pub const T_RESIDUAL_JOINT_OBJECT_POS: usize = term_index(&RESIDUAL_JOINT_TERMS, "object_pos");
pub const T_RESIDUAL_JOINT_OBJECT_ROT: usize = term_index(&RESIDUAL_JOINT_TERMS, "object_rot");
pub const T_RESIDUAL_JOINT_RESIDUAL: usize = term_index(&RESIDUAL_JOINT_TERMS, "residual");
pub const T_RESIDUAL_JOINT_SUCCESS: usize = term_index(&RESIDUAL_JOINT_TERMS, "success");
pub const T_RESIDUAL_TASK_OBJECT: usize = term_index(&RESIDUAL_TASK_TERMS, "object");
pub const T_RESIDUAL_TASK_FINGERTIPS: usize = term_index(&RESIDUAL_TASK_TERMS, "fingertips");
pub const T_RESIDUAL_TASK_WRIST: usize = term_index(&RESIDUAL_TASK_TERMS, "wrist");
pub const T_RESIDUAL_TASK_CONTACT: usize = term_index(&RESIDUAL_TASK_TERMS, "contact");
pub const T_RESIDUAL_TASK_VELOCITY: usize = term_index(&RESIDUAL_TASK_TERMS, "velocity");
pub const T_RESIDUAL_TASK_TORQUE: usize = term_index(&RESIDUAL_TASK_TERMS, "torque");
pub const T_RESIDUAL_TASK_WORK: usize = term_index(&RESIDUAL_TASK_TERMS, "work");
pub const T_RESIDUAL_TASK_TABLE_COLLISION: usize = term_index(&RESIDUAL_TASK_TERMS, "table_collision");
pub const T_LIFT_GRIP_FORCE: usize = term_index(&LIFT_TERMS, "grip_force");
pub const T_LIFT_PENETRATION: usize = term_index(&LIFT_TERMS, "penetration");
pub const T_TRACK_GRIP_FORCE: usize = term_index(&TRACK_TERMS, "grip_force");
pub const T_TRACK_PENETRATION: usize = term_index(&TRACK_TERMS, "penetration");
pub const T_RESIDUAL_JOINT_GRIP_FORCE: usize = term_index(&RESIDUAL_JOINT_TERMS, "grip_force");
pub const T_RESIDUAL_JOINT_PENETRATION: usize = term_index(&RESIDUAL_JOINT_TERMS, "penetration");
pub const T_RESIDUAL_TASK_GRIP_FORCE: usize = term_index(&RESIDUAL_TASK_TERMS, "grip_force");
pub const T_RESIDUAL_TASK_PENETRATION: usize = term_index(&RESIDUAL_TASK_TERMS, "penetration");
// every kind ends with the grasp terms (`task_reward` writes them at the kind's last two slots)
const _: () = assert!(T_LIFT_GRIP_FORCE == LIFT_TERMS.len() - 2 && T_LIFT_PENETRATION == LIFT_TERMS.len() - 1);
const _: () = assert!(T_TRACK_GRIP_FORCE == TRACK_TERMS.len() - 2 && T_TRACK_PENETRATION == TRACK_TERMS.len() - 1);
const _: () = assert!(T_RESIDUAL_JOINT_GRIP_FORCE == RESIDUAL_JOINT_TERMS.len() - 2 && T_RESIDUAL_JOINT_PENETRATION == RESIDUAL_JOINT_TERMS.len() - 1);
const _: () = assert!(T_RESIDUAL_TASK_GRIP_FORCE == RESIDUAL_TASK_TERMS.len() - 2 && T_RESIDUAL_TASK_PENETRATION == RESIDUAL_TASK_TERMS.len() - 1);
/// Offsets in the per-env output record (after the obs and priv obs sections of the GPU's output
/// buffer; keep in sync with task.wgsl `OUT_*`): reward, the weighted terms (`MAX_TERMS` slots,
/// the kind's first), terminated, time_out, success, lift height, max hand–object penetration, the
/// object's position (m) and orientation (rad) error against its reference (reference kinds),
/// whether the physics reset the env for a bad state (NaN, speed or distance beyond the limits);
/// `OUT_MISC` floats in all.
pub const OUT_REWARD: usize = 0;
pub const OUT_TERMS: usize = 1;
pub const OUT_TERMINATED: usize = 13;
pub const OUT_TIME_OUT: usize = 14;
pub const OUT_SUCCESS: usize = 15;
pub const OUT_LIFT: usize = 16;
pub const OUT_MAX_PEN: usize = 17;
pub const OUT_OBJ_POS_ERR: usize = 18;
pub const OUT_OBJ_ROT_ERR: usize = 19;
pub const OUT_BAD_RESET: usize = 20;
pub const OUT_MISC: usize = 21;


/// The observation cursor of one env (the shader's `ob_*` / `pr_base` private variables): where
/// its actor and critic rows go and the counters its noise is drawn from.
pub struct ObsOut<'a> {
    pub seed: u32,
    /// The env's global id (`Globals::env_offset` added): the noise's key.
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

/// `track`'s raw reward terms (slots `T_TRACK_*`) of one env on its post-step state against the
/// reference frame `f` of this instant; `e` = the object's position and angle error against `f`,
/// `fin` = whether the object is within the success tolerance of the reference's final pose,
/// `contact` = the thumb and another fingertip touch the object, `h` = the lift height (m).
#[allow(clippy::too_many_arguments)]
pub fn track_terms(st: &EnvState, ts: &TaskState, f: &RefFrame, e: Vec2, fin: bool, contact: bool, h: f32, tc: &TaskGlobals) -> [f32; MAX_TERMS] {
    let mut raw = [0.0f32; MAX_TERMS];
    let e_wp = (v3(st.wrist_pos) - v3(f.wrist_pos)).length();
    let e_wr = quat_error(Vec4::from_array(f.wrist_rot), Vec4::from_array(st.wrist_rot)).length();
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
    raw[T_TRACK_HAND_FOLLOWING] = tc.beta_joint * rj + tc.beta_wrist_pos * rx + tc.beta_wrist_rot * rr;
    // R_o = exp(−α4‖T − T̂‖) + exp(−α5‖log(q̂⁻¹ ⊗ q)‖)
    raw[T_TRACK_OBJECT_FOLLOWING] = (-tc.alpha_object_pos * e.x).exp() + (-tc.alpha_object_rot * e.y).exp();
    // contact while the reference grasps
    raw[T_TRACK_CONTACT] = if contact && f.grasp > 0.5 { 1.0 } else { 0.0 };
    raw[T_TRACK_SUCCESS] = if fin && f.ended != 0 { 1.0 } else { 0.0 };
    raw[T_TRACK_LIFTING] = h.max(0.0).min(tc.success_height) * 100.0;
    raw[T_TRACK_ACTION_RATE] = ts.act_rate;
    raw[T_TRACK_ACTION_MAGNITUDE] = ts.act_mag;
    raw
}

/// `residual_joint`'s raw reward terms (slots `T_RESIDUAL_JOINT_*`):
/// `w_p exp(−k_p e_p) + w_r exp(−k_r e_R) − λ_a ‖δ‖²` (arguments as [`track_terms`]).
pub fn residual_joint_terms(ts: &TaskState, f: &RefFrame, e: Vec2, fin: bool, tc: &TaskGlobals) -> [f32; MAX_TERMS] {
    let mut raw = [0.0f32; MAX_TERMS];
    raw[T_RESIDUAL_JOINT_OBJECT_POS] = (-tc.res_obj_pos_coef * e.x).exp();
    raw[T_RESIDUAL_JOINT_OBJECT_ROT] = (-tc.res_obj_rot_coef * e.y).exp();
    raw[T_RESIDUAL_JOINT_RESIDUAL] = ts.res_sq;
    raw[T_RESIDUAL_JOINT_SUCCESS] = if fin && f.ended != 0 { 1.0 } else { 0.0 };
    raw
}

/// `residual_task`'s raw reward terms (slots `T_RESIDUAL_TASK_*`; DexRefine): the object, fingertip
/// and wrist tracking exponentials, contact, and the joint velocity, torque, work and table
/// penalties (arguments as [`track_terms`]).
#[allow(clippy::too_many_arguments)]
/// `table`: a hand collider touches the table (`StepStats::table_contact`).
pub fn residual_task_terms(st: &EnvState, p: &EnvParams, ts: &TaskState, f: &RefFrame, e: Vec2, contact: bool, table: bool, m: &Model, tc: &TaskGlobals) -> [f32; MAX_TERMS] {
    let mut raw = [0.0f32; MAX_TERMS];
    let e_wp = (v3(st.wrist_pos) - v3(f.wrist_pos)).length();
    let e_wr = quat_error(Vec4::from_array(f.wrist_rot), Vec4::from_array(st.wrist_rot)).length();
    let mut s = Scratch::default();
    hand_kinematics(st, m, &mut s);
    let mut e_tips = 0.0f32;
    for t in 0..m.g.n_tips as usize {
        e_tips += (tip_position(m, &s, t) - v3(f.tips[t])).length();
    }
    e_tips /= m.g.n_tips.max(1) as f32;
    // object exp(−a_p e_p − a_R e_R), gated by contact or the object being on its reference
    let gate = contact || e.x <= tc.success_pos_tol;
    raw[T_RESIDUAL_TASK_OBJECT] = if gate { (-tc.rw_obj_pos * e.x - tc.rw_obj_rot * e.y).exp() } else { 0.0 };
    raw[T_RESIDUAL_TASK_FINGERTIPS] = (-tc.rw_tips * e_tips).exp();
    raw[T_RESIDUAL_TASK_WRIST] = (-tc.rw_wrist_pos * e_wp - tc.rw_wrist_rot * e_wr).exp();
    raw[T_RESIDUAL_TASK_CONTACT] = if contact && f.grasp > 0.5 { 1.0 } else { 0.0 };
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
    raw[T_RESIDUAL_TASK_VELOCITY] = vel;
    raw[T_RESIDUAL_TASK_TORQUE] = torque;
    raw[T_RESIDUAL_TASK_WORK] = work;
    raw[T_RESIDUAL_TASK_TABLE_COLLISION] = if table { 1.0 } else { 0.0 };
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
    ts.link_contact = stats.link_contact;
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
        raw[T_LIFT_REACHING] = 1.0 - (tc.reach_alpha * dist).min(20.0).tanh();
        // lifting: h in cm, capped at the success height
        raw[T_LIFT_LIFTING] = h.max(0.0).min(tc.success_height) * 100.0;
        raw[T_LIFT_CONTACT] = if thumb && other { 1.0 } else { 0.0 };
        raw[T_LIFT_SUCCESS] = if h >= tc.success_height { 1.0 } else { 0.0 };
        raw[T_LIFT_ACTION_RATE] = ts.act_rate;
        raw[T_LIFT_ACTION_MAGNITUDE] = ts.act_mag;
        success = raw[T_LIFT_SUCCESS];
        time_out = !terminated && st.step >= tc.episode_length;
        if bad {
            // the physics already reset this env: its state says nothing about the step
            raw[T_LIFT_REACHING] = 0.0;
            raw[T_LIFT_LIFTING] = 0.0;
            raw[T_LIFT_CONTACT] = 0.0;
            raw[T_LIFT_SUCCESS] = 0.0;
            success = 0.0;
        }
    } else {
        let f = ref_sample(r, &ts.cursor, st.step, 0);
        let (fin_pos, fin_rot) = ref_object_end(r, &ts.cursor);
        let orot = Vec4::from_array(st.obj_rot);
        // the object's error against its reference now (m, rad) and against the final pose
        err = Vec2::new((obj - v3(f.obj_pos)).length(), quat_error(Vec4::from_array(f.obj_rot), orot).length());
        let fin_p = (obj - fin_pos).length();
        let fin_r = quat_error(fin_rot, orot).length();
        let fin = fin_p <= tc.success_pos_tol && fin_r <= tc.success_rot_tol;
        raw = if tc.kind == KIND_TRACK {
            track_terms(st, ts, &f, err, fin, thumb && other, h, tc)
        } else if tc.kind == KIND_RESIDUAL_JOINT {
            residual_joint_terms(ts, &f, err, fin, tc)
        } else {
            residual_task_terms(st, p, ts, &f, err, thumb && other, stats.table_contact != 0, m, tc)
        };
        success = if fin { 1.0 } else { 0.0 };
        terminated = terminated || (tc.max_object_error > 0.0 && err.x > tc.max_object_error);
        time_out = !terminated && if tc.episode_length > 0 { st.step >= tc.episode_length } else { f.ended != 0 };
        if bad {
            raw = [0.0; MAX_TERMS];
            success = 0.0;
            err = Vec2::ZERO;
        }
    }
    if !bad {
        // the grasp terms, the kind's last two: Σ_tips max(F − F_limit, 0) (N), max(d − d_tol, 0) (mm)
        let mut excess = 0.0f32;
        for i in 0..m.g.n_tips as usize {
            excess += (stats.tip_force[i] - tc.grip_force_limit).max(0.0);
        }
        raw[tc.n_terms as usize - 2] = excess;
        raw[tc.n_terms as usize - 1] = (stats.max_pen_ho - tc.penetration_tolerance).max(0.0) * 1000.0;
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
    out[OUT_BAD_RESET] = if bad { 1.0 } else { 0.0 };
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

/// Actor entries k, k+1, k+2 (noisy) and the same critic entries (clean); returns k + 3.
pub fn put_obs3(o: &mut ObsOut, k: u32, clean: Vec3, noisy_v: Vec3) -> u32 {
    for c in 0..3 {
        put_obs(o, k + c as u32, clean[c], noisy_v[c]);
    }
    k + 3
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

/// This episode's latency (control steps) of the actor's object pose: uniform in
/// [obj_delay_min, obj_delay_max].
pub fn obj_delay_draw(seed: u32, env: u32, episode: u32, tc: &TaskGlobals) -> u32 {
    let span = tc.obj_delay_max - tc.obj_delay_min;
    let u = rand_uniform(seed, env, episode, PURPOSE_OBJ_DELAY, 0);
    tc.obj_delay_min + ((u * (span + 1) as f32) as u32).min(span)
}

/// Records the object pose of this observation in the ring (every slot after an episode start)
/// and returns the slot of the pose `obj_delay` steps earlier.
pub fn obj_delay_slot(ts: &mut TaskState, step: u32, started: bool, pos: [f32; 4], rot: [f32; 4]) -> usize {
    let n = OBJ_HIST as u32;
    if started {
        ts.obj_hist_pos = [pos; OBJ_HIST];
        ts.obj_hist_rot = [rot; OBJ_HIST];
    } else {
        ts.obj_hist_pos[(step % n) as usize] = pos;
        ts.obj_hist_rot[(step % n) as usize] = rot;
    }
    ((step + n - ts.obj_delay) % n) as usize
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
    ts.obj_delay = obj_delay_draw(m.g.seed, env.wrapping_add(m.g.env_offset), st.episode, tc); // the global env id
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
        k = put_obs3(o, k, v3(f.wrist_pos) - wp, v3(f.wrist_pos) - noisy_state.wrist);
        let e = quat_error(Vec4::from_array(f.wrist_rot), wr);
        k = put_obs3(o, k, e, e);
        for a in 0..tc.n_actuated {
            let j = actuated_joint(tc, a);
            put_obs(o, k, f.q[j] - st.q[j], f.q[j] - noisy_state.q[a as usize]);
            k += 1;
        }
        k = put_obs3(o, k, v3(f.obj_pos) - op, v3(f.obj_pos) - noisy_state.obj);
        k = put_obs3(o, k, quat_error(Vec4::from_array(f.obj_rot), orot), quat_error(Vec4::from_array(f.obj_rot), noisy_state.obj_rot));
        for t in 0..m.g.n_tips as usize {
            k = put_obs3(o, k, v3(f.tips[t]) - tip_position(m, s, t), v3(f.tips[t]) - noisy_state.tips[t]);
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
    let started = reset_req != 0 || ts.done != 0;
    if started {
        *ts = task_init(env, st, m, tc, r);
    }
    let st: &EnvState = st;
    // the actor's object pose: the one obj_delay observations ago
    let dslot = obj_delay_slot(ts, st.step, started, st.obj_pos, st.obj_rot);
    write_observation(env, st, p, ts, dslot, m, tc, r, obs, privo);
}

/// The observations of the state an ending episode ended in (twin of task.wgsl's
/// `task_observe_final`): called after [`task_reward`] and before the reset, for an env with a
/// reset request; observes as [`task_observe`] does without initialising anything, and changes no
/// state (the delayed-pose ring is advanced on a copy of the task state).
#[allow(clippy::too_many_arguments)]
pub fn task_observe_final(env: u32, st: &EnvState, p: &EnvParams, ts: &TaskState, m: &Model, tc: &TaskGlobals, r: &RefModel, obs: &mut [f32], privo: &mut [f32]) {
    let mut ts = *ts;
    let dslot = obj_delay_slot(&mut ts, st.step, false, st.obj_pos, st.obj_rot);
    write_observation(env, st, p, &ts, dslot, m, tc, r, obs, privo);
}

/// Writes env's actor row `obs` and critic row `privo` from its state `st`, task state `ts` and the
/// delayed object pose's slot `dslot` (the body shared by [`task_observe`] and [`task_observe_final`]).
#[allow(clippy::too_many_arguments)]
pub fn write_observation(env: u32, st: &EnvState, p: &EnvParams, ts: &TaskState, dslot: usize, m: &Model, tc: &TaskGlobals, r: &RefModel, obs: &mut [f32], privo: &mut [f32]) {
    let mut s = Scratch::default();
    hand_kinematics(st, m, &mut s);
    // the noise is keyed by the global env id
    let mut o = ObsOut { seed: m.g.seed, env: env.wrapping_add(m.g.env_offset), episode: st.episode, step: st.step, obs, privo };
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
    let dp = v3(ts.obj_hist_pos[dslot]);
    let mut on = dp;
    for c in 0..3 {
        on[c] = noisy(&o, k, dp[c], tc.noise_object_pos);
        put_obs(&mut o, k, op[c], on[c]);
        k += 1;
    }
    let oq = Vec4::from_array(st.obj_rot);
    let dq = Vec4::from_array(ts.obj_hist_rot[dslot]);
    let mut qn = dq;
    for c in 0..4 {
        qn[c] = noisy(&o, k + c as u32, dq[c], tc.noise_object_rot);
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
    for l in 0..m.g.n_links {
        put_priv(&mut o, k, ((ts.link_contact[l as usize / 32] >> (l % 32)) & 1) as f32);
        k += 1;
    }
    put_priv(&mut o, k, p.obj_inertia[3]);
    put_priv(&mut o, k + 1, p.obj_friction);
    put_priv(&mut o, k + 2, p.obj_scale);
    put_priv(&mut o, k + 3, p.restitution);
    put_priv(&mut o, k + 4, p.added_gravity);
}
