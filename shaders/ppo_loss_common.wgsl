// PPO's loss of one minibatch as kernels of ours, the shared part (learn/kernels/ppo_loss.rs
// prepends it to ppo_loss_rows.wgsl, ppo_loss_finish.wgsl, ppo_loss_backward.wgsl and
// ppo_loss_backward_finish.wgsl, each a module of its own). The maths are those of
// learn/ppo/mod.rs's ppo_losses (the CPU learner's loss, and the reference of the tests):
//   z_k = (a_k − μ_k) / σ_k,  log π = −½ Σ_k z_k² − Σ_k log σ_k − ½ A ln 2π,  ρ = exp(log π − log π_old)
//   surrogate_r = max(−Â ρ, −Â clip(ρ, 1 − ε, 1 + ε))
//   value_r = (V − R)², or max((V − R)², (V_old + clip(V − V_old, −ε, ε) − R)²) when clipped
//   kl_r = Σ_k [log σ_k − ln σ_old,k + (σ_old,k² + (μ_old,k − μ_k)²) / (2 σ_k²) − ½]
// The minibatch's columns [B, 2A + 4], per row: the actions a (A), the acting policy's mean μ_old
// (A), log π_old, the advantage Â, the return R and the acting critic's value V_old.
// Sums over the rows: a tree over each workgroup's 256 rows, then the workgroups' partial sums in
// order, so a run repeats bit for bit.

struct PpoLossCfg {
    // rows B
    rows: u32,
    // actions A
    a: u32,
    // workgroups of the row kernels (PL_WORKGROUP rows each)
    groups: u32,
    // 1: the clipped value loss
    clipped_value: u32,
    // ε, c_v and c_e as f32 bits
    clip_bits: u32,
    value_coef_bits: u32,
    entropy_coef_bits: u32,
    _pad: u32,
}

const PL_WORKGROUP: u32 = 256u;
const PL_LN_2PI: f32 = 1.8378770664093453;

// each invocation's terms, summed over the workgroup by pl_tree_sum
var<workgroup> pl_sums: array<vec3<f32>, 256>;

// the workgroup's tree sum of pl_sums, left in pl_sums[0] (every invocation calls it, in uniform
// control flow: it holds the workgroup's barriers)
fn pl_tree_sum(t: u32) {
    workgroupBarrier();
    for (var s = PL_WORKGROUP / 2u; s > 0u; s = s / 2u) {
        if t < s {
            pl_sums[t] = pl_sums[t] + pl_sums[t + s];
        }
        workgroupBarrier();
    }
}

// the minibatch columns' row width 2A + 4, and where log π_old, Â, R and V_old sit in a row
fn pl_width() -> u32 {
    return 2u * pc.a + 4u;
}

// a row's surrogate max(−Â ρ, −Â clip(ρ, 1 − ε, 1 + ε))
fn pl_surrogate(adv: f32, ratio: f32) -> f32 {
    let eps = bitcast<f32>(pc.clip_bits);
    return max(-adv * ratio, -adv * clamp(ratio, 1.0 - eps, 1.0 + eps));
}

// ∂surrogate_r/∂ρ: −Â where the unclipped term is the max (ties included, as burn's max_pair
// picks it) or ρ lies within [1 − ε, 1 + ε]; else 0 (the clipped term's flat part)
fn pl_surrogate_dratio(adv: f32, ratio: f32) -> f32 {
    let eps = bitcast<f32>(pc.clip_bits);
    let inside = ratio >= 1.0 - eps && ratio <= 1.0 + eps;
    if -adv * ratio >= -adv * clamp(ratio, 1.0 - eps, 1.0 + eps) || inside {
        return -adv;
    }
    return 0.0;
}

// a row's value loss
fn pl_value(v: f32, ret: f32, old_v: f32) -> f32 {
    let l1 = (v - ret) * (v - ret);
    if pc.clipped_value == 0u {
        return l1;
    }
    let eps = bitcast<f32>(pc.clip_bits);
    let vc = old_v + clamp(v - old_v, -eps, eps);
    return max(l1, (vc - ret) * (vc - ret));
}

// ∂value_r/∂V: 2 (V − R), or where the clipped term is the larger 2 (V_c − R) inside the clip
// range and 0 outside it
fn pl_value_dv(v: f32, ret: f32, old_v: f32) -> f32 {
    let l1 = (v - ret) * (v - ret);
    if pc.clipped_value == 0u {
        return 2.0 * (v - ret);
    }
    let eps = bitcast<f32>(pc.clip_bits);
    let vc = old_v + clamp(v - old_v, -eps, eps);
    if l1 >= (vc - ret) * (vc - ret) {
        return 2.0 * (v - ret);
    }
    if v - old_v >= -eps && v - old_v <= eps {
        return 2.0 * (vc - ret);
    }
    return 0.0;
}
