//! Training runs end to end on the CPU with the shipped lift config shrunk by `--set`: the same seed
//! gives the same metrics, an interrupted and resumed run continues exactly, metrics.csv and the
//! TensorBoard events agree, eval writes its report and recording, and bad runs, names and
//! checkpoints are one-line errors; `--force` replaces only runs; checkpoints keep floats exactly and
//! a damaged, edited or incomplete checkpoint is skipped (latest) or refused (by number).


use std::path::{Path, PathBuf};

use dextrain::learn::checkpoint::{self, CheckpointState, EnvSnapshot, xxh64};
use dextrain::eval::{EvalArgs, run as eval};
use dextrain::learn::state::{LearnerState, TensorValues};
use dextrain::metrics::{event_files, read_csv};
use dextrain::run::{TrainArgs, train};
use dextrain::tensorboard::read_scalars;

const CONFIG: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/configs/lift_cube_cpu.toml");
/// Wall-clock columns: they differ between any two runs.
const CLOCK: [&str; 4] = ["time_s", "fps", "time/collect_s", "time/learn_s"];

fn tiny_sets() -> Vec<String> {
    [
        "sim.backend=cpu",
        "train.device=cpu",
        "sim.num_envs=8",
        "task.episode_length=5",
        "train.iterations=4",
        "train.steps_per_env=4",
        "train.save_interval=2",
        "train.plot_interval=0",
        "policy.actor_hidden=[32, 16]",
        "policy.critic_hidden=[32, 16]",
        "task.obs_noise.object_pos=0.002",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect()
}

fn args(runs: &Path, name: &str) -> TrainArgs {
    TrainArgs {
        config: Some(CONFIG.into()),
        sets: tiny_sets(),
        name: Some(name.into()),
        resume: None,
        force: false,
        runs_dir: runs.to_path_buf(),
        stop_after: None,
        quiet: true,
        live: Default::default(),
        gpu_profile: false,
    }
}

/// metrics.csv without the wall-clock columns and the GPU counts (`gpu/*`: cubecl batches its
/// submissions by what the process did before, and a resumed run's first iteration may launch a
/// kernel or two more; the device-resident tests check the counts on their own).
fn metrics(dir: &Path) -> (Vec<String>, Vec<(u64, Vec<f64>)>) {
    let (cols, rows) = read_csv(&dir.join("metrics.csv")).expect("metrics.csv");
    let keep: Vec<usize> = (0..cols.len()).filter(|&i| !CLOCK.contains(&cols[i].as_str()) && !cols[i].starts_with("gpu/")).collect();
    let names = keep.iter().map(|&i| cols[i].clone()).collect();
    let rows = rows.into_iter().map(|(it, v)| (it, keep.iter().map(|&i| v[i]).collect::<Vec<f64>>())).collect();
    (names, rows)
}

fn same_bits(a: &[(u64, Vec<f64>)], b: &[(u64, Vec<f64>)]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.0 == y.0 && x.1.iter().zip(&y.1).all(|(p, q)| p.to_bits() == q.to_bits()))
}

fn model_bytes(dir: &Path, it: u64) -> Vec<u8> {
    std::fs::read(dir.join(format!("checkpoints/{it}/model.safetensors"))).expect("model")
}

#[test]
fn same_seed_is_identical_and_resume_continues_exactly() {
    let tmp = tempfile::tempdir().unwrap();
    let runs = tmp.path();
    let a = train(&args(runs, "a")).expect("run a");
    let c = train(&args(runs, "c")).expect("run c");
    // b: stopped after 2 iterations (with a checkpoint), then resumed
    let mut b_args = args(runs, "b");
    b_args.stop_after = Some(2);
    let b = train(&b_args).expect("run b, first half");
    assert_eq!(metrics(&b).1.len(), 2);
    let resume = TrainArgs { config: None, sets: vec![], name: None, resume: Some(b.clone()), ..args(runs, "unused") };
    train(&resume).expect("run b, resumed");

    let (cols, ma) = metrics(&a);
    assert!(cols.contains(&"reward/reaching".to_string()) && cols.contains(&"loss/value".to_string()), "{cols:?}");
    assert_eq!(ma.len(), 4);
    assert!(ma.iter().any(|(_, v)| v[cols.iter().position(|c| c == "episode/count").unwrap()] > 0.0), "episodes must end in the test");
    assert!(same_bits(&ma, &metrics(&c).1), "same seed, different metrics.csv");
    assert!(same_bits(&ma, &metrics(&b).1), "resumed run differs from the straight run:\n{:?}\n{:?}", ma, metrics(&b).1);
    assert_eq!(model_bytes(&a, 4), model_bytes(&c, 4));
    assert_eq!(model_bytes(&a, 4), model_bytes(&b, 4), "final model differs after resume");
    // a different seed gives different numbers
    let mut d_args = args(runs, "d");
    d_args.sets.push("seed=5".into());
    let d = train(&d_args).expect("run d");
    assert!(!same_bits(&ma, &metrics(&d).1));

    // resuming a finished run is an error that says how to go on; --set train.iterations extends it
    let err = train(&TrainArgs { resume: Some(a.clone()), ..resume.clone() }).unwrap_err().to_string();
    assert!(err.contains("train.iterations"), "{err}");
    let err = train(&TrainArgs { resume: Some(a.clone()), sets: vec!["sim.num_envs=4".into()], ..resume.clone() }).unwrap_err().to_string();
    assert!(err.contains("only train.* keys"), "{err}");
    train(&TrainArgs { resume: Some(a.clone()), sets: vec!["train.iterations=5".into()], ..resume.clone() }).expect("extend");
    assert_eq!(metrics(&a).1.len(), 5);
    assert!(std::fs::read_to_string(a.join("config.toml")).unwrap().contains("iterations = 5"));
}

