//! SAC's squashed-Gaussian sample as one operation with its own gradient: from the actor's head
//! `[B, 2A]` (μ, then the unsquashed log σ) and the noise ε `[B, A]`, `[B, A + 1]` holding the
//! actions `a = tanh(μ + σ ε)` and their log-probability `log π(a|s)` (log σ squashed into
//! `[lo, hi]`; the maths in `sac::squashed_sample`, whose tensor ops it replaces on the GPU).
//!
//! As tensor ops the sample is ~25 kernels forward (the squash of log σ, the sample, the stable
//! `log(1 − tanh² u)`, the row sum) and ~35 in its backward pass, twice per SAC gradient step (the
//! target's actions and the actor's): on burn's wgpu runtime, where a gradient step's time is the
//! launch of its kernels rather than their arithmetic, a tenth of the step. Through burn's backend
//! extensions:
//! - cubecl (the GPU): one kernel of ours each way (shaders/squashed_sample.wgsl and
//!   shaders/squashed_sample_backward.wgsl, after shaders/squashed_common.wgsl; one invocation per
//!   row), the tensor ops below for tensors the kernels do not take;
//! - burn flex (the CPU) and any other backend: tensor ops (the forward pass the same maths as
//!   `sac::squashed_sample`, the backward pass the analytic gradient). The CPU learner keeps
//!   `sac::squashed_sample` itself, so its numbers are those of before;
//! - autodiff: the backward pass above, for the head (ε is a constant).
//!
//! The gradient, with `a_k = tanh(u_k)`, `u = μ + σ ε`, `log σ = lo + ½ (hi − lo)(tanh x + 1)`:
//! `∂u = ∂a (1 − a²) + ∂log π · 2a`, `∂μ = ∂u`, `∂log σ = ∂u σ ε − ∂log π`,
//! `∂x = ∂log σ · ½ (hi − lo)(1 − tanh² x)`.

use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::checkpoint::strategy::CheckpointStrategy;
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{Backward, Ops, OpsKind, unary};
use burn::backend::tensor::FloatTensor;
use burn::backend::{Autodiff, Backend, Cube, Flex, TensorMetadata, backend_extension};
use burn::prelude::Tensor;

const LN_2: f64 = std::f64::consts::LN_2;
const LN_2PI: f64 = 1.837_877_066_409_345_3; // ln(2π)

use super::columns;

/// `(μ, log σ, tanh x)`, each `[B, A]`, of a head `[B, 2A]`: log σ squashed into [lo, hi].
fn head_parts<B: Backend>(head: FloatTensor<B>, lo: f64, hi: f64) -> (FloatTensor<B>, FloatTensor<B>, FloatTensor<B>) {
    let a = head.shape()[1] / 2;
    let mu = columns::<B>(head.clone(), 0, a);
    let tx = B::float_tanh(columns::<B>(head, a, 2 * a));
    let log_std = B::float_add_scalar(B::float_mul_scalar(B::float_add_scalar(tx.clone(), 1.0f64.into()), (0.5 * (hi - lo)).into()), lo.into()); // lo + ½ (hi − lo)(tanh x + 1)
    (mu, log_std, tx)
}

/// `[a | log π]` `[B, A + 1]` as tensor ops of `B` (the maths of `sac::squashed_sample`).
fn forward_ops<B: Backend>(head: FloatTensor<B>, eps: FloatTensor<B>, lo: f64, hi: f64) -> FloatTensor<B> {
    let a = head.shape()[1] / 2;
    let (mu, log_std, _) = head_parts::<B>(head, lo, hi);
    let u = B::float_add(mu, B::float_mul(B::float_exp(log_std.clone()), eps.clone())); // u = μ + σ ε
    let gauss = B::float_sub(B::float_mul_scalar(B::float_mul(eps.clone(), eps), (-0.5f64).into()), log_std); // −½ ε² − log σ
    let x = B::float_mul_scalar(u.clone(), (-2.0f64).into());
    let softplus = B::float_add(B::relu(x.clone()), B::float_log1p(B::float_exp(B::float_neg(B::float_abs(x))))); // max(x, 0) + ln(1 + e^{−|x|})
    let log_det = B::float_mul_scalar(B::float_sub(B::float_add_scalar(B::float_neg(u.clone()), LN_2.into()), softplus), 2.0f64.into()); // log(1 − tanh² u)
    let log_prob = B::float_sub_scalar(B::float_sum_dim(B::float_sub(gauss, log_det), 1), (0.5 * a as f64 * LN_2PI).into()); // [B, 1]
    B::float_cat(vec![B::float_tanh(u), log_prob], 1)
}

