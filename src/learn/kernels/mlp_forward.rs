//! An MLP's forward pass for acting as one kernel of ours on the GPU (shaders/mlp_forward.wgsl):
//! `h_{l+1} = ELU(h_l W_l + b_l)` for the hidden layers and `h_l W_l + b_l` for the last, where
//! the per-layer path (`nets::mlp_forward`) launches one of dextrain's products per layer. On a
//! hardware GPU each launch costs ~25–40 µs of the host's time (an H200's host, BENCHMARKS.md),
//! and a policy's inference or a rollout step is a few small products: a [512, 256, 128]
//! actor is 4 launches, the actor and critic of a device-resident rollout step 8; here 1 and 2
//! (for the batches [`mode`] gives the kernel).
//!
//! Each entry is summed as dextrain's product sums it (k in increasing order with fused
//! multiply-adds from 0, then the bias, then ELU's expression), so where the learner's products
//! are dextrain's (`gpu_matmul`'s default routines) the result is the per-layer path's bit for bit
//! and a run is the run it was, only with fewer launches; with another routine the per-layer path
//! stays (the update's forward pass, through the routine, must see what acting saw).
//!
//! Which path acting takes (`DEXTRAIN_MLP_FORWARD`): `auto` (the default) the kernel where the MLP's
//! work over the batch is at most [`AUTO_MACS_PER_LAYER`] multiply-adds per layer, the per-layer
//! products above; `fused` the kernel always; `layers` the products always. The kernel holds 8
//! accumulators a thread without double-buffering its slices and re-reads every layer's weights per
//! 32 rows, so on a large batch of wide layers it may run well under the tuned product's ~20 TFLOP/s
//! while it saves a few launches of ~25–40 µs: the bound is an estimate (not yet measured on a
//! GPU; `benches/gpu_suite.sh` times the PPO bench with `auto` and with `fused`).
//!
//! Used for parameters without autodiff (acting: `inference_params`), ELU hidden layers, up to
//! [`MAX_LAYERS`] layers, where the adapter binds its 2 + 2·layers storage buffers in one stage
//! (one more with a hidden layer, three more with a policy's actions); elsewhere the caller runs
//! the per-layer path.

use std::sync::OnceLock;

use burn::backend::Cube;
use burn::backend::ops::FloatTensorOps;
use burn::backend::tensor::FloatTensor;
use burn::prelude::Tensor;
use burn::tensor::{FloatDType, Shape};

use super::wgsl_kernel::{WgslKernel, launch, plain_primitive};
use crate::config::Activation;

/// shaders/mlp_forward.wgsl (a template).
const SHADER: &str = include_str!("../../../shaders/mlp_forward.wgsl");

/// The most layers (hidden and output) the kernel takes.
pub const MAX_LAYERS: usize = 6;

/// Rows per workgroup (the shader's BM).
const ROWS_PER_GROUP: usize = 32;

/// The environment variable that chooses the path: `auto` (unset), `fused` or `layers`.
pub const ENV_VAR: &str = "DEXTRAIN_MLP_FORWARD";

/// Under `auto`, the kernel runs an MLP of L layers over a batch when its multiply-adds (rows ×
/// Σ in·out) are at most L times this: a launch's ~30 µs of host time is ~75 M multiply-adds at
/// 5 TFLOP/s, a guess at the kernel's rate on an H200 for such batches. The lift configs' policies
/// (2,048 rows through [256, 128, 64]: ~0.13 G per MLP) take the kernel; the PPO bench's peer
/// networks at 4,096 rows ([512, 256, 128]: ~0.9 G) the products.
pub const AUTO_MACS_PER_LAYER: usize = 75_000_000;

/// How acting runs its MLPs' forward passes on a GPU (`DEXTRAIN_MLP_FORWARD`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MlpForwardMode {
    /// The kernel up to [`AUTO_MACS_PER_LAYER`] per layer, the per-layer products above.
    Auto,
    /// The kernel wherever it applies.
    Fused,
    /// The per-layer products always.
    Layers,
}

/// The widths of an MLP as the kernel's variant: `widths[0..=layers]` (input, hidden…, output).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct MlpWidths {
    /// Input, hidden and output widths; entries past `layers` are 0.
    pub widths: [u32; MAX_LAYERS + 1],
    /// Dense layers (hidden and output).
    pub layers: u32,
    /// Whether the kernel also writes a policy's sampled actions `μ + σ ε` beside `μ` (its output).
    pub actions: bool,
}

