//! Data-parallel training with MPI (issue 37). Without the `mpi` feature: a run trained on several
//! ranks resumes only with that many (a one-line error otherwise). With it (`cargo test --release
//! --features mpi mpi::`, MPICH's `mpiexec` on the PATH): `mpiexec -n 2 dextrain train` keeps the
//! ranks' parameters and normalisers identical while their envs differ, drifts apart without the
//! gradients' mean, and resumes exactly.

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
        let mut cmd = Command::new("mpiexec");
        cmd.args(["-n", "2", env!("CARGO_BIN_EXE_dextrain")]).args(args).current_dir(ROOT);
        for (k, v) in env {
            cmd.env(k, v);
        }
        let out = cmd.output().expect("mpiexec on the PATH (MPICH: apt-get install mpich)");
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
        // on envs of their own (rank 1 draws from seed + 1): their rollouts differ
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
        // SAC does not average over ranks yet: a one-line error before anything is written
        let runs_s = runs.display().to_string();
        let (ok, _, err) = mpiexec(&["train", "configs/lift_cube_sac_cpu.toml", "--runs-dir", &runs_s, "--name", "s", "--quiet"], &[]);
        assert!(!ok && err.contains("runs on one rank only so far"), "{err}");
        assert!(!runs.join("s").exists());
    }
}
