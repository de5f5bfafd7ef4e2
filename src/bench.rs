//! `dextrain bench`: env-step throughput of either backend on a contact-rich scene, as one JSON line.
//!
//! The default scene mirrors the peer MuJoCo benchmark (`shared/peers/`): the 16-joint hand on a
//! 6-DoF wrist (22 actuators) closing on a 5 cm, 0.1 kg cube, dt = 1/120 s, decimation 4. Every
//! timed chunk of 24 env steps (one PPO rollout's worth) starts from the same grasp state (palm on the
//! cube, fingers closed) and follows the grasp targets plus Gaussian noise (wrist 1 cm / 0.05 rad,
//! fingers 0.25 rad), so the fingers keep squeezing and releasing the cube and contacts persist.

use std::time::Instant;

use anyhow::Result;
use glam::Quat;
use serde_json::json;

use crate::config::Config;
use crate::env::common::rand_uniform;
use crate::env::{EnvBatch, SimModel, Targets};
use crate::geom::ObjectShape;

/// Env steps per timed chunk (rsl_rl's steps per env per iteration in the peer benchmark).
pub const CHUNK_STEPS: usize = 24;

/// The benchmark scene for `n` envs (the hand and cube of the peer benchmark).
pub fn bench_config(n: usize) -> Config {
    let mut c = Config::default();
    c.base_dir = "configs".into();
    c.source = "<bench scene>".into();
    c.sim.num_envs = n;
    c.object.shape = Some(ObjectShape::Box { half_extents: [0.025, 0.025, 0.025] });
    c.object.mass = Some(0.1);
    c.wrist.init_pos = [0.0, 0.0, 0.115];
    // the peer's table is hand-transparent: no hand–table contacts
    c.table.hand_collision = false;
    c
}

/// Grasp targets of the bench scene: the tuned pinch of `dextrain traj synth` (thumb against the
/// middle finger on the cube's sides at mid height, index and ring closed beside it), with the wrist
/// where synth puts it. (The peer's own finger targets curl under the cube in this contact model and
/// hold it with the palm alone; the pinch keeps the hand in contact with the cube.)
pub fn grasp_targets(model: &SimModel) -> Targets {
    let q = crate::synth::grasp_posture(model, 0.6);
    let wrist = crate::synth::grasp_wrist_pose(model, &q);
    let mut t = model.default_targets();
    t.wrist_pos = [wrist.pos.x, wrist.pos.y, wrist.pos.z, 0.0];
    t.wrist_rot = wrist.rot.to_array();
    t.q[..q.len()].copy_from_slice(&q);
    t
}

/// The approach of the peer's `make_grasp_state` at time `t` (s): the wrist ramps down over 0.5 s,
/// the fingers close between 0.3 s and 0.8 s.
pub fn approach_targets(model: &SimModel, grasp: &Targets, t: f32) -> Targets {
    let start = model.default_targets();
    let a = (t / 0.5).min(1.0);
    let b = ((t - 0.3) / 0.5).clamp(0.0, 1.0);
    let mut out = *grasp;
    for k in 0..3 {
        out.wrist_pos[k] = start.wrist_pos[k] + a * (grasp.wrist_pos[k] - start.wrist_pos[k]);
    }
    for j in 0..model.joints.len() {
        out.q[j] = start.q[j] + b * (grasp.q[j] - start.q[j]);
    }
    out
}

/// Standard normal from two counter-based uniforms (Box–Muller).
fn normal(seed: u32, env: u32, step: u32, k: u32) -> f32 {
    let u1 = rand_uniform(seed, env, step, 7, 2 * k).max(1e-7);
    let u2 = rand_uniform(seed, env, step, 7, 2 * k + 1);
    (-2.0 * u1.ln()).sqrt() * (std::f32::consts::TAU * u2).cos()
}

/// The noisy grasp targets of every env for step `k` of a chunk.
pub fn noisy_targets(model: &SimModel, grasp: &Targets, n: usize, k: u32) -> Vec<Targets> {
    (0..n as u32)
        .map(|e| {
            let mut t = *grasp;
            for i in 0..3 {
                t.wrist_pos[i] += 0.01 * normal(1, e, k, i as u32);
            }
            let rv = glam::Vec3::new(normal(1, e, k, 3), normal(1, e, k, 4), normal(1, e, k, 5)) * 0.05;
            t.wrist_rot = (Quat::from_scaled_axis(rv) * Quat::from_array(grasp.wrist_rot)).normalize().to_array();
            for (j, jd) in model.joints.iter().enumerate() {
                t.q[j] = (grasp.q[j] + 0.25 * normal(1, e, k, 6 + j as u32)).clamp(jd.lower, jd.upper);
            }
            t
        })
        .collect()
}