/// `∂L/∂head` `[B, 2A]` from `∂L/∂[a | log π]` `[B, A + 1]` as tensor ops of `B` (the analytic
/// gradient of the module documentation).
fn backward_ops<B: Backend>(head: FloatTensor<B>, eps: FloatTensor<B>, dout: FloatTensor<B>, lo: f64, hi: f64) -> FloatTensor<B> {
    let a = head.shape()[1] / 2;
    let (mu, log_std, tx) = head_parts::<B>(head, lo, hi);
    let sigma_e = B::float_mul(B::float_exp(log_std), eps); // σ ε
    let act = B::float_tanh(B::float_add(mu, sigma_e.clone())); // a = tanh(u)
    let (d_act, d_log_prob) = (columns::<B>(dout.clone(), 0, a), columns::<B>(dout, a, a + 1));
    let one_minus_sq = |t: FloatTensor<B>| B::float_add_scalar(B::float_neg(B::float_mul(t.clone(), t)), 1.0f64.into()); // 1 − t²
    let du = B::float_add(B::float_mul(d_act, one_minus_sq(act.clone())), B::float_mul(B::float_mul_scalar(act, 2.0f64.into()), d_log_prob.clone())); // ∂a (1 − a²) + ∂log π · 2a
    let d_log_std = B::float_sub(B::float_mul(du.clone(), sigma_e), d_log_prob); // ∂u σ ε − ∂log π
    let dx = B::float_mul(B::float_mul_scalar(d_log_std, (0.5 * (hi - lo)).into()), one_minus_sq(tx)); // · ½ (hi − lo)(1 − tanh² x)
    B::float_cat(vec![du, dx], 1)
}

/// The fused squashed sample and its gradient, per backend (the default bodies: tensor ops).
#[backend_extension(Flex, Cube, Autodiff)]
pub trait SquashedSampleOps: Backend {
    /// `[a | log π]` `[B, A + 1]` from the head `[B, 2A]` and ε `[B, A]`, log σ in `[lo, hi]`.
    fn squashed_sample_fused(head: FloatTensor<Self>, eps: FloatTensor<Self>, lo: f64, hi: f64) -> FloatTensor<Self> {
        forward_ops::<Self>(head, eps, lo, hi)
    }

    /// `∂L/∂head` `[B, 2A]` from the forward pass's head and ε and `∂L/∂[a | log π]` `[B, A + 1]`.
    fn squashed_sample_backward(head: FloatTensor<Self>, eps: FloatTensor<Self>, dout: FloatTensor<Self>, lo: f64, hi: f64) -> FloatTensor<Self> {
        backward_ops::<Self>(head, eps, dout, lo, hi)
    }
}

impl SquashedSampleOps for Flex {}

impl SquashedSampleOps for Cube {
    fn squashed_sample_fused(head: FloatTensor<Self>, eps: FloatTensor<Self>, lo: f64, hi: f64) -> FloatTensor<Self> {
        match gpu::forward(&head, &eps, lo, hi) {
            Some(out) => out,
            None => forward_ops::<Self>(head, eps, lo, hi),
        }
    }

    fn squashed_sample_backward(head: FloatTensor<Self>, eps: FloatTensor<Self>, dout: FloatTensor<Self>, lo: f64, hi: f64) -> FloatTensor<Self> {
        match gpu::backward(&head, &eps, &dout, lo, hi) {
            Some(out) => out,
            None => backward_ops::<Self>(head, eps, dout, lo, hi),
        }
    }
}

/// The GPU's kernels, launched on burn's command stream.
mod gpu {
    use burn::backend::Cube;
    use burn::backend::TensorMetadata;
    use burn::backend::ops::FloatTensorOps;
    use burn::backend::tensor::FloatTensor;
    use burn::tensor::{FloatDType, Shape};

    use crate::learn::kernels::wgsl_kernel::{WgslKernel, is_plain, launch};

    /// shaders/squashed_common.wgsl: the constants' struct and the shared maths.
    const SHADER_COMMON: &str = include_str!("../../../shaders/squashed_common.wgsl");
    /// shaders/squashed_sample.wgsl.
    const SHADER_FORWARD: &str = include_str!("../../../shaders/squashed_sample.wgsl");
    /// shaders/squashed_sample_backward.wgsl.
    const SHADER_BACKWARD: &str = include_str!("../../../shaders/squashed_sample_backward.wgsl");
    /// Invocations per workgroup (squashed_common.wgsl's `SQ_WORKGROUP`), one per row.
    const WORKGROUP: u32 = 64;

    /// The forward module (one variant).
    pub fn forward_source(_: ()) -> String {
        [SHADER_COMMON, SHADER_FORWARD].join("\n")
    }

    /// The backward module (one variant).
    pub fn backward_source(_: ()) -> String {
        [SHADER_COMMON, SHADER_BACKWARD].join("\n")
    }

