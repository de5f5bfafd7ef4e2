//! The batched hand–object environment: one model, two backends behind one trait.
//!
//! # The env contract
//!
//! An [`EnvBatch`] holds `num_envs` independent environments, each one floating-wrist hand, one rigid
//! object and the table (docs/design.md §4). Every env has its own [`EnvState`] (wrist, object, joints,
//! friction springs, counters) and [`EnvParams`] (physical parameters drawn at its last reset).
//!
//! - [`EnvBatch::reset_all`] starts episode 0 of every env; [`EnvBatch::reset`] starts the next episode
//!   of the envs whose mask entry is true. A reset draws the env's parameters and initial state from a
//!   counter-based hash of (seed, env, episode, purpose), so both backends draw the same numbers.
//! - [`EnvBatch::step`] takes one [`Targets`] per env (wrist pose, joint positions; mimic followers'
//!   entries are ignored) and advances every env by one control step: `decimation` physics steps of
//!   `dt`, each split into `substeps`. Targets are held over the control step.
//! - After a step, [`EnvBatch::stats`] says, per env, what happened during it (contact counts, deepest
//!   penetration, fingertip forces, whether it was reset). An env whose state became non-finite or left
//!   the configured speed/distance bounds is reset in place during the step: `bad_reset` is 1 in its
//!   stats, `EnvState::bad_resets` counts it, and no other env is touched.
//! - [`EnvBatch::states`] and [`EnvBatch::params`] read the current values back;
//!   [`EnvBatch::set_states`] overwrites the states (kinematic replay, tests).
//!
//! Steps never allocate on the GPU backend: buffers and pipelines are made once in `new`.
//! The task layer (observations, rewards, dones; [`task::TaskBatch`]) sits on top of this contract.

pub mod common;
pub mod cpu;
pub mod gpu;
pub mod object_desc;
pub mod physics;
pub mod reset;

use anyhow::{Context, Result, bail};
use glam::{Mat3, Quat, Vec3};

use crate::config::{BackendChoice, Config};
use crate::hand::{ColliderShape, HandModel, MAX_TIPS};
use crate::object::ObjectModel;
pub use crate::gpu::layout::{EnvParams, EnvState, StepStats, Targets};
use crate::gpu::layout::*;

/// Names and sizes of the env batch.
#[derive(Clone, Debug)]
pub struct EnvSpec {
    pub num_envs: usize,
    pub joint_names: Vec<String>,
    /// Indices (into `joint_names`) of the actuated joints (not mimic followers).
    pub actuated: Vec<usize>,
    pub tip_names: Vec<String>,
    pub dt: f32,
    pub substeps: u32,
    pub decimation: u32,
}

