//! SAC's per-row losses as one operation each with its own gradient, over two columns a, b
//! `[B, 1]` (the maths of `sac::Sac::gradient_step_on`'s tensor ops, which the CPU learner keeps):
//! - [`SacLoss::Critic`]: a critic's `[mean (Q − y)², q_scale · mean Q]` from its values Q and the
//!   target y (a constant);
//! - [`SacLoss::Actor`]: the actor's `[mean (α log π − Q̃), −mean log π]` from log π(ã|s) and the
//!   critics' reduced value Q̃ of ã, α = exp(log α) (a constant here: the temperature has a loss
//!   of its own).
//!
//! As tensor ops a critic's loss and its statistic were ~13 kernels forward and backward, the
//! actor's loss and the entropy estimate ~15, per gradient step; on burn's wgpu runtime, where
//! SAC's step is bound by the launch of its ~300 kernels (BENCHMARKS.md, issue 33), each launch
//! saved is time saved. Through burn's backend extensions:
//! - cubecl (the GPU): two kernels of ours forward (shaders/sac_loss_rows.wgsl, then
//!   sac_loss_finish.wgsl: the sums a tree per workgroup, then the workgroups' sums in order, so a
//!   run repeats bit for bit) and one backward (sac_loss_backward.wgsl), each after
//!   sac_loss_common.wgsl;
//! - burn flex (the CPU) and any other backend: tensor ops (the same maths);
//! - autodiff: only `out[0]` (the loss) carries a gradient; `out[1]` is a statistic, and
//!   `∂L/∂out`'s second column is not read (so the whole `[1, 2]` can start `backward`). With
//!   `g = ∂L/∂out[0]`: critic `∂Q = 2 (Q − y) g / B` (`∂y = −∂Q`); actor `∂ log π = α g / B`,
//!   `∂Q̃ = −g / B`.

use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::checkpoint::strategy::CheckpointStrategy;
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{Backward, Ops, OpsKind};
use burn::backend::tensor::FloatTensor;
use burn::backend::{Autodiff, Backend, Cube, Flex, TensorMetadata, backend_extension};
use burn::prelude::Tensor;
use burn::tensor::{Shape, Slice};

use super::mean_11;

/// Which of SAC's losses.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SacLoss {
    /// A critic's: a = Q_j(ĉ, a), b = the target y; `out = [mean (a − b)², q_scale · mean a]`
    /// (q_scale = 1 / critics: the critics' mean Q adds up over the critics).
    Critic { q_scale: f64 },
    /// The actor's: a = log π(ã|s), b = the critics' reduced Q̃(ĉ, ã); `out = [mean (α a − b),
    /// −mean a]`.
    Actor,
}

impl SacLoss {
    /// The kind's number in the kernels' constants.
    fn code(self) -> u32 {
        match self {
            SacLoss::Critic { .. } => 0,
            SacLoss::Actor => 1,
        }
    }
}

/// `out` `[1, 2]` as tensor ops of `B` (α = exp(log α) `[1, 1]`).
fn forward_ops<B: Backend>(a: FloatTensor<B>, b: FloatTensor<B>, log_alpha: FloatTensor<B>, kind: SacLoss) -> FloatTensor<B> {
    let rows = a.shape()[0];
    match kind {
        SacLoss::Critic { q_scale } => {
            let e = B::float_sub(a.clone(), b); // Q − y
            B::float_cat(vec![mean_11::<B>(B::float_mul(e.clone(), e)), B::float_mul_scalar(mean_11::<B>(a), q_scale.into())], 1)
        }
        SacLoss::Actor => {
            let alpha = B::float_expand(B::float_exp(log_alpha), Shape::new([rows, 1]));
            let loss = mean_11::<B>(B::float_sub(B::float_mul(a.clone(), alpha), b)); // mean(α log π − Q̃)
            B::float_cat(vec![loss, B::float_neg(mean_11::<B>(a))], 1)
        }
    }
}

/// `(∂L/∂a, ∂L/∂b)`, each `[B, 1]`, from `∂L/∂out` `[1, 2]` as tensor ops of `B`.
fn backward_ops<B: Backend>(a: FloatTensor<B>, b: FloatTensor<B>, log_alpha: FloatTensor<B>, dout: FloatTensor<B>, kind: SacLoss) -> (FloatTensor<B>, FloatTensor<B>) {
    let rows = a.shape()[0];
    let g = B::float_slice(dout, &[Slice::from(0..1), Slice::from(0..1)]); // ∂L/∂out[0] [1, 1]
    let g = B::float_expand(B::float_mul_scalar(g, (1.0 / rows as f64).into()), Shape::new([rows, 1])); // g / B
    match kind {
        SacLoss::Critic { .. } => {
            let da = B::float_mul(B::float_mul_scalar(B::float_sub(a, b), 2.0f64.into()), g); // 2 (Q − y) g / B
            (da.clone(), B::float_neg(da))
        }
        SacLoss::Actor => {
            let alpha = B::float_expand(B::float_exp(log_alpha), Shape::new([rows, 1]));
            (B::float_mul(alpha, g.clone()), B::float_neg(g))
        }
    }
}

