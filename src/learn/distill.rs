//! Teacher→student distillation by online DAgger (DexRefine; rsl_rl's `Distillation` with a latent
//! term and a β schedule).
//!
//! - The **teacher** is a PPO policy of another run (with a privileged encoder ẑ = μ(ê), or
//!   without), frozen and run deterministically on the very states the student visits: it labels
//!   every step with its action u (the policy mean) and latent ẑ.
//! - The **student** is the teacher's main actor (copied at the start; the first layer keeps the
//!   weight rows of the observation fields the student may read, `distill.student_obs`, and of the
//!   latent) fed by an adaptation module z = W_h · GRU(x_{t−H+1:t}) + b_h instead of the encoder.
//!   x_t = the history fields (`distill.history_fields`) of the actor observation, normalised with
//!   the teacher's (frozen) normaliser, like every student input.
//! - The history window `[N, H, D]` lives here, on the learner side, filled from the observations
//!   the envs return: at an episode's first step every row is that step's x (the first frame
//!   repeated H times), then the window shifts by one row per step (oldest first).
//! - Who acts: each env's episode is driven by the teacher with probability β (drawn at episode
//!   start), else by the student; β goes linearly from `beta_start` to `beta_end` over
//!   `beta_iterations`.
//! - Update: `L = λ1 mean‖û − u‖² + λ2 mean‖z − ẑ‖²` over the iteration's samples (or the last
//!   `max_rollouts` rollouts), `epochs` × `minibatches`, Adam, global gradient-norm clip.

use std::path::PathBuf;

use anyhow::{Context, Result, anyhow, bail, ensure};
use burn::prelude::*;
use burn::tensor::{Int, TensorData};

use super::adam::Adam;
use super::gru::{gru_forward, gru_shapes, init_gru};
use super::tcn::{init_tcn, tcn_forward, tcn_names, tcn_shapes};
use super::nets::{mlp_forward, to_host, to_tensor};
use super::ppo::Ppo;
use crate::rng::Rng;
use super::state::{LearnerState, TensorValues};
use crate::config::{AdaptationModule, Config, DatasetMode, StudentActor};
use crate::task::TaskSpec;
use crate::task::spec::{ObsSlot, field_indices};

/// The student's state file in a checkpoint (`model.safetensors`, the name every run's policy file has).
pub const STUDENT_FILE: &str = "model";
/// The optimiser's state file (`optimizer.safetensors`).
pub const OPTIMIZER_FILE: &str = "optimizer";
/// The metrics columns of a distillation update, in [`Distill::update`]'s order.
pub const STAT_COLUMNS: [&str; 9] = [
    "loss/action",
    "loss/latent",
    "distill/beta",
    "distill/student_success",
    "distill/teacher_success",
    "distill/student_return",
    "distill/teacher_return",
    crate::metrics::columns::GRAD_NORM,
    crate::metrics::columns::LR,
];

/// Checkpoint names of the GRU's parameters.
const GRU_NAMES: [&str; 4] = ["gru.w_ih", "gru.w_hh", "gru.b_ih", "gru.b_hh"];

/// The frozen teacher.
pub struct Teacher {
    /// Its policy (deterministic: the mean), normalisers included.
    pub ppo: Ppo,
    /// Its run directory and checkpoint.
    pub run: PathBuf,
    pub checkpoint: PathBuf,
    /// Its checkpoint's iteration and the XXH64 of its manifest.json.
    pub iteration: u64,
    pub manifest_xxh64: String,
    /// The size L of its latent (0 without an encoder).
    pub latent: usize,
}

/// The first field where two layouts differ, as "A vs B".
fn layout_difference(a: &[ObsSlot], b: &[ObsSlot]) -> Option<String> {
    let show = |s: Option<&ObsSlot>| s.map(|s| format!("{} ({} numbers)", s.name, s.size)).unwrap_or_else(|| "nothing".into());
    (0..a.len().max(b.len())).find_map(|k| {
        let (x, y) = (a.get(k), b.get(k));
        let same = matches!((x, y), (Some(x), Some(y)) if x.name == y.name && x.size == y.size && x.entries == y.entries);
        (!same).then(|| format!("field {k}: {} vs {}", show(x), show(y)))
    })
}

