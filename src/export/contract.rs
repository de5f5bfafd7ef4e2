//! `policy.json`: the contract that comes with an exported policy — everything a robot's control
//! loop needs to feed `policy.onnx` and to turn its output into joint and wrist targets, with
//! nothing left to guess (docs/design.md §7). `dextrain play` drives the simulator from this file and the
//! ONNX model alone, which is the proof that the contract is complete.
//!
//! Built from what the simulator itself uses: the task's observation layout (`task::spec`), the
//! task constants as the shaders receive them (`TaskGlobals`, so every number is the f32 that
//! training used), and the hand's joints as the physics steps them (`JointDesc`). Joint lists are
//! in the URDF's joint order (movable joints, topological), actions in action order; the two are
//! named, never positional.

use std::collections::BTreeMap;

use anyhow::{Context, Result, ensure};
use serde::{Deserialize, Serialize};

use crate::config::{Config, FingerMode, TaskKind};
use crate::env::SimModel;
use crate::gpu::layout::NO_JOINT;
use crate::task::layout::TaskGlobals;
use crate::task::spec::{Audience, ObsSlot, TaskSpec};

/// The value of [`PolicyContract::format`].
pub const CONTRACT_FORMAT: &str = "dextrain.policy.v1";
/// The contract's file name in an export directory.
pub const CONTRACT_FILE: &str = "policy.json";

/// The whole contract (`policy.json`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PolicyContract {
    /// [`CONTRACT_FORMAT`].
    pub format: String,
    /// The dextrain version that exported it (`CARGO_PKG_VERSION`).
    pub dextrain_version: String,
    /// Where the policy came from.
    pub source: Source,
    /// The ONNX model: file, hash, inputs and output.
    pub model: ModelFile,
    /// Timing of the control loop.
    pub control: Control,
    /// The hand: URDF, joints, limits, servo gains, fingertips.
    pub hand: HandContract,
    /// The task the policy was trained on.
    pub task: TaskContract,
    /// The `obs` input: every field in order.
    pub observation: Layout,
    /// The `priv_obs` input of a teacher with a privileged encoder (simulator-only quantities; a
    /// robot cannot give them), `None` otherwise.
    pub privileged: Option<Layout>,
    /// The `history` input of a student, `None` otherwise.
    pub history: Option<History>,
    /// The `actions` output.
    pub actions: Actions,
    /// How a robot turns `actions` into targets.
    pub action_mapping: ActionMapping,
}

/// The run and checkpoint a policy came from.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Source {
    /// The run directory.
    pub run: String,
    /// The checkpoint's iteration.
    pub checkpoint: u64,
    /// XXH64 (hex) of the checkpoint's `manifest.json`, which holds the hash of every file of it.
    pub checkpoint_xxh64: String,
    /// The learning algorithm ("ppo", "sac", "distill").
    pub algorithm: String,
    /// A student's teacher: its run, checkpoint iteration and manifest hash.
    pub teacher: Option<TeacherRef>,
}

/// A student's teacher.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TeacherRef {
    /// The teacher's run directory.
    pub run: String,
    /// Its checkpoint's iteration.
    pub checkpoint: u64,
    /// XXH64 (hex) of that checkpoint's `manifest.json`.
    pub checkpoint_xxh64: String,
}

/// One tensor of the ONNX model's interface.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TensorIo {
    /// The ONNX name.
    pub name: String,
    /// Dimensions: "batch" for the dynamic batch axis, numbers otherwise.
    pub shape: Vec<serde_json::Value>,
    /// What it holds.
    pub description: String,
}

/// The ONNX file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModelFile {
    /// File name, next to `policy.json`.
    pub file: String,
    /// XXH64 (hex) of the file.
    pub xxh64: String,
    /// ONNX opset (default domain).
    pub opset: u32,
    /// Inputs (f32), in order.
    pub inputs: Vec<TensorIo>,
    /// The output (f32).
    pub output: TensorIo,
    /// How the model treats its inputs.
    pub notes: String,
}

