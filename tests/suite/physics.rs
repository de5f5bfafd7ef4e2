//! Physics behaviour on the CPU backend (the GPU backend is held to the same numbers by tests/parity.rs).


use crate::common::*;
use dextrain::env::EnvBatch;
use dextrain::geom::ObjectShape;

fn obj_pos(b: &mut dyn EnvBatch, i: usize) -> [f32; 3] {
    let s = b.states().unwrap();
    [s[i].obj_pos[0], s[i].obj_pos[1], s[i].obj_pos[2]]
}

fn dist(a: [f32; 3], b: [f32; 3]) -> f32 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

#[test]
fn object_at_rest_drifts_less_than_1mm_in_10s() {
    for shape in [
        ObjectShape::Box { half_extents: [0.025, 0.025, 0.025] },
        ObjectShape::Sphere { radius: 0.03 },
        ObjectShape::Cylinder { radius: 0.03, half_length: 0.05 },
        ObjectShape::Capsule { radius: 0.02, half_length: 0.04 },
    ] {
        let mut c = base_config(1);
        c.object.shape = Some(shape);
        let mut b = cpu_batch(&c);
        let p0 = obj_pos(&mut b, 0);
        let t = b.model().default_targets();
        run(&mut b, t, 300); // 10 s at 30 Hz
        let p1 = obj_pos(&mut b, 0);
        assert!(dist(p0, p1) < 1e-3, "{shape:?}: drifted {:.3} mm", dist(p0, p1) * 1e3);
    }
}

#[test]
fn free_fall_matches_the_analytic_time_within_1_percent() {
    let mut c = base_config(1);
    c.object.shape = Some(ObjectShape::Sphere { radius: 0.03 });
    c.sim.decimation = 1;
    let mut b = cpu_batch(&c);
    let mut s = b.states().unwrap();
    let drop = 1.0f32;
    s[0].obj_pos[0] = 0.5; // clear of the hand
    s[0].obj_pos[2] = 0.03 + drop;
    b.set_states(&s).unwrap();
    let t = b.model().default_targets();
    let dt = c.sim.dt;
    let mut prev = (0.0f32, drop);
    let mut t_hit = None;
    for k in 1..200 {
        run(&mut b, t, 1);
        let z = obj_pos(&mut b, 0)[2] - 0.03;
        if z <= 0.0 {
            // linear interpolation of the crossing between the last two steps
            let tk = k as f32 * dt;
            t_hit = Some(prev.0 + (tk - prev.0) * prev.1 / (prev.1 - z));
            break;
        }
        prev = (k as f32 * dt, z);
    }
    let t_hit = t_hit.expect("the sphere never reached the table");
    let analytic = (2.0 * drop / 9.81f32).sqrt();
    let rel = (t_hit - analytic).abs() / analytic;
    assert!(rel < 0.01, "fall time {t_hit:.4} s vs analytic {analytic:.4} s ({:.2} %)", rel * 100.0);
}

#[test]
fn sliding_box_decelerates_at_mu_g() {
    let mut c = base_config(1);
    c.object.friction = 0.5;
    c.table.friction = 0.5; // μ = mean = 0.5
    c.sim.decimation = 1;
    let mut b = cpu_batch(&c);
    let t = b.model().default_targets();
    run(&mut b, t, 30); // settle
    let mut s = b.states().unwrap();
    s[0].obj_vel = [1.5, 0.0, 0.0, 0.0];
    b.set_states(&s).unwrap();
    let mut samples = Vec::new();
    for k in 0..120 {
        run(&mut b, t, 1);
        let v = b.states().unwrap()[0].obj_vel[0];
        samples.push((k as f32 * c.sim.dt, v));
    }
    // least-squares slope over the sliding phase, away from the start and the stop
    let pts: Vec<(f32, f32)> = samples.into_iter().filter(|&(t, v)| t > 0.03 && v > 0.3).collect();
    assert!(pts.len() > 10, "too few sliding samples: {}", pts.len());
    let n = pts.len() as f32;
    let (st, sv) = pts.iter().fold((0.0, 0.0), |a, p| (a.0 + p.0, a.1 + p.1));
    let (mt, mv) = (st / n, sv / n);
    let slope = pts.iter().map(|p| (p.0 - mt) * (p.1 - mv)).sum::<f32>() / pts.iter().map(|p| (p.0 - mt).powi(2)).sum::<f32>();
    let expected = -0.5 * 9.81;
    assert!((slope - expected).abs() / expected.abs() < 0.05, "deceleration {slope:.3} m/s² vs μg {expected:.3}");
}

/// E = ½ m v² + ½ ωᵀ I ω + m g z of the object.
fn object_energy(s: &dextrain::env::EnvState, p: &dextrain::env::EnvParams) -> f64 {
    let m = p.obj_inertia[3] as f64;
    let v: f64 = s.obj_vel[..3].iter().map(|x| (*x as f64).powi(2)).sum();
    let q = glam::Quat::from_array(s.obj_rot);
    let w = q.inverse() * glam::Vec3::new(s.obj_angvel[0], s.obj_angvel[1], s.obj_angvel[2]);
    let rot: f64 = (0..3).map(|i| p.obj_inertia[i] as f64 * (w[i] as f64).powi(2)).sum();
    0.5 * m * v + 0.5 * rot + m * 9.81 * s.obj_pos[2] as f64
}

