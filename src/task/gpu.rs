//! `GpuTaskBatch`: the task layer on the GPU (the contract is in [`crate::task`]).
//!
//! The module is the simulator's WGSL with `shaders/task.wgsl` appended; its four pipelines and
//! their bind groups, the task buffers (constants, per-env task states, actions, outputs, fingertip
//! frames) and the readback buffer are made once in `new`. One step is one command buffer:
//! `task_act` → `step_main` → `task_reward` → `reset_main` → `task_observe`, then a copy of the
//! output buffer (obs `[N, obs_dim]`, priv obs `[N, priv_dim]`, records `[N, OUT_MISC]`) to the
//! readback buffer, and one map of it. Nothing is allocated on the device per step. With
//! `set_final_observations(true)` (which makes the final-observation buffer and its readback once),
//! `task_observe_final` runs between `task_reward` and `reset_main` and its buffer is read too.
//! `step_with_targets` (an outside controller's targets: `dextrain play`) submits `task_act` alone,
//! reads the task states back, writes the given targets into them and into the targets buffer,
//! then runs the rest of the step.

use anyhow::{Context, Result, ensure};

use super::setup::{TaskSetup, task_setup};
use super::spec::TaskSpec;
use super::task::OUT_MISC;
use super::{DeviceStep, StepBatch, TaskBatch, check_actions, check_targets, decode_snapshot, encode_snapshot};
use super::shaders::task_shader_source;
use crate::env::gpu::GpuEnvBatch;
use crate::gpu::context::{BufferRole, GpuContext, Pass, ReadbackCopy};
use crate::gpu::bindings::{ACTIONS, GLOBALS, JOINTS, PARAMS, REF_CFG, REF_FRAMES, REF_INFO, RESET_MASK, SPRINGS, STATES, STATS, TARGETS, TIPS};
use crate::gpu::bindings::{Binding, FINAL_OUT, TASK_ACT, TASK_CFG, TASK_GROUP, TASK_OBSERVE, TASK_OBSERVE_FINAL, TASK_OUT, TASK_REWARD, TASK_STATES};
use crate::gpu::layout::*;
use super::layout::*;
use crate::env::{EnvBatch, SimModel};
use crate::config::Config;

/// The task on a GPU: a [`GpuEnvBatch`] and the task kernels.
pub struct GpuTaskBatch {
    env: GpuEnvBatch,
    spec: TaskSpec,
    tc: TaskGlobals,
    /// The reference bank's host copy and constants (to sample an env's reference on the host).
    bank: Option<crate::task::bank::RefBank>,
    rg: crate::task::reference::RefGlobals,
    /// `[N, action_dim]` f32.
    actions: wgpu::Buffer,
    task_states: wgpu::Buffer,
    /// obs, priv obs and output records of every env (see the module documentation).
    out: wgpu::Buffer,
    readback: wgpu::Buffer,
    out_bytes: u64,
    /// The task's constant buffers (kept to rebuild the bind groups).
    task_cfg: wgpu::Buffer,
    tips: wgpu::Buffer,
    ref_frames: wgpu::Buffer,
    ref_info: wgpu::Buffer,
    ref_cfg: wgpu::Buffer,
    /// Final obs `[N, obs_dim]` and priv obs `[N, priv_dim]` (one float while they are off).
    final_out: wgpu::Buffer,
    /// Its readback buffer, once the final observations are on.
    final_readback: Option<wgpu::Buffer>,
    act_pipeline: wgpu::ComputePipeline,
    reward_pipeline: wgpu::ComputePipeline,
    observe_pipeline: wgpu::ComputePipeline,
    final_pipeline: wgpu::ComputePipeline,
    act_group: wgpu::BindGroup,
    reward_group: wgpu::BindGroup,
    observe_group: wgpu::BindGroup,
    final_group: wgpu::BindGroup,
    /// The output buffer's contents after the last readback.
    host: Vec<f32>,
    batch: StepBatch,
}

