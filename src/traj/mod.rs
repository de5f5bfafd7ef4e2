//! Reference trajectories: the file format (MCAP with JSON-schema'd messages, and CSV), keyframe
//! interpolation (linear for positions and joints, slerp for rotations) and perturbation (`perturb`);
//! the reference bank is the task layer's (`task::bank`), synthesis a command (`synth`).
//!
//! CONTRACT (used by replay, synth and later the task layer):
//! - A [`Trajectory`] is a list of keyframes sorted by strictly increasing time `t` (s).
//! - Joint targets are by name (`joint_names`); fingertip positions (world frame, by `fingertip_names`)
//!   and the object pose are optional, but present in all frames or in none.
//!
//! Files are read with [`Trajectory::load`] (`.mcap` or `.csv`) and written with
//! [`Trajectory::save`], [`Trajectory::save_mcap`] or [`Trajectory::save_csv`]; the formats are
//! described in `docs/references.md` (section "Reference trajectory format") and implemented in [`io`]. Between keyframes
//! [`Trajectory::sample`] interpolates linearly (positions, joints, fingertips) and by shortest-arc
//! slerp (wrist and object rotations); outside the keyframes it holds the first or last frame.
//! [`npy`] reads NumPy's `.npy` / `.npz` arrays, the files human demonstrations come in.

use anyhow::{Result, bail};
use glam::{Quat, Vec3};

use crate::geom::Pose;

pub mod io;
pub mod npy;
pub mod perturb;

pub use io::{FORMAT_VERSION, REFERENCE_JSON_SCHEMA, REFERENCE_METADATA_NAME, REFERENCE_SCHEMA_NAME, REFERENCE_TOPIC};

/// Quaternions whose norm differs from 1 by less than this are accepted (and normalised when
/// read from a file); anything further from unit length is an error.
pub const QUAT_NORM_TOLERANCE: f64 = 1e-3;

/// Longest reference (s): one hour. Real demonstrations last seconds to minutes; the bound keeps
/// what is derived from the duration finite and small (a replay or a reference bank holds
/// `duration / control step` frames: 108,000 for an hour at 30 Hz), where a last time of `1e9` would
/// ask for terabytes.
pub const MAX_DURATION_S: f64 = 3600.0;
/// Most keyframes in one reference: 2²² (4,194,304; an hour at 1 kHz is 3.6 M).
pub const MAX_KEYFRAMES: usize = 1 << 22;
/// Largest |coordinate| (m) of a wrist, object or fingertip position: 100 m from the world origin.
/// A demonstration happens on a table near it; the simulator works in f32, whose spacing at 100 m
/// is 7.6 µm, and errors are differences of positions, so they stay finite and meaningful.
pub const MAX_POSITION_M: f64 = 100.0;
/// Largest |joint target| (rad): 100 rad (16 turns of a continuous joint; revolute joints stay
/// within their limits of a few rad). f32's spacing at 100 is 7.6 µrad.
pub const MAX_JOINT_RAD: f64 = 100.0;

/// One keyframe of a reference.
#[derive(Clone, Debug, PartialEq)]
pub struct Keyframe {
    /// Time (s) from the start of the reference.
    pub t: f64,
    /// Wrist (root link) pose in the world frame.
    pub wrist: Pose,
    /// Joint position targets (rad), in `Trajectory::joint_names` order.
    pub joints: Vec<f32>,
    /// Fingertip positions (world frame), in `Trajectory::fingertip_names` order.
    pub fingertips: Option<Vec<Vec3>>,
    /// Object pose (world frame).
    pub object: Option<Pose>,
}

/// A reference trajectory.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct Trajectory {
    /// Names of the joints the frames give targets for, in `Keyframe::joints` order.
    pub joint_names: Vec<String>,
    /// Names of the fingertips the frames give positions for, in `Keyframe::fingertips` order.
    pub fingertip_names: Vec<String>,
    /// Keyframes by strictly increasing time.
    pub frames: Vec<Keyframe>,
    /// The name of the object the demonstration handles (`[object] name` or an `[[object.set]]`
    /// entry's): an env following this reference holds that object. MCAP: field `object` of the
    /// `dextrain.reference` metadata record; CSV: a comment line `# object: NAME` before the header.
    pub object_name: Option<String>,
}

impl Trajectory {
    /// Duration (s): time of the last keyframe.
    pub fn duration(&self) -> f64 {
        self.frames.last().map(|f| f.t).unwrap_or(0.0)
    }

    /// Whether the frames carry fingertip positions (decided by the first frame).
    pub fn has_fingertips(&self) -> bool {
        self.frames.first().is_some_and(|f| f.fingertips.is_some())
    }

    /// Whether the frames carry an object pose (decided by the first frame).
    pub fn has_object(&self) -> bool {
        self.frames.first().is_some_and(|f| f.object.is_some())
    }