/// Loads the teacher of `cfg` (`[distill]`) for the task `spec`: its run and checkpoint (checked
/// against its manifest), and checks that it observes exactly what this task observes.
pub fn load_teacher(cfg: &Config, spec: &TaskSpec, device: &Device) -> Result<Teacher> {
    let file = cfg.source.display();
    let run = cfg.resolve(&cfg.distill.teacher);
    crate::run_dir::check_run(&run).map_err(|e| anyhow!("{file}: key `distill.teacher` = {:?}: {}", cfg.distill.teacher, crate::text::one_line(&format!("{e:#}"))))?;
    let tpath = run.join("config.toml");
    let tcfg = Config::load(&tpath)?;
    if tcfg.train.algorithm != crate::config::AlgorithmChoice::Ppo {
        bail!("{file}: key `distill.teacher`: the teacher {} was trained with train.algorithm = {:?}; expected a PPO run (DexRefine's teacher: a privileged encoder trained by PPO)", tpath.display(), tcfg.train.algorithm);
    }
    let tmodel = crate::env::SimModel::from_config(&tcfg)?;
    let tspec = crate::task::task_setup(&tcfg, &tmodel)?.spec;
    for (what, mine, theirs) in [("actor", &spec.obs_layout, &tspec.obs_layout), ("critic", &spec.priv_layout, &tspec.priv_layout)] {
        if let Some(d) = layout_difference(mine, theirs) {
            bail!("{file}: key `distill.teacher`: the teacher {} observes another {what} observation than this task ({d}, this task vs the teacher); expected a teacher of the same task kind and hand", tpath.display());
        }
    }
    ensure!(tspec.action_dim == spec.action_dim, "{file}: key `distill.teacher`: the teacher {} has {} actions, this task {}", tpath.display(), tspec.action_dim, spec.action_dim);
    let ckpt = crate::learn::checkpoint::find(&run, &cfg.distill.checkpoint)?;
    let state = crate::learn::checkpoint::read_state(&ckpt)?;
    let ppo = crate::learn::policy::load_ppo(&tcfg, spec, &ckpt, 1, device.clone(), tcfg.seed as u64).context("the teacher's policy")?;
    let manifest = std::fs::read(ckpt.join(crate::learn::checkpoint::MANIFEST)).with_context(|| format!("cannot read {}", ckpt.join(crate::learn::checkpoint::MANIFEST).display()))?;
    let latent = tcfg.policy.encoder.as_ref().map(|e| e.latent).unwrap_or(0);
    Ok(Teacher { ppo, run, checkpoint: ckpt, iteration: state.iteration, manifest_xxh64: format!("{:016x}", crate::learn::checkpoint::xxh64(&manifest, 0)), latent })
}

/// The student's adaptation module φ, beyond its parameters' shapes.
#[derive(Clone, Debug, PartialEq)]
pub enum Adaptation {
    /// A GRU (`gru.rs`): φ = its last hidden state.
    Gru,
    /// A temporal convolution (`tcn.rs`) with these convolutions (kernel, stride): φ = the flattened
    /// output.
    Tcn { convs: Vec<(usize, usize)> },
}

impl Adaptation {
    /// The name checkpoints and exports give it (`distill.adaptation`'s value).
    pub fn name(&self) -> &'static str {
        match self {
            Adaptation::Gru => "gru",
            Adaptation::Tcn { .. } => "tcn",
        }
    }
}

/// The student network: `[φ's parameters (GRU: 4; TCN: 4 + 2 per convolution), head weight [F, L],
/// head bias [1, L], actor layers…]` (F: φ's output size; no φ and head when the teacher has no
/// latent).
#[derive(Clone)]
pub struct Student {
    /// Autodiff leaves on the learner device.
    pub params: Vec<Tensor<2>>,
    /// Their shapes and checkpoint names.
    pub shapes: Vec<[usize; 2]>,
    pub names: Vec<String>,
    /// Parameters before the actor's (φ and the head).
    pub n_adapt: usize,
    /// φ's kind.
    pub adaptation: Adaptation,
    /// The actor's hidden activation.
    pub activation: crate::config::Activation,
    /// History steps H and numbers per step D; latent size L; student obs size.
    pub history_len: usize,
    pub step_dim: usize,
    pub latent: usize,
    pub obs_dim: usize,
}

impl Student {
    /// (z [B, L] or None, û [B, A]) for normalised student observations `obs` [B, O_s] and
    /// normalised history windows `hist` [B, H·D].
    pub fn forward(&self, params: &[Tensor<2>], obs: Tensor<2>, hist: Tensor<2>) -> (Option<Tensor<2>>, Tensor<2>) {
        if self.latent == 0 {
            return (None, mlp_forward(&params[self.n_adapt..], obs, self.activation));
        }
        let k = self.n_adapt;
        let f = match &self.adaptation {
            Adaptation::Gru => gru_forward(&params[..k - 2], hist, self.history_len), // [B, Hg]
            Adaptation::Tcn { convs } => tcn_forward(&params[..k - 2], hist, self.history_len, convs), // [B, T'·C]
        };
        let z = f.matmul(params[k - 2].clone()) + params[k - 1].clone(); // [B, L]: z = φ W_h + b_h
        let x = Tensor::cat(vec![obs, z.clone()], 1); // [B, O_s + L]
        (Some(z), mlp_forward(&params[self.n_adapt..], x, self.activation))
    }

    /// Every parameter's values on the host.
    pub fn values(&self) -> Result<Vec<Vec<f32>>> {
        self.params.iter().map(|p| to_host(p.clone().inner())).collect()
    }
}

/// One rollout's samples (host, row-major): normalised student obs, history windows, the teacher's
/// actions and latents.
#[derive(Clone, Default)]
struct Rollout {
    obs: Vec<f32>,
    hist: Vec<f32>,
    actions: Vec<f32>,
    latents: Vec<f32>,
}

