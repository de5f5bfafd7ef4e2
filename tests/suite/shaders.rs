//! Shader validation with naga (no GPU needed): every shader parses and validates as the module the
//! GPU backend builds, each shader parses on its own with common.wgsl, every Pod struct in
//! src/gpu/layout.rs has exactly the size and field offsets of its WGSL twin, and the binding tables
//! of src/gpu/bindings.rs name every WGSL binding (index, name, address space) and what each
//! entry point uses.


use crate::common::validate;
use dextrain::gpu::shaders::{SHADER_COMMON, SHADER_PHYSICS, SHADER_RESET, shader_source};
use dextrain::task::layout::*;
use dextrain::task::shaders::{SHADER_IK, SHADER_REFERENCE, SHADER_TASK, task_shader_source};
use dextrain::gpu::layout::*;
use std::mem::{offset_of, size_of};

#[test]
fn full_module_validates_with_both_entry_points() {
    let m = validate(&shader_source());
    let names: Vec<&str> = m.entry_points.iter().map(|e| e.name.as_str()).collect();
    assert!(names.contains(&"step_main"), "entry points: {names:?}");
    assert!(names.contains(&"reset_main"), "entry points: {names:?}");
    for ep in &m.entry_points {
        assert_eq!(ep.workgroup_size, [dextrain::gpu::shaders::WORKGROUP_SIZE, 1, 1], "{}", ep.name);
    }
}

#[test]
fn task_module_validates_with_its_entry_points() {
    let m = validate(&task_shader_source());
    let names: Vec<&str> = m.entry_points.iter().map(|e| e.name.as_str()).collect();
    for name in ["task_act", "task_reward", "task_observe", "step_main", "reset_main"] {
        assert!(names.contains(&name), "{name} missing; entry points: {names:?}");
    }
    for ep in &m.entry_points {
        assert_eq!(ep.workgroup_size, [dextrain::gpu::shaders::WORKGROUP_SIZE, 1, 1], "{}", ep.name);
    }
}

#[test]
fn common_and_reset_validate_without_physics() {
    validate(&[SHADER_COMMON, SHADER_RESET].join("\n"));
    assert!(SHADER_PHYSICS.contains("fn env_step"));
}

macro_rules! rust_fields {
    ($t:ty; $($f:ident),* $(,)?) => {
        vec![$((stringify!($f), offset_of!($t, $f))),*]
    };
}

fn wgsl_struct(m: &naga::Module, name: &str) -> (u32, Vec<(String, u32)>) {
    for (_, ty) in m.types.iter() {
        if ty.name.as_deref() == Some(name) {
            if let naga::TypeInner::Struct { members, span } = &ty.inner {
                return (*span, members.iter().map(|mb| (mb.name.clone().unwrap_or_default(), mb.offset)).collect());
            }
        }
    }
    panic!("no WGSL struct {name}");
}

fn check(m: &naga::Module, name: &str, size: usize, fields: Vec<(&str, usize)>) {
    let (span, members) = wgsl_struct(m, name);
    assert_eq!(span as usize, size, "{name}: WGSL size {span} vs Rust size {size}");
    // Rust pads with arrays where WGSL lists separate pad fields: compare the named, non-pad fields
    let wgsl: Vec<(String, u32)> = members.into_iter().filter(|(n, _)| !n.starts_with('_')).collect();
    let rust: Vec<(String, u32)> = fields.into_iter().filter(|(n, _)| !n.starts_with('_')).map(|(n, o)| (n.to_string(), o as u32)).collect();
    assert_eq!(wgsl, rust, "{name}: field names/offsets differ between WGSL and Rust");
}

