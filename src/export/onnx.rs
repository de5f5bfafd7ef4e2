//! The deployable policy network as an ONNX model: its description ([`PolicyNet`], independent of
//! burn), a plain-Rust forward pass ([`forward`], the reference every backend is compared with),
//! the ONNX writer ([`to_onnx`]) and an ONNX runtime in Rust ([`run_onnx`], tract).
//!
//! The model is built with the ONNX protobuf types that `tract-onnx` generates (`tract_onnx::pb`,
//! prost), written with `prost::Message::encode_to_vec`: IR version 8, opset 17, f32 initialisers
//! as little-endian `raw_data`, a dynamic batch axis (`dim_param = "batch"`) on every input and
//! the output. The observation normalisation `x̂ = (x − μ) / d` (d = σ + ε) is inside the graph, so
//! a robot feeds raw observations.
//!
//! Graph of each kind (B = batch):
//! - `Mlp`: obs [B, O] → Sub μ → Div d → (Gemm → [LayerNormalization] → act)* → Gemm → [Tanh] →
//!   actions [B, A] (LayerNorm and the final Tanh for a SAC actor: its deterministic action tanh(μ));
//! - `Encoder`: also priv_obs [B, P] → Sub → Div → Gather(axis 1, the encoder's inputs) → encoder
//!   MLP → z [B, L]; Concat(x̂, z) → actor;
//! - `Student`: history [B, H, D] → Sub → Div (per component) → φ → Gemm (head) → z; Concat(x̂, z)
//!   → actor. φ is a GRU (Transpose [H, B, D] → GRU → Y_h [1, B, Hg] → Squeeze) or a temporal
//!   convolution (per step (MatMul → Add → Relu)×2 → Transpose [B, C, H] → (Conv → Relu)* →
//!   Transpose [B, T', C] → Flatten [B, T'·C], time-major as `learn::tcn` computes it).
//!
//! The GRU is ONNX's `GRU` op (one node, `linear_before_reset = 1`, PyTorch's formulation), not an
//! unrolled cell: one node that runtimes fuse and that reads as what it is, with H·3 fewer nodes.
//! Its gates in ONNX order z, r, h(n): z = σ(x W_z + b_Wz + h R_z + b_Rz), r = σ(x W_r + b_Wr + h R_r
//! + b_Rr), n = tanh(x W_n + b_Wn + r ⊙ (h R_n + b_Rn)), h' = (1 − z) ⊙ n + z ⊙ h, h₀ = 0.

use anyhow::{Context, Result, anyhow, bail, ensure};
use prost::Message;
use tract_onnx::pb;
use tract_onnx::prelude::*;

use crate::config::Activation;

/// ONNX IR version written.
pub const IR_VERSION: i64 = 8;
/// ONNX opset (default domain) written.
pub const OPSET: i64 = 17;

/// One fully connected layer `y = x W + b`.
#[derive(Clone, Debug, PartialEq)]
pub struct Dense {
    /// W, `[inputs, outputs]` row-major.
    pub weight: Vec<f32>,
    /// b, `[outputs]`.
    pub bias: Vec<f32>,
    pub inputs: usize,
    pub outputs: usize,
}

/// An MLP: the activation between layers, none after the last (or tanh with `tanh_output`).
#[derive(Clone, Debug, PartialEq)]
pub struct Mlp {
    pub layers: Vec<Dense>,
    pub activation: Activation,
    /// LayerNorm after each hidden layer's affine map, before its activation (a SAC actor with
    /// `sac.actor_layer_norm`): empty, or one per hidden layer.
    pub layer_norms: Vec<LayerNorm>,
    /// tanh after the last layer: a SAC actor's deterministic action `tanh(μ)` (the squashed
    /// Gaussian's mean squashed).
    pub tanh_output: bool,
}

impl Mlp {
    /// Layers with `activation` between them, no LayerNorm, nothing after the last.
    pub fn plain(layers: Vec<Dense>, activation: Activation) -> Mlp {
        Mlp { layers, activation, layer_norms: Vec::new(), tanh_output: false }
    }
}

/// LayerNorm over the features: `y = (x − mean(x)) / √(var(x) + ε) · gain + shift` (biased
/// variance, ε = [`LAYER_NORM_EPS`], torch's and ONNX's `LayerNormalization` default).
#[derive(Clone, Debug, PartialEq)]
pub struct LayerNorm {
    pub gain: Vec<f32>,
    pub shift: Vec<f32>,
}

/// LayerNorm's ε: the learner's (`learn::kernels::layer_norm`).
pub use crate::learn::kernels::layer_norm::LAYER_NORM_EPS;

/// Per-component normalisation `x̂ = (x − mean) / denom`.
#[derive(Clone, Debug, PartialEq)]
pub struct Normalization {
    pub mean: Vec<f32>,
    pub denom: Vec<f32>,
}

/// A GRU layer (module documentation: formulation and gate order z, r, n).
#[derive(Clone, Debug, PartialEq)]
pub struct Gru {
    /// Input size D and hidden size Hg.
    pub inputs: usize,
    pub hidden: usize,
    /// Input weights `[D, 3Hg]`, column blocks z | r | n.
    pub w_ih: Vec<f32>,
    /// Recurrent weights `[Hg, 3Hg]`, column blocks z | r | n.
    pub w_hh: Vec<f32>,
    /// Biases `[3Hg]` of the input and the recurrent part.
    pub b_ih: Vec<f32>,
    pub b_hh: Vec<f32>,
}

