//! `[sim]`, `[table]`, `[contact]` and `[randomization]`: the batched physics (docs/design.md §4)
//! and the backend it runs on.

use std::fmt;
use std::str::FromStr;

use anyhow::Result;
use serde::{Deserialize, Serialize};

use super::Check;

/// Where the simulator (`sim.backend`) or the learner (`train.device`) runs. In the TOML and on the
/// command line: `"auto"` (a hardware GPU adapter if there is one, else the CPU), `"cpu"`, `"gpu"`
/// (a hardware GPU adapter; an error if there is none) or `"gpu:NAME"` (the wgpu adapter whose name
/// contains NAME, e.g. `"gpu:llvmpipe"` for Mesa's software Vulkan driver).
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum BackendChoice {
    /// A hardware GPU adapter if there is one, else the CPU.
    Auto,
    /// The CPU.
    Cpu,
    /// A GPU adapter; `None` = any hardware adapter, `Some(name)` = the adapter whose name contains it.
    Gpu(Option<String>),
}

/// The allowed spellings, for error messages.
pub const BACKEND_CHOICES: &str = "one of \"auto\", \"cpu\", \"gpu\", \"gpu:ADAPTER_NAME\"";

impl FromStr for BackendChoice {
    type Err = String;
    /// `"auto"`, `"cpu"`, `"gpu"` or `"gpu:NAME"` (NAME not empty).
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "auto" => Ok(BackendChoice::Auto),
            "cpu" => Ok(BackendChoice::Cpu),
            "gpu" => Ok(BackendChoice::Gpu(None)),
            _ => s.strip_prefix("gpu:").filter(|n| !n.is_empty()).map(|n| BackendChoice::Gpu(Some(n.to_string()))).ok_or_else(|| format!("expected {BACKEND_CHOICES}")),
        }
    }
}

impl fmt::Display for BackendChoice {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            BackendChoice::Auto => f.write_str("auto"),
            BackendChoice::Cpu => f.write_str("cpu"),
            BackendChoice::Gpu(None) => f.write_str("gpu"),
            BackendChoice::Gpu(Some(n)) => write!(f, "gpu:{n}"),
        }
    }
}

impl Serialize for BackendChoice {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(self)
    }
}

impl<'de> Deserialize<'de> for BackendChoice {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let s = String::deserialize(d)?;
        s.parse().map_err(serde::de::Error::custom)
    }
}

/// `[sim]`
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SimConfig {
    /// `"auto"` (a hardware GPU adapter if there is one, else the CPU), `"cpu"`, `"gpu"` (a hardware
    /// GPU adapter; an error if there is none) or `"gpu:NAME"` (the wgpu adapter whose name contains
    /// NAME, e.g. `"gpu:llvmpipe"` for Mesa's software Vulkan driver).
    pub backend: BackendChoice,
    /// Number of parallel environments (of each process in an MPI job: docs/mpi.md).
    pub num_envs: usize,
    /// Physics step (s).
    pub dt: f32,
    /// Substeps inside each physics step (contact stiffness needs them).
    pub substeps: u32,
    /// Physics steps per env (control) step.
    pub decimation: u32,
    /// Object or wrist speed (m/s) above which an env counts as exploded and is reset.
    pub max_speed: f32,
    /// Distance (m) from the origin beyond which an object or wrist counts as exploded.
    pub max_distance: f32,
}

/// `[table]`
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TableConfig {
    /// Coulomb friction coefficient of the table.
    pub friction: f32,
    /// Whether the hand collides with the table.
    pub hand_collision: bool,
}

/// `[contact]`
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ContactConfig {
    /// Normal penalty stiffness (N/m per contact) of the object against the table.
    pub stiffness: f32,
    /// Stiffness of the tangential spring that holds the object's sticking contacts on the table (N/m).
    pub friction_stiffness: f32,
    /// Normal stiffness (N/m) of the hand's contacts (with the object and the table): a fingertip
    /// pushing with F sinks in F/k at rest (2e5: 0.05 mm at 10 N, 0.5 mm under the arm's 100 N).
    /// They are solved implicitly on the hand's side, so any value is stable on the lightest
    /// finger, and the object's answer in its own implicit solve goes back to the hand
    /// (`react_to_object_motion`), so a light object squeezed between stiff fingers holds still
    /// (without that, above ~5e4 it rang between them and slipped out: BENCHMARKS.md).
    pub hand_stiffness: f32,
    /// Stiffness of the tangential spring that holds the hand's sticking contacts (N/m).
    pub hand_friction_stiffness: f32,
    /// Effective mass of a hand link at a contact (kg), used with the object's mass to turn the
    /// restitution into a damping coefficient (reduced mass of the pair).
    pub hand_effective_mass: f32,
    /// Radius (m) of the contact patch of hand–object and object–table contacts: it resists spinning
    /// about the contact normal with up to μ·Fn·radius (torsional friction); 0 turns it off.
    pub torsion_radius: f32,
}

/// `[randomization]`: ranges `[lo, hi]` drawn uniformly per env at every reset. Scales multiply the
/// nominal value; `[1, 1]` turns a scale off.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RandomizationConfig {
    /// Scale of every hand link mass (and the inertias that follow from it).
    pub hand_mass: [f32; 2],
    /// Scale of the hand's friction coefficient.
    pub hand_friction: [f32; 2],
    /// Scale of the finger joints' position limits (both limits are multiplied).
    pub joint_limits: [f32; 2],
    /// Scale of the finger joints' servo stiffness `kp`.
    pub joint_stiffness: [f32; 2],
    /// Scale of the finger joints' servo damping `kd` and joint damping.
    pub joint_damping: [f32; 2],
    /// Scale of the object's mass.
    pub object_mass: [f32; 2],
    /// Scale of the object's friction coefficient.
    pub object_friction: [f32; 2],
    /// Scale of every length of the object.
    pub object_scale: [f32; 2],
    /// Absolute restitution of the object's contacts; unset = `object.restitution`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub object_restitution: Option<[f32; 2]>,
    /// Scale of the table's friction coefficient.
    pub table_friction: [f32; 2],
    /// Extra downward acceleration on the object (m/s², added to g).
    pub added_gravity: [f32; 2],
}

