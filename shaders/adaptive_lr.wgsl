// PPO's adaptive learning rate (rsl_rl's schedule) from a minibatch's KL, on the device, as one
// invocation (learn/kernels/adaptive_lr.rs; the tensor ops of ppo::adapt_learning_rate, which the
// CPU learner runs, are the same comparisons in the same f32 arithmetic):
//   lr / 1.5 (at least lr_min) when KL > 2 KL*, lr · 1.5 (at most lr_max) when 0 < KL < KL* / 2,
//   else lr (a non-finite KL too).

struct AdaptiveLrCfg {
    // the KL's index in kl_row
    column: u32,
    // 2 KL* and KL* / 2, as f32 bits
    above_bits: u32,
    below_bits: u32,
    // the learning rate's bounds, as f32 bits
    min_bits: u32,
    max_bits: u32,
    _pad: u32,
}

@group(0) @binding(0) var<storage, read_write> al_lr: array<f32>;     // [1, 1] the learning rate
@group(0) @binding(1) var<storage, read_write> al_kl_row: array<f32>; // [1, n] holding the KL at `column`
@group(0) @binding(2) var<storage, read_write> al_out: array<f32>;    // [1, 1] the adapted learning rate
@group(0) @binding(3) var<uniform> ac: AdaptiveLrCfg;

@compute @workgroup_size(1, 1, 1)
fn adaptive_lr() {
    let kl = al_kl_row[ac.column];
    let lr = al_lr[0];
    let finite = kl == kl && abs(kl) <= 3.4028235e38;
    var out = lr;
    if finite && kl > bitcast<f32>(ac.above_bits) {
        out = max(lr / 1.5, bitcast<f32>(ac.min_bits));
    } else if finite && kl > 0.0 && kl < bitcast<f32>(ac.below_bits) {
        out = min(lr * 1.5, bitcast<f32>(ac.max_bits));
    }
    al_out[0] = out;
}