#[test]
fn metrics_tensorboard_plots_and_eval_agree_with_the_run() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = train(&args(tmp.path(), "run")).expect("train");
    for f in ["config.toml", "metrics.csv", "plots/learning_curves.png", "checkpoints/2/state.json", "checkpoints/4/optimizer.safetensors", "checkpoints/4/env.safetensors"] {
        assert!(dir.join(f).is_file(), "missing {f}");
    }
    // the saved config is the exact resolved one: it loads and has the overrides
    let saved = dextrain::config::Config::load(&dir.join("config.toml")).expect("saved config loads");
    assert_eq!(saved.sim.num_envs, 8);
    assert_eq!(saved.policy.actor_hidden, vec![32, 16]);
    // TensorBoard holds the same scalars as metrics.csv
    let (cols, rows) = read_csv(&dir.join("metrics.csv")).unwrap();
    let events = event_files(&dir).unwrap();
    assert_eq!(events.len(), 1);
    let scalars = read_scalars(&events[0]).unwrap();
    let k = cols.iter().position(|c| c == "reward/mean").unwrap();
    for (it, v) in &rows {
        let tb = scalars.iter().find(|(tag, step, _)| tag == "reward/mean" && *step == *it as i64).expect("scalar in TensorBoard");
        assert_eq!(tb.2, v[k] as f32);
    }

    let rec = tmp.path().join("eval.mcap");
    let eargs = EvalArgs { run: dir.clone(), checkpoint: "latest".into(), episodes: 5, max_envs: 3, seed: None, record: Some(rec.clone()), backend: None, baseline: None, video: Default::default(), live: Default::default() };
    let r = eval(&eargs).expect("eval");
    assert_eq!(r.episodes, 5);
    assert_eq!(r.iteration, 4);
    assert!((0.0..=1.0).contains(&r.policy.success_rate));
    assert!(r.policy.episode_length.mean >= 1.0 && r.policy.episode_length.mean <= 5.0, "{:?}", r.policy.episode_length);
    assert!(r.policy.reward_terms.contains_key("reaching"));
    assert_eq!(r.policy.per_episode.len(), 5);
    assert!(r.path.is_file());
    let json: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&r.path).unwrap()).unwrap();
    assert_eq!(json["episodes"], 5);
    let bytes = std::fs::read(&rec).unwrap();
    assert!(bytes.starts_with(b"\x89MCAP0\r\n") && bytes.len() > 1000, "recording");
    // deterministic: the same eval twice gives the same report
    let r2 = eval(&EvalArgs { record: None, ..eargs.clone() }).unwrap();
    assert_eq!(r2.policy.episode_return, r.policy.episode_return);
    // another checkpoint and fresh seeds give another report
    let r3 = eval(&EvalArgs { checkpoint: "2".into(), record: None, ..eargs.clone() }).unwrap();
    assert_eq!(r3.iteration, 2);
}

/// A SAC run (`train.algorithm = "sac"`) on the lift task: metrics with SAC's columns, the same
/// seed gives the same run, an interrupted and resumed run continues exactly (the replay buffer is
/// in the checkpoint), eval runs its policy; impossible settings are one-line errors before a run
/// directory is made.
#[test]
fn sac_runs_resume_exactly_and_evaluate() {
    let tmp = tempfile::tempdir().unwrap();
    let runs = tmp.path();
    let sac = |name: &str| {
        let mut a = args(runs, name);
        a.sets.extend(["train.algorithm=\"sac\"", "sac.batch_size=32", "sac.learning_starts=3", "sac.random_steps=2", "sac.buffer_capacity=6", "sac.n_step=2", "sac.updates_per_step=2"].iter().map(|s| s.to_string()));
        a
    };
    let a = train(&sac("a")).expect("sac run a");
    let mut b_args = sac("b");
    b_args.stop_after = Some(2);
    let b = train(&b_args).expect("sac run b, first half");
    assert!(b.join("checkpoints/2/replay.safetensors").is_file(), "the checkpoint holds the replay buffer");
    train(&TrainArgs { config: None, sets: vec![], name: None, resume: Some(b.clone()), ..args(runs, "unused") }).expect("sac run b, resumed");
    let (cols, ma) = metrics(&a);
    for c in ["loss/critic", "loss/actor", "alpha", "policy/entropy", "q/mean", "updates", "buffer/transitions"] {
        assert!(cols.contains(&c.to_string()), "no column {c}: {cols:?}");
    }
    let col = |name: &str| cols.iter().position(|c| c == name).unwrap();
    // 4 env steps per iteration, gradient steps from the 3rd on, 2 per env step; the 6-slot rings fill
    let updates: Vec<f64> = ma.iter().map(|(_, v)| v[col("updates")]).collect();
    assert_eq!(updates, vec![4.0, 8.0, 8.0, 8.0]);
    assert_eq!(ma.last().unwrap().1[col("buffer/transitions")], 48.0);
    assert!(ma.iter().all(|(_, v)| v[col("loss/critic")].is_finite() && v[col("alpha")] > 0.0));
    assert!(same_bits(&ma, &metrics(&b).1), "the resumed SAC run differs from the straight run");
    assert_eq!(model_bytes(&a, 4), model_bytes(&b, 4), "final model differs after resume");
    assert!(same_bits(&ma, &metrics(&train(&sac("c")).expect("sac run c")).1), "same seed, different run");
    let e = EvalArgs { run: a.clone(), checkpoint: "latest".into(), episodes: 3, max_envs: 3, seed: None, record: None, backend: None, baseline: None, video: Default::default(), live: Default::default() };
    let r = eval(&e).expect("eval of a SAC run");
    assert_eq!((r.episodes, r.iteration), (3, 4));
    // a SAC run of a reference kind beside open-loop replay (the baseline's episodes load the run's
    // policy too; they used to refuse a SAC run as if it were a distillation teacher)
    let mut rj = sac("rj");
    rj.config = Some(concat!(env!("CARGO_MANIFEST_DIR"), "/configs/residual_joint_sac.toml").into());
    rj.sets.extend(["task.reference.files=[\"refs/perturbed/ref_000.mcap\"]", "task.episode_length=6", "train.iterations=2"].iter().map(|s| s.to_string()));
    let rj = train(&rj).expect("residual_joint SAC run");
    let r = eval(&EvalArgs { run: rj, baseline: Some(dextrain::eval::Baseline::OpenLoop), ..e.clone() }).expect("eval of a SAC run with the open-loop baseline");
    assert_eq!(r.baseline.expect("an open-loop summary").per_episode.len(), 3);
    // bad input: one line, naming the key, and no run directory
    for (set, key) in [("sac.updates_per_step=0", "sac.updates_per_step"), ("sac.buffer_capacity=1099511627776", "sac.buffer_capacity"), ("sac.buffer_capacity=4000000000", "sac.buffer_capacity"), ("train.algorithm=\"sacc\"", "train.algorithm")] {
        let mut x = sac("bad");
        x.sets.push(set.into());
        let err = format!("{:#}", train(&x).unwrap_err());
        assert!(err.contains(key) && !err.contains('\n'), "{set}: {err}");
        assert!(!runs.join("bad").exists(), "{set}: no run directory for a bad config");
    }
}

