//! Objects from meshes and URDFs as compound bodies (`dextrain::object`): their mass properties
//! against closed forms, the shipped bottle, the YCB meshes of ../shared/objects (read in place when
//! they exist), objects at rest on the table, several objects in one run (drawn per env and
//! reported per object by eval), and one-line errors for bad object input.

use std::path::{Path, PathBuf};

use dextrain::config::{Config, MeshFiles, ObjectItem};
use dextrain::env::{EnvBatch, SimModel};
use dextrain::geom::ObjectShape;
use dextrain::object::load::load_objects;
use dextrain::object::{MassSource, ObjectModel};
use glam::{Quat, Vec3};

use crate::common::*;

const BOTTLE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/configs/objects/bottle.obj");

fn shared_objects() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/objects")
}

/// An OBJ of one box piece: centre `c`, half extents `h`, wound outward.
fn box_obj(c: Vec3, h: Vec3) -> String {
    box_piece("box", c, h, 0)
}

/// One box group of an OBJ whose vertices start after `before` others.
fn box_piece(name: &str, c: Vec3, h: Vec3, before: usize) -> String {
    let mut s = format!("g {name}\n");
    for k in 0..8 {
        let sx = if k & 1 != 0 { 1.0 } else { -1.0 };
        let sy = if k & 2 != 0 { 1.0 } else { -1.0 };
        let sz = if k & 4 != 0 { 1.0 } else { -1.0 };
        s += &format!("v {} {} {}\n", c.x + sx * h.x, c.y + sy * h.y, c.z + sz * h.z);
    }
    // quads (vertex k + 1 at bit pattern k), counter-clockwise seen from outside
    for q in [[1, 3, 4, 2], [5, 6, 8, 7], [1, 2, 6, 5], [3, 7, 8, 4], [1, 5, 7, 3], [2, 4, 8, 6]] {
        s += &format!("f {} {} {} {}\n", q[0] + before, q[1] + before, q[2] + before, q[3] + before);
    }
    s
}

fn object_config(items: Vec<ObjectItem>) -> Config {
    let mut c = base_config(4);
    c.object.set = items;
    c
}

fn mesh_item(path: &Path) -> ObjectItem {
    ObjectItem { mesh: Some(MeshFiles::One(path.display().to_string())), ..Default::default() }
}

fn load_one(item: ObjectItem) -> anyhow::Result<ObjectModel> {
    load_objects(&object_config(vec![item])).map(|mut v| v.remove(0))
}

fn close(a: f32, b: f32, rel: f32) -> bool {
    (a - b).abs() <= rel * a.abs().max(b.abs()).max(1e-12)
}

#[test]
fn a_box_mesh_has_the_analytic_box_mass_properties() {
    let dir = tempfile::tempdir().unwrap();
    let (c, h) = (Vec3::new(0.01, 0.02, 0.03), Vec3::new(0.03, 0.02, 0.01));
    let path = dir.path().join("box.obj");
    std::fs::write(&path, box_obj(c, h)).unwrap();
    let o = load_one(ObjectItem { density: Some(500.0), ..mesh_item(&path) }).unwrap();
    let analytic = ObjectModel::primitive("box", ObjectShape::Box { half_extents: h.to_array() }, 500.0 * 8.0 * h.x * h.y * h.z, MassSource::Given);
    assert_eq!(o.mass_source, MassSource::Density);
    assert!(close(o.mass, analytic.mass, 1e-5), "mass {} vs {}", o.mass, analytic.mass);
    assert!((o.com - c).length() < 1e-7, "centre of mass {:?}", o.com);
    // principal moments, in any order of the axes: m (b² + c²) / 3 with half extents b, c
    let mut got = o.inertia.to_array();
    let mut want = analytic.inertia.to_array();
    got.sort_by(f32::total_cmp);
    want.sort_by(f32::total_cmp);
    for (g, w) in got.iter().zip(want) {
        assert!(close(*g, w, 1e-4), "inertia {got:?} vs {want:?}");
    }
    // the principal axes are the box's: each maps to a coordinate axis
    for axis in [Vec3::X, Vec3::Y, Vec3::Z] {
        let a = o.principal * axis;
        assert!(a.abs().max_element() > 1.0 - 1e-5, "principal axis {a:?}");
    }
    // one piece: the box itself, where the mesh is; it rests on its lowest face
    assert_eq!(o.pieces.len(), 1);
    let ObjectShape::Box { half_extents } = o.pieces[0].shape else { panic!("{:?}", o.pieces[0].shape) };
    let mut he = half_extents;
    he.sort_by(f32::total_cmp);
    assert!((Vec3::from(he) - Vec3::new(0.01, 0.02, 0.03)).abs().max_element() < 1e-6, "{half_extents:?}");
    assert!((o.pieces[0].pose.pos - c).length() < 1e-6);
    assert!(o.pieces[0].fit.as_ref().unwrap().volume_ratio < 1.0 + 1e-6);
    assert!((o.rest_height() - (h.z - c.z)).abs() < 1e-6, "rest height {}", o.rest_height());
}

