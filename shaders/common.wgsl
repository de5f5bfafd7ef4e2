// common.wgsl — structs, constants, quaternion maths and the counter-based hash RNG.
// CPU twins: src/env/layout.rs (structs, keep in sync field by field) and src/env/common.rs
// (functions, same names, same order, same arithmetic).
// Quaternions are vec4<f32> (x, y, z, w).

const MAX_JOINTS: u32 = 32u;
const MAX_LINKS: u32 = 33u;
const MAX_TIPS: u32 = 6u;
const MAX_PIECES: u32 = 32u;
const PROJ_ITERS: u32 = 4u;
const BOX_PROJ_ITERS: u32 = 16u;
const REVISIT_WORDS: u32 = 8u;

const SHAPE_SPHERE: u32 = 0u;
const SHAPE_BOX: u32 = 1u;
const SHAPE_CAPSULE: u32 = 2u;
const SHAPE_CYLINDER: u32 = 3u;
const SHAPE_HULL: u32 = 4u;
const NO_JOINT: u32 = 0xffffffffu;
const NO_OBJECT: u32 = 0xffffffffu;

struct Globals {
    init_wrist_pos: vec4<f32>,
    init_wrist_rot: vec4<f32>,
    obj_init: vec4<f32>,
    rnd: array<vec4<f32>, 6>,
    n_envs: u32,
    n_joints: u32,
    n_colliders: u32,
    n_tips: u32,
    n_links: u32,
    n_objects: u32,
    n_obj_pts: u32,
    substeps: u32,
    decimation: u32,
    seed: u32,
    hand_table: u32,
    n_springs: u32,
    dt: f32,
    gravity: f32,
    contact_k: f32,
    contact_kt: f32,
    hand_eff_mass: f32,
    hand_friction: f32,
    n_ref_objects: u32,
    obj_friction: f32,
    table_friction: f32,
    yaw_noise: f32,
    hand_mass: f32,
    hand_inertia: f32,
    wrist_added_mass: f32,
    wrist_added_inertia: f32,
    wrist_kp_lin: f32,
    wrist_kd_lin: f32,
    wrist_force_limit: f32,
    wrist_kp_rot: f32,
    wrist_kd_rot: f32,
    wrist_torque_limit: f32,
    max_speed: f32,
    max_distance: f32,
    torsion_radius: f32,
    hand_contact_k: f32,
    hand_contact_kt: f32,
    // global id of env 0 of this batch: the counter hash keys an env by env + env_offset
    env_offset: u32,
    _pad3: f32,
    _pad4: f32,
}

struct JointDesc {
    origin_pos: vec4<f32>,
    origin_rot: vec4<f32>,
    axis: vec4<f32>,
    parent_link: u32,
    mimic_leader: u32,
    mimic_mult: f32,
    mimic_offset: f32,
    lower: f32,
    upper: f32,
    effort: f32,
    velocity: f32,
    damping: f32,
    friction: f32,
    armature: f32,
    link_inertia: f32,
    kp: f32,
    kd: f32,
    default_q: f32,
    _pad: f32,
}

struct ColliderDesc {
    pos: vec4<f32>,
    rot: vec4<f32>,
    size: vec4<f32>,
    link: u32,
    shape: u32,
    tip: u32,
    _pad: u32,
}

