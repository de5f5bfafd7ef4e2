// ik.wgsl — damped least-squares inverse kinematics of the fingertips, in the wrist frame.
// CPU twin: src/task/ik.rs (same function names, same order, same arithmetic; its `IkScratch` is
// the var<private> ik_* memory below). The algorithm is described at the top of the twin.
// Needs common.wgsl before it (g: Globals, joints: binding 1, tips: binding 3, quaternion maths).

// 3×3 blocks in the lower block triangle of the stacked system, Jacobian entries.
const IK_BLOCKS: u32 = 21u;
// MAX_TIPS × MAX_JOINTS
const IK_JAC_LEN: u32 = 192u;
// Defaults: iterations, damping λ (m), residual below which λ and the preferred step shrink (m),
// smallest λ / damping, curvature term of λ² (m), preferred step toward mid-range, rounds of
// locking joints at limits per iteration, largest residual one iteration aims to remove (m),
// largest joint change per iteration (rad), residual tolerance (m).
const IK_ITERS: u32 = 24u;
const IK_DAMPING: f32 = 0.02;
const IK_DAMPING_DIST: f32 = 0.01;
const IK_DAMPING_FLOOR: f32 = 0.05;
const IK_DAMPING_CURV: f32 = 0.03;
const IK_BIAS: f32 = 0.3;
const IK_LOCK_ROUNDS: u32 = 2u;
const IK_ERR_CLAMP: f32 = 0.02;
const IK_MAX_STEP: f32 = 0.5;
const IK_TOL: f32 = 1e-7;

struct IkParams {
    iters: u32,
    damping: f32,
    max_step: f32,
    tol: f32,
}

struct IkFrame {
    origin: vec3<f32>,
    axis: vec3<f32>,
    rot: vec4<f32>,
}

// ---- per-invocation working memory (the twin's IkScratch) ----
// The per-slot and per-joint fields are arrays of structs (ik_tip, ik_joint), not an array per
// field: a GPU compiler keeps a private array of at most 256 bytes in registers (RADV's does,
// expanding each dynamic index into it), and task_act was 1.5× its size so on RADV's compiler
// (BENCHMARKS.md "What a GPU's compiler makes of the physics kernel")
var<private> ik_link_pos: array<vec3<f32>, MAX_LINKS>;
var<private> ik_link_rot: array<vec4<f32>, MAX_LINKS>;
// fingertip t's chain (root → tip) at t * MAX_JOINTS + i (its length: ik_tip[t].chain_n), and
// whether entry i is the first driven by its actuated joint
var<private> ik_chain_j: array<u32, IK_JAC_LEN>;
var<private> ik_first: array<u32, IK_JAC_LEN>;
var<private> ik_chain_o: array<vec3<f32>, MAX_JOINTS>;
var<private> ik_chain_a: array<vec3<f32>, MAX_JOINTS>;
// actuated joints driving active slot a's chain: ik_lead[a * MAX_JOINTS + i], i < ik_tip[a].lead_n
var<private> ik_lead: array<u32, IK_JAC_LEN>;
// fingertip slot a's working values
struct IkTip {
    // residual (at most IK_ERR_CLAMP long)
    err: vec3<f32>,
    // the residual's full length
    res: f32,
    // multiplier y of (J Jᵀ + Λ) y = ê − J b (the right-hand side before ik_cholesky)
    y: vec3<f32>,
    // the residual's component from the tip toward its chain's first joint
    shorten: f32,
    // the chain's length (ik_chain_j)
    chain_n: u32,
    // the actuated joints driving the chain (ik_lead)
    lead_n: u32,
    // bit b: slots a and b share a joint
    couple: u32,
    // damping λₐ²
    lam2: f32,
}
var<private> ik_tip: array<IkTip, MAX_TIPS>;
// joint k's working values
struct IkJoint {
    // bit a: actuated joint k drives active slot a's chain
    slots: u32,
    // 1 when the joint is locked
    lock: u32,
    // preferred step bₖ
    pref: f32,
}
var<private> ik_joint: array<IkJoint, MAX_JOINTS>;
// 1 when the model has mimic followers
var<private> ik_followers: u32;
// [slot][joint]: column of actuated joint k for active slot a at a * MAX_JOINTS + k
var<private> ik_jac: array<vec3<f32>, IK_JAC_LEN>;
// lower block triangle of J Jᵀ + Λ ((a, b), b ≤ a, at a(a+1)/2 + b), then of its block
// Cholesky factor, with L_aa⁻¹ in the diagonal blocks
var<private> ik_blk: array<mat3x3<f32>, IK_BLOCKS>;
var<private> ik_dq: array<f32, MAX_JOINTS>;
var<private> ik_q: array<f32, MAX_JOINTS>;

