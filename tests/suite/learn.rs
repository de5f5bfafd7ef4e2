//! The learner's parts against independent computations: GAE vs the naive sum of discounted TD
//! errors, the normaliser vs a two-pass mean/variance, the PPO loss terms vs hand-computed values,
//! global gradient clipping and Adam's first step, and a tiny task that PPO must learn in seconds;
//! PPO's checkpoint state round-trips and a restored learner continues exactly.


use burn::prelude::*;
use dextrain::config::{PolicyConfig, PpoConfig};
use dextrain::learn::adam::{Adam, clipped_grads};
use dextrain::learn::nets::{to_host, to_tensor};
use dextrain::learn::normalizer::Normalizer;
use dextrain::learn::ppo::storage::gae;
use dextrain::learn::ppo::{Batch, Dims, Ppo, ppo_losses};
use dextrain::rng::Rng;

fn cpu() -> Device {
    Device::flex().autodiff()
}

#[test]
fn gae_matches_the_naive_sum_of_discounted_td_errors() {
    let (t_len, n) = (9, 4);
    let mut rng = Rng::new(1, 2);
    let rewards: Vec<f32> = (0..t_len * n).map(|_| rng.normal() as f32).collect();
    let values: Vec<f32> = (0..t_len * n).map(|_| rng.normal() as f32).collect();
    let dones: Vec<f32> = (0..t_len * n).map(|_| (rng.uniform() < 0.2) as u8 as f32).collect();
    assert!(dones.iter().any(|&d| d > 0.0), "the test needs episode ends");
    let last: Vec<f32> = (0..n).map(|_| rng.normal() as f32).collect();
    let (gamma, lam) = (0.97f64, 0.9f64);
    let mut adv = vec![0.0; t_len * n];
    let mut ret = vec![0.0; t_len * n];
    gae(&rewards, &values, &dones, &last, n, gamma as f32, lam as f32, &mut adv, &mut ret);
    for i in 0..n {
        let v = |t: usize| if t == t_len { last[i] as f64 } else { values[t * n + i] as f64 };
        for t in 0..t_len {
            // A_t = Σ_l (γλ)^l δ_{t+l}, stopping after the first done at or after t
            let mut a = 0.0f64;
            let mut w = 1.0f64;
            for u in t..t_len {
                let d = dones[u * n + i] as f64;
                let delta = rewards[u * n + i] as f64 + gamma * v(u + 1) * (1.0 - d) - v(u);
                a += w * delta;
                if d > 0.0 {
                    break;
                }
                w *= gamma * lam;
            }
            let k = t * n + i;
            assert!((adv[k] as f64 - a).abs() < 1e-5, "A[{t},{i}] = {} vs naive {a}", adv[k]);
            assert!((ret[k] as f64 - (a + v(t))).abs() < 1e-5);
        }
    }
}

#[test]
fn normaliser_matches_a_two_pass_mean_and_variance() {
    let d = 3;
    let mut rng = Rng::new(7, 0);
    let mut norm = Normalizer::new(d);
    let mut all: Vec<f32> = Vec::new();
    for rows in [1usize, 5, 17, 2, 40] {
        let batch: Vec<f32> = (0..rows * d).map(|k| (rng.normal() * (1.0 + k as f64 % 3.0) + 10.0 * (k % 3) as f64) as f32).collect();
        norm.update(&batch);
        all.extend_from_slice(&batch);
    }
    let n = (all.len() / d) as f64;
    for k in 0..d {
        let mean = all.iter().skip(k).step_by(d).map(|&x| x as f64).sum::<f64>() / n;
        let var = all.iter().skip(k).step_by(d).map(|&x| (x as f64 - mean).powi(2)).sum::<f64>() / n;
        assert!((norm.mean[k] - mean).abs() < 1e-9 * (1.0 + mean.abs()), "mean[{k}] {} vs {mean}", norm.mean[k]);
        assert!((norm.var()[k] - var).abs() < 1e-9 * (1.0 + var), "var[{k}] {} vs {var}", norm.var()[k]);
    }
    assert_eq!(norm.count, n);
    // apply: (x − μ) / (σ + ε)
    let mut x = vec![1.0f32, 2.0, 3.0];
    norm.apply(&mut x);
    for k in 0..d {
        let want = ((k + 1) as f64 - norm.mean[k]) / (norm.var()[k].sqrt() + 1e-2);
        assert!((x[k] as f64 - want).abs() < 1e-5);
    }
}

fn t2(v: &[f32], shape: [usize; 2]) -> Tensor<2> {
    to_tensor(v.to_vec(), shape, &cpu())
}

#[test]
fn ppo_loss_terms_match_hand_computed_values() {
    // B = 2 transitions, A = 1 action, log σ = 0 (σ = 1), ε = 0.2, c_v = 1, c_e = 0.005.
    // row 0: a = 0.5, μ = 0 → log π = −0.125 − ½ln2π; old log π = log π − 0.1 → ρ = e^0.1; Â = 1
    //        → surrogate max(−ρ, −clip(ρ)) = −1.105171 (ρ < 1.2: no clip)
    // row 1: a = −1, μ = 0 → log π = −0.5 − ½ln2π; old = log π − 0.5 → ρ = e^0.5 = 1.648721; Â = 2
    //        → max(−3.297443, −2.4) = −2.4 (clipped)
    // surrogate = (−1.105171 − 2.4) / 2 = −1.752585
    // values V = (1, 0), V_old = (0.5, 0.5), R = (2, 0):
    //   row 0: (1−2)² = 1 vs (0.5+0.2−2)² = 1.69 → 1.69;  row 1: 0 vs (0.5−0.2)² = 0.09 → 0.09;  mean 0.89
    // entropy = ½(1 + ln2π) = 1.418939;  total = −1.752585 + 0.89 − 0.005·1.418939 = −0.869680
    // KL(old‖new) with μ_old = (0.1, 0), σ_old = (1, 2): row 0: 0 + (1 + 0.01)/2 − ½ = 0.005;
    //   row 1: ln(1/2) + 4/2 − ½ = 0.806853;  mean 0.405926
    let half_ln_2pi = 0.5 * (2.0 * std::f32::consts::PI).ln();
    let lp0 = -0.125 - half_ln_2pi;
    let lp1 = -0.5 - half_ln_2pi;
    let b = Batch {
        obs: t2(&[0.0, 0.0], [2, 1]),
        priv_obs: t2(&[0.0, 0.0], [2, 1]),
        actions: t2(&[0.5, -1.0], [2, 1]),
        old_log_prob: t2(&[lp0 - 0.1, lp1 - 0.5], [2, 1]),
        old_mu: t2(&[0.1, 0.0], [2, 1]),
        old_sigma: t2(&[1.0, 2.0], [2, 1]),
        advantages: t2(&[1.0, 2.0], [2, 1]),
        returns: t2(&[2.0, 0.0], [2, 1]),
        old_values: t2(&[0.5, 0.5], [2, 1]),
    };
    let cfg = PpoConfig::default();
    assert_eq!((cfg.clip_param, cfg.value_loss_coef, cfg.entropy_coef), (0.2, 1.0, 0.005));
    let l = ppo_losses(t2(&[0.0, 0.0], [2, 1]), t2(&[0.0], [1, 1]), t2(&[1.0, 0.0], [2, 1]), &b, &cfg);
    let row = to_host(l.row).unwrap(); // [total, surrogate, value, entropy, KL]
    assert_eq!(to_host(l.root).unwrap(), row[..1], "the gradient starts from the total");
    let close = |name: &str, got: f32, want: f64| assert!((got as f64 - want).abs() < 2e-5, "{name}: {got} vs {want}");
    close("surrogate", row[1], -1.752585);
    close("value", row[2], 0.89);
    close("entropy", row[3], 1.418939);
    close("total", row[0], -0.869680);
    close("kl", row[4], 0.405926);
}

/// PPO's loss as one operation (`learn::kernels::ppo_loss`: two kernels each way on burn's wgpu
/// runtime, tensor ops elsewhere) against `ppo_losses`' tensor ops differentiated by burn, on 600
/// rows (three workgroups of the kernels, the last one partial) of 5 actions whose ratios fall on
/// both sides of the clip range, advantages of both signs, with and without the clipped value
/// loss: `[total, surrogate, value, entropy, KL]` and the gradients of L = w · total in μ, log σ
/// and V agree to float rounding, on the CPU and on the GPU, where each pass is two kernels (the
/// fused loss's gradient starts from its whole `[1, 5]` output, of which only the total counts).
#[test]
fn the_fused_ppo_loss_matches_its_tensor_ops_and_their_gradient() {
    use dextrain::gpu_counts::{Event, GpuCounts};
    use dextrain::learn::kernels::ppo_loss::{LossCoefs, loss_columns, ppo_loss_fused};
    use dextrain::learn::ppo::Losses;
    let (rows, a) = (600usize, 5usize);
    let mut rng = Rng::new(9, 4);
    let mut draw = |n: usize, scale: f64| (0..n).map(|_| (rng.normal() * scale) as f32).collect::<Vec<f32>>();
    let (mu, old_mu, log_std, old_sigma_log) = (draw(rows * a, 1.0), draw(rows * a, 1.0), draw(a, 0.3), draw(a, 0.3));
    let old_sigma: Vec<f32> = old_sigma_log.iter().map(|l| l.exp()).collect();
    let noise = draw(rows * a, 1.0);
    let actions: Vec<f32> = (0..rows * a).map(|i| old_mu[i] + old_sigma[i % a] * noise[i]).collect();
    // log π_old spread around the current policy's log π: ratios from ~0.2 to ~5
    let log_prob = |r: usize| -> f32 {
        (0..a).map(|k| -0.5 * ((actions[r * a + k] - mu[r * a + k]) / log_std[k].exp()).powi(2) - log_std[k]).sum::<f32>() - 0.5 * a as f32 * (2.0 * std::f32::consts::PI).ln()
    };
    let offsets = draw(rows, 0.8);
    let old_log_prob: Vec<f32> = (0..rows).map(|r| log_prob(r) + offsets[r]).collect();
    let (advantages, returns, v, old_values) = (draw(rows, 1.0), draw(rows, 2.0), draw(rows, 2.0), draw(rows, 2.0));
    let w = 1.7; // ∂L/∂total
    let ratios: Vec<f32> = (0..rows).map(|r| (-offsets[r]).exp()).collect();
    assert!(ratios.iter().any(|&x| x < 0.8) && ratios.iter().any(|&x| x > 1.2) && ratios.iter().any(|&x| (0.8..1.2).contains(&x)), "ratios on every side of the clip range");
    // (out [1, 5], ∂L/∂μ, ∂L/∂log σ, ∂L/∂V)
    let run = |device: &Device, fused: bool, clipped_value: bool| -> [Vec<f32>; 4] {
        let t = |v: &[f32], shape: [usize; 2]| to_tensor(v.to_vec(), shape, device);
        let (m, ls, vv) = (t(&mu, [rows, a]).require_grad(), t(&log_std, [1, a]).require_grad(), t(&v, [rows, 1]).require_grad());
        let cfg = PpoConfig { clipped_value_loss: clipped_value, ..PpoConfig::default() };
        let coefs = LossCoefs { clip: cfg.clip_param as f64, value_coef: cfg.value_loss_coef as f64, entropy_coef: cfg.entropy_coef as f64, clipped_value };
        let losses = if fused {
            let columns = loss_columns(t(&actions, [rows, a]), t(&old_mu, [rows, a]), t(&old_log_prob, [rows, 1]), t(&advantages, [rows, 1]), t(&returns, [rows, 1]), t(&old_values, [rows, 1]));
            Losses::from_fused(ppo_loss_fused(m.clone(), ls.clone(), vv.clone(), t(&old_sigma, [1, a]), columns, coefs))
        } else {
            let b = Batch {
                obs: t(&vec![0.0; rows], [rows, 1]),
                priv_obs: t(&vec![0.0; rows], [rows, 1]),
                actions: t(&actions, [rows, a]),
                old_log_prob: t(&old_log_prob, [rows, 1]),
                old_mu: t(&old_mu, [rows, a]),
                old_sigma: t(&old_sigma, [1, a]),
                advantages: t(&advantages, [rows, 1]),
                returns: t(&returns, [rows, 1]),
                old_values: t(&old_values, [rows, 1]),
            };
            ppo_losses(m.clone(), ls.clone(), vv.clone(), &b, &cfg)
        };
        let grads = losses.root.mul_scalar(w).backward();
        let grad = |x: &Tensor<2>| to_host(x.grad(&grads).expect("a gradient")).unwrap();
        [to_host(losses.row).unwrap(), grad(&m), grad(&ls), grad(&vv)]
    };
    let close = |name: &str, got: &[f32], want: &[f32]| {
        assert_eq!(got.len(), want.len(), "{name}");
        for (i, (g, w)) in got.iter().zip(want).enumerate() {
            assert!((g - w).abs() <= 2e-4 * (1.0 + w.abs()), "{name}[{i}]: {g} vs {w}");
        }
    };
    let names = ["out", "∂μ", "∂log σ", "∂V"];
    let gpu = crate::common::wgpu_learner("the_fused_ppo_loss_matches_its_tensor_ops_and_their_gradient");
    for clipped_value in [false, true] {
        let reference = run(&cpu(), false, clipped_value);
        assert!(reference[1].iter().any(|g| g.abs() > 1e-4) && reference[3].iter().any(|g| g.abs() > 1e-3), "the gradients must not vanish");
        for (k, got) in run(&cpu(), true, clipped_value).iter().enumerate() {
            close(&format!("cpu {} (clipped value {clipped_value})", names[k]), got, &reference[k]);
        }
        let Some((_ctx, device)) = &gpu else { continue };
        let before = GpuCounts::now();
        let fused_gpu = run(device, true, clipped_value);
        let counts = GpuCounts::now().since(&before);
        for (k, got) in fused_gpu.iter().enumerate() {
            close(&format!("gpu {} (clipped value {clipped_value})", names[k]), got, &reference[k]);
        }
        let kernels = |name: &str| counts.total_from(Event::Kernel, name);
        assert_eq!(
            [kernels("dextrain:ppo_loss_rows"), kernels("dextrain:ppo_loss_finish"), kernels("dextrain:ppo_loss_backward"), kernels("dextrain:ppo_loss_backward_finish")],
            [1, 1, 2, 1], // (the backward's name is a prefix of its finish's)
            "two kernels each way: {counts:?}"
        );
    }
}

