//! Checkpoints: everything a resumed run needs to continue exactly where it stopped.
//!
//! `runs/NAME/checkpoints/<iteration>/` holds
//! - `model.safetensors`: the actor and critic parameters (`actor.0.weight` [in, out], …, `log_std`
//!   [1, A], `critic.…`) in f32, and the observation normalisers (`obs_norm.mean`, `obs_norm.m2`,
//!   `priv_norm.…`: mean, m2, count, eps; f64); the metadata key `dextrain` holds the dims and activation;
//! - `optimizer.safetensors`: Adam's moments `adam.m.<param>`, `adam.v.<param>` (f32);
//! - `env.safetensors`: the env batch's full state (`task_state`, raw bytes), the last observations
//!   (`obs`, `priv_obs`) and the per-env episode accumulators (`ep_return`, `ep_len`, f64);
//! - `state.json`: iteration, env steps, wall time so far, learning rate, Adam's step count and the
//!   learner RNG's state.
//!
//! A checkpoint is written into `checkpoints/.tmp-<iteration>` and renamed into place, so a crash
//! never leaves a half-written checkpoint under a real name.

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, anyhow, bail, ensure};
use safetensors::{Dtype, SafeTensors, tensor::TensorView};
use serde::{Deserialize, Serialize};

use crate::learn::nets::{to_host, to_tensor};
use crate::learn::normalizer::Normalizer;
use crate::learn::ppo::Ppo;

/// Counters and scalars of a checkpoint (`state.json`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CheckpointState {
    /// Iterations completed.
    pub iteration: u64,
    /// Env steps (transitions of all envs) so far.
    pub env_steps: u64,
    /// Wall time of training so far (s).
    pub time_s: f64,
    pub learning_rate: f64,
    pub adam_step: u64,
    /// The learner RNG's state (hex, so JSON keeps all 64 bits).
    pub rng_state: String,
    pub obs_dim: usize,
    pub priv_dim: usize,
    pub action_dim: usize,
}

/// The trainer's env-side state saved with a checkpoint.
#[derive(Clone, Debug, PartialEq)]
pub struct EnvSnapshot {
    /// The task batch's own state (`TaskBatch::save_state`).
    pub task_state: Vec<u8>,
    /// The current (raw) observations [N, O] and [N, P].
    pub obs: Vec<f32>,
    pub priv_obs: Vec<f32>,
    /// Return and length so far of each env's running episode.
    pub ep_return: Vec<f64>,
    pub ep_len: Vec<f64>,
}

enum Values {
    F32(Vec<f32>),
    F64(Vec<f64>),
    U8(Vec<u8>),
}

