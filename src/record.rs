//! Recorded rollouts as MCAP: hand joint states, wrist and object poses, contacts and forces, plus
//! Foxglove `foxglove.FrameTransforms` and `foxglove.SceneUpdate` messages for 3-D viewing.
//!
//! CONTRACT (used by `dextrain replay --out` and later `dextrain eval --record`):
//! `RolloutWriter::create(path, &meta)`, then `write_frame(&frame)` once per recorded env step, then
//! `finish()`. Everything is in the world frame unless said otherwise.

use glam::Vec3;

use crate::geom::{ObjectShape, Pose};
use crate::hand::HandModel;

/// What kind of pair a contact is between.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ContactKind {
    HandObject,
    HandTable,
    ObjectTable,
}

/// One contact at the time of a frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ContactRecord {
    pub kind: ContactKind,
    /// Hand collider index (into `HandModel::colliders`) for hand contacts, object support-point
    /// index for object–table contacts.
    pub index: u32,
    /// Contact point (world).
    pub pos: Vec3,
    /// Unit normal, pointing from the second body (object or table) to the first (hand or object).
    pub normal: Vec3,
    /// Penetration depth (m, ≥ 0).
    pub depth: f32,
    /// Total contact force on the first body (normal + friction), N.
    pub force: Vec3,
}

/// Static description of a recorded rollout.
#[derive(Clone, Debug)]
pub struct RolloutMeta {
    pub hand: HandModel,
    /// Object shape with the env's object scale already applied.
    pub object: ObjectShape,
    /// Time between recorded frames (s).
    pub dt: f32,
    /// Free-form JSON (config summary, command line) stored as MCAP metadata "dextrain".
    pub info: serde_json::Value,
}

/// State of one env at one recorded time.
#[derive(Clone, Debug, PartialEq)]
pub struct RolloutFrame {
    /// Simulated time (s).
    pub t: f64,
    /// Joint positions and velocities in `HandModel::joints` order (mimic followers included).
    pub joint_pos: Vec<f32>,
    pub joint_vel: Vec<f32>,
    /// Joint position targets, same order.
    pub joint_target: Vec<f32>,
    pub wrist: Pose,
    pub object: Pose,
    /// World pose of every link, in `HandModel::links` order (links[0] is the wrist).
    pub links: Vec<Pose>,
    pub contacts: Vec<ContactRecord>,
    /// Optional reference object pose at this time (drawn as a ghost).
    pub object_ref: Option<Pose>,
}