/// Timing of the control loop.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Control {
    /// Seconds per policy step (`sim.dt · sim.decimation`).
    pub control_dt: f32,
    /// Policy steps per second.
    pub rate_hz: f32,
    /// The simulator's physics step (s) and steps per policy step; substeps per physics step.
    pub sim_dt: f32,
    pub decimation: u32,
    pub substeps: u32,
    /// Policy steps per training episode.
    pub episode_length: u32,
}

/// One movable joint of the hand, as the simulator steps it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct JointContract {
    /// URDF joint name.
    pub name: String,
    /// Position limits (rad; `null` for a continuous joint).
    pub lower: Option<f32>,
    pub upper: Option<f32>,
    /// Target at episode start when no reference sets it (rad).
    pub default: f32,
    /// Position servo of the simulator: τ = clamp(kp (clamp(q*, lower, upper) − q) − kd q̇, ±effort).
    pub kp: f32,
    pub kd: f32,
    pub effort: f32,
    /// A mimic follower: q = multiplier · q_leader + offset; it takes no target.
    pub mimic: Option<MimicContract>,
}

/// A mimic follower's coupling.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MimicContract {
    /// The leader joint's name.
    pub leader: String,
    pub multiplier: f32,
    pub offset: f32,
}

/// A fingertip point.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FingertipContract {
    /// The fingertip's name (its frame in the URDF).
    pub name: String,
    /// The link (after fixed joints are merged) that carries it.
    pub link: String,
    /// Position in that link's frame (m).
    pub position: [f32; 3],
}

/// The hand.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HandContract {
    /// The URDF `<robot name>`.
    pub urdf_name: String,
    /// The URDF file name (as the run used it).
    pub urdf_file: String,
    /// XXH64 (hex) of the URDF file's bytes.
    pub urdf_xxh64: String,
    /// Movable joints in the URDF's (topological) order.
    pub joints: Vec<JointContract>,
    /// The actuated joints, in action order (the `q.<joint>` actions).
    pub actuated: Vec<String>,
    /// Fingertips, in observation order (`tip_pos.<tip>`).
    pub fingertips: Vec<FingertipContract>,
    /// The wrist's pose at episode start (m, world; quaternion x, y, z, w).
    pub init_wrist_pos: [f32; 3],
    pub init_wrist_rot: [f32; 4],
    /// The palm point in the wrist frame (m).
    pub palm_offset: [f32; 3],
}

/// The task.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TaskContract {
    /// `task.kind`.
    pub kind: TaskKind,
    /// Reference-following kinds: how the reference is read.
    pub reference: Option<ReferenceContract>,
}

/// How the reference-following kinds read their reference.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReferenceContract {
    /// Look-ahead frames observed after the current one (`ref1 …`), and policy steps between them.
    pub lookahead: u32,
    pub lookahead_stride: u32,
    /// The reference frames the observations and the action mapping use.
    pub sampling: String,
}

/// One observation field.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FieldContract {
    /// Name (`refK.` in front for the look-ahead block).
    pub name: String,
    /// First index in the input vector, and numbers.
    pub offset: usize,
    pub size: usize,
    /// Units and frame.
    pub units: String,
    pub frame: String,
    /// How the value is computed.
    pub computed: String,
    /// One name per number.
    pub entries: Vec<String>,
    /// Standard deviation of the Gaussian noise training added (the robot gives its measurement).
    pub training_noise_std: f32,
    /// The latency training gave the value, in control steps ([min, max], drawn per episode;
    /// `task.obs_noise.object_delay` on the object pose and what is computed from it): a robot's
    /// measurement as old as this is what the policy learned from.
    pub training_delay_steps: [u32; 2],
}

/// An input vector's layout.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Layout {
    /// Numbers in the vector.
    pub size: usize,
    /// Its fields, in order, covering it exactly.
    pub fields: Vec<FieldContract>,
}

/// A student's history input.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct History {
    /// Steps in the window H.
    pub length: usize,
    /// Numbers per step D, and their layout (offsets within one step; the fields' values are the
    /// same as in `observation`'s fields of the same names).
    pub step: Layout,
    /// Order of the steps.
    pub order: String,
    /// The window's value at episode start.
    pub at_episode_start: String,
}

