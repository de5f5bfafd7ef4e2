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
//!
//! Loader notes: movable joints are ordered depth-first from the root, children in URDF document
//! order (so a finger's joints are contiguous). Mimic chains are resolved to the root leader with the
//! composed multiplier and offset. URDF `rpy` is fixed-axis roll (x), pitch (y), yaw (z):
//! R = Rz(yaw)·Ry(pitch)·Rx(roll). Cylinders and capsules become [`ColliderShape::Capsule`]s
//! (`half_length` = length / 2, axis local z). Colliders are sorted by link (stable). Every error is
//! one line naming the file and, where there is one, the link or joint, and says what is expected;
//! values quoted in it are cut to [`MAX_QUOTED_CHARS`] characters.
//!
//! Before urdf-rs sees the text, a light pre-scan of the XML bounds its size ([`MAX_URDF_BYTES`])
//! and nesting ([`MAX_URDF_DEPTH`]; urdf-rs and its XML parsers recurse per level, so 100,000 nested
//! elements would overflow the stack), and checks every attribute that urdf-rs reads (present where
//! required, a number, three numbers, a joint type…), so that such an error names the link or joint,
//! the element, the attribute and its line instead of urdf-rs's vague message.
//!
//! Every number the model uses must fit it (the bounds are far outside what real hands use; the
//! real URDFs of Allegro, LEAP, Shadow, Inspire, Ability and SCHUNK SVH load):
//! - a link with `<inertial>` has a mass in [[`MIN_LINK_MASS_KG`], [`MAX_LINK_MASS_KG`]] and an
//!   inertia tensor that is positive semi-definite (all principal minors ≥ 0; zero is a point mass,
//!   as Shadow's tips are) with entries within ±[`MAX_INERTIA_KG_M2`]; the triangle inequality of
//!   principal moments is not required (Allegro, Ability and SVH break it slightly). A link without
//!   `<inertial>` is massless (a frame), as in URDF.
//! - origins (`xyz`), collision sizes and mesh bounding boxes are within ±[`MAX_LENGTH_M`]; `rpy`,
//!   revolute limits and mimic offsets within ±[`MAX_ANGLE_RAD`]; axes have components within
//!   ±[`MAX_AXIS_COMPONENT`] and a non-zero length; `effort` in (0, [`MAX_EFFORT_NM`]], `velocity` in
//!   (0, [`MAX_VELOCITY_RAD_S`]], damping and friction in [0, [`MAX_DAMPING`]]; mimic multipliers
//!   (also composed along a chain) within ±[`MAX_MIMIC_MULTIPLIER`]; mesh scales within
//!   ±[`MAX_MESH_SCALE`].

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use anyhow::Result;
use glam::{DMat3, DQuat, DVec3, Quat, Vec3};

pub use crate::config::hand::{FingertipSpec, JointLimitOverride, LinkTip};
use crate::config::{MAX_QUOTED_CHARS, clip, clip_quoted};
use crate::geom::Pose;

/// Most movable joints (actuated + mimic followers) a hand may have (keep in sync with
/// shaders/common.wgsl `MAX_JOINTS`): Shadow's 24 with room to spare. It sizes the joint arrays of
/// the per-env structs (`EnvState::q`, `Targets::q`, the reference frames) and the shaders' private
/// arrays; its cost on the 16-joint hand is measured in BENCHMARKS.md.
pub const MAX_JOINTS: usize = 32;
/// Most collision shapes a hand may have: LEAP's 71 with room to spare. Nothing is sized by it:
/// an env's contact springs take `2 · colliders + object support points` slots of a buffer sized
/// from the hand at run time (`gpu_layout::spring_slot`), and the physics loops over the hand's own
/// colliders. It bounds the cost of a step (every collider is tested against the object each
/// substep).
pub const MAX_COLLIDERS: usize = 256;
/// Most fingertip frames (keep in sync with shaders/common.wgsl `MAX_TIPS`).
pub const MAX_TIPS: usize = 6;

/// Largest URDF text the loader reads (bytes): 16 MiB (real hand URDFs are 15–40 kB).
pub const MAX_URDF_BYTES: usize = 16 << 20;
/// Deepest nesting of XML elements: 32 levels (a URDF uses 5: robot > link > collision > geometry > box).
pub const MAX_URDF_DEPTH: usize = 32;
/// Smallest mass (kg) of a link that has an `<inertial>` (1 mg; real fingertip links weigh ≥ 1 g).
pub const MIN_LINK_MASS_KG: f64 = 1e-6;
/// Largest mass (kg) of a link (Shadow's forearm, the heaviest real link, is 3 kg).
pub const MAX_LINK_MASS_KG: f64 = 100.0;
/// Largest |entry| (kg·m²) of a link's inertia tensor (real links: ≤ 0.014).
pub const MAX_INERTIA_KG_M2: f64 = 10.0;
/// Largest |coordinate| (m) of an origin, and largest collision size or mesh extent (real: < 0.5 m).
pub const MAX_LENGTH_M: f64 = 10.0;
/// Largest |angle| (rad) of an `rpy`, a revolute limit or a mimic offset (real: ≤ π).
pub const MAX_ANGLE_RAD: f64 = 100.0;
/// Largest |component| of an `<axis xyz>` (it is normalised; real axes are unit vectors).
pub const MAX_AXIS_COMPONENT: f64 = 1e3;
/// Largest effort limit (N·m) of a joint (real: ≤ 1000, SCHUNK SVH).
pub const MAX_EFFORT_NM: f64 = 1e5;
/// Largest velocity limit (rad/s) of a joint (real: ≤ 40).
pub const MAX_VELOCITY_RAD_S: f64 = 1e4;
/// Largest `<dynamics damping>` (N·m·s/rad) or `friction` (N·m) of a joint (real: ≤ 0.2).
pub const MAX_DAMPING: f64 = 1e3;
/// Largest |multiplier| of a mimic joint, also composed along a mimic chain (real: ≤ 1.5).
pub const MAX_MIMIC_MULTIPLIER: f64 = 100.0;
/// Largest |component| of a mesh `scale` (1000 turns kilometres into metres).
pub const MAX_MESH_SCALE: f64 = 1e3;

/// What to do with a `<mesh>` collision element, which the simulator cannot represent: fit a
/// primitive to it (`mesh::fit`: the smallest of that kind, by volume, that contains every vertex,
/// in the mesh's principal axes or whatever frame is tighter; STL or OBJ files are read).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MeshApprox {
    /// A mesh collision is an error that names the link (the default).
    #[default]
    Error,
    /// The smallest oriented box around the mesh.
    Box,
    /// The smallest capsule around the mesh, or the smallest sphere where that is tighter.
    Capsule,
}

/// A fit whose primitive has more than this many times the volume of the mesh's convex hull is
/// reported as poor (a warning of `dextrain check`).
pub const POOR_FIT_VOLUME_RATIO: f32 = 2.0;
/// A fit whose primitive sticks out of the mesh's convex hull by more than this (m) is reported as
/// poor.
pub const POOR_FIT_GAP_M: f32 = 0.010;

/// What one `<mesh>` collision became (`mesh_approx`), and how much bigger than the mesh it is.
#[derive(Clone, Debug, PartialEq)]
pub struct MeshFitReport {
    /// The URDF link that holds the mesh.
    pub link: String,
    /// The mesh file read.
    pub mesh: PathBuf,
    /// The fitted primitive.
    pub shape: ColliderShape,
    /// Volume of the mesh's convex hull (m³).
    pub hull_volume: f32,
    /// Primitive volume over hull volume (≥ 1).
    pub volume_ratio: f32,
    /// The axis-aligned primitive of the same kind (what the loader made before), over hull volume.
    pub aligned_volume_ratio: f32,
    /// Largest distance (m) from a point of the primitive's surface to the mesh's convex hull.
    pub max_gap: f32,
}

impl MeshFitReport {
    /// True where the primitive is much bigger than the mesh ([`POOR_FIT_VOLUME_RATIO`],
    /// [`POOR_FIT_GAP_M`]).
    pub fn is_poor(&self) -> bool {
        self.volume_ratio > POOR_FIT_VOLUME_RATIO || self.max_gap > POOR_FIT_GAP_M
    }

    /// One line: link, mesh file, primitive and sizes (mm), volume ratios and the largest gap.
    pub fn describe(&self) -> String {
        let mm = |v: f32| format!("{:.1}", v * 1e3);
        let shape = match self.shape {
            ColliderShape::Sphere { radius } => format!("sphere r {} mm", mm(radius)),
            ColliderShape::Capsule { radius, half_length } => format!("capsule r {} mm, length {} mm", mm(radius), mm(2.0 * half_length)),
            ColliderShape::Box { half_extents: h } => format!("box {} × {} × {} mm", mm(2.0 * h.x), mm(2.0 * h.y), mm(2.0 * h.z)),
        };
        let file = self.mesh.file_name().map(|f| f.to_string_lossy().into_owned()).unwrap_or_default();
        format!(
            "link '{}': mesh {file} -> {shape}: {:.2}× the convex hull's volume (axis-aligned: {:.2}×), sticks out up to {} mm",
            self.link,
            self.volume_ratio,
            self.aligned_volume_ratio,
            mm(self.max_gap)
        )
    }
}

