//! CPU twin of `shaders/physics.wgsl`: one env step of one env (decimation × substeps).
//! Same function names, same order, same arithmetic as the shader; `Scratch` is the shader's
//! `var<private>` memory.
//!
//! The model (docs/design.md §4), per substep of length h:
//! 1. `hand_kinematics`: link poses and velocities from the wrist state and joint positions.
//! 2. Contacts (penalty): hand–object (one per hand collider: the deepest over the object's pieces,
//!    closest points by alternating projection between the collider and a piece — a primitive, or a
//!    convex hull whose closest point is found on the triangles the point is in front of; a hand
//!    box also tests the piece's support points inside it, `box_piece_contact`, and a hand box
//!    overlapping a box piece least along its own face is met on that face's clipped points,
//!    `box_box_contact`, and
//!    a capsule along a box piece's face at both ends of its part over the face,
//!    `capsule_face_contact`: one contact standing for the point springs, `Manifold`),
//!    hand–table (lowest point of each collider), object–table (every piece's support points).
//!    Object–table: normal force `Fn = max(k·depth − c·vn, 0)`; friction from a tangential spring
//!    anchored per contact pair, `Ft = −kt·s − ct·vt`, sliding (s rescaled) when `|Ft| > μ·Fn`, so a
//!    held object does not creep. Hand contacts: the same spring–damper and spring, solved as in 3.
//! 3. Hand contacts are solved one after another against the hand's velocity change this substep
//!    (the servos' first, `hand_servo`, then each solved contact's, `apply_hand_force`: one
//!    Gauss–Seidel sweep), implicitly on the hand's side (`hand_contact_force`): the force is the
//!    spring–damper's at the end of the substep, when the contact point moves with that change plus
//!    the contact's own push through the hand's mobility along the normal (`hand_mobility`),
//!    `Fn = (k·d − (k·h + c)·vn) / (1 + h·w_n·(k·h + c))`. Stable at any stiffness on the lightest
//!    fingers (as MuJoCo's implicit constraint forces are), exactly `Fn = k·d` at rest, and a gap
//!    closing within the substep pushes already (speculative contacts within `speculative_margin`), so
//!    a fast finger stops at the surface. The object takes the opposite force, with its derivative
//!    in the object's velocity in its implicit solve. The hand–object pairs within the margin that
//!    did not push are solved a second time after all the others, against the object's velocity at
//!    the end of the substep as those make it (`object_velocity_change`): a push that throws a
//!    light object into another link within the substep is met there already. Once the object's
//!    velocity change is solved, each pushing pair's link takes the part of the force that the
//!    object's motion took off or added in its solve (`react_to_object_motion`), so that hand and
//!    object feel equal and opposite forces and stiff contacts hold a light object still. A pair
//!    whose contact where collider and object will be at the end of the substep is deeper than
//!    its contact now predicts is solved at that one (`swept_contact`): a turning object brings
//!    an edge into a finger away from the pair's one contact point within a substep. Once the
//!    object's velocity change is solved, each pushing pair is looked at once more under it
//!    (`arriving_contacts`): a feature that the solved motion — a spin the pushes themselves
//!    gave the object — brings into the pair by the end of the substep joins as a contact of its
//!    own, and the object's velocity change is solved again with it.
//! 4. Hand: finger joints are independent 1-DoF servos (PD with effort limit, damping, Coulomb friction,
//!    armature + link inertia about the axis at q = 0), integrated semi-implicitly; mimic followers
//!    follow their leader; the wrist is a free body pulled by a force/torque-limited PD toward its
//!    target (the hand's weight is compensated, as by an arm controller).
//! 5. Object: a free rigid body under gravity, contact forces and an external force at a point of it
//!    (`EnvParams::ext_force`, 0 but in benchmarks and tests), integrated linearly implicitly in
//!    its 6 velocities (M + h·Σ Jᵀ D J) Δu = h·f, so that stiff contacts stay stable for light objects.
//!    Its state is the pose of its own (mesh) frame and the velocity of its centre of mass; the
//!    centre of mass and the principal axes of inertia sit in that frame (`ObjectDesc`).

use glam::{Mat3, Vec3, Vec4};

use super::common::*;
use crate::gpu::layout::*;
use super::reset::{clear_springs, reset_params, reset_state};
use crate::hand::{MAX_JOINTS, MAX_TIPS};
use crate::record::ContactKind;

/// Most links: the root plus one per movable joint.
pub const MAX_LINKS: usize = MAX_JOINTS + 1;
/// Alternating-projection iterations of the hand–object closest-point search.
pub const PROJ_ITERS: usize = 4;
/// The same for a hand box (a palm: one or two per hand), whose projections onto a piece lying
/// flat against it converge slowly.
pub const BOX_PROJ_ITERS: usize = 16;
/// How far apart (m) a hand collider and the object or table may be for their contact to be solved:
/// a gap that closes within the substep pushes already (`hand_contact_force`). A finger at its
/// speed limit travels ~1.3 mm in a 2 ms substep; against the object the margin grows with the
/// pair's speed (`speculative_margin`).
pub const CONTACT_MARGIN: f32 = 0.003;
/// The weight (m) of the piece's nearest point y where a hand box's contact point moves toward the
/// piece's support points deeper than y, each weighted by how much deeper (`box_piece_contact`).
pub const DEEP_BLEND: f32 = 1.0e-4;
/// Words of the mask of hand–object pairs that `contacts_and_forces` solves a second time (one bit
/// per collider).
pub const REVISIT_WORDS: usize = crate::hand::MAX_COLLIDERS / 32;
/// Spin rate (rad/s) below which torsional friction acts as a damper instead of a constant torque.
pub const TORSION_EPS: f32 = 0.05;
/// How much deeper (m) a hand–object pair's contact at the end of the substep must be than its
/// contact now predicts before it takes the pair's place (`swept_contact`): below it the two are
/// the same feature, a smooth turn's curvature apart (0 let contact points flicker between
/// them: a learned lift peaked higher, BENCHMARKS.md).
pub const SWEPT_TOLERANCE: f32 = 3.0e-4;
/// The most hand–object pairs per substep whose force on the hand follows the object's motion in
/// its implicit solve (`react_to_object_motion`; the scripted YCB grasps push with at most 6): a
/// pair past this many keeps the force it was solved with (the shader holds them in private
/// memory).
pub const MAX_REACTIONS: usize = 16;
/// The CPU's second pass reuses the first pass's contacts of this many pairs (the rest are found
/// again, to the same bits; the shader keeps all of them in its narrow-phase rounds' slots,
/// shaders/narrow_rounds.wgsl). CPU only.
pub const REVISIT_CACHE: usize = 16;

/// Read-only description of the run shared by all envs (the shader's bindings 0–3, 18–21).
#[derive(Clone, Copy)]
pub struct Model<'a> {
    pub g: &'a Globals,
    pub joints: &'a [JointDesc],
    pub colliders: &'a [ColliderDesc],
    pub tips: &'a [TipDesc],
    /// The objects' collision pieces (binding 18), the objects (binding 19) and the convex hulls'
    /// planes, triangles and vertices (binding 20, see `hull_vertex`).
    pub pieces: &'a [PieceDesc],
    pub objects: &'a [ObjectDesc],
    pub hulls: &'a [[f32; 4]],
    /// The object of each reference (binding 21, `SimModel::ref_objects`).
    pub ref_objects: &'a [u32],
}

/// Per-invocation working memory (the shader's `var<private>` variables).
#[derive(Clone)]
pub struct Scratch {
    pub link_pos: [Vec3; MAX_LINKS],
    pub link_rot: [Vec4; MAX_LINKS],
    pub link_v: [Vec3; MAX_LINKS],
    pub link_w: [Vec3; MAX_LINKS],
    /// World axis of each joint (its origin is `link_pos[j + 1]`).
    pub joint_axis: [Vec3; MAX_JOINTS],
    /// The change this substep of each independent joint's velocity (a follower's entry is unused:
    /// it moves with its leader), and of the wrist's linear and angular velocity: the servos' part
    /// first (`hand_servo`), then each hand contact's as it is solved (`apply_hand_force`).
    pub dqd: [f32; MAX_JOINTS],
    pub wrist_dv: Vec3,
    pub wrist_dw: Vec3,
    /// Contact force and torque (about the centre) on the object, and the 6×6 implicit damping
    /// Σ Jᵀ D J (row-major).
    pub obj_f: Vec3,
    pub obj_t: Vec3,
    pub obj_d: [f32; 36],
    /// Statistics accumulated over the env step.
    pub tip_force: [f32; MAX_TIPS],
    pub max_pen_ho: f32,
    pub max_pen: f32,
    pub contacts: u32,
    pub contacts_ho: u32,
    /// Bit l % 32 of word l / 32: a collider of link l pushed on the object (Fn > 0) in a substep.
    pub link_contact: [u32; 2],
    /// The hand–object pairs that pushed this substep, in the order solved (the first
    /// `n_reactions`, at most `MAX_REACTIONS`): what `react_to_object_motion` needs of each.
    pub reactions: [Reaction; MAX_REACTIONS],
    pub n_reactions: u32,
}

/// A hand–object pair that pushed this substep, as the object's implicit solve sees it: at the
/// object's velocity change Δu the object takes −(F + D·(J·Δu − δv₀)), F the force on the hand as
/// solved, D = a·nnᵀ + b·(I − nnᵀ) and J·Δu the contact point's change (the shader's `react_*`
/// arrays).
#[derive(Clone, Copy, Default)]
pub struct Reaction {
    /// The hand link the collider is on.
    pub link: u32,
    /// Contact point (world) and unit normal (from the object to the hand).
    pub point: Vec3,
    pub normal: Vec3,
    /// The normal and tangential damping of D, and the torsion's b_r (its torque: −b_r·n·(n·Δω − δω₀)).
    pub a: f32,
    pub b: f32,
    pub br: f32,
    /// The contact point's velocity change δv₀ and the object's δω₀ the force was linearised
    /// about (the second pass's prediction; zero in the first).
    pub dv0: Vec3,
    pub dw0: Vec3,
    /// The contact's manifold (`Contact::spring_count`, `spread_diag`, `spread_off`): its points'
    /// resistance to the object's turning, E (`spread_matrix`), goes back to the hand as well.
    pub spring_count: f32,
    pub spread_diag: Vec3,
    pub spread_off: Vec3,
    /// The hand collider of the pair and the depth of the contact it was solved with
    /// (`arriving_contacts` looks again at the pair under the object's solved velocities).
    pub collider: u32,
    pub depth: f32,
}

impl Default for Scratch {
    fn default() -> Self {
        Scratch {
            link_pos: [Vec3::ZERO; MAX_LINKS],
            link_rot: [Vec4::W; MAX_LINKS],
            link_v: [Vec3::ZERO; MAX_LINKS],
            link_w: [Vec3::ZERO; MAX_LINKS],
            joint_axis: [Vec3::ZERO; MAX_JOINTS],
            dqd: [0.0; MAX_JOINTS],
            wrist_dv: Vec3::ZERO,
            wrist_dw: Vec3::ZERO,
            obj_f: Vec3::ZERO,
            obj_t: Vec3::ZERO,
            obj_d: [0.0; 36],
            tip_force: [0.0; MAX_TIPS],
            max_pen_ho: 0.0,
            max_pen: 0.0,
            contacts: 0,
            contacts_ho: 0,
            link_contact: [0; 2],
            reactions: [Reaction::default(); MAX_REACTIONS],
            n_reactions: 0,
        }
    }
}

/// A contact found by a narrow-phase function.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Contact {
    /// Penetration depth (m); the pair touches when > 0.
    pub depth: f32,
    /// Unit normal from the second body to the first (world).
    pub normal: Vec3,
    /// Contact point on the second body's surface (world).
    pub point: Vec3,
    /// How many point springs the contact stands for: 1 for a contact at one point; for a face
    /// pressed on a face (`box_box_contact`) or a capsule along one (`capsule_face_contact`),
    /// Σ dᵢ / depth over the manifold's points (dᵢ their
    /// depths, `point` their centre weighted by dᵢ), so that k·spring_count·depth at `point` is
    /// the sum of the points' springs and its moment theirs.
    pub spring_count: f32,
    /// The manifold's spread about `point` (world): C = Σ wᵢ eᵢ eᵢᵀ with wᵢ = dᵢ / Σ d and eᵢ
    /// each point's offset from `point`, as its diagonal and (xy, xz, yz); zero at one point. The
    /// object's implicit solve takes the points' resistance to turning from it (`spread_matrix`).
    pub spread_diag: Vec3,
    pub spread_off: Vec3,
}

/// A contact at one point.
#[inline]
pub fn contact_at(depth: f32, normal: Vec3, point: Vec3) -> Contact {
    Contact { depth, normal, point, spring_count: 1.0, spread_diag: Vec3::ZERO, spread_off: Vec3::ZERO }
}

impl Default for Contact {
    fn default() -> Self {
        contact_at(0.0, Vec3::ZERO, Vec3::ZERO)
    }
}

/// The xyz of a padded `[f32; 4]` (a WGSL `vec4`'s `.xyz`).
#[inline]
pub fn v3(a: [f32; 4]) -> Vec3 {
    Vec3::new(a[0], a[1], a[2])
}

/// A `[f32; 4]` as a Vec4 (quaternions, xyzw).
#[inline]
pub fn v4(a: [f32; 4]) -> Vec4 {
    Vec4::from_array(a)
}

/// A Vec3 as a padded `[f32; 4]` (w = 0).
#[inline]
pub fn put3(v: Vec3) -> [f32; 4] {
    [v.x, v.y, v.z, 0.0]
}

/// Sign with sgn(0) = 1 (WGSL's `sign` returns 0 there, so both use this).
pub fn sgn(x: f32) -> f32 {
    if x < 0.0 { -1.0 } else { 1.0 }
}

/// Clamps the length of `v` to `max`.
pub fn clamp_norm(v: Vec3, max: f32) -> Vec3 {
    let l = v.length();
    if l > max { v * (max / l) } else { v }
}

/// Link poses, link velocities and world joint axes from the wrist state and joint positions.
pub fn hand_kinematics(st: &EnvState, m: &Model, s: &mut Scratch) {
    s.link_pos[0] = v3(st.wrist_pos);
    s.link_rot[0] = v4(st.wrist_rot);
    s.link_v[0] = v3(st.wrist_vel);
    s.link_w[0] = v3(st.wrist_angvel);
    for j in 0..m.g.n_joints as usize {
        let jd = &m.joints[j];
        let p = jd.parent_link as usize;
        // most URDF joint frames are not turned from their parent's: the product with the
        // identity is the parent's rotation (to the bit, but for the sign of a zero)
        let frame_rot = if jd.origin_rot == [0.0, 0.0, 0.0, 1.0] { s.link_rot[p] } else { quat_mul(s.link_rot[p], v4(jd.origin_rot)) };
        let o = s.link_pos[p] + quat_rotate(s.link_rot[p], v3(jd.origin_pos));
        let axis = quat_rotate(frame_rot, v3(jd.axis));
        s.joint_axis[j] = axis;
        s.link_pos[j + 1] = o;
        s.link_rot[j + 1] = quat_mul_axis_angle(frame_rot, v3(jd.axis), st.q[j]);
        // ω_child = ω_parent + a q̇;  v_child = v_parent + ω_parent × (o − p_parent)
        s.link_w[j + 1] = s.link_w[p] + axis * st.qd[j];
        s.link_v[j + 1] = s.link_v[p] + s.link_w[p].cross(o - s.link_pos[p]);
    }
}

