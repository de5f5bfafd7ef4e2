//! SAC's device-resident batch as kernels of ours (`sac/device.rs`): the rows of the replay rings
//! gathered into the batch, the observations normalised on the way (shaders/replay_gather.wgsl, one
//! kernel per ring piece where a gather, the mask arithmetic of pieces and the normaliser's two
//! tensor ops were one to four kernels each), and the n-step windows walked in one kernel
//! (shaders/replay_window.wgsl, where the masks launched ~17 kernels per window step). The kernels
//! make the tensor ops' f32 operations in their order (a hardware driver may still contract the
//! return's product and sum into one rounding), so on lavapipe a gradient step's numbers are those
//! of the tensor ops (`sac/device.rs`'s `sample`, kept as the reference and the fallback).
//!
//! Row indices travel as u32 in the memory of f32 tensors: cubecl binds buffers, not types.

use anyhow::{Context, Result, anyhow, ensure};
use burn::backend::Cube;
use burn::backend::ops::FloatTensorOps;
use burn::backend::tensor::FloatTensor;
use burn::prelude::{Device, Tensor};
use burn::tensor::{FloatDType, Shape};

use super::wgsl_kernel::{WgslKernel, launch, plain_primitive};

/// shaders/replay_gather.wgsl and shaders/replay_window.wgsl.
const SHADER_GATHER: &str = include_str!("../../../shaders/replay_gather.wgsl");
const SHADER_WINDOW: &str = include_str!("../../../shaders/replay_window.wgsl");

/// The gather kernel's module (one variant).
pub fn gather_source(_: ()) -> String {
    SHADER_GATHER.to_string()
}

/// The window kernel's module (one variant).
pub fn window_source(_: ()) -> String {
    SHADER_WINDOW.to_string()
}

/// `t`'s primitive on burn's wgpu device (any autodiff wrapper dropped), checked to be a contiguous
/// f32 `shape` tensor.
fn cube(t: &Tensor<2>, shape: [usize; 2], what: &str) -> Result<FloatTensor<Cube>> {
    plain_primitive(&t.clone().inner(), shape).with_context(|| format!("SAC's device-resident batch: {what}"))
}

/// A count as a kernel constant.
fn as_u32(n: usize, what: &str) -> Result<u32> {
    u32::try_from(n).map_err(|_| anyhow!("SAC's device-resident batch: {what} = {n} is over 32 bits"))
}

/// Row indices on the device: u32 values `[n, 1]` in an f32 tensor's memory (one upload).
pub fn upload_rows(rows: &[u32], device: &Device) -> Result<Tensor<2>> {
    let t = crate::learn::nets::upload(bytemuck::cast_slice(rows), [rows.len(), 1], &device.clone().inner())?;
    Ok(t.inner())
}

/// One ring of the replay buffer as the gather reads it: its pieces (`[rows, dim]` tensors, in
/// order, each holding the ring's rows from where the last one ended) and its row length.
pub struct RingView<'a> {
    pub pieces: Vec<&'a Tensor<2>>,
    pub dim: usize,
}

/// The normalisation of a gather: the normaliser's μ and 1 / (σ + ε) `[1, ≥ cols]`, and whether
/// to apply them (both are bound either way).
pub struct GatherNorm<'a> {
    pub mean: &'a Tensor<2>,
    pub scale: &'a Tensor<2>,
    pub apply: bool,
}

