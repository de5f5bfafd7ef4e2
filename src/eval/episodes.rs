//! The episodes of an evaluation (`eval`, `play`, and distillation's side-by-side evaluation):
//! rounds of at most `--max-envs` envs, each env running exactly one episode of the config's task
//! under a policy (or open-loop), the finished episodes added up into a [`Summary`].
//!
//! [`run_episodes`] runs the rounds; a round ([`run_round`]) builds its envs and its policy
//! ([`round_actor`]), steps until every env's episode has ended and hands each finished episode to
//! the evaluation's [`Tally`]; [`Tally::summary`] makes the report's figures.

use anyhow::{Context, Result};

use super::{Driver, EpisodeRow, EvalArgs, ObjectSummary, PolicySource, Summary, mean_std, reference_names};
use crate::config::{BackendChoice, Config};
use crate::env::SimModel;
use crate::gpu::layout::Targets;
use crate::learn::checkpoint;
use crate::learn::device::learner_device;
use crate::learn::ppo::Ppo;
use crate::record::{RolloutFrame, RolloutMeta, RolloutWriter};
use crate::video::VideoEpisode;
use crate::task::{StepBatch, TaskBatch, TaskSpec, decode_snapshot, make_task_batch, reference_paths};

/// A deterministic policy that eval runs.
enum Actor<'a> {
    Ppo(Box<Ppo>),
    /// A SAC run's actor (tanh of its mean).
    Sac(Box<crate::learn::sac::Sac>),
    /// A policy that someone else owns (a distillation run's teacher).
    Borrowed(&'a Ppo),
    Student(Box<crate::learn::distill::StudentPolicy>),
    /// An exported policy with its own action mapping (`dextrain play`).
    Exported(Box<crate::export::controller::Controller>),
}

impl Actor<'_> {
    /// Actions [N, A] for raw observations; `start[i]`: env i starts its episode at this step. An
    /// exported policy also gives the targets (its own action mapping), which the task then steps
    /// toward instead of mapping the actions itself.
    fn act(&mut self, obs: &[f32], priv_obs: &[f32], start: &[bool], task: &mut dyn crate::task::TaskBatch) -> Result<(Vec<f32>, Option<Vec<Targets>>)> {
        match self {
            Actor::Ppo(p) => Ok((p.act_mean(obs, priv_obs)?, None)),
            Actor::Sac(p) => Ok((p.act_mean(obs)?, None)),
            Actor::Borrowed(p) => Ok((p.act_mean(obs, priv_obs)?, None)),
            Actor::Student(s) => Ok((s.act_mean(obs, start)?, None)),
            Actor::Exported(c) => {
                // the reference the deployment follows: each env's first frame (for envs that
                // start) and its frame at the end of this step
                let first = if start.iter().any(|&s| s) { task.reference_frames(0)? } else { None };
                let next = task.reference_frames(1)?;
                let (a, t) = c.act(obs, priv_obs, start, first.as_deref(), next.as_deref())?;
                Ok((a, Some(t)))
            }
        }
    }
}

/// What the finished episodes of every round add up to.
#[derive(Default)]
struct Tally {
    rows: Vec<EpisodeRow>,
    /// Per episode: the object's lift at its end and its highest lift, m.
    final_lift: Vec<f64>,
    max_lift: Vec<f64>,
    /// Per episode: its deepest hand–object penetration, mm.
    peak_pen_mm: Vec<f64>,
    /// Frames of running episodes, and those with a penetration over 1 mm.
    frames: u64,
    frames_over_1mm: u64,
    /// The deepest penetration of any frame, mm.
    max_pen_mm: f64,
    /// Σ and count of the fingertip forces over the contact threshold, N.
    force_sum: f64,
    force_n: u64,
    /// The reward terms' names and their Σ over the frames.
    term_names: Vec<String>,
    term_sums: Vec<f64>,
    /// Per student episode (with its teacher): the mean latent error ‖z − ẑ‖.
    latent_err: Vec<f64>,
}

