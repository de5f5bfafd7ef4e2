//! `dextrain traj synth`: scripted approach–grasp–lift references for a config's hand and object.
//!
//! The script (times in seconds, keyframes at the phase boundaries, interpolated by
//! [`Trajectory::sample`]):
//! 1. `0 → approach`: the wrist moves from its initial pose to the grasp pose above the object with
//!    the hand open (joints at their defaults);
//! 2. `→ + close`: the hand closes to the grasp posture (the wrist holds);
//! 3. `→ + settle`: hold;
//! 4. `→ + lift`: the wrist rises by `lift` metres; the object reference rises with it;
//! 5. `→ + hold`: hold at the top.
//!
//! The grasp (`--grasp`, [`GraspChoice`]):
//! - `antipodal` (the default): planned from the hand's own kinematics by
//!   [`super::grasp::plan_grasp`] (the thumb and the other fingertips on opposite faces, reached by
//!   the fingertip IK, the closing motion moving the fingertips through their contact points), the
//!   same way for every hand. The wrist descends onto the grasp pose from `HOVER_M` above it in the
//!   pre-grasp posture (the last `DESCENT_FRACTION` of the approach), and the closing phase passes
//!   through the plan's closing postures. The variants of [`super::grasp::GRASP_VARIANTS`] are
//!   tried in order, each reference replayed under the config's physics (one env, nominal object
//!   place, no randomisation; 10–30 ms each, the model built once); the first that lifts the object
//!   `VERIFY_LIFT_FRACTION` of `--lift` with less than `VERIFY_PEAK_PENETRATION_MM` is written
//!   (else the best, with a warning). It lifts every hand of `../shared/hands/` (BENCHMARKS.md,
//!   "Real hands").
//! - `envelope`: the palm on a side face of the object and the fingers closed around it
//!   ([`envelope::plan_envelope`]; the hand turns on its side on the way in), the variants of
//!   [`envelope::ENVELOPE_VARIANTS`] checked in simulation as above. `antipodal` falls back to them
//!   when no fingertip variant passes (a heavy, tall object: the thumb's push limits a fingertip
//!   grasp, the fingers' pull and the arm's push an enveloping one).
//! - `posture`: for our dexhand16 a tuned pinch (thumb against three fingers, targets past the
//!   object so the servos squeeze at their effort limit); for any other hand every actuated joint
//!   goes `close` of the way from its lower to its upper limit (URDF flexion positive toward the
//!   palm). The wrist is placed so that the centre of the fingertips' bounding box, in the grasp
//!   posture, sits at the object's centre: the closing fingers stall on the object's sides.
//!
//! Mimic followers are `multiplier × leader + offset` in every keyframe (the open one included).

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use glam::{Quat, Vec3};

pub mod envelope;
pub mod grasp;
pub mod hold;

use envelope::{ENVELOPE_VARIANTS, plan_envelope};
use grasp::{GRASP_VARIANTS, HOVER_M, initial_wrist, object_centre, open_posture, plan_grasp};
use crate::traj::perturb::{PerturbArgs, perturb};
use crate::traj::{Keyframe, Trajectory};
use crate::config::Config;
use crate::env::SimModel;
use crate::geom::Pose;

