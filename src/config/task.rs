//! `[task]`: the task kind, how actions become targets, observation noise, reward weights,
//! terminations, the references of the reference-following kinds and their augmentation, and the
//! residual kinds' parameters (docs/design.md §5). The reward terms of each kind are named in one table,
//! [`super::rewards::reward_terms`].

use std::collections::BTreeMap;

use anyhow::Result;
use serde::{Deserialize, Serialize};

use super::Check;
use super::rewards::reward_terms;

/// The largest `task.obs_noise.object_delay` (control steps); the task state's object-pose ring
/// (`task::layout::OBJ_HIST`) has one slot more.
pub const MAX_OBJ_DELAY: u32 = 7;

/// The task (`task.kind`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TaskKind {
    /// Grasp the object and lift it at least `task.lift.success_height`.
    Lift,
    /// Follow reference trajectories (docs/design.md §5, trajectory following).
    Track,
    /// A bounded joint-space correction of the reference's joint targets.
    ResidualJoint,
    /// A smoothed, integrated task-space correction of the reference's wrist pose and fingertips,
    /// mapped to joints by IK.
    ResidualTask,
}

impl TaskKind {
    /// Every kind, in `TaskGlobals::kind` order.
    pub const ALL: [TaskKind; 4] = [TaskKind::Lift, TaskKind::Track, TaskKind::ResidualJoint, TaskKind::ResidualTask];

    /// The TOML name (`"lift"`, `"track"`, `"residual_joint"`, `"residual_task"`).
    pub fn name(self) -> &'static str {
        match self {
            TaskKind::Lift => "lift",
            TaskKind::Track => "track",
            TaskKind::ResidualJoint => "residual_joint",
            TaskKind::ResidualTask => "residual_task",
        }
    }

    /// `TaskGlobals::kind` (keep in sync with task.wgsl's `KIND_*`).
    pub fn index(self) -> u32 {
        self as u32
    }

    /// Whether the kind follows references (`[task.reference]`, `[task.track]`).
    pub fn follows_reference(self) -> bool {
        self != TaskKind::Lift
    }

    /// The names of the kind's reward terms, in output order.
    pub fn term_names(self) -> Vec<&'static str> {
        reward_terms(self).iter().map(|t| t.name).collect()
    }

    /// The default weights of the kind's reward terms (the tables of [`super::rewards`]).
    pub fn default_rewards(self) -> BTreeMap<String, f32> {
        reward_terms(self).iter().map(|t| (t.name.to_string(), t.default_weight)).collect()
    }
}

impl std::fmt::Display for TaskKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// How lift's (and free track's) finger actions become joint targets (`task.action.finger_mode`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FingerMode {
    /// a ∈ [−1, 1] maps linearly onto [lower, upper] of each joint.
    Absolute,
    /// The previous target moves by `a · finger_delta_scale`, clipped to the limits.
    Delta,
}

/// Where a reference kind's episode starts (`task.track.start`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ReferenceStart {
    /// Hand and object at the reference's first frame, as `dextrain replay` starts.
    Reference,
    /// Hand at `wrist.init_*` and default joints, object where the simulator's reset puts it.
    Config,
}

/// How `track`'s actions become targets (`task.track.action`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TrackAction {
    /// The reference's targets of this step plus a bounded offset (residual_joint's mapping).
    Reference,
    /// Lift's `[task.action]` mapping, with no reference in the action.
    Free,
}

