//! The reference-following task kinds (track, residual_joint, residual_task): a zero residual and
//! the open-loop baseline reproduce `dextrain replay` exactly; the residual mappings, the reward
//! terms and the success test against hand-computed values; CPU and GPU agree.


use std::path::PathBuf;

use crate::common::*;
use dextrain::config::Config;
use dextrain::task::ik::{IkScratch, ik_tip_positions};
use dextrain::task::layout::TaskState;
use dextrain::task::reference::RefFrame;
use dextrain::task::*;
use dextrain::task::task::*;
use dextrain::task::GpuTaskBatch;
use dextrain::env::{EnvState, SimModel};
use dextrain::replay::replay;
use dextrain::traj::Trajectory;
use glam::{Vec2, Vec3};

fn configs() -> PathBuf {
    PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/configs"))
}

/// The grasp-and-lift scene with a reference kind on the shipped clean reference, no augmentation.
fn track_config(kind: &str, n: usize) -> Config {
    let mut c = Config::load(&configs().join("grasp_lift.toml")).expect("config");
    c.sim.backend = "cpu".parse().unwrap();
    c.sim.num_envs = n;
    c.task.kind = kind.parse().unwrap();
    c.task.rewards = kind.parse::<dextrain::config::TaskKind>().map(|k| k.default_rewards()).unwrap();
    c.task.reference.files = vec!["refs/grasp_lift.mcap".into()];
    // long enough that no env resets inside the compared window
    c.task.episode_length = 1000;
    c.validate().expect("valid");
    c
}

fn reference() -> Trajectory {
    Trajectory::load(&configs().join("refs/grasp_lift.mcap")).expect("reference")
}

/// Steps `task` with `actions` for `steps` env steps and returns env 0's object and wrist poses
/// after each step (as raw arrays, to compare bit for bit).
fn rollout(task: &mut dyn TaskBatch, actions: &[f32], steps: usize) -> Vec<([f32; 4], [f32; 4], [f32; 4])> {
    task.reset_all().unwrap();
    let s0 = task.env().states().unwrap()[0];
    let mut out = vec![(s0.obj_pos, s0.obj_rot, s0.wrist_pos)];
    for _ in 0..steps {
        task.step(actions).unwrap();
        let s = task.env().states().unwrap()[0];
        out.push((s.obj_pos, s.obj_rot, s.wrist_pos));
    }
    out
}

#[test]
fn zero_residual_and_open_loop_reproduce_replay_exactly() {
    let traj = reference();
    let base = track_config("residual_joint", 2);
    let r = replay(&base, &traj, false, None).unwrap();
    let frames = r.trace.len();
    assert!(frames > 100);
    let check = |name: &str, got: &[([f32; 4], [f32; 4], [f32; 4])]| {
        for (k, (o, q, w)) in got.iter().enumerate() {
            let (_, obj, wrist) = &r.trace[k];
            assert_eq!([o[0], o[1], o[2]], obj.pos.to_array(), "{name}: object position at frame {k}");
            assert_eq!(*q, obj.rot.to_array(), "{name}: object orientation at frame {k}");
            assert_eq!([w[0], w[1], w[2]], wrist.pos.to_array(), "{name}: wrist position at frame {k}");
        }
    };
    for kind in ["residual_joint", "residual_task", "track"] {
        let c = track_config(kind, 2);
        let mut task = make_task_batch(&c, SimModel::from_config(&c).unwrap()).unwrap();
        let zero = vec![0.0; 2 * task.spec().action_dim];
        let got = rollout(task.as_mut(), &zero, frames - 1);
        check(kind, &got);
    }
    // the open-loop baseline ignores the actions, for every reference kind
    for kind in ["track", "residual_joint", "residual_task"] {
        let mut c = track_config(kind, 2);
        c.task.open_loop = true;
        let mut task = make_task_batch(&c, SimModel::from_config(&c).unwrap()).unwrap();
        let ones = vec![0.7; 2 * task.spec().action_dim];
        let got = rollout(task.as_mut(), &ones, frames - 1);
        check(&format!("{kind} open-loop"), &got);
    }
    // and a non-zero residual does change the outcome
    let c = track_config("residual_joint", 2);
    let mut task = make_task_batch(&c, SimModel::from_config(&c).unwrap()).unwrap();
    let push = vec![0.5; 2 * task.spec().action_dim];
    let got = rollout(task.as_mut(), &push, 40);
    assert_ne!(got[40].2, [r.trace[40].2.pos.x, r.trace[40].2.pos.y, r.trace[40].2.pos.z, got[40].2[3]]);
}