#[test]
fn pod_structs_match_their_wgsl_twins() {
    let m = validate(&shader_source());
    check(&m, "Globals", size_of::<Globals>(), rust_fields!(Globals; init_wrist_pos, init_wrist_rot, obj_init, rnd,
        n_envs, n_joints, n_colliders, n_tips, n_links, n_objects, n_obj_pts, substeps, decimation, seed, hand_table, n_springs,
        dt, gravity, contact_k, contact_kt, hand_eff_mass, hand_friction, n_ref_objects, obj_friction, table_friction, yaw_noise,
        hand_mass, hand_inertia, wrist_added_mass, wrist_added_inertia, wrist_kp_lin, wrist_kd_lin, wrist_force_limit,
        wrist_kp_rot, wrist_kd_rot, wrist_torque_limit, max_speed, max_distance, torsion_radius, hand_contact_k, hand_contact_kt, env_offset, _pad2));
    check(&m, "JointDesc", size_of::<JointDesc>(), rust_fields!(JointDesc; origin_pos, origin_rot, axis, parent_link, mimic_leader,
        mimic_mult, mimic_offset, lower, upper, effort, velocity, damping, friction, armature, link_inertia, kp, kd, default_q, _pad));
    check(&m, "ColliderDesc", size_of::<ColliderDesc>(), rust_fields!(ColliderDesc; pos, rot, size, link, shape, tip, _pad));
    check(&m, "TipDesc", size_of::<TipDesc>(), rust_fields!(TipDesc; pos, link, _pad));
    check(&m, "EnvState", size_of::<EnvState>(), rust_fields!(EnvState; wrist_pos, wrist_rot, wrist_vel, wrist_angvel,
        obj_pos, obj_rot, obj_vel, obj_angvel, q, qd, time, episode, step, bad_resets));
    check(&m, "EnvParams", size_of::<EnvParams>(), rust_fields!(EnvParams; obj_com, obj_inertia, obj_friction, restitution,
        obj_scale, table_friction, hand_friction, hand_mass_scale, limit_scale, kp_scale, kd_scale, added_gravity,
        obj_contact_c, hand_table_c, obj_index, obj_rest_height, _pad, ext_force, ext_point));
    check(&m, "PieceDesc", size_of::<PieceDesc>(), rust_fields!(PieceDesc; pos, rot, size, shape, n_support, hull_first, hull_faces));
    check(&m, "ObjectDesc", size_of::<ObjectDesc>(), rust_fields!(ObjectDesc; com, principal_rot, inertia, first_piece, n_pieces,
        n_support, rest_height));
    check(&m, "Targets", size_of::<Targets>(), rust_fields!(Targets; wrist_pos, wrist_rot, q));
    check(&m, "StepStats", size_of::<StepStats>(), rust_fields!(StepStats; tip_force, max_pen_ho, max_pen, contacts,
        contacts_ho, bad_reset, link_contact, table_contact, _pad));
    let m = validate(&task_shader_source());
    check(&m, "TaskGlobals", size_of::<TaskGlobals>(), rust_fields!(TaskGlobals; wrist_pos_min, wrist_pos_max, palm_offset,
        weights, actuated, n_actuated, n_act, obs_dim, priv_dim, episode_length, finger_mode, thumb, obj_delay_min, wrist_pos_scale,
        wrist_rot_scale, wrist_rot_limit, finger_delta_scale, reach_alpha, success_height, contact_force, drop_height,
        table_half_extent, max_hand_distance, noise_joint_pos, noise_joint_vel, noise_hand_pos, noise_object_pos,
        noise_object_rot, obj_delay_max, kind, n_terms, start_mode, lookahead, lookahead_stride, n_res, open_loop, track_action,
        beta_joint, beta_wrist_pos, beta_wrist_rot, alpha_joint, alpha_wrist_pos, alpha_wrist_rot, alpha_object_pos,
        alpha_object_rot, success_pos_tol, success_rot_tol, max_object_error, res_alpha, res_wrist_pos_alpha,
        res_wrist_rot_alpha, res_obj_pos_coef, res_obj_rot_coef, res_ema, res_scale_wrist_pos, res_scale_wrist_rot,
        res_scale_tips, res_clamp_wrist_pos, res_clamp_wrist_rot, res_clamp_tips, control_dt, rw_obj_pos, rw_obj_rot,
        rw_tips, rw_wrist_pos, rw_wrist_rot, grip_force_limit, penetration_tolerance, _pad1, ik));
    check(&m, "TaskState", size_of::<TaskState>(), rust_fields!(TaskState; targets, rest_pos, prev_action, tip_force,
        act_rate, act_mag, done, res_sq, link_contact, cursor, res_ema, res_delta, obj_hist_pos, obj_hist_rot,
        obj_delay, _pad3));
    // the reference layer (reference.wgsl, src/task/reference.rs)
    use dextrain::task::reference::{RefCursor, RefFrame, RefGlobals, RefInfo};
    check(&m, "RefInfo", size_of::<RefInfo>(), rust_fields!(RefInfo; obj0_pos, obj0_rot, bbox_min, bbox_max, first_frame, n_frames, first_segment_steps, flags));
    check(&m, "RefGlobals", size_of::<RefGlobals>(), rust_fields!(RefGlobals; n_refs, stride, n_joints, n_tips, off_wrist_pos, off_wrist_rot,
        off_q, off_tips, off_obj_pos, off_obj_rot, off_grasp, reground, reinterp, reinterp_steps, _pad0, _pad1, translate_xy, rotate_z,
        mirror_prob, time_scale, wrist_pos_offset, wrist_rot_offset, joint_offset, wrist_pos_noise, joint_noise, _pad2));
    check(&m, "RefCursor", size_of::<RefCursor>(), rust_fields!(RefCursor; d_pos, d_rot, start_pos, start_rot, wrist_off_pos, wrist_off_rot,
        ref_id, env, episode, flags, speed, seg_steps, _pad));
    check(&m, "RefFrame", size_of::<RefFrame>(), rust_fields!(RefFrame; wrist_pos, wrist_rot, obj_pos, obj_rot, tips, q, grasp, ended, _pad));
    assert_eq!(size_of::<RefGlobals>() % 16, 0);
    assert!(size_of::<RefCursor>() <= 128 && size_of::<RefCursor>() % 16 == 0);
    // a uniform struct's size must be a multiple of 16
    assert_eq!(size_of::<TaskGlobals>() % 16, 0);
    // the learner's matrix product (a module of its own)
    use dextrain::learn::kernels::wgsl_matmul::{Loads, MatmulCfg, Tile, Variant, shader_source as matmul_source};
    let reads = [Loads::Scalar, Loads::Vec4AlongK, Loads::Vec4Across];
    let whole = |depth: usize, extent: usize, l: Loads| l == Loads::Scalar || (depth * extent / 4) % 256 == 0;
    let variants = Tile::CANDIDATES.into_iter().flat_map(|tile| reads.into_iter().flat_map(move |a| reads.into_iter().map(move |b| Variant { tile, a, b })));
    for v in variants.filter(|v| whole(v.tile.depth, v.tile.rows, v.a) && whole(v.tile.depth, v.tile.cols, v.b)) {
        // each tile shape's text, with each way of reading A and B, is valid WGSL, its constants filled in
        let src = matmul_source(v);
        let tile = v.label();
        assert!(!src.contains('$'), "{tile}: a template marker left in matmul.wgsl");
        let mm = validate(&src);
        check(&mm, "MatmulCfg", size_of::<MatmulCfg>(), rust_fields!(MatmulCfg; m, n, k, batches, a_row, a_col, a_batch, b_row, b_col, b_batch, c_batch, k_splits, k_chunk, epilogue, ones_row, _pad2));
    }
    assert_eq!(size_of::<MatmulCfg>() % 16, 0);
    // the sums of a split product's partials (a module of its own)
    use dextrain::learn::kernels::wgsl_matmul::{SumSplitsCfg, sum_splits_source};
    let ss = validate(&sum_splits_source(()));
    check(&ss, "SumSplitsCfg", size_of::<SumSplitsCfg>(), rust_fields!(SumSplitsCfg; len_c, len_s, splits, row));
    // the normalisers' launch constants: one slot per normaliser, an array stride of 16's multiple
    use dextrain::learn::kernels::fused_normalizer::{NormEntry, NormKernel, NormSlot, shader_source as norm_source};
    for entry in [NormEntry::Update, NormEntry::Apply] {
        let nm = validate(&norm_source(NormKernel { entry, group: 2 }));
        check(&nm, "NormSlot", size_of::<NormSlot>(), rust_fields!(NormSlot; rows, cols, first, _pad, w_mean, w_m2, count, eps));
    }
    assert_eq!(size_of::<NormSlot>() % 16, 0);
}