/// Arguments of `dextrain traj synth`.
#[derive(clap::Args, Debug, Clone)]
pub struct SynthArgs {
    /// Config whose hand, object and initial wrist pose the reference is for.
    pub config: PathBuf,
    /// Output file (.mcap or .csv).
    #[arg(long)]
    pub out: PathBuf,
    /// How far the wrist (and the object) rise (m).
    #[arg(long, default_value_t = 0.15)]
    pub lift: f32,
    /// Seconds of the approach phase.
    #[arg(long, default_value_t = 1.0)]
    pub approach: f32,
    /// Seconds of the closing phase.
    #[arg(long, default_value_t = 0.8)]
    pub close: f32,
    /// Seconds of the lift phase.
    #[arg(long, default_value_t = 1.5)]
    pub lift_time: f32,
    /// Seconds of the final hold.
    #[arg(long, default_value_t = 1.0)]
    pub hold: f32,
    /// For hands other than dexhand16 under `--grasp posture`: fraction of each actuated joint's
    /// range the grasp closes to.
    #[arg(long, default_value_t = 0.6)]
    pub close_fraction: f32,
    /// How the grasp is made: `antipodal` (planned on the object's faces by the fingertip IK and
    /// checked in simulation) or `posture` (a closing posture, see the module docs).
    #[arg(long, value_enum, default_value_t = GraspChoice::Antipodal)]
    pub grasp: GraspChoice,
    /// Number of references to write. Above 1, `--out` is a directory that receives
    /// `ref_000.mcap`, `ref_001.mcap`, …, each perturbed with its own draws (see `traj::perturb`).
    #[arg(long, default_value_t = 1)]
    pub count: usize,
    /// Seed of the perturbations.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Override a config value, as `train --set` does: `--set hand.urdf="/path/to/hand.urdf"`
    /// (repeatable).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    pub sets: Vec<String>,
    /// Retargeting-like errors on the hand part (the object part stays clean).
    #[command(flatten)]
    pub perturb: PerturbArgs,
}

/// How `traj synth` makes its grasp (see the module documentation).
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum GraspChoice {
    /// Thumb and fingertips on opposite faces of the object, reached by the fingertip IK.
    #[default]
    Antipodal,
    /// Close every joint to a posture (dexhand16's tuned pinch, or a fraction of each range).
    Posture,
    /// The palm on a side face of the object and the fingers closed around it (`synth::envelope`),
    /// checked in simulation; the `antipodal` choice falls back to it when no fingertip grasp lifts.
    Envelope,
}

/// Fraction of the approach phase the `antipodal` grasp spends descending onto the grasp pose.
pub const DESCENT_FRACTION: f64 = 0.4;

impl SynthArgs {
    /// The defaults for a config file (those of the command line).
    pub fn defaults(config: PathBuf, out: PathBuf) -> SynthArgs {
        SynthArgs { config, out, lift: 0.15, approach: 1.0, close: 0.8, lift_time: 1.5, hold: 1.0, close_fraction: 0.6, grasp: GraspChoice::Antipodal, count: 1, seed: 0, sets: vec![], perturb: PerturbArgs::default() }
    }

    /// The defaults with `--grasp posture`.
    pub fn posture(config: PathBuf, out: PathBuf) -> SynthArgs {
        SynthArgs { grasp: GraspChoice::Posture, ..SynthArgs::defaults(config, out) }
    }
}

/// The tuned pinch of dexhand16: thumb against index, middle and ring. Closed in free space, the
/// distal links would lie horizontal 9 cm below the palm with the tips 8 mm past the centre line,
/// i.e. 1.7 cm inside a 5 cm cube: they stall on its sides at mid height and squeeze.
const DEXHAND_GRASP: &[(&str, f32)] = &[
    ("if_j0", 0.1), ("if_j1", 1.6), ("if_j2", 0.62), ("if_j3", 0.8),
    ("mf_j0", 0.0), ("mf_j1", 1.6), ("mf_j2", 0.62), ("mf_j3", 0.8),
    ("rf_j0", -0.1), ("rf_j1", 1.6), ("rf_j2", 0.62), ("rf_j3", 0.8),
    ("th_j0", 0.0), ("th_j1", 1.32), ("th_j2", 0.96), ("th_j3", 0.88),
];

/// Joint targets of the grasp posture (HandModel joint order; followers follow their leaders).
pub fn grasp_posture(model: &SimModel, close_fraction: f32) -> Vec<f32> {
    let hand = &model.hand;
    let is_dexhand = DEXHAND_GRASP.iter().all(|(n, _)| hand.joint_index(n).is_some());
    let mut q: Vec<f32> = model.joints.iter().map(|j| j.default_q).collect();
    for (j, jd) in model.joints.iter().enumerate() {
        if is_dexhand {
            if let Some((_, v)) = DEXHAND_GRASP.iter().find(|(n, _)| *n == hand.joints[j].name) {
                q[j] = *v;
            }
        } else if jd.lower > -1e29 && jd.upper < 1e29 {
            q[j] = jd.lower + close_fraction * (jd.upper - jd.lower);
        }
    }
    hand.with_mimic(q)
}

