//! Run configuration: serde structs that mirror the TOML file (unknown keys are errors, closed
//! choices are enums), defaults, and validation with one-line errors that name the file, the key,
//! the value and what is allowed. Everything is checked once, in [`Config::load`]; the code that
//! reads a `Config` afterwards trusts it.
//!
//! One file per concern: [`sim`] (backend, time stepping, table, contact, randomisation), [`object`]
//! (the object or the set of objects),
//! [`hand`] (the hand and its wrist), [`task`] (task kinds, actions, observations, rewards,
//! references) and [`learn`] (the run, PPO, the networks); each struct's `validate()` sits beside
//! it. Paths inside a config (the hand's URDF, object meshes and URDFs, references) are relative to the config file's
//! directory.

pub mod hand;
pub mod learn;
pub mod object;
pub mod retarget;
pub mod rewards;
pub mod sac;
pub mod sim;
pub mod task;

use std::fmt::Display;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use serde::{Deserialize, Serialize};

use crate::text::{clip_quoted, one_line, quote_short};

pub use hand::{HandConfig, WristConfig};
pub use retarget::{FingerMap, RetargetConfig};
pub use sac::{QReduction, SacConfig};
pub use learn::{Activation, AdaptationModule, AlgorithmChoice, DatasetMode, DistillConfig, EncoderConfig, LrSchedule, PolicyConfig, PpoConfig, StudentActor, TrainConfig};
pub use object::{MeshFiles, ObjectConfig, ObjectItem, PieceKind};
pub use sim::{BackendChoice, ContactConfig, RandomizationConfig, SimConfig, TableConfig};
pub use task::{
    ActionConfig, FingerMode, HandPointsConfig, LiftConfig, ObsNoiseConfig, ReferenceConfig, ReferenceStart, ResidualConfig, TaskConfig, TaskKind,
    TerminationConfig, TrackAction, TrackConfig,
};

/// A whole config file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Config {
    /// The one seed that decides everything random (per-env draws hash (seed, env, episode, purpose)).
    pub seed: u32,
    /// Simulation backend, batch size and time stepping.
    pub sim: SimConfig,
    /// The hand: URDF, joint servo gains, contact friction, initial joint positions.
    pub hand: HandConfig,
    /// The floating wrist's force/torque-limited PD controller and initial pose.
    pub wrist: WristConfig,
    /// The manipulated object.
    pub object: ObjectConfig,
    /// The table (the plane z = 0).
    pub table: TableConfig,
    /// Penalty contact model.
    pub contact: ContactConfig,
    /// Per-env physical parameters drawn at every reset.
    pub randomization: RandomizationConfig,
    /// The task on top of the simulator: actions, observations, rewards, terminations.
    pub task: TaskConfig,
    /// The training run: learner device, iterations, checkpoints.
    pub train: TrainConfig,
    /// PPO hyper-parameters (docs/design.md §6 defaults, rsl_rl conventions).
    pub ppo: PpoConfig,
    /// Actor and critic networks.
    pub policy: PolicyConfig,
    /// Teacher→student distillation (`train.algorithm = "distill"`).
    pub distill: DistillConfig,
    /// Soft Actor-Critic hyper-parameters (`train.algorithm = "sac"`).
    pub sac: SacConfig,
    /// How `traj retarget` maps a human hand onto this hand.
    pub retarget: RetargetConfig,
    /// Directory of the config file (paths in the config are relative to it); not part of the TOML.
    #[serde(skip)]
    pub base_dir: PathBuf,
    /// The file the config came from (for error messages); not part of the TOML.
    #[serde(skip)]
    pub source: PathBuf,
}

impl Default for Config {
    fn default() -> Self {
        Config {
            seed: 0,
            sim: SimConfig::default(),
            hand: HandConfig::default(),
            wrist: WristConfig::default(),
            object: ObjectConfig::default(),
            table: TableConfig::default(),
            contact: ContactConfig::default(),
            randomization: RandomizationConfig::default(),
            task: TaskConfig::default(),
            train: TrainConfig::default(),
            ppo: PpoConfig::default(),
            policy: PolicyConfig::default(),
            distill: DistillConfig::default(),
            sac: SacConfig::default(),
            retarget: RetargetConfig::default(),
            base_dir: PathBuf::from("."),
            source: PathBuf::from("<default>"),
        }
    }
}

