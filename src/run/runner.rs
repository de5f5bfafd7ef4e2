//! The runner: the env loop, logging, checkpoint cadence, Ctrl-C and resume, for any
//! [`Algorithm`] (rsl_rl's runner with the algorithm behind a trait; `on_policy.rs` is PPO's part).
//! Each iteration: `steps_per_iteration` env steps of every env with the algorithm acting, its
//! `update`, one metrics row, a checkpoint every `train.save_interval` iterations, repeat.
//!
//! `dextrain train CONFIG [--set k=v]… [--name NAME] [--force]` starts a run in `runs/NAME/`;
//! `dextrain train --resume runs/NAME` continues it from its latest checkpoint, exactly: the
//! checkpoint holds the algorithm's whole state (PPO: the networks, Adam, the normalisers, the
//! learning rate, the learner RNG), the counters and the whole env batch (states, parameters, task
//! state, current observations and the running episodes' accumulators), so an interrupted run and a
//! straight run write the same `metrics.csv` (but for the wall-clock columns `time_s`, `fps`,
//! `time/collect_s`, `time/learn_s`).
//!
//! Ctrl-C stops a run at the end of the current iteration with a checkpoint. Console output goes
//! through `crate::console`: a closed stdout or stderr never stops a run.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use serde_json::json;

use super::algorithm::{Algorithm, StepOutcome};
use super::device_loop::DeviceLoop;
use crate::console;
use crate::learn::checkpoint::{self, CheckpointState, EnvSnapshot};
use crate::config::{Config, TaskKind};
use crate::env::SimModel;
use crate::task::{TaskBatch, TaskSpec, make_task_batch};
use crate::learn::device::learner_device;
use crate::live::LiveView;
use crate::metrics::MetricsLog;
use crate::run_dir;

/// Arguments of `dextrain train`.
#[derive(clap::Args, Debug, Clone)]
pub struct TrainArgs {
    /// The TOML config of the run (not with --resume).
    #[arg(required_unless_present = "resume", conflicts_with = "resume")]
    pub config: Option<PathBuf>,
    /// Override a config value: `--set ppo.learning_rate=1e-3` (repeatable). With --resume only
    /// `train.*` keys may change (e.g. `--set train.iterations=2000` to train longer).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub sets: Vec<String>,
    /// Run name (default: `<config stem>_<UTC time>`); the run is written to `<runs-dir>/<NAME>/`.
    #[arg(long, conflicts_with = "resume")]
    pub name: Option<String>,
    /// Continue the run in this directory from its latest checkpoint.
    #[arg(long, value_name = "RUN_DIR")]
    pub resume: Option<PathBuf>,
    /// Replace an existing run of the same name (only a run directory: one that holds nothing but
    /// what dextrain writes; anything else is refused and left as it is).
    #[arg(long)]
    pub force: bool,
    /// Where runs are written.
    #[arg(long, default_value = "runs")]
    pub runs_dir: PathBuf,
    /// Stop (with a checkpoint) after this many iterations of this invocation; resume later.
    #[arg(long)]
    pub stop_after: Option<u64>,
    /// No progress bar; one log line every 10 % of the run instead.
    #[arg(long)]
    pub quiet: bool,
    /// The live view (`--live`, `--live-envs`, `--live-hz`, `--live-wait`).
    #[command(flatten)]
    pub live: crate::live::LiveArgs,
    /// Time each of dextrain's kernels and each stretch of the learner's work on the GPU
    /// (timestamp queries; docs/gpu.md "Where a GPU's time goes"): `gpu_profile.json` in the run
    /// directory and in the summary line. Slows the run a little.
    #[arg(long)]
    pub gpu_profile: bool,
}

static STOP: AtomicBool = AtomicBool::new(false);

extern "C" fn on_stop_signal(_: libc::c_int) {
    STOP.store(true, Ordering::SeqCst);
}

