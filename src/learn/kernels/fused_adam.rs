//! Adam with global-norm gradient clipping as three kernels of our own (`shaders/adam.wgsl`) over
//! burn's tensors in place, for a learner on burn's wgpu runtime (the twin of `adam.rs`'s tensor
//! ops: `clipped_grads` then `Adam::step`).
//!
//! As tensor ops an optimiser step is ~5 kernels per parameter for the norm and the clip and ~13
//! for the moments and the update: for PPO's 17 parameters ~300 kernel launches per minibatch,
//! most of them on a few thousand numbers. Here it is 2 dispatches per parameter and one more, in
//! one submission: `adam_norm_partial` (Σ g² in 64 fixed slices per parameter), `adam_norm_final`
//! (‖g‖ and the clip coefficient, into a `[1, 2]` burn tensor the learner reads with its other
//! statistics; both left out of a step that neither clips nor reports the norm), `adam_update` (the clipped gradient into m and v, then the parameter; or
//! `adam_update_polyak`, which then also moves a SAC critic's target copy towards it, where the
//! tensor ops of the Polyak average were three kernels per parameter). The
//! learning rate is a `[1, 1]` burn tensor, so PPO's adaptive schedule stays on the device.
//!
//! The kernels bind slices of cubecl's buffers (`gpu::io`: cubecl aligns every tensor to the
//! adapter's binding-offset alignment, as its own kernels bind them) and write the parameters and
//! moments in place. Ordering: what burn recorded (the backward pass) is flushed to the queue
//! first, so the kernels read finished gradients, and burn's later work (the next forward pass)
//! is submitted after ours.

use anyhow::{Context, Result, ensure};
use burn::prelude::{Device, Tensor};

use crate::gpu::io::{TensorBuffer, flush, tensor_buffer};
use crate::gpu::context::GpuContext;
use crate::gpu::shaders::{SHADER_ADAM, workgroups_of};
use crate::gpu::bindings::{ADAM_GRAD, ADAM_GROUP, ADAM_LR, ADAM_M, ADAM_NORM, ADAM_NORM_FINAL, ADAM_NORM_PARTIAL, ADAM_PARAM, ADAM_PARAM_CFG, ADAM_PARTIALS as ADAM_PARTIALS_BUF, ADAM_STEP, ADAM_TARGET, ADAM_UPDATE, ADAM_UPDATE_POLYAK, ADAM_V};
use crate::gpu_counts::{self, Event};

/// Invocations per workgroup (adam.wgsl's `ADAM_WORKGROUP`).
pub const ADAM_WORKGROUP: u32 = 256;
/// Slices of one parameter's squared norm (adam.wgsl's `ADAM_PARTIALS`).
pub const PARTIALS_PER_PARAM: u32 = 64;

/// `AdamStep` of adam.wgsl (keep in sync): the step's constants.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct AdamStep {
    pub clip: u32,
    pub beta1: f32,
    pub beta2: f32,
    pub eps: f32,
    pub bc1: f32,
    pub bc2_sqrt: f32,
    pub weight_decay: f32,
    pub max_norm: f32,
    pub tau: f32,
    pub one_minus_tau: f32,
    pub _pad0: u32,
    pub _pad1: u32,
}

/// `AdamParam` of adam.wgsl (keep in sync): one parameter's sizes.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
pub struct AdamParam {
    pub n: u32,
    pub partial_base: u32,
    pub n_partials: u32,
    pub _pad: u32,
}

/// The constants of one step (the uniform [`AdamStep`] is made from them).
#[derive(Clone, Copy, Debug)]
pub struct StepConstants {
    pub beta1: f64,
    pub beta2: f64,
    pub eps: f64,
    /// 1 − β1ᵗ.
    pub bc1: f64,
    /// √(1 − β2ᵗ).
    pub bc2_sqrt: f64,
    pub weight_decay: f64,
    /// Clip to this global norm; 0: no clipping.
    pub max_norm: f64,
}

/// adam.wgsl's pipelines and buffers for the parameters of one optimiser.
pub struct FusedAdam {
    ctx: GpuContext,
    partial: wgpu::ComputePipeline,
    fin: wgpu::ComputePipeline,
    update: wgpu::ComputePipeline,
    update_polyak: wgpu::ComputePipeline,
    /// The step's [`AdamStep`] (uploaded each step).
    step_cfg: wgpu::Buffer,
    /// One [`AdamParam`] per parameter, `slot` bytes apart (written once).
    param_cfg: wgpu::Buffer,
    slot: u64,
    /// `[n_params · PARTIALS_PER_PARAM]` f32.
    partials: wgpu::Buffer,
    /// Elements of each parameter.
    sizes: Vec<u32>,
    /// burn's wgpu device (non-autodiff) on `ctx`'s device.
    device: Device,
}