/// The validation context of one config file: builds the one-line errors
/// `FILE: key `KEY` = VALUE: expected ALLOWED` and checks numbers.
pub struct Check {
    file: String,
}

impl Check {
    /// Errors will name `file`.
    pub fn new(file: &Path) -> Check {
        Check { file: file.display().to_string() }
    }

    /// `FILE: key `key` = value: expected allowed` (long values are cut).
    pub fn err(&self, key: &str, value: impl Display, allowed: &str) -> anyhow::Error {
        anyhow::anyhow!("{}: key `{}` = {}: expected {allowed}", self.file, quote_short(key), quote_short(&value.to_string()))
    }

    /// `FILE: message` (for errors that are not about one value).
    pub fn msg(&self, message: impl Display) -> anyhow::Error {
        anyhow::anyhow!("{}: {message}", self.file)
    }

    /// `v` finite and in [lo, hi].
    pub fn in_range(&self, key: &str, v: f32, lo: f32, hi: f32, allowed: &str) -> Result<()> {
        if v.is_finite() && v >= lo && v <= hi { Ok(()) } else { Err(self.err(key, v, allowed)) }
    }

    /// `v` finite and ≥ 0.
    pub fn non_neg(&self, key: &str, v: f32) -> Result<()> {
        if v.is_finite() && v >= 0.0 { Ok(()) } else { Err(self.err(key, v, "a finite number >= 0")) }
    }

    /// `v` finite.
    pub fn finite(&self, key: &str, v: f32) -> Result<()> {
        if v.is_finite() { Ok(()) } else { Err(self.err(key, v, "a finite number")) }
    }

    /// `v` in [0, 1).
    pub fn unit_interval(&self, key: &str, v: f32) -> Result<()> {
        if v.is_finite() && (0.0..1.0).contains(&v) { Ok(()) } else { Err(self.err(key, v, "a number in [0, 1)")) }
    }
}

impl Config {
    /// Reads, parses and validates a config file.
    pub fn load(path: &Path) -> Result<Config> {
        let text = std::fs::read_to_string(path).with_context(|| format!("cannot read config file {}", path.display()))?;
        Config::from_toml_str(&text, path)
    }

    /// Reads a config file and applies `--set key=value` overrides before validation. `key` is a
    /// dotted path (`ppo.learning_rate`, `task.rewards.lifting`); `value` is a TOML value
    /// (`3`, `1e-3`, `true`, `[1, 2]`, `"cpu"`); a bare word that is not TOML is taken as a string.
    pub fn load_with_overrides(path: &Path, sets: &[String]) -> Result<Config> {
        if sets.is_empty() {
            return Config::load(path);
        }
        let text = std::fs::read_to_string(path).with_context(|| format!("cannot read config file {}", path.display()))?;
        let mut table = parse_toml(&text, path)?;
        for set in sets {
            apply_override(&mut table, set)?;
        }
        let merged = toml::to_string(&table).context("cannot serialise the overridden config")?;
        Config::from_toml_str(&merged, path)
    }

    /// Parses and validates config text; `path` is used for error messages and relative paths.
    pub fn from_toml_str(text: &str, path: &Path) -> Result<Config> {
        let file = path.display();
        let mut table = parse_toml(text, path)?;
        migrate_moved_keys(&mut table).map_err(|e| anyhow::anyhow!("{file}: {e}"))?;
        let value = toml::Value::Table(table);
        let parsed = value.clone();
        // without a [task.rewards] table, the kind's default weights
        let has_rewards = value.get("task").and_then(|t| t.get("rewards")).is_some();
        let mut cfg: Config = serde_path_to_error::deserialize(value).map_err(|e| {
            let key = e.path().to_string();
            // serde quotes names with backticks (`unknown variant `x`, expected `a` or `b``): the
            // TOML's own quotes read better
            let msg = one_line(&e.into_inner().to_string()).replace('`', "\"");
            // the offending value, where the key holds one (not a table)
            let shown = value_at(&parsed, &key).filter(|v| !v.is_table()).map(|v| format!(" = {}", quote_short(&v.to_string()))).unwrap_or_default();
            anyhow::anyhow!("{file}: key `{}`{shown}: {}", quote_short(&key), clip_quoted(&msg))
        })?;
        if !has_rewards {
            cfg.task.rewards = cfg.task.kind.default_rewards();
        }
        cfg.source = path.to_path_buf();
        cfg.base_dir = path.parent().map(Path::to_path_buf).unwrap_or_else(|| PathBuf::from("."));
        if cfg.base_dir.as_os_str().is_empty() {
            cfg.base_dir = PathBuf::from(".");
        }
        cfg.validate()?;
        Ok(cfg)
    }

