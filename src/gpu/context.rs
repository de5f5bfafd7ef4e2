//! `GpuContext`: the wgpu adapter, device and queue, and the error handling of every wgpu call:
//! error scopes, the uncaptured-error record, buffer-size checks, the pipeline, bind-group and
//! readback helpers; `run_kernel` runs one shader entry point on given bindings (the tests' and
//! tools' way to check a kernel).
//!
//! # Errors
//!
//! wgpu reports most errors to the device, not as return values, and panics on those nobody
//! catches. Here every creation, upload, submission and readback runs inside out-of-memory,
//! validation and internal error scopes ([`GpuContext::scoped`]), so its error comes back as an
//! `Err` naming the shader, entry point or buffer. Errors outside any scope are recorded by the
//! device's uncaptured-error handler (and the device-lost callback) and returned by the next
//! readback, the synchronisation point ([`GpuContext::submit_and_read`]). Buffer sizes are checked
//! against the device's limits before a buffer is made ([`GpuContext::check_buffer_size`]).

use std::sync::{Arc, Mutex, PoisonError, mpsc};

use anyhow::{Context, Result, anyhow, bail, ensure};
use bytemuck::Pod;
use wgpu::util::DeviceExt;

use std::collections::HashMap;

use super::bindings::{Binding, BindingSpace, EntryBindings};
use super::profile::GpuProfiler;
use super::shaders::WORKGROUP_SIZE;
use crate::gpu_counts::{self, Event};

/// A wgpu instance, adapter, device and queue, with the record of the device's uncaptured errors
/// (a clone shares the device and the record).
#[derive(Clone)]
pub struct GpuContext {
    /// The wgpu instance the adapter came from.
    pub instance: wgpu::Instance,
    /// The chosen adapter.
    pub adapter: wgpu::Adapter,
    /// The device opened on it (the adapter's features and the limits asked for).
    pub device: wgpu::Device,
    /// The device's queue.
    pub queue: wgpu::Queue,
    /// The adapter's name, backend and type.
    pub info: wgpu::AdapterInfo,
    /// One line per error that reached the uncaptured-error handler or the device-lost callback
    /// since the last [`GpuContext::check_uncaptured`].
    uncaptured: Arc<Mutex<Vec<String>>>,
    /// The device-time profile (`--gpu-profile` on an adapter with timestamp queries; else None).
    profiler: Option<Arc<Mutex<GpuProfiler>>>,
    /// Each compute pipeline's entry point, for the profile's names (filled while profiling only).
    pipeline_names: Arc<Mutex<HashMap<wgpu::ComputePipeline, String>>>,
}

/// One dispatch of a compute pass: the pipeline, its bind group 0 and its workgroups (x, y).
pub type Pass<'a> = (&'a wgpu::ComputePipeline, &'a wgpu::BindGroup, (u32, u32));

/// One dispatch into `pass`: its pipeline, its bind group 0, its workgroups (x, y).
fn record(pass: &mut wgpu::ComputePass<'_>, &(pipeline, group, (x, y)): &Pass<'_>) {
    pass.set_pipeline(pipeline);
    pass.set_bind_group(0, group, &[]);
    pass.dispatch_workgroups(x, y, 1);
}

/// What a buffer is bound as, which decides the device limits on its size.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BufferRole {
    /// `var<uniform>`: `max_uniform_buffer_binding_size` and `max_buffer_size`.
    Uniform,
    /// `var<storage>`: `max_storage_buffer_binding_size` and `max_buffer_size`.
    Storage,
    /// A host-mappable copy target of a readback: `max_buffer_size`.
    Staging,
}

impl From<BindingSpace> for BufferRole {
    fn from(space: BindingSpace) -> BufferRole {
        match space {
            BindingSpace::Uniform => BufferRole::Uniform,
            BindingSpace::StorageRead | BindingSpace::StorageReadWrite => BufferRole::Storage,
        }
    }
}

/// One copy of a readback: the first `bytes` bytes of `src` into the start of `staging`
/// (a `MAP_READ | COPY_DST` buffer), named `name` in errors.
pub struct ReadbackCopy<'a> {
    /// The buffer read (named in errors).
    pub name: &'a str,
    /// The device buffer copied from.
    pub src: &'a wgpu::Buffer,
    /// The host-mappable buffer copied to.
    pub staging: &'a wgpu::Buffer,
    /// Bytes copied, from offset 0 (a multiple of 4).
    pub bytes: u64,
}

