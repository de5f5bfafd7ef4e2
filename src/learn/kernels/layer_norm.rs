//! LayerNorm over the last axis as one operation with its own gradient: for h [B, n], gain g and
//! shift s [1, n], per row `ĥ = (h − μ) r` with μ the row mean and `r = 1/√(σ² + ε)` (σ² the biased
//! row variance, torch's), `y = ĥ g + s`; backward from `∂y`: `∂s = Σ_rows ∂y`, `∂g = Σ_rows ∂y ĥ`,
//! and with `d = ∂y g`: `∂h = r (d − mean(d) − ĥ mean(d ĥ))` per row. [`layer_norm_elu`] is the
//! same operation followed by ELU (α = 1), `z = ELU(y)`, whose backward takes `∂y = ∂z ·
//! min(z + 1, 1)` first: a critic's LayerNorm and ELU layers as one operation on the GPU.
//!
//! Written with tensor ops (mean, subtract, square, mean, add, sqrt, divide, multiply, add) it is
//! nine passes over [B, n] forward and about twice that backward, 30 % of a SAC gradient step of
//! the lift config (LayerNorm in both critics and their targets, BENCHMARKS.md). Through burn's
//! backend extensions:
//! - burn flex (the CPU): forward one pass per row (mean, variance, ĥ and y while the row is in
//!   cache), backward one pass per row plus the column sums, rows split over the rayon pool (ELU
//!   stays an operation of its own there: `nets` calls [`layer_norm_elu`] on a GPU only);
//! - cubecl (the GPU): forward one kernel of ours (shaders/layer_norm.wgsl: a workgroup per row;
//!   with ELU in the same kernel for [`layer_norm_elu`]), backward one kernel
//!   (shaders/layer_norm_backward.wgsl: ∂h and the rows `[∂y ĥ | ∂y]`, after ELU's gradient for
//!   [`layer_norm_elu`]; both after layer_norm_common.wgsl) plus one column-sum kernel for both
//!   parameters' gradients in the order of two stages (`row_sums`; none where neither gain nor
//!   shift is tracked, as in SAC's actor update through frozen critics), where the tensor ops
//!   launched ten and about fourteen kernels; the ops remain for tensors the kernels do not take
//!   (not contiguous f32, indices over 32 bits). Until 2026-12-01 (session 38) ELU was a kernel
//!   each way of its own and ∂g and ∂s a column sum each, always: the same arithmetic, so the same
//!   bits;
//! - autodiff: the backward above from the saved ĥ and r (and z), for the tracked inputs.

use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::checkpoint::strategy::CheckpointStrategy;
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{Backward, Ops, OpsKind};
use burn::backend::ops::FloatTensorOps;
use burn::backend::tensor::FloatTensor;
use burn::backend::{Autodiff, Backend, Cube, Flex, backend_extension};
use burn::prelude::Tensor;
use burn::tensor::{Bytes, DType, Shape};
use burn_flex::{FlexTensor, Layout};
use rayon::prelude::*;

use super::row_sums::column_sums_cube;

/// ε under the variance (torch's and ONNX's `LayerNormalization` default).
pub const LAYER_NORM_EPS: f32 = 1e-5;

/// Rows per rayon task.
const ROWS_PER_TASK: usize = 256;

/// `(y, ĥ, r)` as tensor ops of `B`: y [B, n], ĥ [B, n], r [B, 1].
fn forward_ops<B: Backend>(h: FloatTensor<B>, g: FloatTensor<B>, s: FloatTensor<B>) -> (FloatTensor<B>, FloatTensor<B>, FloatTensor<B>) {
    let mean = B::float_mean_dim(h.clone(), 1); // [B, 1]
    let c = B::float_sub(h, mean); // h − μ
    let var = B::float_mean_dim(B::float_mul(c.clone(), c.clone()), 1); // [B, 1], biased
    let r = B::float_recip(B::float_sqrt(B::float_add_scalar(var, (LAYER_NORM_EPS as f64).into()))); // 1/√(σ² + ε)
    let normed = B::float_mul(c, r.clone()); // ĥ
    let y = B::float_add(B::float_mul(normed.clone(), g), s); // ĥ g + s
    (y, normed, r)
}

