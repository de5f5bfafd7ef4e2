//! Policy export: the ONNX writer against the plain-Rust forward pass, run back by tract and by
//! onnxruntime (Python, with `onnx.checker`'s full check), for an MLP policy, a teacher with a
//! privileged encoder, a GRU student and a SAC actor (LayerNorm, tanh); a GRU worked by hand; bad
//! input; and `dextrain export --verify` end to end on a trained run (play.rs: a SAC run's too).

use std::process::Command;

use dextrain::config::Activation;
use dextrain::export::onnx::{Adaptation, Conv1d, Dense, Gru, LayerNorm, Mlp, Normalization, PolicyNet, Tcn, check, forward, read_metadata, run_onnx, to_onnx};
use dextrain::rng::Rng;

const ROOT: &str = env!("CARGO_MANIFEST_DIR");

fn draw(rng: &mut Rng, n: usize, scale: f64) -> Vec<f32> {
    (0..n).map(|_| (rng.normal() * scale) as f32).collect()
}

fn dense(rng: &mut Rng, i: usize, o: usize) -> Dense {
    Dense { weight: draw(rng, i * o, 1.0 / (i as f64).sqrt()), bias: draw(rng, o, 0.1), inputs: i, outputs: o }
}

fn mlp(rng: &mut Rng, widths: &[usize], activation: Activation) -> Mlp {
    Mlp::plain(widths.windows(2).map(|w| dense(rng, w[0], w[1])).collect(), activation)
}

fn norm(rng: &mut Rng, d: usize) -> Normalization {
    Normalization { mean: draw(rng, d, 0.5), denom: (0..d).map(|_| 0.5 + rng.uniform() as f32).collect() }
}

/// The three kinds of network, small: (name, net, priv size, history (H, D)).
fn nets() -> Vec<(&'static str, PolicyNet, usize, (usize, usize))> {
    let mut rng = Rng::new(11, 3);
    let (o, p, a) = (9, 7, 4);
    let mlp_net = PolicyNet::Mlp { obs_norm: norm(&mut rng, o), actor: mlp(&mut rng, &[o, 16, 8, a], Activation::Elu) };
    let encoder = PolicyNet::Encoder {
        obs_norm: norm(&mut rng, o),
        priv_norm: norm(&mut rng, p),
        priv_index: vec![6, 1, 3],
        encoder: mlp(&mut rng, &[3, 8, 5], Activation::Relu),
        actor: mlp(&mut rng, &[o + 5, 12, a], Activation::Tanh),
    };
    let (h, d, hs, l) = (6, 5, 7, 3);
    let student = PolicyNet::Student {
        obs_norm: norm(&mut rng, o),
        hist_norm: norm(&mut rng, d),
        adapt: Adaptation::Gru(Gru { inputs: d, hidden: hs, w_ih: draw(&mut rng, d * 3 * hs, 0.4), w_hh: draw(&mut rng, hs * 3 * hs, 0.4), b_ih: draw(&mut rng, 3 * hs, 0.2), b_hh: draw(&mut rng, 3 * hs, 0.2) }),
        head: dense(&mut rng, hs, l),
        actor: mlp(&mut rng, &[o + l, 10, a], Activation::Elu),
        history_len: h,
    };
    // a temporal convolution over 9 steps: kernels 3 (stride 2) → 4 steps, then 2 (stride 1) → 3
    // steps of 6 channels; the first convolution maps 5 channels to 6, so a transposed weight cannot pass
    let (th, c0, c1, c2) = (9, 5, 6, 6);
    let conv = |rng: &mut Rng, i: usize, o: usize, kernel: usize, stride: usize| Conv1d { inputs: i, outputs: o, kernel, stride, weight: draw(rng, kernel * i * o, 0.5), bias: draw(rng, o, 0.2) };
    let tcn = PolicyNet::Student {
        obs_norm: norm(&mut rng, o),
        hist_norm: norm(&mut rng, d),
        adapt: Adaptation::Tcn(Tcn { embed: vec![dense(&mut rng, d, c0), dense(&mut rng, c0, c0)], convs: vec![conv(&mut rng, c0, c1, 3, 2), conv(&mut rng, c1, c2, 2, 1)] }),
        head: dense(&mut rng, 3 * c2, l),
        actor: mlp(&mut rng, &[o + l, 10, a], Activation::Elu),
        history_len: th,
    };
    // a SAC actor: LayerNorm before every hidden activation, tanh after the last layer
    let mut sac_actor = mlp(&mut rng, &[o, 16, 8, a], Activation::Elu);
    sac_actor.layer_norms = [16, 8].iter().map(|&w| LayerNorm { gain: (0..w).map(|_| 0.5 + rng.uniform() as f32).collect(), shift: draw(&mut rng, w, 0.3) }).collect();
    sac_actor.tanh_output = true;
    let sac = PolicyNet::Mlp { obs_norm: norm(&mut rng, o), actor: sac_actor };
    vec![("mlp", mlp_net, 0, (0, 0)), ("encoder", encoder, p, (0, 0)), ("student", student, 0, (h, d)), ("tcn_student", tcn, 0, (th, d)), ("sac_actor", sac, 0, (0, 0))]
}

