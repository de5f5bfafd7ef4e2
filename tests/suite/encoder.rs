//! The privileged encoder of a teacher policy (`[policy.encoder]`): its inputs are the named
//! critic-observation fields (checked against the simulator's drawn parameters), its latent is
//! what the actor reads beside the observation, a run with it trains and resumes exactly, and an
//! unknown input name is a one-line error listing the allowed ones.

use std::path::Path;

use dextrain::config::{Config, EncoderConfig};
use dextrain::env::SimModel;
use dextrain::learn::nets::{to_host, to_tensor};
use dextrain::learn::ppo::{Dims, Ppo, encoder_index};
use dextrain::task::make_task_batch;
use dextrain::train::{TrainArgs, run as train};

const CONFIG: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/configs/lift_cube_cpu.toml");

fn config(sets: &[&str]) -> Config {
    let sets: Vec<String> = sets.iter().map(|s| s.to_string()).collect();
    Config::load_with_overrides(Path::new(CONFIG), &sets).unwrap()
}

#[test]
fn the_encoder_reads_the_named_privileged_fields() {
    let mut cfg = config(&["sim.backend=cpu", "sim.num_envs=4", "randomization.object_mass=[0.5, 1.5]", "randomization.object_friction=[0.6, 1.2]"]);
    cfg.policy.obs_normalization = false;
    cfg.policy.encoder = Some(EncoderConfig { inputs: vec!["obj_friction".into(), "obj_mass".into()], hidden: vec![], latent: 2, ..EncoderConfig::default() });
    cfg.validate().unwrap();
    let model = SimModel::from_config(&cfg).unwrap();
    let mut task = make_task_batch(&cfg, model).unwrap();
    let spec = task.spec().clone();
    let first = task.reset_all().unwrap().clone();
    let params = task.env().params().unwrap();
    let idx = encoder_index(&cfg.policy, &spec).unwrap();
    assert_eq!(idx.len(), 2);
    assert_eq!((spec.priv_names[idx[0]].as_str(), spec.priv_names[idx[1]].as_str()), ("obj_friction", "obj_mass"));
    for (i, p) in params.iter().enumerate() {
        // the drawn friction and mass of each env, in the order the config names them
        let e = [first.priv_obs[i * spec.priv_dim + idx[0]], first.priv_obs[i * spec.priv_dim + idx[1]]];
        assert_eq!(e, [p.obj_friction, p.obj_inertia[3]], "env {i}");
    }
    assert!(params.windows(2).any(|w| w[0].obj_inertia[3] != w[1].obj_inertia[3]), "masses are drawn per env");
    // with an identity encoder (one layer, W = I, b = 0) the latent is exactly those values
    let dims = Dims { obs: spec.obs_dim, priv_obs: spec.priv_dim, act: spec.action_dim };
    let device = burn::prelude::Device::flex();
    let mut ppo = Ppo::new(dims, 4, 1, &cfg.ppo, &cfg.policy, &idx, device.clone(), 1).unwrap();
    let mut values = ppo.net.values().unwrap();
    let n = values.len();
    values[n - 2] = vec![1.0, 0.0, 0.0, 1.0];
    values[n - 1] = vec![0.0, 0.0];
    ppo.net.set_values(values, &device).unwrap();
    let z = to_host(ppo.net.latent(&ppo.net.inference_params(), to_tensor(first.priv_obs.clone(), [4, spec.priv_dim], &device)).unwrap()).unwrap();
    for i in 0..4 {
        assert_eq!([z[2 * i], z[2 * i + 1]], [params[i].obj_friction, params[i].obj_inertia[3]]);
    }
    // the actor's first layer reads the observation and the latent: [O + L, hidden]
    assert_eq!(ppo.net.actor_shapes[0], [spec.obs_dim + 2, cfg.policy.actor_hidden[0]]);
    // the latent moves the action: other masses, other actions for the same observation
    let a = ppo.act_mean(&first.obs, &first.priv_obs).unwrap();
    let mut other = first.priv_obs.clone();
    for i in 0..4 {
        other[i * spec.priv_dim + idx[1]] += 1.0;
    }
    assert_ne!(a, ppo.act_mean(&first.obs, &other).unwrap());
}

#[test]
fn an_unknown_encoder_input_is_a_one_line_error_listing_the_allowed_names() {
    let sets = vec!["policy.encoder.inputs=[\"obj_mass\", \"obj_colour\"]".to_string()];
    let e = format!("{:#}", Config::load_with_overrides(Path::new(CONFIG), &sets).and_then(|c| dextrain::task::setup::check_config(&c)).unwrap_err());
    assert!(e.contains("lift_cube_cpu.toml") && e.contains("policy.encoder.inputs") && e.contains("obj_colour") && e.contains("obj_friction") && !e.contains('\n'), "{e}");
}

#[test]
fn a_teacher_with_an_encoder_trains_resumes_exactly_and_exports() {
    use dextrain::export::command::{ExportArgs, run as export};
    let tmp = tempfile::tempdir().unwrap();
    let sets: Vec<String> = [
        "sim.backend=cpu",
        "train.device=cpu",
        "sim.num_envs=8",
        "task.episode_length=5",
        "train.iterations=4",
        "train.steps_per_env=4",
        "train.save_interval=2",
        "train.plot_interval=0",
        "policy.actor_hidden=[16]",
        "policy.critic_hidden=[16]",
        "policy.encoder.inputs=[\"obj_mass\", \"obj_friction\", \"obj_vel\", \"tip_contact\"]",
        "policy.encoder.hidden=[8]",
        "policy.encoder.latent=3",
        "randomization.object_mass=[0.5, 1.5]",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    let args = |name: &str| TrainArgs { config: Some(CONFIG.into()), sets: sets.clone(), name: Some(name.into()), resume: None, force: false, runs_dir: tmp.path().into(), stop_after: None, quiet: true, live: Default::default(), gpu_profile: false };
    let a = train(&args("a")).unwrap();
    let mut b_args = args("b");
    b_args.stop_after = Some(2);
    let b = train(&b_args).unwrap();
    train(&TrainArgs { config: None, sets: vec![], name: None, resume: Some(b.clone()), ..args("unused") }).unwrap();
    let model = |d: &Path| std::fs::read(d.join("checkpoints/4/model.safetensors")).unwrap();
    assert_eq!(model(&a), model(&b), "resumed teacher differs from the straight run");
    let text = String::from_utf8_lossy(&model(&a)).into_owned();
    assert!(text.contains("encoder.0.weight") && text.contains("encoder.1.bias"), "the encoder's parameters are in the checkpoint");
    // the exported teacher: obs and priv_obs inputs, verified against burn
    let r = export(&ExportArgs { run: a.clone(), checkpoint: "latest".into(), out: None, verify: true }).unwrap();
    assert!(r.max_abs_diff.unwrap() <= 1e-5, "{r:?}");
    let c = dextrain::export::contract::PolicyContract::read(&a.join("export/policy.json")).unwrap();
    assert_eq!(c.model.inputs.iter().map(|i| i.name.as_str()).collect::<Vec<_>>(), ["obs", "priv_obs"]);
    assert!(c.privileged.as_ref().unwrap().fields.iter().any(|f| f.name == "obj_mass"));
}
