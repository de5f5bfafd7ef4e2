//! The 3D convex hull of a point cloud: quickhull with conflict (outside) lists, on exact
//! orientation predicates.
//!
//! Algorithm (Barber, Dobkin & Huhdanpaa 1996):
//! 1. The points are centred on their bounding box and snapped to an integer grid of
//!    2 × 2^[`GRID_BITS`] steps across the box's largest side (a step is ≈ 1.8e-12 of the
//!    extent); points that snap together are one point.
//! 2. An initial tetrahedron: the two farthest-apart of the six axis-extreme points, the point
//!    farthest from their line, the point farthest from the plane of those three. Every other
//!    point goes to the outside list of the face it is farthest above, if it is above any.
//! 3. While a face has outside points: its farthest point is the eye; the faces that the eye is
//!    strictly above (it sees) are found by a breadth-first walk from that face; the boundary of
//!    that region (the horizon, one closed loop of edges) is joined to the eye by new faces; the
//!    seen faces' outside points move to the new face they are farthest above, or are dropped
//!    (they are inside the hull now).
//!
//! Robustness: "is d above the plane of (a, b, c)" is the sign of a 3×3 determinant of grid
//! coordinates (|coordinate| ≤ 2^39, so the determinant fits an i128), evaluated in floating
//! point when that is certain (Shewchuk's error bound) and exactly in i128 otherwise. So every
//! decision is exact for the snapped points and consistent with every other: the seen region is
//! always a disc, coplanar points (a box's faces), collinear points, duplicates and float32
//! noise need no tolerance, and the hull is the exact hull of the snapped points (coplanar
//! facets come triangulated; near-coplanar noisy points are vertices, as they should be). The
//! output's vertices are the original points (each snapped point's first original), so every
//! input point is inside the hull or within [`ConvexHull::tolerance`] (a few grid steps) of it.
//! Distances used only to choose (the farthest point) are plain floating point.
//!
//! Degenerate input is an error, not a hull of volume 0: no points, a non-finite coordinate, or
//! points that are all one point, on a line, or flat (thinner than [`FLAT_REL`] × extent) give an
//! `Err` with a one-line reason, e.g. "the vertices are flat (thickness 1.2e-12 m for an extent of
//! 3.0e-2 m); expected a solid".

use std::collections::HashMap;

use glam::{DMat3, DVec3};

/// The snapping grid: coordinates (centred on the bounding box) become integers within
/// ±2^GRID_BITS, so that the orientation determinant (three factors of differences ≤ 2^40, six
/// terms) stays below 2^123 and fits an i128 exactly.
pub const GRID_BITS: i32 = 39;

/// A point cloud whose points all lie within `FLAT_REL × extent` of a line or a plane (extent:
/// the diagonal of its bounding box) has no hull (an error): it is flat, not a solid.
pub const FLAT_REL: f64 = 1e-9;

/// The convex hull of a point cloud: a closed triangle mesh, faces counter-clockwise seen from
/// outside (outward normals by the right-hand rule).
#[derive(Clone, Debug, PartialEq)]
pub struct ConvexHull {
    /// The hull's vertices (a subset of the input points, exact copies).
    pub vertices: Vec<DVec3>,
    /// Triangles as indices into `vertices`, counter-clockwise seen from outside.
    pub faces: Vec<[usize; 3]>,
    /// Unit outward normal of each face (computed exactly on the grid, then rounded).
    pub normals: Vec<DVec3>,
    /// Enclosed volume (units³).
    pub volume: f64,
    /// Surface area (units²).
    pub area: f64,
    /// How far outside the hull an input point can be (snapping to the grid and rounding: 8 grid
    /// steps plus 64 ulps of the largest coordinate).
    pub tolerance: f64,
}

/// A grid point.
type Grid = [i64; 3];

