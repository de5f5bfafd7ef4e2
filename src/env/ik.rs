//! CPU twin of `shaders/ik.wgsl`: damped least-squares inverse kinematics of the fingertips.
//! Same function names, same order, same arithmetic as the shader; [`IkScratch`] is the shader's
//! `var<private>` memory (`ik_*`).
//!
//! Everything here is in the **wrist frame**: the root link sits at the identity pose, so the result
//! depends on the joint vector only, never on an env's state. A joint vector `q` holds every model
//! joint, mimic followers included (`[f32; MAX_JOINTS]`, the layout of `EnvState::q`).
//!
//! **Forward kinematics.** Link `l > 0` is moved by joint `l − 1`, whose frame sits at `origin_*` in
//! its parent link (`ik_joint_frame`, the same per-joint arithmetic as `physics::hand_kinematics`).
//! `ik_link_poses` walks every joint in topological order; a fingertip's position (link pose ·
//! `TipDesc::pos`) is computed along its own chain only (`ik_chain` walks from the tip's link up to
//! the root, `ik_chain_fk` back down), and `ik_tip_positions` and the solver use that same code, so
//! a target taken from `ik_tip_positions(q)` gives a residual of exactly zero at `q`.
//!
//! **Solver** (`ik_solve`): a fixed number of sweeps (`IkParams::iters`); each sweep visits the
//! active fingertips (bit `t` of `mask`) in index order, and for fingertip t (`ik_tip_step`):
//! 1. chain FK: tip position p, world axis aⱼ and origin oⱼ of every joint j on its chain;
//! 2. e = x*ₜ − p; if |e| ≤ `tol` (an exact zero included) the tip is left alone;
//! 3. one Jacobian column per *actuated* joint k that moves the tip:
//!    cₖ = Σ_{j on the chain, j = k or j follows k} wⱼ · aⱼ × (p − oⱼ), with wⱼ = 1 for k itself and
//!    the mimic multiplier for a follower (q_f = mult·q_k + offset), so a leader that is not on the
//!    chain still moves the tip through its follower;
//! 4. damped least squares: Δq = Jᵀ (J Jᵀ + λ² I)⁻¹ e, a 3×3 SPD solve (Cholesky, `ik_solve3`),
//!    Δqₖ = cₖ · y with y = (Σₖ cₖ cₖᵀ + λ² I)⁻¹ e;
//! 5. the step is scaled (direction kept) so that max |Δqₖ| ≤ `max_step`, each qₖ is clamped to its
//!    joint limits (`lower`, `upper` of `JointDesc`; ±1e30 = unlimited), and every follower is
//!    recomputed from its leader (`ik_apply_mimic`).
//!
//! Fingertips that share a joint (tri3's wrist roll and mimic-coupled spread, a palm joint) are
//! handled **sequentially** (block Gauss–Seidel / Kaczmarz): each tip's step starts from the joints
//! the previous tips of the sweep left, so a shared joint is never moved twice by stale Jacobians,
//! and the sweeps converge to a joint vector that satisfies every consistent target. A sweep in which
//! no tip moved ends the solve early; since such a sweep leaves `q` unchanged, every further sweep
//! would too, so the early exit never changes the result.
//!
//! Exactness: if every active target equals `ik_tip_positions(q_seed)`, every residual is exactly
//! zero, no tip moves and `ik_solve` returns `q_seed` bit for bit (followers and out-of-limit
//! entries included). Joints that are on no active chain (and lead no follower on one) are never
//! written. NaN or infinite targets leave their tip alone (the residual test and the finite-step
//! test both fail for NaN), so the result stays finite.

use bytemuck::{Pod, Zeroable};
use glam::{Vec3, Vec4};

use super::common::*;
use super::layout::*;
use super::physics::{MAX_LINKS, Model};
use crate::hand::{MAX_JOINTS, MAX_TIPS};

