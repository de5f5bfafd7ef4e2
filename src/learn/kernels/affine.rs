//! A dense layer `y = x W + b` as one operation with its own gradient: x [B, in], W [in, out],
//! b [1, out] → y [B, out]; backward `∂x = g Wᵀ` [B, in], `∂W = xᵀ g` [in, out], `∂b = 1ᵀ g`
//! [1, out] for g = ∂L/∂y.
//!
//! Written as `x.matmul(w) + b`, burn's CPU backend (flex) allocates every product's output as a
//! zeroed byte vector and then copies it into an aligned one (`FlexTensor::empty` →
//! `Bytes::from_bytes_vec`): a memset and a memcpy per matmul, forward and both backward products,
//! 7-8 % of a PPO update on one core (BENCHMARKS.md), plus a separate pass for the broadcast bias
//! add and a reduction for its gradient. Here, through burn's backend extensions:
//! - burn flex (the CPU): the output is a `Vec<f32>` handed to the tensor without a copy; the
//!   forward writes the bias rows and lets gemm accumulate `x W` onto them (`dst = dst + x W`), the
//!   backward products write their outputs directly (gemm without reading dst), and `∂b` is one
//!   read pass; where the learner's kernels are AVX2 (`sgemm::runs`), `x W` and `g Wᵀ` run
//!   dextrain's own AVX2 product (`learn::kernels::sgemm`) instead of gemm's;
//! - cubecl (the GPU): the products with the matmul routine chosen by measurement
//!   (`learn::kernels::gpu_matmul`); with dextrain's kernel (the default) `x W + b` is one kernel, the bias
//!   added as the product is written; `∂b` as a two-stage column sum (`learn::kernels::row_sums`);
//! - autodiff: the gradients above, for the inputs that are tracked only (the first layer's
//!   observations are not: no `∂x` there).
//!
//! A hidden layer with its ELU, `ELU(x W + b)`, is one op too (`affine_elu_fused`): on the GPU
//! with dextrain's kernel one kernel (bias and ELU as the product is written, where a layer was
//! the product, a bias add and ELU's five kernels); on the CPU the two ops' values unchanged; its
//! gradient is ELU's then the dense layer's, as the two ops compute them.
//!
//! In an MLP the layers are linked ([`EluLink`], `nets::mlp_forward`): ELU's gradient of a hidden
//! layer is applied by the layer after it, to its input gradient `g Wᵀ` — on the GPU in that
//! product's epilogue (one kernel where the product and ELU's gradient were two) — and the ELU
//! layer takes what arrives as the gradient before its activation. On the GPU a layer's weight and
//! bias gradients are one product too, `[xᵀ; 1ᵀ] g` (A read with a row of ones,
//! `wgsl_matmul::Epilogue::ColumnSums`; where the product is split over k, one kernel sums both
//! partials): a PPO minibatch's backward pass of two 4-layer networks is 14 kernels fewer. The
//! values: ELU's gradient the same expression on the same product (the same bits); the bias
//! gradient each split's rows added in order by the product, then the splits (where the column
//! sums kernel added row blocks: other rounding, ~1e-7 relative).

use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::checkpoint::strategy::CheckpointStrategy;
use burn::backend::autodiff::NodeId;
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{Backward, Ops, OpsKind};
use burn::backend::tensor::FloatTensor;
use burn::backend::{Autodiff, Backend, Cube, Flex, backend_extension};
use burn::prelude::Tensor;
use burn::tensor::{Bytes, DType, Shape};
use burn_flex::{FlexTensor, Layout};
use rayon::prelude::*;

use burn::backend::TensorMetadata;
use burn::backend::ops::FloatTensorOps;

use crate::learn::kernels::elu::EluOps;
use crate::learn::kernels::wgsl_matmul::Epilogue;
use super::{gpu_matmul, row_sums, sgemm};

/// `x W + b` as tensor ops of `B`.
fn affine_ops<B: Backend>(x: FloatTensor<B>, w: FloatTensor<B>, b: FloatTensor<B>) -> FloatTensor<B> {
    B::float_add(B::float_matmul(x, w), b)
}

