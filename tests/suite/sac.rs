//! SAC (learn/sac): the squashed Gaussian's log-probability, n-step targets, the per-env ring
//! buffer, Polyak averaging, the temperature, learning the tiny steering task, an exact resume
//! (buffer included), and the wgpu learner against the CPU learner.

use burn::prelude::*;
use dextrain::config::{PolicyConfig, QReduction, SacConfig};
use dextrain::learn::nets::{to_host, to_tensor};
use dextrain::learn::ppo::Dims;
use dextrain::rng::Rng;
use dextrain::learn::sac::buffer::{ReplayBuffer, Transitions};
use dextrain::learn::sac::{Sac, squash_log_std, squashed_sample};

use crate::learn::PointTask;

fn cpu() -> Device {
    Device::flex().autodiff()
}

fn small_policy() -> PolicyConfig {
    PolicyConfig { actor_hidden: vec![32, 32], critic_hidden: vec![32, 32], ..PolicyConfig::default() }
}

/// log π(tanh(u)) = Σ_k [−½ ε² − log σ − ½ ln 2π − ln(1 − tanh² u)], computed here in f64 from the
/// definition, including a |u| = 30 entry where 1 − tanh² u underflows in f32.
#[test]
fn the_squashed_gaussians_log_prob_matches_a_hand_computed_value() {
    let rows: [([f64; 3], [f64; 3], [f64; 3]); 2] = [([0.3, -0.2, 1.1], [-0.5, 0.1, -1.7], [0.7, -1.2, 0.05]), ([30.0, -0.4, 0.0], [-2.0, 0.3, 0.0], [0.0, 2.0, -0.3])];
    let flat = |k: usize| rows.iter().flat_map(|r| [r.0, r.1, r.2][k].map(|x| x as f32)).collect::<Vec<f32>>();
    let dev = cpu();
    let (a, logp) = squashed_sample(to_tensor(flat(0), [2, 3], &dev), to_tensor(flat(1), [2, 3], &dev), to_tensor(flat(2), [2, 3], &dev));
    let (a, logp) = (to_host(a).unwrap(), to_host(logp).unwrap());
    for (r, (mu, ls, eps)) in rows.iter().enumerate() {
        let mut expect = 0.0f64;
        for k in 0..3 {
            let u = mu[k] + ls[k].exp() * eps[k];
            // ln(1 − tanh² u) = ln(sech² u) = −2 ln cosh u = −2 (|u| + ln(1 + e^{−2|u|}) − ln 2)
            let log_sech2 = -2.0 * (u.abs() + (-2.0 * u.abs()).exp().ln_1p() - std::f64::consts::LN_2);
            expect += -0.5 * eps[k] * eps[k] - ls[k] - 0.5 * (2.0 * std::f64::consts::PI).ln() - log_sech2;
            assert!((a[r * 3 + k] as f64 - u.tanh()).abs() < 1e-6, "a = tanh(u)");
        }
        assert!((logp[r] as f64 - expect).abs() < 1e-4 * expect.abs().max(1.0), "row {r}: log π {} vs {expect}", logp[r]);
    }
}