#[test]
fn gradients_are_clipped_to_a_global_norm_and_adam_takes_a_signed_first_step() {
    let dev = cpu();
    // loss = Σ p ⊙ c over two parameters: ∂loss/∂p = c; c = (3, 4) and (0) → ‖g‖ = 5
    let p = vec![to_tensor(vec![1.0, 1.0], [1, 2], &dev).require_grad(), to_tensor(vec![2.0], [1, 1], &dev).require_grad()];
    let c0 = to_tensor(vec![3.0, 4.0], [1, 2], &dev);
    let c1 = to_tensor(vec![0.0], [1, 1], &dev);
    let loss = (p[0].clone() * c0).sum() + (p[1].clone() * c1).sum();
    let grads = loss.backward();
    let (g, norm) = clipped_grads(&p, &grads, 0.5).unwrap();
    assert!((to_host(norm).unwrap()[0] - 5.0).abs() < 1e-5);
    let g0 = to_host(g[0].clone()).unwrap();
    assert!((g0[0] - 0.3).abs() < 1e-6 && (g0[1] - 0.4).abs() < 1e-6, "clipped to norm 0.5: {g0:?}");
    // a norm below the limit is untouched
    let (g_big, _) = clipped_grads(&p, &grads, 100.0).unwrap();
    let gb = to_host(g_big[0].clone()).unwrap();
    assert!((gb[0] - 3.0).abs() < 1e-5 && (gb[1] - 4.0).abs() < 1e-5);
    // Adam's first step: m̂ = g, v̂ = g² → Δ = −lr g / (|g| + ε) = −lr sign(g) (0 where g = 0)
    let mut adam = Adam::new(&[[1, 2], [1, 1]], &dev);
    let new = adam.step(&p, g, 0.01);
    let p0 = to_host(new[0].clone().inner()).unwrap();
    let p1 = to_host(new[1].clone().inner()).unwrap();
    assert!((p0[0] - 0.99).abs() < 1e-6 && (p0[1] - 0.99).abs() < 1e-6, "{p0:?}");
    assert_eq!(p1[0], 2.0);
    assert!(new[0].is_require_grad());
}

/// A 2-D point to steer onto a target: obs = target − x, x += 0.1·clip(a), reward = −‖target − x‖,
/// 20-step episodes from random starts. A policy that ignores the observation keeps about
/// −0.8 per step; steering straight at the target averages about −0.3.
pub(crate) struct PointTask {
    pub(crate) x: Vec<[f32; 2]>,
    pub(crate) target: Vec<[f32; 2]>,
    pub(crate) t: Vec<u32>,
    pub(crate) rng: Rng,
    /// [N, 2] each env's observation before its last reset (its ended episode's final one).
    pub(crate) final_obs: Vec<f32>,
}

impl PointTask {
    pub(crate) fn new(n: usize) -> PointTask {
        let mut p = PointTask { x: vec![[0.0; 2]; n], target: vec![[0.0; 2]; n], t: vec![0; n], rng: Rng::new(3, 3), final_obs: vec![0.0; 2 * n] };
        for i in 0..n {
            p.reset(i);
        }
        p
    }
    fn reset(&mut self, i: usize) {
        let mut u = || (2.0 * self.rng.uniform() - 1.0) as f32;
        self.x[i] = [u(), u()];
        self.target[i] = [u(), u()];
        self.t[i] = 0;
    }
    pub(crate) fn obs(&self) -> Vec<f32> {
        self.x.iter().zip(&self.target).flat_map(|(x, g)| [g[0] - x[0], g[1] - x[1]]).collect()
    }
    pub(crate) fn step(&mut self, a: &[f32]) -> (Vec<f32>, Vec<bool>) {
        let n = self.x.len();
        let mut r = vec![0.0; n];
        let mut timeout = vec![false; n];
        for i in 0..n {
            for k in 0..2 {
                self.x[i][k] += 0.1 * a[2 * i + k].clamp(-1.0, 1.0);
            }
            let d = ((self.target[i][0] - self.x[i][0]).powi(2) + (self.target[i][1] - self.x[i][1]).powi(2)).sqrt();
            r[i] = -d;
            self.t[i] += 1;
            if self.t[i] >= 20 {
                timeout[i] = true;
                self.final_obs[2 * i..2 * i + 2].copy_from_slice(&[self.target[i][0] - self.x[i][0], self.target[i][1] - self.x[i][1]]);
                self.reset(i);
            }
        }
        (r, timeout)
    }
}

#[test]
fn ppo_learns_a_tiny_steering_task_in_seconds() {
    let n = 64;
    let steps = 20;
    let cfg = PpoConfig { learning_rate: 3e-3, ..PpoConfig::default() };
    let pol = PolicyConfig { actor_hidden: vec![32, 32], critic_hidden: vec![32, 32], init_std: 0.6, ..PolicyConfig::default() };
    let dims = Dims { obs: 2, priv_obs: 2, act: 2 };
    let mut ppo = Ppo::new(dims, n, steps, &cfg, &pol, &[], cpu(), 11).unwrap();
    let mut env = PointTask::new(n);
    let mut obs = env.obs();
    let no_term = vec![false; n];
    let mut first = None;
    let mut last = 0.0;
    for _it in 0..40 {
        let mut sum = 0.0;
        for _ in 0..steps {
            let a = ppo.act(&obs, &obs).unwrap();
            let (r, to) = env.step(&a);
            sum += r.iter().sum::<f32>() as f64;
            ppo.process_step(&r, &no_term, &to);
            obs = env.obs();
        }
        let mean = sum / (n * steps) as f64;
        first.get_or_insert(mean);
        last = mean;
        let stats = ppo.update(&obs).unwrap();
        assert!(stats.value.is_finite() && stats.surrogate.is_finite() && stats.kl.is_finite());
    }
    let first = first.unwrap();
    eprintln!("tiny task: mean reward per step {first:.3} (first iteration) -> {last:.3} (last)");
    assert!(first < -0.6, "the untrained policy should not steer: {first}");
    assert!(last > -0.45, "PPO did not learn to steer: {last}");
}

/// A student network in the exporter's description whose actions are its adaptation module's output
/// φ [B, F] (F = `features`): no normalisation, head = I, actor = [0 | I] over [obs (1 number); z].
fn pass_through_student(adapt: dextrain::export::onnx::Adaptation, step_dim: usize, features: usize, steps: usize) -> dextrain::export::onnx::PolicyNet {
    use dextrain::config::Activation;
    use dextrain::export::onnx::{Dense, Mlp, Normalization, PolicyNet};
    let f = features;
    let eye: Vec<f32> = (0..f * f).map(|k| if k / f == k % f { 1.0 } else { 0.0 }).collect();
    let mut actor_w = vec![0.0f32; f]; // the obs row (one obs component)
    actor_w.extend(&eye);
    PolicyNet::Student {
        obs_norm: Normalization { mean: vec![0.0], denom: vec![1.0] },
        hist_norm: Normalization { mean: vec![0.0; step_dim], denom: vec![1.0; step_dim] },
        adapt,
        head: Dense { weight: eye, bias: vec![0.0; f], inputs: f, outputs: f },
        actor: Mlp::plain(vec![Dense { weight: actor_w, bias: vec![0.0; f], inputs: 1 + f, outputs: f }], Activation::Elu),
        history_len: steps,
    }
}

/// The same small PPO iteration on burn's wgpu backend (on the simulator's kind of device, e.g.
/// lavapipe) and on the CPU backend: the updated parameters agree to float rounding, and so do the
/// policy means of `act_mean` (normalised on the device on the GPU, on the host on the CPU), before
/// and after the statistics change. On the GPU an inference uploads its rows alone while the
/// statistics stand (they stay on the device), and the statistics again once they change; the
/// update gathers each epoch's rows once where every minibatch is then a view of them (its rows'
/// bytes on the device's binding alignment: 64 envs), else each minibatch's (15 envs: a
/// minibatch of 30 rows of 3 observations, 360 bytes, is off any alignment of 16 bytes or more).
#[test]
fn the_wgpu_learner_matches_the_cpu_learner() {
    use dextrain::gpu_counts::{Event, GpuCounts};
    let Some((_ctx, gpu)) = crate::common::wgpu_learner("the_wgpu_learner_matches_the_cpu_learner") else { return };
    let align = to_tensor(vec![0.0], [1, 1], &gpu.clone().inner()).try_into_primitive::<burn::backend::Cube>().unwrap().client.properties().memory.alignment as usize;
    assert!(align <= 256, "a binding alignment of {align} bytes");
    for n in [15, 64] {
        let steps = 4;
        let cfg = PpoConfig { minibatches: 2, epochs: 2, ..PpoConfig::default() };
        let pol = PolicyConfig { actor_hidden: vec![16], critic_hidden: vec![16], ..PolicyConfig::default() };
        let dims = Dims { obs: 3, priv_obs: 4, act: 2 };
        let mut rng = Rng::new(9, 9);
        let obs: Vec<f32> = (0..n * 3).map(|_| rng.normal() as f32).collect();
        let priv_obs: Vec<f32> = (0..n * 4).map(|_| rng.normal() as f32).collect();
        let rewards: Vec<f32> = (0..n).map(|_| rng.normal() as f32).collect();
        let run = |device: Device| {
            let mut ppo = Ppo::new(dims, n, steps, &cfg, &pol, &[], device, 5).unwrap();
            let mut actions = Vec::new();
            for _ in 0..steps {
                actions.push(ppo.act(&obs, &priv_obs).unwrap());
                ppo.process_step(&rewards, &vec![false; n], &vec![false; n]);
            }
            let before = GpuCounts::now();
            let stats = ppo.update(&priv_obs).unwrap();
            let update = GpuCounts::now().since(&before);
            // inferences: the statistics as they stand (twice), then after another batch is merged;
            // the uploads of the last two counted (from burn's `from_data` / as the rows)
            let mut uploads = Vec::new();
            for k in 0..3 {
                if k == 2 {
                    ppo.obs_norm.update(&priv_obs[..n * 3]);
                }
                let before = GpuCounts::now();
                actions.push(ppo.act_mean(&obs, &priv_obs).unwrap());
                let c = GpuCounts::now().since(&before);
                uploads.push((c.total_from(Event::Upload, "burn:from_data"), c.total_from(Event::Upload, "dextrain:host rows")));
            }
            (ppo.net.values().unwrap(), actions, stats, uploads, update)
        };
        let (p_cpu, a_cpu, s_cpu, _, _) = run(cpu());
        let (p_gpu, a_gpu, s_gpu, uploads, update) = run(gpu.clone());
        // the rows of a minibatch (n · steps / 2) in bytes of each gathered tensor (observations 3,
        // the critic's 4, the loss's columns 2 · 2 + 4 wide) on the alignment: one gather per tensor
        // and epoch, the minibatches views (no copy kernel); else one per tensor and minibatch
        let per_epoch = [3, 4, 8].iter().all(|w| (n * steps / 2 * w * 4) % align == 0);
        assert!(per_epoch == (n == 64) || align < 16, "{n} envs at an alignment of {align} bytes: per epoch {per_epoch}");
        let select = |name: &str| update.by_source.iter().filter(|((e, s), _)| *e == Event::Kernel && s.starts_with(name)).map(|(_, c)| *c).sum::<u64>();
        assert_eq!(select("burn:SelectKernel"), if per_epoch { 3 * 2 } else { 3 * 4 }, "{n} envs: gathers of the update: {update:?}");
        assert!(!per_epoch || select("burn:SliceKernel") == 0, "{n} envs: no minibatch copied out of its epoch's rows: {update:?}");
        assert_eq!(uploads[1..], [(0, 1), (1, 1)], "the rows alone while the statistics stand, the statistics again after a merge");
        assert_eq!(a_gpu[steps], a_gpu[steps + 1], "the kept statistics normalise as the uploaded ones did");
        assert!(a_cpu[steps + 2] != a_cpu[steps + 1], "the merge changed the statistics");
        assert_eq!(a_cpu.len(), steps + 3);
        for (x, y) in a_cpu.iter().flatten().zip(a_gpu.iter().flatten()) {
            assert!((x - y).abs() < 1e-4, "sampled actions differ: {x} vs {y}");
        }
        let mut worst = 0.0f32;
        for (x, y) in p_cpu.iter().flatten().zip(p_gpu.iter().flatten()) {
            worst = worst.max((x - y).abs());
        }
        assert!(worst < 1e-4, "parameters after one update differ by {worst}");
        assert!((s_cpu.value - s_gpu.value).abs() < 1e-3 * (1.0 + s_cpu.value.abs()), "{s_cpu:?} vs {s_gpu:?}");
        // the update did change the parameters
        let fresh = Ppo::new(dims, n, steps, &cfg, &pol, &[], cpu(), 5).unwrap().net.values().unwrap();
        assert!(fresh.iter().flatten().zip(p_cpu.iter().flatten()).any(|(a, b)| a != b));
    }
}

/// The device-resident rollouts' parts on the wgpu device (lavapipe in CI) against their host
/// twins: the action noise (shaders/noise.wgsl vs `host_normals`: the same draws, standard normal,
/// a new draw each call) and the normaliser (tensor ops in f32 vs the f64 host statistics, after
/// three batches, and the normalised values).
#[test]
fn device_noise_and_normaliser_match_their_host_twins() {
    use dextrain::learn::noise::{DeviceNoise, host_normals, host_uniforms};
    use dextrain::learn::normalizer::DeviceNormalizer;
    let Some((ctx, gpu)) = crate::common::wgpu_learner("device_noise_and_normaliser_match_their_host_twins") else { return };
    let (rows, cols) = (300, 22);
    let noise = DeviceNoise::new(&ctx, &gpu, rows * cols).unwrap();
    let (d0, d1) = (to_host(noise.normals(7, 3, rows, cols).unwrap()).unwrap(), to_host(noise.normals(7, 4, rows, cols).unwrap()).unwrap());
    let h0 = host_normals(7, 3, rows, cols);
    assert_eq!(d0.len(), rows * cols);
    let worst = d0.iter().zip(&h0).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
    assert!(worst < 1e-4, "device and host noise differ by {worst}");
    let mean = h0.iter().map(|&x| x as f64).sum::<f64>() / h0.len() as f64;
    let var = h0.iter().map(|&x| (x as f64 - mean).powi(2)).sum::<f64>() / h0.len() as f64;
    assert!(mean.abs() < 0.05 && (var - 1.0).abs() < 0.08, "mean {mean}, var {var}");
    assert!(d0.iter().zip(&d1).filter(|(a, b)| a == b).count() < 5, "a new draw gives new numbers");
    assert_ne!(host_normals(8, 3, rows, cols), h0, "another seed gives other numbers");
    // uniform draws (SAC's random actions): the same numbers, in [−1, 1), mean 0 and variance 1/3
    let (du, hu) = (to_host(noise.uniforms(7, 5, 40, 3).unwrap()).unwrap(), host_uniforms(7, 5, 40, 3));
    assert_eq!(du, hu, "device and host uniform draws differ");
    let hu = host_uniforms(7, 5, rows, cols);
    let mean = hu.iter().map(|&x| x as f64).sum::<f64>() / hu.len() as f64;
    let var = hu.iter().map(|&x| (x as f64 - mean).powi(2)).sum::<f64>() / hu.len() as f64;
    assert!(hu.iter().all(|&x| (-1.0..1.0).contains(&x)) && mean.abs() < 0.03 && (var - 1.0 / 3.0).abs() < 0.02, "mean {mean}, var {var}");
    assert!(noise.normals(7, 6, rows + 1, cols).is_err(), "a draw larger than the kernel was made for");
    // a block of consecutive draws (PPO's rollout, SAC's two draws of a gradient step) is the draws
    // one after the other, bit for bit
    let block = to_host(noise.normals_block(7, 3, 2, rows / 2, cols).unwrap()).unwrap();
    let (b0, b1) = (to_host(noise.normals(7, 3, rows / 2, cols).unwrap()).unwrap(), to_host(noise.normals(7, 4, rows / 2, cols).unwrap()).unwrap());
    assert_eq!(block, [b0, b1].concat(), "a block of draws differs from its draws");
    // the normaliser: three batches of 50 rows of 5 components, offset and scaled per component
    let mut rng = Rng::new(3, 3);
    let mut host = Normalizer::new(5);
    let mut dev = DeviceNormalizer::from_host(&host, &gpu);
    let mut last = Vec::new();
    for b in 0..3 {
        let x: Vec<f32> = (0..50 * 5).map(|i| (rng.normal() * (1.0 + (i % 5) as f64) + 10.0 * b as f64) as f32).collect();
        host.update(&x);
        dev.update(&to_tensor(x.clone(), [50, 5], &gpu));
        last = x;
    }
    let back = dev.to_host().unwrap();
    assert_eq!(back.count, host.count);
    for k in 0..5 {
        assert!((back.mean[k] - host.mean[k]).abs() < 1e-4 * (1.0 + host.mean[k].abs()), "mean {k}: {} vs {}", back.mean[k], host.mean[k]);
        assert!((back.m2[k] - host.m2[k]).abs() < 1e-4 * host.m2[k], "m2 {k}: {} vs {}", back.m2[k], host.m2[k]);
    }
    let want = host.normalized(&last, true);
    let got = to_host(dev.normalized(to_tensor(last.clone(), [50, 5], &gpu), true)).unwrap();
    let worst = want.iter().zip(&got).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
    assert!(worst < 1e-4, "normalised values differ by {worst}");
}

