//! Run configuration: serde structs that mirror the TOML file (unknown keys are errors), defaults,
//! and validation with one-line errors that name the file, the key, the value and what is allowed.
//!
//! Paths inside a config (the hand's URDF) are relative to the directory of the config file.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use serde::{Deserialize, Serialize};

use crate::geom::ObjectShape;
use crate::hand::MeshApprox;

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
    /// PPO hyper-parameters (DESIGN §6 defaults, rsl_rl conventions).
    pub ppo: PpoConfig,
    /// Actor and critic networks.
    pub policy: PolicyConfig,
    /// Directory of the config file (paths in the config are relative to it); not part of the TOML.
    #[serde(skip)]
    pub base_dir: PathBuf,
    /// The file the config came from (for error messages); not part of the TOML.
    #[serde(skip)]
    pub source: PathBuf,
}

/// `[sim]`
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SimConfig {
    /// `"auto"` (a hardware GPU adapter if there is one, else the CPU), `"cpu"`, `"gpu"` (a hardware
    /// GPU adapter; an error if there is none) or `"gpu:NAME"` (the wgpu adapter whose name contains
    /// NAME, e.g. `"gpu:llvmpipe"` for Mesa's software Vulkan driver).
    pub backend: String,
    /// Number of parallel environments.
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

/// `[hand]`
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct HandConfig {
    /// URDF of the hand, relative to the config file's directory.
    pub urdf: String,
    /// Fingertip frame names; empty = every link whose name ends in "tip".
    pub fingertips: Vec<String>,
    /// What to do with mesh collision geometry: "error", "box" or "capsule" (bounding-box approximations).
    pub mesh_approx: MeshApprox,
    /// Position gain of every finger joint servo (N·m/rad).
    pub kp: f32,
    /// Velocity gain of every finger joint servo (N·m·s/rad).
    pub kd: f32,
    /// Rotor inertia added to every finger joint (kg·m²).
    pub armature: f32,
    /// Per-joint overrides of `kp` (joint name -> N·m/rad).
    pub joint_kp: BTreeMap<String, f32>,
    /// Per-joint overrides of `kd` (joint name -> N·m·s/rad).
    pub joint_kd: BTreeMap<String, f32>,
    /// Coulomb friction coefficient of the hand's links.
    pub friction: f32,
    /// Initial joint positions (joint name -> rad); joints not named start at 0 clamped into their limits.
    pub init_joints: BTreeMap<String, f32>,
}

/// `[wrist]`
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct WristConfig {
    /// Initial wrist position (m, world).
    pub init_pos: [f32; 3],
    /// Initial wrist orientation as roll, pitch, yaw (rad; R = Rz(yaw)·Ry(pitch)·Rx(roll)).
    pub init_rpy: [f32; 3],
    /// Translational stiffness of the wrist PD (N/m).
    pub kp_lin: f32,
    /// Translational damping of the wrist PD (N·s/m).
    pub kd_lin: f32,
    /// Force limit of the wrist PD (N).
    pub force_limit: f32,
    /// Rotational stiffness of the wrist PD (N·m/rad).
    pub kp_rot: f32,
    /// Rotational damping of the wrist PD (N·m·s/rad).
    pub kd_rot: f32,
    /// Torque limit of the wrist PD (N·m).
    pub torque_limit: f32,
    /// Mass added to the hand's own for the wrist's translation (kg): the arm's reflected mass.
    pub added_mass: f32,
    /// Inertia added to the hand's own for the wrist's rotation (kg·m²): the arm's reflected inertia.
    pub added_inertia: f32,
}

/// `[object]`
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ObjectConfig {
    /// Shape and size: `{ type = "box", half_extents = [..] }`, `{ type = "sphere", radius = .. }`,
    /// `{ type = "capsule", radius = .., half_length = .. }` or `{ type = "cylinder", radius = .., half_length = .. }`.
    pub shape: ObjectShape,
    /// Mass (kg).
    pub mass: f32,
    /// Coulomb friction coefficient (combined with the other body's by averaging).
    pub friction: f32,
    /// Coefficient of restitution of the object's contacts, in [0, 1).
    pub restitution: f32,
    /// Initial x, y (m) of the object's centre; it starts resting on the table.
    pub init_xy: [f32; 2],
    /// Initial rotation about z (rad).
    pub init_yaw: f32,
    /// Half widths (m) of the uniform noise added to the initial x and y at each reset.
    pub xy_noise: [f32; 2],
    /// Half width (rad) of the uniform noise added to the initial yaw at each reset.
    pub yaw_noise: f32,
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
    /// Normal penalty stiffness (N/m per contact).
    pub stiffness: f32,
    /// Stiffness of the tangential spring that holds a sticking contact (N/m).
    pub friction_stiffness: f32,
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

/// The reward terms of the lift task, in the order of `StepBatch::terms` (DESIGN §5).
pub const LIFT_TERMS: [&str; 6] = ["reaching", "lifting", "contact", "success", "action_rate", "action_magnitude"];
/// Reward terms of the trajectory-following task (`kind = "track"`, DESIGN §5), in output order.
pub const TRACK_TERMS: [&str; 7] = ["hand_following", "object_following", "contact", "success", "lifting", "action_rate", "action_magnitude"];
/// Reward terms of the joint-space residual task (`kind = "residual_joint"`, Real2Sim), in output order.
pub const RESIDUAL_JOINT_TERMS: [&str; 4] = ["object_pos", "object_rot", "residual", "success"];
/// Reward terms of the task-space residual task (`kind = "residual_task"`, DexRefine), in output order.
pub const RESIDUAL_TASK_TERMS: [&str; 8] = ["object", "fingertips", "wrist", "contact", "velocity", "torque", "work", "table_collision"];
/// The task kinds.
pub const TASK_KINDS: [&str; 4] = ["lift", "track", "residual_joint", "residual_task"];

/// The reward terms of a task kind (empty for an unknown kind).
pub fn task_terms(kind: &str) -> &'static [&'static str] {
    match kind {
        "lift" => &LIFT_TERMS,
        "track" => &TRACK_TERMS,
        "residual_joint" => &RESIDUAL_JOINT_TERMS,
        "residual_task" => &RESIDUAL_TASK_TERMS,
        _ => &[],
    }
}

/// The default weights of a task kind's reward terms: lift as tuned for the shipped configs;
/// track with the papers' λ1 = λ2 = λ3 = 1, λ4 = 15 (no lifting, no action penalties);
/// residual_joint `w_p = 1, w_r = 1, λ_a = 1` (the residual term is ‖δ‖², so its weight is −λ_a);
/// residual_task with DexRefine's w_obj 30, w_hand 10, w_wrist 5, w_contact 0.05 and small
/// penalties.
pub fn default_rewards(kind: &str) -> BTreeMap<String, f32> {
    let w: &[(&str, f32)] = match kind {
        "lift" => &[("reaching", 1.0), ("lifting", 0.5), ("contact", 0.5), ("success", 5.0), ("action_rate", -0.01), ("action_magnitude", -0.001)],
        "track" => &[("hand_following", 1.0), ("object_following", 1.0), ("contact", 1.0), ("success", 15.0), ("lifting", 0.0), ("action_rate", 0.0), ("action_magnitude", 0.0)],
        "residual_joint" => &[("object_pos", 1.0), ("object_rot", 1.0), ("residual", -1.0), ("success", 0.0)],
        "residual_task" => &[
            ("object", 30.0),
            ("fingertips", 10.0),
            ("wrist", 5.0),
            ("contact", 0.05),
            ("velocity", -1e-3),
            ("torque", -1e-2),
            ("work", -1e-2),
            ("table_collision", -1.0),
        ],
        _ => &[],
    };
    w.iter().map(|(k, v)| (k.to_string(), *v)).collect()
}

/// `[task]`
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TaskConfig {
    /// The task: `"lift"` (grasp the object and lift it at least `lift.success_height`), `"track"`
    /// (follow reference trajectories: DESIGN §5), `"residual_joint"` (a bounded joint-space
    /// correction of the reference's joint targets) or `"residual_task"` (a smoothed, integrated
    /// task-space correction of the reference's wrist pose and fingertips, mapped to joints by IK).
    pub kind: String,
    /// Episode length in env steps; reaching it is a time-out (returns bootstrap through it).
    /// 0 (reference kinds only): until the env's reference (time-scaled) has ended.
    pub episode_length: u32,
    /// How the policy's actions become joint and wrist targets.
    pub action: ActionConfig,
    /// Standard deviations of the Gaussian noise added to the actor's observations (the critic's are clean).
    pub obs_noise: ObsNoiseConfig,
    /// Weight of each reward term (term name -> weight; 0 turns a term off, an unknown name is an
    /// error). Lift terms: reaching `1 − tanh(α‖p_palm − p_obj‖)`, lifting `h` in cm (capped at the
    /// success height), contact (1 when the thumb and another fingertip touch the object), success (1
    /// while lifted ≥ success height), action_rate `‖a_t − a_{t−1}‖²`, action_magnitude `‖a_t‖²`.
    /// Penalties have negative weights (Isaac Lab's convention).
    pub rewards: BTreeMap<String, f32>,
    /// Parameters of the lift task; `thumb`, `contact_force`, `palm_offset`, `drop_height`,
    /// `table_half_extent` and `max_hand_distance` apply to every kind.
    pub lift: LiftConfig,
    /// The references of the reference-following kinds (track, residual_joint, residual_task) and
    /// their augmentation.
    pub reference: crate::env::reference::ReferenceConfig,
    /// Observations, rewards and success of the reference-following kinds.
    pub track: TrackConfig,
    /// Parameters of the residual kinds.
    pub residual: ResidualConfig,
    /// The open-loop baseline of the reference kinds: actions are ignored and the targets follow the
    /// (augmented) reference, as `dextrain replay` drives them (`dextrain eval --baseline open-loop`
    /// sets it).
    pub open_loop: bool,
}

/// `[task.track]`: observations, tracking rewards and success of `track`, `residual_joint` and
/// `residual_task` (DESIGN §5); the references themselves are `[task.reference]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TrackConfig {
    /// Where an episode starts: `"reference"` (hand and object at the reference's first frame, as
    /// `dextrain replay` starts) or `"config"` (hand at `wrist.init_*` and default joints, object
    /// where the simulator's reset puts it; pair with `task.reference.reground`/`reinterp`).
    pub start: String,
    /// How `track`'s actions become targets. `"reference"`: the reference's targets of this step
    /// plus a bounded offset, mapped as `residual_joint` maps its residual with `[task.residual]`'s
    /// `alpha`, `wrist_pos_alpha` and `wrist_rot_alpha` (PD targets around the reference, as
    /// DeepMimic-style trackers act); `"free"`: lift's `[task.action]` mapping (wrist moves and
    /// finger targets the policy integrates itself, with no reference in the action).
    pub action: String,
    /// Look-ahead reference frames observed after the current one.
    pub lookahead: u32,
    /// Env steps between observed look-ahead frames.
    pub lookahead_stride: u32,
    /// β1 of `R_f = β1 R_j + β2 R_ee,x + β3 R_ee,r`: the weight of joint tracking.
    pub beta_joint: f32,
    /// β2: the weight of wrist position tracking.
    pub beta_wrist_pos: f32,
    /// β3: the weight of wrist rotation tracking.
    pub beta_wrist_rot: f32,
    /// α1 of `R_j = 1 − tanh(α1‖q − q̂‖)` (1/rad, over the actuated joints).
    pub alpha_joint: f32,
    /// α2 of `R_ee,x = 1 − tanh(α2‖x − x̂‖)` (1/m, the wrist position).
    pub alpha_wrist_pos: f32,
    /// α3 of `R_ee,r = 1 − tanh(α3 φ)` (1/rad, φ the wrist's angle from its reference).
    pub alpha_wrist_rot: f32,
    /// α4 of `exp(−α4‖T − T̂‖)` in `R_o` (1/m, the object position).
    pub alpha_object_pos: f32,
    /// α5 of `exp(−α5‖log(q̂⁻¹ ⊗ q)‖)` in `R_o` (1/rad, the object orientation).
    pub alpha_object_rot: f32,
    /// Success: the object ends within this distance (m) of the reference's final object position …
    pub success_pos_tol: f32,
    /// … and this angle (rad) of its final orientation (and so lifted where the reference lifts).
    pub success_rot_tol: f32,
    /// Terminate a training episode when the object is farther than this (m) from its reference
    /// (0 = never). `dextrain eval` ignores it: its episodes run to the reference's end.
    pub max_object_error: f32,
}