/// Volume and centroid height of the frustum of two similar regular 16-gons (areas a0 at z0, a1 at z1).
fn frustum(a0: f64, a1: f64, z0: f64, z1: f64) -> (f64, f64) {
    let h = z1 - z0;
    let m = (a0 * a1).sqrt();
    let v = h / 3.0 * (a0 + m + a1);
    let zc = z0 + h * (a0 + 2.0 * m + 3.0 * a1) / (4.0 * (a0 + m + a1));
    (v, zc)
}

#[test]
fn the_shipped_bottle_is_three_pieces_with_its_prisms_mass_properties() {
    let o = load_one(ObjectItem { mass: Some(0.15), ..mesh_item(Path::new(BOTTLE)) }).unwrap();
    assert_eq!(o.name, "bottle");
    assert_eq!(o.pieces.len(), 3);
    // a regular 16-gon of circumradius r has area 8 r² sin(2π/16)
    let area = |r: f64| 8.0 * r * r * (std::f64::consts::TAU / 16.0).sin();
    let parts = [frustum(area(0.028), area(0.028), 0.0, 0.08), frustum(area(0.028), area(0.014), 0.08, 0.10), frustum(area(0.014), area(0.014), 0.10, 0.13)];
    let v: f64 = parts.iter().map(|p| p.0).sum();
    let zc = parts.iter().map(|p| p.0 * p.1).sum::<f64>() / v;
    assert!(close(o.volume, v as f32, 1e-5), "volume {} vs {v}", o.volume);
    assert!((o.com - Vec3::new(0.0, 0.0, zc as f32)).length() < 1e-6, "centre of mass {:?} vs z {zc}", o.com);
    assert_eq!(o.mass_source, MassSource::Given);
    // the body and the neck are cylinders that fit within 5 %; the object stands on z = 0
    for (i, r) in [(0, 0.028f32), (2, 0.014)] {
        let ObjectShape::Cylinder { radius, .. } = o.pieces[i].shape else { panic!("piece {i}: {:?}", o.pieces[i].shape) };
        assert!((radius - r).abs() < 1e-5, "piece {i} radius {radius}");
        assert!(o.pieces[i].fit.as_ref().unwrap().volume_ratio < 1.05);
    }
    assert!(o.rest_height().abs() < 1e-6, "rest height {}", o.rest_height());
    // symmetric about z: two equal moments about horizontal axes, the smallest about the axis
    let (ix, iy, iz) = (o.inertia.x, o.inertia.y, o.inertia.z);
    let axis = o.principal * Vec3::Z;
    let (a, b, spin) = if axis.z.abs() > 0.999 { (ix, iy, iz) } else if (o.principal * Vec3::X).z.abs() > 0.999 { (iy, iz, ix) } else { (ix, iz, iy) };
    assert!(close(a, b, 1e-3) && spin < a, "inertia {:?} with axes {:?}", o.inertia, o.principal);
}

/// `n` envs of `c` at rest on the table with the hand held high for `seconds`: each env's largest
/// displacement of the object frame's origin (m) and tilt (rad) from its first state.
fn settle(c: &Config, seconds: f32) -> Vec<(f32, f32)> {
    let mut b = cpu_batch(c);
    let start = b.states().unwrap();
    let t = b.model().default_targets();
    let steps = (seconds / (c.sim.dt * c.sim.decimation as f32)).round() as usize;
    let mut worst = vec![(0.0f32, 0.0f32); start.len()];
    for _ in 0..steps {
        run(&mut b, t, 1);
        for (i, (s, s0)) in b.states().unwrap().iter().zip(&start).enumerate() {
            let d = (Vec3::from_slice(&s.obj_pos[..3]) - Vec3::from_slice(&s0.obj_pos[..3])).length();
            let tilt = (Quat::from_array(s.obj_rot) * Vec3::Z).angle_between(Vec3::Z);
            worst[i] = (worst[i].0.max(d), worst[i].1.max(tilt));
        }
    }
    worst
}