#[test]
fn bad_names_existing_runs_and_broken_checkpoints_are_one_line_errors() {
    let tmp = tempfile::tempdir().unwrap();
    let runs = tmp.path();
    for bad in ["../escape", "a/b", "..", ""] {
        let err = train(&args(runs, bad)).unwrap_err().to_string();
        assert!(err.contains("--name") && !err.contains('\n'), "{bad}: {err}");
    }
    assert!(!runs.join("escape").exists() && !tmp.path().parent().unwrap().join("escape").exists());
    let dir = train(&args(runs, "r")).expect("train");
    let err = train(&args(runs, "r")).unwrap_err().to_string();
    assert!(err.contains("exists") && err.contains("--force"), "{err}");
    let mut force = args(runs, "r");
    force.force = true;
    force.sets.push("train.iterations=2".into());
    train(&force).expect("--force replaces the run");
    assert_eq!(metrics(&dir).1.len(), 2);

    // a bad config key names the file and the key
    let mut bad = args(runs, "x");
    bad.sets.push("task.rewards.flying=1.0".into());
    let err = train(&bad).unwrap_err().to_string();
    assert!(err.contains("lift_cube_cpu.toml") && err.contains("task.rewards.flying"), "{err}");
    assert!(!runs.join("x").exists(), "no run directory for a bad config");

    // a missing checkpoint iteration lists the ones there are
    let e = EvalArgs { run: dir.clone(), checkpoint: "7".into(), episodes: 2, max_envs: 2, seed: None, record: None, backend: None, baseline: None, video: Default::default(), live: Default::default() };
    let err = eval(&e).unwrap_err().to_string();
    assert!(err.contains("iteration 7") && err.contains("have: 2"), "{err}");
    // a truncated model file names the file
    let model: PathBuf = dir.join("checkpoints/2/model.safetensors");
    let bytes = std::fs::read(&model).unwrap();
    std::fs::write(&model, &bytes[..bytes.len() / 2]).unwrap();
    let err = format!("{:#}", eval(&EvalArgs { checkpoint: "2".into(), ..e.clone() }).unwrap_err());
    assert!(err.contains("model.safetensors") && !err.contains('\n'), "{err}");
    let err = format!("{:#}", train(&TrainArgs { config: None, sets: vec![], name: None, resume: Some(dir.clone()), ..args(runs, "u") }).unwrap_err());
    assert!(err.contains("model.safetensors") || err.contains("train.iterations"), "{err}");
    // not a run directory
    let err = eval(&EvalArgs { run: tmp.path().join("nope"), ..e }).unwrap_err().to_string();
    assert!(err.contains("not a run directory"), "{err}");
}