#[test]
fn passive_object_never_gains_energy() {
    for (shape, e) in [
        (ObjectShape::Capsule { radius: 0.02, half_length: 0.05 }, 0.6f32),
        (ObjectShape::Box { half_extents: [0.03, 0.02, 0.05] }, 0.3),
        (ObjectShape::Cylinder { radius: 0.03, half_length: 0.02 }, 0.0),
    ] {
        let mut c = base_config(1);
        c.object.shape = Some(shape);
        c.object.restitution = e;
        c.sim.decimation = 1;
        let mut b = cpu_batch(&c);
        let mut s = b.states().unwrap();
        s[0].obj_pos[2] = 0.3;
        s[0].obj_vel = [0.4, -0.2, 0.0, 0.0];
        s[0].obj_angvel = [3.0, 7.0, -2.0, 0.0];
        b.set_states(&s).unwrap();
        let p = b.params().unwrap()[0];
        let t = b.model().default_targets();
        let mut last = object_energy(&s[0], &p);
        let e0 = last;
        for k in 0..600 {
            run(&mut b, t, 1);
            let st = b.stats().unwrap()[0];
            if st.contacts == 0 {
                // out of contact (no spring energy stored): mechanical energy can only have gone down
                let e_now = object_energy(&b.states().unwrap()[0], &p);
                assert!(e_now <= last + 1e-6 * e0.abs(), "{shape:?}: energy rose {last:.6} -> {e_now:.6} J at step {k}");
                last = e_now;
            }
        }
        assert!(last < e0, "{shape:?}: energy should have been dissipated");
    }
}

#[test]
fn exploding_env_is_reset_alone_and_counted() {
    let c = base_config(4);
    let mut a = cpu_batch(&c);
    let mut b = cpu_batch(&c);
    let t = a.model().default_targets();
    run(&mut a, t, 3);
    run(&mut b, t, 3);
    let mut s = b.states().unwrap();
    s[2].obj_vel = [f32::NAN, 0.0, 0.0, 0.0];
    s[1].obj_pos[2] = 1e6; // far outside max_distance
    b.set_states(&s).unwrap();
    run(&mut a, t, 1);
    run(&mut b, t, 1);
    let (sa, sb) = (a.states().unwrap(), b.states().unwrap());
    let stats = b.stats().unwrap();
    for i in [0usize, 3] {
        assert_eq!(sa[i], sb[i], "env {i} must not be touched");
        assert_eq!(stats[i].bad_reset, 0);
    }
    for i in [1usize, 2] {
        assert_eq!(stats[i].bad_reset, 1, "env {i} should have been reset");
        assert_eq!(sb[i].bad_resets, 1);
        assert_eq!(sb[i].episode, 1);
        assert_eq!(sb[i].step, 0);
        assert!(sb[i].obj_pos.iter().all(|x| x.is_finite()) && sb[i].obj_pos[2] < 0.1);
    }
}

fn grasp_lift_replay() -> dextrain::replay::ReplayReport {
    use dextrain::synth::{SynthArgs, synth};
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/configs/grasp_lift.toml");
    let mut cfg = dextrain::config::Config::load(std::path::Path::new(path)).unwrap();
    cfg.sim.backend = "cpu".parse().unwrap();
    let traj = synth(&cfg, &SynthArgs::posture(path.into(), "unused.mcap".into())).unwrap();
    dextrain::replay::replay(&cfg, &traj, false, None).unwrap()
}

#[test]
fn scripted_grasp_lifts_the_object_without_creep_or_deep_penetration() {
    let r = grasp_lift_replay();
    // the script lifts the wrist 15 cm; the object must come along
    assert!(r.object_lift_m > 0.10, "object lifted only {:.3} m", r.object_lift_m);
    assert_eq!(r.bad_resets, 0);
    // hold phase of the default script: 3.6 s → 4.6 s; skip the first 0.2 s of it
    let held: Vec<_> = r.trace.iter().filter(|(t, _, _)| *t >= 3.8 && *t <= 4.6).collect();
    assert!(held.len() > 10);
    let rel = |(_, obj, wrist): &&(f64, dextrain::geom::Pose, dextrain::geom::Pose)| wrist.inverse().transform_point(obj.pos);
    let (first, last) = (held.first().unwrap(), held.last().unwrap());
    let creep = (rel(last) - rel(first)).length() as f64 / (last.0 - first.0);
    assert!(creep < 1e-3, "the held object creeps {:.3} mm/s in the hand", creep * 1e3);
    assert!(first.1.pos.z > 0.1, "the object should be held high, at z = {}", first.1.pos.z);
    // penalty contacts at the default stiffness
    assert!(r.peak_penetration_mm < 2.0, "peak hand–object penetration {:.2} mm", r.peak_penetration_mm);
    assert!(r.mean_fingertip_force_n > 0.5, "fingertips should squeeze: {:.2} N", r.mean_fingertip_force_n);
}

#[test]
fn kinematic_replay_measures_the_penetration_that_physics_prevents() {
    use dextrain::synth::{SynthArgs, synth};
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/configs/grasp_lift.toml");
    let mut cfg = dextrain::config::Config::load(std::path::Path::new(path)).unwrap();
    cfg.sim.backend = "cpu".parse().unwrap();
    let traj = synth(&cfg, &SynthArgs::posture(path.into(), "unused.mcap".into())).unwrap();
    let k = dextrain::replay::replay(&cfg, &traj, true, None).unwrap();
    // the scripted grasp closes past the object: set kinematically, the fingers sink into it
    assert!(k.peak_penetration_mm > 10.0, "kinematic penetration {:.2} mm", k.peak_penetration_mm);
    assert!(k.frac_frames_penetration_over_1mm > 0.3);
    // and the object follows its reference exactly
    assert!(k.terminal_object_pos_err_m.unwrap() < 1e-6);
    let d = grasp_lift_replay();
    assert!(d.peak_penetration_mm < k.peak_penetration_mm / 5.0);
}

