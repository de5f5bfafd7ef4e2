// SAC's per-row losses, forward, stage 2 (after sac_loss_common.wgsl): one workgroup adds the row
// kernel's partial sums and writes out [1, 2] (the means; kind 0: [mean (a − b)², q_scale mean a],
// kind 1: [mean (α a − b), −mean a]).

@group(0) @binding(0) var<storage, read_write> sl_partial: array<f32>; // [groups, 2]
@group(0) @binding(1) var<storage, read_write> sl_out: array<f32>;     // [1, 2]
@group(0) @binding(2) var<uniform> sc: SacLossCfg;

@compute @workgroup_size(256, 1, 1)
fn sac_loss_finish(@builtin(local_invocation_id) lid: vec3<u32>) {
    let t = lid.x;
    var acc = vec2<f32>(0.0);
    for (var g = t; g < sc.groups; g += SL_WORKGROUP) {
        acc += vec2<f32>(sl_partial[g * 2u], sl_partial[g * 2u + 1u]);
    }
    sl_sums[t] = acc;
    sl_tree_sum(t);
    if t == 0u {
        let n = f32(sc.rows);
        sl_out[0] = sl_sums[0].x / n;
        if sc.kind == 0u {
            sl_out[1] = bitcast<f32>(sc.q_scale_bits) * (sl_sums[0].y / n);
        } else {
            sl_out[1] = -(sl_sums[0].y / n);
        }
    }
}
