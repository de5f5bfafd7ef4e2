//! `GpuEnvBatch`, the env batch on a wgpu device (`crate::gpu::context::GpuContext`). The WGSL of
//! `shaders/` (common + reset + physics, concatenated) runs one invocation per env; buffers,
//! pipelines and bind groups are made once in `new`, so a step only uploads targets, dispatches and
//! (on request) copies results back.

use anyhow::{Context, Result, ensure};
use bytemuck::Pod;

use super::{EnvBatch, EnvSpec, SimModel};
use crate::gpu::bindings::{COLLIDERS, GLOBALS, HULLS, JOINTS, OBJECTS, PARAMS, PIECES, REF_OBJECTS, RESET_MASK, STATES, STATS, TARGETS};
use crate::gpu::bindings::{NARROW_QUERIES, RESET_MAIN, SIM_GROUP, SPRINGS, STEP_MAIN, STEP_MAIN_WITHOUT_ROUNDS};
use crate::gpu::context::{BufferRole, GpuContext, Pass, ReadbackCopy};
use crate::gpu::layout::*;
use crate::gpu::shaders::{collider_words, module_workgroups, shader_source_at, step_workgroup_size, workgroups_for, workgroups_of};

/// The env batch on a GPU. The task layer (`task_gpu`) binds its buffers and dispatches its
/// pipelines inside its own command encoders.
pub struct GpuEnvBatch {
    pub(crate) ctx: GpuContext,
    pub(crate) model: SimModel,
    /// [`GLOBALS`]: the model's constants.
    pub(crate) globals: wgpu::Buffer,
    /// [`JOINTS`]: `[n_joints]` `JointDesc`.
    pub(crate) joints: wgpu::Buffer,
    /// [`STATES`]: `[N]` `EnvState`.
    pub(crate) states: wgpu::Buffer,
    /// [`PARAMS`]: `[N]` `EnvParams`.
    pub(crate) params: wgpu::Buffer,
    /// [`TARGETS`]: `[N]` `Targets`.
    pub(crate) targets: wgpu::Buffer,
    /// [`STATS`]: `[N]` `StepStats`.
    pub(crate) stats: wgpu::Buffer,
    /// [`RESET_MASK`]: `[N]` u32.
    pub(crate) reset_mask: wgpu::Buffer,
    /// [`SPRINGS`]: `[N, n_springs]` `vec4<f32>`.
    pub(crate) springs: wgpu::Buffer,
    /// [`NARROW_QUERIES`]: `[N, 2, n_colliders, 4]` `vec4<f32>`, the step's scratch (held here
    /// for its bind group).
    narrow_queries: wgpu::Buffer,
    /// Staging buffer of [`GpuEnvBatch::read`] (the size of the env states or of the springs,
    /// whichever is larger).
    readback: wgpu::Buffer,
    step_pipeline: wgpu::ComputePipeline,
    reset_pipeline: wgpu::ComputePipeline,
    step_group: wgpu::BindGroup,
    reset_group: wgpu::BindGroup,
    /// Invocations per workgroup of the module's `step_main` and `reset_main` (the built-in's:
    /// chosen by the batch's size, [`step_workgroup_size`]; a `--physics-wgsl` module's its own).
    step_workgroup_size: u32,
    reset_workgroup_size: u32,
    mask_host: Vec<u32>,
    /// The last `step`'s dispatch, recorded but not yet submitted: the next readback appends its
    /// copy and submits both at once (one submission per env step of a loop that reads each
    /// step's statistics); anything else that uses the queue submits it first
    /// ([`GpuEnvBatch::flush_pending`]), so the queue runs the work in program order.
    pending: std::sync::Mutex<Option<wgpu::CommandEncoder>>,
}

impl GpuEnvBatch {
    /// Uploads the model, builds the pipelines and starts episode 0 of every env. A batch whose
    /// buffers exceed the device's limits, and every wgpu error while building it, is an error.
    pub fn new(ctx: GpuContext, model: SimModel) -> Result<GpuEnvBatch> {
        GpuEnvBatch::with_readback(ctx, model, 0)
    }

    /// [`GpuEnvBatch::new`] with a readback buffer of at least `min_readback_bytes_per_env` per env
    /// (the task layer reads its per-env states through it).
    pub fn with_readback(ctx: GpuContext, model: SimModel, min_readback_bytes_per_env: u64) -> Result<GpuEnvBatch> {
        GpuEnvBatch::build(ctx, model, min_readback_bytes_per_env, None)
    }

