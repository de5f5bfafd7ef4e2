//! The antipodal grasp of `dextrain traj synth`, planned from the hand's own kinematics (no table of
//! joint values per hand): the thumb's fingertip and the other fingertips are placed on opposite
//! sides of the object and reached by the fingertip IK of `env::ik` (the residual task's solver).
//! A [`GraspVariant`] fixes the choices below; `traj synth` tries [`GRASP_VARIANTS`] in order and
//! keeps the first whose reference lifts the object in simulation.
//!
//! The plan, for the config's hand, object and initial wrist orientation:
//! 0. **Pad points.** The IK moves each fingertip's pad point ([`pad_points`]): the tip frame, or
//!    the far end of its link's collision geometry when that reaches farther out from the joint (a
//!    tip frame at the distal joint).
//! 1. **Opposition.** In the mid-range posture (every actuated joint at the middle of its limits, the
//!    posture the IK prefers), the variant's opposition axis ([`Opposition`]: from the other
//!    fingertips' centroid to the thumb, or along the fingertips' closing motion), turned into the
//!    world by the wrist's initial orientation and projected on the table. The wrist turns about
//!    the vertical by the smallest angle that aligns it with a face normal of the object (a box's
//!    ±x or ±y; any direction for a round one): the thumb goes on that face, the fingers on the
//!    opposite one.
//! 2. **Contact points** at the variant's height: the thumb at the centre of its face; each other
//!    finger on the opposite face, spread along the face as the fingers are spread in the mid-range
//!    posture, squeezed to fit within `SPREAD_FRACTION` of the face's half width (on a round object,
//!    around the circle at the same arc length); then each moves inward from the box's face to the
//!    object's own surface, the first of its pieces met ([`surface_point`]: the same point for a
//!    primitive, whose box is itself).
//! 3. **Wrist and joints together.** The wrist position and the joints are solved in turns
//!    (`WRIST_ROUNDS` rounds): the IK solves the joints for the contact points with the wrist fixed;
//!    a fingertip that stays more than `REACH_TOLERANCE_M` from its contact point (an underactuated
//!    finger moves its tip along a curve) takes the nearest point of its face region instead (within
//!    `SPREAD_FRACTION` of the half width and `HEIGHT_FRACTION` of the half height); then the wrist
//!    moves by the mean remaining fingertip error (a translation moves every tip alike), and then
//!    up, if needed, until every collider of the palm-like links (those that no single finger moves
//!    alone) is the variant's palm clearance above the object's top.
//! 4. **Postures.** `pre`: the fingertips outside their contact points (along the face normal) by
//!    the least of `PRE_CLEARANCES_M` from which the hand descends `HOVER_M` onto the grasp pose
//!    without touching the object (collision-checked against the colliders); `grasp`: the
//!    fingertips on the contact points; `squeeze`: the variant's squeeze past them, into the
//!    object, so that the closing fingers stall on its surface and the servos press through the
//!    contact points; the closing motion steps from `pre` to `squeeze`, each step seeded from the
//!    nearer of the two. Mimic followers are `multiplier × leader + offset` in every posture.

use anyhow::{Result, bail};
use glam::{Quat, Vec3};

use crate::task::ik::{IkParams, ik_solve, ik_tip_positions};
use crate::env::physics::{CONTACT_MARGIN, Scratch, collide_hand_object, hand_kinematics, piece_pose, piece_project};
use crate::env::reset::reset_params;
use crate::env::{EnvParams, EnvState, SimModel};
use crate::geom::Pose;
use crate::gpu::layout::NO_JOINT;
use crate::hand::{ColliderShape, HandModel, MAX_JOINTS, MAX_TIPS};