/// Default sweeps of [`ik_solve`]. Measured (tests/ik.rs): from the default seed (straight fingers, a
/// singular pose) to random reachable targets, the worst fingertip error over 400 targets per shipped
/// hand is well under 1 mm after 24 sweeps; from a seed within 0.3 rad, a handful of sweeps suffice
/// and the early exit ends the solve.
pub const IK_ITERS: u32 = 24;
/// Default damping λ (m) of `(J Jᵀ + λ² I)`: small against the fingers' lever arms (3–15 cm, so
/// convergence is fast away from singularities) and large enough to bound the step near a
/// straight finger (|Δq| ≤ |e| / 2λ).
pub const IK_DAMPING: f32 = 0.01;
/// Default largest joint change (rad) of one tip step: keeps far targets from flinging a finger
/// through half a turn on a linearisation that only holds near the current pose.
pub const IK_MAX_STEP: f32 = 0.3;
/// Default residual (m) at or below which a fingertip counts as reached and is left alone. Small
/// enough that stopping one step earlier or later (CPU vs GPU rounding around the threshold) changes
/// a joint by less than 1e-5 rad (|Δq| ≤ tol / 2λ), and above the f32 noise of the kinematics
/// (~1e-8 m), so converged solves exit early.
pub const IK_TOL: f32 = 1e-7;

/// Block Gauss–Seidel sweeps of the stacked solve per iteration when active chains share a joint
/// (tri3's wrist roll); one sweep is exact for independent chains.
pub const IK_SWEEPS: u32 = 4;

/// Solver settings (WGSL `IkParams`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable, PartialEq)]
pub struct IkParams {
    /// Sweeps over the active fingertips (the loop bound; a sweep that moves nothing ends early).
    pub iters: u32,
    /// λ (m), must be > 0.
    pub damping: f32,
    /// Largest joint change of one tip step (rad), > 0.
    pub max_step: f32,
    /// Residual (m) at or below which a fingertip is left alone, ≥ 0.
    pub tol: f32,
}

impl Default for IkParams {
    /// [`IK_ITERS`], [`IK_DAMPING`], [`IK_MAX_STEP`], [`IK_TOL`].
    fn default() -> Self {
        IkParams { iters: IK_ITERS, damping: IK_DAMPING, max_step: IK_MAX_STEP, tol: IK_TOL }
    }
}

/// One joint's frame in the wrist frame (WGSL `IkFrame`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IkFrame {
    /// Joint origin = position of the child link.
    pub origin: Vec3,
    /// Unit joint axis.
    pub axis: Vec3,
    /// Orientation of the child link (xyzw).
    pub rot: Vec4,
}

/// Per-invocation working memory (the shader's `var<private>` `ik_*` variables).
#[derive(Clone)]
pub struct IkScratch {
    /// Link poses of `ik_link_poses` (wrist frame).
    pub link_pos: [Vec3; MAX_LINKS],
    pub link_rot: [Vec4; MAX_LINKS],
    /// Joints of the current chain, root → tip (`ik_chain`), and how many (`ik_tip_jacobian`).
    pub chain_j: [u32; MAX_JOINTS],
    pub chain_n: usize,
    /// The actuated joint whose Jacobian column chain entry i carries (at the first entry driven by
    /// each unlocked leader), `NO_JOINT` for the others.
    pub chain_k: [u32; MAX_JOINTS],
    /// World origin and axis of each chain joint (`ik_chain_fk`).
    pub chain_o: [Vec3; MAX_JOINTS],
    pub chain_a: [Vec3; MAX_JOINTS],
    /// Jacobian column cₖ of chain entry i (zero when `chain_k[i]` is `NO_JOINT`).
    pub chain_c: [Vec3; MAX_JOINTS],
    /// Active fingertips whose chain each actuated joint drives (`ik_share`).
    pub share: [u32; MAX_JOINTS],
    /// 1 for a joint locked at a limit during the current iteration.
    pub lock: [u32; MAX_JOINTS],
    /// The step Δq = Jᵀ y and the multipliers y of each tip (`ik_dls_step`).
    pub dq: [f32; MAX_JOINTS],
    pub y: [Vec3; MAX_TIPS],
    /// The solver's joint vector.
    pub q: [f32; MAX_JOINTS],
}

