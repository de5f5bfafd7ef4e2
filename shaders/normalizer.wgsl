// ---- The observation normalisers of a device-resident learner, over burn's tensors
// (src/learn/normalizer.rs's `DeviceNormalizers::update_and_normalize`; CPU twin: `Normalizer::update`
// and `Normalizer::apply` in f64). Two launches per env step for the actor's and the critic's
// normalisers together, on burn's command stream (learn/kernels/fused_normalizer.rs):
//   norm_update   one workgroup per column of every normaliser of the launch: the batch's mean and
//                 Σ (x − μ_b)² in a fixed order, Chan's merge into the running statistics (in
//                 place), and the column's scale 1 / (σ + ε)
//   norm_apply    one invocation per entry of every normaliser: (x − μ) · scale
// A template of a module per entry point: each keeps the common text and its own section
// (`//@entry NAME` … `//@end`); fused_normalizer.rs writes in (at the markers that begin with a
// dollar sign) the launch's number of normalisers, a binding per normaliser and role (each role's
// bindings together, normaliser 0 first, as the launch passes them; cubecl binds the buffers in
// order, then the launch's constants as a uniform) and the accessors that pick normaliser k's.

const NORM_WORKGROUP: u32 = 256u;
// the normalisers of this launch
const GROUP: u32 = $GROUPu;

// one normaliser's batch and merge
struct NormSlot {
    // rows B and columns D of its batch
    rows: u32,
    cols: u32,
    // its first workgroup in the launch (workgroups numbered along x then y)
    first: u32,
    _pad: u32,
    // nb / n and na · nb / n for na rows merged before, nb = B, n = na + nb (computed in f64)
    w_mean: f32,
    w_m2: f32,
    // n, the rows merged after this batch (0: no statistics yet, scale 1 / (1 + ε))
    count: f32,
    eps: f32,
}

struct NormLaunch {
    slots: array<NormSlot, GROUP>,
}

$BINDINGS

$ACCESSORS

// the normaliser whose workgroups hold w: the last that starts at or before it (the same for the
// whole workgroup)
fn norm_slot(w: u32) -> u32 {
    var k = 0u;
    for (var j = 1u; j < GROUP; j++) {
        if (nl.slots[j].first <= w) {
            k = j;
        }
    }
    return k;
}

//@entry norm_update
var<workgroup> norm_shared: array<f32, NORM_WORKGROUP>;

// the workgroup's tree sum of norm_shared (every invocation calls it), left in norm_shared[0]
fn norm_tree_sum(lid: u32) {
    var width = NORM_WORKGROUP / 2u;
    loop {
        if (width == 0u) {
            break;
        }
        workgroupBarrier();
        if (lid < width) {
            norm_shared[lid] = norm_shared[lid] + norm_shared[lid + width];
        }
        width = width / 2u;
    }
    workgroupBarrier();
}

// column c of normaliser k = the workgroup: μ_b = x₀ + mean(x − x₀) (about the first row: exact
// for a constant column), M2_b = Σ (x − μ_b)²; Chan: δ = μ_b − μ, μ ← μ + δ nb/n,
// M2 ← M2 + M2_b + δ² na nb/n; scale = 1 / (√(M2 / n) + ε)
@compute @workgroup_size(NORM_WORKGROUP)
fn norm_update(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let w = wid.y * nwg.x + wid.x;
    let k = norm_slot(w);
    let s_k = nl.slots[k];
    let c = w - s_k.first;
    if (c >= s_k.cols) {
        return; // a workgroup past the last column (of the last normaliser): the whole workgroup
    }
    let x0 = norm_x(k, c);
    var s = 0.0;
    for (var r = lid; r < s_k.rows; r = r + NORM_WORKGROUP) {
        s = s + (norm_x(k, r * s_k.cols + c) - x0);
    }
    norm_shared[lid] = s;
    norm_tree_sum(lid);
    let bmean = x0 + norm_shared[0] / f32(s_k.rows);
    workgroupBarrier();
    var s2 = 0.0;
    for (var r = lid; r < s_k.rows; r = r + NORM_WORKGROUP) {
        let d = norm_x(k, r * s_k.cols + c) - bmean;
        s2 = s2 + d * d;
    }
    norm_shared[lid] = s2;
    norm_tree_sum(lid);
    if (lid == 0u) {
        let bm2 = norm_shared[0];
        let mean = norm_mean(k, c);
        let delta = bmean - mean;
        set_norm_mean(k, c, mean + delta * s_k.w_mean);
        let m2 = norm_m2(k, c) + bm2 + (delta * delta) * s_k.w_m2;
        set_norm_m2(k, c, m2);
        set_norm_scale(k, c, 1.0 / (sqrt(m2 / s_k.count) + s_k.eps));
    }
}
//@end

//@entry norm_apply
// out[r, c] = (x[r, c] − μ[c]) · scale[c] of normaliser k; before any statistics (count 0):
// x / (1 + ε)
@compute @workgroup_size(NORM_WORKGROUP)
fn norm_apply(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let w = wid.y * nwg.x + wid.x;
    let k = norm_slot(w);
    let s_k = nl.slots[k];
    let e = (w - s_k.first) * NORM_WORKGROUP + lid; // the entry of normaliser k
    if (e >= s_k.rows * s_k.cols) {
        return;
    }
    let c = e % s_k.cols;
    if (s_k.count > 0.0) {
        set_norm_out(k, e, (norm_x(k, e) - norm_mean(k, c)) * norm_scale(k, c));
    } else {
        set_norm_out(k, e, (norm_x(k, e) - norm_mean(k, c)) * (1.0 / (1.0 + s_k.eps)));
    }
}
//@end
