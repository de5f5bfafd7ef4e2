//! Mass properties of a closed triangle mesh: volume, centre of mass and inertia tensor of the
//! solid it encloses, for a uniform density.
//!
//! By the divergence theorem a volume integral over the solid is a sum over its triangles of the
//! same integral over the signed tetrahedron (origin, a, b, c): positive where the triangle faces
//! away from the origin, negative where it faces it, so that the parts outside the solid cancel
//! (Eberly, "Polyhedral Mass Properties (Revisited)"; Tonon 2004). For precision on meshes far
//! from the origin, the tetrahedra start at a reference point near the mesh (the mean vertex)
//! instead of the origin. A mesh wound inward (negative total volume) has every integral's sign
//! flipped, so either winding gives the same properties; a mesh that is not closed gives
//! meaningless numbers ([`is_closed`] says which it is).
//!
//! Units: the vertices' (metres in dextrain). The inertia is for unit density (kg·m² per kg/m³,
//! i.e. m⁵); [`MassProperties::scaled_to_mass`] gives it for a mass.

use std::collections::HashMap;

use glam::{DMat3, DVec3};

use crate::mesh::hull::symmetric_eigen;
use crate::mesh::read::TriangleMesh;

/// A mesh whose |volume| is at most `VOLUME_REL × d³` (d: the diagonal of its bounding box) is
/// flat or degenerate (an error): for a box of sides 1 × 1 × t (d ≈ √2), that is t ≲ 3e-9.
pub const VOLUME_REL: f64 = 1e-9;

/// Volume, centre of mass and inertia of a solid of unit density.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MassProperties {
    /// Enclosed volume (units³, > 0).
    pub volume: f64,
    /// Centre of mass (= centroid of the volume, for a uniform density).
    pub center_of_mass: DVec3,
    /// Inertia tensor about `center_of_mass`, in the mesh's axes, for unit density (units⁵:
    /// kg·m² per kg/m³); symmetric, I = ∫ (|r|² E − r rᵀ) dV with r measured from the COM.
    pub inertia: DMat3,
}

impl MassProperties {
    /// The centre of mass and the inertia tensor about it for a solid of total `mass` (density
    /// mass / volume).
    pub fn scaled_to_mass(&self, mass: f64) -> (DVec3, DMat3) {
        (self.center_of_mass, self.inertia * (mass / self.volume))
    }

    /// The principal moments (descending) and the principal axes as the columns of a
    /// right-handed rotation R, so that `inertia = R · diag(moments) · Rᵀ` (unit density, like
    /// `inertia`).
    pub fn principal(&self) -> (DVec3, DMat3) {
        symmetric_eigen(self.inertia.to_cols_array_2d()) // symmetric: columns = rows
    }
}

/// The mass properties (unit density) of the solid a closed triangle mesh encloses; either
/// winding. Errors (one line): no triangles, an index out of range, a non-finite vertex, a
/// volume that is zero for the mesh's size (flat or degenerate, see [`VOLUME_REL`]), or a
/// non-finite result.
pub fn mass_properties(mesh: &TriangleMesh) -> Result<MassProperties, String> {
    if mesh.triangles.is_empty() {
        return Err("the mesh has no triangles".to_string());
    }
    let n = mesh.vertices.len();
    if let Some(t) = mesh.triangles.iter().find(|t| t.iter().any(|&i| i as usize >= n)) {
        return Err(format!("triangle {t:?} indexes past the mesh's {n} vertices"));
    }
    if !mesh.vertices.iter().all(|p| p.is_finite()) {
        return Err("a vertex has a non-finite coordinate".to_string());
    }
    let o = mesh.vertices.iter().copied().sum::<DVec3>() / n as f64; // reference point
    let m = moments(mesh, o);
    let (lo, hi) = mesh.vertices.iter().fold((DVec3::INFINITY, DVec3::NEG_INFINITY), |(lo, hi), p| (lo.min(*p), hi.max(*p)));
    let d = (hi - lo).length();
    if !m.volume.is_finite() {
        return Err(format!("the volume is not finite ({})", m.volume));
    }
    if m.volume.abs() <= VOLUME_REL * d * d * d {
        return Err(format!("the mesh encloses no volume ({:e} for a bounding box diagonal of {d:e}): it is flat or degenerate", m.volume));
    }
    let m = if m.volume < 0.0 { m.flipped() } else { m }; // wound inward
    let com = m.first / m.volume; // relative to o
    let second = m.second - outer(com, com) * m.volume; // ∫ r rᵀ dV about the COM (parallel axis)
    let p = MassProperties { volume: m.volume, center_of_mass: o + com, inertia: inertia_of(second) };
    if !(p.center_of_mass.is_finite() && p.inertia.is_finite()) {
        return Err("the centre of mass or the inertia is not finite".to_string());
    }
    Ok(p)
}

/// Volume integrals of a mesh's solid, about a reference point o: ∫ dV, ∫ r dV, ∫ r rᵀ dV with
/// r = x − o (signed: negative for a mesh wound inward).
struct Moments {
    volume: f64,
    first: DVec3,
    second: DMat3,
}

