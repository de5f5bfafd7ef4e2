// ELU's gradient (α = 1) in one pass, launched on burn's command stream by learn/elu_kernel.rs:
// ∂L/∂x = ∂L/∂y · min(y + 1, 1) for y = ELU(x) (1 where y > 0, y + 1 = eˣ otherwise), over
// `count` contiguous entries. The same values as the tensor ops it replaces (add, clamp, mul:
// three kernels and three passes), bit for bit.

struct EluCfg {
    count: u32,
    // entries per row of the 2-D grid: workgroups along x × 256
    row: u32,
    _pad0: u32,
    _pad1: u32,
}

// bound by cubecl in this order: the buffers, then the launch's constants as a uniform
@group(0) @binding(0) var<storage, read_write> elu_y: array<f32>;    // [count] the forward output
@group(0) @binding(1) var<storage, read_write> elu_grad: array<f32>; // [count] ∂L/∂y
@group(0) @binding(2) var<storage, read_write> elu_out: array<f32>;  // [count] ∂L/∂x
@group(0) @binding(3) var<uniform> ec: EluCfg;

@compute @workgroup_size(256, 1, 1)
fn elu_backward(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = gid.y * ec.row + gid.x;
    if i >= ec.count {
        return;
    }
    elu_out[i] = elu_grad[i] * min(elu_y[i] + 1.0, 1.0); // ∂L/∂y · min(y + 1, 1)
}
