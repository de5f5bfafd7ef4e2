//! The simulator's view of an object model: its support points against the table, rest height and
//! bounding radius (from the primitives' support functions of `physics`, the twin of
//! physics.wgsl), and the packed `PieceDesc`/`ObjectDesc` the shaders read. These are inherent
//! methods of [`ObjectModel`] defined at the simulator's layer, so that the object model (a layer
//! below) needs nothing of the simulator.

use std::fmt::Write as _;

use glam::Vec3;

use crate::gpu::layout::{ObjectDesc, PieceDesc, SHAPE_HULL};
use super::physics::{bounding_radius, object_num_support, object_support_point};
use crate::geom::ObjectShape;
use crate::object::{MassSource, ObjectModel, ObjectPiece};

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

impl ObjectModel {
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
