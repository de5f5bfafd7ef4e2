//! `dextrain new hand` and `dextrain new object` (issue 40, item 7): the starter configs pass what
//! `dextrain check` checks, their paths resolve from wherever they are written (every config here
//! goes to a temporary folder, away from the URDF or mesh), `traj synth`'s grasp on a new hand's
//! config lifts the cube, the guessed fingertips, thumb and wrist orientation are those the real
//! hands' configs of `../shared/hands` name (used when that folder exists; the tests say so when it
//! does not), and bad input is a one-line error that writes nothing.

use std::path::{Path, PathBuf};
use std::process::Command;

use dextrain::config::Config;
use dextrain::env::SimModel;
use dextrain::starter::hand::{HandStarter, new_hand};
use dextrain::starter::object::{ObjectStarter, new_object};
use dextrain::geom::quat_from_rpy as rot_of;
use dextrain::starter::{NewHandArgs, NewObjectArgs};
use dextrain::synth::{SynthArgs, synth};

const ROOT: &str = env!("CARGO_MANIFEST_DIR");

fn root() -> &'static Path {
    Path::new(ROOT)
}

/// `../shared/<sub>` when it exists; else says so for `test`.
fn shared(sub: &str, test: &str) -> Option<PathBuf> {
    let p = root().join("../shared").join(sub);
    if p.is_dir() {
        Some(p)
    } else {
        eprintln!("{test}: {} does not exist; the shipped files only", p.display());
        None
    }
}

fn hand_args(urdf: &Path, out: &Path) -> NewHandArgs {
    NewHandArgs { urdf: urdf.to_path_buf(), out: Some(out.to_path_buf()), force: false }
}

fn object_args(mesh: &Path, out: &Path) -> NewObjectArgs {
    NewObjectArgs { mesh: mesh.to_path_buf(), hand_config: None, out: Some(out.to_path_buf()), force: false, mass: None, mesh_scale: None }
}

/// What `dextrain check` does: load and validate the file, build the model (hand and objects),
/// set the task up.
fn check(path: &Path) -> (Config, SimModel) {
    let cfg = Config::load(path).unwrap_or_else(|e| panic!("{}: {e:#}", path.display()));
    let model = SimModel::from_config(&cfg).unwrap_or_else(|e| panic!("{}: {e:#}", path.display()));
    dextrain::task::task_setup(&cfg, &model).unwrap_or_else(|e| panic!("{}: {e:#}", path.display()));
    (cfg, model)
}

/// The value a config file writes for a path key (as written, before resolving).
fn written_path(text: &str, table: &str, key: &str) -> String {
    let t: toml::Table = text.parse().unwrap();
    t[table][key].as_str().unwrap_or_else(|| panic!("[{table}] {key} is not a string")).to_string()
}

/// The path is written relative (the config works wherever its folder goes) and resolves to `target`.
fn assert_resolves(cfg: &Config, written: &str, target: &Path) {
    assert!(!Path::new(written).is_absolute(), "{written} is written absolute");
    let got = cfg.resolve(written).canonicalize().unwrap_or_else(|e| panic!("{written} from {}: {e}", cfg.base_dir.display()));
    assert_eq!(got, target.canonicalize().unwrap(), "{written}");
}

/// `traj synth`'s antipodal grasp for the config (one env on the CPU), replayed under its physics,
/// as tests/suite/grasp.rs does.
fn grasp_report(cfg: &Config, path: &Path) -> dextrain::replay::ReplayReport {
    let mut c = cfg.clone();
    c.sim.backend = "cpu".parse().unwrap();
    c.sim.num_envs = 1;
    let traj = synth(&c, &SynthArgs::defaults(path.to_path_buf(), "unused.mcap".into())).unwrap_or_else(|e| panic!("{}: {e:#}", path.display()));
    dextrain::replay::replay(&c, &traj, false, None).unwrap()
}