struct TipDesc {
    pos: vec4<f32>,
    link: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

struct EnvState {
    wrist_pos: vec4<f32>,
    wrist_rot: vec4<f32>,
    wrist_vel: vec4<f32>,
    wrist_angvel: vec4<f32>,
    obj_pos: vec4<f32>,
    obj_rot: vec4<f32>,
    obj_vel: vec4<f32>,
    obj_angvel: vec4<f32>,
    q: array<f32, MAX_JOINTS>,
    qd: array<f32, MAX_JOINTS>,
    time: f32,
    episode: u32,
    step: u32,
    bad_resets: u32,
}

struct EnvParams {
    obj_com: vec4<f32>,
    obj_inertia: vec4<f32>,
    obj_friction: f32,
    restitution: f32,
    obj_scale: f32,
    table_friction: f32,
    hand_friction: f32,
    hand_mass_scale: f32,
    limit_scale: f32,
    kp_scale: f32,
    kd_scale: f32,
    added_gravity: f32,
    obj_contact_c: f32,
    hand_table_c: f32,
    obj_index: u32,
    obj_rest_height: f32,
    _pad0: u32,
    _pad1: u32,
    ext_force: vec4<f32>,
    ext_point: vec4<f32>,
}

// One collision piece of an object, in the object's frame, unscaled (twin: src/gpu/layout.rs PieceDesc).
struct PieceDesc {
    pos: vec4<f32>,
    rot: vec4<f32>,
    size: vec4<f32>,
    shape: u32,
    n_support: u32,
    hull_first: u32,
    hull_faces: u32,
}

// One object of the run, unscaled (twin: src/gpu/layout.rs ObjectDesc).
struct ObjectDesc {
    com: vec4<f32>,
    principal_rot: vec4<f32>,
    inertia: vec4<f32>,
    first_piece: u32,
    n_pieces: u32,
    n_support: u32,
    rest_height: f32,
}

struct Targets {
    wrist_pos: vec4<f32>,
    wrist_rot: vec4<f32>,
    q: array<f32, MAX_JOINTS>,
}

struct StepStats {
    tip_force: array<f32, 6>,
    max_pen_ho: f32,
    max_pen: f32,
    contacts: u32,
    contacts_ho: u32,
    bad_reset: u32,
    // bit l % 32 of word l / 32: hand link l pushed on the object in a substep of the step
    link_contact: array<u32, 2>,
    // 1 if a hand collider touches the table at the end of the step
    table_contact: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

// Hamilton product a ⊗ b.
fn quat_mul(a: vec4<f32>, b: vec4<f32>) -> vec4<f32> {
    return vec4<f32>(
        a.w * b.x + a.x * b.w + a.y * b.z - a.z * b.y,
        a.w * b.y - a.x * b.z + a.y * b.w + a.z * b.x,
        a.w * b.z + a.x * b.y - a.y * b.x + a.z * b.w,
        a.w * b.w - a.x * b.x - a.y * b.y - a.z * b.z,
    );
}

fn quat_conj(q: vec4<f32>) -> vec4<f32> {
    return vec4<f32>(-q.x, -q.y, -q.z, q.w);
}

// v + 2w(u×v) + 2u×(u×v)
fn quat_rotate(q: vec4<f32>, v: vec3<f32>) -> vec3<f32> {
    let u = q.xyz;
    let t = 2.0 * cross(u, v);
    return v + q.w * t + cross(u, t);
}

// the rotation matrix of q: its columns R·x̂, R·ŷ, R·ẑ (common.rs: quat_axes)
fn quat_axes(q: vec4<f32>) -> mat3x3<f32> {
    let x = q.x;
    let y = q.y;
    let z = q.z;
    let w = q.w;
    return mat3x3<f32>(
        vec3<f32>(1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y + z * w), 2.0 * (x * z - y * w)),
        vec3<f32>(2.0 * (x * y - z * w), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z + x * w)),
        vec3<f32>(2.0 * (x * z + y * w), 2.0 * (y * z - x * w), 1.0 - 2.0 * (x * x + y * y)),
    );
}

fn quat_normalize(q: vec4<f32>) -> vec4<f32> {
    return q / sqrt(dot(q, q));
}

fn quat_from_axis_angle(axis: vec3<f32>, angle: f32) -> vec4<f32> {
    let s = sin(0.5 * angle);
    return vec4<f32>(axis.x * s, axis.y * s, axis.z * s, cos(0.5 * angle));
}

