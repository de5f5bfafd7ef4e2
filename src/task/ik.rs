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
//! **Solver** (`ik_solve`): at most `IkParams::iters` iterations of damped least squares (DLS) on
//! the stacked residuals of the active fingertips (bit t of `mask`; m of them, slots a = 0..m in tip
//! order; `ik_setup` finds their chains once). One iteration (`ik_iterate`):
//! 1. per active tip (`ik_tip_jacobian`): chain FK at q, eₐ = x*ₐ − xₐ, and one Jacobian column per
//!    *actuated* joint k: Jₐₖ = Σ_{j on the chain, j = k or j follows k} wⱼ aⱼ × (xₐ − oⱼ), with aⱼ,
//!    oⱼ joint j's world axis and origin and wⱼ = 1 for k itself, the mimic multiplier for a
//!    follower (q_f = mult·q_k + offset): a leader that is not on the chain still moves the tip
//!    through its follower; followers are never solved for;
//! 2. if every |eₐ| ≤ `tol` (an exact zero included) the solve stops: nothing moves;
//! 3. Δq = b + Jᵀ (J Jᵀ + Λ)⁻¹ (ê − J b) (`ik_build_gram`, `ik_cholesky`, `ik_dls_step`), ê the
//!    residuals shortened to at most `IK_ERR_CLAMP` each, Λ = diag(λₐ² I) the damping of each slot
//!    (`ik_damping`) and b the preferred step (`ik_bias`): the minimiser of
//!    |J Δq − ê|²_Λ⁻¹ + |Δq − b|², i.e. DLS that is pulled toward b instead of toward 0, so that b
//!    acts where J is blind (its visible part is taken back by the solve). J Jᵀ is the 3m × 3m matrix of 3×3 blocks
//!    Σₖ Jₐₖ Jᵦₖᵀ, factored by block Cholesky: tips on independent chains (dexhand16's fingers) give a
//!    block-diagonal matrix, i.e. one 3×3 DLS solve per tip; tips that share a joint (tri3's wrist
//!    roll and its mimic-coupled spread) are solved together, so a shared joint takes the
//!    least-squares compromise instead of being pulled back and forth by one tip after another;
//! 4. a joint at a limit that Δq pushes further out is locked (its columns zeroed) and step 3
//!    repeated (at most `IK_LOCK_ROUNDS` solves), so that it does not absorb the step;
//! 5. Δq is scaled (direction kept) so that max |Δqₖ| ≤ `max_step`, and by (worst − tol) / tol
//!    when the worst residual is below 2·`tol` (the stop fades in), each moved qₖ is clamped to its
//!    limits (`lower`, `upper` of `JointDesc`; ±1e30 = unlimited), and every follower is recomputed
//!    from its leader (`ik_apply_mimic`).
//!
//! **Damping** (`ik_damping`), per active tip from its own residual eₐ:
//! λₐ² = (`damping` · clamp(|eₐ| / `IK_DAMPING_DIST`, `IK_DAMPING_FLOOR`, 1))² + `IK_DAMPING_CURV` · |êₐ|.
//! The first term is full far from the target (bounded steps near singular, straight fingers) and
//! shrinks as the tip arrives, so that directions the Jacobian barely sees (tri3's roll against
//! its spreads) converge in a few iterations instead of hundreds. The second term is the part of
//! the Hessian that Gauss–Newton drops: ½|x(q) − x*|² has Hessian JᵀJ − Σ eᵢ ∇²xᵢ, and a tip
//! swung by a joint curves toward it with curvature ≤ its lever arm, so where a residual cannot be
//! removed (a target beyond a straight finger's reach) that term adds up to |e| · lever along
//! directions JᵀJ barely sees. Without it the DLS step along them overshoots by up to
//! |ê| · lever / λ² (12× at a 1 mm residual on a 5 cm lever; ê, at most `IK_ERR_CLAMP` long, is what the step
//! aims at) and the finger flips between bending either way from one iteration to the next, a
//! chaotic orbit whose end differed by 0.04 rad between CPU and GPU; with λ² ≥
//! `IK_DAMPING_CURV` · |ê| the step is a contraction there and the solve settles. A
//! reachable target keeps its accuracy: the term vanishes with the residual.
//! A tip with a zero residual gets no step from its own block.
//!
//! **Preferred flexion** (`ik_bias`): a straight finger cannot shorten to first order (J has no
//! row along the finger), so a target nearer than its length leaves ê with no component J sees;
//! a plain DLS step then bends it whichever way the rounding of the other components points, and
//! targets on either side of the finger's plane bend it opposite ways (a 0.9 rad jump for 0.1 mm).
//! The preferred step bₖ = `IK_BIAS` · ρₖ · (midₖ − qₖ) pulls each limited joint toward the middle
//! of its range, mid = (lower + upper) / 2, which for a finger's flexion joints (−0.2 .. 1.6 on
//! dexhand16) is the flexion side; ρₖ = max over the active tips a that k moves of
//! ρₐ = min(|eₐ| / `IK_DAMPING_DIST`, 1) · clamp(1 + 2 sₐ / |eₐ|, 0, 1), with
//! sₐ = eₐ · (o₀ − xₐ) / |o₀ − xₐ| the part of the residual that points from the tip toward its
//! chain's first joint o₀. ρ vanishes continuously with the residual (a tiny residual moves the
//! joints a tiny amount, a zero one not at all; |eₐ| · clamp(…) → 0 as eₐ → 0); the second factor
//! is 1 for targets sideways of the tip or nearer the root and 0 for targets more than 30° past
//! sideways beyond the tip, so that a finger that reaches out for a target beyond its reach is
//! left pointing straight at it instead of curled away from it.
//! Through the solve only b's null-space part stays: from a straight finger, a curl that shortens
//! it, after which J sees the residual along the finger and bends it the flexion way. Unlimited
//! joints (±1e30, tri3's roll) and joints on no active chain get no bias. From the straight
//! default pose, dexhand16 now reaches 400 of 400 sampled reachable targets within 1 mm (399
//! before: one finger bent the wrong way into two joint limits).
//!
//! The solve is a continuous function of its inputs (the stop at `tol` fades in, see step 5; only
//! the joint-limit locks are decisions), so the CPU and the GPU agree on it to their rounding
//! times its conditioning: a near-straight finger moves its tip by ~0.6 mm per rad along one
//! direction of its joints, so solving the tip to `tol` turns the f32 rounding of the tips
//! (~1e-8 m) into up to ~2e-5 rad along that direction (tests/ik.rs measures it; elsewhere the
//! backends agree to ~1e-6). tests/ik.rs also sweeps targets through a straight finger's singular
//! pose and bounds the joints' change per metre of target (23 rad/m measured, the old solver
//! jumped 0.9 rad for 0.1 mm).
//!
//! Limits of a local method: from a seed far from the answer the solve can end in a local minimum,
//! e.g. tri3's fingers when the continuous wrist roll must turn by more than about 1 rad;
//! tests/ik.rs measures this.
//!
//! Exactness: if every active target equals `ik_tip_positions(q_seed)`, every residual is exactly
//! zero and `ik_solve` returns `q_seed` bit for bit (followers and out-of-limit entries included).
//! Actuated joints on no active chain are never written (followers are recomputed from their
//! leaders once anything moves). A non-finite target or step moves nothing, so the result stays
//! finite on the CPU; GPUs may assume no NaN, so feed the shader finite targets.
//!
//! Cost: every loop is bounded by the model's sizes (joints, tips, chain lengths), `iters` and
//! `IK_LOCK_ROUNDS`. Mesa's lavapipe stops all loops of an invocation after 65,535 iterations in
//! all; a full 24-iteration solve of dexhand16 takes fewer than ~15,000 (tests/ik.rs checks that it
//! leaves ~45,000 to the rest of a kernel).

