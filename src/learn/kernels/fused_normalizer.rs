//! The device-resident learners' observation normalisers as two kernels of our own
//! (`shaders/normalizer.wgsl`, a template of a module per entry point) over burn's tensors, where
//! the tensor ops of [`DeviceNormalizer::update`] and [`DeviceNormalizer::normalized`] launch ~19
//! kernels per normaliser: the actor's and the critic's normalisers of an env step are two
//! launches on burn's command stream (`wgsl_kernel::launch`: no flush or submission of ours, the
//! constants launch arguments), each over both normalisers.
//!
//! `norm_update` reduces each column in a fixed order (one workgroup per column: the same bits on
//! every run) and merges the batch into the running mean and M2 in place (Chan, as
//! [`crate::learn::normalizer::Normalizer::update`] does in f64 on the host); `norm_apply` writes
//! `(x − μ) / (σ + ε)` into a fresh tensor. Until 2026-12-01 (session 38) each normaliser had its
//! own two launches (and until session 37 the four were dispatches in a pass and a submission of
//! ours after a flush of burn's stream): the same arithmetic per column and per entry, so the same
//! bits.

use anyhow::{Result, ensure};
use burn::backend::Cube;
use burn::backend::ops::FloatTensorOps;
use burn::backend::tensor::FloatTensor;
use burn::prelude::Tensor;
use burn::tensor::{FloatDType, Shape};

use crate::gpu::shaders::workgroups_of;
use crate::learn::kernels::wgsl_kernel::{WgslKernel, entry_module, indexed_getter, indexed_setter, launch, plain_primitive};
use crate::learn::normalizer::DeviceNormalizer;

/// Invocations per workgroup (normalizer.wgsl's `NORM_WORKGROUP`).
pub const NORM_WORKGROUP: u32 = 256;

/// shaders/normalizer.wgsl: a template of a module per entry point.
const TEMPLATE: &str = include_str!("../../../shaders/normalizer.wgsl");

/// `NormSlot` of normalizer.wgsl (keep in sync): one normaliser's batch and merge in a launch's
/// constants (`NormLaunch`, one per normaliser).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct NormSlot {
    pub rows: u32,
    pub cols: u32,
    /// Its first workgroup in the launch.
    pub first: u32,
    pub _pad: u32,
    pub w_mean: f32,
    pub w_m2: f32,
    pub count: f32,
    pub eps: f32,
}

/// An entry point of normalizer.wgsl.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum NormEntry {
    /// `norm_update`: each batch merged into its statistics (x, mean, M2, scale per normaliser).
    Update,
    /// `norm_apply`: each batch normalised (x, mean, scale, out per normaliser).
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

    /// The roles of a normaliser's tensors in a launch, in binding order (each role's bindings
    /// together, normaliser 0 first): (binding name prefix, getter, setter).
    fn roles(self) -> &'static [(&'static str, Option<&'static str>, Option<&'static str>)] {
        match self {
            NormEntry::Update => &[
                ("norm_x", Some("norm_x"), None),
                ("norm_mean", Some("norm_mean"), Some("set_norm_mean")),
                ("norm_m2", Some("norm_m2"), Some("set_norm_m2")),
                ("norm_scale", None, Some("set_norm_scale")),
            ],
            NormEntry::Apply => &[("norm_x", Some("norm_x"), None), ("norm_mean", Some("norm_mean"), None), ("norm_scale", Some("norm_scale"), None), ("norm_out", None, Some("set_norm_out"))],
        }
    }
}

/// One variant of the template: an entry point over `group` normalisers.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct NormKernel {
    /// The entry point.
    pub entry: NormEntry,
    /// Normalisers per launch (1 or 2).
    pub group: u32,
}

/// Storage buffers a launch of `entry` over `group` normalisers binds (the uniform after them).
pub fn storage_bindings(entry: NormEntry, group: u32) -> u32 {
    entry.roles().len() as u32 * group
}

/// The module of one variant: the template's common text and the entry's section, its bindings
/// and the accessors that pick normaliser k's.
pub fn shader_source(key: NormKernel) -> String {
    let group = key.group.max(1);
    let kept = entry_module(TEMPLATE, key.entry.name());
    let mut bindings = String::new();
    let mut at = 0u32;
    for (prefix, _, _) in key.entry.roles() {
        for k in 0..group {
            bindings += &format!("@group(0) @binding({at}) var<storage, read_write> {prefix}_{k}: array<f32>;\n");
            at += 1;
        }
    }
    bindings += &format!("@group(0) @binding({at}) var<uniform> nl: NormLaunch;");
    let mut accessors = String::new();
    for (prefix, get, set) in key.entry.roles() {
        if let Some(get) = get {
            accessors += &indexed_getter(get, prefix, group);
        }
        if let Some(set) = set {
            accessors += &indexed_setter(set, prefix, group);
        }
    }
    kept.replace("$GROUP", &group.to_string()).replace("$BINDINGS", &bindings).replace("$ACCESSORS", &accessors)
}

/// The normalisers one call handles (the actor's and the critic's).
const MAX_NORMALIZERS: usize = 2;

/// The most workgroups one launch numbers (an index past 2^32 would wrap).
const MAX_WORKGROUPS: u64 = 1 << 22;