/// Online DAgger: the teacher, the student, the history windows and the data.
pub struct Distill {
    pub cfg: crate::config::DistillConfig,
    pub device: Device,
    pub teacher: Teacher,
    pub student: Student,
    pub adam: Adam,
    /// Indices in the actor observation of the student's inputs and of one history step.
    pub obs_index: Vec<usize>,
    pub hist_index: Vec<usize>,
    /// Envs N, steps per iteration, actions A.
    pub num_envs: usize,
    pub steps: usize,
    pub act_dim: usize,
    /// Windows `[N, H, D]` of normalised history steps, oldest first.
    pub history: Vec<f32>,
    /// Envs whose next `act` is their episode's first step [N].
    pub episode_start: Vec<bool>,
    /// Envs whose current episode the teacher drives [N].
    pub teacher_drives: Vec<bool>,
    /// The running episodes' returns [N].
    pub ep_return: Vec<f64>,
    /// Iterations completed (β's clock).
    pub iteration: u64,
    pub rng: Rng,
    rollouts: Vec<Rollout>,
    current: Rollout,
    /// This iteration's ended episodes: (success, return) of the student's and of the teacher's.
    ended: [(u64, u64, f64); 2],
}

impl Distill {
    /// The distillation learner for `cfg` on the task `spec`.
    pub fn new(cfg: &Config, spec: &TaskSpec, num_envs: usize, device: Device) -> Result<Distill> {
        let d = &cfg.distill;
        let file = cfg.source.display();
        let teacher = load_teacher(cfg, spec, &device)?;
        let names_of = |l: &[ObsSlot]| l.iter().map(|s| s.name.clone()).collect::<Vec<String>>();
        let student_fields = if d.student_obs.is_empty() { names_of(&spec.obs_layout) } else { d.student_obs.clone() };
        let obs_index = field_indices(&spec.obs_layout, &student_fields).map_err(|m| anyhow!("{file}: key `distill.student_obs`: {m}"))?;
        let hist_index = field_indices(&spec.obs_layout, &d.history_fields).map_err(|m| anyhow!("{file}: key `distill.history_fields`: {m}"))?;
        let (h, dd, l) = (d.history_len as usize, hist_index.len(), teacher.latent);
        // the student's actor: the teacher's, its first layer's rows of the kept fields and the latent
        let t = &teacher.ppo.net;
        let tvalues = t.values()?;
        let n_actor = t.actor_shapes.len();
        let mut values: Vec<Vec<f32>> = Vec::new();
        let mut shapes: Vec<[usize; 2]> = Vec::new();
        let mut names: Vec<String> = Vec::new();
        let mut rng = Rng::new(cfg.seed as u64, 0xD157_1111);
        let adaptation = match d.adaptation {
            AdaptationModule::Gru => Adaptation::Gru,
            AdaptationModule::Tcn => Adaptation::Tcn { convs: d.tcn_convs() },
        };
        if l > 0 {
            // φ's parameters, and its output size F (the head's input)
            let (phi, phi_shapes, phi_names, f) = match &adaptation {
                Adaptation::Gru => (init_gru(dd, d.gru_hidden, &mut rng), gru_shapes(dd, d.gru_hidden), GRU_NAMES.map(String::from).to_vec(), d.gru_hidden),
                Adaptation::Tcn { convs } => {
                    let t = d.tcn_steps_out().ok_or_else(|| anyhow!("{file}: key `distill.tcn_layers`: the convolutions do not fit in distill.history_len = {h} steps"))?;
                    (init_tcn(dd, d.tcn_channels, convs, &mut rng), tcn_shapes(dd, d.tcn_channels, convs), tcn_names(convs.len()), t * d.tcn_channels)
                }
            };
            values.extend(phi);
            shapes.extend(phi_shapes);
            names.extend(phi_names);
            // the head: torch Linear initialisation U(±1/√F)
            let bound = 1.0 / (f as f64).sqrt();
            for (s, n) in [([f, l], "head.weight"), ([1, l], "head.bias")] {
                values.push((0..s[0] * s[1]).map(|_| ((2.0 * rng.uniform() - 1.0) * bound) as f32).collect());
                shapes.push(s);
                names.push(n.into());
            }
        }
        let n_adapt = values.len();
        for (k, (v, s)) in tvalues[..n_actor].iter().zip(&t.actor_shapes).enumerate() {
            let name = format!("actor.{}.{}", k / 2, if k % 2 == 0 { "weight" } else { "bias" });
            if k == 0 {
                // rows: the kept observation entries, then the latent's (the teacher's last L rows)
                let cols = s[1];
                let rows: Vec<usize> = obs_index.iter().copied().chain(spec.obs_dim..spec.obs_dim + l).collect();
                values.push(rows.iter().flat_map(|&r| v[r * cols..(r + 1) * cols].iter().copied()).collect());
                shapes.push([rows.len(), cols]);
            } else {
                values.push(v.clone());
                shapes.push(*s);
            }
            names.push(name);
        }
        // data-parallel (issue 37): every rank starts from rank 0's student
        for v in &mut values {
            crate::dist::broadcast_f32(v);
        }
        let params = values.into_iter().zip(&shapes).map(|(v, s)| to_tensor(v, *s, &device).autodiff().require_grad()).collect();
        let student = Student { params, shapes: shapes.clone(), names, n_adapt, adaptation, activation: t.activation, history_len: h, step_dim: dd, latent: l, obs_dim: obs_index.len() };
        let adam = Adam::new(&shapes, &device);
        if crate::dist::rank() > 0 {
            // who drives each episode (β) and the minibatch shuffles: a stream of each rank's own
            // (rank 0 keeps the one-process stream)
            rng = Rng::new(cfg.seed as u64, 0xD157_1111 + crate::dist::rank() as u64);
        }
        let mut teacher_drives = vec![false; num_envs];
        for x in &mut teacher_drives {
            *x = rng.uniform() < d.beta_start as f64;
        }
        Ok(Distill {
            cfg: d.clone(),
            device,
            teacher,
            student,
            adam,
            obs_index,
            hist_index,
            num_envs,
            steps: cfg.train.steps_per_env as usize,
            act_dim: spec.action_dim,
            history: vec![0.0; num_envs * h * dd],
            episode_start: vec![true; num_envs],
            teacher_drives,
            ep_return: vec![0.0; num_envs],
            iteration: 0,
            rng,
            rollouts: Vec::new(),
            current: Rollout::default(),
            ended: [(0, 0, 0.0); 2],
        })
    }