/// One hand contact against a fixed wall, stepped as the simulator steps it: a point of mobility w
/// (1/kg) pushed into the wall by a servo force, its contact solved by `hand_contact_force`. Returns
/// the depths of every substep.
fn press_into_wall(w: f32, k: f32, servo_n: f32, v0: f32, steps: usize) -> Vec<f32> {
    use dextrain::env::physics::{contact_at, hand_contact_force};
    use glam::Vec3;
    let h = 1.0 / 480.0;
    // the wall's normal points at the hand (+z); the point starts 2 mm above it, moving down at v0
    let (mut z, mut v) = (0.002f32, -v0);
    let mut depths = Vec::new();
    for _ in 0..steps {
        let c = contact_at(-z, Vec3::Z, Vec3::ZERO);
        // the servo alone changes the velocity by −h·w·F_servo this substep
        let dv = Vec3::new(0.0, 0.0, -h * w * servo_n);
        let f = if c.depth > -dextrain::env::physics::CONTACT_MARGIN {
            hand_contact_force(&c, Vec3::new(0.0, 0.0, v), dv, Vec3::ZERO, k, k, 0.0, 1.0, h, w, w).0.z
        } else {
            0.0
        };
        v += dv.z + h * w * f;
        z += h * v;
        depths.push(-z);
    }
    depths
}

#[test]
fn hand_contacts_are_stiff_and_stable_on_any_finger() {
    for w in [1.0f32, 100.0, 1e4] {
        for k in [1e4f32, 1e5, 1e6] {
            // pressing with 10 N: it settles at F/k, whatever the finger's mobility
            let d = press_into_wall(w, k, 10.0, 0.0, 4000);
            let last = *d.last().unwrap();
            assert!((last - 10.0 / k).abs() < 1e-3 * 10.0 / k + 1e-7, "w {w}, k {k}: rests {:.4} mm deep, not {:.4}", last * 1e3, 10.0 / k * 1e3);
            // without ringing: the last 1000 substeps stay within 1 % of it
            let ring = d[3000..].iter().map(|x| (x - last).abs()).fold(0.0, f32::max);
            assert!(ring < 0.01 * last, "w {w}, k {k}: rings by {:.2e} m", ring);
            assert!(d.iter().all(|x| x.is_finite() && *x < 0.01), "w {w}, k {k}: diverged");
        }
    }
    // a fast finger (1 m/s, 2 mm away) stops at the surface: speculative contacts push before it
    // gets there, so it never sinks a substep's travel (2 mm) in
    let d = press_into_wall(100.0, 1e5, 1.0, 1.0, 400);
    let peak = d.iter().copied().fold(f32::MIN, f32::max);
    assert!(peak < 0.2e-3, "a 1 m/s finger sank {:.3} mm in", peak * 1e3);
}

/// The contact-fidelity scenes (`dextrain bench --contacts`, issue 36) against statics: a pushed
/// box slips at μ m g (5 %), a box on a tilting plane at atan μ (1°), a tall box tips at
/// m g (w/2) / h (10 %), a cube at rest drifts < 0.1 mm in 10 s, and two fingertips squeezing a
/// cube at 1, 5 and 10 N push that force (5 %), sink ≤ 1 mm and hold it 5 cm up (slip < 1 mm).
#[test]
fn contact_fidelity_scenes_agree_with_statics() {
    let r = dextrain::bench_contacts::run_contact_bench(&dextrain::config::BackendChoice::Cpu).unwrap();
    let num = |v: &serde_json::Value| v.as_f64().unwrap_or_else(|| panic!("not a number: {v} in {r}"));
    assert!(num(&r["slide"]["error"]).abs() <= 0.05, "slide: {}", r["slide"]);
    assert!(num(&r["tilt"]["error_deg"]).abs() <= 1.0, "tilt: {}", r["tilt"]);
    assert!(num(&r["tip"]["error"]).abs() <= 0.10, "tip: {}", r["tip"]);
    assert!(num(&r["rest"]["drift_mm"]) < 0.1, "rest: {}", r["rest"]);
    let squeeze = r["squeeze"].as_array().unwrap();
    assert_eq!(squeeze.len(), 3);
    for s in squeeze {
        let f = num(&s["force_n"]);
        assert!((num(&s["tip_force_n"]) / f - 1.0).abs() <= 0.05, "squeeze at {f} N: {s}");
        assert!(num(&s["peak_penetration_mm"]) <= 1.0, "squeeze at {f} N: {s}");
        assert!(num(&s["slip_mm"]) < 1.0 && num(&s["lifted_mm"]) > 45.0, "squeeze at {f} N: {s}");
    }
}