/// `quat_mul(a, quat_from_axis_angle(axis, angle))`, to the bit but for the sign of a zero; for a
/// joint axis along ±x, ±y or ±z of its frame (most URDF joints), the terms the axis's zeros
/// make zero left out.
#[inline(always)]
pub fn quat_mul_axis_angle(a: Vec4, axis: Vec3, angle: f32) -> Vec4 {
    let (sn, c) = ((0.5 * angle).sin(), (0.5 * angle).cos());
    // b = (axis·sin(θ/2), cos(θ/2)); quat_mul's rows with b's zero entries dropped, the others
    // summed in its order
    if axis.y == 0.0 && axis.z == 0.0 && axis.x.abs() == 1.0 {
        let bx = axis.x * sn;
        return Vec4::new(a.w * bx + a.x * c, a.y * c + a.z * bx, -(a.y * bx) + a.z * c, a.w * c - a.x * bx);
    }
    if axis.x == 0.0 && axis.z == 0.0 && axis.y.abs() == 1.0 {
        let by = axis.y * sn;
        return Vec4::new(a.x * c - a.z * by, a.w * by + a.y * c, a.x * by + a.z * c, a.w * c - a.y * by);
    }
    if axis.x == 0.0 && axis.y == 0.0 && axis.z.abs() == 1.0 {
        let bz = axis.z * sn;
        return Vec4::new(a.x * c + a.y * bz, -(a.x * bz) + a.y * c, a.w * bz + a.z * c, a.w * c - a.z * bz);
    }
    quat_mul(a, Vec4::new(axis.x * sn, axis.y * sn, axis.z * sn, c))
}

/// Velocity of the point `x` (world) fixed to hand link `l`.
#[inline]
pub fn link_point_velocity(s: &Scratch, l: usize, x: Vec3) -> Vec3 {
    s.link_v[l] + s.link_w[l].cross(x - s.link_pos[l])
}

/// Support point `k` of the object against the table: local position and radius.
pub fn object_support_point(code: u32, size: Vec3, k: u32) -> (Vec3, f32) {
    if code == SHAPE_SPHERE {
        return (Vec3::ZERO, size.x);
    }
    if code == SHAPE_BOX {
        let sx = if (k & 1) != 0 { size.x } else { -size.x };
        let sy = if (k & 2) != 0 { size.y } else { -size.y };
        let sz = if (k & 4) != 0 { size.z } else { -size.z };
        return (Vec3::new(sx, sy, sz), 0.0);
    }
    if code == SHAPE_CAPSULE {
        let z = if k == 0 { -size.y } else { size.y };
        return (Vec3::new(0.0, 0.0, z), size.x);
    }
    // cylinder: 8 points on the rim of each cap
    let a = 0.7853982 * (k % 8) as f32;
    let z = if k < 8 { -size.y } else { size.y };
    (Vec3::new(size.x * a.cos(), size.x * a.sin(), z), 0.0)
}

/// Number of support points of an object shape.
pub fn object_num_support(code: u32) -> u32 {
    if code == SHAPE_SPHERE {
        return 1;
    }
    if code == SHAPE_BOX {
        return 8;
    }
    if code == SHAPE_CAPSULE {
        return 2;
    }
    16
}

/// Closest point of the solid object (local frame) to `p`; the flag is true when `p` is inside.
#[inline]
pub fn object_project(code: u32, size: Vec3, p: Vec3) -> (Vec3, bool) {
    if code == SHAPE_BOX {
        let c = p.clamp(-size, size);
        let inside = p.x.abs() <= size.x && p.y.abs() <= size.y && p.z.abs() <= size.z;
        return (c, inside);
    }
    if code == SHAPE_CYLINDER {
        let z = p.z.clamp(-size.y, size.y);
        let rho = (p.x * p.x + p.y * p.y).sqrt();
        let inside = rho <= size.x && p.z.abs() <= size.y;
        let k = if rho > size.x { size.x / rho } else { 1.0 };
        return (Vec3::new(p.x * k, p.y * k, z), inside);
    }
    // sphere (axis half length 0) and capsule: distance to the axis segment
    let hl = if code == SHAPE_CAPSULE { size.y } else { 0.0 };
    let c = Vec3::new(0.0, 0.0, p.z.clamp(-hl, hl));
    let d = p - c;
    let l = d.length();
    if l <= size.x {
        return (p, true);
    }
    (c + d * (size.x / l), false)
}

/// For a point inside the solid object (local frame): outward normal of the nearest surface and the
/// distance to it.
pub fn object_inside_normal(code: u32, size: Vec3, p: Vec3) -> (Vec3, f32) {
    if code == SHAPE_BOX {
        let dx = size.x - p.x.abs();
        let dy = size.y - p.y.abs();
        let dz = size.z - p.z.abs();
        if dx <= dy && dx <= dz {
            return (Vec3::new(sgn(p.x), 0.0, 0.0), dx);
        }
        if dy <= dz {
            return (Vec3::new(0.0, sgn(p.y), 0.0), dy);
        }
        return (Vec3::new(0.0, 0.0, sgn(p.z)), dz);
    }
    if code == SHAPE_CYLINDER {
        let rho = (p.x * p.x + p.y * p.y).sqrt();
        let dr = size.x - rho;
        let dz = size.y - p.z.abs();
        if dz < dr || rho < 1e-9 {
            return (Vec3::new(0.0, 0.0, sgn(p.z)), dz);
        }
        return (Vec3::new(p.x / rho, p.y / rho, 0.0), dr);
    }
    let hl = if code == SHAPE_CAPSULE { size.y } else { 0.0 };
    let d = p - Vec3::new(0.0, 0.0, p.z.clamp(-hl, hl));
    let l = d.length();
    if l < 1e-9 {
        return (Vec3::X, size.x);
    }
    (d / l, size.x - l)
}

/// Minimum translation that pushes the segment [a, b] (box frame) out of the box of half extents `h`
/// along a face normal (separating-axis test on the three face axes): the outward normal, the distance
/// and the deepest endpoint moved onto that face. Continuous with the closest-point contact at the
/// moment the segment first touches the box, so a capsule that sinks in keeps being pushed out the
/// way it came.
pub fn segment_box_push(a: Vec3, b: Vec3, h: Vec3) -> (Vec3, f32, Vec3) {
    let mut best_d = 1e30f32;
    let mut best_n = Vec3::Z;
    let mut best_p = a;
    for i in 0..3 {
        for side in 0..2 {
            let s = if side == 0 { 1.0 } else { -1.0 };
            // the endpoint deepest along −s·eᵢ and how far it must move along s·eᵢ to reach the face
            let deep = if s * a[i] <= s * b[i] { a } else { b };
            let d = h[i] - s * deep[i];
            if d < best_d {
                best_d = d;
                let mut n = Vec3::ZERO;
                n[i] = s;
                best_n = n;
                let mut p = deep.clamp(-h, h);
                p[i] = s * h[i];
                best_p = p;
            }
        }
    }
    (best_n, best_d, best_p)
}

/// The point of segment [a, b] nearest a box of half extents `h` (all in the box's frame), exactly:
/// the squared distance f(t) = Σᵢ max(|pᵢ(t)| − hᵢ, 0)² of p(t) = a + t (b − a) is convex and
/// piecewise quadratic in t, so its slope f′ is piecewise linear and non-decreasing, with its kinks
/// where a coordinate crosses a face plane (pᵢ(t) = ±hᵢ). The root of f′ lies between the last kink
/// (or 0) where f′ ≤ 0 and the first (or 1) where f′ > 0, where f′ is linear. (Alternating
/// projections zig-zag slowly toward it when the segment lies nearly along a face.)
pub fn segment_box_closest(a: Vec3, b: Vec3, h: Vec3) -> Vec3 {
    let u = b - a;
    let (mut t_lo, mut t_hi) = (0.0f32, 1.0f32);
    let (mut s_lo, mut s_hi) = (segment_box_slope(a, u, h, 0.0), segment_box_slope(a, u, h, 1.0));
    if s_lo >= 0.0 {
        return a;
    }
    if s_hi <= 0.0 {
        return b;
    }
    for i in 0..3 {
        if u[i].abs() < 1e-12 {
            continue;
        }
        for side in 0..2 {
            let face = if side == 0 { h[i] } else { -h[i] };
            let t = (face - a[i]) / u[i];
            if t > t_lo && t < t_hi {
                let st = segment_box_slope(a, u, h, t);
                if st <= 0.0 {
                    (t_lo, s_lo) = (t, st);
                } else {
                    (t_hi, s_hi) = (t, st);
                }
            }
        }
    }
    // f′ linear on [t_lo, t_hi]: its root
    let t = t_lo + (t_hi - t_lo) * (-s_lo / (s_hi - s_lo));
    a + u * t
}

/// Half the slope df/dt of `segment_box_closest`'s f at t: Σᵢ uᵢ · sign(pᵢ) · max(|pᵢ| − hᵢ, 0).
pub fn segment_box_slope(a: Vec3, u: Vec3, h: Vec3, t: f32) -> f32 {
    let p = a + u * t;
    let mut s = 0.0;
    for i in 0..3 {
        s += u[i] * sgn(p[i]) * (p[i].abs() - h[i]).max(0.0);
    }
    s
}

/// Closest point on the segment [a, b] to `p`.
#[inline]
pub fn segment_closest(a: Vec3, b: Vec3, p: Vec3) -> Vec3 {
    let ab = b - a;
    let l2 = ab.dot(ab);
    if l2 < 1e-18 {
        return a;
    }
    a + ab * ((p - a).dot(ab) / l2).clamp(0.0, 1.0)
}

/// Closest point of a box (centre `c`, rotation `r`, half extents `h`) to `p`, all in one frame.
#[inline]
pub fn box_project(c: Vec3, r: Vec4, h: Vec3, p: Vec3) -> Vec3 {
    let local = quat_rotate(quat_conj(r), p - c);
    c + quat_rotate(r, local.clamp(-h, h))
}

/// Closest point of the triangle (a, b, c) to `p` (Ericson, Real-Time Collision Detection §5.1.5:
/// the Voronoi regions of the vertices, then the edges, then the face). The host's f64
/// `mesh::hull::closest_point_on_triangle` is not used here: this twin follows the shader's f32
/// arithmetic step for step.
pub fn triangle_closest(p: Vec3, a: Vec3, b: Vec3, c: Vec3) -> Vec3 {
    let ab = b - a;
    let ac = c - a;
    let ap = p - a;
    let d1 = ab.dot(ap);
    let d2 = ac.dot(ap);
    if d1 <= 0.0 && d2 <= 0.0 {
        return a;
    }
    let bp = p - b;
    let d3 = ab.dot(bp);
    let d4 = ac.dot(bp);
    if d3 >= 0.0 && d4 <= d3 {
        return b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return a + ab * (d1 / (d1 - d3));
    }
    let cp = p - c;
    let d5 = ab.dot(cp);
    let d6 = ac.dot(cp);
    if d6 >= 0.0 && d5 <= d6 {
        return c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return a + ac * (d2 / (d2 - d6));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && d4 - d3 >= 0.0 && d5 - d6 >= 0.0 {
        return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
    }
    // inside the face: barycentric (u, v, w) ∝ (va, vb, vc)
    let denom = 1.0 / (va + vb + vc);
    a + ab * (vb * denom) + ac * (vc * denom)
}

/// Vertex `k` of hull piece `pd` (piece frame, scaled by `scale`). The hull's data in `m.hulls`
/// from `pd.hull_first`: its F face planes (n, d), its F triangles (vertex indices as floats),
/// then its vertices (xyz).
pub fn hull_vertex(m: &Model, pd: &PieceDesc, scale: f32, k: u32) -> Vec3 {
    v3(m.hulls[(pd.hull_first + 2 * pd.hull_faces + k) as usize]) * scale
}

/// Closest point of the solid hull `pd` (piece frame, scaled) to `p`; the flag is true when `p` is
/// inside (on the inner side of every face plane). Outside, the closest point lies on a face whose
/// plane `p` is in front of: the nearest of those triangles' closest points.
pub fn hull_project(m: &Model, pd: &PieceDesc, scale: f32, p: Vec3) -> (Vec3, bool) {
    let base = pd.hull_first as usize;
    let nf = pd.hull_faces as usize;
    let mut inside = true;
    let mut best = p;
    let mut best_d2 = 1e30f32;
    for f in 0..nf {
        let pl = m.hulls[base + f];
        // signed distance to the face plane: n·p − s·d
        if v3(pl).dot(p) - scale * pl[3] > 0.0 {
            inside = false;
            let t = m.hulls[base + nf + f];
            let a = hull_vertex(m, pd, scale, t[0] as u32);
            let b = hull_vertex(m, pd, scale, t[1] as u32);
            let c = hull_vertex(m, pd, scale, t[2] as u32);
            let q = triangle_closest(p, a, b, c);
            let d2 = (p - q).length_squared();
            if d2 < best_d2 {
                best_d2 = d2;
                best = q;
            }
        }
    }
    (best, inside)
}

/// Minimum translation that pushes the segment [a, b] (piece frame) out of hull `pd` along a face
/// normal (the separating-axis test on the hull's faces, as `segment_box_push` on a box's): the
/// outward normal, the distance and the deepest endpoint moved onto that face's plane.
pub fn segment_hull_push(m: &Model, pd: &PieceDesc, scale: f32, a: Vec3, b: Vec3) -> (Vec3, f32, Vec3) {
    let base = pd.hull_first as usize;
    let mut best_d = 1e30f32;
    let mut best_n = Vec3::Z;
    let mut best_p = a;
    for f in 0..pd.hull_faces as usize {
        let pl = m.hulls[base + f];
        let n = v3(pl);
        // the endpoint deepest along −n and how far it must move along n to reach the plane
        let deep = if n.dot(a) <= n.dot(b) { a } else { b };
        let d = scale * pl[3] - n.dot(deep);
        if d < best_d {
            best_d = d;
            best_n = n;
            best_p = deep + n * d;
        }
    }
    (best_n, best_d, best_p)
}

/// Closest point of object piece `pd` (piece frame; scaled `size`, or its hull scaled by `scale`)
/// to `p`, and whether `p` is inside.
#[inline]
pub fn piece_project(m: &Model, pd: &PieceDesc, scale: f32, size: Vec3, p: Vec3) -> (Vec3, bool) {
    if pd.shape == SHAPE_HULL {
        return hull_project(m, pd, scale, p);
    }
    object_project(pd.shape, size, p)
}

/// World pose of hand collider `ci`.
#[inline(always)]
pub fn collider_pose(m: &Model, s: &Scratch, ci: usize) -> (Vec3, Vec4) {
    (collider_centre(m, s, ci), collider_rotation(m, s, ci))
}

/// The centre of `collider_pose` alone (the contact pass turns only the colliders near the object
/// or the table).
#[inline(always)]
pub fn collider_centre(m: &Model, s: &Scratch, ci: usize) -> Vec3 {
    let cd = &m.colliders[ci];
    let l = cd.link as usize;
    s.link_pos[l] + quat_rotate(s.link_rot[l], v3(cd.pos))
}

/// The rotation of `collider_pose` alone.
#[inline(always)]
pub fn collider_rotation(m: &Model, s: &Scratch, ci: usize) -> Vec4 {
    let cd = &m.colliders[ci];
    quat_mul(s.link_rot[cd.link as usize], v4(cd.rot))
}

/// Radius of a sphere about the centre that bounds a shape (sphere/box/capsule/cylinder `code`, size).
#[inline]
pub fn bounding_radius(code: u32, size: Vec3) -> f32 {
    if code == SHAPE_SPHERE {
        return size.x;
    }
    if code == SHAPE_BOX {
        return size.length();
    }
    if code == SHAPE_CAPSULE {
        return size.x + size.y;
    }
    (size.x * size.x + size.y * size.y).sqrt()
}

/// World pose and scaled size of an object piece: (centre, rotation, size).
pub fn piece_pose(st: &EnvState, p: &EnvParams, pd: &PieceDesc) -> (Vec3, Vec4, Vec3) {
    piece_pose_at(p, pd, v3(st.obj_pos), v4(st.obj_rot))
}

/// `piece_pose` with the object's frame at `opos`, `orot`.
pub fn piece_pose_at(p: &EnvParams, pd: &PieceDesc, opos: Vec3, orot: Vec4) -> (Vec3, Vec4, Vec3) {
    // centre = p_obj + R_obj (s · c_piece),  rotation = R_obj R_piece
    let pos = opos + quat_rotate(orot, v3(pd.pos) * p.obj_scale);
    (pos, quat_mul(orot, v4(pd.rot)), v3(pd.size) * p.obj_scale)
}

/// The object's centre of mass (world): p_obj + R_obj c.
pub fn object_com(st: &EnvState, p: &EnvParams) -> Vec3 {
    v3(st.obj_pos) + quat_rotate(v4(st.obj_rot), v3(p.obj_com))
}

/// The speculative margin (m) of hand collider `ci` against the object (its centre of mass `ocom`
/// moving at `ovel`, turning at `ow`): `CONTACT_MARGIN`, or how far the pair's points can close
/// within the substep where that is more — h times a bound on their relative speed, the speed at
/// the collider's centre plus its bounding radius times the pair's relative turn rate (the
/// relative velocity of two rigid bodies is affine in the point). A fingertip hitting a spinning
/// cube at 2.3–2.7 m/s closes 5 mm in a substep, past the fixed margin: first seen already 1–2 mm in.
pub fn speculative_margin(m: &Model, s: &Scratch, ci: usize, h: f32, ocom: Vec3, ovel: Vec3, ow: Vec3) -> f32 {
    speculative_margin_at(m, s, ci, collider_pose(m, s, ci).0, h, ocom, ovel, ow)
}

/// `speculative_margin` with the collider's centre at `cpos` (the CPU's contact pass computes
/// each collider's pose once per substep).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub fn speculative_margin_at(m: &Model, s: &Scratch, ci: usize, cpos: Vec3, h: f32, ocom: Vec3, ovel: Vec3, ow: Vec3) -> f32 {
    let cd = &m.colliders[ci];
    let l = cd.link as usize;
    let v = link_point_velocity(s, l, cpos) - (ovel + ow.cross(cpos - ocom));
    let dw = s.link_w[l] - ow;
    // (|v| + r|Δω|)² ≤ 2(|v|² + r²|Δω|²): where h² times that bound is within 0.99 of the fixed
    // margin's square, h(|v| + r|Δω|) is under the margin however it rounds, and the margin is
    // the fixed one, as the shader finds it (no square roots for the many pairs closing slowly)
    let r2 = if cd.shape == SHAPE_BOX { v3(cd.size).length_squared() } else { bounding_radius(cd.shape, v3(cd.size)).powi(2) };
    if 2.0 * h * h * (v.length_squared() + r2 * dw.length_squared()) <= 0.99 * CONTACT_MARGIN * CONTACT_MARGIN {
        return CONTACT_MARGIN;
    }
    let r = bounding_radius(cd.shape, v3(cd.size));
    (h * (v.length() + r * dw.length())).max(CONTACT_MARGIN)
}

