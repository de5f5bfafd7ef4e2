//! The folders a written file needs: every command that writes a file a user named (`--record`,
//! `--out`) creates the folders above it first, as `mkdir -p` would, so that a fresh run's
//! `eval/` or a new `refs/` folder is never the reason a command fails.

use std::path::Path;

use anyhow::{Context, Result};

/// Creates the folder that will hold `path` and every folder above it (nothing for a bare file
/// name); the error names the folder.
pub fn create_parent_dir(path: &Path) -> Result<()> {
    match path.parent().filter(|p| !p.as_os_str().is_empty()) {
        Some(dir) => std::fs::create_dir_all(dir).with_context(|| format!("cannot create the folder {}", dir.display())),
        None => Ok(()),
    }
}