fn write_tensors(path: &Path, tensors: Vec<(String, Vec<usize>, Values)>, meta: HashMap<String, String>) -> Result<()> {
    let bytes: Vec<(String, Vec<usize>, Dtype, Vec<u8>)> = tensors
        .into_iter()
        .map(|(name, shape, v)| {
            let (dtype, b) = match v {
                Values::F32(x) => (Dtype::F32, x.iter().flat_map(|f| f.to_le_bytes()).collect()),
                Values::F64(x) => (Dtype::F64, x.iter().flat_map(|f| f.to_le_bytes()).collect()),
                Values::U8(x) => (Dtype::U8, x),
            };
            (name, shape, dtype, b)
        })
        .collect();
    let views: Vec<(String, TensorView<'_>)> = bytes
        .iter()
        .map(|(n, s, d, b)| TensorView::new(*d, s.clone(), b).map(|v| (n.clone(), v)).map_err(|e| anyhow!("tensor {n}: {e}")))
        .collect::<Result<_>>()?;
    let data = safetensors::serialize(views, Some(meta)).map_err(|e| anyhow!("cannot serialise {}: {e}", path.display()))?;
    std::fs::write(path, data).with_context(|| format!("cannot write {}", path.display()))
}

/// A read safetensors file.
struct TensorsIn {
    path: PathBuf,
    bytes: Vec<u8>,
}

impl TensorsIn {
    fn open(path: &Path) -> Result<TensorsIn> {
        let bytes = std::fs::read(path).with_context(|| format!("cannot read checkpoint file {}", path.display()))?;
        SafeTensors::deserialize(&bytes).map_err(|e| anyhow!("{}: not a valid safetensors file ({e})", path.display()))?;
        Ok(TensorsIn { path: path.to_path_buf(), bytes })
    }

    fn st(&self) -> SafeTensors<'_> {
        // checked in open()
        SafeTensors::deserialize(&self.bytes).expect("validated in open")
    }

    fn raw(&self, name: &str, dtype: Dtype, len: Option<usize>) -> Result<Vec<u8>> {
        let st = self.st();
        let t = st.tensor(name).map_err(|_| anyhow!("{}: tensor `{name}` is missing", self.path.display()))?;
        if t.dtype() != dtype {
            bail!("{}: tensor `{name}` is {:?}, expected {dtype:?}", self.path.display(), t.dtype());
        }
        let n: usize = t.shape().iter().product();
        if let Some(len) = len
            && n != len
        {
            bail!("{}: tensor `{name}` has {n} values, expected {len} (a checkpoint of another config?)", self.path.display());
        }
        Ok(t.data().to_vec())
    }

    fn f32s(&self, name: &str, len: Option<usize>) -> Result<Vec<f32>> {
        Ok(self.raw(name, Dtype::F32, len)?.chunks_exact(4).map(|c| f32::from_le_bytes(c.try_into().expect("4 bytes"))).collect())
    }

    fn f64s(&self, name: &str, len: Option<usize>) -> Result<Vec<f64>> {
        Ok(self.raw(name, Dtype::F64, len)?.chunks_exact(8).map(|c| f64::from_le_bytes(c.try_into().expect("8 bytes"))).collect())
    }
}

fn norm_tensors(prefix: &str, n: &Normalizer, out: &mut Vec<(String, Vec<usize>, Values)>) {
    out.push((format!("{prefix}.mean"), vec![n.dim()], Values::F64(n.mean.clone())));
    out.push((format!("{prefix}.m2"), vec![n.dim()], Values::F64(n.m2.clone())));
    out.push((format!("{prefix}.count"), vec![1], Values::F64(vec![n.count])));
    out.push((format!("{prefix}.eps"), vec![1], Values::F64(vec![n.eps])));
}

fn read_norm(f: &TensorsIn, prefix: &str, dim: usize) -> Result<Normalizer> {
    Ok(Normalizer {
        count: f.f64s(&format!("{prefix}.count"), Some(1))?[0],
        mean: f.f64s(&format!("{prefix}.mean"), Some(dim))?,
        m2: f.f64s(&format!("{prefix}.m2"), Some(dim))?,
        eps: f.f64s(&format!("{prefix}.eps"), Some(1))?[0],
    })
}

/// Writes the policy (parameters + normalisers) to `path` (safetensors).
pub fn save_model(path: &Path, ppo: &Ppo) -> Result<()> {
    let names = ppo.net.names();
    let shapes = ppo.net.shapes();
    let values = ppo.net.values()?;
    let mut tensors: Vec<(String, Vec<usize>, Values)> =
        names.into_iter().zip(shapes).zip(values).map(|((n, s), v)| (n, s.to_vec(), Values::F32(v))).collect();
    norm_tensors("obs_norm", &ppo.obs_norm, &mut tensors);
    norm_tensors("priv_norm", &ppo.priv_norm, &mut tensors);
    let d = ppo.dims();
    // one metadata key (a HashMap of several would serialise in a random order, and checkpoints
    // of identical runs must be identical files)
    let info = serde_json::json!({
        "format": "dextrain.policy.v1",
        "obs_dim": d.obs,
        "priv_dim": d.priv_obs,
        "action_dim": d.act,
        "activation": format!("{:?}", ppo.net.activation).to_lowercase(),
        "obs_normalization": ppo.normalize,
    });
    write_tensors(path, tensors, HashMap::from([("dextrain".to_string(), info.to_string())]))
}