#[test]
fn shader_constants_match_rust() {
    let src = shader_source();
    for (name, v) in [
        ("MAX_JOINTS", dextrain::hand::MAX_JOINTS),
        ("MAX_TIPS", dextrain::hand::MAX_TIPS),
        ("MAX_PIECES", MAX_PIECES),
        ("MAX_LINKS", dextrain::env::physics::MAX_LINKS),
        ("PROJ_ITERS", dextrain::env::physics::PROJ_ITERS),
        ("BOX_PROJ_ITERS", dextrain::env::physics::BOX_PROJ_ITERS),
        ("REVISIT_WORDS", dextrain::env::physics::REVISIT_WORDS),
        ("MAX_REACTIONS", dextrain::env::physics::MAX_REACTIONS),
    ] {
        assert!(src.contains(&format!("const {name}: u32 = {v}u;")), "{name} should be {v} in the WGSL");
    }
    use dextrain::task::task;
    for (name, v) in [
        ("PURPOSE_OBS_NOISE", task::PURPOSE_OBS_NOISE as usize),
        ("PURPOSE_OBJ_DELAY", task::PURPOSE_OBJ_DELAY as usize),
        ("OBJ_HIST", dextrain::task::layout::OBJ_HIST),
        ("OBS_KEY_STRIDE", task::OBS_KEY_STRIDE as usize),
        ("MAX_ACTIONS", MAX_ACTIONS),
        ("MAX_TERMS", task::MAX_TERMS),
        ("KIND_LIFT", task::KIND_LIFT as usize),
        ("KIND_TRACK", task::KIND_TRACK as usize),
        ("KIND_RESIDUAL_JOINT", task::KIND_RESIDUAL_JOINT as usize),
        ("KIND_RESIDUAL_TASK", task::KIND_RESIDUAL_TASK as usize),
        ("OUT_REWARD", task::OUT_REWARD),
        ("OUT_TERMS", task::OUT_TERMS),
        ("OUT_TERMINATED", task::OUT_TERMINATED),
        ("OUT_TIME_OUT", task::OUT_TIME_OUT),
        ("OUT_SUCCESS", task::OUT_SUCCESS),
        ("OUT_LIFT", task::OUT_LIFT),
        ("OUT_MAX_PEN", task::OUT_MAX_PEN),
        ("OUT_OBJ_POS_ERR", task::OUT_OBJ_POS_ERR),
        ("OUT_OBJ_ROT_ERR", task::OUT_OBJ_ROT_ERR),
        ("OUT_BAD_RESET", task::OUT_BAD_RESET),
        ("OUT_MISC", task::OUT_MISC),
    ] {
        assert!(SHADER_TASK.contains(&format!("const {name}: u32 = {v}u;")), "{name} should be {v} in task.wgsl");
    }
    // every kind's terms fit the output record's term slots, and the kinds are the config's
    for kind in dextrain::config::TaskKind::ALL {
        assert!(dextrain::task::spec::reward_terms(kind).len() <= task::MAX_TERMS, "{kind}");
        let name = format!("KIND_{}", kind.name().to_uppercase());
        assert!(SHADER_TASK.contains(&format!("const {name}: u32 = {}u;", kind.index())), "{name} should be {} in task.wgsl", kind.index());
    }
    // the reset purposes and the task's are distinct
    for p in [dextrain::env::reset::PURPOSE_PARAMS, dextrain::env::reset::PURPOSE_INIT] {
        assert_ne!(p, task::PURPOSE_OBS_NOISE);
    }
    // the learner's action noise has its own stream, the same in noise.wgsl
    use dextrain::learn::noise::PURPOSE_ACTION_NOISE;
    assert!(dextrain::gpu::shaders::SHADER_NOISE.contains(&format!("const PURPOSE_ACTION_NOISE: u32 = {PURPOSE_ACTION_NOISE}u;")));
    let purposes = [dextrain::env::reset::PURPOSE_PARAMS, dextrain::env::reset::PURPOSE_INIT, task::PURPOSE_OBS_NOISE, task::PURPOSE_OBJ_DELAY, dextrain::task::reference::PURPOSE_REF];
    assert!(!purposes.contains(&PURPOSE_ACTION_NOISE), "{purposes:?}");
    use dextrain::task::reference::*;
    for (name, v) in [
        ("PURPOSE_REF", PURPOSE_REF),
        ("REF_KEY_ID", REF_KEY_ID),
        ("REF_KEY_SPEED", REF_KEY_SPEED),
        ("REF_KEY_MIRROR", REF_KEY_MIRROR),
        ("REF_KEY_TRANSLATE", REF_KEY_TRANSLATE),
        ("REF_KEY_ROTATE", REF_KEY_ROTATE),
        ("REF_KEY_WRIST_POS", REF_KEY_WRIST_POS),
        ("REF_KEY_WRIST_ROT", REF_KEY_WRIST_ROT),
        ("REF_KEY_JOINT", REF_KEY_JOINT),
        ("REF_KEY_NOISE", REF_KEY_NOISE),
        ("REF_KEY_STRIDE", REF_KEY_STRIDE),
        ("CUR_WRIST", CUR_WRIST),
        ("CUR_JOINT", CUR_JOINT),
        ("CUR_MIRROR", CUR_MIRROR),
        ("CUR_TRANSFORM", CUR_TRANSFORM),
        ("CUR_REINTERP", CUR_REINTERP),
        ("REF_HAS_OBJECT", REF_HAS_OBJECT),
        ("REF_TIPS_FROM_FILE", REF_TIPS_FROM_FILE),
    ] {
        assert!(SHADER_REFERENCE.contains(&format!("const {name}: u32 = {v}u;")), "{name} should be {v} in reference.wgsl");
    }
    // the reference draw keys do not overlap: joints end before the noise, one step's noise fits its stride
    assert!(REF_KEY_JOINT as usize + dextrain::hand::MAX_JOINTS <= REF_KEY_NOISE as usize);
    assert!(2 * (3 + dextrain::hand::MAX_JOINTS) <= REF_KEY_STRIDE as usize);
    for p in [dextrain::env::reset::PURPOSE_PARAMS, dextrain::env::reset::PURPOSE_INIT, task::PURPOSE_OBS_NOISE] {
        assert_ne!(p, PURPOSE_REF);
    }
    for (name, v) in [("SHAPE_SPHERE", SHAPE_SPHERE), ("SHAPE_BOX", SHAPE_BOX), ("SHAPE_CAPSULE", SHAPE_CAPSULE), ("SHAPE_CYLINDER", SHAPE_CYLINDER), ("SHAPE_HULL", SHAPE_HULL)] {
        assert!(src.contains(&format!("const {name}: u32 = {v}u;")), "{name} should be {v} in the WGSL");
    }
    assert_eq!((NO_JOINT, NO_OBJECT), (u32::MAX, u32::MAX));
    for name in ["NO_JOINT", "NO_OBJECT"] {
        assert!(src.contains(&format!("const {name}: u32 = 0xffffffffu;")), "{name} should be u32::MAX in the WGSL");
    }
}

