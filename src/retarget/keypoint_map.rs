//! Which human keypoint goes to which point of a robot hand, worked out from the hand's model (its
//! fingertips and their kinematic chains), and the robot's size over the human's.
//!
//! - **Fingers.** Each of the hand's fingertips (`hand.fingertips`) ends a finger; the finger's
//!   knuckle is the origin of the first link of its chain out of the palm (the link whose parent
//!   is the wrist). The **thumb** is the fingertip whose name starts with `th` or contains
//!   `thumb` (`HandModel::thumb_by_name`, `traj synth`'s rule), else the one farthest from the
//!   mean of the others at the hand's default posture (the opposed digit). Where the other
//!   fingertips' names each say a finger of their own (`index`/`if…`/`ff…`, `middle`/`mf…`,
//!   `ring`/`rf…`, `little`/`pinky`/`lf…`: dexhand16's, LEAP's, Shadow's), the names decide;
//!   otherwise the fingers, in the order of their knuckles along the palm's row from the end
//!   nearer the thumb's knuckle, are the human index, middle, ring and little fingers (a hand with fewer fingers maps a subset: a
//!   four-fingered hand has no little finger).
//! - **The config's table.** `[retarget.fingers]` (`thumb = "…"`, `index = "…"`, …) names the
//!   fingertip each human finger drives, in place of the rules above; a finger left out is not
//!   mapped.
//! - **Points** (dex-retargeting's vector method): the wrist, then per finger its knuckle and its
//!   tip. **Vectors**: wrist → tip and knuckle → tip (weight 1: where the finger points and how
//!   it bends), wrist → knuckle (weight ½: the palm's orientation). The palm frame that starts the
//!   solve is the wrist and the first and last fingers' knuckles after the thumb.
//! - **Scale**: the robot's fingers' lengths (the distances between consecutive joint origins of
//!   each chain, wrist to tip: the same at any posture) over the human's (wrist → knuckle → …
//!   → tip, the median over the demonstration's frames), summed over the mapped fingers.

use anyhow::{Result, anyhow, ensure};
use glam::Vec3;

use super::demo::{HUMAN_KEYPOINTS, KEYPOINT_NAMES};
use super::solve::{RetargetSpec, RobotPoint, VectorPair};
use crate::config::FingerMap;
use crate::env::SimModel;
use crate::hand::MAX_JOINTS;
use crate::task::ik::{IkScratch, ik_apply_mimic, ik_chain, ik_link_poses, ik_tip_positions};

/// The human fingers' keypoints (wrist excluded), thumb first: knuckle (the thumb's CMC, the
/// fingers' MCP) to tip, in [`KEYPOINT_NAMES`] order.
pub const HUMAN_FINGERS: [[usize; 4]; 5] = [[1, 2, 3, 4], [5, 6, 7, 8], [9, 10, 11, 12], [13, 14, 15, 16], [17, 18, 19, 20]];

/// The human fingers' names, thumb first.
pub const FINGER_NAMES: [&str; 5] = ["thumb", "index", "middle", "ring", "little"];

/// One finger of the robot mapped to a human finger.
#[derive(Clone, Debug, PartialEq)]
pub struct MappedFinger {
    /// The human finger (an index into [`HUMAN_FINGERS`]: 0 the thumb).
    pub human: usize,
    /// The robot's fingertip (its name in `hand.fingertips`).
    pub tip_name: String,
    /// The fingertip's link and its point in that link's frame.
    pub tip: RobotPoint,
    /// The knuckle: the origin of the chain's first link out of the palm.
    pub knuckle: RobotPoint,
    /// The finger's length, wrist to tip (m).
    pub length: f32,
}

/// The hand's fingers mapped to human fingers, the spec the solve runs and the human keypoints it
/// reads (in `spec.points` order).
#[derive(Clone, Debug)]
pub struct KeypointMap {
    pub fingers: Vec<MappedFinger>,
    pub spec: RetargetSpec,
    /// The human keypoint of each spec point.
    pub human_keypoints: Vec<usize>,
}

impl KeypointMap {
    /// The human keypoints of one frame, in `spec.points` order, relative to the wrist (the solve
    /// scales them about it).
    pub fn frame_points(&self, keypoints: &[Vec3; HUMAN_KEYPOINTS]) -> Vec<Vec3> {
        self.human_keypoints.iter().map(|&i| keypoints[i] - keypoints[0]).collect()
    }

