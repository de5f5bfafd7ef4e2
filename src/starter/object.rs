//! `dextrain new object MESH`: a starter lift config for an object from a mesh, with the hand of
//! another config.
//!
//! - **The object**: `[object] mesh` is the mesh, its path relative to the written file's folder,
//!   loaded by the object loader (each OBJ group/object, or the STL file, one convex piece: a
//!   fitted primitive or its hull; docs/objects.md). A mesh more than [`MILLIMETRE_EXTENT_M`]
//!   across at scale 1 is taken to be in millimetres (`mesh_scale = 0.001`) unless `--mesh-scale`
//!   says otherwise. The mass is `--mass`, else [`STARTER_DENSITY_KG_M3`] × the closed pieces'
//!   volume (water's density, the loader's own default), written out so that it can be edited.
//! - **The hand**: `[hand]`, `[wrist]` and `[task.hand]` of `--hand-config` (default
//!   configs/lift_cube_cpu.toml: dexhand16) as that file writes them (keys it left at their
//!   defaults stay so; keys of `[task.lift]`'s old place move to `[task.hand]`), `hand.urdf`
//!   re-written relative to the new file. The wrist starts higher where the open hand would
//!   otherwise be less than [`super::pose::START_CLEARANCE_M`] above the object's top.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};

use super::pose;
use super::template::{self, Section, Starter, num, string, vec3};
use super::{NewObjectArgs, output};
use crate::config::object::DEFAULT_DENSITY;
use crate::config::{Config, MeshFiles, ObjectItem};
use crate::hand::{HandLoadOptions, HandModel};
use crate::object::ObjectModel;

/// Density (kg/m³) the mass is guessed at: water's, the object loader's default
/// (`config::object::DEFAULT_DENSITY`).
pub const STARTER_DENSITY_KG_M3: f32 = DEFAULT_DENSITY;
/// A mesh whose largest extent at scale 1 is above this (m) is taken to be in millimetres.
pub const MILLIMETRE_EXTENT_M: f32 = 1.0;
/// The hand config used without `--hand-config`, relative to the current directory or to the
/// source checkout.
pub const DEFAULT_HAND_CONFIG: &str = "configs/lift_cube_cpu.toml";

/// What `dextrain new object` wrote and what it guessed.
#[derive(Clone, Debug)]
pub struct ObjectStarter {
    /// The config written.
    pub path: PathBuf,
    /// The object's name (the file's stem, or its folder's for `collision.obj`).
    pub name: String,
    /// `object.mass` (kg).
    pub mass: f32,
    /// `object.mesh_scale`.
    pub mesh_scale: f32,
    /// The mesh's volume at that scale (m³).
    pub volume: f32,
    /// The hand config copied.
    pub hand_config: PathBuf,
    /// The file's text.
    pub text: String,
}

