//! The crate's layers (docs/design.md §11): every top-level module of `src/` has a place in one
//! declared order, lowest first, and imports (any `crate::<module>` path, `use crate::{…}` groups
//! included, doc links too) only modules placed before it. A module that is not placed, or an
//! import from a lower module to a higher one, fails here with the file and line.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

/// The layers, lowest first; within a layer, the order is also the allowed direction.
const LAYERS: &[(&str, &[&str])] = &[
    ("base helpers", &["text", "files", "rng", "console", "run_dir", "gpu_counts", "host_traffic", "dist", "tensorboard", "metrics", "plot"]),
    ("geometry and meshes", &["geom", "mesh"]),
    ("config: plain data, validated where only lower layers are needed", &["config"]),
    ("models: hand, object, reference trajectories, recordings", &["hand", "object", "traj", "record"]),
    ("the GPU context and the shader ABI: Pod structs, bindings, shader sources, burn buffer interop", &["gpu"]),
    ("views: rollouts rendered headless with wgpu into MP4, GIF or PNG frames", &["video"]),
    ("simulator: the physics twins, the CPU and GPU env batches", &["env"]),
    ("task layer: tasks, IK, references, the reference bank", &["task"]),
    ("views: the live Foxglove view of env batches", &["live"]),
    ("learners: kernels, networks, PPO, SAC, distillation, checkpoints", &["learn"]),
    ("export, eval (with play), the runner", &["export", "eval", "run"]),
    ("commands", &["replay", "synth", "retarget", "starter", "bench_contacts", "bench_matmul", "bench", "train"]),
];

/// The declared order, flattened.
fn order() -> Vec<&'static str> {
    LAYERS.iter().flat_map(|(_, m)| m.iter().copied()).collect()
}

/// The top-level modules a source text names through `crate::` paths, with the 1-based line of
/// each mention. Unit tests at the end of a file (`#[cfg(test)] mod tests`) are left out.
fn imports(text: &str) -> Vec<(String, usize)> {
    let text = match text.find("#[cfg(test)]\nmod tests") {
        Some(i) => &text[..i],
        None => text,
    };
    let mut out = Vec::new();
    let line_of = |i: usize| text[..i].matches('\n').count() + 1;
    let ident = |s: &str| -> String { s.chars().take_while(|c| c.is_ascii_alphanumeric() || *c == '_').collect() };
    let mut from = 0;
    while let Some(k) = text[from..].find("crate::") {
        let at = from + k;
        from = at + "crate::".len();
        // `dextrain_crate::` or `some_crate::` are other paths
        if at > 0 && text[..at].chars().next_back().is_some_and(|c| c.is_ascii_alphanumeric() || c == '_') {
            continue;
        }
        let rest = &text[from..];
        if let Some(group) = rest.strip_prefix('{') {
            // `crate::{a::b, c, d::{e, f}}`: the first name of each top-level item
            let mut depth = 0usize;
            let mut item_start = true;
            for (i, c) in group.char_indices() {
                match c {
                    '{' => depth += 1,
                    '}' if depth == 0 => break,
                    '}' => depth -= 1,
                    ',' if depth == 0 => item_start = true,
                    c if item_start && (c.is_ascii_alphabetic() || c == '_') => {
                        out.push((ident(&group[i..]), line_of(from + 1 + i)));
                        item_start = false;
                    }
                    _ => {}
                }
            }
        } else {
            let name = ident(rest);
            if !name.is_empty() {
                out.push((name, line_of(at)));
            }
        }
    }
    out
}

/// The back edges and unplaced modules among `files` (path relative to src/, text), as messages.
fn violations(files: &[(PathBuf, String)]) -> Vec<String> {
    let order = order();
    let rank = |m: &str| order.iter().position(|o| *o == m);
    let modules: BTreeSet<String> = files.iter().filter_map(|(p, _)| top_module(p)).collect();
    let mut out = Vec::new();
    for m in &modules {
        if rank(m).is_none() {
            out.push(format!("src/{m}: a top-level module without a place in tests/suite/layers.rs LAYERS"));
        }
    }
    for (path, text) in files {
        let Some(m) = top_module(path) else { continue };
        let Some(r) = rank(&m) else { continue };
        for (target, line) in imports(text) {
            if target == m || !modules.contains(&target) {
                continue;
            }
            match rank(&target) {
                Some(t) if t < r => {}
                _ => out.push(format!("src/{}:{line}: `{m}` imports `{target}`, which is not below it", path.display())),
            }
        }
    }
    out
}

/// The top-level module of a file under src/ (None for the crate roots).
fn top_module(rel: &Path) -> Option<String> {
    let first = rel.components().next()?.as_os_str().to_str()?.to_string();
    let name = first.strip_suffix(".rs").unwrap_or(&first).to_string();
    (name != "lib" && name != "main").then_some(name)
}

fn sources(dir: &Path, root: &Path, out: &mut Vec<(PathBuf, String)>) {
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            sources(&p, root, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push((p.strip_prefix(root).unwrap().to_path_buf(), std::fs::read_to_string(&p).unwrap()));
        }
    }
}

#[test]
fn no_module_imports_a_higher_layer() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    sources(&src, &src, &mut files);
    assert!(files.len() > 50, "{} source files", files.len());
    // every declared module exists (a stale list hides nothing)
    let present: BTreeSet<String> = files.iter().filter_map(|(p, _)| top_module(p)).collect();
    for m in order() {
        assert!(present.contains(m), "LAYERS names `{m}`, which is not a module of src/");
    }
    let v = violations(&files);
    assert!(v.is_empty(), "{} layer violations:\n{}", v.len(), v.join("\n"));
}

#[test]
fn one_added_back_edge_fails() {
    // the real crate, plus one import from the geometry layer into the simulator
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    sources(&src, &src, &mut files);
    let geom = files.iter_mut().find(|(p, _)| p == Path::new("geom.rs")).expect("src/geom.rs");
    geom.1 = format!("use crate::env::SimModel;\n{}", geom.1);
    let v = violations(&files);
    assert_eq!(v, vec!["src/geom.rs:1: `geom` imports `env`, which is not below it".to_string()]);
    // a group import and an unplaced module are caught too
    let files = vec![
        (PathBuf::from("config/mod.rs"), "use crate::{geom::Pose, task::spec};\n".to_string()),
        (PathBuf::from("geom.rs"), String::new()),
        (PathBuf::from("task/mod.rs"), String::new()),
        (PathBuf::from("newcomer.rs"), String::new()),
    ];
    let v = violations(&files);
    assert_eq!(
        v,
        vec![
            "src/newcomer: a top-level module without a place in tests/suite/layers.rs LAYERS".to_string(),
            "src/config/mod.rs:1: `config` imports `task`, which is not below it".to_string(),
        ]
    );
}
