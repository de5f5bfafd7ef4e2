//! Adam with global-norm gradient clipping as kernels of our own (`shaders/adam.wgsl`) over
//! burn's tensors in place, for a learner on burn's wgpu runtime (the twin of `adam.rs`'s tensor
//! ops: `clip_to_norm` then `Adam::step`).
//!
//! As tensor ops an optimiser step is ~5 kernels per parameter for the norm and the clip and ~13
//! for the moments and the update: for PPO's 17 parameters ~300 kernel launches per minibatch,
//! most of them on a few thousand numbers. Here a step is three launches on burn's command stream
//! (no flush, no submission of ours), each over all the parameters at once where the device binds
//! enough storage buffers (else over groups of them: [`FusedAdam::kernels_per_step`]):
//! `adam_norm_partial` (Σ g² of each gradient in 64 fixed slices), `adam_norm_final` (‖g‖ into a
//! `[1, 1]` burn tensor the learner reads with its other statistics, and the clip coefficient;
//! both left out of a step that neither clips nor reports the norm), `adam_update` (the clipped
//! gradient into m and v, then the parameter; or `adam_update_polyak`, which then also moves a SAC
//! critic's target copy towards it, where the tensor ops of the Polyak average were three kernels
//! per parameter). The learning rate is a `[1, 1]` burn tensor, so PPO's adaptive schedule stays
//! on the device. Until 2026-12-01 it was two dispatches per parameter and one more in a pass and
//! a submission of ours (2 P + 1 kernels, plus a slice of the norm): the same sums in the same
//! order and the same arithmetic per element, so the same bits.

use anyhow::{Result, ensure};
use burn::backend::tensor::FloatTensor;
use burn::backend::Cube;
use burn::prelude::{Device, Tensor};

use crate::gpu::context::GpuContext;
use crate::gpu::io::{TensorBuffer, tensor_buffer};
use crate::gpu::shaders::workgroups_of;
use crate::learn::kernels::wgsl_kernel::{WgslKernel, entry_module, indexed_getter, indexed_setter, launch, plain_primitive};

/// Invocations per workgroup (adam.wgsl's `ADAM_WORKGROUP`).
pub const ADAM_WORKGROUP: u32 = 256;
/// Slices of one parameter's squared norm (adam.wgsl's `ADAM_PARTIALS`).
pub const PARTIALS_PER_PARAM: u32 = 64;

/// The template of the optimiser's kernels.
const TEMPLATE: &str = include_str!("../../../shaders/adam.wgsl");

/// adam.wgsl's entry points.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum AdamEntry {
    /// Σ g² of each gradient of a group in fixed slices.
    NormPartial,
    /// ‖g‖ and the clip coefficient from every slice.
    NormFinal,
    /// The Adam step of a group's parameters.
    Update,
    /// The Adam step, then each parameter's target copy moved towards it.
    UpdatePolyak,
}

impl AdamEntry {
    /// The `@compute` function's name.
    pub fn name(self) -> &'static str {
        match self {
            AdamEntry::NormPartial => "adam_norm_partial",
            AdamEntry::NormFinal => "adam_norm_final",
            AdamEntry::Update => "adam_update",
            AdamEntry::UpdatePolyak => "adam_update_polyak",
        }
    }
}

/// One variant of the template: an entry point over a group of `group` parameters.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct AdamKernel {
    /// The entry point.
    pub entry: AdamEntry,
    /// Parameters per launch (1 for `NormFinal`).
    pub group: u32,
}

/// The roles of a parameter's tensors in a launch of `entry`, in binding order (each role's
/// `group` bindings, parameter 0 first): (binding name prefix, getter, setter).
fn roles(entry: AdamEntry) -> &'static [(&'static str, &'static str, Option<&'static str>)] {
    match entry {
        AdamEntry::NormPartial => &[("adam_g", "grad", None)],
        AdamEntry::NormFinal => &[],
        AdamEntry::Update => &[("adam_p", "param", Some("set_param")), ("adam_g", "grad", None), ("adam_m", "moment1", Some("set_moment1")), ("adam_v", "moment2", Some("set_moment2"))],
        AdamEntry::UpdatePolyak => &[
            ("adam_p", "param", Some("set_param")),
            ("adam_g", "grad", None),
            ("adam_m", "moment1", Some("set_moment1")),
            ("adam_v", "moment2", Some("set_moment2")),
            ("adam_t", "polyak_target", Some("set_polyak_target")),
        ],
    }
}

