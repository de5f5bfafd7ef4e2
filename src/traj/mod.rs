//! Reference trajectories: the file format (MCAP with JSON-schema'd messages, and CSV), keyframe
//! interpolation (linear for positions and joints, slerp for rotations), and synthesis (`synth`).
//!
//! CONTRACT (used by replay, synth and later the task layer):
//! - A [`Trajectory`] is a list of keyframes sorted by strictly increasing time `t` (s).
//! - Joint targets are by name (`joint_names`); fingertip positions (world frame, by `fingertip_names`)
//!   and the object pose are optional, but present in all frames or in none.

use glam::Vec3;

use crate::geom::Pose;

pub mod synth;

/// One keyframe of a reference.
#[derive(Clone, Debug, PartialEq)]
pub struct Frame {
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
    pub joint_names: Vec<String>,
    pub fingertip_names: Vec<String>,
    pub frames: Vec<Frame>,
}

impl Trajectory {
    /// Duration (s): time of the last keyframe.
    pub fn duration(&self) -> f64 {
        self.frames.last().map(|f| f.t).unwrap_or(0.0)
    }
}