/// The whole loop on a GPU adapter (lavapipe in CI): the envs and burn's wgpu learner share one
/// wgpu device.
/// - The device-resident rollouts (the default there) give the host path's run to float rounding:
///   every metric and every policy value;
/// - their host traffic per iteration is exactly what the README says (no observation bytes: the
///   kernels' parameters, the metrics' sums, the minibatch indices, the learning rate and the
///   update's one read), where the host path moves every step's observations;
/// - a device-resident run stopped and resumed continues bit for bit (whole-tensor sums on the GPU
///   are `nets::sum_all`'s fixed reductions, not burn's atomic ones), and its policy evaluates.
#[test]
fn training_runs_with_env_and_learner_on_one_gpu_device() {
    let Some(ctx) = crate::common::gpu_context("training_runs_with_env_and_learner_on_one_gpu_device") else { return };
    let adapter = format!("gpu:{}", ctx.info.name.split_whitespace().next().unwrap_or("llvmpipe"));
    drop(ctx);
    let tmp = tempfile::tempdir().unwrap();
    let gpu_args = |name: &str, extra: &[&str]| gpu_run_args(tmp.path(), name, &adapter, 2, extra);
    // the two paths compared under a fixed learning rate: the adaptive schedule turns a float
    // rounding of a minibatch's KL at its thresholds into a factor 1.5 (the adaptive runs below
    // are compared bit for bit with each other)
    let fixed = "ppo.schedule=\"fixed\"";
    let host = train(&gpu_args("host", &["train.device_rollouts=false", fixed])).expect("train on the GPU, host path");
    let dev = train(&gpu_args("dev", &[fixed])).expect("train on the GPU, device-resident");
    let adaptive = train(&gpu_args("adaptive", &[])).expect("train on the GPU, device-resident, adaptive learning rate");
    let mut profiled_args = gpu_args("profiled", &[]);
    profiled_args.gpu_profile = true;
    let profiled = train(&profiled_args).expect("train on the GPU, device-resident, profiled");
    let mut half = gpu_args("half", &[]);
    half.stop_after = Some(1);
    let resumed = train(&half).expect("first half");
    train(&TrainArgs { config: None, sets: vec![], name: None, resume: Some(resumed.clone()), ..args(tmp.path(), "unused") }).expect("resumed");

    let (cols, rows_host) = metrics(&host);
    let (_, rows_dev) = metrics(&dev);
    assert_eq!((rows_host.len(), rows_dev.len()), (2, 2));
    let bytes = cols.iter().position(|c| c == "time/host_bytes").unwrap();
    assert_rows_close(&cols, &rows_host, &rows_dev, bytes, "host path vs device-resident");
    assert_policies_close(&host, &dev, 2);
    // host traffic per iteration (the config's: 8 envs, 4 steps, obs O + P, 22 actions, PPO's defaults)
    let cfg = dextrain::config::Config::load(&dev.join("config.toml")).unwrap();
    let [o, p, a] = dims(&dev);
    let (n, t) = (8u64, 4u64);
    let (epochs, minibatches) = (cfg.ppo.epochs as u64, cfg.ppo.minibatches as u64);
    let misc = dextrain::task::task::OUT_MISC as u64;
    let expected = 32 // the noise kernel's parameters (one kernel draws the rollout's noise)
        + (2 * misc + 4) * 4 // the iteration's sums
        + epochs * n * t * 4 // the minibatch indices (i32, one upload)
        + 4 // the learning rate up
        + (1 + 6 * epochs * minibatches + a as u64) * 4; // the update's one read: learning rate, each minibatch's losses, KL and gradient norm, log σ
    for (_, d) in &rows_dev {
        assert_eq!(d[bytes], expected as f64, "host bytes of a device-resident iteration");
        assert!(d[bytes] < (n * (o + p) as u64 * 4) as f64, "less than one step's observations");
    }
    for (_, h) in &rows_host {
        assert!(h[bytes] >= (t * n * (o + p) as u64 * 4) as f64, "the host path reads every step's observations: {}", h[bytes]);
    }
    // stopped and resumed: the same run, bit for bit (host bytes included)
    let rows_adaptive = metrics(&adaptive).1;
    assert!(same_bits(&rows_adaptive, &metrics(&resumed).1), "the resumed device-resident run differs:\n{rows_adaptive:?}\n{:?}", metrics(&resumed).1);
    assert_eq!(model_bytes(&adaptive, 2), model_bytes(&resumed, 2), "final model differs after resume");
    // `--gpu-profile` (docs/gpu.md "Where a GPU's time goes"): the same run to the bit (its stamps
    // and reads move no value; the host bytes are not compared), and a profile of every kernel and
    // bracket of the learner's work, each stamped as often as it ran
    let (_, rows_profiled) = metrics(&profiled);
    let without_bytes = |rows: &[(u64, Vec<f64>)]| rows.iter().map(|(it, v)| (*it, v.iter().enumerate().filter(|&(i, _)| i != bytes).map(|(_, x)| *x).collect())).collect::<Vec<(u64, Vec<f64>)>>();
    assert!(same_bits(&without_bytes(&rows_adaptive), &without_bytes(&rows_profiled)), "the profiled run differs:\n{rows_adaptive:?}\n{rows_profiled:?}");
    assert_eq!(model_bytes(&adaptive, 2), model_bytes(&profiled, 2), "the profiled run's model differs");
    assert!(!adaptive.join("gpu_profile.json").exists(), "a profile without --gpu-profile");
    let profile: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(profiled.join("gpu_profile.json")).expect("gpu_profile.json")).unwrap();
    let spans = profile["spans"].as_array().expect("spans");
    let span = |name: &str| spans.iter().find(|s| s["name"] == name).unwrap_or_else(|| panic!("no span {name} in {profile}"));
    let calls = |name: &str| span(name)["calls"].as_u64().unwrap();
    let (iterations, steps) = (2, t);
    for name in ["kernel:step_main", "kernel:task_act", "kernel:task_reward", "burn:act", "burn:observe"] {
        assert_eq!(calls(name), iterations * steps, "{name}: {profile}");
    }
    let optimiser_steps = iterations * epochs * minibatches;
    assert_eq!((calls("burn:update"), calls("burn:adam")), (iterations, optimiser_steps), "{profile}");
    assert_eq!((calls("burn:ppo forward and loss"), calls("burn:ppo backward")), (optimiser_steps, optimiser_steps), "{profile}");
    assert_eq!(profile["dropped_spans"], 0, "{profile}");
    for s in spans {
        assert!(s["total_ms"].as_f64().unwrap() > 0.0 && s["max_us"].as_f64().unwrap() * 1e-3 <= s["total_ms"].as_f64().unwrap(), "{s}");
    }
    // the spans follow one another on the queue (those inside others aside: the optimiser's and
    // the minibatches' passes inside the update, the rollout's noise inside acting): their device
    // time is within the loop's wall time
    let nested = ["burn:adam", "kernel:learner_noise", "burn:ppo forward and loss", "burn:ppo backward"];
    let device_ms: f64 = spans.iter().filter(|s| !nested.iter().any(|n| s["name"] == *n)).map(|s| s["total_ms"].as_f64().unwrap()).sum();
    assert!(device_ms <= 1e3 * profile["loop_wall_s"].as_f64().unwrap(), "{device_ms} ms of device time in {profile}");
    // what the GPU is asked to do, pinned (the same on any adapter; docs/gpu.md "What the GPU is asked
    // to do"): per env step of the device-resident loop, the policy's kernels (the normalisers'
    // 4 of normalizer.wgsl, the actor's forward pass with the sampled actions, the critic's), the
    // task step's 5 of task.wgsl and the loop's sums, and one host read per iteration (the sums);
    // per PPO update of 5 × 4 minibatches, adam.wgsl's optimiser steps (three kernels each) and one read. A change that adds kernels or reads
    // fails here: measure it, then update the figures here and in BENCHMARKS.md.
    let (all_cols, all_rows) = read_csv(&adaptive.join("metrics.csv")).unwrap();
    let gpu = |name: &str| all_rows[1].1[all_cols.iter().position(|c| c == name).unwrap()];
    assert_eq!(gpu("gpu/syncs_per_step"), 1.0 / t as f64, "host reads per env step");
    assert_eq!(gpu("gpu/syncs_per_update"), 1.0, "host reads per update");
    assert_eq!(gpu("gpu/kernels_per_step"), PINNED_KERNELS_PER_STEP, "kernels per env step (device-resident PPO)");
    assert_eq!(gpu("gpu/kernels_per_update"), PINNED_KERNELS_PER_UPDATE, "kernels per PPO update");
    assert!(gpu("gpu/submissions_per_step") <= 7.0 && gpu("gpu/submissions_per_update") <= 200.0, "submissions: {} per step, {} per update", gpu("gpu/submissions_per_step"), gpu("gpu/submissions_per_update"));
    let r = eval(&EvalArgs { run: dev, checkpoint: "latest".into(), episodes: 3, max_envs: 3, seed: None, record: None, backend: None, baseline: None, video: Default::default(), live: Default::default() }).expect("eval");
    assert!(r.env_backend.starts_with("gpu") && r.learner_device.starts_with("gpu (burn wgpu"), "{} / {}", r.env_backend, r.learner_device);
    assert_eq!(r.episodes, 3);
}

