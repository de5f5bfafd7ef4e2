//! The folders a written file needs: every command that writes a file a user named (`--record`,
//! `--out`, `--video`) creates the folders above it first, as `mkdir -p` would, so that a fresh
//! run's `eval/` or a new `refs/` folder is never the reason a command fails; and the temporary
//! path beside a file that is renamed into place once complete.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use anyhow::{Context, Result};

/// Creates the folder that will hold `path` and every folder above it (nothing for a bare file
/// name); the error names the folder.
pub fn create_parent_dir(path: &Path) -> Result<()> {
    match path.parent().filter(|p| !p.as_os_str().is_empty()) {
        Some(dir) => std::fs::create_dir_all(dir).with_context(|| format!("cannot create the folder {}", dir.display())),
        None => Ok(()),
    }
}

/// A hidden temporary path beside `path` (`dir/.name.tmp-<pid>-<n>`, n counting up in the
/// process), for a file written there and renamed to `path` once complete; the error names `path`.
pub fn temp_path_beside(path: &Path) -> Result<PathBuf> {
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let name = path.file_name().with_context(|| format!("{}: the path has no file name", path.display()))?;
    let n = COUNTER.fetch_add(1, Ordering::Relaxed);
    Ok(path.with_file_name(format!(".{}.tmp-{}-{}", name.to_string_lossy(), std::process::id(), n)))
}
