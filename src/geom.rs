//! Geometry shared by the hand, the object, trajectories and recordings.
//!
//! Conventions (docs/design.md §2): metres, radians; z up; quaternions stored x, y, z, w (glam's order).

use glam::{Quat, Vec3};
use serde::{Deserialize, Serialize};

/// The rotation of roll, pitch, yaw (rad): R = Rz(yaw)·Ry(pitch)·Rx(roll), as `wrist.init_rpy` and
/// URDF origins define it.
pub fn quat_from_rpy([roll, pitch, yaw]: [f32; 3]) -> Quat {
    Quat::from_rotation_z(yaw) * Quat::from_rotation_y(pitch) * Quat::from_rotation_x(roll)
}

/// A rigid pose: position (m) and orientation (unit quaternion, x y z w).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Pose {
    pub pos: Vec3,
    pub rot: Quat,
}

impl Default for Pose {
    fn default() -> Self {
        Self::IDENTITY
    }
}

impl Pose {
    pub const IDENTITY: Pose = Pose { pos: Vec3::ZERO, rot: Quat::IDENTITY };

    /// From the GPU layout's `[x, y, z, _]` position and `[x, y, z, w]` quaternion (EnvState fields).
    pub fn from_arrays(p: [f32; 4], q: [f32; 4]) -> Self {
        Self { pos: Vec3::new(p[0], p[1], p[2]), rot: Quat::from_array(q) }
    }

    pub fn new(pos: Vec3, rot: Quat) -> Self {
        Self { pos, rot }
    }

    /// `self ∘ other`: `other` expressed in `self`'s frame, mapped to the parent frame.
    pub fn mul(&self, other: &Pose) -> Pose {
        Pose { pos: self.pos + self.rot * other.pos, rot: (self.rot * other.rot).normalize() }
    }

    /// Maps a point from this frame to the parent frame.
    pub fn transform_point(&self, p: Vec3) -> Vec3 {
        self.pos + self.rot * p
    }

    pub fn inverse(&self) -> Pose {
        let r = self.rot.inverse();
        Pose { pos: -(r * self.pos), rot: r }
    }
}

/// Shape of the manipulated object. Sizes are the unscaled ones; the per-env object scale multiplies
/// every length. Capsule and cylinder axes are the object's local z.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case", deny_unknown_fields)]
pub enum ObjectShape {
    /// A sphere of `radius` (m).
    Sphere { radius: f32 },
    /// A box with half extents `half_extents` (m) along its local x, y, z.
    Box { half_extents: [f32; 3] },
    /// A capsule: a segment of half length `half_length` along local z swept by `radius`.
    Capsule { radius: f32, half_length: f32 },
    /// A solid cylinder of `radius`, `half_length` along local z.
    Cylinder { radius: f32, half_length: f32 },
}

/// Object shape codes (keep in sync with shaders/common.wgsl `SHAPE_*`).
pub const SHAPE_SPHERE: u32 = 0;
pub const SHAPE_BOX: u32 = 1;
pub const SHAPE_CAPSULE: u32 = 2;
pub const SHAPE_CYLINDER: u32 = 3;
/// An object piece that collides as its convex hull (`PieceDesc::hull_first`).
pub const SHAPE_HULL: u32 = 4;

/// Principal moments of inertia (about the centre, along the shape's axes) of a solid primitive (`code`, scaled `size`) of mass `m`.
pub fn object_inertia(code: u32, size: Vec3, m: f32) -> Vec3 {
    let r = size.x;
    if code == SHAPE_SPHERE {
        return Vec3::splat(0.4 * m * r * r);
    }
    if code == SHAPE_BOX {
        let (x, y, z) = (size.x, size.y, size.z);
        // I_xx = m (b² + c²)/3 with half extents b, c
        return Vec3::new(m * (y * y + z * z) / 3.0, m * (x * x + z * z) / 3.0, m * (x * x + y * y) / 3.0);
    }
    let h = size.y;
    let l = 2.0 * h;
    if code == SHAPE_CYLINDER {
        let ixx = m * (3.0 * r * r + l * l) / 12.0;
        return Vec3::new(ixx, ixx, 0.5 * m * r * r);
    }
    // capsule: a cylinder and two hemispheres sharing the mass by volume
    let vc = 3.14159265 * r * r * l;
    let vs = 4.0 / 3.0 * 3.14159265 * r * r * r;
    let mc = m * vc / (vc + vs);
    let ms = m - mc;
    let izz = 0.5 * mc * r * r + 0.4 * ms * r * r;
    let ixx = mc * (3.0 * r * r + l * l) / 12.0 + ms * (0.4 * r * r + h * h + 0.75 * h * r);
    Vec3::new(ixx, ixx, izz)
}

impl ObjectShape {
    /// Integer code used in the GPU/CPU layouts ([`SHAPE_SPHERE`] …).
    pub fn code(&self) -> u32 {
        match self {
            ObjectShape::Sphere { .. } => SHAPE_SPHERE,
            ObjectShape::Box { .. } => SHAPE_BOX,
            ObjectShape::Capsule { .. } => SHAPE_CAPSULE,
            ObjectShape::Cylinder { .. } => SHAPE_CYLINDER,
        }
    }

    /// The size parameters packed as (a, b, c): sphere (r, 0, 0); box (hx, hy, hz);
    /// capsule/cylinder (r, half_length, 0).
    pub fn size_params(&self) -> [f32; 3] {
        match *self {
            ObjectShape::Sphere { radius } => [radius, 0.0, 0.0],
            ObjectShape::Box { half_extents } => half_extents,
            ObjectShape::Capsule { radius, half_length } | ObjectShape::Cylinder { radius, half_length } => {
                [radius, half_length, 0.0]
            }
        }
    }

    /// Height of the shape's centre above the table when it rests upright (local z up).
    pub fn rest_height(&self) -> f32 {
        match *self {
            ObjectShape::Sphere { radius } => radius,
            ObjectShape::Box { half_extents } => half_extents[2],
            ObjectShape::Capsule { radius, half_length } => radius + half_length,
            ObjectShape::Cylinder { half_length, .. } => half_length,
        }
    }

    /// Principal moments of inertia (kg·m²) of the solid of mass `mass`, about its centre (the same
    /// formulas the simulator uses at reset).
    pub fn inertia_diag(&self, mass: f32) -> Vec3 {
        object_inertia(self.code(), Vec3::from(self.size_params()), mass)
    }

    /// The shape with every length multiplied by `scale` (an env's object scale).
    pub fn scaled(&self, scale: f32) -> ObjectShape {
        match *self {
            ObjectShape::Sphere { radius } => ObjectShape::Sphere { radius: radius * scale },
            ObjectShape::Box { half_extents: h } => ObjectShape::Box { half_extents: [h[0] * scale, h[1] * scale, h[2] * scale] },
            ObjectShape::Capsule { radius, half_length } => ObjectShape::Capsule { radius: radius * scale, half_length: half_length * scale },
            ObjectShape::Cylinder { radius, half_length } => ObjectShape::Cylinder { radius: radius * scale, half_length: half_length * scale },
        }
    }
}
