// ELU (α = 1) in one pass, launched on burn's command stream by learn/kernels/elu.rs: y = x for
// x > 0, eˣ − 1 otherwise, over `count` contiguous entries. matmul.wgsl's epilogue expression, the
// same values as the tensor ops it replaces (clamp, clamp, exp, subtract, add: five kernels and five
// passes), bit for bit: for x > 0 they add exp(0) − 1 = 0 to x, otherwise 0 to eˣ − 1.

struct EluForwardCfg {
    count: u32,
    // entries per row of the 2-D grid: workgroups along x × 256
    row: u32,
    _pad0: u32,
    _pad1: u32,
}

// bound by cubecl in this order: the buffers, then the launch's constants as a uniform
@group(0) @binding(0) var<storage, read_write> elu_x: array<f32>;     // [count] the input
@group(0) @binding(1) var<storage, read_write> elu_y_out: array<f32>; // [count] ELU(x)
@group(0) @binding(2) var<uniform> efc: EluForwardCfg;

@compute @workgroup_size(256, 1, 1)
fn elu_forward(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = gid.y * efc.row + gid.x;
    if i >= efc.count {
        return;
    }
    let x = elu_x[i];
    elu_y_out[i] = select(exp(min(x, 0.0)) - 1.0, x, x > 0.0); // x for x > 0, eˣ − 1 otherwise
}
