//! Tight primitives around a mesh: the smallest sphere, capsule, oriented box or cylinder (by volume) that
//! contains every vertex, and how much bigger than the mesh each one is.
//!
//! The search:
//! - **Frames.** Candidate frames are the mesh's own axes (the identity, so that a fit is never
//!   worse than the axis-aligned one), the principal axes of the convex hull's surface
//!   ([`ConvexHull::principal_axes`]: area-weighted, so dense tessellation in one place does not
//!   tilt them), the principal frame turned about each of its axes in [`ROTATION_STEP_DEG`] steps
//!   up to 90°, and frames on the hull's largest flat parts (the normals of the
//!   [`FLAT_DIRECTIONS`] largest sets of coplanar hull faces: a tight box tends to lie flush with
//!   hull faces, and where the principal axes are not unique — a cube — they are the only exact
//!   ones): z along each such normal, x along each other one (made orthogonal) or turned about z in
//!   [`ROTATION_STEP_DEG`] steps. The best candidate is then polished by coordinate descent: small
//!   turns about its axes and their diagonals, halving the step down to [`REFINE_MIN_DEG`].
//! - **Box**: the extents of the vertices in the frame, centred.
//! - **Capsule** (axis = local z, as URDF cylinders): for a candidate axis, the radius r is that of
//!   the minimum enclosing circle of the vertices projected on the plane normal to the axis
//!   (Welzl's algorithm in 2D), and the segment [s0, s1] on the axis is the shortest that covers
//!   every vertex with that radius: a vertex at axial coordinate t and radial distance d ≤ r is
//!   inside iff [s0, s1] meets [t − w, t + w], w = √(r² − d²), so s0 = minᵢ(tᵢ + wᵢ) and
//!   s1 = maxᵢ(tᵢ − wᵢ); when s0 > s1 every interval shares a point and the capsule degenerates to
//!   a sphere of radius r centred between them (half_length 0). Candidate axes are the three axes
//!   of the identity, of the principal frame and of its turns, and the normals of the hull's
//!   largest flat parts (the polish turns the axis only); the axis-aligned capsule
//!   ([`axis_aligned`]) is a candidate too.
//! - **Cylinder** (axis = local z, flat caps; for objects): the capsule's circle for each candidate
//!   axis, and the vertices' extent along it.
//! - **Sphere**: the minimum enclosing sphere (Welzl's algorithm in 3D); no orientation (`rot` is
//!   the identity).
//!
//! The search runs on the hull's vertices (a convex primitive contains the mesh iff it contains
//! the hull; for a hull of more than [`SEARCH_MAX_POINTS`] vertices, the frames are searched on
//! its extreme vertices along that many directions); the final primitive is sized on every vertex
//! in the chosen frame, so it contains all of them up to rounding (≈1e-15 relative), whatever the
//! hull's tolerance.
//!
//! How much bigger than the mesh: [`PrimitiveFit::volume_ratio`] (primitive volume over hull
//! volume, ≥ 1) and [`PrimitiveFit::max_gap`], the largest distance from a point of the
//! primitive's surface to the hull. The distance to a convex set is a convex function, so over a
//! convex primitive its maximum is reached at an extreme point: a box's corners (exact), a
//! capsule's two hemispherical caps, a sphere's surface; caps and spheres are sampled
//! ([`GAP_SAMPLES`] deterministic points each, plus the poles along the primitive's axes), so the
//! gap of a sphere or capsule can be short of the truth by about r·(1 − cos δ), δ ≈ √(4π/N).

use glam::{DMat3, DQuat, DVec2, DVec3};

use super::hull::{ConvexHull, convex_hull};

/// Step (degrees) of the turns of the principal frame about each principal axis, up to 90°.
pub const ROTATION_STEP_DEG: f64 = 3.0;
/// The smallest turn (degrees) of the coordinate-descent polish of the best frame.
pub const REFINE_MIN_DEG: f64 = 0.002;
/// How many of the hull's largest flat parts (sets of coplanar faces) give candidate frames.
pub const FLAT_DIRECTIONS: usize = 6;
/// Sample points per sphere and per capsule cap for [`PrimitiveFit::max_gap`].
pub const GAP_SAMPLES: usize = 1000;
/// A hull with more vertices than this is searched on this many of them (its extreme vertices
/// along evenly spread directions); the chosen primitive is then sized on every vertex.
pub const SEARCH_MAX_POINTS: usize = 1000;

/// The kinds of primitive a mesh can become.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum PrimitiveKind {
    /// A ball.
    Sphere,
    /// A segment swept by a ball (a cylinder with hemispherical caps).
    Capsule,
    /// An oriented box.
    Box,
    /// A solid cylinder (flat caps), axis = local z.
    Cylinder,
}

