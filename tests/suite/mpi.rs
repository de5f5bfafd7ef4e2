//! Data-parallel training with MPI (issue 37). Without the `mpi` feature: a run trained on several
//! ranks resumes only with that many (a one-line error otherwise), and the ranks' minibatches are
//! the one process's split by env. With it (`cargo test --release --features mpi mpi::`, MPICH's
//! `mpiexec` on the PATH): `mpiexec -n 2 dextrain train` keeps the ranks' parameters and
//! normalisers identical while their envs differ (PPO, SAC, distillation), drifts apart without
//! the gradients' mean, resumes exactly, computes with 2 × 128 envs what one process computes
//! with 256, and after a rank is killed resumes from the newest checkpoint both ranks hold.

use std::path::Path;
use std::process::Command;

const ROOT: &str = env!("CARGO_MANIFEST_DIR");

/// A run directory that ranks 0 and 1 trained (rank 1's `ranks/1/` beside rank 0's files),
/// resumed by one process: the error names the run and the number of ranks to resume with.
#[test]
fn a_run_of_two_ranks_resumed_by_one_process_is_a_one_line_error() {
    let tmp = tempfile::tempdir().unwrap();
    let run = tmp.path().join("two");
    std::fs::create_dir_all(run.join("ranks/1")).unwrap();
    let cfg = std::fs::read_to_string(Path::new(ROOT).join("configs/lift_cube_cpu.toml")).unwrap();
    std::fs::write(run.join("config.toml"), &cfg).unwrap();
    std::fs::write(run.join("ranks/1/config.toml"), &cfg).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_dextrain")).args(["train", "--resume"]).arg(&run).current_dir(ROOT).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(err.contains("trained with 2 rank(s) and is resumed with 1") && err.contains("mpiexec -n 2"), "{err}");
    assert_eq!(err.trim().lines().count(), 1, "{err}");
}

/// The minibatches of a data-parallel update (`learn::ppo::minibatch_rows`): with one rank, the
/// rollout's permutation cut into minibatches (the same draws as before ranks existed); split
/// over ranks, each minibatch's rows on the ranks, mapped back to the job's rows, are that
/// minibatch's rows of the one process, and the ranks' weights (their shares × ranks) average 1;
/// a rank with no row in a minibatch weighs 0 and holds one stand-in row.
#[test]
fn the_ranks_minibatches_are_the_one_process_minibatches_split_by_env() {
    use dextrain::learn::ppo::minibatch_rows;
    use dextrain::rng::Rng;
    let (epochs, minibatches, steps, job_envs) = (3, 4, 5, 12);
    let one = minibatch_rows(&mut Rng::new(9, 1), epochs, minibatches, steps, job_envs, 0, job_envs);
    let mut rng = Rng::new(9, 1);
    let plain: Vec<i32> = (0..epochs).flat_map(|_| rng.permutation(steps * job_envs)).map(|i| i as i32).collect();
    assert_eq!(one.rows, plain);
    assert_eq!(one.starts, (0..=epochs * minibatches).map(|k| k * steps * job_envs / minibatches).collect::<Vec<_>>());
    assert!(one.weights.iter().all(|&w| w == 1.0));
    for ranks in [2usize, 3, 4] {
        let envs = job_envs / ranks;
        let split: Vec<_> = (0..ranks).map(|r| minibatch_rows(&mut Rng::new(9, 1), epochs, minibatches, steps, envs, r * envs, job_envs)).collect();
        for k in 0..epochs * minibatches {
            let mut want: Vec<i32> = one.rows[one.starts[k]..one.starts[k + 1]].to_vec();
            let mut got = Vec::new();
            let mut weight = 0.0;
            for (r, m) in split.iter().enumerate() {
                let rows = &m.rows[m.starts[k]..m.starts[k + 1]];
                if m.weights[k] > 0.0 {
                    // rank r's row t·E + i is the job's row t·job_envs + r·E + i
                    got.extend(rows.iter().map(|&x| ((x as usize / envs) * job_envs + r * envs + x as usize % envs) as i32));
                    assert_eq!(m.weights[k], (rows.len() * ranks) as f32 / want.len() as f32);
                }
                weight += m.weights[k];
            }
            want.sort();
            got.sort();
            assert_eq!(got, want, "{ranks} ranks, minibatch {k}");
            assert!((weight / ranks as f32 - 1.0).abs() < 1e-6, "{ranks} ranks, minibatch {k}: weights {weight}");
        }
    }
    // 12 ranks of 1 env, minibatches of one row: one rank holds it, the others a stand-in at 0
    let lone: Vec<_> = (0..12).map(|r| minibatch_rows(&mut Rng::new(9, 1), 1, 12, 1, 1, r, 12)).collect();
    for k in 0..12 {
        let holders: Vec<usize> = (0..12).filter(|&r| lone[r].weights[k] > 0.0).collect();
        assert_eq!(holders.len(), 1);
        assert_eq!(lone[holders[0]].weights[k], 12.0);
        assert!((0..12).all(|r| lone[r].starts[k + 1] - lone[r].starts[k] == 1));
    }
}

