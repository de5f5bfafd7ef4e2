// SAC's device-resident batch (learn/kernels/replay_sample.rs, for learn/sac/device.rs), launched on
// burn's command stream: rows of one piece of a replay ring gathered into a batch tensor, optionally
// normalised as the device normaliser does it, `(x − μ) · scale` (a subtraction, then a product: the
// tensor ops' two roundings). One invocation per output entry; the rows that lie in other pieces are
// left to those pieces' launches, so that every piece's launch together write each entry once.
//   out[out_first + k, c] = ring[rows[k], c] (· normalised) for k < n, c < cols, rows[k] in the piece

struct GatherCfg {
    // rows of the output to fill, and the columns taken from each ring row (its first `cols`)
    n: u32,
    cols: u32,
    // the ring's row length, the piece's first row in the ring and its rows
    dim: u32,
    first: u32,
    piece_rows: u32,
    // 1: (x − μ[c]) · scale[c]; 0: x (μ and scale bound but not read)
    normalize: u32,
    // the output's row of k = 0
    out_first: u32,
    // entries per row of the 2-D grid: workgroups along x × 256
    row: u32,
}

// bound by cubecl in this order: the buffers, then the launch's constants as a uniform
@group(0) @binding(0) var<storage, read_write> rg_rows: array<u32>;  // [≥ n] ring rows (slot · N + env)
@group(0) @binding(1) var<storage, read_write> rg_piece: array<f32>; // [piece_rows, dim] the piece
@group(0) @binding(2) var<storage, read_write> rg_mean: array<f32>;  // [1, ≥ cols] μ
@group(0) @binding(3) var<storage, read_write> rg_scale: array<f32>; // [1, ≥ cols] 1 / (σ + ε)
@group(0) @binding(4) var<storage, read_write> rg_out: array<f32>;   // [out_first + n, cols]
@group(0) @binding(5) var<uniform> gc: GatherCfg;

@compute @workgroup_size(256, 1, 1)
fn replay_gather(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = gid.y * gc.row + gid.x;
    if i >= gc.n * gc.cols {
        return;
    }
    let k = i / gc.cols;
    let c = i % gc.cols;
    let r = rg_rows[k];
    if r < gc.first || r - gc.first >= gc.piece_rows {
        return; // another piece's row
    }
    var x = rg_piece[(r - gc.first) * gc.dim + c];
    if gc.normalize != 0u {
        x = (x - rg_mean[c]) * rg_scale[c]; // (x − μ) · 1 / (σ + ε)
    }
    rg_out[(gc.out_first + k) * gc.cols + c] = x;
}