/// Loads parameters and normalisers saved by [`save_model`] into `ppo` (same config).
pub fn load_model(path: &Path, ppo: &mut Ppo) -> Result<()> {
    let f = TensorsIn::open(path)?;
    let names = ppo.net.names();
    let shapes = ppo.net.shapes();
    let mut values = Vec::with_capacity(names.len());
    for (n, s) in names.iter().zip(&shapes) {
        values.push(f.f32s(n, Some(s[0] * s[1]))?);
    }
    let device = ppo.device.clone();
    ppo.net.set_values(values, &device)?;
    let d = ppo.dims();
    ppo.obs_norm = read_norm(&f, "obs_norm", d.obs)?;
    ppo.priv_norm = read_norm(&f, "priv_norm", d.priv_obs)?;
    Ok(())
}

/// Writes a whole checkpoint atomically into `dir/<iteration>/`; returns its path.
pub fn save(dir: &Path, state: &CheckpointState, ppo: &Ppo, env: &EnvSnapshot) -> Result<PathBuf> {
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let final_dir = dir.join(state.iteration.to_string());
    let tmp = dir.join(format!(".tmp-{}", state.iteration));
    if tmp.exists() {
        std::fs::remove_dir_all(&tmp).with_context(|| format!("cannot remove {}", tmp.display()))?;
    }
    std::fs::create_dir_all(&tmp).with_context(|| format!("cannot create {}", tmp.display()))?;
    save_model(&tmp.join("model.safetensors"), ppo)?;
    let names = ppo.net.names();
    let shapes = ppo.net.shapes();
    let mut opt = Vec::new();
    for (i, (n, s)) in names.iter().zip(&shapes).enumerate() {
        opt.push((format!("adam.m.{n}"), s.to_vec(), Values::F32(to_host(ppo.adam.m[i].clone())?)));
        opt.push((format!("adam.v.{n}"), s.to_vec(), Values::F32(to_host(ppo.adam.v[i].clone())?)));
    }
    write_tensors(&tmp.join("optimizer.safetensors"), opt, HashMap::new())?;
    let n = env.ep_return.len();
    let envt = vec![
        ("task_state".to_string(), vec![env.task_state.len()], Values::U8(env.task_state.clone())),
        ("obs".to_string(), vec![n, env.obs.len() / n.max(1)], Values::F32(env.obs.clone())),
        ("priv_obs".to_string(), vec![n, env.priv_obs.len() / n.max(1)], Values::F32(env.priv_obs.clone())),
        ("ep_return".to_string(), vec![n], Values::F64(env.ep_return.clone())),
        ("ep_len".to_string(), vec![n], Values::F64(env.ep_len.clone())),
    ];
    write_tensors(&tmp.join("env.safetensors"), envt, HashMap::new())?;
    let json = serde_json::to_string_pretty(state).context("cannot serialise the checkpoint state")?;
    std::fs::write(tmp.join("state.json"), json).with_context(|| format!("cannot write {}", tmp.join("state.json").display()))?;
    if final_dir.exists() {
        std::fs::remove_dir_all(&final_dir).with_context(|| format!("cannot replace {}", final_dir.display()))?;
    }
    std::fs::rename(&tmp, &final_dir).with_context(|| format!("cannot rename {} to {}", tmp.display(), final_dir.display()))?;
    Ok(final_dir)
}

/// Reads `state.json` of a checkpoint directory.
pub fn read_state(ckpt: &Path) -> Result<CheckpointState> {
    let p = ckpt.join("state.json");
    let text = std::fs::read_to_string(&p).with_context(|| format!("cannot read checkpoint file {}", p.display()))?;
    serde_json::from_str(&text).map_err(|e| anyhow!("{}: not a dextrain checkpoint state ({e})", p.display()))
}

