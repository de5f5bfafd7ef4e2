// A whole MLP's forward pass for acting, in one kernel (learn/kernels/mlp_forward.rs): y = h_L for
// h_0 = x [B, W0], h_{l+1} = ELU(h_l W_l + b_l) for the hidden layers and h_l W_l + b_l for the
// last, where the per-layer path launches one of dextrain's products (matmul.wgsl, with its
// bias-and-ELU epilogue) per layer. A workgroup of 16 × 16 threads carries BM = 32 rows through
// every layer: each layer's output in column tiles of BN = 64, each thread 2 rows × 4 columns, the
// layer's input and weights staged BK = 16 deep in workgroup memory. The hidden layers' outputs
// go to the rows' own place in a scratch buffer [B, 2 · WH] (halves used in turn), read back by
// the same workgroup after a barrier. Each entry is the product's: its k summed in increasing
// order with fused multiply-adds from 0 (the zero padding past k adds +0), then + b, then ELU's
// expression — so on one adapter the result is matmul.wgsl's layer by layer, bit for bit.
//
// A template: mlp_forward.rs writes in the widths (the markers that begin with a dollar sign), the
// layers' parameter bindings and one block per layer, which reads its own bindings. A policy's
// variant also writes the sampled actions a = μ + σ ε beside its output μ (σ, ε and a bound after
// the scratch buffer).

struct MlpCfg {
    rows: u32, // B
    eps_row0: u32, // with the actions: this step's first row of ε
}

// bound by cubecl in this order: the buffers, then the launch's constants as a uniform. Every
// buffer read_write (burn's tensors may share one buffer). After x and y: W_l and b_l of each
// layer, then (with a hidden layer) the scratch buffer mf_h [B, 2 · WH] of the hidden layers'
// outputs — a binding the shader does not use is left out of its layout.
@group(0) @binding(0) var<storage, read_write> mf_x: array<f32>; // [B, W0]
@group(0) @binding(1) var<storage, read_write> mf_y: array<f32>; // [B, W_L]
$PARAM_BINDINGS
@group(0) @binding($UNIFORM_BINDINGu) var<uniform> mc: MlpCfg;

const BM: u32 = 32u; // rows per workgroup
const BN: u32 = 64u; // columns per tile of a layer's output
const BK: u32 = 16u; // k per staged slice
const TX: u32 = 16u; // threads along the columns (4 columns each)
const TY: u32 = 16u; // threads along the rows (2 rows each)
const WH: u32 = $WHu; // the widest hidden layer: each half of a scratch row
const H_ROW: u32 = 2u * WH; // a scratch row's length

var<workgroup> mf_sa: array<f32, 512>; // [BK][BM]: the input's rows at each k of the slice
var<workgroup> mf_sb: array<vec4<f32>, 256>; // [BK][BN / 4]: the weight's columns at each k, 4 a vec4

// ELU (α = 1) of z: z for z > 0, e^z − 1 otherwise (matmul.wgsl's expression)
fn elu(z: f32) -> f32 {
    return select(exp(min(z, 0.0)) - 1.0, z, z > 0.0);
}

@compute @workgroup_size(16, 16, 1)
fn mlp_forward(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_id) lid: vec3<u32>) {
    let row0 = wg.x * BM;
    let tx = lid.x;
    let ty = lid.y;
    let tid = ty * TX + tx;
    // this thread's share of a slice: input values (tid and tid + 256 of the BM × BK), and one
    // vec4 of the weight's BK × BN
    let a_r0 = tid / BK; // rows 0..16 of the tile, then + 16
    let a_d = tid % BK;
    let b_d = tid / (BN / 4u);
    let b_c = (tid % (BN / 4u)) * 4u;
$LAYERS
}