/// The metrics columns of a run, in order (after "iteration"): the env's, the algorithm's
/// (`learner`, e.g. PPO's losses, kl, lr…), then the reference kinds' tracking errors.
pub fn metric_columns(spec: &TaskSpec, learner: &[String]) -> Vec<String> {
    use crate::metrics::columns::*;
    let mut c: Vec<String> = [ENV_STEPS, TIME_S, FPS, COLLECT_S, LEARN_S, HOST_BYTES].iter().map(|s| s.to_string()).collect();
    c.extend(GPU_COUNT_COLUMNS.iter().map(|s| s.to_string()));
    c.push(REWARD_MEAN.into());
    c.extend(spec.term_names.iter().map(|t| format!("{REWARD_PREFIX}{t}")));
    c.extend(
        [EPISODE_COUNT, EPISODE_RETURN, EPISODE_LENGTH, EPISODE_SUCCESS_RATE, EPISODE_LIFT_HEIGHT, EPISODE_TERMINATED_FRAC, EPISODE_BAD_RESET_FRAC]
            .iter()
            .map(|s| s.to_string()),
    );
    c.extend(learner.iter().cloned());
    if spec.kind.follows_reference() {
        // the object's error against its reference, mean over the rollout's env steps
        c.extend([TRACKING_OBJ_POS_ERR_M, TRACKING_OBJ_ROT_ERR_DEG].iter().map(|s| s.to_string()));
    }
    c
}

/// What the iteration asked of the GPU ([`crate::gpu_counts`]; 0 without a GPU): kernels, queue
/// submissions and host synchronisations per env step of the collection (an env step of all envs;
/// for SAC it includes the gradient steps taken inside the env loop) and of the learner's update
/// at the end of the iteration (PPO's whole update). Submissions are those of the simulator's
/// queue (burn's included when the learner shares the GPU), else dextrain's own.
pub const GPU_COUNT_COLUMNS: [&str; 6] =
    ["gpu/kernels_per_step", "gpu/submissions_per_step", "gpu/syncs_per_step", "gpu/kernels_per_update", "gpu/submissions_per_update", "gpu/syncs_per_update"];

/// A fraction of episodes ended by bad-state resets above which `train` warns: a healthy sim has
/// none, so one in a hundred means exploding envs (too large a time step, gains or randomisation).
pub const BAD_RESET_WARN_FRAC: f64 = 0.01;
/// Iterations between two bad-reset warnings (the first comes at once).
const BAD_RESET_WARN_EVERY: u64 = 50;

/// What the algorithm needs to know of the run to build itself.
pub struct RunContext {
    /// The run's config.
    pub cfg: Config,
    /// Number of envs N.
    pub num_envs: usize,
    /// [actor obs O, critic obs P, actions A].
    pub dims: [usize; 3],
    /// The learner device.
    pub device: burn::prelude::Device,
    /// The critic-observation entries of the privileged encoder's inputs (empty: no encoder).
    pub encoder_index: Vec<usize>,
    /// The task's sizes and observation layouts.
    pub spec: TaskSpec,
}

/// Builds the algorithm of a run.
pub type MakeAlgorithm = fn(&RunContext) -> Result<Box<dyn Algorithm>>;

/// What happened during one iteration's rollout (host-side sums).
#[derive(Default)]
pub(super) struct RolloutSums {
    /// Σ reward and Σ of each weighted term over the env steps of every env.
    pub reward: f64,
    pub terms: Vec<f64>,
    /// Env steps of all envs.
    pub steps: u64,
    /// Episodes that ended, those that ended with success, by a termination.
    pub episodes: u64,
    pub successes: u64,
    pub terminated: u64,
    /// Episodes that ended because the physics reset a bad state (NaN, speed or distance beyond
    /// the sim's limits).
    pub bad_resets: u64,
    /// Σ over the ended episodes of their return, length and final lift height.
    pub ep_return: f64,
    pub ep_len: f64,
    pub lift: f64,
    /// Σ over env steps of the object's position (m) and orientation (deg) error against its reference.
    pub obj_pos_err: f64,
    pub obj_rot_err: f64,
}

impl RolloutSums {
    /// `x` per env step (NaN without steps).
    fn per_step(&self, x: f64) -> f64 {
        if self.steps > 0 { x / self.steps as f64 } else { f64::NAN }
    }

    /// `x` per ended episode (NaN without one).
    fn per_episode(&self, x: f64) -> f64 {
        if self.episodes > 0 { x / self.episodes as f64 } else { f64::NAN }
    }

    /// The mean reward per env step (metrics.csv's `reward/mean`).
    fn mean_reward(&self) -> f64 {
        self.per_step(self.reward)
    }

    /// The fraction of the ended episodes that succeeded (`episode/success_rate`).
    fn success_rate(&self) -> f64 {
        self.per_episode(self.successes as f64)
    }
}

/// Per-env accumulators of the running episodes.
pub(super) struct Episodes {
    /// Return so far [N].
    pub ret: Vec<f64>,
    /// Length so far [N].
    pub len: Vec<f64>,
}

