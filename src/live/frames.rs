//! The first envs of a batch as recording frames ([`RolloutFrame`]): what a live view shows, read
//! from the task's env states, parameters, contact springs and targets at the current step.

use anyhow::Result;

use crate::env::{EnvParams, EnvState, SimModel, contact_records, hand_link_poses};
use crate::gpu::layout::Targets;
use crate::geom::Pose;
use crate::record::{RolloutFrame, RolloutMeta};
use crate::task::TaskBatch;

/// What decides the look of an env's object: its object's index in the model and its scale (an
/// env's reset may draw both anew).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ObjectKey {
    /// The object's index in the model's objects.
    pub index: u32,
    /// The env's object scale (every length multiplied by it).
    pub scale: f32,
}

/// One shown env at the current step: its frame and the key of its object.
pub struct EnvFrame {
    /// The env's state as a recording frame.
    pub frame: RolloutFrame,
    /// Which object (and scale) the frame's object is.
    pub object: ObjectKey,
}

/// The first `k` envs of `task` (fewer if the batch has fewer) at the current step; the frame's
/// time is the env's own episode time (its step count × the control step).
pub fn first_env_frames(model: &SimModel, task: &mut dyn TaskBatch, k: usize) -> Result<Vec<EnvFrame>> {
    let control_dt = task.spec().control_dt as f64;
    let targets = task.first_targets(k)?;
    let k = k.min(targets.len());
    let mut refs = Vec::with_capacity(k);
    for i in 0..k {
        refs.push(task.reference_now(i)?.map(|f| Pose::from_arrays(f.obj_pos, f.obj_rot)));
    }
    let (states, params, springs) = task.env().first_envs(k)?;
    Ok(env_frames(model, &EnvSlices { states: &states, params: &params, springs: &springs, targets: &targets, refs: &refs }, control_dt, k))
}

/// What a batch's first envs hold at one step (each slice from env 0 on).
pub struct EnvSlices<'a> {
    /// The envs' states.
    pub states: &'a [EnvState],
    /// The envs' parameters.
    pub params: &'a [EnvParams],
    /// The envs' contact springs, `[N, n_springs]`.
    pub springs: &'a [[f32; 4]],
    /// Each env's targets (one entry: every env's).
    pub targets: &'a [Targets],
    /// Each env's reference object pose now (none: no reference).
    pub refs: &'a [Option<Pose>],
}

/// The frames of the first `k` envs of `at` (fewer where a slice is shorter).
pub fn env_frames(model: &SimModel, at: &EnvSlices, control_dt: f64, k: usize) -> Vec<EnvFrame> {
    if at.targets.is_empty() {
        return Vec::new();
    }
    let ns = model.globals.n_springs as usize;
    let nj = model.joints.len();
    let k = k.min(at.states.len()).min(at.params.len()).min(at.springs.len() / ns.max(1));
    (0..k)
        .map(|i| {
            let s = &at.states[i];
            let tg = &at.targets[i.min(at.targets.len() - 1)];
            EnvFrame {
                frame: RolloutFrame {
                    t: s.step as f64 * control_dt,
                    joint_pos: s.q[..nj].to_vec(),
                    joint_vel: s.qd[..nj].to_vec(),
                    joint_target: tg.q[..nj].to_vec(),
                    wrist: Pose::from_arrays(s.wrist_pos, s.wrist_rot),
                    object: Pose::from_arrays(s.obj_pos, s.obj_rot),
                    links: hand_link_poses(model, s),
                    contacts: contact_records(model, s, &at.springs[i * ns..(i + 1) * ns], &at.params[i], tg),
                    object_ref: at.refs.get(i).copied().flatten(),
                    overlay: Vec::new(),
                },
                object: ObjectKey { index: at.params[i].obj_index, scale: at.params[i].obj_scale },
            }
        })
        .collect()
}

/// The recording description of an env whose object is `key` (the hand and the object's pieces at
/// the env's scale); `dt`: the control step.
pub fn env_meta(model: &SimModel, key: ObjectKey, dt: f32) -> RolloutMeta {
    RolloutMeta {
        hand: model.hand.clone(),
        object: crate::record::object_parts(&model.objects[key.index as usize], key.scale),
        dt,
        info: serde_json::Value::Null,
    }
}