/// The wrist pose (initial orientation) that puts the centre of the fingertips' bounding box, in the
/// posture `q`, at the object's nominal centre: closing to `q`, the fingers stall on its sides.
pub fn grasp_wrist_pose(model: &SimModel, q: &[f32]) -> Pose {
    let g = &model.globals;
    let rot = Quat::from_array(g.init_wrist_rot);
    let links = model.hand.forward_kinematics(q);
    let tips: Vec<Vec3> = model.hand.fingertips.iter().map(|t| rot * links[t.link].transform_point(t.pos)).collect();
    let lo = tips.iter().copied().fold(Vec3::splat(f32::INFINITY), Vec3::min);
    let hi = tips.iter().copied().fold(Vec3::splat(f32::NEG_INFINITY), Vec3::max);
    let obj = object_centre(model);
    Pose::new(obj - 0.5 * (lo + hi), rot)
}

/// Lift (fraction of `--lift`) the cube must reach when `traj synth --grasp antipodal` replays a
/// variant's reference, for that variant to be kept.
pub const VERIFY_LIFT_FRACTION: f32 = 0.6;
/// Peak penetration (mm) a kept variant's replay must stay under.
pub const VERIFY_PEAK_PENETRATION_MM: f64 = 3.0;

/// Builds the scripted reference for a config.
pub fn synth(cfg: &Config, args: &SynthArgs) -> Result<Trajectory> {
    for (name, v) in [("--approach", args.approach), ("--close", args.close), ("--lift-time", args.lift_time), ("--hold", args.hold)] {
        if !(v.is_finite() && v > 0.0) {
            bail!("{name} = {v}: expected a duration in seconds > 0");
        }
    }
    if !args.lift.is_finite() || args.lift < 0.0 || args.lift > 2.0 {
        bail!("--lift = {}: expected a height in m in [0, 2]", args.lift);
    }
    let model = SimModel::from_config(cfg)?;
    let hand = &model.hand;
    if hand.fingertips.is_empty() {
        bail!("{}: the hand has no fingertip frames; synth places the wrist from them", hand.source.display());
    }
    // a reference that starts with the hand inside the object knocks it over in its first step
    let g = &model.globals;
    let overlap = grasp::hand_object_depth(&model, &initial_wrist(&model), &open_posture(&model));
    if overlap > 0.0 {
        let (_, hi) = model.objects[0].bounding_box();
        bail!(
            "{}: wrist.init_pos = {:?}: the open hand there overlaps the object by {:.1} mm; expected a start clear of it (the object's top is at z = {:.3} m)",
            args.config.display(),
            &g.init_wrist_pos[..3],
            overlap * 1e3,
            g.obj_init[3] + hi.z
        );
    }
    match args.grasp {
        GraspChoice::Posture => {
            let closed = grasp_posture(&model, args.close_fraction);
            script(&model, args, grasp_wrist_pose(&model, &closed), vec![], vec![closed])
        }
        GraspChoice::Antipodal => antipodal(cfg, args, &model),
        GraspChoice::Envelope => {
            let checker = Verifier::new(cfg)?;
            match enveloping(args, &model, &checker)? {
                Ok(traj) => Ok(traj),
                Err((Some(best), _)) => {
                    crate::console::warn(&format!(
                        "warning: {}: no enveloping grasp lifted the object {:.3} m with less than {} mm penetration in simulation; writing the best: {}",
                        args.config.display(),
                        VERIFY_LIFT_FRACTION * args.lift,
                        VERIFY_PEAK_PENETRATION_MM,
                        best.about
                    ));
                    Ok(best.traj)
                }
                Err((None, e)) => bail!("{}: cannot plan an enveloping grasp: {:#}", args.config.display(), e.expect("a variant's error")),
            }
        }
    }
}

/// The replay that checks a planned reference: the config's physics on one env on the CPU, the
/// object at its nominal place, no randomisation.
struct Verifier {
    cfg: Config,
    model: SimModel,
}

impl Verifier {
    fn new(cfg: &Config) -> Result<Verifier> {
        let mut verify = cfg.clone();
        verify.sim.num_envs = 1;
        verify.sim.backend = crate::config::BackendChoice::Cpu;
        verify.object.xy_noise = [0.0, 0.0];
        verify.object.yaw_noise = 0.0;
        verify.randomization = Default::default();
        let model = SimModel::from_config(&verify)?;
        Ok(Verifier { cfg: verify, model })
    }

