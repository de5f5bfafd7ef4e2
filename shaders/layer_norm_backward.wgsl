// LayerNorm's backward pass for the rows, one workgroup per row, launched on burn's command stream
// by learn/layer_norm.rs (the GPU twin of its CPU loop), after layer_norm_common.wgsl: from ĥ
// [B, n], r [B], the gain g [n] and ∂y [B, n], with d = ∂y g: ∂h = r (d − mean(d) − ĥ mean(d ĥ))
// per row, and the rows whose column sums (taken after, in two stages, in one launch) are the
// parameters' gradients: [∂y ĥ | ∂y] [B, 2n] (∂g = Σ_rows ∂y ĥ, ∂s = Σ_rows ∂y). One kernel where
// the tensor ops were eight. A template of a module per entry point (`//@entry NAME` … `//@end`):
//   layer_norm_backward       ∂y given
//   layer_norm_elu_backward   LayerNorm then ELU (α = 1) in one operation: ∂y = ∂L/∂z · min(z + 1, 1)
//                             from the ELU's output z and its gradient (elu_backward.wgsl's
//                             expression), the ELU's kernel of the backward pass folded in

// the workgroup's row (from its id): ∂h and the rows of the parameters' gradients; ∂y at entry i
// (`lnb_dy_at`) and the bindings are each section's
fn lnb_rows(wid: vec3<u32>, lane: u32) {
    let row = wid.y * lbc.grid_x + wid.x;
    if row >= lbc.rows {
        return; // (uniform across the workgroup)
    }
    let base = row * lbc.n;
    var sums = vec2<f32>(0.0, 0.0);
    for (var j = lane; j < lbc.n; j = j + LANES) {
        let d = lnb_dy_at(base + j) * lnb_gain[j]; // d = ∂y g
        sums = sums + vec2<f32>(d, d * lnb_normed[base + j]);
    }
    let means = lanes_sum2(sums, lane) / f32(lbc.n); // (mean(d), mean(d ĥ))
    let r = lnb_rstd[row];
    let params = 2u * base; // the row's first entry of [∂y ĥ | ∂y]
    for (var j = lane; j < lbc.n; j = j + LANES) {
        let dy = lnb_dy_at(base + j);
        let normed = lnb_normed[base + j];
        lnb_dh[base + j] = r * (dy * lnb_gain[j] - means.x - normed * means.y); // r (d − mean(d) − ĥ mean(d ĥ))
        lnb_param_rows[params + j] = dy * normed; // ∂y ĥ
        lnb_param_rows[params + lbc.n + j] = dy; // ∂y
    }
}

//@entry layer_norm_backward
// bound by cubecl in this order: the buffers, then the launch's constants as a uniform
@group(0) @binding(0) var<storage, read_write> lnb_normed: array<f32>;     // [B, n] ĥ
@group(0) @binding(1) var<storage, read_write> lnb_rstd: array<f32>;       // [B] r
@group(0) @binding(2) var<storage, read_write> lnb_gain: array<f32>;       // [n] g
@group(0) @binding(3) var<storage, read_write> lnb_dy: array<f32>;         // [B, n] ∂L/∂y
@group(0) @binding(4) var<storage, read_write> lnb_dh: array<f32>;         // [B, n] ∂L/∂h
@group(0) @binding(5) var<storage, read_write> lnb_param_rows: array<f32>; // [B, 2n] [∂y ĥ | ∂y]
@group(0) @binding(6) var<uniform> lbc: LnCfg;

fn lnb_dy_at(i: u32) -> f32 {
    return lnb_dy[i];
}

@compute @workgroup_size(64, 1, 1)
fn layer_norm_backward(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lane: u32) {
    lnb_rows(wid, lane);
}
//@end

//@entry layer_norm_elu_backward
// bound by cubecl in this order: the buffers, then the launch's constants as a uniform
@group(0) @binding(0) var<storage, read_write> lnb_normed: array<f32>;     // [B, n] ĥ
@group(0) @binding(1) var<storage, read_write> lnb_rstd: array<f32>;       // [B] r
@group(0) @binding(2) var<storage, read_write> lnb_gain: array<f32>;       // [n] g
@group(0) @binding(3) var<storage, read_write> lnb_dz: array<f32>;         // [B, n] ∂L/∂z, z = ELU(y)
@group(0) @binding(4) var<storage, read_write> lnb_z: array<f32>;          // [B, n] z
@group(0) @binding(5) var<storage, read_write> lnb_dh: array<f32>;         // [B, n] ∂L/∂h
@group(0) @binding(6) var<storage, read_write> lnb_param_rows: array<f32>; // [B, 2n] [∂y ĥ | ∂y]
@group(0) @binding(7) var<uniform> lbc: LnCfg;

fn lnb_dy_at(i: u32) -> f32 {
    return lnb_dz[i] * min(lnb_z[i] + 1.0, 1.0); // ∂L/∂z · min(z + 1, 1)
}

@compute @workgroup_size(64, 1, 1)
fn layer_norm_elu_backward(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lane: u32) {
    lnb_rows(wid, lane);
}
//@end