impl PrimitiveKind {
    /// The lower-case name ("sphere", "capsule", "box").
    pub fn name(self) -> &'static str {
        match self {
            PrimitiveKind::Sphere => "sphere",
            PrimitiveKind::Capsule => "capsule",
            PrimitiveKind::Box => "box",
            PrimitiveKind::Cylinder => "cylinder",
        }
    }

    /// Simplicity rank for ties in [`fit_tightest`]: sphere < capsule < box < cylinder.
    fn rank(self) -> u8 {
        match self {
            PrimitiveKind::Sphere => 0,
            PrimitiveKind::Capsule => 1,
            PrimitiveKind::Box => 2,
            PrimitiveKind::Cylinder => 3,
        }
    }
}

impl std::fmt::Display for PrimitiveKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// A primitive's shape and size in its own frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum FittedShape {
    /// A ball of this radius about the origin.
    Sphere {
        /// Radius.
        radius: f64,
    },
    /// The points within `radius` of the segment from (0, 0, −half_length) to (0, 0, half_length):
    /// axis = local z, as URDF cylinders. `half_length` 0 is a sphere.
    Capsule {
        /// Radius of the swept ball.
        radius: f64,
        /// Half the length of the segment (the cylindrical part).
        half_length: f64,
    },
    /// The box [−h, h] per axis.
    Box {
        /// Half extents along local x, y, z.
        half_extents: DVec3,
    },
    /// The points within `radius` of the z axis with |z| ≤ `half_length` (flat caps).
    Cylinder {
        /// Radius.
        radius: f64,
        /// Half the length along local z.
        half_length: f64,
    },
}

impl FittedShape {
    /// Which kind of primitive this is.
    pub fn kind(&self) -> PrimitiveKind {
        match self {
            FittedShape::Sphere { .. } => PrimitiveKind::Sphere,
            FittedShape::Capsule { .. } => PrimitiveKind::Capsule,
            FittedShape::Box { .. } => PrimitiveKind::Box,
            FittedShape::Cylinder { .. } => PrimitiveKind::Cylinder,
        }
    }

    /// The enclosed volume.
    pub fn volume(&self) -> f64 {
        use std::f64::consts::PI;
        match *self {
            FittedShape::Sphere { radius } => 4.0 / 3.0 * PI * radius.powi(3),
            // V = π r² · 2h (cylinder) + 4/3 π r³ (the two caps)
            FittedShape::Capsule { radius, half_length } => PI * radius * radius * 2.0 * half_length + 4.0 / 3.0 * PI * radius.powi(3),
            FittedShape::Box { half_extents: h } => 8.0 * h.x * h.y * h.z,
            // V = π r² · 2h
            FittedShape::Cylinder { radius, half_length } => PI * radius * radius * 2.0 * half_length,
        }
    }
}

/// A primitive fitted to a mesh, with how much bigger than the mesh it is.
#[derive(Clone, Debug, PartialEq)]
pub struct PrimitiveFit {
    /// The primitive's centre in the mesh frame.
    pub centre: DVec3,
    /// The primitive frame in the mesh frame: a mesh-frame point p is `centre + rot * q` for q in
    /// the primitive frame.
    pub rot: DQuat,
    /// Shape and size in the primitive frame.
    pub shape: FittedShape,
    /// The primitive's volume.
    pub volume: f64,
    /// The volume of the mesh's convex hull.
    pub hull_volume: f64,
    /// The largest distance from a point of the primitive's surface to the convex hull (how far
    /// the primitive sticks out of the mesh; 0 where it does not). See the module docs for how it
    /// is sampled.
    pub max_gap: f64,
}

impl PrimitiveFit {
    /// The kind of the fitted primitive.
    pub fn kind(&self) -> PrimitiveKind {
        self.shape.kind()
    }

    /// Primitive volume over hull volume (≥ 1 for a primitive that contains the mesh).
    pub fn volume_ratio(&self) -> f64 {
        self.volume / self.hull_volume
    }

    /// Whether the mesh-frame point `p` is inside the primitive or within `tol` of it.
    pub fn contains(&self, p: DVec3, tol: f64) -> bool {
        let q = self.rot.inverse() * (p - self.centre);
        match self.shape {
            FittedShape::Sphere { radius } => q.length() <= radius + tol,
            FittedShape::Capsule { radius, half_length } => {
                let z = q.z.clamp(-half_length, half_length); // nearest point of the segment
                DVec3::new(q.x, q.y, q.z - z).length() <= radius + tol
            }
            FittedShape::Box { half_extents } => (q.abs() - half_extents).max_element() <= tol,
            FittedShape::Cylinder { radius, half_length } => q.truncate().length() <= radius + tol && q.z.abs() <= half_length + tol,
        }
    }
}

