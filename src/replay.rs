//! `dextrain replay`: the papers' "dynamic replay" baseline — drive the hand open-loop along a
//! reference under the physics — and, with `--kinematic`, the kinematic replay (states set directly
//! from the reference, penetration measured) for comparison.
//!
//! Both start every env at the reference's first frame: wrist pose and joint positions from it, and
//! the object at the reference's first object pose when it has one (else where the config puts it).
//! Dynamic replay then holds, for each control step k, the reference sampled at the end of the step,
//! `t = (k + 1)·dt·decimation`, as the targets; joints the reference does not name hold their default.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use glam::Quat;
use serde::Serialize;

use crate::config::Config;
use crate::env::reset::{reset_params, reset_state};
use crate::env::{EnvBatch, EnvState, SimModel, Targets, contact_records, make_env_batch};
use crate::geom::Pose;
use crate::record::{ContactKind, RolloutFrame, RolloutMeta, RolloutWriter};
use crate::traj::Trajectory;
use crate::task::bank::{MAX_REF_FRAMES, targets_at};

/// Arguments of `dextrain replay`.
#[derive(clap::Args, Debug, Clone)]
pub struct ReplayArgs {
    /// Config of the hand, object and physics.
    pub config: PathBuf,
    /// Reference trajectory (.mcap or .csv).
    #[arg(long)]
    pub traj: PathBuf,
    /// Kinematic replay: set the states from the reference instead of simulating.
    #[arg(long)]
    pub kinematic: bool,
    /// Record env 0's rollout to this MCAP file (watchable in Foxglove).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Number of envs to replay on (each with its own randomised parameters); default 1.
    #[arg(long, default_value_t = 1)]
    pub envs: usize,
    /// Backend: cpu, gpu, gpu:NAME or auto (overrides the config).
    #[arg(long)]
    pub backend: Option<crate::config::BackendChoice>,
    /// Override a config value, as `train --set` does: `--set hand.urdf="/path/to/hand.urdf"`
    /// (repeatable).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub sets: Vec<String>,
    /// The live view (`--live`, `--live-envs`, `--live-hz`, `--live-wait`): the envs at real time,
    /// the reference's object as a ghost.
    #[command(flatten)]
    pub live: crate::live::LiveArgs,
    /// `--video`: render env 0's rollout to a video (`--video-episodes` does not apply: one
    /// rollout).
    #[command(flatten)]
    pub video: crate::video::VideoArgs,
}

/// The one-line JSON report of a replay. Each metric name means the same as in the eval report
/// (`crate::eval::Summary`); the envs play like eval's episodes. Object errors are left out of the
/// JSON (not null) when the reference has no object pose; every value printed is finite (a
/// non-finite one is an error, see [`crate::eval::check_finite`]).
#[derive(Clone, Debug, Serialize)]
pub struct ReplayReport {
    /// `dynamic` (simulated, the targets follow the reference) or `kinematic` (states set from it).
    pub mode: String,
    /// The env backend that ran the replay.
    pub backend: String,
    /// Number of envs replayed (each with its own randomised parameters).
    pub envs: usize,
    /// Frames per env: the initial state and one per control step, `ceil(duration / control step) + 1`.
    pub frames: usize,
    /// Whether the reference has an object pose (the object errors are left out without one).
    pub has_object_reference: bool,
    /// The object's distance (m) from the reference's object position at the last frame, mean over envs.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub terminal_object_pos_err_m: Option<f64>,
    /// The object's angle (deg) from the reference's object orientation at the last frame, mean over envs.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub terminal_object_rot_err_deg: Option<f64>,
    /// The object's distance (m) from the reference, mean over the frames of an env, then over envs.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mean_object_pos_err_m: Option<f64>,
    /// The object's angle (deg) from the reference, mean over the frames of an env, then over envs.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mean_object_rot_err_deg: Option<f64>,
    /// Deepest hand–object penetration (mm) of any frame of any env (as eval's `peak_penetration_mm`).
    pub peak_penetration_mm: f64,
    /// Fraction of all frames (every env's) whose deepest hand–object penetration exceeds 1 mm
    /// (as eval's `frac_frames_penetration_over_1mm`).
    pub frac_frames_penetration_over_1mm: f64,
    /// Mean normal force (N) of a fingertip while it touches the object: over every fingertip-frame
    /// whose force exceeds `task.hand.contact_force` (the threshold of the task's contact flags), 0
    /// when none does (as eval's `mean_fingertip_force_n`).
    pub mean_fingertip_force_n: f64,
    /// Height (m) the object ended above where it started, mean over envs.
    pub object_lift_m: f64,
    /// Resets caused by non-finite or exploding states.
    pub bad_resets: u64,
    /// Object and wrist poses of env 0 at every frame (for tests and plots; not in the JSON).
    #[serde(skip)]
    pub trace: Vec<(f64, Pose, Pose)>,
}

