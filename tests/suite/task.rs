//! The task layer (env::task, shaders/task.wgsl): CPU/GPU parity, reward terms and dones on
//! constructed states, the action mapping, the observation layout and noise, bad config input.
//! GPU tests run on any wgpu adapter, lavapipe included; without one they print why (fail with
//! REQUIRE_GPU=1).


use crate::common::*;
use dextrain::config::Config;
use dextrain::task::spec::LIFT_TERMS;
use dextrain::env::common::{quat_error, rand_uniform};
use dextrain::gpu::layout::StepStats;
use dextrain::task::layout::TaskState;
use dextrain::env::physics::hand_kinematics;
use dextrain::task::*;
use dextrain::task::task::*;
use dextrain::task::GpuTaskBatch;
use dextrain::env::{SimModel, hand_link_poses};
use glam::{Vec3, Vec4};

/// A contact-free lift scene: the hand high above the cube, wide termination distance.
fn task_config(n: usize) -> Config {
    let mut c = base_config(n);
    c.wrist.init_pos = [0.0, 0.0, 0.35];
    c.task.termination.max_hand_distance = 1.0;
    c
}

fn cpu_task(c: &Config) -> CpuTaskBatch {
    CpuTaskBatch::new(c, SimModel::from_config(c).expect("model")).expect("cpu task")
}

/// Deterministic pseudo-random actions in [−1.2, 1.2] (some get clipped) for step `t`.
fn random_actions(n: usize, a: usize, t: u32) -> Vec<f32> {
    (0..n * a).map(|k| 2.4 * rand_uniform(12345, t, 0, 77, k as u32) - 1.2).collect()
}

fn index(names: &[String], name: &str) -> usize {
    names.iter().position(|n| n == name).unwrap_or_else(|| panic!("no obs named {name}"))
}

fn term(spec: &TaskSpec, name: &str) -> usize {
    spec.term_names.iter().position(|n| n == name).unwrap()
}

/// Largest |a − b| / max(|a|, |b|, floor) and where; the floor is 1 for velocities and forces
/// (rad/s, m/s, N) and `floor` for everything else.
fn max_rel(a: &[f32], b: &[f32], floor: f32, dim: usize, names: &[String]) -> (f32, String) {
    let floors: Vec<f32> =
        names.iter().map(|n| if n.starts_with("qd.") || n.contains("vel.") || n.starts_with("tip_force.") { 1.0 } else { floor }).collect();
    let mut worst = (0.0f32, String::new());
    for (k, (x, y)) in a.iter().zip(b).enumerate() {
        let d = (x - y).abs() / x.abs().max(y.abs()).max(floors[k % dim]);
        let d = if d.is_finite() { d } else { f32::INFINITY };
        if d > worst.0 {
            worst = (d, format!("env {} {}: cpu {x} gpu {y}", k / dim, names[k % dim]));
        }
    }
    worst
}