/// The squashed sample as one operation (`learn::kernels::squashed`: a kernel each way on burn's
/// wgpu runtime, tensor ops elsewhere) against `squashed_sample`'s tensor ops differentiated by
/// burn, on 37 rows of 5 actions with μ up to ±30 (saturated actions) and log σ squashed into
/// [−5, 2]: the actions, log π and ∂L/∂head for L = Σ w ⊙ a + Σ v ⊙ log π agree to float rounding,
/// on the CPU and on the GPU, where the sample and its gradient are one kernel each.
#[test]
fn the_fused_squashed_sample_matches_its_tensor_ops_and_their_gradient() {
    use dextrain::gpu_counts::{Event, GpuCounts};
    use dextrain::learn::kernels::squashed::squashed_sample_fused;
    let (rows, a, lo, hi) = (37usize, 5usize, -5.0, 2.0);
    let mut rng = Rng::new(8, 1);
    let mut draw = |n: usize, scale: f64| (0..n).map(|_| (rng.normal() * scale) as f32).collect::<Vec<f32>>();
    let mut head = draw(rows * 2 * a, 1.5);
    head[0] = 30.0; // saturated: 1 − tanh² u underflows
    head[2 * a + 1] = -30.0;
    let (eps, w, v) = (draw(rows * a, 1.0), draw(rows * a, 1.0), draw(rows, 1.0));
    // (a, log π, ∂L/∂head) with the sample made by `sample`
    let run = |device: &Device, fused: bool| -> (Vec<f32>, Vec<f32>, Vec<f32>) {
        let h = to_tensor(head.clone(), [rows, 2 * a], device).require_grad();
        let e = to_tensor(eps.clone(), [rows, a], device);
        let (act, logp) = if fused {
            squashed_sample_fused(h.clone(), e, lo, hi)
        } else {
            squashed_sample(h.clone().narrow(1, 0, a), squash_log_std(h.clone().narrow(1, a, a), lo, hi), e)
        };
        let loss = (act.clone() * to_tensor(w.clone(), [rows, a], device)).sum() + (logp.clone() * to_tensor(v.clone(), [rows, 1], device)).sum();
        let grads = loss.backward();
        (to_host(act).unwrap(), to_host(logp).unwrap(), to_host(h.grad(&grads).expect("a gradient of the head")).unwrap())
    };
    let close = |name: &str, got: &[f32], want: &[f32]| {
        assert_eq!(got.len(), want.len(), "{name}");
        for (i, (g, w)) in got.iter().zip(want).enumerate() {
            assert!((g - w).abs() <= 1e-4 * (1.0 + w.abs()), "{name}[{i}]: {g} vs {w}");
        }
    };
    let reference = run(&cpu(), false);
    assert!(reference.2.iter().any(|g| g.abs() > 0.1), "the gradient must not vanish");
    let fused_cpu = run(&cpu(), true);
    for (name, k) in [("cpu a", 0), ("cpu log π", 1), ("cpu ∂head", 2)] {
        let pick = |r: &(Vec<f32>, Vec<f32>, Vec<f32>)| [&r.0, &r.1, &r.2][k].clone();
        close(name, &pick(&fused_cpu), &pick(&reference));
    }
    let Some((_ctx, gpu)) = crate::common::wgpu_learner("the_fused_squashed_sample_matches_its_tensor_ops_and_their_gradient") else { return };
    let before = GpuCounts::now();
    let fused_gpu = run(&gpu, true);
    let counts = GpuCounts::now().since(&before);
    for (name, k) in [("gpu a", 0), ("gpu log π", 1), ("gpu ∂head", 2)] {
        let pick = |r: &(Vec<f32>, Vec<f32>, Vec<f32>)| [&r.0, &r.1, &r.2][k].clone();
        close(name, &pick(&fused_gpu), &pick(&reference));
    }
    assert_eq!(
        (counts.total_from(Event::Kernel, "dextrain:squashed_sample"), counts.total_from(Event::Kernel, "dextrain:squashed_sample_backward")),
        (2, 1), // (the first name is a prefix of the second)
        "one kernel each way: {counts:?}"
    );
}

