//! `GpuEnvBatch`: the env batch on a wgpu device. The WGSL of `shaders/` (common + reset + physics,
//! concatenated) runs one invocation per env; buffers, pipelines and bind groups are made once in
//! `new`, so a step only uploads targets, dispatches and (on request) copies results back.

use std::sync::mpsc;

use anyhow::{Context, Result, anyhow, bail, ensure};
use bytemuck::Pod;
use wgpu::util::DeviceExt;

use super::gpu_layout::*;
use super::{EnvBatch, EnvSpec, SimModel};

pub const SHADER_COMMON: &str = include_str!("../../shaders/common.wgsl");
pub const SHADER_RESET: &str = include_str!("../../shaders/reset.wgsl");
pub const SHADER_PHYSICS: &str = include_str!("../../shaders/physics.wgsl");
pub const SHADER_TASK: &str = include_str!("../../shaders/task.wgsl");
pub const SHADER_REFERENCE: &str = include_str!("../../shaders/reference.wgsl");
pub const SHADER_IK: &str = include_str!("../../shaders/ik.wgsl");
/// Invocations per workgroup (keep in sync with `WORKGROUP_SIZE` in common.wgsl).
pub const WORKGROUP_SIZE: u32 = 64;

/// The WGSL module the simulator runs: common, reset and physics concatenated.
pub fn shader_source() -> String {
    [SHADER_COMMON, SHADER_RESET, SHADER_PHYSICS].join("\n")
}

/// The WGSL module of the task layer: the simulator's module with the reference layer, the
/// fingertip IK and task.wgsl appended (task.wgsl reuses the physics' hand kinematics).
pub fn task_shader_source() -> String {
    [SHADER_COMMON, SHADER_RESET, SHADER_PHYSICS, SHADER_REFERENCE, SHADER_IK, SHADER_TASK].join("\n")
}

/// A wgpu instance, adapter, device and queue.
pub struct GpuContext {
    pub instance: wgpu::Instance,
    pub adapter: wgpu::Adapter,
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    pub info: wgpu::AdapterInfo,
}

fn is_software(info: &wgpu::AdapterInfo) -> bool {
    info.device_type == wgpu::DeviceType::Cpu || info.name.to_lowercase().contains("llvmpipe")
}

impl GpuContext {
    /// Picks an adapter: `name` = the first adapter whose name contains it (case-insensitive; Vulkan,
    /// Metal and DX12 before OpenGL); `None` = the first hardware adapter — a software adapter such as
    /// lavapipe is only used when asked for by name.
    pub fn new(name: Option<&str>) -> Result<GpuContext> {
        let mut desc = wgpu::InstanceDescriptor::new_without_display_handle_from_env();
        if std::env::var_os("WGPU_BACKEND").is_none() {
            // Vulkan, Metal, DX12: probing OpenGL (EGL) prints errors on headless machines, and its
            // adapters lack what the shaders need; WGPU_BACKEND=gl still selects it
            desc.backends = wgpu::Backends::PRIMARY;
        }
        let instance = wgpu::Instance::new(desc);
        let mut adapters = pollster::block_on(instance.enumerate_adapters(wgpu::Backends::all()));
        // prefer the native APIs over OpenGL
        adapters.sort_by_key(|a| (a.get_info().backend == wgpu::Backend::Gl) as u8);
        let listed: Vec<String> = adapters.iter().map(|a| format!("{} ({:?})", a.get_info().name, a.get_info().backend)).collect();
        let chosen = match name {
            Some(n) => {
                let n = n.to_lowercase();
                adapters.into_iter().find(|a| a.get_info().name.to_lowercase().contains(&n)).ok_or_else(|| {
                    anyhow!("no wgpu adapter named like '{n}' (adapters: {})", if listed.is_empty() { "none".into() } else { listed.join(", ") })
                })?
            }
            None => adapters.into_iter().find(|a| !is_software(&a.get_info())).ok_or_else(|| {
                anyhow!(
                    "no hardware GPU adapter (adapters: {}); name a software one with backend = \"gpu:llvmpipe\"",
                    if listed.is_empty() { "none".into() } else { listed.join(", ") }
                )
            })?,
        };
        let info = chosen.get_info();
        // as burn/cubecl expect, so the learner can later share this device
        let desc = wgpu::DeviceDescriptor {
            label: Some("dextrain"),
            required_features: chosen.features().difference(wgpu::Features::MAPPABLE_PRIMARY_BUFFERS),
            required_limits: chosen.limits(),
            ..Default::default()
        };
        let (device, queue) = pollster::block_on(chosen.request_device(&desc))
            .with_context(|| format!("cannot open a device on adapter {}", info.name))?;
        Ok(GpuContext { instance, adapter: chosen, device, queue, info })
    }