fn frame_of(task: &CpuTaskBatch, step: u32, k: u32) -> RefFrame {
    task.reference_frame(0, step, k).expect("a reference kind")
}

/// residual_joint, and track with `task.track.action = "reference"` (the default), map their actions
/// around the reference with `[task.residual]`'s α; track with `"free"` does not.
#[test]
fn residual_joint_and_reference_track_map_actions_around_the_reference() {
    for kind in ["residual_joint", "track"] {
        joint_mapping_around_the_reference(kind);
    }
    let mut c = track_config("track", 1);
    c.task.track.action = dextrain::config::TrackAction::Free;
    let model = SimModel::from_config(&c).unwrap();
    let mut task = CpuTaskBatch::new(&c, model.clone()).unwrap();
    task.reset_all().unwrap();
    let mut a = vec![0.0f32; task.spec().action_dim];
    a[0] = 1.0;
    let before = task.targets().unwrap()[0];
    task.step(&a).unwrap();
    let t = task.targets().unwrap()[0];
    // [task.action]: the wrist target moves by wrist_pos_scale from where it was
    assert!((t.wrist_pos[0] - (before.wrist_pos[0] + c.task.action.wrist_pos_scale)).abs() < 1e-6, "{:?} {:?}", t.wrist_pos, before.wrist_pos);
}

fn joint_mapping_around_the_reference(kind: &str) {
    let c = track_config(kind, 1);
    let model = SimModel::from_config(&c).unwrap();
    let mut task = CpuTaskBatch::new(&c, model.clone()).unwrap();
    task.reset_all().unwrap();
    let spec = task.spec().clone();
    let mut a = vec![0.0f32; spec.action_dim];
    a[0] = 1.0; // wrist +x
    a[5] = -0.5; // wrist rotation about z
    a[6] = 1.0; // first actuated joint
    a[7] = -3.0; // clipped to −1
    let nominal = frame_of(&task, 0, 1);
    task.step(&a).unwrap();
    let t = task.targets().unwrap()[0];
    let r = &c.task.residual;
    assert!((t.wrist_pos[0] - (nominal.wrist_pos[0] + r.wrist_pos_alpha)).abs() < 1e-7);
    assert_eq!(t.wrist_pos[1], nominal.wrist_pos[1]);
    // R* = exp(α_r a) ⊗ R̄: the rotation between them is 0.5 α_r about −z
    let d = glam::Quat::from_array(t.wrist_rot) * glam::Quat::from_array(nominal.wrist_rot).inverse();
    let (axis, angle) = d.to_axis_angle();
    assert!((angle - 0.5 * r.wrist_rot_alpha).abs() < 1e-5 && (axis - glam::Vec3::NEG_Z).length() < 1e-3, "{axis} {angle}");
    let es = &model.spec;
    let (j0, j1) = (es.actuated[0], es.actuated[1]);
    let clampj = |j: usize, v: f32| v.max(model.joints[j].lower).min(model.joints[j].upper);
    assert_eq!(t.q[j0], clampj(j0, nominal.q[j0] + r.alpha));
    assert_eq!(t.q[j1], clampj(j1, nominal.q[j1] - r.alpha));
    for &j in &es.actuated[2..] {
        assert_eq!(t.q[j], nominal.q[j], "joint {j} follows the reference");
    }
    // the residual term: ‖δ‖² with δ = (α_p a_wrist, α_r a_rot, α a_joints), weighted
    let want = r.wrist_pos_alpha.powi(2) + (0.5 * r.wrist_rot_alpha).powi(2) + 2.0 * r.alpha.powi(2);
    assert!((task.task_states()[0].res_sq - want).abs() < 1e-6, "{} vs {want}", task.task_states()[0].res_sq);
}

