// The GPU learner's matrix product of our own (learn/wgsl_matmul.rs binds it over burn's tensors):
// C[b] = A[b] · B[b] for A [M, K] and B [K, N] given by their strides (a transposed view is a
// strided one), C [M, N] row-major, b < batches. A workgroup of 16 × 16 threads computes a
// 64 × 64 tile of C, 4 × 4 entries per thread, staging 16-deep slices of A's rows and B's columns
// in workgroup memory; each entry sums its K products in increasing k (the same order every run).

struct MatmulCfg {
    m: u32,
    n: u32,
    k: u32,
    batches: u32,
    // strides in f32 elements: A's row, column and batch; B's row, column and batch; C's batch
    a_row: u32,
    a_col: u32,
    a_batch: u32,
    b_row: u32,
    b_col: u32,
    b_batch: u32,
    c_batch: u32,
    _pad: u32,
}

@group(0) @binding(0) var<uniform> mc: MatmulCfg;
// every operand read_write: burn's tensors may share one buffer, and wgpu forbids one buffer bound
// read-only and writable in one dispatch
@group(0) @binding(1) var<storage, read_write> mm_a: array<f32>;
@group(0) @binding(2) var<storage, read_write> mm_b: array<f32>;
@group(0) @binding(3) var<storage, read_write> mm_c: array<f32>;

const MM_TILE: u32 = 64u;   // C rows and columns per workgroup
const MM_DEPTH: u32 = 16u;  // k per staged slice
const MM_THREADS: u32 = 256u;

var<workgroup> mm_sa: array<f32, 1024>; // [MM_DEPTH][MM_TILE]: A's 64 rows at 16 k, k-major
var<workgroup> mm_sb: array<f32, 1024>; // [MM_DEPTH][MM_TILE]: B's 64 columns at 16 k, k-major

@compute @workgroup_size(16, 16, 1)
fn matmul_tiled(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_id) lid: vec3<u32>) {
    let row0 = wg.y * MM_TILE;
    let col0 = wg.x * MM_TILE;
    let batch = wg.z;
    let tid = lid.y * 16u + lid.x;
    let a_base = batch * mc.a_batch;
    let b_base = batch * mc.b_batch;
    // which index runs fastest over the threads when loading: the one with stride 1 (coalesced reads)
    let a_rows_fast = mc.a_row == 1u && mc.a_col != 1u;
    let b_cols_fast = mc.b_col == 1u || mc.b_row != 1u;
    var acc: array<f32, 16>;
    for (var i = 0u; i < 16u; i++) {
        acc[i] = 0.0;
    }
    for (var k0 = 0u; k0 < mc.k; k0 += MM_DEPTH) {
        for (var s = 0u; s < 4u; s++) {
            let e = tid + s * MM_THREADS; // 0..1023: one staged value of A and one of B
            // A: row r of the tile at depth d
            var r = e / MM_DEPTH;
            var d = e % MM_DEPTH;
            if a_rows_fast {
                r = e % MM_TILE;
                d = e / MM_TILE;
            }
            let ga = row0 + r;
            let ka = k0 + d;
            var va = 0.0;
            if ga < mc.m && ka < mc.k {
                va = mm_a[a_base + ga * mc.a_row + ka * mc.a_col];
            }
            mm_sa[d * MM_TILE + r] = va;
            // B: column c of the tile at depth d
            var c = e % MM_TILE;
            var db = e / MM_TILE;
            if !b_cols_fast {
                c = e / MM_DEPTH;
                db = e % MM_DEPTH;
            }
            let gb = col0 + c;
            let kb = k0 + db;
            var vb = 0.0;
            if gb < mc.n && kb < mc.k {
                vb = mm_b[b_base + kb * mc.b_row + gb * mc.b_col];
            }
            mm_sb[db * MM_TILE + c] = vb;
        }
        workgroupBarrier();
        for (var d = 0u; d < MM_DEPTH; d++) {
            var av: array<f32, 4>;
            var bv: array<f32, 4>;
            for (var i = 0u; i < 4u; i++) {
                av[i] = mm_sa[d * MM_TILE + lid.y * 4u + i];
                bv[i] = mm_sb[d * MM_TILE + lid.x * 4u + i];
            }
            for (var i = 0u; i < 4u; i++) {
                for (var j = 0u; j < 4u; j++) {
                    acc[i * 4u + j] = acc[i * 4u + j] + av[i] * bv[j]; // C[r, c] += A[r, k] B[k, c]
                }
            }
        }
        workgroupBarrier();
    }
    let c_base = batch * mc.c_batch;
    for (var i = 0u; i < 4u; i++) {
        let r = row0 + lid.y * 4u + i;
        for (var j = 0u; j < 4u; j++) {
            let c = col0 + lid.x * 4u + j;
            if r < mc.m && c < mc.n {
                mm_c[c_base + r * mc.n + c] = acc[i * 4u + j];
            }
        }
    }
}
