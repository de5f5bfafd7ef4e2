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
//! the root, `ik_chain_fk` back down). `ik_tip_positions` and the solver share that code, so a
//! target taken from `ik_tip_positions(q)` is a residual of exactly zero at `q`.
//!
//! **Solver** (`ik_solve`): at most `IkParams::iters` iterations of damped least squares on the
//! stacked fingertip residuals of the active tips (bit t of `mask`; m of them, slots a = 0..m in tip
//! order). One iteration (`ik_iterate`):
//! 1. per active tip (`ik_tip_jacobian`): chain FK at q, eₐ = x*ₐ − xₐ, and one Jacobian column per
//!    *actuated* joint k: Jₐₖ = Σ_{j on the chain, j = k or j follows k} wⱼ aⱼ × (xₐ − oⱼ), with aⱼ,
//!    oⱼ joint j's axis and origin and wⱼ = 1 for k, the mimic multiplier for a follower
//!    (q_f = mult·q_k + offset): a leader that is not on the chain still moves the tip through its
//!    follower; followers themselves are never solved for;
//! 2. if every |eₐ| ≤ `tol` (an exact zero included) the solve stops: nothing moves;
//! 3. Δq = Jᵀ (J Jᵀ + λ² I)⁻¹ e (`ik_build_gram`, `ik_cholesky`, `ik_dls_step`): J Jᵀ is the
//!    3m × 3m matrix of 3×3 blocks Σₖ Jₐₖ Jᵦₖᵀ, so fingertips that share a joint (tri3's wrist roll,
//!    its mimic-coupled spread) are solved together, and tips on independent chains (dexhand16's
//!    fingers) give a block-diagonal matrix, i.e. one 3×3 DLS solve per tip;
//! 4. a joint at a limit that Δq pushes further out is locked (its columns zeroed) and step 3
//!    repeated, so that it does not absorb the step;
//! 5. Δq is scaled (direction kept) so that max |Δqₖ| ≤ `max_step`, each moved qₖ is clamped to its
//!    limits (`lower`, `upper` of `JointDesc`; ±1e30 = unlimited), and every follower is recomputed
//!    from its leader (`ik_apply_mimic`).
//!
//! The damping is λ = `damping` · clamp(max |eₐ| / `IK_DAMPING_DIST`, `IK_DAMPING_FLOOR`, 1):
//! full λ far from the targets (bounded steps near singular, straight fingers), shrinking as the
//! tips arrive, so that directions the Jacobian barely sees (tri3's roll against its spreads)
//! converge in a few iterations instead of hundreds.
//!
//! Exactness: if every active target equals `ik_tip_positions(q_seed)`, every residual is exactly
//! zero and `ik_solve` returns `q_seed` bit for bit (followers and out-of-limit entries included).
//! Actuated joints on no active chain are never written (followers are recomputed from their
//! leaders once anything moves). A non-finite step (a NaN or infinite target) moves nothing, so the
//! result stays finite on the CPU; the GPU may assume no NaN, so feed it finite targets.

use bytemuck::{Pod, Zeroable};
use glam::{Vec3, Vec4};

use super::common::*;
use super::layout::*;
use super::physics::{MAX_LINKS, Model};
use crate::hand::{MAX_JOINTS, MAX_TIPS};

/// Rows of the stacked system: 3 per fingertip (keep in sync with ik.wgsl `IK_ROWS`).
pub const IK_ROWS: usize = 3 * MAX_TIPS;
/// Default iteration bound of [`ik_solve`] (see tests/ik.rs for the measured accuracy).
pub const IK_ITERS: u32 = 24;
/// Default damping λ (m) of `(J Jᵀ + λ² I)` far from the targets: small against the fingers' lever
/// arms (3–15 cm) and large enough to bound the step near a straight finger (|Δq| ≤ |e| / 2λ).
pub const IK_DAMPING: f32 = 0.02;
/// Residual (m) below which the damping shrinks in proportion to it.
pub const IK_DAMPING_DIST: f32 = 0.01;
/// Smallest damping, as a fraction of `damping` (keeps J Jᵀ + λ² I well conditioned in f32).
pub const IK_DAMPING_FLOOR: f32 = 0.05;
/// Default largest joint change (rad) of one iteration: keeps far targets from flinging a finger
/// through half a turn on a linearisation that only holds near the current pose.
pub const IK_MAX_STEP: f32 = 0.5;
/// Default residual (m) at or below which every tip counts as reached and the solve stops. Above
/// the f32 noise of the kinematics (~1e-8 m), so converged solves stop early, and small enough that
/// stopping one iteration earlier or later (CPU vs GPU rounding at the threshold) changes a joint by
/// about 1e-5 rad at most.
pub const IK_TOL: f32 = 1e-7;

