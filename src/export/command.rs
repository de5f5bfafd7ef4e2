//! `dextrain export RUN [--checkpoint N] [--out DIR] [--verify]`: writes a run's policy as
//! `policy.onnx` (the deterministic policy with its observation normalisation baked in) and its
//! contract `policy.json`, plus `world.toml` (the run's config: the world `dextrain play` rebuilds;
//! the policy side reads nothing from it), by default into `RUN/export/`.
//!
//! The files are written into a temporary directory beside the destination and renamed into place,
//! so an export is never half-written; an existing destination is replaced only if it holds nothing
//! but an export's files. `--verify` runs the exported model (tract) on observations recorded from
//! real episodes of the task and compares it with the burn policy.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail, ensure};
use serde::Serialize;

use super::contract::{self, CONTRACT_FILE, ContractSource, PolicyContract, Source, TensorIo};
use super::onnx::{self, Dense, LayerNorm, Mlp, Normalization, PolicyNet};
use crate::learn::checkpoint;
use crate::config::Config;
use crate::env::SimModel;
use crate::learn::normalizer::Normalizer;
use crate::learn::distill::{Adaptation, StudentPolicy};
use crate::learn::nets::to_host;
use crate::learn::ppo::Ppo;
use crate::learn::policy::{LoadedPolicy, load_policy};
use crate::learn::sac::Sac;
use crate::run_dir;
use crate::task::{make_task_batch, task_setup};

/// The ONNX file's name in an export directory.
pub const ONNX_FILE: &str = "policy.onnx";
/// The world file's name in an export directory (the run's resolved config).
pub const WORLD_FILE: &str = "world.toml";
/// Every file an export directory holds.
pub const EXPORT_FILES: [&str; 3] = [ONNX_FILE, CONTRACT_FILE, WORLD_FILE];
/// The largest difference `--verify` accepts between the ONNX model and the burn policy.
pub const VERIFY_TOLERANCE: f64 = 1e-5;

/// `dextrain export`.
#[derive(clap::Args, Clone, Debug)]
pub struct ExportArgs {
    /// The run directory (runs/NAME).
    pub run: PathBuf,
    /// Which checkpoint: an iteration number or "latest".
    #[arg(long, default_value = "latest")]
    pub checkpoint: String,
    /// Where to write the files (default: RUN/export).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Run the exported model (tract) on observations recorded from real episodes and compare it
    /// with the burn policy; fails above 1e-5.
    #[arg(long)]
    pub verify: bool,
}

/// What `dextrain export` prints (one JSON line).
#[derive(Clone, Debug, Serialize)]
pub struct ExportReport {
    /// The export directory.
    pub dir: String,
    /// The checkpoint exported.
    pub checkpoint: String,
    /// `--verify`: rows compared and the largest |ONNX − burn| over every action.
    pub verified_rows: Option<usize>,
    pub max_abs_diff: Option<f64>,
}

/// The normalisation x̂ = (x − μ) / (σ + ε) of a normaliser, or the identity when the policy does
/// not normalise.
fn normalization(n: &Normalizer, on: bool) -> Normalization {
    let d = n.dim();
    if !on || n.count <= 0.0 {
        return Normalization { mean: vec![0.0; d], denom: vec![1.0; d] };
    }
    // σ = √(m2 / count), as the learner computes it
    let denom = n.m2.iter().map(|&m2| ((m2 / n.count).sqrt() + n.eps) as f32).collect();
    Normalization { mean: n.mean.iter().map(|&m| m as f32).collect(), denom }
}

/// The layer whose flat parameters `[w, b]` (shapes `[in, out]`, `[1, out]`) start `values`.
fn dense(values: &[Vec<f32>], shapes: &[[usize; 2]]) -> Dense {
    Dense { weight: values[0].clone(), bias: values[1].clone(), inputs: shapes[0][0], outputs: shapes[0][1] }
}

/// An MLP's layers from flat parameters `[w0, b0, w1, b1, …]` with shapes `[in, out]`, `[1, out]`.
fn mlp(values: &[Vec<f32>], shapes: &[[usize; 2]], activation: crate::config::Activation) -> Mlp {
    let layers = values.chunks(2).zip(shapes.chunks(2)).map(|(v, s)| dense(v, s)).collect();
    Mlp::plain(layers, activation)
}

/// The burn policy `--verify` compares the ONNX model with.
enum BurnPolicy {
    Ppo(Box<Ppo>),
    Sac(Box<Sac>),
}

