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

#[test]
fn sweep() {
    for urdf in ["dexhand16.urdf", "tri3_mimic.urdf"] {
        let sm = model_for(urdf);
        let m = sm.view();
        let all = (1u32 << m.g.n_tips) - 1;
        for lam in [0.003f32, 0.005, 0.01, 0.02] {
            for ms in [0.2f32, 0.3, 0.5] {
                for iters in [8u32, 16, 24, 32, 48] {
                    let prm = IkParams { iters, damping: lam, max_step: ms, tol: IK_TOL };
                    let mut worst = 0.0f32;
                    let mut worst_p = 0.0f32;
                    let mut errs = Vec::new();
                    for i in 0..400 {
                        let qt = random_q(&m, i);
                        let t = tips(&m, &qt);
                        let q = ik_solve(&m, &default_seed(&m), &t, all, &prm);
                        let e = worst_err(&m, &q, &t);
                        errs.push(e);
                        worst = worst.max(e);
                        let mut qs = qt;
                        for j in 0..m.g.n_joints as usize { let jd = &m.joints[j]; qs[j] = (qt[j] + 0.6 * (uni(i + 1000, j as u32) - 0.5)).clamp(jd.lower, jd.upper); }
                        ik_apply_mimic(&m, &mut qs);
                        let q = ik_solve(&m, &qs, &t, all, &prm);
                        worst_p = worst_p.max(worst_err(&m, &q, &t));
                    }
                    errs.sort_by(|a, b| a.total_cmp(b));
                    println!("{urdf} lam {lam} step {ms} iters {iters}: worst default {:.2e} (p99 {:.2e}, n>1mm {}) perturbed {:.2e}", worst, errs[395], errs.iter().filter(|&&e| e > 1e-3).count(), worst_p);
                }
            }
        }
    }
    let _ = NO_JOINT;
}

#[test]
fn diag() {
    let sm = model_for("dexhand16.urdf");
    let m = sm.view();
    let all = (1u32 << m.g.n_tips) - 1;
    let mut shown = 0;
    for i in 0..400 {
        let qt = random_q(&m, i);
        let t = tips(&m, &qt);
        let prm = IkParams { iters: 32, damping: 0.01, max_step: 0.5, tol: IK_TOL };
        let q = ik_solve(&m, &default_seed(&m), &t, all, &prm);
        let p = tips(&m, &q);
        for k in 0..4 {
            let e = (p[k] - t[k]).length();
            if e > 1e-3 && shown < 12 {
                shown += 1;
                let js: Vec<usize> = (0..16).filter(|j| sm.hand.joints[*j].name.starts_with(&sm.spec.tip_names[k][..2])).collect();
                println!("case {i} tip {} err {e:.2e}: true {:?} got {:?}", sm.spec.tip_names[k], js.iter().map(|&j| qt[j]).collect::<Vec<_>>(), js.iter().map(|&j| q[j]).collect::<Vec<_>>());
                let mut trace = vec![];
                for it in [1, 2, 4, 8, 16, 32, 64, 128] {
                    let q = ik_solve(&m, &default_seed(&m), &t, 1 << k, &IkParams { iters: it, ..prm });
                    trace.push(format!("{it}:{:.1e}", (tips(&m, &q)[k] - t[k]).length()));
                }
                println!("   {}", trace.join(" "));
            }
        }
    }
}

#[test]
fn diag3() {
    let sm = model_for("tri3_mimic.urdf");
    let m = sm.view();
    for (j, jd) in sm.joints.iter().enumerate() {
        println!("{j} {} parent {} leader {} mult {} off {} lim [{}, {}]", sm.hand.joints[j].name, jd.parent_link, jd.mimic_leader as i32, jd.mimic_mult, jd.mimic_offset, jd.lower, jd.upper);
    }
    for (t, td) in sm.tips.iter().enumerate() { println!("tip {t} {} link {} pos {:?}", sm.spec.tip_names[t], td.link, td.pos); }
    for i in 0..5 {
        let qt = random_q(&m, i);
        let t = tips(&m, &qt);
        for k in 0..3 {
            let mut trace = vec![];
            for it in [1, 2, 4, 8, 16, 32, 64, 128] {
                let q = ik_solve(&m, &default_seed(&m), &t, 1 << k, &IkParams { iters: it, damping: 0.01, max_step: 0.3, tol: 1e-7 });
                trace.push(format!("{it}:{:.1e}", (tips(&m, &q)[k] - t[k]).length()));
            }
            println!("case {i} tip {k}: {}", trace.join(" "));
        }
    }
}