/// A 1-D convolution over time (no padding, no dilation), ReLU after it in a [`Tcn`].
#[derive(Clone, Debug, PartialEq)]
pub struct Conv1d {
    /// Input and output channels, kernel length K and stride S.
    pub inputs: usize,
    pub outputs: usize,
    pub kernel: usize,
    pub stride: usize,
    /// `[K·C_in, C_out]` row-major, row k·C_in + c (ONNX's W[o, c, k] is `weight[(k·C_in + c)·C_out + o]`).
    pub weight: Vec<f32>,
    /// `[C_out]`.
    pub bias: Vec<f32>,
}

/// A temporal-convolution adaptation module (`learn::tcn`): each step through the `embed` layers
/// (ReLU after each), then the convolutions (ReLU after each), flattened time-major [T'·C].
#[derive(Clone, Debug, PartialEq)]
pub struct Tcn {
    pub embed: Vec<Dense>,
    pub convs: Vec<Conv1d>,
}

/// A student's adaptation module φ over its history window.
#[derive(Clone, Debug, PartialEq)]
pub enum Adaptation {
    /// φ = the GRU's last hidden state.
    Gru(Gru),
    /// φ = the TCN's flattened output.
    Tcn(Tcn),
}

/// A deterministic policy network (the Gaussian policy's mean).
#[derive(Clone, Debug, PartialEq)]
pub enum PolicyNet {
    /// actions = actor(norm(obs)).
    Mlp { obs_norm: Normalization, actor: Mlp },
    /// A teacher with a privileged encoder: z = encoder(norm_p(priv_obs)[priv_index]),
    /// actions = actor([norm(obs); z]).
    Encoder { obs_norm: Normalization, priv_norm: Normalization, priv_index: Vec<usize>, encoder: Mlp, actor: Mlp },
    /// A student: z = head(φ(norm_h(history))), actions = actor([norm(obs); z]).
    Student { obs_norm: Normalization, hist_norm: Normalization, adapt: Adaptation, head: Dense, actor: Mlp, history_len: usize },
}

/// Input sizes of a network: (obs, priv_obs or 0, history steps × step size or (0, 0)).
pub fn input_sizes(net: &PolicyNet) -> (usize, usize, (usize, usize)) {
    match net {
        PolicyNet::Mlp { obs_norm, .. } => (obs_norm.mean.len(), 0, (0, 0)),
        PolicyNet::Encoder { obs_norm, priv_norm, .. } => (obs_norm.mean.len(), priv_norm.mean.len(), (0, 0)),
        PolicyNet::Student { obs_norm, hist_norm, history_len, .. } => (obs_norm.mean.len(), 0, (*history_len, hist_norm.mean.len())),
    }
}

/// Output size of a network.
pub fn output_size(net: &PolicyNet) -> usize {
    let actor = match net {
        PolicyNet::Mlp { actor, .. } | PolicyNet::Encoder { actor, .. } | PolicyNet::Student { actor, .. } => actor,
    };
    actor.layers.last().map(|l| l.outputs).unwrap_or(0)
}

// ---------------------------------------------------------------------------------------------
// Checks
// ---------------------------------------------------------------------------------------------

fn check_dense(d: &Dense, what: &str) -> Result<()> {
    ensure!(d.inputs > 0 && d.outputs > 0, "{what}: {} × {} layer; expected positive sizes", d.inputs, d.outputs);
    ensure!(d.weight.len() == d.inputs * d.outputs, "{what}: weight has {} values; expected {} × {} = {}", d.weight.len(), d.inputs, d.outputs, d.inputs * d.outputs);
    ensure!(d.bias.len() == d.outputs, "{what}: bias has {} values; expected {}", d.bias.len(), d.outputs);
    ensure!(d.weight.iter().chain(&d.bias).all(|x| x.is_finite()), "{what}: a weight or bias is not finite");
    Ok(())
}

/// Checks a chain of layers over `inputs` numbers; returns its output size.
fn check_layers(layers: &[Dense], inputs: usize, what: &str) -> Result<usize> {
    ensure!(!layers.is_empty(), "{what}: no layers");
    let mut width = inputs;
    for (k, l) in layers.iter().enumerate() {
        let name = format!("{what} layer {k}");
        check_dense(l, &name)?;
        ensure!(l.inputs == width, "{name}: {} inputs; expected {width} (the previous layer's outputs)", l.inputs);
        width = l.outputs;
    }
    Ok(width)
}

fn check_mlp(m: &Mlp, inputs: usize, what: &str) -> Result<()> {
    check_layers(&m.layers, inputs, what)?;
    if !m.layer_norms.is_empty() {
        ensure!(m.layer_norms.len() + 1 == m.layers.len(), "{what}: {} LayerNorms for {} hidden layers; expected one per hidden layer", m.layer_norms.len(), m.layers.len() - 1);
        for (k, (ln, l)) in m.layer_norms.iter().zip(&m.layers).enumerate() {
            ensure!(ln.gain.len() == l.outputs && ln.shift.len() == l.outputs, "{what} LayerNorm {k}: {} gains and {} shifts; expected {} (the layer's outputs)", ln.gain.len(), ln.shift.len(), l.outputs);
            ensure!(ln.gain.iter().chain(&ln.shift).all(|x| x.is_finite()), "{what} LayerNorm {k}: a gain or shift is not finite");
        }
    }
    Ok(())
}