/// The smallest primitive of `kind` (by volume) that contains every vertex, in the best frame
/// found (module docs). Errors (one line) where the vertices have no convex hull: none, a
/// non-finite coordinate, or all one point, on a line or flat ([`convex_hull`]).
pub fn fit(vertices: &[DVec3], kind: PrimitiveKind) -> Result<PrimitiveFit, String> {
    let hull = convex_hull(vertices)?;
    Ok(fit_with_hull(vertices, &hull, kind))
}

/// [`fit`] with the convex hull of `vertices` already computed (several kinds share one hull).
/// `hull` must be `convex_hull(vertices)`.
pub fn fit_with_hull(vertices: &[DVec3], hull: &ConvexHull, kind: PrimitiveKind) -> PrimitiveFit {
    let search = Search::new(hull);
    let (centre, rot, shape) = match kind {
        PrimitiveKind::Box => {
            let mut frames = search.frames.clone();
            frames.extend(search.flat_frames.iter().copied());
            // polish about the frame's axes and the diagonals between each pair of them
            let about = [
                DVec3::X,
                DVec3::Y,
                DVec3::Z,
                DVec3::new(1.0, 1.0, 0.0),
                DVec3::new(1.0, -1.0, 0.0),
                DVec3::new(0.0, 1.0, 1.0),
                DVec3::new(0.0, 1.0, -1.0),
                DVec3::new(1.0, 0.0, 1.0),
                DVec3::new(-1.0, 0.0, 1.0),
            ];
            let frame = search.best_frame(|f| search.box_volume(f), &about, &frames);
            box_in_frame(vertices, frame)
        }
        PrimitiveKind::Capsule | PrimitiveKind::Cylinder => {
            // the principal frames offer their three axes as the primitive's z (columns turned
            // cyclically, so each stays right-handed), a flat part its normal
            let mut axes: Vec<DMat3> = Vec::new();
            let turned = search
                .frames
                .iter()
                .flat_map(|m| [*m, DMat3::from_cols(m.y_axis, m.z_axis, m.x_axis), DMat3::from_cols(m.z_axis, m.x_axis, m.y_axis)]);
            for m in turned.chain(search.flat_frames.iter().copied()) {
                if !axes.iter().any(|a| a.z_axis.dot(m.z_axis).abs() > 1.0 - 1e-12) {
                    axes.push(m); // one frame per axis: turning about z changes neither shape
                }
            }
            // polish about x, y and their diagonals (not about z, for the same reason)
            let about = [DVec3::X, DVec3::Y, DVec3::new(1.0, 1.0, 0.0), DVec3::new(1.0, -1.0, 0.0)];
            let capped = kind == PrimitiveKind::Cylinder;
            let frame = search.best_frame(|f| round_in_frame(&search.points, &search.points, *f, search.tol, capped).2.volume(), &about, &axes);
            round_in_frame(&search.all, vertices, frame, search.tol, capped)
        }
        PrimitiveKind::Sphere => {
            let (c, _) = min_sphere(&search.all, search.tol);
            // sized on every vertex: r = maxᵢ |vᵢ − c|
            let r = vertices.iter().map(|v| v.distance(c)).fold(0.0, f64::max);
            (c, DQuat::IDENTITY, FittedShape::Sphere { radius: r })
        }
    };
    // never worse than the axis-aligned primitive (the identity frame is searched for boxes; the
    // capsule's tight segment for the smallest radius can, rarely, lose to it)
    let aligned = aligned_primitive(vertices, kind);
    let (centre, rot, shape) = if aligned.2.volume() < shape.volume() { aligned } else { (centre, rot, shape) };
    finish(hull, centre, rot, shape)
}

/// The smallest primitive among `kinds` ([`fit`] of each; an error for an empty list). Volumes
/// within 1e-9 (relative) of each other are a tie, which the simpler kind wins (sphere, then
/// capsule, then box). The hand loader asks for [Capsule, Sphere] ("a capsule, or a sphere where
/// that is tighter") and [Box].
pub fn fit_tightest(vertices: &[DVec3], kinds: &[PrimitiveKind]) -> Result<PrimitiveFit, String> {
    if kinds.is_empty() {
        return Err("no primitive kinds to fit; expected at least one of sphere, capsule, box".to_string());
    }
    fit_tightest_with_hull(vertices, &convex_hull(vertices)?, kinds)
}