/// The backend-independent env contract (see the module documentation).
pub trait EnvBatch: Send {
    fn spec(&self) -> &EnvSpec;
    /// Human-readable backend: "cpu (rayon, N threads)" or "gpu (ADAPTER, API)".
    fn backend_name(&self) -> String;
    /// Bytes of device memory the batch's own buffers hold (every per-env buffer, the constants
    /// and the readback staging); 0 on the CPU.
    fn device_bytes(&self) -> u64 {
        0
    }
    /// Invocations per workgroup of the simulator's step on a GPU (chosen by the batch's size:
    /// `gpu::shaders::step_workgroup_size`); None on the CPU.
    fn step_workgroup_size(&self) -> Option<u32> {
        None
    }
    /// Starts episode 0 of every env.
    fn reset_all(&mut self) -> Result<()>;
    /// Starts the next episode of every env whose mask entry is true.
    fn reset(&mut self, mask: &[bool]) -> Result<()>;
    /// Advances every env by one control step toward `targets` (one per env).
    fn step(&mut self, targets: &[Targets]) -> Result<()>;
    fn states(&mut self) -> Result<Vec<EnvState>>;
    fn set_states(&mut self, states: &[EnvState]) -> Result<()>;
    /// The contact springs of every env, `[N, n_springs]` (`crate::gpu::layout::spring_slot`).
    fn springs(&mut self) -> Result<Vec<[f32; 4]>>;
    /// Overwrites the contact springs (`[N, n_springs]`; checkpoint restore).
    fn set_springs(&mut self, springs: &[[f32; 4]]) -> Result<()>;
    fn params(&mut self) -> Result<Vec<EnvParams>>;
    /// The first `k` envs' states, parameters and contact springs (`[k, n_springs]`), for a view of
    /// a few envs (the live view): the GPU batch reads only those back.
    fn first_envs(&mut self, k: usize) -> Result<(Vec<EnvState>, Vec<EnvParams>, Vec<[f32; 4]>)> {
        let k = k.min(self.spec().num_envs);
        let (mut states, mut params, mut springs) = (self.states()?, self.params()?, self.springs()?);
        let per_env = springs.len() / self.spec().num_envs.max(1);
        states.truncate(k);
        params.truncate(k);
        springs.truncate(k * per_env);
        Ok((states, params, springs))
    }
    /// Overwrites the parameters (checkpoint restore; a benchmark's external force,
    /// `EnvParams::ext_force`). They hold until the env's next reset draws new ones.
    fn set_params(&mut self, params: &[EnvParams]) -> Result<()>;
    /// What happened in each env during the last step.
    fn stats(&mut self) -> Result<Vec<StepStats>>;
}

/// Everything both backends need, built once from a config and a hand.
#[derive(Clone, Debug)]
pub struct SimModel {
    pub globals: Globals,
    pub joints: Vec<JointDesc>,
    pub colliders: Vec<ColliderDesc>,
    pub tips: Vec<TipDesc>,
    /// The run's objects (`[object]` or `[[object.set]]`, in order), their simulator descriptions
    /// and all their pieces (`objects[i]`'s from `object_descs[i].first_piece`).
    pub objects: Vec<ObjectModel>,
    pub object_descs: Vec<ObjectDesc>,
    pub pieces: Vec<PieceDesc>,
    /// The convex-hull pieces' planes, triangles and vertices (`physics::hull_vertex`).
    pub hulls: Vec<[f32; 4]>,
    /// The object of each reference of the task's bank (`NO_OBJECT` for one that names none);
    /// empty without references that name objects (`set_reference_objects`).
    pub ref_objects: Vec<u32>,
    pub hand: HandModel,
    pub spec: EnvSpec,
}

impl SimModel {
    /// Loads the config's hand and builds the model.
    pub fn from_config(cfg: &Config) -> Result<SimModel> {
        let path = cfg.resolve(&cfg.hand.urdf);
        let opts = crate::hand::HandLoadOptions {
            fingertips: cfg.hand.fingertips.clone(),
            mesh_approx: cfg.hand.mesh_approx,
            effort: cfg.hand.effort.clone(),
            velocity: cfg.hand.velocity.clone(),
        };
        // a hand that does not load names the config's key too (an empty config's default hand
        // is not next to it)
        let hand = HandModel::from_urdf_file(&path, &opts).with_context(|| {
            let default = if cfg.hand.urdf == crate::config::HandConfig::default().urdf { " (the default, relative to the config's directory)" } else { "" };
            format!("{}: key `hand.urdf` = {:?}{default}", cfg.source.display(), cfg.hand.urdf)
        })?;
        // the hand's warnings, once per process (a run builds its model more than once)
        static WARNED: std::sync::Mutex<Vec<String>> = std::sync::Mutex::new(Vec::new());
        if let Ok(mut warned) = WARNED.lock() {
            for w in &hand.warnings {
                if !warned.contains(w) {
                    crate::console::warn(&format!("warning: {w}"));
                    warned.push(w.clone());
                }
            }
        }
        SimModel::new(cfg, hand)
    }