/// Fingertips outside their contact points in the pre-grasp posture (m), the first clearance tried.
pub const PRE_CLEARANCE_M: f32 = 0.02;
/// Fingertips past their contact points, into the object, in the squeezing posture (m), the
/// shallower of the variants' two squeezes.
pub const SQUEEZE_M: f32 = 0.015;
/// Least height of the palm-like links' colliders above the object's top (m) in the first variants.
pub const PALM_CLEARANCE_M: f32 = 0.005;
/// Fraction of a face's half width that the fingers' contact points may spread over.
pub const SPREAD_FRACTION: f32 = 0.7;
/// Rounds of (IK for the joints, move the wrist) in step 3.
pub const WRIST_ROUNDS: usize = 40;
/// A fingertip farther than this (m) from its contact point after the IK cannot reach it (an
/// underactuated finger moves its tip along a curve): its contact point moves to the point of its
/// face region nearest to where the tip got.
pub const REACH_TOLERANCE_M: f32 = 0.002;
/// Fraction of the object's half height about its centre that contact points may move within.
pub const HEIGHT_FRACTION: f32 = 0.6;
/// Height (m) above the grasp pose from which the wrist descends onto it in the pre-grasp posture.
pub const HOVER_M: f32 = 0.05;
/// Pre-grasp clearances (m) tried in turn until the hand descends onto the grasp pose without
/// touching the object; the last is kept if none does.
pub const PRE_CLEARANCES_M: [f32; 5] = [PRE_CLEARANCE_M, 0.03, 0.04, 0.05, 0.06];
/// Iterations of each IK solve.
pub const IK_ITERS: u32 = 100;
/// Postures of the closing motion, `pre` and `squeeze` included.
pub const CLOSING_STEPS: usize = 5;

/// Which way the thumb opposes the fingers, in the hand's frame; the wrist turns about the vertical
/// to align it with a face normal of the object.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Opposition {
    /// From the other fingertips' centroid to the thumb's fingertip in the mid-range posture (the
    /// fingers press sideways, as a pinch between thumb and index does).
    ThumbToFingers,
    /// Along the fingertips' closing motion (the mid-range posture flexed by a tenth of each range):
    /// the fingers press with their pads as they curl (a hand whose fingers only curl, as Ability's,
    /// Inspire's and SCHUNK SVH's coupled fingers do).
    FingerClosing,
}

/// The choices a grasp plan is made with; `traj synth` tries [`GRASP_VARIANTS`] in order.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GraspVariant {
    /// The opposition axis.
    pub opposition: Opposition,
    /// Height of the contact points above the object's centre, as a fraction of its half height.
    pub height: f32,
    /// How far past the contact points (m), into the object, the squeezing posture reaches.
    pub squeeze: f32,
    /// Least height (m) of the palm-like links' colliders above the object's top (0: the palm may
    /// rest on it).
    pub palm_clearance: f32,
}

/// The variants `traj synth --grasp antipodal` tries in order, the same for every hand: the first
/// whose reference lifts the object in simulation is kept. The palm clear of the object's top, then
/// resting on it (a hand whose fingers are short for the object); within each, contact points at
/// mid height, above and below it, each with a shallow and a deep squeeze, each with both
/// oppositions.
pub const GRASP_VARIANTS: [GraspVariant; 24] = {
    const O: [Opposition; 2] = [Opposition::ThumbToFingers, Opposition::FingerClosing];
    const HEIGHT: [f32; 3] = [0.0, 0.3, -0.3];
    const SQUEEZE: [f32; 2] = [SQUEEZE_M, 2.0 * SQUEEZE_M];
    const PALM: [f32; 2] = [PALM_CLEARANCE_M, 0.0];
    let mut v = [GraspVariant { opposition: Opposition::ThumbToFingers, height: 0.0, squeeze: SQUEEZE_M, palm_clearance: PALM_CLEARANCE_M }; 24];
    let mut i = 0;
    while i < 24 {
        v[i] = GraspVariant { opposition: O[i % 2], squeeze: SQUEEZE[(i / 2) % 2], height: HEIGHT[(i / 4) % 3], palm_clearance: PALM[i / 12] };
        i += 1;
    }
    v
};

