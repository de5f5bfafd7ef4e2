//! The live view (`--live`): a Foxglove WebSocket client (`tests/live_client.py`, Python
//! `websockets`) connects to a training run and to an eval through the binary, receives the advertised
//! channels, and decodes scene, transform and metrics messages, validated against the schemas the
//! server advertised; the metrics it receives are the run's metrics.csv rows; the shipped layout
//! is the one a lift run writes; a client that connects mid-run first gets the rows so far; bad
//! addresses are one-line errors; without a client nothing is sent.

use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Child, Command, Stdio};

const ROOT: &str = env!("CARGO_MANIFEST_DIR");

/// `dextrain train` of the tiny lift run `name` (into `runs`) for `iterations` iterations.
fn tiny_lift_train(runs: &str, name: &str, iterations: u32) -> Vec<String> {
    let mut args: Vec<String> = ["train", "configs/lift_cube_cpu.toml", "--name", name, "--runs-dir", runs, "--quiet"].iter().map(|s| s.to_string()).collect();
    args.extend(tiny_lift(iterations));
    args
}

/// The tiny lift run's overrides (CPU, 8 envs, short episodes, small nets).
fn tiny_lift(iterations: u32) -> Vec<String> {
    [
        "sim.backend=cpu".to_string(),
        "train.device=cpu".into(),
        "sim.num_envs=8".into(),
        "task.episode_length=6".into(),
        format!("train.iterations={iterations}"),
        "train.steps_per_env=6".into(),
        "train.save_interval=100".into(),
        "train.plot_interval=0".into(),
        "policy.actor_hidden=[16, 16]".into(),
        "policy.critic_hidden=[16, 16]".into(),
    ]
    .into_iter()
    .flat_map(|s| ["--set".to_string(), s])
    .collect()
}

fn dextrain(args: &[String]) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_dextrain"));
    c.args(args).current_dir(ROOT);
    c
}

/// Starts `dextrain ARGS` and reads its stderr until the live view's address; the rest of stderr is
/// drained (and returned) by a thread.
fn spawn_live(args: &[String]) -> (Child, String, std::thread::JoinHandle<String>) {
    let mut child = dextrain(args).stdout(Stdio::piped()).stderr(Stdio::piped()).spawn().unwrap();
    let mut lines = BufReader::new(child.stderr.take().unwrap()).lines();
    let mut seen = String::new();
    let url = loop {
        let line = lines.next().unwrap_or_else(|| panic!("dextrain ended before serving the live view: {seen}")).unwrap();
        seen.push_str(&line);
        seen.push('\n');
        if let Some(i) = line.find("ws://") {
            break line[i..].split_whitespace().next().unwrap().to_string();
        }
    };
    let rest = std::thread::spawn(move || lines.map_while(Result::ok).collect::<Vec<_>>().join("\n"));
    (child, url, rest)
}

/// Whether the Python client can run (`websockets` importable), or why not (REQUIRE_PYTHON_WEBSOCKETS=1: fail).
fn client_available(test: &str) -> bool {
    let required = std::env::var("REQUIRE_PYTHON_WEBSOCKETS").is_ok_and(|v| v == "1");
    let probe = Command::new("python3").args(["-c", "import websockets.sync.client, jsonschema"]).output();
    if probe.as_ref().is_ok_and(|o| o.status.success()) {
        return true;
    }
    assert!(!required, "REQUIRE_PYTHON_WEBSOCKETS=1 but Python's websockets and jsonschema are not importable (pip install websockets jsonschema)");
    eprintln!("{test}: SKIPPED: Python's websockets or jsonschema is not importable (pip install websockets jsonschema)");
    false
}

