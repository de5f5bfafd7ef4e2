//! `policy.json`, the exported policy's contract: built from each shipped task, it describes every
//! observation field once and exactly (offsets cover the input), names joints and actions, carries
//! the action mapping's constants as the simulator uses them, and reads back to the same value.

use dextrain::config::{Config, TaskKind};
use dextrain::env::SimModel;
use dextrain::export::contract::{ActionMapping, ContractSource, PolicyContract, Source, TensorIo, build, computed};
use dextrain::task::spec::OBS_FIELDS;
use dextrain::task::task_setup;

const ROOT: &str = env!("CARGO_MANIFEST_DIR");

fn io(name: &str) -> TensorIo {
    TensorIo { name: name.into(), shape: vec!["batch".into()], description: String::new() }
}

fn contract_of(config: &str) -> (Config, PolicyContract) {
    let cfg = Config::load(std::path::Path::new(&format!("{ROOT}/configs/{config}"))).unwrap();
    let model = SimModel::from_config(&cfg).unwrap();
    let setup = task_setup(&cfg, &model).unwrap();
    let fields: Vec<String> = setup.spec.obs_layout.iter().map(|s| s.name.clone()).collect();
    let src = ContractSource {
        source: Source { run: "runs/x".into(), checkpoint: 7, checkpoint_xxh64: "0".repeat(16), algorithm: "ppo".into(), teacher: None },
        model_file: "policy.onnx",
        model_bytes: b"bytes",
        inputs: vec![io("obs")],
        output: io("actions"),
        obs_fields: fields,
        priv_fields: None,
        history: Some((vec!["q".into(), "prev_action".into()], 30)),
    };
    let c = build(&cfg, &setup.spec, &setup.tc, &model, src).unwrap();
    (cfg, c)
}

#[test]
fn every_observation_field_has_a_description() {
    for f in OBS_FIELDS {
        assert!(computed(f.name).is_some() || f.per_reference_frame, "{} has no description", f.name);
    }
}

#[test]
fn the_contract_of_each_task_kind_covers_its_inputs_and_reads_back() {
    let tmp = tempfile::tempdir().unwrap();
    for (config, kind) in [
        ("lift_cube_cpu.toml", TaskKind::Lift),
        ("track_cube.toml", TaskKind::Track),
        ("residual_joint_cube.toml", TaskKind::ResidualJoint),
        ("residual_task_cube.toml", TaskKind::ResidualTask),
    ] {
        let (cfg, c) = contract_of(config);
        assert_eq!(c.task.kind, kind);
        c.check().unwrap();
        // the observation layout is the task's, field by field, and its entries are the spec's names
        let model = SimModel::from_config(&cfg).unwrap();
        let spec = task_setup(&cfg, &model).unwrap().spec;
        assert_eq!(c.observation.size, spec.obs_dim, "{config}");
        let entries: Vec<String> = c.observation.fields.iter().flat_map(|f| f.entries.clone()).collect();
        assert_eq!(entries, spec.obs_names, "{config}");
        assert!(c.observation.fields.iter().all(|f| !f.computed.is_empty()));
        // the noise training added is the config's
        let q = c.observation.fields.iter().find(|f| f.name == "q").unwrap();
        assert_eq!(q.training_noise_std, cfg.task.obs_noise.joint_pos);
        // actions: 6 wrist actions, then one per actuated joint named after the URDF joint (or,
        // residual_task, 3 per fingertip)
        assert_eq!(c.actions.names, spec.action_names);
        if kind == TaskKind::ResidualTask {
            assert_eq!(c.actions.size, 6 + 3 * c.hand.fingertips.len());
        } else {
            for (k, j) in c.hand.actuated.iter().enumerate() {
                assert_eq!(c.actions.names[6 + k], format!("q.{j}"), "{config}");
            }
        }
        // the history: H rows of q and prev_action
        let h = c.history.as_ref().unwrap();
        assert_eq!((h.length, h.step.size), (30, 2 * model.spec.actuated.len() + spec.action_dim - model.spec.actuated.len()));
        // the mapping carries the config's constants
        match (&c.action_mapping, kind) {
            (ActionMapping::Direct { wrist_pos_scale, finger_mode, .. }, TaskKind::Lift) => {
                assert_eq!(*wrist_pos_scale, cfg.task.action.wrist_pos_scale);
                assert_eq!(*finger_mode, cfg.task.action.finger_mode);
            }
            (ActionMapping::ResidualJoint { joint_alpha, .. }, TaskKind::ResidualJoint | TaskKind::Track) => assert_eq!(*joint_alpha, cfg.task.residual.alpha),
            (ActionMapping::ResidualTask { ema, clamp_tips, .. }, TaskKind::ResidualTask) => {
                assert_eq!((*ema, *clamp_tips), (cfg.task.residual.ema, cfg.task.residual.clamp_tips));
            }
            (m, k) => panic!("{config}: kind {k} got mapping {m:?}"),
        }
        assert_eq!(c.task.reference.is_some(), kind.follows_reference());
        // the URDF's hash is its bytes'
        let urdf = std::fs::read(cfg.resolve(&cfg.hand.urdf)).unwrap();
        assert_eq!(c.hand.urdf_xxh64, format!("{:016x}", dextrain::learn::checkpoint::xxh64(&urdf, 0)));
        // round trip through the file
        let p = tmp.path().join(format!("{config}.json"));
        std::fs::write(&p, serde_json::to_string_pretty(&c).unwrap()).unwrap();
        assert_eq!(PolicyContract::read(&p).unwrap(), c, "{config}");
    }
}

#[test]
fn a_damaged_contract_is_a_one_line_error_naming_the_field() {
    let tmp = tempfile::tempdir().unwrap();
    let (_, c) = contract_of("residual_task_cube.toml");
    let p = tmp.path().join("policy.json");
    // a field that is not a number
    let mut v = serde_json::to_value(&c).unwrap();
    v["control"]["control_dt"] = serde_json::json!("fast");
    std::fs::write(&p, v.to_string()).unwrap();
    let e = format!("{:#}", PolicyContract::read(&p).unwrap_err());
    assert!(e.contains("policy.json") && e.contains("control.control_dt") && !e.contains('\n'), "{e}");
    // a layout whose offsets do not add up
    let mut bad = c.clone();
    bad.observation.fields[1].offset += 1;
    std::fs::write(&p, serde_json::to_string(&bad).unwrap()).unwrap();
    let e = format!("{:#}", PolicyContract::read(&p).unwrap_err());
    assert!(e.contains("observation.fields") && e.contains("offset"), "{e}");
    // not JSON at all
    std::fs::write(&p, b"\x00\xffnot json").unwrap();
    let e = format!("{:#}", PolicyContract::read(&p).unwrap_err());
    assert!(e.contains("policy.json") && !e.contains('\n'), "{e}");
}
