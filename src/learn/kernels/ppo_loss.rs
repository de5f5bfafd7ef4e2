//! PPO's loss of one minibatch as one operation with its own gradient: from the actor's mean μ
//! `[B, A]`, log σ `[1, A]`, the critic's values V `[B, 1]`, the acting policy's σ_old `[1, A]`
//! and the minibatch's columns `[B, 2A + 4]` (the actions, μ_old, log π_old, Â, R, V_old: see
//! [`loss_columns`]), `[1, 5]` holding `[total, surrogate, value, entropy, KL]` — the maths of
//! `ppo::ppo_losses`, whose tensor ops it replaces on the GPU.
//!
//! As tensor ops the loss is ~45 kernels forward and ~65 in its backward pass per minibatch, half
//! of a PPO update's launches; on burn's wgpu runtime, where the lift's small networks make an
//! update's time the launch of its kernels rather than their arithmetic (BENCHMARKS.md, issue 33),
//! that is half of the learning time. Through burn's backend extensions:
//! - cubecl (the GPU): two kernels of ours each way (shaders/ppo_loss_rows.wgsl then
//!   ppo_loss_finish.wgsl; ppo_loss_backward.wgsl then ppo_loss_backward_finish.wgsl, each after
//!   ppo_loss_common.wgsl): one invocation per row, the sums over the rows a tree per workgroup
//!   then the workgroups' partial sums in order (a run repeats bit for bit);
//! - burn flex (the CPU) and any other backend: tensor ops (the forward pass the maths of
//!   `ppo_losses`, the backward pass the analytic gradient below). The CPU learner keeps
//!   `ppo_losses` itself, so its numbers are those of before;
//! - autodiff: the backward pass below, for μ, log σ and V (σ_old and the columns are constants).
//!
//! Only the total carries a gradient: the surrogate, value, entropy and KL columns are statistics,
//! and `∂L/∂out`'s other columns are not read (so the whole `[1, 5]` can start `backward`, whose
//! seed of ones then is `∂L/∂total = 1`, with no slice of it). The gradient, with
//! `g = ∂L/∂total` and per row `g_lp = g / B · ∂surr/∂ρ · ρ` (`∂surr/∂ρ = −Â` where the unclipped
//! term is the max or ρ within the clip range, else 0):
//! `∂μ_k = g_lp z_k / σ_k`, `∂ log σ_k = Σ_rows g_lp (z_k² − 1) − c_e g`,
//! `∂V = c_v g / B · ∂value/∂V` (`2 (V − R)`, or for the clipped loss where its clipped term is
//! the larger `2 (V_c − R)` inside the clip range and 0 outside it).

use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::checkpoint::strategy::CheckpointStrategy;
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{Backward, Ops, OpsKind};
use burn::backend::tensor::FloatTensor;
use burn::backend::{Autodiff, Backend, Cube, Flex, TensorMetadata, backend_extension, get_device_settings};
use burn::prelude::Tensor;
use burn::tensor::{FloatDType, Shape};

use super::{columns, mean_11};

const LN_2PI: f64 = 1.837_877_066_409_345_3; // ln(2π)

/// The loss's coefficients (`PpoConfig`'s).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LossCoefs {
    /// ε, the ratio's (and the clipped value loss's) clip range.
    pub clip: f64,
    /// c_v, the value loss's weight.
    pub value_coef: f64,
    /// c_e, the entropy bonus's weight.
    pub entropy_coef: f64,
    /// Whether the value loss is clipped around V_old.
    pub clipped_value: bool,
}