/// `[task.residual]`: how residual actions correct the reference (DESIGN §1, §5).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ResidualConfig {
    /// residual_joint: `q* = clip(q̄ + α·a, lower, upper)` for the finger joints (rad at |a| = 1).
    pub alpha: f32,
    /// residual_joint: wrist position residual at |a| = 1 (m): `p* = p̄ + wrist_pos_alpha·a`.
    pub wrist_pos_alpha: f32,
    /// residual_joint: wrist rotation residual at |a| = 1 (rad): `R* = exp(wrist_rot_alpha·a) ⊗ R̄`.
    pub wrist_rot_alpha: f32,
    /// residual_joint reward `r_obj-p = exp(−obj_pos_coef·e_p)` (1/m).
    pub obj_pos_coef: f32,
    /// residual_joint reward `r_obj-r = exp(−obj_rot_coef·e_R)` (1/rad).
    pub obj_rot_coef: f32,
    /// residual_task: EMA weight of the new output, `ũ_t = ema·u_t + (1 − ema)·ũ_{t−1}`.
    pub ema: f32,
    /// residual_task: integration scale s of `Δa_t = Δa_{t−1} + s ⊙ ũ_t Δt` for the wrist
    /// translation (m/s at |ũ| = 1).
    pub scale_wrist_pos: f32,
    /// … for the wrist rotation (rad/s).
    pub scale_wrist_rot: f32,
    /// … for the fingertips (m/s, wrist frame).
    pub scale_tips: f32,
    /// residual_task: clamp of each wrist-translation component of Δa (m).
    pub clamp_wrist_pos: f32,
    /// … of each wrist-rotation component (rad).
    pub clamp_wrist_rot: f32,
    /// … of each fingertip component (m).
    pub clamp_tips: f32,
    /// residual_task reward: a_pos of the object term `exp(−a_pos e_p − a_rot e_R)` (1/m).
    pub reward_obj_pos: f32,
    /// … its a_rot (1/rad).
    pub reward_obj_rot: f32,
    /// a of the fingertip term `exp(−a e_tips)` (1/m; e_tips the mean fingertip distance).
    pub reward_tips: f32,
    /// a_pos of the wrist term `exp(−a_pos e_p − a_rot e_R)` (1/m).
    pub reward_wrist_pos: f32,
    /// … its a_rot (1/rad).
    pub reward_wrist_rot: f32,
}