fn check_norm(n: &Normalization, what: &str) -> Result<()> {
    ensure!(n.mean.len() == n.denom.len(), "{what}: {} means for {} denominators", n.mean.len(), n.denom.len());
    ensure!(n.mean.iter().all(|x| x.is_finite()) && n.denom.iter().all(|d| d.is_finite() && *d > 0.0), "{what}: means must be finite and denominators finite and positive");
    Ok(())
}

/// Checks a GRU over steps of `d` numbers; returns its output size (hidden).
fn check_gru(gru: &Gru, d: usize) -> Result<usize> {
    let h = gru.hidden;
    ensure!(gru.inputs == d, "gru: {} inputs; expected {d} (the history step size)", gru.inputs);
    ensure!(h > 0, "gru: hidden size 0");
    ensure!(gru.w_ih.len() == d * 3 * h, "gru: w_ih has {} values; expected {d} × {} = {}", gru.w_ih.len(), 3 * h, d * 3 * h);
    ensure!(gru.w_hh.len() == h * 3 * h, "gru: w_hh has {} values; expected {h} × {} = {}", gru.w_hh.len(), 3 * h, h * 3 * h);
    ensure!(gru.b_ih.len() == 3 * h && gru.b_hh.len() == 3 * h, "gru: biases have {} and {} values; expected {} each", gru.b_ih.len(), gru.b_hh.len(), 3 * h);
    ensure!(gru.w_ih.iter().chain(&gru.w_hh).chain(&gru.b_ih).chain(&gru.b_hh).all(|x| x.is_finite()), "gru: a weight or bias is not finite");
    Ok(h)
}

/// Checks a TCN over `steps` steps of `d` numbers; returns its output size T'·C.
fn check_tcn(tcn: &Tcn, d: usize, steps: usize) -> Result<usize> {
    let mut width = check_layers(&tcn.embed, d, "tcn embedding")?;
    ensure!(!tcn.convs.is_empty(), "tcn: no convolutions");
    let mut t = steps;
    for (k, c) in tcn.convs.iter().enumerate() {
        let name = format!("tcn convolution {k}");
        ensure!(c.inputs == width, "{name}: {} input channels; expected {width}", c.inputs);
        ensure!(c.outputs > 0 && c.kernel > 0 && c.stride > 0, "{name}: {} channels, kernel {}, stride {}; expected positive sizes", c.outputs, c.kernel, c.stride);
        ensure!(c.kernel <= t, "{name}: kernel {} over {t} steps; expected a kernel at most the steps left", c.kernel);
        ensure!(c.weight.len() == c.kernel * c.inputs * c.outputs, "{name}: weight has {} values; expected {} × {} × {}", c.weight.len(), c.kernel, c.inputs, c.outputs);
        ensure!(c.bias.len() == c.outputs, "{name}: bias has {} values; expected {}", c.bias.len(), c.outputs);
        ensure!(c.weight.iter().chain(&c.bias).all(|x| x.is_finite()), "{name}: a weight or bias is not finite");
        t = (t - c.kernel) / c.stride + 1;
        width = c.outputs;
    }
    Ok(t * width)
}

/// Checks a network's sizes: one-line errors naming the part and the expected sizes.
pub fn check(net: &PolicyNet) -> Result<()> {
    match net {
        PolicyNet::Mlp { obs_norm, actor } => {
            check_norm(obs_norm, "obs normalisation")?;
            check_mlp(actor, obs_norm.mean.len(), "actor")
        }
        PolicyNet::Encoder { obs_norm, priv_norm, priv_index, encoder, actor } => {
            check_norm(obs_norm, "obs normalisation")?;
            check_norm(priv_norm, "priv_obs normalisation")?;
            ensure!(!priv_index.is_empty(), "encoder: no privileged inputs");
            if let Some(&bad) = priv_index.iter().find(|&&i| i >= priv_norm.mean.len()) {
                bail!("encoder: privileged input index {bad}; expected < {} (the priv_obs size)", priv_norm.mean.len());
            }
            check_mlp(encoder, priv_index.len(), "encoder")?;
            let latent = encoder.layers.last().map(|l| l.outputs).unwrap_or(0);
            check_mlp(actor, obs_norm.mean.len() + latent, "actor")
        }
        PolicyNet::Student { obs_norm, hist_norm, adapt, head, actor, history_len } => {
            check_norm(obs_norm, "obs normalisation")?;
            check_norm(hist_norm, "history normalisation")?;
            ensure!(*history_len > 0, "student: history length 0; expected at least 1");
            let f = match adapt {
                Adaptation::Gru(gru) => check_gru(gru, hist_norm.mean.len())?,
                Adaptation::Tcn(tcn) => check_tcn(tcn, hist_norm.mean.len(), *history_len)?,
            };
            check_dense(head, "head")?;
            ensure!(head.inputs == f, "head: {} inputs; expected {f} (the adaptation module's outputs)", head.inputs);
            check_mlp(actor, obs_norm.mean.len() + head.outputs, "actor")
        }
    }
}

// ---------------------------------------------------------------------------------------------
// The plain-Rust forward pass
// ---------------------------------------------------------------------------------------------

/// y [B, out] = x [B, in] W + b.
fn dense(d: &Dense, x: &[f32], b: usize) -> Vec<f32> {
    let mut y = vec![0.0f32; b * d.outputs];
    for r in 0..b {
        let row = &mut y[r * d.outputs..(r + 1) * d.outputs];
        row.copy_from_slice(&d.bias);
        for i in 0..d.inputs {
            let xi = x[r * d.inputs + i];
            let w = &d.weight[i * d.outputs..(i + 1) * d.outputs];
            for (o, wo) in row.iter_mut().zip(w) {
                *o += xi * wo;
            }
        }
    }
    y
}

