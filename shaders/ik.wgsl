// ik.wgsl — damped least-squares inverse kinematics of the fingertips, in the wrist frame.
// CPU twin: src/env/ik.rs (same function names, same order, same arithmetic; its `IkScratch` is
// the var<private> ik_* memory below). The algorithm is described at the top of the twin.
// Needs common.wgsl before it (g: Globals, joints: binding 1, tips: binding 3, quaternion maths).

// Default sweeps, damping λ (m), largest joint change per tip step (rad), residual tolerance (m).
const IK_ITERS: u32 = 24u;
const IK_DAMPING: f32 = 0.01;
const IK_MAX_STEP: f32 = 0.3;
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
var<private> ik_link_pos: array<vec3<f32>, MAX_LINKS>;
var<private> ik_link_rot: array<vec4<f32>, MAX_LINKS>;
var<private> ik_chain_j: array<u32, MAX_JOINTS>;
var<private> ik_chain_k: array<u32, MAX_JOINTS>;
var<private> ik_chain_o: array<vec3<f32>, MAX_JOINTS>;
var<private> ik_chain_a: array<vec3<f32>, MAX_JOINTS>;
var<private> ik_chain_c: array<vec3<f32>, MAX_JOINTS>;
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
    // walk up: link l is moved by joint l − 1, whose parent link is next
    var n = 0u;
    var link = tips[t].link;
    for (var k = 0u; k < MAX_JOINTS; k++) {
        if (link == 0u) {
            break;
        }
        let j = link - 1u;
        ik_chain_j[n] = j;
        n += 1u;
        link = joints[j].parent_link;
    }
    // reverse into root → tip order
    for (var i = 0u; i < n / 2u; i++) {
        let a = ik_chain_j[i];
        ik_chain_j[i] = ik_chain_j[n - 1u - i];
        ik_chain_j[n - 1u - i] = a;
    }
    return n;
}

fn ik_chain_fk(t: u32, n: u32, q: array<f32, MAX_JOINTS>) -> vec3<f32> {
    var pos = vec3<f32>(0.0);
    var rot = vec4<f32>(0.0, 0.0, 0.0, 1.0);
    for (var i = 0u; i < n; i++) {
        let j = ik_chain_j[i];
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

// A x = b for a symmetric positive definite A = (a00, a01, a02, a11, a12, a22), by Cholesky
fn ik_solve3(a: array<f32, 6>, b: vec3<f32>) -> vec3<f32> {
    let l00 = sqrt(max(a[0], 1e-20));
    let l10 = a[1] / l00;
    let l20 = a[2] / l00;
    let l11 = sqrt(max(a[3] - l10 * l10, 1e-20));
    let l21 = (a[4] - l20 * l10) / l11;
    let l22 = sqrt(max(a[5] - l20 * l20 - l21 * l21, 1e-20));
    // L y = b
    let y0 = b.x / l00;
    let y1 = (b.y - l10 * y0) / l11;
    let y2 = (b.z - l20 * y0 - l21 * y1) / l22;
    // Lᵀ x = y
    let x2 = y2 / l22;
    let x1 = (y1 - l21 * x2) / l11;
    let x0 = (y0 - l10 * x1 - l20 * x2) / l00;
    return vec3<f32>(x0, x1, x2);
}

fn ik_leader(j: u32) -> u32 {
    let l = joints[j].mimic_leader;
    return select(j, l, l != NO_JOINT);
}

fn ik_tip_step(t: u32, target: vec3<f32>, prm: IkParams) -> bool {
    let n = ik_chain(t);
    let q = ik_q;
    let p = ik_chain_fk(t, n, q);
    // e = x* − x
    let e = target - p;
    if (!(length(e) > prm.tol)) {
        return false;
    }
    // A = J Jᵀ + λ² I = Σₖ cₖ cₖᵀ + λ² I, (a00, a01, a02, a11, a12, a22)
    let l2 = prm.damping * prm.damping;
    var a = array<f32, 6>(l2, 0.0, 0.0, l2, 0.0, l2);
    for (var i = 0u; i < n; i++) {
        let k = ik_leader(ik_chain_j[i]);
        // the first chain entry driven by k carries k's column
        var first = true;
        for (var i2 = 0u; i2 < i; i2++) {
            if (ik_leader(ik_chain_j[i2]) == k) {
                first = false;
            }
        }
        var c = vec3<f32>(0.0);
        ik_chain_k[i] = NO_JOINT;
        if (first) {
            ik_chain_k[i] = k;
            for (var i2 = i; i2 < n; i2++) {
                let j2 = ik_chain_j[i2];
                if (ik_leader(j2) == k) {
                    let w = select(joints[j2].mimic_mult, 1.0, j2 == k);
                    // cₖ += w aⱼ × (p − oⱼ)
                    c += w * cross(ik_chain_a[i2], p - ik_chain_o[i2]);
                }
            }
        }
        ik_chain_c[i] = c;
        a[0] += c.x * c.x;
        a[1] += c.x * c.y;
        a[2] += c.x * c.z;
        a[3] += c.y * c.y;
        a[4] += c.y * c.z;
        a[5] += c.z * c.z;
    }
    // y = (J Jᵀ + λ² I)⁻¹ e;  Δqₖ = cₖ · y
    let y = ik_solve3(a, e);
    var dmax = 0.0;
    for (var i = 0u; i < n; i++) {
        dmax = max(dmax, abs(dot(ik_chain_c[i], y)));
    }
    // a non-finite step (NaN or infinite target) moves nothing
    if (!(dmax < 1e30)) {
        return false;
    }
    // scale Δq so that max |Δqₖ| ≤ max_step
    let scale = select(1.0, prm.max_step / dmax, dmax > prm.max_step);
    for (var i = 0u; i < n; i++) {
        let k = ik_chain_k[i];
        if (k != NO_JOINT) {
            let jd = joints[k];
            ik_q[k] = clamp(ik_q[k] + scale * dot(ik_chain_c[i], y), jd.lower, jd.upper);
        }
    }
    var qm = ik_q;
    ik_apply_mimic(&qm);
    ik_q = qm;
    return true;
}

fn ik_solve(q_seed: array<f32, MAX_JOINTS>, targets: array<vec3<f32>, MAX_TIPS>, mask: u32, prm: IkParams) -> array<f32, MAX_JOINTS> {
    ik_q = q_seed;
    for (var it = 0u; it < prm.iters; it++) {
        var moved = false;
        for (var t = 0u; t < g.n_tips; t++) {
            if (((mask >> t) & 1u) != 0u) {
                let mv = ik_tip_step(t, targets[t], prm);
                moved = moved || mv;
            }
        }
        // a sweep that moved nothing would repeat forever: stop
        if (!moved) {
            break;
        }
    }
    return ik_q;
}
