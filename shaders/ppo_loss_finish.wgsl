// PPO's loss, forward, stage 2 (after ppo_loss_common.wgsl): one workgroup adds the row kernel's
// partial sums and writes [total, surrogate, value, entropy, KL] [1, 5]:
//   the means over the B rows; entropy = Σ_k log σ_k + ½ A (1 + ln 2π);
//   total = surrogate + c_v value − c_e entropy.

@group(0) @binding(0) var<storage, read_write> pl_partial: array<f32>; // [groups, 3]
@group(0) @binding(1) var<storage, read_write> pl_log_std: array<f32>; // [1, A] log σ
@group(0) @binding(2) var<storage, read_write> pl_out: array<f32>;     // [1, 5]
@group(0) @binding(3) var<uniform> pc: PpoLossCfg;

@compute @workgroup_size(256, 1, 1)
fn ppo_loss_finish(@builtin(local_invocation_id) lid: vec3<u32>) {
    let t = lid.x;
    var acc = vec3<f32>(0.0);
    for (var g = t; g < pc.groups; g += PL_WORKGROUP) {
        acc += vec3<f32>(pl_partial[g * 3u], pl_partial[g * 3u + 1u], pl_partial[g * 3u + 2u]);
    }
    pl_sums[t] = acc;
    pl_tree_sum(t);
    if t == 0u {
        let n = f32(pc.rows);
        let surrogate = pl_sums[0].x / n;
        let value = pl_sums[0].y / n;
        var sum_ls = 0.0;
        for (var k = 0u; k < pc.a; k++) {
            sum_ls += pl_log_std[k];
        }
        let entropy = sum_ls + 0.5 * f32(pc.a) * (1.0 + PL_LN_2PI);
        pl_out[0] = surrogate + bitcast<f32>(pc.value_coef_bits) * value - bitcast<f32>(pc.entropy_coef_bits) * entropy;
        pl_out[1] = surrogate;
        pl_out[2] = value;
        pl_out[3] = entropy;
        pl_out[4] = pl_sums[0].z / n;
    }
}