fn is_software(info: &wgpu::AdapterInfo) -> bool {
    info.device_type == wgpu::DeviceType::Cpu || info.name.to_lowercase().contains("llvmpipe")
}

/// A wgpu error on one line: its kind and description.
fn wgpu_error_line(e: &wgpu::Error) -> String {
    match e {
        wgpu::Error::OutOfMemory { source } => format!("out of memory ({})", crate::text::one_line(&source.to_string())),
        wgpu::Error::Validation { description, .. } => format!("validation error: {}", crate::text::one_line(description)),
        wgpu::Error::Internal { description, .. } => format!("internal error: {}", crate::text::one_line(description)),
    }
}

/// Bytes in KiB, MiB or GiB, for messages.
fn human(bytes: u64) -> String {
    let b = bytes as f64;
    match bytes {
        0..0x10_0000 => format!("{:.1} KiB", b / 1024.0),
        0x10_0000..0x4000_0000 => format!("{:.1} MiB", b / (1u64 << 20) as f64),
        _ => format!("{:.1} GiB", b / (1u64 << 30) as f64),
    }
}

/// Among `adapters` (in preference order), those that `accept` of the first accepted one's API (a
/// GPU is listed once per API); the process takes the (k mod count)-th, k its rank among its
/// node's MPI ranks (`crate::dist::local_rank`, 0 without MPI): each rank of a node on a GPU of its
/// own, as far as there are GPUs. None when none is accepted.
fn node_rank_pick(adapters: Vec<wgpu::Adapter>, accept: impl Fn(&wgpu::AdapterInfo) -> bool) -> Option<wgpu::Adapter> {
    let api = adapters.iter().find(|a| accept(&a.get_info())).map(|a| a.get_info().backend)?;
    let mut accepted: Vec<wgpu::Adapter> = adapters.into_iter().filter(|a| a.get_info().backend == api && accept(&a.get_info())).collect();
    let k = crate::dist::local_rank() % accepted.len();
    Some(accepted.swap_remove(k))
}

impl GpuContext {
    /// Picks an adapter: `name` = an adapter whose name contains it (case-insensitive; Vulkan, Metal
    /// and DX12 before OpenGL); `None` = a hardware adapter — a software adapter such as lavapipe is
    /// only used when asked for by name. With one such adapter (per API) it is that one; with
    /// several, rank k of an MPI job's ranks on this node takes the (k mod count)-th
    /// ([`node_rank_pick`]), the first without MPI. The device gets all of the adapter's limits.
    pub fn new(name: Option<&str>) -> Result<GpuContext> {
        GpuContext::with_limits(name, |adapter_limits| adapter_limits)
    }

    /// `backend = "auto"`'s GPU: the first hardware adapter, or None. The first time a process finds
    /// none it says so on one line (why, and that the CPU runs the work) and remembers it: later
    /// calls (the learner after the envs, each of a distillation's evaluations) neither probe
    /// again nor repeat the line.
    pub fn auto() -> Option<GpuContext> {
        static NONE_FOUND: std::sync::OnceLock<()> = std::sync::OnceLock::new();
        if NONE_FOUND.get().is_some() {
            return None;
        }
        match GpuContext::new(None) {
            Ok(ctx) => Some(ctx),
            Err(e) => {
                NONE_FOUND.get_or_init(|| crate::console::warn(&format!("dextrain: {e:#}; the CPU runs what backend = \"auto\" would have put on a GPU")));
                None
            }
        }
    }