    /// β of the current iteration.
    pub fn beta(&self) -> f64 {
        let (a, b) = (self.cfg.beta_start as f64, self.cfg.beta_end as f64);
        let k = self.cfg.beta_iterations.max(1) as f64;
        // linear from β_start at iteration 0 to β_end at `beta_iterations`, then held
        a + (b - a) * (self.iteration as f64 / k).min(1.0)
    }

    /// The teacher's normalised observations.
    fn normalize(&self, obs: &[f32], priv_obs: &[f32]) -> (Vec<f32>, Vec<f32>) {
        let (mut o, mut p) = (obs.to_vec(), priv_obs.to_vec());
        if self.teacher.ppo.normalize {
            self.teacher.ppo.obs_norm.apply(&mut o);
            self.teacher.ppo.priv_norm.apply(&mut p);
        }
        (o, p)
    }

    /// Rows `idx` of each `width`-wide row of `x`.
    fn gather(x: &[f32], width: usize, idx: &[usize]) -> Vec<f32> {
        x.chunks(width).flat_map(|r| idx.iter().map(move |&i| r[i])).collect()
    }

    /// Pushes each env's current history step (episode start: fills its window with it).
    fn push_history(&mut self, obs_n: &[f32], width: usize) {
        let (h, d) = (self.student.history_len, self.student.step_dim);
        for i in 0..self.num_envs {
            let x: Vec<f32> = self.hist_index.iter().map(|&k| obs_n[i * width + k]).collect();
            let w = &mut self.history[i * h * d..(i + 1) * h * d];
            if self.episode_start[i] {
                for row in w.chunks_mut(d) {
                    row.copy_from_slice(&x);
                }
                self.episode_start[i] = false;
            } else {
                w.copy_within(d.., 0);
                w[(h - 1) * d..].copy_from_slice(&x);
            }
        }
    }

    /// The student's deterministic action [N, A] and latent for normalised inputs.
    fn student_act(&self, obs_s: &[f32], hist: &[f32], n: usize) -> Result<Vec<f32>> {
        let p: Vec<Tensor<2>> = self.student.params.iter().map(|p| p.clone().inner()).collect();
        let o = to_tensor(obs_s.to_vec(), [n, self.student.obs_dim], &self.device).inner();
        let hh = to_tensor(hist.to_vec(), [n, self.student.history_len * self.student.step_dim], &self.device).inner();
        let (_, u) = self.student.forward(&p, o.autodiff(), hh.autodiff());
        to_host(u.inner())
    }

    /// Acting during training: the teacher labels, the driver of each env's episode acts.
    pub fn act(&mut self, obs: &[f32], priv_obs: &[f32]) -> Result<Vec<f32>> {
        let n = self.num_envs;
        let o = obs.len() / n;
        let (obs_n, priv_n) = self.normalize(obs, priv_obs);
        self.push_history(&obs_n, o);
        let t = &self.teacher.ppo;
        let tp = t.net.inference_params();
        let x = to_tensor(obs_n.clone(), [n, o], &self.device);
        let c = to_tensor(priv_n.clone(), [n, priv_obs.len() / n], &self.device);
        let u = to_host(t.net.actor(&tp, x, c.clone()))?; // [N, A]
        let z_hat = match t.net.latent(&tp, c) {
            Some(z) => to_host(z)?,
            None => Vec::new(),
        };
        let obs_s = Self::gather(&obs_n, o, &self.obs_index);
        let mine = self.student_act(&obs_s, &self.history, n)?;
        let a = self.act_dim;
        let mut actions = mine;
        for i in 0..n {
            if self.teacher_drives[i] {
                actions[i * a..(i + 1) * a].copy_from_slice(&u[i * a..(i + 1) * a]);
            }
        }
        self.current.obs.extend_from_slice(&obs_s);
        self.current.hist.extend_from_slice(&self.history);
        self.current.actions.extend_from_slice(&u);
        self.current.latents.extend_from_slice(&z_hat);
        Ok(actions)
    }

