//! `dextrain new hand URDF`: a starter lift config for a hand that has none, every hand-specific
//! key guessed from the URDF by the loader and the planner the rest of dextrain uses, and said.
//!
//! The guesses, in order:
//! 1. **Colliders and limits.** The URDF is loaded by the hand loader with `mesh_approx =
//!    "capsule"`; a hand with `<mesh>` collisions keeps it (or `"box"`, where only that one's
//!    grasp lifts the cube in step 6). A movable joint whose URDF `effort` or `velocity` is missing
//!    or 0 (the ROS Allegro description writes 0) gets the median of the hand's other joints'
//!    limits, or [`FALLBACK_EFFORT_NM`] / [`FALLBACK_VELOCITY_RAD_S`] where no joint has one
//!    (`hand.effort`, `hand.velocity`).
//! 2. **Fingertips**, one per finger chain, and 3. **the thumb**: [`super::fingers`] (the loader's
//!    name rule, else the chains' last links; the thumb by name, else the finger that points
//!    across the others).
//! 4. **Wrist orientation** from the geometry ([`super::pose`]): palm down, fingers along +x.
//! 5. **Start height**: the open hand's lowest point [`super::pose::START_CLEARANCE_M`] above the
//!    cube's top, the wrist over the cube's nominal place.
//! 6. **Palm point**: `traj synth`'s antipodal grasp is planned for the config and replayed under
//!    its physics; `task.hand.palm_offset` is where the cube's centre sits in the wrist frame in
//!    that grasp (what `traj synth` prints: docs/hands.md says not to guess it from the URDF).

use std::path::{Path, PathBuf};

use anyhow::{Result, anyhow, bail};

use super::fingers::{TipGuess, guess_thumb, guess_tips};
use super::pose::{self, WristOrientation};
use super::template::{self, Section, Starter, num, string, vec3};
use super::{NewHandArgs, output};
use crate::config::hand::{FingertipSpec, JointLimitOverride, MeshApprox};
use crate::config::{BackendChoice, Config};
use crate::env::SimModel;
use crate::hand::{HandLoadOptions, HandModel};
use crate::synth::grasp::object_centre;
use crate::synth::{SynthArgs, VERIFY_LIFT_FRACTION, VERIFY_PEAK_PENETRATION_MM, synth};

/// Effort limit (N·m) given to the joints whose URDF has none when no joint of the hand has one:
/// the Allegro hand's rated joint torque (a small hand servo's).
pub const FALLBACK_EFFORT_NM: f32 = 0.7;
/// Velocity limit (rad/s) given to the joints whose URDF has none when no joint of the hand has
/// one (a small hand servo's, about 1 turn per second).
pub const FALLBACK_VELOCITY_RAD_S: f32 = 6.0;
/// Height (m) of the top of the starter's cube (5 cm, resting on the table).
pub const CUBE_TOP_M: f32 = 0.05;

/// What `dextrain new hand` wrote and what it guessed.
#[derive(Clone, Debug)]
pub struct HandStarter {
    /// The config written.
    pub path: PathBuf,
    /// The fingertips' names, in the config's order.
    pub fingertips: Vec<String>,
    /// The thumb's fingertip.
    pub thumb: String,
    /// `wrist.init_rpy`.
    pub init_rpy: [f32; 3],
    /// `wrist.init_pos`.
    pub init_pos: [f32; 3],
    /// `task.hand.palm_offset`.
    pub palm_offset: [f32; 3],
    /// `hand.mesh_approx`.
    pub mesh_approx: MeshApprox,
    /// How far the planned grasp lifted the cube in its replay (m).
    pub lift_m: f64,
    /// The deepest hand–object penetration in that replay (mm).
    pub peak_penetration_mm: f64,
    /// The file's text.
    pub text: String,
}

/// Effort and velocity limits the URDF lacks, and what was said about them.
#[derive(Clone, Debug, Default)]
struct Limits {
    effort: Option<JointLimitOverride>,
    velocity: Option<JointLimitOverride>,
    notes: Vec<String>,
}

/// Everything guessed for one `mesh_approx`, with the config text that holds it.
struct Plan {
    approx: MeshApprox,
    tips: Vec<TipGuess>,
    thumb: String,
    orientation: WristOrientation,
    init_pos: [f32; 3],
    palm_offset: [f32; 3],
    lift_m: f64,
    penetration_mm: f64,
    starter: Starter,
    mesh_colliders: usize,
}

