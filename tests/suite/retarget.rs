//! Retargeting human keypoints to a robot hand (`retarget::solve`, issue 39): keypoints made from
//! known poses of a robot hand — two palm points, its link origins and fingertips, in a moving
//! wrist frame — are
//! retargeted back to those poses on both shipped hands (dexhand16 and the mimic-coupled tri3):
//! joints within 0.01 rad, keypoints within 1 mm, the wrist with them; a smaller "human" hand
//! (the keypoints at 0.8× scale) retargets with `scale` = 1.25; bad input is an error.

use crate::common::*;
use dextrain::env::SimModel;
use dextrain::env::common::rand_uniform;
use dextrain::env::physics::Model;
use dextrain::gpu::layout::NO_JOINT;
use dextrain::hand::MAX_JOINTS;
use dextrain::retarget::solve::{RetargetSpec, RobotPoint, VectorPair, retarget_frame, retarget_sequence};
use dextrain::task::ik::{IkScratch, ik_apply_mimic, ik_link_poses};
use glam::{Quat, Vec3};

/// The default config with another shipped hand.
fn model_for(urdf: &str) -> SimModel {
    let mut c = base_config(1);
    c.hand.urdf = format!("hands/{urdf}");
    SimModel::from_config(&c).expect("model")
}

/// The robot's own keypoints: the wrist, every link's origin and every fingertip; vectors from the
/// wrist to each and from each link's parent to it (a tip from its link's origin).
fn self_spec(m: &Model) -> RetargetSpec {
    let n = m.g.n_joints as usize;
    let mut points = vec![RobotPoint { link: 0, offset: Vec3::ZERO }];
    points.extend((1..=n).map(|l| RobotPoint { link: l, offset: Vec3::ZERO }));
    // two points on the palm (the wrist link), as a human hand's knuckles are: without them a
    // joint that turns the whole hand (tri3's wrist roll) and the wrist's rotation are one motion
    let palm = [n + 1 + m.g.n_tips as usize, n + 2 + m.g.n_tips as usize];
    let tips: Vec<usize> = (0..m.g.n_tips as usize).collect();
    for &t in &tips {
        let tip = &m.tips[t];
        points.push(RobotPoint { link: tip.link as usize, offset: Vec3::new(tip.pos[0], tip.pos[1], tip.pos[2]) });
    }
    points.push(RobotPoint { link: 0, offset: Vec3::new(0.03, 0.02, 0.0) });
    points.push(RobotPoint { link: 0, offset: Vec3::new(0.03, -0.02, 0.01) });
    let mut pairs: Vec<VectorPair> = (1..points.len()).map(|i| VectorPair { origin: 0, target: i, weight: 1.0 }).collect();
    for l in 1..=n {
        pairs.push(VectorPair { origin: m.joints[l - 1].parent_link as usize, target: l, weight: 1.0 });
    }
    for (i, &t) in tips.iter().enumerate() {
        pairs.push(VectorPair { origin: m.tips[t].link as usize, target: n + 1 + i, weight: 1.0 });
    }
    RetargetSpec { points, pairs, palm: [0, palm[0], palm[1]], scale: 1.0, smooth: 1e-6, iterations: 100 }
}

/// Uniform in [0, 1) from the counter hash.
fn uni(i: u32, k: u32) -> f32 {
    rand_uniform(23, i, 0, 7, k)
}

/// A joint vector inside the limits (an unlimited joint within ±0.5 rad), away from them by a
/// tenth of the range, followers from their leaders.
fn random_q(m: &Model, i: u32) -> [f32; MAX_JOINTS] {
    let mut q = [0.0; MAX_JOINTS];
    for j in 0..m.g.n_joints as usize {
        let jd = &m.joints[j];
        let (lo, hi) = if jd.lower <= -1e29 || jd.upper >= 1e29 { (-0.5, 0.5) } else { (jd.lower, jd.upper) };
        let margin = 0.1 * (hi - lo);
        q[j] = lo + margin + (hi - lo - 2.0 * margin) * uni(i, j as u32);
    }
    ik_apply_mimic(m, &mut q);
    q
}

/// The joints a reset starts from: defaults clamped into the limits, followers from their leaders.
fn default_q(m: &Model) -> [f32; MAX_JOINTS] {
    let mut q = [0.0; MAX_JOINTS];
    for j in 0..m.g.n_joints as usize {
        q[j] = m.joints[j].default_q.clamp(m.joints[j].lower, m.joints[j].upper);
    }
    ik_apply_mimic(m, &mut q);
    q
}

/// The spec's keypoints (world frame) of the robot at wrist pose (pos, rot) and joints q, scaled.
fn keypoints(m: &Model, spec: &RetargetSpec, pos: Vec3, rot: Quat, q: &[f32; MAX_JOINTS], scale: f32) -> Vec<Vec3> {
    let mut s = IkScratch::default();
    ik_link_poses(m, q, &mut s);
    spec.points
        .iter()
        .map(|p| {
            let r = Quat::from_array(s.link_rot[p.link].to_array());
            (pos + rot * (s.link_pos[p.link] + r * p.offset)) * scale
        })
        .collect()
}

