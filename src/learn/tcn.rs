//! A temporal-convolution adaptation module on flat tensors (HORA's `ProprioAdaptTConv`, RMA's
//! adaptation module), the student's second choice of φ beside the GRU (`distill.adaptation =
//! "tcn"`):
//!
//! e_t = ReLU(ReLU(x_t W_0 + b_0) W_1 + b_1)                         (each step, [D] → [C])
//! y_{t'} = ReLU(b + Σ_{k<K} e_{t'·S + k} W_k)                          (each convolution, [C] → [C])
//! φ(x) = flatten(y) [T'·C], time-major (index t'·C + c)
//!
//! which is ONNX's `Conv` (no padding, no dilation) on [B, C, T] with weight W[o, c, k] = W_k[c, o];
//! `export::onnx` writes it as MatMul/Add/Relu, Transpose, Conv/Relu…, Transpose, Flatten.
//!
//! Parameters `[embed.0.weight [D, C], embed.0.bias [1, C], embed.1.weight [C, C], embed.1.bias
//! [1, C], then per convolution weight [K·C, C] (row k·C + c: the window's step k, channel c) and
//! bias [1, C]]`, as `Tensor<2>` like `nets.rs`' layers.

use burn::prelude::*;
use burn::tensor::activation::relu;

use crate::rng::Rng;

/// Layers of the step embedding.
pub const EMBED_LAYERS: usize = 2;

pub use crate::config::learn::tcn_steps_out as steps_out;

/// Shapes of a TCN's parameters for step size `input` (D) and `channels` (C).
pub fn tcn_shapes(input: usize, channels: usize, convs: &[(usize, usize)]) -> Vec<[usize; 2]> {
    let mut s = vec![[input, channels], [1, channels], [channels, channels], [1, channels]];
    for &(k, _) in convs {
        s.push([k * channels, channels]);
        s.push([1, channels]);
    }
    s
}

/// Checkpoint names of a TCN's parameters, in [`tcn_shapes`]' order.
pub fn tcn_names(convs: usize) -> Vec<String> {
    let mut n: Vec<String> = (0..EMBED_LAYERS).flat_map(|k| [format!("tcn.embed.{k}.weight"), format!("tcn.embed.{k}.bias")]).collect();
    n.extend((0..convs).flat_map(|k| [format!("tcn.conv.{k}.weight"), format!("tcn.conv.{k}.bias")]));
    n
}

/// torch's initialisation of Linear and Conv1d: weight and bias U(−1/√fan_in, 1/√fan_in), fan_in =
/// inputs (Linear) or C·K (Conv1d).
pub fn init_tcn(input: usize, channels: usize, convs: &[(usize, usize)], rng: &mut Rng) -> Vec<Vec<f32>> {
    let shapes = tcn_shapes(input, channels, convs);
    shapes
        .chunks(2)
        .flat_map(|wb| {
            // the weight's rows are its fan-in (Linear: inputs; Conv1d: K·C)
            let bound = 1.0 / (wb[0][0] as f64).sqrt();
            wb.iter().map(move |s| (s[0], s[1], bound)).collect::<Vec<_>>()
        })
        .map(|(r, c, bound)| (0..r * c).map(|_| ((2.0 * rng.uniform() - 1.0) * bound) as f32).collect())
        .collect()
}

/// φ(x) [B, T'·C] (time-major) of the TCN `params` over windows `x` [B, T·D] (row-major [B, T, D],
/// oldest step first).
pub fn tcn_forward(params: &[Tensor<2>], x: Tensor<2>, steps: usize, convs: &[(usize, usize)]) -> Tensor<2> {
    let [d, c] = params[0].dims();
    let b = x.dims()[0];
    // the step embedding on every step at once: [B·T, D] → [B·T, C]
    let mut e = x.reshape([b * steps, d]);
    for k in 0..EMBED_LAYERS {
        e = relu(e.matmul(params[2 * k].clone()) + params[2 * k + 1].clone());
    }
    let mut h = e.reshape([b, steps * c]); // [B, T·C], time-major
    let mut t = steps;
    for (j, &(k, s)) in convs.iter().enumerate() {
        let (w, bias) = (&params[2 * (EMBED_LAYERS + j)], &params[2 * (EMBED_LAYERS + j) + 1]);
        let t_out = (t - k) / s + 1;
        // each output step's window of K input steps: columns [t'·S·C, (t'·S + K)·C) → [B, T'·K·C]
        let windows: Vec<Tensor<2>> = (0..t_out).map(|to| h.clone().slice([0..b, to * s * c..(to * s + k) * c])).collect();
        let cols = Tensor::cat(windows, 1).reshape([b * t_out, k * c]);
        // y = ReLU(window · W + b): [B·T', K·C] · [K·C, C]
        h = relu(cols.matmul(w.clone()) + bias.clone()).reshape([b, t_out * c]);
        t = t_out;
    }
    h
}