/// A planned grasp: the wrist pose at the object and the joint postures (HandModel joint order,
/// followers included).
#[derive(Clone, Debug)]
pub struct GraspPlan {
    /// The wrist (root link) pose at the object, in the world.
    pub wrist: Pose,
    /// Fingertips on their contact points (as far as the hand reaches).
    pub grasp: Vec<f32>,
    /// The closing motion: postures with the fingertips at `CLOSING_STEPS` evenly spaced offsets
    /// along the face normals, from `pre_clearance` outside their contact points (the pre-grasp
    /// posture) to the variant's squeeze past them (the squeezing posture), so that interpolated
    /// keyframes move every fingertip nearly straight through its contact point.
    pub closing: Vec<Vec<f32>>,
    /// Contact points (world), in fingertip order.
    pub contacts: Vec<Vec3>,
    /// Outward face normal (world, horizontal) at each contact point.
    pub normals: Vec<Vec3>,
    /// The index (into the fingertips) of the thumb.
    pub thumb: usize,
    /// Distance (m) from each fingertip in `grasp` to its contact point.
    pub reach_error: Vec<f32>,
    /// Distance (m) of the fingertips outside their contact points in the pre-grasp posture (one of
    /// `PRE_CLEARANCES_M`).
    pub pre_clearance: f32,
}

/// The thumb among the hand's fingertips: `named` if given, else the first fingertip whose name
/// starts with "th" or contains "thumb", else the fingertip farthest from the others' centroid in
/// the mid-range posture (a thumb sits apart from the fingers).
pub fn thumb_index(hand: &HandModel, named: &str, mid_tips: &[Vec3]) -> Result<usize> {
    let names: Vec<&str> = hand.fingertips.iter().map(|t| t.name.as_str()).collect();
    if !named.is_empty() {
        return names.iter().position(|n| *n == named).ok_or_else(|| {
            anyhow::anyhow!("the thumb '{named}' is not one of the hand's fingertips ({}); expected one of them", names.join(", "))
        });
    }
    if let Some(i) = hand.thumb_by_name() {
        return Ok(i);
    }
    let n = mid_tips.len();
    let apart = |i: usize| {
        let others = mid_tips.iter().enumerate().filter(|(k, _)| *k != i).map(|(_, p)| *p).sum::<Vec3>() / (n - 1).max(1) as f32;
        (mid_tips[i] - others).length()
    };
    Ok((0..n).max_by(|&a, &b| apart(a).total_cmp(&apart(b))).unwrap_or(0))
}

/// The object's footprint for the grasp: centre (world), yaw, half width along its local x and y
/// (equal for a round object), half height, and whether it is round (sphere, capsule, cylinder).
struct Footprint {
    centre: Vec3,
    yaw: f32,
    half: [f32; 2],
    half_height: f32,
    round: bool,
}

/// The first object's footprint at its nominal place: the box around its pieces (in its frame,
/// turned by the initial yaw), round for an upright cylinder, capsule or a sphere. For a primitive
/// object that is the primitive itself.
fn footprint(model: &SimModel) -> Footprint {
    let o = &model.objects[0];
    let (lo, hi) = o.bounding_box();
    let h = (hi - lo) * 0.5;
    Footprint { centre: object_centre(model), yaw: model.globals.obj_init[2], half: [h.x, h.y], half_height: h.z, round: o.is_round() }
}

/// The centre (world) of the box around the first object's pieces, with the object resting at
/// its nominal place: where a grasp aims.
pub fn object_centre(model: &SimModel) -> Vec3 {
    let g = &model.globals;
    let (lo, hi) = model.objects[0].bounding_box();
    let origin = Vec3::new(g.obj_init[0], g.obj_init[1], g.obj_init[3]);
    origin + Quat::from_rotation_z(g.obj_init[2]) * ((lo + hi) * 0.5)
}

/// Links that no single finger moves alone: the root and every link that lies on the chains of two
/// or more fingertips (a wrist or palm link), or on none. Their colliders must stay above the object.
pub(super) fn palm_links(hand: &HandModel) -> Vec<bool> {
    (0..hand.links.len())
        .map(|l| l == 0 || hand.fingertips.iter().filter(|t| hand.is_ancestor_or_same(l, t.link)).count() != 1)
        .collect()
}

