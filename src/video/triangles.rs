//! The triangles of a video frame: every shape of a recording (hand colliders, object pieces, the
//! table, the reference ghost) as a flat list of world-space triangles with a normal and a colour
//! per vertex, built on the CPU for each frame (a hand is a few thousand triangles).

use glam::{Quat, Vec3};

use crate::geom::{ObjectShape, Pose};
use crate::hand::ColliderShape;
use crate::record::{ObjectPart, RolloutFrame, RolloutMeta, TABLE_SIZE};

/// Segments around the axis of a sphere, capsule or cylinder.
const AROUND: usize = 16;
/// Rings from pole to equator of a sphere or a capsule's cap.
const CAP_RINGS: usize = 6;

/// The colours, the values of the Foxglove scene of a recording (`record/scene.rs`), RGBA in 0..1.
pub const HAND_COLOR: [f32; 4] = [0.75, 0.72, 0.68, 1.0];
/// The object: orange.
pub const OBJECT_COLOR: [f32; 4] = [0.95, 0.55, 0.15, 1.0];
/// The reference ghost: translucent green.
pub const GHOST_COLOR: [f32; 4] = [0.2, 0.85, 0.3, 0.3];
/// The table.
pub const TABLE_COLOR: [f32; 4] = [0.45, 0.42, 0.4, 1.0];

/// One vertex of a triangle list: world position (m), unit normal, RGBA colour. 40 bytes, the
/// vertex layout of `render.rs` (locations 0, 1, 2).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Vertex {
    /// World position (m).
    pub pos: [f32; 3],
    /// Unit normal (world; zero for a degenerate hull triangle).
    pub normal: [f32; 3],
    /// RGBA, 0..1 (alpha < 1: blended, the ghost).
    pub color: [f32; 4],
}

/// A triangle list under construction (three vertices per triangle).
#[derive(Default)]
struct Triangles {
    vertices: Vec<Vertex>,
}

/// A point of a lathe profile: distance from the axis, height along it, and the normal's radial
/// and axial parts.
#[derive(Clone, Copy)]
struct ProfilePoint {
    rho: f32,
    z: f32,
    n_rho: f32,
    n_z: f32,
}

impl Triangles {
    /// One triangle with a normal per vertex (local points and normals mapped by `pose`).
    fn push(&mut self, pose: &Pose, p: [Vec3; 3], n: [Vec3; 3], color: [f32; 4]) {
        for k in 0..3 {
            self.vertices.push(Vertex { pos: pose.transform_point(p[k]).to_array(), normal: (pose.rot * n[k]).to_array(), color });
        }
    }

    /// A surface of revolution about the pose's local z: each pair of consecutive profile points
    /// swept around the axis in `AROUND` quads (two triangles each); a pair at the same place (a
    /// sharp edge: the same point with two normals) adds nothing.
    fn lathe(&mut self, pose: &Pose, profile: &[ProfilePoint], color: [f32; 4]) {
        let ring = |p: &ProfilePoint, k: usize| {
            // angle φ = 2πk / AROUND; position (ρ cos φ, ρ sin φ, z), normal (n_ρ cos φ, n_ρ sin φ, n_z)
            let phi = std::f32::consts::TAU * k as f32 / AROUND as f32;
            let (s, c) = phi.sin_cos();
            (Vec3::new(p.rho * c, p.rho * s, p.z), Vec3::new(p.n_rho * c, p.n_rho * s, p.n_z))
        };
        for w in profile.windows(2) {
            let (a, b) = (&w[0], &w[1]);
            if a.rho == b.rho && a.z == b.z {
                continue;
            }
            for k in 0..AROUND {
                let (a0, na0) = ring(a, k);
                let (a1, na1) = ring(a, k + 1);
                let (b0, nb0) = ring(b, k);
                let (b1, nb1) = ring(b, k + 1);
                self.push(pose, [a0, a1, b1], [na0, na1, nb1], color);
                self.push(pose, [a0, b1, b0], [na0, nb1, nb0], color);
            }
        }
    }

    /// A capsule of `radius` about the segment z ∈ [−h, h] of the pose's local z (h = 0: a sphere).
    fn capsule(&mut self, pose: &Pose, radius: f32, half_length: f32, color: [f32; 4]) {
        let mut profile = Vec::with_capacity(2 * CAP_RINGS + 2);
        // bottom cap: polar angle θ from −π/2 (south pole) to 0; top cap: 0 to π/2
        for (centre, from) in [(-half_length, -std::f32::consts::FRAC_PI_2), (half_length, 0.0)] {
            for r in 0..=CAP_RINGS {
                let theta = from + std::f32::consts::FRAC_PI_2 * r as f32 / CAP_RINGS as f32;
                let (s, c) = theta.sin_cos();
                profile.push(ProfilePoint { rho: radius * c, z: centre + radius * s, n_rho: c, n_z: s });
            }
        }
        self.lathe(pose, &profile, color);
    }