/// SAC's per-row losses as one operation each (`learn::kernels::sac_loss`: two kernels forward and
/// one backward on burn's wgpu runtime, tensor ops elsewhere) against the tensor ops of SAC's
/// gradient step differentiated by burn, on 600 rows (three workgroups, the last one partial): a
/// critic's `[mean (Q − y)², mean Q / 2]` and the actor's `[mean (α log π − Q̃), −mean log π]`, and
/// the gradients of w · out[0] in Q (critic) and in log π and Q̃ (actor), agree to float rounding,
/// on the CPU and on the GPU, where each is three kernels.
#[test]
fn the_fused_sac_losses_match_their_tensor_ops_and_their_gradient() {
    use dextrain::gpu_counts::{Event, GpuCounts};
    use dextrain::learn::kernels::sac_loss::{SacLoss, sac_loss_fused};
    let rows = 600usize;
    let mut rng = Rng::new(10, 3);
    let mut draw = |n: usize, scale: f64| (0..n).map(|_| (rng.normal() * scale) as f32).collect::<Vec<f32>>();
    let (a, b, log_alpha, w) = (draw(rows, 2.0), draw(rows, 2.0), -0.7f32, 1.3f64);
    // (out [1, 2], ∂L/∂a, ∂L/∂b) for L = w · out[0]
    let run = |device: &Device, fused: bool, kind: SacLoss| -> [Vec<f32>; 3] {
        let at = to_tensor(a.clone(), [rows, 1], device).require_grad();
        let bt = to_tensor(b.clone(), [rows, 1], device).require_grad();
        let la = to_tensor(vec![log_alpha], [1, 1], device);
        let (root, out) = if fused {
            let out = sac_loss_fused(at.clone(), bt.clone(), la, kind);
            (out.clone(), out)
        } else {
            let (loss, stat) = match kind {
                SacLoss::Critic { q_scale } => ((at.clone() - bt.clone()).square().mean(), at.clone().mean().mul_scalar(q_scale)),
                SacLoss::Actor => ((at.clone() * la.exp() - bt.clone()).mean(), at.clone().mean().neg()),
            };
            (loss.clone().reshape([1, 1]), Tensor::cat(vec![loss, stat], 0).reshape([1, 2]))
        };
        let grads = root.mul_scalar(w).backward();
        let grad = |x: &Tensor<2>| to_host(x.grad(&grads).expect("a gradient")).unwrap();
        [to_host(out).unwrap(), grad(&at), grad(&bt)]
    };
    let close = |name: &str, got: &[f32], want: &[f32]| {
        assert_eq!(got.len(), want.len(), "{name}");
        for (i, (g, w)) in got.iter().zip(want).enumerate() {
            assert!((g - w).abs() <= 1e-4 * (1.0 + w.abs()), "{name}[{i}]: {g} vs {w}");
        }
    };
    let gpu = crate::common::wgpu_learner("the_fused_sac_losses_match_their_tensor_ops_and_their_gradient");
    for kind in [SacLoss::Critic { q_scale: 0.5 }, SacLoss::Actor] {
        let reference = run(&cpu(), false, kind);
        assert!(reference[1].iter().all(|g| g.abs() > 0.0) && reference[0][1] != 0.0, "{kind:?}: the gradients and the statistic must not vanish");
        let names = ["out", "∂a", "∂b"];
        for (k, got) in run(&cpu(), true, kind).iter().enumerate() {
            close(&format!("cpu {kind:?} {}", names[k]), got, &reference[k]);
        }
        let Some((_ctx, device)) = &gpu else { continue };
        let before = GpuCounts::now();
        let fused_gpu = run(device, true, kind);
        let counts = GpuCounts::now().since(&before);
        for (k, got) in fused_gpu.iter().enumerate() {
            close(&format!("gpu {kind:?} {}", names[k]), got, &reference[k]);
        }
        let kernels = |name: &str| counts.total_from(Event::Kernel, name);
        assert_eq!([kernels("dextrain:sac_loss_rows"), kernels("dextrain:sac_loss_finish"), kernels("dextrain:sac_loss_backward")], [1, 1, 1], "{kind:?}: {counts:?}");
    }
}

/// One env, 8 slots, rewards 1…6; transition 2 ends by a time-out and transition 4 by a
/// termination; the next critic observation of slot j is 10 + j. Every start's n-step target
/// (n = 3, γ = 0.9) is the sum written out by hand.
#[test]
fn n_step_targets_match_the_naive_sum_through_time_outs_and_terminations() {
    let mut buf = ReplayBuffer::new(1, 8, 1, 1, 1);
    for j in 0..6 {
        let f = j as f32;
        buf.push(&Transitions {
            obs: &[f],
            priv_obs: &[f],
            actions: &[0.0],
            rewards: &[f + 1.0],
            done: &[j == 2],
            terminated: &[j == 4],
            next_obs: &[10.0 + f],
            next_priv_obs: &[10.0 + f],
        })
        .unwrap();
    }
    let g = 0.9f32;
    // (R, bootstrap factor, the observation it bootstraps from) for starts 0…5
    let expect = [
        (1.0 + g * 2.0 + g * g * 3.0, g * g * g, 12.0), // 0,1,2: ends at the time-out, bootstraps γ³ from its final obs
        (2.0 + g * 3.0, g * g, 12.0),                   // 1,2: cut at the time-out
        (3.0, g, 12.0),                                 // the time-out itself
        (4.0 + g * 5.0, 0.0, 14.0),                     // 3,4: cut at the termination, no bootstrap
        (5.0, 0.0, 14.0),                               // the termination
        (6.0, g, 15.0),                                 // the newest: its window stops there
    ];
    let mut rng = Rng::new(1, 1);
    let s = buf.sample(400, 3, g, &mut rng).unwrap();
    let mut seen = [false; 6];
    for (k, &(env, slot)) in s.rows.iter().enumerate() {
        assert_eq!(env, 0);
        assert!(slot < 6, "slot {slot} was never written");
        let (r, b, next) = expect[slot];
        assert!((s.returns[k] - r).abs() < 1e-5, "start {slot}: R {} vs {r}", s.returns[k]);
        assert!((s.bootstrap[k] - b).abs() < 1e-6, "start {slot}: bootstrap {} vs {b}", s.bootstrap[k]);
        assert_eq!(s.next_priv_obs[k], next, "start {slot}");
        assert_eq!(s.priv_obs[k], slot as f32);
        seen[slot] = true;
    }
    assert!(seen.iter().all(|&x| x), "every written slot is drawn");
    // n = 1 is the one-step target
    let s1 = buf.sample(50, 1, g, &mut rng).unwrap();
    for (k, &(_, slot)) in s1.rows.iter().enumerate() {
        assert_eq!(s1.returns[k], slot as f32 + 1.0);
        assert_eq!(s1.bootstrap[k], if slot == 4 { 0.0 } else { g });
    }
}