/// Runs the Python client against `url` until it has `scenes` scene and `metrics` metrics messages.
fn client(url: &str, scenes: usize, metrics: usize) -> serde_json::Value {
    let out = Command::new("python3")
        .arg(Path::new(ROOT).join("tests/live_client.py"))
        .args([url, "--scenes", &scenes.to_string(), "--metrics", &metrics.to_string(), "--timeout", "120"])
        .output()
        .unwrap();
    assert!(out.status.success(), "live client failed: {}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_slice(&out.stdout).unwrap()
}

/// The one JSON line a command prints on stdout.
fn summary(child: Child) -> serde_json::Value {
    let out = child.wait_with_output().unwrap();
    assert!(out.status.success(), "dextrain failed");
    let text = String::from_utf8_lossy(&out.stdout);
    serde_json::from_str(text.lines().last().unwrap()).unwrap()
}

#[test]
fn a_foxglove_client_watches_a_training_run_and_gets_its_metrics_rows() {
    if !client_available("live training") {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let runs = tmp.path().to_str().unwrap().to_string();
    let mut args = tiny_lift_train(&runs, "live", 12);
    args.extend(["--live", "127.0.0.1:0", "--live-envs", "3", "--live-hz", "1000", "--live-wait"].map(String::from));
    let (child, url, _stderr) = spawn_live(&args);
    let got = client(&url, 3, 2);
    let s = summary(child);

    assert_eq!(got["subprotocol"], "foxglove.sdk.v1");
    assert_eq!(got["server_op"], "serverInfo");
    for (topic, schema) in [("/tf", "foxglove.FrameTransforms"), ("/scene", "foxglove.SceneUpdate"), ("/dextrain/metrics", "dextrain.Metrics")] {
        let c = &got["channels"][topic];
        assert_eq!(c["encoding"], "json", "{topic}");
        assert_eq!(c["schemaEncoding"], "jsonschema", "{topic}");
        assert_eq!(c["schemaName"], schema, "{topic}");
    }
    assert_eq!(got["validated"], true, "every message matches its advertised schema: {}", got["errors"]);

    // the scene: three envs, each its hand's links, object and table, and contacts, under envK/
    let cfg = dextrain::config::Config::load(&Path::new(ROOT).join("configs/lift_cube_cpu.toml")).unwrap();
    let links = dextrain::env::SimModel::from_config(&cfg).unwrap().hand.links.len();
    for scene in got["scenes"].as_array().unwrap() {
        let ids: Vec<&str> = scene["entity_ids"].as_array().unwrap().iter().map(|v| v.as_str().unwrap()).collect();
        for k in 0..3 {
            let prefix = format!("env{k}/");
            let mine: Vec<&&str> = ids.iter().filter(|i| i.starts_with(&prefix)).collect();
            for e in ["object", "table", "contacts"] {
                assert!(mine.contains(&&&*format!("{prefix}{e}")), "{e} of env {k} in {ids:?}");
            }
            assert_eq!(mine.iter().filter(|i| i.starts_with(&format!("{prefix}hand/"))).count(), links, "env {k}'s hand links");
        }
        assert!(ids.iter().all(|i| ["env0/", "env1/", "env2/"].iter().any(|p| i.starts_with(p))), "only the 3 shown envs: {ids:?}");
        // the lift task has no reference: its ghost is deleted, not drawn
        assert!(scene["deletions"].as_array().unwrap().iter().any(|d| d == "env0/object_ref"));
    }
    // the transforms place env k's world in a grid 0.6 m apart (2 columns for 3 envs)
    let tf = &got["tf"][0];
    let place = |child: &str| -> Vec<f64> {
        let t = tf.as_array().unwrap().iter().find(|t| t[0] == "world" && t[1] == child).unwrap_or_else(|| panic!("world → {child} in {tf}"));
        ["x", "y", "z"].iter().map(|a| t[2][a].as_f64().unwrap()).collect()
    };
    assert_eq!(place("env0/world"), vec![0.0, 0.0, 0.0]);
    let p1 = place("env1/world");
    assert!((p1[0] - 0.6).abs() < 1e-6 && p1[1].abs() < 1e-6, "{p1:?}");
    let p2 = place("env2/world");
    assert!(p2[0].abs() < 1e-6 && (p2[1] - 0.6).abs() < 1e-6, "{p2:?}");
    // every link frame hangs off its env's world
    let env1_children = tf.as_array().unwrap().iter().filter(|t| t[0] == "env1/world").count();
    assert!(env1_children > 5, "{tf}");

    // the metrics messages are the run's metrics.csv rows, nested by '/'
    let dir = Path::new(&runs).join("live");
    let (cols, rows) = dextrain::metrics::read_csv(&dir.join("metrics.csv")).unwrap();
    let metrics = got["metrics"].as_array().unwrap();
    assert!(metrics.len() >= 2);
    for m in metrics {
        let it = m["iteration"].as_u64().unwrap();
        let (_, row) = rows.iter().find(|(i, _)| *i == it).unwrap_or_else(|| panic!("iteration {it} in metrics.csv"));
        for (c, v) in cols.iter().zip(row) {
            let path: Vec<&str> = c.split('/').collect();
            let mut node = m;
            for p in &path {
                node = &node[*p];
            }
            match node.as_f64() {
                Some(x) => assert!((x - v).abs() <= 1e-9 * v.abs().max(1.0), "{c} at iteration {it}: message {x}, metrics.csv {v}"),
                None => assert!(node.is_null() && !v.is_finite(), "{c} at iteration {it}: message {node}, metrics.csv {v}"),
            }
        }
    }
    for term in dextrain::config::rewards::reward_terms(dextrain::config::TaskKind::Lift) {
        assert!(metrics[0]["reward"][term.name].is_number(), "reward term {} in {}", term.name, metrics[0]);
    }
    assert!(s["live"]["scene_messages"].as_u64().unwrap() >= 3 && s["live"]["metrics_messages"].as_u64().unwrap() >= 2, "{}", s["live"]);

    // the run's own layout is the shipped one (the lift task's terms, PPO's losses), and every
    // plotted path is a column of the run
    let written: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(dir.join("foxglove_layout.json")).unwrap()).unwrap();
    let shipped: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(Path::new(ROOT).join("assets/foxglove/dextrain.json")).unwrap()).unwrap();
    assert_eq!(written, shipped, "assets/foxglove/dextrain.json is stale: copy a lift run's foxglove_layout.json over it");
    check_layout(&shipped, &cols);
}