    pub fn describe(&self) -> String {
        format!("{} ({:?}, {:?})", self.info.name, self.info.backend, self.info.device_type)
    }
}

/// The env batch on a GPU. The task layer (`task_gpu`) binds its buffers and dispatches its
/// pipelines inside its own command encoders.
pub struct GpuEnvBatch {
    pub(crate) ctx: GpuContext,
    pub(crate) model: SimModel,
    /// Binding 0 (`Globals`) and 1 (`JointDesc`s).
    pub(crate) globals: wgpu::Buffer,
    pub(crate) joints: wgpu::Buffer,
    pub(crate) states: wgpu::Buffer,
    pub(crate) params: wgpu::Buffer,
    pub(crate) targets: wgpu::Buffer,
    pub(crate) stats: wgpu::Buffer,
    pub(crate) reset_mask: wgpu::Buffer,
    readback: wgpu::Buffer,
    pub(crate) step_pipeline: wgpu::ComputePipeline,
    pub(crate) reset_pipeline: wgpu::ComputePipeline,
    pub(crate) step_group: wgpu::BindGroup,
    pub(crate) reset_group: wgpu::BindGroup,
    mask_host: Vec<u32>,
}

pub(crate) fn entry(binding: u32, buffer: &wgpu::Buffer) -> wgpu::BindGroupEntry<'_> {
    wgpu::BindGroupEntry { binding, resource: buffer.as_entire_binding() }
}

pub(crate) fn storage<T: Pod>(device: &wgpu::Device, label: &str, data: &[T], extra: wgpu::BufferUsages) -> wgpu::Buffer {
    // zero-length bindings are invalid: pad with one zeroed element
    let bytes: Vec<u8> = if data.is_empty() { vec![0u8; std::mem::size_of::<T>().max(16)] } else { bytemuck::cast_slice(data).to_vec() };
    device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some(label),
        contents: &bytes,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::COPY_SRC | extra,
    })
}

