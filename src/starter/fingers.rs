//! Which links are a hand's fingertips and which fingertip is the thumb, guessed from the URDF's
//! kinematic tree and the open hand's geometry (for `dextrain new hand`).
//!
//! - **Fingertips** ([`guess_tips`]), one per finger chain (a leaf of the movable-joint tree,
//!   [`HandModel::finger_chains`]): the loader's own default where it finds one on that chain
//!   (every link whose name contains "tip", the most distal per finger; `hand.fingertips = []`);
//!   else the chain's last link, at the far end of its collision geometry (`{ link, offset, name =
//!   "<link>_tip" }`: the pad point that `traj synth`'s planner moves, [`pad_points`]), or at its
//!   origin where it has no geometry.
//! - **Thumb** ([`guess_thumb`]): the first fingertip whose name starts with "th" or contains
//!   "thumb" (the task's and `traj synth`'s own name rule); else the fingertip whose finger, in the
//!   open hand, points farthest (in angle) from the mean direction of the other fingers: a thumb
//!   stands across the fingers (measured on the shipped and the real hands of ../shared/hands:
//!   42–180° for the thumb against at most 36° for any other finger; Allegro's thumb, whose name
//!   says nothing, 104°).

use anyhow::{Result, bail};
use glam::Vec3;

use crate::config::hand::{FingertipSpec, LinkTip};
use crate::hand::{Fingertip, HandModel, MAX_TIPS};
use crate::synth::grasp::pad_points;

/// One guessed fingertip: the config entry, the loader's frame for it, and whether it was found
/// by name.
#[derive(Clone, Debug)]
pub struct TipGuess {
    /// The `hand.fingertips` entry.
    pub spec: FingertipSpec,
    /// What the loader makes of it.
    pub tip: Fingertip,
    /// Found by the loader's name rule (else the chain's last link).
    pub by_name: bool,
}

/// Every joint at 0 clamped into its limits, followers from their leaders: the simulator's start.
pub fn open_posture(hand: &HandModel) -> Vec<f32> {
    hand.with_mimic(hand.joints.iter().map(|j| 0.0f32.clamp(j.lower, j.upper)).collect())
}

/// For fingertip `i`: the joints that move it and no other fingertip (its finger's own joints), in
/// joint (topological) order.
pub fn own_joints(hand: &HandModel, i: usize) -> Vec<usize> {
    let tips = &hand.fingertips;
    (0..hand.joints.len())
        .filter(|&j| {
            let child = j + 1;
            hand.is_ancestor_or_same(child, tips[i].link) && tips.iter().enumerate().all(|(k, t)| k == i || !hand.is_ancestor_or_same(child, t.link))
        })
        .collect()
}

/// Each finger's base (the origin of its first own joint; the root's origin for a finger without
/// one) and tip, in the root frame, for the joint positions `q`.
pub fn bases_and_tips(hand: &HandModel, q: &[f32]) -> Vec<(Vec3, Vec3)> {
    let links = hand.forward_kinematics(q);
    (0..hand.fingertips.len())
        .map(|i| {
            let base = match own_joints(hand, i).first() {
                Some(&j) => links[hand.joints[j].parent_link].mul(&hand.joints[j].origin).pos,
                None => Vec3::ZERO,
            };
            let t = &hand.fingertips[i];
            (base, links[t.link].transform_point(t.pos))
        })
        .collect()
}

/// One fingertip per finger chain (module documentation). `hand` is loaded with the loader's
/// default fingertips (`hand.fingertips = []`).
pub fn guess_tips(hand: &HandModel) -> Result<Vec<TipGuess>> {
    let chains = hand.finger_chains();
    if chains.is_empty() {
        bail!("{}: the hand has no movable joints, so no fingers; expected a hand URDF with revolute or continuous finger joints", hand.source.display());
    }
    if chains.len() > MAX_TIPS {
        bail!(
            "{}: {} finger chains; expected at most {MAX_TIPS} (MAX_TIPS): write the config by hand, with hand.fingertips naming at most {MAX_TIPS} of them",
            hand.source.display(),
            chains.len()
        );
    }
    // the far ends of the leaf links' geometry: the pad points of a hand whose tips are the leaves' origins
    let mut leaves = hand.clone();
    leaves.fingertips = chains.iter().map(|&l| Fingertip { name: hand.links[l].name.clone(), link: l, pos: Vec3::ZERO }).collect();
    let pads = pad_points(&leaves);
    let mut out = Vec::new();
    for (k, &leaf) in chains.iter().enumerate() {
        // the loader's tip on this chain, on a link of this chain alone
        let on_chain = |t: &&Fingertip| t.link != 0 && chains.iter().filter(|&&c| hand.is_ancestor_or_same(t.link, c)).count() == 1 && hand.is_ancestor_or_same(t.link, leaf);
        if let Some(t) = hand.fingertips.iter().find(on_chain) {
            out.push(TipGuess { spec: FingertipSpec::Frame(t.name.clone()), tip: t.clone(), by_name: true });
            continue;
        }
        let link = hand.links[leaf].name.clone();
        let pad = pads[k];
        if pad.length() < 1e-6 {
            out.push(TipGuess { spec: FingertipSpec::Frame(link.clone()), tip: Fingertip { name: link, link: leaf, pos: Vec3::ZERO }, by_name: false });
            continue;
        }
        // rounded as the config writes it (0.01 mm)
        let offset = pad.to_array().map(|x| (x * 1e5).round() / 1e5);
        let name = format!("{link}_tip");
        out.push(TipGuess {
            spec: FingertipSpec::Link(LinkTip { link: link.clone(), offset, name: Some(name.clone()) }),
            tip: Fingertip { name, link: leaf, pos: Vec3::from_array(offset) },
            by_name: false,
        });
    }
    Ok(out)
}

/// The thumb among `hand.fingertips` (module documentation): its index and why.
pub fn guess_thumb(hand: &HandModel) -> (usize, String) {
    if let Some(i) = hand.thumb_by_name() {
        return (i, "its name starts with \"th\" or contains \"thumb\" (the first such fingertip)".to_string());
    }
    let dirs: Vec<Vec3> = bases_and_tips(hand, &open_posture(hand)).iter().map(|(b, t)| (*t - *b).normalize_or_zero()).collect();
    let n = dirs.len();
    // the angle between finger i's direction and the others' mean direction
    let apart = |i: usize| {
        let others = (0..n).filter(|&k| k != i).map(|k| dirs[k]).sum::<Vec3>().normalize_or_zero();
        dirs[i].dot(others).clamp(-1.0, 1.0).acos()
    };
    let angles: Vec<f32> = (0..n).map(apart).collect();
    // the first of the largest (a symmetric claw has no thumb: its first finger)
    let th = (0..n).fold(0, |best, i| if angles[i] > angles[best] + 1e-4 { i } else { best });
    if angles.iter().all(|a| (a - angles[0]).abs() < 1f32.to_radians()) {
        return (0, format!("no fingertip's name says thumb and the fingers are alike (each {:.0}° from the others' mean direction: a claw): the first", angles[0].to_degrees()));
    }
    let reason = format!(
        "no fingertip's name says thumb: the finger that points farthest from the others' mean direction in the open hand ({:.0}°; the others {})",
        angles[th].to_degrees(),
        (0..n).filter(|&i| i != th).map(|i| format!("{:.0}°", angles[i].to_degrees())).collect::<Vec<_>>().join(", ")
    );
    (th, reason)
}
