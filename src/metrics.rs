//! Training metrics: one row per iteration, in `runs/NAME/metrics.csv` and in a TensorBoard event
//! file in `runs/NAME/` (docs/design.md §7).
//!
//! `metrics.csv` is the record of a run: a header `iteration,<column>,...` and one row per
//! iteration, numbers written with Rust's shortest round-trip formatting (`{}`; NaN as `nan`,
//! infinities as `inf`/`-inf`), so reading a row back gives the exact f64 that was logged and equal
//! inputs give byte-identical rows. The event file holds the same numbers (as f32, TensorBoard's
//! `simple_value`) with tag = column name and step = iteration.
//!
//! Resuming from a checkpoint at iteration `upto` ([`MetricsLog::resume`]) drops the rows logged
//! after that checkpoint and rewrites the event file from the kept rows, so the two files agree.

use std::fs::{File, OpenOptions};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::{SystemTime, UNIX_EPOCH};

use anyhow::{Context, Result, bail};

use crate::tensorboard::{EventWriter, read_scalar_events};

/// The names of the metrics columns that more than one part of dextrain names: the runner and the
/// learners write them, the plots (and the stop rules of the benches) read them. Per-term and
/// per-group columns are a prefix and a name (`reward/<term>`, `loss/<what>`).
pub mod columns {
    pub const ENV_STEPS: &str = "env_steps";
    pub const TIME_S: &str = "time_s";
    pub const FPS: &str = "fps";
    pub const COLLECT_S: &str = "time/collect_s";
    pub const LEARN_S: &str = "time/learn_s";
    pub const HOST_BYTES: &str = "time/host_bytes";
    /// The mean reward per env step; each reward term's mean is [`REWARD_PREFIX`] + its name.
    pub const REWARD_MEAN: &str = "reward/mean";
    pub const REWARD_PREFIX: &str = "reward/";
    pub const EPISODE_COUNT: &str = "episode/count";
    pub const EPISODE_RETURN: &str = "episode/return";
    pub const EPISODE_LENGTH: &str = "episode/length";
    pub const EPISODE_SUCCESS_RATE: &str = "episode/success_rate";
    pub const EPISODE_LIFT_HEIGHT: &str = "episode/lift_height";
    pub const EPISODE_TERMINATED_FRAC: &str = "episode/terminated_frac";
    pub const EPISODE_BAD_RESET_FRAC: &str = "episode/bad_reset_frac";
    /// The learners' losses: [`LOSS_PREFIX`] + what (PPO's `surrogate`, `value`, `entropy`; SAC's
    /// `critic`, `actor`; distillation's `action`, `latent`).
    pub const LOSS_PREFIX: &str = "loss/";
    pub const LOSS_ENTROPY: &str = "loss/entropy";
    pub const POLICY_ENTROPY: &str = "policy/entropy";
    pub const POLICY_STD: &str = "policy/std";
    pub const LR: &str = "lr";
    pub const KL: &str = "kl";
    pub const GRAD_NORM: &str = "grad_norm";
    /// The reference kinds: the object's error against its reference (m, deg), mean over the
    /// rollout's env steps.
    pub const TRACKING_OBJ_POS_ERR_M: &str = "tracking/obj_pos_err_m";
    pub const TRACKING_OBJ_ROT_ERR_DEG: &str = "tracking/obj_rot_err_deg";
    /// A distillation run's side-by-side evaluation: [`DISTILL_EVAL_PREFIX`] + what.
    pub const DISTILL_EVAL_PREFIX: &str = "distill/eval_";
    pub const DISTILL_EVAL_STUDENT_SUCCESS: &str = "distill/eval_student_success";
    pub const DISTILL_EVAL_TEACHER_SUCCESS: &str = "distill/eval_teacher_success";
}

/// The CSV file inside a run directory.
pub const CSV_NAME: &str = "metrics.csv";

/// One CSV row: (iteration, values in column order).
pub type Row = (u64, Vec<f64>);

/// Appends one row per training iteration to `metrics.csv` and to a TensorBoard event file.
pub struct MetricsLog {
    csv_path: PathBuf,
    csv: File,
    events: EventWriter,
    columns: Vec<String>,
    /// The iteration of the last row written (rows must have increasing iterations).
    last: Option<u64>,
}

