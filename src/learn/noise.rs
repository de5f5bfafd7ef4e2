//! The learners' action noise, drawn from the counter hash the simulator uses (common.wgsl's
//! `rand_uniform`), so the host and the device draw the same numbers. Draw d (a learner's count of
//! draws so far) of stream `seed` is a `[rows, cols]` matrix; entry (i, k) uses the hash's uniforms
//! (seed, row i, episode slot d, purpose [`PURPOSE_ACTION_NOISE`], keys 2k and 2k + 1):
//! - normal: Box–Muller of the two (PPO's and SAC's ε);
//! - uniform in [−1, 1): 2u − 1 of the first (SAC's random actions).
//!
//! [`host_normals`] / [`host_uniforms`] draw on the host (the host paths); [`DeviceNoise`] runs
//! `shaders/noise.wgsl` on the simulator's wgpu device and writes into a tensor of burn's wgpu
//! learner on that device (the device-resident rollouts): no host traffic but the 32-byte
//! parameters of each kernel, which may draw several draws at once ([`DeviceNoise::normals_block`]).

use anyhow::{Result, ensure};
use burn::prelude::{Device, Tensor};
use rayon::prelude::*;

use crate::gpu::io::{empty_buffer, flush};
use crate::env::common::rand_uniform;
use crate::gpu::context::GpuContext;
use crate::gpu::shaders::{noise_shader_source, workgroups_for};
use crate::gpu::bindings::{EntryBindings, LEARNER_NOISE, LEARNER_UNIFORM, NOISE_CFG, NOISE_GROUP, NOISE_OUT};

/// The action noise's stream in the counter hash (the env's purposes are 1–5; noise.wgsl's twin).
pub const PURPOSE_ACTION_NOISE: u32 = 6;

/// Rows per rayon task of [`host_normals`] (each number costs two hashes, a `ln` and a `cos`).
const NOISE_ROWS_PER_TASK: usize = 256;

/// Standard normal draws `[rows, cols]` (row-major) of draw `draw` (the module documentation),
/// blocks of rows over the rayon pool (each entry depends on its indices only: the same numbers
/// for any number of threads).
pub fn host_normals(seed: u32, draw: u32, rows: usize, cols: usize) -> Vec<f32> {
    host_normals_from_row(seed, draw, 0, rows, cols)
}

/// Rows `first_row .. first_row + rows` of draw `draw`'s standard normal numbers: what
/// [`host_normals`] with `first_row + rows` rows holds there (rank r of a data-parallel job draws
/// its envs' rows of the job's noise, `first_row` = its first env's global id).
pub fn host_normals_from_row(seed: u32, draw: u32, first_row: u32, rows: usize, cols: usize) -> Vec<f32> {
    let mut out = vec![0.0f32; rows * cols];
    if cols == 0 {
        return out;
    }
    out.par_chunks_mut(NOISE_ROWS_PER_TASK * cols).enumerate().for_each(|(block, chunk)| {
        for (e, v) in chunk.iter_mut().enumerate() {
            let (i, k) = (first_row.wrapping_add((block * NOISE_ROWS_PER_TASK + e / cols) as u32), (e % cols) as u32);
            let u1 = 1.0 - rand_uniform(seed, i, draw, PURPOSE_ACTION_NOISE, 2 * k);
            let u2 = rand_uniform(seed, i, draw, PURPOSE_ACTION_NOISE, 2 * k + 1);
            // √(−2 ln u1) cos(2π u2), 2π as the shader's 6.2831853 (the same f32)
            *v = (-2.0 * u1.ln()).sqrt() * (std::f32::consts::TAU * u2).cos();
        }
    });
    out
}

/// Uniform draws in [−1, 1) `[rows, cols]` (row-major) of draw `draw`.
pub fn host_uniforms(seed: u32, draw: u32, rows: usize, cols: usize) -> Vec<f32> {
    host_uniforms_from_row(seed, draw, 0, rows, cols)
}

/// Rows `first_row .. first_row + rows` of draw `draw`'s uniform numbers (as
/// [`host_normals_from_row`]).
pub fn host_uniforms_from_row(seed: u32, draw: u32, first_row: u32, rows: usize, cols: usize) -> Vec<f32> {
    (0..rows * cols).map(|e| 2.0 * rand_uniform(seed, first_row.wrapping_add((e / cols) as u32), draw, PURPOSE_ACTION_NOISE, 2 * (e % cols) as u32) - 1.0).collect()
}