#[test]
fn residual_task_smooths_integrates_clamps_and_moves_fingertips_by_ik() {
    let c = track_config("residual_task", 1);
    let model = SimModel::from_config(&c).unwrap();
    let mut task = CpuTaskBatch::new(&c, model.clone()).unwrap();
    task.reset_all().unwrap();
    let spec = task.spec().clone();
    let r = c.task.residual.clone();
    let dt = spec.control_dt;
    assert_eq!(spec.action_dim, 6 + 3 * model.tips.len());
    // constant u = 1 on wrist x and on the first fingertip's z (wrist frame: the open finger points
    // along x, so z is the direction its flexion moves the tip)
    let mut a = vec![0.0f32; spec.action_dim];
    a[0] = 1.0;
    a[8] = 1.0;
    let (mut ema, mut delta) = (0.0f32, 0.0f32);
    for step in 0..3 {
        let nominal = frame_of(&task, step, 1);
        task.step(&a).unwrap();
        // ũ = 0.8 u + 0.2 ũ;  Δa = clamp(Δa + s ũ Δt)
        ema = r.ema * 1.0 + (1.0 - r.ema) * ema;
        delta = (delta + r.scale_wrist_pos * ema * dt).clamp(-r.clamp_wrist_pos, r.clamp_wrist_pos);
        let ts = task.task_states()[0];
        assert!((ts.res_ema[0] - ema).abs() < 1e-7 && (ts.res_delta[0] - delta).abs() < 1e-7, "step {step}");
        let t = task.targets().unwrap()[0];
        assert!((t.wrist_pos[0] - (nominal.wrist_pos[0] + delta)).abs() < 1e-6, "step {step}");
        // the fingertip residual moves the first fingertip (wrist frame) by Δa_tip, the others stay
        let m = model.view();
        let mut s = IkScratch::default();
        let base = ik_tip_positions(&m, &nominal.q, &mut s);
        let got = ik_tip_positions(&m, &t.q, &mut s);
        let want0 = base[0] + Vec3::new(0.0, 0.0, ts.res_delta[8]);
        assert!((got[0] - want0).length() < 1e-3, "step {step}: tip 0 at {} vs {}", got[0], want0);
        for k in 1..model.tips.len() {
            assert!((got[k] - base[k]).length() < 1e-3, "step {step}: tip {k} moved");
        }
    }
    // the integrated residual saturates at its clamp
    for _ in 0..400 {
        task.step(&a).unwrap();
        if task.task_states()[0].res_delta[0] >= r.clamp_wrist_pos {
            break;
        }
    }
    assert_eq!(task.task_states()[0].res_delta[0], r.clamp_wrist_pos);
    assert!(task.task_states()[0].res_delta[8] <= r.clamp_tips);
}

