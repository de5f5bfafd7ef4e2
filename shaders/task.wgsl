// task.wgsl — the task kinds (lift, track, residual_joint, residual_task) on top of the physics:
// actions -> targets, reward terms and dones, observations. One invocation per env, three entry
// points run in this order around the physics:
//   task_act -> step_main -> task_reward -> reset_main -> task_observe
// CPU twin: src/env/task.rs (same function names, same order, same arithmetic; the module doc there
// is the contract and lists the observation layout). This file is appended to common + reset +
// physics + reference + ik: it reuses hand_kinematics and its var<private> memory (st, link_pos,
// link_rot), the reference sampler (ref_begin, ref_sample) and the fingertip IK (ik_solve).

// The task layer's constants (twin: layout.rs TaskGlobals; a uniform, so arrays are of vec4).
struct TaskGlobals {
    wrist_pos_min: vec4<f32>,
    wrist_pos_max: vec4<f32>,
    palm_offset: vec4<f32>,
    weights: array<vec4<f32>, 3>,
    // joint index of each actuated joint, 4 per vec4: MAX_JOINTS / 4 vec4s
    actuated: array<vec4<u32>, MAX_JOINTS / 4u>,
    n_actuated: u32,
    n_act: u32,
    obs_dim: u32,
    priv_dim: u32,
    episode_length: u32,
    finger_mode: u32,
    thumb: u32,
    obj_delay_min: u32,
    wrist_pos_scale: f32,
    wrist_rot_scale: f32,
    wrist_rot_limit: f32,
    finger_delta_scale: f32,
    reach_alpha: f32,
    success_height: f32,
    contact_force: f32,
    drop_height: f32,
    table_half_extent: f32,
    max_hand_distance: f32,
    noise_joint_pos: f32,
    noise_joint_vel: f32,
    noise_hand_pos: f32,
    noise_object_pos: f32,
    noise_object_rot: f32,
    obj_delay_max: u32,
    kind: u32,
    n_terms: u32,
    start_mode: u32,
    lookahead: u32,
    lookahead_stride: u32,
    n_res: u32,
    open_loop: u32,
    track_action: u32,
    beta_joint: f32,
    beta_wrist_pos: f32,
    beta_wrist_rot: f32,
    alpha_joint: f32,
    alpha_wrist_pos: f32,
    alpha_wrist_rot: f32,
    alpha_object_pos: f32,
    alpha_object_rot: f32,
    success_pos_tol: f32,
    success_rot_tol: f32,
    max_object_error: f32,
    res_alpha: f32,
    res_wrist_pos_alpha: f32,
    res_wrist_rot_alpha: f32,
    res_obj_pos_coef: f32,
    res_obj_rot_coef: f32,
    res_ema: f32,
    res_scale_wrist_pos: f32,
    res_scale_wrist_rot: f32,
    res_scale_tips: f32,
    res_clamp_wrist_pos: f32,
    res_clamp_wrist_rot: f32,
    res_clamp_tips: f32,
    control_dt: f32,
    rw_obj_pos: f32,
    rw_obj_rot: f32,
    rw_tips: f32,
    rw_wrist_pos: f32,
    rw_wrist_rot: f32,
    grip_force_limit: f32,
    penetration_tolerance: f32,
    _pad1: f32,
    ik: IkParams,
}

// The task layer's per-env state (twin: layout.rs TaskState).
struct TaskState {
    targets: Targets,
    rest_pos: vec4<f32>,
    prev_action: array<f32, MAX_ACTIONS>,
    tip_force: array<f32, MAX_TIPS>,
    act_rate: f32,
    act_mag: f32,
    done: u32,
    // ‖δ‖² of the last residual (residual kinds)
    res_sq: f32,
    // StepStats.link_contact of the last step (0 after a reset)
    link_contact: array<u32, 2>,
    // the reference this episode follows (reference kinds)
    cursor: RefCursor,
    // residual_task: the EMA-smoothed output ũ and the integrated residual Δa [n_res]
    res_ema: array<f32, MAX_RES>,
    res_delta: array<f32, MAX_RES>,
    // the object poses of the last OBJ_HIST observations (slot step % OBJ_HIST) and this
    // episode's latency (control steps) of the actor's object pose
    obj_hist_pos: array<vec4<f32>, 8>,
    obj_hist_rot: array<vec4<f32>, 8>,
    obj_delay: u32,
    _pad3a: u32,
    _pad3b: u32,
    _pad3c: u32,
}

// the task layer (shaders/task.wgsl, src/env/task_gpu.rs)
@group(0) @binding(9) var<uniform> tc: TaskGlobals;
@group(0) @binding(10) var<storage, read_write> task_states: array<TaskState>;
// actions [N, n_act]
@group(0) @binding(11) var<storage, read> actions: array<f32>;
// obs [N, obs_dim], then priv obs [N, priv_dim], then per-env reward/terms/flags [N, OUT_MISC]
@group(0) @binding(12) var<storage, read_write> task_out: array<f32>;
// task_observe_final's output: the final obs [N, obs_dim], then the final priv obs [N, priv_dim]
// (one element while the final observations are off)
@group(0) @binding(17) var<storage, read_write> final_out: array<f32>;