// q' = exp(w h / 2) ⊗ q
fn quat_integrate(q: vec4<f32>, w: vec3<f32>, h: f32) -> vec4<f32> {
    let angle = length(w) * h;
    if (angle < 1e-9) {
        return q;
    }
    let dq = quat_from_axis_angle(w / length(w), angle);
    return quat_normalize(quat_mul(dq, q));
}

// log(goal ⊗ q⁻¹) as a rotation vector, shortest arc
fn quat_error(goal: vec4<f32>, q: vec4<f32>) -> vec3<f32> {
    var e = quat_mul(goal, quat_conj(q));
    if (e.w < 0.0) {
        e = -e;
    }
    let v = e.xyz;
    let s = length(v);
    if (s < 1e-9) {
        return 2.0 * v;
    }
    return v * (2.0 * atan2(s, e.w) / s);
}

fn pcg_hash(v: u32) -> u32 {
    let state = v * 747796405u + 2891336453u;
    let word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
    return (word >> 22u) ^ word;
}

fn rand_u32(seed: u32, env: u32, episode: u32, purpose: u32, k: u32) -> u32 {
    return pcg_hash(pcg_hash(pcg_hash(pcg_hash(pcg_hash(seed) ^ env) ^ episode) ^ purpose) ^ k);
}

fn rand_uniform(seed: u32, env: u32, episode: u32, purpose: u32, k: u32) -> f32 {
    return f32(rand_u32(seed, env, episode, purpose, k) >> 8u) * (1.0 / 16777216.0);
}

// ---- resources (bound by src/env/gpu.rs and src/task/gpu.rs; each pipeline uses the subset it needs) ----
@group(0) @binding(0) var<uniform> g: Globals;
@group(0) @binding(1) var<storage, read> joints: array<JointDesc>;
@group(0) @binding(2) var<storage, read> colliders: array<ColliderDesc>;
// binding 3 (fingertip frames, `TipDesc`): used by the task layer
@group(0) @binding(3) var<storage, read> tips: array<TipDesc>;
@group(0) @binding(4) var<storage, read_write> states: array<EnvState>;
@group(0) @binding(5) var<storage, read_write> params: array<EnvParams>;
// written by the task layer's task_act
@group(0) @binding(6) var<storage, read_write> targets: array<Targets>;
@group(0) @binding(7) var<storage, read_write> stats: array<StepStats>;
// reset request per env: 0 none, 1 next episode, 2 episode 0 (written by the task layer's task_reward)
@group(0) @binding(8) var<storage, read_write> reset_mask: array<u32>;
// contact springs [N, g.n_springs]: tangential spring (xyz, world), w = 1 while in contact; env e's
// slots from e * g.n_springs: hand collider c vs object at c, vs table at n_colliders + c, object
// support point k vs table at 2 n_colliders + k (twin: src/gpu/layout.rs spring_slot)
@group(0) @binding(16) var<storage, read_write> springs: array<vec4<f32>>;
// the objects' collision pieces and the objects (twin: SimModel::pieces, SimModel::objects)
@group(0) @binding(18) var<storage, read> pieces: array<PieceDesc>;
@group(0) @binding(19) var<storage, read> objects: array<ObjectDesc>;
// the convex-hull pieces' data: per hull F planes (n, d), F triangles (vertex indices as floats),
// then its vertices (twin: SimModel::hulls)
@group(0) @binding(20) var<storage, read> hulls: array<vec4<f32>>;
// the object of each reference (NO_OBJECT: uniform), [g.n_ref_objects] (twin: SimModel::ref_objects)
@group(0) @binding(21) var<storage, read> ref_objects: array<u32>;
const WORKGROUP_SIZE: u32 = 64u;

// Env index of an invocation of a (possibly 2-D) dispatch.
fn env_index(gid: vec3<u32>, nwg: vec3<u32>) -> u32 {
    return gid.x + gid.y * nwg.x * WORKGROUP_SIZE;
}