    /// A path from the config, resolved against the config file's directory.
    pub fn resolve(&self, p: &str) -> PathBuf {
        let p = Path::new(p);
        if p.is_absolute() { p.to_path_buf() } else { self.base_dir.join(p) }
    }

    /// The resolved config as TOML, every default filled in.
    pub fn to_toml(&self) -> Result<String> {
        toml::to_string(self).context("cannot serialise the config")
    }

    /// The backend the config asks for.
    pub fn backend(&self) -> BackendChoice {
        self.sim.backend.clone()
    }

    /// Checks every value; the first problem is returned as a one-line error.
    pub fn validate(&self) -> Result<()> {
        let c = Check::new(&self.source);
        self.sim.validate(&c)?;
        self.hand.validate(&c)?;
        self.wrist.validate(&c)?;
        self.object.validate(&c)?;
        c.non_neg("table.friction", self.table.friction)?;
        self.contact.validate(&c)?;
        self.randomization.validate(&c)?;
        self.task.validate(&c)?;
        self.train.validate(&c)?;
        self.ppo.validate(&c, self.sim.num_envs as u64 * self.train.steps_per_env as u64)?;
        self.policy.validate(&c)?;
        if self.train.algorithm == AlgorithmChoice::Distill {
            self.distill.validate(&c, self.sim.num_envs as u64 * self.train.steps_per_env as u64)?;
        }
        if self.train.algorithm == AlgorithmChoice::Sac {
            self.sac.validate(&c, self.sim.num_envs as u64)?;
            if self.policy.encoder.is_some() {
                return Err(c.err("policy.encoder", "a table", "no [policy.encoder] with train.algorithm = \"sac\" (the privileged encoder is PPO's)"));
            }
        }
        // the encoder's inputs are checked against the task's observation spec by
        // `task::setup::check_config` (the task layer, above the config)
        Ok(())
    }
}

/// Keys that moved, as (old table, key, new table): `[task.lift]`'s keys that every kind uses now
/// live in `[task.hand]` and `[task.termination]`. Configs written before the move still load.
pub const MOVED_KEYS: [(&str, &str, &str); 6] = [
    ("lift", "thumb", "hand"),
    ("lift", "contact_force", "hand"),
    ("lift", "palm_offset", "hand"),
    ("lift", "drop_height", "termination"),
    ("lift", "table_half_extent", "termination"),
    ("lift", "max_hand_distance", "termination"),
];

/// Moves the keys of [`MOVED_KEYS`] from their old `[task.*]` table to the new one; a key given in
/// both places is an error.
fn migrate_moved_keys(table: &mut toml::Table) -> Result<()> {
    let Some(toml::Value::Table(task)) = table.get_mut("task") else { return Ok(()) };
    for (old, key, new) in MOVED_KEYS {
        let Some(toml::Value::Table(from)) = task.get_mut(old) else { continue };
        let Some(v) = from.remove(key) else { continue };
        let to = task.entry(new.to_string()).or_insert_with(|| toml::Value::Table(toml::Table::new()));
        let toml::Value::Table(to) = to else { bail!("key `task.{new}`: expected a table") };
        if to.contains_key(key) {
            bail!("key `task.{old}.{key}` (the old place of `task.{new}.{key}`) and `task.{new}.{key}` are both given; expected one of them");
        }
        to.insert(key.to_string(), v);
    }
    Ok(())
}

