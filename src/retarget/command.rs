//! `dextrain traj retarget DEMO --config CONFIG --out REF`: a human demonstration retargeted to the
//! config's hand and written as a reference (wrist path, every joint, the fingertips, the object's
//! path and name) on the config's table; one JSON line of what was estimated and how well the
//! robot's keypoints follow the human's.
//!
//! Steps: the demonstration (`demo.rs`); its world frame from the object at rest (`world.rs`:
//! up, the table, the object moved to the config's position); the human-to-robot keypoint map and
//! the scale from the hand's model (`keypoint_map.rs`); the per-frame solve (`solve.rs`), each
//! frame warm-started from the previous. The robot's wrist is placed where the solve puts it
//! relative to the human wrist, whose keypoints are scaled about it. Then the contact clean-up
//! (`contact.rs`, `--contacts`: the human's grasp re-grounded on the object, or `traj synth`'s
//! planned grasp, carried along the object's path; or nothing) and the table clean-up: a frame
//! whose hand would come within [`HAND_CLEARANCE_M`] of the table (a link origin or a fingertip)
//! has its wrist raised, and one whose object pose (a video estimate) sinks into the table has
//! the object raised onto it; the report says which and how far.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result, anyhow, ensure};
use glam::Vec3;
use serde_json::json;

use super::contact::{ContactReport, GraspSource, HAND_CLEARANCE_M, HandFrame, contact_cleanup, hand_lowest_z, raise_onto_table, tips_world};
use super::demo::{HUMAN_KEYPOINTS, KEYPOINT_NAMES, load_demo};
use super::keypoint_map::{HUMAN_FINGERS, default_posture, keypoint_map};
use super::solve::retarget_sequence;
use super::world::{DemoFrame, ObjectAxis, estimate_world};
use crate::config::Config;
use crate::env::SimModel;
use crate::geom::Pose;
use crate::record::{RolloutFrame, RolloutMeta, RolloutWriter, object_parts};
use crate::synth::{SynthArgs, synth};
use crate::traj::{Keyframe, Trajectory};

/// What the table clean-up moved: frames and the largest raise (m), of the hand and of the object.
#[derive(Clone, Copy, Debug, Default)]
struct Cleanup {
    hand_frames: usize,
    hand_raise_m: f32,
    object_frames: usize,
    object_raise_m: f32,
}

/// What becomes of the demonstration's hand–object contact (`--contacts`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum ContactChoice {
    /// The retargeted hand re-grounded on the object: its fingertips squeezed onto the object's
    /// surface at the grasp, the object carried from there (`retarget/contact.rs`). For estimates
    /// whose hand and object disagree (a video's).
    #[default]
    Reground,
    /// As `reground`, with `traj synth`'s planned grasp of the object (checked in simulation
    /// there) in place of the human's: the demonstration gives the object's path, the approach
    /// and the timing. For a demonstration whose grasp the robot cannot copy.
    Planned,
    /// The retargeted hand and the object's path as the demonstration has them (a demonstration
    /// whose hand and object already touch where they should, e.g. motion capture).
    Keep,
}

/// `dextrain traj retarget`'s arguments.
#[derive(clap::Args, Debug, Clone)]
pub struct RetargetArgs {
    /// The human demonstration: DexMV's `.npz` or dextrain's `.csv` (docs/file-formats.md).
    pub demo: PathBuf,
    /// Config whose hand and object the reference is for (the object's position on the table is
    /// where the demonstration's object starts).
    #[arg(long)]
    pub config: PathBuf,
    /// Output reference (.mcap or .csv).
    #[arg(long)]
    pub out: PathBuf,
    /// The robot's size over the human's (a human vector is scaled by it); default: the hand's
    /// fingers' lengths over the demonstration's.
    #[arg(long)]
    pub scale: Option<f32>,
    /// The object's axis (its model frame) that points up while it rests, where the estimate
    /// should not decide it.
    #[arg(long, value_enum)]
    pub object_up: Option<ObjectAxis>,
    /// The reference's duration over the demonstration's: 2 plays it at half the human's speed (a
    /// robot hand's grip may not carry an object as fast as a human's).
    #[arg(long, default_value_t = 1.0)]
    pub time_scale: f64,
    /// Seconds of the reference kept before the grasp window (the pre-grasp pose): the earlier
    /// approach is dropped and the reference starts there (a shorter episode spent on the grasp
    /// and the carry); default: the whole demonstration. Needs a contact clean-up.
    #[arg(long)]
    pub lead_in: Option<f64>,
    /// The contact clean-up: `reground` (default), `planned` or `keep`.
    #[arg(long, value_enum, default_value_t)]
    pub contacts: ContactChoice,
    /// Also write a recording (MCAP, for Foxglove) of the reference played kinematically, with
    /// the human's keypoints beside the robot hand (scaled to it and moved with its wrist).
    #[arg(long)]
    pub record: Option<PathBuf>,
    /// Override a config value, as `train --set` does (repeatable).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub sets: Vec<String>,
}