/// Lowest world z of the palm-like links' colliders above the object's footprint (a disc of
/// `reach` about `centre`, padded by each collider's bounding radius) for the wrist pose and joints
/// `q`; +∞ when none is above it.
fn palm_bottom(hand: &HandModel, palm: &[bool], wrist: &Pose, q: &[f32], centre: Vec3, reach: f32) -> f32 {
    let links = hand.forward_kinematics(q);
    let mut lo = f32::INFINITY;
    for c in hand.colliders.iter().filter(|c| palm[c.link]) {
        let pose = wrist.mul(&links[c.link]).mul(&c.pose);
        let bound = match c.shape {
            ColliderShape::Sphere { radius } => radius,
            ColliderShape::Capsule { radius, half_length } => radius + half_length,
            ColliderShape::Box { half_extents } => half_extents.length(),
        };
        if Vec3::new(pose.pos.x - centre.x, pose.pos.y - centre.y, 0.0).length() > reach + bound {
            continue;
        }
        let z = match c.shape {
            ColliderShape::Sphere { radius } => pose.pos.z - radius,
            ColliderShape::Capsule { radius, half_length } => {
                // the segment's lower end, minus the radius
                let axis = pose.rot * Vec3::Z;
                pose.pos.z - axis.z.abs() * half_length - radius
            }
            ColliderShape::Box { half_extents } => {
                // support in −z: Σ |R[2][k]| h_k
                let (x, y, z) = (pose.rot * Vec3::X, pose.rot * Vec3::Y, pose.rot * Vec3::Z);
                pose.pos.z - x.z.abs() * half_extents.x - y.z.abs() * half_extents.y - z.z.abs() * half_extents.z
            }
        };
        lo = lo.min(z);
    }
    lo
}

/// The point of each fingertip's link that the plan puts on its contact point, in the link frame:
/// the fingertip itself, unless its link's collision geometry reaches farther out from the link's
/// joint (a tip frame at the distal joint, as LEAP_Hand_Sim's link origins are): then the centre of
/// the geometry's far end (a capsule's far cap centre, a sphere's centre, a box's far face pulled in
/// by its smallest half extent), so that the finger's pad, not its knuckle, meets the object.
pub fn pad_points(hand: &HandModel) -> Vec<Vec3> {
    hand.fingertips
        .iter()
        .map(|tip| {
            let cols: Vec<_> = hand.colliders.iter().filter(|c| c.link == tip.link).collect();
            if cols.is_empty() {
                return tip.pos;
            }
            // outward: from the joint (the link origin) toward the geometry's centre
            let centre = cols.iter().map(|c| c.pose.pos).sum::<Vec3>() / cols.len() as f32;
            if centre.length() < 1e-3 {
                return tip.pos;
            }
            let u = centre.normalize();
            let far_end = |c: &crate::hand::Collider| -> Vec3 {
                match c.shape {
                    ColliderShape::Sphere { .. } => c.pose.pos,
                    ColliderShape::Capsule { half_length, .. } => {
                        let axis = c.pose.rot * Vec3::Z;
                        c.pose.pos + axis * (half_length * axis.dot(u).signum())
                    }
                    ColliderShape::Box { half_extents: h } => {
                        // support along u, Σ_k |u·e_k| h_k, less the smallest half extent
                        let ub = c.pose.rot.inverse() * u;
                        let support = ub.x.abs() * h.x + ub.y.abs() * h.y + ub.z.abs() * h.z;
                        c.pose.pos + u * (support - h.min_element()).max(0.0)
                    }
                }
            };
            cols.iter().map(|c| far_end(c)).fold(tip.pos, |best, p| if p.dot(u) > best.dot(u) { p } else { best })
        })
        .collect()
}

