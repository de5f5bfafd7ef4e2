// ---- Adam with global-norm gradient clipping on the learner's GPU, over burn's tensors in place
// (src/learn/fused_adam.rs; CPU twin: learn::adam — `clipped_grads` and `Adam::step` as tensor ops).
// A standalone module: three entry points that one optimiser step runs in order, in one submission.
//   adam_norm_partial  once per parameter: Σ g² of its gradient in ADAM_PARTIALS fixed slices
//   adam_norm_final    once: ‖g‖ = √(Σ of every slice's sum), the clip coefficient
//   adam_update        once per parameter: the clipped gradient into the moments and the parameter
//   adam_update_polyak adam_update and then, for SAC's critics, the target network's copy of the
//                      parameter moved towards it: t ← τ p + (1 − τ) t (Polyak averaging)
// Every sum runs in a fixed order (the same bits on every run of the same adapter).

const ADAM_WORKGROUP: u32 = 256u;
// the slices (workgroups) of one parameter's squared norm
const ADAM_PARTIALS: u32 = 64u;

// the step's constants (one upload per optimiser step)
struct AdamStep {
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
    _pad0: u32,
    _pad1: u32,
}

// one parameter's sizes (a slot per parameter, written once)
struct AdamParam {
    // elements of this parameter
    n: u32,
    // this parameter's first slot in adam_partials
    partial_base: u32,
    // the slots the final pass sums (n_params · ADAM_PARTIALS)
    n_partials: u32,
    _pad: u32,
}

@group(0) @binding(0) var<uniform> ac: AdamStep;
@group(0) @binding(1) var<uniform> ap: AdamParam;
// the parameter, its gradient, its first and second moments (burn tensors; p, m, v updated in place).
// Every burn tensor is bound read_write, those only read too: two tensors may be slices of one of
// cubecl's buffers, and wgpu allows one buffer in a dispatch under one kind of use only
@group(0) @binding(2) var<storage, read_write> adam_p: array<f32>;
@group(0) @binding(3) var<storage, read_write> adam_g: array<f32>;
@group(0) @binding(4) var<storage, read_write> adam_m: array<f32>;
@group(0) @binding(5) var<storage, read_write> adam_v: array<f32>;
// the squared norm's partial sums [n_params · ADAM_PARTIALS]
@group(0) @binding(6) var<storage, read_write> adam_partials: array<f32>;
// [‖g‖ before clipping, clip coefficient] (a burn tensor [1, 2])
@group(0) @binding(7) var<storage, read_write> adam_norm: array<f32>;
// the learning rate [1] (a burn tensor [1, 1]: the adaptive schedule changes it on the device)
@group(0) @binding(8) var<storage, read_write> adam_lr: array<f32>;
// the target network's copy of the parameter (adam_update_polyak; updated in place)
@group(0) @binding(9) var<storage, read_write> adam_target: array<f32>;

var<workgroup> adam_shared: array<f32, ADAM_WORKGROUP>;

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

// slot partial_base + w = Σ g[i]² over i ≡ (w · ADAM_WORKGROUP + lid) mod (ADAM_PARTIALS · ADAM_WORKGROUP)
@compute @workgroup_size(ADAM_WORKGROUP)
fn adam_norm_partial(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let stride = ADAM_PARTIALS * ADAM_WORKGROUP;
    var s = 0.0;
    var i = wid.x * ADAM_WORKGROUP + lid;
    loop {
        if (i >= ap.n) {
            break;
        }
        let g = adam_g[i];
        s = s + g * g;
        i = i + stride;
    }
    adam_shared[lid] = s;
    adam_tree_sum(lid);
    if (lid == 0u) {
        adam_partials[ap.partial_base + wid.x] = adam_shared[0];
    }
}

// ‖g‖ = √(Σ slots) and the clip coefficient min(1, max_norm / (‖g‖ + 1e-6)) (torch's clip_grad_norm_)
@compute @workgroup_size(ADAM_WORKGROUP)
fn adam_norm_final(@builtin(local_invocation_index) lid: u32) {
    var s = 0.0;
    var i = lid;
    loop {
        if (i >= ap.n_partials) {
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
        adam_norm[1] = select(1.0, min(1.0, ac.max_norm / (norm + 1e-6)), ac.clip == 1u);
    }
}

// one element of the parameter: g ← coef · g (coef = 1 without clipping); m ← β1 m + (1 − β1) g; v ← β2 v + (1 − β2) g²;
// p ← p (1 − lr λ); p ← p − lr/(1 − β1ᵗ) · m / (√v / √(1 − β2ᵗ) + ε). Returns the new p.
fn adam_element(i: u32) -> f32 {
    let lr = adam_lr[0];
    let g = adam_g[i] * select(1.0, adam_norm[1], ac.clip == 1u); // (the norm's passes ran only when clipping or asked for)
    let m = adam_m[i] * ac.beta1 + g * (1.0 - ac.beta1);
    let v = adam_v[i] * ac.beta2 + (g * g) * (1.0 - ac.beta2);
    adam_m[i] = m;
    adam_v[i] = v;
    let denom = sqrt(v) / ac.bc2_sqrt + ac.eps;
    var p = adam_p[i];
    if (ac.weight_decay > 0.0) {
        p = p * (1.0 - lr * ac.weight_decay);
    }
    p = p - (m / denom) * (lr / ac.bc1);
    adam_p[i] = p;
    return p;
}

// the element of this invocation (a 2-D grid of ADAM_WORKGROUP-wide rows), or n and beyond
fn adam_index(gid: vec3<u32>, nwg: vec3<u32>) -> u32 {
    return gid.x + gid.y * nwg.x * ADAM_WORKGROUP;
}

@compute @workgroup_size(ADAM_WORKGROUP)
fn adam_update(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = adam_index(gid, nwg);
    if (i >= ap.n) {
        return;
    }
    adam_element(i);
}

// adam_update, then t ← τ p + (1 − τ) t with the new p (the twin of SAC's tensor ops
// `p·τ + t·(1 − τ)`)
@compute @workgroup_size(ADAM_WORKGROUP)
fn adam_update_polyak(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = adam_index(gid, nwg);
    if (i >= ap.n) {
        return;
    }
    let p = adam_element(i);
    adam_target[i] = p * ac.tau + adam_target[i] * ac.one_minus_tau;
}