/// [`fit_tightest`] with the convex hull of `vertices` already computed (`convex_hull(vertices)`).
pub fn fit_tightest_with_hull(vertices: &[DVec3], hull: &ConvexHull, kinds: &[PrimitiveKind]) -> Result<PrimitiveFit, String> {
    let mut best: Option<PrimitiveFit> = None;
    for &k in kinds {
        let f = fit_with_hull(vertices, hull, k);
        best = Some(match best {
            None => f,
            Some(b) => {
                let tie = (f.volume - b.volume).abs() <= 1e-9 * b.volume.max(f.volume);
                if (tie && k.rank() < b.kind().rank()) || (!tie && f.volume < b.volume) { f } else { b }
            }
        });
    }
    best.ok_or_else(|| "no primitive kinds to fit".to_string())
}

/// The axis-aligned primitive of `kind` in the mesh frame that contains every vertex, for
/// comparison: box = the bounding box; sphere = about the bounding box's centre, the radius of the
/// farthest vertex; capsule = along the bounding box's longest axis (ties prefer z, then x)
/// through its centre, the radius of the vertex farthest from that axis, and the shortest segment
/// symmetric about the centre that covers every vertex with that radius. Errors as [`fit`].
pub fn axis_aligned(vertices: &[DVec3], kind: PrimitiveKind) -> Result<PrimitiveFit, String> {
    let hull = convex_hull(vertices)?;
    Ok(axis_aligned_with_hull(vertices, &hull, kind))
}

/// [`axis_aligned`] with the hull already computed.
pub fn axis_aligned_with_hull(vertices: &[DVec3], hull: &ConvexHull, kind: PrimitiveKind) -> PrimitiveFit {
    let (centre, rot, shape) = aligned_primitive(vertices, kind);
    finish(hull, centre, rot, shape)
}

/// The axis-aligned primitive of [`axis_aligned`]: centre, rotation, shape.
fn aligned_primitive(vertices: &[DVec3], kind: PrimitiveKind) -> (DVec3, DQuat, FittedShape) {
    let (lo, hi) = vertices.iter().fold((DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)), |(lo, hi), p| (lo.min(*p), hi.max(*p)));
    let (c, half) = ((lo + hi) * 0.5, (hi - lo) * 0.5);
    match kind {
        PrimitiveKind::Box => (c, DQuat::IDENTITY, FittedShape::Box { half_extents: half }),
        PrimitiveKind::Sphere => (c, DQuat::IDENTITY, FittedShape::Sphere { radius: vertices.iter().map(|v| v.distance(c)).fold(0.0, f64::max) }),
        PrimitiveKind::Capsule | PrimitiveKind::Cylinder => {
            // the rotation taking local z to the longest axis (as the hand loader did)
            let rot = if half.z >= half.x && half.z >= half.y {
                DQuat::IDENTITY
            } else if half.x >= half.y {
                DQuat::from_rotation_y(std::f64::consts::FRAC_PI_2)
            } else {
                DQuat::from_rotation_x(-std::f64::consts::FRAC_PI_2)
            };
            let inv = rot.inverse();
            let local: Vec<DVec3> = vertices.iter().map(|v| inv * (*v - c)).collect();
            let r = local.iter().map(|q| q.truncate().length()).fold(0.0, f64::max); // d = √(x² + y²)
            if kind == PrimitiveKind::Cylinder {
                let h = local.iter().map(|q| q.z.abs()).fold(0.0, f64::max);
                return (c, rot, FittedShape::Cylinder { radius: r, half_length: h });
            }
            // symmetric segment [−h, h]: a vertex at (t, d) needs |t| ≤ h + √(r² − d²)
            let h = local.iter().map(|q| q.z.abs() - (r * r - q.truncate().length_squared()).max(0.0).sqrt()).fold(0.0, f64::max);
            (c, rot, FittedShape::Capsule { radius: r, half_length: h })
        }
    }
}

/// A fit with its volume, the hull's volume and the gap.
fn finish(hull: &ConvexHull, centre: DVec3, rot: DQuat, shape: FittedShape) -> PrimitiveFit {
    let samples: Vec<DVec3> = surface_samples(&shape).into_iter().map(|q| centre + rot * q).collect();
    let max_gap = hull.max_distance(&samples);
    PrimitiveFit { centre, rot, shape, volume: shape.volume(), hull_volume: hull.volume, max_gap }
}

