//! THE description of what a task exchanges with a learner: every observation field (actor and
//! critic) once — its name, size, units, frame, noise and the task kinds that have it — and each
//! kind's reward terms. [`TaskSpec`] (names, sizes, offsets), `dextrain check`'s printout, the
//! twins' tests and the exported policy's contract are all derived from these tables; the twins
//! (`task::task` and `shaders/task.wgsl`) write the fields in the order listed here, and
//! `tests/suite/task.rs` checks that each field's values land at its offset on both backends.

use crate::config::TaskKind;
pub use super::task::MAX_TERMS;

// ---------------------------------------------------------------------------------------------
// Observations
// ---------------------------------------------------------------------------------------------

/// How many times a field repeats for a hand (its size is `repeat × components`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Repeat {
    /// Once.
    Once,
    /// Once per actuated joint (`q.<joint>`).
    PerJoint,
    /// Once per action (`prev_action.<action>`).
    PerAction,
    /// Once per fingertip (`tip_pos.<tip>`).
    PerTip,
    /// Once per hand link, after fixed joints are merged (`link_contact.<link>`).
    PerLink,
}

/// The components of one repetition of a field.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Components {
    /// One number.
    Scalar,
    /// x, y, z.
    Xyz,
    /// A quaternion qx, qy, qz, qw.
    Quat,
}

impl Components {
    /// Numbers per repetition.
    pub fn len(self) -> usize {
        match self {
            Components::Scalar => 1,
            Components::Xyz => 3,
            Components::Quat => 4,
        }
    }

    /// Suffixes of the entry names (none for a scalar).
    pub fn suffixes(self) -> &'static [&'static str] {
        match self {
            Components::Scalar => &[],
            Components::Xyz => &["x", "y", "z"],
            Components::Quat => &["qx", "qy", "qz", "qw"],
        }
    }
}

/// Which task kinds have a field.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kinds {
    /// Every kind.
    All,
    /// The lift task only.
    Lift,
    /// The reference-following kinds (track, residual_joint, residual_task).
    Reference,
    /// residual_task only.
    ResidualTask,
}

impl Kinds {
    /// Whether `kind` has the field.
    pub fn has(self, kind: TaskKind) -> bool {
        match self {
            Kinds::All => true,
            Kinds::Lift => kind == TaskKind::Lift,
            Kinds::Reference => kind.follows_reference(),
            Kinds::ResidualTask => kind == TaskKind::ResidualTask,
        }
    }

    /// For printouts.
    pub fn describe(self) -> &'static str {
        match self {
            Kinds::All => "all",
            Kinds::Lift => "lift",
            Kinds::Reference => "track, residual_joint, residual_task",
            Kinds::ResidualTask => "residual_task",
        }
    }
}

/// Who sees a field.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Audience {
    /// The actor (with noise where `noise` is set) and, clean, the critic.
    Actor,
    /// The critic only (privileged simulator state).
    Critic,
}

/// One observation field.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ObsField {
    /// The name; entries are `<name>.<joint|action|tip>.<component>` (`refK.` in front for the
    /// look-ahead block).
    pub name: &'static str,
    /// Repetitions.
    pub repeat: Repeat,
    /// Components per repetition.
    pub components: Components,
    /// Units of the values.
    pub units: &'static str,
    /// The frame the values are expressed in (or what they are relative to).
    pub frame: &'static str,
    /// The task kinds that have the field.
    pub kinds: Kinds,
    /// Actor (and critic) or critic only.
    pub audience: Audience,
    /// The `[task.obs_noise]` key of the actor's noise ("" = none).
    pub noise: &'static str,
    /// Whether the field is part of the reference block repeated for `ref0 … refK` (the current
    /// reference frame and `task.track.lookahead` frames after it).
    pub per_reference_frame: bool,
}

