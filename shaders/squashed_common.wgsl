// SAC's squashed-Gaussian sample, the shared part (learn/kernels/squashed.rs prepends it to
// squashed_sample.wgsl and squashed_sample_backward.wgsl, each a module of its own): the launch's
// constants and the per-entry maths. One invocation per row of the batch, 64 to a workgroup. The
// actor's head [B, 2A] holds μ in its first A columns and the unsquashed log σ in the last A.

struct SqCfg {
    rows: u32,
    // actions A
    a: u32,
    // rows per row of the 2-D grid: workgroups along x × 64 (rows beyond wrap into y)
    grid_row: u32,
    // log σ's range [lo, hi] as f32 bits, and ½ (hi − lo)
    lo_bits: u32,
    half_bits: u32,
    _pad: u32,
}

const SQ_WORKGROUP: u32 = 64u;
const SQ_LN_2: f32 = 0.6931471805599453;

// tanh that no driver turns into ∞/∞: |x| ≥ 15 is ±1 in f32 already
fn sq_tanh(x: f32) -> f32 {
    return tanh(clamp(x, -15.0, 15.0));
}

// ln(1 + t) for t ≥ 0, accurate for small t (WGSL has no log1p): log(w) · t / (w − 1), w = 1 + t
fn sq_log1p(t: f32) -> f32 {
    let w = 1.0 + t;
    if w == 1.0 {
        return t;
    }
    return log(w) * t / (w - 1.0);
}

// the row of this invocation (a 2-D grid), or rows and beyond
fn sq_row(gid: vec3<u32>) -> u32 {
    return gid.y * sc.grid_row + gid.x;
}

// log σ squashed into [lo, hi] from the head's unsquashed value x, given tanh x:
// lo + ½ (hi − lo)(tanh x + 1)
fn sq_log_std(tanh_x: f32) -> f32 {
    return bitcast<f32>(sc.lo_bits) + bitcast<f32>(sc.half_bits) * (tanh_x + 1.0);
}