#[test]
fn cpu_and_gpu_agree_over_random_actions_with_resets_and_noise() {
    let Some(ctx) = gpu_context("cpu_and_gpu_agree_over_random_actions_with_resets_and_noise") else { return };
    let n = 16;
    let mut c = task_config(n);
    c.task.episode_length = 8;
    c.object.xy_noise = [0.03, 0.03];
    c.object.yaw_noise = 0.5;
    let nz = &mut c.task.obs_noise;
    (nz.joint_pos, nz.joint_vel, nz.hand_pos, nz.object_pos, nz.object_rot) = (0.01, 0.1, 0.005, 0.005, 0.02);
    // a vision tracker's latency, drawn per episode: both backends draw the same and delay alike
    nz.object_delay = [0, 4];
    let mut cpu = cpu_task(&c);
    let mut gpu = GpuTaskBatch::new(&c, ctx, SimModel::from_config(&c).unwrap()).expect("gpu task");
    assert!(gpu.gpu_context().is_some() && cpu.gpu_context().is_none());
    // the ended episodes' final observations too (task_observe_final and its twin)
    cpu.set_final_observations(true).unwrap();
    gpu.set_final_observations(true).unwrap();
    let spec = cpu.spec().clone();
    let (od, pd, na) = (spec.obs_dim, spec.priv_dim, spec.action_dim);
    let term_names: Vec<String> = spec.term_names.clone();
    let worst = std::cell::RefCell::new((0.0f32, String::new()));
    let finals = std::cell::Cell::new(0usize);
    let compare = |step: u32, a: &StepBatch, b: &StepBatch| {
        for i in (0..n).filter(|&i| a.done(i) && !a.bad_reset[i]) {
            let (d, at) = max_rel(&a.final_obs[i * od..(i + 1) * od], &b.final_obs[i * od..(i + 1) * od], 0.1, od, &spec.obs_names);
            assert!(d < 2e-4, "step {step}: env {i}'s final actor obs differ by {d:e}: {at}");
            let (d, at) = max_rel(&a.final_priv_obs[i * pd..(i + 1) * pd], &b.final_priv_obs[i * pd..(i + 1) * pd], 0.1, pd, &spec.priv_names);
            assert!(d < 2e-4, "step {step}: env {i}'s final critic obs differ by {d:e}: {at}");
            // the final state is not the next episode's first
            assert_ne!(a.final_priv_obs[i * pd..(i + 1) * pd], a.priv_obs[i * pd..(i + 1) * pd]);
            finals.set(finals.get() + 1);
        }
        // contact-free rollouts agree to ~1e-4 (docs/design.md §4); positions (and their noise draws) are
        // compared relative to max(|x|, 0.1 m), velocities relative to max(|v|, 1) as in parity.rs
        let (d, at) = max_rel(&a.obs, &b.obs, 0.1, od, &spec.obs_names);
        assert!(d < 2e-4, "step {step}: actor obs differ by {d:e}: {at}");
        if d > worst.borrow().0 {
            *worst.borrow_mut() = (d, format!("step {step} {at}"));
        }
        let (d, at) = max_rel(&a.priv_obs, &b.priv_obs, 0.1, pd, &spec.priv_names);
        assert!(d < 2e-4, "step {step}: critic obs differ by {d:e}: {at}");
        if d > worst.borrow().0 {
            *worst.borrow_mut() = (d, format!("step {step} {at}"));
        }
        let (d, at) = max_rel(&a.terms, &b.terms, 1e-2, spec.term_names.len(), &term_names);
        assert!(d < 2e-4, "step {step}: reward terms differ by {d:e}: {at}");
        let (d, _) = max_rel(&a.reward, &b.reward, 1e-2, 1, &["reward".to_string()]);
        assert!(d < 2e-4, "step {step}: rewards differ by {d:e}: {:?} vs {:?}", a.reward, b.reward);
        let (d, _) = max_rel(&a.lift_height, &b.lift_height, 1e-1, 1, &["lift".to_string()]);
        assert!(d < 2e-4, "step {step}: lift heights differ by {d:e}");
        assert_eq!(a.terminated, b.terminated, "step {step}: terminated");
        assert_eq!(a.time_out, b.time_out, "step {step}: time_out");
        assert_eq!(a.success, b.success, "step {step}: success");
        assert!(a.max_pen.iter().chain(&b.max_pen).all(|&p| p == 0.0), "step {step}: the scene should be contact-free");
    };
    let (a, b) = (cpu.reset_all().unwrap().clone(), gpu.reset_all().unwrap().clone());
    compare(0, &a, &b);
    let (mut timeouts, mut terminations) = (0, 0);
    for t in 1..=30u32 {
        if t == 12 {
            // push env 3's object off the table on both backends: it terminates at this step
            for task in [&mut cpu as &mut dyn TaskBatch, &mut gpu] {
                let mut s = task.env().states().unwrap();
                s[3].obj_pos[0] = 0.7;
                task.env().set_states(&s).unwrap();
            }
        }
        let actions = random_actions(n, na, t);
        let a = cpu.step(&actions).unwrap().clone();
        let b = gpu.step(&actions).unwrap().clone();
        compare(t, &a, &b);
        if t == 12 {
            assert!(a.terminated[3] && !a.time_out[3], "the object off the table terminates");
        }
        timeouts += a.time_out.iter().filter(|&&x| x).count();
        terminations += a.terminated.iter().filter(|&&x| x).count();
        let (tc, tg) = (cpu.targets().unwrap(), gpu.targets().unwrap());
        for (x, y) in tc.iter().zip(&tg) {
            let (fx, fy): (&[f32], &[f32]) = (bytemuck::cast_slice(std::slice::from_ref(x)), bytemuck::cast_slice(std::slice::from_ref(y)));
            for (u, v) in fx.iter().zip(fy) {
                assert!((u - v).abs() <= 1e-5 * u.abs().max(1.0), "step {t}: targets differ: {x:?} vs {y:?}");
            }
        }
    }
    // episodes of 8 steps in 30 steps: 3 time-outs per env (env 3: at 8, then terminated at 12, then 20, 28)
    assert_eq!(timeouts, 3 * n);
    assert_eq!(terminations, 1);
    assert_eq!(finals.get(), 3 * n + 1, "every ended episode's final observations were compared");
    let (d, at) = worst.borrow().clone();
    eprintln!("largest relative obs difference over 30 steps: {d:.1e} ({at})");
    // the env states and task states underneath agree too (counters exactly)
    let (sc, sg) = (cpu.env().states().unwrap(), gpu.env().states().unwrap());
    for (x, y) in sc.iter().zip(&sg) {
        assert_eq!((x.episode, x.step), (y.episode, y.step));
    }
    let (kc, kg) = (cpu.task_states().to_vec(), gpu.task_states().unwrap());
    for (x, y) in kc.iter().zip(&kg) {
        assert_eq!(x.done, y.done);
        for (u, v) in x.rest_pos.iter().zip(&y.rest_pos) {
            assert!((u - v).abs() < 1e-6);
        }
    }
    // a snapshot of the GPU batch continues identically on the CPU
    let snap = gpu.save_state().unwrap();
    cpu.load_state(&snap).unwrap();
    let actions = random_actions(n, na, 99);
    let a = cpu.step(&actions).unwrap().clone();
    let b = gpu.step(&actions).unwrap().clone();
    compare(99, &a, &b);
}

/// `set_final_observations`: an episode that times out gets, as its final observations, exactly
/// what the same env observes at that step when its episode goes on (a batch with one more step
/// per episode), and `obs` holds its next episode's first; without the switch nothing is written.
#[test]
fn final_observations_are_the_observations_of_the_state_an_episode_ended_in() {
    let n = 4;
    let mut c = task_config(n);
    c.task.episode_length = 6;
    let nz = &mut c.task.obs_noise;
    (nz.joint_pos, nz.object_pos) = (0.01, 0.005);
    nz.object_delay = [0, 3];
    let mut longer = c.clone();
    longer.task.episode_length = 7;
    let (mut a, mut b, mut off) = (cpu_task(&c), cpu_task(&longer), cpu_task(&c));
    a.set_final_observations(true).unwrap();
    let (od, pd, na) = (a.spec().obs_dim, a.spec().priv_dim, a.spec().action_dim);
    for t in 1..=6u32 {
        let actions = random_actions(n, na, t);
        let sa = a.step(&actions).unwrap().clone();
        let sb = b.step(&actions).unwrap().clone();
        let so = off.step(&actions).unwrap().clone();
        if t < 6 {
            assert!(!sa.time_out.iter().any(|&x| x));
            assert_eq!(sa.obs, sb.obs);
            continue;
        }
        assert!(sa.time_out.iter().all(|&x| x) && !sb.time_out.iter().any(|&x| x), "episodes of 6 steps end at step 6, of 7 do not");
        assert_eq!(sa.final_obs, sb.obs, "the final actor observations are the continuing episode's");
        assert_eq!(sa.final_priv_obs, sb.priv_obs, "the final critic observations are the continuing episode's");
        for i in 0..n {
            assert_ne!(sa.obs[i * od..(i + 1) * od], sa.final_obs[i * od..(i + 1) * od], "obs holds the next episode's first");
        }
        assert!(so.final_obs.iter().chain(&so.final_priv_obs).all(|&x| x == 0.0), "written without set_final_observations");
        assert_eq!(so.obs, sa.obs, "observing the final states changes nothing");
        assert_eq!(sa.final_priv_obs.len(), n * pd);
    }
}

