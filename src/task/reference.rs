//! The reference layer of the trajectory-following and residual tasks: a per-env cursor into the
//! run's [`RefBank`] with an augmentation drawn at reset, and sampling of the augmented reference at
//! the current env step and at look-ahead steps. CPU twin of `shaders/reference.wgsl`: the functions
//! after [`RefModel`] have the shader's names, order and arithmetic (tests/suite/reference.rs checks
//! the order and the results).
//!
//! # The contract
//!
//! - At an env's reset the task calls [`ref_begin`] with the env's freshly reset state and keeps the
//!   returned [`RefCursor`] (128 bytes, meant to sit in the task's per-env state). When
//!   `reground = false` the task then places the object at [`ref_object_start`] (the augmented
//!   reference's first object pose); with `reground = true` the reference is moved onto the object
//!   where the env's reset put it.
//! - At env step `step` (0 right after the reset) the task calls [`ref_sample`]`(cursor, step, k)`
//!   for the reference it tracks now (`k = 0`) and for look-ahead frames (`k > 0`): the augmented
//!   reference at env step `n = step + k`. Everything in [`RefFrame`] is in the world frame.
//! - Env step `n` plays the reference at the fractional frame index `x = n · speed` (`speed` = 1 unless
//!   `time_scale` is on). An integral `x` gives the stored frame EXACTLY (no interpolation, no
//!   renormalisation); a fractional one interpolates frames ⌊x⌋ and ⌊x⌋ + 1 (positions, joints,
//!   fingertips linearly, rotations by shortest-arc slerp; the grasp flag of the nearer frame). From
//!   `x ≥ last frame` on the last frame is held and [`RefFrame::ended`] is 1 (it is 1 at the last
//!   frame itself: the reference has been played to its end).
//! - Both backends draw the same numbers: every draw is `rand_uniform(g.seed, env, episode,`
//!   [`PURPOSE_REF`]`, key)` with the keys `REF_KEY_*` below.
//!
//! # Augmentations (each off at its default; [`crate::config::ReferenceConfig`], `[task.reference]`)
//!
//! Drawn once per episode in [`ref_begin`]: the reference (uniform over the bank), the speed
//! `1 + time_scale · U(−1, 1)`, the mirror (with probability `mirror_prob`), the wrist offsets
//! (each component of the position offset and of the rotation-vector offset uniform in ±half-range),
//! the joint offsets (one per actuated joint, uniform in ±`joint_offset`; a mimic follower gets
//! `mult ×` its leader's), and the rigid transform D of the whole reference. Per frame: Gaussian
//! noise on the wrist position (σ = `wrist_pos_noise`) and the joints (σ = `joint_noise`; followers
//! again `mult ×` their leader's), keyed by the env step `n` the sample is for and the component, so
//! that `ref_sample(c, s, k)` and `ref_sample(c, s + k, 0)` are the same numbers.
//!
//! A sample is built in this order:
//! 1. the raw frame at `x = n · speed` (above);
//! 2. `ref_perturb`, hand parts only: the wrist moves by the position offset + noise and rotates by
//!    exp(rotation offset) about its own position (world axes, left-multiplied); the fingertips move
//!    rigidly with the wrist (`p' = w + Δ + Q(p − w)`); joints get their offsets + noise (the
//!    fingertips do not follow the joint noise: there is no forward kinematics in the sampler). The
//!    object reference is never perturbed;
//! 3. `ref_mirror`: reflection across the vertical x–z plane through the reference's first object
//!    position `y0`: `p.y → 2·y0 − p.y` for the wrist, fingertips and object, quaternions
//!    `(x, y, z, w) → (−x, y, −z, w)`, joints unchanged (so a right hand tracks the reflected wrist
//!    path with its own joint angles; the mirrored fingertips are those of a mirrored hand);
//! 4. `ref_transform`: D applied to every pose and point (`p' = R_D p + t_D`, `q' = q_D ⊗ q`).
//!    With `reground`, D = T_obj,env · T_obj,ref(0)⁻¹ (T_obj,ref(0): the reference's first object
//!    pose after steps 2–3), so that every wrist keyframe keeps its pose relative to the object,
//!    T̂_a = T̂_o · (T_o⁻¹ T_a) (Praxis), and the reference object starts exactly where the env's reset put
//!    the object. Without it, D = translation by (`translate_xy` · U(−1, 1)) in x and y after a
//!    rotation by `rotate_z` · U(−1, 1) about the vertical axis through the reference's first object
//!    position. (With `reground` on, a translation/rotation before it would cancel out: the env's own
//!    object randomisation, `object.xy_noise` / `yaw_noise`, plays that role.) With D off it is
//!    skipped entirely, so an un-augmented reference is the bank's record bit for bit;
//! 5. re-interpolation (`reinterp`, DexRefine App. C): during the first segment, env steps
//!    `n < seg_steps` (`seg_steps` = the reference's first segment, to its keyframe 1, divided by the
//!    speed and rounded, at least 1; or `reinterp_steps` when that is > 0), the wrist is replaced by
//!    `lerp(p_start, p_end, n / seg_steps)` / `slerp(q_start, q_end, n / seg_steps)` from the robot's
//!    wrist pose at the reset (stored in the cursor) to the augmented reference's wrist at step
//!    `seg_steps`; the fingertips are carried rigidly with the wrist; joints and object are the
//!    augmented reference's. Step 0 is exactly the start pose; from `seg_steps` on the sample is the
//!    augmented reference.
//!
//! Expressing a frame relative to the current state (observations, rewards) is the task layer's.

