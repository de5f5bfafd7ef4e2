//! Shared helpers of the integration tests.
#![allow(dead_code)]

use dextrain::config::Config;
use dextrain::env::cpu::CpuEnvBatch;
use dextrain::env::gpu::GpuEnvBatch;
use dextrain::gpu::context::GpuContext;
use dextrain::env::{EnvBatch, SimModel};
use dextrain::env::physics::Model;
use dextrain::hand::{Collider, ColliderShape, Fingertip, HandModel, Joint, Link, MAX_JOINTS};
use dextrain::geom::Pose;
use glam::{Quat, Vec3};
use std::path::PathBuf;
use dextrain::task::ik::ik_apply_mimic;

/// The default config with the shipped hand, CPU backend, `n` envs, the wrist parked high above
/// the table.
pub fn base_config(n: usize) -> Config {
    let mut c = Config::default();
    c.base_dir = concat!(env!("CARGO_MANIFEST_DIR"), "/configs").into();
    c.source = "test.toml".into();
    c.sim.backend = "cpu".parse().unwrap();
    c.sim.num_envs = n;
    c.wrist.init_pos = [0.0, 0.0, 0.5];
    c
}

pub fn cpu_batch(c: &Config) -> CpuEnvBatch {
    CpuEnvBatch::new(SimModel::from_config(c).expect("model"))
}

/// A GPU context on any adapter (lavapipe included). Without one, prints why and returns None —
/// or fails when REQUIRE_GPU=1 (CI).
pub fn gpu_context(test: &str) -> Option<GpuContext> {
    let name = std::env::var("DEXTRAIN_TEST_ADAPTER").ok();
    let mut attempt = GpuContext::new(name.as_deref());
    if attempt.is_err() && name.is_none() {
        // no hardware adapter: take the software one
        attempt = GpuContext::new(Some("llvmpipe"));
    }
    match attempt {
        Ok(ctx) => Some(ctx),
        Err(e) => {
            if std::env::var("REQUIRE_GPU").map(|v| v == "1").unwrap_or(false) {
                panic!("{test}: REQUIRE_GPU=1 but no wgpu adapter: {e:#}");
            }
            eprintln!("{test}: SKIPPED, no wgpu adapter ({e:#}); install mesa-vulkan-drivers for lavapipe");
            None
        }
    }
}

/// How much looser than on lavapipe the CPU/GPU comparisons are on `ctx`'s adapter: 1 on a
/// software (CPU) adapter, 10 on a hardware GPU. lavapipe runs the shaders with LLVM on the CPU
/// and rounds as the CPU twins do (the tolerances are a few times what it measured), so in CI a
/// twin that drifts from its shader is caught tightly. A hardware driver computes sin, cos, exp
/// and sqrt with its own approximations (Vulkan allows sin and cos an absolute error of 2^-11)
/// and fuses a·b + c freely. Measured on an H100 (NVIDIA 580.159, 2026-11-25), against the
/// lavapipe tolerances: 3.1× at reset (a yaw quaternion's sin of a small angle: 6e-8 absolute),
/// 6.6× after the 100-step contact-free rollout, 1.3× in the reference kinds' observations, 4.3×
/// in the near-straight IK solves; a shader that computes another formula than its twin differs
/// by 1e-2 and more.
pub fn parity_slack(ctx: &GpuContext) -> f32 {
    if ctx.info.device_type == wgpu::DeviceType::Cpu { 1.0 } else { 10.0 }
}

pub fn gpu_batch(c: &Config, ctx: GpuContext) -> GpuEnvBatch {
    GpuEnvBatch::new(ctx, SimModel::from_config(c).expect("model")).expect("gpu batch")
}

/// Steps `b` `n` times with the same targets for every env.
pub fn run(b: &mut dyn EnvBatch, t: dextrain::env::Targets, n: usize) {
    let targets = vec![t; b.spec().num_envs];
    for _ in 0..n {
        b.step(&targets).expect("step");
    }
}

/// Parses and validates a WGSL source with naga (every validation flag), panicking with the
/// error; returns the module.
pub fn validate(src: &str) -> naga::Module {
    let module = naga::front::wgsl::parse_str(src).unwrap_or_else(|e| panic!("WGSL parse error:\n{}", e.emit_to_string(src)));
    naga::valid::Validator::new(naga::valid::ValidationFlags::all(), naga::valid::Capabilities::empty())
        .validate(&module)
        .unwrap_or_else(|e| panic!("WGSL validation error: {e:?}"));
    module
}