impl FusedAdam {
    /// The kernels for parameters of `shapes`, whose tensors live on `device` (burn's wgpu runtime
    /// on `ctx`'s device).
    pub fn new(ctx: &GpuContext, device: &Device, shapes: &[[usize; 2]]) -> Result<FusedAdam> {
        ensure!(!shapes.is_empty(), "an optimiser without parameters");
        let [partial, fin, update, update_polyak] =
            ctx.compute_pipelines(ADAM_GROUP.shader, SHADER_ADAM, [ADAM_NORM_PARTIAL.entry_point, ADAM_NORM_FINAL.entry_point, ADAM_UPDATE.entry_point, ADAM_UPDATE_POLYAK.entry_point])?;
        let align = ctx.device.limits().min_uniform_buffer_offset_alignment as u64;
        let slot = (std::mem::size_of::<AdamParam>() as u64).next_multiple_of(align.max(16));
        let mut bytes = vec![0u8; (slot * shapes.len() as u64) as usize];
        for (i, s) in shapes.iter().enumerate() {
            let p = AdamParam { n: (s[0] * s[1]) as u32, partial_base: i as u32 * PARTIALS_PER_PARAM, n_partials: shapes.len() as u32 * PARTIALS_PER_PARAM, _pad: 0 };
            let at = (slot * i as u64) as usize;
            bytes[at..at + std::mem::size_of::<AdamParam>()].copy_from_slice(bytemuck::bytes_of(&p));
        }
        let param_cfg = ctx.create_buffer_with(ADAM_PARAM_CFG.name, &bytes, ADAM_PARAM_CFG.space.into(), ADAM_PARAM_CFG.space.usage())?;
        let step_cfg = ctx.create_binding_buffer(ADAM_STEP, &[AdamStep::default()], wgpu::BufferUsages::empty())?;
        let partials = ctx.create_binding_buffer(ADAM_PARTIALS_BUF, &vec![0f32; shapes.len() * PARTIALS_PER_PARAM as usize], wgpu::BufferUsages::empty())?;
        let sizes = shapes.iter().map(|s| (s[0] * s[1]) as u32).collect();
        Ok(FusedAdam { ctx: ctx.clone(), partial, fin, update, update_polyak, step_cfg, param_cfg, slot, partials, sizes, device: device.clone().inner() })
    }

