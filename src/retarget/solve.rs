//! The retargeting solve: per frame, the robot hand's wrist rotation and joint angles whose
//! keypoint vectors match the human hand's (dex-retargeting's vector method), within the joint
//! limits, pulled toward the previous frame, warm-started from it.
//!
//! **Keypoints and vectors.** [`RetargetSpec::points`] pairs each human keypoint i with a point
//! on a robot link (`link`, `offset` in the link's frame); [`RetargetSpec::pairs`] lists the
//! vectors compared, origin → target (wrist → fingertip, knuckle → fingertip, one finger segment),
//! each with a weight. The residual of pair p at wrist rotation R and joints q is
//! `wₚ · (R · (P_t(q) − P_o(q)) − s · (h_t − h_o))`: robot vector (wrist frame, rotated into the
//! world) against the human vector scaled by s (`scale`: the robot's size over the human's).
//! Vectors, not positions, so that a hand of another size still bends its fingers as the human's.
//!
//! **Solve** (Levenberg–Marquardt over x = [δ, q_a]: δ a rotation vector applied on top of the
//! frame's starting rotation, q_a the actuated joints; mimic followers follow their leaders): cost
//! ½ Σ |rₚ|² + ½ λ_s |q_a − q_prev|² + ½ λ_s |δ|² (`smooth`: the pull toward the previous frame,
//! whose rotation is the start), Jacobian by forward differences, steps clamped into the joint
//! limits (a projected step) and taken only where the cost falls (else μ ×10; on success μ ÷3).
//! The wrist's position is fitted last: the translation that puts the robot's keypoints on the
//! scaled human ones in the least-squares sense (their centroids coincide).
//!
//! **Start.** The first frame's rotation comes from a palm frame built on three keypoints
//! ([`RetargetSpec::palm`]: wrist and two knuckles) of the human hand and of the robot at its
//! starting joints; its joints start at `q_start` (the hand's default posture). Each later frame
//! starts from the previous one's solution.

use anyhow::{Result, ensure};
use glam::{Mat3, Quat, Vec3};

use crate::env::common::quat_rotate;
use crate::env::SimModel;
use crate::env::physics::Model;
use crate::hand::MAX_JOINTS;
use crate::task::ik::{IkScratch, ik_apply_mimic, ik_link_poses};

/// A point on a robot link: `offset` in link `link`'s frame (link 0: the wrist).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RobotPoint {
    /// The link (the simulator's link index: 0 the root, l > 0 moved by joint l − 1).
    pub link: usize,
    /// The point in the link's frame (m).
    pub offset: Vec3,
}

/// One vector compared: keypoint `origin` → keypoint `target`, weighted.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VectorPair {
    /// The vector's origin (an index into the keypoints).
    pub origin: usize,
    /// Its end.
    pub target: usize,
    /// Its weight in the cost.
    pub weight: f32,
}

/// What the solve matches: the robot point of each human keypoint, the vectors, the scale.
#[derive(Clone, Debug)]
pub struct RetargetSpec {
    /// The robot point of human keypoint i, for each keypoint the solve uses (`points[i]`).
    pub points: Vec<RobotPoint>,
    /// The vectors compared.
    pub pairs: Vec<VectorPair>,
    /// The keypoints of the palm frame that starts the first frame: the wrist and two knuckles on
    /// either side of the palm.
    pub palm: [usize; 3],
    /// The robot's size over the human's (a human vector is scaled by it).
    pub scale: f32,
    /// The pull toward the previous frame (weight of |q − q_prev|² and |δ|², rad⁻²·m²).
    pub smooth: f32,
    /// Levenberg–Marquardt iterations per frame, at most.
    pub iterations: usize,
}

/// One retargeted frame.
#[derive(Clone, Debug)]
pub struct RetargetFrame {
    /// The wrist's position and rotation (world frame).
    pub wrist_pos: Vec3,
    pub wrist_rot: Quat,
    /// Every model joint (followers from their leaders).
    pub q: [f32; MAX_JOINTS],
    /// Each keypoint's distance from its human keypoint (scaled, after the wrist's fit; m).
    pub keypoint_error: Vec<f32>,
    /// Each pair's vector error |R (P_t − P_o) − s (h_t − h_o)| (m).
    pub vector_error: Vec<f32>,
    /// Iterations taken.
    pub iterations: usize,
}