#[test]
fn keypoints_of_known_poses_retarget_back_to_those_poses_on_both_hands() {
    for urdf in ["dexhand16.urdf", "tri3_mimic.urdf"] {
        let model = model_for(urdf);
        let m = model.view();
        let spec = self_spec(&m);
        let actuated: Vec<usize> = (0..m.g.n_joints as usize).filter(|&j| m.joints[j].mimic_leader == NO_JOINT).collect();
        // a 20-frame motion between two random poses, the wrist turning and moving with it
        let (qa, qb) = (random_q(&m, 1), random_q(&m, 2));
        let axis = Vec3::new(0.3, -0.8, 0.5).normalize();
        let frames = 20;
        let mut truth = Vec::new();
        let mut demo = Vec::new();
        for f in 0..frames {
            let t = f as f32 / (frames - 1) as f32;
            let mut q = [0.0; MAX_JOINTS];
            for j in 0..MAX_JOINTS {
                q[j] = qa[j] + (qb[j] - qa[j]) * t;
            }
            ik_apply_mimic(&m, &mut q);
            let rot = Quat::from_axis_angle(axis, 0.5 + 0.4 * t);
            let pos = Vec3::new(0.1, -0.05 + 0.1 * t, 0.3);
            demo.push(keypoints(&m, &spec, pos, rot, &q, 1.0));
            truth.push((pos, rot, q));
        }
        let out = retarget_sequence(&m, &spec, &demo, &default_q(&m)).expect("retargeted");
        assert_eq!(out.len(), frames);
        for (f, (got, (pos, rot, q))) in out.iter().zip(&truth).enumerate() {
            let joint_err = actuated.iter().map(|&j| (got.q[j] - q[j]).abs()).fold(0.0f32, f32::max);
            let key_err = got.keypoint_error.iter().copied().fold(0.0f32, f32::max);
            let pos_err = (got.wrist_pos - *pos).length();
            let rot_err = got.wrist_rot.angle_between(*rot);
            assert!(joint_err <= 0.01, "{urdf} frame {f}: joints off by {joint_err} rad ({} iterations)", got.iterations);
            assert!(key_err <= 1e-3, "{urdf} frame {f}: a keypoint off by {} mm", key_err * 1e3);
            assert!(pos_err <= 1e-3 && rot_err <= 0.01, "{urdf} frame {f}: wrist off by {pos_err} m, {rot_err} rad");
            for j in 0..m.g.n_joints as usize {
                assert!(got.q[j] >= m.joints[j].lower - 1e-6 && got.q[j] <= m.joints[j].upper + 1e-6, "{urdf} frame {f}: joint {j} outside its limits");
            }
        }
    }
}

#[test]
fn a_smaller_hand_retargets_with_its_scale_and_bad_keypoints_are_errors() {
    let model = model_for("dexhand16.urdf");
    let m = model.view();
    let mut spec = self_spec(&m);
    let q = random_q(&m, 5);
    let rot = Quat::from_axis_angle(Vec3::Z, 0.3);
    // a "human" hand 0.8× the robot's: its vectors are scaled back by 1.25
    let human = keypoints(&m, &spec, Vec3::new(0.0, 0.0, 0.2), rot, &q, 0.8);
    spec.scale = 1.25;
    let start = dextrain::retarget::solve::palm_rotation(&m, &spec, &human, &default_q(&m));
    let got = retarget_frame(&m, &spec, &human, start, &default_q(&m)).expect("retargeted");
    let joint_err = (0..m.g.n_joints as usize).map(|j| (got.q[j] - q[j]).abs()).fold(0.0f32, f32::max);
    assert!(joint_err <= 0.01, "joints off by {joint_err} rad");
    assert!((got.wrist_pos - Vec3::new(0.0, 0.0, 0.2)).length() < 1e-3, "the wrist at the scaled position: {}", got.wrist_pos);
    // without the scale the vectors cannot all match: the error says so
    spec.scale = 1.0;
    let unscaled = retarget_frame(&m, &spec, &human, start, &default_q(&m)).expect("retargeted");
    assert!(unscaled.vector_error.iter().copied().fold(0.0f32, f32::max) > 5e-3, "a 0.8× hand matched unscaled");
    // a missing keypoint or a NaN is an error, not a panic
    let err = retarget_frame(&m, &spec, &human[1..], start, &default_q(&m)).unwrap_err().to_string();
    assert!(err.contains("keypoints for"), "{err}");
    let mut bad = human.clone();
    bad[3].x = f32::NAN;
    let err = retarget_sequence(&m, &spec, &[human.clone(), bad], &default_q(&m)).unwrap_err().to_string();
    assert!(err.contains("frame 1") && err.contains("not finite"), "{err}");
}