/// `(∂h, ∂g, ∂s)` as tensor ops of `B` from ĥ [B, n], r [B, 1], g [1, n] and ∂y [B, n].
fn backward_ops<B: Backend>(
    normed: FloatTensor<B>,
    r: FloatTensor<B>,
    g: FloatTensor<B>,
    dy: FloatTensor<B>,
) -> (FloatTensor<B>, FloatTensor<B>, FloatTensor<B>) {
    let ds = B::float_sum_dim(dy.clone(), 0); // [1, n]
    let dg = B::float_sum_dim(B::float_mul(dy.clone(), normed.clone()), 0); // [1, n]
    let d = B::float_mul(dy, g); // ∂ĥ
    let m1 = B::float_mean_dim(d.clone(), 1); // [B, 1]
    let m2 = B::float_mean_dim(B::float_mul(d.clone(), normed.clone()), 1); // [B, 1]
    let dh = B::float_mul(B::float_sub(B::float_sub(d, m1), B::float_mul(normed, m2)), r); // r (d − m1 − ĥ m2)
    (dh, dg, ds)
}

/// `z = ELU(y)` (α = 1) as ops of `B`: `y` for y > 0, `e^min(y, 0) − 1` otherwise
/// (elu_forward.wgsl's expression).
fn elu_ops<B: Backend>(y: FloatTensor<B>) -> FloatTensor<B> {
    let bools = burn::backend::get_device_settings::<B>(&burn::backend::TensorMetadata::device(&y)).bool_dtype;
    let negative = B::float_sub_scalar(B::float_exp(B::float_clamp_max(y.clone(), 0.0f64.into())), 1.0f64.into()); // e^min(y, 0) − 1
    let positive = B::float_greater_elem(y.clone(), 0.0f64.into(), bools);
    B::float_mask_where(negative, positive, y)
}

/// The fused LayerNorm and its gradient, per backend (the default bodies: tensor ops).
#[backend_extension(Flex, Cube, Autodiff)]
pub trait LayerNormOps: Backend {
    /// `y = (h − μ)/√(σ² + ε) · g + s` per row: h [B, n], g and s [1, n] → [B, n].
    fn layer_norm_fused(h: FloatTensor<Self>, g: FloatTensor<Self>, s: FloatTensor<Self>) -> FloatTensor<Self> {
        Self::layer_norm_forward(h, g, s, false).0
    }

    /// `ELU(layer_norm(h, g, s))`.
    fn layer_norm_elu_fused(h: FloatTensor<Self>, g: FloatTensor<Self>, s: FloatTensor<Self>) -> FloatTensor<Self> {
        Self::layer_norm_forward(h, g, s, true).0
    }

    /// `(y, ĥ, r)`: the output [B, n] (ELU of it with `then_elu`), the normalised rows [B, n] and
    /// 1/√(σ² + ε) [B, 1].
    fn layer_norm_forward(
        h: FloatTensor<Self>,
        g: FloatTensor<Self>,
        s: FloatTensor<Self>,
        then_elu: bool,
    ) -> (FloatTensor<Self>, FloatTensor<Self>, FloatTensor<Self>) {
        let (y, normed, r) = forward_ops::<Self>(h, g, s);
        (if then_elu { elu_ops::<Self>(y) } else { y }, normed, r)
    }

}

/// LayerNorm's backward pass per backend, called by the autodiff operation on its inner backend
/// (the default body: tensor ops).
pub trait LayerNormBackward: Backend {
    /// `(∂h, (∂g, ∂s))` from ĥ [B, n], r [B, 1], g [1, n] and ∂y [B, n] — or with `elu_out`, the
    /// ELU's output z [B, n], from ∂z (∂y = ∂z · min(z + 1, 1)); the parameters' gradients only
    /// with `params`.
    fn layer_norm_backward(
        normed: FloatTensor<Self>,
        r: FloatTensor<Self>,
        g: FloatTensor<Self>,
        dy: FloatTensor<Self>,
        elu_out: Option<FloatTensor<Self>>,
        params: bool,
    ) -> (FloatTensor<Self>, Option<(FloatTensor<Self>, FloatTensor<Self>)>) {
        let dy = match elu_out {
            Some(z) => Self::float_mul(dy, Self::float_clamp_max(Self::float_add_scalar(z, 1.0f64.into()), 1.0f64.into())), // ∂z · min(z + 1, 1)
            None => dy,
        };
        let (dh, dg, ds) = backward_ops::<Self>(normed, r, g, dy);
        (dh, params.then_some((dg, ds)))
    }
}

