//! MLPs as plain burn tensors (shared by every learner: PPO's actor and critic, SAC's actor and
//! Q critics, the distilled student). Adam and gradient clipping are in `adam.rs`.
//!
//! Every parameter is a `Tensor<2>`: a layer's weight is `[in, out]`, its bias `[1, out]` (broadcast
//! over the batch), the actor's log-std `[1, A]`. Keeping them in one flat list (actor layers, log-std,
//! critic layers) makes Adam, gradient clipping and checkpoints one loop each, and lets the same code
//! run on burn's CPU (flex) and wgpu devices.

use anyhow::{Result, anyhow};
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
