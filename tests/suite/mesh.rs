//! The mesh module: reading STL/OBJ, the convex hull, and the primitive fits (sphere, capsule,
//! oriented box) that contain every vertex and are tighter than the axis-aligned ones; triangle
//! meshes and their mass properties.

use std::path::{Path, PathBuf};

use dextrain::mesh::fit::{FittedShape, PrimitiveFit, PrimitiveKind, axis_aligned, fit, fit_tightest, fit_with_hull};
use dextrain::mesh::hull::convex_hull;
use dextrain::mesh::mass::{MassProperties, combine, is_closed, mass_properties};
use dextrain::mesh::read::{TriangleMesh, parse_obj, parse_obj_pieces, parse_stl, parse_stl_mesh};
use glam::{DMat3, DQuat, DVec3};

const KINDS: [PrimitiveKind; 3] = [PrimitiveKind::Sphere, PrimitiveKind::Capsule, PrimitiveKind::Box];

/// A deterministic pseudo-random stream (64-bit LCG, Knuth's MMIX constants; top 53 bits).
struct Lcg(u64);

impl Lcg {
    fn new(seed: u64) -> Lcg {
        let mut l = Lcg(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ 0xD1B5_4A32_D192_ED03);
        l.next();
        l
    }
    /// Uniform in [0, 1).
    fn next(&mut self) -> f64 {
        self.0 = self.0.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
    /// Uniform in [a, b).
    fn range(&mut self, a: f64, b: f64) -> f64 {
        a + (b - a) * self.next()
    }
    /// Uniform in the unit ball (rejection).
    fn in_ball(&mut self) -> DVec3 {
        loop {
            let p = DVec3::new(self.range(-1.0, 1.0), self.range(-1.0, 1.0), self.range(-1.0, 1.0));
            if p.length_squared() <= 1.0 {
                return p;
            }
        }
    }
    /// A rotation about a random axis by a random angle.
    fn rotation(&mut self) -> DQuat {
        let axis = loop {
            let a = self.in_ball();
            if a.length() > 0.1 {
                break a.normalize();
            }
        };
        DQuat::from_axis_angle(axis, self.range(0.3, 3.0))
    }
}

fn moved(points: &[DVec3], rot: DQuat, t: DVec3) -> Vec<DVec3> {
    points.iter().map(|p| rot * *p + t).collect()
}

fn extent(points: &[DVec3]) -> f64 {
    let (lo, hi) = points.iter().fold((DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)), |(lo, hi), p| (lo.min(*p), hi.max(*p)));
    (hi - lo).length()
}

/// Panics naming the first vertex outside `f` (tolerance 1e-9 × the cloud's extent).
fn assert_contains_all(f: &PrimitiveFit, points: &[DVec3], what: &str) {
    let tol = 1e-9 * extent(points);
    if let Some(p) = points.iter().find(|p| !f.contains(**p, tol)) {
        panic!("{what}: {:?} does not contain vertex {p} (tolerance {tol:e}): {f:?}", f.kind());
    }
}

/// The 8 corners, `n` points on the faces (some on the edges) and `n` inside of the box [−h, h].
fn box_cloud(h: DVec3, n: usize, rng: &mut Lcg) -> Vec<DVec3> {
    let sign = |bit: bool, x: f64| if bit { x } else { -x };
    let mut v: Vec<DVec3> = (0..8).map(|i| DVec3::new(sign(i & 1 != 0, h.x), sign(i & 2 != 0, h.y), sign(i & 4 != 0, h.z))).collect();
    for i in 0..n {
        let mut p = DVec3::new(rng.range(-h.x, h.x), rng.range(-h.y, h.y), rng.range(-h.z, h.z));
        let k = i % 3;
        p[k] = if rng.next() < 0.5 { -h[k] } else { h[k] }; // onto a face
        if i % 7 == 0 {
            let j = (k + 1) % 3;
            p[j] = if rng.next() < 0.5 { -h[j] } else { h[j] }; // onto an edge
        }
        v.push(p);
        v.push(DVec3::new(rng.range(-h.x, h.x), rng.range(-h.y, h.y), rng.range(-h.z, h.z)));
    }
    v
}

/// A cylinder along z of radius r and half length hh: both rim circles (`rim` points each), points
/// on the side and the end discs, and inside.
fn cylinder_cloud(r: f64, hh: f64, rim: usize, rng: &mut Lcg) -> Vec<DVec3> {
    let mut v = Vec::new();
    for k in 0..rim {
        let a = k as f64 * std::f64::consts::TAU / rim as f64;
        v.push(DVec3::new(r * a.cos(), r * a.sin(), hh));
        v.push(DVec3::new(r * a.cos(), r * a.sin(), -hh));
    }
    for _ in 0..400 {
        let a = rng.range(0.0, std::f64::consts::TAU);
        v.push(DVec3::new(r * a.cos(), r * a.sin(), rng.range(-hh, hh))); // side
        let s = r * rng.next().sqrt();
        v.push(DVec3::new(s * a.cos(), s * a.sin(), if rng.next() < 0.5 { hh } else { -hh })); // end discs
        v.push(DVec3::new(s * a.cos(), s * a.sin(), rng.range(-hh, hh))); // inside
    }
    v
}

/// `n` points evenly spread on the sphere of radius r about c (Fibonacci lattice).
fn sphere_cloud(n: usize, r: f64, c: DVec3) -> Vec<DVec3> {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    (0..n)
        .map(|i| {
            let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
            let rho = (1.0 - z * z).sqrt();
            let a = i as f64 * golden;
            c + DVec3::new(rho * a.cos(), rho * a.sin(), z) * r
        })
        .collect()
}

fn sorted(v: DVec3) -> [f64; 3] {
    let mut a = v.to_array();
    a.sort_by(f64::total_cmp);
    a
}

// ------------------------------------------------------------------------------------------ hull

/// A unit cube's 8 corners, each three times, with points on its faces and edges and inside: the
/// hull is the cube (8 vertices, 12 faces, volume 1, area 6), every face outward.
#[test]
fn hull_of_a_cube_with_duplicates_coplanar_and_interior_points() {
    let mut rng = Lcg::new(1);
    let corner = |i: usize| DVec3::new((i & 1) as f64, ((i >> 1) & 1) as f64, ((i >> 2) & 1) as f64);
    let mut v = Vec::new();
    for _ in 0..3 {
        v.extend((0..8).map(corner));
    }
    v.extend(box_cloud(DVec3::splat(0.5), 300, &mut rng).into_iter().map(|p| p + 0.5));
    let t = DVec3::new(3.0, -2.0, 0.7);
    let v: Vec<DVec3> = v.iter().map(|p| *p + t).collect();
    let h = convex_hull(&v).expect("hull");
    assert_eq!((h.vertices.len(), h.faces.len()), (8, 12), "{h:?}");
    assert!((h.volume - 1.0).abs() < 1e-12, "volume {}", h.volume);
    assert!((h.area - 6.0).abs() < 1e-12, "area {}", h.area);
    let centre = t + 0.5;
    for (f, n) in h.faces.iter().zip(&h.normals) {
        let (a, b, c) = (h.vertices[f[0]], h.vertices[f[1]], h.vertices[f[2]]);
        let cross = (b - a).cross(c - a);
        assert!(cross.dot(*n) > 0.0 && n.dot(a - centre) > 0.4, "face {f:?} is not counter-clockwise from outside");
    }
    assert!(v.iter().all(|p| h.contains(*p, 1e-12)));
    assert_eq!(h.distance(centre), 0.0);
    assert!((h.distance(t + DVec3::new(2.0, 0.5, 0.5)) - 1.0).abs() < 1e-12, "distance to a face");
    assert!((h.distance(t + DVec3::new(2.0, 2.0, 0.5)) - 2f64.sqrt()).abs() < 1e-12, "distance to an edge");
}