/// The run, task and learner sections of a starter are configs/lift_cube_cpu.toml's (the wrist
/// box's top may be higher for a hand that starts higher).
fn assert_lift_cube_cpu_task(cfg: &Config, name: &str) {
    let reference = Config::load(&root().join("configs/lift_cube_cpu.toml")).unwrap();
    assert_eq!(cfg.seed, reference.seed, "{name}");
    assert_eq!(cfg.sim, reference.sim, "{name}: [sim]");
    assert_eq!(cfg.table, reference.table, "{name}");
    assert_eq!(cfg.contact, reference.contact, "{name}");
    assert_eq!(cfg.randomization, reference.randomization, "{name}");
    let mut task = cfg.task.clone();
    assert!(task.action.wrist_pos_max[2] >= reference.task.action.wrist_pos_max[2], "{name}");
    task.action.wrist_pos_max = reference.task.action.wrist_pos_max;
    task.hand = reference.task.hand.clone();
    assert_eq!(task, reference.task, "{name}: [task]");
    assert_eq!(cfg.train, reference.train, "{name}: [train]");
    assert_eq!(cfg.ppo, reference.ppo, "{name}: [ppo]");
    assert_eq!(cfg.policy, reference.policy, "{name}: [policy]");
    assert_eq!((cfg.object.xy_noise, cfg.object.yaw_noise, cfg.object.friction), (reference.object.xy_noise, reference.object.yaw_noise, reference.object.friction), "{name}");
}

/// `new hand` on `urdf` into `dir/configs/<name>.toml`, checked; the written config, its model and
/// what was guessed.
fn starter_for(urdf: &Path, dir: &Path, name: &str) -> (HandStarter, Config, SimModel) {
    let out = dir.join("configs").join(format!("{name}.toml"));
    let s = new_hand(&hand_args(urdf, &out)).unwrap_or_else(|e| panic!("{name}: {e:#}"));
    assert_eq!(s.path, out);
    assert_eq!(std::fs::read_to_string(&out).unwrap(), s.text, "{name}: the file is the text reported");
    let (cfg, model) = check(&out);
    assert_resolves(&cfg, &written_path(&s.text, "hand", "urdf"), urdf);
    // the config names the guessed tips and thumb
    let tips: Vec<&str> = cfg.hand.fingertips.iter().map(|t| t.name()).collect();
    assert_eq!(tips, s.fingertips, "{name}");
    assert_eq!(cfg.task.hand.thumb, s.thumb, "{name}");
    assert_eq!(model.hand.fingertips.len(), s.fingertips.len(), "{name}");
    (s, cfg, model)
}

/// The angle (rad) between two rotations.
fn angle_between(a: glam::Quat, b: glam::Quat) -> f32 {
    a.angle_between(b)
}

/// Shipped hands: dexhand16 keeps its palm −z / fingers +x frame (no turn), the tri3 claw hangs its
/// fingers down (no turn); both configs check, resolve the URDF from another folder, and `traj
/// synth`'s grasp on them lifts the cube ≥ 8 cm. The other sections are lift_cube_cpu.toml's.
#[test]
fn new_hand_on_the_shipped_hands_checks_and_its_grasp_lifts_the_cube() {
    let dir = tempfile::tempdir().unwrap();
    for (name, tips, thumb) in [("dexhand16", vec!["if_tip", "mf_tip", "rf_tip", "th_tip"], "th_tip"), ("tri3_mimic", vec!["fa_tip", "fb_tip", "fc_tip"], "fa_tip")] {
        let urdf = root().join(format!("configs/hands/{name}.urdf"));
        let (s, cfg, _) = starter_for(&urdf, dir.path(), name);
        assert_eq!(s.fingertips, tips, "{name}");
        assert_eq!(s.thumb, thumb, "{name}");
        assert_eq!(s.init_rpy, [0.0, 0.0, 0.0], "{name}: its root frame already has the palm (or the claw's fingers) down");
        assert_eq!(cfg.hand.mesh_approx, dextrain::config::hand::MeshApprox::Error, "{name}: no meshes, the default stays");
        assert_lift_cube_cpu_task(&cfg, name);
        assert_eq!(cfg.object, Config::load(&root().join("configs/lift_cube_cpu.toml")).unwrap().object, "{name}: lift_cube_cpu.toml's cube");
        let r = grasp_report(&cfg, &s.path);
        eprintln!("{name}: lift {:.3} m, peak penetration {:.2} mm; palm_offset {:?}", r.object_lift_m, r.peak_penetration_mm, s.palm_offset);
        assert!(r.object_lift_m >= 0.08, "{name}: lifted {:.3} m", r.object_lift_m);
        assert_eq!(r.bad_resets, 0, "{name}");
        // the palm point is the held cube's centre, below the palm: inside the hand's reach
        assert!(glam::Vec3::from(s.palm_offset).length() < 0.25, "{name}: palm_offset {:?}", s.palm_offset);
    }
}

