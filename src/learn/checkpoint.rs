//! Checkpoints: everything a resumed run needs to continue exactly where it stopped, written so that
//! a crash or a damaged file is noticed instead of resumed from.
//!
//! `runs/NAME/checkpoints/<iteration>/` holds
//! - one `<file>.safetensors` per file of the learner's state ([`LearnerState`], handed over by the
//!   algorithm): for PPO `model.safetensors` (the actor and critic parameters `actor.0.weight`
//!   [in, out], …, `log_std` [1, A], `critic.…` in f32, and the observation normalisers
//!   `obs_norm.*`, `priv_norm.*`: mean, m2, count, eps in f64; the metadata key `dextrain` holds the
//!   dims and activation) and `optimizer.safetensors` (Adam's moments `adam.m.<param>`,
//!   `adam.v.<param>`, f32);
//! - `env.safetensors`: the env batch's full state (`task_state`, raw bytes), the last observations
//!   (`obs`, `priv_obs`) and the per-env episode accumulators (`ep_return`, `ep_len`, f64);
//! - `state.json`: the runner's counters (iteration, env steps, wall time so far, sizes) and the
//!   learner's scalars (PPO: learning rate, Adam's step count, the RNG's state); every f64 also as
//!   its exact bit pattern under `exact_f64`, so that a resumed run continues bit for bit;
//! - `manifest.json`, written last: the size and XXH64 hash of every other file.
//!
//! A checkpoint is written into `checkpoints/.tmp-<iteration>` and renamed into place, so a crash
//! never leaves a half-written checkpoint under a real name. [`find`] checks the manifest: the newest
//! checkpoint that fails (damaged, edited, incomplete, or from before manifests) is skipped with a
//! warning when "latest" is asked for, and is an error when asked for by number; resume and eval
//! both go through it.

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, anyhow, bail, ensure};
use safetensors::{Dtype, SafeTensors, tensor::TensorView};
use serde::{Deserialize, Serialize};

use crate::learn::ppo::{MODEL_FILE, Ppo};
use crate::learn::state::{LearnerState, NamedTensor, StateFile, TensorValues, hex64, parse_hex64};

/// The env-side file of a checkpoint (not part of the learner's state).
const ENV_FILE: &str = "env";
/// The manifest's file name.
pub const MANIFEST: &str = "manifest.json";
/// The manifest's format tag.
const MANIFEST_FORMAT: &str = "dextrain.checkpoint.manifest.v1";

/// Counters and scalars of a checkpoint (`state.json`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CheckpointState {
    /// Iterations completed.
    pub iteration: u64,
    /// Env steps (transitions of all envs) so far.
    pub env_steps: u64,
    /// Wall time of training so far (s).
    pub time_s: f64,
    /// Actor observation size of the run.
    pub obs_dim: usize,
    /// Critic observation size of the run.
    pub priv_dim: usize,
    /// Action size of the run.
    pub action_dim: usize,
    /// The learner's scalars (PPO: `learning_rate`, `adam_step`, `rng_state`).
    #[serde(flatten)]
    pub learner: BTreeMap<String, serde_json::Value>,
    /// Exact bit patterns (16 hex digits) of the f64 values above (`time_s` and the learner's).
    #[serde(default)]
    pub exact_f64: BTreeMap<String, String>,
}

impl CheckpointState {
    /// The counters of a checkpoint, with the learner's scalars of `learner` (time_s kept exactly).
    pub fn new(iteration: u64, env_steps: u64, time_s: f64, dims: [usize; 3], learner: &LearnerState) -> CheckpointState {
        let mut exact_f64 = learner.exact_f64.clone();
        exact_f64.insert("time_s".into(), hex64(time_s.to_bits()));
        CheckpointState {
            iteration,
            env_steps,
            time_s,
            obs_dim: dims[0],
            priv_dim: dims[1],
            action_dim: dims[2],
            learner: learner.scalars.clone(),
            exact_f64,
        }
    }

    /// Wall time so far, exactly as saved.
    pub fn exact_time_s(&self) -> f64 {
        self.exact_f64.get("time_s").and_then(|h| parse_hex64(h)).map(f64::from_bits).unwrap_or(self.time_s)
    }
}

/// The trainer's env-side state saved with a checkpoint.
#[derive(Clone, Debug, PartialEq)]
pub struct EnvSnapshot {
    /// The task batch's own state (`TaskBatch::save_state`).
    pub task_state: Vec<u8>,
    /// The current (raw) actor observations [N, O].
    pub obs: Vec<f32>,
    /// The current (raw) critic observations [N, P].
    pub priv_obs: Vec<f32>,
    /// Return so far of each env's running episode [N].
    pub ep_return: Vec<f64>,
    /// Length so far of each env's running episode [N].
    pub ep_len: Vec<f64>,
}

