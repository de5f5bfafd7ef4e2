//! The wrist's initial pose of a starter config, from the hand's own geometry: the orientation
//! that puts the palm down with the fingers along +x (or, for a gripper whose fingers close toward
//! each other, the fingers straight down), and the height that keeps the open hand clear above the
//! object.
//!
//! The rule ([`wrist_orientation`]), in the root (wrist) frame, in the open posture (every joint at
//! 0 clamped into its limits, as the simulator starts it):
//! - **Fingers** `f`: the mean over the fingers (the thumb left out) of the direction from each
//!   finger's base (the origin of its first joint that moves no other fingertip) to its tip.
//! - **Closing** `dᵢ`: how each fingertip moves when each of its finger's own joints moves a tenth
//!   of its range toward the limit farther from its open value (a finger rests open at one end of
//!   its flexion range and closes across it, whatever the URDF's sign convention); joints open at
//!   the middle of their range (side-to-side, abduction joints) stay. `dᵢ⊥` is its part across `f`.
//! - **Palm or gripper**: the coherence `|Σ dᵢ⊥| / Σ |dᵢ⊥|` over every finger, thumb included, is
//!   near 1 when the fingers curl toward one side (the palm's) and near 0 when they close toward
//!   each other around the hand's axis (a parallel gripper, a three-finger claw). At or above
//!   [`PALM_COHERENCE`]: a hand with a palm, whose normal `n` is `Σ dᵢ⊥` over the fingers (thumb
//!   left out) with its part along the line of the finger bases removed; it is turned so that
//!   `f → +x` and `n → −z` (the palm faces the table, as `wrist.init_rpy = [0, π/2, 0]` does for
//!   dex-urdf's hands, whose palm normal is +x and fingers +z). Below it: a gripper, turned by the
//!   smallest rotation that points `f` down (`f → −z`).
//! - `f` and `n` within [`SNAP_DEG`] of an axis of the root frame are taken as that axis (URDF
//!   frames are drawn along the hand's axes; the measured directions lean with the fingers' rest
//!   curl), so dex-urdf's hands get exactly pitch +90° and LEAP_Hand_Sim's frame (palm −z, fingers
//!   +x) exactly the identity.

use glam::{DVec3, Mat3, Quat, Vec3};

use super::fingers::{bases_and_tips, open_posture, own_joints};
use crate::hand::{ColliderShape, HandModel};

/// Coherence of the fingers' closing directions at or above which the hand is taken to have a palm
/// (see the module documentation).
pub const PALM_COHERENCE: f32 = 0.5;
/// A measured direction within this angle (degrees) of an axis of the root frame is taken as it.
pub const SNAP_DEG: f32 = 25.0;
/// Fraction of a joint's range each own joint moves to measure a finger's closing direction.
pub const CLOSING_STEP: f32 = 0.1;
/// A joint whose open value lies within this fraction of its range of the range's middle is taken
/// for a side-to-side (abduction) joint and left out of the closing motion.
pub const MID_RANGE_BAND: f32 = 0.1;

/// The orientation chosen, and why.
#[derive(Clone, Debug)]
pub struct WristOrientation {
    /// The initial wrist orientation (world from root frame).
    pub rot: Quat,
    /// `wrist.init_rpy` (roll, pitch, yaw, rad; R = Rz(yaw)·Ry(pitch)·Rx(roll)), rounded to 7 decimals.
    pub rpy: [f32; 3],
    /// Whether the hand was taken to have a palm (else a gripper).
    pub palm: bool,
    /// One line saying what was measured and what was chosen.
    pub reason: String,
}

/// A direction snapped to the nearest ± axis when within [`SNAP_DEG`] of it.
fn snap(v: Vec3) -> Vec3 {
    let v = v.normalize();
    let k = (0..3).max_by(|&a, &b| v[a].abs().total_cmp(&v[b].abs())).unwrap_or(0);
    if v[k].abs() >= SNAP_DEG.to_radians().cos() {
        let mut a = Vec3::ZERO;
        a[k] = v[k].signum();
        a
    } else {
        v
    }
}

/// A direction for a message: `+x` for an axis, else its components.
pub fn axis_name(v: Vec3) -> String {
    for (k, n) in ["x", "y", "z"].iter().enumerate() {
        if (v[k].abs() - 1.0).abs() < 1e-6 {
            return format!("{}{n}", if v[k] > 0.0 { "+" } else { "−" });
        }
    }
    format!("[{:.2}, {:.2}, {:.2}]", v.x, v.y, v.z)
}