    /// The outcome of the last step: episode bookkeeping and new drivers (β) for new episodes.
    pub fn observe(&mut self, reward: &[f32], terminated: &[bool], time_out: &[bool], success: &[bool]) {
        let beta = self.beta();
        for i in 0..self.num_envs {
            self.ep_return[i] += reward[i] as f64;
            if terminated[i] || time_out[i] {
                let k = self.teacher_drives[i] as usize;
                self.ended[k].0 += 1;
                self.ended[k].1 += success[i] as u64;
                self.ended[k].2 += self.ep_return[i];
                self.ep_return[i] = 0.0;
                self.episode_start[i] = true;
                self.teacher_drives[i] = self.rng.uniform() < beta;
            }
        }
    }

    /// The update at the iteration's end; returns [`STAT_COLUMNS`]' values.
    pub fn update(&mut self) -> Result<Vec<f64>> {
        let beta = self.beta();
        self.rollouts.push(std::mem::take(&mut self.current));
        let keep = match self.cfg.dataset {
            DatasetMode::Once => 1,
            DatasetMode::Aggregate => self.cfg.max_rollouts as usize,
        };
        while self.rollouts.len() > keep {
            self.rollouts.remove(0);
        }
        let cat = |f: fn(&Rollout) -> &Vec<f32>| self.rollouts.iter().flat_map(|r| f(r).iter().copied()).collect::<Vec<f32>>();
        let (obs, hist, acts, lats) = (cat(|r| &r.obs), cat(|r| &r.hist), cat(|r| &r.actions), cat(|r| &r.latents));
        let (os, hw, a, l) = (self.student.obs_dim, self.student.history_len * self.student.step_dim, self.act_dim, self.student.latent);
        let rows = acts.len() / a;
        let dev = self.device.clone();
        let all_obs = to_tensor(obs, [rows, os], &dev);
        let all_hist = to_tensor(hist, [rows, hw], &dev);
        let all_u = to_tensor(acts, [rows, a], &dev);
        let all_z = (l > 0).then(|| to_tensor(lats, [rows, l], &dev));
        let mb = (rows / self.cfg.minibatches as usize).max(1);
        let (mut la_sum, mut ll_sum, mut gn_sum, mut count) = (0.0f64, 0.0f64, 0.0f64, 0usize);
        for _ in 0..self.cfg.epochs {
            let perm = self.rng.permutation(rows);
            for m in 0..self.cfg.minibatches as usize {
                let idx: Vec<i64> = perm[m * mb..((m + 1) * mb).min(rows)].iter().map(|&i| i as i64).collect();
                if idx.is_empty() {
                    continue;
                }
                let k = idx.len();
                let idx = Tensor::<1, Int>::from_data(TensorData::new(idx, [k]), &dev);
                let pick = |t: &Tensor<2>| t.clone().select(0, idx.clone());
                let params = &self.student.params;
                let (z, u_hat) = self.student.forward(params, pick(&all_obs), pick(&all_hist));
                // λ1 mean (û − u)² + λ2 mean (z − ẑ)²
                let la = (u_hat - pick(&all_u)).square().mean();
                let ll = match (&z, &all_z) {
                    (Some(z), Some(zh)) => (z.clone() - pick(zh)).square().mean(),
                    _ => la.clone().mul_scalar(0.0),
                };
                let loss = la.clone().mul_scalar(self.cfg.lambda_action) + ll.clone().mul_scalar(self.cfg.lambda_latent);
                let s = to_host(Tensor::cat(vec![la.detach().inner(), ll.detach().inner()], 0))?;
                let grads = loss.backward();
                // a parameter outside the loss's graph (the actor when λ1 = 0) gets a zero gradient
                let mut gs: Vec<Tensor<2>> = params.iter().map(|p| p.grad(&grads).unwrap_or_else(|| p.clone().inner().zeros_like())).collect();
                if self.cfg.actor == StudentActor::Frozen {
                    for g in &mut gs[self.student.n_adapt..] {
                        *g = g.clone().zeros_like();
                    }
                }
                // data-parallel (issue 37): the gradients' mean over the ranks, each on its own envs'
                // samples (every rank has as many rows, so every rank takes this minibatch)
                let gs = super::adam::mean_over_ranks(gs)?;
                // global norm clip: coef = min(1, max / (‖g‖ + 1e-6))
                let norm = gs.iter().map(|g| to_host(super::nets::sum_all(g.clone().square())).map(|v| v[0] as f64)).sum::<Result<f64>>()?.sqrt();
                let coef = (self.cfg.max_grad_norm as f64 / (norm + 1e-6)).min(1.0);
                let gs = gs.into_iter().map(|g| g.mul_scalar(coef)).collect();
                self.student.params = self.adam.step(params, gs, self.cfg.learning_rate as f64);
                la_sum += s[0] as f64;
                ll_sum += s[1] as f64;
                gn_sum += norm;
                count += 1;
            }
        }
        let c = count.max(1) as f64;
        let rate = |k: usize| if self.ended[k].0 > 0 { self.ended[k].1 as f64 / self.ended[k].0 as f64 } else { f64::NAN };
        let ret = |k: usize| if self.ended[k].0 > 0 { self.ended[k].2 / self.ended[k].0 as f64 } else { f64::NAN };
        let stats = vec![la_sum / c, ll_sum / c, beta, rate(0), rate(1), ret(0), ret(1), gn_sum / c, self.cfg.learning_rate as f64];
        self.ended = [(0, 0, 0.0); 2];
        self.iteration += 1;
        Ok(stats)
    }