impl Default for TrackConfig {
    fn default() -> Self {
        TrackConfig {
            start: "reference".into(),
            action: "reference".into(),
            lookahead: 2,
            lookahead_stride: 3,
            beta_joint: 0.1,
            beta_wrist_pos: 1.0,
            beta_wrist_rot: 1.0,
            alpha_joint: 1.0,
            alpha_wrist_pos: 1.0,
            alpha_wrist_rot: 1.0,
            alpha_object_pos: 1.0,
            alpha_object_rot: 1.0,
            success_pos_tol: 0.03,
            success_rot_tol: 0.35,
            max_object_error: 0.0,
        }
    }
}

impl Default for ResidualConfig {
    fn default() -> Self {
        ResidualConfig {
            alpha: 0.1,
            wrist_pos_alpha: 0.05,
            wrist_rot_alpha: 0.1,
            obj_pos_coef: 10.0,
            obj_rot_coef: 1.0,
            ema: 0.8,
            scale_wrist_pos: 0.05,
            scale_wrist_rot: 0.2,
            scale_tips: 0.05,
            clamp_wrist_pos: 0.1,
            clamp_wrist_rot: 40f32.to_radians(),
            clamp_tips: 0.04,
            reward_obj_pos: 10.0,
            reward_obj_rot: 20.0,
            reward_tips: 10.0,
            reward_wrist_pos: 5.0,
            reward_wrist_rot: 5.0,
        }
    }
}

/// `[task.action]`: the action is `6 + actuated joints` numbers in [−1, 1] (clipped): wrist
/// translation (3, world frame), wrist rotation (3, a rotation vector in the world frame), then one
/// per actuated finger joint in URDF order.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ActionConfig {
    /// Finger joints: `"absolute"` maps a ∈ [−1, 1] linearly onto [lower, upper] of each joint;
    /// `"delta"` moves the previous target by `a · finger_delta_scale`, clipped to the limits.
    pub finger_mode: String,
    /// Finger target change per env step at |a| = 1 (rad), for `finger_mode = "delta"`.
    pub finger_delta_scale: f32,
    /// Wrist target translation per env step at |a| = 1 (m).
    pub wrist_pos_scale: f32,
    /// Wrist target rotation per env step at |a| = 1 (rad).
    pub wrist_rot_scale: f32,
    /// Lower corner of the box (m, world) the wrist position target is clipped to.
    pub wrist_pos_min: [f32; 3],
    /// Upper corner of that box (m, world).
    pub wrist_pos_max: [f32; 3],
    /// Largest angle (rad) between the wrist orientation target and the initial wrist orientation.
    pub wrist_rot_limit: f32,
}

/// `[task.obs_noise]`: noise standard deviations (0 = none).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ObsNoiseConfig {
    /// Joint positions (rad).
    pub joint_pos: f32,
    /// Joint velocities (rad/s).
    pub joint_vel: f32,
    /// Wrist and fingertip positions (m).
    pub hand_pos: f32,
    /// Object position (m).
    pub object_pos: f32,
    /// Object orientation (each quaternion component, renormalised).
    pub object_rot: f32,
}

/// `[task.lift]`
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LiftConfig {
    /// α of the reaching term `1 − tanh(α‖p_palm − p_obj‖)` (1/m).
    pub reach_alpha: f32,
    /// Lift height (m) of the object's centre above its rest height that counts as success.
    pub success_height: f32,
    /// Fingertip normal force (N) above which a fingertip touches the object.
    pub contact_force: f32,
    /// The thumb's fingertip frame (one of `hand.fingertips`); "" = the first whose name starts with "th".
    pub thumb: String,
    /// The palm point (m) in the wrist frame that the reaching term brings to the object.
    pub palm_offset: [f32; 3],
    /// The episode terminates when the object's centre falls below this height (m; off the table).
    pub drop_height: f32,
    /// ... or leaves the square |x|, |y| ≤ this (m) on the table.
    pub table_half_extent: f32,
    /// ... or the palm point gets farther than this from the object (m).
    pub max_hand_distance: f32,
}

