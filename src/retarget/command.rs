//! `dextrain traj retarget DEMO --config CONFIG --out REF`: a human demonstration retargeted to the
//! config's hand and written as a reference (wrist path, every joint, the fingertips, the object's
//! path and name) on the config's table; one JSON line of what was estimated and how well the
//! robot's keypoints follow the human's.
//!
//! Steps: the demonstration (`demo.rs`); its world frame from the object at rest (`world.rs`:
//! up, the table, the object moved to the config's position); the human-to-robot keypoint map and
//! the scale from the hand's model (`keypoint_map.rs`); the per-frame solve (`solve.rs`), each
//! frame warm-started from the previous. The robot's wrist is placed where the solve puts it
//! relative to the human wrist, whose keypoints are scaled about it. Then the table clean-up: a
//! frame whose hand would come within [`HAND_CLEARANCE_M`] of the table (a link origin or a
//! fingertip) has its wrist raised, and one whose object pose (a video estimate) sinks into the
//! table has the object raised onto it; the report says which and how far.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result, anyhow, ensure};
use glam::Vec3;
use serde_json::json;

use super::demo::{HUMAN_KEYPOINTS, KEYPOINT_NAMES, load_demo};
use super::keypoint_map::{default_posture, keypoint_map};
use super::solve::retarget_sequence;
use super::world::{DemoFrame, estimate_world};
use crate::config::Config;
use crate::env::SimModel;
use crate::geom::Pose;
use crate::traj::{Keyframe, Trajectory};

/// How far above the table the retargeted hand's lowest link origin or fingertip is kept (m): a
/// frame whose hand would be lower has its wrist raised.
pub const HAND_CLEARANCE_M: f32 = 0.01;

/// What the clean-up moved: frames and the largest raise (m), of the hand and of the object.
#[derive(Clone, Copy, Debug, Default)]
struct Cleanup {
    hand_frames: usize,
    hand_raise_m: f32,
    object_frames: usize,
    object_raise_m: f32,
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
    /// Override a config value, as `train --set` does (repeatable).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub sets: Vec<String>,
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
    let world = estimate_world(&demo, frame, &shape, [g.obj_init[0], g.obj_init[1]]).map_err(|e| anyhow!("{demo_name}: {e}"))?;
    let frames: Vec<[Vec3; HUMAN_KEYPOINTS]> = demo.keypoints.iter().map(|k| k.map(|p| world.point(p))).collect();
    let mut map = keypoint_map(&model, &frames).map_err(|e| anyhow!("{}: {e}", args.config.display()))?;
    if let Some(s) = args.scale {
        ensure!(s.is_finite() && s > 0.0, "--scale {s}: expected a positive number (the robot's size over the human's)");
        map.spec.scale = s;
    }
    let started = Instant::now();
    let relative: Vec<Vec<Vec3>> = frames.iter().map(|k| map.frame_points(k)).collect();
    let solved = retarget_sequence(&model, &map.spec, &relative, &default_posture(&model)).map_err(|e| anyhow!("{demo_name}: {e}"))?;
    let solve_s = started.elapsed().as_secs_f64();

    let hand = &model.hand;
    let n = hand.joints.len();
    let mut traj = Trajectory {
        joint_names: hand.joints.iter().map(|j| j.name.clone()).collect(),
        fingertip_names: hand.fingertips.iter().map(|t| t.name.clone()).collect(),
        frames: Vec::with_capacity(solved.len()),
        object_name: cfg.object.name.clone(),
    };
    let mut cleanup = Cleanup::default();
    for (i, (f, k)) in solved.iter().zip(&frames).enumerate() {
        let mut wrist = Pose::new(k[0] + f.wrist_pos, f.wrist_rot); // the solve's wrist is relative to the human's
        let q = &f.q[..n];
        let links = hand.forward_kinematics(q);
        // the hand kept off the table: its lowest link origin or fingertip HAND_CLEARANCE_M above it
        let lowest = links.iter().map(|l| l.pos).chain(hand.fingertips.iter().map(|t| links[t.link].transform_point(t.pos))).map(|p| wrist.transform_point(p).z).fold(f32::INFINITY, f32::min);
        if lowest < HAND_CLEARANCE_M {
            wrist.pos.z += HAND_CLEARANCE_M - lowest;
            cleanup.hand_frames += 1;
            cleanup.hand_raise_m = cleanup.hand_raise_m.max(HAND_CLEARANCE_M - lowest);
        }
        let tips = hand.fingertips.iter().map(|t| wrist.transform_point(links[t.link].transform_point(t.pos))).collect();
        // the object kept on or above the table
        let mut object = world.pose(&demo.object[i]);
        let bottom = shape.iter().map(|v| object.transform_point(*v).z).fold(f32::INFINITY, f32::min);
        if bottom < 0.0 {
            object.pos.z -= bottom;
            cleanup.object_frames += 1;
            cleanup.object_raise_m = cleanup.object_raise_m.max(-bottom);
        }
        traj.frames.push(Keyframe { t: i as f64 / demo.fps, wrist, joints: q.to_vec(), fingertips: Some(tips), object: Some(object) });
    }
    traj.save(&args.out)?;

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
        "frames": solved.len(),
        "fps": demo.fps,
        "duration_s": traj.duration(),
        "solve_s": solve_s,
        "scale": map.spec.scale,
        "map": map.describe(&model),
        "world": {
            "demo_frame": demo.frame,
            "rest_frames": world.rest_frames,
            "up_in_demo": [up.x, up.y, up.z],
            "object_axis_up": world.object_axis_up,
            "table_height_in_demo_m": world.table_height_in_demo,
        },
        // what was moved off the table: frames and the largest raise (m)
        "cleanup": {
            "hand_frames_raised": cleanup.hand_frames,
            "hand_largest_raise_m": cleanup.hand_raise_m,
            "object_frames_raised": cleanup.object_frames,
            "object_largest_raise_m": cleanup.object_raise_m,
        },
        "keypoint_error": errors,
        "object": cfg.object.name,
    }))
}