    /// One clipped Adam step in place: `params`, `m`, `v` (non-autodiff views of the learner's
    /// tensors) move by the gradients `grads` at learning rate `lr` `[1, 1]`. Returns
    /// [`FusedStep::Taken`] with `[‖g‖, coef]` `[1, 2]` (the norm before clipping and the factor
    /// applied) when `c.max_norm > 0` or `norm_wanted` (else the norm's P + 1 dispatches are not
    /// run), or [`FusedStep::NotTaken`] when a tensor is not a contiguous f32 tensor of burn's
    /// wgpu device (then nothing was done: the caller runs the tensor ops). With `polyak` = (targets, τ), each parameter's target copy then moves in
    /// place to `τ p + (1 − τ) t` with the new p; a target whose memory overlaps a parameter's,
    /// moment's or gradient's (the kernel would write it twice) is refused the same way.
    #[allow(clippy::too_many_arguments)]
    pub fn step(&self, params: &[Tensor<2>], grads: &[Tensor<2>], m: &[Tensor<2>], v: &[Tensor<2>], lr: &Tensor<2>, c: &StepConstants, polyak: Option<(&[Tensor<2>], f64)>, norm_wanted: bool) -> Result<FusedStep> {
        let n = self.sizes.len();
        ensure!(params.len() == n && grads.len() == n && m.len() == n && v.len() == n, "fused Adam of {n} parameters given {} parameters, {} gradients, {} m, {} v", params.len(), grads.len(), m.len(), v.len());
        let buffers = |ts: &[Tensor<2>]| ts.iter().map(tensor_buffer).collect::<Result<Vec<TensorBuffer>>>();
        let (Ok(p), Ok(g), Ok(mb), Ok(vb), Ok(lrb)) = (buffers(params), buffers(grads), buffers(m), buffers(v), tensor_buffer(lr)) else {
            return Ok(FusedStep::NotTaken);
        };
        for (i, t) in p.iter().enumerate() {
            ensure!(t.size() == 4 * self.sizes[i] as u64, "fused Adam: parameter {i} has {} bytes, {} expected", t.size(), 4 * self.sizes[i]);
        }
        let targets = match polyak {
            None => None,
            Some((ts, _)) => {
                ensure!(ts.len() == n, "fused Adam of {n} parameters given {} Polyak targets", ts.len());
                let Ok(tb) = buffers(ts) else { return Ok(FusedStep::NotTaken) };
                let others: Vec<&TensorBuffer> = p.iter().chain(&g).chain(&mb).chain(&vb).chain(&tb).collect();
                for (i, t) in tb.iter().enumerate() {
                    if t.size() != 4 * self.sizes[i] as u64 || others.iter().any(|o| !std::ptr::eq(*o, t) && overlaps(o, t)) {
                        return Ok(FusedStep::NotTaken);
                    }
                }
                Some(tb)
            }
        };
        let (tau, one_minus_tau) = polyak.map_or((0.0, 1.0), |(_, tau)| (tau as f32, (1.0 - tau) as f32));
        let norm = tensor_buffer(&Tensor::<2>::empty([1, 2], &self.device)).context("fused Adam: the norm's tensor")?;
        // the step's constants: one upload
        let step = AdamStep {
            clip: (c.max_norm > 0.0) as u32,
            beta1: c.beta1 as f32,
            beta2: c.beta2 as f32,
            eps: c.eps as f32,
            bc1: c.bc1 as f32,
            bc2_sqrt: c.bc2_sqrt as f32,
            weight_decay: c.weight_decay as f32,
            max_norm: c.max_norm as f32,
            tau,
            one_minus_tau,
            _pad0: 0,
            _pad1: 0,
        };
        self.ctx.upload(ADAM_STEP.name, &self.step_cfg, bytemuck::bytes_of(&step))?;
        let step_cfg = (&self.step_cfg, 0u64, std::mem::size_of::<AdamStep>() as u64);
        let cfg_slot = |i: usize| (&self.param_cfg, self.slot * i as u64, std::mem::size_of::<AdamParam>() as u64);
        let partials = (&self.partials, 0u64, self.partials.size());
        // the norm's passes: when clipping (the update reads the coefficient) or asked for
        let with_norm = c.max_norm > 0.0 || norm_wanted;
        let mut groups = Vec::with_capacity(2 * n + 1);
        if with_norm {
            for i in 0..n {
                groups.push(self.ctx.bind_group_slices(&self.partial, &ADAM_NORM_PARTIAL, &[(ADAM_PARAM_CFG, cfg_slot(i)), (ADAM_GRAD, g[i].slice()), (ADAM_PARTIALS_BUF, partials)])?);
            }
            groups.push(self.ctx.bind_group_slices(&self.fin, &ADAM_NORM_FINAL, &[(ADAM_STEP, step_cfg), (ADAM_PARAM_CFG, cfg_slot(0)), (ADAM_PARTIALS_BUF, partials), (ADAM_NORM, norm.slice())])?);
        }
        let first_update = groups.len();
        let (update, update_entry) = if targets.is_some() { (&self.update_polyak, &ADAM_UPDATE_POLYAK) } else { (&self.update, &ADAM_UPDATE) };
        for i in 0..n {
            let mut uses = vec![
                (ADAM_STEP, step_cfg),
                (ADAM_PARAM_CFG, cfg_slot(i)),
                (ADAM_PARAM, p[i].slice()),
                (ADAM_GRAD, g[i].slice()),
                (ADAM_M, mb[i].slice()),
                (ADAM_V, vb[i].slice()),
                (ADAM_NORM, norm.slice()),
                (ADAM_LR, lrb.slice()),
            ];
            if let Some(tb) = &targets {
                uses.push((ADAM_TARGET, tb[i].slice()));
            }
            groups.push(self.ctx.bind_group_slices(update, update_entry, &uses)?);
        }
        let mut enc = self.ctx.device.create_command_encoder(&Default::default());
        {
            // profiling (gpu::profile): the whole step is one span, `kernel:adam`
            let mut profiler = self.ctx.profiler();
            let first = profiler.as_mut().and_then(|p| p.reserve("kernel:adam"));
            let timestamp_writes = profiler.as_ref().zip(first).map(|(p, f)| p.pass_writes(f));
            let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor { label: None, timestamp_writes });
            if with_norm {
                for group in &groups[..n] {
                    pass.set_pipeline(&self.partial);
                    pass.set_bind_group(0, group, &[]);
                    pass.dispatch_workgroups(PARTIALS_PER_PARAM, 1, 1);
                }
                pass.set_pipeline(&self.fin);
                pass.set_bind_group(0, &groups[n], &[]);
                pass.dispatch_workgroups(1, 1, 1);
            }
            for (i, group) in groups[first_update..].iter().enumerate() {
                pass.set_pipeline(update);
                pass.set_bind_group(0, group, &[]);
                let (x, y) = workgroups_of(self.sizes[i], ADAM_WORKGROUP);
                pass.dispatch_workgroups(x, y, 1);
            }
        }
        gpu_counts::add_n(Event::Kernel, "dextrain:adam", groups.len() as u64);
        // the backward pass that made the gradients runs first (module documentation)
        flush(&self.device)?;
        self.ctx.submit(enc, "the optimiser step (adam.wgsl)")?;
        Ok(FusedStep::Taken(with_norm.then_some(norm.tensor)))
    }
}

/// What [`FusedAdam::step`] did.
pub enum FusedStep {
    /// A tensor was not ours to bind: nothing was done.
    NotTaken,
    /// The step ran, with `[‖g‖, coef]` `[1, 2]` when its norm was worked out.
    Taken(Option<Tensor<2>>),
}

/// Whether two tensors' memory shares a byte.
fn overlaps(a: &TensorBuffer, b: &TensorBuffer) -> bool {
    a.buffer() == b.buffer() && a.offset() < b.offset() + b.size() && b.offset() < a.offset() + a.size()
}