    pub fn new(cfg: &Config, hand: HandModel) -> Result<SimModel> {
        let file = cfg.source.display();
        for (map, key) in [(&cfg.hand.joint_kp, "hand.joint_kp"), (&cfg.hand.joint_kd, "hand.joint_kd"), (&cfg.hand.init_joints, "hand.init_joints")] {
            for name in map.keys() {
                if hand.joint_index(name).is_none() {
                    let names: Vec<&str> = hand.joints.iter().map(|j| j.name.as_str()).collect();
                    bail!("{file}: key `{key}.{name}`: the hand {} has no joint '{name}' (joints: {})", hand.source.display(), names.join(", "));
                }
            }
        }
        if hand.fingertips.len() > MAX_TIPS {
            bail!("{}: {} fingertips, at most {MAX_TIPS} are supported", hand.source.display(), hand.fingertips.len());
        }
        let poses = hand.forward_kinematics(&vec![0.0; hand.joints.len()]);
        // subtree membership: is link `l` moved by joint `j`?
        let moved_by = |l: usize, j: usize| -> bool {
            let mut link = l;
            while link > 0 {
                if link == j + 1 {
                    return true;
                }
                link = hand.joints[link - 1].parent_link;
            }
            false
        };
        let link_inertia_world = |l: usize| -> Mat3 {
            let r = Mat3::from_quat(poses[l].rot);
            let i = Mat3::from_cols_array_2d(&hand.links[l].inertia).transpose();
            r * i * r.transpose()
        };
        let mut joints: Vec<JointDesc> = Vec::with_capacity(hand.joints.len());
        for (j, jt) in hand.joints.iter().enumerate() {
            let frame = poses[jt.parent_link].mul(&jt.origin);
            let axis = frame.rot * jt.axis;
            let o = frame.pos;
            // I_axis = Σ_subtree m d⊥² + aᵀ I_l a
            let mut link_inertia = 0.0;
            for l in 0..hand.links.len() {
                if !moved_by(l, j) {
                    continue;
                }
                let com = poses[l].transform_point(hand.links[l].com);
                let d = com - o;
                let perp2 = d.length_squared() - d.dot(axis).powi(2);
                link_inertia += hand.links[l].mass * perp2.max(0.0) + axis.dot(link_inertia_world(l) * axis);
            }
            let kp = cfg.hand.joint_kp.get(&jt.name).copied().unwrap_or(cfg.hand.kp);
            let kd = cfg.hand.joint_kd.get(&jt.name).copied().unwrap_or(cfg.hand.kd);
            let default_q = cfg.hand.init_joints.get(&jt.name).copied().unwrap_or(0.0);
            joints.push(JointDesc {
                origin_pos: [jt.origin.pos.x, jt.origin.pos.y, jt.origin.pos.z, 0.0],
                origin_rot: jt.origin.rot.to_array(),
                axis: [jt.axis.x, jt.axis.y, jt.axis.z, 0.0],
                parent_link: jt.parent_link as u32,
                mimic_leader: jt.mimic.map(|m| m.leader as u32).unwrap_or(NO_JOINT),
                mimic_mult: jt.mimic.map(|m| m.multiplier).unwrap_or(0.0),
                mimic_offset: jt.mimic.map(|m| m.offset).unwrap_or(0.0),
                lower: jt.lower.max(-1e30),
                upper: jt.upper.min(1e30),
                effort: jt.effort,
                velocity: jt.velocity,
                damping: jt.damping,
                friction: jt.friction,
                armature: cfg.hand.armature,
                link_inertia,
                kp,
                kd,
                default_q,
                _pad: 0.0,
            });
        }
        // a follower's inertia is carried by its leader: I_leader += mult² I_follower
        for j in 0..joints.len() {
            if joints[j].mimic_leader != NO_JOINT {
                let l = joints[j].mimic_leader as usize;
                let m2 = joints[j].mimic_mult * joints[j].mimic_mult;
                joints[l].armature += m2 * joints[j].armature;
                joints[l].link_inertia += m2 * joints[j].link_inertia;
            }
        }
        let mut colliders = Vec::with_capacity(hand.colliders.len());
        for c in &hand.colliders {
            let (shape, size) = match c.shape {
                ColliderShape::Sphere { radius } => (SHAPE_SPHERE, [radius, 0.0, 0.0, 0.0]),
                ColliderShape::Capsule { radius, half_length } => (SHAPE_CAPSULE, [radius, half_length, 0.0, 0.0]),
                ColliderShape::Box { half_extents: h } => (SHAPE_BOX, [h.x, h.y, h.z, 0.0]),
            };
            let tip = hand.fingertips.iter().position(|t| t.link == c.link).map(|i| i as u32).unwrap_or(NO_JOINT);
            colliders.push(ColliderDesc {
                pos: [c.pose.pos.x, c.pose.pos.y, c.pose.pos.z, 0.0],
                rot: c.pose.rot.to_array(),
                size,
                link: c.link as u32,
                shape,
                tip,
                _pad: 0,
            });
        }
        let tips: Vec<TipDesc> =
            hand.fingertips.iter().map(|t| TipDesc { pos: [t.pos.x, t.pos.y, t.pos.z, 0.0], link: t.link as u32, _pad: [0; 3] }).collect();
        // wrist: total mass and an isotropic rotational inertia trace(I)/3 about the wrist at q = 0
        let mut hand_mass = 0.0;
        let mut i_total = Mat3::ZERO;
        for l in 0..hand.links.len() {
            let m = hand.links[l].mass;
            let d = poses[l].transform_point(hand.links[l].com);
            hand_mass += m;
            // parallel axis: I + m (|d|² 1 − d dᵀ)
            i_total += link_inertia_world(l) + (Mat3::IDENTITY * d.length_squared() - outer(d, d)) * m;
        }
        let hand_inertia = (i_total.x_axis.x + i_total.y_axis.y + i_total.z_axis.z) / 3.0;
        if hand_mass + cfg.wrist.added_mass <= 0.0 || hand_inertia + cfg.wrist.added_inertia <= 0.0 {
            bail!(
                "{}: the hand has no mass or inertia and `wrist.added_mass` / `wrist.added_inertia` in {file} are 0: expected a positive wrist mass and inertia",
                hand.source.display()
            );
        }

        let r = &cfg.randomization;
        let restitution = r.object_restitution.unwrap_or([cfg.object.restitution; 2]);
        let wrist_rot = crate::geom::quat_from_rpy(cfg.wrist.init_rpy);
        let objects = crate::object::load::load_objects(cfg)?;
        let mut object_descs = Vec::with_capacity(objects.len());
        let mut pieces = Vec::new();
        let mut hulls = Vec::new();
        for o in &objects {
            let (d, p, h) = o.descs(pieces.len() as u32, hulls.len() as u32);
            object_descs.push(d);
            pieces.extend(p);
            hulls.extend(h);
        }
        let n_obj_pts = object_descs.iter().map(|d| d.n_support).max().unwrap_or(0);
        let globals = Globals {
            init_wrist_pos: [cfg.wrist.init_pos[0], cfg.wrist.init_pos[1], cfg.wrist.init_pos[2], 0.0],
            init_wrist_rot: wrist_rot.normalize().to_array(),
            obj_init: [cfg.object.init_xy[0], cfg.object.init_xy[1], cfg.object.init_yaw, object_descs[0].rest_height],
            rnd: [
                [r.hand_mass[0], r.hand_mass[1], r.hand_friction[0], r.hand_friction[1]],
                [r.joint_limits[0], r.joint_limits[1], r.joint_stiffness[0], r.joint_stiffness[1]],
                [r.joint_damping[0], r.joint_damping[1], r.object_mass[0], r.object_mass[1]],
                [r.object_friction[0], r.object_friction[1], r.object_scale[0], r.object_scale[1]],
                [restitution[0], restitution[1], r.table_friction[0], r.table_friction[1]],
                [r.added_gravity[0], r.added_gravity[1], cfg.object.xy_noise[0], cfg.object.xy_noise[1]],
            ],
            n_envs: cfg.sim.num_envs as u32,
            n_joints: joints.len() as u32,
            n_colliders: colliders.len() as u32,
            n_tips: tips.len() as u32,
            n_links: hand.links.len() as u32,
            n_objects: objects.len() as u32,
            n_obj_pts,
            substeps: cfg.sim.substeps,
            decimation: cfg.sim.decimation,
            seed: cfg.seed,
            hand_table: cfg.table.hand_collision as u32,
            n_springs: crate::gpu::layout::spring_slot::per_env(colliders.len() as u32, n_obj_pts),
            dt: cfg.sim.dt,
            gravity: 9.81,
            contact_k: cfg.contact.stiffness,
            contact_kt: cfg.contact.friction_stiffness,
            hand_eff_mass: cfg.contact.hand_effective_mass,
            hand_friction: cfg.hand.friction,
            n_ref_objects: 0,
            obj_friction: cfg.object.friction,
            table_friction: cfg.table.friction,
            yaw_noise: cfg.object.yaw_noise,
            hand_mass,
            hand_inertia,
            wrist_added_mass: cfg.wrist.added_mass,
            wrist_added_inertia: cfg.wrist.added_inertia,
            wrist_kp_lin: cfg.wrist.kp_lin,
            wrist_kd_lin: cfg.wrist.kd_lin,
            wrist_force_limit: cfg.wrist.force_limit,
            wrist_kp_rot: cfg.wrist.kp_rot,
            wrist_kd_rot: cfg.wrist.kd_rot,
            wrist_torque_limit: cfg.wrist.torque_limit,
            max_speed: cfg.sim.max_speed,
            max_distance: cfg.sim.max_distance,
            torsion_radius: cfg.contact.torsion_radius,
            hand_contact_k: cfg.contact.hand_stiffness,
            hand_contact_kt: cfg.contact.hand_friction_stiffness,
            env_offset: 0,
            _pad2: [0.0; 2],
        };
        let spec = EnvSpec {
            num_envs: cfg.sim.num_envs,
            joint_names: hand.joints.iter().map(|j| j.name.clone()).collect(),
            actuated: (0..hand.joints.len()).filter(|&j| hand.joints[j].mimic.is_none()).collect(),
            tip_names: hand.fingertips.iter().map(|t| t.name.clone()).collect(),
            dt: cfg.sim.dt,
            substeps: cfg.sim.substeps,
            decimation: cfg.sim.decimation,
        };
        Ok(SimModel { globals, joints, colliders, tips, objects, object_descs, pieces, hulls, ref_objects: Vec::new(), hand, spec })
    }

