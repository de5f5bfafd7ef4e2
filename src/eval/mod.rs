//! `dextrain eval runs/NAME`: deterministic episodes (the policy mean) of a checkpoint on fresh
//! seeds, a JSON report in `runs/NAME/eval/`, and optionally an MCAP recording of env 0's first
//! episode that Foxglove shows in 3-D.
//!
//! Reference kinds add the tracking metrics (OTE, OOE, terminal object error) per episode and
//! aggregated (the lift task has no reference: its report leaves them out); `--baseline open-loop` evaluates the same episodes with the policy off (the targets
//! follow the reference), so the JSON and the Markdown table next to it show policy vs replay.
//!
//! Every env runs exactly one episode (envs = the number of episodes, in rounds of at most
//! `--max-envs`), so short and long episodes are counted alike. The eval seed defaults to the run's
//! seed + 1,000,003 (`--seed` overrides it): the initial states and physical parameters are draws
//! the policy never trained on. Observation noise stays as the config sets it.

mod episodes;
pub mod play;

pub(crate) use episodes::{Filmed, run_episodes, run_episodes_filmed};

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use serde::Serialize;

use crate::learn::checkpoint;
use crate::config::{Config, TaskKind};
use crate::learn::ppo::Ppo;
use crate::run_dir;

/// Arguments of `dextrain eval`.
#[derive(clap::Args, Debug, Clone)]
pub struct EvalArgs {
    /// The run directory (runs/NAME).
    pub run: PathBuf,
    /// Which checkpoint: an iteration number or "latest".
    #[arg(long, default_value = "latest")]
    pub checkpoint: String,
    /// Number of episodes (one per env).
    #[arg(long, default_value_t = 100)]
    pub episodes: usize,
    /// Most envs stepped at once.
    #[arg(long, default_value_t = 1024)]
    pub max_envs: usize,
    /// Seed of the eval episodes (default: the run's seed + 1000003).
    #[arg(long)]
    pub seed: Option<u32>,
    /// Record env 0's episode to this MCAP file.
    #[arg(long)]
    pub record: Option<PathBuf>,
    /// Env backend (overrides the run's config): cpu, gpu, gpu:NAME or auto.
    #[arg(long)]
    pub backend: Option<crate::config::BackendChoice>,
    /// Also evaluate a baseline on the same seeds: `open-loop` (reference kinds) drives the
    /// targets along the references with the policy switched off, as `dextrain replay` does.
    #[arg(long, value_enum)]
    pub baseline: Option<Baseline>,
    /// The live view (`--live`, `--live-envs`, `--live-hz`, `--live-wait`): the first envs'
    /// episodes at real time.
    #[command(flatten)]
    pub live: crate::live::LiveArgs,
    /// `--video`: render the first envs' episodes (the policy's) to a video, and the image strip
    /// `RUN/plots/eval_strip.png`.
    #[command(flatten)]
    pub video: crate::video::VideoArgs,
}

/// `dextrain eval --baseline`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Baseline {
    /// The policy switched off: the targets follow the (augmented) references, as `dextrain
    /// replay` drives them (reference kinds).
    OpenLoop,
    /// A distilled student's teacher (the run and checkpoint its checkpoint names), acting on the
    /// same seeds with its privileged observations: student and teacher side by side.
    Teacher,
}

/// Who drives a set of eval episodes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Driver {
    /// The run's policy (PPO, or a distilled student with its history windows).
    Policy,
    /// The policy switched off: the targets follow the references.
    OpenLoop,
    /// A student's teacher.
    Teacher,
}

/// Where the evaluated policy comes from.
#[derive(Clone, Copy)]
pub(crate) enum PolicySource<'a> {
    /// A run's checkpoint directory (`dextrain eval`).
    Checkpoint(&'a std::path::Path),
    /// An export's `policy.json` (`dextrain play`): the ONNX model and the contract's action
    /// mapping, nothing of the checkpoint.
    Export(&'a std::path::Path),
    /// A distillation run's student as it is now and its frozen teacher, both in memory (the run's
    /// side-by-side evaluation, `distill.eval_interval`): `Driver::Policy` runs the student,
    /// `Driver::Teacher` the teacher.
    Distilling { student: &'a crate::learn::distill::StudentPolicy, teacher: &'a Ppo },
}

/// Mean and standard deviation.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct MeanStd {
    /// Mean of the values.
    pub mean: f64,
    /// Population standard deviation of the values.
    pub std: f64,
}