/// SAC's fused losses and their gradient, per backend (the default bodies: tensor ops).
#[backend_extension(Flex, Cube, Autodiff)]
pub trait SacLossOps: Backend {
    /// `out` `[1, 2]` of `kind` from a, b `[B, 1]` and log α `[1, 1]`.
    fn sac_loss_fused(a: FloatTensor<Self>, b: FloatTensor<Self>, log_alpha: FloatTensor<Self>, kind: SacLoss) -> FloatTensor<Self> {
        forward_ops::<Self>(a, b, log_alpha, kind)
    }

    /// `(∂L/∂a, ∂L/∂b)` from the forward pass's a, b, log α and `∂L/∂out` `[1, 2]`.
    fn sac_loss_backward(a: FloatTensor<Self>, b: FloatTensor<Self>, log_alpha: FloatTensor<Self>, dout: FloatTensor<Self>, kind: SacLoss) -> (FloatTensor<Self>, FloatTensor<Self>) {
        backward_ops::<Self>(a, b, log_alpha, dout, kind)
    }
}

impl SacLossOps for Flex {}

impl SacLossOps for Cube {
    fn sac_loss_fused(a: FloatTensor<Self>, b: FloatTensor<Self>, log_alpha: FloatTensor<Self>, kind: SacLoss) -> FloatTensor<Self> {
        match gpu::forward(&a, &b, &log_alpha, kind) {
            Some(out) => out,
            None => forward_ops::<Self>(a, b, log_alpha, kind),
        }
    }

