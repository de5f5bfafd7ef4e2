//! `#[repr(C)]` bytemuck Pod structs shared by the CPU backend and the GPU storage buffers.
//!
//! Every struct here is the twin of a WGSL struct in `shaders/common.wgsl` with the same name and
//! the same fields in the same order: keep them in sync (tests/suite/shaders.rs compares sizes and offsets
//! with naga's layouter). Only `f32`, `u32` and `[f32; 4]` (WGSL `vec4<f32>`) are used, vec4 fields
//! come first so that they sit on 16-byte boundaries, and every struct's size is a multiple of 16.

use bytemuck::{Pod, Zeroable};

use crate::hand::{MAX_JOINTS, MAX_TIPS};

/// Object shape codes and the object model's limits (keep in sync with shaders/common.wgsl).
pub use crate::geom::{SHAPE_BOX, SHAPE_CAPSULE, SHAPE_CYLINDER, SHAPE_HULL, SHAPE_SPHERE};
pub use crate::object::{MAX_HULL_VERTICES, MAX_PIECES};

/// One collision piece of an object (WGSL `PieceDesc`): a primitive at a pose in the object's
/// frame. Lengths are unscaled (an env's object scale multiplies them).
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable, PartialEq)]
pub struct PieceDesc {
    /// Centre in the object frame (xyz); w = radius about the centre that bounds the piece.
    pub pos: [f32; 4],
    /// Orientation in the object frame (quaternion xyzw).
    pub rot: [f32; 4],
    /// Sphere (r, 0, 0), box (hx, hy, hz), capsule and cylinder (r, half_length, 0).
    pub size: [f32; 4],
    /// `SHAPE_*` code.
    pub shape: u32,
    /// Support points of the piece against the table (`object_num_support`; a hull's vertices).
    pub n_support: u32,
    /// A hull piece: its data's first entry in the `hulls` buffer (F planes, F triangles, then its
    /// `n_support` vertices) and its number of faces F; 0 otherwise.
    pub hull_first: u32,
    pub hull_faces: u32,
}

/// One object of the run (WGSL `ObjectDesc`): its pieces and mass properties, unscaled.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable, PartialEq)]
pub struct ObjectDesc {
    /// Centre of mass in the object frame (xyz); w = radius about the frame's origin that bounds
    /// every piece.
    pub com: [f32; 4],
    /// Principal axes of inertia in the object frame (quaternion xyzw).
    pub principal_rot: [f32; 4],
    /// Principal moments of inertia per unit mass (m², xyz, about the centre of mass); w = the
    /// nominal mass (kg).
    pub inertia: [f32; 4],
    /// The object's pieces: `pieces[first_piece .. first_piece + n_pieces]`.
    pub first_piece: u32,
    pub n_pieces: u32,
    /// Support points of all its pieces against the table (≤ `Globals::n_obj_pts`).
    pub n_support: u32,
    /// Height of the object frame's origin above the table when the object rests in the mesh's
    /// orientation (m).
    pub rest_height: f32,
}

/// Marks "no object" in `SimModel::ref_objects` (a reference that names none).
pub const NO_OBJECT: u32 = u32::MAX;
/// Marks "no joint" in `JointDesc::mimic_leader`.
pub const NO_JOINT: u32 = u32::MAX;