    /// The read-only model view used by the CPU physics.
    pub fn view(&self) -> physics::Model<'_> {
        physics::Model { g: &self.globals, joints: &self.joints, colliders: &self.colliders, tips: &self.tips, pieces: &self.pieces, objects: &self.object_descs, hulls: &self.hulls, ref_objects: &self.ref_objects }
    }

    /// The index of the object named `name` among the run's objects.
    pub fn object_index(&self, name: &str) -> Option<u32> {
        self.objects.iter().position(|o| o.name == name).map(|i| i as u32)
    }

    /// Makes each env hold the object of the reference it follows: `ref_objects[r]` is reference
    /// `r`'s object (`NO_OBJECT`: drawn uniformly); all `NO_OBJECT` (or none) keeps the uniform draw.
    pub fn set_reference_objects(&mut self, ref_objects: Vec<u32>) {
        let any = ref_objects.iter().any(|&o| o != NO_OBJECT);
        self.globals.n_ref_objects = if any { ref_objects.len() as u32 } else { 0 };
        self.ref_objects = if any { ref_objects } else { Vec::new() };
    }

    /// Targets that hold the initial wrist pose and default joint positions.
    pub fn default_targets(&self) -> Targets {
        let mut t = Targets { wrist_pos: self.globals.init_wrist_pos, wrist_rot: self.globals.init_wrist_rot, ..Default::default() };
        for (j, jd) in self.joints.iter().enumerate() {
            t.q[j] = jd.default_q;
        }
        t
    }
}