/// 3 envs, 4 slots: before the rings wrap only written slots are drawn; after 6 pushes the two
/// oldest are overwritten and never drawn again; every env gives the same number of rows.
#[test]
fn the_ring_buffer_wraps_and_samples_only_written_slots_evenly_over_envs() {
    let (n, cap) = (3, 4);
    let mut buf = ReplayBuffer::new(n, cap, 1, 2, 1);
    let push = |buf: &mut ReplayBuffer, j: usize| {
        let v: Vec<f32> = (0..n).map(|i| (100 * j + i) as f32).collect();
        let p: Vec<f32> = v.iter().flat_map(|&x| [x, -x]).collect();
        buf.push(&Transitions { obs: &v, priv_obs: &p, actions: &v, rewards: &v, done: &[false; 3], terminated: &[false; 3], next_obs: &v, next_priv_obs: &p }).unwrap();
    };
    let mut rng = Rng::new(2, 2);
    assert!(buf.sample(4, 1, 0.9, &mut rng).is_err(), "an empty buffer has nothing to draw");
    for j in 0..3 {
        push(&mut buf, j);
    }
    let s = buf.sample(300, 1, 0.9, &mut rng).unwrap();
    let mut per_env = [0; 3];
    for (k, &(env, _)) in s.rows.iter().enumerate() {
        let push_index = (s.obs[k] as usize) / 100;
        assert!(push_index < 3 && s.obs[k] as usize % 100 == env, "{}", s.obs[k]);
        assert_eq!(s.priv_obs[2 * k + 1], -s.obs[k]);
        per_env[env] += 1;
    }
    assert_eq!(per_env, [100; 3]);
    for j in 3..6 {
        push(&mut buf, j);
    }
    assert_eq!((buf.len, buf.pos, buf.transitions()), (4, 2, 12));
    let s = buf.sample(600, 1, 0.9, &mut rng).unwrap();
    let mut drawn = std::collections::BTreeSet::new();
    for &o in &s.obs {
        drawn.insert(o as usize / 100);
    }
    assert_eq!(drawn.into_iter().collect::<Vec<_>>(), vec![2, 3, 4, 5], "pushes 0 and 1 were overwritten");
}

/// A learner on random transitions of 8 envs (obs 3, critic obs 4, actions 2).
fn filled(cfg: &SacConfig, device: Device, seed: u64) -> Sac {
    let dims = Dims { obs: 3, priv_obs: 4, act: 2 };
    let n = 8;
    let mut sac = Sac::new(dims, n, cfg, &small_policy(), device, seed).unwrap();
    let mut rng = Rng::new(7, 7);
    let mut v = |k: usize| (0..k).map(|_| rng.normal() as f32).collect::<Vec<f32>>();
    for _ in 0..4 {
        let (o, p) = (v(n * 3), v(n * 4));
        sac.act(&o, &p).unwrap();
        let (r, o2, p2) = (v(n), v(n * 3), v(n * 4));
        let done: Vec<bool> = (0..n).map(|i| i == 2).collect();
        let none = vec![false; n];
        sac.observe(&r, &none, &done, &o2, &p2, &o2, &p2).unwrap();
    }
    sac
}

