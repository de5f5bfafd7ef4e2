//! The task layer's Pod twins of task.wgsl's structs (`TaskGlobals`, a uniform, and the per-env
//! `TaskState`), with their sizes; tests/suite/shaders.rs checks sizes and offsets against the WGSL.

use bytemuck::{Pod, Zeroable};

use crate::gpu::layout::Targets;
use crate::hand::{MAX_JOINTS, MAX_TIPS};

/// Most actions (6 wrist + actuated joints) a `TaskState` holds (keep in sync with task.wgsl
/// `MAX_ACTIONS`): 6 + `MAX_JOINTS`, rounded up to a multiple of 4 (WGSL struct padding).
pub const MAX_ACTIONS: usize = (6 + MAX_JOINTS).div_ceil(4) * 4;

/// Run-wide constants of the task layer (WGSL `TaskGlobals`, a uniform; built by `task::setup` from
/// `[task]` of the config and the hand).
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable, PartialEq)]
pub struct TaskGlobals {
    /// Box (m, world) that the wrist position target is clipped to, xyz.
    pub wrist_pos_min: [f32; 4],
    pub wrist_pos_max: [f32; 4],
    /// Palm point in the wrist frame (m), xyz.
    pub palm_offset: [f32; 4],
    /// Weight of each reward term in the kind's order (`config::rewards`), packed 4 per vec4.
    pub weights: [[f32; 4]; 3],
    /// Joint index of each actuated joint (`EnvSpec::actuated`), packed 4 per vec4 (uniform arrays
    /// need a 16-byte stride).
    pub actuated: [[u32; 4]; MAX_JOINTS / 4],
    /// Number of actuated joints and of actions (6 + actuated).
    pub n_actuated: u32,
    pub n_act: u32,
    /// Actor and critic observation lengths.
    pub obs_dim: u32,
    pub priv_dim: u32,
    /// Env steps per episode.
    pub episode_length: u32,
    /// 0 = absolute finger targets, 1 = delta.
    pub finger_mode: u32,
    /// Fingertip index of the thumb.
    pub thumb: u32,
    /// `task.obs_noise.object_delay`: the least and the largest latency (control steps) of the
    /// actor's object pose.
    pub obj_delay_min: u32,
    pub wrist_pos_scale: f32,
    pub wrist_rot_scale: f32,
    pub wrist_rot_limit: f32,
    pub finger_delta_scale: f32,
    pub reach_alpha: f32,
    pub success_height: f32,
    pub contact_force: f32,
    pub drop_height: f32,
    pub table_half_extent: f32,
    pub max_hand_distance: f32,
    /// Standard deviations of the actor observation noise.
    pub noise_joint_pos: f32,
    pub noise_joint_vel: f32,
    pub noise_hand_pos: f32,
    pub noise_object_pos: f32,
    pub noise_object_rot: f32,
    pub obj_delay_max: u32,
    /// `KIND_LIFT`, `KIND_TRACK`, `KIND_RESIDUAL_JOINT` or `KIND_RESIDUAL_TASK` (env::task).
    pub kind: u32,
    /// Number of reward terms of the kind (≤ `MAX_TERMS`).
    pub n_terms: u32,
    /// 0: episodes start at the reference's first frame; 1: where the config puts hand and object.
    pub start_mode: u32,
    /// Look-ahead reference frames observed, and env steps between them.
    pub lookahead: u32,
    pub lookahead_stride: u32,
    /// residual_task: residual components (6 + 3 · fingertips).
    pub n_res: u32,
    /// 1: the open-loop baseline (actions ignored, targets = the reference's).
    pub open_loop: u32,
    /// track: 1 maps the actions around the reference like residual_joint (`task.track.action =
    /// "reference"`), 0 with `[task.action]` (`"free"`).
    pub track_action: u32,
    /// `[task.track]` β1–β3, α1–α5, success tolerances (m, rad), early-termination distance (m).
    pub beta_joint: f32,
    pub beta_wrist_pos: f32,
    pub beta_wrist_rot: f32,
    pub alpha_joint: f32,
    pub alpha_wrist_pos: f32,
    pub alpha_wrist_rot: f32,
    pub alpha_object_pos: f32,
    pub alpha_object_rot: f32,
    pub success_pos_tol: f32,
    pub success_rot_tol: f32,
    pub max_object_error: f32,
    /// `[task.residual]` (see config::ResidualConfig).
    pub res_alpha: f32,
    pub res_wrist_pos_alpha: f32,
    pub res_wrist_rot_alpha: f32,
    pub res_obj_pos_coef: f32,
    pub res_obj_rot_coef: f32,
    pub res_ema: f32,
    pub res_scale_wrist_pos: f32,
    pub res_scale_wrist_rot: f32,
    pub res_scale_tips: f32,
    pub res_clamp_wrist_pos: f32,
    pub res_clamp_wrist_rot: f32,
    pub res_clamp_tips: f32,
    /// Seconds per env step (Δt of the residual integration).
    pub control_dt: f32,
    pub rw_obj_pos: f32,
    pub rw_obj_rot: f32,
    pub rw_tips: f32,
    pub rw_wrist_pos: f32,
    pub rw_wrist_rot: f32,
    /// `task.hand.grip_force_limit` (N) and `task.hand.penetration_tolerance` (m): the grasp terms.
    pub grip_force_limit: f32,
    pub penetration_tolerance: f32,
    pub _pad1: f32,
    /// The fingertip IK of residual_task.
    pub ik: crate::task::ik::IkParams,
}