impl MlpWidths {
    /// The widest hidden layer (1 without one: the scratch buffer is then unused).
    fn widest_hidden(&self) -> u32 {
        self.widths[1..self.layers as usize].iter().copied().max().unwrap_or(1).max(1)
    }
}

/// The path of this process (`DEXTRAIN_MLP_FORWARD`, read once; a value other than `fused` or
/// `layers` is `auto`).
pub fn mode() -> MlpForwardMode {
    static MODE: OnceLock<MlpForwardMode> = OnceLock::new();
    *MODE.get_or_init(|| match std::env::var(ENV_VAR).as_deref() {
        Ok("fused") => MlpForwardMode::Fused,
        Ok("layers") => MlpForwardMode::Layers,
        _ => MlpForwardMode::Auto,
    })
}

/// The path as the benches report it: `auto`, `fused` or `layers`.
pub fn mode_name() -> &'static str {
    match mode() {
        MlpForwardMode::Auto => "auto",
        MlpForwardMode::Fused => "fused",
        MlpForwardMode::Layers => "layers",
    }
}

/// Whether `mode` runs an MLP of `widths` (input, hidden…, output) over `rows` rows in the kernel.
pub fn takes(mode: MlpForwardMode, rows: usize, widths: &[usize]) -> bool {
    let layers = widths.len().saturating_sub(1);
    let macs: usize = widths.windows(2).map(|w| w[0].saturating_mul(w[1])).fold(0, usize::saturating_add).saturating_mul(rows); // rows · Σ in·out
    match mode {
        MlpForwardMode::Auto => macs <= AUTO_MACS_PER_LAYER.saturating_mul(layers),
        MlpForwardMode::Fused => true,
        MlpForwardMode::Layers => false,
    }
}

/// The kernel's text for `shape`: the widths and one block per layer written into the template.
pub fn shader_source(shape: MlpWidths) -> String {
    let layers = shape.layers as usize;
    let w = &shape.widths;
    let mut bindings = String::new();
    for l in 0..layers {
        bindings += &format!(
            "@group(0) @binding({}) var<storage, read_write> mf_w{l}: array<f32>; // W_{l} [{}, {}]\n@group(0) @binding({}) var<storage, read_write> mf_b{l}: array<f32>; // b_{l} [1, {}]\n",
            2 + 2 * l,
            w[l],
            w[l + 1],
            3 + 2 * l,
            w[l + 1]
        );
    }
    if layers > 1 {
        bindings += &format!("@group(0) @binding({}) var<storage, read_write> mf_h: array<f32>; // [B, 2 · WH]: the hidden layers' outputs\n", 2 + 2 * layers);
    }
    if shape.actions {
        let first = buffer_count(layers, false);
        let a = w[layers];
        bindings += &format!(
            "@group(0) @binding({first}) var<storage, read_write> mf_sigma: array<f32>; // σ [1, {a}]\n@group(0) @binding({}) var<storage, read_write> mf_eps: array<f32>; // ε [K · B, {a}]: this step's rows from mc.eps_row0\n@group(0) @binding({}) var<storage, read_write> mf_a: array<f32>; // the actions [B, {a}]\n",
            first + 1,
            first + 2
        );
    }
    let mut blocks = String::new();
    for l in 0..layers {
        let (k, n) = (w[l], w[l + 1]);
        let last = l + 1 == layers;
        // where layer l reads its input (row r, column k) and writes its output (row r, column c)
        let input = if l == 0 { format!("mf_x[r * {k}u + k]") } else { format!("mf_h[r * H_ROW + {}u + k]", ((l - 1) % 2) as u32 * shape.widest_hidden()) };
        let output = if last && shape.actions {
            format!(
                "let mu = acc[j] + mf_b{l}[c]; // μ = h W + b\n                        mf_y[r * {n}u + c] = mu;\n                        mf_a[r * {n}u + c] = mu + mf_sigma[c] * mf_eps[(mc.eps_row0 + r) * {n}u + c]; // a = μ + σ ε"
            )
        } else if last {
            format!("mf_y[r * {n}u + c] = acc[j] + mf_b{l}[c]; // h W + b")
        } else {
            format!("mf_h[r * H_ROW + {}u + c] = elu(acc[j] + mf_b{l}[c]); // ELU(h W + b)", (l % 2) as u32 * shape.widest_hidden())
        };
        blocks += &format!(
            r#"    // layer {l}: [B, {k}] · [{k}, {n}] + b{act}
    for (var col0 = 0u; col0 < {n}u; col0 += BN) {{
        var acc0 = vec4<f32>(0.0); // row row0 + 2·ty, columns col0 + 4·tx .. + 4
        var acc1 = vec4<f32>(0.0); // row row0 + 2·ty + 1
        for (var k0 = 0u; k0 < {k}u; k0 += BK) {{
            for (var s = 0u; s < 2u; s++) {{
                let r = row0 + a_r0 + s * 16u;
                let k = k0 + a_d;
                var v = 0.0;
                if r < mc.rows && k < {k}u {{
                    v = {input};
                }}
                mf_sa[a_d * BM + a_r0 + s * 16u] = v;
            }}
            {{
                let k = k0 + b_d;
                var w = vec4<f32>(0.0);
                if k < {k}u {{
                    for (var j = 0u; j < 4u; j++) {{
                        let c = col0 + b_c + j;
                        if c < {n}u {{
                            w[j] = mf_w{l}[k * {n}u + c];
                        }}
                    }}
                }}
                mf_sb[b_d * (BN / 4u) + b_c / 4u] = w;
            }}
            workgroupBarrier();
            for (var d = 0u; d < BK; d++) {{
                // acc[r, c] += h[r, k0 + d] · W[k0 + d, c]
                let w = mf_sb[d * (BN / 4u) + tx];
                acc0 = fma(vec4<f32>(mf_sa[d * BM + 2u * ty]), w, acc0);
                acc1 = fma(vec4<f32>(mf_sa[d * BM + 2u * ty + 1u]), w, acc1);
            }}
            workgroupBarrier();
        }}
        for (var i = 0u; i < 2u; i++) {{
            let r = row0 + 2u * ty + i;
            let acc = select(acc0, acc1, i == 1u);
            if r < mc.rows {{
                for (var j = 0u; j < 4u; j++) {{
                    let c = col0 + 4u * tx + j;
                    if c < {n}u {{
                        {output}
                    }}
                }}
            }}
        }}
    }}
{barrier}"#,
            act = if last { "" } else { ", ELU" },
            barrier = if last { "" } else { "    // the layer's output, written by this workgroup's threads, read by them next\n    storageBarrier();\n    workgroupBarrier();\n" },
        );
    }
    SHADER
        .replace("$PARAM_BINDINGS", bindings.trim_end())
        .replace("$UNIFORM_BINDING", &buffer_count(layers, shape.actions).to_string())
        .replace("$WH", &shape.widest_hidden().to_string())
        .replace("$LAYERS", blocks.trim_end())
}