/// `NoiseCfg` of noise.wgsl (keep in sync).
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct NoiseCfg {
    seed: u32,
    draw: u32,
    rows: u32,
    cols: u32,
    envs: u32,
    _pad: [u32; 3],
}

/// noise.wgsl's pipelines for draws of up to `capacity` numbers, on the simulator's device; each
/// draw is written by the kernel straight into a fresh tensor of burn's wgpu learner.
pub struct DeviceNoise {
    ctx: GpuContext,
    normal: wgpu::ComputePipeline,
    uniform: wgpu::ComputePipeline,
    cfg: wgpu::Buffer,
    capacity: usize,
    /// burn's wgpu device on `ctx` (the tensors' device).
    device: Device,
}

impl DeviceNoise {
    /// The kernels for draws of up to `capacity` numbers into tensors on `device` (burn's wgpu
    /// runtime on `ctx`'s device).
    pub fn new(ctx: &GpuContext, device: &Device, capacity: usize) -> Result<DeviceNoise> {
        let [normal, uniform] = ctx.compute_pipelines(NOISE_GROUP.shader, &noise_shader_source(), [LEARNER_NOISE.entry_point, LEARNER_UNIFORM.entry_point])?;
        let zero = NoiseCfg { seed: 0, draw: 0, rows: 0, cols: 0, envs: 1, _pad: [0; 3] };
        let cfg = ctx.create_binding_buffer(NOISE_CFG, &[zero], wgpu::BufferUsages::empty())?;
        Ok(DeviceNoise { ctx: ctx.clone(), normal, uniform, cfg, capacity, device: device.clone().inner() })
    }

    /// Draw `draw` of stream `seed` as a `[rows, cols]` tensor of standard normal numbers on the
    /// learner device: [`host_normals`]' numbers to the GPU's `log`/`cos` rounding.
    pub fn normals(&self, seed: u32, draw: u32, rows: usize, cols: usize) -> Result<Tensor<2>> {
        self.normals_block(seed, draw, 1, rows, cols)
    }

    /// Draws `draw`, `draw + 1`, … (`draws` of them) of stream `seed`, each `[rows, cols]`, stacked
    /// as one `[draws · rows, cols]` tensor by one kernel: rows `t · rows ..` are draw `draw + t`
    /// (PPO draws a rollout's noise at its first step).
    pub fn normals_block(&self, seed: u32, draw: u32, draws: usize, rows: usize, cols: usize) -> Result<Tensor<2>> {
        self.run(&self.normal, &LEARNER_NOISE, NoiseCfg { seed, draw, rows: (draws * rows) as u32, cols: cols as u32, envs: rows.max(1) as u32, _pad: [0; 3] })
    }

    /// As [`DeviceNoise::normals`] with uniform numbers in [−1, 1) ([`host_uniforms`]' numbers).
    pub fn uniforms(&self, seed: u32, draw: u32, rows: usize, cols: usize) -> Result<Tensor<2>> {
        self.run(&self.uniform, &LEARNER_UNIFORM, NoiseCfg { seed, draw, rows: rows as u32, cols: cols as u32, envs: rows.max(1) as u32, _pad: [0; 3] })
    }

    fn run(&self, pipeline: &wgpu::ComputePipeline, entry: &EntryBindings, c: NoiseCfg) -> Result<Tensor<2>> {
        let (rows, cols) = (c.rows as usize, c.cols as usize);
        ensure!(rows * cols <= self.capacity, "a draw of {rows} × {cols} numbers from a noise kernel made for {}", self.capacity);
        if rows * cols == 0 {
            return Ok(Tensor::empty([rows, cols], &self.device));
        }
        self.ctx.upload(NOISE_CFG.name, &self.cfg, bytemuck::bytes_of(&c))?;
        let dst = empty_buffer(rows, cols, &self.device)?; // the kernel writes every number
        let cfg_bytes = std::mem::size_of::<NoiseCfg>() as u64;
        let group = self.ctx.bind_group_slices(pipeline, entry, &[(NOISE_CFG, (&self.cfg, 0, cfg_bytes)), (NOISE_OUT, dst.slice())])?;
        let enc = self.ctx.encode_passes(&[(pipeline, &group)], workgroups_for((rows * cols) as u32), "the learner's action noise");
        // work burn recorded before (which may still use this memory under its former owner) runs first
        flush(&self.device)?;
        self.ctx.submit(enc, "the learner's action noise")?;
        Ok(dst.tensor)
    }
}