    /// A solid cylinder of `radius`, z ∈ [−h, h] of the pose's local z, with flat caps.
    fn cylinder(&mut self, pose: &Pose, radius: f32, half_length: f32, color: [f32; 4]) {
        let (r, h) = (radius, half_length);
        let profile = [
            ProfilePoint { rho: 0.0, z: -h, n_rho: 0.0, n_z: -1.0 },
            ProfilePoint { rho: r, z: -h, n_rho: 0.0, n_z: -1.0 },
            ProfilePoint { rho: r, z: -h, n_rho: 1.0, n_z: 0.0 },
            ProfilePoint { rho: r, z: h, n_rho: 1.0, n_z: 0.0 },
            ProfilePoint { rho: r, z: h, n_rho: 0.0, n_z: 1.0 },
            ProfilePoint { rho: 0.0, z: h, n_rho: 0.0, n_z: 1.0 },
        ];
        self.lathe(pose, &profile, color);
    }

    /// A box of half extents `e` about the pose's origin: 6 faces, 2 triangles each.
    fn cuboid(&mut self, pose: &Pose, e: Vec3, color: [f32; 4]) {
        for axis in 0..3 {
            for sign in [-1.0f32, 1.0] {
                // the face's normal n = sign·e_axis; u, v span the face
                let n = Vec3::AXES[axis] * sign;
                let u = Vec3::AXES[(axis + 1) % 3] * e[(axis + 1) % 3];
                let v = Vec3::AXES[(axis + 2) % 3] * e[(axis + 2) % 3];
                let c = n * e[axis];
                let q = [c - u - v, c + u - v, c + u + v, c - u + v];
                self.push(pose, [q[0], q[1], q[2]], [n; 3], color);
                self.push(pose, [q[0], q[2], q[3]], [n; 3], color);
            }
        }
    }

    /// The pieces of an object at world pose `at`: primitives, or a hull's triangles (flat normals).
    fn object(&mut self, parts: &[ObjectPart], at: &Pose, color: [f32; 4]) {
        for part in parts {
            let pose = at.mul(&part.pose);
            if !part.triangles.is_empty() {
                for t in part.triangles.chunks_exact(3) {
                    let p = [Vec3::from(t[0]), Vec3::from(t[1]), Vec3::from(t[2])];
                    // flat normal n = (p1 − p0) × (p2 − p0), normalised (zero for a degenerate one)
                    let n = (p[1] - p[0]).cross(p[2] - p[0]).normalize_or_zero();
                    self.push(&pose, p, [n; 3], color);
                }
                continue;
            }
            match part.shape {
                ObjectShape::Sphere { radius } => self.capsule(&pose, radius, 0.0, color),
                ObjectShape::Box { half_extents } => self.cuboid(&pose, Vec3::from(half_extents), color),
                ObjectShape::Capsule { radius, half_length } => self.capsule(&pose, radius, half_length, color),
                ObjectShape::Cylinder { radius, half_length } => self.cylinder(&pose, radius, half_length, color),
            }
        }
    }
}

/// The opaque triangles of `frame` (hand colliders at `links[c.link] · c.pose`, the object, the
/// table with its top face at z = 0) and the translucent ones (the reference ghost, if the frame
/// has one). Non-finite poses are skipped, so a broken state draws what is left.
pub fn frame_triangles(meta: &RolloutMeta, frame: &RolloutFrame) -> (Vec<Vertex>, Vec<Vertex>) {
    let finite = |p: &Pose| p.pos.is_finite() && p.rot.is_finite();
    let mut opaque = Triangles::default();
    let [sx, sy, sz] = TABLE_SIZE;
    opaque.cuboid(&Pose::new(Vec3::new(0.0, 0.0, -0.5 * sz), Quat::IDENTITY), 0.5 * Vec3::new(sx, sy, sz), TABLE_COLOR);
    for c in &meta.hand.colliders {
        let Some(link) = frame.links.get(c.link).filter(|p| finite(p)) else { continue };
        let pose = link.mul(&c.pose);
        match c.shape {
            ColliderShape::Sphere { radius } => opaque.capsule(&pose, radius, 0.0, HAND_COLOR),
            ColliderShape::Capsule { radius, half_length } => opaque.capsule(&pose, radius, half_length, HAND_COLOR),
            ColliderShape::Box { half_extents } => opaque.cuboid(&pose, half_extents, HAND_COLOR),
        }
    }
    if finite(&frame.object) {
        opaque.object(&meta.object, &frame.object, OBJECT_COLOR);
    }
    let mut ghost = Triangles::default();
    if let Some(r) = frame.object_ref.filter(finite) {
        ghost.object(&meta.object, &r, GHOST_COLOR);
    }
    (opaque.vertices, ghost.vertices)
}
