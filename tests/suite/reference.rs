//! The reference layer: the bank (`task::bank`: resampling, record layout, grasp flag, errors), the
//! cursor and sampling (`task::reference`, CPU) against `replay` and `Trajectory::sample`, every
//! augmentation's defining property, and the WGSL twin (`shaders/reference.wgsl`): it validates, its
//! structs and functions match the CPU twin's, and it computes the same cursors and frames.


use std::mem::size_of;
use std::path::PathBuf;

use crate::common::{base_config, gpu_context};
use dextrain::config::{Config, ReferenceConfig};
use dextrain::gpu::context::{KernelBinding, run_kernel};
use dextrain::task::shaders::SHADER_REFERENCE;
use dextrain::gpu::layout::{EnvState, NO_JOINT};
use dextrain::task::reference::*;
use dextrain::env::reset::{reset_params, reset_state};
use dextrain::env::SimModel;
use dextrain::geom::Pose;
use dextrain::task::bank::targets_at;
use dextrain::traj::Trajectory;
use dextrain::task::bank::{REC_Q, REC_WRIST_POS, REC_WRIST_ROT, RecordLayout, RefBank};
use dextrain::synth::{SynthArgs, synth};
use glam::{Quat, Vec3, Vec4};

// ---------------------------------------------------------------------------------------------
// Helpers
// ---------------------------------------------------------------------------------------------

/// The test config: `n` envs, the object's reset randomised in x, y and yaw.
fn config(n: usize) -> Config {
    let mut c = base_config(n);
    c.seed = 7;
    c.object.xy_noise = [0.04, 0.03];
    c.object.yaw_noise = 0.8;
    c
}

fn tri3_config(n: usize) -> Config {
    let mut c = config(n);
    c.hand.urdf = "hands/tri3_mimic.urdf".into();
    c.wrist.init_pos = [0.0, 0.0, 0.3];
    c
}

fn model(c: &Config) -> SimModel {
    SimModel::from_config(c).expect("model")
}

/// The thumb as the lift task finds it (first tip named "th…"), else tip 0.
fn thumb(m: &SimModel) -> usize {
    m.spec.tip_names.iter().position(|n| n.to_lowercase().starts_with("th")).unwrap_or(0)
}

fn synth_ref(c: &Config, approach: f32, lift: f32) -> Trajectory {
    let mut a = SynthArgs::posture(PathBuf::from("test.toml"), PathBuf::from("unused.mcap"));
    a.approach = approach;
    a.lift = lift;
    synth(c, &a).expect("synth")
}

fn shipped_ref() -> Trajectory {
    Trajectory::load(concat!(env!("CARGO_MANIFEST_DIR"), "/configs/refs/grasp_lift.mcap")).expect("shipped reference")
}

/// `t` without fingertips and without an object (the bank computes the tips by kinematics and
/// uses the config's object pose).
fn bare(t: &Trajectory) -> Trajectory {
    let mut t = t.clone();
    t.fingertip_names.clear();
    for f in &mut t.frames {
        f.fingertips = None;
        f.object = None;
    }
    t
}

/// Every augmentation on (reground as given).
fn all_on(reground: bool) -> ReferenceConfig {
    ReferenceConfig {
        files: Vec::new(),
        translate_xy: 0.05,
        rotate_z: 0.6,
        reground,
        reinterp: true,
        reinterp_steps: 0,
        mirror_prob: 0.5,
        wrist_pos_offset: 0.02,
        wrist_rot_offset: 0.1,
        joint_offset: 0.05,
        wrist_pos_noise: 0.005,
        joint_noise: 0.02,
        time_scale: 0.3,
    }
}

/// The validation context of the tests' configs.
fn check() -> dextrain::config::Check {
    dextrain::config::Check::new(std::path::Path::new("run.toml"))
}

fn globals(bank: &RefBank, cfg: &ReferenceConfig) -> RefGlobals {
    cfg.validate(&check()).expect("valid reference config");
    dextrain::task::setup::reference_globals(bank, cfg)
}

/// Env `i`'s state right after the reset of episode `i % 3`, its wrist moved away from the
/// initial pose (so that re-interpolation has something to do).
fn states(m: &SimModel, n: usize) -> Vec<EnvState> {
    let g = &m.globals;
    (0..n as u32)
        .map(|i| {
            let ep = i % 3;
            let p = reset_params(g, &m.object_descs, &m.ref_objects, i, ep);
            let mut s = reset_state(g, &m.joints, &p, i, ep, 0);
            let f = i as f32;
            s.wrist_pos[0] += 0.01 * (f * 0.7).sin();
            s.wrist_pos[1] -= 0.02 * (f * 0.3).cos();
            let tilt = Quat::from_rotation_x(0.2 * (f * 0.5).sin()) * Quat::from_array(s.wrist_rot);
            s.wrist_rot = tilt.normalize().to_array();
            s
        })
        .collect()
}

fn v3(a: [f32; 4]) -> Vec3 {
    Vec3::new(a[0], a[1], a[2])
}

fn pose(p: [f32; 4], q: [f32; 4]) -> Pose {
    Pose::new(v3(p), Quat::from_array(q))
}

/// Distance between two unit quaternions as orientations: min(‖a − b‖, ‖a + b‖) (≈ half the angle).
fn qdist(a: Quat, b: Quat) -> f32 {
    (Vec4::from(a) - Vec4::from(b)).length().min((Vec4::from(a) + Vec4::from(b)).length())
}

