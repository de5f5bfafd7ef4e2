// GAE over a device-resident rollout (learn/kernels/ppo_rollout.rs; the twin of ppo/storage.rs's
// `gae` and of the [N, 1] tensor ops it replaces, the same f32 arithmetic in the same order), one
// invocation per env, backwards in time over its T steps (row t · N + i):
//   δ_t = r_t + (γ V(s_{t+1})) (1 − d_t) − V(s_t),  A_t = δ_t + (γλ A_{t+1}) (1 − d_t)  (A_T = 0)

struct GaeCfg {
    envs: u32,
    steps: u32,
    // γ and γλ as f32 bits
    gamma_bits: u32,
    gamma_lam_bits: u32,
}

@group(0) @binding(0) var<storage, read_write> gae_rd: array<f32>;     // [T · N, 2] r', done
@group(0) @binding(1) var<storage, read_write> gae_values: array<f32>; // [T · N, 1] V(s_t)
@group(0) @binding(2) var<storage, read_write> gae_last: array<f32>;   // [N, 1] V(s_T)
@group(0) @binding(3) var<storage, read_write> gae_adv: array<f32>;    // [T · N, 1] A_t
@group(0) @binding(4) var<uniform> gc: GaeCfg;

@compute @workgroup_size(64, 1, 1)
fn gae(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = gid.x;
    if i >= gc.envs {
        return;
    }
    let n = gc.envs;
    let gamma = bitcast<f32>(gc.gamma_bits);
    let gamma_lam = bitcast<f32>(gc.gamma_lam_bits);
    var next_value = gae_last[i];
    var next_adv = 0.0;
    for (var k = 0u; k < gc.steps; k++) {
        let t = gc.steps - 1u - k;
        let row = t * n + i;
        let not_done = 1.0 - gae_rd[2u * row + 1u];
        let v = gae_values[row];
        let delta = gae_rd[2u * row] + (next_value * gamma) * not_done - v;
        var adv = delta;
        if k > 0u {
            adv = delta + (next_adv * gamma_lam) * not_done;
        }
        gae_adv[row] = adv;
        next_adv = adv;
        next_value = v;
    }
}