/// Plans the grasp of the config's object by the model's hand (see the module documentation).
/// `thumb`: the thumb's fingertip name ("" = detect).
pub fn plan_grasp(model: &SimModel, thumb: &str, variant: &GraspVariant) -> Result<GraspPlan> {
    let hand = &model.hand;
    let nt = hand.fingertips.len();
    if nt < 2 {
        bail!(
            "{}: the hand has {nt} fingertip frame(s); an antipodal grasp needs the thumb and at least one other fingertip (name them with hand.fingertips)",
            hand.source.display()
        );
    }
    // the IK moves each fingertip's pad point (see `pad_points`)
    let mut pads = model.clone();
    for (td, p) in pads.tips.iter_mut().zip(pad_points(hand)) {
        td.pos = [p.x, p.y, p.z, 0.0];
    }
    let m = pads.view();
    let nj = model.joints.len();
    let prm = IkParams { iters: IK_ITERS, ..IkParams::default() };
    let to_arr = |q: &[f32]| {
        let mut a = [0.0f32; MAX_JOINTS];
        a[..q.len()].copy_from_slice(q);
        a
    };
    let mid = hand.with_mimic(
        model
            .joints
            .iter()
            .map(|j| if j.lower > -1e29 && j.upper < 1e29 { 0.5 * (j.lower + j.upper) } else { j.default_q })
            .collect(),
    );
    let mid_tips: Vec<Vec3> = ik_tip_positions(&m, &to_arr(&mid), &mut Default::default())[..nt].to_vec();
    let th = thumb_index(hand, thumb, &mid_tips)?;
    let fingers: Vec<usize> = (0..nt).filter(|&i| i != th).collect();
    let finger_centroid = fingers.iter().map(|&i| mid_tips[i]).sum::<Vec3>() / fingers.len() as f32;

    // 1. opposition axis, and the wrist's turn about the vertical that aligns it with a face normal
    let obj = footprint(model);
    let rot0 = Quat::from_array(model.globals.init_wrist_rot);
    let opp = match variant.opposition {
        Opposition::ThumbToFingers => rot0 * (mid_tips[th] - finger_centroid),
        Opposition::FingerClosing => {
            // the fingertips' motion when every joint flexes by a tenth of its range
            let flexed = hand.with_mimic(
                model.joints.iter().zip(&mid).map(|(j, q)| if j.lower > -1e29 && j.upper < 1e29 { q + 0.1 * (j.upper - j.lower) } else { *q }).collect(),
            );
            let flexed_tips = ik_tip_positions(&m, &to_arr(&flexed), &mut Default::default());
            rot0 * fingers.iter().map(|&i| flexed_tips[i] - mid_tips[i]).sum::<Vec3>()
        }
    };
    let opp_h = Vec3::new(opp.x, opp.y, 0.0);
    if opp_h.length() < 1e-4 {
        bail!(
            "{}: in the initial wrist orientation the opposition axis ({:?}) is vertical; expected an orientation (wrist.init_rpy) in which the thumb opposes the fingers across the object",
            hand.source.display(),
            variant.opposition
        );
    }
    let opp_angle = opp_h.y.atan2(opp_h.x);
    // face normals (angles in the world): a box's four, or the opposition itself for a round object
    let (normal_angle, face) = if obj.round {
        (opp_angle, 0usize)
    } else {
        (0..4)
            .map(|k| {
                let a = obj.yaw + k as f32 * std::f32::consts::FRAC_PI_2;
                (a, k % 2)
            })
            .min_by(|x, y| wrap(x.0 - opp_angle).abs().total_cmp(&wrap(y.0 - opp_angle).abs()))
            .expect("four faces")
    };
    let sq = variant.squeeze;
    let turn = Quat::from_rotation_z(wrap(normal_angle - opp_angle));
    let rot = (turn * rot0).normalize();
    let n = Vec3::new(normal_angle.cos(), normal_angle.sin(), 0.0); // toward the thumb's face
    let t = Vec3::Z.cross(n); // along the faces
    let (half_n, half_t) = (obj.half[face], obj.half[1 - face]);

    // 2. contact points at the variant's height: thumb on +n, fingers on −n spread along t
    let z = obj.centre.z + variant.height * obj.half_height;
    let centre = Vec3::new(obj.centre.x, obj.centre.y, z);
    let spread: Vec<f32> = fingers.iter().map(|&i| (rot * (mid_tips[i] - finger_centroid)).dot(t)).collect();
    let widest = spread.iter().fold(0.0f32, |a, s| a.max(s.abs()));
    let fit = if widest > SPREAD_FRACTION * half_t { SPREAD_FRACTION * half_t / widest } else { 1.0 };
    let mut contacts = vec![Vec3::ZERO; nt];
    let mut normals = vec![Vec3::ZERO; nt];
    contacts[th] = centre + n * half_n;
    normals[th] = n;
    for (k, &i) in fingers.iter().enumerate() {
        let s = spread[k] * fit;
        if obj.round {
            // the same arc length around the circle from −n
            let a = s / half_n;
            let dir = Quat::from_rotation_z(a) * -n;
            contacts[i] = centre + dir * half_n;
            normals[i] = dir;
        } else {
            contacts[i] = centre - n * half_n + t * s;
            normals[i] = -n;
        }
    }
    // on the object's own surface: each contact point moves inward from the box's face to the
    // first of the object's pieces it meets (a no-op for a primitive, whose box is itself)
    let surface_reach = 2.0 * half_n;
    for i in 0..nt {
        contacts[i] = surface_point(model, contacts[i], -normals[i], surface_reach);
    }

    // 3. wrist position and joints together
    let palm = palm_links(hand);
    let top = obj.centre.z + obj.half_height;
    let footprint_radius = if obj.round { obj.half[0] } else { Vec3::new(obj.half[0], obj.half[1], 0.0).length() };
    let mask = (1u32 << nt) - 1;
    let solve = |wrist: &Pose, seed: &[f32], contacts: &[Vec3], normals: &[Vec3], offset: f32| -> Vec<f32> {
        let mut targets = [Vec3::ZERO; MAX_TIPS];
        for i in 0..nt {
            targets[i] = wrist.inverse().transform_point(contacts[i] + normals[i] * offset);
        }
        ik_solve(&m, &to_arr(seed), &targets, mask, &prm)[..nj].to_vec()
    };
    let tips_world = |wrist: &Pose, q: &[f32]| -> Vec<Vec3> {
        ik_tip_positions(&m, &to_arr(q), &mut Default::default())[..nt].iter().map(|p| wrist.transform_point(*p)).collect()
    };
    // the face region of tip i: its face (box) or its half of the side (round), within
    // SPREAD_FRACTION of the face's half width and HEIGHT_FRACTION of the half height
    let z_band = HEIGHT_FRACTION * obj.half_height;
    let on_face = |i: usize, p: Vec3| -> (Vec3, Vec3) {
        let z = p.z.clamp(obj.centre.z - z_band, obj.centre.z + z_band);
        let side = if i == th { n } else { -n };
        if obj.round {
            // radial direction, within 60° of the side's normal
            let d = Vec3::new(p.x - centre.x, p.y - centre.y, 0.0);
            let a = if d.length() > 1e-6 { wrap(d.y.atan2(d.x) - side.y.atan2(side.x)) } else { 0.0 };
            let dir = Quat::from_rotation_z(a.clamp(-std::f32::consts::FRAC_PI_3, std::f32::consts::FRAC_PI_3)) * side;
            (Vec3::new(centre.x, centre.y, z) + dir * half_n, dir)
        } else {
            let along = (p - centre).dot(t).clamp(-SPREAD_FRACTION * half_t, SPREAD_FRACTION * half_t);
            (surface_point(model, Vec3::new(centre.x, centre.y, z) + side * half_n + t * along, -side, surface_reach), side)
        }
    };
    // start: the mid-range fingertips' centre at the contact points' centre
    let contact_centre = contacts.iter().sum::<Vec3>() / nt as f32;
    let tip_centre = mid_tips.iter().sum::<Vec3>() / nt as f32;
    let mut wrist = Pose::new(contact_centre - rot * tip_centre, rot);
    let mut q = mid.clone();
    for _ in 0..WRIST_ROUNDS {
        q = solve(&wrist, &q, &contacts, &normals, 0.0);
        let tips = tips_world(&wrist, &q);
        // a tip that cannot reach its contact point takes the nearest point of its face region
        for i in 0..nt {
            if (tips[i] - contacts[i]).length() > REACH_TOLERANCE_M {
                (contacts[i], normals[i]) = on_face(i, tips[i]);
            }
        }
        let mean_err = (0..nt).map(|i| contacts[i] - tips[i]).sum::<Vec3>() / nt as f32;
        wrist.pos += mean_err;
        let lift = top + variant.palm_clearance - palm_bottom(hand, &palm, &wrist, &q, centre, footprint_radius);
        if lift > 0.0 {
            wrist.pos.z += lift;
        }
    }
    let grasp = solve(&wrist, &q, &contacts, &normals, 0.0);
    let tips = tips_world(&wrist, &grasp);
    let reach_error = (0..nt).map(|i| (tips[i] - contacts[i]).length()).collect();
    // 4. the pre-grasp posture: the least clearance from which the hand descends from HOVER_M above
    //    onto the grasp pose without touching the object
    let descent_clear = |q: &[f32]| {
        (0..=DESCENT_CHECKS).all(|k| {
            let w = Pose::new(wrist.pos + Vec3::Z * (HOVER_M * k as f32 / DESCENT_CHECKS as f32), wrist.rot);
            hand_object_depth(model, &w, q) <= 0.0
        })
    };
    let mut pre_clearance = PRE_CLEARANCES_M[PRE_CLEARANCES_M.len() - 1];
    for c in PRE_CLEARANCES_M {
        if descent_clear(&solve(&wrist, &grasp, &contacts, &normals, c)) {
            pre_clearance = c;
            break;
        }
    }
    // the closing motion, seeded from the pre-grasp and squeezing postures (solved from the grasp)
    let pre = solve(&wrist, &grasp, &contacts, &normals, pre_clearance);
    let squeeze = solve(&wrist, &grasp, &contacts, &normals, -sq);
    let closing = (0..CLOSING_STEPS)
        .map(|k| {
            let a = k as f32 / (CLOSING_STEPS - 1) as f32;
            let offset = pre_clearance + a * (-sq - pre_clearance);
            solve(&wrist, if offset > 0.0 { &pre } else { &squeeze }, &contacts, &normals, offset)
        })
        .collect();
    Ok(GraspPlan { wrist, grasp, closing, contacts, normals, thumb: th, reach_error, pre_clearance })
}