/// Angle (deg) between two orientations.
pub fn rot_err_deg(a: Quat, b: Quat) -> f64 {
    let d = (a.inverse() * b).normalize();
    (2.0 * (d.w.abs().min(1.0) as f64).acos()).to_degrees()
}

/// The state of env `env` placed on the reference at time t (velocities zero).
fn state_on_reference(model: &SimModel, base: &EnvState, tg: &Targets, object: Option<Pose>) -> EnvState {
    let mut s = *base;
    s.wrist_pos = tg.wrist_pos;
    s.wrist_rot = tg.wrist_rot;
    s.wrist_vel = [0.0; 4];
    s.wrist_angvel = [0.0; 4];
    for (j, jd) in model.joints.iter().enumerate() {
        s.q[j] = tg.q[j];
        s.qd[j] = 0.0;
        if jd.mimic_leader != crate::gpu::layout::NO_JOINT {
            s.q[j] = jd.mimic_mult * tg.q[jd.mimic_leader as usize] + jd.mimic_offset;
        }
    }
    if let Some(o) = object {
        s.obj_pos = [o.pos.x, o.pos.y, o.pos.z, 0.0];
        s.obj_rot = o.rot.normalize().to_array();
        s.obj_vel = [0.0; 4];
        s.obj_angvel = [0.0; 4];
    }
    s
}

/// Per-env accumulators of the metrics.
#[derive(Default, Clone)]
struct Acc {
    pos_err_sum: f64,
    rot_err_sum: f64,
    last_pos_err: f64,
    last_rot_err: f64,
    peak_pen: f64,
    frames_over: usize,
    force_sum: f64,
    force_n: usize,
    z0: f64,
    z_last: f64,
}

/// Replays `traj` for `cfg` (with `cfg.sim.num_envs` envs) and returns the report.
pub fn replay(cfg: &Config, traj: &Trajectory, kinematic: bool, out: Option<&Path>) -> Result<ReplayReport> {
    replay_with_model(cfg, &SimModel::from_config(cfg)?, traj, kinematic, out)
}

/// [`replay`] with the model of `cfg` already built (`SimModel::from_config(cfg)`), for callers
/// that replay many references under one config.
pub fn replay_with_model(cfg: &Config, model: &SimModel, traj: &Trajectory, kinematic: bool, out: Option<&Path>) -> Result<ReplayReport> {
    Ok(replay_filmed(cfg, model, traj, kinematic, out, false, None)?.0)
}