/// The actions.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Actions {
    /// Numbers A.
    pub size: usize,
    /// One name per action.
    pub names: Vec<String>,
    /// What each action moves and its unit at |a| = 1 (see `action_mapping` for the formulas).
    pub units: Vec<String>,
    /// Every action is clipped to this range before the mapping.
    pub clip: [f32; 2],
}

/// The fingertip IK of `residual_task`'s mapping (`env::ik`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct IkContract {
    /// Most iterations, base damping λ (m), largest joint change per iteration (rad), tolerance (m).
    pub iters: u32,
    pub damping: f32,
    pub max_step: f32,
    pub tol: f32,
    /// The solver's fixed constants (`env::ik`): damping shrink distance (m) and floor (fraction),
    /// curvature term (m), mid-range step fraction, lock rounds, per-iteration residual clamp (m).
    pub damping_dist: f32,
    pub damping_floor: f32,
    pub damping_curvature: f32,
    pub midrange_bias: f32,
    pub lock_rounds: u32,
    pub residual_clamp: f32,
    /// The algorithm.
    pub method: String,
}

/// How a robot turns the policy's output into wrist and joint targets. Every formula is applied
/// per policy step to the clipped actions `a`; targets go to the servos (joints) and the wrist's
/// pose controller.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case", deny_unknown_fields)]
pub enum ActionMapping {
    /// lift, and track with `task.track.action = "free"`: the actions move the wrist target and set
    /// or move the finger targets.
    Direct {
        /// Wrist translation per step at |a| = 1 (m), and the box (world, m) it is clipped to.
        wrist_pos_scale: f32,
        wrist_pos_min: [f32; 3],
        wrist_pos_max: [f32; 3],
        /// Wrist rotation per step at |a| = 1 (rad) and the largest angle from the initial
        /// orientation (rad).
        wrist_rot_scale: f32,
        wrist_rot_limit: f32,
        /// Finger targets: absolute or delta.
        finger_mode: FingerMode,
        /// The targets at episode start (the previous targets of the first step).
        start: StartTargets,
        /// Delta mode: change per step at |a| = 1 (rad).
        finger_delta_scale: f32,
        /// The formulas, in order.
        formulas: Vec<String>,
    },
    /// residual_joint, and track with `task.track.action = "reference"`: targets around the
    /// reference frame at the end of the step.
    ResidualJoint {
        /// Finger residual at |a| = 1 (rad), wrist translation (m) and rotation (rad) residuals.
        joint_alpha: f32,
        wrist_pos_alpha: f32,
        wrist_rot_alpha: f32,
        /// The formulas, in order.
        formulas: Vec<String>,
    },
    /// residual_task: smoothed, integrated wrist and fingertip residuals around the reference, the
    /// fingers from fingertip IK.
    ResidualTask {
        /// EMA weight of the new output.
        ema: f32,
        /// Integration scales (m/s, rad/s, m/s) and clamps (m, rad, m) of the wrist translation,
        /// wrist rotation and fingertip components.
        scale_wrist_pos: f32,
        scale_wrist_rot: f32,
        scale_tips: f32,
        clamp_wrist_pos: f32,
        clamp_wrist_rot: f32,
        clamp_tips: f32,
        /// Δt of the integration (s): the control step.
        dt: f32,
        /// The fingertip IK.
        ik: IkContract,
        /// The formulas, in order.
        formulas: Vec<String>,
    },
}

/// The targets a `direct` mapping starts each episode from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StartTargets {
    /// The initial wrist pose (`hand.init_wrist_pos/rot`) and each joint's `default`.
    Initial,
    /// The reference's first frame: its wrist pose and joint positions (track with free actions
    /// and `task.track.start = "reference"`).
    ReferenceFirstFrame,
}

/// What the caller knows of the run that the task and hand do not say.
pub struct ContractSource<'a> {
    pub source: Source,
    /// The ONNX file's name, bytes and interface.
    pub model_file: &'a str,
    pub model_bytes: &'a [u8],
    pub inputs: Vec<TensorIo>,
    pub output: TensorIo,
    /// The `obs` input's fields: the names of the actor layout's fields it holds, in order (a
    /// student may hold fewer than the task's actor observation), and the `priv_obs` input's.
    pub obs_fields: Vec<String>,
    pub priv_fields: Option<Vec<String>>,
    /// A student's history: field names and length.
    pub history: Option<(Vec<String>, usize)>,
}

