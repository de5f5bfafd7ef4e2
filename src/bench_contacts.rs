//! `dextrain bench --contacts`: the contact-fidelity benchmark (issue 36), as one JSON object.
//!
//! Five scenes with answers known from statics, each measured the way
//! `benches/contact_fidelity_mujoco.py` measures it in MuJoCo 4.0 (that script builds its scenes
//! from the `scenes` object of this JSON, so both run the same sizes, masses, friction, forces,
//! ramps and thresholds; `benches/contact_fidelity.sh` runs both and compares):
//!
//! - **slide**: a 10 × 10 × 5 cm, 1 kg box (μ = 0.5) pushed at its centre of mass by a force that
//!   ramps up at 0.5 N/s; the force when the box has moved `onset_mm` is its slip force (μ m g).
//! - **tilt**: the same box on a plane tilted at 0.5°/s (gravity turned about y: a tilted table);
//!   the angle when it has moved `onset_mm` is its slip angle (atan μ).
//! - **tip**: a 5 × 5 × 20 cm, 0.5 kg box (μ = 1) pushed horizontally at 15 cm above the table by
//!   a ramped force; the force when it has turned `onset_deg` is its tipping force (m g (w/2) / h).
//! - **rest**: a 5 cm, 0.1 kg cube left on the table for 10 s: how far it drifts.
//! - **squeeze**: the two-finger gripper (`configs/hands/gripper2.urdf`) closes on a 5 cm, 0.1 kg
//!   cube with fingers whose effort limits stall them at 1, 5 and 10 N, lifts it 5 cm and holds it:
//!   the fingertips' penetration and force, and how far the cube slips in the grip.
//!
//! Forces and tilts act through `EnvParams::ext_force` / `ext_point` / `added_gravity`, set before
//! every physics step (the scenes run with decimation 1: one env step is one physics step of
//! 1/120 s, as MuJoCo's step is). The hand of the object scenes (dexhand16) is parked 0.6 m above
//! the table, where nothing touches it. Paths: the hands are read from `configs/hands/` in the
//! working directory, as `dextrain bench`'s built-in scene reads its hand.

use anyhow::{Context, Result, ensure};
use glam::{Quat, Vec3};
use serde_json::{Value, json};

use crate::config::hand::{FingertipSpec, JointLimitOverride, LinkTip};
use crate::config::{BackendChoice, Config};
use crate::env::{EnvBatch, SimModel, make_env_batch};
use crate::geom::ObjectShape;

/// Gravity of the simulator (m/s²; `Globals::gravity`).
const G: f64 = 9.81;

/// The scenes' constants (lengths m, masses kg, forces N, times s, angles degrees). The MuJoCo
/// script builds its scenes from this object as printed.
pub fn scenes() -> Value {
    json!({
        "slide": {"half": [0.05, 0.05, 0.025], "mass": 1.0, "mu": 0.5, "settle_s": 0.5,
                  "force_start": 0.5 * 0.5 * 1.0 * G, "force_rate": 0.5, "duration_s": 12.0, "onset_mm": 0.5},
        "tilt": {"half": [0.05, 0.05, 0.025], "mass": 1.0, "mu": 0.5, "settle_s": 0.5,
                 "angle_start": 20.0, "angle_rate": 0.5, "duration_s": 30.0, "onset_mm": 0.5},
        "tip": {"half": [0.025, 0.025, 0.1], "mass": 0.5, "mu": 1.0, "settle_s": 0.5, "push_height": 0.15,
                "force_start": 0.4, "force_rate": 0.1, "duration_s": 10.0, "onset_deg": 1.0},
        "rest": {"half": [0.025, 0.025, 0.025], "mass": 0.1, "mu": 1.0, "settle_s": 0.5, "duration_s": 10.0},
        "squeeze": {"half": [0.025, 0.025, 0.025], "mass": 0.1, "mu": 1.0, "forces": [1.0, 5.0, 10.0],
                    "finger_length": 0.1, "tip_radius": 0.01, "open_rad": 0.2, "kp": 50.0, "kd": 1.0,
                    "armature": 0.002, "wrist_kp": 2000.0, "wrist_kd": 100.0,
                    "close_ramp_s": 0.5, "close_s": 1.0, "lift_m": 0.05, "lift_s": 1.0, "hold_s": 1.0},
    })
}

/// A number of a scene's constants.
fn num(s: &Value, key: &str) -> f64 {
    s[key].as_f64().unwrap_or_else(|| panic!("bench_contacts::scenes(): {key} is not a number"))
}