/// The robot's keypoints in the wrist frame at `q`.
fn robot_points(m: &Model, spec: &RetargetSpec, q: &[f32; MAX_JOINTS], s: &mut IkScratch) -> Vec<Vec3> {
    ik_link_poses(m, q, s);
    spec.points.iter().map(|p| s.link_pos[p.link] + quat_rotate(s.link_rot[p.link], p.offset)).collect()
}

/// The spec's robot keypoints in the wrist frame at joints `q` (every model joint).
pub fn robot_keypoints(model: &SimModel, spec: &RetargetSpec, q: &[f32; MAX_JOINTS]) -> Vec<Vec3> {
    robot_points(&model.view(), spec, q, &mut IkScratch::default())
}

/// An orthonormal palm frame on three points: x from the wrist toward the knuckles' midpoint, z
/// the palm's normal, y completing it.
fn palm_frame(w: Vec3, a: Vec3, b: Vec3) -> Mat3 {
    let x = ((a + b) * 0.5 - w).normalize_or_zero();
    let z = (a - w).cross(b - w).normalize_or_zero();
    let y = z.cross(x).normalize_or_zero();
    Mat3::from_cols(x, y, x.cross(y))
}

/// Rotation by the rotation vector `v` (angle |v| about v).
fn rotation(v: Vec3) -> Quat {
    let angle = v.length();
    if angle < 1e-12 { Quat::IDENTITY } else { Quat::from_axis_angle(v / angle, angle) }
}

/// Solves `a x = b` for a symmetric positive definite `a` (n × n, row-major) by Cholesky; None
/// where it is not positive definite.
fn cholesky_solve(a: &[f64], b: &[f64], n: usize) -> Option<Vec<f64>> {
    let mut l = vec![0.0f64; n * n];
    for i in 0..n {
        for j in 0..=i {
            let mut sum = a[i * n + j];
            for k in 0..j {
                sum -= l[i * n + k] * l[j * n + k];
            }
            if i == j {
                if sum <= 0.0 {
                    return None;
                }
                l[i * n + i] = sum.sqrt();
            } else {
                l[i * n + j] = sum / l[j * n + j];
            }
        }
    }
    // L y = b, then Lᵀ x = y
    let mut y = vec![0.0f64; n];
    for i in 0..n {
        y[i] = (b[i] - (0..i).map(|k| l[i * n + k] * y[k]).sum::<f64>()) / l[i * n + i];
    }
    let mut x = vec![0.0f64; n];
    for i in (0..n).rev() {
        x[i] = (y[i] - (i + 1..n).map(|k| l[k * n + i] * x[k]).sum::<f64>()) / l[i * n + i];
    }
    Some(x)
}

/// The solver's state for one frame: the starting rotation, the previous frame's joints.
struct Problem<'a> {
    m: &'a Model<'a>,
    spec: &'a RetargetSpec,
    /// The human keypoints, scaled.
    human: Vec<Vec3>,
    /// The rotation δ is applied on (the previous frame's, or the palm frames' for the first).
    start_rot: Quat,
    /// The previous frame's actuated joints (the smoothness term's anchor).
    prev: Vec<f32>,
    joints: Vec<usize>,
}

