//! The reference bank: every reference trajectory of a run, resampled at the control step and packed
//! into one flat `Vec<f32>` of fixed-stride frame records (the GPU's `ref_frames` storage buffer),
//! with one [`RefInfo`] per reference (the GPU's `ref_info`). The task layer samples it through
//! `task::reference` (CPU) and `shaders/reference.wgsl` (GPU).
//!
//! # Resampling
//!
//! Reference `r` is sampled at the control step `ctrl_dt = (dt · decimation)` (computed as
//! `replay` does: `(g.dt * g.decimation as f32) as f64`): frame `i` is the reference at
//! `t = i · ctrl_dt`, for `i = 0 ..= ceil(duration / ctrl_dt)` (so the last frame is at or after the
//! last keyframe, which it holds). Frame `i` is what env step `i` of an un-augmented episode tracks.
//!
//! # Record layout (f32, world frame; `J` = model joints, `T` = model fingertips)
//!
//! | offset                      | len | field                                                          |
//! |-----------------------------|-----|----------------------------------------------------------------|
//! | [`REC_WRIST_POS`] = 0       | 3   | wrist position (m)                                             |
//! | [`REC_WRIST_ROT`] = 3       | 4   | wrist orientation, quaternion x y z w                          |
//! | [`REC_Q`] = 7               | J   | joint targets (rad), model joint order                         |
//! | `7 + J`                     | 3·T | fingertip positions (m), model fingertip order                 |
//! | `7 + J + 3T`                | 3   | object position (m)                                            |
//! | `10 + J + 3T`               | 4   | object orientation, quaternion x y z w                         |
//! | `14 + J + 3T`               | 1   | grasp flag (0 or 1)                                            |
//!
//! stride = `15 + J + 3T` ([`RecordLayout`]). Frame `i` of reference `r` starts at
//! `(info[r].first_frame + i) · stride`.
//!
//! - Wrist and joints are exactly those of [`targets_at`] at `t`
//!   (joints the reference does not name hold their default), then every mimic follower is set from
//!   its leader, `q_f = mult · q_leader + offset` (as replay's kinematic states are), so that the record
//!   can be compared with an env's full joint state.
//! - Fingertips come from the reference ([`Trajectory::sample`]) when it has them and every model
//!   fingertip name is among its `fingertip_names`; otherwise they are computed by the hand's forward
//!   kinematics of the frame's joints and wrist, as `traj synth` does ([`RefInfo::flags`] says which).
//! - The object is [`Trajectory::sample`]'s when the reference has one, else the config's nominal
//!   initial pose (`object.init_xy`, the unscaled rest height, `object.init_yaw`).
//! - The grasp flag is 1 when the thumb's fingertip and at least one other fingertip are within the
//!   object's bounding radius (unscaled) + 1 cm of the object centre, or when the object has moved
//!   more than 1 cm from its first position; else 0.

use std::path::PathBuf;

use anyhow::{Result, anyhow, bail};
use glam::{Quat, Vec3};

use crate::env::SimModel;
use crate::env::common::quat_from_axis_angle;
use crate::gpu::layout::{NO_JOINT, NO_OBJECT, Targets};
pub use crate::task::reference::{REF_HAS_OBJECT, REF_TIPS_FROM_FILE, RefGlobals, RefInfo};
use crate::geom::Pose;

use crate::traj::Trajectory;

/// The targets of `model` at time `t` (s) of `traj`: the sampled wrist pose and, through `map`
/// (model joint -> reference column, [`Trajectory::joint_map`]), its joint targets; joints the
/// reference does not name hold their default.
pub fn targets_at(model: &SimModel, traj: &Trajectory, map: &[Option<usize>], t: f64) -> Targets {
    let f = traj.sample(t);
    let mut out = model.default_targets();
    out.wrist_pos = [f.wrist.pos.x, f.wrist.pos.y, f.wrist.pos.z, 0.0];
    out.wrist_rot = f.wrist.rot.normalize().to_array();
    for (j, m) in map.iter().enumerate() {
        if let Some(k) = m {
            out.q[j] = f.joints[*k];
        }
    }
    out
}