/// An external force at a point off the centre of mass (`EnvParams::ext_force`, `ext_point`)
/// moves and turns a free object as Newton and Euler say: a = F/m, and for a force along x at a
/// point z above the centre of a cube, dω_y/dt = z F / I_y.
#[test]
fn an_external_force_off_the_centre_accelerates_and_turns_a_free_object() {
    let mut c = base_config(1);
    c.wrist.init_pos = [0.0, 0.0, 0.6];
    c.sim.max_distance = 100.0;
    let mut b = cpu_batch(&c);
    let mut s = b.states().unwrap();
    s[0].obj_pos = [0.0, 0.0, 2.0, 0.0];
    b.set_states(&s).unwrap();
    let mut p = b.params().unwrap();
    let (m, inertia) = (p[0].obj_inertia[3], p[0].obj_inertia[1]); // mass, the moment about y
    let (f, z) = (0.02f32, 0.02f32);
    p[0].ext_force = [f, 0.0, 0.0, 0.0];
    p[0].ext_point = [0.0, 0.0, z, 0.0];
    b.set_params(&p).unwrap();
    let t = b.model().default_targets();
    let steps = 3; // 0.1 s: the cube turns by ~0.02 rad
    run(&mut b, t, steps);
    let st = b.states().unwrap();
    let secs = steps as f32 / 30.0;
    let (vx, wy) = (st[0].obj_vel[0], st[0].obj_angvel[1]);
    assert!((vx / (f / m * secs) - 1.0).abs() < 0.02, "v_x {vx} against F t / m = {}", f / m * secs);
    assert!((wy / (z * f / inertia * secs) - 1.0).abs() < 0.05, "ω_y {wy} against z F t / I = {}", z * f / inertia * secs);
    assert!(st[0].obj_vel[2] < -0.9, "the cube falls meanwhile: v_z {}", st[0].obj_vel[2]);
}

/// A box turned into the palm box (a hand box collider against a piece) is pushed where it enters:
/// the contact's depth is that of its deepest edge, not of its point nearest the palm's centre
/// (which lies on its top face, shallower), and the contact point sits on that edge.
#[test]
fn a_box_turned_into_the_palm_is_pushed_at_its_deepest_edge() {
    use dextrain::record::ContactKind;
    let c = base_config(1);
    let mut b = cpu_batch(&c);
    let depth = 0.004;
    let edge = box_turned_into_palm(&mut b, depth, |_| 0.02)[0];
    let model = b.model().clone();
    let palm = |b: &mut dextrain::env::cpu::CpuEnvBatch| {
        let (s, p, springs) = (b.states().unwrap(), b.params().unwrap(), b.springs().unwrap());
        let contacts = dextrain::env::contact_records(&model, &s[0], &springs, &p[0], &model.default_targets());
        contacts.into_iter().find(|k| k.kind == ContactKind::HandObject && k.index == 0)
    };
    let k = palm(&mut b).expect("the palm touches the box");
    assert!((k.depth - depth).abs() < 1e-4, "palm contact {:.3} mm deep, the edge is {:.3} mm in", k.depth * 1e3, depth * 1e3);
    assert!(k.pos.distance(edge) < 3e-3, "contact at {:?}, {:.1} mm from the deep edge {edge:?}", k.pos, k.pos.distance(edge) * 1e3);
}

/// The palm's (collider 0's) contact with a cube tilted `tilt` degrees under it, its near edge
/// `depth` in (negative: apart), `lateral` m off the palm's centre (`box_tilted_against_palm`):
/// the contact, the near edge's middle (world), the model, the env's state and parameters.
fn palm_contact_with_tilted_cube(depth: f32, tilt: f32, lateral: f32) -> (dextrain::env::physics::Contact, glam::Vec3, dextrain::env::SimModel, dextrain::env::EnvState, dextrain::env::EnvParams) {
    use dextrain::env::physics::{CONTACT_MARGIN, Scratch, collide_hand_object, hand_kinematics};
    let c = base_config(1);
    let mut b = cpu_batch(&c);
    let edge = box_tilted_against_palm(&mut b, depth, tilt, |_| lateral)[0];
    let model = b.model().clone();
    let (st, p) = (b.states().unwrap()[0], b.params().unwrap()[0]);
    let mut s = Scratch::default();
    hand_kinematics(&st, &model.view(), &mut s);
    let k = collide_hand_object(&st, &p, &model.view(), &s, 0, CONTACT_MARGIN);
    (k, edge, model, st, p)
}

/// A hand box meets a piece that is not a box wherever they overlap: the narrow phase's early
/// rejection of a box piece that the separating axes find apart by more than the margin leaves
/// other pieces (which have no separation) alone. A sphere 1 mm into the palm's face, anywhere
/// under it, is met 1 mm deep.
#[test]
fn a_palm_pressed_into_a_sphere_meets_it_as_deep_as_it_is() {
    use dextrain::env::physics::{CONTACT_MARGIN, Scratch, collide_hand_object, hand_kinematics};
    use glam::Vec3;
    let radius = 0.03;
    let mut c = base_config(1);
    c.object.shape = Some(ObjectShape::Sphere { radius });
    let mut b = cpu_batch(&c);
    let model = b.model().clone();
    let h = Vec3::from_slice(&model.colliders[0].size[..3]);
    for lateral in [0.0f32, 0.01] {
        let mut states = b.states().unwrap();
        // the object lies on the palm's −z side (toward_palm is the palm's +z)
        let palm = palm_pose(&model, &states[0]);
        let centre = palm.transform_point(Vec3::new(lateral, 0.0, -(h.z + radius - 0.001)));
        states[0].obj_pos = [centre.x, centre.y, centre.z, 0.0];
        b.set_states(&states).unwrap();
        let (st, p) = (b.states().unwrap()[0], b.params().unwrap()[0]);
        let mut s = Scratch::default();
        hand_kinematics(&st, &model.view(), &mut s);
        let k = collide_hand_object(&st, &p, &model.view(), &s, 0, CONTACT_MARGIN);
        assert!((k.depth - 0.001).abs() < 1e-4, "a sphere 1 mm into the palm ({lateral} m off its centre) met {:.3} mm deep", k.depth * 1e3);
    }
}