/// The sign of det[b − a; c − a; d − a] = ((b − a) × (c − a)) · (d − a): > 0 where d is above the
/// plane of (a, b, c) (on the side of its counter-clockwise normal). Exact: floating point where
/// Shewchuk's bound makes the sign certain, i128 otherwise.
fn orient(a: &Grid, b: &Grid, c: &Grid, d: &Grid) -> i32 {
    let u = [b[0] - a[0], b[1] - a[1], b[2] - a[2]]; // |·| ≤ 2^40: exact in i64 and in f64
    let v = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
    let w = [d[0] - a[0], d[1] - a[1], d[2] - a[2]];
    let f = |x: &[i64; 3]| [x[0] as f64, x[1] as f64, x[2] as f64];
    let (uf, vf, wf) = (f(&u), f(&v), f(&w));
    // det = u · (v × w) and its permanent (the same with absolute values)
    let det = uf[0] * (vf[1] * wf[2] - vf[2] * wf[1]) - uf[1] * (vf[0] * wf[2] - vf[2] * wf[0]) + uf[2] * (vf[0] * wf[1] - vf[1] * wf[0]);
    let perm = uf[0].abs() * ((vf[1] * wf[2]).abs() + (vf[2] * wf[1]).abs())
        + uf[1].abs() * ((vf[0] * wf[2]).abs() + (vf[2] * wf[0]).abs())
        + uf[2].abs() * ((vf[0] * wf[1]).abs() + (vf[1] * wf[0]).abs());
    let bound = 8.0 * f64::EPSILON * perm; // ≥ Shewchuk's orient3d bound (7 + 56ε)ε · permanent
    if det > bound {
        return 1;
    }
    if det < -bound {
        return -1;
    }
    let i = |x: &[i64; 3]| [x[0] as i128, x[1] as i128, x[2] as i128];
    let (u, v, w) = (i(&u), i(&v), i(&w));
    let exact = u[0] * (v[1] * w[2] - v[2] * w[1]) - u[1] * (v[0] * w[2] - v[2] * w[0]) + u[2] * (v[0] * w[1] - v[1] * w[0]);
    exact.signum() as i32
}

/// One face while the hull is built.
struct Face {
    /// Corners, counter-clockwise seen from outside.
    v: [usize; 3],
    /// Unit outward normal, from the exact grid cross product (b − a) × (c − a).
    n: DVec3,
    /// `adj[e]`: the face across edge (v[e], v[e+1]).
    adj: [usize; 3],
    /// Points strictly above this face (its conflict list).
    outside: Vec<usize>,
    alive: bool,
}

impl Face {
    fn new(g: &[Grid], v: [usize; 3]) -> Face {
        let (a, b, c) = (g[v[0]], g[v[1]], g[v[2]]);
        let u = [(b[0] - a[0]) as i128, (b[1] - a[1]) as i128, (b[2] - a[2]) as i128];
        let w = [(c[0] - a[0]) as i128, (c[1] - a[1]) as i128, (c[2] - a[2]) as i128];
        // |n| = 2·area, along the outward normal for counter-clockwise corners
        let n = [u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2], u[0] * w[1] - u[1] * w[0]];
        let n = DVec3::new(n[0] as f64, n[1] as f64, n[2] as f64);
        Face { v, n: n.normalize_or_zero(), adj: [usize::MAX; 3], outside: Vec::new(), alive: true }
    }

    /// Whether grid point `d` is strictly above the face (exact).
    fn sees(&self, g: &[Grid], d: usize) -> bool {
        orient(&g[self.v[0]], &g[self.v[1]], &g[self.v[2]], &g[d]) > 0
    }

    /// Distance (grid units, rounded) of `p` above the face's plane: for choosing only.
    fn height(&self, gf: &[DVec3], p: DVec3) -> f64 {
        self.n.dot(p - gf[self.v[0]])
    }
}

fn bounds(points: &[DVec3]) -> (DVec3, DVec3) {
    points.iter().fold((DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)), |(lo, hi), p| (lo.min(*p), hi.max(*p)))
}

