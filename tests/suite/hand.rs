//! URDF loader tests: the two shipped hands (counts, kinematics, merges, mimics) and the loader's
//! one-line errors. Expected numbers are computed by hand from the URDF files.

use std::f32::consts::{FRAC_PI_2, FRAC_PI_4};
use std::path::{Path, PathBuf};

use dextrain::geom::Pose;
use dextrain::hand::*;
use glam::{Quat, Vec3};

// ------------------------------------------------------------------------------------------------
// helpers

fn hand_path(file: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/hands").join(file)
}

fn load_hand(file: &str) -> HandModel {
    HandModel::from_urdf_file(&hand_path(file), &HandLoadOptions::default())
        .unwrap_or_else(|e| panic!("loading {file}: {e}"))
}

#[track_caller]
fn assert_close(a: f32, b: f32, tol: f32, what: &str) {
    assert!((a - b).abs() <= tol, "{what}: got {a}, expected {b} (tol {tol})");
}

#[track_caller]
fn assert_vec(a: Vec3, b: Vec3, tol: f32, what: &str) {
    assert!((a - b).abs().max_element() <= tol, "{what}: got {a}, expected {b} (tol {tol})");
}

/// Rotations are equal up to the quaternion sign.
#[track_caller]
fn assert_rot(a: Quat, b: Quat, tol: f32, what: &str) {
    assert!(a.dot(b).abs() >= 1.0 - tol, "{what}: got {a}, expected {b}");
}


fn tip_in_wrist(h: &HandModel, name: &str, q: &[f32]) -> Vec3 {
    let poses = h.forward_kinematics(q);
    let t = h.fingertips.iter().find(|t| t.name == name).unwrap_or_else(|| panic!("no fingertip {name}"));
    poses[t.link].transform_point(t.pos)
}

fn q_with(h: &HandModel, set: &[(&str, f32)]) -> Vec<f32> {
    let mut q = vec![0.0; h.joints.len()];
    for (name, v) in set {
        q[h.joint_index(name).unwrap_or_else(|| panic!("no joint {name}"))] = *v;
    }
    q
}

const PALM: &str = r#"<link name="palm"><inertial><mass value="0.2"/><inertia ixx="1e-4" ixy="0" ixz="0" iyy="1e-4" iyz="0" izz="1e-4"/></inertial><collision><geometry><box size="0.08 0.1 0.02"/></geometry></collision></link>"#;

fn link(name: &str) -> String {
    format!(
        r#"<link name="{name}"><inertial><mass value="0.01"/><inertia ixx="1e-6" ixy="0" ixz="0" iyy="1e-6" iyz="0" izz="1e-6"/></inertial><collision><geometry><sphere radius="0.01"/></geometry></collision></link>"#
    )
}

fn joint(name: &str, ty: &str, parent: &str, child: &str, extra: &str) -> String {
    format!(
        r#"<joint name="{name}" type="{ty}"><parent link="{parent}"/><child link="{child}"/><origin xyz="0.05 0 0" rpy="0 0 0"/><axis xyz="0 1 0"/><limit lower="-1" upper="1" effort="1" velocity="2"/>{extra}</joint>"#
    )
}

fn rev(name: &str, parent: &str, child: &str) -> String {
    joint(name, "revolute", parent, child, "")
}

fn robot(parts: &[String]) -> String {
    format!("<robot name=\"test_hand\">{}</robot>", parts.concat())
}

fn load_str(text: &str, source: &str, opts: &HandLoadOptions) -> anyhow::Result<HandModel> {
    HandModel::from_urdf_str(text, Path::new(source), opts)
}

/// Loads `text` expecting an error; checks it is one line, names `source`'s file name, contains every
/// needle and says what is expected.
#[track_caller]
fn expect_err(text: &str, source: &str, opts: &HandLoadOptions, needles: &[&str]) -> String {
    let msg = match load_str(text, source, opts) {
        Ok(_) => panic!("{source} loaded, expected an error containing {needles:?}"),
        Err(e) => format!("{e:#}"),
    };
    check_msg(&msg, Path::new(source).file_name().unwrap().to_str().unwrap(), needles);
    msg
}

#[track_caller]
fn check_msg(msg: &str, file: &str, needles: &[&str]) {
    assert!(!msg.contains('\n') && !msg.contains('\r'), "error is not one line: {msg:?}");
    assert!(msg.contains(file), "error does not name the file {file}: {msg}");
    assert!(msg.contains("expected") || msg.contains("support"), "error does not say what is expected: {msg}");
    for n in needles {
        assert!(msg.contains(n), "error does not contain {n:?}: {msg}");
    }
}

// ------------------------------------------------------------------------------------------------
// dexhand16

const FINGERS: [&str; 4] = ["if", "mf", "rf", "th"];

#[test]
#[allow(clippy::approx_constant)] // 6.28 rad/s is the URDF's velocity limit, not an approximation of TAU
fn dexhand16_counts_and_names() {
    let h = load_hand("dexhand16.urdf");
    assert_eq!(h.name, "dexhand16");
    assert_eq!(h.joints.len(), 16);
    assert_eq!(h.num_actuated(), 16);
    assert_eq!(h.links.len(), 17);
    assert_eq!(h.colliders.len(), 17);
    assert_eq!(h.links[0].name, "palm");
    let names: Vec<&str> = h.joints.iter().map(|j| j.name.as_str()).collect();
    let expected: Vec<String> = FINGERS.iter().flat_map(|f| (0..4).map(move |k| format!("{f}_j{k}"))).collect();
    assert_eq!(names, expected, "depth-first order, fingers in document order");
    let tips: Vec<&str> = h.fingertips.iter().map(|t| t.name.as_str()).collect();
    assert_eq!(tips, ["if_tip", "mf_tip", "rf_tip", "th_tip"]);
    // tip links are merged away into the distal links
    assert!(h.links.iter().all(|l| !l.name.ends_with("_tip")));
    for f in FINGERS {
        let (link, pose) = h.frame(&format!("{f}_tip")).unwrap();
        assert_eq!(h.links[link].name, format!("{f}_dist"));
        let len = if f == "th" { 0.0423 } else { 0.0387 };
        assert_vec(pose.pos, Vec3::new(len, 0.0, 0.0), 1e-7, "tip frame");
    }
    assert_eq!(h.frame("palm"), Some((0, Pose::IDENTITY)));
    assert_eq!(h.frame("no_such_link"), None);
    // all joints: limits, effort, velocity, damping
    for j in &h.joints {
        assert!(j.mimic.is_none() && !j.continuous);
        assert_close(j.effort, 0.7, 1e-7, "effort");
        assert_close(j.velocity, 6.28, 1e-6, "velocity");
        assert_close(j.damping, 0.01, 1e-8, "damping");
        assert_eq!(j.friction, 0.0);
        if j.name.ends_with("_j0") {
            assert_eq!((j.lower, j.upper), (-0.47, 0.47));
            assert_vec(j.axis, Vec3::Z, 0.0, "abduction axis");
        } else {
            assert_eq!((j.lower, j.upper), (-0.2, 1.6));
            assert_vec(j.axis, Vec3::Y, 0.0, "flexion axis");
        }
    }
    // mass: palm 0.4 + 4 fingers of 0.012 + 0.065 + 0.036 + 0.026
    assert_close(h.links[0].mass, 0.4, 1e-7, "palm mass");
    assert_close(h.total_mass(), 0.4 + 4.0 * 0.139, 1e-6, "total mass");
}

#[test]
fn topological_order_invariant() {
    for file in ["dexhand16.urdf", "tri3_mimic.urdf"] {
        let h = load_hand(file);
        assert_eq!(h.links.len(), h.joints.len() + 1, "{file}");
        for (i, j) in h.joints.iter().enumerate() {
            assert!(j.parent_link < i + 1, "{file}: joint {} has parent link {} >= {}", j.name, j.parent_link, i + 1);
            if let Some(m) = j.mimic {
                assert!(h.joints[m.leader].mimic.is_none(), "{file}: {} leads through a follower", j.name);
                assert_ne!(m.leader, i);
            }
        }
        for c in &h.colliders {
            assert!(c.link < h.links.len());
        }
        for t in &h.fingertips {
            assert!(t.link < h.links.len());
        }
    }
}

#[test]
fn dexhand16_colliders_match_mjcf_capsules() {
    let h = load_hand("dexhand16.urdf");
    let palm = &h.colliders[0];
    assert_eq!(palm.link, 0);
    assert_eq!(palm.shape, ColliderShape::Box { half_extents: Vec3::new(0.045, 0.065, 0.015) });
    assert_eq!(palm.pose, Pose::IDENTITY);
    let lens = [("base", 0.0164, 0.0177), ("prox", 0.054, 0.0514), ("mid", 0.0384, 0.054), ("dist", 0.0387, 0.0423)];
    for f in FINGERS {
        for (seg, len_f, len_th) in lens {
            let len: f32 = if f == "th" { len_th } else { len_f };
            let li = h.link_index(&format!("{f}_{seg}")).unwrap();
            let cs: Vec<&Collider> = h.colliders.iter().filter(|c| c.link == li).collect();
            assert_eq!(cs.len(), 1, "{f}_{seg}");
            // cylinder length L -> capsule half length L/2 (MJCF fromto 0..L capsule)
            match cs[0].shape {
                ColliderShape::Capsule { radius, half_length } => {
                    assert_close(radius, 0.0098, 1e-8, "radius");
                    assert_close(half_length, len / 2.0, 1e-8, "half length");
                }
                s => panic!("{f}_{seg}: expected a capsule, got {s:?}"),
            }
            assert_vec(cs[0].pose.pos, Vec3::new(len / 2.0, 0.0, 0.0), 1e-8, "capsule centre");
            // capsule axis (local z) lies along the link's +x
            assert_vec(cs[0].pose.rot * Vec3::Z, Vec3::X, 1e-6, "capsule axis");
        }
    }
    // link inertia: solid cylinder along x about its centre
    let l = &h.links[h.link_index("if_prox").unwrap()];
    let (m, r, len) = (0.065f32, 0.0098f32, 0.054f32);
    assert_close(l.mass, m, 1e-8, "if_prox mass");
    assert_vec(l.com, Vec3::new(0.027, 0.0, 0.0), 1e-8, "if_prox com");
    assert_close(l.inertia[0][0], 0.5 * m * r * r, 1e-10, "Ixx");
    assert_close(l.inertia[1][1], m * (3.0 * r * r + len * len) / 12.0, 1e-10, "Iyy");
    assert_close(l.inertia[2][2], m * (3.0 * r * r + len * len) / 12.0, 1e-10, "Izz");
    assert_eq!(l.inertia[0][1], 0.0);
    // the massless tip frame leaves the distal link alone
    let d = &h.links[h.link_index("if_dist").unwrap()];
    assert_close(d.mass, 0.026, 1e-8, "if_dist mass");
    assert_vec(d.com, Vec3::new(0.01935, 0.0, 0.0), 1e-8, "if_dist com");
}