/// The value at a dotted key path such as `task.kind` or `wrist.init_pos[1]` (`None` where there is
/// none).
fn value_at<'a>(root: &'a toml::Value, path: &str) -> Option<&'a toml::Value> {
    let mut cur = root;
    for part in path.split('.') {
        let (name, indices) = match part.find('[') {
            Some(i) => (&part[..i], &part[i..]),
            None => (part, ""),
        };
        if !name.is_empty() {
            cur = cur.get(name)?;
        }
        for index in indices.split('[').filter(|x| !x.is_empty()) {
            cur = cur.get(index.trim_end_matches(']').parse::<usize>().ok()?)?;
        }
    }
    Some(cur)
}

/// Parses TOML text into a table; a syntax error (or a key defined twice) is one line with the
/// file, line and column, and the key's dotted path where the parser names it.
fn parse_toml(text: &str, path: &Path) -> Result<toml::Table> {
    match text.parse::<toml::Table>() {
        Ok(t) => Ok(t),
        Err(e) => {
            let at = e.span().map(|s| line_col(text, s.start)).unwrap_or_default();
            let key = e.span().and_then(|s| key_path_at(text, s.start)).map(|k| format!(" (key `{k}`)")).unwrap_or_default();
            bail!("{}{at}{key}: invalid TOML: {}", path.display(), quote_short(&one_line(e.message())))
        }
    }
}

/// The dotted key defined on the line that holds `offset`, with its table header: `[a.b]` then
/// `c = …` gives `a.b.c` (a best effort for error messages; `None` where the line is no key).
fn key_path_at(text: &str, offset: usize) -> Option<String> {
    let before = text.get(..offset.min(text.len()))?;
    let line_start = before.rfind('\n').map(|i| i + 1).unwrap_or(0);
    let line = text.get(line_start..)?.lines().next().unwrap_or("").trim();
    let (key, _) = line.split_once('=')?;
    let key = key.trim().trim_matches('"');
    if key.is_empty() || key.starts_with('#') {
        return None;
    }
    let header = before[..line_start]
        .lines()
        .rev()
        .map(str::trim)
        .find(|l| l.starts_with('[') && !l.starts_with("[["))
        .map(|l| l.trim_matches(|c| c == '[' || c == ']').trim().to_string());
    Some(match header {
        Some(h) if !h.is_empty() => format!("{h}.{key}"),
        _ => key.to_string(),
    })
}

/// Applies one `key=value` override to a parsed TOML table.
pub fn apply_override(table: &mut toml::Table, set: &str) -> Result<()> {
    let Some((key, value)) = set.split_once('=') else {
        bail!("--set {:?}: expected key=value (e.g. ppo.learning_rate=1e-3)", quote_short(set));
    };
    let key = key.trim();
    let parts: Vec<&str> = key.split('.').collect();
    if parts.iter().any(|p| p.is_empty()) {
        bail!("--set {:?}: `{}` is not a dotted key path", quote_short(set), quote_short(key));
    }
    let value = value.trim();
    let parsed: toml::Value = match format!("v = {value}").parse::<toml::Table>() {
        Ok(mut t) => t.remove("v").unwrap_or_else(|| toml::Value::String(value.to_string())),
        Err(_) => toml::Value::String(value.to_string()),
    };
    let mut cur = table;
    for p in &parts[..parts.len() - 1] {
        let entry = cur.entry(p.to_string()).or_insert_with(|| toml::Value::Table(toml::Table::new()));
        cur = match entry {
            toml::Value::Table(t) => t,
            _ => bail!("--set {:?}: `{p}` is a value, not a table", quote_short(set)),
        };
    }
    cur.insert(parts[parts.len() - 1].to_string(), parsed);
    Ok(())
}

fn line_col(text: &str, offset: usize) -> String {
    let before = text.get(..offset.min(text.len())).unwrap_or(text);
    let line = before.matches('\n').count() + 1;
    let col = before.rsplit('\n').next().map(|l| l.chars().count() + 1).unwrap_or(1);
    format!(":{line}:{col}")
}
