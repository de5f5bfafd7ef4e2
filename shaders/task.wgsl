// task.wgsl — the lift task on top of the physics: actions -> targets, reward terms and dones,
// observations. One invocation per env, three entry points run in this order around the physics:
//   task_act -> step_main -> task_reward -> reset_main -> task_observe
// CPU twin: src/env/task.rs (same function names, same order, same arithmetic; the module doc there
// is the contract and lists the observation layout). This file is appended to common + reset +
// physics: it reuses hand_kinematics and its var<private> memory (st, link_pos, link_rot).

const PURPOSE_OBS_NOISE: u32 = 3u;
// noise draw k of obs entry i at env step s: key = s * OBS_KEY_STRIDE + 2 i + k (k = 0, 1)
const OBS_KEY_STRIDE: u32 = 4096u;
const MAX_ACTIONS: u32 = 32u;
const N_TERMS: u32 = 6u;
// per-env record of the outputs after the obs and priv obs sections of task_out
const OUT_REWARD: u32 = 0u;
const OUT_TERMS: u32 = 1u;
const OUT_TERMINATED: u32 = 7u;
const OUT_TIME_OUT: u32 = 8u;
const OUT_SUCCESS: u32 = 9u;
const OUT_LIFT: u32 = 10u;
const OUT_MAX_PEN: u32 = 11u;
const OUT_MISC: u32 = 12u;

// ---- per-invocation observation cursor (the twin's ObsOut) ----
var<private> ob_env: u32;
var<private> ob_episode: u32;
var<private> ob_step: u32;
var<private> ob_base: u32;
var<private> pr_base: u32;

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

// exp(rv) ⊗ rot, then at most wrist_rot_limit from the initial orientation: exp(e·limit/|e|) ⊗ init
fn wrist_rot_target(rot: vec4<f32>, rv: vec3<f32>) -> vec4<f32> {
    var r = rot;
    let angle = length(rv);
    if (angle > 1e-9) {
        r = quat_normalize(quat_mul(quat_from_axis_angle(rv / angle, angle), rot));
    }
    let init = g.init_wrist_rot;
    let e = quat_error(r, init);
    let d = length(e);
    if (d > tc.wrist_rot_limit) {
        r = quat_normalize(quat_mul(quat_from_axis_angle(e / d, tc.wrist_rot_limit), init));
    }
    return r;
}

@compute @workgroup_size(64)
fn task_act(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let env = env_index(gid, nwg);
    if (env >= g.n_envs) {
        return;
    }
    var ts = task_states[env];
    let base = env * tc.n_act;
    var a: array<f32, 32>;
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
    for (var i = 0u; i < g.n_tips; i++) {
        ts.tip_force[i] = sts.tip_force[i];
        if (i != tc.thumb && sts.tip_force[i] > tc.contact_force) {
            other = true;
        }
    }
    let thumb = sts.tip_force[tc.thumb] > tc.contact_force;
    var raw: array<f32, 6>;
    // reaching 1 − tanh(α d) (tanh saturates at 20: some GPUs' tanh overflows beyond)
    raw[0] = 1.0 - tanh(min(tc.reach_alpha * dist, 20.0));
    // lifting: h in cm, capped at the success height
    raw[1] = clamp(h, 0.0, tc.success_height) * 100.0;
    raw[2] = select(0.0, 1.0, thumb && other);
    raw[3] = select(0.0, 1.0, h >= tc.success_height);
    raw[4] = ts.act_rate;
    raw[5] = ts.act_mag;
    var lift = h;
    if (bad) {
        // the physics already reset this env: its state says nothing about the step
        raw[0] = 0.0;
        raw[1] = 0.0;
        raw[2] = 0.0;
        raw[3] = 0.0;
        lift = 0.0;
    }
    var terminated = bad || obj.z < tc.drop_height || abs(obj.x) > tc.table_half_extent || abs(obj.y) > tc.table_half_extent;
    terminated = terminated || dist > tc.max_hand_distance;
    let time_out = !terminated && s.step >= tc.episode_length;
    let mb = g.n_envs * (tc.obs_dim + tc.priv_dim) + env * OUT_MISC;
    var reward = 0.0;
    for (var k = 0u; k < N_TERMS; k++) {
        // term_k = w_k · raw_k, reward = Σ_k term_k
        let wk = tc.weights[k / 4u][k % 4u] * raw[k];
        task_out[mb + OUT_TERMS + k] = wk;
        reward += wk;
    }
    task_out[mb + OUT_REWARD] = reward;
    task_out[mb + OUT_TERMINATED] = select(0.0, 1.0, terminated);
    task_out[mb + OUT_TIME_OUT] = select(0.0, 1.0, time_out);
    task_out[mb + OUT_SUCCESS] = raw[3];
    task_out[mb + OUT_LIFT] = lift;
    task_out[mb + OUT_MAX_PEN] = sts.max_pen_ho;
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
    task_out[ob_base + k] = noisy_v;
    task_out[pr_base + k] = clean;
}

// critic-only entry k (k >= obs_dim)
fn put_priv(k: u32, v: f32) {
    task_out[pr_base + k] = v;
}

// world position of fingertip t (after hand_kinematics)
fn tip_position(t: u32) -> vec3<f32> {
    let tip = tips[t];
    return link_pos[tip.link] + quat_rotate(link_rot[tip.link], tip.pos.xyz);
}

// the task state of an env that was just reset: default targets, no previous action, rest position
fn task_init(s: EnvState) -> TaskState {
    var ts: TaskState;
    ts.targets.wrist_pos = g.init_wrist_pos;
    ts.targets.wrist_rot = g.init_wrist_rot;
    for (var j = 0u; j < g.n_joints; j++) {
        ts.targets.q[j] = joints[j].default_q;
    }
    ts.rest_pos = vec4<f32>(s.obj_pos.xyz, 0.0);
    return ts;
}

@compute @workgroup_size(64)
fn task_observe(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let env = env_index(gid, nwg);
    if (env >= g.n_envs) {
        return;
    }
    st = states[env];
    let p = params[env];
    var ts = task_states[env];
    if (reset_mask[env] != 0u || ts.done != 0u) {
        ts = task_init(st);
        task_states[env] = ts;
    }
    hand_kinematics();
    ob_env = env;
    ob_episode = st.episode;
    ob_step = st.step;
    ob_base = env * tc.obs_dim;
    pr_base = g.n_envs * tc.obs_dim + env * tc.priv_dim;
    var k = 0u;
    for (var i = 0u; i < tc.n_actuated; i++) {
        let v = st.q[actuated_joint(i)];
        put_obs(k, v, noisy(k, v, tc.noise_joint_pos));
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
        for (var c = 0u; c < 3u; c++) {
            put_obs(k, tp[c], noisy(k, tp[c], tc.noise_hand_pos));
            k++;
        }
    }
    let op = st.obj_pos.xyz;
    var on = op;
    for (var c = 0u; c < 3u; c++) {
        on[c] = noisy(k, op[c], tc.noise_object_pos);
        put_obs(k, op[c], on[c]);
        k++;
    }
    let oq = st.obj_rot;
    var qn = oq;
    for (var c = 0u; c < 4u; c++) {
        qn[c] = noisy(k + c, oq[c], tc.noise_object_rot);
    }
    if (tc.noise_object_rot > 0.0) {
        qn = quat_normalize(qn);
    }
    for (var c = 0u; c < 4u; c++) {
        put_obs(k, oq[c], qn[c]);
        k++;
    }
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
    put_priv(k, p.obj_inertia.w);
    put_priv(k + 1u, p.obj_friction);
    put_priv(k + 2u, p.obj_scale);
}