use bytemuck::{Pod, Zeroable};
use glam::{Vec3, Vec4};


use crate::env::SimModel;
use crate::env::common::{quat_conj, quat_from_axis_angle, quat_mul, quat_normalize, quat_rotate, rand_uniform};
use crate::gpu::layout::{EnvState, Globals, JointDesc, NO_JOINT};
use crate::env::physics::{put3, v3, v4};
use crate::hand::{MAX_JOINTS, MAX_TIPS};
use crate::task::bank::RefBank;

/// RNG purpose of the reference draws (keep in sync with reference.wgsl; reset uses 1 and 2, the
/// observation noise 3).
pub const PURPOSE_REF: u32 = 4;
/// Draw keys of [`ref_begin`] (keep in sync with reference.wgsl): the reference, the speed, the mirror.
pub const REF_KEY_ID: u32 = 0;
pub const REF_KEY_SPEED: u32 = 1;
pub const REF_KEY_MIRROR: u32 = 2;
/// Translation x, y (keys 3, 4) and rotation (5) of D.
pub const REF_KEY_TRANSLATE: u32 = 3;
pub const REF_KEY_ROTATE: u32 = 5;
/// Wrist position offset x y z (6–8) and rotation-vector offset x y z (9–11).
pub const REF_KEY_WRIST_POS: u32 = 6;
pub const REF_KEY_WRIST_ROT: u32 = 9;
/// Joint offset of joint j: key 16 + j.
pub const REF_KEY_JOINT: u32 = 16;
/// Per-frame noise: component `c` (0–2 wrist xyz, 3 + j joint j) of env step `n` uses keys
/// `REF_KEY_NOISE + n · REF_KEY_STRIDE + 2c + {0, 1}` (Box–Muller), wrapping in u32.
pub const REF_KEY_NOISE: u32 = 64;
pub const REF_KEY_STRIDE: u32 = 128;

/// [`RefCursor::flags`] bits (keep in sync with reference.wgsl): wrist offsets or noise on.
pub const CUR_WRIST: u32 = 1;
/// Joint offsets or noise on.
pub const CUR_JOINT: u32 = 2;
/// This episode's reference is mirrored.
pub const CUR_MIRROR: u32 = 4;
/// D is applied (not the identity).
pub const CUR_TRANSFORM: u32 = 8;
/// The first segment is re-interpolated from the start wrist pose.
pub const CUR_REINTERP: u32 = 16;

/// [`RefInfo::flags`] bits: the reference has an object pose (else the config's nominal one).
pub const REF_HAS_OBJECT: u32 = 1;
/// The fingertips came from the reference file (else from forward kinematics).
pub const REF_TIPS_FROM_FILE: u32 = 2;

