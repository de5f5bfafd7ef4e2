//! `dextrain play`: the simulator driven from an export's files alone gives eval's episodes — for
//! each action mapping (lift's direct one, track's direct one from the reference's first frame,
//! residual_joint's, residual_task's with its IK), a SAC actor (tanh, LayerNorm), and (distill.rs)
//! a student with its history —
//! and a damaged export is a one-line error naming the file and the field.

use std::path::{Path, PathBuf};

use dextrain::eval::{EvalArgs, EvalReport, run as eval};
use dextrain::export::command::{ExportArgs, run as export};
use dextrain::eval::play::{PlayArgs, run as play};
use dextrain::train::{TrainArgs, run as train};

const ROOT: &str = env!("CARGO_MANIFEST_DIR");

fn s(v: &[&str]) -> Vec<String> {
    v.iter().map(|x| x.to_string()).collect()
}

/// A run of `config` trained one iteration with tiny nets, 4 envs, on the CPU.
fn tiny_run(runs: &Path, name: &str, config: &str, extra: &[&str]) -> PathBuf {
    let mut sets = s(&["sim.backend=cpu", "train.device=cpu", "sim.num_envs=4", "train.iterations=1", "train.steps_per_env=8", "train.plot_interval=0", "policy.actor_hidden=[16]", "policy.critic_hidden=[16]"]);
    sets.extend(s(extra));
    let args = TrainArgs { config: Some(format!("{ROOT}/configs/{config}").into()), sets, name: Some(name.into()), resume: None, force: false, runs_dir: runs.into(), stop_after: None, quiet: true, live: Default::default(), gpu_profile: false };
    train(&args).unwrap()
}

/// The controller built from `run`'s export maps actions to exactly the simulator's targets: on
/// the export's world (CPU, 4 envs), the controller acts, the task maps the same actions itself,
/// and the two sets of targets are equal bit for bit at every step of every running episode (so
/// its memory — previous action, smoothed and integrated residual, delta targets — and the
/// fields it fills from it are the simulator's too).
fn mapping_is_exact(run: &Path, what: &str) {
    use dextrain::config::Config;
    use dextrain::env::SimModel;
    use dextrain::export::controller::Controller;
    let dir = run.join("export");
    let mut cfg = Config::load(&dir.join("world.toml")).unwrap();
    cfg.sim.num_envs = 4;
    cfg.seed = 5;
    let model = SimModel::from_config(&cfg).unwrap();
    let mut task = dextrain::task::make_task_batch(&cfg, model.clone()).unwrap();
    let spec = task.spec().clone();
    let urdf = std::fs::read(cfg.resolve(&cfg.hand.urdf)).unwrap();
    let mut ctl = Controller::load(&dir.join("policy.json"), &urdf, &spec, &model, 4).unwrap();
    let b = task.reset_all().unwrap();
    let (mut obs, mut priv_obs) = (b.obs.clone(), b.priv_obs.clone());
    let mut start = vec![true; 4];
    let mut moved = 0;
    // 25 steps: across episode ends (the controller restarts its memory with the envs)
    for step in 0..25 {
        let first = if start.iter().any(|&s| s) { task.reference_frames(0).unwrap() } else { None };
        let next = task.reference_frames(1).unwrap();
        let (actions, targets) = ctl.act(&obs, &priv_obs, &start, first.as_deref(), next.as_deref()).unwrap();
        let before = task.targets().unwrap();
        let b = task.step(&actions).unwrap().clone();
        let mapped = task.targets().unwrap();
        for i in 0..4 {
            if b.done(i) {
                continue;
            }
            let bits = |t: &dextrain::gpu::layout::Targets| bytemuck::bytes_of(t).to_vec();
            assert_eq!(bits(&targets[i]), bits(&mapped[i]), "{what}: env {i} step {step}: the controller's targets are not the simulator's");
            moved += (bits(&before[i]) != bits(&mapped[i])) as usize;
        }
        for (i, s) in start.iter_mut().enumerate() {
            *s = b.done(i);
        }
        (obs, priv_obs) = (b.obs, b.priv_obs);
    }
    assert!(moved > 0, "{what}: the targets never moved");
}