/// CPU time of this process (all threads), seconds.
pub fn process_cpu_time() -> f64 {
    let mut ts = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: clock_gettime writes into the timespec we pass.
    unsafe { libc::clock_gettime(libc::CLOCK_PROCESS_CPUTIME_ID, &mut ts) };
    ts.tv_sec as f64 + ts.tv_nsec as f64 * 1e-9
}

fn summary(mut v: Vec<f64>) -> serde_json::Value {
    v.sort_by(|a, b| a.total_cmp(b));
    let median = if v.is_empty() { 0.0 } else { v[v.len() / 2] };
    json!({ "median": median, "min": v.first().copied().unwrap_or(0.0), "max": v.last().copied().unwrap_or(0.0), "n_runs": v.len() })
}

/// Options of a benchmark run.
pub struct BenchOptions {
    /// Least number of timed chunks.
    pub min_chunks: usize,
    /// Least wall time of the timed part (s).
    pub min_seconds: f64,
}

/// Runs the benchmark on `env` (already built from `model`) and returns the JSON report.
pub fn run_bench(env: &mut dyn EnvBatch, model: &SimModel, opts: &BenchOptions) -> Result<serde_json::Value> {
    let n = env.spec().num_envs;
    let g = &model.globals;
    let grasp = grasp_targets(model);
    // grasp state: 0.9 s of the peer's approach (untimed)
    let approach_steps = (0.9 / (g.dt * g.decimation as f32)).round() as usize;
    for k in 0..approach_steps {
        let t = approach_targets(model, &grasp, k as f32 * g.dt * g.decimation as f32);
        env.step(&vec![t; n])?;
    }
    let grasp_state = env.states()?;
    let chunks: Vec<Vec<Vec<Targets>>> =
        (0..4).map(|c| (0..CHUNK_STEPS as u32).map(|k| noisy_targets(model, &grasp, n, c * 100 + k)).collect()).collect();
    let phys_per_env_step = (g.decimation * g.substeps) as f64;
    let (mut rates, mut cpu_us) = (Vec::new(), Vec::new());
    let (mut contacts, mut contacts_ho, mut samples, mut bad) = (0u64, 0u64, 0u64, 0u64);
    let mut step_counts = crate::gpu_counts::GpuCounts::default();
    let mut run_chunk = |env: &mut dyn EnvBatch, c: usize, record: bool| -> Result<(f64, f64)> {
        env.set_states(&grasp_state)?;
        let counts0 = crate::gpu_counts::GpuCounts::now();
        let (c0, t0) = (process_cpu_time(), Instant::now());
        for targets in &chunks[c % chunks.len()] {
            env.step(targets)?;
            // what an RL loop would read back every step
            let stats = env.stats()?;
            if record {
                for s in &stats {
                    contacts += s.contacts as u64;
                    contacts_ho += s.contacts_ho as u64;
                    bad += s.bad_reset as u64;
                }
                samples += stats.len() as u64;
            }
        }
        let out = (t0.elapsed().as_secs_f64(), process_cpu_time() - c0);
        step_counts = crate::gpu_counts::GpuCounts::now().since(&counts0);
        Ok(out)
    };
    run_chunk(env, 0, false)?; // warm-up
    let start = Instant::now();
    let mut c = 0;
    while c < opts.min_chunks || start.elapsed().as_secs_f64() < opts.min_seconds {
        let (wall, cpu) = run_chunk(env, c, true)?;
        let steps = (n * CHUNK_STEPS) as f64;
        rates.push(steps / wall);
        cpu_us.push(cpu * 1e6 / steps);
        c += 1;
        if c >= 10_000 {
            break;
        }
    }
    let env_rate = summary(rates.clone());
    let phys_rate = summary(rates.iter().map(|r| r * g.decimation as f64).collect());
    Ok(json!({
        "bench": "dextrain_env_step",
        "backend": env.backend_name(),
        "num_envs": n,
        "threads": rayon::current_num_threads(),
        "dt": g.dt, "decimation": g.decimation, "substeps": g.substeps,
        "actuators": 6 + model.spec.actuated.len(),
        "env_steps_per_chunk": CHUNK_STEPS,
        "env_steps_per_s": env_rate,
        "physics_steps_per_s": phys_rate,
        "cpu_us_per_env_step": summary(cpu_us.clone()),
        "cpu_us_per_physics_step": summary(cpu_us.iter().map(|u| u / g.decimation as f64).collect()),
        "contacts_per_physics_step": contacts as f64 / (samples as f64 * phys_per_env_step).max(1.0),
        "hand_object_contacts_per_physics_step": contacts_ho as f64 / (samples as f64 * phys_per_env_step).max(1.0),
        "bad_resets": bad,
        // the simulator's buffers per env (0 on the CPU)
        "device_bytes_per_env": env.device_bytes() as f64 / n.max(1) as f64,
        // invocations per workgroup of the simulator's step on a GPU (null on the CPU)
        "step_workgroup_size": env.step_workgroup_size(),
        // per env step of all envs: the step and the statistics read (the simulator's own
        // submissions are all of the queue's)
        "gpu_counts_per_env_step": if env.device_bytes() > 0 { step_counts.to_json(CHUNK_STEPS as f64, None) } else { serde_json::Value::Null },
        "wall_s": start.elapsed().as_secs_f64(),
    }))
}

