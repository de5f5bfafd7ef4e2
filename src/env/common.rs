//! CPU twin of `shaders/common.wgsl`: quaternion maths and the counter-based hash RNG.
//! Same function names, same order, same arithmetic as the shader.
//!
//! Quaternions are `Vec4` (x, y, z, w).

use glam::{Vec3, Vec4};

/// Hamilton product `a ⊗ b`.
pub fn quat_mul(a: Vec4, b: Vec4) -> Vec4 {
    Vec4::new(
        a.w * b.x + a.x * b.w + a.y * b.z - a.z * b.y,
        a.w * b.y - a.x * b.z + a.y * b.w + a.z * b.x,
        a.w * b.z + a.x * b.y - a.y * b.x + a.z * b.w,
        a.w * b.w - a.x * b.x - a.y * b.y - a.z * b.z,
    )
}

/// Conjugate (= inverse of a unit quaternion).
pub fn quat_conj(q: Vec4) -> Vec4 {
    Vec4::new(-q.x, -q.y, -q.z, q.w)
}

/// Rotates `v` by the unit quaternion `q`: v + 2w(u×v) + 2u×(u×v).
pub fn quat_rotate(q: Vec4, v: Vec3) -> Vec3 {
    let u = Vec3::new(q.x, q.y, q.z);
    let t = 2.0 * u.cross(v);
    v + q.w * t + u.cross(t)
}

/// The columns of the rotation matrix of the unit quaternion `q` (R·x̂, R·ŷ, R·ẑ: `quat_rotate` of
/// each axis, in fewer operations).
pub fn quat_axes(q: Vec4) -> [Vec3; 3] {
    let (x, y, z, w) = (q.x, q.y, q.z, q.w);
    [
        Vec3::new(1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y + z * w), 2.0 * (x * z - y * w)),
        Vec3::new(2.0 * (x * y - z * w), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z + x * w)),
        Vec3::new(2.0 * (x * z + y * w), 2.0 * (y * z - x * w), 1.0 - 2.0 * (x * x + y * y)),
    ]
}

pub fn quat_normalize(q: Vec4) -> Vec4 {
    q / q.dot(q).sqrt()
}

/// Rotation of `angle` about the unit `axis`.
pub fn quat_from_axis_angle(axis: Vec3, angle: f32) -> Vec4 {
    let s = (0.5 * angle).sin();
    Vec4::new(axis.x * s, axis.y * s, axis.z * s, (0.5 * angle).cos())
}

/// Advances `q` by the world angular velocity `w` over `h`: q' = exp(w h / 2) ⊗ q.
pub fn quat_integrate(q: Vec4, w: Vec3, h: f32) -> Vec4 {
    let angle = w.length() * h;
    if angle < 1e-9 {
        return q;
    }
    let dq = quat_from_axis_angle(w / w.length(), angle);
    quat_normalize(quat_mul(dq, q))
}

/// Rotation vector (axis · angle, world) that takes `q` to `goal`: log(goal ⊗ q⁻¹), shortest arc.
pub fn quat_error(goal: Vec4, q: Vec4) -> Vec3 {
    let mut e = quat_mul(goal, quat_conj(q));
    if e.w < 0.0 {
        e = -e;
    }
    let v = Vec3::new(e.x, e.y, e.z);
    let s = v.length();
    if s < 1e-9 {
        return 2.0 * v;
    }
    v * (2.0 * s.atan2(e.w) / s)
}

/// PCG hash (Jarzynski & Olano 2020) of one u32.
pub fn pcg_hash(v: u32) -> u32 {
    let state = v.wrapping_mul(747796405).wrapping_add(2891336453);
    let word = ((state >> ((state >> 28) + 4)) ^ state).wrapping_mul(277803737);
    (word >> 22) ^ word
}

/// Counter-based random u32 of (seed, env, episode, purpose, k): no state to store or synchronise.
pub fn rand_u32(seed: u32, env: u32, episode: u32, purpose: u32, k: u32) -> u32 {
    pcg_hash(pcg_hash(pcg_hash(pcg_hash(pcg_hash(seed) ^ env) ^ episode) ^ purpose) ^ k)
}

/// Uniform in [0, 1) with 24 random bits (exact in f32 on both backends).
pub fn rand_uniform(seed: u32, env: u32, episode: u32, purpose: u32, k: u32) -> f32 {
    (rand_u32(seed, env, episode, purpose, k) >> 8) as f32 * (1.0 / 16777216.0)
}
