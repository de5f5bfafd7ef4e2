//! ELU (α = 1) as one operation with its own gradient: `y = x` for x > 0, `eˣ − 1` otherwise, and
//! `∂L/∂x = ∂L/∂y · (1 if y > 0 else y + 1)`.
//!
//! burn has no ELU kernel of its own on its CPU backend: written with tensor ops it is five passes
//! over the activations forward (relu, neg, relu, exp, add) and as many backward, and burn-flex's
//! `exp` calls libm's scalar `expf` per element (18 % of a SAC gradient step, 13 % of a PPO update
//! on one core; BENCHMARKS.md). Here, through burn's backend extensions:
//! - burn flex (the CPU): one pass each way, in place where the tensor is not shared, with a
//!   vectorised `exp` (Cephes' expf polynomial, ≤ 2 ulp on [−87, 0]) compiled for AVX-512 and for
//!   AVX2 + FMA and picked at run time ([`crate::learn::kernels::isa::isa`]), split over the rayon pool for large tensors;
//! - cubecl (the GPU): one kernel of ours each way (shaders/elu_forward.wgsl,
//!   shaders/elu_backward.wgsl), the values of the tensor ops they replace (`impl EluOps for Cube`);
//! - autodiff: the backward pass above, from the saved output.

use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::checkpoint::strategy::CheckpointStrategy;
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{Backward, Ops, OpsKind, unary};
use burn::backend::tensor::FloatTensor;
use burn::backend::{Autodiff, Backend, Cube, Flex, backend_extension};
use burn::prelude::Tensor;
use burn::tensor::DType;
use rayon::prelude::*;

use crate::learn::kernels::isa::{Isa, detected_isa, isa};
use crate::learn::kernels::wgsl_kernel::{WgslKernel, launch};

/// `ELU(x) = relu(x) + exp(−relu(−x)) − 1` as tensor ops of `B`.
pub(crate) fn elu_ops<B: Backend>(x: FloatTensor<B>) -> FloatTensor<B> {
    let pos = B::relu(x.clone());
    let neg = B::float_neg(B::relu(B::float_neg(x)));
    B::float_add(pos, B::float_sub_scalar(B::float_exp(neg), 1.0f64.into()))
}

/// `∂L/∂x` from `y = ELU(x)` and `∂L/∂y` as tensor ops of `B`: `grad · (1 − relu(−y))` (= grad for
/// y > 0, grad · (y + 1) = grad · eˣ otherwise).
pub(crate) fn elu_backward_ops<B: Backend>(y: FloatTensor<B>, grad: FloatTensor<B>) -> FloatTensor<B> {
    let slope = B::float_add_scalar(B::float_neg(B::relu(B::float_neg(y))), 1.0f64.into());
    B::float_mul(grad, slope)
}

/// The fused ELU and its gradient, per backend (the default bodies: tensor ops).
#[backend_extension(Flex, Cube, Autodiff)]
pub trait EluOps: Backend {
    /// `ELU(x)`, α = 1.
    fn elu_fused(x: FloatTensor<Self>) -> FloatTensor<Self> {
        elu_ops::<Self>(x)
    }

    /// `∂L/∂x` from `y = ELU(x)` and `∂L/∂y`.
    fn elu_fused_backward(y: FloatTensor<Self>, grad: FloatTensor<Self>) -> FloatTensor<Self> {
        elu_backward_ops::<Self>(y, grad)
    }
}

/// cubecl (the GPU): one kernel of ours each way where the tensors are plain contiguous f32, else
/// 5 kernels forward and 3 backward where [`elu_ops`] and [`elu_backward_ops`] launch 9 and 6
/// (cubecl's `relu` and `clamp_max` are two kernels each, its `clamp` one):
/// `ELU(x) = clamp(x, 0, ∞) + (exp(clamp(x, −∞, 0)) − 1)`, the same values as [`elu_ops`] bit for
/// bit (and the kernel's `x > 0 ? x : eˣ − 1` theirs), and `∂L/∂x = grad · min(y + 1, 1)`, bit
/// for bit `grad · (1 − relu(−y))`.
impl EluOps for Cube {
    fn elu_fused(x: FloatTensor<Self>) -> FloatTensor<Self> {
        // one kernel of ours (shaders/elu_forward.wgsl) where the tensor is plain contiguous f32,
        // the same values as the ops below
        match elu_forward_kernel(&x) {
            Some(y) => y,
            None => elu_clamp_ops::<Self>(x),
        }
    }