/// XXH64 (Yann Collet's xxHash, 64-bit) of `data` with `seed`: the checkpoint manifest's hash.
pub fn xxh64(data: &[u8], seed: u64) -> u64 {
    const P1: u64 = 0x9E37_79B1_85EB_CA87;
    const P2: u64 = 0xC2B2_AE3D_27D4_EB4F;
    const P3: u64 = 0x1656_67B1_9E37_79F9;
    const P4: u64 = 0x85EB_CA77_C2B2_AE63;
    const P5: u64 = 0x27D4_EB2F_1656_67C5;
    let round = |acc: u64, lane: u64| acc.wrapping_add(lane.wrapping_mul(P2)).rotate_left(31).wrapping_mul(P1); // acc = rotl(acc + lane·P2, 31)·P1
    let merge = |acc: u64, v: u64| (acc ^ round(0, v)).wrapping_mul(P1).wrapping_add(P4); // acc = (acc ^ round(0, v))·P1 + P4
    let u64_at = |b: &[u8]| u64::from_le_bytes(b[..8].try_into().expect("8 bytes"));
    let mut rest = data;
    let mut h = if data.len() >= 32 {
        let mut v = [seed.wrapping_add(P1).wrapping_add(P2), seed.wrapping_add(P2), seed, seed.wrapping_sub(P1)];
        while rest.len() >= 32 {
            for (k, acc) in v.iter_mut().enumerate() {
                *acc = round(*acc, u64_at(&rest[8 * k..]));
            }
            rest = &rest[32..];
        }
        let mut h = v[0].rotate_left(1).wrapping_add(v[1].rotate_left(7)).wrapping_add(v[2].rotate_left(12)).wrapping_add(v[3].rotate_left(18));
        for x in v {
            h = merge(h, x);
        }
        h
    } else {
        seed.wrapping_add(P5)
    };
    h = h.wrapping_add(data.len() as u64);
    while rest.len() >= 8 {
        h = (h ^ round(0, u64_at(rest))).rotate_left(27).wrapping_mul(P1).wrapping_add(P4);
        rest = &rest[8..];
    }
    if rest.len() >= 4 {
        let lane = u32::from_le_bytes(rest[..4].try_into().expect("4 bytes")) as u64;
        h = (h ^ lane.wrapping_mul(P1)).rotate_left(23).wrapping_mul(P2).wrapping_add(P3);
        rest = &rest[4..];
    }
    for &b in rest {
        h = (h ^ (b as u64).wrapping_mul(P5)).rotate_left(11).wrapping_mul(P1);
    }
    // avalanche
    h ^= h >> 33;
    h = h.wrapping_mul(P2);
    h ^= h >> 29;
    h = h.wrapping_mul(P3);
    h ^ (h >> 32)
}

/// One file's entry in `manifest.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
struct ManifestEntry {
    bytes: u64,
    /// XXH64 (seed 0) of the file's bytes, 16 hex digits.
    xxh64: String,
}

/// `manifest.json`: every file of the checkpoint with its size and hash.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
struct Manifest {
    format: String,
    files: BTreeMap<String, ManifestEntry>,
}

/// Writes `bytes` to `dir/name` and records it in `manifest`.
fn write_file(dir: &Path, name: &str, bytes: &[u8], manifest: &mut Manifest) -> Result<()> {
    let path = dir.join(name);
    std::fs::write(&path, bytes).with_context(|| format!("cannot write {}", path.display()))?;
    manifest.files.insert(name.to_string(), ManifestEntry { bytes: bytes.len() as u64, xxh64: hex64(xxh64(bytes, 0)) });
    Ok(())
}