/// Narrow phase between hand collider `ci` and the env's object: the deepest contact over the
/// object's pieces (normal from object to hand; a negative depth is the gap of a pair within
/// `margin`, `speculative_margin`). Pairs whose bounding spheres, grown by the margin, do not
/// touch (the whole object's first, then each piece's) are rejected (depth −1).
#[inline]
pub fn collide_hand_object(st: &EnvState, p: &EnvParams, m: &Model, s: &Scratch, ci: usize, margin: f32) -> Contact {
    let (cpos, crot) = collider_pose(m, s, ci);
    collide_hand_object_at(p, m, ci, cpos, crot, v3(st.obj_pos), v4(st.obj_rot), margin)
}

/// `collide_hand_object` with the collider at `cpos`, `crot` and the object's frame at `opos`,
/// `orot`.
#[allow(clippy::too_many_arguments)]
pub fn collide_hand_object_at(p: &EnvParams, m: &Model, ci: usize, cpos: Vec3, crot: Vec4, opos: Vec3, orot: Vec4, margin: f32) -> Contact {
    let cd = &m.colliders[ci];
    let rc = bounding_radius(cd.shape, v3(cd.size)) + margin;
    let mut best = contact_at(-1.0, Vec3::Z, opos);
    if !object_in_reach(p, cd, cpos, opos, margin) {
        return best;
    }
    let od = &m.objects[p.obj_index as usize];
    // the collider's centre in the object frame: each piece's bounding sphere is tested there,
    // without turning the piece into the world
    let c_obj = quat_rotate(quat_conj(orot), cpos - opos);
    for k in 0..od.n_pieces {
        let pd = &m.pieces[(od.first_piece + k) as usize];
        let r = rc + pd.pos[3] * p.obj_scale;
        if (c_obj - v3(pd.pos) * p.obj_scale).length_squared() > r * r {
            continue;
        }
        // a piece whose frame is the object's (a primitive object's one piece): its pose is the
        // object's (`piece_pose_at` returns it to the bit, but for the sign of a zero), and the
        // collider's centre in it is c_obj (CPU only: in the shader this shortcut blew up the
        // bench scene's envs on lavapipe, cause not found, BENCHMARKS.md "The shader takes the
        // CPU's exact cuts"; since 2026-11-30 it does not, but is slower there)
        let c = if pd.pos[..3] == [0.0; 3] && pd.rot == [0.0, 0.0, 0.0, 1.0] {
            collide_collider_piece_in(m, cd, c_obj, quat_mul(quat_conj(orot), crot), pd, p.obj_scale, opos, orot, margin)
        } else {
            let (ppos, prot, _) = piece_pose_at(p, pd, opos, orot);
            collide_collider_piece(m, cd, cpos, crot, pd, p.obj_scale, ppos, prot, margin)
        };
        if c.depth > best.depth {
            best = c;
        }
    }
    best
}

/// `collide_hand_object_at`'s first test: the collider's bounding sphere, grown by `margin`,
/// meets the object's (a NaN pose passes, on to the narrow phase). The contact pass takes it first,
/// to leave a far collider unturned.
#[inline(always)]
pub fn object_in_reach(p: &EnvParams, cd: &ColliderDesc, cpos: Vec3, opos: Vec3, margin: f32) -> bool {
    let reach = bounding_radius(cd.shape, v3(cd.size)) + margin + p.obj_com[3];
    #[allow(clippy::neg_cmp_op_on_partial_ord)]
    let within = !((cpos - opos).length_squared() > reach * reach);
    within
}

/// The object's frame (origin, rotation) at the end of the substep if it keeps its velocities (its
/// centre of mass `ocom` moving at `ovel`, turning at `ow`), as `integrate_object` moves it: the
/// frame turns about the centre of mass.
#[inline(always)]
pub fn object_frame_at_end(st: &EnvState, p: &EnvParams, h: f32, ocom: Vec3, ovel: Vec3, ow: Vec3) -> (Vec3, Vec4) {
    let rot = quat_integrate(v4(st.obj_rot), ow, h);
    (ocom + ovel * h - quat_rotate(rot, v3(p.obj_com)), rot)
}

/// A collider's pose (`cpos`, `crot`, on link `l`) at the end of the substep: it moves with its link.
#[inline(always)]
pub fn collider_pose_at_end(s: &Scratch, l: usize, cpos: Vec3, crot: Vec4, h: f32) -> (Vec3, Vec4) {
    (cpos + link_point_velocity(s, l, cpos) * h, quat_integrate(crot, s.link_w[l], h))
}

/// The test of `swept_contact_at` for hand collider `ci`'s contact `c` at the substep's poses,
/// against the object's velocities `ovel`, `ow`: `Some(c_end)`, `c`'s own depth by the end of the
/// substep, where the swept search may find a contact deeper than that by more than
/// `SWEPT_TOLERANCE`; `None` where it cannot.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub fn swept_test(m: &Model, s: &Scratch, ci: usize, c: &Contact, h: f32, ocom: Vec3, ovel: Vec3, ow: Vec3) -> Option<f32> {
    if c.depth <= -1.0 {
        return None;
    }
    let cd = &m.colliders[ci];
    let l = cd.link as usize;
    // c's own depth by the end of the substep (v_hand − v_object at c along n: separating speed)
    let c_end = c.depth - h * (link_point_velocity(s, l, c.point) - (ovel + ow.cross(c.point - ocom))).dot(c.normal);
    // points of the collider's bounding sphere (radius r) move relative to the object at
    // v_rel(c) + (ω_link − ω_obj) × (x − c): any two differ by at most 2r·|ω_link − ω_obj|, so no
    // feature gets deeper than c's own prediction by more than h times that: nothing to find
    // where that is within the tolerance, or where even so nothing would be touching by then
    // (a bound of r + |c − centre| instead of 2r skipped a fifth of the searches that found a
    // deeper contact: the bound is a first-order one)
    let sweep = h * 2.0 * bounding_radius(cd.shape, v3(cd.size)) * (s.link_w[l] - ow).length();
    if sweep <= SWEPT_TOLERANCE || c_end + sweep <= 0.0 {
        return None;
    }
    Some(c_end)
}

/// The contact `end` that the swept search found at the end of the substep for link `l`, taken
/// back to the start of the substep along the relative motion: its point with the object, its
/// depth d = d_end + h·(v_rel·n).
#[allow(clippy::too_many_arguments)]
pub fn swept_contact_from_end(s: &Scratch, l: usize, end: &Contact, h: f32, ocom: Vec3, ovel: Vec3, ow: Vec3) -> Contact {
    let x = end.point - (ovel + ow.cross(end.point - ocom)) * h;
    // v_hand − v_object at x: positive along the normal where the pair separates
    let v_rel = link_point_velocity(s, l, x) - (ovel + ow.cross(x - ocom));
    Contact { depth: end.depth + h * v_rel.dot(end.normal), point: x, ..*end }
}

/// Hand–object contact `c` of collider `ci`, or the pair's contact where the collider and the
/// object will be at the end of the substep if they keep their velocities (the object's centre of
/// mass `ocom` moving at `ovel`, turning at `ow`) when that one is deeper than `c` itself would be
/// by then (`c`'s depth less its separating speed times h) by more than `SWEPT_TOLERANCE`: one
/// contact per pair sits at today's closest point, and a cube turning at 10–20 rad/s sweeps an
/// edge into the middle of a finger lying against it within a substep, 1–1.5 mm deep before
/// the next substep sees it. The swept contact is taken back to the start of the substep along
/// the relative motion (its point with the object, its depth less h times the closing speed
/// there), so the pair's implicit solve stops it at the surface. Pairs the broad phase rejects
/// (depth −1), those turning too slowly against each other for any feature to get
/// `SWEPT_TOLERANCE` deeper than `c`'s prediction within the substep, and those too far apart for
/// any to touch by its end are left alone.
#[allow(clippy::too_many_arguments)]
pub fn swept_contact(st: &EnvState, p: &EnvParams, m: &Model, s: &Scratch, ci: usize, c: Contact, h: f32, ocom: Vec3, ovel: Vec3, ow: Vec3, margin: f32) -> Contact {
    if c.depth <= -1.0 {
        return c;
    }
    let (cpos, crot) = collider_pose(m, s, ci);
    let mut obj_end = None;
    swept_contact_at(st, p, m, s, ci, cpos, crot, c, h, ocom, ovel, ow, margin, &mut obj_end)
}

/// `swept_contact` with the collider at `cpos`, `crot` (its pose at the substep's start); the
/// test that leaves a pair alone inlined, the search at the end of the substep not
/// (`swept_search`). `obj_end`: the object's frame at the end of the substep for these
/// velocities, found by the first search of a pass and kept for the others.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub fn swept_contact_at(st: &EnvState, p: &EnvParams, m: &Model, s: &Scratch, ci: usize, cpos: Vec3, crot: Vec4, c: Contact, h: f32, ocom: Vec3, ovel: Vec3, ow: Vec3, margin: f32, obj_end: &mut Option<(Vec3, Vec4)>) -> Contact {
    match swept_test(m, s, ci, &c, h, ocom, ovel, ow) {
        Some(c_end) => swept_search(st, p, m, s, ci, cpos, crot, c, c_end, h, ocom, ovel, ow, margin, obj_end),
        None => c,
    }
}

/// The search of `swept_contact_at` for a pair that may meet deeper by the substep's end (`c_end`:
/// `c`'s own depth by then).
#[allow(clippy::too_many_arguments)]
#[inline(never)]
fn swept_search(st: &EnvState, p: &EnvParams, m: &Model, s: &Scratch, ci: usize, cpos: Vec3, crot: Vec4, c: Contact, c_end: f32, h: f32, ocom: Vec3, ovel: Vec3, ow: Vec3, margin: f32, obj_end: &mut Option<(Vec3, Vec4)>) -> Contact {
    let end = contact_at_end(st, p, m, s, ci, cpos, crot, h, ocom, ovel, ow, margin, obj_end);
    swept_end_contact(s, m.colliders[ci].link as usize, &end, c_end, h, ocom, ovel, ow).unwrap_or(c)
}

/// Hand collider `ci`'s contact with the object where both will be at the end of the substep
/// (the collider at `cpos`, `crot` now, moving with its link; the object's centre of mass `ocom`
/// moving at `ovel`, turning at `ow`; `obj_end`: its frame then, found by a pass's first search
/// and kept for the others).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn contact_at_end(st: &EnvState, p: &EnvParams, m: &Model, s: &Scratch, ci: usize, cpos: Vec3, crot: Vec4, h: f32, ocom: Vec3, ovel: Vec3, ow: Vec3, margin: f32, obj_end: &mut Option<(Vec3, Vec4)>) -> Contact {
    let (cpos_end, crot_end) = collider_pose_at_end(s, m.colliders[ci].link as usize, cpos, crot, h);
    let (opos_end, orot_end) = *obj_end.get_or_insert_with(|| object_frame_at_end(st, p, h, ocom, ovel, ow));
    collide_hand_object_at(p, m, ci, cpos_end, crot_end, opos_end, orot_end, margin)
}

/// The swept search's contact `end` (found at the end of the substep for link `l`), taken back
/// to the substep's start, where it is deeper than `c_end` (the pair's own contact's depth by
/// then) by more than `SWEPT_TOLERANCE`; `None` where not (or where the narrow phase found none).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub fn swept_end_contact(s: &Scratch, l: usize, end: &Contact, c_end: f32, h: f32, ocom: Vec3, ovel: Vec3, ow: Vec3) -> Option<Contact> {
    if end.depth <= -1.0 || end.depth <= c_end + SWEPT_TOLERANCE {
        return None;
    }
    Some(swept_contact_from_end(s, l, end, h, ocom, ovel, ow))
}

/// Narrow phase between a hand collider (`cd` at `cpos`, `crot`) and object piece `pd` (its
/// lengths scaled by `scale`, at `opos`, `orot`); normal from the piece to the hand; apart by
/// more than `margin`, depth −1 (or the gap).
#[allow(clippy::too_many_arguments)]
pub fn collide_collider_piece(m: &Model, cd: &ColliderDesc, cpos: Vec3, crot: Vec4, pd: &PieceDesc, scale: f32, opos: Vec3, orot: Vec4, margin: f32) -> Contact {
    let oinv = quat_conj(orot);
    // collider in the object's frame
    collide_collider_piece_in(m, cd, quat_rotate(oinv, cpos - opos), quat_mul(oinv, crot), pd, scale, opos, orot, margin)
}