    fn elu_fused_backward(y: FloatTensor<Self>, grad: FloatTensor<Self>) -> FloatTensor<Self> {
        // one kernel of ours (shaders/elu_backward.wgsl) where the tensors are plain contiguous
        // f32 of one shape, the same values as the ops below
        match elu_backward_kernel(&y, &grad) {
            Some(out) => out,
            None => elu_clamp_backward_ops::<Self>(y, grad),
        }
    }
}

/// shaders/elu_forward.wgsl.
const SHADER_ELU_FORWARD: &str = include_str!("../../../shaders/elu_forward.wgsl");

/// The text of shaders/elu_forward.wgsl (the kernel has one variant).
pub fn elu_forward_source(_: ()) -> String {
    SHADER_ELU_FORWARD.to_string()
}

/// Entries of a plain contiguous f32 tensor that one launch of a 256-wide element-wise kernel of
/// ours covers with 32-bit indices, or None (not f32, not contiguous, empty or too many).
fn plain_count(t: &FloatTensor<Cube>) -> Option<u32> {
    use burn::backend::TensorMetadata;
    if t.dtype != DType::F32 || !t.is_contiguous() || !t.is_contiguous_buffer() {
        return None;
    }
    u32::try_from(t.shape().num_elements()).ok().filter(|&c| c > 0 && c < u32::MAX - 65_535 * 256)
}

/// `ELU(x)` as one kernel on burn's stream (matmul.wgsl's epilogue expression: the values of
/// [`elu_clamp_ops`]), or None where [`plain_count`] refuses `x`.
fn elu_forward_kernel(x: &FloatTensor<Cube>) -> Option<FloatTensor<Cube>> {
    use burn::backend::TensorMetadata;
    use burn::backend::ops::FloatTensorOps;
    use burn::tensor::FloatDType;
    let count = plain_count(x)?;
    let (gx, gy) = crate::gpu::shaders::workgroups_of(count, 256);
    let out = Cube::float_empty(x.shape(), &x.device, FloatDType::F32); // written whole below
    let kernel = WgslKernel { name: "dextrain_elu_forward", key: (), source: elu_forward_source, entry_point: "elu_forward", workgroup: [256, 1] };
    // EluForwardCfg: count, entries per row of the grid
    launch(kernel, [gx, gy, 1], &[x, &out], &[count, gx * 256, 0, 0]);
    Some(out)
}

/// shaders/elu_backward.wgsl.
const SHADER_ELU_BACKWARD: &str = include_str!("../../../shaders/elu_backward.wgsl");

/// The text of shaders/elu_backward.wgsl (the kernel has one variant).
pub fn elu_backward_source(_: ()) -> String {
    SHADER_ELU_BACKWARD.to_string()
}

/// `∂L/∂x = grad · min(y + 1, 1)` as one kernel on burn's stream, or None where the tensors are not
/// f32, contiguous, of one shape, or too many entries for 32-bit indices.
fn elu_backward_kernel(y: &FloatTensor<Cube>, grad: &FloatTensor<Cube>) -> Option<FloatTensor<Cube>> {
    use burn::backend::TensorMetadata;
    use burn::backend::ops::FloatTensorOps;
    use burn::tensor::FloatDType;
    if y.shape() != grad.shape() {
        return None;
    }
    let count = plain_count(y).and(plain_count(grad))?;
    let (gx, gy) = crate::gpu::shaders::workgroups_of(count, 256);
    let out = Cube::float_empty(y.shape(), &y.device, FloatDType::F32); // written whole below
    let kernel = WgslKernel { name: "dextrain_elu_backward", key: (), source: elu_backward_source, entry_point: "elu_backward", workgroup: [256, 1] };
    // EluCfg: count, entries per row of the grid
    launch(kernel, [gx, gy, 1], &[y, grad, &out], &[count, gx * 256, 0, 0]);
    Some(out)
}