/// Wrist poses checked along the descent onto the grasp pose (besides the grasp pose itself).
const DESCENT_CHECKS: usize = 10;

/// The deepest overlap (m; ≤ 0 when none) of the hand's colliders, at wrist pose `wrist` with the
/// joints `q` (followers included), with the object at rest at its nominal place and size.
pub fn hand_object_depth(model: &SimModel, wrist: &Pose, q: &[f32]) -> f32 {
    hand_object_depths(model, wrist, q, &nominal_pose(model)).0
}

/// The deepest overlap (m; ≤ 0 when none) of the hand's colliders, at wrist pose `wrist` with the
/// joints `q` (followers included), with the first object, unscaled, at `object`: over every
/// collider, and over those on no fingertip's link (the palm and the fingers' inner links).
pub fn hand_object_depths(model: &SimModel, wrist: &Pose, q: &[f32], object: &Pose) -> (f32, f32) {
    let m = model.view();
    let (p, mut st) = object_at(model, object);
    st.wrist_pos = [wrist.pos.x, wrist.pos.y, wrist.pos.z, 0.0];
    st.wrist_rot = wrist.rot.to_array();
    st.q[..q.len()].copy_from_slice(q);
    let mut s = Scratch::default();
    hand_kinematics(&st, &m, &mut s);
    let (mut all, mut off_tips) = (-1.0f32, -1.0f32);
    for ci in 0..model.colliders.len() {
        let d = collide_hand_object(&st, &p, &m, &s, ci, CONTACT_MARGIN).depth;
        all = all.max(d);
        if model.colliders[ci].tip == NO_JOINT {
            off_tips = off_tips.max(d);
        }
    }
    (all, off_tips)
}