/// `dextrain new hand`: guesses, writes and checks the starter config (see the module
/// documentation), printing each guess and its reason.
pub fn new_hand(args: &NewHandArgs) -> Result<HandStarter> {
    let urdf = &args.urdf;
    if !urdf.is_file() {
        let what = if urdf.exists() { "not a file" } else { "no such file" };
        bail!("{}: {what}; expected a hand URDF (.urdf)", urdf.display());
    }
    let stem = urdf.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| "hand".into());
    let out = output::output_path(args.out.as_deref(), &stem);
    output::refuse_existing(&out, args.force)?;
    let limits = Limits::default();
    let (hand, limits) = match load(urdf, MeshApprox::Capsule, &[], &limits) {
        Ok(h) => (h, limits),
        Err(first) => {
            let limits = guess_limits(urdf).ok_or(first)?;
            (load(urdf, MeshApprox::Capsule, &[], &limits)?, limits)
        }
    };
    crate::console::status(&format!(
        "dextrain new hand: {}: robot '{}', {} links, {} movable joints ({} actuated), {} finger chains, {} colliders",
        urdf.display(),
        hand.name,
        hand.links.len(),
        hand.joints.len(),
        hand.num_actuated(),
        hand.finger_chains().len(),
        hand.colliders.len()
    ));
    for n in &limits.notes {
        crate::console::status(&format!("  limits: {n}"));
    }
    // hand.urdf relative to the file's folder, which is made now: the guesses load the config as
    // it will be written (a relative path resolves only from a folder that exists)
    let dir = out.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    let rel = output::path_from(dir, urdf)?;
    std::fs::create_dir_all(dir).map_err(|e| anyhow!("cannot create the folder {}: {e}", dir.display()))?;
    let mut plan = self::plan(urdf, &rel, &out, hand, MeshApprox::Capsule, &limits)?;
    if plan.mesh_colliders > 0 && !plan.lifts() {
        crate::console::status(&format!(
            "  with capsule colliders the grasp lifts the cube {:.3} m, peak penetration {:.2} mm (wanted: ≥ {:.3} m, < {VERIFY_PEAK_PENETRATION_MM} mm): trying boxes (hand.mesh_approx = \"box\")",
            plan.lift_m,
            plan.penetration_mm,
            lift_goal()
        ));
        let boxed = load(urdf, MeshApprox::Box, &[], &limits).and_then(|h| self::plan(urdf, &rel, &out, h, MeshApprox::Box, &limits));
        match boxed {
            Ok(b) if (b.lifts(), b.lift_m) > (plan.lifts(), plan.lift_m) => plan = b,
            Ok(b) => crate::console::status(&format!("  with boxes it lifts {:.3} m: keeping the capsules", b.lift_m)),
            Err(e) => crate::console::status(&format!("  with boxes: {}", crate::text::one_line(&format!("{e:#}")))),
        }
    }
    if !plan.lifts() {
        crate::console::warn(&format!(
            "warning: {}: the planned grasp lifts the cube {:.3} m with {:.2} mm peak penetration in simulation (wanted: ≥ {:.3} m, < {VERIFY_PEAK_PENETRATION_MM} mm); the config is written: check its orientation and fingertips (docs/hands.md)",
            urdf.display(),
            plan.lift_m,
            plan.penetration_mm,
            lift_goal()
        ));
    }
    let text = template::render(&plan.starter);
    super::check_and_write(&text, &out, args.force)?;
    crate::console::status(&format!(
        "wrote {}: `dextrain check` passes on it; next: `dextrain traj synth {} --out grasp.mcap`, then `dextrain train {}`",
        out.display(),
        out.display(),
        out.display()
    ));
    Ok(HandStarter {
        path: out,
        fingertips: plan.tips.iter().map(|t| t.tip.name.clone()).collect(),
        thumb: plan.thumb,
        init_rpy: plan.orientation.rpy,
        init_pos: plan.init_pos,
        palm_offset: plan.palm_offset,
        mesh_approx: plan.approx,
        lift_m: plan.lift_m,
        peak_penetration_mm: plan.penetration_mm,
        text,
    })
}

impl Plan {
    /// Whether the planned grasp passes `traj synth`'s own check in its replay: it lifts the cube
    /// [`lift_goal`] with less than `VERIFY_PEAK_PENETRATION_MM`.
    fn lifts(&self) -> bool {
        self.lift_m >= lift_goal() && self.penetration_mm < VERIFY_PEAK_PENETRATION_MM
    }
}