impl BurnPolicy {
    /// The deterministic actions [N, A] for raw observations (and critic observations).
    fn act_mean(&self, obs: &[f32], priv_obs: &[f32]) -> Result<Vec<f32>> {
        match self {
            BurnPolicy::Ppo(p) => p.act_mean(obs, priv_obs),
            BurnPolicy::Sac(s) => s.act_mean(obs),
        }
    }
}

/// A run's policy as the exporter sees it: the network description and the burn policy.
struct Loaded {
    net: PolicyNet,
    policy: BurnPolicy,
}

/// The network of a loaded PPO policy (with or without a privileged encoder reading
/// the critic observation's entries `ppo.net.encoder_index`).
fn ppo_net(ppo: Box<Ppo>) -> Result<Loaded> {
    let values = ppo.net.values()?;
    let n_actor = ppo.net.actor_shapes.len();
    let actor = mlp(&values[..n_actor], &ppo.net.actor_shapes, ppo.net.activation);
    let obs_norm = normalization(&ppo.obs_norm, ppo.normalize);
    let net = if ppo.net.encoder_shapes.is_empty() {
        PolicyNet::Mlp { obs_norm, actor }
    } else {
        // parameters: actor…, log_std, critic…, encoder…
        let start = n_actor + 1 + ppo.net.critic_shapes.len();
        let encoder = mlp(&values[start..], &ppo.net.encoder_shapes, ppo.net.encoder_activation);
        PolicyNet::Encoder { obs_norm, priv_norm: normalization(&ppo.priv_norm, ppo.normalize), priv_index: ppo.net.encoder_index.clone(), encoder, actor }
    };
    Ok(Loaded { net, policy: BurnPolicy::Ppo(ppo) })
}

/// The network of a loaded SAC actor: its deterministic action `tanh(μ(ŝ))`, the first `A` of the
/// actor's `2A` outputs (the rest are log σ, which the deterministic action does not use), with
/// the actor's LayerNorms when `sac.actor_layer_norm` is on.
fn sac_net(sac: Box<Sac>, ckpt: &Path) -> Result<Loaded> {
    let values = sac.actor.iter().map(|p| to_host(p.clone().inner())).collect::<Result<Vec<Vec<f32>>>>()?;
    let shapes = sac.actor_layout.shapes();
    let per_hidden = sac.actor_layout.per_hidden();
    let hidden = sac.actor_layout.hidden.len();
    let mut layers = Vec::new();
    let mut layer_norms = Vec::new();
    for l in 0..hidden {
        let k = l * per_hidden;
        layers.push(dense(&values[k..], &shapes[k..]));
        if sac.actor_layout.layer_norm {
            layer_norms.push(LayerNorm { gain: values[k + 2].clone(), shift: values[k + 3].clone() });
        }
    }
    // the output layer [h, 2A]: μ's columns 0..A of every row
    let k = hidden * per_hidden;
    let [h, two_a] = shapes[k];
    let a = sac.dims.act;
    ensure!(two_a == 2 * a, "{}: the SAC actor has {two_a} outputs; expected {} (μ and log σ for {a} actions)", ckpt.display(), 2 * a);
    let weight = values[k].chunks(two_a).flat_map(|row| row[..a].iter().copied()).collect();
    layers.push(Dense { weight, bias: values[k + 1][..a].to_vec(), inputs: h, outputs: a });
    let actor = Mlp { layers, activation: sac.activation, layer_norms, tanh_output: true };
    let net = PolicyNet::Mlp { obs_norm: normalization(&sac.obs_norm, sac.normalize), actor };
    Ok(Loaded { net, policy: BurnPolicy::Sac(sac) })
}

/// XXH64 (hex) of a checkpoint's manifest.
fn manifest_hash(ckpt: &Path) -> Result<String> {
    let p = ckpt.join(checkpoint::MANIFEST);
    let bytes = std::fs::read(&p).with_context(|| format!("cannot read {}", p.display()))?;
    Ok(contract::hex(checkpoint::xxh64(&bytes, 0)))
}