/// A regular icosahedron of edge a (rotated, moved, with points inside): volume 5/12·(3 + √5)·a³,
/// area 5√3·a², 12 vertices and 20 faces.
#[test]
fn hull_of_a_regular_icosahedron() {
    let phi = (1.0 + 5f64.sqrt()) / 2.0;
    let mut v = Vec::new();
    for s1 in [-1.0, 1.0] {
        for s2 in [-1.0, 1.0] {
            v.push(DVec3::new(0.0, s1, s2 * phi));
            v.push(DVec3::new(s1, s2 * phi, 0.0));
            v.push(DVec3::new(s2 * phi, 0.0, s1));
        }
    }
    let mut rng = Lcg::new(2);
    for _ in 0..200 {
        v.push(rng.in_ball() * 0.7); // the inscribed sphere's radius is 1.51
    }
    let scale = 0.01; // edge 2 · 0.01 m
    let a = 2.0 * scale;
    let v: Vec<DVec3> = moved(&v, rng.rotation(), DVec3::new(0.1, 0.2, -0.3)).into_iter().map(|p| p * scale).collect();
    let h = convex_hull(&v).expect("hull");
    assert_eq!((h.vertices.len(), h.faces.len()), (12, 20));
    let volume = 5.0 / 12.0 * (3.0 + 5f64.sqrt()) * a.powi(3);
    let area = 5.0 * 3f64.sqrt() * a * a;
    assert!((h.volume / volume - 1.0).abs() < 1e-12, "volume {} vs {volume}", h.volume);
    assert!((h.area / area - 1.0).abs() < 1e-12, "area {} vs {area}", h.area);
}

/// Random clouds (a ball, a thin slab-like ellipsoid, points on a sphere, a dense cluster with a
/// few far points), several seeds: every point is inside the hull, every face has every hull
/// vertex behind it (convex), and the hull's volume is below its primitives'.
#[test]
fn hull_of_random_clouds_contains_every_point_and_is_convex() {
    for seed in 1..=5u64 {
        let mut rng = Lcg::new(seed);
        let rot = rng.rotation();
        let clouds: Vec<(&str, Vec<DVec3>)> = vec![
            ("ball", (0..3000).map(|_| rng.in_ball() * 0.03).collect()),
            ("slab", moved(&(0..2000).map(|_| rng.in_ball() * DVec3::new(0.05, 0.02, 0.001)).collect::<Vec<_>>(), rot, DVec3::new(0.3, 0.0, -0.2))),
            ("sphere", moved(&sphere_cloud(2500, 0.02, DVec3::ZERO), rot, DVec3::X)),
            ("cluster", {
                let mut v: Vec<DVec3> = (0..2000).map(|_| DVec3::splat(0.01) + rng.in_ball() * 0.002).collect();
                v.extend((0..30).map(|_| rng.in_ball() * 0.05));
                v
            }),
        ];
        for (name, v) in clouds {
            let h = convex_hull(&v).unwrap_or_else(|e| panic!("seed {seed} {name}: {e}"));
            let tol = 10.0 * h.tolerance;
            for p in &v {
                assert!(h.contains(*p, tol), "seed {seed} {name}: {p} outside by {}", h.plane_distance(*p));
            }
            for (f, n) in h.faces.iter().zip(&h.normals) {
                let a = h.vertices[f[0]];
                let worst = h.vertices.iter().map(|q| n.dot(*q - a)).fold(f64::NEG_INFINITY, f64::max);
                assert!(worst <= tol, "seed {seed} {name}: a hull vertex is {worst:e} above face {f:?}");
            }
            assert!(h.volume > 0.0 && h.area > 0.0);
            let b = axis_aligned(&v, PrimitiveKind::Box).unwrap();
            assert!(h.volume <= b.volume * (1.0 + 1e-12), "seed {seed} {name}");
            if name == "sphere" {
                // a polyhedron inscribed in the sphere: a little smaller than the ball
                let ball = 4.0 / 3.0 * std::f64::consts::PI * 0.02f64.powi(3);
                assert!(h.volume < ball && h.volume > 0.99 * ball, "seed {seed}: {} vs {ball}", h.volume);
            }
        }
    }
}

/// No points, one point, a line, a plane (turned, with noise far below FLAT_REL × extent) and
/// non-finite coordinates are errors that say what is wrong; every fit passes the error on.
#[test]
fn flat_and_degenerate_point_sets_are_errors() {
    let mut rng = Lcg::new(3);
    let rot = rng.rotation();
    let plane: Vec<DVec3> = (0..200).map(|_| rot * DVec3::new(rng.range(-0.02, 0.02), rng.range(-0.01, 0.01), rng.range(-1e-13, 1e-13))).collect();
    let line: Vec<DVec3> = (0..50).map(|i| rot * DVec3::new(i as f64 * 1e-3, 0.0, 0.0)).collect();
    let cases: Vec<(Vec<DVec3>, &str)> = vec![
        (vec![], "no vertices"),
        (vec![DVec3::new(0.1, 0.2, 0.3); 10], "all one point"),
        (line, "on a line"),
        (plane, "the vertices are flat (thickness"),
        (vec![DVec3::ZERO, DVec3::X, DVec3::Y, DVec3::new(0.0, 0.0, f64::NAN)], "non-finite"),
    ];
    for (v, want) in cases {
        let e = convex_hull(&v).unwrap_err();
        assert!(e.contains(want) && !e.contains('\n'), "{want}: {e}");
        for k in KINDS {
            assert_eq!(fit(&v, k).unwrap_err(), e, "fit passes the hull's error on");
        }
    }
    assert!(fit_tightest(&box_cloud(DVec3::ONE, 10, &mut rng), &[]).unwrap_err().contains("no primitive kinds"));
}

// ------------------------------------------------------------------------------------------- fit