/// Every leaf of the layout's tree is a configured panel, and every plotted path is `/dextrain/metrics.`
/// + a column (or the iteration).
fn check_layout(layout: &serde_json::Value, cols: &[String]) {
    fn leaves<'a>(node: &'a serde_json::Value, out: &mut Vec<&'a str>) {
        match node.as_str() {
            Some(id) => out.push(id),
            None => {
                leaves(&node["first"], out);
                leaves(&node["second"], out);
            }
        }
    }
    let mut ids = Vec::new();
    leaves(&layout["layout"], &mut ids);
    assert!(ids.len() >= 4 && ids.contains(&"3D!scene"), "{ids:?}");
    for id in &ids {
        assert!(layout["configById"][id].is_object(), "panel {id} has a config");
    }
    let paths: Vec<String> = cols.iter().map(|c| format!("/dextrain/metrics.{}", c.replace('/', "."))).chain(["/dextrain/metrics.iteration".to_string()]).collect();
    let mut plotted = 0;
    for (id, panel) in layout["configById"].as_object().unwrap() {
        if !id.starts_with("Plot!") {
            continue;
        }
        for p in panel["paths"].as_array().unwrap().iter().map(|p| &p["value"]).chain([&panel["xAxisPath"]["value"]]) {
            assert!(paths.iter().any(|c| c == p.as_str().unwrap()), "{id} plots {p}, not a column");
            plotted += 1;
        }
    }
    assert!(plotted >= 10, "{plotted} plotted paths");
}