/// Shapes of the PPO update benchmark (the peer `rsl_rl_ppo_bench.py`'s defaults).
#[derive(Clone, Debug)]
pub struct PpoBenchOptions {
    pub envs: usize,
    pub steps: usize,
    pub obs: usize,
    pub priv_obs: usize,
    pub actions: usize,
    pub hidden: Vec<usize>,
    pub epochs: u32,
    pub minibatches: u32,
    pub warmup: usize,
    pub iters: usize,
}

impl Default for PpoBenchOptions {
    fn default() -> Self {
        PpoBenchOptions { envs: 4096, steps: 24, obs: 96, priv_obs: 130, actions: 22, hidden: vec![512, 256, 128], epochs: 5, minibatches: 4, warmup: 1, iters: 5 }
    }
}

fn stats(xs: &[f64]) -> serde_json::Value {
    let mut s = xs.to_vec();
    s.sort_by(f64::total_cmp);
    let median = if s.is_empty() { f64::NAN } else if s.len() % 2 == 1 { s[s.len() / 2] } else { 0.5 * (s[s.len() / 2 - 1] + s[s.len() / 2]) };
    json!({"median": median, "min": s.first(), "max": s.last(), "n_runs": s.len()})
}

/// The learner-side cost of one PPO iteration on synthetic data, as rsl_rl's peer benchmark times it:
/// a rollout of `steps` × [act + process_step] with pre-generated observations, rewards and dones
/// (1/250 of transitions end an episode, half of those by time-out), then `update` (GAE +
/// `epochs` × `minibatches` gradient steps with the adaptive-KL learning rate). Prints one JSON line.
///
/// With `ctx` (the wgpu context of a GPU learner device), the same iterations again with the
/// rollout on the device (`act_device`, `process_step_device`, `update_device`: the training
/// loop's path when the envs share the GPU), and `gpu_counts`: the kernels, submissions and host
/// synchronisations of one policy inference, one rollout step and one update on each path
/// ([`crate::gpu_counts`]; the same on any adapter).
pub fn run_ppo_bench(o: &PpoBenchOptions, device: burn::prelude::Device, device_name: &str, ctx: Option<&crate::gpu::context::GpuContext>) -> Result<serde_json::Value> {
    use crate::config::{PolicyConfig, PpoConfig};
    use crate::gpu_counts::{GpuCounts, queue_submissions, submissions_between};
    use crate::learn::nets::to_tensor;
    use crate::learn::ppo::{Dims, Ppo};
    use crate::rng::Rng;
    let cfg = PpoConfig { learning_rate: 1e-3, epochs: o.epochs, minibatches: o.minibatches, ..PpoConfig::default() };
    let pol = PolicyConfig { actor_hidden: o.hidden.clone(), critic_hidden: o.hidden.clone(), ..PolicyConfig::default() };
    let dims = Dims { obs: o.obs, priv_obs: o.priv_obs, act: o.actions };
    let mut ppo = Ppo::new(dims, o.envs, o.steps, &cfg, &pol, &[], device.clone(), 0)?;
    let mut rng = Rng::new(1, 1);
    let mut draw = |len: usize| -> Vec<f32> { (0..len).map(|_| rng.normal() as f32).collect() };
    let obs: Vec<(Vec<f32>, Vec<f32>)> = (0..2).map(|_| (draw(o.envs * o.obs), draw(o.envs * o.priv_obs))).collect();
    let rewards: Vec<Vec<f32>> = (0..o.steps).map(|_| draw(o.envs)).collect();
    let mut rng = Rng::new(2, 2);
    let mut dones = Vec::new();
    for _ in 0..o.steps {
        let d: Vec<bool> = (0..o.envs).map(|_| rng.uniform() < 1.0 / 250.0).collect();
        let to: Vec<bool> = d.iter().map(|&x| x && rng.uniform() < 0.5).collect();
        let term: Vec<bool> = d.iter().zip(&to).map(|(&x, &t)| x && !t).collect();
        dones.push((term, to));
    }
    // the counts of a phase: what this thread asked of the GPU, and the queue's submissions
    let mark = || (GpuCounts::now(), ctx.and_then(|c| queue_submissions(&c.queue)));
    let counted = |m: &(GpuCounts, Option<u64>), per: f64| {
        let (c, q) = mark();
        c.since(&m.0).to_json(per, submissions_between(m.1, q))
    };
    let (mut rollout_ms, mut update_ms, mut update_cpu_s) = (Vec::new(), Vec::new(), Vec::new());
    let (mut step_counts, mut update_counts) = (serde_json::Value::Null, serde_json::Value::Null);
    let mut last = None;
    for it in 0..o.warmup + o.iters {
        let m0 = mark();
        let t0 = Instant::now();
        for k in 0..o.steps {
            let (ob, pr) = &obs[k % 2];
            ppo.act(ob, pr)?;
            ppo.process_step(&rewards[k], &dones[k].0, &dones[k].1);
        }
        let rollout_s = t0.elapsed().as_secs_f64();
        step_counts = counted(&m0, o.steps as f64);
        let m1 = mark();
        let (t1, c1) = (Instant::now(), process_cpu_time());
        let u = ppo.update(&obs[o.steps % 2].1)?;
        let (update_s, c2) = (t1.elapsed().as_secs_f64(), process_cpu_time());
        update_counts = counted(&m1, 1.0);
        crate::console::status(&format!(
            "  iter {it}{}: rollout {:.0} ms, update {:.0} ms (cpu {:.1} s), lr {:.2e}",
            if it < o.warmup { " (warm-up)" } else { "" },
            1e3 * rollout_s,
            1e3 * update_s,
            c2 - c1,
            u.lr
        ));
        if it >= o.warmup {
            rollout_ms.push(1e3 * rollout_s);
            update_ms.push(1e3 * update_s);
            update_cpu_s.push(c2 - c1);
        }
        last = Some(u);
    }
    let mut inf_ms = Vec::new();
    let mut inference_counts = serde_json::Value::Null;
    for _ in 0..10 {
        let m = mark();
        let t0 = Instant::now();
        ppo.act_mean(&obs[0].0, &obs[0].1)?;
        inf_ms.push(1e3 * t0.elapsed().as_secs_f64());
        inference_counts = counted(&m, 1.0);
    }
    // where an inference's time goes: its phases timed apart, each ended by a wait for the device
    let mut phases: [Vec<f64>; 4] = Default::default();
    for _ in 0..10 {
        for (v, x) in phases.iter_mut().zip(ppo.act_mean_phases_ms(&obs[0].0, &obs[0].1)?) {
            v.push(x);
        }
    }
    // the device-resident path: observations, rewards and dones as tensors made once
    let mut device_path = serde_json::Value::Null;
    if let Some(ctx) = ctx.filter(|_| crate::learn::nets::is_gpu(&device)) {
        ppo.start_device_rollouts(ctx)?;
        let dev = device.clone().inner();
        let obs_t: Vec<(burn::prelude::Tensor<2>, burn::prelude::Tensor<2>)> =
            obs.iter().map(|(ob, pr)| (to_tensor(ob.clone(), [o.envs, o.obs], &dev), to_tensor(pr.clone(), [o.envs, o.priv_obs], &dev))).collect();
        let col = |v: Vec<f32>| to_tensor(v, [o.envs, 1], &dev);
        let flags = |v: &[bool]| col(v.iter().map(|&b| b as u8 as f32).collect());
        let rew_t: Vec<_> = rewards.iter().map(|r| col(r.clone())).collect();
        let done_t: Vec<_> = dones.iter().map(|(t, to)| (flags(t), flags(to))).collect();
        let (mut d_rollout_ms, mut d_update_ms) = (Vec::new(), Vec::new());
        let (mut d_step_counts, mut d_update_counts) = (serde_json::Value::Null, serde_json::Value::Null);
        for it in 0..o.warmup + o.iters {
            let m0 = mark();
            let t0 = Instant::now();
            for k in 0..o.steps {
                let (ob, pr) = &obs_t[k % 2];
                ppo.act_device(ob, pr)?;
                ppo.process_step_device(&rew_t[k], &done_t[k].0, &done_t[k].1)?;
            }
            // the rollout's kernels have run when the device is idle
            // (counted before the bench's wait for the device: the training loop reads once per iteration)
            let (before_sync, queue_now) = mark();
            crate::gpu::io::sync(&device)?;
            let rollout_s = t0.elapsed().as_secs_f64();
            d_step_counts = before_sync.since(&m0.0).to_json(o.steps as f64, submissions_between(m0.1, queue_now));
            let m1 = mark();
            let t1 = Instant::now();
            let u = ppo.update_device(&obs_t[o.steps % 2].1)?;
            let update_s = t1.elapsed().as_secs_f64();
            d_update_counts = counted(&m1, 1.0);
            crate::console::status(&format!(
                "  device-resident iter {it}{}: rollout {:.0} ms, update {:.0} ms, lr {:.2e}",
                if it < o.warmup { " (warm-up)" } else { "" },
                1e3 * rollout_s,
                1e3 * update_s,
                u.lr
            ));
            if it >= o.warmup {
                d_rollout_ms.push(1e3 * rollout_s);
                d_update_ms.push(1e3 * update_s);
            }
        }
        device_path = json!({
            "update_ms": stats(&d_update_ms),
            "rollout_policy_ms_24_steps": stats(&d_rollout_ms),
            "gpu_counts": {"per_rollout_step": d_step_counts, "per_update": d_update_counts},
        });
    }
    let transitions = (o.envs * o.steps) as f64;
    let mut upd_sorted = update_ms.clone();
    upd_sorted.sort_by(f64::total_cmp);
    let upd_median_s = upd_sorted.get(upd_sorted.len() / 2).copied().unwrap_or(f64::NAN) / 1e3;
    let u = last.unwrap_or_default();
    let on_gpu = crate::learn::nets::is_gpu(&device);
    Ok(json!({
        "bench": "dextrain_ppo_bench",
        "device": device_name,
        // products that fell back from the chosen GPU matmul routine to burn's (0: all ran the chosen one)
        "gpu_matmul_fallbacks": crate::learn::kernels::gpu_matmul::fallbacks(),
        // the GPU products' routine and, with `dextrain_tuned`, each product's timed tile shapes
        "gpu_matmul": crate::learn::kernels::gpu_matmul::chosen().name(),
        // how acting ran its forward passes (DEXTRAIN_MLP_FORWARD): "auto" (one kernel per MLP
        // for small batches), "fused" (always) or "layers" (a product per layer)
        "mlp_forward": crate::learn::kernels::mlp_forward::mode_name(),
        "matmul_tuning": crate::learn::kernels::matmul_tuning::report(),
        "threads": rayon::current_num_threads(),
        "config": {"num_envs": o.envs, "num_steps_per_env": o.steps, "obs_dim": o.obs, "critic_obs_dim": o.priv_obs,
                   "action_dim": o.actions, "hidden": o.hidden, "activation": "elu", "epochs": o.epochs,
                   "minibatches": o.minibatches, "minibatch_size": o.envs * o.steps / o.minibatches as usize,
                   "schedule": "adaptive", "desired_kl": 0.01, "clipped_value_loss": true},
        "transitions_per_iteration": o.envs * o.steps,
        "update_ms": stats(&update_ms),
        "update_process_cpu_s": stats(&update_cpu_s),
        "update_transitions_per_s_median": transitions / upd_median_s,
        "rollout_policy_ms_24_steps": stats(&rollout_ms),
        "policy_inference_ms": stats(&inf_ms),
        "policy_inference_phases_ms": {"host_normalization_alone": stats(&phases[0]), "inputs_uploaded": stats(&phases[1]),
                                       "actor_forward": stats(&phases[2]), "actions_read_back": stats(&phases[3])},
        "gpu_counts": if on_gpu { json!({"per_policy_inference": inference_counts, "per_rollout_step": step_counts, "per_update": update_counts}) } else { serde_json::Value::Null },
        "device_resident": device_path,
        "last_losses": {"surrogate": u.surrogate, "value": u.value, "entropy": u.entropy, "kl": u.kl, "lr": u.lr},
        "cpu": cpu_model(),
    }))
}