    /// [`GpuEnvBatch::new`] with the simulator's WGSL module `source` in place of the built-in one
    /// ([`crate::gpu::shaders::shader_source`]: common, reset and physics; `dextrain bench
    /// --physics-wgsl`, to time a variant of the physics shader), its entry points dispatched at
    /// their own workgroup sizes. A module that fails validation is an error naming the shader.
    pub fn with_physics_source(ctx: GpuContext, model: SimModel, source: &str) -> Result<GpuEnvBatch> {
        GpuEnvBatch::build(ctx, model, 0, Some(source))
    }

    /// The batch on `source`, or (None) on the built-in module at the step's workgroup size for
    /// this many envs on this device ([`step_workgroup_size`]) and with the collider lists of the
    /// model's hand ([`collider_words`]).
    fn build(ctx: GpuContext, model: SimModel, min_readback_bytes_per_env: u64, source: Option<&str>) -> Result<GpuEnvBatch> {
        let n = model.spec.num_envs;
        let built_in;
        let source = match source {
            Some(source) => source,
            None => {
                let l = ctx.device.limits();
                // the collider lists' words for this hand
                let words = collider_words(model.globals.n_colliders as usize);
                // a size fits where its invocations and its module's workgroup memory are within the device's limits
                let fits = |size: u32| {
                    size <= l.max_compute_invocations_per_workgroup
                        && size <= l.max_compute_workgroup_size_x
                        && module_workgroups(&shader_source_at(size, words), &[]).is_ok_and(|(_, bytes)| bytes <= l.max_compute_workgroup_storage_size)
                };
                built_in = shader_source_at(step_workgroup_size(n, fits), words);
                &built_in
            }
        };
        // the largest per-env buffer, checked before anything is allocated
        let state_bytes = (n * std::mem::size_of::<EnvState>()) as u64;
        ctx.check_buffer_size(STATES.name, state_bytes, BufferRole::Storage).with_context(|| format!("sim.num_envs = {n}"))?;
        let n_springs = n * model.globals.n_springs as usize;
        let spring_bytes = (n_springs * 16) as u64;
        ctx.check_buffer_size(SPRINGS.name, spring_bytes, BufferRole::Storage)
            .with_context(|| format!("sim.num_envs = {n} × {} contact springs per env", model.globals.n_springs))?;
        // the narrow-phase rounds' slots: 2 regions × n_colliders × 4 vec4 per env
        let query_bytes = n as u64 * 2 * model.globals.n_colliders as u64 * 64;
        ctx.check_buffer_size(NARROW_QUERIES.name, query_bytes, BufferRole::Storage)
            .with_context(|| format!("sim.num_envs = {n} × {} hand colliders × 128 bytes of narrow-phase queries", model.globals.n_colliders))?;
        let none = wgpu::BufferUsages::empty();
        let globals = ctx.create_binding_buffer(GLOBALS, std::slice::from_ref(&model.globals), none)?;
        let joints = ctx.create_binding_buffer(JOINTS, &model.joints, none)?;
        let colliders = ctx.create_binding_buffer(COLLIDERS, &model.colliders, none)?;
        let pieces = ctx.create_binding_buffer(PIECES, &model.pieces, none)?;
        let objects = ctx.create_binding_buffer(OBJECTS, &model.object_descs, none)?;
        let hulls = ctx.create_binding_buffer(HULLS, &model.hulls, none)?;
        let ref_objects = ctx.create_binding_buffer(REF_OBJECTS, &model.ref_objects, none)?;
        let per_env = || format!("sim.num_envs = {n}");
        let states = ctx.create_binding_buffer(STATES, &vec![EnvState::default(); n], none).with_context(per_env)?;
        let params = ctx.create_binding_buffer(PARAMS, &vec![<EnvParams as bytemuck::Zeroable>::zeroed(); n], none).with_context(per_env)?;
        let targets = ctx.create_binding_buffer(TARGETS, &vec![Targets::default(); n], none).with_context(per_env)?;
        let stats = ctx.create_binding_buffer(STATS, &vec![<StepStats as bytemuck::Zeroable>::zeroed(); n], none).with_context(per_env)?;
        let reset_mask = ctx.create_binding_buffer(RESET_MASK, &vec![0u32; n], none).with_context(per_env)?;
        let springs = ctx.create_binding_buffer(SPRINGS, &vec![[0.0f32; 4]; n_springs.max(1)], none).with_context(per_env)?;
        let narrow_queries = ctx.create_scratch_buffer(NARROW_QUERIES, query_bytes).with_context(per_env)?;
        // the largest per-env readback: env states, contact springs or what the caller reads (the task layer's states)
        let task_bytes = n as u64 * min_readback_bytes_per_env;
        let readback = ctx.create_staging_buffer("env readback", state_bytes.max(spring_bytes).max(task_bytes)).with_context(per_env)?;
        // the entry points' workgroup sizes, and the module's workgroup memory against the device's
        // limit, before anything is compiled
        let (sizes, workgroup_bytes) = module_workgroups(source, &[STEP_MAIN.entry_point, RESET_MAIN.entry_point]).with_context(|| format!("shader `{}`", SIM_GROUP.shader))?;
        let (step_workgroup_size, reset_workgroup_size) = (sizes[0], sizes[1]);
        let limit = ctx.device.limits().max_compute_workgroup_storage_size;
        ensure!(
            workgroup_bytes <= limit,
            "shader `{}`: {workgroup_bytes} bytes of workgroup memory (`var<workgroup>`), over the device's {limit} (max_compute_workgroup_storage_size)",
            SIM_GROUP.shader
        );
        let [step_pipeline, reset_pipeline] =
            ctx.compute_pipelines(SIM_GROUP.shader, source, [STEP_MAIN.entry_point, RESET_MAIN.entry_point])?;
        let buffers = [
            (GLOBALS, &globals),
            (JOINTS, &joints),
            (COLLIDERS, &colliders),
            (STATES, &states),
            (PARAMS, &params),
            (TARGETS, &targets),
            (STATS, &stats),
            (RESET_MASK, &reset_mask),
            (SPRINGS, &springs),
            (PIECES, &pieces),
            (OBJECTS, &objects),
            (HULLS, &hulls),
            (REF_OBJECTS, &ref_objects),
            (NARROW_QUERIES, &narrow_queries),
        ];
        // a module from before the narrow-phase rounds (`bench --physics-wgsl`) binds without them
        let step_uses = if source.contains(&format!("@binding({}) var<storage, read_write> {}", NARROW_QUERIES.index, NARROW_QUERIES.name)) {
            &STEP_MAIN
        } else {
            &STEP_MAIN_WITHOUT_ROUNDS
        };
        let step_group = ctx.bind_group(&step_pipeline, step_uses, &buffers)?;
        let reset_group = ctx.bind_group(&reset_pipeline, &RESET_MAIN, &buffers)?;
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
            springs,
            narrow_queries,
            readback,
            step_pipeline,
            reset_pipeline,
            step_group,
            reset_group,
            step_workgroup_size,
            reset_workgroup_size,
            mask_host: vec![0; n],
            pending: std::sync::Mutex::new(None),
        };
        b.reset_all()?;
        Ok(b)
    }

    /// The wgpu context the batch runs on.
    pub fn context(&self) -> &GpuContext {
        &self.ctx
    }

    /// Workgroups of a dispatch over all envs (x, y: 2-D past 65535 workgroups) of kernels of
    /// [`crate::gpu::shaders::WORKGROUP_SIZE`] invocations (the task layer's).
    pub(crate) fn workgroups(&self) -> (u32, u32) {
        workgroups_for(self.model.spec.num_envs as u32)
    }

    /// The step's dispatch over all envs: `step_main`, its bind group and workgroups.
    pub(crate) fn step_pass(&self) -> Pass<'_> {
        (&self.step_pipeline, &self.step_group, self.workgroups_of_size(self.step_workgroup_size))
    }

    /// The reset's dispatch over all envs: `reset_main`, its bind group and workgroups.
    pub(crate) fn reset_pass(&self) -> Pass<'_> {
        (&self.reset_pipeline, &self.reset_group, self.workgroups_of_size(self.reset_workgroup_size))
    }

    /// Workgroups of a dispatch over all envs of an entry point of `size` invocations a workgroup.
    fn workgroups_of_size(&self, size: u32) -> (u32, u32) {
        workgroups_of(self.model.spec.num_envs as u32, size)
    }

    fn dispatch(&self, pass: Pass<'_>, what: &str) -> Result<()> {
        self.flush_pending()?;
        let enc = self.ctx.encode_dispatches(&[pass], what);
        self.ctx.submit(enc, what)
    }

    /// The recorded but unsubmitted step, taken (None when there is none).
    fn take_pending(&self) -> Option<wgpu::CommandEncoder> {
        self.pending.lock().unwrap_or_else(std::sync::PoisonError::into_inner).take()
    }

    /// Submits the step that [`EnvBatch::step`] recorded, if any. Every use of the queue other
    /// than a readback of this batch calls it first: a `queue.write_buffer` runs before the next
    /// submission, so an upload must not overtake a step recorded before it. The task layer,
    /// which records its own command buffers on the same queue, calls it too.
    pub fn flush_pending(&self) -> Result<()> {
        match self.take_pending() {
            Some(enc) => self.ctx.submit(enc, "dispatching step_main"),
            None => Ok(()),
        }
    }

    fn run_reset(&mut self) -> Result<()> {
        self.flush_pending()?;
        self.ctx.upload(RESET_MASK.name, &self.reset_mask, bytemuck::cast_slice(&self.mask_host))?;
        self.dispatch(self.reset_pass(), "dispatching reset_main")
    }

    /// Overwrites the parameters (checkpoint restore).
    pub fn set_params(&mut self, params: &[EnvParams]) -> Result<()> {
        ensure!(params.len() == self.model.spec.num_envs, "{} parameter sets for {} envs", params.len(), self.model.spec.num_envs);
        self.flush_pending()?;
        self.ctx.upload(PARAMS.name, &self.params, bytemuck::cast_slice(params))
    }

    /// Copies `count` elements of `T` from `src` (named `name` in errors) back to the host, through
    /// the batch's staging buffer or, for a larger read, a staging buffer made for it.
    pub(crate) fn read<T: Pod>(&self, src: &wgpu::Buffer, name: &str, count: usize) -> Result<Vec<T>> {
        let bytes = (count * std::mem::size_of::<T>()) as u64;
        // the recorded step, if any, and the copy in one submission
        let enc = self.take_pending().unwrap_or_else(|| self.ctx.device.create_command_encoder(&Default::default()));
        let mut out = Vec::new();
        let larger;
        let staging = if bytes <= self.readback.size() {
            &self.readback
        } else {
            larger = self.ctx.create_staging_buffer(name, bytes)?;
            &larger
        };
        let copy = ReadbackCopy { name, src, staging, bytes };
        self.ctx.submit_and_read(enc, &[copy], &format!("reading GPU buffer `{name}` back"), |_, b| out = bytemuck::pod_collect_to_vec(b))?;
        Ok(out)
    }
}

