//! The GPU learner's matrix product of our own: `shaders/matmul.wgsl` (64 × 64 tiles of the
//! product per workgroup, 4 × 4 per thread, operands staged in workgroup memory) over burn's
//! tensors' memory, the `dextrain_tiled` routine of `learn::gpu_matmul`.
//!
//! cubek's routines on WGSL adapters are unit routines (one thread per output tile, operands read
//! from global memory); its shared-memory routines need cooperative matrices. This kernel stages
//! the operands in workgroup memory as a plain WGSL kernel can. Each product is one dispatch and
//! one submission of ours (what burn recorded before is flushed first, as `fused_normalizer.rs`
//! does), so it pays where a product is large; `bench --matmul` measures it beside cubek's.

use anyhow::{Result, anyhow, ensure};
use burn::backend::Cube;
use burn::backend::tensor::FloatTensor;
use burn::prelude::Tensor;
use burn::tensor::DType;
use burn_cubecl::kernel::matmul::init_matmul_output;
use cubecl_wgpu::{AutoCompiler, WgpuServer};
use std::sync::Mutex;

use crate::env::gpu::{GpuContext, SHADER_MATMUL};
use crate::env::gpu_bindings::{MM_A, MM_B, MM_C, MM_CFG, MM_GROUP, MM_TILED};
use crate::gpu_counts::{self, Event};

/// C rows and columns per workgroup (matmul.wgsl's `MM_TILE`).
const TILE: usize = 64;

/// `MatmulCfg` of matmul.wgsl (keep in sync): sizes and strides in f32 elements.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct MatmulCfg {
    pub m: u32,
    pub n: u32,
    pub k: u32,
    pub batches: u32,
    pub a_row: u32,
    pub a_col: u32,
    pub a_batch: u32,
    pub b_row: u32,
    pub b_col: u32,
    pub b_batch: u32,
    pub c_batch: u32,
    pub _pad: u32,
}

/// The kernel on one device: its context, pipeline and constants' buffer.
struct Kernel {
    ctx: GpuContext,
    pipeline: wgpu::ComputePipeline,
    cfg: wgpu::Buffer,
}

/// One kernel per wgpu device the process uses (found by the context's device).
static KERNELS: Mutex<Vec<Kernel>> = Mutex::new(Vec::new());

/// (rows, columns, batch) strides and the batch count of a rank-2 or rank-3 operand; a batch of
/// one is broadcast (stride 0).
fn strides_of(t: &FloatTensor<Cube>) -> Result<([usize; 2], [usize; 3], usize)> {
    let shape = t.meta.shape().to_vec();
    let strides = t.meta.strides().to_vec();
    match shape.len() {
        2 => Ok(([shape[0], shape[1]], [strides[0], strides[1], 0], 1)),
        3 => Ok(([shape[1], shape[2]], [strides[1], strides[2], if shape[0] == 1 { 0 } else { strides[0] }], shape[0])),
        r => Err(anyhow!("matmul.wgsl takes rank-2 or rank-3 operands, not rank {r}")),
    }
}