// the loops index arrays as the shader's do; `!(x > tol)` is true for NaN on purpose
#![allow(clippy::needless_range_loop, clippy::neg_cmp_op_on_partial_ord)]

use bytemuck::{Pod, Zeroable};
use glam::{Mat3, Vec3, Vec4};

use crate::env::common::*;
use crate::gpu::layout::*;
use crate::env::physics::{MAX_LINKS, Model};
use crate::hand::{MAX_JOINTS, MAX_TIPS};

/// 3×3 blocks in the lower block triangle of the stacked system (keep in sync with ik.wgsl
/// `IK_BLOCKS`).
pub const IK_BLOCKS: usize = MAX_TIPS * (MAX_TIPS + 1) / 2;
/// Default iteration bound of [`ik_solve`]: enough for a straight hand to reach random reachable
/// targets (99.75 % within 1 mm on dexhand16, all on tri3; tests/ik.rs); a seed near the answer,
/// the task layer's case, stops after a few iterations (4–7 on average).
pub const IK_ITERS: u32 = 24;
/// Default damping λ (m) of `(J Jᵀ + λ² I)` far from a target: small against the fingers' lever
/// arms (3–15 cm) and large enough to bound the step near a straight finger (|Δq| ≤ |e| / 2λ).
pub const IK_DAMPING: f32 = 0.02;
/// Residual (m) below which a tip's damping shrinks in proportion to its residual, and below
/// which its joints' preferred step shrinks likewise.
pub const IK_DAMPING_DIST: f32 = 0.01;
/// Smallest damping, as a fraction of `damping` (λ ≥ 1 mm keeps J Jᵀ + λ² I well conditioned in
/// f32 and bounds a step taken at the noise floor).
pub const IK_DAMPING_FLOOR: f32 = 0.05;
/// Curvature term (m) of the damping, λₐ² += `IK_DAMPING_CURV` · |eₐ|: stands in for the
/// Hessian term |e| · lever arm that Gauss–Newton drops, with a lever of 3 cm (a quarter of a
/// dexhand16 finger; 0.1 slowed reachable solves from straight fingers, 0.02 left more
/// sensitivity to rounding where targets are out of reach; see the module documentation).
pub const IK_DAMPING_CURV: f32 = 0.03;
/// Preferred step toward mid-range, as a fraction of (mid − q) per iteration at a full residual
/// (≥ `IK_DAMPING_DIST`): enough to decide a straight finger's bend well above f32 noise and to
/// lead straight dexhand16 fingers to every sampled reachable target; 0.1 left 2 in 300 targets
/// off by more than 1 mm.
pub const IK_BIAS: f32 = 0.3;
/// Most DLS solves per iteration while locking joints at their limits (the last solve's step is
/// taken even if it locked another joint; that joint then stays where it is).
pub const IK_LOCK_ROUNDS: u32 = 2;
/// Largest residual (m) one iteration aims to remove per fingertip: longer residuals are scaled down
/// to it, so that the linearisation holds and a finger stretched toward a far target does not
/// swing about its straight (singular) pose (at 5 cm such solves differed by 1e-4 rad between CPU
/// and GPU; at 2 cm by 3e-6).
pub const IK_ERR_CLAMP: f32 = 0.02;
/// Default largest joint change (rad) of one iteration: keeps far targets from flinging a finger
/// through half a turn on a linearisation that only holds near the current pose.
pub const IK_MAX_STEP: f32 = 0.5;
/// Default residual (m) at or below which every tip counts as reached and the solve stops: above
/// the f32 noise of the kinematics (~3e-8 m), so converged solves stop early. CPU and GPU round the
/// residual differently, so at the threshold one may take one more step than the other; that step
/// fades to nothing at the threshold (scaled by (worst − tol) / tol below 2·tol), where a whole
/// step could move a joint by tol / 2λ_min = 5e-5 rad along a direction the tips barely see.
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
    /// Joints of fingertip t's chain, root → tip, at `t * MAX_JOINTS + i` (`ik_chain`), how many
    /// (`ik_setup`), and whether entry i is the first driven by its actuated joint.
    pub chain_j: [u32; MAX_TIPS * MAX_JOINTS],
    pub chain_n: [u32; MAX_TIPS],
    pub first: [u32; MAX_TIPS * MAX_JOINTS],
    /// World origin and axis of each chain joint (`ik_chain_fk`).
    pub chain_o: [Vec3; MAX_JOINTS],
    pub chain_a: [Vec3; MAX_JOINTS],
    /// The actuated joints that drive active slot a's chain: `lead[a * MAX_JOINTS + i]`, i <
    /// `lead_n[a]` (`ik_setup`).
    pub lead: [u32; MAX_TIPS * MAX_JOINTS],
    pub lead_n: [u32; MAX_TIPS],
    /// Bit a set: actuated joint k drives active slot a's chain.
    pub slots: [u32; MAX_JOINTS],
    /// Bit b set: slots a and b share a joint (their block of J Jᵀ is not zero).
    pub couple: [u32; MAX_TIPS],
    /// 1 when the model has mimic followers.
    pub followers: u32,
    /// 1 for a joint locked at a limit during the current iteration.
    pub lock: [u32; MAX_JOINTS],
    /// Jacobian `[slot][joint]`: column of actuated joint k for active slot a at
    /// `a * MAX_JOINTS + k` (zero off the slot's chain and for locked joints).
    pub jac: [Vec3; MAX_TIPS * MAX_JOINTS],
    /// Residual eₐ of each slot (at most `IK_ERR_CLAMP` long), its full length |eₐ|, and the
    /// multipliers yₐ of (J Jᵀ + Λ) y = ê − J b (the right-hand side before `ik_cholesky`).
    pub err: [Vec3; MAX_TIPS],
    pub res: [f32; MAX_TIPS],
    /// The residual's component from the tip toward its chain's first joint (`ik_tip_jacobian`).
    pub shorten: [f32; MAX_TIPS],
    pub y: [Vec3; MAX_TIPS],
    /// Damping λₐ² of each slot (`ik_damping`).
    pub lam2: [f32; MAX_TIPS],
    /// Preferred step bₖ of each joint (`ik_bias`; zero off the active chains and when locked).
    pub pref: [f32; MAX_JOINTS],
    /// Lower block triangle of J Jᵀ + Λ (3×3 blocks, (a, b) with b ≤ a at a(a+1)/2 + b), then
    /// of its block Cholesky factor L, with L_aa⁻¹ in the diagonal blocks.
    pub blk: [Mat3; IK_BLOCKS],
    /// The step Δq = b + Jᵀ y.
    pub dq: [f32; MAX_JOINTS],
    /// The solver's joint vector.
    pub q: [f32; MAX_JOINTS],
}

