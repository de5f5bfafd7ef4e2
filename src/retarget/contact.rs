//! The contact clean-up of a retargeted demonstration: a human hand–object estimate whose hand and
//! object do not touch (a video's hand and object come from two estimators; DexMV's disagree by
//! centimetres) made into a reference in which the robot's fingertips close on the object's
//! surface and the hand carries the object along the demonstration's object path.
//!
//! The object's path is the task (where the object goes), so it is kept; the hand is re-grounded on
//! the object (the references' `reground` augmentation does the same at every reset):
//!
//! 1. **The object's path.** While the object rests (the world frame's rest frames, up to the last
//!    within [`CARRY_START_M`] of the resting position) it stays at its resting pose (the
//!    estimate's jitter is noise); from the first frame it moves, the demonstration's path,
//!    blended from the resting pose into it over [`BLEND_S`], smoothed over ±[`SMOOTH_FRAMES`]
//!    frames and raised onto the table where it dips into it. Its rotations are followed only
//!    where the estimate's agree while the object rests ([`MAX_REST_ROTATION_SPREAD_RAD`]); else
//!    the object keeps its resting rotation and follows the demonstrated position (a relocation).
//! 2. **The grasp** ([`GraspSource`]). The human's: the retargeted hand [`GRASP_LEAD_S`] before
//!    the object moves is the start; its wrist moves and its fingers close so that each
//!    fingertip's target is [`SQUEEZE_M`] inside the object's surface, past the surface point
//!    nearest it (in rounds: the fingertip IK for those targets with the wrist fixed, then the
//!    wrist moved by the rigid motion that best carries the reached fingertips onto them; the
//!    wrist kept where no link origin or fingertip is below [`HAND_CLEARANCE_M`] over the table
//!    and no collider off the fingertips is deeper than [`PALM_DEPTH_TOL_M`] in the object). A
//!    servo whose target is inside the object presses on its surface: that is the grip. Its
//!    pre-grasp pose is [`APPROACH_M`] above or away from the object's vertical axis, whichever
//!    straight line onto the grasp overlaps the object less, the fingertips [`PRE_CLEARANCE_M`]
//!    outside their contact points; the fingers close over [`CLOSE_S`]. Or `traj synth`'s
//!    planned grasp (its hover, descent and closing, relative to its resting object).
//! 3. **The carry.** From the first frame the object moves, the wrist keeps its grasp pose
//!    relative to the object (`W(t) = O(t) · O(c)⁻¹ · W(c)`) and the fingers their posture.
//! 4. **The approach.** Until the grasp window (the pre-grasp pose) the wrist follows the
//!    demonstration, moved to end [`HOVER_M`] above the pre-grasp pose and kept no lower than
//!    that (a hand that comes in low sweeps the object over), turning into its rotation, its
//!    fingers blending from the demonstration's posture into the pre-grasp one, each frame kept
//!    off the table and raised until the hand is [`APPROACH_GAP_M`] clear of the object; then it
//!    comes straight down onto the pre-grasp pose over [`DESCENT_S`].
//!
//! A grasp the robot cannot copy from the human (the estimate's hand is elsewhere, the robot's
//! fingers are not a human's) can come from `traj synth`'s planner instead ([`GraspSource`]): the
//! demonstration then gives the object's path, the approach and the timing.

use anyhow::{Result, ensure};
use glam::{Quat, Vec3};

use crate::env::SimModel;
use crate::env::physics::{hull_project, object_inside_normal, object_project};
use crate::geom::{Pose, SHAPE_HULL};
use crate::traj::{Keyframe, Trajectory};
use crate::hand::{MAX_JOINTS, MAX_TIPS};
use crate::synth::grasp::hand_object_depths;
use crate::task::ik::{IkParams, IkScratch, ik_apply_mimic, ik_solve, ik_tip_positions};