impl Tally {
    /// The report's figures; `object_names`: the config's objects in order.
    fn summary(self, object_names: &[String], has_reference: bool) -> Summary {
        let total_frames = self.frames.max(1) as f64;
        let reward_terms = self.term_names.iter().zip(&self.term_sums).map(|(k, v)| (k.clone(), serde_json::json!(v / total_frames))).collect();
        let rows = self.rows;
        let n_ep = rows.len().max(1) as f64;
        let col = |f: fn(&EpisodeRow) -> f64| rows.iter().map(f).collect::<Vec<f64>>();
        // a tracking metric over episodes: None for lift
        let tracking = |f: fn(&EpisodeRow) -> Option<f64>| has_reference.then(|| mean_std(&rows.iter().filter_map(f).collect::<Vec<f64>>()));
        Summary {
            success_rate: rows.iter().filter(|r| r.success).count() as f64 / n_ep,
            terminated_rate: rows.iter().filter(|r| r.terminated).count() as f64 / n_ep,
            episode_return: mean_std(&col(|r| r.ret)),
            episode_length: mean_std(&col(|r| r.length as f64)),
            final_lift_height_m: mean_std(&self.final_lift),
            max_lift_height_m: mean_std(&self.max_lift),
            ote_m: tracking(|r| r.ote_m),
            ooe_deg: tracking(|r| r.ooe_deg),
            terminal_obj_pos_err_m: tracking(|r| r.terminal_pos_err_m),
            terminal_obj_rot_err_deg: tracking(|r| r.terminal_rot_err_deg),
            reward_terms,
            peak_penetration_mm: self.max_pen_mm,
            episode_peak_penetration_mm: mean_std(&self.peak_pen_mm),
            frac_frames_penetration_over_1mm: self.frames_over_1mm as f64 / total_frames,
            mean_fingertip_force_n: if self.force_n > 0 { self.force_sum / self.force_n as f64 } else { 0.0 },
            latent_error: (!self.latent_err.is_empty()).then(|| mean_std(&self.latent_err)),
            per_object: object_summaries(&rows, object_names, has_reference),
            per_episode: rows,
        }
    }
}

/// One round's envs, each running its one episode: what is summed while it runs.
struct RoundEpisodes {
    done: Vec<bool>,
    ret: Vec<f64>,
    len: Vec<u32>,
    /// The highest lift so far, m; the deepest penetration so far, mm, its step and the lift then.
    lift_max: Vec<f64>,
    pen_max_mm: Vec<f64>,
    pen_max_at: Vec<(u32, f64)>,
    /// Σ of the object's position error (m) and rotation error (degrees) over the steps.
    err_sum: Vec<(f64, f64)>,
    /// Σ of the latent error ‖z − ẑ‖ over the steps (a student beside its teacher).
    latent_sum: Vec<f64>,
    /// Each env's reference (its name; empty for lift) and object, as its reset drew them.
    refs: Vec<String>,
    objects: Vec<String>,
}

/// What a round's steps are measured with.
struct StepRules {
    has_reference: bool,
    /// Whether the latent error is measured (a student beside its teacher).
    with_latent: bool,
    /// The critic observation's columns of the fingertip forces, and its width.
    force_cols: Vec<usize>,
    priv_dim: usize,
    /// A fingertip force counts from this, N (`task.hand.contact_force`).
    contact_force: f64,
}

impl RoundEpisodes {
    fn new(refs: Vec<String>, objects: Vec<String>) -> RoundEpisodes {
        let n = refs.len();
        RoundEpisodes {
            done: vec![false; n],
            ret: vec![0.0; n],
            len: vec![0; n],
            lift_max: vec![0.0; n],
            pen_max_mm: vec![0.0; n],
            pen_max_at: vec![(0, 0.0); n],
            err_sum: vec![(0.0, 0.0); n],
            latent_sum: vec![0.0; n],
            refs,
            objects,
        }
    }