impl Problem<'_> {
    /// Every model joint from the actuated ones (followers from their leaders).
    fn full_q(&self, qa: &[f32]) -> [f32; MAX_JOINTS] {
        let mut q = [0.0f32; MAX_JOINTS];
        for (&j, &v) in self.joints.iter().zip(qa) {
            q[j] = v;
        }
        ik_apply_mimic(self.m, &mut q);
        q
    }

    /// The residual vector at x = [δ, q_a]: the pairs' (3 each), then the smoothness terms.
    fn residuals(&self, x: &[f64], s: &mut IkScratch) -> Vec<f64> {
        let rot = rotation(Vec3::new(x[0] as f32, x[1] as f32, x[2] as f32)) * self.start_rot;
        let qa: Vec<f32> = x[3..].iter().map(|&v| v as f32).collect();
        let pts = robot_points(self.m, self.spec, &self.full_q(&qa), s);
        let mut r = Vec::with_capacity(3 * self.spec.pairs.len() + x.len());
        for p in &self.spec.pairs {
            // wₚ (R (P_t − P_o) − s (h_t − h_o))
            let e = (rot * (pts[p.target] - pts[p.origin]) - (self.human[p.target] - self.human[p.origin])) * p.weight;
            r.extend([e.x as f64, e.y as f64, e.z as f64]);
        }
        let w = (self.spec.smooth as f64).sqrt();
        r.extend(x[..3].iter().map(|&d| w * d)); // √λ_s δ
        r.extend(x[3..].iter().zip(&self.prev).map(|(&q, &p)| w * (q - p as f64))); // √λ_s (q − q_prev)
        r
    }

    /// Projects x into the joint limits (the rotation is free).
    fn clamp(&self, x: &mut [f64]) {
        for (v, &j) in x[3..].iter_mut().zip(&self.joints) {
            let jd = &self.m.joints[j];
            *v = v.clamp(jd.lower as f64, jd.upper as f64);
        }
    }
}

/// Retargets one frame of human `keypoints` (world frame, `spec.points.len()` of them): from
/// `start_rot` and joints `q_start` (every model joint), pulled toward `q_start`.
pub fn retarget_frame(model: &SimModel, spec: &RetargetSpec, keypoints: &[Vec3], start_rot: Quat, q_start: &[f32; MAX_JOINTS]) -> Result<RetargetFrame> {
    let m = &model.view();
    ensure!(keypoints.len() == spec.points.len(), "{} keypoints for {} robot points", keypoints.len(), spec.points.len());
    ensure!(keypoints.iter().all(|k| k.is_finite()), "a keypoint is not finite");
    let joints = model.hand.actuated_joints();
    let prev: Vec<f32> = joints.iter().map(|&j| q_start[j]).collect();
    let human: Vec<Vec3> = keypoints.iter().map(|&k| k * spec.scale).collect();
    let problem = Problem { m, spec, human, start_rot, prev: prev.clone(), joints };
    let mut s = IkScratch::default();
    let n = 3 + problem.joints.len();
    let mut x: Vec<f64> = [0.0, 0.0, 0.0].into_iter().chain(prev.iter().map(|&v| v as f64)).collect();
    problem.clamp(&mut x);
    let cost = |r: &[f64]| 0.5 * r.iter().map(|v| v * v).sum::<f64>();
    let mut r = problem.residuals(&x, &mut s);
    let mut c = cost(&r);
    let mut mu = 1e-3;
    let mut taken = 0;
    for it in 0..spec.iterations {
        taken = it + 1;
        // J by forward differences: ∂r/∂xᵢ ≈ (r(x + h eᵢ) − r(x)) / h
        let h = 1e-4;
        let rows = r.len();
        let mut jac = vec![0.0f64; rows * n];
        for i in 0..n {
            let mut xh = x.clone();
            xh[i] += h;
            let rh = problem.residuals(&xh, &mut s);
            for k in 0..rows {
                jac[k * n + i] = (rh[k] - r[k]) / h;
            }
        }
        // JᵀJ and Jᵀr
        let mut jtj = vec![0.0f64; n * n];
        let mut jtr = vec![0.0f64; n];
        for k in 0..rows {
            let row = &jac[k * n..(k + 1) * n];
            for i in 0..n {
                jtr[i] += row[i] * r[k];
                for j in 0..=i {
                    jtj[i * n + j] += row[i] * row[j];
                }
            }
        }
        for i in 0..n {
            for j in 0..i {
                jtj[j * n + i] = jtj[i * n + j];
            }
        }
        let mut improved = false;
        let mut settled = false;
        for _ in 0..8 {
            // (JᵀJ + μ diag(JᵀJ) + μ I) Δ = −Jᵀr
            let mut a = jtj.clone();
            for i in 0..n {
                a[i * n + i] += mu * (jtj[i * n + i] + 1.0);
            }
            let Some(step) = cholesky_solve(&a, &jtr.iter().map(|v| -v).collect::<Vec<_>>(), n) else {
                mu *= 10.0;
                continue;
            };
            let mut xn: Vec<f64> = x.iter().zip(&step).map(|(a, b)| a + b).collect();
            problem.clamp(&mut xn);
            let rn = problem.residuals(&xn, &mut s);
            let cn = cost(&rn);
            if cn < c {
                let moved = x.iter().zip(&xn).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
                (x, r, c) = (xn, rn, cn);
                mu = (mu / 3.0).max(1e-9);
                improved = true;
                settled = moved < 1e-7;
                break;
            }
            mu *= 10.0;
        }
        if !improved || settled || c < 1e-16 {
            break;
        }
    }
    let rot = rotation(Vec3::new(x[0] as f32, x[1] as f32, x[2] as f32)) * start_rot;
    let qa: Vec<f32> = x[3..].iter().map(|&v| v as f32).collect();
    let q = problem.full_q(&qa);
    let pts = robot_points(m, spec, &q, &mut s);
    // the wrist's position: the centroids of the robot's and the scaled human keypoints coincide
    let count = pts.len().max(1) as f32;
    let wrist_pos = problem.human.iter().zip(&pts).map(|(h, p)| *h - rot * *p).sum::<Vec3>() / count;
    let keypoint_error = problem.human.iter().zip(&pts).map(|(h, p)| (wrist_pos + rot * *p - *h).length()).collect();
    let vector_error = spec
        .pairs
        .iter()
        .map(|p| (rot * (pts[p.target] - pts[p.origin]) - (problem.human[p.target] - problem.human[p.origin])).length())
        .collect();
    Ok(RetargetFrame { wrist_pos, wrist_rot: rot, q, keypoint_error, vector_error, iterations: taken })
}