/// A hand box overlapping a box piece is a manifold of point springs (`box_box_contact`): pressed
/// flat 1 mm onto a cube's face it stands for the face's four corners (spring count 4, its point
/// at the face's centre, the corners' spread about it), tilted 3° for its deep edge's two corners
/// (count 2, at the edge's middle); wherever the cube lies under the palm.
#[test]
fn a_palm_pressed_on_a_cube_s_face_stands_for_the_corners_below_it() {
    for lateral in [0.0f32, 0.02] {
        for (tilt, springs) in [(0.0f32, 4.0f32), (3.0, 2.0)] {
            let (k, edge, model, st, p) = palm_contact_with_tilted_cube(0.001, tilt, lateral);
            let at = format!("tilt {tilt}°, {lateral} m off the palm's centre");
            assert!((k.depth - 0.001).abs() < 2e-6, "{at}: depth {:.4} mm", k.depth * 1e3);
            assert!((k.spring_count - springs).abs() < 1e-3, "{at}: {} springs", k.spring_count);
            let up = toward_palm(&model, &st);
            assert!(k.normal.dot(up) > 0.998, "{at}: normal {:?}, toward the palm {up:?}", k.normal);
            // half the cube's side
            let half = p.obj_scale * model.pieces[0].size[0];
            let (centre, spread) = if tilt == 0.0 {
                (glam::Vec3::from_slice(&st.obj_pos[..3]) + up * half, 2.0 * half * half)
            } else {
                (edge, half * half)
            };
            assert!(k.point.distance(centre) < 1e-4, "{at}: point {:?}, {:.3} mm from {centre:?}", k.point, k.point.distance(centre) * 1e3);
            let trace = k.spread_diag.x + k.spread_diag.y + k.spread_diag.z;
            assert!((trace / spread - 1.0).abs() < 2e-3, "{at}: spread {trace:e} m², the corners' {spread:e}");
        }
    }
}

/// A cube pressed into the palm across the palm's rim (`cube_across_the_palm_rim`: the boxes
/// overlap least along an edge–edge axis a few degrees off the palm's normal) is met on the palm's
/// face, as deep as the boxes overlap: the support points alone (the cube's corners inside the
/// palm) met it 0.1 mm deep where it was 1.7 mm in, until a turn of a fraction of a degree made
/// the face's axis the least and the contact jumped to 1.4 mm (`EDGE_AXIS_SHARE`).
#[test]
fn a_cube_pressed_into_the_palm_across_its_rim_is_met_as_deep_as_it_is() {
    use dextrain::env::physics::{CONTACT_MARGIN, Scratch, collide_hand_object, hand_kinematics};
    for sink in [-0.0005f32, 0.0, 0.0005] {
        let c = base_config(1);
        let mut b = cpu_batch(&c);
        let overlap = cube_across_the_palm_rim(&mut b, |_| sink, |_| 0.0)[0];
        let model = b.model().clone();
        let (st, p) = (b.states().unwrap()[0], b.params().unwrap()[0]);
        let mut s = Scratch::default();
        hand_kinematics(&st, &model.view(), &mut s);
        let k = collide_hand_object(&st, &p, &model.view(), &s, 0, CONTACT_MARGIN);
        let at = format!("{:.1} mm further in", sink * 1e3);
        // the deepest point under the palm's face is at its rim, a little shallower than the corner past it
        assert!(k.depth > 0.85 * overlap && k.depth <= overlap + 1e-5, "{at}: contact {:.3} mm deep, the boxes overlap {:.3} mm", k.depth * 1e3, overlap * 1e3);
        assert!(k.normal.dot(toward_palm(&model, &st)) > 0.999, "{at}: normal {:?} is not the palm's", k.normal);
        assert!(k.spring_count > 1.0, "{at}: {} springs: the face's clipped points", k.spring_count);
    }
}

/// A capsule lying along a box's face is two point springs, one at each end of its segment's part
/// over the face (`capsule_face_contact`): flat 1 mm in, two springs at the part's middle; tilted
/// so that one end is 0.5 mm in, 1.5 springs two thirds of the way to the deep end; partly past
/// the face's edge, the part over the face; one end out, a single spring (no manifold).
#[test]
fn a_capsule_along_a_box_face_is_a_spring_at_each_end_over_the_face() {
    use dextrain::env::physics::capsule_face_contact;
    use glam::Vec3;
    let (h, rc) = (Vec3::splat(0.025), 0.008);
    // the segment's height over the +z face at which an end is `d` deep
    let z = |d: f32| 0.025 + rc - d;
    let cases = [
        // (a, b, depth, springs, point)
        (Vec3::new(-0.01, 0.0, z(0.001)), Vec3::new(0.02, 0.0, z(0.001)), 0.001, 2.0, Vec3::new(0.005, 0.0, 0.025)),
        (Vec3::new(-0.01, 0.0, z(0.001)), Vec3::new(0.02, 0.0, z(0.0005)), 0.001, 1.5, Vec3::new(0.0, 0.0, 0.025)),
        (Vec3::new(0.01, 0.01, z(0.001)), Vec3::new(0.04, 0.01, z(0.001)), 0.001, 2.0, Vec3::new(0.0175, 0.01, 0.025)),
        (Vec3::new(-0.01, 0.0, z(0.001)), Vec3::new(0.02, 0.0, z(-0.001)), 0.001, 1.0, Vec3::new(-0.01, 0.0, 0.025)),
    ];
    for (i, (a, b, depth, springs, point)) in cases.into_iter().enumerate() {
        let k = capsule_face_contact(a, b, rc, h, Vec3::Z);
        assert!((k.depth - depth).abs() < 1e-6, "case {i}: depth {:.4} mm", k.depth * 1e3);
        assert!((k.spring_count - springs).abs() < 1e-3, "case {i}: {} springs", k.spring_count);
        assert!(k.point.distance(point) < 1e-5, "case {i}: point {:?}, expected {point:?}", k.point);
    }
    // a normal off the box's axes (an edge or corner contact): no manifold
    assert_eq!(capsule_face_contact(cases[0].0, cases[0].1, rc, h, Vec3::new(0.0, 0.6, 0.8)).depth, -1.0);
}

