//! The enveloping (palm) grasp of `dextrain traj synth`: the palm flat on a side face of the object
//! and the fingers closed around it, so that the arm pushes the palm into the object and the fingers
//! pull it back. A fingertip grasp squeezes with what its weakest side (the thumb) pushes; an
//! enveloping grasp squeezes with what the fingers pull and the arm pushes, which is what a heavy,
//! tall object (the 1.13 kg YCB bleach cleanser in dexhand16) needs. `traj synth` tries it after
//! every fingertip variant has failed in simulation (or first, with `--grasp envelope`).
//!
//! The plan, for the config's hand and first object, from the hand's own kinematics:
//! 1. **The hand's axes** (in the wrist frame, open posture: every joint at its default): the
//!    flexing joints, those whose turn toward the upper limit moves their fingertips mostly
//!    (`FLEX_FRACTION`) along the fingertips' summed motion when every joint turns, each with the
//!    sign that curls; the palm normal `p`, the flexing joints' summed fingertip motion (abduction's
//!    sideways motion left out); the fingers' direction `f`, from the palm-like links' colliders'
//!    centre to the fingertips' centroid, made perpendicular to `p`; the wrap axis `a = p × f`,
//!    about which the fingers curl.
//! 2. **The face and the wrist's orientation.** The palm goes on a side face of the box around the
//!    object's pieces (the variant picks the face across the thinner or the wider side, so the
//!    fingers wrap the other way round); the wrist turns so that `p` points into that face (−n)
//!    and `a` is vertical: the fingers curl in the table's plane, around the object, as a hand
//!    around a bottle.
//! 3. **The wrist's position**: the palm-like colliders' centre on the face's centre line at the
//!    variant's height about the object's centre of mass (raised if the hand would touch the
//!    table), the palm's surface (its colliders' support along `p`) on the object's own surface
//!    (the first piece met inward from the box's face), then `press` further in, so that the arm's
//!    PD pushes the palm into the object.
//! 4. **The closing ("close until contact", as GraspIt's auto-grasp)**: with the palm just touching,
//!    each actuated joint that curls its fingertips toward the palm (its fingertips' motion mostly
//!    along `p`), proximal first, closes toward its limit in steps of `CLOSE_STEP_RAD` until a
//!    collider of a link it moves comes within `TOUCH_M` of the object; the joints beyond it stay
//!    open while it closes. The closing keyframes close one level of the chains at a time (every
//!    first flexing joint, then every second, …), so the interpolated motion does not sweep a
//!    finger through the object; the squeeze closes each flexing joint `SQUEEZE_RAD` further,
//!    past the contact, so the servos pull at their effort limits.
//! 5. **The approach**: from the initial pose, up and out to `STANDOFF_M` outside the face above the
//!    object's top (the hand turning on the way), down to the grasp height, in along −n onto the
//!    grasp pose with the hand open, then the closing.

use anyhow::{Result, bail};
use glam::{Mat3, Quat, Vec3};

use super::grasp::{nominal_object, open_posture, palm_links, surface_point};
use crate::env::physics::{CONTACT_MARGIN, Scratch, collide_hand_object, hand_kinematics};
use crate::env::SimModel;
use crate::geom::Pose;
use crate::hand::{ColliderShape, HandModel};

/// Joint step (rad) of the closing until contact.
pub const CLOSE_STEP_RAD: f32 = 0.01;
/// A finger's collider this close (m) to the object stops its joint's closing.
pub const TOUCH_M: f32 = 0.001;
/// How far past the contact posture (rad) each flexing joint's squeezing target is.
pub const SQUEEZE_RAD: f32 = 0.4;
/// Distance (m) outside the face from which the open hand moves in onto the grasp pose.
pub const STANDOFF_M: f32 = 0.05;
/// Clearance (m) of the hand above the object's top while it moves out and turns, and above the
/// table at the grasp.
pub const CLEARANCE_M: f32 = 0.02;
/// A joint curls its fingertips toward the palm when their motion along `p` is at least this
/// fraction of their whole motion.
pub const FLEX_FRACTION: f32 = 0.5;

/// Which face of the box around the object the palm goes on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PalmFace {
    /// The face across the object's thinner side: the fingers wrap around its shorter depth.
    Wide,
    /// The face across the wider side: the fingers wrap around the longer depth.
    Narrow,
}

/// The choices an enveloping grasp is made with; `traj synth` tries [`ENVELOPE_VARIANTS`] in order.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EnvelopeVariant {
    /// The face the palm goes on.
    pub face: PalmFace,
    /// Height of the palm's centre above the object's centre of mass, as a fraction of the object's
    /// half height.
    pub height: f32,
    /// How far (m) the wrist's target is pressed past the palm's touching the object.
    pub press: f32,
    /// Which way up the wrap axis goes (+1: `a` up, −1: down).
    pub up: f32,
}