#[test]
fn dexhand16_fingertip_kinematics() {
    let h = load_hand("dexhand16.urdf");
    let zero = vec![0.0; 16];
    // index straight along +x
    let x_if = 0.055 + 0.0164 + 0.054 + 0.0384 + 0.0387;
    assert_vec(tip_in_wrist(&h, "if_tip", &zero), Vec3::new(x_if, 0.045, 0.0), 1e-6, "index tip at q=0");
    assert_vec(tip_in_wrist(&h, "rf_tip", &zero), Vec3::new(x_if, -0.045, 0.0), 1e-6, "ring tip at q=0");
    // flexing if_j1 by pi/2 about +y turns the rest of the finger toward -z (the palm side)
    let q = q_with(&h, &[("if_j1", FRAC_PI_2)]);
    let curled = Vec3::new(0.055 + 0.0164, 0.045, -(0.054 + 0.0384 + 0.0387));
    assert_vec(tip_in_wrist(&h, "if_tip", &q), curled, 1e-6, "index tip with if_j1 = pi/2");
    // the middle finger did not move
    assert_vec(tip_in_wrist(&h, "mf_tip", &q), Vec3::new(x_if, 0.0, 0.0), 1e-6, "middle tip");
    // abduction about +z swings the index toward +y
    let q = q_with(&h, &[("if_j0", 0.3)]);
    let l = 0.0164 + 0.054 + 0.0384 + 0.0387;
    let abd = Vec3::new(0.055 + l * 0.3f32.cos(), 0.045 + l * 0.3f32.sin(), 0.0);
    assert_vec(tip_in_wrist(&h, "if_tip", &q), abd, 1e-6, "index tip with if_j0 = 0.3");
    // thumb points -x and curls to -z as well
    let x_th = -(0.055 + 0.0177 + 0.0514 + 0.054 + 0.0423);
    let th = tip_in_wrist(&h, "th_tip", &zero);
    assert!(th.x < 0.0);
    assert_vec(th, Vec3::new(x_th, 0.0, 0.0), 1e-6, "thumb tip at q=0");
    let q = q_with(&h, &[("th_j1", FRAC_PI_2)]);
    let th_curled = Vec3::new(-(0.055 + 0.0177), 0.0, -(0.0514 + 0.054 + 0.0423));
    assert_vec(tip_in_wrist(&h, "th_tip", &q), th_curled, 1e-6, "thumb tip with th_j1 = pi/2");
    // fingertip_positions agrees with the per-tip computation
    let all = h.fingertip_positions(&h.forward_kinematics(&zero));
    assert_vec(all[0], Vec3::new(x_if, 0.045, 0.0), 1e-6, "fingertip_positions[0]");
}

#[test]
fn fingertip_option_and_default_suffix() {
    let opts = HandLoadOptions { fingertips: vec!["th_tip".into(), "if_dist".into()], ..Default::default() };
    let h = HandModel::from_urdf_file(&hand_path("dexhand16.urdf"), &opts).unwrap();
    assert_eq!(h.fingertips.len(), 2);
    assert_eq!(h.fingertips[0].name, "th_tip");
    assert_eq!(h.fingertips[0].link, h.link_index("th_dist").unwrap());
    assert_vec(h.fingertips[0].pos, Vec3::new(0.0423, 0.0, 0.0), 1e-7, "th_tip pos");
    assert_eq!(h.fingertips[1].link, h.link_index("if_dist").unwrap());
    assert_eq!(h.fingertips[1].pos, Vec3::ZERO);
    // default: every link whose name contains "tip", case-insensitive, in document order
    let text = robot(&[PALM.into(), link("b_ThumbTIP"), link("a"), link("a_tip"), rev("j_b", "palm", "b_ThumbTIP"), rev("j_a", "palm", "a"), joint("a_fix", "fixed", "a", "a_tip", "")]);
    let h = load_str(&text, "suffix.urdf", &HandLoadOptions::default()).unwrap();
    let names: Vec<&str> = h.fingertips.iter().map(|t| t.name.as_str()).collect();
    assert_eq!(names, ["b_ThumbTIP", "a_tip"]);
    assert_eq!(h.fingertips[1].link, h.link_index("a").unwrap());
    assert_vec(h.fingertips[1].pos, Vec3::new(0.05, 0.0, 0.0), 1e-7, "a_tip pos");
}

// ------------------------------------------------------------------------------------------------
// tri3_mimic

#[test]
fn tri3_counts_and_shapes() {
    let h = load_hand("tri3_mimic.urdf");
    assert_eq!(h.name, "tri3_mimic");
    assert_eq!(h.links[0].name, "wrist");
    assert_eq!(h.joints.len(), 10);
    assert_eq!(h.num_actuated(), 6);
    assert_eq!(h.links.len(), 11);
    assert_eq!(h.colliders.len(), 15);
    let tips: Vec<&str> = h.fingertips.iter().map(|t| t.name.as_str()).collect();
    assert_eq!(tips, ["fa_tip", "fb_tip", "fc_tip"]);
    let count = |f: &dyn Fn(&ColliderShape) -> bool| h.colliders.iter().filter(|c| f(&c.shape)).count();
    assert_eq!(count(&|s| matches!(s, ColliderShape::Box { .. })), 1);
    assert_eq!(count(&|s| matches!(s, ColliderShape::Sphere { .. })), 3);
    assert_eq!(count(&|s| matches!(s, ColliderShape::Capsule { .. })), 11);
    // colliders are grouped by link
    assert!(h.colliders.windows(2).all(|w| w[0].link <= w[1].link));
    let actuated: Vec<&str> = h.actuated_joints().iter().map(|&i| h.joints[i].name.as_str()).collect();
    assert_eq!(actuated, ["wrist_roll", "fa_spread", "fa_j1", "fb_j1", "fc_spread", "fc_j1"]);
    // continuous wrist roll
    let roll = &h.joints[h.joint_index("wrist_roll").unwrap()];
    assert!(roll.continuous);
    assert_eq!((roll.lower, roll.upper), (f32::NEG_INFINITY, f32::INFINITY));
    assert_close(roll.effort, 2.0, 0.0, "roll effort");
    assert_close(roll.damping, 0.05, 1e-9, "roll damping");
    assert_close(roll.friction, 0.01, 1e-9, "roll friction");
    // round palm: cylinder r 0.05, length 0.03 -> capsule half length 0.015, axis z
    let palm = h.link_index("palm").unwrap();
    let pc: Vec<&Collider> = h.colliders.iter().filter(|c| c.link == palm).collect();
    assert_eq!(pc.len(), 2, "palm disc + merged pad");
    assert_eq!(pc[0].shape, ColliderShape::Capsule { radius: 0.05, half_length: 0.015 });
    assert_vec(pc[0].pose.pos, Vec3::new(0.0, 0.0, -0.015), 1e-8, "palm disc centre");
    assert_rot(pc[0].pose.rot, Quat::IDENTITY, 1e-7, "palm disc axis");
}

#[test]
fn tri3_fixed_joints_merge_mass_and_colliders() {
    let h = load_hand("tri3_mimic.urdf");
    let palm = h.link_index("palm").unwrap();
    assert_eq!(palm, 1);
    assert_eq!(h.link_index("pad"), None, "pad is merged");
    let l = &h.links[palm];
    // palm 0.3 kg at z = -0.015 + pad 0.02 kg at z = -0.032
    assert_close(l.mass, 0.32, 1e-7, "palm + pad mass");
    assert_vec(l.com, Vec3::new(0.0, 0.0, (0.3 * -0.015 + 0.02 * -0.032) / 0.32), 1e-8, "merged com");
    // pad box, yawed 45 degrees, its collision origin 5 mm along the pad's x
    let pad = h.colliders.iter().find(|c| c.link == palm && matches!(c.shape, ColliderShape::Box { .. })).unwrap();
    assert_eq!(pad.shape, ColliderShape::Box { half_extents: Vec3::new(0.015, 0.01, 0.002) });
    let d = 0.005 * FRAC_PI_4.cos();
    assert_vec(pad.pose.pos, Vec3::new(d, d, -0.032), 1e-8, "pad collider in palm frame");
    assert_rot(pad.pose.rot, Quat::from_rotation_z(FRAC_PI_4), 1e-7, "pad collider rotation");
    let (pl, pp) = h.frame("pad").unwrap();
    assert_eq!(pl, palm);
    assert_vec(pp.pos, Vec3::new(0.0, 0.0, -0.032), 1e-8, "pad frame");
    // sphere fingertips merged into the distal links
    for f in ["fa", "fb", "fc"] {
        let dist = h.link_index(&format!("{f}_dist")).unwrap();
        assert_close(h.links[dist].mass, 0.035, 1e-8, "dist + tip mass");
        // com: 0.03 kg at z = -0.0225 and 0.005 kg at z = -0.045
        assert_close(h.links[dist].com.z, (0.03 * -0.0225 + 0.005 * -0.045) / 0.035, 1e-8, "dist com");
        let s = h.colliders.iter().find(|c| c.link == dist && matches!(c.shape, ColliderShape::Sphere { .. })).unwrap();
        assert_eq!(s.shape, ColliderShape::Sphere { radius: 0.011 });
        assert_vec(s.pose.pos, Vec3::new(0.0, 0.0, -0.045), 1e-8, "tip sphere");
        let t = h.fingertips.iter().find(|t| t.name == format!("{f}_tip")).unwrap();
        assert_eq!(t.link, dist);
        assert_vec(t.pos, Vec3::new(0.0, 0.0, -0.045), 1e-8, "tip pos");
    }
}

#[test]
fn tri3_mimic_followers_in_fk() {
    let h = load_hand("tri3_mimic.urdf");
    let idx = |n: &str| h.joint_index(n).unwrap();
    let fb_spread = h.joints[idx("fb_spread")].mimic.expect("fb_spread is a follower");
    assert_eq!(fb_spread, Mimic { leader: idx("fa_spread"), multiplier: -1.0, offset: 0.0 });
    for f in ["fa", "fb", "fc"] {
        let m = h.joints[idx(&format!("{f}_j2"))].mimic.expect("distal joints are followers");
        assert_eq!(m.leader, idx(&format!("{f}_j1")));
        assert_close(m.multiplier, 0.8, 1e-7, "multiplier");
        assert_close(m.offset, 0.15, 1e-7, "offset");
    }
    let (roll, spread, q1) = (0.3f32, 0.2f32, 0.5f32);
    let mut q = q_with(&h, &[("wrist_roll", roll), ("fa_spread", spread), ("fa_j1", q1)]);
    // followers' own entries are ignored
    q[idx("fb_spread")] = 9.0;
    q[idx("fa_j2")] = -7.0;
    // finger in its base frame: j1 2 cm below the spread joint, prox 6 cm, dist 4.5 cm, flexion about +y
    let finger = |q1: f32| {
        let q2 = q1 + 0.8 * q1 + 0.15; // absolute angle of the distal segment
        Vec3::new(0.0, 0.0, -0.02) + 0.06 * Vec3::new(-q1.sin(), 0.0, -q1.cos()) + 0.045 * Vec3::new(-q2.sin(), 0.0, -q2.cos())
    };
    let expect = |phi_deg: f32, yaw: f32, local: Vec3| {
        let phi = phi_deg.to_radians();
        let base = Vec3::new(0.035 * phi.cos(), 0.035 * phi.sin(), -0.03);
        let in_palm = base + Quat::from_rotation_z(phi + yaw) * local;
        Quat::from_rotation_z(roll) * (Vec3::new(0.0, 0.0, -0.02) + in_palm)
    };
    assert_vec(tip_in_wrist(&h, "fa_tip", &q), expect(60.0, spread, finger(q1)), 1e-6, "fa tip");
    assert_vec(tip_in_wrist(&h, "fb_tip", &q), expect(-60.0, -spread, finger(0.0)), 1e-6, "fb tip");
    assert_vec(tip_in_wrist(&h, "fc_tip", &q), expect(180.0, 0.0, finger(0.0)), 1e-6, "fc tip");
    // relative rotation of fa_dist w.r.t. fa_prox is 0.8 q1 + 0.15 about y
    let poses = h.forward_kinematics(&q);
    let rel = poses[h.link_index("fa_prox").unwrap()].rot.inverse() * poses[h.link_index("fa_dist").unwrap()].rot;
    assert_rot(rel, Quat::from_rotation_y(0.8 * q1 + 0.15), 1e-6, "distal mimic angle");
    // at q = 0 the fa tip hangs straight-ish: offset 0.15 on the distal joint
    let zero = vec![0.0; h.joints.len()];
    let expected_fa = Vec3::new(0.0175, 0.035 * 60f32.to_radians().sin(), -0.02 - 0.03) + {
        let local = finger(0.0);
        Quat::from_rotation_z(60f32.to_radians()) * local
    };
    assert_vec(tip_in_wrist(&h, "fa_tip", &zero), expected_fa, 1e-6, "fa tip at q = 0");
}

