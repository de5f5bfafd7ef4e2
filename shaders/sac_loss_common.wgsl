// SAC's per-row losses as kernels of ours, the shared part (learn/kernels/sac_loss.rs prepends it
// to sac_loss_rows.wgsl, sac_loss_finish.wgsl and sac_loss_backward.wgsl, each a module of its
// own). Two kinds, over two columns a, b [B, 1] (the maths of learn/sac/mod.rs's tensor ops, which
// the CPU learner runs):
//   kind 0, a critic's loss: a = Q_j(ĉ, a), b = the target y:
//     out = [mean (a − b)², q_scale · mean a]
//   kind 1, the actor's loss: a = log π(ã|s), b = the critics' reduced value of ã, α = exp(log α):
//     out = [mean (α a − b), −mean a]  (the loss, and the entropy estimate)
// Only out[0] carries a gradient. Sums over the rows: a tree over each workgroup's 256 rows, then
// the workgroups' partial sums in order, so a run repeats bit for bit.

struct SacLossCfg {
    rows: u32,
    // 0: a critic's loss, 1: the actor's
    kind: u32,
    // workgroups of the row kernels (SL_WORKGROUP rows each)
    groups: u32,
    // q_scale (kind 0) as f32 bits
    q_scale_bits: u32,
}

const SL_WORKGROUP: u32 = 256u;

// each invocation's two terms, summed over the workgroup by sl_tree_sum
var<workgroup> sl_sums: array<vec2<f32>, 256>;

// the workgroup's tree sum of sl_sums, left in sl_sums[0] (every invocation calls it, in uniform
// control flow: it holds the workgroup's barriers)
fn sl_tree_sum(t: u32) {
    workgroupBarrier();
    for (var s = SL_WORKGROUP / 2u; s > 0u; s = s / 2u) {
        if t < s {
            sl_sums[t] = sl_sums[t] + sl_sums[t + s];
        }
        workgroupBarrier();
    }
}

// the row's two terms (kind 0: (a − b)², a; kind 1: α a − b, a)
fn sl_terms(a: f32, b: f32, alpha: f32) -> vec2<f32> {
    if sc.kind == 0u {
        return vec2<f32>((a - b) * (a - b), a);
    }
    return vec2<f32>(alpha * a - b, a);
}