/// Options of the URDF loader (built from `[hand]`; errors about them name the config keys).
#[derive(Clone, Debug, Default)]
pub struct HandLoadOptions {
    /// The fingertips (`hand.fingertips`): frame names (links, possibly merged by fixed joints) or
    /// points on links. Empty: every link whose name contains `tip` (case-insensitive), only the
    /// most distal one per finger chain, in URDF order (see [`HandModel::finger_chains`]).
    pub fingertips: Vec<FingertipSpec>,
    /// Opt-in approximation of mesh collision geometry.
    pub mesh_approx: MeshApprox,
    /// Effort limits (N·m) that replace the URDF's (`hand.effort`); a joint it names need not have
    /// a valid URDF `effort`.
    pub effort: Option<JointLimitOverride>,
    /// Velocity limits (rad/s) that replace the URDF's (`hand.velocity`); a joint it names need not
    /// have a valid URDF `velocity`.
    pub velocity: Option<JointLimitOverride>,
}

/// A mimic relation: `q = multiplier * q[leader] + offset`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Mimic {
    /// Index into `HandModel::joints` of the leader (never itself a follower).
    pub leader: usize,
    /// `multiplier` of `q = multiplier * q[leader] + offset` (composed along a mimic chain).
    pub multiplier: f32,
    /// `offset` (rad) of `q = multiplier * q[leader] + offset` (composed along a mimic chain).
    pub offset: f32,
}

/// A movable (revolute or continuous) joint.
#[derive(Clone, Debug, PartialEq)]
pub struct Joint {
    /// The URDF joint name.
    pub name: String,
    /// Index into `HandModel::links` of the parent link.
    pub parent_link: usize,
    /// Pose of the joint frame in the parent link's frame (URDF `<origin>`).
    pub origin: Pose,
    /// Unit rotation axis in the joint frame (URDF `<axis>`, default x).
    pub axis: Vec3,
    /// Lower position limit (rad). Continuous joints: -inf.
    pub lower: f32,
    /// Upper position limit (rad). Continuous joints: +inf.
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
    /// The URDF link name.
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
    /// A sphere of `radius` (m) about the collider's origin.
    Sphere { radius: f32 },
    /// A URDF cylinder or capsule becomes a capsule: `half_length` of the segment, not counting caps.
    Capsule { radius: f32, half_length: f32 },
    /// A box with `half_extents` (m) along the collider's axes.
    Box { half_extents: Vec3 },
}

/// A collision shape attached to a link.
#[derive(Clone, Debug, PartialEq)]
pub struct Collider {
    /// Index into `HandModel::links`.
    pub link: usize,
    /// Pose of the shape in the link frame.
    pub pose: Pose,
    /// The shape and its size.
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

/// A named frame of a URDF link that was merged into another link by a fixed joint.
#[derive(Clone, Debug, PartialEq)]
pub struct LinkFrame {
    /// The URDF link name.
    pub name: String,
    /// Index into `HandModel::links` of the link it was merged into.
    pub link: usize,
    /// Pose of the frame in that link's frame (the composed fixed-joint origins).
    pub pose: Pose,
}

/// A hand, ready for the simulator.
#[derive(Clone, Debug, PartialEq)]
pub struct HandModel {
    /// The URDF `<robot name>`.
    pub name: String,
    /// The URDF file (or the `source` given to [`HandModel::from_urdf_str`]).
    pub source: PathBuf,
    /// Rigid links after fixed joints are merged; `links[0]` is the root (see the CONTRACT).
    pub links: Vec<Link>,
    /// Movable joints in topological order; `links[i + 1]` is the child of `joints[i]`.
    pub joints: Vec<Joint>,
    /// Collision shapes, sorted by link.
    pub colliders: Vec<Collider>,
    /// Fingertip frames, in the order of the `fingertips` option (or of the URDF).
    pub fingertips: Vec<Fingertip>,
    /// URDF links merged away by fixed joints, in URDF document order (the links of `links` are
    /// not repeated here). Use [`HandModel::frame`] to resolve any URDF link name.
    pub frames: Vec<LinkFrame>,
    /// Problems that do not stop the hand from loading (one line each, naming the URDF): the
    /// number of fingertips differs from the number of finger chains. The config-based callers
    /// print them once.
    pub warnings: Vec<String>,
    /// What each `<mesh>` collision became (`mesh_approx`), in URDF order.
    pub mesh_fits: Vec<MeshFitReport>,
}

impl HandModel {
    /// Loads a hand from a URDF file. Errors are one line and name the file and the link or joint.
    pub fn from_urdf_file(path: &Path, opts: &HandLoadOptions) -> Result<HandModel> {
        if let Ok(meta) = std::fs::metadata(path)
            && meta.len() > MAX_URDF_BYTES as u64
        {
            return Err(one_line_error(format!(
                "cannot read hand URDF {}: {} bytes; expected at most {MAX_URDF_BYTES} bytes (MAX_URDF_BYTES)",
                path.display(),
                meta.len()
            )));
        }
        let text = std::fs::read_to_string(path).map_err(|e| {
            one_line_error(format!(
                "cannot read hand URDF {}: {e}; expected a readable UTF-8 URDF file",
                path.display()
            ))
        })?;
        Self::from_urdf_str(&text, path, opts)
    }

    /// Parses a URDF document; `source` is used in error messages and to resolve mesh paths.
    /// The text is pre-scanned first (size, nesting, the attributes urdf-rs reads; see the module
    /// documentation), so that a malformed document is a one-line error naming the element.
    pub fn from_urdf_str(text: &str, source: &Path, opts: &HandLoadOptions) -> Result<HandModel> {
        let file = source.display().to_string();
        if text.len() > MAX_URDF_BYTES {
            return Err(one_line_error(format!(
                "cannot parse hand URDF {file}: {} bytes; expected at most {MAX_URDF_BYTES} bytes (MAX_URDF_BYTES)",
                text.len()
            )));
        }
        let (elems, end) = scan_xml(text).map_err(|e| one_line_error(format!("cannot parse hand URDF {file}: {e}")))?;
        let problem = match end {
            ScanEnd::Complete => check_urdf_elements(&elems),
            ScanEnd::EndsInside(e) => Some(format!(
                "line {}: {}: <{}> is not closed before the end of the text (truncated?); expected a complete URDF document",
                elems[e].line,
                owner_of(&elems, e),
                clip(&elems[e].name, MAX_QUOTED_CHARS)
            )),
            // malformed XML: urdf-rs's parser says where
            ScanEnd::Stopped => None,
        };
        if let Some(e) = problem {
            return Err(one_line_error(format!("cannot parse hand URDF {file}: {e}")));
        }
        let robot = urdf_rs::read_from_string(text).map_err(|e| {
            one_line_error(format!(
                "cannot parse hand URDF {file}: {}; expected a well-formed URDF <robot> document",
                clip(&e.to_string(), 2 * MAX_QUOTED_CHARS)
            ))
        })?;
        // the names of the <parent> elements that hold a <child> element
        let holders = |child: &str, parent: &str| {
            elems
                .iter()
                .filter(|e| e.name == child)
                .filter_map(|e| e.parent.map(|p| &elems[p]))
                .filter(|p| p.name == parent)
                .filter_map(|p| p.attr("name").map(str::to_string))
                .collect()
        };
        // links with an <inertial> element (the others are massless frames)
        let inertial_links = holders("inertial", "link");
        // joints with a <limit> element (urdf-rs reads a missing one as all zeros)
        let limit_joints = holders("limit", "joint");
        let loader = Loader { file, source, opts, inertial_links, limit_joints, mesh_fits: Default::default() };
        loader.build(&robot).map_err(one_line_error)
    }

    /// Index of a joint by name.
    pub fn joint_index(&self, name: &str) -> Option<usize> {
        self.joints.iter().position(|j| j.name == name)
    }

    /// Index of a link by name (links merged by fixed joints resolve through [`HandModel::frame`]).
    pub fn link_index(&self, name: &str) -> Option<usize> {
        self.links.iter().position(|l| l.name == name)
    }

    /// Resolves a URDF link name to `(index into links, pose of that frame in the link's frame)`.
    /// A link of `links` resolves to itself with the identity pose; a link merged by fixed joints
    /// resolves to the link it was merged into with the composed fixed-joint origins.
    pub fn frame(&self, name: &str) -> Option<(usize, Pose)> {
        if let Some(i) = self.link_index(name) {
            return Some((i, Pose::IDENTITY));
        }
        self.frames.iter().find(|f| f.name == name).map(|f| (f.link, f.pose))
    }

    /// Number of actuated joints (movable joints that are not mimic followers).
    pub fn num_actuated(&self) -> usize {
        self.joints.iter().filter(|j| j.mimic.is_none()).count()
    }

    /// Indices (into `joints`) of the actuated joints, in joint order.
    pub fn actuated_joints(&self) -> Vec<usize> {
        (0..self.joints.len()).filter(|&i| self.joints[i].mimic.is_none()).collect()
    }