/// The variants `traj synth` tries in order: the palm on the wide face, then the narrow one; at the
/// centre of mass's height, then above it; pressed 3 mm, then 8 mm; the wrap axis up, then down.
pub const ENVELOPE_VARIANTS: [EnvelopeVariant; 16] = {
    const FACE: [PalmFace; 2] = [PalmFace::Wide, PalmFace::Narrow];
    const HEIGHT: [f32; 2] = [0.0, 0.3];
    const PRESS: [f32; 2] = [0.003, 0.008];
    const UP: [f32; 2] = [1.0, -1.0];
    let mut v = [EnvelopeVariant { face: PalmFace::Wide, height: 0.0, press: 0.003, up: 1.0 }; 16];
    let mut i = 0;
    while i < 16 {
        v[i] = EnvelopeVariant { up: UP[i % 2], press: PRESS[(i / 2) % 2], height: HEIGHT[(i / 4) % 2], face: FACE[i / 8] };
        i += 1;
    }
    v
};

/// A planned enveloping grasp.
#[derive(Clone, Debug)]
pub struct EnvelopePlan {
    /// The wrist's target at the grasp (the palm `press` into the object).
    pub wrist: Pose,
    /// The approach's waypoints after the initial pose, hand open: out and above the object, then
    /// beside the face at the grasp height, `STANDOFF_M` out.
    pub approach: Vec<Pose>,
    /// The closing keyframes: one level of the fingers' chains closed at a time, then the squeeze.
    pub closing: Vec<Vec<f32>>,
    /// The face's outward normal (world, horizontal).
    pub normal: Vec3,
    /// Joints closed until contact (the flexing leaders).
    pub flexing: usize,
    /// How many of them stopped on the object (the rest reached their limits).
    pub touching: usize,
}

/// The hand's axes in the wrist frame (module documentation, step 1): the palm normal `p`, the
/// fingers' direction `f`, the wrap axis `a`, the palm-like colliders' centre, and per joint the
/// sign of its motion that curls its fingertips toward the palm (0: not a flexing leader).
struct HandAxes {
    p: Vec3,
    f: Vec3,
    a: Vec3,
    palm_centre: Vec3,
    flex_sign: Vec<f32>,
}

/// Joint step (rad) of the finite differences that find the hand's axes.
const AXES_DQ: f32 = 1e-2;

fn hand_axes(model: &SimModel, open: &[f32]) -> Result<HandAxes> {
    let hand = &model.hand;
    let links = hand.forward_kinematics(open);
    let tips = hand.fingertip_positions(&links);
    let bounded = |j: usize| {
        let jd = &model.joints[j];
        hand.joints[j].mimic.is_none() && jd.lower > -1e29 && jd.upper < 1e29 && jd.upper - jd.lower > 1e-3
    };
    // each leader's fingertip motion when it alone turns by AXES_DQ toward its upper limit
    let motion: Vec<Vec<Vec3>> = (0..model.joints.len())
        .map(|j| {
            if !bounded(j) {
                return vec![Vec3::ZERO; tips.len()];
            }
            let mut q = open.to_vec();
            q[j] += AXES_DQ;
            let moved = hand.fingertip_positions(&hand.forward_kinematics(&hand.with_mimic(q)));
            moved.iter().zip(&tips).map(|(b, a)| *b - *a).collect()
        })
        .collect();
    // a first palm normal from every joint's motion, then the flexing joints (their motion mostly
    // along it), then the palm normal from those alone (abduction's sideways motion left out)
    let all: Vec3 = motion.iter().flatten().sum();
    if all.length() < 1e-6 {
        bail!("{}: flexing every joint does not move the fingertips; an enveloping grasp needs fingers that curl", hand.source.display());
    }
    let p0 = all.normalize();
    let flex_sign: Vec<f32> = motion
        .iter()
        .map(|m| {
            let along: f32 = m.iter().map(|v| v.dot(p0)).sum();
            let whole: f32 = m.iter().map(|v| v.length()).sum();
            if whole > 1e-7 && along.abs() >= FLEX_FRACTION * whole { along.signum() } else { 0.0 }
        })
        .collect();
    let flexing: Vec3 = motion.iter().zip(&flex_sign).map(|(m, s)| m.iter().sum::<Vec3>() * *s).sum();
    if flexing.length() < 1e-6 {
        bail!("{}: no joint curls the fingertips toward the palm; an enveloping grasp needs fingers that curl", hand.source.display());
    }
    let p = flexing.normalize();
    let palm = palm_links(hand);
    let palm_cols: Vec<Vec3> = hand.colliders.iter().filter(|c| palm[c.link]).map(|c| links[c.link].transform_point(c.pose.pos)).collect();
    let palm_centre = if palm_cols.is_empty() { Vec3::ZERO } else { palm_cols.iter().sum::<Vec3>() / palm_cols.len() as f32 };
    let tip_centre = tips.iter().sum::<Vec3>() / tips.len() as f32;
    let d = tip_centre - palm_centre;
    let mut f = d - p * d.dot(p);
    if f.length() < 1e-4 {
        // fingertips all round the palm (no one direction): any direction perpendicular to p
        f = p.any_orthonormal_vector();
    }
    let f = f.normalize();
    Ok(HandAxes { p, f, a: p.cross(f).normalize(), palm_centre, flex_sign })
}