/// A hand whose URDF names neither tips nor thumb: dexhand16 with its `*_tip` frames renamed and
/// its thumb's links and joints renamed. The fingertips are the chains' last links (at the far
/// end of their geometry), the thumb is found by its direction (it points back at the fingers),
/// and the grasp still lifts the cube.
#[test]
fn new_hand_without_tip_or_thumb_names_takes_the_last_links_and_the_thumb_by_direction() {
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(root().join("configs/hands/dexhand16.urdf")).unwrap();
    let renamed = text.replace("_tip", "_end").replace("th_", "q4_");
    let urdf = dir.path().join("hands/anon16.urdf");
    std::fs::create_dir_all(urdf.parent().unwrap()).unwrap();
    std::fs::write(&urdf, renamed).unwrap();
    let (s, cfg, model) = starter_for(&urdf, dir.path(), "anon16");
    assert_eq!(s.fingertips, ["if_dist_tip", "mf_dist_tip", "rf_dist_tip", "q4_dist_tip"]);
    assert_eq!(s.thumb, "q4_dist_tip");
    // the pads: beyond the distal joint, at the tip end of the distal link (dexhand16's *_tip
    // frames sit there too)
    let original = SimModel::from_config(&dextrain::config::Config::load(&root().join("configs/grasp_lift.toml")).unwrap()).unwrap();
    for (t, o) in model.hand.fingertips.iter().zip(&original.hand.fingertips) {
        let pos = |h: &dextrain::hand::HandModel, t: &dextrain::hand::Fingertip| h.forward_kinematics(&vec![0.0; h.joints.len()])[t.link].transform_point(t.pos);
        let d = (pos(&model.hand, t) - pos(&original.hand, o)).length();
        assert!(d < 0.02, "{}: {d} m from dexhand16's {}", t.name, o.name);
    }
    assert_eq!(s.init_rpy, [0.0, 0.0, 0.0]);
    let r = grasp_report(&cfg, &s.path);
    eprintln!("anon16: lift {:.3} m, peak penetration {:.2} mm", r.object_lift_m, r.peak_penetration_mm);
    assert!(r.object_lift_m >= 0.08, "lifted {:.3} m", r.object_lift_m);
}

/// The real hands of ../shared/hands: the guessed fingertips (as a set) and thumb are those their
/// configs name (or the thumb the task's default would take), the wrist orientation is theirs
/// (dex-urdf's pitch +90°, LEAP_Hand_Sim's identity), the configs check from another folder, and
/// `traj synth`'s grasp on each lifts the cube ≥ 8 cm. The ROS Allegro (effort="0", velocity="0")
/// gets limits written in.
#[test]
fn new_hand_on_the_real_hands_agrees_with_their_configs_and_lifts_the_cube() {
    let Some(hands) = shared("hands", "new_hand_on_the_real_hands_agrees_with_their_configs_and_lifts_the_cube") else { return };
    let dir = tempfile::tempdir().unwrap();
    for name in ["allegro", "leap", "leap_sim", "inspire", "ability", "schunk_svh", "shadow", "allegro_simlab"] {
        let known = Config::load(&hands.join(name).join("config.toml")).unwrap();
        let urdf = known.resolve(&known.hand.urdf);
        let (s, cfg, _) = starter_for(&urdf, dir.path(), name);
        let mut want: Vec<&str> = known.hand.fingertips.iter().map(|t| t.name()).collect();
        let mut got: Vec<&str> = s.fingertips.iter().map(String::as_str).collect();
        want.sort();
        got.sort();
        assert_eq!(got, want, "{name}: fingertips");
        let thumb = if known.task.hand.thumb.is_empty() { want.iter().find(|t| t.starts_with("th")).unwrap().to_string() } else { known.task.hand.thumb.clone() };
        assert_eq!(s.thumb, thumb, "{name}: thumb");
        let angle = angle_between(rot_of(s.init_rpy), rot_of(known.wrist.init_rpy));
        assert!(angle < 1e-3, "{name}: init_rpy {:?} is {:.1}° from the config's {:?}", s.init_rpy, angle.to_degrees(), known.wrist.init_rpy);
        assert_lift_cube_cpu_task(&cfg, name);
        if name == "allegro_simlab" {
            assert!(s.text.contains("effort = 0.7") && s.text.contains("velocity = 6.0"), "{name}: the missing limits are written:\n{}", s.text);
        }
        let r = grasp_report(&cfg, &s.path);
        eprintln!("{name}: mesh_approx {:?}, lift {:.3} m, peak penetration {:.2} mm, palm_offset {:?}", s.mesh_approx, r.object_lift_m, r.peak_penetration_mm, s.palm_offset);
        assert!(r.object_lift_m >= 0.08, "{name}: lifted {:.3} m", r.object_lift_m);
        assert!(r.peak_penetration_mm < 3.0, "{name}: peak penetration {:.2} mm", r.peak_penetration_mm);
        assert_eq!(r.bad_resets, 0, "{name}");
    }
}