impl EnvBatch for GpuEnvBatch {
    fn spec(&self) -> &EnvSpec {
        &self.model.spec
    }

    fn step_workgroup_size(&self) -> Option<u32> {
        Some(self.step_workgroup_size)
    }

    fn device_bytes(&self) -> u64 {
        [&self.globals, &self.joints, &self.states, &self.params, &self.targets, &self.stats, &self.reset_mask, &self.springs, &self.narrow_queries, &self.readback].iter().map(|b| b.size()).sum()
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
        self.flush_pending()?;
        self.ctx.upload(TARGETS.name, &self.targets, bytemuck::cast_slice(targets))?;
        // recorded now, submitted with the next readback or before the next use of the queue
        let enc = self.ctx.encode_dispatches(&[self.step_pass()], "dispatching step_main");
        *self.pending.lock().unwrap_or_else(std::sync::PoisonError::into_inner) = Some(enc);
        Ok(())
    }

    fn states(&mut self) -> Result<Vec<EnvState>> {
        self.read(&self.states, STATES.name, self.model.spec.num_envs)
    }

    fn set_states(&mut self, states: &[EnvState]) -> Result<()> {
        ensure!(states.len() == self.model.spec.num_envs, "{} states for {} envs", states.len(), self.model.spec.num_envs);
        self.flush_pending()?;
        self.ctx.upload(STATES.name, &self.states, bytemuck::cast_slice(states))
    }