const fn field(name: &'static str, repeat: Repeat, components: Components, units: &'static str, frame: &'static str, kinds: Kinds, noise: &'static str) -> ObsField {
    ObsField { name, repeat, components, units, frame, kinds, audience: Audience::Actor, noise, per_reference_frame: false }
}

const fn reference(name: &'static str, repeat: Repeat, components: Components, units: &'static str, frame: &'static str) -> ObsField {
    ObsField { name, repeat, components, units, frame, kinds: Kinds::Reference, audience: Audience::Actor, noise: "", per_reference_frame: true }
}

const fn critic(name: &'static str, repeat: Repeat, components: Components, units: &'static str, frame: &'static str) -> ObsField {
    ObsField { name, repeat, components, units, frame, kinds: Kinds::All, audience: Audience::Critic, noise: "", per_reference_frame: false }
}

use Components::{Quat, Scalar, Xyz};
use Repeat::{Once, PerAction, PerJoint, PerLink, PerTip};

/// The critic's field of each fingertip's normal force (N), which eval's force statistics read.
pub const TIP_FORCE: &str = "tip_force";

/// Every observation field, in the order the twins write them: the actor's fields (which the
/// critic also sees, without noise), then the critic's privileged extras. The reference block
/// (`per_reference_frame`) is written once per reference frame `ref0 … refK`, each relative to the
/// env's (actor: noisy) state.
pub const OBS_FIELDS: [ObsField; 30] = [
    field("q", PerJoint, Scalar, "rad", "joint", Kinds::All, "joint_pos"),
    field("qd", PerJoint, Scalar, "rad/s", "joint", Kinds::All, "joint_vel"),
    field("prev_action", PerAction, Scalar, "action in [-1, 1]", "action", Kinds::All, ""),
    field("wrist_pos", Once, Xyz, "m", "world", Kinds::All, "hand_pos"),
    field("wrist_rot", Once, Quat, "unit quaternion", "world", Kinds::All, ""),
    field("tip_pos", PerTip, Xyz, "m", "world", Kinds::All, "hand_pos"),
    field("obj_pos", Once, Xyz, "m", "world", Kinds::All, "object_pos"),
    field("obj_rot", Once, Quat, "unit quaternion", "world", Kinds::All, "object_rot"),
    field("goal", Once, Xyz, "m", "world (rest position + success_height)", Kinds::Lift, ""),
    field("obj_rel", Once, Xyz, "m", "world (p_obj − p_palm)", Kinds::Lift, "object_pos, hand_pos"),
    reference("wrist_pos", Once, Xyz, "m", "world, reference − wrist"),
    reference("wrist_rot", Once, Xyz, "rad (rotation vector)", "world, log(q_ref ⊗ q_wrist⁻¹)"),
    reference("q", PerJoint, Scalar, "rad", "joint, reference − q"),
    reference("obj_pos", Once, Xyz, "m", "world, reference − object"),
    reference("obj_rot", Once, Xyz, "rad (rotation vector)", "world, log(q_ref ⊗ q_obj⁻¹)"),
    reference("tip_pos", PerTip, Xyz, "m", "world, reference − fingertip"),
    field("phase", Once, Scalar, "fraction in [0, 1]", "reference progress", Kinds::Reference, ""),
    field("residual", PerAction, Scalar, "fraction of the clamp in [-1, 1]", "Δa / clamp", Kinds::ResidualTask, ""),
    critic("obj_vel", Once, Xyz, "m/s", "world"),
    critic("obj_angvel", Once, Xyz, "rad/s", "world"),
    critic("wrist_vel", Once, Xyz, "m/s", "world"),
    critic("wrist_angvel", Once, Xyz, "rad/s", "world"),
    critic("tip_contact", PerTip, Scalar, "0 or 1 (force > task.hand.contact_force)", "fingertip"),
    critic(TIP_FORCE, PerTip, Scalar, "N (the step's mean normal force)", "fingertip"),
    critic("link_contact", PerLink, Scalar, "0 or 1 (pushed on the object during the step)", "hand link"),
    critic("obj_mass", Once, Scalar, "kg", "drawn parameter"),
    critic("obj_friction", Once, Scalar, "coefficient", "drawn parameter"),
    critic("obj_scale", Once, Scalar, "scale", "drawn parameter"),
    critic("obj_restitution", Once, Scalar, "coefficient in [0, 1]", "drawn parameter"),
    critic("added_gravity", Once, Scalar, "m/s² (added to gravity's magnitude, pulling the object down)", "drawn parameter"),
];

