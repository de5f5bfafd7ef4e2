//! A GRU on flat tensors (the student's adaptation module over its history window), in the
//! formulation that ONNX's `GRU` op computes with `linear_before_reset = 1` (PyTorch's), so that
//! `export::onnx` writes it as one node:
//!
//! z = σ(x W_z + b_iz + h U_z + b_hz), r = σ(x W_r + b_ir + h U_r + b_hr),
//! n = tanh(x W_n + b_in + r ⊙ (h U_n + b_hn)), h' = (1 − z) ⊙ n + z ⊙ h, h₀ = 0.
//!
//! Parameters `[w_ih [D, 3H], w_hh [H, 3H], b_ih [1, 3H], b_hh [1, 3H]]`, column blocks in ONNX's
//! gate order z | r | n, as `Tensor<2>` like `nets.rs`' layers (one list for Adam, clipping and
//! checkpoints).

use burn::prelude::*;
use burn::tensor::activation::sigmoid;

use crate::rng::Rng;

/// Shapes of a GRU's parameters for input size `input` (D) and hidden size `hidden` (H).
pub fn gru_shapes(input: usize, hidden: usize) -> Vec<[usize; 2]> {
    vec![[input, 3 * hidden], [hidden, 3 * hidden], [1, 3 * hidden], [1, 3 * hidden]]
}

/// torch.nn.GRU's initialisation: every parameter U(−1/√H, 1/√H).
pub fn init_gru(input: usize, hidden: usize, rng: &mut Rng) -> Vec<Vec<f32>> {
    let bound = 1.0 / (hidden as f64).sqrt();
    gru_shapes(input, hidden).iter().map(|s| (0..s[0] * s[1]).map(|_| ((2.0 * rng.uniform() - 1.0) * bound) as f32).collect()).collect()
}

/// The last hidden state h_T [B, H] of the GRU `params` run over a window `x` [B, T·D] (row-major
/// [B, T, D], oldest step first) from h₀ = 0.
pub fn gru_forward(params: &[Tensor<2>], x: Tensor<2>, steps: usize) -> Tensor<2> {
    let [w_ih, w_hh, b_ih, b_hh] = [&params[0], &params[1], &params[2], &params[3]];
    let [d, h3] = w_ih.dims();
    let hs = h3 / 3;
    let b = x.dims()[0];
    // every step's input projection in one matmul: [B·T, D] · [D, 3H] + b_i → [B, T·3H] (row-major
    // [B, T, 3H]); the recurrence below is left with h U only
    let gi_all = (x.reshape([b * steps, d]).matmul(w_ih.clone()) + b_ih.clone()).reshape([b, steps * h3]);
    let mut h = Tensor::<2>::zeros([b, hs], &gi_all.device());
    for t in 0..steps {
        let block = |g: &Tensor<2>, k: usize| g.clone().slice([0..b, k * hs..(k + 1) * hs]);
        let gi = gi_all.clone().slice([0..b, t * h3..(t + 1) * h3]); // [B, 3H]: x_t W + b_i
        let gh = h.clone().matmul(w_hh.clone()) + b_hh.clone(); // [B, 3H]: h U + b_h
        let z = sigmoid(block(&gi, 0) + block(&gh, 0));
        let r = sigmoid(block(&gi, 1) + block(&gh, 1));
        // linear_before_reset: r multiplies (h U_n + b_hn)
        let n = (block(&gi, 2) + r * block(&gh, 2)).tanh();
        // h' = (1 − z) ⊙ n + z ⊙ h = n + z ⊙ (h − n)
        h = n.clone() + z * (h - n);
    }
    h
}
