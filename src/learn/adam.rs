//! Adam (Kingma & Ba 2015, torch's update rule) over a flat list of `Tensor<2>` parameters, and
//! torch's global gradient-norm clipping. Shared by every learner; its moments and step count are
//! part of the learner's checkpoint state ([`Adam::save`] / [`Adam::load`]).

use anyhow::{Context, Result, ensure};
use burn::prelude::*;

use super::kernels::fused_adam::{FusedAdam, FusedStep, StepConstants};
use super::nets::{to_host, to_tensor};
use super::state::{LearnerState, TensorValues};

/// Adam with torch's update rule, over a flat list of `Tensor<2>` parameters. On burn's wgpu
/// runtime [`Adam::step_clipped`] runs adam.wgsl's kernels (`fused_adam.rs`); elsewhere, and for
/// [`Adam::step`], tensor ops.
pub struct Adam {
    /// Decay of the first moment (β1).
    pub beta1: f64,
    /// Decay of the second moment (β2).
    pub beta2: f64,
    /// ε added to √v̂ in the denominator.
    pub eps: f64,
    /// Decoupled weight decay λ (torch's AdamW: `p ← p (1 − lr λ)` before the Adam step; 0 = Adam).
    pub weight_decay: f64,
    /// Steps taken.
    pub t: u64,
    /// First moment estimates, one per parameter (non-autodiff tensors).
    pub m: Vec<Tensor<2>>,
    /// Second moment estimates (same shapes as `m`).
    pub v: Vec<Tensor<2>>,
    /// Whether a step reports the gradients' norm (true by default). An optimiser whose learner
    /// does not read it and does not clip sets false: on a GPU its norm's kernels are then not run
    /// and [`Adam::step_clipped`] returns no norm.
    pub report_norm: bool,
    /// The kernels of a GPU learner (None on the CPU).
    fused: Option<FusedAdam>,
}

impl Adam {
    /// torch's defaults: β = (0.9, 0.999), ε = 1e-8; moments start at zero.
    pub fn new(shapes: &[[usize; 2]], device: &Device) -> Adam {
        let zeros = || shapes.iter().map(|s| Tensor::zeros(*s, device).inner()).collect::<Vec<_>>();
        // (a kernel that cannot be built leaves the tensor ops, which give the same step)
        let fused = super::device::gpu_context_of(device).and_then(|ctx| FusedAdam::new(&ctx, device, shapes).ok());
        Adam { beta1: 0.9, beta2: 0.999, eps: 1e-8, weight_decay: 0.0, t: 0, m: zeros(), v: zeros(), report_norm: true, fused }
    }

    /// On a GPU learner, the kernels one [`Adam::step_clipped`] launches (with the norm: when it
    /// clips or reports the norm); None where the step runs as tensor ops.
    pub fn gpu_kernels_per_step(&self, with_norm: bool) -> Option<usize> {
        self.fused.as_ref().map(|f| f.kernels_per_step(with_norm))
    }

    /// On a GPU learner, steps in launches over groups of at most `max` parameters (the same
    /// step; a device that binds few storage buffers gets small groups by itself).
    pub fn limit_gpu_group(&mut self, max: usize) {
        if let Some(f) = &mut self.fused {
            f.limit_group(max);
        }
    }

    /// One step from a backward pass, with torch's global-norm gradient clipping: the gradients
    /// of `params` (in order) scaled by `min(1, max_norm / (‖g‖ + 1e-6))` (not scaled when
    /// `max_norm` is 0), then [`Adam::step`] at learning rate `lr` (`[1, 1]` on the learner
    /// device, so that a schedule can change it without a host read). Returns the new leaves and
    /// `‖g‖` before clipping (`[1]`, read lazily; None when `report_norm` is off and the step did
    /// not clip). On burn's wgpu runtime this is adam.wgsl's kernels in place, three launches
    /// over all the parameters (`fused_adam.rs`), elsewhere tensor ops: the same maths.
    pub fn step_clipped(&mut self, params: &[Tensor<2>], grads: &burn::tensor::Gradients, max_norm: f64, lr: &Tensor<2>) -> Result<(Vec<Tensor<2>>, Option<Tensor<1>>)> {
        self.step_clipped_and_average(params, grads, max_norm, lr, None)
    }