#[test]
fn reward_terms_match_hand_computed_values_on_constructed_states() {
    let n = 4;
    let mut c = task_config(n);
    c.task.episode_length = 5;
    let mut task = cpu_task(&c);
    let spec = task.spec().clone();
    let w = |name: &str| c.task.rewards.get(name).copied().unwrap_or(0.0);
    let sh = c.task.lift.success_height;
    task.reset_all().unwrap();
    let rest: Vec<[f32; 4]> = task.task_states().iter().map(|t| t.rest_pos).collect();
    let mut s = task.env().states().unwrap();
    // env 0: the object lifted 12 cm (it falls ~5 mm during the step); env 2: off the table
    s[0].obj_pos[2] = rest[0][2] + 0.12;
    s[2].obj_pos[0] = c.task.termination.table_half_extent + 0.2;
    task.env().set_states(&s).unwrap();
    let zero = vec![0.0; n * spec.action_dim];
    let b = task.step(&zero).unwrap().clone();
    let post = task.env().states().unwrap();
    // success and lifting of env 0
    assert!(b.lift_height[0] > sh && b.lift_height[0] < 0.12, "lift {}", b.lift_height[0]);
    assert!(b.success[0] && !b.success[1]);
    assert_eq!(b.terms[term(&spec, "success")], w("success"));
    assert!((b.terms[term(&spec, "lifting")] - w("lifting") * 100.0 * sh).abs() < 1e-5);
    let nt = spec.term_names.len();
    assert!(b.terms[nt + term(&spec, "lifting")].abs() < 1e-3 * w("lifting"), "env 1 rests on the table");
    // reaching of every env from its post-step state: 1 − tanh(α‖p_palm − p_obj‖)
    for i in [0, 1, 3] {
        let st = &post[i];
        let rot = glam::Quat::from_array(st.wrist_rot);
        let palm = Vec3::from_slice(&st.wrist_pos[..3]) + rot * Vec3::from(c.task.hand.palm_offset);
        let d = (palm - Vec3::from_slice(&st.obj_pos[..3])).length();
        let want = w("reaching") * (1.0 - (c.task.lift.reach_alpha * d).tanh());
        assert!((b.terms[i * nt + term(&spec, "reaching")] - want).abs() < 1e-5, "env {i}: reaching");
        let sum: f32 = b.terms[i * nt..(i + 1) * nt].iter().sum();
        assert!((b.reward[i] - sum).abs() < 1e-6);
        assert!(!b.terminated[i] && !b.time_out[i]);
    }
    // env 2 terminated and started its next episode within the step
    assert!(b.terminated[2] && !b.time_out[2] && b.done(2));
    assert_eq!((post[2].episode, post[2].step), (1, 0));
    assert_eq!((post[1].episode, post[1].step), (0, 1));
    assert_eq!(b.obs[2 * spec.obs_dim + index(&spec.obs_names, "obj_pos.x")], post[2].obj_pos[0]);
    // time-out at episode_length exactly, not before (env 1, 3 have made 1 step)
    for k in 2..=5 {
        let b = task.step(&zero).unwrap();
        for i in [1, 3] {
            assert_eq!(b.time_out[i], k == 5, "env {i} step {k}");
            assert!(!b.terminated[i]);
        }
        assert!(!b.time_out[2], "env 2 restarted one step later");
    }
    let post = task.env().states().unwrap();
    assert_eq!((post[1].episode, post[1].step), (1, 0));
    assert_eq!((post[2].episode, post[2].step), (1, 4));
}

#[test]
fn reward_twin_on_exact_states_contact_and_bad_resets() {
    let c = task_config(1);
    let model = SimModel::from_config(&c).unwrap();
    let TaskSetup { spec, tc, .. } = task_setup(&c, &model).unwrap();
    let m = model.view();
    let rg = dextrain::task::reference::RefGlobals::default();
    let r = ref_model(&model, None, &rg);
    let params: dextrain::env::EnvParams = bytemuck::Zeroable::zeroed();
    let mut st = dextrain::env::EnvState::default();
    st.wrist_rot = [0.0, 0.0, 0.0, 1.0];
    st.obj_rot = [0.0, 0.0, 0.0, 1.0];
    st.wrist_pos = [0.1, 0.2, 0.3, 0.0];
    st.step = 3;
    // palm = wrist + palm_offset; the object 5 cm beside it
    let palm = Vec3::new(0.1, 0.2, 0.3) + Vec3::from(c.task.hand.palm_offset);
    st.obj_pos = [palm.x + 0.05, palm.y, palm.z, 0.0];
    let mut ts = TaskState { rest_pos: [0.0, 0.0, palm.z, 0.0], act_rate: 0.5, act_mag: 2.0, ..Default::default() };
    let mut stats: StepStats = bytemuck::Zeroable::zeroed();
    let thumb = spec_thumb(&model);
    stats.tip_force[thumb] = 1.0;
    stats.max_pen_ho = 0.002;
    let mut out = [0.0f32; OUT_MISC];
    let w = |name: &str| c.task.rewards.get(name).copied().unwrap_or(0.0);
    let req = task_reward(&st, &params, &stats, &mut ts, &m, &tc, &r, &mut out);
    assert_eq!(req, 0);
    let t = |name: &str| out[OUT_TERMS + term(&spec, name)];
    assert!((t("reaching") - w("reaching") * (1.0 - (c.task.lift.reach_alpha * 0.05f32).tanh())).abs() < 1e-6);
    assert_eq!(t("lifting"), 0.0);
    assert_eq!(t("contact"), 0.0, "the thumb alone is no grasp");
    assert_eq!(t("action_rate"), w("action_rate") * 0.5);
    assert_eq!(t("action_magnitude"), w("action_magnitude") * 2.0);
    assert_eq!(out[OUT_MAX_PEN], 0.002);
    assert_eq!(ts.tip_force[thumb], 1.0);
    let other = if thumb == 0 { 1 } else { 0 };
    stats.tip_force[other] = 1.0;
    task_reward(&st, &params, &stats, &mut ts, &m, &tc, &r, &mut out);
    assert_eq!(out[OUT_TERMS + term(&spec, "contact")], w("contact"), "thumb and another finger");
    stats.tip_force[thumb] = 0.5 * c.task.hand.contact_force;
    task_reward(&st, &params, &stats, &mut ts, &m, &tc, &r, &mut out);
    assert_eq!(out[OUT_TERMS + term(&spec, "contact")], 0.0, "thumb below the contact force");
    // 5 cm up: lifting = 100 h, no success yet
    st.obj_pos[2] = palm.z + 0.05;
    task_reward(&st, &params, &stats, &mut ts, &m, &tc, &r, &mut out);
    assert!((out[OUT_TERMS + term(&spec, "lifting")] - w("lifting") * 5.0).abs() < 1e-4);
    assert_eq!(out[OUT_SUCCESS], 0.0);
    assert!((out[OUT_LIFT] - 0.05).abs() < 1e-6);
    // time-out at episode_length, not before
    st.step = c.task.episode_length - 1;
    assert_eq!(task_reward(&st, &params, &stats, &mut ts, &m, &tc, &r, &mut out), 0);
    assert_eq!(out[OUT_TIME_OUT], 0.0);
    st.step = c.task.episode_length;
    assert_eq!(task_reward(&st, &params, &stats, &mut ts, &m, &tc, &r, &mut out), 1);
    assert_eq!((out[OUT_TIME_OUT], out[OUT_TERMINATED], ts.done), (1.0, 0.0, 1));
    // hand too far: terminated, not timed out
    st.obj_pos[0] = palm.x + c.task.termination.max_hand_distance + 0.01;
    assert_eq!(task_reward(&st, &params, &stats, &mut ts, &m, &tc, &r, &mut out), 1);
    assert_eq!((out[OUT_TIME_OUT], out[OUT_TERMINATED]), (0.0, 1.0));
    // dropped below the table
    st.obj_pos = [palm.x, palm.y, c.task.termination.drop_height - 0.01, 0.0];
    task_reward(&st, &params, &stats, &mut ts, &m, &tc, &r, &mut out);
    assert_eq!(out[OUT_TERMINATED], 1.0);
    // a bad-state reset: terminated, already reset by the physics (no reset request), state terms 0
    st.step = 0;
    st.obj_pos = [0.0, 0.0, 0.02, 0.0];
    stats.bad_reset = 1;
    assert_eq!(task_reward(&st, &params, &stats, &mut ts, &m, &tc, &r, &mut out), 0);
    assert_eq!((out[OUT_TERMINATED], ts.done), (1.0, 1));
    for name in ["reaching", "lifting", "contact", "success"] {
        assert_eq!(out[OUT_TERMS + term(&spec, name)], 0.0, "{name}");
    }
    let sum: f32 = (0..spec.term_names.len()).map(|k| out[OUT_TERMS + k]).sum();
    assert_eq!(out[OUT_REWARD], sum);
}

