//! Config parsing, validation and `dextrain check`: every error is one line naming the file, the key,
//! the value and what is allowed; unknown keys are errors; the resolved config has every default.

use std::path::Path;
use std::process::Command;

use dextrain::config::Config;

fn err_of(text: &str) -> String {
    let e = Config::from_toml_str(text, Path::new("configs/bad.toml")).expect_err("should fail");
    let msg = format!("{e:#}");
    assert!(!msg.contains('\n'), "error must be one line: {msg:?}");
    assert!(msg.contains("configs/bad.toml"), "error must name the file: {msg}");
    msg
}

#[test]
fn every_shipped_config_loads_and_builds_its_model() {
    let shared = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/hands");
    let mut real_hands = 0;
    for entry in std::fs::read_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/configs")).unwrap() {
        let p = entry.unwrap().path();
        if p.extension().is_some_and(|e| e == "toml") {
            let cfg = Config::load(&p).unwrap_or_else(|e| panic!("{}: {e:#}", p.display()));
            let urdf = cfg.resolve(&cfg.hand.urdf);
            // the YCB examples read the meshes of ../shared/objects, which the project does not ship:
            // without them the error names the missing mesh
            let missing: Vec<String> = cfg
                .object
                .items()
                .iter()
                .filter_map(|(_, it)| it.mesh.as_ref().map(|m| m.files().iter().map(|f| f.to_string()).collect::<Vec<_>>()))
                .flatten()
                .filter(|f| !cfg.resolve(f).is_file())
                .collect();
            if !missing.is_empty() {
                assert!(missing.iter().all(|f| f.contains("shared/objects/")), "{}: meshes {missing:?} do not exist", p.display());
                let e = format!("{:#}", dextrain::env::SimModel::from_config(&cfg).unwrap_err());
                assert!(missing.iter().any(|f| e.contains(f.trim_start_matches("../"))) && !e.contains('\n'), "{}: {e}", p.display());
                eprintln!("every_shipped_config_loads_and_builds_its_model: {}: {} missing; not built", p.display(), missing[0]);
                continue;
            }
            if urdf.exists() {
                let model = dextrain::env::SimModel::from_config(&cfg).unwrap_or_else(|e| panic!("{}: {e:#}", p.display()));
                // the human-demonstration example reads the reference its walkthrough's `traj
                // retarget` writes under runs/ (not shipped): without it the error names the file
                let made: Vec<&String> = cfg.task.reference.files.iter().filter(|f| f.contains("runs/") && !cfg.resolve(f).exists()).collect();
                if let Some(f) = made.first() {
                    let e = format!("{:#}", dextrain::task::task_setup(&cfg, &model).err().unwrap_or_else(|| panic!("{}: no error for the missing {f}", p.display())));
                    assert!(e.contains(f.trim_start_matches("../")) && !e.contains('\n'), "{}: {e}", p.display());
                    eprintln!("every_shipped_config_loads_and_builds_its_model: {}: {f} missing (made by its walkthrough); task not built", p.display());
                    continue;
                }
                dextrain::task::task_setup(&cfg, &model).unwrap_or_else(|e| panic!("{}: {e:#}", p.display()));
                continue;
            }
            // the real-hand examples name a dex-urdf clone the project does not ship: without it the
            // error names the file; with ../shared/hands (the same URDFs) they load and build their task
            assert!(cfg.hand.urdf.contains("dex-urdf/robots/hands/"), "{}: hand.urdf {} does not exist", p.display(), urdf.display());
            let e = format!("{:#}", dextrain::env::SimModel::from_config(&cfg).unwrap_err());
            assert!(e.contains(&cfg.hand.urdf) || e.contains(&*urdf.to_string_lossy()), "{}: {e}", p.display());
            let name = urdf.file_name().unwrap();
            let Some(copy) = std::fs::read_dir(&shared).into_iter().flatten().map(|d| d.unwrap().path().join(name)).find(|c| c.is_file()) else {
                eprintln!("every_shipped_config_loads_and_builds_its_model: {} has no {}; {} not loaded", shared.display(), name.to_string_lossy(), p.display());
                continue;
            };
            let set = format!("hand.urdf={:?}", copy.to_string_lossy());
            let cfg = Config::load_with_overrides(&p, &[set]).unwrap_or_else(|e| panic!("{}: {e:#}", p.display()));
            let model = dextrain::env::SimModel::from_config(&cfg).unwrap_or_else(|e| panic!("{}: {e:#}", p.display()));
            let task = dextrain::task::task_setup(&cfg, &model).unwrap_or_else(|e| panic!("{}: {e:#}", p.display())).spec;
            // one tip per finger, the thumb among them, and no warning about the fingertips
            assert_eq!(model.hand.fingertips.len(), model.hand.finger_chains().len(), "{}", p.display());
            assert!(model.hand.warnings.iter().all(|w| !w.contains("finger chains")), "{}: {:?}", p.display(), model.hand.warnings);
            assert_eq!(task.action_dim, 6 + model.spec.actuated.len(), "{}", p.display());
            real_hands += 1;
        }
    }
    if shared.is_dir() {
        assert!(real_hands >= 2, "the Allegro and LEAP examples should load from {}", shared.display());
    }
}

