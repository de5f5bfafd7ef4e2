//! Online DAgger (`train.algorithm = "distill"`): the student's history windows, its copy of the
//! teacher's actor, one update lowering both losses, λ1 = 0 leaving the actor alone, an exact
//! resume, one-line errors for a missing teacher or one of another task, and the wgpu learner
//! distilling as the CPU one does.

use std::path::{Path, PathBuf};

use burn::prelude::*;
use dextrain::config::{Config, DatasetMode};
use dextrain::env::SimModel;
use dextrain::learn::distill::Distill;
use dextrain::learn::nets::{mlp_forward, to_host, to_tensor};
use dextrain::task::{TaskBatch, make_task_batch};
use dextrain::train::{TrainArgs, run as train};

const CONFIG: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/configs/lift_cube_cpu.toml");

fn s(v: &[&str]) -> Vec<String> {
    v.iter().map(|x| x.to_string()).collect()
}

const TINY: [&str; 9] = ["sim.backend=cpu", "train.device=cpu", "sim.num_envs=8", "task.episode_length=6", "train.steps_per_env=4", "train.plot_interval=0", "policy.actor_hidden=[16]", "policy.critic_hidden=[16]", "randomization.object_mass=[0.5, 1.5]"];

/// A teacher with an encoder, trained 2 iterations into `runs/teacher`.
fn teacher(runs: &Path) -> PathBuf {
    let mut sets = s(&TINY);
    sets.extend(s(&["train.iterations=2", "policy.encoder.inputs=[\"obj_mass\", \"obj_vel\", \"tip_contact\"]", "policy.encoder.hidden=[8]", "policy.encoder.latent=3"]));
    train(&TrainArgs { config: Some(CONFIG.into()), sets, name: Some("teacher".into()), resume: None, force: false, runs_dir: runs.into(), stop_after: None, quiet: true, live: Default::default(), gpu_profile: false }).unwrap()
}

fn student_sets(teacher: &Path, extra: &[&str]) -> Vec<String> {
    let mut sets = s(&TINY);
    sets.extend(s(&["train.algorithm=\"distill\"", "distill.history_len=4", "distill.gru_hidden=8", "distill.beta_iterations=2", "distill.epochs=10", "distill.minibatches=1"]));
    sets.push(format!("distill.teacher=\"{}\"", teacher.display()));
    sets.extend(s(extra));
    sets
}

/// A distillation learner on a CPU task batch, and the batch.
fn learner(teacher: &Path, extra: &[&str]) -> (Config, Distill, Box<dyn TaskBatch>) {
    let cfg = Config::load_with_overrides(Path::new(CONFIG), &student_sets(teacher, extra)).unwrap();
    let model = SimModel::from_config(&cfg).unwrap();
    let task = make_task_batch(&cfg, model).unwrap();
    let d = Distill::new(&cfg, task.spec(), 8, Device::flex().autodiff()).unwrap();
    (cfg, d, task)
}

/// Steps the batch 4 times from `first` with the learner acting, then updates twice on that same
/// data (`dataset = "aggregate"` keeps it) and checks that both losses drop.
fn two_updates_lower_both_losses(d: &mut Distill, task: &mut dyn TaskBatch, first: &dextrain::task::StepBatch) {
    let mut obs = (first.obs.clone(), first.priv_obs.clone());
    for _ in 0..4 {
        let a = d.act(&obs.0, &obs.1).unwrap();
        let st = task.step(&a).unwrap();
        d.observe(&st.reward, &st.terminated, &st.time_out, &st.success);
        obs = (st.obs.clone(), st.priv_obs.clone());
    }
    let before = d.update().unwrap();
    let after = d.update().unwrap();
    assert!(after[0] < before[0] && after[1] < before[1], "losses before {:?} after {:?}", &before[..2], &after[..2]);
}