/// Angle (rad) between two orientations.
fn angle(a: Quat, b: Quat) -> f32 {
    2.0 * a.dot(b).abs().min(1.0).acos()
}

fn bits(a: &[f32]) -> Vec<u32> {
    a.iter().map(|x| x.to_bits()).collect()
}

/// Every float of a frame, in a fixed order.
fn floats(f: &RefFrame) -> Vec<f32> {
    let mut v = Vec::new();
    v.extend(f.wrist_pos);
    v.extend(f.wrist_rot);
    v.extend(f.obj_pos);
    v.extend(f.obj_rot);
    for t in &f.tips {
        v.extend(t);
    }
    v.extend(f.q);
    v.push(f.grasp);
    v
}

fn cursor_floats(c: &RefCursor) -> Vec<f32> {
    let mut v = Vec::new();
    for a in [c.d_pos, c.d_rot, c.start_pos, c.start_rot, c.wrist_off_pos, c.wrist_off_rot] {
        v.extend(a);
    }
    v.push(c.speed);
    v
}

// ---------------------------------------------------------------------------------------------
// The bank
// ---------------------------------------------------------------------------------------------

#[test]
fn record_layout_is_the_documented_one() {
    let l = RecordLayout::new(16, 4);
    assert_eq!((REC_WRIST_POS, REC_WRIST_ROT, REC_Q), (0, 3, 7));
    assert_eq!((l.q, l.tips, l.obj_pos, l.obj_rot, l.grasp, l.stride), (7, 23, 35, 38, 42, 43));
    let c = config(1);
    let m = model(&c);
    let bank = RefBank::build(&[synth_ref(&c, 1.0, 0.15)], &m, thumb(&m)).unwrap();
    let (j, t) = (m.joints.len(), m.tips.len());
    assert_eq!(bank.layout, RecordLayout::new(j, t));
    assert_eq!(bank.layout.stride, 15 + j + 3 * t);
    let rg = bank.globals();
    assert_eq!((rg.n_refs, rg.stride, rg.n_joints, rg.n_tips), (1, (15 + j + 3 * t) as u32, j as u32, t as u32));
    assert_eq!((rg.off_wrist_pos, rg.off_wrist_rot, rg.off_q), (0, 3, 7));
    assert_eq!((rg.off_tips, rg.off_obj_pos, rg.off_obj_rot, rg.off_grasp), ((7 + j) as u32, (7 + j + 3 * t) as u32, (10 + j + 3 * t) as u32, (14 + j + 3 * t) as u32));
    // every augmentation off
    assert_eq!((rg.reground, rg.reinterp, rg.translate_xy, rg.rotate_z, rg.mirror_prob, rg.time_scale), (0, 0, 0.0, 0.0, 0.0, 0.0));
}

#[test]
fn bank_resamples_at_the_control_step_and_flags_the_grasp() {
    let c = config(1);
    let m = model(&c);
    let a = synth_ref(&c, 1.0, 0.15);
    let b = synth_ref(&c, 0.5, 0.1);
    let bank = RefBank::build(&[a.clone(), b.clone()], &m, thumb(&m)).unwrap();
    let ctrl_dt = (m.globals.dt * m.globals.decimation as f32) as f64;
    assert_eq!(bank.ctrl_dt, ctrl_dt);
    for (r, t) in [&a, &b].iter().enumerate() {
        let info = bank.info[r];
        assert_eq!(info.n_frames as usize, (t.duration() / ctrl_dt).ceil() as usize + 1);
        // keyframe 1 is the end of the approach
        assert_eq!(info.first_segment_steps as f64, (t.frames[1].t / ctrl_dt).round());
        assert_eq!(info.flags, REF_HAS_OBJECT | REF_TIPS_FROM_FILE);
        let o = t.frames[0].object.unwrap();
        assert_eq!(info.obj0_pos[..3], o.pos.to_array());
        assert_eq!(info.obj0_rot, o.rot.to_array());
        for i in 0..info.n_frames as usize {
            let rec = bank.record(r, i);
            for k in 0..3 {
                assert!(rec[k] >= info.bbox_min[k] && rec[k] <= info.bbox_max[k], "wrist outside the bounding box");
            }
        }
    }
    assert_eq!(bank.info[0].first_segment_steps, 30);
    assert_eq!(bank.info[1].first_frame, bank.info[0].n_frames);
    assert_eq!(bank.frames.len(), (bank.info[0].n_frames + bank.info[1].n_frames) as usize * bank.layout.stride);
    // grasp: not at the start (hand open, far above), yes while squeezing and lifting
    let l = bank.layout;
    let grasp = |i: usize| bank.record(0, i)[l.grasp];
    assert_eq!(grasp(0), 0.0);
    let t2 = ((a.frames[2].t) / ctrl_dt).round() as usize;
    assert_eq!(grasp(t2), 1.0, "closed on the object at keyframe 2");
    assert_eq!(grasp(bank.info[0].n_frames as usize - 1), 1.0, "lifted");
}

