//! CPU twin of `shaders/reset.wgsl`: randomised physical parameters and initial states.
//! Same function names, same order, same arithmetic as the shader.

use glam::{Vec3, Vec4};

use super::common::{quat_from_axis_angle, rand_uniform};
use crate::gpu::layout::*;

/// Purposes of the counter-based RNG (keep in sync with reset.wgsl `PURPOSE_*`).
pub const PURPOSE_PARAMS: u32 = 1;
pub const PURPOSE_INIT: u32 = 2;

/// Uniform draw in [lo, hi] for (env, episode, purpose, k).
pub fn rand_range(g: &Globals, env: u32, episode: u32, purpose: u32, k: u32, lo: f32, hi: f32) -> f32 {
    lo + (hi - lo) * rand_uniform(g.seed, env.wrapping_add(g.env_offset), episode, purpose, k) // keyed by the global env id
}

/// Damping ratio of a spring-damper contact whose coefficient of restitution is `e`:
/// ζ = −ln e / √(π² + ln² e); ζ = 1 (critical) for e → 0.
pub fn damping_ratio(e: f32) -> f32 {
    if e < 1e-3 {
        return 1.0;
    }
    let l = e.ln();
    -l / (9.8696044 + l * l).sqrt()
}

/// The reference draw of `reference.wgsl` (`ref_begin`): purpose and key (keep in sync with
/// `env::reference::PURPOSE_REF`, `REF_KEY_ID`).
pub const PURPOSE_REF_DRAW: u32 = 4;
pub const REF_KEY_ID_DRAW: u32 = 0;

/// Draws the physical parameters of `env` for `episode`, the object among `objects` included:
/// uniformly, or — when the references name their objects (`ref_objects[r]`, `NO_OBJECT` for one
/// that names none) — the object of the reference the task layer draws for this episode.
pub fn reset_params(g: &Globals, objects: &[ObjectDesc], ref_objects: &[u32], env: u32, episode: u32) -> EnvParams {
    let pp = PURPOSE_PARAMS;
    let mut p = EnvParams::default_zeroed();
    // the object: ⌊u · n⌋, clamped (u < 1, but f32 rounding of u · n could reach n)
    p.obj_index = ((rand_uniform(g.seed, env.wrapping_add(g.env_offset), episode, pp, 11) * g.n_objects as f32) as u32).min(g.n_objects - 1);
    if g.n_ref_objects > 0 {
        // the reference's draw, as ref_begin makes it
        let u = rand_uniform(g.seed, env.wrapping_add(g.env_offset), episode, PURPOSE_REF_DRAW, REF_KEY_ID_DRAW);
        let o = ref_objects[((u * g.n_ref_objects as f32) as u32).min(g.n_ref_objects - 1) as usize];
        if o != NO_OBJECT {
            p.obj_index = o;
        }
    }
    let od = &objects[p.obj_index as usize];
    p.hand_mass_scale = rand_range(g, env, episode, pp, 0, g.rnd[0][0], g.rnd[0][1]);
    p.hand_friction = g.hand_friction * rand_range(g, env, episode, pp, 1, g.rnd[0][2], g.rnd[0][3]);
    p.limit_scale = rand_range(g, env, episode, pp, 2, g.rnd[1][0], g.rnd[1][1]);
    p.kp_scale = rand_range(g, env, episode, pp, 3, g.rnd[1][2], g.rnd[1][3]);
    p.kd_scale = rand_range(g, env, episode, pp, 4, g.rnd[2][0], g.rnd[2][1]);
    let mass = od.inertia[3] * rand_range(g, env, episode, pp, 5, g.rnd[2][2], g.rnd[2][3]);
    p.obj_friction = g.obj_friction * rand_range(g, env, episode, pp, 6, g.rnd[3][0], g.rnd[3][1]);
    p.obj_scale = rand_range(g, env, episode, pp, 7, g.rnd[3][2], g.rnd[3][3]);
    p.restitution = rand_range(g, env, episode, pp, 8, g.rnd[4][0], g.rnd[4][1]);
    p.table_friction = g.table_friction * rand_range(g, env, episode, pp, 9, g.rnd[4][2], g.rnd[4][3]);
    p.added_gravity = rand_range(g, env, episode, pp, 10, g.rnd[5][0], g.rnd[5][1]);
    let sc = p.obj_scale;
    p.obj_com = [od.com[0] * sc, od.com[1] * sc, od.com[2] * sc, od.com[3] * sc];
    p.obj_rest_height = od.rest_height * sc;
    // I = (I/m) · m · s² (every length scaled by s)
    let inertia = Vec3::new(od.inertia[0], od.inertia[1], od.inertia[2]) * (mass * sc * sc);
    p.obj_inertia = [inertia.x, inertia.y, inertia.z, mass];
    // reduced mass of a hand link and the object: m_h m_o / (m_h + m_o)
    let m_red = g.hand_eff_mass * mass / (g.hand_eff_mass + mass);
    // c = 2 ζ √(k m)
    p.obj_contact_c = 2.0 * damping_ratio(p.restitution) * (g.contact_k * m_red).sqrt();
    p.hand_table_c = 2.0 * (g.contact_k * g.hand_eff_mass).sqrt();
    p
}

/// The initial state of `env` for `episode`: wrist at its initial pose, joints at their defaults
/// (clamped into the env's scaled limits), the object resting on the table at its (noisy) place.
pub fn reset_state(g: &Globals, joints: &[JointDesc], p: &EnvParams, env: u32, episode: u32, bad_resets: u32) -> EnvState {
    let mut s = EnvState::default();
    s.wrist_pos = g.init_wrist_pos;
    s.wrist_rot = g.init_wrist_rot;
    for j in 0..g.n_joints as usize {
        let jd = &joints[j];
        let lo = jd.lower * p.limit_scale;
        let hi = jd.upper * p.limit_scale;
        s.q[j] = jd.default_q.clamp(lo, hi);
    }
    for j in 0..g.n_joints as usize {
        let jd = &joints[j];
        if jd.mimic_leader != NO_JOINT {
            s.q[j] = jd.mimic_mult * s.q[jd.mimic_leader as usize] + jd.mimic_offset;
        }
    }
    let pi = PURPOSE_INIT;
    let x = g.obj_init[0] + rand_range(g, env, episode, pi, 0, -g.rnd[5][2], g.rnd[5][2]);
    let y = g.obj_init[1] + rand_range(g, env, episode, pi, 1, -g.rnd[5][3], g.rnd[5][3]);
    let yaw = g.obj_init[2] + rand_range(g, env, episode, pi, 2, -g.yaw_noise, g.yaw_noise);
    s.obj_pos = [x, y, p.obj_rest_height, 0.0];
    let rot: Vec4 = quat_from_axis_angle(Vec3::Z, yaw);
    s.obj_rot = rot.to_array();
    s.episode = episode;
    s.bad_resets = bad_resets;
    s
}

impl EnvParams {
    fn default_zeroed() -> Self {
        bytemuck::Zeroable::zeroed()
    }
}

/// Zeroes an env's contact springs (`[n_springs]`: no contact, no stretched spring).
pub fn clear_springs(springs: &mut [[f32; 4]]) {
    springs.fill([0.0; 4]);
}