fn mean_std(x: &[f64]) -> MeanStd {
    let n = x.len().max(1) as f64;
    let mean = x.iter().sum::<f64>() / n;
    let var = x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n;
    MeanStd { mean, std: var.sqrt() }
}

/// One evaluated episode. The tracking errors are `None` (left out of the JSON) for the lift
/// task, which has no reference to measure them against.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct EpisodeRow {
    /// Undiscounted return.
    pub ret: f64,
    /// Length (env steps).
    pub length: u32,
    /// The task's success at the episode's last step.
    pub success: bool,
    /// Whether the episode ended by termination rather than time-out.
    pub terminated: bool,
    /// Reference kinds: OTE, the mean object translation error (m) against the reference over the
    /// episode's steps.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ote_m: Option<f64>,
    /// Reference kinds: OOE, the mean object orientation error (deg) over the episode's steps.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ooe_deg: Option<f64>,
    /// Reference kinds: the object translation error (m) at the episode's last step.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub terminal_pos_err_m: Option<f64>,
    /// Reference kinds: the object orientation error (deg) at the episode's last step.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub terminal_rot_err_deg: Option<f64>,
    /// Reference kinds: the file name of the episode's reference (`task.reference.files`; its path
    /// when two references share a name), so that the demonstrations the policy cannot follow
    /// stand out; empty for lift.
    pub reference: String,
    /// The name of the object the episode's env held (`[object]` or `[[object.set]]`).
    pub object: String,
    /// Object lift height at the episode's last step (m).
    pub final_lift_m: f64,
    /// The episode's deepest hand–object penetration (mm), the env step (from 1) it came in, and
    /// the object's lift height then (m): whether the peak is the grasp closing on the resting
    /// object or the lift.
    pub peak_penetration_mm: f64,
    pub peak_penetration_step: u32,
    pub lift_at_peak_m: f64,
}

/// The episodes of one object (runs with several objects: each env draws one at its reset).
#[derive(Clone, Debug, Serialize)]
pub struct ObjectSummary {
    /// The object's name.
    pub object: String,
    /// Its episodes.
    pub episodes: usize,
    /// Their success rate.
    pub success_rate: f64,
    /// Object lift height at the episodes' last step (m).
    pub final_lift_height_m: MeanStd,
    /// Reference kinds: the object's translation error (m) at the episodes' last step.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub terminal_obj_pos_err_m: Option<MeanStd>,
    /// Reference kinds: the object's orientation error (deg) at the episodes' last step.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub terminal_obj_rot_err_deg: Option<MeanStd>,
}

/// What a set of episodes did (the policy's, or the open-loop baseline's). The metric names mean
/// the same as in `dextrain replay`'s report (`dextrain replay`'s `ReplayReport`). The tracking metrics
/// are `None` (left out of the JSON and of the Markdown table) for the lift task.
#[derive(Clone, Debug, Serialize)]
pub struct Summary {
    /// The task's success at the episode's last step (lift: object ≥ success height above its rest
    /// height; reference kinds: object within the tolerances of the reference's final pose).
    pub success_rate: f64,
    /// Fraction of episodes that ended by termination (drop, hand too far, object too far from its
    /// reference, bad state) rather than time-out.
    pub terminated_rate: f64,
    /// Undiscounted episode return.
    pub episode_return: MeanStd,
    /// Episode length (env steps).
    pub episode_length: MeanStd,
    /// Object lift height at the episode's last step (m).
    pub final_lift_height_m: MeanStd,
    /// Largest lift height during the episode (m).
    pub max_lift_height_m: MeanStd,
    /// Reference kinds: OTE (m), each episode's mean object translation error, over episodes.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ote_m: Option<MeanStd>,
    /// Reference kinds: OOE (deg), each episode's mean object orientation error, over episodes.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ooe_deg: Option<MeanStd>,
    /// Reference kinds: the object's translation error (m) at the episode's last step, over episodes.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub terminal_obj_pos_err_m: Option<MeanStd>,
    /// Reference kinds: the object's orientation error (deg) at the episode's last step, over episodes.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub terminal_obj_rot_err_deg: Option<MeanStd>,
    /// Mean weighted value per env step of each reward term.
    pub reward_terms: serde_json::Map<String, serde_json::Value>,
    /// Deepest hand–object penetration (mm) of any step of any episode (as replay's).
    pub peak_penetration_mm: f64,
    /// Each episode's deepest hand–object penetration (mm), over episodes.
    pub episode_peak_penetration_mm: MeanStd,
    /// Fraction of all env steps (every episode's) with a hand–object penetration > 1 mm (as replay's).
    pub frac_frames_penetration_over_1mm: f64,
    /// Mean normal force (N) of a fingertip while it touches the object: over every fingertip-step
    /// whose force exceeds `task.hand.contact_force` (the threshold of the task's contact flags), 0
    /// when none does (as replay's).
    pub mean_fingertip_force_n: f64,
    /// A distilled student's episodes: ‖z − ẑ‖, the distance between the student's latent and its
    /// teacher's on the same states, mean over each episode's steps, then mean ± std over
    /// episodes (left out otherwise).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub latent_error: Option<MeanStd>,
    /// Per object, in the order of the config's objects (those with episodes).
    pub per_object: Vec<ObjectSummary>,
    /// Every episode, in env order.
    pub per_episode: Vec<EpisodeRow>,
}