/// The first frame's starting rotation: the human palm frame against the robot's at `q_start`;
/// an error where either palm's three keypoints are (nearly) on one line.
pub fn palm_rotation(model: &SimModel, spec: &RetargetSpec, keypoints: &[Vec3], q_start: &[f32; MAX_JOINTS]) -> Result<Quat> {
    let [w, a, b] = spec.palm;
    ensure!(w.max(a).max(b) < keypoints.len() && w.max(a).max(b) < spec.points.len(), "palm keypoints {:?} for {} keypoints", spec.palm, keypoints.len());
    let pts = robot_keypoints(model, spec, q_start);
    let human = palm_frame(keypoints[w], keypoints[a], keypoints[b]);
    let robot = palm_frame(pts[w], pts[a], pts[b]);
    for (who, f) in [("the human", human), ("the robot", robot)] {
        ensure!((f.determinant() - 1.0).abs() < 1e-3, "{who}'s palm keypoints {:?} are on one line: no palm frame", spec.palm);
    }
    // R robot = human  ⇒  R = human · robotᵀ
    Ok(Quat::from_mat3(&(human * robot.transpose())).normalize())
}

/// Retargets a sequence of frames: the first from the palm frames and `q_start`, each later one
/// warm-started from (and pulled toward) the previous solution.
pub fn retarget_sequence(model: &SimModel, spec: &RetargetSpec, frames: &[Vec<Vec3>], q_start: &[f32; MAX_JOINTS]) -> Result<Vec<RetargetFrame>> {
    let mut out: Vec<RetargetFrame> = Vec::with_capacity(frames.len());
    for (i, k) in frames.iter().enumerate() {
        let (rot, q) = match out.last() {
            Some(prev) => (prev.wrist_rot, prev.q),
            None => (palm_rotation(model, spec, k, q_start).map_err(|e| anyhow::anyhow!("frame {i}: {e}"))?, *q_start),
        };
        let f = retarget_frame(model, spec, k, rot, &q).map_err(|e| anyhow::anyhow!("frame {i}: {e}"))?;
        out.push(f);
    }
    Ok(out)
}