    /// Total mass of the hand (kg).
    pub fn total_mass(&self) -> f32 {
        self.links.iter().map(|l| l.mass).sum()
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

    /// `q` (one entry per joint) with every mimic follower set to `multiplier × leader + offset`.
    pub fn with_mimic(&self, mut q: Vec<f32>) -> Vec<f32> {
        for (j, jt) in self.joints.iter().enumerate() {
            if let Some(m) = jt.mimic {
                q[j] = m.multiplier * q[m.leader] + m.offset;
            }
        }
        q
    }

    /// Fingertip positions in the wrist frame, in `fingertips` order, for link poses from
    /// [`HandModel::forward_kinematics`].
    pub fn fingertip_positions(&self, link_poses: &[Pose]) -> Vec<Vec3> {
        self.fingertips.iter().map(|t| link_poses[t.link].transform_point(t.pos)).collect()
    }

    /// The finger chains, one per finger, as the index (into `links`) of the link that ends it: a
    /// finger is a path of movable joints that ends at a link no movable joint leaves (a leaf of
    /// the movable-joint tree, the root excluded), so a joint chain shared by several fingers
    /// above the point where they branch (Shadow's wrist WRJ2/WRJ1, SCHUNK SVH's `j5` that carries
    /// the ring and little fingers) is part of each and counts as none. In link order.
    pub fn finger_chains(&self) -> Vec<usize> {
        let mut has_child = vec![false; self.links.len()];
        for j in &self.joints {
            has_child[j.parent_link] = true;
        }
        (1..self.links.len()).filter(|&l| !has_child[l]).collect()
    }

    /// Whether link `a` is link `b` or one of the links it hangs from.
    pub fn is_ancestor_or_same(&self, a: usize, b: usize) -> bool {
        let mut l = b;
        loop {
            if l == a {
                return true;
            }
            if l == 0 {
                return false;
            }
            l = self.joints[l - 1].parent_link;
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Loader internals. Everything is computed in f64 and converted to f32 at the end.

/// Turns a message into a one-line `anyhow::Error`, quoted values cut to [`MAX_QUOTED_CHARS`].
fn one_line_error(msg: String) -> anyhow::Error {
    let msg = msg.replace('\r', "\n");
    let line: Vec<&str> = msg.lines().map(str::trim).filter(|l| !l.is_empty()).collect();
    anyhow::anyhow!("{}", clip_quoted(&line.join(" ")))
}

type R<T> = std::result::Result<T, String>;

/// A rigid pose in f64.
#[derive(Clone, Copy, Debug)]
struct DPose {
    pos: DVec3,
    rot: DQuat,
}

impl DPose {
    const IDENTITY: DPose = DPose { pos: DVec3::ZERO, rot: DQuat::IDENTITY };

    fn mul(&self, o: &DPose) -> DPose {
        DPose { pos: self.pos + self.rot * o.pos, rot: (self.rot * o.rot).normalize() }
    }

    fn to_pose(self) -> Pose {
        Pose::new(self.pos.as_vec3(), self.rot.as_quat().normalize())
    }
}

/// URDF rpy (fixed axes: roll about x, then pitch about y, then yaw about z):
/// R = Rz(yaw) · Ry(pitch) · Rx(roll).
fn rpy_to_quat(rpy: [f64; 3]) -> DQuat {
    (DQuat::from_rotation_z(rpy[2]) * DQuat::from_rotation_y(rpy[1]) * DQuat::from_rotation_x(rpy[0])).normalize()
}

fn urdf_pose(p: &urdf_rs::Pose) -> DPose {
    DPose { pos: DVec3::from_array(p.xyz.0), rot: rpy_to_quat(p.rpy.0) }
}

fn finite3(v: &[f64; 3]) -> bool {
    v.iter().all(|x| x.is_finite())
}

fn fmt3(v: &[f64; 3]) -> String {
    format!("{} {} {}", fnum(v[0]), fnum(v[1]), fnum(v[2]))
}

/// A number as a message shows it: plain, or in exponent form when huge or tiny (`1e300`, not
/// 301 digits).
fn fnum(v: f64) -> String {
    if v != 0.0 && v.is_finite() && !(1e-4..1e6).contains(&v.abs()) { format!("{v:e}") } else { format!("{v}") }
}

fn pose_is_finite(p: &urdf_rs::Pose) -> bool {
    finite3(&p.xyz.0) && finite3(&p.rpy.0)
}

/// A finite `<origin>` whose `xyz` is within ±[`MAX_LENGTH_M`] and `rpy` within ±[`MAX_ANGLE_RAD`];
/// `owner` names the link or joint (and the file), `what` the element.
fn check_origin(owner: &str, what: &str, p: &urdf_rs::Pose) -> R<()> {
    if p.xyz.0.iter().any(|v| v.abs() > MAX_LENGTH_M) {
        return Err(format!("{owner} has {what} xyz {}; expected coordinates within ±{MAX_LENGTH_M} m", fmt3(&p.xyz.0)));
    }
    if p.rpy.0.iter().any(|v| v.abs() > MAX_ANGLE_RAD) {
        return Err(format!("{owner} has {what} rpy {}; expected angles within ±{MAX_ANGLE_RAD} rad", fmt3(&p.rpy.0)));
    }
    Ok(())
}

/// A name as a TOML key: bare where it can be (`joint_0`), quoted otherwise (`"joint_0.0"`).
fn toml_key(name: &str) -> String {
    if !name.is_empty() && name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-') { name.to_string() } else { format!("{name:?}") }
}

fn is_movable(j: &urdf_rs::Joint) -> bool {
    matches!(j.joint_type, urdf_rs::JointType::Revolute | urdf_rs::JointType::Continuous)
}

fn joint_type_name(t: &urdf_rs::JointType) -> &'static str {
    use urdf_rs::JointType::*;
    match t {
        Revolute => "revolute",
        Continuous => "continuous",
        Prismatic => "prismatic",
        Fixed => "fixed",
        Floating => "floating",
        Planar => "planar",
        Spherical => "spherical",
    }
}

/// Mass, centre of mass and inertia about the COM of one URDF link's `<inertial>`, expressed in a
/// merged link's frame.
struct MassPart {
    mass: f64,
    com: DVec3,
    inertia: DMat3,
}

fn combine_mass(parts: &[MassPart]) -> (f64, DVec3, DMat3) {
    let mass: f64 = parts.iter().map(|p| p.mass).sum();
    let com = if mass > 0.0 {
        parts.iter().map(|p| p.com * p.mass).sum::<DVec3>() / mass
    } else {
        DVec3::ZERO
    };
    let mut inertia = DMat3::ZERO;
    for p in parts {
        // parallel-axis theorem: I_com + m (|d|² E − d dᵀ)
        let d = p.com - com;
        let outer = DMat3::from_cols(d * d.x, d * d.y, d * d.z);
        inertia += p.inertia + (DMat3::from_diagonal(DVec3::splat(d.length_squared())) - outer) * p.mass;
    }
    let inertia = (inertia + inertia.transpose()) * 0.5;
    (mass, com, inertia)
}

struct Loader<'a> {
    file: String,
    source: &'a Path,
    opts: &'a HandLoadOptions,
    /// Names of the links that have an `<inertial>` element.
    inertial_links: std::collections::HashSet<String>,
    /// Names of the joints that have a `<limit>` element.
    limit_joints: std::collections::HashSet<String>,
    /// What each `<mesh>` collision became, in the order the colliders are read.
    mesh_fits: std::cell::RefCell<Vec<MeshFitReport>>,
}

impl Loader<'_> {
    fn build(&self, robot: &urdf_rs::Robot) -> R<HandModel> {
        let f = &self.file;
        let n = robot.links.len();
        if n == 0 {
            return Err(format!("{f} has no <link>; expected a hand whose root link is the palm"));
        }

        // ---- links
        let mut link_index: HashMap<&str, usize> = HashMap::new();
        for (i, l) in robot.links.iter().enumerate() {
            if link_index.insert(l.name.as_str(), i).is_some() {
                return Err(format!("link '{}' in {f} is defined twice; expected unique link names", l.name));
            }
            self.check_link(l)?;
        }

        // ---- joints and the tree structure
        let mut joint_index: HashMap<&str, usize> = HashMap::new();
        let mut parent_joint: Vec<Option<usize>> = vec![None; n];
        let mut children: Vec<Vec<usize>> = vec![Vec::new(); n];
        let mut ends: Vec<(usize, usize)> = Vec::with_capacity(robot.joints.len());
        for (ji, j) in robot.joints.iter().enumerate() {
            let name = &j.name;
            if joint_index.insert(name.as_str(), ji).is_some() {
                return Err(format!("joint '{name}' in {f} is defined twice; expected unique joint names"));
            }
            if !matches!(
                j.joint_type,
                urdf_rs::JointType::Revolute | urdf_rs::JointType::Continuous | urdf_rs::JointType::Fixed
            ) {
                return Err(format!(
                    "joint '{name}' in {f} is {}; dextrain hands support revolute, continuous and fixed joints",
                    joint_type_name(&j.joint_type)
                ));
            }
            let lookup = |role: &str, link: &str| {
                link_index.get(link).copied().ok_or_else(|| {
                    format!(
                        "joint '{name}' in {f} references unknown {role} link '{link}'; expected the name of a <link> in the file"
                    )
                })
            };
            let p = lookup("parent", &j.parent.link)?;
            let c = lookup("child", &j.child.link)?;
            if p == c {
                return Err(format!(
                    "joint '{name}' in {f} connects link '{}' to itself; expected a tree of links (no loops)",
                    j.parent.link
                ));
            }
            if let Some(other) = parent_joint[c] {
                return Err(format!(
                    "link '{}' in {f} has two parent joints ('{}' and '{name}'); expected a tree (every link has at most one parent joint, no loops)",
                    j.child.link, robot.joints[other].name
                ));
            }
            if !pose_is_finite(&j.origin) {
                return Err(format!(
                    "joint '{name}' in {f} has a non-finite <origin> (xyz {}, rpy {}); expected finite numbers",
                    fmt3(&j.origin.xyz.0),
                    fmt3(&j.origin.rpy.0)
                ));
            }
            check_origin(&format!("joint '{name}' in {f}"), "<origin>", &j.origin)?;
            parent_joint[c] = Some(ji);
            children[p].push(ji);
            ends.push((p, c));
        }

        // joints named by hand.effort / hand.velocity tables are movable joints of this hand
        for (what, limit) in [("effort", &self.opts.effort), ("velocity", &self.opts.velocity)] {
            let Some(JointLimitOverride::PerJoint(m)) = limit else { continue };
            if let Some(bad) = m.keys().find(|k| !robot.joints.iter().any(|j| &j.name == *k && is_movable(j))) {
                let names: Vec<&str> = robot.joints.iter().filter(|j| is_movable(j)).map(|j| j.name.as_str()).collect();
                return Err(format!(
                    "key `hand.{what}.{bad}`: {f} has no movable joint '{bad}'; expected the name of one of its revolute or continuous joints ({})",
                    names.join(", ")
                ));
            }
        }

        let roots: Vec<usize> = (0..n).filter(|&i| parent_joint[i].is_none()).collect();
        if roots.is_empty() {
            return Err(format!(
                "{f} has no root link: every link has a parent joint, so the joints form a loop (e.g. through link '{}'); expected a tree rooted at the palm",
                robot.links[0].name
            ));
        }
        if roots.len() > 1 {
            let names: Vec<String> = roots.iter().map(|&i| format!("'{}'", robot.links[i].name)).collect();
            return Err(format!(
                "{f} has several root links ({}); expected exactly one link without a parent joint (the palm), every other link connected to it by joints",
                names.join(", ")
            ));
        }
        let root = roots[0];

        let movable: Vec<&urdf_rs::Joint> = robot.joints.iter().filter(|j| is_movable(j)).collect();
        if movable.len() > MAX_JOINTS {
            return Err(format!(
                "{f} has {} movable (revolute or continuous) joints, joint '{}' is number {}; expected at most {MAX_JOINTS} (MAX_JOINTS)",
                movable.len(),
                movable[MAX_JOINTS].name,
                MAX_JOINTS + 1
            ));
        }

        // ---- depth-first walk from the root: merged links, movable joints in topological order
        let mut place: Vec<Option<(usize, DPose)>> = vec![None; n];
        place[root] = Some((0, DPose::IDENTITY));
        let mut body_of: Vec<usize> = vec![root]; // merged link -> URDF link
        let mut joint_of: Vec<usize> = Vec::new(); // movable joint -> URDF joint
        let mut joints: Vec<Joint> = Vec::new();
        let mut stack: Vec<usize> = children[root].iter().rev().copied().collect();
        while let Some(ji) = stack.pop() {
            let j = &robot.joints[ji];
            let (p, c) = ends[ji];
            let (plink, ppose) = place[p].expect("a parent link is placed before its child joints");
            let origin = ppose.mul(&urdf_pose(&j.origin));
            if is_movable(j) {
                joints.push(self.movable_joint(j, plink, origin)?);
                joint_of.push(ji);
                body_of.push(c);
                place[c] = Some((joints.len(), DPose::IDENTITY));
            } else {
                place[c] = Some((plink, origin));
            }
            stack.extend(children[c].iter().rev().copied());
        }
        if let Some(i) = (0..n).find(|&i| place[i].is_none()) {
            return Err(format!(
                "link '{}' in {f} is not connected to the root link '{}' (its parent joints form a loop); expected a tree of links",
                robot.links[i].name, robot.links[root].name
            ));
        }

        // ---- mimic joints: resolve to the root leader
        let mut movable_of: HashMap<usize, usize> = HashMap::new(); // URDF joint -> movable joint
        for (mi, &ji) in joint_of.iter().enumerate() {
            movable_of.insert(ji, mi);
        }
        for (mi, &ji) in joint_of.iter().enumerate() {
            let j = &robot.joints[ji];
            let Some(m) = &j.mimic else { continue };
            let name = &j.name;
            let (mut mult, mut off) = self.mimic_coeffs(name, m)?;
            let mut leader_name = m.joint.as_str();
            let mut steps = 0;
            let leader = loop {
                let Some(&lj) = joint_index.get(leader_name) else {
                    return Err(format!(
                        "joint '{name}' in {f} mimics unknown joint '{leader_name}'; expected the name of a revolute or continuous joint"
                    ));
                };
                if lj == ji {
                    return Err(if steps == 0 {
                        format!("joint '{name}' in {f} mimics itself; expected <mimic joint> to name another revolute or continuous joint")
                    } else {
                        format!("joint '{name}' in {f} is part of a mimic cycle; expected mimic chains to end at a joint without <mimic>")
                    });
                }
                let lead = &robot.joints[lj];
                if !is_movable(lead) {
                    return Err(format!(
                        "joint '{name}' in {f} mimics joint '{leader_name}', which is {}; expected a revolute or continuous leader",
                        joint_type_name(&lead.joint_type)
                    ));
                }
                match &lead.mimic {
                    None => break movable_of[&lj],
                    Some(m2) => {
                        let (mult2, off2) = self.mimic_coeffs(&lead.name, m2)?;
                        // q = mult (mult2 q_leader2 + off2) + off
                        off += mult * off2;
                        mult *= mult2;
                        leader_name = m2.joint.as_str();
                        steps += 1;
                        if steps > robot.joints.len() {
                            return Err(format!(
                                "joint '{name}' in {f} has a mimic chain through joint '{}' that forms a cycle; expected mimic chains to end at a joint without <mimic>",
                                lead.name
                            ));
                        }
                    }
                }
            };
            if mult.abs() > MAX_MIMIC_MULTIPLIER || off.abs() > MAX_ANGLE_RAD {
                return Err(format!(
                    "joint '{name}' in {f} follows its root leader with multiplier {} and offset {} (composed along its mimic chain); expected |multiplier| <= {MAX_MIMIC_MULTIPLIER} and |offset| <= {MAX_ANGLE_RAD} rad",
                    fnum(mult),
                    fnum(off)
                ));
            }
            joints[mi].mimic = Some(Mimic { leader, multiplier: mult as f32, offset: off as f32 });
        }

        // ---- masses (merged), colliders, frames
        let nl = body_of.len();
        let mut parts: Vec<Vec<MassPart>> = (0..nl).map(|_| Vec::new()).collect();
        let mut colliders: Vec<Collider> = Vec::new();
        let mut frames: Vec<LinkFrame> = Vec::new();
        for (i, l) in robot.links.iter().enumerate() {
            let (li, lpose) = place[i].expect("every link is placed");
            if body_of[li] != i {
                frames.push(LinkFrame { name: l.name.clone(), link: li, pose: lpose.to_pose() });
            }
            let inr = &l.inertial;
            let ipose = lpose.mul(&urdf_pose(&inr.origin));
            let rot = DMat3::from_quat(ipose.rot);
            let t = &inr.inertia;
            let local = DMat3::from_cols(
                DVec3::new(t.ixx, t.ixy, t.ixz),
                DVec3::new(t.ixy, t.iyy, t.iyz),
                DVec3::new(t.ixz, t.iyz, t.izz),
            );
            parts[li].push(MassPart { mass: inr.mass.value, com: ipose.pos, inertia: rot * local * rot.transpose() });
            for (ci, c) in l.collision.iter().enumerate() {
                colliders.push(self.collider(l, ci, c, li, lpose)?);
            }
        }
        colliders.sort_by_key(|c| c.link);

        let links: Vec<Link> = body_of
            .iter()
            .zip(&parts)
            .map(|(&ui, parts)| {
                let (mass, com, inertia) = combine_mass(parts);
                let r = |k: usize| {
                    let row = inertia.row(k);
                    [row.x as f32, row.y as f32, row.z as f32]
                };
                Link { name: robot.links[ui].name.clone(), mass: mass as f32, com: com.as_vec3(), inertia: [r(0), r(1), r(2)] }
            })
            .collect();

        let root_name = &robot.links[root].name;
        if colliders.is_empty() {
            return Err(format!(
                "{f} has no collision shapes (root link '{root_name}'); expected at least one <collision> with a sphere, box, cylinder or capsule"
            ));
        }
        if colliders.len() > MAX_COLLIDERS {
            return Err(format!(
                "{f} has {} collision shapes, link '{}' holds number {}; expected at most {MAX_COLLIDERS} (MAX_COLLIDERS)",
                colliders.len(),
                links[colliders[MAX_COLLIDERS].link].name,
                MAX_COLLIDERS + 1
            ));
        }

        let mut model = HandModel {
            name: robot.name.clone(),
            source: self.source.to_path_buf(),
            links,
            joints,
            colliders,
            fingertips: Vec::new(),
            frames,
            warnings: Vec::new(),
            mesh_fits: self.mesh_fits.take(),
        };
        (model.fingertips, model.warnings) = self.fingertips(robot, &model)?;
        for fit in model.mesh_fits.iter().filter(|m| m.is_poor()) {
            model.warnings.push(format!(
                "{}: poor mesh fit: {} (more than {POOR_FIT_VOLUME_RATIO}× or {} mm); split the mesh into convex pieces or give the link primitive collision shapes",
                self.file,
                fit.describe(),
                POOR_FIT_GAP_M * 1e3
            ));
        }
        Ok(model)
    }

    fn check_link(&self, l: &urdf_rs::Link) -> R<()> {
        let f = &self.file;
        let name = &l.name;
        let inr = &l.inertial;
        if !pose_is_finite(&inr.origin) {
            return Err(format!("link '{name}' in {f} has a non-finite <inertial><origin>; expected finite numbers"));
        }
        let m = inr.mass.value;
        if !m.is_finite() {
            return Err(format!("link '{name}' in {f} has a non-finite mass ({m}); expected a finite mass >= 0 kg"));
        }
        if m < 0.0 {
            return Err(format!("link '{name}' in {f} has a negative mass ({m}); expected a mass >= 0 kg"));
        }
        // a link without <inertial> is a massless frame (urdf-rs reads it as mass 0, inertia 0)
        if self.inertial_links.contains(name.as_str()) && !(MIN_LINK_MASS_KG..=MAX_LINK_MASS_KG).contains(&m) {
            return Err(format!(
                "link '{name}' in {f} has <inertial><mass value> {}; expected a mass in [{MIN_LINK_MASS_KG}, {MAX_LINK_MASS_KG}] kg (leave <inertial> out for a massless frame)",
                fnum(m)
            ));
        }
        let t = &inr.inertia;
        let all = [t.ixx, t.ixy, t.ixz, t.iyy, t.iyz, t.izz];
        if !all.iter().all(|x| x.is_finite()) {
            return Err(format!("link '{name}' in {f} has a non-finite <inertia>; expected finite numbers (kg·m²)"));
        }
        if t.ixx < 0.0 || t.iyy < 0.0 || t.izz < 0.0 {
            return Err(format!(
                "link '{name}' in {f} has a negative principal inertia (ixx {} iyy {} izz {}); expected ixx, iyy, izz >= 0",
                t.ixx, t.iyy, t.izz
            ));
        }
        for (attr, v) in ["ixx", "ixy", "ixz", "iyy", "iyz", "izz"].iter().zip(all) {
            if v.abs() > MAX_INERTIA_KG_M2 {
                return Err(format!(
                    "link '{name}' in {f} has <inertia {attr}> {}; expected |{attr}| <= {MAX_INERTIA_KG_M2} kg·m²",
                    fnum(v)
                ));
            }
        }
        // positive semi-definite: every principal minor >= 0 (up to rounding, relative to the
        // largest moment s): ixx·iyy − ixy² ≥ 0, ixx·izz − ixz² ≥ 0, iyy·izz − iyz² ≥ 0, det ≥ 0
        let s = t.ixx.max(t.iyy).max(t.izz);
        let tol = 1e-6;
        let det = t.ixx * (t.iyy * t.izz - t.iyz * t.iyz) - t.ixy * (t.ixy * t.izz - t.iyz * t.ixz)
            + t.ixz * (t.ixy * t.iyz - t.iyy * t.ixz);
        let minors = [t.ixx * t.iyy - t.ixy * t.ixy, t.ixx * t.izz - t.ixz * t.ixz, t.iyy * t.izz - t.iyz * t.iyz];
        if minors.iter().any(|&m2| m2 < -tol * s * s) || det < -tol * s * s * s {
            return Err(format!(
                "link '{name}' in {f} has an <inertia> that is not positive semi-definite (ixx {} ixy {} ixz {} iyy {} iyz {} izz {}); expected a physical inertia tensor (ixx·iyy >= ixy², ixx·izz >= ixz², iyy·izz >= iyz², determinant >= 0)",
                fnum(t.ixx),
                fnum(t.ixy),
                fnum(t.ixz),
                fnum(t.iyy),
                fnum(t.iyz),
                fnum(t.izz)
            ));
        }
        check_origin(&format!("link '{name}' in {f}"), "<inertial><origin>", &inr.origin)?;
        for (ci, c) in l.collision.iter().enumerate() {
            if !pose_is_finite(&c.origin) {
                return Err(format!(
                    "link '{name}' in {f} has a non-finite <collision><origin> (collision {ci}); expected finite numbers"
                ));
            }
            check_origin(&format!("link '{name}' in {f}"), &format!("<collision><origin> (collision {ci})"), &c.origin)?;
        }
        Ok(())
    }

    fn mimic_coeffs(&self, joint: &str, m: &urdf_rs::Mimic) -> R<(f64, f64)> {
        let mult = m.multiplier.unwrap_or(1.0);
        let off = m.offset.unwrap_or(0.0);
        if !mult.is_finite() || !off.is_finite() {
            return Err(format!(
                "joint '{joint}' in {} has a non-finite <mimic> (multiplier {mult}, offset {off}); expected finite numbers",
                self.file
            ));
        }
        if mult.abs() > MAX_MIMIC_MULTIPLIER || off.abs() > MAX_ANGLE_RAD {
            return Err(format!(
                "joint '{joint}' in {} has <mimic multiplier=\"{}\" offset=\"{}\">; expected |multiplier| <= {MAX_MIMIC_MULTIPLIER} and |offset| <= {MAX_ANGLE_RAD} rad",
                self.file,
                fnum(mult),
                fnum(off)
            ));
        }
        Ok((mult, off))
    }

    fn movable_joint(&self, j: &urdf_rs::Joint, parent_link: usize, origin: DPose) -> R<Joint> {
        let f = &self.file;
        let name = &j.name;
        let axis = DVec3::from_array(j.axis.xyz.0);
        if !axis.is_finite() || axis.length() < 1e-9 || axis.abs().max_element() > MAX_AXIS_COMPONENT {
            return Err(format!(
                "joint '{name}' in {f} has axis ({}); expected a finite non-zero <axis xyz> with components within ±{MAX_AXIS_COMPONENT}",
                fmt3(&j.axis.xyz.0)
            ));
        }
        let lim = &j.limit;
        let continuous = j.joint_type == urdf_rs::JointType::Continuous;
        if !continuous && !self.limit_joints.contains(name.as_str()) {
            // urdf-rs reads a missing <limit> as lower = upper = 0: a locked joint. The config can
            // give effort and velocity, not position limits.
            return Err(format!(
                "joint '{name}' in {f} is revolute but has no <limit>; expected <limit lower upper effort velocity> on a revolute joint (hand.effort and hand.velocity in the config replace effort and velocity only; position limits come from the URDF)"
            ));
        }
        let (lower, upper) = if continuous {
            (f32::NEG_INFINITY, f32::INFINITY)
        } else {
            if !lim.lower.is_finite() || !lim.upper.is_finite() {
                return Err(format!(
                    "joint '{name}' in {f} has non-finite limits (lower {}, upper {}); expected finite <limit lower upper> (rad) on a revolute joint",
                    lim.lower, lim.upper
                ));
            }
            for (what, v) in [("lower", lim.lower), ("upper", lim.upper)] {
                if v.abs() > MAX_ANGLE_RAD {
                    return Err(format!(
                        "joint '{name}' in {f} has <limit {what}> {}; expected a revolute limit within ±{MAX_ANGLE_RAD} rad",
                        fnum(v)
                    ));
                }
            }
            if lim.lower > lim.upper {
                return Err(format!(
                    "joint '{name}' in {f} has lower limit {} > upper limit {}; expected lower <= upper",
                    lim.lower, lim.upper
                ));
            }
            (lim.lower as f32, lim.upper as f32)
        };
        // effort and velocity: the config's override where it names this joint, else the URDF's
        let mut limits = [0.0f32; 2];
        for (k, (what, urdf, over, unit, max)) in [
            ("effort", lim.effort, &self.opts.effort, "N·m", MAX_EFFORT_NM),
            ("velocity", lim.velocity, &self.opts.velocity, "rad/s", MAX_VELOCITY_RAD_S),
        ]
        .into_iter()
        .enumerate()
        {
            if let Some(v) = over.as_ref().and_then(|o| o.get(name)) {
                let v = f64::from(v);
                if !(v.is_finite() && v > 0.0 && v <= max) {
                    return Err(format!(
                        "joint '{name}' in {f}: hand.{what} gives it {what} limit {}; expected a positive finite limit of at most {max} {unit}",
                        fnum(v)
                    ));
                }
                limits[k] = v as f32;
                continue;
            }
            let fix = format!(
                "or set hand.{what} = <{unit}> (all joints) or hand.{what}.{} = <{unit}> in the config",
                toml_key(name)
            );
            if !(urdf.is_finite() && urdf > 0.0) {
                return Err(format!(
                    "joint '{name}' in {f} has {what} limit {}{}; expected a positive finite <limit {what}> ({unit}) on a movable joint, {fix}",
                    fnum(urdf),
                    if urdf == 0.0 { " (a missing <limit> or attribute reads as 0)" } else { "" }
                ));
            }
            if urdf > max {
                return Err(format!(
                    "joint '{name}' in {f} has {what} limit {}; expected a <limit {what}> of at most {max} {unit}, {fix}",
                    fnum(urdf)
                ));
            }
            limits[k] = urdf as f32;
        }
        let (damping, friction) = j.dynamics.as_ref().map_or((0.0, 0.0), |d| (d.damping, d.friction));
        for (what, v) in [("damping", damping), ("friction", friction)] {
            if !(v.is_finite() && (0.0..=MAX_DAMPING).contains(&v)) {
                return Err(format!(
                    "joint '{name}' in {f} has <dynamics {what}> {}; expected a finite number in [0, {MAX_DAMPING}]",
                    fnum(v)
                ));
            }
        }
        Ok(Joint {
            name: name.clone(),
            parent_link,
            origin: origin.to_pose(),
            axis: axis.normalize().as_vec3(),
            lower,
            upper,
            effort: limits[0],
            velocity: limits[1],
            damping: damping as f32,
            friction: friction as f32,
            mimic: None,
            continuous,
        })
    }

    fn collider(&self, l: &urdf_rs::Link, ci: usize, c: &urdf_rs::Collision, link: usize, lpose: DPose) -> R<Collider> {
        let f = &self.file;
        let name = &l.name;
        let pose = lpose.mul(&urdf_pose(&c.origin));
        let what = match &c.name {
            Some(n) => format!("collision '{n}'"),
            None => format!("collision {ci}"),
        };
        let radius_ok = |r: f64| r.is_finite() && r > 0.0 && r <= MAX_LENGTH_M;
        let size_ok = |s: f64| s.is_finite() && (0.0..=MAX_LENGTH_M).contains(&s);
        let (pose, shape) = match &c.geometry {
            urdf_rs::Geometry::Sphere { radius } => {
                if !radius_ok(*radius) {
                    return Err(format!(
                        "link '{name}' in {f}: {what} sphere radius {}; expected a positive finite radius <= {MAX_LENGTH_M} (m)",
                        fnum(*radius)
                    ));
                }
                (pose, ColliderShape::Sphere { radius: *radius as f32 })
            }
            urdf_rs::Geometry::Box { size } => {
                if !size.0.iter().all(|&s| size_ok(s)) {
                    return Err(format!(
                        "link '{name}' in {f}: {what} box size {}; expected finite sizes in [0, {MAX_LENGTH_M}] (m)",
                        fmt3(&size.0)
                    ));
                }
                let half = DVec3::from_array(size.0) * 0.5;
                (pose, ColliderShape::Box { half_extents: half.as_vec3() })
            }
            urdf_rs::Geometry::Cylinder { radius, length } | urdf_rs::Geometry::Capsule { radius, length } => {
                let kind = if matches!(c.geometry, urdf_rs::Geometry::Cylinder { .. }) { "cylinder" } else { "capsule" };
                if !radius_ok(*radius) || !size_ok(*length) {
                    return Err(format!(
                        "link '{name}' in {f}: {what} {kind} radius {} length {}; expected a positive finite radius and a finite length >= 0, both <= {MAX_LENGTH_M} (m)",
                        fnum(*radius),
                        fnum(*length)
                    ));
                }
                (pose, ColliderShape::Capsule { radius: *radius as f32, half_length: (*length * 0.5) as f32 })
            }
            urdf_rs::Geometry::Mesh { filename, scale } => match self.opts.mesh_approx {
                MeshApprox::Error => {
                    return Err(format!(
                        "link '{name}' in {f} has a <mesh> {what} ('{filename}'); expected sphere, box, cylinder or capsule collision geometry (or opt in to a fitted primitive with hand.mesh_approx = \"capsule\" or \"box\")"
                    ));
                }
                approx => self.mesh_collider(name, filename, scale.as_ref(), approx, pose)?,
            },
        };
        Ok(Collider { link, pose: pose.to_pose(), shape })
    }

    /// Candidate paths of a mesh file name, in lookup order.
    fn mesh_candidates(&self, filename: &str) -> Vec<PathBuf> {
        let parent = self.source.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
        let dir = std::fs::canonicalize(parent).unwrap_or_else(|_| parent.to_path_buf());
        if let Some(rest) = filename.strip_prefix("package://") {
            let (pkg, rel) = rest.split_once('/').unwrap_or(("", rest));
            let mut v = Vec::new();
            for a in dir.ancestors() {
                v.push(a.join(rel));
                if !pkg.is_empty() {
                    v.push(a.join(pkg).join(rel));
                }
            }
            v
        } else {
            let p = Path::new(filename.strip_prefix("file://").unwrap_or(filename));
            vec![if p.is_absolute() { p.to_path_buf() } else { dir.join(p) }]
        }
    }

    fn mesh_collider(
        &self,
        link: &str,
        filename: &str,
        scale: Option<&urdf_rs::Vec3>,
        approx: MeshApprox,
        pose: DPose,
    ) -> R<(DPose, ColliderShape)> {
        let f = &self.file;
        let ext = Path::new(filename).extension().map(|e| e.to_string_lossy().to_ascii_lowercase()).unwrap_or_default();
        if ext != "stl" && ext != "obj" {
            return Err(format!(
                "link '{link}' in {f}: mesh '{filename}' has unsupported format '.{ext}'; expected a .stl (binary or ASCII) or .obj mesh for mesh_approx"
            ));
        }
        let scale = scale.map_or(DVec3::ONE, |s| DVec3::from_array(s.0));
        if !scale.is_finite() || scale.abs().max_element() > MAX_MESH_SCALE {
            return Err(format!(
                "link '{link}' in {f}: mesh '{filename}' has scale {}; expected finite numbers within ±{MAX_MESH_SCALE}",
                fmt3(&scale.to_array())
            ));
        }
        let candidates = self.mesh_candidates(filename);
        let Some(path) = candidates.iter().find(|p| p.is_file()) else {
            return Err(format!(
                "link '{link}' in {f}: mesh file '{filename}' not found (looked for {}{}); expected a path relative to the URDF directory, package://pkg/path or file:///absolute/path",
                candidates[0].display(),
                if candidates.len() > 1 { " and in parent directories" } else { "" }
            ));
        };
        let bytes = std::fs::read(path)
            .map_err(|e| format!("link '{link}' in {f}: cannot read mesh {}: {e}", path.display()))?;
        let verts = if ext == "stl" { parse_stl(&bytes) } else { parse_obj(&bytes) }
            .map_err(|e| format!("link '{link}' in {f}: cannot read mesh {}: {e}", path.display()))?;
        if verts.is_empty() {
            return Err(format!("link '{link}' in {f}: mesh {} has no vertices; expected a non-empty mesh", path.display()));
        }
        let scaled: Vec<DVec3> = verts.iter().map(|v| *v * scale).collect();
        let mut lo = DVec3::splat(f64::INFINITY);
        let mut hi = DVec3::splat(f64::NEG_INFINITY);
        for v in &scaled {
            lo = lo.min(*v);
            hi = hi.max(*v);
        }
        let centre = (lo + hi) * 0.5;
        let half = (hi - lo) * 0.5;
        if centre.abs().max_element() > MAX_LENGTH_M || half.max_element() > MAX_LENGTH_M {
            return Err(format!(
                "link '{link}' in {f}: mesh {} spans {} .. {} (scaled, m); expected a mesh within ±{MAX_LENGTH_M} m of its frame (in metres: set <mesh scale> for a mesh in millimetres)",
                path.display(),
                lo,
                hi
            ));
        }
        let kinds: &[PrimitiveKind] = match approx {
            MeshApprox::Box => &[PrimitiveKind::Box],
            _ => &[PrimitiveKind::Capsule, PrimitiveKind::Sphere],
        };
        // one hull serves the fit and the axis-aligned primitive it is compared with
        let mesh_err = |e: String| format!("link '{link}' in {f}: mesh {}: {e}", path.display());
        let hull = convex_hull(&scaled).map_err(mesh_err)?;
        let fit = fit_tightest_with_hull(&scaled, &hull, kinds).map_err(mesh_err)?;
        let aligned = axis_aligned_with_hull(&scaled, &hull, fit.kind());
        let shape = match fit.shape {
            FittedShape::Sphere { radius } => ColliderShape::Sphere { radius: radius as f32 },
            FittedShape::Capsule { radius, half_length } => ColliderShape::Capsule { radius: radius as f32, half_length: half_length as f32 },
            FittedShape::Box { half_extents } => ColliderShape::Box { half_extents: half_extents.as_vec3() },
            // not among the kinds asked for above; the capsule on the same segment contains it
            FittedShape::Cylinder { radius, half_length } => ColliderShape::Capsule { radius: radius as f32, half_length: half_length as f32 },
        };
        self.mesh_fits.borrow_mut().push(MeshFitReport {
            link: link.to_string(),
            mesh: path.clone(),
            shape,
            hull_volume: fit.hull_volume as f32,
            volume_ratio: fit.volume_ratio() as f32,
            aligned_volume_ratio: aligned.volume_ratio() as f32,
            max_gap: fit.max_gap as f32,
        });
        Ok((pose.mul(&DPose { pos: fit.centre, rot: fit.rot }), shape))
    }

    fn fingertips(&self, robot: &urdf_rs::Robot, model: &HandModel) -> R<(Vec<Fingertip>, Vec<String>)> {
        let f = &self.file;
        let detect = self.opts.fingertips.is_empty();
        let mut tips: Vec<Fingertip> = Vec::new();
        if detect {
            let mut found = Vec::new();
            for l in robot.links.iter().filter(|l| l.name.to_ascii_lowercase().contains("tip")) {
                let (link, pose) = model.frame(&l.name).expect("every URDF link resolves to a frame");
                found.push(Fingertip { name: l.name.clone(), link, pos: pose.pos });
            }
            // several on one finger chain (`tip` and `tip_head` frames of one finger): the most
            // distal one, i.e. none lies on a link below it, or farther from the origin of the same
            // link (the joint); among equally far ones on one link, the first in URDF order
            const SAME: f32 = 1e-9;
            let distal = |i: usize| {
                let a = &found[i];
                !found.iter().enumerate().any(|(k, b)| {
                    if b.link != a.link {
                        model.is_ancestor_or_same(a.link, b.link)
                    } else {
                        let (da, db) = (a.pos.length(), b.pos.length());
                        db > da + SAME || (k < i && (db - da).abs() <= SAME)
                    }
                })
            };
            tips = (0..found.len()).filter(|&i| distal(i)).map(|i| found[i].clone()).collect();
        } else {
            for (i, spec) in self.opts.fingertips.iter().enumerate() {
                let name = spec.name();
                if self.opts.fingertips[..i].iter().any(|o| o.name() == name) {
                    return Err(format!(
                        "fingertip '{name}' in {f} is named twice (hand.fingertips[{i}]); expected distinct fingertip names (two tips on one link need distinct `name`s)"
                    ));
                }
                let tip = match spec {
                    FingertipSpec::Frame(frame) => {
                        let Some((link, pose)) = model.frame(frame) else {
                            return Err(format!(
                                "fingertip '{frame}' does not exist in {f}; expected the name of a link (frame) of the hand"
                            ));
                        };
                        Fingertip { name: name.to_string(), link, pos: pose.pos }
                    }
                    FingertipSpec::Link(t) => {
                        let Some((link, pose)) = model.frame(&t.link) else {
                            return Err(format!(
                                "fingertip '{name}' (hand.fingertips[{i}]) is on link '{}', which does not exist in {f}; expected the name of a link (frame) of the hand",
                                t.link
                            ));
                        };
                        let offset = Vec3::from_array(t.offset);
                        if !offset.is_finite() || offset.abs().max_element() as f64 > MAX_LENGTH_M {
                            return Err(format!(
                                "fingertip '{name}' (hand.fingertips[{i}]) in {f} has offset {offset}; expected a finite offset within ±{MAX_LENGTH_M} m in the frame of link '{}'",
                                t.link
                            ));
                        }
                        // the frame's pose in its rigid link ∘ the offset in the frame
                        Fingertip { name: name.to_string(), link, pos: pose.transform_point(offset) }
                    }
                };
                tips.push(tip);
            }
        }
        let names = |v: &mut dyn Iterator<Item = &str>| v.map(|n| format!("'{n}'")).collect::<Vec<_>>().join(", ");
        let tip_names = names(&mut tips.iter().map(|t| t.name.as_str()));
        if tips.len() > MAX_TIPS {
            return Err(format!(
                "{f} has {} fingertip frames ({tip_names}); expected at most {MAX_TIPS} (MAX_TIPS); name fewer in hand.fingertips",
                tips.len(),
            ));
        }
        let chains = model.finger_chains();
        let mut warnings = Vec::new();
        if tips.is_empty() || tips.len() != chains.len() {
            let found = if detect {
                if tips.is_empty() {
                    "no link name contains \"tip\", so no fingertips were found".to_string()
                } else {
                    format!("{} fingertips were found by name (links containing \"tip\": {tip_names})", tips.len())
                }
            } else {
                format!("hand.fingertips names {} fingertips ({tip_names})", tips.len())
            };
            let has = match chains.len() {
                0 => "no finger chains (no movable joints)".to_string(),
                n => format!("{n} finger chains (ending at links {})", names(&mut chains.iter().map(|&l| model.links[l].name.as_str()))),
            };
            warnings.push(format!(
                "{f}: {found}, but the hand has {has}; name one fingertip per finger with hand.fingertips = [\"<frame>\", ...] or {{ link = \"<link>\", offset = [x, y, z] }} entries (offset in m, in the link's frame)"
            ));
        }
        Ok((tips, warnings))
    }
}

use crate::mesh::fit::{FittedShape, PrimitiveKind, axis_aligned_with_hull, fit_tightest_with_hull};
use crate::mesh::hull::convex_hull;
use crate::mesh::read::{parse_obj, parse_stl};

// ---------------------------------------------------------------------------------------------
// The pre-scan: a light, non-recursive reading of the XML's elements and attributes, run before
// urdf-rs (which recurses per nesting level) so that the nesting is bounded and a malformed
// attribute is reported with its element. It stops quietly at anything it does not understand
// (urdf-rs then reports the malformed XML); only the nesting depth is an error here.

/// One element of the pre-scanned XML.
struct XmlElem {
    /// Tag name.
    name: String,
    /// Attributes in document order, values with the five predefined entities decoded.
    attrs: Vec<(String, String)>,
    /// Index of the parent element (None for the root).
    parent: Option<usize>,
    /// Line (from 1) of the element's `<`.
    line: usize,
    /// Whether the element holds non-whitespace text.
    has_text: bool,
}

impl XmlElem {
    fn attr(&self, name: &str) -> Option<&str> {
        self.attrs.iter().find(|(k, _)| k == name).map(|(_, v)| v.as_str())
    }
}

/// Decodes `&lt; &gt; &amp; &quot; &apos;` (other references are kept as written).
fn decode_entities(v: &str) -> String {
    if !v.contains('&') {
        return v.to_string();
    }
    v.replace("&lt;", "<").replace("&gt;", ">").replace("&quot;", "\"").replace("&apos;", "'").replace("&amp;", "&")
}

/// How the pre-scan ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum ScanEnd {
    /// Every element was read and closed.
    Complete,
    /// The text ends inside this element (a truncated file).
    EndsInside(usize),
    /// The scan met something it does not read (malformed XML, a mismatched end tag): urdf-rs reports it.
    Stopped,
}

/// The elements of `text` in document order and how the scan ended. Errors (one line) when
/// elements nest deeper than [`MAX_URDF_DEPTH`].
fn scan_xml(text: &str) -> std::result::Result<(Vec<XmlElem>, ScanEnd), String> {
    let b = text.as_bytes();
    let lines_in = |from: usize, to: usize| b[from..to.min(b.len())].iter().filter(|&&c| c == b'\n').count();
    let find = |from: usize, pat: &str| text.get(from..).and_then(|r| r.find(pat)).map(|k| from + k);
    let mut elems: Vec<XmlElem> = Vec::new();
    let mut open: Vec<usize> = Vec::new(); // indices of the elements not yet closed
    let mut i = 0;
    let mut line = 1;
    while i < b.len() {
        // text up to the next '<'
        let next = find(i, "<").unwrap_or(b.len());
        if let Some(&top) = open.last()
            && !text[i..next].trim().is_empty()
        {
            elems[top].has_text = true;
        }
        line += lines_in(i, next);
        i = next;
        if i >= b.len() {
            break;
        }
        let rest = &text[i..];
        // comments, CDATA, processing instructions, DOCTYPE: skipped
        let skip_to = |end: &str, start_len: usize| find(i + start_len, end).map(|k| k + end.len());
        let skipped = if rest.starts_with("<!--") {
            Some(skip_to("-->", 4))
        } else if rest.starts_with("<![CDATA[") {
            if let Some(&top) = open.last() {
                elems[top].has_text = true;
            }
            Some(skip_to("]]>", 9))
        } else if rest.starts_with("<?") {
            Some(skip_to("?>", 2))
        } else if rest.starts_with("<!") {
            // DOCTYPE, possibly with an internal subset in [ ]
            let mut depth = 0i32;
            let mut end = None;
            for (k, &c) in b[i..].iter().enumerate() {
                match c {
                    b'[' => depth += 1,
                    b']' => depth -= 1,
                    b'>' if depth <= 0 => {
                        end = Some(i + k + 1);
                        break;
                    }
                    _ => {}
                }
            }
            Some(end)
        } else {
            None
        };
        if let Some(end) = skipped {
            let Some(end) = end else { return Ok((elems, ScanEnd::Stopped)) };
            line += lines_in(i, end);
            i = end;
            continue;
        }
        if rest.starts_with("</") {
            let Some(end) = find(i, ">") else { return Ok((elems, ScanEnd::Stopped)) };
            let closing = text[i + 2..end].trim();
            match open.last() {
                Some(&top) if elems[top].name == closing => {}
                _ => return Ok((elems, ScanEnd::Stopped)),
            }
            line += lines_in(i, end);
            open.pop();
            i = end + 1;
            continue;
        }
        // a start tag: <name attr="v" ...> or .../>
        let tag_line = line;
        let mut k = i + 1;
        let name_end = b[k..].iter().position(|c| c.is_ascii_whitespace() || *c == b'/' || *c == b'>').map_or(b.len(), |p| k + p);
        let name = &text[k..name_end];
        if name.is_empty() {
            return Ok((elems, ScanEnd::Stopped));
        }
        k = name_end;
        let mut attrs = Vec::new();
        let mut self_closing = false;
        let mut complete = false;
        while k < b.len() {
            match b[k] {
                c if c.is_ascii_whitespace() => {
                    if c == b'\n' {
                        line += 1;
                    }
                    k += 1;
                }
                b'>' => {
                    k += 1;
                    complete = true;
                    break;
                }
                b'/' if b.get(k + 1) == Some(&b'>') => {
                    k += 2;
                    self_closing = true;
                    complete = true;
                    break;
                }
                _ => {
                    let Some(eq) = find(k, "=") else { break };
                    let key = text[k..eq].trim();
                    if key.is_empty() || key.contains(['<', '>', '"', '\'']) {
                        break;
                    }
                    let mut v = eq + 1;
                    while v < b.len() && b[v].is_ascii_whitespace() {
                        v += 1;
                    }
                    let Some(&q) = b.get(v).filter(|&&q| q == b'"' || q == b'\'') else { break };
                    let Some(close) = find(v + 1, if q == b'"' { "\"" } else { "'" }) else { break };
                    line += lines_in(k, close);
                    attrs.push((key.to_string(), decode_entities(&text[v + 1..close])));
                    k = close + 1;
                }
            }
        }
        if !complete {
            return Ok((elems, ScanEnd::Stopped));
        }
        let depth = open.len() + 1;
        if depth > MAX_URDF_DEPTH {
            let path: Vec<&str> = open.iter().take(4).map(|&e| elems[e].name.as_str()).collect();
            return Err(format!(
                "line {tag_line}: element <{}> is nested {depth} levels deep (in <{}> …); expected at most {MAX_URDF_DEPTH} levels (a URDF nests 5: robot > link > collision > geometry > box)",
                clip(name, MAX_QUOTED_CHARS),
                path.join("> <")
            ));
        }
        elems.push(XmlElem { name: name.to_string(), attrs, parent: open.last().copied(), line: tag_line, has_text: false });
        if !self_closing {
            open.push(elems.len() - 1);
        }
        i = k;
    }
    let end = match open.last() {
        None => ScanEnd::Complete,
        Some(&e) => ScanEnd::EndsInside(e),
    };
    Ok((elems, end))
}

/// How urdf-rs reads an attribute.
#[derive(Clone, Copy)]
enum AttrKind {
    /// Any text.
    Text,
    /// One number (`f64`).
    Number,
    /// `n` numbers separated by spaces.
    Numbers(usize),
    /// A joint type.
    JointType,
}

const JOINT_TYPES: [&str; 7] = ["revolute", "continuous", "prismatic", "fixed", "floating", "planar", "spherical"];

/// What urdf-rs requires of an element under a given parent: `(attribute, kind, required)`,
/// the child elements it requires, and those it reads at most once.
struct ElemRule {
    attrs: &'static [(&'static str, AttrKind, bool)],
    required_children: &'static [&'static str],
    single_children: &'static [&'static str],
}