/// The eval report (written as JSON, and a Markdown table next to it).
#[derive(Clone, Debug, Serialize)]
pub struct EvalReport {
    /// The run directory.
    pub run: String,
    /// The checkpoint directory evaluated.
    pub checkpoint: String,
    /// The checkpoint's iteration.
    pub iteration: u64,
    /// Seed of the eval episodes.
    pub seed: u32,
    /// Number of episodes.
    pub episodes: usize,
    /// The task kind (`task.kind`).
    pub task: String,
    /// The env backend that ran the episodes.
    pub env_backend: String,
    /// The device the policy ran on.
    pub learner_device: String,
    /// The policy's episodes (deterministic: the policy mean).
    #[serde(flatten)]
    pub policy: Summary,
    /// `--baseline open-loop`: the same episodes (same seeds, references and augmentation) with
    /// the policy switched off and the targets driven along the reference, as `dextrain replay`;
    /// `--baseline teacher`: the same episodes driven by a student's teacher. Left out of the JSON
    /// without `--baseline`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub baseline: Option<Summary>,
    /// What the baseline is: "open-loop", "teacher" (empty without `--baseline`).
    #[serde(skip_serializing_if = "String::is_empty")]
    pub baseline_kind: String,
    /// The report's path (not in the JSON).
    #[serde(skip)]
    pub path: PathBuf,
}

/// Checks that every number of a report is finite: serde_json writes a NaN or an infinity as
/// `null`, and the reports leave absent values out rather than writing `null`, so any `null` in
/// the serialised report is a non-finite value. The error is one line naming the field's path
/// (e.g. `baseline.ote_m.mean`); `what` names the report.
pub fn check_finite<T: Serialize>(report: &T, what: &str) -> Result<()> {
    let value = serde_json::to_value(report).with_context(|| format!("cannot serialise the {what}"))?;
    // depth-first over (path, value); arrays index by position
    let mut stack: Vec<(String, &serde_json::Value)> = vec![(String::new(), &value)];
    while let Some((path, v)) = stack.pop() {
        let join = |k: &str| if path.is_empty() { k.to_string() } else { format!("{path}.{k}") };
        match v {
            serde_json::Value::Null => {
                bail!("{what}: field `{path}` is not a finite number (NaN or infinite): expected every reported value finite")
            }
            serde_json::Value::Object(m) => stack.extend(m.iter().rev().map(|(k, v)| (join(k), v))),
            serde_json::Value::Array(a) => stack.extend(a.iter().enumerate().rev().map(|(i, v)| (join(&i.to_string()), v))),
            _ => {}
        }
    }
    Ok(())
}