#[test]
fn malformed_toml_names_the_line() {
    let m = err_of("[sim]\nnum_envs = = 3\n");
    assert!(m.contains("bad.toml:2:"), "{m}");
    assert!(m.contains("invalid TOML"), "{m}");
}

#[test]
fn unknown_keys_are_errors() {
    let m = err_of("[sim]\nnum_env = 3\n");
    assert!(m.contains("num_env") && m.contains("sim"), "{m}");
    let m = err_of("[simulation]\n");
    assert!(m.contains("simulation"), "{m}");
    let m = err_of("[object]\nshape = { type = \"box\", half_extent = [0.1, 0.1, 0.1] }\n");
    assert!(m.contains("half_extent"), "{m}");
}

#[test]
fn wrong_types_name_the_key() {
    let m = err_of("[sim]\ndt = \"fast\"\n");
    assert!(m.contains("sim.dt"), "{m}");
    let m = err_of("[object]\nshape = { type = \"cone\", radius = 0.1 }\n");
    assert!(m.contains("object.shape") && m.contains("cone"), "{m}");
}

#[test]
fn out_of_range_values_say_what_is_allowed() {
    for (toml, key, allowed) in [
        ("[sim]\ndt = -0.01\n", "sim.dt", "[1e-5, 0.1]"),
        ("[sim]\nnum_envs = 0\n", "sim.num_envs", "[1, 16777216]"),
        ("[sim]\nsubsteps = 0\n", "sim.substeps", "[1, 64]"),
        ("[sim]\nbackend = \"tpu\"\n", "sim.backend", "\"cpu\""),
        ("[object]\nmass = 0.0\n", "object.mass", "kg"),
        ("[object]\nrestitution = 1.5\n", "object.restitution", "[0, 1)"),
        ("[randomization]\nobject_mass = [1.0, 0.5]\n", "randomization.object_mass", "lo <= hi"),
        ("[randomization]\nadded_gravity = [0.0, -1.0]\n", "randomization.added_gravity", "0 <= lo"),
        ("[contact]\nstiffness = 0.0\n", "contact.stiffness", "N/m"),
        ("[hand]\nkp = -3.0\n", "hand.kp", ">= 0"),
    ] {
        let m = err_of(toml);
        assert!(m.contains(key), "{toml}: {m}");
        assert!(m.contains(allowed), "{toml}: {m}");
        assert!(m.contains(" = "), "{toml}: the value should be shown: {m}");
    }
}

#[test]
fn an_empty_config_names_the_key_of_its_default_hand() {
    // an empty config is valid; its default hand is looked for beside it, and the error says so
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("empty.toml");
    std::fs::write(&path, "").unwrap();
    let c = Config::load(&path).unwrap();
    let e = format!("{:#}", dextrain::env::SimModel::from_config(&c).unwrap_err());
    assert!(e.contains("empty.toml") && e.contains("`hand.urdf`") && e.contains("the default") && e.contains("dexhand16.urdf") && !e.contains('\n'), "{e}");
}