/// [`replay_with_model`], and with `film` env 0's rollout as a video episode (every frame; no
/// outcome: a replay has no success); `live`: a live view that shows the envs.
pub fn replay_filmed(cfg: &Config, model: &SimModel, traj: &Trajectory, kinematic: bool, out: Option<&Path>, film: bool, mut live: Option<&mut crate::live::LiveView>) -> Result<(ReplayReport, Option<crate::video::VideoEpisode>)> {
    // a reference that names its object is replayed with that object in every env
    let named;
    let model = match &traj.object_name {
        Some(o) => {
            let mut m = model.clone();
            let k = m.object_index(o).ok_or_else(|| {
                let names: Vec<&str> = m.objects.iter().map(|x| x.name.as_str()).collect();
                anyhow::anyhow!("the reference names object '{}': expected one of the config's objects ({})", crate::text::clip(o, 40), names.join(", "))
            })?;
            m.set_reference_objects(vec![k]);
            named = m;
            &named
        }
        None => model,
    };
    let map = traj.joint_map(&model.spec.joint_names)?;
    let g = model.globals;
    let n = cfg.sim.num_envs;
    let ctrl_dt = (g.dt * g.decimation as f32) as f64;
    traj.validate().context("the reference")?;
    // frames = ⌈duration / ctrl_dt⌉ + 1, bounded before anything is allocated
    let steps = (traj.duration() / ctrl_dt).ceil();
    if !(steps.is_finite() && steps < MAX_REF_FRAMES as f64) {
        bail!(
            "the reference lasts {} s (its last frame, frame {}): {steps} control steps of {ctrl_dt} s; expected at most {} frames (MAX_REF_FRAMES): shorten the reference or lengthen sim.dt · sim.decimation",
            traj.duration(),
            traj.frames.len().saturating_sub(1),
            MAX_REF_FRAMES
        );
    }
    let frames = steps as usize + 1;
    // a fingertip touches the object when its force exceeds the task's contact threshold (N)
    let contact_force = cfg.task.hand.contact_force as f64;
    let has_obj = traj.frames.first().is_some_and(|f| f.object.is_some());
    let meta = || RolloutMeta {
        hand: model.hand.clone(),
        object: {
            let p0 = reset_params(&g, &model.object_descs, &model.ref_objects, 0, 0);
            crate::record::object_parts(&model.objects[p0.obj_index as usize], p0.obj_scale)
        },
        dt: ctrl_dt as f32,
        info: serde_json::json!({ "command": "replay", "mode": if kinematic { "kinematic" } else { "dynamic" }, "config": cfg.source.display().to_string() }),
    };
    let mut writer = match out {
        Some(p) => Some(RolloutWriter::create(p, &meta())?),
        None => None,
    };
    let mut filmed = film.then(|| crate::video::VideoEpisode { meta: meta(), frames: Vec::with_capacity(frames), success: None });
    let t0 = targets_at(&model, traj, &map, 0.0);
    let obj0 = traj.frames.first().and_then(|f| f.object);
    let mut acc = vec![Acc::default(); n];
    let mut trace = Vec::with_capacity(frames);
    let mut bad = 0u64;
    let backend;
    // the per-frame observation shared by both modes: states, params, each env's deepest penetration
    // and fingertip forces at this frame
    // `springs`: every env's contact springs `[N, n_springs]`, read only for a recording, a video or a live view
    let per_env = model.globals.n_springs as usize;
    let mut observe = |k: usize,
                       states: &[EnvState],
                       params: &[crate::env::EnvParams],
                       springs: &mut dyn FnMut() -> Result<Vec<[f32; 4]>>,
                       pen: &[f32],
                       tips: &[Vec<f32>],
                       tg: &Targets,
                       writer: &mut Option<RolloutWriter>|
     -> Result<()> {
        let t = (k as f64) * ctrl_dt;
        let r = traj.sample(t);
        for i in 0..n {
            let s = &states[i];
            let a = &mut acc[i];
            let obj = Pose::from_arrays(s.obj_pos, s.obj_rot);
            if k == 0 {
                a.z0 = obj.pos.z as f64;
            }
            a.z_last = obj.pos.z as f64;
            if let Some(o) = r.object {
                a.last_pos_err = (obj.pos - o.pos).length() as f64;
                a.last_rot_err = rot_err_deg(obj.rot, o.rot);
                a.pos_err_sum += a.last_pos_err;
                a.rot_err_sum += a.last_rot_err;
            }
            a.peak_pen = a.peak_pen.max(pen[i] as f64);
            if pen[i] > 1e-3 {
                a.frames_over += 1;
            }
            for f in &tips[i] {
                if *f as f64 > contact_force {
                    a.force_sum += *f as f64;
                    a.force_n += 1;
                }
            }
        }
        trace.push((t, Pose::from_arrays(states[0].obj_pos, states[0].obj_rot), Pose::from_arrays(states[0].wrist_pos, states[0].wrist_rot)));
        let live_due = live.as_deref().is_some_and(|l| l.wants_scene());
        let kept = writer.is_some() || filmed.is_some();
        if live_due || kept {
            // the shown envs (a live view's first ones; env 0 for a recording or a video)
            let shown = live.as_deref().filter(|_| live_due).map_or(1, |l| l.shown_envs().max(1));
            let springs = springs()?;
            let refs = vec![r.object; states.len()];
            let at = crate::live::EnvSlices { states, params, springs: &springs, targets: std::slice::from_ref(tg), refs: &refs };
            let mut frames = crate::live::env_frames(&model, &at, ctrl_dt, shown);
            if let Some(l) = live.as_deref_mut()
                && live_due
            {
                l.send_scene(&frames)?;
            }
            if kept && !frames.is_empty() {
                // the replay's own clock (a kinematic state's step count stays 0)
                let frame = RolloutFrame { t, ..frames.swap_remove(0).frame };
                if let Some(w) = writer.as_mut() {
                    w.write_frame(&frame)?;
                }
                if let Some(f) = filmed.as_mut() {
                    f.frames.push(frame);
                }
            }
        }
        Ok(())
    };
    if kinematic {
        backend = "kinematic (cpu)".to_string();
        let params: Vec<_> = (0..n as u32).map(|i| reset_params(&g, &model.object_descs, &model.ref_objects, i, 0)).collect();
        let bases: Vec<EnvState> = (0..n).map(|i| reset_state(&g, &model.joints, &params[i], i as u32, 0, 0)).collect();
        // a kinematic state has no contact history: every spring is relaxed
        let relaxed = vec![[0.0f32; 4]; model.globals.n_springs as usize];
        let mut relaxed_springs = || Ok(vec![[0.0f32; 4]; n * per_env]);
        for k in 0..frames {
            let t = k as f64 * ctrl_dt;
            let tg = targets_at(&model, traj, &map, t);
            let obj = traj.sample(t).object.or(obj0);
            let states: Vec<EnvState> = bases.iter().map(|b| state_on_reference(&model, b, &tg, obj)).collect();
            let mut pen = vec![0.0f32; n];
            let mut tips = vec![vec![0.0f32; model.tips.len()]; n];
            for i in 0..n {
                for c in contact_records(&model, &states[i], &relaxed, &params[i], &tg) {
                    if c.kind == ContactKind::HandObject {
                        pen[i] = pen[i].max(c.depth);
                        let tip = model.colliders[c.index as usize].tip;
                        if tip != crate::gpu::layout::NO_JOINT {
                            tips[i][tip as usize] += c.force.dot(c.normal);
                        }
                    }
                }
            }
            observe(k, &states, &params, &mut relaxed_springs, &pen, &tips, &tg, &mut writer)?;
        }
    } else {
        let mut env: Box<dyn EnvBatch> = make_env_batch(cfg, model.clone())?;
        backend = env.backend_name();
        let start: Vec<EnvState> = env.states()?.iter().map(|b| state_on_reference(&model, b, &t0, obj0)).collect();
        env.set_states(&start)?;
        // parameters change only at a reset: read them again only after a step that reset an env
        let mut params = env.params()?;
        let zero = vec![0.0f32; n];
        let no_tips = vec![vec![0.0f32; model.tips.len()]; n];
        observe(0, &start, &params, &mut || env.springs(), &zero, &no_tips, &t0, &mut writer)?;
        for k in 1..frames {
            let tg = targets_at(&model, traj, &map, k as f64 * ctrl_dt);
            env.step(&vec![tg; n])?;
            let states = env.states()?;
            let stats = env.stats()?;
            let resets = stats.iter().map(|s| s.bad_reset as u64).sum::<u64>();
            if resets > 0 {
                params = env.params()?;
            }
            bad += resets;
            let pen: Vec<f32> = stats.iter().map(|s| s.max_pen_ho).collect();
            let tips: Vec<Vec<f32>> = stats.iter().map(|s| s.tip_force[..model.tips.len()].to_vec()).collect();
            observe(k, &states, &params, &mut || env.springs(), &pen, &tips, &tg, &mut writer)?;
        }
    }
    if let Some(w) = writer {
        w.finish()?;
    }
    let mean = |f: &dyn Fn(&Acc) -> f64| acc.iter().map(f).sum::<f64>() / n as f64;
    let obj_metric = |v: f64| if has_obj { Some(v) } else { None };
    let force_n: usize = acc.iter().map(|a| a.force_n).sum();
    let report = ReplayReport {
        mode: if kinematic { "kinematic".into() } else { "dynamic".into() },
        backend,
        envs: n,
        frames,
        has_object_reference: has_obj,
        terminal_object_pos_err_m: obj_metric(mean(&|a| a.last_pos_err)),
        terminal_object_rot_err_deg: obj_metric(mean(&|a| a.last_rot_err)),
        mean_object_pos_err_m: obj_metric(mean(&|a| a.pos_err_sum / frames as f64)),
        mean_object_rot_err_deg: obj_metric(mean(&|a| a.rot_err_sum / frames as f64)),
        peak_penetration_mm: acc.iter().map(|a| a.peak_pen).fold(0.0, f64::max) * 1e3,
        frac_frames_penetration_over_1mm: mean(&|a| a.frames_over as f64 / frames as f64),
        mean_fingertip_force_n: if force_n == 0 { 0.0 } else { acc.iter().map(|a| a.force_sum).sum::<f64>() / force_n as f64 },
        object_lift_m: mean(&|a| a.z_last - a.z0),
        bad_resets: bad,
        trace,
    };
    crate::eval::check_finite(&report, "replay report")?;
    Ok((report, filmed))
}