/// The open hand: every joint at its default, mimic followers from their leaders.
pub(super) fn open_posture(model: &SimModel) -> Vec<f32> {
    model.hand.with_mimic(model.joints.iter().map(|j| j.default_q).collect())
}

/// The wrist's initial pose (`wrist.init_pos`, `wrist.init_rpy`): where every script starts.
pub(super) fn initial_wrist(model: &SimModel) -> Pose {
    let g = &model.globals;
    Pose::new(Vec3::from_slice(&g.init_wrist_pos[..3]), Quat::from_array(g.init_wrist_rot))
}

/// The first object's nominal resting pose: the config's position (x, y, rest height) and yaw.
fn nominal_pose(model: &SimModel) -> Pose {
    let g = &model.globals;
    Pose::new(Vec3::new(g.obj_init[0], g.obj_init[1], g.obj_init[3]), Quat::from_rotation_z(g.obj_init[2]))
}

/// The first object as the planner sees it: env 0's parameters with the object forced to the
/// first one, unscaled, and a state with it resting at its nominal place (the rest zero).
pub(super) fn nominal_object(model: &SimModel) -> (EnvParams, EnvState) {
    object_at(model, &nominal_pose(model))
}

/// Env 0's parameters with the object forced to the first one, unscaled, and a state with it at
/// `pose` (the rest zero).
fn object_at(model: &SimModel, pose: &Pose) -> (EnvParams, EnvState) {
    let mut p = reset_params(&model.globals, &model.object_descs, &[], 0, 0);
    let od = &model.object_descs[0];
    (p.obj_index, p.obj_scale, p.obj_com) = (0, 1.0, od.com);
    let st = EnvState { obj_pos: [pose.pos.x, pose.pos.y, pose.pos.z, 0.0], obj_rot: pose.rot.to_array(), ..Default::default() };
    (p, st)
}

