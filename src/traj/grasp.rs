//! The antipodal grasp of `dextrain traj synth`, planned from the hand's own kinematics (no table of
//! joint values per hand): the thumb's fingertip and the other fingertips are placed on opposite
//! sides of the object and reached by the fingertip IK of `env::ik` (the residual task's solver).
//!
//! The plan, for the config's hand, object and initial wrist orientation:
//! 1. **Opposition.** In the mid-range posture (every actuated joint at the middle of its limits, the
//!    posture the IK prefers), the direction from the other fingertips' centroid to the thumb's
//!    fingertip, turned into the world by the wrist's initial orientation and projected on the
//!    table, is the hand's opposition axis. The wrist turns about the vertical by the smallest angle
//!    that aligns it with a face normal of the object (a box's ±x or ±y; any direction for a round
//!    one): the thumb goes on that face, the fingers on the opposite one.
//! 2. **Contact points** at the object's mid height: the thumb at the centre of its face; each other
//!    finger on the opposite face, spread along the face as the fingers are spread in the mid-range
//!    posture, squeezed to fit within 70 % of the face's half width (on a round object, around the
//!    circle at the same arc length).
//! 3. **Wrist and joints together.** The wrist position and the joints are solved in turns
//!    (`WRIST_ROUNDS` rounds): the IK solves the joints for the contact points with the wrist fixed,
//!    then the wrist moves by the mean remaining fingertip error (a translation moves every tip
//!    alike), and then up, if needed, until every collider of the palm-like links (those that no
//!    single finger moves alone) is `PALM_CLEARANCE_M` above the object's top.
//! 4. **Postures.** `pre`: the fingertips `PRE_CLEARANCE_M` outside their contact points (along the
//!    face normal), so that the hand descends around the object without touching it; `grasp`: the
//!    fingertips on the contact points; `squeeze`: `SQUEEZE_M` past them, into the object, so that
//!    the closing fingers stall on its surface and the servos press through the contact points;
//!    the closing motion steps from `pre` to `squeeze`, each step seeded from the nearer of the two.
//!    Mimic followers are `multiplier × leader + offset` in every posture.

use anyhow::{Result, bail};
use glam::{Quat, Vec3};

use crate::env::SimModel;
use crate::env::ik::{IkParams, ik_solve, ik_tip_positions};
use crate::geom::{ObjectShape, Pose};
use crate::hand::{ColliderShape, HandModel, MAX_JOINTS, MAX_TIPS};

/// Fingertips outside their contact points in the pre-grasp posture (m).
pub const PRE_CLEARANCE_M: f32 = 0.02;
/// Fingertips past their contact points, into the object, in the squeezing posture (m).
pub const SQUEEZE_M: f32 = 0.015;
/// Least height of the palm-like links' colliders above the object's top (m).
pub const PALM_CLEARANCE_M: f32 = 0.005;
/// Fraction of a face's half width that the fingers' contact points may spread over.
pub const SPREAD_FRACTION: f32 = 0.7;
/// Rounds of (IK for the joints, move the wrist) in step 3.
pub const WRIST_ROUNDS: usize = 40;
/// Iterations of each IK solve.
pub const IK_ITERS: u32 = 100;
/// Postures of the closing motion, `pre` and `squeeze` included.
pub const CLOSING_STEPS: usize = 5;