    /// Checks the CONTRACT and what the file formats need: at least one and at most
    /// [`MAX_KEYFRAMES`] frames; finite times `0 ≤ t ≤` [`MAX_DURATION_S`], strictly increasing;
    /// one joint value per joint name and, where present, one fingertip per fingertip name in every
    /// frame; optional parts in all frames or none; finite numbers, positions within
    /// ±[`MAX_POSITION_M`] and joint values within ±[`MAX_JOINT_RAD`]; quaternions within
    /// [`QUAT_NORM_TOLERANCE`] of unit length; names valid (see [`is_valid_name`]) and unique.
    /// The error is one line naming the frame and the field. The savers, `replay` and the
    /// reference bank call this first.
    pub fn validate(&self) -> Result<()> {
        check_names("joint_names", &self.joint_names)?;
        check_names("fingertip_names", &self.fingertip_names)?;
        let Some(first) = self.frames.first() else {
            bail!("trajectory has no frames: expected at least 1 frame");
        };
        if self.frames.len() > MAX_KEYFRAMES {
            bail!("trajectory has {} frames: expected at most {MAX_KEYFRAMES} (MAX_KEYFRAMES)", self.frames.len());
        }
        let tips = first.fingertips.is_some();
        let object = first.object.is_some();
        if !tips && !self.fingertip_names.is_empty() {
            bail!(
                "frame 0: field `fingertips`: expected positions for the {} fingertip names, got none",
                self.fingertip_names.len()
            );
        }
        let mut prev_t = f64::NEG_INFINITY;
        for (i, f) in self.frames.iter().enumerate() {
            if !f.t.is_finite() || f.t < 0.0 {
                bail!("frame {i}: field `t`: expected a finite time ≥ 0, got {}", f.t);
            }
            if f.t > MAX_DURATION_S {
                bail!("frame {i}: field `t`: expected a time ≤ {MAX_DURATION_S} s (one hour, MAX_DURATION_S), got {}", f.t);
            }
            if f.t <= prev_t {
                bail!("frame {i}: field `t`: expected times strictly increasing, got {} after {}", f.t, prev_t);
            }
            prev_t = f.t;
            check_pose(i, "wrist", &f.wrist)?;
            if f.joints.len() != self.joint_names.len() {
                bail!(
                    "frame {i}: field `joints`: expected {} values (one per joint name), got {}",
                    self.joint_names.len(),
                    f.joints.len()
                );
            }
            for (name, v) in self.joint_names.iter().zip(&f.joints) {
                if !v.is_finite() {
                    bail!("frame {i}: field `joints.{name}`: expected a finite number, got {v}");
                }
                if (*v as f64).abs() > MAX_JOINT_RAD {
                    bail!("frame {i}: field `joints.{name}`: expected a joint value within ±{MAX_JOINT_RAD} rad (MAX_JOINT_RAD), got {v}");
                }
            }
            match (&f.fingertips, tips) {
                (Some(p), true) => {
                    if p.len() != self.fingertip_names.len() {
                        bail!(
                            "frame {i}: field `fingertips`: expected {} positions (one per fingertip name), got {}",
                            self.fingertip_names.len(),
                            p.len()
                        );
                    }
                    for (name, p) in self.fingertip_names.iter().zip(p) {
                        if !p.is_finite() {
                            bail!("frame {i}: field `fingertips.{name}`: expected finite numbers, got {p}");
                        }
                        check_position(i, &format!("fingertips.{name}"), *p)?;
                    }
                }
                (None, false) => {}
                (Some(_), false) => {
                    bail!("frame {i}: field `fingertips`: expected none (frame 0 has none), got some")
                }
                (None, true) => bail!("frame {i}: field `fingertips`: expected some (frame 0 has them), got none"),
            }
            match (&f.object, object) {
                (Some(p), true) => check_pose(i, "object", p)?,
                (None, false) => {}
                (Some(_), false) => bail!("frame {i}: field `object`: expected none (frame 0 has none), got some"),
                (None, true) => bail!("frame {i}: field `object`: expected a pose (frame 0 has one), got none"),
            }
        }
        Ok(())
    }

    /// The reference at time `t` (s).
    ///
    /// Before the first keyframe (or for a NaN `t`) this is the first keyframe, after the last one
    /// the last keyframe; at a keyframe's time exactly that keyframe. Between two keyframes,
    /// positions, joints and fingertips are interpolated linearly and the wrist and object
    /// rotations by slerp along the shortest arc. The returned frame's `t` is always the `t` asked
    /// for. On a trajectory with no frames this is the identity wrist pose with zero joints.
    pub fn sample(&self, t: f64) -> Keyframe {
        let n = self.frames.len();
        let Some(first) = self.frames.first() else {
            return Keyframe {
                t,
                wrist: Pose::IDENTITY,
                joints: vec![0.0; self.joint_names.len()],
                fingertips: None,
                object: None,
            };
        };
        // Index of the first keyframe strictly after t (NaN compares false: lands on 0).
        let i = self.frames.partition_point(|f| f.t <= t);
        if i == 0 {
            return Keyframe { t, ..first.clone() };
        }
        let a = &self.frames[i - 1];
        if i == n || a.t == t {
            return Keyframe { t, ..a.clone() };
        }
        let b = &self.frames[i];
        let s = ((t - a.t) / (b.t - a.t)) as f32;
        let lerp = |x: f32, y: f32| x + (y - x) * s;
        Keyframe {
            t,
            wrist: lerp_pose(&a.wrist, &b.wrist, s),
            joints: a.joints.iter().zip(&b.joints).map(|(&x, &y)| lerp(x, y)).collect(),
            fingertips: match (&a.fingertips, &b.fingertips) {
                (Some(pa), Some(pb)) => Some(pa.iter().zip(pb).map(|(&x, &y)| x.lerp(y, s)).collect()),
                (pa, _) => pa.clone(),
            },
            object: match (&a.object, &b.object) {
                (Some(pa), Some(pb)) => Some(lerp_pose(pa, pb, s)),
                (pa, _) => *pa,
            },
        }
    }