/// A 3-vector of a scene's constants.
fn vec3_of(s: &Value, key: &str) -> [f32; 3] {
    let a: Vec<f32> = s[key].as_array().map(|a| a.iter().filter_map(|x| x.as_f64()).map(|x| x as f32).collect()).unwrap_or_default();
    [a[0], a[1], a[2]]
}

/// One env of a scene, stepped one physics step at a time.
struct Scene {
    env: Box<dyn EnvBatch>,
    model: SimModel,
    /// The env's parameters as its reset drew them, kept here so that a push does not read them
    /// back every step.
    params: Vec<crate::env::EnvParams>,
    dt: f64,
}

impl Scene {
    fn new(cfg: &Config) -> Result<Scene> {
        cfg.validate()?;
        let model = SimModel::from_config(cfg)?;
        let mut env = make_env_batch(cfg, model.clone())?;
        env.reset_all()?;
        let params = env.params()?;
        Ok(Scene { env, params, dt: cfg.sim.dt as f64, model })
    }

    /// Sets the external force `force` (N, world) at `point` (m, the object's frame) and the
    /// extra downward acceleration `added_gravity` (m/s²) for the next steps.
    fn push(&mut self, force: Vec3, point: Vec3, added_gravity: f32) -> Result<()> {
        let p = &mut self.params[0];
        p.ext_force = [force.x, force.y, force.z, 0.0];
        p.ext_point = [point.x, point.y, point.z, 0.0];
        p.added_gravity = added_gravity;
        self.env.set_params(&self.params)
    }

    /// One physics step toward `targets` (the model's default targets when None); the object's
    /// position and orientation after it.
    fn step(&mut self, targets: Option<&crate::env::Targets>) -> Result<(Vec3, Quat)> {
        let t = targets.copied().unwrap_or_else(|| self.model.default_targets());
        self.env.step(&[t])?;
        let st = self.env.states()?;
        Ok((Vec3::from_slice(&st[0].obj_pos[..3]), Quat::from_array(st[0].obj_rot)))
    }

    /// Steps with no force until `secs` of simulated time; the object's position then.
    fn settle(&mut self, secs: f64) -> Result<Vec3> {
        let mut pos = Vec3::from_slice(&self.env.states()?[0].obj_pos[..3]);
        for _ in 0..(secs / self.dt).round() as usize {
            pos = self.step(None)?.0;
        }
        Ok(pos)
    }
}

/// A config of one env on `backend`, one physics step per env step, the object a box of half
/// extents `half`, `mass` and friction `mu` (the table's too) resting at the origin, and dexhand16
/// parked out of reach.
fn box_config(backend: &BackendChoice, half: [f32; 3], mass: f32, mu: f32) -> Config {
    let mut c = Config::default();
    c.base_dir = "configs".into();
    c.source = "<contact-fidelity scene>".into();
    c.sim.backend = backend.clone();
    c.sim.num_envs = 1;
    c.sim.decimation = 1;
    c.object.shape = Some(ObjectShape::Box { half_extents: half });
    c.object.mass = Some(mass);
    c.object.friction = mu;
    c.table.friction = mu;
    c.table.hand_collision = false;
    c.wrist.init_pos = [0.0, 0.0, 0.6];
    c
}

/// The slide scene: the push force (N) at slip onset.
fn slide(backend: &BackendChoice, s: &Value) -> Result<Value> {
    let mut sc = Scene::new(&box_config(backend, vec3_of(s, "half"), num(s, "mass") as f32, num(s, "mu") as f32))?;
    let p0 = sc.settle(num(s, "settle_s"))?;
    let mut onset = None;
    for k in 0..(num(s, "duration_s") / sc.dt).round() as usize {
        let f = num(s, "force_start") + num(s, "force_rate") * k as f64 * sc.dt; // the ramp, at this step's start
        sc.push(Vec3::new(f as f32, 0.0, 0.0), Vec3::ZERO, 0.0)?;
        let (p, _) = sc.step(None)?;
        if (p - p0).truncate().length() as f64 > num(s, "onset_mm") * 1e-3 {
            onset = Some(f);
            break;
        }
    }
    let expected = num(s, "mu") * num(s, "mass") * G;
    Ok(json!({"slip_force_n": onset, "expected_n": expected, "error": onset.map(|f| f / expected - 1.0)}))
}