/// burn's wgpu learner device on the test adapter, with the context it runs on (keep it alive
/// beside the device); None as [`gpu_context`] when there is no adapter.
pub fn wgpu_learner(test: &str) -> Option<(GpuContext, burn::prelude::Device)> {
    let ctx = gpu_context(test)?;
    let choice = dextrain::config::BackendChoice::Gpu(Some(ctx.info.name.clone()));
    let (device, name) = dextrain::learn::device::learner_device(&choice, Some(&ctx)).expect("burn wgpu on the test adapter");
    assert!(name.starts_with("gpu (burn wgpu"), "{name}");
    Some((ctx, device))
}

/// Puts every env's object of `b` (a box: the run's first piece) against dexhand16's palm box
/// (collider 0), at rest, turned 30° about the palm's x axis so that one edge of it lies `depth`
/// inside the palm's −z face, `lateral(env)` m off the palm's centre along its y: the box's point
/// nearest the palm's centre is then on its top face, shallower than that edge. Returns, per env,
/// the midpoint of that edge (world), where the palm's contact should push.
pub fn box_turned_into_palm(b: &mut CpuEnvBatch, depth: f32, lateral: impl Fn(usize) -> f32) -> Vec<glam::Vec3> {
    box_tilted_against_palm(b, depth, 30.0, lateral)
}

/// `box_turned_into_palm`, turned `tilt_deg` instead of 30° (a small tilt: the box's top face lies
/// nearly flat against the palm's face).
pub fn box_tilted_against_palm(b: &mut CpuEnvBatch, depth: f32, tilt_deg: f32, lateral: impl Fn(usize) -> f32) -> Vec<glam::Vec3> {
    use dextrain::env::physics::object_support_point;
    use glam::{Quat, Vec3};
    let model = b.model().clone();
    let cd = model.colliders[0];
    let (piece, size, h) = object_box_and_palm(&model);
    assert!(piece.pos[..3].iter().all(|x| *x == 0.0) && piece.rot == [0.0, 0.0, 0.0, 1.0], "one box at the object's frame");
    let turn = Quat::from_rotation_x(tilt_deg.to_radians());
    // the turned box's corners in the palm frame, about its centre; the top ones along +z
    let corners: Vec<Vec3> = (0..8).map(|k| turn * object_support_point(piece.shape, size, k).0).collect();
    let top = corners.iter().map(|c| c.z).fold(f32::MIN, f32::max);
    let mut states = b.states().unwrap();
    let mut edges = Vec::new();
    for (i, st) in states.iter_mut().enumerate() {
        // the centre below the −z face (at −h_z) so that the top corners are `depth` past it
        let centre = Vec3::new(0.0, lateral(i), -h.z + depth - top);
        let edge: Vec3 = corners.iter().filter(|c| c.z > top - 1e-6).map(|c| *c + centre).sum::<Vec3>() / 2.0;
        let links = dextrain::env::hand_link_poses(&model, st);
        let palm = links[cd.link as usize].mul(&dextrain::geom::Pose::from_arrays(cd.pos, cd.rot));
        object_at_rest_in_palm_frame(st, &palm, centre, turn);
        edges.push(palm.transform_point(edge));
    }
    b.set_states(&states).unwrap();
    edges
}

/// Puts every env's object of `b` (a box: the run's first piece) 0.5 mm under dexhand16's palm box
/// (collider 0), tilted `tilt_deg` off flat about an axis in the palm's plane that turns 40° from
/// env to env (and turned 0.3 rad more about the palm's normal each env), its centre on a grid 6 mm
/// apart over the palm (8 per row), thrown at the palm at `speed` m/s: its highest corner or edge
/// strikes first, and the strike turns the cube so that the rest of its top face comes up within
/// the substep (`physics::arriving_contacts`).
pub fn cube_struck_at_the_palm(b: &mut CpuEnvBatch, tilt_deg: f32, speed: f32) {
    use dextrain::env::physics::object_support_point;
    let model = b.model().clone();
    let (piece, size, h) = object_box_and_palm(&model);
    let mut states = b.states().unwrap();
    for (i, st) in states.iter_mut().enumerate() {
        let axis = Vec3::new((0.7 * i as f32).cos(), (0.7 * i as f32).sin(), 0.0);
        let turn = Quat::from_axis_angle(axis, tilt_deg.to_radians()) * Quat::from_rotation_z(0.3 * i as f32);
        // the highest corner 0.5 mm below the palm's −z face
        let top = (0..8).map(|k| (turn * object_support_point(piece.shape, size, k).0).z).fold(f32::MIN, f32::max);
        let grid = Vec3::new(0.006 * ((i % 8) as f32 - 3.5), 0.006 * ((i / 8) as f32 - 3.5), 0.0);
        let palm = palm_pose(&model, st);
        object_at_rest_in_palm_frame(st, &palm, Vec3::new(0.0, 0.0, -h.z - 0.0005 - top) + grid, turn);
        let v = palm.rot * Vec3::Z * speed;
        st.obj_vel = [v.x, v.y, v.z, 0.0];
    }
    b.set_states(&states).unwrap();
}