/// The lift the planned grasp must reach in its replay: `traj synth`'s own bar
/// (`VERIFY_LIFT_FRACTION` of its default 0.15 m).
fn lift_goal() -> f64 {
    (VERIFY_LIFT_FRACTION * SynthArgs::defaults(PathBuf::new(), PathBuf::new()).lift) as f64
}

/// Loads the URDF with the loader's options for these guesses.
fn load(urdf: &Path, approx: MeshApprox, tips: &[FingertipSpec], limits: &Limits) -> Result<HandModel> {
    let opts = HandLoadOptions { fingertips: tips.to_vec(), mesh_approx: approx, effort: limits.effort.clone(), velocity: limits.velocity.clone() };
    HandModel::from_urdf_file(urdf, &opts)
}

/// Limits for the movable joints whose URDF `effort` or `velocity` is missing, 0 or not finite
/// (urdf-rs reads a missing `<limit>` as zeros): the median of the others, else the fallback.
/// `None` where the URDF does not parse or every joint has both (the loader's error stands).
fn guess_limits(urdf: &Path) -> Option<Limits> {
    let robot = urdf_rs::read_file(urdf).ok()?;
    let movable: Vec<&urdf_rs::Joint> =
        robot.joints.iter().filter(|j| matches!(j.joint_type, urdf_rs::JointType::Revolute | urdf_rs::JointType::Continuous)).collect();
    let mut limits = Limits::default();
    for (what, unit, fallback) in [("effort", "N·m", FALLBACK_EFFORT_NM), ("velocity", "rad/s", FALLBACK_VELOCITY_RAD_S)] {
        let value = |j: &urdf_rs::Joint| if what == "effort" { j.limit.effort } else { j.limit.velocity };
        let ok = |v: f64| v.is_finite() && v > 0.0;
        let missing: Vec<&str> = movable.iter().filter(|j| !ok(value(j))).map(|j| j.name.as_str()).collect();
        if missing.is_empty() {
            continue;
        }
        let mut given: Vec<f64> = movable.iter().map(|j| value(j)).filter(|v| ok(*v)).collect();
        given.sort_by(f64::total_cmp);
        let (v, why) = match given.len() {
            0 => (fallback, format!("no joint of the URDF has one: {fallback} {unit}, a small hand servo's (the Allegro hand's); replace it with the hand's rating")),
            n => (given[n / 2] as f32, format!("the median of the other joints' URDF {what} limits")),
        };
        let over = if missing.len() == movable.len() {
            JointLimitOverride::All(v)
        } else {
            JointLimitOverride::PerJoint(missing.iter().map(|n| (n.to_string(), v)).collect())
        };
        limits.notes.push(format!("{} of {} movable joints have no URDF {what} limit (missing or 0): hand.{what} = {v} {unit}, {why}", missing.len(), movable.len()));
        if what == "effort" {
            limits.effort = Some(over);
        } else {
            limits.velocity = Some(over);
        }
    }
    (limits.effort.is_some() || limits.velocity.is_some()).then_some(limits)
}