/// `collide_collider_piece` with the collider's centre `c_o` and rotation `r_o` in the piece's
/// frame (`collide_hand_object_at` has them for a piece whose frame is the object's).
#[allow(clippy::too_many_arguments)]
pub fn collide_collider_piece_in(m: &Model, cd: &ColliderDesc, c_o: Vec3, r_o: Vec4, pd: &PieceDesc, scale: f32, opos: Vec3, orot: Vec4, margin: f32) -> Contact {
    let code = pd.shape;
    let size = v3(pd.size) * scale;
    let mut out = Contact::default();
    // the piece farther from the collider's centre than the collider reaches (with the margin):
    // no contact
    let (y0, _) = piece_project(m, pd, scale, size, c_o);
    let reach = bounding_radius(cd.shape, v3(cd.size)) + margin;
    if (c_o - y0).length_squared() > reach * reach {
        out.depth = -1.0;
        return out;
    }
    if cd.shape == SHAPE_BOX {
        let h = v3(cd.size);
        // two boxes overlapping over every separating axis, least along one of the hand box's
        // faces: that face's clipped points (box_box_contact). Least along one of the piece's
        // faces or an edge pair, the support points below (with those, LEAP lost its enveloping
        // grasp of a 1.1 kg box and its antipodal grasp of the cube sank 8.8 mm:
        // docs/not-done-yet.md)
        let sat = if code == SHAPE_BOX { box_box_separation(c_o, r_o, h, size, margin) } else { (1.0, Vec3::Z, 0) };
        // a box piece apart along an axis by more than the margin: the boxes are at least that
        // far apart (the separation is a lower bound on their distance), out of reach within the
        // substep (other pieces have no separation: `sat` stands in for it)
        if code == SHAPE_BOX && sat.0 > margin {
            out.depth = -1.0;
            return out;
        }
        if sat.0 <= 0.0 && sat.2 < 3 {
            let c = box_box_contact(c_o, r_o, h, size, sat.1, sat.2);
            if c.depth > 0.0 {
                return piece_contact_to_world(c, opos, orot);
            }
        }
        let mut x = c_o;
        for _ in 0..BOX_PROJ_ITERS {
            let (y, _) = piece_project(m, pd, scale, size, x);
            let x_next = box_project(c_o, r_o, h, y);
            // a fixed point: every further round returns the same x. (Stopping once a round
            // moves x less than 0.1 µm instead moved the contact by that much, 0.02 N at the
            // hand's stiffness, at a round the two backends' roundings choose apart)
            if x_next == x {
                break;
            }
            x = x_next;
        }
        let (y, _) = piece_project(m, pd, scale, size, x);
        // y: the piece's point nearest the box where the projections end, inside the box when they
        // converged into the overlap; the piece's support points as well, since a piece turned
        // into the box enters with a corner, and where the two meet at a shallow angle the
        // projections end outside the overlap (box_piece_contact)
        let (mut depth, n_local, point) = box_piece_contact(m, pd, scale, size, c_o, r_o, h, y);
        // the normal in the object's frame
        let mut normal = quat_rotate(r_o, n_local);
        // apart by the projections, from a box piece: the gap is no more than the two boxes'
        // separation over their separating axes where those find them apart (the projections
        // zig-zag slowly between faces that meet at a shallow angle and stop short of the nearest
        // points, overstating the gap). Where the axes find them overlapping while the projections
        // end apart, the projections' answer stands: an overlap's contact point and normal need a
        // box–box contact of their own (docs/not-done-yet.md)
        if depth < 0.0 && code == SHAPE_BOX {
            let (sep, axis, _) = sat;
            if sep > 0.0 && sep < -depth {
                depth = -sep;
                normal = axis;
            }
        }
        // overlapping least along an edge pair, deeper than the support points and projections
        // find (they miss an edge across an edge: a palm's rim across a cube's edge 4.6 mm in was
        // met less than 1 mm deep, BENCHMARKS.md): the edges' own contact
        if code == SHAPE_BOX && sat.0 <= 0.0 && sat.2 >= 6 && -sat.0 > depth {
            return piece_contact_to_world(box_edge_contact(c_o, r_o, h, size, sat.1, -sat.0, sat.2), opos, orot);
        }
        out.depth = depth;
        out.normal = quat_rotate(orot, normal);
        out.point = opos + quat_rotate(orot, point);
        return out;
    }
    // sphere or capsule collider: a segment swept by a radius
    let hl = if cd.shape == SHAPE_CAPSULE { cd.size[1] } else { 0.0 };
    let axis = quat_rotate(r_o, Vec3::new(0.0, 0.0, hl));
    let a = c_o - axis;
    let b = c_o + axis;
    let x = if code == SHAPE_BOX {
        segment_box_closest(a, b, size)
    } else {
        let mut x = segment_closest(a, b, Vec3::ZERO);
        for _ in 0..PROJ_ITERS {
            let (y, _) = piece_project(m, pd, scale, size, x);
            x = segment_closest(a, b, y);
        }
        x
    };
    let (y, inside) = piece_project(m, pd, scale, size, x);
    let rc = cd.size[0];
    let mut n = Vec3::Z;
    let mut surf = y;
    if inside && code == SHAPE_BOX {
        let (nb, dist, pb) = segment_box_push(a, b, size);
        n = nb;
        out.depth = rc + dist;
        surf = pb;
    } else if inside && code == SHAPE_HULL {
        let (nh, dist, ph) = segment_hull_push(m, pd, scale, a, b);
        n = nh;
        out.depth = rc + dist;
        surf = ph;
    } else if inside {
        let (ni, dist) = object_inside_normal(code, size, x);
        n = ni;
        out.depth = rc + dist;
        surf = x + ni * dist;
    } else {
        let d = x - y;
        let l = d.length();
        out.depth = rc - l;
        if l > 1e-12 {
            n = d / l;
        }
    }
    // a capsule lying along a box piece's face: the ends of its segment's part over the face are
    // two point springs (capsule_face_contact)
    if code == SHAPE_BOX && hl > 0.0 && out.depth > 0.0 {
        let line = capsule_face_contact(a, b, rc, size, n);
        if line.spring_count > 1.0 {
            return piece_contact_to_world(line, opos, orot);
        }
    }
    out.normal = quat_rotate(orot, n);
    out.point = opos + quat_rotate(orot, surf);
    out
}

/// The face of a box (half extents `h`) nearest a point `v` inside it (box frame; `d` = h − |v|):
/// the push out through it (the box's outward normal there, negated: it pushes the box away from
/// the point) and the point's distance to it.
pub fn nearest_box_face(v: Vec3, d: Vec3) -> (Vec3, f32) {
    if d.x <= d.y && d.x <= d.z {
        return (Vec3::new(-sgn(v.x), 0.0, 0.0), d.x);
    }
    if d.y <= d.z {
        return (Vec3::new(0.0, -sgn(v.y), 0.0), d.y);
    }
    (Vec3::new(0.0, 0.0, -sgn(v.z)), d.z)
}

/// The contact of a hand box (centre `c_o`, rotation `r_o`, half extents `h`, in the piece frame)
/// with piece `pd` (scaled `size`, its hull scaled by `scale`), given the piece's point `y` nearest
/// the box (the alternating projections' end): (depth, the push on the hand in the box frame, the
/// contact point in the piece frame; depth −1 when apart). The candidates are y, when inside the
/// box, and each of the piece's support points inside it (corners, hull vertices, a rounded
/// support's point nearest the box's inside), each at its distance to its nearest face: the
/// deepest gives the depth and the face. The point is the average of y (weight DEEP_BLEND) and the
/// support points of that face deeper than y's depth past it (or than the face, y outside) by w,
/// weighted by w: y itself while the piece lies flat against the face, the entering corner or
/// edge as it turns in, continuously in between.
#[allow(clippy::too_many_arguments)]
pub fn box_piece_contact(m: &Model, pd: &PieceDesc, scale: f32, size: Vec3, c_o: Vec3, r_o: Vec4, h: Vec3, y: Vec3) -> (f32, Vec3, Vec3) {
    let inv = quat_conj(r_o);
    let ly = quat_rotate(inv, y - c_o);
    let dy = h - ly.abs();
    let mut depth = -1.0f32;
    let mut n = Vec3::Z;
    if dy.x >= 0.0 && dy.y >= 0.0 && dy.z >= 0.0 {
        (n, depth) = nearest_box_face(ly, dy);
    }
    // the piece's bounding sphere (about its frame's origin) apart from the box: no support point
    // inside it
    let gap = (quat_rotate(inv, -c_o).abs() - h).max(Vec3::ZERO);
    let radius = pd.pos[3] * scale;
    if gap.length_squared() > radius * radius {
        return box_gap_contact(h, ly, y);
    }
    // the deepest support point inside the box, at its nearest face
    let y_depth = depth;
    for k in 0..pd.n_support {
        let (v, r) = box_frame_support(m, pd, scale, size, inv, c_o, k);
        let dd = h - v.abs();
        let (nk, dk) = nearest_box_face(v, dd);
        if dd.x >= -r && dd.y >= -r && dd.z >= -r && dk + r > depth {
            depth = dk + r;
            n = nk;
        }
    }
    if depth < 0.0 {
        return box_gap_contact(h, ly, y);
    }
    // no support point deeper than y: none is deeper than y past y's face either (the point is y)
    if depth == y_depth {
        return (depth, n, y);
    }
    // y's depth past that face (negative outside it) sets the floor the support points are weighed from
    let floor = (h.dot(n.abs()) + n.dot(ly)).max(0.0);
    let mut wsum = DEEP_BLEND;
    let mut psum = y * DEEP_BLEND;
    for k in 0..pd.n_support {
        let (v, r) = box_frame_support(m, pd, scale, size, inv, c_o, k);
        let dd = h - v.abs();
        let (nk, dk) = nearest_box_face(v, dd);
        let w = dk + r - floor;
        if dd.x >= -r && dd.y >= -r && dd.z >= -r && nk == n && w > 0.0 {
            wsum += w;
            // a rounded support's point nearest the box's inside
            psum += (c_o + quat_rotate(r_o, v + n * r)) * w;
        }
    }
    (depth, n, psum / wsum)
}

/// How much larger (m) an edge–edge axis's separation must be than the best face axis's for two
/// boxes' contact to be taken along it, plus `EDGE_AXIS_SHARE` of the face's overlap: where a
/// face and an edge overlap alike, the face's clipped points make the steadier contact.
pub const EDGE_AXIS_BIAS: f32 = 1.0e-4;

/// The share of the best face axis's overlap by which an edge–edge axis must overlap less to be
/// taken (with `EDGE_AXIS_BIAS`): pushed along a face that overlaps at most 10 % more than the
/// least, the boxes part within 10 % of the shortest way. A palm lying nearly flat on a cube, its
/// rim across the cube's edge, overlaps 6 % less along an edge pair than along its face; there
/// the support points (the cube's corners inside the palm) missed the rim, a cube 1.7 mm in was
/// met 0.1 mm deep, and the face's clipped points meet it (BENCHMARKS.md).
pub const EDGE_AXIS_SHARE: f32 = 0.1;

/// The largest separation (m) of a box (centre `c`, rotation `r`, half-extents `ha`) from the
/// axis-aligned box of half-extents `hb` at the origin over the 15 separating axes of two boxes
/// (each box's 3 face normals, then the 9 cross products of their edges; near-parallel edges
/// skipped: a face axis stands for them), that axis, pointing from the second box to the first,
/// and its index k (0–2: the first box's faces, 3–5: the second's, 6 + 3i + j: edge i of the
/// first × edge j of the second). An edge axis is taken only where it beats the best face axis
/// by `EDGE_AXIS_BIAS` and `EDGE_AXIS_SHARE` of that face's overlap. Positive: a lower bound on
/// the boxes' distance, equal to it where their nearest features are a face and what lies
/// against it; zero or less: they overlap, by its magnitude along the axis (the separating-axis
/// theorem). As soon as an axis taken separates them by more than `apart_beyond`, that axis (the
/// narrow phase needs no more of boxes apart by more than the margin).
pub fn box_box_separation(c: Vec3, r: Vec4, ha: Vec3, hb: Vec3, apart_beyond: f32) -> (f32, Vec3, usize) {
    // the first box's axes aᵢ (the second's are x̂, ŷ, ẑ)
    let a = quat_axes(r);
    let mut best = (-3.0e38f32, Vec3::Z, 0usize);
    for k in 0..15 {
        // the axis l, 1/|l|, and each box's half-width along l times |l| (Σ hᵢ |uᵢ·l|)
        let (l, inv_len, ra, rb) = if k < 3 {
            // the first box's face: its half-width along its own axis is h_k
            let l = a[k];
            (l, 1.0, ha[k], hb.x * l.x.abs() + hb.y * l.y.abs() + hb.z * l.z.abs())
        } else if k < 6 {
            // the second box's face: aᵢ·ê_j is aᵢ's component j
            let j = k - 3;
            let mut l = Vec3::ZERO;
            l[j] = 1.0;
            (l, 1.0, ha.x * a[0][j].abs() + ha.y * a[1][j].abs() + ha.z * a[2][j].abs(), hb[j])
        } else {
            let (i, j) = ((k - 6) / 3, (k - 6) % 3);
            let mut e = Vec3::ZERO;
            e[j] = 1.0;
            let l = a[i].cross(e);
            // |aᵢ × ê_j|² = 1 − (aᵢ)_j²: parallel edges are skipped (a face axis stands for them)
            let len2 = 1.0 - a[i][j] * a[i][j];
            if len2 < 1e-8 {
                continue;
            }
            // a_m·(aᵢ × ê_j) = ê_j·(a_m × aᵢ): 0 for m = i, ± the third axis's component j otherwise
            let (i1, i2) = ((i + 1) % 3, (i + 2) % 3);
            let ra = ha[i1] * a[i2][j].abs() + ha[i2] * a[i1][j].abs();
            (l, 1.0 / len2.sqrt(), ra, hb.x * l.x.abs() + hb.y * l.y.abs() + hb.z * l.z.abs())
        };
        let t = c.dot(l);
        let sep = (t.abs() - ra - rb) * inv_len;
        // an edge axis must beat the faces' best by the bias and a share of its overlap (−sep)
        let bias = if k >= 6 { EDGE_AXIS_BIAS + EDGE_AXIS_SHARE * (-best.0).max(0.0) } else { 0.0 };
        if sep > best.0 + bias {
            best = (sep, if t >= 0.0 { l * inv_len } else { -l * inv_len }, k);
            if best.0 > apart_beyond {
                return best;
            }
        }
    }
    best
}

/// Sutherland–Hodgman: the part of polygon `poly` (its first `n` points, in order) where
/// `sign·q[t] ≤ lim`, and its point count (at most 8: a quadrilateral clipped by four lines).
pub fn clip_polygon(poly: &[Vec3; 8], n: usize, t: usize, sign: f32, lim: f32) -> ([Vec3; 8], usize) {
    let mut out = [Vec3::ZERO; 8];
    let mut m = 0;
    if n == 0 {
        return (out, 0);
    }
    let mut prev = poly[n - 1];
    // how far past the line (inside ≤ 0)
    let mut dp = sign * prev[t] - lim;
    for &cur in poly.iter().take(n) {
        let dc = sign * cur[t] - lim;
        if (dc <= 0.0) != (dp <= 0.0) && m < 8 {
            // the edge crosses the line: prev + (cur − prev)·dp / (dp − dc)
            out[m] = prev + (cur - prev) * (dp / (dp - dc));
            m += 1;
        }
        if dc <= 0.0 && m < 8 {
            out[m] = cur;
            m += 1;
        }
        prev = cur;
        dp = dc;
    }
    (out, m)
}