#[test]
fn tracking_reward_terms_match_hand_computed_values() {
    let frame = |dx: f32, rot: f32| {
        let mut f = RefFrame::default();
        f.wrist_pos = [0.1 + dx, 0.0, 0.3, 0.0];
        f.wrist_rot = glam::Quat::from_rotation_z(rot).to_array();
        f.obj_pos = [0.0, 0.0, 0.05, 0.0];
        f.obj_rot = [0.0, 0.0, 0.0, 1.0];
        f.grasp = 1.0;
        f
    };
    let mut st = EnvState::default();
    st.wrist_pos = [0.1, 0.0, 0.3, 0.0];
    st.wrist_rot = [0.0, 0.0, 0.0, 1.0];
    st.obj_rot = [0.0, 0.0, 0.0, 1.0];
    let params: dextrain::env::EnvParams = bytemuck::Zeroable::zeroed();
    let ts = TaskState { act_rate: 0.25, act_mag: 1.5, res_sq: 0.04, ..Default::default() };
    for kind in ["track", "residual_joint", "residual_task"] {
        let mut c = track_config(kind, 1);
        c.task.track.alpha_wrist_pos = 10.0;
        c.task.track.alpha_object_pos = 20.0;
        let model = SimModel::from_config(&c).unwrap();
        let tc = task_setup(&c, &model).unwrap().tc;
        let m = model.view();
        let mut f = frame(0.02, 0.3);
        // joints: every actuated joint 0.1 rad off the reference
        for &j in &model.spec.actuated {
            f.q[j] = st.q[j] + 0.1;
        }
        let e = Vec2::new(0.01, 0.2);
        // the kind's own term function (each kind's terms are a function of its own)
        let terms_on_table = |st: &EnvState, f: &RefFrame, e: Vec2, fin: bool, contact: bool, h: f32, table: bool| match kind {
            "track" => track_terms(st, &ts, f, e, fin, contact, h, &tc),
            "residual_joint" => residual_joint_terms(&ts, f, e, fin, &tc),
            _ => residual_task_terms(st, &params, &ts, f, e, contact, table, &m, &tc),
        };
        let terms = |st: &EnvState, f: &RefFrame, e: Vec2, fin: bool, contact: bool, h: f32| terms_on_table(st, f, e, fin, contact, h, false);
        let raw = terms(&st, &f, e, false, true, 0.04);
        let k = &c.task.track;
        match kind {
            "track" => {
                let nj = model.spec.actuated.len() as f32;
                let rj = 1.0 - (k.alpha_joint * (nj * 0.01).sqrt()).tanh();
                let rx = 1.0 - (k.alpha_wrist_pos * 0.02f32).tanh();
                let rr = 1.0 - (k.alpha_wrist_rot * 0.3f32).tanh();
                let rf = k.beta_joint * rj + k.beta_wrist_pos * rx + k.beta_wrist_rot * rr;
                assert!((raw[0] - rf).abs() < 1e-5, "R_f {} vs {rf}", raw[0]);
                let ro = (-k.alpha_object_pos * 0.01f32).exp() + (-k.alpha_object_rot * 0.2f32).exp();
                assert!((raw[1] - ro).abs() < 1e-6, "R_o {} vs {ro}", raw[1]);
                assert_eq!(raw[2], 1.0, "contact while the reference grasps");
                assert_eq!(raw[3], 0.0, "not at the final pose");
                assert!((raw[4] - 4.0).abs() < 1e-4, "lifting in cm");
                assert_eq!((raw[5], raw[6]), (0.25, 1.5));
                // success only once the reference has ended and the object is at its final pose
                f.ended = 1;
                assert_eq!(terms(&st, &f, e, true, true, 0.04)[3], 1.0);
                f.grasp = 0.0;
                assert_eq!(terms(&st, &f, e, true, true, 0.04)[2], 0.0, "no contact bonus before the grasp");
            }
            "residual_joint" => {
                let r = &c.task.residual;
                assert!((raw[0] - (-r.obj_pos_coef * 0.01f32).exp()).abs() < 1e-6);
                assert!((raw[1] - (-r.obj_rot_coef * 0.2f32).exp()).abs() < 1e-6);
                assert_eq!(raw[2], 0.04);
            }
            _ => {
                let r = &c.task.residual;
                // object term gated by contact (true here)
                assert!((raw[0] - (-r.reward_obj_pos * 0.01 - r.reward_obj_rot * 0.2f32).exp()).abs() < 1e-6);
                let e_w = (-r.reward_wrist_pos * 0.02 - r.reward_wrist_rot * 0.3f32).exp();
                assert!((raw[2] - e_w).abs() < 1e-5, "wrist {} vs {e_w}", raw[2]);
                // fingertips: the reference tips 1 cm above the actual ones
                let mut s = dextrain::env::physics::Scratch::default();
                dextrain::env::physics::hand_kinematics(&st, &m, &mut s);
                for t in 0..model.tips.len() {
                    let p = tip_position(&m, &s, t) + Vec3::Z * 0.01;
                    f.tips[t] = [p.x, p.y, p.z, 0.0];
                }
                let far = Vec2::new(c.task.track.success_pos_tol + 0.01, 0.2);
                let raw = terms(&st, &f, far, false, false, 0.0);
                assert!((raw[1] - (-r.reward_tips * 0.01f32).exp()).abs() < 1e-5, "tips {}", raw[1]);
                assert_eq!(raw[0], 0.0, "no contact and beyond the tolerance: the object term is gated off");
                let near = terms(&st, &f, e, false, false, 0.0);
                assert!(near[0] > 0.0, "within the tolerance the object term counts without contact");
                assert_eq!(raw[3], 0.0);
                assert_eq!(raw[7], 0.0, "no hand–table contact");
                assert_eq!(terms_on_table(&st, &f, e, false, false, 0.0, true)[7], 1.0);
            }
        }
    }
}