const PURPOSE_OBS_NOISE: u32 = 3u;
// RNG purpose of the object-pose latency draw (reference.wgsl uses 4)
const PURPOSE_OBJ_DELAY: u32 = 5u;
// slots of TaskState's object-pose ring
const OBJ_HIST: u32 = 8u;
// noise draw k of obs entry i at env step s: key = s * OBS_KEY_STRIDE + 2 i + k (k = 0, 1)
const OBS_KEY_STRIDE: u32 = 4096u;
const MAX_ACTIONS: u32 = 40u;
// residual_task's residual: wrist (6) + 3 per fingertip (layout.rs MAX_RES)
const MAX_RES: u32 = 6u + 3u * MAX_TIPS;
const KIND_LIFT: u32 = 0u;
const KIND_TRACK: u32 = 1u;
const KIND_RESIDUAL_JOINT: u32 = 2u;
const KIND_RESIDUAL_TASK: u32 = 3u;
const MAX_TERMS: u32 = 12u;
// the slot of each reward term in its kind's output (the tables of src/task/spec.rs, in their
// order; tests/suite/shaders.rs checks every name and index)
const T_LIFT_REACHING: u32 = 0u;
const T_LIFT_LIFTING: u32 = 1u;
const T_LIFT_CONTACT: u32 = 2u;
const T_LIFT_SUCCESS: u32 = 3u;
const T_LIFT_ACTION_RATE: u32 = 4u;
const T_LIFT_ACTION_MAGNITUDE: u32 = 5u;
const T_LIFT_GRIP_FORCE: u32 = 6u;
const T_LIFT_PENETRATION: u32 = 7u;
const T_TRACK_HAND_FOLLOWING: u32 = 0u;
const T_TRACK_OBJECT_FOLLOWING: u32 = 1u;
const T_TRACK_CONTACT: u32 = 2u;
const T_TRACK_SUCCESS: u32 = 3u;
const T_TRACK_LIFTING: u32 = 4u;
const T_TRACK_ACTION_RATE: u32 = 5u;
const T_TRACK_ACTION_MAGNITUDE: u32 = 6u;
const T_TRACK_GRIP_FORCE: u32 = 7u;
const T_TRACK_PENETRATION: u32 = 8u;
const T_RESIDUAL_JOINT_OBJECT_POS: u32 = 0u;
const T_RESIDUAL_JOINT_OBJECT_ROT: u32 = 1u;
const T_RESIDUAL_JOINT_RESIDUAL: u32 = 2u;
const T_RESIDUAL_JOINT_SUCCESS: u32 = 3u;
const T_RESIDUAL_JOINT_GRIP_FORCE: u32 = 4u;
const T_RESIDUAL_JOINT_PENETRATION: u32 = 5u;
const T_RESIDUAL_TASK_OBJECT: u32 = 0u;
const T_RESIDUAL_TASK_FINGERTIPS: u32 = 1u;
const T_RESIDUAL_TASK_WRIST: u32 = 2u;
const T_RESIDUAL_TASK_CONTACT: u32 = 3u;
const T_RESIDUAL_TASK_VELOCITY: u32 = 4u;
const T_RESIDUAL_TASK_TORQUE: u32 = 5u;
const T_RESIDUAL_TASK_WORK: u32 = 6u;
const T_RESIDUAL_TASK_TABLE_COLLISION: u32 = 7u;
const T_RESIDUAL_TASK_GRIP_FORCE: u32 = 8u;
const T_RESIDUAL_TASK_PENETRATION: u32 = 9u;
// every kind's grasp terms are its last two (T_*_GRIP_FORCE = n_terms − 2, T_*_PENETRATION =
// n_terms − 1): task_reward writes them there
// per-env record of the outputs after the obs and priv obs sections of task_out
const OUT_REWARD: u32 = 0u;
const OUT_TERMS: u32 = 1u;
const OUT_TERMINATED: u32 = 13u;
const OUT_TIME_OUT: u32 = 14u;
const OUT_SUCCESS: u32 = 15u;
const OUT_LIFT: u32 = 16u;
const OUT_MAX_PEN: u32 = 17u;
const OUT_OBJ_POS_ERR: u32 = 18u;
const OUT_OBJ_ROT_ERR: u32 = 19u;
const OUT_BAD_RESET: u32 = 20u;
const OUT_MISC: u32 = 21u;

// ---- per-invocation observation cursor (the twin's ObsOut) ----
var<private> ob_env: u32;
var<private> ob_episode: u32;
var<private> ob_step: u32;
var<private> ob_base: u32;
var<private> pr_base: u32;
// the rows go to final_out (task_observe_final) instead of task_out
var<private> ob_final: bool;

fn actuated_joint(i: u32) -> u32 {
    return tc.actuated[i / 4u][i % 4u];
}

// absolute: lower + (a + 1)/2 (upper − lower) (unlimited joints: default + a π); delta: clamp(q* + a s)
fn finger_target(mode: u32, jd: JointDesc, a: f32, prev: f32) -> f32 {
    if (mode == 0u) {
        if (jd.lower <= -1e29 || jd.upper >= 1e29) {
            return jd.default_q + a * 3.14159265;
        }
        return jd.lower + 0.5 * (a + 1.0) * (jd.upper - jd.lower);
    }
    return clamp(prev + a * tc.finger_delta_scale, jd.lower, jd.upper);
}

// exp(rv) ⊗ rot, normalised; rot itself when the rotation is below 1e-9 rad
fn rotate_by(rot: vec4<f32>, rv: vec3<f32>) -> vec4<f32> {
    let angle = length(rv);
    if (angle > 1e-9) {
        return quat_normalize(quat_mul(quat_from_axis_angle(rv / angle, angle), rot));
    }
    return rot;
}