/// Writes `traj` played kinematically (every frame's joints, wrist and object as the reference has
/// them) as a recording, with `overlay[f]` drawn beside frame `f`.
fn record_reference(model: &SimModel, traj: &Trajectory, overlay: Vec<Vec<Vec<Vec3>>>, path: &std::path::Path) -> Result<()> {
    let object = model.objects.first().context("the config has no object")?;
    let dt = traj.frames.get(1).map_or(0.0, |f| f.t) as f32;
    let meta = RolloutMeta { hand: model.hand.clone(), object: object_parts(object, 1.0), dt, info: json!({"command": "traj retarget", "overlay": "the human demonstration's fingers, scaled to the robot"}) };
    let mut w = RolloutWriter::create(path, &meta)?;
    for (f, chains) in traj.frames.iter().zip(overlay) {
        let object = f.object.unwrap_or(Pose::IDENTITY);
        w.write_frame(&RolloutFrame {
            t: f.t,
            joint_pos: f.joints.clone(),
            joint_vel: vec![0.0; f.joints.len()],
            joint_target: f.joints.clone(),
            wrist: f.wrist,
            object,
            links: model.hand.forward_kinematics(&f.joints).iter().map(|l| f.wrist.mul(l)).collect(),
            contacts: Vec::new(),
            object_ref: f.object,
            overlay: chains,
        })?;
    }
    w.finish()
}

/// Runs the command: writes the reference and prints the report (one JSON line).
pub fn run(args: &RetargetArgs) -> Result<()> {
    let report = retarget(args)?;
    println!("{report}");
    Ok(())
}