#[test]
fn every_shader_function_has_its_cpu_twin_in_the_same_order() {
    // docs/design.md §4: same function names in the same order in shaders/x.wgsl and its twin (src/env/x.rs, src/task/x.rs)
    let fns = |src: &str, prefix: &str| -> Vec<String> {
        src.lines()
            .filter_map(|l| l.trim_start().strip_prefix(prefix))
            .map(|rest| rest.split(|c| c == '(' || c == '<').next().unwrap_or("").trim().to_string())
            .collect()
    };
    for (wgsl, rs) in [
        (SHADER_COMMON, include_str!("../../src/env/common.rs")),
        (SHADER_RESET, include_str!("../../src/env/reset.rs")),
        (SHADER_PHYSICS, include_str!("../../src/env/physics.rs")),
        (SHADER_REFERENCE, include_str!("../../src/task/reference.rs")),
        (SHADER_IK, include_str!("../../src/task/ik.rs")),
        (SHADER_TASK, include_str!("../../src/task/task.rs")),
    ] {
        let w: Vec<String> = fns(wgsl, "fn ").into_iter().filter(|n| !n.ends_with("_main") && n != "env_index").collect();
        let r: Vec<String> = fns(rs, "pub fn ").into_iter().filter(|n| w.contains(n)).collect();
        assert!(!w.is_empty());
        assert_eq!(w, r, "shader functions and their CPU twins differ in names or order");
    }
}