// exp(rv) ⊗ rot, then at most wrist_rot_limit from the initial orientation: exp(e·limit/|e|) ⊗ init
fn wrist_rot_target(rot: vec4<f32>, rv: vec3<f32>) -> vec4<f32> {
    var r = rotate_by(rot, rv);
    let init = g.init_wrist_rot;
    let e = quat_error(r, init);
    let d = length(e);
    if (d > tc.wrist_rot_limit) {
        r = quat_normalize(quat_mul(quat_from_axis_angle(e / d, tc.wrist_rot_limit), init));
    }
    return r;
}

// targets that follow a reference frame exactly (what `dextrain replay` drives)
fn nominal_targets(f: RefFrame) -> Targets {
    var t: Targets;
    t.wrist_pos = f.wrist_pos;
    t.wrist_rot = f.wrist_rot;
    t.q = f.q;
    return t;
}

// residual kinds (and track with action "reference"): targets from the nominal frame f and the
// clipped actions a (see the twin)
fn residual_targets(a: array<f32, MAX_ACTIONS>, f: RefFrame, ts: ptr<function, TaskState>) -> Targets {
    var t = nominal_targets(f);
    var sq = 0.0;
    if (tc.kind != KIND_RESIDUAL_TASK) {
        // residual_joint, and track with `task.track.action = "reference"`
        let dp = vec3<f32>(a[0], a[1], a[2]) * tc.res_wrist_pos_alpha;
        let dr = vec3<f32>(a[3], a[4], a[5]) * tc.res_wrist_rot_alpha;
        t.wrist_pos = vec4<f32>(f.wrist_pos.x + dp.x, f.wrist_pos.y + dp.y, f.wrist_pos.z + dp.z, 0.0);
        t.wrist_rot = rotate_by(f.wrist_rot, dr);
        // ‖δ‖² = Σ δ_i² over every component
        sq = dot(dp, dp) + dot(dr, dr);
        for (var i = 0u; i < tc.n_actuated; i++) {
            let j = actuated_joint(i);
            let jd = joints[j];
            let d = a[6u + i] * tc.res_alpha;
            t.q[j] = min(max(f.q[j] + d, jd.lower), jd.upper);
            sq += d * d;
        }
    } else {
        var tips_moved = false;
        for (var c = 0u; c < tc.n_res; c++) {
            // ũ_t = ema·u_t + (1 − ema)·ũ_{t−1}
            (*ts).res_ema[c] = tc.res_ema * a[c] + (1.0 - tc.res_ema) * (*ts).res_ema[c];
            var scale = tc.res_scale_tips;
            var lim = tc.res_clamp_tips;
            if (c < 3u) {
                scale = tc.res_scale_wrist_pos;
                lim = tc.res_clamp_wrist_pos;
            } else if (c < 6u) {
                scale = tc.res_scale_wrist_rot;
                lim = tc.res_clamp_wrist_rot;
            }
            // Δa_t = clamp(Δa_{t−1} + s ũ_t Δt, −c, c)
            (*ts).res_delta[c] = min(max((*ts).res_delta[c] + scale * (*ts).res_ema[c] * tc.control_dt, -lim), lim);
            sq += (*ts).res_delta[c] * (*ts).res_delta[c];
            if (c >= 6u && (*ts).res_delta[c] != 0.0) {
                tips_moved = true;
            }
        }
        let d = (*ts).res_delta;
        t.wrist_pos = vec4<f32>(f.wrist_pos.x + d[0], f.wrist_pos.y + d[1], f.wrist_pos.z + d[2], 0.0);
        t.wrist_rot = rotate_by(f.wrist_rot, vec3<f32>(d[3], d[4], d[5]));
        if (tips_moved) {
            let base = ik_tip_positions(f.q);
            var goal: array<vec3<f32>, MAX_TIPS>;
            for (var k = 0u; k < g.n_tips; k++) {
                goal[k] = base[k] + vec3<f32>(d[6u + 3u * k], d[7u + 3u * k], d[8u + 3u * k]);
            }
            let mask = (1u << g.n_tips) - 1u;
            t.q = ik_solve(f.q, goal, mask, tc.ik);
        }
    }
    (*ts).res_sq = sq;
    return t;
}

@compute @workgroup_size(64)
fn task_act(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let env = env_index(gid, nwg);
    if (env >= g.n_envs) {
        return;
    }
    var ts = task_states[env];
    let base = env * tc.n_act;
    var a: array<f32, MAX_ACTIONS>;
    var rate = 0.0;
    var mag = 0.0;
    for (var i = 0u; i < tc.n_act; i++) {
        let ai = clamp(actions[base + i], -1.0, 1.0);
        let d = ai - ts.prev_action[i];
        // Σ (a_t − a_{t−1})², Σ a_t²
        rate += d * d;
        mag += ai * ai;
        a[i] = ai;
        ts.prev_action[i] = ai;
    }
    ts.act_rate = rate;
    ts.act_mag = mag;
    if (tc.kind != KIND_LIFT && (tc.open_loop != 0u || tc.kind != KIND_TRACK || tc.track_action != 0u)) {
        // the reference at the end of this step: replay's targets for control step `step`
        let f = ref_sample(ts.cursor, states[env].step, 1u);
        if (tc.open_loop != 0u) {
            ts.targets = nominal_targets(f);
            ts.res_sq = 0.0;
        } else {
            ts.targets = residual_targets(a, f, &ts);
        }
        task_states[env] = ts;
        targets[env] = ts.targets;
        return;
    }
    let wp = ts.targets.wrist_pos.xyz + vec3<f32>(a[0], a[1], a[2]) * tc.wrist_pos_scale;
    ts.targets.wrist_pos = vec4<f32>(clamp(wp, tc.wrist_pos_min.xyz, tc.wrist_pos_max.xyz), 0.0);
    ts.targets.wrist_rot = wrist_rot_target(ts.targets.wrist_rot, vec3<f32>(a[3], a[4], a[5]) * tc.wrist_rot_scale);
    for (var i = 0u; i < tc.n_actuated; i++) {
        let j = actuated_joint(i);
        ts.targets.q[j] = finger_target(tc.finger_mode, joints[j], a[6u + i], ts.targets.q[j]);
    }
    task_states[env] = ts;
    targets[env] = ts.targets;
}