    /// [`Adam::step_clipped`], then each parameter's target copy (SAC's target critics, one per
    /// parameter, non-autodiff) moved towards the new value: `t ← τ p + (1 − τ) t` (Polyak
    /// averaging; `tau` in (0, 1)). On burn's wgpu runtime in the optimiser's own kernels
    /// (`adam_update_polyak`, the targets written in place), elsewhere as tensor ops.
    pub fn step_clipped_polyak(&mut self, params: &[Tensor<2>], grads: &burn::tensor::Gradients, max_norm: f64, lr: &Tensor<2>, targets: &mut [Tensor<2>], tau: f64) -> Result<(Vec<Tensor<2>>, Option<Tensor<1>>)> {
        ensure!(targets.len() == params.len(), "{} Polyak targets for {} parameters", targets.len(), params.len());
        self.step_clipped_and_average(params, grads, max_norm, lr, Some((targets, tau)))
    }

    /// [`Adam::step_clipped`] with the Polyak average of [`Adam::step_clipped_polyak`] when
    /// `polyak` is given.
    fn step_clipped_and_average(&mut self, params: &[Tensor<2>], grads: &burn::tensor::Gradients, max_norm: f64, lr: &Tensor<2>, polyak: Option<(&mut [Tensor<2>], f64)>) -> Result<(Vec<Tensor<2>>, Option<Tensor<1>>)> {
        let gs: Vec<Tensor<2>> = params
            .iter()
            .enumerate()
            .map(|(i, p)| p.grad(grads).with_context(|| format!("parameter {i} got no gradient")))
            .collect::<Result<_>>()?;
        // data-parallel (issue 37): every rank steps with the gradients' mean over the ranks
        let gs = mean_over_ranks(gs)?;
        let lr = lr.clone().inner();
        if let Some(fused) = &self.fused {
            let t = self.t + 1;
            let c = StepConstants {
                beta1: self.beta1,
                beta2: self.beta2,
                eps: self.eps,
                bc1: 1.0 - self.beta1.powi(t as i32),
                bc2_sqrt: (1.0 - self.beta2.powi(t as i32)).sqrt(),
                weight_decay: self.weight_decay,
                max_norm,
            };
            let inner: Vec<Tensor<2>> = params.iter().map(|p| p.clone().inner()).collect();
            let targets = polyak.as_ref().map(|(ts, tau)| (&ts[..], *tau));
            if let FusedStep::Taken(norm) = fused.step(&inner, &gs, &self.m, &self.v, &lr, &c, targets, self.report_norm)? {
                self.t = t;
                let out = inner.into_iter().map(|p| p.autodiff().require_grad()).collect();
                return Ok((out, norm.map(|n| n.reshape([1]))));
            }
        }
        let (gs, norm) = clip_to_norm(gs, max_norm)?;
        let out = if !super::nets::is_gpu(&lr.device()) {
            // on the CPU a read costs nothing, and a number multiplies faster than a broadcast tensor
            let value = to_host(lr)?[0] as f64;
            self.step_at(params, gs, LearningRate::Value(value))
        } else {
            self.step_at(params, gs, LearningRate::Tensor(&lr))
        };
        if let Some((targets, tau)) = polyak {
            for (t, p) in targets.iter_mut().zip(&out) {
                *t = p.clone().inner().mul_scalar(tau) + t.clone().mul_scalar(1.0 - tau); // τ p + (1 − τ) t
            }
        }
        Ok((out, Some(norm)))
    }

    /// One step: `params[i] ← params[i] − lr/(1−β1ᵗ) · m / (√v/√(1−β2ᵗ) + ε)`. `params` are the
    /// autodiff leaves; the returned list holds new leaves (require_grad) with the updated values.
    pub fn step(&mut self, params: &[Tensor<2>], grads: Vec<Tensor<2>>, lr: f64) -> Vec<Tensor<2>> {
        self.step_at(params, grads, LearningRate::Value(lr))
    }