#[test]
fn diag_jac() {
    for urdf in ["tri3_mimic.urdf", "dexhand16.urdf"] {
    let sm = model_for(urdf);
    let m = sm.view();
    let mut worst = 0.0f32;
    for i in 0..20 {
        let mut q = random_q(&m, i);
        for j in 0..m.g.n_joints as usize { let jd = &m.joints[j]; q[j] = q[j].clamp(jd.lower + 0.05, jd.upper - 0.05); }
        ik_apply_mimic(&m, &mut q);
        let p0 = tips(&m, &q);
        for t in 0..m.g.n_tips as usize {
            let mut s = IkScratch::default();
            s.q = q;
            ik_tip_jacobian(&m, t, p0[t], &mut s);
            let n = ik_chain(&m, t, &mut IkScratch::default());
            for e in 0..n {
                let k = s.chain_k[e];
                if k == NO_JOINT { continue; }
                let h = 1e-3;
                let mut qp = q; qp[k as usize] += h; ik_apply_mimic(&m, &mut qp);
                let mut qm = q; qm[k as usize] -= h; ik_apply_mimic(&m, &mut qm);
                let fd = (tips(&m, &qp)[t] - tips(&m, &qm)[t]) / (2.0 * h);
                let d = (fd - s.chain_c[e]).length();
                if d > 1e-4 { println!("{urdf} case {i} tip {t} joint {k}: fd {fd:?} col {:?}", s.chain_c[e]); }
                worst = worst.max(d);
            }
        }
    }
    println!("{urdf} worst column error {worst:e}");
    }
}

#[test]
fn diag4() {
    let sm = model_for("tri3_mimic.urdf");
    let m = sm.view();
    let all = 7;
    let mut nbad = 0;
    for i in 0..400 {
        let qt = random_q(&m, i);
        let t = tips(&m, &qt);
        for (name, mask) in [("all", all), ("fa", 1), ("fb", 2), ("fc", 4)] {
            let q = ik_solve(&m, &default_seed(&m), &t, mask, &IkParams { iters: 64, damping: 0.01, max_step: 0.3, tol: 1e-7 });
            let e = (0..3).filter(|k| mask & (1 << k) != 0).map(|k| (tips(&m, &q)[k] - t[k]).length()).fold(0.0, f32::max);
            if e > 1e-3 { nbad += 1; if nbad < 30 { println!("case {i} {name} err {e:.1e} true {:?}\n      got {:?}", &qt[..10].iter().map(|x| format!("{x:.2}")).collect::<Vec<_>>(), &q[..10].iter().map(|x| format!("{x:.2}")).collect::<Vec<_>>()); } }
        }
    }
}

#[test]
fn diag5() {
    let sm = model_for("tri3_mimic.urdf");
    let m = sm.view();
    let all = 7;
    let mut nbad = 0;
    for i in 0..400 {
        let qt = random_q(&m, i);
        let t = tips(&m, &qt);
        let mut qs = qt;
        for j in 0..m.g.n_joints as usize { let jd = &m.joints[j]; qs[j] = (qt[j] + 0.6 * (uni(i + 1000, j as u32) - 0.5)).clamp(jd.lower, jd.upper); }
        ik_apply_mimic(&m, &mut qs);
        let mut trace = vec![];
        let mut bad = false;
        for it in [1, 2, 4, 8, 16, 32, 64, 128] {
            let q = ik_solve(&m, &qs, &t, all, &IkParams { iters: it, damping: 0.01, max_step: 0.3, tol: 1e-7 });
            let e = worst_err(&m, &q, &t);
            trace.push(format!("{it}:{e:.1e}"));
            if it == 32 && e > 1e-3 { bad = true; }
        }
        if bad { nbad += 1; if nbad < 10 {
            let q = ik_solve(&m, &qs, &t, all, &IkParams { iters: 128, damping: 0.01, max_step: 0.3, tol: 1e-7 });
            println!("case {i}: {}\n  true {:?}\n  seed {:?}\n  got  {:?}", trace.join(" "), &qt[..10].iter().map(|x| format!("{x:.2}")).collect::<Vec<_>>(), &qs[..10].iter().map(|x| format!("{x:.2}")).collect::<Vec<_>>(), &q[..10].iter().map(|x| format!("{x:.2}")).collect::<Vec<_>>()); } }
    }
    println!("bad {nbad}");
}