// p_palm = p_wrist + R_wrist · palm_offset
fn palm_position(wrist_pos: vec3<f32>, wrist_rot: vec4<f32>) -> vec3<f32> {
    return wrist_pos + quat_rotate(wrist_rot, tc.palm_offset.xyz);
}

// track's raw reward terms (slots T_TRACK_*) against the reference frame f of this instant;
// e = the object's position and angle error against f, fin = within the success tolerances of the
// reference's final pose, contact = the thumb and another fingertip touch, h = the lift height (m)
fn track_terms(s: EnvState, ts: TaskState, f: RefFrame, e: vec2<f32>, fin: bool, contact: bool, h: f32) -> array<f32, MAX_TERMS> {
    var raw: array<f32, MAX_TERMS>;
    let e_wp = length(s.wrist_pos.xyz - f.wrist_pos.xyz);
    let e_wr = length(quat_error(f.wrist_rot, s.wrist_rot));
    var dq = 0.0;
    for (var i = 0u; i < tc.n_actuated; i++) {
        let j = actuated_joint(i);
        let d = s.q[j] - f.q[j];
        dq += d * d;
    }
    // R_f = β1 (1 − tanh(α1‖q − q̂‖)) + β2 (1 − tanh(α2‖x − x̂‖)) + β3 (1 − tanh(α3 φ))
    let rj = 1.0 - tanh(min(tc.alpha_joint * sqrt(dq), 20.0));
    let rx = 1.0 - tanh(min(tc.alpha_wrist_pos * e_wp, 20.0));
    let rr = 1.0 - tanh(min(tc.alpha_wrist_rot * e_wr, 20.0));
    raw[T_TRACK_HAND_FOLLOWING] = tc.beta_joint * rj + tc.beta_wrist_pos * rx + tc.beta_wrist_rot * rr;
    // R_o = exp(−α4‖T − T̂‖) + exp(−α5‖log(q̂⁻¹ ⊗ q)‖)
    raw[T_TRACK_OBJECT_FOLLOWING] = exp(-tc.alpha_object_pos * e.x) + exp(-tc.alpha_object_rot * e.y);
    // contact while the reference grasps
    raw[T_TRACK_CONTACT] = select(0.0, 1.0, contact && f.grasp > 0.5);
    raw[T_TRACK_SUCCESS] = select(0.0, 1.0, fin && f.ended != 0u);
    raw[T_TRACK_LIFTING] = clamp(h, 0.0, tc.success_height) * 100.0;
    raw[T_TRACK_ACTION_RATE] = ts.act_rate;
    raw[T_TRACK_ACTION_MAGNITUDE] = ts.act_mag;
    return raw;
}

// residual_joint's raw reward terms (slots T_RESIDUAL_JOINT_*): w_p exp(−k_p e_p) + w_r exp(−k_r e_R) − λ_a ‖δ‖²
fn residual_joint_terms(ts: TaskState, f: RefFrame, e: vec2<f32>, fin: bool) -> array<f32, MAX_TERMS> {
    var raw: array<f32, MAX_TERMS>;
    raw[T_RESIDUAL_JOINT_OBJECT_POS] = exp(-tc.res_obj_pos_coef * e.x);
    raw[T_RESIDUAL_JOINT_OBJECT_ROT] = exp(-tc.res_obj_rot_coef * e.y);
    raw[T_RESIDUAL_JOINT_RESIDUAL] = ts.res_sq;
    raw[T_RESIDUAL_JOINT_SUCCESS] = select(0.0, 1.0, fin && f.ended != 0u);
    return raw;
}