impl LayerNormOps for Cube {
    fn layer_norm_forward(
        h: FloatTensor<Self>,
        g: FloatTensor<Self>,
        s: FloatTensor<Self>,
        then_elu: bool,
    ) -> (FloatTensor<Self>, FloatTensor<Self>, FloatTensor<Self>) {
        match gpu::forward(&h, &g, &s, then_elu) {
            Some(out) => out,
            None => {
                let (y, normed, r) = forward_ops::<Self>(h, g, s);
                (if then_elu { elu_ops::<Self>(y) } else { y }, normed, r)
            }
        }
    }
}

impl LayerNormBackward for Cube {
    fn layer_norm_backward(
        normed: FloatTensor<Self>,
        r: FloatTensor<Self>,
        g: FloatTensor<Self>,
        dy: FloatTensor<Self>,
        elu_out: Option<FloatTensor<Self>>,
        params: bool,
    ) -> (FloatTensor<Self>, Option<(FloatTensor<Self>, FloatTensor<Self>)>) {
        let Some((dh, param_rows)) = gpu::backward(&normed, &r, &g, &dy, elu_out.as_ref()) else {
            let dy = match elu_out {
                Some(z) => Self::float_mul(dy, Self::float_clamp_max(Self::float_add_scalar(z, 1.0f64.into()), 1.0f64.into())),
                None => dy,
            };
            let (dh, dg, ds) = backward_ops::<Self>(normed, r, g, dy);
            return (dh, params.then_some((dg, ds)));
        };
        (dh, params.then(|| gpu::parameter_gradients(param_rows)))
    }
}

/// The GPU's kernels (shaders/layer_norm.wgsl, shaders/layer_norm_backward.wgsl), launched on
/// burn's command stream.
mod gpu {
    use burn::backend::TensorMetadata;
    use burn::backend::ops::FloatTensorOps;
    use burn::backend::tensor::FloatTensor;
    use burn::backend::Cube;
    use burn::tensor::{DType, FloatDType, Shape};

    use super::LAYER_NORM_EPS;
    use super::column_sums_cube;
    use crate::learn::kernels::wgsl_kernel::{WgslKernel, entry_module, launch};

    /// shaders/layer_norm_common.wgsl: the constants' struct and the workgroup's sums.
    const SHADER_COMMON: &str = include_str!("../../../shaders/layer_norm_common.wgsl");
    /// shaders/layer_norm.wgsl (a template: whether ELU follows).
    const SHADER_FORWARD: &str = include_str!("../../../shaders/layer_norm.wgsl");
    /// shaders/layer_norm_backward.wgsl (a template of a module per entry point).
    const SHADER_BACKWARD: &str = include_str!("../../../shaders/layer_norm_backward.wgsl");

    /// The forward module: layer_norm_common.wgsl and layer_norm.wgsl, ELU after LayerNorm in the
    /// same kernel with `then_elu`.
    pub fn forward_source(then_elu: bool) -> String {
        [SHADER_COMMON, &SHADER_FORWARD.replace("$THEN_ELU", if then_elu { "true" } else { "false" })].join("\n")
    }

    /// The backward module of LayerNorm (`then_elu` false: `layer_norm_backward`) or of LayerNorm
    /// then ELU (`layer_norm_elu_backward`): layer_norm_common.wgsl and that entry point's part of
    /// layer_norm_backward.wgsl.
    pub fn backward_source(then_elu: bool) -> String {
        [SHADER_COMMON, &entry_module(SHADER_BACKWARD, backward_entry(then_elu))].join("\n")
    }