    /// (rows, A, the launch's constants `SqCfg`, the grid) for a head `[rows, 2A]` and ε
    /// `[rows, A]`, or None where they do not fit the kernels.
    fn config(head: &FloatTensor<Cube>, eps: &FloatTensor<Cube>, lo: f64, hi: f64) -> Option<(usize, usize, [u32; 6], [u32; 3])> {
        let [rows, two_a] = <[usize; 2]>::try_from(head.shape().to_vec()).ok()?;
        let a = two_a / 2;
        if rows == 0 || a == 0 || two_a != 2 * a || !is_plain(head, [rows, two_a]) || !is_plain(eps, [rows, a]) {
            return None;
        }
        u32::try_from(rows.checked_mul(two_a + 2)?).ok()?; // every index within 32 bits
        let (gx, gy) = crate::gpu::shaders::workgroups_of(u32::try_from(rows).ok()?, WORKGROUP);
        let half = (0.5 * (hi - lo)) as f32;
        Some((rows, a, [rows as u32, a as u32, gx * WORKGROUP, (lo as f32).to_bits(), half.to_bits(), 0], [gx, gy, 1]))
    }

    /// `[a | log π]` `[B, A + 1]` as one kernel, or None where the tensors do not fit it.
    pub fn forward(head: &FloatTensor<Cube>, eps: &FloatTensor<Cube>, lo: f64, hi: f64) -> Option<FloatTensor<Cube>> {
        let (rows, a, constants, groups) = config(head, eps, lo, hi)?;
        let out = Cube::float_empty(Shape::new([rows, a + 1]), &head.device, FloatDType::F32); // written whole below
        let kernel = WgslKernel { name: "dextrain_squashed_sample", key: (), source: forward_source, entry_point: "squashed_sample", workgroup: [WORKGROUP, 1] };
        launch(kernel, groups, &[head, eps, &out], &constants);
        Some(out)
    }

    /// `∂L/∂head` `[B, 2A]` as one kernel, or None where the tensors do not fit it.
    pub fn backward(head: &FloatTensor<Cube>, eps: &FloatTensor<Cube>, dout: &FloatTensor<Cube>, lo: f64, hi: f64) -> Option<FloatTensor<Cube>> {
        let (rows, a, constants, groups) = config(head, eps, lo, hi)?;
        if !is_plain(dout, [rows, a + 1]) {
            return None;
        }
        let dhead = Cube::float_empty(Shape::new([rows, 2 * a]), &head.device, FloatDType::F32); // written whole below
        let kernel = WgslKernel { name: "dextrain_squashed_sample_backward", key: (), source: backward_source, entry_point: "squashed_sample_backward", workgroup: [WORKGROUP, 1] };
        launch(kernel, groups, &[head, eps, dout, &dhead], &constants);
        Some(dhead)
    }
}

pub use gpu::{backward_source as squashed_sample_backward_source, forward_source as squashed_sample_source};

impl<B: Backend + SquashedSampleOps, C: CheckpointStrategy> SquashedSampleOps for Autodiff<B, C> {
    fn squashed_sample_fused(head: FloatTensor<Self>, eps: FloatTensor<Self>, lo: f64, hi: f64) -> FloatTensor<Self> {
        #[derive(Debug)]
        struct Squashed;

        impl<B: Backend + SquashedSampleOps> Backward<B, 1> for Squashed {
            /// The head, ε, lo and hi of the forward pass.
            type State = (FloatTensor<B>, FloatTensor<B>, f64, f64);

            fn backward(self, ops: Ops<Self::State, 1>, grads: &mut Gradients, _checkpointer: &mut Checkpointer) {
                let (head, eps, lo, hi) = ops.state;
                unary::<B, _>(ops.parents, ops.node, grads, |dout| B::squashed_sample_backward(head, eps, dout, lo, hi));
            }
        }

        let eps = eps.into_primitive(); // a constant: no gradient flows into the noise
        match Squashed.prepare::<C>([head.node()]).compute_bound().stateful() {
            OpsKind::Tracked(prep) => {
                let head = head.into_primitive();
                let out = B::squashed_sample_fused(head.clone(), eps.clone(), lo, hi);
                prep.finish((head, eps, lo, hi), out)
            }
            OpsKind::UnTracked(prep) => prep.finish(B::squashed_sample_fused(head.into_primitive(), eps, lo, hi)),
        }
    }
}

/// `(a [B, A], log π [B, 1])` from the actor's head `[B, 2A]` and ε `[B, A]` on any learner device,
/// differentiable in the head, as one operation (log σ squashed into `[lo, hi]`).
pub fn squashed_sample_fused(head: Tensor<2>, eps: Tensor<2>, lo: f64, hi: f64) -> (Tensor<2>, Tensor<2>) {
    let [_, two_a] = head.dims();
    let a = two_a / 2;
    let out: Tensor<2> = Tensor::from_dispatch(<burn::backend::Dispatch as SquashedSampleOps>::squashed_sample_fused(head.into_dispatch(), eps.into_dispatch(), lo, hi));
    (out.clone().narrow(1, 0, a), out.narrow(1, a, 1))
}