/// What both passes work out again per row as tensor ops of `B`: `(σ [B, A] (broadcast),
/// z [B, A], ρ [B, 1])`.
fn ratio_parts<B: Backend>(mu: FloatTensor<B>, log_std: FloatTensor<B>, cols: FloatTensor<B>) -> (FloatTensor<B>, FloatTensor<B>, FloatTensor<B>) {
    let (rows, a) = (mu.shape()[0], mu.shape()[1]);
    let sigma = B::float_expand(B::float_exp(log_std.clone()), Shape::new([rows, a])); // σ [B, A]
    let z = B::float_div(B::float_sub(columns::<B>(cols.clone(), 0, a), mu), sigma.clone()); // (a − μ) / σ
    let sum_ls = B::float_expand(B::float_sum_dim(log_std, 1), Shape::new([rows, 1])); // Σ log σ [B, 1]
    let log_prob = B::float_sub(B::float_mul_scalar(B::float_sum_dim(B::float_mul(z.clone(), z.clone()), 1), (-0.5f64).into()), sum_ls);
    let log_prob = B::float_sub_scalar(log_prob, (0.5 * a as f64 * LN_2PI).into()); // −½ Σ z² − Σ log σ − ½ A ln 2π
    let ratio = B::float_exp(B::float_sub(log_prob, columns::<B>(cols, 2 * a, 2 * a + 1))); // ρ
    (sigma, z, ratio)
}

/// `(−Â ρ, −Â clip(ρ, 1 − ε, 1 + ε))`, each `[B, 1]`.
fn surrogate_terms<B: Backend>(adv: FloatTensor<B>, ratio: FloatTensor<B>, eps: f64) -> (FloatTensor<B>, FloatTensor<B>) {
    let s1 = B::float_neg(B::float_mul(adv.clone(), ratio.clone()));
    let s2 = B::float_neg(B::float_mul(adv, B::float_clamp(ratio, (1.0 - eps).into(), (1.0 + eps).into())));
    (s1, s2)
}

/// `(V − R, V_c − R)` with `V_c = V_old + clip(V − V_old, −ε, ε)`, each `[B, 1]`, and `V − V_old`.
fn value_terms<B: Backend>(v: FloatTensor<B>, ret: FloatTensor<B>, old_v: FloatTensor<B>, eps: f64) -> (FloatTensor<B>, FloatTensor<B>, FloatTensor<B>) {
    let dv_old = B::float_sub(v.clone(), old_v.clone());
    let vc = B::float_add(old_v, B::float_clamp(dv_old.clone(), (-eps).into(), eps.into()));
    (B::float_sub(v, ret.clone()), B::float_sub(vc, ret), dv_old)
}

/// `[total, surrogate, value, entropy, KL]` `[1, 5]` as tensor ops of `B` (the maths of
/// `ppo_losses`).
fn forward_ops<B: Backend>(mu: FloatTensor<B>, log_std: FloatTensor<B>, v: FloatTensor<B>, old_sigma: FloatTensor<B>, cols: FloatTensor<B>, c: LossCoefs) -> FloatTensor<B> {
    let (rows, a) = (mu.shape()[0], mu.shape()[1]);
    let (sigma, _, ratio) = ratio_parts::<B>(mu.clone(), log_std.clone(), cols.clone());
    let (s1, s2) = surrogate_terms::<B>(columns::<B>(cols.clone(), 2 * a + 1, 2 * a + 2), ratio, c.clip);
    let bools = get_device_settings::<B>(&mu.device()).bool_dtype;
    let surrogate = mean_11::<B>(B::float_mask_where(s1.clone(), B::float_lower(s1, s2.clone(), bools), s2)); // max(s1, s2)
    let (e1, e2, _) = value_terms::<B>(v, columns::<B>(cols.clone(), 2 * a + 2, 2 * a + 3), columns::<B>(cols.clone(), 2 * a + 3, 2 * a + 4), c.clip);
    let l1 = B::float_mul(e1.clone(), e1);
    let value_rows = if c.clipped_value {
        let l2 = B::float_mul(e2.clone(), e2);
        B::float_mask_where(l1.clone(), B::float_lower(l1, l2.clone(), bools), l2)
    } else {
        l1
    };
    let value = mean_11::<B>(value_rows);
    let entropy = B::float_add_scalar(B::float_sum_dim(log_std.clone(), 1), (0.5 * a as f64 * (1.0 + LN_2PI)).into()); // [1, 1]
    let total = B::float_sub(
        B::float_add(surrogate.clone(), B::float_mul_scalar(value.clone(), c.value_coef.into())),
        B::float_mul_scalar(entropy.clone(), c.entropy_coef.into()),
    );
    // KL(π_old ‖ π) per row: Σ_k [log σ − ln σ_old + (σ_old² + (μ_old − μ)²) / (2σ²) − ½]
    let shape = Shape::new([rows, a]);
    let old_sigma = B::float_expand(old_sigma, shape.clone());
    let dm = B::float_sub(columns::<B>(cols, a, 2 * a), mu);
    let num = B::float_add(B::float_mul(old_sigma.clone(), old_sigma.clone()), B::float_mul(dm.clone(), dm));
    let den = B::float_mul_scalar(B::float_mul(sigma.clone(), sigma), 2.0f64.into());
    let log_ratio = B::float_sub(B::float_expand(log_std, shape), B::float_log(old_sigma));
    let kl_terms = B::float_sub_scalar(B::float_add(log_ratio, B::float_div(num, den)), 0.5f64.into());
    let kl = mean_11::<B>(B::float_sum_dim(kl_terms, 1));
    B::float_cat(vec![total, surrogate, value, entropy, kl], 1)
}