/// `[task]`
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TaskConfig {
    /// The task: `"lift"` (grasp the object and lift it at least `lift.success_height`), `"track"`
    /// (follow reference trajectories: docs/design.md §5), `"residual_joint"` (a bounded joint-space
    /// correction of the reference's joint targets) or `"residual_task"` (a smoothed, integrated
    /// task-space correction of the reference's wrist pose and fingertips, mapped to joints by IK).
    pub kind: TaskKind,
    /// Episode length in env steps; reaching it is a time-out (returns bootstrap through it).
    /// 0 (reference kinds only): until the env's reference (time-scaled) has ended.
    pub episode_length: u32,
    /// How the policy's actions become joint and wrist targets.
    pub action: ActionConfig,
    /// Standard deviations of the Gaussian noise added to the actor's observations (the critic's are clean).
    pub obs_noise: ObsNoiseConfig,
    /// Weight of each reward term (term name -> weight; 0 turns a term off, an unknown name is an
    /// error). The terms of each kind and their formulas: docs/tasks.md ("Reward terms") and
    /// [`super::rewards::reward_terms`]. Penalties have negative weights (Isaac Lab's convention).
    pub rewards: BTreeMap<String, f32>,
    /// The points and thresholds on the hand that every kind uses: the thumb, fingertip contact,
    /// the palm point.
    pub hand: HandPointsConfig,
    /// When an episode terminates (every kind).
    pub termination: TerminationConfig,
    /// Parameters of the lift task's rewards and success.
    pub lift: LiftConfig,
    /// The references of the reference-following kinds (track, residual_joint, residual_task) and
    /// their augmentation.
    pub reference: ReferenceConfig,
    /// Observations, rewards and success of the reference-following kinds.
    pub track: TrackConfig,
    /// Parameters of the residual kinds.
    pub residual: ResidualConfig,
    /// The open-loop baseline of the reference kinds: actions are ignored and the targets follow the
    /// (augmented) reference, as `dextrain replay` drives them (`dextrain eval --baseline open-loop`
    /// sets it).
    pub open_loop: bool,
}

/// `[task.action]`: the action is `6 + actuated joints` numbers in [−1, 1] (clipped): wrist
/// translation (3, world frame), wrist rotation (3, a rotation vector in the world frame), then one
/// per actuated finger joint in URDF order.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ActionConfig {
    /// Finger joints: `"absolute"` maps a ∈ [−1, 1] linearly onto [lower, upper] of each joint;
    /// `"delta"` moves the previous target by `a · finger_delta_scale`, clipped to the limits.
    pub finger_mode: FingerMode,
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

/// `[task.obs_noise]`: what the actor's sensors add to the state: noise standard deviations (0 =
/// none) and the latency of the object pose.
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
    /// Latency of the object pose the actor sees, as a vision tracker's, in control steps: each
    /// episode draws k uniformly from [min, max]; the actor's `obj_pos` / `obj_rot` (and what is
    /// computed from them: lift's `obj_rel`, the reference block's object errors) are the pose of k
    /// steps earlier (the episode's first pose before that), with the noise on top; the critic
    /// sees the current pose. [0, 0] = none; at most [`MAX_OBJ_DELAY`].
    pub object_delay: [u32; 2],
}

/// `[task.hand]`: points and thresholds on the hand that every task kind uses.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct HandPointsConfig {
    /// The thumb's fingertip frame (one of `hand.fingertips`); "" = the first whose name starts with "th".
    pub thumb: String,
    /// Fingertip normal force (N) above which a fingertip touches the object (the contact reward
    /// terms, the `tip_contact` critic observations, eval's contact metrics).
    pub contact_force: f32,
    /// The palm point (m) in the wrist frame: lift's reaching term brings it to the object, and
    /// `task.termination.max_hand_distance` is measured from it.
    pub palm_offset: [f32; 3],
    /// Fingertip normal force (N) that a grasp should not exceed: every kind's `grip_force` reward
    /// term counts each fingertip's force beyond it (10 N: what a robot hand's fingertip presses
    /// with; a 0.1 kg object needs ~0.25 N per finger at μ = 1).
    pub grip_force_limit: f32,
    /// Hand–object penetration (m) that every kind's `penetration` reward term tolerates before it
    /// counts (in mm).
    pub penetration_tolerance: f32,
}

/// `[task.termination]`: when an episode terminates (every kind; a time-out is `task.episode_length`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TerminationConfig {
    /// The episode terminates when the object's centre falls below this height (m; off the table).
    pub drop_height: f32,
    /// ... or leaves the square |x|, |y| ≤ this (m) on the table.
    pub table_half_extent: f32,
    /// ... or the palm point gets farther than this from the object (m).
    pub max_hand_distance: f32,
}