/// `g Wᵀ` as tensor ops of `B`.
fn grad_x_ops<B: Backend>(g: FloatTensor<B>, w: FloatTensor<B>) -> FloatTensor<B> {
    B::float_matmul(g, B::float_transpose(w))
}

/// `xᵀ g` as tensor ops of `B`.
fn grad_w_ops<B: Backend>(x: FloatTensor<B>, g: FloatTensor<B>) -> FloatTensor<B> {
    B::float_matmul(B::float_transpose(x), g)
}

/// `1ᵀ g` as tensor ops of `B`.
fn grad_b_ops<B: Backend>(g: FloatTensor<B>) -> FloatTensor<B> {
    B::float_sum_dim(g, 0)
}

/// How a dense layer's op shares ELU's gradient with its neighbours in an MLP: the layer after an
/// ELU layer applies that ELU's gradient to its own input gradient, and the ELU layer takes the
/// gradient that arrives as the one before its activation. `nets::mlp_forward` links consecutive
/// layers where each hidden activation is the next layer's input and nothing else's (the contract:
/// a second consumer's gradient would arrive without ELU's factor).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct EluLink {
    /// x is the output of a linked ELU layer (`into_linked`): ∂x here is `(g Wᵀ) · ELU'(x)`,
    /// ∂L/∂(that layer's x W + b) (on the GPU one product with ELU's gradient in its epilogue).
    pub from_linked: bool,
    /// (An ELU layer) its output's one consumer is the next layer's op with `from_linked`: the
    /// gradient arriving is ∂L/∂(x W + b) already.
    pub into_linked: bool,
}

/// The fused dense layer and its gradients, per backend (the default bodies: tensor ops).
#[backend_extension(Flex, Cube, Autodiff)]
pub trait AffineOps: Backend {
    /// `x W + b`: x [B, in], W [in, out], b [1, out] → [B, out].
    fn affine_fused(x: FloatTensor<Self>, w: FloatTensor<Self>, b: FloatTensor<Self>) -> FloatTensor<Self> {
        affine_ops::<Self>(x, w, b)
    }

    /// `ELU(x W + b)`, α = 1: a hidden layer with its activation, x [B, in] → [B, out].
    fn affine_elu_fused(x: FloatTensor<Self>, w: FloatTensor<Self>, b: FloatTensor<Self>) -> FloatTensor<Self> {
        crate::learn::kernels::elu::elu_ops::<Self>(affine_ops::<Self>(x, w, b))
    }

    /// `∂x = g Wᵀ`: g [B, out], W [in, out] → [B, in].
    fn affine_grad_x(g: FloatTensor<Self>, w: FloatTensor<Self>) -> FloatTensor<Self> {
        grad_x_ops::<Self>(g, w)
    }

    /// `∂W = xᵀ g`: x [B, in], g [B, out] → [in, out].
    fn affine_grad_w(x: FloatTensor<Self>, g: FloatTensor<Self>) -> FloatTensor<Self> {
        grad_w_ops::<Self>(x, g)
    }

    /// `∂b = 1ᵀ g`, the column sums: g [B, out] → [1, out].
    fn affine_grad_b(g: FloatTensor<Self>) -> FloatTensor<Self> {
        grad_b_ops::<Self>(g)
    }

    /// `(∂W, ∂b) = (xᵀ g, 1ᵀ g)`: x [B, in], g [B, out] → ([in, out], [1, out]).
    fn affine_grad_wb(x: FloatTensor<Self>, g: FloatTensor<Self>) -> (FloatTensor<Self>, FloatTensor<Self>) {
        (Self::affine_grad_w(x, g.clone()), Self::affine_grad_b(g))
    }

    /// `∂x = (g Wᵀ) · min(y + 1, 1)` where x = y = ELU(·) (a linked layer's input, [`EluLink`]):
    /// g [B, out], W [in, out], y [B, in] → [B, in].
    fn affine_grad_x_elu(g: FloatTensor<Self>, w: FloatTensor<Self>, y: FloatTensor<Self>) -> FloatTensor<Self> {
        crate::learn::kernels::elu::elu_backward_ops::<Self>(y, Self::affine_grad_x(g, w))
    }