/// A cube pressed flat 1 mm into the palm (the hand held, the cube free) is pushed out straight,
/// wherever it lies under the palm: its four corners push alike, so it does not turn, and the
/// palm's manifold resists the turn the push would start.
#[test]
fn a_cube_pressed_flat_into_the_palm_is_pushed_out_without_turning() {
    for lateral in [0.0f32, 0.01, 0.02] {
        let c = base_config(1);
        let mut b = cpu_batch(&c);
        box_tilted_against_palm(&mut b, 0.001, 0.0, |_| lateral);
        let s = b.states().unwrap();
        let mut t = b.model().default_targets();
        t.wrist_pos = s[0].wrist_pos;
        t.wrist_rot = s[0].wrist_rot;
        t.q = s[0].q;
        b.step(&[t]).unwrap();
        let after = b.states().unwrap()[0];
        let w = glam::Vec3::from_slice(&after.obj_angvel[..3]).length();
        let v = glam::Vec3::from_slice(&after.obj_vel[..3]).dot(-toward_palm(&b.model().clone(), &after));
        assert!(v > 0.05, "{lateral} m off the centre: pushed out at {v:.3} m/s");
        assert!(w < 0.05 * v / 0.025, "{lateral} m off the centre: turning at {w:.3} rad/s while pushed out at {v:.3} m/s");
    }
}

/// A capsule's segment against a box piece: `segment_box_closest` finds the segment's point nearest
/// the box exactly — its distance to the box is the least over a dense sampling of the segment, and
/// never more than four rounds of alternating projections find (which zig-zag when the segment lies
/// nearly along a face).
#[test]
fn the_segment_point_nearest_a_box_is_exact() {
    use dextrain::env::physics::{segment_box_closest, segment_closest};
    use glam::Vec3;
    let h = Vec3::new(0.025, 0.025, 0.025);
    let dist = |p: Vec3| (p - p.clamp(-h, h)).length();
    let mut rng = dextrain::rng::Rng::new(7, 3);
    let mut worse_projections = 0;
    for case in 0..2000 {
        let mut u = |lo: f32, hi: f32| lo + (hi - lo) * rng.uniform() as f32;
        let (a, b) = if case % 2 == 0 {
            (Vec3::new(u(-0.06, 0.06), u(-0.06, 0.06), u(-0.06, 0.06)), Vec3::new(u(-0.06, 0.06), u(-0.06, 0.06), u(-0.06, 0.06)))
        } else {
            // nearly along the top face, 1–3 mm above it
            let z = 0.025 + u(0.001, 0.003);
            let a = Vec3::new(u(-0.05, 0.0), u(-0.02, 0.02), z);
            (a, Vec3::new(u(0.0, 0.05), u(-0.02, 0.02), z + u(-0.002, 0.002)))
        };
        let exact = dist(segment_box_closest(a, b, h));
        let sampled = (0..=20000).map(|i| dist(a + (b - a) * (i as f32 / 20000.0))).fold(f32::MAX, f32::min);
        assert!(exact <= sampled + 2e-6, "case {case}: {exact} m, sampling finds {sampled} m ({a:?} to {b:?})");
        let mut x = segment_closest(a, b, Vec3::ZERO);
        for _ in 0..4 {
            x = segment_closest(a, b, x.clamp(-h, h));
        }
        assert!(exact <= dist(x) + 1e-7, "case {case}: the projections' {} m is nearer than {exact} m", dist(x));
        if dist(x) > exact + 1e-4 {
            worse_projections += 1;
        }
    }
    assert!(worse_projections > 0, "the projections should miss by > 0.1 mm on some nearly parallel segment");
}

/// A hand box's gap to a box piece is the boxes' largest separation over their 15 separating axes
/// where the alternating projections stop short of the nearest points (`box_box_separation`): a
/// cube tilted under the palm, its near edge 0.5 or 2 mm from the palm's face, reports that gap,
/// however flat it lies (the projections zig-zag slowly between faces that meet at a shallow angle
/// and end far from the nearest points).
#[test]
fn the_palm_s_gap_to_a_cube_tilted_under_it_is_exact() {
    for tilt in [0.5f32, 2.0, 10.0, 30.0] {
        for gap in [0.0005f32, 0.002] {
            let k = palm_contact_with_tilted_cube(-gap, tilt, 0.0).0;
            assert!((k.depth + gap).abs() < 2e-5, "tilt {tilt}°, gap {:.2} mm: reported {:.4} mm", gap * 1e3, -k.depth * 1e3);
        }
    }
}

/// A hand box (the palm) apart from the object reports the gap as a speculative contact, as a
/// capsule does: a cube flying at the palm at 2 m/s from 2.5 mm away is slowed before it gets
/// there, not a substep's travel (4.2 mm: 1.7 mm inside) later.
#[test]
fn a_cube_thrown_at_the_palm_is_slowed_before_it_gets_there() {
    let pen = palm_penetration_of_a_thrown_cube(0.0025, 2.0);
    assert!(pen < 1.0e-3, "the cube sank {:.3} mm into the palm", pen * 1e3);
}