fn values(params: &[Tensor<2>]) -> Vec<Vec<f32>> {
    params.iter().map(|p| to_host(p.clone().inner()).unwrap()).collect()
}

/// τ = 1 makes every target a copy of its critic; τ = 0.25 moves it a quarter of the way.
#[test]
fn polyak_averaging_with_tau_one_copies_the_critics() {
    let base = SacConfig { batch_size: 16, learning_starts: 100, ..SacConfig::default() };
    let mut sac = filled(&SacConfig { tau: 1.0, ..base.clone() }, cpu(), 3);
    sac.gradient_step().unwrap();
    for (t, c) in sac.targets.iter().zip(&sac.critics) {
        assert_eq!(values(t), values(c));
    }
    let mut sac = filled(&SacConfig { tau: 0.25, ..base }, cpu(), 3);
    let before: Vec<Vec<Vec<f32>>> = sac.targets.iter().map(|t| values(t)).collect();
    sac.gradient_step().unwrap();
    let mut moved = false;
    for ((t, c), old) in sac.targets.iter().zip(&sac.critics).zip(&before) {
        for ((tv, cv), ov) in values(t).iter().zip(values(c)).zip(old) {
            for ((x, y), z) in tv.iter().zip(&cv).zip(ov) {
                assert!((x - (0.25 * y + 0.75 * z)).abs() < 1e-6, "θ̄ = τθ + (1 − τ)θ̄: {x} vs {y}, {z}");
                moved |= (x - z).abs() > 1e-7;
            }
        }
    }
    assert!(moved, "the critics changed, so the targets moved");
}

/// The temperature rises while the policy's entropy is below its target and falls while above.
#[test]
fn the_temperature_rises_when_the_entropy_is_below_its_target() {
    let base = SacConfig { batch_size: 32, learning_starts: 100, alpha_learning_rate: 1e-2, init_alpha: 0.2, ..SacConfig::default() };
    // a squashed Gaussian over 2 actions has entropy below 2·ln 2: a target of +20 is out of reach
    let mut high = filled(&SacConfig { target_entropy_scale: -10.0, ..base.clone() }, cpu(), 4);
    let mut low = filled(&SacConfig { target_entropy_scale: 10.0, ..base.clone() }, cpu(), 4);
    for _ in 0..5 {
        high.gradient_step().unwrap();
        low.gradient_step().unwrap();
    }
    assert!(high.alpha().unwrap() > 0.2 * 1.04, "α = {} should rise", high.alpha().unwrap());
    assert!(low.alpha().unwrap() < 0.2 / 1.04, "α = {} should fall", low.alpha().unwrap());
    // learn_alpha = false keeps it
    let mut fixed = filled(&SacConfig { learn_alpha: false, ..base }, cpu(), 4);
    fixed.gradient_step().unwrap();
    assert!((fixed.alpha().unwrap() - 0.2).abs() < 1e-6);
}

/// SAC learns to steer the point onto its target (the task PPO's test learns): the policy mean's
/// reward per step goes from about −0.8 to above −0.45.
#[test]
fn sac_learns_the_tiny_steering_task() {
    let n = 32;
    let cfg = SacConfig {
        gamma: 0.9, // the task is myopic: the reward is the distance now
        updates_per_step: 2,
        batch_size: 256,
        learning_starts: 20,
        random_steps: 20,
        buffer_capacity: 400,
        n_step: 3,
        actor_learning_rate: 1e-3,
        critic_learning_rate: 1e-3,
        alpha_learning_rate: 1e-3,
        tau: 0.05,
        critic_layer_norm: true,
        q_reduction: QReduction::Mean,
        ..SacConfig::default()
    };
    let dims = Dims { obs: 2, priv_obs: 2, act: 2 };
    let mut sac = Sac::new(dims, n, &cfg, &small_policy(), cpu(), 5).unwrap();
    let greedy = |sac: &Sac| -> f64 {
        let mut env = PointTask::new(64);
        let mut sum = 0.0;
        for _ in 0..20 {
            let a = sac.act_mean(&env.obs()).unwrap();
            sum += env.step(&a).0.iter().map(|&r| r as f64).sum::<f64>();
        }
        sum / (64.0 * 20.0)
    };
    let first = greedy(&sac);
    let mut env = PointTask::new(n);
    let mut obs = env.obs();
    let none = vec![false; n];
    for _ in 0..300 {
        let a = sac.act(&obs, &obs).unwrap();
        let (r, to) = env.step(&a);
        let next = env.obs();
        sac.observe(&r, &none, &to, &next, &next, &env.final_obs, &env.final_obs).unwrap();
        obs = next;
    }
    let stats = sac.take_stats().unwrap();
    assert!(stats.critic_loss.is_finite() && stats.actor_loss.is_finite() && stats.updates == 562, "{stats:?}");
    let last = greedy(&sac);
    eprintln!("tiny task, SAC: mean reward per step {first:.3} (untrained mean) -> {last:.3} after 300 env steps");
    assert!(first < -0.6, "the untrained policy should not steer: {first}");
    assert!(last > -0.45, "SAC did not learn to steer: {last}");
}