    /// The backward pass's entry point.
    pub fn backward_entry(then_elu: bool) -> &'static str {
        if then_elu { "layer_norm_elu_backward" } else { "layer_norm_backward" }
    }

    /// Contiguous row-major f32 of `len` entries (the binding starts at the tensor's first entry:
    /// cubecl binds a view's slice of its buffer).
    fn plain(t: &FloatTensor<Cube>, len: usize) -> bool {
        t.dtype == DType::F32 && t.is_contiguous() && t.shape().num_elements() == len
    }

    /// `[rows, n, grid_x, ε]` and the grid for `rows` rows of n, or None where the shape is empty or
    /// its indices (up to the backward pass's `2 rows n`) need more than 32 bits.
    fn config(rows: usize, n: usize) -> Option<([u32; 4], [u32; 3])> {
        let (rows32, n32) = (u32::try_from(rows).ok()?, u32::try_from(n).ok()?);
        u32::try_from(rows.checked_mul(n)?.checked_mul(2)?).ok().filter(|_| rows > 0 && n > 0)?;
        let (gx, gy) = crate::gpu::shaders::workgroups_of(rows32, 1); // a workgroup per row
        Some(([rows32, n32, gx, LAYER_NORM_EPS.to_bits()], [gx, gy, 1]))
    }

    /// `(y, ĥ, r)` for h [B, n], g and s [1, n] as one kernel (y = ELU(ĥ g + s) with `then_elu`),
    /// or None where the tensors do not fit it.
    pub fn forward(h: &FloatTensor<Cube>, g: &FloatTensor<Cube>, s: &FloatTensor<Cube>, then_elu: bool) -> Option<(FloatTensor<Cube>, FloatTensor<Cube>, FloatTensor<Cube>)> {
        let dims = h.shape().to_vec();
        let [rows, n] = <[usize; 2]>::try_from(dims).ok()?;
        if !plain(h, rows * n) || !plain(g, n) || !plain(s, n) {
            return None;
        }
        let (constants, groups) = config(rows, n)?;
        let empty = |shape: [usize; 2]| Cube::float_empty(Shape::new(shape), &h.device, FloatDType::F32); // written whole below
        let (y, normed, r) = (empty([rows, n]), empty([rows, n]), empty([rows, 1]));
        let kernel = WgslKernel { name: "dextrain_layer_norm", key: then_elu, source: forward_source, entry_point: "layer_norm_forward", workgroup: [64, 1] };
        launch(kernel, groups, &[h, g, s, &y, &normed, &r], &constants);
        Some((y, normed, r))
    }

    /// `(∂h, [∂y ĥ | ∂y] [B, 2n])` from ĥ [B, n], r [B, 1], g [1, n] and ∂y [B, n] — or, with
    /// `elu_out` z [B, n], from ∂z — as one kernel, or None where the tensors do not fit it.
    pub fn backward(normed: &FloatTensor<Cube>, r: &FloatTensor<Cube>, g: &FloatTensor<Cube>, dy: &FloatTensor<Cube>, elu_out: Option<&FloatTensor<Cube>>) -> Option<(FloatTensor<Cube>, FloatTensor<Cube>)> {
        let dims = normed.shape().to_vec();
        let [rows, n] = <[usize; 2]>::try_from(dims).ok()?;
        if !plain(normed, rows * n) || !plain(r, rows) || !plain(g, n) || !plain(dy, rows * n) || dy.shape() != normed.shape() {
            return None;
        }
        if elu_out.is_some_and(|z| !plain(z, rows * n) || z.shape() != normed.shape()) {
            return None;
        }
        let (constants, groups) = config(rows, n)?;
        let empty = |cols: usize| Cube::float_empty(Shape::new([rows, cols]), &normed.device, FloatDType::F32); // written whole below
        let (dh, param_rows) = (empty(n), empty(2 * n));
        let then_elu = elu_out.is_some();
        let kernel = WgslKernel { name: "dextrain_layer_norm_backward", key: then_elu, source: backward_source, entry_point: backward_entry(then_elu), workgroup: [64, 1] };
        match elu_out {
            Some(z) => launch(kernel, groups, &[normed, r, g, dy, z, &dh, &param_rows], &constants),
            None => launch(kernel, groups, &[normed, r, g, dy, &dh, &param_rows], &constants),
        }
        Some((dh, param_rows))
    }

    /// `(∂g, ∂s)` `[1, n]` each from the rows `[∂y ĥ | ∂y]` [B, 2n]: one column-sum kernel (each
    /// column's sum depends on the rows alone, so these are the bits of a sum per parameter), then
    /// its two halves as views where they fall on the binding alignment (burn's slice copies them
    /// otherwise).
    pub fn parameter_gradients(param_rows: FloatTensor<Cube>) -> (FloatTensor<Cube>, FloatTensor<Cube>) {
        let n = param_rows.shape()[1] / 2;
        let sums = Cube::float_reshape(column_sums_cube(param_rows), Shape::new([2, n])); // [Σ ∂y ĥ ; Σ ∂y]
        let row = |k: usize| Cube::float_slice(sums.clone(), &[burn::tensor::Slice::from(k..k + 1), burn::tensor::Slice::from(0..n)]);
        (row(0), row(1))
    }
}