/// The shared tensors a launch of `entry` binds after the parameters' (in order).
fn shared_bindings(entry: AdamEntry) -> &'static [(&'static str, &'static str)] {
    match entry {
        AdamEntry::NormPartial => &[("adam_partials", "[n_params · ADAM_PARTIALS]")],
        AdamEntry::NormFinal => &[("adam_partials", "[n_params · ADAM_PARTIALS]"), ("adam_norm", "[1]"), ("adam_coef", "[1]")],
        AdamEntry::Update | AdamEntry::UpdatePolyak => &[("adam_coef", "[1]"), ("adam_lr", "[1]")],
    }
}

/// Storage buffers a launch of `entry` over `group` parameters binds.
pub fn storage_bindings(entry: AdamEntry, group: u32) -> u32 {
    roles(entry).len() as u32 * group + shared_bindings(entry).len() as u32
}

/// The WGSL of one variant: the template's common text and `key.entry`'s sections (`//@entry
/// NAMES` … `//@end`), its bindings, and the accessors that pick parameter k's binding.
pub fn shader_source(key: AdamKernel) -> String {
    let group = key.group.max(1);
    let kept = entry_module(TEMPLATE, key.entry.name());
    let mut bindings = String::new();
    let mut at = 0u32;
    for (prefix, _, _) in roles(key.entry) {
        for k in 0..group {
            bindings += &format!("@group(0) @binding({at}) var<storage, read_write> {prefix}_{k}: array<f32>;\n");
            at += 1;
        }
    }
    for (name, shape) in shared_bindings(key.entry) {
        bindings += &format!("@group(0) @binding({at}) var<storage, read_write> {name}: array<f32>; // {shape}\n");
        at += 1;
    }
    bindings += &format!("@group(0) @binding({at}) var<uniform> ac: AdamLaunch;");
    // each role's getter (and setter): a switch on the parameter's index in the group, the same
    // index across a workgroup (no divergence)
    let mut accessors = String::new();
    for (prefix, get, set) in roles(key.entry) {
        accessors += &indexed_getter(get, prefix, group);
        if let Some(set) = set {
            accessors += &indexed_setter(set, prefix, group);
        }
    }
    kept.replace("$GROUP", &group.to_string()).replace("$BINDINGS", &bindings).replace("$ACCESSORS", &accessors)
}

/// The constants of one step.
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

/// The optimiser's kernels for the parameters of one optimiser.
pub struct FusedAdam {
    ctx: GpuContext,
    /// Elements of each parameter.
    sizes: Vec<u32>,
    /// Parameters per launch: all of them where the device binds enough storage buffers.
    group: usize,
    /// `[1, n_params · PARTIALS_PER_PARAM]`: the squared norm's partial sums (every slot written
    /// by each step that works the norm out).
    partials: FloatTensor<Cube>,
    /// `[1, 1]`: the clip coefficient of the step.
    coef: FloatTensor<Cube>,
    /// burn's wgpu device (non-autodiff) on `ctx`'s device.
    device: Device,
}

impl FusedAdam {
    /// The kernels for parameters of `shapes`, whose tensors live on `device` (burn's wgpu runtime
    /// on `ctx`'s device).
    pub fn new(ctx: &GpuContext, device: &Device, shapes: &[[usize; 2]]) -> Result<FusedAdam> {
        ensure!(!shapes.is_empty(), "an optimiser without parameters");
        let device = device.clone().inner();
        // the largest group whose Polyak update (5 bindings a parameter, 2 shared) the device binds
        let limit = ctx.device.limits().max_storage_buffers_per_shader_stage;
        let group = (1..=shapes.len()).rev().find(|&g| storage_bindings(AdamEntry::UpdatePolyak, g as u32) <= limit).unwrap_or(1);
        ensure!(storage_bindings(AdamEntry::UpdatePolyak, 1) <= limit, "the device binds {limit} storage buffers per kernel, the optimiser needs {}", storage_bindings(AdamEntry::UpdatePolyak, 1));
        let zeros = |cols: usize| plain_primitive(&Tensor::<2>::zeros([1, cols], &device), [1, cols]);
        let partials = zeros(shapes.len() * PARTIALS_PER_PARAM as usize)?;
        let coef = zeros(1)?;
        let sizes = shapes.iter().map(|s| (s[0] * s[1]) as u32).collect();
        Ok(FusedAdam { ctx: ctx.clone(), sizes, group, partials, coef, device })
    }