    /// The spec's points by name, `human keypoint → robot point` (for reports).
    pub fn describe(&self, model: &SimModel) -> Vec<String> {
        let link_name = |l: usize| if l == 0 { "the wrist".to_string() } else { model.hand.joints.get(l - 1).map_or(format!("link {l}"), |j| format!("the link of joint {}", j.name)) };
        let mut out = vec![format!("{} → the wrist", KEYPOINT_NAMES[0])];
        for f in &self.fingers {
            let h = HUMAN_FINGERS[f.human];
            out.push(format!("{} → {} (knuckle)", KEYPOINT_NAMES[h[0]], link_name(f.knuckle.link)));
            out.push(format!("{} → fingertip {}", KEYPOINT_NAMES[h[3]], f.tip_name));
        }
        out
    }
}

/// The human finger other than the thumb (an index into [`FINGER_NAMES`], 1–4) a fingertip's name
/// says it ends, if any (the thumb is `traj synth`'s: `HandModel::thumb_by_name`).
pub fn finger_of_name(name: &str) -> Option<usize> {
    let n = name.to_ascii_lowercase();
    let starts = |p: &[&str]| p.iter().any(|p| n.starts_with(p));
    let has = |p: &[&str]| p.iter().any(|p| n.contains(p));
    if has(&["index"]) || starts(&["if_", "ff_", "ff", "if"]) {
        Some(1)
    } else if has(&["middle"]) || starts(&["mf_", "mf"]) {
        Some(2)
    } else if has(&["ring"]) || starts(&["rf_", "rf"]) {
        Some(3)
    } else if has(&["little", "pinky"]) || starts(&["lf_", "lf"]) {
        Some(4)
    } else {
        None
    }
}

/// The hand's default posture (every model joint, followers from their leaders).
pub fn default_posture(model: &SimModel) -> [f32; MAX_JOINTS] {
    let mut q = [0.0f32; MAX_JOINTS];
    for (j, jd) in model.joints.iter().enumerate() {
        q[j] = jd.default_q;
    }
    ik_apply_mimic(&model.view(), &mut q);
    q
}

/// The median over frames of the human fingers' lengths (wrist → knuckle → … → tip), thumb first.
pub fn human_finger_lengths(frames: &[[Vec3; HUMAN_KEYPOINTS]]) -> [f32; 5] {
    let mut out = [0.0f32; 5];
    for (f, kp) in HUMAN_FINGERS.iter().enumerate() {
        let mut lengths: Vec<f32> = frames
            .iter()
            .map(|k| (k[kp[0]] - k[0]).length() + kp.windows(2).map(|w| (k[w[1]] - k[w[0]]).length()).sum::<f32>())
            .collect();
        lengths.sort_by(f32::total_cmp);
        out[f] = lengths.get(lengths.len() / 2).copied().unwrap_or(0.0);
    }
    out
}