/// The activation, element-wise (ELU with α = 1).
fn activate(a: Activation, x: &mut [f32]) {
    for v in x {
        *v = match a {
            Activation::Elu => {
                if *v > 0.0 {
                    *v
                } else {
                    v.exp() - 1.0
                }
            }
            Activation::Relu => v.max(0.0),
            Activation::Tanh => v.tanh(),
        };
    }
}

/// LayerNorm of every row of `x` [B, gain.len()] in place.
fn layer_norm(ln: &LayerNorm, x: &mut [f32]) {
    let d = ln.gain.len();
    for row in x.chunks_mut(d) {
        let mean = row.iter().sum::<f32>() / d as f32;
        let var = row.iter().map(|v| (v - mean) * (v - mean)).sum::<f32>() / d as f32; // biased
        let inv = 1.0 / (var + LAYER_NORM_EPS).sqrt();
        for ((v, g), s) in row.iter_mut().zip(&ln.gain).zip(&ln.shift) {
            *v = (*v - mean) * inv * g + s; // (x − μ)/√(σ² + ε) · g + s
        }
    }
}

fn mlp_forward(m: &Mlp, x: &[f32], b: usize) -> Vec<f32> {
    let mut h = x.to_vec();
    for (k, l) in m.layers.iter().enumerate() {
        h = dense(l, &h, b);
        if k + 1 < m.layers.len() {
            if let Some(ln) = m.layer_norms.get(k) {
                layer_norm(ln, &mut h);
            }
            activate(m.activation, &mut h);
        }
    }
    if m.tanh_output {
        h.iter_mut().for_each(|v| *v = v.tanh());
    }
    h
}

fn normalize(n: &Normalization, x: &[f32]) -> Vec<f32> {
    let d = n.mean.len();
    x.iter().enumerate().map(|(k, v)| (v - n.mean[k % d]) / n.denom[k % d]).collect()
}

/// [a; b] per row.
fn concat(a: &[f32], da: usize, b: &[f32], db: usize, rows: usize) -> Vec<f32> {
    let mut out = Vec::with_capacity(rows * (da + db));
    for r in 0..rows {
        out.extend_from_slice(&a[r * da..(r + 1) * da]);
        out.extend_from_slice(&b[r * db..(r + 1) * db]);
    }
    out
}

fn sigmoid(x: f32) -> f32 {
    1.0 / (1.0 + (-x).exp())
}

/// The GRU's last hidden state [B, Hg] over a normalised history [B, H, D] (oldest first).
fn gru_forward(g: &Gru, hist: &[f32], b: usize, steps: usize) -> Vec<f32> {
    let (d, hs) = (g.inputs, g.hidden);
    let mut h = vec![0.0f32; b * hs];
    let wi = Dense { weight: g.w_ih.clone(), bias: g.b_ih.clone(), inputs: d, outputs: 3 * hs };
    let wh = Dense { weight: g.w_hh.clone(), bias: g.b_hh.clone(), inputs: hs, outputs: 3 * hs };
    for t in 0..steps {
        let x: Vec<f32> = (0..b).flat_map(|r| hist[(r * steps + t) * d..(r * steps + t + 1) * d].iter().copied()).collect();
        // gi = x W_ih + b_ih, gh = h W_hh + b_hh, both [B, 3Hg] in blocks z | r | n
        let gi = dense(&wi, &x, b);
        let gh = dense(&wh, &h, b);
        for r in 0..b {
            for j in 0..hs {
                let (iz, ir, in_) = (gi[r * 3 * hs + j], gi[r * 3 * hs + hs + j], gi[r * 3 * hs + 2 * hs + j]);
                let (hz, hr, hn) = (gh[r * 3 * hs + j], gh[r * 3 * hs + hs + j], gh[r * 3 * hs + 2 * hs + j]);
                let z = sigmoid(iz + hz);
                let rr = sigmoid(ir + hr);
                // linear_before_reset: r multiplies (h R_n + b_Rn)
                let n = (in_ + rr * hn).tanh();
                let hp = h[r * hs + j];
                h[r * hs + j] = (1.0 - z) * n + z * hp;
            }
        }
    }
    h
}

/// The TCN's flattened output [B, T'·C] (time-major) over a normalised history [B, H, D].
fn tcn_forward(t: &Tcn, hist: &[f32], b: usize, steps: usize) -> Vec<f32> {
    // every step embedded: [B·H, D] → [B·H, C], ReLU after each layer
    let mut e = hist.to_vec();
    for l in &t.embed {
        e = dense(l, &e, b * steps);
        activate(Activation::Relu, &mut e);
    }
    let mut width = t.embed.last().map(|l| l.outputs).unwrap_or(0);
    let mut len = steps;
    for c in &t.convs {
        let out_len = (len - c.kernel) / c.stride + 1;
        let mut y = vec![0.0f32; b * out_len * c.outputs];
        for r in 0..b {
            for to in 0..out_len {
                let out = &mut y[(r * out_len + to) * c.outputs..(r * out_len + to + 1) * c.outputs];
                out.copy_from_slice(&c.bias);
                // y[t', o] = b[o] + Σ_k Σ_c x[t'·S + k, c] W[k·C_in + c, o]
                for k in 0..c.kernel {
                    for ch in 0..c.inputs {
                        let x = e[(r * len + to * c.stride + k) * width + ch];
                        let w = &c.weight[(k * c.inputs + ch) * c.outputs..(k * c.inputs + ch + 1) * c.outputs];
                        for (o, wo) in out.iter_mut().zip(w) {
                            *o += x * wo;
                        }
                    }
                }
            }
        }
        activate(Activation::Relu, &mut y);
        e = y;
        len = out_len;
        width = c.outputs;
    }
    e
}

