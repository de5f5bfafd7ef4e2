//! `dextrain play EXPORT/policy.json [--episodes N] [--seed S] [--backend …]`: drives the
//! simulator from an export's files alone — the ONNX model, and the contract's observation
//! fields, history layout and action mapping (`controller`) — on the world the export names
//! (`world.toml` beside it: hand, object, task, references, randomisation; its learner settings
//! are not read). It runs eval's episodes (the same seeds, one episode per env, the same
//! metrics) and prints the same JSON report as `dextrain eval`, so the two can be compared: equal
//! outcomes prove that `policy.json` holds everything a robot needs.

use std::path::PathBuf;

use anyhow::{Context, Result};

use crate::export::command::WORLD_FILE;
use crate::export::contract::PolicyContract;
use crate::config::Config;
use super::{Driver, EvalArgs, EvalReport, PolicySource, check_finite, film, run_episodes_filmed};

/// `dextrain play`.
#[derive(clap::Args, Debug, Clone)]
pub struct PlayArgs {
    /// The export's contract (runs/NAME/export/policy.json); policy.onnx and world.toml lie beside it.
    pub contract: PathBuf,
    /// Number of episodes (one per env).
    #[arg(long, default_value_t = 100)]
    pub episodes: usize,
    /// Most envs stepped at once.
    #[arg(long, default_value_t = 1024)]
    pub max_envs: usize,
    /// Seed of the episodes (default: the world's seed + 1000003, as `dextrain eval`).
    #[arg(long)]
    pub seed: Option<u32>,
    /// Env backend (overrides the world's): cpu, gpu, gpu:NAME or auto.
    #[arg(long)]
    pub backend: Option<crate::config::BackendChoice>,
    /// Record env 0's episode to this MCAP file.
    #[arg(long)]
    pub record: Option<PathBuf>,
    /// The live view (`--live`…), as `dextrain eval`'s.
    #[command(flatten)]
    pub live: crate::live::LiveArgs,
    /// `--video`: render the first envs' episodes to a video.
    #[command(flatten)]
    pub video: crate::video::VideoArgs,
}

/// Runs `dextrain play`: the report (not written anywhere: the caller prints it).
pub fn run(args: &PlayArgs) -> Result<EvalReport> {
    let contract = PolicyContract::read(&args.contract)?;
    let dir = args.contract.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(std::path::Path::new("."));
    let world = dir.join(WORLD_FILE);
    let mut cfg = Config::load(&world).with_context(|| format!("the world of {}", args.contract.display()))?;
    let seed = args.seed.unwrap_or(cfg.seed.wrapping_add(1_000_003));
    cfg.seed = seed;
    if let Some(b) = &args.backend {
        cfg.sim.backend = b.clone();
    }
    let eval_args = EvalArgs {
        run: dir.to_path_buf(),
        checkpoint: "export".into(),
        episodes: args.episodes,
        max_envs: args.max_envs,
        seed: Some(seed),
        record: args.record.clone(),
        backend: args.backend.clone(),
        baseline: None,
        live: args.live.clone(),
        video: args.video.clone(),
    };
    // a bad --video fails before the episodes run
    let video_envs = args.video.episodes_to_film()?;
    let video_ctx = args.video.render_context()?;
    let (policy, env_backend, device, filmed) = run_episodes_filmed(&cfg, PolicySource::Export(&args.contract), &eval_args, Driver::Policy, video_envs)?;
    if let (Some(path), Some(ctx)) = (&args.video.video, video_ctx) {
        film(path, &args.video, filmed, ctx, None)?;
    }
    let report = EvalReport {
        run: contract.source.run.clone(),
        checkpoint: format!("{} (exported: {})", contract.source.checkpoint, args.contract.display()),
        iteration: contract.source.checkpoint,
        seed,
        episodes: policy.per_episode.len(),
        task: cfg.task.kind.to_string(),
        env_backend,
        learner_device: device,
        policy,
        baseline: None,
        baseline_kind: String::new(),
        path: PathBuf::new(),
    };
    check_finite(&report, "play report")?;
    Ok(report)
}