/// `Sac::state` holds the whole learner, the replay buffer included: a learner of another seed
/// that loads it continues bit for bit; without the buffer the load says so and starts empty.
#[test]
fn sac_state_restores_a_learner_that_continues_exactly() {
    let n = 16;
    let cfg = SacConfig { batch_size: 64, learning_starts: 3, random_steps: 2, buffer_capacity: 8, n_step: 2, policy_frequency: 2, weight_decay: 0.01, max_grad_norm: 1.0, ..SacConfig::default() };
    let dims = Dims { obs: 2, priv_obs: 2, act: 2 };
    let none = vec![false; n];
    let run = |sac: &mut Sac, env: &mut PointTask, steps: usize| -> Vec<Vec<f32>> {
        let mut acts = Vec::new();
        for _ in 0..steps {
            let obs = env.obs();
            let a = sac.act(&obs, &obs).unwrap();
            let (r, to) = env.step(&a);
            let next = env.obs();
            sac.observe(&r, &none, &to, &next, &next, &env.final_obs, &env.final_obs).unwrap();
            acts.push(a);
        }
        acts
    };
    let mut env = PointTask::new(n);
    let mut a = Sac::new(dims, n, &cfg, &small_policy(), cpu(), 3).unwrap();
    run(&mut a, &mut env, 12); // wraps the 8-slot rings
    let state = a.state().unwrap();
    assert!(state.file("replay").is_some() && state.u64("critic_adam_step").unwrap() == 10 && state.u64("actor_adam_step").unwrap() == 5);
    let mut b = Sac::new(dims, n, &cfg, &small_policy(), cpu(), 99).unwrap();
    assert!(b.load_state(&state).unwrap(), "the buffer was restored");
    assert_eq!(b.state().unwrap(), state, "the loaded learner's state is the saved one");
    let mut env_b = PointTask { x: env.x.clone(), target: env.target.clone(), t: env.t.clone(), rng: env.rng.clone(), final_obs: env.final_obs.clone() };
    assert_eq!(run(&mut a, &mut env, 5), run(&mut b, &mut env_b, 5), "the restored learner acts differently");
    assert_eq!(a.state().unwrap(), b.state().unwrap(), "the restored learner learns differently");
    // a checkpoint without the buffer: the learner loads, says so, and its buffer is empty
    let mut small = a.state().unwrap();
    small.files.retain(|f| f.name != "replay");
    let mut c = Sac::new(dims, n, &cfg, &small_policy(), cpu(), 1).unwrap();
    assert!(!c.load_state(&small).unwrap());
    assert_eq!(c.buffer.transitions(), 0);
    // a state without the optimiser is an error that names the file
    let mut partial = state.clone();
    partial.files.retain(|f| f.name != "optimizer");
    let err = format!("{:#}", c.load_state(&partial).unwrap_err());
    assert!(err.contains("optimizer.safetensors"), "{err}");
}

/// One gradient step (critics, actor, temperature, the targets' Polyak average) on burn's wgpu
/// backend (lavapipe in CI: the squashed sample, the losses and the Polyak average in kernels of
/// ours) and on the CPU backend (tensor ops) from the same state and batch: the parameters agree to
/// float rounding.
/// The GPU kernels of one gradient step of [`the_wgpu_sac_learner_matches_the_cpu_learner`]'s
/// learner (297 before the critics' and the actor's losses were kernels of ours, 262 before the
/// host path's batch was standardised on the device by one kernel of ours, 248 before the actor's
/// forward pass for the next states' actions, which no gradient flows through, was one kernel:
/// `mlp_forward.wgsl`; 246 before ELU's forward pass after the critics' LayerNorm was one kernel
/// of ours, where the tensor ops were five; 198 before the optimiser's steps ran three kernels over
/// all their parameters where each was two a parameter and one more — on lavapipe, which binds 32
/// storage buffers per kernel, the critics' step runs in groups of six parameters); 177 before each
/// dense layer's weight and bias gradients were one product and the actor's ELU gradients went
/// into its layers' input gradient products; 166 before the critics' LayerNorm and ELU were one
/// operation each way, their gain's and shift's gradients one column sum, and none where the
/// frozen critics of the actor's update leave them untracked).
const PINNED_SAC_KERNELS_PER_GRADIENT_STEP: u64 = 134;