#[test]
fn cpu_and_gpu_agree_on_every_reference_kind() {
    let Some(_) = gpu_context("cpu_and_gpu_agree_on_every_reference_kind") else { return };
    // residual_task twice: with its fingertip IK, and with the fingertip actions at 0 (the wrist
    // residual alone, which keeps the tight tolerances of the other kinds)
    for name in ["track", "track_free", "residual_joint", "residual_task", "residual_task_wrist"] {
        let kind = name.trim_end_matches("_free").trim_end_matches("_wrist");
        let mut c = track_config(kind, 8);
        if name == "track_free" {
            c.task.track.action = dextrain::config::TrackAction::Free;
        }
        // every augmentation on, observation noise on, short episodes so that resets happen
        let a = &mut c.task.reference;
        a.translate_xy = 0.03;
        a.rotate_z = 0.3;
        a.mirror_prob = 0.5;
        a.wrist_pos_offset = 0.01;
        a.wrist_pos_noise = 0.002;
        a.joint_offset = 0.05;
        a.joint_noise = 0.01;
        a.time_scale = 0.1;
        c.task.obs_noise.joint_pos = 0.01;
        c.task.obs_noise.object_pos = 0.005;
        c.task.episode_length = 12;
        let model = SimModel::from_config(&c).unwrap();
        let mut cpu = CpuTaskBatch::new(&c, model.clone()).unwrap();
        let ctx = gpu_context(kind).unwrap();
        let slack = parity_slack(&ctx);
        let mut gpu = GpuTaskBatch::new(&c, ctx, model).unwrap();
        let spec = cpu.spec().clone();
        let a0 = cpu.reset_all().unwrap().clone();
        let b0 = gpu.reset_all().unwrap().clone();
        // residual_task runs its fingertip IK on both backends. At the reference's straight
        // fingers (the open hand) a finger moves its tip by ~0.6 mm per rad along one direction of
        // its joints, so the backends' f32 rounding of the tips (~1e-8 m) leaves their IK targets up
        // to 3.1e-5 rad apart (measured here: step 13, env 5), and contact turns that into object
        // rotations up to 3.1e-3 (relative, floor 0.1) apart in the observations. The IK is smooth
        // and deterministic there (tests/ik.rs sweeps it on both backends); its tolerances here are
        // about 3× what was measured; the other runs keep the tight ones.
        let ik = name == "residual_task";
        // (the tight ones × parity_slack on a hardware GPU; the IK run's hold there as measured)
        let (tol, q_tol) = if ik { (1e-2, 1e-4) } else { (2e-4 * slack, 1e-5 * slack) };
        let close = |x: &[f32], y: &[f32], floor: f32, what: &str, step: usize| {
            for (i, (u, v)) in x.iter().zip(y).enumerate() {
                let d = (u - v).abs() / u.abs().max(v.abs()).max(floor);
                assert!(d < tol, "{name} step {step}: {what}[{i}] cpu {u} gpu {v}");
            }
        };
        close(&a0.obs, &b0.obs, 0.1, "obs", 0);
        let mut rng = 12345u64;
        for step in 1..=16 {
            let actions: Vec<f32> = (0..spec.num_envs * spec.action_dim)
                .map(|k| {
                    rng = rng.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                    let a = ((rng >> 40) as f32 / (1u64 << 24) as f32) * 2.0 - 1.0;
                    // residual_task's actions 6.. are the fingertip residuals
                    if name == "residual_task_wrist" && k % spec.action_dim >= 6 { 0.0 } else { a }
                })
                .collect();
            let a = cpu.step(&actions).unwrap().clone();
            let b = gpu.step(&actions).unwrap().clone();
            for (e, (x, y)) in cpu.targets().unwrap().iter().zip(gpu.targets().unwrap()).enumerate() {
                let d = x.q.iter().zip(&y.q).map(|(u, v)| (u - v).abs()).fold(0.0f32, f32::max);
                assert!(d < q_tol, "{name} step {step} env {e}: joint targets differ by {d} rad");
                let w = (glam::Vec4::from_array(x.wrist_pos) - glam::Vec4::from_array(y.wrist_pos)).abs().max_element();
                assert!(w < 1e-5, "{name} step {step} env {e}: wrist targets differ by {w} m");
            }
            close(&a.obs, &b.obs, 0.1, "obs", step);
            close(&a.priv_obs, &b.priv_obs, 0.1, "priv_obs", step);
            close(&a.reward, &b.reward, 1e-2, "reward", step);
            close(&a.terms, &b.terms, 1e-2, "terms", step);
            close(&a.obj_pos_err, &b.obj_pos_err, 1e-2, "obj_pos_err", step);
            assert_eq!(a.terminated, b.terminated, "{name} step {step}");
            assert_eq!(a.time_out, b.time_out, "{name} step {step}");
            assert_eq!(a.success, b.success, "{name} step {step}");
        }
    }
}

