//! The mesh module: reading STL/OBJ, the convex hull, and the primitive fits (sphere, capsule,
//! oriented box) that contain every vertex and are tighter than the axis-aligned ones.

use std::path::{Path, PathBuf};

use dextrain::mesh::fit::{FittedShape, PrimitiveFit, PrimitiveKind, axis_aligned, fit, fit_tightest, fit_with_hull};
use dextrain::mesh::hull::convex_hull;
use dextrain::mesh::read::{parse_obj, parse_stl};
use glam::{DQuat, DVec3};

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