    /// Launches over groups of at most `max` parameters (at least one; a device's own limit may
    /// make them smaller already): the same step in more launches (tests compare the two).
    pub fn limit_group(&mut self, max: usize) {
        self.group = self.group.min(max.max(1));
    }

    /// Kernels one step launches: with the norm (clipping, or the norm reported) 2 ⌈P / G⌉ + 1,
    /// else ⌈P / G⌉ for P parameters in groups of G.
    pub fn kernels_per_step(&self, with_norm: bool) -> usize {
        let groups = self.sizes.len().div_ceil(self.group);
        if with_norm { 2 * groups + 1 } else { groups }
    }

    /// One clipped Adam step in place: `params`, `m`, `v` (non-autodiff views of the learner's
    /// tensors) move by the gradients `grads` at learning rate `lr` `[1, 1]`. Returns
    /// [`FusedStep::Taken`] with `‖g‖` `[1, 1]` (the norm before clipping) when `c.max_norm > 0`
    /// or `norm_wanted` (else the norm's kernels are not run), or [`FusedStep::NotTaken`] when a
    /// tensor is not a contiguous f32 tensor of burn's wgpu device (then nothing was done: the
    /// caller runs the tensor ops). With `polyak` = (targets, τ), each parameter's target copy then
    /// moves in place to `τ p + (1 − τ) t` with the new p; a target whose memory overlaps a
    /// parameter's, moment's or gradient's (the kernel would write it twice) is refused the same way.
    #[allow(clippy::too_many_arguments)]
    pub fn step(&self, params: &[Tensor<2>], grads: &[Tensor<2>], m: &[Tensor<2>], v: &[Tensor<2>], lr: &Tensor<2>, c: &StepConstants, polyak: Option<(&[Tensor<2>], f64)>, norm_wanted: bool) -> Result<FusedStep> {
        let n = self.sizes.len();
        ensure!(params.len() == n && grads.len() == n && m.len() == n && v.len() == n, "fused Adam of {n} parameters given {} parameters, {} gradients, {} m, {} v", params.len(), grads.len(), m.len(), v.len());
        // each tensor's primitive, which the kernels bind and index flat (a tensor that is not a
        // contiguous f32 tensor of burn's wgpu device leaves the step to the tensor ops)
        let prims = |ts: &[Tensor<2>]| ts.iter().map(|t| plain_primitive(&t.clone().inner(), t.dims())).collect::<Result<Vec<FloatTensor<Cube>>>>();
        for (i, t) in params.iter().enumerate() {
            ensure!(t.shape().num_elements() == self.sizes[i] as usize, "fused Adam: parameter {i} has {} elements, {} expected", t.shape().num_elements(), self.sizes[i]);
        }
        let (Ok(p), Ok(g), Ok(mb), Ok(vb), Ok(lrb)) = (prims(params), prims(grads), prims(m), prims(v), plain_primitive(&lr.clone().inner(), [1, 1])) else {
            return Ok(FusedStep::NotTaken);
        };
        let targets = match polyak {
            None => None,
            Some((ts, _)) => {
                ensure!(ts.len() == n, "fused Adam of {n} parameters given {} Polyak targets", ts.len());
                // a target must share no byte with another tensor of the step
                let buffers = |ts: &[Tensor<2>]| ts.iter().map(tensor_buffer).collect::<Result<Vec<TensorBuffer>>>();
                let (Ok(tb), Ok(pb), Ok(gb), Ok(mbb), Ok(vbb)) = (buffers(ts), buffers(params), buffers(grads), buffers(m), buffers(v)) else { return Ok(FusedStep::NotTaken) };
                let others: Vec<&TensorBuffer> = pb.iter().chain(&gb).chain(&mbb).chain(&vbb).chain(&tb).collect();
                for (i, t) in tb.iter().enumerate() {
                    if t.size() != 4 * self.sizes[i] as u64 || others.iter().any(|o| !std::ptr::eq(*o, t) && overlaps(o, t)) {
                        return Ok(FusedStep::NotTaken);
                    }
                }
                let Ok(tp) = prims(ts) else { return Ok(FusedStep::NotTaken) };
                Some(tp)
            }
        };
        let (tau, one_minus_tau) = polyak.map_or((0.0, 1.0), |(_, tau)| (tau as f32, (1.0 - tau) as f32));
        let norm = plain_primitive(&Tensor::<2>::empty([1, 1], &self.device), [1, 1])?;
        let with_norm = c.max_norm > 0.0 || norm_wanted;
        // the launch's constants: AdamLaunch of adam.wgsl, the group's (elements, first
        // workgroup) after the step's
        let constants = |first: usize, count: usize| -> (Vec<u32>, u32) {
            let mut words = vec![
                (c.max_norm > 0.0) as u32,
                (c.beta1 as f32).to_bits(),
                (c.beta2 as f32).to_bits(),
                (c.eps as f32).to_bits(),
                (c.bc1 as f32).to_bits(),
                (c.bc2_sqrt as f32).to_bits(),
                (c.weight_decay as f32).to_bits(),
                (c.max_norm as f32).to_bits(),
                tau.to_bits(),
                one_minus_tau.to_bits(),
                first as u32 * PARTIALS_PER_PARAM,
                n as u32 * PARTIALS_PER_PARAM,
            ];
            let mut workgroups = 0u32;
            for &size in &self.sizes[first..first + count] {
                words.extend([size, workgroups, 0, 0]);
                workgroups += size.div_ceil(ADAM_WORKGROUP);
            }
            (words, workgroups)
        };
        let kernel = |entry: AdamEntry, group: usize| WgslKernel { name: "dextrain_adam", key: AdamKernel { entry, group: group as u32 }, source: shader_source, entry_point: entry.name(), workgroup: [ADAM_WORKGROUP, 1] };
        // each group's (first parameter, parameters, launch constants, update workgroups)
        let groups: Vec<(usize, usize, Vec<u32>, u32)> = (0..n)
            .step_by(self.group)
            .map(|first| {
                let count = self.group.min(n - first);
                let (words, workgroups) = constants(first, count);
                (first, count, words, workgroups)
            })
            .collect();
        // profiling (gpu::profile): the whole step is one span of burn's stream, `burn:adam`
        crate::gpu::profile::around_burn(Some(&self.ctx), &self.device, "adam", || {
            if with_norm {
                for (first, count, words, _) in &groups {
                    let (first, count) = (*first, *count);
                    let mut buffers: Vec<&FloatTensor<Cube>> = g[first..first + count].iter().collect();
                    buffers.push(&self.partials);
                    launch(kernel(AdamEntry::NormPartial, count), [PARTIALS_PER_PARAM, count as u32, 1], &buffers, words);
                }
                let (words, _) = constants(0, 1);
                launch(kernel(AdamEntry::NormFinal, 1), [1, 1, 1], &[&self.partials, &norm, &self.coef], &words);
            }
            for (first, count, words, workgroups) in &groups {
                let range = *first..first + count;
                let mut buffers: Vec<&FloatTensor<Cube>> = p[range.clone()].iter().chain(&g[range.clone()]).chain(&mb[range.clone()]).chain(&vb[range.clone()]).collect();
                let entry = match &targets {
                    Some(tp) => {
                        buffers.extend(&tp[range]);
                        AdamEntry::UpdatePolyak
                    }
                    None => AdamEntry::Update,
                };
                buffers.extend([&self.coef, &lrb]);
                // workgroups numbered along x then y (adam.wgsl's adam_place)
                let (x, y) = workgroups_of(workgroups * ADAM_WORKGROUP, ADAM_WORKGROUP);
                launch(kernel(entry, *count), [x, y, 1], &buffers, words);
            }
            Ok(())
        })?;
        Ok(FusedStep::Taken(with_norm.then(|| Tensor::from_primitive::<Cube>(norm))))
    }
}

/// What [`FusedAdam::step`] did.
pub enum FusedStep {
    /// A tensor was not ours to bind: nothing was done.
    NotTaken,
    /// The step ran, with `‖g‖` `[1, 1]` when its norm was worked out.
    Taken(Option<Tensor<2>>),
}

/// Whether two tensors' memory shares a byte.
fn overlaps(a: &TensorBuffer, b: &TensorBuffer) -> bool {
    a.buffer() == b.buffer() && a.offset() < b.offset() + b.size() && b.offset() < a.offset() + a.size()
}
