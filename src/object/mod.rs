//! The manipulated objects (docs/design.md §4): each is one rigid body made of up to [`MAX_PIECES`]
//! convex collision pieces, each piece a primitive (sphere, box, capsule, cylinder) at a pose in the
//! object's frame, with the mass properties of the solid.
//!
//! - The **object frame** is the frame of the mesh (or URDF link) the object came from: the pose
//!   that references, observations and recordings give for the object is this frame's. The
//!   simulator keeps that pose and, beside it, the centre of mass (`com`) and the principal axes of
//!   inertia (`principal`) in this frame, so nothing is re-expressed at the boundaries.
//! - A **primitive** object (`[object] shape`) is one piece at the origin; its mass properties are
//!   the solid's closed forms.
//! - A **mesh** object ([`load`]): each OBJ group/object or STL file is one piece, fitted with the
//!   smallest primitive among `pieces_as` that contains its vertices (`mesh::fit`); the mass
//!   properties are those of the closed pieces' solid (`mesh::mass`: divergence theorem, pieces
//!   summed) with the given mass or density.
//!
//! The simulator's view of an object (its support points, rest height, bounding radius and the
//! packed `PieceDesc`/`ObjectDesc`) is the simulator's (`env::object_desc`), a layer above.

pub mod load;

use std::path::PathBuf;

use glam::{Quat, Vec3};

use crate::geom::{ObjectShape, Pose};

pub use crate::geom::object_inertia;

/// Most collision pieces of one object (keep in sync with shaders/common.wgsl `MAX_PIECES`): like a
/// hand's colliders, a few dozen; a 16-piece mug fits.
pub const MAX_PIECES: usize = 32;
/// Most vertices of one convex-hull piece (its support points against the table).
pub const MAX_HULL_VERTICES: usize = 64;

/// How well a fitted primitive matches its mesh piece.
#[derive(Clone, Debug, PartialEq)]
pub struct PieceFit {
    /// The OBJ group/object name (or the file name of an STL piece).
    pub name: String,
    /// Vertices of the mesh piece.
    pub vertices: usize,
    /// Primitive volume over the piece's convex-hull volume (≥ 1).
    pub volume_ratio: f64,
    /// How far (m) the primitive's surface sticks out of the piece's convex hull, at most.
    pub max_gap: f64,
}

/// A convex piece that collides as its hull: vertices and outward face planes in the piece frame
/// (whose origin is the vertices' mean).
#[derive(Clone, Debug, PartialEq)]
pub struct HullPiece {
    pub vertices: Vec<Vec3>,
    /// Triangles (indices into `vertices`), wound outward.
    pub faces: Vec<[u32; 3]>,
    /// Each face's outward unit normal n and offset d: the face's plane is n·x = d.
    pub planes: Vec<(Vec3, f32)>,
}

/// One collision piece: a primitive, or a convex hull, at a pose in the object frame.
#[derive(Clone, Debug, PartialEq)]
pub struct ObjectPiece {
    /// The primitive (for a hull piece: the best-fitting primitive, which it replaced).
    pub shape: ObjectShape,
    /// The piece's frame in the object frame (capsule and cylinder axes along its z).
    pub pose: Pose,
    /// A piece that collides as its convex hull (where no primitive fits it closely enough).
    pub hull: Option<HullPiece>,
    /// For a piece fitted to a mesh: how well the primitive fits.
    pub fit: Option<PieceFit>,
}

/// Where an object's mass came from (for `dextrain check`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MassSource {
    /// The config's `mass`.
    Given,
    /// The config's `density` × the volume.
    Density,
    /// The URDF's `<mass>`.
    Urdf,
    /// The default: 0.1 kg for a primitive, 1000 kg/m³ × volume for a mesh.
    Default,
}

/// One object of a run.
#[derive(Clone, Debug, PartialEq)]
pub struct ObjectModel {
    /// Name in reports.
    pub name: String,
    /// The mesh or URDF file(s) it came from (empty for a primitive).
    pub sources: Vec<PathBuf>,
    pub pieces: Vec<ObjectPiece>,
    /// Mass (kg) and where it came from.
    pub mass: f32,
    pub mass_source: MassSource,
    /// Volume of the solid (m³; the pieces' volumes summed for a mesh).
    pub volume: f32,
    /// Centre of mass in the object frame.
    pub com: Vec3,
    /// Principal moments of inertia (kg·m², about the centre of mass) at `mass`.
    pub inertia: Vec3,
    /// Principal axes in the object frame: the inertia tensor is R diag(inertia) Rᵀ.
    pub principal: Quat,
}