impl Default for SimConfig {
    fn default() -> Self {
        SimConfig { backend: BackendChoice::Auto, num_envs: 64, dt: 1.0 / 120.0, substeps: 4, decimation: 4, max_speed: 50.0, max_distance: 10.0 }
    }
}

impl Default for TableConfig {
    fn default() -> Self {
        TableConfig { friction: 1.0, hand_collision: true }
    }
}

impl Default for ContactConfig {
    fn default() -> Self {
        ContactConfig { stiffness: 1.0e4, friction_stiffness: 1.0e4, hand_stiffness: 2.0e5, hand_friction_stiffness: 1.0e4, hand_effective_mass: 0.1, torsion_radius: 0.005 }
    }
}

impl Default for RandomizationConfig {
    fn default() -> Self {
        RandomizationConfig {
            hand_mass: [1.0, 1.0],
            hand_friction: [1.0, 1.0],
            joint_limits: [1.0, 1.0],
            joint_stiffness: [1.0, 1.0],
            joint_damping: [1.0, 1.0],
            object_mass: [1.0, 1.0],
            object_friction: [1.0, 1.0],
            object_scale: [1.0, 1.0],
            object_restitution: None,
            table_friction: [1.0, 1.0],
            added_gravity: [0.0, 0.0],
        }
    }
}

impl SimConfig {
    /// Checks `[sim]`.
    pub fn validate(&self, c: &Check) -> Result<()> {
        if self.num_envs == 0 || self.num_envs > 16_777_216 {
            return Err(c.err("sim.num_envs", self.num_envs, "an integer in [1, 16777216]"));
        }
        c.in_range("sim.dt", self.dt, 1e-5, 0.1, "a time step in seconds in [1e-5, 0.1]")?;
        if !(1..=64).contains(&self.substeps) {
            return Err(c.err("sim.substeps", self.substeps, "an integer in [1, 64]"));
        }
        if !(1..=1000).contains(&self.decimation) {
            return Err(c.err("sim.decimation", self.decimation, "an integer in [1, 1000]"));
        }
        c.in_range("sim.max_speed", self.max_speed, 1e-3, 1e6, "a speed in m/s in (0, 1e6]")?;
        c.in_range("sim.max_distance", self.max_distance, 1e-3, 1e6, "a distance in m in (0, 1e6]")
    }
}

impl ContactConfig {
    /// Checks `[contact]`.
    pub fn validate(&self, c: &Check) -> Result<()> {
        c.in_range("contact.stiffness", self.stiffness, 1.0, 1e8, "a stiffness in N/m in [1, 1e8]")?;
        c.in_range("contact.friction_stiffness", self.friction_stiffness, 1.0, 1e8, "a stiffness in N/m in [1, 1e8]")?;
        c.in_range("contact.hand_stiffness", self.hand_stiffness, 1.0, 1e8, "a stiffness in N/m in [1, 1e8]")?;
        c.in_range("contact.hand_friction_stiffness", self.hand_friction_stiffness, 1.0, 1e8, "a stiffness in N/m in [1, 1e8]")?;
        c.in_range("contact.hand_effective_mass", self.hand_effective_mass, 1e-4, 1e3, "a mass in kg in [1e-4, 1000]")?;
        c.in_range("contact.torsion_radius", self.torsion_radius, 0.0, 0.1, "a patch radius in m in [0, 0.1]")
    }
}

impl RandomizationConfig {
    /// Checks `[randomization]`.
    pub fn validate(&self, c: &Check) -> Result<()> {
        for (key, range) in [
            ("randomization.hand_mass", self.hand_mass),
            ("randomization.hand_friction", self.hand_friction),
            ("randomization.joint_limits", self.joint_limits),
            ("randomization.joint_stiffness", self.joint_stiffness),
            ("randomization.joint_damping", self.joint_damping),
            ("randomization.object_mass", self.object_mass),
            ("randomization.object_friction", self.object_friction),
            ("randomization.object_scale", self.object_scale),
            ("randomization.table_friction", self.table_friction),
        ] {
            let ok = range.iter().all(|v| v.is_finite() && *v > 0.0 && *v <= 100.0) && range[0] <= range[1];
            if !ok {
                return Err(c.err(key, format!("{range:?}"), "a scale range [lo, hi] with 0 < lo <= hi <= 100"));
            }
        }
        if let Some(range) = self.object_restitution {
            let ok = range.iter().all(|v| v.is_finite() && (0.0..1.0).contains(v)) && range[0] <= range[1];
            if !ok {
                return Err(c.err("randomization.object_restitution", format!("{range:?}"), "a range [lo, hi] with 0 <= lo <= hi < 1"));
            }
        }
        let g = self.added_gravity;
        if !(g.iter().all(|v| v.is_finite() && (0.0..=100.0).contains(v)) && g[0] <= g[1]) {
            return Err(c.err("randomization.added_gravity", format!("{g:?}"), "a range [lo, hi] in m/s² with 0 <= lo <= hi <= 100"));
        }
        Ok(())
    }
}
