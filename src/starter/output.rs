//! Where a starter config goes and how it gets there: the default file name, the refusal to
//! overwrite, paths written relative to the config's folder (how `Config::resolve` reads them),
//! and the write itself (a temporary file beside the destination, then a rename or a link: a
//! reader never sees half a file, and an interrupted run leaves none).

use std::path::{Component, Path, PathBuf};

use anyhow::{Context, Result, bail};

/// The output file: `out` if given, else `<stem>_lift.toml` in the current directory.
pub fn output_path(out: Option<&Path>, stem: &str) -> PathBuf {
    match out {
        Some(p) => p.to_path_buf(),
        None => PathBuf::from(format!("{stem}_lift.toml")),
    }
}

/// Refuses an output that exists unless `force` (one line naming the file).
pub fn refuse_existing(out: &Path, force: bool) -> Result<()> {
    if !force && std::fs::symlink_metadata(out).is_ok() {
        bail!("{}: the file exists; expected a new file for the starter config (give --force to overwrite it)", out.display());
    }
    if std::fs::metadata(out).is_ok_and(|m| m.is_dir()) {
        bail!("{}: is a folder; expected the path of a config file (.toml) to write", out.display());
    }
    Ok(())
}

/// `p` made absolute (against the current directory) with `.` and `..` resolved lexically, then
/// its longest existing prefix resolved through the file system (symbolic links), the rest kept.
pub fn absolute(p: &Path) -> Result<PathBuf> {
    let joined = if p.is_absolute() { p.to_path_buf() } else { std::env::current_dir().context("cannot read the current directory")?.join(p) };
    let mut lexical = PathBuf::new();
    for c in joined.components() {
        match c {
            Component::CurDir => {}
            Component::ParentDir => {
                lexical.pop();
            }
            c => lexical.push(c),
        }
    }
    // the longest prefix that exists, canonical; the rest (folders still to be made) appended
    let mut head = lexical.clone();
    let mut tail = Vec::new();
    loop {
        if let Ok(c) = head.canonicalize() {
            let mut out = c;
            out.extend(tail.iter().rev());
            return Ok(out);
        }
        match (head.file_name().map(|n| n.to_os_string()), head.parent().map(Path::to_path_buf)) {
            (Some(name), Some(parent)) => {
                tail.push(name);
                head = parent;
            }
            _ => return Ok(lexical),
        }
    }
}

/// How a config in `config_dir` names `file`: the relative path from the folder to the file (both
/// made [`absolute`]), or the absolute path where there is no relative one (another drive or
/// prefix).
pub fn path_from(config_dir: &Path, file: &Path) -> Result<String> {
    let (dir, file) = (absolute(config_dir)?, absolute(file)?);
    let (d, f): (Vec<Component>, Vec<Component>) = (dir.components().collect(), file.components().collect());
    // different roots or prefixes (Windows drives): no relative path
    if d.first() != f.first() {
        return Ok(file.display().to_string());
    }
    let common = d.iter().zip(&f).take_while(|(a, b)| a == b).count();
    let mut rel = PathBuf::new();
    for _ in common..d.len() {
        rel.push("..");
    }
    for c in &f[common..] {
        rel.push(c.as_os_str());
    }
    // TOML configs are shared between systems: forward slashes
    Ok(rel.to_string_lossy().replace('\\', "/"))
}

/// Writes `text` to `out`: the folders above it first, then a temporary file beside it, then
/// either a rename onto it (`force`) or a hard link that fails if `out` appeared meanwhile (so a
/// file that is there is never replaced without `force`). The temporary file is removed on every
/// path.
pub fn write_atomic(out: &Path, text: &str, force: bool) -> Result<()> {
    crate::files::create_parent_dir(out)?;
    let dir = out.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    let name = out.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_else(|| "starter.toml".into());
    let tmp = dir.join(format!(".{name}.{}.tmp", std::process::id()));
    let result = (|| -> Result<()> {
        std::fs::write(&tmp, text).with_context(|| format!("cannot write {}", tmp.display()))?;
        if force {
            std::fs::rename(&tmp, out).with_context(|| format!("cannot rename {} to {}", tmp.display(), out.display()))
        } else {
            match std::fs::hard_link(&tmp, out) {
                Ok(()) => Ok(()),
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {
                    bail!("{}: the file exists; expected a new file for the starter config (give --force to overwrite it)", out.display())
                }
                // a file system without hard links: check, then rename
                Err(_) => {
                    refuse_existing(out, false)?;
                    std::fs::rename(&tmp, out).with_context(|| format!("cannot rename {} to {}", tmp.display(), out.display()))
                }
            }
        }
    })();
    let _ = std::fs::remove_file(&tmp);
    result
}
