//! CPU/GPU parity: the WGSL kernels and their CPU twins must compute the same thing.
//! Runs on any wgpu adapter, lavapipe included; without one it prints why (fails with REQUIRE_GPU=1).

mod common;

use common::*;
use dextrain::env::{EnvBatch, EnvState, Targets};

/// Every f32 of two Pod values, side by side.
fn floats<T: bytemuck::Pod>(a: &T) -> Vec<f32> {
    bytemuck::cast_slice::<u8, f32>(bytemuck::bytes_of(a)).to_vec()
}

/// Largest relative difference over all state variables (|a − b| / max(|a|, |b|, floor)).
fn max_rel_diff(a: &[EnvState], b: &[EnvState], floor: f32) -> (f32, String) {
    let mut worst = (0.0f32, String::new());
    for (i, (x, y)) in a.iter().zip(b).enumerate() {
        // integer counters must match exactly
        assert_eq!((x.episode, x.step, x.bad_resets), (y.episode, y.step, y.bad_resets), "env {i} counters");
        for (k, (u, v)) in floats(x).iter().zip(floats(y)).enumerate() {
            let d = (u - v).abs() / u.abs().max(v.abs()).max(floor);
            if d > worst.0 || !d.is_finite() {
                worst = (d, format!("env {i} float #{k}: cpu {u} gpu {v}"));
            }
        }
    }
    worst
}

/// Grasp targets of the bench scene: palm lowered onto the cube, fingers closed.
fn grasp_targets(b: &dextrain::env::cpu::CpuEnvBatch) -> Targets {
    dextrain::bench::grasp_targets(b.model())
}

#[test]
fn reset_draws_the_same_parameters_on_both_backends() {
    let Some(ctx) = gpu_context("reset_draws_the_same_parameters_on_both_backends") else { return };
    let mut c = base_config(64);
    c.randomization = dextrain::config::Config::load(std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/configs/dexrefine_dr.toml")))
        .expect("shipped DR config")
        .randomization;
    c.object.xy_noise = [0.05, 0.05];
    c.object.yaw_noise = 0.5;
    let mut cpu = cpu_batch(&c);
    let mut gpu = gpu_batch(&c, ctx);
    let (pc, pg) = (cpu.params().unwrap(), gpu.params().unwrap());
    for (i, (a, b)) in pc.iter().zip(&pg).enumerate() {
        for (u, v) in floats(a).iter().zip(floats(b)) {
            assert!((u - v).abs() <= 1e-6 * u.abs().max(1.0), "env {i}: params differ: {a:?} vs {b:?}");
        }
    }
    // the draws really are random across envs
    assert!(pc.iter().any(|p| (p.obj_inertia[3] - pc[0].obj_inertia[3]).abs() > 1e-4));
    let (sc, sg) = (cpu.states().unwrap(), gpu.states().unwrap());
    let (d, at) = max_rel_diff(&sc, &sg, 1e-3);
    assert!(d < 1e-5, "initial states differ: {d:e} at {at}");
    // a masked reset starts the next episode of those envs only
    let mask: Vec<bool> = (0..64).map(|i| i % 3 == 0).collect();
    cpu.reset(&mask).unwrap();
    gpu.reset(&mask).unwrap();
    let (sc, sg) = (cpu.states().unwrap(), gpu.states().unwrap());
    for i in 0..64 {
        assert_eq!(sc[i].episode, if i % 3 == 0 { 1 } else { 0 });
    }
    let (d, at) = max_rel_diff(&sc, &sg, 1e-3);
    assert!(d < 1e-5, "states after a masked reset differ: {d:e} at {at}");
}

#[test]
fn one_contact_rich_step_agrees_to_1e_5() {
    let Some(ctx) = gpu_context("one_contact_rich_step_agrees_to_1e_5") else { return };
    let mut c = dextrain::bench::bench_config(16);
    c.base_dir = concat!(env!("CARGO_MANIFEST_DIR"), "/configs").into();
    let mut cpu = cpu_batch(&c);
    let t = grasp_targets(&cpu);
    // drive the CPU into a grasp, then give both backends that state
    run(&mut cpu, t, 20);
    let start = cpu.states().unwrap();
    let contacts = cpu.stats().unwrap().iter().map(|s| s.contacts_ho).sum::<u32>();
    assert!(contacts > 0, "the scene should be in contact");
    let mut gpu = gpu_batch(&c, ctx);
    gpu.set_states(&start).unwrap();
    run(&mut cpu, t, 1);
    run(&mut gpu, t, 1);
    let (d, at) = max_rel_diff(&cpu.states().unwrap(), &gpu.states().unwrap(), 1e-2);
    assert!(d < 1e-5, "one step differs by {d:e} (relative) at {at}");
    let (a, b) = (cpu.stats().unwrap(), gpu.stats().unwrap());
    for (x, y) in a.iter().zip(&b) {
        assert_eq!(x.contacts, y.contacts);
        assert!((x.max_pen_ho - y.max_pen_ho).abs() < 1e-6);
    }
}

#[test]
fn contact_free_rollout_of_100_steps_agrees_to_1e_4() {
    let Some(ctx) = gpu_context("contact_free_rollout_of_100_steps_agrees_to_1e_4") else { return };
    let mut c = base_config(8);
    c.object.init_xy = [0.6, 0.0];
    c.wrist.init_pos = [0.0, 0.0, 0.6];
    let mut cpu = cpu_batch(&c);
    let mut gpu = gpu_batch(&c, ctx);
    // the object starts in the air with a spin; the hand waves its fingers and moves its wrist
    let mut s = cpu.states().unwrap();
    for (i, st) in s.iter_mut().enumerate() {
        st.obj_pos[2] = 1.5 + 0.1 * i as f32;
        st.obj_angvel = [1.0, 2.0 + i as f32, -0.5, 0.0];
    }
    cpu.set_states(&s).unwrap();
    gpu.set_states(&s).unwrap();
    let base = cpu.model().default_targets();
    for k in 0..100 {
        let targets: Vec<Targets> = (0..8)
            .map(|i| {
                let mut t = base;
                let ph = 0.1 * k as f32 + i as f32;
                for j in 0..16 {
                    t.q[j] = 0.6 + 0.5 * (ph + j as f32).sin();
                }
                t.wrist_pos = [0.05 * ph.sin(), 0.05 * ph.cos(), 0.6, 0.0];
                t.wrist_rot = glam::Quat::from_rotation_z(0.3 * ph.sin()).to_array();
                t
            })
            .collect();
        cpu.step(&targets).unwrap();
        gpu.step(&targets).unwrap();
    }
    assert_eq!(cpu.stats().unwrap().iter().map(|s| s.contacts).sum::<u32>(), 0, "rollout should be contact free");
    let (d, at) = max_rel_diff(&cpu.states().unwrap(), &gpu.states().unwrap(), 1e-2);
    assert!(d < 1e-4, "100-step rollout differs by {d:e} (relative) at {at}");
}