/// The convex hull of `points` (any number ≥ 4 spanning a solid; duplicates, coplanar and
/// collinear points are fine). Errors (one line) for no points, a non-finite coordinate, or
/// points that are all one point, on a line or flat (see the module docs).
pub fn convex_hull(points: &[DVec3]) -> Result<ConvexHull, String> {
    if points.is_empty() {
        return Err("no vertices; expected points spanning a solid".to_string());
    }
    if let Some(p) = points.iter().find(|p| !p.is_finite()) {
        return Err(format!("a vertex has a non-finite coordinate ({p}); expected finite coordinates"));
    }
    let (lo, hi) = bounds(points);
    let mid = (lo + hi) * 0.5;
    let extent = (hi - lo).length();
    let half = ((hi - lo) * 0.5).max_element();
    if half == 0.0 {
        return Err(format!("the vertices are all one point ({}); expected a solid", points[0]));
    }
    // grid: x ↦ round((x − mid) · 2^GRID_BITS / half) ∈ [−2^GRID_BITS, 2^GRID_BITS]
    let scale = 2f64.powi(GRID_BITS) / half;
    let step = 1.0 / scale;
    let snapped: Vec<Grid> = points.iter().map(|p| ((*p - mid) * scale).round().to_array().map(|x| x as i64)).collect();
    let mut order: Vec<usize> = (0..points.len()).collect();
    order.sort_by_key(|&i| (snapped[i], i));
    order.dedup_by(|a, b| snapped[*a] == snapped[*b]); // keeps each grid point's first original
    let g: Vec<Grid> = order.iter().map(|&i| snapped[i]).collect();
    let gf: Vec<DVec3> = g.iter().map(|x| DVec3::new(x[0] as f64, x[1] as f64, x[2] as f64)).collect(); // exact
    let flat = FLAT_REL * extent * scale; // in grid units

    // --- the initial tetrahedron
    let mut ext = [0usize; 6]; // argmin x, argmax x, argmin y, …
    for (i, p) in g.iter().enumerate() {
        for k in 0..3 {
            if p[k] < g[ext[2 * k]][k] {
                ext[2 * k] = i;
            }
            if p[k] > g[ext[2 * k + 1]][k] {
                ext[2 * k + 1] = i;
            }
        }
    }
    let (mut i0, mut i1, mut span) = (ext[0], ext[0], -1.0);
    for a in 0..6 {
        for b in a + 1..6 {
            let d = gf[ext[a]].distance(gf[ext[b]]);
            if d > span {
                (i0, i1, span) = (ext[a], ext[b], d);
            }
        }
    }
    if span <= flat {
        return Err(format!("the vertices are all one point ({}); expected a solid", points[order[i0]]));
    }
    let dir = (gf[i1] - gf[i0]) / span;
    let off_line = |p: DVec3| {
        let r = p - gf[i0];
        (r - dir * r.dot(dir)).length() // distance from the line through i0, i1
    };
    let i2 = (0..g.len()).max_by(|&a, &b| off_line(gf[a]).total_cmp(&off_line(gf[b]))).unwrap_or(0);
    let width = off_line(gf[i2]);
    if width <= flat {
        return Err(format!(
            "the vertices are on a line (within {:.1e} m over a length of {:.1e} m); expected a solid",
            width * step,
            span * step
        ));
    }
    let n = (gf[i1] - gf[i0]).cross(gf[i2] - gf[i0]).normalize();
    let sd = |p: DVec3| n.dot(p - gf[i0]); // signed distance from the plane of i0, i1, i2
    let (mut i3, mut lo_sd, mut hi_sd) = (i0, 0.0f64, 0.0f64);
    for (i, p) in gf.iter().enumerate() {
        let d = sd(*p);
        lo_sd = lo_sd.min(d);
        hi_sd = hi_sd.max(d);
        if d.abs() > sd(gf[i3]).abs() {
            i3 = i;
        }
    }
    let side = orient(&g[i0], &g[i1], &g[i2], &g[i3]);
    if sd(gf[i3]).abs() <= flat || side == 0 {
        return Err(format!(
            "the vertices are flat (thickness {:.1e} m for an extent of {extent:.1e} m); expected a solid",
            (hi_sd - lo_sd) * step
        ));
    }
    // corners a, b, c, d with d below the plane of (a, b, c)
    let (a, mut b, mut c, d) = (i0, i1, i2, i3);
    if side > 0 {
        std::mem::swap(&mut b, &mut c);
    }
    let mut faces: Vec<Face> = [[a, b, c], [a, d, b], [b, d, c], [c, d, a]].iter().map(|v| Face::new(&g, *v)).collect();
    for f in 0..4 {
        for e in 0..3 {
            let (u, w) = (faces[f].v[e], faces[f].v[(e + 1) % 3]);
            let nb = (0..4).find(|&h| (0..3).any(|k| faces[h].v[k] == w && faces[h].v[(k + 1) % 3] == u));
            faces[f].adj[e] = nb.ok_or("convex hull: the initial tetrahedron is not closed")?;
        }
    }
    // each point to the face it is farthest above, among those it is strictly above
    let assign = |faces: &mut Vec<Face>, range: std::ops::Range<usize>, i: usize| {
        let mut best = (usize::MAX, f64::NEG_INFINITY);
        for f in range {
            if faces[f].sees(&g, i) {
                let h = faces[f].height(&gf, gf[i]);
                if h > best.1 {
                    best = (f, h);
                }
            }
        }
        if best.0 != usize::MAX {
            faces[best.0].outside.push(i);
        }
    };
    for i in 0..g.len() {
        if ![a, b, c, d].contains(&i) {
            assign(&mut faces, 0..4, i);
        }
    }

    // --- quickhull
    let mut stack: Vec<usize> = (0..4).filter(|&f| !faces[f].outside.is_empty()).collect();
    let mut mark: Vec<u64> = vec![0; faces.len()]; // mark[f] == round: f is seen this round
    let mut round = 0u64;
    while let Some(f0) = stack.pop() {
        if !faces[f0].alive || faces[f0].outside.is_empty() {
            continue;
        }
        round += 1;
        let eye = faces[f0].outside.iter().copied().fold((usize::MAX, f64::NEG_INFINITY), |m, i| {
            let h = faces[f0].height(&gf, gf[i]);
            if h > m.1 { (i, h) } else { m }
        });
        let eye = eye.0;
        // the faces the eye sees: breadth-first from f0 (with exact signs the seen region of a
        // point outside a convex polytope is one disc)
        let mut seen = vec![f0];
        mark[f0] = round;
        let mut q = 0;
        while q < seen.len() {
            let f = seen[q];
            q += 1;
            for nb in faces[f].adj {
                if mark[nb] != round && faces[nb].sees(&g, eye) {
                    mark[nb] = round;
                    seen.push(nb);
                }
            }
        }
        let horizon = horizon_loop(&faces, &seen, &mark, round)
            .map_err(|e| format!("convex hull: {e} (at point {}); this is a bug", points[order[eye]]))?;
        // the cone from the horizon to the eye: new face k = (a_k, b_k, eye), b_k = a_{k+1}
        let first = faces.len();
        let m = horizon.len();
        for (k, &(ha, hb, nb)) in horizon.iter().enumerate() {
            let mut f = Face::new(&g, [ha, hb, eye]);
            f.adj = [nb, first + (k + 1) % m, first + (k + m - 1) % m]; // across (a,b), (b,eye), (eye,a)
            for e in 0..3 {
                if faces[nb].v[e] == hb && faces[nb].v[(e + 1) % 3] == ha {
                    faces[nb].adj[e] = first + k;
                }
            }
            faces.push(f);
        }
        mark.resize(faces.len(), 0);
        // the seen faces die; their outside points move to the new faces (or are inside now)
        let mut orphans = Vec::new();
        for &f in &seen {
            faces[f].alive = false;
            orphans.append(&mut faces[f].outside);
        }
        for i in orphans {
            if i != eye {
                assign(&mut faces, first..first + m, i);
            }
        }
        stack.extend((first..faces.len()).filter(|&f| !faces[f].outside.is_empty()));
    }

    // --- the result: live faces, their vertices compacted, volume and area
    let mut index: HashMap<usize, usize> = HashMap::new();
    let mut vertices = Vec::new();
    let mut local = Vec::new(); // centred copies, for volume and area
    let mut out_faces = Vec::new();
    let mut normals = Vec::new();
    for f in faces.iter().filter(|f| f.alive) {
        let mut t = [0usize; 3];
        for (k, &v) in f.v.iter().enumerate() {
            t[k] = *index.entry(v).or_insert_with(|| {
                vertices.push(points[order[v]]);
                local.push(points[order[v]] - mid);
                vertices.len() - 1
            });
        }
        out_faces.push(t);
        normals.push(f.n);
    }
    // Euler: a closed triangulated sphere has F = 2V − 4
    if out_faces.len() + 4 != 2 * vertices.len() {
        return Err(format!(
            "convex hull: {} vertices and {} faces do not close a surface (expected {} faces); this is a bug",
            vertices.len(),
            out_faces.len(),
            2 * vertices.len() - 4
        ));
    }
    let o = local.iter().copied().sum::<DVec3>() / local.len() as f64;
    let (mut volume, mut area) = (0.0, 0.0);
    for t in &out_faces {
        let (p, q, r) = (local[t[0]] - o, local[t[1]] - o, local[t[2]] - o);
        volume += p.dot(q.cross(r)) / 6.0; // signed volume of the tetrahedron (o, p, q, r)
        area += (q - p).cross(r - p).length() / 2.0;
    }
    let tolerance = 8.0 * step + 64.0 * f64::EPSILON * lo.abs().max(hi.abs()).max_element();
    Ok(ConvexHull { vertices, faces: out_faces, normals, volume, area, tolerance })
}