pub use gpu::{backward_source as layer_norm_backward_source, forward_source as layer_norm_forward_source};

/// A row-major f32 tensor owning `data`, without a copy.
fn from_vec(data: Vec<f32>, shape: [usize; 2]) -> FlexTensor {
    FlexTensor::new(Bytes::from_elems(data), Layout::contiguous(Shape::from(shape.to_vec())), DType::F32)
}

/// The values of a flex tensor, row-major (a copy only when it is strided or offset).
fn contiguous(t: FloatTensor<Flex>) -> FloatTensor<Flex> {
    if t.is_contiguous() && t.layout().start_offset() == 0 { t } else { t.to_contiguous() }
}

/// Whether every tensor is an f32 matrix (else the tensor-op bodies run).
fn all_f32_2d(ts: &[&FlexTensor]) -> bool {
    ts.iter().all(|t| t.dtype() == DType::F32 && t.layout().num_dims() == 2)
}

/// Lanes of the partial sums below (one AVX-512 register; the compiler vectorises a fixed-width
/// array where it would not reorder a plain float sum).
const LANES: usize = 16;

/// `Σ f(a[i], b[i])` over equal-length slices, in LANES partial sums.
#[inline(always)]
fn lane_sum(a: &[f32], b: &[f32], f: impl Fn(f32, f32) -> f32) -> f32 {
    let mut acc = [0.0f32; LANES];
    let (ac, bc) = (a.chunks_exact(LANES), b.chunks_exact(LANES));
    let tail: f32 = ac.remainder().iter().zip(bc.remainder()).map(|(x, y)| f(*x, *y)).sum();
    for (x, y) in ac.zip(bc) {
        let (x, y): (&[f32; LANES], &[f32; LANES]) = (x.try_into().unwrap(), y.try_into().unwrap());
        for l in 0..LANES {
            acc[l] += f(x[l], y[l]);
        }
    }
    acc.iter().sum::<f32>() + tail
}

/// Adds `b` into `a` element by element.
fn add_into(a: &mut [f32], b: &[f32]) {
    a.iter_mut().zip(b).for_each(|(x, y)| *x += y);
}

impl LayerNormOps for Flex {
    fn layer_norm_forward(
        h: FloatTensor<Self>,
        g: FloatTensor<Self>,
        s: FloatTensor<Self>,
        then_elu: bool,
    ) -> (FloatTensor<Self>, FloatTensor<Self>, FloatTensor<Self>) {
        if then_elu || !all_f32_2d(&[&h, &g, &s]) {
            // (LayerNorm then ELU is one operation on the GPU alone: here the tensor ops)
            let (y, normed, r) = forward_ops::<Self>(h, g, s);
            return (if then_elu { elu_ops::<Self>(y) } else { y }, normed, r);
        }
        let (h, g, s) = (contiguous(h), contiguous(g), contiguous(s));
        let [rows, n] = [h.layout().shape()[0], h.layout().shape()[1]];
        let (hs, gs, ss): (&[f32], &[f32], &[f32]) = (&h.storage()[..rows * n], &g.storage()[..n], &s.storage()[..n]);
        let (mut y, mut normed, mut r) = (vec![0.0f32; rows * n], vec![0.0f32; rows * n], vec![0.0f32; rows]);
        if n > 0 {
            let inv_n = 1.0 / n as f32;
            y.par_chunks_mut(ROWS_PER_TASK * n)
                .zip(normed.par_chunks_mut(ROWS_PER_TASK * n))
                .zip(r.par_chunks_mut(ROWS_PER_TASK))
                .zip(hs.par_chunks(ROWS_PER_TASK * n))
                .for_each(|(((y, normed), r), h)| {
                    for (((y, nh), r), h) in y.chunks_exact_mut(n).zip(normed.chunks_exact_mut(n)).zip(r.iter_mut()).zip(h.chunks_exact(n)) {
                        let mean = lane_sum(h, h, |x, _| x) * inv_n; // μ
                        let var = lane_sum(h, h, |x, _| (x - mean) * (x - mean)) * inv_n; // σ², biased
                        *r = 1.0 / (var + LAYER_NORM_EPS).sqrt();
                        let r = *r;
                        for ((((y, nh), h), g), s) in y.iter_mut().zip(nh.iter_mut()).zip(h).zip(gs).zip(ss) {
                            *nh = (h - mean) * r; // ĥ
                            *y = *nh * g + s; // ĥ g + s
                        }
                    }
                });
        }
        (from_vec(y, [rows, n]), from_vec(normed, [rows, n]), from_vec(r, [rows, 1]))
    }
}

