//! Whether a hand can hold an object in a planned grasp (issue 36): the statics `traj synth` says
//! when no grasp variant lifts the object, so that "cannot be held" comes with its reason.
//!
//! In the grasp posture each fingertip pushes along its contact normal, into the object. Through
//! the kinematics a push F along the inward normal −n at fingertip i asks each actuated joint a
//! for τ_a = F (∂p_i/∂q_a · −n): the leader of a mimic-coupled chain carries its followers' share,
//! as the derivative is taken through the coupling. So the largest push of fingertip i within the
//! effort limits is F_i = min_a effort_a / |∂p_i/∂q_a · n|. The thumb balances the other
//! fingertips across the object, so the squeeze is S = min(F_thumb, Σ F_fingers), and friction on
//! both sides holds at most 2 μ S of weight (μ: the hand–object friction of the physics, the mean
//! of the hand's and the object's coefficients).

use glam::Vec3;

use super::grasp::{GraspPlan, pad_points};
use crate::env::SimModel;
use crate::env::reset::reset_params;
use crate::gpu::layout::NO_JOINT;
use crate::hand::MAX_JOINTS;
use crate::task::ik::{ik_apply_mimic, ik_tip_positions};

/// Step (rad) of the finite differences of the fingertips' positions.
const DQ: f32 = 1e-3;

/// What the hand can hold in one planned grasp.
#[derive(Clone, Debug, PartialEq)]
pub struct HoldCapacity {
    /// The largest push (N) of each fingertip along its contact normal within its joints' effort
    /// limits (f32::INFINITY for a fingertip that no joint moves along its normal).
    pub tip_push: Vec<f32>,
    /// The index of the thumb in `tip_push`.
    pub thumb: usize,
    /// The other fingertips' pushes added up (N).
    pub fingers_push: f32,
    /// The squeeze (N) the thumb and the other fingertips balance across the object.
    pub squeeze: f32,
    /// The hand–object friction coefficient.
    pub mu: f32,
    /// The weight (N) that squeeze holds by friction on both sides: 2 μ S.
    pub holds: f32,
    /// The object's weight (N).
    pub weight: f32,
}

impl HoldCapacity {
    /// One line: the pushes, the squeeze, what it holds against the weight.
    pub fn describe(&self) -> String {
        format!(
            "within the effort limits the thumb pushes at most {:.1} N against the other fingertips' {:.1} N, a squeeze of {:.1} N that friction (μ = {:.2}) turns into {:.1} N of hold, against the object's weight of {:.1} N",
            self.tip_push[self.thumb], self.fingers_push, self.squeeze, self.mu, self.holds, self.weight
        )
    }
}

/// The hold capacity of `plan` for `model`'s hand and first object (its nominal mass; the
/// friction of env 0's parameters).
pub fn hold_capacity(model: &SimModel, plan: &GraspPlan) -> HoldCapacity {
    let nt = model.hand.fingertips.len();
    let nj = model.joints.len();
    // the pads are what touch the object (the planner's fingertip points)
    let mut pads = model.clone();
    for (td, p) in pads.tips.iter_mut().zip(pad_points(&model.hand)) {
        td.pos = [p.x, p.y, p.z, 0.0];
    }
    let m = pads.view();
    let mut q = [0.0f32; MAX_JOINTS];
    q[..nj].copy_from_slice(&plan.grasp[..nj]);
    let tips = |q: &[f32; MAX_JOINTS]| -> Vec<Vec3> { ik_tip_positions(&m, q, &mut Default::default())[..nt].iter().map(|p| plan.wrist.rot * *p).collect() };
    let base = tips(&q);
    let mut tip_push = vec![f32::INFINITY; nt];
    for (a, jd) in model.joints.iter().enumerate() {
        if jd.mimic_leader != NO_JOINT {
            continue;
        }
        let mut qa = q;
        qa[a] += DQ;
        ik_apply_mimic(&m, &mut qa);
        let moved = tips(&qa);
        for i in 0..nt {
            // ∂p_i/∂q_a · n: the torque per newton of push along the normal
            let lever = ((moved[i] - base[i]) / DQ).dot(plan.normals[i]).abs();
            if lever > 1e-6 {
                tip_push[i] = tip_push[i].min(jd.effort / lever);
            }
        }
    }
    let fingers_push: f32 = tip_push.iter().enumerate().filter(|(i, _)| *i != plan.thumb).map(|(_, f)| *f).sum();
    let squeeze = tip_push[plan.thumb].min(fingers_push);
    let p = reset_params(&model.globals, &model.object_descs, &[], 0, 0);
    let mu = 0.5 * (p.hand_friction + p.obj_friction);
    // the planned object's weight: the first, as the planner grasps it (env 0's draw may be another
    // of an object set)
    let weight = model.objects[0].mass * model.globals.gravity;
    HoldCapacity { tip_push, thumb: plan.thumb, fingers_push, squeeze, mu, holds: 2.0 * mu * squeeze, weight }
}