/// Reward terms are named, not positional: each kind's terms come from one table
/// (`task::spec::reward_terms`), task.wgsl has one `T_<KIND>_<TERM>` slot constant per table row at
/// the row's index (and no other), the Rust twin's constants are the same, and the config's
/// default weights name exactly the table's terms.
#[test]
fn reward_term_slots_agree_in_the_table_the_shader_and_the_config() {
    use dextrain::config::TaskKind;
    use dextrain::task::spec::reward_terms;
    use dextrain::task::task::*;
    let declared: Vec<(String, usize)> = SHADER_TASK
        .lines()
        .filter_map(|l| l.trim().strip_prefix("const T_"))
        .filter_map(|l| {
            let (name, rest) = l.split_once(": u32 = ")?;
            Some((name.to_string(), rest.trim_end_matches(';').trim_end_matches('u').parse().ok()?))
        })
        .collect();
    let mut expected = Vec::new();
    for kind in TaskKind::ALL {
        let terms = reward_terms(kind);
        assert!(terms.len() <= MAX_TERMS, "{kind}");
        let mut names: Vec<&str> = terms.iter().map(|t| t.name).collect();
        for (k, t) in terms.iter().enumerate() {
            let name = format!("{}_{}", kind.name().to_uppercase(), t.name.to_uppercase());
            assert!(declared.contains(&(name.clone(), k)), "task.wgsl should declare `const T_{name}: u32 = {k}u;` ({kind}'s term {:?})", t.name);
            expected.push((name, k));
            assert!(!t.formula.is_empty(), "{kind}.{}: a formula", t.name);
        }
        names.sort();
        let defaults = kind.default_rewards();
        assert_eq!(defaults.keys().map(String::as_str).collect::<Vec<_>>(), names, "{kind}: the default weights name the table's terms");
    }
    let mut declared_sorted = declared.clone();
    declared_sorted.sort();
    expected.sort();
    assert_eq!(declared_sorted, expected, "task.wgsl declares exactly the tables' term slots");
    // the Rust twin's slots are the tables' (a sample of each kind)
    assert_eq!((T_LIFT_REACHING, T_LIFT_ACTION_MAGNITUDE), (0, 5));
    assert_eq!((T_TRACK_HAND_FOLLOWING, T_TRACK_LIFTING), (0, 4));
    assert_eq!((T_RESIDUAL_JOINT_RESIDUAL, T_RESIDUAL_TASK_TABLE_COLLISION), (2, 7));
    for (name, k) in &declared {
        let (kind, term) = TaskKind::ALL
            .iter()
            .find_map(|kd| name.strip_prefix(&format!("{}_", kd.name().to_uppercase())).map(|t| (*kd, t.to_lowercase())))
            .unwrap_or_else(|| panic!("T_{name}: no task kind"));
        assert_eq!(reward_terms(kind).iter().position(|t| t.name == term), Some(*k), "T_{name}");
    }
}

/// Every `@group(g) @binding(k) var<space> name` of a WGSL module, sorted by (group, index), and
/// the binding indices that each entry point uses (reads, writes or queries), sorted.
fn wgsl_bindings(src: &str) -> (Vec<(u32, u32, String, dextrain::gpu::bindings::BindingSpace)>, Vec<(String, Vec<u32>)>) {
    use dextrain::gpu::bindings::BindingSpace;
    let module = validate(src);
    let info = naga::valid::Validator::new(naga::valid::ValidationFlags::all(), naga::valid::Capabilities::empty())
        .validate(&module)
        .unwrap_or_else(|e| panic!("WGSL validation error: {e:?}"));
    let mut declared = Vec::new();
    for (_, var) in module.global_variables.iter() {
        let Some(rb) = &var.binding else { continue };
        let name = var.name.clone().unwrap_or_default();
        let space = match var.space {
            naga::AddressSpace::Uniform => BindingSpace::Uniform,
            naga::AddressSpace::Storage { access } if access.contains(naga::StorageAccess::STORE) => BindingSpace::StorageReadWrite,
            naga::AddressSpace::Storage { .. } => BindingSpace::StorageRead,
            other => panic!("binding {} `{name}` is in address space {other:?}, which no table describes", rb.binding),
        };
        declared.push((rb.group, rb.binding, name, space));
    }
    declared.sort_by_key(|d| (d.0, d.1));
    let used = module
        .entry_points
        .iter()
        .enumerate()
        .map(|(i, ep)| {
            let fi = info.get_entry_point(i);
            let mut ix: Vec<u32> = module
                .global_variables
                .iter()
                .filter(|(h, v)| v.binding.is_some() && !fi[*h].is_empty())
                .filter_map(|(_, v)| v.binding.as_ref().map(|b| b.binding))
                .collect();
            ix.sort();
            (ep.name.clone(), ix)
        })
        .collect();
    (declared, used)
}