/// The task layer's per-env state (WGSL `TaskState`), kept between steps.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable, PartialEq)]
pub struct TaskState {
    /// The current wrist and joint targets (actions in delta modes move them).
    pub targets: Targets,
    /// Object centre position right after the env's last reset (xyz).
    pub rest_pos: [f32; 4],
    /// The last clipped action (0 after a reset).
    pub prev_action: [f32; MAX_ACTIONS],
    /// Fingertip forces (N) of the last step (`StepStats::tip_force`; 0 after a reset).
    pub tip_force: [f32; MAX_TIPS],
    /// Σ (a_t − a_{t−1})² and Σ a_t² of the last action.
    pub act_rate: f32,
    pub act_mag: f32,
    /// 1 if the last step ended the episode (terminated or timed out).
    pub done: u32,
    /// ‖δ‖² of the last residual (residual kinds).
    pub res_sq: f32,
    /// `StepStats::link_contact` of the last step (0 after a reset).
    pub link_contact: [u32; 2],
    /// The reference this episode follows (reference kinds).
    pub cursor: crate::task::reference::RefCursor,
    /// residual_task: the EMA-smoothed output ũ and the integrated residual Δa (`n_res` used).
    pub res_ema: [f32; MAX_RES],
    pub res_delta: [f32; MAX_RES],
    /// The object poses of the last [`OBJ_HIST`] observations (position xyz_, quaternion xyzw),
    /// slot `step % OBJ_HIST`, and this episode's latency (control steps) of the actor's view.
    pub obj_hist_pos: [[f32; 4]; OBJ_HIST],
    pub obj_hist_rot: [[f32; 4]; OBJ_HIST],
    pub obj_delay: u32,
    pub _pad3: [u32; 3],
}

/// The largest `task.obs_noise.object_delay` (control steps; the config's bound).
pub use crate::config::task::MAX_OBJ_DELAY;
/// Slots of the object-pose ring of [`TaskState`]: one more than the largest latency.
pub const OBJ_HIST: usize = MAX_OBJ_DELAY as usize + 1;

/// Most residual components of residual_task: 6 wrist + 3 per fingertip.
pub const MAX_RES: usize = 6 + 3 * MAX_TIPS;

impl Default for TaskState {
    fn default() -> Self {
        Zeroable::zeroed()
    }
}