/// One reference of the bank (WGSL `RefInfo`, storage binding 14 `ref_info`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable, PartialEq)]
pub struct RefInfo {
    /// The reference's first object pose (frame 0's record): position xyz (m), quaternion xyzw.
    pub obj0_pos: [f32; 4],
    pub obj0_rot: [f32; 4],
    /// Bounding box (m, world, xyz) of every wrist, fingertip and object position of the reference.
    pub bbox_min: [f32; 4],
    pub bbox_max: [f32; 4],
    /// Index (in records) of the reference's frame 0 in the bank.
    pub first_frame: u32,
    /// Number of frames (≥ 1).
    pub n_frames: u32,
    /// Frames (control steps) from frame 0 to the reference's keyframe 1, rounded, ≥ 1.
    pub first_segment_steps: u32,
    /// `REF_HAS_OBJECT | REF_TIPS_FROM_FILE`.
    pub flags: u32,
}

/// Run-wide constants of the reference layer (WGSL `RefGlobals`, uniform binding 15 `rg`): the
/// bank's sizes and record offsets ([`RefBank::globals`]) and the augmentation settings
/// ([`crate::task::setup::reference_globals`]; see the module documentation).
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable, PartialEq, Default)]
pub struct RefGlobals {
    /// Number of references in the bank.
    pub n_refs: u32,
    /// Floats per frame record.
    pub stride: u32,
    /// Joints J and fingertips T of a record (the model's).
    pub n_joints: u32,
    pub n_tips: u32,
    /// Offsets (floats) of the record fields (`task::bank` module documentation).
    pub off_wrist_pos: u32,
    pub off_wrist_rot: u32,
    pub off_q: u32,
    pub off_tips: u32,
    pub off_obj_pos: u32,
    pub off_obj_rot: u32,
    pub off_grasp: u32,
    /// 1: D re-grounds the reference onto the env's object.
    pub reground: u32,
    /// 1: re-interpolate the first segment from the robot's start wrist pose.
    pub reinterp: u32,
    /// Length (env steps) of the re-interpolated segment; 0 = the reference's first segment.
    pub reinterp_steps: u32,
    pub _pad0: u32,
    pub _pad1: u32,
    /// Half-range (m) of the x and y translation of D.
    pub translate_xy: f32,
    /// Half-range (rad) of the rotation of D about the vertical axis.
    pub rotate_z: f32,
    /// Probability of mirroring an episode's reference.
    pub mirror_prob: f32,
    /// Half-range of the speed: the episode plays at 1 ± time_scale.
    pub time_scale: f32,
    /// Half-range (m) of the per-episode wrist position offset (per axis).
    pub wrist_pos_offset: f32,
    /// Half-range (rad) of each component of the per-episode wrist rotation-vector offset.
    pub wrist_rot_offset: f32,
    /// Half-range (rad) of the per-episode joint offsets.
    pub joint_offset: f32,
    /// Standard deviation (m) of the per-frame wrist position noise.
    pub wrist_pos_noise: f32,
    /// Standard deviation (rad) of the per-frame joint noise.
    pub joint_noise: f32,
    pub _pad2: [f32; 3],
}

/// One env's position in its episode's reference and the episode's augmentation (WGSL `RefCursor`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable, PartialEq, Default)]
pub struct RefCursor {
    /// D: translation (m, xyz) and rotation (quaternion xyzw); the identity unless `CUR_TRANSFORM`.
    pub d_pos: [f32; 4],
    pub d_rot: [f32; 4],
    /// The robot's wrist pose right after the reset (the re-interpolation's start).
    pub start_pos: [f32; 4],
    pub start_rot: [f32; 4],
    /// Per-episode wrist position offset (m, xyz) and rotation offset (rotation vector, rad, xyz).
    pub wrist_off_pos: [f32; 4],
    pub wrist_off_rot: [f32; 4],
    /// Index of the episode's reference in the bank.
    pub ref_id: u32,
    /// The env and episode (they key the per-frame noise).
    pub env: u32,
    pub episode: u32,
    /// `CUR_*` bits.
    pub flags: u32,
    /// Reference frames per env step (1 ± time_scale · u).
    pub speed: f32,
    /// Env steps of the re-interpolated first segment (0 when re-interpolation is off).
    pub seg_steps: u32,
    pub _pad: [u32; 2],
}