    /// The object's lift (m) and the peak hand–object penetration (mm) of `traj`'s replay.
    fn replay(&self, traj: &Trajectory, what: &str) -> Result<(f64, f64)> {
        let report = crate::replay::replay_with_model(&self.cfg, &self.model, traj, false, None).with_context(|| what.to_string())?;
        Ok((report.object_lift_m, report.peak_penetration_mm))
    }

    /// Whether a replay's lift and peak penetration pass the check.
    fn passes(args: &SynthArgs, lift: f64, pen: f64) -> bool {
        lift >= (VERIFY_LIFT_FRACTION * args.lift) as f64 && pen < VERIFY_PEAK_PENETRATION_MM
    }
}

/// A replayed reference that did not pass the check: its lift, and one line about it.
struct Attempt {
    lift: f64,
    traj: Trajectory,
    about: String,
}

/// The first of [`ENVELOPE_VARIANTS`] whose reference passes the replay check (`Ok`), else the one
/// that lifted the object highest, if any could be planned, and the first planning error, if any.
fn enveloping(args: &SynthArgs, model: &SimModel, checker: &Verifier) -> Result<std::result::Result<Trajectory, (Option<Attempt>, Option<anyhow::Error>)>> {
    let mut best: Option<Attempt> = None;
    let mut first_err = None;
    for (k, variant) in ENVELOPE_VARIANTS.iter().enumerate() {
        let plan = match plan_envelope(model, variant) {
            Ok(plan) => plan,
            Err(e) => {
                first_err.get_or_insert(e);
                continue;
            }
        };
        let t1 = args.approach as f64;
        let open = open_posture(model);
        let approach = vec![
            (t1 * ENVELOPE_ABOVE_AT, plan.approach[0], open.clone()),
            (t1 * ENVELOPE_BESIDE_AT, plan.approach[1], open.clone()),
            (t1, plan.wrist, open),
        ];
        let traj = script(model, args, plan.wrist, approach, plan.closing.clone())?;
        let held = plan.wrist.inverse().transform_point(object_centre(model));
        let about = format!(
            "enveloping variant {}/{} (palm on the {:?} face, {:+.1} of the half height about the centre of mass, pressed {:.0} mm, wrap axis {}), {} joints closed around the object ({} stopped on it); object centre in the wrist frame at the grasp: [{:.3}, {:.3}, {:.3}] m (task.hand.palm_offset)",
            k + 1,
            ENVELOPE_VARIANTS.len(),
            variant.face,
            variant.height,
            variant.press * 1e3,
            if variant.up > 0.0 { "up" } else { "down" },
            plan.flexing,
            plan.touching,
            held.x,
            held.y,
            held.z
        );
        if args.lift == 0.0 {
            crate::console::status(&format!("enveloping grasp: {about}"));
            return Ok(Ok(traj));
        }
        let (lift, pen) = checker.replay(&traj, &format!("{}: replaying enveloping grasp variant {}", args.config.display(), k + 1))?;
        let about = format!("{about}; in simulation it lifts the object {lift:.3} m, peak penetration {pen:.2} mm");
        if Verifier::passes(args, lift, pen) {
            crate::console::status(&format!("enveloping grasp: {about}"));
            return Ok(Ok(traj));
        }
        if best.as_ref().is_none_or(|b| lift > b.lift) {
            best = Some(Attempt { lift, traj, about });
        }
    }
    Ok(Err((best, first_err)))
}

/// Fractions of the approach phase at which the enveloping grasp's hand is above the object
/// (turned, out beside the face) and then beside the face at the grasp height; it reaches the
/// grasp pose at the end of the approach.
pub const ENVELOPE_ABOVE_AT: f64 = 0.45;
/// See [`ENVELOPE_ABOVE_AT`].
pub const ENVELOPE_BESIDE_AT: f64 = 0.75;