#[test]
fn bank_computes_missing_fingertips_by_kinematics_and_uses_the_nominal_object() {
    for c in [config(1), tri3_config(1)] {
        let m = model(&c);
        let t = synth_ref(&c, 1.0, 0.15);
        let bank = RefBank::build(&[t.clone(), bare(&t)], &m, thumb(&m)).unwrap();
        assert_eq!(bank.info[1].flags, 0);
        let l = bank.layout;
        let mut worst = 0.0f32;
        let (t2, t3) = (t.frames[2].t, t.frames[3].t);
        let mut compared = 0;
        for i in 0..bank.info[0].n_frames as usize {
            let (from_file, from_fk) = (bank.record(0, i), bank.record(1, i));
            // wrist and joints identical
            assert_eq!(bits(&from_file[..l.tips]), bits(&from_fk[..l.tips]));
            // tips: synth's kinematics vs the bank's (same maths) where the file's tips are not
            // interpolated between different postures: at the start, while settling, after the end
            let ti = i as f64 * bank.ctrl_dt;
            if ti == 0.0 || (ti >= t2 && ti <= t3) || ti >= t.duration() {
                compared += 1;
                for k in l.tips..l.obj_pos {
                    worst = worst.max((from_file[k] - from_fk[k]).abs());
                }
            }
            // no object: the config's nominal pose (x, y, rest height, yaw)
            let g = &m.globals;
            assert_eq!(from_fk[l.obj_pos..l.obj_pos + 3], [g.obj_init[0], g.obj_init[1], g.obj_init[3]]);
            assert!((Quat::from_slice(&from_fk[l.obj_rot..l.obj_rot + 4]).dot(Quat::from_rotation_z(g.obj_init[2])) - 1.0).abs() < 1e-6);
        }
        assert!(compared >= 8, "{compared} frames compared");
        assert!(worst < 1e-6, "fingertips by kinematics differ from synth's by {worst}");
    }
}

#[test]
fn unaugmented_sampling_reproduces_replay_bit_for_bit() {
    for (c, traj) in [(config(1), shipped_ref()), (config(1), synth_ref(&config(1), 0.7, 0.1)), (tri3_config(1), synth_ref(&tri3_config(1), 1.0, 0.15))] {
        let m = model(&c);
        let bank = RefBank::build(std::slice::from_ref(&traj), &m, thumb(&m)).unwrap();
        let rg = globals(&bank, &ReferenceConfig::default());
        let r = RefModel::new(&m, &bank, &rg);
        let st = states(&m, 1)[0];
        let cur = ref_begin(&r, 0, 0, &st);
        assert_eq!((cur.ref_id, cur.flags, cur.speed, cur.seg_steps), (0, 0, 1.0, 0));
        assert_eq!(cur.d_rot, [0.0, 0.0, 0.0, 1.0]);
        let map = traj.joint_map(&m.spec.joint_names).unwrap();
        let last = bank.info[0].n_frames - 1;
        let tip_cols: Vec<usize> = m.spec.tip_names.iter().map(|n| traj.fingertip_names.iter().position(|x| x == n).unwrap()).collect();
        for n in 0..last + 4 {
            let t = n.min(last) as f64 * bank.ctrl_dt;
            let tg = targets_at(&m, &traj, &map, t);
            let f = ref_sample(&r, &cur, n, 0);
            assert_eq!(bits(&f.wrist_pos), bits(&tg.wrist_pos), "wrist position at step {n}");
            assert_eq!(bits(&f.wrist_rot), bits(&tg.wrist_rot), "wrist rotation at step {n}");
            for (j, jd) in m.joints.iter().enumerate() {
                let want = if jd.mimic_leader == NO_JOINT { tg.q[j] } else { jd.mimic_mult * tg.q[jd.mimic_leader as usize] + jd.mimic_offset };
                assert_eq!(f.q[j].to_bits(), want.to_bits(), "joint {j} at step {n}");
            }
            let s = traj.sample(t);
            let tips = s.fingertips.unwrap();
            for (k, &col) in tip_cols.iter().enumerate() {
                assert_eq!(bits(&f.tips[k][..3]), bits(&tips[col].to_array()), "tip {k} at step {n}");
            }
            let o = s.object.unwrap();
            assert_eq!(bits(&f.obj_pos[..3]), bits(&o.pos.to_array()), "object at step {n}");
            assert_eq!(bits(&f.obj_rot), bits(&o.rot.to_array()), "object rotation at step {n}");
            assert_eq!(f.ended, (n >= last) as u32, "ended at step {n}");
            // a look-ahead is the later step's frame
            assert_eq!(ref_sample(&r, &cur, n.saturating_sub(3), n.min(3)), f);
        }
        let (p, q) = ref_object_start(&r, &cur);
        assert_eq!(bits(&p.to_array()), bits(&bank.info[0].obj0_pos[..3]));
        assert_eq!(bits(&q.to_array()), bits(&bank.info[0].obj0_rot));
    }
}

// ---------------------------------------------------------------------------------------------
// Augmentations (CPU)
// ---------------------------------------------------------------------------------------------

