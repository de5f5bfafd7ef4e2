//! CPU/GPU parity: the WGSL kernels and their CPU twins must compute the same thing; and wgpu's
//! errors (buffers beyond the device's limits, shaders that fail validation, errors outside any
//! error scope) come back as one-line errors naming the buffer or shader, never as panics.
//! Runs on any wgpu adapter, lavapipe included; without one it prints why (fails with REQUIRE_GPU=1).


use crate::common::*;
use dextrain::env::{EnvBatch, EnvState, Targets};

/// Every f32 of two Pod values, side by side.
fn floats<T: bytemuck::Pod>(a: &T) -> Vec<f32> {
    bytemuck::cast_slice::<u8, f32>(bytemuck::bytes_of(a)).to_vec()
}

/// The states and contact springs of every env of a batch.
struct Snap {
    states: Vec<EnvState>,
    springs: Vec<[f32; 4]>,
}

fn snap(b: &mut dyn EnvBatch) -> Snap {
    Snap { states: b.states().unwrap(), springs: b.springs().unwrap() }
}

/// Gives a batch a snapshot's states and springs.
fn restore(b: &mut dyn EnvBatch, s: &Snap) {
    b.set_states(&s.states).unwrap();
    b.set_springs(&s.springs).unwrap();
}

/// Largest relative difference over all state variables, |a − b| / max(|a|, |b|, scale), where the
/// scale of poses and velocities (m, m/s, rad/s, quaternion components) is `scale` and that of the
/// friction springs is 1e-3 m (μ·Fn/kt for a 10 N contact). Also returns the five worst entries, named, for the message.
fn max_rel_diff(a: &Snap, b: &Snap, scale: f32) -> (f32, String) {
    let mut all = Vec::new();
    let mut push = |d: f32, what: String, u: f32, v: f32| all.push((if d.is_finite() { d } else { f32::INFINITY }, what, u, v));
    for (i, (x, y)) in a.states.iter().zip(&b.states).enumerate() {
        // integer counters must match exactly
        assert_eq!((x.episode, x.step, x.bad_resets), (y.episode, y.step, y.bad_resets), "env {i} counters");
        for (k, (u, v)) in floats(x).iter().zip(floats(y)).enumerate() {
            push((u - v).abs() / u.abs().max(v.abs()).max(scale), format!("env {i} {}", field_name(k)), *u, v);
        }
    }
    assert_eq!(a.springs.len(), b.springs.len(), "contact springs per batch");
    let per_env = a.springs.len() / a.states.len().max(1);
    for (j, (x, y)) in a.springs.iter().zip(&b.springs).enumerate() {
        for c in 0..4 {
            let (u, v) = (x[c], y[c]);
            push((u - v).abs() / u.abs().max(v.abs()).max(1e-3), format!("env {} spring {}[{c}]", j / per_env.max(1), j % per_env.max(1)), u, v);
        }
    }
    all.sort_by(|x, y| y.0.total_cmp(&x.0));
    let worst: Vec<String> = all.iter().take(5).map(|x| format!("{}: cpu {} gpu {} ({:.1e})", x.1, x.2, x.3, x.0)).collect();
    (all.first().map(|x| x.0).unwrap_or(0.0), worst.join("; "))
}

fn field_name(k: usize) -> String {
    use dextrain::hand::MAX_JOINTS;
    let names = ["wrist_pos", "wrist_rot", "wrist_vel", "wrist_angvel", "obj_pos", "obj_rot", "obj_vel", "obj_angvel"];
    match k {
        0..32 => format!("{}[{}]", names[k / 4], k % 4),
        k if k < 32 + MAX_JOINTS => format!("q[{}]", k - 32),
        k if k < 32 + 2 * MAX_JOINTS => format!("qd[{}]", k - 32 - MAX_JOINTS),
        _ => "time".into(),
    }
}

/// Grasp targets of the bench scene: palm lowered onto the cube, fingers closed.
fn grasp_targets(b: &dextrain::env::cpu::CpuEnvBatch) -> Targets {
    dextrain::bench::grasp_targets(b.model())
}

