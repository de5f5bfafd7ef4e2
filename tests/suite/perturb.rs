//! Perturbed reference datasets (`dextrain traj synth --count N` with retargeting-like errors):
//! the object part stays clean, each error stays within its bound, the hand stays consistent, the
//! draws are deterministic, and the errors make open-loop replay fail where the clean one lifts.

use std::path::PathBuf;

use dextrain::config::Config;
use dextrain::env::SimModel;
use dextrain::replay::{replay, rot_err_deg};
use dextrain::traj::perturb::{PerturbArgs, perturb};
use dextrain::synth::{SynthArgs, synth, synth_set};

fn grasp_config() -> Config {
    let mut cfg = Config::load(&PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/configs/grasp_lift.toml"))).expect("config");
    cfg.sim.backend = "cpu".parse().unwrap();
    cfg.sim.num_envs = 1;
    cfg
}

/// The errors of the shipped perturbed dataset (configs/refs/perturbed/, README).
fn shipped_errors() -> PerturbArgs {
    PerturbArgs { time_shift: 0.4, wrist_offset: 0.035, wrist_rot_offset: 0.2, joint_offset: 0.3, wrist_noise: 0.002, joint_noise: 0.02, rate: 30.0 }
}

#[test]
fn zero_errors_give_the_clean_reference_resampled() {
    let cfg = grasp_config();
    let model = SimModel::from_config(&cfg).unwrap();
    let clean = synth(&cfg, &SynthArgs::posture("x".into(), "y".into())).unwrap();
    let p = perturb(&clean, &model.hand, &PerturbArgs::default(), 3, 5).unwrap();
    assert!(p.frames.len() > 100, "30 Hz keyframes over 4.6 s");
    for f in &p.frames {
        let c = clean.sample(f.t);
        assert!((f.wrist.pos - c.wrist.pos).length() < 1e-6, "t = {}", f.t);
        assert!(rot_err_deg(f.wrist.rot, c.wrist.rot) < 1e-3, "t = {}", f.t);
        // leaders as in the clean reference (followers are recomputed from their leaders; the
        // physics ignores followers' targets)
        for jt in model.hand.joints.iter().filter(|j| j.mimic.is_none()) {
            let k = p.joint_names.iter().position(|n| *n == jt.name).unwrap();
            assert!((f.joints[k] - c.joints[k]).abs() < 1e-6, "{} at t = {}", jt.name, f.t);
        }
        assert_eq!(f.object, c.object, "t = {}", f.t);
        // fingertips: forward kinematics of the clean joints (between keyframes the clean
        // reference interpolates its tips linearly, which FK of interpolated joints is not)
        let q: Vec<f32> = model.hand.joints.iter().map(|jt| c.joints[p.joint_names.iter().position(|n| *n == jt.name).unwrap()]).collect();
        let links = model.hand.forward_kinematics(&q);
        for (a, tp) in f.fingertips.as_ref().unwrap().iter().zip(&model.hand.fingertips) {
            let b = c.wrist.transform_point(links[tp.link].transform_point(tp.pos));
            assert!((*a - b).length() < 1e-5, "t = {}", f.t);
        }
    }
}

#[test]
fn each_error_stays_within_its_bound_and_the_object_is_untouched() {
    let cfg = grasp_config();
    let model = SimModel::from_config(&cfg).unwrap();
    let hand = &model.hand;
    let clean = synth(&cfg, &SynthArgs::posture("x".into(), "y".into())).unwrap();
    // constant offsets only: every frame differs from the clean one by the same bounded amount
    let offsets = PerturbArgs { wrist_offset: 0.03, wrist_rot_offset: 0.2, joint_offset: 0.1, ..Default::default() };
    let mut moved = 0;
    for index in 0..6 {
        let p = perturb(&clean, hand, &offsets, 7, index).unwrap();
        let d0 = p.frames[0].wrist.pos - clean.sample(0.0).wrist.pos;
        assert!(d0.length() <= 0.03 + 1e-6, "offset {} m beyond 3 cm", d0.length());
        if d0.length() > 1e-3 {
            moved += 1;
        }
        for f in &p.frames {
            let c = clean.sample(f.t);
            assert!(((f.wrist.pos - c.wrist.pos) - d0).length() < 1e-5, "the wrist offset is constant");
            assert!(rot_err_deg(f.wrist.rot, c.wrist.rot) <= 0.2f64.to_degrees() + 1e-3);
            assert_eq!(f.object, c.object);
            for jt in &hand.joints {
                let k = p.joint_names.iter().position(|n| *n == jt.name).unwrap();
                let q = f.joints[k];
                assert!(q >= jt.lower - 1e-6 && q <= jt.upper + 1e-6, "{} = {q} outside its limits", jt.name);
                if jt.mimic.is_none() {
                    assert!((q - c.joints[k]).abs() <= 0.1 + 1e-5 || q == jt.lower || q == jt.upper, "{} moved more than its offset", jt.name);
                }
            }
        }
    }
    assert!(moved >= 5, "the offsets were drawn (only {moved} of 6 moved the wrist)");

    // a time shift only: the hand is the clean hand re-timed, so it starts to rise up to
    // time_shift earlier or later than the clean one
    let shift = PerturbArgs { time_shift: 0.4, ..Default::default() };
    let rise = |t: &dextrain::traj::Trajectory| {
        let peak = t.frames.iter().map(|f| f.wrist.pos.z).fold(f32::MIN, f32::max);
        // the lift phase: first time past the middle of the final climb
        let grasp_z = t.sample(2.2).wrist.pos.z;
        let mid = 0.5 * (grasp_z + peak);
        t.frames.iter().find(|f| f.t > 2.2 && f.wrist.pos.z > mid).map(|f| f.t).unwrap()
    };
    let clean30 = clean.resample(1.0 / 30.0);
    let mut shifts = Vec::new();
    for index in 0..6 {
        let p = perturb(&clean, hand, &shift, 11, index).unwrap();
        let d = rise(&p) - rise(&clean30);
        assert!(d.abs() <= 0.4 + 1.0 / 30.0 + 1e-9, "shift {d} s beyond 0.4 s");
        for (a, b) in p.frames.iter().zip(&clean30.frames) {
            assert_eq!(a.object, b.object, "the object keeps its clean timing");
        }
        shifts.push(d);
    }
    assert!(shifts.iter().any(|d| *d > 0.05) && shifts.iter().any(|d| *d < -0.05), "shifts both ways: {shifts:?}");
}

#[test]
fn datasets_are_deterministic_in_seed_and_index() {
    let cfg = grasp_config();
    let mut args = SynthArgs::posture("x".into(), "y".into());
    args.count = 3;
    args.seed = 4;
    args.perturb = shipped_errors();
    let a = synth_set(&cfg, &args).unwrap();
    let b = synth_set(&cfg, &args).unwrap();
    assert_eq!(a, b);
    assert_ne!(a[0], a[1]);
    args.seed = 5;
    let c = synth_set(&cfg, &args).unwrap();
    assert_ne!(a[0], c[0]);
    // bad flags are one-line errors naming the flag
    args.perturb.wrist_offset = -1.0;
    let e = format!("{:#}", synth_set(&cfg, &args).unwrap_err());
    assert!(e.contains("--wrist-offset") && !e.contains('\n'), "{e}");
    args.perturb = PerturbArgs::default();
    args.count = 0;
    assert!(format!("{:#}", synth_set(&cfg, &args).unwrap_err()).contains("--count"));
}

/// The point of the dataset: open-loop replay of the clean reference lifts the cube close to its
/// reference, while the perturbed references often end far from it.
#[test]
fn perturbed_references_make_open_loop_replay_fail_often() {
    let cfg = grasp_config();
    let mut args = SynthArgs::posture("x".into(), "y".into());
    let clean = synth(&cfg, &args).unwrap();
    let r = replay(&cfg, &clean, false, None).unwrap();
    let clean_err = r.terminal_object_pos_err_m.unwrap();
    assert!(clean_err < 0.03, "clean replay ends {clean_err} m from the reference");
    args.count = 6;
    args.seed = 1;
    args.perturb = shipped_errors();
    let errs: Vec<f64> = synth_set(&cfg, &args).unwrap().iter().map(|t| replay(&cfg, t, false, None).unwrap().terminal_object_pos_err_m.unwrap()).collect();
    let failed = errs.iter().filter(|&&e| e > 0.05).count();
    let mean = errs.iter().sum::<f64>() / errs.len() as f64;
    assert!(failed >= 2, "only {failed} of 6 perturbed replays end > 5 cm off: {errs:?}");
    assert!(mean > 2.0 * clean_err, "mean terminal error {mean} m vs clean {clean_err} m");
}

/// configs/refs/perturbed/ holds what its README's command writes (so the data can be regenerated).
#[test]
fn shipped_perturbed_references_are_what_synth_writes() {
    let cfg = grasp_config();
    let dir = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/configs/refs/perturbed"));
    let mut args = SynthArgs::posture("x".into(), dir.clone());
    args.count = 16;
    args.seed = 1;
    args.perturb = shipped_errors();
    let fresh = synth_set(&cfg, &args).unwrap();
    for (i, t) in fresh.iter().enumerate() {
        let path = dir.join(format!("ref_{i:03}.mcap"));
        let shipped = dextrain::traj::Trajectory::load(&path).unwrap();
        assert_eq!(&shipped, t, "{} is stale: regenerate it with the command in configs/refs/perturbed/README.md", path.display());
    }
}