/// How each observation field is computed, by field name (the reference block's names without
/// their `refK.`). Every field of `task::spec::OBS_FIELDS` has an entry (a test checks it).
pub fn computed(name: &str) -> Option<&'static str> {
    Some(match name {
        "q" => "position of each actuated joint (rad), in `hand.actuated` order",
        "qd" => "velocity of each actuated joint (rad/s)",
        "prev_action" => "the previous policy step's actions after clipping to [-1, 1] (0 at episode start)",
        "wrist_pos" => "wrist (root link) position in the world frame (m)",
        "wrist_rot" => "wrist orientation in the world frame, unit quaternion x, y, z, w",
        "tip_pos" => "each fingertip point (hand.fingertips) in the world frame (m)",
        "obj_pos" => "object centre position in the world frame (m)",
        "obj_rot" => "object orientation in the world frame, unit quaternion x, y, z, w",
        "goal" => "the lift goal: the object's rest position at episode start raised by the success height (m, world)",
        "obj_rel" => "object centre minus the palm point (wrist_pos + R_wrist · palm_offset), world frame (m)",
        "phase" => "policy steps since episode start / the reference's length in policy steps, clamped to [0, 1]",
        "residual" => "residual_task's integrated residual Δa divided component-wise by max(clamp, 1e-9) (clamps: wrist pos, wrist rot, fingertips); 0 at episode start",
        "obj_vel" => "object linear velocity, world frame (m/s)",
        "obj_angvel" => "object angular velocity, world frame (rad/s)",
        "wrist_vel" => "wrist linear velocity, world frame (m/s)",
        "wrist_angvel" => "wrist angular velocity, world frame (rad/s)",
        "tip_contact" => "1 if the fingertip's mean normal force on the object over the step exceeds the contact threshold, else 0",
        "tip_force" => "each fingertip's normal force on the object, mean over the step's physics substeps (N)",
        "obj_mass" => "the object's mass drawn for the episode (kg)",
        "obj_friction" => "the object's friction coefficient drawn for the episode",
        "obj_scale" => "the object's size scale drawn for the episode",
        "obj_restitution" => "the object's restitution drawn for the episode",
        "added_gravity" => "the extra gravity drawn for the episode (m/s²)",
        "link_contact" => "1 if a collision shape of the hand link pushed on the object (normal force > 0) in any physics substep of the step, else 0; one per link of the URDF after fixed joints are merged",
        _ => return None,
    })
}

/// How a reference-block field is computed (the reference frame minus the current state).
fn computed_reference(name: &str) -> Option<&'static str> {
    Some(match name {
        "wrist_pos" => "reference wrist position minus the wrist position, world frame (m)",
        "wrist_rot" => "rotation vector of q_ref ⊗ q_wrist⁻¹ (rad, world frame)",
        "q" => "reference joint position minus the joint position, per actuated joint (rad)",
        "obj_pos" => "reference object position minus the object position, world frame (m)",
        "obj_rot" => "rotation vector of q_ref ⊗ q_obj⁻¹ (rad, world frame)",
        "tip_pos" => "reference fingertip position minus the fingertip position, world frame (m)",
        _ => return None,
    })
}

/// The noise standard deviation training added to a field (`noise` key list of the spec).
fn training_noise(cfg: &Config, slot: &ObsSlot, actor: bool) -> f32 {
    if !actor || slot.field.audience == Audience::Critic {
        return 0.0;
    }
    let n = &cfg.task.obs_noise;
    // the first key of the field's noise column is the one its values get
    match slot.field.noise.split(',').next().map(str::trim).unwrap_or("") {
        "joint_pos" => n.joint_pos,
        "joint_vel" => n.joint_vel,
        "hand_pos" => n.hand_pos,
        "object_pos" => n.object_pos,
        "object_rot" => n.object_rot,
        _ => 0.0,
    }
}