/// The contact of a hand box (centre `c`, rotation `r`, half extents `ha`, in the piece frame)
/// overlapping a box piece (half extents `hb` at the origin) least along one of its own faces, k
/// < 3 (`box_box_separation`; `axis` from the piece to the hand box), in the piece frame; depth
/// −1 where no point of the manifold is below that face. The piece's face turned most squarely
/// against it (the incident face) is clipped to its rectangle; each clipped point below it is a
/// point spring of depth dᵢ, and the contact stands for them all (`Manifold`): depth max dᵢ,
/// point Σ dᵢ xᵢ / Σ dᵢ (on the piece's face), `spring_count` Σ dᵢ / max dᵢ, `spread` their
/// spread about the point — as MuJoCo's box–box contact gives a constraint per clipped point. The
/// palm pressed flat on a cube's face is four springs at the face's centre, one corner pressed in
/// one spring at the corner.
pub fn box_box_contact(c: Vec3, r: Vec4, ha: Vec3, hb: Vec3, axis: Vec3, k: usize) -> Contact {
    let a = [quat_rotate(r, Vec3::X), quat_rotate(r, Vec3::Y), quat_rotate(r, Vec3::Z)];
    let e = [Vec3::X, Vec3::Y, Vec3::Z];
    // the reference face: the hand box's face k toward the piece (outward −axis)
    let nref = -axis;
    // the incident face: the piece's face whose outward normal is most against nref
    let mut j = 0;
    for m in 1..3 {
        if nref[m].abs() > nref[j].abs() {
            j = m;
        }
    }
    let f = e[j] * (-hb[j] * sgn(nref[j]));
    let eu = e[(j + 1) % 3] * hb[(j + 1) % 3];
    let ev = e[(j + 2) % 3] * hb[(j + 2) % 3];
    // its corners in the hand box's frame, in order around the face
    let to_ref = |x: Vec3| {
        let d = x - c;
        Vec3::new(d.dot(a[0]), d.dot(a[1]), d.dot(a[2]))
    };
    let mut poly = [Vec3::ZERO; 8];
    poly[0] = to_ref(f + eu + ev);
    poly[1] = to_ref(f - eu + ev);
    poly[2] = to_ref(f - eu - ev);
    poly[3] = to_ref(f + eu - ev);
    let mut n = 4;
    // clipped to the hand box face's rectangle: |q_t| ≤ h_t along its two other axes
    for t in [(k + 1) % 3, (k + 2) % 3] {
        for sign in [1.0f32, -1.0] {
            (poly, n) = clip_polygon(&poly, n, t, sign, ha[t]);
        }
    }
    // each point's depth below the hand box's face: dᵢ = h_k − s·q_k (s: nref's sign along a_k)
    let s_ref = sgn(nref.dot(a[k]));
    let mut springs = Manifold::default();
    for q in poly.iter().take(n) {
        let d = ha[k] - s_ref * q[k];
        if d > 0.0 {
            // back in the piece frame, on the piece's incident face
            manifold_add(&mut springs, c + a[0] * q.x + a[1] * q.y + a[2] * q.z, d);
        }
    }
    manifold_contact(&springs, axis, c)
}

/// The contact of a hand box (centre `c`, rotation `r`, half extents `ha`, in the piece frame)
/// overlapping a box piece (half extents `hb` at the origin) least along edge axis k ≥ 6
/// (`box_box_separation`: the hand box's edge i = (k − 6) / 3 × the piece's edge j = (k − 6) % 3,
/// `axis` from the piece to the hand box, `overlap` the boxes' overlap along it), in the piece
/// frame: of the edges along those directions the two that reach furthest into each other, met
/// at the piece's edge's point nearest the hand box's edge, `overlap` deep along the axis — as
/// MuJoCo's box–box contact meets an edge pair.
pub fn box_edge_contact(c: Vec3, r: Vec4, ha: Vec3, hb: Vec3, axis: Vec3, overlap: f32, k: usize) -> Contact {
    let a = quat_axes(r);
    let (i, j) = ((k - 6) / 3, (k - 6) % 3);
    // the middle of the hand box's edge along aᵢ furthest toward the piece (against the axis)
    let mut pa = c;
    for m in 0..3 {
        if m != i {
            pa -= a[m] * (ha[m] * sgn(a[m].dot(axis)));
        }
    }
    // the middle of the piece's edge along ê_j furthest toward the hand box (along the axis)
    let mut pb = Vec3::ZERO;
    for m in 0..3 {
        if m != j {
            pb[m] = hb[m] * sgn(axis[m]);
        }
    }
    // the lines' nearest points pa + s aᵢ, pb + t ê_j: s (1 − b²) = b (d·ê_j) − d·aᵢ, t = d·ê_j + s b
    // (d = pa − pb, b = aᵢ·ê_j; 1 − b² = |aᵢ × ê_j|² ≥ 1e-8, box_box_separation skips nearer
    // parallel edges), each kept on its edge and t found again from the kept s
    let d = pa - pb;
    let b = a[i][j];
    let (da, db) = (a[i].dot(d), d[j]);
    let s = ((b * db - da) / (1.0 - b * b)).clamp(-ha[i], ha[i]);
    let t = (db + s * b).clamp(-hb[j], hb[j]);
    let mut x = pb;
    x[j] += t;
    contact_at(overlap, axis, x)
}

/// The point springs of one contact as they are gathered (`box_box_contact`,
/// `capsule_face_contact`): Σ dᵢ, max dᵢ, Σ dᵢ xᵢ and Σ dᵢ xᵢ xᵢᵀ (diagonal, then xy, xz, yz).
#[derive(Clone, Copy, Default)]
pub struct Manifold {
    pub dsum: f32,
    pub dmax: f32,
    pub xsum: Vec3,
    pub xx_diag: Vec3,
    pub xx_off: Vec3,
}

/// Adds a point spring at `x`, `d` deep (> 0), to `m`.
pub fn manifold_add(m: &mut Manifold, x: Vec3, d: f32) {
    m.dsum += d;
    m.dmax = m.dmax.max(d);
    m.xsum += x * d;
    m.xx_diag += x * x * d;
    m.xx_off += Vec3::new(x.x * x.y, x.x * x.z, x.y * x.z) * d;
}

/// The contact along `normal` standing for the springs gathered in `m` (depth −1 at `empty` where
/// there are none): depth max dᵢ, point p = Σ dᵢ xᵢ / Σ dᵢ, spring count Σ dᵢ / max dᵢ, spread
/// C = Σ wᵢ xᵢ xᵢᵀ − p pᵀ.
pub fn manifold_contact(m: &Manifold, normal: Vec3, empty: Vec3) -> Contact {
    if m.dsum <= 0.0 {
        return contact_at(-1.0, normal, empty);
    }
    let p = m.xsum / m.dsum;
    let spread_diag = (m.xx_diag / m.dsum - p * p).max(Vec3::ZERO);
    let spread_off = m.xx_off / m.dsum - Vec3::new(p.x * p.y, p.x * p.z, p.y * p.z);
    Contact { depth: m.dmax, normal, point: p, spring_count: m.dsum / m.dmax, spread_diag, spread_off }
}

/// A capsule (segment a–b, radius `rc`, in the piece frame) against the face of a box piece (half
/// extents `h`) whose outward normal is `n` (the pair's normal; a box's axis, else no manifold):
/// the segment's part over the face (|x_t| ≤ h_t along the face's two axes), its two ends each a
/// point spring of depth dₖ = rc − (its height over the face), the contact standing for those
/// below rc as `box_box_contact`'s for a face's points — as MuJoCo's capsule–box contact gives a
/// constraint per end. Spring count 1 (or depth −1) where one end or none is in.
pub fn capsule_face_contact(a: Vec3, b: Vec3, rc: f32, h: Vec3, n: Vec3) -> Contact {
    let none = contact_at(-1.0, n, a);
    let na = n.abs();
    let i = if na.x >= na.y && na.x >= na.z { 0 } else if na.y >= na.z { 1 } else { 2 };
    if na[i] < 0.9999 {
        return none;
    }
    let s = sgn(n[i]);
    // the segment's parameter range over the face's rectangle
    let d = b - a;
    let (mut t0, mut t1) = (0.0f32, 1.0f32);
    for t in [(i + 1) % 3, (i + 2) % 3] {
        if d[t].abs() < 1e-12 {
            if a[t].abs() > h[t] {
                return none;
            }
        } else {
            let (u0, u1) = ((-h[t] - a[t]) / d[t], (h[t] - a[t]) / d[t]);
            t0 = t0.max(u0.min(u1));
            t1 = t1.min(u0.max(u1));
        }
    }
    if t0 >= t1 {
        return none;
    }
    let mut springs = Manifold::default();
    for t in [t0, t1] {
        let mut x = a + d * t;
        // depth: rc less the end's height over the face
        let dk = rc - (s * x[i] - h[i]);
        if dk <= 0.0 {
            continue;
        }
        // on the face
        x[i] = s * h[i];
        manifold_add(&mut springs, x, dk);
    }
    manifold_contact(&springs, n, a)
}

/// Contact `c` in the frame of a piece at `opos`, `orot`, in the world: its normal, point and
/// spread (R C Rᵀ) turned.
pub fn piece_contact_to_world(c: Contact, opos: Vec3, orot: Vec4) -> Contact {
    let qi = quat_conj(orot);
    // column j of R C Rᵀ: R C (Rᵀ eⱼ)
    let col = |x: Vec3| quat_rotate(orot, spread_mul(c.spread_diag, c.spread_off, quat_rotate(qi, x)));
    let (c0, c1, c2) = (col(Vec3::X), col(Vec3::Y), col(Vec3::Z));
    let (spread_diag, spread_off) = (Vec3::new(c0.x, c1.y, c2.z), Vec3::new(c1.x, c2.x, c2.y));
    Contact { depth: c.depth, normal: quat_rotate(orot, c.normal), point: opos + quat_rotate(orot, c.point), spring_count: c.spring_count, spread_diag, spread_off }
}

/// C·x for a symmetric C given as its diagonal `d` and (xy, xz, yz) `o`.
pub fn spread_mul(d: Vec3, o: Vec3, x: Vec3) -> Vec3 {
    Vec3::new(d.x * x.x + o.x * x.y + o.y * x.z, o.x * x.x + d.y * x.y + o.z * x.z, o.y * x.x + o.z * x.y + d.z * x.z)
}

/// The rotational stiffness a manifold's points add about their centre, Σ wᵢ [eᵢ]×ᵀ D [eᵢ]× with
/// D = a nnᵀ + b (I − nnᵀ) (the pair's damping, shared out as wᵢ): b (tr C·I − C) + (a − b)
/// [n]× C [n]×ᵀ, as its three columns. Pressed at one point the object's implicit solve sees no
/// resistance to turning about it; four springs at a face's corners resist it, and in the implicit
/// solve that resistance stays stable at any stiffness, as each of the object's table contacts'.
pub fn spread_matrix(d: Vec3, o: Vec3, n: Vec3, a: f32, b: f32) -> [Vec3; 3] {
    let tr = d.x + d.y + d.z;
    let col = |x: Vec3| (x * tr - spread_mul(d, o, x)) * b - n.cross(spread_mul(d, o, n.cross(x))) * (a - b);
    [col(Vec3::X), col(Vec3::Y), col(Vec3::Z)]
}


/// A hand box apart from a piece (`ly`: the piece's point `y` nearest the box, in the box frame,
/// outside it): the gap between y and the box's point nearest it as a negative depth, along the line
/// between them (a speculative contact, as a capsule's; the projections overestimate the gap,
/// never underestimate it). Depth −1 when they touch at y (no direction).
pub fn box_gap_contact(h: Vec3, ly: Vec3, y: Vec3) -> (f32, Vec3, Vec3) {
    let d = ly.clamp(-h, h) - ly;
    let gap = d.length();
    if gap > 1e-9 {
        return (-gap, d / gap, y);
    }
    (-1.0, Vec3::Z, y)
}

/// Support point `k` of piece `pd` in a hand box's frame (`inv`: the box's rotation in the piece
/// frame, inverted; `c_o`: its centre there) and its radius (a hull's vertices and a box's corners
/// have none).
pub fn box_frame_support(m: &Model, pd: &PieceDesc, scale: f32, size: Vec3, inv: Vec4, c_o: Vec3, k: u32) -> (Vec3, f32) {
    let (sp, r) = piece_support_point(m, pd, scale, size, k);
    (quat_rotate(inv, sp - c_o), r)
}

/// Support point `k` of piece `pd` in its own frame (scaled `size`, its hull scaled by `scale`) and
/// its radius: a primitive's (`object_support_point`), or a hull's vertex (no radius).
pub fn piece_support_point(m: &Model, pd: &PieceDesc, scale: f32, size: Vec3, k: u32) -> (Vec3, f32) {
    if pd.shape == SHAPE_HULL { (hull_vertex(m, pd, scale, k), 0.0) } else { object_support_point(pd.shape, size, k) }
}

/// Narrow phase between hand collider `ci` and the table (its lowest point).
pub fn collide_hand_table(m: &Model, s: &Scratch, ci: usize) -> Contact {
    let (cpos, crot) = collider_pose(m, s, ci);
    collide_hand_table_at(m, ci, cpos, crot)
}

/// `collide_hand_table` with the collider at `cpos`, `crot`.
pub fn collide_hand_table_at(m: &Model, ci: usize, cpos: Vec3, crot: Vec4) -> Contact {
    let cd = &m.colliders[ci];
    let mut low = cpos;
    let mut r = cd.size[0];
    if cd.shape == SHAPE_CAPSULE {
        let axis = quat_rotate(crot, Vec3::new(0.0, 0.0, cd.size[1]));
        low = if axis.z > 0.0 { cpos - axis } else { cpos + axis };
    } else if cd.shape == SHAPE_BOX {
        r = 0.0;
        for k in 0..8u32 {
            let (corner, _) = object_support_point(SHAPE_BOX, v3(cd.size), k);
            let w = cpos + quat_rotate(crot, corner);
            if w.z < low.z || k == 0 {
                low = w;
            }
        }
    }
    contact_at(r - low.z, Vec3::Z, Vec3::new(low.x, low.y, 0.0))
}

/// Narrow phase between support point `k` of object piece `pd` (scaled `size`, its hull scaled by
/// `scale`, at `ppos`, `prot`) and the table: a primitive's support points, a hull's vertices.
pub fn collide_piece_table(m: &Model, pd: &PieceDesc, scale: f32, size: Vec3, ppos: Vec3, prot: Vec4, k: u32) -> Contact {
    let (local, r) = piece_support_point(m, pd, scale, size, k);
    let w = ppos + quat_rotate(prot, local);
    contact_at(r - w.z, Vec3::Z, Vec3::new(w.x, w.y, 0.0))
}

/// Penalty contact force on the first body, the new tangential spring, and the tangential damping
/// the object's implicit solve uses for this contact. `vrel`: velocity of the first body relative to
/// the second at the contact point. Returns (force, spring, tangential damping).
///
/// Sticking, the tangential force −kt·(s + vt·h) − c·vt has the damping kt·h + c. Sliding, the force
/// μ·Fn opposing the slip is treated as the damper μ·Fn/|vt|, so that the implicit solve can bring the
/// slip to rest but never reverse it within a substep (explicit sliding friction chatters on light objects).
#[allow(clippy::too_many_arguments)]
pub fn contact_force(c: &Contact, vrel: Vec3, anchor: Vec3, k: f32, kt: f32, damp: f32, mu: f32, h: f32) -> (Vec3, Vec3, f32) {
    let n = c.normal;
    let vn = vrel.dot(n);
    let vt = vrel - n * vn;
    // Fn = max(k·depth − c·vn, 0)
    let fn_ = (k * c.depth - damp * vn).max(0.0);
    if fn_ <= 0.0 {
        return (Vec3::ZERO, Vec3::ZERO, 0.0);
    }
    // spring kept in the tangent plane, stretched by the tangential slip: s ← s − (s·n)n + vt h
    let spring = anchor - n * anchor.dot(n) + vt * h;
    // Ft = −kt s − ct vt, with ct = c
    let ft = -kt * spring - damp * vt;
    let ft_len = ft.length();
    let limit = mu * fn_;
    if ft_len > limit {
        // sliding: the friction force sits on the cone and the spring carries it
        let f_slide = ft * (limit / ft_len);
        let vt_len = vt.length();
        let b = if vt_len > 1e-6 { (limit / vt_len).min(kt * h + damp) } else { kt * h + damp };
        return (n * fn_ + f_slide, -f_slide / kt, b);
    }
    (n * fn_ + ft, spring, kt * h + damp)
}

/// Torsional friction of a contact patch of radius `radius`: a torque on the first body opposing the
/// relative spin about the normal, up to μ·Fn·radius, regularised as a damper below `TORSION_EPS`.
/// Returns (torque, its damping coefficient for the object's implicit solve).
pub fn torsion_torque(n: Vec3, w_rel: Vec3, fn_: f32, mu: f32, radius: f32) -> (Vec3, f32) {
    let wn = w_rel.dot(n);
    // b = μ Fn r / max(|ω·n|, ε);  τ = −b (ω·n) n
    let b = mu * fn_ * radius / wn.abs().max(TORSION_EPS);
    (n * (-b * wn), b)
}