/// The fused ELU (`learn::kernels::elu`): on the CPU (its vectorised exp) and on the wgpu device (tensor
/// ops), the values and the gradient match an f64 reference over [−100, 10] — large negative
/// inputs at −1, 0 and tiny inputs included — on a tensor shared with another (copy on write) and
/// on a transposed one.
#[test]
fn fused_elu_and_its_gradient_match_the_reference() {
    use dextrain::learn::kernels::elu::elu;
    let xs: Vec<f32> = (0..40_000).map(|i| -100.0 + 110.0 * i as f32 / 40_000.0).chain([0.0, -1e-7, 1e-7, -87.5, -88.0, -1e30, 3.0e38]).collect();
    let n = xs.len();
    let check = |device: Device, what: &str| {
        let x = to_tensor(xs.clone(), [1, n], &device).require_grad();
        let kept = x.clone(); // shared storage: the ELU must not write into it
        let y = elu(x.clone());
        let w: Vec<f32> = (0..n).map(|i| 1.0 + (i % 7) as f32).collect();
        let grads = (y.clone() * to_tensor(w.clone(), [1, n], &device)).sum().backward();
        let (y, g) = (to_host(y.inner()).unwrap(), to_host(x.grad(&grads).unwrap()).unwrap());
        assert_eq!(to_host(kept.inner()).unwrap(), xs, "{what}: the input changed");
        for i in 0..n {
            let v = xs[i] as f64;
            let want = if v > 0.0 { v } else { v.exp() - 1.0 };
            let dwant = w[i] as f64 * if v > 0.0 { 1.0 } else { v.exp() };
            // 2 ulp of eˣ, absolute below 1 (eˣ − 1 cancels there), relative above
            assert!((y[i] as f64 - want).abs() <= 2.4e-7 * want.abs().max(1.0), "{what}: ELU({v}) = {} vs {want}", y[i]);
            assert!((g[i] as f64 - dwant).abs() <= 2.4e-7 * dwant.abs().max(w[i] as f64), "{what}: ELU'({v}) · {} = {} vs {dwant}", w[i], g[i]);
        }
        // a transposed (non-contiguous) input
        let t = to_tensor(xs[..40_000].to_vec(), [200, 200], &device);
        let yt = to_host(elu(t.clone().transpose())).unwrap();
        let want = to_host(elu(t).transpose().reshape([200 * 200])).unwrap();
        assert_eq!(yt, want, "{what}: a transposed input");
    };
    check(cpu(), "cpu");
    // every CPU kernel, whichever the op picked: AVX-512, AVX2 + FMA (what an AVX2-only CPU runs)
    // and the plain loop; a kernel this CPU lacks runs the next narrower one
    use dextrain::learn::kernels::elu::{elu_backward_slice_with, elu_slice_with};
    use dextrain::learn::kernels::isa::Isa;
    for isa in [Isa::Avx512, Isa::Avx2, Isa::Scalar] {
        let mut y = xs.clone();
        elu_slice_with(isa, &mut y);
        let mut g: Vec<f32> = (0..n).map(|i| 1.0 + (i % 7) as f32).collect();
        elu_backward_slice_with(isa, &y, &mut g);
        for i in 0..n {
            let v = xs[i] as f64;
            let want = if v > 0.0 { v } else { v.exp() - 1.0 };
            let w = 1.0 + (i % 7) as f64;
            let dwant = w * if v > 0.0 { 1.0 } else { v.exp() };
            assert!((y[i] as f64 - want).abs() <= 2.4e-7 * want.abs().max(1.0), "{isa:?}: ELU({v}) = {} vs {want}", y[i]);
            assert!((g[i] as f64 - dwant).abs() <= 2.4e-7 * dwant.abs().max(w), "{isa:?}: ELU'({v}) · {w} = {} vs {dwant}", g[i]);
        }
    }
    if let Some((_ctx, gpu)) = crate::common::wgpu_learner("fused_elu_and_its_gradient_match_the_reference") {
        check(gpu.clone(), "wgpu");
        // the forward kernel of ours gives the tensor ops it replaced bit for bit:
        // clamp(x, 0, ∞) + (exp(clamp(x, −∞, 0)) − 1) (the inputs padded to whole 16-byte words:
        // the kernel takes tensors whose memory is exactly theirs)
        let mut xs4 = xs.clone();
        xs4.resize(n.next_multiple_of(4), -2.5);
        let x = to_tensor(xs4.clone(), [1, xs4.len()], &gpu);
        let ops = x.clone().clamp(0.0, f32::MAX) + x.clone().clamp(-f32::MAX, 0.0).exp().sub_scalar(1.0);
        let before = dextrain::gpu_counts::GpuCounts::now();
        let ours = to_host(elu(x)).unwrap();
        let launched = dextrain::gpu_counts::GpuCounts::now().since(&before).total_from(dextrain::gpu_counts::Event::Kernel, "dextrain:elu_forward");
        assert_eq!(launched, 1, "wgpu: ELU's forward pass is one kernel of ours");
        let theirs = to_host(ops).unwrap();
        for i in 0..xs4.len() {
            assert_eq!(ours[i].to_bits(), theirs[i].to_bits(), "wgpu: ELU({}) = {} against the tensor ops' {}", xs4[i], ours[i], theirs[i]);
        }
    }
}

/// The fused dense layer (`learn::kernels::affine`: on the CPU gemm straight into the output, the bias
/// rows first; on the wgpu device tensor ops): `y = x W + b` and the gradients of x, W and b match
/// an f64 reference, with x given transposed (non-contiguous) and W shared with another tensor
/// (it must not change), at sizes where gemm splits the work over threads; an untracked x gets no
/// gradient while W and b still get theirs.
#[test]
fn fused_affine_and_its_gradients_match_the_reference() {
    use dextrain::learn::kernels::affine::fused_affine;
    let (b, i, o) = (1030, 97, 83); // 8.3 M multiply-adds: over gemm's threshold for threads
    let mut rng = Rng::new(5, 6);
    let mut normal = |n: usize| -> Vec<f32> { (0..n).map(|_| rng.normal() as f32).collect() };
    let (xt, w, bias, g) = (normal(i * b), normal(i * o), normal(o), normal(b * o)); // x given as xᵀ [in, B]
    let x = |r: usize, c: usize| xt[c * b + r] as f64; // x[r, c]
    let mut want_y = vec![0.0f64; b * o];
    let (mut want_dx, mut want_dw, mut want_db) = (vec![0.0f64; b * i], vec![0.0f64; i * o], vec![0.0f64; o]);
    for r in 0..b {
        for c in 0..o {
            let gv = g[r * o + c] as f64;
            want_db[c] += gv; // ∂b = 1ᵀ g
            want_y[r * o + c] = bias[c] as f64 + (0..i).map(|k| x(r, k) * w[k * o + c] as f64).sum::<f64>();
            for k in 0..i {
                want_dx[r * i + k] += gv * w[k * o + c] as f64; // ∂x = g Wᵀ
                want_dw[k * o + c] += x(r, k) * gv; // ∂W = xᵀ g
            }
        }
    }
    // each output sums ~100 (y, ∂x) or ~1,000 (∂W, ∂b) products of N(0, 1) values
    let close = |got: &[f32], want: &[f64], tol: f64, what: &str| {
        assert_eq!(got.len(), want.len(), "{what}: length");
        let worst = got.iter().zip(want).map(|(a, b)| (*a as f64 - b).abs()).fold(0.0, f64::max);
        assert!(worst < tol, "{what}: off by {worst}");
    };
    let check = |device: Device, what: &str| {
        let xin = to_tensor(xt.clone(), [i, b], &device).transpose().require_grad(); // [B, in], strided
        let wt = to_tensor(w.clone(), [i, o], &device).require_grad();
        let w_kept = wt.clone(); // shared storage: must not be written
        let bt = to_tensor(bias.clone(), [1, o], &device).require_grad();
        let y = fused_affine(xin.clone(), wt.clone(), bt.clone());
        let grads = (y.clone() * to_tensor(g.clone(), [b, o], &device)).sum().backward();
        close(&to_host(y.inner()).unwrap(), &want_y, 1e-3, &format!("{what}: y"));
        close(&to_host(xin.grad(&grads).unwrap()).unwrap(), &want_dx, 1e-3, &format!("{what}: ∂x"));
        close(&to_host(wt.grad(&grads).unwrap()).unwrap(), &want_dw, 1e-2, &format!("{what}: ∂W"));
        close(&to_host(bt.grad(&grads).unwrap()).unwrap(), &want_db, 1e-2, &format!("{what}: ∂b"));
        assert_eq!(to_host(w_kept.inner()).unwrap(), w, "{what}: W changed");
        // an untracked input (the first layer's observations): W and b still get their gradients
        let xin = to_tensor(xt.clone(), [i, b], &device).transpose();
        let wt = to_tensor(w.clone(), [i, o], &device).require_grad();
        let bt = to_tensor(bias.clone(), [1, o], &device).require_grad();
        let grads = (fused_affine(xin.clone(), wt.clone(), bt.clone()) * to_tensor(g.clone(), [b, o], &device)).sum().backward();
        close(&to_host(wt.grad(&grads).unwrap()).unwrap(), &want_dw, 1e-2, &format!("{what}: ∂W, x untracked"));
        close(&to_host(bt.grad(&grads).unwrap()).unwrap(), &want_db, 1e-2, &format!("{what}: ∂b, x untracked"));
    };
    check(cpu(), "cpu");
    if let Some((_ctx, gpu)) = crate::common::wgpu_learner("fused_affine_and_its_gradients_match_the_reference") {
        check(gpu, "wgpu");
    }
}

/// dextrain's own AVX2 matrix product (`learn::kernels::sgemm`, what the dense layers' `x W` and `g Wᵀ` run
/// where the learner's kernels are AVX2): against an f64 reference, over shapes that leave partial
/// tiles (rows not a multiple of 6, columns not a multiple of 16, fewer than 16 columns), depths
/// over one block (256) and over one packed slab of B, B given transposed (strided), A rows with a
/// stride above their length, accumulation onto C, and split over the rayon pool.
#[test]
fn own_avx2_product_matches_the_reference() {
    use dextrain::learn::kernels::isa::{Isa, detected_isa};
    use dextrain::learn::kernels::sgemm::matmul_slices;
    if detected_isa() < Isa::Avx2 {
        eprintln!("own_avx2_product_matches_the_reference: not run, this CPU has no AVX2 + FMA (the kernel never runs here)");
        return;
    }
    let mut rng = Rng::new(9, 10);
    // (m, n, k, B transposed, accumulate, parallel)
    let cases = [
        (13, 37, 5, false, false, false),
        (250, 512, 96, false, false, true),
        (97, 22, 300, true, true, true),
        (6, 16, 256, false, true, false),
        (7, 5, 16_500, false, false, false), // one panel: a slab of B is 16,384 deep
        (1, 1, 1, true, false, false),
        (40, 33, 0, false, false, false),
    ];
    for (m, n, k, transposed, accumulate, parallel) in cases {
        let a_row = k + 3; // A rows padded: the stride is not the width
        let a: Vec<f32> = (0..m * a_row).map(|_| rng.normal() as f32).collect();
        let b: Vec<f32> = (0..k * n).map(|_| rng.normal() as f32).collect();
        let (b_row, b_col) = if transposed { (1, k) } else { (n, 1) }; // B(p, j) = b[p·b_row + j·b_col]
        let c0: Vec<f32> = (0..m * n).map(|_| rng.normal() as f32).collect();
        let mut c = if accumulate { c0.clone() } else { vec![f32::NAN; m * n] };
        matmul_slices(m, n, k, &a, a_row, &b, b_row, b_col, &mut c, accumulate, parallel).unwrap();
        for i in 0..m {
            for j in 0..n {
                let dot: f64 = (0..k).map(|p| a[i * a_row + p] as f64 * b[p * b_row + j * b_col] as f64).sum();
                let want = dot + if accumulate { c0[i * n + j] as f64 } else { 0.0 };
                // k products of N(0, 1) values summed in f32: error ~ 1e-7 · k
                let tol = 1e-5 * (k as f64).max(1.0);
                assert!((c[i * n + j] as f64 - want).abs() < tol, "[{m}, {k}]·[{k}, {n}] at ({i}, {j}): {} vs {want}", c[i * n + j]);
            }
        }
    }
    // a slice too short for the shape is an error, not a read out of bounds
    let mut c = vec![0.0; 4];
    assert!(matmul_slices(2, 2, 3, &[0.0; 5], 3, &[0.0; 6], 2, 1, &mut c, false, false).is_err());
}