/// Exports `run`, checks the controller's mapping ([`mapping_is_exact`]), plays the export and
/// evaluates the checkpoint on the same 4 episodes (CPU), and checks that every episode's outcome
/// is the same: success, termination, length and reference exactly; return and tracking errors
/// to 1e-4 relative. The ONNX model's actions are burn's to ~1e-7, not bit for bit, and contacts
/// amplify such a difference over a long episode (0.2 % of a 20-step lift return, a different
/// orientation error after 138 steps of an untrained residual_task policy), so the runs here are
/// 10 steps long: the exactness of the mapping is [`mapping_is_exact`]'s. Returns (eval, play).
pub fn play_equals_eval(run: &Path, what: &str) -> (EvalReport, EvalReport) {
    export(&ExportArgs { run: run.into(), checkpoint: "latest".into(), out: None, verify: false }).unwrap();
    mapping_is_exact(run, what);
    let backend = Some("cpu".parse().unwrap());
    let e = eval(&EvalArgs { run: run.into(), checkpoint: "latest".into(), episodes: 4, max_envs: 4, seed: Some(77), record: None, backend: backend.clone(), baseline: None, video: Default::default(), live: Default::default() }).unwrap();
    let p = play(&PlayArgs { contract: run.join("export/policy.json"), episodes: 4, max_envs: 4, seed: Some(77), backend, record: None, video: Default::default(), live: Default::default() }).unwrap();
    assert_eq!(p.seed, e.seed);
    assert_eq!(p.task, e.task);
    assert_eq!(p.learner_device, "onnx (tract, cpu)");
    let (ee, pe) = (&e.policy.per_episode, &p.policy.per_episode);
    assert_eq!(ee.len(), pe.len(), "{what}");
    let close = |a: Option<f64>, b: Option<f64>| match (a, b) {
        (Some(a), Some(b)) => (a - b).abs() <= 1e-4 * a.abs().max(1e-3),
        (a, b) => a == b,
    };
    for (k, (x, y)) in ee.iter().zip(pe).enumerate() {
        assert_eq!((x.success, x.terminated, x.length, &x.reference), (y.success, y.terminated, y.length, &y.reference), "{what}: episode {k}");
        assert!(close(Some(x.ret), Some(y.ret)), "{what}: episode {k}: return {} (eval) vs {} (play)", x.ret, y.ret);
        for (a, b) in [(x.ote_m, y.ote_m), (x.ooe_deg, y.ooe_deg), (x.terminal_pos_err_m, y.terminal_pos_err_m), (x.terminal_rot_err_deg, y.terminal_rot_err_deg)] {
            assert!(close(a, b), "{what}: episode {k}: {a:?} (eval) vs {b:?} (play)");
        }
    }
    (e, p)
}

#[test]
fn play_reproduces_eval_from_the_exported_files_for_every_action_mapping() {
    let tmp = tempfile::tempdir().unwrap();
    // lift: the direct mapping (wrist deltas, absolute finger targets)
    let lift = tiny_run(tmp.path(), "lift", "lift_cube_cpu.toml", &["task.episode_length=10"]);
    play_equals_eval(&lift, "lift");
    // a SAC actor (tanh of its mean, LayerNorm in the actor, trained a few gradient steps): the
    // export runs as the burn actor does (--verify) and plays eval's episodes
    let sac = ["task.episode_length=10", "train.algorithm=\"sac\"", "sac.batch_size=16", "sac.learning_starts=2", "sac.random_steps=0", "sac.buffer_capacity=8", "sac.actor_layer_norm=true", "policy.zero_init_output=false"];
    let sac_run = tiny_run(tmp.path(), "lift_sac", "lift_cube_cpu.toml", &sac);
    let r = export(&ExportArgs { run: sac_run.clone(), checkpoint: "latest".into(), out: None, verify: true }).unwrap();
    assert!(r.max_abs_diff.unwrap() <= 1e-5 && r.verified_rows.unwrap() >= 16, "{r:?}");
    let c = dextrain::export::contract::PolicyContract::read(&sac_run.join("export/policy.json")).unwrap();
    assert_eq!(c.source.algorithm, "sac");
    play_equals_eval(&sac_run, "lift (SAC actor)");
    // the reference mappings, with a policy whose output is not zero (so the residuals move)
    let short = ["task.reference.files=[\"refs/perturbed/ref_000.mcap\", \"refs/perturbed/ref_001.mcap\"]", "task.episode_length=10", "policy.zero_init_output=false", "policy.init_std=0.5"];
    let mut rt = short.to_vec();
    rt.push("task.residual.scale_tips=0.5");
    let residual_task = tiny_run(tmp.path(), "rt", "residual_task_cube.toml", &rt);
    let (_, p) = play_equals_eval(&residual_task, "residual_task");
    assert!(p.policy.per_episode.iter().all(|e| e.ote_m.is_some()), "tracking errors reported");
    // on the GPU backend (the controller's targets replace the task's mapped ones on the device):
    // the same episodes as on the CPU, to the parity tolerances of the IK run (tests/suite/parity.rs)
    if let Some(ctx) = crate::common::gpu_context("play_reproduces_eval_from_the_exported_files_for_every_action_mapping") {
        let backend = Some(format!("gpu:{}", ctx.info.name).parse().unwrap());
        drop(ctx);
        let g = play(&PlayArgs { contract: residual_task.join("export/policy.json"), episodes: 4, max_envs: 4, seed: Some(77), backend, record: None, video: Default::default(), live: Default::default() }).unwrap();
        assert!(!g.env_backend.starts_with("cpu"), "{}", g.env_backend);
        for (k, (x, y)) in p.policy.per_episode.iter().zip(&g.policy.per_episode).enumerate() {
            assert_eq!((x.success, x.terminated, x.length), (y.success, y.terminated, y.length), "residual_task on the GPU: episode {k}");
            assert!((x.ret - y.ret).abs() <= 1e-2 * x.ret.abs().max(1.0), "residual_task on the GPU: episode {k}: return {} (CPU) vs {} (GPU)", x.ret, y.ret);
        }
    }
    let residual_joint = tiny_run(tmp.path(), "rj", "residual_joint_cube.toml", &short);
    play_equals_eval(&residual_joint, "residual_joint");
    let mut free = short.to_vec();
    free.push("task.track.action=\"free\"");
    free.push("task.action.finger_mode=\"delta\"");
    let track = tiny_run(tmp.path(), "track", "track_cube.toml", &free);
    play_equals_eval(&track, "track (free actions, delta fingers)");
    let c = dextrain::export::contract::PolicyContract::read(&track.join("export/policy.json")).unwrap();
    use dextrain::export::contract::{ActionMapping, StartTargets};
    assert!(matches!(c.action_mapping, ActionMapping::Direct { start: StartTargets::ReferenceFirstFrame, .. }), "{:?}", c.action_mapping);
}