/// Runs the evaluation and writes the report.
pub fn run(args: &EvalArgs) -> Result<EvalReport> {
    run_dir::check_run(&args.run)?;
    let ckpt = checkpoint::find(&args.run, &args.checkpoint)?;
    let state = checkpoint::read_state(&ckpt)?;
    let mut cfg = Config::load(&args.run.join("config.toml"))?;
    let seed = args.seed.unwrap_or(cfg.seed.wrapping_add(1_000_003));
    cfg.seed = seed;
    if let Some(b) = &args.backend {
        cfg.sim.backend = b.clone();
    }
    let baseline = match args.baseline {
        None => None,
        Some(Baseline::OpenLoop) => {
            if cfg.task.kind == TaskKind::Lift {
                bail!("--baseline open-loop: the lift task has no reference to replay; expected a run of task.kind = track, residual_joint or residual_task");
            }
            Some(Driver::OpenLoop)
        }
        Some(Baseline::Teacher) => {
            if cfg.train.algorithm != crate::config::AlgorithmChoice::Distill {
                bail!("--baseline teacher: {} is not a distilled student (train.algorithm = \"{}\"); expected a run of train.algorithm = \"distill\"", args.run.display(), serde_json::to_value(cfg.train.algorithm).ok().and_then(|v| v.as_str().map(String::from)).unwrap_or_default());
            }
            Some(Driver::Teacher)
        }
    };
    // a bad --video fails before the episodes run
    let video_envs = args.video.episodes_to_film()?;
    let video_ctx = args.video.render_context()?;
    let (policy, env_backend, device_name, filmed) = run_episodes_filmed(&cfg, PolicySource::Checkpoint(&ckpt), args, Driver::Policy, video_envs)?;
    if let (Some(path), Some(ctx)) = (&args.video.video, video_ctx) {
        film(path, &args.video, filmed, ctx, Some(&args.run.join("plots").join(EVAL_STRIP_PNG)))?;
    }
    let base = match baseline {
        Some(d) => Some(run_episodes(&cfg, PolicySource::Checkpoint(&ckpt), args, d)?.0),
        None => None,
    };
    let suffix = match baseline {
        Some(Driver::OpenLoop) => "_openloop",
        Some(Driver::Teacher) => "_teacher",
        _ => "",
    };
    let mut report = EvalReport {
        run: args.run.display().to_string(),
        checkpoint: ckpt.display().to_string(),
        iteration: state.iteration,
        seed,
        episodes: policy.per_episode.len(),
        task: cfg.task.kind.to_string(),
        env_backend,
        learner_device: device_name,
        policy,
        baseline: base,
        baseline_kind: match baseline {
            Some(Driver::OpenLoop) => "open-loop".into(),
            Some(Driver::Teacher) => "teacher".into(),
            _ => String::new(),
        },
        path: PathBuf::new(),
    };
    let dir = args.run.join("eval");
    std::fs::create_dir_all(&dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let stem = format!("eval_it{}_seed{}_n{}{suffix}", state.iteration, seed, report.episodes);
    let path = dir.join(format!("{stem}.json"));
    check_finite(&report, "eval report")?;
    let json = serde_json::to_string_pretty(&report).context("cannot serialise the eval report")?;
    std::fs::write(&path, json).with_context(|| format!("cannot write {}", path.display()))?;
    let md = dir.join(format!("{stem}.md"));
    std::fs::write(&md, markdown(&report)).with_context(|| format!("cannot write {}", md.display()))?;
    report.path = path;
    Ok(report)
}

/// The image strip `eval --video` writes into the run's `plots/`: the first and last frame of each
/// filmed episode.
pub const EVAL_STRIP_PNG: &str = "eval_strip.png";

/// Renders the filmed episodes to the video at `path` (and the image strip at `strip`, if given),
/// on the evaluation's GPU if it had one, else on `ctx` (`VideoArgs::render_context`), and says on
/// stderr what it wrote.
pub(crate) fn film(path: &Path, video: &crate::video::VideoArgs, filmed: Filmed, ctx: crate::gpu::context::GpuContext, strip: Option<&Path>) -> Result<()> {
    anyhow::ensure!(!filmed.episodes.is_empty(), "video {}: no episodes to render (--video-episodes {})", path.display(), video.video_episodes);
    let ctx = filmed.gpu.unwrap_or(ctx);
    let v = crate::video::write_video(path, &filmed.episodes, ctx, video.video_size)?;
    let per_frame_ms = 1e3 * (v.render_s + v.encode_s) / v.frames.max(1) as f64;
    crate::console::status(&format!(
        "  video {} ({} episodes, {} frames, {}x{} at {:.0} fps; rendered on {}, {per_frame_ms:.1} ms per frame)",
        path.display(),
        filmed.episodes.len(),
        v.frames,
        v.width,
        v.height,
        v.fps,
        v.adapter
    ));
    if let Some(strip) = strip {
        crate::video::eval_strip(strip, &v)?;
        crate::console::status(&format!("  image strip (first and last frame of each episode) {}", strip.display()));
    }
    Ok(())
}

/// The report as `dextrain eval` and `play` print it on stdout (one JSON line): every figure, and
/// the per-episode rows (`per_episode`, in the report file always) only when `episodes` is true
/// (`--episodes-json`).
pub fn stdout_json(report: &EvalReport, episodes: bool) -> Result<serde_json::Value> {
    let mut v = serde_json::to_value(report).context("cannot serialise the eval report")?;
    if !episodes {
        // the policy's summary is flattened into the top level; the baseline's is a field
        if let Some(top) = v.as_object_mut() {
            top.remove("per_episode");
            if let Some(base) = top.get_mut("baseline").and_then(|b| b.as_object_mut()) {
                base.remove("per_episode");
            }
        }
    }
    Ok(v)
}

/// A few lines for a person (stderr): what was evaluated, the success rate and the key errors of
/// the policy (and baseline), and where the report, its table and the recording are.
pub fn human_summary(r: &EvalReport, record: Option<&Path>) -> String {
    let line = |who: &str, s: &Summary| {
        let mut parts = vec![format!("success {:.1} %", 100.0 * s.success_rate)];
        if let Some(m) = &s.terminal_obj_pos_err_m {
            parts.push(format!("terminal object error {:.1} ± {:.1} mm", m.mean * 1e3, m.std * 1e3));
        }
        if let Some(m) = &s.ote_m {
            parts.push(format!("OTE {:.1} mm", m.mean * 1e3));
        }
        if let Some(m) = &s.ooe_deg {
            parts.push(format!("OOE {:.1}°", m.mean));
        }
        if s.ote_m.is_none() {
            parts.push(format!("final lift {:.1} ± {:.1} cm", s.final_lift_height_m.mean * 1e2, s.final_lift_height_m.std * 1e2));
        }
        parts.push(format!("peak penetration {:.1} mm", s.peak_penetration_mm));
        parts.push(format!("terminated {:.0} %", 100.0 * s.terminated_rate));
        format!("  {who}: {}", parts.join(", "))
    };
    let mut out = vec![format!("dextrain eval: {} episodes of {} (iteration {}, {}, seed {})", r.episodes, r.run, r.iteration, r.task, r.seed)];
    out.push(line("policy", &r.policy));
    if let Some(b) = &r.baseline {
        out.push(line(&r.baseline_kind, b));
    }
    if !r.path.as_os_str().is_empty() {
        out.push(format!("  report {} (every episode), table {}", r.path.display(), r.path.with_extension("md").display()));
    }
    if let Some(p) = record {
        out.push(format!("  recording (env 0, for Foxglove) {}", p.display()));
    }
    out.join("\n")
}

/// The short Markdown table of a report: policy (and baseline) side by side.
pub fn markdown(r: &EvalReport) -> String {
    let mut cols: Vec<(&str, &Summary)> = vec![("policy", &r.policy)];
    if let Some(b) = &r.baseline {
        cols.push((if r.baseline_kind == "teacher" { "teacher" } else { "open-loop replay" }, b));
    }
    let ms = |m: &MeanStd, scale: f64, digits: usize| format!("{:.*} ± {:.*}", digits, m.mean * scale, digits, m.std * scale);
    // a row whose metric applies to no column (the tracking errors of lift) is left out
    type Cell = Box<dyn Fn(&Summary) -> Option<String>>;
    let rows: Vec<(&str, Cell)> = vec![
        ("success rate", Box::new(|s: &Summary| Some(format!("{:.1} %", 100.0 * s.success_rate)))),
        ("OTE (mm)", Box::new(move |s: &Summary| s.ote_m.as_ref().map(|m| ms(m, 1e3, 1)))),
        ("OOE (deg)", Box::new(move |s: &Summary| s.ooe_deg.as_ref().map(|m| ms(m, 1.0, 1)))),
        ("terminal object error (mm)", Box::new(move |s: &Summary| s.terminal_obj_pos_err_m.as_ref().map(|m| ms(m, 1e3, 1)))),
        ("terminal object error (deg)", Box::new(move |s: &Summary| s.terminal_obj_rot_err_deg.as_ref().map(|m| ms(m, 1.0, 1)))),
        ("terminated", Box::new(|s: &Summary| Some(format!("{:.1} %", 100.0 * s.terminated_rate)))),
        ("episode return", Box::new(move |s: &Summary| Some(ms(&s.episode_return, 1.0, 2)))),
        ("peak penetration (mm)", Box::new(|s: &Summary| Some(format!("{:.2}", s.peak_penetration_mm)))),
        ("episode peak penetration (mm)", Box::new(move |s: &Summary| Some(ms(&s.episode_peak_penetration_mm, 1.0, 2)))),
        ("frames with penetration > 1 mm", Box::new(|s: &Summary| Some(format!("{:.1} %", 100.0 * s.frac_frames_penetration_over_1mm)))),
        ("mean fingertip force (N)", Box::new(|s: &Summary| Some(format!("{:.2}", s.mean_fingertip_force_n)))),
        ("latent error ‖z − ẑ‖", Box::new(move |s: &Summary| s.latent_error.as_ref().map(|m| ms(m, 1.0, 4)))),
    ];
    let mut out = format!(
        "# Evaluation of {} ({}, iteration {}, seed {}, {} episodes)\n\n| metric | {} |\n|---|{}\n",
        r.run,
        r.task,
        r.iteration,
        r.seed,
        r.episodes,
        cols.iter().map(|c| c.0).collect::<Vec<_>>().join(" | "),
        "---|".repeat(cols.len())
    );
    for (name, f) in &rows {
        let cells: Vec<Option<String>> = cols.iter().map(|c| f(c.1)).collect();
        if cells.iter().all(Option::is_none) {
            continue;
        }
        let cells: Vec<String> = cells.into_iter().map(|c| c.unwrap_or_else(|| "–".into())).collect();
        out.push_str(&format!("| {name} | {} |\n", cells.join(" | ")));
    }
    // several objects: per object, its episodes' success, final lift and terminal error
    if r.policy.per_object.len() > 1 {
        // the terminal object error only where there is one (the reference kinds)
        let has_error = r.policy.per_object.iter().any(|o| o.terminal_obj_pos_err_m.is_some());
        out.push_str(&format!(
            "\nPer object: successes, final lift (mean){}\n\n| object | {} |\n|---|{}\n",
            if has_error { " and terminal object error (mean)" } else { "" },
            cols.iter().map(|c| c.0).collect::<Vec<_>>().join(" | "),
            "---|".repeat(cols.len())
        ));
        for o in &r.policy.per_object {
            let cell = |s: &Summary| {
                s.per_object.iter().find(|x| x.object == o.object).map_or("–".to_string(), |x| {
                    let err = x.terminal_obj_pos_err_m.as_ref().map_or(String::new(), |m| format!(", {:.1} mm", m.mean * 1e3));
                    format!("{}/{} ({:.1} %), lift {:.1} mm{err}", (x.success_rate * x.episodes as f64).round(), x.episodes, 100.0 * x.success_rate, x.final_lift_height_m.mean * 1e3)
                })
            };
            out.push_str(&format!("| {} | {} |\n", o.object, cols.iter().map(|c| cell(c.1)).collect::<Vec<_>>().join(" | ")));
        }
    }
    // reference kinds: per reference, its episodes' mean terminal error and success
    let mut names: Vec<&str> = r.policy.per_episode.iter().map(|e| e.reference.as_str()).filter(|n| !n.is_empty()).collect();
    names.sort_unstable();
    names.dedup();
    if !names.is_empty() {
        let per_ref = |s: &Summary, name: &str| {
            let eps: Vec<&EpisodeRow> = s.per_episode.iter().filter(|e| e.reference == name).collect();
            let k = eps.len().max(1) as f64;
            let err = eps.iter().filter_map(|e| e.terminal_pos_err_m).sum::<f64>() / k;
            let ok = eps.iter().filter(|e| e.success).count();
            format!("{:.1} mm, {ok}/{}", err * 1e3, eps.len())
        };
        out.push_str(&format!(
            "\nPer reference: terminal object error (mean) and successes\n\n| reference | {} |\n|---|{}\n",
            cols.iter().map(|c| c.0).collect::<Vec<_>>().join(" | "),
            "---|".repeat(cols.len())
        ));
        for name in names {
            out.push_str(&format!("| {name} | {} |\n", cols.iter().map(|c| per_ref(c.1, name)).collect::<Vec<_>>().join(" | ")));
        }
    }
    out
}

/// The names the report gives the bank's references, in its order: their file names, or their whole
/// paths where two file names are the same (two datasets with a `ref_000.mcap` each).
pub fn reference_names(paths: &[PathBuf]) -> Vec<String> {
    let names: Vec<String> = paths.iter().map(|p| p.file_name().map(|f| f.to_string_lossy().into_owned()).unwrap_or_default()).collect();
    let unique = names.iter().collect::<std::collections::HashSet<_>>().len() == names.len();
    if unique { names } else { paths.iter().map(|p| p.display().to_string()).collect() }
}

impl PolicySource<'_> {
    /// The checkpoint directory or the contract's path.
    pub(crate) fn describe(&self) -> String {
        match self {
            PolicySource::Checkpoint(p) | PolicySource::Export(p) => p.display().to_string(),
            PolicySource::Distilling { student, .. } => format!("a distillation run's student (teacher {} at iteration {})", student.teacher.0, student.teacher.1),
        }
    }
}