/// The hand's mass and its rotational inertia about the wrist, as the wrist moves (the arm's added
/// mass and inertia included).
pub fn wrist_mass_inertia(p: &EnvParams, g: &Globals) -> (f32, f32) {
    (g.hand_mass * p.hand_mass_scale + g.wrist_added_mass, g.hand_inertia * p.hand_mass_scale + g.wrist_added_inertia)
}

/// The coordinate that moves joint `j` (itself, or its mimic leader) and its multiplier.
pub fn joint_lead(m: &Model, j: usize) -> (usize, f32) {
    let jd = &m.joints[j];
    if jd.mimic_leader != NO_JOINT { (jd.mimic_leader as usize, jd.mimic_mult) } else { (j, 1.0) }
}

/// A joint coordinate's inertia as a contact impulse meets it this substep: I + h·d (armature, link
/// inertia about the axis, and the implicit joint damping of `integrate_hand`:
/// Δq̇ = h·τ / (I + h·d)).
pub fn joint_impulse_inertia(p: &EnvParams, m: &Model, j: usize, h: f32) -> f32 {
    let jd = &m.joints[j];
    jd.armature + jd.link_inertia * p.hand_mass_scale + h * jd.damping * p.kd_scale
}

/// Applies a force on hand link `l` at world point `x` for this substep: the velocity changes it
/// makes join the hand's (`Scratch::dqd`, `wrist_dv`, `wrist_dw`), so the contacts solved after it
/// see it (one Gauss–Seidel sweep over the hand's contacts):
/// Δq̇_L += h·m_j·aⱼ·((x − oⱼ) × F) / (I_L + h·d_L) up the chain (L: the joint's coordinate, m_j
/// its multiplier), Δv_w += h·F / m_w, Δω_w += h·(x − p_w) × F / I_w.
pub fn apply_hand_force(p: &EnvParams, m: &Model, s: &mut Scratch, l: usize, x: Vec3, f: Vec3, h: f32) {
    let (mass, inertia) = wrist_mass_inertia(p, m.g);
    s.wrist_dv += f * (h / mass);
    s.wrist_dw += (x - s.link_pos[0]).cross(f) * (h / inertia);
    let mut link = l;
    while link > 0 {
        let j = link - 1;
        let (lj, mult) = joint_lead(m, j);
        let tq = s.joint_axis[j].dot((x - s.link_pos[link]).cross(f));
        s.dqd[lj] += h * mult * tq / joint_impulse_inertia(p, m, lj, h);
        link = m.joints[j].parent_link as usize;
    }
}

/// Applies a torque on hand link `l` for this substep (as `apply_hand_force`):
/// Δq̇_L += h·m_j·aⱼ·T / (I_L + h·d_L) up the chain, Δω_w += h·T / I_w.
pub fn apply_hand_torque(p: &EnvParams, m: &Model, s: &mut Scratch, l: usize, tq: Vec3, h: f32) {
    let (_, inertia) = wrist_mass_inertia(p, m.g);
    s.wrist_dw += tq * (h / inertia);
    let mut link = l;
    while link > 0 {
        let j = link - 1;
        let (lj, mult) = joint_lead(m, j);
        s.dqd[lj] += h * mult * s.joint_axis[j].dot(tq) / joint_impulse_inertia(p, m, lj, h);
        link = m.joints[j].parent_link as usize;
    }
}

/// The change this substep of the velocity of point `x` (world) on hand link `l`, from the servos
/// and the contacts applied so far: Δv = Δv_w + Δω_w × (x − p_w) + Σ_chain m_j·Δq̇_L·aⱼ × (x − oⱼ).
pub fn hand_point_velocity_change(m: &Model, s: &Scratch, l: usize, x: Vec3) -> Vec3 {
    let mut dv = s.wrist_dv + s.wrist_dw.cross(x - s.link_pos[0]);
    let mut link = l;
    while link > 0 {
        let j = link - 1;
        let (lj, mult) = joint_lead(m, j);
        dv += s.joint_axis[j].cross(x - s.link_pos[link]) * (mult * s.dqd[lj]);
        link = m.joints[j].parent_link as usize;
    }
    dv
}

/// The hand's mobility (1/kg: velocity change per unit impulse) at world point `x` on link `l`, as
/// `apply_hand_force` moves the hand, along the unit normal `n` and summed over all directions
/// (the trace: its part in the tangent plane, trace − w_n, bounds the mobility along any tangent):
/// w_u = 1/m_w + |(x − p_w) × u|²/I_w + Σ_L (J_L·u)²/(I_L + h·d_L),
/// J_L = Σ_{k in chain, lead(k) = L} m_k · a_k × (x − o_k). Returns (w_n, trace).
pub fn hand_mobility(p: &EnvParams, m: &Model, s: &Scratch, l: usize, x: Vec3, n: Vec3, h: f32) -> (f32, f32) {
    let (mass, inertia) = wrist_mass_inertia(p, m.g);
    let r0 = x - s.link_pos[0];
    let rn = r0.cross(n);
    // the wrist: translation along u, rotation about the wrist
    let (wrist_n, wrist_tr) = (1.0 / mass + rn.dot(rn) / inertia, 3.0 / mass + 2.0 * r0.dot(r0) / inertia);
    let (mut w_n, mut w_tr) = (wrist_n, wrist_tr);
    // no follower on the chain (the common case): every joint is its own coordinate, J_j = a_j × r
    let mut link = l;
    let mut coupled = false;
    while link > 0 {
        let j = link - 1;
        if m.joints[j].mimic_leader != NO_JOINT {
            coupled = true;
            break;
        }
        let jac = s.joint_axis[j].cross(x - s.link_pos[link]);
        let inv_i = 1.0 / joint_impulse_inertia(p, m, j, h);
        w_n += jac.dot(n) * jac.dot(n) * inv_i;
        w_tr += jac.dot(jac) * inv_i;
        link = m.joints[j].parent_link as usize;
    }
    if !coupled {
        return (w_n, w_tr);
    }
    (w_n, w_tr) = (wrist_n, wrist_tr);
    let mut link = l;
    while link > 0 {
        let j = link - 1;
        let (lj, _) = joint_lead(m, j);
        // J_L over the whole chain, counted once: at the chain joint nearest the tip that L moves
        let mut first = true;
        let mut jac = Vec3::ZERO;
        let mut k_link = l;
        while k_link > 0 {
            let k = k_link - 1;
            let (lk, mult) = joint_lead(m, k);
            if lk == lj {
                if k_link > link {
                    first = false;
                }
                jac += s.joint_axis[k].cross(x - s.link_pos[k_link]) * mult;
            }
            k_link = m.joints[k].parent_link as usize;
        }
        if first {
            let inv_i = 1.0 / joint_impulse_inertia(p, m, lj, h);
            w_n += jac.dot(n) * jac.dot(n) * inv_i;
            w_tr += jac.dot(jac) * inv_i;
        }
        link = m.joints[j].parent_link as usize;
    }
    (w_n, w_tr)
}

/// A hand contact's force, solved implicitly on the hand's side (the hand is integrated explicitly,
/// so an explicit spring on a light finger would ring). `vrel`: the hand point's velocity relative
/// to the other body now; `dv`: its change this substep from the servos and the contacts solved
/// before (`hand_point_velocity_change`); `w_n`, `w_t`: the hand's mobility along the normal and
/// its bound along any tangent (`hand_mobility`). With K = k·h + c and the end-of-substep relative
/// velocity v' = vrel + dv + h·w·F, the force is the spring–damper's at the end of the substep:
///   Fn = k·(d − h·v'n) − c·v'n  ⇒  Fn = (k·d − K·(vrel + dv)·n) / (1 + h·w_n·K),
///   Ft = −kt·(s + h·v't) − c·v't  ⇒  Ft = −(kt·s + Kt·(vrel + dv)t) / (1 + h·w_t·Kt),
/// with s the tangential spring after this substep's slip (as `contact_force`) and Ft limited to
/// μ·Fn (sliding). At rest Fn = k·d whatever k; a gap (d < 0) closing within the substep pushes
/// already (a speculative contact), so a fast finger stops at the surface instead of a substep's
/// travel inside it. Returns (force, spring, the object's normal and tangential damping: the force's
/// derivative with respect to the other body's velocity).
#[allow(clippy::too_many_arguments)]
pub fn hand_contact_force(c: &Contact, vrel: Vec3, dv: Vec3, anchor: Vec3, k: f32, kt: f32, damp: f32, mu: f32, h: f32, w_n: f32, w_t: f32) -> (Vec3, Vec3, f32, f32) {
    let n = c.normal;
    let vp = vrel + dv;
    let vn = vp.dot(n);
    let kn = k * h + damp;
    // Fn = (k·d − K·vn) / (1 + h·w_n·K)
    let fn_ = ((k * c.depth - kn * vn) / (1.0 + h * w_n * kn)).max(0.0);
    if fn_ <= 0.0 {
        return (Vec3::ZERO, Vec3::ZERO, 0.0, 0.0);
    }
    let a = kn / (1.0 + h * w_n * kn);
    // spring kept in the tangent plane, stretched by the slip now: s ← s − (s·n)n + vt h
    let vt_now = vrel - n * vrel.dot(n);
    let spring = anchor - n * anchor.dot(n) + vt_now * h;
    let vt = vp - n * vn;
    let ktn = kt * h + damp;
    // Ft = −(kt·s + Kt·vt) / (1 + h·w_t·Kt)
    let ft = -(spring * kt + vt * ktn) / (1.0 + h * w_t * ktn);
    let b_stick = ktn / (1.0 + h * w_t * ktn);
    let ft_len = ft.length();
    let limit = mu * fn_;
    if ft_len > limit {
        // sliding: the friction force sits on the cone and the spring carries it
        let f_slide = ft * (limit / ft_len);
        let vt_len = vt.length();
        let b = if vt_len > 1e-6 { (limit / vt_len).min(b_stick) } else { b_stick };
        return (n * fn_ + f_slide, -f_slide / kt, a, b);
    }
    (n * fn_ + ft, spring, a, b_stick)
}

/// Adds a torque on the object and its implicit rotational damping b·nnᵀ.
pub fn apply_object_torque(s: &mut Scratch, tq: Vec3, n: Vec3, b: f32) {
    s.obj_t += tq;
    for row in 0..3 {
        for col in 0..3 {
            s.obj_d[(3 + row) * 6 + 3 + col] += b * n[row] * n[col];
        }
    }
}

/// Adds a manifold's resistance to turning `e` (`spread_matrix`, its columns) to the object's
/// implicit damping, and its linearisation E·`dw` about the velocities the force was solved
/// against to the object's torque.
pub fn apply_object_spread(s: &mut Scratch, e: &[Vec3; 3], dw: Vec3) {
    s.obj_t += e[0] * dw.x + e[1] * dw.y + e[2] * dw.z;
    for col in 0..3 {
        for row in 0..3 {
            s.obj_d[(3 + row) * 6 + 3 + col] += e[col][row];
        }
    }
}

/// Adds a contact force `f` at world point `x` on the object (centre of mass `com`), and its
/// implicit damping D = a nnᵀ + b (I − nnᵀ) mapped through J = [I, −[r]×]: Σ Jᵀ D J.
pub fn apply_object_force(com: Vec3, s: &mut Scratch, x: Vec3, f: Vec3, n: Vec3, a: f32, b: f32) {
    let r = x - com;
    s.obj_f += f;
    s.obj_t += r.cross(f);
    // D columns: D e_i = b e_i + (a − b) n n_i
    let mut dm = [Vec3::ZERO; 3];
    for i in 0..3 {
        let mut e = Vec3::ZERO;
        e[i] = 1.0;
        dm[i] = e * b + n * ((a - b) * n[i]);
    }
    // JᵀDJ with Jᵀ = [I; [r]×], column by column:
    // A_vv = D, A_vw = −D[r]×, A_wv = [r]× D, A_ww = −[r]× D [r]×
    for i in 0..3 {
        let mut e = Vec3::ZERO;
        e[i] = 1.0;
        let d_col = dm[i]; // D e_i
        let rd_col = r.cross(d_col); // [r]× D e_i
        // column i of D[r]× is D (r × e_i)
        let rxe = r.cross(e);
        let drx_col = dm[0] * rxe.x + dm[1] * rxe.y + dm[2] * rxe.z; // D (r × e_i)
        let rdrx_col = r.cross(drx_col); // [r]× D [r]× e_i
        for row in 0..3 {
            s.obj_d[row * 6 + i] += d_col[row];
            s.obj_d[row * 6 + 3 + i] -= drx_col[row];
            s.obj_d[(3 + row) * 6 + i] += rd_col[row];
            s.obj_d[(3 + row) * 6 + 3 + i] -= rdrx_col[row];
        }
    }
}

/// Solves hand contact `c` on link `l` against a body whose contact point moves at `v_other`, with
/// the spring in slot `slot` (xyz: the tangential spring, w: 1 while the pair touches): the force
/// on the hand (applied to it for the contacts after), and the object's damping (a, b): the object
/// meets the force in its own implicit solve. Only the hand's mobility enters the hand's solve, so
/// that at rest Fn = k·d (with the object's as well, a held object, which its other contacts keep
/// still, would sink in further by h²·w_o·Fn). A pair whose solve gives no push gets no force and its
/// spring is cleared.
#[allow(clippy::too_many_arguments)]
pub fn solve_hand_contact(p: &EnvParams, m: &Model, s: &mut Scratch, springs: &mut [[f32; 4]], slot: usize, l: usize, c: &Contact, v_other: Vec3, damp: f32, mu: f32, h: f32) -> (Vec3, f32, f32) {
    let (f, spring, a, b) = solve_hand_contact_from(p, m, s, v3(springs[slot]), l, c, v_other, damp, mu, h);
    springs[slot] = hand_spring_after(c, f, spring);
    (f, a, b)
}

/// `solve_hand_contact` from the tangential spring `anchor`, leaving the spring slots alone: the
/// force (applied to the hand when it pushes), the tangential spring it leaves, the object's
/// damping (a, b). The pair's spring, where it has one, is the caller's to keep.
#[allow(clippy::too_many_arguments)]
pub fn solve_hand_contact_from(p: &EnvParams, m: &Model, s: &mut Scratch, anchor: Vec3, l: usize, c: &Contact, v_other: Vec3, damp: f32, mu: f32, h: f32) -> (Vec3, Vec3, f32, f32) {
    let g = m.g;
    let vrel = link_point_velocity(s, l, c.point) - v_other;
    let dv = hand_point_velocity_change(m, s, l, c.point);
    // a manifold of point springs in parallel: their stiffness, friction spring and damping add up
    let n_s = c.spring_count;
    // no push where `hand_contact_force`'s Fn has a numerator k·d − K·vn ≤ 0 (its denominator is
    // positive): the same zero force without the hand's mobility (CPU only; the same arithmetic)
    let (k_s, damp_s) = (g.hand_contact_k * n_s, damp * n_s);
    if k_s * c.depth - (k_s * h + damp_s) * (vrel + dv).dot(c.normal) <= 0.0 {
        return (Vec3::ZERO, Vec3::ZERO, 0.0, 0.0);
    }
    let (w_n, w_tr) = hand_mobility(p, m, s, l, c.point, c.normal, h);
    let (f, spring, a, b) = hand_contact_force(c, vrel, dv, anchor, k_s, g.hand_contact_kt * n_s, damp_s, mu, h, w_n, w_tr - w_n);
    if f.dot(c.normal) > 0.0 {
        apply_hand_force(p, m, s, l, c.point, f, h);
    }
    (f, spring, a, b)
}

/// What a hand contact's spring slot keeps once contact `c` is solved to force `f` leaving the
/// tangential spring `spring`: the spring while it pushes (w: 1, touching); else none, still
/// flagged as touching where `c` is in (separating without pushing).
pub fn hand_spring_after(c: &Contact, f: Vec3, spring: Vec3) -> [f32; 4] {
    if f.dot(c.normal) > 0.0 {
        [spring.x, spring.y, spring.z, 1.0]
    } else {
        [0.0, 0.0, 0.0, if c.depth > 0.0 { 1.0 } else { 0.0 }]
    }
}

