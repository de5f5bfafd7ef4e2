//! Tensors of burn's wgpu learner as wgpu buffers, so that the simulator's command buffers copy
//! observations into them and actions out of them on the device (the device-resident rollouts of
//! `run/runner.rs`; docs/gpu.md "The GPU loop").
//!
//! burn's wgpu backend (cubecl) owns its tensors' memory: a tensor is a slice (offset, size) of a
//! `wgpu::Buffer` of cubecl's pool, which cubecl hands out through its compute client
//! (`ComputeClient::get_resource`). The simulator runs on the same `wgpu::Device` and `wgpu::Queue`
//! (`learn::device`), so a copy between our buffers and that slice is one
//! `copy_buffer_to_buffer` in our command encoder. Ordering: cubecl records its kernels into its
//! own encoder and submits them later; [`flush`] submits what it has recorded, so that work
//! submitted next on the shared queue (ours) runs after it, and whatever cubecl records afterwards
//! runs after ours. A [`TensorBuffer`] keeps the tensor and cubecl's binding alive, so the slice is
//! neither freed nor handed to another tensor while our commands use it.

use anyhow::{Result, anyhow, ensure};
use burn::backend::Cube;
use cubecl_wgpu::{AutoCompiler, WgpuResource, WgpuServer};
use burn::prelude::{Device, Tensor};
use burn::tensor::DType;

/// The device memory of one f32 tensor: `size` bytes from `offset` in `buffer`.
pub struct TensorBuffer {
    /// The tensor (kept alive while its memory is used).
    pub tensor: Tensor<2>,
    /// cubecl's binding of the memory (keeps the slice in place).
    resource: cubecl_runtime::storage::ManagedResource<WgpuResource>,
}

impl TensorBuffer {
    /// The buffer holding the tensor.
    pub fn buffer(&self) -> &wgpu::Buffer {
        &self.resource.resource().buffer
    }

    /// The tensor's first byte in [`TensorBuffer::buffer`].
    pub fn offset(&self) -> u64 {
        self.resource.resource().offset
    }

    /// The tensor's bytes (rows × columns × 4).
    pub fn size(&self) -> u64 {
        4 * self.tensor.shape().num_elements() as u64
    }

    /// (buffer, offset, bytes): the slice a bind group binds (`GpuContext::bind_group_slices`).
    pub fn slice(&self) -> (&wgpu::Buffer, u64, u64) {
        (self.buffer(), self.offset(), self.size())
    }
}

/// The device memory of `t`, a contiguous f32 tensor on burn's wgpu device (the autodiff wrapper,
/// if any, is dropped: the memory is the same).
pub fn tensor_buffer(t: &Tensor<2>) -> Result<TensorBuffer> {
    let tensor = t.clone().inner();
    let prim = tensor.clone().try_into_primitive::<Cube>().map_err(|e| anyhow!("not a tensor of burn's wgpu device: {e:?}"))?;
    ensure!(prim.dtype == DType::F32, "a device-resident tensor must be f32, not {:?}", prim.dtype);
    // row-major strides from the handle's first byte (cubecl may pad the allocation past the
    // last element: only `size()` bytes are ever bound or copied)
    ensure!(prim.is_contiguous(), "a device-resident tensor must be contiguous (shape {:?})", t.dims());
    let resource = prim
        .client
        .get_resource::<WgpuServer<AutoCompiler>>(prim.handle.clone())
        .map_err(|e| anyhow!("cannot reach the memory of a tensor of burn's wgpu device: {e:?}"))?;
    let out = TensorBuffer { tensor, resource };
    let r = out.resource.resource();
    ensure!(r.size >= out.size(), "burn's wgpu tensor holds {} bytes, its shape needs {}", r.size, out.size());
    Ok(out)
}

/// A zeroed `[rows, cols]` tensor on `device` and its memory (a fresh tensor each call: what the
/// learner still holds of an earlier one is never overwritten).
pub fn zeros_buffer(rows: usize, cols: usize, device: &Device) -> Result<TensorBuffer> {
    tensor_buffer(&Tensor::zeros([rows, cols], &device.clone().inner()))
}

/// A fresh `[rows, cols]` tensor on `device` and its memory, for a copy or a kernel of ours to
/// fill: not initialised (no fill kernel runs; every byte must be written before burn reads it),
/// and never memory the learner still holds.
pub fn empty_buffer(rows: usize, cols: usize, device: &Device) -> Result<TensorBuffer> {
    tensor_buffer(&Tensor::empty([rows, cols], &device.clone().inner()))
}

/// Submits the work burn has recorded on `device` to the queue (see the module documentation).
pub fn flush(device: &Device) -> Result<()> {
    device.flush().map_err(|e| anyhow!("burn's wgpu device: {e:?}"))
}

/// Waits until the work recorded on `device` has run (a host synchronisation, counted as a wait).
pub fn sync(device: &Device) -> Result<()> {
    crate::gpu_counts::add(crate::gpu_counts::Event::Wait, "burn:sync");
    device.sync().map_err(|e| anyhow!("burn's wgpu device: {e:?}"))
}