/// How far above the table the hand's lowest link origin or fingertip is kept (m).
pub const HAND_CLEARANCE_M: f32 = 0.01;
/// How far inside the object's surface the grasp puts each fingertip's target (m): the servos
/// press the fingers onto the surface (the deeper of `traj synth`'s two squeezes).
pub const SQUEEZE_M: f32 = 0.03;
/// The human grasp is taken this long before the object first moves (s), and held from there: the
/// fingers are closed when the carry begins.
pub const GRASP_LEAD_S: f64 = 0.3;
/// The human grasp's fingers close over this long, from the pre-grasp pose (s).
pub const CLOSE_S: f64 = 0.4;
/// The object starts moving after the last frame of its rest within this distance of its resting
/// position (m): the world frame's rest frames run until it is 4 cm away, well into the motion.
pub const CARRY_START_M: f32 = 0.01;
/// The carry starts at the resting pose and blends into the demonstration's path over this long (s).
pub const BLEND_S: f64 = 0.5;
/// The object's path while it moves is averaged over ±this many frames (a video estimate jitters).
pub const SMOOTH_FRAMES: usize = 2;
/// How far from the human grasp the pre-grasp wrist is (m): above it, or away from the object's
/// vertical axis; it comes straight in from there.
pub const APPROACH_M: f32 = 0.06;
/// The fingertips' distance outside their contact points when the fingers start closing (m).
pub const PRE_CLEARANCE_M: f32 = 0.02;
/// The approach ends this far above the grasp window's first pose (m) and comes down onto it over
/// [`DESCENT_S`] (s).
pub const HOVER_M: f32 = 0.1;
pub const DESCENT_S: f64 = 0.4;
/// The gap the approach keeps from the resting object (m), and the step of the raise that keeps it.
pub const APPROACH_GAP_M: f32 = 0.005;
pub const RAISE_STEP_M: f32 = 0.005;
/// Most raises of one approach frame (0.3 m).
pub const MAX_RAISES: usize = 60;
/// Rounds of (fingertip IK, wrist move) of the grasp.
pub const GRASP_ROUNDS: usize = 30;
/// The fraction of the fitted rotation the wrist takes per round, and the most it turns (rad): the
/// grasp stays near the human's wrist orientation where a small turn suffices.
pub const ROTATION_GAIN: f32 = 0.5;
pub const MAX_TURN_RAD: f32 = 0.1;
/// The object's estimated rotations are followed only where they stay within this angle of the
/// first while it rests (rad, 20°): a nearly symmetric object's estimate flips about its axis
/// (DexMV's mustard bottle's by 50–90° between frames at rest), and a path that spins with it
/// would spin the hand that carries it.
pub const MAX_REST_ROTATION_SPREAD_RAD: f32 = 0.35;
/// Deepest a collider off the fingertips may reach into the object at the grasp (m); deeper, the
/// wrist backs away from the object.
pub const PALM_DEPTH_TOL_M: f32 = 0.01;

/// A frame of the retargeted hand: its wrist pose (world) and every joint's angle.
#[derive(Clone, Debug, PartialEq)]
pub struct HandFrame {
    pub wrist: Pose,
    pub q: Vec<f32>,
}

/// What the contact clean-up did.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct ContactReport {
    /// The first frame of the grasp window (the hand at the pre-grasp pose), and the first frame
    /// the object moves (the grasp held from there).
    pub window_from: usize,
    pub carry_from: usize,
    /// Whether the object's path turns as the demonstration's does (its rotations agreed while it
    /// rested) or keeps its resting rotation.
    pub object_rotations: bool,
    /// The cleaned path's frames whose object was raised out of the table, and the largest raise (m).
    pub object_frames_raised: usize,
    pub object_largest_raise_m: f32,
    /// How far the grasp is from the retargeted wrist [`GRASP_LEAD_S`] before the carry (m).
    pub wrist_shift_m: f32,
    /// Each fingertip's signed distance from the resting object's surface (m; negative inside):
    /// the retargeted hand's [`GRASP_LEAD_S`] before the carry, and the grasp's.
    pub tip_distance_before_m: Vec<f32>,
    pub tip_distance_after_m: Vec<f32>,
    /// The deepest collider off the fingertips inside the object at the grasp (m; ≤ 0: none).
    pub palm_depth_m: f32,
    /// The deepest any collider reaches into the resting object before the grasp window (m; ≤ 0:
    /// none).
    pub approach_depth_m: f32,
}