/// `(∂L/∂μ [B, A], ∂L/∂ log σ [1, A], ∂L/∂V [B, 1])` from `∂L/∂out` `[1, 5]` (its first column,
/// `∂L/∂total`) as tensor ops of `B` (the analytic gradient of the module documentation).
fn backward_ops<B: Backend>(mu: FloatTensor<B>, log_std: FloatTensor<B>, v: FloatTensor<B>, cols: FloatTensor<B>, dout: FloatTensor<B>, c: LossCoefs) -> (FloatTensor<B>, FloatTensor<B>, FloatTensor<B>) {
    let (rows, a) = (mu.shape()[0], mu.shape()[1]);
    let device = mu.device();
    let bools = get_device_settings::<B>(&device).bool_dtype;
    let zeros = || B::float_zeros(Shape::new([rows, 1]), &device, FloatDType::F32);
    let g = columns::<B>(dout, 0, 1); // ∂L/∂total [1, 1]
    let inv_b = 1.0 / rows as f64;
    let g_s = B::float_mul_scalar(g.clone(), inv_b.into()); // g / B
    let g_v = B::float_mul_scalar(g.clone(), (c.value_coef * inv_b).into()); // c_v g / B
    let g_e = B::float_mul_scalar(g, (-c.entropy_coef).into()); // −c_e g
    let (sigma, z, ratio) = ratio_parts::<B>(mu, log_std, cols.clone());
    let adv = columns::<B>(cols.clone(), 2 * a + 1, 2 * a + 2);
    let (s1, s2) = surrogate_terms::<B>(adv.clone(), ratio.clone(), c.clip);
    // −Â where the unclipped term is the max or ρ lies within the clip range, else 0
    let inside = B::bool_and(B::float_greater_equal_elem(ratio.clone(), (1.0 - c.clip).into(), bools), B::float_lower_equal_elem(ratio.clone(), (1.0 + c.clip).into(), bools));
    let passes = B::bool_or(B::float_greater_equal(s1, s2, bools), inside);
    let dratio = B::float_mask_where(zeros(), passes, B::float_neg(adv));
    let g_lp = B::float_mul(B::float_mul(dratio, ratio), B::float_expand(g_s, Shape::new([rows, 1]))); // ∂L/∂ log π [B, 1]
    let g_lp_a = B::float_expand(g_lp, Shape::new([rows, a]));
    let dmu = B::float_div(B::float_mul(g_lp_a.clone(), z.clone()), sigma); // g_lp z / σ
    let row_terms = B::float_mul(g_lp_a, B::float_sub_scalar(B::float_mul(z.clone(), z), 1.0f64.into())); // g_lp (z² − 1)
    let dlog_std = B::float_add(B::float_sum_dim(row_terms, 0), B::float_expand(g_e, Shape::new([1, a])));
    let (e1, e2, dv_old) = value_terms::<B>(v, columns::<B>(cols.clone(), 2 * a + 2, 2 * a + 3), columns::<B>(cols, 2 * a + 3, 2 * a + 4), c.clip);
    let dvalue = if c.clipped_value {
        // 2 (V − R) where the unclipped term is the larger, else 2 (V_c − R) inside the clip range, 0 outside
        let unclipped = B::float_greater_equal(B::float_mul(e1.clone(), e1.clone()), B::float_mul(e2.clone(), e2.clone()), bools);
        let inside = B::bool_and(B::float_greater_equal_elem(dv_old.clone(), (-c.clip).into(), bools), B::float_lower_equal_elem(dv_old, c.clip.into(), bools));
        let clipped = B::float_mask_where(zeros(), inside, e2);
        B::float_mul_scalar(B::float_mask_where(clipped, unclipped, e1), 2.0f64.into())
    } else {
        B::float_mul_scalar(e1, 2.0f64.into())
    };
    let dv = B::float_mul(dvalue, B::float_expand(g_v, Shape::new([rows, 1])));
    (dmu, dlog_std, dv)
}