#[test]
fn a_mesh_object_at_rest_drifts_less_than_1_mm_over_10_s() {
    let mut c = object_config(vec![ObjectItem { mass: Some(0.15), ..mesh_item(Path::new(BOTTLE)) }]);
    c.object.yaw_noise = 3.0;
    c.wrist.init_pos = [0.0, 0.0, 0.6];
    for (i, (d, tilt)) in settle(&c, 10.0).into_iter().enumerate() {
        eprintln!("bottle env {i}: drift {:.4} mm, tilt {:.4}°", d * 1e3, tilt.to_degrees());
        assert!(d < 1e-3, "env {i}: the bottle drifted {:.3} mm", d * 1e3);
        assert!(tilt.to_degrees() < 0.1, "env {i}: the bottle tilted {:.3}°", tilt.to_degrees());
    }
}

#[test]
fn the_hollow_mug_stands_on_its_base() {
    let path = shared_objects().join("025_mug/collision.obj");
    if !path.is_file() {
        eprintln!("the_hollow_mug_stands_on_its_base: {} does not exist; not run", path.display());
        return;
    }
    let mut c = object_config(vec![mesh_item(&path)]);
    c.wrist.init_pos = [0.0, 0.0, 0.6];
    c.object.yaw_noise = 3.0;
    let model = SimModel::from_config(&c).unwrap();
    let mug = &model.objects[0];
    assert_eq!(mug.pieces.len(), 16);
    // it rests on the mesh's lowest point: the base disc's underside
    let pieces = dextrain::mesh::read::parse_obj_pieces(&std::fs::read(&path).unwrap()).unwrap();
    let lowest = pieces.iter().flat_map(|p| p.mesh.vertices.iter()).map(|v| v.z).fold(f64::INFINITY, f64::min) as f32;
    eprintln!("mug: rest height {:.4} m from its pieces, {:.4} m from the mesh", mug.rest_height(), -lowest);
    assert!((mug.rest_height() + lowest).abs() < 1e-3, "rest height {} vs the mesh's {}", mug.rest_height(), -lowest);
    let mut b = cpu_batch(&c);
    let z0: Vec<f32> = b.states().unwrap().iter().map(|s| s.obj_pos[2]).collect();
    for (i, (d, tilt)) in settle(&c, 10.0).into_iter().enumerate() {
        eprintln!("mug env {i}: drift {:.4} mm, tilt {:.4}°", d * 1e3, tilt.to_degrees());
        assert!(d < 1e-3 && tilt.to_degrees() < 0.2, "env {i}: drift {:.3} mm, tilt {:.3}°", d * 1e3, tilt.to_degrees());
    }
    // after 10 s it stands at its rest height (sunk by m g / k at most) with only the base touching
    run(&mut b, model.default_targets(), 300);
    for (s, z) in b.states().unwrap().iter().zip(&z0) {
        assert!((s.obj_pos[2] - z).abs() < 5e-4, "height {} vs {}", s.obj_pos[2], z);
    }
    // it stands on its base: the base disc (piece 0, a cylinder: support points 0–15) and the
    // walls' lower edges touch the table, the handle (pieces 1–3, boxes: points 16–39) does not
    assert!(matches!(mug.pieces[0].shape, ObjectShape::Cylinder { .. }), "{:?}", mug.pieces[0].shape);
    let (params, springs) = (b.params().unwrap(), b.springs().unwrap());
    let per_env = model.globals.n_springs as usize;
    for (i, s) in b.states().unwrap().iter().enumerate() {
        let contacts = dextrain::env::contact_records(&model, s, &springs[i * per_env..(i + 1) * per_env], &params[i], &model.default_targets());
        let table: Vec<u32> = contacts.iter().filter(|k| k.kind == dextrain::record::ContactKind::ObjectTable).map(|k| k.index).collect();
        assert!(table.iter().filter(|&&k| k < 16).count() >= 8 && !table.iter().any(|k| (16..40).contains(k)), "env {i}: table contacts at support points {table:?}");
    }
}