fn spec_thumb(model: &SimModel) -> usize {
    model.spec.tip_names.iter().position(|n| n.starts_with("th")).expect("thumb")
}

#[test]
fn action_mapping_reaches_limits_and_clips_the_wrist() {
    let n = 2;
    let mut c = task_config(n);
    c.task.action.wrist_rot_limit = 0.3;
    c.task.action.wrist_rot_scale = 0.2;
    c.task.action.wrist_pos_scale = 0.05;
    let model = SimModel::from_config(&c).unwrap();
    let joints = model.joints.clone();
    let actuated = model.spec.actuated.clone();
    let init_rot = Vec4::from_array(model.globals.init_wrist_rot);
    let mut task = cpu_task(&c);
    let na = task.spec().action_dim;
    task.reset_all().unwrap();
    // absolute: a = +1 → upper, a = −1 → lower (also beyond ±1: clipped); env 1 gets the opposite
    let mut act = vec![0.0; n * na];
    for k in 0..na {
        act[k] = 1.5;
        act[na + k] = -1.0;
    }
    act[na] = 1.0; // env 1's wrist x up
    for _ in 0..12 {
        task.step(&act).unwrap();
    }
    let t = task.targets().unwrap();
    for &j in &actuated {
        assert!((t[0].q[j] - joints[j].upper).abs() < 1e-6, "joint {j}: {} vs upper {}", t[0].q[j], joints[j].upper);
        assert!((t[1].q[j] - joints[j].lower).abs() < 1e-6, "joint {j}: {} vs lower {}", t[1].q[j], joints[j].lower);
    }
    // wrist position: 12 × 5 cm clipped into the box
    let (lo, hi) = (c.task.action.wrist_pos_min, c.task.action.wrist_pos_max);
    assert_eq!(t[0].wrist_pos[..3], hi[..]);
    assert_eq!([t[1].wrist_pos[0], t[1].wrist_pos[1], t[1].wrist_pos[2]], [hi[0], lo[1], lo[2]]);
    // wrist orientation: 12 × 0.2·√3 rad about (1, 1, 1), clamped to 0.3 rad from the initial one
    for i in 0..2 {
        let e = quat_error(Vec4::from_array(t[i].wrist_rot), init_rot);
        assert!((e.length() - 0.3).abs() < 1e-4, "env {i}: {} rad from the initial orientation", e.length());
        let axis = if i == 0 { Vec3::ONE } else { -Vec3::ONE }.normalize();
        assert!(e.normalize().dot(axis) > 0.999, "env {i}: rotated about {e:?}");
        assert!((Vec4::from_array(t[i].wrist_rot).length() - 1.0).abs() < 1e-5);
    }
    // the previous action (clipped) is observed and its rate/magnitude terms are charged
    let b = task.step(&act).unwrap().clone();
    let spec = task.spec().clone();
    let p0 = index(&spec.obs_names, &format!("prev_action.{}", spec.action_names[0]));
    assert_eq!(b.obs[p0], 1.0);
    assert_eq!(b.terms[term(&spec, "action_rate")], 0.0);
    let mag = na as f32 * c.task.rewards["action_magnitude"];
    assert!((b.terms[term(&spec, "action_magnitude")] - mag).abs() < 1e-5);

    // delta: targets move by a·scale and stop at the limits
    c.task.action.finger_mode = dextrain::config::FingerMode::Delta;
    c.task.action.finger_delta_scale = 0.25;
    let mut task = cpu_task(&c);
    task.reset_all().unwrap();
    let t0 = task.targets().unwrap();
    let mut act = vec![0.0; n * na];
    for k in 6..na {
        act[k] = 1.0;
        act[na + k] = -0.5;
    }
    task.step(&act).unwrap();
    let t1 = task.targets().unwrap();
    for &j in &actuated {
        let want = (t0[0].q[j] + 0.25).clamp(joints[j].lower, joints[j].upper);
        assert!((t1[0].q[j] - want).abs() < 1e-6);
        let want = (t0[1].q[j] - 0.125).clamp(joints[j].lower, joints[j].upper);
        assert!((t1[1].q[j] - want).abs() < 1e-6);
    }
    for _ in 0..30 {
        task.step(&act).unwrap();
    }
    let t = task.targets().unwrap();
    for &j in &actuated {
        assert_eq!(t[0].q[j], joints[j].upper);
        assert_eq!(t[1].q[j], joints[j].lower);
    }
    // wrist unchanged by zero wrist actions (the default pose, inside the box)
    assert_eq!(t[0].wrist_pos, t0[0].wrist_pos);
    assert_eq!(t[0].wrist_rot, t0[0].wrist_rot);
}

