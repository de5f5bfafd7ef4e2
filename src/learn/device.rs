//! The learner device (`train.device`): burn's CPU backend (`flex`) or burn's wgpu backend.
//!
//! `"cpu"` is flex. `"gpu"` / `"gpu:NAME"` is burn's wgpu runtime: on the simulator's own wgpu device
//! when the simulator runs on a GPU (burn registers the existing instance, adapter, device and queue,
//! so observations never cross to another device), else on a device opened the same way as the
//! simulator's (`GpuContext::new`). `"auto"` is the simulator's GPU when it has one, else a hardware
//! GPU adapter, else the CPU.

use anyhow::{Result, anyhow};
use burn::prelude::Device;

use crate::config::BackendChoice;
use crate::env::gpu::GpuContext;

/// The learner device and a description of it.
pub fn learner_device(choice: &BackendChoice, sim_gpu: Option<&GpuContext>) -> Result<(Device, String)> {
    let cpu = || (Device::flex().autodiff(), format!("cpu (burn flex, {} threads)", rayon::current_num_threads()));
    match choice {
        BackendChoice::Cpu => Ok(cpu()),
        BackendChoice::Gpu(name) => {
            if let Some(ctx) = sim_gpu
                && shares_sim_device(choice, sim_gpu)
            {
                return wgpu_on(ctx);
            }
            let ctx = GpuContext::new(name.as_deref())?;
            wgpu_on(&ctx)
        }
        BackendChoice::Auto => {
            if let Some(ctx) = sim_gpu {
                return wgpu_on(ctx);
            }
            match GpuContext::new(None) {
                Ok(ctx) => wgpu_on(&ctx),
                Err(_) => Ok(cpu()),
            }
        }
    }
}

/// Whether [`learner_device`] puts the learner on the simulator's own wgpu device `sim_gpu`.
pub fn shares_sim_device(choice: &BackendChoice, sim_gpu: Option<&GpuContext>) -> bool {
    match (choice, sim_gpu) {
        (BackendChoice::Gpu(name), Some(ctx)) => name.as_ref().is_none_or(|n| ctx.info.name.to_lowercase().contains(&n.to_lowercase())),
        (BackendChoice::Auto, Some(_)) => true,
        _ => false,
    }
}

/// burn's wgpu runtime on an existing wgpu device.
fn wgpu_on(ctx: &GpuContext) -> Result<(Device, String)> {
    let setup = burn::tensor::wgpu::WgpuSetup {
        instance: ctx.instance.clone(),
        adapter: ctx.adapter.clone(),
        device: ctx.device.clone(),
        queue: ctx.queue.clone(),
        backend: ctx.info.backend,
    };
    let device = Device::wgpu_options()
        .setup(setup)
        .init()
        .map_err(|e| anyhow!("cannot start burn's wgpu runtime on {}: {e}", ctx.describe()))?;
    Ok((device.autodiff(), format!("gpu (burn wgpu, {})", ctx.describe())))
}