/// The signed distance of `p` (world) from the surface of `model`'s first object at `pose` (m,
/// negative inside), the nearest surface point and the outward normal there.
pub fn object_surface(model: &SimModel, pose: &Pose, p: Vec3) -> (f32, Vec3, Vec3) {
    let m = model.view();
    let od = &model.object_descs[0];
    let mut best = (f32::INFINITY, p, Vec3::Z);
    for pd in &model.pieces[od.first_piece as usize..(od.first_piece + od.n_pieces) as usize] {
        // the piece's frame in the world: centre p_obj + R_obj c, rotation R_obj R_piece
        let rot = pose.rot * Quat::from_array(pd.rot);
        let centre = pose.transform_point(Vec3::new(pd.pos[0], pd.pos[1], pd.pos[2]));
        let local = rot.inverse() * (p - centre);
        let size = Vec3::new(pd.size[0], pd.size[1], pd.size[2]);
        let (d, surface, normal) = if pd.shape == SHAPE_HULL {
            let (closest, inside) = hull_project(&m, pd, 1.0, local);
            if inside {
                // the nearest face plane: the largest n·p − d (≤ 0 inside)
                let (base, nf) = (pd.hull_first as usize, pd.hull_faces as usize);
                let (d, n) = (0..nf).map(|f| m.hulls[base + f]).map(|pl| (Vec3::new(pl[0], pl[1], pl[2]).dot(local) - pl[3], Vec3::new(pl[0], pl[1], pl[2]))).fold((f32::NEG_INFINITY, Vec3::Z), |a, b| if b.0 > a.0 { b } else { a });
                (d, local - n * d, n)
            } else {
                let l = (local - closest).length();
                (l, closest, (local - closest) / l.max(1e-9))
            }
        } else {
            let (closest, inside) = object_project(pd.shape, size, local);
            if inside {
                let (n, depth) = object_inside_normal(pd.shape, size, local);
                (-depth, local + n * depth, n)
            } else {
                let l = (local - closest).length();
                (l, closest, (local - closest) / l.max(1e-9))
            }
        };
        if d < best.0 {
            best = (d, centre + rot * surface, (rot * normal).normalize_or(Vec3::Z));
        }
    }
    best
}

/// The height of the hand's lowest link origin or fingertip (world z) at `wrist` and `q`.
pub fn hand_lowest_z(model: &SimModel, wrist: &Pose, q: &[f32]) -> f32 {
    let links = model.hand.forward_kinematics(q);
    let tips = model.hand.fingertip_positions(&links);
    links.iter().map(|l| l.pos).chain(tips).map(|p| wrist.transform_point(p).z).fold(f32::INFINITY, f32::min)
}

/// The hand's fingertips (world) at `wrist` and `q`.
pub fn tips_world(model: &SimModel, wrist: &Pose, q: &[f32]) -> Vec<Vec3> {
    model.hand.fingertip_positions(&model.hand.forward_kinematics(q)).into_iter().map(|p| wrist.transform_point(p)).collect()
}