    /// Whether an episode of the round still runs.
    fn running(&self) -> bool {
        self.done.iter().any(|d| !d)
    }

    /// Adds the latent error of this step's running episodes: the student's latent `z` [N, L]
    /// against its teacher's `ẑ` [N, L].
    fn add_latent(&mut self, z: &[f32], z_hat: &[f32], l: usize) {
        for i in 0..self.done.len() {
            if !self.done[i] {
                let e: f64 = (0..l).map(|k| ((z[i * l + k] - z_hat[i * l + k]) as f64).powi(2)).sum();
                self.latent_sum[i] += e.sqrt();
            }
        }
    }

    /// Adds env step `b` to the running episodes; an episode that ended goes into `tally`.
    fn add_step(&mut self, b: &StepBatch, rules: &StepRules, tally: &mut Tally) {
        let nt = tally.term_names.len();
        let pd = rules.priv_dim;
        for i in 0..self.done.len() {
            if self.done[i] {
                continue;
            }
            self.ret[i] += b.reward[i] as f64;
            self.len[i] += 1;
            for k in 0..nt {
                tally.term_sums[k] += b.terms[i * nt + k] as f64;
            }
            let pen_mm = b.max_pen[i] as f64 * 1000.0;
            if pen_mm > self.pen_max_mm[i] {
                self.pen_max_mm[i] = pen_mm;
                self.pen_max_at[i] = (self.len[i], b.lift_height[i] as f64);
            }
            tally.max_pen_mm = tally.max_pen_mm.max(pen_mm);
            tally.frames += 1;
            tally.frames_over_1mm += (pen_mm > 1.0) as u64;
            self.lift_max[i] = self.lift_max[i].max(b.lift_height[i] as f64);
            self.err_sum[i].0 += b.obj_pos_err[i] as f64;
            self.err_sum[i].1 += (b.obj_rot_err[i] as f64).to_degrees();
            if !b.done(i) {
                // forces of this step (a done env's critic obs are its next episode's first)
                for &k in &rules.force_cols {
                    let f = b.priv_obs[i * pd + k] as f64;
                    if f > rules.contact_force {
                        tally.force_sum += f;
                        tally.force_n += 1;
                    }
                }
                continue;
            }
            self.done[i] = true;
            let l = self.len[i].max(1) as f64;
            if rules.with_latent {
                tally.latent_err.push(self.latent_sum[i] / l);
            }
            let has_reference = rules.has_reference;
            tally.rows.push(EpisodeRow {
                ret: self.ret[i],
                length: self.len[i],
                success: b.success[i],
                terminated: b.terminated[i],
                ote_m: has_reference.then(|| self.err_sum[i].0 / l),
                ooe_deg: has_reference.then(|| self.err_sum[i].1 / l),
                terminal_pos_err_m: has_reference.then(|| b.obj_pos_err[i] as f64),
                terminal_rot_err_deg: has_reference.then(|| (b.obj_rot_err[i] as f64).to_degrees()),
                reference: self.refs[i].clone(),
                object: self.objects[i].clone(),
                final_lift_m: b.lift_height[i] as f64,
                peak_penetration_mm: self.pen_max_mm[i],
                peak_penetration_step: self.pen_max_at[i].0,
                lift_at_peak_m: self.pen_max_at[i].1,
            });
            tally.final_lift.push(b.lift_height[i] as f64);
            tally.max_lift.push(self.lift_max[i]);
            tally.peak_pen_mm.push(self.pen_max_mm[i]);
        }
    }
}

/// Every episode of an evaluation (the policy's, or a baseline's), the env backend and the
/// learner device.
pub(crate) fn run_episodes(cfg: &Config, source: PolicySource, args: &EvalArgs, driver: Driver) -> Result<(Summary, String, String)> {
    let (summary, env_backend, device_name, _) = run_episodes_filmed(cfg, source, args, driver, 0)?;
    Ok((summary, env_backend, device_name))
}