/// Runs `dextrain export`.
pub fn run(args: &ExportArgs) -> Result<ExportReport> {
    run_dir::check_run(&args.run)?;
    let ckpt = checkpoint::find(&args.run, &args.checkpoint)?;
    let state = checkpoint::read_state(&ckpt)?;
    let cfg_path = args.run.join("config.toml");
    let cfg = Config::load(&cfg_path)?;
    let model = SimModel::from_config(&cfg)?;
    let setup = task_setup(&cfg, &model)?;
    let spec = &setup.spec;
    ensure!(
        (state.obs_dim, state.priv_dim, state.action_dim) == (spec.obs_dim, spec.priv_dim, spec.action_dim),
        "{}: the checkpoint's sizes (obs {}, critic obs {}, actions {}) are not the task's of {} (obs {}, critic obs {}, actions {})",
        ckpt.display(),
        state.obs_dim,
        state.priv_dim,
        state.action_dim,
        cfg_path.display(),
        spec.obs_dim,
        spec.priv_dim,
        spec.action_dim
    );
    if cfg.train.algorithm == crate::config::AlgorithmChoice::Distill {
        return export_student(args, &cfg, &cfg_path, &ckpt, state.iteration, &model, &setup);
    }
    // the policy's network, the encoder's inputs as the loaded policy resolved them (SAC has none)
    // and whether its action is SAC's squashed mean
    let (loaded, encoder_index, is_sac) = match load_policy(&cfg, spec, &ckpt, 1, burn::prelude::Device::flex())? {
        LoadedPolicy::Ppo(ppo) => {
            let index = ppo.net.encoder_index.clone();
            (ppo_net(ppo)?, index, false)
        }
        LoadedPolicy::Sac(sac) => (sac_net(sac, &ckpt)?, Vec::new(), true),
        LoadedPolicy::Student(_) => bail!("{}: a distillation run's student is exported by export_student", ckpt.display()),
    };
    let has_encoder = !encoder_index.is_empty();
    let io = |name: &str, dims: Vec<serde_json::Value>, description: &str| TensorIo { name: name.into(), shape: dims, description: description.into() };
    let batch = serde_json::Value::from("batch");
    let mut inputs = vec![io("obs", vec![batch.clone(), spec.obs_dim.into()], "the observation, raw values in `observation`'s layout")];
    if has_encoder {
        inputs.push(io("priv_obs", vec![batch.clone(), spec.priv_dim.into()], "the privileged (critic) observation, raw values in `privileged`'s layout: simulator state a robot does not have; the encoder reads the entries of policy.encoder.inputs"));
    }
    let action = if is_sac {
        "the policy's deterministic action tanh(μ) (the squashed Gaussian's mean squashed), in (−1, 1), before the action mapping"
    } else {
        "the policy's mean action, before clipping and the action mapping"
    };
    let output = io("actions", vec![batch, spec.action_dim.into()], action);
    let metadata = metadata(spec, &model, args, state.iteration);
    let bytes = onnx::to_onnx(&loaded.net, &metadata)?;
    let src = ContractSource {
        source: Source {
            run: std::fs::canonicalize(&args.run).unwrap_or_else(|_| args.run.clone()).display().to_string(),
            checkpoint: state.iteration,
            checkpoint_xxh64: manifest_hash(&ckpt)?,
            algorithm: if is_sac { "sac" } else { "ppo" }.into(),
            teacher: None,
        },
        model_file: ONNX_FILE,
        model_bytes: &bytes,
        inputs,
        output,
        obs_fields: spec.obs_layout.iter().map(|s| s.name.clone()).collect(),
        priv_fields: has_encoder.then(|| spec.priv_layout.iter().map(|s| s.name.clone()).collect()),
        history: None,
    };
    let c = contract::build(&cfg, spec, &setup.tc, &model, src)?;
    let out = args.out.clone().unwrap_or_else(|| args.run.join("export"));
    let world = std::fs::read(&cfg_path).with_context(|| format!("cannot read {}", cfg_path.display()))?;
    write_export(&out, &bytes, &c, &world)?;
    let mut report = ExportReport { dir: out.display().to_string(), checkpoint: ckpt.display().to_string(), verified_rows: None, max_abs_diff: None };
    if args.verify {
        let (rows, diff) = verify(&cfg, &loaded, &bytes)?;
        check_verified(&mut report, rows, diff)?;
    }
    Ok(report)
}