/// Support (m) of a collider along the unit direction `u` (in the collider's frame's parent, the
/// collider at `pose`): max over its points of x · u.
fn collider_support(shape: &ColliderShape, pose: &Pose, u: Vec3) -> f32 {
    pose.pos.dot(u)
        + match *shape {
            ColliderShape::Sphere { radius } => radius,
            ColliderShape::Capsule { radius, half_length } => (pose.rot * Vec3::Z).dot(u).abs() * half_length + radius,
            ColliderShape::Box { half_extents: h } => {
                // Σ_k |u · e_k| h_k
                let ub = pose.rot.inverse() * u;
                ub.x.abs() * h.x + ub.y.abs() * h.y + ub.z.abs() * h.z
            }
        }
}

/// How far (m) the hand's colliders reach along the world direction `u` from the wrist, for the
/// wrist orientation `rot` and joints `q`, over the colliders `which` selects.
fn hand_reach(hand: &HandModel, rot: Quat, q: &[f32], u: Vec3, which: impl Fn(usize) -> bool) -> f32 {
    let links = hand.forward_kinematics(q);
    hand.colliders
        .iter()
        .filter(|c| which(c.link))
        .map(|c| {
            let pose = Pose::new(rot * links[c.link].transform_point(c.pose.pos), rot * links[c.link].rot * c.pose.rot);
            collider_support(&c.shape, &pose, u)
        })
        .fold(f32::NEG_INFINITY, f32::max)
}

/// The deepest overlap (m) with the object at its nominal place of the hand's colliders on links
/// that `which` selects, the wrist at `wrist`, joints `q` (followers included).
fn depth_of(model: &SimModel, wrist: &Pose, q: &[f32], which: &[bool]) -> f32 {
    let m = model.view();
    let (p, mut st) = nominal_object(model);
    st.wrist_pos = [wrist.pos.x, wrist.pos.y, wrist.pos.z, 0.0];
    st.wrist_rot = wrist.rot.to_array();
    st.q[..q.len()].copy_from_slice(q);
    let mut s = Scratch::default();
    hand_kinematics(&st, &m, &mut s);
    (0..model.colliders.len()).filter(|&ci| which[model.hand.colliders[ci].link]).map(|ci| collide_hand_object(&st, &p, &m, &s, ci, CONTACT_MARGIN).depth).fold(-1.0, f32::max)
}