/// Step (m) of the march from a face of the box around the object to the object's own surface.
const SURFACE_STEP_M: f32 = 0.001;

/// The first point of the object's own surface met going from `p` (world, on a face of the box
/// around its pieces) inward along `dir` (unit, horizontal), at most `reach` m: the point where the
/// distance to the nearest piece (primitive or hull, at the object's nominal place, unscaled) falls
/// under one march step; `p` itself when nothing is met (the march passed through a gap).
pub fn surface_point(model: &SimModel, p: Vec3, dir: Vec3, reach: f32) -> Vec3 {
    let m = model.view();
    let (prm, st) = nominal_object(model);
    let od = &model.object_descs[0];
    let pieces = &model.pieces[od.first_piece as usize..(od.first_piece + od.n_pieces) as usize];
    let distance = |x: Vec3| -> f32 {
        pieces
            .iter()
            .map(|pd| {
                let (ppos, prot, size) = piece_pose(&st, &prm, pd);
                let r = Quat::from_array(prot.to_array());
                let local = r.inverse() * (x - ppos);
                let (closest, inside) = piece_project(&m, pd, 1.0, size, local);
                if inside { 0.0 } else { (local - closest).length() }
            })
            .fold(f32::INFINITY, f32::min)
    };
    let steps = (reach / SURFACE_STEP_M).ceil() as usize;
    (0..=steps).map(|k| p + dir * (k as f32 * SURFACE_STEP_M)).find(|&x| distance(x) < SURFACE_STEP_M).unwrap_or(p)
}

/// An angle wrapped into (−π, π].
fn wrap(a: f32) -> f32 {
    let two_pi = std::f32::consts::TAU;
    let mut a = a % two_pi;
    if a > std::f32::consts::PI {
        a -= two_pi;
    } else if a <= -std::f32::consts::PI {
        a += two_pi;
    }
    a
}