impl LayerNormBackward for Flex {
    fn layer_norm_backward(
        normed: FloatTensor<Self>,
        r: FloatTensor<Self>,
        g: FloatTensor<Self>,
        dy: FloatTensor<Self>,
        elu_out: Option<FloatTensor<Self>>,
        params: bool,
    ) -> (FloatTensor<Self>, Option<(FloatTensor<Self>, FloatTensor<Self>)>) {
        if elu_out.is_some() || !all_f32_2d(&[&normed, &r, &g, &dy]) {
            let dy = match elu_out {
                Some(z) => Self::float_mul(dy, Self::float_clamp_max(Self::float_add_scalar(z, 1.0f64.into()), 1.0f64.into())), // ∂z · min(z + 1, 1)
                None => dy,
            };
            let (dh, dg, ds) = backward_ops::<Self>(normed, r, g, dy);
            return (dh, params.then_some((dg, ds)));
        }
        let (normed, r, g, dy) = (contiguous(normed), contiguous(r), contiguous(g), contiguous(dy));
        let [rows, n] = [normed.layout().shape()[0], normed.layout().shape()[1]];
        let (nhs, rs, gs, dys): (&[f32], &[f32], &[f32], &[f32]) =
            (&normed.storage()[..rows * n], &r.storage()[..rows], &g.storage()[..n], &dy.storage()[..rows * n]);
        let mut dh = vec![0.0f32; rows * n];
        let (mut dg, mut ds) = (vec![0.0f32; n], vec![0.0f32; n]);
        if n > 0 {
            let inv_n = 1.0 / n as f32;
            let sums = dh
                .par_chunks_mut(ROWS_PER_TASK * n)
                .zip(nhs.par_chunks(ROWS_PER_TASK * n))
                .zip(rs.par_chunks(ROWS_PER_TASK))
                .zip(dys.par_chunks(ROWS_PER_TASK * n))
                .map(|(((dh, nh), r), dy)| {
                    let (mut dg, mut ds) = (vec![0.0f32; n], vec![0.0f32; n]); // this task's column sums
                    let mut d = vec![0.0f32; n]; // one row's ∂ĥ = ∂y g
                    for (((dh, nh), r), dy) in dh.chunks_exact_mut(n).zip(nh.chunks_exact(n)).zip(r).zip(dy.chunks_exact(n)) {
                        for (((dg, ds), y), nh) in dg.iter_mut().zip(ds.iter_mut()).zip(dy).zip(nh) {
                            *dg += y * nh; // Σ ∂y ĥ
                            *ds += y; // Σ ∂y
                        }
                        d.iter_mut().zip(dy).zip(gs).for_each(|((d, y), g)| *d = y * g);
                        let m1 = lane_sum(&d, &d, |x, _| x) * inv_n; // mean(d)
                        let m2 = lane_sum(&d, nh, |x, y| x * y) * inv_n; // mean(d ĥ)
                        for ((dh, d), nh) in dh.iter_mut().zip(&d).zip(nh) {
                            *dh = r * (d - m1 - nh * m2); // r (d − m1 − ĥ m2)
                        }
                    }
                    (dg, ds)
                })
                .reduce(
                    || (vec![0.0f32; n], vec![0.0f32; n]),
                    |(mut ga, mut sa), (gb, sb)| {
                        add_into(&mut ga, &gb);
                        add_into(&mut sa, &sb);
                        (ga, sa)
                    },
                );
            (dg, ds) = sums;
        }
        (from_vec(dh, [rows, n]), params.then(|| (from_vec(dg, [1, n]), from_vec(ds, [1, n]))))
    }
}