impl GpuTaskBatch {
    /// Builds the env batch on `ctx` and the task pipelines, with every env at the start of
    /// episode 0 (`reset_all` returns the first observations).
    pub fn new(cfg: &Config, ctx: GpuContext, model: SimModel) -> Result<GpuTaskBatch> {
        let TaskSetup { spec, tc, bank, rg } = task_setup(cfg, &model)?;
        let mut model = model;
        if let Some(b) = &bank {
            // each env holds the object its reference names
            model.set_reference_objects(b.objects.clone());
        }
        let n = spec.num_envs;
        let out_floats = n * (spec.obs_dim + spec.priv_dim + OUT_MISC);
        let out_bytes = (out_floats * 4) as u64;
        // the task's largest buffers, checked before the env batch is built
        let file = cfg.source.display();
        ctx.check_buffer_size(TASK_OUT.name, out_bytes, BufferRole::Storage).with_context(|| format!("{file}: key `sim.num_envs` = {n}: the task outputs"))?;
        let ref_bytes = (bank.as_ref().map_or(0, |b| b.frames.len()) * 4) as u64;
        ctx.check_buffer_size(REF_FRAMES.name, ref_bytes, BufferRole::Storage)
            .with_context(|| format!("{file}: key `task.reference.files`: the references"))?;
        let tips_host = model.tips.clone();
        let env = GpuEnvBatch::with_readback(ctx, model, std::mem::size_of::<TaskState>() as u64)?;
        let ctx = &env.ctx;
        let none = wgpu::BufferUsages::empty();
        let task_cfg = ctx.create_binding_buffer(TASK_CFG, std::slice::from_ref(&tc), none)?;
        let tips = ctx.create_binding_buffer(TIPS, &tips_host, none)?;
        // the reference layer (one zeroed element each for the lift task)
        let (ref_frames_host, ref_info_host) = match &bank {
            Some(b) => (b.frames.as_slice(), b.info.as_slice()),
            None => (&[][..], &[][..]),
        };
        let ref_frames = ctx.create_binding_buffer(REF_FRAMES, ref_frames_host, none)?;
        let ref_info = ctx.create_binding_buffer(REF_INFO, ref_info_host, none)?;
        let ref_cfg = ctx.create_binding_buffer(REF_CFG, std::slice::from_ref(&rg), none)?;
        let per_env = || format!("{file}: key `sim.num_envs` = {n}");
        let task_states = ctx.create_binding_buffer(TASK_STATES, &vec![TaskState::default(); n], none).with_context(per_env)?;
        let actions = ctx.create_binding_buffer(ACTIONS, &vec![0f32; n * spec.action_dim], none).with_context(per_env)?;
        let out = ctx.create_binding_buffer(TASK_OUT, &vec![0f32; out_floats], none).with_context(per_env)?;
        let readback = ctx.create_staging_buffer("task readback", out_bytes).with_context(per_env)?;
        let final_out = ctx.create_binding_buffer(FINAL_OUT, &[0f32], none)?;
        let [act_pipeline, reward_pipeline, observe_pipeline, final_pipeline] = ctx.compute_pipelines(
            TASK_GROUP.shader,
            &task_shader_source(),
            [TASK_ACT.entry_point, TASK_REWARD.entry_point, TASK_OBSERVE.entry_point, TASK_OBSERVE_FINAL.entry_point],
        )?;
        let batch = StepBatch::new(&spec);
        let own = [
            (TIPS, &tips),
            (TASK_CFG, &task_cfg),
            (TASK_STATES, &task_states),
            (ACTIONS, &actions),
            (TASK_OUT, &out),
            (FINAL_OUT, &final_out),
            (REF_FRAMES, &ref_frames),
            (REF_INFO, &ref_info),
            (REF_CFG, &ref_cfg),
        ];
        let [act_group, reward_group, observe_group, final_group] = bind_groups(&env, [&act_pipeline, &reward_pipeline, &observe_pipeline, &final_pipeline], &own)?;
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
            task_cfg,
            tips,
            ref_frames,
            ref_info,
            ref_cfg,
            final_out,
            final_readback: None,
            act_pipeline,
            reward_pipeline,
            observe_pipeline,
            final_pipeline,
            act_group,
            reward_group,
            observe_group,
            final_group,
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

    /// Remakes the four bind groups (after a buffer was replaced).
    fn rebind(&mut self) -> Result<()> {
        let own = [
            (TIPS, &self.tips),
            (TASK_CFG, &self.task_cfg),
            (TASK_STATES, &self.task_states),
            (ACTIONS, &self.actions),
            (TASK_OUT, &self.out),
            (FINAL_OUT, &self.final_out),
            (REF_FRAMES, &self.ref_frames),
            (REF_INFO, &self.ref_info),
            (REF_CFG, &self.ref_cfg),
        ];
        let pipelines = [&self.act_pipeline, &self.reward_pipeline, &self.observe_pipeline, &self.final_pipeline];
        [self.act_group, self.reward_group, self.observe_group, self.final_group] = bind_groups(&self.env, pipelines, &own)?;
        Ok(())
    }

    /// Reads the per-env task states back (tests, recordings; not used by `step`).
    pub fn task_states(&mut self) -> Result<Vec<TaskState>> {
        self.env.read(&self.task_states, TASK_STATES.name, self.spec.num_envs)
    }

    /// One step's kernels over the uploaded actions (`task_act` first when `act`; without it the
    /// targets are already in place), then the readback into the batch.
    fn run_step(&mut self, act: bool) -> Result<&StepBatch> {
        let e = &self.env;
        e.flush_pending()?;
        // the task's kernels over its workgroups, the simulator's step and reset over theirs
        let wg = e.workgroups();
        let mut passes: Vec<Pass<'_>> = Vec::with_capacity(5);
        if act {
            passes.push((&self.act_pipeline, &self.act_group, wg));
        }
        passes.extend([e.step_pass(), (&self.reward_pipeline, &self.reward_group, wg)]);
        if self.final_readback.is_some() {
            passes.push((&self.final_pipeline, &self.final_group, wg));
        }
        passes.extend([e.reset_pass(), (&self.observe_pipeline, &self.observe_group, wg)]);
        match &self.final_readback {
            None => dispatch_and_read(e, &passes, &self.out, &self.readback, self.out_bytes, &mut self.host, "task step")?,
            Some(final_readback) => {
                let enc = e.ctx.encode_dispatches(&passes, "task step");
                let (od, pd) = (self.spec.obs_dim, self.spec.priv_dim);
                let n = self.spec.num_envs;
                let fin_bytes = (n * (od + pd) * 4) as u64;
                let copies = [
                    ReadbackCopy { name: TASK_OUT.name, src: &self.out, staging: &self.readback, bytes: self.out_bytes },
                    ReadbackCopy { name: FINAL_OUT.name, src: &self.final_out, staging: final_readback, bytes: fin_bytes },
                ];
                let (host, batch) = (&mut self.host, &mut self.batch);
                e.ctx.submit_and_read(enc, &copies, "task step", |k, bytes| {
                    if k == 0 {
                        bytemuck::cast_slice_mut::<f32, u8>(host).copy_from_slice(bytes);
                    } else {
                        let f: &[f32] = &bytemuck::pod_collect_to_vec::<u8, f32>(bytes);
                        // rows of the envs that did not end keep what they had (the contract)
                        for i in 0..n {
                            let ended = host_ended(host, n, od + pd, i);
                            if ended {
                                batch.final_obs[i * od..(i + 1) * od].copy_from_slice(&f[i * od..(i + 1) * od]);
                                batch.final_priv_obs[i * pd..(i + 1) * pd].copy_from_slice(&f[n * od + i * pd..n * od + (i + 1) * pd]);
                            }
                        }
                    }
                })?;
            }
        }
        self.unpack_obs();
        let n = self.spec.num_envs;
        let base = n * (self.spec.obs_dim + self.spec.priv_dim);
        self.batch.fill_misc(&self.host[base..base + n * OUT_MISC]);
        Ok(&self.batch)
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
        dispatch_and_read(&self.env, &[(&self.observe_pipeline, &self.observe_group, self.env.workgroups())], &self.out, &self.readback, self.out_bytes, &mut self.host, "task reset_all")?;
        self.unpack_obs();
        self.batch.clear_misc();
        Ok(&self.batch)
    }

    fn step(&mut self, actions: &[f32]) -> Result<&StepBatch> {
        check_actions(&self.spec, actions)?;
        self.env.flush_pending()?; // a step recorded through env() runs before these uploads
        self.env.ctx.upload(ACTIONS.name, &self.actions, bytemuck::cast_slice(actions))?;
        self.run_step(true)
    }

    fn can_step_on_device(&self) -> bool {
        true
    }

    fn device_bytes(&self) -> u64 {
        let own = [&self.actions, &self.task_states, &self.out, &self.readback, &self.task_cfg, &self.tips, &self.ref_frames, &self.ref_info, &self.ref_cfg, &self.final_out];
        self.env.device_bytes() + own.iter().map(|b| b.size()).sum::<u64>() + self.final_readback.as_ref().map_or(0, |b| b.size())
    }

    fn step_on_device(&mut self, actions: &burn::prelude::Tensor<2>, device: &burn::prelude::Device) -> Result<DeviceStep> {
        use crate::gpu::io::{empty_buffer, flush, tensor_buffer};
        let (n, od, pd, ad) = (self.spec.num_envs, self.spec.obs_dim, self.spec.priv_dim, self.spec.action_dim);
        ensure!(actions.dims() == [n, ad], "actions of shape {:?} for {n} envs × {ad} actions", actions.dims());
        self.env.flush_pending()?;
        let act = tensor_buffer(actions)?;
        // (fresh, unfilled tensors: the copies below write every byte)
        let outs = [empty_buffer(n, od, device)?, empty_buffer(n, pd, device)?, empty_buffer(n, OUT_MISC, device)?];
        let finals = match self.final_readback {
            Some(_) => Some([empty_buffer(n, od, device)?, empty_buffer(n, pd, device)?]),
            None => None,
        };
        let e = &self.env;
        // the actions into the task's action buffer, then the step's kernels (as run_step's), then
        // the outputs ([N, od] obs, [N, pd] priv obs, [N, OUT_MISC] records, back to back in `out`;
        // the final observations [N, od], [N, pd] back to back in `final_out`) into the tensors
        let mut copy_in = e.ctx.device.create_command_encoder(&Default::default());
        copy_in.copy_buffer_to_buffer(act.buffer(), act.offset(), &self.actions, 0, act.size());
        let wg = e.workgroups();
        let mut passes = vec![(&self.act_pipeline, &self.act_group, wg), e.step_pass(), (&self.reward_pipeline, &self.reward_group, wg)];
        if finals.is_some() {
            passes.push((&self.final_pipeline, &self.final_group, wg));
        }
        passes.extend([e.reset_pass(), (&self.observe_pipeline, &self.observe_group, wg)]);
        let mut enc = e.ctx.encode_dispatches(&passes, "task step (device-resident)");
        for (src, dsts) in [(&self.out, &outs[..]), (&self.final_out, finals.as_ref().map_or(&[][..], |f| &f[..]))] {
            let mut from = 0u64;
            for o in dsts {
                enc.copy_buffer_to_buffer(src, from, o.buffer(), o.offset(), o.size());
                from += o.size();
            }
        }
        // what burn recorded (the actions) runs first (gpu::io)
        flush(device)?;
        e.ctx.submit_all(vec![copy_in, enc], "task step (device-resident)")?;
        let [obs, priv_obs, misc] = outs;
        let (final_obs, final_priv_obs) = match finals {
            Some([o, p]) => (Some(o.tensor), Some(p.tensor)),
            None => (None, None),
        };
        Ok(DeviceStep { obs: obs.tensor, priv_obs: priv_obs.tensor, misc: misc.tensor, final_obs, final_priv_obs })
    }

    fn set_final_observations(&mut self, on: bool) -> Result<()> {
        if on == self.final_readback.is_some() {
            return Ok(());
        }
        let ctx = &self.env.ctx;
        let n = self.spec.num_envs;
        let floats = n * (self.spec.obs_dim + self.spec.priv_dim);
        let what = || format!("sim.num_envs = {n}: the final observations");
        if on {
            ctx.check_buffer_size(FINAL_OUT.name, (floats * 4) as u64, BufferRole::Storage).with_context(what)?;
            self.final_out = ctx.create_binding_buffer(FINAL_OUT, &vec![0f32; floats], wgpu::BufferUsages::empty()).with_context(what)?;
            self.final_readback = Some(ctx.create_staging_buffer("task final readback", (floats * 4) as u64).with_context(what)?);
        } else {
            self.final_out = ctx.create_binding_buffer(FINAL_OUT, &[0f32], wgpu::BufferUsages::empty())?;
            self.final_readback = None;
        }
        self.rebind()
    }

    fn step_with_targets(&mut self, actions: &[f32], targets: &[Targets]) -> Result<&StepBatch> {
        check_actions(&self.spec, actions)?;
        check_targets(&self.spec, targets)?;
        self.env.flush_pending()?; // a step recorded through env() runs before these uploads
        self.env.ctx.upload(ACTIONS.name, &self.actions, bytemuck::cast_slice(actions))?;
        let e = &self.env;
        // task_act records the actions; then the controller's targets replace the mapped ones in the
        // task states and in the buffer the physics reads (uploads land before the next submit)
        e.ctx.submit(e.ctx.encode_passes(&[(&self.act_pipeline, &self.act_group)], e.workgroups(), "task act"), "task act")?;
        let mut ts = self.task_states()?;
        for (t, g) in ts.iter_mut().zip(targets) {
            t.targets = *g;
        }
        let e = &self.env;
        e.ctx.upload(TASK_STATES.name, &self.task_states, bytemuck::cast_slice(&ts))?;
        e.ctx.upload(TARGETS.name, &e.targets, bytemuck::cast_slice(targets))?;
        self.run_step(false)
    }

    fn reference_frames(&mut self, k: u32) -> Result<Option<Vec<crate::task::reference::RefFrame>>> {
        if self.bank.is_none() {
            return Ok(None);
        }
        // the shader's sampler, run on the host (its CPU twin) with each env's cursor and step
        let (ts, states) = (self.task_states()?, self.env.states()?);
        let r = crate::task::ref_model(&self.env.model, self.bank.as_ref(), &self.rg);
        Ok(Some(ts.iter().zip(&states).map(|(t, s)| crate::task::reference::ref_sample(&r, &t.cursor, s.step, k)).collect()))
    }

    fn targets(&mut self) -> Result<Vec<Targets>> {
        Ok(self.task_states()?.iter().map(|t| t.targets).collect())
    }

    fn first_targets(&mut self, k: usize) -> Result<Vec<Targets>> {
        let k = k.min(self.spec.num_envs);
        let first: Vec<TaskState> = self.env.read(&self.task_states, TASK_STATES.name, k)?;
        Ok(first.iter().map(|t| t.targets).collect())
    }

    fn reference_now(&mut self, env: usize) -> Result<Option<crate::task::reference::RefFrame>> {
        if self.bank.is_none() {
            return Ok(None);
        }
        // the shader's sampler, run on the host (its CPU twin) with the env's cursor and step
        // (envs 0..=env read back, not the batch)
        ensure!(env < self.spec.num_envs, "reference_now: env {env} of {} envs", self.spec.num_envs);
        let first: Vec<TaskState> = self.env.read(&self.task_states, TASK_STATES.name, env + 1)?;
        let cursor = first[env].cursor;
        let step = self.env.first_envs(env + 1)?.0[env].step;
        let r = crate::task::ref_model(&self.env.model, self.bank.as_ref(), &self.rg);
        Ok(Some(crate::task::reference::ref_sample(&r, &cursor, step, 0)))
    }

    fn save_state(&mut self) -> Result<Vec<u8>> {
        let (states, springs, params) = (self.env.states()?, self.env.springs()?, self.env.params()?);
        Ok(encode_snapshot(&states, &springs, &params, &self.task_states()?))
    }

    fn load_state(&mut self, state: &[u8]) -> Result<()> {
        let (env, task) = decode_snapshot(state, self.spec.num_envs, self.env.model.globals.n_springs as usize)?;
        self.env.set_states(&env.states)?;
        self.env.set_springs(&env.springs)?;
        self.env.set_params(&env.params)?;
        self.env.flush_pending()?;
        self.env.ctx.upload(TASK_STATES.name, &self.task_states, bytemuck::cast_slice(&task))
    }
}

/// The bind groups of `task_act`, `task_reward`, `task_observe` and `task_observe_final` (`pipelines`
/// in that order) over the env batch's buffers and the task's (`own`); each lists exactly the
/// bindings its entry point uses (the layouts are derived).
fn bind_groups(env: &GpuEnvBatch, pipelines: [&wgpu::ComputePipeline; 4], own: &[(Binding, &wgpu::Buffer)]) -> Result<[wgpu::BindGroup; 4]> {
    let mut buffers: Vec<(Binding, &wgpu::Buffer)> = vec![
        (GLOBALS, &env.globals),
        (JOINTS, &env.joints),
        (STATES, &env.states),
        (PARAMS, &env.params),
        (TARGETS, &env.targets),
        (STATS, &env.stats),
        (RESET_MASK, &env.reset_mask),
        (SPRINGS, &env.springs),
    ];
    buffers.extend_from_slice(own);
    let ctx = &env.ctx;
    Ok([
        ctx.bind_group(pipelines[0], &TASK_ACT, &buffers)?,
        ctx.bind_group(pipelines[1], &TASK_REWARD, &buffers)?,
        ctx.bind_group(pipelines[2], &TASK_OBSERVE, &buffers)?,
        ctx.bind_group(pipelines[3], &TASK_OBSERVE_FINAL, &buffers)?,
    ])
}

/// Whether env `i` ended in the step whose output records are in `host` (`[N, row]` obs and priv obs
/// first, then `[N, OUT_MISC]` records).
fn host_ended(host: &[f32], n: usize, row: usize, i: usize) -> bool {
    use super::task::{OUT_TERMINATED, OUT_TIME_OUT, OUT_BAD_RESET};
    let r = &host[n * row + i * OUT_MISC..n * row + (i + 1) * OUT_MISC];
    (r[OUT_TERMINATED] != 0.0 || r[OUT_TIME_OUT] != 0.0) && r[OUT_BAD_RESET] == 0.0
}

/// Records the given (pipeline, bind group) dispatches over all envs in one compute pass (wgpu
/// orders dispatches that share buffers), copies `out` (`out_bytes` bytes) to `readback`, submits,
/// and reads it into `host`. `what` names the call in errors.
fn dispatch_and_read(
    env: &GpuEnvBatch,
    passes: &[Pass<'_>],
    out: &wgpu::Buffer,
    readback: &wgpu::Buffer,
    out_bytes: u64,
    host: &mut [f32],
    what: &str,
) -> Result<()> {
    env.flush_pending()?;
    let enc = env.ctx.encode_dispatches(passes, what);
    let copy = ReadbackCopy { name: TASK_OUT.name, src: out, staging: readback, bytes: out_bytes };
    // host as bytes: any f32 slice is a valid byte slice, so no alignment question arises
    env.ctx.submit_and_read(enc, &[copy], what, |_, bytes| bytemuck::cast_slice_mut::<f32, u8>(host).copy_from_slice(bytes))
}