/// `[task.lift]`: the lift task's reaching term and success (`success_height` also caps the
/// `lifting` term of `track`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LiftConfig {
    /// α of the reaching term `1 − tanh(α‖p_palm − p_obj‖)` (1/m).
    pub reach_alpha: f32,
    /// Lift height (m) of the object's centre above its rest height that counts as success.
    pub success_height: f32,
}

/// `[task.reference]`: the references a trajectory-following or residual task tracks and their
/// augmentation (`task::reference`'s module documentation). Every augmentation is off by default.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ReferenceConfig {
    /// Reference trajectories (`.mcap` or `.csv`, paths relative to the config file); each episode
    /// plays one drawn uniformly.
    pub files: Vec<String>,
    /// Half-range (m) of a uniform x and y shift of the whole reference (object and hand together).
    pub translate_xy: f32,
    /// Half-range (rad) of a uniform rotation of the whole reference about the vertical axis through
    /// its first object position.
    pub rotate_z: f32,
    /// Re-ground the reference onto the object where the env's reset put it (Praxis): every wrist
    /// pose keeps its pose relative to the object. Makes `translate_xy` and `rotate_z` moot.
    pub reground: bool,
    /// Re-interpolate the wrist over the first segment from the robot's start pose to the reference
    /// (DexRefine App. C).
    pub reinterp: bool,
    /// Length (env steps) of the re-interpolated segment; 0 = up to the reference's keyframe 1.
    pub reinterp_steps: u32,
    /// Probability (0–1) that an episode's reference is mirrored across the vertical x–z plane
    /// through its first object position.
    pub mirror_prob: f32,
    /// Half-range (m) of a per-episode constant offset of the wrist position (per axis).
    pub wrist_pos_offset: f32,
    /// Half-range (rad) of a per-episode constant wrist rotation offset (each component of a
    /// rotation vector).
    pub wrist_rot_offset: f32,
    /// Half-range (rad) of a per-episode constant offset of each joint.
    pub joint_offset: f32,
    /// Standard deviation (m) of per-frame Gaussian noise on the wrist position.
    pub wrist_pos_noise: f32,
    /// Standard deviation (rad) of per-frame Gaussian noise on each joint.
    pub joint_noise: f32,
    /// Half-range of the playback speed: each episode plays the reference at speed
    /// 1 + time_scale · U(−1, 1) reference frames per env step (a fraction in [0, 0.9]).
    pub time_scale: f32,
}

/// `[task.track]`: observations, tracking rewards and success of `track`, `residual_joint` and
/// `residual_task` (docs/design.md §5); the references themselves are `[task.reference]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TrackConfig {
    /// Where an episode starts: `"reference"` (hand and object at the reference's first frame, as
    /// `dextrain replay` starts) or `"config"` (hand at `wrist.init_*` and default joints, object
    /// where the simulator's reset puts it; pair with `task.reference.reground`/`reinterp`).
    pub start: ReferenceStart,
    /// How `track`'s actions become targets. `"reference"`: the reference's targets of this step
    /// plus a bounded offset, mapped as `residual_joint` maps its residual with `[task.residual]`'s
    /// `alpha`, `wrist_pos_alpha` and `wrist_rot_alpha` (PD targets around the reference, as
    /// DeepMimic-style trackers act); `"free"`: lift's `[task.action]` mapping (wrist moves and
    /// finger targets the policy integrates itself, with no reference in the action).
    pub action: TrackAction,
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

/// `[task.residual]`: how residual actions correct the reference (docs/design.md §1, §5).
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

impl Default for TaskConfig {
    fn default() -> Self {
        TaskConfig {
            kind: TaskKind::Lift,
            episode_length: 90,
            action: ActionConfig::default(),
            obs_noise: ObsNoiseConfig::default(),
            rewards: TaskKind::Lift.default_rewards(),
            hand: HandPointsConfig::default(),
            termination: TerminationConfig::default(),
            lift: LiftConfig::default(),
            reference: ReferenceConfig::default(),
            track: TrackConfig::default(),
            residual: ResidualConfig::default(),
            open_loop: false,
        }
    }
}

