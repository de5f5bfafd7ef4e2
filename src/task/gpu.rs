//! `GpuTaskBatch`: the task layer on the GPU (the contract is in [`crate::task`]).
//!
//! The module is the simulator's WGSL with `shaders/task.wgsl` appended; its three pipelines and
//! their bind groups, the task buffers (constants, per-env task states, actions, outputs, fingertip
//! frames) and the readback buffer are made once in `new`. One step is one command buffer:
//! `task_act` → `step_main` → `task_reward` → `reset_main` → `task_observe`, then a copy of the
//! output buffer (obs `[N, obs_dim]`, priv obs `[N, priv_dim]`, records `[N, OUT_MISC]`) to the
//! readback buffer, and one map of it. Nothing is allocated on the device per step.

use std::sync::mpsc;

use anyhow::{Context, Result, anyhow, bail};
use wgpu::util::DeviceExt;

use super::setup::{TaskSetup, task_setup};
use super::spec::TaskSpec;
use super::task::OUT_MISC;
use super::{StepBatch, TaskBatch, check_actions, decode_snapshot, encode_snapshot};
use crate::env::gpu::{GpuContext, GpuEnvBatch, entry, storage, task_shader_source};
use crate::env::gpu_layout::*;
use crate::env::{EnvBatch, SimModel};
use crate::config::Config;

/// The task on a GPU: a [`GpuEnvBatch`] and the task kernels.
pub struct GpuTaskBatch {
    env: GpuEnvBatch,
    spec: TaskSpec,
    tc: TaskGlobals,
    /// The reference bank's host copy and constants (to sample an env's reference on the host).
    bank: Option<crate::traj::bank::RefBank>,
    rg: crate::env::reference::RefGlobals,
    /// `[N, action_dim]` f32.
    actions: wgpu::Buffer,
    task_states: wgpu::Buffer,
    /// obs, priv obs and output records of every env (see the module documentation).
    out: wgpu::Buffer,
    readback: wgpu::Buffer,
    out_bytes: u64,
    act_pipeline: wgpu::ComputePipeline,
    reward_pipeline: wgpu::ComputePipeline,
    observe_pipeline: wgpu::ComputePipeline,
    act_group: wgpu::BindGroup,
    reward_group: wgpu::BindGroup,
    observe_group: wgpu::BindGroup,
    /// The output buffer's contents after the last readback.
    host: Vec<f32>,
    batch: StepBatch,
}