/// Record offset of the wrist position (3 floats).
pub const REC_WRIST_POS: usize = 0;
/// Record offset of the wrist quaternion (4 floats, x y z w).
pub const REC_WRIST_ROT: usize = 3;
/// Record offset of the joint targets (J floats).
pub const REC_Q: usize = 7;
/// Distance (m) beyond the object's bounding radius within which a fingertip counts as grasping,
/// and displacement (m) of the object from its first position that counts as grasped.
pub const GRASP_MARGIN: f32 = 0.01;
/// Most frames of one reference (about 9 hours at 30 Hz).
pub const MAX_REF_FRAMES: usize = 1 << 20;
/// Most floats in a bank (indices into it are u32 on the GPU; 8 GiB of f32).
pub const MAX_BANK_FLOATS: usize = (1 << 31) - 1;

/// Offsets (in f32) of the fields of one frame record for `n_joints` joints and `n_tips` fingertips.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RecordLayout {
    pub n_joints: usize,
    pub n_tips: usize,
    /// Joint targets: [`REC_Q`].
    pub q: usize,
    /// Fingertip positions (3 per tip): `7 + J`.
    pub tips: usize,
    /// Object position: `7 + J + 3T`.
    pub obj_pos: usize,
    /// Object quaternion: `10 + J + 3T`.
    pub obj_rot: usize,
    /// Grasp flag: `14 + J + 3T`.
    pub grasp: usize,
    /// Floats per record: `15 + J + 3T`.
    pub stride: usize,
}

impl RecordLayout {
    /// The layout for `n_joints` joints and `n_tips` fingertips.
    pub fn new(n_joints: usize, n_tips: usize) -> RecordLayout {
        let tips = REC_Q + n_joints;
        let obj_pos = tips + 3 * n_tips;
        let obj_rot = obj_pos + 3;
        let grasp = obj_rot + 4;
        RecordLayout { n_joints, n_tips, q: REC_Q, tips, obj_pos, obj_rot, grasp, stride: grasp + 1 }
    }
}

/// All references of a run, resampled and packed (see the module documentation).
#[derive(Clone, Debug)]
pub struct RefBank {
    /// Frame records, `[Σ n_frames, stride]` row-major.
    pub frames: Vec<f32>,
    /// One per reference, in the order given.
    pub info: Vec<RefInfo>,
    /// Where each reference came from (its file, or `reference #k`), for messages.
    pub sources: Vec<String>,
    /// The object each reference names (index into the config's objects; `NO_OBJECT`: none).
    pub objects: Vec<u32>,
    pub layout: RecordLayout,
    /// The control step (s) the references were resampled at.
    pub ctrl_dt: f64,
    /// Fingertip index of the thumb (for the grasp flag).
    pub thumb: usize,
}

impl RefBank {
    /// Packs `trajs` (errors name them `reference #k`, from 0) for `model`; `thumb` is the thumb's
    /// fingertip index (`TaskGlobals::thumb`).
    pub fn build(trajs: &[Trajectory], model: &SimModel, thumb: usize) -> Result<RefBank> {
        let named: Vec<(String, &Trajectory)> = trajs.iter().enumerate().map(|(k, t)| (format!("reference #{k}"), t)).collect();
        RefBank::build_named(&named, model, thumb)
    }

    /// Loads the reference files (`.mcap` or `.csv`, [`Trajectory::load`]) and packs them; every
    /// error is one line and names the file.
    pub fn load(paths: &[PathBuf], model: &SimModel, thumb: usize) -> Result<RefBank> {
        let mut trajs = Vec::with_capacity(paths.len());
        for p in paths {
            // Trajectory::load's errors already start with the file name
            trajs.push((p.display().to_string(), Trajectory::load(p)?));
        }
        let named: Vec<(String, &Trajectory)> = trajs.iter().map(|(n, t)| (n.clone(), t)).collect();
        RefBank::build_named(&named, model, thumb)
    }