/// An MLP fed its input as two column blocks (`forward_split_input`, SAC's actor update through the
/// critics) gives the values of the concatenated input's forward, and the tracked block's gradient
/// and the first layer's weight gradient are the concatenated input's — with and without LayerNorm,
/// on the CPU and on the wgpu device.
#[test]
fn split_input_forward_matches_the_concatenated_input() {
    use dextrain::learn::nets::{Activation, MlpLayout};
    let mut devices = vec![("cpu", cpu())];
    let gpu = crate::common::wgpu_learner("split_input_forward_matches_the_concatenated_input");
    if let Some((_, d)) = &gpu {
        devices.push(("wgpu", d.clone()));
    }
    for (what, device) in devices {
        let mut rng = Rng::new(11, 12);
        let (b, head, tail) = (37, 13, 5);
        for layer_norm in [false, true] {
            let layout = MlpLayout { input: head + tail, hidden: vec![24, 16], output: 3, layer_norm };
            let values = layout.init(&mut rng);
            let tracked = || -> Vec<Tensor<2>> { values.iter().zip(layout.shapes()).map(|(v, s)| to_tensor(v.clone(), s, &device).require_grad()).collect() };
            let xh = to_tensor((0..b * head).map(|_| rng.normal() as f32).collect(), [b, head], &device);
            let xt: Vec<f32> = (0..b * tail).map(|_| rng.normal() as f32).collect();
            let g = to_tensor((0..b * 3).map(|_| rng.normal() as f32).collect(), [b, 3], &device);
            // the concatenated input, tracked as a whole
            let params = tracked();
            let cat = Tensor::cat(vec![xh.clone(), to_tensor(xt.clone(), [b, tail], &device)], 1).require_grad();
            let y_cat = layout.forward(&params, cat.clone(), Activation::Elu);
            let grads = (y_cat.clone() * g.clone()).sum().backward();
            let d_cat = to_host(cat.grad(&grads).unwrap()).unwrap(); // [b, head + tail]
            let dw_cat = to_host(params[0].grad(&grads).unwrap()).unwrap(); // [head + tail, 24]
            // the two blocks, the tail tracked
            let params = tracked();
            let t = to_tensor(xt, [b, tail], &device).require_grad();
            let y = layout.forward_split_input(&params, xh, t.clone(), Activation::Elu);
            let grads = (y.clone() * g).sum().backward();
            let d_t = to_host(t.grad(&grads).unwrap()).unwrap(); // [b, tail]
            let dw = to_host(params[0].grad(&grads).unwrap()).unwrap();
            let (y, y_cat) = (to_host(y.inner()).unwrap(), to_host(y_cat.inner()).unwrap());
            let worst = y.iter().zip(&y_cat).map(|(a, c)| (a - c).abs()).fold(0.0f32, f32::max);
            assert!(worst < 1e-5, "{what}, layer_norm {layer_norm}: outputs differ by {worst}");
            for r in 0..b {
                for c in 0..tail {
                    let (got, want) = (d_t[r * tail + c], d_cat[r * (head + tail) + head + c]);
                    assert!((got - want).abs() < 1e-5, "{what}, layer_norm {layer_norm}: ∂tail[{r}, {c}] = {got} vs {want}");
                }
            }
            let worst_w = dw.iter().zip(&dw_cat).map(|(a, c)| (a - c).abs() / c.abs().max(1.0)).fold(0.0f32, f32::max);
            assert!(worst_w < 1e-5, "{what}, layer_norm {layer_norm}: the first layer's ∂W differs by {worst_w}");
            assert!(dw[head * 24..].iter().any(|v| v.abs() > 1e-3), "{what}: the tail's rows of ∂W are a real gradient");
        }
    }
}

/// The fused LayerNorm (`learn::kernels::layer_norm`: one pass per row on the CPU, a kernel of ours each
/// way on the wgpu device): y and the gradients of h, gain and shift match an f64 reference — rows of every scale,
/// a constant row (σ² = 0) and widths that are not a multiple of the CPU's 16 lanes — and the input
/// it normalises is left as it was.
#[test]
fn fused_layer_norm_and_its_gradients_match_the_reference() {
    use dextrain::learn::kernels::layer_norm::{LAYER_NORM_EPS, layer_norm};
    let (b, n) = (700, 37); // over the CPU's 256 rows per task: several tasks and a reduction
    let mut rng = Rng::new(7, 8);
    let mut h: Vec<f32> = (0..b * n).map(|i| (rng.normal() * (1.0 + (i / n % 5) as f64 * 10.0) + 3.0) as f32).collect();
    h[..n].iter_mut().for_each(|v| *v = 2.5); // a constant row
    let gain: Vec<f32> = (0..n).map(|_| 1.0 + 0.5 * rng.normal() as f32).collect();
    let shift: Vec<f32> = (0..n).map(|_| rng.normal() as f32).collect();
    let dy: Vec<f32> = (0..b * n).map(|_| rng.normal() as f32).collect();
    // the f64 reference
    let (mut want_y, mut want_dh, mut want_dg, mut want_ds) = (vec![0.0f64; b * n], vec![0.0f64; b * n], vec![0.0f64; n], vec![0.0f64; n]);
    for r in 0..b {
        let row: Vec<f64> = h[r * n..(r + 1) * n].iter().map(|&v| v as f64).collect();
        let mean = row.iter().sum::<f64>() / n as f64;
        let var = row.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n as f64;
        let rstd = 1.0 / (var + LAYER_NORM_EPS as f64).sqrt();
        let nh: Vec<f64> = row.iter().map(|v| (v - mean) * rstd).collect();
        let d: Vec<f64> = (0..n).map(|j| dy[r * n + j] as f64 * gain[j] as f64).collect();
        let (m1, m2) = (d.iter().sum::<f64>() / n as f64, d.iter().zip(&nh).map(|(a, b)| a * b).sum::<f64>() / n as f64);
        for j in 0..n {
            want_y[r * n + j] = nh[j] * gain[j] as f64 + shift[j] as f64;
            want_dh[r * n + j] = rstd * (d[j] - m1 - nh[j] * m2);
            want_dg[j] += dy[r * n + j] as f64 * nh[j];
            want_ds[j] += dy[r * n + j] as f64;
        }
    }
    let close = |got: &[f32], want: &[f64], tol: f64, what: &str| {
        assert_eq!(got.len(), want.len(), "{what}: length");
        let worst = got.iter().zip(want).map(|(a, b)| (*a as f64 - b).abs() / b.abs().max(1.0)).fold(0.0, f64::max);
        assert!(worst < tol, "{what}: off by {worst}");
    };
    let check = |device: Device, what: &str| {
        let ht = to_tensor(h.clone(), [b, n], &device).require_grad();
        let kept = ht.clone();
        let gt = to_tensor(gain.clone(), [1, n], &device).require_grad();
        let st = to_tensor(shift.clone(), [1, n], &device).require_grad();
        let y = layer_norm(ht.clone(), gt.clone(), st.clone());
        let grads = (y.clone() * to_tensor(dy.clone(), [b, n], &device)).sum().backward();
        close(&to_host(y.inner()).unwrap(), &want_y, 1e-5, &format!("{what}: y"));
        // a constant row: ∂h = r (d − mean d) with r = 1/√ε ≈ 316, so its rounding is 316× larger
        close(&to_host(ht.grad(&grads).unwrap()).unwrap(), &want_dh, 2e-3, &format!("{what}: ∂h"));
        close(&to_host(gt.grad(&grads).unwrap()).unwrap(), &want_dg, 1e-4, &format!("{what}: ∂gain"));
        close(&to_host(st.grad(&grads).unwrap()).unwrap(), &want_ds, 1e-4, &format!("{what}: ∂shift"));
        assert_eq!(to_host(kept.inner()).unwrap(), h, "{what}: the input changed");
    };
    check(cpu(), "cpu");
    if let Some((_ctx, gpu)) = crate::common::wgpu_learner("fused_layer_norm_and_its_gradients_match_the_reference") {
        use dextrain::gpu_counts::{Event, GpuCounts};
        let before = GpuCounts::now();
        check(gpu, "wgpu");
        // on the GPU, forward and backward are one kernel of ours each (shaders/layer_norm*.wgsl)
        let counts = GpuCounts::now().since(&before);
        assert_eq!(counts.total_from(Event::Kernel, "dextrain:layer_norm"), 2, "forward and backward: {counts:?}");
        assert_eq!(counts.total_from(Event::Kernel, "dextrain:layer_norm_backward"), 1, "{counts:?}");
    }
}

/// LayerNorm then ELU as one operation (`layer_norm::layer_norm_elu`, a SAC critic's hidden layer
/// on a GPU): on the wgpu device the value and the gradients of h, gain and shift are those of
/// `layer_norm` followed by ELU's own operation bit for bit, in two kernels of ours and one
/// column sum for both parameters where the separate operations launched four and two; with gain
/// and shift untracked (SAC's actor update through frozen critics) no column sum at all; rows of
/// a width that falls off the binding alignment (37) and one that does not (64). On the CPU the
/// operation's tensor ops agree with the separate operations to rounding.
#[test]
fn layer_norm_then_elu_is_one_operation_with_the_same_bits() {
    use dextrain::gpu_counts::{Event, GpuCounts};
    use dextrain::learn::kernels::elu::elu;
    use dextrain::learn::kernels::layer_norm::{layer_norm, layer_norm_elu};
    let gpu = crate::common::wgpu_learner("layer_norm_then_elu_is_one_operation_with_the_same_bits").map(|(_ctx, d)| d);
    for n in [37usize, 64] {
        let b = 300;
        let mut rng = Rng::new(11, n as u64);
        let h: Vec<f32> = (0..b * n).map(|_| (rng.normal() * 2.0 + 0.3) as f32).collect();
        let gain: Vec<f32> = (0..n).map(|_| 1.0 + 0.5 * rng.normal() as f32).collect();
        let shift: Vec<f32> = (0..n).map(|_| 0.5 * rng.normal() as f32).collect();
        let dz: Vec<f32> = (0..b * n).map(|_| rng.normal() as f32).collect();
        // (z, ∂h, ∂gain, ∂shift) and the counts, fused or not, with gain and shift tracked or not
        let run = |device: &Device, fused: bool, params: bool| {
            let ht = to_tensor(h.clone(), [b, n], device).require_grad();
            let (gt, st) = (to_tensor(gain.clone(), [1, n], device), to_tensor(shift.clone(), [1, n], device));
            let (gt, st) = if params { (gt.require_grad(), st.require_grad()) } else { (gt, st) };
            let before = GpuCounts::now();
            let z = if fused { layer_norm_elu(ht.clone(), gt.clone(), st.clone()) } else { elu(layer_norm(ht.clone(), gt.clone(), st.clone())) };
            let grads = (z.clone() * to_tensor(dz.clone(), [b, n], device)).sum().backward();
            let dh = to_host(ht.grad(&grads).unwrap()).unwrap();
            let counts = GpuCounts::now().since(&before);
            let pg = params.then(|| [to_host(gt.grad(&grads).unwrap()).unwrap(), to_host(st.grad(&grads).unwrap()).unwrap()]);
            (to_host(z.inner()).unwrap(), dh, pg, counts)
        };
        let (zc, dhc, pc, _) = run(&cpu(), true, true);
        let (zs, dhs, ps, _) = run(&cpu(), false, true);
        let worst = |a: &[f32], b: &[f32]| a.iter().zip(b).map(|(u, v)| (u - v).abs() / v.abs().max(1.0)).fold(0.0f32, f32::max);
        assert!(worst(&zc, &zs) < 1e-6 && worst(&dhc, &dhs) < 1e-5, "n = {n}: the CPU's tensor ops");
        let (pc, ps) = (pc.unwrap(), ps.unwrap());
        assert!(worst(&pc[0], &ps[0]) < 1e-5 && worst(&pc[1], &ps[1]) < 1e-5, "n = {n}: the CPU's parameter gradients");
        let Some(gpu) = gpu.as_ref() else { continue };
        let (z1, dh1, p1, c1) = run(gpu, true, true);
        let (z2, dh2, p2, c2) = run(gpu, false, true);
        assert!(z1 == z2 && dh1 == dh2 && p1 == p2, "n = {n}: LayerNorm then ELU as one operation differs from the two");
        assert!(worst(&z1, &zs) < 1e-5 && worst(&dh1, &dhs) < 1e-4, "n = {n}: the GPU against the CPU");
        assert!(z1.iter().any(|&v| v < -0.1) && z1.iter().any(|&v| v > 0.1), "n = {n}: ELU's two branches");
        let count = |c: &GpuCounts, source: &str| c.total_from(Event::Kernel, source);
        // LayerNorm's kernel each way and one column sum for ∂gain and ∂shift (two slices of it
        // where the width falls off the alignment), where the separate operations add ELU's
        // kernels each way (its tensor ops where its kernel does not take the tensor)
        assert_eq!((count(&c1, "dextrain:layer_norm"), count(&c1, "dextrain:elu"), count(&c1, "dextrain:column_sums")), (2, 0, 1), "n = {n}: {c1:?}");
        assert_eq!((count(&c2, "dextrain:layer_norm"), count(&c2, "dextrain:column_sums")), (2, 1), "n = {n}: {c2:?}");
        assert!(c2.total(Event::Kernel) >= c1.total(Event::Kernel) + 2, "n = {n}: ELU's kernels (or its tensor ops) each way: {c2:?}");
        // gain and shift untracked: ∂h the same bits, no column sum
        let (z3, dh3, p3, c3) = run(gpu, true, false);
        assert!(z3 == z1 && dh3 == dh1 && p3.is_none(), "n = {n}: untracked parameters");
        assert_eq!(count(&c3, "dextrain:column_sums"), 0, "n = {n}: {c3:?}");
    }
}

/// The row-split layer (`nets::affine`, the GPU's layers at large batches): on the wgpu device a
/// batch of 4,096 rows is split (2 slices of 2,048), and `x W + b` and the gradients of W and b
/// (summed over the slices by autodiff; b's through its `1 b` product) equal the plain layer's to
/// float rounding; on the CPU nothing is split.
#[test]
fn split_rows_give_the_plain_product_and_weight_gradient() {
    use dextrain::learn::nets::{affine, row_split};
    assert_eq!(row_split(&cpu(), 65536), 1);
    let Some((_ctx, gpu)) = crate::common::wgpu_learner("split_rows_give_the_plain_product_and_weight_gradient") else { return };
    let (b, i, o) = (4096, 7, 5);
    let split = row_split(&gpu, b);
    assert_eq!(split, 2, "4,096 rows on a GPU: 2 slices of 2,048");
    assert_eq!(row_split(&gpu, 24576), 12);
    assert_eq!(row_split(&gpu, 1000), 1);
    let mut rng = Rng::new(3, 4);
    let x: Vec<f32> = (0..b * i).map(|_| rng.normal() as f32).collect();
    let w: Vec<f32> = (0..i * o).map(|_| rng.normal() as f32).collect();
    let g: Vec<f32> = (0..b * o).map(|_| rng.normal() as f32).collect();
    let bias: Vec<f32> = (0..o).map(|_| rng.normal() as f32).collect();
    let run = |split: usize| {
        let wt = to_tensor(w.clone(), [i, o], &gpu).require_grad();
        let bt = to_tensor(bias.clone(), [1, o], &gpu).require_grad();
        let y = affine(to_tensor(x.clone(), [b, i], &gpu), wt.clone(), bt.clone(), split);
        let loss = (y.clone() * to_tensor(g.clone(), [b, o], &gpu)).sum(); // ∂loss/∂W = xᵀ g, ∂loss/∂b = 1ᵀ g
        let grads = loss.backward();
        (to_host(y.inner()).unwrap(), [to_host(wt.grad(&grads).unwrap()).unwrap(), to_host(bt.grad(&grads).unwrap()).unwrap()].concat())
    };
    let (y1, g1) = run(1);
    let (ys, gs) = run(split);
    let worst = |a: &[f32], b: &[f32]| a.iter().zip(b).map(|(u, v)| (u - v).abs() / u.abs().max(1.0)).fold(0.0f32, f32::max);
    assert!(worst(&y1, &ys) < 1e-5, "products differ by {}", worst(&y1, &ys));
    // the gradient sums 4,096 products: ~√4096 · 1 in size, rounding ~1e-5 of it
    assert!(worst(&g1, &gs) < 1e-4, "weight and bias gradients differ by {}", worst(&g1, &gs));
    assert!(g1.iter().any(|v| v.abs() > 1.0), "a real gradient");
}

