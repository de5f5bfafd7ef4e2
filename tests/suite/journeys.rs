//! Issue 40: every command of the documented journeys runs as written, in order, from a fresh
//! folder. A journey is a fenced block of README.md or docs/*.md that follows a
//! `<!-- journey: NAME -->` line; its commands are the block's lines that start with `dextrain `
//! (or the set-up's `cargo run --release -- `), a trailing `# comment` dropped. Each journey runs in
//! a temporary folder holding a copy of `configs/` (as a clean clone's root would; `../shared`
//! beside it, a link to the project's, for a journey that reads it — skipped, and said, on a
//! machine without it), through the built binary, with `XDG_RUNTIME_DIR` unset (as on a headless
//! machine).
//!
//! Only the sizes change ("tiny sizes"), by options appended to what is written: a training run
//! gets 2 iterations of 4 envs × 8 steps (and stops after 1 when the journey's next command
//! resumes it, as Ctrl-C would), eval and play 2 episodes, the env bench one short chunk, the PPO
//! bench 16 envs and one update. Every command must exit 0 and print no line that starts with
//! `error:`; the files its `--out`/`--record` name must exist afterwards.

use std::path::{Path, PathBuf};
use std::process::Command;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// One documented journey: where it is written and its commands (each split into arguments,
/// `dextrain` itself left out).
struct Journey {
    name: String,
    source: String,
    commands: Vec<Vec<String>>,
}

/// Splits a shell command line into words: whitespace separates, single and double quotes group
/// (and are removed), an unquoted `#` starts a comment.
fn shell_words(line: &str) -> Vec<String> {
    let (mut words, mut cur, mut quote, mut in_word) = (Vec::new(), String::new(), None::<char>, false);
    for c in line.chars() {
        match (quote, c) {
            (Some(q), c) if c == q => quote = None,
            (Some(_), c) => cur.push(c),
            (None, '"' | '\'') => {
                quote = Some(c);
                in_word = true;
            }
            (None, '#') if !in_word => break,
            (None, c) if c.is_whitespace() => {
                if in_word {
                    words.push(std::mem::take(&mut cur));
                    in_word = false;
                }
            }
            (None, c) => {
                cur.push(c);
                in_word = true;
            }
        }
    }
    if in_word {
        words.push(cur);
    }
    words
}

/// Every journey of README.md and docs/*.md.
fn journeys() -> Vec<Journey> {
    let mut files = vec![root().join("README.md")];
    let mut docs: Vec<PathBuf> = std::fs::read_dir(root().join("docs")).unwrap().map(|e| e.unwrap().path()).filter(|p| p.extension().is_some_and(|x| x == "md")).collect();
    docs.sort();
    files.extend(docs);
    let mut out = Vec::new();
    for file in files {
        let text = std::fs::read_to_string(&file).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        for (i, line) in lines.iter().enumerate() {
            let Some(name) = line.trim().strip_prefix("<!-- journey:").and_then(|r| r.strip_suffix("-->")) else { continue };
            let source = format!("{}:{}", file.strip_prefix(root()).unwrap().display(), i + 1);
            assert!(lines.get(i + 1).is_some_and(|l| l.trim_start().starts_with("```")), "{source}: a journey marker must be followed by a fenced block");
            let mut commands = Vec::new();
            for l in lines[i + 2..].iter().take_while(|l| !l.trim_start().starts_with("```")) {
                let t = l.trim();
                let rest = t.strip_prefix("dextrain ").or_else(|| t.strip_prefix("cargo run --release -- "));
                if let Some(rest) = rest {
                    commands.push(shell_words(rest));
                }
            }
            assert!(!commands.is_empty(), "{source}: a journey without dextrain commands");
            out.push(Journey { name: name.trim().to_string(), source, commands });
        }
    }
    out
}

