//! Hands from URDF (urdf-rs) -> [`HandModel`]: the joint tree, limits, mimic joints, collision shapes
//! and fingertip frames that the simulator needs.
//!
//! CONTRACT (used by env/physics.rs, record.rs, traj synth — do not change field meanings):
//! - `links[0]` is the root link (the palm; its frame is the wrist frame driven by the floating base).
//! - `joints` holds only the movable joints (revolute and continuous), in topological order: a joint's
//!   parent link is moved by an earlier joint (or is the root). `links[i + 1]` is the child link of
//!   `joints[i]`, so `joints[i].parent_link < i + 1`.
//! - Fixed joints are merged: the child link's inertia, colliders and frames move onto its parent link,
//!   with the fixed joint's origin composed in. A merged link's name still resolves through
//!   [`HandModel::frame`].
//! - Poses are in the parent link's frame, metres and unit quaternions (x, y, z, w).

use std::path::{Path, PathBuf};

use anyhow::Result;
use glam::{Quat, Vec3};

use crate::geom::Pose;

/// Most movable joints (actuated + mimic followers) a hand may have (keep in sync with
/// shaders/common.wgsl `MAX_JOINTS`).
pub const MAX_JOINTS: usize = 24;
/// Most collision shapes a hand may have (keep in sync with shaders/common.wgsl `MAX_COLLIDERS`).
pub const MAX_COLLIDERS: usize = 32;
/// Most fingertip frames (keep in sync with shaders/common.wgsl `MAX_TIPS`).
pub const MAX_TIPS: usize = 6;

/// What to do with a `<mesh>` collision element, which the simulator cannot represent.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MeshApprox {
    /// A mesh collision is an error that names the link (the default).
    #[default]
    Error,
    /// Replace the mesh by the box bounding its vertices (STL or OBJ files are read).
    Box,
    /// Replace the mesh by a capsule along the longest axis of its bounding box.
    Capsule,
}

/// Options of the URDF loader.
#[derive(Clone, Debug, Default)]
pub struct HandLoadOptions {
    /// Names of the fingertip frames (links, possibly merged by fixed joints). Empty: every link whose
    /// name ends in `tip` (case-insensitive), in URDF order.
    pub fingertips: Vec<String>,
    /// Opt-in approximation of mesh collision geometry.
    pub mesh_approx: MeshApprox,
}

/// A mimic relation: `q = multiplier * q[leader] + offset`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Mimic {
    /// Index into `HandModel::joints` of the leader (never itself a follower).
    pub leader: usize,
    pub multiplier: f32,
    pub offset: f32,
}

/// A movable (revolute or continuous) joint.
#[derive(Clone, Debug, PartialEq)]
pub struct Joint {
    pub name: String,
    /// Index into `HandModel::links` of the parent link.
    pub parent_link: usize,
    /// Pose of the joint frame in the parent link's frame (URDF `<origin>`).
    pub origin: Pose,
    /// Unit rotation axis in the joint frame (URDF `<axis>`, default x).
    pub axis: Vec3,
    /// Position limits (rad). Continuous joints: -inf / +inf.
    pub lower: f32,
    pub upper: f32,
    /// Effort limit (N·m); URDF `effort`.
    pub effort: f32,
    /// Velocity limit (rad/s); URDF `velocity`.
    pub velocity: f32,
    /// Viscous damping (N·m·s/rad) from `<dynamics damping>`, 0 if absent.
    pub damping: f32,
    /// Coulomb friction (N·m) from `<dynamics friction>`, 0 if absent.
    pub friction: f32,
    /// `Some` for a mimic follower.
    pub mimic: Option<Mimic>,
    /// True for a `continuous` joint (no position limits).
    pub continuous: bool,
}

/// A rigid link after fixed joints are merged.
#[derive(Clone, Debug, PartialEq)]
pub struct Link {
    pub name: String,
    /// Mass (kg), including merged links.
    pub mass: f32,
    /// Centre of mass in the link frame.
    pub com: Vec3,
    /// Inertia tensor about the centre of mass, in the link frame, row-major 3x3.
    pub inertia: [[f32; 3]; 3],
}

/// Collision shape of a hand link. Capsule axes are the collider's local z (as URDF cylinders).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ColliderShape {
    Sphere { radius: f32 },
    /// A URDF cylinder or capsule becomes a capsule: `half_length` of the segment, not counting caps.
    Capsule { radius: f32, half_length: f32 },
    Box { half_extents: Vec3 },
}

/// A collision shape attached to a link.
#[derive(Clone, Debug, PartialEq)]
pub struct Collider {
    /// Index into `HandModel::links`.
    pub link: usize,
    /// Pose of the shape in the link frame.
    pub pose: Pose,
    pub shape: ColliderShape,
}

/// A named fingertip frame: a point on a link.
#[derive(Clone, Debug, PartialEq)]
pub struct Fingertip {
    pub name: String,
    /// Index into `HandModel::links`.
    pub link: usize,
    /// Position of the tip in the link frame.
    pub pos: Vec3,
}

/// A hand, ready for the simulator.
#[derive(Clone, Debug, PartialEq)]
pub struct HandModel {
    pub name: String,
    pub source: PathBuf,
    pub links: Vec<Link>,
    pub joints: Vec<Joint>,
    pub colliders: Vec<Collider>,
    pub fingertips: Vec<Fingertip>,
}

impl HandModel {
    /// Loads a hand from a URDF file. Errors are one line and name the file and the link or joint.
    pub fn from_urdf_file(path: &Path, opts: &HandLoadOptions) -> Result<HandModel> {
        let _ = (path, opts);
        anyhow::bail!("URDF loading not implemented yet")
    }

    /// Parses a URDF document; `source` is used in error messages and to resolve mesh paths.
    pub fn from_urdf_str(text: &str, source: &Path, opts: &HandLoadOptions) -> Result<HandModel> {
        let _ = (text, source, opts);
        anyhow::bail!("URDF loading not implemented yet")
    }

    /// Index of a joint by name.
    pub fn joint_index(&self, name: &str) -> Option<usize> {
        self.joints.iter().position(|j| j.name == name)
    }

    /// Number of actuated joints (movable joints that are not mimic followers).
    pub fn num_actuated(&self) -> usize {
        self.joints.iter().filter(|j| j.mimic.is_none()).count()
    }

    /// Link poses in the wrist (root link) frame for joint positions `q` (one per joint; mimic
    /// followers' entries are ignored and recomputed from their leaders).
    pub fn forward_kinematics(&self, q: &[f32]) -> Vec<Pose> {
        let mut poses = vec![Pose::IDENTITY; self.links.len()];
        for (i, j) in self.joints.iter().enumerate() {
            let qi = match j.mimic {
                Some(m) => m.multiplier * q[m.leader] + m.offset,
                None => q[i],
            };
            let parent = poses[j.parent_link];
            let joint_frame = parent.mul(&j.origin);
            poses[i + 1] = joint_frame.mul(&Pose::new(Vec3::ZERO, Quat::from_axis_angle(j.axis, qi)));
        }
        poses
    }
}
