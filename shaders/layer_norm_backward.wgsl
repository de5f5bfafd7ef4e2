// LayerNorm's backward pass for the rows, one workgroup per row, launched on burn's command stream
// by learn/layer_norm.rs (the GPU twin of its CPU loop), after layer_norm_common.wgsl: from ĥ
// [B, n], r [B], the gain g [n] and ∂y [B, n], with d = ∂y g: ∂h = r (d − mean(d) − ĥ mean(d ĥ))
// per row, and ∂y ĥ [B, n], whose column sums (taken after, in two stages) are ∂g. One kernel where
// the tensor ops were eight.

// bound by cubecl in this order: the buffers, then the launch's constants as a uniform
@group(0) @binding(0) var<storage, read_write> lnb_normed: array<f32>;    // [B, n] ĥ
@group(0) @binding(1) var<storage, read_write> lnb_rstd: array<f32>;      // [B] r
@group(0) @binding(2) var<storage, read_write> lnb_gain: array<f32>;      // [n] g
@group(0) @binding(3) var<storage, read_write> lnb_dy: array<f32>;        // [B, n] ∂L/∂y
@group(0) @binding(4) var<storage, read_write> lnb_dh: array<f32>;        // [B, n] ∂L/∂h
@group(0) @binding(5) var<storage, read_write> lnb_dy_normed: array<f32>; // [B, n] ∂y ĥ
@group(0) @binding(6) var<uniform> lbc: LnCfg;

@compute @workgroup_size(64, 1, 1)
fn layer_norm_backward(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lane: u32) {
    let row = wid.y * lbc.grid_x + wid.x;
    if row >= lbc.rows {
        return; // (uniform across the workgroup)
    }
    let base = row * lbc.n;
    var sums = vec2<f32>(0.0, 0.0);
    for (var j = lane; j < lbc.n; j = j + LANES) {
        let d = lnb_dy[base + j] * lnb_gain[j]; // d = ∂y g
        sums = sums + vec2<f32>(d, d * lnb_normed[base + j]);
    }
    let means = lanes_sum2(sums, lane) / f32(lbc.n); // (mean(d), mean(d ĥ))
    let r = lnb_rstd[row];
    for (var j = lane; j < lbc.n; j = j + LANES) {
        let dy = lnb_dy[base + j];
        let normed = lnb_normed[base + j];
        lnb_dh[base + j] = r * (dy * lnb_gain[j] - means.x - normed * means.y); // r (d − mean(d) − ĥ mean(d ĥ))
        lnb_dy_normed[base + j] = dy * normed; // ∂y ĥ
    }
}