/// Guesses everything for the hand as loaded (with `mesh_approx = approx`), plans and replays the
/// grasp; `rel` is the URDF's path from the config's folder.
fn plan(urdf: &Path, rel: &str, out: &Path, loaded: HandModel, approx: MeshApprox, limits: &Limits) -> Result<Plan> {
    // without meshes the key is not written: its default stays
    let approx = if loaded.mesh_fits.is_empty() { MeshApprox::Error } else { approx };
    let tips = guess_tips(&loaded)?;
    let mut hand = loaded.clone();
    hand.fingertips = tips.iter().map(|t| t.tip.clone()).collect();
    if hand.fingertips.len() < 2 {
        bail!(
            "{}: one finger chain ({}); expected a hand with a thumb and at least one finger (an antipodal grasp needs two fingertips)",
            urdf.display(),
            hand.fingertips.first().map(|t| t.name.as_str()).unwrap_or("")
        );
    }
    let (thumb, thumb_reason) = guess_thumb(&hand);
    let orientation = pose::wrist_orientation(&hand, thumb);
    let init_pos = [0.0, 0.0, pose::start_height(&hand, orientation.rot, CUBE_TOP_M)];
    let mesh_colliders = loaded.mesh_fits.len();

    // the sections; palm_offset is filled in from the planned grasp below
    let by_name = tips.iter().filter(|t| t.by_name).count();
    let chains = tips.len();
    let mut tip_comment = vec![format!("{chains} fingertips, one per finger chain (a leaf of the URDF's movable-joint tree):")];
    if by_name > 0 {
        tip_comment.push(format!("{by_name} found by name: every link whose name contains \"tip\", the most distal per finger (the loader's default, written out)"));
    }
    for t in tips.iter().filter(|t| !t.by_name) {
        let FingertipSpec::Link(l) = &t.spec else {
            tip_comment.push(format!("'{}': no link named *tip* on that finger and no collision geometry: the finger's last link's origin", t.tip.name));
            continue;
        };
        tip_comment.push(format!("'{}': no link named *tip* on that finger: the far end of the collision geometry of its last link, '{}'", t.tip.name, l.link));
    }
    let mut hand_s = Section::new("hand");
    hand_s.push(&["relative to this file's folder (every path in a config is); written by `dextrain new hand`".to_string()], "urdf", string(rel));
    let tip_values: Vec<toml::Value> = tips.iter().map(|t| tip_value(&t.spec)).collect();
    hand_s.push(&tip_comment, "fingertips", toml::Value::Array(tip_values));
    if approx != MeshApprox::Error {
        let kind = if approx == MeshApprox::Box { "box" } else { "capsule" };
        hand_s.push(
            &[format!(
                "{mesh_colliders} of the {} collision shapes are meshes: each fitted by the smallest {kind}{} around it (`dextrain check` prints every fit)",
                loaded.colliders.len(),
                if approx == MeshApprox::Capsule { " (or sphere)" } else { "" }
            )],
            "mesh_approx",
            string(kind),
        );
    }
    for (key, over) in [("effort", &limits.effort), ("velocity", &limits.velocity)] {
        if let Some(o) = over {
            let note = limits.notes.iter().find(|n| n.contains(&format!("URDF {key} limit"))).cloned().unwrap_or_default();
            let value = match o {
                JointLimitOverride::All(v) => num(*v, 4),
                JointLimitOverride::PerJoint(m) => toml::Value::Table(m.iter().map(|(k, v)| (k.clone(), num(*v, 4))).collect()),
            };
            hand_s.push(&[note], key, value);
        }
    }
    let mut wrist = Section::new("wrist");
    wrist.push(&[orientation.reason.clone()], "init_rpy", vec3(orientation.rpy, 7));
    wrist.push(
        &[format!(
            "over the cube's nominal place, the open hand's lowest point {:.0} cm above the cube's top",
            pose::START_CLEARANCE_M * 100.0
        )],
        "init_pos",
        vec3(init_pos, 2),
    );
    let mut starter = Starter {
        title: title(urdf, out, &loaded.name),
        hand: hand_s,
        wrist,
        object: template::cube_object(),
        task_hand: Section::new("task.hand"),
        wrist_pos_max_z: (init_pos[2] + 0.1).max(0.35),
    };
    let thumb_name = hand.fingertips[thumb].name.clone();
    starter.task_hand.push(&[format!("the thumb's fingertip: {thumb_reason}")], "thumb", string(&thumb_name));
    starter.task_hand.push(&[], "contact_force", num(0.05, 4));
    starter.task_hand.push(&[], "palm_offset", vec3([0.0, 0.0, -0.04], 3));

    say(&tips, &thumb_name, &thumb_reason, &orientation, init_pos, approx, mesh_colliders);

    // the grasp: planned by traj synth for this config, replayed under its physics
    let text = template::render(&starter);
    let cfg = Config::from_toml_str(&text, out)?;
    let traj = synth(&cfg, &SynthArgs::defaults(out.to_path_buf(), PathBuf::from("unused.mcap")))?;
    let mut verify = cfg.clone();
    verify.sim.num_envs = 1;
    verify.sim.backend = BackendChoice::Cpu;
    verify.object.xy_noise = [0.0, 0.0];
    verify.object.yaw_noise = 0.0;
    verify.randomization = Default::default();
    let model = SimModel::from_config(&verify)?;
    let report = crate::replay::replay_with_model(&verify, &model, &traj, false, None)?;
    // the grasp pose: the wrist of the last keyframe before the object moves
    let rest = traj.frames.first().and_then(|f| f.object).map(|p| p.pos);
    let grasp = traj
        .frames
        .iter()
        .rev()
        .find(|f| f.object.map(|p| p.pos).zip(rest).is_some_and(|(p, r)| (p - r).length() < 1e-6))
        .ok_or_else(|| anyhow!("{}: the planned reference has no keyframe with the object at rest", urdf.display()))?;
    // where the object's centre sits in the wrist frame when held: p = T_wrist⁻¹ c
    let held = grasp.wrist.inverse().transform_point(object_centre(&model));
    let palm_offset = held.to_array().map(|x| (x * 1e3).round() / 1e3);
    let (lift_m, penetration_mm) = (report.object_lift_m, report.peak_penetration_mm);
    if let Some(e) = starter.task_hand.entries.iter_mut().find(|e| e.key == "palm_offset") {
        e.value = vec3(palm_offset, 3);
        e.comment = vec![format!(
            "the point the reaching reward brings to the cube: where the cube's centre sits in the wrist frame in the grasp `dextrain traj synth` plans for this file (replayed, it lifts the cube {lift_m:.3} m, peak penetration {penetration_mm:.2} mm; a point guessed from the URDF can keep the fingers off the cube)"
        )];
    }
    crate::console::status(&format!(
        "  task.hand.palm_offset = {} — the cube's centre in the wrist frame in the planned grasp, which lifts the cube {lift_m:.3} m in simulation (peak penetration {penetration_mm:.2} mm)",
        vec3(palm_offset, 3)
    ));
    Ok(Plan { approx, tips, thumb: thumb_name, orientation, init_pos, palm_offset, lift_m, penetration_mm, starter, mesh_colliders })
}