// residual_task's raw reward terms (slots T_RESIDUAL_TASK_*; DexRefine): the object, fingertip and
// wrist tracking exponentials, contact, and the joint velocity, torque, work and table penalties
fn residual_task_terms(s: EnvState, p: EnvParams, ts: TaskState, f: RefFrame, e: vec2<f32>, contact: bool, table: bool) -> array<f32, MAX_TERMS> {
    var raw: array<f32, MAX_TERMS>;
    let e_wp = length(s.wrist_pos.xyz - f.wrist_pos.xyz);
    let e_wr = length(quat_error(f.wrist_rot, s.wrist_rot));
    st = s;
    hand_kinematics();
    var e_tips = 0.0;
    for (var t = 0u; t < g.n_tips; t++) {
        e_tips += length(tip_position(t) - f.tips[t].xyz);
    }
    e_tips /= f32(max(g.n_tips, 1u));
    // object exp(−a_p e_p − a_R e_R), gated by contact or the object being on its reference
    let gate = contact || e.x <= tc.success_pos_tol;
    raw[T_RESIDUAL_TASK_OBJECT] = select(0.0, exp(-tc.rw_obj_pos * e.x - tc.rw_obj_rot * e.y), gate);
    raw[T_RESIDUAL_TASK_FINGERTIPS] = exp(-tc.rw_tips * e_tips);
    raw[T_RESIDUAL_TASK_WRIST] = exp(-tc.rw_wrist_pos * e_wp - tc.rw_wrist_rot * e_wr);
    raw[T_RESIDUAL_TASK_CONTACT] = select(0.0, 1.0, contact && f.grasp > 0.5);
    var vel = 0.0;
    var torque = 0.0;
    var work = 0.0;
    for (var i = 0u; i < tc.n_actuated; i++) {
        let j = actuated_joint(i);
        let jd = joints[j];
        let qd = s.qd[j];
        // the servo's torque: clamp(kp (clamp(q*, lo, hi) − q) − kd q̇, ±effort)
        let goal = clamp(ts.targets.q[j], jd.lower * p.limit_scale, jd.upper * p.limit_scale);
        let tau = clamp(jd.kp * p.kp_scale * (goal - s.q[j]) - jd.kd * p.kd_scale * qd, -jd.effort, jd.effort);
        vel += qd * qd;
        torque += tau * tau;
        work += abs(tau * qd);
    }
    raw[T_RESIDUAL_TASK_VELOCITY] = vel;
    raw[T_RESIDUAL_TASK_TORQUE] = torque;
    raw[T_RESIDUAL_TASK_WORK] = work;
    raw[T_RESIDUAL_TASK_TABLE_COLLISION] = select(0.0, 1.0, table);
    return raw;
}

@compute @workgroup_size(64)
fn task_reward(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let env = env_index(gid, nwg);
    if (env >= g.n_envs) {
        return;
    }
    let s = states[env];
    let sts = stats[env];
    var ts = task_states[env];
    let bad = sts.bad_reset != 0u;
    let obj = s.obj_pos.xyz;
    let dist = length(obj - palm_position(s.wrist_pos.xyz, s.wrist_rot));
    // lifted height of the centre above its rest height (m)
    let h = obj.z - ts.rest_pos.z;
    var other = false;
    ts.link_contact = sts.link_contact;
    for (var i = 0u; i < g.n_tips; i++) {
        ts.tip_force[i] = sts.tip_force[i];
        if (i != tc.thumb && sts.tip_force[i] > tc.contact_force) {
            other = true;
        }
    }
    let thumb = sts.tip_force[tc.thumb] > tc.contact_force;
    var raw: array<f32, MAX_TERMS>;
    var terminated = bad || obj.z < tc.drop_height || abs(obj.x) > tc.table_half_extent || abs(obj.y) > tc.table_half_extent;
    terminated = terminated || dist > tc.max_hand_distance;
    var time_out: bool;
    var success: f32;
    var err = vec2<f32>(0.0, 0.0);
    if (tc.kind == KIND_LIFT) {
        // reaching 1 − tanh(α d) (tanh saturates at 20: some GPUs' tanh overflows beyond)
        raw[T_LIFT_REACHING] = 1.0 - tanh(min(tc.reach_alpha * dist, 20.0));
        // lifting: h in cm, capped at the success height
        raw[T_LIFT_LIFTING] = clamp(h, 0.0, tc.success_height) * 100.0;
        raw[T_LIFT_CONTACT] = select(0.0, 1.0, thumb && other);
        raw[T_LIFT_SUCCESS] = select(0.0, 1.0, h >= tc.success_height);
        raw[T_LIFT_ACTION_RATE] = ts.act_rate;
        raw[T_LIFT_ACTION_MAGNITUDE] = ts.act_mag;
        success = raw[T_LIFT_SUCCESS];
        time_out = !terminated && s.step >= tc.episode_length;
        if (bad) {
            // the physics already reset this env: its state says nothing about the step
            raw[T_LIFT_REACHING] = 0.0;
            raw[T_LIFT_LIFTING] = 0.0;
            raw[T_LIFT_CONTACT] = 0.0;
            raw[T_LIFT_SUCCESS] = 0.0;
            success = 0.0;
        }
    } else {
        let f = ref_sample(ts.cursor, s.step, 0u);
        let fin_ref = ref_object_end(ts.cursor);
        // the object's error against its reference now (m, rad) and against the final pose
        err = vec2<f32>(length(obj - f.obj_pos.xyz), length(quat_error(f.obj_rot, s.obj_rot)));
        let fin_p = length(obj - fin_ref.pos);
        let fin_r = length(quat_error(fin_ref.rot, s.obj_rot));
        let fin = fin_p <= tc.success_pos_tol && fin_r <= tc.success_rot_tol;
        if (tc.kind == KIND_TRACK) {
            raw = track_terms(s, ts, f, err, fin, thumb && other, h);
        } else if (tc.kind == KIND_RESIDUAL_JOINT) {
            raw = residual_joint_terms(ts, f, err, fin);
        } else {
            raw = residual_task_terms(s, params[env], ts, f, err, thumb && other, sts.table_contact != 0u);
        }
        success = select(0.0, 1.0, fin);
        terminated = terminated || (tc.max_object_error > 0.0 && err.x > tc.max_object_error);
        var ended = s.step >= tc.episode_length;
        if (tc.episode_length == 0u) {
            ended = f.ended != 0u;
        }
        time_out = !terminated && ended;
        if (bad) {
            for (var k = 0u; k < MAX_TERMS; k++) {
                raw[k] = 0.0;
            }
            success = 0.0;
            err = vec2<f32>(0.0, 0.0);
        }
    }
    if (!bad) {
        // the grasp terms, the kind's last two: Σ_tips max(F − F_limit, 0) (N), max(d − d_tol, 0) (mm)
        var excess = 0.0;
        for (var i = 0u; i < g.n_tips; i++) {
            excess += max(sts.tip_force[i] - tc.grip_force_limit, 0.0);
        }
        raw[tc.n_terms - 2u] = excess;
        raw[tc.n_terms - 1u] = max(sts.max_pen_ho - tc.penetration_tolerance, 0.0) * 1000.0;
    }
    var lift = h;
    if (bad) {
        lift = 0.0;
    }
    let mb = g.n_envs * (tc.obs_dim + tc.priv_dim) + env * OUT_MISC;
    var reward = 0.0;
    for (var k = 0u; k < MAX_TERMS; k++) {
        // term_k = w_k · raw_k, reward = Σ_k term_k
        let wk = tc.weights[k / 4u][k % 4u] * raw[k];
        task_out[mb + OUT_TERMS + k] = wk;
        reward += wk;
    }
    time_out = time_out && !terminated;
    task_out[mb + OUT_REWARD] = reward;
    task_out[mb + OUT_TERMINATED] = select(0.0, 1.0, terminated);
    task_out[mb + OUT_TIME_OUT] = select(0.0, 1.0, time_out);
    task_out[mb + OUT_SUCCESS] = success;
    task_out[mb + OUT_LIFT] = lift;
    task_out[mb + OUT_MAX_PEN] = sts.max_pen_ho;
    task_out[mb + OUT_OBJ_POS_ERR] = err.x;
    task_out[mb + OUT_OBJ_ROT_ERR] = err.y;
    task_out[mb + OUT_BAD_RESET] = select(0.0, 1.0, bad);
    let done = terminated || time_out;
    ts.done = select(0u, 1u, done);
    task_states[env] = ts;
    // a bad-state env was already reset by the physics
    reset_mask[env] = select(0u, 1u, done && !bad);
}