/// The episodes of the first `video_envs` envs of the first round, kept for a video, and the GPU
/// context their envs ran on (None on the CPU).
#[derive(Default)]
pub(crate) struct Filmed {
    pub(crate) episodes: Vec<VideoEpisode>,
    pub(crate) gpu: Option<crate::gpu::context::GpuContext>,
}

/// [`run_episodes`], keeping every frame of the episodes of the first round's first
/// `video_envs` envs (at most the round's envs) for a video.
pub(crate) fn run_episodes_filmed(cfg: &Config, source: PolicySource, args: &EvalArgs, driver: Driver, video_envs: usize) -> Result<(Summary, String, String, Filmed)> {
    let episodes = args.episodes.max(1);
    let max_envs = args.max_envs.max(1);
    // the reference kinds measure the object against a reference; lift has none
    let has_reference = cfg.task.kind.follows_reference();
    let ref_names: Vec<String> = if has_reference { reference_names(&reference_paths(cfg)?) } else { Vec::new() };
    let mut tally = Tally::default();
    let mut filmed = Filmed::default();
    let (mut object_names, mut env_backend, mut device_name) = (Vec::new(), String::new(), String::new());
    // the live view (`--live`), started by the first round, shows every round
    let mut live = None;
    for round in 0..episodes.div_ceil(max_envs) {
        let n = (episodes - round * max_envs).min(max_envs);
        let film = if round == 0 { Some((video_envs.min(n), &mut filmed)) } else { None };
        // the config's objects, in order (the same every round)
        (object_names, env_backend, device_name) = run_round(cfg, round, n, source, args, driver, &ref_names, &mut tally, film, &mut live)?;
    }
    Ok((tally.summary(&object_names, has_reference), env_backend, device_name, filmed))
}

