// Σ over the rows of g [R, C] → [C] in one kernel, launched on burn's command stream by
// learn/kernels/row_sums.rs, in the order of the two stages of burn's reductions it replaces
// (`column_sums_ops`: the rows cut in k blocks of R/k, each block's sum from 0 in row order, then
// the k sums from 0 in block order; k = 1 is the one-stage sum), so the same bits. A workgroup
// takes 16 columns: its 16 × 16 threads sum the blocks of their column (block j on the thread of
// row j % 16), keep the k partial sums in workgroup memory, and one thread per column adds them.

struct ColumnSumsCfg {
    rows: u32,
    cols: u32,
    // k: blocks of rows / k rows each (1 ≤ k ≤ CS_MAX_BLOCKS)
    blocks: u32,
    _pad: u32,
}

// bound by cubecl in this order: the buffers, then the launch's constants as a uniform
@group(0) @binding(0) var<storage, read_write> cs_in: array<f32>;  // [R, C] g
@group(0) @binding(1) var<storage, read_write> cs_out: array<f32>; // [C] 1ᵀ g
@group(0) @binding(2) var<uniform> csc: ColumnSumsCfg;

// columns per workgroup, and threads per column
const CS_COLS: u32 = 16u;
const CS_LANES: u32 = 16u;
// row_sums.rs's MAX_BLOCKS: the partial sums fill 16 KiB of workgroup memory
const CS_MAX_BLOCKS: u32 = 256u;

var<workgroup> cs_partial: array<f32, 4096>; // [CS_MAX_BLOCKS, CS_COLS] block j's sum of column c at j · CS_COLS + c

@compute @workgroup_size(16, 16, 1)
fn column_sums(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_id) lid: vec3<u32>) {
    let c = wid.x * CS_COLS + lid.x;
    let per_block = csc.rows / csc.blocks;
    if c < csc.cols {
        for (var j = lid.y; j < csc.blocks; j += CS_LANES) {
            var acc = 0.0;
            let first = j * per_block;
            for (var r = 0u; r < per_block; r++) {
                acc = acc + cs_in[(first + r) * csc.cols + c]; // the block's rows in order
            }
            cs_partial[j * CS_COLS + lid.x] = acc;
        }
    }
    workgroupBarrier();
    if lid.y == 0u && c < csc.cols {
        var total = 0.0;
        for (var j = 0u; j < csc.blocks; j++) {
            total = total + cs_partial[j * CS_COLS + lid.x]; // the blocks in order
        }
        cs_out[c] = total;
    }
}