#[test]
fn diag6() {
    let sm = model_for("dexhand16.urdf");
    let m = sm.view();
    for i in 0..400 {
        let qt = random_q(&m, i);
        let t = tips(&m, &qt);
        for (seedname, qs) in [("default", default_seed(&m)), ("perturbed", {
            let mut qs = qt;
            for j in 0..m.g.n_joints as usize { let jd = &m.joints[j]; qs[j] = (qt[j] + 0.6 * (uni(i + 1000, j as u32) - 0.5)).clamp(jd.lower, jd.upper); }
            qs })] {
            let prm = IkParams { iters: 48, damping: 0.01, max_step: 0.3, tol: 1e-7 };
            let q = ik_solve(&m, &qs, &t, 15, &prm);
            let p = tips(&m, &q);
            for k in 0..4 {
                let e = (p[k] - t[k]).length();
                if e > 5e-4 {
                    let js: Vec<usize> = (4 * k..4 * k + 4).collect();
                    let mut trace = vec![];
                    for it in [1, 2, 4, 8, 16, 32, 64, 128, 256] {
                        let q = ik_solve(&m, &qs, &t, 15, &IkParams { iters: it, ..prm });
                        trace.push(format!("{it}:{:.1e}", (tips(&m, &q)[k] - t[k]).length()));
                    }
                    println!("{seedname} case {i} tip {} err {e:.2e}: true {:?} seed {:?} got {:?}\n  {}", sm.spec.tip_names[k], js.iter().map(|&j| qt[j]).collect::<Vec<_>>(), js.iter().map(|&j| qs[j]).collect::<Vec<_>>(), js.iter().map(|&j| q[j]).collect::<Vec<_>>(), trace.join(" "));
                }
            }
        }
    }
}

#[test]
fn diag7() {
    let sm = model_for("tri3_mimic.urdf");
    let m = sm.view();
    for rr in [0.3f32, 0.6, 1.0, 1.5, 2.0, 3.14] {
        for prm in [IkParams { iters: 24, damping: 0.01, max_step: 0.3, tol: 1e-7 }, IkParams { iters: 48, damping: 0.01, max_step: 0.3, tol: 1e-7 }, IkParams { iters: 48, damping: 0.02, max_step: 0.3, tol: 1e-7 }] {
        let mut bad = [0; 2];
        let mut worst = [0.0f32; 2];
        for i in 0..400 {
            let mut qt = random_q(&m, i);
            qt[0] = rr * (2.0 * uni(i, 0) - 1.0);
            ik_apply_mimic(&m, &mut qt);
            let t = tips(&m, &qt);
            let mut qs = qt;
            for j in 0..m.g.n_joints as usize { let jd = &m.joints[j]; qs[j] = (qt[j] + 0.6 * (uni(i + 1000, j as u32) - 0.5)).clamp(jd.lower, jd.upper); }
            ik_apply_mimic(&m, &mut qs);
            for (s, seed) in [default_seed(&m), qs].iter().enumerate() {
                let q = ik_solve(&m, seed, &t, 7, &prm);
                let e = worst_err(&m, &q, &t);
                if e > 1e-3 { bad[s] += 1; }
                worst[s] = worst[s].max(e);
            }
        }
        println!("roll ±{rr} {prm:?}: default bad {} worst {:.1e}; perturbed bad {} worst {:.1e}", bad[0], worst[0], bad[1], worst[1]);
        }
    }
}

#[test]
fn diag8() {
    let sm = model_for("tri3_mimic.urdf");
    let m = sm.view();
    let prm = IkParams { iters: 48, damping: 0.01, max_step: 0.3, tol: 1e-7 };
    let mut shown = 0;
    for i in 0..400 {
        let mut qt = random_q(&m, i);
        qt[0] = 0.3 * (2.0 * uni(i, 0) - 1.0);
        ik_apply_mimic(&m, &mut qt);
        let t = tips(&m, &qt);
        let q = ik_solve(&m, &default_seed(&m), &t, 7, &prm);
        let e = worst_err(&m, &q, &t);
        if e > 1e-2 && shown < 3 {
            shown += 1;
            println!("case {i} err {e:.2e}\n true {:?}", qt[..10].iter().map(|x| format!("{x:.2}")).collect::<Vec<_>>());
            for it in 1..=24 {
                let q = ik_solve(&m, &default_seed(&m), &t, 7, &IkParams { iters: it, ..prm });
                let p = tips(&m, &q);
                println!(" it {it:2} errs {:.1e} {:.1e} {:.1e} q {:?}", (p[0]-t[0]).length(), (p[1]-t[1]).length(), (p[2]-t[2]).length(), q[..10].iter().map(|x| format!("{x:.2}")).collect::<Vec<_>>());
            }
        }
    }
}

