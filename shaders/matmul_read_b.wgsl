// matmul.wgsl's scalar reads of B (learn/wgsl_matmul.rs puts them in the template where B is
// read one f32 at a time, with any strides).

// the tile's (column, k) position of the e-th staged B value: k runs fastest over the threads
// where B's rows are contiguous in k (a transposed view), the column where its columns are
fn b_slot(e: u32, cols_fast: bool) -> vec2<u32> {
    if cols_fast {
        return vec2<u32>(e % BN, e / BN);
    }
    return vec2<u32>(e / BK, e % BK);
}

// B's value at tile position p = (column, k) of the slice that starts at k0 (0 outside B or
// past this layer's k range), for the tile's first column col0 and the batch's B at b_base
fn b_value(p: vec2<u32>, col0: u32, k0: u32, k_end: u32, b_base: u32) -> f32 {
    let c = col0 + p.x;
    let k = k0 + p.y;
    if c < mc.n && k < k_end {
        return mm_b[b_base + k * mc.b_row + c * mc.b_col];
    }
    return 0.0;
}