/// One field of a built layout: where it sits in the observation vector.
#[derive(Clone, Debug, PartialEq)]
pub struct ObsSlot {
    /// The field it lays out.
    pub field: ObsField,
    /// Its name in this layout (`refK.<name>` for the reference block).
    pub name: String,
    /// First index in the observation vector.
    pub offset: usize,
    /// Numbers.
    pub size: usize,
    /// One name per number (`q.<joint>`, `tip_pos.<tip>.x`, …).
    pub entries: Vec<String>,
}

/// The names a layout repeats over: the hand's actuated joints, the actions and the fingertips.
pub struct LayoutNames<'a> {
    /// Actuated joint names, in action order.
    pub joints: &'a [String],
    /// Action names.
    pub actions: &'a [String],
    /// Fingertip names.
    pub tips: &'a [String],
    /// Hand link names (after fixed joints are merged), in the model's link order.
    pub links: &'a [String],
}

/// The actor and critic layouts of `kind` for a hand (`lookahead`: `task.track.lookahead`). The
/// critic's layout starts with every actor field (clean), then the critic-only ones.
pub fn obs_layout(kind: TaskKind, names: &LayoutNames, lookahead: u32) -> (Vec<ObsSlot>, Vec<ObsSlot>) {
    let mut actor = Vec::new();
    let mut offset = 0;
    let push = |out: &mut Vec<ObsSlot>, f: &ObsField, prefix: &str, offset: &mut usize| {
        let items: Vec<&str> = match f.repeat {
            Repeat::Once => vec![""],
            Repeat::PerJoint => names.joints.iter().map(String::as_str).collect(),
            Repeat::PerAction => names.actions.iter().map(String::as_str).collect(),
            Repeat::PerTip => names.tips.iter().map(String::as_str).collect(),
            Repeat::PerLink => names.links.iter().map(String::as_str).collect(),
        };
        let name = format!("{prefix}{}", f.name);
        let mut entries = Vec::new();
        for item in &items {
            let base = if item.is_empty() { name.clone() } else { format!("{name}.{item}") };
            match f.components {
                Components::Scalar => entries.push(base),
                c => entries.extend(c.suffixes().iter().map(|s| format!("{base}.{s}"))),
            }
        }
        let size = entries.len();
        out.push(ObsSlot { field: *f, name, offset: *offset, size, entries });
        *offset += size;
    };
    let mut i = 0;
    while i < OBS_FIELDS.len() {
        let f = &OBS_FIELDS[i];
        if f.audience == Audience::Critic || !f.kinds.has(kind) {
            i += 1;
            continue;
        }
        if f.per_reference_frame {
            // the block of consecutive per-frame fields, repeated for ref0 … refK
            let end = (i..OBS_FIELDS.len()).find(|&j| !OBS_FIELDS[j].per_reference_frame).unwrap_or(OBS_FIELDS.len());
            for r in 0..=lookahead {
                for g in &OBS_FIELDS[i..end] {
                    push(&mut actor, g, &format!("ref{r}."), &mut offset);
                }
            }
            i = end;
            continue;
        }
        push(&mut actor, f, "", &mut offset);
        i += 1;
    }
    let mut critic = actor.clone();
    for f in OBS_FIELDS.iter().filter(|f| f.audience == Audience::Critic && f.kinds.has(kind)) {
        push(&mut critic, f, "", &mut offset);
    }
    (actor, critic)
}