fn max_diff(a: &[f32], b: &[f32]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter().zip(b).map(|(x, y)| (*x as f64 - *y as f64).abs()).fold(0.0, f64::max)
}

/// onnxruntime and onnx.checker (Python), or why they cannot run (REQUIRE_PYTHON_ONNX=1: fail).
fn python_onnx() -> Option<String> {
    let python = std::env::var("DEXTRAIN_PYTHON").unwrap_or_else(|_| "python3".into());
    let required = std::env::var("REQUIRE_PYTHON_ONNX").is_ok_and(|v| v == "1");
    match Command::new(&python).args(["-c", "import onnx, onnxruntime"]).output() {
        Ok(o) if o.status.success() => Some(python),
        other => {
            let why = match other {
                Ok(o) => format!("`import onnx, onnxruntime` failed: {}", String::from_utf8_lossy(&o.stderr).trim()),
                Err(e) => format!("cannot run {python}: {e}"),
            };
            assert!(!required, "REQUIRE_PYTHON_ONNX=1 but {why} (pip install onnxruntime onnx)");
            eprintln!("the onnxruntime comparison did not run: {why} (pip install onnxruntime onnx to run it)");
            None
        }
    }
}

/// Runs tests/run_onnx.py on a model file and inputs; returns its JSON.
fn onnxruntime(python: &str, model: &std::path::Path, inputs: serde_json::Value) -> serde_json::Value {
    let spec = model.with_extension("inputs.json");
    std::fs::write(&spec, inputs.to_string()).unwrap();
    let out = Command::new(python).arg(format!("{ROOT}/tests/run_onnx.py")).arg(model).arg(&spec).output().unwrap();
    assert!(out.status.success(), "run_onnx.py: {}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_slice(&out.stdout).unwrap()
}

#[test]
fn exported_networks_match_the_reference_forward_pass_in_tract_and_onnxruntime() {
    let tmp = tempfile::tempdir().unwrap();
    let python = python_onnx();
    let mut rng = Rng::new(5, 8);
    for (name, net, p, (h, d)) in nets() {
        let meta = vec![("dextrain.kind".to_string(), name.to_string()), ("dextrain.note".to_string(), "ünïcode ok".to_string())];
        let bytes = to_onnx(&net, &meta).unwrap();
        assert_eq!(read_metadata(&bytes).unwrap(), meta);
        for batch in [1, 5] {
            let obs = draw(&mut rng, batch * 9, 2.0);
            let priv_obs = draw(&mut rng, batch * p, 2.0);
            let hist = draw(&mut rng, batch * h * d, 2.0);
            let want = forward(&net, &obs, &priv_obs, &hist, batch).unwrap();
            assert_eq!(want.len(), batch * 4);
            if name == "sac_actor" {
                assert!(want.iter().all(|a| a.abs() < 1.0), "tanh bounds a SAC actor's actions: {want:?}");
            }
            let tract = run_onnx(&bytes, &obs, &priv_obs, &hist, batch).unwrap();
            let dt = max_diff(&tract, &want);
            eprintln!("{name} batch {batch}: |tract − forward| ≤ {dt:e}");
            assert!(dt <= 1e-5, "{name}: tract differs by {dt}");
            if let Some(py) = &python {
                let model = tmp.path().join(format!("{name}.onnx"));
                std::fs::write(&model, &bytes).unwrap();
                let mut inputs = serde_json::json!({"obs": {"shape": [batch, 9], "data": obs}});
                if p > 0 {
                    inputs["priv_obs"] = serde_json::json!({"shape": [batch, p], "data": priv_obs});
                }
                if h > 0 {
                    inputs["history"] = serde_json::json!({"shape": [batch, h, d], "data": hist});
                }
                let r = onnxruntime(py, &model, inputs);
                let got: Vec<f32> = r["actions"].as_array().unwrap().iter().map(|x| x.as_f64().unwrap() as f32).collect();
                let dr = max_diff(&got, &want);
                eprintln!("{name} batch {batch}: |onnxruntime − forward| ≤ {dr:e}");
                assert!(dr <= 1e-5, "{name}: onnxruntime differs by {dr}");
                assert_eq!(r["shape"], serde_json::json!([batch, 4]));
                assert_eq!(r["metadata"]["dextrain.note"], "ünïcode ok");
                assert_eq!(r["opset"], 17);
            }
        }
    }
}

/// The GRU's formulation and gate order, pinned by a case worked by hand: one input, one hidden
/// unit, two steps, then the identity head and actor.
#[test]
fn a_gru_worked_by_hand() {
    // gates z, r, n: w_ih = [wz, wr, wn], w_hh = [uz, ur, un]
    let (wz, wr, wn, uz, ur, un) = (0.5f32, -0.3, 0.8, 0.2, 0.4, -0.6);
    let (bz, br, bn, cz, cr, cn) = (0.1f32, 0.0, -0.2, 0.05, 0.1, 0.3);
    let gru = Gru { inputs: 1, hidden: 1, w_ih: vec![wz, wr, wn], w_hh: vec![uz, ur, un], b_ih: vec![bz, br, bn], b_hh: vec![cz, cr, cn] };
    let one = |w: f32| Dense { weight: vec![w], bias: vec![0.0], inputs: 1, outputs: 1 };
    let net = PolicyNet::Student {
        obs_norm: Normalization { mean: vec![0.0], denom: vec![1.0] },
        hist_norm: Normalization { mean: vec![1.0], denom: vec![2.0] },
        adapt: Adaptation::Gru(gru),
        head: one(1.0),
        // actions = 0 · obs + 1 · z
        actor: Mlp::plain(vec![Dense { weight: vec![0.0, 1.0], bias: vec![0.0], inputs: 2, outputs: 1 }], Activation::Elu),
        history_len: 2,
    };
    let sig = |x: f32| 1.0 / (1.0 + (-x).exp());
    // raw history 3, −1 → normalised (3 − 1)/2 = 1, (−1 − 1)/2 = −1
    let mut h = 0.0f32;
    for x in [1.0f32, -1.0] {
        let z = sig(wz * x + bz + uz * h + cz);
        let r = sig(wr * x + br + ur * h + cr);
        let n = (wn * x + bn + r * (un * h + cn)).tanh();
        h = (1.0 - z) * n + z * h;
    }
    let want = forward(&net, &[0.7], &[], &[3.0, -1.0], 1).unwrap();
    assert!((want[0] - h).abs() < 1e-6, "forward {} by hand {h}", want[0]);
    let got = run_onnx(&to_onnx(&net, &[]).unwrap(), &[0.7], &[], &[3.0, -1.0], 1).unwrap();
    assert!((got[0] - h).abs() < 1e-6, "tract {} by hand {h}", got[0]);
}

#[test]
fn bad_networks_and_bytes_are_one_line_errors() {
    let (_, mut net, _, _) = nets().remove(0);
    if let PolicyNet::Mlp { actor, .. } = &mut net {
        let l = &mut actor.layers[1];
        l.inputs = 15;
        let n = 15 * l.outputs;
        l.weight.truncate(n);
    }
    let e = format!("{:#}", check(&net).unwrap_err());
    assert!(e.contains("actor layer 1") && e.contains("expected 16") && !e.contains('\n'), "{e}");
    assert!(to_onnx(&net, &[]).is_err());
    for bytes in [&b""[..], b"\xff\xfe\x00garbage", b"\x08\x08"] {
        let e = format!("{:#}", run_onnx(bytes, &[0.0; 9], &[], &[], 1).unwrap_err());
        assert!(!e.contains('\n'), "{e}");
    }
}

/// `dextrain export --verify` on a trained lift run: the files land in RUN/export, the model
/// agrees with the burn policy on recorded observations, the contract reads back and names the
/// checkpoint, a second export replaces the first, and a directory holding other files is refused.
#[test]
fn export_writes_a_verified_model_and_its_contract() {
    use dextrain::export::command::{ExportArgs, run as export};
    use dextrain::export::contract::PolicyContract;
    use dextrain::train::{TrainArgs, run as train};
    let tmp = tempfile::tempdir().unwrap();
    let sets: Vec<String> = ["sim.backend=cpu", "train.device=cpu", "sim.num_envs=4", "task.episode_length=16", "train.iterations=2", "train.steps_per_env=8", "train.plot_interval=0", "policy.actor_hidden=[16, 8]", "policy.critic_hidden=[8]"]
        .iter()
        .map(|s| s.to_string())
        .collect();
    let args = TrainArgs { config: Some(format!("{ROOT}/configs/lift_cube_cpu.toml").into()), sets, name: Some("lift".into()), resume: None, force: false, runs_dir: tmp.path().into(), stop_after: None, quiet: true, live: Default::default(), gpu_profile: false };
    let run = train(&args).unwrap();
    let a = ExportArgs { run: run.clone(), checkpoint: "latest".into(), out: None, verify: true };
    let r = export(&a).unwrap();
    let diff = r.max_abs_diff.unwrap();
    assert!(diff <= 1e-5 && r.verified_rows.unwrap() >= 16, "{r:?}");
    let dir = run.join("export");
    let c = PolicyContract::read(&dir.join("policy.json")).unwrap();
    assert_eq!(c.source.checkpoint, 2);
    let bytes = std::fs::read(dir.join("policy.onnx")).unwrap();
    assert_eq!(c.model.xxh64, format!("{:016x}", dextrain::learn::checkpoint::xxh64(&bytes, 0)));
    let meta = read_metadata(&bytes).unwrap();
    assert!(meta.iter().any(|(k, v)| k == "dextrain.task" && v == "lift"));
    // the world file is the run's config
    assert_eq!(std::fs::read(dir.join("world.toml")).unwrap(), std::fs::read(run.join("config.toml")).unwrap());
    // again: replaced in place, nothing else left beside it
    export(&ExportArgs { verify: false, ..a.clone() }).unwrap();
    let mut names: Vec<String> = std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    names.sort();
    assert_eq!(names, ["policy.json", "policy.onnx", "world.toml"]);
    let beside: Vec<String> = std::fs::read_dir(&run).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).filter(|n| n.starts_with('.')).collect();
    assert!(beside.is_empty(), "temporary directories left: {beside:?}");
    // a directory with a file of the user's is not replaced
    let user = tmp.path().join("mine");
    std::fs::create_dir(&user).unwrap();
    std::fs::write(user.join("notes.txt"), "keep me").unwrap();
    let e = format!("{:#}", export(&ExportArgs { out: Some(user.clone()), ..a.clone() }).unwrap_err());
    assert!(e.contains("notes.txt") && !e.contains('\n'), "{e}");
    assert_eq!(std::fs::read_to_string(user.join("notes.txt")).unwrap(), "keep me");
    // a run that does not exist
    let e = format!("{:#}", export(&ExportArgs { run: tmp.path().join("nope"), ..a }).unwrap_err());
    assert!(e.contains("nope") && !e.contains('\n'), "{e}");
}