fn outer(a: Vec3, b: Vec3) -> Mat3 {
    Mat3::from_cols(a * b.x, a * b.y, a * b.z)
}

/// Makes the env batch the config asks for (`sim.backend`): `cpu`, `gpu`, `gpu:NAME` or `auto` (a
/// hardware GPU adapter if there is one, else the CPU; never a software adapter unless named).
pub fn make_env_batch(cfg: &Config, model: SimModel) -> Result<Box<dyn EnvBatch>> {
    match sim_gpu_context(cfg)? {
        Some(ctx) => Ok(Box::new(gpu::GpuEnvBatch::new(ctx, model)?)),
        None => Ok(Box::new(cpu::CpuEnvBatch::new(model))),
    }
}

/// The GPU the config's `sim.backend` asks for: `None` for `cpu`, the named or any hardware adapter
/// for `gpu`/`gpu:NAME` (an error if there is none), and for `auto` a hardware adapter if there is
/// one, else `None` (with a message saying why, once per process: [`GpuContext::auto`](crate::gpu::context::GpuContext::auto)).
pub fn sim_gpu_context(cfg: &Config) -> Result<Option<crate::gpu::context::GpuContext>> {
    match cfg.backend() {
        BackendChoice::Cpu => Ok(None),
        BackendChoice::Gpu(name) => Ok(Some(crate::gpu::context::GpuContext::new(name.as_deref())?)),
        BackendChoice::Auto => Ok(crate::gpu::context::GpuContext::auto()),
    }
}