#[test]
fn reset_draws_the_same_parameters_on_both_backends() {
    let Some(ctx) = gpu_context("reset_draws_the_same_parameters_on_both_backends") else { return };
    let slack = parity_slack(&ctx);
    let mut c = base_config(64);
    c.randomization = dextrain::config::Config::load(std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/configs/dexrefine_dr.toml")))
        .expect("shipped DR config")
        .randomization;
    c.object.xy_noise = [0.05, 0.05];
    c.object.yaw_noise = 0.5;
    let mut cpu = cpu_batch(&c);
    let mut gpu = gpu_batch(&c, ctx);
    let (pc, pg) = (cpu.params().unwrap(), gpu.params().unwrap());
    for (i, (a, b)) in pc.iter().zip(&pg).enumerate() {
        for (u, v) in floats(a).iter().zip(floats(b)) {
            assert!((u - v).abs() <= 1e-6 * u.abs().max(1.0), "env {i}: params differ: {a:?} vs {b:?}");
        }
    }
    // the draws really are random across envs
    assert!(pc.iter().any(|p| (p.obj_inertia[3] - pc[0].obj_inertia[3]).abs() > 1e-4));
    let (sc, sg) = (snap(&mut cpu), snap(&mut gpu));
    let (d, at) = max_rel_diff(&sc, &sg, 1e-3);
    assert!(d < 1e-5 * slack, "initial states differ: {d:e}: {at}");
    // a masked reset starts the next episode of those envs only
    let mask: Vec<bool> = (0..64).map(|i| i % 3 == 0).collect();
    cpu.reset(&mask).unwrap();
    gpu.reset(&mask).unwrap();
    let (sc, sg) = (snap(&mut cpu), snap(&mut gpu));
    for i in 0..64 {
        assert_eq!(sc.states[i].episode, if i % 3 == 0 { 1 } else { 0 });
    }
    let (d, at) = max_rel_diff(&sc, &sg, 1e-3);
    assert!(d < 1e-5 * slack, "states after a masked reset differ: {d:e}: {at}");
}

#[test]
fn one_contact_rich_physics_step_agrees() {
    let Some(ctx) = gpu_context("one_contact_rich_physics_step_agrees") else { return };
    let mut c = dextrain::bench::bench_config(16);
    c.base_dir = concat!(env!("CARGO_MANIFEST_DIR"), "/configs").into();
    contact_rich_step_agrees(c, ctx);
}

/// The bench grasp pressed onto the table (the hand colliding with it): every env's hand touches
/// the table and the cube in the same physics step, so the shader's contact pass walks colliders
/// near the object and colliders near the table in one list (a list that left out the table's
/// colliders differed by 2 in relative terms), and one physics step agrees on both backends.
#[test]
fn a_grasp_pressed_onto_the_table_steps_the_same_on_both_backends() {
    let Some(ctx) = gpu_context("a_grasp_pressed_onto_the_table_steps_the_same_on_both_backends") else { return };
    let mut c = dextrain::bench::bench_config(16);
    c.base_dir = concat!(env!("CARGO_MANIFEST_DIR"), "/configs").into();
    c.table.hand_collision = true;
    let mut cpu = cpu_batch(&c);
    let model = cpu.model().clone();
    let t = grasp_targets(&cpu);
    let mut tk = t;
    for k in 0..27 {
        tk = dextrain::bench::approach_targets(&model, &t, k as f32 / 30.0);
        run(&mut cpu, tk, 1);
    }
    // the hand lowered until its lowest point is 2 mm into the table, each env by a little more
    // (the envs differ; in the bench grasp the fingertips reach the table's plane), the cube no
    // more than 0.5 mm into the table, the wrist's target lowered with it
    let mut states = cpu.states().unwrap();
    for (e, st) in states.iter_mut().enumerate() {
        let links = model.hand.forward_kinematics(&st.q[..model.hand.joints.len()]);
        let wrist = dextrain::geom::Pose::from_arrays(st.wrist_pos, st.wrist_rot);
        // each collider's lowest point: a sphere's centre less r, a capsule's lower end less r, a
        // box's lowest corner
        let lowest = model
            .colliders
            .iter()
            .map(|cd| {
                let pose = wrist.mul(&links[cd.link as usize]);
                let rot = pose.rot * glam::Quat::from_array(cd.rot);
                let z = pose.transform_point(glam::Vec3::from_slice(&cd.pos[..3])).z;
                let reach = |k: usize, half: f32| (rot * glam::Vec3::AXES[k]).z.abs() * half;
                match cd.shape {
                    dextrain::geom::SHAPE_BOX => z - reach(0, cd.size[0]) - reach(1, cd.size[1]) - reach(2, cd.size[2]),
                    dextrain::geom::SHAPE_CAPSULE => z - reach(2, cd.size[1]) - cd.size[0],
                    _ => z - cd.size[0],
                }
            })
            .fold(f32::INFINITY, f32::min);
        let dz = lowest + 0.002 + 0.0002 * e as f32;
        st.wrist_pos[2] -= dz;
        st.obj_pos[2] = (st.obj_pos[2] - dz).max(0.0245);
    }
    cpu.set_states(&states).unwrap();
    tk.wrist_pos[2] = states[0].wrist_pos[2];
    let start = snap(&mut cpu);
    // in that physics step every env's hand pushes on the table (a penetration over 1 mm: the cube
    // rests on the table and the hand–object pairs are shallower; by the step's end the table has
    // pushed the hand out, its springs cleared) and on the cube
    let mut c1 = c.clone();
    c1.sim.decimation = 1;
    let mut probe = cpu_batch(&c1);
    restore(&mut probe, &start);
    run(&mut probe, tk, 1);
    let stats = probe.stats().unwrap();
    let both = stats.iter().filter(|s| s.max_pen > 1e-3 && s.max_pen_ho < 1e-3 && s.contacts_ho > 0).count();
    assert_eq!(both, 16, "envs whose hand touches both the table and the cube: {:?}", stats.iter().map(|s| (s.max_pen, s.max_pen_ho, s.contacts_ho)).collect::<Vec<_>>());
    one_physics_step_agrees(c, &start, tk, ctx);
}

/// LEAP (dex-urdf) has 71 collision shapes, more than the 32 the per-env state once held: its
/// contact springs live in the runtime-sized springs buffer, and the backends agree on it too.
#[test]
fn one_contact_rich_physics_step_agrees_for_a_hand_with_71_colliders() {
    let test = "one_contact_rich_physics_step_agrees_for_a_hand_with_71_colliders";
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/hands/leap/config.toml");
    if !path.is_file() {
        eprintln!("{test}: {} does not exist; not run", path.display());
        return;
    }
    let Some(ctx) = gpu_context(test) else { return };
    let mut c = dextrain::config::Config::load(&path).unwrap();
    c.sim.num_envs = 16;
    c.sim.backend = "cpu".parse().unwrap();
    let n_colliders = dextrain::env::SimModel::from_config(&c).unwrap().colliders.len();
    assert!(n_colliders > 32, "LEAP has {n_colliders} colliders");
    contact_rich_step_agrees(c, ctx);
}

/// A hand with mimic joints (the tri3 test hand: each finger's distal joint follows its middle
/// one): the contacts' stiffness and damping, capped to the hand's mobility through the coupled
/// coordinates, agree on both backends.
#[test]
fn one_contact_rich_physics_step_agrees_for_a_hand_with_mimic_joints() {
    let test = "one_contact_rich_physics_step_agrees_for_a_hand_with_mimic_joints";
    let Some(ctx) = gpu_context(test) else { return };
    let mut c = dextrain::config::Config::load(&std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/grasp_lift.toml")).unwrap();
    c.hand.urdf = "hands/tri3_mimic.urdf".into();
    c.hand.fingertips.clear();
    c.sim.num_envs = 16;
    c.sim.backend = "cpu".parse().unwrap();
    let model = dextrain::env::SimModel::from_config(&c).unwrap();
    assert!(model.hand.joints.iter().any(|j| j.mimic.is_some()), "tri3_mimic has mimic joints");
    contact_rich_step_agrees(c, ctx);
}

/// Drives the CPU batch of `c` into the bench grasp of its hand (0.9 s of approach), gives both
/// backends that state (contact springs included), steps one physics step and compares.
fn contact_rich_step_agrees(c: dextrain::config::Config, ctx: dextrain::gpu::context::GpuContext) {
    let mut cpu = cpu_batch(&c);
    let t = grasp_targets(&cpu);
    // drive the CPU into the bench scene's grasp (0.9 s of approach), then give both backends that state
    let model = cpu.model().clone();
    let mut tk = t;
    for k in 0..27 {
        tk = dextrain::bench::approach_targets(&model, &t, k as f32 / 30.0);
        run(&mut cpu, tk, 1);
    }
    // a hand whose scripted grasp misses the cube (the posture grasp is dexhand16's): the cube is
    // put at the centroid of its fingertips, where the closed fingers press on it
    let touching = |b: &mut dextrain::env::cpu::CpuEnvBatch| b.stats().unwrap().iter().all(|s| s.contacts_ho > 0);
    if !touching(&mut cpu) {
        let hand = &model.hand;
        let mut states = cpu.states().unwrap();
        for st in states.iter_mut() {
            let links = hand.forward_kinematics(&st.q[..hand.joints.len()]);
            let wrist = dextrain::geom::Pose::from_arrays(st.wrist_pos, st.wrist_rot);
            let tips = hand.fingertips.iter().map(|t| wrist.mul(&links[t.link]).transform_point(t.pos));
            let centroid = tips.sum::<glam::Vec3>() / hand.fingertips.len() as f32;
            st.obj_pos = [centroid.x, centroid.y, centroid.z, 0.0];
            st.obj_vel = [0.0; 4];
            st.obj_angvel = [0.0; 4];
        }
        cpu.set_states(&states).unwrap();
        run(&mut cpu, tk, 1);
    }
    let t = tk;
    let start = snap(&mut cpu);
    // every env's hand pushed on the object in the last step (a contact that touches or pushes, a
    // speculative one included); the springs say which of them still touch at its end
    assert!(touching(&mut cpu), "every env's hand should touch the object");
    let per_env = start.springs.len() / c.sim.num_envs;
    let n_col = model.colliders.len();
    let holding = start.springs.chunks(per_env).filter(|e| e[..n_col].iter().any(|s| s[3] > 0.0)).count();
    eprintln!("{holding} of {} envs end the approach with a hand–object pair touching", c.sim.num_envs);
    one_physics_step_agrees(c, &start, t, ctx);
}

/// One physics step (dt, all its substeps) of config `c` from state `start` under targets `t` on
/// both backends: the states, springs, contact counts and deepest hand–object penetrations agree.
fn one_physics_step_agrees(c: dextrain::config::Config, start: &Snap, t: Targets, ctx: dextrain::gpu::context::GpuContext) {
    let mut c = c;
    c.sim.decimation = 1;
    let mut cpu = cpu_batch(&c);
    restore(&mut cpu, start);
    let mut gpu = gpu_batch(&c, ctx);
    restore(&mut gpu, start);
    run(&mut cpu, t, 1);
    run(&mut gpu, t, 1);
    // In contact, a 1-ulp difference of a 0.1 m coordinate (sin/cos, fused multiply-adds on the GPU)
    // changes a penalty force by k·1e-8 m = 1e-4 N, so joint velocities agree to ~1e-5 rad/s absolute:
    // velocities are compared relative to max(|v|, 1 rad/s), positions to max(|x|, 1 m). The bound is
    // 2e-5, or 4× what the CPU itself does when every input coordinate moves by one ulp (the f32
    // conditioning of this very state), whichever is larger, and never above 5e-4 (LEAP's 71
    // colliders: a 1-ulp nudge alone moves its contact-rich step by ~1.3e-4). A twin that
    // computes something else is off by orders of magnitude more.
    let (d, at) = max_rel_diff(&snap(&mut cpu), &snap(&mut gpu), 1.0);
    let mut nudged = Snap { states: start.states.clone(), springs: start.springs.clone() };
    for s in nudged.states.iter_mut() {
        for x in s.wrist_pos[..3].iter_mut().chain(s.obj_pos[..3].iter_mut()).chain(s.q.iter_mut()) {
            *x = f32::from_bits(x.to_bits() + 1);
        }
    }
    let mut cpu2 = cpu_batch(&c);
    restore(&mut cpu2, &nudged);
    run(&mut cpu2, t, 1);
    let (cond, _) = max_rel_diff(&snap(&mut cpu), &snap(&mut cpu2), 1.0);
    let bound = (4.0 * cond).clamp(2e-5, 5e-4);
    eprintln!("one physics step: cpu vs gpu {d:e} (relative), cpu vs cpu with 1-ulp nudged inputs {cond:e}");
    assert!(d < bound, "one physics step differs by {d:e} (relative; bound {bound:e}, 1-ulp conditioning {cond:e}): {at}");
    let (a, b) = (cpu.stats().unwrap(), gpu.stats().unwrap());
    for (x, y) in a.iter().zip(&b) {
        assert_eq!(x.contacts, y.contacts);
        assert!((x.max_pen_ho - y.max_pen_ho).abs() < 1e-6);
    }
}

/// A box turned into the palm box, an edge 3 mm in (the palm's contact at the box's deepest
/// support points, `box_deepest_support`), the hand held still: one physics step agrees.
#[test]
fn a_box_turned_into_the_palm_steps_the_same_on_both_backends() {
    let Some(ctx) = gpu_context("a_box_turned_into_the_palm_steps_the_same_on_both_backends") else { return };
    let c = base_config(8);
    let mut cpu = cpu_batch(&c);
    // each env's box a little further off the palm's centre
    box_turned_into_palm(&mut cpu, 0.003, |i| 0.004 * i as f32 - 0.012);
    held_hand_step_agrees(c, &mut cpu, ctx);
}

/// `one_physics_step_agrees` from `cpu`'s states, the hand's targets where env 0's hand is (held).
fn held_hand_step_agrees(c: dextrain::config::Config, cpu: &mut dextrain::env::cpu::CpuEnvBatch, ctx: dextrain::gpu::context::GpuContext) {
    let first = cpu.states().unwrap()[0];
    let mut t = cpu.model().default_targets();
    t.wrist_pos = first.wrist_pos;
    t.wrist_rot = first.wrist_rot;
    t.q = first.q;
    let start = snap(cpu);
    one_physics_step_agrees(c, &start, t, ctx);
}

/// A cube struck into the palm at 1 m/s, tilted 1° (`cube_struck_at_the_palm`): the strike turns
/// the cube and the rest of its top face arrives within the substep, met by a contact of its own
/// after the object's solve (`arriving_contacts`, the object solved again); one physics step
/// agrees.
#[test]
fn a_cube_struck_into_the_palm_steps_the_same_on_both_backends() {
    let Some(ctx) = gpu_context("a_cube_struck_into_the_palm_steps_the_same_on_both_backends") else { return };
    let c = base_config(8);
    let mut cpu = cpu_batch(&c);
    cpu.reset_all().unwrap();
    cube_struck_at_the_palm(&mut cpu, 1.0, 1.0);
    held_hand_step_agrees(c, &mut cpu, ctx);
}

/// A cube lying nearly flat under the palm box (tilted 0.5°), 1 mm apart and thrown at it at 1 m/s:
/// the palm's speculative contact from the boxes' separation over their separating axes
/// (`box_box_separation`), where the projections overstate the gap; one physics step agrees.
#[test]
fn a_cube_thrown_flat_at_the_palm_steps_the_same_on_both_backends() {
    let Some(ctx) = gpu_context("a_cube_thrown_flat_at_the_palm_steps_the_same_on_both_backends") else { return };
    cube_under_the_palm_steps_the_same(ctx, -0.001, 0.5, |_, model, st| {
        let up = toward_palm(model, st);
        st.obj_vel = [up.x, up.y, up.z, 0.0];
    });
}

/// A cube lying nearly flat under the palm (tilted 0.5°), 5 mm apart and thrown at it at 3 m/s
/// (past the fixed 3 mm margin within a substep): the speculative margin grown with the pair's
/// speed (`speculative_margin`) meets it; one physics step agrees.
#[test]
fn a_cube_thrown_fast_at_the_palm_steps_the_same_on_both_backends() {
    let Some(ctx) = gpu_context("a_cube_thrown_fast_at_the_palm_steps_the_same_on_both_backends") else { return };
    cube_under_the_palm_steps_the_same(ctx, -0.005, 0.5, |_, model, st| {
        let up = toward_palm(model, st) * 3.0;
        st.obj_vel = [up.x, up.y, up.z, 0.0];
    });
}

/// A cube tilted `tilt_deg` under the palm, its near edge `depth` in (negative: apart), 4 mm
/// further sideways in each of 8 envs, its velocities set by `moving` (env, model, state), the hand
/// held where it is: one physics step agrees.
fn cube_under_the_palm_steps_the_same(ctx: dextrain::gpu::context::GpuContext, depth: f32, tilt_deg: f32, moving: impl Fn(usize, &dextrain::env::SimModel, &mut dextrain::env::EnvState)) {
    let c = base_config(8);
    let mut cpu = cpu_batch(&c);
    box_tilted_against_palm(&mut cpu, depth, tilt_deg, |i| 0.004 * i as f32 - 0.012);
    let model = cpu.model().clone();
    let mut s = cpu.states().unwrap();
    for (i, st) in s.iter_mut().enumerate() {
        moving(i, &model, st);
    }
    cpu.set_states(&s).unwrap();
    held_hand_step_agrees(c, &mut cpu, ctx);
}

/// A cube tilted 10° under the palm, its near edge 0.2 mm away, spinning at 15–29 rad/s one way or
/// the other about the palm's x axis, so that an edge sweeps toward the palm within the substep
/// (`swept_contact` looks at the pair where the poses will be at its end): one physics step agrees.
#[test]
fn a_cube_spinning_against_the_palm_steps_the_same_on_both_backends() {
    let Some(ctx) = gpu_context("a_cube_spinning_against_the_palm_steps_the_same_on_both_backends") else { return };
    cube_under_the_palm_steps_the_same(ctx, -0.0002, 10.0, |i, model, st| {
        let palm = palm_pose(model, st);
        let sign = if i % 2 == 0 { 1.0 } else { -1.0 };
        let w = palm.rot * glam::Vec3::X * (sign * (15.0 + 2.0 * i as f32));
        st.obj_angvel = [w.x, w.y, w.z, 0.0];
    });
}

/// A cube pressed nearly flat (1° off) 1 mm into the palm, 4 mm further sideways in each env and
/// turning at 2–9 rad/s one way or the other about the palm's y axis: the palm's contact is a
/// manifold of the corners below its face (`box_box_contact`), whose spread resists the cube's turn
/// in its implicit solve and goes back to the hand (`spread_matrix`): one physics step agrees.
#[test]
fn a_cube_pressed_flat_into_the_palm_steps_the_same_on_both_backends() {
    let Some(ctx) = gpu_context("a_cube_pressed_flat_into_the_palm_steps_the_same_on_both_backends") else { return };
    cube_under_the_palm_steps_the_same(ctx, 0.001, 1.0, |i, model, st| {
        let palm = palm_pose(model, st);
        let sign = if i % 2 == 0 { 1.0 } else { -1.0 };
        let w = palm.rot * glam::Vec3::Y * (sign * (2.0 + i as f32));
        st.obj_angvel = [w.x, w.y, w.z, 0.0];
    });
}

/// A cube pressed into the palm across the palm's rim (`cube_across_the_palm_rim`), 0.2 mm
/// less to 0.5 mm further in and up to 3.5 mm sideways over the 8 envs: the edge–edge axes near the palm's
/// normal give way to its face (`EDGE_AXIS_SHARE`), whose clipped points meet the cube; one
/// physics step agrees.
#[test]
fn a_cube_pressed_into_the_palm_across_its_rim_steps_the_same_on_both_backends() {
    let Some(ctx) = gpu_context("a_cube_pressed_into_the_palm_across_its_rim_steps_the_same_on_both_backends") else { return };
    let c = base_config(8);
    let mut cpu = cpu_batch(&c);
    cube_across_the_palm_rim(&mut cpu, |i| 0.0001 * i as f32 - 0.0002, |i| 0.0005 * i as f32);
    held_hand_step_agrees(c, &mut cpu, ctx);
}

/// A palm's rim pressed across a cube's top edge (`cube_under_the_palm_s_edge`), 1 mm less to
/// 0.75 mm more and up to 3.5 mm sideways over the 8 envs: the edge pair's contact
/// (`box_edge_contact`); one physics step agrees.
#[test]
fn a_palm_s_rim_across_a_cube_s_edge_steps_the_same_on_both_backends() {
    let Some(ctx) = gpu_context("a_palm_s_rim_across_a_cube_s_edge_steps_the_same_on_both_backends") else { return };
    let c = base_config(8);
    let mut cpu = cpu_batch(&c);
    cube_under_the_palm_s_edge(&mut cpu, |i| 0.00025 * i as f32 - 0.001, |i| 0.0005 * i as f32);
    held_hand_step_agrees(c, &mut cpu, ctx);
}

/// A cube lying along a fingertip capsule, on the capsule's side away from the palm, the capsule's
/// middle 1 mm into the face and the cube turned 0–7° about the face's axis across the capsule in
/// the 8 envs, so that both ends of the segment are in (two point springs,
/// `capsule_face_contact`) or one is out: one physics step agrees.
#[test]
fn a_cube_along_a_fingertip_steps_the_same_on_both_backends() {
    use dextrain::gpu::layout::{NO_JOINT, SHAPE_CAPSULE};
    use glam::{Mat3, Quat, Vec3};
    let Some(ctx) = gpu_context("a_cube_along_a_fingertip_steps_the_same_on_both_backends") else { return };
    let c = base_config(8);
    let mut cpu = cpu_batch(&c);
    let model = cpu.model().clone();
    let ci = model.colliders.iter().position(|cd| cd.shape == SHAPE_CAPSULE && cd.tip != NO_JOINT).expect("a fingertip capsule");
    let cd = model.colliders[ci];
    assert_eq!(model.pieces[0].shape, dextrain::gpu::layout::SHAPE_BOX, "the object is a box");
    let (rc, half) = (cd.size[0], model.pieces[0].size[2]);
    let mut s = cpu.states().unwrap();
    for (i, st) in s.iter_mut().enumerate() {
        let links = dextrain::env::hand_link_poses(&model, st);
        let cap = links[cd.link as usize].mul(&dextrain::geom::Pose::from_arrays(cd.pos, cd.rot));
        let u = cap.rot * Vec3::Z;
        // away from the palm, across the capsule
        let out = cap.pos - palm_pose(&model, st).pos;
        let away = (out - u * out.dot(u)).normalize();
        // the cube's +z face toward the capsule, its x axis along the segment, then turned
        let nrm = -away;
        let flat = Quat::from_mat3(&Mat3::from_cols(u, nrm.cross(u), nrm));
        let rot = Quat::from_axis_angle(nrm.cross(u), (i as f32).to_radians()) * flat;
        let centre = cap.pos - rot * Vec3::Z * (half + rc - 0.001);
        st.obj_pos = [centre.x, centre.y, centre.z, 0.0];
        st.obj_rot = rot.to_array();
        st.obj_vel = [0.0; 4];
        st.obj_angvel = [0.0; 4];
    }
    cpu.set_states(&s).unwrap();
    // the scene as described: two springs in the flattest envs, one in the most turned
    let p = cpu.params().unwrap();
    let springs: Vec<f32> = s
        .iter()
        .zip(&p)
        .map(|(st, p)| {
            let mut scratch = dextrain::env::physics::Scratch::default();
            dextrain::env::physics::hand_kinematics(st, &model.view(), &mut scratch);
            dextrain::env::physics::collide_hand_object(st, p, &model.view(), &scratch, ci, dextrain::env::physics::CONTACT_MARGIN).spring_count
        })
        .collect();
    assert!(springs[0] > 1.9 && springs[7] == 1.0, "spring counts {springs:?}");
    held_hand_step_agrees(c, &mut cpu, ctx);
}

/// Three objects in one batch (a cube, the shipped 3-piece bottle — two cylinders and a hull — and
/// a two-box "L" whose centre of mass and principal axes are off its frame, its pieces colliding
/// as their convex hulls), each env holding the one it drew.
fn compound_objects(c: &mut dextrain::config::Config) {
    use dextrain::config::{MeshFiles, ObjectItem, PieceKind};
    let dir = std::env::temp_dir().join(format!("dextrain-parity-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    // two boxes of an "L", each its own OBJ group, wound outward
    let mut l = String::new();
    for (k, (c, h)) in [([0.02f32, 0.0, 0.01], [0.03f32, 0.012, 0.01]), ([-0.005, 0.0, 0.045], [0.005, 0.012, 0.025])].iter().enumerate() {
        l += &format!("g part{k}\n");
        for v in 0..8 {
            let s = |bit: usize, i: usize| if v & bit != 0 { c[i] + h[i] } else { c[i] - h[i] };
            l += &format!("v {} {} {}\n", s(1, 0), s(2, 1), s(4, 2));
        }
        for q in [[1, 3, 4, 2], [5, 6, 8, 7], [1, 2, 6, 5], [3, 7, 8, 4], [1, 5, 7, 3], [2, 4, 8, 6]] {
            l += &format!("f {} {} {} {}\n", q[0] + 8 * k, q[1] + 8 * k, q[2] + 8 * k, q[3] + 8 * k);
        }
    }
    std::fs::write(dir.join("l.obj"), l).unwrap();
    let mesh = |p: String| Some(MeshFiles::One(p));
    c.object.set = vec![
        ObjectItem::default(),
        ObjectItem { mesh: mesh(concat!(env!("CARGO_MANIFEST_DIR"), "/configs/objects/bottle.obj").into()), mass: Some(0.15), ..Default::default() },
        ObjectItem { mesh: mesh(dir.join("l.obj").display().to_string()), density: Some(800.0), pieces_as: vec![PieceKind::Hull], ..Default::default() },
    ];
}

#[test]
fn reset_draws_the_same_objects_on_both_backends() {
    let Some(ctx) = gpu_context("reset_draws_the_same_objects_on_both_backends") else { return };
    let slack = parity_slack(&ctx);
    let mut c = base_config(48);
    compound_objects(&mut c);
    c.randomization.object_scale = [0.8, 1.2];
    c.randomization.object_mass = [0.5, 2.0];
    let mut cpu = cpu_batch(&c);
    let mut gpu = gpu_batch(&c, ctx);
    let (pc, pg) = (cpu.params().unwrap(), gpu.params().unwrap());
    for (i, (a, b)) in pc.iter().zip(&pg).enumerate() {
        assert_eq!(a.obj_index, b.obj_index, "env {i}");
        for (u, v) in floats(a).iter().zip(floats(b)) {
            assert!((u - v).abs() <= 1e-6 * u.abs().max(1.0), "env {i}: params differ: {a:?} vs {b:?}");
        }
    }
    let drawn: std::collections::BTreeSet<u32> = pc.iter().map(|p| p.obj_index).collect();
    assert_eq!(drawn.len(), 3, "every object is drawn");
    let (d, at) = max_rel_diff(&snap(&mut cpu), &snap(&mut gpu), 1e-3);
    assert!(d < 1e-5 * slack, "initial states differ: {d:e}: {at}");
}

#[test]
fn one_contact_rich_physics_step_agrees_for_compound_objects() {
    let Some(ctx) = gpu_context("one_contact_rich_physics_step_agrees_for_compound_objects") else { return };
    let mut c = dextrain::bench::bench_config(16);
    c.base_dir = concat!(env!("CARGO_MANIFEST_DIR"), "/configs").into();
    c.object.shape = None;
    c.object.mass = None;
    compound_objects(&mut c);
    contact_rich_step_agrees(c, ctx);
}

#[test]
fn contact_free_rollout_of_100_steps_agrees_to_1e_4() {
    let Some(ctx) = gpu_context("contact_free_rollout_of_100_steps_agrees_to_1e_4") else { return };
    contact_free_rollout_agrees(base_config(8), 100, ctx);
}

/// The spinning, flying objects are the compound ones: their centre of mass and principal axes
/// are off their frame (the integrator's twin paths). The L's three moments differ, and a spin
/// near its intermediate axis is unstable (rounding differences grow exponentially): 30 steps.
#[test]
fn contact_free_rollout_of_30_steps_agrees_to_1e_4_for_compound_objects() {
    let Some(ctx) = gpu_context("contact_free_rollout_of_30_steps_agrees_to_1e_4_for_compound_objects") else { return };
    let mut c = base_config(8);
    compound_objects(&mut c);
    contact_free_rollout_agrees(c, 30, ctx);
}

/// `steps` steps of `c`'s 8 envs with the objects in flight under an external force and the hand
/// waving, far apart.
fn contact_free_rollout_agrees(mut c: dextrain::config::Config, steps: usize, ctx: dextrain::gpu::context::GpuContext) {
    let slack = parity_slack(&ctx);
    c.object.init_xy = [0.6, 0.0];
    c.wrist.init_pos = [0.0, 0.0, 0.6];
    c.sim.max_distance = 100.0;
    let mut cpu = cpu_batch(&c);
    let mut gpu = gpu_batch(&c, ctx);
    // the object starts in the air with a spin; the hand waves its fingers and moves its wrist
    let mut s = cpu.states().unwrap();
    for (i, st) in s.iter_mut().enumerate() {
        st.obj_pos[2] = 1.5 + 0.1 * i as f32;
        st.obj_vel = [0.0, 0.0, 16.5, 0.0]; // in flight for the whole rollout
        st.obj_angvel = [1.0, 2.0 + i as f32, -0.5, 0.0];
    }
    cpu.set_states(&s).unwrap();
    gpu.set_states(&s).unwrap();
    // the rollout's own f32 conditioning: the CPU again with every object velocity one ulp off
    let mut nudged = cpu_batch(&c);
    for st in s.iter_mut() {
        for x in st.obj_angvel[..3].iter_mut().chain(st.obj_vel[..3].iter_mut()) {
            *x = f32::from_bits(x.to_bits() + 1);
        }
    }
    nudged.set_states(&s).unwrap();
    // an external force at a point off the centre of every object (the twins' `ext_force` path)
    let mut p = cpu.params().unwrap();
    for (i, pp) in p.iter_mut().enumerate() {
        pp.ext_force = [0.02 * (i % 3) as f32, -0.01, 0.03, 0.0];
        pp.ext_point = [0.01, -0.02 * (i % 2) as f32, 0.015, 0.0];
    }
    for b in [&mut cpu as &mut dyn EnvBatch, &mut gpu, &mut nudged] {
        b.set_params(&p).unwrap();
    }
    let base = cpu.model().default_targets();
    for k in 0..steps {
        let targets: Vec<Targets> = (0..8)
            .map(|i| {
                let mut t = base;
                let ph = 0.1 * k as f32 + i as f32;
                for j in 0..16 {
                    t.q[j] = 0.6 + 0.5 * (ph + j as f32).sin();
                }
                t.wrist_pos = [0.05 * ph.sin(), 0.05 * ph.cos(), 0.6, 0.0];
                t.wrist_rot = glam::Quat::from_rotation_z(0.3 * ph.sin()).to_array();
                t
            })
            .collect();
        cpu.step(&targets).unwrap();
        gpu.step(&targets).unwrap();
        nudged.step(&targets).unwrap();
    }
    assert_eq!(cpu.stats().unwrap().iter().map(|s| s.contacts).sum::<u32>(), 0, "rollout should be contact free");
    let (d, at) = max_rel_diff(&snap(&mut cpu), &snap(&mut gpu), 1e-2);
    // the bound: 1e-4 (times the adapter's slack), or 4× what one ulp of the initial velocities
    // does on the CPU itself, whichever is larger (a free spin near an unstable axis amplifies both)
    let (cond, _) = max_rel_diff(&snap(&mut cpu), &snap(&mut nudged), 1e-2);
    let bound = (1e-4 * slack).max(4.0 * cond);
    eprintln!("{steps}-step rollout: cpu vs gpu {d:e}, cpu vs cpu with 1-ulp nudged velocities {cond:e}");
    assert!(d < bound, "{steps}-step rollout differs by {d:e} (relative; bound {bound:e}): {at}");
}

#[test]
fn scripted_grasp_and_lift_has_the_same_outcome_on_both_backends() {
    let Some(ctx) = gpu_context("scripted_grasp_and_lift_has_the_same_outcome_on_both_backends") else { return };
    let adapter = ctx.info.name.clone();
    drop(ctx);
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/configs/grasp_lift.toml");
    let mut cfg = dextrain::config::Config::load(std::path::Path::new(path)).unwrap();
    let traj = dextrain::synth::synth(&cfg, &dextrain::synth::SynthArgs::posture(path.into(), "unused.mcap".into())).unwrap();
    cfg.sim.backend = "cpu".parse().unwrap();
    let cpu = dextrain::replay::replay(&cfg, &traj, false, None).unwrap();
    cfg.sim.backend = format!("gpu:{adapter}").parse().unwrap();
    let gpu = dextrain::replay::replay(&cfg, &traj, false, None).unwrap();
    assert!(gpu.backend.starts_with("gpu"), "{}", gpu.backend);
    for r in [&cpu, &gpu] {
        assert!(r.object_lift_m > 0.10, "{}: the object was not lifted: {:.3} m", r.backend, r.object_lift_m);
    }
    assert!((cpu.object_lift_m - gpu.object_lift_m).abs() < 0.01, "lift: cpu {:.4} gpu {:.4}", cpu.object_lift_m, gpu.object_lift_m);
    let (a, b) = (cpu.terminal_object_pos_err_m.unwrap(), gpu.terminal_object_pos_err_m.unwrap());
    assert!((a - b).abs() < 0.01, "terminal object error: cpu {a:.4} gpu {b:.4}");
    assert!((cpu.peak_penetration_mm - gpu.peak_penetration_mm).abs() < 0.5);
}

/// The bench scene's rollout (`dextrain bench`: 0.9 s of approach into a grasp, then chunks of 24
/// env steps of noisy grasp targets from it) at 256 envs on both backends: no env blows up, and the
/// contacts per physics step agree within 2 %. The single steps and short rollouts above can agree
/// while a shader goes wrong over many contact-rich steps: two variants of physics.wgsl that passed
/// every parity test above blew up 34–390 of the bench's envs on lavapipe, with 4 % to 2× more
/// contacts (BENCHMARKS.md "The physics shader's call sites").
#[test]
fn the_bench_scene_s_rollout_has_the_same_contacts_on_both_backends() {
    let test = "the_bench_scene_s_rollout_has_the_same_contacts_on_both_backends";
    let Some(ctx) = gpu_context(test) else { return };
    let mut c = dextrain::bench::bench_config(256);
    c.base_dir = concat!(env!("CARGO_MANIFEST_DIR"), "/configs").into();
    let model = dextrain::env::SimModel::from_config(&c).unwrap();
    let opts = dextrain::bench::BenchOptions { min_chunks: 2, min_seconds: 0.0 };
    let on_cpu = dextrain::bench::run_bench(&mut cpu_batch(&c), &model, &opts).unwrap();
    let on_gpu = dextrain::bench::run_bench(&mut gpu_batch(&c, ctx), &model, &opts).unwrap();
    for r in [&on_cpu, &on_gpu] {
        assert_eq!(r["bad_resets"].as_u64(), Some(0), "{}: envs blew up in the bench scene ({} contacts per physics step)", r["backend"], r["contacts_per_physics_step"]);
    }
    let contacts = |r: &serde_json::Value| r["contacts_per_physics_step"].as_f64().unwrap();
    let (a, b) = (contacts(&on_cpu), contacts(&on_gpu));
    eprintln!("{test}: contacts per physics step: cpu {a:.5}, gpu {b:.5}");
    assert!(a > 1.0, "the bench scene's grasp should touch: {a} contacts per physics step");
    assert!((a - b).abs() <= 0.02 * a, "contacts per physics step: cpu {a:.5}, gpu {b:.5} (more than 2 % apart)");
}

/// The simulator's step runs at the workgroup size its batch's size picks
/// (`gpu::shaders::step_workgroup_size`: 32 invocations a workgroup at 100 envs, three
/// workgroups and part of a fourth) with collider lists of its hand's words (one for the bench
/// hand's 17 colliders), and a module at another size (`bench --physics-wgsl`;
/// benches/physics_variants.py's `workgroup_N`) is dispatched at its own: the bench scene's
/// rollout leaves every env's state the same to the bit as the module as written (64, 8 words:
/// the rounds share the same queries out over fewer envs). A module whose workgroup memory is over the
/// device's limit is a one-line error naming the shader and the limit: wgpu does not check it, and
/// lavapipe ran such a module (36 kB over its 32 kB) with the memory overlapping and the contacts
/// wrong.
#[test]
fn the_step_s_workgroup_size_leaves_the_envs_as_they_were() {
    use dextrain::env::gpu::GpuEnvBatch;
    use dextrain::gpu::shaders::shader_source;
    let test = "the_step_s_workgroup_size_leaves_the_envs_as_they_were";
    let Some(ctx) = gpu_context(test) else { return };
    let adapter = ctx.info.name.clone();
    let mut c = dextrain::bench::bench_config(100);
    c.base_dir = concat!(env!("CARGO_MANIFEST_DIR"), "/configs").into();
    let model = dextrain::env::SimModel::from_config(&c).unwrap();
    let opts = dextrain::bench::BenchOptions { min_chunks: 1, min_seconds: 0.0 };
    let mut by_32 = GpuEnvBatch::new(ctx, model.clone()).unwrap();
    assert_eq!(by_32.step_workgroup_size(), Some(32), "100 envs step in workgroups of 32");
    let a = dextrain::bench::run_bench(&mut by_32, &model, &opts).unwrap();
    assert_eq!(a["step_workgroup_size"], 32);
    let Some(other_ctx) = gpu_context(test) else { return };
    let mut by_64 = GpuEnvBatch::with_physics_source(other_ctx, model.clone(), &shader_source()).unwrap();
    assert_eq!(by_64.step_workgroup_size(), Some(64), "the module's own size");
    let b = dextrain::bench::run_bench(&mut by_64, &model, &opts).unwrap();
    assert!(a["contacts_per_physics_step"].as_f64().unwrap() > 1.0, "the bench scene's grasp should touch: {a}");
    assert_eq!(a["contacts_per_physics_step"], b["contacts_per_physics_step"]);
    assert_eq!(b["bad_resets"].as_u64(), Some(0));
    let (sa, sb) = (by_32.states().unwrap(), by_64.states().unwrap());
    assert_eq!(sa.len(), 100);
    for (i, (x, y)) in sa.iter().zip(&sb).enumerate() {
        assert!(bytemuck::bytes_of(x) == bytemuck::bytes_of(y), "env {i}: the state differs between workgroups of 32 and of 64");
    }
    // the module at 64 (the rounds' lists: 4,616 bytes of workgroup memory) on a device allowing 4 kB
    let small = dextrain::gpu::context::GpuContext::with_limits(Some(&adapter), |l| wgpu::Limits { max_compute_workgroup_storage_size: 4096, ..l }).unwrap();
    let err = format!("{:#}", GpuEnvBatch::with_physics_source(small, model, &shader_source()).err().expect("the module's workgroup memory is over 4 kB"));
    for part in ["dextrain physics", "4616 bytes of workgroup memory", "4096", "max_compute_workgroup_storage_size"] {
        assert!(err.contains(part), "the error should say {part:?}: {err}");
    }
    assert!(!err.contains('\n'), "one line: {err}");
}

/// `run_kernel` (the harness of the shader-function parity tests) on common.wgsl's quaternion
/// maths and counter hash: the shader and the CPU twins in `env::common` agree.
#[test]
fn common_functions_match_their_cpu_twins() {
    use dextrain::env::common::{quat_error, quat_from_axis_angle, quat_mul, quat_normalize, quat_rotate, rand_uniform};
    use dextrain::gpu::context::{KernelBinding, run_kernel};
    use dextrain::gpu::shaders::SHADER_COMMON;
    use glam::Vec4;
    let Some(ctx) = gpu_context("common_functions_match_their_cpu_twins") else { return };
    let kernel = r#"
@group(0) @binding(30) var<storage, read> t_in: array<vec4<f32>>;
@group(0) @binding(31) var<storage, read_write> t_out: array<vec4<f32>>;
@compute @workgroup_size(64)
fn t_main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = gid.x;
    if (i >= arrayLength(&t_in) / 2u) { return; }
    let a = quat_normalize(t_in[2u * i]);
    let v = t_in[2u * i + 1u];
    let b = quat_from_axis_angle(normalize(v.xyz), v.w);
    t_out[4u * i] = quat_mul(a, b);
    t_out[4u * i + 1u] = vec4<f32>(quat_rotate(a, v.xyz), 0.0);
    t_out[4u * i + 2u] = vec4<f32>(quat_error(a, b), rand_uniform(7u, i, 3u, 5u, 11u));
    t_out[4u * i + 3u] = a;
}
"#;
    let n = 200;
    let mut input = Vec::new();
    for i in 0..n {
        let f = i as f32;
        input.push(Vec4::new((f * 0.37).sin(), (f * 0.11).cos(), (f * 0.73).sin(), 0.5 + (f * 0.05).cos()));
        input.push(Vec4::new((f * 0.21).cos() + 0.1, (f * 0.57).sin(), 0.3, (f * 0.013) - 1.0));
    }
    let out = run_kernel(
        &ctx,
        &format!("{SHADER_COMMON}\n{kernel}"),
        "t_main",
        &[(30, KernelBinding::Storage(bytemuck::cast_slice(&input))), (31, KernelBinding::StorageRw(&vec![0u8; n * 4 * 16]))],
        n as u32,
    )
    .expect("kernel");
    let gpu: &[Vec4] = bytemuck::cast_slice(&out[0]);
    let mut worst = 0.0f32;
    for i in 0..n {
        let a = quat_normalize(input[2 * i]);
        let v = input[2 * i + 1];
        let b = quat_from_axis_angle(v.truncate().normalize(), v.w);
        let cpu = [quat_mul(a, b), quat_rotate(a, v.truncate()).extend(0.0), quat_error(a, b).extend(rand_uniform(7, i as u32, 3, 5, 11)), a];
        for k in 0..4 {
            worst = worst.max((cpu[k] - gpu[4 * i + k]).abs().max_element());
        }
        // the hash is integer arithmetic: exactly the same draw
        assert_eq!(cpu[2].w, gpu[4 * i + 2].w, "rand_uniform of invocation {i}");
    }
    // docs/design.md §4: one evaluation agrees to about 1e-5 (values here are O(1); quat_error uses atan2)
    assert!(worst < 1e-5, "largest difference between shader and CPU twin: {worst}");
}

/// The adapter `gpu_context` picks, reopened with `max_storage_buffer_binding_size` lowered to
/// `limit` bytes (None, and why printed, without an adapter).
fn limited_context(test: &str, limit: u64) -> Option<dextrain::gpu::context::GpuContext> {
    let probe = gpu_context(test)?;
    let adapter = probe.info.name.clone();
    drop(probe);
    let ctx = dextrain::gpu::context::GpuContext::with_limits(Some(&adapter), |l| wgpu::Limits { max_storage_buffer_binding_size: limit, ..l })
        .expect("a device with a lower storage-binding limit");
    assert_eq!(ctx.device.limits().max_storage_buffer_binding_size, limit);
    Some(ctx)
}

#[test]
fn an_env_batch_beyond_the_storage_binding_limit_is_an_error_naming_the_buffer() {
    use dextrain::env::SimModel;
    use dextrain::env::gpu::GpuEnvBatch;
    let test = "an_env_batch_beyond_the_storage_binding_limit_is_an_error_naming_the_buffer";
    let limit = 1u64 << 16;
    let Some(ctx) = limited_context(test, limit) else { return };
    let n = limit as usize / std::mem::size_of::<EnvState>() + 1;
    let bytes = (n * std::mem::size_of::<EnvState>()) as u64;
    assert!(bytes > limit, "the test needs a states buffer above the limit");
    let err = GpuEnvBatch::new(ctx, SimModel::from_config(&base_config(n)).unwrap()).err().expect("the envs exceed a 64 KiB storage binding");
    let msg = format!("{err:#}");
    for part in [&format!("sim.num_envs = {n}"), "GPU buffer `states`", &format!("needs {bytes} bytes"), &format!("allows {limit} bytes"), "max_storage_buffer_binding_size"] {
        assert!(msg.contains(part), "the error should say {part:?}: {msg}");
    }
    assert!(!msg.contains('\n'), "one line: {msg}");
    // the same limit takes a batch that fits, and it runs
    let Some(ctx) = limited_context(test, limit) else { return };
    let fits = (limit as usize / std::mem::size_of::<EnvState>()).min(8);
    let mut b = GpuEnvBatch::new(ctx, SimModel::from_config(&base_config(fits)).unwrap()).expect("a batch within the limit");
    assert_eq!(b.states().unwrap().len(), fits);
}

#[test]
fn a_task_batch_beyond_the_storage_binding_limit_is_an_error_naming_the_buffer() {
    use dextrain::env::SimModel;
    use dextrain::task::task::OUT_MISC;
    use dextrain::task::{CpuTaskBatch, GpuTaskBatch, TaskBatch};
    let limit = 1u64 << 14;
    let Some(ctx) = limited_context("a_task_batch_beyond_the_storage_binding_limit_is_an_error_naming_the_buffer", limit) else { return };
    let n = 64;
    let c = base_config(n);
    let spec = CpuTaskBatch::new(&c, SimModel::from_config(&c).unwrap()).expect("cpu task").spec().clone();
    // obs [N, obs_dim], priv obs [N, priv_dim], records [N, OUT_MISC], f32
    let bytes = (n * (spec.obs_dim + spec.priv_dim + OUT_MISC) * 4) as u64;
    assert!(bytes > limit, "the test needs a task output above the limit");
    let err = GpuTaskBatch::new(&c, ctx, SimModel::from_config(&c).unwrap()).err().expect("the task outputs exceed a 16 KiB storage binding");
    let msg = format!("{err:#}");
    for part in ["test.toml: key `sim.num_envs` = 64", "GPU buffer `task_out`", &format!("needs {bytes} bytes"), &format!("allows {limit} bytes")] {
        assert!(msg.contains(part), "the error should say {part:?}: {msg}");
    }
    assert!(!msg.contains('\n'), "one line: {msg}");
}

#[test]
fn a_shader_that_fails_validation_is_an_error_naming_the_shader_not_a_panic() {
    use dextrain::gpu::context::{KernelBinding, run_kernel};
    let Some(ctx) = gpu_context("a_shader_that_fails_validation_is_an_error_naming_the_shader_not_a_panic") else { return };
    // a u32 array assigned an f32: WGSL has no implicit conversion
    let broken = "@group(0) @binding(0) var<storage, read_write> t_out: array<u32>;\n\
                  @compute @workgroup_size(64)\n\
                  fn t_main(@builtin(global_invocation_id) gid: vec3<u32>) { t_out[gid.x] = 1.5f; }\n";
    let err = ctx.compute_pipelines("broken kernel", broken, ["t_main"]).err().expect("the module must not compile");
    let msg = format!("{err:#}");
    for part in ["compiling shader `broken kernel`", "entry points t_main", "validation error", &ctx.info.name, "cannot convert"] {
        assert!(msg.contains(part), "the error should say {part:?}: {msg}");
    }
    assert!(!msg.contains('\n'), "one line: {msg}");
    // the same through run_kernel, whose shader is named after its entry point
    let err = run_kernel(&ctx, broken, "t_main", &[(0, KernelBinding::StorageRw(&[0u8; 256]))], 64).err().expect("the module must not compile");
    assert!(format!("{err:#}").contains("compiling shader `t_main`"), "{err:#}");
    // a module that compiles but lacks the entry point: the pipeline's error names it
    let fine = broken.replace("1.5f", "7u");
    let err = ctx.compute_pipelines("fine kernel", &fine, ["t_main", "no_such_main"]).err().expect("no entry point no_such_main");
    let msg = format!("{err:#}");
    assert!(msg.contains("entry point `no_such_main` of shader `fine kernel`") && msg.contains("validation error"), "{msg}");
    // and the device still works: the valid kernel runs and writes 7 everywhere
    let out = run_kernel(&ctx, &fine, "t_main", &[(0, KernelBinding::StorageRw(&[0u8; 256]))], 64).expect("the valid kernel");
    assert!(bytemuck::cast_slice::<u8, u32>(&out[0]).iter().all(|&v| v == 7));
}

#[test]
fn an_error_outside_any_scope_is_returned_by_the_next_readback() {
    let Some(ctx) = gpu_context("an_error_outside_any_scope_is_returned_by_the_next_readback") else { return };
    let mut b = gpu_batch(&base_config(4), ctx);
    let small = b.context().device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("small"),
        size: 16,
        usage: wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    // 32 bytes into a 16-byte buffer, outside any error scope: wgpu's default handler would panic
    b.context().queue.write_buffer(&small, 0, &[0u8; 32]);
    let err = b.states().expect_err("the recorded error comes back from the next readback");
    let msg = format!("{err:#}");
    for part in ["reading GPU buffer `states` back", "validation error", "since the last check"] {
        assert!(msg.contains(part), "the error should say {part:?}: {msg}");
    }
    // it is reported once: the batch goes on working
    let states = b.states().expect("the readback after the reported error");
    assert_eq!(states.len(), 4);
    assert!(states.iter().all(|s| s.episode == 0 && s.wrist_pos[2] > 0.0));
}

/// Issue 37: a batch whose `Globals::env_offset` is 32 (rank 1 of a job of 2 × 32 envs) draws
/// what envs 32–63 of one 64-env batch draw — their randomised parameters and objects, initial
/// states, observation noise and object latency, and a reference kind's reference draw and
/// augmentation — on the CPU to the bit, and on the GPU as its CPU twin does.
#[test]
fn an_env_offset_draws_what_the_job_draws_for_those_envs_on_both_backends() {
    use dextrain::env::SimModel;
    use dextrain::task::{CpuTaskBatch, GpuTaskBatch, TaskBatch};
    let ctx = gpu_context("an_env_offset_draws_what_the_job_draws_for_those_envs_on_both_backends");
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut lift = base_config(64);
    lift.randomization = dextrain::config::Config::load(&root.join("configs/dexrefine_dr.toml")).expect("shipped DR config").randomization;
    (lift.object.xy_noise, lift.object.yaw_noise) = ([0.05, 0.05], 0.5);
    let n = &mut lift.task.obs_noise;
    (n.joint_pos, n.hand_pos, n.object_pos, n.object_rot, n.object_delay) = (0.01, 0.005, 0.01, 0.02, [0, 3]);
    let mut track = dextrain::config::Config::load(&root.join("configs/track_cube.toml")).expect("shipped config");
    (track.sim.backend, track.sim.num_envs) = ("cpu".parse().unwrap(), 64);
    for (name, c) in [("lift", lift), ("track_cube", track)] {
        let mut full = CpuTaskBatch::new(&c, SimModel::from_config(&c).unwrap()).unwrap();
        let obs_full = full.reset_all().unwrap().obs.clone();
        let params_full = full.env().params().unwrap();
        let mut half_cfg = c.clone();
        half_cfg.sim.num_envs = 32;
        let mut model = SimModel::from_config(&half_cfg).unwrap();
        model.globals.env_offset = 32;
        let mut half = CpuTaskBatch::new(&half_cfg, model.clone()).unwrap();
        let obs_half = half.reset_all().unwrap().obs.clone();
        let params_half = half.env().params().unwrap();
        let row = obs_half.len() / 32;
        assert_eq!(obs_half, obs_full[32 * row..], "{name}: the actor's observations (noise included)");
        for (i, (a, b)) in params_half.iter().zip(&params_full[32..]).enumerate() {
            assert_eq!(floats(a), floats(b), "{name}: env {i}'s parameters");
        }
        // the offset matters: envs 0–31 drew otherwise
        assert_ne!(obs_half, obs_full[..32 * row], "{name}: envs 0–31 observe the same");
        let Some(ctx) = ctx.clone() else { continue };
        let slack = parity_slack(&ctx);
        let mut gpu = GpuTaskBatch::new(&half_cfg, ctx, model).unwrap();
        let obs_gpu = gpu.reset_all().unwrap().obs.clone();
        let worst = obs_gpu.iter().zip(&obs_half).map(|(g, c)| (g - c).abs() / c.abs().max(1.0)).fold(0.0f32, f32::max);
        assert!(worst < 1e-4 * slack, "{name}: the GPU's observations with env_offset 32 differ from the CPU's by {worst:e}");
        for (i, (g, c)) in gpu.env().params().unwrap().iter().zip(&params_half).enumerate() {
            for (u, v) in floats(g).iter().zip(floats(c)) {
                assert!((u - v).abs() <= 1e-6 * v.abs().max(1.0) * slack, "{name}: env {i}'s parameters on the GPU: {g:?} vs {c:?}");
            }
        }
    }
}