#[test]
fn regrounding_keeps_the_hand_relative_to_the_object() {
    let c = config(16);
    let m = model(&c);
    let traj = synth_ref(&c, 1.0, 0.15);
    let bank = RefBank::build(std::slice::from_ref(&traj), &m, thumb(&m)).unwrap();
    let rg = globals(&bank, &ReferenceConfig { reground: true, ..Default::default() });
    let raw_rg = bank.globals();
    let r = RefModel::new(&m, &bank, &rg);
    let raw = RefModel::new(&m, &bank, &raw_rg);
    let info = bank.info[0];
    let obj0 = pose(info.obj0_pos, info.obj0_rot);
    let mut moved = 0;
    for (i, st) in states(&m, 16).iter().enumerate() {
        let cur = ref_begin(&r, i as u32, st.episode, st);
        assert_eq!(cur.flags, CUR_TRANSFORM);
        let env_obj = pose(st.obj_pos, st.obj_rot);
        if (env_obj.pos - obj0.pos).length() > 1e-3 || angle(env_obj.rot, obj0.rot) > 1e-3 {
            moved += 1;
        }
        // the reference object starts at the env's object
        let (p, q) = ref_object_start(&r, &cur);
        let f0 = ref_sample(&r, &cur, 0, 0);
        for (pp, qq) in [(p, Quat::from_array(q.to_array())), (v3(f0.obj_pos), Quat::from_array(f0.obj_rot))] {
            assert!((pp - env_obj.pos).length() < 1e-6, "env {i}: object start {pp} vs the env's {}", env_obj.pos);
            assert!(qdist(qq, env_obj.rot) < 1e-6, "env {i}: object start rotation");
        }
        // every wrist keyframe keeps its pose relative to the object: T̂_o⁻¹ T̂_a = T_o⁻¹ T_a
        let raw_cur = ref_begin(&raw, i as u32, st.episode, st);
        for n in [0, 15, 30, 54, 63, 108, 138] {
            let a = ref_sample(&raw, &raw_cur, n, 0);
            let b = ref_sample(&r, &cur, n, 0);
            for (ta, tb) in [(pose(a.wrist_pos, a.wrist_rot), pose(b.wrist_pos, b.wrist_rot)), (pose(a.obj_pos, a.obj_rot), pose(b.obj_pos, b.obj_rot))] {
                let rel_a = obj0.inverse().mul(&ta);
                let rel_b = env_obj.inverse().mul(&tb);
                assert!((rel_a.pos - rel_b.pos).length() < 1e-5, "env {i} step {n}: {} vs {}", rel_a.pos, rel_b.pos);
                assert!(qdist(rel_a.rot, rel_b.rot) < 1e-5, "env {i} step {n}: rotation {}", qdist(rel_a.rot, rel_b.rot));
            }
            for k in 0..m.tips.len() {
                let pa = obj0.inverse().transform_point(v3(a.tips[k]));
                let pb = env_obj.inverse().transform_point(v3(b.tips[k]));
                assert!((pa - pb).length() < 1e-5, "env {i} step {n} tip {k}");
            }
        }
    }
    assert!(moved >= 12, "the env resets should move the object ({moved} of 16 moved)");
}

#[test]
fn translation_and_rotation_move_the_whole_reference_rigidly_about_the_first_object_position() {
    let c = config(8);
    let m = model(&c);
    let traj = synth_ref(&c, 1.0, 0.15);
    let bank = RefBank::build(std::slice::from_ref(&traj), &m, thumb(&m)).unwrap();
    let rg = globals(&bank, &ReferenceConfig { translate_xy: 0.05, rotate_z: 0.6, ..Default::default() });
    let raw_rg = bank.globals();
    let (r, raw) = (RefModel::new(&m, &bank, &rg), RefModel::new(&m, &bank, &raw_rg));
    let info = bank.info[0];
    for (i, st) in states(&m, 8).iter().enumerate() {
        let cur = ref_begin(&r, i as u32, st.episode, st);
        let d = pose(cur.d_pos, cur.d_rot);
        let dz = d.pos.z;
        assert_eq!(dz, 0.0, "a horizontal move");
        let (p, q) = ref_object_start(&r, &cur);
        let shift = p - v3(info.obj0_pos);
        assert!(shift.x.abs() <= 0.05 + 1e-6 && shift.y.abs() <= 0.05 + 1e-6 && shift.z.abs() < 1e-6, "object start moved by {shift}");
        assert!(angle(Quat::from_array(q.to_array()), Quat::from_array(info.obj0_rot)) <= 0.6 + 1e-4);
        for n in [0, 30, 100] {
            let a = ref_sample(&raw, &ref_begin(&raw, i as u32, st.episode, st), n, 0);
            let b = ref_sample(&r, &cur, n, 0);
            let want = d.mul(&pose(a.wrist_pos, a.wrist_rot));
            assert!((want.pos - v3(b.wrist_pos)).length() < 1e-6 && qdist(want.rot, Quat::from_array(b.wrist_rot)) < 1e-6);
            assert_eq!(bits(&a.q), bits(&b.q), "joints are not moved");
        }
    }
}