/// World pose of every hand link of a state (HandModel link order).
pub fn hand_link_poses(model: &SimModel, st: &EnvState) -> Vec<crate::geom::Pose> {
    let mut s = physics::Scratch::default();
    physics::hand_kinematics(st, &model.view(), &mut s);
    (0..model.hand.links.len())
        .map(|l| crate::geom::Pose::new(s.link_pos[l], Quat::from_array(s.link_rot[l].to_array())))
        .collect()
}

/// Every contact of a state, with the force the next substep would apply under `targets` (for
/// recordings and kinematic replay): the CPU twin's contact pass itself
/// ([`physics::contacts_and_forces`], after the hand's kinematics and servos, then
/// [`physics::arriving_contacts`]), on copies of the state's springs: each force as its pair is
/// solved, without the part the object's motion changes in its implicit solve
/// ([`physics::react_to_object_motion`]). `springs` are the env's
/// `[n_springs]` contact springs.
pub fn contact_records(model: &SimModel, st: &EnvState, springs: &[[f32; 4]], p: &EnvParams, targets: &Targets) -> Vec<crate::record::ContactRecord> {
    use crate::record::ContactRecord;
    let m = model.view();
    let g = &model.globals;
    let mut s = physics::Scratch::default();
    let h = g.dt / g.substeps as f32;
    physics::hand_kinematics(st, &m, &mut s);
    physics::hand_servo(st, p, targets, &m, &mut s, h);
    let mut springs = springs.to_vec();
    let mut out = Vec::new();
    let mut record = |kind, index: usize, c: &physics::Contact, f| {
        out.push(ContactRecord { kind, index: index as u32, pos: c.point, normal: c.normal, depth: c.depth, force: f });
    };
    let predicted = physics::contacts_and_forces(st, &mut springs, p, &m, &mut s, h, &mut record);
    // and the contacts that the object's solved motion brings in (`physics::substep`)
    let (vel_n, w_n) = predicted.unwrap_or_else(|| physics::object_velocity_change(st, p, &m, &s, h));
    physics::arriving_contacts(st, p, &m, &mut s, h, vel_n, w_n, &mut record);
    out
}