/// The search state: the points searched on (shuffled for Welzl's algorithms), the candidate
/// frames and the tolerance.
struct Search {
    /// The hull's vertices in a fixed pseudo-random order (Welzl's expected linear time).
    all: Vec<DVec3>,
    /// The points the frames are searched on: `all`, or for a hull of more than
    /// [`SEARCH_MAX_POINTS`] vertices those extreme along SEARCH_MAX_POINTS directions (in the
    /// same order). The final primitive is sized on every vertex.
    points: Vec<DVec3>,
    /// Candidate frames (rotations whose columns are the frame's axes in the mesh frame): the
    /// identity, the principal frame and its turns.
    frames: Vec<DMat3>,
    /// Candidate frames on the hull's largest flat parts (z along a flat part's normal).
    flat_frames: Vec<DMat3>,
    /// Containment tolerance of the circle and sphere tests: 1e-12 × the hull's extent.
    tol: f64,
}

impl Search {
    fn new(hull: &ConvexHull) -> Search {
        let mut all = hull.vertices.clone();
        let mut state = 0x9E37_79B9_7F4A_7C15u64;
        for i in (1..all.len()).rev() {
            // Fisher–Yates with a 64-bit LCG (Knuth's MMIX constants)
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            all.swap(i, ((state >> 33) % (i as u64 + 1)) as usize);
        }
        let points = if all.len() <= SEARCH_MAX_POINTS {
            all.clone()
        } else {
            // the support points: for each of evenly spread directions u, the vertex maximising u·v
            let mut pick: Vec<usize> = fibonacci(SEARCH_MAX_POINTS, -1.0)
                .into_iter()
                .map(|u| (0..all.len()).fold(0, |m, i| if u.dot(all[i]) > u.dot(all[m]) { i } else { m }))
                .collect();
            pick.sort_unstable();
            pick.dedup();
            pick.into_iter().map(|i| all[i]).collect()
        };
        let (lo, hi) = all.iter().fold((DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)), |(lo, hi), p| (lo.min(*p), hi.max(*p)));
        let (_, principal, _) = hull.principal_axes();
        let mut frames = vec![DMat3::IDENTITY, principal];
        let steps = (90.0 / ROTATION_STEP_DEG).round() as usize;
        for k in 0..3 {
            let axis = DVec3::AXES[k];
            for s in 1..steps {
                // turn the principal frame about its own k-th axis: R · Rot_k(θ)
                frames.push(principal * DMat3::from_axis_angle(axis, (s as f64 * ROTATION_STEP_DEG).to_radians()));
            }
        }
        // frames on the largest flat parts: z = n_i, x = n_j made orthogonal to n_i, or turned
        let normals = flat_directions(hull, FLAT_DIRECTIONS);
        let mut flat_frames = Vec::new();
        for (i, &n) in normals.iter().enumerate() {
            for (j, &m) in normals.iter().enumerate() {
                let x = m - n * m.dot(n); // Gram–Schmidt
                if i != j && x.length() > 1e-6 {
                    let x = x.normalize();
                    flat_frames.push(DMat3::from_cols(x, n.cross(x), n));
                }
            }
            let (x, y) = n.any_orthonormal_pair();
            let base = DMat3::from_cols(x, y, n);
            for s in 0..steps {
                flat_frames.push(base * DMat3::from_rotation_z((s as f64 * ROTATION_STEP_DEG).to_radians()));
            }
        }
        Search { all, points, frames, flat_frames, tol: 1e-12 * (hi - lo).length() }
    }

    /// The best of `candidates` by `volume`, polished by coordinate descent: turns by ±step about
    /// each of the directions `about` (in the frame), kept while they shrink the volume, the step
    /// halving from ROTATION_STEP_DEG / 2 to REFINE_MIN_DEG.
    fn best_frame(&self, volume: impl Fn(&DMat3) -> f64, about: &[DVec3], candidates: &[DMat3]) -> DMat3 {
        let (mut best, mut best_v) = candidates.iter().map(|f| (*f, volume(f))).fold((DMat3::IDENTITY, f64::INFINITY), |m, x| if x.1 < m.1 { x } else { m });
        let mut step = ROTATION_STEP_DEG / 2.0;
        while step >= REFINE_MIN_DEG {
            for _pass in 0..16 {
                let mut improved = false;
                for &axis in about {
                    for sign in [1.0, -1.0] {
                        let f = best * DMat3::from_axis_angle(axis.normalize(), sign * step.to_radians());
                        let v = volume(&f);
                        if v < best_v * (1.0 - 1e-12) {
                            (best, best_v, improved) = (f, v, true);
                        }
                    }
                }
                if !improved {
                    break;
                }
            }
            step /= 2.0;
        }
        best
    }

    /// Volume of the box around the search points in `frame`.
    fn box_volume(&self, frame: &DMat3) -> f64 {
        let (lo, hi) = extents(&self.points, frame);
        let d = hi - lo;
        d.x * d.y * d.z
    }

}