/// A residual run end to end: train a few iterations from the shipped config, then `eval
/// --baseline open-loop`: the JSON holds both, the Markdown table is written, and the baseline's
/// episodes (un-augmented reference, no randomisation) end exactly where `dextrain replay` ends.
#[test]
fn residual_run_trains_and_evaluates_against_the_open_loop_baseline() {
    use dextrain::eval::{EvalArgs, run as eval};
    use dextrain::train::{TrainArgs, run as train};
    let tmp = tempfile::tempdir().unwrap();
    let sets: Vec<String> = [
        "sim.backend=cpu",
        "train.device=cpu",
        "sim.num_envs=4",
        "train.iterations=2",
        "train.steps_per_env=8",
        "train.save_interval=2",
        "train.plot_interval=0",
        "policy.actor_hidden=[16]",
        "policy.critic_hidden=[16]",
        "task.reference.files=[\"refs/grasp_lift.mcap\"]",
        "task.reference.translate_xy=0",
        "task.reference.rotate_z=0",
        "task.reference.time_scale=0",
        // training ends episodes 5 mm off the reference; eval must play every reference to its end
        "task.track.max_object_error=0.005",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    let args = TrainArgs {
        config: Some(configs().join("residual_joint_cube.toml")),
        sets,
        name: Some("rj".into()),
        resume: None,
        force: false,
        runs_dir: tmp.path().to_path_buf(),
        stop_after: None,
        quiet: true,
        live: Default::default(),
        gpu_profile: false,
    };
    let dir = train(&args).expect("train");
    // metrics.csv logs the object's tracking error for the reference kinds
    let (cols, rows) = dextrain::metrics::read_csv(&dir.join("metrics.csv")).unwrap();
    let k = cols.iter().position(|c| c == "tracking/obj_pos_err_m").expect("a tracking column");
    assert!(cols.contains(&"tracking/obj_rot_err_deg".to_string()) && cols.contains(&"reward/object_pos".to_string()));
    for (_, v) in &rows {
        assert!(v[k] > 0.0 && v[k] < 0.2, "mean object error {} m", v[k]);
    }
    let rec = tmp.path().join("eval.mcap");
    let e = EvalArgs { run: dir.clone(), checkpoint: "latest".into(), episodes: 2, max_envs: 2, seed: None, record: Some(rec.clone()), backend: None, baseline: Some(dextrain::eval::Baseline::OpenLoop), video: Default::default(), live: Default::default() };
    let r = eval(&e).expect("eval");
    // the recording shows the reference object next to the object, frame by frame
    let bytes = std::fs::read(&rec).unwrap();
    let mut poses = 0;
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        if m.channel.topic == "/dextrain/poses" {
            let v: serde_json::Value = serde_json::from_slice(&m.data).unwrap();
            assert!(v["object_ref"]["qw"].is_number(), "object_ref in {v}");
            poses += 1;
        }
    }
    assert!(poses > 100, "{poses} pose messages");
    let base = r.baseline.as_ref().expect("baseline");
    assert_eq!((r.policy.per_episode.len(), base.per_episode.len()), (2, 2));
    assert!(r.path.with_extension("md").is_file());
    let json: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&r.path).unwrap()).unwrap();
    assert!(json["baseline"]["ote_m"]["mean"].is_number() && json["ote_m"]["mean"].is_number());
    // replay of the same reference under the run's config
    let cfg = Config::load(&dir.join("config.toml")).unwrap();
    let rep = replay(&Config { sim: dextrain::config::SimConfig { num_envs: 1, ..cfg.sim.clone() }, ..cfg.clone() }, &reference(), false, None).unwrap();
    let want = rep.terminal_object_pos_err_m.unwrap();
    assert!(want > 0.005, "replay ends {want} m off: the early termination would have cut it");
    for ep in &base.per_episode {
        let end = ep.terminal_pos_err_m.expect("a reference kind reports the terminal error");
        assert!((end - want).abs() < 1e-6, "baseline ends {end} m off, replay {want} m");
        assert_eq!(ep.length as usize, rep.trace.len() - 1, "the episode plays the whole reference");
    }
    // every episode names its reference, and the Markdown has a row per reference
    for ep in r.policy.per_episode.iter().chain(&base.per_episode) {
        assert_eq!(ep.reference, "grasp_lift.mcap");
        assert_eq!(ep.length as usize, rep.trace.len() - 1, "eval ignores task.track.max_object_error");
    }
    let md = std::fs::read_to_string(r.path.with_extension("md")).unwrap();
    assert!(md.lines().any(|l| l.starts_with("| grasp_lift.mcap | ") && l.matches("/2").count() == 2), "{md}");
    let ote = base.ote_m.as_ref().expect("a reference kind reports OTE");
    assert!(ote.mean > 0.0 && ote.mean < 0.05, "{ote:?}");
    // one meaning per metric name: the peak is the deepest of any step, at least each episode's peak
    for summary in [&json, &json["baseline"]] {
        let peak = summary["peak_penetration_mm"].as_f64().expect("peak_penetration_mm is a number");
        let per_episode = &summary["episode_peak_penetration_mm"];
        assert!(peak >= per_episode["mean"].as_f64().unwrap() && peak >= 0.0, "{summary}");
        assert!(summary["mean_fingertip_force_n"].is_number(), "{summary}");
        assert!(summary.get("max_penetration_mm").is_none() && summary.get("mean_contact_force_n").is_none(), "{summary}");
    }
    // an unknown baseline is an error that names the flag and the allowed value (a closed choice:
    // the command line rejects it before eval runs)
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_dextrain")).arg("eval").arg(&dir).args(["--baseline", "closed-loop"]).output().unwrap();
    let bad = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && bad.contains("--baseline") && bad.contains("open-loop"), "{bad}");
}