/// The volume of a primitive solid (m³).
pub fn shape_volume(shape: &ObjectShape) -> f32 {
    use std::f32::consts::PI;
    match *shape {
        ObjectShape::Sphere { radius } => 4.0 / 3.0 * PI * radius.powi(3),
        ObjectShape::Box { half_extents: h } => 8.0 * h[0] * h[1] * h[2],
        // π r² · 2h + 4/3 π r³
        ObjectShape::Capsule { radius, half_length } => PI * radius * radius * 2.0 * half_length + 4.0 / 3.0 * PI * radius.powi(3),
        ObjectShape::Cylinder { radius, half_length } => PI * radius * radius * 2.0 * half_length,
    }
}

impl ObjectModel {
    /// An object that is one primitive at the origin, of `mass` (kg).
    pub fn primitive(name: &str, shape: ObjectShape, mass: f32, mass_source: MassSource) -> ObjectModel {
        ObjectModel {
            name: name.to_string(),
            sources: Vec::new(),
            pieces: vec![ObjectPiece { shape, pose: Pose::IDENTITY, hull: None, fit: None }],
            mass,
            mass_source,
            volume: shape_volume(&shape),
            com: Vec3::ZERO,
            inertia: object_inertia(shape.code(), Vec3::from(shape.size_params()), mass),
            principal: Quat::IDENTITY,
        }
    }


    /// The axis-aligned box (lo, hi) in the object frame around every piece.
    pub fn bounding_box(&self) -> (Vec3, Vec3) {
        let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
        for p in &self.pieces {
            let (pos, rot) = (p.pose.pos, p.pose.rot);
            if let Some(h) = &p.hull {
                for v in &h.vertices {
                    let w = p.pose.transform_point(*v);
                    (lo, hi) = (lo.min(w), hi.max(w));
                }
                continue;
            }
            // half extents along the object's axes: a box's |R| h; a round shape's along its axis a:
            // |aᵢ|·l + r (capsule) or |aᵢ|·l + r·√(1 − aᵢ²) (cylinder); a sphere's r
            let e = match p.shape {
                ObjectShape::Box { half_extents: h } => {
                    let m = glam::Mat3::from_quat(rot);
                    Vec3::new(
                        m.row(0).abs().dot(Vec3::from(h)),
                        m.row(1).abs().dot(Vec3::from(h)),
                        m.row(2).abs().dot(Vec3::from(h)),
                    )
                }
                ObjectShape::Sphere { radius } => Vec3::splat(radius),
                ObjectShape::Capsule { radius, half_length } => (rot * Vec3::Z).abs() * half_length + Vec3::splat(radius),
                ObjectShape::Cylinder { radius, half_length } => {
                    let a = (rot * Vec3::Z).abs();
                    a * half_length + (Vec3::ONE - a * a).max(Vec3::ZERO).map(f32::sqrt) * radius
                }
            };
            (lo, hi) = (lo.min(pos - e), hi.max(pos + e));
        }
        (lo, hi)
    }

    /// Points of the collision shape in the object frame that bound it from every side: the
    /// convex pieces' vertices, or, for a shape without hulls (primitives), the corners of
    /// [`ObjectModel::bounding_box`].
    pub fn collision_points(&self) -> Vec<Vec3> {
        let pts: Vec<Vec3> = self.pieces.iter().filter_map(|p| p.hull.as_ref().map(|h| (p, h))).flat_map(|(p, h)| h.vertices.iter().map(move |v| p.pose.transform_point(*v))).collect();
        if !pts.is_empty() {
            return pts;
        }
        let (lo, hi) = self.bounding_box();
        (0..8).map(|i| Vec3::new(if i & 1 == 0 { lo.x } else { hi.x }, if i & 2 == 0 { lo.y } else { hi.y }, if i & 4 == 0 { lo.z } else { hi.z })).collect()
    }

    /// Whether the object is one sphere, or one cylinder or capsule standing upright: round in
    /// the table's plane (a grasp may close on it from any side).
    pub fn is_round(&self) -> bool {
        match self.pieces.as_slice() {
            [p] if p.hull.is_none() => match p.shape {
                ObjectShape::Sphere { .. } => true,
                ObjectShape::Capsule { .. } | ObjectShape::Cylinder { .. } => (p.pose.rot * Vec3::Z).z.abs() > 0.9999,
                ObjectShape::Box { .. } => false,
            },
            _ => false,
        }
    }

}
