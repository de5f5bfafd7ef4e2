// SAC's squashed-Gaussian sample, forward (after squashed_common.wgsl): per row, for each action k
//   log σ = lo + ½ (hi − lo)(tanh(x_k) + 1),  u = μ_k + σ ε_k,  a_k = tanh(u)
//   log π = Σ_k [−½ ε_k² − log σ − log(1 − tanh² u)] − ½ A ln 2π,
// with log(1 − tanh² u) = 2 (ln 2 − u − softplus(−2u)) (stable for any u); the twin of
// learn/sac/mod.rs's `squashed_sample` tensor ops.

@group(0) @binding(0) var<storage, read_write> sq_head: array<f32>; // [B, 2A] μ, then the unsquashed log σ
@group(0) @binding(1) var<storage, read_write> sq_eps: array<f32>;  // [B, A] ε ~ N(0, 1)
@group(0) @binding(2) var<storage, read_write> sq_out: array<f32>;  // [B, A + 1] a, then log π
@group(0) @binding(3) var<uniform> sc: SqCfg;

@compute @workgroup_size(64, 1, 1)
fn squashed_sample(@builtin(global_invocation_id) gid: vec3<u32>) {
    let r = sq_row(gid);
    if r >= sc.rows {
        return;
    }
    let a = sc.a;
    var log_prob = 0.0;
    for (var k = 0u; k < a; k++) {
        let mu = sq_head[r * 2u * a + k];
        let log_std = sq_log_std(sq_tanh(sq_head[r * 2u * a + a + k])); // squashed into [lo, hi]
        let e = sq_eps[r * a + k];
        let u = mu + exp(log_std) * e; // u = μ + σ ε
        let z = -2.0 * u;
        let softplus = max(z, 0.0) + sq_log1p(exp(-abs(z))); // softplus(−2u)
        let log_det = 2.0 * (SQ_LN_2 - u - softplus); // log(1 − tanh² u)
        log_prob += -0.5 * e * e - log_std - log_det;
        sq_out[r * (a + 1u) + k] = sq_tanh(u);
    }
    sq_out[r * (a + 1u) + a] = log_prob - 0.9189385332046727 * f32(a); // − ½ A ln 2π
}