/// A state file as safetensors bytes (the metadata key `dextrain` holds `info`, when there is one:
/// one key, as a HashMap of several would serialise in a random order, and checkpoints of identical
/// runs must be identical files).
fn safetensors_bytes(file: &StateFile) -> Result<Vec<u8>> {
    let bytes: Vec<(&str, &[usize], Dtype, Vec<u8>)> = file
        .tensors
        .iter()
        .map(|t| {
            let (dtype, b) = match &t.values {
                TensorValues::F32(x) => (Dtype::F32, x.iter().flat_map(|f| f.to_le_bytes()).collect()),
                TensorValues::F64(x) => (Dtype::F64, x.iter().flat_map(|f| f.to_le_bytes()).collect()),
                TensorValues::U8(x) => (Dtype::U8, x.clone()),
            };
            (t.name.as_str(), t.shape.as_slice(), dtype, b)
        })
        .collect();
    let views: Vec<(String, TensorView<'_>)> = bytes
        .iter()
        .map(|(n, s, d, b)| TensorView::new(*d, s.to_vec(), b).map(|v| (n.to_string(), v)).map_err(|e| anyhow!("tensor {n}: {e}")))
        .collect::<Result<_>>()?;
    let meta: HashMap<String, String> = file.info.iter().map(|i| ("dextrain".to_string(), i.clone())).collect();
    safetensors::serialize(views, Some(meta)).map_err(|e| anyhow!("cannot serialise {}.safetensors: {e}", file.name))
}

/// Reads a safetensors file into a state file named `name` (every tensor, in file order).
fn read_state_file(path: &Path, name: &str) -> Result<StateFile> {
    let bytes = std::fs::read(path).with_context(|| format!("cannot read checkpoint file {}", path.display()))?;
    let st = SafeTensors::deserialize(&bytes).map_err(|e| anyhow!("{}: not a valid safetensors file ({e})", path.display()))?;
    let (_, meta) = SafeTensors::read_metadata(&bytes).map_err(|e| anyhow!("{}: not a valid safetensors file ({e})", path.display()))?;
    let info = meta.metadata().as_ref().and_then(|m| m.get("dextrain").cloned());
    let mut tensors = Vec::new();
    for (tname, t) in st.tensors() {
        let d = t.data();
        let values = match t.dtype() {
            Dtype::F32 => TensorValues::F32(d.chunks_exact(4).map(|c| f32::from_le_bytes(c.try_into().expect("4 bytes"))).collect()),
            Dtype::F64 => TensorValues::F64(d.chunks_exact(8).map(|c| f64::from_le_bytes(c.try_into().expect("8 bytes"))).collect()),
            Dtype::U8 => TensorValues::U8(d.to_vec()),
            other => bail!("{}: tensor `{tname}` is {other:?}, expected F32, F64 or U8", path.display()),
        };
        tensors.push(NamedTensor { name: tname, shape: t.shape().to_vec(), values });
    }
    Ok(StateFile { name: name.to_string(), info, tensors })
}

/// Writes the policy of `ppo` (parameters + normalisers) to `path` (safetensors).
pub fn save_model(path: &Path, ppo: &Ppo) -> Result<()> {
    let mut state = LearnerState::default();
    ppo.save_policy(&mut state)?;
    let file = state.file(MODEL_FILE).context("the policy wrote no model file")?;
    std::fs::write(path, safetensors_bytes(file)?).with_context(|| format!("cannot write {}", path.display()))
}

/// One learner file of a checkpoint (e.g. `model.safetensors` named `model`) as a [`LearnerState`].
pub fn read_learner_file(path: &Path, name: &str) -> Result<LearnerState> {
    Ok(LearnerState { files: vec![read_state_file(path, name)?], ..Default::default() })
}

/// Loads parameters and normalisers saved by [`save_model`] (or a checkpoint's `model.safetensors`)
/// into `ppo` (same config). Errors name the file.
pub fn load_model(path: &Path, ppo: &mut Ppo) -> Result<()> {
    let file = read_state_file(path, MODEL_FILE)?;
    let state = LearnerState { files: vec![file], ..Default::default() };
    ppo.load_policy(&state).with_context(|| format!("{}", path.display()))
}

/// Writes a whole checkpoint atomically into `dir/<iteration>/`: the learner's files, the env
/// snapshot, `state.json`, and last `manifest.json`; returns its path.
pub fn save(dir: &Path, state: &CheckpointState, learner: &LearnerState, env: &EnvSnapshot) -> Result<PathBuf> {
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let final_dir = dir.join(state.iteration.to_string());
    let tmp = dir.join(format!(".tmp-{}", state.iteration));
    if tmp.exists() {
        std::fs::remove_dir_all(&tmp).with_context(|| format!("cannot remove {}", tmp.display()))?;
    }
    std::fs::create_dir_all(&tmp).with_context(|| format!("cannot create {}", tmp.display()))?;
    let mut manifest = Manifest { format: MANIFEST_FORMAT.into(), files: BTreeMap::new() };
    for f in &learner.files {
        ensure!(f.name != ENV_FILE, "a learner state file may not be called `{ENV_FILE}`");
        write_file(&tmp, &format!("{}.safetensors", f.name), &safetensors_bytes(f)?, &mut manifest)?;
    }
    let n = env.ep_return.len();
    let mut envf = StateFile { name: ENV_FILE.into(), ..Default::default() };
    let mut push = |name: &str, shape: Vec<usize>, values| envf.tensors.push(NamedTensor { name: name.into(), shape, values });
    push("task_state", vec![env.task_state.len()], TensorValues::U8(env.task_state.clone()));
    push("obs", vec![n, env.obs.len() / n.max(1)], TensorValues::F32(env.obs.clone())); // [N, O]
    push("priv_obs", vec![n, env.priv_obs.len() / n.max(1)], TensorValues::F32(env.priv_obs.clone())); // [N, P]
    push("ep_return", vec![n], TensorValues::F64(env.ep_return.clone()));
    push("ep_len", vec![n], TensorValues::F64(env.ep_len.clone()));
    write_file(&tmp, "env.safetensors", &safetensors_bytes(&envf)?, &mut manifest)?;
    let json = serde_json::to_string_pretty(state).context("cannot serialise the checkpoint state")?;
    write_file(&tmp, "state.json", json.as_bytes(), &mut manifest)?;
    // last: a checkpoint without a manifest is incomplete
    let json = serde_json::to_string_pretty(&manifest).context("cannot serialise the checkpoint manifest")?;
    std::fs::write(tmp.join(MANIFEST), json).with_context(|| format!("cannot write {}", tmp.join(MANIFEST).display()))?;
    if final_dir.exists() {
        std::fs::remove_dir_all(&final_dir).with_context(|| format!("cannot replace {}", final_dir.display()))?;
    }
    std::fs::rename(&tmp, &final_dir).with_context(|| format!("cannot rename {} to {}", tmp.display(), final_dir.display()))?;
    Ok(final_dir)
}

/// Checks a checkpoint against its manifest: every listed file has its size and XXH64, the files a
/// checkpoint needs (`model.safetensors`, `env.safetensors`, `state.json`) are listed, and
/// `state.json`'s iteration is the directory's name. The error names the file and what is wrong.
pub fn verify(ckpt: &Path) -> Result<()> {
    let mpath = ckpt.join(MANIFEST);
    let text = std::fs::read_to_string(&mpath)
        .map_err(|_| anyhow!("{}: missing, so the checkpoint is incomplete (interrupted while written, or written before checkpoints had manifests)", mpath.display()))?;
    let m: Manifest = serde_json::from_str(&text).map_err(|e| anyhow!("{}: not a checkpoint manifest ({e})", mpath.display()))?;
    ensure!(m.format == MANIFEST_FORMAT, "{}: `format` is {:?}, expected {MANIFEST_FORMAT:?}", mpath.display(), m.format);
    for need in [format!("{MODEL_FILE}.safetensors"), format!("{ENV_FILE}.safetensors"), "state.json".to_string()] {
        ensure!(m.files.contains_key(&need), "{}: does not list {need}, so the checkpoint is incomplete", mpath.display());
    }
    for (name, e) in &m.files {
        ensure!(!name.contains('/') && !name.contains('\\') && !name.starts_with('.'), "{}: file name {name:?} is not a plain file name", mpath.display());
        let p = ckpt.join(name);
        let bytes = std::fs::read(&p).map_err(|err| anyhow!("{}: cannot read ({err}), so the checkpoint is incomplete", p.display()))?;
        ensure!(bytes.len() as u64 == e.bytes, "{}: {} bytes, but the manifest says {} (damaged or edited)", p.display(), bytes.len(), e.bytes);
        let h = hex64(xxh64(&bytes, 0));
        ensure!(h == e.xxh64, "{}: content hash {h} does not match the manifest's {} (damaged or edited)", p.display(), e.xxh64);
    }
    let st = read_state(ckpt)?;
    let name = ckpt.file_name().and_then(|n| n.to_str()).unwrap_or("");
    ensure!(name == st.iteration.to_string(), "{}: `iteration` = {} but the checkpoint directory is {name:?}", ckpt.join("state.json").display(), st.iteration);
    Ok(())
}

/// Reads `state.json` of a checkpoint directory.
pub fn read_state(ckpt: &Path) -> Result<CheckpointState> {
    let p = ckpt.join("state.json");
    let text = std::fs::read_to_string(&p).with_context(|| format!("cannot read checkpoint file {}", p.display()))?;
    serde_json::from_str(&text).map_err(|e| anyhow!("{}: not a dextrain checkpoint state ({e})", p.display()))
}

/// Reads a checkpoint (checked against its manifest first): its counters, the learner's state (to
/// hand to the algorithm's `load_state`) and the env snapshot. `dims` = [obs, priv_obs, action]
/// and `num_envs` are the run's, checked against the checkpoint's.
pub fn load(ckpt: &Path, dims: [usize; 3], num_envs: usize) -> Result<(CheckpointState, LearnerState, EnvSnapshot)> {
    verify(ckpt)?;
    let state = read_state(ckpt)?;
    ensure!(
        [state.obs_dim, state.priv_dim, state.action_dim] == dims,
        "{}: the checkpoint has obs/priv/action sizes {}/{}/{} but the config gives {}/{}/{}",
        ckpt.display(),
        state.obs_dim,
        state.priv_dim,
        state.action_dim,
        dims[0],
        dims[1],
        dims[2]
    );
    let text = std::fs::read_to_string(ckpt.join(MANIFEST)).with_context(|| format!("cannot read {}", ckpt.join(MANIFEST).display()))?;
    let m: Manifest = serde_json::from_str(&text).map_err(|e| anyhow!("{}: not a checkpoint manifest ({e})", ckpt.join(MANIFEST).display()))?;
    let mut learner = LearnerState { scalars: state.learner.clone(), exact_f64: state.exact_f64.clone(), ..Default::default() };
    learner.exact_f64.remove("time_s");
    for name in m.files.keys() {
        if let Some(stem) = name.strip_suffix(".safetensors")
            && stem != ENV_FILE
        {
            learner.files.push(read_state_file(&ckpt.join(name), stem)?);
        }
    }
    let envf = read_state_file(&ckpt.join("env.safetensors"), ENV_FILE)?;
    let e = LearnerState { files: vec![envf], ..Default::default() };
    let env = (|| -> Result<EnvSnapshot> {
        Ok(EnvSnapshot {
            task_state: e.bytes(ENV_FILE, "task_state")?,
            obs: e.f32s(ENV_FILE, "obs", Some(num_envs * dims[0]))?,
            priv_obs: e.f32s(ENV_FILE, "priv_obs", Some(num_envs * dims[1]))?,
            ep_return: e.f64s(ENV_FILE, "ep_return", Some(num_envs))?,
            ep_len: e.f64s(ENV_FILE, "ep_len", Some(num_envs))?,
        })
    })()
    .with_context(|| format!("{}", ckpt.display()))?;
    Ok((state, learner, env))
}

/// Checkpoint directories of a run, oldest first: (iteration, path). Every directory named by a
/// number is listed, whole or not ([`verify`] tells).
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
            && e.path().is_dir()
        {
            out.insert(it, e.path());
        }
    }
    Ok(out.into_iter().collect())
}