fn ik_joint_frame(jd: JointDesc, parent_pos: vec3<f32>, parent_rot: vec4<f32>, q: f32) -> IkFrame {
    let frame_rot = quat_mul(parent_rot, jd.origin_rot);
    // o = p_parent + R_parent · origin
    let origin = parent_pos + quat_rotate(parent_rot, jd.origin_pos.xyz);
    let axis = quat_rotate(frame_rot, jd.axis.xyz);
    // R_child = R_parent ⊗ R_origin ⊗ R(axis, q)
    let rot = quat_mul(frame_rot, quat_from_axis_angle(jd.axis.xyz, q));
    return IkFrame(origin, axis, rot);
}

fn ik_link_poses(q: array<f32, MAX_JOINTS>) {
    ik_link_pos[0] = vec3<f32>(0.0);
    ik_link_rot[0] = vec4<f32>(0.0, 0.0, 0.0, 1.0);
    for (var j = 0u; j < g.n_joints; j++) {
        let p = joints[j].parent_link;
        let f = ik_joint_frame(joints[j], ik_link_pos[p], ik_link_rot[p], q[j]);
        ik_link_pos[j + 1u] = f.origin;
        ik_link_rot[j + 1u] = f.rot;
    }
}

// q_f = mult · q_leader + offset
fn ik_apply_mimic(q: ptr<function, array<f32, MAX_JOINTS>>) {
    for (var j = 0u; j < g.n_joints; j++) {
        let jd = joints[j];
        if (jd.mimic_leader != NO_JOINT) {
            (*q)[j] = jd.mimic_mult * (*q)[jd.mimic_leader] + jd.mimic_offset;
        }
    }
}

fn ik_chain(t: u32) -> u32 {
    let base = t * MAX_JOINTS;
    // walk up: link l is moved by joint l − 1, whose parent link is next
    var n = 0u;
    var link = tips[t].link;
    for (var k = 0u; k < MAX_JOINTS; k++) {
        if (link == 0u) {
            break;
        }
        let j = link - 1u;
        ik_chain_j[base + n] = j;
        n += 1u;
        link = joints[j].parent_link;
    }
    // reverse into root → tip order
    for (var i = 0u; i < n / 2u; i++) {
        let a = ik_chain_j[base + i];
        ik_chain_j[base + i] = ik_chain_j[base + n - 1u - i];
        ik_chain_j[base + n - 1u - i] = a;
    }
    return n;
}

fn ik_chain_fk(t: u32, n: u32, q: array<f32, MAX_JOINTS>) -> vec3<f32> {
    var pos = vec3<f32>(0.0);
    var rot = vec4<f32>(0.0, 0.0, 0.0, 1.0);
    for (var i = 0u; i < n; i++) {
        let j = ik_chain_j[t * MAX_JOINTS + i];
        let f = ik_joint_frame(joints[j], pos, rot, q[j]);
        ik_chain_o[i] = f.origin;
        ik_chain_a[i] = f.axis;
        pos = f.origin;
        rot = f.rot;
    }
    // x_tip = p_link + R_link · tip.pos
    return pos + quat_rotate(rot, tips[t].pos.xyz);
}

fn ik_tip_positions(q: array<f32, MAX_JOINTS>) -> array<vec3<f32>, MAX_TIPS> {
    var out: array<vec3<f32>, MAX_TIPS>;
    for (var t = 0u; t < g.n_tips; t++) {
        let n = ik_chain(t);
        out[t] = ik_chain_fk(t, n, q);
    }
    return out;
}

fn ik_leader(j: u32) -> u32 {
    let l = joints[j].mimic_leader;
    return select(j, l, l != NO_JOINT);
}

