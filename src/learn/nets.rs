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

use crate::learn::kernels::affine::EluLink;
use crate::rng::Rng;

/// Hidden-layer activation (`policy.activation`; the enum is the config's).
pub use crate::config::Activation;

impl Activation {
    /// The activation applied element-wise.
    pub fn apply(self, x: Tensor<2>) -> Tensor<2> {
        match self {
            // one fused operation with its own gradient (`elu.rs`): burn's `elu` uses mask_where,
            // which burn's CPU backend runs on a slow generic path under autodiff
            Activation::Elu => super::kernels::elu::elu(x),
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

/// Rows per slice that [`row_split`] aims at.
const SPLIT_ROWS: usize = 2048;
/// The most slices [`row_split`] makes.
const MAX_SPLIT: usize = 32;

/// In how many slices [`affine`] multiplies a batch of `rows` on `device`: 1 on the CPU (burn
/// flex's gemm splits the work itself); on a GPU (a cubecl device) the largest S ≤ 32 that divides
/// `rows` with at least 2,048 rows per slice. cubecl's matmul tiles the output: a weight gradient
/// `xᵀ g` ([in, out], summed over all B rows) is a handful of tiles with a B-long loop each — a
/// [96, 512] gradient over 24,576 rows kept 16 tiles busy on an H100's 132 SMs (matmul: 3.2 of
/// 4.8 GPU-seconds of the PPO bench, BENCHMARKS.md). S slices turn it into S× the tiles with a
/// B/S loop, summed after.
pub fn row_split(device: &Device, rows: usize) -> usize {
    if device.identity().is_none() {
        return 1;
    }
    split_for_rows(rows)
}

/// [`row_split`]'s slice count on a GPU: the largest S ≤ 32 that divides `rows` with at least 2,048
/// rows per slice (1 for fewer rows).
pub fn split_for_rows(rows: usize) -> usize {
    (1..=MAX_SPLIT.min(rows / SPLIT_ROWS).max(1)).rev().find(|s| rows % s == 0).unwrap_or(1)
}

/// `x W` [B, out] for x [B, in] and W [in, out], as S products of B/S rows against the same W
/// (`[S, B/S, in] · [1, in, out]`, [`row_split`]): the same sums in another order; burn's
/// autodiff sums the S slices of the weight gradient over the broadcast axis.
pub fn matmul_rows(x: Tensor<2>, w: Tensor<2>, split: usize) -> Tensor<2> {
    if split <= 1 {
        return x.matmul(w);
    }
    let [b, i] = x.dims();
    let o = w.dims()[1];
    let y = x.reshape([split, b / split, i]).matmul(w.unsqueeze_dim::<3>(0)); // [S, B/S, out]
    y.reshape([b, o])
}

/// `x W + b` [B, out] for x [B, in], W [in, out], b [1, out]. On a GPU with dextrain's or a cubek
/// matmul routine (`learn::kernels::gpu_matmul`; dextrain's is the default) and on the CPU: `affine.rs`'s
/// one op (on the GPU its weight gradient is split over k by dextrain's kernel, or over row slices
/// inside the op with cubek's, its bias gradient a two-stage column sum). With
/// `DEXTRAIN_GPU_MATMUL=burn`: burn's products in `split` row slices ([`matmul_rows`]), the bias
/// entering as a product too, `1 b` ([B, 1] · [1, out]), so that its gradient `1ᵀ g` is a split
/// product and a sum over S rather than burn's one-thread-per-column reduction over the B rows.
pub fn affine(x: Tensor<2>, w: Tensor<2>, b: Tensor<2>, split: usize) -> Tensor<2> {
    if affine_is_one_op(split) {
        // [B, out]: one op with its own gradient (affine.rs; on a GPU its weight gradient is split
        // over k by dextrain's kernel, or over row slices inside the op with a cubek routine)
        return super::kernels::affine::fused_affine(x, w, b);
    }
    let ones = Tensor::<2>::ones([x.dims()[0], 1], &x.device()); // [B, 1]
    matmul_rows(x, w, split) + matmul_rows(ones, b, split)
}

/// Whether [`affine`] with this row split is `affine.rs`'s one op (then an ELU layer can be one op
/// with its activation, `affine::fused_affine_elu`): unsplit, or on a GPU with a routine that
/// splits inside the op.
fn affine_is_one_op(split: usize) -> bool {
    split <= 1 || super::kernels::gpu_matmul::chosen().splits_inside()
}

/// The row split of a forward pass of `params` over `rows` rows: [`row_split`] when the
/// parameters are autodiff leaves (the split is for the backward pass's weight gradients), else 1
/// (acting: one product per layer, `affine`'s fused op).
fn forward_split(params: &[Tensor<2>], device: &Device, rows: usize) -> usize {
    if params.first().is_some_and(|p| p.is_autodiff()) { row_split(device, rows) } else { 1 }
}

/// `h = act(h W + b)` for every layer but the last: x [B, in] → [B, out].
pub fn mlp_forward(params: &[Tensor<2>], x: Tensor<2>, act: Activation) -> Tensor<2> {
    if is_gpu(&x.device()) && !params.first().is_some_and(|p| p.is_autodiff()) {
        // acting on a GPU: the whole MLP in one kernel of ours where it applies (ELU layers), the
        // same values as the layers below (`kernels::mlp_forward`)
        if let Some(y) = super::kernels::mlp_forward::forward(params, &x, act) {
            return y;
        }
    }
    let layers = params.len() / 2;
    let split = forward_split(params, &x.device(), x.dims()[0]);
    let mut h = x;
    let one_op = affine_is_one_op(split);
    // ELU layers as one op each, linked: each hidden activation is the next layer's input alone,
    // so the next layer applies ELU's gradient (affine.rs's EluLink)
    let linked = act == Activation::Elu && one_op;
    for l in 0..layers {
        let (w, b) = (params[2 * l].clone(), params[2 * l + 1].clone());
        let link = EluLink { from_linked: linked && l > 0, into_linked: linked && l + 1 < layers };
        h = if l + 1 < layers && linked {
            super::kernels::affine::fused_affine_elu_linked(h, w, b, link) // ELU(h W + b) [B, out] as one op (affine.rs)
        } else if l + 1 < layers {
            act.apply(affine(h, w, b, split))
        } else if linked {
            super::kernels::affine::fused_affine_linked(h, w, b, link) // [B, out]
        } else {
            affine(h, w, b, split) // [B, out]
        };
    }
    h
}

/// `Tensor::cat(parts, 0)` of `[n_k, D]` row blocks: on a GPU learner device a few kernels of ours
/// (`kernels::cat_rows`, where burn's cat launches one per block), the result with autodiff where
/// the first block has it (a constant, as cat's); elsewhere, or for blocks the kernel does not
/// take, burn's cat. The same values either way.
pub fn stack_rows(parts: Vec<Tensor<2>>) -> Tensor<2> {
    let max_buffers = parts.first().and_then(|p| crate::learn::device::gpu_context_of(&p.device())).map(|c| c.device.limits().max_storage_buffers_per_shader_stage);
    match max_buffers.and_then(|m| super::kernels::cat_rows::cat_rows(&parts, m)) {
        Some(all) if parts[0].is_autodiff() => all.autodiff(),
        Some(all) => all,
        None => Tensor::cat(parts, 0),
    }
}

/// A host matrix → a tensor on `device` (counted in [`crate::host_traffic`] and
/// [`crate::gpu_counts`] on a GPU device).
pub fn to_tensor(data: Vec<f32>, shape: [usize; 2], device: &Device) -> Tensor<2> {
    if is_gpu(device) {
        crate::host_traffic::add(4 * data.len() as u64);
        crate::gpu_counts::add(crate::gpu_counts::Event::Upload, "burn:from_data");
    }
    Tensor::from_data(TensorData::new(data, shape), device)
}

/// Host rows `data` as a `[rows, cols]` tensor on `device`, copied once. On burn's wgpu runtime
/// they go straight into a fresh tensor's memory through the queue (wgpu's one staging copy) where
/// [`to_tensor`] takes an owned copy that cubecl copies again: for a PPO rollout of the peer
/// shapes (~100 MB) two host copies fewer per update. burn's recorded work is submitted first, so
/// the write lands after every kernel that used the memory before (cubecl does the same before
/// its own writes). Elsewhere (the CPU) [`to_tensor`] of a copy.
pub fn upload(data: &[f32], shape: [usize; 2], device: &Device) -> Result<Tensor<2>> {
    anyhow::ensure!(data.len() == shape[0] * shape[1], "{} values for a [{}, {}] tensor", data.len(), shape[0], shape[1]);
    let ctx = match super::device::gpu_context_of(device) {
        Some(ctx) if !data.is_empty() => ctx,
        _ => return Ok(to_tensor(data.to_vec(), shape, device)),
    };
    crate::gpu::io::flush(device)?;
    let out = crate::gpu::io::empty_buffer(shape[0], shape[1], device)?;
    ctx.upload_at("host rows", out.buffer(), out.offset(), bytemuck::cast_slice(data))?; // counted as traffic and an upload
    let t = out.tensor.clone();
    Ok(if device.is_autodiff() { t.autodiff() } else { t })
}

/// A tensor → its values on the host (row-major; counted in [`crate::host_traffic`] and, as a
/// host synchronisation, in [`crate::gpu_counts`] from a GPU device).
pub fn to_host<const D: usize>(t: Tensor<D>) -> Result<Vec<f32>> {
    if is_gpu(&t.device()) {
        crate::host_traffic::add(4 * t.shape().num_elements() as u64);
        crate::gpu_counts::add(crate::gpu_counts::Event::Read, "burn:into_data");
    }
    t.into_data().try_to_vec::<f32>().map_err(|e| anyhow!("cannot read a tensor back: {e:?}"))
}

/// Σ of every entry of `t` `[R, C]` as a `[1]` tensor, in an order that does not change from run
/// to run. On a GPU, burn's whole-tensor `sum` adds the partial sums of its workgroups with float
/// atomics, in whatever order they finish (lavapipe: 3 outcomes ~1e-8 apart in 13 runs of the same
/// training); the sums over each dimension in turn are fixed reductions. The CPU keeps `sum`.
pub fn sum_all(t: Tensor<2>) -> Tensor<1> {
    if is_gpu(&t.device()) {
        crate::learn::kernels::row_sums::sum_all_two_stage(t) // a long axis in two stages: many threads, fixed order
    } else {
        t.sum()
    }
}

/// The mean of every entry of `t` `[R, C]` as a `[1]` tensor: on a GPU, for as many entries as
/// `learn::kernels::row_sums` cuts in blocks, [`sum_all`] / (R·C) (a fixed order on many threads, where
/// burn's `mean` sums all entries on one thread); elsewhere `mean`.
pub fn mean_all(t: Tensor<2>) -> Tensor<1> {
    let n = t.shape().num_elements();
    if is_gpu(&t.device()) && crate::learn::kernels::row_sums::blocks_for(n).is_some() {
        sum_all(t).div_scalar(n as f64)
    } else {
        t.mean() // the CPU, or too few entries for a second stage to pay
    }
}

/// `x` [1, C] to meet a batch of `rows` rows: on a GPU repeated over the rows with a two-stage
/// column sum as its gradient (`learn::kernels::row_sums::rows_of`), on the CPU `x` itself (broadcast by
/// the operation that uses it, as before).
pub fn batch_row(x: Tensor<2>, rows: usize) -> Tensor<2> {
    if is_gpu(&x.device()) { crate::learn::kernels::row_sums::rows_of(x, rows) } else { x }
}

/// Whether `device` is a GPU (burn's cubecl backend: wgpu), i.e. not host memory.
pub fn is_gpu(device: &Device) -> bool {
    matches!(device.clone().inner().as_dispatch(), burn::backend::DispatchDevice::Cube(_))
}

/// An MLP `input → hidden… → output` with an optional LayerNorm after every hidden layer (before
/// its activation; FastTD3's and FastSAC's critics). Its parameters, in order, per hidden layer:
/// weight `[in, out]`, bias `[1, out]`, then with LayerNorm its gain and shift `[1, out]`; then the
/// output layer's weight and bias. Without LayerNorm this is [`mlp_shapes`]' list.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct MlpLayout {
    /// Input width.
    pub input: usize,
    /// Hidden widths.
    pub hidden: Vec<usize>,
    /// Output width.
    pub output: usize,
    /// LayerNorm after every hidden layer.
    pub layer_norm: bool,
}


impl MlpLayout {
    /// Parameters per hidden layer (2, or 4 with LayerNorm).
    pub fn per_hidden(&self) -> usize {
        if self.layer_norm { 4 } else { 2 }
    }

    /// Shapes of every parameter, in order.
    pub fn shapes(&self) -> Vec<[usize; 2]> {
        let mut out = Vec::new();
        let mut w = self.input;
        for &h in &self.hidden {
            out.extend([[w, h], [1, h]]);
            if self.layer_norm {
                out.extend([[1, h], [1, h]]);
            }
            w = h;
        }
        out.extend([[w, self.output], [1, self.output]]);
        out
    }

    /// Checkpoint names: `<prefix>.<layer>.weight|bias`, LayerNorm's `<prefix>.<layer>.ln_gain|ln_shift`.
    pub fn names(&self, prefix: &str) -> Vec<String> {
        let mut out = Vec::new();
        for l in 0..self.hidden.len() {
            out.extend([format!("{prefix}.{l}.weight"), format!("{prefix}.{l}.bias")]);
            if self.layer_norm {
                out.extend([format!("{prefix}.{l}.ln_gain"), format!("{prefix}.{l}.ln_shift")]);
            }
        }
        let l = self.hidden.len();
        out.extend([format!("{prefix}.{l}.weight"), format!("{prefix}.{l}.bias")]);
        out
    }

    /// Fresh values: linear layers as [`init_mlp`] (torch's Linear), LayerNorm gain 1, shift 0.
    pub fn init(&self, rng: &mut Rng) -> Vec<Vec<f32>> {
        let mut out = Vec::new();
        let mut w = self.input;
        for &h in &self.hidden {
            out.extend(init_mlp(&[[w, h], [1, h]], rng));
            if self.layer_norm {
                out.push(vec![1.0; h]);
                out.push(vec![0.0; h]);
            }
            w = h;
        }
        out.extend(init_mlp(&[[w, self.output], [1, self.output]], rng));
        out
    }

    /// x [B, input] → [B, output]: `h = act(LN(h W + b))` per hidden layer, then `h W + b`.
    pub fn forward(&self, params: &[Tensor<2>], x: Tensor<2>, act: Activation) -> Tensor<2> {
        if !self.layer_norm {
            // without LayerNorm the parameters are `mlp_shapes`' list: acting on a GPU takes the
            // one kernel where it applies
            return mlp_forward(params, x, act);
        }
        let split = forward_split(params, &x.device(), x.dims()[0]);
        self.forward_from(params, x, None, split, act)
    }

    /// [`MlpLayout::forward`] of the input `[x_head | x_tail]` ([B, input] in two column blocks)
    /// without forming it: the first layer is `x_head W[..h] + x_tail W[h..] + b` (W's first h
    /// rows, then the rest). The same values to rounding; where only `x_tail` is tracked (SAC's
    /// actor update: the critic's state columns are data, its action columns the actor's output)
    /// the input gradient is `g W[h..]ᵀ` [B, tail] where the concatenated input's would be
    /// `g Wᵀ` [B, input] — for SAC's critics 22 of 152 columns.
    pub fn forward_split_input(&self, params: &[Tensor<2>], x_head: Tensor<2>, x_tail: Tensor<2>, act: Activation) -> Tensor<2> {
        let split = forward_split(params, &x_head.device(), x_head.dims()[0]);
        self.forward_from(params, x_head, Some(x_tail), split, act)
    }

    /// The layers, the first one's input given as `x` or as the column blocks `[x | tail]`.
    fn forward_from(&self, params: &[Tensor<2>], x: Tensor<2>, mut tail: Option<Tensor<2>>, split: usize, act: Activation) -> Tensor<2> {
        let k = self.per_hidden();
        // without LayerNorm, an ELU layer whose input is one block is one op (affine.rs)
        let one_op = !self.layer_norm && act == Activation::Elu && affine_is_one_op(split);
        let mut h = x;
        // whether h is the output of an ELU layer linked into the next (affine.rs's EluLink: the
        // next layer applies ELU's gradient; h is its input alone)
        let mut h_linked = false;
        for l in 0..self.hidden.len() {
            let p = &params[l * k..(l + 1) * k];
            if one_op && tail.is_none() {
                let link = EluLink { from_linked: h_linked, into_linked: true };
                h = super::kernels::affine::fused_affine_elu_linked(h, p[0].clone(), p[1].clone(), link); // ELU(h W + b) [B, out]
                h_linked = true;
                continue;
            }
            h = first_or_affine(h, tail.take(), p[0].clone(), p[1].clone(), split); // [B, out]
            if self.layer_norm && act == Activation::Elu && is_gpu(&h.device()) {
                // one operation each way on a GPU, where LayerNorm and ELU were two (the same bits)
                h = super::kernels::layer_norm::layer_norm_elu(h, p[2].clone(), p[3].clone()); // ELU((h − μ)/√(σ² + ε) · g + s) per row
                continue;
            }
            if self.layer_norm {
                h = super::kernels::layer_norm::layer_norm(h, p[2].clone(), p[3].clone()); // (h − μ)/√(σ² + ε) · g + s per row
            }
            h = act.apply(h);
        }
        let o = self.hidden.len() * k;
        if h_linked {
            // (one_op: the output layer is affine.rs's op too, its input the last ELU layer's)
            let link = EluLink { from_linked: true, into_linked: false };
            return super::kernels::affine::fused_affine_linked(h, params[o].clone(), params[o + 1].clone(), link); // [B, out]
        }
        first_or_affine(h, tail, params[o].clone(), params[o + 1].clone(), split)
    }
}

/// `x W + b`, or with `tail` (the input's last columns) `x W[..h] + tail W[h..] + b` for h the
/// width of x: x [B, h], tail [B, t], W [h + t, out], b [1, out] → [B, out].
fn first_or_affine(x: Tensor<2>, tail: Option<Tensor<2>>, w: Tensor<2>, b: Tensor<2>, split: usize) -> Tensor<2> {
    let Some(tail) = tail else {
        return affine(x, w, b, split);
    };
    let (head, t) = (x.dims()[1], tail.dims()[1]);
    let w_tail = w.clone().narrow(0, head, t); // [t, out]
    if is_gpu(&tail.device()) && affine_is_one_op(split) {
        // tail W[h..] as dextrain's product too (an affine op with a zero bias, untracked: no
        // gradient of its own), where burn's product of these thin shapes took ~0.2 ms on an H200
        let zero = Tensor::zeros([1, w_tail.dims()[1]], &tail.device().inner());
        return affine(x, w.narrow(0, 0, head), b, split) + affine(tail, w_tail, Tensor::from_inner(zero), split);
    }
    affine(x, w.narrow(0, 0, head), b, split) + matmul_rows(tail, w_tail, split)
}