/// `dextrain new object`: guesses, writes and checks the starter config (see the module
/// documentation), printing each guess and its reason.
pub fn new_object(args: &NewObjectArgs) -> Result<ObjectStarter> {
    let mesh = &args.mesh;
    if !mesh.is_file() {
        let what = if mesh.exists() { "not a file" } else { "no such file" };
        bail!("{}: {what}; expected an object mesh (.obj or .stl)", mesh.display());
    }
    if let Some(s) = args.mesh_scale
        && !(s.is_finite() && s > 0.0)
    {
        bail!("--mesh-scale {s}: expected a factor > 0 on the mesh's coordinates (0.001 for millimetres)");
    }
    if let Some(m) = args.mass
        && !(m.is_finite() && (1e-4..=1e3).contains(&m))
    {
        bail!("--mass {m}: expected a mass in [1e-4, 1000] kg");
    }
    let hand_path = match &args.hand_config {
        Some(p) => p.clone(),
        None => default_hand_config()?,
    };
    let hand_cfg = Config::load(&hand_path)?;
    let opts = HandLoadOptions {
        fingertips: hand_cfg.hand.fingertips.clone(),
        mesh_approx: hand_cfg.hand.mesh_approx,
        effort: hand_cfg.hand.effort.clone(),
        velocity: hand_cfg.hand.velocity.clone(),
    };
    let urdf = hand_cfg.resolve(&hand_cfg.hand.urdf);
    let hand = HandModel::from_urdf_file(&urdf, &opts).with_context(|| format!("{}: key `hand.urdf` = {:?}", hand_path.display(), hand_cfg.hand.urdf))?;
    let abs_mesh = output::absolute(mesh)?;

    // the mesh at scale 1 (its size decides the unit), then at the scale chosen
    let probe = load_mesh(&abs_mesh, 1.0)?;
    let extent = size(&probe).max_element();
    let (scale, scale_note) = match args.mesh_scale {
        Some(s) => (s, Some(format!("--mesh-scale {s}"))),
        None if extent > MILLIMETRE_EXTENT_M => (
            0.001,
            Some(format!("the mesh is {extent:.1} units across at scale 1, more than {MILLIMETRE_EXTENT_M} m: taken to be in millimetres (give --mesh-scale otherwise)")),
        ),
        None => (1.0, None),
    };
    let object = if scale == 1.0 { probe } else { load_mesh(&abs_mesh, scale)? };
    let volume = object.volume;
    let (mass, mass_note) = match args.mass {
        Some(m) => (m, "--mass".to_string()),
        None => {
            let m = STARTER_DENSITY_KG_M3 * volume;
            if !(m.is_finite() && (1e-4..=1e3).contains(&m)) {
                bail!(
                    "{}: the mesh's volume {volume:.3e} m³ at {STARTER_DENSITY_KG_M3} kg/m³ gives {m:.3e} kg; expected a mass in [1e-4, 1000] kg: give --mass (or --mesh-scale for a mesh not in metres)",
                    mesh.display()
                );
            }
            // four significant digits
            let digits = 3 - m.log10().floor() as i32;
            let m = ((m as f64 * 10f64.powi(digits)).round() / 10f64.powi(digits)) as f32;
            (m, format!("guessed: {STARTER_DENSITY_KG_M3} kg/m³ (water's, the loader's default density) × the mesh's volume {volume:.3e} m³; set the real mass here or with --mass"))
        }
    };
    let out = output::output_path(args.out.as_deref(), &object.name);
    output::refuse_existing(&out, args.force)?;
    let dims = size(&object);
    crate::console::status(&format!(
        "dextrain new object: {}: '{}', {} piece(s), {:.1} × {:.1} × {:.1} cm, volume {volume:.3e} m³",
        mesh.display(),
        object.name,
        object.pieces.len(),
        dims.x * 100.0,
        dims.y * 100.0,
        dims.z * 100.0
    ));
    if let Some(n) = &scale_note {
        crate::console::status(&format!("  object.mesh_scale = {scale} — {n}"));
    }
    crate::console::status(&format!("  object.mass = {mass} kg — {mass_note}"));

    // [object]
    let dir = out.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    let mut object_s = Section::new("object");
    object_s.push(
        &[format!(
            "relative to this file's folder (every path in a config is); each OBJ group/object (or the STL file) is one convex piece, fitted by a primitive or collided as its hull: {} piece(s) (`dextrain check` prints each)",
            object.pieces.len()
        )],
        "mesh",
        string(&output::path_from(dir, mesh)?),
    );
    if let Some(n) = &scale_note {
        object_s.push(std::slice::from_ref(n), "mesh_scale", num(scale, 6));
    }
    object_s.push(&[mass_note.clone()], "mass", num(mass, 6));
    template::push_object_common(&mut object_s);

    // [hand], [wrist], [task.hand] of the hand config
    let (mut hand_s, mut wrist_s, mut task_hand_s) = copied_sections(&hand_path)?;
    let from = hand_path.display().to_string();
    hand_s.comment = vec![format!("[hand] of {from}, hand.urdf re-written relative to this file's folder")];
    // urdf first, as configs write it
    hand_s.entries.retain(|e| e.key != "urdf");
    hand_s.entries.insert(0, template::Entry { comment: vec![], key: "urdf".into(), value: string(&output::path_from(dir, &urdf)?) });
    wrist_s.comment = vec![format!("[wrist] of {from}")];
    task_hand_s.comment = vec![if task_hand_s.get("palm_offset").is_some() {
        format!("[task.hand] of {from}: its palm_offset is where that config's object sits in the grasp; `dextrain traj synth` on this file prints the point for this object (\"object centre in the wrist frame\")")
    } else {
        format!("[task.hand] of {from} (palm_offset at its default: `dextrain traj synth` on this file prints the point for this object, \"object centre in the wrist frame\")")
    }];
    // the start height: the open hand clear above the object's top
    let top = dims.z;
    // the simulator's start: hand.init_joints, else 0, clamped into the limits
    let q = hand.with_mimic(hand.joints.iter().map(|j| hand_cfg.hand.init_joints.get(&j.name).copied().unwrap_or(0.0).clamp(j.lower, j.upper)).collect());
    let rot = crate::geom::quat_from_rpy(hand_cfg.wrist.init_rpy);
    let need = ((top + pose::START_CLEARANCE_M + pose::reach_below_wrist(&hand, rot, &q)) * 100.0 - 1e-3).ceil() / 100.0;
    let mut init = hand_cfg.wrist.init_pos;
    if init[2] < need {
        crate::console::status(&format!(
            "  wrist.init_pos z = {need:.2} m (was {:.2} in {from}) — the open hand's lowest point {:.0} cm above the object's top ({:.1} cm)",
            init[2],
            pose::START_CLEARANCE_M * 100.0,
            top * 100.0
        ));
        init[2] = need;
        let comment = vec![format!(
            "raised from {from}'s so that the open hand's lowest point is {:.0} cm above the object's top ({:.1} cm)",
            pose::START_CLEARANCE_M * 100.0,
            top * 100.0
        )];
        match wrist_s.entries.iter_mut().find(|e| e.key == "init_pos") {
            Some(e) => {
                e.value = vec3(init, 3);
                e.comment = comment;
            }
            None => wrist_s.push(&comment, "init_pos", vec3(init, 3)),
        }
    }
    crate::console::status(&format!("  [hand], [wrist], [task.hand]: {from}'s (hand {}), hand.urdf relative to {}", urdf.display(), dir.display()));
    let starter = Starter {
        title: title(mesh, &out, &object.name, &from),
        hand: hand_s,
        wrist: wrist_s,
        object: object_s,
        task_hand: task_hand_s,
        wrist_pos_max_z: (init[2] + 0.1).max(0.35),
    };
    let text = template::render(&starter);
    super::check_and_write(&text, &out, args.force)?;
    crate::console::status(&format!(
        "wrote {}: `dextrain check` passes on it; next: `dextrain traj synth {} --out grasp.mcap` (does the hand lift it?), then `dextrain train {}`",
        out.display(),
        out.display(),
        out.display()
    ));
    Ok(ObjectStarter { path: out, name: object.name, mass, mesh_scale: scale, volume, hand_config: hand_path, text })
}