/// The object's first piece (asserted a box), its half extents, and the half extents of dexhand16's
/// palm box (collider 0, asserted a box): what the palm scenes place.
fn object_box_and_palm(model: &SimModel) -> (dextrain::gpu::layout::PieceDesc, Vec3, Vec3) {
    let cd = model.colliders[0];
    assert_eq!(cd.shape, dextrain::gpu::layout::SHAPE_BOX, "collider 0 is the palm box");
    let piece = model.pieces[0];
    assert_eq!(piece.shape, dextrain::gpu::layout::SHAPE_BOX, "the object is a box");
    (piece, Vec3::from_slice(&piece.size[..3]), Vec3::from_slice(&cd.size[..3]))
}

/// Puts the object of `st` at rest with its frame at `centre`, turned `turn`, in the frame `palm`.
fn object_at_rest_in_palm_frame(st: &mut dextrain::env::EnvState, palm: &Pose, centre: Vec3, turn: Quat) {
    let pos = palm.transform_point(centre);
    st.obj_pos = [pos.x, pos.y, pos.z, 0.0];
    st.obj_rot = (palm.rot * turn).to_array();
    st.obj_vel = [0.0; 4];
    st.obj_angvel = [0.0; 4];
}

/// Puts every env's object of `b` (a box: the run's first piece) under dexhand16's palm box
/// (collider 0) as a learned lift pressed it (recorded 2026-11-29): turned ~30° about the palm's
/// normal and 3.6° off flat, its top face 1.8 mm into the palm along the palm's normal at its
/// highest corner, which lies 2.8 mm past the palm's rim: the palm's rim crosses the cube's top
/// edge, so the boxes overlap least along an edge–edge axis within a few degrees of the palm's
/// normal. Moved `sink(env)` m further into the palm along its normal and `lateral(env)` m along
/// the palm's y. Returns, per env, the boxes' overlap along the palm's normal (the highest
/// corner's depth past the palm's face, m).
pub fn cube_across_the_palm_rim(b: &mut CpuEnvBatch, sink: impl Fn(usize) -> f32, lateral: impl Fn(usize) -> f32) -> Vec<f32> {
    let recorded = (Vec3::new(0.869, -0.491, -0.056), Vec3::new(0.493, 0.870, 0.030), Vec3::new(-0.006_482, 0.014_656, 0.041_413));
    cube_under_the_palm_as_recorded(b, recorded, sink, lateral)
}

/// `cube_across_the_palm_rim` with another learned lift's press (recorded 2026-11-29): the palm
/// 21° off the cube's top face, its rim's edge 4.6 mm across the cube's top edge, the boxes
/// overlapping least along that edge pair (4.6 mm; 8.9 mm along the palm's normal).
pub fn cube_under_the_palm_s_edge(b: &mut CpuEnvBatch, sink: impl Fn(usize) -> f32, lateral: impl Fn(usize) -> f32) {
    let recorded = (Vec3::new(0.939_158, 0.212_628, -0.269_764), Vec3::new(-0.151_305, 0.961_158, 0.230_830), Vec3::new(-0.030_024, -0.019_237, 0.050_759));
    cube_under_the_palm_as_recorded(b, recorded, sink, lateral);
}

