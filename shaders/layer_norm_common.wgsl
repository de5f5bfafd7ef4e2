// LayerNorm's shared part (learn/layer_norm.rs prepends it to layer_norm.wgsl and
// layer_norm_backward.wgsl, each a module of its own): the launch's constants and the workgroup's
// sums. One workgroup of LANES invocations per row.

struct LnCfg {
    rows: u32,
    // the row length n
    n: u32,
    // workgroups along x of the 2-D grid (rows beyond 65,535 wrap into y)
    grid_x: u32,
    eps: f32,
}

const LANES: u32 = 64u;

var<workgroup> ln_partial: array<vec2<f32>, 64>;

// Σ of `v` over the workgroup's 64 lanes (a fixed tree order), both components at once, returned
// to every lane.
fn lanes_sum2(v: vec2<f32>, lane: u32) -> vec2<f32> {
    ln_partial[lane] = v;
    workgroupBarrier();
    for (var stride = LANES / 2u; stride > 0u; stride = stride / 2u) {
        if lane < stride {
            ln_partial[lane] = ln_partial[lane] + ln_partial[lane + stride];
        }
        workgroupBarrier();
    }
    let total = ln_partial[0];
    workgroupBarrier(); // every lane has read the total before the array is reused
    return total;
}