/// The `antipodal` reference: the first of [`GRASP_VARIANTS`] whose reference, replayed under the
/// config's physics (one env, the object at its nominal place, no randomisation), lifts the object
/// `VERIFY_LIFT_FRACTION` of `--lift` with less than `VERIFY_PEAK_PENETRATION_MM`; if none does,
/// the one that lifted it highest, with a warning.
fn antipodal(cfg: &Config, args: &SynthArgs, model: &SimModel) -> Result<Trajectory> {
    let hand = &model.hand;
    let checker = Verifier::new(cfg)?;
    let mut first_err = None;
    let mut best: Option<(f64, f64, Trajectory, String)> = None;
    // over the planned variants: the grasp that holds the most (statics), and the best reach
    let mut strongest: Option<hold::HoldCapacity> = None;
    let mut closest_reach = f32::INFINITY;
    for (k, variant) in GRASP_VARIANTS.iter().enumerate() {
        let plan = match plan_grasp(model, &cfg.task.hand.thumb, variant) {
            Ok(plan) => plan,
            Err(e) => {
                first_err.get_or_insert(e);
                continue;
            }
        };
        let capacity = hold::hold_capacity(model, &plan);
        let hold_ratio = capacity.holds / capacity.weight;
        if strongest.as_ref().is_none_or(|s| capacity.holds > s.holds) {
            strongest = Some(capacity);
        }
        closest_reach = closest_reach.min(plan.reach_error.iter().copied().fold(0.0, f32::max));
        let hover = Pose::new(plan.wrist.pos + Vec3::Z * HOVER_M, plan.wrist.rot);
        let pre = plan.closing[0].clone();
        let t1 = args.approach as f64;
        let approach = vec![(t1 * (1.0 - DESCENT_FRACTION), hover, pre.clone()), (t1, plan.wrist, pre)];
        let traj = script(model, args, plan.wrist, approach, plan.closing[1..].to_vec())?;
        // where the object sits in the wrist frame at the grasp: what `task.hand.palm_offset` names
        let held = plan.wrist.inverse().transform_point(object_centre(model));
        let errs: Vec<String> = hand.fingertips.iter().zip(&plan.reach_error).map(|(t, e)| format!("{} {:.1}", t.name, e * 1e3)).collect();
        let about = format!(
            "variant {}/{} ({:?}, contacts at {:+.1} of the half height, squeeze {:.0} mm, palm {:.0} mm above the object), thumb '{}', fingertip distance from its contact point (mm): {}; object centre in the wrist frame at the grasp: [{:.3}, {:.3}, {:.3}] m (task.hand.palm_offset); it holds {hold_ratio:.1}× the object's weight in statics",
            k + 1,
            GRASP_VARIANTS.len(),
            variant.opposition,
            variant.height,
            variant.squeeze * 1e3,
            variant.palm_clearance * 1e3,
            hand.fingertips[plan.thumb].name,
            errs.join(", "),
            held.x,
            held.y,
            held.z
        );
        if args.lift == 0.0 {
            crate::console::status(&format!("antipodal grasp: {about}"));
            return Ok(traj);
        }
        let (lift, pen) = checker.replay(&traj, &format!("{}: replaying grasp variant {}", args.config.display(), k + 1))?;
        if Verifier::passes(args, lift, pen) {
            crate::console::status(&format!("antipodal grasp: {about}; in simulation it lifts the object {:.3} m, peak penetration {pen:.2} mm", lift));
            return Ok(traj);
        }
        if best.as_ref().is_none_or(|(l, _, _, _)| lift > *l) {
            best = Some((lift, pen, traj, format!("{about}; in simulation it lifts the object {lift:.3} m, peak penetration {pen:.2} mm")));
        }
    }
    // no fingertip grasp passed: the enveloping grasps, the palm on a face and the fingers around
    let (envelope_best, envelope_err) = match enveloping(args, model, &checker)? {
        Ok(traj) => return Ok(traj),
        Err(miss) => miss,
    };
    let envelope_line = match (&envelope_best, envelope_err) {
        (Some(e), _) => format!("nor did an enveloping grasp (the best: {})", e.about),
        (None, Some(e)) => format!("and no enveloping grasp could be planned ({e:#})"),
        (None, None) => "and no enveloping grasp could be planned".to_string(),
    };
    match best {
        Some((lift, pen, traj, about)) => {
            let why = match &strongest {
                Some(s) => cannot_hold_reason(s, closest_reach, lift, pen),
                None => String::new(),
            };
            let (traj, about) = match envelope_best {
                Some(e) if e.lift > lift => (e.traj, e.about),
                _ => (traj, about),
            };
            crate::console::warn(&format!(
                "warning: {}: no fingertip grasp lifted the object {:.3} m with less than {} mm penetration in simulation; {why}; {envelope_line}; writing the best: {about}",
                args.config.display(),
                VERIFY_LIFT_FRACTION * args.lift,
                VERIFY_PEAK_PENETRATION_MM
            ));
            Ok(traj)
        }
        None => match envelope_best {
            Some(e) => {
                crate::console::warn(&format!(
                    "warning: {}: no fingertip grasp could be planned ({:#}); no enveloping grasp lifted the object {:.3} m with less than {} mm penetration in simulation; writing the best: {}",
                    args.config.display(),
                    first_err.expect("a variant's error"),
                    VERIFY_LIFT_FRACTION * args.lift,
                    VERIFY_PEAK_PENETRATION_MM,
                    e.about
                ));
                Ok(e.traj)
            }
            None => Err(anyhow::anyhow!("{}: cannot plan the grasp: {:#}", args.config.display(), first_err.expect("a variant's error"))),
        },
    }
}