/// The normals of the `k` largest flat parts of the hull: its faces grouped by normal (rounded to
/// 1e-7; coplanar triangles of one polygon agree to rounding), largest total area first.
fn flat_directions(hull: &ConvexHull, k: usize) -> Vec<DVec3> {
    let mut groups: std::collections::HashMap<[i64; 3], (DVec3, f64)> = std::collections::HashMap::new();
    for (f, n) in hull.faces.iter().zip(&hull.normals) {
        let (a, b, c) = (hull.vertices[f[0]], hull.vertices[f[1]], hull.vertices[f[2]]);
        let area = (b - a).cross(c - a).length() / 2.0;
        let key = (*n * 1e7).round().to_array().map(|x| x as i64);
        let g = groups.entry(key).or_insert((DVec3::ZERO, 0.0));
        g.0 += *n * area; // area-weighted mean normal
        g.1 += area;
    }
    let mut groups: Vec<(DVec3, f64)> = groups.into_values().filter(|g| g.0.length() > 0.0).collect();
    // largest first; ties by the normal, so the order does not depend on the hash map's
    groups.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.to_array().partial_cmp(&b.0.to_array()).unwrap_or(std::cmp::Ordering::Equal)));
    groups.into_iter().take(k).map(|g| g.0.normalize()).collect()
}

/// Smallest and largest coordinates of `points` along the columns of `frame`.
fn extents(points: &[DVec3], frame: &DMat3) -> (DVec3, DVec3) {
    let ft = frame.transpose();
    points.iter().fold((DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)), |(lo, hi), p| {
        let q = ft * *p; // coordinates in the frame: q = Rᵀ p
        (lo.min(q), hi.max(q))
    })
}

/// The rotation of a frame as a unit quaternion and the frame re-made from it (so that sizes are
/// measured in exactly the frame that `contains` uses).
fn as_rotation(frame: DMat3) -> (DQuat, DMat3) {
    let rot = DQuat::from_mat3(&frame).normalize();
    (rot, DMat3::from_quat(rot))
}

/// The box around `points` in `frame`: centre, rotation, shape.
fn box_in_frame(points: &[DVec3], frame: DMat3) -> (DVec3, DQuat, FittedShape) {
    let (rot, frame) = as_rotation(frame);
    let (lo, hi) = extents(points, &frame);
    (frame * ((lo + hi) * 0.5), rot, FittedShape::Box { half_extents: (hi - lo) * 0.5 })
}

/// The capsule (`capped` false) or cylinder (`capped` true) along `frame`'s z around `points`:
/// radius of the minimum enclosing circle of the projections; a capsule's segment is the shortest
/// covering one (module docs), a cylinder spans the points' extent along z. The circle's centre is
/// found on `hull` (the extreme points, in random order for Welzl's algorithm; `points` itself when
/// searching), the radius and the length are sized on `points`.
fn round_in_frame(hull: &[DVec3], points: &[DVec3], frame: DMat3, tol: f64, capped: bool) -> (DVec3, DQuat, FittedShape) {
    let (rot, frame) = as_rotation(frame);
    let ft = frame.transpose();
    let hull_flat: Vec<DVec2> = hull.iter().map(|p| (ft * *p).truncate()).collect();
    let (c2, _) = min_circle(&hull_flat, tol);
    let local: Vec<DVec3> = points.iter().map(|p| ft * *p).collect();
    let flat: Vec<DVec2> = local.iter().map(|q| q.truncate()).collect();
    let r = flat.iter().map(|q| q.distance(c2)).fold(0.0, f64::max); // covers every projection
    if capped {
        let (lo, hi) = local.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), q| (lo.min(q.z), hi.max(q.z)));
        let centre = frame * DVec3::new(c2.x, c2.y, (lo + hi) * 0.5);
        return (centre, rot, FittedShape::Cylinder { radius: r, half_length: (hi - lo) * 0.5 });
    }
    // a vertex (t, d) is inside iff [s0, s1] meets [t − w, t + w], w = √(r² − d²)
    let (mut s0, mut s1) = (f64::INFINITY, f64::NEG_INFINITY);
    for (q, p2) in local.iter().zip(&flat) {
        let w = (r * r - p2.distance_squared(c2)).max(0.0).sqrt();
        s0 = s0.min(q.z + w); // s0 = min(t + w)
        s1 = s1.max(q.z - w); // s1 = max(t − w)
    }
    // s0 > s1: all intervals share [s1, s0]; a sphere of radius r at its middle covers every vertex
    let half_length = ((s1 - s0) * 0.5).max(0.0);
    let centre = frame * DVec3::new(c2.x, c2.y, (s0 + s1) * 0.5);
    (centre, rot, FittedShape::Capsule { radius: r, half_length })
}