    /// [`AffineOps::affine_fused`] linked to its neighbours in an MLP ([`EluLink`]: the link
    /// changes the gradient's path, not the value).
    fn affine_linked(x: FloatTensor<Self>, w: FloatTensor<Self>, b: FloatTensor<Self>, _link: EluLink) -> FloatTensor<Self> {
        Self::affine_fused(x, w, b)
    }

    /// [`AffineOps::affine_elu_fused`] linked to its neighbours in an MLP ([`EluLink`]).
    fn affine_elu_linked(x: FloatTensor<Self>, w: FloatTensor<Self>, b: FloatTensor<Self>, _link: EluLink) -> FloatTensor<Self> {
        Self::affine_elu_fused(x, w, b)
    }
}

/// On burn's wgpu backend: the products with the routine `learn::kernels::gpu_matmul` chose, `∂b` as the
/// two-stage column sum of `learn::kernels::row_sums` (one thread per column would sum all the batch's rows
/// alone: 1.3 ms for the policy's 22 outputs on an H200).
impl AffineOps for Cube {
    fn affine_fused(x: FloatTensor<Self>, w: FloatTensor<Self>, b: FloatTensor<Self>) -> FloatTensor<Self> {
        // dextrain's kernel adds b as it writes the product (one kernel); else a second one
        match gpu_matmul::matmul_then(&x, &w, Epilogue::Bias(&b)) {
            Some(y) => y,
            None => Cube::float_add(gpu_matmul::matmul(x, w), b), // x W [B, out] + b [1, out]
        }
    }

    fn affine_elu_fused(x: FloatTensor<Self>, w: FloatTensor<Self>, b: FloatTensor<Self>) -> FloatTensor<Self> {
        // dextrain's kernel: the bias and the ELU as it writes the product (one kernel where the
        // layer and its activation were six); the same values as the ops below
        match gpu_matmul::matmul_then(&x, &w, Epilogue::BiasElu(&b)) {
            Some(y) => y,
            None => <Cube as EluOps>::elu_fused(Self::affine_fused(x, w, b)),
        }
    }

    fn affine_grad_x(g: FloatTensor<Self>, w: FloatTensor<Self>) -> FloatTensor<Self> {
        gpu_matmul::matmul(g, Cube::float_transpose(w)) // [B, out] · [out, in]
    }

    fn affine_grad_w(x: FloatTensor<Self>, g: FloatTensor<Self>) -> FloatTensor<Self> {
        let (shape_x, shape_g) = (x.shape(), g.shape());
        let (rows, inputs, outputs) = (shape_x[0], shape_x[1], shape_g[1]);
        // dextrain's kernel splits a long k itself (`wgsl_matmul::plan`), into as many slices as
        // the shapes need, without S dividing the rows
        let split = if gpu_matmul::chosen().splits_k_itself() { 1 } else { crate::learn::nets::split_for_rows(rows) };
        if split <= 1 {
            return gpu_matmul::matmul(Cube::float_transpose(x), g); // [in, B] · [B, out]
        }
        // Σ_s x_sᵀ g_s over S row slices: S× the output tiles, each a B/S-long loop (one B-long
        // loop per tile keeps few of the GPU's cores busy), then a sum over the slices
        let xs = Cube::float_swap_dims(Cube::float_reshape(x, Shape::new([split, rows / split, inputs])), 1, 2); // [S, in, B/S]
        let gs = Cube::float_reshape(g, Shape::new([split, rows / split, outputs])); // [S, B/S, out]
        let per_slice = gpu_matmul::matmul(xs, gs); // [S, in, out]
        Cube::float_reshape(Cube::float_sum_dim(per_slice, 0), Shape::new([inputs, outputs])) // [in, out]
    }

    fn affine_grad_b(g: FloatTensor<Self>) -> FloatTensor<Self> {
        row_sums::column_sums_cube(g) // one kernel of ours in the two stages' order
    }

    fn affine_grad_wb(x: FloatTensor<Self>, g: FloatTensor<Self>) -> (FloatTensor<Self>, FloatTensor<Self>) {
        // dextrain's kernel: [xᵀ; 1ᵀ] g in one product (and one kernel summing its splits over k)
        match gpu_matmul::matmul_and_column_sums(&Cube::float_transpose(x.clone()), &g) {
            Some(wb) => wb,
            None => (Self::affine_grad_w(x, g.clone()), Self::affine_grad_b(g)),
        }
    }