impl<B: Backend + LayerNormOps + LayerNormBackward, C: CheckpointStrategy> LayerNormOps for Autodiff<B, C> {
    fn layer_norm_fused(h: FloatTensor<Self>, g: FloatTensor<Self>, s: FloatTensor<Self>) -> FloatTensor<Self> {
        layer_norm_autodiff::<B, C>(h, g, s, false)
    }

    fn layer_norm_elu_fused(h: FloatTensor<Self>, g: FloatTensor<Self>, s: FloatTensor<Self>) -> FloatTensor<Self> {
        layer_norm_autodiff::<B, C>(h, g, s, true)
    }
}

/// LayerNorm (then ELU with `then_elu`) on `Autodiff<B>`: the backward pass from the saved ĥ, r
/// and g (and the ELU's output z), the parameters' gradients only where gain or shift is tracked.
fn layer_norm_autodiff<B: Backend + LayerNormOps + LayerNormBackward, C: CheckpointStrategy>(
    h: FloatTensor<Autodiff<B, C>>,
    g: FloatTensor<Autodiff<B, C>>,
    s: FloatTensor<Autodiff<B, C>>,
    then_elu: bool,
) -> FloatTensor<Autodiff<B, C>> {
    #[derive(Debug)]
    struct LayerNorm;

    impl<B: Backend + LayerNormOps + LayerNormBackward> Backward<B, 3> for LayerNorm {
        /// ĥ [B, n], r [B, 1], the gain g [1, n], and the ELU's output z [B, n] where it follows.
        type State = (FloatTensor<B>, FloatTensor<B>, FloatTensor<B>, Option<FloatTensor<B>>);

        fn backward(self, ops: Ops<Self::State, 3>, grads: &mut Gradients, _checkpointer: &mut Checkpointer) {
            let (normed, r, g, elu_out) = ops.state;
            let [node_h, node_g, node_s] = ops.parents;
            let dy = grads.consume::<B>(&ops.node);
            let (dh, params) = B::layer_norm_backward(normed, r, g, dy, elu_out, node_g.is_some() || node_s.is_some());
            if let Some(node) = node_h {
                grads.register::<B>(node.id, dh);
            }
            if let Some((dg, ds)) = params {
                for (node, grad) in [(node_g, dg), (node_s, ds)] {
                    if let Some(node) = node {
                        grads.register::<B>(node.id, grad);
                    }
                }
            }
        }
    }

    match LayerNorm.prepare::<C>([h.node(), g.node(), s.node()]).compute_bound().stateful() {
        OpsKind::Tracked(prep) => {
            let g = g.into_primitive();
            let (y, normed, r) = B::layer_norm_forward(h.into_primitive(), g.clone(), s.into_primitive(), then_elu);
            prep.finish((normed, r, g, then_elu.then(|| y.clone())), y)
        }
        OpsKind::UnTracked(prep) => {
            let (h, g, s) = (h.into_primitive(), g.into_primitive(), s.into_primitive());
            prep.finish(if then_elu { B::layer_norm_elu_fused(h, g, s) } else { B::layer_norm_fused(h, g, s) })
        }
    }
}

/// LayerNorm of each row of h [B, n] with gain and shift [1, n] on any learner device,
/// differentiable.
pub fn layer_norm(h: Tensor<2>, gain: Tensor<2>, shift: Tensor<2>) -> Tensor<2> {
    Tensor::from_dispatch(<burn::backend::Dispatch as LayerNormOps>::layer_norm_fused(
        h.into_dispatch(),
        gain.into_dispatch(),
        shift.into_dispatch(),
    ))
}

/// `ELU(layer_norm(h, gain, shift))` as one operation (α = 1): on burn's wgpu runtime a kernel each
/// way where LayerNorm and ELU were two, the same values bit for bit; on the CPU tensor ops (the
/// learners there call [`layer_norm`] and ELU's own operation), differentiable.
pub fn layer_norm_elu(h: Tensor<2>, gain: Tensor<2>, shift: Tensor<2>) -> Tensor<2> {
    Tensor::from_dispatch(<burn::backend::Dispatch as LayerNormOps>::layer_norm_elu_fused(
        h.into_dispatch(),
        gain.into_dispatch(),
        shift.into_dispatch(),
    ))
}