/// Kernels per env step of the tiny device-resident PPO run of
/// `training_runs_with_env_and_learner_on_one_gpu_device` (lift, actor and critic [32, 16], 8 envs
/// × 4 steps), its second iteration: 149.5 before issue 33's work, 72.75 before the dense layers'
/// bias and ELU went into dextrain's matmul kernel, 46.75 before the output record grew from 17 to
/// 21 floats (issue 36's grasp terms: up to 12 term slots), 47.75 before the loop's per-env sums
/// were one kernel of ours, 29.75 before PPO's reward and done flag of a step were one, 23.75
/// before the actor's and the critic's forward passes were one kernel each (`mlp_forward.wgsl`),
/// 19.75 before the actor's kernel wrote the sampled actions too, 17.75 before the actor's and the
/// critic's observation normalisers shared their two launches (four before).
const PINNED_KERNELS_PER_STEP: f64 = 15.75;
/// Kernels per PPO update of the same run (5 epochs × 4 minibatches): 9,306 before issue 33's work,
/// 4,912 before the matmul kernel's epilogues, 4,379 before ELU's gradient was one kernel of ours,
/// 4,219 before PPO's loss (two kernels each way) and the adaptive learning rate (one) were
/// kernels of ours, 1,386 before GAE was one (this run's rollouts are 4 steps long), 1,354 before
/// the critic's value of the state after the rollout was one kernel, 1,352 before each optimiser
/// step ran adam.wgsl's kernels over groups of parameters (on lavapipe, which binds 32 storage
/// buffers per kernel, groups of six: 7 kernels a step for this run's 13 parameters where they
/// were 28; 3 on a device that binds 5 × 13 + 2 = 67, as the hardware GPUs do), 932 before each
/// layer's weight and bias gradients were one product and ELU's gradient went into the input
/// gradient's product of the layer after it (10 kernels a minibatch fewer for two 3-layer nets),
/// 732 before the rollout's steps were stacked by a kernel of ours per tensor (`cat_rows`: 7 where
/// burn's cat launched 7 × 4), 711 before each epoch's rows were gathered once and its minibatches
/// taken as views of them (3 selects an epoch where there were 3 a minibatch), 666 before each
/// minibatch's losses and gradient norm stayed on the device to be read once and added up on the
/// host (two additions a minibatch on the device before; two stacking kernels now).
const PINNED_KERNELS_PER_UPDATE: f64 = 629.0;

/// SAC with its replay buffer on the GPU (lavapipe in CI): the device-resident run gives the host
/// path's run to float rounding (every metric, every policy value), its host traffic per iteration
/// is exactly the README's (noise parameters, the batches' rows, the loss scalars; no observation),
/// and stopped and resumed (the buffer read from the device into the checkpoint and written back)
/// it continues bit for bit.
#[test]
fn sac_trains_with_its_replay_buffer_on_one_gpu_device() {
    let Some(ctx) = crate::common::gpu_context("sac_trains_with_its_replay_buffer_on_one_gpu_device") else { return };
    let adapter = format!("gpu:{}", ctx.info.name.split_whitespace().next().unwrap_or("llvmpipe"));
    drop(ctx);
    let tmp = tempfile::tempdir().unwrap();
    let (batch, n_step, updates) = (32u64, 2u64, 2u64);
    let sac_args = |name: &str, extra: &[&str]| {
        let mut a = gpu_run_args(tmp.path(), name, &adapter, 3, extra);
        a.sets.extend(["train.algorithm=\"sac\"", "sac.learning_starts=3", "sac.random_steps=2", "sac.buffer_capacity=6", "sac.policy_frequency=1"].iter().map(|s| s.to_string()));
        a.sets.extend([format!("sac.batch_size={batch}"), format!("sac.n_step={n_step}"), format!("sac.updates_per_step={updates}")]);
        a
    };
    let host = train(&sac_args("host", &["train.device_rollouts=false"])).expect("SAC on the GPU, host path");
    let dev = train(&sac_args("dev", &[])).expect("SAC on the GPU, device-resident");
    // the rings in pieces of a few slots (as an adapter's binding limit would cut a large buffer:
    // here 9,000 bytes, 2 slots of the 8 envs' critic observations, 3 of the actor's): the same
    // run bit for bit; the half run below and its resume keep pieces too (read into the checkpoint
    // and written back piece by piece)
    let pieces = "sac.device_piece_bytes=9000";
    let split = train(&sac_args("split", &[pieces])).expect("SAC with its rings in pieces");
    assert!(same_bits(&metrics(&dev).1, &metrics(&split).1), "the rings in pieces changed the run:\n{:?}\n{:?}", metrics(&dev).1, metrics(&split).1);
    assert_eq!(model_bytes(&dev, 3), model_bytes(&split, 3), "the rings in pieces changed the model");
    let mut half = sac_args("half", &[pieces]);
    half.stop_after = Some(2);
    let resumed = train(&half).expect("first part");
    assert!(resumed.join("checkpoints/2/replay.safetensors").is_file(), "the checkpoint holds the buffer read from the device");
    train(&TrainArgs { config: None, sets: vec![], name: None, resume: Some(resumed.clone()), ..args(tmp.path(), "unused") }).expect("resumed");
    let (cols, rows_host) = metrics(&host);
    let (_, rows_dev) = metrics(&dev);
    let rows_resumed = metrics(&resumed).1;
    assert_eq!((rows_host.len(), rows_dev.len(), rows_resumed.len()), (3, 3, 3));
    let col = |c: &str| cols.iter().position(|x| x == c).unwrap();
    let bytes = col("time/host_bytes");
    assert_rows_close(&cols, &rows_host, &rows_dev, bytes, "host path vs device-resident");
    assert!(same_bits(&rows_dev, &rows_resumed), "the resumed device-resident SAC run differs:\n{rows_dev:?}\n{rows_resumed:?}");
    assert_eq!(model_bytes(&dev, 3), model_bytes(&resumed, 3), "final model differs after resume");
    assert!(rows_dev.iter().all(|(_, v)| v[col("loss/critic")].is_finite() && v[col("updates")] > 0.0));
    assert_policies_close(&host, &dev, 3);
    // host traffic of an iteration with gradient steps: per env step the noise kernel's
    // parameters; per gradient step one noise kernel's parameters and the rows (i32) and window
    // flags (f32) of n_step × B transitions (the optimiser steps' and the normalisers' constants
    // are launch arguments on burn's stream, not counted); the sums; the learner's statistics and
    // log α (one read)
    let [o, p, _] = dims(&dev);
    let (n, t) = (8u64, 4u64);
    let misc = dextrain::task::task::OUT_MISC as u64;
    for (it, d) in &rows_dev {
        let g = d[col("updates")] as u64;
        let expected = t * 32 + g * (32 + n_step * batch * 8) + (2 * misc + 4) * 4 + 5 * 4;
        assert_eq!(d[bytes], expected as f64, "host bytes of device-resident iteration {it} ({g} gradient steps)");
    }
    for (_, h) in &rows_host {
        assert!(h[bytes] >= (t * n * (o + p) as u64 * 4) as f64, "the host path reads every step's observations: {}", h[bytes]);
    }
    assert_eq!(rows_dev.iter().map(|(_, v)| v[col("updates")]).collect::<Vec<_>>(), vec![4.0, 8.0, 8.0], "gradient steps from the 3rd env step on, {updates} per env step");
}