    fn affine_grad_x_elu(g: FloatTensor<Self>, w: FloatTensor<Self>, y: FloatTensor<Self>) -> FloatTensor<Self> {
        // dextrain's kernel: ELU's gradient in the product's epilogue, the same bits as the product
        // then elu_backward.wgsl
        match gpu_matmul::matmul_then(&g, &Cube::float_transpose(w.clone()), Epilogue::EluGrad(&y)) {
            Some(dx) => dx,
            None => <Cube as EluOps>::elu_fused_backward(y, Self::affine_grad_x(g, w)),
        }
    }
}

/// Multiply-adds (m·n·k) from which gemm splits a product over the rayon pool (burn flex's own
/// threshold).
const PARALLEL_MACS: usize = 192 * 192 * 192;

/// Rows per rayon task in the bias fill and the bias gradient.
const ROWS_PER_TASK: usize = 512;

/// A rank-2 f32 flex tensor as (pointer to its first element, [rows, cols], row stride, column
/// stride), or None for another rank, dtype or a negative stride (then the default bodies run).
fn view_2d(t: &FlexTensor) -> Option<(*const f32, [usize; 2], isize, isize)> {
    let layout = t.layout();
    if t.dtype() != DType::F32 || layout.num_dims() != 2 {
        return None;
    }
    let strides = layout.strides();
    if strides.iter().any(|&s| s < 0) {
        return None;
    }
    let shape = layout.shape();
    let data: &[f32] = t.storage();
    // SAFETY: start_offset is inside the storage for any non-empty tensor of this layout
    let ptr = unsafe { data.as_ptr().add(layout.start_offset()) };
    Some((ptr, [shape[0], shape[1]], strides[0], strides[1]))
}

/// gemm's thread split for an m×n×k product.
fn parallelism(m: usize, n: usize, k: usize) -> gemm::Parallelism {
    if split_over_threads(m, n, k) { gemm::Parallelism::Rayon(0) } else { gemm::Parallelism::None }
}

/// Whether an m×n×k product is split over the rayon pool (either kernel).
fn split_over_threads(m: usize, n: usize, k: usize) -> bool {
    m.saturating_mul(n).saturating_mul(k) >= PARALLEL_MACS
}

/// A row-major [rows, cols] f32 tensor owning `data`, without a copy.
fn from_rows(data: Vec<f32>, rows: usize, cols: usize) -> FlexTensor {
    FlexTensor::new(Bytes::from_elems(data), Layout::contiguous(Shape::from(vec![rows, cols])), DType::F32)
}

/// `lhs · rhs` [m, n] into a new row-major tensor, each operand given by its view (pointer, rows
/// and columns of the operand as multiplied, row stride, column stride).
fn product(lhs: (*const f32, [usize; 2], isize, isize), rhs: (*const f32, [usize; 2], isize, isize)) -> FlexTensor {
    let (lp, [m, k], lrs, lcs) = lhs;
    let (rp, [_, n], rrs, rcs) = rhs;
    let mut out = Vec::<f32>::with_capacity(m * n);
    // SAFETY: the views describe live storage of the operands' shapes; both kernels write all m·n
    // outputs without reading them (accumulate / read_dst = false), after which they are
    // initialised; sgemm::runs() means the CPU has AVX2 + FMA
    unsafe {
        if sgemm::runs() && lcs == 1 {
            sgemm::matmul(m, n, k, lp, lrs as usize, rp, rrs, rcs, out.as_mut_ptr(), false, split_over_threads(m, n, k));
        } else {
            gemm::gemm(
                m, n, k, out.as_mut_ptr(), 1, n as isize, false, lp, lcs, lrs, rp, rcs, rrs, 0.0f32, 1.0f32, false,
                false, false, parallelism(m, n, k),
            );
        }
        out.set_len(m * n);
    }
    from_rows(out, m, n)
}

/// The transposed view of a 2-D view (swapped shape and strides; no data moves).
fn transposed(v: (*const f32, [usize; 2], isize, isize)) -> (*const f32, [usize; 2], isize, isize) {
    let (p, [r, c], rs, cs) = v;
    (p, [c, r], cs, rs)
}