impl Moments {
    /// The same integrals with the opposite sign (the mesh wound the other way).
    fn flipped(self) -> Moments {
        Moments { volume: -self.volume, first: -self.first, second: -self.second }
    }
}

/// The sums, over the mesh's triangles (a, b, c), of the integrals over the signed tetrahedron
/// (o, a, b, c) (indices already checked).
fn moments(mesh: &TriangleMesh, o: DVec3) -> Moments {
    let mut m = Moments { volume: 0.0, first: DVec3::ZERO, second: DMat3::ZERO };
    for t in &mesh.triangles {
        let [a, b, c] = t.map(|i| mesh.vertices[i as usize] - o);
        // tetrahedron (0, a, b, c) = {αa + βb + γc : α, β, γ ≥ 0, α + β + γ ≤ 1}, Jacobian det[a b c]:
        // V = det[a b c] / 6 = a · (b × c) / 6 (> 0 when (a, b, c) is counter-clockwise seen from
        // outside the tetrahedron, i.e. from beyond its face abc)
        let v = a.dot(b.cross(c)) / 6.0;
        let s = a + b + c;
        // ∫ r dV = V · (0 + a + b + c) / 4   (the centroid of the four corners)
        m.volume += v;
        m.first += s * (v / 4.0);
        // ∫ r rᵀ dV = V/20 · (Σ_k p_k p_kᵀ + (Σ_k p_k)(Σ_k p_k)ᵀ) over the corners p_k = 0, a, b, c
        // (r = αa + βb + γc; the Dirichlet integrals ∫ α² = 2!/5! and ∫ αβ = 1!·1!/5! over the
        // standard simplex, times the Jacobian 6V, give ∫ α² dV = V/10 and ∫ αβ dV = V/20), e.g.
        // ∫ x² dV = V/10 · (a_x² + b_x² + c_x² + a_x b_x + b_x c_x + c_x a_x)
        m.second += (outer(a, a) + outer(b, b) + outer(c, c) + outer(s, s)) * (v / 20.0);
    }
    m
}

/// u vᵀ (3×3).
fn outer(u: DVec3, v: DVec3) -> DMat3 {
    DMat3::from_cols(u * v.x, u * v.y, u * v.z)
}

/// The inertia tensor I = tr(C) E − C of the second moment C = ∫ r rᵀ dV (both about the same
/// point): I_xx = ∫ (y² + z²) dV, I_xy = −∫ x y dV, ...
fn inertia_of(c: DMat3) -> DMat3 {
    let trace = c.x_axis.x + c.y_axis.y + c.z_axis.z;
    DMat3::from_diagonal(DVec3::splat(trace)) - c
}

/// Whether the mesh is closed and consistently oriented: every edge (i, j) of a triangle is used
/// once in that direction and once, by another triangle, in the direction (j, i). False for no
/// triangles and for a triangle with a repeated corner index.
pub fn is_closed(mesh: &TriangleMesh) -> bool {
    let mut directed: HashMap<(u32, u32), u32> = HashMap::new(); // (from, to) → how many triangles
    for t in &mesh.triangles {
        if t[0] == t[1] || t[1] == t[2] || t[2] == t[0] {
            return false;
        }
        for k in 0..3 {
            *directed.entry((t[k], t[(k + 1) % 3])).or_insert(0) += 1;
        }
    }
    !directed.is_empty() && directed.iter().all(|(&(i, j), &count)| count == 1 && directed.get(&(j, i)) == Some(&1))
}

/// The mass properties of the union of disjoint solids of one density: volumes add, the centre
/// of mass is the volume-weighted mean, and each inertia moves to the common centre of mass by
/// the parallel-axis theorem (I + V (|d|² E − d dᵀ), d from the common COM to the part's).
/// Errors: no parts, or a part whose volume is not positive and finite.
pub fn combine(parts: &[MassProperties]) -> Result<MassProperties, String> {
    if parts.is_empty() {
        return Err("no parts to combine".to_string());
    }
    if let Some((k, p)) = parts.iter().enumerate().find(|(_, p)| !(p.volume.is_finite() && p.volume > 0.0)) {
        return Err(format!("part {k} has volume {} (not positive and finite)", p.volume));
    }
    let volume: f64 = parts.iter().map(|p| p.volume).sum();
    let com = parts.iter().map(|p| p.center_of_mass * p.volume).sum::<DVec3>() / volume;
    let mut inertia = DMat3::ZERO;
    for p in parts {
        let d = p.center_of_mass - com;
        // parallel axis: I_com = I_part + V (|d|² E − d dᵀ) = I_part + inertia_of(V d dᵀ)
        inertia += p.inertia + inertia_of(outer(d, d) * p.volume);
    }
    let out = MassProperties { volume, center_of_mass: com, inertia };
    if !(out.volume.is_finite() && out.center_of_mass.is_finite() && out.inertia.is_finite()) {
        return Err("the combined mass properties are not finite".to_string());
    }
    Ok(out)
}