fn ik_setup(mask: u32) -> u32 {
    ik_followers = 0u;
    for (var k = 0u; k < MAX_JOINTS; k++) {
        ik_joint[k].slots = 0u;
        ik_joint[k].lock = 0u;
        if (k < g.n_joints && joints[k].mimic_leader != NO_JOINT) {
            ik_followers = 1u;
        }
    }
    var a = 0u;
    for (var t = 0u; t < g.n_tips; t++) {
        if (((mask >> t) & 1u) != 0u) {
            let n = ik_chain(t);
            ik_tip[t].chain_n = n;
            for (var k = 0u; k < g.n_joints; k++) {
                ik_jac[a * MAX_JOINTS + k] = vec3<f32>(0.0);
            }
            var cnt = 0u;
            for (var i = 0u; i < n; i++) {
                let k = ik_leader(ik_chain_j[t * MAX_JOINTS + i]);
                // each leader once per slot
                let first = ((ik_joint[k].slots >> a) & 1u) == 0u;
                ik_first[t * MAX_JOINTS + i] = select(0u, 1u, first);
                if (first) {
                    ik_lead[a * MAX_JOINTS + cnt] = k;
                    cnt += 1u;
                }
                ik_joint[k].slots |= 1u << a;
            }
            ik_tip[a].lead_n = cnt;
            a += 1u;
        }
    }
    for (var b = 0u; b < a; b++) {
        ik_tip[b].couple = 0u;
        for (var i = 0u; i < ik_tip[b].lead_n; i++) {
            ik_tip[b].couple |= ik_joint[ik_lead[b * MAX_JOINTS + i]].slots;
        }
    }
    return a;
}

fn ik_tip_jacobian(t: u32, a: u32, goal: vec3<f32>) -> vec3<f32> {
    let n = ik_tip[t].chain_n;
    let q = ik_q;
    let x = ik_chain_fk(t, n, q);
    for (var i = 0u; i < n; i++) {
        let j = ik_chain_j[t * MAX_JOINTS + i];
        let k = ik_leader(j);
        let w = select(joints[j].mimic_mult, 1.0, j == k);
        // Jₐₖ = Σ wⱼ aⱼ × (x − oⱼ) over the chain joints driven by k
        let c = w * cross(ik_chain_a[i], x - ik_chain_o[i]);
        if (ik_first[t * MAX_JOINTS + i] != 0u) {
            ik_jac[a * MAX_JOINTS + k] = c;
        } else {
            ik_jac[a * MAX_JOINTS + k] += c;
        }
    }
    // e = x* − x, aimed at no farther than IK_ERR_CLAMP per iteration
    let e = goal - x;
    let len = length(e);
    ik_tip[a].err = select(e, e * (IK_ERR_CLAMP / len), len > IK_ERR_CLAMP);
    // sₐ = e · (o₀ − x) / |o₀ − x|: how far the target lies nearer to the chain's first joint o₀
    // than the tip (> 0: the finger must get shorter)
    let root = select(x, ik_chain_o[0], n > 0u);
    let inward = root - x;
    ik_tip[a].shorten = dot(e, inward) / max(length(inward), 1e-6);
    return e;
}

// u vᵀ
fn ik_outer(u: vec3<f32>, v: vec3<f32>) -> mat3x3<f32> {
    return mat3x3<f32>(u * v.x, u * v.y, u * v.z);
}

// L⁻¹ for the lower Cholesky factor of a symmetric positive definite a (lower triangle read)
fn ik_chol3_inv(a: mat3x3<f32>) -> mat3x3<f32> {
    let l00 = sqrt(max(a[0].x, 1e-20));
    let l10 = a[0].y / l00;
    let l20 = a[0].z / l00;
    let l11 = sqrt(max(a[1].y - l10 * l10, 1e-20));
    let l21 = (a[1].z - l20 * l10) / l11;
    let l22 = sqrt(max(a[2].z - l20 * l20 - l21 * l21, 1e-20));
    let i00 = 1.0 / l00;
    let i11 = 1.0 / l11;
    let i22 = 1.0 / l22;
    let i10 = -l10 * i00 * i11;
    let i21 = -l21 * i11 * i22;
    let i20 = -(l20 * i00 + l21 * i10) * i22;
    return mat3x3<f32>(vec3<f32>(i00, i10, i20), vec3<f32>(0.0, i11, i21), vec3<f32>(0.0, 0.0, i22));
}

// block (a, b) of J Jᵀ + Λ = Σₖ Jₐₖ Jᵦₖᵀ (+ λₐ² I for a = b), over slot a's joints
fn ik_build_gram(n_active: u32) {
    for (var a = 0u; a < n_active; a++) {
        for (var b = 0u; b <= a; b++) {
            var sum = mat3x3<f32>(vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0));
            if (a == b) {
                let l2 = ik_tip[a].lam2;
                sum = mat3x3<f32>(vec3<f32>(l2, 0.0, 0.0), vec3<f32>(0.0, l2, 0.0), vec3<f32>(0.0, 0.0, l2));
            }
            // chains that share no joint leave their block zero
            if (((ik_tip[a].couple >> b) & 1u) != 0u) {
                for (var i = 0u; i < ik_tip[a].lead_n; i++) {
                    let k = ik_lead[a * MAX_JOINTS + i];
                    sum += ik_outer(ik_jac[a * MAX_JOINTS + k], ik_jac[b * MAX_JOINTS + k]);
                }
            }
            ik_blk[a * (a + 1u) / 2u + b] = sum;
        }
    }
}

