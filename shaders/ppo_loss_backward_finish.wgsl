// PPO's loss, backward, stage 2 (after ppo_loss_common.wgsl): ∂L/∂ log σ_k = the row kernel's
// partial sums of column k in order − c_e ∂L/∂total, the entropy's share (∂ entropy/∂ log σ_k =
// 1). One invocation per column.

@group(0) @binding(0) var<storage, read_write> pl_partial: array<f32>; // [groups, A]
@group(0) @binding(1) var<storage, read_write> pl_dout: array<f32>;    // [1, 5] ∂L/∂out
@group(0) @binding(2) var<storage, read_write> pl_dlog_std: array<f32>; // [1, A] ∂L/∂ log σ
@group(0) @binding(3) var<uniform> pc: PpoLossCfg;

@compute @workgroup_size(256, 1, 1)
fn ppo_loss_backward_finish(@builtin(global_invocation_id) gid: vec3<u32>) {
    let k = gid.x;
    if k >= pc.a {
        return;
    }
    var acc = 0.0;
    for (var g = 0u; g < pc.groups; g++) {
        acc += pl_partial[g * pc.a + k];
    }
    pl_dlog_std[k] = acc - bitcast<f32>(pc.entropy_coef_bits) * pl_dout[0];
}