/// The augmented reference at one env step (WGSL `RefFrame`; world frame).
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable, PartialEq)]
pub struct RefFrame {
    /// Wrist position (m, xyz, w = 0) and orientation (quaternion xyzw).
    pub wrist_pos: [f32; 4],
    pub wrist_rot: [f32; 4],
    /// Object position (m, xyz, w = 0) and orientation.
    pub obj_pos: [f32; 4],
    pub obj_rot: [f32; 4],
    /// Fingertip positions (m, xyz, w = 0), model fingertip order; entries past T are 0.
    pub tips: [[f32; 4]; MAX_TIPS],
    /// Joint targets (rad), model joint order (followers included); entries past J are 0.
    pub q: [f32; MAX_JOINTS],
    /// 1 while the reference grasps the object (bank module documentation), else 0.
    pub grasp: f32,
    /// 1 when the sample is at or past the reference's last frame.
    pub ended: u32,
    pub _pad: [u32; 2],
}

impl Default for RefFrame {
    fn default() -> Self {
        Zeroable::zeroed()
    }
}

/// Everything the CPU twin reads (the shader's bindings 0, 1, 13, 14, 15).
#[derive(Clone, Copy)]
pub struct RefModel<'a> {
    pub g: &'a Globals,
    pub joints: &'a [JointDesc],
    pub rg: &'a RefGlobals,
    pub info: &'a [RefInfo],
    /// The bank's records (`ref_frames`).
    pub frames: &'a [f32],
}

