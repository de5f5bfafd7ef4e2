// PPO's loss, forward, stage 1 (after ppo_loss_common.wgsl): one invocation per row; each
// workgroup writes the sums of its rows' surrogate, value loss and KL.

@group(0) @binding(0) var<storage, read_write> pl_mu: array<f32>;        // [B, A] μ
@group(0) @binding(1) var<storage, read_write> pl_v: array<f32>;         // [B, 1] V
@group(0) @binding(2) var<storage, read_write> pl_log_std: array<f32>;   // [1, A] log σ
@group(0) @binding(3) var<storage, read_write> pl_old_sigma: array<f32>; // [1, A] σ_old
@group(0) @binding(4) var<storage, read_write> pl_cols: array<f32>;      // [B, 2A + 4] the minibatch's columns
@group(0) @binding(5) var<storage, read_write> pl_partial: array<f32>;   // [groups, 3] Σ surrogate, value, KL
@group(0) @binding(6) var<uniform> pc: PpoLossCfg;

@compute @workgroup_size(256, 1, 1)
fn ppo_loss_rows(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(local_invocation_id) lid: vec3<u32>, @builtin(workgroup_id) wid: vec3<u32>) {
    let r = gid.x;
    let a = pc.a;
    let w = pl_width();
    var terms = vec3<f32>(0.0);
    if r < pc.rows {
        var sq = 0.0;     // Σ z_k²
        var sum_ls = 0.0; // Σ log σ_k
        var kl = 0.0;
        for (var k = 0u; k < a; k++) {
            let ls = pl_log_std[k];
            let sigma = exp(ls);
            let mu = pl_mu[r * a + k];
            let z = (pl_cols[r * w + k] - mu) / sigma;
            sq += z * z;
            sum_ls += ls;
            let so = pl_old_sigma[k];
            let dm = pl_cols[r * w + a + k] - mu; // μ_old − μ
            kl += (ls - log(so)) + (so * so + dm * dm) / (2.0 * sigma * sigma) - 0.5;
        }
        let log_prob = -0.5 * sq - sum_ls - 0.5 * f32(a) * PL_LN_2PI;
        let ratio = exp(log_prob - pl_cols[r * w + 2u * a]);
        let adv = pl_cols[r * w + 2u * a + 1u];
        terms = vec3<f32>(pl_surrogate(adv, ratio), pl_value(pl_v[r], pl_cols[r * w + 2u * a + 2u], pl_cols[r * w + 2u * a + 3u]), kl);
    }
    // the workgroup's rows summed as a tree (a fixed order)
    let t = lid.x;
    pl_sums[t] = terms;
    pl_tree_sum(t);
    if t == 0u {
        let total = pl_sums[0];
        pl_partial[wid.x * 3u] = total.x;
        pl_partial[wid.x * 3u + 1u] = total.y;
        pl_partial[wid.x * 3u + 2u] = total.z;
    }
}