    /// Packs `(source name, trajectory)` pairs; errors are one line and start with the source name.
    pub fn build_named(trajs: &[(String, &Trajectory)], model: &SimModel, thumb: usize) -> Result<RefBank> {
        if trajs.is_empty() {
            bail!("no reference trajectories: expected at least one reference file");
        }
        let n_tips = model.tips.len();
        if thumb >= n_tips {
            bail!("thumb fingertip index {thumb}: expected one of the hand's {n_tips} fingertips");
        }
        let g = &model.globals;
        let ctrl_dt = (g.dt * g.decimation as f32) as f64;
        let layout = RecordLayout::new(model.joints.len(), n_tips);
        let mut bank = RefBank { frames: Vec::new(), info: Vec::new(), sources: Vec::new(), objects: Vec::new(), layout, ctrl_dt, thumb };
        for (name, traj) in trajs {
            bank.push(name, traj, model).map_err(|e| anyhow!("{name}: {}", one_line(&e)))?;
        }
        Ok(bank)
    }

    /// Resamples and appends one reference.
    fn push(&mut self, name: &str, traj: &Trajectory, model: &SimModel) -> Result<()> {
        traj.validate()?;
        let object = match &traj.object_name {
            None => NO_OBJECT,
            Some(o) => model.object_index(o).ok_or_else(|| {
                let names: Vec<&str> = model.objects.iter().map(|x| x.name.as_str()).collect();
                anyhow!("names object '{}': expected one of the config's objects ({})", crate::text::clip(o, 40), names.join(", "))
            })?,
        };
        self.objects.push(object);
        let map = traj.joint_map(&model.spec.joint_names)?;
        let l = self.layout;
        let ctrl_dt = self.ctrl_dt;
        let n_frames = (traj.duration() / ctrl_dt).ceil() as usize + 1;
        if n_frames > MAX_REF_FRAMES {
            bail!(
                "{:.1} s long: {n_frames} frames at the control step {ctrl_dt} s, expected at most {MAX_REF_FRAMES}",
                traj.duration()
            );
        }
        let first_frame = self.frames.len() / l.stride;
        if (first_frame + n_frames) * l.stride > MAX_BANK_FLOATS {
            bail!("the references together need more than {MAX_BANK_FLOATS} floats: expected fewer or shorter references");
        }
        // fingertips from the file only when every model fingertip is named in it
        let tip_cols: Option<Vec<usize>> = if traj.has_fingertips() {
            model.spec.tip_names.iter().map(|n| traj.fingertip_names.iter().position(|m| m == n)).collect()
        } else {
            None
        };
        let g = &model.globals;
        let nominal_obj = Pose::new(
            Vec3::new(g.obj_init[0], g.obj_init[1], g.obj_init[3]),
            Quat::from_array(quat_from_axis_angle(Vec3::Z, g.obj_init[2]).to_array()),
        );
        // the first object's bounding radius about its frame's origin
        let radius = model.object_descs[0].com[3];
        let mut rec = vec![0.0f32; l.stride];
        let mut obj0 = nominal_obj;
        let mut lo = Vec3::splat(f32::INFINITY);
        let mut hi = Vec3::splat(f32::NEG_INFINITY);
        self.frames.reserve(n_frames * l.stride);
        for i in 0..n_frames {
            let t = i as f64 * ctrl_dt;
            let tg = targets_at(model, traj, &map, t);
            let mut q = tg.q;
            for (j, jd) in model.joints.iter().enumerate() {
                if jd.mimic_leader != NO_JOINT {
                    // q_f = mult · q_leader + offset
                    q[j] = jd.mimic_mult * q[jd.mimic_leader as usize] + jd.mimic_offset;
                }
            }
            let f = traj.sample(t);
            let wrist = Pose::from_arrays(tg.wrist_pos, tg.wrist_rot);
            let tips: Vec<Vec3> = match (&tip_cols, &f.fingertips) {
                (Some(cols), Some(p)) => cols.iter().map(|&c| p[c]).collect(),
                _ => {
                    let links = model.hand.forward_kinematics(&q[..l.n_joints]);
                    model.hand.fingertips.iter().map(|tp| wrist.transform_point(links[tp.link].transform_point(tp.pos))).collect()
                }
            };
            let obj = f.object.unwrap_or(nominal_obj);
            if i == 0 {
                obj0 = obj;
            }
            // grasp: thumb and another tip within r + margin of the centre, or the object moved
            let near = |p: Vec3| (p - obj.pos).length() <= radius + GRASP_MARGIN;
            let thumb_near = near(tips[self.thumb]);
            let other_near = tips.iter().enumerate().any(|(k, &p)| k != self.thumb && near(p));
            let moved = (obj.pos - obj0.pos).length() > GRASP_MARGIN;
            let grasp = (thumb_near && other_near) || moved;

            rec[REC_WRIST_POS..REC_WRIST_POS + 3].copy_from_slice(&tg.wrist_pos[..3]);
            rec[REC_WRIST_ROT..REC_WRIST_ROT + 4].copy_from_slice(&tg.wrist_rot);
            rec[l.q..l.q + l.n_joints].copy_from_slice(&q[..l.n_joints]);
            for (k, p) in tips.iter().enumerate() {
                rec[l.tips + 3 * k..l.tips + 3 * k + 3].copy_from_slice(&p.to_array());
            }
            rec[l.obj_pos..l.obj_pos + 3].copy_from_slice(&obj.pos.to_array());
            rec[l.obj_rot..l.obj_rot + 4].copy_from_slice(&obj.rot.to_array());
            rec[l.grasp] = if grasp { 1.0 } else { 0.0 };
            self.frames.extend_from_slice(&rec);
            for p in tips.iter().chain([&wrist.pos, &obj.pos]) {
                lo = lo.min(*p);
                hi = hi.max(*p);
            }
        }
        let first_segment_steps = if traj.frames.len() >= 2 {
            // steps to keyframe 1, rounded, within [1, last frame]
            let s = (traj.frames[1].t / ctrl_dt + 0.5).floor() as usize;
            s.clamp(1, (n_frames - 1).max(1))
        } else {
            1
        };
        let mut flags = 0;
        if traj.has_object() {
            flags |= REF_HAS_OBJECT;
        }
        if tip_cols.is_some() {
            flags |= REF_TIPS_FROM_FILE;
        }
        self.info.push(RefInfo {
            obj0_pos: [obj0.pos.x, obj0.pos.y, obj0.pos.z, 0.0],
            obj0_rot: obj0.rot.to_array(),
            bbox_min: [lo.x, lo.y, lo.z, 0.0],
            bbox_max: [hi.x, hi.y, hi.z, 0.0],
            first_frame: first_frame as u32,
            n_frames: n_frames as u32,
            first_segment_steps: first_segment_steps as u32,
            flags,
        });
        self.sources.push(name.to_string());
        Ok(())
    }