    /// [`GpuContext::new`], with the device's limits chosen by `limits` from the adapter's (lower
    /// ones make a smaller device: tests of the limit checks, or a budget on a shared GPU).
    pub fn with_limits(name: Option<&str>, limits: impl FnOnce(wgpu::Limits) -> wgpu::Limits) -> Result<GpuContext> {
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
                node_rank_pick(adapters, |info| info.name.to_lowercase().contains(&n)).ok_or_else(|| {
                    anyhow!("no wgpu adapter named like '{n}' (adapters: {})", if listed.is_empty() { "none".into() } else { listed.join(", ") })
                })?
            }
            None => node_rank_pick(adapters, |info| !is_software(info)).ok_or_else(|| {
                // the loader's and the drivers' story only where something in it failed: on a
                // machine whose drivers all load (Mesa's in a VM) there is simply no GPU
                let why = super::vulkan_probe::diagnosis();
                anyhow!(
                    "no hardware GPU adapter (adapters: {}); name a software one with backend = \"gpu:llvmpipe\"{}",
                    if listed.is_empty() { "none".into() } else { listed.join(", ") },
                    if why.failed { format!(". {}", why.line) } else { String::new() }
                )
            })?,
        };
        let info = chosen.get_info();
        // as burn/cubecl open their own devices (cubecl-wgpu's `try_request_device`), so the learner
        // can later share this device: every adapter feature but mappable primary buffers, with
        // wgpu's experimental features allowed. A hardware adapter lists experimental ones (an
        // H100's Vulkan driver: mesh shaders, cooperative matrices, ray-tracing pipelines), and
        // asking for them without the opt-in fails the device request; cubecl uses the cooperative
        // matrices for its matmuls. Our shaders use none of them.
        let desc = wgpu::DeviceDescriptor {
            label: Some("dextrain"),
            required_features: chosen.features().difference(wgpu::Features::MAPPABLE_PRIMARY_BUFFERS),
            required_limits: limits(chosen.limits()),
            // SAFETY: the opt-in that cubecl-wgpu also gives; what it guards (experimental shader
            // stages and passthrough shaders) is used only by burn's kernels, as on a device of its own
            experimental_features: unsafe { wgpu::ExperimentalFeatures::enabled() },
            ..Default::default()
        };
        let (device, queue) = pollster::block_on(chosen.request_device(&desc))
            .with_context(|| format!("cannot open a device on adapter {}", info.name))?;
        // record the errors that no scope catches instead of panicking (wgpu's default); the next
        // readback returns them. burn's wgpu runtime installs its own handler when it shares the
        // device; our calls still return their errors through their scopes.
        let uncaptured: Arc<Mutex<Vec<String>>> = Arc::default();
        let record = uncaptured.clone();
        device.on_uncaptured_error(Arc::new(move |e: wgpu::Error| {
            record.lock().unwrap_or_else(PoisonError::into_inner).push(wgpu_error_line(&e));
        }));
        let record = uncaptured.clone();
        device.set_device_lost_callback(move |reason, message| {
            record.lock().unwrap_or_else(PoisonError::into_inner).push(format!("device lost ({reason:?}): {}", crate::text::one_line(&message)));
        });
        let profiler = if super::profile::requested() {
            let p = GpuProfiler::new(&device, &queue);
            if p.is_none() {
                crate::console::status(&format!("--gpu-profile: adapter {} writes no timestamps in compute passes and between commands; no profile", info.name));
            }
            p.map(|p| Arc::new(Mutex::new(p)))
        } else {
            None
        };
        Ok(GpuContext { instance, adapter: chosen, device, queue, info, uncaptured, profiler, pipeline_names: Arc::default() })
    }

    /// Whether the adapter is a software rasteriser (lavapipe / llvmpipe) rather than a GPU.
    pub fn is_software(&self) -> bool {
        is_software(&self.info)
    }

    /// "ADAPTER (API, TYPE)".
    pub fn describe(&self) -> String {
        format!("{} ({:?}, {:?})", self.info.name, self.info.backend, self.info.device_type)
    }

    /// Runs `f` (wgpu calls, which report their errors to the device rather than return them) inside
    /// out-of-memory, validation and internal error scopes; an error they caught comes back as an
    /// `Err` of one line that starts with `what()` (the shader, entry point or buffer concerned).
    pub fn scoped<T>(&self, what: impl FnOnce() -> String, f: impl FnOnce() -> T) -> Result<T> {
        let oom = self.device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let validation = self.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let internal = self.device.push_error_scope(wgpu::ErrorFilter::Internal);
        let out = f();
        // scopes pop in the reverse order of their pushes
        let caught = [internal.pop(), validation.pop(), oom.pop()].map(pollster::block_on);
        match caught.into_iter().flatten().next() {
            Some(e) => bail!("{} (adapter {}): wgpu {}", what(), self.info.name, wgpu_error_line(&e)),
            None => Ok(out),
        }
    }

    /// Fails with the errors that reached the uncaptured-error handler or the device-lost callback
    /// since the last check (and forgets them); `what` is the call that found them.
    pub fn check_uncaptured(&self, what: &str) -> Result<()> {
        let errors = std::mem::take(&mut *self.uncaptured.lock().unwrap_or_else(PoisonError::into_inner));
        ensure!(errors.is_empty(), "{what}: GPU error on adapter {} since the last check: {}", self.info.name, errors.join("; "));
        Ok(())
    }

    /// Fails (one line naming the buffer, its bytes, the limit and the adapter) when a buffer
    /// `name` of `bytes` bytes, bound as `role`, exceeds the device's limits.
    pub fn check_buffer_size(&self, name: &str, bytes: u64, role: BufferRole) -> Result<()> {
        let l = self.device.limits();
        let binding = match role {
            BufferRole::Uniform => Some((l.max_uniform_buffer_binding_size, "max_uniform_buffer_binding_size")),
            BufferRole::Storage => Some((l.max_storage_buffer_binding_size, "max_storage_buffer_binding_size")),
            BufferRole::Staging => None,
        };
        // the tighter of the binding limit and the buffer limit
        let (limit, key) = binding.into_iter().chain([(l.max_buffer_size, "max_buffer_size")]).min_by_key(|(v, _)| *v).unwrap_or((l.max_buffer_size, "max_buffer_size"));
        ensure!(
            bytes <= limit,
            "GPU buffer `{name}` needs {bytes} bytes ({}), but adapter {} allows {limit} bytes ({}, `{key}`)",
            human(bytes),
            self.info.name,
            human(limit)
        );
        Ok(())
    }

    /// Creates buffer `name` holding `contents` (padded to 16 bytes at least: zero-length bindings
    /// are invalid), bound as `role`, with `usage`: the size is checked first, and wgpu's errors
    /// (out of memory included) come back naming the buffer and its bytes.
    pub fn create_buffer_with(&self, name: &str, contents: &[u8], role: BufferRole, usage: wgpu::BufferUsages) -> Result<wgpu::Buffer> {
        let mut padded;
        let contents = if contents.len() < 16 {
            padded = contents.to_vec();
            padded.resize(16, 0);
            &padded[..]
        } else {
            contents
        };
        self.check_buffer_size(name, contents.len() as u64, role)?;
        crate::host_traffic::add(contents.len() as u64);
        self.scoped(
            || format!("creating GPU buffer `{name}` of {} bytes", contents.len()),
            || self.device.create_buffer_init(&wgpu::util::BufferInitDescriptor { label: Some(name), contents, usage }),
        )
    }

    /// Creates the buffer of `binding` (labelled with its WGSL name) holding `data`, with the
    /// usages of its address space plus `extra`; an empty `data` becomes one zeroed element.
    pub fn create_binding_buffer<T: Pod>(&self, binding: Binding, data: &[T], extra: wgpu::BufferUsages) -> Result<wgpu::Buffer> {
        let zeroed;
        let bytes: &[u8] = if data.is_empty() {
            zeroed = vec![0u8; std::mem::size_of::<T>()];
            &zeroed
        } else {
            bytemuck::cast_slice(data)
        };
        self.create_buffer_with(binding.name, bytes, binding.space.into(), binding.space.usage() | extra)
    }

    /// Creates the buffer of `binding` of `bytes` bytes (at least 16) that the device alone writes
    /// and reads (a kernel's scratch memory: nothing uploaded; wgpu hands it over zeroed).
    pub fn create_scratch_buffer(&self, binding: Binding, bytes: u64) -> Result<wgpu::Buffer> {
        self.create_empty_buffer(binding.name, "GPU buffer", bytes, binding.space.into(), binding.space.usage())
    }

    /// Creates the host-mappable staging buffer `name` of `bytes` bytes that readbacks copy into.
    pub fn create_staging_buffer(&self, name: &str, bytes: u64) -> Result<wgpu::Buffer> {
        self.create_empty_buffer(name, "GPU staging buffer", bytes, BufferRole::Staging, wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST)
    }

    /// Creates buffer `name` (a `kind`, as errors call it) of `bytes` bytes, at least 16 and a
    /// multiple of the copy alignment, with nothing written to it: the size checked for `role`
    /// first, wgpu's errors named.
    fn create_empty_buffer(&self, name: &str, kind: &str, bytes: u64, role: BufferRole, usage: wgpu::BufferUsages) -> Result<wgpu::Buffer> {
        let size = bytes.max(16).next_multiple_of(wgpu::COPY_BUFFER_ALIGNMENT);
        self.check_buffer_size(name, size, role)?;
        self.scoped(
            || format!("creating {kind} `{name}` of {size} bytes"),
            || self.device.create_buffer(&wgpu::BufferDescriptor { label: Some(name), size, usage, mapped_at_creation: false }),
        )
    }

    /// Compiles `source` as the shader module `shader` and makes one compute pipeline of each of
    /// `entry_points`, in order (layouts derived from the shader). A module that does not compile,
    /// or an entry point that is missing or that the driver rejects, is an error naming the shader
    /// and the entry point.
    pub fn compute_pipelines<const N: usize>(&self, shader: &str, source: &str, entry_points: [&str; N]) -> Result<[wgpu::ComputePipeline; N]> {
        let module = self.scoped(
            || format!("compiling shader `{shader}` (entry points {})", entry_points.join(", ")),
            || self.device.create_shader_module(wgpu::ShaderModuleDescriptor { label: Some(shader), source: wgpu::ShaderSource::Wgsl(source.into()) }),
        )?;
        let mut pipelines = Vec::with_capacity(N);
        for entry_point in entry_points {
            pipelines.push(self.scoped(
                || format!("creating the compute pipeline of entry point `{entry_point}` of shader `{shader}`"),
                || {
                    self.device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                        label: Some(entry_point),
                        layout: None,
                        module: &module,
                        entry_point: Some(entry_point),
                        compilation_options: Default::default(),
                        cache: None,
                    })
                },
            )?);
        }
        if self.profiler.is_some() {
            let mut names = self.pipeline_names.lock().unwrap_or_else(PoisonError::into_inner);
            for (p, e) in pipelines.iter().zip(entry_points) {
                names.insert(p.clone(), e.to_string());
            }
        }
        pipelines.try_into().map_err(|p: Vec<_>| anyhow!("shader `{shader}`: {} pipelines for {N} entry points", p.len()))
    }

    /// The bind group of entry point `uses` on `pipeline`'s derived layout: for each binding the
    /// entry point uses, the buffer that `buffers` (the module's buffers, by binding) gives for it.
    pub fn bind_group(&self, pipeline: &wgpu::ComputePipeline, uses: &EntryBindings, buffers: &[(Binding, &wgpu::Buffer)]) -> Result<wgpu::BindGroup> {
        let whole: Vec<(Binding, (&wgpu::Buffer, u64, u64))> = buffers.iter().map(|&(b, buffer)| (b, (buffer, 0, buffer.size()))).collect();
        self.bind_group_slices(pipeline, uses, &whole)
    }

    /// As [`GpuContext::bind_group`], each binding a slice `(buffer, offset, bytes)` (a burn tensor's
    /// memory in cubecl's buffer, or a slot of a buffer of ours; offsets aligned to the adapter's
    /// binding-offset alignment, sizes rounded up to 4 bytes).
    pub fn bind_group_slices(&self, pipeline: &wgpu::ComputePipeline, uses: &EntryBindings, slices: &[(Binding, (&wgpu::Buffer, u64, u64))]) -> Result<wgpu::BindGroup> {
        let mut entries = Vec::with_capacity(uses.bindings.len());
        for b in uses.bindings {
            let (_, (buffer, offset, size)) = slices
                .iter()
                .find(|(have, _)| have == b)
                .ok_or_else(|| anyhow!("bind group of entry point `{}`: no buffer for binding {} `{}`", uses.entry_point, b.index, b.name))?;
            let size = std::num::NonZeroU64::new(size.next_multiple_of(4)).ok_or_else(|| anyhow!("bind group of entry point `{}`: binding `{}` is empty", uses.entry_point, b.name))?;
            entries.push(wgpu::BindGroupEntry { binding: b.index, resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding { buffer, offset: *offset, size: Some(size) }) });
        }
        self.scoped(
            || format!("creating the bind group of entry point `{}`", uses.entry_point),
            || {
                self.device.create_bind_group(&wgpu::BindGroupDescriptor {
                    label: Some(uses.entry_point),
                    layout: &pipeline.get_bind_group_layout(0),
                    entries: &entries,
                })
            },
        )
    }

    /// Writes `data` to the start of `buffer` (named `name` in errors) through the queue.
    pub fn upload(&self, name: &str, buffer: &wgpu::Buffer, data: &[u8]) -> Result<()> {
        self.upload_at(name, buffer, 0, data)
    }

    /// Writes `data` at byte `offset` of `buffer` (named `name` in errors) through the queue.
    pub fn upload_at(&self, name: &str, buffer: &wgpu::Buffer, offset: u64, data: &[u8]) -> Result<()> {
        ensure!(offset + data.len() as u64 <= buffer.size(), "uploading {} bytes at {offset} to GPU buffer `{name}` of {} bytes", data.len(), buffer.size());
        crate::host_traffic::add(data.len() as u64);
        gpu_counts::add(Event::Upload, &format!("dextrain:{name}"));
        self.scoped(|| format!("uploading {} bytes to GPU buffer `{name}`", data.len()), || self.queue.write_buffer(buffer, offset, data))
    }

    /// A command encoder with one compute pass that dispatches `passes` in order (pipeline, its
    /// bind group 0), each over `workgroups` (x, y); wgpu orders dispatches that share buffers.
    /// The dispatches are counted as kernels of `what` ([`crate::gpu_counts`]).
    pub fn encode_passes(&self, passes: &[(&wgpu::ComputePipeline, &wgpu::BindGroup)], workgroups: (u32, u32), what: &str) -> wgpu::CommandEncoder {
        let passes: Vec<Pass<'_>> = passes.iter().map(|&(pipeline, group)| (pipeline, group, workgroups)).collect();
        self.encode_dispatches(&passes, what)
    }

    /// [`GpuContext::encode_passes`] with each dispatch's own workgroups (x, y): the simulator's
    /// step and reset at theirs among the task layer's kernels.
    pub fn encode_dispatches(&self, passes: &[Pass<'_>], what: &str) -> wgpu::CommandEncoder {
        gpu_counts::add_n(Event::Kernel, &format!("dextrain:{what}"), passes.len() as u64);
        let mut enc = self.device.create_command_encoder(&Default::default());
        if let Some(profiler) = &self.profiler {
            // a pass per dispatch, stamped at its start and end (gpu::profile)
            let mut profiler = profiler.lock().unwrap_or_else(PoisonError::into_inner);
            let names = self.pipeline_names.lock().unwrap_or_else(PoisonError::into_inner);
            for &(pipeline, group, (x, y)) in passes {
                let name = format!("kernel:{}", names.get(pipeline).map_or("(unnamed)", |n| n.as_str()));
                let first = profiler.reserve(&name);
                let timestamp_writes = first.map(|f| profiler.pass_writes(f));
                record(&mut enc.begin_compute_pass(&wgpu::ComputePassDescriptor { label: None, timestamp_writes }), &(pipeline, group, (x, y)));
            }
            return enc;
        }
        {
            let mut pass = enc.begin_compute_pass(&Default::default());
            for dispatch in passes {
                record(&mut pass, dispatch);
            }
        }
        enc
    }

    /// Submits `encs` in order as one submission; an error of their commands comes back naming `what`.
    pub fn submit_all(&self, encs: Vec<wgpu::CommandEncoder>, what: &str) -> Result<()> {
        gpu_counts::add(Event::Submission, &format!("dextrain:{what}"));
        self.scoped(|| what.to_string(), || self.queue.submit(encs.into_iter().map(|e| e.finish()))).map(|_| ())
    }

    /// Submits `enc`; an error of its commands comes back naming `what`.
    pub fn submit(&self, enc: wgpu::CommandEncoder, what: &str) -> Result<()> {
        gpu_counts::add(Event::Submission, &format!("dextrain:{what}"));
        self.scoped(|| what.to_string(), || self.queue.submit([enc.finish()])).map(|_| ())
    }

    /// The synchronisation point of every readback: appends `copies` to `enc` (after whatever the
    /// caller recorded), submits it, waits for the device, maps each staging buffer and hands its
    /// first `bytes` bytes to `sink(copy index, bytes)`. Errors of the commands, the submission,
    /// the wait or the mapping, and those recorded by the uncaptured-error handler since the last
    /// check, come back naming `what`.
    pub fn submit_and_read(&self, mut enc: wgpu::CommandEncoder, copies: &[ReadbackCopy], what: &str, mut sink: impl FnMut(usize, &[u8])) -> Result<()> {
        self.check_uncaptured(what)?;
        for c in copies {
            ensure!(
                c.bytes <= c.src.size() && c.bytes <= c.staging.size() && c.bytes % wgpu::COPY_BUFFER_ALIGNMENT == 0,
                "{what}: cannot copy {} bytes of GPU buffer `{}` ({} bytes) through a staging buffer of {} bytes",
                c.bytes,
                c.name,
                c.src.size(),
                c.staging.size()
            );
        }
        crate::host_traffic::add(copies.iter().map(|c| c.bytes).sum());
        let source = format!("dextrain:{what}");
        for kind in [Event::Submission, Event::Read, Event::Wait] {
            gpu_counts::add(kind, &source);
        }
        gpu_counts::add_n(Event::Map, &source, copies.len() as u64);
        let receivers = self.scoped(
            || format!("{what}: submitting"),
            || {
                for c in copies {
                    enc.copy_buffer_to_buffer(c.src, 0, c.staging, 0, c.bytes);
                }
                self.queue.submit([enc.finish()]);
                copies
                    .iter()
                    .map(|c| {
                        let (tx, rx) = mpsc::channel();
                        c.staging.slice(0..c.bytes).map_async(wgpu::MapMode::Read, move |r| {
                            let _ = tx.send(r);
                        });
                        rx
                    })
                    .collect::<Vec<_>>()
            },
        )?;
        let waited = self.device.poll(wgpu::PollType::wait_indefinitely());
        // read (and unmap) every staging buffer that mapped, so that none stays mapped after an error
        let mut first_error = None;
        for (i, (c, rx)) in copies.iter().zip(receivers).enumerate() {
            let mapped = match rx.recv() {
                Ok(r) => r.map_err(|e| anyhow!("{what}: mapping the staging buffer of `{}` failed: {e}", c.name)),
                Err(_) => Err(anyhow!("{what}: the map of the staging buffer of `{}` never completed", c.name)),
            };
            let read = mapped.and_then(|()| {
                let view = c.staging.slice(0..c.bytes).get_mapped_range().map_err(|e| anyhow!("{what}: reading the staging buffer of `{}`: {e:?}", c.name));
                let out = view.map(|v| sink(i, &v));
                c.staging.unmap();
                out
            });
            if let Err(e) = read {
                first_error.get_or_insert(e);
            }
        }
        waited.map_err(|e| anyhow!("{what}: waiting for adapter {}: {e}", self.info.name))?;
        self.check_uncaptured(what)?;
        first_error.map_or(Ok(()), Err)
    }

    /// Whether this context keeps a device-time profile (`gpu::profile`).
    pub fn profiles(&self) -> bool {
        self.profiler.is_some()
    }

    /// The profiler (locked), for a pass of its own to stamp; None when not profiling.
    pub fn profiler(&self) -> Option<std::sync::MutexGuard<'_, GpuProfiler>> {
        self.profiler.as_ref().map(|p| p.lock().unwrap_or_else(PoisonError::into_inner))
    }

    /// Stamps the queue (a submission of its own): with `first` None, the start of a new span
    /// `name` (its index returned; None when the query set is full or nothing profiles), else the
    /// end of span `first`. A nearly full query set is read first.
    pub fn profile_stamp(&self, first: Option<u32>, name: &str) -> Result<Option<u32>> {
        let Some(profiler) = &self.profiler else { return Ok(None) };
        if first.is_none() && profiler.lock().unwrap_or_else(PoisonError::into_inner).nearly_full() {
            self.profile_read()?;
        }
        let mut p = profiler.lock().unwrap_or_else(PoisonError::into_inner);
        let (index, out) = match first {
            None => match p.reserve(name) {
                Some(f) => (f, Some(f)),
                None => return Ok(None),
            },
            Some(f) => (f + 1, None),
        };
        let mut enc = self.device.create_command_encoder(&Default::default());
        p.stamp(&mut enc, index);
        drop(p);
        self.submit(enc, "gpu profile stamp")?;
        Ok(out)
    }

    /// Reads the profile's timestamps recorded so far into its totals (one readback; nothing when
    /// none wait). Call it where every stamped command has been submitted.
    pub fn profile_read(&self) -> Result<()> {
        let Some(profiler) = &self.profiler else { return Ok(()) };
        let mut p = profiler.lock().unwrap_or_else(PoisonError::into_inner);
        if !p.has_pending() {
            return Ok(());
        }
        let mut enc = self.device.create_command_encoder(&Default::default());
        p.encode_resolve(&mut enc);
        let (resolve, staging, bytes) = p.buffers();
        let copy = ReadbackCopy { name: "gpu profile", src: resolve, staging, bytes };
        let mut ticks = Vec::new();
        self.submit_and_read(enc, &[copy], "reading the gpu profile", |_, b| ticks = b.to_vec())?;
        p.take(&ticks);
        Ok(())
    }

    /// Starts the profile afresh: what was stamped so far is read and forgotten (a run's set-up,
    /// before its loop).
    pub fn profile_restart(&self) -> Result<()> {
        self.profile_read()?;
        if let Some(mut p) = self.profiler() {
            p.clear();
        }
        Ok(())
    }

    /// The profile so far (`GpuProfiler::to_json` with the adapter), after reading what waits;
    /// None when this context does not profile.
    pub fn profile_report(&self) -> Result<Option<serde_json::Value>> {
        if self.profiler.is_none() {
            return Ok(None);
        }
        self.profile_read()?;
        let mut j = self.profiler().expect("profiles").to_json();
        j["adapter"] = serde_json::json!(self.describe());
        Ok(Some(j))
    }
}