/// The tiny run of [`args`] with the envs and the learner on `adapter` (`gpu:NAME`), `iterations`
/// iterations, a checkpoint after each, and the `extra` overrides last.
fn gpu_run_args(runs: &Path, name: &str, adapter: &str, iterations: u32, extra: &[&str]) -> TrainArgs {
    let mut a = args(runs, name);
    a.sets.retain(|s| !s.starts_with("sim.backend") && !s.starts_with("train.device"));
    a.sets.extend([format!("sim.backend={adapter}"), format!("train.device={adapter}"), format!("train.iterations={iterations}"), "train.save_interval=1".into()]);
    a.sets.extend(extra.iter().map(|s| s.to_string()));
    a
}

/// Every metric of two runs' rows within 1e-4 (relative above 1; NaN matching NaN), column `skip`
/// (the host bytes) aside.
fn assert_rows_close(cols: &[String], a: &[(u64, Vec<f64>)], b: &[(u64, Vec<f64>)], skip: usize, what: &str) {
    assert_eq!(a.len(), b.len(), "{what}: row counts");
    for ((_, x), (_, y)) in a.iter().zip(b) {
        for (k, c) in cols.iter().enumerate() {
            if k != skip {
                assert!((x[k] - y[k]).abs() <= 1e-4 * (1.0 + x[k].abs()) || (x[k].is_nan() && y[k].is_nan()), "{what}: {c}: {} vs {}", x[k], y[k]);
            }
        }
    }
}

/// Every value of two runs' policy files at checkpoint `it` (parameters and normalisers, tensors in
/// name order) within 1e-4 (relative above 1).
fn assert_policies_close(a: &Path, b: &Path, it: u64) {
    let values = |dir: &Path| -> Vec<f64> {
        let (_, learner, _) = checkpoint::load(&dir.join(format!("checkpoints/{it}")), dims(dir), 8).expect("checkpoint");
        let mut tensors: Vec<_> = learner.files.iter().filter(|f| f.name == "model").flat_map(|f| f.tensors.iter()).collect();
        tensors.sort_by(|x, y| x.name.cmp(&y.name));
        tensors.iter().flat_map(|t| match &t.values {
            TensorValues::F32(v) => v.iter().map(|&x| x as f64).collect::<Vec<_>>(),
            TensorValues::F64(v) => v.clone(),
            TensorValues::U8(_) => Vec::new(),
        }).collect()
    };
    let (va, vb) = (values(a), values(b));
    assert!(!va.is_empty() && va.len() == vb.len(), "policy sizes {} vs {}", va.len(), vb.len());
    for (x, y) in va.iter().zip(&vb) {
        assert!((x - y).abs() <= 1e-4 * (1.0 + x.abs()), "a policy value: {x} (host path) vs {y} (device-resident)");
    }
}

/// A run's [obs, critic obs, actions] sizes (from its first checkpoint's state).
fn dims(dir: &Path) -> [usize; 3] {
    let st: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(dir.join("checkpoints/1/state.json")).unwrap()).unwrap();
    ["obs_dim", "priv_dim", "action_dim"].map(|k| st[k].as_u64().unwrap() as usize)
}

/// `--force` replaces a run, and only a run: a directory that is not one, or a run with a file of
/// the user's in it, is refused in one line and keeps every file.
#[test]
fn force_only_ever_replaces_a_run_directory() {
    let tmp = tempfile::tempdir().unwrap();
    let runs = tmp.path();
    let mut force = args(runs, "mine");
    force.force = true;
    // a directory of the user's, not a run
    let mine = runs.join("mine");
    std::fs::create_dir_all(mine.join("sub")).unwrap();
    std::fs::write(mine.join("notes.txt"), "my notes").unwrap();
    std::fs::write(mine.join("sub/data.bin"), [1u8, 2, 3]).unwrap();
    let err = format!("{:#}", train(&force).unwrap_err());
    assert!(err.contains("not a run directory") && err.contains("nothing was deleted") && !err.contains('\n'), "{err}");
    assert_eq!(std::fs::read_to_string(mine.join("notes.txt")).unwrap(), "my notes");
    assert_eq!(std::fs::read(mine.join("sub/data.bin")).unwrap(), [1, 2, 3]);
    // a directory with only a config.toml of the user's is not a run either
    std::fs::write(mine.join("config.toml"), "seed = 1").unwrap();
    assert!(train(&force).is_err());
    assert_eq!(std::fs::read_to_string(mine.join("config.toml")).unwrap(), "seed = 1");
    // a run with a file of the user's in it is refused too, and keeps it
    let run = train(&args(runs, "r")).expect("train");
    std::fs::write(run.join("analysis.ipynb"), "{}").unwrap();
    let mut force_r = args(runs, "r");
    force_r.force = true;
    let err = format!("{:#}", train(&force_r).unwrap_err());
    assert!(err.contains("analysis.ipynb") && err.contains("nothing was deleted"), "{err}");
    assert!(run.join("analysis.ipynb").is_file() && run.join("checkpoints/4/state.json").is_file());
    // without it, --force replaces the run (the replacement's eval/ etc. are gone with it)
    std::fs::remove_file(run.join("analysis.ipynb")).unwrap();
    force_r.sets.push("train.iterations=2".into());
    train(&force_r).expect("--force replaces a run");
    assert_eq!(metrics(&run).1.len(), 2);
    assert!(!run.join("checkpoints/4").exists());
}