/// Pieces and masses of every YCB object of ../shared/objects (SOURCES.md's table): source A's OBJ
/// groups at 1000 kg/m³, source B's URDFs with their stated masses.
#[test]
fn ycb_objects_load_with_their_pieces_and_masses() {
    let dir = shared_objects();
    if !dir.is_dir() {
        eprintln!("ycb_objects_load_with_their_pieces_and_masses: {} does not exist; not run", dir.display());
        return;
    }
    // (folder, pieces, URDF mass or None for 1000 kg/m³ × volume and that mass)
    let table: [(&str, usize, f32); 10] = [
        ("003_cracker_box", 1, 0.411),
        ("005_tomato_soup_can", 1, 0.387),
        ("006_mustard_bottle", 2, 0.717),
        ("010_potted_meat_can", 2, 0.426),
        ("011_banana", 3, 0.212),
        ("021_bleach_cleanser", 1, 1.105),
        ("025_mug", 16, 0.226),
        ("035_power_drill", 9, 0.895),
        ("037_scissors", 14, 0.082),
        ("061_foam_brick", 1, 0.214),
    ];
    for (name, pieces, mass) in table {
        let urdf = dir.join(name).join("model.urdf");
        let item = if urdf.is_file() { ObjectItem { urdf: Some(urdf.display().to_string()), ..Default::default() } } else { mesh_item(&dir.join(name).join("collision.obj")) };
        let o = load_one(item).unwrap_or_else(|e| panic!("{name}: {e:#}"));
        eprint!("{}", o.describe());
        assert_eq!(o.name, name);
        assert_eq!(o.pieces.len(), pieces, "{name}");
        let from_urdf = urdf.is_file();
        assert_eq!(o.mass_source, if from_urdf { MassSource::Urdf } else { MassSource::Default }, "{name}");
        assert!((o.mass - mass).abs() < 0.0015, "{name}: mass {} vs {mass}", o.mass);
        // the URDFs' inertia blocks are placeholders (diag 1e-3): the mesh's are used
        assert!(o.inertia.max_element() < 0.9e-3 || !from_urdf || o.inertia.min_element() != 1e-3, "{name}: {:?}", o.inertia);
        assert!(o.inertia.min_element() > 0.0 && o.com.is_finite());
        for p in &o.pieces {
            assert!(p.fit.as_ref().unwrap().volume_ratio >= 1.0 - 1e-4, "{name}");
        }
    }
}

#[test]
fn three_objects_are_drawn_per_env_and_episode() {
    let mut c = object_config(vec![
        ObjectItem { name: Some("cube".into()), ..Default::default() },
        ObjectItem { shape: Some(ObjectShape::Sphere { radius: 0.03 }), mass: Some(0.05), ..Default::default() },
        ObjectItem { mass: Some(0.15), ..mesh_item(Path::new(BOTTLE)) },
    ]);
    c.sim.num_envs = 48;
    // the randomisation keys apply to every object: lengths, mass and friction
    c.randomization.object_scale = [0.7, 1.3];
    c.randomization.object_mass = [0.5, 1.5];
    c.randomization.object_friction = [0.5, 1.5];
    let model = SimModel::from_config(&c).unwrap();
    let names: Vec<&str> = model.objects.iter().map(|o| o.name.as_str()).collect();
    assert_eq!(names, ["cube", "sphere", "bottle"]);
    assert_eq!(model.globals.n_obj_pts, 64, "the bottle (two 16-point cylinders and a 32-vertex hull) has the most support points");
    let mut b = cpu_batch(&c);
    let (params, states) = (b.params().unwrap(), b.states().unwrap());
    let mut count = [0usize; 3];
    for (p, s) in params.iter().zip(&states) {
        let k = p.obj_index as usize;
        count[k] += 1;
        // each env starts resting on its own object's base (scaled), with that object's mass
        // (randomised) and inertia I/m · m · s², its centre of mass and bound scaled
        let (d, sc, m) = (&model.object_descs[k], p.obj_scale, p.obj_inertia[3]);
        assert!((0.7..=1.3).contains(&sc) && (0.5..=1.5).contains(&(m / model.objects[k].mass)), "scale {sc}, mass {m}");
        assert!((s.obj_pos[2] - d.rest_height * sc).abs() < 1e-6);
        assert!((p.obj_rest_height - d.rest_height * sc).abs() < 1e-7);
        for i in 0..3 {
            assert!((p.obj_inertia[i] - d.inertia[i] * m * sc * sc).abs() <= 1e-6 * p.obj_inertia[i]);
            assert!((p.obj_com[i] - d.com[i] * sc).abs() < 1e-7);
        }
        assert!((p.obj_com[3] - d.com[3] * sc).abs() < 1e-7);
    }
    assert!(params.iter().any(|p| (p.obj_friction - params[0].obj_friction).abs() > 1e-3), "friction drawn per env");
    assert!(count.iter().all(|&n| n >= 8), "each object drawn: {count:?}");
    // the next episode draws again: some envs change object
    b.reset(&vec![true; 48]).unwrap();
    let changed = b.params().unwrap().iter().zip(&params).filter(|(a, b)| a.obj_index != b.obj_index).count();
    assert!(changed >= 16, "{changed} of 48 envs changed object at the next episode");
    // all three hold still on the table
    run(&mut b, model.default_targets(), 30);
    for s in b.stats().unwrap() {
        assert_eq!(s.bad_reset, 0);
    }
}