#[test]
fn eval_names_references_by_file_name_unless_two_collide() {
    use dextrain::eval::reference_names;
    use std::path::PathBuf;
    let p = |s: &str| PathBuf::from(s);
    assert_eq!(reference_names(&[p("refs/a/ref_000.mcap"), p("refs/a/ref_001.mcap")]), ["ref_000.mcap", "ref_001.mcap"]);
    // two datasets with a ref_000.mcap each: every reference is named by its whole path
    let both = [p("refs/a/ref_000.mcap"), p("refs/b/ref_000.mcap"), p("refs/b/ref_001.mcap")];
    assert_eq!(reference_names(&both), ["refs/a/ref_000.mcap", "refs/b/ref_000.mcap", "refs/b/ref_001.mcap"]);
}

// ------------------------------------------------------------------------------------------------
// eval and replay reports

/// A summary with every tracking metric set (reference kinds) or none (lift).
fn summary(tracking: bool) -> dextrain::eval::Summary {
    use dextrain::eval::{EpisodeRow, MeanStd, Summary};
    let ms = |mean: f64| MeanStd { mean, std: 0.5 * mean };
    let t = |v: f64| tracking.then_some(v);
    Summary {
        success_rate: 0.5,
        terminated_rate: 0.25,
        episode_return: ms(10.0),
        episode_length: ms(100.0),
        final_lift_height_m: ms(0.05),
        max_lift_height_m: ms(0.08),
        ote_m: tracking.then(|| ms(0.012)),
        ooe_deg: tracking.then(|| ms(4.0)),
        terminal_obj_pos_err_m: tracking.then(|| ms(0.02)),
        terminal_obj_rot_err_deg: tracking.then(|| ms(6.0)),
        reward_terms: serde_json::Map::new(),
        peak_penetration_mm: 3.0,
        episode_peak_penetration_mm: ms(1.5),
        frac_frames_penetration_over_1mm: 0.1,
        mean_fingertip_force_n: 2.0,
        latent_error: None,
        per_object: Vec::new(),
        per_episode: vec![EpisodeRow {
            ret: 10.0,
            length: 100,
            success: true,
            terminated: false,
            ote_m: t(0.012),
            ooe_deg: t(4.0),
            terminal_pos_err_m: t(0.02),
            terminal_rot_err_deg: t(6.0),
            reference: if tracking { "a.mcap".into() } else { String::new() },
            object: "box".into(),
            final_lift_m: 0.05,
            peak_penetration_mm: 1.5,
            peak_penetration_step: 40,
            lift_at_peak_m: 0.0,
        }],
    }
}

fn report(task: &str, tracking: bool, baseline: bool) -> dextrain::eval::EvalReport {
    dextrain::eval::EvalReport {
        run: "runs/x".into(),
        checkpoint: "runs/x/checkpoints/4".into(),
        iteration: 4,
        seed: 7,
        episodes: 1,
        task: task.into(),
        env_backend: "cpu".into(),
        learner_device: "cpu".into(),
        policy: summary(tracking),
        baseline: baseline.then(|| summary(tracking)),
        baseline_kind: if baseline { "open-loop".into() } else { String::new() },
        path: PathBuf::new(),
    }
}

/// Item 6: the lift task has no reference, so its report leaves OTE, OOE and the terminal object
/// error out (the Markdown rows, and the JSON keys) instead of printing "0.0 ± 0.0"; a reference
/// kind shows them.
#[test]
fn lift_reports_leave_the_tracking_metrics_out() {
    let lift = report("lift", false, false);
    let md = dextrain::eval::markdown(&lift);
    for row in ["OTE", "OOE", "terminal object error"] {
        assert!(!md.contains(row), "lift table has a {row} row:\n{md}");
    }
    assert!(md.contains("| success rate | 50.0 % |") && md.contains("| peak penetration (mm) | 3.00 |"), "{md}");
    assert!(md.contains("| episode peak penetration (mm) | 1.50 ± 0.75 |"), "{md}");
    let json = serde_json::to_value(&lift).unwrap();
    for key in ["ote_m", "ooe_deg", "terminal_obj_pos_err_m", "terminal_obj_rot_err_deg", "baseline"] {
        assert!(json.get(key).is_none(), "lift JSON has `{key}`: {json}");
    }
    assert!(json["per_episode"][0].get("ote_m").is_none() && json["per_episode"][0]["ret"] == 10.0, "{json}");
    let track = report("track", true, true);
    let md = dextrain::eval::markdown(&track);
    assert!(md.contains("| OTE (mm) | 12.0 ± 6.0 | 12.0 ± 6.0 |") && md.contains("| OOE (deg) | 4.0 ± 2.0 | 4.0 ± 2.0 |"), "{md}");
    assert!(md.contains("| terminal object error (mm) | 20.0 ± 10.0 | 20.0 ± 10.0 |"), "{md}");
    let json = serde_json::to_value(&track).unwrap();
    assert_eq!(json["ote_m"]["mean"], 0.012);
    assert_eq!(json["baseline"]["terminal_obj_rot_err_deg"]["mean"], 6.0);
}