/// A new run that fails to start (here: no such GPU adapter) removes the directory it made, and
/// `--force` replaces what a failed start left (config.toml and a metrics.csv without rows).
#[test]
fn a_failed_start_leaves_nothing_that_force_refuses() {
    let tmp = tempfile::tempdir().unwrap();
    let runs = tmp.path();
    let mut failing = args(runs, "f");
    failing.sets.push("sim.backend=gpu:no-such-adapter".into());
    let err = format!("{:#}", train(&failing).unwrap_err());
    assert!(err.contains("no-such-adapter"), "{err}");
    assert!(!runs.join("f").exists(), "the failed start left its directory behind");
    // what a failed start of an older dextrain left behind
    let old = runs.join("f");
    std::fs::create_dir_all(&old).unwrap();
    std::fs::write(old.join("config.toml"), "seed = 0\n").unwrap();
    std::fs::write(old.join("metrics.csv"), "iteration,env_steps\n").unwrap();
    let err = format!("{:#}", train(&args(runs, "f")).unwrap_err());
    assert!(err.contains("--force"), "without --force the directory is kept: {err}");
    let mut force = args(runs, "f");
    force.force = true;
    let run = train(&force).expect("--force replaces a failed start's directory");
    assert!(!metrics(&run).1.is_empty() && run.join("checkpoints").is_dir());
    // a run with iterations that then fails (here: resumed past its end) keeps its directory
    let err = format!("{:#}", train(&TrainArgs { resume: Some(run.clone()), config: None, sets: Vec::new(), ..args(runs, "f") }).unwrap_err());
    assert!(err.contains("finished"), "{err}");
    assert!(run.join("checkpoints").is_dir());
}

/// Two processes starting a run of the same name at the same moment: one gets the directory, the
/// other the one-line "exists" error (both passed the existence test once, made the directory and
/// trained it at once: seen when MPI started two ranks each as rank 0 of 1). 200 rounds of two
/// threads released together.
#[test]
fn two_runs_of_one_name_started_at_once_make_one_directory() {
    let tmp = tempfile::tempdir().unwrap();
    let runs = tmp.path().to_path_buf();
    for round in 0..200 {
        let name = format!("r{round}");
        let go = std::sync::Arc::new(std::sync::Barrier::new(2));
        let both: Vec<_> = (0..2)
            .map(|_| {
                let (go, runs, name) = (go.clone(), runs.clone(), name.clone());
                std::thread::spawn(move || {
                    go.wait();
                    dextrain::run_dir::create(&runs, &name, false).map_err(|e| format!("{e:#}"))
                })
            })
            .collect();
        let results: Vec<_> = both.into_iter().map(|t| t.join().unwrap()).collect();
        let made = results.iter().filter(|r| r.is_ok()).count();
        assert_eq!(made, 1, "round {round}: {results:?}");
        let err = results.iter().find_map(|r| r.as_ref().err()).unwrap();
        assert!(err.contains("exists") && !err.contains('\n'), "{err}");
    }
}