/// Merges each `x` `[B, D]` into its normaliser (statistics in place, the host count advanced),
/// then normalises it with the new statistics: `(x − μ) / (σ + ε)` as fresh tensors, in order.
/// Two launches on burn's stream for all of them where the device binds `4 · work.len()` storage
/// buffers per kernel (else two per normaliser); the statistics are not read back. None (and
/// nothing done) when a tensor is not a contiguous f32 tensor of burn's wgpu device: the caller
/// runs tensor ops.
pub fn update_and_normalize(work: &mut [(&mut DeviceNormalizer, &Tensor<2>)], max_storage_buffers: u32) -> Result<Option<Vec<Tensor<2>>>> {
    ensure!(work.len() <= MAX_NORMALIZERS, "{} normalisers in one call (at most {MAX_NORMALIZERS})", work.len());
    // every tensor's primitive first: a refusal leaves everything as it was
    let mut inputs: Vec<[FloatTensor<Cube>; 4]> = Vec::with_capacity(work.len());
    for (norm, x) in work.iter() {
        let [b, d] = x.dims();
        ensure!(b > 0 && d > 0 && d == norm.mean.dims()[1], "a batch of shape [{b}, {d}] for a normaliser of {} components", norm.mean.dims()[1]);
        ensure!(((b * d) as u64).div_ceil(NORM_WORKGROUP as u64) + d as u64 <= MAX_WORKGROUPS, "a batch of shape [{b}, {d}]: over the normalisers' {MAX_WORKGROUPS} workgroups");
        let prim = |t: &Tensor<2>, shape: [usize; 2]| plain_primitive(&t.clone().inner(), shape).ok();
        let (Some(xp), Some(mp), Some(m2p), Some(sp)) = (prim(x, [b, d]), prim(&norm.mean, [1, d]), prim(&norm.m2, [1, d]), prim(&norm.scale, [1, d])) else {
            return Ok(None);
        };
        inputs.push([xp, mp, m2p, sp]);
    }
    if inputs.is_empty() {
        return Ok(Some(Vec::new()));
    }
    // each normaliser's merge, in f64 as the host's (Chan's weights), and its fresh output
    let mut slots = Vec::with_capacity(work.len());
    let mut outs = Vec::with_capacity(work.len());
    for ((norm, x), [xp, ..]) in work.iter_mut().zip(&inputs) {
        let [b, d] = x.dims();
        let (na, nb) = (norm.count, b as f64);
        let n = na + nb;
        slots.push(NormSlot { rows: b as u32, cols: d as u32, first: 0, _pad: 0, w_mean: (nb / n) as f32, w_m2: (na * nb / n) as f32, count: n as f32, eps: norm.eps as f32 });
        norm.count = n;
        outs.push(Cube::float_empty(Shape::new([b, d]), &xp.device, FloatDType::F32)); // norm_apply writes every entry
    }
    // one launch per entry over all the normalisers, or over one each where the device binds fewer
    let per_launch = if max_storage_buffers >= storage_bindings(NormEntry::Update, inputs.len() as u32).max(storage_bindings(NormEntry::Apply, inputs.len() as u32)) { inputs.len() } else { 1 };
    for (chunk, (ins, outs)) in slots.chunks(per_launch).zip(inputs.chunks(per_launch).zip(outs.chunks(per_launch))) {
        let group = chunk.len() as u32;
        let kernel = |entry: NormEntry| WgslKernel { name: "dextrain_normalizers", key: NormKernel { entry, group }, source: shader_source, entry_point: entry.name(), workgroup: [NORM_WORKGROUP, 1] };
        // (counted by gpu_counts' launch observer as `dextrain:normalizers`)
        // norm_update: one workgroup per column, the normalisers' columns one after another
        let mut update = chunk.to_vec();
        let mut groups = 0u32;
        for s in update.iter_mut() {
            s.first = groups;
            groups += s.cols;
        }
        let buffers: Vec<&FloatTensor<Cube>> = (0..4).flat_map(|role| ins.iter().map(move |i| &i[role])).collect(); // x…, mean…, M2…, scale…
        let (gx, gy) = workgroups_of(groups * NORM_WORKGROUP, NORM_WORKGROUP);
        launch(kernel(NormEntry::Update), [gx, gy, 1], &buffers, bytemuck::cast_slice(update.as_slice()));
        // norm_apply: one invocation per entry, each normaliser from a workgroup of its own
        let mut apply = chunk.to_vec();
        let mut groups = 0u32;
        for s in apply.iter_mut() {
            s.first = groups;
            groups += (s.rows * s.cols).div_ceil(NORM_WORKGROUP);
        }
        let buffers: Vec<&FloatTensor<Cube>> = [0, 1, 3].iter().flat_map(|&role| ins.iter().map(move |i| &i[role])).chain(outs.iter()).collect(); // x…, mean…, scale…, out…
        let (gx, gy) = workgroups_of(groups * NORM_WORKGROUP, NORM_WORKGROUP);
        launch(kernel(NormEntry::Apply), [gx, gy, 1], &buffers, bytemuck::cast_slice(apply.as_slice()));
    }
    Ok(Some(outs.into_iter().map(Tensor::from_primitive::<Cube>).collect()))
}