/// One binding of a [`run_kernel`] dispatch (its bytes are uploaded as they are).
pub enum KernelBinding<'a> {
    /// `var<uniform>`.
    Uniform(&'a [u8]),
    /// `var<storage, read>`.
    Storage(&'a [u8]),
    /// `var<storage, read_write>`: read back after the dispatch.
    StorageRw(&'a [u8]),
}

/// Runs entry point `entry_point` of the WGSL module `source` once over `invocations` invocations
/// (workgroups of [`WORKGROUP_SIZE`] along x; the kernel must ignore ids past the end), with
/// `bindings` in group 0 (exactly those the entry point uses: the layout is derived from the shader;
/// test kernels put their own bindings from 30 up, beside those of `gpu::bindings`).
/// Returns the contents of every `StorageRw` binding after the dispatch, in the order given.
/// For tests that compare a shader function with its CPU twin.
pub fn run_kernel(ctx: &GpuContext, source: &str, entry_point: &str, bindings: &[(u32, KernelBinding)], invocations: u32) -> Result<Vec<Vec<u8>>> {
    let [pipeline] = ctx.compute_pipelines(entry_point, source, [entry_point])?;
    let mut buffers = Vec::with_capacity(bindings.len());
    for (b, k) in bindings {
        let (bytes, role) = match k {
            KernelBinding::Uniform(d) => (*d, BindingSpace::Uniform),
            KernelBinding::Storage(d) => (*d, BindingSpace::StorageRead),
            KernelBinding::StorageRw(d) => (*d, BindingSpace::StorageReadWrite),
        };
        buffers.push(ctx.create_buffer_with(&format!("binding {b}"), bytes, role.into(), role.usage())?);
    }
    let entries: Vec<wgpu::BindGroupEntry> =
        bindings.iter().zip(&buffers).map(|((b, _), buf)| wgpu::BindGroupEntry { binding: *b, resource: buf.as_entire_binding() }).collect();
    let group = ctx.scoped(
        || format!("creating the bind group of entry point `{entry_point}`"),
        || ctx.device.create_bind_group(&wgpu::BindGroupDescriptor { label: Some(entry_point), layout: &pipeline.get_bind_group_layout(0), entries: &entries }),
    )?;
    // the read-write bindings: (index into `bindings`, their byte count, a staging buffer)
    let mut rw = Vec::new();
    for (i, (b, k)) in bindings.iter().enumerate() {
        if let KernelBinding::StorageRw(d) = k {
            rw.push((i, d.len(), ctx.create_staging_buffer(&format!("binding {b} readback"), buffers[i].size())?));
        }
    }
    let names: Vec<String> = rw.iter().map(|(i, _, _)| format!("binding {}", bindings[*i].0)).collect();
    let copies: Vec<ReadbackCopy> = rw
        .iter()
        .zip(&names)
        .map(|((i, _, staging), name)| ReadbackCopy { name, src: &buffers[*i], staging, bytes: buffers[*i].size() })
        .collect();
    let enc = ctx.encode_passes(&[(&pipeline, &group)], (invocations.div_ceil(WORKGROUP_SIZE).max(1), 1), entry_point);
    let mut out = vec![Vec::new(); rw.len()];
    ctx.submit_and_read(enc, &copies, &format!("running kernel `{entry_point}`"), |k, bytes| out[k] = bytes[..rw[k].1].to_vec())?;
    Ok(out)
}
