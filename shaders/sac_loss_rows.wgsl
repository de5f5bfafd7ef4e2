// SAC's per-row losses, forward, stage 1 (after sac_loss_common.wgsl): one invocation per row; each
// workgroup writes the sums of its rows' two terms.

@group(0) @binding(0) var<storage, read_write> sl_a: array<f32>;       // [B, 1]
@group(0) @binding(1) var<storage, read_write> sl_b: array<f32>;       // [B, 1]
@group(0) @binding(2) var<storage, read_write> sl_alpha: array<f32>;   // [1, 1] log α (kind 1)
@group(0) @binding(3) var<storage, read_write> sl_partial: array<f32>; // [groups, 2]
@group(0) @binding(4) var<uniform> sc: SacLossCfg;

@compute @workgroup_size(256, 1, 1)
fn sac_loss_rows(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(local_invocation_id) lid: vec3<u32>, @builtin(workgroup_id) wid: vec3<u32>) {
    let r = gid.x;
    var terms = vec2<f32>(0.0);
    if r < sc.rows {
        terms = sl_terms(sl_a[r], sl_b[r], exp(sl_alpha[0]));
    }
    let t = lid.x;
    sl_sums[t] = terms;
    sl_tree_sum(t);
    if t == 0u {
        sl_partial[wid.x * 2u] = sl_sums[0].x;
        sl_partial[wid.x * 2u + 1u] = sl_sums[0].y;
    }
}
