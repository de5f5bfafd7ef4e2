//! Sums over the batch's rows that keep a GPU busy, in an order fixed run to run.
//!
//! burn's wgpu backend (without autotune) reduces an axis with one thread per output: a sum over
//! the 24,576 rows of a minibatch into one value, or into the 22 columns of the policy's σ, runs on
//! one or 22 threads, 0.2-1.3 ms each on an NVIDIA H200, where the update's whole 4-layer backward
//! product takes 0.4 ms (BENCHMARKS.md, issue 33). Here such a sum runs in two stages: the rows are
//! cut into `k` blocks ([k, R/k, C]), each block summed on its own threads, then the k partial
//! sums (k·C threads, then C). Both stages are burn's plain reductions in a fixed order, so a run
//! still repeats bit for bit. Where the rows, or their count, are not long or even enough the
//! one-stage sum runs.
//!
//! The stages pay on the GPU only: the CPU (burn flex, `affine.rs`) sums a column in one pass over
//! memory already, and its sums keep their order (`is_gpu` callers choose).
//!
//! On burn's wgpu runtime the two stages are one kernel of ours (shaders/column_sums.wgsl, the
//! same additions in the same order; [`column_sums_cube`]) where `g` is a contiguous f32 matrix
//! of two columns or more.
//!
//! Also here: [`rows_of`], a [1, C] row repeated over the batch whose gradient is the two-stage
//! column sum, for a parameter that meets the batch by broadcasting (PPO's log σ): burn's own
//! broadcast takes the one-stage sum in its backward.

use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::checkpoint::strategy::CheckpointStrategy;
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{Backward, Ops, OpsKind};
use burn::backend::tensor::FloatTensor;
use burn::backend::{Autodiff, Backend, Cube, Flex, backend_extension};
use burn::prelude::Tensor;
use burn::backend::TensorMetadata;
use burn::tensor::Shape;

/// Rows below which the one-stage sum is kept (too few to pay for a second kernel).
const MIN_ROWS: usize = 2048;

/// The most blocks of the first stage.
const MAX_BLOCKS: usize = 256;

/// The block count for `rows` rows: the largest power of two ≤ 256 that divides `rows` and leaves
/// at least 8 rows per block; None where `rows` < 2048 or no such power (an odd count).
pub fn blocks_for(rows: usize) -> Option<usize> {
    if rows < MIN_ROWS {
        return None;
    }
    let mut k = MAX_BLOCKS;
    while k >= 8 {
        if rows % k == 0 && rows / k >= 8 {
            return Some(k);
        }
        k /= 2;
    }
    None
}

/// Column sums `1ᵀ g` of g [R, C] → [1, C] as ops of `B`: in two stages ([k, R/k, C] summed over
/// dim 1, then over the k blocks) where [`blocks_for`] finds blocks, else one.
pub fn column_sums_ops<B: Backend>(g: FloatTensor<B>) -> FloatTensor<B> {
    let shape = g.shape();
    let (rows, cols) = (shape[0], shape[1]);
    match blocks_for(rows) {
        Some(k) => {
            let blocks = B::float_reshape(g, Shape::new([k, rows / k, cols])); // [k, R/k, C]
            let partial = B::float_sum_dim(blocks, 1); // [k, 1, C]: Σ over each block's rows
            let total = B::float_sum_dim(partial, 0); // [1, 1, C]: Σ over the blocks
            B::float_reshape(total, Shape::new([1, cols]))
        }
        None => B::float_sum_dim(g, 0),
    }
}

/// Σ of every entry of `t` [R, C] as a [1] tensor in the two-stage order (the entries taken as one
/// column of R·C rows), or the sums over each dimension in turn where no blocks divide R·C.
pub fn sum_all_two_stage(t: Tensor<2>) -> Tensor<1> {
    let n = t.shape().num_elements();
    match blocks_for(n) {
        Some(k) => t.reshape([k, n / k]).sum_dim(1).sum_dim(0).reshape([1]), // [k, n/k] → [k, 1] → [1, 1]
        None => t.sum_dim(0).sum_dim(1).reshape([1]),
    }
}

/// A [1, C] row repeated over `rows` rows, with a two-stage column sum as its gradient.
#[backend_extension(Flex, Cube, Autodiff)]
pub trait RowsOps: Backend {
    /// x [1, C] → [rows, C] (a broadcast view where the backend has one).
    fn rows_of(x: FloatTensor<Self>, rows: usize) -> FloatTensor<Self> {
        let cols = x.shape()[1];
        Self::float_expand(x, Shape::new([rows, cols]))
    }