/// The squeezing grasp from the retargeted hand `start` with the object at `object`: the wrist and
/// every joint (step 2 of the module documentation).
fn solve_grasp(model: &SimModel, start: &HandFrame, object: &Pose) -> HandFrame {
    let m = model.view();
    let n_tips = model.hand.fingertips.len();
    let n = model.hand.joints.len();
    let mut q = [0.0f32; MAX_JOINTS];
    q[..n].copy_from_slice(&start.q[..n]);
    let mut wrist = start.wrist;
    let prm = IkParams::default();
    let mask = (1u32 << n_tips) - 1;
    let mut s = IkScratch::default();
    for _ in 0..GRASP_ROUNDS {
        // each fingertip's target: SQUEEZE_M inside the surface point nearest it
        let tips = tips_world(model, &wrist, &q[..n]);
        let mut targets = [Vec3::ZERO; MAX_TIPS];
        for (t, &tip) in tips.iter().enumerate() {
            let (_, surface, normal) = object_surface(model, object, tip);
            targets[t] = wrist.inverse().transform_point(surface - normal * SQUEEZE_M);
        }
        q = ik_solve(&m, &q, &targets, mask, &prm);
        ik_apply_mimic(&m, &mut q);
        // the wrist moves by the rigid motion that best carries the reached fingertips onto their
        // targets, linearised: the mean error as the translation, and the rotation about the tips'
        // centroid c that least-squares fits the rest, ω = Σ rᵢ × eᵢ / Σ |rᵢ|² (rᵢ = xᵢ − c;
        // exact for tips spread alike in every direction), damped by ROTATION_GAIN
        let reached: Vec<Vec3> = ik_tip_positions(&m, &q, &mut s)[..n_tips].iter().map(|&x| wrist.transform_point(x)).collect();
        let errors: Vec<Vec3> = (0..n_tips).map(|t| wrist.transform_point(targets[t]) - reached[t]).collect();
        let mean = errors.iter().sum::<Vec3>() / n_tips as f32;
        let centroid = reached.iter().sum::<Vec3>() / n_tips as f32;
        let (mut torque, mut spread) = (Vec3::ZERO, 0.0f32);
        for (x, e) in reached.iter().zip(&errors) {
            let r = *x - centroid;
            torque += r.cross(*e - mean);
            spread += r.length_squared();
        }
        let omega = torque / spread.max(1e-9) * ROTATION_GAIN;
        let turn = Quat::from_scaled_axis(omega.clamp_length_max(MAX_TURN_RAD));
        wrist = Pose::new(centroid + mean + turn * (wrist.pos - centroid), (turn * wrist.rot).normalize());
        // back away from the object while the palm or a finger's inner link is deep in it
        let (_, palm) = hand_object_depths(model, &wrist, &q[..n], object);
        if palm > PALM_DEPTH_TOL_M {
            let mut away = wrist.pos - object.pos;
            away.z = 0.0;
            wrist.pos += away.normalize_or(Vec3::X) * (palm - PALM_DEPTH_TOL_M);
        }
        // and above the table
        let lowest = hand_lowest_z(model, &wrist, &q[..n]);
        if lowest < HAND_CLEARANCE_M {
            wrist.pos.z += HAND_CLEARANCE_M - lowest;
        }
    }
    HandFrame { wrist, q: q[..n].to_vec() }
}

/// Raises every pose of `objects` whose shape (points of its model frame) dips below the table
/// (z = 0) onto it; returns how many were raised and the largest raise (m).
pub fn raise_onto_table(objects: &mut [Pose], shape: &[Vec3]) -> (usize, f32) {
    let (mut frames, mut most) = (0, 0.0f32);
    for object in objects.iter_mut() {
        let bottom = shape.iter().map(|v| object.transform_point(*v).z).fold(f32::INFINITY, f32::min);
        if bottom < 0.0 {
            object.pos.z -= bottom;
            frames += 1;
            most = most.max(-bottom);
        }
    }
    (frames, most)
}

/// The fingers opened from the grasp: each fingertip [`PRE_CLEARANCE_M`] outside the surface point
/// nearest its grasp position, the wrist where the grasp has it.
fn open_fingers(model: &SimModel, grasp: &HandFrame, object: &Pose) -> Vec<f32> {
    let m = model.view();
    let n = model.hand.joints.len();
    let mut q = [0.0f32; MAX_JOINTS];
    q[..n].copy_from_slice(&grasp.q);
    let mut targets = [Vec3::ZERO; MAX_TIPS];
    for (t, tip) in tips_world(model, &grasp.wrist, &grasp.q).into_iter().enumerate() {
        let (_, surface, normal) = object_surface(model, object, tip);
        targets[t] = grasp.wrist.inverse().transform_point(surface + normal * PRE_CLEARANCE_M);
    }
    let mut q = ik_solve(&m, &q, &targets, (1u32 << model.hand.fingertips.len()) - 1, &IkParams::default());
    ik_apply_mimic(&m, &mut q);
    q[..n].to_vec()
}

