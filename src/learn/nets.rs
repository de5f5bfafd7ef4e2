//! The actor and critic MLPs as plain burn tensors, and Adam with global gradient-norm clipping.
//!
//! Every parameter is a `Tensor<2>`: a layer's weight is `[in, out]`, its bias `[1, out]` (broadcast
//! over the batch), the actor's log-std `[1, A]`. Keeping them in one flat list (actor layers, log-std,
//! critic layers) makes Adam, gradient clipping and checkpoints one loop each, and lets the same code
//! run on burn's CPU (flex) and wgpu devices.

use anyhow::{Context, Result, anyhow};
use burn::prelude::*;
use burn::tensor::{TensorData, activation};

use super::rng::Rng;

/// Hidden-layer activation (`policy.activation`; the enum is the config's).
pub use crate::config::Activation;

impl Activation {
    /// The activation applied element-wise.
    pub fn apply(self, x: Tensor<2>) -> Tensor<2> {
        match self {
            // ELU(x) = max(x, 0) + exp(min(x, 0)) − 1, written with relu: burn's `elu` uses
            // mask_where, which burn's CPU backend runs on a slow generic path under autodiff
            Activation::Elu => activation::relu(x.clone()) + activation::relu(-x).neg().exp().sub_scalar(1.0),
            Activation::Relu => activation::relu(x),
            Activation::Tanh => activation::tanh(x),
        }
    }
}

/// Shapes of an MLP's parameters: `[w0, b0, w1, b1, …]` for widths `in → hidden… → out`.
pub fn mlp_shapes(input: usize, hidden: &[usize], output: usize) -> Vec<[usize; 2]> {
    let mut widths = vec![input];
    widths.extend_from_slice(hidden);
    widths.push(output);
    widths.windows(2).flat_map(|w| [[w[0], w[1]], [1, w[1]]]).collect()
}

/// torch.nn.Linear's default initialisation: weights and biases U(−1/√fan_in, 1/√fan_in).
pub fn init_mlp(shapes: &[[usize; 2]], rng: &mut Rng) -> Vec<Vec<f32>> {
    let mut out = Vec::new();
    for layer in shapes.chunks(2) {
        let bound = 1.0 / (layer[0][0] as f64).sqrt(); // fan_in = rows of the weight
        for s in layer {
            out.push((0..s[0] * s[1]).map(|_| ((2.0 * rng.uniform() - 1.0) * bound) as f32).collect());
        }
    }
    out
}

/// `h = act(h W + b)` for every layer but the last: x [B, in] → [B, out].
pub fn mlp_forward(params: &[Tensor<2>], x: Tensor<2>, act: Activation) -> Tensor<2> {
    let layers = params.len() / 2;
    let mut h = x;
    for l in 0..layers {
        h = h.matmul(params[2 * l].clone()) + params[2 * l + 1].clone(); // [B, out] + [1, out]
        if l + 1 < layers {
            h = act.apply(h);
        }
    }
    h
}

/// A host matrix → a tensor on `device`.
pub fn to_tensor(data: Vec<f32>, shape: [usize; 2], device: &Device) -> Tensor<2> {
    Tensor::from_data(TensorData::new(data, shape), device)
}

/// A tensor → its values on the host (row-major).
pub fn to_host<const D: usize>(t: Tensor<D>) -> Result<Vec<f32>> {
    t.into_data().try_to_vec::<f32>().map_err(|e| anyhow!("cannot read a tensor back: {e:?}"))
}

/// Adam (Kingma & Ba) with torch's update rule, over a flat list of `Tensor<2>` parameters.
pub struct Adam {
    pub beta1: f64,
    pub beta2: f64,
    pub eps: f64,
    /// Steps taken.
    pub t: u64,
    /// First and second moment estimates, one per parameter (non-autodiff tensors).
    pub m: Vec<Tensor<2>>,
    pub v: Vec<Tensor<2>>,
}

impl Adam {
    /// torch's defaults: β = (0.9, 0.999), ε = 1e-8; moments start at zero.
    pub fn new(shapes: &[[usize; 2]], device: &Device) -> Adam {
        let zeros = || shapes.iter().map(|s| Tensor::zeros(*s, device).inner()).collect::<Vec<_>>();
        Adam { beta1: 0.9, beta2: 0.999, eps: 1e-8, t: 0, m: zeros(), v: zeros() }
    }

    /// One step: `params[i] ← params[i] − lr/(1−β1ᵗ) · m / (√v/√(1−β2ᵗ) + ε)`. `params` are the
    /// autodiff leaves; the returned list holds new leaves (require_grad) with the updated values.
    pub fn step(&mut self, params: &[Tensor<2>], grads: Vec<Tensor<2>>, lr: f64) -> Vec<Tensor<2>> {
        self.t += 1;
        let bc1 = 1.0 - self.beta1.powi(self.t as i32);
        let bc2_sqrt = (1.0 - self.beta2.powi(self.t as i32)).sqrt();
        let step_size = lr / bc1;
        let mut out = Vec::with_capacity(params.len());
        for (i, g) in grads.into_iter().enumerate() {
            // m = β1 m + (1 − β1) g;  v = β2 v + (1 − β2) g²
            self.m[i] = self.m[i].clone().mul_scalar(self.beta1) + g.clone().mul_scalar(1.0 - self.beta1);
            self.v[i] = self.v[i].clone().mul_scalar(self.beta2) + g.square().mul_scalar(1.0 - self.beta2);
            let denom = self.v[i].clone().sqrt().div_scalar(bc2_sqrt).add_scalar(self.eps);
            let p = params[i].clone().inner() - self.m[i].clone().div(denom).mul_scalar(step_size);
            out.push(p.autodiff().require_grad());
        }
        out
    }
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
    let mut sq: Option<Tensor<1>> = None;
    for g in &gs {
        let s = g.clone().square().sum(); // [1]
        sq = Some(match sq {
            Some(acc) => acc + s,
            None => s,
        });
    }
    let norm = sq.context("no parameters")?.sqrt(); // [1]
    let coef = norm.clone().add_scalar(1e-6).recip().mul_scalar(max_norm).clamp_max(1.0); // [1]
    let coef2: Tensor<2> = coef.unsqueeze(); // [1, 1]
    let out = gs.into_iter().map(|g| g * coef2.clone()).collect();
    Ok((out, norm))
}
