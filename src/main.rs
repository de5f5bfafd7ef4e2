//! The `dextrain` command line.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{Context, Result};
use clap::{Parser, Subcommand};

use dextrain::bench::{BenchOptions, bench_config, run_bench};
use dextrain::config::Config;
use dextrain::console;
use dextrain::learn::kernels::gpu_matmul::GpuMatmul;
use dextrain::env::{SimModel, make_env_batch};

#[derive(Parser)]
#[command(name = "dextrain", version, about = "Batched GPU/CPU simulator and trainer for dexterous robot hands")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Validate a config and print it resolved, with every default filled in (stdout), and the
    /// layout of the actor's and the critic's observations (stderr).
    Check {
        /// The TOML config file.
        config: PathBuf,
        /// Override a config value, as `train --set` does: `--set hand.urdf="/path/to/hand.urdf"`
        /// (repeatable).
        #[arg(long = "set", value_name = "KEY=VALUE")]
        sets: Vec<String>,
    },
    /// Measure env-step throughput on the contact-rich benchmark scene (or, with --ppo / --sac,
    /// the learner update of the peer rsl_rl / skrl benchmark); prints one JSON line.
    Bench {
        /// Time a PPO update (4096 envs × 24 steps, obs 96, critic obs 130, 22 actions, [512, 256, 128]
        /// ELU, 5 epochs × 4 minibatches) on synthetic data instead of the simulator.
        #[arg(long, conflicts_with_all = ["sac", "matmul"])]
        ppo: bool,
        /// Time SAC's gradient step (replay of --envs × 64 transitions, obs 96, critic obs 130, 22
        /// actions, [512, 256, 128] ELU, 2 critics, learned α) on synthetic data.
        #[arg(long, conflicts_with = "matmul")]
        sac: bool,
        /// Time the GPU learner's matrix products (one PPO minibatch of --envs × 24 / 4 rows through
        /// the peer networks) with each matmul routine (`DEXTRAIN_GPU_MATMUL` names one for a run).
        #[arg(long)]
        matmul: bool,
        /// Matmul bench: the routines to time, comma-separated (default: every routine).
        #[arg(long, value_delimiter = ',', requires = "matmul")]
        routines: Vec<String>,
        /// Run the contact-fidelity scenes (a box sliding, on a tilting plane, tipped; a cube at
        /// rest; two fingertips squeezing a cube at 1, 5 and 10 N) on --backend (default cpu) and
        /// print their figures with the answers of statics; benches/contact_fidelity.sh compares
        /// them with MuJoCo's.
        #[arg(long, conflicts_with_all = ["ppo", "sac", "matmul"])]
        contacts: bool,
        /// Time the video of `--video` per frame: render (both views, readback, caption) and encode
        /// (MP4, or GIF with --video-format gif) --chunks × 24 frames of one env of the bench scene,
        /// on lavapipe unless --backend names an adapter (gpu, gpu:NAME).
        #[arg(long, conflicts_with_all = ["ppo", "sac", "matmul", "contacts"])]
        video: bool,
        /// Video bench: the encoder, mp4 or gif.
        #[arg(long, value_enum, default_value = "mp4", requires = "video")]
        video_format: dextrain::bench::VideoBenchFormat,
        /// Video bench: the size of each of the two views, WIDTHxHEIGHT.
        #[arg(long, default_value_t = dextrain::video::ViewSize::default(), requires = "video")]
        video_size: dextrain::video::ViewSize,
        /// SAC bench: transitions per gradient step.
        #[arg(long, default_value_t = 4096)]
        batch: usize,
        /// SAC bench: gradient steps per timed update.
        #[arg(long, default_value_t = 8)]
        gradient_steps: usize,
        /// SAC bench: transitions per return (`sac.n_step`; 1 is skrl's SAC, the shipped lift configs take 3).
        #[arg(long, default_value_t = 1, requires = "sac")]
        n_step: u32,
        /// SAC bench: LayerNorm after every hidden layer of the critics (`sac.critic_layer_norm`, as the shipped lift configs).
        #[arg(long, requires = "sac")]
        critic_layer_norm: bool,
        /// Worker threads of the CPU backends (default: one per core).
        #[arg(long)]
        threads: Option<usize>,
        /// PPO / SAC / matmul bench: learner device (cpu, gpu, gpu:NAME, auto).
        #[arg(long, default_value = "cpu")]
        device: dextrain::config::BackendChoice,
        /// PPO / SAC bench: timed iterations (after one warm-up); matmul bench: timed rounds per product.
        #[arg(long, default_value_t = 5)]
        iters: usize,
        /// A config file (default: the built-in scene of configs/bench_cube.toml).
        config: Option<PathBuf>,
        /// Backend: cpu, gpu, gpu:NAME or auto (overrides the config).
        #[arg(long)]
        backend: Option<dextrain::config::BackendChoice>,
        /// Number of envs (overrides the config).
        #[arg(long)]
        envs: Option<usize>,
        /// Least number of timed 24-step chunks.
        #[arg(long, default_value_t = 5)]
        chunks: usize,
        /// Least timed wall time (s).
        #[arg(long, default_value_t = 3.0)]
        seconds: f64,
        /// Env-step bench on a GPU backend: the simulator's WGSL module (shaders/common.wgsl,
        /// reset.wgsl and physics.wgsl concatenated, as the built-in one) read from this file, to
        /// time a variant of the physics shader on a GPU without rebuilding dextrain. It must bind
        /// and lay out its buffers as the built-in module does; the report names the file.
        #[arg(long, value_name = "FILE", conflicts_with_all = ["ppo", "sac", "matmul", "contacts", "video"])]
        physics_wgsl: Option<PathBuf>,
        /// Compile the simulator's and the task layer's kernels (or --physics-wgsl FILE's) on a
        /// Vulkan driver and print the statistics its compiler reports (registers, spills,
        /// scratch, instructions: the driver's names) instead of timing anything. --backend
        /// gpu:NAME picks the device (default: the first that reports them; lavapipe does not).
        /// Without an AMD GPU, RADV_FORCE_FAMILY=navi21 gives RADV's compiler (docs/gpu.md).
        #[arg(long, conflicts_with_all = ["ppo", "sac", "matmul", "contacts", "video"])]
        shader_stats: bool,
    },
    /// Train a policy with PPO from a TOML config (or resume a run).
    Train(dextrain::run::TrainArgs),
    /// Evaluate a run's checkpoint: deterministic episodes on fresh seeds, a JSON report in RUN/eval/.
    Eval {
        #[command(flatten)]
        args: dextrain::eval::EvalArgs,
        /// Also print every episode's row (`per_episode`) in the JSON on stdout (the report file
        /// always has them).
        #[arg(long)]
        episodes_json: bool,
    },
    /// Export a run's policy for a robot: RUN/export/policy.onnx (normalisation baked in) and
    /// policy.json (the contract: observation layout, action mapping, joints, timing), world.toml.
    Export(dextrain::export::command::ExportArgs),
    /// Drive the simulator from an export alone (policy.json, policy.onnx, world.toml): eval's
    /// episodes and JSON report, the exported model and the contract's action mapping acting.
    Play {
        #[command(flatten)]
        args: dextrain::eval::play::PlayArgs,
        /// Also print every episode's row (`per_episode`) in the JSON on stdout.
        #[arg(long)]
        episodes_json: bool,
    },
    /// Draw a run's learning curves (PNG) from its metrics.csv into RUN/plots/.
    Plot {
        /// The run directory (runs/NAME).
        run: PathBuf,
    },
    /// Replay a reference trajectory open-loop under the physics (or kinematically) and report tracking.
    Replay(dextrain::replay::ReplayArgs),
    /// Reference trajectories.
    Traj {
        #[command(subcommand)]
        command: TrajCommand,
    },
    /// Write a starter config for a hand URDF or an object mesh, every guess said.
    New {
        #[command(subcommand)]
        command: dextrain::starter::NewCommand,
    },
}