impl AffineOps for Flex {
    fn affine_elu_fused(x: FloatTensor<Self>, w: FloatTensor<Self>, b: FloatTensor<Self>) -> FloatTensor<Self> {
        <Flex as EluOps>::elu_fused(Self::affine_fused(x, w, b)) // the two ops' values, unchanged
    }

    fn affine_grad_x_elu(g: FloatTensor<Self>, w: FloatTensor<Self>, y: FloatTensor<Self>) -> FloatTensor<Self> {
        <Flex as EluOps>::elu_fused_backward(y, Self::affine_grad_x(g, w)) // what the ELU layer's op computed from g Wᵀ: the same bits
    }

    fn affine_fused(x: FloatTensor<Self>, w: FloatTensor<Self>, b: FloatTensor<Self>) -> FloatTensor<Self> {
        let (Some(xv), Some(wv), Some(bv)) = (view_2d(&x), view_2d(&w), view_2d(&b)) else {
            return affine_ops::<Self>(x, w, b);
        };
        let ((xp, [m, k], xrs, xcs), (wp, [_, n], wrs, wcs), (bp, [_, bn], _, bcs)) = (xv, wv, bv);
        assert_eq!(bn, n, "affine: bias width {bn} against {n} outputs");
        let bias: Vec<f32> = (0..n).map(|j| unsafe { *bp.offset(j as isize * bcs) }).collect(); // [out]
        let mut out = Vec::<f32>::with_capacity(m * n);
        // y rows start as b (one write pass, where burn zeroed the output and copied it)
        for _ in 0..m {
            out.extend_from_slice(&bias);
        }
        // SAFETY: x and W views describe live storage of [m, k] and [k, n]; out holds m·n values;
        // sgemm::runs() means the CPU has AVX2 + FMA
        unsafe {
            if sgemm::runs() && xcs == 1 {
                sgemm::matmul(m, n, k, xp, xrs as usize, wp, wrs, wcs, out.as_mut_ptr(), true, split_over_threads(m, n, k)); // y += x W
            } else {
                gemm::gemm(
                    m, n, k, out.as_mut_ptr(), 1, n as isize, true, xp, xcs, xrs, wp, wcs, wrs, 1.0f32, 1.0f32, false,
                    false, false, parallelism(m, n, k),
                ); // y = 1 · y + 1 · x W
            }
        }
        from_rows(out, m, n)
    }

    fn affine_grad_x(g: FloatTensor<Self>, w: FloatTensor<Self>) -> FloatTensor<Self> {
        match (view_2d(&g), view_2d(&w)) {
            (Some(gv), Some(wv)) => product(gv, transposed(wv)), // [B, out] · [out, in]
            _ => grad_x_ops::<Self>(g, w),
        }
    }

    fn affine_grad_w(x: FloatTensor<Self>, g: FloatTensor<Self>) -> FloatTensor<Self> {
        match (view_2d(&x), view_2d(&g)) {
            (Some(xv), Some(gv)) => product(transposed(xv), gv), // [in, B] · [B, out]
            _ => grad_w_ops::<Self>(x, g),
        }
    }

    fn affine_grad_b(g: FloatTensor<Self>) -> FloatTensor<Self> {
        let contiguous = g.is_contiguous() && g.layout().start_offset() == 0;
        if g.dtype() != DType::F32 || g.layout().num_dims() != 2 || !contiguous {
            return grad_b_ops::<Self>(g);
        }
        let n = g.layout().shape()[1];
        let rows: &[f32] = &g.storage::<f32>()[..g.layout().num_elements()];
        let add_rows = |acc: &mut Vec<f32>, block: &[f32]| {
            for row in block.chunks_exact(n) {
                acc.iter_mut().zip(row).for_each(|(a, v)| *a += v); // Σ over rows, per column
            }
        };
        let sums = if n == 0 {
            Vec::new()
        } else {
            rows.par_chunks(ROWS_PER_TASK * n)
                .map(|block| {
                    let mut acc = vec![0.0f32; n];
                    add_rows(&mut acc, block);
                    acc
                })
                .reduce(|| vec![0.0f32; n], |mut a, b| {
                    a.iter_mut().zip(&b).for_each(|(x, y)| *x += y);
                    a
                })
        };
        from_rows(sums, 1, n)
    }
}