/// Round `round` of `n` envs: each runs one episode into `tally`; `film` = (k, into): the
/// episodes of envs 0..k go into `into`, every frame. Returns the config's object names, the env
/// backend and the learner device.
#[allow(clippy::too_many_arguments)]
fn run_round(cfg: &Config, round: usize, n: usize, source: PolicySource, args: &EvalArgs, driver: Driver, ref_names: &[String], tally: &mut Tally, film: Option<(usize, &mut Filmed)>, live: &mut Option<crate::live::LiveView>) -> Result<(Vec<String>, String, String)> {
    let open_loop = driver == Driver::OpenLoop;
    let has_reference = cfg.task.kind.follows_reference();
    let mut c = cfg.clone();
    c.sim.num_envs = n;
    c.task.open_loop = open_loop;
    // episodes run to the reference's end: an early termination on the object's error
    // (`task.track.max_object_error`, a training aid) would cap the terminal error it reports
    c.task.track.max_object_error = 0.0;
    // each round draws other episodes: the seed moves by the round
    c.seed = cfg.seed.wrapping_add(round as u32 * 7919);
    c.validate()?;
    let model = SimModel::from_config(&c)?;
    let object_names: Vec<String> = model.objects.iter().map(|o| o.name.clone()).collect();
    let mut task = make_task_batch(&c, model.clone())?;
    let spec = task.spec().clone();
    let env_backend = task.backend_name();
    if live.is_none() {
        *live = args.live.start(&model, spec.control_dt, None, true)?;
    }
    let (mut actor, teacher_loaded, device_name) = round_actor(&c, source, driver, &spec, &model, n, task.as_ref())?;
    let teacher: Option<&Ppo> = match (source, &actor, driver) {
        (PolicySource::Distilling { teacher, .. }, Actor::Student(s), Driver::Policy) if s.student.latent > 0 => Some(teacher),
        _ => teacher_loaded.as_deref(),
    };
    tally.term_names = spec.term_names.clone();
    tally.term_sums.resize(tally.term_names.len(), 0.0);
    // the fingertip forces are critic observations (every kind's critic has them)
    let force_cols = crate::task::spec::field_indices(&spec.priv_layout, &[crate::task::spec::TIP_FORCE.to_string()]).map_err(|m| anyhow::anyhow!("the task's critic observation: {m}"))?;
    let rules = StepRules {
        has_reference,
        with_latent: teacher.is_some(),
        force_cols,
        priv_dim: spec.priv_dim,
        contact_force: c.task.hand.contact_force as f64,
    };
    let first = task.reset_all()?;
    let (mut obs, mut priv_obs) = (first.obs.clone(), first.priv_obs.clone());
    // the reference and the object of each env's (only) episode, drawn at the reset
    let (env_snap, ts) = decode_snapshot(&task.save_state()?, n, model.globals.n_springs as usize)?;
    let refs: Vec<String> = if !has_reference { vec![String::new(); n] } else { ts.iter().map(|t| ref_names.get(t.cursor.ref_id as usize).cloned().unwrap_or_default()).collect() };
    let objects: Vec<String> = env_snap.params.iter().map(|p| model.objects[p.obj_index as usize].name.clone()).collect();
    // env i's recording: its object as its reset drew it
    let meta_of = |i: usize| {
        let p = &env_snap.params[i];
        RolloutMeta {
            hand: model.hand.clone(),
            object: crate::record::object_parts(&model.objects[p.obj_index as usize], p.obj_scale),
            dt: spec.control_dt,
            info: serde_json::json!({"run": args.run.display().to_string(), "checkpoint": source.describe(), "seed": c.seed, "env": i}),
        }
    };
    let mut writer = match (&args.record, round, open_loop) {
        (Some(path), 0, false) => Some(RolloutWriter::create(path, &meta_of(0))?),
        _ => None,
    };
    // the filmed envs 0..k: their episodes, filled frame by frame
    let (film_k, mut filmed) = match film {
        Some((k, into)) if k > 0 => {
            into.gpu = task.gpu_context().cloned();
            let start = into.episodes.len();
            into.episodes.extend((0..k).map(|i| VideoEpisode { meta: meta_of(i), frames: Vec::new(), success: None }));
            (k, Some(&mut into.episodes[start..]))
        }
        _ => (0, None),
    };
    let mut episodes = RoundEpisodes::new(refs, objects);
    let mut t = 0.0f64;
    let recorded = (writer.is_some() as usize).max(film_k);
    if recorded > 0 {
        let frames = rollout_frames(&model, task.as_mut(), recorded, t)?;
        keep_frames(frames, &vec![true; recorded], writer.as_mut(), filmed.as_deref_mut())?;
    }
    let zeros = vec![0.0f32; n * spec.action_dim];
    let mut start = vec![true; n];
    while episodes.running() {
        let (actions, targets) = if open_loop { (zeros.clone(), None) } else { actor.act(&obs, &priv_obs, &start, task.as_mut())? };
        if let (Some(t), Actor::Student(s)) = (&teacher, &actor) {
            // ẑ = μ(ĉ) of the teacher on the critic observation, normalised as it trained
            let mut p = priv_obs.clone();
            if t.normalize {
                t.priv_norm.apply(&mut p);
            }
            let pt = crate::learn::nets::to_tensor(p, [n, spec.priv_dim], &t.device);
            if let Some(zh) = t.net.latent(&t.net.inference_params(), pt) {
                episodes.add_latent(&s.last_latent, &crate::learn::nets::to_host(zh)?, s.student.latent);
            }
        }
        let b = match &targets {
            Some(tg) => task.step_with_targets(&actions, tg)?,
            None => task.step(&actions)?,
        };
        // an env whose episode ended starts its next one (not counted) at the next step
        for (i, s) in start.iter_mut().enumerate() {
            *s = b.done(i);
        }
        t += spec.control_dt as f64;
        // a recorded env whose episode ends at this step: its outcome (its state is already the
        // next episode's, not recorded)
        let was_running: Vec<bool> = (0..recorded).map(|i| !episodes.done[i]).collect();
        if let Some(f) = filmed.as_deref_mut() {
            for (i, e) in f.iter_mut().enumerate() {
                if was_running[i] && b.done(i) {
                    e.success = Some(b.success[i]);
                }
            }
        }
        episodes.add_step(b, &rules, tally);
        let running: Vec<bool> = (0..recorded).map(|i| !episodes.done[i]).collect();
        obs = b.obs.clone();
        priv_obs = b.priv_obs.clone();
        if running.iter().any(|&r| r) {
            let frames = rollout_frames(&model, task.as_mut(), recorded, t)?;
            keep_frames(frames, &running, writer.as_mut(), filmed.as_deref_mut())?;
        }
        if let Some(l) = live.as_mut() {
            l.after_step(task.as_mut())?;
        }
    }
    if let Some(w) = writer.take() {
        w.finish()?;
    }
    Ok((object_names, env_backend, device_name))
}