/// A fingertip that ends farther than this (m) from its contact point in every planned variant
/// does not reach around the object.
pub const SPAN_TOLERANCE_M: f32 = 0.01;

/// A best replay that lifted the object less than this (m) with a peak penetration under
/// `GRAZE_PENETRATION_MM` did not squeeze it: the fingertips closed off the object's surface.
pub const GRAZE_LIFT_M: f64 = 0.01;
/// See [`GRAZE_LIFT_M`].
pub const GRAZE_PENETRATION_MM: f64 = 0.5;

/// Why no variant lifted the object, in one line, from the statics of the strongest planned grasp
/// (`strongest`), the best reach of any variant (`closest_reach`: its largest fingertip distance
/// from a contact point, m) and the best replay (`best_lift` m, `best_peak_pen` mm): too heavy for
/// the hand's effort limits (its grasps hold less than its weight), too wide for its span, the
/// fingertips closing off the object's surface — every one that applies — or else that the grasp
/// slips or turns in simulation, with how many times its weight the strongest grasp holds (under
/// 2×, the lift's acceleration and the object's turning about the grip are the likely cause: with
/// dexhand16 the YCB bleach cleanser, 1.45×, falls where the power drill, 1.4×, lifts).
pub fn cannot_hold_reason(strongest: &hold::HoldCapacity, closest_reach: f32, best_lift: f64, best_peak_pen: f64) -> String {
    let ratio = strongest.holds / strongest.weight;
    let mut why = Vec::new();
    if ratio < 1.0 {
        why.push(format!("too heavy for the hand's effort limits ({})", strongest.describe()));
    }
    if closest_reach > SPAN_TOLERANCE_M {
        why.push(format!(
            "too wide for the hand's span (in every grasp planned some fingertip ends {:.0} mm or more from its contact point on the object)",
            closest_reach * 1e3
        ));
    }
    if best_lift < GRAZE_LIFT_M && best_peak_pen < GRAZE_PENETRATION_MM {
        why.push(format!(
            "the fingertips close without squeezing it (best lift {:.1} mm, peak penetration {best_peak_pen:.2} mm): the planned contacts miss its surface",
            best_lift * 1e3
        ));
    }
    if !why.is_empty() {
        format!("it cannot be held as planned: {}", why.join("; and "))
    } else if ratio < 2.0 {
        format!(
            "the grasp slips or turns in simulation: the strongest grasp planned holds only {ratio:.2}× the object's weight in statics, too little for the lift's acceleration and the object's turning about the grip ({})",
            strongest.describe()
        )
    } else {
        format!("the hand reaches around it and could hold {ratio:.1}× its weight in statics ({}), but the grasp slips or turns in simulation", strongest.describe())
    }
}