#[test]
fn eval_reports_success_per_object() {
    let tmp = tempfile::tempdir().unwrap();
    let base = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/configs/lift_cube_cpu.toml")).unwrap();
    let single = "shape = { type = \"box\", half_extents = [0.025, 0.025, 0.025] }\nmass = 0.1\n";
    assert!(base.contains(single));
    let text = base.replace(single, "")
        + &format!(
            "\n[[object.set]]\nname = \"cube\"\n\n[[object.set]]\nshape = {{ type = \"cylinder\", radius = 0.025, half_length = 0.03 }}\n\n[[object.set]]\nmesh = \"meshes/bottle.obj\"\nmass = 0.15\n"
        );
    // the mesh relative to the config file
    std::fs::create_dir_all(tmp.path().join("meshes")).unwrap();
    std::fs::copy(BOTTLE, tmp.path().join("meshes/bottle.obj")).unwrap();
    let cfg = tmp.path().join("three.toml");
    std::fs::write(&cfg, text).unwrap();
    let sets: Vec<String> = [
        format!("hand.urdf={}", concat!(env!("CARGO_MANIFEST_DIR"), "/configs/hands/dexhand16.urdf")),
        "sim.backend=cpu".into(),
        "train.device=cpu".into(),
        "sim.num_envs=6".into(),
        "task.episode_length=4".into(),
        "train.iterations=1".into(),
        "train.steps_per_env=4".into(),
        "train.plot_interval=0".into(),
        "policy.actor_hidden=[16]".into(),
        "policy.critic_hidden=[16]".into(),
    ]
    .to_vec();
    let args = dextrain::run::TrainArgs { config: Some(cfg), sets, name: Some("three".into()), resume: None, force: false, runs_dir: tmp.path().into(), stop_after: None, quiet: true, live: Default::default(), gpu_profile: false };
    let dir = dextrain::run::train(&args).expect("train");
    // the saved config names the mesh by its absolute path and loads from the run directory
    let saved = Config::load(&dir.join("config.toml")).unwrap();
    assert_eq!(saved.object.set.len(), 3);
    let Some(MeshFiles::One(mesh)) = &saved.object.set[2].mesh else { panic!("{:?}", saved.object.set[2]) };
    assert!(Path::new(mesh).is_absolute() && mesh.ends_with("meshes/bottle.obj"), "{mesh}");
    let e = dextrain::eval::EvalArgs { run: dir, checkpoint: "latest".into(), episodes: 24, max_envs: 12, seed: Some(5), record: None, backend: None, baseline: None, video: Default::default(), live: Default::default() };
    let r = dextrain::eval::run(&e).unwrap();
    let per: Vec<(&str, usize)> = r.policy.per_object.iter().map(|o| (o.object.as_str(), o.episodes)).collect();
    assert_eq!(per.iter().map(|p| p.0).collect::<Vec<_>>(), ["cube", "cylinder", "bottle"], "{per:?}");
    assert_eq!(per.iter().map(|p| p.1).sum::<usize>(), 24);
    for o in &r.policy.per_object {
        let rows: Vec<_> = r.policy.per_episode.iter().filter(|row| row.object == o.object).collect();
        assert_eq!(rows.len(), o.episodes);
        assert_eq!(o.success_rate, rows.iter().filter(|row| row.success).count() as f64 / rows.len() as f64);
        let lift = rows.iter().map(|row| row.final_lift_m).sum::<f64>() / rows.len() as f64;
        assert!((o.final_lift_height_m.mean - lift).abs() < 1e-12);
    }
    let md = std::fs::read_to_string(r.path.with_extension("md")).unwrap();
    assert!(md.contains("Per object") && md.contains("| bottle |"), "{md}");
}