impl Default for IkScratch {
    fn default() -> Self {
        IkScratch {
            link_pos: [Vec3::ZERO; MAX_LINKS],
            link_rot: [Vec4::W; MAX_LINKS],
            chain_j: [0; MAX_JOINTS],
            chain_n: 0,
            chain_k: [NO_JOINT; MAX_JOINTS],
            chain_o: [Vec3::ZERO; MAX_JOINTS],
            chain_a: [Vec3::ZERO; MAX_JOINTS],
            chain_c: [Vec3::ZERO; MAX_JOINTS],
            share: [0; MAX_JOINTS],
            lock: [0; MAX_JOINTS],
            dq: [0.0; MAX_JOINTS],
            y: [Vec3::ZERO; MAX_TIPS],
            q: [0.0; MAX_JOINTS],
        }
    }
}

fn v3(a: [f32; 4]) -> Vec3 {
    Vec3::new(a[0], a[1], a[2])
}

fn v4(a: [f32; 4]) -> Vec4 {
    Vec4::from_array(a)
}

/// Frame of joint `jd` at angle `q`, given its parent link's pose (wrist frame).
pub fn ik_joint_frame(jd: &JointDesc, parent_pos: Vec3, parent_rot: Vec4, q: f32) -> IkFrame {
    let frame_rot = quat_mul(parent_rot, v4(jd.origin_rot));
    // o = p_parent + R_parent · origin
    let origin = parent_pos + quat_rotate(parent_rot, v3(jd.origin_pos));
    let axis = quat_rotate(frame_rot, v3(jd.axis));
    // R_child = R_parent ⊗ R_origin ⊗ R(axis, q)
    let rot = quat_mul(frame_rot, quat_from_axis_angle(v3(jd.axis), q));
    IkFrame { origin, axis, rot }
}

/// Every link's pose in the wrist frame (root at the identity) into `s.link_pos` / `s.link_rot`.
pub fn ik_link_poses(m: &Model, q: &[f32; MAX_JOINTS], s: &mut IkScratch) {
    s.link_pos[0] = Vec3::ZERO;
    s.link_rot[0] = Vec4::W;
    for j in 0..m.g.n_joints as usize {
        let p = m.joints[j].parent_link as usize;
        let f = ik_joint_frame(&m.joints[j], s.link_pos[p], s.link_rot[p], q[j]);
        s.link_pos[j + 1] = f.origin;
        s.link_rot[j + 1] = f.rot;
    }
}

/// Sets every mimic follower from its leader: q_f = mult · q_leader + offset.
pub fn ik_apply_mimic(m: &Model, q: &mut [f32; MAX_JOINTS]) {
    for j in 0..m.g.n_joints as usize {
        let jd = &m.joints[j];
        if jd.mimic_leader != NO_JOINT {
            q[j] = jd.mimic_mult * q[jd.mimic_leader as usize] + jd.mimic_offset;
        }
    }
}

/// The joints that move fingertip `t`, root → tip, into `s.chain_j`; returns how many.
pub fn ik_chain(m: &Model, t: usize, s: &mut IkScratch) -> usize {
    // walk up: link l is moved by joint l − 1, whose parent link is next
    let mut n = 0;
    let mut link = m.tips[t].link;
    for _ in 0..MAX_JOINTS {
        if link == 0 {
            break;
        }
        let j = link - 1;
        s.chain_j[n] = j;
        n += 1;
        link = m.joints[j as usize].parent_link;
    }
    // reverse into root → tip order
    for i in 0..n / 2 {
        let a = s.chain_j[i];
        s.chain_j[i] = s.chain_j[n - 1 - i];
        s.chain_j[n - 1 - i] = a;
    }
    n
}

