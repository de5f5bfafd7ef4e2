// SAC's per-row losses, backward (after sac_loss_common.wgsl): from g = ∂L/∂out[0] (out[1] is a
// statistic: no gradient), one invocation per row writes
//   kind 0: ∂a = 2 (a − b) g / B,  ∂b = −∂a
//   kind 1: ∂a = α g / B,          ∂b = −g / B

@group(0) @binding(0) var<storage, read_write> sl_a: array<f32>;     // [B, 1]
@group(0) @binding(1) var<storage, read_write> sl_b: array<f32>;     // [B, 1]
@group(0) @binding(2) var<storage, read_write> sl_alpha: array<f32>; // [1, 1] log α (kind 1)
@group(0) @binding(3) var<storage, read_write> sl_dout: array<f32>;  // [1, 2] ∂L/∂out
@group(0) @binding(4) var<storage, read_write> sl_da: array<f32>;    // [B, 1]
@group(0) @binding(5) var<storage, read_write> sl_db: array<f32>;    // [B, 1]
@group(0) @binding(6) var<uniform> sc: SacLossCfg;

@compute @workgroup_size(256, 1, 1)
fn sac_loss_backward(@builtin(global_invocation_id) gid: vec3<u32>) {
    let r = gid.x;
    if r >= sc.rows {
        return;
    }
    let g = sl_dout[0] / f32(sc.rows);
    if sc.kind == 0u {
        let da = 2.0 * (sl_a[r] - sl_b[r]) * g;
        sl_da[r] = da;
        sl_db[r] = -da;
    } else {
        sl_da[r] = exp(sl_alpha[0]) * g;
        sl_db[r] = -g;
    }
}