// (J Jᵀ + Λ) y = r in place (r in ik_tip[·].y on entry) by block Cholesky, then L z = r and Lᵀ y = z
fn ik_cholesky(n_active: u32) {
    for (var i = 0u; i < n_active; i++) {
        for (var j = 0u; j <= i; j++) {
            var mm = ik_blk[i * (i + 1u) / 2u + j];
            for (var k = 0u; k < j; k++) {
                mm -= ik_blk[i * (i + 1u) / 2u + k] * transpose(ik_blk[j * (j + 1u) / 2u + k]);
            }
            if (i == j) {
                // the diagonal block keeps L_ii⁻¹
                ik_blk[i * (i + 1u) / 2u + i] = ik_chol3_inv(mm);
            } else {
                ik_blk[i * (i + 1u) / 2u + j] = mm * transpose(ik_blk[j * (j + 1u) / 2u + j]);
            }
        }
    }
    // L z = r: z_i = L_ii⁻¹ (r_i − Σ_{k<i} L_ik z_k), z_k (k < i) already in ik_tip[·].y
    for (var i = 0u; i < n_active; i++) {
        var r = ik_tip[i].y;
        for (var k = 0u; k < i; k++) {
            r -= ik_blk[i * (i + 1u) / 2u + k] * ik_tip[k].y;
        }
        ik_tip[i].y = ik_blk[i * (i + 1u) / 2u + i] * r;
    }
    // Lᵀ y = z: y_i = L_ii⁻ᵀ (z_i − Σ_{k>i} L_kiᵀ y_k)
    for (var ii = 0u; ii < n_active; ii++) {
        let i = n_active - 1u - ii;
        var r = ik_tip[i].y;
        for (var k = i + 1u; k < n_active; k++) {
            r -= transpose(ik_blk[k * (k + 1u) / 2u + i]) * ik_tip[k].y;
        }
        ik_tip[i].y = transpose(ik_blk[i * (i + 1u) / 2u + i]) * r;
    }
}

// Δq = b + Jᵀ (J Jᵀ + Λ)⁻¹ (ê − J b), Δqₖ = bₖ + Σₐ Jₐₖ · yₐ
fn ik_dls_step(n_active: u32) {
    // r_a = ê_a − Σₖ Jₐₖ bₖ: the solve takes back what J sees of b
    for (var a = 0u; a < n_active; a++) {
        var r = ik_tip[a].err;
        for (var i = 0u; i < ik_tip[a].lead_n; i++) {
            let k = ik_lead[a * MAX_JOINTS + i];
            r -= ik_jac[a * MAX_JOINTS + k] * ik_joint[k].pref;
        }
        ik_tip[a].y = r;
    }
    ik_build_gram(n_active);
    ik_cholesky(n_active);
    for (var k = 0u; k < g.n_joints; k++) {
        ik_dq[k] = ik_joint[k].pref;
    }
    for (var a = 0u; a < n_active; a++) {
        for (var i = 0u; i < ik_tip[a].lead_n; i++) {
            let k = ik_lead[a * MAX_JOINTS + i];
            ik_dq[k] += dot(ik_jac[a * MAX_JOINTS + k], ik_tip[a].y);
        }
    }
}

// λₐ² = (damping · clamp(|eₐ| / IK_DAMPING_DIST, IK_DAMPING_FLOOR, 1))² + IK_DAMPING_CURV · |êₐ|
fn ik_damping(n_active: u32, prm: IkParams) {
    for (var a = 0u; a < n_active; a++) {
        // λ = damping · clamp(|e| / IK_DAMPING_DIST, IK_DAMPING_FLOOR, 1)
        let l = prm.damping * clamp(ik_tip[a].res / IK_DAMPING_DIST, IK_DAMPING_FLOOR, 1.0);
        // λ² + C·|ê|: the dropped Hessian term |ê| · lever, ê the residual the step aims at
        ik_tip[a].lam2 = l * l + IK_DAMPING_CURV * min(ik_tip[a].res, IK_ERR_CLAMP);
    }
}