/// Solver settings (WGSL `IkParams`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable, PartialEq)]
pub struct IkParams {
    /// Most iterations (the loop bound; the solve stops early once every tip is within `tol`).
    pub iters: u32,
    /// λ (m) far from the targets, > 0.
    pub damping: f32,
    /// Largest joint change of one iteration (rad), > 0.
    pub max_step: f32,
    /// Residual (m) at or below which every tip counts as reached, ≥ 0.
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
    /// Joints of the current chain, root → tip (`ik_chain`).
    pub chain_j: [u32; MAX_JOINTS],
    /// World origin and axis of each chain joint (`ik_chain_fk`).
    pub chain_o: [Vec3; MAX_JOINTS],
    pub chain_a: [Vec3; MAX_JOINTS],
    /// Jacobian `[slot][joint]`: column of actuated joint k in active tip slot a at `a * MAX_JOINTS + k`
    /// (zero for followers, joints off the chain and locked joints).
    pub jac: [Vec3; MAX_TIPS * MAX_JOINTS],
    /// Residual eₐ of each slot.
    pub err: [Vec3; MAX_TIPS],
    /// J Jᵀ + λ² I (`[IK_ROWS, IK_ROWS]`, row-major), then its Cholesky factor L (lower triangle).
    pub gram: [f32; IK_ROWS * IK_ROWS],
    /// The multipliers y = (J Jᵀ + λ² I)⁻¹ e `[IK_ROWS]`.
    pub y: [f32; IK_ROWS],
    /// The step Δq = Jᵀ y.
    pub dq: [f32; MAX_JOINTS],
    /// 1 for an actuated joint that drives an active chain (`ik_touched`; WGSL `ik_touched_k`).
    pub touched: [u32; MAX_JOINTS],
    /// 1 for a joint locked at a limit during the current iteration.
    pub lock: [u32; MAX_JOINTS],
    /// The solver's joint vector.
    pub q: [f32; MAX_JOINTS],
}