fn elem_rule(parent: &str, name: &str, v12: bool) -> Option<ElemRule> {
    use AttrKind::*;
    const NONE: &[&str] = &[];
    const NO_ATTRS: &[(&str, AttrKind, bool)] = &[];
    const ORIGIN: &[(&str, AttrKind, bool)] = &[("xyz", Numbers(3), false), ("rpy", Numbers(3), false)];
    fn rule(
        attrs: &'static [(&'static str, AttrKind, bool)],
        required_children: &'static [&'static str],
        single_children: &'static [&'static str],
    ) -> Option<ElemRule> {
        Some(ElemRule { attrs, required_children, single_children })
    }
    match (parent, name) {
        ("robot", "link") => rule(&[("name", Text, true)], NONE, &["inertial"]),
        ("robot", "joint") => rule(
            &[("name", Text, true), ("type", JointType, true)],
            &["parent", "child"],
            &["origin", "parent", "child", "axis", "limit", "calibration", "dynamics", "mimic", "safety_controller"],
        ),
        ("robot" | "visual", "material") => rule(&[("name", Text, true)], NONE, &["color", "texture"]),
        ("material", "color") => rule(&[("rgba", Numbers(4), true)], NONE, NONE),
        ("material", "texture") => rule(&[("filename", Text, true)], NONE, NONE),
        ("link", "inertial") => rule(NO_ATTRS, &["mass", "inertia"], &["origin", "mass", "inertia"]),
        ("link", "visual") => rule(NO_ATTRS, &["geometry"], &["origin", "geometry", "material"]),
        ("link", "collision") => rule(NO_ATTRS, &["geometry"], &["origin", "geometry"]),
        ("inertial", "mass") => rule(&[("value", Number, true)], NONE, NONE),
        ("inertial", "inertia") => rule(
            &[("ixx", Number, true), ("ixy", Number, true), ("ixz", Number, true), ("iyy", Number, true), ("iyz", Number, true), ("izz", Number, true)],
            NONE,
            NONE,
        ),
        ("inertial" | "visual" | "collision" | "joint", "origin") => rule(ORIGIN, NONE, NONE),
        ("visual" | "collision", "geometry") => rule(NO_ATTRS, NONE, NONE),
        ("geometry", "box") => rule(&[("size", Numbers(3), true)], NONE, NONE),
        ("geometry", "cylinder" | "capsule") => rule(&[("radius", Number, true), ("length", Number, true)], NONE, NONE),
        ("geometry", "sphere") => rule(&[("radius", Number, true)], NONE, NONE),
        ("geometry", "mesh") => rule(&[("filename", Text, true), ("scale", Numbers(3), false)], NONE, NONE),
        ("joint", "parent" | "child") => rule(&[("link", Text, true)], NONE, NONE),
        ("joint", "axis") => rule(&[("xyz", Numbers(3), true)], NONE, NONE),
        // URDF 1.2: urdf-rs fills in a missing velocity (infinite)
        ("joint", "limit") if v12 => rule(
            &[("lower", Number, false), ("upper", Number, false), ("effort", Number, false), ("velocity", Number, false)],
            NONE,
            NONE,
        ),
        ("joint", "limit") => rule(
            &[("lower", Number, false), ("upper", Number, false), ("effort", Number, false), ("velocity", Number, true)],
            NONE,
            NONE,
        ),
        ("joint", "mimic") => rule(&[("joint", Text, true), ("multiplier", Number, false), ("offset", Number, false)], NONE, NONE),
        ("joint", "dynamics") => rule(&[("damping", Number, false), ("friction", Number, false)], NONE, NONE),
        ("joint", "calibration") => rule(&[("rising", Number, false), ("falling", Number, false)], NONE, NONE),
        ("joint", "safety_controller") => rule(
            &[("soft_lower_limit", Number, false), ("soft_upper_limit", Number, false), ("k_position", Number, false), ("k_velocity", Number, true)],
            NONE,
            NONE,
        ),
        _ => None,
    }
}