impl Default for IkScratch {
    fn default() -> Self {
        IkScratch {
            link_pos: [Vec3::ZERO; MAX_LINKS],
            link_rot: [Vec4::W; MAX_LINKS],
            chain_j: [0; MAX_TIPS * MAX_JOINTS],
            chain_n: [0; MAX_TIPS],
            first: [0; MAX_TIPS * MAX_JOINTS],
            chain_o: [Vec3::ZERO; MAX_JOINTS],
            chain_a: [Vec3::ZERO; MAX_JOINTS],
            lead: [0; MAX_TIPS * MAX_JOINTS],
            lead_n: [0; MAX_TIPS],
            slots: [0; MAX_JOINTS],
            couple: [0; MAX_TIPS],
            followers: 0,
            lock: [0; MAX_JOINTS],
            jac: [Vec3::ZERO; MAX_TIPS * MAX_JOINTS],
            err: [Vec3::ZERO; MAX_TIPS],
            res: [0.0; MAX_TIPS],
            shorten: [0.0; MAX_TIPS],
            y: [Vec3::ZERO; MAX_TIPS],
            lam2: [0.0; MAX_TIPS],
            pref: [0.0; MAX_JOINTS],
            blk: [Mat3::ZERO; IK_BLOCKS],
            dq: [0.0; MAX_JOINTS],
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

/// The joints that move fingertip `t`, root → tip, into `s.chain_j[t * MAX_JOINTS..]`; returns
/// how many.
pub fn ik_chain(m: &Model, t: usize, s: &mut IkScratch) -> usize {
    let base = t * MAX_JOINTS;
    // walk up: link l is moved by joint l − 1, whose parent link is next
    let mut n = 0;
    let mut link = m.tips[t].link;
    for _ in 0..MAX_JOINTS {
        if link == 0 {
            break;
        }
        let j = link - 1;
        s.chain_j[base + n] = j;
        n += 1;
        link = m.joints[j as usize].parent_link;
    }
    // reverse into root → tip order
    for i in 0..n / 2 {
        s.chain_j.swap(base + i, base + n - 1 - i);
    }
    n
}

/// FK along the chain of `ik_chain` (`n` joints): the origin and axis of each chain joint into
/// `s.chain_o` / `s.chain_a`; returns fingertip `t`'s position (wrist frame).
pub fn ik_chain_fk(m: &Model, t: usize, n: usize, q: &[f32; MAX_JOINTS], s: &mut IkScratch) -> Vec3 {
    let mut pos = Vec3::ZERO;
    let mut rot = Vec4::W;
    for i in 0..n {
        let j = s.chain_j[t * MAX_JOINTS + i] as usize;
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

/// For every active fingertip (bit t of `mask`, slots a = 0.. in tip order): its chain
/// (`ik_chain`, `s.chain_n`), which chain entries are the first driven by their actuated joint
/// (`s.first`), the actuated joints that drive the chain (itself or through a follower; `s.lead`,
/// `s.lead_n`), which slots each joint drives (`s.slots`) and which slots share a joint
/// (`s.couple`); clears the locks and the slots' Jacobian rows. Returns the number of active tips.
pub fn ik_setup(m: &Model, mask: u32, s: &mut IkScratch) -> usize {
    s.followers = 0;
    for k in 0..MAX_JOINTS {
        s.slots[k] = 0;
        s.lock[k] = 0;
        if k < m.g.n_joints as usize && m.joints[k].mimic_leader != NO_JOINT {
            s.followers = 1;
        }
    }
    let mut a = 0;
    for t in 0..m.g.n_tips as usize {
        if ((mask >> t) & 1) != 0 {
            let n = ik_chain(m, t, s);
            s.chain_n[t] = n as u32;
            for k in 0..m.g.n_joints as usize {
                s.jac[a * MAX_JOINTS + k] = Vec3::ZERO;
            }
            let mut cnt = 0;
            for i in 0..n {
                let k = ik_leader(m, s.chain_j[t * MAX_JOINTS + i]);
                // each leader once per slot
                let first = (s.slots[k as usize] >> a) & 1 == 0;
                s.first[t * MAX_JOINTS + i] = first as u32;
                if first {
                    s.lead[a * MAX_JOINTS + cnt] = k;
                    cnt += 1;
                }
                s.slots[k as usize] |= 1 << a;
            }
            s.lead_n[a] = cnt as u32;
            a += 1;
        }
    }
    for b in 0..a {
        s.couple[b] = 0;
        for i in 0..s.lead_n[b] as usize {
            s.couple[b] |= s.slots[s.lead[b * MAX_JOINTS + i] as usize];
        }
    }
    a
}

/// Chain FK of fingertip `t` at `s.q` and its Jacobian columns in slot `a` of `s.jac` (unlocked
/// actuated joints, see the module documentation; needs `ik_setup`); stores the residual, at most
/// `IK_ERR_CLAMP` long, in `s.err[a]` and its part toward the chain's first joint in
/// `s.shorten[a]`, and returns e = goal − x.
pub fn ik_tip_jacobian(m: &Model, t: usize, a: usize, goal: Vec3, s: &mut IkScratch) -> Vec3 {
    let n = s.chain_n[t] as usize;
    let q = s.q;
    let x = ik_chain_fk(m, t, n, &q, s);
    for i in 0..n {
        let j = s.chain_j[t * MAX_JOINTS + i];
        let k = ik_leader(m, j) as usize;
        let w = if j as usize == k { 1.0 } else { m.joints[j as usize].mimic_mult };
        // Jₐₖ = Σ wⱼ aⱼ × (x − oⱼ) over the chain joints driven by k
        let c = w * s.chain_a[i].cross(x - s.chain_o[i]);
        if s.first[t * MAX_JOINTS + i] != 0 {
            s.jac[a * MAX_JOINTS + k] = c;
        } else {
            s.jac[a * MAX_JOINTS + k] += c;
        }
    }
    // e = x* − x, aimed at no farther than IK_ERR_CLAMP per iteration
    let e = goal - x;
    let len = e.length();
    s.err[a] = if len > IK_ERR_CLAMP { e * (IK_ERR_CLAMP / len) } else { e };
    // sₐ = e · (o₀ − x) / |o₀ − x|: how far the target lies nearer to the chain's first joint o₀
    // than the tip (> 0: the finger must get shorter)
    let root = if n > 0 { s.chain_o[0] } else { x };
    let inward = root - x;
    s.shorten[a] = e.dot(inward) / inward.length().max(1e-6);
    e
}

/// u vᵀ.
pub fn ik_outer(u: Vec3, v: Vec3) -> Mat3 {
    Mat3::from_cols(u * v.x, u * v.y, u * v.z)
}

/// L⁻¹ for the lower Cholesky factor L of a symmetric positive definite 3×3 `a` (L Lᵀ = a; only
/// its lower triangle is read), a lower triangular matrix.
pub fn ik_chol3_inv(a: Mat3) -> Mat3 {
    let l00 = a.x_axis.x.max(1e-20).sqrt();
    let l10 = a.x_axis.y / l00;
    let l20 = a.x_axis.z / l00;
    let l11 = (a.y_axis.y - l10 * l10).max(1e-20).sqrt();
    let l21 = (a.y_axis.z - l20 * l10) / l11;
    let l22 = (a.z_axis.z - l20 * l20 - l21 * l21).max(1e-20).sqrt();
    let i00 = 1.0 / l00;
    let i11 = 1.0 / l11;
    let i22 = 1.0 / l22;
    let i10 = -l10 * i00 * i11;
    let i21 = -l21 * i11 * i22;
    let i20 = -(l20 * i00 + l21 * i10) * i22;
    Mat3::from_cols(Vec3::new(i00, i10, i20), Vec3::new(0.0, i11, i21), Vec3::new(0.0, 0.0, i22))
}

/// Lower block triangle of J Jᵀ + Λ over `n_active` slots into `s.blk`: block (a, b) =
/// Σₖ Jₐₖ Jᵦₖᵀ (+ λₐ² I for a = b, `s.lam2`), the sum over slot a's joints (Jᵦₖ = 0 off b's chain).
pub fn ik_build_gram(n_active: usize, s: &mut IkScratch) {
    for a in 0..n_active {
        for b in 0..=a {
            let mut sum = Mat3::ZERO;
            if a == b {
                sum = Mat3::from_diagonal(Vec3::splat(s.lam2[a]));
            }
            // chains that share no joint leave their block zero
            if ((s.couple[a] >> b) & 1) != 0 {
                for i in 0..s.lead_n[a] as usize {
                    let k = s.lead[a * MAX_JOINTS + i] as usize;
                    sum += ik_outer(s.jac[a * MAX_JOINTS + k], s.jac[b * MAX_JOINTS + k]);
                }
            }
            s.blk[a * (a + 1) / 2 + b] = sum;
        }
    }
}

/// Solves (J Jᵀ + Λ) y = r (`n_active` block rows) in place, r in `s.y` on entry, y on return,
/// by block Cholesky (3×3 blocks): L_ij = (S_ij − Σ_{k<j} L_ik L_jkᵀ) L_jj⁻ᵀ, L_jj the Cholesky
/// factor of S_jj − Σ_{k<j} L_jk L_jkᵀ; then L z = r and Lᵀ y = z.
pub fn ik_cholesky(n_active: usize, s: &mut IkScratch) {
    for i in 0..n_active {
        for j in 0..=i {
            let mut mm = s.blk[i * (i + 1) / 2 + j];
            for k in 0..j {
                mm -= s.blk[i * (i + 1) / 2 + k] * s.blk[j * (j + 1) / 2 + k].transpose();
            }
            if i == j {
                // the diagonal block keeps L_ii⁻¹
                s.blk[i * (i + 1) / 2 + i] = ik_chol3_inv(mm);
            } else {
                s.blk[i * (i + 1) / 2 + j] = mm * s.blk[j * (j + 1) / 2 + j].transpose();
            }
        }
    }
    // L z = r: z_i = L_ii⁻¹ (r_i − Σ_{k<i} L_ik z_k), z_k (k < i) already in s.y
    for i in 0..n_active {
        let mut r = s.y[i];
        for k in 0..i {
            r -= s.blk[i * (i + 1) / 2 + k] * s.y[k];
        }
        s.y[i] = s.blk[i * (i + 1) / 2 + i] * r;
    }
    // Lᵀ y = z: y_i = L_ii⁻ᵀ (z_i − Σ_{k>i} L_kiᵀ y_k)
    for ii in 0..n_active {
        let i = n_active - 1 - ii;
        let mut r = s.y[i];
        for k in (i + 1)..n_active {
            r -= s.blk[k * (k + 1) / 2 + i].transpose() * s.y[k];
        }
        s.y[i] = s.blk[i * (i + 1) / 2 + i].transpose() * r;
    }
}

/// Δq = b + Jᵀ (J Jᵀ + Λ)⁻¹ (ê − J b) into `s.dq` (Δqₖ = bₖ + Σₐ Jₐₖ · yₐ), b = `s.pref`.
pub fn ik_dls_step(m: &Model, n_active: usize, s: &mut IkScratch) {
    // r_a = ê_a − Σₖ Jₐₖ bₖ: the solve takes back what J sees of b
    for a in 0..n_active {
        let mut r = s.err[a];
        for i in 0..s.lead_n[a] as usize {
            let k = s.lead[a * MAX_JOINTS + i] as usize;
            r -= s.jac[a * MAX_JOINTS + k] * s.pref[k];
        }
        s.y[a] = r;
    }
    ik_build_gram(n_active, s);
    ik_cholesky(n_active, s);
    for k in 0..m.g.n_joints as usize {
        s.dq[k] = s.pref[k];
    }
    for a in 0..n_active {
        for i in 0..s.lead_n[a] as usize {
            let k = s.lead[a * MAX_JOINTS + i] as usize;
            s.dq[k] += s.jac[a * MAX_JOINTS + k].dot(s.y[a]);
        }
    }
}

/// Damping of each active slot from its residual length `s.res[a]` into `s.lam2`:
/// λₐ² = (`damping` · clamp(|eₐ| / `IK_DAMPING_DIST`, `IK_DAMPING_FLOOR`, 1))² + `IK_DAMPING_CURV` · |êₐ|.
pub fn ik_damping(n_active: usize, prm: &IkParams, s: &mut IkScratch) {
    for a in 0..n_active {
        // λ = damping · clamp(|e| / IK_DAMPING_DIST, IK_DAMPING_FLOOR, 1)
        let l = prm.damping * (s.res[a] / IK_DAMPING_DIST).clamp(IK_DAMPING_FLOOR, 1.0);
        // λ² + C·|ê|: the dropped Hessian term |ê| · lever, ê the residual the step aims at
        s.lam2[a] = l * l + IK_DAMPING_CURV * s.res[a].min(IK_ERR_CLAMP);
    }
}

/// The preferred step of every joint into `s.pref`: bₖ = `IK_BIAS` · ρₖ · (midₖ − qₖ) for an
/// actuated joint on an active chain with finite limits, ρₖ = max over the active slots a that k
/// drives of ρₐ = min(|eₐ| / `IK_DAMPING_DIST`, 1) · clamp(1 + 2 sₐ / |eₐ|, 0, 1), sₐ =
/// `s.shorten[a]`; 0 for every other joint.
pub fn ik_bias(m: &Model, n_active: usize, s: &mut IkScratch) {
    let n = m.g.n_joints as usize;
    for k in 0..n {
        s.pref[k] = 0.0;
    }
    // ρₖ = max over k's slots of ρₐ, gathered in s.pref
    for a in 0..n_active {
        // wₐ = clamp(1 + 2 sₐ / |eₐ|, 0, 1): 1 unless the target lies beyond the tip, 0 from 30°
        // past sideways on (sₐ / |eₐ| ≤ −½)
        let toward = (1.0 + 2.0 * s.shorten[a] / s.res[a].max(1e-30)).clamp(0.0, 1.0);
        // ρₐ = min(|eₐ| / IK_DAMPING_DIST, 1) · wₐ
        let rho = (s.res[a] / IK_DAMPING_DIST).min(1.0) * toward;
        for i in 0..s.lead_n[a] as usize {
            let k = s.lead[a * MAX_JOINTS + i] as usize;
            s.pref[k] = s.pref[k].max(rho);
        }
    }
    for k in 0..n {
        let jd = &m.joints[k];
        // unlimited joints (±1e30) have no middle
        if jd.lower > -1e29 && jd.upper < 1e29 {
            // bₖ = IK_BIAS · ρₖ · ((lower + upper) / 2 − qₖ)
            s.pref[k] = IK_BIAS * s.pref[k] * (0.5 * (jd.lower + jd.upper) - s.q[k]);
        } else {
            s.pref[k] = 0.0;
        }
    }
}

/// One solver iteration on `s.q` (see the module documentation); returns false, leaving `s.q`
/// untouched, when every active residual is ≤ `tol` or the step is not finite.
pub fn ik_iterate(m: &Model, targets: &[Vec3; MAX_TIPS], mask: u32, n_active: usize, prm: &IkParams, s: &mut IkScratch) -> bool {
    let n = m.g.n_joints as usize;
    let mut worst = 0.0f32;
    let mut finite = true;
    let mut a = 0;
    for t in 0..m.g.n_tips as usize {
        if ((mask >> t) & 1) != 0 {
            let e = ik_tip_jacobian(m, t, a, targets[t], s).length();
            s.res[a] = e;
            worst = worst.max(e);
            // NaN fails the comparison
            finite = finite && e < 1e30;
            a += 1;
        }
    }
    // every tip reached, or a non-finite target: nothing moves
    if !(worst > prm.tol) || !finite {
        return false;
    }
    ik_damping(n_active, prm, s);
    ik_bias(m, n_active, s);
    let mut dmax = 0.0f32;
    for _ in 0..IK_LOCK_ROUNDS {
        ik_dls_step(m, n_active, s);
        // lock every joint at a limit that Δq pushes further out, zero its columns, solve again
        let mut locked = false;
        dmax = 0.0;
        for k in 0..n {
            let jd = &m.joints[k];
            let d = s.dq[k];
            if s.lock[k] == 0 && ((s.q[k] <= jd.lower && d < 0.0) || (s.q[k] >= jd.upper && d > 0.0)) {
                s.lock[k] = 1;
                locked = true;
                s.pref[k] = 0.0;
                for b in 0..n_active {
                    s.jac[b * MAX_JOINTS + k] = Vec3::ZERO;
                }
            } else if s.lock[k] == 0 {
                dmax = dmax.max(d.abs());
                // NaN fails the comparison
                finite = finite && d.abs() < 1e30;
            }
        }
        if !locked {
            break;
        }
    }
    // a non-finite step moves nothing
    if !finite {
        return false;
    }
    // the stop fades in: below 2·tol the step shrinks to 0 at tol (fade = (worst − tol) / tol),
    // so a residual that one backend rounds to just above tol and the other to just below moves
    // the joints by ~0 instead of by one whole step (up to tol / 2λ_min = 5e-5 rad)
    let fade = if worst < 2.0 * prm.tol { (worst - prm.tol) / prm.tol } else { 1.0 };
    // scale Δq so that max |Δqₖ| ≤ max_step, keeping its direction
    let scale = (if dmax > prm.max_step { prm.max_step / dmax } else { 1.0 }) * fade;
    for k in 0..n {
        let jd = &m.joints[k];
        if s.slots[k] != 0 && s.lock[k] == 0 {
            s.q[k] = (s.q[k] + scale * s.dq[k]).clamp(jd.lower, jd.upper);
        }
        // the locks hold for one iteration
        s.lock[k] = 0;
    }
    if s.followers != 0 {
        ik_apply_mimic(m, &mut s.q);
    }
    true
}

/// Joint vector whose active fingertips (bit t of `mask`) reach `targets` (wrist frame, xyz), by
/// damped least squares from `q_seed` (see the module documentation). Actuated joints on no active
/// chain keep their seed values; every joint the solver moves stays within its limits.
pub fn ik_solve(m: &Model, q_seed: &[f32; MAX_JOINTS], targets: &[Vec3; MAX_TIPS], mask: u32, prm: &IkParams) -> [f32; MAX_JOINTS] {
    // the shader's ik_q = q_seed
    let mut s = IkScratch { q: *q_seed, ..Default::default() };
    let n_active = ik_setup(m, mask, &mut s);
    for _ in 0..prm.iters {
        if !ik_iterate(m, targets, mask, n_active, prm, &mut s) {
            break;
        }
    }
    s.q
}