/// Shapes of the SAC update benchmark (the peer `skrl_sac_update_bench.py`'s defaults).
#[derive(Clone, Debug)]
pub struct SacBenchOptions {
    /// Envs of the replay buffer.
    pub envs: usize,
    /// Transitions kept per env.
    pub memory: usize,
    pub obs: usize,
    pub priv_obs: usize,
    pub actions: usize,
    pub hidden: Vec<usize>,
    /// Transitions per gradient step.
    pub batch: usize,
    /// Gradient steps per timed update.
    pub gradient_steps: usize,
    pub warmup: usize,
    pub iters: usize,
    /// Transitions per return (`sac.n_step`): 1 as skrl's SAC.
    pub n_step: u32,
    /// LayerNorm in the critics (`sac.critic_layer_norm`): off as skrl's SAC.
    pub critic_layer_norm: bool,
}

impl Default for SacBenchOptions {
    fn default() -> Self {
        SacBenchOptions { envs: 4096, memory: 64, obs: 96, priv_obs: 130, actions: 22, hidden: vec![512, 256, 128], batch: 4096, gradient_steps: 8, warmup: 1, iters: 5, n_step: 1, critic_layer_norm: false }
    }
}

/// The cost of SAC's gradient step on synthetic replay data, as skrl's peer benchmark times it: a
/// buffer of `envs × memory` random transitions (1 % terminated), then `warmup + iters` updates of
/// `gradient_steps` gradient steps each; one gradient step = a critic update of both critics
/// (target from the target critics and a fresh next action), an actor update, a temperature update
/// and a Polyak step of both targets (n = 1, clipped double-Q, ELU, no LayerNorm: skrl's SAC;
/// `n_step` and `critic_layer_norm` give the shipped lift configs' shape).
/// Returns one JSON object with `ms_per_gradient_step` (median, min, max over the timed updates).
///
/// On a GPU, `gpu_counts`: the kernels, submissions and host synchronisations per gradient step
/// ([`crate::gpu_counts`]; `ctx`, the learner's wgpu context, gives the queue's submissions); and
/// `device_resident`: the same updates again with the buffer copied to the device (what a GPU
/// training run samples from), each update ended by a wait for the device.
pub fn run_sac_bench(o: &SacBenchOptions, device: burn::prelude::Device, device_name: &str, ctx: Option<&crate::gpu::context::GpuContext>) -> Result<serde_json::Value> {
    use crate::gpu_counts::{GpuCounts, queue_submissions, submissions_between};
    use crate::config::{PolicyConfig, SacConfig};
    use crate::learn::ppo::Dims;
    use crate::rng::Rng;
    use crate::learn::sac::Sac;
    use crate::learn::sac::buffer::Transitions;
    let cfg = SacConfig { batch_size: o.batch as u32, buffer_capacity: o.memory as u32, learning_starts: u32::MAX, tau: 0.005, init_alpha: 0.2, n_step: o.n_step, critic_layer_norm: o.critic_layer_norm, ..SacConfig::default() };
    let pol = PolicyConfig { actor_hidden: o.hidden.clone(), critic_hidden: o.hidden.clone(), ..PolicyConfig::default() };
    let dims = Dims { obs: o.obs, priv_obs: o.priv_obs, act: o.actions };
    let mut sac = Sac::new(dims, o.envs, &cfg, &pol, device, 0)?;
    let mut rng = Rng::new(1, 1);
    let n = o.envs;
    for _ in 0..o.memory {
        let mut draw = |len: usize| -> Vec<f32> { (0..len).map(|_| rng.normal() as f32).collect() };
        let (ob, pr, next_ob, next_pr, rew) = (draw(n * o.obs), draw(n * o.priv_obs), draw(n * o.obs), draw(n * o.priv_obs), draw(n));
        let act: Vec<f32> = (0..n * o.actions).map(|_| (2.0 * rng.uniform() - 1.0) as f32).collect();
        let term: Vec<bool> = (0..n).map(|_| rng.uniform() < 0.01).collect();
        sac.buffer.push(&Transitions { obs: &ob, priv_obs: &pr, actions: &act, rewards: &rew, done: &term, terminated: &term, next_obs: &next_ob, next_priv_obs: &next_pr })?;
    }
    // `warmup + iters` updates of `gradient_steps` steps, each update timed (and, with `sync`,
    // ended by a wait for the device): ms per gradient step and process CPU s of the timed ones,
    // and the last update's GPU counts per gradient step
    let timed = |sac: &mut Sac, label: &str, sync: bool| -> Result<(Vec<f64>, Vec<f64>, serde_json::Value)> {
        let (mut per_step_ms, mut cpu_s, mut counts) = (Vec::new(), Vec::new(), serde_json::Value::Null);
        for it in 0..o.warmup + o.iters {
            let (m0, q0) = (GpuCounts::now(), ctx.and_then(|c| queue_submissions(&c.queue)));
            let (t0, c0) = (Instant::now(), process_cpu_time());
            for _ in 0..o.gradient_steps {
                sac.gradient_step()?;
            }
            if sync {
                crate::gpu::io::sync(&sac.device)?;
            }
            let (dt, dc) = (t0.elapsed().as_secs_f64(), process_cpu_time() - c0);
            let q1 = ctx.and_then(|c| queue_submissions(&c.queue));
            counts = GpuCounts::now().since(&m0).to_json(o.gradient_steps as f64, submissions_between(q0, q1));
            crate::console::status(&format!("  {label}update {it}{}: {:.0} ms ({:.1} ms per gradient step)", if it < o.warmup { " (warm-up)" } else { "" }, 1e3 * dt, 1e3 * dt / o.gradient_steps as f64));
            if it >= o.warmup {
                per_step_ms.push(1e3 * dt / o.gradient_steps as f64);
                cpu_s.push(dc);
            }
        }
        Ok((per_step_ms, cpu_s, counts))
    };
    let (per_step_ms, cpu_s, counts) = timed(&mut sac, "", false)?;
    let s = sac.take_stats()?;
    let st = stats(&per_step_ms);
    let median = st["median"].as_f64().unwrap_or(f64::NAN);
    // the device-resident replay buffer (what a GPU training run samples from, and where skrl's
    // memory lives): the same transitions copied to the device, the same updates timed again, each
    // ended when the device is idle (a training run reads its statistics once per iteration)
    let mut device_path = serde_json::Value::Null;
    if let Some(ctx) = ctx.filter(|_| crate::learn::nets::is_gpu(&sac.device)) {
        sac.start_device_rollouts(ctx)?;
        let (d_ms, d_cpu_s, d_counts) = timed(&mut sac, "device-resident ", true)?;
        sac.take_stats()?;
        device_path = json!({"ms_per_gradient_step": stats(&d_ms), "update_process_cpu_s": stats(&d_cpu_s), "gpu_counts": {"per_gradient_step": d_counts}});
    }
    Ok(json!({
        "bench": "dextrain_sac_bench",
        "device": device_name,
        // products that fell back from the chosen GPU matmul routine to burn's (0: all ran the chosen one)
        "gpu_matmul_fallbacks": crate::learn::kernels::gpu_matmul::fallbacks(),
        // the GPU products' routine and, with `dextrain_tuned`, each product's timed tile shapes
        "gpu_matmul": crate::learn::kernels::gpu_matmul::chosen().name(),
        // how acting ran its forward passes (DEXTRAIN_MLP_FORWARD): "auto" (one kernel per MLP
        // for small batches), "fused" (always) or "layers" (a product per layer)
        "mlp_forward": crate::learn::kernels::mlp_forward::mode_name(),
        "matmul_tuning": crate::learn::kernels::matmul_tuning::report(),
        "threads": rayon::current_num_threads(),
        "batch": o.batch, "gradient_steps": o.gradient_steps, "hidden": o.hidden, "activation": "elu",
        "n_step": o.n_step, "critic_layer_norm": o.critic_layer_norm,
        "obs": o.obs, "state": o.priv_obs, "actions": o.actions, "num_envs": o.envs, "memory_size": o.memory,
        "ms_per_gradient_step": st,
        "gradient_steps_per_s": 1e3 / median,
        "transitions_per_s": o.batch as f64 * 1e3 / median,
        "update_process_cpu_s": stats(&cpu_s),
        "gpu_counts": if crate::learn::nets::is_gpu(&sac.device) { json!({"per_gradient_step": counts}) } else { serde_json::Value::Null },
        // on a GPU, the same gradient steps sampling the device-resident replay buffer
        "device_resident": device_path,
        "last": {"critic_loss": s.critic_loss, "actor_loss": s.actor_loss, "alpha": s.alpha, "entropy": s.entropy},
        "cpu": cpu_model(),
    }))
}