/// The round's policy from `source` for `driver`, the teacher a student's latent error is measured
/// against where the student came from a checkpoint (None where it has no latent, or its teacher
/// run is gone: then it is evaluated without the latent error), and the learner device's name.
fn round_actor<'a>(c: &Config, source: PolicySource<'a>, driver: Driver, spec: &TaskSpec, model: &SimModel, n: usize, task: &dyn TaskBatch) -> Result<(Actor<'a>, Option<Box<Ppo>>, String)> {
    match source {
        PolicySource::Checkpoint(ckpt) => {
            // the learner device: where a checkpoint's policy is loaded (the other sources bring
            // theirs). With train.device = "auto" and the envs on the CPU the policy runs on the
            // CPU too: eval's small batches gain nothing from a GPU of their own, and `eval
            // --backend cpu` then touches no GPU at all
            let choice = match (&c.train.device, task.gpu_context()) {
                (BackendChoice::Auto, None) => BackendChoice::Cpu,
                (chosen, _) => chosen.clone(),
            };
            let (device, device_name) = learner_device(&choice, task.gpu_context())?;
            let actor = load_actor(c, ckpt, spec, n, device.clone(), driver)?;
            let teacher = match (&actor, driver) {
                (Actor::Student(s), Driver::Policy) if s.student.latent > 0 => match load_actor(c, ckpt, spec, n, device, Driver::Teacher) {
                    Ok(Actor::Ppo(p)) => Some(p),
                    Ok(Actor::Borrowed(_) | Actor::Sac(_) | Actor::Student(_) | Actor::Exported(_)) => None,
                    Err(e) => {
                        crate::console::warn(&format!("warning: no latent error: cannot load the student's teacher: {}", crate::text::one_line(&format!("{e:#}"))));
                        None
                    }
                },
                _ => None,
            };
            Ok((actor, teacher, device_name))
        }
        PolicySource::Distilling { student, teacher } => {
            // both in memory (the latent error's teacher is the source's, [`run_round`])
            let actor = match driver {
                Driver::Teacher => Actor::Borrowed(teacher),
                _ => Actor::Student(Box::new(student.clone())),
            };
            Ok((actor, None, "the distillation run's learner".into()))
        }
        PolicySource::Export(contract) => {
            let urdf_path = c.resolve(&c.hand.urdf);
            let urdf = std::fs::read(&urdf_path).with_context(|| format!("cannot read the hand URDF {}", urdf_path.display()))?;
            let controller = crate::export::controller::Controller::load(contract, &urdf, spec, model, n)?;
            Ok((Actor::Exported(Box::new(controller)), None, "onnx (tract, cpu)".into()))
        }
    }
}