/// Puts every env's object of `b` (a box: the run's first piece) under dexhand16's palm box
/// (collider 0) where the palm's x and y axes and its centre in the cube's frame are `recorded`
/// (the axes orthonormalised), moved `sink(env)` m further into the palm along its normal and
/// `lateral(env)` m along its y. Returns, per env, the boxes' overlap along the palm's normal.
pub fn cube_under_the_palm_as_recorded(b: &mut CpuEnvBatch, recorded: (Vec3, Vec3, Vec3), sink: impl Fn(usize) -> f32, lateral: impl Fn(usize) -> f32) -> Vec<f32> {
    use dextrain::env::physics::object_support_point;
    use glam::Mat3;
    let model = b.model().clone();
    let (piece, size, h) = object_box_and_palm(&model);
    // the palm's axes and centre in the cube's frame, as recorded (the axes orthonormalised)
    let (x, y, c_o) = recorded;
    let x = x.normalize();
    let z = x.cross(y).normalize();
    let palm_in_cube = Mat3::from_cols(x, z.cross(x), z);
    // the cube in the palm's frame: rotation Rᵀ, centre −Rᵀ c_o
    let turn = Quat::from_mat3(&palm_in_cube.transpose());
    let centre0 = -(palm_in_cube.transpose() * c_o);
    let mut states = b.states().unwrap();
    let mut overlaps = Vec::new();
    for (i, st) in states.iter_mut().enumerate() {
        let centre = centre0 + Vec3::new(0.0, lateral(i), sink(i));
        let top = (0..8).map(|k| (turn * object_support_point(piece.shape, size, k).0 + centre).z).fold(f32::MIN, f32::max);
        overlaps.push(top + h.z);
        let palm = palm_pose(&model, st);
        object_at_rest_in_palm_frame(st, &palm, centre, turn);
    }
    b.set_states(&states).unwrap();
    overlaps
}

/// The direction from the object toward the palm box of `box_turned_into_palm`'s scene: the
/// palm's +z (its −z face looks at the object), in the world.
pub fn toward_palm(model: &dextrain::env::SimModel, st: &dextrain::env::EnvState) -> glam::Vec3 {
    palm_pose(model, st).rot * glam::Vec3::Z
}

/// The world pose of the palm box (collider 0) in state `st`.
pub fn palm_pose(model: &dextrain::env::SimModel, st: &dextrain::env::EnvState) -> dextrain::geom::Pose {
    let links = dextrain::env::hand_link_poses(model, st);
    let cd = model.colliders[0];
    links[cd.link as usize].mul(&dextrain::geom::Pose::from_arrays(cd.pos, cd.rot))
}

/// The joints a reset starts from: defaults clamped into the limits, followers from their leaders.
pub fn default_joints(m: &Model) -> [f32; MAX_JOINTS] {
    let mut q = [0.0; MAX_JOINTS];
    for j in 0..m.g.n_joints as usize {
        q[j] = m.joints[j].default_q.clamp(m.joints[j].lower, m.joints[j].upper);
    }
    ik_apply_mimic(m, &mut q);
    q
}

/// A link of 0.1 kg.
pub fn tiny_link(name: &str) -> Link {
    Link {
        name: name.to_string(),
        mass: 0.1,
        com: Vec3::ZERO,
        inertia: [[1e-5, 0.0, 0.0], [0.0, 1e-5, 0.0], [0.0, 0.0, 1e-5]],
    }
}

/// A palm (box) and one finger (capsule, fingertip at its end) on a revolute joint: the hand of
/// the recording and video tests.
pub fn tiny_hand() -> HandModel {
    HandModel {
        name: "tiny_hand".to_string(),
        source: PathBuf::from("tiny_hand.urdf"),
        links: vec![tiny_link("palm"), tiny_link("finger")],
        joints: vec![Joint {
            name: "finger_joint".to_string(),
            parent_link: 0,
            origin: Pose::new(Vec3::new(0.0, 0.0, 0.05), Quat::IDENTITY),
            axis: Vec3::X,
            lower: -1.0,
            upper: 1.5,
            effort: 1.0,
            velocity: 5.0,
            damping: 0.01,
            friction: 0.0,
            mimic: None,
            continuous: false,
        }],
        colliders: vec![
            Collider {
                link: 0,
                pose: Pose::IDENTITY,
                shape: ColliderShape::Box { half_extents: Vec3::new(0.04, 0.05, 0.01) },
            },
            Collider {
                link: 1,
                pose: Pose::new(Vec3::new(0.0, 0.0, 0.02), Quat::IDENTITY),
                shape: ColliderShape::Capsule { radius: 0.01, half_length: 0.02 },
            },
        ],
        fingertips: vec![Fingertip { name: "finger_tip".to_string(), link: 1, pos: Vec3::new(0.0, 0.0, 0.05) }],
        frames: Vec::new(),
        warnings: Vec::new(),
        mesh_fits: Vec::new(),
    }
}