/// `[train]`
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TrainConfig {
    /// Learner device, chosen like `sim.backend`: `"auto"`, `"cpu"` (burn's flex backend), `"gpu"` or
    /// `"gpu:NAME"` (burn's wgpu backend; on the simulator's own device when the simulator is on the GPU).
    pub device: String,
    /// PPO iterations (each: `steps_per_env` env steps of every env, then one update).
    pub iterations: u32,
    /// Env steps per env per iteration (rollout length).
    pub steps_per_env: u32,
    /// Write a checkpoint every this many iterations (and always after the last one).
    pub save_interval: u32,
    /// Keep only the newest this many checkpoints (0 = keep all).
    pub keep_checkpoints: u32,
    /// Redraw the learning-curve PNGs every this many iterations (0 = only at the end).
    pub plot_interval: u32,
    /// Start each env's first episode at a random step count in [0, episode_length), so that the
    /// envs' episodes do not all end in the same iteration (rsl_rl's `init_at_random_ep_len`).
    /// The lift task only: a reference kind's episodes start at their reference's first frame
    /// (`task.reference.time_scale` spreads their ends).
    pub init_at_random_ep_len: bool,
}

/// `[ppo]` (DESIGN §6; rsl_rl's names and defaults)
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PpoConfig {
    /// Initial learning rate of Adam.
    pub learning_rate: f32,
    /// `"adaptive"` (from the KL: ÷1.5 above 2× `desired_kl`, ×1.5 below ½×) or `"fixed"`.
    pub schedule: String,
    /// Target KL divergence between the old and the new policy per update.
    pub desired_kl: f32,
    /// Lower bound of the adaptive learning rate.
    pub min_learning_rate: f32,
    /// Upper bound of the adaptive learning rate.
    pub max_learning_rate: f32,
    /// Discount γ.
    pub gamma: f32,
    /// GAE λ.
    pub lam: f32,
    /// Clip range ε of the surrogate (and of the value loss).
    pub clip_param: f32,
    /// Weight of the value loss.
    pub value_loss_coef: f32,
    /// Clip the value loss around the old values (rsl_rl's `use_clipped_value_loss`).
    pub clipped_value_loss: bool,
    /// Weight of the entropy bonus.
    pub entropy_coef: f32,
    /// Passes over the rollout per update.
    pub epochs: u32,
    /// Minibatches per pass.
    pub minibatches: u32,
    /// Clip of the global gradient norm (actor and critic together).
    pub max_grad_norm: f32,
    /// Factor on the rewards before the value targets and advantages (rl_games' `scale_value`);
    /// logged rewards and returns are unscaled. The clipped value loss moves each value by at most
    /// `clip_param` per update, so with large per-step rewards (DexRefine's weights sum to ~45 per
    /// step, returns of thousands) the critic needs many updates to follow; 0.01–0.1 brings the
    /// returns back to O(10–100).
    pub reward_scale: f32,
}

/// `[policy]`
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PolicyConfig {
    /// Hidden layer widths of the actor MLP.
    pub actor_hidden: Vec<usize>,
    /// Hidden layer widths of the critic MLP.
    pub critic_hidden: Vec<usize>,
    /// Hidden activation: `"elu"`, `"relu"` or `"tanh"`.
    pub activation: String,
    /// Initial standard deviation of the Gaussian policy (its log is learned, one per action).
    pub init_std: f32,
    /// Normalise observations with running mean and variance (saved with the model).
    pub obs_normalization: bool,
    /// Start the actor's output layer at zero, so that the initial policy mean is 0: a residual
    /// policy then starts as the reference it corrects (residual RL's usual initialisation).
    pub zero_init_output: bool,
}

impl Default for TaskConfig {
    fn default() -> Self {
        TaskConfig {
            kind: "lift".into(),
            episode_length: 90,
            action: ActionConfig::default(),
            obs_noise: ObsNoiseConfig::default(),
            rewards: default_rewards("lift"),
            lift: LiftConfig::default(),
            reference: Default::default(),
            track: TrackConfig::default(),
            residual: ResidualConfig::default(),
            open_loop: false,
        }
    }
}

impl Default for ActionConfig {
    fn default() -> Self {
        ActionConfig {
            finger_mode: "absolute".into(),
            finger_delta_scale: 0.1,
            wrist_pos_scale: 0.01,
            wrist_rot_scale: 0.05,
            wrist_pos_min: [-0.2, -0.2, 0.03],
            wrist_pos_max: [0.2, 0.2, 0.4],
            wrist_rot_limit: 0.8,
        }
    }
}

impl Default for ObsNoiseConfig {
    fn default() -> Self {
        ObsNoiseConfig { joint_pos: 0.0, joint_vel: 0.0, hand_pos: 0.0, object_pos: 0.0, object_rot: 0.0 }
    }
}

impl Default for LiftConfig {
    fn default() -> Self {
        LiftConfig {
            reach_alpha: 10.0,
            success_height: 0.10,
            contact_force: 0.05,
            thumb: String::new(),
            palm_offset: [0.0, 0.0, -0.04],
            drop_height: -0.05,
            table_half_extent: 0.5,
            max_hand_distance: 0.5,
        }
    }
}

impl Default for TrainConfig {
    fn default() -> Self {
        TrainConfig {
            device: "cpu".into(),
            iterations: 100,
            steps_per_env: 32,
            save_interval: 50,
            keep_checkpoints: 0,
            plot_interval: 50,
            init_at_random_ep_len: true,
        }
    }
}

impl Default for PpoConfig {
    fn default() -> Self {
        PpoConfig {
            learning_rate: 5e-4,
            schedule: "adaptive".into(),
            desired_kl: 0.01,
            min_learning_rate: 1e-5,
            max_learning_rate: 1e-2,
            gamma: 0.99,
            lam: 0.95,
            clip_param: 0.2,
            value_loss_coef: 1.0,
            clipped_value_loss: true,
            entropy_coef: 0.005,
            epochs: 5,
            minibatches: 4,
            max_grad_norm: 1.0,
            reward_scale: 1.0,
        }
    }
}

impl Default for PolicyConfig {
    fn default() -> Self {
        PolicyConfig { actor_hidden: vec![256, 128, 64], critic_hidden: vec![256, 128, 64], activation: "elu".into(), init_std: 1.0, obs_normalization: true, zero_init_output: false }
    }
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
            base_dir: PathBuf::from("."),
            source: PathBuf::from("<default>"),
        }
    }
}