/// The object's poses, frame by frame (step 1), whether they follow the estimate's rotations, and
/// the first frame the object moves; `blend`: the frames over which the carry blends from the
/// resting pose into the demonstration's path.
fn clean_object_path(objects: &[Pose], rest_frames: usize, blend: usize) -> (Vec<Pose>, bool, usize) {
    let rest_frames = rest_frames.clamp(1, objects.len());
    // the estimate's rotations are trusted where they agree while the object rests
    let spread = objects[..rest_frames].iter().map(|o| o.rot.angle_between(objects[0].rot)).fold(0.0f32, f32::max);
    let rotations = spread <= MAX_REST_ROTATION_SPREAD_RAD;
    // the resting pose: the median position over the rest frames, the first frame's rotation
    let median = |axis: usize| {
        let mut v: Vec<f32> = objects[..rest_frames].iter().map(|p| p.pos[axis]).collect();
        v.sort_by(f32::total_cmp);
        v[v.len() / 2]
    };
    let rest = Pose::new(Vec3::new(median(0), median(1), median(2)), objects[0].rot);
    // the carry starts after the last rest frame within CARRY_START_M of the resting position (the
    // rest frames run until the object is REST_RADIUS_M away, well into its motion)
    let carry_from = (0..rest_frames).rev().find(|&f| (objects[f].pos - rest.pos).length() <= CARRY_START_M).map_or(rest_frames, |f| f + 1).min(objects.len());
    let mut out = vec![rest; objects.len()];
    if carry_from < objects.len() {
        let first = objects[carry_from];
        // the carry starts at the resting pose and blends into the demonstration's own path over
        // `blend` frames: p(t) = p_d(t) + w (p_rest − p_d(c)), R(t) = slerp(I, R_rest R_d(c)⁻¹, w) R_d(t),
        // w = 1 − t / blend (≥ 0), so that it ends where the demonstration's does
        let turn = (rest.rot * first.rot.inverse()).normalize();
        let blended: Vec<Pose> = objects[carry_from..]
            .iter()
            .enumerate()
            .map(|(i, o)| {
                let w = (1.0 - i as f32 / blend.max(1) as f32).max(0.0);
                let rot = if rotations { (Quat::IDENTITY.slerp(turn, w) * o.rot).normalize() } else { rest.rot };
                Pose::new(o.pos + (rest.pos - first.pos) * w, rot)
            })
            .collect();
        let n = blended.len();
        for (i, slot) in out[carry_from..].iter_mut().enumerate() {
            // the mean over ±h frames, h = SMOOTH_FRAMES or fewer near the carry's ends (a window
            // centred on the frame: the ends stay where they are); rotations as the normalised sum
            // of sign-aligned quaternions
            let h = SMOOTH_FRAMES.min(i).min(n - 1 - i);
            let window = &blended[i - h..=i + h];
            let pos = window.iter().map(|p| p.pos).sum::<Vec3>() / window.len() as f32;
            let q0 = blended[i].rot;
            let rot = window.iter().map(|p| if p.rot.dot(q0) < 0.0 { -p.rot } else { p.rot }).fold(Quat::from_xyzw(0.0, 0.0, 0.0, 0.0), |a, b| a + b).normalize();
            *slot = Pose::new(pos, rot);
        }
    }
    (out, rotations, carry_from)
}

/// Where the grasp comes from (`traj retarget --contacts`).
#[derive(Clone, Debug)]
pub enum GraspSource {
    /// The retargeted hand at the grasp frame, re-grounded on the object (step 2).
    Human,
    /// `traj synth`'s planned grasp of the config's object (checked in simulation there): its
    /// reference, whose object rests at the config's pose and whose wrist is placed against it.
    Planned(Trajectory),
}