/// Minimum enclosing circle (Welzl's algorithm, iterative form with the points in random order;
/// expected linear time): centre and radius. A point counts as inside within `tol`.
fn min_circle(p: &[DVec2], tol: f64) -> (DVec2, f64) {
    let Some(&first) = p.first() else {
        return (DVec2::ZERO, 0.0);
    };
    let (mut c, mut r) = (first, 0.0);
    let out = |c: DVec2, r: f64, q: DVec2| q.distance(c) > r + tol;
    for i in 1..p.len() {
        if !out(c, r, p[i]) {
            continue;
        }
        (c, r) = (p[i], 0.0); // p_i is on the circle of {p_0..p_i}
        for j in 0..i {
            if !out(c, r, p[j]) {
                continue;
            }
            (c, r) = ((p[i] + p[j]) * 0.5, p[i].distance(p[j]) * 0.5); // p_i, p_j on it
            for k in 0..j {
                if out(c, r, p[k]) {
                    (c, r) = circle3(p[i], p[j], p[k]); // p_i, p_j, p_k on it
                }
            }
        }
    }
    (c, r)
}

/// The circle through three points (the smallest covering circle of the farthest pair when they
/// are collinear).
fn circle3(a: DVec2, b: DVec2, c: DVec2) -> (DVec2, f64) {
    let (u, v) = (b - a, c - a);
    let d = 2.0 * u.perp_dot(v);
    let scale = u.length_squared().max(v.length_squared());
    if d.abs() <= 1e-14 * scale {
        let pairs = [(a, b), (a, c), (b, c)];
        let (p, q) = pairs.into_iter().fold((a, b), |m, x| if x.0.distance(x.1) > m.0.distance(m.1) { x } else { m });
        return ((p + q) * 0.5, p.distance(q) * 0.5);
    }
    // centre − a = (|u|² v⊥ − |v|² u⊥)… solved from 2u·x = |u|², 2v·x = |v|²
    let (uu, vv) = (u.length_squared(), v.length_squared());
    let x = DVec2::new(v.y * uu - u.y * vv, u.x * vv - v.x * uu) / d;
    (a + x, x.length())
}

/// Minimum enclosing sphere (Welzl's algorithm, iterative form with the points in random order):
/// centre and radius. A point counts as inside within `tol`.
fn min_sphere(p: &[DVec3], tol: f64) -> (DVec3, f64) {
    let Some(&first) = p.first() else {
        return (DVec3::ZERO, 0.0);
    };
    let (mut c, mut r) = (first, 0.0);
    let out = |c: DVec3, r: f64, q: DVec3| q.distance(c) > r + tol;
    for i in 1..p.len() {
        if !out(c, r, p[i]) {
            continue;
        }
        (c, r) = (p[i], 0.0);
        for j in 0..i {
            if !out(c, r, p[j]) {
                continue;
            }
            (c, r) = ((p[i] + p[j]) * 0.5, p[i].distance(p[j]) * 0.5);
            for k in 0..j {
                if !out(c, r, p[k]) {
                    continue;
                }
                (c, r) = sphere3(p[i], p[j], p[k]);
                for l in 0..k {
                    if out(c, r, p[l]) {
                        (c, r) = sphere4(p[i], p[j], p[k], p[l], tol);
                    }
                }
            }
        }
    }
    (c, r)
}

/// The smallest sphere through three points: their circumcircle (the farthest pair's sphere when
/// they are collinear).
fn sphere3(a: DVec3, b: DVec3, c: DVec3) -> (DVec3, f64) {
    let (u, v) = (b - a, c - a);
    let w = u.cross(v);
    let ww = w.length_squared();
    if ww <= 1e-28 * u.length_squared().max(v.length_squared()).powi(2) {
        let pairs = [(a, b), (a, c), (b, c)];
        let (p, q) = pairs.into_iter().fold((a, b), |m, x| if x.0.distance(x.1) > m.0.distance(m.1) { x } else { m });
        return ((p + q) * 0.5, p.distance(q) * 0.5);
    }
    // circumcentre − a = (|u|² (v × w) + |v|² (w × u)) / (2 |w|²), w = u × v
    let x = (v.cross(w) * u.length_squared() + w.cross(u) * v.length_squared()) / (2.0 * ww);
    (a + x, x.length())
}