#[test]
fn bad_object_input_is_a_one_line_error() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let write = |name: &str, text: &str| {
        let p = d.join(name);
        std::fs::write(&p, text).unwrap();
        p
    };
    let open = write("open.obj", "g lid\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 2 4\nf 1 3 4\n");
    let ply = write("cube.ply", "ply\n");
    let many: String = (0..33).map(|k| box_piece(&format!("b{k}"), Vec3::new(0.1 * k as f32, 0.0, 0.0), Vec3::splat(0.01), 8 * k)).collect();
    let many = write("many.obj", &many);
    let two_links = write("two.urdf", "<robot name=\"r\"><link name=\"a\"/><link name=\"b\"/></robot>");
    let cases: Vec<(ObjectItem, Vec<&str>)> = vec![
        (mesh_item(&d.join("missing.obj")), vec!["missing.obj", "object.set[0].mesh"]),
        (mesh_item(&ply), vec!["cube.ply", "unsupported mesh format"]),
        (mesh_item(&open), vec!["open.obj", "piece 'lid'", "closed"]),
        (mesh_item(&many), vec!["many.obj", "33 collision pieces", "at most 32"]),
        (ObjectItem { urdf: Some(two_links.display().to_string()), ..Default::default() }, vec!["two.urdf", "2 links", "single-link"]),
    ];
    for (item, want) in cases {
        let e = format!("{:#}", load_one(item).unwrap_err());
        assert!(!e.contains('\n'), "{e}");
        for w in want {
            assert!(e.contains(w), "{w:?} not in: {e}");
        }
    }
    // two objects of one name (eval and references tell objects apart by name)
    let e = format!("{:#}", load_objects(&object_config(vec![mesh_item(Path::new(BOTTLE)), mesh_item(Path::new(BOTTLE))])).unwrap_err());
    assert!(e.contains("`object.set[0]` and `object.set[1]` are both named 'bottle'") && !e.contains('\n'), "{e}");
    // config keys that contradict each other
    for (toml, want) in [
        ("[object]\nmesh = \"a.obj\"\nshape = { type = \"sphere\", radius = 0.03 }\n", "more than one of `shape`, `mesh`, `urdf`"),
        ("[object]\nmesh = \"a.obj\"\nmass = 0.1\ndensity = 500.0\n", "both `mass` and `density`"),
        ("[object]\nmass = 0.1\n[[object.set]]\nname = \"a\"\n", "`[[object.set]]`"),
        ("[[object.set]]\ndensity = 0.0\n", "object.set[0].density"),
    ] {
        let e = format!("{:#}", Config::from_toml_str(toml, Path::new("objects.toml")).unwrap_err());
        assert!(e.contains(want) && e.contains("objects.toml") && !e.contains('\n'), "{want:?} not in: {e}");
    }
}

/// A hull piece's narrow phase (`physics::hull_project`, `segment_hull_push`) against the exact
/// convex hull of `mesh::hull` (f64): the bottle's shoulder is a frustum no primitive fits within
/// 3 mm, so it collides as its hull.
#[test]
fn hull_pieces_project_like_the_exact_hull() {
    use dextrain::gpu::layout::SHAPE_HULL;
    use dextrain::env::physics::{hull_project, segment_hull_push};
    let mut c = object_config(vec![ObjectItem { mass: Some(0.15), ..mesh_item(Path::new(BOTTLE)) }]);
    c.sim.num_envs = 1;
    let model = SimModel::from_config(&c).unwrap();
    let kinds: Vec<u32> = model.pieces.iter().map(|p| p.shape).collect();
    assert_eq!(kinds, [dextrain::gpu::layout::SHAPE_CYLINDER, SHAPE_HULL, dextrain::gpu::layout::SHAPE_CYLINDER], "body, shoulder, neck");
    let piece = &model.objects[0].pieces[1];
    let h = piece.hull.as_ref().unwrap();
    assert_eq!((h.vertices.len(), model.pieces[1].n_support), (32, 32));
    let exact = dextrain::mesh::hull::convex_hull(&h.vertices.iter().map(|v| v.as_dvec3()).collect::<Vec<_>>()).unwrap();
    let (m, pd) = (model.view(), &model.pieces[1]);
    let mut state = 12345u64;
    let mut rnd = || {
        state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        ((state >> 40) as f32 / (1u64 << 24) as f32) * 2.0 - 1.0
    };
    let (mut inside_n, mut outside_n) = (0, 0);
    for _ in 0..2000 {
        let p = Vec3::new(rnd(), rnd(), rnd()) * 0.045;
        let (q, inside) = hull_project(&m, pd, 1.0, p);
        let want = exact.distance(p.as_dvec3()) as f32;
        if inside {
            inside_n += 1;
            assert!(want < 1e-6, "{p:?} is outside the hull by {want}");
            assert_eq!(q, p);
        } else {
            outside_n += 1;
            assert!(((p - q).length() - want).abs() < 1e-6, "{p:?}: distance {} vs {want}", (p - q).length());
            assert!(exact.distance(q.as_dvec3()) < 1e-6, "the closest point {q:?} is on the hull");
        }
        // a point inside is pushed out through the nearest face plane: onto the hull's surface
        if inside {
            let (n, d, at) = segment_hull_push(&m, pd, 1.0, p, p);
            assert!(d >= 0.0 && (n.length() - 1.0).abs() < 1e-5 && (at - (p + n * d)).length() < 1e-6);
            assert!(exact.distance(at.as_dvec3()) < 1e-6 && exact.plane_distance(at.as_dvec3()).abs() < 1e-6, "{at:?}");
        }
        // scaled by 2: the same answer at twice the distance
        let (q2, inside2) = hull_project(&m, pd, 2.0, 2.0 * p);
        assert_eq!(inside2, inside);
        assert!((q2 - 2.0 * q).length() < 1e-6);
    }
    assert!(inside_n > 50 && outside_n > 500, "{inside_n} inside, {outside_n} outside");
}