/// Roll, pitch, yaw of a rotation (R = Rz(yaw)·Ry(pitch)·Rx(roll), as `wrist.init_rpy`); at pitch
/// ±90° (where only roll − yaw is defined) yaw is 0.
pub fn rpy_of(rot: Quat) -> [f32; 3] {
    let m = Mat3::from_quat(rot);
    // r[i][j]: row i, column j
    let r = |i: usize, j: usize| m.col(j)[i];
    if r(2, 0).abs() < 1.0 - 1e-6 {
        let pitch = (-r(2, 0)).asin();
        [r(2, 1).atan2(r(2, 2)), pitch, r(1, 0).atan2(r(0, 0))]
    } else {
        // R = Ry(∓90°)·Rx(roll): r11 = cos roll, r12 = −sin roll
        let pitch = -r(2, 0).signum() * std::f32::consts::FRAC_PI_2;
        [(-r(1, 2)).atan2(r(1, 1)), pitch, 0.0]
    }
}

/// The initial wrist orientation for the hand (rule in the module documentation); `thumb` indexes
/// `hand.fingertips`. The hand needs at least one fingertip.
pub fn wrist_orientation(hand: &HandModel, thumb: usize) -> WristOrientation {
    let nt = hand.fingertips.len();
    let open = open_posture(hand);
    let own: Vec<Vec<usize>> = (0..nt).map(|i| own_joints(hand, i)).collect();
    let at_open = bases_and_tips(hand, &open);
    let base = |i: usize| at_open[i].0;
    let fingers: Vec<usize> = if nt > 1 { (0..nt).filter(|&i| i != thumb).collect() } else { vec![0] };
    // f: base → tip, averaged over the fingers
    let mut f = fingers.iter().map(|&i| (at_open[i].1 - base(i)).normalize_or_zero()).sum::<Vec3>();
    if f.length() < 1e-6 {
        f = fingers.iter().map(|&i| at_open[i].1).sum::<Vec3>();
    }
    let f = if f.length() < 1e-6 { Vec3::Z } else { snap(f) };
    // the closing motion: every finger's own joints a tenth of their range toward the far limit
    let mut closed = open.clone();
    for js in &own {
        for &j in js {
            let jt = &hand.joints[j];
            if jt.mimic.is_some() || !(jt.lower.is_finite() && jt.upper.is_finite()) || jt.upper - jt.lower < 1e-6 {
                continue;
            }
            let range = jt.upper - jt.lower;
            let mid = 0.5 * (jt.lower + jt.upper);
            if (open[j] - mid).abs() <= MID_RANGE_BAND * range {
                continue;
            }
            let toward = if jt.upper - open[j] >= open[j] - jt.lower { 1.0 } else { -1.0 };
            closed[j] = open[j] + toward * CLOSING_STEP * range;
        }
    }
    let at_closed = bases_and_tips(hand, &hand.with_mimic(closed));
    // dᵢ⊥ = dᵢ − (dᵢ·f) f
    let across: Vec<Vec3> = (0..nt)
        .map(|i| {
            let d = at_closed[i].1 - at_open[i].1;
            d - d.dot(f) * f
        })
        .collect();
    let total: f32 = across.iter().map(|d| d.length()).sum();
    let coherence = if total > 1e-9 { across.iter().sum::<Vec3>().length() / total } else { 0.0 };
    let (rot, palm, reason) = if coherence >= PALM_COHERENCE {
        // n: the fingers' closing direction across f, less its part along the line of their bases
        let mut n = fingers.iter().map(|&i| across[i]).sum::<Vec3>();
        if let Some(s) = spread_axis(&fingers.iter().map(|&i| base(i)).collect::<Vec<_>>(), f) {
            n -= n.dot(s) * s;
        }
        if n.length() < 1e-9 {
            n = across.iter().sum::<Vec3>();
        }
        let n = snap(n - n.dot(f) * f);
        // where only one of the two is an axis, the other is made square to it
        let is_axis = |v: Vec3| v.abs().max_element() > 1.0 - 1e-6;
        let (f, n) = if is_axis(n) && !is_axis(f) { ((f - f.dot(n) * n).normalize(), n) } else { (f, (n - n.dot(f) * f).normalize()) };
        // rows of R (world from root) are the root-frame directions that go to +x, +y, +z:
        // f → +x, n → −z, and y = z × x completes a right-handed frame
        let z = -n;
        let y = z.cross(f);
        let r = Mat3::from_cols(f, y, z).transpose();
        let rot = Quat::from_mat3(&r).normalize();
        let reason = format!(
            "fingers along {} of the root frame (the mean direction from each finger's base to its tip, thumb left out), palm normal {} (the side the fingers curl toward as their joints close: coherence {coherence:.2} ≥ {PALM_COHERENCE}); turned so that the palm faces down (−z) and the fingers point along +x",
            axis_name(f),
            axis_name(n)
        );
        (rot, true, reason)
    } else {
        let rot = Quat::from_rotation_arc(f, -Vec3::Z).normalize();
        let reason = format!(
            "fingers along {} of the root frame; they close toward each other (coherence of their closing directions {coherence:.2} < {PALM_COHERENCE}: a gripper or claw, no palm side), so the hand is turned by the smallest rotation that points them down (−z)",
            axis_name(f)
        );
        (rot, false, reason)
    };
    // rounded as the config writes it: a multiple of 90° as π/2 rounds (1.5707963), no −0
    let rpy = rpy_of(rot).map(|a| {
        let quarter = (a as f64 / std::f64::consts::FRAC_PI_2).round();
        let a = if (a as f64 - quarter * std::f64::consts::FRAC_PI_2).abs() < 1e-5 { quarter * std::f64::consts::FRAC_PI_2 } else { a as f64 };
        ((a * 1e7).round() / 1e7) as f32 + 0.0
    });
    WristOrientation { rot: crate::geom::quat_from_rpy(rpy), rpy, palm, reason }
}