/// Item 8, finding 5: a non-finite value in a report (serde_json would print it as `null`) is an
/// error naming the field, in the policy's summary, the baseline's, an episode row or a reward term.
#[test]
fn a_non_finite_report_value_is_an_error_naming_the_field() {
    use dextrain::eval::check_finite;
    check_finite(&report("track", true, true), "eval report").expect("a finite report passes");
    check_finite(&report("lift", false, false), "eval report").expect("absent lift metrics are not nulls");
    let mut r = report("track", true, true);
    r.policy.ote_m.as_mut().unwrap().mean = f64::NAN;
    let e = check_finite(&r, "eval report").unwrap_err().to_string();
    assert!(e.contains("eval report") && e.contains("`ote_m.mean`") && e.contains("finite") && !e.contains('\n'), "{e}");
    let mut r = report("track", true, true);
    r.baseline.as_mut().unwrap().peak_penetration_mm = f64::INFINITY;
    let e = check_finite(&r, "eval report").unwrap_err().to_string();
    assert!(e.contains("`baseline.peak_penetration_mm`"), "{e}");
    let mut r = report("track", true, false);
    r.policy.per_episode[0].terminal_rot_err_deg = Some(f64::NAN);
    let e = check_finite(&r, "eval report").unwrap_err().to_string();
    assert!(e.contains("`per_episode.0.terminal_rot_err_deg`"), "{e}");
    let mut r = report("lift", false, false);
    r.policy.reward_terms.insert("reaching".into(), serde_json::json!(f64::NAN));
    let e = check_finite(&r, "eval report").unwrap_err().to_string();
    assert!(e.contains("`reward_terms.reaching`"), "{e}");
}

/// Finding 5 at replay: a reference whose object is 3.4e38 m away is refused before it is
/// simulated (it printed `"mean_object_pos_err_m": null` and exited 0), and a replay's report is
/// all finite, with the object errors left out (not null) when the reference has no object.
#[test]
fn replay_refuses_values_it_cannot_simulate_and_reports_only_finite_numbers() {
    let cfg = track_config("track", 1);
    let mut traj = reference();
    let k = traj.frames.len() / 2;
    traj.frames[k].object.as_mut().expect("the reference has an object").pos.y = 3.4e38;
    let e = format!("{:#}", replay(&cfg, &traj, true, None).unwrap_err());
    assert!(e.contains(&format!("frame {k}")) && e.contains("`object.y`") && e.contains("±100 m") && !e.contains('\n'), "{e}");
    // without an object pose the object errors are left out of the JSON, and nothing is null
    let mut traj = reference();
    traj.frames.truncate(10);
    for f in &mut traj.frames {
        f.object = None;
    }
    let r = replay(&cfg, &traj, true, None).expect("kinematic replay");
    let json = serde_json::to_value(&r).unwrap();
    assert_eq!(json["has_object_reference"], false);
    assert!(json.get("mean_object_pos_err_m").is_none() && json.get("terminal_object_rot_err_deg").is_none(), "{json}");
    dextrain::eval::check_finite(&r, "replay report").expect("finite");
    assert!(json.as_object().unwrap().values().all(|v| !v.is_null()), "{json}");
}

/// Finding 1 at replay: the frame count (duration / control step) is bounded before anything is
/// allocated: an hour-long reference at a 1 ms control step (3.6 M frames) is an error naming the
/// duration, the last frame and the bound, where it used to allocate and run for hours.
#[test]
fn replay_bounds_the_frame_count_before_allocating() {
    let mut cfg = track_config("track", 1);
    cfg.sim.dt = 1e-3;
    cfg.sim.decimation = 1;
    cfg.validate().expect("a 1 ms step is a valid config");
    let mut traj = reference();
    traj.frames.truncate(2);
    traj.frames[1].t = 3600.0;
    let e = format!("{:#}", replay(&cfg, &traj, false, None).unwrap_err());
    assert!(e.contains("3600 s") && e.contains("frame 1") && e.contains("MAX_REF_FRAMES") && !e.contains('\n'), "{e}");
    // the bank says the same for training
    let e = format!("{:#}", dextrain::task::bank::RefBank::build(&[traj], &SimModel::from_config(&cfg).unwrap(), 0).unwrap_err());
    assert!(e.contains("expected at most"), "{e}");
}