/// Run-wide constants (WGSL `Globals`, one per run, read-only).
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable, PartialEq)]
pub struct Globals {
    /// Initial wrist position (xyz) and orientation (quaternion xyzw).
    pub init_wrist_pos: [f32; 4],
    pub init_wrist_rot: [f32; 4],
    /// Nominal object placement: x, y, yaw, and the first object's unscaled rest height (z of its
    /// frame's origin; resets use each object's `ObjectDesc::rest_height`).
    pub obj_init: [f32; 4],
    /// Randomisation ranges [lo, hi] as pairs: (hand_mass, hand_friction), (joint_limits, joint_stiffness),
    /// (joint_damping, object_mass), (object_friction, object_scale), (restitution, table_friction),
    /// (added_gravity, xy noise x / y packed as (nx, ny)).
    pub rnd: [[f32; 4]; 6],
    pub n_envs: u32,
    pub n_joints: u32,
    pub n_colliders: u32,
    pub n_tips: u32,
    pub n_links: u32,
    /// Objects of the run (`ObjectDesc`s); each env draws one at every reset.
    pub n_objects: u32,
    /// Support points against the table of the object with the most (the springs reserved per env).
    pub n_obj_pts: u32,
    pub substeps: u32,
    pub decimation: u32,
    pub seed: u32,
    pub hand_table: u32,
    /// Contact springs per env in the springs buffer: `2 · n_colliders + n_obj_pts` (see
    /// [`spring_slot`]).
    pub n_springs: u32,
    /// Physics step (s).
    pub dt: f32,
    /// Gravity magnitude (m/s², acting along −z).
    pub gravity: f32,
    pub contact_k: f32,
    pub contact_kt: f32,
    pub hand_eff_mass: f32,
    pub hand_friction: f32,
    /// References that the object draw follows (`SimModel::ref_objects`; 0: objects are drawn
    /// uniformly).
    pub n_ref_objects: u32,
    pub obj_friction: f32,
    pub table_friction: f32,
    pub yaw_noise: f32,
    /// Hand mass (kg, links only, unscaled) and the wrist's rotational inertia from the links (kg·m²).
    pub hand_mass: f32,
    pub hand_inertia: f32,
    pub wrist_added_mass: f32,
    pub wrist_added_inertia: f32,
    pub wrist_kp_lin: f32,
    pub wrist_kd_lin: f32,
    pub wrist_force_limit: f32,
    pub wrist_kp_rot: f32,
    pub wrist_kd_rot: f32,
    pub wrist_torque_limit: f32,
    pub max_speed: f32,
    pub max_distance: f32,
    /// Radius (m) of the contact patch that gives torsional friction (μ·Fn·r).
    pub torsion_radius: f32,
    /// Normal and tangential-spring stiffness (N/m) of the hand's contacts (`contact_k`,
    /// `contact_kt`: the object's against the table).
    pub hand_contact_k: f32,
    pub hand_contact_kt: f32,
    /// Global id of env 0 of this batch: every draw of the counter hash keys an env by its global
    /// id (`env + env_offset`), so that rank r of a data-parallel job (`crate::dist`), simulating
    /// envs `[r·E, (r+1)·E)`, draws what one process with every env draws for them; 0 otherwise.
    pub env_offset: u32,
    pub _pad2: [f32; 2],
}

/// One movable joint of the hand (WGSL `JointDesc`), in topological order.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable, PartialEq)]
pub struct JointDesc {
    /// Joint frame in the parent link's frame: position (xyz) and rotation (quaternion xyzw).
    pub origin_pos: [f32; 4],
    pub origin_rot: [f32; 4],
    /// Unit axis in the joint frame.
    pub axis: [f32; 4],
    pub parent_link: u32,
    /// Leader joint of a mimic follower, `NO_JOINT` otherwise.
    pub mimic_leader: u32,
    pub mimic_mult: f32,
    pub mimic_offset: f32,
    pub lower: f32,
    pub upper: f32,
    pub effort: f32,
    pub velocity: f32,
    pub damping: f32,
    pub friction: f32,
    /// Armature (kg·m²) and the links' inertia about the axis at q = 0 (kg·m², scaled by hand mass),
    /// both including mimic followers' shares (multiplier²).
    pub armature: f32,
    pub link_inertia: f32,
    pub kp: f32,
    pub kd: f32,
    pub default_q: f32,
    pub _pad: f32,
}

/// One hand collision shape (WGSL `ColliderDesc`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable, PartialEq)]
pub struct ColliderDesc {
    /// Pose in its link's frame.
    pub pos: [f32; 4],
    pub rot: [f32; 4],
    /// Sphere (r, 0, 0), capsule (r, half_length, 0), box (hx, hy, hz).
    pub size: [f32; 4],
    pub link: u32,
    /// 0 sphere, 1 box, 2 capsule (the object shape codes).
    pub shape: u32,
    /// Fingertip index this collider belongs to (its link carries that tip), or `NO_JOINT`.
    pub tip: u32,
    pub _pad: u32,
}

/// One fingertip frame (WGSL `TipDesc`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable, PartialEq)]
pub struct TipDesc {
    /// Position in the link frame.
    pub pos: [f32; 4],
    pub link: u32,
    pub _pad: [u32; 3],
}

/// The dynamic state of one env (WGSL `EnvState`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable, PartialEq)]
pub struct EnvState {
    /// Wrist (root link) position, orientation (xyzw), linear and angular velocity (world).
    pub wrist_pos: [f32; 4],
    pub wrist_rot: [f32; 4],
    pub wrist_vel: [f32; 4],
    pub wrist_angvel: [f32; 4],
    /// Object centre position, orientation, linear and angular velocity (world).
    pub obj_pos: [f32; 4],
    pub obj_rot: [f32; 4],
    pub obj_vel: [f32; 4],
    pub obj_angvel: [f32; 4],
    /// Joint positions (rad) and velocities (rad/s), followers included.
    pub q: [f32; MAX_JOINTS],
    pub qd: [f32; MAX_JOINTS],
    /// Simulated time since the reset (s).
    pub time: f32,
    /// Episodes started by this env (0 for the first).
    pub episode: u32,
    /// Env steps since the reset.
    pub step: u32,
    /// Resets caused by non-finite or exploding state since the batch was made.
    pub bad_resets: u32,
}