/// A build without MPI started by a launcher as one of 2 processes (`PMI_SIZE=2`) would train
/// two copies of one run, each alone: it stops with a one-line error saying how to build with MPI,
/// and writes nothing; started as one of 1 it trains as ever.
#[cfg(not(feature = "mpi"))]
#[test]
fn a_build_without_mpi_launched_as_one_of_two_is_a_one_line_error() {
    let tmp = tempfile::tempdir().unwrap();
    let runs = tmp.path().join("runs");
    let train = |size: &str| {
        Command::new(env!("CARGO_BIN_EXE_dextrain"))
            .args(["train", "configs/lift_cube_cpu.toml", "--runs-dir"])
            .arg(&runs)
            .args(["--name", "n", "--quiet", "--set", "train.iterations=1", "--set", "sim.num_envs=16", "--set", "train.steps_per_env=2"])
            .args(["--set", "policy.actor_hidden=[16]", "--set", "policy.critic_hidden=[16]", "--set", "sim.backend=cpu", "--set=train.device=cpu"])
            .env("PMI_RANK", "0")
            .env("PMI_SIZE", size)
            .current_dir(ROOT)
            .output()
            .unwrap()
    };
    let out = train("2");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{err}");
    assert!(err.contains("PMI_SIZE=2") && err.contains("built without MPI") && err.contains("--features mpi"), "{err}");
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(!runs.exists(), "a run directory was written");
    let out = train("1");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert!(runs.join("n/checkpoints").is_dir());
}

#[cfg(feature = "mpi")]
mod with_mpi {
    use super::ROOT;
    use std::path::Path;
    use std::process::Command;

    /// A small lift run on the CPU: 64 envs × 8 steps per rank, [32] networks.
    const TINY: [&str; 12] = [
        "--quiet",
        "--set",
        "sim.num_envs=64",
        "--set",
        "train.steps_per_env=8",
        "--set",
        "policy.actor_hidden=[32]",
        "--set",
        "policy.critic_hidden=[32]",
        "--set",
        "sim.backend=cpu",
        "--set=train.device=cpu",
    ];