/// The fused PPO loss and its gradient, per backend (the default bodies: tensor ops).
#[backend_extension(Flex, Cube, Autodiff)]
pub trait PpoLossOps: Backend {
    /// `[total, surrogate, value, entropy, KL]` `[1, 5]` from μ `[B, A]`, log σ `[1, A]`, V
    /// `[B, 1]`, σ_old `[1, A]` and the columns `[B, 2A + 4]`.
    fn ppo_loss_fused(mu: FloatTensor<Self>, log_std: FloatTensor<Self>, v: FloatTensor<Self>, old_sigma: FloatTensor<Self>, cols: FloatTensor<Self>, coefs: LossCoefs) -> FloatTensor<Self> {
        forward_ops::<Self>(mu, log_std, v, old_sigma, cols, coefs)
    }

    /// `(∂L/∂μ, ∂L/∂ log σ, ∂L/∂V)` from the forward pass's μ, log σ, V and columns and
    /// `∂L/∂out` `[1, 5]`.
    fn ppo_loss_backward(mu: FloatTensor<Self>, log_std: FloatTensor<Self>, v: FloatTensor<Self>, cols: FloatTensor<Self>, dout: FloatTensor<Self>, coefs: LossCoefs) -> (FloatTensor<Self>, FloatTensor<Self>, FloatTensor<Self>) {
        backward_ops::<Self>(mu, log_std, v, cols, dout, coefs)
    }
}

impl PpoLossOps for Flex {}

impl PpoLossOps for Cube {
    fn ppo_loss_fused(mu: FloatTensor<Self>, log_std: FloatTensor<Self>, v: FloatTensor<Self>, old_sigma: FloatTensor<Self>, cols: FloatTensor<Self>, coefs: LossCoefs) -> FloatTensor<Self> {
        match gpu::forward(&mu, &log_std, &v, &old_sigma, &cols, coefs) {
            Some(out) => out,
            None => forward_ops::<Self>(mu, log_std, v, old_sigma, cols, coefs),
        }
    }