#[test]
fn the_history_window_holds_the_last_h_steps_and_restarts_with_each_episode() {
    let tmp = tempfile::tempdir().unwrap();
    let t = teacher(tmp.path());
    let (_, mut d, mut task) = learner(&t, &[]);
    let spec = task.spec().clone();
    let first = task.reset_all().unwrap().clone();
    let (o, p, n) = (spec.obs_dim, spec.priv_dim, 8);
    let (h, dd) = (d.student.history_len, d.student.step_dim);
    assert_eq!((h, dd), (4, 16 + 22));
    // observations whose first history entry (q of the first joint) is the step number
    let q0 = d.hist_index[0];
    let frame = |k: f32| {
        let mut x = first.obs.clone();
        for i in 0..n {
            x[i * o + q0] = k;
        }
        x
    };
    let (tn, on) = (d.teacher.ppo.obs_norm.clone(), d.teacher.ppo.normalize);
    // the teacher's normalisation of one value of that entry
    let norm = |v: f32| {
        let mut x = vec![0.0f32; o];
        x[q0] = v;
        if on {
            tn.apply(&mut x);
        }
        x[q0]
    };
    let window = |d: &Distill, env: usize| (0..h).map(|r| d.history[(env * h + r) * dd]).collect::<Vec<f32>>();
    d.act(&frame(0.0), &first.priv_obs).unwrap();
    assert_eq!(window(&d, 3), vec![norm(0.0); 4], "episode start: the first frame repeated H times");
    for k in 1..6 {
        d.act(&frame(k as f32), &first.priv_obs).unwrap();
        d.observe(&[0.0; 8], &[false; 8], &[false; 8], &[false; 8]);
    }
    assert_eq!(window(&d, 3), [2.0, 3.0, 4.0, 5.0].map(norm).to_vec(), "the last H steps, oldest first");
    // env 0's episode ends: its next window is its new first frame repeated; env 1's shifts on
    let mut term = [false; 8];
    term[0] = true;
    d.observe(&[1.0; 8], &term, &[false; 8], &[true; 8]);
    d.act(&frame(9.0), &vec![0.0; n * p]).unwrap();
    assert_eq!(window(&d, 0), vec![norm(9.0); 4]);
    assert_eq!(window(&d, 1), [3.0, 4.0, 5.0, 9.0].map(norm).to_vec());
}

#[test]
fn the_student_copies_the_teachers_actor_and_one_update_lowers_both_losses() {
    let tmp = tempfile::tempdir().unwrap();
    let t = teacher(tmp.path());
    let (_, mut d, mut task) = learner(&t, &["distill.dataset=\"aggregate\"", "distill.max_rollouts=8"]);
    let spec = task.spec().clone();
    let b = task.reset_all().unwrap().clone();
    // the student's actor fed the teacher's latent ẑ instead of z gives the teacher's actions
    let (obs_n, priv_n) = {
        let (mut o, mut p) = (b.obs.clone(), b.priv_obs.clone());
        if d.teacher.ppo.normalize {
            d.teacher.ppo.obs_norm.apply(&mut o);
            d.teacher.ppo.priv_norm.apply(&mut p);
        }
        (o, p)
    };
    let dev = d.device.clone();
    let tp = d.teacher.ppo.net.inference_params();
    let c = to_tensor(priv_n.clone(), [8, spec.priv_dim], &dev);
    let z_hat = d.teacher.ppo.net.latent(&tp, c).unwrap();
    let x = Tensor::cat(vec![to_tensor(obs_n.clone(), [8, spec.obs_dim], &dev), z_hat], 1);
    let sp: Vec<_> = d.student.params[d.student.n_adapt..].iter().map(|p| p.clone().inner()).collect();
    let mine = to_host(mlp_forward(&sp, x, d.student.activation)).unwrap();
    let teachers = d.teacher.ppo.act_mean(&b.obs, &b.priv_obs).unwrap();
    assert_eq!(mine, teachers, "with ẑ the student's actor is the teacher's");
    // one rollout, then two updates on that same data (aggregate keeps it): both losses drop
    two_updates_lower_both_losses(&mut d, task.as_mut(), &b);
    assert_eq!(d.cfg.dataset, DatasetMode::Aggregate);
}

#[test]
fn with_no_action_loss_only_the_adaptation_module_learns() {
    let tmp = tempfile::tempdir().unwrap();
    let t = teacher(tmp.path());
    let (_, mut d, mut task) = learner(&t, &["distill.lambda_action=0"]);
    let b = task.reset_all().unwrap().clone();
    let before = d.student.values().unwrap();
    let mut obs = (b.obs.clone(), b.priv_obs.clone());
    for _ in 0..4 {
        let a = d.act(&obs.0, &obs.1).unwrap();
        let st = task.step(&a).unwrap();
        d.observe(&st.reward, &st.terminated, &st.time_out, &st.success);
        obs = (st.obs.clone(), st.priv_obs.clone());
    }
    d.update().unwrap();
    let after = d.student.values().unwrap();
    let k = d.student.n_adapt;
    assert!(before[..k].iter().zip(&after[..k]).any(|(x, y)| x != y), "the GRU and head learn");
    assert_eq!(before[k..], after[k..], "the actor is untouched bit for bit");
}