/// The horizon of the seen region as one loop of edges `(from, to, unseen neighbour)`, in order
/// (`to` of one edge is `from` of the next). An error where the boundary is not one simple loop
/// (impossible with exact signs).
fn horizon_loop(faces: &[Face], seen: &[usize], mark: &[u64], round: u64) -> Result<Vec<(usize, usize, usize)>, String> {
    let mut edges = Vec::new();
    for &f in seen {
        for e in 0..3 {
            let nb = faces[f].adj[e];
            if mark[nb] != round {
                edges.push((faces[f].v[e], faces[f].v[(e + 1) % 3], nb));
            }
        }
    }
    if edges.is_empty() {
        return Err("the eye sees every face".to_string());
    }
    let mut by_from: HashMap<usize, usize> = HashMap::with_capacity(edges.len());
    for (k, e) in edges.iter().enumerate() {
        if by_from.insert(e.0, k).is_some() {
            return Err("the seen region pinches at a vertex".to_string());
        }
    }
    let mut ordered = Vec::with_capacity(edges.len());
    let mut k = 0;
    loop {
        ordered.push(edges[k]);
        match by_from.get(&edges[k].1) {
            Some(&0) => break,
            Some(&next) if ordered.len() < edges.len() => k = next,
            _ => return Err("the horizon is not a closed loop".to_string()),
        }
    }
    if ordered.len() != edges.len() {
        return Err("the seen region has a hole".to_string());
    }
    Ok(ordered)
}

