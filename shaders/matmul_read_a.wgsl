// matmul.wgsl's scalar reads of A (learn/wgsl_matmul.rs puts them in the template where A is
// read one f32 at a time, with any strides).

// the tile's (row, k) position of the e-th staged A value: k runs fastest over the threads where
// A's columns are contiguous (a row-major A), the row where its rows are (a transposed view),
// so that neighbouring threads read neighbouring memory
fn a_slot(e: u32, rows_fast: bool) -> vec2<u32> {
    if rows_fast {
        return vec2<u32>(e % BM, e / BM);
    }
    return vec2<u32>(e / BK, e % BK);
}

// A's value at tile position p = (row, k) of the slice that starts at k0 (0 outside A or past
// this layer's k range; 1 in its row of ones), for the tile's first row row0 and the batch's A at
// a_base
fn a_value(p: vec2<u32>, row0: u32, k0: u32, k_end: u32, a_base: u32) -> f32 {
    let r = row0 + p.x;
    let k = k0 + p.y;
    if r == mc.ones_row && k < k_end {
        return 1.0;
    }
    if r < mc.m && k < k_end {
        return mm_a[a_base + r * mc.a_row + k * mc.a_col];
    }
    return 0.0;
}