/// `policy.zero_init_output`: the initial policy mean is exactly 0 for any observation (a residual
/// policy starts as its reference), the std is still `init_std`, and one update moves the mean.
#[test]
fn zero_initialised_output_layer_starts_at_a_zero_mean_and_still_learns() {
    let (n, steps) = (8, 4);
    let dims = Dims { obs: 3, priv_obs: 3, act: 2 };
    let cfg = PpoConfig { minibatches: 1, epochs: 2, ..PpoConfig::default() };
    let mut rng = Rng::new(3, 3);
    let obs: Vec<f32> = (0..n * 3).map(|_| 3.0 * rng.normal() as f32).collect();
    let plain = PolicyConfig { actor_hidden: vec![16], critic_hidden: vec![16], init_std: 0.3, ..PolicyConfig::default() };
    let zero = PolicyConfig { zero_init_output: true, ..plain.clone() };
    let mean_of = |pol: &PolicyConfig| Ppo::new(dims, n, steps, &cfg, pol, &[], cpu(), 5).unwrap().act_mean(&obs, &obs).unwrap();
    assert!(mean_of(&plain).iter().any(|m| m.abs() > 1e-3), "torch's initialisation gives a non-zero mean");
    assert!(mean_of(&zero).iter().all(|&m| m == 0.0));
    let mut ppo = Ppo::new(dims, n, steps, &cfg, &zero, &[], cpu(), 5).unwrap();
    let rewards: Vec<f32> = (0..n).map(|i| if i % 2 == 0 { 1.0 } else { -1.0 }).collect();
    for _ in 0..steps {
        let a = ppo.act(&obs, &obs).unwrap();
        assert!(a.iter().all(|x| x.abs() < 2.0), "actions ~ N(0, 0.3²)");
        ppo.process_step(&rewards, &vec![false; n], &vec![false; n]);
    }
    ppo.update(&obs).unwrap();
    assert!(ppo.act_mean(&obs, &obs).unwrap().iter().any(|&m| m != 0.0), "the update moved the mean");
}

/// `Ppo::state` holds the whole learner: a fresh learner of another seed that loads it has the same
/// state, and from there both draw the same actions and make the same update, bit for bit.
#[test]
fn ppo_state_restores_a_learner_that_continues_exactly() {
    let (n, steps) = (16, 4);
    let cfg = PpoConfig { learning_rate: 3e-3, ..PpoConfig::default() };
    let pol = PolicyConfig { actor_hidden: vec![16], critic_hidden: vec![16], ..PolicyConfig::default() };
    let dims = Dims { obs: 2, priv_obs: 2, act: 2 };
    let mut env = PointTask::new(n);
    let no_term = vec![false; n];
    let rollout = |ppo: &mut Ppo, env: &mut PointTask| -> Vec<Vec<f32>> {
        let mut actions = Vec::new();
        let mut obs = env.obs();
        for _ in 0..steps {
            let a = ppo.act(&obs, &obs).unwrap();
            let (r, to) = env.step(&a);
            ppo.process_step(&r, &no_term, &to);
            obs = env.obs();
            actions.push(a);
        }
        ppo.update(&obs).unwrap();
        actions
    };
    let mut a = Ppo::new(dims, n, steps, &cfg, &pol, &[], cpu(), 3).unwrap();
    rollout(&mut a, &mut env);
    rollout(&mut a, &mut env);
    let state = a.state().unwrap();
    assert!(state.u64("adam_step").unwrap() > 0, "the learner has taken Adam steps");
    assert!(state.file("optimizer").is_some() && state.file("model").is_some());
    let mut b = Ppo::new(dims, n, steps, &cfg, &pol, &[], cpu(), 99).unwrap();
    assert_ne!(b.state().unwrap(), state, "another seed gives another learner");
    b.load_state(&state).unwrap();
    assert_eq!(b.state().unwrap(), state, "the loaded learner's state is the saved one");
    assert_eq!(b.lr.to_bits(), a.lr.to_bits());
    let mut env_b = PointTask { x: env.x.clone(), target: env.target.clone(), t: env.t.clone(), rng: env.rng.clone(), final_obs: env.final_obs.clone() };
    let acts_a = rollout(&mut a, &mut env);
    let acts_b = rollout(&mut b, &mut env_b);
    assert_eq!(acts_a, acts_b, "the restored learner acts differently");
    assert_eq!(a.state().unwrap(), b.state().unwrap(), "the restored learner updates differently");
    // a state without the optimiser is an error that names the file
    let mut partial = state.clone();
    partial.files.retain(|f| f.name != "optimizer");
    let err = format!("{:#}", b.load_state(&partial).unwrap_err());
    assert!(err.contains("optimizer.safetensors"), "{err}");
}

/// The learner's GRU (flat tensors, burn) computes what the exported ONNX GRU computes: its last
/// hidden state equals `export::onnx::forward`'s for the same weights (a student network whose
/// head and actor pass the hidden state through), and gradients reach all four parameters.
#[test]
fn the_learners_gru_matches_the_exported_formulation() {
    use dextrain::export::onnx::{Adaptation, Gru, forward};
    use dextrain::learn::gru::{gru_forward, gru_shapes, init_gru};
    let (d, hs, steps, b) = (3, 5, 7, 4);
    let mut rng = Rng::new(9, 9);
    let values = init_gru(d, hs, &mut rng);
    let shapes = gru_shapes(d, hs);
    assert_eq!(values.iter().map(Vec::len).collect::<Vec<_>>(), shapes.iter().map(|s| s[0] * s[1]).collect::<Vec<_>>());
    let x: Vec<f32> = (0..b * steps * d).map(|_| 2.0 * rng.normal() as f32).collect();
    let dev = cpu().autodiff();
    let params: Vec<_> = values.iter().zip(&shapes).map(|(v, s)| to_tensor(v.clone(), *s, &dev).require_grad()).collect();
    let h = gru_forward(&params, to_tensor(x.clone(), [b, steps * d], &dev), steps);
    let ours = to_host(h.clone().inner()).unwrap();
    // the same GRU in the exporter's reference
    let net = pass_through_student(Adaptation::Gru(Gru { inputs: d, hidden: hs, w_ih: values[0].clone(), w_hh: values[1].clone(), b_ih: values[2].clone(), b_hh: values[3].clone() }), d, hs, steps);
    let want = forward(&net, &vec![0.3; b], &[], &x, b).unwrap();
    let diff = ours.iter().zip(&want).map(|(a, w)| (a - w).abs()).fold(0.0f32, f32::max);
    assert!(diff < 1e-5, "burn GRU vs the exporter's: {diff}");
    assert!(ours.iter().any(|v| v.abs() > 1e-2), "a non-trivial hidden state");
    let grads = h.sum().backward();
    for (k, p) in params.iter().enumerate() {
        let g = to_host(p.grad(&grads).expect("a gradient")).unwrap();
        assert!(g.iter().all(|v| v.is_finite()) && g.iter().any(|v| *v != 0.0), "parameter {k}");
    }
}

/// The learner's temporal convolution (`learn::tcn`, flat tensors, windows by slicing) gives what
/// `export::onnx::forward` computes for the same weights (its direct sum over kernel steps and
/// channels, the reference the ONNX Conv graph is checked against), and gradients reach every
/// parameter.
#[test]
fn the_learners_tcn_matches_the_exported_formulation() {
    use dextrain::export::onnx::{Adaptation, Conv1d, Dense, Tcn, forward};
    use dextrain::learn::tcn::{init_tcn, steps_out, tcn_forward, tcn_names, tcn_shapes};
    let (d, c, steps, b) = (3, 4, 11, 4);
    let convs = [(3, 2), (2, 1)];
    // T' = ⌊(11 − 3)/2⌋ + 1 = 5, then 5 − 2 + 1 = 4
    assert_eq!(steps_out(steps, &convs), Some(4));
    assert_eq!(steps_out(steps, &[(12, 1)]), None);
    let f = 4 * c;
    let mut rng = Rng::new(9, 10);
    let values = init_tcn(d, c, &convs, &mut rng);
    let shapes = tcn_shapes(d, c, &convs);
    assert_eq!(tcn_names(convs.len()).len(), shapes.len());
    assert_eq!(values.iter().map(Vec::len).collect::<Vec<_>>(), shapes.iter().map(|s| s[0] * s[1]).collect::<Vec<_>>());
    let x: Vec<f32> = (0..b * steps * d).map(|_| 2.0 * rng.normal() as f32).collect();
    let dev = cpu().autodiff();
    let params: Vec<_> = values.iter().zip(&shapes).map(|(v, s)| to_tensor(v.clone(), *s, &dev).require_grad()).collect();
    let y = tcn_forward(&params, to_tensor(x.clone(), [b, steps * d], &dev), steps, &convs);
    assert_eq!(y.dims(), [b, f]);
    let ours = to_host(y.clone().inner()).unwrap();
    let dense = |i: usize| Dense { weight: values[i].clone(), bias: values[i + 1].clone(), inputs: shapes[i][0], outputs: shapes[i][1] };
    let conv = |i: usize, (kernel, stride): (usize, usize)| Conv1d { inputs: c, outputs: c, kernel, stride, weight: values[i].clone(), bias: values[i + 1].clone() };
    let net = pass_through_student(Adaptation::Tcn(Tcn { embed: vec![dense(0), dense(2)], convs: vec![conv(4, convs[0]), conv(6, convs[1])] }), d, f, steps);
    let want = forward(&net, &vec![0.3; b], &[], &x, b).unwrap();
    let diff = ours.iter().zip(&want).map(|(a, w)| (a - w).abs()).fold(0.0f32, f32::max);
    assert!(diff < 1e-5, "burn TCN vs the exporter's: {diff}");
    assert!(ours.iter().filter(|v| **v > 1e-3).count() > f, "a non-trivial output: {ours:?}");
    let grads = y.sum().backward();
    for (k, p) in params.iter().enumerate() {
        let g = to_host(p.grad(&grads).expect("a gradient")).unwrap();
        assert!(g.iter().all(|v| v.is_finite()) && g.iter().any(|v| *v != 0.0), "parameter {k}");
    }
}