/// A binding table as (group 0, index, name, space), sorted by index.
fn table(bindings: &[dextrain::gpu::bindings::Binding]) -> Vec<(u32, u32, String, dextrain::gpu::bindings::BindingSpace)> {
    let mut t: Vec<_> = bindings.iter().map(|b| (0, b.index, b.name.to_string(), b.space)).collect();
    t.sort_by_key(|d| d.1);
    t
}

#[test]
fn binding_tables_match_the_wgsl_globals() {
    use dextrain::gpu::bindings::{AL_GROUP, BindingSpace, COLLIDERS, CS_GROUP, ELU_FORWARD_GROUP, ELU_GROUP, GAE_GROUP, LN_GROUP, LNB_GROUP, LNBE_GROUP, LS_GROUP, MM_GROUP, NOISE_GROUP, PL_BACKWARD_FINISH_GROUP, PL_BACKWARD_GROUP, PL_FINISH_GROUP, PL_ROWS_GROUP, REF_CFG, REF_FRAMES, RG_GROUP, RW_GROUP, SIM_GROUP, SL_BACKWARD_GROUP, SL_FINISH_GROUP, SL_ROWS_GROUP, SQ_GROUP, SQB_GROUP, SR_GROUP, SS_GROUP, ST_GROUP, TASK_GROUP};
    use dextrain::learn::kernels::ppo_loss::ppo_loss_source;
    use dextrain::learn::kernels::sac_loss::sac_loss_source;
    let noise = dextrain::gpu::shaders::noise_shader_source();
    let matmul = dextrain::learn::kernels::wgsl_matmul::shader_source(dextrain::learn::kernels::wgsl_matmul::Variant::scalar(dextrain::learn::kernels::wgsl_matmul::Tile::LARGE));
    for (src, group) in [(shader_source(), SIM_GROUP), (task_shader_source(), TASK_GROUP), (noise, NOISE_GROUP), (matmul, MM_GROUP), (dextrain::learn::kernels::elu::elu_backward_source(()), ELU_GROUP), (dextrain::learn::kernels::elu::elu_forward_source(()), ELU_FORWARD_GROUP), (dextrain::learn::kernels::replay_sample::gather_source(()), RG_GROUP), (dextrain::learn::kernels::replay_sample::window_source(()), RW_GROUP), (dextrain::learn::kernels::row_sums::column_sums_source(()), CS_GROUP), (dextrain::learn::kernels::wgsl_matmul::sum_splits_source(()), SS_GROUP), (dextrain::learn::kernels::layer_norm::layer_norm_forward_source(false), LN_GROUP), (dextrain::learn::kernels::layer_norm::layer_norm_forward_source(true), LN_GROUP), (dextrain::learn::kernels::layer_norm::layer_norm_backward_source(false), LNB_GROUP), (dextrain::learn::kernels::layer_norm::layer_norm_backward_source(true), LNBE_GROUP), (dextrain::learn::kernels::squashed::squashed_sample_source(()), SQ_GROUP), (dextrain::learn::kernels::squashed::squashed_sample_backward_source(()), SQB_GROUP), (ppo_loss_source(0), PL_ROWS_GROUP), (ppo_loss_source(1), PL_FINISH_GROUP), (ppo_loss_source(2), PL_BACKWARD_GROUP), (ppo_loss_source(3), PL_BACKWARD_FINISH_GROUP), (sac_loss_source(0), SL_ROWS_GROUP), (sac_loss_source(1), SL_FINISH_GROUP), (sac_loss_source(2), SL_BACKWARD_GROUP), (dextrain::learn::kernels::adaptive_lr::adaptive_lr_source(()), AL_GROUP), (dextrain::learn::kernels::standardize::standardize_source(()), ST_GROUP), (dextrain::learn::kernels::ppo_rollout::step_reward_source(()), SR_GROUP), (dextrain::learn::kernels::ppo_rollout::gae_source(()), GAE_GROUP), (dextrain::run::device_loop::loop_sums_source(()), LS_GROUP)] {
        let (declared, used) = wgsl_bindings(&src);
        // every global of the module, by group, index, name and address space, is in the table and no other
        assert_eq!(declared, table(group.bindings), "{}: the WGSL's bindings (left) differ from gpu/bindings.rs (right)", group.shader);
        // indices and names are unique, and indices from 25 up stay free for the test kernels
        let mut ix: Vec<u32> = group.bindings.iter().map(|b| b.index).collect();
        ix.sort();
        ix.dedup();
        assert_eq!(ix.len(), group.bindings.len(), "{}: an index appears twice", group.shader);
        assert!(ix.iter().all(|&i| i < 25), "{}: {ix:?}", group.shader);
        // each entry point's table lists exactly the globals it uses (its bind group binds these)
        for ep in group.entry_points {
            let (_, uses) = used.iter().find(|(n, _)| n == ep.entry_point).unwrap_or_else(|| panic!("{}: no entry point {}", group.shader, ep.entry_point));
            let mut table_ix: Vec<u32> = ep.bindings.iter().map(|b| b.index).collect();
            table_ix.sort();
            assert_eq!(uses, &table_ix, "{}: entry point {} uses (left) vs its table (right)", group.shader, ep.entry_point);
            assert!(ep.bindings.iter().all(|b| group.bindings.contains(b)), "{}: {} binds a binding the module lacks", group.shader, ep.entry_point);
        }
    }
    // spot checks against the WGSL text: the reference bank at 13–15, the uniforms where the tables say
    assert!(SHADER_REFERENCE.contains("@group(0) @binding(13) var<storage, read> ref_frames: array<f32>;"));
    assert_eq!((REF_FRAMES.index, REF_CFG.index, REF_CFG.space), (13, 15, BindingSpace::Uniform));
    // the comparison has teeth: a binding moved in the WGSL alone no longer matches the table
    let moved = shader_source().replace("@group(0) @binding(2) var<storage, read> colliders", "@group(0) @binding(17) var<storage, read> colliders");
    assert_ne!(moved, shader_source());
    let (declared, _) = wgsl_bindings(&moved);
    assert_ne!(declared, table(SIM_GROUP.bindings), "moving `{}` to binding 17 should break the match", COLLIDERS.name);
}