/// A box cloud turned by an arbitrary rotation: the oriented box recovers the half extents and
/// the centre, sits flush (max_gap ≈ 0, volume ratio 1), and is far smaller than the axis-aligned
/// box, which sticks out at its corners.
#[test]
fn box_fit_recovers_a_rotated_box() {
    for seed in [4u64, 5, 6] {
        let mut rng = Lcg::new(seed);
        let h = DVec3::new(0.031, 0.012, 0.007);
        let rot = rng.rotation();
        let t = DVec3::new(0.02, -0.01, 0.05);
        let v = moved(&box_cloud(h, 500, &mut rng), rot, t);
        let f = fit(&v, PrimitiveKind::Box).unwrap();
        let FittedShape::Box { half_extents } = f.shape else { panic!("{f:?}") };
        for (got, want) in sorted(half_extents).iter().zip(sorted(h)) {
            assert!((got - want).abs() < 1e-9, "seed {seed}: half extents {half_extents} vs {h}");
        }
        assert!(f.centre.distance(t) < 1e-9, "seed {seed}: centre {} vs {t}", f.centre);
        assert!((f.volume_ratio() - 1.0).abs() < 1e-9 && f.max_gap < 1e-9, "seed {seed}: {f:?}");
        let a = axis_aligned(&v, PrimitiveKind::Box).unwrap();
        assert!(a.volume > 1.5 * f.volume, "seed {seed}: axis-aligned {} vs oriented {}", a.volume, f.volume);
        assert!(a.max_gap > 1e-3, "seed {seed}: the axis-aligned box's corners stick out ({})", a.max_gap);
        assert_contains_all(&f, &v, "box");
        assert_contains_all(&a, &v, "axis-aligned box");
    }
}

/// A cylinder cloud turned by an arbitrary rotation: the capsule's radius is the cylinder's, its
/// axis the cylinder's, its segment the cylinder's length (the rims sit on the caps' equators), and
/// it sticks out by exactly r (the caps' tips); it is smaller than the axis-aligned capsule. The
/// capsule-or-sphere choice takes the capsule.
#[test]
fn capsule_fit_recovers_a_rotated_cylinder() {
    for seed in [7u64, 8, 9] {
        let mut rng = Lcg::new(seed);
        let (r, hh) = (0.009, 0.022);
        let rot = rng.rotation();
        let t = DVec3::new(-0.03, 0.04, 0.01);
        let v = moved(&cylinder_cloud(r, hh, 96, &mut rng), rot, t);
        let f = fit(&v, PrimitiveKind::Capsule).unwrap();
        let FittedShape::Capsule { radius, half_length } = f.shape else { panic!("{f:?}") };
        // the segment's end is where a rim point (d ≈ r) meets the cap: w = √(r² − d²) turns a
        // rounding δ in r − d into √(2 r δ) ≈ 1e-8 m of length, hence the looser tolerance
        assert!((radius - r).abs() < 1e-12 && (half_length - hh).abs() < 1e-7, "seed {seed}: r {radius} h {half_length}");
        let axis = f.rot * DVec3::Z;
        assert!(axis.dot(rot * DVec3::Z).abs() > 1.0 - 1e-12, "seed {seed}: axis {axis}");
        assert!(f.centre.distance(t) < 1e-7, "seed {seed}: centre {}", f.centre);
        assert!((f.max_gap - r).abs() < 1e-7, "seed {seed}: max_gap {} vs r {r}", f.max_gap);
        let a = axis_aligned(&v, PrimitiveKind::Capsule).unwrap();
        assert!(a.volume > 1.2 * f.volume, "seed {seed}: axis-aligned {} vs fitted {}", a.volume, f.volume);
        assert_contains_all(&f, &v, "capsule");
        assert_contains_all(&a, &v, "axis-aligned capsule");
        let best = fit_tightest(&v, &[PrimitiveKind::Capsule, PrimitiveKind::Sphere]).unwrap();
        assert_eq!(best.kind(), PrimitiveKind::Capsule);
        assert_eq!(best, f);
    }
}

/// Points on a sphere: the capsule-or-sphere choice takes the sphere, whose centre and radius are
/// the sphere's; a capsule fit of the same points is no smaller.
#[test]
fn sphere_cloud_fits_a_sphere() {
    let (r, c) = (0.02, DVec3::new(0.1, -0.05, 0.03));
    let v = sphere_cloud(1500, r, c);
    let best = fit_tightest(&v, &[PrimitiveKind::Capsule, PrimitiveKind::Sphere]).unwrap();
    let FittedShape::Sphere { radius } = best.shape else { panic!("expected a sphere: {best:?}") };
    assert!(radius <= r * (1.0 + 1e-12) && radius > r * (1.0 - 1e-3), "radius {radius}");
    assert!(best.centre.distance(c) < 1e-3 * r, "centre {}", best.centre);
    let cap = fit(&v, PrimitiveKind::Capsule).unwrap();
    assert!(cap.volume >= best.volume * (1.0 - 1e-9), "{cap:?}");
    assert_contains_all(&best, &v, "sphere");
    assert!(best.volume_ratio() > 1.0 && best.volume_ratio() < 1.01, "{}", best.volume_ratio());
}

/// The sphere around a cube of half side h has radius √3·h and sticks out of the cube by
/// (√3 − 1)·h (along the face normals, the farthest points of the sphere from the cube); a box fit
/// of a cube has no gap. Axis-aligned cube: the sphere's poles are sampled, the gap is exact;
/// turned cube: the sampled gap is within 1 % below the truth.
#[test]
fn max_gap_of_a_sphere_around_a_cube() {
    let h = 0.01;
    let mut rng = Lcg::new(10);
    let cube = box_cloud(DVec3::splat(h), 300, &mut rng);
    let want = (3f64.sqrt() - 1.0) * h;
    for (turned, rot) in [(false, DQuat::IDENTITY), (true, rng.rotation())] {
        let t = DVec3::new(0.2, -0.1, 0.05);
        let v = moved(&cube, rot, t);
        let s = fit(&v, PrimitiveKind::Sphere).unwrap();
        let FittedShape::Sphere { radius } = s.shape else { panic!() };
        assert!((radius - 3f64.sqrt() * h).abs() < 1e-12 && s.centre.distance(t) < 1e-12, "{s:?}");
        if turned {
            assert!(s.max_gap <= want * (1.0 + 1e-9) && s.max_gap > 0.99 * want, "turned: {} vs {want}", s.max_gap);
        } else {
            assert!((s.max_gap - want).abs() < 1e-12, "{} vs {want}", s.max_gap);
        }
        let b = fit(&v, PrimitiveKind::Box).unwrap();
        assert!(b.max_gap < 1e-12 && (b.volume_ratio() - 1.0).abs() < 1e-9, "{b:?}");
        assert_contains_all(&s, &v, "sphere");
    }
}