/// The tilt scene: the plane's angle (degrees) at slip onset. A plane tilted by θ about y is
/// gravity turned by θ: m g sin θ along +x at the centre of mass, m g cos θ down.
fn tilt(backend: &BackendChoice, s: &Value) -> Result<Value> {
    let mass = num(s, "mass");
    let mut sc = Scene::new(&box_config(backend, vec3_of(s, "half"), mass as f32, num(s, "mu") as f32))?;
    let tilted = |sc: &mut Scene, deg: f64| {
        let a = deg.to_radians();
        // x: m g sin θ; z: g + added = g cos θ
        sc.push(Vec3::new((mass * G * a.sin()) as f32, 0.0, 0.0), Vec3::ZERO, (G * (a.cos() - 1.0)) as f32)
    };
    tilted(&mut sc, num(s, "angle_start"))?;
    let p0 = sc.settle(num(s, "settle_s"))?;
    let mut onset = None;
    for k in 0..(num(s, "duration_s") / sc.dt).round() as usize {
        let deg = num(s, "angle_start") + num(s, "angle_rate") * k as f64 * sc.dt;
        tilted(&mut sc, deg)?;
        let (p, _) = sc.step(None)?;
        if (p - p0).truncate().length() as f64 > num(s, "onset_mm") * 1e-3 {
            onset = Some(deg);
            break;
        }
    }
    let expected = num(s, "mu").atan().to_degrees();
    Ok(json!({"slip_angle_deg": onset, "expected_deg": expected, "error_deg": onset.map(|d| d - expected)}))
}

/// The tip scene: the push (N, horizontal, `push_height` above the table) at which the box has
/// turned `onset_deg`.
fn tip(backend: &BackendChoice, s: &Value) -> Result<Value> {
    let half = vec3_of(s, "half");
    let mut sc = Scene::new(&box_config(backend, half, num(s, "mass") as f32, num(s, "mu") as f32))?;
    sc.settle(num(s, "settle_s"))?;
    // the point of the push in the box's frame (its origin is its centre of mass)
    let point = Vec3::new(0.0, 0.0, num(s, "push_height") as f32 - half[2]);
    let mut onset = None;
    for k in 0..(num(s, "duration_s") / sc.dt).round() as usize {
        let f = num(s, "force_start") + num(s, "force_rate") * k as f64 * sc.dt;
        sc.push(Vec3::new(f as f32, 0.0, 0.0), point, 0.0)?;
        let (_, rot) = sc.step(None)?;
        let up = rot * Vec3::Z;
        if (up.z.min(1.0) as f64).acos().to_degrees() > num(s, "onset_deg") {
            onset = Some(f);
            break;
        }
    }
    // about the front bottom edge: F h = m g (w/2)
    let expected = num(s, "mass") * G * half[0] as f64 / num(s, "push_height");
    Ok(json!({"tip_force_n": onset, "expected_n": expected, "error": onset.map(|f| f / expected - 1.0)}))
}

/// The rest scene: the largest distance (mm) the cube moves from where it settled, and how far
/// it sinks into the table at the end.
fn rest(backend: &BackendChoice, s: &Value) -> Result<Value> {
    let half = vec3_of(s, "half");
    let mut sc = Scene::new(&box_config(backend, half, num(s, "mass") as f32, num(s, "mu") as f32))?;
    let p0 = sc.settle(num(s, "settle_s"))?;
    let (mut drift, mut last) = (0.0f32, p0);
    for _ in 0..(num(s, "duration_s") / sc.dt).round() as usize {
        last = sc.step(None)?.0;
        drift = drift.max((last - p0).length());
    }
    Ok(json!({"drift_mm": 1e3 * drift as f64, "sink_mm": 1e3 * (half[2] - last.z) as f64}))
}