/// The episodes of each object in `names` (the config's order) that has any.
fn object_summaries(rows: &[EpisodeRow], names: &[String], has_reference: bool) -> Vec<ObjectSummary> {
    names
        .iter()
        .filter_map(|name| {
            let eps: Vec<&EpisodeRow> = rows.iter().filter(|r| &r.object == name).collect();
            if eps.is_empty() {
                return None;
            }
            let col = |f: &dyn Fn(&EpisodeRow) -> Option<f64>| mean_std(&eps.iter().filter_map(|r| f(r)).collect::<Vec<f64>>());
            Some(ObjectSummary {
                object: name.clone(),
                episodes: eps.len(),
                success_rate: eps.iter().filter(|r| r.success).count() as f64 / eps.len() as f64,
                final_lift_height_m: col(&|r| Some(r.final_lift_m)),
                terminal_obj_pos_err_m: has_reference.then(|| col(&|r| r.terminal_pos_err_m)),
                terminal_obj_rot_err_deg: has_reference.then(|| col(&|r| r.terminal_rot_err_deg)),
            })
        })
        .collect()
}

/// The policy that drives `driver`'s episodes: the run's (`learn::policy::load_policy`: PPO, SAC or
/// a distilled student), or a student's teacher (its run and the checkpoint the student's
/// checkpoint names). Open-loop episodes load the run's policy too, and do not use it.
fn load_actor(c: &Config, ckpt: &std::path::Path, spec: &crate::task::TaskSpec, n: usize, device: burn::prelude::Device, driver: Driver) -> Result<Actor<'static>> {
    use crate::learn::policy::{LoadedPolicy, load_policy, load_ppo};
    if driver != Driver::Teacher {
        return Ok(match load_policy(c, spec, ckpt, n, device)? {
            LoadedPolicy::Ppo(p) => Actor::Ppo(p),
            LoadedPolicy::Sac(s) => Actor::Sac(s),
            LoadedPolicy::Student(s) => Actor::Student(s),
        });
    }
    let s = crate::learn::distill::StudentPolicy::load(ckpt, spec.obs_dim, &device)?;
    let run = std::path::PathBuf::from(&s.teacher.0);
    let tc = checkpoint::find(&run, &s.teacher.1.to_string()).with_context(|| format!("the teacher of {}", ckpt.display()))?;
    let run_cfg = Config::load(&run.join("config.toml"))?;
    anyhow::ensure!(run_cfg.train.algorithm != crate::config::AlgorithmChoice::Sac, "{}: a SAC run cannot be a distillation teacher yet (the teacher must be a PPO run)", tc.display());
    // the learner's own random numbers: this evaluation's seed, as for the run's own policy
    Ok(Actor::Ppo(Box::new(load_ppo(&run_cfg, spec, &tc, n, device, c.seed as u64)?)))
}

/// The current state of envs 0..k, one recording frame each, at time `t` (the live view's
/// reading of the first envs: only those are read back from a GPU).
fn rollout_frames(model: &SimModel, task: &mut dyn crate::task::TaskBatch, k: usize, t: f64) -> Result<Vec<RolloutFrame>> {
    Ok(crate::live::frames::first_env_frames(model, task, k)?
        .into_iter()
        .map(|f| RolloutFrame { t, ..f.frame })
        .collect())
}

/// Env 0's frame into the recording `writer`, env i's into the filmed episode i, for the envs
/// whose episode still runs (`running[i]`).
fn keep_frames(frames: Vec<RolloutFrame>, running: &[bool], writer: Option<&mut RolloutWriter>, filmed: Option<&mut [VideoEpisode]>) -> Result<()> {
    if let Some(w) = writer
        && running[0]
    {
        w.write_frame(&frames[0])?;
    }
    if let Some(f) = filmed {
        for ((e, frame), &run) in f.iter_mut().zip(frames).zip(running) {
            if run {
                e.frames.push(frame);
            }
        }
    }
    Ok(())
}