/// Source A's mustard bottle: no primitive fits its two rounded hulls (the best box sticks out
/// 20–42 mm), so both collide as their hulls; it rests at the mesh's own height and stays upright.
#[test]
fn the_mustard_bottle_rests_on_its_hulls_at_the_meshs_height() {
    let path = shared_objects().join("006_mustard_bottle/collision.obj");
    if !path.is_file() {
        eprintln!("the_mustard_bottle_rests_on_its_hulls_at_the_meshs_height: {} does not exist; not run", path.display());
        return;
    }
    let mut c = object_config(vec![ObjectItem { mass: Some(0.6), ..mesh_item(&path) }]);
    c.wrist.init_pos = [0.0, 0.0, 0.6];
    c.object.yaw_noise = 3.0;
    let model = SimModel::from_config(&c).unwrap();
    let o = &model.objects[0];
    assert!(o.pieces.iter().all(|p| p.hull.is_some()), "{}", o.describe());
    let pieces = dextrain::mesh::read::parse_obj_pieces(&std::fs::read(&path).unwrap()).unwrap();
    let lowest = pieces.iter().flat_map(|p| p.mesh.vertices.iter()).map(|v| v.z).fold(f64::INFINITY, f64::min) as f32;
    assert!((o.rest_height() + lowest).abs() < 1e-6, "rest height {} vs the mesh's {}", o.rest_height(), -lowest);
    for (i, (d, tilt)) in settle(&c, 10.0).into_iter().enumerate() {
        eprintln!("mustard env {i}: drift {:.4} mm, tilt {:.4}°", d * 1e3, tilt.to_degrees());
        assert!(d < 1e-3 && tilt.to_degrees() < 0.2, "env {i}: drift {:.3} mm, tilt {:.3}°", d * 1e3, tilt.to_degrees());
    }
}