/// The map for `model`'s hand and a demonstration whose frames are `frames` (for the scale); the
/// fingers as `given` (the config's `[retarget.fingers]`) where it is set.
pub fn keypoint_map(model: &SimModel, frames: &[[Vec3; HUMAN_KEYPOINTS]], given: Option<&FingerMap>) -> Result<KeypointMap> {
    let m = model.view();
    let hand = &model.hand;
    let n_tips = m.g.n_tips as usize;
    ensure!(n_tips >= 2, "{}: the hand has {n_tips} fingertip(s); retargeting a human hand needs a thumb and at least one finger (hand.fingertips)", hand.source.display());
    ensure!(n_tips <= 5, "{}: the hand has {n_tips} fingertips; a human hand has 5 fingers to map them to", hand.source.display());
    let q = default_posture(model);
    let mut s = IkScratch::default();
    let tip_pos = ik_tip_positions(&m, &q, &mut s);
    ik_link_poses(&m, &q, &mut s);
    // each fingertip's chain of links, root → tip (link j + 1 is moved by joint j)
    let chains: Vec<Vec<usize>> = (0..n_tips)
        .map(|t| {
            let n = ik_chain(&m, t, &mut s);
            (0..n).map(|i| s.chain_j[t * MAX_JOINTS + i] as usize + 1).collect()
        })
        .collect();
    for (t, c) in chains.iter().enumerate() {
        ensure!(!c.is_empty(), "{}: fingertip {} is on the wrist link itself; a finger needs joints", hand.source.display(), hand.fingertips[t].name);
    }
    let knuckle_of = |t: usize| chains[t][0];
    // the thumb: by its name (`HandModel::thumb_by_name`), else the fingertip farthest from the
    // mean of the others
    let apart = |t: usize| {
        let others: Vec<Vec3> = (0..n_tips).filter(|&o| o != t).map(|o| tip_pos[o]).collect();
        (tip_pos[t] - others.iter().sum::<Vec3>() / others.len() as f32).length()
    };
    let thumb = hand.thumb_by_name().unwrap_or_else(|| (0..n_tips).max_by(|&a, &b| apart(a).total_cmp(&apart(b))).expect("two tips at least"));
    let rest: Vec<usize> = (0..n_tips).filter(|&t| t != thumb).collect();
    // the other fingers by their names where each says a finger of its own
    let mut by_name: Vec<(usize, usize)> = rest.iter().filter_map(|&t| finger_of_name(&hand.fingertips[t].name).map(|f| (f, t))).collect();
    by_name.sort();
    let order: Vec<(usize, usize)> = if let Some(given) = given {
        // the config's table: each named fingertip must be one of the hand's, each used once
        let names: Vec<&str> = hand.fingertips.iter().map(|t| t.name.as_str()).collect();
        let mut order = Vec::new();
        for (human, key, tip) in given.entries() {
            let t = names.iter().position(|n| *n == tip).ok_or_else(|| anyhow!("key `retarget.fingers.{key}` = \"{tip}\": expected one of the hand's fingertips ({})", names.join(", ")))?;
            ensure!(!order.iter().any(|&(_, u)| u == t), "key `retarget.fingers.{key}` = \"{tip}\": that fingertip is already another finger's; expected each fingertip once");
            order.push((human, t));
        }
        ensure!(order.len() >= 2, "key `retarget.fingers`: only the thumb is mapped; expected the thumb and at least one other finger");
        order
    } else if by_name.len() == rest.len() && by_name.windows(2).all(|w| w[0].0 != w[1].0) {
        std::iter::once((0, thumb)).chain(by_name).collect()
    } else {
        // along the row of their knuckles, from the end nearer the thumb's
        let at = |t: usize| s.link_pos[knuckle_of(t)];
        let (mut a, mut b) = (rest[0], rest[0]);
        for &i in &rest {
            for &j in &rest {
                if (at(i) - at(j)).length() > (at(a) - at(b)).length() {
                    (a, b) = (i, j);
                }
            }
        }
        let thumb_knuckle = at(thumb);
        let start = if (at(a) - thumb_knuckle).length() <= (at(b) - thumb_knuckle).length() { a } else { b };
        let mut rest = rest;
        rest.sort_by(|&i, &j| (at(i) - at(start)).length().total_cmp(&(at(j) - at(start)).length()));
        std::iter::once(thumb).chain(rest).enumerate().collect()
    };
    let human_lengths = human_finger_lengths(frames);
    let mut fingers = Vec::new();
    for (human, t) in order {
        let tip = &m.tips[t];
        let links = &chains[t];
        let knuckle = links[0];
        // wrist → knuckle → … → the tip's link, then the tip's offset: constant segment lengths
        let mut length = s.link_pos[knuckle].length();
        for w in links.windows(2).rev() {
            length += (s.link_pos[w[1]] - s.link_pos[w[0]]).length(); // summed tip first
        }
        let offset = Vec3::new(tip.pos[0], tip.pos[1], tip.pos[2]);
        length += offset.length();
        fingers.push(MappedFinger {
            human,
            tip_name: hand.fingertips[t].name.clone(),
            tip: RobotPoint { link: tip.link as usize, offset },
            knuckle: RobotPoint { link: knuckle, offset: Vec3::ZERO },
            length,
        });
    }
    let robot_len: f32 = fingers.iter().map(|f| f.length).sum();
    let human_len: f32 = fingers.iter().map(|f| human_lengths[f.human]).sum();
    ensure!(human_len > 0.0 && robot_len > 0.0, "the demonstration's fingers have no length (all keypoints at one point)");
    // points: the wrist, then each finger's knuckle and tip
    let mut points = vec![RobotPoint { link: 0, offset: Vec3::ZERO }];
    let mut human_keypoints = vec![0usize];
    let mut pairs = Vec::new();
    for f in &fingers {
        let (k, t) = (points.len(), points.len() + 1);
        points.push(f.knuckle);
        points.push(f.tip);
        human_keypoints.push(HUMAN_FINGERS[f.human][0]);
        human_keypoints.push(HUMAN_FINGERS[f.human][3]);
        pairs.push(VectorPair { origin: 0, target: t, weight: 1.0 });
        pairs.push(VectorPair { origin: k, target: t, weight: 1.0 });
        pairs.push(VectorPair { origin: 0, target: k, weight: 0.5 });
    }
    // the palm frame: the wrist and the first and last fingers' knuckles after the thumb (for a
    // hand of two fingers, the thumb's and the finger's)
    let first = if fingers.len() > 2 { 3 } else { 1 };
    let last = 1 + 2 * (fingers.len() - 1);
    let spec = RetargetSpec { points, pairs, palm: [0, first, last], scale: robot_len / human_len, smooth: 1e-6, iterations: 100 };
    Ok(KeypointMap { fingers, spec, human_keypoints })
}