/// The optimiser's template (shaders/adam.wgsl, `learn::kernels::fused_adam`): each entry point over
/// groups of 1, 2 and 17 parameters is valid WGSL with no marker left, one entry point, and
/// bindings 0, 1, … in the order the launch passes its tensors (each role's parameters, then the
/// shared tensors), the uniform last, every one used (cubecl binds every tensor it is given: a
/// binding the kernel does not use would be left out of its layout).
#[test]
fn the_optimiser_s_kernels_bind_what_they_are_given() {
    use dextrain::gpu::bindings::BindingSpace;
    use dextrain::learn::kernels::fused_adam::{AdamEntry, AdamKernel, shader_source as adam_source, storage_bindings};
    for entry in [AdamEntry::NormPartial, AdamEntry::NormFinal, AdamEntry::Update, AdamEntry::UpdatePolyak] {
        for group in [1, 2, 17] {
            let src = adam_source(AdamKernel { entry, group });
            assert!(!src.contains('$'), "{entry:?} × {group}: a template marker left");
            let (declared, used) = wgsl_bindings(&src);
            let storage = storage_bindings(entry, group);
            let want: Vec<u32> = (0..=storage).collect();
            assert_eq!(declared.iter().map(|d| d.1).collect::<Vec<_>>(), want, "{entry:?} × {group}: {declared:?}");
            assert!(declared[..storage as usize].iter().all(|d| d.3 == BindingSpace::StorageReadWrite) && declared[storage as usize].3 == BindingSpace::Uniform, "{entry:?} × {group}: {declared:?}");
            assert_eq!(used, vec![(entry.name().to_string(), want.clone())], "{entry:?} × {group}");
        }
    }
    // the per-parameter roles: the gradients alone for the norm's slices, four per parameter for
    // the update, five with the Polyak targets
    assert_eq!([storage_bindings(AdamEntry::NormPartial, 17), storage_bindings(AdamEntry::NormFinal, 1), storage_bindings(AdamEntry::Update, 17), storage_bindings(AdamEntry::UpdatePolyak, 17)], [18, 3, 70, 87]);
}

/// The row blocks' stacking kernel (`kernels::cat_rows`, a template) over 1, 2 and 31 parts: valid
/// WGSL with a storage binding per part, then the output, then the launch's constants, every one
/// used by its entry point in that order (the order the launch passes the tensors).
#[test]
fn the_row_stacking_kernel_binds_its_parts_then_its_output() {
    use dextrain::gpu::bindings::BindingSpace;
    use dextrain::learn::kernels::cat_rows::shader_source;
    for group in [1u32, 2, 31] {
        let src = shader_source(group);
        assert!(!src.contains('$'), "{group} parts: a template marker left");
        let (declared, used) = wgsl_bindings(&src);
        let want: Vec<u32> = (0..=group + 1).collect();
        assert_eq!(declared.iter().map(|d| d.1).collect::<Vec<_>>(), want, "{group} parts: {declared:?}");
        assert_eq!(declared[group as usize].2, "cat_out", "{group} parts: the output after the parts");
        assert!(declared[..=group as usize].iter().all(|d| d.3 == BindingSpace::StorageReadWrite) && declared[group as usize + 1].3 == BindingSpace::Uniform, "{group} parts: {declared:?}");
        assert_eq!(used, vec![("cat_rows".to_string(), want.clone())], "{group} parts");
    }
}