impl MetricsLog {
    /// Creates `dir/metrics.csv` (header: "iteration" then `columns`) and a new TensorBoard event file
    /// in `dir` (created if missing). Fails if `metrics.csv` already exists: a run is never silently
    /// overwritten. Column names must be unique, not "iteration", and free of `,`, `"` and line breaks.
    pub fn create(dir: &Path, columns: &[String]) -> Result<MetricsLog> {
        check_columns(columns)?;
        std::fs::create_dir_all(dir).with_context(|| format!("creating run directory {}", dir.display()))?;
        let csv_path = dir.join(CSV_NAME);
        let mut csv = OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&csv_path)
            .with_context(|| format!("creating {} (a run is never overwritten)", csv_path.display()))?;
        csv.write_all(header_line(columns).as_bytes()).with_context(|| format!("writing {}", csv_path.display()))?;
        let events = EventWriter::create(dir)?;
        Ok(MetricsLog { csv_path, csv, events, columns: columns.to_vec(), last: None })
    }

    /// Re-opens a run for resuming after iteration `upto`: keeps the CSV rows with iteration <= upto
    /// (drops rows written after that checkpoint), checks the header equals `columns` (one-line error
    /// naming the file otherwise), deletes the run's old event files and writes one new event file
    /// holding exactly the kept rows, so that metrics.csv and TensorBoard always agree.
    ///
    /// The kept rows keep the wall times the old event files recorded for their steps (the current
    /// time where none is found). A final CSV line without its newline (a run killed while writing
    /// it) is dropped; any other malformed line is an error.
    pub fn resume(dir: &Path, columns: &[String], upto: u64) -> Result<MetricsLog> {
        check_columns(columns)?;
        let csv_path = dir.join(CSV_NAME);
        let text = std::fs::read_to_string(&csv_path)
            .with_context(|| format!("reading {} to resume the run", csv_path.display()))?;
        // a torn last line is the row being written when the run died
        let complete = match text.rfind('\n') {
            Some(i) => &text[..=i],
            None => "",
        };
        let (header, rows) = parse_csv(&csv_path, complete)?;
        if header != columns {
            bail!(
                "{}: its columns [{}] differ from this run's columns [{}]; resume with the config the run was started with",
                csv_path.display(),
                header.join(", "),
                columns.join(", ")
            );
        }
        let kept: Vec<Row> = rows.into_iter().filter(|(it, _)| *it <= upto).collect();

        // metrics.csv: rewrite the kept rows (canonical formatting round-trips, so they are unchanged)
        let mut body = header_line(columns);
        for (it, values) in &kept {
            body.push_str(&row_line(*it, values));
        }
        let tmp = dir.join(format!("{CSV_NAME}.tmp"));
        std::fs::write(&tmp, &body).with_context(|| format!("writing {}", tmp.display()))?;
        std::fs::rename(&tmp, &csv_path)
            .with_context(|| format!("replacing {} with {}", csv_path.display(), tmp.display()))?;

        // old event files: remember their wall times, write the new file, then delete them
        let old = event_files(dir)?;
        let mut wall_times = std::collections::HashMap::new();
        for path in &old {
            for e in read_scalar_events(path, true).unwrap_or_default() {
                wall_times.entry(e.step).or_insert(e.wall_time);
            }
        }
        let mut events = EventWriter::create(dir)?;
        let now = unix_now();
        for (it, values) in &kept {
            let wall = wall_times.get(&(*it as i64)).copied().unwrap_or(now);
            for (name, v) in columns.iter().zip(values) {
                events.add_scalar(name, *it as i64, *v as f32, wall)?;
            }
        }
        events.flush()?;
        for path in old.iter().filter(|p| p.as_path() != events.path()) {
            std::fs::remove_file(path).with_context(|| format!("deleting old event file {}", path.display()))?;
        }

        let csv = OpenOptions::new()
            .append(true)
            .open(&csv_path)
            .with_context(|| format!("opening {} to append", csv_path.display()))?;
        let last = kept.last().map(|(it, _)| *it);
        Ok(MetricsLog { csv_path, csv, events, columns: columns.to_vec(), last })
    }

    /// Appends one row (values.len() == columns.len()) to the CSV (flushed) and every value as a
    /// TensorBoard scalar with tag = column name, step = iteration (flushed too). Iterations must
    /// increase from row to row.
    pub fn append(&mut self, iteration: u64, values: &[f64]) -> Result<()> {
        if values.len() != self.columns.len() {
            bail!(
                "{}: row for iteration {iteration} has {} values, the log has {} columns",
                self.csv_path.display(),
                values.len(),
                self.columns.len()
            );
        }
        if let Some(last) = self.last.filter(|&last| iteration <= last) {
            bail!(
                "{}: iteration {iteration} logged after iteration {last} (iterations must increase)",
                self.csv_path.display()
            );
        }
        // one write per row, so a killed run leaves at most one torn line
        self.csv
            .write_all(row_line(iteration, values).as_bytes())
            .with_context(|| format!("writing {}", self.csv_path.display()))?;
        let wall = unix_now();
        for (name, v) in self.columns.iter().zip(values) {
            self.events.add_scalar(name, iteration as i64, *v as f32, wall)?;
        }
        self.events.flush()?;
        self.last = Some(iteration);
        Ok(())
    }

    /// The column names (without "iteration").
    pub fn columns(&self) -> &[String] {
        &self.columns
    }

    /// The path of `metrics.csv`.
    pub fn csv_path(&self) -> &Path {
        &self.csv_path
    }

    /// The path of the event file being written.
    pub fn event_file(&self) -> &Path {
        self.events.path()
    }
}

