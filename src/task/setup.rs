//! The task's spec, constants and references from a config and a hand (both backends build from
//! [`TaskSetup`]): names and sizes from the observation spec ([`super::spec`]), the constants the
//! twins read ([`TaskGlobals`]), and for the reference kinds the reference bank and its globals.

use anyhow::{Result, bail};

use super::spec::{LayoutNames, TaskSpec, entry_names, obs_layout, reward_terms};
use super::task::*;
use crate::config::{Config, FingerMode, ReferenceConfig, ReferenceStart, TaskKind, TrackAction};
use crate::env::SimModel;
use super::layout::*;
use crate::task::ik::IkParams;
use crate::task::reference::{RefGlobals, RefModel};
use crate::hand::MAX_JOINTS;
use crate::task::bank::RefBank;

/// Everything both backends build a task from: names and sizes, the constants, and (reference
/// kinds) the reference bank and its constants.
pub struct TaskSetup {
    pub spec: TaskSpec,
    pub tc: TaskGlobals,
    /// The references (`task.reference.files`); `None` for the lift task.
    pub bank: Option<RefBank>,
    /// The reference layer's constants (zeroed for the lift task).
    pub rg: RefGlobals,
}

/// The reference files of `task.reference.files`, resolved against the config's directory; a
/// directory stands for every `.mcap` and `.csv` file in it, sorted by name.
pub fn reference_paths(cfg: &Config) -> Result<Vec<std::path::PathBuf>> {
    let mut out = Vec::new();
    for f in &cfg.task.reference.files {
        let p = cfg.resolve(f);
        if p.is_dir() {
            let mut inside: Vec<std::path::PathBuf> = std::fs::read_dir(&p)
                .map_err(|e| anyhow::anyhow!("{}: key `task.reference.files`: cannot list {}: {e}", cfg.source.display(), p.display()))?
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|q| q.extension().is_some_and(|x| x == "mcap" || x == "csv"))
                .collect();
            if inside.is_empty() {
                bail!("{}: key `task.reference.files`: the directory {} holds no .mcap or .csv reference", cfg.source.display(), p.display());
            }
            inside.sort();
            out.extend(inside);
        } else {
            out.push(p);
        }
    }
    Ok(out)
}

/// The reference layer's constants: the bank's part ([`RefBank::globals`]) with the augmentation
/// settings of `[task.reference]`.
pub fn reference_globals(bank: &RefBank, aug: &ReferenceConfig) -> RefGlobals {
    let mut rg = bank.globals();
    apply_augmentation(aug, &mut rg);
    rg
}

/// Writes the augmentation settings of `[task.reference]` into `rg` (its bank part is kept).
pub fn apply_augmentation(aug: &ReferenceConfig, rg: &mut RefGlobals) {
    rg.reground = aug.reground as u32;
    rg.reinterp = aug.reinterp as u32;
    rg.reinterp_steps = aug.reinterp_steps;
    rg.translate_xy = aug.translate_xy;
    rg.rotate_z = aug.rotate_z;
    rg.mirror_prob = aug.mirror_prob;
    rg.time_scale = aug.time_scale;
    rg.wrist_pos_offset = aug.wrist_pos_offset;
    rg.wrist_rot_offset = aug.wrist_rot_offset;
    rg.joint_offset = aug.joint_offset;
    rg.wrist_pos_noise = aug.wrist_pos_noise;
    rg.joint_noise = aug.joint_noise;
}

/// The config's checks that need the task's observation spec (`Config::validate` holds the rest):
/// the privileged encoder's inputs are fields of this task's critic observation. [`task_setup`]
/// runs it first.
pub fn check_config(cfg: &Config) -> Result<()> {
    let c = crate::config::Check::new(&cfg.source);
    if let Some(e) = &cfg.policy.encoder {
        let names = super::spec::critic_field_names(cfg.task.kind, cfg.task.track.lookahead);
        if let Some(bad) = e.inputs.iter().find(|n| !names.contains(n)) {
            return Err(c.err("policy.encoder.inputs", bad, &format!("field names of the {} task's critic observation: {}", cfg.task.kind, names.join(", "))));
        }
    }
    Ok(())
}