#[derive(Subcommand)]
enum TrajCommand {
    /// Write a scripted approach–grasp–lift reference for a config's hand and object.
    Synth(dextrain::synth::SynthArgs),
    /// Retarget a human demonstration (DexMV `.npz`, or dextrain `.csv` or `.mcap`: 21 keypoints
    /// and the object's pose per frame) to a config's hand: a reference on its table, its grasp
    /// closed on the object, and a JSON report.
    Retarget(dextrain::retarget::command::RetargetArgs),
}

fn load_config(path: &Path) -> Result<Config> {
    Config::load(path)
}

fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Check { config, sets } => {
            let cfg = Config::load_with_overrides(&config, &sets)?;
            // the hand must load too
            let model = SimModel::from_config(&cfg)?;
            let task = dextrain::task::task_setup(&cfg, &model)?.spec;
            console::result(cfg.to_toml()?.trim_end());
            console::status(&format!(
                "{}: ok ({} joints, {} actuated, {} colliders, {} fingertips; task {}: obs {}, critic obs {}, actions {})",
                config.display(),
                model.joints.len(),
                model.spec.actuated.len(),
                model.colliders.len(),
                model.tips.len(),
                cfg.task.kind,
                task.obs_dim,
                task.priv_dim,
                task.action_dim
            ));
            // what each mesh collision became (poor fits are also warnings, printed by from_config)
            if !model.hand.mesh_fits.is_empty() {
                console::status(&format!("mesh collision shapes ({}, hand.mesh_approx = {:?}):", model.hand.mesh_fits.len(), cfg.hand.mesh_approx));
                for fit in &model.hand.mesh_fits {
                    console::status(&format!("  {}{}", fit.describe(), if fit.is_poor() { "  [poor fit]" } else { "" }));
                }
            }
            // what each object became: pieces, fit quality, mass properties
            for o in &model.objects {
                console::status(o.describe().trim_end());
            }
            // what the policy sees: the actor's and the critic's observation layouts
            console::status(dextrain::task::spec::layout_table(&task.obs_layout, "actor observation").trim_end());
            console::status(dextrain::task::spec::layout_table(&task.priv_layout, "critic observation").trim_end());
            Ok(())
        }
        Command::Bench { ppo, sac, matmul, routines, contacts, video, video_format, video_size, batch, gradient_steps, n_step, critic_layer_norm, threads, device, iters, config, backend, envs, chunks, seconds, physics_wgsl, shader_stats } => {
            if let Some(t) = threads {
                rayon::ThreadPoolBuilder::new().num_threads(t.max(1)).build_global().context("cannot size the thread pool")?;
            }
            if ppo {
                let (dev, name, ctx) = dextrain::learn::device::learner_device_and_context(&device)?;
                let opts = dextrain::bench::PpoBenchOptions { envs: envs.unwrap_or(4096), iters: iters.max(1), ..Default::default() };
                let report = dextrain::bench::run_ppo_bench(&opts, dev, &name, ctx.as_ref())?;
                console::result(&serde_json::to_string(&report).context("cannot serialise the report")?);
                return Ok(());
            }
            if matmul {
                let (dev, name, _ctx) = dextrain::learn::device::learner_device_and_context(&device)?;
                anyhow::ensure!(dextrain::learn::nets::is_gpu(&dev), "bench --matmul: --device must be a GPU (got {name})");
                let rows = envs.unwrap_or(4096) * 24 / 4;
                let routines = if routines.is_empty() {
                    GpuMatmul::NAMES.iter().map(|(r, _)| *r).collect()
                } else {
                    let names: Vec<&str> = GpuMatmul::NAMES.iter().map(|(_, n)| *n).collect();
                    routines
                        .iter()
                        .map(|n| GpuMatmul::parse(n).map_err(|_| anyhow::anyhow!("bench --routines: {n:?} is not a routine; expected some of {}", names.join(", "))))
                        .collect::<anyhow::Result<Vec<_>>>()?
                };
                let report = dextrain::bench_matmul::run_matmul_bench(rows, 10, iters.max(1), &routines, dev, &name)?;
                console::result(&serde_json::to_string(&report).context("cannot serialise the report")?);
                return Ok(());
            }
            if sac {
                let (dev, name, ctx) = dextrain::learn::device::learner_device_and_context(&device)?;
                let opts = dextrain::bench::SacBenchOptions { envs: envs.unwrap_or(4096), iters: iters.max(1), batch: batch.max(1), gradient_steps: gradient_steps.max(1), n_step, critic_layer_norm, ..Default::default() };
                let report = dextrain::bench::run_sac_bench(&opts, dev, &name, ctx.as_ref())?;
                console::result(&serde_json::to_string(&report).context("cannot serialise the report")?);
                return Ok(());
            }
            if video {
                // the adapter: lavapipe unless --backend names another (gpu = the first hardware one)
                let ctx = match &backend {
                    Some(dextrain::config::BackendChoice::Gpu(name)) => dextrain::gpu::context::GpuContext::new(name.as_deref())?,
                    Some(other) => anyhow::bail!("bench --video: --backend {other:?}: expected gpu or gpu:NAME (the adapter that renders; lavapipe without --backend)"),
                    None => dextrain::gpu::context::GpuContext::new(Some("llvmpipe"))?,
                };
                let report = dextrain::bench::run_video_bench(chunks.max(1) * dextrain::bench::CHUNK_STEPS, video_size, video_format, ctx)?;
                console::result(&serde_json::to_string(&report).context("cannot serialise the report")?);
                return Ok(());
            }
            if contacts {
                let report = dextrain::bench_contacts::run_contact_bench(&backend.unwrap_or(dextrain::config::BackendChoice::Cpu))?;
                console::result(&serde_json::to_string(&report).context("cannot serialise the report")?);
                return Ok(());
            }
            if shader_stats {
                let adapter = match &backend {
                    None => None,
                    Some(dextrain::config::BackendChoice::Gpu(name)) => name.as_deref(),
                    Some(other) => anyhow::bail!("bench --shader-stats: --backend {other}: expected gpu or gpu:NAME (the Vulkan device whose compiler reports)"),
                };
                use dextrain::gpu::shader_stats::compile_stats;
                let mut report = match &physics_wgsl {
                    Some(path) => {
                        let source = std::fs::read_to_string(path).with_context(|| format!("bench --physics-wgsl {}: cannot read the file", path.display()))?;
                        let module = path.display().to_string();
                        let mut report = compile_stats(&source, &module, adapter, &|_| true)?.to_json();
                        report["module"] = serde_json::Value::String(module);
                        report
                    }
                    None => {
                        // the simulator's kernels, then the task layer's own (its module holds the
                        // simulator's too: those are not compiled twice)
                        let sim = compile_stats(&dextrain::gpu::shaders::shader_source(), "the simulator's module", adapter, &|_| true)?;
                        let task = compile_stats(&dextrain::task::shaders::task_shader_source(), "the task layer's module", adapter, &|e| e.starts_with("task_"))?;
                        let mut report = sim.to_json();
                        let kernels = report["kernels"].as_array_mut().expect("to_json lists the kernels");
                        kernels.iter_mut().for_each(|k| k["module"] = serde_json::Value::String("simulator".into()));
                        for mut k in task.to_json()["kernels"].as_array().cloned().unwrap_or_default() {
                            k["module"] = serde_json::Value::String("task".into());
                            kernels.push(k);
                        }
                        report["module"] = serde_json::Value::String("<built-in simulator and task modules>".into());
                        report
                    }
                };
                report["bench"] = serde_json::Value::String("shader_stats".into());
                console::result(&serde_json::to_string(&report).context("cannot serialise the report")?);
                return Ok(());
            }
            let mut cfg = match &config {
                Some(p) => load_config(p)?,
                None => bench_config(1024),
            };
            if let Some(b) = backend {
                cfg.sim.backend = b;
            }
            if let Some(n) = envs {
                cfg.sim.num_envs = n;
            }
            cfg.validate()?;
            let model = SimModel::from_config(&cfg)?;
            let mut env = match &physics_wgsl {
                None => make_env_batch(&cfg, model.clone())?,
                Some(path) => {
                    let flag = format!("bench --physics-wgsl {}", path.display());
                    let source = std::fs::read_to_string(path).with_context(|| format!("{flag}: cannot read the file"))?;
                    let Some(ctx) = dextrain::env::sim_gpu_context(&cfg)? else {
                        anyhow::bail!("{flag}: the env runs on the CPU (backend {}); expected --backend gpu or gpu:NAME", cfg.sim.backend)
                    };
                    Box::new(dextrain::env::gpu::GpuEnvBatch::with_physics_source(ctx, model.clone(), &source).with_context(|| flag.clone())?)
                }
            };
            let mut report = run_bench(env.as_mut(), &model, &BenchOptions { min_chunks: chunks, min_seconds: seconds })?;
            if let Some(path) = &physics_wgsl {
                report["physics_wgsl"] = serde_json::Value::String(path.display().to_string());
            }
            report["config"] = serde_json::Value::String(config.map(|p| p.display().to_string()).unwrap_or_else(|| "<bench scene>".into()));
            console::result(&serde_json::to_string(&report).context("cannot serialise the report")?);
            Ok(())
        }
        Command::Train(args) => dextrain::run::train(&args).map(|_| ()),
        Command::Eval { args, episodes_json } => {
            let report = dextrain::eval::run(&args)?;
            console::status(&dextrain::eval::human_summary(&report, args.record.as_deref()));
            console::result(&serde_json::to_string(&dextrain::eval::stdout_json(&report, episodes_json)?).context("cannot serialise the report")?);
            Ok(())
        }
        Command::Export(args) => {
            let report = dextrain::export::command::run(&args)?;
            console::result(&serde_json::to_string(&report).context("cannot serialise the report")?);
            Ok(())
        }
        Command::Play { args, episodes_json } => {
            let report = dextrain::eval::play::run(&args)?;
            console::status(&dextrain::eval::human_summary(&report, args.record.as_deref()));
            console::result(&serde_json::to_string(&dextrain::eval::stdout_json(&report, episodes_json)?).context("cannot serialise the report")?);
            Ok(())
        }
        Command::Plot { run } => {
            dextrain::run_dir::check_run(&run)?;
            for p in dextrain::plot::plot_run(&run.join("metrics.csv"), &run.join("plots"))? {
                console::result(&p.display().to_string());
            }
            Ok(())
        }
        Command::Replay(args) => dextrain::replay::run(&args),
        Command::Traj { command: TrajCommand::Synth(args) } => dextrain::synth::run(&args),
        Command::Traj { command: TrajCommand::Retarget(args) } => dextrain::retarget::command::run(&args),
        Command::New { command } => dextrain::starter::run(&command),
    }
}