/// Exact distances from points to a hull's surface (bounding balls of the faces, a scratch list of
/// plane distances).
struct NearestFace<'a> {
    hull: &'a ConvexHull,
    /// A bounding ball of each face (centroid, farthest corner): |p − c| − r ≤ distance to it.
    balls: Vec<(DVec3, f64)>,
    /// Plane distances of the current point.
    h: Vec<f64>,
}

impl<'a> NearestFace<'a> {
    fn new(hull: &'a ConvexHull) -> NearestFace<'a> {
        let v = &hull.vertices;
        let balls = hull
            .faces
            .iter()
            .map(|f| {
                let c = (v[f[0]] + v[f[1]] + v[f[2]]) / 3.0;
                (c, f.iter().map(|&i| v[i].distance(c)).fold(0.0, f64::max))
            })
            .collect();
        NearestFace { hull, balls, h: vec![0.0; hull.faces.len()] }
    }

    fn distance(&mut self, p: DVec3) -> f64 {
        let hull = self.hull;
        // plane distances; the largest is a lower bound of the distance (the hull lies behind
        // every face's plane)
        let mut top = (0, f64::NEG_INFINITY);
        for (k, (f, n)) in hull.faces.iter().zip(&hull.normals).enumerate() {
            self.h[k] = n.dot(p - hull.vertices[f[0]]);
            if self.h[k] > top.1 {
                top = (k, self.h[k]);
            }
        }
        if top.1 <= 0.0 {
            return 0.0; // behind every face: inside
        }
        // Outside a convex polytope the nearest point lies on a face whose plane p is above
        // (p − x is a non-negative mix of the normals of the faces at x, and |p − x|² > 0). Faces
        // up to `tolerance` below p are searched too, so that rounding does not drop the nearest
        // face of a point on the surface (any superset of the faces above p gives the exact
        // distance). Start from the face p is farthest above (often the nearest); skip faces whose
        // plane or bounding ball is farther than the best so far.
        let tri = |k: usize| {
            let f = hull.faces[k];
            point_triangle_distance(p, hull.vertices[f[0]], hull.vertices[f[1]], hull.vertices[f[2]])
        };
        let mut best = tri(top.0);
        for k in 0..hull.faces.len() {
            if self.h[k] > -hull.tolerance && self.h[k] < best && p.distance(self.balls[k].0) - self.balls[k].1 < best {
                best = best.min(tri(k));
            }
        }
        best
    }
}

impl ConvexHull {
    /// The largest signed distance of `p` above the faces' planes: ≤ 0 inside the hull, and the
    /// distance itself where the nearest point of the hull is inside a face.
    pub fn plane_distance(&self, p: DVec3) -> f64 {
        self.faces
            .iter()
            .zip(&self.normals)
            .map(|(f, n)| n.dot(p - self.vertices[f[0]]))
            .fold(f64::NEG_INFINITY, f64::max)
    }