impl GpuEnvBatch {
    /// Uploads the model, builds the pipelines and starts episode 0 of every env.
    pub fn new(ctx: GpuContext, model: SimModel) -> Result<GpuEnvBatch> {
        let n = model.spec.num_envs;
        let device = &ctx.device;
        let limits = device.limits();
        let state_bytes = (n * std::mem::size_of::<EnvState>()) as u64;
        if state_bytes > limits.max_storage_buffer_binding_size as u64 || state_bytes > limits.max_buffer_size {
            bail!(
                "sim.num_envs = {n} needs {} MiB of env state, but adapter {} allows {} MiB per storage binding",
                state_bytes >> 20,
                ctx.info.name,
                (limits.max_storage_buffer_binding_size as u64).min(limits.max_buffer_size) >> 20
            );
        }
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("dextrain physics"),
            source: wgpu::ShaderSource::Wgsl(shader_source().into()),
        });
        let globals = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("globals"),
            contents: bytemuck::bytes_of(&model.globals),
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        });
        let none = wgpu::BufferUsages::empty();
        let joints = storage(device, "joints", &model.joints, none);
        let colliders = storage(device, "colliders", &model.colliders, none);
        let states = storage(device, "states", &vec![EnvState::default(); n], none);
        let params = storage(device, "params", &vec![<EnvParams as bytemuck::Zeroable>::zeroed(); n], none);
        let targets = storage(device, "targets", &vec![Targets::default(); n], none);
        let stats = storage(device, "stats", &vec![<StepStats as bytemuck::Zeroable>::zeroed(); n], none);
        let reset_mask = storage(device, "reset_mask", &vec![0u32; n], none);
        let readback = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback"),
            size: state_bytes.max(16),
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let make = |entry: &str| {
            device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(entry),
                layout: None,
                module: &module,
                entry_point: Some(entry),
                compilation_options: Default::default(),
                cache: None,
            })
        };
        let step_pipeline = make("step_main");
        let reset_pipeline = make("reset_main");
        let step_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("step"),
            layout: &step_pipeline.get_bind_group_layout(0),
            entries: &[
                entry(0, &globals),
                entry(1, &joints),
                entry(2, &colliders),
                entry(4, &states),
                entry(5, &params),
                entry(6, &targets),
                entry(7, &stats),
            ],
        });
        let reset_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("reset"),
            layout: &reset_pipeline.get_bind_group_layout(0),
            entries: &[entry(0, &globals), entry(1, &joints), entry(4, &states), entry(5, &params), entry(8, &reset_mask)],
        });
        let mut b = GpuEnvBatch {
            ctx,
            model,
            globals,
            joints,
            states,
            params,
            targets,
            stats,
            reset_mask,
            readback,
            step_pipeline,
            reset_pipeline,
            step_group,
            reset_group,
            mask_host: vec![0; n],
        };
        b.reset_all()?;
        Ok(b)
    }

    pub fn context(&self) -> &GpuContext {
        &self.ctx
    }

    /// Workgroups of a dispatch over all envs (x, y: 2-D past 65535 workgroups).
    pub(crate) fn workgroups(&self) -> (u32, u32) {
        let wg = (self.model.spec.num_envs as u32).div_ceil(WORKGROUP_SIZE);
        let x = wg.min(65535);
        (x, wg.div_ceil(x))
    }

    fn dispatch(&self, pipeline: &wgpu::ComputePipeline, group: &wgpu::BindGroup) {
        let (x, y) = self.workgroups();
        let mut enc = self.ctx.device.create_command_encoder(&Default::default());
        {
            let mut pass = enc.begin_compute_pass(&Default::default());
            pass.set_pipeline(pipeline);
            pass.set_bind_group(0, group, &[]);
            pass.dispatch_workgroups(x, y, 1);
        }
        self.ctx.queue.submit([enc.finish()]);
    }

    fn run_reset(&mut self) -> Result<()> {
        self.ctx.queue.write_buffer(&self.reset_mask, 0, bytemuck::cast_slice(&self.mask_host));
        self.dispatch(&self.reset_pipeline, &self.reset_group);
        Ok(())
    }

    /// Overwrites the parameters (checkpoint restore).
    pub fn set_params(&mut self, params: &[EnvParams]) -> Result<()> {
        ensure!(params.len() == self.model.spec.num_envs, "{} parameter sets for {} envs", params.len(), self.model.spec.num_envs);
        self.ctx.queue.write_buffer(&self.params, 0, bytemuck::cast_slice(params));
        Ok(())
    }

    /// Copies `count` elements of `T` (at most the size of the env states) from `src` back to the host.
    pub(crate) fn read<T: Pod>(&self, src: &wgpu::Buffer, count: usize) -> Result<Vec<T>> {
        let size = (count * std::mem::size_of::<T>()) as u64;
        let mut enc = self.ctx.device.create_command_encoder(&Default::default());
        enc.copy_buffer_to_buffer(src, 0, &self.readback, 0, size);
        self.ctx.queue.submit([enc.finish()]);
        let slice = self.readback.slice(0..size);
        let (tx, rx) = mpsc::channel();
        slice.map_async(wgpu::MapMode::Read, move |r| {
            let _ = tx.send(r);
        });
        self.ctx.device.poll(wgpu::PollType::wait_indefinitely()).map_err(|e| anyhow!("GPU poll failed: {e}"))?;
        rx.recv().context("GPU readback was dropped")?.map_err(|e| anyhow!("GPU readback failed: {e}"))?;
        let out = {
            let view = slice.get_mapped_range().map_err(|e| anyhow!("GPU readback failed: {e:?}"))?;
            bytemuck::pod_collect_to_vec(&view)
        };
        self.readback.unmap();
        Ok(out)
    }
}

impl EnvBatch for GpuEnvBatch {
    fn spec(&self) -> &EnvSpec {
        &self.model.spec
    }

    fn backend_name(&self) -> String {
        format!("gpu ({})", self.ctx.describe())
    }

    fn reset_all(&mut self) -> Result<()> {
        self.mask_host.fill(2);
        self.run_reset()
    }

    fn reset(&mut self, mask: &[bool]) -> Result<()> {
        ensure!(mask.len() == self.mask_host.len(), "reset mask has {} entries for {} envs", mask.len(), self.mask_host.len());
        for (m, &b) in self.mask_host.iter_mut().zip(mask) {
            *m = b as u32;
        }
        self.run_reset()
    }

    fn step(&mut self, targets: &[Targets]) -> Result<()> {
        ensure!(targets.len() == self.model.spec.num_envs, "{} targets for {} envs", targets.len(), self.model.spec.num_envs);
        self.ctx.queue.write_buffer(&self.targets, 0, bytemuck::cast_slice(targets));
        self.dispatch(&self.step_pipeline, &self.step_group);
        Ok(())
    }

    fn states(&mut self) -> Result<Vec<EnvState>> {
        self.read(&self.states, self.model.spec.num_envs)
    }

    fn set_states(&mut self, states: &[EnvState]) -> Result<()> {
        ensure!(states.len() == self.model.spec.num_envs, "{} states for {} envs", states.len(), self.model.spec.num_envs);
        self.ctx.queue.write_buffer(&self.states, 0, bytemuck::cast_slice(states));
        Ok(())
    }