/// With no hardware adapter, the error says what Vulkan found: the loader, each driver manifest
/// and why its library does not load, the packages that usually fix it and the next step.
#[test]
fn the_no_adapter_message_names_the_loader_and_the_drivers() {
    let tmp = tempfile::tempdir().unwrap();
    let icd = tmp.path().join("broken_icd.json");
    std::fs::write(&icd, r#"{"file_format_version": "1.0.0", "ICD": {"library_path": "/nonexistent/libGLX_broken.so.0", "api_version": "1.3.0"}}"#).unwrap();
    std::fs::write(tmp.path().join("no_path.json"), r#"{"ICD": {}}"#).unwrap();
    let msg = dextrain::gpu::vulkan_probe::diagnose_with(Some(&tmp.path().display().to_string()));
    assert!(msg.contains("libvulkan.so.1"), "{msg}");
    assert!(msg.contains("broken_icd.json") && msg.contains("libGLX_broken.so.0: does not load") && msg.contains("No such file"), "{msg}");
    assert!(msg.contains("no_path.json: no ICD.library_path"), "{msg}");
    assert!(msg.contains("libvulkan1") && msg.contains("libglvnd0") && msg.contains("libegl1") && msg.contains("VK_LOADER_DEBUG=error"), "{msg}");
    assert!(!msg.contains('\n'), "one line: {msg}");
    let empty = tempfile::tempdir().unwrap();
    let msg = dextrain::gpu::vulkan_probe::diagnose_with(Some(&empty.path().display().to_string()));
    assert!(msg.contains("no driver manifest"), "{msg}");
}

/// XXH64 against the reference implementation's published values (xxhsum / twox-hash's tests).
#[test]
fn xxh64_matches_the_reference_values() {
    let hundred: Vec<u8> = (0..100u8).collect();
    assert_eq!(xxh64(b"", 0), 0xef46_db37_51d8_e999);
    assert_eq!(xxh64(&[42], 0), 0x0a9e_dece_beb0_3ae4);
    assert_eq!(xxh64(b"Hello, world!\0", 0), 0x7b06_c531_ea43_e89f);
    assert_eq!(xxh64(&hundred, 0), 0x6ac1_e580_3216_6597);
    assert_eq!(xxh64(b"", 0xae05_4331_1b70_2d91), 0x4b6a_04fc_df7a_4672);
    assert_eq!(xxh64(&hundred, 0xae05_4331_1b70_2d91), 0x567e_355e_0682_e1f1);
}

/// Every f64 of a checkpoint (the learner's scalars, the wall time) reads back with the same bits:
/// values of the adaptive learning-rate schedule (lr ÷ 1.5 and × 1.5 within its clamps) and random
/// bit patterns, among them `LOSSY`, which a plain decimal round trip through serde_json does not
/// give back (it did not resume bit for bit before checkpoints kept the bits).
#[test]
fn checkpoint_scalars_read_back_bit_for_bit() {
    // 5e-4 × 1.5 × 1.5: the default learning rate after two increases of the adaptive schedule
    const LOSSY: f64 = 0.001_125_000_000_000_000_1;
    let mut values = vec![LOSSY, 5e-4, 1e-5, 1e-2, f64::MIN_POSITIVE, 1.0 / 3.0];
    let mut lr = 5e-4f64;
    let mut rng = dextrain::rng::Rng::new(7, 7);
    for _ in 0..500 {
        lr = if rng.uniform() < 0.5 { (lr / 1.5).max(1e-5) } else { (lr * 1.5).min(1e-2) };
        values.push(lr);
        values.push(f64::from_bits(rng.next_u64() >> 2)); // positive, finite
    }
    // the values include ones that a plain decimal round trip through serde_json does not give back
    let plain = |v: &f64| serde_json::from_str::<f64>(&serde_json::to_string(v).unwrap()).unwrap();
    let lossy: Vec<f64> = values.iter().copied().filter(|v| plain(v).to_bits() != v.to_bits()).collect();
    eprintln!("{} of {} values change in a plain JSON round trip, e.g. {:?}", lossy.len(), values.len(), &lossy[..lossy.len().min(3)]);
    assert!(lossy.contains(&LOSSY), "LOSSY reads back exactly through plain JSON: the test lost its point");
    let mut learner = LearnerState::default();
    learner.push_tensor("model", "w", vec![1, 2], TensorValues::F32(vec![1.0, 2.0]));
    for (k, v) in values.iter().enumerate() {
        learner.set_f64(&format!("x{k}"), *v);
    }
    let tmp = tempfile::tempdir().unwrap();
    let env = EnvSnapshot { task_state: vec![1, 2, 3], obs: vec![0.5; 2], priv_obs: vec![0.25; 2], ep_return: vec![0.0; 2], ep_len: vec![1.0; 2] };
    let time_s = values[3 * values.len() / 4];
    let st = CheckpointState::new(3, 24, time_s, [1, 1, 2], &learner);
    let dir = checkpoint::save(&tmp.path().join("checkpoints"), &st, &learner, &env).expect("save");
    let (st2, learner2, env2) = checkpoint::load(&dir, [1, 1, 2], 2).expect("load");
    assert_eq!(env2, env);
    assert_eq!(st2.exact_time_s().to_bits(), time_s.to_bits());
    for (k, v) in values.iter().enumerate() {
        let got = learner2.f64(&format!("x{k}")).unwrap();
        assert_eq!(got.to_bits(), v.to_bits(), "x{k}: {v:e} read back as {got:e}");
    }
    assert_eq!(learner2.f32s("model", "w", Some(2)).unwrap(), vec![1.0, 2.0]);
}

/// A checkpoint whose files were damaged, edited or not all written is never resumed from or
/// evaluated silently: "latest" skips it (eval and resume agree on which checkpoint that is), and
/// asking for it by number is a one-line error naming the file.
#[test]
fn damaged_edited_or_incomplete_checkpoints_are_skipped_or_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let runs = tmp.path();
    let mut a = args(runs, "a");
    a.sets.push("train.iterations=6".into());
    let dir = train(&a).expect("train");
    for it in [2, 4, 6] {
        checkpoint::verify(&dir.join(format!("checkpoints/{it}"))).expect("a fresh checkpoint passes");
    }
    let e = EvalArgs { run: dir.clone(), checkpoint: "latest".into(), episodes: 2, max_envs: 2, seed: None, record: None, backend: None, baseline: None, video: Default::default(), live: Default::default() };
    // 64 bytes of 0xFF in the middle of the newest env.safetensors (same size)
    let envf = dir.join("checkpoints/6/env.safetensors");
    let mut bytes = std::fs::read(&envf).unwrap();
    let mid = bytes.len() / 2;
    bytes[mid..mid + 64].fill(0xFF);
    std::fs::write(&envf, &bytes).unwrap();
    assert_eq!(checkpoint::find(&dir, "latest").unwrap(), dir.join("checkpoints/4"));
    assert_eq!(eval(&e).expect("eval of latest").iteration, 4);
    let err = format!("{:#}", eval(&EvalArgs { checkpoint: "6".into(), ..e.clone() }).unwrap_err());
    assert!(err.contains("env.safetensors") && err.contains("hash") && !err.contains('\n'), "{err}");
    // state.json of checkpoint 4 edited to another iteration (same length)
    let sj = dir.join("checkpoints/4/state.json");
    let text = std::fs::read_to_string(&sj).unwrap();
    assert!(text.contains("\"iteration\": 4"), "{text}");
    std::fs::write(&sj, text.replace("\"iteration\": 4", "\"iteration\": 5")).unwrap();
    let err = format!("{:#}", checkpoint::find(&dir, "4").unwrap_err());
    assert!(err.contains("state.json") && !err.contains('\n'), "{err}");
    // checkpoint 2 incomplete: no manifest
    std::fs::remove_file(dir.join("checkpoints/2/manifest.json")).unwrap();
    let err = format!("{:#}", checkpoint::find(&dir, "2").unwrap_err());
    assert!(err.contains("manifest.json") && err.contains("incomplete"), "{err}");
    let err = format!("{:#}", eval(&e).unwrap_err());
    assert!(err.contains("no checkpoint passes"), "{err}");
    // restore checkpoint 4: resume and eval both take it, and the resumed run ends as a straight one
    std::fs::write(&sj, text).unwrap();
    assert_eq!(eval(&e).expect("eval").iteration, 4);
    let resume = TrainArgs { config: None, sets: vec![], name: None, resume: Some(dir.clone()), ..args(runs, "unused") };
    train(&resume).expect("resume from checkpoint 4");
    let straight = train(&TrainArgs { name: Some("b".into()), ..a.clone() }).expect("straight run");
    assert!(same_bits(&metrics(&dir).1, &metrics(&straight).1), "resumed from 4 after skipping 6: metrics differ");
    assert_eq!(model_bytes(&dir, 6), model_bytes(&straight, 6));
    checkpoint::verify(&dir.join("checkpoints/6")).expect("checkpoint 6 was written again");
}