/// adam.wgsl and normalizer.wgsl (`learn::kernels::fused_adam`, `learn::kernels::fused_normalizer`: what a learner on
/// burn's wgpu runtime runs) against their tensor-op twins on the CPU backend:
/// - two clipped AdamW steps of three parameters (one large enough that each of the norm's 64
///   slices adds several blocks), the norm (also against an f64 sum), and an unclipped step: the
///   parameters agree to float rounding, and the GPU ran adam.wgsl's three kernels per step (the
///   norm's slices of every parameter, the norm, the update of every parameter); the same steps in
///   launches over groups of two parameters (`limit_gpu_group`) give the same bits;
/// - the last step with SAC's Polyak average of target copies (`step_clipped_polyak`, τ = 0.3): the
///   targets agree with τ p + (1 − τ) t worked out on the host, and on the GPU the average ran in
///   adam.wgsl's kernels (`adam_update_polyak`: no kernel more);
/// - an unclipped step without the norm (`report_norm = false`, SAC's): P kernels, the same bits;
/// - the normalisers over three batches (a constant column included, which must normalise to
///   exactly 0, as on the host): the statistics and the normalised values agree with the host's
///   f64 `Normalizer`, in one submission of four dispatches per step.
#[test]
fn optimiser_and_normaliser_kernels_match_their_tensor_twins() {
    use dextrain::gpu_counts::{Event, GpuCounts};
    use dextrain::learn::kernels::fused_normalizer;
    use dextrain::learn::normalizer::{DeviceNormalizer, DeviceNormalizers};
    let Some((_ctx, gpu)) = crate::common::wgpu_learner("optimiser_and_normaliser_kernels_match_their_tensor_twins") else { return };
    let shapes = [[200usize, 200usize], [1, 200], [3, 5]];
    let mut rng = Rng::new(4, 4);
    let mut draw = |len: usize, scale: f64| -> Vec<f32> { (0..len).map(|_| (rng.normal() * scale) as f32).collect() };
    let init: Vec<Vec<f32>> = shapes.iter().map(|s| draw(s[0] * s[1], 1.0)).collect();
    let coefs: Vec<Vec<Vec<f32>>> = (0..3).map(|_| shapes.iter().map(|s| draw(s[0] * s[1], 0.01)).collect()).collect();
    let target_init: Vec<Vec<f32>> = shapes.iter().map(|s| draw(s[0] * s[1], 1.0)).collect();
    let tau = 0.3;
    // three steps of loss = Σ p ⊙ c_k (∂loss/∂p = c_k): clipped to 1.0, clipped to 1.0, unclipped
    // and with the targets' Polyak average
    let run = |device: Device, group: usize| -> (Vec<Vec<f32>>, Vec<f32>, GpuCounts, Vec<Vec<f32>>) {
        let mut adam = Adam::new(&shapes, &device);
        adam.limit_gpu_group(group);
        adam.weight_decay = 0.01;
        let lr = to_tensor(vec![0.003], [1, 1], &device.clone().inner());
        let mut params: Vec<Tensor<2>> = init.iter().zip(&shapes).map(|(v, s)| to_tensor(v.clone(), *s, &device).require_grad()).collect();
        let mut targets: Vec<Tensor<2>> = target_init.iter().zip(&shapes).map(|(v, s)| to_tensor(v.clone(), *s, &device).inner()).collect();
        let mut norms = Vec::new();
        let before = GpuCounts::now();
        for (k, c) in coefs.iter().enumerate() {
            let loss = params.iter().zip(c).zip(&shapes).map(|((p, c), s)| (p.clone() * to_tensor(c.clone(), *s, &device)).sum()).reduce(|a, b| a + b).unwrap();
            let grads = loss.backward();
            let (new, norm) = if k < 2 {
                adam.step_clipped(&params, &grads, 1.0, &lr).unwrap()
            } else {
                adam.step_clipped_polyak(&params, &grads, 0.0, &lr, &mut targets, tau).unwrap()
            };
            params = new;
            norms.push(to_host(norm.expect("the norm is reported")).unwrap()[0]);
        }
        let counts = GpuCounts::now().since(&before);
        let host = |ts: &[Tensor<2>]| ts.iter().map(|p| to_host(p.clone().inner()).unwrap()).collect::<Vec<_>>();
        (host(&params), norms, counts, host(&targets))
    };
    let (p_cpu, n_cpu, _, t_cpu) = run(cpu(), 3);
    let (p_gpu, n_gpu, counts, t_gpu) = run(gpu.clone(), 3);
    // in groups of two (two launches each for the norm's slices and the update): the same bits
    let (p_pairs, n_pairs, pair_counts, t_pairs) = run(gpu.clone(), 2);
    assert!(p_pairs == p_gpu && n_pairs == n_gpu && t_pairs == t_gpu, "the step in groups of two differs from the step in one group");
    assert_eq!(pair_counts.total_from(Event::Kernel, "dextrain:adam"), 3 * (2 * 2 + 1), "in groups of two: {pair_counts:?}");
    for (name, p, t) in [("cpu", &p_cpu, &t_cpu), ("gpu", &p_gpu, &t_gpu)] {
        let want = p.iter().flatten().zip(target_init.iter().flatten()).map(|(&p, &t)| tau as f32 * p + (1.0 - tau as f32) * t);
        let worst = want.zip(t.iter().flatten()).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
        assert!(worst < 1e-5, "the {name} targets differ from τ p + (1 − τ) t by {worst}");
    }
    // three kernels a step where the device binds 5 P + 2 = 17 storage buffers per kernel (lavapipe
    // and the hardware GPUs do; WebGPU's default of 8 would take groups of one)
    assert_eq!(Adam::new(&shapes, &gpu).gpu_kernels_per_step(true), Some(3), "adam.wgsl's kernels over one group of three parameters");
    assert_eq!(counts.total_from(Event::Kernel, "dextrain:adam"), 3 * 3, "adam.wgsl's kernels per step: {counts:?}");
    for (k, c) in coefs.iter().enumerate() {
        let want = c.iter().flatten().map(|&x| (x as f64).powi(2)).sum::<f64>().sqrt();
        for (name, got) in [("cpu", n_cpu[k]), ("gpu", n_gpu[k])] {
            assert!((got as f64 - want).abs() < 1e-5 * want, "step {k}: the {name} gradient norm {got} vs {want}");
        }
        assert!(want > 1.0, "the test's gradients must be clipped (norm {want})");
    }
    let worst = p_cpu.iter().flatten().zip(p_gpu.iter().flatten()).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
    assert!(worst < 1e-5, "parameters after three steps differ by {worst}");
    // an unclipped step that does not report its norm (SAC's): the update kernels alone, the
    // same parameters bit for bit as a step that works the norm out
    let unreported = |report_norm: bool| -> (Vec<Vec<f32>>, bool, u64) {
        let mut adam = Adam::new(&shapes, &gpu);
        adam.report_norm = report_norm;
        let lr = to_tensor(vec![0.003], [1, 1], &gpu.clone().inner());
        let params: Vec<Tensor<2>> = init.iter().zip(&shapes).map(|(v, s)| to_tensor(v.clone(), *s, &gpu).require_grad()).collect();
        let loss = params.iter().zip(&coefs[0]).zip(&shapes).map(|((p, c), s)| (p.clone() * to_tensor(c.clone(), *s, &gpu)).sum()).reduce(|a, b| a + b).unwrap();
        let grads = loss.backward();
        let before = GpuCounts::now();
        let (new, norm) = adam.step_clipped(&params, &grads, 0.0, &lr).unwrap();
        let kernels = GpuCounts::now().since(&before).total_from(Event::Kernel, "dextrain:adam");
        (new.iter().map(|p| to_host(p.clone().inner()).unwrap()).collect(), norm.is_some(), kernels)
    };
    let (with, without) = (unreported(true), unreported(false));
    assert_eq!((with.1, with.2, without.1, without.2), (true, 3, false, 1), "norm reported, adam kernels; unreported");
    assert_eq!(with.0, without.0, "the same step with and without the norm's kernels");
    let moved = init.iter().flatten().zip(p_gpu.iter().flatten()).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
    assert!(moved > 5e-3, "the steps moved the parameters by {moved} only");

    // the normalisers: actor observations of 5 components (the last constant), critic ones of 3
    let mut host = [Normalizer::new(5), Normalizer::new(3)];
    let mut dev = DeviceNormalizers::from_host(&host[0], &host[1], &gpu);
    // the same normalisers a launch each, as on a device that binds four storage buffers a kernel
    let mut apart = [DeviceNormalizer::from_host(&host[0], &gpu), DeviceNormalizer::from_host(&host[1], &gpu)];
    for b in 0..3 {
        let rows = 300 + 37 * b;
        let obs: Vec<f32> = (0..rows * 5).map(|i| if i % 5 == 4 { 0.37 } else { (rng.normal() * (1.0 + (i % 5) as f64) + 10.0 * b as f64) as f32 }).collect();
        let priv_obs: Vec<f32> = (0..rows * 3).map(|_| (rng.normal() * 3.0 - 1.0) as f32).collect();
        let before = GpuCounts::now();
        let (o, p) = dev.update_and_normalize(&to_tensor(obs.clone(), [rows, 5], &gpu), &to_tensor(priv_obs.clone(), [rows, 3], &gpu), true).unwrap();
        let counts = GpuCounts::now().since(&before);
        // two kernels on burn's stream for both normalisers, no submission of ours
        assert_eq!((counts.total_from(Event::Kernel, "dextrain:normalizers"), counts.total(Event::Submission)), (2, 0), "{counts:?}");
        let (obs_t, priv_t) = (to_tensor(obs.clone(), [rows, 5], &gpu), to_tensor(priv_obs.clone(), [rows, 3], &gpu));
        let [a0, a1] = &mut apart;
        let before = GpuCounts::now();
        let one_each = fused_normalizer::update_and_normalize(&mut [(a0, &obs_t), (a1, &priv_t)], 4).unwrap().expect("plain tensors of the GPU");
        assert_eq!(GpuCounts::now().since(&before).total_from(Event::Kernel, "dextrain:normalizers"), 4, "a launch per normaliser and entry");
        let (o, p) = (to_host(o).unwrap(), to_host(p).unwrap());
        assert!(to_host(one_each[0].clone()).unwrap() == o && to_host(one_each[1].clone()).unwrap() == p, "batch {b}: one launch over both normalisers differs from one each");
        for (a, d) in apart.iter().zip([&dev.obs, &dev.priv_obs]) {
            assert!(to_host(a.mean.clone()).unwrap() == to_host(d.mean.clone()).unwrap() && to_host(a.m2.clone()).unwrap() == to_host(d.m2.clone()).unwrap() && to_host(a.scale.clone()).unwrap() == to_host(d.scale.clone()).unwrap(), "batch {b}: the statistics differ");
        }
        host[0].update(&obs);
        host[1].update(&priv_obs);
        for (h, x, got) in [(&host[0], &obs, o), (&host[1], &priv_obs, p)] {
            let want = h.normalized(x, true);
            let worst = want.iter().zip(&got).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
            assert!(worst < 1e-4, "batch {b}: normalised values differ by {worst}");
        }
        let o_got = to_host(dev.update_and_normalize(&to_tensor(obs.clone(), [rows, 5], &gpu), &to_tensor(priv_obs.clone(), [rows, 3], &gpu), false).unwrap().0).unwrap();
        assert_eq!(o_got, obs, "normalisation off: the observations as they are");
        let normalised = to_host(dev.obs.normalized(to_tensor(obs.clone(), [rows, 5], &gpu), true)).unwrap();
        assert!(normalised.iter().skip(4).step_by(5).all(|&x| x == 0.0), "a constant column normalises to exactly 0");
    }
    let (o, p) = dev.to_host().unwrap();
    for (h, d) in [(&host[0], &o), (&host[1], &p)] {
        assert_eq!(d.count, h.count);
        for k in 0..h.mean.len() {
            assert!((d.mean[k] - h.mean[k]).abs() < 1e-4 * (1.0 + h.mean[k].abs()), "mean {k}: {} vs {}", d.mean[k], h.mean[k]);
            assert!((d.m2[k] - h.m2[k]).abs() <= 1e-4 * h.m2[k] + 1e-6, "m2 {k}: {} vs {}", d.m2[k], h.m2[k]);
        }
    }
}

/// The GPU learner's sums over the batch's rows in two stages (`learn::kernels::row_sums`) and its products
/// with each matmul routine (`learn::kernels::gpu_matmul`) against plain tensor ops: the same values, the
/// same bits run to run, the two-stage path taken where the rows allow it, and a broadcast
/// parameter's gradient through `rows_of` equal to burn's broadcast gradient.
#[test]
fn row_sums_and_matmul_routines_match_their_tensor_twins() {
    use dextrain::learn::kernels::gpu_matmul::{self, GpuMatmul};
    use dextrain::learn::kernels::row_sums::{blocks_for, column_sums, rows_of, sum_all_two_stage};
    assert_eq!(blocks_for(24_576), Some(256));
    assert_eq!(blocks_for(6_144), Some(256));
    assert_eq!(blocks_for(2_048 + 8), Some(8), "2056 = 8 · 257");
    assert_eq!(blocks_for(4_097), None, "an odd count has no blocks");
    assert_eq!(blocks_for(1_024), None, "too few rows to pay");
    let Some((_ctx, gpu)) = crate::common::wgpu_learner("row_sums_and_matmul_routines_match_their_tensor_twins") else { return };
    let dev = gpu.clone().inner();
    let mut rng = Rng::new(9, 9);
    let mut draw = |len: usize| -> Vec<f32> { (0..len).map(|_| rng.normal() as f32).collect() };
    for (rows, cols) in [(4096usize, 22usize), (4096, 1), (3001, 5), (6144, 517), (2056, 3), (100, 2)] {
        let host = draw(rows * cols);
        let g = to_tensor(host.clone(), [rows, cols], &dev);
        let before = dextrain::gpu_counts::GpuCounts::now();
        let got = to_host(column_sums(g.clone())).unwrap();
        // two columns or more: one launch of the kernel of ours; one column: burn's stages
        let ours = dextrain::gpu_counts::GpuCounts::now().since(&before).total_from(dextrain::gpu_counts::Event::Kernel, "dextrain:column_sums");
        assert_eq!(ours, (cols >= 2) as u64, "{rows}×{cols}: launches of the column-sum kernel");
        let again = to_host(column_sums(g.clone())).unwrap();
        assert_eq!(got, again, "{rows}×{cols}: the column sums repeat bit for bit");
        // the kernel of ours (two columns or more) adds in the order of burn's two stages (or its
        // one): the same bits as those reductions
        let stages = to_host(Tensor::<2>::from_primitive::<burn::backend::Cube>(dextrain::learn::kernels::row_sums::column_sums_ops::<burn::backend::Cube>(g.clone().try_into_primitive::<burn::backend::Cube>().unwrap()))).unwrap();
        assert!(got.iter().zip(&stages).all(|(a, b)| a.to_bits() == b.to_bits()), "{rows}×{cols}: the kernel against burn's stages:\n{got:?}\n{stages:?}");
        for c in 0..cols {
            let want: f64 = (0..rows).map(|r| host[r * cols + c] as f64).sum();
            assert!((got[c] as f64 - want).abs() < 1e-4 * (1.0 + want.abs()), "{rows}×{cols} column {c}: {} vs {want}", got[c]);
        }
        let all = to_host(sum_all_two_stage(g)).unwrap()[0] as f64;
        let want: f64 = host.iter().map(|&v| v as f64).sum();
        assert!((all - want).abs() < 1e-3 * (1.0 + want.abs()), "{rows}×{cols} Σ all: {all} vs {want}");
    }
    // ∂/∂x of Σ (rows_of(x) ⊙ y) = 1ᵀ y, as burn's broadcast gives it
    let (rows, cols) = (4096, 22);
    let x0 = draw(cols);
    let y = to_tensor(draw(rows * cols), [rows, cols], &gpu);
    let grad_of = |expand: bool| -> Vec<f32> {
        let x = to_tensor(x0.clone(), [1, cols], &gpu).require_grad();
        let xr = if expand { rows_of(x.clone(), rows) } else { x.clone() };
        let loss = (xr * y.clone()).sum();
        let grads = loss.backward();
        to_host(x.grad(&grads).expect("x has a gradient")).unwrap()
    };
    let (ours, burns) = (grad_of(true), grad_of(false));
    for c in 0..cols {
        assert!((ours[c] - burns[c]).abs() < 1e-3 * (1.0 + burns[c].abs()), "∂x[{c}]: rows_of {} vs broadcast {}", ours[c], burns[c]);
    }
    // every routine that takes the shapes gives burn's products (transposed views included)
    let (m, k, n) = (300, 70, 45);
    let a = to_tensor(draw(m * k), [m, k], &dev);
    let b = to_tensor(draw(k * n), [k, n], &dev);
    let bt = to_tensor(draw(n * k), [n, k], &dev).transpose(); // [k, n], a strided view
    let prim = |t: &Tensor<2>| t.clone().try_into_primitive::<burn::backend::Cube>().unwrap();
    for rhs in [&b, &bt] {
        let want = to_host(a.clone().matmul(rhs.clone())).unwrap();
        let mut ran = 0;
        for (routine, name) in GpuMatmul::NAMES {
            let before = gpu_matmul::fallbacks();
            let got = to_host(Tensor::<2>::from_primitive::<burn::backend::Cube>(gpu_matmul::matmul_with(routine, prim(&a), prim(rhs)))).unwrap();
            ran += usize::from(gpu_matmul::fallbacks() == before);
            if name.starts_with("dextrain_tiled") {
                assert_eq!(gpu_matmul::fallbacks(), before, "{name}: matmul.wgsl fell back to burn's product");
            }
            let worst = got.iter().zip(&want).map(|(g, w)| (g - w).abs() / (1.0 + w.abs())).fold(0.0f32, f32::max);
            assert!(worst < 1e-4, "{name}: products differ from burn's by {worst}");
        }
        assert!(ran >= 5, "the unit routines and ours run on any adapter: {ran} of {} ran", GpuMatmul::NAMES.len());
    }
    // a long k over few output tiles (a weight gradient xᵀ g over 2,100 rows): dextrain's kernel
    // splits it over k (plan) and sums the partials; every routine gives burn's product
    use dextrain::learn::kernels::wgsl_matmul::{MIN_K_PER_SPLIT, Tile, plan};
    assert_eq!(plan(512, 256, 24_576, 1, None), (Tile::LARGE, 66, 376), "the PPO bench's widest weight gradient");
    assert_eq!(plan(512, 256, 4_096, 1, None), (Tile::SMALL, 16, 256), "SAC's: 128 × 128 tiles would not fill the GPU");
    assert_eq!(plan(24_576, 512, 256, 1, None).1, 1, "a forward product fills the GPU unsplit");
    assert_eq!(plan(40, 30, 2_100, 3, None).1, 1, "batched products are not split");
    let (rows_k, i2, o2) = (2_100, 40, 30);
    let (tile, splits, chunk) = plan(i2, o2, rows_k, 1, None);
    assert!(splits == rows_k.div_ceil(chunk) && splits >= 8 && chunk >= MIN_K_PER_SPLIT && chunk % tile.depth == 0, "{splits} splits of {chunk}");
    let xk = to_tensor(draw(rows_k * i2), [rows_k, i2], &dev).transpose(); // [in, B], a strided view
    let gk = to_tensor(draw(rows_k * o2), [rows_k, o2], &dev); // [B, out]
    let want = to_host(xk.clone().matmul(gk.clone())).unwrap();
    for (routine, name) in GpuMatmul::NAMES {
        let got = to_host(Tensor::<2>::from_primitive::<burn::backend::Cube>(gpu_matmul::matmul_with(routine, prim(&xk), prim(&gk)))).unwrap();
        assert_eq!(got.len(), i2 * o2, "{name}: the split product's size");
        let worst = got.iter().zip(&want).map(|(g, w)| (g - w).abs() / (1.0 + w.abs())).fold(0.0f32, f32::max);
        assert!(worst < 1e-4, "{name}: the product over a long k differs from burn's by {worst}");
        let again = to_host(Tensor::<2>::from_primitive::<burn::backend::Cube>(gpu_matmul::matmul_with(routine, prim(&xk), prim(&gk)))).unwrap();
        assert_eq!(got, again, "{name}: the product over a long k repeats bit for bit");
    }
    // batched, as the weight gradient split over row slices multiplies: [S, in, B/S] (a view with
    // its last two dimensions swapped) · [S, B/S, out]
    let (s3, r3, i3, o3) = (3, 200, 70, 45);
    let x3 = Tensor::<3>::from_data(TensorData::new(draw(s3 * r3 * i3), [s3, r3, i3]), &dev).swap_dims(1, 2); // [S, in, B/S]
    let g3 = Tensor::<3>::from_data(TensorData::new(draw(s3 * r3 * o3), [s3, r3, o3]), &dev); // [S, B/S, out]
    let want = x3.clone().matmul(g3.clone()).into_data().try_to_vec::<f32>().unwrap();
    let prim3 = |t: &Tensor<3>| t.clone().try_into_primitive::<burn::backend::Cube>().unwrap();
    for (routine, name) in GpuMatmul::NAMES {
        let got = Tensor::<3>::from_primitive::<burn::backend::Cube>(gpu_matmul::matmul_with(routine, prim3(&x3), prim3(&g3))).into_data().try_to_vec::<f32>().unwrap();
        assert_eq!(got.len(), s3 * i3 * o3, "{name}: batched product's size");
        let worst = got.iter().zip(&want).map(|(g, w)| (g - w).abs() / (1.0 + w.abs())).fold(0.0f32, f32::max);
        assert!(worst < 1e-4, "{name}: batched products differ from burn's by {worst}");
    }
    // the dense layer's gradients on the GPU (the weight gradient split over 2 row slices of
    // 2,048 inside the op, ∂b two-stage) against the CPU's
    let (rows, i, o) = (4096, 24, 40);
    let (xv, wv, bv, cv) = (draw(rows * i), draw(i * o), draw(o), draw(rows * o));
    let grads_on = |device: &Device| -> Vec<Vec<f32>> {
        let x = to_tensor(xv.clone(), [rows, i], device).require_grad();
        let w = to_tensor(wv.clone(), [i, o], device).require_grad();
        let b = to_tensor(bv.clone(), [1, o], device).require_grad();
        let y = dextrain::learn::kernels::affine::fused_affine(x.clone(), w.clone(), b.clone());
        let grads = (y * to_tensor(cv.clone(), [rows, o], device)).sum().backward();
        [x, w, b].iter().map(|t| to_host(t.grad(&grads).expect("a gradient")).unwrap()).collect()
    };
    assert_eq!(dextrain::learn::nets::split_for_rows(rows), 2);
    for (k, (g, c)) in grads_on(&gpu).iter().zip(grads_on(&cpu())).enumerate() {
        let worst = g.iter().zip(&c).map(|(a, b)| (a - b).abs() / (1.0 + b.abs())).fold(0.0f32, f32::max);
        assert!(worst < 1e-4, "gradient {k} (x, W, b) differs from the CPU's by {worst}");
    }
    // a hidden layer with its ELU as one op (on the GPU one kernel with dextrain's matmul): the
    // values and gradients of the two ops, on the GPU against the CPU, and on the CPU bit for bit
    let layer_on = |device: &Device, one_op: bool| -> Vec<Vec<f32>> {
        let x = to_tensor(xv.clone(), [rows, i], device).require_grad();
        let w = to_tensor(wv.clone(), [i, o], device).require_grad();
        let b = to_tensor(bv.clone(), [1, o], device).require_grad();
        let y = if one_op {
            dextrain::learn::kernels::affine::fused_affine_elu(x.clone(), w.clone(), b.clone())
        } else {
            dextrain::learn::kernels::elu::elu(dextrain::learn::kernels::affine::fused_affine(x.clone(), w.clone(), b.clone()))
        };
        let values = to_host(y.clone()).unwrap();
        let grads = (y * to_tensor(cv.clone(), [rows, o], device)).sum().backward();
        let mut out = vec![values];
        out.extend([x, w, b].iter().map(|t| to_host(t.grad(&grads).expect("a gradient")).unwrap()));
        out
    };
    assert_eq!(layer_on(&cpu(), true), layer_on(&cpu(), false), "the CPU's ELU layer as one op changes nothing");
    let (gpu_layer, gpu_ops) = (layer_on(&gpu, true), layer_on(&gpu, false));
    assert_eq!(gpu_layer[0], gpu_ops[0], "the GPU's ELU layer as one kernel gives the ops' values bit for bit");
    for (k, (g, c)) in gpu_layer.iter().zip(layer_on(&cpu(), false)).enumerate() {
        let worst = g.iter().zip(&c).map(|(a, b)| (a - b).abs() / (1.0 + b.abs())).fold(0.0f32, f32::max);
        assert!(worst < 1e-4, "ELU layer {k} (y, ∂x, ∂W, ∂b) differs from the CPU's by {worst}");
    }
    assert!(GpuMatmul::parse("double_unit").is_ok());
    let err = GpuMatmul::parse("fastest").unwrap_err().to_string();
    assert!(err.contains("DEXTRAIN_GPU_MATMUL") && err.contains("simple_unit"), "{err}");
}

