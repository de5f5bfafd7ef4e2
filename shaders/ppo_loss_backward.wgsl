// PPO's loss, backward, stage 1 (after ppo_loss_common.wgsl): from g = ∂L/∂total (the first
// column of ∂L/∂out [1, 5]; the other columns are statistics and carry no gradient), one
// invocation per row writes
//   ∂μ_k = g_lp z_k / σ_k,  ∂V = c_v g / B · ∂value_r/∂V,   g_lp = g / B · ∂surrogate_r/∂ρ · ρ
// (∂ log π/∂μ_k = z_k / σ_k, ∂ρ/∂ log π = ρ), and each workgroup the sums over its rows of
// g_lp (z_k² − 1) = g_lp ∂ log π/∂ log σ_k.

@group(0) @binding(0) var<storage, read_write> pl_mu: array<f32>;       // [B, A] μ
@group(0) @binding(1) var<storage, read_write> pl_v: array<f32>;        // [B, 1] V
@group(0) @binding(2) var<storage, read_write> pl_log_std: array<f32>;  // [1, A] log σ
@group(0) @binding(3) var<storage, read_write> pl_cols: array<f32>;     // [B, 2A + 4]
@group(0) @binding(4) var<storage, read_write> pl_dout: array<f32>;     // [1, 5] ∂L/∂out (∂L/∂total first)
@group(0) @binding(5) var<storage, read_write> pl_dmu: array<f32>;      // [B, A] ∂L/∂μ
@group(0) @binding(6) var<storage, read_write> pl_dv: array<f32>;       // [B, 1] ∂L/∂V
@group(0) @binding(7) var<storage, read_write> pl_partial: array<f32>;  // [groups, A] Σ over rows of ∂L/∂log σ's row terms
@group(0) @binding(8) var<uniform> pc: PpoLossCfg;

@compute @workgroup_size(256, 1, 1)
fn ppo_loss_backward(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(local_invocation_id) lid: vec3<u32>, @builtin(workgroup_id) wid: vec3<u32>) {
    let r = gid.x;
    let t = lid.x;
    let a = pc.a;
    let w = pl_width();
    let valid = r < pc.rows;
    let n = f32(pc.rows);
    var g_lp = 0.0; // ∂L/∂ log π of this row
    if valid {
        var sq = 0.0;
        var sum_ls = 0.0;
        for (var k = 0u; k < a; k++) {
            let ls = pl_log_std[k];
            let z = (pl_cols[r * w + k] - pl_mu[r * a + k]) / exp(ls);
            sq += z * z;
            sum_ls += ls;
        }
        let log_prob = -0.5 * sq - sum_ls - 0.5 * f32(a) * PL_LN_2PI;
        let ratio = exp(log_prob - pl_cols[r * w + 2u * a]);
        let g = pl_dout[0];
        g_lp = g / n * pl_surrogate_dratio(pl_cols[r * w + 2u * a + 1u], ratio) * ratio;
        pl_dv[r] = bitcast<f32>(pc.value_coef_bits) * g / n * pl_value_dv(pl_v[r], pl_cols[r * w + 2u * a + 2u], pl_cols[r * w + 2u * a + 3u]);
    }
    for (var k = 0u; k < a; k++) {
        var term = 0.0;
        if valid {
            let sigma = exp(pl_log_std[k]);
            let z = (pl_cols[r * w + k] - pl_mu[r * a + k]) / sigma;
            pl_dmu[r * a + k] = g_lp * z / sigma;
            term = g_lp * (z * z - 1.0);
        }
        // the workgroup's rows summed as a tree (a fixed order)
        pl_sums[t] = vec3<f32>(term, 0.0, 0.0);
        pl_tree_sum(t);
        if t == 0u {
            pl_partial[wid.x * a + k] = pl_sums[0].x;
        }
        workgroupBarrier();
    }
}