impl GpuTaskBatch {
    /// Builds the env batch on `ctx` and the task pipelines, with every env at the start of
    /// episode 0 (`reset_all` returns the first observations).
    pub fn new(cfg: &Config, ctx: GpuContext, model: SimModel) -> Result<GpuTaskBatch> {
        let TaskSetup { spec, tc, bank, rg } = task_setup(cfg, &model)?;
        let n = spec.num_envs;
        let out_floats = n * (spec.obs_dim + spec.priv_dim + OUT_MISC);
        let out_bytes = (out_floats * 4) as u64;
        let limits = ctx.device.limits();
        if out_bytes > limits.max_storage_buffer_binding_size || out_bytes > limits.max_buffer_size {
            bail!(
                "sim.num_envs = {n} needs {} MiB of task outputs, but adapter {} allows {} MiB per storage binding",
                out_bytes >> 20,
                ctx.info.name,
                limits.max_storage_buffer_binding_size.min(limits.max_buffer_size) >> 20
            );
        }
        let ref_bytes = (bank.as_ref().map_or(0, |b| b.frames.len()) * 4) as u64;
        if ref_bytes > limits.max_storage_buffer_binding_size || ref_bytes > limits.max_buffer_size {
            bail!(
                "{}: key `task.reference.files`: the references need {} MiB on the device, but adapter {} allows {} MiB per storage binding",
                cfg.source.display(),
                ref_bytes >> 20,
                ctx.info.name,
                limits.max_storage_buffer_binding_size.min(limits.max_buffer_size) >> 20
            );
        }
        let tips_host = model.tips.clone();
        let env = GpuEnvBatch::new(ctx, model)?;
        let device = &env.ctx.device;
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("dextrain task"),
            source: wgpu::ShaderSource::Wgsl(task_shader_source().into()),
        });
        let task_cfg = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("task_cfg"),
            contents: bytemuck::bytes_of(&tc),
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        });
        let none = wgpu::BufferUsages::empty();
        let tips = storage(device, "tips", &tips_host, none);
        // the reference layer (bindings 13–15; one zeroed element each for the lift task)
        let (ref_frames_host, ref_info_host) = match &bank {
            Some(b) => (b.frames.clone(), b.info.clone()),
            None => (Vec::new(), Vec::new()),
        };
        let ref_frames = storage(device, "ref_frames", &ref_frames_host, none);
        let ref_info = storage(device, "ref_info", &ref_info_host, none);
        let ref_cfg = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("ref_cfg"),
            contents: bytemuck::bytes_of(&rg),
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        });
        let task_states = storage(device, "task_states", &vec![TaskState::default(); n], none);
        let actions = storage(device, "actions", &vec![0f32; n * spec.action_dim], none);
        let out = storage(device, "task_out", &vec![0f32; out_floats], none);
        let readback = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("task readback"),
            size: out_bytes,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let make = |name: &str| {
            device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(name),
                layout: None,
                module: &module,
                entry_point: Some(name),
                compilation_options: Default::default(),
                cache: None,
            })
        };
        let act_pipeline = make("task_act");
        let reward_pipeline = make("task_reward");
        let observe_pipeline = make("task_observe");
        // each bind group lists exactly the bindings its entry point uses (the layouts are derived)
        let group = |pipeline: &wgpu::ComputePipeline, label: &str, entries: &[wgpu::BindGroupEntry]| {
            device.create_bind_group(&wgpu::BindGroupDescriptor { label: Some(label), layout: &pipeline.get_bind_group_layout(0), entries })
        };
        let act_group = group(
            &act_pipeline,
            "task_act",
            &[
                entry(0, &env.globals),
                entry(1, &env.joints),
                entry(3, &tips),
                entry(4, &env.states),
                entry(6, &env.targets),
                entry(9, &task_cfg),
                entry(10, &task_states),
                entry(11, &actions),
                entry(13, &ref_frames),
                entry(14, &ref_info),
                entry(15, &ref_cfg),
            ],
        );
        let reward_group = group(
            &reward_pipeline,
            "task_reward",
            &[
                entry(0, &env.globals),
                entry(1, &env.joints),
                entry(3, &tips),
                entry(4, &env.states),
                entry(5, &env.params),
                entry(7, &env.stats),
                entry(8, &env.reset_mask),
                entry(9, &task_cfg),
                entry(10, &task_states),
                entry(12, &out),
                entry(13, &ref_frames),
                entry(14, &ref_info),
                entry(15, &ref_cfg),
            ],
        );
        let observe_group = group(
            &observe_pipeline,
            "task_observe",
            &[
                entry(0, &env.globals),
                entry(1, &env.joints),
                entry(3, &tips),
                entry(4, &env.states),
                entry(5, &env.params),
                entry(8, &env.reset_mask),
                entry(9, &task_cfg),
                entry(10, &task_states),
                entry(12, &out),
                entry(13, &ref_frames),
                entry(14, &ref_info),
                entry(15, &ref_cfg),
            ],
        );
        let batch = StepBatch::new(&spec);
        let mut b = GpuTaskBatch {
            env,
            spec,
            tc,
            bank,
            rg,
            actions,
            task_states,
            out,
            readback,
            out_bytes,
            act_pipeline,
            reward_pipeline,
            observe_pipeline,
            act_group,
            reward_group,
            observe_group,
            host: vec![0.0; out_floats],
            batch,
        };
        b.reset_all()?;
        Ok(b)
    }

    /// The task constants uploaded to the GPU.
    pub fn task_globals(&self) -> &TaskGlobals {
        &self.tc
    }

    /// Reads the per-env task states back (tests, recordings; not used by `step`).
    pub fn task_states(&mut self) -> Result<Vec<TaskState>> {
        self.env.read(&self.task_states, self.spec.num_envs)
    }

    /// Copies the obs and priv obs sections of `self.host` into the batch.
    fn unpack_obs(&mut self) {
        let n = self.spec.num_envs;
        let (od, pd) = (self.spec.obs_dim, self.spec.priv_dim);
        self.batch.obs.copy_from_slice(&self.host[..n * od]);
        self.batch.priv_obs.copy_from_slice(&self.host[n * od..n * (od + pd)]);
    }
}

impl TaskBatch for GpuTaskBatch {
    fn spec(&self) -> &TaskSpec {
        &self.spec
    }

    fn backend_name(&self) -> String {
        self.env.backend_name()
    }

    fn env(&mut self) -> &mut dyn EnvBatch {
        &mut self.env
    }

    fn gpu_context(&self) -> Option<&GpuContext> {
        Some(&self.env.ctx)
    }