/// The object of a mesh file (absolute path) at `scale`, at 1 kg (the mass is decided later).
fn load_mesh(mesh: &Path, scale: f32) -> Result<ObjectModel> {
    let item = ObjectItem { mesh: Some(MeshFiles::One(mesh.display().to_string())), mass: Some(1.0), mesh_scale: scale, ..Default::default() };
    crate::object::load::load_object(&item, "object.mesh", "dextrain new object", &|p| PathBuf::from(p))
}

/// The size (m) of the box around the object's pieces.
fn size(o: &ObjectModel) -> glam::Vec3 {
    let (lo, hi) = o.bounding_box();
    hi - lo
}

/// configs/lift_cube_cpu.toml in the current directory, else in the source checkout this binary
/// was built from.
fn default_hand_config() -> Result<PathBuf> {
    let here = PathBuf::from(DEFAULT_HAND_CONFIG);
    if here.is_file() {
        return Ok(here);
    }
    let built = Path::new(env!("CARGO_MANIFEST_DIR")).join(DEFAULT_HAND_CONFIG);
    if built.is_file() {
        return Ok(built);
    }
    bail!("{DEFAULT_HAND_CONFIG}: not in the current directory nor in {}; expected --hand-config CONFIG naming a config with the hand", env!("CARGO_MANIFEST_DIR"))
}

/// `[hand]`, `[wrist]` and `[task.hand]` as the hand config writes them, the keys of `[task.lift]`'s
/// old place (`config::MOVED_KEYS`) moved into `[task.hand]`.
fn copied_sections(path: &Path) -> Result<(Section, Section, Section)> {
    let text = std::fs::read_to_string(path).with_context(|| format!("cannot read config file {}", path.display()))?;
    let table: toml::Table = text.parse().with_context(|| format!("{}: invalid TOML", path.display()))?;
    let sub = |v: Option<&toml::Value>, key: &str| v.and_then(|t| t.get(key)).and_then(|t| t.as_table()).cloned().unwrap_or_default();
    let root = toml::Value::Table(table);
    let to_section = |name: &str, t: &toml::Table| {
        let mut s = Section::new(name);
        for (k, v) in t {
            s.push(&[], k, v.clone());
        }
        s
    };
    let task = root.get("task");
    let mut task_hand = sub(task, "hand");
    let lift = sub(task, "lift");
    for (old, key, new) in crate::config::MOVED_KEYS {
        if old == "lift"
            && new == "hand"
            && let Some(v) = lift.get(key)
        {
            task_hand.insert(key.to_string(), v.clone());
        }
    }
    Ok((to_section("hand", &sub(Some(&root), "hand")), to_section("wrist", &sub(Some(&root), "wrist")), to_section("task.hand", &task_hand)))
}

/// The comment lines at the top of the file.
fn title(mesh: &Path, out: &Path, name: &str, hand_config: &str) -> Vec<String> {
    let file = mesh.file_name().map(|f| f.to_string_lossy().into_owned()).unwrap_or_default();
    let me = out.file_name().map(|f| f.to_string_lossy().into_owned()).unwrap_or_default();
    vec![
        format!(
            "Grasp and lift '{name}' ({file}) with the hand of {hand_config}: PPO sized for a 2-core CPU. Written by `dextrain new object {}`: [object] is guessed from the mesh, [hand], [wrist] and [task.hand] are {hand_config}'s, everything else is configs/lift_cube_cpu.toml. Does the hand lift it? `dextrain traj synth` on this file plans a grasp, replays it and prints the object's place in the wrist frame (a task.hand.palm_offset for this object).",
            mesh.display()
        ),
        String::new(),
        format!("  dextrain check {me}"),
        format!("  dextrain traj synth {me} --out grasp.mcap"),
        format!("  dextrain train {me}"),
    ]
}