// standard normal draw for obs entry k (Box–Muller: √(−2 ln u1) cos(2π u2), u1 ∈ (0, 1])
fn obs_noise(k: u32) -> f32 {
    let key = ob_step * OBS_KEY_STRIDE + 2u * k;
    let u1 = 1.0 - rand_uniform(g.seed, ob_env, ob_episode, PURPOSE_OBS_NOISE, key);
    let u2 = rand_uniform(g.seed, ob_env, ob_episode, PURPOSE_OBS_NOISE, key + 1u);
    return sqrt(-2.0 * log(u1)) * cos(6.2831853 * u2);
}

// v + σ · N(0, 1) for obs entry k (v itself when σ = 0)
fn noisy(k: u32, v: f32, sigma: f32) -> f32 {
    if (sigma > 0.0) {
        return v + sigma * obs_noise(k);
    }
    return v;
}

// actor obs entry k (noisy) and the same entry of the critic obs (clean)
fn put_obs(k: u32, clean: f32, noisy_v: f32) {
    if (ob_final) {
        final_out[ob_base + k] = noisy_v;
        final_out[pr_base + k] = clean;
    } else {
        task_out[ob_base + k] = noisy_v;
        task_out[pr_base + k] = clean;
    }
}

// actor entries k, k+1, k+2 (noisy) and the same critic entries (clean); returns k + 3
fn put_obs3(k: u32, clean: vec3<f32>, noisy_v: vec3<f32>) -> u32 {
    for (var c = 0u; c < 3u; c++) {
        put_obs(k + c, clean[c], noisy_v[c]);
    }
    return k + 3u;
}

// critic-only entry k (k >= obs_dim)
fn put_priv(k: u32, v: f32) {
    if (ob_final) {
        final_out[pr_base + k] = v;
    } else {
        task_out[pr_base + k] = v;
    }
}

// world position of fingertip t (after hand_kinematics)
fn tip_position(t: u32) -> vec3<f32> {
    let tip = tips[t];
    return link_pos[tip.link] + quat_rotate(link_rot[tip.link], tip.pos.xyz);
}

// the task state of an env that was just reset: default targets, no previous action, rest position;
// reference kinds begin the episode's reference and may place hand and object on it (see the twin)
// This episode's latency (control steps) of the actor's object pose: uniform in
// [obj_delay_min, obj_delay_max].
fn obj_delay_draw(env: u32, episode: u32) -> u32 {
    let span = tc.obj_delay_max - tc.obj_delay_min;
    let u = rand_uniform(g.seed, env, episode, PURPOSE_OBJ_DELAY, 0u);
    return tc.obj_delay_min + min(u32(u * f32(span + 1u)), span);
}

// Records the object pose of this observation in the ring (every slot after an episode start)
// and returns the slot of the pose obj_delay steps earlier.
fn obj_delay_slot(ts: ptr<function, TaskState>, step: u32, started: bool, pos: vec4<f32>, rot: vec4<f32>) -> u32 {
    if (started) {
        for (var k = 0u; k < OBJ_HIST; k++) {
            (*ts).obj_hist_pos[k] = pos;
            (*ts).obj_hist_rot[k] = rot;
        }
    } else {
        (*ts).obj_hist_pos[step % OBJ_HIST] = pos;
        (*ts).obj_hist_rot[step % OBJ_HIST] = rot;
    }
    return (step + OBJ_HIST - (*ts).obj_delay) % OBJ_HIST;
}

