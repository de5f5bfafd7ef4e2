// SAC's squashed-Gaussian sample, backward (after squashed_common.wgsl): from ∂L/∂a_k and ∂L/∂log π
// of each row, with u, σ and tanh(x_k) worked out again as the forward pass does:
//   ∂L/∂u = ∂L/∂a_k (1 − a_k²) + ∂L/∂log π · 2 a_k      (∂ log π/∂u = −∂ log(1 − tanh² u)/∂u = 2 tanh u)
//   ∂L/∂μ_k = ∂L/∂u
//   ∂L/∂log σ = ∂L/∂u · σ ε_k − ∂L/∂log π                 (u = μ + e^{log σ} ε; log π has −log σ)
//   ∂L/∂x_k = ∂L/∂log σ · ½ (hi − lo)(1 − tanh² x_k)

@group(0) @binding(0) var<storage, read_write> sq_head: array<f32>;  // [B, 2A] the forward pass's input
@group(0) @binding(1) var<storage, read_write> sq_eps: array<f32>;   // [B, A] ε
@group(0) @binding(2) var<storage, read_write> sq_dout: array<f32>;  // [B, A + 1] ∂L/∂a, then ∂L/∂log π
@group(0) @binding(3) var<storage, read_write> sq_dhead: array<f32>; // [B, 2A] ∂L/∂head
@group(0) @binding(4) var<uniform> sc: SqCfg;

@compute @workgroup_size(64, 1, 1)
fn squashed_sample_backward(@builtin(global_invocation_id) gid: vec3<u32>) {
    let r = sq_row(gid);
    if r >= sc.rows {
        return;
    }
    let a = sc.a;
    let half = bitcast<f32>(sc.half_bits); // ½ (hi − lo)
    let d_log_prob = sq_dout[r * (a + 1u) + a];
    for (var k = 0u; k < a; k++) {
        let mu = sq_head[r * 2u * a + k];
        let tx = sq_tanh(sq_head[r * 2u * a + a + k]);
        let log_std = sq_log_std(tx);
        let e = sq_eps[r * a + k];
        let sigma_e = exp(log_std) * e; // σ ε
        let act = sq_tanh(mu + sigma_e); // a = tanh(u)
        let du = sq_dout[r * (a + 1u) + k] * (1.0 - act * act) + d_log_prob * 2.0 * act;
        let d_log_std = du * sigma_e - d_log_prob;
        sq_dhead[r * 2u * a + k] = du;
        sq_dhead[r * 2u * a + a + k] = d_log_std * half * (1.0 - tx * tx);
    }
}