    /// `1ᵀ g`: g [R, C] → [1, C] ([`column_sums_ops`]).
    fn column_sums(g: FloatTensor<Self>) -> FloatTensor<Self> {
        column_sums_ops::<Self>(g)
    }
}

impl RowsOps for Flex {}

impl RowsOps for Cube {
    fn column_sums(g: FloatTensor<Self>) -> FloatTensor<Self> {
        column_sums_cube(g)
    }
}

/// shaders/column_sums.wgsl.
const SHADER_COLUMN_SUMS: &str = include_str!("../../../shaders/column_sums.wgsl");

/// The column-sum kernel's module (one variant).
pub fn column_sums_source(_: ()) -> String {
    SHADER_COLUMN_SUMS.to_string()
}

/// `1ᵀ g` on burn's wgpu runtime: one kernel of ours (shaders/column_sums.wgsl) in the order of
/// [`column_sums_ops`]' two stages (the same bits, one launch where they were two), or those
/// stages where the kernel does not take `g`: not a contiguous f32 `[R, C]`, indices over 32 bits,
/// or one column (burn's reduction then runs along the contiguous rows in vectors, in another
/// order of additions).
pub fn column_sums_cube(g: FloatTensor<Cube>) -> FloatTensor<Cube> {
    match column_sums_kernel(&g) {
        Some(out) => out,
        None => column_sums_ops::<Cube>(g),
    }
}

/// [`column_sums_cube`]'s kernel: `[1, C]` from one launch of ⌈C / 16⌉ workgroups, or None where
/// it does not take `g`.
fn column_sums_kernel(g: &FloatTensor<Cube>) -> Option<FloatTensor<Cube>> {
    use burn::backend::ops::FloatTensorOps;
    use burn::tensor::FloatDType;
    use super::wgsl_kernel::{WgslKernel, is_plain, launch};
    let shape = g.shape();
    if shape.num_dims() != 2 {
        return None;
    }
    let (rows, cols) = (shape[0], shape[1]);
    if cols < 2 || rows == 0 || !is_plain(g, [rows, cols]) || u32::try_from(rows * cols).is_err() {
        return None;
    }
    let blocks = blocks_for(rows).unwrap_or(1); // column_sums_ops' stages
    let groups = u32::try_from(cols.div_ceil(16)).ok().filter(|&x| x <= 65_535)?;
    let out = Cube::float_empty(Shape::new([1, cols]), &g.device, FloatDType::F32); // written whole below
    let kernel = WgslKernel { name: "dextrain_column_sums", key: (), source: column_sums_source, entry_point: "column_sums", workgroup: [16, 16] };
    // ColumnSumsCfg: rows, cols, blocks, padding
    launch(kernel, [groups, 1, 1], &[g, &out], &[rows as u32, cols as u32, blocks as u32, 0]);
    Some(out)
}

impl<B: Backend + RowsOps, C: CheckpointStrategy> RowsOps for Autodiff<B, C> {
    fn rows_of(x: FloatTensor<Self>, rows: usize) -> FloatTensor<Self> {
        #[derive(Debug)]
        struct Rows;

        impl<B: Backend + RowsOps> Backward<B, 1> for Rows {
            type State = ();

            fn backward(self, ops: Ops<Self::State, 1>, grads: &mut Gradients, _checkpointer: &mut Checkpointer) {
                let [node_x] = ops.parents;
                let g = grads.consume::<B>(&ops.node); // [rows, C]
                if let Some(node) = node_x {
                    grads.register::<B>(node.id, B::column_sums(g)); // [1, C]
                }
            }
        }

        match Rows.prepare::<C>([x.node()]).compute_bound().stateful() {
            OpsKind::Tracked(prep) => prep.finish((), B::rows_of(x.into_primitive(), rows)),
            OpsKind::UnTracked(prep) => prep.finish(B::rows_of(x.into_primitive(), rows)),
        }
    }
}

/// `x` [1, C] repeated over `rows` rows → [rows, C], differentiable (its gradient the two-stage
/// column sum).
pub fn rows_of(x: Tensor<2>, rows: usize) -> Tensor<2> {
    Tensor::from_dispatch(<burn::backend::Dispatch as RowsOps>::rows_of(x.into_dispatch(), rows))
}

/// `1ᵀ g` for g [R, C] → [1, C] on any learner device, two-stage where it pays.
pub fn column_sums(g: Tensor<2>) -> Tensor<2> {
    Tensor::from_dispatch(<burn::backend::Dispatch as RowsOps>::column_sums(g.into_dispatch()))
}