/// The CPU's model name, whether it has AVX-512 and AVX2 (from /proc/cpuinfo), and which kernels the
/// learner runs on it: gemm's (AVX-512 when built with the `x86-v4` feature and the CPU has it, else
/// AVX2 + FMA), whether the dense layers' `x W` and `g Wᵀ` run dextrain's own AVX2 product instead
/// ([`crate::learn::kernels::sgemm::runs`]), and the fused ELU's ([`crate::learn::kernels::isa::isa`], capped by
/// `DEXTRAIN_SIMD`).
pub fn cpu_model() -> serde_json::Value {
    let info = std::fs::read_to_string("/proc/cpuinfo").unwrap_or_default();
    let model = info.lines().find(|l| l.starts_with("model name")).and_then(|l| l.split(':').nth(1)).map(|s| s.trim().to_string());
    let flags = info.lines().find(|l| l.starts_with("flags")).unwrap_or("");
    let avx512f = flags.split_whitespace().any(|f| f == "avx512f");
    let gemm = if cfg!(feature = "x86-v4") && avx512f { "avx512" } else { "avx2" };
    json!({"model": model, "avx512f": avx512f, "avx2": flags.split_whitespace().any(|f| f == "avx2"),
           "kernels": {"gemm": gemm, "own_avx2_product": crate::learn::kernels::sgemm::runs(),
                       "elu": format!("{:?}", crate::learn::kernels::isa::isa()).to_lowercase()}})
}

