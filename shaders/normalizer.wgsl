// ---- The observation normalisers of a device-resident learner, over burn's tensors
// (src/learn/normalizer.rs's `DeviceNormalizers::update_and_normalize`; CPU twin: `Normalizer::update`
// and `Normalizer::apply` in f64). Two entry points per normaliser and env step, launched on burn's
// command stream by learn/kernels/fused_normalizer.rs:
//   norm_update   one workgroup per column: the batch's mean and Σ (x − μ_b)² in a fixed order, Chan's
//                 merge into the running statistics (in place), and the column's scale 1 / (σ + ε)
//   norm_apply    one invocation per entry: (x − μ) · scale
// A template of two modules: each keeps the common text and its own section (`//@entry NAME` …
// `//@end`), with the bindings it uses numbered as the launch passes them (cubecl binds the
// buffers in order, then the launch's constants as a uniform).

const NORM_WORKGROUP: u32 = 256u;

struct NormCfg {
    // rows B and columns D of the batch
    rows: u32,
    cols: u32,
    _pad0: u32,
    _pad1: u32,
    // nb / n and na · nb / n for na rows merged before, nb = B, n = na + nb (computed in f64)
    w_mean: f32,
    w_m2: f32,
    // n, the rows merged after this batch (0: no statistics yet, scale 1 / (1 + ε))
    count: f32,
    eps: f32,
}

//@entry norm_update
// [B, D] raw observations (read only, bound read_write as every burn tensor: see adam.wgsl)
@group(0) @binding(0) var<storage, read_write> norm_x: array<f32>;
// [D] running mean and Σ (x − μ)² (burn tensors [1, D], updated in place)
@group(0) @binding(1) var<storage, read_write> norm_mean: array<f32>;
@group(0) @binding(2) var<storage, read_write> norm_m2: array<f32>;
// [D] 1 / (√(M2 / n) + ε) after the update
@group(0) @binding(3) var<storage, read_write> norm_scale: array<f32>;
@group(0) @binding(4) var<uniform> nc: NormCfg;

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

// column c = the workgroup: μ_b = x₀ + mean(x − x₀) (about the first row: exact for a constant
// column), M2_b = Σ (x − μ_b)²; Chan: δ = μ_b − μ, μ ← μ + δ nb/n, M2 ← M2 + M2_b + δ² na nb/n;
// scale = 1 / (√(M2 / n) + ε)
@compute @workgroup_size(NORM_WORKGROUP)
fn norm_update(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    // (dispatched over exactly `cols` workgroups: no early return before the barriers)
    let c = wid.x;
    let x0 = norm_x[c];
    var s = 0.0;
    for (var r = lid; r < nc.rows; r = r + NORM_WORKGROUP) {
        s = s + (norm_x[r * nc.cols + c] - x0);
    }
    norm_shared[lid] = s;
    norm_tree_sum(lid);
    let bmean = x0 + norm_shared[0] / f32(nc.rows);
    workgroupBarrier();
    var s2 = 0.0;
    for (var r = lid; r < nc.rows; r = r + NORM_WORKGROUP) {
        let d = norm_x[r * nc.cols + c] - bmean;
        s2 = s2 + d * d;
    }
    norm_shared[lid] = s2;
    norm_tree_sum(lid);
    if (lid == 0u) {
        let bm2 = norm_shared[0];
        let delta = bmean - norm_mean[c];
        norm_mean[c] = norm_mean[c] + delta * nc.w_mean;
        let m2 = norm_m2[c] + bm2 + (delta * delta) * nc.w_m2;
        norm_m2[c] = m2;
        norm_scale[c] = 1.0 / (sqrt(m2 / nc.count) + nc.eps);
    }
}

//@end

//@entry norm_apply
// [B, D] raw observations, [D] the running mean and 1 / (σ + ε)
@group(0) @binding(0) var<storage, read_write> norm_x: array<f32>;
@group(0) @binding(1) var<storage, read_write> norm_mean: array<f32>;
@group(0) @binding(2) var<storage, read_write> norm_scale: array<f32>;
// [B, D] the normalised observations
@group(0) @binding(3) var<storage, read_write> norm_out: array<f32>;
@group(0) @binding(4) var<uniform> nc: NormCfg;

// out[r, c] = (x[r, c] − μ[c]) · scale[c]; before any statistics (count 0): x / (1 + ε)
@compute @workgroup_size(NORM_WORKGROUP)
fn norm_apply(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let e = gid.x + gid.y * nwg.x * NORM_WORKGROUP;
    if (e >= nc.rows * nc.cols) {
        return;
    }
    let c = e % nc.cols;
    if (nc.count > 0.0) {
        norm_out[e] = (norm_x[e] - norm_mean[c]) * norm_scale[c];
    } else {
        norm_out[e] = (norm_x[e] - norm_mean[c]) * (1.0 / (1.0 + nc.eps));
    }
}
//@end
