//! The PPO update with dextrain's flat-tensor MLPs and hand-written Adam against burn's own
//! `nn::Linear` modules and `optim::Adam`: the same data, losses, minibatches and learning rate,
//! timed in one process, alternating (issue 12, item 4: keep the faster, write the figures down).
//!
//! `cargo bench --bench nn_vs_flat` (env `NB_ENVS`, default 4096 × 24 steps: the PPO benchmark's
//! shape; `NB_REPS` timed repetitions after one warm-up, default 3; `RAYON_NUM_THREADS=1` for the
//! one-thread figure of BENCHMARKS.md). Prints one JSON line with the medians.
//! What burn's version leaves out that the flat one does (the global gradient-norm clip) favours
//! burn's side, not ours.
use std::time::Instant;

use burn::module::{Module, Param};
use burn::nn::{Linear, LinearConfig};
use burn::optim::{AdamConfig, GradientsParams};
use burn::prelude::*;
use burn::tensor::{Int, TensorData};
use dextrain::config::{PolicyConfig, PpoConfig};
use dextrain::learn::adam::{Adam, clipped_grads};
use dextrain::learn::nets::{Activation, to_host, to_tensor};
use dextrain::learn::ppo::{ActorCritic, Batch, Dims, ppo_losses};
use dextrain::rng::Rng;

/// The actor-critic as burn modules: actor and critic MLPs of `Linear` layers and the log-std.
#[derive(Module, Debug)]
struct NnActorCritic {
    actor: Vec<Linear>,
    log_std: Param<Tensor<2>>,
    critic: Vec<Linear>,
}

/// An MLP's forward pass: ELU between layers, none after the last.
fn mlp(layers: &[Linear], x: Tensor<2>) -> Tensor<2> {
    let mut h = x;
    for (l, lin) in layers.iter().enumerate() {
        h = lin.forward(h);
        if l + 1 < layers.len() {
            h = Activation::Elu.apply(h);
        }
    }
    h
}

/// `Linear` layers input → hidden… → out.
fn linears(input: usize, hidden: &[usize], out: usize, dev: &Device) -> Vec<Linear> {
    let mut w = vec![input];
    w.extend_from_slice(hidden);
    w.push(out);
    w.windows(2).map(|p| LinearConfig::new(p[0], p[1]).init(dev)).collect()
}

fn main() {
    nn_vs_flat();
}