/// The contact springs of the envs live outside [`EnvState`], in one buffer `[N, n_springs]` of
/// `[f32; 4]` (WGSL `springs: array<vec4<f32>>`), so that an env's memory grows with its hand's
/// colliders instead of with a compile-time maximum. Each entry is the tangential spring of one
/// contact pair (xyz, world) and w = 1 while the pair is in contact. Slots of env `e`, relative to
/// `e · n_springs`: hand collider `c` against the object at `c`, against the table at
/// `n_colliders + c`, object support point `k` against the table at `2 · n_colliders + k`.
pub mod spring_slot {
    /// Slot of hand collider `c`'s contact with the object.
    pub const fn hand_object(c: u32) -> u32 {
        c
    }
    /// Slot of hand collider `c`'s contact with the table.
    pub const fn hand_table(n_colliders: u32, c: u32) -> u32 {
        n_colliders + c
    }
    /// Slot of object support point `k`'s contact with the table.
    pub const fn object_table(n_colliders: u32, k: u32) -> u32 {
        2 * n_colliders + k
    }
    /// Springs per env.
    pub const fn per_env(n_colliders: u32, n_obj_pts: u32) -> u32 {
        2 * n_colliders + n_obj_pts
    }
}

/// Per-env physical parameters drawn at reset (WGSL `EnvParams`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable, PartialEq)]
pub struct EnvParams {
    /// The object's centre of mass in its frame (xyz, scaled) and the radius about the frame's
    /// origin that bounds its pieces (w, scaled).
    pub obj_com: [f32; 4],
    /// Object principal moments of inertia (xyz, about the centre of mass along
    /// `ObjectDesc::principal_rot`) and mass (w).
    pub obj_inertia: [f32; 4],
    pub obj_friction: f32,
    pub restitution: f32,
    pub obj_scale: f32,
    pub table_friction: f32,
    pub hand_friction: f32,
    pub hand_mass_scale: f32,
    pub limit_scale: f32,
    pub kp_scale: f32,
    pub kd_scale: f32,
    pub added_gravity: f32,
    /// Normal damping of hand–object and object–table contacts (N·s/m), from the restitution.
    pub obj_contact_c: f32,
    /// Normal damping of hand–table contacts (N·s/m).
    pub hand_table_c: f32,
    /// The object this env holds (index into the `objects` buffer).
    pub obj_index: u32,
    /// Height of the object frame's origin when it rests on the table (m, scaled).
    pub obj_rest_height: f32,
    pub _pad: [u32; 2],
    /// An external force on the object (N, world frame; xyz, w unused), acting at `ext_point` in
    /// every substep: what a benchmark or test pushes an object with (`dextrain bench --contacts`).
    /// 0 after every reset; training never sets it.
    pub ext_force: [f32; 4],
    /// Where `ext_force` acts: a point in the object's frame, relative to its origin (m; xyz, w unused).
    pub ext_point: [f32; 4],
}

/// Per-env joint and wrist targets for one env step (WGSL `Targets`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable, PartialEq)]
pub struct Targets {
    pub wrist_pos: [f32; 4],
    pub wrist_rot: [f32; 4],
    /// Joint position targets (rad); followers' entries are ignored.
    pub q: [f32; MAX_JOINTS],
}

/// What happened in one env during the last env step (WGSL `StepStats`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable, PartialEq)]
pub struct StepStats {
    /// Normal force (N) of each fingertip's hand–object contacts, averaged over the env step's substeps.
    pub tip_force: [f32; MAX_TIPS],
    /// Deepest hand–object penetration (m) over the env step.
    pub max_pen_ho: f32,
    /// Deepest penetration of any contact (m) over the env step.
    pub max_pen: f32,
    /// Contacts summed over the env step's substeps (all pairs / hand–object only).
    pub contacts: u32,
    pub contacts_ho: u32,
    /// 1 if the env was reset during this step because its state was non-finite or exploded.
    pub bad_reset: u32,
    /// Bit l % 32 of word l / 32 set: a collision shape of hand link l pushed on the object
    /// (normal force > 0) in at least one physics substep of the env step.
    pub link_contact: [u32; 2],
    /// 1 if a hand collider touches the table at the end of the env step.
    pub table_contact: u32,
    pub _pad: [u32; 3],
}

impl Default for EnvState {
    fn default() -> Self {
        Zeroable::zeroed()
    }
}

impl Default for Targets {
    fn default() -> Self {
        Zeroable::zeroed()
    }
}