#[test]
fn mirroring_twice_is_the_identity_and_keeps_the_first_object_position() {
    let c = config(1);
    let m = model(&c);
    let traj = synth_ref(&c, 1.0, 0.15);
    let mut t2 = traj.clone();
    // move the reference off y = 0 so that the mirror plane is not the world's
    for f in &mut t2.frames {
        f.wrist.pos.y += 0.07;
        f.object.as_mut().unwrap().pos.y += 0.07;
        for p in f.fingertips.as_mut().unwrap() {
            p.y += 0.07;
        }
    }
    let bank = RefBank::build(&[t2], &m, thumb(&m)).unwrap();
    let rg = globals(&bank, &ReferenceConfig { mirror_prob: 1.0, ..Default::default() });
    let raw_rg = bank.globals();
    let (r, raw) = (RefModel::new(&m, &bank, &rg), RefModel::new(&m, &bank, &raw_rg));
    let st = states(&m, 1)[0];
    let cur = ref_begin(&r, 0, 0, &st);
    assert_eq!(cur.flags, CUR_MIRROR);
    let raw_cur = ref_begin(&raw, 0, 0, &st);
    let y0 = bank.info[0].obj0_pos[1];
    assert!((y0 - 0.07).abs() < 1e-6);
    for n in [0, 20, 40, 80, 120, 1000] {
        let a = ref_sample(&raw, &raw_cur, n, 0);
        let b = ref_sample(&r, &cur, n, 0);
        // reflected: y → 2 y0 − y, quaternion (−x, y, −z, w), joints unchanged
        assert_eq!(b.wrist_pos[1], 2.0 * y0 - a.wrist_pos[1]);
        assert_eq!((b.wrist_pos[0], b.wrist_pos[2]), (a.wrist_pos[0], a.wrist_pos[2]));
        assert_eq!(b.wrist_rot, [-a.wrist_rot[0], a.wrist_rot[1], -a.wrist_rot[2], a.wrist_rot[3]]);
        assert_eq!(bits(&b.q), bits(&a.q));
        let twice = ref_mirror(&r, &cur, &b);
        for (x, y) in floats(&twice).iter().zip(floats(&a)) {
            assert!((x - y).abs() < 1e-6, "mirror twice at step {n}: {x} vs {y}");
        }
    }
    // the first object position is kept exactly
    let f0 = ref_sample(&r, &cur, 0, 0);
    assert_eq!(bits(&f0.obj_pos[..3]), bits(&bank.info[0].obj0_pos[..3]));
    let (p, _) = ref_object_start(&r, &cur);
    assert_eq!(bits(&p.to_array()), bits(&bank.info[0].obj0_pos[..3]));
    // mirror_prob draws: about half of the envs at 0.5
    let rg_half = globals(&bank, &ReferenceConfig { mirror_prob: 0.5, ..Default::default() });
    let rh = RefModel::new(&m, &bank, &rg_half);
    let mirrored = (0..400).filter(|&e| ref_begin(&rh, e, 0, &st).flags & CUR_MIRROR != 0).count();
    assert!((150..250).contains(&mirrored), "{mirrored} of 400 mirrored at p = 0.5");
}

#[test]
fn lookahead_is_consistent_under_noise_and_time_scaling() {
    let c = tri3_config(4);
    let m = model(&c);
    let bank = RefBank::build(&[synth_ref(&c, 1.0, 0.15), synth_ref(&c, 0.6, 0.1)], &m, thumb(&m)).unwrap();
    let rg = globals(&bank, &all_on(false));
    let r = RefModel::new(&m, &bank, &rg);
    let raw_rg = bank.globals();
    let raw = RefModel::new(&m, &bank, &raw_rg);
    for (i, st) in states(&m, 4).iter().enumerate() {
        let cur = ref_begin(&r, i as u32, st.episode, st);
        assert_ne!(cur.speed, 1.0);
        assert!((cur.speed - 1.0).abs() <= 0.3);
        for s in [0u32, 3, 17, 29, 30, 31, 77, 150, 300] {
            for k in 0..6 {
                assert_eq!(ref_sample(&r, &cur, s, k), ref_sample(&r, &cur, s + k, 0), "env {i} step {s} look-ahead {k}");
            }
        }
        // the noise is there, and the object reference is never noised
        let nc = RefCursor { flags: cur.flags & (CUR_WRIST | CUR_JOINT), ..cur };
        let plain = RefCursor { flags: 0, ..cur };
        let (a, b) = (ref_sample(&r, &nc, 40, 0), ref_sample(&raw, &plain, 40, 0));
        assert_ne!(a.q, b.q);
        assert_ne!(a.wrist_pos, b.wrist_pos);
        assert_eq!((a.obj_pos, a.obj_rot), (b.obj_pos, b.obj_rot));
        // a mimic follower's noise is its leader's times the multiplier
        for (j, jd) in m.joints.iter().enumerate() {
            if jd.mimic_leader != NO_JOINT {
                let l = jd.mimic_leader as usize;
                let (dj, dl) = (a.q[j] - b.q[j], a.q[l] - b.q[l]);
                assert!((dj - jd.mimic_mult * dl).abs() < 1e-5, "follower {j}: {dj} vs {} × {dl}", jd.mimic_mult);
            }
        }
    }
}