/// The deepest hand–object overlap (m) over one env step of a cube turned into the palm
/// (`box_turned_into_palm`) `gap` m from it and thrown at it at `speed` m/s, the hand held.
fn palm_penetration_of_a_thrown_cube(gap: f32, speed: f32) -> f32 {
    let c = base_config(1);
    let mut b = cpu_batch(&c);
    box_turned_into_palm(&mut b, -gap, |_| 0.02);
    let mut s = b.states().unwrap();
    let up = toward_palm(&b.model().clone(), &s[0]) * speed;
    s[0].obj_vel = [up.x, up.y, up.z, 0.0];
    b.set_states(&s).unwrap();
    let mut t = b.model().default_targets();
    t.wrist_pos = s[0].wrist_pos;
    t.wrist_rot = s[0].wrist_rot;
    b.step(&[t]).unwrap();
    b.stats().unwrap()[0].max_pen_ho
}

/// A cube struck flat-ish into the palm at 1 m/s (`cube_struck_at_the_palm`, tilted 1°, 16 envs
/// over the palm, the hand held): the palm's push at the corner that strikes first turns the cube
/// so that the rest of its top face comes up within the substep. Met where the solved motion
/// brings it (`arriving_contacts`), no env sinks over 1 mm into the palm over 4 env steps; with
/// the contacts found only before the solve, 9 of the 16 did (1.56 mm, BENCHMARKS.md).
#[test]
fn a_cube_struck_into_the_palm_is_met_where_the_strike_turns_it() {
    let c = base_config(16);
    let mut b = cpu_batch(&c);
    b.reset_all().unwrap();
    cube_struck_at_the_palm(&mut b, 1.0, 1.0);
    let s = b.states().unwrap();
    let mut t = b.model().default_targets();
    (t.wrist_pos, t.wrist_rot, t.q) = (s[0].wrist_pos, s[0].wrist_rot, s[0].q);
    let mut peak = [0.0f32; 16];
    for _ in 0..4 {
        b.step(&[t; 16]).unwrap();
        for (p, st) in peak.iter_mut().zip(b.stats().unwrap()) {
            *p = p.max(st.max_pen_ho);
        }
    }
    let deepest = peak.iter().fold(0.0f32, |a, b| a.max(*b));
    assert!(deepest <= 1.0e-3, "a struck cube sank {:.3} mm into the palm (peaks {:?})", deepest * 1e3, peak);
    // the strike presses every env's cube in: the scene tests the contacts, not a miss
    assert!(peak.iter().all(|p| *p > 0.1e-3), "every cube should press into the palm: {peak:?}");
}

/// A palm's rim pressed across a cube's top edge (`cube_under_the_palm_s_edge`: 21° off its top
/// face, the boxes overlapping least along that edge pair) is met on the edges, as deep as the
/// boxes overlap along them (`box_edge_contact`): the support points and projections met it
/// less than 1 mm deep where it was 4.6 mm in, and a learned lift pressed the palm 12 mm in.
#[test]
fn a_palm_s_rim_across_a_cube_s_edge_is_met_as_deep_as_it_is() {
    use dextrain::env::physics::{CONTACT_MARGIN, Scratch, collide_hand_object, hand_kinematics};
    for sink in [-0.002f32, 0.0, 0.001] {
        let c = base_config(1);
        let mut b = cpu_batch(&c);
        cube_under_the_palm_s_edge(&mut b, |_| sink, |_| 0.0);
        let model = b.model().clone();
        let (st, p) = (b.states().unwrap()[0], b.params().unwrap()[0]);
        let mut s = Scratch::default();
        hand_kinematics(&st, &model.view(), &mut s);
        let k = collide_hand_object(&st, &p, &model.view(), &s, 0, CONTACT_MARGIN);
        // the overlap along each edge pair's axis (the palm's edge i × the cube's edge j), in the
        // cube's frame: the least is the boxes' penetration along edges
        let palm = palm_pose(&model, &st);
        let cube = dextrain::geom::Pose::from_arrays(st.obj_pos, st.obj_rot);
        let to_cube = cube.rot.inverse();
        let c_o = to_cube * (palm.pos - cube.pos);
        let a = [to_cube * palm.rot * glam::Vec3::X, to_cube * palm.rot * glam::Vec3::Y, to_cube * palm.rot * glam::Vec3::Z];
        let (ha, hb) = (glam::Vec3::from_slice(&model.colliders[0].size[..3]), glam::Vec3::splat(p.obj_scale * model.pieces[0].size[0]));
        let mut least = (f32::MAX, glam::Vec3::Z);
        for i in 0..3 {
            for j in 0..3 {
                let l = a[i].cross(glam::Vec3::AXES[j]);
                if l.length() < 1e-3 {
                    continue;
                }
                let l = l.normalize();
                let reach = (0..3).map(|m| ha[m] * a[m].dot(l).abs()).sum::<f32>() + hb.dot(l.abs());
                let overlap = reach - c_o.dot(l).abs();
                if overlap < least.0 {
                    least = (overlap, if c_o.dot(l) >= 0.0 { l } else { -l });
                }
            }
        }
        let at = format!("{:.1} mm further in", sink * 1e3);
        assert!((k.depth - least.0).abs() < 1e-5, "{at}: contact {:.3} mm deep, the edges overlap {:.3} mm", k.depth * 1e3, least.0 * 1e3);
        let n = cube.rot * least.1;
        assert!(k.normal.dot(n) > 0.9999, "{at}: normal {:?}, the edge pair's axis {n:?}", k.normal);
        // on one of the cube's edges: two of its coordinates at the half side
        let x = (to_cube * (k.point - cube.pos)).abs();
        let on = (0..3).filter(|&m| (x[m] - hb[m]).abs() < 1e-5).count();
        assert!(on >= 2, "{at}: point {x:?} (cube frame) is not on an edge");
    }
}