/// A dense layer's gradients from g = ∂L/∂(x W + b) [B, out], registered for the parents (x, W, b)
/// that are tracked: `∂b = 1ᵀ g`, `∂W = xᵀ g` (x kept when W is tracked; both in one op where both
/// are tracked), `∂x = g Wᵀ` (W kept when x is tracked), times ELU's gradient at x where x is a
/// linked ELU layer's output (`from_linked`: x kept too).
fn register_layer_grads<B: Backend + AffineOps>(
    grads: &mut Gradients,
    [node_x, node_w, node_b]: [Option<NodeId>; 3],
    x: Option<FloatTensor<B>>,
    w: Option<FloatTensor<B>>,
    g: FloatTensor<B>,
    from_linked: bool,
) {
    match (node_w, node_b, x.clone()) {
        (Some(id_w), Some(id_b), Some(x)) => {
            let (dw, db) = B::affine_grad_wb(x, g.clone());
            grads.register::<B>(id_b, db);
            grads.register::<B>(id_w, dw);
        }
        (node_w, node_b, x) => {
            if let Some(id) = node_b {
                grads.register::<B>(id, B::affine_grad_b(g.clone()));
            }
            if let (Some(id), Some(x)) = (node_w, x) {
                grads.register::<B>(id, B::affine_grad_w(x, g.clone()));
            }
        }
    }
    if let (Some(id), Some(w)) = (node_x, w) {
        let dx = match x {
            Some(y) if from_linked => B::affine_grad_x_elu(g, w, y), // (g Wᵀ) · ELU'(x)
            _ => B::affine_grad_x(g, w),
        };
        grads.register::<B>(id, dx);
    }
}

impl<B: Backend + AffineOps + EluOps, C: CheckpointStrategy> AffineOps for Autodiff<B, C> {
    fn affine_elu_fused(x: FloatTensor<Self>, w: FloatTensor<Self>, b: FloatTensor<Self>) -> FloatTensor<Self> {
        Self::affine_elu_linked(x, w, b, EluLink::default())
    }

    fn affine_fused(x: FloatTensor<Self>, w: FloatTensor<Self>, b: FloatTensor<Self>) -> FloatTensor<Self> {
        Self::affine_linked(x, w, b, EluLink::default())
    }

    fn affine_elu_linked(x: FloatTensor<Self>, w: FloatTensor<Self>, b: FloatTensor<Self>, link: EluLink) -> FloatTensor<Self> {
        /// `y = ELU(x W + b)`: the gradient before the activation `g' = elu_backward(y, g)` (or, linked
        /// into the next layer, g as it arrives), then the dense layer's gradients of g' (what the two
        /// ops' backward passes compute, in the same order).
        #[derive(Debug)]
        struct AffineElu {
            link: EluLink,
        }

        impl<B: Backend + AffineOps + EluOps> Backward<B, 3> for AffineElu {
            /// x when W is tracked (for ∂W) or x is a linked ELU output (for its gradient), W when x
            /// is tracked (for ∂x), and the output y unless the next layer applies ELU's gradient.
            type State = (Option<FloatTensor<B>>, Option<FloatTensor<B>>, Option<FloatTensor<B>>);

            fn backward(self, ops: Ops<Self::State, 3>, grads: &mut Gradients, _checkpointer: &mut Checkpointer) {
                let (x, w, y) = ops.state;
                let arrived = grads.consume::<B>(&ops.node);
                let g = match y {
                    Some(y) => B::elu_fused_backward(y, arrived), // ∂L/∂(x W + b) [B, out]
                    None => arrived, // linked: the next layer applied ELU's gradient
                };
                register_layer_grads::<B>(grads, ops.parents.map(|p| p.map(|n| n.id)), x, w, g, self.link.from_linked);
            }
        }

        let x_tracked = x.is_tracked();
        let w_tracked = w.is_tracked();
        match (AffineElu { link }).prepare::<C>([x.node(), w.node(), b.node()]).compute_bound().stateful() {
            OpsKind::Tracked(prep) => {
                let (x, w, b) = (x.into_primitive(), w.into_primitive(), b.into_primitive());
                let keep_x = w_tracked || (x_tracked && link.from_linked);
                let (xs, ws) = (keep_x.then(|| x.clone()), x_tracked.then(|| w.clone()));
                let y = B::affine_elu_fused(x, w, b);
                let ys = (!link.into_linked).then(|| y.clone());
                prep.finish((xs, ws, ys), y)
            }
            OpsKind::UnTracked(prep) => {
                prep.finish(B::affine_elu_fused(x.into_primitive(), w.into_primitive(), b.into_primitive()))
            }
        }
    }