/// One iteration's env steps: act, step, observe; returns the sums. `obs`/`priv_obs` are updated to
/// the observations after the last step.
fn collect(task: &mut dyn TaskBatch, algo: &mut dyn Algorithm, obs: &mut [f32], priv_obs: &mut [f32], eps: &mut Episodes, steps: usize, mut live: Option<&mut LiveView>) -> Result<RolloutSums> {
    let n_terms = task.spec().term_names.len();
    let mut s = RolloutSums { terms: vec![0.0; n_terms], ..Default::default() };
    for _ in 0..steps {
        let actions = algo.act(obs, priv_obs)?;
        let b = task.step(&actions)?;
        algo.observe(&StepOutcome {
            reward: &b.reward,
            terminated: &b.terminated,
            time_out: &b.time_out,
            obs: &b.obs,
            priv_obs: &b.priv_obs,
            success: &b.success,
            final_obs: &b.final_obs,
            final_priv_obs: &b.final_priv_obs,
        })?;
        let n = b.reward.len();
        for i in 0..n {
            let r = b.reward[i] as f64;
            s.reward += r;
            for k in 0..n_terms {
                s.terms[k] += b.terms[i * n_terms + k] as f64;
            }
            eps.ret[i] += r;
            eps.len[i] += 1.0;
            s.obj_pos_err += b.obj_pos_err[i] as f64;
            s.obj_rot_err += (b.obj_rot_err[i] as f64).to_degrees();
            if b.done(i) {
                s.episodes += 1;
                s.successes += b.success[i] as u64;
                s.terminated += b.terminated[i] as u64;
                s.bad_resets += b.bad_reset[i] as u64;
                s.ep_return += eps.ret[i];
                s.ep_len += eps.len[i];
                s.lift += b.lift_height[i] as f64;
                eps.ret[i] = 0.0;
                eps.len[i] = 0.0;
            }
        }
        s.steps += n as u64;
        obs.copy_from_slice(&b.obs);
        priv_obs.copy_from_slice(&b.priv_obs);
        if let Some(l) = live.as_deref_mut() {
            l.after_step(task)?;
        }
    }
    Ok(s)
}

/// One metrics row in `metric_columns` order (`learner`: the algorithm's update values;
/// `host_bytes`: the iteration's host↔GPU traffic; `tracking`: the reference kinds' extra columns).
#[allow(clippy::too_many_arguments)]
fn metric_row(s: &RolloutSums, learner: &[f64], env_steps: u64, time_s: f64, fps: f64, collect_s: f64, learn_s: f64, host_bytes: u64, gpu: [f64; 6], tracking: bool) -> Vec<f64> {
    let mut row = vec![env_steps as f64, time_s, fps, collect_s, learn_s, host_bytes as f64];
    row.extend(gpu);
    row.push(s.mean_reward());
    row.extend(s.terms.iter().map(|&t| s.per_step(t)));
    row.extend([
        s.episodes as f64,
        s.per_episode(s.ep_return),
        s.per_episode(s.ep_len),
        s.success_rate(),
        s.per_episode(s.lift),
        s.per_episode(s.terminated as f64),
        s.per_episode(s.bad_resets as f64),
    ]);
    row.extend_from_slice(learner);
    if tracking {
        row.extend([s.per_step(s.obj_pos_err), s.per_step(s.obj_rot_err)]);
    }
    row
}

/// A run's config as `train` loads it, once: a new run's (its file with the `--set` overrides) or
/// a resumed run's (its `config.toml`, with `train.*` overrides only, written back), with the
/// resumed run's directory and checkpoint.
pub struct LoadedRun {
    pub cfg: Config,
    /// (run directory, checkpoint) of a resume.
    resume: Option<(PathBuf, PathBuf)>,
}

/// Loads the config of a new run or of a resumed one ([`LoadedRun`]).
pub fn load(args: &TrainArgs) -> Result<LoadedRun> {
    if let Some(dir) = &args.resume {
        run_dir::check_run(dir)?;
        let cfg_path = dir.join("config.toml");
        for s in &args.sets {
            if !s.trim_start().starts_with("train.") {
                bail!("--set {s:?}: only train.* keys can change when resuming (the rest of {} is fixed)", cfg_path.display());
            }
        }
        let cfg = Config::load_with_overrides(&cfg_path, &args.sets)?;
        let ckpt = checkpoint::find(dir, "latest")?;
        // several ranks resume from one iteration: the newest that every rank holds
        let ckpt = super::ranks::common_checkpoint(dir, ckpt)?;
        checkpoint::read_state(&ckpt)?;
        if !args.sets.is_empty() {
            std::fs::write(&cfg_path, cfg.to_toml()?).with_context(|| format!("cannot write {}", cfg_path.display()))?;
        }
        return Ok(LoadedRun { cfg, resume: Some((dir.clone(), ckpt)) });
    }
    let path = args.config.as_ref().context("a config file or --resume is needed")?;
    Ok(LoadedRun { cfg: Config::load_with_overrides(path, &args.sets)?, resume: None })
}

