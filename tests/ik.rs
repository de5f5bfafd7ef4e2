mod common;

use common::*;
use dextrain::env::SimModel;
use dextrain::env::common::rand_uniform;
use dextrain::env::ik::*;
use dextrain::env::layout::NO_JOINT;
use dextrain::env::physics::Model;
use dextrain::hand::{MAX_JOINTS, MAX_TIPS};
use glam::Vec3;

fn model_for(urdf: &str) -> SimModel {
    let mut c = base_config(1);
    c.hand.urdf = format!("hands/{urdf}");
    SimModel::from_config(&c).expect("model")
}

fn uni(i: u32, k: u32) -> f32 {
    rand_uniform(17, i, 0, 99, k)
}

fn random_q(m: &Model, i: u32) -> [f32; MAX_JOINTS] {
    let mut q = [0.0; MAX_JOINTS];
    for j in 0..m.g.n_joints as usize {
        let jd = &m.joints[j];
        let (lo, hi) = (jd.lower.max(-3.14159), jd.upper.min(3.14159));
        q[j] = lo + (hi - lo) * uni(i, j as u32);
    }
    ik_apply_mimic(m, &mut q);
    q
}

fn default_seed(m: &Model) -> [f32; MAX_JOINTS] {
    let mut q = [0.0; MAX_JOINTS];
    for j in 0..m.g.n_joints as usize {
        q[j] = m.joints[j].default_q.clamp(m.joints[j].lower, m.joints[j].upper);
    }
    ik_apply_mimic(m, &mut q);
    q
}

fn tips(m: &Model, q: &[f32; MAX_JOINTS]) -> [Vec3; MAX_TIPS] {
    ik_tip_positions(m, q, &mut IkScratch::default())
}

fn worst_err(m: &Model, q: &[f32; MAX_JOINTS], t: &[Vec3; MAX_TIPS]) -> f32 {
    let p = tips(m, q);
    (0..m.g.n_tips as usize).map(|i| (p[i] - t[i]).length()).fold(0.0, f32::max)
}


fn iterate_with(m: &Model, targets: &[Vec3; MAX_TIPS], mask: u32, n_active: usize, prm: &IkParams, dist: f32, floor: f32, s: &mut IkScratch) -> bool {
    for k in 0..MAX_JOINTS { s.lock[k] = 0; }
    let mut worst = 0.0f32;
    let mut a = 0;
    for t in 0..m.g.n_tips as usize {
        if ((mask >> t) & 1) != 0 {
            let e = ik_tip_jacobian(m, t, a, targets[t], s).length();
            if !(e <= worst) { worst = e; }
            a += 1;
        }
    }
    if !(worst > prm.tol) { return false; }
    let damping = prm.damping * (worst / dist).clamp(floor, 1.0);
    for _ in 0..MAX_JOINTS {
        ik_dls_step(m, n_active, damping, s);
        let mut locked = false;
        for k in 0..m.g.n_joints as usize {
            let jd = &m.joints[k];
            let d = s.dq[k];
            if s.lock[k] == 0 && ((s.q[k] <= jd.lower && d < 0.0) || (s.q[k] >= jd.upper && d > 0.0)) {
                s.lock[k] = 1; locked = true;
                for b in 0..n_active { s.jac[b * MAX_JOINTS + k] = Vec3::ZERO; }
            }
        }
        if !locked { break; }
    }
    let mut dmax = 0.0f32;
    for k in 0..m.g.n_joints as usize { let d = s.dq[k].abs(); if !(d <= dmax) { dmax = d; } }
    if !(dmax < 1e30) { return false; }
    let scale = if dmax > prm.max_step { prm.max_step / dmax } else { 1.0 };
    for k in 0..m.g.n_joints as usize {
        let jd = &m.joints[k];
        if s.touched[k] != 0 && s.lock[k] == 0 { s.q[k] = (s.q[k] + scale * s.dq[k]).clamp(jd.lower, jd.upper); }
    }
    ik_apply_mimic(m, &mut s.q);
    true
}

#[test]
fn sweep() {
    for urdf in ["dexhand16.urdf", "tri3_mimic.urdf"] {
        let sm = model_for(urdf);
        let m = sm.view();
        let all = (1u32 << m.g.n_tips) - 1;
        let mut cases = vec![];
        for i in 0..400 {
            let mut qt = random_q(&m, i);
            qt[0] = qt[0].clamp(-0.6, 0.6);
            ik_apply_mimic(&m, &mut qt);
            let t = tips(&m, &qt);
            let mut qs = qt;
            for j in 0..m.g.n_joints as usize { let jd = &m.joints[j]; qs[j] = (qt[j] + 0.6 * (uni(i + 1000, j as u32) - 0.5)).clamp(jd.lower, jd.upper); }
            ik_apply_mimic(&m, &mut qs);
            cases.push((t, qs));
        }
        for lam in [0.01f32, 0.02, 0.04] {
            for dist in [0.003f32, 0.01, 0.03] {
                for floor in [0.02f32, 0.05, 0.1, 1.0] {
                    for ms in [0.3f32, 0.5] {
                    for iters in [16u32, 24, 32] {
                        let prm = IkParams { iters, damping: lam, max_step: ms, tol: IK_TOL };
                        let mut w = [0.0f32; 2];
                        let mut bad = [0; 2];
                        let mut its = [0u32; 2];
                        for (t, qs) in &cases {
                            for (k, seed) in [default_seed(&m), *qs].iter().enumerate() {
                                let mut s = IkScratch::default();
                                s.q = *seed;
                                let na = ik_touched(&m, all, &mut s);
                                for _ in 0..prm.iters { if !iterate_with(&m, t, all, na, &prm, dist, floor, &mut s) { break; } its[k] += 1; }
                                let e = worst_err(&m, &s.q, t);
                                w[k] = w[k].max(e);
                                if e > 1e-3 { bad[k] += 1; }
                            }
                        }
                        println!("{urdf} lam {lam} dist {dist} floor {floor} step {ms} iters {iters}: default worst {:.1e} bad {} its {:.1}; perturbed worst {:.1e} bad {} its {:.1}", w[0], bad[0], its[0] as f32 / 400.0, w[1], bad[1], its[1] as f32 / 400.0);
                    }
                    }
                }
            }
        }
    }
}
