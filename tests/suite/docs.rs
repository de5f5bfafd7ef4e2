//! README.md and docs/*.md stay true to the repository: every relative link resolves to a file of
//! the repository (and every `#anchor` to a heading of the linked Markdown file, by GitHub's slug
//! rules), and every repository path they name — in inline code, or in a fenced block's listing —
//! exists. Placeholders (`runs/<name>/`, `eval_it*.json`) are checked up to their fixed part.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Component, Path, PathBuf};

/// Characters or words that mark a path as a pattern, not a file.
const PLACEHOLDER_MARKS: [&str; 10] = ["<", ">", "*", "{", "}", "…", "|", "...", "NAME", "RUN"];

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The Markdown files the check covers, relative to the root.
fn doc_files(root: &Path) -> Vec<PathBuf> {
    let mut files = vec![PathBuf::from("README.md")];
    let mut docs: Vec<PathBuf> = std::fs::read_dir(root.join("docs"))
        .expect("docs/")
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "md"))
        .map(|p| p.strip_prefix(root).unwrap().to_path_buf())
        .collect();
    docs.sort();
    files.extend(docs);
    files
}

/// Each line with its 1-based number and whether it is inside a fenced code block (fence lines
/// themselves are dropped).
fn lines_with_fences(text: &str) -> Vec<(usize, &str, bool)> {
    let mut out = Vec::new();
    let mut fence: Option<String> = None;
    for (i, line) in text.lines().enumerate() {
        let t = line.trim_start();
        let marker: String = t.chars().take_while(|c| *c == '`' || *c == '~').collect();
        if marker.len() >= 3 {
            match &fence {
                None => fence = Some(marker),
                Some(f) if t.starts_with(f.as_str()) => fence = None,
                Some(_) => out.push((i + 1, line, true)),
            }
            continue;
        }
        out.push((i + 1, line, fence.is_some()));
    }
    out
}

/// GitHub's anchor of a heading: lower case, code marks and link targets dropped, only letters,
/// digits, spaces, `-` and `_` kept, spaces turned into `-`.
fn slug(heading: &str) -> String {
    let mut text = String::new();
    let mut rest = heading.trim();
    // a link's text stays, its target goes
    while let Some(open) = rest.find("](") {
        let close = rest[open..].find(')').map_or(rest.len(), |c| open + c + 1);
        text.push_str(&rest[..open]);
        rest = &rest[close..];
    }
    text.push_str(rest);
    text.to_lowercase()
        .chars()
        .filter(|c| c.is_alphanumeric() || matches!(c, ' ' | '-' | '_'))
        .map(|c| if c == ' ' { '-' } else { c })
        .collect()
}

/// The anchors of a Markdown file's headings (duplicates numbered as GitHub does: `x`, `x-1`, …).
fn anchors(text: &str) -> BTreeSet<String> {
    let mut seen: BTreeMap<String, usize> = BTreeMap::new();
    let mut out = BTreeSet::new();
    for (_, line, fenced) in lines_with_fences(text) {
        if fenced {
            continue;
        }
        let hashes = line.chars().take_while(|c| *c == '#').count();
        if (1..=6).contains(&hashes) && line[hashes..].starts_with(' ') {
            let base = slug(line[hashes..].trim().trim_end_matches('#').trim());
            let n = seen.entry(base.clone()).or_insert(0);
            out.insert(if *n == 0 { base.clone() } else { format!("{base}-{n}") });
            *n += 1;
        }
    }
    out
}

/// The inline code spans of a line and the line without them.
fn split_code_spans(line: &str) -> (Vec<&str>, String) {
    let mut spans = Vec::new();
    let mut bare = String::new();
    let mut rest = line;
    while let Some(open) = rest.find('`') {
        let ticks = rest[open..].chars().take_while(|c| *c == '`').count();
        let fence = &rest[open..open + ticks];
        match rest[open + ticks..].find(fence) {
            Some(close) => {
                bare.push_str(&rest[..open]);
                spans.push(&rest[open + ticks..open + ticks + close]);
                rest = &rest[open + ticks + close + ticks..];
            }
            None => break,
        }
    }
    bare.push_str(rest);
    (spans, bare)
}

/// The targets of the Markdown links `[text](target)` in `text`.
fn link_targets(text: &str) -> Vec<&str> {
    let mut out = Vec::new();
    let mut rest = text;
    while let Some(i) = rest.find("](") {
        let after = &rest[i + 2..];
        let end = after.find(')').unwrap_or(after.len());
        let target = after[..end].split_whitespace().next().unwrap_or("");
        if !target.is_empty() {
            out.push(target);
        }
        rest = &after[end.min(after.len())..];
    }
    out
}

/// `path` with `.` and `..` resolved lexically.
fn normalise(path: &Path) -> PathBuf {
    let mut out = PathBuf::new();
    for c in path.components() {
        match c {
            Component::ParentDir => {
                out.pop();
            }
            Component::CurDir => {}
            c => out.push(c),
        }
    }
    out
}