/// The encoder `bench --video` times (`--video-format`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum VideoBenchFormat {
    /// H.264 in MP4 (OpenH264 + muxide).
    Mp4,
    /// An animated GIF.
    Gif,
}

impl VideoBenchFormat {
    /// The file extension that selects the format.
    pub fn extension(self) -> &'static str {
        match self {
            VideoBenchFormat::Mp4 => "mp4",
            VideoBenchFormat::Gif => "gif",
        }
    }
}

/// `dextrain bench --video`: render + encode time per video frame. One env of the bench scene on
/// the CPU (the 16-joint hand's colliders and the cube) approaches and grasps (the approach, then
/// the noisy grasp targets), `frames` of its states are kept, then each is rendered (triangles
/// built, both views drawn and read back, the caption drawn) and encoded into a temporary video of
/// `format`'s kind (`mp4` or `gif`) on `ctx`; per-frame times in ms (median, min, max).
pub fn run_video_bench(frames: usize, view: crate::video::ViewSize, format: VideoBenchFormat, ctx: crate::gpu::context::GpuContext) -> Result<serde_json::Value> {
    use crate::record::RolloutFrame;
    use crate::video::{FrameRenderer, VideoWriter, camera::FollowTarget};
    let frames = frames.max(2);
    let mut cfg = bench_config(1);
    cfg.sim.backend = "cpu".parse().map_err(|e| anyhow::anyhow!("{e}"))?;
    cfg.validate()?;
    let model = SimModel::from_config(&cfg)?;
    let mut env = crate::env::make_env_batch(&cfg, model.clone())?;
    let g = &model.globals;
    let dt = g.dt * g.decimation as f32;
    let grasp = grasp_targets(&model);
    let approach_steps = (0.9 / dt).round() as usize;
    let params = env.params()?;
    let mut states = Vec::with_capacity(frames);
    for k in 0..frames {
        let t = if k < approach_steps { approach_targets(&model, &grasp, k as f32 * dt) } else { noisy_targets(&model, &grasp, 1, k as u32)[0] };
        env.step(&[t])?;
        states.push(env.states()?[0]);
    }
    let meta = crate::record::RolloutMeta {
        hand: model.hand.clone(),
        object: crate::record::object_parts(&model.objects[params[0].obj_index as usize], params[0].obj_scale),
        dt,
        info: json!({ "command": "bench --video" }),
    };
    let nj = model.joints.len();
    let rollout: Vec<RolloutFrame> = states
        .iter()
        .enumerate()
        .map(|(k, s)| RolloutFrame {
            t: k as f64 * dt as f64,
            joint_pos: s.q[..nj].to_vec(),
            joint_vel: s.qd[..nj].to_vec(),
            joint_target: s.q[..nj].to_vec(),
            wrist: crate::geom::Pose::from_arrays(s.wrist_pos, s.wrist_rot),
            object: crate::geom::Pose::from_arrays(s.obj_pos, s.obj_rot),
            links: crate::env::hand_link_poses(&model, s),
            contacts: Vec::new(),
            object_ref: None,
            overlay: Vec::new(),
        })
        .collect();
    let dir = std::env::temp_dir().join(format!("dextrain-bench-video-{}", std::process::id()));
    std::fs::create_dir_all(&dir).map_err(|e| anyhow::anyhow!("bench --video: cannot create {}: {e}", dir.display()))?;
    let path = dir.join(format!("bench.{}", format.extension()));
    let adapter = ctx.describe();
    let mut renderer = FrameRenderer::new(ctx, view)?;
    let (width, height) = renderer.frame_size();
    let result = (|| -> Result<(Vec<f64>, Vec<f64>, u64)> {
        let mut writer = VideoWriter::create(&path, width, height, 1.0 / dt as f64)?;
        let (mut render_ms, mut encode_ms) = (Vec::with_capacity(frames), Vec::with_capacity(frames));
        let mut follow = FollowTarget::new();
        // the first frame warms up (pipelines, buffers, the encoder) untimed
        let warm = renderer.render(&meta, &rollout[0], follow.update(rollout[0].object.pos), "warm-up")?;
        writer.push(&warm)?;
        for (k, frame) in rollout.iter().enumerate().skip(1) {
            let t0 = Instant::now();
            let image = renderer.render(&meta, frame, follow.update(frame.object.pos), &format!("frame {k}"))?;
            let t1 = Instant::now();
            writer.push(&image)?;
            render_ms.push((t1 - t0).as_secs_f64() * 1e3);
            encode_ms.push(t1.elapsed().as_secs_f64() * 1e3);
        }
        writer.finish()?;
        let bytes = std::fs::metadata(&path).map(|m| m.len()).unwrap_or(0);
        Ok((render_ms, encode_ms, bytes))
    })();
    let _ = std::fs::remove_dir_all(&dir);
    let (render_ms, encode_ms, bytes) = result?;
    let total: Vec<f64> = render_ms.iter().zip(&encode_ms).map(|(a, b)| a + b).collect();
    let triangles = crate::video::triangles::frame_triangles(&meta, &rollout[0]).0.len() / 3;
    Ok(json!({
        "bench": "video",
        "adapter": adapter,
        "format": format.extension(),
        "frame_width": width,
        "frame_height": height,
        "frames_timed": render_ms.len(),
        "triangles_per_frame": triangles,
        "render_ms_per_frame": summary(render_ms),
        "encode_ms_per_frame": summary(encode_ms),
        "total_ms_per_frame": summary(total),
        "bytes_per_frame": bytes as f64 / frames as f64,
    }))
}