/// Writes `out[out_first + k, c] = ring[rows[k], c]` (normalised by `norm` when it applies) for
/// k < `n`, c < `cols` (the ring rows' first `cols` columns): one launch per piece of the ring.
/// `rows` holds at least `n` u32 row indices ([`upload_rows`], or a window's last rows); `out` is
/// `[≥ out_first + n, cols]`.
pub fn gather_into(rows: &Tensor<2>, n: usize, ring: &RingView<'_>, cols: usize, norm: &GatherNorm<'_>, out: &FloatTensor<Cube>, out_first: usize) -> Result<()> {
    ensure!(cols <= ring.dim, "SAC's device-resident batch: {cols} columns of a ring of {}", ring.dim);
    ensure!(rows.dims()[0] >= n, "SAC's device-resident batch: {} row indices for {n} rows", rows.dims()[0]);
    let entries = as_u32(n * cols, "the batch's entries")?;
    if entries == 0 {
        return Ok(());
    }
    let rows_p = cube(rows, [rows.dims()[0], 1], "the row indices")?;
    let stats = |t: &Tensor<2>, what: &str| cube(t, [1, t.dims()[1]], what);
    let (mean, scale) = (stats(norm.mean, "the normaliser's mean")?, stats(norm.scale, "the normaliser's scale")?);
    ensure!(!norm.apply || (norm.mean.dims()[1] >= cols && norm.scale.dims()[1] >= cols), "SAC's device-resident batch: a normaliser of {} columns for {cols}", norm.mean.dims()[1]);
    let (gx, gy) = crate::gpu::shaders::workgroups_of(entries, 256);
    let mut first = 0usize;
    for piece in &ring.pieces {
        let piece_rows = piece.dims()[0];
        let p = cube(piece, [piece_rows, ring.dim], "a ring's piece")?;
        let kernel = WgslKernel { name: "dextrain_replay_gather", key: (), source: gather_source, entry_point: "replay_gather", workgroup: [256, 1] };
        // GatherCfg: n, cols, dim, first, piece_rows, normalize, out_first, row
        let constants = [as_u32(n, "the batch's rows")?, cols as u32, as_u32(ring.dim, "a ring's width")?, as_u32(first, "a piece's first row")?, as_u32(piece_rows, "a piece's rows")?, norm.apply as u32, as_u32(out_first, "the output's first row")?, gx * 256];
        launch(kernel, [gx, gy, 1], &[&rows_p, &p, &mean, &scale, out], &constants);
        first += piece_rows;
    }
    Ok(())
}

/// `[rows, cols]` f32 on the device of `like`, for a kernel to fill (not initialised).
pub fn empty_like(like: &Tensor<2>, rows: usize, cols: usize) -> Result<FloatTensor<Cube>> {
    let p = cube(like, like.dims(), "a ring's piece")?;
    Ok(Cube::float_empty(Shape::new([rows, cols]), &p.device, FloatDType::F32))
}

/// A kernel's output as a tensor of burn's wgpu device (no autodiff).
pub fn tensor_of(p: FloatTensor<Cube>) -> Tensor<2> {
    Tensor::from_primitive::<Cube>(p)
}

/// The n-step windows of a batch of `batch` rows: from `idx` (`[2 · n_step · B]` u32: each window
/// step's ring rows, then whether each is written, 0 or 1) and `flags` (`[3 · n_step · B, 1]`: those
/// rows' rewards, done flags and terminated flags, gathered in that layout), the return R and the
/// bootstrap factor β `[B, 1]` and the last row of each window `[B, 1]` (u32) at discount `gamma`.
pub fn windows(idx: &Tensor<2>, flags: &FloatTensor<Cube>, batch: usize, n_step: usize, gamma: f64) -> Result<(Tensor<2>, Tensor<2>, Tensor<2>)> {
    let nb = n_step * batch;
    let idx_p = cube(idx, [2 * nb, 1], "the window rows")?;
    let out = || Cube::float_empty(Shape::new([batch, 1]), &idx_p.device, FloatDType::F32); // written whole below
    let (ret, disc, last) = (out(), out(), out());
    let groups = u32::try_from(batch.div_ceil(64)).ok().filter(|&g| (1..=65_535).contains(&g)).ok_or_else(|| anyhow!("SAC's device-resident batch: {batch} rows are not one kernel's grid"))?;
    let kernel = WgslKernel { name: "dextrain_replay_window", key: (), source: window_source, entry_point: "replay_window", workgroup: [64, 1] };
    // WindowCfg: batch, n_step, γ − 1 as f32 (the tensor ops' scalar), padding
    let constants = [as_u32(batch, "the batch")?, as_u32(n_step, "sac.n_step")?, ((gamma - 1.0) as f32).to_bits(), 0];
    launch(kernel, [groups, 1, 1], &[&idx_p, flags, &ret, &disc, &last], &constants);
    Ok((tensor_of(ret), tensor_of(disc), tensor_of(last)))
}