#[test]
fn reinterpolation_starts_at_the_robot_and_joins_the_reference() {
    let c = config(6);
    let m = model(&c);
    let bank = RefBank::build(&[synth_ref(&c, 1.0, 0.15)], &m, thumb(&m)).unwrap();
    let mut on = all_on(true);
    on.mirror_prob = 1.0;
    let rg = globals(&bank, &on);
    let r = RefModel::new(&m, &bank, &rg);
    for (i, st) in states(&m, 6).iter().enumerate() {
        let cur = ref_begin(&r, i as u32, st.episode, st);
        assert!(cur.flags & CUR_REINTERP != 0);
        let seg = cur.seg_steps;
        assert_eq!(seg, ((30.0 / cur.speed + 0.5).floor() as u32).max(1), "first segment after time scaling");
        let off = RefCursor { flags: cur.flags & !CUR_REINTERP, ..cur };
        let f0 = ref_sample(&r, &cur, 0, 0);
        assert_eq!(f0.wrist_pos[..3], st.wrist_pos[..3], "env {i}: starts exactly at the robot's wrist");
        assert_eq!(f0.wrist_rot, st.wrist_rot);
        let end = ref_sample(&r, &off, seg, 0);
        for n in 0..seg + 10 {
            let f = ref_sample(&r, &cur, n, 0);
            let g = ref_sample(&r, &off, n, 0);
            if n >= seg {
                assert_eq!(f, g, "env {i}: joins the reference at step {n}");
                continue;
            }
            let a = n as f32 / seg as f32;
            // on the straight segment from the start to the reference at the segment's end
            let want = v3(st.wrist_pos).lerp(v3(end.wrist_pos), a);
            assert!((v3(f.wrist_pos) - want).length() < 1e-6);
            let rot_err = qdist(Quat::from_array(f.wrist_rot), Quat::from_array(st.wrist_rot).slerp(Quat::from_array(end.wrist_rot), a));
            assert!(rot_err < 1e-6, "env {i} step {n}: slerp off by {rot_err}");
            // joints and object are the reference's; fingertips rigid with the wrist
            assert_eq!((f.q, f.obj_pos, f.obj_rot), (g.q, g.obj_pos, g.obj_rot));
            for k in 0..m.tips.len() {
                let lf = pose(f.wrist_pos, f.wrist_rot).inverse().transform_point(v3(f.tips[k]));
                let lg = pose(g.wrist_pos, g.wrist_rot).inverse().transform_point(v3(g.tips[k]));
                assert!((lf - lg).length() < 1e-5, "env {i} step {n} tip {k}: {lf} vs {lg}");
            }
        }
    }
    // reinterp_steps overrides the reference's first segment
    let rg2 = globals(&bank, &ReferenceConfig { reinterp: true, reinterp_steps: 12, ..Default::default() });
    let st = states(&m, 1)[0];
    assert_eq!(ref_begin(&RefModel::new(&m, &bank, &rg2), 0, 0, &st).seg_steps, 12);
}

#[test]
fn episodes_draw_every_reference() {
    let c = config(1);
    let m = model(&c);
    let bank = RefBank::build(&[synth_ref(&c, 1.0, 0.15), shipped_ref(), synth_ref(&c, 0.5, 0.1)], &m, thumb(&m)).unwrap();
    let rg = bank.globals();
    let r = RefModel::new(&m, &bank, &rg);
    let st = states(&m, 1)[0];
    let mut count = [0usize; 3];
    for e in 0..300 {
        count[ref_begin(&r, e % 7, e / 7, &st).ref_id as usize] += 1;
    }
    assert!(count.iter().all(|&k| k > 70), "reference draws {count:?}");
}

// ---------------------------------------------------------------------------------------------
// Errors and the config section
// ---------------------------------------------------------------------------------------------

#[test]
fn bank_errors_are_one_line_and_name_the_file() {
    let c = config(1);
    let m = model(&c);
    let dir = tempfile::tempdir().unwrap();
    let mut t = synth_ref(&c, 1.0, 0.15);
    t.joint_names[2] = "bogus_joint".into();
    let path = dir.path().join("bad_joint.csv");
    t.save(&path).unwrap();
    let good = dir.path().join("good.mcap");
    synth_ref(&c, 1.0, 0.15).save(&good).unwrap();
    let one_line = |e: anyhow::Error| -> String {
        let s = format!("{e:#}");
        assert!(!s.contains('\n'), "not one line: {s}");
        s
    };
    let e = one_line(RefBank::load(&[good.clone(), path.clone()], &m, thumb(&m)).unwrap_err());
    assert!(e.starts_with(&path.display().to_string()) && e.contains("\"bogus_joint\"") && e.contains("not in the hand"), "{e}");
    let e = one_line(RefBank::build(&[synth_ref(&c, 1.0, 0.15), t.clone()], &m, thumb(&m)).unwrap_err());
    assert!(e.starts_with("reference #1: ") && e.contains("bogus_joint"), "{e}");
    let missing = dir.path().join("missing.mcap");
    let e = one_line(RefBank::load(&[missing.clone()], &m, thumb(&m)).unwrap_err());
    assert!(e.contains(&missing.display().to_string()), "{e}");
    let bad_ext = dir.path().join("ref.json");
    std::fs::write(&bad_ext, "{}").unwrap();
    let e = one_line(RefBank::load(&[bad_ext.clone()], &m, thumb(&m)).unwrap_err());
    assert!(e.contains(&bad_ext.display().to_string()), "{e}");
    let e = one_line(RefBank::build(&[], &m, 0).unwrap_err());
    assert!(e.contains("at least one"), "{e}");
    let e = one_line(RefBank::build(&[t.clone()], &m, 99).unwrap_err());
    assert!(e.contains("thumb"), "{e}");
    // an invalid trajectory built in memory
    let mut bad = synth_ref(&c, 1.0, 0.15);
    bad.frames[3].t = bad.frames[2].t;
    let e = one_line(RefBank::build(&[bad], &m, thumb(&m)).unwrap_err());
    assert!(e.starts_with("reference #0: frame 3: field `t`"), "{e}");
    // the good file loads
    assert_eq!(RefBank::load(&[good], &m, thumb(&m)).unwrap().len(), 1);
}

