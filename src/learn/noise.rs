//! The learner's Gaussian action noise, drawn from the counter hash the simulator uses (common.wgsl's
//! `rand_uniform`), so the host and the device draw the same numbers: ε[i, k] for row i (the env),
//! column k (the action) and draw d (the learner's act calls so far) is Box–Muller of the hash's
//! uniforms (seed, env i, episode slot d, purpose [`PURPOSE_ACTION_NOISE`], keys 2k and 2k + 1).
//!
//! - [`host_normals`]: on the host (PPO's host rollouts);
//! - [`DeviceNoise`]: `shaders/noise.wgsl` on the simulator's wgpu device, written into a tensor of
//!   burn's wgpu learner on that device (PPO's device-resident rollouts): no host traffic but the
//!   16-byte parameters of each draw.

use anyhow::{Context, Result};
use burn::prelude::{Device, Tensor};

use super::gpu_io::{flush, zeros_buffer};
use crate::env::common::rand_uniform;
use crate::env::gpu::{GpuContext, WORKGROUP_SIZE, noise_shader_source};
use crate::env::gpu_bindings::{LEARNER_NOISE, NOISE_CFG, NOISE_GROUP, NOISE_OUT};

/// The action noise's stream in the counter hash (the env's purposes are 1–5; noise.wgsl's twin).
pub const PURPOSE_ACTION_NOISE: u32 = 6;

/// Standard normal draws `[rows, cols]` (row-major) of draw `draw` (the module documentation).
pub fn host_normals(seed: u32, draw: u32, rows: usize, cols: usize) -> Vec<f32> {
    let mut out = vec![0.0f32; rows * cols];
    for (e, v) in out.iter_mut().enumerate() {
        let (i, k) = ((e / cols) as u32, (e % cols) as u32);
        let u1 = 1.0 - rand_uniform(seed, i, draw, PURPOSE_ACTION_NOISE, 2 * k);
        let u2 = rand_uniform(seed, i, draw, PURPOSE_ACTION_NOISE, 2 * k + 1);
        // √(−2 ln u1) cos(2π u2), 2π as the shader's 6.2831853 (the same f32)
        *v = (-2.0 * u1.ln()).sqrt() * (std::f32::consts::TAU * u2).cos();
    }
    out
}

/// `NoiseCfg` of noise.wgsl.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct NoiseCfg {
    seed: u32,
    draw: u32,
    rows: u32,
    cols: u32,
}

/// noise.wgsl's pipeline and buffers for draws of `[rows, cols]`, on the simulator's device.
pub struct DeviceNoise {
    ctx: GpuContext,
    pipeline: wgpu::ComputePipeline,
    group: wgpu::BindGroup,
    cfg: wgpu::Buffer,
    out: wgpu::Buffer,
    rows: usize,
    cols: usize,
    /// burn's wgpu device on `ctx` (the tensors' device).
    device: Device,
}

impl DeviceNoise {
    /// The kernel for draws of `[rows, cols]` into tensors on `device` (burn's wgpu runtime on `ctx`'s device).
    pub fn new(ctx: &GpuContext, device: &Device, rows: usize, cols: usize) -> Result<DeviceNoise> {
        let [pipeline] = ctx.compute_pipelines(NOISE_GROUP.shader, &noise_shader_source(), [LEARNER_NOISE.entry_point])?;
        let cfg = ctx.create_binding_buffer(NOISE_CFG, &[NoiseCfg { seed: 0, draw: 0, rows: rows as u32, cols: cols as u32 }], wgpu::BufferUsages::empty())?;
        let out = ctx
            .create_binding_buffer(NOISE_OUT, &vec![0f32; rows * cols], wgpu::BufferUsages::empty())
            .with_context(|| format!("the action noise of {rows} envs × {cols} actions"))?;
        let group = ctx.bind_group(&pipeline, &LEARNER_NOISE, &[(NOISE_CFG, &cfg), (NOISE_OUT, &out)])?;
        Ok(DeviceNoise { ctx: ctx.clone(), pipeline, group, cfg, out, rows, cols, device: device.clone() })
    }

    /// Draw `draw` of stream `seed` as a `[rows, cols]` tensor on the learner device: the same
    /// numbers as [`host_normals`] to the GPU's `log`/`cos` rounding.
    pub fn normals(&self, seed: u32, draw: u32) -> Result<Tensor<2>> {
        let (rows, cols) = (self.rows, self.cols);
        self.ctx.upload(NOISE_CFG.name, &self.cfg, bytemuck::bytes_of(&NoiseCfg { seed, draw, rows: rows as u32, cols: cols as u32 }))?;
        let dst = zeros_buffer(rows, cols, &self.device)?;
        let wg = ((rows * cols) as u32).div_ceil(WORKGROUP_SIZE);
        let x = wg.clamp(1, 65535);
        let mut enc = self.ctx.encode_passes(&[(&self.pipeline, &self.group)], (x, wg.div_ceil(x).max(1)));
        enc.copy_buffer_to_buffer(&self.out, 0, dst.buffer(), dst.offset(), dst.size());
        // burn's zero fill of dst runs before this copy (module doc of gpu_io)
        flush(&self.device)?;
        self.ctx.submit(enc, "the learner's action noise")?;
        Ok(dst.tensor)
    }
}