    /// The student's parameters, one after another (what the ranks of a data-parallel job must
    /// hold alike).
    pub fn student_values(&self) -> Result<Vec<f32>> {
        Ok(self.student.values()?.into_iter().flatten().collect())
    }

    /// Everything a resumed run needs: the student, Adam, the history windows and episode state,
    /// the RNG, the iteration, the kept rollouts (`aggregate`), and the teacher it came from.
    pub fn state(&self) -> Result<LearnerState> {
        let mut s = LearnerState::default();
        for ((n, sh), v) in self.student.names.iter().zip(&self.student.shapes).zip(self.student.values()?) {
            s.push_tensor(STUDENT_FILE, n, sh.to_vec(), TensorValues::F32(v));
        }
        let n = self.num_envs;
        s.push_tensor(STUDENT_FILE, "history", vec![n, self.student.history_len, self.student.step_dim], TensorValues::F32(self.history.clone()));
        let flags = |v: &[bool]| TensorValues::F32(v.iter().map(|&b| b as u8 as f32).collect());
        s.push_tensor(STUDENT_FILE, "episode_start", vec![n], flags(&self.episode_start));
        s.push_tensor(STUDENT_FILE, "teacher_drives", vec![n], flags(&self.teacher_drives));
        s.push_tensor(STUDENT_FILE, "ep_return", vec![n], TensorValues::F64(self.ep_return.clone()));
        for (k, r) in self.rollouts.iter().enumerate() {
            for (name, v) in [("obs", &r.obs), ("hist", &r.hist), ("actions", &r.actions), ("latents", &r.latents)] {
                s.push_tensor(STUDENT_FILE, &format!("rollout.{k}.{name}"), vec![v.len()], TensorValues::F32(v.clone()));
            }
        }
        s.set_u64("rollouts", self.rollouts.len() as u64);
        // the (frozen) normalisation every student input goes through: the teacher's
        self.teacher.ppo.obs_norm.save("obs_norm", &mut s, STUDENT_FILE);
        s.push_tensor(STUDENT_FILE, "obs_index", vec![self.obs_index.len()], TensorValues::F64(self.obs_index.iter().map(|&i| i as f64).collect()));
        s.push_tensor(STUDENT_FILE, "hist_index", vec![self.hist_index.len()], TensorValues::F64(self.hist_index.iter().map(|&i| i as f64).collect()));
        self.adam.save(&self.student.names, &self.student.shapes, &mut s, OPTIMIZER_FILE)?;
        s.set_u64("distill_iteration", self.iteration);
        s.set_bits("rng_state", self.rng.state);
        let info = StudentInfo {
            format: STUDENT_FORMAT.to_string(),
            teacher_run: self.teacher.run.display().to_string(),
            teacher_checkpoint: self.teacher.iteration,
            teacher_manifest_xxh64: self.teacher.manifest_xxh64.clone(),
            history_len: self.student.history_len,
            latent: self.student.latent,
            adaptation: self.student.adaptation.name().to_string(),
            tcn_layers: match &self.student.adaptation {
                Adaptation::Tcn { convs } => Some(convs.iter().map(|&(k, s)| [k, s]).collect()),
                Adaptation::Gru => None,
            },
            activation: self.student.activation,
            obs_normalization: self.teacher.ppo.normalize,
        };
        s.set_info(STUDENT_FILE, serde_json::to_string(&info)?);
        Ok(s)
    }

    /// Restores what [`Distill::state`] gave.
    pub fn load_state(&mut self, s: &LearnerState) -> Result<()> {
        let mut values = Vec::new();
        for (n, sh) in self.student.names.iter().zip(&self.student.shapes) {
            values.push(to_tensor(s.f32s(STUDENT_FILE, n, Some(sh[0] * sh[1]))?, *sh, &self.device).autodiff().require_grad());
        }
        self.student.params = values;
        let n = self.num_envs;
        self.history = s.f32s(STUDENT_FILE, "history", Some(self.history.len()))?;
        self.episode_start = s.f32s(STUDENT_FILE, "episode_start", Some(n))?.iter().map(|&x| x != 0.0).collect();
        self.teacher_drives = s.f32s(STUDENT_FILE, "teacher_drives", Some(n))?.iter().map(|&x| x != 0.0).collect();
        self.ep_return = s.f64s(STUDENT_FILE, "ep_return", Some(n))?;
        self.rollouts.clear();
        for k in 0..s.u64("rollouts")? {
            let get = |name: &str| s.f32s(STUDENT_FILE, &format!("rollout.{k}.{name}"), None);
            self.rollouts.push(Rollout { obs: get("obs")?, hist: get("hist")?, actions: get("actions")?, latents: get("latents")? });
        }
        self.adam.load(&self.student.names, &self.student.shapes, s, OPTIMIZER_FILE, &self.device)?;
        self.iteration = s.u64("distill_iteration")?;
        self.rng.state = s.bits("rng_state")?;
        Ok(())
    }
}