/// A planned grasp: the wrist pose at the object and the joint postures (HandModel joint order,
/// followers included).
#[derive(Clone, Debug)]
pub struct GraspPlan {
    /// The wrist (root link) pose at the object, in the world.
    pub wrist: Pose,
    /// Fingertips on their contact points (as far as the hand reaches).
    pub grasp: Vec<f32>,
    /// The closing motion: postures with the fingertips at `CLOSING_STEPS` evenly spaced offsets
    /// along the face normals, from `PRE_CLEARANCE_M` outside their contact points (the pre-grasp
    /// posture) to `SQUEEZE_M` past them (the squeezing posture), so that interpolated
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
    let lower: Vec<String> = names.iter().map(|n| n.to_ascii_lowercase()).collect();
    if let Some(i) = lower.iter().position(|n| n.starts_with("th") || n.contains("thumb")) {
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

fn footprint(model: &SimModel, shape: ObjectShape) -> Footprint {
    let g = &model.globals;
    let centre = Vec3::new(g.obj_init[0], g.obj_init[1], g.obj_init[3]);
    let yaw = g.obj_init[2];
    match shape {
        ObjectShape::Box { half_extents: h } => Footprint { centre, yaw, half: [h[0], h[1]], half_height: h[2], round: false },
        ObjectShape::Sphere { radius } => Footprint { centre, yaw, half: [radius; 2], half_height: radius, round: true },
        ObjectShape::Capsule { radius, half_length } => Footprint { centre, yaw, half: [radius; 2], half_height: half_length + radius, round: true },
        ObjectShape::Cylinder { radius, half_length } => Footprint { centre, yaw, half: [radius; 2], half_height: half_length, round: true },
    }
}

/// Links that no single finger moves alone: the root and every link that lies on the chains of two
/// or more fingertips (a wrist or palm link), or on none. Their colliders must stay above the object.
fn palm_links(hand: &HandModel) -> Vec<bool> {
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

/// Plans the grasp of the config's object by the model's hand (see the module documentation).
/// `thumb`: the thumb's fingertip name ("" = detect).
pub fn plan_grasp(model: &SimModel, shape: ObjectShape, thumb: &str) -> Result<GraspPlan> {
    let hand = &model.hand;
    let nt = hand.fingertips.len();
    if nt < 2 {
        bail!(
            "{}: the hand has {nt} fingertip frame(s); an antipodal grasp needs the thumb and at least one other fingertip (name them with hand.fingertips)",
            hand.source.display()
        );
    }
    let m = model.view();
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
    let obj = footprint(model, shape);
    let rot0 = Quat::from_array(model.globals.init_wrist_rot);
    let opp = rot0 * (mid_tips[th] - finger_centroid);
    let opp_h = Vec3::new(opp.x, opp.y, 0.0);
    if opp_h.length() < 1e-4 {
        bail!(
            "{}: in the initial wrist orientation the thumb is straight above or below the other fingertips; expected an orientation (wrist.init_rpy) in which the thumb opposes the fingers across the object",
            hand.source.display()
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
    let turn = Quat::from_rotation_z(wrap(normal_angle - opp_angle));
    let rot = (turn * rot0).normalize();
    let n = Vec3::new(normal_angle.cos(), normal_angle.sin(), 0.0); // toward the thumb's face
    let t = Vec3::Z.cross(n); // along the faces
    let (half_n, half_t) = (obj.half[face], obj.half[1 - face]);

    // 2. contact points at mid height: thumb on +n, fingers on −n spread along t
    let z = obj.centre.z;
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

    // 3. wrist position and joints together
    let palm = palm_links(hand);
    let top = obj.centre.z + obj.half_height;
    let footprint_radius = if obj.round { obj.half[0] } else { Vec3::new(obj.half[0], obj.half[1], 0.0).length() };
    let mask = (1u32 << nt) - 1;
    let solve = |wrist: &Pose, seed: &[f32], offset: f32| -> Vec<f32> {
        let mut targets = [Vec3::ZERO; MAX_TIPS];
        for i in 0..nt {
            targets[i] = wrist.inverse().transform_point(contacts[i] + normals[i] * offset);
        }
        ik_solve(&m, &to_arr(seed), &targets, mask, &prm)[..nj].to_vec()
    };
    let tips_world = |wrist: &Pose, q: &[f32]| -> Vec<Vec3> {
        ik_tip_positions(&m, &to_arr(q), &mut Default::default())[..nt].iter().map(|p| wrist.transform_point(*p)).collect()
    };
    // start: the mid-range fingertips' centre at the contact points' centre
    let contact_centre = contacts.iter().sum::<Vec3>() / nt as f32;
    let tip_centre = mid_tips.iter().sum::<Vec3>() / nt as f32;
    let mut wrist = Pose::new(contact_centre - rot * tip_centre, rot);
    let mut q = mid.clone();
    for _ in 0..WRIST_ROUNDS {
        q = solve(&wrist, &q, 0.0);
        let tips = tips_world(&wrist, &q);
        let mean_err = (0..nt).map(|i| contacts[i] - tips[i]).sum::<Vec3>() / nt as f32;
        wrist.pos += mean_err;
        let lift = top + PALM_CLEARANCE_M - palm_bottom(hand, &palm, &wrist, &q, centre, footprint_radius);
        if lift > 0.0 {
            wrist.pos.z += lift;
        }
    }
    let grasp = solve(&wrist, &q, 0.0);
    let tips = tips_world(&wrist, &grasp);
    let reach_error = (0..nt).map(|i| (tips[i] - contacts[i]).length()).collect();
    // 4. the closing motion, seeded from the pre-grasp and squeezing postures (solved from the grasp)
    let pre = solve(&wrist, &grasp, PRE_CLEARANCE_M);
    let squeeze = solve(&wrist, &grasp, -SQUEEZE_M);
    let closing = (0..CLOSING_STEPS)
        .map(|k| {
            let a = k as f32 / (CLOSING_STEPS - 1) as f32;
            let offset = PRE_CLEARANCE_M + a * (-SQUEEZE_M - PRE_CLEARANCE_M);
            solve(&wrist, if offset > 0.0 { &pre } else { &squeeze }, offset)
        })
        .collect();
    Ok(GraspPlan { wrist, grasp, closing, contacts, normals, thumb: th, reach_error })
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