    /// [`Adam::step`] as tensor ops at a learning rate given as a number or as a `[1, 1]` tensor.
    fn step_at(&mut self, params: &[Tensor<2>], grads: Vec<Tensor<2>>, lr: LearningRate) -> Vec<Tensor<2>> {
        self.t += 1;
        let bc1 = 1.0 - self.beta1.powi(self.t as i32);
        let bc2_sqrt = (1.0 - self.beta2.powi(self.t as i32)).sqrt();
        let mut out = Vec::with_capacity(params.len());
        for (i, g) in grads.into_iter().enumerate() {
            // m = β1 m + (1 − β1) g;  v = β2 v + (1 − β2) g²
            self.m[i] = self.m[i].clone().mul_scalar(self.beta1) + g.clone().mul_scalar(1.0 - self.beta1);
            self.v[i] = self.v[i].clone().mul_scalar(self.beta2) + g.square().mul_scalar(1.0 - self.beta2);
            let denom = self.v[i].clone().sqrt().div_scalar(bc2_sqrt).add_scalar(self.eps);
            let mut p = params[i].clone().inner();
            let step = self.m[i].clone().div(denom);
            let p = match &lr {
                LearningRate::Value(lr) => {
                    if self.weight_decay > 0.0 {
                        p = p.mul_scalar(1.0 - lr * self.weight_decay); // AdamW: p ← p (1 − lr λ)
                    }
                    p - step.mul_scalar(lr / bc1) // p − lr/(1 − β1ᵗ) · m / (√v̂ + ε)
                }
                LearningRate::Tensor(lr) => {
                    if self.weight_decay > 0.0 {
                        p = p * (*lr).clone().mul_scalar(-self.weight_decay).add_scalar(1.0); // AdamW: p ← p (1 − lr λ)
                    }
                    p - step * (*lr).clone().div_scalar(bc1) // p − lr/(1 − β1ᵗ) · m / (√v̂ + ε)
                }
            };
            out.push(p.autodiff().require_grad());
        }
        out
    }

    /// Saves the moments as `adam.m.<name>` / `adam.v.<name>` ([rows, cols] each, f32) into `file`
    /// of `state`, and the step count as the scalar `adam_step` (`names`/`shapes`: the parameters').
    pub fn save(&self, names: &[String], shapes: &[[usize; 2]], state: &mut LearnerState, file: &str) -> Result<()> {
        self.save_as(names, shapes, state, file, "adam_step")
    }

    /// [`Adam::save`] with the step count under the scalar `step_key` (a learner with several
    /// optimisers names each one's).
    pub fn save_as(&self, names: &[String], shapes: &[[usize; 2]], state: &mut LearnerState, file: &str, step_key: &str) -> Result<()> {
        for (i, (n, s)) in names.iter().zip(shapes).enumerate() {
            state.push_tensor(file, &format!("adam.m.{n}"), s.to_vec(), TensorValues::F32(to_host(self.m[i].clone())?));
            state.push_tensor(file, &format!("adam.v.{n}"), s.to_vec(), TensorValues::F32(to_host(self.v[i].clone())?));
        }
        state.set_u64(step_key, self.t);
        Ok(())
    }

    /// Restores what [`Adam::save`] wrote (same names and shapes).
    pub fn load(&mut self, names: &[String], shapes: &[[usize; 2]], state: &LearnerState, file: &str, device: &Device) -> Result<()> {
        self.load_as(names, shapes, state, file, device, "adam_step")
    }

    /// Restores what [`Adam::save_as`] wrote.
    pub fn load_as(&mut self, names: &[String], shapes: &[[usize; 2]], state: &LearnerState, file: &str, device: &Device, step_key: &str) -> Result<()> {
        ensure!(names.len() == self.m.len(), "Adam has {} moments but {} parameters were named", self.m.len(), names.len());
        for (i, (n, s)) in names.iter().zip(shapes).enumerate() {
            self.m[i] = to_tensor(state.f32s(file, &format!("adam.m.{n}"), Some(s[0] * s[1]))?, *s, device).inner();
            self.v[i] = to_tensor(state.f32s(file, &format!("adam.v.{n}"), Some(s[0] * s[1]))?, *s, device).inner();
        }
        self.t = state.u64(step_key)?;
        Ok(())
    }
}