/// The names of the fields of `kind`'s critic observation (`lookahead`: `task.track.lookahead`).
pub fn critic_field_names(kind: TaskKind, lookahead: u32) -> Vec<String> {
    let none: [String; 0] = [];
    let names = LayoutNames { joints: &none, actions: &none, tips: &none, links: &none };
    obs_layout(kind, &names, lookahead).1.into_iter().map(|s| s.name).collect()
}

/// The indices in a layout's vector of every entry of the named fields, field by field in the
/// order given (e.g. the privileged encoder's inputs in the critic observation).
pub fn field_indices(layout: &[ObsSlot], names: &[String]) -> Result<Vec<usize>, String> {
    let mut out = Vec::new();
    for n in names {
        let s = layout.iter().find(|s| &s.name == n).ok_or_else(|| {
            let have: Vec<&str> = layout.iter().map(|s| s.name.as_str()).collect();
            format!("no observation field {n:?} (fields: {})", have.join(", "))
        })?;
        out.extend(s.offset..s.offset + s.size);
    }
    Ok(out)
}

/// The entry names of a layout, in order.
pub fn entry_names(layout: &[ObsSlot]) -> Vec<String> {
    layout.iter().flat_map(|s| s.entries.iter().cloned()).collect()
}

/// A layout as an aligned table (`dextrain check`'s printout): offset, size, name, units, frame,
/// noise and the kinds that have each field.
pub fn layout_table(layout: &[ObsSlot], title: &str) -> String {
    let mut out = format!("{title} ({} numbers)\n", layout.iter().map(|s| s.size).sum::<usize>());
    out.push_str(&format!("  {:>6} {:>5}  {:<22} {:<34} {:<40} {}\n", "offset", "size", "field", "units", "frame", "noise"));
    for s in layout {
        let noise = if s.field.noise.is_empty() { "-".to_string() } else { format!("task.obs_noise.{}", s.field.noise) };
        out.push_str(&format!("  {:>6} {:>5}  {:<22} {:<34} {:<40} {}\n", s.offset, s.size, s.name, s.field.units, s.field.frame, noise));
    }
    out
}

// Reward terms: the tables are config-level data (`crate::config::rewards`), re-exported here.
pub use crate::config::rewards::*;

// ---------------------------------------------------------------------------------------------
// Names and sizes of a built task
// ---------------------------------------------------------------------------------------------

/// Names and sizes of a task batch.
#[derive(Clone, Debug)]
pub struct TaskSpec {
    /// Number of envs N.
    pub num_envs: usize,
    /// Actor observation length.
    pub obs_dim: usize,
    /// Critic observation length: the clean (noise-free) actor obs, then privileged extras.
    pub priv_dim: usize,
    /// 6 + number of actuated joints.
    pub action_dim: usize,
    /// One name per actor obs entry (see the module documentation).
    pub obs_names: Vec<String>,
    /// One name per critic obs entry.
    pub priv_names: Vec<String>,
    /// One name per action: `wrist_dx`, `wrist_dy`, `wrist_dz`, `wrist_rx`, `wrist_ry`, `wrist_rz`,
    /// then `q.<joint>` per actuated joint.
    pub action_names: Vec<String>,
    /// The reward terms (`config::LIFT_TERMS`, in that order).
    pub term_names: Vec<String>,
    /// Env steps per episode (`task.episode_length`).
    pub episode_length: u32,
    /// Seconds per env step (`sim.dt · sim.decimation`).
    pub control_dt: f32,
    /// `task.kind`.
    pub kind: TaskKind,
    /// The actor observation's layout (fields, offsets, sizes; [`obs_layout`]).
    pub obs_layout: Vec<ObsSlot>,
    /// The critic observation's layout: the actor's fields, then the privileged ones.
    pub priv_layout: Vec<ObsSlot>,
}