fn solve_with(m: &Model, seed: &[f32; MAX_JOINTS], t: &[Vec3; MAX_TIPS], mask: u32, prm: &IkParams, sweeps: u32) -> [f32; MAX_JOINTS] {
    let mut s = IkScratch::default();
    s.q = *seed;
    let sw = if ik_share(m, mask, &mut s) > 1 { sweeps } else { 1 };
    for _ in 0..prm.iters {
        if !ik_iterate(m, t, mask, prm, sw, &mut s) { break; }
    }
    s.q
}

#[test]
fn sweep2() {
    for urdf in ["dexhand16.urdf", "tri3_mimic.urdf"] {
        let sm = model_for(urdf);
        let m = sm.view();
        let all = (1u32 << m.g.n_tips) - 1;
        let sweeps_list: &[u32] = if urdf.starts_with("tri3") { &[1, 2, 4, 8] } else { &[1] };
        for &sweeps in sweeps_list {
        for lam in [0.005f32, 0.01, 0.02] {
            for ms in [0.2f32, 0.3, 0.5] {
                for iters in [16u32, 24, 32, 48] {
                    let prm = IkParams { iters, damping: lam, max_step: ms, tol: IK_TOL };
                    let mut w = [0.0f32; 2];
                    let mut bad = [0; 2];
                    for i in 0..400 {
                        let mut qt = random_q(&m, i);
                        qt[0] = qt[0].clamp(-0.6, 0.6);
                        ik_apply_mimic(&m, &mut qt);
                        let t = tips(&m, &qt);
                        let mut qs = qt;
                        for j in 0..m.g.n_joints as usize { let jd = &m.joints[j]; qs[j] = (qt[j] + 0.6 * (uni(i + 1000, j as u32) - 0.5)).clamp(jd.lower, jd.upper); }
                        ik_apply_mimic(&m, &mut qs);
                        for (k, seed) in [default_seed(&m), qs].iter().enumerate() {
                            let q = solve_with(&m, seed, &t, all, &prm, sweeps);
                            let e = worst_err(&m, &q, &t);
                            w[k] = w[k].max(e);
                            if e > 1e-3 { bad[k] += 1; }
                        }
                    }
                    println!("{urdf} sweeps {sweeps} lam {lam} step {ms} iters {iters}: default worst {:.1e} bad {}; perturbed worst {:.1e} bad {}", w[0], bad[0], w[1], bad[1]);
                }
            }
        }
        }
    }
}

#[test]
fn diag9() {
    let sm = model_for("tri3_mimic.urdf");
    let m = sm.view();
    let prm = IkParams { iters: 48, damping: 0.02, max_step: 0.3, tol: 1e-7 };
    let mut cases = vec![];
    for i in 0..400 {
        let mut qt = random_q(&m, i);
        qt[0] = qt[0].clamp(-0.6, 0.6);
        ik_apply_mimic(&m, &mut qt);
        let t = tips(&m, &qt);
        let mut qs = qt;
        for j in 0..m.g.n_joints as usize { let jd = &m.joints[j]; qs[j] = (qt[j] + 0.6 * (uni(i + 1000, j as u32) - 0.5)).clamp(jd.lower, jd.upper); }
        ik_apply_mimic(&m, &mut qs);
        let q = solve_with(&m, &qs, &t, 7, &prm, 8);
        cases.push((worst_err(&m, &q, &t), i, qt, qs));
    }
    cases.sort_by(|a, b| b.0.total_cmp(&a.0));
    for (e, i, qt, qs) in cases.iter().take(3) {
        println!("case {i} err {e:.1e}\n true {:?}\n seed {:?}", qt[..10].iter().map(|x| format!("{x:.3}")).collect::<Vec<_>>(), qs[..10].iter().map(|x| format!("{x:.3}")).collect::<Vec<_>>());
        let t = tips(&m, qt);
        for it in [1, 2, 4, 8, 16, 32, 64, 128, 256, 512] {
            for sw in [8, 32] {
            let q = solve_with(&m, qs, &t, 7, &IkParams { iters: it, ..prm }, sw);
            let p = tips(&m, &q);
            println!(" it {it:3} sw {sw} errs {:.1e} {:.1e} {:.1e} q {:?}", (p[0]-t[0]).length(), (p[1]-t[1]).length(), (p[2]-t[2]).length(), q[..10].iter().map(|x| format!("{x:.3}")).collect::<Vec<_>>());
            }
        }
    }
}