/// A distilled student read back from a checkpoint, acting deterministically with its own history
/// windows (what `eval` and `export --verify` run): every shape comes from the file.
#[derive(Clone)]
pub struct StudentPolicy {
    /// The network (inference tensors).
    pub student: Student,
    /// Indices in the actor observation of the student's inputs and of one history step.
    pub obs_index: Vec<usize>,
    pub hist_index: Vec<usize>,
    /// The teacher's normaliser that every student input goes through (`None`: no normalisation).
    pub norm: Option<crate::learn::normalizer::Normalizer>,
    /// The teacher: run, checkpoint iteration, XXH64 of its manifest.
    pub teacher: (String, u64, String),
    /// Raw history windows `[N, H, D]`, oldest first, and which envs start an episode next.
    pub window: Vec<f32>,
    /// The latent z [N, L] of the last `act_mean` (empty without a latent).
    pub last_latent: Vec<f32>,
    start: Vec<bool>,
}

/// The metadata format of a student's policy file.
pub const STUDENT_FORMAT: &str = "dextrain.student.v1";

/// The student file's metadata (its safetensors `info`): what loading it needs beyond the tensors.
#[derive(Debug, serde::Serialize, serde::Deserialize)]
struct StudentInfo {
    /// [`STUDENT_FORMAT`].
    format: String,
    /// The teacher's run directory, the checkpoint's iteration and its manifest's XXH64 (hex).
    #[serde(default)]
    teacher_run: String,
    #[serde(default)]
    teacher_checkpoint: u64,
    #[serde(default)]
    teacher_manifest_xxh64: String,
    /// Steps of the history window.
    history_len: usize,
    /// Width of the latent (0: none).
    latent: usize,
    /// φ: "gru" or "tcn" (students written before the TCN have none: a GRU).
    #[serde(default = "gru_name")]
    adaptation: String,
    /// The TCN's [kernel, stride] pairs (none for a GRU).
    #[serde(default)]
    tcn_layers: Option<Vec<[usize; 2]>>,
    /// The hidden layers' activation.
    activation: crate::config::Activation,
    /// Whether the student normalises its observation (older files: yes).
    #[serde(default = "yes")]
    obs_normalization: bool,
}

fn gru_name() -> String {
    Adaptation::Gru.name().to_string()
}

fn yes() -> bool {
    true
}

impl StudentPolicy {
    /// Reads the student of checkpoint `ckpt` (`model.safetensors`) for an actor observation of
    /// `obs_dim` numbers.
    pub fn load(ckpt: &std::path::Path, obs_dim: usize, device: &Device) -> Result<StudentPolicy> {
        let path = ckpt.join(format!("{STUDENT_FILE}.safetensors"));
        let st = crate::learn::checkpoint::read_learner_file(&path, STUDENT_FILE)?;
        let file = st.file(STUDENT_FILE).context("no student file")?;
        let info: StudentInfo = serde_json::from_str(file.info.as_deref().unwrap_or("{}")).with_context(|| format!("{}: its metadata is not a student's", path.display()))?;
        ensure!(info.format == STUDENT_FORMAT, "{}: not a distilled student's policy file (metadata format {:?})", path.display(), info.format);
        let (activation, history_len, latent) = (info.activation, info.history_len, info.latent);
        let shape = |name: &str| -> Result<[usize; 2]> {
            let t = file.tensors.iter().find(|t| t.name == name).with_context(|| format!("{}: tensor `{name}` is missing", path.display()))?;
            Ok([t.shape[0], t.shape.get(1).copied().unwrap_or(1)])
        };
        let idx = |name: &str| -> Result<Vec<usize>> { Ok(st.f64s(STUDENT_FILE, name, None)?.iter().map(|&x| x as usize).collect()) };
        let (obs_index, hist_index) = (idx("obs_index")?, idx("hist_index")?);
        ensure!(obs_index.iter().chain(&hist_index).all(|&i| i < obs_dim), "{}: input indices beyond the task's observation ({obs_dim} numbers)", path.display());
        // φ: a GRU unless the metadata names a TCN (students written before the TCN have no key)
        let adaptation = match info.adaptation.as_str() {
            "gru" => Adaptation::Gru,
            "tcn" => {
                let convs: Vec<(usize, usize)> = info.tcn_layers.clone().with_context(|| format!("{}: metadata `tcn_layers`: expected [[kernel, stride], …]", path.display()))?.into_iter().map(|[k, s]| (k, s)).collect();
                ensure!(crate::learn::tcn::steps_out(history_len, &convs).is_some(), "{}: metadata `tcn_layers` {convs:?} do not fit in history_len {history_len}", path.display());
                Adaptation::Tcn { convs }
            }
            other => bail!("{}: metadata `adaptation` = {other:?}; expected \"gru\" or \"tcn\"", path.display()),
        };
        let mut names: Vec<String> = match (&adaptation, latent > 0) {
            (_, false) => Vec::new(),
            (Adaptation::Gru, true) => GRU_NAMES.map(String::from).to_vec(),
            (Adaptation::Tcn { convs }, true) => tcn_names(convs.len()),
        };
        if latent > 0 {
            names.extend(["head.weight".to_string(), "head.bias".to_string()]);
        }
        let n_adapt = names.len();
        let mut k = 0;
        while file.tensors.iter().any(|t| t.name == format!("actor.{k}.weight")) {
            names.push(format!("actor.{k}.weight"));
            names.push(format!("actor.{k}.bias"));
            k += 1;
        }
        ensure!(k > 0, "{}: no actor layers", path.display());
        let shapes: Vec<[usize; 2]> = names.iter().map(|n| shape(n)).collect::<Result<_>>()?;
        let params = names.iter().zip(&shapes).map(|(n, s)| Ok(to_tensor(st.f32s(STUDENT_FILE, n, Some(s[0] * s[1]))?, *s, device))).collect::<Result<_>>()?;
        let norm = if info.obs_normalization { Some(crate::learn::normalizer::Normalizer::load("obs_norm", obs_dim, &st, STUDENT_FILE)?) } else { None };
        let d = hist_index.len();
        let student = Student { params, shapes, names, n_adapt, adaptation, activation, history_len, step_dim: d, latent, obs_dim: obs_index.len() };
        let teacher = (info.teacher_run, info.teacher_checkpoint, info.teacher_manifest_xxh64);
        Ok(StudentPolicy { student, obs_index, hist_index, norm, teacher, window: Vec::new(), last_latent: Vec::new(), start: Vec::new() })
    }