// ------------------------------------------------------------------------------------------------
// loader details on small documents

#[test]
fn mimic_of_mimic_resolves_to_root_leader() {
    // j_c mimics j_b (x3 + 0.2) which mimics j_a (x2 + 0.1): j_c = 6 j_a + 0.5. j_c comes first.
    let text = robot(&[
        PALM.into(),
        link("a"),
        link("b"),
        link("c"),
        joint("j_c", "revolute", "b", "c", r#"<mimic joint="j_b" multiplier="3" offset="0.2"/>"#),
        rev("j_a", "palm", "a"),
        joint("j_b", "continuous", "a", "b", r#"<mimic joint="j_a" multiplier="2" offset="0.1"/>"#),
    ]);
    let h = load_str(&text, "chain.urdf", &HandLoadOptions::default()).unwrap();
    let names: Vec<&str> = h.joints.iter().map(|j| j.name.as_str()).collect();
    assert_eq!(names, ["j_a", "j_b", "j_c"], "topological order, not document order");
    assert_eq!(h.num_actuated(), 1);
    assert_eq!(h.joints[1].mimic, Some(Mimic { leader: 0, multiplier: 2.0, offset: 0.1 }));
    let m = h.joints[2].mimic.unwrap();
    assert_eq!(m.leader, 0);
    assert_close(m.multiplier, 6.0, 1e-6, "composed multiplier");
    assert_close(m.offset, 0.5, 1e-6, "composed offset");
    assert!(h.joints[1].continuous && h.joints[1].lower == f32::NEG_INFINITY);
    let poses = h.forward_kinematics(&[0.1, 0.0, 0.0]);
    let rel = poses[2].rot.inverse() * poses[3].rot;
    assert_rot(rel, Quat::from_rotation_y(6.0 * 0.1 + 0.5), 1e-6, "j_c angle");
}

#[test]
fn fixed_merge_combines_inertia_with_parallel_axis() {
    // palm: 1 kg at the origin, inertia diag(1,1,1)e-3. Fixed child 'weight': its frame at (0.1,0,0)
    // yawed by pi/4, its 1 kg COM 0.1 m along its own x, its inertia diag(1,2,3)e-3 about axes yawed
    // by another pi/4 (90 degrees in all, so diag(2,1,3)e-3 in the palm frame).
    // Merged: COM halfway; both bodies are |d| from it: parallel-axis term 2 (|d|² E − d dᵀ).
    let text = r#"<robot name="inertia">
      <link name="palm"><inertial><mass value="1"/><inertia ixx="1e-3" ixy="0" ixz="0" iyy="1e-3" iyz="0" izz="1e-3"/></inertial>
        <collision><geometry><sphere radius="0.05"/></geometry></collision></link>
      <link name="weight"><inertial><origin xyz="0.1 0 0" rpy="0 0 0.7853981633974483"/><mass value="1"/>
        <inertia ixx="1e-3" ixy="0" ixz="0" iyy="2e-3" iyz="0" izz="3e-3"/></inertial>
        <collision><origin xyz="0 0 0.01" rpy="0 0 0"/><geometry><box size="0.02 0.04 0.06"/></geometry></collision></link>
      <joint name="weld" type="fixed"><parent link="palm"/><child link="weight"/>
        <origin xyz="0.1 0 0" rpy="0 0 0.7853981633974483"/></joint>
    </robot>"#;
    let h = load_str(text, "inertia.urdf", &HandLoadOptions::default()).unwrap();
    assert_eq!(h.links.len(), 1);
    let l = &h.links[0];
    assert_close(l.mass, 2.0, 1e-6, "mass");
    let c = 0.1 * FRAC_PI_4.cos();
    let child_com = Vec3::new(0.1 + c, c, 0.0);
    assert_vec(l.com, child_com / 2.0, 1e-6, "com");
    let d = child_com / 2.0; // both bodies are d away from the com, in opposite directions
    let pa = |i: usize, j: usize| {
        let dd = [d.x, d.y, d.z];
        2.0 * ((if i == j { d.length_squared() } else { 0.0 }) - dd[i] * dd[j])
    };
    // child inertia rotated by yaw pi/2 in total: diag(2,1,3)e-3
    let expect = [[1e-3 + 2e-3 + pa(0, 0), pa(0, 1), 0.0], [pa(1, 0), 1e-3 + 1e-3 + pa(1, 1), 0.0], [0.0, 0.0, 1e-3 + 3e-3 + pa(2, 2)]];
    for (i, (got, want)) in l.inertia.iter().zip(&expect).enumerate() {
        for (j, (g, w)) in got.iter().zip(want).enumerate() {
            assert_close(*g, *w, 1e-7, &format!("inertia[{i}][{j}]"));
        }
    }
    // the box moved with the fixed joint: its origin (0,0,0.01) in the weight frame
    let b = h.colliders.iter().find(|c| matches!(c.shape, ColliderShape::Box { .. })).unwrap();
    assert_eq!(b.link, 0);
    assert_vec(b.pose.pos, Vec3::new(0.1, 0.0, 0.01), 1e-7, "box pos");
    assert_rot(b.pose.rot, Quat::from_rotation_z(FRAC_PI_4), 1e-7, "box rot");
    assert_eq!(b.shape, ColliderShape::Box { half_extents: Vec3::new(0.01, 0.02, 0.03) });
    assert_eq!(h.frame("weight").unwrap().0, 0);
}

#[test]
fn rpy_is_fixed_axis_roll_pitch_yaw() {
    // R = Rz(yaw) Ry(pitch) Rx(roll); with roll = yaw = pi/2: x -> y, y -> z, z -> x.
    let text = robot(&[
        r#"<link name="palm"><collision><origin xyz="0 0 0" rpy="1.5707963267948966 0 1.5707963267948966"/><geometry><capsule radius="0.01" length="0.04"/></geometry></collision>
           <collision><origin xyz="0.1 0.2 0.3" rpy="0.3 0.2 0.1"/><geometry><cylinder radius="0.02" length="0.1"/></geometry></collision></link>"#
            .into(),
    ]);
    let h = load_str(&text, "rpy.urdf", &HandLoadOptions::default()).unwrap();
    assert!(h.joints.is_empty() && h.fingertips.is_empty());
    let r = h.colliders[0].pose.rot;
    assert_vec(r * Vec3::X, Vec3::Y, 1e-6, "x axis");
    assert_vec(r * Vec3::Y, Vec3::Z, 1e-6, "y axis");
    assert_vec(r * Vec3::Z, Vec3::X, 1e-6, "capsule axis");
    assert_eq!(h.colliders[0].shape, ColliderShape::Capsule { radius: 0.01, half_length: 0.02 });
    let expect = Quat::from_rotation_z(0.1) * Quat::from_rotation_y(0.2) * Quat::from_rotation_x(0.3);
    assert_rot(h.colliders[1].pose.rot, expect, 1e-6, "general rpy");
    assert_vec(h.colliders[1].pose.pos, Vec3::new(0.1, 0.2, 0.3), 0.0, "pos");
    assert_eq!(h.colliders[1].shape, ColliderShape::Capsule { radius: 0.02, half_length: 0.05 });
}

// ------------------------------------------------------------------------------------------------
// meshes

fn mesh_hand(filename: &str, extra: &str) -> String {
    format!(
        r#"<robot name="mesh_hand"><link name="palm"><collision><geometry><box size="0.1 0.1 0.02"/></geometry></collision></link>
        <link name="finger"><collision><origin xyz="0 0 0.1" rpy="0 0 0"/><geometry><mesh filename="{filename}" {extra}/></geometry></collision></link>
        <joint name="j" type="revolute"><parent link="palm"/><child link="finger"/><axis xyz="0 1 0"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint></robot>"#
    )
}

fn binary_stl(tris: &[[[f32; 3]; 3]]) -> Vec<u8> {
    let mut b = vec![0u8; 80];
    b.extend_from_slice(&(tris.len() as u32).to_le_bytes());
    for t in tris {
        for _ in 0..3 {
            b.extend_from_slice(&0f32.to_le_bytes());
        }
        for v in t {
            for c in v {
                b.extend_from_slice(&c.to_le_bytes());
            }
        }
        b.extend_from_slice(&[0, 0]);
    }
    b
}

fn opts(m: MeshApprox) -> HandLoadOptions {
    HandLoadOptions { mesh_approx: m, ..Default::default() }
}

#[test]
fn mesh_collision_is_an_error_without_opt_in() {
    let text = mesh_hand("meshes/finger.stl", "");
    let msg = expect_err(&text, "/robots/mesh_hand.urdf", &HandLoadOptions::default(), &["link 'finger'", "mesh", "finger.stl", "mesh_approx"]);
    assert!(msg.starts_with("link 'finger' in /robots/mesh_hand.urdf"), "{msg}");
}

/// The fitted collider of link 1 (`finger`, whose mesh sits at z = 0.1 in the link) contains every
/// mesh vertex (given in the mesh frame, scaled) and is no bigger than the axis-aligned primitive of
/// its kind; the mesh report says so. Returns the collider's shape.
fn assert_fit_contains(h: &HandModel, mesh_verts: &[Vec3], file: &str, what: &str) -> ColliderShape {
    let c = h.colliders.iter().find(|c| c.link == 1).unwrap();
    for v in mesh_verts {
        let p = c.pose.inverse().transform_point(*v + Vec3::new(0.0, 0.0, 0.1));
        let outside = match c.shape {
            ColliderShape::Sphere { radius } => p.length() - radius,
            ColliderShape::Capsule { radius, half_length } => (p - Vec3::new(0.0, 0.0, p.z.clamp(-half_length, half_length))).length() - radius,
            ColliderShape::Box { half_extents } => (p.abs() - half_extents).max_element(),
        };
        assert!(outside < 1e-6, "{what}: vertex {v} is {outside} m outside {:?}", c.shape);
    }
    assert_eq!(h.mesh_fits.len(), 1, "{what}");
    let r = &h.mesh_fits[0];
    assert_eq!(r.link, "finger", "{what}");
    assert_eq!(r.mesh.file_name().unwrap().to_string_lossy(), file, "{what}");
    assert_eq!(r.shape, c.shape, "{what}");
    assert!(r.volume_ratio >= 1.0 - 1e-4 && r.volume_ratio <= r.aligned_volume_ratio * (1.0 + 1e-5), "{what}: {r:?}");
    assert!(r.max_gap >= 0.0 && r.hull_volume > 0.0, "{what}: {r:?}");
    c.shape
}

#[test]
fn mesh_opt_in_binary_stl_box_and_capsule() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir(dir.path().join("meshes")).unwrap();
    let tris = [
        [[-0.01, 0.0, -0.005], [0.03, 0.0, 0.0], [0.0, 0.02, 0.005]],
        [[0.0, 0.01, 0.0], [0.01, 0.005, 0.001], [0.02, 0.015, -0.002]],
    ];
    std::fs::write(dir.path().join("meshes/finger.STL"), binary_stl(&tris)).unwrap();
    let urdf = dir.path().join("hand.urdf");
    std::fs::write(&urdf, mesh_hand("meshes/finger.STL", r#"scale="2 1 1""#)).unwrap();
    // scaled by 2 along x
    let verts: Vec<Vec3> = tris.iter().flatten().map(|v| Vec3::new(2.0 * v[0], v[1], v[2])).collect();
    let h = HandModel::from_urdf_file(&urdf, &opts(MeshApprox::Box)).unwrap();
    assert!(matches!(assert_fit_contains(&h, &verts, "finger.STL", "box"), ColliderShape::Box { .. }));
    let h = HandModel::from_urdf_file(&urdf, &opts(MeshApprox::Capsule)).unwrap();
    assert!(matches!(assert_fit_contains(&h, &verts, "finger.STL", "capsule"), ColliderShape::Capsule { .. } | ColliderShape::Sphere { .. }));
    // a mesh that is flat is an error naming the link and the file
    std::fs::write(dir.path().join("meshes/finger.STL"), binary_stl(&tris[..1])).unwrap();
    let msg = format!("{:#}", HandModel::from_urdf_file(&urdf, &opts(MeshApprox::Capsule)).unwrap_err());
    check_msg(&msg, "hand.urdf", &["link 'finger'", "finger.STL", "flat"]);
}

#[test]
fn mesh_opt_in_obj_via_package_and_ascii_stl_via_file_url() {
    let dir = tempfile::tempdir().unwrap();
    let pkg = dir.path().join("my_hand");
    std::fs::create_dir_all(pkg.join("urdf")).unwrap();
    std::fs::create_dir_all(pkg.join("meshes")).unwrap();
    // OBJ: a tetrahedron, long along y; faces, normals and comments are ignored
    let obj = "# a finger\nv -0.01 -0.05 0.0\nv 0.01 0.05 0.02\nv 0.0 0.0 0.03 1.0\nv 0.01 -0.05 0.0\nvn 0 0 1\nvt 0.5 0.5\nf 1 2 3\n";
    let verts = [Vec3::new(-0.01, -0.05, 0.0), Vec3::new(0.01, 0.05, 0.02), Vec3::new(0.0, 0.0, 0.03), Vec3::new(0.01, -0.05, 0.0)];
    std::fs::write(pkg.join("meshes/finger.obj"), obj).unwrap();
    let urdf = pkg.join("urdf/hand.urdf");
    std::fs::write(&urdf, mesh_hand("package://my_hand/meshes/finger.obj", "")).unwrap();
    let h = HandModel::from_urdf_file(&urdf, &opts(MeshApprox::Capsule)).unwrap();
    if let ColliderShape::Capsule { .. } = assert_fit_contains(&h, &verts, "finger.obj", "obj capsule") {
        let c = h.colliders.iter().find(|c| c.link == 1).unwrap();
        assert!((c.pose.rot * Vec3::Z).y.abs() > 0.9, "the capsule lies along the mesh's long axis (y)");
    }
    let h = HandModel::from_urdf_file(&urdf, &opts(MeshApprox::Box)).unwrap();
    assert_fit_contains(&h, &verts, "finger.obj", "obj box");

    // ASCII STL by absolute file:// URL, half size via scale
    let stl = "solid cube\n facet normal 0 0 1\n  outer loop\n   vertex 0 0 0\n   vertex 0.04 0.02 0\n   vertex 0 0 0.1\n  endloop\n endfacet\n facet normal 1 0 0\n  outer loop\n   vertex 0 0.03 0.02\n   vertex 0.04 0.02 0\n   vertex 0 0 0.1\n  endloop\n endfacet\nendsolid cube\n";
    let verts: Vec<Vec3> = [[0.0, 0.0, 0.0], [0.04, 0.02, 0.0], [0.0, 0.0, 0.1], [0.0, 0.03, 0.02]].iter().map(|v| Vec3::from_array(*v) * 0.5).collect();
    let abs = dir.path().join("abs.stl");
    std::fs::write(&abs, stl).unwrap();
    let text = mesh_hand(&format!("file://{}", abs.display()), r#"scale="0.5 0.5 0.5""#);
    let h = load_str(&text, "/elsewhere/hand.urdf", &opts(MeshApprox::Capsule)).unwrap();
    assert_fit_contains(&h, &verts, "abs.stl", "ascii stl capsule");
}

#[test]
fn mesh_errors_name_link_and_file() {
    let text = mesh_hand("package://my_hand/meshes/finger.dae", "");
    expect_err(&text, "/robots/dae_hand.urdf", &opts(MeshApprox::Box), &["link 'finger'", "finger.dae", "'.dae'"]);
    let text = mesh_hand("meshes/missing_mesh.obj", "");
    expect_err(&text, "/nonexistent/robots/nomesh_hand.urdf", &opts(MeshApprox::Box), &["link 'finger'", "missing_mesh.obj", "not found"]);
}

// ------------------------------------------------------------------------------------------------
// errors

#[test]
fn error_missing_file() {
    let path = Path::new("/nonexistent/dir/missing_hand.urdf");
    let msg = format!("{:#}", HandModel::from_urdf_file(path, &HandLoadOptions::default()).unwrap_err());
    check_msg(&msg, "missing_hand.urdf", &["cannot read"]);
}

#[test]
fn error_malformed_xml() {
    let text = r#"<robot name="x"><link name="palm"><collision></link></robot>"#;
    expect_err(text, "broken_hand.urdf", &HandLoadOptions::default(), &["cannot parse"]);
    expect_err("", "empty_hand.urdf", &HandLoadOptions::default(), &["cannot parse"]);
    // a joint without parent
    let text = r#"<robot name="x"><link name="palm"/><link name="a"/><joint name="j" type="fixed"><child link="a"/></joint></robot>"#;
    expect_err(text, "noparent_hand.urdf", &HandLoadOptions::default(), &["cannot parse"]);
}

#[test]
fn error_unsupported_joint_types() {
    for ty in ["floating", "planar", "prismatic"] {
        let text = robot(&[PALM.into(), link("a"), joint("slider", ty, "palm", "a", "")]);
        let msg = expect_err(&text, "hand.urdf", &HandLoadOptions::default(), &["joint 'slider'"]);
        assert_eq!(msg, format!("joint 'slider' in hand.urdf is {ty}; dextrain hands support revolute, continuous and fixed joints"));
    }
}

#[test]
fn error_loops_and_roots() {
    // link 'b' has two parent joints
    let text = robot(&[PALM.into(), link("a"), link("b"), rev("ja", "palm", "a"), rev("jb1", "palm", "b"), rev("jb2", "a", "b")]);
    expect_err(&text, "loop_hand.urdf", &HandLoadOptions::default(), &["link 'b'", "'jb1'", "'jb2'", "two parent joints"]);
    // a cycle detached from the root
    let text = robot(&[PALM.into(), link("a"), link("b"), rev("ab", "a", "b"), rev("ba", "b", "a")]);
    expect_err(&text, "cycle_hand.urdf", &HandLoadOptions::default(), &["link 'a'", "loop"]);
    // every link has a parent
    let text = robot(&[PALM.into(), link("a"), rev("pa", "palm", "a"), rev("ap", "a", "palm")]);
    expect_err(&text, "noroot_hand.urdf", &HandLoadOptions::default(), &["loop", "link 'palm'"]);
    // two roots
    let text = robot(&[PALM.into(), link("a"), link("stray")]);
    let _ = expect_err(&text, "roots_hand.urdf", &HandLoadOptions::default(), &["several root links", "'palm'", "'a'", "'stray'"]);
    // unknown link
    let text = robot(&[PALM.into(), link("a"), rev("ja", "palm", "a"), rev("jx", "a", "ghost")]);
    expect_err(&text, "unknown_link_hand.urdf", &HandLoadOptions::default(), &["joint 'jx'", "unknown child link 'ghost'"]);
}

#[test]
fn error_mimic() {
    let text = robot(&[PALM.into(), link("a"), link("b"), rev("ja", "palm", "a"), joint("jb", "revolute", "a", "b", r#"<mimic joint="nobody"/>"#)]);
    expect_err(&text, "mimic_hand.urdf", &HandLoadOptions::default(), &["joint 'jb'", "unknown joint 'nobody'"]);
    let text = robot(&[PALM.into(), link("a"), link("b"), rev("ja", "palm", "a"), joint("jb", "revolute", "a", "b", r#"<mimic joint="jb"/>"#)]);
    expect_err(&text, "self_mimic_hand.urdf", &HandLoadOptions::default(), &["joint 'jb'", "itself"]);
    let text = robot(&[
        PALM.into(),
        link("a"),
        link("b"),
        joint("ja", "revolute", "palm", "a", r#"<mimic joint="jb"/>"#),
        joint("jb", "revolute", "a", "b", r#"<mimic joint="ja"/>"#),
    ]);
    expect_err(&text, "cycle_mimic_hand.urdf", &HandLoadOptions::default(), &["joint 'ja'", "cycle"]);
    let text = robot(&[PALM.into(), link("a"), link("b"), joint("ja", "fixed", "palm", "a", ""), joint("jb", "revolute", "a", "b", r#"<mimic joint="ja"/>"#)]);
    expect_err(&text, "fixed_mimic_hand.urdf", &HandLoadOptions::default(), &["joint 'jb'", "joint 'ja'", "fixed"]);
}

#[test]
fn error_limits() {
    let lim = |l: &str| {
        robot(&[
            PALM.into(),
            link("a"),
            format!(r#"<joint name="flex" type="revolute"><parent link="palm"/><child link="a"/><axis xyz="0 1 0"/>{l}</joint>"#),
        ])
    };
    expect_err(&lim(r#"<limit lower="1" upper="-1" effort="1" velocity="1"/>"#), "limits_hand.urdf", &HandLoadOptions::default(), &["joint 'flex'", "lower limit 1 > upper limit -1"]);
    expect_err(&lim(r#"<limit lower="-1" upper="1" effort="0" velocity="1"/>"#), "effort_hand.urdf", &HandLoadOptions::default(), &["joint 'flex'", "effort"]);
    expect_err(&lim(r#"<limit lower="-1" upper="1" effort="1" velocity="-2"/>"#), "velocity_hand.urdf", &HandLoadOptions::default(), &["joint 'flex'", "velocity"]);
    expect_err(&lim(""), "nolimit_hand.urdf", &HandLoadOptions::default(), &["joint 'flex'", "no <limit>"]);
    expect_err(&lim(r#"<limit lower="-1" upper="nan" effort="1" velocity="1"/>"#), "nan_hand.urdf", &HandLoadOptions::default(), &["joint 'flex'", "non-finite"]);
    // URDF 1.2: omitted limits are infinite, which a revolute joint cannot have
    let text = lim(r#"<limit effort="1" velocity="1"/>"#).replace("<robot ", "<robot version=\"1.2\" ");
    expect_err(&text, "v12_hand.urdf", &HandLoadOptions::default(), &["joint 'flex'", "non-finite limits"]);
}

#[test]
fn error_too_many() {
    // MAX_JOINTS + 1 movable joints in a chain
    let mut parts = vec![PALM.to_string()];
    let mut parent = "palm".to_string();
    for i in 0..=MAX_JOINTS {
        let name = format!("l{i}");
        parts.push(format!(r#"<link name="{name}"/>"#));
        parts.push(rev(&format!("j{i}"), &parent, &name));
        parent = name;
    }
    let (n, last, most) = (format!("{} movable", MAX_JOINTS + 1), format!("joint 'j{MAX_JOINTS}'"), format!("at most {MAX_JOINTS}"));
    expect_err(&robot(&parts), "long_hand.urdf", &HandLoadOptions::default(), &[&n, &last, &most]);
    // MAX_COLLIDERS + 1 colliders
    let col = r#"<collision><geometry><sphere radius="0.01"/></geometry></collision>"#.repeat(MAX_COLLIDERS + 1);
    let text = robot(&[format!(r#"<link name="palm">{col}</link>"#)]);
    let (n, most) = (format!("{} collision shapes", MAX_COLLIDERS + 1), format!("at most {MAX_COLLIDERS}"));
    expect_err(&text, "spiky_hand.urdf", &HandLoadOptions::default(), &[&n, "link 'palm'", &most]);
    // 7 fingertips, one per finger
    let mut parts = vec![PALM.to_string()];
    for i in 0..=MAX_TIPS {
        parts.push(link(&format!("f{i}")));
        parts.push(rev(&format!("j{i}"), "palm", &format!("f{i}")));
        parts.push(format!(r#"<link name="f{i}_tip"/>"#));
        parts.push(joint(&format!("t{i}"), "fixed", &format!("f{i}"), &format!("f{i}_tip"), ""));
    }
    expect_err(&robot(&parts), "octopus_hand.urdf", &HandLoadOptions::default(), &["7 fingertip frames", "f6_tip", "at most 6"]);
}

#[test]
fn error_fingertips_and_colliders() {
    let opts = HandLoadOptions { fingertips: vec!["if_tip".into(), "pinky_tip".into()], ..Default::default() };
    let path = hand_path("dexhand16.urdf");
    let msg = format!("{:#}", HandModel::from_urdf_file(&path, &opts).unwrap_err());
    check_msg(&msg, "dexhand16.urdf", &["fingertip 'pinky_tip'", "does not exist"]);
    // no collision at all
    let text = robot(&[r#"<link name="palm"/>"#.into(), r#"<link name="a"/>"#.into(), rev("ja", "palm", "a")]);
    expect_err(&text, "ghost_hand.urdf", &HandLoadOptions::default(), &["no collision", "'palm'"]);
}

#[test]
fn error_bad_numbers() {
    let with_palm = |palm: &str| robot(&[palm.to_string(), link("a"), rev("ja", "palm", "a")]);
    let bad_mass = with_palm(r#"<link name="palm"><inertial><mass value="-1"/><inertia ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"/></inertial></link>"#);
    expect_err(&bad_mass, "mass_hand.urdf", &HandLoadOptions::default(), &["link 'palm'", "negative mass"]);
    let nan_mass = with_palm(r#"<link name="palm"><inertial><mass value="NaN"/><inertia ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"/></inertial></link>"#);
    expect_err(&nan_mass, "nanmass_hand.urdf", &HandLoadOptions::default(), &["link 'palm'", "non-finite mass"]);
    let bad_box = with_palm(r#"<link name="palm"><collision><geometry><box size="0.1 -0.1 0.02"/></geometry></collision></link>"#);
    expect_err(&bad_box, "box_hand.urdf", &HandLoadOptions::default(), &["link 'palm'", "box size 0.1 -0.1 0.02"]);
    let bad_radius = with_palm(r#"<link name="palm"><collision><geometry><cylinder radius="-0.01" length="0.1"/></geometry></collision></link>"#);
    expect_err(&bad_radius, "radius_hand.urdf", &HandLoadOptions::default(), &["link 'palm'", "cylinder radius -0.01"]);
    let inf_origin = robot(&[
        PALM.into(),
        link("a"),
        r#"<joint name="ja" type="revolute"><parent link="palm"/><child link="a"/><origin xyz="0 inf 0"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>"#.into(),
    ]);
    expect_err(&inf_origin, "inf_hand.urdf", &HandLoadOptions::default(), &["joint 'ja'", "non-finite <origin>"]);
    let zero_axis = robot(&[
        PALM.into(),
        link("a"),
        r#"<joint name="ja" type="revolute"><parent link="palm"/><child link="a"/><axis xyz="0 0 0"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>"#.into(),
    ]);
    expect_err(&zero_axis, "axis_hand.urdf", &HandLoadOptions::default(), &["joint 'ja'", "axis"]);
}

// ------------------------------------------------------------------------------------------------
// inputs the fuzzing review found getting through (issue 12, item 8)

/// Finding 2: 100,000 nested elements (700 kB) overflowed the stack inside urdf-rs (an abort).
/// The pre-scan bounds the nesting and the size with a one-line error naming the file and the line.
#[test]
fn deeply_nested_urdf_is_an_error_not_a_stack_overflow() {
    let deep = format!("<robot name=\"x\">{}{}</robot>", "<a>".repeat(100_000), "</a>".repeat(100_000));
    let msg = expect_err(&deep, "deep_hand.urdf", &HandLoadOptions::default(), &["cannot parse", "line 1", "<a>", "at most 32 levels"]);
    assert!(msg.len() < 400, "{msg}");
    // the depth is counted across lines and through comments and self-closing elements
    let mut text = String::from("<?xml version=\"1.0\"?>\n<robot name=\"x\">\n");
    for _ in 0..40 {
        text.push_str("<b><!-- <c> --><d/>\n");
    }
    expect_err(&text, "deep2_hand.urdf", &HandLoadOptions::default(), &["line 33", "<d>", "nested 33 levels"]);
    // 32 levels is fine for the pre-scan (urdf-rs ignores the unknown elements)
    let ok = robot(&[PALM.into(), link("a"), rev("ja", "palm", "a"), format!("{}{}", "<e>".repeat(31), "</e>".repeat(31))]);
    load_str(&ok, "nested_ok.urdf", &HandLoadOptions::default()).expect("31 levels inside <robot> load");
    // a file larger than MAX_URDF_BYTES is refused before it is read
    let dir = tempfile::tempdir().unwrap();
    let big = dir.path().join("big_hand.urdf");
    std::fs::write(&big, vec![b' '; MAX_URDF_BYTES + 1]).unwrap();
    let msg = format!("{:#}", HandModel::from_urdf_file(&big, &HandLoadOptions::default()).unwrap_err());
    check_msg(&msg, "big_hand.urdf", &["bytes", &MAX_URDF_BYTES.to_string()]);
}

/// Finding 3: numbers that do not fit the model (`ixz="-1e300"`, `xyz="1e300 …"`, mass 0 or 1e30, …)
/// were accepted; each is now an error naming the link or joint and the attribute.
#[test]
fn urdf_numbers_that_do_not_fit_the_model_are_errors() {
    let o = HandLoadOptions::default();
    let inertial = |mass: &str, inertia: &str| {
        format!(r#"<link name="palm"><inertial><origin xyz="0 0 0"/><mass value="{mass}"/><inertia {inertia}/></inertial><collision><geometry><box size="0.08 0.1 0.02"/></geometry></collision></link>"#)
    };
    let diag = r#"ixx="1e-4" ixy="0" ixz="0" iyy="1e-4" iyz="0" izz="1e-4""#;
    let with_palm = |palm: String| robot(&[palm, link("a"), rev("ja", "palm", "a")]);
    let cases: Vec<(&str, String, Vec<&str>)> = vec![
        ("ixz.urdf", with_palm(inertial("0.2", &diag.replace(r#"ixz="0""#, r#"ixz="-1e300""#))), vec!["link 'palm'", "ixz"]),
        ("indefinite.urdf", with_palm(inertial("0.2", &diag.replace(r#"ixy="0""#, r#"ixy="5e-4""#))), vec!["link 'palm'", "positive semi-definite"]),
        ("mass0.urdf", with_palm(inertial("0", diag)), vec!["link 'palm'", "mass", "leave <inertial> out"]),
        ("mass1e30.urdf", with_palm(inertial("1e30", diag)), vec!["link 'palm'", "mass", "100"]),
        ("com.urdf", with_palm(inertial("0.2", diag).replace(r#"<origin xyz="0 0 0"/>"#, r#"<origin xyz="0 0 50"/>"#)), vec!["link 'palm'", "<inertial><origin> xyz 0 0 50"]),
        ("xyz.urdf", robot(&[PALM.into(), link("a"), joint("ja", "revolute", "palm", "a", "").replace(r#"xyz="0.05 0 0""#, r#"xyz="1e300 0 0""#)]), vec!["joint 'ja'", "<origin> xyz 1e300 0 0"]),
        ("rpy.urdf", robot(&[PALM.into(), link("a"), joint("ja", "revolute", "palm", "a", "").replace(r#"rpy="0 0 0""#, r#"rpy="0 1e10 0""#)]), vec!["joint 'ja'", "rpy"]),
        ("axis.urdf", robot(&[PALM.into(), link("a"), joint("ja", "revolute", "palm", "a", "").replace(r#"<axis xyz="0 1 0"/>"#, r#"<axis xyz="1e300 1e300 0"/>"#)]), vec!["joint 'ja'", "axis"]),
        ("lower.urdf", robot(&[PALM.into(), link("a"), joint("ja", "revolute", "palm", "a", "").replace(r#"lower="-1""#, r#"lower="-1e4""#)]), vec!["joint 'ja'", "<limit lower> -10000"]),
        ("effort.urdf", robot(&[PALM.into(), link("a"), joint("ja", "revolute", "palm", "a", "").replace(r#"effort="1""#, r#"effort="1e30""#)]), vec!["joint 'ja'", "effort limit 1e30"]),
        ("velocity.urdf", robot(&[PALM.into(), link("a"), joint("ja", "revolute", "palm", "a", "").replace(r#"velocity="2""#, r#"velocity="1e300""#)]), vec!["joint 'ja'", "velocity limit"]),
        ("damping.urdf", robot(&[PALM.into(), link("a"), joint("ja", "revolute", "palm", "a", r#"<dynamics damping="1e9"/>"#)]), vec!["joint 'ja'", "<dynamics damping>"]),
        (
            "mimic.urdf",
            robot(&[PALM.into(), link("a"), link("b"), rev("ja", "palm", "a"), joint("jb", "revolute", "a", "b", r#"<mimic joint="ja" multiplier="1e6"/>"#)]),
            vec!["joint 'jb'", "multiplier"],
        ),
        (
            "collision_origin.urdf",
            with_palm(r#"<link name="palm"><collision><origin xyz="0 -1e300 0"/><geometry><sphere radius="0.01"/></geometry></collision></link>"#.into()),
            vec!["link 'palm'", "<collision><origin>"],
        ),
        ("radius.urdf", with_palm(r#"<link name="palm"><collision><geometry><sphere radius="1e3"/></geometry></collision></link>"#.into()), vec!["link 'palm'", "sphere radius 1000"]),
    ];
    for (file, text, needles) in &cases {
        expect_err(text, file, &o, needles);
    }
    // a chain of mimics whose composed multiplier grows past the bound
    let mut parts = vec![PALM.to_string(), link("l0"), rev("j0", "palm", "l0")];
    for i in 1..6 {
        parts.push(link(&format!("l{i}")));
        parts.push(joint(&format!("j{i}"), "revolute", &format!("l{}", i - 1), &format!("l{i}"), &format!(r#"<mimic joint="j{}" multiplier="3"/>"#, i - 1)));
    }
    expect_err(&robot(&parts), "chain.urdf", &o, &["joint 'j5'", "composed"]);
    // what real hands have keeps loading: a link without <inertial> (a massless frame), a tip with a
    // small mass and a zero inertia (Shadow), an inertia breaking the triangle inequality (Allegro)
    let fine = robot(&[
        PALM.into(),
        r#"<link name="frame"/>"#.into(),
        joint("jf", "fixed", "palm", "frame", ""),
        inertial("0.001", r#"ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0""#).replace("\"palm\"", "\"tip\""),
        rev("jt", "palm", "tip"),
        inertial("0.05", r#"ixx="1.3e-5" ixy="0" ixz="0" iyy="7.1e-5" iyz="0" izz="9.98e-5""#).replace("\"palm\"", "\"a\""),
        rev("ja", "palm", "a"),
    ]);
    let h = load_str(&fine, "fine.urdf", &o).expect("real-hand numbers load");
    assert_eq!(h.links.len(), 3);
    assert_close(h.links[1].mass, 0.001, 1e-9, "the tip's mass");
}

/// The real hands under ../shared/hands (Allegro, LEAP, Shadow, Inspire, Ability, SCHUNK SVH; see
/// its SOURCES.md) and the project's own hands load with the bounds of finding 3 in force.
#[test]
fn real_and_shipped_hands_still_load() {
    for file in ["dexhand16.urdf", "tri3_mimic.urdf"] {
        let h = load_hand(file);
        assert!(h.total_mass() > 0.0, "{file}");
    }
    let shared = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/hands");
    if !shared.is_dir() {
        eprintln!("real_and_shipped_hands_still_load: {} does not exist; only the shipped hands were checked", shared.display());
        return;
    }
    // every config that loaded before the bounds of finding 3 (checked with `dextrain check`)
    let load = [
        "ability/config.toml",
        "allegro/config.toml",
        "inspire/config.toml",
        "leap_sim/config.toml",
        "schunk_svh/config.toml",
        "shadow/config.toml",
        // more colliders than the old maximum of 32: LEAP's 71, the unmodified Shadow's 45 (and 24 joints)
        "leap/config.toml",
        "broken/box_leap.toml",
        "broken/orig_shadow.toml",
        "broken/box_ability.toml",
        "broken/box_allegro.toml",
        "broken/box_inspire.toml",
        "broken/box_schunk_svh.toml",
        "broken/box_shadow.toml",
        "broken/capsule_leap_sim.toml",
        "broken/leap_sim_notips.toml",
        "broken/package_uri.toml",
    ];
    for c in load.map(|c| shared.join(c)) {
        let cfg = dextrain::config::Config::load(&c).unwrap_or_else(|e| panic!("{}: {e:#}", c.display()));
        let model = dextrain::env::SimModel::from_config(&cfg).unwrap_or_else(|e| panic!("{}: {e:#}", c.display()));
        assert!(model.hand.total_mass() > 0.0 && !model.hand.joints.is_empty(), "{}", c.display());
    }
    // the real hand refused before, still for its own reason (not the new bounds)
    let tmp = tempfile::tempdir().unwrap();
    for (c, why) in [(allegro_without_limits(&shared, tmp.path()), "effort limit 0")] {
        let cfg = dextrain::config::Config::load(&c).unwrap();
        let e = format!("{:#}", dextrain::env::SimModel::from_config(&cfg).unwrap_err());
        assert!(e.contains(why), "{}: {e}", c.display());
    }
}

/// Finding 4: urdf-rs's vague errors (`missing field 'link'`, `unknown variant ''`, `Wrong vector
/// element count…`, an XmlEvent dump) did not name the element; a 5,000-character value was printed
/// whole. The errors now name the link or joint, the element, the attribute and the line, and cut
/// quoted values to 80 characters.
#[test]
fn malformed_urdf_errors_name_the_element_and_stay_short() {
    let o = HandLoadOptions::default();
    let j = |extra: &str| robot(&[PALM.into(), link("a"), joint("ja", "revolute", "palm", "a", extra)]);
    let cases: Vec<(&str, String, Vec<&str>)> = vec![
        ("noattr.urdf", j("").replace(r#"<parent link="palm"/>"#, "<parent/>"), vec!["joint 'ja'", "<parent>", "no attribute `link`"]),
        ("type.urdf", j("").replace(r#"type="revolute""#, r#"type="""#), vec!["joint 'ja'", "`type`", "revolute, continuous"]),
        ("vec.urdf", j("").replace(r#"xyz="0.05 0 0""#, r#"xyz="""#), vec!["joint 'ja'", "<origin>", "`xyz`", "3 numbers"]),
        ("vec2.urdf", j("").replace(r#"xyz="0.05 0 0""#, r#"xyz="0.05 0 x 0""#), vec!["joint 'ja'", "<origin>", "\"0.05 0 x 0\""]),
        ("mass.urdf", robot(&[PALM.replace(r#"value="0.2""#, r#"value="heavy""#)]), vec!["link 'palm'", "<mass>", "`value`", "one number"]),
        ("nomass.urdf", robot(&[PALM.replace(r#"<mass value="0.2"/>"#, "")]), vec!["link 'palm'", "<inertial>", "no <mass>"]),
        ("geometry.urdf", robot(&[PALM.replace(r#"<box size="0.08 0.1 0.02"/>"#, "")]), vec!["link 'palm'", "<geometry>", "0 shapes"]),
        ("shape.urdf", robot(&[PALM.replace("<box ", "<cone ")]), vec!["link 'palm'", "unknown geometry <cone>"]),
        ("twice.urdf", j(r#"<origin xyz="0 0 0"/>"#), vec!["joint 'ja'", "2 <origin> elements"]),
        ("text.urdf", j("oops"), vec!["joint 'ja'", "holds text"]),
        ("mimic.urdf", j("<mimic/>"), vec!["joint 'ja'", "<mimic>", "`joint`"]),
        ("noname.urdf", robot(&[PALM.replace(r#"<link name="palm">"#, "<link>")]), vec!["<link>", "`name`"]),
        ("root.urdf", "<robots><link name=\"palm\"/></robots>".into(), vec!["root element is <robots>", "<robot>"]),
    ];
    for (file, text, needles) in &cases {
        let msg = expect_err(text, file, &o, needles);
        assert!(msg.contains("line "), "{msg}");
    }
    // the line is the element's
    let text = format!("<robot name=\"x\">\n{PALM}\n{}\n\n{}\n</robot>", link("a"), joint("ja", "revolute", "palm", "a", "").replace(r#"<child link="a"/>"#, "<child/>"));
    expect_err(&text, "lines.urdf", &o, &["line 5: joint 'ja': <child>"]);
    // a 5,000-character value is cut to 80 characters, in the pre-scan's errors and the loader's
    let long = "9".repeat(5000);
    let msg = expect_err(&j("").replace(r#"xyz="0.05 0 0""#, &format!(r#"xyz="{long}""#)), "long.urdf", &o, &["joint 'ja'", "…"]);
    assert!(msg.len() < 400, "{} characters: {msg}", msg.len());
    let ghost = "g".repeat(5000);
    let text = robot(&[PALM.into(), link("a"), rev("ja", "palm", "a"), rev("jx", "a", &ghost)]);
    let msg = expect_err(&text, "ghost.urdf", &o, &["joint 'jx'", "unknown child link", "…"]);
    assert!(msg.len() < 400, "{} characters: {msg}", msg.len());
}

// ------------------------------------------------------------------------------------------------
// fingertips and limits from the config (issue "Real hands … out of the box", item 3)

/// ../shared/hands (the real hands), or None with the reason printed.
fn shared_hands(test: &str) -> Option<PathBuf> {
    let shared = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/hands");
    if shared.is_dir() {
        Some(shared)
    } else {
        eprintln!("{test}: SKIPPED, {} does not exist (the real hands are not part of the project)", shared.display());
        None
    }
}

/// The ROS Allegro's test config (`shared/hands/allegro_simlab/config.toml`) without the
/// `effort` and `velocity` lines that make up for its URDF's zero limits, written into `dir`
/// (the URDF path made absolute): the config that the URDF's zeros must refuse.
fn allegro_without_limits(shared: &Path, dir: &Path) -> PathBuf {
    let src = shared.join("allegro_simlab");
    let text = std::fs::read_to_string(src.join("config.toml")).unwrap();
    let kept: Vec<String> = text
        .lines()
        .filter(|l| !l.trim_start().starts_with("effort") && !l.trim_start().starts_with("velocity"))
        .map(|l| if l.trim_start().starts_with("urdf") { format!("urdf = {:?}", src.join("allegro_hand_description_right.urdf").display().to_string()) } else { l.to_string() })
        .collect();
    let out = dir.join("allegro_without_limits.toml");
    std::fs::write(&out, kept.join("\n")).unwrap();
    out
}

fn tip_names(h: &HandModel) -> Vec<&str> {
    h.fingertips.iter().map(|t| t.name.as_str()).collect()
}

fn chain_ends(h: &HandModel) -> Vec<&str> {
    h.finger_chains().iter().map(|&l| h.links[l].name.as_str()).collect()
}

/// A shared hand's config with `hand.fingertips` removed (and `sets` applied), built into a model.
fn load_shared_without_tips(config: &Path, sets: &[&str]) -> HandModel {
    let sets: Vec<String> = sets.iter().map(|s| s.to_string()).chain(["hand.fingertips=[]".to_string()]).collect();
    let cfg = dextrain::config::Config::load_with_overrides(config, &sets).unwrap_or_else(|e| panic!("{}: {e:#}", config.display()));
    dextrain::env::SimModel::from_config(&cfg).unwrap_or_else(|e| panic!("{}: {e:#}", config.display())).hand
}

/// The hand's warnings about its fingertips (not those about poor mesh fits).
fn tip_warnings(h: &HandModel) -> Vec<&String> {
    h.warnings.iter().filter(|w| !w.contains("poor mesh fit")).collect()
}

/// Finding: default detection took the links whose name ENDS in "tip", and found 2 of
/// LEAP_Hand_Sim's 4 tips (`fingertip_2`, `fingertip_3` were missed) without a word.
#[test]
fn leap_sim_default_detection_finds_all_four_tips() {
    let Some(shared) = shared_hands("leap_sim_default_detection_finds_all_four_tips") else { return };
    let h = HandModel::from_urdf_file(&shared.join("leap_sim/robot_palmbox.urdf"), &opts(MeshApprox::Box)).unwrap();
    assert_eq!(tip_names(&h), ["fingertip", "fingertip_2", "fingertip_3", "thumb_fingertip"]);
    assert_eq!(chain_ends(&h), ["fingertip", "fingertip_2", "fingertip_3", "thumb_fingertip"]);
    assert!(tip_warnings(&h).is_empty(), "{:?}", h.warnings);
    // the tips are the distal links' origins
    for t in &h.fingertips {
        assert_eq!(h.links[t.link].name, t.name);
        assert_eq!(t.pos, Vec3::ZERO);
    }
}

/// Every real hand, its config's `hand.fingertips` removed: detection finds one tip per finger
/// (checked by hand against each URDF's tree), in URDF order, and says nothing. Finger chains end
/// at the links no movable joint leaves: Shadow's wrist (WRJ2, WRJ1) above the palm and SCHUNK
/// SVH's `j5` (which carries the ring and little fingers) are not fingers of their own.
#[test]
fn every_real_hand_detects_one_tip_per_finger_chain() {
    let Some(shared) = shared_hands("every_real_hand_detects_one_tip_per_finger_chain") else { return };
    let limits = ["hand.effort=0.7", "hand.velocity=3.14"];
    let cases: [(&str, &[&str], &[&str], &[&str]); 8] = [
        ("ability", &[], &["thumb_tip", "index_tip", "middle_tip", "ring_tip", "pinky_tip"], &["thumb_L2", "index_L2", "middle_L2", "ring_L2", "pinky_L2"]),
        ("allegro", &[], &["link_3.0_tip", "link_7.0_tip", "link_11.0_tip", "link_15.0_tip"], &["link_3.0", "link_7.0", "link_11.0", "link_15.0"]),
        // the ROS Allegro has effort="0" velocity="0" on every joint: the config gives them
        ("allegro_simlab", &limits, &["link_3.0_tip", "link_7.0_tip", "link_11.0_tip", "link_15.0_tip"], &["link_3.0", "link_7.0", "link_11.0", "link_15.0"]),
        ("inspire", &[], &["thumb_tip", "index_tip", "middle_tip", "ring_tip", "pinky_tip"], &["thumb_distal", "index_intermediate", "middle_intermediate", "ring_intermediate", "pinky_intermediate"]),
        // `fingertip` (the distal link) and `index_tip_head` (a frame on it) lie on one finger:
        // the farther one from the distal joint is kept
        ("leap", &[], &["thumb_tip_head", "index_tip_head", "middle_tip_head", "ring_tip_head"], &["fingertip", "fingertip_2", "fingertip_3", "thumb_fingertip"]),
        ("leap_sim", &[], &["fingertip", "fingertip_2", "fingertip_3", "thumb_fingertip"], &["fingertip", "fingertip_2", "fingertip_3", "thumb_fingertip"]),
        ("schunk_svh", &[], &["thtip", "fftip", "mftip", "rftip", "lftip"], &["right_hand_c", "right_hand_r", "right_hand_q", "right_hand_t", "right_hand_s"]),
        ("shadow", &[], &["fftip", "mftip", "rftip", "lftip", "thtip"], &["ffdistal", "mfdistal", "rfdistal", "lfdistal", "thdistal"]),
    ];
    for (dir, sets, tips, chains) in cases {
        let h = load_shared_without_tips(&shared.join(dir).join("config.toml"), sets);
        assert_eq!(tip_names(&h), tips, "{dir}");
        assert_eq!(chain_ends(&h), chains, "{dir}");
        assert!(tip_warnings(&h).is_empty(), "{dir}: {:?}", h.warnings);
        // every tip on a finger of its own: its link lies on exactly one chain, a different one each
        let mut covered: Vec<usize> = h
            .fingertips
            .iter()
            .map(|t| {
                let on: Vec<usize> = h.finger_chains().into_iter().filter(|&c| h.is_ancestor_or_same(t.link, c)).collect();
                assert_eq!(on.len(), 1, "{dir}: {} lies on chains {on:?}", t.name);
                on[0]
            })
            .collect();
        covered.sort();
        assert_eq!(covered, h.finger_chains(), "{dir}");
    }
    // LEAP's tip_head frames sit beyond the distal links' origins
    let h = load_shared_without_tips(&shared.join("leap/config.toml"), &[]);
    assert!(h.fingertips.iter().all(|t| t.pos.length() > 0.01), "{:?}", h.fingertips);
}

/// Detection keeps the most distal "tip" per finger; fewer tips than finger chains is a warning
/// that names the URDF, the tips, the chains and how to name them. The explicit list warns too.
#[test]
fn detection_keeps_the_most_distal_tip_and_warns_about_missing_fingers() {
    let frame = |name: &str, parent: &str, x: f32| {
        format!(
            r#"<link name="{name}"/><joint name="{name}_fix" type="fixed"><parent link="{parent}"/><child link="{name}"/><origin xyz="{x} 0 0"/></joint>"#
        )
    };
    let text = robot(&[
        PALM.into(),
        frame("palm_tip_marker", "palm", 0.01),
        link("a1"),
        link("a2"),
        rev("ja1", "palm", "a1"),
        rev("ja2", "a1", "a2"),
        frame("a_mid_TIP", "a1", 0.02),
        frame("a_tip", "a2", 0.03),
        frame("a_tip_head", "a_tip", 0.01),
        frame("a_tip_side", "a2", 0.02),
        link("b_fingertip"),
        rev("jb", "palm", "b_fingertip"),
        frame("b_pad", "b_fingertip", 0.01),
        link("c1"),
        rev("jc", "palm", "c1"),
    ]);
    let h = load_str(&text, "/robots/three_fingers.urdf", &HandLoadOptions::default()).unwrap();
    assert_eq!(tip_names(&h), ["a_tip_head", "b_fingertip"]);
    assert_eq!(h.fingertips[0].link, h.link_index("a2").unwrap());
    assert_vec(h.fingertips[0].pos, Vec3::new(0.04, 0.0, 0.0), 1e-7, "a_tip_head in a2");
    assert_eq!(chain_ends(&h), ["a2", "b_fingertip", "c1"]);
    assert_eq!(h.warnings.len(), 1, "{:?}", h.warnings);
    let w = &h.warnings[0];
    for needle in ["three_fingers.urdf", "2 fingertips", "'a_tip_head', 'b_fingertip'", "3 finger chains", "'c1'", "hand.fingertips = [", "{ link = ", "offset = [x, y, z]"] {
        assert!(w.contains(needle), "warning does not contain {needle:?}: {w}");
    }
    assert!(!w.contains('\n'), "{w}");
    // one tip per finger: no warning
    let with_c = text.replace("</robot>", &format!("{}</robot>", frame("c_tip", "c1", 0.02)));
    let h = load_str(&with_c, "three_tips.urdf", &HandLoadOptions::default()).unwrap();
    assert_eq!(tip_names(&h), ["a_tip_head", "b_fingertip", "c_tip"]);
    assert!(tip_warnings(&h).is_empty(), "{:?}", h.warnings);
    // two equally far frames on one link: the first in URDF order
    let twins = with_c.replace("</robot>", &format!("{}</robot>", frame("c_tip_twin", "c1", 0.02)));
    assert_eq!(tip_names(&load_str(&twins, "twins.urdf", &HandLoadOptions::default()).unwrap()), ["a_tip_head", "b_fingertip", "c_tip"]);
    // no tip at all
    let none = robot(&[PALM.into(), link("a1"), rev("ja1", "palm", "a1")]);
    let h = load_str(&none, "tipless.urdf", &HandLoadOptions::default()).unwrap();
    assert!(h.fingertips.is_empty());
    assert!(h.warnings.len() == 1 && h.warnings[0].contains("tipless.urdf") && h.warnings[0].contains("no link name contains"), "{:?}", h.warnings);
    // an explicit list with another count than the chains warns, naming the list
    let o = HandLoadOptions { fingertips: vec!["a_tip".into()], ..Default::default() };
    let h = load_str(&text, "named.urdf", &o).unwrap();
    assert!(h.warnings.len() == 1 && h.warnings[0].contains("hand.fingertips names 1 fingertips ('a_tip')") && h.warnings[0].contains("3 finger chains"), "{:?}", h.warnings);
    // the shipped hands: one tip per finger (tri3's continuous wrist roll is above the branching)
    for (file, n) in [("dexhand16.urdf", 4), ("tri3_mimic.urdf", 3)] {
        let h = load_hand(file);
        assert_eq!((h.fingertips.len(), h.finger_chains().len()), (n, n), "{file}");
        assert!(tip_warnings(&h).is_empty(), "{file}: {:?}", h.warnings);
    }
}

/// `{ link, offset, name }` tips: the point `offset` in the link's frame (a link merged by a fixed
/// joint composes its fixed-joint origins), moving with the link; mixed with frame names.
#[test]
fn link_offset_fingertips_move_with_their_link() {
    let spec = |link: &str, offset: [f32; 3], name: Option<&str>| FingertipSpec::Link(LinkTip { link: link.into(), offset, name: name.map(String::from) });
    let o = HandLoadOptions {
        fingertips: vec![
            "th_tip".into(),
            spec("if_dist", [0.01, 0.002, -0.003], None),
            spec("if_dist", [0.03, 0.0, 0.008], Some("if_pad")),
            spec("mf_tip", [0.005, 0.0, 0.001], Some("mf_nail")),
        ],
        ..Default::default()
    };
    let h = HandModel::from_urdf_file(&hand_path("dexhand16.urdf"), &o).unwrap();
    assert_eq!(tip_names(&h), ["th_tip", "if_dist", "if_pad", "mf_nail"]);
    let if_dist = h.link_index("if_dist").unwrap();
    assert_eq!((h.fingertips[1].link, h.fingertips[2].link), (if_dist, if_dist));
    assert_vec(h.fingertips[1].pos, Vec3::new(0.01, 0.002, -0.003), 1e-7, "if_dist + offset");
    // mf_tip is merged into mf_dist at x = 0.0387 (no rotation)
    assert_eq!(h.fingertips[3].link, h.link_index("mf_dist").unwrap());
    assert_vec(h.fingertips[3].pos, Vec3::new(0.0387 + 0.005, 0.0, 0.001), 1e-7, "mf_tip ∘ offset");
    // forward kinematics: the tip is the link's pose applied to the offset, at any joint angles
    for q in [vec![0.0; h.joints.len()], q_with(&h, &[("if_j0", 0.3), ("if_j1", 0.5), ("if_j3", 1.2), ("mf_j2", 0.9)])] {
        let poses = h.forward_kinematics(&q);
        let tips = h.fingertip_positions(&poses);
        assert_vec(tips[1], poses[if_dist].transform_point(Vec3::new(0.01, 0.002, -0.003)), 1e-6, "if_dist tip");
        assert_vec(tips[2], poses[if_dist].transform_point(Vec3::new(0.03, 0.0, 0.008)), 1e-6, "if_pad");
        let mf_tip = poses[h.link_index("mf_dist").unwrap()].mul(&h.frame("mf_tip").unwrap().1);
        assert_vec(tips[3], mf_tip.transform_point(Vec3::new(0.005, 0.0, 0.001)), 1e-6, "mf_nail");
    }
    // at q = 0 the index points along +x from (0.055, 0.045, 0): the distal joint at
    // 0.055 + 0.0164 + 0.054 + 0.0384; flexing if_j3 by pi/2 about +y turns the offset's x into -z
    let x3 = 0.055 + 0.0164 + 0.054 + 0.0384;
    assert_vec(tip_in_wrist(&h, "if_pad", &vec![0.0; h.joints.len()]), Vec3::new(x3 + 0.03, 0.045, 0.008), 1e-6, "if_pad at q = 0");
    assert_vec(tip_in_wrist(&h, "if_pad", &q_with(&h, &[("if_j3", FRAC_PI_2)])), Vec3::new(x3 + 0.008, 0.045, -0.03), 1e-6, "if_pad with if_j3 = pi/2");
    // errors: a link that does not exist, two tips with one name, an offset out of bounds
    let path = hand_path("dexhand16.urdf");
    let err = |tips: Vec<FingertipSpec>| format!("{:#}", HandModel::from_urdf_file(&path, &HandLoadOptions { fingertips: tips, ..Default::default() }).unwrap_err());
    check_msg(&err(vec!["if_tip".into(), spec("if_distal", [0.0; 3], None)]), "dexhand16.urdf", &["link 'if_distal'", "hand.fingertips[1]", "does not exist"]);
    check_msg(&err(vec![spec("if_dist", [0.0; 3], None), spec("if_dist", [0.01, 0.0, 0.0], None)]), "dexhand16.urdf", &["'if_dist'", "named twice", "hand.fingertips[1]", "`name`"]);
    check_msg(&err(vec![spec("if_dist", [0.0, f32::NAN, 0.0], None)]), "dexhand16.urdf", &["hand.fingertips[0]", "offset", "link 'if_dist'"]);
    check_msg(&err(vec![spec("if_dist", [0.0, 0.0, 1e3], None)]), "dexhand16.urdf", &["hand.fingertips[0]", "offset", "within"]);
}

/// Finding: the ROS Allegro URDF has `effort="0" velocity="0"` on every joint and could not be
/// loaded at all. The config's limits replace the URDF's; without them the error says how to fix
/// it.
#[test]
fn ros_allegro_loads_with_limits_from_the_config() {
    let Some(shared) = shared_hands("ros_allegro_loads_with_limits_from_the_config") else { return };
    let tmp = tempfile::tempdir().unwrap();
    let config = allegro_without_limits(&shared, tmp.path());
    let load = |sets: &[&str]| {
        let sets: Vec<String> = sets.iter().map(|s| s.to_string()).collect();
        let cfg = dextrain::config::Config::load_with_overrides(&config, &sets).unwrap_or_else(|e| panic!("{e:#}"));
        dextrain::env::SimModel::from_config(&cfg).map(|m| m.hand)
    };
    let err = |sets: &[&str]| format!("{:#}", load(sets).unwrap_err());
    // the first joint's effort; then, effort given, its velocity
    let e = err(&[]);
    check_msg(&e, "allegro_hand_description_right.urdf", &["joint 'joint_0.0'", "effort limit 0", "hand.effort = <N·m> (all joints)", "hand.effort.\"joint_0.0\" = <N·m>"]);
    let e = err(&["hand.effort=0.7"]);
    check_msg(&e, "allegro_hand_description_right.urdf", &["joint 'joint_0.0'", "velocity limit 0", "hand.velocity = <rad/s>"]);
    let h = load(&["hand.effort=0.7", "hand.velocity=3.14"]).unwrap();
    assert_eq!(h.joints.len(), 16);
    assert!(h.joints.iter().all(|j| j.effort == 0.7 && j.velocity == 3.14), "{:?}", h.joints.iter().map(|j| (j.effort, j.velocity)).collect::<Vec<_>>());
    // position limits still come from the URDF
    assert_eq!((h.joints[0].lower, h.joints[0].upper), (-0.47, 0.47));
    // per joint: a table that covers every joint loads; one that misses a joint names it
    let names: Vec<String> = h.joints.iter().map(|j| j.name.clone()).collect();
    let table = |skip: &str, base: f32| {
        let entries: Vec<String> = names.iter().enumerate().filter(|(_, n)| n.as_str() != skip).map(|(i, n)| format!("\"{n}\" = {}", base + 0.01 * i as f32)).collect();
        format!("{{ {} }}", entries.join(", "))
    };
    let h = load(&[&format!("hand.effort={}", table("", 0.5)), &format!("hand.velocity={}", table("", 2.0))]).unwrap();
    for (i, j) in h.joints.iter().enumerate() {
        assert_close(j.effort, 0.5 + 0.01 * i as f32, 1e-6, &j.name);
        assert_close(j.velocity, 2.0 + 0.01 * i as f32, 1e-6, &j.name);
    }
    let e = err(&[&format!("hand.effort={}", table("joint_9.0", 0.5)), "hand.velocity=3"]);
    check_msg(&e, "allegro_hand_description_right.urdf", &["joint 'joint_9.0'", "effort limit 0", "hand.effort.\"joint_9.0\""]);
    let e = err(&["hand.effort=1", &format!("hand.velocity={}", table("joint_15.0", 2.0))]);
    check_msg(&e, "allegro_hand_description_right.urdf", &["joint 'joint_15.0'", "velocity limit 0", "hand.velocity.\"joint_15.0\""]);
    // a table key that is no movable joint of the hand
    let e = err(&["hand.effort={ \"joint_0.0\" = 1, joint_3_tip = 1 }", "hand.velocity=3"]);
    check_msg(&e, "allegro_hand_description_right.urdf", &["key `hand.effort.joint_3_tip`", "no movable joint 'joint_3_tip'", "joint_0.0"]);
    let e = err(&["hand.effort=1", "hand.velocity={ \"joint_3.0_tip\" = 1 }"]);
    check_msg(&e, "allegro_hand_description_right.urdf", &["key `hand.velocity.joint_3.0_tip`", "no movable joint"]);
}

/// The config's limits replace the URDF's where it names a joint (the others keep theirs); a
/// revolute joint without `<limit>` has no position limits, which the config cannot give: still
/// an error. A continuous joint needs none and loads with the config's effort and velocity.
#[test]
fn limit_overrides_replace_the_urdf_values_but_not_missing_position_limits() {
    let path = hand_path("dexhand16.urdf");
    let with = |effort: Option<JointLimitOverride>, velocity: Option<JointLimitOverride>| {
        HandModel::from_urdf_file(&path, &HandLoadOptions { effort, velocity, ..Default::default() })
    };
    let urdf = load_hand("dexhand16.urdf");
    let h = with(Some(JointLimitOverride::All(2.5)), None).unwrap();
    for (a, b) in h.joints.iter().zip(&urdf.joints) {
        assert_eq!((a.effort, a.velocity, a.lower, a.upper), (2.5, b.velocity, b.lower, b.upper), "{}", a.name);
    }
    let per = |pairs: &[(&str, f32)]| Some(JointLimitOverride::PerJoint(pairs.iter().map(|(k, v)| (k.to_string(), *v)).collect()));
    let h = with(per(&[("if_j0", 1.5)]), per(&[("th_j3", 9.0), ("mf_j1", 1.0)])).unwrap();
    for (a, b) in h.joints.iter().zip(&urdf.joints) {
        let effort = if a.name == "if_j0" { 1.5 } else { b.effort };
        let velocity = match a.name.as_str() {
            "th_j3" => 9.0,
            "mf_j1" => 1.0,
            _ => b.velocity,
        };
        assert_eq!((a.effort, a.velocity), (effort, velocity), "{}", a.name);
    }
    // the loader checks the values itself (a caller need not come through the config)
    check_msg(&format!("{:#}", with(Some(JointLimitOverride::All(-1.0)), None).unwrap_err()), "dexhand16.urdf", &["hand.effort", "-1", "positive"]);
    check_msg(&format!("{:#}", with(None, per(&[("if_j2", f32::INFINITY)])).unwrap_err()), "dexhand16.urdf", &["joint 'if_j2'", "hand.velocity", "inf"]);
    check_msg(&format!("{:#}", with(per(&[("if_j9", 1.0)]), None).unwrap_err()), "dexhand16.urdf", &["key `hand.effort.if_j9`", "no movable joint 'if_j9'", "if_j0"]);
    // no <limit> on a revolute joint: an error with or without the config's limits
    let nolimit = |ty: &str| robot(&[PALM.into(), link("a"), format!(r#"<joint name="flex" type="{ty}"><parent link="palm"/><child link="a"/><axis xyz="0 1 0"/></joint>"#)]);
    let all = HandLoadOptions { effort: Some(JointLimitOverride::All(1.0)), velocity: Some(JointLimitOverride::All(2.0)), ..Default::default() };
    expect_err(&nolimit("revolute"), "nolimit_hand.urdf", &all, &["joint 'flex'", "revolute but has no <limit>", "position limits"]);
    // a continuous joint without <limit>: an error that says how to fix it, then loads with it
    expect_err(&nolimit("continuous"), "spin_hand.urdf", &HandLoadOptions::default(), &["joint 'flex'", "effort limit 0", "hand.effort = <N·m>", "hand.effort.flex = <N·m>"]);
    let h = load_str(&nolimit("continuous"), "spin_hand.urdf", &all).unwrap();
    assert_eq!((h.joints[0].effort, h.joints[0].velocity, h.joints[0].continuous), (1.0, 2.0, true));
    // the URDF's own bounds still hold where the config says nothing
    let huge = robot(&[PALM.into(), link("a"), joint("ja", "revolute", "palm", "a", "").replace(r#"effort="1""#, r#"effort="1e30""#)]);
    expect_err(&huge, "huge_hand.urdf", &HandLoadOptions::default(), &["joint 'ja'", "effort limit 1e30", "hand.effort.ja"]);
    load_str(&huge, "huge_hand.urdf", &HandLoadOptions { effort: per(&[("ja", 5.0)]), ..Default::default() }).expect("the config's effort replaces the URDF's 1e30");
    // the shared broken/no_limit.urdf (joint_5.0's <limit> removed) stays an error with the limits given
    let Some(shared) = shared_hands("limit_overrides_replace_the_urdf_values_but_not_missing_position_limits") else { return };
    let cfg = dextrain::config::Config::load_with_overrides(&shared.join("broken/no_limit.toml"), &["hand.effort=1".into(), "hand.velocity=3".into()]).unwrap();
    let e = format!("{:#}", dextrain::env::SimModel::from_config(&cfg).unwrap_err());
    check_msg(&e, "no_limit.urdf", &["joint 'joint_5.0'", "no <limit>"]);
}