    /// Whether `p` is inside the hull or within `tol` of its faces' planes.
    pub fn contains(&self, p: DVec3, tol: f64) -> bool {
        self.plane_distance(p) <= tol
    }

    /// The distance from `p` to the hull: 0 inside, else the distance to the nearest point of
    /// its surface. (For many points, [`ConvexHull::distances`] is faster.)
    pub fn distance(&self, p: DVec3) -> f64 {
        self.distances(&[p])[0]
    }

    /// [`ConvexHull::distance`] of each point.
    pub fn distances(&self, points: &[DVec3]) -> Vec<f64> {
        let mut q = NearestFace::new(self);
        points.iter().map(|&p| q.distance(p)).collect()
    }

    /// The largest [`ConvexHull::distance`] of `points` (0 for none), exact but without computing
    /// every distance: an upper bound of each (the distance to the nearest of up to 256 extreme
    /// vertices) orders them, and the exact distances are computed, largest bound first, until the
    /// next bound is no larger than the largest distance found.
    pub fn max_distance(&self, points: &[DVec3]) -> f64 {
        let probes: Vec<DVec3> = if self.vertices.len() <= 256 {
            self.vertices.clone()
        } else {
            // the vertices extreme along 256 evenly spread directions (Fibonacci lattice)
            let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
            let mut pick: Vec<usize> = (0..256)
                .map(|i| {
                    let z = 1.0 - 2.0 * (i as f64 + 0.5) / 256.0;
                    let rho = (1.0 - z * z).sqrt();
                    let u = DVec3::new(rho * (i as f64 * golden).cos(), rho * (i as f64 * golden).sin(), z);
                    (0..self.vertices.len()).fold(0, |m, k| if u.dot(self.vertices[k]) > u.dot(self.vertices[m]) { k } else { m })
                })
                .collect();
            pick.sort_unstable();
            pick.dedup();
            pick.into_iter().map(|k| self.vertices[k]).collect()
        };
        // bound ≥ distance: the probes are points of the hull
        let mut order: Vec<(f64, DVec3)> = points.iter().map(|&p| (probes.iter().map(|v| v.distance(p)).fold(f64::INFINITY, f64::min), p)).collect();
        order.sort_by(|a, b| b.0.total_cmp(&a.0));
        let mut q = NearestFace::new(self);
        let mut best = 0.0f64;
        for (bound, p) in order {
            if bound <= best {
                break;
            }
            best = best.max(q.distance(p));
        }
        best
    }

