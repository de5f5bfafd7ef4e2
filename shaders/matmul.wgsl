// The GPU learner's matrix product of our own, launched on burn's command stream by
// learn/wgsl_matmul.rs: C[b] = A[b] · B[b] for A [M, K] and B [K, N] given by their strides (a
// transposed view is a strided one), C [M, N] row-major, b < batches. Split over k (a product
// with few tiles of C and a long k, as the weight gradient over a batch's rows): workgroup layer z
// sums k in [s·k_chunk, (s + 1)·k_chunk) for s = z mod k_splits into its own [M, N] partial, which
// the caller sums over s (one batch only then). An epilogue on C's entries (unsplit products):
// + b[c] (a dense layer's bias), or ELU(· + b[c]) (with its activation, α = 1), or · min(y + 1, 1)
// for y [M, N] in mm_bias (ELU's gradient through a layer's output y, α = 1). A product may read A
// with a row of ones after its last (`ones_row`): C's entries in that row, Σ_k B[k, c] (B's column
// sums over the layer's k range: a dense layer's bias gradient 1ᵀ g beside its weight gradient
// xᵀ g), go to mm_bias [splits, N] instead of C.
//
// A template: learn/wgsl_matmul.rs writes in the tile shape (the markers that begin with a dollar
// sign: numbers), the per-thread accumulation, unrolled (the ACC blocks), so that every
// accumulator is a named register, and how each operand is read (the LOAD blocks): one f32 at a
// time with any strides, or four at a time (a vec4 along the operand's contiguous dimension, for
// operands whose sizes and strides are multiples of 4; the operand is then bound as vec4s). A workgroup of TX × TY = 256 threads computes a BM × BN tile
// of C, TM × TN entries per thread (TM rows in groups of 4 spaced 4·TY apart, TN columns in
// groups of 4 spaced 4·TX apart, so that neighbouring threads read neighbouring vec4s of
// workgroup memory). Each BK-deep slice of A's rows and B's columns is staged in workgroup
// memory; the next slice's values are fetched into registers while the current one is
// multiplied. Each entry sums the products of its k range in increasing k with fused
// multiply-adds (the same order every run).

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
    // k per split and the splits (1: no split)
    k_splits: u32,
    k_chunk: u32,
    // 0: C = A · B; 1: C = A · B + b (b [N] in mm_bias); 2: C = ELU(A · B + b); 3: C = (A · B) ·
    // min(y + 1, 1) (y [M, N] in mm_bias)
    epilogue: u32,
    // A's row of ones (its last, m − 1, and C's row there to mm_bias), or 0xffffffff: none
    ones_row: u32,
    _pad2: u32,
}

// bound by cubecl in this order: the buffers, then the launch's constants as a uniform.
// Every operand read_write: burn's tensors may share one buffer, and wgpu forbids one buffer bound
// read-only and writable in one dispatch.
@group(0) @binding(0) var<storage, read_write> mm_a: array<$A_ELEM>;
@group(0) @binding(1) var<storage, read_write> mm_b: array<$B_ELEM>;
@group(0) @binding(2) var<storage, read_write> mm_c: array<f32>;
@group(0) @binding(3) var<storage, read_write> mm_bias: array<f32>; // [N] bias, [M, N] y, or [splits, N] the ones row's sums out (any buffer without an epilogue or a ones row)
@group(0) @binding(4) var<uniform> mc: MatmulCfg;

const BM: u32 = $BMu; // C rows per workgroup
const BN: u32 = $BNu; // C columns per workgroup
const BK: u32 = $BKu; // k per staged slice
const TX: u32 = $TXu; // threads along C's columns: BN / TN
const TY: u32 = $TYu; // threads along C's rows: BM / TM
const THREADS: u32 = $THREADSu; // TX · TY
const A_LOADS: u32 = $A_LOADSu; // A values each thread stages per slice: BK · BM / THREADS
const B_LOADS: u32 = $B_LOADSu; // B values likewise: BK · BN / THREADS

var<workgroup> mm_sa: array<vec4<f32>, $SA_LENu>; // [BK][BM / 4]: A's tile rows at each k, 4 rows a vec4
var<workgroup> mm_sb: array<vec4<f32>, $SB_LENu>; // [BK][BN / 4]: B's tile columns at each k, 4 a vec4

$LOAD_FUNCS
// C's entry `v` at row `r`, column `c` after the epilogue
fn finish(v: f32, r: u32, c: u32) -> f32 {
    if mc.epilogue == 0u {
        return v;
    }
    if mc.epilogue == 3u {
        return v * min(mm_bias[r * mc.n + c] + 1.0, 1.0); // ∂L/∂y · min(y + 1, 1): elu_backward.wgsl's expression
    }
    let z = v + mm_bias[c]; // x W + b
    if mc.epilogue == 1u {
        return z;
    }
    return select(exp(min(z, 0.0)) - 1.0, z, z > 0.0); // ELU: z for z > 0, e^z − 1 otherwise
}

// writes C's entry `v` at (r, c) of output layer z (c_base its first entry): the ones row's sum to
// mm_bias [z, c], every other row after the epilogue to C
fn put(c_base: u32, z: u32, r: u32, c: u32, v: f32) {
    if r == mc.ones_row {
        mm_bias[z * mc.n + c] = v; // Σ_k B[k, c] over this layer's k range
        return;
    }
    mm_c[c_base + r * mc.n + c] = finish(v, r, c);
}

@compute @workgroup_size($TXu, $TYu, 1)
fn matmul_tiled(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_id) lid: vec3<u32>) {
    let row0 = wg.y * BM;
    let col0 = wg.x * BN;
    let batch = wg.z / mc.k_splits;
    let k_begin = (wg.z % mc.k_splits) * mc.k_chunk; // this layer's k range
    let k_end = min(mc.k, k_begin + mc.k_chunk);
    let tx = lid.x;
    let ty = lid.y;
    let tid = ty * TX + tx;
    let a_base = batch * mc.a_batch;
    let b_base = batch * mc.b_batch;
$LOAD_REGS
$ACC_DECL
    // the first slice into registers
$LOAD_FIRST
    for (var k0 = k_begin; k0 < k_end; k0 += BK) {
        // the fetched slice into workgroup memory
$LOAD_STAGE
        workgroupBarrier();
        // the next slice into registers while this one is multiplied
        let k1 = k0 + BK;
        if k1 < k_end {
$LOAD_NEXT
        }
        for (var d = 0u; d < BK; d++) {
            // C[r, c] += A[r, k0 + d] · B[k0 + d, c] for this thread's rows and columns
$ACC_FMA
        }
        workgroupBarrier();
    }
    let c_base = wg.z * mc.c_batch; // [batches · k_splits] outputs of [M, N] ([M − 1, N] with a ones row)
    var r = 0u;
    var c = 0u;
$ACC_STORE
}