/// The sphere through four points (when they are nearly coplanar: the smallest of the spheres of
/// three of them that covers the fourth).
fn sphere4(a: DVec3, b: DVec3, c: DVec3, d: DVec3, tol: f64) -> (DVec3, f64) {
    let (u, v, w) = (b - a, c - a, d - a);
    let det = u.dot(v.cross(w));
    let scale = u.length() * v.length() * w.length();
    if det.abs() > 1e-12 * scale {
        // x = centre − a solves 2u·x = |u|², 2v·x = |v|², 2w·x = |w|² (Cramer):
        // x = (|u|² (v × w) + |v|² (w × u) + |w|² (u × v)) / (2 u·(v × w))
        let x = (v.cross(w) * u.length_squared() + w.cross(u) * v.length_squared() + u.cross(v) * w.length_squared()) / (2.0 * det);
        return (a + x, x.length());
    }
    let all = [a, b, c, d];
    let mut best = (a, f64::INFINITY);
    for skip in 0..4 {
        let t: Vec<DVec3> = (0..4).filter(|&i| i != skip).map(|i| all[i]).collect();
        let (c, r) = sphere3(t[0], t[1], t[2]);
        if all[skip].distance(c) <= r + tol && r < best.1 {
            best = (c, r);
        }
    }
    if best.1.is_finite() {
        best
    } else {
        // no three of them cover the fourth (cannot happen for coplanar points in exact
        // arithmetic): the farthest pair's sphere, grown to cover all four
        let c = all.iter().copied().sum::<DVec3>() / 4.0;
        (c, all.iter().map(|p| p.distance(c)).fold(0.0, f64::max))
    }
}

/// Deterministic points of the primitive's surface (primitive frame) where its gap to the hull
/// can be largest: a box's 8 corners; a sphere's Fibonacci lattice plus its 6 poles; a capsule's
/// two hemispherical caps (Fibonacci lattices on each plus the rim circles and the poles).
fn surface_samples(shape: &FittedShape) -> Vec<DVec3> {
    match *shape {
        FittedShape::Box { half_extents: h } => {
            (0..8).map(|i| DVec3::new(if i & 1 == 0 { -h.x } else { h.x }, if i & 2 == 0 { -h.y } else { h.y }, if i & 4 == 0 { -h.z } else { h.z })).collect()
        }
        FittedShape::Sphere { radius } => {
            let mut s: Vec<DVec3> = fibonacci(GAP_SAMPLES, -1.0).into_iter().map(|u| u * radius).collect();
            s.extend([DVec3::X, DVec3::NEG_X, DVec3::Y, DVec3::NEG_Y, DVec3::Z, DVec3::NEG_Z].map(|u| u * radius));
            s
        }
        FittedShape::Cylinder { radius, half_length } => {
            // the extreme points are the two rim circles
            let n = GAP_SAMPLES / 2;
            let mut s = Vec::with_capacity(2 * n);
            for k in 0..n {
                let a = k as f64 * std::f64::consts::TAU / n as f64;
                for z in [-half_length, half_length] {
                    s.push(DVec3::new(radius * a.cos(), radius * a.sin(), z));
                }
            }
            s
        }
        FittedShape::Capsule { radius, half_length } => {
            let mut cap = fibonacci(GAP_SAMPLES, 0.0); // upper unit hemisphere
            cap.push(DVec3::Z);
            for k in 0..64 {
                let a = k as f64 * std::f64::consts::TAU / 64.0;
                cap.push(DVec3::new(a.cos(), a.sin(), 0.0)); // the rim
            }
            let mut s = Vec::with_capacity(2 * cap.len());
            for u in cap {
                s.push(u * radius + DVec3::Z * half_length);
                s.push(DVec3::new(u.x, u.y, -u.z) * radius - DVec3::Z * half_length);
            }
            s
        }
    }
}

/// `n` nearly evenly spread unit vectors with z in [z_min, 1] (Fibonacci lattice: z evenly spaced,
/// azimuth stepped by the golden angle).
fn fibonacci(n: usize, z_min: f64) -> Vec<DVec3> {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt()); // 2π (1 − 1/φ)
    (0..n)
        .map(|i| {
            let z = 1.0 - (1.0 - z_min) * (i as f64 + 0.5) / n as f64;
            let rho = (1.0 - z * z).max(0.0).sqrt();
            let a = i as f64 * golden;
            DVec3::new(rho * a.cos(), rho * a.sin(), z)
        })
        .collect()
}