/// Random clouds of several shapes and seeds: every fit and every axis-aligned primitive contains
/// every vertex; the fit is never bigger than the axis-aligned one of its kind nor smaller than
/// the hull; fit_tightest returns the smallest of the kinds asked for.
#[test]
fn every_fit_contains_every_vertex_of_random_clouds() {
    for seed in 11..=18u64 {
        let mut rng = Lcg::new(seed);
        let rot = rng.rotation();
        let t = DVec3::new(rng.range(-0.1, 0.1), rng.range(-0.1, 0.1), rng.range(-0.1, 0.1));
        let scale = DVec3::new(rng.range(0.005, 0.05), rng.range(0.005, 0.05), rng.range(0.005, 0.05));
        let clouds: Vec<(&str, Vec<DVec3>)> = vec![
            ("ellipsoid", moved(&(0..1500).map(|_| rng.in_ball() * scale).collect::<Vec<_>>(), rot, t)),
            ("cube-ish", moved(&(0..800).map(|_| DVec3::new(rng.next(), rng.next(), rng.next()) * scale).collect::<Vec<_>>(), rot, t)),
            ("few", (0..9).map(|_| t + rng.in_ball() * scale).collect()),
            ("uneven", {
                // a dense blob at one end of a rod, a sparse rest
                let mut v: Vec<DVec3> = (0..2000).map(|_| t + rot * (DVec3::X * 0.04 + rng.in_ball() * 0.004)).collect();
                v.extend((0..40).map(|_| t + rot * (DVec3::new(rng.range(-0.04, 0.04), 0.0, 0.0) + rng.in_ball() * 0.006)));
                v
            }),
        ];
        for (name, v) in clouds {
            let what = format!("seed {seed} {name}");
            let hull = convex_hull(&v).unwrap();
            let mut fits = Vec::new();
            for k in KINDS {
                let f = fit_with_hull(&v, &hull, k);
                let a = axis_aligned(&v, k).unwrap();
                assert_eq!((f.kind(), a.kind()), (k, k));
                assert_contains_all(&f, &v, &what);
                assert_contains_all(&a, &v, &what);
                assert!(f.volume <= a.volume * (1.0 + 1e-12), "{what} {k}: fit {} > axis-aligned {}", f.volume, a.volume);
                assert!(f.volume_ratio() >= 1.0 - 1e-9 && f.hull_volume == hull.volume, "{what} {k}: {f:?}");
                assert!(f.max_gap.is_finite() && f.max_gap >= 0.0 && f.max_gap <= a.max_gap.max(f.max_gap));
                assert_eq!(f, fit(&v, k).unwrap(), "{what} {k}: deterministic");
                fits.push(f);
            }
            let best = fit_tightest(&v, &KINDS).unwrap();
            let min = fits.iter().map(|f| f.volume).fold(f64::INFINITY, f64::min);
            assert!(best.volume <= min * (1.0 + 1e-9), "{what}: tightest {} vs {min}", best.volume);
        }
    }
}

/// contains() and the volumes against hand-computed primitives.
#[test]
fn contains_and_volumes_of_known_primitives() {
    use std::f64::consts::PI;
    let prim = |shape: FittedShape| PrimitiveFit {
        centre: DVec3::new(1.0, 2.0, 3.0),
        rot: DQuat::from_rotation_x(std::f64::consts::FRAC_PI_2), // local z → mesh −y
        shape,
        volume: shape.volume(),
        hull_volume: 1.0,
        max_gap: 0.0,
    };
    let c = DVec3::new(1.0, 2.0, 3.0);
    let cap = prim(FittedShape::Capsule { radius: 0.5, half_length: 1.0 });
    assert!((cap.volume - (PI * 0.25 * 2.0 + 4.0 / 3.0 * PI * 0.125)).abs() < 1e-12);
    assert!(cap.contains(c + DVec3::new(0.0, -1.49, 0.0), 0.0) && !cap.contains(c + DVec3::new(0.0, -1.51, 0.0), 0.0));
    assert!(cap.contains(c + DVec3::new(0.49, 0.9, 0.0), 0.0) && !cap.contains(c + DVec3::new(0.0, 0.9, 0.51), 0.0));
    assert!(cap.contains(c + DVec3::new(0.0, -1.51, 0.0), 0.02), "tolerance");
    let b = prim(FittedShape::Box { half_extents: DVec3::new(0.1, 0.2, 0.3) });
    assert!((b.volume - 0.048).abs() < 1e-15 && b.volume_ratio() == b.volume);
    // local (0.1, 0.2, 0.3) is mesh (0.1, −0.3, 0.2)
    assert!(b.contains(c + DVec3::new(0.099, -0.299, 0.199), 0.0) && !b.contains(c + DVec3::new(0.0, 0.0, 0.25), 0.0));
    let s = prim(FittedShape::Sphere { radius: 0.5 });
    assert!((s.volume - 4.0 / 3.0 * PI * 0.125).abs() < 1e-15);
    assert!(s.contains(c + DVec3::splat(0.28), 0.0) && !s.contains(c + DVec3::splat(0.29), 0.0));
}

// ------------------------------------------------------------------------------------------ read

/// STL (binary and ASCII) and OBJ vertices, and the errors.
#[test]
fn reads_stl_and_obj_vertices() {
    let tri = [[0.0f32, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 2.5, -1.0]];
    let mut bin = vec![b'x'; 80];
    bin.extend(1u32.to_le_bytes());
    bin.extend([0u8; 12]); // normal
    for p in tri {
        for x in p {
            bin.extend(x.to_le_bytes());
        }
    }
    bin.extend([0u8; 2]);
    let want: Vec<DVec3> = tri.iter().map(|p| DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64)).collect();
    assert_eq!(parse_stl(&bin).unwrap(), want);
    let ascii = "solid t\n facet normal 0 0 1\n  outer loop\n   vertex 0 0 0\n   vertex 1 0 0\n   vertex 0 2.5 -1\n  endloop\n endfacet\nendsolid t\n";
    assert_eq!(parse_stl(ascii.as_bytes()).unwrap(), want);
    let obj = "# c\nv 0 0 0 0.5 0.5 0.5\nvn 0 0 1\nv 1 0 0\nv 0 2.5 -1\nf 1 2 3\n";
    assert_eq!(parse_obj(obj.as_bytes()).unwrap(), want);
    assert_eq!(parse_obj(b"v 0 0 0\nv 1 x 0\n").unwrap_err(), "OBJ line 2: a 'v' line needs three numbers");
    assert!(parse_stl(b"not a mesh").unwrap_err().starts_with("neither a binary STL"));
    assert_eq!(parse_stl(b"solid s vertex 1 2").unwrap_err(), "an ASCII STL 'vertex' line needs three numbers");
    assert_eq!(parse_obj(b"v 0 nan 0\n").unwrap_err(), "a vertex has a non-finite coordinate");
}

// --------------------------------------------------------------------------------- real meshes