/// Writes the export files into `out` atomically: a temporary directory beside it, then renames.
/// An existing `out` is replaced only if it holds nothing but [`EXPORT_FILES`].
fn write_export(out: &Path, onnx_bytes: &[u8], c: &PolicyContract, world: &[u8]) -> Result<()> {
    if out.exists() {
        ensure!(out.is_dir(), "--out {}: exists and is not a directory", out.display());
        for e in std::fs::read_dir(out).with_context(|| format!("cannot list {}", out.display()))? {
            let name = e.with_context(|| format!("cannot list {}", out.display()))?.file_name().to_string_lossy().into_owned();
            ensure!(
                EXPORT_FILES.contains(&name.as_str()),
                "--out {}: holds {name:?}, which an export does not write; refusing to replace it (expected a directory of {})",
                out.display(),
                EXPORT_FILES.join(", ")
            );
        }
    }
    let parent = out.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    std::fs::create_dir_all(parent).with_context(|| format!("cannot create {}", parent.display()))?;
    let stem = out.file_name().map(|f| f.to_string_lossy().into_owned()).unwrap_or_else(|| "export".into());
    let tmp = parent.join(format!(".{stem}.tmp-{}", std::process::id()));
    if tmp.exists() {
        std::fs::remove_dir_all(&tmp).with_context(|| format!("cannot remove {}", tmp.display()))?;
    }
    std::fs::create_dir(&tmp).with_context(|| format!("cannot create {}", tmp.display()))?;
    let json = serde_json::to_string_pretty(c).context("cannot serialise policy.json")?;
    for (name, data) in [(ONNX_FILE, onnx_bytes), (CONTRACT_FILE, json.as_bytes()), (WORLD_FILE, world)] {
        let p = tmp.join(name);
        std::fs::write(&p, data).with_context(|| format!("cannot write {}", p.display()))?;
    }
    if out.exists() {
        let old = parent.join(format!(".{stem}.old-{}", std::process::id()));
        std::fs::rename(out, &old).with_context(|| format!("cannot move the old export {} aside", out.display()))?;
        std::fs::rename(&tmp, out).with_context(|| format!("cannot rename {} to {}", tmp.display(), out.display()))?;
        std::fs::remove_dir_all(&old).with_context(|| format!("cannot remove the old export {}", old.display()))?;
    } else {
        std::fs::rename(&tmp, out).with_context(|| format!("cannot rename {} to {}", tmp.display(), out.display()))?;
    }
    Ok(())
}

/// The task batch `--verify` records episodes on: CPU backend, 16 envs, eval's seed offset.
fn verify_task(cfg: &Config) -> Result<Box<dyn crate::task::TaskBatch>> {
    let mut c = cfg.clone();
    c.sim.backend = crate::config::BackendChoice::Cpu;
    c.sim.num_envs = 16;
    c.seed = c.seed.wrapping_add(1_000_003);
    let model = SimModel::from_config(&c)?;
    make_task_batch(&c, model)
}

/// max |a − b| (NaN if any difference is NaN).
fn max_abs_diff(a: &[f32], b: &[f32]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (*x as f64 - *y as f64).abs()).fold(0.0f64, |m, d| if d.is_nan() || m.is_nan() { f64::NAN } else { m.max(d) })
}

/// Records `--verify`'s result in the report; an error above [`VERIFY_TOLERANCE`].
fn check_verified(report: &mut ExportReport, rows: usize, diff: f64) -> Result<()> {
    report.verified_rows = Some(rows);
    report.max_abs_diff = Some(diff);
    if diff.is_nan() || diff > VERIFY_TOLERANCE {
        bail!("--verify: the exported model differs from the burn policy by {diff:e} (max abs over {rows} observations), above {VERIFY_TOLERANCE:e}");
    }
    Ok(())
}

/// Observations rows recorded for `--verify`: at most this many.
const VERIFY_ROWS: usize = 2048;