/// The normalisers' kernels (`kernels::fused_normalizer`, a template) over one and two
/// normalisers: valid WGSL with no marker left, one entry point, a storage binding per normaliser
/// and role (each role's together: x, mean, M2, scale for the update; x, mean, scale, out for the
/// apply) in the order the launch passes its tensors, the uniform last, every one used.
#[test]
fn the_normalisers_kernels_bind_each_normaliser_s_tensors_by_role() {
    use dextrain::gpu::bindings::BindingSpace;
    use dextrain::learn::kernels::fused_normalizer::{NormEntry, NormKernel, shader_source, storage_bindings};
    for (entry, roles) in [(NormEntry::Update, ["norm_x", "norm_mean", "norm_m2", "norm_scale"]), (NormEntry::Apply, ["norm_x", "norm_mean", "norm_scale", "norm_out"])] {
        for group in [1u32, 2] {
            let src = shader_source(NormKernel { entry, group });
            assert!(!src.contains('$'), "{entry:?} × {group}: a template marker left");
            let (declared, used) = wgsl_bindings(&src);
            let storage = storage_bindings(entry, group);
            assert_eq!(storage, 4 * group);
            let want: Vec<u32> = (0..=storage).collect();
            assert_eq!(declared.iter().map(|d| d.1).collect::<Vec<_>>(), want, "{entry:?} × {group}: {declared:?}");
            let names: Vec<String> = roles.iter().flat_map(|r| (0..group).map(move |k| format!("{r}_{k}"))).collect();
            assert_eq!(declared[..storage as usize].iter().map(|d| d.2.clone()).collect::<Vec<_>>(), names, "{entry:?} × {group}");
            assert!(declared[..storage as usize].iter().all(|d| d.3 == BindingSpace::StorageReadWrite) && declared[storage as usize].3 == BindingSpace::Uniform, "{entry:?} × {group}: {declared:?}");
            assert_eq!(used, vec![(entry.name().to_string(), want.clone())], "{entry:?} × {group}");
        }
    }
}

/// The simulator step's workgroup size by batch (`step_workgroup_size`): the largest size that
/// leaves 128 workgroups and fits the device, else 32; the built-in module at each size
/// (`shader_source_at`) declares that size for both entry points, its rounds' workgroup memory
/// growing with it (what a device's limit is checked against); and the collider lists' words by
/// hand (`collider_words`), the rounds' lists shrinking with them.
#[test]
fn the_step_s_workgroup_size_follows_the_batch() {
    use dextrain::gpu::shaders::{STEP_WORKGROUP_SIZES, collider_words, module_workgroups, shader_source_at, step_workgroup_size};
    let all = |_: u32| true;
    assert_eq!(step_workgroup_size(100, all), 32);
    assert_eq!(step_workgroup_size(2048, all), 32);
    assert_eq!(step_workgroup_size(8192, all), 64);
    assert_eq!(step_workgroup_size(16384, all), 128);
    assert_eq!(step_workgroup_size(65536, all), 512);
    assert_eq!(step_workgroup_size(1 << 20, all), 512);
    // a device that takes none above 256 (lavapipe's 32 kB of workgroup memory)
    assert_eq!(step_workgroup_size(65536, |s| s <= 256), 256);
    assert_eq!(step_workgroup_size(65536, |_| false), 32);
    let mut last = 0;
    for size in STEP_WORKGROUP_SIZES.into_iter().rev() {
        let source = shader_source_at(size, 8);
        validate(&source);
        let (sizes, bytes) = module_workgroups(&source, &["step_main", "reset_main"]).unwrap();
        assert_eq!(sizes, [size, size]);
        assert!(bytes > last, "workgroup memory at {size}: {bytes} bytes");
        last = bytes;
    }
    assert_eq!(shader_source_at(64, 8), dextrain::gpu::shaders::shader_source(), "64 and 8 words are the module as written");
    // the collider lists' words by hand: the bench hand's 17 colliders 1, 71 colliders 3, at most 8
    assert_eq!([collider_words(0), collider_words(17), collider_words(32), collider_words(33), collider_words(71), collider_words(256)], [1, 1, 1, 2, 3, 8]);
    let (_, one_word) = module_workgroups(&shader_source_at(512, 1), &[]).unwrap();
    validate(&shader_source_at(512, 1));
    assert!(one_word * 4 < last, "the rounds' lists of one word: {one_word} bytes against {last} of 8 words");
}