/// The storage buffers the kernel binds for `layers` layers: x, y, each layer's W and b, the
/// scratch buffer where there is a hidden layer, and σ, ε and the actions with `actions`.
fn buffer_count(layers: usize, actions: bool) -> usize {
    2 + 2 * layers + usize::from(layers > 1) + if actions { 3 } else { 0 }
}

/// `t`'s primitive on burn's wgpu device if it is a contiguous f32 tensor of `shape` without
/// autodiff (the parameters for acting); else None.
fn plain(t: &Tensor<2>, shape: [usize; 2]) -> Option<FloatTensor<Cube>> {
    if t.is_autodiff() {
        return None;
    }
    plain_primitive(t, shape).ok()
}

/// A policy's action noise for [`forward_acting`]: the kernel writes `a = μ + σ ε` beside `μ`.
pub struct ActionNoise<'a> {
    /// σ `[1, A]`.
    pub sigma: &'a Tensor<2>,
    /// ε `[K · B, A]`: a block of draws, this step's B rows from `first_row` on.
    pub eps: &'a Tensor<2>,
    /// The first row of this step's draws in `eps`.
    pub first_row: usize,
}

/// The MLP `params` (`[W_0, b_0, …]`, `nets::mlp_shapes`' order) with `act` hidden layers applied
/// to `x` [B, in] → [B, out] in one kernel; None where it does not apply (the CPU, an activation
/// other than ELU, parameters with autodiff or an input in an autodiff graph, another matmul
/// routine, too many layers or bindings, tensors that are not contiguous f32, or a batch that
/// [`mode`] leaves to the products): the caller then runs the per-layer path.
pub fn forward(params: &[Tensor<2>], x: &Tensor<2>, act: Activation) -> Option<Tensor<2>> {
    forward_acting(params, x, act, None).map(|(y, _)| y)
}