/// The network's actions [B, A] for raw inputs (row-major): `obs` [B, O], `priv_obs` [B, P]
/// (Encoder), `history` [B, H, D] (Student); the reference for every other implementation.
pub fn forward(net: &PolicyNet, obs: &[f32], priv_obs: &[f32], history: &[f32], batch: usize) -> Result<Vec<f32>> {
    check(net)?;
    let (o, p, (hl, hd)) = input_sizes(net);
    ensure!(obs.len() == batch * o, "obs: {} values; expected {batch} × {o}", obs.len());
    ensure!(priv_obs.len() == batch * p, "priv_obs: {} values; expected {batch} × {p}", priv_obs.len());
    ensure!(history.len() == batch * hl * hd, "history: {} values; expected {batch} × {hl} × {hd}", history.len());
    Ok(match net {
        PolicyNet::Mlp { obs_norm, actor } => mlp_forward(actor, &normalize(obs_norm, obs), batch),
        PolicyNet::Encoder { obs_norm, priv_norm, priv_index, encoder, actor } => {
            let pn = normalize(priv_norm, priv_obs);
            let e: Vec<f32> = (0..batch).flat_map(|r| priv_index.iter().map(move |&i| (r, i))).map(|(r, i)| pn[r * p + i]).collect();
            let z = mlp_forward(encoder, &e, batch);
            let l = z.len() / batch.max(1);
            mlp_forward(actor, &concat(&normalize(obs_norm, obs), o, &z, l, batch), batch)
        }
        PolicyNet::Student { obs_norm, hist_norm, adapt, head, actor, history_len } => {
            let hn = normalize(hist_norm, history);
            let f = match adapt {
                Adaptation::Gru(gru) => gru_forward(gru, &hn, batch, *history_len),
                Adaptation::Tcn(tcn) => tcn_forward(tcn, &hn, batch, *history_len),
            };
            let z = dense(head, &f, batch);
            mlp_forward(actor, &concat(&normalize(obs_norm, obs), o, &z, head.outputs, batch), batch)
        }
    })
}

// ---------------------------------------------------------------------------------------------
// The ONNX writer
// ---------------------------------------------------------------------------------------------

/// Builds the graph: nodes, initialisers, and a counter for unique names.
struct Graph {
    nodes: Vec<pb::NodeProto>,
    inits: Vec<pb::TensorProto>,
}