fn nn_vs_flat() {
    let envs: usize = std::env::var("NB_ENVS").ok().and_then(|s| s.parse().ok()).unwrap_or(4096);
    let steps = 24;
    let (o, p, a) = (96, 130, 22);
    let hidden = vec![512, 256, 128];
    let reps: usize = std::env::var("NB_REPS").ok().and_then(|s| s.parse().ok()).unwrap_or(3);
    let dev = Device::flex().autodiff();
    let cfg = PpoConfig { learning_rate: 1e-3, ..PpoConfig::default() };
    let total = envs * steps;
    let mut rng = Rng::new(1, 1);
    let mut draw = |n: usize| -> Vec<f32> { (0..n).map(|_| rng.normal() as f32).collect() };
    let col = |v: Vec<f32>| to_tensor(v, [total, 1], &dev);
    let all = Batch {
        obs: to_tensor(draw(total * o), [total, o], &dev),
        priv_obs: to_tensor(draw(total * p), [total, p], &dev),
        actions: to_tensor(draw(total * a), [total, a], &dev),
        old_log_prob: col(draw(total).iter().map(|x| x - 30.0).collect()),
        old_mu: to_tensor(vec![0.0; total * a], [total, a], &dev),
        old_sigma: to_tensor(vec![1.0; total * a], [total, a], &dev),
        advantages: col(draw(total)),
        returns: col(draw(total)),
        old_values: col(vec![0.0; total]),
    };
    let mb = total / cfg.minibatches as usize;
    let pick = |idx: &Tensor<1, Int>| Batch {
        obs: all.obs.clone().select(0, idx.clone()),
        priv_obs: all.priv_obs.clone().select(0, idx.clone()),
        actions: all.actions.clone().select(0, idx.clone()),
        old_log_prob: all.old_log_prob.clone().select(0, idx.clone()),
        old_mu: all.old_mu.clone().select(0, idx.clone()),
        old_sigma: all.old_sigma.clone().select(0, idx.clone()),
        advantages: all.advantages.clone().select(0, idx.clone()),
        returns: all.returns.clone().select(0, idx.clone()),
        old_values: all.old_values.clone().select(0, idx.clone()),
    };
    let mut prng = Rng::new(5, 5);
    let mut perms = || -> Vec<Tensor<1, Int>> {
        let mut out = Vec::new();
        for _ in 0..cfg.epochs {
            let perm = prng.permutation(total);
            for m in 0..cfg.minibatches as usize {
                let idx: Vec<i64> = perm[m * mb..(m + 1) * mb].iter().map(|&i| i as i64).collect();
                out.push(Tensor::<1, Int>::from_data(TensorData::new(idx, [mb]), &dev));
            }
        }
        out
    };
    // flat
    let pol = PolicyConfig { actor_hidden: hidden.clone(), critic_hidden: hidden.clone(), ..PolicyConfig::default() };
    let mut r = Rng::new(3, 3);
    let mut net = ActorCritic::new(Dims { obs: o, priv_obs: p, act: a }, &pol, &[], &dev, &mut r).unwrap();
    let mut adam = Adam::new(&net.shapes(), &dev);
    // nn
    let mut nn = NnActorCritic {
        actor: linears(o, &hidden, a, &dev),
        log_std: Param::from_tensor(Tensor::zeros([1, a], &dev).require_grad()),
        critic: linears(p, &hidden, 1, &dev),
    };
    let mut optim = AdamConfig::new().with_epsilon(1e-8).init();
    let (mut flat_ms, mut nn_ms) = (Vec::new(), Vec::new());
    for rep in 0..reps + 1 {
        let idxs = perms();
        let t0 = Instant::now();
        for idx in &idxs {
            let b = pick(idx);
            let params = net.params.clone();
            let losses = ppo_losses(net.actor(&params, b.obs.clone(), b.priv_obs.clone()), net.log_std(&params), net.critic(&params, b.priv_obs.clone()), &b, &cfg);
            let s = to_host(Tensor::cat(vec![losses.kl.clone().inner(), losses.surrogate.clone().detach().inner()], 0)).unwrap();
            assert!(s[0].is_finite());
            let grads = losses.total.backward();
            let (gs, norm) = clipped_grads(&params, &grads, 1.0).unwrap();
            net.params = adam.step(&params, gs, 1e-3);
            to_host(norm).unwrap();
        }
        let flat = t0.elapsed().as_secs_f64() * 1e3;
        let t0 = Instant::now();
        for idx in &idxs {
            let b = pick(idx);
            let mu = mlp(&nn.actor, b.obs.clone());
            let v = mlp(&nn.critic, b.priv_obs.clone());
            let losses = ppo_losses(mu, nn.log_std.val(), v, &b, &cfg);
            let s = to_host(Tensor::cat(vec![losses.kl.clone().inner(), losses.surrogate.clone().detach().inner()], 0)).unwrap();
            assert!(s[0].is_finite());
            let grads = losses.total.backward();
            let gp = GradientsParams::from_grads(grads, &nn);
            nn = optim.step(1e-3, nn, gp);
        }
        let nnt = t0.elapsed().as_secs_f64() * 1e3;
        eprintln!("rep {rep}: flat {flat:.0} ms, burn nn {nnt:.0} ms");
        if rep > 0 {
            flat_ms.push(flat);
            nn_ms.push(nnt);
        }
    }
    flat_ms.sort_by(f64::total_cmp);
    nn_ms.sort_by(f64::total_cmp);
    let (f, n) = (flat_ms[flat_ms.len() / 2], nn_ms[nn_ms.len() / 2]);
    println!(
        "{}",
        serde_json::json!({"envs": envs, "steps": steps, "hidden": hidden, "epochs": cfg.epochs, "minibatches": cfg.minibatches,
            "flat_update_ms": f, "burn_nn_update_ms": n, "burn_nn_over_flat": n / f, "reps": reps})
    );
}