#[test]
fn the_wgpu_sac_learner_matches_the_cpu_learner() {
    use dextrain::gpu_counts::{Event, GpuCounts};
    let kernels = std::cell::Cell::new(0u64);
    let Some((_ctx, gpu)) = crate::common::wgpu_learner("the_wgpu_sac_learner_matches_the_cpu_learner") else { return };
    let cfg = SacConfig { batch_size: 32, learning_starts: 100, critic_layer_norm: true, ..SacConfig::default() };
    let step = |device: Device| {
        let mut sac = filled(&cfg, device, 6);
        let before = GpuCounts::now();
        sac.gradient_step().unwrap();
        let counts = GpuCounts::now().since(&before);
        kernels.set(counts.total(Event::Kernel));
        let mut all = values(&sac.actor);
        for c in sac.critics.iter().chain(&sac.targets) {
            all.extend(values(c));
        }
        (all, sac.alpha().unwrap())
    };
    let (p_cpu, a_cpu) = step(cpu());
    let (p_gpu, a_gpu) = step(gpu);
    // the GPU's kernels for one gradient step of this learner (actor, two critics with LayerNorm,
    // their targets, the temperature; the host path, whose batch is normalised on the device;
    // `bench --sac`'s learner went from 384 to 215 when the squashed sample and the Polyak average
    // went into kernels of ours and SAC's optimisers stopped working out norms they do not read)
    assert_eq!(kernels.get(), PINNED_SAC_KERNELS_PER_GRADIENT_STEP, "kernels per SAC gradient step");
    let mut worst = 0.0f32;
    for (x, y) in p_cpu.iter().flatten().zip(p_gpu.iter().flatten()) {
        worst = worst.max((x - y).abs());
    }
    assert!(worst < 1e-4, "parameters after one gradient step differ by {worst}");
    assert!((a_cpu - a_gpu).abs() < 1e-6, "α {a_cpu} vs {a_gpu}");
    let fresh = filled(&cfg, cpu(), 6);
    assert_ne!(values(&fresh.actor), p_cpu[..fresh.actor.len()].to_vec(), "the step changed the actor");
}