/// The latency training gave a field: the object pose's, on the actor's fields computed from it.
fn training_delay(cfg: &Config, slot: &ObsSlot, actor: bool) -> [u32; 2] {
    let from_object_pose = matches!(slot.field.name, "obj_pos" | "obj_rot" | "obj_rel");
    if actor && slot.field.audience == Audience::Actor && from_object_pose { cfg.task.obs_noise.object_delay } else { [0, 0] }
}

/// The contract's view of one layout slot.
fn field_contract(cfg: &Config, slot: &ObsSlot, offset: usize, actor: bool) -> Result<FieldContract> {
    let computed = if slot.field.per_reference_frame { computed_reference(slot.field.name) } else { computed(slot.field.name) };
    let computed = computed.with_context(|| format!("observation field {:?} has no description in export::contract", slot.name))?;
    Ok(FieldContract {
        name: slot.name.clone(),
        offset,
        size: slot.size,
        units: slot.field.units.to_string(),
        frame: slot.field.frame.to_string(),
        computed: computed.to_string(),
        entries: slot.entries.clone(),
        training_noise_std: training_noise(cfg, slot, actor),
        training_delay_steps: training_delay(cfg, slot, actor),
    })
}

/// The layout of an input holding the named fields of `layout`, in the given order.
fn layout_of(cfg: &Config, layout: &[ObsSlot], names: &[String], actor: bool, what: &str) -> Result<Layout> {
    let mut fields = Vec::new();
    let mut offset = 0;
    for name in names {
        let slot = layout.iter().find(|s| &s.name == name).with_context(|| {
            let have: Vec<&str> = layout.iter().map(|s| s.name.as_str()).collect();
            format!("{what}: no observation field {name:?} (fields: {})", have.join(", "))
        })?;
        fields.push(field_contract(cfg, slot, offset, actor)?);
        offset += slot.size;
    }
    Ok(Layout { size: offset, fields })
}

/// Lower-case hex of a 64-bit hash.
pub fn hex(h: u64) -> String {
    format!("{h:016x}")
}