    /// The principal axes of the hull's surface (a uniform density on its triangles; stable
    /// against uneven vertex density, unlike the vertices' covariance): the surface centroid,
    /// the axes as the columns of a rotation (right-handed; largest variance first) and the
    /// variances along them.
    pub fn principal_axes(&self) -> (DVec3, DMat3, DVec3) {
        let o = self.vertices.iter().copied().sum::<DVec3>() / self.vertices.len() as f64; // reference, against cancellation
        let mut total = 0.0;
        let mut m1 = DVec3::ZERO;
        let mut m2 = [[0.0f64; 3]; 3];
        for f in &self.faces {
            let (a, b, c) = (self.vertices[f[0]] - o, self.vertices[f[1]] - o, self.vertices[f[2]] - o);
            let area = (b - a).cross(c - a).length() / 2.0;
            let s = a + b + c;
            total += area;
            m1 += s * (area / 3.0); // ∫ x dA = A·(a + b + c)/3
            for i in 0..3 {
                for j in 0..3 {
                    // ∫ x xᵀ dA = A/12 · (a aᵀ + b bᵀ + c cᵀ + s sᵀ), s = a + b + c
                    m2[i][j] += area / 12.0 * (a[i] * a[j] + b[i] * b[j] + c[i] * c[j] + s[i] * s[j]);
                }
            }
        }
        let mean = m1 / total;
        let mut cov = [[0.0f64; 3]; 3];
        for i in 0..3 {
            for j in 0..3 {
                cov[i][j] = m2[i][j] / total - mean[i] * mean[j]; // Σ = E[x xᵀ] − μ μᵀ
            }
        }
        let (values, axes) = symmetric_eigen(cov);
        (mean + o, axes, values)
    }
}

/// Eigen-decomposition of a symmetric 3×3 matrix (cyclic Jacobi): eigenvalues in descending
/// order and the unit eigenvectors as the columns of a right-handed rotation.
pub fn symmetric_eigen(m: [[f64; 3]; 3]) -> (DVec3, DMat3) {
    let mut a = m;
    let mut v = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]; // v[row][col], columns = eigenvectors
    let scale: f64 = a.iter().flatten().map(|x| x * x).sum();
    for _sweep in 0..64 {
        let off = a[0][1] * a[0][1] + a[0][2] * a[0][2] + a[1][2] * a[1][2];
        if off <= 1e-32 * scale || off == 0.0 {
            break;
        }
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            if a[p][q] == 0.0 {
                continue;
            }
            // the rotation J in the (p, q) plane that zeroes a_pq in Jᵀ A J:
            // θ = (a_qq − a_pp) / (2 a_pq), t = tan φ = sgn θ / (|θ| + √(θ² + 1))
            let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
            let t = if theta >= 0.0 { 1.0 } else { -1.0 } / (theta.abs() + (theta * theta + 1.0).sqrt());
            let c = 1.0 / (t * t + 1.0).sqrt();
            let s = t * c;
            for row in a.iter_mut() {
                // A ← A J (columns p, q)
                let (akp, akq) = (row[p], row[q]);
                row[p] = c * akp - s * akq;
                row[q] = s * akp + c * akq;
            }
            // A ← Jᵀ A (rows p, q)
            let (rp, rq) = (a[p], a[q]);
            a[p] = std::array::from_fn(|k| c * rp[k] - s * rq[k]);
            a[q] = std::array::from_fn(|k| s * rp[k] + c * rq[k]);
            for row in v.iter_mut() {
                // V ← V J
                let (vkp, vkq) = (row[p], row[q]);
                row[p] = c * vkp - s * vkq;
                row[q] = s * vkp + c * vkq;
            }
        }
    }
    let mut idx = [0usize, 1, 2];
    idx.sort_by(|&i, &j| a[j][j].total_cmp(&a[i][i]));
    let col = |k: usize| DVec3::new(v[0][k], v[1][k], v[2][k]).normalize();
    let (x, y) = (col(idx[0]), col(idx[1]));
    let z = x.cross(y).normalize(); // right-handed (a sign flip of an eigenvector is still one)
    let y = z.cross(x);
    (DVec3::new(a[idx[0]][idx[0]], a[idx[1]][idx[1]], a[idx[2]][idx[2]]), DMat3::from_cols(x, y, z))
}

/// The distance from `p` to the triangle (a, b, c) (Ericson, Real-Time Collision Detection §5.1.5:
/// the nearest point is found by the Voronoi region of p among the corners, edges and inside).
pub fn point_triangle_distance(p: DVec3, a: DVec3, b: DVec3, c: DVec3) -> f64 {
    p.distance(closest_point_on_triangle(p, a, b, c))
}

/// The point of the triangle (a, b, c) nearest to `p`.
pub fn closest_point_on_triangle(p: DVec3, a: DVec3, b: DVec3, c: DVec3) -> DVec3 {
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(ap), ac.dot(ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return a; // corner a
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(bp), ac.dot(bp));
    if d3 >= 0.0 && d4 <= d3 {
        return b; // corner b
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return a + ab * (d1 / (d1 - d3)); // edge ab
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(cp), ac.dot(cp));
    if d6 >= 0.0 && d5 <= d6 {
        return c; // corner c
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return a + ac * (d2 / (d2 - d6)); // edge ac
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && d4 - d3 >= 0.0 && d5 - d6 >= 0.0 {
        return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6))); // edge bc
    }
    let denom = va + vb + vc;
    if denom.abs() <= 0.0 || !denom.is_finite() {
        // a triangle of zero area: the nearest of its corners
        return [a, b, c].into_iter().fold(a, |m, x| if x.distance(p) < m.distance(p) { x } else { m });
    }
    a + ab * (vb / denom) + ac * (vc / denom) // inside: barycentric (u, v, w) = (va, vb, vc) / Σ
}