/// A grasp as the clean-up plays it: keyframes of the wrist relative to the object (the object
/// field unused) and the joints, from the window's start (t = 0, the pre-grasp: the approach ends
/// there) to the carry's start (the last keyframe: the grasp held through the carry).
fn human_script(model: &SimModel, start: &HandFrame, object: &Pose, lead_s: f64, report: &mut ContactReport) -> Trajectory {
    let grasp = solve_grasp(model, start, object);
    let mut away = grasp.wrist.pos - object.pos;
    away.z = 0.0;
    let away = away.normalize_or(Vec3::X);
    let q_pre = open_fingers(model, &grasp, object);
    // the closing window's hand at s ∈ [0, 1] from a pre-grasp `from`, and the deepest overlap
    // with the object along it: the straight line from above or from the side, whichever is clearer
    let window = |from: Vec3, s: f32| HandFrame { wrist: Pose::new(from.lerp(grasp.wrist.pos, s), grasp.wrist.rot), q: q_pre.iter().zip(&grasp.q).map(|(o, g)| o + s * (g - o)).collect() };
    let depth_along = |from: Vec3| (0..=8).map(|k| window(from, k as f32 / 8.0)).map(|h| hand_object_depths(model, &h.wrist, &h.q, object).0).fold(f32::NEG_INFINITY, f32::max);
    let (from_above, from_side) = (grasp.wrist.pos + Vec3::Z * APPROACH_M, grasp.wrist.pos + away * APPROACH_M);
    let pre = if depth_along(from_above) <= depth_along(from_side) { from_above } else { from_side };
    report.wrist_shift_m = (grasp.wrist.pos - start.wrist.pos).length();
    report.palm_depth_m = hand_object_depths(model, &grasp.wrist, &grasp.q, object).1;
    let rel = |w: Pose| object.inverse().mul(&w);
    let key = |t: f64, w: Pose, q: &[f32]| Keyframe { t, wrist: rel(w), joints: q.to_vec(), fingertips: None, object: None };
    let frames = vec![key(0.0, Pose::new(pre, grasp.wrist.rot), &q_pre), key(CLOSE_S, grasp.wrist, &grasp.q), key(CLOSE_S + lead_s, grasp.wrist, &grasp.q)];
    Trajectory { frames, ..Default::default() }
}

/// `traj synth`'s reference `synth` as a grasp script: its keyframes from the first after its start
/// (the hover above the grasp) to the last before the object rises, relative to its resting object.
fn planned_script(synth: &Trajectory) -> Result<Trajectory> {
    let rest = synth.frames.first().and_then(|f| f.object).ok_or_else(|| anyhow::anyhow!("the planned grasp's reference has no object"))?;
    let lift_from = synth.frames.iter().position(|f| f.object.is_some_and(|o| (o.pos - rest.pos).length() > 1e-6)).unwrap_or(synth.frames.len());
    ensure!(lift_from >= 3, "the planned grasp's reference lifts the object at keyframe {lift_from}; expected an approach and a grasp first");
    let t0 = synth.frames[1].t;
    let frames = synth.frames[1..lift_from].iter().map(|f| Keyframe { t: f.t - t0, wrist: rest.inverse().mul(&f.wrist), joints: f.joints.clone(), fingertips: None, object: None }).collect();
    Ok(Trajectory { frames, ..Default::default() })
}