#[test]
fn reference_config_parses_validates_and_fills() {
    let cfg: ReferenceConfig = toml::from_str("files = [\"refs/a.mcap\"]\nrotate_z = 0.5\nreground = true\ntime_scale = 0.2").unwrap();
    assert_eq!((cfg.rotate_z, cfg.reground, cfg.time_scale, cfg.translate_xy), (0.5, true, 0.2, 0.0));
    cfg.validate(&check()).unwrap();
    ReferenceConfig::default().validate(&check()).unwrap();
    all_on(true).validate(&check()).unwrap();
    let e = toml::from_str::<ReferenceConfig>("rotate_zz = 0.5").unwrap_err().to_string();
    assert!(e.contains("rotate_zz"), "{e}");
    for (patch, key) in [
        (ReferenceConfig { rotate_z: 4.0, ..Default::default() }, "task.reference.rotate_z"),
        (ReferenceConfig { translate_xy: -0.1, ..Default::default() }, "task.reference.translate_xy"),
        (ReferenceConfig { mirror_prob: 1.5, ..Default::default() }, "task.reference.mirror_prob"),
        (ReferenceConfig { time_scale: 1.0, ..Default::default() }, "task.reference.time_scale"),
        (ReferenceConfig { wrist_pos_noise: f32::NAN, ..Default::default() }, "task.reference.wrist_pos_noise"),
        (ReferenceConfig { joint_offset: -1.0, ..Default::default() }, "task.reference.joint_offset"),
        (ReferenceConfig { reinterp_steps: 2_000_000, ..Default::default() }, "task.reference.reinterp_steps"),
        (ReferenceConfig { files: vec![" ".into()], ..Default::default() }, "task.reference.files[0]"),
    ] {
        let e = format!("{:#}", patch.validate(&check()).unwrap_err());
        assert!(e.contains(&format!("`{key}`")) && !e.contains('\n'), "{e}");
    }
    let mut rg = RefGlobals { n_refs: 3, stride: 50, ..Default::default() };
    dextrain::task::setup::apply_augmentation(&all_on(true), &mut rg);
    assert_eq!((rg.n_refs, rg.stride, rg.reground, rg.reinterp, rg.mirror_prob, rg.joint_noise, rg.time_scale), (3, 50, 1, 1, 0.5, 0.02, 0.3));
}

// ---------------------------------------------------------------------------------------------
// CPU/GPU parity
// ---------------------------------------------------------------------------------------------

/// The (step, look-ahead) pairs sampled per env.
const SAMPLES: [[u32; 2]; 16] =
    [[0, 0], [0, 1], [0, 3], [1, 0], [2, 5], [7, 0], [12, 4], [20, 9], [29, 1], [30, 0], [31, 5], [55, 2], [100, 0], [140, 3], [400, 0], [400, 10]];

const KERNEL: &str = r#"
@group(0) @binding(30) var<storage, read> t_states: array<EnvState>;
@group(0) @binding(31) var<storage, read> t_steps: array<vec2<u32>>;
@group(0) @binding(32) var<storage, read_write> t_cursors: array<RefCursor>;
@group(0) @binding(33) var<storage, read_write> t_frames: array<RefFrame>;
@group(0) @binding(34) var<storage, read_write> t_starts: array<vec4<f32>>;
@compute @workgroup_size(64)
fn t_main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = gid.x;
    if (i >= arrayLength(&t_states)) {
        return;
    }
    let c = ref_begin(i, t_states[i].episode, t_states[i]);
    t_cursors[i] = c;
    let o = ref_object_start(c);
    t_starts[2u * i] = vec4<f32>(o.pos, 0.0);
    t_starts[2u * i + 1u] = o.rot;
    let ns = arrayLength(&t_steps);
    for (var k = 0u; k < ns; k++) {
        t_frames[i * ns + k] = ref_sample(c, t_steps[k].x, t_steps[k].y);
    }
}
"#;

struct Run {
    cursors: Vec<RefCursor>,
    frames: Vec<RefFrame>,
    starts: Vec<Vec4>,
}

fn cpu_run(m: &SimModel, bank: &RefBank, rg: &RefGlobals, states: &[EnvState]) -> Run {
    let r = RefModel::new(m, bank, rg);
    let mut out = Run { cursors: Vec::new(), frames: Vec::new(), starts: Vec::new() };
    for (i, s) in states.iter().enumerate() {
        let c = ref_begin(&r, i as u32, s.episode, s);
        let (p, q) = ref_object_start(&r, &c);
        out.starts.extend([p.extend(0.0), q]);
        for [step, k] in SAMPLES {
            out.frames.push(ref_sample(&r, &c, step, k));
        }
        out.cursors.push(c);
    }
    out
}

fn gpu_run(ctx: &dextrain::gpu::context::GpuContext, m: &SimModel, bank: &RefBank, rg: &RefGlobals, states: &[EnvState]) -> Run {
    let n = states.len();
    // the parity kernel, appended to the simulator's module and the reference layer
    let src = format!("{}\n{SHADER_REFERENCE}\n{KERNEL}", dextrain::gpu::shaders::shader_source());
    let out = run_kernel(
        ctx,
        &src,
        "t_main",
        &[
            (0, KernelBinding::Uniform(bytemuck::bytes_of(&m.globals))),
            (1, KernelBinding::Storage(bytemuck::cast_slice(&m.joints))),
            (13, KernelBinding::Storage(bytemuck::cast_slice(&bank.frames))),
            (14, KernelBinding::Storage(bytemuck::cast_slice(&bank.info))),
            (15, KernelBinding::Uniform(bytemuck::bytes_of(rg))),
            (30, KernelBinding::Storage(bytemuck::cast_slice(states))),
            (31, KernelBinding::Storage(bytemuck::cast_slice(&SAMPLES[..]))),
            (32, KernelBinding::StorageRw(&vec![0u8; n * size_of::<RefCursor>()])),
            (33, KernelBinding::StorageRw(&vec![0u8; n * SAMPLES.len() * size_of::<RefFrame>()])),
            (34, KernelBinding::StorageRw(&vec![0u8; n * 2 * 16])),
        ],
        n as u32,
    )
    .expect("kernel");
    Run {
        cursors: bytemuck::cast_slice::<u8, RefCursor>(&out[0]).to_vec(),
        frames: bytemuck::cast_slice::<u8, RefFrame>(&out[1]).to_vec(),
        starts: bytemuck::cast_slice::<u8, Vec4>(&out[2]).to_vec(),
    }
}