    /// Number of references.
    pub fn len(&self) -> usize {
        self.info.len()
    }

    /// Whether the bank holds no reference (never, for a bank that was built).
    pub fn is_empty(&self) -> bool {
        self.info.is_empty()
    }

    /// The record of frame `i` of reference `r` (`stride` floats).
    pub fn record(&self, r: usize, i: usize) -> &[f32] {
        let s = self.layout.stride;
        let b = (self.info[r].first_frame as usize + i) * s;
        &self.frames[b..b + s]
    }

    /// The bank's [`RefGlobals`]: sizes and record offsets, every augmentation off (fill those with
    /// `task::setup::reference_globals`).
    pub fn globals(&self) -> RefGlobals {
        let l = self.layout;
        RefGlobals {
            n_refs: self.info.len() as u32,
            stride: l.stride as u32,
            n_joints: l.n_joints as u32,
            n_tips: l.n_tips as u32,
            off_wrist_pos: REC_WRIST_POS as u32,
            off_wrist_rot: REC_WRIST_ROT as u32,
            off_q: l.q as u32,
            off_tips: l.tips as u32,
            off_obj_pos: l.obj_pos as u32,
            off_obj_rot: l.obj_rot as u32,
            off_grasp: l.grasp as u32,
            ..RefGlobals::default()
        }
    }
}

/// An error as one line (its whole chain, newlines replaced).
fn one_line(e: &anyhow::Error) -> String {
    format!("{e:#}").replace(['\n', '\r'], " ")
}