fn mesh_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else { return };
    let mut entries: Vec<PathBuf> = entries.filter_map(|e| e.ok().map(|e| e.path())).collect();
    entries.sort();
    for p in entries {
        if p.is_dir() {
            mesh_files(&p, out);
        } else if matches!(p.extension().and_then(|e| e.to_str()).map(|e| e.to_ascii_lowercase()).as_deref(), Some("obj" | "stl")) {
            out.push(p);
        }
    }
}

/// Every .obj and .stl under ../shared/hands (the real hands' collision and visual meshes): every
/// kind's fit contains every vertex and is no bigger than the axis-aligned primitive of its kind.
/// Prints a table (run with --nocapture): per mesh, the hull, and per kind the volume ratio
/// against the hull and max_gap (mm) of the fit and of the axis-aligned one, and what
/// mesh_approx = "capsule" would pick. Meshes spanning more than 1 unit are in millimetres (Shadow's,
/// scaled by their URDF): they are scaled to metres first, marked "(mm)".
#[test]
fn shared_hand_meshes_fit_tighter_than_axis_aligned() {
    let shared = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/hands");
    if !shared.is_dir() {
        eprintln!("shared_hand_meshes_fit_tighter_than_axis_aligned: SKIPPED, {} does not exist", shared.display());
        return;
    }
    let mut files = Vec::new();
    mesh_files(&shared, &mut files);
    assert!(!files.is_empty(), "no .obj or .stl under {}", shared.display());
    let start = std::time::Instant::now();
    println!(
        "{:<57} {:>6} {:>5} {:>8} {:>8} | {:>13} {:>13} | {:>13} {:>13} | {:>13} {:>13} | {}",
        "mesh", "verts", "hullv", "extent m", "hull cm3", "sphere ratio", "gap mm", "capsule ratio", "gap mm", "box ratio", "gap mm", "capsule|sphere: ratio, gap mm"
    );
    let mut tighter = [0usize; 3];
    for path in &files {
        let name = path.strip_prefix(&shared).unwrap_or(path).display().to_string();
        let bytes = std::fs::read(path).unwrap();
        let is_stl = path.extension().is_some_and(|e| e.eq_ignore_ascii_case("stl"));
        let mut v = if is_stl { parse_stl(&bytes) } else { parse_obj(&bytes) }.unwrap_or_else(|e| panic!("{name}: {e}"));
        let name = if extent(&v) > 1.0 {
            v.iter_mut().for_each(|p| *p *= 1e-3);
            format!("{name} (mm)")
        } else {
            name
        };
        let hull = convex_hull(&v).unwrap_or_else(|e| panic!("{name}: {e}"));
        let mut cols = String::new();
        for (i, k) in KINDS.into_iter().enumerate() {
            let f = fit_with_hull(&v, &hull, k);
            let a = axis_aligned(&v, k).unwrap();
            assert_contains_all(&f, &v, &name);
            assert_contains_all(&a, &v, &name);
            assert!(f.volume <= a.volume * (1.0 + 1e-12), "{name} {k}: fit {} > axis-aligned {}", f.volume, a.volume);
            if f.volume < a.volume * (1.0 - 1e-6) {
                tighter[i] += 1;
            }
            cols += &format!(
                " | {:>13} {:>13}",
                format!("{:.2}/{:.2}", f.volume_ratio(), a.volume_ratio()),
                format!("{:.2}/{:.2}", f.max_gap * 1e3, a.max_gap * 1e3)
            );
        }
        let best = fit_tightest(&v, &[PrimitiveKind::Capsule, PrimitiveKind::Sphere]).unwrap();
        println!(
            "{:<57} {:>6} {:>5} {:>8.4} {:>8.3}{cols} | {} {:.2} {:.2}",
            name,
            v.len(),
            hull.vertices.len(),
            extent(&v),
            hull.volume * 1e6,
            best.kind(),
            best.volume_ratio(),
            best.max_gap * 1e3
        );
    }
    println!(
        "{} meshes in {:.1} s; fits strictly tighter than axis-aligned: sphere {}, capsule {}, box {} (ratio and gap: fit/axis-aligned)",
        files.len(),
        start.elapsed().as_secs_f64(),
        tighter[0],
        tighter[1],
        tighter[2]
    );
}

// ------------------------------------------------------------------------- mass and triangles

/// A convex mesh with every triangle turned counter-clockwise seen from outside (away from the
/// mean vertex).
fn wound_outward(vertices: Vec<DVec3>, triangles: Vec<[u32; 3]>) -> TriangleMesh {
    let mean = vertices.iter().copied().sum::<DVec3>() / vertices.len() as f64;
    let triangles = triangles
        .into_iter()
        .map(|[i, j, k]| {
            let [a, b, c] = [i, j, k].map(|x| vertices[x as usize]);
            if (b - a).cross(c - a).dot(a - mean) > 0.0 { [i, j, k] } else { [i, k, j] }
        })
        .collect();
    TriangleMesh { vertices, triangles }
}

/// The box of half extents h about `centre`, turned by `rot` about its centre: 8 vertices
/// (index bits 0, 1, 2: the +x, +y, +z side), 12 triangles wound outward.
fn box_mesh(h: DVec3, centre: DVec3, rot: DQuat) -> TriangleMesh {
    let sign = |bit: u32, x: f64| if bit != 0 { x } else { -x };
    let vertices = (0..8u32).map(|i| centre + rot * DVec3::new(sign(i & 1, h.x), sign(i & 2, h.y), sign(i & 4, h.z))).collect();
    let mut triangles = Vec::new();
    for k in 0..3 {
        let (u, v) = (1u32 << ((k + 1) % 3), 1u32 << ((k + 2) % 3));
        for side in [0, 1u32 << k] {
            let q = [side, side | u, side | u | v, side | v]; // the face's corners in cyclic order
            triangles.push([q[0], q[1], q[2]]);
            triangles.push([q[0], q[2], q[3]]);
        }
    }
    wound_outward(vertices, triangles)
}

/// Full sides 2h: I_xx = V ((2h_y)² + (2h_z)²)/12 etc. (unit density).
fn box_inertia(h: DVec3) -> DMat3 {
    let v = 8.0 * h.x * h.y * h.z;
    let s = (2.0 * h) * (2.0 * h);
    DMat3::from_diagonal(DVec3::new(s.y + s.z, s.z + s.x, s.x + s.y) * (v / 12.0))
}

fn max_abs(m: DMat3) -> f64 {
    m.to_cols_array().iter().fold(0.0f64, |a, x| a.max(x.abs()))
}

/// Panics unless `got` is within `rel` × |want| (largest entry) of `want`, entry by entry.
fn assert_mat_close(got: DMat3, want: DMat3, rel: f64, what: &str) {
    let err = max_abs(got - want);
    assert!(err <= rel * max_abs(want), "{what}: inertia {got} vs {want} (off by {err:e})");
}

