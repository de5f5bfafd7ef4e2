//! The reward terms of each task kind: their names in `[task.rewards]` and `metrics.csv`, formulas
//! and default weights. Plain data at the config's level (the config fills and checks
//! `[task.rewards]` from it); the task layer's twins take their term indices from it
//! ([`term_index`]) and the task layer's `spec` re-exports it.

use super::TaskKind;


/// One reward term of a task kind: its name in `[task.rewards]` and in `metrics.csv`
/// (`reward/<name>`), the formula of its raw value (the twins compute it; the weight multiplies
/// it) and its default weight.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RewardTerm {
    /// The name in `[task.rewards]`.
    pub name: &'static str,
    /// The raw value, as the twins compute it (docs/tasks.md "Reward terms").
    pub formula: &'static str,
    /// The weight when `[task.rewards]` is not given.
    pub default_weight: f32,
}

const fn term(name: &'static str, formula: &'static str, default_weight: f32) -> RewardTerm {
    RewardTerm { name, formula, default_weight }
}

/// The grasp terms every kind ends with (off by default): the fingertip forces beyond
/// `task.hand.grip_force_limit` and the hand–object penetration beyond
/// `task.hand.penetration_tolerance`, so that a policy can be kept from squeezing harder or sinking
/// deeper than a robot hand would. The twins write them at the last two term indices.
pub const GRIP_FORCE_FORMULA: &str = "Σ_tips max(F_tip − grip_force_limit, 0) (N; F_tip: the fingertip's normal force, averaged over the step's substeps)";
/// See [`GRIP_FORCE_FORMULA`].
pub const PENETRATION_FORMULA: &str = "max(d − penetration_tolerance, 0) · 1000 (mm; d: the step's deepest hand–object penetration)";

/// The lift task's terms, in output order (as tuned for the shipped configs).
pub const LIFT_TERMS: [RewardTerm; 8] = [
    term("reaching", "1 − tanh(reach_alpha · ‖p_palm − p_obj‖)", 1.0),
    term("lifting", "clamp(h, 0, success_height) · 100 (h: the object's lift in m; cm)", 0.5),
    term("contact", "1 when the thumb and another fingertip push on the object with > contact_force", 0.5),
    term("success", "1 while h ≥ success_height", 5.0),
    term("action_rate", "Σ (a_t − a_{t−1})²", -0.01),
    term("action_magnitude", "Σ a_t²", -0.001),
    term("grip_force", GRIP_FORCE_FORMULA, 0.0),
    term("penetration", PENETRATION_FORMULA, 0.0),
];

/// `track`'s terms, in output order (the papers' λ1 = λ2 = λ3 = 1, λ4 = 15; no lifting, no action
/// penalties by default).
pub const TRACK_TERMS: [RewardTerm; 9] = [
    term("hand_following", "R_f = β1 (1 − tanh(α1‖q − q̂‖)) + β2 (1 − tanh(α2‖x − x̂‖)) + β3 (1 − tanh(α3 φ))", 1.0),
    term("object_following", "R_o = exp(−α4‖T − T̂‖) + exp(−α5‖log(q̂⁻¹ ⊗ q)‖)", 1.0),
    term("contact", "1 when the thumb and another fingertip touch the object while the reference grasps", 1.0),
    term("success", "1 at the reference's end when the object is within success_pos_tol / success_rot_tol of its final pose", 15.0),
    term("lifting", "clamp(h, 0, success_height) · 100", 0.0),
    term("action_rate", "Σ (a_t − a_{t−1})²", 0.0),
    term("action_magnitude", "Σ a_t²", 0.0),
    term("grip_force", GRIP_FORCE_FORMULA, 0.0),
    term("penetration", PENETRATION_FORMULA, 0.0),
];

/// `residual_joint`'s terms, in output order: `w_p r_obj-p + w_r r_obj-r − λ_a‖δ‖²` with
/// w_p = w_r = λ_a = 1 (the residual term is ‖δ‖², so its weight is −λ_a).
pub const RESIDUAL_JOINT_TERMS: [RewardTerm; 6] = [
    term("object_pos", "exp(−obj_pos_coef · e_p)", 1.0),
    term("object_rot", "exp(−obj_rot_coef · e_R)", 1.0),
    term("residual", "‖δ‖² (the applied residual, every component)", -1.0),
    term("success", "1 at the reference's end when the object is within the success tolerances", 0.0),
    term("grip_force", GRIP_FORCE_FORMULA, 0.0),
    term("penetration", PENETRATION_FORMULA, 0.0),
];

/// `residual_task`'s terms, in output order: DexRefine's w_obj 30, w_hand 10, w_wrist 5,
/// w_contact 0.05 and small penalties.
pub const RESIDUAL_TASK_TERMS: [RewardTerm; 10] = [
    term("object", "exp(−a_pos e_p − a_rot e_R), gated by contact or e_p ≤ success_pos_tol", 30.0),
    term("fingertips", "exp(−a e_tips) (e_tips: the mean fingertip distance)", 10.0),
    term("wrist", "exp(−a_pos e_p − a_rot e_R) of the wrist", 5.0),
    term("contact", "1 when the thumb and another fingertip touch the object while the reference grasps", 0.05),
    term("velocity", "Σ q̇² (actuated joints)", -1e-3),
    term("torque", "Σ τ² (the servos' torques)", -1e-2),
    term("work", "Σ |τ q̇|", -1e-2),
    term("table_collision", "1 when a hand collider touches the table", -1.0),
    term("grip_force", GRIP_FORCE_FORMULA, 0.0),
    term("penetration", PENETRATION_FORMULA, 0.0),
];

/// The reward terms of a task kind, in the order the twins write them.
pub fn reward_terms(kind: TaskKind) -> &'static [RewardTerm] {
    match kind {
        TaskKind::Lift => &LIFT_TERMS,
        TaskKind::Track => &TRACK_TERMS,
        TaskKind::ResidualJoint => &RESIDUAL_JOINT_TERMS,
        TaskKind::ResidualTask => &RESIDUAL_TASK_TERMS,
    }
}

/// The index of term `name` in `terms` (a compile-time lookup: the twins' term indices come from
/// the tables, so a renamed or reordered term cannot leave an index behind).
pub const fn term_index(terms: &[RewardTerm], name: &str) -> usize {
    let mut i = 0;
    while i < terms.len() {
        if str_eq(terms[i].name, name) {
            return i;
        }
        i += 1;
    }
    panic!("no such reward term")
}

const fn str_eq(a: &str, b: &str) -> bool {
    let (a, b) = (a.as_bytes(), b.as_bytes());
    if a.len() != b.len() {
        return false;
    }
    let mut i = 0;
    while i < a.len() {
        if a[i] != b[i] {
            return false;
        }
        i += 1;
    }
    true
}