/// The task's spec, constants and references from the config's `[task]` and the hand (both backends).
pub fn task_setup(cfg: &Config, model: &SimModel) -> Result<TaskSetup> {
    check_config(cfg)?;
    let file = cfg.source.display();
    let t = &cfg.task;
    let es = &model.spec;
    let hand = model.hand.source.display();
    let joint_names = &es.joint_names;
    let tips = &es.tip_names;
    let kind = t.kind.index();
    let terms = reward_terms(t.kind);
    let n_actuated = es.actuated.len();
    let n_res = 6 + 3 * tips.len();
    let action_dim = if t.kind == TaskKind::ResidualTask { n_res } else { 6 + n_actuated };
    if action_dim > MAX_ACTIONS || n_actuated > MAX_JOINTS {
        bail!(
            "{file}: the hand {hand} has {n_actuated} actuated joints, so the {} task would have {action_dim} actions; at most {MAX_ACTIONS} (MAX_ACTIONS) are supported",
            t.kind
        );
    }
    if tips.is_empty() {
        bail!("{file}: the {} task needs fingertips, but the hand {hand} has none: name them in `hand.fingertips`", t.kind);
    }
    let thumb_name = &t.hand.thumb;
    let thumb = if thumb_name.is_empty() {
        tips.iter().position(|n| n.to_lowercase().starts_with("th")).ok_or_else(|| {
            anyhow::anyhow!(
                "{file}: key `task.hand.thumb` = \"\": no fingertip of the hand {hand} has a name starting with \"th\"; expected the thumb's fingertip, one of: {}",
                tips.join(", ")
            )
        })?
    } else {
        tips.iter().position(|n| n == thumb_name).ok_or_else(|| {
            anyhow::anyhow!(
                "{file}: key `task.hand.thumb` = {:?}: expected one of the hand's fingertips: {}",
                crate::text::quote_short(thumb_name),
                tips.join(", ")
            )
        })?
    };
    let finger_mode = match t.action.finger_mode {
        FingerMode::Absolute => 0,
        FingerMode::Delta => 1,
    };
    let (bank, rg) = if !t.kind.follows_reference() {
        (None, RefGlobals::default())
    } else {
        let paths = reference_paths(cfg)?;
        let bank = RefBank::load(&paths, model, thumb).map_err(|e| anyhow::anyhow!("{file}: key `task.reference.files`: {e:#}"))?;
        let rg = reference_globals(&bank, &t.reference);
        (Some(bank), rg)
    };

    let mut action_names: Vec<String> = ["wrist_dx", "wrist_dy", "wrist_dz", "wrist_rx", "wrist_ry", "wrist_rz"].iter().map(|s| s.to_string()).collect();
    if t.kind == TaskKind::ResidualTask {
        for tip in tips {
            action_names.extend(["x", "y", "z"].iter().map(|c| format!("tip.{tip}.{c}")));
        }
    } else {
        action_names.extend(es.actuated.iter().map(|&j| format!("q.{}", joint_names[j])));
    }
    let actuated_names: Vec<String> = es.actuated.iter().map(|&j| joint_names[j].clone()).collect();
    let link_names: Vec<String> = model.hand.links.iter().map(|l| l.name.clone()).collect();
    let names = LayoutNames { joints: &actuated_names, actions: &action_names, tips, links: &link_names };
    let (obs_layout, priv_layout) = obs_layout(t.kind, &names, t.track.lookahead);
    let obs_names = entry_names(&obs_layout);
    let priv_names = entry_names(&priv_layout);
    let (obs_dim, priv_dim) = (obs_names.len(), priv_names.len());
    if 2 * priv_dim >= OBS_KEY_STRIDE as usize {
        bail!("{}: {priv_dim} observations, at most {} are supported", hand, OBS_KEY_STRIDE / 2 - 1);
    }

    let mut weights = [[0.0f32; 4]; 3];
    for (k, term) in terms.iter().enumerate() {
        weights[k / 4][k % 4] = t.rewards.get(term.name).copied().unwrap_or(0.0);
    }
    let mut actuated = [[0u32; 4]; MAX_JOINTS / 4];
    for (i, &j) in es.actuated.iter().enumerate() {
        actuated[i / 4][i % 4] = j as u32;
    }
    let a = &t.action;
    let l = &t.lift;
    let hp = &t.hand;
    let term_cfg = &t.termination;
    let n = &t.obs_noise;
    let k = &t.track;
    let r = &t.residual;
    let control_dt = es.dt * es.decimation as f32;
    let v4 = |v: [f32; 3]| [v[0], v[1], v[2], 0.0];
    let tc = TaskGlobals {
        wrist_pos_min: v4(a.wrist_pos_min),
        wrist_pos_max: v4(a.wrist_pos_max),
        palm_offset: v4(hp.palm_offset),
        weights,
        actuated,
        n_actuated: n_actuated as u32,
        n_act: action_dim as u32,
        obs_dim: obs_dim as u32,
        priv_dim: priv_dim as u32,
        episode_length: t.episode_length,
        finger_mode,
        thumb: thumb as u32,
        obj_delay_min: t.obs_noise.object_delay[0],
        wrist_pos_scale: a.wrist_pos_scale,
        wrist_rot_scale: a.wrist_rot_scale,
        wrist_rot_limit: a.wrist_rot_limit,
        finger_delta_scale: a.finger_delta_scale,
        reach_alpha: l.reach_alpha,
        success_height: l.success_height,
        contact_force: hp.contact_force,
        drop_height: term_cfg.drop_height,
        table_half_extent: term_cfg.table_half_extent,
        max_hand_distance: term_cfg.max_hand_distance,
        noise_joint_pos: n.joint_pos,
        noise_joint_vel: n.joint_vel,
        noise_hand_pos: n.hand_pos,
        noise_object_pos: n.object_pos,
        noise_object_rot: n.object_rot,
        obj_delay_max: t.obs_noise.object_delay[1],
        kind,
        n_terms: terms.len() as u32,
        start_mode: (k.start == ReferenceStart::Config) as u32,
        lookahead: k.lookahead,
        lookahead_stride: k.lookahead_stride,
        n_res: n_res as u32,
        open_loop: t.open_loop as u32,
        track_action: (k.action == TrackAction::Reference) as u32,
        beta_joint: k.beta_joint,
        beta_wrist_pos: k.beta_wrist_pos,
        beta_wrist_rot: k.beta_wrist_rot,
        alpha_joint: k.alpha_joint,
        alpha_wrist_pos: k.alpha_wrist_pos,
        alpha_wrist_rot: k.alpha_wrist_rot,
        alpha_object_pos: k.alpha_object_pos,
        alpha_object_rot: k.alpha_object_rot,
        success_pos_tol: k.success_pos_tol,
        success_rot_tol: k.success_rot_tol,
        max_object_error: k.max_object_error,
        res_alpha: r.alpha,
        res_wrist_pos_alpha: r.wrist_pos_alpha,
        res_wrist_rot_alpha: r.wrist_rot_alpha,
        res_obj_pos_coef: r.obj_pos_coef,
        res_obj_rot_coef: r.obj_rot_coef,
        res_ema: r.ema,
        res_scale_wrist_pos: r.scale_wrist_pos,
        res_scale_wrist_rot: r.scale_wrist_rot,
        res_scale_tips: r.scale_tips,
        res_clamp_wrist_pos: r.clamp_wrist_pos,
        res_clamp_wrist_rot: r.clamp_wrist_rot,
        res_clamp_tips: r.clamp_tips,
        control_dt,
        rw_obj_pos: r.reward_obj_pos,
        rw_obj_rot: r.reward_obj_rot,
        rw_tips: r.reward_tips,
        rw_wrist_pos: r.reward_wrist_pos,
        rw_wrist_rot: r.reward_wrist_rot,
        grip_force_limit: t.hand.grip_force_limit,
        penetration_tolerance: t.hand.penetration_tolerance,
        _pad1: 0.0,
        ik: IkParams::default(),
    };
    // episode length for the learner's random initial episode lengths: the longest reference
    let episode_length = match (&bank, t.episode_length) {
        (Some(b), 0) => b.info.iter().map(|i| i.n_frames.saturating_sub(1)).max().unwrap_or(1).max(1),
        _ => t.episode_length,
    };
    let spec = TaskSpec {
        num_envs: es.num_envs,
        obs_dim,
        priv_dim,
        action_dim,
        obs_names,
        priv_names,
        action_names,
        term_names: terms.iter().map(|t| t.name.to_string()).collect(),
        episode_length,
        control_dt,
        kind: t.kind,
        obs_layout,
        priv_layout,
    };
    Ok(TaskSetup { spec, tc, bank, rg })
}

/// The reference layer's view of a task's bank (an empty one for the lift task).
pub fn ref_model<'a>(model: &'a SimModel, bank: Option<&'a RefBank>, rg: &'a RefGlobals) -> RefModel<'a> {
    match bank {
        Some(b) => RefModel::new(model, b, rg),
        None => RefModel { g: &model.globals, joints: &model.joints, rg, info: &[], frames: &[] },
    }
}