/// `lhs · rhs` for f32 lhs [(S,) M, K], rhs [(S,) K, N] (any strides) with matmul.wgsl → [(S,) M, N]
/// row-major; an error where the operands do not fit it (the caller falls back to cubek's).
pub fn matmul(lhs: &FloatTensor<Cube>, rhs: &FloatTensor<Cube>) -> Result<FloatTensor<Cube>> {
    ensure!(lhs.dtype == DType::F32 && rhs.dtype == DType::F32, "matmul.wgsl multiplies f32 tensors");
    let (([m, k], [a_row, a_col, a_batch], a_batches), ([k2, n], [b_row, b_col, b_batch], b_batches)) = (strides_of(lhs)?, strides_of(rhs)?);
    ensure!(k == k2 && (a_batches == b_batches || a_batches == 1 || b_batches == 1), "matmul.wgsl: shapes do not multiply");
    let batches = a_batches.max(b_batches);
    let fits = |v: usize| u32::try_from(v).ok();
    let cfg = MatmulCfg {
        m: fits(m).ok_or_else(|| anyhow!("too large"))?,
        n: fits(n).ok_or_else(|| anyhow!("too large"))?,
        k: fits(k).ok_or_else(|| anyhow!("too large"))?,
        batches: batches as u32,
        a_row: a_row as u32,
        a_col: a_col as u32,
        a_batch: a_batch as u32,
        b_row: b_row as u32,
        b_col: b_col as u32,
        b_batch: b_batch as u32,
        c_batch: fits(m * n).ok_or_else(|| anyhow!("too large"))?,
        _pad: 0,
    };
    let (gx, gy) = (n.div_ceil(TILE), m.div_ceil(TILE));
    ensure!(gx <= 65_535 && gy <= 65_535 && batches <= 65_535 && m * n > 0 && k > 0, "matmul.wgsl: a grid of {gx} × {gy} × {batches}");
    // the context of the tensors' device, and its kernel
    let device = match lhs.meta.shape().len() {
        2 => Tensor::<2>::from_primitive::<Cube>(lhs.clone()).device(),
        _ => Tensor::<3>::from_primitive::<Cube>(lhs.clone()).device(),
    };
    let ctx = crate::learn::device::gpu_context_of(&device).ok_or_else(|| anyhow!("matmul.wgsl: no wgpu context of this device"))?;
    let out = init_matmul_output(lhs, rhs, DType::F32); // [(S,) M, N], written whole below
    let resource = |t: &FloatTensor<Cube>| t.client.get_resource::<WgpuServer<AutoCompiler>>(t.handle.clone()).map_err(|e| anyhow!("cannot reach a tensor's memory: {e:?}"));
    let (ra, rb, rc) = (resource(lhs)?, resource(rhs)?, resource(&out)?);
    let mut kernels = KERNELS.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
    let at = match kernels.iter().position(|kn| kn.ctx.device == ctx.device) {
        Some(i) => i,
        None => {
            let [pipeline] = ctx.compute_pipelines(MM_GROUP.shader, SHADER_MATMUL, [MM_TILED.entry_point])?;
            let cfg_buffer = ctx.create_buffer_with(MM_CFG.name, &[0u8; std::mem::size_of::<MatmulCfg>()], MM_CFG.space.into(), MM_CFG.space.usage())?;
            kernels.push(Kernel { ctx: ctx.clone(), pipeline, cfg: cfg_buffer });
            kernels.len() - 1
        }
    };
    let kn = &kernels[at];
    // (written before the submission below, which is the next on the queue to read it)
    kn.ctx.upload_at(MM_CFG.name, &kn.cfg, 0, bytemuck::bytes_of(&cfg))?;
    fn slice(r: &cubecl_runtime::storage::ManagedResource<cubecl_wgpu::WgpuResource>) -> (&wgpu::Buffer, u64, u64) {
        let r = r.resource();
        (&r.buffer, r.offset, r.size)
    }
    let cfg_slice = (&kn.cfg, 0u64, std::mem::size_of::<MatmulCfg>() as u64);
    let group = kn.ctx.bind_group_slices(&kn.pipeline, &MM_TILED, &[(MM_CFG, cfg_slice), (MM_A, slice(&ra)), (MM_B, slice(&rb)), (MM_C, slice(&rc))])?;
    let mut enc = kn.ctx.device.create_command_encoder(&Default::default());
    {
        let mut pass = enc.begin_compute_pass(&Default::default());
        pass.set_pipeline(&kn.pipeline);
        pass.set_bind_group(0, &group, &[]);
        pass.dispatch_workgroups(gx as u32, gy as u32, batches as u32);
    }
    gpu_counts::add(Event::Kernel, "dextrain:matmul");
    // what burn recorded (the operands) runs first; burn's later work (reading C) after ours
    crate::learn::gpu_io::flush(&device)?;
    kn.ctx.submit(enc, "the learner's matrix product (matmul.wgsl)")?;
    Ok(out)
}