/// Restores the learner (model, normalisers, Adam, learning rate, RNG) and returns the counters and
/// the env snapshot.
pub fn load(ckpt: &Path, ppo: &mut Ppo) -> Result<(CheckpointState, EnvSnapshot)> {
    let state = read_state(ckpt)?;
    let d = ppo.dims();
    ensure!(
        (state.obs_dim, state.priv_dim, state.action_dim) == (d.obs, d.priv_obs, d.act),
        "{}: the checkpoint has obs/priv/action sizes {}/{}/{} but the config gives {}/{}/{}",
        ckpt.display(),
        state.obs_dim,
        state.priv_dim,
        state.action_dim,
        d.obs,
        d.priv_obs,
        d.act
    );
    load_model(&ckpt.join("model.safetensors"), ppo)?;
    let f = TensorsIn::open(&ckpt.join("optimizer.safetensors"))?;
    let names = ppo.net.names();
    let shapes = ppo.net.shapes();
    for (i, (n, s)) in names.iter().zip(&shapes).enumerate() {
        ppo.adam.m[i] = to_tensor(f.f32s(&format!("adam.m.{n}"), Some(s[0] * s[1]))?, *s, &ppo.device).inner();
        ppo.adam.v[i] = to_tensor(f.f32s(&format!("adam.v.{n}"), Some(s[0] * s[1]))?, *s, &ppo.device).inner();
    }
    ppo.adam.t = state.adam_step;
    ppo.lr = state.learning_rate;
    ppo.rng.state = u64::from_str_radix(state.rng_state.trim_start_matches("0x"), 16)
        .map_err(|_| anyhow!("{}: `rng_state` = {:?} is not a hex u64", ckpt.join("state.json").display(), state.rng_state))?;
    let e = TensorsIn::open(&ckpt.join("env.safetensors"))?;
    let n = ppo.storage.envs;
    let env = EnvSnapshot {
        task_state: e.raw("task_state", Dtype::U8, None)?,
        obs: e.f32s("obs", Some(n * d.obs))?,
        priv_obs: e.f32s("priv_obs", Some(n * d.priv_obs))?,
        ep_return: e.f64s("ep_return", Some(n))?,
        ep_len: e.f64s("ep_len", Some(n))?,
    };
    Ok((state, env))
}

/// Checkpoint directories of a run, oldest first: (iteration, path).
pub fn list(run_dir: &Path) -> Result<Vec<(u64, PathBuf)>> {
    let dir = run_dir.join("checkpoints");
    let mut out = BTreeMap::new();
    let rd = match std::fs::read_dir(&dir) {
        Ok(rd) => rd,
        Err(_) => return Ok(Vec::new()),
    };
    for e in rd {
        let e = e.with_context(|| format!("cannot list {}", dir.display()))?;
        if let Some(it) = e.file_name().to_str().and_then(|s| s.parse::<u64>().ok())
            && e.path().join("state.json").exists()
        {
            out.insert(it, e.path());
        }
    }
    Ok(out.into_iter().collect())
}

/// The checkpoint `which` ("latest" or an iteration number) of a run.
pub fn find(run_dir: &Path, which: &str) -> Result<PathBuf> {
    let all = list(run_dir)?;
    if all.is_empty() {
        bail!("{}: the run has no checkpoints (expected {}/<iteration>/state.json)", run_dir.display(), run_dir.join("checkpoints").display());
    }
    if which == "latest" {
        return Ok(all.last().expect("non-empty").1.clone());
    }
    let it: u64 = which.parse().map_err(|_| anyhow!("--checkpoint {which:?}: expected \"latest\" or an iteration number"))?;
    all.iter().find(|(i, _)| *i == it).map(|(_, p)| p.clone()).ok_or_else(|| {
        let have: Vec<String> = all.iter().map(|(i, _)| i.to_string()).collect();
        anyhow!("{}: no checkpoint of iteration {it} (have: {})", run_dir.display(), have.join(", "))
    })
}