#[test]
fn a_distillation_run_resumes_exactly_and_bad_teachers_are_one_line_errors() {
    let tmp = tempfile::tempdir().unwrap();
    let t = teacher(tmp.path());
    let args = |name: &str| TrainArgs {
        config: Some(CONFIG.into()),
        sets: student_sets(&t, &["train.iterations=4", "train.save_interval=2", "distill.eval_interval=2", "distill.eval_episodes=4"]),
        name: Some(name.into()),
        resume: None,
        force: false,
        runs_dir: tmp.path().into(),
        stop_after: None,
        quiet: true,
        live: Default::default(),
        gpu_profile: false,
    };
    let a = train(&args("a")).unwrap();
    let mut b_args = args("b");
    b_args.stop_after = Some(2);
    let b = train(&b_args).unwrap();
    train(&TrainArgs { config: None, sets: vec![], name: None, resume: Some(b.clone()), ..args("unused") }).unwrap();
    let (cols, ra) = dextrain::metrics::read_csv(&a.join("metrics.csv")).unwrap();
    let (_, rb) = dextrain::metrics::read_csv(&b.join("metrics.csv")).unwrap();
    let clock = ["time_s", "fps", "time/collect_s", "time/learn_s"];
    for (x, y) in ra.iter().zip(&rb) {
        for (k, c) in cols.iter().enumerate() {
            if !clock.contains(&c.as_str()) {
                assert_eq!(x.1[k].to_bits(), y.1[k].to_bits(), "{c} at iteration {}", x.0);
            }
        }
    }
    let col = |name: &str| cols.iter().position(|c| c == name).unwrap_or_else(|| panic!("column {name}"));
    let beta: Vec<f64> = ra.iter().map(|r| r.1[col("distill/beta")]).collect();
    assert_eq!(beta, [1.0, 0.5, 0.0, 0.0]);
    assert!(ra.iter().all(|r| r.1[col("loss/action")].is_finite() && r.1[col("loss/latent")].is_finite()));
    // the side-by-side evaluation every 2 iterations (resumed above bit for bit, the teacher's
    // episodes run again after the resume), nan between
    let evals = dextrain::run::distill::EVAL_COLUMNS;
    for r in &ra {
        assert!(evals.iter().all(|c| r.1[col(c)].is_finite() == (r.0 % 2 == 0)), "iteration {}: {:?}", r.0, evals.map(|c| r.1[col(c)]));
    }
    let student = |d: &Path| std::fs::read(d.join("checkpoints/4/model.safetensors")).unwrap();
    assert_eq!(student(&a), student(&b));
    let text = String::from_utf8_lossy(&student(&a)).into_owned();
    assert!(text.contains("teacher_manifest_xxh64") && text.contains(&t.display().to_string()), "the student names its teacher");
    // the student exported: obs (its fields) and history inputs, verified against burn on real episodes
    use dextrain::export::command::{ExportArgs, run as export};
    let r = export(&ExportArgs { run: a.clone(), checkpoint: "latest".into(), out: None, verify: true }).unwrap();
    assert!(r.max_abs_diff.unwrap() <= 1e-5, "{r:?}");
    let c = dextrain::export::contract::PolicyContract::read(&a.join("export/policy.json")).unwrap();
    assert_eq!(c.model.inputs.iter().map(|i| i.name.as_str()).collect::<Vec<_>>(), ["obs", "history"]);
    let h = c.history.as_ref().unwrap();
    assert_eq!((h.length, h.step.fields.iter().map(|f| f.name.as_str()).collect::<Vec<_>>()), (4, vec!["q", "prev_action"]));
    assert_eq!(c.source.teacher.as_ref().unwrap().checkpoint, 2);
    // played from the export alone (its history window kept by the controller): eval's episodes
    crate::play::play_equals_eval(&a, "student");
    // eval of the student beside its teacher on the same seeds: the teacher's side is exactly what
    // evaluating the teacher run itself gives
    use dextrain::eval::{Baseline, EvalArgs, run as eval};
    let e = |run: &Path, baseline: Option<Baseline>| EvalArgs { run: run.into(), checkpoint: "latest".into(), episodes: 4, max_envs: 4, seed: Some(77), record: None, backend: None, baseline, video: Default::default(), live: Default::default() };
    let r = eval(&e(&a, Some(Baseline::Teacher))).unwrap();
    assert_eq!(r.baseline_kind, "teacher");
    // the student's latent against its teacher's on the same states: measured, and only for it
    let le = r.policy.latent_error.as_ref().expect("a latent error for the student");
    assert!(le.mean.is_finite() && le.mean > 0.0, "{le:?}");
    assert!(r.baseline.as_ref().unwrap().latent_error.is_none());
    assert_eq!(r.policy.per_episode.len(), 4);
    let teacher_alone = eval(&e(&t, None)).unwrap();
    let returns = |s: &dextrain::eval::Summary| s.per_episode.iter().map(|e| e.ret.to_bits()).collect::<Vec<_>>();
    assert_eq!(returns(r.baseline.as_ref().unwrap()), returns(&teacher_alone.policy));
    assert!(r.path.to_string_lossy().ends_with("_teacher.json"));
    let md = std::fs::read_to_string(r.path.with_extension("md")).unwrap();
    assert!(md.contains("teacher") && md.contains("latent error"), "{md}");
    // the run's side-by-side row at iteration 4 is `dextrain eval --baseline teacher` of checkpoint 4
    // on eval's default seeds: the same episodes, bit for bit
    let r4 = eval(&EvalArgs { seed: None, ..e(&a, Some(Baseline::Teacher)) }).unwrap();
    let (b4, row) = (r4.baseline.as_ref().unwrap(), &ra[3].1);
    let got = evals.map(|c| row[col(c)].to_bits());
    let want = [r4.policy.success_rate, b4.success_rate, r4.policy.episode_return.mean, b4.episode_return.mean, r4.policy.latent_error.as_ref().unwrap().mean].map(f64::to_bits);
    assert_eq!(got, want, "the run's row {:?} vs eval's", evals.map(|c| row[col(c)]));
    let err = format!("{:#}", eval(&e(&t, Some(Baseline::Teacher))).unwrap_err());
    assert!(err.contains("not a distilled student") && !err.contains('\n'), "{err}");
    // a teacher that does not exist, and one of another task
    let mut bad = args("c");
    bad.sets.push(format!("distill.teacher=\"{}\"", tmp.path().join("nobody").display()));
    let e = format!("{:#}", train(&bad).unwrap_err());
    assert!(e.contains("distill.teacher") && e.contains("nobody") && !e.contains('\n'), "{e}");
    let other = Config::load_with_overrides(Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/configs/residual_task_cube.toml")), &student_sets(&t, &[])).unwrap();
    let model = SimModel::from_config(&other).unwrap();
    let task = make_task_batch(&other, model).unwrap();
    let e = format!("{:#}", Distill::new(&other, task.spec(), 8, Device::flex().autodiff()).err().unwrap());
    assert!(e.contains("residual_task_cube.toml") && e.contains("teacher") && e.contains("config.toml") && !e.contains('\n'), "{e}");
}

/// Distillation on burn's wgpu learner (lavapipe in CI) acts and updates as on the CPU learner: the
/// same teacher labels, the same executed actions, the same losses and updated student to float
/// rounding.
#[test]
fn the_wgpu_learner_distills_as_the_cpu_learner_does() {
    let Some((_ctx, gpu_dev)) = crate::common::wgpu_learner("the_wgpu_learner_distills_as_the_cpu_learner_does") else { return };
    let tmp = tempfile::tempdir().unwrap();
    let t = teacher(tmp.path());
    // β = 0.5: some envs driven by the teacher, some by the student
    let (cfg, mut cpu, mut task) = learner(&t, &["distill.beta_start=0.5", "distill.epochs=2"]);
    let mut gpu = Distill::new(&cfg, task.spec(), 8, gpu_dev).unwrap();
    assert_eq!(cpu.teacher_drives, gpu.teacher_drives);
    assert!(cpu.teacher_drives.iter().any(|&d| d) && cpu.teacher_drives.iter().any(|&d| !d), "{:?}", cpu.teacher_drives);
    let b = task.reset_all().unwrap().clone();
    let mut obs = (b.obs.clone(), b.priv_obs.clone());
    for _ in 0..4 {
        let a = cpu.act(&obs.0, &obs.1).unwrap();
        let g = gpu.act(&obs.0, &obs.1).unwrap();
        for (x, y) in a.iter().zip(&g) {
            assert!((x - y).abs() < 1e-4, "executed actions differ: {x} vs {y}");
        }
        let st = task.step(&a).unwrap();
        cpu.observe(&st.reward, &st.terminated, &st.time_out, &st.success);
        gpu.observe(&st.reward, &st.terminated, &st.time_out, &st.success);
        obs = (st.obs.clone(), st.priv_obs.clone());
    }
    let fresh = cpu.student.values().unwrap();
    let (s_cpu, s_gpu) = (cpu.update().unwrap(), gpu.update().unwrap());
    for k in 0..2 {
        assert!((s_cpu[k] - s_gpu[k]).abs() < 1e-3 * (1e-3 + s_cpu[k].abs()), "loss {k}: {} vs {}", s_cpu[k], s_gpu[k]);
    }
    let (p_cpu, p_gpu) = (cpu.student.values().unwrap(), gpu.student.values().unwrap());
    let worst = p_cpu.iter().flatten().zip(p_gpu.iter().flatten()).map(|(x, y)| (x - y).abs()).fold(0.0f32, f32::max);
    assert!(worst < 1e-4, "students after one update differ by {worst}");
    let moved = fresh.iter().flatten().zip(p_cpu.iter().flatten()).map(|(x, y)| (x - y).abs()).fold(0.0f32, f32::max);
    assert!(moved > 1e-4, "the update moved the student ({moved})");
}

/// The temporal-convolution student (`distill.adaptation = "tcn"`): one DAgger update lowers both
/// losses; a run's checkpoint holds the TCN, its export (Conv nodes) matches burn on real
/// episodes and plays as eval does; convolutions longer than the window are a one-line error.
#[test]
fn a_tcn_student_learns_exports_and_plays() {
    let tmp = tempfile::tempdir().unwrap();
    let t = teacher(tmp.path());
    // H = 4: a kernel of 2 at stride 2 leaves 2 steps, a kernel of 2 at stride 1 one step
    let tcn = ["distill.adaptation=\"tcn\"", "distill.tcn_channels=6", "distill.tcn_layers=[[2, 2], [2, 1]]"];
    let mut extra = tcn.to_vec();
    extra.extend(["distill.dataset=\"aggregate\"", "distill.max_rollouts=8"]);
    let (_, mut d, mut task) = learner(&t, &extra);
    assert!(d.student.names.iter().any(|n| n == "tcn.conv.1.weight") && !d.student.names.iter().any(|n| n.starts_with("gru")), "{:?}", d.student.names);
    let b = task.reset_all().unwrap().clone();
    two_updates_lower_both_losses(&mut d, task.as_mut(), &b);
    let mut sets = student_sets(&t, &tcn);
    sets.push("train.iterations=2".into());
    let run = train(&TrainArgs { config: Some(CONFIG.into()), sets, name: Some("tcn".into()), resume: None, force: false, runs_dir: tmp.path().into(), stop_after: None, quiet: true, live: Default::default(), gpu_profile: false }).unwrap();
    // read back from the checkpoint: the TCN with its convolutions, and the same parameters
    let back = dextrain::learn::distill::StudentPolicy::load(&run.join("checkpoints/2"), task.spec().obs_dim, &Device::flex()).unwrap();
    assert_eq!(back.student.adaptation, dextrain::learn::distill::Adaptation::Tcn { convs: vec![(2, 2), (2, 1)] });
    assert_eq!(back.student.names.iter().filter(|n| n.starts_with("tcn.")).count(), 8);
    use dextrain::export::command::{ExportArgs, run as export};
    let r = export(&ExportArgs { run: run.clone(), checkpoint: "latest".into(), out: None, verify: true }).unwrap();
    assert!(r.max_abs_diff.unwrap() <= 1e-5, "{r:?}");
    crate::play::play_equals_eval(&run, "tcn student");
    let long = Config::load_with_overrides(Path::new(CONFIG), &student_sets(&t, &["distill.adaptation=\"tcn\"", "distill.tcn_layers=[[3, 1], [3, 1]]"]));
    let e = format!("{:#}", long.unwrap_err());
    assert!(e.contains("distill.tcn_layers") && e.contains("history_len = 4") && !e.contains('\n'), "{e}");
}