fn attr_int(name: &str, i: i64) -> pb::AttributeProto {
    pb::AttributeProto { name: name.into(), r#type: pb::attribute_proto::AttributeType::Int as i32, i, ..Default::default() }
}

fn attr_ints(name: &str, ints: Vec<i64>) -> pb::AttributeProto {
    pb::AttributeProto { name: name.into(), r#type: pb::attribute_proto::AttributeType::Ints as i32, ints, ..Default::default() }
}

fn attr_float(name: &str, f: f32) -> pb::AttributeProto {
    pb::AttributeProto { name: name.into(), r#type: pb::attribute_proto::AttributeType::Float as i32, f, ..Default::default() }
}

impl Graph {
    /// An f32 initialiser of shape `dims` (row-major values), little-endian raw data.
    fn f32s(&mut self, name: &str, dims: &[usize], values: &[f32]) -> String {
        let raw = values.iter().flat_map(|v| v.to_le_bytes()).collect();
        self.inits.push(pb::TensorProto {
            name: name.into(),
            dims: dims.iter().map(|&d| d as i64).collect(),
            data_type: pb::tensor_proto::DataType::Float as i32,
            raw_data: raw,
            ..Default::default()
        });
        name.into()
    }

    /// An i64 initialiser.
    fn i64s(&mut self, name: &str, dims: &[usize], values: &[i64]) -> String {
        let raw = values.iter().flat_map(|v| v.to_le_bytes()).collect();
        self.inits.push(pb::TensorProto {
            name: name.into(),
            dims: dims.iter().map(|&d| d as i64).collect(),
            data_type: pb::tensor_proto::DataType::Int64 as i32,
            raw_data: raw,
            ..Default::default()
        });
        name.into()
    }

    /// A node `op(inputs) → output` named `output`; returns the output's name.
    fn node(&mut self, op: &str, inputs: &[&str], output: &str, attrs: Vec<pb::AttributeProto>) -> String {
        self.nodes.push(pb::NodeProto {
            name: format!("{output}_{}", op.to_lowercase()),
            op_type: op.into(),
            input: inputs.iter().map(|s| s.to_string()).collect(),
            output: vec![output.into()],
            attribute: attrs,
            ..Default::default()
        });
        output.into()
    }

    /// x̂ = (x − mean) / denom, broadcast over the leading axes.
    fn normalize(&mut self, x: &str, n: &Normalization, prefix: &str) -> String {
        let d = n.mean.len();
        let mean = self.f32s(&format!("{prefix}_mean"), &[d], &n.mean);
        let denom = self.f32s(&format!("{prefix}_denom"), &[d], &n.denom);
        let c = self.node("Sub", &[x, &mean], &format!("{prefix}_centred"), vec![]);
        self.node("Div", &[&c, &denom], &format!("{prefix}_normalized"), vec![])
    }

    /// y = x W + b as Gemm (W stored [in, out], so transB = 0).
    fn dense(&mut self, x: &str, d: &Dense, prefix: &str) -> String {
        let w = self.f32s(&format!("{prefix}_weight"), &[d.inputs, d.outputs], &d.weight);
        let b = self.f32s(&format!("{prefix}_bias"), &[d.outputs], &d.bias);
        self.node("Gemm", &[x, &w, &b], &format!("{prefix}_out"), vec![])
    }

    /// A GRU over a normalised history [B, H, D]; returns its last hidden state [B, Hg].
    fn gru(&mut self, h: &str, gru: &Gru) -> String {
        // [B, H, D] → [H, B, D]: ONNX GRU's layout 0 is sequence first
        let seq = self.node("Transpose", &[h], "history_seq", vec![attr_ints("perm", vec![1, 0, 2])]);
        let hs = gru.hidden;
        let w = self.f32s("gru_w", &[1, 3 * hs, gru.inputs], &gates_rows(&gru.w_ih, gru.inputs, hs));
        let r = self.f32s("gru_r", &[1, 3 * hs, hs], &gates_rows(&gru.w_hh, hs, hs));
        let b: Vec<f32> = gru.b_ih.iter().chain(&gru.b_hh).copied().collect();
        let b = self.f32s("gru_b", &[1, 6 * hs], &b);
        self.nodes.push(pb::NodeProto {
            name: "gru".into(),
            op_type: "GRU".into(),
            // X, W, R, B; no sequence lengths, h₀ = 0
            input: vec![seq, w, r, b],
            output: vec!["gru_y".into(), "gru_h".into()],
            attribute: vec![attr_int("hidden_size", hs as i64), attr_int("linear_before_reset", 1)],
            ..Default::default()
        });
        // Y_h [1, B, Hg] → [B, Hg]
        let axes = self.i64s("gru_h_axes", &[1], &[0]);
        self.node("Squeeze", &["gru_h", &axes], "gru_last", vec![])
    }

    /// A TCN over a normalised history [B, H, D]; returns its flattened output [B, T'·C]
    /// (time-major).
    fn tcn(&mut self, h: &str, tcn: &Tcn) -> String {
        // every step embedded: [B, H, D] · [D, C] + b, ReLU (MatMul broadcasts over B and H)
        let mut e = h.to_string();
        for (k, l) in tcn.embed.iter().enumerate() {
            let w = self.f32s(&format!("tcn_embed_{k}_weight"), &[l.inputs, l.outputs], &l.weight);
            let b = self.f32s(&format!("tcn_embed_{k}_bias"), &[l.outputs], &l.bias);
            let m = self.node("MatMul", &[&e, &w], &format!("tcn_embed_{k}_matmul"), vec![]);
            let a = self.node("Add", &[&m, &b], &format!("tcn_embed_{k}_out"), vec![]);
            e = self.node("Relu", &[&a], &format!("tcn_embed_{k}_act"), vec![]);
        }
        // [B, H, C] → [B, C, H]: Conv's channels-first layout
        let mut y = self.node("Transpose", &[&e], "tcn_channels_first", vec![attr_ints("perm", vec![0, 2, 1])]);
        for (k, c) in tcn.convs.iter().enumerate() {
            // W[o, c, k] = weight[(k·C_in + c)·C_out + o]
            let mut w = vec![0.0f32; c.outputs * c.inputs * c.kernel];
            for o in 0..c.outputs {
                for ch in 0..c.inputs {
                    for kk in 0..c.kernel {
                        w[(o * c.inputs + ch) * c.kernel + kk] = c.weight[(kk * c.inputs + ch) * c.outputs + o];
                    }
                }
            }
            let w = self.f32s(&format!("tcn_conv_{k}_weight"), &[c.outputs, c.inputs, c.kernel], &w);
            let b = self.f32s(&format!("tcn_conv_{k}_bias"), &[c.outputs], &c.bias);
            let attrs = vec![attr_ints("kernel_shape", vec![c.kernel as i64]), attr_ints("strides", vec![c.stride as i64])];
            let conv = self.node("Conv", &[&y, &w, &b], &format!("tcn_conv_{k}_out"), attrs);
            y = self.node("Relu", &[&conv], &format!("tcn_conv_{k}_act"), vec![]);
        }
        // [B, C, T'] → [B, T', C] → [B, T'·C]: time-major like the learner's
        let t = self.node("Transpose", &[&y], "tcn_time_major", vec![attr_ints("perm", vec![0, 2, 1])]);
        self.node("Flatten", &[&t], "tcn_out", vec![attr_int("axis", 1)])
    }

    /// An MLP; the last layer's output is named `output`.
    fn mlp(&mut self, x: &str, m: &Mlp, prefix: &str, output: &str) -> String {
        let mut h = x.to_string();
        let n = m.layers.len();
        for (k, l) in m.layers.iter().enumerate() {
            let mut y = self.dense(&h, l, &format!("{prefix}_{k}"));
            h = if k + 1 < n {
                if let Some(ln) = m.layer_norms.get(k) {
                    let g = self.f32s(&format!("{prefix}_{k}_ln_gain"), &[ln.gain.len()], &ln.gain);
                    let s = self.f32s(&format!("{prefix}_{k}_ln_shift"), &[ln.shift.len()], &ln.shift);
                    y = self.node("LayerNormalization", &[&y, &g, &s], &format!("{prefix}_{k}_ln"), vec![attr_int("axis", -1), attr_float("epsilon", LAYER_NORM_EPS)]);
                }
                let act = format!("{prefix}_{k}_act");
                match m.activation {
                    Activation::Elu => self.node("Elu", &[&y], &act, vec![attr_float("alpha", 1.0)]),
                    Activation::Relu => self.node("Relu", &[&y], &act, vec![]),
                    Activation::Tanh => self.node("Tanh", &[&y], &act, vec![]),
                }
            } else {
                y
            };
        }
        if m.tanh_output {
            return self.node("Tanh", &[&h], output, vec![]);
        }
        self.node("Identity", &[&h], output, vec![])
    }
}

/// A graph input or output `[batch, dims…]` of f32.
fn value_info(name: &str, dims: &[usize]) -> pb::ValueInfoProto {
    use pb::tensor_shape_proto::{Dimension, dimension::Value};
    let mut dim = vec![Dimension { denotation: String::new(), value: Some(Value::DimParam("batch".into())) }];
    dim.extend(dims.iter().map(|&d| Dimension { denotation: String::new(), value: Some(Value::DimValue(d as i64)) }));
    pb::ValueInfoProto {
        name: name.into(),
        r#type: Some(pb::TypeProto {
            denotation: String::new(),
            value: Some(pb::type_proto::Value::TensorType(pb::type_proto::Tensor {
                elem_type: pb::tensor_proto::DataType::Float as i32,
                shape: Some(pb::TensorShapeProto { dim }),
            })),
        }),
        doc_string: String::new(),
    }
}

/// Reorders the gate blocks of a `[rows, 3Hg]` matrix (z | r | n columns) into ONNX's `[3Hg, rows]`
/// (z, r, h rows): ONNX's W is `[num_directions, 3·hidden, input]`.
fn gates_rows(w: &[f32], rows: usize, hs: usize) -> Vec<f32> {
    let mut out = vec![0.0f32; 3 * hs * rows];
    for i in 0..rows {
        for g in 0..3 * hs {
            out[g * rows + i] = w[i * 3 * hs + g];
        }
    }
    out
}

/// The network as ONNX bytes; `metadata` goes into `metadata_props`.
pub fn to_onnx(net: &PolicyNet, metadata: &[(String, String)]) -> Result<Vec<u8>> {
    check(net)?;
    let (o, p, (hl, hd)) = input_sizes(net);
    let a = output_size(net);
    let mut g = Graph { nodes: Vec::new(), inits: Vec::new() };
    let mut inputs = vec![value_info("obs", &[o])];
    match net {
        PolicyNet::Mlp { obs_norm, actor } => {
            let x = g.normalize("obs", obs_norm, "obs");
            g.mlp(&x, actor, "actor", "actions");
        }
        PolicyNet::Encoder { obs_norm, priv_norm, priv_index, encoder, actor } => {
            inputs.push(value_info("priv_obs", &[p]));
            let x = g.normalize("obs", obs_norm, "obs");
            let pn = g.normalize("priv_obs", priv_norm, "priv_obs");
            let idx: Vec<i64> = priv_index.iter().map(|&i| i as i64).collect();
            let idx = g.i64s("encoder_input_index", &[idx.len()], &idx);
            let e = g.node("Gather", &[&pn, &idx], "encoder_input", vec![attr_int("axis", 1)]);
            let z = g.mlp(&e, encoder, "encoder", "latent");
            let xz = g.node("Concat", &[&x, &z], "actor_input", vec![attr_int("axis", 1)]);
            g.mlp(&xz, actor, "actor", "actions");
        }
        PolicyNet::Student { obs_norm, hist_norm, adapt, head, actor, history_len: _ } => {
            inputs.push(value_info("history", &[hl, hd]));
            let x = g.normalize("obs", obs_norm, "obs");
            let h = g.normalize("history", hist_norm, "history");
            let f = match adapt {
                Adaptation::Gru(gru) => g.gru(&h, gru),
                Adaptation::Tcn(tcn) => g.tcn(&h, tcn),
            };
            let z = g.dense(&f, head, "head");
            let z = g.node("Identity", &[&z], "latent", vec![]);
            let xz = g.node("Concat", &[&x, &z], "actor_input", vec![attr_int("axis", 1)]);
            g.mlp(&xz, actor, "actor", "actions");
        }
    }
    let graph = pb::GraphProto {
        name: "policy".into(),
        node: g.nodes,
        initializer: g.inits,
        input: inputs,
        output: vec![value_info("actions", &[a])],
        ..Default::default()
    };
    let model = pb::ModelProto {
        ir_version: IR_VERSION,
        opset_import: vec![pb::OperatorSetIdProto { domain: String::new(), version: OPSET }],
        producer_name: "dextrain".into(),
        producer_version: env!("CARGO_PKG_VERSION").into(),
        doc_string: "dextrain policy: the deterministic action (the Gaussian policy's mean; tanh of it for a SAC actor) for raw observations; see policy.json".into(),
        graph: Some(graph),
        metadata_props: metadata.iter().map(|(k, v)| pb::StringStringEntryProto { key: k.clone(), value: v.clone() }).collect(),
        ..Default::default()
    };
    Ok(model.encode_to_vec())
}

/// The `metadata_props` of ONNX bytes.
pub fn read_metadata(bytes: &[u8]) -> Result<Vec<(String, String)>> {
    let m = pb::ModelProto::decode(bytes).map_err(|e| anyhow!("not an ONNX model: {e}"))?;
    Ok(m.metadata_props.into_iter().map(|e| (e.key, e.value)).collect())
}

/// An ONNX policy prepared by tract for one batch size: inputs `obs`, `priv_obs`, `history` as
/// the model declares them.
pub struct OnnxRunner {
    plan: std::sync::Arc<TypedRunnableModel>,
    /// The model's inputs in order: name and shape `[batch, …]`.
    inputs: Vec<(String, Vec<usize>)>,
    batch: usize,
}

/// Errors of tract in one line.
fn tract_error(what: &str, e: impl std::fmt::Display) -> anyhow::Error {
    anyhow!("{what}: {}", crate::text::one_line(&e.to_string()))
}

impl OnnxRunner {
    /// Prepares ONNX bytes for `batch` rows; `per_row(name)`: the numbers per row of an input
    /// (`history`: H · D, the step size D read from the model's declared shape).
    pub fn new(bytes: &[u8], batch: usize, per_row: impl Fn(&str) -> Result<usize>) -> Result<OnnxRunner> {
        ensure!(batch > 0, "an ONNX batch of 0 rows");
        let proto = pb::ModelProto::decode(bytes).map_err(|e| anyhow!("not an ONNX model: {e}"))?;
        let graph = proto.graph.as_ref().context("not an ONNX model: no graph")?;
        let mut model = tract_onnx::onnx().model_for_read(&mut &bytes[..]).map_err(|e| tract_error("cannot load the ONNX model", format!("{e:#}")))?;
        let mut inputs = Vec::new();
        for (k, input) in graph.input.iter().enumerate() {
            ensure!(matches!(input.name.as_str(), "obs" | "priv_obs" | "history"), "the ONNX model has an input {:?}; expected obs, priv_obs or history", input.name);
            let per = per_row(&input.name)?;
            let shape: Vec<usize> = if input.name == "history" {
                // [batch, H, D]: D from the declared shape
                let d = match input.r#type.as_ref().and_then(|t| t.value.as_ref()) {
                    Some(pb::type_proto::Value::TensorType(t)) => t.shape.as_ref().and_then(|s| s.dim.get(2)).and_then(|d| match d.value {
                        Some(pb::tensor_shape_proto::dimension::Value::DimValue(v)) => Some(v as usize),
                        _ => None,
                    }),
                    None => None,
                }
                .context("input \"history\": no step size in the model")?;
                ensure!(d > 0 && per % d == 0, "input \"history\": {per} values per row, not a multiple of its step size {d}");
                vec![batch, per / d, d]
            } else {
                vec![batch, per]
            };
            model = model.with_input_fact(k, f32::fact(&shape).into()).map_err(|e| anyhow!("input {:?}: {e}", input.name))?;
            inputs.push((input.name.clone(), shape));
        }
        let plan = model.into_optimized().and_then(|m| m.into_runnable()).map_err(|e| tract_error("cannot prepare the ONNX model", format!("{e:#}")))?;
        Ok(OnnxRunner { plan, inputs, batch })
    }

    /// The model's input names, in order.
    pub fn input_names(&self) -> Vec<&str> {
        self.inputs.iter().map(|(n, _)| n.as_str()).collect()
    }

    /// Runs the model on raw row-major inputs (`priv_obs`/`history` ignored when the model has no
    /// such input); returns the output `[batch, A]`.
    pub fn run(&self, obs: &[f32], priv_obs: &[f32], history: &[f32]) -> Result<Vec<f32>> {
        let mut tensors: TVec<TValue> = tvec!();
        for (name, shape) in &self.inputs {
            let data = match name.as_str() {
                "obs" => obs,
                "priv_obs" => priv_obs,
                _ => history,
            };
            let want: usize = shape.iter().product();
            ensure!(data.len() == want, "input {name:?}: {} values, expected {want} ({} rows of {:?})", data.len(), self.batch, &shape[1..]);
            let t = Tensor::from_shape(shape, data).map_err(|e| anyhow!("input {name:?}: {e}"))?;
            tensors.push(t.into());
        }
        let out = self.plan.run(tensors).map_err(|e| tract_error("cannot run the ONNX model", format!("{e:#}")))?;
        let y = out[0].to_plain_array_view::<f32>().map_err(|e| anyhow!("the ONNX model's output: {e}"))?;
        Ok(y.iter().copied().collect())
    }
}

/// Runs ONNX bytes with tract on raw inputs (row-major; `priv_obs`/`history` empty when the model
/// has no such input) and returns the output [batch, A].
pub fn run_onnx(bytes: &[u8], obs: &[f32], priv_obs: &[f32], history: &[f32], batch: usize) -> Result<Vec<f32>> {
    ensure!(batch > 0, "run_onnx: batch 0");
    let per_row = |name: &str| -> Result<usize> {
        let data = match name {
            "obs" => obs,
            "priv_obs" => priv_obs,
            _ => history,
        };
        ensure!(!data.is_empty() && data.len() % batch == 0, "input {name:?}: {} values for a batch of {batch}", data.len());
        Ok(data.len() / batch)
    };
    OnnxRunner::new(bytes, batch, per_row)?.run(obs, priv_obs, history)
}