fn task_init(env: u32, s: ptr<function, EnvState>) -> TaskState {
    var ts: TaskState;
    ts.targets.wrist_pos = g.init_wrist_pos;
    ts.targets.wrist_rot = g.init_wrist_rot;
    for (var j = 0u; j < g.n_joints; j++) {
        ts.targets.q[j] = joints[j].default_q;
    }
    if (tc.kind != KIND_LIFT) {
        ts.cursor = ref_begin(env, (*s).episode, *s);
        if (tc.start_mode == 0u) {
            let f0 = ref_sample(ts.cursor, 0u, 0u);
            (*s).wrist_pos = f0.wrist_pos;
            (*s).wrist_rot = f0.wrist_rot;
            (*s).wrist_vel = vec4<f32>(0.0);
            (*s).wrist_angvel = vec4<f32>(0.0);
            for (var j = 0u; j < g.n_joints; j++) {
                let jd = joints[j];
                (*s).q[j] = f0.q[j];
                (*s).qd[j] = 0.0;
                if (jd.mimic_leader != NO_JOINT) {
                    (*s).q[j] = jd.mimic_mult * f0.q[jd.mimic_leader] + jd.mimic_offset;
                }
            }
            if (rg.reground == 0u) {
                let o = ref_object_start(ts.cursor);
                (*s).obj_pos = vec4<f32>(o.pos, 0.0);
                (*s).obj_rot = o.rot;
                (*s).obj_vel = vec4<f32>(0.0);
                (*s).obj_angvel = vec4<f32>(0.0);
            }
            ts.targets = nominal_targets(f0);
        }
    }
    ts.rest_pos = vec4<f32>((*s).obj_pos.xyz, 0.0);
    ts.obj_delay = obj_delay_draw(env + g.env_offset, (*s).episode); // the global env id
    return ts;
}

// the actor's noisy view of the state the reference observations are relative to (twin: NoisyState)
var<private> ns_wrist: vec3<f32>;
var<private> ns_obj: vec3<f32>;
var<private> ns_obj_rot: vec4<f32>;
var<private> ns_q: array<f32, MAX_JOINTS>;
var<private> ns_tips: array<vec3<f32>, MAX_TIPS>;

// reference kinds: the frames ref0 … refK relative to the state, the phase and (residual_task) the
// integrated residual over its clamps (after hand_kinematics of st; see the twin)
fn observe_reference(k0: u32, ts: TaskState) -> u32 {
    var k = k0;
    let wp = st.wrist_pos.xyz;
    let wr = st.wrist_rot;
    let op = st.obj_pos.xyz;
    let orot = st.obj_rot;
    for (var i = 0u; i <= tc.lookahead; i++) {
        let f = ref_sample(ts.cursor, st.step, i * tc.lookahead_stride);
        k = put_obs3(k, f.wrist_pos.xyz - wp, f.wrist_pos.xyz - ns_wrist);
        let e = quat_error(f.wrist_rot, wr);
        k = put_obs3(k, e, e);
        for (var a = 0u; a < tc.n_actuated; a++) {
            let j = actuated_joint(a);
            put_obs(k, f.q[j] - st.q[j], f.q[j] - ns_q[a]);
            k++;
        }
        k = put_obs3(k, f.obj_pos.xyz - op, f.obj_pos.xyz - ns_obj);
        k = put_obs3(k, quat_error(f.obj_rot, orot), quat_error(f.obj_rot, ns_obj_rot));
        for (var t = 0u; t < g.n_tips; t++) {
            k = put_obs3(k, f.tips[t].xyz - tip_position(t), f.tips[t].xyz - ns_tips[t]);
        }
    }
    // phase: the reference's progress, 0 at its first frame, 1 from its end on
    let info = ref_info[ts.cursor.ref_id];
    let phase = min(f32(st.step) * ts.cursor.speed / f32(max(info.n_frames, 2u) - 1u), 1.0);
    put_obs(k, phase, phase);
    k++;
    if (tc.kind == KIND_RESIDUAL_TASK) {
        for (var c = 0u; c < tc.n_res; c++) {
            var lim = tc.res_clamp_tips;
            if (c < 3u) {
                lim = tc.res_clamp_wrist_pos;
            } else if (c < 6u) {
                lim = tc.res_clamp_wrist_rot;
            }
            let v = ts.res_delta[c] / max(lim, 1e-9);
            put_obs(k, v, v);
            k++;
        }
    }
    return k;
}

@compute @workgroup_size(64)
fn task_observe(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let env = env_index(gid, nwg);
    if (env >= g.n_envs) {
        return;
    }
    var s0 = states[env];
    var ts = task_states[env];
    let started = reset_mask[env] != 0u || ts.done != 0u;
    if (started) {
        ts = task_init(env, &s0);
        if (tc.kind != KIND_LIFT) {
            states[env] = s0;
        }
    }
    st = s0;
    // the actor's object pose: the one obj_delay observations ago
    let dslot = obj_delay_slot(&ts, st.step, started, st.obj_pos, st.obj_rot);
    task_states[env] = ts;
    write_observation(env, ts, dslot, false, env * tc.obs_dim, g.n_envs * tc.obs_dim + env * tc.priv_dim);
}