impl Default for IkScratch {
    fn default() -> Self {
        IkScratch {
            link_pos: [Vec3::ZERO; MAX_LINKS],
            link_rot: [Vec4::W; MAX_LINKS],
            chain_j: [0; MAX_JOINTS],
            chain_o: [Vec3::ZERO; MAX_JOINTS],
            chain_a: [Vec3::ZERO; MAX_JOINTS],
            jac: [Vec3::ZERO; MAX_TIPS * MAX_JOINTS],
            err: [Vec3::ZERO; MAX_TIPS],
            gram: [0.0; IK_ROWS * IK_ROWS],
            y: [0.0; IK_ROWS],
            dq: [0.0; MAX_JOINTS],
            touched: [0; MAX_JOINTS],
            lock: [0; MAX_JOINTS],
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

/// Actuated joint that drives joint `j`: itself, or its mimic leader.
pub fn ik_leader(m: &Model, j: u32) -> u32 {
    let l = m.joints[j as usize].mimic_leader;
    if l != NO_JOINT { l } else { j }
}

/// Marks in `s.touched` every actuated joint that drives the chain of an active fingertip (bit t of
/// `mask`), itself or through a follower; returns how many tips are active.
pub fn ik_touched(m: &Model, mask: u32, s: &mut IkScratch) -> usize {
    for k in 0..MAX_JOINTS {
        s.touched[k] = 0;
    }
    let mut n_active = 0;
    for t in 0..m.g.n_tips as usize {
        if ((mask >> t) & 1) != 0 {
            n_active += 1;
            let n = ik_chain(m, t, s);
            for i in 0..n {
                s.touched[ik_leader(m, s.chain_j[i]) as usize] = 1;
            }
        }
    }
    n_active
}

/// Chain FK of fingertip `t` at `s.q` and its Jacobian row block in slot `a` of `s.jac` (columns of
/// unlocked actuated joints, see the module documentation); stores and returns e = goal − x.
pub fn ik_tip_jacobian(m: &Model, t: usize, a: usize, goal: Vec3, s: &mut IkScratch) -> Vec3 {
    let n = ik_chain(m, t, s);
    let q = s.q;
    let x = ik_chain_fk(m, t, n, &q, s);
    for k in 0..MAX_JOINTS {
        s.jac[a * MAX_JOINTS + k] = Vec3::ZERO;
    }
    for i in 0..n {
        let j = s.chain_j[i];
        let k = ik_leader(m, j) as usize;
        if s.lock[k] == 0 {
            let w = if j as usize == k { 1.0 } else { m.joints[j as usize].mimic_mult };
            // Jₐₖ += wⱼ aⱼ × (x − oⱼ)
            s.jac[a * MAX_JOINTS + k] += w * s.chain_a[i].cross(x - s.chain_o[i]);
        }
    }
    // e = x* − x
    let e = goal - x;
    s.err[a] = e;
    e
}

/// J Jᵀ + λ² I over `n_active` slots into `s.gram` (`[3m, 3m]` at stride `IK_ROWS`, lower triangle
/// and diagonal): block (a, b) = Σₖ Jₐₖ Jᵦₖᵀ.
pub fn ik_build_gram(m: &Model, n_active: usize, damping: f32, s: &mut IkScratch) {
    let n = m.g.n_joints as usize;
    for a in 0..n_active {
        for b in 0..=a {
            for r in 0..3 {
                for c in 0..3 {
                    let mut sum = 0.0;
                    for k in 0..n {
                        sum += s.jac[a * MAX_JOINTS + k][r] * s.jac[b * MAX_JOINTS + k][c];
                    }
                    if a == b && r == c {
                        sum += damping * damping;
                    }
                    s.gram[(3 * a + r) * IK_ROWS + 3 * b + c] = sum;
                }
            }
        }
    }
}

/// Solves (J Jᵀ + λ² I) y = e (`3 · n_active` rows) into `s.y` by Cholesky, L overwriting
/// `s.gram`'s lower triangle.
pub fn ik_cholesky(n_active: usize, s: &mut IkScratch) {
    let n = 3 * n_active;
    for i in 0..n {
        for j in 0..=i {
            let mut sum = s.gram[i * IK_ROWS + j];
            for k in 0..j {
                sum -= s.gram[i * IK_ROWS + k] * s.gram[j * IK_ROWS + k];
            }
            if i == j {
                s.gram[i * IK_ROWS + i] = sum.max(1e-20).sqrt();
            } else {
                s.gram[i * IK_ROWS + j] = sum / s.gram[j * IK_ROWS + j];
            }
        }
    }
    // L z = e
    for i in 0..n {
        let mut sum = s.err[i / 3][i % 3];
        for k in 0..i {
            sum -= s.gram[i * IK_ROWS + k] * s.y[k];
        }
        s.y[i] = sum / s.gram[i * IK_ROWS + i];
    }
    // Lᵀ y = z
    for ii in 0..n {
        let i = n - 1 - ii;
        let mut sum = s.y[i];
        for k in (i + 1)..n {
            sum -= s.gram[k * IK_ROWS + i] * s.y[k];
        }
        s.y[i] = sum / s.gram[i * IK_ROWS + i];
    }
}

/// Δq = Jᵀ (J Jᵀ + λ² I)⁻¹ e into `s.dq` (Δqₖ = Σₐ Jₐₖ · yₐ).
pub fn ik_dls_step(m: &Model, n_active: usize, damping: f32, s: &mut IkScratch) {
    ik_build_gram(m, n_active, damping, s);
    ik_cholesky(n_active, s);
    for k in 0..m.g.n_joints as usize {
        let mut d = 0.0;
        for a in 0..n_active {
            d += s.jac[a * MAX_JOINTS + k].dot(Vec3::new(s.y[3 * a], s.y[3 * a + 1], s.y[3 * a + 2]));
        }
        s.dq[k] = d;
    }
}

/// One solver iteration on `s.q` (see the module documentation); returns false, leaving `s.q`
/// untouched, when every active residual is ≤ `tol` or the step is not finite.
pub fn ik_iterate(m: &Model, targets: &[Vec3; MAX_TIPS], mask: u32, n_active: usize, prm: &IkParams, s: &mut IkScratch) -> bool {
    for k in 0..MAX_JOINTS {
        s.lock[k] = 0;
    }
    let mut worst = 0.0f32;
    let mut a = 0;
    for t in 0..m.g.n_tips as usize {
        if ((mask >> t) & 1) != 0 {
            let e = ik_tip_jacobian(m, t, a, targets[t], s).length();
            // written so that a NaN propagates
            if !(e <= worst) {
                worst = e;
            }
            a += 1;
        }
    }
    if !(worst > prm.tol) {
        return false;
    }
    // λ = damping · clamp(max |e| / IK_DAMPING_DIST, IK_DAMPING_FLOOR, 1)
    let damping = prm.damping * (worst / IK_DAMPING_DIST).clamp(IK_DAMPING_FLOOR, 1.0);
    for _ in 0..MAX_JOINTS {
        ik_dls_step(m, n_active, damping, s);
        // lock every joint at a limit that Δq pushes further out, zero its columns, solve again
        let mut locked = false;
        for k in 0..m.g.n_joints as usize {
            let jd = &m.joints[k];
            let d = s.dq[k];
            if s.lock[k] == 0 && ((s.q[k] <= jd.lower && d < 0.0) || (s.q[k] >= jd.upper && d > 0.0)) {
                s.lock[k] = 1;
                locked = true;
                for b in 0..n_active {
                    s.jac[b * MAX_JOINTS + k] = Vec3::ZERO;
                }
            }
        }
        if !locked {
            break;
        }
    }
    let mut dmax = 0.0f32;
    for k in 0..m.g.n_joints as usize {
        let d = s.dq[k].abs();
        if !(d <= dmax) {
            dmax = d;
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
        if s.touched[k] != 0 && s.lock[k] == 0 {
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
    let n_active = ik_touched(m, mask, &mut s);
    for _ in 0..prm.iters {
        if !ik_iterate(m, targets, mask, n_active, prm, &mut s) {
            break;
        }
    }
    s.q
}
