// LayerNorm's forward pass, one workgroup per row, launched on burn's command stream by
// learn/layer_norm.rs (the GPU twin of its CPU loop, `impl LayerNormOps for Flex`), after
// layer_norm_common.wgsl: for h [B, n], gain g and shift s [n], per row μ = mean(h),
// σ² = mean((h − μ)²) (biased, torch's), r = 1/√(σ² + ε), ĥ = (h − μ) r, y = ĥ g + s. One kernel
// where the tensor ops were ten (two reductions and eight element-wise passes). A template of two
// modules: layer_norm.rs writes in (at the marker that begins with a dollar sign) whether ELU
// (α = 1) follows in the same kernel, y = ELU(ĥ g + s) with elu_forward.wgsl's expression (the
// output of the LayerNorm and ELU layers of a critic in one launch where they were two).

const LN_THEN_ELU: bool = $THEN_ELU;

// bound by cubecl in this order: the buffers, then the launch's constants as a uniform
@group(0) @binding(0) var<storage, read_write> ln_h: array<f32>;      // [B, n] the input
@group(0) @binding(1) var<storage, read_write> ln_gain: array<f32>;   // [n] g
@group(0) @binding(2) var<storage, read_write> ln_shift: array<f32>;  // [n] s
@group(0) @binding(3) var<storage, read_write> ln_y: array<f32>;      // [B, n] the output
@group(0) @binding(4) var<storage, read_write> ln_normed: array<f32>; // [B, n] ĥ (for the backward pass)
@group(0) @binding(5) var<storage, read_write> ln_rstd: array<f32>;   // [B] r (for the backward pass)
@group(0) @binding(6) var<uniform> lc: LnCfg;

@compute @workgroup_size(64, 1, 1)
fn layer_norm_forward(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lane: u32) {
    let row = wid.y * lc.grid_x + wid.x;
    if row >= lc.rows {
        return; // (uniform across the workgroup)
    }
    let base = row * lc.n;
    var sum = 0.0;
    for (var j = lane; j < lc.n; j = j + LANES) {
        sum = sum + ln_h[base + j];
    }
    let mean = lanes_sum2(vec2<f32>(sum, 0.0), lane).x / f32(lc.n); // μ
    var squares = 0.0;
    for (var j = lane; j < lc.n; j = j + LANES) {
        let c = ln_h[base + j] - mean;
        squares = squares + c * c;
    }
    let variance = lanes_sum2(vec2<f32>(squares, 0.0), lane).x / f32(lc.n); // σ², biased
    let r = 1.0 / sqrt(variance + lc.eps); // 1/√(σ² + ε)
    for (var j = lane; j < lc.n; j = j + LANES) {
        let normed = (ln_h[base + j] - mean) * r; // ĥ
        ln_normed[base + j] = normed;
        let y = normed * ln_gain[j] + ln_shift[j]; // ĥ g + s
        if LN_THEN_ELU {
            ln_y[base + j] = select(exp(min(y, 0.0)) - 1.0, y, y > 0.0); // ELU: y for y > 0, eʸ − 1 otherwise
        } else {
            ln_y[base + j] = y;
        }
    }
    if lane == 0u {
        ln_rstd[row] = r;
    }
}