    fn params(&mut self) -> Result<Vec<EnvParams>> {
        self.read(&self.params, self.model.spec.num_envs)
    }

    fn stats(&mut self) -> Result<Vec<StepStats>> {
        self.read(&self.stats, self.model.spec.num_envs)
    }
}

/// One binding of a [`run_kernel`] dispatch (its bytes are uploaded as they are).
pub enum KernelBinding<'a> {
    Uniform(&'a [u8]),
    /// `var<storage, read>`.
    Storage(&'a [u8]),
    /// `var<storage, read_write>`: read back after the dispatch.
    StorageRw(&'a [u8]),
}

/// Runs entry point `entry_point` of the WGSL module `source` once over `invocations` invocations
/// (workgroups of [`WORKGROUP_SIZE`] along x; the kernel must ignore ids past the end), with
/// `bindings` in group 0 (exactly those the entry point uses: the layout is derived from the shader).
/// Returns the contents of every `StorageRw` binding after the dispatch, in the order given.
/// For tests that compare a shader function with its CPU twin.
pub fn run_kernel(ctx: &GpuContext, source: &str, entry_point: &str, bindings: &[(u32, KernelBinding)], invocations: u32) -> Result<Vec<Vec<u8>>> {
    let device = &ctx.device;
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor { label: Some(entry_point), source: wgpu::ShaderSource::Wgsl(source.into()) });
    let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some(entry_point),
        layout: None,
        module: &module,
        entry_point: Some(entry_point),
        compilation_options: Default::default(),
        cache: None,
    });
    let buffers: Vec<wgpu::Buffer> = bindings
        .iter()
        .map(|(b, k)| {
            let (bytes, usage) = match k {
                KernelBinding::Uniform(d) => (*d, wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST),
                KernelBinding::Storage(d) | KernelBinding::StorageRw(d) => (*d, wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC),
            };
            // zero-length bindings are invalid: pad to 16 bytes
            let mut contents = bytes.to_vec();
            contents.resize(contents.len().max(16), 0);
            device.create_buffer_init(&wgpu::util::BufferInitDescriptor { label: Some(&format!("binding {b}")), contents: &contents, usage })
        })
        .collect();
    let entries: Vec<wgpu::BindGroupEntry> = bindings.iter().zip(&buffers).map(|((b, _), buf)| entry(*b, buf)).collect();
    let group = device.create_bind_group(&wgpu::BindGroupDescriptor { label: Some(entry_point), layout: &pipeline.get_bind_group_layout(0), entries: &entries });
    let rw: Vec<usize> = bindings.iter().enumerate().filter(|(_, (_, k))| matches!(k, KernelBinding::StorageRw(_))).map(|(i, _)| i).collect();
    let readbacks: Vec<wgpu::Buffer> = rw
        .iter()
        .map(|&i| device.create_buffer(&wgpu::BufferDescriptor { label: Some("kernel readback"), size: buffers[i].size(), usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST, mapped_at_creation: false }))
        .collect();
    let mut enc = device.create_command_encoder(&Default::default());
    {
        let mut pass = enc.begin_compute_pass(&Default::default());
        pass.set_pipeline(&pipeline);
        pass.set_bind_group(0, &group, &[]);
        pass.dispatch_workgroups(invocations.div_ceil(WORKGROUP_SIZE).max(1), 1, 1);
    }
    for (&i, rb) in rw.iter().zip(&readbacks) {
        enc.copy_buffer_to_buffer(&buffers[i], 0, rb, 0, buffers[i].size());
    }
    ctx.queue.submit([enc.finish()]);
    let mut out = Vec::new();
    for (&i, rb) in rw.iter().zip(&readbacks) {
        let slice = rb.slice(..);
        let (tx, rx) = mpsc::channel();
        slice.map_async(wgpu::MapMode::Read, move |r| {
            let _ = tx.send(r);
        });
        device.poll(wgpu::PollType::wait_indefinitely()).map_err(|e| anyhow!("GPU poll failed: {e}"))?;
        rx.recv().context("GPU readback was dropped")?.map_err(|e| anyhow!("GPU readback failed: {e}"))?;
        let bytes = {
            let view = slice.get_mapped_range().map_err(|e| anyhow!("GPU readback failed: {e:?}"))?;
            let len = match &bindings[i].1 {
                KernelBinding::StorageRw(d) => d.len(),
                _ => 0,
            };
            view[..len].to_vec()
        };
        rb.unmap();
        out.push(bytes);
    }
    Ok(out)
}