/// The keyframes of the script (module documentation) for a grasp: the wrist pose at the object,
/// the approach keyframes after the start (empty: straight to the grasp pose, hand open), and the
/// closing postures (the last one is held through the lift).
fn script(model: &SimModel, args: &SynthArgs, grasp: Pose, approach: Vec<(f64, Pose, Vec<f32>)>, closing: Vec<Vec<f32>>) -> Result<Trajectory> {
    let hand = &model.hand;
    let g = &model.globals;
    let wrist0 = initial_wrist(model);
    let open = open_posture(model);
    let obj = Vec3::new(g.obj_init[0], g.obj_init[1], g.obj_init[3]);
    let obj_rot = Quat::from_rotation_z(g.obj_init[2]);
    let t1 = args.approach as f64;
    let t2 = t1 + args.close as f64;
    let t3 = t2 + 0.3;
    let t4 = t3 + args.lift_time as f64;
    let t5 = t4 + args.hold as f64;
    let obj_up = Pose::new(obj + Vec3::Z * args.lift, obj_rot);
    let obj_rest = Pose::new(obj, obj_rot);
    let closed = closing.last().expect("a closed posture").clone();
    let lifted = Pose::new(grasp.pos + Vec3::Z * args.lift, grasp.rot);
    let mut keys = vec![(0.0, wrist0, open.clone(), obj_rest)];
    if approach.is_empty() {
        keys.push((t1, grasp, open.clone(), obj_rest));
    }
    keys.extend(approach.into_iter().map(|(t, w, q)| (t, w, q, obj_rest)));
    // the closing motion (one posture, or the planned steps through the contact points)
    let n = closing.len();
    keys.extend(closing.into_iter().enumerate().map(|(k, q)| (t1 + (t2 - t1) * (k + 1) as f64 / n as f64, grasp, q, obj_rest)));
    keys.extend([(t3, grasp, closed.clone(), obj_rest), (t4, lifted, closed.clone(), obj_up), (t5, lifted, closed, obj_up)]);
    let frames = keys
        .iter()
        .map(|(t, wrist, q, object)| {
            let links = hand.forward_kinematics(q);
            let tips = hand.fingertips.iter().map(|tp| wrist.transform_point(links[tp.link].transform_point(tp.pos))).collect();
            Keyframe { t: *t, wrist: *wrist, joints: q.clone(), fingertips: Some(tips), object: Some(*object) }
        })
        .collect();
    let traj = Trajectory {
        joint_names: hand.joints.iter().map(|j| j.name.clone()).collect(),
        fingertip_names: hand.fingertips.iter().map(|t| t.name.clone()).collect(),
        frames,
        // a synthesised reference is the config's own object's: it names none
        object_name: None,
    };
    traj.validate()?;
    Ok(traj)
}

/// The references `dextrain traj synth` writes: the scripted one, or `count` perturbed copies of it
/// (when `count` > 1 or a perturbation is set).
pub fn synth_set(cfg: &Config, args: &SynthArgs) -> Result<Vec<Trajectory>> {
    if args.count == 0 || args.count > 10_000 {
        bail!("--count = {}: expected 1 to 10000 references", args.count);
    }
    let clean = synth(cfg, args)?;
    if args.count == 1 && !args.perturb.is_active() {
        return Ok(vec![clean]);
    }
    let model = SimModel::from_config(cfg)?;
    (0..args.count as u64).map(|i| perturb(&clean, &model.hand, &args.perturb, args.seed, i)).collect()
}

/// `dextrain traj synth`.
pub fn run(args: &SynthArgs) -> Result<()> {
    let cfg = Config::load_with_overrides(&args.config, &args.sets)?;
    let set = synth_set(&cfg, args)?;
    if args.count == 1 {
        set[0].save(&args.out)?;
        crate::console::status(&format!("wrote {} ({} keyframes, {:.2} s)", args.out.display(), set[0].frames.len(), set[0].duration()));
        return Ok(());
    }
    std::fs::create_dir_all(&args.out).with_context(|| format!("cannot create the directory {}", args.out.display()))?;
    for (i, t) in set.iter().enumerate() {
        t.save(&args.out.join(format!("ref_{i:03}.mcap")))?;
    }
    crate::console::status(&format!("wrote {} references to {} ({:.2} s each)", set.len(), args.out.display(), set[0].duration()));
    Ok(())
}