/// The contact clean-up (module documentation) of the retargeted `hands` and the demonstration's
/// `objects` (world), whose object rests for its first `rest_frames` frames, at `fps`, with the
/// grasp from `source`.
pub fn contact_cleanup(model: &SimModel, hands: &mut [HandFrame], objects: &mut [Pose], rest_frames: usize, fps: f64, source: &GraspSource) -> Result<ContactReport> {
    ensure!(hands.len() == objects.len() && !hands.is_empty(), "contact clean-up: {} hand frames and {} object poses", hands.len(), objects.len());
    ensure!(!model.object_descs.is_empty(), "contact clean-up: the config has no object");
    let frames = hands.len();
    let (cleaned, rotations, carry_from) = clean_object_path(objects, rest_frames, (BLEND_S * fps).round() as usize);
    objects.copy_from_slice(&cleaned);
    let (raised_frames, raised_m) = raise_onto_table(objects, &model.objects[0].collision_points());
    let carry_from = carry_from.min(frames - 1);
    let rest = objects[carry_from];
    let lead = (GRASP_LEAD_S * fps).round() as usize;
    let human_grasp = carry_from.saturating_sub(lead);
    let mut report = ContactReport { carry_from, object_rotations: rotations, object_frames_raised: raised_frames, object_largest_raise_m: raised_m, approach_depth_m: -1.0, ..Default::default() };
    let script = match source {
        GraspSource::Human => human_script(model, &hands[human_grasp].clone(), &rest, lead as f64 / fps, &mut report),
        GraspSource::Planned(synth) => {
            // the plan is for the object standing as the config places it (its +z up)
            let up = rest.rot * Vec3::Z;
            ensure!(up.z > 0.95, "the planned grasp is for the object resting as the config places it (its +z up); this demonstration's rests with its +z at {:.0}° from up: use --contacts reground, or --object-up +z if that is how it stands", up.z.clamp(-1.0, 1.0).acos().to_degrees());
            planned_script(synth)?
        }
    };
    let window_s = script.duration();
    // the first frame of the grasp window: window_s before the carry (0 where the rest is shorter)
    let window_from = (0..=carry_from).find(|&f| f as f64 / fps >= carry_from as f64 / fps - window_s - 1e-9).unwrap_or(carry_from);
    report.window_from = window_from;
    let held = script.frames.last().expect("a script has keyframes").clone();
    report.tip_distance_before_m = tips_world(model, &hands[human_grasp].wrist, &hands[human_grasp].q).into_iter().map(|t| object_surface(model, &rest, t).0).collect();
    let grasp_wrist = rest.mul(&held.wrist);
    report.tip_distance_after_m = tips_world(model, &grasp_wrist, &held.joints).into_iter().map(|t| object_surface(model, &rest, t).0).collect();
    if let GraspSource::Planned(_) = source {
        report.wrist_shift_m = (grasp_wrist.pos - hands[human_grasp].wrist.pos).length();
        report.palm_depth_m = hand_object_depths(model, &grasp_wrist, &held.joints, &rest).1;
    }
    // the carry: the grasp held relative to the object
    for (h, o) in hands[carry_from..].iter_mut().zip(&objects[carry_from..]) {
        *h = HandFrame { wrist: o.mul(&held.wrist), q: held.joints.clone() };
    }
    // the grasp window: the script against the resting object
    let window_t0 = carry_from as f64 / fps - window_s;
    for (f, h) in hands.iter_mut().enumerate().take(carry_from).skip(window_from) {
        let k = script.sample(f as f64 / fps - window_t0);
        *h = HandFrame { wrist: rest.mul(&k.wrist), q: k.joints };
    }
    // the approach: the demonstration's wrist path moved to end HOVER_M above the window's first
    // pose, turning into its rotation and its fingers blending into its posture, kept off the
    // table and raised off the resting object while it touches it; then straight down onto the
    // window's first pose over DESCENT_S
    let first = &script.frames[0];
    let pre = rest.mul(&first.wrist);
    let hover = Pose::new(pre.pos + Vec3::Z * HOVER_M, pre.rot);
    let descent_from = window_from.saturating_sub(((DESCENT_S * fps).round() as usize).max(1));
    let human_at_descent = hands[descent_from].wrist;
    let shift = hover.pos - human_at_descent.pos;
    for (f, h) in hands[..window_from].iter_mut().enumerate() {
        if f >= descent_from {
            let s = (f - descent_from) as f32 / (window_from - descent_from) as f32;
            *h = HandFrame { wrist: Pose::new(hover.pos.lerp(pre.pos, s), pre.rot), q: first.joints.clone() };
            continue;
        }
        let s = f as f32 / descent_from as f32;
        h.wrist = Pose::new(h.wrist.pos + shift, h.wrist.rot.slerp(pre.rot, s));
        h.wrist.pos.z = h.wrist.pos.z.max(hover.pos.z); // no lower than the hover until the descent
        h.q = h.q.iter().zip(&first.joints).map(|(d, p)| d + s * (p - d)).collect(); // (1 − s) q_demo + s q_pre
        let lowest = hand_lowest_z(model, &h.wrist, &h.q);
        if lowest < HAND_CLEARANCE_M {
            h.wrist.pos.z += HAND_CLEARANCE_M - lowest;
        }
        for _ in 0..MAX_RAISES {
            if hand_object_depths(model, &h.wrist, &h.q, &objects[f]).0 <= -APPROACH_GAP_M {
                break;
            }
            h.wrist.pos.z += RAISE_STEP_M;
        }
    }
    for (h, o) in hands[..window_from].iter().zip(&objects[..window_from]) {
        report.approach_depth_m = report.approach_depth_m.max(hand_object_depths(model, &h.wrist, &h.q, o).0);
    }
    Ok(report)
}