impl Default for ActionConfig {
    fn default() -> Self {
        ActionConfig {
            finger_mode: FingerMode::Absolute,
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
        ObsNoiseConfig { joint_pos: 0.0, joint_vel: 0.0, hand_pos: 0.0, object_pos: 0.0, object_rot: 0.0, object_delay: [0, 0] }
    }
}

impl Default for HandPointsConfig {
    fn default() -> Self {
        HandPointsConfig { thumb: String::new(), contact_force: 0.05, palm_offset: [0.0, 0.0, -0.04], grip_force_limit: 10.0, penetration_tolerance: 0.001 }
    }
}

impl Default for TerminationConfig {
    fn default() -> Self {
        TerminationConfig { drop_height: -0.05, table_half_extent: 0.5, max_hand_distance: 0.5 }
    }
}

impl Default for LiftConfig {
    fn default() -> Self {
        LiftConfig { reach_alpha: 10.0, success_height: 0.10 }
    }
}

impl Default for ReferenceConfig {
    fn default() -> Self {
        ReferenceConfig {
            files: Vec::new(),
            translate_xy: 0.0,
            rotate_z: 0.0,
            reground: false,
            reinterp: false,
            reinterp_steps: 0,
            mirror_prob: 0.0,
            wrist_pos_offset: 0.0,
            wrist_rot_offset: 0.0,
            joint_offset: 0.0,
            wrist_pos_noise: 0.0,
            joint_noise: 0.0,
            time_scale: 0.0,
        }
    }
}

impl Default for TrackConfig {
    fn default() -> Self {
        TrackConfig {
            start: ReferenceStart::Reference,
            action: TrackAction::Reference,
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

impl TaskConfig {
    /// Checks `[task]` and its tables.
    pub fn validate(&self, c: &Check) -> Result<()> {
        let follows = self.kind.follows_reference();
        if self.episode_length > 1_000_000 || (self.episode_length == 0 && !follows) {
            return Err(c.err(
                "task.episode_length",
                self.episode_length,
                if follows { "an integer number of env steps in [0, 1000000] (0: until the reference ends)" } else { "an integer number of env steps in [1, 1000000]" },
            ));
        }
        self.action.validate(c)?;
        self.obs_noise.validate(c)?;
        let terms = self.kind.term_names();
        for (name, w) in &self.rewards {
            if !terms.contains(&name.as_str()) {
                return Err(c.err(&format!("task.rewards.{name}"), w, &format!("a term of the {} task: {}", self.kind, terms.join(", "))));
            }
            c.finite(&format!("task.rewards.{name}"), *w)?;
        }
        if follows && self.reference.files.is_empty() {
            return Err(c.err("task.reference.files", "[]", &format!("at least one reference file for task.kind = \"{}\"", self.kind)));
        }
        self.reference.validate(c)?;
        self.track.validate(c)?;
        self.residual.validate(c)?;
        self.hand.validate(c)?;
        self.termination.validate(c)?;
        self.lift.validate(c)
    }
}

impl ActionConfig {
    /// Checks `[task.action]`.
    pub fn validate(&self, c: &Check) -> Result<()> {
        c.non_neg("task.action.finger_delta_scale", self.finger_delta_scale)?;
        c.non_neg("task.action.wrist_pos_scale", self.wrist_pos_scale)?;
        c.non_neg("task.action.wrist_rot_scale", self.wrist_rot_scale)?;
        for i in 0..3 {
            c.finite(&format!("task.action.wrist_pos_min[{i}]"), self.wrist_pos_min[i])?;
            c.finite(&format!("task.action.wrist_pos_max[{i}]"), self.wrist_pos_max[i])?;
            if self.wrist_pos_min[i] > self.wrist_pos_max[i] {
                return Err(c.err(&format!("task.action.wrist_pos_max[{i}]"), self.wrist_pos_max[i], "a value >= task.action.wrist_pos_min of the same axis"));
            }
        }
        c.in_range("task.action.wrist_rot_limit", self.wrist_rot_limit, 0.0, std::f32::consts::PI, "an angle in rad in [0, π]")
    }
}

impl ObsNoiseConfig {
    /// Checks `[task.obs_noise]`.
    pub fn validate(&self, c: &Check) -> Result<()> {
        for (key, v) in [
            ("task.obs_noise.joint_pos", self.joint_pos),
            ("task.obs_noise.joint_vel", self.joint_vel),
            ("task.obs_noise.hand_pos", self.hand_pos),
            ("task.obs_noise.object_pos", self.object_pos),
            ("task.obs_noise.object_rot", self.object_rot),
        ] {
            c.non_neg(key, v)?;
        }
        let [lo, hi] = self.object_delay;
        let max = MAX_OBJ_DELAY;
        if lo > hi || hi > max {
            return Err(c.err("task.obs_noise.object_delay", format!("[{lo}, {hi}]"), &format!("[min, max] control steps with min <= max <= {max}")));
        }
        Ok(())
    }
}

impl HandPointsConfig {
    /// Checks `[task.hand]` (the thumb's name is checked against the hand when the task is built).
    pub fn validate(&self, c: &Check) -> Result<()> {
        c.non_neg("task.hand.contact_force", self.contact_force)?;
        c.non_neg("task.hand.grip_force_limit", self.grip_force_limit)?;
        c.non_neg("task.hand.penetration_tolerance", self.penetration_tolerance)?;
        for i in 0..3 {
            c.finite(&format!("task.hand.palm_offset[{i}]"), self.palm_offset[i])?;
        }
        Ok(())
    }
}

impl TerminationConfig {
    /// Checks `[task.termination]`.
    pub fn validate(&self, c: &Check) -> Result<()> {
        c.finite("task.termination.drop_height", self.drop_height)?;
        c.in_range("task.termination.table_half_extent", self.table_half_extent, 1e-3, 1e3, "a distance in m in [0.001, 1000]")?;
        c.in_range("task.termination.max_hand_distance", self.max_hand_distance, 1e-3, 1e3, "a distance in m in [0.001, 1000]")
    }
}

impl LiftConfig {
    /// Checks `[task.lift]`.
    pub fn validate(&self, c: &Check) -> Result<()> {
        c.non_neg("task.lift.reach_alpha", self.reach_alpha)?;
        c.in_range("task.lift.success_height", self.success_height, 1e-3, 10.0, "a height in m in [0.001, 10]")
    }
}

impl ReferenceConfig {
    /// Checks `[task.reference]` (the files themselves are checked when they load).
    pub fn validate(&self, c: &Check) -> Result<()> {
        let pi = std::f32::consts::PI;
        for (k, f) in self.files.iter().enumerate() {
            if f.trim().is_empty() {
                return Err(c.err(&format!("task.reference.files[{k}]"), "\"\"", "the path of a .mcap or .csv reference"));
            }
        }
        c.in_range("task.reference.translate_xy", self.translate_xy, 0.0, 10.0, "a distance in m in [0, 10]")?;
        c.in_range("task.reference.rotate_z", self.rotate_z, 0.0, pi, "an angle in rad in [0, π]")?;
        if self.reinterp_steps > 1_000_000 {
            return Err(c.err("task.reference.reinterp_steps", self.reinterp_steps, "a number of env steps in [0, 1000000]"));
        }
        c.in_range("task.reference.mirror_prob", self.mirror_prob, 0.0, 1.0, "a probability in [0, 1]")?;
        c.in_range("task.reference.wrist_pos_offset", self.wrist_pos_offset, 0.0, 1.0, "a distance in m in [0, 1]")?;
        c.in_range("task.reference.wrist_rot_offset", self.wrist_rot_offset, 0.0, pi, "an angle in rad in [0, π]")?;
        c.in_range("task.reference.joint_offset", self.joint_offset, 0.0, pi, "an angle in rad in [0, π]")?;
        c.in_range("task.reference.wrist_pos_noise", self.wrist_pos_noise, 0.0, 1.0, "a standard deviation in m in [0, 1]")?;
        c.in_range("task.reference.joint_noise", self.joint_noise, 0.0, pi, "a standard deviation in rad in [0, π]")?;
        c.in_range("task.reference.time_scale", self.time_scale, 0.0, 0.9, "a fraction in [0, 0.9] (the speed 1 ± u must stay > 0)")
    }
}

impl TrackConfig {
    /// Checks `[task.track]`.
    pub fn validate(&self, c: &Check) -> Result<()> {
        if self.lookahead > 8 {
            return Err(c.err("task.track.lookahead", self.lookahead, "an integer in [0, 8]"));
        }
        if !(1..=1000).contains(&self.lookahead_stride) {
            return Err(c.err("task.track.lookahead_stride", self.lookahead_stride, "an integer in [1, 1000]"));
        }
        for (key, v) in [
            ("task.track.beta_joint", self.beta_joint),
            ("task.track.beta_wrist_pos", self.beta_wrist_pos),
            ("task.track.beta_wrist_rot", self.beta_wrist_rot),
            ("task.track.alpha_joint", self.alpha_joint),
            ("task.track.alpha_wrist_pos", self.alpha_wrist_pos),
            ("task.track.alpha_wrist_rot", self.alpha_wrist_rot),
            ("task.track.alpha_object_pos", self.alpha_object_pos),
            ("task.track.alpha_object_rot", self.alpha_object_rot),
            ("task.track.max_object_error", self.max_object_error),
        ] {
            c.non_neg(key, v)?;
        }
        c.in_range("task.track.success_pos_tol", self.success_pos_tol, 1e-4, 10.0, "a distance in m in [0.0001, 10]")?;
        c.in_range("task.track.success_rot_tol", self.success_rot_tol, 1e-4, std::f32::consts::PI, "an angle in rad in [0.0001, π]")
    }
}

impl ResidualConfig {
    /// Checks `[task.residual]`.
    pub fn validate(&self, c: &Check) -> Result<()> {
        for (key, v) in [
            ("task.residual.alpha", self.alpha),
            ("task.residual.wrist_pos_alpha", self.wrist_pos_alpha),
            ("task.residual.wrist_rot_alpha", self.wrist_rot_alpha),
            ("task.residual.obj_pos_coef", self.obj_pos_coef),
            ("task.residual.obj_rot_coef", self.obj_rot_coef),
            ("task.residual.scale_wrist_pos", self.scale_wrist_pos),
            ("task.residual.scale_wrist_rot", self.scale_wrist_rot),
            ("task.residual.scale_tips", self.scale_tips),
            ("task.residual.clamp_wrist_pos", self.clamp_wrist_pos),
            ("task.residual.clamp_tips", self.clamp_tips),
            ("task.residual.reward_obj_pos", self.reward_obj_pos),
            ("task.residual.reward_obj_rot", self.reward_obj_rot),
            ("task.residual.reward_tips", self.reward_tips),
            ("task.residual.reward_wrist_pos", self.reward_wrist_pos),
            ("task.residual.reward_wrist_rot", self.reward_wrist_rot),
        ] {
            c.non_neg(key, v)?;
        }
        c.in_range("task.residual.ema", self.ema, 1e-3, 1.0, "a weight in [0.001, 1]")?;
        c.in_range("task.residual.clamp_wrist_rot", self.clamp_wrist_rot, 0.0, std::f32::consts::PI, "an angle in rad in [0, π]")
    }
}

impl std::str::FromStr for TaskKind {
    type Err = String;
    /// The TOML name of a kind.
    fn from_str(s: &str) -> Result<Self, String> {
        TaskKind::ALL.into_iter().find(|k| k.name() == s).ok_or_else(|| {
            let names: Vec<String> = TaskKind::ALL.iter().map(|k| format!("\"{}\"", k.name())).collect();
            format!("expected one of {}", names.join(", "))
        })
    }
}