/// Plans the enveloping grasp of the config's first object (module documentation).
pub fn plan_envelope(model: &SimModel, variant: &EnvelopeVariant) -> Result<EnvelopePlan> {
    let hand = &model.hand;
    let g = &model.globals;
    let open = open_posture(model);
    let axes = hand_axes(model, &open)?;

    // 2. the face: the box around the pieces, in the object's frame turned by its yaw
    let o = &model.objects[0];
    let (lo, hi) = o.bounding_box();
    let half = (hi - lo) * 0.5;
    let yaw = Quat::from_rotation_z(g.obj_init[2]);
    let origin = Vec3::new(g.obj_init[0], g.obj_init[1], g.obj_init[3]);
    let centre = origin + yaw * ((lo + hi) * 0.5);
    let com = origin + yaw * o.com;
    // the palm on the face across the thinner side (Wide) has its normal along the shorter axis
    let x_thinner = half.x <= half.y;
    let along_x = match variant.face {
        PalmFace::Wide => x_thinner,
        PalmFace::Narrow => !x_thinner,
    };
    let (n_local, half_n) = if along_x { (Vec3::X, half.x) } else { (Vec3::Y, half.y) };
    let n = yaw * n_local;
    // the wrist's orientation: p → −n, a → up·Z, f → a × p ↦ (up·Z) × (−n)
    let world = Mat3::from_cols((variant.up * Vec3::Z).cross(-n), variant.up * Vec3::Z, -n);
    let local = Mat3::from_cols(axes.f, axes.a, axes.p);
    let rot = Quat::from_mat3(&(world * local.transpose())).normalize();

    // 3. the height: about the centre of mass, the hand clear of the table
    let all = |_: usize| true;
    let below = hand_reach(hand, rot, &open, -Vec3::Z, all); // lowest collider point: wrist z − below
    let palm_c = rot * axes.palm_centre;
    let mut z = com.z + variant.height * half.z;
    // the palm centre at z puts the wrist at z − palm_c.z, its lowest point at that − below
    z = z.max(CLEARANCE_M + below + palm_c.z);
    let top = centre.z + half.z;
    let lowest = z - palm_c.z - below;
    if lowest + CLEARANCE_M > top {
        bail!(
            "the object is too low for an enveloping grasp: turned on its side, the hand reaches down to {:.0} mm above the table, less than {:.0} mm below the object's top at {:.0} mm",
            lowest * 1e3,
            CLEARANCE_M * 1e3,
            top * 1e3
        );
    }
    // the palm's surface on the object's surface, on the face's centre line
    let palm = palm_links(hand);
    let palm_surface = hand_reach(hand, rot, &open, -n, |l| palm[l]); // along −n from the wrist
    let on_box = Vec3::new(centre.x, centre.y, z) + n * half_n;
    let face_point = surface_point(model, on_box, -n, 2.0 * half_n);
    // the wrist where the palm's surface touches the face point, the palm's centre on the centre line
    let lateral = palm_c - n * palm_c.dot(n); // the palm centre's offset across the face (t and z)
    let touching = Pose::new(face_point + n * palm_surface - lateral, rot);

    // 4. the closing until contact, with the palm just touching
    let nj = model.joints.len();
    let flex_sign = &axes.flex_sign;
    // the links each joint moves: its child and the child's descendants, and those of its followers
    let moved_by = |j: usize| -> Vec<bool> {
        (0..hand.links.len())
            .map(|l| {
                hand.joints.iter().enumerate().any(|(k, jt)| (k == j || jt.mimic.is_some_and(|m| m.leader == j)) && hand.is_ancestor_or_same(k + 1, l))
            })
            .collect()
    };
    // the level of a flexing joint: how many flexing joints lie before it on its chain
    let level = |j: usize| -> usize { (0..j).filter(|&k| flex_sign[k] != 0.0 && hand.is_ancestor_or_same(k + 1, j + 1)).count() };
    let levels = (0..nj).filter(|&j| flex_sign[j] != 0.0).map(level).max().map_or(0, |l| l + 1);
    let mut q = open.clone();
    let mut closing = Vec::new();
    let (mut flexing, mut touching_joints) = (0, 0);
    for lv in 0..levels {
        for j in (0..nj).filter(|&j| flex_sign[j] != 0.0 && level(j) == lv) {
            flexing += 1;
            let which = moved_by(j);
            let jd = &model.joints[j];
            let limit = if flex_sign[j] > 0.0 { jd.upper } else { jd.lower };
            let mut stopped = false;
            while (limit - q[j]).abs() > 1e-6 {
                let mut next = q.clone();
                next[j] = if flex_sign[j] > 0.0 { (q[j] + CLOSE_STEP_RAD).min(limit) } else { (q[j] - CLOSE_STEP_RAD).max(limit) };
                let next = hand.with_mimic(next);
                if depth_of(model, &touching, &next, &which) > -TOUCH_M {
                    stopped = true;
                    break;
                }
                q = next;
            }
            touching_joints += stopped as usize;
        }
        closing.push(q.clone());
    }
    // the squeeze: each flexing joint SQUEEZE_RAD further toward its limit
    let mut squeeze = q.clone();
    for j in (0..nj).filter(|&j| flex_sign[j] != 0.0) {
        let jd = &model.joints[j];
        squeeze[j] = (q[j] + flex_sign[j] * SQUEEZE_RAD).clamp(jd.lower, jd.upper);
    }
    closing.push(hand.with_mimic(squeeze));

    // 5. the approach
    let wrist = Pose::new(touching.pos - n * variant.press, rot);
    let standoff = Pose::new(touching.pos + n * STANDOFF_M, rot);
    let above_z = standoff.pos.z.max(top + CLEARANCE_M + below);
    let above = Pose::new(Vec3::new(standoff.pos.x, standoff.pos.y, above_z), rot);
    Ok(EnvelopePlan { wrist, approach: vec![above, standoff], closing, normal: n, flexing, touching: touching_joints })
}
