// reset.wgsl — randomised physical parameters and initial states.
// CPU twin: src/env/reset.rs (same function names, same order, same arithmetic).

const PURPOSE_PARAMS: u32 = 1u;
const PURPOSE_INIT: u32 = 2u;
// the reference draw of reference.wgsl's ref_begin (PURPOSE_REF, REF_KEY_ID)
const PURPOSE_REF_DRAW: u32 = 4u;
const REF_KEY_ID_DRAW: u32 = 0u;

fn rand_range(env: u32, episode: u32, purpose: u32, k: u32, lo: f32, hi: f32) -> f32 {
    return lo + (hi - lo) * rand_uniform(g.seed, env + g.env_offset, episode, purpose, k); // keyed by the global env id
}

// ζ = −ln e / √(π² + ln² e); ζ = 1 for e → 0
fn damping_ratio(e: f32) -> f32 {
    if (e < 1e-3) {
        return 1.0;
    }
    let l = log(e);
    return -l / sqrt(9.8696044 + l * l);
}

fn reset_params(env: u32, episode: u32) -> EnvParams {
    let pp = PURPOSE_PARAMS;
    var p: EnvParams;
    // the object: ⌊u · n⌋, clamped (u < 1, but f32 rounding of u · n could reach n)
    p.obj_index = min(u32(rand_uniform(g.seed, env + g.env_offset, episode, pp, 11u) * f32(g.n_objects)), g.n_objects - 1u);
    if (g.n_ref_objects > 0u) {
        // the reference's draw, as ref_begin makes it
        let u = rand_uniform(g.seed, env + g.env_offset, episode, PURPOSE_REF_DRAW, REF_KEY_ID_DRAW);
        let o = ref_objects[min(u32(u * f32(g.n_ref_objects)), g.n_ref_objects - 1u)];
        if (o != NO_OBJECT) {
            p.obj_index = o;
        }
    }
    let od = objects[p.obj_index];
    p.hand_mass_scale = rand_range(env, episode, pp, 0u, g.rnd[0].x, g.rnd[0].y);
    p.hand_friction = g.hand_friction * rand_range(env, episode, pp, 1u, g.rnd[0].z, g.rnd[0].w);
    p.limit_scale = rand_range(env, episode, pp, 2u, g.rnd[1].x, g.rnd[1].y);
    p.kp_scale = rand_range(env, episode, pp, 3u, g.rnd[1].z, g.rnd[1].w);
    p.kd_scale = rand_range(env, episode, pp, 4u, g.rnd[2].x, g.rnd[2].y);
    let mass = od.inertia.w * rand_range(env, episode, pp, 5u, g.rnd[2].z, g.rnd[2].w);
    p.obj_friction = g.obj_friction * rand_range(env, episode, pp, 6u, g.rnd[3].x, g.rnd[3].y);
    p.obj_scale = rand_range(env, episode, pp, 7u, g.rnd[3].z, g.rnd[3].w);
    p.restitution = rand_range(env, episode, pp, 8u, g.rnd[4].x, g.rnd[4].y);
    p.table_friction = g.table_friction * rand_range(env, episode, pp, 9u, g.rnd[4].z, g.rnd[4].w);
    p.added_gravity = rand_range(env, episode, pp, 10u, g.rnd[5].x, g.rnd[5].y);
    let sc = p.obj_scale;
    p.obj_com = od.com * sc;
    p.obj_rest_height = od.rest_height * sc;
    // I = (I/m) · m · s² (every length scaled by s)
    let inertia = od.inertia.xyz * (mass * sc * sc);
    p.obj_inertia = vec4<f32>(inertia, mass);
    // reduced mass m_h m_o / (m_h + m_o)
    let m_red = g.hand_eff_mass * mass / (g.hand_eff_mass + mass);
    // c = 2 ζ √(k m)
    p.obj_contact_c = 2.0 * damping_ratio(p.restitution) * sqrt(g.contact_k * m_red);
    p.hand_table_c = 2.0 * sqrt(g.contact_k * g.hand_eff_mass);
    return p;
}

fn reset_state(p: EnvParams, env: u32, episode: u32, bad_resets: u32) -> EnvState {
    var s: EnvState;
    s.wrist_pos = g.init_wrist_pos;
    s.wrist_rot = g.init_wrist_rot;
    for (var j = 0u; j < g.n_joints; j++) {
        let jd = joints[j];
        let lo = jd.lower * p.limit_scale;
        let hi = jd.upper * p.limit_scale;
        s.q[j] = clamp(jd.default_q, lo, hi);
    }
    for (var j = 0u; j < g.n_joints; j++) {
        let jd = joints[j];
        if (jd.mimic_leader != NO_JOINT) {
            s.q[j] = jd.mimic_mult * s.q[jd.mimic_leader] + jd.mimic_offset;
        }
    }
    let pi = PURPOSE_INIT;
    let x = g.obj_init.x + rand_range(env, episode, pi, 0u, -g.rnd[5].z, g.rnd[5].z);
    let y = g.obj_init.y + rand_range(env, episode, pi, 1u, -g.rnd[5].w, g.rnd[5].w);
    let yaw = g.obj_init.z + rand_range(env, episode, pi, 2u, -g.yaw_noise, g.yaw_noise);
    s.obj_pos = vec4<f32>(x, y, p.obj_rest_height, 0.0);
    s.obj_rot = quat_from_axis_angle(vec3<f32>(0.0, 0.0, 1.0), yaw);
    s.episode = episode;
    s.bad_resets = bad_resets;
    return s;
}

// Zeroes env `env`'s contact springs (no contact, no stretched spring).
fn clear_springs(env: u32) {
    let base = env * g.n_springs;
    for (var i = 0u; i < g.n_springs; i++) {
        springs[base + i] = vec4<f32>(0.0);
    }
}

@compute @workgroup_size(64)
fn reset_main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let env = env_index(gid, nwg);
    if (env >= g.n_envs) {
        return;
    }
    let req = reset_mask[env];
    if (req == 0u) {
        return;
    }
    let old = states[env];
    var episode = 0u;
    if (req == 1u) {
        episode = old.episode + 1u;
    }
    let p = reset_params(env, episode);
    params[env] = p;
    states[env] = reset_state(p, env, episode, old.bad_resets);
    clear_springs(env);
}