/// Every variant of dextrain's matrix product — each tile shape, with scalar reads and with vec4
/// reads along k or across rows / columns — gives the shape rule's product bit for bit (a forward
/// product with its bias and ELU, a weight gradient split over k, a product by a transposed view,
/// an input gradient with ELU's gradient in its epilogue, weight and bias gradients in one product
/// split over k and not), so `dextrain_tuned` may pick any of them per process and a run still
/// repeats and resumes exactly; the tuner times every variant that takes a product, remembers its
/// pick, and reports it. ELU's gradient in the epilogue gives the product then ELU's gradient
/// kernel bit for bit; the row of ones' sums are the column sums of B.
#[test]
fn every_tile_shape_gives_the_same_bits_and_the_tuner_picks_one() {
    use dextrain::learn::kernels::matmul_tuning::records;
    use dextrain::learn::kernels::elu::EluOps;
    use dextrain::learn::kernels::wgsl_matmul::{Epilogue, Loads, TileChoice, candidate_variants, matmul_and_column_sums, matmul_as_planned_in, matmul_then, plan};
    let Some((_ctx, gpu)) = crate::common::wgpu_learner("every_tile_shape_gives_the_same_bits_and_the_tuner_picks_one") else { return };
    let dev = gpu.clone().inner();
    let mut rng = Rng::new(17, 3);
    let mut draw = |len: usize| -> Vec<f32> { (0..len).map(|_| rng.normal() as f32).collect() };
    let prim = |t: &Tensor<2>| t.clone().try_into_primitive::<burn::backend::Cube>().unwrap();
    let host = |t: burn::backend::tensor::FloatTensor<burn::backend::Cube>| to_host(Tensor::<2>::from_primitive::<burn::backend::Cube>(t)).unwrap();
    // a dense layer ELU(x W + b) over 300 rows (unsplit; A read along k, B across columns), its
    // input gradient g Wᵀ (B a transposed view, read along k), xᵀ g over 1,100 rows (split over k;
    // A a transposed view read across rows), and a product whose sizes allow no vec4 reads
    let (rows, i, o) = (300, 72, 44);
    let x = to_tensor(draw(rows * i), [rows, i], &dev);
    let w = to_tensor(draw(i * o), [i, o], &dev);
    let b = to_tensor(draw(o), [1, o], &dev);
    let g = to_tensor(draw(rows * o), [rows, o], &dev);
    let (long, i2, o2) = (1_100, 40, 32);
    let xt = to_tensor(draw(long * i2), [long, i2], &dev).transpose(); // [in, B], a strided view
    let g2 = to_tensor(draw(long * o2), [long, o2], &dev);
    assert!(plan(i2, o2, long, 1, None).1 > 1, "the weight gradient is split over k");
    let odd_a = to_tensor(draw(130 * 45), [130, 45], &dev);
    let odd_b = to_tensor(draw(45 * 22), [45, 22], &dev);
    let bias = prim(&b);
    // ELU's outputs (> −1) at the input gradient's entries
    let y = to_tensor(draw(rows * i).into_iter().map(|v| if v > 0.0 { v } else { v.exp() - 1.0 }).collect(), [rows, i], &dev);
    let y_prim = prim(&y);
    let cases: [(&str, Tensor<2>, Tensor<2>, Epilogue<'_>, [Loads; 2]); 8] = [
        ("ELU(x W + b)", x.clone(), w.clone(), Epilogue::BiasElu(&bias), [Loads::Vec4AlongK, Loads::Vec4Across]),
        ("g Wᵀ", g.clone(), w.clone().transpose(), Epilogue::None, [Loads::Vec4AlongK, Loads::Vec4AlongK]),
        ("(g Wᵀ) · ELU'(y)", g.clone(), w.transpose(), Epilogue::EluGrad(&y_prim), [Loads::Vec4AlongK, Loads::Vec4AlongK]),
        ("xᵀ g, split over k", xt.clone(), g2.clone(), Epilogue::None, [Loads::Vec4Across, Loads::Vec4Across]),
        ("[xᵀ; 1ᵀ] g, split over k", xt, g2, Epilogue::ColumnSums, [Loads::Vec4Across, Loads::Vec4Across]),
        ("[xᵀ; 1ᵀ] g", x.transpose(), g, Epilogue::ColumnSums, [Loads::Vec4Across, Loads::Vec4Across]),
        ("[130 × 45] · [45 × 22]", odd_a.clone(), odd_b.clone(), Epilogue::None, [Loads::Scalar, Loads::Scalar]),
        ("[130 × 45; 1ᵀ] · [45 × 22]", odd_a, odd_b, Epilogue::ColumnSums, [Loads::Scalar, Loads::Scalar]),
    ];
    assert!(plan(i2 + 1, o2, long, 1, None).1 > 1 && plan(i + 1, o, rows, 1, None).1 == 1, "one product with a row of ones split over k, one not");
    // C (and the row of ones' sums) of the product as the tile choice runs it
    let product = |l: &burn::backend::tensor::FloatTensor<burn::backend::Cube>, r: &burn::backend::tensor::FloatTensor<burn::backend::Cube>, choice: TileChoice, epilogue: Epilogue<'_>| -> (Vec<f32>, Option<Vec<f32>>) {
        if epilogue.ones_row() {
            let (c, s) = matmul_and_column_sums(l, r, choice).unwrap();
            (host(c), Some(host(s)))
        } else {
            (host(matmul_then(l, r, choice, epilogue).unwrap()), None)
        }
    };
    for (name, lhs, rhs, epilogue, vector_reads) in cases {
        let (l, r) = (prim(&lhs), prim(&rhs));
        let (by_shape, sums) = product(&l, &r, TileChoice::ByShape, epilogue);
        let want = host(prim(&lhs.clone().matmul(rhs.clone())));
        assert_eq!(by_shape.len(), want.len());
        let close = |got: &[f32], want: &[f32]| got.iter().zip(want).map(|(g, w)| (g - w).abs() / (1.0 + w.abs())).fold(0.0f32, f32::max);
        if matches!(epilogue, Epilogue::None | Epilogue::ColumnSums) {
            let worst = close(&by_shape, &want);
            assert!(worst < 1e-4, "{name}: the product differs from burn's by {worst}");
        }
        if let Some(sums) = &sums {
            let want_sums = host(prim(&rhs.clone().sum_dim(0)));
            assert_eq!(sums.len(), rhs.dims()[1], "{name}: one sum per column of B");
            let worst = close(sums, &want_sums);
            assert!(worst < 1e-4, "{name}: the row of ones' sums differ from B's column sums by {worst}");
        }
        if let Epilogue::EluGrad(y) = epilogue {
            let plain = matmul_then(&l, &r, TileChoice::ByShape, Epilogue::None).unwrap();
            let then_kernel = host(<burn::backend::Cube as EluOps>::elu_fused_backward(y.clone(), plain));
            assert!(by_shape.iter().zip(&then_kernel).all(|(a, b)| a.to_bits() == b.to_bits()), "{name}: the epilogue gives the product then ELU's gradient kernel bit for bit");
        }
        let variants = candidate_variants(&l, &r, epilogue).unwrap();
        let vector = variants.iter().filter(|v| [v.a, v.b] == vector_reads && vector_reads != [Loads::Scalar; 2]).count();
        let scalar_only = vector_reads == [Loads::Scalar; 2];
        assert!(scalar_only || vector >= 4, "{name}: vec4 reads {vector_reads:?} in {vector} variants of {}", variants.len());
        assert!(!scalar_only || variants.iter().all(|v| [v.a, v.b] == [Loads::Scalar; 2]), "{name}: no vec4 reads where the sizes are not multiples of 4");
        for v in &variants {
            let (got, got_sums) = matmul_as_planned_in(&l, &r, *v, epilogue).unwrap();
            let (got, got_sums) = (host(got), got_sums.map(host));
            let differing = got.iter().zip(&by_shape).filter(|(a, b)| a.to_bits() != b.to_bits()).count();
            assert_eq!(differing, 0, "{name}: {} gives {differing} entries other bits than the shape rule's", v.label());
            assert_eq!(got_sums.map(|s| s.iter().map(|v| v.to_bits()).collect::<Vec<_>>()), sums.as_ref().map(|s| s.iter().map(|v| v.to_bits()).collect()), "{name}: {}'s sums", v.label());
        }
        // this product's records (tests side by side may tune other products in this process)
        let sizes = [(lhs.dims()[0] + usize::from(epilogue.ones_row())) as u32, rhs.dims()[1] as u32, lhs.dims()[1] as u32, 1];
        let mine = || records().into_iter().filter(|r| r.key.sizes == sizes && r.key.vector_reads && r.key.epilogue == epilogue.code() && r.key.ones_row == epilogue.ones_row()).collect::<Vec<_>>();
        assert!(mine().is_empty(), "{name}: not tuned before");
        let (tuned, tuned_sums) = product(&l, &r, TileChoice::Tuned { vector_reads: true }, epilogue);
        assert!(tuned.iter().zip(&by_shape).all(|(a, b)| a.to_bits() == b.to_bits()), "{name}: the tuned product's bits");
        assert_eq!(tuned_sums, sums, "{name}: the tuned product's sums");
        let recs = mine();
        assert_eq!(recs.len(), 1, "{name}: one product tuned");
        let rec = recs.last().unwrap();
        assert_eq!(rec.micros.iter().map(|(v, _)| *v).collect::<Vec<_>>(), variants, "{name}: every variant timed");
        assert!(rec.micros.iter().all(|(_, us)| us.is_finite() && *us > 0.0), "{name}: {:?}", rec.micros);
        let fastest = rec.micros.iter().min_by(|a, b| a.1.total_cmp(&b.1)).unwrap().0;
        assert_eq!(rec.chosen, fastest, "{name}: the fastest variant is chosen");
        // the second product of the shape takes the remembered pick without timing again
        let (again, _) = product(&l, &r, TileChoice::Tuned { vector_reads: true }, epilogue);
        assert_eq!(again, tuned, "{name}: the tuned product repeats");
        assert_eq!(mine().len(), 1, "{name}: no second timing of the shape");
    }
}