fn assert_props_close(got: &MassProperties, want: &MassProperties, rel: f64, what: &str) {
    assert!((got.volume / want.volume - 1.0).abs() <= rel, "{what}: volume {} vs {}", got.volume, want.volume);
    let size = want.volume.cbrt();
    assert!(got.center_of_mass.distance(want.center_of_mass) <= rel * size, "{what}: COM {} vs {}", got.center_of_mass, want.center_of_mass);
    assert_mat_close(got.inertia, want.inertia, rel, what);
}

/// An axis-aligned box away from the origin: volume 8abc, COM the centre, inertia diagonal with
/// V(s_y² + s_z²)/12 ... (sides s = 2h), to 1e-12; scaled_to_mass multiplies by mass / V; the
/// principal moments are the diagonal, sorted descending, the axes the coordinate axes.
#[test]
fn mass_properties_of_an_axis_aligned_box() {
    let (h, centre) = (DVec3::new(0.031, 0.012, 0.007), DVec3::new(0.3, -0.2, 0.5));
    let mesh = box_mesh(h, centre, DQuat::IDENTITY);
    assert_eq!((mesh.vertices.len(), mesh.triangles.len()), (8, 12));
    let p = mass_properties(&mesh).unwrap();
    let v = 8.0 * h.x * h.y * h.z;
    assert!((p.volume / v - 1.0).abs() < 1e-12, "volume {} vs {v}", p.volume);
    assert!(p.center_of_mass.distance(centre) < 1e-12 * h.length(), "COM {}", p.center_of_mass);
    assert_mat_close(p.inertia, box_inertia(h), 1e-12, "box");
    let (com, inertia) = p.scaled_to_mass(0.25);
    assert_eq!(com, p.center_of_mass);
    assert_mat_close(inertia, box_inertia(h) * (0.25 / v), 1e-12, "scaled to 0.25 kg");
    let (moments, axes) = p.principal();
    let d = box_inertia(h);
    let want = DVec3::new(d.x_axis.x, d.y_axis.y, d.z_axis.z); // h.x > h.y > h.z: I_zz > I_yy > I_xx
    for (got, want) in moments.to_array().iter().zip([want.z, want.y, want.x]) {
        assert!((got / want - 1.0).abs() < 1e-12, "principal moments {moments} vs {want}");
    }
    assert!(axes.x_axis.z.abs() > 1.0 - 1e-12 && axes.z_axis.x.abs() > 1.0 - 1e-12, "axes {axes}");
}

/// The box turned by R (about its centre, three seeds): inertia R I Rᵀ, the same principal
/// moments, the principal axes R's columns up to sign; principal() reassembles the inertia.
#[test]
fn mass_properties_of_a_rotated_box() {
    let (h, centre) = (DVec3::new(0.031, 0.012, 0.007), DVec3::new(0.3, -0.2, 0.5));
    let straight = mass_properties(&box_mesh(h, centre, DQuat::IDENTITY)).unwrap();
    for seed in [21u64, 22, 23] {
        let rot = Lcg::new(seed).rotation();
        let p = mass_properties(&box_mesh(h, centre, rot)).unwrap();
        let r = DMat3::from_quat(rot);
        let want = MassProperties { volume: 8.0 * h.x * h.y * h.z, center_of_mass: centre, inertia: r * box_inertia(h) * r.transpose() };
        assert_props_close(&p, &want, 1e-12, &format!("seed {seed}"));
        let ((m0, _), (m, axes)) = (straight.principal(), p.principal());
        assert!((m - m0).abs().max_element() < 1e-12 * m0.max_element(), "seed {seed}: moments {m} vs {m0}");
        // largest moment about the shortest side (z of the box), smallest about the longest (x)
        assert!(axes.x_axis.dot(rot * DVec3::Z).abs() > 1.0 - 1e-9 && axes.z_axis.dot(rot * DVec3::X).abs() > 1.0 - 1e-9, "seed {seed}: {axes}");
        assert_mat_close(axes * DMat3::from_diagonal(m) * axes.transpose(), p.inertia, 1e-12, "R diag(m) Rᵀ");
    }
}

/// The unit right tetrahedron (0, X, Y, Z): V = 1/6, COM (1/4, 1/4, 1/4), and its inertia from
/// the closed-form moments about the origin: ∫ x² dV = ∫₀¹ x² (1 − x)²/2 dx = B(3, 3)/2 = 1/60
/// (the cross-section at x is a right triangle of legs 1 − x), ∫ x y dV = ∫∫ x y (1 − x − y) dy
/// dx over the unit triangle = 1/120; about the COM: ∫ x'² = 1/60 − V/16 = 1/160, ∫ x'y' =
/// 1/120 − V/16 = −1/480, so I_xx = 2/160 = 1/80 and I_xy = +1/480. Moved far from the origin
/// (1e3 units, coordinates rounded) the reference point keeps 1e-9 relative precision (tetrahedra
/// from the origin would lose several digits: their determinants cancel terms of ~1e10 to ~1).
#[test]
fn mass_properties_of_the_unit_right_tetrahedron() {
    let vertices = vec![DVec3::ZERO, DVec3::X, DVec3::Y, DVec3::Z];
    let mesh = wound_outward(vertices, vec![[0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3]]);
    let (v, origin_xx, origin_xy): (f64, f64, f64) = (1.0 / 6.0, 1.0 / 60.0, 1.0 / 120.0);
    let (cxx, cxy) = (origin_xx - v / 16.0, origin_xy - v / 16.0); // parallel axis, COM at 1/4
    assert!((cxx - 1.0 / 160.0).abs() < 1e-15 && (cxy + 1.0 / 480.0).abs() < 1e-15);
    let inertia = DMat3::from_cols(DVec3::new(2.0 * cxx, -cxy, -cxy), DVec3::new(-cxy, 2.0 * cxx, -cxy), DVec3::new(-cxy, -cxy, 2.0 * cxx));
    assert!((inertia.x_axis.x - 1.0 / 80.0).abs() < 1e-15);
    let want = MassProperties { volume: v, center_of_mass: DVec3::splat(0.25), inertia };
    assert_props_close(&mass_properties(&mesh).unwrap(), &want, 1e-12, "tetrahedron");
    let far = DVec3::new(1000.1, -2000.3, 500.7); // not exact: the corners are rounded
    let moved = TriangleMesh { vertices: mesh.vertices.iter().map(|p| *p + far).collect(), triangles: mesh.triangles.clone() };
    let want_far = MassProperties { center_of_mass: want.center_of_mass + far, ..want };
    assert_props_close(&mass_properties(&moved).unwrap(), &want_far, 1e-9, "tetrahedron far away");
}

