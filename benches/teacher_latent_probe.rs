//! Does a teacher need its privileged latent? Runs the teacher of a distillation run on eval's
//! episodes (the run's seed + 1000003, one episode per env, no early termination, CPU backend)
//! three times: with its own latent ẑ = μ(ê), with each env's ẑ taken from the next env (a latent
//! of other physics), and with the batch mean of ẑ. Where the success does not drop, the latent
//! carries nothing the task needs, and no student can gain from reconstructing it (the λ2 = 0 and
//! no-history ablations of BENCHMARKS.md's distillation section).
//!
//! `cargo bench --bench teacher_latent_probe -- runs/STUDENT [episodes]` (default 64). Prints one
//! JSON line per latent: success rate, and the mean |Δa| / mean |a| of the actions against the
//! teacher's own on the same states.

use anyhow::{Context, Result, bail};
use burn::prelude::*;
use dextrain::config::Config;
use dextrain::env::SimModel;
use dextrain::learn::nets::{mlp_forward, to_host, to_tensor};
use dextrain::task::make_task_batch;

/// Which latent the teacher's actor reads.
#[derive(Clone, Copy)]
enum Latent {
    Own,
    NextEnvs,
    BatchMean,
}

fn main() -> Result<()> {
    // `cargo bench` passes `--bench` to a harness-less target: keep the positional arguments
    let args: Vec<String> = std::env::args().skip(1).filter(|a| !a.starts_with("--")).collect();
    let Some(run) = args.first().map(std::path::PathBuf::from) else { bail!("usage: teacher_latent_probe runs/STUDENT [episodes]") };
    let n: usize = match args.get(1) {
        Some(s) => s.parse().with_context(|| format!("episodes: {s:?} is not a number"))?,
        None => 64,
    };
    let mut cfg = Config::load(&run.join("config.toml"))?;
    cfg.seed = cfg.seed.wrapping_add(1_000_003);
    cfg.sim.num_envs = n;
    cfg.task.track.max_object_error = 0.0;
    cfg.sim.backend = dextrain::config::BackendChoice::Cpu;
    let dev = Device::flex();
    for (latent, name) in [(Latent::Own, "own"), (Latent::NextEnvs, "next_env"), (Latent::BatchMean, "batch_mean")] {
        let mut task = make_task_batch(&cfg, SimModel::from_config(&cfg)?)?;
        let spec = task.spec().clone();
        let teacher = dextrain::learn::distill::load_teacher(&cfg, &spec, &dev)?;
        let p = &teacher.ppo;
        let params = p.net.inference_params();
        let n_actor = p.net.actor_shapes.len();
        let first = task.reset_all()?.clone();
        let (mut obs, mut priv_obs) = (first.obs, first.priv_obs);
        let mut done = vec![false; n];
        let (mut successes, mut change, mut size) = (0usize, 0.0f64, 0.0f64);
        while done.iter().any(|d| !d) {
            let (mut o, mut c) = (obs.clone(), priv_obs.clone());
            if p.normalize {
                p.obs_norm.apply(&mut o);
                p.priv_norm.apply(&mut c);
            }
            let z = to_host(p.net.latent(&params, to_tensor(c, [n, spec.priv_dim], &dev)).context("the teacher has no encoder")?)?; // [N, L]
            let l = z.len() / n;
            let fed: Vec<f32> = match latent {
                Latent::Own => z.clone(),
                Latent::NextEnvs => (0..n).flat_map(|i| z[(i + 1) % n * l..((i + 1) % n + 1) * l].to_vec()).collect(),
                Latent::BatchMean => {
                    let mean: Vec<f32> = (0..l).map(|k| (0..n).map(|i| z[i * l + k]).sum::<f32>() / n as f32).collect();
                    (0..n).flat_map(|_| mean.clone()).collect()
                }
            };
            // the actor on [ŝ; z]: the teacher's own mean action, and the one it takes here
            let act = |zz: &[f32]| -> Result<Vec<f32>> {
                let x = Tensor::cat(vec![to_tensor(o.clone(), [n, spec.obs_dim], &dev), to_tensor(zz.to_vec(), [n, l], &dev)], 1);
                to_host(mlp_forward(&params[..n_actor], x, p.net.activation))
            };
            let (own, a) = (act(&z)?, act(&fed)?);
            let na = spec.action_dim;
            for i in (0..n).filter(|&i| !done[i]) {
                change += (i * na..(i + 1) * na).map(|j| (a[j] - own[j]).abs() as f64).sum::<f64>();
                size += (i * na..(i + 1) * na).map(|j| own[j].abs() as f64).sum::<f64>();
            }
            let b = task.step(&a)?;
            for i in 0..n {
                if !done[i] && b.done(i) {
                    done[i] = true;
                    successes += b.success[i] as usize;
                }
            }
            (obs, priv_obs) = (b.obs.clone(), b.priv_obs.clone());
        }
        let line = serde_json::json!({"run": run.display().to_string(), "latent": name, "episodes": n, "success_rate": successes as f64 / n as f64, "mean_abs_action_change_rel": change / size.max(1e-12)});
        println!("{line}");
    }
    Ok(())
}