/// The contract of a policy trained with `cfg` on the task `spec`/`tc` and the hand `model`.
pub fn build(cfg: &Config, spec: &TaskSpec, tc: &TaskGlobals, model: &SimModel, src: ContractSource<'_>) -> Result<PolicyContract> {
    let hand = &model.hand;
    let urdf_path = cfg.resolve(&cfg.hand.urdf);
    let urdf = std::fs::read(&urdf_path).with_context(|| format!("cannot read the hand URDF {}", urdf_path.display()))?;
    ensure!(model.joints.len() == hand.joints.len(), "the simulator's joints do not match the hand's");
    let joints = hand
        .joints
        .iter()
        .zip(&model.joints)
        .map(|(j, d)| JointContract {
            name: j.name.clone(),
            lower: (!j.continuous).then_some(d.lower),
            upper: (!j.continuous).then_some(d.upper),
            default: d.default_q,
            kp: d.kp,
            kd: d.kd,
            effort: d.effort,
            mimic: (d.mimic_leader != NO_JOINT).then(|| MimicContract {
                leader: hand.joints[d.mimic_leader as usize].name.clone(),
                multiplier: d.mimic_mult,
                offset: d.mimic_offset,
            }),
        })
        .collect();
    let actuated: Vec<String> = model.spec.actuated.iter().map(|&j| hand.joints[j].name.clone()).collect();
    let fingertips = hand
        .fingertips
        .iter()
        .map(|t| FingertipContract { name: t.name.clone(), link: hand.links[t.link].name.clone(), position: t.pos.to_array() })
        .collect();
    let g = &model.globals;
    let control = Control {
        control_dt: spec.control_dt,
        rate_hz: 1.0 / spec.control_dt,
        sim_dt: cfg.sim.dt,
        decimation: cfg.sim.decimation,
        substeps: cfg.sim.substeps,
        episode_length: spec.episode_length,
    };
    let observation = layout_of(cfg, &spec.obs_layout, &src.obs_fields, true, "the policy's obs input")?;
    let privileged = match &src.priv_fields {
        Some(names) => Some(layout_of(cfg, &spec.priv_layout, names, false, "the policy's priv_obs input")?),
        None => None,
    };
    let history = match &src.history {
        Some((names, length)) => Some(History {
            length: *length,
            step: layout_of(cfg, &spec.obs_layout, names, true, "the policy's history input")?,
            order: "oldest first: history[b, H − 1] is the current step's values, history[b, H − 1 − k] those of k policy steps earlier".into(),
            at_episode_start: "every row equals the episode's first step's values (the first frame repeated H times); from then on the window shifts by one row per policy step".into(),
        }),
        None => None,
    };
    let reference = spec.kind.follows_reference().then(|| ReferenceContract {
        lookahead: tc.lookahead,
        lookahead_stride: tc.lookahead_stride,
        sampling: "the reference is resampled at the control step; frame k of an episode is the reference at time k · control_dt (held at its last frame after its end). \
                   The observation's ref0 block is the frame of the current step, refK the frame K · lookahead_stride steps later; \
                   the action mapping adds to the frame at the end of this step (k + 1)."
            .into(),
    });
    let action_mapping = match spec.kind {
        TaskKind::Lift => direct(tc, StartTargets::Initial),
        // task_init: a reference kind that starts at the reference starts its targets there too
        TaskKind::Track if tc.track_action == 0 => direct(tc, if tc.start_mode == 0 { StartTargets::ReferenceFirstFrame } else { StartTargets::Initial }),
        TaskKind::Track | TaskKind::ResidualJoint => ActionMapping::ResidualJoint {
            joint_alpha: tc.res_alpha,
            wrist_pos_alpha: tc.res_wrist_pos_alpha,
            wrist_rot_alpha: tc.res_wrist_rot_alpha,
            formulas: vec![
                "a = clip(actions, -1, 1); (p̄, R̄, q̄) = the reference frame at the end of this step".into(),
                "wrist position target p* = p̄ + wrist_pos_alpha · a[0..3]".into(),
                "wrist orientation target R* = exp(wrist_rot_alpha · a[3..6]) ⊗ R̄ (rotation vector in the world frame)".into(),
                "for each actuated joint j (action 6 + j): q*_j = clamp(q̄_j + joint_alpha · a[6 + j], lower_j, upper_j)".into(),
                "mimic followers take no target: q = multiplier · q_leader + offset".into(),
            ],
        },
        TaskKind::ResidualTask => ActionMapping::ResidualTask {
            ema: tc.res_ema,
            scale_wrist_pos: tc.res_scale_wrist_pos,
            scale_wrist_rot: tc.res_scale_wrist_rot,
            scale_tips: tc.res_scale_tips,
            clamp_wrist_pos: tc.res_clamp_wrist_pos,
            clamp_wrist_rot: tc.res_clamp_wrist_rot,
            clamp_tips: tc.res_clamp_tips,
            dt: tc.control_dt,
            ik: IkContract {
                iters: tc.ik.iters,
                damping: tc.ik.damping,
                max_step: tc.ik.max_step,
                tol: tc.ik.tol,
                damping_dist: crate::task::ik::IK_DAMPING_DIST,
                damping_floor: crate::task::ik::IK_DAMPING_FLOOR,
                damping_curvature: crate::task::ik::IK_DAMPING_CURV,
                midrange_bias: crate::task::ik::IK_BIAS,
                lock_rounds: crate::task::ik::IK_LOCK_ROUNDS,
                residual_clamp: crate::task::ik::IK_ERR_CLAMP,
                method: "damped least squares over all fingertips together in the wrist frame, seeded at the reference's q̄, with joint-limit locking, \
                         residual-dependent damping and a small step toward each joint's mid-range (dextrain src/task/ik.rs)"
                    .into(),
            },
            formulas: vec![
                "a = clip(actions, -1, 1); (p̄, R̄, q̄) = the reference frame at the end of this step; ũ and Δa start at 0 each episode".into(),
                "for each component c: ũ_c = ema · a_c + (1 − ema) · ũ_c".into(),
                "Δa_c = clamp(Δa_c + s_c · ũ_c · dt, −clamp_c, clamp_c) with (s, clamp) = wrist_pos for c < 3, wrist_rot for 3 ≤ c < 6, tips for c ≥ 6".into(),
                "wrist position target p* = p̄ + Δa[0..3]; orientation R* = exp(Δa[3..6]) ⊗ R̄".into(),
                "finger targets: q* = IK(fingertip goals FK(q̄)_k + Δa[6 + 3k .. 9 + 3k] in the wrist frame, seed q̄); q* = q̄ when every fingertip component of Δa is 0".into(),
                "mimic followers take no target: q = multiplier · q_leader + offset".into(),
            ],
        },
    };
    let model_file = ModelFile {
        file: src.model_file.to_string(),
        xxh64: hex(crate::learn::checkpoint::xxh64(src.model_bytes, 0)),
        opset: 17,
        inputs: src.inputs,
        output: src.output,
        notes: format!(
            "inputs are raw values as described here: the observation normalisation is inside the model; the output is {} before clipping and mapping",
            if src.source.algorithm == "sac" { "the SAC actor's deterministic action tanh(μ), in (−1, 1)," } else { "the policy's mean action" }
        ),
    };
    let units = spec
        .action_names
        .iter()
        .enumerate()
        .map(|(k, _)| {
            let (wrist_pos, wrist_rot, rest) = match &action_mapping {
                ActionMapping::Direct { finger_mode: FingerMode::Absolute, .. } => ("m per step (× wrist_pos_scale)", "rad per step (× wrist_rot_scale)", "joint range: −1 lower, +1 upper"),
                ActionMapping::Direct { .. } => ("m per step (× wrist_pos_scale)", "rad per step (× wrist_rot_scale)", "rad per step (× finger_delta_scale)"),
                ActionMapping::ResidualJoint { .. } => ("m from the reference (× wrist_pos_alpha)", "rad from the reference (× wrist_rot_alpha)", "rad from the reference (× joint_alpha)"),
                ActionMapping::ResidualTask { .. } => ("m/s of the residual's rate (× scale_wrist_pos)", "rad/s (× scale_wrist_rot)", "m/s of the fingertip residual, wrist frame (× scale_tips)"),
            };
            match k {
                0..3 => wrist_pos,
                3..6 => wrist_rot,
                _ => rest,
            }
            .to_string()
        })
        .collect();
    let actions = Actions { size: spec.action_dim, names: spec.action_names.clone(), units, clip: [-1.0, 1.0] };
    Ok(PolicyContract {
        format: CONTRACT_FORMAT.into(),
        dextrain_version: env!("CARGO_PKG_VERSION").into(),
        source: src.source,
        model: model_file,
        control,
        hand: HandContract {
            urdf_name: hand.name.clone(),
            urdf_file: urdf_path.file_name().map(|f| f.to_string_lossy().into_owned()).unwrap_or_default(),
            urdf_xxh64: hex(crate::learn::checkpoint::xxh64(&urdf, 0)),
            joints,
            actuated,
            fingertips,
            init_wrist_pos: [g.init_wrist_pos[0], g.init_wrist_pos[1], g.init_wrist_pos[2]],
            init_wrist_rot: g.init_wrist_rot,
            palm_offset: [tc.palm_offset[0], tc.palm_offset[1], tc.palm_offset[2]],
        },
        task: TaskContract { kind: spec.kind, reference },
        observation,
        privileged,
        history,
        actions,
        action_mapping,
    })
}