impl<'a> RefModel<'a> {
    /// The view of `bank` for `model` with the constants `rg`.
    pub fn new(model: &'a SimModel, bank: &'a RefBank, rg: &'a RefGlobals) -> RefModel<'a> {
        RefModel { g: &model.globals, joints: &model.joints, rg, info: &bank.info, frames: &bank.frames }
    }
}

/// Index of the first float of frame `i` of the reference `info`.
pub fn ref_record(r: &RefModel, info: &RefInfo, i: u32) -> u32 {
    (info.first_frame + i) * r.rg.stride
}

/// Three floats of the bank from index `b`.
pub fn ref_vec3(r: &RefModel, b: u32) -> Vec3 {
    let b = b as usize;
    Vec3::new(r.frames[b], r.frames[b + 1], r.frames[b + 2])
}

/// Four floats of the bank from index `b`.
pub fn ref_vec4(r: &RefModel, b: u32) -> Vec4 {
    let b = b as usize;
    Vec4::new(r.frames[b], r.frames[b + 1], r.frames[b + 2], r.frames[b + 3])
}

/// The record at `b` as a frame, exactly as stored (`ended` = 0).
pub fn ref_read(r: &RefModel, b: u32) -> RefFrame {
    let rg = r.rg;
    let mut f = RefFrame::default();
    f.wrist_pos = put3(ref_vec3(r, b + rg.off_wrist_pos));
    f.wrist_rot = ref_vec4(r, b + rg.off_wrist_rot).to_array();
    for j in 0..rg.n_joints {
        f.q[j as usize] = r.frames[(b + rg.off_q + j) as usize];
    }
    for t in 0..rg.n_tips {
        f.tips[t as usize] = put3(ref_vec3(r, b + rg.off_tips + 3 * t));
    }
    f.obj_pos = put3(ref_vec3(r, b + rg.off_obj_pos));
    f.obj_rot = ref_vec4(r, b + rg.off_obj_rot).to_array();
    f.grasp = r.frames[(b + rg.off_grasp) as usize];
    f
}

/// A quaternion reflected across the x–z plane: (x, y, z, w) → (−x, y, −z, w).
pub fn ref_mirror_quat(q: Vec4) -> Vec4 {
    Vec4::new(-q.x, q.y, -q.z, q.w)
}

/// Shortest-arc slerp from `a` (exactly `a` at s ≤ 0), normalised; nlerp when the two are close.
pub fn ref_slerp(a: Vec4, b: Vec4, s: f32) -> Vec4 {
    if s <= 0.0 {
        return a;
    }
    let mut bb = b;
    let mut d = a.dot(b);
    if d < 0.0 {
        bb = -b;
        d = -d;
    }
    if d > 0.9995 {
        return quat_normalize(a + (bb - a) * s);
    }
    let th = d.acos();
    let sn = th.sin();
    // (sin((1 − s)θ) a + sin(sθ) b) / sin θ
    quat_normalize(a * (((1.0 - s) * th).sin() / sn) + bb * ((s * th).sin() / sn))
}

/// Frames `a` and `b` interpolated at `s` ∈ (0, 1): positions, joints and fingertips linearly,
/// rotations by slerp, the grasp flag of the nearer frame.
pub fn ref_lerp(r: &RefModel, a: &RefFrame, b: &RefFrame, s: f32) -> RefFrame {
    let lp = |x: [f32; 4], y: [f32; 4]| -> [f32; 4] {
        let p = v3(x);
        put3(p + (v3(y) - p) * s)
    };
    let mut f = RefFrame::default();
    f.wrist_pos = lp(a.wrist_pos, b.wrist_pos);
    f.wrist_rot = ref_slerp(v4(a.wrist_rot), v4(b.wrist_rot), s).to_array();
    for j in 0..r.rg.n_joints as usize {
        f.q[j] = a.q[j] + (b.q[j] - a.q[j]) * s;
    }
    for t in 0..r.rg.n_tips as usize {
        f.tips[t] = lp(a.tips[t], b.tips[t]);
    }
    f.obj_pos = lp(a.obj_pos, b.obj_pos);
    f.obj_rot = ref_slerp(v4(a.obj_rot), v4(b.obj_rot), s).to_array();
    f.grasp = if s < 0.5 { a.grasp } else { b.grasp };
    f
}

/// Uniform draw in [−1, 1) for key `k` of (env, episode).
pub fn ref_signed(r: &RefModel, env: u32, episode: u32, k: u32) -> f32 {
    2.0 * rand_uniform(r.g.seed, env.wrapping_add(r.g.env_offset), episode, PURPOSE_REF, k) - 1.0 // keyed by the global env id
}

/// Standard normal draw of noise component `comp` at env step `n` (Box–Muller: √(−2 ln u1) cos(2π u2),
/// u1 ∈ (0, 1]).
pub fn ref_gauss(r: &RefModel, c: &RefCursor, n: u32, comp: u32) -> f32 {
    let key = REF_KEY_NOISE.wrapping_add(n.wrapping_mul(REF_KEY_STRIDE)).wrapping_add(2 * comp);
    let u1 = 1.0 - rand_uniform(r.g.seed, c.env.wrapping_add(r.g.env_offset), c.episode, PURPOSE_REF, key);
    let u2 = rand_uniform(r.g.seed, c.env.wrapping_add(r.g.env_offset), c.episode, PURPOSE_REF, key.wrapping_add(1));
    (-2.0 * u1.ln()).sqrt() * (std::f32::consts::TAU * u2).cos()
}

/// The un-augmented reference at env step `n`: the frame at x = n · speed (exactly the record when x
/// is integral), holding the last frame (and `ended` = 1) from x ≥ last on.
pub fn ref_raw(r: &RefModel, c: &RefCursor, n: u32) -> RefFrame {
    let info = &r.info[c.ref_id as usize];
    let last = info.n_frames - 1;
    let x = n as f32 * c.speed;
    // the shader's shape: one place that reads the first record (its twin inlines every call)
    let ended = x >= last as f32;
    let (i0, s) = if ended {
        (last, 0.0)
    } else {
        let i0 = x.floor() as u32;
        (i0, x - i0 as f32)
    };
    let mut f = ref_read(r, ref_record(r, info, i0));
    if s != 0.0 {
        f = ref_lerp(r, &f, &ref_read(r, ref_record(r, info, i0 + 1)), s);
    }
    f.ended = u32::from(ended);
    f
}

/// Offset + noise of joint `j` at env step `n`; a mimic follower gets `mult ×` its leader's.
pub fn ref_joint_delta(r: &RefModel, c: &RefCursor, n: u32, j: u32) -> f32 {
    let jd = &r.joints[j as usize];
    let mut jj = j;
    let mut m = 1.0;
    if jd.mimic_leader != NO_JOINT {
        jj = jd.mimic_leader;
        m = jd.mimic_mult;
    }
    let mut d = 0.0;
    if r.rg.joint_offset > 0.0 {
        d += r.rg.joint_offset * ref_signed(r, c.env, c.episode, REF_KEY_JOINT + jj);
    }
    if r.rg.joint_noise > 0.0 {
        d += r.rg.joint_noise * ref_gauss(r, c, n, 3 + jj);
    }
    m * d
}

/// Retargeting-error emulation on the hand parts (wrist offsets + noise, fingertips rigidly with the
/// wrist, joint offsets + noise); the object is untouched.
pub fn ref_perturb(r: &RefModel, c: &RefCursor, f: &RefFrame, n: u32) -> RefFrame {
    let rg = r.rg;
    let mut o = *f;
    if c.flags & CUR_WRIST != 0 {
        let mut off = v3(c.wrist_off_pos);
        if rg.wrist_pos_noise > 0.0 {
            off += rg.wrist_pos_noise * Vec3::new(ref_gauss(r, c, n, 0), ref_gauss(r, c, n, 1), ref_gauss(r, c, n, 2));
        }
        let rv = v3(c.wrist_off_rot);
        let ang = rv.length();
        let mut qo = Vec4::new(0.0, 0.0, 0.0, 1.0);
        if ang > 0.0 {
            qo = quat_from_axis_angle(rv / ang, ang);
        }
        let w = v3(f.wrist_pos);
        for t in 0..rg.n_tips as usize {
            // p' = w + Δ + Q (p − w)
            o.tips[t] = put3(w + off + quat_rotate(qo, v3(f.tips[t]) - w));
        }
        o.wrist_pos = put3(w + off);
        o.wrist_rot = quat_normalize(quat_mul(qo, v4(f.wrist_rot))).to_array();
    }
    if c.flags & CUR_JOINT != 0 {
        for j in 0..rg.n_joints {
            o.q[j as usize] = f.q[j as usize] + ref_joint_delta(r, c, n, j);
        }
    }
    o
}

/// Reflection across the vertical x–z plane through the reference's first object position y0.
pub fn ref_mirror(r: &RefModel, c: &RefCursor, f: &RefFrame) -> RefFrame {
    let y0 = r.info[c.ref_id as usize].obj0_pos[1];
    let mut o = *f;
    // p.y → 2·y0 − p.y
    o.wrist_pos[1] = 2.0 * y0 - f.wrist_pos[1];
    o.wrist_rot = ref_mirror_quat(v4(f.wrist_rot)).to_array();
    for t in 0..r.rg.n_tips as usize {
        o.tips[t][1] = 2.0 * y0 - f.tips[t][1];
    }
    o.obj_pos[1] = 2.0 * y0 - f.obj_pos[1];
    o.obj_rot = ref_mirror_quat(v4(f.obj_rot)).to_array();
    o
}

/// D applied to every pose and point of the frame: p' = R_D p + t_D, q' = q_D ⊗ q.
pub fn ref_transform(r: &RefModel, c: &RefCursor, f: &RefFrame) -> RefFrame {
    let dr = v4(c.d_rot);
    let dp = v3(c.d_pos);
    let mut o = *f;
    o.wrist_pos = put3(quat_rotate(dr, v3(f.wrist_pos)) + dp);
    o.wrist_rot = quat_normalize(quat_mul(dr, v4(f.wrist_rot))).to_array();
    for t in 0..r.rg.n_tips as usize {
        o.tips[t] = put3(quat_rotate(dr, v3(f.tips[t])) + dp);
    }
    o.obj_pos = put3(quat_rotate(dr, v3(f.obj_pos)) + dp);
    o.obj_rot = quat_normalize(quat_mul(dr, v4(f.obj_rot))).to_array();
    o
}

/// The augmented reference at env step `n` without the re-interpolation: raw → perturb → mirror → D
/// (each skipped when off).
pub fn ref_augmented(r: &RefModel, c: &RefCursor, n: u32) -> RefFrame {
    let mut f = ref_raw(r, c, n);
    if c.flags & (CUR_WRIST | CUR_JOINT) != 0 {
        f = ref_perturb(r, c, &f, n);
    }
    if c.flags & CUR_MIRROR != 0 {
        f = ref_mirror(r, c, &f);
    }
    if c.flags & CUR_TRANSFORM != 0 {
        f = ref_transform(r, c, &f);
    }
    f
}

/// Starts episode `episode` of env `env` on a reference: draws the reference and the augmentation
/// (module documentation) for the state `s` right after the env's reset.
pub fn ref_begin(r: &RefModel, env: u32, episode: u32, s: &EnvState) -> RefCursor {
    let rg = r.rg;
    let mut c = RefCursor { env, episode, ..Default::default() };
    let u = rand_uniform(r.g.seed, env.wrapping_add(r.g.env_offset), episode, PURPOSE_REF, REF_KEY_ID);
    c.ref_id = ((u * rg.n_refs as f32) as u32).min(rg.n_refs - 1);
    let info = &r.info[c.ref_id as usize];
    c.speed = 1.0;
    if rg.time_scale > 0.0 {
        c.speed = 1.0 + rg.time_scale * ref_signed(r, env, episode, REF_KEY_SPEED);
    }
    if rg.mirror_prob > 0.0 && rand_uniform(r.g.seed, env.wrapping_add(r.g.env_offset), episode, PURPOSE_REF, REF_KEY_MIRROR) < rg.mirror_prob {
        c.flags |= CUR_MIRROR;
    }
    if rg.wrist_pos_offset > 0.0 {
        let h = rg.wrist_pos_offset;
        let k = REF_KEY_WRIST_POS;
        c.wrist_off_pos = [h * ref_signed(r, env, episode, k), h * ref_signed(r, env, episode, k + 1), h * ref_signed(r, env, episode, k + 2), 0.0];
    }
    if rg.wrist_rot_offset > 0.0 {
        let h = rg.wrist_rot_offset;
        let k = REF_KEY_WRIST_ROT;
        c.wrist_off_rot = [h * ref_signed(r, env, episode, k), h * ref_signed(r, env, episode, k + 1), h * ref_signed(r, env, episode, k + 2), 0.0];
    }
    if rg.wrist_pos_offset > 0.0 || rg.wrist_rot_offset > 0.0 || rg.wrist_pos_noise > 0.0 {
        c.flags |= CUR_WRIST;
    }
    if rg.joint_offset > 0.0 || rg.joint_noise > 0.0 {
        c.flags |= CUR_JOINT;
    }
    // the reference's first object pose after the mirror (which keeps its position)
    let p0 = v3(info.obj0_pos);
    let mut r0 = v4(info.obj0_rot);
    if c.flags & CUR_MIRROR != 0 {
        r0 = ref_mirror_quat(r0);
    }
    c.d_rot = [0.0, 0.0, 0.0, 1.0];
    if rg.reground != 0 {
        // D = T_env · T_ref(0)⁻¹: q_D = q_env ⊗ q_ref⁻¹, t_D = p_env − R_D p_ref
        let dr = quat_normalize(quat_mul(v4(s.obj_rot), quat_conj(r0)));
        c.d_rot = dr.to_array();
        c.d_pos = put3(v3(s.obj_pos) - quat_rotate(dr, p0));
        c.flags |= CUR_TRANSFORM;
    } else if rg.translate_xy > 0.0 || rg.rotate_z > 0.0 {
        let mut th = 0.0;
        if rg.rotate_z > 0.0 {
            th = rg.rotate_z * ref_signed(r, env, episode, REF_KEY_ROTATE);
        }
        let mut t = Vec3::ZERO;
        if rg.translate_xy > 0.0 {
            let h = rg.translate_xy;
            t = Vec3::new(h * ref_signed(r, env, episode, REF_KEY_TRANSLATE), h * ref_signed(r, env, episode, REF_KEY_TRANSLATE + 1), 0.0);
        }
        let dr = quat_from_axis_angle(Vec3::Z, th);
        // rotation about the vertical axis through (x0, y0), then the shift: t_D = c + t − R_D c
        let cxy = Vec3::new(p0.x, p0.y, 0.0);
        c.d_rot = dr.to_array();
        c.d_pos = put3(cxy + t - quat_rotate(dr, cxy));
        c.flags |= CUR_TRANSFORM;
    }
    c.start_pos = s.wrist_pos;
    c.start_rot = s.wrist_rot;
    if rg.reinterp != 0 {
        c.flags |= CUR_REINTERP;
        if rg.reinterp_steps > 0 {
            c.seg_steps = rg.reinterp_steps;
        } else {
            // round(first segment / speed), at least 1
            c.seg_steps = ((info.first_segment_steps as f32 / c.speed + 0.5).floor() as u32).max(1);
        }
    }
    c
}

/// The augmented reference at env step `step + k` (module documentation).
pub fn ref_sample(r: &RefModel, c: &RefCursor, step: u32, k: u32) -> RefFrame {
    let n = step.wrapping_add(k);
    let mut f = ref_augmented(r, c, n);
    if c.flags & CUR_REINTERP != 0 && n < c.seg_steps {
        let e = ref_augmented(r, c, c.seg_steps);
        let a = n as f32 / c.seg_steps as f32;
        let sp = v3(c.start_pos);
        // p = p_start + (p_end − p_start)·α, q = slerp(q_start, q_end, α)
        let wp = sp + (v3(e.wrist_pos) - sp) * a;
        let wr = ref_slerp(v4(c.start_rot), v4(e.wrist_rot), a);
        // fingertips carried with the wrist: p' = w' + (q' ⊗ q⁻¹)(p − w)
        let rel = quat_mul(wr, quat_conj(v4(f.wrist_rot)));
        let w = v3(f.wrist_pos);
        for t in 0..r.rg.n_tips as usize {
            f.tips[t] = put3(wp + quat_rotate(rel, v3(f.tips[t]) - w));
        }
        f.wrist_pos = put3(wp);
        f.wrist_rot = wr.to_array();
    }
    f
}

/// An object pose of the reference's records carried through the episode's augmentation, D ·
/// mirror(p, q) (the hand perturbation and the re-interpolation leave the object alone).
pub fn ref_object_augmented(r: &RefModel, c: &RefCursor, pos: Vec3, rot: Vec4) -> (Vec3, Vec4) {
    let (mut p, mut q) = (pos, rot);
    if c.flags & CUR_MIRROR != 0 {
        // p.y → 2·y0 − p.y, as ref_mirror does it
        p.y = 2.0 * r.info[c.ref_id as usize].obj0_pos[1] - p.y;
        q = ref_mirror_quat(q);
    }
    if c.flags & CUR_TRANSFORM != 0 {
        let dr = v4(c.d_rot);
        p = quat_rotate(dr, p) + v3(c.d_pos);
        q = quat_normalize(quat_mul(dr, q));
    }
    (p, q)
}

/// The object's first pose in the episode's augmented reference, D · mirror(T_obj,ref(0)) (with
/// `reground`: the env's object pose at the reset, up to rounding). Without `reground` the task
/// places the object here at the reset.
pub fn ref_object_start(r: &RefModel, c: &RefCursor) -> (Vec3, Vec4) {
    let info = &r.info[c.ref_id as usize];
    ref_object_augmented(r, c, v3(info.obj0_pos), v4(info.obj0_rot))
}

/// The object's final pose in the episode's augmented reference: the object of the last record,
/// as `ref_sample` gives it from the last frame on, without building the whole frame.
pub fn ref_object_end(r: &RefModel, c: &RefCursor) -> (Vec3, Vec4) {
    let info = &r.info[c.ref_id as usize];
    let b = ref_record(r, info, info.n_frames - 1);
    ref_object_augmented(r, c, ref_vec3(r, b + r.rg.off_obj_pos), ref_vec4(r, b + r.rg.off_obj_rot))
}
