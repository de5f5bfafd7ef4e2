// ---- Adam with global-norm gradient clipping on the learner's GPU, over burn's tensors in place,
// several parameters per launch (src/learn/kernels/fused_adam.rs; CPU twin: learn::adam —
// `clip_to_norm` and `Adam::step` as tensor ops). Launched on burn's command stream (cubecl binds
// the buffers in order, then the launch's constants as a uniform). A template: fused_adam.rs keeps
// the sections (`//@entry NAMES` … `//@end`) of the one entry point a launch runs and writes in
// (at the markers that begin with a dollar sign) the group's size, its bindings — one per
// parameter and role — and the accessors that pick a parameter's binding by its index in the
// group. One optimiser step runs, in order:
//   adam_norm_partial  once per group: Σ g² of each of its gradients in ADAM_PARTIALS fixed slices
//   adam_norm_final    once: ‖g‖ = √(Σ of every slice's sum), the clip coefficient
//   adam_update        once per group: the clipped gradient into the moments and the parameter
//   adam_update_polyak adam_update and then, for SAC's critics, the target network's copy of each
//                      parameter moved towards it: t ← τ p + (1 − τ) t (Polyak averaging)
// Every sum runs in a fixed order (the same bits on every run of the same adapter), the same
// order whatever the group's size: a slice's sum, a slot's place and an element's update do not
// depend on which parameters share a launch.

const ADAM_WORKGROUP: u32 = 256u;
// the slices (workgroups) of one parameter's squared norm
const ADAM_PARTIALS: u32 = 64u;
// the parameters of this launch
const GROUP: u32 = $GROUPu;

// the launch's constants (the step's, and the group's sizes)
struct AdamLaunch {
    // 1: scale the gradients by min(1, max_norm / (‖g‖ + 1e-6)); 0: use them as they are
    clip: u32,
    beta1: f32,
    beta2: f32,
    eps: f32,
    // 1 − β1ᵗ
    bc1: f32,
    // √(1 − β2ᵗ)
    bc2_sqrt: f32,
    // decoupled weight decay λ (AdamW), 0 for Adam
    weight_decay: f32,
    max_norm: f32,
    // adam_update_polyak's τ and 1 − τ (worked out on the host in f64)
    tau: f32,
    one_minus_tau: f32,
    // the group's first slot in adam_partials (its first parameter's index · ADAM_PARTIALS)
    partial_base: u32,
    // the slots adam_norm_final sums (every parameter's: n_params · ADAM_PARTIALS)
    n_partials: u32,
    // per parameter of the group: (its elements, its first workgroup in adam_update's grid, 0, 0)
    params: array<vec4<u32>, GROUP>,
}

// the burn tensors (every one bound read_write, those only read too: two tensors may be slices of
// one of cubecl's buffers, and wgpu allows one buffer in a dispatch under one kind of use only):
//   adam_p_k, adam_g_k, adam_m_k, adam_v_k: parameter k of the group, its gradient, its first and
//     second moments (p, m, v updated in place); adam_t_k: its target copy (adam_update_polyak)
//   adam_partials [n_params · ADAM_PARTIALS]: the squared norm's partial sums
//   adam_norm [1]: ‖g‖ before clipping (the step's reported norm)
//   adam_coef [1]: the clip coefficient
//   adam_lr [1]: the learning rate (PPO's adaptive schedule changes it on the device)
$BINDINGS

var<workgroup> adam_shared: array<f32, ADAM_WORKGROUP>;

$ACCESSORS

// the workgroup's tree sum of adam_shared (every invocation calls it), left in adam_shared[0]
fn adam_tree_sum(lid: u32) {
    var width = ADAM_WORKGROUP / 2u;
    loop {
        if (width == 0u) {
            break;
        }
        workgroupBarrier();
        if (lid < width) {
            adam_shared[lid] = adam_shared[lid] + adam_shared[lid + width];
        }
        width = width / 2u;
    }
    workgroupBarrier();
}