impl Default for SimConfig {
    fn default() -> Self {
        SimConfig {
            backend: "auto".into(),
            num_envs: 64,
            dt: 1.0 / 120.0,
            substeps: 4,
            decimation: 4,
            max_speed: 50.0,
            max_distance: 10.0,
        }
    }
}

impl Default for HandConfig {
    fn default() -> Self {
        HandConfig {
            urdf: "hands/dexhand16.urdf".into(),
            fingertips: Vec::new(),
            mesh_approx: MeshApprox::Error,
            kp: 3.0,
            kd: 0.1,
            armature: 0.002,
            joint_kp: BTreeMap::new(),
            joint_kd: BTreeMap::new(),
            friction: 1.0,
            init_joints: BTreeMap::new(),
        }
    }
}

impl Default for WristConfig {
    fn default() -> Self {
        WristConfig {
            init_pos: [0.0, 0.0, 0.15],
            init_rpy: [0.0, 0.0, 0.0],
            kp_lin: 2000.0,
            kd_lin: 100.0,
            force_limit: 100.0,
            kp_rot: 50.0,
            kd_rot: 2.0,
            torque_limit: 20.0,
            added_mass: 0.5,
            added_inertia: 0.01,
        }
    }
}

impl Default for ObjectConfig {
    fn default() -> Self {
        ObjectConfig {
            shape: ObjectShape::Box { half_extents: [0.025, 0.025, 0.025] },
            mass: 0.1,
            friction: 1.0,
            restitution: 0.0,
            init_xy: [0.0, 0.0],
            init_yaw: 0.0,
            xy_noise: [0.0, 0.0],
            yaw_noise: 0.0,
        }
    }
}

impl Default for TableConfig {
    fn default() -> Self {
        TableConfig { friction: 1.0, hand_collision: true }
    }
}