    fn springs(&mut self) -> Result<Vec<[f32; 4]>> {
        self.read(&self.springs, SPRINGS.name, self.model.spec.num_envs * self.model.globals.n_springs as usize)
    }

    fn set_springs(&mut self, springs: &[[f32; 4]]) -> Result<()> {
        let want = self.model.spec.num_envs * self.model.globals.n_springs as usize;
        ensure!(springs.len() == want, "{} contact springs for {want} (N × n_springs)", springs.len());
        self.flush_pending()?;
        self.ctx.upload(SPRINGS.name, &self.springs, bytemuck::cast_slice(springs))
    }

    fn params(&mut self) -> Result<Vec<EnvParams>> {
        self.read(&self.params, PARAMS.name, self.model.spec.num_envs)
    }

    fn set_params(&mut self, params: &[EnvParams]) -> Result<()> {
        GpuEnvBatch::set_params(self, params)
    }

    fn first_envs(&mut self, k: usize) -> Result<(Vec<EnvState>, Vec<EnvParams>, Vec<[f32; 4]>)> {
        // each buffer's first k envs: a readback of their bytes only
        let k = k.min(self.model.spec.num_envs);
        let ns = self.model.globals.n_springs as usize;
        Ok((self.read(&self.states, STATES.name, k)?, self.read(&self.params, PARAMS.name, k)?, self.read(&self.springs, SPRINGS.name, k * ns)?))
    }

    fn stats(&mut self) -> Result<Vec<StepStats>> {
        self.read(&self.stats, STATS.name, self.model.spec.num_envs)
    }
}