/// [`forward`], and with `noise` also a policy's actions `a = μ + σ ε` [B, out] for its output μ,
/// in the same kernel (where the tensor ops launch two more): `(μ, Some(a))`. `μ + σ ε` is
/// rounded as the tensor ops round it on lavapipe; a driver may contract it into one rounding.
pub fn forward_acting(params: &[Tensor<2>], x: &Tensor<2>, act: Activation, noise: Option<ActionNoise<'_>>) -> Option<(Tensor<2>, Option<Tensor<2>>)> {
    let layers = params.len() / 2;
    if act != Activation::Elu || mode() == MlpForwardMode::Layers || layers == 0 || layers > MAX_LAYERS || params.len() % 2 != 0 || !super::gpu_matmul::chosen().is_ours() {
        return None;
    }
    let [rows, input] = x.dims();
    let groups = u32::try_from(rows.div_ceil(ROWS_PER_GROUP)).ok().filter(|&g| (1..=65_535).contains(&g))?;
    let mut widths = [0u32; MAX_LAYERS + 1];
    widths[0] = u32::try_from(input).ok()?;
    let mut prims = Vec::with_capacity(params.len());
    for l in 0..layers {
        let [k, n] = params[2 * l].dims();
        if k as u32 != widths[l] || n == 0 {
            return None;
        }
        widths[l + 1] = u32::try_from(n).ok()?;
        prims.push(plain(&params[2 * l], [k, n])?);
        prims.push(plain(&params[2 * l + 1], [1, n])?);
    }
    // an input with autodiff but in no graph (a device-resident rollout's observations) is a
    // constant to the layers: the kernel reads its memory, and the output gets autodiff back as
    // the layers' output would have it
    if x.is_tracked() {
        return None;
    }
    let all_widths: Vec<usize> = widths[..=layers].iter().map(|&w| w as usize).collect();
    if !takes(mode(), rows, &all_widths) {
        return None;
    }
    let x_prim = plain(&x.clone().inner(), [rows, input])?;
    let out_width = widths[layers] as usize;
    // σ [1, A] and the step's rows of ε, where the actions are asked for
    let noise_prims = match &noise {
        Some(n) => {
            let eps_rows = n.eps.dims()[0];
            if n.first_row.checked_add(rows)? > eps_rows {
                return None;
            }
            Some((plain(n.sigma, [1, out_width])?, plain(n.eps, [eps_rows, out_width])?, u32::try_from(n.first_row).ok()?, eps_rows))
        }
        None => None,
    };
    let shape = MlpWidths { widths, layers: layers as u32, actions: noise.is_some() };
    // every index the kernel forms stays under 2^32
    let widest = (0..=layers).map(|l| widths[l] as usize).max().unwrap_or(0).max(2 * shape.widest_hidden() as usize);
    u32::try_from(rows.checked_mul(widest)?).ok()?;
    if let Some((_, _, _, eps_rows)) = &noise_prims {
        u32::try_from(eps_rows.checked_mul(out_width)?).ok()?;
    }
    let ctx = crate::learn::device::gpu_context_of(&x.device())?;
    if (ctx.device.limits().max_storage_buffers_per_shader_stage as usize) < buffer_count(layers, shape.actions) {
        return None;
    }
    let device = &x_prim.device;
    let out = Cube::float_empty(Shape::new([rows, out_width]), device, FloatDType::F32); // written whole
    let actions = noise_prims.as_ref().map(|_| Cube::float_empty(Shape::new([rows, out_width]), device, FloatDType::F32)); // written whole
    let scratch = (layers > 1).then(|| Cube::float_empty(Shape::new([rows, 2 * shape.widest_hidden() as usize]), device, FloatDType::F32));
    let mut buffers: Vec<&FloatTensor<Cube>> = vec![&x_prim, &out];
    buffers.extend(prims.iter());
    buffers.extend(scratch.as_ref());
    let mut eps_row0 = 0;
    if let (Some((sigma, eps, first, _)), Some(a)) = (&noise_prims, &actions) {
        buffers.extend([sigma, eps, a]);
        eps_row0 = *first;
    }
    let kernel = WgslKernel { name: "dextrain_mlp_forward", key: shape, source: shader_source, entry_point: "mlp_forward", workgroup: [16, 16] };
    launch(kernel, [groups, 1, 1], &buffers, &[rows as u32, eps_row0]);
    let like_x = |p: FloatTensor<Cube>| {
        let t = Tensor::from_primitive::<Cube>(p);
        if x.is_autodiff() { t.autodiff() } else { t }
    };
    Some((like_x(out), actions.map(like_x)))
}