/// Records observations from real episodes of the run's task (the burn policy acting, CPU
/// backend, 16 envs, up to one episode each) and returns (rows, max |ONNX − burn|).
fn verify(cfg: &Config, loaded: &Loaded, bytes: &[u8]) -> Result<(usize, f64)> {
    let mut task = verify_task(cfg)?;
    let spec = task.spec().clone();
    let first = task.reset_all()?;
    let (mut obs, mut priv_obs) = (first.obs.clone(), first.priv_obs.clone());
    let mut rows: Vec<f32> = Vec::new();
    let mut priv_rows: Vec<f32> = Vec::new();
    let mut burn: Vec<f32> = Vec::new();
    for _ in 0..spec.episode_length {
        let a = loaded.policy.act_mean(&obs, &priv_obs)?;
        rows.extend_from_slice(&obs);
        priv_rows.extend_from_slice(&priv_obs);
        burn.extend_from_slice(&a);
        if rows.len() / spec.obs_dim >= VERIFY_ROWS {
            break;
        }
        let b = task.step(&a)?;
        obs = b.obs.clone();
        priv_obs = b.priv_obs.clone();
    }
    let n = rows.len() / spec.obs_dim;
    let has_priv = matches!(loaded.net, PolicyNet::Encoder { .. });
    let ours = onnx::run_onnx(bytes, &rows, if has_priv { &priv_rows } else { &[] }, &[], n)?;
    ensure!(ours.len() == burn.len(), "--verify: the ONNX model gave {} numbers for {} expected", ours.len(), burn.len());
    let diff = max_abs_diff(&ours, &burn);
    Ok((n, diff))
}

/// The key facts written into the ONNX file's `metadata_props`.
fn metadata(spec: &crate::task::TaskSpec, model: &SimModel, args: &ExportArgs, iteration: u64) -> Vec<(String, String)> {
    vec![
        ("dextrain.format".to_string(), contract::CONTRACT_FORMAT.to_string()),
        ("dextrain.version".to_string(), env!("CARGO_PKG_VERSION").to_string()),
        ("dextrain.task".to_string(), spec.kind.to_string()),
        ("dextrain.obs_dim".to_string(), spec.obs_dim.to_string()),
        ("dextrain.action_dim".to_string(), spec.action_dim.to_string()),
        ("dextrain.control_dt".to_string(), spec.control_dt.to_string()),
        ("dextrain.hand".to_string(), model.hand.name.clone()),
        ("dextrain.run".to_string(), args.run.display().to_string()),
        ("dextrain.checkpoint".to_string(), iteration.to_string()),
        ("dextrain.contract".to_string(), CONTRACT_FILE.to_string()),
    ]
}

/// The network description of a student read back from its checkpoint.
fn student_net(s: &StudentPolicy, obs_dim: usize) -> Result<PolicyNet> {
    let full = match &s.norm {
        Some(n) => normalization(n, true),
        None => Normalization { mean: vec![0.0; obs_dim], denom: vec![1.0; obs_dim] },
    };
    let pick = |idx: &[usize]| Normalization { mean: idx.iter().map(|&i| full.mean[i]).collect(), denom: idx.iter().map(|&i| full.denom[i]).collect() };
    let st = &s.student;
    let values = st.values()?;
    let k = st.n_adapt;
    let actor = mlp(&values[k..], &st.shapes[k..], st.activation);
    let layer = |i: usize| dense(&values[i..], &st.shapes[i..]);
    Ok(if st.latent > 0 {
        let adapt = match &st.adaptation {
            Adaptation::Gru => onnx::Adaptation::Gru(onnx::Gru { inputs: st.step_dim, hidden: st.shapes[1][0], w_ih: values[0].clone(), w_hh: values[1].clone(), b_ih: values[2].clone(), b_hh: values[3].clone() }),
            Adaptation::Tcn { convs } => {
                let e = crate::learn::tcn::EMBED_LAYERS;
                let embed = (0..e).map(|j| layer(2 * j)).collect();
                let convs = convs
                    .iter()
                    .enumerate()
                    .map(|(j, &(kernel, stride))| {
                        let i = 2 * (e + j);
                        // weight [K·C_in, C_out]
                        let (rows, outputs) = (st.shapes[i][0], st.shapes[i][1]);
                        onnx::Conv1d { inputs: rows / kernel, outputs, kernel, stride, weight: values[i].clone(), bias: values[i + 1].clone() }
                    })
                    .collect();
                onnx::Adaptation::Tcn(onnx::Tcn { embed, convs })
            }
        };
        let head = layer(k - 2);
        PolicyNet::Student { obs_norm: pick(&s.obs_index), hist_norm: pick(&s.hist_index), adapt, head, actor, history_len: st.history_len }
    } else {
        PolicyNet::Mlp { obs_norm: pick(&s.obs_index), actor }
    })
}