/// SAC's device-resident batch as kernels of ours (`learn::kernels::replay_sample`: the rings' rows
/// gathered and normalised, the n-step windows walked) against the tensor ops they replace
/// (`DeviceReplay::sample` and the normaliser): 8 envs × 6 slots written 7 times (the ring wrapped),
/// time-outs and terminations inside the windows, n = 3, γ = 0.9, statistics whose mean and scale
/// are far from 0 and 1; whole rings and rings in pieces of 2 slots (the flag rings too); the
/// actor's observations kept and taken from the head of the critic's; normalised and raw. Every
/// tensor is the tensor ops' bit for bit (lavapipe), and a batch is one gather per ring piece of
/// each array and one window kernel.
#[test]
fn the_device_batch_kernels_match_the_tensor_ops() {
    use dextrain::gpu_counts::{Event, GpuCounts};
    use dextrain::learn::normalizer::{DeviceNormalizers, Normalizer};
    use dextrain::learn::sac::device::DeviceReplay;
    let Some((ctx, gpu)) = crate::common::wgpu_learner("the_device_batch_kernels_match_the_tensor_ops") else { return };
    let (envs, cap, od, pd, ad, b, n_step) = (8usize, 6usize, 3usize, 5usize, 2usize, 64usize, 3usize);
    let mut rng = Rng::new(3, 4);
    let mut normal = |k: usize, scale: f64, shift: f64| -> Vec<f32> { (0..k).map(|_| (shift + scale * rng.normal()) as f32).collect() };
    let (mut on, mut pn) = (Normalizer::new(od), Normalizer::new(pd));
    on.update(&normal(40 * od, 3.0, 1.5));
    pn.update(&normal(40 * pd, 0.2, -4.0));
    let norms = DeviceNormalizers::from_host(&on, &pn, &gpu);
    for keep_obs in [true, false] {
        let mut host = ReplayBuffer::new(envs, cap, if keep_obs { od } else { 0 }, pd, ad);
        for j in 0..7 {
            let (o, p, a, r) = (normal(envs * od, 1.0, 0.0), normal(envs * pd, 1.0, -4.0), normal(envs * ad, 1.0, 0.0), normal(envs, 1.0, 0.0));
            let (o2, p2) = (normal(envs * od, 1.0, 0.0), normal(envs * pd, 1.0, -4.0));
            let done: Vec<bool> = (0..envs).map(|i| (i + j) % 3 == 0).collect();
            let terminated: Vec<bool> = (0..envs).map(|i| (i + j) % 3 == 0 && (i + 2 * j) % 2 == 0).collect();
            let kept = |v: &Vec<f32>| if keep_obs { v.clone() } else { vec![] };
            host.push(&Transitions { obs: &kept(&o), priv_obs: &p, actions: &a, rewards: &r, done: &done, terminated: &terminated, next_obs: &kept(&o2), next_priv_obs: &p2 }).unwrap();
        }
        // one slot of the critic's observations a piece: every ring in pieces (6 of the critic's
        // and of the actor's, 3 of the actions', 2 of each flag ring)
        for piece_bytes in [0u64, (4 * envs * pd) as u64] {
            let replay = DeviceReplay::new(&ctx, &gpu, &host, piece_bytes).unwrap();
            replay.load(&host).unwrap();
            let pieces = |dim: usize| if piece_bytes == 0 { 1 } else { cap.div_ceil(((piece_bytes as usize) / (4 * envs * dim)).min(cap)) };
            let arrays: Vec<usize> = if keep_obs { vec![od, od, pd, pd, ad, 1, 1, 1] } else { vec![pd, pd, pd, pd, ad, 1, 1, 1] };
            let gathers: usize = arrays.iter().map(|&d| pieces(d)).sum();
            let draw = host.draw(b, n_step, &mut Rng::new(9, 9)).unwrap();
            for normalize in [true, false] {
                let what = format!("actor obs kept {keep_obs}, piece bytes {piece_bytes}, normalised {normalize}");
                let before = GpuCounts::now();
                let k = replay.sample_batch(&draw, 0.9, od, &norms, normalize).unwrap();
                let counts = GpuCounts::now().since(&before);
                let launched = |name: &str| counts.total_from(Event::Kernel, name) as usize;
                assert_eq!((launched("dextrain:replay_gather"), launched("dextrain:replay_window")), (gathers, 1), "{what}: {counts:?}");
                assert_eq!(counts.total(Event::Kernel) as usize, gathers + 1, "{what}: no other kernel: {counts:?}");
                let (obs, priv_obs, actions, returns, bootstrap, next_obs, next_priv) = replay.sample(&draw, 0.9).unwrap();
                let actor = |kept: Option<Tensor<2>>, critic: &Tensor<2>| kept.unwrap_or_else(|| critic.clone().slice([0..b, 0..od]));
                let (obs, next_obs) = (actor(obs, &priv_obs), actor(next_obs, &next_priv));
                let pairs = [
                    ("obs", k.obs, norms.obs.normalized(obs, normalize)),
                    ("next obs", k.next_obs, norms.obs.normalized(next_obs, normalize)),
                    ("critic obs", k.priv_obs, norms.priv_obs.normalized(priv_obs, normalize)),
                    ("next critic obs", k.next_priv, norms.priv_obs.normalized(next_priv, normalize)),
                    ("actions", k.actions, actions),
                    ("returns", k.returns, returns),
                    ("bootstrap", k.bootstrap, bootstrap),
                ];
                for (name, ours, theirs) in pairs {
                    assert_eq!(ours.dims(), theirs.dims(), "{what}: {name}");
                    let (x, y) = (to_host(ours).unwrap(), to_host(theirs.inner()).unwrap());
                    assert!(x.iter().zip(&y).all(|(p, q)| p.to_bits() == q.to_bits()), "{what}: {name}:\n{x:?}\n{y:?}");
                }
            }
        }
    }
}