    fn sac_loss_backward(a: FloatTensor<Self>, b: FloatTensor<Self>, log_alpha: FloatTensor<Self>, dout: FloatTensor<Self>, kind: SacLoss) -> (FloatTensor<Self>, FloatTensor<Self>) {
        match gpu::backward(&a, &b, &log_alpha, &dout, kind) {
            Some(grads) => grads,
            None => backward_ops::<Self>(a, b, log_alpha, dout, kind),
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

    use super::SacLoss;
    use crate::learn::kernels::wgsl_kernel::{WgslKernel, is_plain, launch};

    /// shaders/sac_loss_common.wgsl: the constants' struct and the per-row terms.
    const SHADER_COMMON: &str = include_str!("../../../shaders/sac_loss_common.wgsl");
    /// The three modules, each after the common part.
    const SHADER_ROWS: &str = include_str!("../../../shaders/sac_loss_rows.wgsl");
    const SHADER_FINISH: &str = include_str!("../../../shaders/sac_loss_finish.wgsl");
    const SHADER_BACKWARD: &str = include_str!("../../../shaders/sac_loss_backward.wgsl");
    /// Invocations per workgroup (sac_loss_common.wgsl's `SL_WORKGROUP`).
    const WORKGROUP: u32 = 256;

    /// The WGSL module of kernel `k` (0 rows, 1 finish, 2 backward).
    pub fn source(k: u8) -> String {
        let body = match k {
            0 => SHADER_ROWS,
            1 => SHADER_FINISH,
            _ => SHADER_BACKWARD,
        };
        [SHADER_COMMON, body].join("\n")
    }

    fn kernel(k: u8) -> WgslKernel<u8> {
        let (name, entry_point) = match k {
            0 => ("dextrain_sac_loss_rows", "sac_loss_rows"),
            1 => ("dextrain_sac_loss_finish", "sac_loss_finish"),
            _ => ("dextrain_sac_loss_backward", "sac_loss_backward"),
        };
        WgslKernel { name, key: k, source, entry_point, workgroup: [WORKGROUP, 1] }
    }

    /// (B, the launch's constants `SacLossCfg`, the row kernels' workgroups), or None where the
    /// tensors do not fit the kernels.
    fn config(a: &FloatTensor<Cube>, b: &FloatTensor<Cube>, log_alpha: &FloatTensor<Cube>, kind: SacLoss) -> Option<(usize, [u32; 4], u32)> {
        let rows = a.shape()[0];
        if rows == 0 || !is_plain(a, [rows, 1]) || !is_plain(b, [rows, 1]) || !is_plain(log_alpha, [1, 1]) {
            return None;
        }
        let rows32 = u32::try_from(rows).ok()?;
        let groups = rows32.div_ceil(WORKGROUP);
        if groups > 65_535 {
            return None; // a 1-D grid
        }
        let q_scale = match kind {
            SacLoss::Critic { q_scale } => q_scale as f32,
            SacLoss::Actor => 0.0,
        };
        Some((rows, [rows32, kind.code(), groups, q_scale.to_bits()], groups))
    }

    /// `out` `[1, 2]` as two kernels, or None where the tensors do not fit them.
    pub fn forward(a: &FloatTensor<Cube>, b: &FloatTensor<Cube>, log_alpha: &FloatTensor<Cube>, kind: SacLoss) -> Option<FloatTensor<Cube>> {
        let (_, constants, groups) = config(a, b, log_alpha, kind)?;
        let partial = Cube::float_empty(Shape::new([groups as usize, 2]), &a.device, FloatDType::F32); // written whole by the row kernel
        launch(kernel(0), [groups, 1, 1], &[a, b, log_alpha, &partial], &constants);
        let out = Cube::float_empty(Shape::new([1, 2]), &a.device, FloatDType::F32); // written whole below
        launch(kernel(1), [1, 1, 1], &[&partial, &out], &constants);
        Some(out)
    }

    /// `(∂a, ∂b)` as one kernel, or None where the tensors do not fit it.
    pub fn backward(a: &FloatTensor<Cube>, b: &FloatTensor<Cube>, log_alpha: &FloatTensor<Cube>, dout: &FloatTensor<Cube>, kind: SacLoss) -> Option<(FloatTensor<Cube>, FloatTensor<Cube>)> {
        let (rows, constants, groups) = config(a, b, log_alpha, kind)?;
        if !is_plain(dout, [1, 2]) {
            return None;
        }
        // each written whole by the kernel
        let da = Cube::float_empty(Shape::new([rows, 1]), &a.device, FloatDType::F32);
        let db = Cube::float_empty(Shape::new([rows, 1]), &a.device, FloatDType::F32);
        launch(kernel(2), [groups, 1, 1], &[a, b, log_alpha, dout, &da, &db], &constants);
        Some((da, db))
    }
}

pub use gpu::source as sac_loss_source;

impl<B: Backend + SacLossOps, C: CheckpointStrategy> SacLossOps for Autodiff<B, C> {
    fn sac_loss_fused(a: FloatTensor<Self>, b: FloatTensor<Self>, log_alpha: FloatTensor<Self>, kind: SacLoss) -> FloatTensor<Self> {
        #[derive(Debug)]
        struct SacLossOp;

        impl<B: Backend + SacLossOps> Backward<B, 2> for SacLossOp {
            /// a, b, log α and the kind of the forward pass.
            type State = (FloatTensor<B>, FloatTensor<B>, FloatTensor<B>, SacLoss);

            fn backward(self, ops: Ops<Self::State, 2>, grads: &mut Gradients, _checkpointer: &mut Checkpointer) {
                let (a, b, log_alpha, kind) = ops.state;
                let dout = grads.consume::<B>(&ops.node); // [1, 2]
                let (da, db) = B::sac_loss_backward(a, b, log_alpha, dout, kind);
                let [node_a, node_b] = ops.parents;
                for (node, grad) in [(node_a, da), (node_b, db)] {
                    if let Some(node) = node {
                        grads.register::<B>(node.id, grad);
                    }
                }
            }
        }

        let log_alpha = log_alpha.into_primitive(); // a constant here: α has a loss of its own
        match SacLossOp.prepare::<C>([a.node(), b.node()]).compute_bound().stateful() {
            OpsKind::Tracked(prep) => {
                let (a, b) = (a.into_primitive(), b.into_primitive());
                let out = B::sac_loss_fused(a.clone(), b.clone(), log_alpha.clone(), kind);
                prep.finish((a, b, log_alpha, kind), out)
            }
            OpsKind::UnTracked(prep) => prep.finish(B::sac_loss_fused(a.into_primitive(), b.into_primitive(), log_alpha, kind)),
        }
    }
}

/// SAC's loss `kind` `[1, 2]` on any learner device, differentiable in a and b `[B, 1]` through
/// its first entry (log α `[1, 1]` a constant), as one operation.
pub fn sac_loss_fused(a: Tensor<2>, b: Tensor<2>, log_alpha: Tensor<2>, kind: SacLoss) -> Tensor<2> {
    Tensor::from_dispatch(<burn::backend::Dispatch as SacLossOps>::sac_loss_fused(a.into_dispatch(), b.into_dispatch(), log_alpha.into_dispatch(), kind))
}