/// Every triangle reversed (wound inward): the same properties. is_closed: the box yes; with a
/// triangle missing or flipped, or with no triangles, no.
#[test]
fn inward_winding_and_closedness() {
    let mesh = box_mesh(DVec3::new(0.05, 0.02, 0.01), DVec3::new(0.3, -0.2, 0.5), Lcg::new(24).rotation());
    let p = mass_properties(&mesh).unwrap();
    let inward = TriangleMesh { triangles: mesh.triangles.iter().map(|[a, b, c]| [*a, *c, *b]).collect(), ..mesh.clone() };
    assert_props_close(&mass_properties(&inward).unwrap(), &p, 1e-12, "inward");
    assert!(is_closed(&mesh) && is_closed(&inward));
    let mut missing = mesh.clone();
    missing.triangles.remove(5);
    assert!(!is_closed(&missing), "a triangle missing");
    let mut flipped = mesh.clone();
    flipped.triangles[3].swap(1, 2);
    assert!(!is_closed(&flipped), "a triangle flipped");
    let mut doubled = mesh.clone();
    doubled.triangles.extend(mesh.triangles.clone());
    assert!(!is_closed(&doubled), "every edge used four times");
    assert!(!is_closed(&TriangleMesh::default()));
}

/// Errors: no triangles, an index out of range, a flat mesh (one triangle, or the two sides of one
/// triangle: closed, but zero volume), a non-finite vertex; combine of nothing.
#[test]
fn mass_property_errors() {
    let tri = TriangleMesh { vertices: vec![DVec3::ZERO, DVec3::X, DVec3::Y], triangles: vec![[0, 1, 2]] };
    let sheet = TriangleMesh { triangles: vec![[0, 1, 2], [0, 2, 1]], ..tri.clone() };
    assert!(is_closed(&sheet), "closed, but flat");
    let cases = [
        (TriangleMesh::default(), "no triangles"),
        (TriangleMesh { triangles: vec![[0, 1, 3]], ..tri.clone() }, "indexes past"),
        (tri.clone(), "no volume"),
        (sheet, "flat or degenerate"),
        (TriangleMesh { vertices: vec![DVec3::ZERO, DVec3::X, DVec3::new(0.0, f64::INFINITY, 0.0)], ..tri }, "non-finite"),
    ];
    for (mesh, want) in cases {
        let e = mass_properties(&mesh).unwrap_err();
        assert!(e.contains(want) && !e.contains('\n'), "{want}: {e}");
    }
    assert!(combine(&[]).unwrap_err().contains("no parts"));
}

/// combine() of two disjoint boxes (one turned) equals the mass properties of one mesh that
/// holds both.
#[test]
fn combine_equals_one_mesh_of_both_parts() {
    let a = box_mesh(DVec3::new(0.03, 0.02, 0.01), DVec3::new(0.3, -0.2, 0.5), DQuat::IDENTITY);
    let b = box_mesh(DVec3::new(0.01, 0.04, 0.02), DVec3::new(0.2, -0.1, 0.45), Lcg::new(25).rotation());
    let offset = a.vertices.len() as u32;
    let both = TriangleMesh {
        vertices: a.vertices.iter().chain(&b.vertices).copied().collect(),
        triangles: a.triangles.iter().copied().chain(b.triangles.iter().map(|t| t.map(|i| i + offset))).collect(),
    };
    let parts = [mass_properties(&a).unwrap(), mass_properties(&b).unwrap()];
    let c = combine(&parts).unwrap();
    assert_props_close(&c, &mass_properties(&both).unwrap(), 1e-12, "combined");
    assert!((c.volume - parts[0].volume - parts[1].volume).abs() < 1e-18);
    assert_props_close(&combine(&parts[..1]).unwrap(), &parts[0], 1e-15, "one part is itself");
    assert!(max_abs(c.inertia - parts[0].inertia - parts[1].inertia) > 1e-3 * max_abs(c.inertia), "the parallel-axis terms matter here");
}