/// What is wrong with one repository path named in the docs (None: it exists, or its fixed part
/// does).
fn check_path(root: &Path, top: &BTreeSet<String>, token: &str) -> Option<String> {
    let first = token.split('/').next().unwrap_or("");
    if !top.contains(first) {
        return None;
    }
    if let Some(cut) = PLACEHOLDER_MARKS.iter().filter_map(|m| token.find(m)).min() {
        let fixed = &token[..token[..cut].rfind('/').map_or(0, |i| i + 1)];
        return (!fixed.is_empty() && !root.join(fixed).exists()).then(|| format!("`{token}`: its fixed part {fixed} does not exist"));
    }
    (!root.join(token).exists()).then(|| format!("`{token}` does not exist"))
}

/// Every problem of the docs under `root`, as `file:line: what`.
fn problems(root: &Path) -> Vec<String> {
    let top: BTreeSet<String> = std::fs::read_dir(root)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| !n.starts_with(".git") && n != "target")
        .collect();
    let mut out = Vec::new();
    for rel in doc_files(root) {
        let text = std::fs::read_to_string(root.join(&rel)).unwrap();
        let here = rel.parent().unwrap_or(Path::new(""));
        for (n, line, fenced) in lines_with_fences(&text) {
            let at = format!("{}:{n}", rel.display());
            if fenced {
                // a listing's paths: words that start at a top-level folder of ours
                for word in line.split(|c: char| c.is_whitespace() || matches!(c, '(' | ')' | ',' | ';' | '`' | '"' | '\'' | '=')) {
                    let word = word.trim_end_matches([':', '.']);
                    if ["src/", "tests/", "configs/", "shaders/", "benches/", "docs/"].iter().any(|p| word.starts_with(p)) {
                        if let Some(e) = check_path(root, &top, word) {
                            out.push(format!("{at}: {e} (in a code block)"));
                        }
                    }
                }
                continue;
            }
            let (spans, bare) = split_code_spans(line);
            for target in link_targets(&bare) {
                if target.contains(':') && !target.starts_with('#') {
                    continue; // https:, mailto:
                }
                let (file, anchor) = target.split_once('#').unwrap_or((target, ""));
                let dest = if file.is_empty() { rel.clone() } else { normalise(&here.join(file)) };
                if dest.components().next() == Some(Component::ParentDir) || !root.join(&dest).exists() {
                    out.push(format!("{at}: link {target}: no file {} in the repository", dest.display()));
                    continue;
                }
                if !anchor.is_empty() {
                    let linked = std::fs::read_to_string(root.join(&dest)).unwrap_or_default();
                    if !anchors(&linked).contains(anchor) {
                        out.push(format!("{at}: link {target}: no heading with anchor #{anchor} in {}", dest.display()));
                    }
                }
            }
            for span in spans {
                let token = span.trim();
                if token.contains(' ') || !token.contains('/') || token.starts_with('/') {
                    continue;
                }
                if let Some(e) = check_path(root, &top, token) {
                    out.push(format!("{at}: {e}"));
                }
            }
        }
    }
    out
}

#[test]
fn every_link_anchor_and_path_in_the_docs_exists() {
    let root = root();
    let files = doc_files(&root);
    assert!(files.len() >= 10, "README.md and docs/: {files:?}");
    let p = problems(&root);
    assert!(p.is_empty(), "{} problems in README.md and docs/:\n{}", p.len(), p.join("\n"));
}

#[test]
fn a_broken_link_anchor_or_path_is_found() {
    // a copy of the docs with one broken link, one broken anchor and one missing path
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path();
    std::fs::create_dir_all(root.join("docs")).unwrap();
    std::fs::create_dir_all(root.join("src/env")).unwrap();
    std::fs::write(root.join("src/env/mod.rs"), "").unwrap();
    std::fs::write(root.join("README.md"), "# Top\n\nSee [the guide](docs/guide.md#the-gpu-loop) and [gone](docs/gone.md).\n").unwrap();
    std::fs::write(
        root.join("docs/guide.md"),
        "# Guide\n\n## The GPU loop\n\n`src/env/mod.rs` is there, `src/env/gone.rs` is not; `runs/<name>/` is a pattern.\n[up](../README.md#top), [nowhere](#no-such-heading)\n\n```\nsrc/env/mod.rs   listed\nsrc/task/         missing\n```\n",
    )
    .unwrap();
    std::fs::create_dir_all(root.join("runs")).unwrap();
    let p = problems(root);
    assert_eq!(
        p,
        vec![
            "README.md:3: link docs/gone.md: no file docs/gone.md in the repository".to_string(),
            "docs/guide.md:5: `src/env/gone.rs` does not exist".to_string(),
            "docs/guide.md:6: link #no-such-heading: no heading with anchor #no-such-heading in docs/guide.md".to_string(),
            "docs/guide.md:10: `src/task/` does not exist (in a code block)".to_string(),
        ]
    );
    assert_eq!(slug("§4 The environment (`env`)"), "4-the-environment-env");
}