/// A check of an algorithm's own on the config and the task before a new run's directory is made
/// (SAC's: that its replay buffer fits).
pub type Preflight = fn(&Config, &crate::task::TaskSpec) -> Result<()>;

/// The [`Preflight`] of an algorithm that needs none.
pub fn no_preflight(_: &Config, _: &crate::task::TaskSpec) -> Result<()> {
    Ok(())
}

/// A new run's directory with its resolved config, made once the hand, the references and the
/// algorithm's `preflight` accept the config; or the resumed run's directory. Returns the
/// directory, the checkpoint to resume from, and the sim model where it was built here.
fn setup(args: &TrainArgs, loaded: &LoadedRun, preflight: Preflight) -> Result<(PathBuf, Option<PathBuf>, Option<SimModel>)> {
    if let Some((dir, ckpt)) = &loaded.resume {
        return Ok((dir.clone(), Some(ckpt.clone()), None));
    }
    let cfg = &loaded.cfg;
    let path = args.config.as_ref().context("a config file or --resume is needed")?;
    let name = match &args.name {
        Some(n) => n.clone(),
        None => run_dir::default_name(path),
    };
    run_dir::validate_name(&name)?;
    // the hand and the references must load before a run directory is made
    let model = SimModel::from_config(cfg)?;
    let setup = crate::task::task_setup(cfg, &model)?;
    // the algorithm's own check (a replay buffer that cannot fit) before anything is written
    preflight(cfg, &setup.spec)?;
    let dir = run_dir::create(&args.runs_dir, &name, args.force)?;
    // the exact resolved config, with the hand's URDF and the reference files as absolute paths so
    // that it loads from the run directory
    let mut saved = cfg.clone();
    saved.hand.urdf = absolute(&cfg.resolve(&cfg.hand.urdf));
    saved.object = cfg.object.with_paths(|p| absolute(&cfg.resolve(p)));
    saved.task.reference.files = cfg.task.reference.files.iter().map(|f| absolute(&cfg.resolve(f))).collect();
    if !cfg.distill.teacher.is_empty() {
        saved.distill.teacher = absolute(&cfg.resolve(&cfg.distill.teacher));
    }
    std::fs::write(dir.join("config.toml"), saved.to_toml()?).with_context(|| format!("cannot write {}", dir.join("config.toml").display()))?;
    Ok((dir, None, Some(model)))
}

fn absolute(p: &Path) -> String {
    std::fs::canonicalize(p).unwrap_or_else(|_| p.to_path_buf()).display().to_string()
}

/// Runs (or resumes) the training run `loaded` with the algorithm that `make` builds, after its
/// `preflight` check; returns its directory.
pub fn run(args: &TrainArgs, loaded: LoadedRun, make: MakeAlgorithm, preflight: Preflight) -> Result<PathBuf> {
    // before any GPU context is made (each keeps its own profiler)
    crate::gpu::profile::request(args.gpu_profile);
    // several ranks (`mpiexec`): rank 0 makes the run directory first, then the others theirs
    // inside it (`super::ranks`); each waits for rank 0, and a rank that failed stops them all
    let first = crate::dist::rank() == 0;
    let rank0 = if first { Some(setup(args, &loaded, preflight)) } else { None };
    if crate::dist::any(rank0.as_ref().is_some_and(|r| r.is_err())) {
        return match rank0 {
            Some(r) => r.map(|(dir, _, _)| dir),
            None => bail!("rank 0 could not set up the run (its error is above)"),
        };
    }
    let mine = match rank0 {
        Some(r) => r,
        None => setup(args, &loaded, preflight),
    };
    if crate::dist::any(mine.is_err()) {
        return match mine {
            Err(e) => Err(e),
            Ok(_) => bail!("another rank could not set up the run (its error is above)"),
        };
    }
    let (dir, resume, model) = mine?;
    let fresh = resume.is_none();
    let result = train_in(args, make, loaded.cfg, model, dir.clone(), resume);
    if result.is_err() && fresh {
        // a new run that failed before its first iteration (no adapter, a buffer too large, …)
        // leaves no directory behind; one with iterations or checkpoints stays
        if let Err(e) = run_dir::remove_failed_start(&dir) {
            console::status(&format!("warning: {e:#}"));
        }
    }
    result
}