/// The object's side of hand–object contact `c` of collider `ci` (force `f` on the hand, the
/// object's normal and tangential damping `a`, `b` from `solve_hand_contact`), its torsional
/// friction (against the object's spin `w_obj`), and the statistics. `dv_point`, `dw`: how far the
/// velocities the force was solved against (the object's predicted ones) are from its present
/// ones; the damping times them joins the force, so that the object's implicit solve, which starts
/// from the present velocities, linearises the force about the predicted ones. (The penetration
/// statistics are the pair's overlap, `contacts_and_forces`.)
#[allow(clippy::too_many_arguments)]
pub fn hand_object_force(p: &EnvParams, m: &Model, s: &mut Scratch, h: f32, ci: usize, c: &Contact, f: Vec3, a: f32, b: f32, ocom: Vec3, w_obj: Vec3, dv_point: Vec3, dw: Vec3, mu: f32, on_contact: &mut impl FnMut(ContactKind, usize, &Contact, Vec3)) {
    let g = m.g;
    let l = m.colliders[ci].link as usize;
    let n = c.normal;
    let fn_ = f.dot(n);
    if fn_ > 0.0 {
        // D·δv with D = a nnᵀ + b (I − nnᵀ): the force's change as the object's velocity goes back to its present one
        let dvn = dv_point.dot(n);
        let lin = n * (a * dvn) + (dv_point - n * dvn) * b;
        apply_object_force(ocom, s, c.point, lin - f, n, a, b);
        if c.spring_count > 1.0 {
            // a manifold's points resist the object's turning about their centre, linearised as
            // the force: + E·δω
            let e = spread_matrix(c.spread_diag, c.spread_off, n, a, b);
            apply_object_spread(s, &e, dw);
        }
        let (tq, br) = torsion_torque(n, s.link_w[l] - w_obj, fn_, mu, g.torsion_radius);
        apply_hand_torque(p, m, s, l, tq, h);
        // the torsion's damping, linearised likewise: + b_r n (n·δω)
        apply_object_torque(s, n * (br * n.dot(dw)) - tq, n, br);
        if (s.n_reactions as usize) < MAX_REACTIONS {
            s.reactions[s.n_reactions as usize] = Reaction { link: l as u32, point: c.point, normal: n, a, b, br, dv0: dv_point, dw0: dw, spring_count: c.spring_count, spread_diag: c.spread_diag, spread_off: c.spread_off, collider: ci as u32, depth: c.depth };
            s.n_reactions += 1;
        }
        s.link_contact[l / 32] |= 1 << (l % 32);
        let tip = m.colliders[ci].tip;
        if tip != NO_JOINT {
            s.tip_force[tip as usize] += fn_;
        }
    }
    if fn_ > 0.0 || c.depth > 0.0 {
        s.contacts += 1;
        s.contacts_ho += 1;
        on_contact(ContactKind::HandObject, ci, c, f);
    }
}

/// The first collider of bit list `list` (bit ci % 32 of word ci / 32) from word `word` on, taken
/// off the list (`word` left at its word); `None` once it is empty. The shader walks its passes'
/// lists so, to post their queries and to solve their pairs in this file's order.
#[inline(always)]
pub fn next_in_list(list: &mut [u32; REVISIT_WORDS], word: &mut usize) -> Option<usize> {
    while *word < REVISIT_WORDS && list[*word] == 0 {
        *word += 1;
    }
    let bits = *list.get(*word)?;
    // the lowest bit cleared
    list[*word] = bits & (bits - 1);
    Some(*word * 32 + bits.trailing_zeros() as usize)
}

/// Evaluates every contact of the substep: forces on hand and object, springs (`springs`: this
/// env's `[n_springs]` slots, see [`spring_slot`]), statistics. `on_contact` sees each contact
/// that touches or pushes, with the force on its first body (the hand; the object against the
/// table): the host's recordings take them from here (`env::contact_records`); the step passes a
/// closure that does nothing. Returns the object's velocities at the end of the substep when the
/// second pass predicted them and none of its pairs pushed (nothing its implicit solve reads has
/// changed since, so `object_velocity_change` would return them again).
#[allow(clippy::too_many_arguments)]
pub fn contacts_and_forces(st: &EnvState, springs: &mut [[f32; 4]], p: &EnvParams, m: &Model, s: &mut Scratch, h: f32, on_contact: &mut impl FnMut(ContactKind, usize, &Contact, Vec3)) -> Option<(Vec3, Vec3)> {
    let g = m.g;
    let k = g.contact_k;
    let kt = g.contact_kt;
    // the object's velocities are those of its centre of mass
    let ocom = object_com(st, p);
    let ovel = v3(st.obj_vel);
    let ow = v3(st.obj_angvel);
    let (opos, orot) = (v3(st.obj_pos), v4(st.obj_rot));
    let mu_ho = 0.5 * (p.hand_friction + p.obj_friction);
    let mu_ht = 0.5 * (p.hand_friction + p.table_friction);
    let mu_ot = 0.5 * (p.obj_friction + p.table_friction);
    let n_c = g.n_colliders;
    // hand–object pairs within the margin that did not push: solved again once the object's
    // velocity this substep is predicted (bit ci % 32 of word ci / 32)
    let mut revisit = [0u32; REVISIT_WORDS];
    // the first REVISIT_CACHE of those pairs' contacts and margins, in collider order: the link
    // poses do not change within the substep, so the second pass's narrow phase would find them
    // again (the shader keeps every pair's contact and margin in its narrow-phase rounds' slots)
    let mut cached = [(Contact::default(), 0.0f32); REVISIT_CACHE];
    let mut n_cached = 0usize;
    // the object's frame at the end of the substep, found by the pass's first swept search
    let mut obj_end = None;
    for ci in 0..g.n_colliders as usize {
        let (sho, sht) = (spring_slot::hand_object(ci as u32) as usize, spring_slot::hand_table(n_c, ci as u32) as usize);
        let cd = &m.colliders[ci];
        let l = cd.link as usize;
        let r_c = bounding_radius(cd.shape, v3(cd.size));
        // the collider's pose once for the margin, the narrow phase, the swept contact and the
        // table (as the shader); its turn only for a collider near the object or
        // the table (the rest find no contact: `collide_hand_object_at`'s first test, a depth
        // under −CONTACT_MARGIN against the table)
        let cpos = collider_centre(m, s, ci);
        let margin = speculative_margin_at(m, s, ci, cpos, h, ocom, ovel, ow);
        let near_object = object_in_reach(p, cd, cpos, opos, margin);
        // the collider's lowest point is at least r_c below its centre: a 1 mm allowance over
        // the margin for the rounding of `collide_hand_table_at`
        let near_table = g.hand_table != 0 && cpos.z <= r_c + CONTACT_MARGIN + 1.0e-3;
        let crot = if near_object || near_table { collider_rotation(m, s, ci) } else { Vec4::W };
        // hand–object: a touching pair, or one apart by less than the speculative margin (at the
        // end of the substep where the object's turn brings a feature in elsewhere)
        if near_object {
            let raw = collide_hand_object_at(p, m, ci, cpos, crot, opos, orot, margin);
            let c = swept_contact_at(st, p, m, s, ci, cpos, crot, raw, h, ocom, ovel, ow, margin, &mut obj_end);
            // the penetration the statistics record: the pair's overlap at the substep's poses,
            // not a swept contact's depth (where the pair would be by the substep's end if
            // nothing pushed, taken back along the motion: not a pose the env reaches)
            s.max_pen_ho = s.max_pen_ho.max(raw.depth);
            s.max_pen = s.max_pen.max(raw.depth);
            if c.depth > -margin {
                let (f, a, b) = solve_hand_contact(p, m, s, springs, sho, l, &c, ovel + ow.cross(c.point - ocom), p.obj_contact_c, mu_ho, h);
                if f.dot(c.normal) > 0.0 {
                    hand_object_force(p, m, s, h, ci, &c, f, a, b, ocom, ow, Vec3::ZERO, Vec3::ZERO, mu_ho, on_contact);
                } else {
                    revisit[ci / 32] |= 1 << (ci % 32);
                    if n_cached < REVISIT_CACHE {
                        cached[n_cached] = (raw, margin);
                        n_cached += 1;
                    }
                }
            } else {
                springs[sho] = [0.0; 4];
            }
        } else {
            springs[sho] = [0.0; 4];
        }
        // hand–table
        if near_table {
            let c = collide_hand_table_at(m, ci, cpos, crot);
            if c.depth > -CONTACT_MARGIN {
                let (f, _, _) = solve_hand_contact(p, m, s, springs, sht, l, &c, Vec3::ZERO, p.hand_table_c, mu_ht, h);
                if f.dot(c.normal) > 0.0 || c.depth > 0.0 {
                    s.contacts += 1;
                    s.max_pen = s.max_pen.max(c.depth);
                    on_contact(ContactKind::HandTable, ci, &c, f);
                }
            } else {
                springs[sht] = [0.0; 4];
            }
        } else if g.hand_table != 0 {
            springs[sht] = [0.0; 4];
        }
    }
    // object–table: every support point of every piece, in order (spring slots 0.. of the object);
    // a piece whose bounding sphere is above the table has none touching (its springs are cleared)
    let od = &m.objects[p.obj_index as usize];
    let mut kp = 0u32;
    let above = st.obj_pos[2] > p.obj_com[3];
    for pi in 0..od.n_pieces {
        let pd = &m.pieces[(od.first_piece + pi) as usize];
        let (ppos, prot, size) = if above { (Vec3::Z, Vec4::W, Vec3::ZERO) } else { piece_pose(st, p, pd) };
        if above || ppos.z > pd.pos[3] * p.obj_scale {
            for _ in 0..pd.n_support {
                springs[spring_slot::object_table(n_c, kp) as usize] = [0.0; 4];
                kp += 1;
            }
            continue;
        }
        for j in 0..pd.n_support {
            let ki = spring_slot::object_table(n_c, kp) as usize;
            let c = collide_piece_table(m, pd, p.obj_scale, size, ppos, prot, j);
            if c.depth > 0.0 {
                let vo = ovel + ow.cross(c.point - ocom);
                let (f, spring, b) = contact_force(&c, vo, v3(springs[ki]), k, kt, p.obj_contact_c, mu_ot, h);
                springs[ki] = [spring.x, spring.y, spring.z, 1.0];
                let a = if f.dot(c.normal) > 0.0 { k * h + p.obj_contact_c } else { 0.0 };
                apply_object_force(ocom, s, c.point, f, c.normal, a, b);
                let (tq, br) = torsion_torque(c.normal, ow, f.dot(c.normal), mu_ot, g.torsion_radius);
                apply_object_torque(s, tq, c.normal, br);
                s.contacts += 1;
                s.max_pen = s.max_pen.max(c.depth);
                on_contact(ContactKind::ObjectTable, kp as usize, &c, f);
            } else {
                springs[ki] = [0.0; 4];
            }
            kp += 1;
        }
    }
    // the second pass: the pairs that did not push, against the object's velocity at the end of the
    // substep as the forces so far make it (a finger's push can throw a light object into another
    // link within the substep, which a pair solved against the object's velocity now cannot see)
    if revisit.iter().any(|&w| w != 0) {
        let (vel_p, w_p) = object_velocity_change(st, p, m, s, h);
        let mut pushed = false;
        let mut n_seen = 0usize;
        let mut obj_end_p = None;
        let mut word = 0;
        while let Some(ci) = next_in_list(&mut revisit, &mut word) {
            let l = m.colliders[ci].link as usize;
            // past the cache, the first pass's margin again (from the present velocities): the
            // same raw contact
            let (cpos, crot) = collider_pose(m, s, ci);
            let (raw, margin) = if n_seen < n_cached {
                cached[n_seen]
            } else {
                let margin = speculative_margin_at(m, s, ci, cpos, h, ocom, ovel, ow);
                (collide_hand_object_at(p, m, ci, cpos, crot, opos, orot, margin), margin)
            };
            n_seen += 1;
            let c = swept_contact_at(st, p, m, s, ci, cpos, crot, raw, h, ocom, vel_p, w_p, margin, &mut obj_end_p);
            let v_other = vel_p + w_p.cross(c.point - ocom);
            let (f, a, b) = solve_hand_contact(p, m, s, springs, spring_slot::hand_object(ci as u32) as usize, l, &c, v_other, p.obj_contact_c, mu_ho, h);
            // the object's force is linearised about the predicted velocity, not the present one:
            // F(u) = F(u_p) − D·J·(u − u_p) = [F(u_p) + D·J·(u_p − u₀)] − D·J·(u − u₀)
            let dv_point = (vel_p - ovel) + (w_p - ow).cross(c.point - ocom);
            hand_object_force(p, m, s, h, ci, &c, f, a, b, ocom, w_p, dv_point, w_p - ow, mu_ho, on_contact);
            pushed = pushed || f.dot(c.normal) > 0.0;
        }
        if !pushed {
            return Some((vel_p, w_p));
        }
    }
    None
}

/// The servos' part of the substep, before the contacts: each independent finger joint's velocity
/// change from its servo (PD within the effort limit, Coulomb friction, implicit joint damping) and
/// the wrist's from its controller, into `Scratch::dqd`, `wrist_dv`, `wrist_dw`. The hand's
/// contacts are solved against these (`hand_contact_force`) and add their own.
pub fn hand_servo(st: &EnvState, p: &EnvParams, t: &Targets, m: &Model, s: &mut Scratch, h: f32) {
    let g = m.g;
    for j in 0..g.n_joints as usize {
        let jd = &m.joints[j];
        s.dqd[j] = 0.0;
        if jd.mimic_leader != NO_JOINT {
            continue;
        }
        let lo = jd.lower * p.limit_scale;
        let hi = jd.upper * p.limit_scale;
        let inertia = jd.armature + jd.link_inertia * p.hand_mass_scale;
        let qd = st.qd[j];
        let goal = t.q[j].clamp(lo, hi);
        // τ_pd = clamp(kp (q* − q) − kd q̇, ±effort)
        let tau_pd = (jd.kp * p.kp_scale * (goal - st.q[j]) - jd.kd * p.kd_scale * qd).clamp(-jd.effort, jd.effort);
        // Coulomb friction, regularised over 0.01 rad/s
        let tau_f = -jd.friction * (qd / 0.01).clamp(-1.0, 1.0);
        // joint damping implicit: q̇' = (q̇ + h τ / I) / (1 + h d / I)
        s.dqd[j] = (qd + h * (tau_pd + tau_f) / inertia) / (1.0 + h * jd.damping * p.kd_scale / inertia) - qd;
    }
    // wrist: F = clamp(kp (p* − p) − kd v, Fmax); the hand's weight is compensated
    let (mass, inertia) = wrist_mass_inertia(p, g);
    let vel = v3(st.wrist_vel);
    let w = v3(st.wrist_angvel);
    let f_pd = clamp_norm(g.wrist_kp_lin * (v3(t.wrist_pos) - v3(st.wrist_pos)) - g.wrist_kd_lin * vel, g.wrist_force_limit);
    let t_pd = clamp_norm(g.wrist_kp_rot * quat_error(v4(t.wrist_rot), v4(st.wrist_rot)) - g.wrist_kd_rot * w, g.wrist_torque_limit);
    s.wrist_dv = f_pd * (h / mass);
    s.wrist_dw = t_pd * (h / inertia);
}

