// SAC's n-step windows of a device-resident batch (learn/kernels/replay_sample.rs, for
// learn/sac/device.rs), launched on burn's command stream: buffer.rs's window walk, one invocation
// per batch row, in the f32 operations of the tensor ops it replaces (device.rs's masks), in their
// order (a hardware driver may still contract the return's product and sum into one rounding):
//   ok = alive · valid_w;  R += (ok · β) · r_w;  last = row_w where ok;
//   β ← β · (ok (γ − 1) + 1);  β ← β · (1 − ok · terminated_w);  alive ← alive · (1 − ok · done_w)
// from R = 0, β = 1, alive = 1, last = the window's first row. R is the n-step return, β the
// bootstrap factor (γᵐ, 0 after a termination), last the row whose next observation bootstraps.

struct WindowCfg {
    batch: u32,
    n_step: u32,
    // γ − 1 as f32 bits
    gamma_minus_one_bits: u32,
    _pad: u32,
}

// bound by cubecl in this order: the buffers, then the launch's constants as a uniform
@group(0) @binding(0) var<storage, read_write> rw_idx: array<u32>;   // [2 · n_step · B] the rows of window step w of batch row k at w · B + k, then whether each is written (0/1)
@group(0) @binding(1) var<storage, read_write> rw_flags: array<f32>; // [3 · n_step · B] the rows' rewards, done flags, terminated flags (each laid out as the rows)
@group(0) @binding(2) var<storage, read_write> rw_return: array<f32>;    // [B] R
@group(0) @binding(3) var<storage, read_write> rw_bootstrap: array<f32>; // [B] β
@group(0) @binding(4) var<storage, read_write> rw_last: array<u32>;      // [B] the last row of the window
@group(0) @binding(5) var<uniform> wc: WindowCfg;

@compute @workgroup_size(64, 1, 1)
fn replay_window(@builtin(global_invocation_id) gid: vec3<u32>) {
    let k = gid.x;
    if k >= wc.batch {
        return;
    }
    let nb = wc.n_step * wc.batch;
    let gm1 = bitcast<f32>(wc.gamma_minus_one_bits);
    var ret = 0.0;
    var disc = 1.0;
    var alive = 1.0;
    var last = rw_idx[k];
    for (var w = 0u; w < wc.n_step; w++) {
        let j = w * wc.batch + k;
        let ok = alive * f32(rw_idx[nb + j]); // the window goes on and the slot is written
        let r = rw_flags[j];
        let done = rw_flags[nb + j];
        let term = rw_flags[2u * nb + j];
        ret = ret + ok * disc * r; // R += γᵏ r
        if ok > 0.5 {
            last = rw_idx[j];
        }
        disc = disc * (ok * gm1 + 1.0); // γᵏ⁺¹ where the window went on
        disc = disc * (1.0 - ok * term); // 0 after a termination (no bootstrap)
        alive = alive * (1.0 - ok * done); // the window stops at an episode's end
    }
    rw_return[k] = ret;
    rw_bootstrap[k] = disc;
    rw_last[k] = last;
}