/// Row blocks stacked by the kernels of ours (`kernels::cat_rows`) give burn's cat bit for bit —
/// blocks of different heights, one empty, in launches of every size the device's limit allows
/// down to one block — in ⌈blocks / launch⌉ launches, and refuse what they cannot bind.
#[test]
fn row_blocks_stack_as_cat_does_in_a_few_kernels() {
    use dextrain::gpu_counts::{Event, GpuCounts};
    use dextrain::learn::kernels::cat_rows::cat_rows;
    let Some((_ctx, gpu)) = crate::common::wgpu_learner("row_blocks_stack_as_cat_does_in_a_few_kernels") else { return };
    let dev = gpu.clone().inner();
    let mut rng = Rng::new(31, 2);
    let heights = [7usize, 300, 0, 64, 1, 129, 33];
    let parts: Vec<Tensor<2>> = heights.iter().map(|&h| to_tensor((0..h * 5).map(|_| rng.normal() as f32).collect(), [h, 5], &dev)).collect();
    let want = to_host(Tensor::cat(parts.clone(), 0)).unwrap();
    for max_buffers in [2u32, 3, 4, 32] {
        let before = GpuCounts::now();
        let got = cat_rows(&parts, max_buffers).expect("contiguous f32 blocks of one width");
        let counts = GpuCounts::now().since(&before);
        assert_eq!(got.dims(), [heights.iter().sum::<usize>(), 5]);
        let got = to_host(got).unwrap();
        assert!(got.iter().zip(&want).all(|(a, b)| a.to_bits() == b.to_bits()), "{max_buffers} buffers: the values of cat");
        // launches of max − 1 blocks; a launch of the empty block alone is skipped
        let group = max_buffers as usize - 1;
        let launches: usize = heights.chunks(group).filter(|c| c.iter().any(|&h| h > 0)).count();
        assert_eq!(counts.total(Event::Kernel), launches as u64, "{max_buffers} buffers: {counts:?}");
    }
    assert!(cat_rows(&parts, 1).is_none(), "a device that binds one buffer");
    let wider = vec![parts[0].clone(), to_tensor(vec![0.0; 12], [2, 6], &dev)];
    assert!(cat_rows(&wider, 32).is_none(), "blocks of different widths");
    assert!(cat_rows(&[parts[1].clone().transpose()], 32).is_none(), "a strided view");
    assert!(cat_rows(&[], 32).is_none(), "no block");
}

/// An MLP's ELU layers linked (`affine::EluLink`: the layer after an ELU layer applies its
/// gradient, on the GPU in the input gradient's product) give the gradients of the layers unlinked
/// bit for bit — on the CPU and on the GPU, where the linked backward pass launches no ELU
/// gradient kernel and one product per layer for its weight and bias gradients — and the GPU's
/// agree with the CPU's.
#[test]
fn linked_elu_layers_give_the_unlinked_gradients_in_fewer_kernels() {
    use dextrain::gpu_counts::{Event, GpuCounts};
    use dextrain::learn::kernels::affine::{fused_affine, fused_affine_elu};
    use dextrain::learn::nets::{Activation, init_mlp, mlp_forward, mlp_shapes};
    let Some((_ctx, gpu)) = crate::common::wgpu_learner("linked_elu_layers_give_the_unlinked_gradients_in_fewer_kernels") else { return };
    let mut rng = Rng::new(29, 7);
    // 600 rows: the first layer's weight gradient is split over k, the others' too
    let (rows, shapes) = (600usize, mlp_shapes(24, &[40, 36], 5));
    let params_host = init_mlp(&shapes, &mut rng);
    let x_host: Vec<f32> = (0..rows * 24).map(|_| 2.0 * rng.normal() as f32).collect();
    let c_host: Vec<f32> = (0..rows * 5).map(|_| rng.normal() as f32).collect();
    // the input's and every parameter's gradient of Σ c ⊙ MLP(x), and the backward pass's counts
    let grads_on = |device: &Device, linked: bool| -> (Vec<Vec<f32>>, GpuCounts) {
        let params: Vec<Tensor<2>> = params_host.iter().zip(&shapes).map(|(v, s)| to_tensor(v.clone(), *s, device).require_grad()).collect();
        let x = to_tensor(x_host.clone(), [rows, 24], device).require_grad();
        let y = if linked {
            mlp_forward(&params, x.clone(), Activation::Elu)
        } else {
            let mut h = x.clone();
            for l in 0..params.len() / 2 {
                let (w, b) = (params[2 * l].clone(), params[2 * l + 1].clone());
                h = if 2 * l + 2 < params.len() { fused_affine_elu(h, w, b) } else { fused_affine(h, w, b) };
            }
            h
        };
        let loss = (y * to_tensor(c_host.clone(), [rows, 5], device)).sum();
        let before = GpuCounts::now();
        let grads = loss.backward();
        let out: Vec<Vec<f32>> = std::iter::once(&x).chain(&params).map(|t| to_host(t.grad(&grads).expect("a gradient")).unwrap()).collect();
        (out, GpuCounts::now().since(&before))
    };
    let bits = |v: &[Vec<f32>]| v.iter().map(|g| g.iter().map(|x| x.to_bits()).collect::<Vec<_>>()).collect::<Vec<_>>();
    let (cpu_linked, _) = grads_on(&cpu(), true);
    assert_eq!(bits(&cpu_linked), bits(&grads_on(&cpu(), false).0), "the CPU's linked layers change no bit");
    let ((linked, counts), (unlinked, counts_unlinked)) = (grads_on(&gpu, true), grads_on(&gpu, false));
    assert_eq!(bits(&linked), bits(&unlinked), "the GPU's linked layers change no bit");
    for (k, (g, c)) in linked.iter().zip(&cpu_linked).enumerate() {
        let worst = g.iter().zip(c).map(|(a, b)| (a - b).abs() / (1.0 + b.abs())).fold(0.0f32, f32::max);
        assert!(worst < 1e-4, "gradient {k} (x, then W, b per layer) differs from the CPU's by {worst}");
        assert!(g.iter().any(|v| *v != 0.0), "gradient {k} is not all zeros");
    }
    let kernels = |c: &GpuCounts, name: &str| c.by_source.get(&(Event::Kernel, format!("dextrain:{name}"))).copied().unwrap_or(0);
    // three layers: ∂x of the two after an ELU layer and of the first (the input is tracked), ∂W
    // with ∂b of each; ELU's gradient in the products
    assert_eq!((kernels(&counts, "elu_backward"), kernels(&counts_unlinked, "elu_backward")), (0, 2), "ELU's gradient kernels, linked and not");
    assert_eq!(kernels(&counts, "matmul"), 6, "one product per layer for ∂W and ∂b, one for ∂x: {counts:?}");
    assert_eq!(kernels(&counts, "column_sums"), 0, "the bias gradients come out of the weight gradients' products");
    assert_eq!(counts.total(Event::Kernel) + 2, counts_unlinked.total(Event::Kernel), "two kernels fewer than the unlinked layers'");
}

/// An MLP's forward pass for acting in one kernel (`learn::kernels::mlp_forward`, on the GPU) gives
/// the per-layer products' values bit for bit — hidden and output widths that are not multiples of
/// the kernel's tiles, rows that are not a multiple of its 32, one layer alone — in one launch, and
/// `nets::mlp_forward` takes it for acting; the CPU, autodiff parameters and other activations keep
/// the per-layer path.
#[test]
fn an_mlp_forward_in_one_kernel_gives_the_layers_bits() {
    use dextrain::gpu_counts::{Event, GpuCounts};
    use dextrain::learn::kernels::affine::{fused_affine, fused_affine_elu};
    use dextrain::learn::kernels::mlp_forward::{ActionNoise, MlpForwardMode, forward, forward_acting, takes};
    // the default (auto) takes the kernel for the lift configs' policies and leaves the PPO
    // bench's peer networks at 4,096 rows to the products; `fused` and `layers` always and never
    assert!(takes(MlpForwardMode::Auto, 2048, &[86, 256, 128, 64, 22]) && takes(MlpForwardMode::Auto, 2048, &[128, 256, 128, 64, 1]));
    assert!(!takes(MlpForwardMode::Auto, 4096, &[96, 512, 256, 128, 22]) && !takes(MlpForwardMode::Auto, 4096, &[130, 512, 256, 128, 1]));
    assert!(takes(MlpForwardMode::Fused, 4096, &[96, 512, 256, 128, 22]) && !takes(MlpForwardMode::Layers, 8, &[4, 8, 2]));
    use dextrain::learn::nets::{Activation, init_mlp, mlp_forward, mlp_shapes};
    let Some((_ctx, gpu)) = crate::common::wgpu_learner("an_mlp_forward_in_one_kernel_gives_the_layers_bits") else { return };
    let dev = gpu.clone().inner();
    let mut rng = Rng::new(23, 5);
    for (rows, input, hidden, output) in [(300usize, 45usize, vec![70usize, 33], 22usize), (1000, 96, vec![130, 64, 16], 22), (77, 5, vec![], 1), (33, 128, vec![256, 128, 64], 1)] {
        let shapes = mlp_shapes(input, &hidden, output);
        let params: Vec<Tensor<2>> = init_mlp(&shapes, &mut rng).into_iter().zip(&shapes).map(|(v, s)| to_tensor(v, *s, &dev)).collect();
        let x_host: Vec<f32> = (0..rows * input).map(|_| 2.0 * rng.normal() as f32).collect();
        let x = to_tensor(x_host.clone(), [rows, input], &dev);
        // the per-layer path: one of dextrain's products per layer, bias and ELU in its epilogue
        let mut h = x.clone();
        for l in 0..params.len() / 2 {
            let (w, b) = (params[2 * l].clone(), params[2 * l + 1].clone());
            h = if 2 * l + 2 < params.len() { fused_affine_elu(h, w, b) } else { fused_affine(h, w, b) };
        }
        let want = to_host(h).unwrap();
        let before = GpuCounts::now();
        let got = forward(&params, &x, Activation::Elu).expect("the fused kernel takes the MLP");
        let counts = GpuCounts::now().since(&before);
        let got = to_host(got).unwrap();
        let ours = counts.by_source.get(&(Event::Kernel, "dextrain:mlp_forward".to_string())).copied();
        assert_eq!((counts.total(Event::Kernel), ours), (1, Some(1)), "{rows} × {input} → {hidden:?} → {output}: one launch, ours: {counts:?}");
        assert_eq!(got.len(), rows * output);
        let differing = got.iter().zip(&want).filter(|(a, b)| a.to_bits() != b.to_bits() && !(**a == 0.0 && **b == 0.0)).count();
        assert_eq!(differing, 0, "{rows} × {input} → {hidden:?} → {output}: {differing} entries differ from the layers' (e.g. {:?} vs {:?})", &got[..4.min(got.len())], &want[..4.min(want.len())]);
        assert!(got.iter().any(|v| *v != 0.0), "a forward pass that computed something");
        // nets::mlp_forward acts with it; the CPU's values agree to rounding
        assert_eq!(to_host(mlp_forward(&params, x.clone(), Activation::Elu)).unwrap(), got, "mlp_forward acts through the kernel");
        let cpu_params: Vec<Tensor<2>> = params.iter().map(|p| to_tensor(to_host(p.clone()).unwrap(), p.dims(), &cpu())).collect();
        let on_cpu = to_host(mlp_forward(&cpu_params, to_tensor(x_host, [rows, input], &cpu()), Activation::Elu)).unwrap();
        let worst = got.iter().zip(&on_cpu).map(|(a, b)| (a - b).abs() / (1.0 + b.abs())).fold(0.0f32, f32::max);
        assert!(worst < 1e-4, "the GPU's forward pass differs from the CPU's by {worst}");
        // parameters under autodiff (an update's forward pass) are not the kernel's
        let tracked: Vec<Tensor<2>> = params.iter().map(|p| p.clone().autodiff().require_grad()).collect();
        assert!(forward(&tracked, &x, Activation::Elu).is_none(), "autodiff parameters take the layers' path");
        assert!(forward(&params, &x, Activation::Relu).is_none(), "ReLU layers take the layers' path");
        // an input with autodiff in no graph (a device-resident rollout's) is a constant: the
        // kernel, its output with autodiff as the layers' would be; a tracked input is not
        let y = forward(&params, &x.clone().autodiff(), Activation::Elu).expect("an untracked autodiff input takes the kernel");
        assert!(y.is_autodiff() && to_host(y).unwrap() == got, "the same values, with autodiff");
        assert!(forward(&params, &x.clone().autodiff().require_grad(), Activation::Elu).is_none(), "a tracked input takes the layers' path");
        // a policy's actions in the same kernel: μ as above and a = μ + σ ε from this step's rows
        // (from `first_row` on) of a block of draws, as the tensor ops give it
        let eps_host: Vec<f32> = (0..3 * rows * output).map(|_| rng.normal() as f32).collect();
        let eps = to_tensor(eps_host, [3 * rows, output], &dev);
        let sigma = to_tensor((0..output).map(|c| 0.2 + 0.1 * c as f32).collect(), [1, output], &dev);
        let (mu, actions) = forward_acting(&params, &x, Activation::Elu, Some(ActionNoise { sigma: &sigma, eps: &eps, first_row: rows })).expect("the kernel with the actions");
        assert_eq!(to_host(mu.clone()).unwrap(), got, "μ with the actions");
        let want_a = to_host(mu + sigma.clone() * eps.clone().narrow(0, rows, rows)).unwrap();
        let got_a = to_host(actions.expect("the actions")).unwrap();
        let worst = got_a.iter().zip(&want_a).map(|(a, b)| (a - b).abs() / (1.0 + b.abs())).fold(0.0f32, f32::max);
        assert!(worst <= 2.0 * f32::EPSILON, "a = μ + σ ε differs from the tensor ops' by {worst}");
        assert!(forward_acting(&params, &x, Activation::Elu, Some(ActionNoise { sigma: &sigma, eps: &eps, first_row: 2 * rows + 1 })).is_none(), "rows past the block's end");
    }
}