/// The mapping of lift (and track with free actions).
fn direct(tc: &TaskGlobals, start: StartTargets) -> ActionMapping {
    let finger_mode = if tc.finger_mode == 0 { FingerMode::Absolute } else { FingerMode::Delta };
    ActionMapping::Direct {
        wrist_pos_scale: tc.wrist_pos_scale,
        wrist_pos_min: [tc.wrist_pos_min[0], tc.wrist_pos_min[1], tc.wrist_pos_min[2]],
        wrist_pos_max: [tc.wrist_pos_max[0], tc.wrist_pos_max[1], tc.wrist_pos_max[2]],
        wrist_rot_scale: tc.wrist_rot_scale,
        wrist_rot_limit: tc.wrist_rot_limit,
        finger_mode,
        start,
        finger_delta_scale: tc.finger_delta_scale,
        formulas: vec![
            "a = clip(actions, -1, 1); at episode start the targets are `start`: initial = the initial wrist pose (hand.init_wrist_pos/rot) and each joint's default, reference_first_frame = the reference's first frame (wrist pose and joints)".into(),
            "wrist position target p* = clamp(p*_prev + wrist_pos_scale · a[0..3], wrist_pos_min, wrist_pos_max) (component-wise)".into(),
            "wrist orientation target R* = exp(wrist_rot_scale · a[3..6]) ⊗ R*_prev (world-frame rotation vector), then, if its angle from the initial orientation R0 exceeds wrist_rot_limit, R* = exp(e · wrist_rot_limit / |e|) ⊗ R0 with e the rotation vector of R* ⊗ R0⁻¹".into(),
            "finger_mode absolute: q*_j = lower_j + (a[6 + j] + 1) / 2 · (upper_j − lower_j) (continuous joints: default_j + π · a[6 + j])".into(),
            "finger_mode delta: q*_j = clamp(q*_j,prev + finger_delta_scale · a[6 + j], lower_j, upper_j)".into(),
            "mimic followers take no target: q = multiplier · q_leader + offset".into(),
        ],
    }
}