#[test]
fn an_eval_serves_its_episodes_live_and_a_run_without_a_client_sends_nothing() {
    let tmp = tempfile::tempdir().unwrap();
    let runs = tmp.path().to_str().unwrap().to_string();
    // nobody connects: the run trains as usual and the view sends nothing
    let mut args = tiny_lift_train(&runs, "quiet", 2);
    args.extend(["--live=127.0.0.1:0".to_string()]);
    let out = dextrain(&args).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let s: serde_json::Value = serde_json::from_str(String::from_utf8_lossy(&out.stdout).lines().last().unwrap()).unwrap();
    assert_eq!(s["live"]["scene_messages"], 0);
    assert_eq!(s["live"]["metrics_messages"], 0);
    assert!(s["live"]["url"].as_str().unwrap().starts_with("ws://127.0.0.1:"));

    // bad addresses: one line naming --live and what was expected
    let run = Path::new(&runs).join("quiet");
    let run_s = run.to_str().unwrap().to_string();
    for bad in ["nonsense", "127.0.0.1:99999", "127.0.0.1:http"] {
        let out = dextrain(&["eval".into(), run_s.clone(), "--episodes".into(), "1".into(), format!("--live={bad}")]).output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success());
        assert_eq!(err.trim_end().lines().count(), 1, "{err}");
        assert!(err.contains("--live") && err.contains("HOST:PORT"), "{err}");
    }
    // a port in use
    let taken = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let port = taken.local_addr().unwrap().port();
    let out = dextrain(&["eval".into(), run_s.clone(), "--episodes".into(), "1".into(), format!("--live=127.0.0.1:{port}")]).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("cannot serve the live view"), "{err}");

    if !client_available("live eval") {
        return;
    }
    // an eval: two envs' episodes, every step (no metrics channel)
    // (at real time: one control step of wall time per step)
    let args: Vec<String> = ["eval", &run_s, "--episodes", "4", "--backend", "cpu", "--live", "127.0.0.1:0", "--live-envs", "2", "--live-wait"].iter().map(|s| s.to_string()).collect();
    let (child, url, _stderr) = spawn_live(&args);
    let got = client(&url, 3, 0);
    let out = child.wait_with_output().unwrap();
    assert!(out.status.success());
    assert!(got["channels"].get("/dextrain/metrics").is_none(), "{}", got["channels"]);
    assert_eq!(got["validated"], true, "{}", got["errors"]);
    let scenes = got["scenes"].as_array().unwrap();
    assert!(scenes.len() >= 3);
    for scene in scenes {
        let ids = scene["entity_ids"].as_array().unwrap();
        assert!(ids.iter().any(|i| i == "env1/object") && ids.iter().all(|i| i.as_str().unwrap().starts_with("env0/") || i.as_str().unwrap().starts_with("env1/")), "{ids:?}");
    }
}

#[test]
fn a_client_that_connects_mid_run_first_gets_the_metrics_rows_so_far() {
    if !client_available("live history") {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let runs = tmp.path().to_str().unwrap().to_string();
    // long enough to still run when the client comes; stopped once the client has its rows
    let mut args = tiny_lift_train(&runs, "late", 5000);
    args.extend(["--live=127.0.0.1:0".to_string()]);
    let (mut child, url, _stderr) = spawn_live(&args);
    let csv = Path::new(&runs).join("late/metrics.csv");
    let rows_now = || std::fs::read_to_string(&csv).map(|t| t.lines().count().saturating_sub(1)).unwrap_or(0);
    let t0 = std::time::Instant::now();
    while rows_now() < 6 {
        assert!(t0.elapsed().as_secs() < 120, "the run wrote no 6 rows in 2 minutes");
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    let before = rows_now();
    let got = client(&url, 0, before + 3);
    // SIGTERM: the run ends its iteration, writes a checkpoint and stops (no torn row)
    assert!(Command::new("kill").args(["-TERM", &child.id().to_string()]).status().unwrap().success());
    assert!(child.wait().unwrap().success());

    // the replayed rows from iteration 1, then the live ones: consecutive (a row sent while the
    // client subscribed may come twice)
    let mut its: Vec<u64> = got["metrics"].as_array().unwrap().iter().map(|m| m["iteration"].as_u64().unwrap()).collect();
    its.dedup();
    assert_eq!(its[0], 1, "{its:?}");
    assert!(its.windows(2).all(|w| w[1] == w[0] + 1), "{its:?}");
    assert!(its.len() >= before + 3, "{} rows, {before} in metrics.csv at the connection", its.len());
    let (cols, rows) = dextrain::metrics::read_csv(&csv).unwrap();
    let reward = |it: u64| rows.iter().find(|(i, _)| *i == it).map(|(_, v)| v.clone()).unwrap();
    let k = cols.iter().position(|c| c == "reward/mean").unwrap();
    for m in got["metrics"].as_array().unwrap() {
        let it = m["iteration"].as_u64().unwrap();
        // (serde_json's default float parsing may be 1 ulp off)
        let (x, v) = (m["reward"]["mean"].as_f64().unwrap(), reward(it)[k]);
        assert!((x - v).abs() <= 1e-12 * v.abs().max(1.0), "reward/mean at iteration {it}: message {x}, metrics.csv {v}");
    }
}