/// Finger joints and wrist: their velocities change by what the servos and contacts made of
/// `Scratch::dqd`, `wrist_dv`, `wrist_dw`; then the speed and position limits, positions, followers.
pub fn integrate_hand(st: &mut EnvState, p: &EnvParams, m: &Model, s: &Scratch, h: f32) {
    let g = m.g;
    let n = g.n_joints as usize;
    for j in 0..n {
        let jd = &m.joints[j];
        if jd.mimic_leader != NO_JOINT {
            continue;
        }
        let lo = jd.lower * p.limit_scale;
        let hi = jd.upper * p.limit_scale;
        let mut qd = (st.qd[j] + s.dqd[j]).clamp(-jd.velocity, jd.velocity);
        let mut qn = st.q[j] + h * qd;
        if qn < lo {
            qn = lo;
            qd = qd.max(0.0);
        }
        if qn > hi {
            qn = hi;
            qd = qd.min(0.0);
        }
        st.q[j] = qn;
        st.qd[j] = qd;
    }
    for j in 0..n {
        let jd = &m.joints[j];
        if jd.mimic_leader != NO_JOINT {
            let l = jd.mimic_leader as usize;
            st.q[j] = jd.mimic_mult * st.q[l] + jd.mimic_offset;
            st.qd[j] = jd.mimic_mult * st.qd[l];
        }
    }
    let vel_n = v3(st.wrist_vel) + s.wrist_dv;
    let w_n = v3(st.wrist_angvel) + s.wrist_dw;
    st.wrist_vel = put3(vel_n);
    st.wrist_angvel = put3(w_n);
    st.wrist_pos = put3(v3(st.wrist_pos) + vel_n * h);
    st.wrist_rot = quat_integrate(v4(st.wrist_rot), w_n, h).to_array();
}

/// Solves A x = b for a symmetric positive definite 6×6 A (row-major) by Cholesky. Every loop
/// runs over 0..6 with its bound as a test inside, so that the compiler unrolls them all and keeps
/// L in registers (the same operations in the same order as loops to i and j: the shader's twin).
pub fn solve6(a: &[f32; 36], b: [f32; 6]) -> [f32; 6] {
    let mut l = [0.0f32; 36];
    for i in 0..6 {
        for j in 0..6 {
            if j > i {
                continue;
            }
            let mut sum = a[i * 6 + j];
            for k in 0..6 {
                if k < j {
                    sum -= l[i * 6 + k] * l[j * 6 + k];
                }
            }
            if i == j {
                l[i * 6 + i] = sum.max(1e-20).sqrt();
            } else {
                l[i * 6 + j] = sum / l[j * 6 + j];
            }
        }
    }
    let mut y = [0.0f32; 6];
    for i in 0..6 {
        let mut sum = b[i];
        for k in 0..6 {
            if k < i {
                sum -= l[i * 6 + k] * y[k];
            }
        }
        y[i] = sum / l[i * 6 + i];
    }
    let mut x = [0.0f32; 6];
    for ii in 0..6 {
        let i = 5 - ii;
        let mut sum = y[i];
        for k in 0..6 {
            if k > i {
                sum -= l[k * 6 + i] * x[k];
            }
        }
        x[i] = sum / l[i * 6 + i];
    }
    x
}

/// The world inertia R diag(ib) Rᵀ of principal moments `ib` in the principal frame `rot`: column c
/// is Σₖ ibₖ (rₖ)_c rₖ, rₖ the frame's axes.
pub fn world_inertia(rot: Vec4, ib: Vec3) -> Mat3 {
    let r = quat_axes(rot);
    let col = |c: usize| r[0] * (ib.x * r[0][c]) + r[1] * (ib.y * r[1][c]) + r[2] * (ib.z * r[2][c]);
    Mat3::from_cols(col(0), col(1), col(2))
}

/// The object's velocities at the end of the substep (centre-of-mass velocity, angular velocity)
/// under gravity and the contact forces so far, linearly implicit in its 6 velocities:
/// (M + h Σ JᵀDJ) Δu = h f, with the gyroscopic term applied first and kept energy-neutral.
pub fn object_velocity_change(st: &EnvState, p: &EnvParams, m: &Model, s: &Scratch, h: f32) -> (Vec3, Vec3) {
    let mass = p.obj_inertia[3];
    let ib = v3(p.obj_inertia);
    let rot = v4(st.obj_rot);
    // the principal frame in the world: R_obj R_principal
    let prot = quat_mul(rot, v4(m.objects[p.obj_index as usize].principal_rot));
    let com = object_com(st, p);
    let w = v3(st.obj_angvel);
    // the world inertia I and its inverse (the principal moments' reciprocals)
    let inertia = world_inertia(prot, ib);
    // gyroscopic: ω ← ω − h I⁻¹ (ω × Iω), rescaled so that ωᵀIω (the rotational energy) is unchanged
    let iw = inertia * w;
    let e0 = w.dot(iw);
    let mut wg = w - h * (world_inertia(prot, ib.recip()) * w.cross(iw));
    let e1 = wg.dot(inertia * wg);
    if e1 > 1e-20 {
        wg *= (e0 / e1).sqrt();
    }
    // A = M + h Σ JᵀDJ
    let mut a = [0.0f32; 36];
    for i in 0..36 {
        a[i] = h * s.obj_d[i];
    }
    for i in 0..3 {
        a[i * 6 + i] += mass;
        let col = inertia.col(i);
        for row in 0..3 {
            a[(3 + row) * 6 + 3 + i] += col[row];
        }
    }
    let gz = -(m.g.gravity + p.added_gravity) * mass;
    // the external force at its point of the object, and its moment about the centre of mass
    let ext = v3(p.ext_force);
    let at = v3(st.obj_pos) + quat_rotate(rot, v3(p.ext_point));
    let f = s.obj_f + ext + Vec3::new(0.0, 0.0, gz);
    let tq = s.obj_t + (at - com).cross(ext);
    let du = solve6(&a, [h * f.x, h * f.y, h * f.z, h * tq.x, h * tq.y, h * tq.z]);
    (v3(st.obj_vel) + Vec3::new(du[0], du[1], du[2]), wg + Vec3::new(du[3], du[4], du[5]))
}

/// The features that arrive at the pushing pairs under the object's solved velocities `vel_n`,
/// `w_n`: the pairs' contacts were found (and swept) against the object's velocities before the
/// forces of the substep, and a corner struck at the palm, a cube squeezed between a finger and
/// the palm, can change the object's spin within the substep so that another feature of the pair
/// — the next corner, the rest of the face — is pressed 1 mm in by the next substep. Each pair
/// that pushed, where the solved spin differs from the one it was found with by enough to bring
/// a feature `SWEPT_TOLERANCE` deeper than its own search or test allowed (so a feature may end up
/// to twice that deeper than the pair's contact predicts), is tested as `swept_test` tests it,
/// now against `vel_n`, `w_n`; where a feature
/// would end the substep deeper than the pair's contact by more than `SWEPT_TOLERANCE`, it joins
/// as a contact of its own (no friction spring: it starts from none), solved against the solved
/// velocities and linearised about them as the second pass's pairs are. Returns whether one
/// pushed: the object's velocity change is then solved again with it (`substep`).
#[allow(clippy::too_many_arguments)]
pub fn arriving_contacts(st: &EnvState, p: &EnvParams, m: &Model, s: &mut Scratch, h: f32, vel_n: Vec3, w_n: Vec3, on_contact: &mut impl FnMut(ContactKind, usize, &Contact, Vec3)) -> bool {
    let ocom = object_com(st, p);
    let (ovel, ow) = (v3(st.obj_vel), v3(st.obj_angvel));
    let mu_ho = 0.5 * (p.hand_friction + p.obj_friction);
    let mut obj_end = None;
    let mut pushed = false;
    // the pairs that pushed before this pass (those it adds are not looked at again)
    for i in 0..s.n_reactions as usize {
        let r = s.reactions[i];
        let (ci, l) = (r.collider as usize, r.link as usize);
        // the features' order by depth at the end of the substep changes with the object's turn
        // alone, by at most h·2r·|Δω| (Δω: the solved spin less the one the pair was found
        // with): its test or search then held every feature within SWEPT_TOLERANCE of its
        // contact, and where the change cannot add as much again nothing new arrives
        let cd = &m.colliders[ci];
        if h * 2.0 * bounding_radius(cd.shape, v3(cd.size)) * ((w_n - ow) - r.dw0).length() <= SWEPT_TOLERANCE {
            continue;
        }
        let c = contact_at(r.depth, r.normal, r.point);
        let Some(c_end) = swept_test(m, s, ci, &c, h, ocom, vel_n, w_n) else { continue };
        let (cpos, crot) = collider_pose(m, s, ci);
        let end = contact_at_end(st, p, m, s, ci, cpos, crot, h, ocom, vel_n, w_n, CONTACT_MARGIN, &mut obj_end);
        // a feature that would not be touching by the end of the substep needs no contact
        if end.depth <= 0.0 {
            continue;
        }
        let Some(x) = swept_end_contact(s, l, &end, c_end, h, ocom, vel_n, w_n) else { continue };
        let v_other = vel_n + w_n.cross(x.point - ocom);
        let (f, _, a, b) = solve_hand_contact_from(p, m, s, Vec3::ZERO, l, &x, v_other, p.obj_contact_c, mu_ho, h);
        // linearised about the solved velocities, as the second pass's pairs about the predicted ones
        let dv_point = (vel_n - ovel) + (w_n - ow).cross(x.point - ocom);
        hand_object_force(p, m, s, h, ci, &x, f, a, b, ocom, w_n, dv_point, w_n - ow, mu_ho, on_contact);
        pushed = pushed || f.dot(x.normal) > 0.0;
    }
    pushed
}

/// The hand's side of the object's implicit solve: at its velocity change Δu = (`vel_n` − v,
/// `w_n` − ω) the object took −(F + D·(J·Δu − δv₀)) from each pushing pair (`Reaction`), while the
/// hand took F as solved against the object's velocity then; each pair's link now takes the
/// difference, D·(J·Δu − δv₀) at the contact point and b_r·n·(n·Δω − n·δω₀) about the normal, so
/// that hand and object feel equal and opposite forces. Without it a cube squeezed by two light
/// fingertips at stiff contacts rattles between them and slips out (a finger is pushed back by the
/// whole force while the cube gives way).
pub fn react_to_object_motion(st: &EnvState, p: &EnvParams, m: &Model, s: &mut Scratch, vel_n: Vec3, w_n: Vec3, h: f32) {
    let com = object_com(st, p);
    let dv = vel_n - v3(st.obj_vel);
    let dw = w_n - v3(st.obj_angvel);
    for i in 0..s.n_reactions as usize {
        let r = s.reactions[i];
        let n = r.normal;
        // J·Δu − δv₀: the contact point's velocity change past the one linearised about
        let du = dv + dw.cross(r.point - com) - r.dv0;
        let dun = du.dot(n);
        // D·(J·Δu − δv₀) with D = a nnᵀ + b (I − nnᵀ)
        let f = n * (r.a * dun) + (du - n * dun) * r.b;
        apply_hand_force(p, m, s, r.link as usize, r.point, f, h);
        // the torsion's damping: b_r n (n·Δω − n·δω₀)
        let mut tq = n * (r.br * (n.dot(dw) - n.dot(r.dw0)));
        if r.spring_count > 1.0 {
            // a manifold's resistance to the object's turning: E (Δω − δω₀)
            let e = spread_matrix(r.spread_diag, r.spread_off, n, r.a, r.b);
            let x = dw - r.dw0;
            tq += e[0] * x.x + e[1] * x.y + e[2] * x.z;
        }
        apply_hand_torque(p, m, s, r.link as usize, tq, h);
    }
}

/// The object: its pose from its velocities at the end of the substep, `vel_n` and `w_n`
/// (`object_velocity_change`).
pub fn integrate_object(st: &mut EnvState, p: &EnvParams, vel_n: Vec3, w_n: Vec3, h: f32) {
    let com = object_com(st, p);
    // the centre of mass moves with v, the frame turns about it: p_obj = com − R c
    let rot_n = quat_integrate(v4(st.obj_rot), w_n, h);
    st.obj_vel = put3(vel_n);
    st.obj_angvel = put3(w_n);
    st.obj_pos = put3(com + vel_n * h - quat_rotate(rot_n, v3(p.obj_com)));
    st.obj_rot = rot_n.to_array();
}

/// One substep of length h.
pub fn substep(st: &mut EnvState, springs: &mut [[f32; 4]], p: &EnvParams, t: &Targets, m: &Model, s: &mut Scratch, h: f32) {
    hand_kinematics(st, m, s);
    s.obj_f = Vec3::ZERO;
    s.obj_t = Vec3::ZERO;
    s.obj_d = [0.0; 36];
    s.n_reactions = 0;
    hand_servo(st, p, t, m, s, h);
    let predicted = contacts_and_forces(st, springs, p, m, s, h, &mut |_, _, _, _| {});
    // the object's velocities at the end of the substep: the second pass's prediction when no
    // force has joined its implicit solve since
    let (mut vel_n, mut w_n) = predicted.unwrap_or_else(|| object_velocity_change(st, p, m, s, h));
    // features the solved motion brings in at the pushing pairs: solved again with them
    if arriving_contacts(st, p, m, s, h, vel_n, w_n, &mut |_, _, _, _| {}) {
        (vel_n, w_n) = object_velocity_change(st, p, m, s, h);
    }
    react_to_object_motion(st, p, m, s, vel_n, w_n, h);
    integrate_hand(st, p, m, s, h);
    integrate_object(st, p, vel_n, w_n, h);
}

/// True when every component is finite (NaN fails every comparison; ±inf fails the bound).
pub fn is_finite3(v: Vec3) -> bool {
    v.x.abs() < 3.0e38 && v.y.abs() < 3.0e38 && v.z.abs() < 3.0e38
}

/// True when the state is finite and inside the configured speed and distance bounds.
pub fn state_is_sane(st: &EnvState, g: &Globals) -> bool {
    let mut ok = is_finite3(v3(st.wrist_pos)) && is_finite3(v3(st.wrist_vel)) && is_finite3(v3(st.wrist_angvel));
    ok = ok && is_finite3(v3(st.obj_pos)) && is_finite3(v3(st.obj_vel)) && is_finite3(v3(st.obj_angvel));
    for j in 0..g.n_joints as usize {
        ok = ok && st.q[j].abs() < 3.0e38 && st.qd[j].abs() < 3.0e38;
    }
    ok = ok && st.wrist_rot.iter().chain(st.obj_rot.iter()).all(|x| x.abs() < 3.0e38);
    ok = ok && v3(st.obj_pos).length() < g.max_distance && v3(st.wrist_pos).length() < g.max_distance;
    ok = ok && v3(st.obj_vel).length() < g.max_speed && v3(st.wrist_vel).length() < g.max_speed;
    ok = ok && v3(st.obj_angvel).length() < 100.0 * g.max_speed && v3(st.wrist_angvel).length() < 100.0 * g.max_speed;
    ok
}

/// One env step of env `env` (`springs`: its `[n_springs]` contact springs): decimation ×
/// substeps, statistics, and a reset if the state went bad.
pub fn env_step(env: u32, st: &mut EnvState, springs: &mut [[f32; 4]], p: &mut EnvParams, t: &Targets, m: &Model, stats: &mut StepStats) {
    let g = m.g;
    let mut s = Scratch::default();
    let h = g.dt / g.substeps as f32;
    let n_sub = g.decimation * g.substeps;
    for _ in 0..n_sub {
        substep(st, springs, p, t, m, &mut s, h);
    }
    st.time += g.dt * g.decimation as f32;
    st.step += 1;
    for i in 0..MAX_TIPS {
        stats.tip_force[i] = s.tip_force[i] / n_sub as f32;
    }
    stats.max_pen_ho = s.max_pen_ho;
    stats.max_pen = s.max_pen;
    stats.contacts = s.contacts;
    stats.contacts_ho = s.contacts_ho;
    stats.link_contact = s.link_contact;
    stats.table_contact = 0;
    for ci in 0..g.n_colliders {
        if springs[spring_slot::hand_table(g.n_colliders, ci) as usize][3] > 0.0 {
            stats.table_contact = 1;
        }
    }
    stats.bad_reset = 0;
    if !state_is_sane(st, g) {
        let episode = st.episode + 1;
        let bad = st.bad_resets + 1;
        *p = reset_params(g, m.objects, m.ref_objects, env, episode);
        *st = reset_state(g, m.joints, p, env, episode, bad);
        clear_springs(springs);
        stats.bad_reset = 1;
    }
}