/// "joint 'x'" / "link 'y'" / "material 'z'" for the nearest named link, joint or material
/// enclosing element `i` (itself included), else "<name>".
fn owner_of(elems: &[XmlElem], i: usize) -> String {
    let mut k = Some(i);
    while let Some(e) = k {
        let el = &elems[e];
        if matches!(el.name.as_str(), "link" | "joint" | "material")
            && let Some(n) = el.attr("name")
        {
            return format!("{} '{}'", el.name, clip(n, MAX_QUOTED_CHARS));
        }
        k = el.parent;
    }
    format!("<{}>", elems[i].name)
}

/// Checks the elements urdf-rs reads against what it requires: the first problem, as "line N:
/// <owner>: <what>; expected …", or None.
fn check_urdf_elements(elems: &[XmlElem]) -> Option<String> {
    let root = elems.first()?;
    if root.name != "robot" {
        return Some(format!("line {}: the root element is <{}>; expected <robot>", root.line, clip(&root.name, MAX_QUOTED_CHARS)));
    }
    let v12 = root
        .attr("version")
        .and_then(|v| v.trim().split_once('.'))
        .and_then(|(a, b)| Some((a.parse::<u32>().ok()?, b.parse::<u32>().ok()?)))
        .is_some_and(|v| v >= (1, 2));
    let mut children: Vec<Vec<usize>> = vec![Vec::new(); elems.len()];
    for (i, e) in elems.iter().enumerate() {
        if let Some(p) = e.parent {
            children[p].push(i);
        }
    }
    for (i, e) in elems.iter().enumerate() {
        let Some(p) = e.parent else { continue };
        let parent = elems[p].name.as_str();
        let Some(rule) = elem_rule(parent, &e.name, v12) else {
            if parent == "geometry" && matches!(elems[p].parent.map(|g| elems[g].name.as_str()), Some("visual" | "collision")) {
                return Some(format!(
                    "line {}: {}: unknown geometry <{}>; expected <box>, <cylinder>, <capsule>, <sphere> or <mesh>",
                    e.line,
                    owner_of(elems, i),
                    clip(&e.name, MAX_QUOTED_CHARS)
                ));
            }
            continue;
        };
        let at = |what: String, expected: String| Some(format!("line {}: {}: <{}> {what}; expected {expected}", e.line, owner_of(elems, i), e.name));
        for &(attr, kind, required) in rule.attrs {
            let Some(v) = e.attr(attr) else {
                if required {
                    return at(format!("has no attribute `{attr}`"), format!("{} `{attr}`", kind_words(kind)));
                }
                continue;
            };
            let quoted = format!("{:?}", clip(v, MAX_QUOTED_CHARS));
            let ok = match kind {
                AttrKind::Text => true,
                AttrKind::Number => v.trim().parse::<f64>().is_ok(),
                AttrKind::Numbers(n) => {
                    let parts: Vec<&str> = v.split_whitespace().collect();
                    parts.len() == n && parts.iter().all(|x| x.parse::<f64>().is_ok())
                }
                AttrKind::JointType => JOINT_TYPES.contains(&v),
            };
            if !ok {
                let expected = match kind {
                    AttrKind::JointType => format!("`type` to be one of {}", JOINT_TYPES.join(", ")),
                    _ => format!("{} `{attr}`", kind_words(kind)),
                };
                return at(format!("has `{attr}` = {quoted}"), expected);
            }
        }
        let kids = &children[i];
        for &req in rule.required_children {
            if !kids.iter().any(|&c| elems[c].name == req) {
                return at(format!("has no <{req}>"), format!("a <{req}> inside <{}>", e.name));
            }
        }
        for &single in rule.single_children {
            let n = kids.iter().filter(|&&c| elems[c].name == single).count();
            if n > 1 {
                return at(format!("has {n} <{single}> elements"), format!("at most one <{single}> inside <{}>", e.name));
            }
        }
        if e.name == "geometry" {
            let n = kids.len();
            if n != 1 {
                return at(format!("holds {n} shapes"), "exactly one of <box>, <cylinder>, <capsule>, <sphere>, <mesh>".into());
            }
        }
        if e.has_text {
            return at("holds text".into(), format!("only attributes and child elements in <{}>", e.name));
        }
    }
    None
}

/// What an attribute of a kind should hold, in words.
fn kind_words(kind: AttrKind) -> String {
    match kind {
        AttrKind::Text => "a value for".into(),
        AttrKind::Number => "one number in".into(),
        AttrKind::Numbers(n) => format!("{n} numbers separated by spaces in"),
        AttrKind::JointType => "a joint type in".into(),
    }
}