/// The training loop of [`run`] in `dir`, from `resume`'s checkpoint or from the start; `model`:
/// the sim model where [`setup`] built it already (a new run's), else built here.
fn train_in(args: &TrainArgs, make: MakeAlgorithm, cfg: Config, model: Option<SimModel>, dir: PathBuf, resume: Option<PathBuf>) -> Result<PathBuf> {
    let mut model = match model {
        Some(m) => m,
        None => SimModel::from_config(&cfg)?,
    };
    // data-parallel (`mpiexec`): rank r simulates the job's envs [r·E, (r+1)·E), every rank E of them
    let (rank, ranks) = (crate::dist::rank(), crate::dist::size());
    if ranks > 1 {
        let envs = crate::dist::gather_f64(cfg.sim.num_envs as f64);
        if envs.iter().any(|&e| e != envs[0]) {
            let list: Vec<String> = envs.iter().map(|e| e.to_string()).collect();
            bail!("{}: sim.num_envs differs between the ranks ({}, in rank order); expected the same number on every rank", cfg.source.display(), list.join(", "));
        }
        model.globals.env_offset = (rank * cfg.sim.num_envs) as u32;
    }
    let live_model = args.live.live.is_some().then(|| model.clone());
    let mut task = make_task_batch(&cfg, model)?;
    let spec = task.spec().clone();
    let choice = cfg.train.device.clone();
    let (device, device_name) = learner_device(&choice, task.gpu_context())?;
    let n = spec.num_envs;
    let dims = [spec.obs_dim, spec.priv_dim, spec.action_dim];
    let encoder_index = crate::learn::ppo::encoder_index(&cfg.policy, &spec).with_context(|| cfg.source.display().to_string())?;
    let mut algo = make(&RunContext { cfg: cfg.clone(), num_envs: n, dims, device: device.clone(), encoder_index, spec: spec.clone() })?;
    if algo.wants_final_observations() {
        task.set_final_observations(true)?;
    }
    let steps = algo.steps_per_iteration();
    let columns = metric_columns(&spec, &algo.stat_columns());
    let (mut iteration, mut env_steps, mut time_base, mut obs, mut priv_obs, mut eps, mut metrics) = match &resume {
        Some(ckpt) => {
            let (st, learner, snap) = checkpoint::load(ckpt, dims, n)?;
            algo.load_state(&learner).with_context(|| format!("{}: cannot restore the learner", ckpt.display()))?;
            task.load_state(&snap.task_state).with_context(|| format!("{}: cannot restore the env batch", ckpt.display()))?;
            let metrics = MetricsLog::resume(&dir, &columns, st.iteration)?;
            (st.iteration, st.env_steps, st.exact_time_s(), snap.obs, snap.priv_obs, Episodes { ret: snap.ep_return, len: snap.ep_len }, metrics)
        }
        None => {
            let first = task.reset_all()?;
            let (o, p) = (first.obs.clone(), first.priv_obs.clone());
            // (the lift task only: a reference kind's episode starts at its reference's first frame,
            // and a random step count would start the reference elsewhere than the hand and object)
            if cfg.train.init_at_random_ep_len && cfg.task.kind == TaskKind::Lift {
                // desynchronise the episodes: each env's first episode starts at a random step count
                // (the job's draws for every env, in env order: a rank takes its envs' ones)
                let mut rng = crate::rng::Rng::new(cfg.seed as u64, 0xE915_0DE5);
                let starts: Vec<u32> = (0..n * ranks).map(|_| rng.below(spec.episode_length as usize) as u32).collect();
                let mut states = task.env().states()?;
                for (s, start) in states.iter_mut().zip(&starts[rank * n..]) {
                    s.step = *start;
                }
                task.env().set_states(&states)?;
            }
            let metrics = MetricsLog::create(&dir, &columns)?;
            (0, 0, 0.0, o, p, Episodes { ret: vec![0.0; n], len: vec![0.0; n] }, metrics)
        }
    };
    // the rollouts stay on the device when the envs and the learner share a GPU (docs/gpu.md "The GPU loop")
    let mut device_loop = None;
    if cfg.train.device_rollouts
        && crate::dist::size() == 1
        && task.can_step_on_device()
        && algo.can_run_on_device()
        && let Some(ctx) = task.gpu_context().filter(|c| crate::learn::device::shares_sim_device(&choice, Some(c)))
    {
        algo.start_device_rollouts(ctx)?;
        device_loop = Some(DeviceLoop::new(&obs, &priv_obs, &eps, dims, &device));
    }
    let total = cfg.train.iterations as u64;
    if iteration >= total {
        bail!("{}: the run has finished its {total} iterations; resume with --set train.iterations=N (N > {iteration}) to train longer", dir.display());
    }
    // the live view (rank 0 of an MPI job shows its envs), with the run's own Foxglove layout
    let mut live = match &live_model {
        Some(m) if crate::dist::rank() == 0 => {
            let losses: Vec<String> = algo.stat_columns().into_iter().filter(|c| c.starts_with(crate::metrics::columns::LOSS_PREFIX)).collect();
            let layout = crate::live::layout::layout(&spec.term_names, &losses);
            let path = dir.join(crate::live::layout::RUN_LAYOUT);
            crate::live::layout::write(&path, &layout)?;
            args.live.start(m, spec.control_dt, Some(&columns), false)?
        }
        _ => None,
    };
    let stop_at = args.stop_after.map(|k| (iteration + k).min(total)).unwrap_or(total);
    console::status(&format!(
        "dextrain train: {} | envs: {} ({n} envs, obs {}, critic obs {}, actions {}) | learner: {} on {device_name}{} | iterations {iteration}..{stop_at} of {total}",
        dir.display(),
        task.backend_name(),
        dims[0],
        dims[1],
        dims[2],
        algo.name(),
        if device_loop.is_some() { " | rollouts on the device" } else { "" }
    ));
    // Ctrl-C, and `kill` / `timeout` / a job scheduler's SIGTERM: finish the iteration, checkpoint, stop
    unsafe {
        libc::signal(libc::SIGINT, on_stop_signal as *const () as libc::sighandler_t);
        libc::signal(libc::SIGTERM, on_stop_signal as *const () as libc::sighandler_t);
    }
    let bar = ProgressBar::new(total);
    bar.set_position(iteration);
    if args.quiet {
        bar.set_draw_target(ProgressDrawTarget::hidden());
    }
    bar.set_style(
        ProgressStyle::with_template("{bar:30} {pos}/{len} it | {msg} | {elapsed_precise} ETA {eta_precise}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    // `--gpu-profile`: the context whose profile the run reports (the simulator's, else the learner's)
    let learner_ctx = crate::learn::device::gpu_context_of(&device);
    let gpu_ctx = task.gpu_context().or(learner_ctx.as_ref());
    if args.gpu_profile && gpu_ctx.is_none() {
        console::status("--gpu-profile: neither the envs nor the learner run on a GPU; no profile");
    }
    let profiled = gpu_ctx.filter(|c| c.profiles()).cloned();
    let profiled = profiled.as_ref();
    if let Some(ctx) = profiled {
        ctx.profile_restart()?; // the training loop's profile: the set-up's kernels left out
    }
    let started = Instant::now();
    let mut last_saved = iteration;
    let mut last_row = Vec::new();
    let mut last_bad_warning: Option<u64> = None;
    while iteration < stop_at {
        let t0 = Instant::now();
        let bytes0 = crate::host_traffic::total();
        let counts0 = GpuCounter::start(task.gpu_context());
        let (sums, upd, collect_and_learn_s, counts1) = match &mut device_loop {
            Some(dl) => {
                dl.collect(task.as_mut(), algo.as_mut(), steps, live.as_mut())?;
                // reading the sums waits for the envs' steps: the collection's time ends here
                let sums = dl.take_sums(spec.term_names.len())?;
                if let Some(ctx) = task.gpu_context() {
                    // a device lost or an error outside any call's scope, as the host path's readbacks check
                    ctx.check_uncaptured("the iteration's device-resident env steps")?;
                }
                let collect_s = t0.elapsed().as_secs_f64();
                let counts1 = GpuCounter::start(task.gpu_context());
                let update = crate::gpu::profile::around_burn(learner_ctx.as_ref(), &device, "update", || algo.update_device(&dl.obs, &dl.priv_obs))?;
                (sums, update, collect_s, counts1)
            }
            None => {
                let sums = collect(task.as_mut(), algo.as_mut(), &mut obs, &mut priv_obs, &mut eps, steps, live.as_mut())?;
                let collect_s = t0.elapsed().as_secs_f64();
                let counts1 = GpuCounter::start(task.gpu_context());
                let update = crate::gpu::profile::around_burn(learner_ctx.as_ref(), &device, "update", || algo.update(&obs, &priv_obs))?;
                (sums, update, collect_s, counts1)
            }
        };
        let host_bytes = crate::host_traffic::total() - bytes0;
        let counts2 = GpuCounter::start(task.gpu_context());
        if let Some(ctx) = profiled {
            ctx.profile_read()?; // the iteration's stamps (one read, between the iterations' counts)
        }
        let (per_step, per_update) = (counts0.until(&counts1), counts1.until(&counts2));
        let env_step_count = steps.max(1) as f64;
        let gpu = [
            per_step[0] / env_step_count,
            per_step[1] / env_step_count,
            per_step[2] / env_step_count,
            per_update[0],
            per_update[1],
            per_update[2],
        ];
        // an off-policy learner's gradient steps ran inside the env loop: they count as learning
        let inner_learn_s = algo.take_learn_seconds().min(collect_and_learn_s);
        let collect_s = collect_and_learn_s - inner_learn_s;
        let learn_s = t0.elapsed().as_secs_f64() - collect_s;
        iteration += 1;
        env_steps += sums.steps;
        let dt = t0.elapsed().as_secs_f64();
        let time_s = time_base + started.elapsed().as_secs_f64();
        let fps = sums.steps as f64 / dt.max(1e-9);
        let row = metric_row(&sums, &upd, env_steps, time_s, fps, collect_s, learn_s, host_bytes, gpu, spec.kind.follows_reference());
        metrics.append(iteration, &row)?;
        if let Some(l) = live.as_mut() {
            l.metrics(iteration, &columns, &row)?;
        }
        let (success, reward) = (sums.success_rate(), sums.mean_reward());
        // no episode ended yet (the first iterations of long episodes): no success rate to show
        let success = if success.is_finite() { format!("{:.0}%", 100.0 * success) } else { "– (no episode ended yet)".to_string() };
        let msg = format!("{fps:.0} steps/s (collect {collect_s:.2} s, learn {learn_s:.2} s), reward {reward:.3}, success {success}");
        bar.set_message(msg.clone());
        bar.set_position(iteration);
        // (ranks ≥ 1 of an MPI job keep theirs in their metrics: one rank's lines are enough)
        if (args.quiet || bar.is_hidden()) && crate::dist::rank() == 0 && (iteration % (total / 10).max(1) == 0 || iteration == stop_at) {
            console::status(&format!("iteration {iteration}/{total}: {env_steps} env steps, {time_s:.1} s, {msg}"));
        }
        if sums.episodes > 0 {
            let frac = sums.bad_resets as f64 / sums.episodes as f64;
            if frac > BAD_RESET_WARN_FRAC && last_bad_warning.is_none_or(|w| iteration >= w + BAD_RESET_WARN_EVERY) {
                bar.suspend(|| {
                    console::warn(&format!(
                        "warning: iteration {iteration}: {:.1} % of the episodes that ended ({} of {}) were reset for a bad state (NaN, or speed or distance beyond the sim's limits); check sim.dt, the hand's gains and the randomisation ranges (column episode/bad_reset_frac)",
                        100.0 * frac,
                        sums.bad_resets,
                        sums.episodes
                    ))
                });
                last_bad_warning = Some(iteration);
            }
        }
        last_row = row;
        // every rank of an MPI job stops at the same iteration (the next one's collectives would wait)
        let interrupted = crate::dist::any(STOP.load(Ordering::SeqCst));
        if iteration % cfg.train.save_interval as u64 == 0 || iteration == stop_at || interrupted {
            if let Some(dl) = &device_loop {
                (obs, priv_obs, eps) = dl.to_host()?;
            }
            let snap = EnvSnapshot { task_state: task.save_state()?, obs: obs.clone(), priv_obs: priv_obs.clone(), ep_return: eps.ret.clone(), ep_len: eps.len.clone() };
            let learner = algo.state()?;
            let st = CheckpointState::new(iteration, env_steps, time_s, dims, &learner);
            checkpoint::save(&dir.join("checkpoints"), &st, &learner, &snap)?;
            last_saved = iteration;
            prune(&dir, cfg.train.keep_checkpoints)?;
        }
        if cfg.train.plot_interval > 0 && iteration % cfg.train.plot_interval as u64 == 0 {
            crate::plot::plot_run(&dir.join("metrics.csv"), &dir.join("plots"))?;
        }
        if interrupted {
            // the bar stays where the run stopped (finish() would fill it), and ends its line:
            // indicatif leaves the cursor after the bar, where the next line would be glued on
            bar.abandon_with_message("interrupted");
            end_bar_line(&bar);
            console::status(&format!("dextrain train: interrupted at iteration {iteration}; checkpoint written; continue with --resume {}", dir.display()));
            break;
        }
    }
    if !bar.is_finished() {
        bar.finish();
        end_bar_line(&bar);
    }
    let loop_wall_s = started.elapsed().as_secs_f64();
    time_base += loop_wall_s;
    crate::plot::plot_run(&dir.join("metrics.csv"), &dir.join("plots"))?;
    // device memory at the end: the simulator's buffers and what burn's allocator has reserved
    // (its pools keep their pages, so this is about the run's peak)
    let sim_bytes = task.device_bytes();
    let learner_bytes = if crate::learn::nets::is_gpu(&device) { device.memory_pool_usage().map_or(0, |u| u.bytes_reserved) } else { 0 };
    // the ranks of an MPI job hold the same parameters (they step with the same averaged gradients)
    let deviation = if crate::dist::size() > 1 { algo.max_rank_deviation()? } else { 0.0 };
    let mut summary = json!({
        "run": dir.display().to_string(),
        "device_memory": { "sim_bytes": sim_bytes, "learner_bytes": learner_bytes, "bytes_per_env": (sim_bytes + learner_bytes) as f64 / n as f64 },
        "iterations": iteration,
        "env_steps": env_steps,
        "time_s": time_base,
        "checkpoint": last_saved,
        "env_backend": task.backend_name(),
        "learner_device": device_name,
        "last": columns.iter().zip(&last_row).map(|(c, v)| (c.clone(), json!(v))).collect::<serde_json::Map<_, _>>(),
    });
    if let Some(l) = &live {
        summary["live"] = l.summary();
    }
    if let Some(ctx) = profiled
        && let Some(mut profile) = ctx.profile_report()?
    {
        profile["loop_wall_s"] = json!(loop_wall_s);
        let path = dir.join(crate::run_dir::GPU_PROFILE);
        let tmp = crate::files::temp_path_beside(&path)?;
        std::fs::write(&tmp, format!("{profile}\n")).with_context(|| format!("cannot write {}", tmp.display()))?;
        std::fs::rename(&tmp, &path).with_context(|| format!("cannot write {}", path.display()))?;
        summary["gpu_profile"] = profile;
    }
    if crate::dist::size() > 1 {
        summary["ranks"] = json!({ "size": crate::dist::size(), "rank": crate::dist::rank(), "max_parameter_deviation": deviation });
    }
    console::result(&summary.to_string());
    Ok(dir)
}

/// A reading of [`crate::gpu_counts`] and of the simulator's queue (see [`GPU_COUNT_COLUMNS`]).
struct GpuCounter {
    counts: crate::gpu_counts::GpuCounts,
    queue: Option<u64>,
}

impl GpuCounter {
    fn start(ctx: Option<&crate::gpu::context::GpuContext>) -> GpuCounter {
        GpuCounter { counts: crate::gpu_counts::GpuCounts::now(), queue: ctx.and_then(|c| crate::gpu_counts::queue_submissions(&c.queue)) }
    }

    /// [kernels, submissions, host syncs] from this reading to `later`.
    fn until(&self, later: &GpuCounter) -> [f64; 3] {
        use crate::gpu_counts::Event;
        let d = later.counts.since(&self.counts);
        let submissions = d.queue_submissions(crate::gpu_counts::submissions_between(self.queue, later.queue));
        [d.total(Event::Kernel) as f64, submissions as f64, d.host_syncs() as f64]
    }
}

/// Removes all but the newest `keep` checkpoints (0 = keep all).
fn prune(dir: &Path, keep: u32) -> Result<()> {
    if keep == 0 {
        return Ok(());
    }
    let all = checkpoint::list(dir)?;
    let excess = all.len().saturating_sub(keep as usize);
    for (_, p) in all.into_iter().take(excess) {
        std::fs::remove_dir_all(&p).with_context(|| format!("cannot remove old checkpoint {}", p.display()))?;
    }
    Ok(())
}

/// Ends the progress bar's line on the terminal (indicatif leaves the cursor after a finished or
/// abandoned bar, so the next status line or the summary would be glued onto it); nothing when
/// the bar is not drawn (`--quiet`, or stderr not a terminal).
fn end_bar_line(bar: &ProgressBar) {
    if !bar.is_hidden() {
        console::status("");
    }
}
