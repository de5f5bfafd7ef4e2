//! The device-resident learners' observation normalisers as two kernels of our own per normaliser
//! (`shaders/normalizer.wgsl`, a module per entry point) over burn's tensors, where the tensor ops
//! of [`DeviceNormalizer::update`] and [`DeviceNormalizer::normalized`] launch ~19 kernels: the
//! actor's and the critic's normalisers of an env step are four launches on burn's command stream
//! (`wgsl_kernel::launch`: no flush or submission of ours, the constants launch arguments).
//!
//! `norm_update` reduces each column in a fixed order (one workgroup per column: the same bits on
//! every run) and merges the batch into the running mean and M2 in place (Chan, as
//! [`crate::learn::normalizer::Normalizer::update`] does in f64 on the host); `norm_apply` writes
//! `(x − μ) / (σ + ε)` into a fresh tensor. Until 2026-12-01 (session 37) the four were dispatches
//! in a pass and a submission of ours after a flush of burn's stream, with their constants
//! uploaded: the same kernels, so the same bits.

use anyhow::{Result, ensure};
use burn::backend::Cube;
use burn::backend::ops::FloatTensorOps;
use burn::backend::tensor::FloatTensor;
use burn::prelude::Tensor;
use burn::tensor::{FloatDType, Shape};

use crate::gpu::shaders::workgroups_of;
use crate::learn::kernels::wgsl_kernel::{WgslKernel, entry_module, launch, plain_primitive};
use crate::learn::normalizer::DeviceNormalizer;

/// Invocations per workgroup (normalizer.wgsl's `NORM_WORKGROUP`).
pub const NORM_WORKGROUP: u32 = 256;

/// shaders/normalizer.wgsl: a template of a module per entry point.
const TEMPLATE: &str = include_str!("../../../shaders/normalizer.wgsl");

/// `NormCfg` of normalizer.wgsl (keep in sync).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct NormCfg {
    pub rows: u32,
    pub cols: u32,
    pub _pad0: u32,
    pub _pad1: u32,
    pub w_mean: f32,
    pub w_m2: f32,
    pub count: f32,
    pub eps: f32,
}

/// An entry point of normalizer.wgsl.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum NormEntry {
    /// `norm_update`: the batch merged into the statistics (x, mean, M2, scale).
    Update,
    /// `norm_apply`: the batch normalised (x, mean, scale, out).
    Apply,
}

impl NormEntry {
    /// Its function's name.
    pub fn name(self) -> &'static str {
        match self {
            NormEntry::Update => "norm_update",
            NormEntry::Apply => "norm_apply",
        }
    }
}

/// The module of one entry point: the template's common text and the entry's section.
pub fn shader_source(entry: NormEntry) -> String {
    entry_module(TEMPLATE, entry.name())
}

/// The normalisers one call handles (the actor's and the critic's).
const MAX_NORMALIZERS: usize = 2;

/// Merges each `x` `[B, D]` into its normaliser (statistics in place, the host count advanced),
/// then normalises it with the new statistics: `(x − μ) / (σ + ε)` as fresh tensors, in order.
/// Two launches per normaliser on burn's stream; the statistics are not read back. None (and
/// nothing done) when a tensor is not a contiguous f32 tensor of burn's wgpu device: the caller
/// runs tensor ops.
pub fn update_and_normalize(work: &mut [(&mut DeviceNormalizer, &Tensor<2>)]) -> Result<Option<Vec<Tensor<2>>>> {
    ensure!(work.len() <= MAX_NORMALIZERS, "{} normalisers in one call (at most {MAX_NORMALIZERS})", work.len());
    // every tensor's primitive first: a refusal leaves everything as it was
    let mut inputs: Vec<[FloatTensor<Cube>; 4]> = Vec::with_capacity(work.len());
    for (norm, x) in work.iter() {
        let [b, d] = x.dims();
        ensure!(b > 0 && d > 0 && d <= 65_535 && d == norm.mean.dims()[1], "a batch of shape [{b}, {d}] for a normaliser of {} components", norm.mean.dims()[1]);
        let prim = |t: &Tensor<2>, shape: [usize; 2]| plain_primitive(&t.clone().inner(), shape).ok();
        let (Some(xp), Some(mp), Some(m2p), Some(sp)) = (prim(x, [b, d]), prim(&norm.mean, [1, d]), prim(&norm.m2, [1, d]), prim(&norm.scale, [1, d])) else {
            return Ok(None);
        };
        inputs.push([xp, mp, m2p, sp]);
    }
    let kernel = |entry: NormEntry| WgslKernel { name: "dextrain_normalizers", key: entry, source: shader_source, entry_point: entry.name(), workgroup: [NORM_WORKGROUP, 1] };
    let mut outs = Vec::with_capacity(work.len());
    for ((norm, x), [xp, mp, m2p, sp]) in work.iter_mut().zip(inputs) {
        let [b, d] = x.dims();
        let (na, nb) = (norm.count, b as f64);
        let n = na + nb;
        // Chan's weights in f64, as the host's merge
        let cfg = NormCfg { rows: b as u32, cols: d as u32, _pad0: 0, _pad1: 0, w_mean: (nb / n) as f32, w_m2: (na * nb / n) as f32, count: n as f32, eps: norm.eps as f32 };
        let words: &[u32] = bytemuck::cast_slice(std::slice::from_ref(&cfg));
        norm.count = n;
        let out = Cube::float_empty(Shape::new([b, d]), &xp.device, FloatDType::F32); // norm_apply writes every entry
        // (counted by gpu_counts' launch observer as `dextrain:normalizers`)
        launch(kernel(NormEntry::Update), [d as u32, 1, 1], &[&xp, &mp, &m2p, &sp], words); // one workgroup per column
        let (gx, gy) = workgroups_of((b * d) as u32, NORM_WORKGROUP);
        launch(kernel(NormEntry::Apply), [gx, gy, 1], &[&xp, &mp, &sp, &out], words);
        outs.push(Tensor::from_primitive::<Cube>(out));
    }
    Ok(Some(outs))
}