/// `dextrain replay`.
pub fn run(args: &ReplayArgs) -> Result<()> {
    let mut cfg = Config::load_with_overrides(&args.config, &args.sets)?;
    cfg.sim.num_envs = args.envs;
    if let Some(b) = &args.backend {
        cfg.sim.backend = b.clone();
    }
    cfg.validate()?;
    let traj = Trajectory::load(&args.traj)?;
    let model = SimModel::from_config(&cfg)?;
    let ctrl_dt = model.globals.dt * model.globals.decimation as f32;
    // a bad --video path, or no adapter to render on, fails before the replay runs
    args.video.episodes_to_film()?;
    let video_ctx = args.video.render_context()?;
    let mut live = args.live.start(&model, ctrl_dt, None, true)?;
    let (report, filmed) = replay_filmed(&cfg, &model, &traj, args.kinematic, args.out.as_deref(), args.video.video.is_some(), live.as_mut())
        .with_context(|| format!("replaying {} with {}", args.traj.display(), args.config.display()))?;
    if let (Some(path), Some(episode), Some(ctx)) = (&args.video.video, filmed, video_ctx) {
        let v = crate::video::write_video(path, std::slice::from_ref(&episode), ctx, args.video.video_size)?;
        crate::console::status(&format!("dextrain replay: video {} ({} frames, {}x{} at {:.0} fps; rendered on {})", path.display(), v.frames, v.width, v.height, v.fps, v.adapter));
    }
    crate::console::result(&serde_json::to_string(&report)?);
    Ok(())
}