/// `new object` on the shipped bottle (dexhand16 by default) and YCB's mug with the Allegro's
/// config: the configs check from another folder, the mesh and the hand resolve, the mass is
/// 1000 kg/m³ × the loaded volume (or `--mass`), the hand config's keys are copied (the Allegro's
/// `[task.lift] thumb` into `[task.hand]`), and the wrist starts with the open hand above the
/// object's top.
#[test]
fn new_object_writes_configs_that_check() {
    let dir = tempfile::tempdir().unwrap();
    let bottle = root().join("configs/objects/bottle.obj");
    let out = dir.path().join("a/b/bottle.toml");
    let s: ObjectStarter = new_object(&object_args(&bottle, &out)).unwrap();
    let (cfg, model) = check(&out);
    assert_resolves(&cfg, &written_path(&s.text, "object", "mesh"), &bottle);
    assert_resolves(&cfg, &written_path(&s.text, "hand", "urdf"), &root().join("configs/hands/dexhand16.urdf"));
    let o = &model.objects[0];
    assert_eq!(o.name, "bottle");
    assert!((o.mass - 1000.0 * o.volume).abs() < 1e-3 * o.mass, "mass {} for volume {}", o.mass, o.volume);
    assert_eq!(o.mass, s.mass);
    assert_lift_cube_cpu_task(&cfg, "bottle");
    let reference = Config::load(&root().join("configs/lift_cube_cpu.toml")).unwrap();
    assert_eq!(cfg.task.hand, reference.task.hand, "dexhand16's [task.hand]");
    // the bottle is 13 cm tall: the wrist starts higher than lift_cube_cpu's 0.15 m, the open hand
    // 10 cm above the bottle's top
    let (lo, hi) = o.bounding_box();
    let reach = dextrain::starter::pose::reach_below_wrist(&model.hand, rot_of(cfg.wrist.init_rpy), &vec![0.0; model.hand.joints.len()]);
    let clearance = cfg.wrist.init_pos[2] - reach - (hi.z - lo.z);
    assert!((0.099..0.111).contains(&clearance), "clearance {clearance} m at init_pos {:?}", cfg.wrist.init_pos);
    assert!(cfg.task.action.wrist_pos_max[2] >= cfg.wrist.init_pos[2] + 0.1 - 1e-6);

    // --mass is written as given
    let out = dir.path().join("bottle_heavy.toml");
    new_object(&NewObjectArgs { mass: Some(0.5), ..object_args(&bottle, &out) }).unwrap();
    assert_eq!(check(&out).1.objects[0].mass, 0.5);

    if let Some(objects) = shared("objects", "new_object_writes_configs_that_check") {
        let mug = objects.join("025_mug/collision.obj");
        let allegro = root().join("../shared/hands/allegro/config.toml");
        let out = dir.path().join("mug/mug.toml");
        let s = new_object(&NewObjectArgs { hand_config: Some(allegro.clone()), ..object_args(&mug, &out) }).unwrap();
        let (cfg, model) = check(&out);
        assert_eq!(s.name, "025_mug");
        assert_resolves(&cfg, &written_path(&s.text, "object", "mesh"), &mug);
        let known = Config::load(&allegro).unwrap();
        assert_resolves(&cfg, &written_path(&s.text, "hand", "urdf"), &known.resolve(&known.hand.urdf));
        assert_eq!(cfg.hand.fingertips, known.hand.fingertips);
        assert_eq!(cfg.hand.mesh_approx, known.hand.mesh_approx);
        assert_eq!(cfg.wrist.init_rpy, known.wrist.init_rpy);
        assert_eq!(cfg.task.hand.thumb, "link_15.0_tip", "moved from the Allegro config's [task.lift]");
        assert_eq!(model.objects[0].pieces.len(), 16);
    }
}