/// FK along the chain of `ik_chain` (`n` joints): the origin and axis of each chain joint into
/// `s.chain_o` / `s.chain_a`; returns fingertip `t`'s position (wrist frame).
pub fn ik_chain_fk(m: &Model, t: usize, n: usize, q: &[f32; MAX_JOINTS], s: &mut IkScratch) -> Vec3 {
    let mut pos = Vec3::ZERO;
    let mut rot = Vec4::W;
    for i in 0..n {
        let j = s.chain_j[i] as usize;
        let f = ik_joint_frame(&m.joints[j], pos, rot, q[j]);
        s.chain_o[i] = f.origin;
        s.chain_a[i] = f.axis;
        pos = f.origin;
        rot = f.rot;
    }
    // x_tip = p_link + R_link · tip.pos
    pos + quat_rotate(rot, v3(m.tips[t].pos))
}

/// Every fingertip's position (wrist frame) at `q`; entries past `n_tips` are zero.
pub fn ik_tip_positions(m: &Model, q: &[f32; MAX_JOINTS], s: &mut IkScratch) -> [Vec3; MAX_TIPS] {
    let mut out = [Vec3::ZERO; MAX_TIPS];
    for t in 0..m.g.n_tips as usize {
        let n = ik_chain(m, t, s);
        out[t] = ik_chain_fk(m, t, n, q, s);
    }
    out
}

/// Solves A x = b for a symmetric positive definite 3×3 A given as (a00, a01, a02, a11, a12, a22),
/// by Cholesky (A = L Lᵀ).
pub fn ik_solve3(a: [f32; 6], b: Vec3) -> Vec3 {
    let l00 = a[0].max(1e-20).sqrt();
    let l10 = a[1] / l00;
    let l20 = a[2] / l00;
    let l11 = (a[3] - l10 * l10).max(1e-20).sqrt();
    let l21 = (a[4] - l20 * l10) / l11;
    let l22 = (a[5] - l20 * l20 - l21 * l21).max(1e-20).sqrt();
    // L y = b
    let y0 = b.x / l00;
    let y1 = (b.y - l10 * y0) / l11;
    let y2 = (b.z - l20 * y0 - l21 * y1) / l22;
    // Lᵀ x = y
    let x2 = y2 / l22;
    let x1 = (y1 - l21 * x2) / l11;
    let x0 = (y0 - l10 * x1 - l20 * x2) / l00;
    Vec3::new(x0, x1, x2)
}

/// Actuated joint that drives joint `j`: itself, or its mimic leader.
pub fn ik_leader(m: &Model, j: u32) -> u32 {
    let l = m.joints[j as usize].mimic_leader;
    if l != NO_JOINT { l } else { j }
}

/// Counts, for every actuated joint k, the active fingertips (bit t of `mask`) whose chain it drives
/// (itself or through a follower) into `s.share`; returns the largest count (> 1: the active chains
/// are coupled).
pub fn ik_share(m: &Model, mask: u32, s: &mut IkScratch) -> u32 {
    for k in 0..MAX_JOINTS {
        s.share[k] = 0;
    }
    let mut most = 0;
    for t in 0..m.g.n_tips as usize {
        if ((mask >> t) & 1) != 0 {
            let n = ik_chain(m, t, s);
            for i in 0..n {
                let k = ik_leader(m, s.chain_j[i]) as usize;
                // once per tip: skip a leader that an earlier entry of this chain already counted
                let mut first = true;
                for i2 in 0..i {
                    if ik_leader(m, s.chain_j[i2]) as usize == k {
                        first = false;
                    }
                }
                if first {
                    s.share[k] += 1;
                    most = most.max(s.share[k]);
                }
            }
        }
    }
    most
}