    fn reset_all(&mut self) -> Result<&StepBatch> {
        // reset_mask = 2 everywhere: task_observe initialises every env's task state
        self.env.reset_all()?;
        dispatch_and_read(&self.env, &[(&self.observe_pipeline, &self.observe_group)], &self.out, &self.readback, self.out_bytes, &mut self.host)?;
        self.unpack_obs();
        self.batch.clear_misc();
        Ok(&self.batch)
    }

    fn step(&mut self, actions: &[f32]) -> Result<&StepBatch> {
        check_actions(&self.spec, actions)?;
        self.env.ctx.queue.write_buffer(&self.actions, 0, bytemuck::cast_slice(actions));
        let e = &self.env;
        let passes = [
            (&self.act_pipeline, &self.act_group),
            (&e.step_pipeline, &e.step_group),
            (&self.reward_pipeline, &self.reward_group),
            (&e.reset_pipeline, &e.reset_group),
            (&self.observe_pipeline, &self.observe_group),
        ];
        dispatch_and_read(e, &passes, &self.out, &self.readback, self.out_bytes, &mut self.host)?;
        self.unpack_obs();
        let n = self.spec.num_envs;
        let base = n * (self.spec.obs_dim + self.spec.priv_dim);
        self.batch.fill_misc(&self.host[base..base + n * OUT_MISC]);
        Ok(&self.batch)
    }

    fn targets(&mut self) -> Result<Vec<Targets>> {
        Ok(self.task_states()?.iter().map(|t| t.targets).collect())
    }

    fn reference_now(&mut self, env: usize) -> Result<Option<crate::env::reference::RefFrame>> {
        if self.bank.is_none() {
            return Ok(None);
        }
        // the shader's sampler, run on the host (its CPU twin) with the env's cursor and step
        let cursor = self.task_states()?[env].cursor;
        let step = self.env.states()?[env].step;
        let r = crate::task::ref_model(&self.env.model, self.bank.as_ref(), &self.rg);
        Ok(Some(crate::env::reference::ref_sample(&r, &cursor, step, 0)))
    }

    fn save_state(&mut self) -> Result<Vec<u8>> {
        let (states, params) = (self.env.states()?, self.env.params()?);
        Ok(encode_snapshot(&states, &params, &self.task_states()?))
    }

    fn load_state(&mut self, state: &[u8]) -> Result<()> {
        let (states, params, task) = decode_snapshot(state, self.spec.num_envs)?;
        self.env.set_states(&states)?;
        self.env.set_params(&params)?;
        self.env.ctx.queue.write_buffer(&self.task_states, 0, bytemuck::cast_slice(&task));
        Ok(())
    }
}

/// Records the given (pipeline, bind group) dispatches over all envs in one compute pass (wgpu
/// orders dispatches that share buffers), copies `out` to `readback`, submits, and reads it into `host`.
fn dispatch_and_read(
    env: &GpuEnvBatch,
    passes: &[(&wgpu::ComputePipeline, &wgpu::BindGroup)],
    out: &wgpu::Buffer,
    readback: &wgpu::Buffer,
    out_bytes: u64,
    host: &mut [f32],
) -> Result<()> {
    let (x, y) = env.workgroups();
    let ctx = &env.ctx;
    let mut enc = ctx.device.create_command_encoder(&Default::default());
    {
        let mut pass = enc.begin_compute_pass(&Default::default());
        for (pipeline, group) in passes {
            pass.set_pipeline(pipeline);
            pass.set_bind_group(0, *group, &[]);
            pass.dispatch_workgroups(x, y, 1);
        }
    }
    enc.copy_buffer_to_buffer(out, 0, readback, 0, out_bytes);
    ctx.queue.submit([enc.finish()]);
    let slice = readback.slice(..);
    let (tx, rx) = mpsc::channel();
    slice.map_async(wgpu::MapMode::Read, move |r| {
        let _ = tx.send(r);
    });
    ctx.device.poll(wgpu::PollType::wait_indefinitely()).map_err(|e| anyhow!("GPU poll failed: {e}"))?;
    rx.recv().context("GPU readback was dropped")?.map_err(|e| anyhow!("GPU readback failed: {e}"))?;
    {
        let view = slice.get_mapped_range().map_err(|e| anyhow!("GPU readback failed: {e:?}"))?;
        match bytemuck::try_cast_slice::<u8, f32>(&view) {
            Ok(f) => host.copy_from_slice(f),
            Err(_) => {
                for (h, b) in host.iter_mut().zip(view.chunks_exact(4)) {
                    *h = f32::from_ne_bytes([b[0], b[1], b[2], b[3]]);
                }
            }
        }
    }
    readback.unmap();
    Ok(())
}