#[test]
fn observations_match_the_state_and_noise_has_the_configured_std() {
    // the default scene (hand just above the cube), a few steps in so velocities are non-zero
    let n = 4;
    let mut c = base_config(n);
    c.wrist.init_pos = Config::default().wrist.init_pos;
    let mut task = cpu_task(&c);
    let spec = task.spec().clone();
    let model = SimModel::from_config(&c).unwrap();
    let es = &model.spec;
    let (nj, nt) = (es.actuated.len(), es.tip_names.len());
    assert_eq!(spec.obs_names.len(), spec.obs_dim);
    assert_eq!(spec.priv_names.len(), spec.priv_dim);
    assert_eq!(spec.action_names.len(), spec.action_dim);
    assert_eq!(spec.action_dim, 6 + nj);
    assert_eq!(spec.obs_dim, 3 * nj + 26 + 3 * nt);
    // + object and wrist velocities (12), mass, friction, scale, restitution, added gravity (5),
    // per-tip contact flags and forces, per-link contact flags
    assert_eq!(spec.priv_dim, spec.obs_dim + 17 + 2 * nt + model.hand.links.len());
    assert_eq!(spec.term_names, LIFT_TERMS.iter().map(|t| t.name).collect::<Vec<_>>());
    assert_eq!(spec.priv_names[..spec.obs_dim], spec.obs_names[..]);
    let mut uniq = spec.priv_names.clone();
    uniq.sort();
    uniq.dedup();
    assert_eq!(uniq.len(), spec.priv_dim, "names are unique");
    // a field's critic columns (what eval's force statistics read): one per fingertip, named for it
    let force_cols = dextrain::task::spec::field_indices(&spec.priv_layout, &[dextrain::task::spec::TIP_FORCE.to_string()]).unwrap();
    assert_eq!(force_cols.len(), nt);
    for (k, &col) in force_cols.iter().enumerate() {
        assert_eq!(spec.priv_names[col], format!("tip_force.{}", es.tip_names[k]));
    }
    assert!(dextrain::task::spec::field_indices(&spec.priv_layout, &["no_such_field".to_string()]).is_err());
    assert!((spec.control_dt - c.sim.dt * c.sim.decimation as f32).abs() < 1e-9);
    eprintln!("dexhand16 default config: obs_dim {}, priv_dim {}, action_dim {}", spec.obs_dim, spec.priv_dim, spec.action_dim);

    task.reset_all().unwrap();
    let act: Vec<f32> = random_actions(n, spec.action_dim, 1);
    for _ in 0..3 {
        task.step(&act).unwrap();
    }
    let b = task.step(&act).unwrap().clone();
    let states = task.env().states().unwrap();
    let params = task.env().params().unwrap();
    let stats = task.env().stats().unwrap();
    let ts = task.task_states().to_vec();
    let (od, pd) = (spec.obs_dim, spec.priv_dim);
    for i in 0..n {
        let (o, p, st) = (&b.obs[i * od..(i + 1) * od], &b.priv_obs[i * pd..(i + 1) * pd], &states[i]);
        assert_eq!(o, &p[..od], "no noise: the actor obs are the clean ones");
        let at = |name: &str| o[index(&spec.obs_names, name)];
        let pt = |name: &str| p[index(&spec.priv_names, name)];
        for &j in &es.actuated {
            assert_eq!(at(&format!("q.{}", es.joint_names[j])), st.q[j]);
            assert_eq!(at(&format!("qd.{}", es.joint_names[j])), st.qd[j]);
        }
        for (k, a) in spec.action_names.iter().enumerate() {
            assert_eq!(at(&format!("prev_action.{a}")), act[i * spec.action_dim + k].clamp(-1.0, 1.0));
        }
        for (c3, axis) in ["x", "y", "z"].iter().enumerate() {
            assert_eq!(at(&format!("wrist_pos.{axis}")), st.wrist_pos[c3]);
            assert_eq!(at(&format!("obj_pos.{axis}")), st.obj_pos[c3]);
            assert_eq!(at(&format!("goal.{axis}")), ts[i].rest_pos[c3] + if c3 == 2 { c.task.lift.success_height } else { 0.0 });
            assert_eq!(pt(&format!("obj_vel.{axis}")), st.obj_vel[c3]);
            assert_eq!(pt(&format!("wrist_angvel.{axis}")), st.wrist_angvel[c3]);
        }
        for (c4, q) in ["qx", "qy", "qz", "qw"].iter().enumerate() {
            assert_eq!(at(&format!("wrist_rot.{q}")), st.wrist_rot[c4]);
            assert_eq!(at(&format!("obj_rot.{q}")), st.obj_rot[c4]);
        }
        // fingertips against the hand model's link poses
        let poses = hand_link_poses(&model, st);
        for tip in &model.hand.fingertips {
            let want = poses[tip.link].transform_point(tip.pos);
            for (c3, axis) in ["x", "y", "z"].iter().enumerate() {
                let got = at(&format!("tip_pos.{}.{axis}", tip.name));
                assert!((got - want[c3]).abs() < 1e-5, "{} {axis}: {got} vs {}", tip.name, want[c3]);
            }
            let k = es.tip_names.iter().position(|n| *n == tip.name).unwrap();
            assert_eq!(pt(&format!("tip_force.{}", tip.name)), stats[i].tip_force[k]);
            // a fingertip that pushed on the object over the step: its link pushed in some substep
            if stats[i].tip_force[k] > 0.0 {
                assert_eq!(pt(&format!("link_contact.{}", model.hand.links[tip.link].name)), 1.0, "{}: tip force without link contact", tip.name);
            }
        }
        // one flag per link: bit l of the step's statistics
        for (l, link) in model.hand.links.iter().enumerate() {
            assert_eq!(pt(&format!("link_contact.{}", link.name)), ((stats[i].link_contact[l / 32] >> (l % 32)) & 1) as f32, "link {}", link.name);
        }
        let rot = glam::Quat::from_array(st.wrist_rot);
        let palm = Vec3::from_slice(&st.wrist_pos[..3]) + rot * Vec3::from(c.task.hand.palm_offset);
        let rel = Vec3::from_slice(&st.obj_pos[..3]) - palm;
        for (c3, axis) in ["x", "y", "z"].iter().enumerate() {
            assert!((at(&format!("obj_rel.{axis}")) - rel[c3]).abs() < 1e-6);
        }
        assert_eq!(pt("obj_mass"), params[i].obj_inertia[3]);
        assert_eq!(pt("obj_friction"), params[i].obj_friction);
        assert_eq!(pt("obj_scale"), params[i].obj_scale);
        assert_eq!(pt("obj_restitution"), params[i].restitution);
        assert_eq!(pt("added_gravity"), params[i].added_gravity);
    }
    // the twin's fingertip helper agrees with hand_link_poses (same kinematics)
    let mut s = dextrain::env::physics::Scratch::default();
    hand_kinematics(&states[0], &model.view(), &mut s);
    let t0 = tip_position(&model.view(), &s, 0);
    let want = hand_link_poses(&model, &states[0])[model.hand.fingertips[0].link].transform_point(model.hand.fingertips[0].pos);
    assert!((t0 - want).length() < 1e-6);

    // noise: 512 envs at reset; (noisy − clean) per group has the configured std
    let n = 512;
    let mut c = base_config(n);
    let sig = [0.02f32, 0.3, 0.01, 0.015, 0.05];
    let nz = &mut c.task.obs_noise;
    (nz.joint_pos, nz.joint_vel, nz.hand_pos, nz.object_pos, nz.object_rot) = (sig[0], sig[1], sig[2], sig[3], sig[4]);
    let mut task = cpu_task(&c);
    let b = task.reset_all().unwrap().clone();
    let groups: [(&str, f32); 5] = [("q.", sig[0]), ("qd.", sig[1]), ("wrist_pos.", sig[2]), ("obj_pos.", sig[3]), ("obj_rot.", sig[4])];
    for (prefix, want) in groups {
        let idx: Vec<usize> = (0..od).filter(|&k| spec.obs_names[k].starts_with(prefix)).collect();
        let d: Vec<f64> = (0..n).flat_map(|i| idx.iter().map(move |&k| (i, k))).map(|(i, k)| (b.obs[i * od + k] - b.priv_obs[i * pd + k]) as f64).collect();
        let mean = d.iter().sum::<f64>() / d.len() as f64;
        let std = (d.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / d.len() as f64).sqrt();
        assert!((std / want as f64 - 1.0).abs() < 0.2, "{prefix}: std {std} vs {want}");
        assert!(mean.abs() < 0.2 * want as f64, "{prefix}: mean {mean}");
    }
    // tips and obj_rel carry the hand / object noise; the quaternion stays unit; goal and the
    // previous action are exact
    for i in 0..n {
        let q: Vec<f32> = ["qx", "qy", "qz", "qw"].iter().map(|c| b.obs[i * od + index(&spec.obs_names, &format!("obj_rot.{c}"))]).collect();
        assert!((Vec4::from_slice(&q).length() - 1.0).abs() < 1e-5);
        for k in 0..od {
            let name = &spec.obs_names[k];
            if name.starts_with("goal.") || name.starts_with("prev_action.") || name.starts_with("wrist_rot.") {
                assert_eq!(b.obs[i * od + k], b.priv_obs[i * pd + k], "{name}");
            }
        }
    }
    let tip_k = index(&spec.obs_names, &format!("tip_pos.{}.x", spec_tips(&c)[0]));
    assert!((0..n).any(|i| b.obs[i * od + tip_k] != b.priv_obs[i * pd + tip_k]));
    // a new draw at every step
    let zero = vec![0.0; n * spec.action_dim];
    let b2 = task.step(&zero).unwrap().clone();
    let k = index(&spec.obs_names, "obj_pos.x");
    let d1 = b.obs[k] - b.priv_obs[k];
    let d2 = b2.obs[k] - b2.priv_obs[k];
    assert_ne!(d1, d2);
}