    /// `mpiexec -n 2 dextrain ARGS` (with `env` set): the exit status and each rank's summary
    /// line (rank order).
    fn mpiexec(args: &[&str], env: &[(&str, &str)]) -> (bool, Vec<serde_json::Value>, String) {
        let launch = || {
            let mut cmd = Command::new("mpiexec");
            cmd.args(["-n", "2", env!("CARGO_BIN_EXE_dextrain")]).args(args).current_dir(ROOT);
            for (k, v) in env {
                cmd.env(k, v);
            }
            cmd.output().expect("mpiexec on the PATH (MPICH: apt-get install mpich)")
        };
        let mut out = launch();
        for _ in 0..2 {
            if !launch_failed(&String::from_utf8_lossy(&out.stderr)) {
                break;
            }
            out = launch();
        }
        let stdout = String::from_utf8_lossy(&out.stdout);
        let mut ranks: Vec<serde_json::Value> = stdout.lines().filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok()).filter(|v| v.get("ranks").is_some()).collect();
        ranks.sort_by_key(|v| v["ranks"]["rank"].as_u64());
        (out.status.success(), ranks, format!("{}\nstdout: {}", String::from_utf8_lossy(&out.stderr), &stdout[..stdout.len().min(600)]))
    }

    fn train(runs: &Path, name: &str, iterations: u32, env: &[(&str, &str)]) -> Vec<serde_json::Value> {
        let runs = runs.display().to_string();
        let it = format!("train.iterations={iterations}");
        let mut args = vec!["train", "configs/lift_cube_cpu.toml", "--runs-dir", &runs, "--name", name, "--set", &it];
        args.extend(TINY);
        let (ok, ranks, err) = mpiexec(&args, env);
        assert!(ok && ranks.len() == 2, "mpiexec -n 2 dextrain train: success {ok}, {} summaries: {err}", ranks.len());
        ranks
    }

    /// The metrics columns that do not depend on the wall clock: iteration, env steps, and the
    /// reward, episode and learner columns.
    fn metrics(dir: &Path) -> Vec<String> {
        std::fs::read_to_string(dir.join("metrics.csv")).unwrap().lines().map(|l| l.split(',').enumerate().filter(|(i, _)| *i < 2 || *i >= 13).map(|(_, v)| v).collect::<Vec<_>>().join(",")).collect()
    }

    /// The parameters of a run's last checkpoint (`model.safetensors`: every f32 tensor, by name).
    fn parameters(run: &Path) -> Vec<(String, Vec<f32>)> {
        use dextrain::learn::state::TensorValues;
        let ckpt = dextrain::learn::checkpoint::find(run, "latest").unwrap();
        let state = dextrain::learn::checkpoint::read_learner_file(&ckpt.join("model.safetensors"), "model").unwrap();
        let mut out: Vec<(String, Vec<f32>)> = state.files[0]
            .tensors
            .iter()
            .filter_map(|t| match &t.values {
                TensorValues::F32(v) => Some((t.name.clone(), v.clone())),
                _ => None,
            })
            .collect();
        out.sort_by(|a, b| a.0.cmp(&b.0));
        out
    }

    /// The largest difference between two runs' parameters: over the tensors, ‖a − b‖ / ‖a‖.
    fn relative_difference(a: &[(String, Vec<f32>)], b: &[(String, Vec<f32>)]) -> f64 {
        assert_eq!(a.iter().map(|t| &t.0).collect::<Vec<_>>(), b.iter().map(|t| &t.0).collect::<Vec<_>>());
        let norm = |v: &mut dyn Iterator<Item = f64>| v.map(|x| x * x).sum::<f64>().sqrt();
        a.iter()
            .zip(b)
            .map(|((_, x), (_, y))| norm(&mut x.iter().zip(y).map(|(p, q)| *p as f64 - *q as f64)) / norm(&mut x.iter().map(|p| *p as f64)).max(1e-12))
            .fold(0.0, f64::max)
    }

    /// Issue 37: 2 ranks × 128 envs compute the updates 1 process × 256 envs computes. Every env is
    /// keyed by its global id (rank 1's env i is the one process's env 128 + i: the same
    /// randomisation, observation and action noise), the minibatches are cut from one permutation
    /// of the job's rows, each rank's loss weighted by its share of the minibatch, and the
    /// gradients, normaliser and advantage statistics summed over the ranks: after 3 updates the
    /// parameters agree to 1e-5 (measured: 9e-7; float rounding, the sums run in another order).
    /// Without the gradients' mean they differ by 0.7. Rollouts of 2 steps keep the hands off the
    /// cube, and the learning rate is fixed: a contact, a termination or the adaptive schedule's
    /// ×1.5 / ÷1.5 at a KL threshold that rounding tips one way makes any two runs that differ in
    /// rounding diverge (docs/mpi.md).
    #[test]
    fn two_ranks_of_128_envs_train_as_one_process_of_256() {
        let tmp = tempfile::tempdir().unwrap();
        let runs = tmp.path().display().to_string();
        let common = [
            "--set", "train.iterations=3", "--set", "train.steps_per_env=2", "--set", "ppo.schedule=\"fixed\"", "--set", "policy.actor_hidden=[32]",
            "--set", "policy.critic_hidden=[32]", "--set", "sim.backend=cpu", "--set=train.device=cpu", "--quiet",
        ];
        let one = Command::new(env!("CARGO_BIN_EXE_dextrain"))
            .args(["train", "configs/lift_cube_cpu.toml", "--runs-dir", &runs, "--name", "one", "--set", "sim.num_envs=256"])
            .args(common)
            .current_dir(ROOT)
            .output()
            .unwrap();
        assert!(one.status.success(), "{}", String::from_utf8_lossy(&one.stderr));
        let mut args = vec!["train", "configs/lift_cube_cpu.toml", "--runs-dir", &runs, "--name", "two", "--set", "sim.num_envs=128"];
        args.extend(common);
        let (ok, _, err) = mpiexec(&args, &[]);
        assert!(ok, "{err}");
        let (p1, p2) = (parameters(&tmp.path().join("one")), parameters(&tmp.path().join("two")));
        assert!(p1.len() >= 5, "{} tensors", p1.len());
        let d = relative_difference(&p1, &p2);
        eprintln!("1 × 256 against 2 × 128: largest relative parameter difference {d:.3e}");
        assert!(d <= 1e-5, "1 × 256 against 2 × 128: {d:.3e}");
        // each rank stepping on its own gradients: far from the one process
        args[5] = "apart";
        let (ok, _, err) = mpiexec(&args, &[("DEXTRAIN_TEST_NO_GRADIENT_MEAN", "1")]);
        assert!(ok, "{err}");
        let apart = relative_difference(&p1, &parameters(&tmp.path().join("apart")));
        eprintln!("without the gradients' mean: {apart:.3e}");
        assert!(apart > 1e-2, "without the gradients' mean: {apart:.3e}");
    }

    #[test]
    fn two_ranks_hold_the_same_parameters_on_different_envs_and_resume_exactly() {
        let tmp = tempfile::tempdir().unwrap();
        let runs = tmp.path();
        // 3 iterations: both ranks end with rank 0's parameters and normalisers, to the bit
        let ranks = train(runs, "a", 3, &[]);
        for r in &ranks {
            assert_eq!(r["ranks"]["size"], 2);
            assert_eq!(r["ranks"]["max_parameter_deviation"].as_f64(), Some(0.0), "{r}");
        }
        // on envs of their own (rank 1's are the job's envs 64–127): their rollouts differ
        let (m0, m1) = (metrics(&runs.join("a")), metrics(&runs.join("a/ranks/1")));
        assert_eq!(m0.len(), 4);
        assert_ne!(m0[1..], m1[1..], "rank 1 simulated the same envs as rank 0");
        assert_eq!(ranks[1]["run"].as_str().unwrap(), runs.join("a/ranks/1").display().to_string());
        // without the gradients' mean each rank steps on its own data: they drift apart
        let apart = train(runs, "b", 3, &[("DEXTRAIN_TEST_NO_GRADIENT_MEAN", "1")]);
        assert!(apart[0]["ranks"]["max_parameter_deviation"].as_f64().unwrap() > 1e-4, "{}", apart[0]);
        // 3 iterations, then resumed to 5, write what 5 in one go write, on both ranks
        let resumed = runs.join("a").display().to_string();
        let (ok, ranks, err) = mpiexec(&["train", "--resume", &resumed, "--set", "train.iterations=5", "--quiet"], &[]);
        assert!(ok && ranks.len() == 2, "resume failed: {err}");
        train(runs, "c", 5, &[]);
        assert_eq!(metrics(&runs.join("a")), metrics(&runs.join("c")));
        assert_eq!(metrics(&runs.join("a/ranks/1")), metrics(&runs.join("c/ranks/1")));
    }

    /// Distillation on 2 ranks: a teacher trained by one process, its student distilled by 2
    /// ranks, each on its own envs (β drawn per rank): every minibatch's student gradients are
    /// averaged, so both ranks end with rank 0's student and Adam moments to the bit; without the
    /// mean they drift apart.
    #[test]
    fn two_ranks_distill_one_student() {
        let tmp = tempfile::tempdir().unwrap();
        let runs = tmp.path().display().to_string();
        let tiny = [
            "--set", "sim.num_envs=16", "--set", "task.episode_length=6", "--set", "train.steps_per_env=4", "--set", "policy.actor_hidden=[16]",
            "--set", "policy.critic_hidden=[16]", "--set", "randomization.object_mass=[0.5, 1.5]", "--set", "sim.backend=cpu", "--set=train.device=cpu", "--quiet",
        ];
        // a teacher with a privileged encoder: the student's adaptation module has a latent to learn
        let encoder = ["--set", "policy.encoder.inputs=[\"obj_mass\", \"obj_vel\", \"tip_contact\"]", "--set", "policy.encoder.hidden=[8]", "--set", "policy.encoder.latent=3"];
        let teacher = Command::new(env!("CARGO_BIN_EXE_dextrain"))
            .args(["train", "configs/lift_cube_cpu.toml", "--runs-dir", &runs, "--name", "teacher", "--set", "train.iterations=2"])
            .args(tiny)
            .args(encoder)
            .current_dir(ROOT)
            .output()
            .unwrap();
        assert!(teacher.status.success(), "{}", String::from_utf8_lossy(&teacher.stderr));
        let teacher_dir = format!("distill.teacher=\"{}\"", tmp.path().join("teacher").display());
        let student = |name: &str, env: &[(&str, &str)]| {
            let mut args = vec!["train", "configs/lift_cube_cpu.toml", "--runs-dir", &runs, "--name", name, "--set", "train.iterations=3", "--set", "train.algorithm=\"distill\"", "--set", &teacher_dir];
            args.extend(["--set", "distill.history_len=4", "--set", "distill.gru_hidden=8", "--set", "distill.beta_iterations=2", "--set", "distill.epochs=2", "--set", "distill.minibatches=2"]);
            args.extend(tiny);
            let (ok, ranks, err) = mpiexec(&args, env);
            assert!(ok && ranks.len() == 2, "mpiexec -n 2 dextrain train (distill): success {ok}, {} summaries: {err}", ranks.len());
            ranks
        };
        for r in student("s", &[]) {
            assert_eq!(r["ranks"]["max_parameter_deviation"].as_f64(), Some(0.0), "{r}");
        }
        let apart = student("t", &[("DEXTRAIN_TEST_NO_GRADIENT_MEAN", "1")]);
        assert!(apart[0]["ranks"]["max_parameter_deviation"].as_f64().unwrap() > 1e-5, "{}", apart[0]);
    }

    /// True when a job's ranks stopped because MPI did not join them into the launcher's job
    /// (`dist::init`'s error): MPICH's `MPI_Init`, once in a few CI runs under load, started
    /// both processes of an `mpiexec -n 2` alone, each as rank 0 of 1 (they then trained one run
    /// directory at once, until one failed). That is the launcher's failure, which dextrain now
    /// reports and stops at before writing anything; the tests launch such a job again, noting it.
    fn launch_failed(stderr: &str) -> bool {
        let failed = stderr.contains("did not join the launcher's job");
        if failed {
            eprintln!("mpiexec: the ranks were not joined into one job (dist::init); launching again: {}", stderr.trim());
        }
        failed
    }

    /// Launched by a launcher that declares 2 processes (`PMI_RANK`, `PMI_SIZE`) but with no way
    /// to reach it (no `PMI_FD`), MPICH's `MPI_Init` makes the process rank 0 of 1: dextrain stops
    /// with a one-line error naming the declared size and writes no run directory (two such
    /// processes would otherwise both create and train the same run).
    #[test]
    fn a_rank_that_mpi_starts_alone_is_a_one_line_error() {
        let tmp = tempfile::tempdir().unwrap();
        let runs = tmp.path().join("runs");
        let out = Command::new(env!("CARGO_BIN_EXE_dextrain"))
            .args(["train", "configs/lift_cube_cpu.toml", "--runs-dir"])
            .arg(&runs)
            .args(["--name", "alone", "--set", "train.iterations=1"])
            .args(TINY)
            .env("PMI_RANK", "0")
            .env("PMI_SIZE", "2")
            .env_remove("PMI_FD")
            .env_remove("PMI_PORT")
            .current_dir(ROOT)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{err}");
        // one error line (the MPI library may add warnings of its own on other lines)
        let errors: Vec<&str> = err.lines().filter(|l| l.starts_with("error:")).collect();
        assert_eq!(errors.len(), 1, "{err}");
        assert!(errors[0].contains("PMI_SIZE=2") && errors[0].contains("rank 0 of 1") && errors[0].contains("did not join the launcher's job"), "{err}");
        assert!(!runs.exists(), "a run directory was written");
    }

    /// The PIDs of the processes whose command line mentions `marker` and whose environment says
    /// they are MPI rank `rank` (MPICH's launcher sets PMI_RANK).
    fn rank_pids(marker: &str, rank: usize) -> Vec<u32> {
        let want = format!("PMI_RANK={rank}");
        std::fs::read_dir("/proc")
            .unwrap()
            .filter_map(|e| e.ok()?.file_name().to_str()?.parse::<u32>().ok())
            .filter(|pid| {
                let cmd = std::fs::read(format!("/proc/{pid}/cmdline")).unwrap_or_default();
                let env = std::fs::read(format!("/proc/{pid}/environ")).unwrap_or_default();
                String::from_utf8_lossy(&cmd).contains(marker) && env.split(|b| *b == 0).any(|kv| kv == want.as_bytes())
            })
            .collect()
    }

    /// Issue 37: rank 1 killed (SIGKILL) mid-run ends the job — the launcher stops rank 0, nobody
    /// waits forever — and `--resume` with 2 ranks continues from the newest checkpoint both ranks
    /// hold (rank 0's newest two removed here, so that rank 1 must step back to it), exactly: the
    /// resumed run's metrics, on both ranks, are an uninterrupted run's.
    #[test]
    fn a_rank_killed_mid_run_ends_the_job_and_the_run_resumes_exactly() {
        let tmp = tempfile::tempdir().unwrap();
        let runs = tmp.path().display().to_string();
        let args = |name: &'static str| -> Vec<String> {
            let mut a: Vec<String> = ["train", "configs/lift_cube_cpu.toml", "--runs-dir", &runs, "--name", name, "--set", "train.iterations=150", "--set", "train.save_interval=1"]
                .iter()
                .map(|s| s.to_string())
                .collect();
            a.extend(TINY.iter().map(|s| s.to_string()));
            a
        };
        let job_log = tmp.path().join("k.stderr");
        let spawn = || {
            Command::new("mpiexec")
                .args(["-n", "2", env!("CARGO_BIN_EXE_dextrain")])
                .args(args("k"))
                .current_dir(ROOT)
                .stdout(std::process::Stdio::null())
                .stderr(std::fs::File::create(&job_log).unwrap())
                .spawn()
                .expect("mpiexec on the PATH")
        };
        let mut job = spawn();
        let mut launches = 1;
        // once rank 1 has checkpointed a few iterations, kill it
        let third = tmp.path().join("k/ranks/1/checkpoints/3/manifest.json");
        let start = std::time::Instant::now();
        while !third.exists() {
            if job.try_wait().unwrap().is_some() && launches < 3 && launch_failed(&std::fs::read_to_string(&job_log).unwrap_or_default()) {
                job = spawn();
                launches += 1;
            }
            assert!(start.elapsed().as_secs() < 120 && job.try_wait().unwrap().is_none(), "rank 1 wrote no third checkpoint: {}", std::fs::read_to_string(&job_log).unwrap_or_default());
            std::thread::sleep(std::time::Duration::from_millis(20));
        }
        let pids = rank_pids(&runs, 1);
        assert_eq!(pids.len(), 1, "rank 1's process: {pids:?}");
        assert!(Command::new("kill").args(["-9", &pids[0].to_string()]).status().unwrap().success());
        let killed_at = std::time::Instant::now();
        let status = loop {
            if let Some(s) = job.try_wait().unwrap() {
                break s;
            }
            if killed_at.elapsed().as_secs() > 60 {
                let _ = job.kill();
                panic!("the job did not end within 60 s of rank 1's death");
            }
            std::thread::sleep(std::time::Duration::from_millis(50));
        };
        assert!(!status.success(), "the job ended successfully with a rank killed");
        let done = |dir: &Path| std::fs::read_to_string(dir.join("metrics.csv")).unwrap().lines().count() - 1;
        assert!(done(&tmp.path().join("k")) < 150, "the run finished before the kill");
        // rank 0 was at most one checkpoint ahead of rank 1; without its newest two it is behind,
        // and rank 1 has to step back to rank 0's newest
        let ckpts = |dir: &Path| -> Vec<u64> {
            let mut v: Vec<u64> = std::fs::read_dir(dir.join("checkpoints")).unwrap().filter_map(|e| e.ok()?.file_name().to_str()?.parse().ok()).collect();
            v.sort();
            v
        };
        let mine = ckpts(&tmp.path().join("k"));
        for it in &mine[mine.len() - 2..] {
            std::fs::remove_dir_all(tmp.path().join("k/checkpoints").join(it.to_string())).unwrap();
        }
        let (k0, k1) = (mine[mine.len() - 3], *ckpts(&tmp.path().join("k/ranks/1")).last().unwrap());
        assert!(k0 < k1, "rank 0's newest {k0}, rank 1's {k1}");
        // resumed with 2 ranks: from the newest checkpoint both hold, to the end, exactly
        let resumed = tmp.path().join("k").display().to_string();
        let (ok, ranks, err) = mpiexec(&["train", "--resume", &resumed, "--quiet"], &[]);
        assert!(ok && ranks.len() == 2, "resume after the kill: {err}");
        assert!(err.contains(&format!("warning: rank 1 resumes from iteration {k0}, the newest checkpoint every rank holds (its own newest is {k1})")), "{err}");
        assert_eq!(ranks[0]["ranks"]["max_parameter_deviation"].as_f64(), Some(0.0));
        let whole: Vec<String> = args("u");
        let whole: Vec<&str> = whole.iter().map(|s| s.as_str()).collect();
        let (ok, _, err) = mpiexec(&whole, &[]);
        assert!(ok, "{err}");
        assert_eq!(metrics(&tmp.path().join("k")), metrics(&tmp.path().join("u")));
        assert_eq!(metrics(&tmp.path().join("k/ranks/1")), metrics(&tmp.path().join("u/ranks/1")));
    }

    /// SAC on 2 ranks: every gradient step (critics, actor, temperature) averages the ranks'
    /// gradients, each rank sampling its own envs' replay buffer, so the ranks hold rank 0's
    /// actor, critics, targets, log α and normalisers to the bit; without the mean they drift
    /// apart; a 3-iteration run resumed to 5 writes what 5 in one go write, on both ranks.
    #[test]
    fn two_sac_ranks_hold_the_same_parameters_and_resume_exactly() {
        let tmp = tempfile::tempdir().unwrap();
        let runs = tmp.path().display().to_string();
        let run = |name: &str, iterations: u32, env: &[(&str, &str)]| {
            let it = format!("train.iterations={iterations}");
            let args = [
                "train", "configs/lift_cube_sac_cpu.toml", "--runs-dir", &runs, "--name", name, "--set", &it, "--set", "sim.num_envs=32",
                "--set", "train.steps_per_env=4", "--set", "sac.batch_size=64", "--set", "sac.learning_starts=2", "--set", "sac.random_steps=2",
                "--set", "sac.buffer_capacity=64", "--set", "policy.actor_hidden=[32]", "--set", "policy.critic_hidden=[32]",
                "--set", "sim.backend=cpu", "--set=train.device=cpu", "--quiet",
            ];
            let (ok, ranks, err) = mpiexec(&args, env);
            assert!(ok && ranks.len() == 2, "mpiexec -n 2 dextrain train (SAC): success {ok}, {} summaries: {err}", ranks.len());
            ranks
        };
        for r in run("a", 3, &[]) {
            assert_eq!(r["ranks"]["max_parameter_deviation"].as_f64(), Some(0.0), "{r}");
        }
        let apart = run("b", 3, &[("DEXTRAIN_TEST_NO_GRADIENT_MEAN", "1")]);
        assert!(apart[0]["ranks"]["max_parameter_deviation"].as_f64().unwrap() > 1e-4, "{}", apart[0]);
        let resumed = tmp.path().join("a").display().to_string();
        let (ok, _, err) = mpiexec(&["train", "--resume", &resumed, "--set", "train.iterations=5", "--quiet"], &[]);
        assert!(ok, "resume failed: {err}");
        run("c", 5, &[]);
        assert_eq!(metrics(&tmp.path().join("a")), metrics(&tmp.path().join("c")));
        assert_eq!(metrics(&tmp.path().join("a/ranks/1")), metrics(&tmp.path().join("c/ranks/1")));
    }
}