/// The squeeze scene at each force: peak and held penetration (mm), the fingertips' force (N) over
/// the last 0.5 s, the cube's slip in the grip while lifted (mm) and its final height (mm).
fn squeeze(backend: &BackendChoice, s: &Value) -> Result<Value> {
    let half = vec3_of(s, "half");
    let length = num(s, "finger_length") as f32;
    let mut out = Vec::new();
    for force in s["forces"].as_array().map(|a| a.iter().filter_map(|f| f.as_f64()).collect::<Vec<f64>>()).unwrap_or_default() {
        let mut c = box_config(backend, half, num(s, "mass") as f32, num(s, "mu") as f32);
        c.hand.urdf = "hands/gripper2.urdf".into();
        let tip = |link: &str, name: &str| FingertipSpec::Link(LinkTip { link: link.into(), offset: [0.0, 0.0, -length], name: Some(name.into()) });
        c.hand.fingertips = vec![tip("finger_l", "tip_l"), tip("finger_r", "tip_r")];
        c.hand.kp = num(s, "kp") as f32;
        c.hand.kd = num(s, "kd") as f32;
        c.hand.armature = num(s, "armature") as f32;
        c.hand.friction = num(s, "mu") as f32;
        // τ = F L: the stall torque of a vertical finger that pushes F at its tip
        c.hand.effort = Some(JointLimitOverride::All(force as f32 * length));
        let open = num(s, "open_rad") as f32;
        c.hand.init_joints = [("j_l".to_string(), -open), ("j_r".to_string(), -open)].into_iter().collect();
        c.wrist.init_pos = [0.0, 0.0, half[2] + length];
        c.wrist.kp_lin = num(s, "wrist_kp") as f32;
        c.wrist.kd_lin = num(s, "wrist_kd") as f32;
        c.task.hand.thumb = "tip_r".into();
        let mut sc = Scene::new(&c).with_context(|| format!("the squeeze scene at {force} N"))?;
        let names = &sc.model.spec.joint_names;
        let joints: Vec<usize> = ["j_l", "j_r"].iter().map(|j| names.iter().position(|n| n == j)).collect::<Option<_>>().context("gripper2.urdf: joints j_l and j_r")?;
        let (t_close, t_lift) = (num(s, "close_s"), num(s, "close_s") + num(s, "lift_s"));
        let t_end = t_lift + num(s, "hold_s");
        let (mut peak, mut pens, mut forces, mut rel0) = (0.0f32, Vec::new(), Vec::new(), None);
        let (mut cube, mut wrist) = (Vec3::ZERO, Vec3::ZERO);
        let steps = (t_end / sc.dt).round() as usize;
        for k in 0..steps {
            let t = k as f64 * sc.dt;
            let mut tg = sc.model.default_targets();
            // the fingers: from open (−open_rad) to closed (+open_rad) over close_ramp_s
            let q = open * (2.0 * (t / num(s, "close_ramp_s")).min(1.0) as f32 - 1.0);
            for &j in &joints {
                tg.q[j] = q;
            }
            tg.wrist_pos[2] += (num(s, "lift_m") * ((t - t_close) / num(s, "lift_s")).clamp(0.0, 1.0)) as f32;
            sc.step(Some(&tg))?;
            let (st, stats) = (sc.env.states()?, sc.env.stats()?);
            cube = Vec3::from_slice(&st[0].obj_pos[..3]);
            wrist = Vec3::from_slice(&st[0].wrist_pos[..3]);
            peak = peak.max(stats[0].max_pen_ho);
            let t_after = t + sc.dt;
            if t_after >= t_close && rel0.is_none() {
                rel0 = Some(cube.z - wrist.z);
            }
            if t_after >= t_end - 0.5 {
                pens.push(stats[0].max_pen_ho);
                forces.push(0.5 * (stats[0].tip_force[0] + stats[0].tip_force[1]));
            }
        }
        let mean = |v: &[f32]| v.iter().map(|&x| x as f64).sum::<f64>() / v.len().max(1) as f64;
        ensure!(!pens.is_empty(), "the squeeze scene held for less than 0.5 s");
        out.push(json!({
            "force_n": force,
            "peak_penetration_mm": 1e3 * peak as f64,
            "penetration_mm": 1e3 * mean(&pens),
            "tip_force_n": mean(&forces),
            "slip_mm": rel0.map(|r| 1e3 * (r - (cube.z - wrist.z)) as f64),
            "lifted_mm": 1e3 * (cube.z - half[2]) as f64,
        }));
    }
    Ok(Value::Array(out))
}

/// Runs the five scenes on `backend` (one env each) and returns the report.
pub fn run_contact_bench(backend: &BackendChoice) -> Result<Value> {
    let s = scenes();
    let probe = Scene::new(&box_config(backend, [0.025; 3], 0.1, 1.0))?;
    let (backend_name, substeps) = (probe.env.backend_name(), probe.model.spec.substeps);
    drop(probe);
    Ok(json!({
        "bench": "dextrain_contact_fidelity",
        "tool": "dextrain",
        "backend": backend_name,
        "dt": 1.0 / 120.0,
        "substeps": substeps,
        "scenes": s,
        "slide": slide(backend, &s["slide"])?,
        "tilt": tilt(backend, &s["tilt"])?,
        "tip": tip(backend, &s["tip"])?,
        "rest": rest(backend, &s["rest"])?,
        "squeeze": squeeze(backend, &s["squeeze"])?,
    }))
}