fn spec_tips(c: &Config) -> Vec<String> {
    SimModel::from_config(c).unwrap().spec.tip_names
}

#[test]
fn bad_thumb_names_give_one_line_errors_naming_the_key() {
    let mut c = task_config(1);
    c.task.hand.thumb = "pinky_tip".into();
    let e = format!("{:#}", CpuTaskBatch::new(&c, SimModel::from_config(&c).unwrap()).err().expect("an error"));
    assert!(e.contains("task.hand.thumb") && e.contains("pinky_tip") && e.contains("th_tip") && e.contains("test.toml"), "{e}");
    assert!(!e.contains('\n'), "{e}");
    // "" = the first fingertip starting with "th": none among the chosen fingertips
    let mut c = task_config(1);
    c.hand.fingertips = vec!["if_tip".into(), "mf_tip".into()];
    let e = format!("{:#}", make_task_batch(&c, SimModel::from_config(&c).unwrap()).err().expect("an error"));
    assert!(e.contains("task.hand.thumb") && e.contains("if_tip"), "{e}");
    assert!(!e.contains('\n'), "{e}");
    // a named thumb among them works, and the default finds th_tip
    c.task.hand.thumb = "mf_tip".into();
    assert!(make_task_batch(&c, SimModel::from_config(&c).unwrap()).is_ok());
    let c = task_config(1);
    let model = SimModel::from_config(&c).unwrap();
    let tc = task_setup(&c, &model).unwrap().tc;
    assert_eq!(model.spec.tip_names[tc.thumb as usize], "th_tip");
    // wrong action counts and non-finite actions are errors, not NaNs
    let mut task = cpu_task(&c);
    task.reset_all().unwrap();
    let a = task.spec().action_dim;
    assert!(task.step(&vec![0.0; a + 1]).is_err());
    let mut bad = vec![0.0; a];
    bad[2] = f32::NAN;
    let e = format!("{:#}", task.step(&bad).err().unwrap());
    assert!(e.contains("finite"), "{e}");
}