    /// The student of a distillation learner as it is now (inference copies of its parameters), for
    /// the run's side-by-side evaluation: it acts exactly as [`StudentPolicy::load`] of a checkpoint
    /// written now would.
    pub fn of_learner(d: &Distill) -> StudentPolicy {
        let mut student = d.student.clone();
        student.params = d.student.params.iter().map(|p| p.clone().inner()).collect();
        let t = &d.teacher;
        StudentPolicy {
            student,
            obs_index: d.obs_index.clone(),
            hist_index: d.hist_index.clone(),
            norm: t.ppo.normalize.then(|| t.ppo.obs_norm.clone()),
            teacher: (t.run.display().to_string(), t.iteration, t.manifest_xxh64.clone()),
            window: Vec::new(),
            last_latent: Vec::new(),
            start: Vec::new(),
        }
    }

    /// The student's fields of raw observations [N, O] → [N, O_s].
    pub fn student_obs(&self, obs: &[f32], obs_dim: usize) -> Vec<f32> {
        obs.chunks(obs_dim).flat_map(|r| self.obs_index.iter().map(move |&k| r[k])).collect()
    }

    /// Deterministic actions [N, A] for raw observations `obs` [N, O]; `episode_start[i]`: env i
    /// starts an episode at this step (its window restarts). The windows shift by one step.
    pub fn act_mean(&mut self, obs: &[f32], episode_start: &[bool]) -> Result<Vec<f32>> {
        let n = episode_start.len();
        let o = obs.len() / n.max(1);
        let (h, d) = (self.student.history_len, self.student.step_dim);
        if self.window.len() != n * h * d {
            self.window = vec![0.0; n * h * d];
            self.start = vec![true; n];
        }
        for i in 0..n {
            let x: Vec<f32> = self.hist_index.iter().map(|&k| obs[i * o + k]).collect();
            let w = &mut self.window[i * h * d..(i + 1) * h * d];
            if episode_start[i] || self.start[i] {
                for row in w.chunks_mut(d) {
                    row.copy_from_slice(&x);
                }
                self.start[i] = false;
            } else {
                w.copy_within(d.., 0);
                w[(h - 1) * d..].copy_from_slice(&x);
            }
        }
        let mut obs_n = obs.to_vec();
        let mut hist_n = self.window.clone();
        if let Some(nm) = &self.norm {
            nm.apply(&mut obs_n);
            // each step's entries normalised like the observation's entries they come from
            for (j, v) in hist_n.iter_mut().enumerate() {
                let k = self.hist_index[j % d];
                *v = ((*v as f64 - nm.mean[k]) / ((nm.m2[k] / nm.count).sqrt() + nm.eps)) as f32;
            }
        }
        let obs_s = self.student_obs(&obs_n, o);
        let device = self.student.params[0].device();
        let (z, u) = self.student.forward(&self.student.params, to_tensor(obs_s, [n, self.student.obs_dim], &device), to_tensor(hist_n, [n, h * d], &device));
        self.last_latent = match z {
            Some(z) => to_host(z)?,
            None => Vec::new(),
        };
        to_host(u)
    }
}