/// An OBJ of two `o` pieces: a unit cube of quads (`i/t/n`, `i//n`, `i/t` and `i` corners,
/// scaled by 0.1 and moved) and a tetrahedron of negative indices: 12 and 4 triangles, 8 and 4
/// vertices each, closed, volumes 1e-3 and 1/6; usemtl, s, vt, vn and comments are skipped.
#[test]
fn obj_pieces_of_a_cube_of_quads_and_a_tetrahedron() {
    let obj = "# two pieces\nmtllib x.mtl\no cube\n\
        v 1 1 1\nv 1.1 1 1\nv 1.1 1.1 1\nv 1 1.1 1\nv 1 1 1.1\nv 1.1 1 1.1\nv 1.1 1.1 1.1\nv 1 1.1 1.1\n\
        vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvn 0 0 1\nusemtl m\ns off\n\
        f 1/1/1 4/4/1 3/3/1 2/2/1\nf 5/1/1 6/2/1 7/3/1 8/4/1\nf 1//1 2//1 6//1 5//1\nf 4/1 8/2 7/3 3/4\nf 1 5 8 4 # left\nf 2/2/1 3/3/1 7/3/1 6/2/1\n\
        o tet\nv 2 0 0\nv 3 0 0\nv 2 1 0\nv 2 0 1\n\
        f -4 -2 -3\nf -4 -3 -1\nf -4 -1 -2\nf -3 -2 -1\n";
    let pieces = parse_obj_pieces(obj.as_bytes()).unwrap();
    let summary: Vec<(&str, usize, usize)> = pieces.iter().map(|p| (p.name.as_str(), p.mesh.vertices.len(), p.mesh.triangles.len())).collect();
    assert_eq!(summary, [("cube", 8, 12), ("tet", 4, 4)]);
    for (p, volume, com) in [(&pieces[0], 1e-3, DVec3::splat(1.05)), (&pieces[1], 1.0 / 6.0, DVec3::new(2.25, 0.25, 0.25))] {
        assert!(is_closed(&p.mesh), "{} is closed", p.name);
        let m = mass_properties(&p.mesh).unwrap();
        assert!((m.volume / volume - 1.0).abs() < 1e-12 && m.center_of_mass.distance(com) < 1e-12, "{}: {m:?}", p.name);
    }
    assert_eq!(pieces[1].mesh.vertices[0], DVec3::new(2.0, 0.0, 0.0), "re-indexed from the piece's own vertices");
    // faces before any o/g go to "default"; a group without faces is dropped; g's name is kept
    let p = parse_obj_pieces(b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\ng empty\no\ng side 2\nf 3 2 1\n").unwrap();
    let names: Vec<&str> = p.iter().map(|p| p.name.as_str()).collect();
    assert_eq!(names, ["default", "side 2"]);
    assert_eq!(p[1].mesh.triangles, [[0, 1, 2]]);
    assert!(parse_obj_pieces(b"# nothing\n").unwrap().is_empty());
}

/// OBJ errors are one line naming the line and what was expected; no input panics.
#[test]
fn obj_piece_errors_name_the_line() {
    let head = "v 0 0 0\nv 1 0 0\nv 0 1 0\n";
    let cases = [
        ("f 1 2 9\n", "OBJ line 4: face index 9 is out of range (the file has 3 vertices so far)"),
        ("f -4 1 2\n", "OBJ line 4: face index -4 is out of range"),
        ("f 1 2\n", "OBJ line 4: a face needs at least 3 corners, found 2"),
        ("f 1 x 3\n", "OBJ line 4: a face corner must start with a vertex index"),
        ("f 1/2/3 /1/1 3\n", "'/1/1'"),
        ("f 0 1 2\n", "OBJ line 4: face index 0 is invalid"),
        ("v 1 2\n", "OBJ line 4: a 'v' line needs three numbers"),
        ("v 1 nan 2\n", "OBJ line 4: a vertex has a non-finite coordinate"),
        ("v 1 2 inf\n", "non-finite"),
        ("f 1 2 99999999999999999999999\n", "OBJ line 4: a face corner"),
        ("f 1 2 -9223372036854775808\n", "out of range"),
        ("f\n", "found 0"),
    ];
    for (tail, want) in cases {
        let e = parse_obj_pieces(format!("{head}{tail}").as_bytes()).unwrap_err();
        assert!(e.contains(want) && !e.contains('\n'), "{tail:?}: {e}");
    }
}

/// The box as a binary STL (f32 corners, exactly representable) and as an ASCII STL: welded to 8
/// vertices, closed, volume 8abc, the same mesh both ways.
#[test]
fn stl_mesh_is_welded_and_closed() {
    let (h, centre) = (DVec3::new(0.5, 0.25, 0.125), DVec3::new(0.25, -0.125, 0.5));
    let mesh = box_mesh(h, centre, DQuat::IDENTITY);
    let mut bin = vec![0u8; 80];
    bin.extend((mesh.triangles.len() as u32).to_le_bytes());
    let mut ascii = "solid box\n".to_string();
    for t in &mesh.triangles {
        bin.extend([0u8; 12]); // normal
        ascii += " facet normal 0 0 0\n  outer loop\n";
        for i in t {
            let p = mesh.vertices[*i as usize];
            bin.extend(p.to_array().iter().flat_map(|x| (*x as f32).to_le_bytes()));
            ascii += &format!("   vertex {} {} {}\n", p.x, p.y, p.z);
        }
        bin.extend([0u8; 2]);
        ascii += "  endloop\n endfacet\n";
    }
    ascii += "endsolid box\n";
    let m = parse_stl_mesh(&bin).unwrap();
    assert_eq!((m.vertices.len(), m.triangles.len()), (8, 12));
    assert!(is_closed(&m));
    let p = mass_properties(&m).unwrap();
    assert!((p.volume / (8.0 * h.x * h.y * h.z) - 1.0).abs() < 1e-12 && p.center_of_mass.distance(centre) < 1e-12, "{p:?}");
    assert_eq!(parse_stl_mesh(ascii.as_bytes()).unwrap(), m);
    // -0.0 and 0.0 weld
    let signed_zero = "solid z\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\nvertex -0 0 0\nvertex 0 1 0\nvertex 1 0 0\nendsolid\n";
    assert_eq!(parse_stl_mesh(signed_zero.as_bytes()).unwrap().vertices.len(), 3);
    assert!(parse_stl_mesh(b"solid s\nvertex 0 0 0\nvertex 1 0 0\nendsolid\n").unwrap_err().contains("three vertices per triangle"));
}

/// The signed volume a mesh's triangles enclose (tetrahedra from the mean vertex): > 0 when wound
/// outward (reported, not asserted).
fn signed_volume(m: &TriangleMesh) -> f64 {
    let o = m.vertices.iter().copied().sum::<DVec3>() / m.vertices.len() as f64;
    m.triangles.iter().map(|t| t.map(|i| m.vertices[i as usize] - o)).map(|[a, b, c]| a.dot(b.cross(c)) / 6.0).sum()
}

/// Every .obj under ../shared/objects (real YCB collision meshes, see its SOURCES.md): every
/// piece that is closed has 0 < volume ≤ its convex hull's (× (1 + 1e-6)) and its centre of mass
/// inside the hull. Prints a line per file (run with --nocapture): pieces, closed, wound inward,
/// the smallest volume / hull volume of a piece, total volume of the closed pieces, their combined
/// COM, and the mass at 1000 kg/m³.
#[test]
fn shared_object_meshes_have_sane_mass_properties() {
    let shared = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/objects");
    if !shared.is_dir() {
        eprintln!("shared_object_meshes_have_sane_mass_properties: SKIPPED, {} does not exist", shared.display());
        return;
    }
    let mut files = Vec::new();
    mesh_files(&shared, &mut files);
    files.retain(|p| p.extension().is_some_and(|e| e.eq_ignore_ascii_case("obj")));
    assert!(!files.is_empty(), "no .obj under {}", shared.display());
    let mut all_closed = 0;
    for path in &files {
        let name = path.strip_prefix(&shared).unwrap_or(path).display().to_string();
        let pieces = parse_obj_pieces(&std::fs::read(path).unwrap()).unwrap_or_else(|e| panic!("{name}: {e}"));
        assert!(!pieces.is_empty(), "{name}: no pieces");
        let mut closed = Vec::new();
        let mut inward = 0;
        let mut fill = f64::INFINITY; // the smallest volume / hull volume of a closed piece
        for piece in &pieces {
            if signed_volume(&piece.mesh) < 0.0 {
                inward += 1;
            }
            if !is_closed(&piece.mesh) {
                continue;
            }
            let what = format!("{name} / {}", piece.name);
            let m = mass_properties(&piece.mesh).unwrap_or_else(|e| panic!("{what}: {e}"));
            let hull = convex_hull(&piece.mesh.vertices).unwrap_or_else(|e| panic!("{what}: {e}"));
            assert!(m.volume > 0.0 && m.volume <= hull.volume * (1.0 + 1e-6), "{what}: volume {:e} vs hull {:e}", m.volume, hull.volume);
            let tol = 1e-9 * extent(&piece.mesh.vertices) + hull.tolerance;
            assert!(hull.contains(m.center_of_mass, tol), "{what}: COM {} outside the hull by {:e}", m.center_of_mass, hull.plane_distance(m.center_of_mass));
            fill = fill.min(m.volume / hull.volume);
            closed.push(m);
        }
        all_closed += closed.len();
        let (volume, com) = match combine(&closed) {
            Ok(c) => (c.volume, format!("({:.1}, {:.1}, {:.1}) mm", c.center_of_mass.x * 1e3, c.center_of_mass.y * 1e3, c.center_of_mass.z * 1e3)),
            Err(_) => (0.0, "-".to_string()),
        };
        println!(
            "{name:<40} pieces {:>2}, closed {:>2}, wound inward {}, volume/hull min {:.4}, volume {:.2} cm3, COM {com}, mass at 1000 kg/m3 {:.3} kg",
            pieces.len(),
            closed.len(),
            inward,
            fill,
            volume * 1e6,
            volume * 1e3
        );
    }
    assert!(all_closed > 0, "no closed piece in any file under {}", shared.display());
}