/// Compares the runs; `exact`: every float bit for bit. Returns the largest difference.
fn compare(what: &str, cpu: &Run, gpu: &Run, exact: bool) -> f32 {
    let mut worst = 0.0f32;
    let mut diff = |a: &[f32], b: &[f32], ctx: &dyn Fn() -> String| {
        for (x, y) in a.iter().zip(b) {
            if exact {
                assert_eq!(x.to_bits(), y.to_bits(), "{what}: {} differs: CPU {x} GPU {y}", ctx());
            }
            // relative to the magnitude (positions are O(0.1–1) m, quaternions and joints O(1))
            worst = worst.max((x - y).abs() / x.abs().max(1.0));
        }
    };
    for (i, (c, g)) in cpu.cursors.iter().zip(&gpu.cursors).enumerate() {
        // the integer draws are the same
        assert_eq!((c.ref_id, c.env, c.episode, c.flags, c.seg_steps), (g.ref_id, g.env, g.episode, g.flags, g.seg_steps), "{what}: cursor of env {i}");
        diff(&cursor_floats(c), &cursor_floats(g), &|| format!("cursor of env {i}"));
        diff(&cpu.starts[2 * i].to_array(), &gpu.starts[2 * i].to_array(), &|| format!("object start of env {i}"));
        diff(&cpu.starts[2 * i + 1].to_array(), &gpu.starts[2 * i + 1].to_array(), &|| format!("object start rotation of env {i}"));
    }
    for (k, (a, b)) in cpu.frames.iter().zip(&gpu.frames).enumerate() {
        let (env, s) = (k / SAMPLES.len(), SAMPLES[k % SAMPLES.len()]);
        assert_eq!((a.ended, a.grasp), (b.ended, b.grasp), "{what}: env {env} sample {s:?}: ended/grasp");
        diff(&floats(a), &floats(b), &|| format!("env {env} sample {s:?}"));
    }
    assert_eq!(cpu.frames.len(), gpu.frames.len());
    worst
}

#[test]
fn shader_matches_its_cpu_twin() {
    let Some(ctx) = gpu_context("reference shader_matches_its_cpu_twin") else { return };
    let n = 64;

    // 1. dexhand16, three references (file tips and object / kinematic tips and nominal object),
    //    every augmentation on, re-grounded onto the env's object
    let c = config(n);
    let m = model(&c);
    let refs = [synth_ref(&c, 1.0, 0.15), shipped_ref(), bare(&synth_ref(&c, 0.5, 0.1))];
    let bank = RefBank::build(&refs, &m, thumb(&m)).unwrap();
    let st = states(&m, n);
    let rg = globals(&bank, &all_on(true));
    let cpu = cpu_run(&m, &bank, &rg, &st);
    let gpu = gpu_run(&ctx, &m, &bank, &rg, &st);
    // every reference, the mirror and its absence are exercised
    for r in 0..3 {
        assert!(cpu.cursors.iter().any(|c| c.ref_id == r), "reference {r} never drawn");
    }
    assert!(cpu.cursors.iter().any(|c| c.flags & CUR_MIRROR != 0) && cpu.cursors.iter().any(|c| c.flags & CUR_MIRROR == 0));
    assert!(cpu.frames.iter().any(|f| f.ended == 1) && cpu.frames.iter().any(|f| f.ended == 0));
    let w1 = compare("all on, reground", &cpu, &gpu, false);

    // 2. tri3_mimic (mimic followers), every augmentation on, translated and rotated
    let c = tri3_config(n);
    let m = model(&c);
    let bank = RefBank::build(&[synth_ref(&c, 1.0, 0.15), synth_ref(&c, 0.4, 0.2)], &m, thumb(&m)).unwrap();
    let st = states(&m, n);
    let rg = globals(&bank, &all_on(false));
    let cpu = cpu_run(&m, &bank, &rg, &st);
    let gpu = gpu_run(&ctx, &m, &bank, &rg, &st);
    let w2 = compare("all on, tri3_mimic, translate/rotate", &cpu, &gpu, false);

    // 3. everything off: both backends return the bank's records bit for bit
    let c = config(n);
    let m = model(&c);
    let bank = RefBank::build(&refs, &m, thumb(&m)).unwrap();
    let st = states(&m, n);
    let rg = globals(&bank, &ReferenceConfig::default());
    let cpu = cpu_run(&m, &bank, &rg, &st);
    let gpu = gpu_run(&ctx, &m, &bank, &rg, &st);
    compare("all off", &cpu, &gpu, true);

    // docs/design.md §4: one evaluation agrees to about 1e-5
    eprintln!("largest CPU/GPU differences: {w1:e} (reground), {w2:e} (translate/rotate)");
    assert!(w1 < 1e-5 && w2 < 1e-5, "largest difference between shader and CPU twin: {w1}, {w2}");
}
