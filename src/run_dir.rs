//! Run directories (docs/design.md §7): `runs/<name>/` with the exact resolved config, metrics, TensorBoard
//! events, plots, checkpoints and eval reports.
//!
//! A run name is one path component of letters, digits, `-`, `_` and `.` (not `.` or `..`), so a
//! run cannot escape `runs/`. An existing run directory is never overwritten unless `--force` is
//! given, and `--force` only ever replaces a run directory: one with a `config.toml` (what dextrain
//! writes first, so a run that failed to start has one) that holds
//! nothing but what dextrain writes into a run ([`RUN_ENTRIES`], TensorBoard event files). Anything
//! else — a directory that is not a run, a run with a file of the user's in it — is refused with a
//! one-line error and left untouched: nothing a user wrote is deleted.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};

/// Checks a run name.
pub fn validate_name(name: &str) -> Result<()> {
    let ok = !name.is_empty()
        && name.len() <= 200
        && name != "."
        && name != ".."
        && name.chars().all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_' || c == '.');
    if !ok {
        bail!("--name {name:?}: expected a run name of letters, digits, '-', '_' and '.' (one path component inside runs/)");
    }
    Ok(())
}

/// Seconds since the Unix epoch → "YYYYMMDD-HHMMSS" (UTC).
pub fn timestamp(secs: u64) -> String {
    let days = (secs / 86_400) as i64;
    let rem = secs % 86_400;
    // civil-from-days (Howard Hinnant)
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let y = yoe + era * 400;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = if m <= 2 { y + 1 } else { y };
    format!("{y:04}{m:02}{d:02}-{:02}{:02}{:02}", rem / 3600, rem % 3600 / 60, rem % 60)
}

/// The default run name: `<config file stem>_<UTC timestamp>`.
pub fn default_name(config: &Path) -> String {
    let stem = config.file_stem().and_then(|s| s.to_str()).unwrap_or("run");
    let stem: String = stem.chars().map(|c| if c.is_ascii_alphanumeric() || c == '-' || c == '_' || c == '.' { c } else { '_' }).collect();
    let secs = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map(|d| d.as_secs()).unwrap_or(0);
    format!("{stem}_{}", timestamp(secs))
}

/// What dextrain writes at the top of a run directory (besides TensorBoard's `events.out.tfevents.*`).
pub const RUN_ENTRIES: [&str; 9] = ["config.toml", "metrics.csv", "plots", "checkpoints", "eval", "export", "ranks", FOXGLOVE_LAYOUT, GPU_PROFILE];

/// The GPU time profile of a run's training loop (`train --gpu-profile`: `gpu::profile`).
pub const GPU_PROFILE: &str = "gpu_profile.json";

/// The Foxglove layout of a run's live view (`train --live`: the run's reward terms plotted).
pub const FOXGLOVE_LAYOUT: &str = "foxglove_layout.json";

/// Why `dir` may not be replaced by `--force`, or None when it is a run directory that holds only
/// what dextrain writes.
fn not_replaceable(dir: &Path) -> Result<Option<String>> {
    let meta = std::fs::symlink_metadata(dir).with_context(|| format!("cannot read {}", dir.display()))?;
    if !meta.is_dir() {
        return Ok(Some("it is not a directory".into()));
    }
    // dextrain writes config.toml first: a run that failed to start (no adapter, a buffer too
    // large) may hold nothing else, or an empty or partial metrics.csv
    if !dir.join("config.toml").is_file() {
        return Ok(Some("it is not a run directory (no config.toml)".into()));
    }
    let rd = std::fs::read_dir(dir).with_context(|| format!("cannot list {}", dir.display()))?;
    for e in rd {
        let e = e.with_context(|| format!("cannot list {}", dir.display()))?;
        let name = e.file_name().to_string_lossy().into_owned();
        if !RUN_ENTRIES.contains(&name.as_str()) && !name.starts_with("events.out.tfevents.") {
            return Ok(Some(format!("it holds {name:?}, which dextrain did not write")));
        }
    }
    Ok(None)
}

/// Creates `runs_root/name`. It fails if the directory exists, unless `force` and it is a run
/// directory that holds only what dextrain writes: then that run is removed first.
pub fn create(runs_root: &Path, name: &str, force: bool) -> Result<PathBuf> {
    validate_name(name)?;
    let dir = runs_root.join(name);
    if std::fs::symlink_metadata(&dir).is_ok() {
        if !force {
            bail!("{}: the run directory exists; pick another --name, resume it with --resume, or pass --force to overwrite it", dir.display());
        }
        if let Some(why) = not_replaceable(&dir)? {
            bail!("{}: --force only replaces a run directory, and {why}; nothing was deleted: pick another --name or move it away", dir.display());
        }
        std::fs::remove_dir_all(&dir).with_context(|| format!("cannot remove {}", dir.display()))?;
    }
    std::fs::create_dir_all(runs_root).with_context(|| format!("cannot create the runs directory {}", runs_root.display()))?;
    // the run's own directory made by this process alone: a second process starting a run of the
    // same name at the same moment (passed the test above as well) gets the one-line error, not a
    // share of this run (nor, failing later, the removal of it by `remove_failed_start`)
    match std::fs::create_dir(&dir) {
        Ok(()) => Ok(dir),
        Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {
            bail!("{}: the run directory exists (another process just created it); pick another --name", dir.display())
        }
        Err(e) => Err(e).with_context(|| format!("cannot create the run directory {}", dir.display())),
    }
}

/// Removes the directory of a new run that failed before its first iteration, when it holds only
/// what dextrain wrote (config.toml, an empty or partial metrics.csv, TensorBoard files): a failed
/// start leaves nothing behind that `--force` or a new run would trip on. Anything else is kept.
pub fn remove_failed_start(dir: &Path) -> Result<()> {
    let metrics_rows = std::fs::read_to_string(dir.join("metrics.csv")).map(|t| t.lines().count().saturating_sub(1)).unwrap_or(0);
    if metrics_rows == 0 && !dir.join("checkpoints").exists() && not_replaceable(dir)?.is_none() {
        std::fs::remove_dir_all(dir).with_context(|| format!("cannot remove {}", dir.display()))?;
    }
    Ok(())
}

/// Checks that `dir` is a run directory (it has `config.toml`).
pub fn check_run(dir: &Path) -> Result<()> {
    if !dir.join("config.toml").is_file() {
        bail!("{}: not a run directory (expected {})", dir.display(), dir.join("config.toml").display());
    }
    Ok(())
}