impl Default for ContactConfig {
    fn default() -> Self {
        ContactConfig { stiffness: 1.0e4, friction_stiffness: 1.0e4, hand_effective_mass: 0.1, torsion_radius: 0.005 }
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

/// Which simulation backend a config asks for.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum BackendChoice {
    Auto,
    Cpu,
    /// A GPU adapter; `None` = any hardware adapter, `Some(name)` = the adapter whose name contains it.
    Gpu(Option<String>),
}

impl BackendChoice {
    pub fn parse(s: &str) -> Option<BackendChoice> {
        match s {
            "auto" => Some(BackendChoice::Auto),
            "cpu" => Some(BackendChoice::Cpu),
            "gpu" => Some(BackendChoice::Gpu(None)),
            _ => s.strip_prefix("gpu:").filter(|n| !n.is_empty()).map(|n| BackendChoice::Gpu(Some(n.to_string()))),
        }
    }
}

impl Config {
    /// Reads, parses and validates a config file.
    pub fn load(path: &Path) -> Result<Config> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("cannot read config file {}", path.display()))?;
        Config::from_toml_str(&text, path)
    }

    /// Reads a config file and applies `--set key=value` overrides before validation. `key` is a
    /// dotted path (`ppo.learning_rate`, `task.rewards.lifting`); `value` is a TOML value
    /// (`3`, `1e-3`, `true`, `[1, 2]`, `"cpu"`); a bare word that is not TOML is taken as a string.
    pub fn load_with_overrides(path: &Path, sets: &[String]) -> Result<Config> {
        if sets.is_empty() {
            return Config::load(path);
        }
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("cannot read config file {}", path.display()))?;
        let mut table: toml::Table = match text.parse::<toml::Table>() {
            Ok(t) => t,
            Err(e) => {
                let at = e.span().map(|s| line_col(&text, s.start)).unwrap_or_default();
                bail!("{}{at}: invalid TOML: {}", path.display(), one_line(e.message()));
            }
        };
        for set in sets {
            apply_override(&mut table, set)?;
        }
        let merged = toml::to_string(&table).context("cannot serialise the overridden config")?;
        Config::from_toml_str(&merged, path)
    }

    /// Parses and validates config text; `path` is used for error messages and relative paths.
    pub fn from_toml_str(text: &str, path: &Path) -> Result<Config> {
        let file = path.display();
        let value: toml::Value = match text.parse::<toml::Table>() {
            Ok(t) => toml::Value::Table(t),
            Err(e) => {
                let at = e.span().map(|s| line_col(text, s.start)).unwrap_or_default();
                bail!("{file}{at}: invalid TOML: {}", one_line(e.message()));
            }
        };
        // without a [task.rewards] table, the kind's default weights
        let has_rewards = value.get("task").and_then(|t| t.get("rewards")).is_some();
        let mut cfg: Config = serde_path_to_error::deserialize(value).map_err(|e| {
            let key = e.path().to_string();
            anyhow::anyhow!("{file}: key `{key}`: {}", one_line(&e.into_inner().to_string()))
        })?;
        if !has_rewards {
            cfg.task.rewards = default_rewards(&cfg.task.kind);
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
        // validate() has checked that the string parses.
        BackendChoice::parse(&self.sim.backend).unwrap_or(BackendChoice::Auto)
    }

    /// Checks every value; the first problem is returned as a one-line error.
    pub fn validate(&self) -> Result<()> {
        let file = self.source.display().to_string();
        let err = |key: &str, value: String, allowed: &str| -> anyhow::Error {
            anyhow::anyhow!("{file}: key `{key}` = {value}: expected {allowed}")
        };
        let s = &self.sim;
        if BackendChoice::parse(&s.backend).is_none() {
            return Err(err("sim.backend", format!("{:?}", s.backend), "one of \"auto\", \"cpu\", \"gpu\", \"gpu:ADAPTER_NAME\""));
        }
        if s.num_envs == 0 || s.num_envs > 16_777_216 {
            return Err(err("sim.num_envs", s.num_envs.to_string(), "an integer in [1, 16777216]"));
        }
        pos_in(&err, "sim.dt", s.dt, 1e-5, 0.1, "a time step in seconds in [1e-5, 0.1]")?;
        if !(1..=64).contains(&s.substeps) {
            return Err(err("sim.substeps", s.substeps.to_string(), "an integer in [1, 64]"));
        }
        if !(1..=1000).contains(&s.decimation) {
            return Err(err("sim.decimation", s.decimation.to_string(), "an integer in [1, 1000]"));
        }
        pos_in(&err, "sim.max_speed", s.max_speed, 1e-3, 1e6, "a speed in m/s in (0, 1e6]")?;
        pos_in(&err, "sim.max_distance", s.max_distance, 1e-3, 1e6, "a distance in m in (0, 1e6]")?;

        let h = &self.hand;
        if h.urdf.trim().is_empty() {
            return Err(err("hand.urdf", "\"\"".into(), "the path of a URDF file"));
        }
        non_neg(&err, "hand.kp", h.kp)?;
        non_neg(&err, "hand.kd", h.kd)?;
        pos_in(&err, "hand.armature", h.armature, 1e-7, 10.0, "a rotor inertia in kg·m² in [1e-7, 10] (it keeps the finger joints stable)")?;
        for (k, v) in &h.joint_kp {
            non_neg(&err, &format!("hand.joint_kp.{k}"), *v)?;
        }
        for (k, v) in &h.joint_kd {
            non_neg(&err, &format!("hand.joint_kd.{k}"), *v)?;
        }
        non_neg(&err, "hand.friction", h.friction)?;
        for (k, v) in &h.init_joints {
            finite(&err, &format!("hand.init_joints.{k}"), *v)?;
        }

        let w = &self.wrist;
        for (i, v) in w.init_pos.iter().chain(w.init_rpy.iter()).enumerate() {
            let key = if i < 3 { format!("wrist.init_pos[{i}]") } else { format!("wrist.init_rpy[{}]", i - 3) };
            finite(&err, &key, *v)?;
        }
        for (key, v) in [
            ("wrist.kp_lin", w.kp_lin),
            ("wrist.kd_lin", w.kd_lin),
            ("wrist.force_limit", w.force_limit),
            ("wrist.kp_rot", w.kp_rot),
            ("wrist.kd_rot", w.kd_rot),
            ("wrist.torque_limit", w.torque_limit),
            ("wrist.added_mass", w.added_mass),
            ("wrist.added_inertia", w.added_inertia),
        ] {
            non_neg(&err, key, v)?;
        }

        let o = &self.object;
        match o.shape {
            ObjectShape::Sphere { radius } => pos_in(&err, "object.shape.radius", radius, 1e-4, 10.0, "a radius in m in [1e-4, 10]")?,
            ObjectShape::Box { half_extents } => {
                for (i, v) in half_extents.iter().enumerate() {
                    pos_in(&err, &format!("object.shape.half_extents[{i}]"), *v, 1e-4, 10.0, "a half extent in m in [1e-4, 10]")?;
                }
            }
            ObjectShape::Capsule { radius, half_length } | ObjectShape::Cylinder { radius, half_length } => {
                pos_in(&err, "object.shape.radius", radius, 1e-4, 10.0, "a radius in m in [1e-4, 10]")?;
                if !(half_length.is_finite() && (0.0..=10.0).contains(&half_length)) {
                    return Err(err("object.shape.half_length", half_length.to_string(), "a half length in m in [0, 10]"));
                }
            }
        }
        pos_in(&err, "object.mass", o.mass, 1e-4, 1e3, "a mass in kg in [1e-4, 1000]")?;
        non_neg(&err, "object.friction", o.friction)?;
        unit_interval(&err, "object.restitution", o.restitution)?;
        for (i, v) in o.init_xy.iter().enumerate() {
            finite(&err, &format!("object.init_xy[{i}]"), *v)?;
        }
        finite(&err, "object.init_yaw", o.init_yaw)?;
        for (i, v) in o.xy_noise.iter().enumerate() {
            non_neg(&err, &format!("object.xy_noise[{i}]"), *v)?;
        }
        non_neg(&err, "object.yaw_noise", o.yaw_noise)?;
        non_neg(&err, "table.friction", self.table.friction)?;

        let c = &self.contact;
        pos_in(&err, "contact.stiffness", c.stiffness, 1.0, 1e8, "a stiffness in N/m in [1, 1e8]")?;
        pos_in(&err, "contact.friction_stiffness", c.friction_stiffness, 1.0, 1e8, "a stiffness in N/m in [1, 1e8]")?;
        pos_in(&err, "contact.hand_effective_mass", c.hand_effective_mass, 1e-4, 1e3, "a mass in kg in [1e-4, 1000]")?;
        if !(c.torsion_radius.is_finite() && (0.0..=0.1).contains(&c.torsion_radius)) {
            return Err(err("contact.torsion_radius", c.torsion_radius.to_string(), "a patch radius in m in [0, 0.1]"));
        }

        let r = &self.randomization;
        for (key, range) in [
            ("randomization.hand_mass", r.hand_mass),
            ("randomization.hand_friction", r.hand_friction),
            ("randomization.joint_limits", r.joint_limits),
            ("randomization.joint_stiffness", r.joint_stiffness),
            ("randomization.joint_damping", r.joint_damping),
            ("randomization.object_mass", r.object_mass),
            ("randomization.object_friction", r.object_friction),
            ("randomization.object_scale", r.object_scale),
            ("randomization.table_friction", r.table_friction),
        ] {
            let ok = range.iter().all(|v| v.is_finite() && *v > 0.0 && *v <= 100.0) && range[0] <= range[1];
            if !ok {
                return Err(err(key, format!("{range:?}"), "a scale range [lo, hi] with 0 < lo <= hi <= 100"));
            }
        }
        if let Some(range) = r.object_restitution {
            let ok = range.iter().all(|v| v.is_finite() && (0.0..1.0).contains(v)) && range[0] <= range[1];
            if !ok {
                return Err(err("randomization.object_restitution", format!("{range:?}"), "a range [lo, hi] with 0 <= lo <= hi < 1"));
            }
        }
        let g = r.added_gravity;
        if !(g.iter().all(|v| v.is_finite() && (0.0..=100.0).contains(v)) && g[0] <= g[1]) {
            return Err(err("randomization.added_gravity", format!("{g:?}"), "a range [lo, hi] in m/s² with 0 <= lo <= hi <= 100"));
        }
        self.validate_learning(&err)
    }

    /// Validation of `[task]`, `[train]`, `[ppo]` and `[policy]`.
    fn validate_learning(&self, err: &dyn Fn(&str, String, &str) -> anyhow::Error) -> Result<()> {
        let t = &self.task;
        if !TASK_KINDS.contains(&t.kind.as_str()) {
            return Err(err("task.kind", format!("{:?}", t.kind), "one of \"lift\", \"track\", \"residual_joint\", \"residual_task\""));
        }
        let follows = t.kind != "lift";
        if t.episode_length > 1_000_000 || (t.episode_length == 0 && !follows) {
            return Err(err(
                "task.episode_length",
                t.episode_length.to_string(),
                if follows { "an integer number of env steps in [0, 1000000] (0: until the reference ends)" } else { "an integer number of env steps in [1, 1000000]" },
            ));
        }
        let a = &t.action;
        if a.finger_mode != "absolute" && a.finger_mode != "delta" {
            return Err(err("task.action.finger_mode", format!("{:?}", a.finger_mode), "\"absolute\" or \"delta\""));
        }
        non_neg(err, "task.action.finger_delta_scale", a.finger_delta_scale)?;
        non_neg(err, "task.action.wrist_pos_scale", a.wrist_pos_scale)?;
        non_neg(err, "task.action.wrist_rot_scale", a.wrist_rot_scale)?;
        for i in 0..3 {
            finite(err, &format!("task.action.wrist_pos_min[{i}]"), a.wrist_pos_min[i])?;
            finite(err, &format!("task.action.wrist_pos_max[{i}]"), a.wrist_pos_max[i])?;
            if a.wrist_pos_min[i] > a.wrist_pos_max[i] {
                return Err(err(&format!("task.action.wrist_pos_max[{i}]"), a.wrist_pos_max[i].to_string(), "a value >= task.action.wrist_pos_min of the same axis"));
            }
        }
        pos_in(err, "task.action.wrist_rot_limit", a.wrist_rot_limit, 0.0, std::f32::consts::PI, "an angle in rad in [0, π]")?;
        let n = &t.obs_noise;
        for (key, v) in [
            ("task.obs_noise.joint_pos", n.joint_pos),
            ("task.obs_noise.joint_vel", n.joint_vel),
            ("task.obs_noise.hand_pos", n.hand_pos),
            ("task.obs_noise.object_pos", n.object_pos),
            ("task.obs_noise.object_rot", n.object_rot),
        ] {
            non_neg(err, key, v)?;
        }
        let terms = task_terms(&t.kind);
        for (name, w) in &t.rewards {
            if !terms.contains(&name.as_str()) {
                return Err(err(&format!("task.rewards.{name}"), w.to_string(), &format!("a term of the {} task: {}", t.kind, terms.join(", "))));
            }
            finite(err, &format!("task.rewards.{name}"), *w)?;
        }
        if follows && t.reference.files.is_empty() {
            return Err(err("task.reference.files", "[]".into(), &format!("at least one reference file for task.kind = {:?}", t.kind)));
        }
        t.reference.validate().map_err(|e| anyhow::anyhow!("{}: {e:#}", self.source.display()))?;
        let k = &t.track;
        if k.start != "reference" && k.start != "config" {
            return Err(err("task.track.start", format!("{:?}", k.start), "\"reference\" or \"config\""));
        }
        if k.action != "reference" && k.action != "free" {
            return Err(err("task.track.action", format!("{:?}", k.action), "\"reference\" or \"free\""));
        }
        if k.lookahead > 8 {
            return Err(err("task.track.lookahead", k.lookahead.to_string(), "an integer in [0, 8]"));
        }
        if !(1..=1000).contains(&k.lookahead_stride) {
            return Err(err("task.track.lookahead_stride", k.lookahead_stride.to_string(), "an integer in [1, 1000]"));
        }
        for (key, v) in [
            ("task.track.beta_joint", k.beta_joint),
            ("task.track.beta_wrist_pos", k.beta_wrist_pos),
            ("task.track.beta_wrist_rot", k.beta_wrist_rot),
            ("task.track.alpha_joint", k.alpha_joint),
            ("task.track.alpha_wrist_pos", k.alpha_wrist_pos),
            ("task.track.alpha_wrist_rot", k.alpha_wrist_rot),
            ("task.track.alpha_object_pos", k.alpha_object_pos),
            ("task.track.alpha_object_rot", k.alpha_object_rot),
            ("task.track.max_object_error", k.max_object_error),
        ] {
            non_neg(err, key, v)?;
        }
        pos_in(err, "task.track.success_pos_tol", k.success_pos_tol, 1e-4, 10.0, "a distance in m in [0.0001, 10]")?;
        pos_in(err, "task.track.success_rot_tol", k.success_rot_tol, 1e-4, std::f32::consts::PI, "an angle in rad in [0.0001, π]")?;
        let r = &t.residual;
        for (key, v) in [
            ("task.residual.alpha", r.alpha),
            ("task.residual.wrist_pos_alpha", r.wrist_pos_alpha),
            ("task.residual.wrist_rot_alpha", r.wrist_rot_alpha),
            ("task.residual.obj_pos_coef", r.obj_pos_coef),
            ("task.residual.obj_rot_coef", r.obj_rot_coef),
            ("task.residual.scale_wrist_pos", r.scale_wrist_pos),
            ("task.residual.scale_wrist_rot", r.scale_wrist_rot),
            ("task.residual.scale_tips", r.scale_tips),
            ("task.residual.clamp_wrist_pos", r.clamp_wrist_pos),
            ("task.residual.clamp_tips", r.clamp_tips),
            ("task.residual.reward_obj_pos", r.reward_obj_pos),
            ("task.residual.reward_obj_rot", r.reward_obj_rot),
            ("task.residual.reward_tips", r.reward_tips),
            ("task.residual.reward_wrist_pos", r.reward_wrist_pos),
            ("task.residual.reward_wrist_rot", r.reward_wrist_rot),
        ] {
            non_neg(err, key, v)?;
        }
        pos_in(err, "task.residual.ema", r.ema, 1e-3, 1.0, "a weight in [0.001, 1]")?;
        pos_in(err, "task.residual.clamp_wrist_rot", r.clamp_wrist_rot, 0.0, std::f32::consts::PI, "an angle in rad in [0, π]")?;
        let l = &t.lift;
        non_neg(err, "task.lift.reach_alpha", l.reach_alpha)?;
        pos_in(err, "task.lift.success_height", l.success_height, 1e-3, 10.0, "a height in m in [0.001, 10]")?;
        non_neg(err, "task.lift.contact_force", l.contact_force)?;
        for i in 0..3 {
            finite(err, &format!("task.lift.palm_offset[{i}]"), l.palm_offset[i])?;
        }
        finite(err, "task.lift.drop_height", l.drop_height)?;
        pos_in(err, "task.lift.table_half_extent", l.table_half_extent, 1e-3, 1e3, "a distance in m in [0.001, 1000]")?;
        pos_in(err, "task.lift.max_hand_distance", l.max_hand_distance, 1e-3, 1e3, "a distance in m in [0.001, 1000]")?;

        let tr = &self.train;
        if BackendChoice::parse(&tr.device).is_none() {
            return Err(err("train.device", format!("{:?}", tr.device), "one of \"auto\", \"cpu\", \"gpu\", \"gpu:ADAPTER_NAME\""));
        }
        if tr.iterations == 0 {
            return Err(err("train.iterations", "0".into(), "an integer >= 1"));
        }
        if !(1..=100_000).contains(&tr.steps_per_env) {
            return Err(err("train.steps_per_env", tr.steps_per_env.to_string(), "an integer in [1, 100000]"));
        }
        if tr.save_interval == 0 {
            return Err(err("train.save_interval", "0".into(), "an integer >= 1 (iterations between checkpoints)"));
        }

        let p = &self.ppo;
        if p.schedule != "adaptive" && p.schedule != "fixed" {
            return Err(err("ppo.schedule", format!("{:?}", p.schedule), "\"adaptive\" or \"fixed\""));
        }
        pos_in(err, "ppo.learning_rate", p.learning_rate, 1e-9, 1.0, "a learning rate in (0, 1]")?;
        pos_in(err, "ppo.min_learning_rate", p.min_learning_rate, 0.0, 1.0, "a learning rate in [0, 1]")?;
        pos_in(err, "ppo.max_learning_rate", p.max_learning_rate, p.min_learning_rate, 1.0, "a learning rate in [ppo.min_learning_rate, 1]")?;
        pos_in(err, "ppo.desired_kl", p.desired_kl, 1e-9, 10.0, "a KL divergence in (0, 10]")?;
        pos_in(err, "ppo.gamma", p.gamma, 0.0, 1.0, "a discount in [0, 1]")?;
        pos_in(err, "ppo.lam", p.lam, 0.0, 1.0, "a GAE λ in [0, 1]")?;
        pos_in(err, "ppo.clip_param", p.clip_param, 1e-6, 10.0, "a clip range in (0, 10]")?;
        non_neg(err, "ppo.value_loss_coef", p.value_loss_coef)?;
        non_neg(err, "ppo.entropy_coef", p.entropy_coef)?;
        pos_in(err, "ppo.max_grad_norm", p.max_grad_norm, 1e-9, 1e9, "a gradient norm > 0")?;
        pos_in(err, "ppo.reward_scale", p.reward_scale, 1e-9, 1e9, "a factor > 0")?;
        if !(1..=1000).contains(&p.epochs) {
            return Err(err("ppo.epochs", p.epochs.to_string(), "an integer in [1, 1000]"));
        }
        let batch = self.sim.num_envs as u64 * tr.steps_per_env as u64;
        if p.minibatches == 0 || p.minibatches as u64 > batch {
            return Err(err("ppo.minibatches", p.minibatches.to_string(), &format!("an integer in [1, sim.num_envs × train.steps_per_env = {batch}]")));
        }

        let pol = &self.policy;
        for (key, layers) in [("policy.actor_hidden", &pol.actor_hidden), ("policy.critic_hidden", &pol.critic_hidden)] {
            if layers.is_empty() || layers.iter().any(|&w| w == 0 || w > 65536) {
                return Err(err(key, format!("{layers:?}"), "a non-empty list of layer widths in [1, 65536]"));
            }
        }
        if !["elu", "relu", "tanh"].contains(&pol.activation.as_str()) {
            return Err(err("policy.activation", format!("{:?}", pol.activation), "\"elu\", \"relu\" or \"tanh\""));
        }
        pos_in(err, "policy.init_std", pol.init_std, 1e-6, 100.0, "a standard deviation in (0, 100]")?;
        Ok(())
    }
}