/// The observation spec (`task::spec::OBS_FIELDS`) is what the twins write: the layout covers the
/// observation exactly, and each field's values land at its offset — checked against the env
/// state, the drawn parameters and the applied actions, on the CPU and (when there is an adapter)
/// the GPU, for the lift task and every reference kind.
#[test]
fn each_observation_field_lands_at_its_offset_on_both_backends() {
    use dextrain::config::TaskKind;
    for kind in TaskKind::ALL {
        let mut c = if kind == TaskKind::Lift {
            task_config(4)
        } else {
            let mut c = Config::load(std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/configs/grasp_lift.toml"))).expect("config");
            c.sim.backend = "cpu".parse().unwrap();
            c.sim.num_envs = 4;
            c.task.kind = kind;
            c.task.rewards = kind.default_rewards();
            c.task.reference.files = vec!["refs/grasp_lift.mcap".into()];
            c
        };
        // no resets inside the checked step
        c.task.episode_length = 1000;
        c.validate().unwrap();
        let model = SimModel::from_config(&c).unwrap();
        let mut backends: Vec<(String, Box<dyn TaskBatch>)> = vec![("cpu".into(), Box::new(CpuTaskBatch::new(&c, model.clone()).unwrap()))];
        if let Some(ctx) = gpu_context("each_observation_field_lands_at_its_offset_on_both_backends") {
            backends.push(("gpu".into(), Box::new(GpuTaskBatch::new(&c, ctx, model.clone()).unwrap())));
        }
        for (backend, mut task) in backends {
            let spec = task.spec().clone();
            let what = format!("{kind} on {backend}");
            // the layouts tile the observations exactly, the critic's starting with the actor's
            for (layout, dim, names) in [(&spec.obs_layout, spec.obs_dim, &spec.obs_names), (&spec.priv_layout, spec.priv_dim, &spec.priv_names)] {
                let mut next = 0;
                for s in layout.iter() {
                    assert_eq!((s.offset, s.entries.len()), (next, s.size), "{what}: {}", s.name);
                    assert_eq!(&names[s.offset..s.offset + s.size], &s.entries[..], "{what}: {}", s.name);
                    next += s.size;
                }
                assert_eq!(next, dim, "{what}");
            }
            assert_eq!(&spec.priv_layout[..spec.obs_layout.len()], &spec.obs_layout[..], "{what}");
            task.reset_all().unwrap();
            let actions: Vec<f32> = random_actions(spec.num_envs, spec.action_dim, 1);
            let b = task.step(&actions).unwrap().clone();
            assert!(b.terminated.iter().chain(&b.time_out).all(|d| !d), "{what}: no env may reset in the checked step");
            let states = task.env().states().unwrap();
            let params = task.env().params().unwrap();
            let (od, pd, na) = (spec.obs_dim, spec.priv_dim, spec.action_dim);
            let act = &model.spec.actuated;
            for e in 0..spec.num_envs {
                let (st, p) = (&states[e], &params[e]);
                let obs = &b.obs[e * od..(e + 1) * od];
                let privo = &b.priv_obs[e * pd..(e + 1) * pd];
                // no observation noise in these configs: the actor sees what the critic sees
                assert_eq!(obs, &privo[..od], "{what}");
                let slot = |name: &str| spec.priv_layout.iter().find(|s| s.name == name).unwrap_or_else(|| panic!("{what}: no field {name}"));
                let at = |name: &str| {
                    let s = slot(name);
                    &privo[s.offset..s.offset + s.size]
                };
                let close = |name: &str, want: &[f32]| {
                    let got = at(name);
                    assert_eq!(got.len(), want.len(), "{what}: {name}");
                    for (i, (g, w)) in got.iter().zip(want).enumerate() {
                        assert!((g - w).abs() <= 1e-5 * w.abs().max(1.0), "{what} env {e}: {name}[{i}] = {g}, expected {w}");
                    }
                };
                close("q", &act.iter().map(|&j| st.q[j]).collect::<Vec<_>>());
                close("qd", &act.iter().map(|&j| st.qd[j]).collect::<Vec<_>>());
                close("prev_action", &actions[e * na..(e + 1) * na].iter().map(|a| a.clamp(-1.0, 1.0)).collect::<Vec<_>>());
                close("wrist_pos", &st.wrist_pos[..3]);
                close("wrist_rot", &st.wrist_rot);
                close("obj_pos", &st.obj_pos[..3]);
                close("obj_rot", &st.obj_rot);
                close("obj_vel", &st.obj_vel[..3]);
                close("obj_angvel", &st.obj_angvel[..3]);
                close("wrist_vel", &st.wrist_vel[..3]);
                close("wrist_angvel", &st.wrist_angvel[..3]);
                close("obj_mass", &[p.obj_inertia[3]]);
                close("obj_friction", &[p.obj_friction]);
                close("obj_scale", &[p.obj_scale]);
                close("obj_restitution", &[p.restitution]);
                close("added_gravity", &[p.added_gravity]);
                assert!(at("tip_contact").iter().all(|&v| v == 0.0 || v == 1.0), "{what}: tip_contact");
                let contact = at("tip_contact").to_vec();
                for (t, f) in at("tip_force").iter().enumerate() {
                    assert_eq!(contact[t] == 1.0, *f > c.task.hand.contact_force, "{what}: tip_contact follows tip_force");
                }
                if kind == TaskKind::Lift {
                    let goal = at("goal");
                    assert!((goal[2] - at("obj_pos")[2] - c.task.lift.success_height).abs() < 0.01, "{what}: the goal is the rest position raised by success_height");
                } else {
                    let phase = at("phase")[0];
                    assert!(phase > 0.0 && phase < 1.0, "{what}: phase {phase} one step into the reference");
                    assert_eq!(slot("ref0.q").size, act.len(), "{what}");
                    assert!(spec.priv_layout.iter().any(|s| s.name == format!("ref{}.tip_pos", c.task.track.lookahead)), "{what}: one block per look-ahead frame");
                }
                if kind == TaskKind::ResidualTask {
                    assert!(at("residual").iter().all(|v| v.abs() <= 1.0), "{what}: the residual over its clamps");
                }
            }
        }
    }
}

/// `link_contact` (critic): replaying a grasp (residual_joint, zero residual) on both backends,
/// every fingertip that pushed on the object during a step has its link flagged, flags are 0 or
/// 1, and the replay does grasp (the implication is checked on real contacts).
#[test]
fn link_contact_flags_the_links_that_push_on_the_object() {
    use dextrain::config::TaskKind;
    let mut c = Config::load(std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/configs/grasp_lift.toml"))).expect("config");
    c.sim.backend = "cpu".parse().unwrap();
    c.sim.num_envs = 2;
    c.task.kind = TaskKind::ResidualJoint;
    c.task.rewards = TaskKind::ResidualJoint.default_rewards();
    c.task.reference.files = vec!["refs/grasp_lift.mcap".into()];
    c.validate().unwrap();
    let model = SimModel::from_config(&c).unwrap();
    let mut backends: Vec<(String, Box<dyn TaskBatch>)> = vec![("cpu".into(), Box::new(CpuTaskBatch::new(&c, model.clone()).unwrap()))];
    if let Some(ctx) = gpu_context("link_contact_flags_the_links_that_push_on_the_object") {
        backends.push(("gpu".into(), Box::new(GpuTaskBatch::new(&c, ctx, model.clone()).unwrap())));
    }
    for (backend, mut task) in backends {
        let spec = task.spec().clone();
        let slot = spec.priv_layout.iter().find(|s| s.name == "link_contact").expect("link_contact field");
        assert_eq!(slot.size, model.hand.links.len(), "{backend}: one flag per link");
        let tips = spec.priv_layout.iter().find(|s| s.name == "tip_force").unwrap();
        task.reset_all().unwrap();
        let zeros = vec![0.0; spec.num_envs * spec.action_dim];
        let mut pushing_steps = 0;
        for _ in 0..spec.episode_length.min(150) {
            let b = task.step(&zeros).unwrap().clone();
            for e in 0..spec.num_envs {
                if b.done(e) {
                    continue;
                }
                let p = &b.priv_obs[e * spec.priv_dim..(e + 1) * spec.priv_dim];
                let flags = &p[slot.offset..slot.offset + slot.size];
                assert!(flags.iter().all(|&f| f == 0.0 || f == 1.0), "{backend}: flags {flags:?}");
                for (k, tip) in model.spec.tip_names.iter().enumerate() {
                    if p[tips.offset + k] > 0.0 {
                        pushing_steps += 1;
                        let t = model.hand.fingertips.iter().find(|t| &t.name == tip).unwrap();
                        assert_eq!(flags[t.link], 1.0, "{backend}: {tip} pushed on the object but its link is not flagged");
                    }
                }
            }
        }
        assert!(pushing_steps > 0, "{backend}: the replay never grasped");
    }
}

/// `task.obs_noise.object_delay`: the actor sees the object pose of k control steps earlier (the
/// episode's first pose before that) while the critic sees the current one — on both backends,
/// with k fixed at 3; and with a range, every episode's k lies in it and the range is used.
#[test]
fn the_actors_object_pose_lags_by_the_drawn_latency_on_both_backends() {
    let mut c = task_config(4);
    c.task.episode_length = 12;
    c.task.obs_noise.object_delay = [3, 3];
    let model = SimModel::from_config(&c).unwrap();
    let mut backends: Vec<(String, Box<dyn TaskBatch>)> = vec![("cpu".into(), Box::new(CpuTaskBatch::new(&c, model.clone()).unwrap()))];
    if let Some(ctx) = gpu_context("the_actors_object_pose_lags_by_the_drawn_latency_on_both_backends") {
        backends.push(("gpu".into(), Box::new(GpuTaskBatch::new(&c, ctx, model.clone()).unwrap())));
    }
    for (backend, mut task) in backends {
        let spec = task.spec().clone();
        let (od, pd, n) = (spec.obs_dim, spec.priv_dim, spec.num_envs);
        let slot = |name: &str| spec.obs_layout.iter().find(|s| s.name == name).unwrap().offset;
        let (p, q) = (slot("obj_pos"), slot("obj_rot"));
        let pose = |rows: &[f32], dim: usize, i: usize| rows[i * dim + p..i * dim + q + 4].to_vec();
        let first = task.reset_all().unwrap().clone();
        // the critic's (current) poses of every step, and the actor's
        let mut critic = vec![(0..n).map(|i| pose(&first.priv_obs, pd, i)).collect::<Vec<_>>()];
        let mut actor = vec![(0..n).map(|i| pose(&first.obs, od, i)).collect::<Vec<_>>()];
        let actions = random_actions(n, spec.action_dim, 3);
        for _ in 0..10 {
            let b = task.step(&actions).unwrap().clone();
            critic.push((0..n).map(|i| pose(&b.priv_obs, pd, i)).collect());
            actor.push((0..n).map(|i| pose(&b.obs, od, i)).collect());
        }
        let mut moved = false;
        for t in 0..critic.len() {
            for i in 0..n {
                let want = &critic[t.saturating_sub(3)][i];
                assert_eq!(&actor[t][i], want, "{backend}: env {i} step {t}: the actor's object pose is not the critic's of 3 steps earlier");
                moved |= critic[t][i] != critic[0][i];
            }
        }
        assert!(moved, "{backend}: the object never moved, the lag is not observable");
    }
    // a range: each episode draws its own latency in it
    let cfg = |lo: u32, hi: u32| {
        let mut c = task_config(64);
        c.task.obs_noise.object_delay = [lo, hi];
        c
    };
    let mut task = cpu_task(&cfg(1, 5));
    task.reset_all().unwrap();
    let delays: Vec<u32> = task.task_states().iter().map(|t| t.obj_delay).collect();
    assert!(delays.iter().all(|&d| (1..=5).contains(&d)), "{delays:?}");
    assert!(delays.contains(&1) && delays.contains(&5), "the range's ends are drawn: {delays:?}");
    // beyond the ring: a one-line error naming the key
    let mut c = cfg(0, 9);
    let e = format!("{:#}", c.validate().unwrap_err());
    assert!(e.contains("task.obs_noise.object_delay") && e.contains("7") && !e.contains('\n'), "{e}");
    c.task.obs_noise.object_delay = [3, 2];
    assert!(c.validate().is_err());
}