/// A mesh in millimetres (the bottle's vertices × 1000) is taken as such: `mesh_scale = 0.001`,
/// and the same volume and mass as the bottle in metres.
#[test]
fn new_object_takes_a_mesh_over_a_metre_across_for_millimetres() {
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(root().join("configs/objects/bottle.obj")).unwrap();
    let mm: String = text
        .lines()
        .map(|l| match l.strip_prefix("v ") {
            Some(v) => format!("v {}\n", v.split_whitespace().map(|x| format!("{}", x.parse::<f64>().unwrap() * 1000.0)).collect::<Vec<_>>().join(" ")),
            None => format!("{l}\n"),
        })
        .collect();
    let mesh = dir.path().join("meshes/bottle_mm.obj");
    std::fs::create_dir_all(mesh.parent().unwrap()).unwrap();
    std::fs::write(&mesh, mm).unwrap();
    let s = new_object(&object_args(&mesh, &dir.path().join("cfg/bottle_mm.toml"))).unwrap();
    assert_eq!(s.mesh_scale, 0.001);
    let m = new_object(&object_args(&root().join("configs/objects/bottle.obj"), &dir.path().join("cfg/bottle.toml"))).unwrap();
    assert_eq!(m.mesh_scale, 1.0);
    assert!((s.volume - m.volume).abs() < 1e-4 * m.volume, "{} vs {}", s.volume, m.volume);
    assert!((s.mass - m.mass).abs() < 1e-3 * m.mass);
    check(&s.path);
}

/// An existing output is refused without --force (one line naming it) and left as it was; with
/// --force it is replaced by a config that checks.
#[test]
fn an_existing_output_is_refused_and_left_unchanged() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("taken.toml");
    std::fs::write(&out, "# mine\n").unwrap();
    let urdf = root().join("configs/hands/dexhand16.urdf");
    let bottle = root().join("configs/objects/bottle.obj");
    for e in [new_hand(&hand_args(&urdf, &out)).unwrap_err(), new_object(&object_args(&bottle, &out)).unwrap_err()] {
        let msg = format!("{e:#}");
        assert!(!msg.contains('\n') && msg.contains(&out.display().to_string()) && msg.contains("--force"), "{msg}");
        assert_eq!(std::fs::read_to_string(&out).unwrap(), "# mine\n");
    }
    new_hand(&NewHandArgs { force: true, ..hand_args(&urdf, &out) }).unwrap();
    check(&out);
    new_object(&NewObjectArgs { force: true, ..object_args(&bottle, &out) }).unwrap();
    assert_eq!(check(&out).1.objects[0].name, "bottle");
    // nothing else is left in the folder (no temporary file)
    let names: Vec<_> = std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert_eq!(names, ["taken.toml"]);
}

/// Bad input (a missing or unparseable URDF, a missing mesh, a mesh of another format) is a
/// one-line error naming the file and what was expected, and writes nothing.
#[test]
fn bad_input_is_one_line_naming_the_file_and_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let garbage = dir.path().join("garbage.urdf");
    std::fs::write(&garbage, "<robot name=\"x\"><link name=\"a\">").unwrap();
    let ply = dir.path().join("thing.ply");
    std::fs::write(&ply, "ply\n").unwrap();
    let missing_urdf = dir.path().join("nowhere/hand.urdf");
    let missing_mesh = dir.path().join("nowhere/thing.obj");
    let out = dir.path().join("out/x.toml");
    let cases: Vec<(PathBuf, anyhow::Error, &str)> = vec![
        (missing_urdf.clone(), new_hand(&hand_args(&missing_urdf, &out)).unwrap_err(), "URDF"),
        (garbage.clone(), new_hand(&hand_args(&garbage, &out)).unwrap_err(), "expected"),
        (missing_mesh.clone(), new_object(&object_args(&missing_mesh, &out)).unwrap_err(), "mesh"),
        (ply.clone(), new_object(&object_args(&ply, &out)).unwrap_err(), ".obj or .stl"),
    ];
    for (file, e, expected) in cases {
        let msg = format!("{e:#}");
        assert!(!msg.contains('\n'), "{msg}");
        assert!(msg.contains(&file.display().to_string()), "{msg} names {}", file.display());
        assert!(msg.contains(expected), "{msg} says {expected}");
        assert!(!out.exists() && !out.parent().unwrap().exists(), "{msg}: something was written");
    }
}