fn main() -> ExitCode {
    // The Vulkan drivers' window-system code (Mesa's Wayland support) prints "error: XDG_RUNTIME_DIR
    // is invalid or not set in the environment." when it looks for a display on a machine without
    // that variable (a server, a container, CI), though dextrain opens no window. Point it at a
    // folder that does not exist: the drivers find no display there and stay quiet. Set here,
    // before any thread starts (changing the environment beside threads that read it is unsound).
    if std::env::var_os("XDG_RUNTIME_DIR").is_none_or(|v| !Path::new(&v).is_absolute()) {
        // SAFETY: no other thread exists yet
        unsafe { std::env::set_var("XDG_RUNTIME_DIR", std::env::temp_dir().join("dextrain-no-display")) };
    }
    // glibc serves blocks above 32 MiB with mmap and returns them on free, so every minibatch
    // page-faults its (≈50 MB) activations back in and the kernel zeroes them (18 % of a PPO update):
    // keep every block on the heap and never trim it
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    unsafe {
        libc::mallopt(libc::M_MMAP_MAX, 0);
        libc::mallopt(libc::M_TRIM_THRESHOLD, i32::MAX);
    }
    // an MPI job's rank joins it here (`--features mpi`, launched by mpiexec or srun); MPI is
    // finalised when `_mpi` drops at the end of main
    let _mpi = match dextrain::dist::init() {
        Ok(guard) => guard,
        Err(e) => {
            console::status(&format!("error: {}", dextrain::text::one_line(&format!("{e:#}"))));
            return ExitCode::FAILURE;
        }
    };
    match run(Cli::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            console::status(&format!("error: {}", dextrain::text::one_line(&format!("{e:#}"))));
            // in an MPI job the other ranks would wait for this one in their next collective
            dextrain::dist::abort_job(1);
            ExitCode::FAILURE
        }
    }
}
