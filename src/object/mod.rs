//! The manipulated objects (DESIGN §4): each is one rigid body made of up to [`MAX_PIECES`]
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
//! [`ObjectModel::descs`] packs an object for the simulator (`PieceDesc`, `ObjectDesc`).

pub mod load;

use std::fmt::Write as _;
use std::path::PathBuf;

use glam::{Quat, Vec3};

use crate::env::gpu_layout::{ObjectDesc, PieceDesc, SHAPE_BOX, SHAPE_CYLINDER, SHAPE_HULL, SHAPE_SPHERE};
use crate::env::physics::{bounding_radius, object_num_support, object_support_point};
use crate::geom::{ObjectShape, Pose};
use crate::record::ObjectPart;

pub use crate::env::gpu_layout::MAX_PIECES;

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

/// The radius about a piece's origin that bounds it.
fn piece_bound(p: &ObjectPiece) -> f32 {
    match &p.hull {
        Some(h) => h.vertices.iter().map(|v| v.length()).fold(0.0, f32::max),
        None => bounding_radius(p.shape.code(), Vec3::from(p.shape.size_params())),
    }
}

/// A piece's support points against the table: a primitive's, or a hull's vertices.
fn piece_support(p: &ObjectPiece) -> u32 {
    p.hull.as_ref().map_or_else(|| object_num_support(p.shape.code()), |h| h.vertices.len() as u32)
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

    /// The support points of every piece in the object frame: (position, radius).
    pub fn support_points(&self) -> Vec<(Vec3, f32)> {
        let mut out = Vec::new();
        for p in &self.pieces {
            if let Some(h) = &p.hull {
                out.extend(h.vertices.iter().map(|v| (p.pose.transform_point(*v), 0.0)));
                continue;
            }
            let size = Vec3::from(p.shape.size_params());
            for k in 0..object_num_support(p.shape.code()) {
                let (local, r) = object_support_point(p.shape.code(), size, k);
                out.push((p.pose.transform_point(local), r));
            }
        }
        out
    }

    /// Height of the object frame's origin above the table when the object rests on its lowest
    /// support points in the frame's own orientation (z up).
    pub fn rest_height(&self) -> f32 {
        // the lowest point of a support point's ball is z − r
        -self.support_points().iter().map(|(p, r)| p.z - r).fold(f32::INFINITY, f32::min)
    }

    /// The radius about the object frame's origin that bounds every piece.
    pub fn bounding_radius(&self) -> f32 {
        self.pieces.iter().map(|p| p.pose.pos.length() + piece_bound(p)).fold(0.0, f32::max)
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

    /// Support points of all pieces against the table.
    pub fn n_support(&self) -> u32 {
        self.pieces.iter().map(piece_support).sum()
    }

    /// The simulator's description of the object (its pieces from `first_piece` in the run's
    /// piece buffer, its hulls' data from `first_hull` in the hull buffer), its pieces and its
    /// hulls' data (per hull: F planes (n, d), F triangles (indices as floats), its vertices).
    pub fn descs(&self, first_piece: u32, first_hull: u32) -> (ObjectDesc, Vec<PieceDesc>, Vec<[f32; 4]>) {
        let mut hulls: Vec<[f32; 4]> = Vec::new();
        let pieces: Vec<PieceDesc> = self
            .pieces
            .iter()
            .map(|p| {
                let size = p.shape.size_params();
                let pos = p.pose.pos;
                let mut d = PieceDesc {
                    pos: [pos.x, pos.y, pos.z, piece_bound(p)],
                    rot: p.pose.rot.normalize().to_array(),
                    size: [size[0], size[1], size[2], 0.0],
                    shape: p.shape.code(),
                    n_support: piece_support(p),
                    hull_first: 0,
                    hull_faces: 0,
                };
                if let Some(h) = &p.hull {
                    (d.shape, d.size) = (SHAPE_HULL, [0.0; 4]);
                    (d.hull_first, d.hull_faces) = (first_hull + hulls.len() as u32, h.faces.len() as u32);
                    hulls.extend(h.planes.iter().map(|(n, off)| [n.x, n.y, n.z, *off]));
                    hulls.extend(h.faces.iter().map(|f| [f[0] as f32, f[1] as f32, f[2] as f32, 0.0]));
                    hulls.extend(h.vertices.iter().map(|v| [v.x, v.y, v.z, 0.0]));
                }
                d
            })
            .collect();
        // per unit mass, so that a randomised mass scales it: I/m
        let per_mass = self.inertia / self.mass;
        let desc = ObjectDesc {
            com: [self.com.x, self.com.y, self.com.z, self.bounding_radius()],
            principal_rot: self.principal.normalize().to_array(),
            inertia: [per_mass.x, per_mass.y, per_mass.z, self.mass],
            first_piece,
            n_pieces: self.pieces.len() as u32,
            n_support: self.n_support(),
            rest_height: self.rest_height(),
        };
        (desc, pieces, hulls)
    }

    /// The pieces with every length multiplied by `scale` (an env's object scale), for recordings.
    pub fn parts(&self, scale: f32) -> Vec<ObjectPart> {
        self.pieces
            .iter()
            .map(|p| {
                // a hull is drawn as its triangles
                let triangles = p.hull.as_ref().map_or_else(Vec::new, |h| h.faces.iter().flat_map(|f| f.map(|i| (h.vertices[i as usize] * scale).to_array())).collect());
                ObjectPart { shape: p.shape.scaled(scale), pose: Pose::new(p.pose.pos * scale, p.pose.rot), triangles }
            })
            .collect()
    }

    /// What the object became, for `dextrain check`: one header line, one line per piece.
    pub fn describe(&self) -> String {
        let mut s = String::new();
        let src = if self.sources.is_empty() { "primitive".to_string() } else { self.sources.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(", ") };
        let mass_from = match self.mass_source {
            MassSource::Given => "given",
            MassSource::Density => "from density",
            MassSource::Urdf => "from the URDF",
            MassSource::Default => "default",
        };
        let _ = writeln!(s, "object '{}' ({src}): {} piece(s), {} support points", self.name, self.pieces.len(), self.n_support());
        let _ = writeln!(
            s,
            "  mass {:.4} kg ({mass_from}), volume {:.3e} m³, centre of mass [{:.4}, {:.4}, {:.4}] m, principal inertia [{:.3e}, {:.3e}, {:.3e}] kg·m², rest height {:.4} m, bounding radius {:.4} m",
            self.mass,
            self.volume,
            self.com.x,
            self.com.y,
            self.com.z,
            self.inertia.x,
            self.inertia.y,
            self.inertia.z,
            self.rest_height(),
            self.bounding_radius()
        );
        for (i, p) in self.pieces.iter().enumerate() {
            let shape = match p.shape {
                ObjectShape::Sphere { radius } => format!("sphere r {radius:.4}"),
                ObjectShape::Box { half_extents: h } => format!("box half extents [{:.4}, {:.4}, {:.4}]", h[0], h[1], h[2]),
                ObjectShape::Capsule { radius, half_length } => format!("capsule r {radius:.4} half length {half_length:.4}"),
                ObjectShape::Cylinder { radius, half_length } => format!("cylinder r {radius:.4} half length {half_length:.4}"),
            };
            let at = p.pose.pos;
            let fit = p.fit.as_ref().map_or(String::new(), |f| {
                let what = if p.hull.is_some() { "the best primitive would be" } else { "fits" };
                format!(" — {what} '{}' ({} vertices): volume {:.2}× its hull, sticks out ≤ {:.1} mm", f.name, f.vertices, f.volume_ratio, f.max_gap * 1e3)
            });
            let shape = match &p.hull {
                Some(h) => format!("convex hull of {} vertices, {} faces (instead of a {shape})", h.vertices.len(), h.faces.len()),
                None => shape,
            };
            let _ = writeln!(s, "  piece {i}: {shape} at [{:.4}, {:.4}, {:.4}]{fit}", at.x, at.y, at.z);
        }
        s
    }
}