#[test]
fn unknown_joint_names_and_missing_urdf_are_clear() {
    let mut c = Config::from_toml_str("[hand]\nurdf = \"hands/dexhand16.urdf\"\ninit_joints = { if_j9 = 0.1 }\n", Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/configs/x.toml"))).unwrap();
    let e = format!("{:#}", dextrain::env::SimModel::from_config(&c).unwrap_err());
    assert!(e.contains("hand.init_joints.if_j9") && e.contains("if_j0"), "{e}");
    c.hand.urdf = "hands/missing.urdf".into();
    let e = format!("{:#}", dextrain::env::SimModel::from_config(&c).unwrap_err());
    assert!(e.contains("missing.urdf") && !e.contains('\n'), "{e}");
}

#[test]
fn check_prints_the_resolved_config_with_every_default() {
    let out = Command::new(env!("CARGO_BIN_EXE_dextrain"))
        .args(["check", concat!(env!("CARGO_MANIFEST_DIR"), "/configs/grasp_lift.toml")])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = String::from_utf8(out.stdout).unwrap();
    // defaults the file does not set are printed
    for key in ["substeps = 4", "decimation = 4", "friction_stiffness", "[randomization]", "kp_lin", "hand_collision = true"] {
        assert!(text.contains(key), "missing {key} in:\n{text}");
    }
    // and the printed config is itself a valid config equal to the original
    let again = Config::from_toml_str(&text, Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/configs/printed.toml"))).unwrap();
    let orig = Config::load(Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/configs/grasp_lift.toml"))).unwrap();
    assert_eq!(again.sim, orig.sim);
    assert_eq!(again.randomization, orig.randomization);
    assert_eq!(again.object, orig.object);
}

#[test]
fn cli_errors_are_one_line_and_exit_nonzero() {
    let dir = tempfile::tempdir().unwrap();
    let bad = dir.path().join("bad.toml");
    std::fs::write(&bad, "[sim]\nnum_envs = -4\n").unwrap();
    for args in [vec!["check", bad.to_str().unwrap()], vec!["check", "no/such/config.toml"]] {
        let out = Command::new(env!("CARGO_BIN_EXE_dextrain")).args(&args).output().unwrap();
        assert!(!out.status.success());
        let err = String::from_utf8(out.stderr).unwrap();
        assert_eq!(err.trim_end().lines().count(), 1, "one line: {err}");
        assert!(err.contains(".toml"), "{err}");
    }
}

#[test]
fn task_and_learner_keys_are_checked_with_one_line_errors() {
    let p = Path::new("run.toml");
    for (text, key, hint) in [
        ("[task.rewards]\nflying = 1.0\n", "task.rewards.flying", "reaching"),
        ("[task]\nkind = \"juggle\"\n", "task.kind", "lift"),
        ("[task.action]\nfinger_mode = \"torque\"\n", "task.action.finger_mode", "absolute"),
        ("[ppo]\nschedule = \"cosine\"\n", "ppo.schedule", "adaptive"),
        ("[ppo]\ngamma = 1.5\n", "ppo.gamma", "[0, 1]"),
        ("[ppo]\nminibatches = 100000\n", "ppo.minibatches", "sim.num_envs"),
        ("[policy]\nactor_hidden = []\n", "policy.actor_hidden", "non-empty"),
        ("[policy]\nactivation = \"gelu\"\n", "policy.activation", "elu"),
        ("[train]\ndevice = \"tpu\"\n", "train.device", "gpu:ADAPTER_NAME"),
        ("[train]\nsteps_per_env = 0\n", "train.steps_per_env", "[1, 100000]"),
        ("[train]\nalgorithm = \"distill\"\n[distill]\nteacher = \"t\"\neval_episodes = 0\n", "distill.eval_episodes", "[1, 65536]"),
    ] {
        let e = format!("{:#}", Config::from_toml_str(text, p).unwrap_err());
        assert!(e.contains("run.toml") && e.contains(key) && e.contains(hint) && !e.contains('\n'), "{text}: {e}");
    }
    // the defaults are valid and match docs/design.md §6
    let c = Config::from_toml_str("", p).unwrap();
    assert_eq!((c.ppo.clip_param, c.ppo.entropy_coef, c.ppo.epochs, c.ppo.minibatches, c.ppo.desired_kl), (0.2, 0.005, 5, 4, 0.01));
    assert_eq!((c.ppo.gamma, c.ppo.lam, c.ppo.learning_rate, c.ppo.max_grad_norm), (0.99, 0.95, 5e-4, 1.0));
}

#[test]
fn reference_task_keys_are_checked_and_each_kind_has_its_default_rewards() {
    let p = Path::new("run.toml");
    let track = "[task]\nkind = \"track\"\n[task.reference]\nfiles = [\"refs/grasp_lift.mcap\"]\n";
    for (text, key, hint) in [
        ("[task]\nkind = \"track\"\n".to_string(), "task.reference.files", "at least one reference"),
        (format!("{track}[task.track]\nstart = \"table\"\n"), "task.track.start", "\"config\""),
        (format!("{track}[task.track]\naction = \"joint\"\n"), "task.track.action", "\"free\""),
        (format!("{track}[task.track]\nlookahead = 20\n"), "task.track.lookahead", "[0, 8]"),
        (format!("{track}[task.track]\nsuccess_pos_tol = 0\n"), "task.track.success_pos_tol", "distance"),
        (format!("{track}[task.track]\nalpha_joint = -1\n"), "task.track.alpha_joint", ">= 0"),
        (format!("{track}[task.residual]\nema = 0\n"), "task.residual.ema", "[0.001, 1]"),
        (format!("{track}[task.residual]\nclamp_wrist_rot = 4\n"), "task.residual.clamp_wrist_rot", "π"),
        (format!("{track}[task.reference]\nmirror_prob = 2\n").replace("[task.reference]\nfiles = [\"refs/grasp_lift.mcap\"]\n[task.reference]\n", "[task.reference]\nfiles = [\"refs/grasp_lift.mcap\"]\n"), "task.reference.mirror_prob", "probability"),
        (format!("{track}[task.rewards]\nreaching = 1.0\n"), "task.rewards.reaching", "hand_following"),
        ("[task]\nkind = \"lift\"\nepisode_length = 0\n".to_string(), "task.episode_length", "[1, 1000000]"),
    ] {
        let e = format!("{:#}", Config::from_toml_str(&text, p).unwrap_err());
        assert!(e.contains("run.toml") && e.contains(key) && e.contains(hint) && !e.contains('\n'), "{text}: {e}");
    }
    // without a [task.rewards] table every kind gets its own default weights (the papers')
    for kind in dextrain::config::TaskKind::ALL {
        let text = if kind == dextrain::config::TaskKind::Lift { String::new() } else { track.replace("track", kind.name()) };
        let c = Config::from_toml_str(&text, p).unwrap();
        assert_eq!(c.task.rewards, kind.default_rewards(), "{kind}");
        let names: Vec<&str> = c.task.rewards.keys().map(|k| k.as_str()).collect();
        let mut want: Vec<&str> = kind.term_names();
        want.sort();
        assert_eq!(names, want, "{kind}: a default weight for every term");
    }
    let c = Config::from_toml_str(track, p).unwrap();
    assert_eq!((c.task.rewards["hand_following"], c.task.rewards["success"]), (1.0, 15.0));
    assert_eq!((c.task.track.beta_joint, c.task.track.beta_wrist_pos, c.task.track.alpha_object_pos), (0.1, 1.0, 1.0));
    assert_eq!((c.task.residual.alpha, c.task.residual.ema, c.task.residual.clamp_tips), (0.1, 0.8, 0.04));
}

#[test]
fn set_overrides_apply_before_validation() {
    let dir = tempfile::tempdir().unwrap();
    let f = dir.path().join("c.toml");
    std::fs::write(&f, "[ppo]\nlearning_rate = 1e-3\n").unwrap();
    let sets = ["ppo.learning_rate=3e-4", "policy.actor_hidden=[64, 32]", "sim.backend=cpu", "task.rewards.lifting=2"].map(String::from);
    let c = Config::load_with_overrides(&f, &sets).unwrap();
    assert_eq!(c.ppo.learning_rate, 3e-4);
    assert_eq!(c.policy.actor_hidden, vec![64, 32]);
    assert_eq!(c.sim.backend, dextrain::config::BackendChoice::Cpu);
    assert_eq!(c.task.rewards["lifting"], 2.0);
    for (bad, want) in [("ppo.learning_rate", "key=value"), ("ppo.nope=1", "ppo.nope"), ("ppo.learning_rate=-1", "ppo.learning_rate")] {
        let e = format!("{:#}", Config::load_with_overrides(&f, &[bad.to_string()]).unwrap_err());
        assert!(e.contains(want) && !e.contains('\n'), "{bad}: {e}");
    }
}

/// Closed choices are enums: a wrong spelling is a one-line error naming the file and the key and
/// listing the allowed values; a key defined twice names the key; a huge value is cut in the
/// message.
#[test]
fn closed_choices_duplicate_keys_and_long_values_give_readable_one_line_errors() {
    let p = Path::new("run.toml");
    for (text, key, allowed) in [
        ("[task]\nkind = \"lfit\"\n", "task.kind", "\"residual_task\""),
        ("[task.action]\nfinger_mode = \"relative\"\n", "task.action.finger_mode", "\"delta\""),
        ("[ppo]\nschedule = \"cosine\"\n", "ppo.schedule", "\"adaptive\""),
        ("[policy]\nactivation = \"gelu\"\n", "policy.activation", "\"tanh\""),
        ("[sim]\nbackend = \"cuda\"\n", "sim.backend", "\"gpu:ADAPTER_NAME\""),
        ("[train]\ndevice = \"gpu:\"\n", "train.device", "\"auto\""),
        ("[hand]\nmesh_approx = \"hull\"\n", "hand.mesh_approx", "capsule"),
    ] {
        let e = format!("{:#}", Config::from_toml_str(text, p).unwrap_err());
        assert!(e.contains("run.toml") && e.contains(&format!("`{key}`")) && e.contains(allowed) && !e.contains('\n'), "{text}: {e}");
    }
    // a key given twice: the error names it (and where)
    let e = format!("{:#}", Config::from_toml_str("[sim]\nnum_envs = 4\ndt = 0.01\nnum_envs = 8\n", p).unwrap_err());
    assert!(e.contains("run.toml:4") && e.contains("sim.num_envs") && !e.contains('\n'), "{e}");
    // a 5,000-character value is cut to a readable line
    let long = "x".repeat(5000);
    for text in [format!("[task]\nkind = \"{long}\"\n"), format!("[sim]\nbackend = \"{long}\"\n"), format!("[task.rewards]\n{long} = 1.0\n"), format!("[hand.joint_kp]\n{long} = -1.0\n")] {
        let e = format!("{:#}", Config::from_toml_str(&text, p).unwrap_err());
        assert!(e.len() < 400 && !e.contains('\n'), "{} characters: {}", e.len(), &e[..e.len().min(400)]);
    }
    // the typed config round-trips through its TOML (what a run directory keeps)
    let c = Config::from_toml_str("[task]\nkind = \"residual_task\"\n[task.reference]\nfiles = [\"a.mcap\"]\n[sim]\nbackend = \"gpu:llvmpipe\"\n", p).unwrap();
    let again = Config::from_toml_str(&c.to_toml().unwrap(), p).unwrap();
    assert_eq!(again.task.kind, dextrain::config::TaskKind::ResidualTask);
    assert_eq!(again.sim.backend, dextrain::config::BackendChoice::Gpu(Some("llvmpipe".into())));
    assert_eq!(again, Config { base_dir: again.base_dir.clone(), ..c });
}

/// `[task.lift]`'s keys that every kind uses moved to `[task.hand]` and `[task.termination]`;
/// configs written before still load (into the new places), and giving both is an error.
#[test]
fn keys_moved_out_of_task_lift_still_load() {
    let p = Path::new("run.toml");
    let c = Config::from_toml_str("[task.lift]\nthumb = \"th_tip\"\ncontact_force = 0.2\nmax_hand_distance = 0.7\nsuccess_height = 0.05\n", p).unwrap();
    assert_eq!((c.task.hand.thumb.as_str(), c.task.hand.contact_force, c.task.termination.max_hand_distance, c.task.lift.success_height), ("th_tip", 0.2, 0.7, 0.05));
    assert!(!c.to_toml().unwrap().contains("[task.lift]\nthumb"), "written back in the new place");
    let e = format!("{:#}", Config::from_toml_str("[task.lift]\ncontact_force = 0.2\n[task.hand]\ncontact_force = 0.3\n", p).unwrap_err());
    assert!(e.contains("run.toml") && e.contains("task.lift.contact_force") && e.contains("task.hand.contact_force") && !e.contains('\n'), "{e}");
}

/// `hand.fingertips` entries are frame names or `{ link, offset, name }` tables; `hand.effort` and
/// `hand.velocity` are one number or a table by joint name. Both round-trip through the TOML.
#[test]
fn fingertip_tables_and_joint_limits_parse_and_round_trip() {
    use dextrain::config::hand::{FingertipSpec, JointLimitOverride, LinkTip};
    let p = Path::new("run.toml");
    let text = "[hand]\nfingertips = [\"th_tip\", { link = \"if_dist\", offset = [0.01, 0, -0.002] }, { link = \"mf_dist\", name = \"mf_pad\" }]\neffort = 0.7\n[hand.velocity]\nif_j0 = 3\n\"joint_1.0\" = 2.5\n";
    let c = Config::from_toml_str(text, p).unwrap();
    assert_eq!(
        c.hand.fingertips,
        vec![
            FingertipSpec::Frame("th_tip".into()),
            FingertipSpec::Link(LinkTip { link: "if_dist".into(), offset: [0.01, 0.0, -0.002], name: None }),
            FingertipSpec::Link(LinkTip { link: "mf_dist".into(), offset: [0.0; 3], name: Some("mf_pad".into()) }),
        ]
    );
    assert_eq!(c.hand.fingertips.iter().map(|t| t.name()).collect::<Vec<_>>(), ["th_tip", "if_dist", "mf_pad"]);
    assert_eq!(c.hand.effort, Some(JointLimitOverride::All(0.7)));
    assert_eq!(c.hand.velocity, Some(JointLimitOverride::PerJoint([("if_j0".to_string(), 3.0), ("joint_1.0".to_string(), 2.5)].into())));
    let again = Config::from_toml_str(&c.to_toml().unwrap(), p).unwrap();
    assert_eq!(again.hand, c.hand);
    // the defaults: no tips named (detection), the URDF's limits (and nothing written for them)
    let d = Config::from_toml_str("", p).unwrap();
    assert!(d.hand.fingertips.is_empty() && d.hand.effort.is_none() && d.hand.velocity.is_none());
    assert!(!d.to_toml().unwrap().contains("effort"), "{}", d.to_toml().unwrap());
    assert_eq!(Config::from_toml_str(&d.to_toml().unwrap(), p).unwrap().hand, d.hand);
}

/// A typo in a fingertip table, a wrong type, a negative limit or a bad offset is a one-line error
/// naming the file, the key and what is expected.
#[test]
fn fingertip_and_limit_errors_name_the_key() {
    let p = Path::new("run.toml");
    for (text, key, hint) in [
        ("[hand]\nfingertips = [\"th_tip\", { lnk = \"if_dist\" }]\n", "hand.fingertips[1]", "unknown field \"lnk\", expected one of \"link\", \"offset\", \"name\""),
        ("[hand]\nfingertips = [{ link = \"if_dist\", ofset = [0, 0, 0] }]\n", "hand.fingertips[0]", "\"offset\""),
        ("[hand]\nfingertips = [{ offset = [0, 0, 0.01] }]\n", "hand.fingertips[0]", "missing field \"link\""),
        ("[hand]\nfingertips = [\"a\", 3]\n", "hand.fingertips[1]", "a fingertip frame name (a string) or a table { link ="),
        ("[hand]\nfingertips = [{ link = \"a\", offset = [0, 0] }]\n", "hand.fingertips[0].offset", "3"),
        ("[hand]\nfingertips = [{ link = \"a\", offset = [0, 0, 20] }]\n", "hand.fingertips[0].offset[2]", "within ±10 m"),
        ("[hand]\nfingertips = [{ link = \"a\", offset = [0, nan, 0] }]\n", "hand.fingertips[0].offset[1]", "finite"),
        ("[hand]\nfingertips = [\"\"]\n", "hand.fingertips[0]", "frame name"),
        ("[hand]\nfingertips = [{ link = \"\" }]\n", "hand.fingertips[0].link", "link"),
        ("[hand]\nfingertips = [{ link = \"a\", name = \"\" }]\n", "hand.fingertips[0].name", "non-empty"),
        ("[hand]\nfingertips = [{ link = \"a\" }, { link = \"a\", offset = [0.01, 0, 0] }]\n", "hand.fingertips[1]", "distinct `name`s"),
        ("[hand]\nfingertips = [\"a\", { link = \"b\", name = \"a\" }]\n", "hand.fingertips[1]", "hand.fingertips[0]"),
        ("[hand]\neffort = -1\n", "hand.effort", "(0, 100000] N·m"),
        ("[hand]\neffort = 0\n", "hand.effort", "(0, 100000] N·m"),
        ("[hand]\neffort = 1e30\n", "hand.effort", "(0, 100000] N·m"),
        ("[hand]\nvelocity = 0.0\n", "hand.velocity", "(0, 10000] rad/s"),
        ("[hand]\neffort = { if_j0 = 1, if_j1 = -0.5 }\n", "hand.effort.if_j1", "(0, 100000] N·m"),
        ("[hand.velocity]\nif_j0 = nan\n", "hand.velocity.if_j0", "rad/s"),
        ("[hand]\neffort = \"strong\"\n", "hand.effort", "one limit for every movable joint (a number) or a table of limits by joint name"),
        ("[hand]\nvelocity = [1, 2]\n", "hand.velocity", "a number"),
        ("[hand]\neffort = { if_j0 = \"x\" }\n", "hand.effort.if_j0", "f32"),
    ] {
        let e = format!("{:#}", Config::from_toml_str(text, p).unwrap_err());
        // the key path may go on into the table (`hand.fingertips[1].lnk`)
        assert!(e.contains("run.toml") && e.contains(&format!("`{key}")) && e.contains(hint) && !e.contains('\n'), "{text}: {e}");
    }
    // a joint the hand does not have: named when the hand loads, with the URDF
    let cfg = Config::from_toml_str("[hand]\nurdf = \"hands/dexhand16.urdf\"\neffort = { if_j0 = 1, if_j9 = 1 }\n", Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/configs/x.toml"))).unwrap();
    let e = format!("{:#}", dextrain::env::SimModel::from_config(&cfg).unwrap_err());
    assert!(e.contains("`hand.effort.if_j9`") && e.contains("dexhand16.urdf") && e.contains("if_j0") && !e.contains('\n'), "{e}");
}

/// `dextrain check` prints the hand's warnings (here: one tip named for a four-finger hand) once,
/// on stderr, and still succeeds.
#[test]
fn check_prints_the_hand_warnings_once() {
    let dir = tempfile::tempdir().unwrap();
    let f = dir.path().join("one_tip.toml");
    let urdf = concat!(env!("CARGO_MANIFEST_DIR"), "/configs/hands/dexhand16.urdf");
    std::fs::write(&f, format!("[hand]\nurdf = \"{urdf}\"\nfingertips = [\"th_tip\"]\n")).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_dextrain")).args(["check", f.to_str().unwrap()]).output().unwrap();
    let err = String::from_utf8(out.stderr).unwrap();
    assert!(out.status.success(), "{err}");
    let warnings: Vec<&str> = err.lines().filter(|l| l.starts_with("warning:")).collect();
    assert_eq!(warnings.len(), 1, "{err}");
    for needle in ["dexhand16.urdf", "1 fingertips ('th_tip')", "4 finger chains", "hand.fingertips = ["] {
        assert!(warnings[0].contains(needle), "{needle:?} not in {}", warnings[0]);
    }
}