impl PolicyContract {
    /// Reads and checks a `policy.json`: one-line errors naming the file and the field.
    pub fn read(path: &std::path::Path) -> Result<PolicyContract> {
        let text = std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
        let de = &mut serde_json::Deserializer::from_str(&text);
        let c: PolicyContract = serde_path_to_error::deserialize(de)
            .map_err(|e| anyhow::anyhow!("{}: field `{}`: {}", path.display(), e.path(), crate::text::one_line(&e.inner().to_string())))?;
        c.check().with_context(|| format!("{}", path.display()))?;
        Ok(c)
    }

    /// Internal consistency: the format, layouts that cover their inputs exactly, action names.
    pub fn check(&self) -> Result<()> {
        ensure!(self.format == CONTRACT_FORMAT, "field `format`: {:?}, expected {CONTRACT_FORMAT:?}", self.format);
        let mut layouts: Vec<(&str, &Layout)> = vec![("observation", &self.observation)];
        if let Some(p) = &self.privileged {
            layouts.push(("privileged", p));
        }
        if let Some(h) = &self.history {
            ensure!(h.length > 0, "field `history.length`: 0, expected at least 1");
            layouts.push(("history.step", &h.step));
        }
        for (what, l) in layouts {
            let mut at = 0;
            for f in &l.fields {
                ensure!(f.offset == at && f.entries.len() == f.size, "field `{what}.fields` ({:?}): offset {} size {} with {} entries, expected offset {at} and one entry per number", f.name, f.offset, f.size, f.entries.len());
                at += f.size;
            }
            ensure!(at == l.size, "field `{what}.size`: {}, but its fields hold {at} numbers", l.size);
        }
        ensure!(self.actions.names.len() == self.actions.size, "field `actions.names`: {} names for {} actions", self.actions.names.len(), self.actions.size);
        ensure!(self.actions.units.len() == self.actions.size, "field `actions.units`: {} units for {} actions", self.actions.units.len(), self.actions.size);
        // 6 wrist actions, then one per actuated joint, or (residual_task) 3 per fingertip
        let expected = match self.action_mapping {
            ActionMapping::ResidualTask { .. } => 6 + 3 * self.hand.fingertips.len(),
            _ => 6 + self.hand.actuated.len(),
        };
        ensure!(expected == self.actions.size, "field `actions.size`: {} actions, expected {expected} for this mapping and hand", self.actions.size);
        let names: BTreeMap<&str, ()> = self.hand.joints.iter().map(|j| (j.name.as_str(), ())).collect();
        for a in &self.hand.actuated {
            ensure!(names.contains_key(a.as_str()), "field `hand.actuated`: {a:?} is not one of `hand.joints`");
        }
        Ok(())
    }
}