/// Reads a metrics.csv: (column names without "iteration", rows as (iteration, values)). One-line
/// errors naming file and line.
pub fn read_csv(path: &Path) -> Result<(Vec<String>, Vec<Row>)> {
    let text = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    parse_csv(path, &text)
}

/// The event files TensorBoard would read in `dir` (names containing "tfevents"), sorted.
pub fn event_files(dir: &Path) -> Result<Vec<PathBuf>> {
    let mut out = Vec::new();
    for entry in std::fs::read_dir(dir).with_context(|| format!("listing {}", dir.display()))? {
        let entry = entry.with_context(|| format!("listing {}", dir.display()))?;
        if entry.file_name().to_string_lossy().contains("tfevents") && entry.path().is_file() {
            out.push(entry.path());
        }
    }
    out.sort();
    Ok(out)
}

/// Writes a CSV number: shortest round-trip decimal, `nan` for every NaN.
fn fmt_value(v: f64) -> String {
    if v.is_nan() { "nan".to_string() } else { format!("{v}") }
}

fn header_line(columns: &[String]) -> String {
    let mut s = String::from("iteration");
    for c in columns {
        s.push(',');
        s.push_str(c);
    }
    s.push('\n');
    s
}

fn row_line(iteration: u64, values: &[f64]) -> String {
    let mut s = iteration.to_string();
    for v in values {
        s.push(',');
        s.push_str(&fmt_value(*v));
    }
    s.push('\n');
    s
}

fn check_columns(columns: &[String]) -> Result<()> {
    for (i, c) in columns.iter().enumerate() {
        if c.is_empty() || c.contains([',', '"', '\n', '\r']) {
            bail!("metrics column {c:?} is empty or contains a comma, quote or line break");
        }
        if c == "iteration" {
            bail!("metrics column \"iteration\" is implicit (the first column); remove it from the list");
        }
        if columns[..i].contains(c) {
            bail!("metrics column {c:?} appears twice");
        }
    }
    Ok(())
}

fn parse_csv(path: &Path, text: &str) -> Result<(Vec<String>, Vec<Row>)> {
    let mut lines = text.lines().enumerate();
    let Some((_, header)) = lines.next() else {
        bail!("{}: empty file, expected a header starting with \"iteration\"", path.display());
    };
    let mut names = header.split(',');
    if names.next() != Some("iteration") {
        bail!("{}:1: header must start with \"iteration\", found {header:?}", path.display());
    }
    let columns: Vec<String> = names.map(str::to_string).collect();
    let mut rows = Vec::new();
    for (i, line) in lines {
        let lineno = i + 1;
        if line.is_empty() {
            continue;
        }
        let mut fields = line.split(',');
        let it_text = fields.next().unwrap_or_default();
        let Ok(iteration) = it_text.parse::<u64>() else {
            bail!("{}:{lineno}: iteration {it_text:?} is not a non-negative integer", path.display());
        };
        let mut values = Vec::with_capacity(columns.len());
        for (k, field) in fields.enumerate() {
            let Ok(v) = field.parse::<f64>() else {
                let col = columns.get(k).map_or("?", String::as_str);
                bail!("{}:{lineno}: column {col:?}: {field:?} is not a number", path.display());
            };
            values.push(v);
        }
        if values.len() != columns.len() {
            bail!(
                "{}:{lineno}: {} values, the header has {} columns after \"iteration\"",
                path.display(),
                values.len(),
                columns.len()
            );
        }
        rows.push((iteration, values));
    }
    Ok((columns, rows))
}

fn unix_now() -> f64 {
    SystemTime::now().duration_since(UNIX_EPOCH).map(|d| d.as_secs_f64()).unwrap_or(0.0)
}