// The observations of every env whose episode ends in this step (reset_mask ≠ 0), of the state it
// ended in: dispatched after task_reward and before the resets, it writes final_out and changes no
// state (its task state is a copy).
// An env that the physics already reset for a bad state has no reset request and is not observed
// (it terminated: a learner does not bootstrap from it).
@compute @workgroup_size(64)
fn task_observe_final(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let env = env_index(gid, nwg);
    if (env >= g.n_envs || reset_mask[env] == 0u) {
        return;
    }
    st = states[env];
    var ts = task_states[env];
    let dslot = obj_delay_slot(&ts, st.step, false, st.obj_pos, st.obj_rot);
    write_observation(env, ts, dslot, true, env * tc.obs_dim, g.n_envs * tc.obs_dim + env * tc.priv_dim);
}

// Writes env's actor row at [obs_base..] and critic row at [priv_base..] of task_out (or of
// final_out when `to_final`) from the state in `st` (private), its task state `ts` and the
// delayed object pose's slot `dslot`.
fn write_observation(env: u32, ts: TaskState, dslot: u32, to_final: bool, obs_base: u32, priv_base: u32) {
    let p = params[env];
    hand_kinematics();
    // the noise is keyed by the global env id
    ob_env = env + g.env_offset;
    ob_episode = st.episode;
    ob_step = st.step;
    ob_final = to_final;
    ob_base = obs_base;
    pr_base = priv_base;
    var k = 0u;
    for (var i = 0u; i < tc.n_actuated; i++) {
        let v = st.q[actuated_joint(i)];
        let nv = noisy(k, v, tc.noise_joint_pos);
        ns_q[i] = nv;
        put_obs(k, v, nv);
        k++;
    }
    for (var i = 0u; i < tc.n_actuated; i++) {
        let v = st.qd[actuated_joint(i)];
        put_obs(k, v, noisy(k, v, tc.noise_joint_vel));
        k++;
    }
    for (var i = 0u; i < tc.n_act; i++) {
        put_obs(k, ts.prev_action[i], ts.prev_action[i]);
        k++;
    }
    let wp = st.wrist_pos.xyz;
    var wn = wp;
    for (var c = 0u; c < 3u; c++) {
        wn[c] = noisy(k, wp[c], tc.noise_hand_pos);
        put_obs(k, wp[c], wn[c]);
        k++;
    }
    for (var c = 0u; c < 4u; c++) {
        put_obs(k, st.wrist_rot[c], st.wrist_rot[c]);
        k++;
    }
    for (var t = 0u; t < g.n_tips; t++) {
        let tp = tip_position(t);
        var tn = tp;
        for (var c = 0u; c < 3u; c++) {
            tn[c] = noisy(k, tp[c], tc.noise_hand_pos);
            put_obs(k, tp[c], tn[c]);
            k++;
        }
        ns_tips[t] = tn;
    }
    let op = st.obj_pos.xyz;
    let dp = ts.obj_hist_pos[dslot].xyz;
    var on = dp;
    for (var c = 0u; c < 3u; c++) {
        on[c] = noisy(k, dp[c], tc.noise_object_pos);
        put_obs(k, op[c], on[c]);
        k++;
    }
    let oq = st.obj_rot;
    let dq = ts.obj_hist_rot[dslot];
    var qn = dq;
    for (var c = 0u; c < 4u; c++) {
        qn[c] = noisy(k + c, dq[c], tc.noise_object_rot);
    }
    if (tc.noise_object_rot > 0.0) {
        qn = quat_normalize(qn);
    }
    for (var c = 0u; c < 4u; c++) {
        put_obs(k, oq[c], qn[c]);
        k++;
    }
    if (tc.kind == KIND_LIFT) {
        // goal: the rest position raised by the success height
        let goal = vec3<f32>(ts.rest_pos.x, ts.rest_pos.y, ts.rest_pos.z + tc.success_height);
        for (var c = 0u; c < 3u; c++) {
            put_obs(k, goal[c], goal[c]);
            k++;
        }
        // p_obj − p_palm (the actor's from the noisy object and wrist positions)
        let rel = op - palm_position(wp, st.wrist_rot);
        let rel_n = on - palm_position(wn, st.wrist_rot);
        for (var c = 0u; c < 3u; c++) {
            put_obs(k, rel[c], rel_n[c]);
            k++;
        }
    } else {
        ns_wrist = wn;
        ns_obj = on;
        ns_obj_rot = qn;
        k = observe_reference(k, ts);
    }
    // privileged extras
    for (var c = 0u; c < 3u; c++) {
        put_priv(k, st.obj_vel[c]);
        k++;
    }
    for (var c = 0u; c < 3u; c++) {
        put_priv(k, st.obj_angvel[c]);
        k++;
    }
    for (var c = 0u; c < 3u; c++) {
        put_priv(k, st.wrist_vel[c]);
        k++;
    }
    for (var c = 0u; c < 3u; c++) {
        put_priv(k, st.wrist_angvel[c]);
        k++;
    }
    for (var t = 0u; t < g.n_tips; t++) {
        put_priv(k, select(0.0, 1.0, ts.tip_force[t] > tc.contact_force));
        k++;
    }
    for (var t = 0u; t < g.n_tips; t++) {
        put_priv(k, ts.tip_force[t]);
        k++;
    }
    for (var l = 0u; l < g.n_links; l++) {
        put_priv(k, f32((ts.link_contact[l / 32u] >> (l % 32u)) & 1u));
        k++;
    }
    put_priv(k, p.obj_inertia.w);
    put_priv(k + 1u, p.obj_friction);
    put_priv(k + 2u, p.obj_scale);
    put_priv(k + 3u, p.restitution);
    put_priv(k + 4u, p.added_gravity);
}