/// A learning rate: a number, or a `[1, 1]` tensor on the learner device.
enum LearningRate<'a> {
    Value(f64),
    Tensor(&'a Tensor<2>),
}

/// `gs` scaled so that their global L2 norm is at most `max_norm` (unscaled when it is 0), and the
/// norm before scaling `[1]` (torch's `clip_grad_norm_`: coef = min(1, max_norm / (‖g‖ + 1e-6))).
fn clip_to_norm(gs: Vec<Tensor<2>>, max_norm: f64) -> Result<(Vec<Tensor<2>>, Tensor<1>)> {
    let mut sq: Option<Tensor<1>> = None;
    for g in &gs {
        let s = super::nets::sum_all(g.clone().square()); // [1], the same bits every run
        sq = Some(match sq {
            Some(acc) => acc + s,
            None => s,
        });
    }
    let norm = sq.context("no parameters")?.sqrt(); // [1]
    if max_norm <= 0.0 {
        return Ok((gs, norm));
    }
    let coef = norm.clone().add_scalar(1e-6).recip().mul_scalar(max_norm).clamp_max(1.0); // [1]
    let coef2: Tensor<2> = coef.unsqueeze(); // [1, 1]
    let out = gs.into_iter().map(|g| g * coef2.clone()).collect();
    Ok((out, norm))
}

/// The gradients of `params` (in order) from a backward pass, clipped to a global norm of
/// `max_norm` as [`clipped_grads`] does when `max_norm > 0`, unclipped when it is 0.
pub fn grads_of(params: &[Tensor<2>], grads: &burn::tensor::Gradients, max_norm: f64) -> Result<Vec<Tensor<2>>> {
    if max_norm > 0.0 {
        return Ok(clipped_grads(params, grads, max_norm)?.0);
    }
    params.iter().enumerate().map(|(i, p)| p.grad(grads).with_context(|| format!("parameter {i} got no gradient"))).collect()
}

/// The gradients of `params` (in order) from a backward pass, scaled so that their global L2 norm
/// is at most `max_norm` (torch's `clip_grad_norm_`: coef = min(1, max_norm / (‖g‖ + 1e-6))).
/// Returns the gradients and the norm before clipping (as a [1]-tensor, read lazily).
pub fn clipped_grads(params: &[Tensor<2>], grads: &burn::tensor::Gradients, max_norm: f64) -> Result<(Vec<Tensor<2>>, Tensor<1>)> {
    let gs: Vec<Tensor<2>> = params
        .iter()
        .enumerate()
        .map(|(i, p)| p.grad(grads).with_context(|| format!("parameter {i} got no gradient")))
        .collect::<Result<_>>()?;
    clip_to_norm(gs, max_norm)
}

/// The gradients' element-wise mean over the ranks of a data-parallel job (`crate::dist`): read
/// back as one flat buffer, one all-reduce, and uploaded again in the same shapes (on a GPU
/// learner, 4 bytes per parameter each way per step). With one rank they are returned as they are.
pub fn mean_over_ranks(gs: Vec<Tensor<2>>) -> Result<Vec<Tensor<2>>> {
    // DEXTRAIN_TEST_NO_GRADIENT_MEAN (tests only): each rank steps with its own gradients, which the
    // equivalence test uses to show that without the mean the ranks drift apart
    static OFF: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    if crate::dist::size() == 1 || *OFF.get_or_init(|| std::env::var_os("DEXTRAIN_TEST_NO_GRADIENT_MEAN").is_some()) {
        return Ok(gs);
    }
    let shapes: Vec<[usize; 2]> = gs.iter().map(|g| g.dims()).collect();
    let device = gs.first().map(|g| g.device());
    let mut flat = Vec::with_capacity(shapes.iter().map(|s| s[0] * s[1]).sum());
    for g in gs {
        flat.extend(super::nets::to_host(g)?);
    }
    crate::dist::mean_f32(&mut flat);
    let Some(device) = device else { return Ok(Vec::new()) };
    let mut out = Vec::with_capacity(shapes.len());
    let mut at = 0;
    for s in shapes {
        let n = s[0] * s[1];
        out.push(super::nets::to_tensor(flat[at..at + n].to_vec(), s, &device));
        at += n;
    }
    Ok(out)
}