fn pos_in(
    err: &dyn Fn(&str, String, &str) -> anyhow::Error,
    key: &str,
    v: f32,
    lo: f32,
    hi: f32,
    allowed: &str,
) -> Result<()> {
    if v.is_finite() && v >= lo && v <= hi { Ok(()) } else { Err(err(key, v.to_string(), allowed)) }
}

fn non_neg(err: &dyn Fn(&str, String, &str) -> anyhow::Error, key: &str, v: f32) -> Result<()> {
    if v.is_finite() && v >= 0.0 { Ok(()) } else { Err(err(key, v.to_string(), "a finite number >= 0")) }
}

fn finite(err: &dyn Fn(&str, String, &str) -> anyhow::Error, key: &str, v: f32) -> Result<()> {
    if v.is_finite() { Ok(()) } else { Err(err(key, v.to_string(), "a finite number")) }
}

fn unit_interval(err: &dyn Fn(&str, String, &str) -> anyhow::Error, key: &str, v: f32) -> Result<()> {
    if v.is_finite() && (0.0..1.0).contains(&v) { Ok(()) } else { Err(err(key, v.to_string(), "a number in [0, 1)")) }
}

/// Applies one `key=value` override to a parsed TOML table.
pub fn apply_override(table: &mut toml::Table, set: &str) -> Result<()> {
    let Some((key, value)) = set.split_once('=') else {
        bail!("--set {set:?}: expected key=value (e.g. ppo.learning_rate=1e-3)");
    };
    let key = key.trim();
    let parts: Vec<&str> = key.split('.').collect();
    if parts.iter().any(|p| p.is_empty()) {
        bail!("--set {set:?}: `{key}` is not a dotted key path");
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
            _ => bail!("--set {set:?}: `{p}` is a value, not a table"),
        };
    }
    cur.insert(parts[parts.len() - 1].to_string(), parsed);
    Ok(())
}

/// Collapses a multi-line message to one line.
pub fn one_line(s: &str) -> String {
    s.split_whitespace().collect::<Vec<_>>().join(" ")
}

fn line_col(text: &str, offset: usize) -> String {
    let before = &text[..offset.min(text.len())];
    let line = before.matches('\n').count() + 1;
    let col = before.rsplit('\n').next().map(|l| l.chars().count() + 1).unwrap_or(1);
    format!(":{line}:{col}")
}