    /// The reference sampled (see [`sample`](Self::sample)) at the uniform times `k·dt`,
    /// k = 0, 1, …, while `k·dt` is before the duration, plus a last frame at exactly the
    /// duration (times closer than `dt·1e-6` to it are dropped, so the times strictly increase).
    /// Names are kept; a trajectory with no frames gives one with no frames.
    ///
    /// # Panics
    /// If `dt` is not finite and positive.
    pub fn resample(&self, dt: f64) -> Trajectory {
        assert!(dt.is_finite() && dt > 0.0, "Trajectory::resample: dt must be finite and > 0, got {dt}");
        let mut frames = Vec::new();
        if !self.frames.is_empty() {
            let end = self.duration();
            let mut k: u64 = 0;
            loop {
                let t = k as f64 * dt;
                if t >= end - dt * 1e-6 {
                    break;
                }
                frames.push(self.sample(t));
                k += 1;
            }
            frames.push(self.sample(end));
        }
        Trajectory { joint_names: self.joint_names.clone(), fingertip_names: self.fingertip_names.clone(), frames, object_name: self.object_name.clone() }
    }

    /// Maps a hand's joints (`names`, e.g. `HandModel` joint order) to this trajectory's joint
    /// columns: element `k` is `Some(j)` when `names[k]` is `self.joint_names[j]`, `None` when the
    /// trajectory has no target for that joint (the caller decides, e.g. holds its default).
    /// Errors, naming them, if the trajectory has joints the hand lacks.
    pub fn joint_map(&self, names: &[String]) -> Result<Vec<Option<usize>>> {
        let unknown: Vec<String> =
            self.joint_names.iter().filter(|j| !names.contains(j)).map(|j| format!("{j:?}")).collect();
        if !unknown.is_empty() {
            let hand: Vec<String> = names.iter().map(|n| format!("{n:?}")).collect();
            bail!(
                "reference joint{} {} not in the hand: expected one of the hand's joints [{}]",
                if unknown.len() == 1 { "" } else { "s" },
                unknown.join(", "),
                hand.join(", ")
            );
        }
        Ok(names.iter().map(|n| self.joint_names.iter().position(|j| j == n)).collect())
    }
}

/// Whether `name` can be a joint or fingertip name in a reference file: non-empty, with no
/// whitespace, control characters, commas or double quotes (so it fits a CSV column name).
pub fn is_valid_name(name: &str) -> bool {
    !name.is_empty() && name.chars().all(|c| !c.is_whitespace() && !c.is_control() && c != ',' && c != '"')
}

fn check_names(what: &str, names: &[String]) -> Result<()> {
    for (k, name) in names.iter().enumerate() {
        if !is_valid_name(name) {
            bail!(
                "field `{what}`: name {name:?}: expected a non-empty name without whitespace, control characters, commas or double quotes"
            );
        }
        if names[..k].contains(name) {
            bail!("field `{what}`: name {name:?}: expected unique names, got it twice");
        }
    }
    Ok(())
}

fn check_pose(i: usize, field: &str, p: &Pose) -> Result<()> {
    if !p.pos.is_finite() || !p.rot.is_finite() {
        bail!("frame {i}: field `{field}`: expected finite numbers, got pos {} rot {}", p.pos, p.rot);
    }
    check_position(i, field, p.pos)?;
    let norm = p.rot.as_dquat().length();
    if (norm - 1.0).abs() >= QUAT_NORM_TOLERANCE {
        bail!("frame {i}: field `{field}`: expected a unit quaternion (qx, qy, qz, qw), got norm {norm}");
    }
    Ok(())
}

/// A position within ±[`MAX_POSITION_M`] on every axis.
fn check_position(i: usize, field: &str, p: Vec3) -> Result<()> {
    for (axis, v) in ["x", "y", "z"].iter().zip(p.to_array()) {
        if (v as f64).abs() > MAX_POSITION_M {
            bail!("frame {i}: field `{field}.{axis}`: expected a position within ±{MAX_POSITION_M} m (MAX_POSITION_M), got {v}");
        }
    }
    Ok(())
}

fn lerp_pose(a: &Pose, b: &Pose, s: f32) -> Pose {
    Pose { pos: a.pos.lerp(b.pos, s), rot: slerp(a.rot, b.rot, s) }
}

/// Shortest-arc slerp, normalised.
fn slerp(a: Quat, b: Quat, s: f32) -> Quat {
    a.slerp(b, s).normalize()
}