/// The checkpoint `which` ("latest" or an iteration number) of a run, checked against its manifest.
/// "latest" is the newest checkpoint that passes; each newer one that fails is skipped with a
/// warning on stderr. A numbered checkpoint that fails is an error.
pub fn find(run_dir: &Path, which: &str) -> Result<PathBuf> {
    let all = list(run_dir)?;
    if all.is_empty() {
        // the way out: a run that never checkpointed has nothing to resume or evaluate
        bail!(
            "{}: the run has no checkpoints (expected {}/<iteration>/state.json): it stopped before its first; start it again with `dextrain train CONFIG --name NAME --force`, which replaces it",
            run_dir.display(),
            run_dir.join("checkpoints").display()
        );
    }
    if which == "latest" {
        let mut failures = Vec::new();
        for (_, p) in all.iter().rev() {
            match verify(p) {
                Ok(()) => return Ok(p.clone()),
                Err(e) => {
                    crate::console::warn(&format!("warning: skipping checkpoint {}: {}", p.display(), crate::text::one_line(&format!("{e:#}"))));
                    failures.push(format!("{e:#}"));
                }
            }
        }
        bail!("{}: no checkpoint passes its check (newest: {})", run_dir.display(), failures.first().map(String::as_str).unwrap_or("none"));
    }
    let it: u64 = which.parse().map_err(|_| anyhow!("--checkpoint {which:?}: expected \"latest\" or an iteration number"))?;
    let p = all.iter().find(|(i, _)| *i == it).map(|(_, p)| p.clone()).ok_or_else(|| {
        let have: Vec<String> = all.iter().map(|(i, _)| i.to_string()).collect();
        anyhow!("{}: no checkpoint of iteration {it} (have: {})", run_dir.display(), have.join(", "))
    })?;
    verify(&p).with_context(|| format!("checkpoint {} fails its check", p.display()))?;
    Ok(p)
}