// bₖ = IK_BIAS · ρₖ · (midₖ − qₖ) for a limited joint on an active chain, else 0
fn ik_bias(n_active: u32) {
    let n = g.n_joints;
    for (var k = 0u; k < n; k++) {
        ik_joint[k].pref = 0.0;
    }
    // ρₖ = max over k's slots of ρₐ, gathered in ik_joint[·].pref
    for (var a = 0u; a < n_active; a++) {
        // wₐ = clamp(1 + 2 sₐ / |eₐ|, 0, 1): 1 unless the target lies beyond the tip
        let toward = clamp(1.0 + 2.0 * ik_tip[a].shorten / max(ik_tip[a].res, 1e-30), 0.0, 1.0);
        // ρₐ = min(|eₐ| / IK_DAMPING_DIST, 1) · wₐ
        let rho = min(ik_tip[a].res / IK_DAMPING_DIST, 1.0) * toward;
        for (var i = 0u; i < ik_tip[a].lead_n; i++) {
            let k = ik_lead[a * MAX_JOINTS + i];
            ik_joint[k].pref = max(ik_joint[k].pref, rho);
        }
    }
    for (var k = 0u; k < n; k++) {
        let jd = joints[k];
        // unlimited joints (±1e30) have no middle
        if (jd.lower > -1e29 && jd.upper < 1e29) {
            // bₖ = IK_BIAS · ρₖ · ((lower + upper) / 2 − qₖ)
            ik_joint[k].pref = IK_BIAS * ik_joint[k].pref * (0.5 * (jd.lower + jd.upper) - ik_q[k]);
        } else {
            ik_joint[k].pref = 0.0;
        }
    }
}

fn ik_iterate(targets: array<vec3<f32>, MAX_TIPS>, mask: u32, n_active: u32, prm: IkParams) -> bool {
    let n = g.n_joints;
    var worst = 0.0;
    var finite = true;
    var a = 0u;
    for (var t = 0u; t < g.n_tips; t++) {
        if (((mask >> t) & 1u) != 0u) {
            let e = length(ik_tip_jacobian(t, a, targets[t]));
            ik_tip[a].res = e;
            worst = max(worst, e);
            // NaN fails the comparison
            finite = finite && e < 1e30;
            a += 1u;
        }
    }
    // every tip reached, or a non-finite target: nothing moves
    if (!(worst > prm.tol) || !finite) {
        return false;
    }
    ik_damping(n_active, prm);
    ik_bias(n_active);
    var dmax = 0.0;
    for (var lr = 0u; lr < IK_LOCK_ROUNDS; lr++) {
        ik_dls_step(n_active);
        // lock every joint at a limit that Δq pushes further out, zero its columns, solve again
        var locked = false;
        dmax = 0.0;
        for (var k = 0u; k < n; k++) {
            let jd = joints[k];
            let d = ik_dq[k];
            if (ik_joint[k].lock == 0u && ((ik_q[k] <= jd.lower && d < 0.0) || (ik_q[k] >= jd.upper && d > 0.0))) {
                ik_joint[k].lock = 1u;
                locked = true;
                ik_joint[k].pref = 0.0;
                for (var b = 0u; b < n_active; b++) {
                    ik_jac[b * MAX_JOINTS + k] = vec3<f32>(0.0);
                }
            } else if (ik_joint[k].lock == 0u) {
                dmax = max(dmax, abs(d));
                // NaN fails the comparison
                finite = finite && abs(d) < 1e30;
            }
        }
        if (!locked) {
            break;
        }
    }
    // a non-finite step moves nothing
    if (!finite) {
        return false;
    }
    // the stop fades in: below 2·tol the step shrinks to 0 at tol, fade = (worst − tol) / tol
    let fade = select(1.0, (worst - prm.tol) / prm.tol, worst < 2.0 * prm.tol);
    // scale Δq so that max |Δqₖ| ≤ max_step, keeping its direction
    let scale = select(1.0, prm.max_step / dmax, dmax > prm.max_step) * fade;
    for (var k = 0u; k < n; k++) {
        let jd = joints[k];
        if (ik_joint[k].slots != 0u && ik_joint[k].lock == 0u) {
            ik_q[k] = clamp(ik_q[k] + scale * ik_dq[k], jd.lower, jd.upper);
        }
        // the locks hold for one iteration
        ik_joint[k].lock = 0u;
    }
    if (ik_followers != 0u) {
        var qm = ik_q;
        ik_apply_mimic(&qm);
        ik_q = qm;
    }
    return true;
}

fn ik_solve(q_seed: array<f32, MAX_JOINTS>, targets: array<vec3<f32>, MAX_TIPS>, mask: u32, prm: IkParams) -> array<f32, MAX_JOINTS> {
    ik_q = q_seed;
    let n_active = ik_setup(mask);
    for (var it = 0u; it < prm.iters; it++) {
        if (!ik_iterate(targets, mask, n_active, prm)) {
            break;
        }
    }
    return ik_q;
}