#[test]
fn a_damaged_export_is_a_one_line_error_naming_the_file_and_the_field() {
    let tmp = tempfile::tempdir().unwrap();
    let run = tiny_run(tmp.path(), "lift", "lift_cube_cpu.toml", &["task.episode_length=8"]);
    export(&ExportArgs { run: run.clone(), checkpoint: "latest".into(), out: None, verify: false }).unwrap();
    let dir = run.join("export");
    let contract = dir.join("policy.json");
    let args = |c: &Path| PlayArgs { contract: c.into(), episodes: 2, max_envs: 2, seed: Some(1), backend: Some("cpu".parse().unwrap()), record: None, video: Default::default(), live: Default::default() };
    let err = |c: &Path| {
        let e = format!("{:#}", play(&args(c)).unwrap_err());
        assert!(!e.contains('\n'), "{e}");
        e
    };
    let good = std::fs::read_to_string(&contract).unwrap();
    let copy = |name: &str, text: &str| -> PathBuf {
        let d = tmp.path().join(name);
        std::fs::create_dir_all(&d).unwrap();
        for f in ["policy.onnx", "world.toml"] {
            std::fs::copy(dir.join(f), d.join(f)).unwrap();
        }
        std::fs::write(d.join("policy.json"), text).unwrap();
        d.join("policy.json")
    };
    // not JSON, a wrong type, a field the world does not have, another hand
    let e = err(&copy("truncated", &good[..good.len() / 2]));
    assert!(e.contains("truncated/policy.json"), "{e}");
    let e = err(&copy("type", &good.replacen("\"rate_hz\": ", "\"rate_hz\": \"fast\", \"x\": ", 1)));
    assert!(e.contains("policy.json") && e.contains("rate_hz"), "{e}");
    let e = err(&copy("field", &good.replacen("\"name\": \"obj_rel\"", "\"name\": \"obj_rel_typo\"", 1)));
    assert!(e.contains("policy.json") && e.contains("observation.fields") && e.contains("obj_rel_typo"), "{e}");
    let mut v: serde_json::Value = serde_json::from_str(&good).unwrap();
    v["hand"]["urdf_xxh64"] = "0123456789abcdef".into();
    let e = err(&copy("hand", &serde_json::to_string(&v).unwrap()));
    assert!(e.contains("policy.json") && e.contains("hand.urdf_xxh64"), "{e}");
    // a damaged model: its hash is not the contract's
    let d = copy("model", &good);
    let mut onnx = std::fs::read(d.with_file_name("policy.onnx")).unwrap();
    let last = onnx.len() - 1;
    onnx[last] ^= 0x55;
    std::fs::write(d.with_file_name("policy.onnx"), onnx).unwrap();
    let e = err(&d);
    assert!(e.contains("policy.onnx") && e.contains("model.xxh64"), "{e}");
    // no world beside it, and no contract at all
    let d = copy("noworld", &good);
    std::fs::remove_file(d.with_file_name("world.toml")).unwrap();
    let e = err(&d);
    assert!(e.contains("world.toml"), "{e}");
    let e = err(&tmp.path().join("nothing/policy.json"));
    assert!(e.contains("nothing/policy.json"), "{e}");
}
