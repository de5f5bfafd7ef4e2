// The partial products of a matrix product split over k (matmul.wgsl: [S, M, N]), and the
// partial sums of its row of ones ([S, N], a bias gradient's), each summed over S in increasing s
// from 0, in one kernel launched on burn's command stream by learn/kernels/wgsl_matmul.rs: entry i
// of the product for i < len_c, entry i − len_c of the sums after it.

struct SumSplitsCfg {
    len_c: u32,
    // 0: no sums
    len_s: u32,
    splits: u32,
    // entries per row of the 2-D grid: workgroups along x × 256
    row: u32,
}

// bound by cubecl in this order: the buffers, then the launch's constants as a uniform
@group(0) @binding(0) var<storage, read_write> ss_partials: array<f32>;      // [S, len_c]
@group(0) @binding(1) var<storage, read_write> ss_sum_partials: array<f32>;  // [S, len_s] (any buffer without sums)
@group(0) @binding(2) var<storage, read_write> ss_out: array<f32>;           // [len_c] Σ_s partial_s
@group(0) @binding(3) var<storage, read_write> ss_sums_out: array<f32>;      // [len_s] Σ_s sums_s (any buffer without sums)
@group(0) @binding(4) var<uniform> sc: SumSplitsCfg;

@compute @workgroup_size(256, 1, 1)
fn sum_splits(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = gid.y * sc.row + gid.x;
    if i < sc.len_c {
        var acc = 0.0;
        for (var s = 0u; s < sc.splits; s++) {
            acc = acc + ss_partials[s * sc.len_c + i]; // the splits in order
        }
        ss_out[i] = acc;
    } else if i < sc.len_c + sc.len_s {
        let j = i - sc.len_c;
        var acc = 0.0;
        for (var s = 0u; s < sc.splits; s++) {
            acc = acc + ss_sum_partials[s * sc.len_s + j];
        }
        ss_sums_out[j] = acc;
    }
}