/// Chain FK of fingertip `t` at `s.q` and its Jacobian: for each actuated joint k that moves the tip
/// and is not locked, the column cₖ = Σ_{j on the chain driven by k} wⱼ aⱼ × (p − oⱼ) (wⱼ = 1 for k,
/// the mimic multiplier for its followers), kept at k's first chain entry (`s.chain_k`,
/// `s.chain_c`; other entries get `NO_JOINT` and a zero column). Returns e = target − p.
pub fn ik_tip_jacobian(m: &Model, t: usize, target: Vec3, s: &mut IkScratch) -> Vec3 {
    let n = ik_chain(m, t, s);
    s.chain_n = n;
    let q = s.q;
    let p = ik_chain_fk(m, t, n, &q, s);
    for i in 0..n {
        let k = ik_leader(m, s.chain_j[i]);
        // the first chain entry driven by k carries k's column
        let mut first = true;
        for i2 in 0..i {
            if ik_leader(m, s.chain_j[i2]) == k {
                first = false;
            }
        }
        let mut c = Vec3::ZERO;
        s.chain_k[i] = NO_JOINT;
        if first && s.lock[k as usize] == 0 {
            s.chain_k[i] = k;
            for i2 in i..n {
                let j2 = s.chain_j[i2];
                if ik_leader(m, j2) == k {
                    let w = if j2 == k { 1.0 } else { m.joints[j2 as usize].mimic_mult };
                    // cₖ += w aⱼ × (p − oⱼ)
                    c += w * s.chain_a[i2].cross(p - s.chain_o[i2]);
                }
            }
        }
        s.chain_c[i] = c;
    }
    // e = x* − x
    target - p
}

/// Jₜ Jₜᵀ + λ² I = Σᵢ cᵢ cᵢᵀ + λ² I over the columns of `ik_tip_jacobian`, as
/// (a00, a01, a02, a11, a12, a22).
pub fn ik_normal_matrix(damping: f32, s: &IkScratch) -> [f32; 6] {
    let l2 = damping * damping;
    let mut a = [l2, 0.0, 0.0, l2, 0.0, l2];
    for i in 0..s.chain_n {
        let c = s.chain_c[i];
        a[0] += c.x * c.x;
        a[1] += c.x * c.y;
        a[2] += c.x * c.z;
        a[3] += c.y * c.y;
        a[4] += c.y * c.z;
        a[5] += c.z * c.z;
    }
    a
}

/// One block Gauss–Seidel update of fingertip `t`'s rows of (J Jᵀ + λ² I) y = e, the stacked DLS
/// system of all active tips: rₜ = eₜ − Jₜ Δq − λ² yₜ, δ = (Jₜ Jₜᵀ + λ² I)⁻¹ rₜ, yₜ += δ,
/// Δq += Jₜᵀ δ (Δq = Jᵀ y is kept in `s.dq`, yₜ in `s.y`).
pub fn ik_block_update(m: &Model, t: usize, target: Vec3, damping: f32, s: &mut IkScratch) {
    let e = ik_tip_jacobian(m, t, target, s);
    // a non-finite target (NaN, ±inf) takes no part in the solve
    if !(e.length() < 1e30) {
        return;
    }
    // rₜ = eₜ − Jₜ Δq − λ² yₜ
    let mut r = e - damping * damping * s.y[t];
    for i in 0..s.chain_n {
        let k = s.chain_k[i];
        if k != NO_JOINT {
            r -= s.chain_c[i] * s.dq[k as usize];
        }
    }
    let d = ik_solve3(ik_normal_matrix(damping, s), r);
    s.y[t] += d;
    // Δqₖ += cₖ · δ
    for i in 0..s.chain_n {
        let k = s.chain_k[i];
        if k != NO_JOINT {
            s.dq[k as usize] += s.chain_c[i].dot(d);
        }
    }
}