/// `dextrain export` of a distilled student: inputs `obs` (the student's fields) and `history`.
fn export_student(args: &ExportArgs, cfg: &Config, cfg_path: &Path, ckpt: &Path, iteration: u64, model: &SimModel, setup: &crate::task::TaskSetup) -> Result<ExportReport> {
    let spec = &setup.spec;
    let mut s = StudentPolicy::load(ckpt, spec.obs_dim, &burn::prelude::Device::flex())?;
    let net = student_net(&s, spec.obs_dim)?;
    // the fields whose first entry the index lists, in the index's order
    let names_at = |idx: &[usize]| -> Vec<String> {
        let mut found: Vec<(usize, String)> = spec.obs_layout.iter().filter_map(|f| idx.iter().position(|&i| i == f.offset).map(|p| (p, f.name.clone()))).collect();
        found.sort();
        found.into_iter().map(|(_, n)| n).collect()
    };
    let obs_fields = names_at(&s.obs_index);
    let hist_fields = names_at(&s.hist_index);
    let bytes = onnx::to_onnx(&net, &metadata(spec, model, args, iteration))?;
    let batch = serde_json::Value::from("batch");
    let io = |name: &str, dims: Vec<serde_json::Value>, description: &str| TensorIo { name: name.into(), shape: dims, description: description.into() };
    let mut inputs = vec![io("obs", vec![batch.clone(), s.obs_index.len().into()], "the student's observation, raw values in `observation`'s layout")];
    if s.student.latent > 0 {
        inputs.push(io("history", vec![batch.clone(), s.student.history_len.into(), s.hist_index.len().into()], "the history window, raw values: `history` says its layout"));
    }
    let output = io("actions", vec![batch, spec.action_dim.into()], "the policy's action, before clipping and the action mapping");
    let src = ContractSource {
        source: Source {
            run: std::fs::canonicalize(&args.run).unwrap_or_else(|_| args.run.clone()).display().to_string(),
            checkpoint: iteration,
            checkpoint_xxh64: manifest_hash(ckpt)?,
            algorithm: "distill".into(),
            teacher: Some(contract::TeacherRef { run: s.teacher.0.clone(), checkpoint: s.teacher.1, checkpoint_xxh64: s.teacher.2.clone() }),
        },
        model_file: ONNX_FILE,
        model_bytes: &bytes,
        inputs,
        output,
        obs_fields,
        priv_fields: None,
        history: (s.student.latent > 0).then(|| (hist_fields, s.student.history_len)),
    };
    let c = contract::build(cfg, spec, &setup.tc, model, src)?;
    let out = args.out.clone().unwrap_or_else(|| args.run.join("export"));
    let world = std::fs::read(cfg_path).with_context(|| format!("cannot read {}", cfg_path.display()))?;
    write_export(&out, &bytes, &c, &world)?;
    let mut report = ExportReport { dir: out.display().to_string(), checkpoint: ckpt.display().to_string(), verified_rows: None, max_abs_diff: None };
    if args.verify {
        let (rows, diff) = verify_student(cfg, &mut s, &bytes)?;
        check_verified(&mut report, rows, diff)?;
    }
    Ok(report)
}

/// `--verify` for a student: real episodes driven by the burn student (its history windows kept
/// as the contract says), then the ONNX model on the same raw inputs.
fn verify_student(cfg: &Config, s: &mut StudentPolicy, bytes: &[u8]) -> Result<(usize, f64)> {
    let mut task = verify_task(cfg)?;
    let spec = task.spec().clone();
    let (n, o) = (16, spec.obs_dim);
    let mut obs = task.reset_all()?.obs.clone();
    let mut start = vec![true; n];
    let (mut obs_rows, mut hist_rows, mut burn) = (Vec::new(), Vec::new(), Vec::new());
    for _ in 0..spec.episode_length {
        let a = s.act_mean(&obs, &start)?;
        obs_rows.extend(s.student_obs(&obs, o));
        hist_rows.extend_from_slice(&s.window);
        burn.extend_from_slice(&a);
        if burn.len() / spec.action_dim >= VERIFY_ROWS {
            break;
        }
        let b = task.step(&a)?;
        for (i, st) in start.iter_mut().enumerate() {
            *st = b.done(i);
        }
        obs = b.obs.clone();
    }
    let rows = burn.len() / spec.action_dim;
    let hist: &[f32] = if s.student.latent > 0 { &hist_rows } else { &[] };
    let ours = onnx::run_onnx(bytes, &obs_rows, &[], hist, rows)?;
    ensure!(ours.len() == burn.len(), "--verify: the ONNX model gave {} numbers for {} expected", ours.len(), burn.len());
    let diff = max_abs_diff(&ours, &burn);
    Ok((rows, diff))
}
