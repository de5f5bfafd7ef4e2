//! The device-resident learners' observation normalisers as two kernels of our own per normaliser
//! (`shaders/normalizer.wgsl`) over burn's tensors, where the tensor ops of
//! [`DeviceNormalizer::update`] and [`DeviceNormalizer::normalized`] launch ~19 kernels: the
//! actor's and the critic's normalisers of an env step are one submission of four dispatches.
//!
//! `norm_update` reduces each column in a fixed order (one workgroup per column: the same bits on
//! every run) and merges the batch into the running mean and M2 in place (Chan, as
//! [`crate::learn::normalizer::Normalizer::update`] does in f64 on the host); `norm_apply` writes
//! `(x − μ) / (σ + ε)` into a fresh tensor. Ordering as in `fused_adam.rs`: burn's recorded work is
//! flushed to the queue before ours.

use anyhow::{Result, ensure};
use burn::prelude::{Device, Tensor};

use crate::gpu::io::{TensorBuffer, empty_buffer, flush, tensor_buffer};
use crate::learn::normalizer::DeviceNormalizer;
use crate::gpu::context::GpuContext;
use crate::gpu::shaders::{SHADER_NORMALIZER, workgroups_of};
use crate::gpu::bindings::{NORM_APPLY, NORM_CFG, NORM_GROUP, NORM_M2, NORM_MEAN, NORM_OUT, NORM_SCALE, NORM_UPDATE, NORM_X};
use crate::gpu_counts::{self, Event};

/// Invocations per workgroup (normalizer.wgsl's `NORM_WORKGROUP`).
pub const NORM_WORKGROUP: u32 = 256;

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

/// normalizer.wgsl's pipelines and the constants' buffer (a slot per normaliser of a step).
pub struct NormalizerKernels {
    ctx: GpuContext,
    update: wgpu::ComputePipeline,
    apply: wgpu::ComputePipeline,
    cfg: wgpu::Buffer,
    slot: u64,
    device: Device,
}

/// The normalisers one submission handles.
const SLOTS: usize = 2;

impl NormalizerKernels {
    /// The kernels on `ctx`'s device, for tensors of `device` (burn's wgpu runtime on it).
    pub fn new(ctx: &GpuContext, device: &Device) -> Result<NormalizerKernels> {
        let [update, apply] = ctx.compute_pipelines(NORM_GROUP.shader, SHADER_NORMALIZER, [NORM_UPDATE.entry_point, NORM_APPLY.entry_point])?;
        let align = ctx.device.limits().min_uniform_buffer_offset_alignment as u64;
        let slot = (std::mem::size_of::<NormCfg>() as u64).next_multiple_of(align.max(16));
        let cfg = ctx.create_buffer_with(NORM_CFG.name, &vec![0u8; (slot * SLOTS as u64) as usize], NORM_CFG.space.into(), NORM_CFG.space.usage())?;
        Ok(NormalizerKernels { ctx: ctx.clone(), update, apply, cfg, slot, device: device.clone().inner() })
    }

    /// Merges each `x` `[B, D]` into its normaliser (statistics in place, the host count advanced),
    /// then normalises it with the new statistics: `(x − μ) / (σ + ε)` as fresh tensors, in order.
    /// One upload per normaliser, one submission; the statistics are not read back. None (and nothing done) when
    /// a tensor is not a contiguous f32 tensor of burn's wgpu device: the caller runs tensor ops.
    pub fn update_and_normalize(&self, work: &mut [(&mut DeviceNormalizer, &Tensor<2>)]) -> Result<Option<Vec<Tensor<2>>>> {
        ensure!(work.len() <= SLOTS, "{} normalisers in one submission (at most {SLOTS})", work.len());
        let mut inputs = Vec::with_capacity(work.len());
        for (norm, x) in work.iter() {
            let [b, d] = x.dims();
            ensure!(b > 0 && d > 0 && d <= 65_535 && d == norm.mean.dims()[1], "a batch of shape [{b}, {d}] for a normaliser of {} components", norm.mean.dims()[1]);
            let (Ok(xb), Ok(mb), Ok(m2b), Ok(sb)) = (tensor_buffer(x), tensor_buffer(&norm.mean), tensor_buffer(&norm.m2), tensor_buffer(&norm.scale)) else {
                return Ok(None);
            };
            inputs.push([xb, mb, m2b, sb]);
        }
        let mut held: Vec<[TensorBuffer; 5]> = Vec::with_capacity(work.len());
        let mut outs = Vec::with_capacity(work.len());
        for (k, ((norm, x), [xb, mb, m2b, sb])) in work.iter_mut().zip(inputs).enumerate() {
            let [b, d] = x.dims();
            let (na, nb) = (norm.count, b as f64);
            let n = na + nb;
            // Chan's weights in f64, as the host's merge
            let cfg = NormCfg { rows: b as u32, cols: d as u32, _pad0: 0, _pad1: 0, w_mean: (nb / n) as f32, w_m2: (na * nb / n) as f32, count: n as f32, eps: norm.eps as f32 };
            // (one 32-byte upload per normaliser: the bytes do not depend on the adapter's alignment)
            self.ctx.upload_at(NORM_CFG.name, &self.cfg, self.slot * k as u64, bytemuck::bytes_of(&cfg))?;
            norm.count = n;
            let out = empty_buffer(b, d, &self.device)?; // norm_apply writes every entry
            held.push([xb, mb, m2b, sb, out]);
        }
        let cfg_bytes = std::mem::size_of::<NormCfg>() as u64;
        let mut groups = Vec::with_capacity(2 * held.len());
        for (k, [x, mean, m2, scale, out]) in held.iter().enumerate() {
            let cfg = (&self.cfg, self.slot * k as u64, cfg_bytes);
            let all = [(NORM_CFG, cfg), (NORM_X, x.slice()), (NORM_MEAN, mean.slice()), (NORM_M2, m2.slice()), (NORM_SCALE, scale.slice()), (NORM_OUT, out.slice())];
            groups.push(self.ctx.bind_group_slices(&self.update, &NORM_UPDATE, &all)?);
            groups.push(self.ctx.bind_group_slices(&self.apply, &NORM_APPLY, &all)?);
        }
        let mut enc = self.ctx.device.create_command_encoder(&Default::default());
        {
            let mut pass = enc.begin_compute_pass(&Default::default());
            for (k, (_, x)) in work.iter().enumerate() {
                let [b, d] = x.dims();
                pass.set_pipeline(&self.update);
                pass.set_bind_group(0, &groups[2 * k], &[]);
                pass.dispatch_workgroups(d as u32, 1, 1);
                pass.set_pipeline(&self.apply);
                pass.set_bind_group(0, &groups[2 * k + 1], &[]);
                let (gx, gy) = workgroups_of((b * d) as u32, NORM_WORKGROUP);
                pass.dispatch_workgroups(gx, gy, 1);
            }
        }
        gpu_counts::add_n(Event::Kernel, "dextrain:normalizers", 2 * work.len() as u64);
        // what burn recorded (the observations, and reads of the statistics) runs first
        flush(&self.device)?;
        self.ctx.submit(enc, "the observation normalisers (normalizer.wgsl)")?;
        for [_, _, _, _, out] in held {
            outs.push(out.tensor);
        }
        Ok(Some(outs))
    }
}