/// `ELU(x) = clamp(x, 0, ∞) + (exp(clamp(x, −∞, 0)) − 1)` as tensor ops of `B` (∞: f32's largest).
fn elu_clamp_ops<B: Backend>(x: FloatTensor<B>) -> FloatTensor<B> {
    let big = f32::MAX as f64;
    let pos = B::float_clamp(x.clone(), 0.0f64.into(), big.into()); // max(x, 0)
    let neg = B::float_clamp(x, (-big).into(), 0.0f64.into()); // min(x, 0)
    B::float_add(pos, B::float_sub_scalar(B::float_exp(neg), 1.0f64.into()))
}

/// `∂L/∂x = grad · min(y + 1, 1)` as tensor ops of `B`.
fn elu_clamp_backward_ops<B: Backend>(y: FloatTensor<B>, grad: FloatTensor<B>) -> FloatTensor<B> {
    let slope = B::float_clamp(B::float_add_scalar(y, 1.0f64.into()), (-(f32::MAX as f64)).into(), 1.0f64.into()); // min(y + 1, 1)
    B::float_mul(grad, slope)
}

/// Elements per rayon task.
const CHUNK: usize = 16 * 1024;

/// eˣ for x ≤ 0 (Cephes' expf: x = n ln 2 + r, |r| ≤ ½ ln 2, eʳ by a degree-7 polynomial, 2ⁿ by
/// the exponent bits); x below −87.3 gives e^−87.3 ≈ 1.2e−38 (ELU's −1 to f32 precision).
#[inline(always)]
fn exp_nonpositive(x: f32) -> f32 {
    const ROUNDER: f32 = 12_582_912.0; // 1.5 · 2²³: adding it rounds to an integer in the low mantissa bits
    let x = x.max(-87.3);
    // n = round(x / ln 2) as a float and as an integer, without a float → int conversion (Rust's
    // saturating `as` does not vectorise): the integer is in the low bits of t
    let t = x * std::f32::consts::LOG2_E + ROUNDER;
    let n_int = t.to_bits().wrapping_sub(ROUNDER.to_bits()) as i32;
    let n = t - ROUNDER;
    let r = x - n * 0.693_359_4 - n * -2.121_944_4e-4; // r = x − n ln 2, ln 2 in two parts
    let mut p = 1.987_569_1e-4f32;
    p = p * r + 1.398_199_9e-3;
    p = p * r + 8.333_452e-3;
    p = p * r + 4.166_579_6e-2;
    p = p * r + 1.666_666_5e-1;
    p = p * r + 5.000_000_1e-1;
    let er = p * r * r + r + 1.0; // eʳ
    er * f32::from_bits(((n_int + 127) as u32) << 23) // · 2ⁿ (n ≥ −126: a normal number)
}

#[inline(always)]
fn elu_loop(xs: &mut [f32]) {
    for v in xs.iter_mut() {
        let e = exp_nonpositive(v.min(0.0)) - 1.0;
        *v = if *v > 0.0 { *v } else { e };
    }
}

#[inline(always)]
fn elu_backward_loop(ys: &[f32], gs: &mut [f32]) {
    for (g, &y) in gs.iter_mut().zip(ys) {
        *g *= if y > 0.0 { 1.0 } else { y + 1.0 };
    }
}

#[cfg(target_arch = "x86_64")]
mod simd {
    #[target_feature(enable = "avx512f")]
    pub unsafe fn elu_avx512(xs: &mut [f32]) {
        super::elu_loop(xs)
    }
    #[target_feature(enable = "avx2,fma")]
    pub unsafe fn elu_avx2(xs: &mut [f32]) {
        super::elu_loop(xs)
    }
    #[target_feature(enable = "avx512f")]
    pub unsafe fn backward_avx512(ys: &[f32], gs: &mut [f32]) {
        super::elu_backward_loop(ys, gs)
    }
    #[target_feature(enable = "avx2,fma")]
    pub unsafe fn backward_avx2(ys: &[f32], gs: &mut [f32]) {
        super::elu_backward_loop(ys, gs)
    }
}