    fn affine_linked(x: FloatTensor<Self>, w: FloatTensor<Self>, b: FloatTensor<Self>, link: EluLink) -> FloatTensor<Self> {
        #[derive(Debug)]
        struct Affine {
            from_linked: bool,
        }

        impl<B: Backend + AffineOps> Backward<B, 3> for Affine {
            /// x when W is tracked (for ∂W) or x is a linked ELU output (for its gradient), W when x
            /// is tracked (for ∂x).
            type State = (Option<FloatTensor<B>>, Option<FloatTensor<B>>);

            fn backward(self, ops: Ops<Self::State, 3>, grads: &mut Gradients, _checkpointer: &mut Checkpointer) {
                let (x, w) = ops.state;
                let g = grads.consume::<B>(&ops.node); // [B, out]
                register_layer_grads::<B>(grads, ops.parents.map(|p| p.map(|n| n.id)), x, w, g, self.from_linked);
            }
        }

        let x_tracked = x.is_tracked();
        let w_tracked = w.is_tracked();
        match (Affine { from_linked: link.from_linked }).prepare::<C>([x.node(), w.node(), b.node()]).compute_bound().stateful() {
            OpsKind::Tracked(prep) => {
                let (x, w, b) = (x.into_primitive(), w.into_primitive(), b.into_primitive());
                let keep_x = w_tracked || (x_tracked && link.from_linked);
                let state = (keep_x.then(|| x.clone()), x_tracked.then(|| w.clone()));
                prep.finish(state, B::affine_fused(x, w, b))
            }
            OpsKind::UnTracked(prep) => {
                prep.finish(B::affine_fused(x.into_primitive(), w.into_primitive(), b.into_primitive()))
            }
        }
    }
}

/// `ELU(x W + b)` for x [B, in], W [in, out], b [1, out] on any learner device, differentiable:
/// [`fused_affine`] then `elu::elu`, as one op (on the GPU with dextrain's matmul, one kernel).
pub fn fused_affine_elu(x: Tensor<2>, w: Tensor<2>, b: Tensor<2>) -> Tensor<2> {
    Tensor::from_dispatch(<burn::backend::Dispatch as AffineOps>::affine_elu_fused(
        x.into_dispatch(),
        w.into_dispatch(),
        b.into_dispatch(),
    ))
}

/// `x W + b` for x [B, in], W [in, out], b [1, out] on any learner device, differentiable.
pub fn fused_affine(x: Tensor<2>, w: Tensor<2>, b: Tensor<2>) -> Tensor<2> {
    Tensor::from_dispatch(<burn::backend::Dispatch as AffineOps>::affine_fused(
        x.into_dispatch(),
        w.into_dispatch(),
        b.into_dispatch(),
    ))
}

/// [`fused_affine`] linked to its neighbours in an MLP ([`EluLink`]).
pub fn fused_affine_linked(x: Tensor<2>, w: Tensor<2>, b: Tensor<2>, link: EluLink) -> Tensor<2> {
    Tensor::from_dispatch(<burn::backend::Dispatch as AffineOps>::affine_linked(x.into_dispatch(), w.into_dispatch(), b.into_dispatch(), link))
}

/// [`fused_affine_elu`] linked to its neighbours in an MLP ([`EluLink`]).
pub fn fused_affine_elu_linked(x: Tensor<2>, w: Tensor<2>, b: Tensor<2>, link: EluLink) -> Tensor<2> {
    Tensor::from_dispatch(<burn::backend::Dispatch as AffineOps>::affine_elu_linked(x.into_dispatch(), w.into_dispatch(), b.into_dispatch(), link))
}