    fn ppo_loss_backward(mu: FloatTensor<Self>, log_std: FloatTensor<Self>, v: FloatTensor<Self>, cols: FloatTensor<Self>, dout: FloatTensor<Self>, coefs: LossCoefs) -> (FloatTensor<Self>, FloatTensor<Self>, FloatTensor<Self>) {
        match gpu::backward(&mu, &log_std, &v, &cols, &dout, coefs) {
            Some(grads) => grads,
            None => backward_ops::<Self>(mu, log_std, v, cols, dout, coefs),
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

    use super::LossCoefs;
    use crate::learn::kernels::wgsl_kernel::{WgslKernel, is_plain, launch};

    /// shaders/ppo_loss_common.wgsl: the constants' struct and the per-row terms.
    const SHADER_COMMON: &str = include_str!("../../../shaders/ppo_loss_common.wgsl");
    /// The four modules, each after the common part.
    const SHADER_ROWS: &str = include_str!("../../../shaders/ppo_loss_rows.wgsl");
    const SHADER_FINISH: &str = include_str!("../../../shaders/ppo_loss_finish.wgsl");
    const SHADER_BACKWARD: &str = include_str!("../../../shaders/ppo_loss_backward.wgsl");
    const SHADER_BACKWARD_FINISH: &str = include_str!("../../../shaders/ppo_loss_backward_finish.wgsl");
    /// Invocations per workgroup (ppo_loss_common.wgsl's `PL_WORKGROUP`).
    const WORKGROUP: u32 = 256;

    /// The WGSL module of kernel `k` (0 rows, 1 finish, 2 backward, 3 backward finish).
    pub fn source(k: u8) -> String {
        let body = match k {
            0 => SHADER_ROWS,
            1 => SHADER_FINISH,
            2 => SHADER_BACKWARD,
            _ => SHADER_BACKWARD_FINISH,
        };
        [SHADER_COMMON, body].join("\n")
    }

    /// (B, A, the launch's constants `PpoLossCfg`, the row kernels' workgroups) for the forward
    /// pass's inputs, or None where they do not fit the kernels.
    fn config(mu: &FloatTensor<Cube>, log_std: &FloatTensor<Cube>, v: &FloatTensor<Cube>, cols: &FloatTensor<Cube>, c: LossCoefs) -> Option<(usize, usize, [u32; 8], u32)> {
        let [rows, a] = <[usize; 2]>::try_from(mu.shape().to_vec()).ok()?;
        if rows == 0 || a == 0 || !is_plain(mu, [rows, a]) || !is_plain(log_std, [1, a]) || !is_plain(v, [rows, 1]) || !is_plain(cols, [rows, 2 * a + 4]) {
            return None;
        }
        u32::try_from(rows.checked_mul(2 * a + 4)?).ok()?; // every index within 32 bits
        let groups = u32::try_from(rows.div_ceil(WORKGROUP as usize)).ok().filter(|&g| g <= 65_535)?; // a 1-D grid
        let f = |x: f64| (x as f32).to_bits();
        let constants = [rows as u32, a as u32, groups, u32::from(c.clipped_value), f(c.clip), f(c.value_coef), f(c.entropy_coef), 0];
        Some((rows, a, constants, groups))
    }

    fn kernel(k: u8) -> WgslKernel<u8> {
        let (name, entry_point) = match k {
            0 => ("dextrain_ppo_loss_rows", "ppo_loss_rows"),
            1 => ("dextrain_ppo_loss_finish", "ppo_loss_finish"),
            2 => ("dextrain_ppo_loss_backward", "ppo_loss_backward"),
            _ => ("dextrain_ppo_loss_backward_finish", "ppo_loss_backward_finish"),
        };
        WgslKernel { name, key: k, source, entry_point, workgroup: [WORKGROUP, 1] }
    }

    /// `[1, 5]` as two kernels, or None where the tensors do not fit them.
    pub fn forward(mu: &FloatTensor<Cube>, log_std: &FloatTensor<Cube>, v: &FloatTensor<Cube>, old_sigma: &FloatTensor<Cube>, cols: &FloatTensor<Cube>, c: LossCoefs) -> Option<FloatTensor<Cube>> {
        let (_, a, constants, groups) = config(mu, log_std, v, cols, c)?;
        if !is_plain(old_sigma, [1, a]) {
            return None;
        }
        let device = &mu.device;
        let partial = Cube::float_empty(Shape::new([groups as usize, 3]), device, FloatDType::F32); // written whole by the row kernel
        launch(kernel(0), [groups, 1, 1], &[mu, v, log_std, old_sigma, cols, &partial], &constants);
        let out = Cube::float_empty(Shape::new([1, 5]), device, FloatDType::F32); // written whole below
        launch(kernel(1), [1, 1, 1], &[&partial, log_std, &out], &constants);
        Some(out)
    }

    /// `(∂μ, ∂ log σ, ∂V)` as two kernels, or None where the tensors do not fit them.
    pub fn backward(mu: &FloatTensor<Cube>, log_std: &FloatTensor<Cube>, v: &FloatTensor<Cube>, cols: &FloatTensor<Cube>, dout: &FloatTensor<Cube>, c: LossCoefs) -> Option<(FloatTensor<Cube>, FloatTensor<Cube>, FloatTensor<Cube>)> {
        let (rows, a, constants, groups) = config(mu, log_std, v, cols, c)?;
        if !is_plain(dout, [1, 5]) {
            return None;
        }
        let device = &mu.device;
        // each written whole by the kernels below
        let dmu = Cube::float_empty(Shape::new([rows, a]), device, FloatDType::F32);
        let dv = Cube::float_empty(Shape::new([rows, 1]), device, FloatDType::F32);
        let partial = Cube::float_empty(Shape::new([groups as usize, a]), device, FloatDType::F32);
        launch(kernel(2), [groups, 1, 1], &[mu, v, log_std, cols, dout, &dmu, &dv, &partial], &constants);
        let dlog_std = Cube::float_empty(Shape::new([1, a]), device, FloatDType::F32);
        launch(kernel(3), [(a as u32).div_ceil(WORKGROUP), 1, 1], &[&partial, dout, &dlog_std], &constants);
        Some((dmu, dlog_std, dv))
    }
}

pub use gpu::source as ppo_loss_source;

impl<B: Backend + PpoLossOps, C: CheckpointStrategy> PpoLossOps for Autodiff<B, C> {
    fn ppo_loss_fused(mu: FloatTensor<Self>, log_std: FloatTensor<Self>, v: FloatTensor<Self>, old_sigma: FloatTensor<Self>, cols: FloatTensor<Self>, coefs: LossCoefs) -> FloatTensor<Self> {
        #[derive(Debug)]
        struct PpoLoss;

        impl<B: Backend + PpoLossOps> Backward<B, 3> for PpoLoss {
            /// μ, log σ, V, the columns and the coefficients of the forward pass.
            type State = (FloatTensor<B>, FloatTensor<B>, FloatTensor<B>, FloatTensor<B>, LossCoefs);

            fn backward(self, ops: Ops<Self::State, 3>, grads: &mut Gradients, _checkpointer: &mut Checkpointer) {
                let (mu, log_std, v, cols, coefs) = ops.state;
                let dout = grads.consume::<B>(&ops.node); // [1, 5]
                let (dmu, dlog_std, dv) = B::ppo_loss_backward(mu, log_std, v, cols, dout, coefs);
                let [node_mu, node_log_std, node_v] = ops.parents;
                for (node, grad) in [(node_mu, dmu), (node_log_std, dlog_std), (node_v, dv)] {
                    if let Some(node) = node {
                        grads.register::<B>(node.id, grad);
                    }
                }
            }
        }

        // σ_old and the columns are constants: no gradient flows into them
        let (old_sigma, cols) = (old_sigma.into_primitive(), cols.into_primitive());
        match PpoLoss.prepare::<C>([mu.node(), log_std.node(), v.node()]).compute_bound().stateful() {
            OpsKind::Tracked(prep) => {
                let (mu, log_std, v) = (mu.into_primitive(), log_std.into_primitive(), v.into_primitive());
                let out = B::ppo_loss_fused(mu.clone(), log_std.clone(), v.clone(), old_sigma, cols.clone(), coefs);
                prep.finish((mu, log_std, v, cols, coefs), out)
            }
            OpsKind::UnTracked(prep) => prep.finish(B::ppo_loss_fused(mu.into_primitive(), log_std.into_primitive(), v.into_primitive(), old_sigma, cols, coefs)),
        }
    }
}

/// The minibatch columns the fused loss reads, `[R, 2A + 4]`: the actions, μ_old (each `[R, A]`),
/// log π_old, Â, R and V_old (each `[R, 1]`), side by side (one gather per minibatch picks them).
pub fn loss_columns(actions: Tensor<2>, old_mu: Tensor<2>, old_log_prob: Tensor<2>, advantages: Tensor<2>, returns: Tensor<2>, old_values: Tensor<2>) -> Tensor<2> {
    Tensor::cat(vec![actions, old_mu, old_log_prob, advantages, returns, old_values], 1)
}

/// `[total, surrogate, value, entropy, KL]` `[1, 5]` of PPO's loss on any learner device,
/// differentiable in μ `[B, A]`, log σ `[1, A]` and V `[B, 1]` (σ_old `[1, A]` and the columns
/// `[B, 2A + 4]` of [`loss_columns`] constants), as one operation.
pub fn ppo_loss_fused(mu: Tensor<2>, log_std: Tensor<2>, v: Tensor<2>, old_sigma: Tensor<2>, cols: Tensor<2>, coefs: LossCoefs) -> Tensor<2> {
    Tensor::from_dispatch(<burn::backend::Dispatch as PpoLossOps>::ppo_loss_fused(
        mu.into_dispatch(),
        log_std.into_dispatch(),
        v.into_dispatch(),
        old_sigma.into_dispatch(),
        cols.into_dispatch(),
        coefs,
    ))
}