/// A fingertip entry as a TOML value: a frame name, or `{ link, offset, name }`.
fn tip_value(spec: &FingertipSpec) -> toml::Value {
    match spec {
        FingertipSpec::Frame(f) => string(f),
        FingertipSpec::Link(l) => {
            let mut t = toml::Table::new();
            t.insert("link".into(), string(&l.link));
            t.insert("offset".into(), vec3(l.offset, 5));
            if let Some(n) = &l.name {
                t.insert("name".into(), string(n));
            }
            toml::Value::Table(t)
        }
    }
}

/// The comment lines at the top of the file.
fn title(urdf: &Path, out: &Path, robot: &str) -> Vec<String> {
    let file = urdf.file_name().map(|f| f.to_string_lossy().into_owned()).unwrap_or_default();
    let me = out.file_name().map(|f| f.to_string_lossy().into_owned()).unwrap_or_default();
    vec![
        format!(
            "Grasp and lift a 5 cm cube with the hand of {file} (URDF robot '{robot}'): PPO sized for a 2-core CPU. Written by `dextrain new hand {}`: everything but [hand], [wrist] and [task.hand] is configs/lift_cube_cpu.toml; the hand's keys are guesses from the URDF, each with its reason above it. `dextrain traj synth` on this file plans the grasp that task.hand.palm_offset comes from.",
            urdf.display()
        ),
        String::new(),
        format!("  dextrain check {me}"),
        format!("  dextrain traj synth {me} --out grasp.mcap"),
        format!("  dextrain train {me}"),
    ]
}

/// Prints the guesses of one plan and why (stderr).
fn say(tips: &[TipGuess], thumb: &str, thumb_reason: &str, o: &WristOrientation, init_pos: [f32; 3], approx: MeshApprox, mesh_colliders: usize) {
    let names: Vec<String> = tips.iter().map(|t| format!("{}{}", t.tip.name, if t.by_name { "" } else { " (last link)" })).collect();
    crate::console::status(&format!(
        "  hand.fingertips = {} — one per finger chain: the link named *tip* on it (the loader's default), else the chain's last link's far end",
        names.join(", ")
    ));
    crate::console::status(&format!("  task.hand.thumb = {thumb} — {thumb_reason}"));
    crate::console::status(&format!("  wrist.init_rpy = {} — {}", vec3(o.rpy, 7), o.reason));
    crate::console::status(&format!(
        "  wrist.init_pos = {} — over the cube, the open hand's lowest point {:.0} cm above its top",
        vec3(init_pos, 2),
        pose::START_CLEARANCE_M * 100.0
    ));
    let mesh = match approx {
        MeshApprox::Error => "no mesh collisions: hand.mesh_approx left at its default".to_string(),
        MeshApprox::Box => format!("hand.mesh_approx = \"box\" — {mesh_colliders} mesh collisions, each fitted by the smallest box around it"),
        MeshApprox::Capsule => format!("hand.mesh_approx = \"capsule\" — {mesh_colliders} mesh collisions, each fitted by the smallest capsule (or sphere) around it"),
    };
    crate::console::status(&format!("  {mesh}"));
    crate::console::status("  planning the grasp (traj synth's antipodal planner, replayed under the config's physics):");
}