/// Δq = Jᵀ (J Jᵀ + λ² I)⁻¹ e over the active tips, by `sweeps` block Gauss–Seidel sweeps from
/// y = 0 (exact after one sweep when no two active chains share a joint), into `s.dq`.
pub fn ik_dls_step(m: &Model, targets: &[Vec3; MAX_TIPS], mask: u32, damping: f32, sweeps: u32, s: &mut IkScratch) {
    for k in 0..MAX_JOINTS {
        s.dq[k] = 0.0;
    }
    for t in 0..MAX_TIPS {
        s.y[t] = Vec3::ZERO;
    }
    for _ in 0..sweeps {
        for t in 0..m.g.n_tips as usize {
            if ((mask >> t) & 1) != 0 {
                ik_block_update(m, t, targets[t], damping, s);
            }
        }
    }
}

/// One solver iteration on `s.q` (see the module documentation): returns false, leaving `s.q`
/// untouched, when every active residual is ≤ `tol` or the step is not finite.
pub fn ik_iterate(m: &Model, targets: &[Vec3; MAX_TIPS], mask: u32, prm: &IkParams, sweeps: u32, s: &mut IkScratch) -> bool {
    let mut worst = 0.0f32;
    for k in 0..MAX_JOINTS {
        s.lock[k] = 0;
    }
    for t in 0..m.g.n_tips as usize {
        if ((mask >> t) & 1) != 0 {
            let e = ik_tip_jacobian(m, t, targets[t], s);
            // NaN fails the comparison: a NaN target counts as reached
            if e.length() > worst {
                worst = e.length();
            }
        }
    }
    if !(worst > prm.tol) {
        return false;
    }
    // a joint at a limit that Δq pushes further out is locked and the step solved again without it,
    // so that it does not absorb the step
    for _ in 0..MAX_JOINTS {
        ik_dls_step(m, targets, mask, prm.damping, sweeps, s);
        let mut locked = false;
        for k in 0..m.g.n_joints as usize {
            let jd = &m.joints[k];
            let d = s.dq[k];
            if s.lock[k] == 0 && ((s.q[k] <= jd.lower && d < 0.0) || (s.q[k] >= jd.upper && d > 0.0)) {
                s.lock[k] = 1;
                locked = true;
            }
        }
        if !locked {
            break;
        }
    }
    let mut dmax = 0.0f32;
    for k in 0..m.g.n_joints as usize {
        // written so that a NaN propagates
        let a = s.dq[k].abs();
        if !(a <= dmax) {
            dmax = a;
        }
    }
    // a non-finite step moves nothing
    if !(dmax < 1e30) {
        return false;
    }
    // scale Δq so that max |Δqₖ| ≤ max_step, keeping its direction
    let scale = if dmax > prm.max_step { prm.max_step / dmax } else { 1.0 };
    for k in 0..m.g.n_joints as usize {
        let jd = &m.joints[k];
        if s.share[k] > 0 && s.lock[k] == 0 {
            s.q[k] = (s.q[k] + scale * s.dq[k]).clamp(jd.lower, jd.upper);
        }
    }
    ik_apply_mimic(m, &mut s.q);
    true
}

/// Joint vector whose active fingertips (bit t of `mask`) reach `targets` (wrist frame, xyz), by
/// damped least squares from `q_seed` (see the module documentation). Actuated joints on no active
/// chain keep their seed values; every joint the solver moves stays within its limits.
pub fn ik_solve(m: &Model, q_seed: &[f32; MAX_JOINTS], targets: &[Vec3; MAX_TIPS], mask: u32, prm: &IkParams) -> [f32; MAX_JOINTS] {
    let mut s = IkScratch::default();
    s.q = *q_seed;
    // coupled chains need several sweeps for the stacked solve, independent ones one
    let sweeps = if ik_share(m, mask, &mut s) > 1 { IK_SWEEPS } else { 1 };
    for _ in 0..prm.iters {
        if !ik_iterate(m, targets, mask, prm, sweeps, &mut s) {
            break;
        }
    }
    s.q
}