// workgroup (w, k): slot partial_base + k · ADAM_PARTIALS + w = Σ g_k[i]² over
// i ≡ (w · ADAM_WORKGROUP + lid) mod (ADAM_PARTIALS · ADAM_WORKGROUP)
//@entry adam_norm_partial
@compute @workgroup_size(ADAM_WORKGROUP)
fn adam_norm_partial(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let k = wid.y;
    let n = ac.params[k].x;
    let stride = ADAM_PARTIALS * ADAM_WORKGROUP;
    var s = 0.0;
    var i = wid.x * ADAM_WORKGROUP + lid;
    loop {
        if (i >= n) {
            break;
        }
        let g = grad(k, i);
        s = s + g * g;
        i = i + stride;
    }
    adam_shared[lid] = s;
    adam_tree_sum(lid);
    if (lid == 0u) {
        adam_partials[ac.partial_base + k * ADAM_PARTIALS + wid.x] = adam_shared[0];
    }
}
//@end

// ‖g‖ = √(Σ slots) and the clip coefficient min(1, max_norm / (‖g‖ + 1e-6)) (torch's clip_grad_norm_)
//@entry adam_norm_final
@compute @workgroup_size(ADAM_WORKGROUP)
fn adam_norm_final(@builtin(local_invocation_index) lid: u32) {
    var s = 0.0;
    var i = lid;
    loop {
        if (i >= ac.n_partials) {
            break;
        }
        s = s + adam_partials[i];
        i = i + ADAM_WORKGROUP;
    }
    adam_shared[lid] = s;
    adam_tree_sum(lid);
    if (lid == 0u) {
        let norm = sqrt(adam_shared[0]);
        adam_norm[0] = norm;
        adam_coef[0] = select(1.0, min(1.0, ac.max_norm / (norm + 1e-6)), ac.clip == 1u);
    }
}
//@end

//@entry adam_update adam_update_polyak
// element i of parameter k: g ← coef · g (coef = 1 without clipping); m ← β1 m + (1 − β1) g;
// v ← β2 v + (1 − β2) g²; p ← p (1 − lr λ); p ← p − lr/(1 − β1ᵗ) · m / (√v / √(1 − β2ᵗ) + ε).
// Returns the new p.
fn adam_element(k: u32, i: u32) -> f32 {
    let lr = adam_lr[0];
    let g = grad(k, i) * select(1.0, adam_coef[0], ac.clip == 1u); // (the norm's passes ran only when clipping or asked for)
    let m = moment1(k, i) * ac.beta1 + g * (1.0 - ac.beta1);
    let v = moment2(k, i) * ac.beta2 + (g * g) * (1.0 - ac.beta2);
    set_moment1(k, i, m);
    set_moment2(k, i, v);
    let denom = sqrt(v) / ac.bc2_sqrt + ac.eps;
    var p = param(k, i);
    if (ac.weight_decay > 0.0) {
        p = p * (1.0 - lr * ac.weight_decay);
    }
    p = p - (m / denom) * (lr / ac.bc1);
    set_param(k, i, p);
    return p;
}

// the (parameter, element) of this invocation: a 2-D grid of workgroups, numbered along x then y;
// parameter k owns the workgroups from params[k].y, ADAM_WORKGROUP elements each. The element is
// the parameter's size or beyond past its end.
fn adam_place(wid: vec3<u32>, nwg: vec3<u32>, lid: u32) -> vec2<u32> {
    let w = wid.x + wid.y * nwg.x;
    var k = 0u;
    for (var j = 1u; j < GROUP; j = j + 1u) {
        if (ac.params[j].y <= w) {
            k = j;
        }
    }
    return vec2<u32>(k, (w - ac.params[k].y) * ADAM_WORKGROUP + lid);
}
//@end

//@entry adam_update
@compute @workgroup_size(ADAM_WORKGROUP)
fn adam_update(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let at = adam_place(wid, nwg, lid);
    if (at.y >= ac.params[at.x].x) {
        return;
    }
    adam_element(at.x, at.y);
}
//@end

// adam_update, then t ← τ p + (1 − τ) t with the new p (the twin of SAC's tensor ops
// `p·τ + t·(1 − τ)`)
//@entry adam_update_polyak
@compute @workgroup_size(ADAM_WORKGROUP)
fn adam_update_polyak(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let at = adam_place(wid, nwg, lid);
    if (at.y >= ac.params[at.x].x) {
        return;
    }
    let p = adam_element(at.x, at.y);
    set_polyak_target(at.x, at.y, p * ac.tau + polyak_target(at.x, at.y) * ac.one_minus_tau);
}
//@end
