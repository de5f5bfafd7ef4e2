// Observations standardised with the normaliser's statistics, one invocation per entry
// (learn/kernels/standardize.rs; the tensor ops it replaces computed the same (x − μ) · s):
//   out[r, k] = (x[r, k] − μ_k) · s_k,   μ = stats[0, ·], s = stats[1, ·] = 1 / (√var + eps)

struct StandardizeCfg {
    // entries of x (rows × dim)
    n: u32,
    dim: u32,
    // invocations per row of the 2-D grid
    grid_row: u32,
    _pad: u32,
}

@group(0) @binding(0) var<storage, read_write> st_x: array<f32>;     // [rows, dim]
@group(0) @binding(1) var<storage, read_write> st_stats: array<f32>; // [2, dim] μ, then s
@group(0) @binding(2) var<storage, read_write> st_out: array<f32>;   // [rows, dim]
@group(0) @binding(3) var<uniform> sc: StandardizeCfg;

@compute @workgroup_size(256, 1, 1)
fn standardize(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = gid.y * sc.grid_row + gid.x;
    if i >= sc.n {
        return;
    }
    let k = i % sc.dim;
    st_out[i] = (st_x[i] - st_stats[k]) * st_stats[sc.dim + k];
}