/// The line the finger bases lie along (unit, across `f`): the principal axis of the bases, or
/// `None` for fewer than two fingers or bases that coincide.
fn spread_axis(bases: &[Vec3], f: Vec3) -> Option<Vec3> {
    if bases.len() < 2 {
        return None;
    }
    let c = bases.iter().sum::<Vec3>() / bases.len() as f32;
    let mut m = [[0.0f64; 3]; 3];
    for b in bases {
        let d = (*b - c).as_dvec3();
        for (i, row) in m.iter_mut().enumerate() {
            for (j, v) in row.iter_mut().enumerate() {
                *v += d[i] * d[j];
            }
        }
    }
    let (values, vectors) = crate::mesh::hull::symmetric_eigen(m);
    if values.x < 1e-12 {
        return None;
    }
    let s: DVec3 = vectors.x_axis;
    let s = s.as_vec3();
    let s = s - s.dot(f) * f;
    (s.length() > 1e-3).then(|| s.normalize())
}

/// How far (m, ≥ 0) the hand reaches below its wrist origin when the wrist is turned by `rot`,
/// the joints at `q`: the lowest point of its colliders (its fingertips where it has none).
pub fn reach_below_wrist(hand: &HandModel, rot: Quat, q: &[f32]) -> f32 {
    let links = hand.forward_kinematics(q);
    let mut lo = 0.0f32;
    for c in &hand.colliders {
        let pose = links[c.link].mul(&c.pose);
        let (pos, r) = (rot * pose.pos, rot * pose.rot);
        // support in −z: a sphere's r; a capsule's |axis·z| l + r; a box's Σ |R[2][k]| h_k
        let down = match c.shape {
            ColliderShape::Sphere { radius } => radius,
            ColliderShape::Capsule { radius, half_length } => (r * Vec3::Z).z.abs() * half_length + radius,
            ColliderShape::Box { half_extents: h } => (r * Vec3::X).z.abs() * h.x + (r * Vec3::Y).z.abs() * h.y + (r * Vec3::Z).z.abs() * h.z,
        };
        lo = lo.min(pos.z - down);
    }
    if hand.colliders.is_empty() {
        for t in &hand.fingertips {
            lo = lo.min((rot * links[t.link].transform_point(t.pos)).z);
        }
    }
    -lo
}

/// Clearance (m) between the open hand's lowest point and the object's top at the start: room for
/// the fingers to open around the object as the hand comes down (with 5 cm, `traj synth`'s
/// approach to the Ability hand's grasp touched the cube).
pub const START_CLEARANCE_M: f32 = 0.10;

/// The wrist height (m) that puts the open hand's lowest point [`START_CLEARANCE_M`] above an
/// object whose top is at `object_top` (m), rounded up to the centimetre.
pub fn start_height(hand: &HandModel, rot: Quat, object_top: f32) -> f32 {
    let z = object_top + START_CLEARANCE_M + reach_below_wrist(hand, rot, &open_posture(hand));
    (z * 100.0 - 1e-3).ceil() / 100.0
}