/// ELU of every element, in place, with the kernel of `isa` (at most what this CPU has: a wider
/// one than [`isa`] reports runs the scalar loop).
pub fn elu_slice_with(isa: Isa, xs: &mut [f32]) {
    #[cfg(target_arch = "x86_64")]
    match isa.min(detected_isa()) {
        // SAFETY: the CPU has AVX-512F (checked by detected_isa)
        Isa::Avx512 => return unsafe { simd::elu_avx512(xs) },
        // SAFETY: the CPU has AVX2 and FMA (checked by detected_isa)
        Isa::Avx2 => return unsafe { simd::elu_avx2(xs) },
        Isa::Scalar => {}
    }
    let _ = isa;
    elu_loop(xs)
}

/// `gs[i] *= 1 if ys[i] > 0 else ys[i] + 1` with the kernel of `isa` (as [`elu_slice_with`]).
pub fn elu_backward_slice_with(isa: Isa, ys: &[f32], gs: &mut [f32]) {
    #[cfg(target_arch = "x86_64")]
    match isa.min(detected_isa()) {
        // SAFETY: the CPU has AVX-512F (checked by detected_isa)
        Isa::Avx512 => return unsafe { simd::backward_avx512(ys, gs) },
        // SAFETY: the CPU has AVX2 and FMA (checked by detected_isa)
        Isa::Avx2 => return unsafe { simd::backward_avx2(ys, gs) },
        Isa::Scalar => {}
    }
    let _ = isa;
    elu_backward_loop(ys, gs)
}

/// A flex tensor laid out contiguously from offset 0 (copied if it is not).
fn contiguous(t: FloatTensor<Flex>) -> FloatTensor<Flex> {
    if t.is_contiguous() && t.layout().start_offset() == 0 { t } else { t.to_contiguous() }
}

impl EluOps for Flex {
    fn elu_fused(x: FloatTensor<Self>) -> FloatTensor<Self> {
        if x.dtype() != DType::F32 {
            return elu_ops::<Self>(x);
        }
        let mut y = contiguous(x);
        let n = y.layout().num_elements();
        let s: &mut [f32] = y.storage_mut(); // copies first if the storage is shared
        let isa = isa();
        s[..n].par_chunks_mut(CHUNK).for_each(|c| elu_slice_with(isa, c));
        y
    }

    fn elu_fused_backward(y: FloatTensor<Self>, grad: FloatTensor<Self>) -> FloatTensor<Self> {
        if y.dtype() != DType::F32 || grad.dtype() != DType::F32 {
            return elu_backward_ops::<Self>(y, grad);
        }
        let y = contiguous(y);
        let mut g = contiguous(grad);
        let n = g.layout().num_elements();
        let ys: &[f32] = &y.storage::<f32>()[..n];
        let gs: &mut [f32] = &mut g.storage_mut::<f32>()[..n];
        let isa = isa();
        gs.par_chunks_mut(CHUNK).zip(ys.par_chunks(CHUNK)).for_each(|(g, y)| elu_backward_slice_with(isa, y, g));
        g
    }
}

impl<B: Backend + EluOps, C: CheckpointStrategy> EluOps for Autodiff<B, C> {
    fn elu_fused(x: FloatTensor<Self>) -> FloatTensor<Self> {
        #[derive(Debug)]
        struct Elu;

        impl<B: Backend + EluOps> Backward<B, 1> for Elu {
            /// The output y.
            type State = FloatTensor<B>;

            fn backward(self, ops: Ops<Self::State, 1>, grads: &mut Gradients, _checkpointer: &mut Checkpointer) {
                let y = ops.state;
                unary::<B, _>(ops.parents, ops.node, grads, |grad| B::elu_fused_backward(y, grad));
            }
        }

        let node = x.node();
        match Elu.prepare::<C>([node]).compute_bound().stateful() {
            OpsKind::Tracked(prep) => {
                let y = B::elu_fused(x.into_primitive());
                prep.finish(y.clone(), y)
            }
            OpsKind::UnTracked(prep) => prep.finish(B::elu_fused(x.into_primitive())),
        }
    }
}

/// ELU (α = 1) of a tensor on any learner device, differentiable.
pub fn elu<const D: usize>(x: Tensor<D>) -> Tensor<D> {
    Tensor::from_dispatch(<burn::backend::Dispatch as EluOps>::elu_fused(x.into_dispatch()))
}