/// A reference names its object (MCAP metadata `object`, CSV `# object: NAME`): both formats keep
/// it, and an env following a reference holds that object on both backends, episode after episode.
#[test]
fn references_name_their_objects() {
    use dextrain::task::{CpuTaskBatch, TaskBatch};
    use dextrain::traj::Trajectory;
    let tmp = tempfile::tempdir().unwrap();
    let configs = Path::new(env!("CARGO_MANIFEST_DIR")).join("configs");
    let base = Trajectory::load(&configs.join("refs/grasp_lift.mcap")).unwrap();
    assert_eq!(base.object_name, None);
    let named = |o: &str| Trajectory { object_name: Some(o.into()), ..base.clone() };
    let (a, b) = (tmp.path().join("a.mcap"), tmp.path().join("b.csv"));
    named("cube").save_mcap(&a).unwrap();
    named("can").save_csv(&b).unwrap();
    assert_eq!(Trajectory::load(&a).unwrap().object_name.as_deref(), Some("cube"));
    assert_eq!(Trajectory::load(&b).unwrap().object_name.as_deref(), Some("can"));
    assert!(std::fs::read_to_string(&b).unwrap().starts_with("# object: can\n"));
    let bad = Trajectory::from_csv_str("# object: \u{7}bell\nt,wrist_x\n", "bad.csv").unwrap_err().to_string();
    assert!(bad.contains("bad.csv") && bad.contains("object name") && !bad.contains('\n'), "{bad}");
    // the physics reset repeats the reference layer's draw: the same purpose and key on both sides
    use dextrain::env::reset;
    use dextrain::task::{reference, shaders::SHADER_REFERENCE};
    assert_eq!((reset::PURPOSE_REF_DRAW, reset::REF_KEY_ID_DRAW), (reference::PURPOSE_REF, reference::REF_KEY_ID));
    for (src, line) in [
        (dextrain::gpu::shaders::SHADER_RESET, format!("const PURPOSE_REF_DRAW: u32 = {}u;", reference::PURPOSE_REF)),
        (dextrain::gpu::shaders::SHADER_RESET, format!("const REF_KEY_ID_DRAW: u32 = {}u;", reference::REF_KEY_ID)),
        (SHADER_REFERENCE, format!("const PURPOSE_REF: u32 = {}u;", reference::PURPOSE_REF)),
        (SHADER_REFERENCE, format!("const REF_KEY_ID: u32 = {}u;", reference::REF_KEY_ID)),
    ] {
        assert!(src.contains(&line), "{line}");
    }

    let mut c = Config::load(&configs.join("grasp_lift.toml")).unwrap();
    c.sim.backend = "cpu".parse().unwrap();
    c.sim.num_envs = 32;
    c.task.kind = "track".parse().unwrap();
    c.task.rewards = dextrain::config::TaskKind::Track.default_rewards();
    c.task.episode_length = 20;
    c.object.shape = None;
    c.object.mass = None;
    c.object.set = vec![
        ObjectItem { name: Some("cube".into()), ..Default::default() },
        ObjectItem { name: Some("ball".into()), shape: Some(ObjectShape::Sphere { radius: 0.03 }), ..Default::default() },
        ObjectItem { name: Some("can".into()), shape: Some(ObjectShape::Cylinder { radius: 0.025, half_length: 0.03 }), ..Default::default() },
    ];
    c.task.reference.files = vec![a.display().to_string(), b.display().to_string()];
    let model = SimModel::from_config(&c).unwrap();
    let mut cpu = CpuTaskBatch::new(&c, model.clone()).unwrap();
    // reference 0 holds the cube (object 0), reference 1 the can (object 2): never the ball
    let check = |params: &[dextrain::env::EnvParams], refs: &[u32]| {
        for (p, r) in params.iter().zip(refs) {
            assert_eq!(p.obj_index, [0, 2][*r as usize], "reference {r}");
        }
        assert!(refs.contains(&0) && refs.contains(&1), "both references drawn: {refs:?}");
    };
    cpu.reset_all().unwrap();
    let zeros = vec![0.0f32; 32 * cpu.spec().action_dim];
    for episode in 0..3u32 {
        let states = cpu.env().states().unwrap();
        assert!(states.iter().all(|s| s.episode == episode), "episode {episode}");
        let refs: Vec<u32> = cpu.task_states().iter().map(|t| t.cursor.ref_id).collect();
        check(&cpu.env().params().unwrap(), &refs);
        // the episode runs out (20 steps): every env starts the next one with a new draw
        for _ in 0..20 {
            cpu.step(&zeros).unwrap();
        }
    }
    // a reference naming an object the config lacks is a one-line error naming both
    let mut bad = c.clone();
    bad.object.set.remove(2);
    let e = format!("{:#}", CpuTaskBatch::new(&bad, SimModel::from_config(&bad).unwrap()).err().unwrap());
    assert!(e.contains("b.csv") && e.contains("names object 'can'") && e.contains("cube, ball") && !e.contains('\n'), "{e}");
    // replay puts the reference's object in every env; an object the config lacks is an error
    let mut one = c.clone();
    one.sim.num_envs = 2;
    let e = format!("{:#}", dextrain::replay::replay(&one, &named("mug"), true, None).unwrap_err());
    assert!(e.contains("names object 'mug'") && e.contains("cube, ball, can"), "{e}");
    let rec = tmp.path().join("ball.mcap");
    dextrain::replay::replay(&one, &named("ball"), true, Some(&rec)).unwrap();
    let bytes = std::fs::read(&rec).unwrap();
    let summary = mcap::read::Summary::read(&bytes).unwrap().expect("a summary");
    let md = summary.metadata_indexes.iter().map(|i| mcap::read::metadata(&bytes, i).unwrap()).find(|m| m.name == "dextrain").expect("dextrain metadata");
    let parts: Vec<dextrain::record::ObjectPart> = serde_json::from_str(&md.metadata["object"]).unwrap();
    assert!(matches!(parts[..], [dextrain::record::ObjectPart { shape: ObjectShape::Sphere { .. }, .. }]), "{parts:?}");
    // the GPU draws the same objects
    let Some(ctx) = gpu_context("references_name_their_objects") else { return };
    let mut gpu = dextrain::task::GpuTaskBatch::new(&c, ctx, model).unwrap();
    gpu.reset_all().unwrap();
    let mut cpu = CpuTaskBatch::new(&c, SimModel::from_config(&c).unwrap()).unwrap();
    cpu.reset_all().unwrap();
    let (pg, pc) = (gpu.env().params().unwrap(), cpu.env().params().unwrap());
    assert_eq!(pg.iter().map(|p| p.obj_index).collect::<Vec<_>>(), pc.iter().map(|p| p.obj_index).collect::<Vec<_>>());
    let refs: Vec<u32> = gpu.task_states().unwrap().iter().map(|t| t.cursor.ref_id).collect();
    check(&pg, &refs);
}