fn dextrain(args: &[&str], cwd: &Path) -> (bool, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_dextrain")).args(args).current_dir(cwd).env("XDG_RUNTIME_DIR", "/tmp").output().unwrap();
    (out.status.success(), String::from_utf8_lossy(&out.stdout).into_owned(), String::from_utf8_lossy(&out.stderr).into_owned())
}

/// Through the binary: `dextrain new hand URDF` writes `<stem>_lift.toml` in the current
/// directory, prints its path (stdout) and every guess with its reason (stderr), and `dextrain
/// check` passes on it; run again it exits non-zero with one line and leaves the file.
#[test]
fn new_hand_command_writes_the_default_file_and_says_its_guesses() {
    let dir = tempfile::tempdir().unwrap();
    let urdf = root().join("configs/hands/dexhand16.urdf");
    let (ok, stdout, stderr) = dextrain(&["new", "hand", urdf.to_str().unwrap()], dir.path());
    assert!(ok, "{stderr}");
    assert_eq!(stdout.trim(), "dexhand16_lift.toml");
    for said in ["hand.fingertips = if_tip, mf_tip, rf_tip, th_tip —", "task.hand.thumb = th_tip —", "wrist.init_rpy = [0.0, 0.0, 0.0] —", "wrist.init_pos =", "task.hand.palm_offset =", "no mesh collisions"] {
        assert!(stderr.contains(said), "stderr says {said:?}:\n{stderr}");
    }
    let written = std::fs::read_to_string(dir.path().join("dexhand16_lift.toml")).unwrap();
    let (ok, _, stderr) = dextrain(&["check", "dexhand16_lift.toml"], dir.path());
    assert!(ok, "{stderr}");
    let (ok, stdout, stderr) = dextrain(&["new", "hand", urdf.to_str().unwrap()], dir.path());
    assert!(!ok && stdout.is_empty());
    assert_eq!(stderr.lines().count(), 1, "{stderr}");
    assert!(stderr.starts_with("error: dexhand16_lift.toml: the file exists") && stderr.contains("--force"), "{stderr}");
    assert_eq!(std::fs::read_to_string(dir.path().join("dexhand16_lift.toml")).unwrap(), written);
    let (ok, _, stderr) = dextrain(&["new", "object", "no_such.stl"], dir.path());
    assert!(!ok && stderr.lines().count() == 1 && stderr.contains("no_such.stl"), "{stderr}");
    // a hand that loads but cannot be planned for (one finger: no antipodal grasp) fails after the
    // --out folders were made (its text is checked from there): the folders it made are gone
    // again, nothing else is touched
    let one = r#"<robot name="one">
  <link name="palm"><collision><geometry><box size="0.08 0.08 0.02"/></geometry></collision><inertial><mass value="0.3"/><inertia ixx="1e-4" iyy="1e-4" izz="1e-4" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="f1"><collision><origin xyz="0 0 0.02"/><geometry><box size="0.015 0.015 0.04"/></geometry></collision><inertial><mass value="0.02"/><inertia ixx="1e-6" iyy="1e-6" izz="1e-6" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <joint name="j1" type="revolute"><parent link="palm"/><child link="f1"/><origin xyz="0.03 0 0.01"/><axis xyz="0 1 0"/><limit lower="0" upper="1.5" effort="1" velocity="5"/></joint>
</robot>"#;
    std::fs::write(dir.path().join("one.urdf"), one).unwrap();
    let (ok, _, stderr) = dextrain(&["new", "hand", "one.urdf", "--out", "made/deeper/one.toml"], dir.path());
    assert!(!ok && stderr.contains("one finger chain"), "{stderr}");
    assert!(!dir.path().join("made").exists(), "a failed `new` left the folders it made");
    assert!(dir.path().join("dexhand16_lift.toml").is_file());
}