/// Retargets `args.demo`, writes `args.out`, and returns the report.
pub fn retarget(args: &RetargetArgs) -> Result<serde_json::Value> {
    let cfg = Config::load_with_overrides(&args.config, &args.sets)?;
    let model = SimModel::from_config(&cfg)?;
    let demo = load_demo(&args.demo)?;
    let demo_name = args.demo.display().to_string();
    let frame = DemoFrame::parse(&demo.frame).ok_or_else(|| anyhow!("{demo_name}: frame `{}`; expected `camera` or `world`", demo.frame))?;
    let obj = model.objects.first().with_context(|| format!("{}: the config has no object to put the demonstration's on", args.config.display()))?;
    let g = &model.globals;
    let shape = obj.collision_points();
    let world = estimate_world(&demo, frame, &shape, [g.obj_init[0], g.obj_init[1]], args.object_up).map_err(|e| anyhow!("{demo_name}: {e}"))?;
    let frames: Vec<[Vec3; HUMAN_KEYPOINTS]> = demo.keypoints.iter().map(|k| k.map(|p| world.point(p))).collect();
    let mut map = keypoint_map(&model, &frames, cfg.retarget.fingers.as_ref()).map_err(|e| anyhow!("{}: {e}", args.config.display()))?;
    if let Some(s) = args.scale {
        ensure!(s.is_finite() && s > 0.0, "--scale {s}: expected a positive number (the robot's size over the human's)");
        map.spec.scale = s;
    }
    ensure!(args.time_scale.is_finite() && args.time_scale > 0.0, "--time-scale {}: expected a positive number (the reference's duration over the demonstration's)", args.time_scale);
    // the reference's frame rate: the demonstration's, slowed by the time scale
    let fps = demo.fps / args.time_scale;
    let started = Instant::now();
    let relative: Vec<Vec<Vec3>> = frames.iter().map(|k| map.frame_points(k)).collect();
    let solved = retarget_sequence(&model, &map.spec, &relative, &default_posture(&model)).map_err(|e| anyhow!("{demo_name}: {e}"))?;
    let solve_s = started.elapsed().as_secs_f64();

    let hand = &model.hand;
    let n = hand.joints.len();
    // the solve's wrist is relative to the human's
    let mut hands: Vec<HandFrame> = solved.iter().zip(&frames).map(|(f, k)| HandFrame { wrist: Pose::new(k[0] + f.wrist_pos, f.wrist_rot), q: f.q[..n].to_vec() }).collect();
    let retargeted_wrists: Vec<Vec3> = hands.iter().map(|h| h.wrist.pos).collect();
    let mut objects: Vec<Pose> = demo.object.iter().map(|o| world.pose(o)).collect();
    let source = match args.contacts {
        ContactChoice::Reground => Some(GraspSource::Human),
        ContactChoice::Planned => Some(GraspSource::Planned(synth(&cfg, &SynthArgs::defaults(args.config.clone(), args.out.clone()))?)),
        ContactChoice::Keep => None,
    };
    let mut cleanup = Cleanup::default();
    let contacts: Option<ContactReport> = match source {
        Some(source) => {
            let report = contact_cleanup(&model, &mut hands, &mut objects, world.rest_frames, fps, &source).map_err(|e| anyhow!("{demo_name}: {e}"))?;
            (cleanup.object_frames, cleanup.object_raise_m) = (report.object_frames_raised, report.object_largest_raise_m);
            Some(report)
        }
        // the object kept on or above the table
        None => {
            (cleanup.object_frames, cleanup.object_raise_m) = raise_onto_table(&mut objects, &shape);
            None
        }
    };
    let mut traj = Trajectory {
        joint_names: hand.joints.iter().map(|j| j.name.clone()).collect(),
        fingertip_names: hand.fingertips.iter().map(|t| t.name.clone()).collect(),
        frames: Vec::with_capacity(solved.len()),
        object_name: cfg.object.name.clone(),
    };
    for (i, (h, object)) in hands.into_iter().zip(objects).enumerate() {
        let mut wrist = h.wrist;
        // the hand kept off the table: its lowest link origin or fingertip HAND_CLEARANCE_M above it
        let lowest = hand_lowest_z(&model, &wrist, &h.q);
        if lowest < HAND_CLEARANCE_M {
            wrist.pos.z += HAND_CLEARANCE_M - lowest;
            cleanup.hand_frames += 1;
            cleanup.hand_raise_m = cleanup.hand_raise_m.max(HAND_CLEARANCE_M - lowest);
        }
        let tips = tips_world(&model, &wrist, &h.q);
        traj.frames.push(Keyframe { t: i as f64 / fps, wrist, joints: h.q, fingertips: Some(tips), object: Some(object) });
    }
    // the lead-in: the frames from lead_in before the grasp window, their times from 0
    let first_frame = match (args.lead_in, &contacts) {
        (None, _) => 0,
        (Some(s), Some(c)) => {
            ensure!(s.is_finite() && s >= 0.0, "--lead-in {s}: expected seconds ≥ 0");
            c.window_from.saturating_sub((s * fps).round() as usize)
        }
        (Some(_), None) => return Err(anyhow!("--lead-in: needs the grasp window of a contact clean-up (--contacts reground or planned)")),
    };
    if first_frame > 0 {
        traj.frames.drain(..first_frame);
        let t0 = traj.frames[0].t;
        for f in &mut traj.frames {
            f.t -= t0;
        }
    }
    traj.save(&args.out)?;
    if let Some(path) = &args.record {
        // the human's fingers (wrist → knuckle → … → tip) as the solve saw them, scaled about the
        // human wrist, moved by what the clean-ups moved the robot's wrist
        let overlay: Vec<Vec<Vec<Vec3>>> = frames[first_frame..]
            .iter()
            .zip(&traj.frames)
            .zip(&retargeted_wrists[first_frame..])
            .map(|((k, f), &retargeted)| {
                let at = |p: Vec3| k[0] + (p - k[0]) * map.spec.scale + (f.wrist.pos - retargeted);
                HUMAN_FINGERS.iter().map(|finger| std::iter::once(at(k[0])).chain(finger.iter().map(|&i| at(k[i]))).collect()).collect()
            })
            .collect();
        record_reference(&model, &traj, overlay, path)?;
    }

    // each mapped keypoint's distance from the scaled human one, mean and largest over the frames
    let errors: serde_json::Map<String, serde_json::Value> = map
        .human_keypoints
        .iter()
        .enumerate()
        .map(|(p, &h)| {
            let e: Vec<f32> = solved.iter().map(|f| f.keypoint_error[p]).collect();
            let mean = e.iter().sum::<f32>() / e.len().max(1) as f32;
            let max = e.iter().copied().fold(0.0f32, f32::max);
            (KEYPOINT_NAMES[h].to_string(), json!({"mean_mm": 1e3 * mean, "max_mm": 1e3 * max}))
        })
        .collect();
    let up = world.up_in_demo;
    Ok(json!({
        "out": args.out.display().to_string(),
        "record": args.record.as_ref().map(|p| p.display().to_string()),
        "frames": traj.frames.len(),
        "first_demo_frame": first_frame,
        "fps": demo.fps,
        "time_scale": args.time_scale,
        "lead_in_s": args.lead_in,
        "duration_s": traj.duration(),
        "solve_s": solve_s,
        "scale": map.spec.scale,
        "map": map.describe(&model),
        "world": {
            "demo_frame": demo.frame,
            "rest_frames": world.rest_frames,
            "up_in_demo": [up.x, up.y, up.z],
            "object_axis_up": world.object_axis_up,
            "object_axis_given": world.object_axis_given,
            "hand_clearance_m": world.hand_clearance_m,
            "table_height_in_demo_m": world.table_height_in_demo,
        },
        // what was moved off the table: frames and the largest raise (m)
        "cleanup": {
            "hand_frames_raised": cleanup.hand_frames,
            "hand_largest_raise_m": cleanup.hand_raise_m,
            "object_frames_raised": cleanup.object_frames,
            "object_largest_raise_m": cleanup.object_raise_m,
        },
        "contacts": contacts,
        "keypoint_error": errors,
        "object": cfg.object.name,
    }))
}