/// The penetration the step's statistics record is the overlap at the substep's poses, not the
/// depth of a swept contact (`swept_contact`: where the pair would be by the end of the substep
/// if nothing pushed, taken back along the motion), which the env never reaches: a cube pressed
/// nearly flat (1° off) 0.8 mm into the palm, closing on it at 0.4 m/s and turning at 8–22 rad/s
/// one way or the other about the palm's y axis, up to 16 mm off its centre (as a learned lift's
/// deepest press: 0.82 mm in, closing at 0.38 m/s, turning at 8.8 rad/s, solved on a swept
/// contact 1.14 mm deep), is solved on contacts deeper than the boxes overlap, and the statistics
/// say how deep they do.
#[test]
fn the_statistics_record_the_overlap_not_the_swept_contact_s_depth() {
    use dextrain::env::physics::{CONTACT_MARGIN, Scratch, collide_hand_object, contacts_and_forces, hand_kinematics};
    use dextrain::record::ContactKind;
    let mut swept = 0;
    let c = base_config(8);
    let mut b = cpu_batch(&c);
    box_tilted_against_palm(&mut b, 0.0008, 1.0, |i| 0.004 * i as f32 - 0.012);
    let model = b.model().clone();
    let m = model.view();
    let all_springs = b.springs().unwrap();
    let (states, params) = (b.states().unwrap(), b.params().unwrap());
    for (i, (mut st, p)) in states.into_iter().zip(params).enumerate() {
        let sign = if i % 2 == 0 { 1.0 } else { -1.0 };
        let w = palm_pose(&model, &st).rot * glam::Vec3::Y * (sign * (8.0 + 2.0 * i as f32));
        st.obj_angvel = [w.x, w.y, w.z, 0.0];
        let v = toward_palm(&model, &st) * 0.4;
        st.obj_vel = [v.x, v.y, v.z, 0.0];
        let n = m.g.n_springs as usize;
        let mut springs = all_springs[i * n..(i + 1) * n].to_vec();
        let mut s = Scratch::default();
        hand_kinematics(&st, &m, &mut s);
        let overlap = (0..m.g.n_colliders as usize).map(|ci| collide_hand_object(&st, &p, &m, &s, ci, CONTACT_MARGIN).depth).fold(0.0f32, f32::max);
        let mut solved = 0.0f32;
        contacts_and_forces(&st, &mut springs, &p, &m, &mut s, m.g.dt / m.g.substeps as f32, &mut |kind, _, k, _| {
            if kind == ContactKind::HandObject {
                solved = solved.max(k.depth);
            }
        });
        let at = format!("env {i}");
        assert_eq!(s.max_pen_ho, overlap, "{at}: statistics {:.4} mm, overlap {:.4} mm (solved on {:.4} mm)", s.max_pen_ho * 1e3, overlap * 1e3, solved * 1e3);
        if solved > overlap + 1e-4 {
            swept += 1;
        }
    }
    assert!(swept >= 4, "{swept} of 8 envs solved on a swept contact deeper than the overlap");
}

/// The speculative margin grows with the pair's speed (`speculative_margin`): a cube thrown at the
/// palm at 3 m/s from 5 mm away (a 2.08 ms substep closes 6.2 mm, past the fixed 3 mm margin) is
/// met before it gets there, not first seen 1.2 mm inside.
#[test]
fn a_cube_thrown_fast_from_past_the_fixed_margin_is_met_before_it_gets_there() {
    let pen = palm_penetration_of_a_thrown_cube(0.005, 3.0);
    assert!(pen < 0.3e-3, "the cube sank {:.3} mm into the palm", pen * 1e3);
}

/// The second pass of the hand's contacts: a pair apart and not pushing, solved against the
/// object's velocity at the end of the substep as the other forces make it. A cube at rest 1 mm
/// from the palm, pushed at it by 200 N (an external force standing in for a finger's throw),
/// meets the palm within the substep: the palm pushes back already, though at the substep's start
/// the cube neither touched nor moved.
#[test]
fn a_pair_apart_pushes_once_the_object_is_predicted_to_close_the_gap() {
    use dextrain::record::ContactKind;
    let c = base_config(1);
    let mut b = cpu_batch(&c);
    box_turned_into_palm(&mut b, -0.001, |_| 0.02);
    let model = b.model().clone();
    let s = b.states().unwrap();
    let up = toward_palm(&model, &s[0]);
    let springs = b.springs().unwrap();
    let records = |p: &dextrain::env::EnvParams| {
        dextrain::env::contact_records(&model, &s[0], &springs, p, &model.default_targets()).into_iter().find(|k| k.kind == ContactKind::HandObject && k.index == 0)
    };
    let mut p = b.params().unwrap();
    assert!(records(&p[0]).is_none(), "at rest and apart, the palm does not push");
    p[0].ext_force = [200.0 * up.x, 200.0 * up.y, 200.0 * up.z, 0.0];
    let k = records(&p[0]).expect("the cube thrown at the palm meets it within the substep");
    let fn_ = k.force.dot(k.normal);
    assert!(k.depth < 0.0 && fn_ > 10.0 && fn_ < 2000.0, "depth {:.2} mm, push {fn_:.1} N", k.depth * 1e3);
}