/// The options that make a documented command tiny; `resumed_next`: the journey's next command
/// resumes this training run.
fn tiny(args: &[String], resumed_next: bool) -> Vec<String> {
    let has = |flag: &str| args.iter().any(|a| a == flag);
    let set = |kv: &str| ["--set".to_string(), kv.to_string()];
    let mut extra: Vec<String> = Vec::new();
    match args.first().map(String::as_str) {
        Some("train") if !has("--resume") => {
            for kv in ["train.iterations=2", "sim.num_envs=4", "train.steps_per_env=8"] {
                extra.extend(set(kv));
            }
            if resumed_next {
                extra.extend(["--stop-after".to_string(), "1".to_string()]);
            }
        }
        Some("eval" | "play") => extra.extend(["--episodes", "2", "--max-envs", "2"].map(String::from)),
        Some("bench") if has("--ppo") => extra.extend(["--envs", "16", "--iters", "1"].map(String::from)),
        Some("bench") if !has("--sac") && !has("--matmul") => extra.extend(["--envs", "64", "--chunks", "1", "--seconds", "0"].map(String::from)),
        _ => {}
    }
    extra
}

/// Copies the folder `from` into `to` (files and folders; symbolic links followed).
fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap() {
        let p = e.unwrap().path();
        let dest = to.join(p.file_name().unwrap());
        if p.is_dir() {
            copy_dir(&p, &dest);
        } else {
            std::fs::copy(&p, &dest).unwrap();
        }
    }
}

/// The files a command promises to write: the values of its `--out` and `--record`.
fn promised_files(args: &[String]) -> Vec<String> {
    args.windows(2).filter(|w| w[0] == "--out" || w[0] == "--record").map(|w| w[1].clone()).collect()
}

#[test]
fn documented_journeys_run_as_written() {
    let all = journeys();
    // the journeys that issue 40 names are documented and marked
    for name in ["set-up", "tour", "own-hand", "own-object", "residual", "distillation", "human-demo"] {
        assert!(all.iter().any(|j| j.name == name), "no journey {name:?} is marked in README.md or docs/");
    }
    let shared = root().join("../shared");
    for j in &all {
        // a checkout's copy with `../shared` beside it where the project's has one (the
        // human-demonstration journey reads its demo and mesh there)
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path().join("checkout");
        if j.commands.iter().flatten().any(|a| a.contains("../shared")) {
            if !shared.is_dir() {
                eprintln!("journey {:?} ({}) SKIPPED: it reads {}, which this machine lacks", j.name, j.source, shared.display());
                continue;
            }
            std::os::unix::fs::symlink(shared.canonicalize().unwrap(), tmp.path().join("shared")).unwrap();
        }
        copy_dir(&root().join("configs"), &dir.join("configs"));
        for (k, args) in j.commands.iter().enumerate() {
            let resumed_next = j.commands.get(k + 1).is_some_and(|n| n.first().is_some_and(|c| c == "train") && n.iter().any(|a| a == "--resume"));
            let mut full = args.clone();
            full.extend(tiny(args, resumed_next));
            let out = Command::new(env!("CARGO_BIN_EXE_dextrain")).args(&full).current_dir(&dir).env_remove("XDG_RUNTIME_DIR").output().unwrap();
            let stderr = String::from_utf8_lossy(&out.stderr);
            let what = format!("journey {:?} ({}), command {}: dextrain {}", j.name, j.source, k + 1, full.join(" "));
            assert!(out.status.success(), "{what} failed:\n{stderr}");
            let errors: Vec<&str> = stderr.lines().filter(|l| l.trim_start().starts_with("error:")).collect();
            assert!(errors.is_empty(), "{what} printed error lines: {errors:?}");
            for f in promised_files(args) {
                assert!(dir.join(&f).is_file(), "{what}: {f} was not written");
            }
            eprintln!("{what}: ok");
        }
    }
}

#[test]
fn shell_words_split_as_a_shell_would() {
    assert_eq!(shell_words(r#"check a.toml --set hand.urdf="/x y/h.urdf"  # comment"#), ["check", "a.toml", "--set", "hand.urdf=/x y/h.urdf"]);
    assert_eq!(shell_words("train --set 'hand.fingertips=[]' --name a#b"), ["train", "--set", "hand.fingertips=[]", "--name", "a#b"]);
}
