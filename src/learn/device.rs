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
use crate::gpu::context::GpuContext;

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
            match GpuContext::auto() {
                Some(ctx) => wgpu_on(&ctx),
                None => Ok(cpu()),
            }
        }
    }
}

/// As [`learner_device`] without a simulator, also returning the wgpu context of a GPU learner
/// (the benches read its queue's submission count and run device-resident rollouts on it).
pub fn learner_device_and_context(choice: &BackendChoice) -> Result<(Device, String, Option<GpuContext>)> {
    let ctx = match choice {
        BackendChoice::Cpu => None,
        BackendChoice::Gpu(name) => Some(GpuContext::new(name.as_deref())?),
        BackendChoice::Auto => GpuContext::auto(),
    };
    let (device, name) = learner_device(choice, ctx.as_ref())?;
    Ok((device, name, ctx))
}

/// Whether [`learner_device`] puts the learner on the simulator's own wgpu device `sim_gpu`.
pub fn shares_sim_device(choice: &BackendChoice, sim_gpu: Option<&GpuContext>) -> bool {
    match (choice, sim_gpu) {
        (BackendChoice::Gpu(name), Some(ctx)) => name.as_ref().is_none_or(|n| ctx.info.name.to_lowercase().contains(&n.to_lowercase())),
        (BackendChoice::Auto, Some(_)) => true,
        _ => false,
    }
}

/// The wgpu contexts that burn's wgpu devices run on (their non-autodiff devices), so that the
/// learner's own kernels (`fused_adam`) find the queue and device of a tensor's device.
static CONTEXTS: std::sync::Mutex<Vec<(Device, GpuContext)>> = std::sync::Mutex::new(Vec::new());

/// The wgpu context of burn's wgpu `device` (autodiff or not), if [`learner_device`] made it.
pub fn gpu_context_of(device: &Device) -> Option<GpuContext> {
    let inner = device.clone().inner();
    CONTEXTS.lock().unwrap_or_else(std::sync::PoisonError::into_inner).iter().find(|(d, _)| *d == inner).map(|(_, c)| c.clone())
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
    crate::gpu_counts::observe_burn_launches();
    let matmul = crate::learn::kernels::gpu_matmul::configure(ctx.is_software())?;
    let device = Device::wgpu_options()
        .setup(setup)
        .init()
        .map_err(|e| anyhow!("cannot start burn's wgpu runtime on {}: {e}", ctx.describe()))?;
    {
        let mut all = CONTEXTS.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
        let inner = device.clone().inner();
        all.retain(|(d, _)| *d != inner);
        all.push((inner, ctx.clone()));
    }
    Ok((device.autodiff(), format!("gpu (burn wgpu, {}, matmul {})", ctx.describe(), matmul.name())))
}
