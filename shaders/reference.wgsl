// reference.wgsl — the reference layer of the trajectory-following and residual tasks: a per-env
// cursor into the bank of reference frames, with an augmentation drawn at reset, and sampling of the
// augmented reference at the current and look-ahead env steps. Plain functions, no entry points.
// Appended after common.wgsl + reset.wgsl + physics.wgsl (uses g, joints and the quaternion maths).
// CPU twin: src/task/reference.rs (same function names, same order, same arithmetic; the contract and
// the augmentations are described at its top); the bank's record layout: src/task/bank.rs.

const PURPOSE_REF: u32 = 4u;
const REF_KEY_ID: u32 = 0u;
const REF_KEY_SPEED: u32 = 1u;
const REF_KEY_MIRROR: u32 = 2u;
const REF_KEY_TRANSLATE: u32 = 3u;
const REF_KEY_ROTATE: u32 = 5u;
const REF_KEY_WRIST_POS: u32 = 6u;
const REF_KEY_WRIST_ROT: u32 = 9u;
const REF_KEY_JOINT: u32 = 16u;
const REF_KEY_NOISE: u32 = 64u;
const REF_KEY_STRIDE: u32 = 128u;

const CUR_WRIST: u32 = 1u;
const CUR_JOINT: u32 = 2u;
const CUR_MIRROR: u32 = 4u;
const CUR_TRANSFORM: u32 = 8u;
const CUR_REINTERP: u32 = 16u;

const REF_HAS_OBJECT: u32 = 1u;
const REF_TIPS_FROM_FILE: u32 = 2u;

// one reference of the bank (twin: reference.rs RefInfo)
struct RefInfo {
    obj0_pos: vec4<f32>,
    obj0_rot: vec4<f32>,
    bbox_min: vec4<f32>,
    bbox_max: vec4<f32>,
    first_frame: u32,
    n_frames: u32,
    first_segment_steps: u32,
    flags: u32,
}

// bank sizes, record offsets, augmentation settings (twin: reference.rs RefGlobals; a uniform)
struct RefGlobals {
    n_refs: u32,
    stride: u32,
    n_joints: u32,
    n_tips: u32,
    off_wrist_pos: u32,
    off_wrist_rot: u32,
    off_q: u32,
    off_tips: u32,
    off_obj_pos: u32,
    off_obj_rot: u32,
    off_grasp: u32,
    reground: u32,
    reinterp: u32,
    reinterp_steps: u32,
    _pad0: u32,
    _pad1: u32,
    translate_xy: f32,
    rotate_z: f32,
    mirror_prob: f32,
    time_scale: f32,
    wrist_pos_offset: f32,
    wrist_rot_offset: f32,
    joint_offset: f32,
    wrist_pos_noise: f32,
    joint_noise: f32,
    _pad2: f32,
    _pad3: f32,
    _pad4: f32,
}

// one env's episode on a reference (twin: reference.rs RefCursor)
struct RefCursor {
    d_pos: vec4<f32>,
    d_rot: vec4<f32>,
    start_pos: vec4<f32>,
    start_rot: vec4<f32>,
    wrist_off_pos: vec4<f32>,
    wrist_off_rot: vec4<f32>,
    ref_id: u32,
    env: u32,
    episode: u32,
    flags: u32,
    speed: f32,
    seg_steps: u32,
    _pad0: u32,
    _pad1: u32,
}

// the augmented reference at one env step, world frame (twin: reference.rs RefFrame)
struct RefFrame {
    wrist_pos: vec4<f32>,
    wrist_rot: vec4<f32>,
    obj_pos: vec4<f32>,
    obj_rot: vec4<f32>,
    tips: array<vec4<f32>, 6>,
    q: array<f32, MAX_JOINTS>,
    grasp: f32,
    ended: u32,
    _pad0: u32,
    _pad1: u32,
}

struct RefPose {
    pos: vec3<f32>,
    rot: vec4<f32>,
}

// frame records [Σ n_frames, stride] (src/task/bank.rs)
@group(0) @binding(13) var<storage, read> ref_frames: array<f32>;
@group(0) @binding(14) var<storage, read> ref_info: array<RefInfo>;
@group(0) @binding(15) var<uniform> rg: RefGlobals;

fn ref_record(info: RefInfo, i: u32) -> u32 {
    return (info.first_frame + i) * rg.stride;
}

fn ref_vec3(b: u32) -> vec3<f32> {
    return vec3<f32>(ref_frames[b], ref_frames[b + 1u], ref_frames[b + 2u]);
}

fn ref_vec4(b: u32) -> vec4<f32> {
    return vec4<f32>(ref_frames[b], ref_frames[b + 1u], ref_frames[b + 2u], ref_frames[b + 3u]);
}

// the record at b, exactly as stored (ended = 0)
fn ref_read(b: u32) -> RefFrame {
    var f: RefFrame;
    f.wrist_pos = vec4<f32>(ref_vec3(b + rg.off_wrist_pos), 0.0);
    f.wrist_rot = ref_vec4(b + rg.off_wrist_rot);
    for (var j = 0u; j < rg.n_joints; j++) {
        f.q[j] = ref_frames[b + rg.off_q + j];
    }
    for (var t = 0u; t < rg.n_tips; t++) {
        f.tips[t] = vec4<f32>(ref_vec3(b + rg.off_tips + 3u * t), 0.0);
    }
    f.obj_pos = vec4<f32>(ref_vec3(b + rg.off_obj_pos), 0.0);
    f.obj_rot = ref_vec4(b + rg.off_obj_rot);
    f.grasp = ref_frames[b + rg.off_grasp];
    return f;
}

// (x, y, z, w) → (−x, y, −z, w): reflection across the x–z plane
fn ref_mirror_quat(q: vec4<f32>) -> vec4<f32> {
    return vec4<f32>(-q.x, q.y, -q.z, q.w);
}

// shortest-arc slerp from a (exactly a at s ≤ 0), normalised; nlerp when the two are close
fn ref_slerp(a: vec4<f32>, b: vec4<f32>, s: f32) -> vec4<f32> {
    if (s <= 0.0) {
        return a;
    }
    var bb = b;
    var d = dot(a, b);
    if (d < 0.0) {
        bb = -b;
        d = -d;
    }
    if (d > 0.9995) {
        return quat_normalize(a + (bb - a) * s);
    }
    let th = acos(d);
    let sn = sin(th);
    // (sin((1 − s)θ) a + sin(sθ) b) / sin θ
    return quat_normalize(a * (sin((1.0 - s) * th) / sn) + bb * (sin(s * th) / sn));
}

// frames a and b at s ∈ (0, 1): linear, slerp for rotations, the grasp flag of the nearer frame
fn ref_lerp(a: RefFrame, b: RefFrame, s: f32) -> RefFrame {
    var f: RefFrame;
    f.wrist_pos = vec4<f32>(a.wrist_pos.xyz + (b.wrist_pos.xyz - a.wrist_pos.xyz) * s, 0.0);
    f.wrist_rot = ref_slerp(a.wrist_rot, b.wrist_rot, s);
    for (var j = 0u; j < rg.n_joints; j++) {
        f.q[j] = a.q[j] + (b.q[j] - a.q[j]) * s;
    }
    for (var t = 0u; t < rg.n_tips; t++) {
        f.tips[t] = vec4<f32>(a.tips[t].xyz + (b.tips[t].xyz - a.tips[t].xyz) * s, 0.0);
    }
    f.obj_pos = vec4<f32>(a.obj_pos.xyz + (b.obj_pos.xyz - a.obj_pos.xyz) * s, 0.0);
    f.obj_rot = ref_slerp(a.obj_rot, b.obj_rot, s);
    f.grasp = select(b.grasp, a.grasp, s < 0.5);
    return f;
}

// uniform in [−1, 1) for key k of (env, episode)
fn ref_signed(env: u32, episode: u32, k: u32) -> f32 {
    return 2.0 * rand_uniform(g.seed, env + g.env_offset, episode, PURPOSE_REF, k) - 1.0; // keyed by the global env id
}

// standard normal for noise component comp at env step n (Box–Muller, u1 ∈ (0, 1])
fn ref_gauss(c: RefCursor, n: u32, comp: u32) -> f32 {
    let key = REF_KEY_NOISE + n * REF_KEY_STRIDE + 2u * comp;
    let u1 = 1.0 - rand_uniform(g.seed, c.env + g.env_offset, c.episode, PURPOSE_REF, key);
    let u2 = rand_uniform(g.seed, c.env + g.env_offset, c.episode, PURPOSE_REF, key + 1u);
    return sqrt(-2.0 * log(u1)) * cos(6.2831855 * u2);
}

// the un-augmented reference at env step n: frame x = n · speed (the record itself when integral),
// the last frame held (ended = 1) from x ≥ last on
fn ref_raw(c: RefCursor, n: u32) -> RefFrame {
    let info = ref_info[c.ref_id];
    let last = info.n_frames - 1u;
    let x = f32(n) * c.speed;
    // one record read for the end and one place that reads (a shader inlines every call: fewer
    // copies of ref_read compile much faster on LLVM drivers such as lavapipe)
    let ended = x >= f32(last);
    var i0 = last;
    var s = 0.0;
    if (!ended) {
        i0 = u32(floor(x));
        s = x - f32(i0);
    }
    var f = ref_read(ref_record(info, i0));
    if (s != 0.0) {
        f = ref_lerp(f, ref_read(ref_record(info, i0 + 1u)), s);
    }
    f.ended = select(0u, 1u, ended);
    return f;
}

// offset + noise of joint j at env step n; a mimic follower gets mult × its leader's
fn ref_joint_delta(c: RefCursor, n: u32, j: u32) -> f32 {
    let jd = joints[j];
    var jj = j;
    var m = 1.0;
    if (jd.mimic_leader != NO_JOINT) {
        jj = jd.mimic_leader;
        m = jd.mimic_mult;
    }
    var d = 0.0;
    if (rg.joint_offset > 0.0) {
        d += rg.joint_offset * ref_signed(c.env, c.episode, REF_KEY_JOINT + jj);
    }
    if (rg.joint_noise > 0.0) {
        d += rg.joint_noise * ref_gauss(c, n, 3u + jj);
    }
    return m * d;
}

// retargeting-error emulation on the hand parts; the object is untouched
fn ref_perturb(c: RefCursor, f: RefFrame, n: u32) -> RefFrame {
    var o = f;
    if ((c.flags & CUR_WRIST) != 0u) {
        var off = c.wrist_off_pos.xyz;
        if (rg.wrist_pos_noise > 0.0) {
            off += rg.wrist_pos_noise * vec3<f32>(ref_gauss(c, n, 0u), ref_gauss(c, n, 1u), ref_gauss(c, n, 2u));
        }
        let rv = c.wrist_off_rot.xyz;
        let ang = length(rv);
        var qo = vec4<f32>(0.0, 0.0, 0.0, 1.0);
        if (ang > 0.0) {
            qo = quat_from_axis_angle(rv / ang, ang);
        }
        let w = f.wrist_pos.xyz;
        for (var t = 0u; t < rg.n_tips; t++) {
            // p' = w + Δ + Q (p − w)
            o.tips[t] = vec4<f32>(w + off + quat_rotate(qo, f.tips[t].xyz - w), 0.0);
        }
        o.wrist_pos = vec4<f32>(w + off, 0.0);
        o.wrist_rot = quat_normalize(quat_mul(qo, f.wrist_rot));
    }
    if ((c.flags & CUR_JOINT) != 0u) {
        for (var j = 0u; j < rg.n_joints; j++) {
            o.q[j] = f.q[j] + ref_joint_delta(c, n, j);
        }
    }
    return o;
}

// reflection across the vertical x–z plane through the reference's first object position y0
fn ref_mirror(c: RefCursor, f: RefFrame) -> RefFrame {
    let y0 = ref_info[c.ref_id].obj0_pos.y;
    var o = f;
    // p.y → 2·y0 − p.y
    o.wrist_pos.y = 2.0 * y0 - f.wrist_pos.y;
    o.wrist_rot = ref_mirror_quat(f.wrist_rot);
    for (var t = 0u; t < rg.n_tips; t++) {
        o.tips[t].y = 2.0 * y0 - f.tips[t].y;
    }
    o.obj_pos.y = 2.0 * y0 - f.obj_pos.y;
    o.obj_rot = ref_mirror_quat(f.obj_rot);
    return o;
}

// D on every pose and point: p' = R_D p + t_D, q' = q_D ⊗ q
fn ref_transform(c: RefCursor, f: RefFrame) -> RefFrame {
    let dr = c.d_rot;
    let dp = c.d_pos.xyz;
    var o = f;
    o.wrist_pos = vec4<f32>(quat_rotate(dr, f.wrist_pos.xyz) + dp, 0.0);
    o.wrist_rot = quat_normalize(quat_mul(dr, f.wrist_rot));
    for (var t = 0u; t < rg.n_tips; t++) {
        o.tips[t] = vec4<f32>(quat_rotate(dr, f.tips[t].xyz) + dp, 0.0);
    }
    o.obj_pos = vec4<f32>(quat_rotate(dr, f.obj_pos.xyz) + dp, 0.0);
    o.obj_rot = quat_normalize(quat_mul(dr, f.obj_rot));
    return o;
}

// raw → perturb → mirror → D (each skipped when off), without the re-interpolation
fn ref_augmented(c: RefCursor, n: u32) -> RefFrame {
    var f = ref_raw(c, n);
    if ((c.flags & (CUR_WRIST | CUR_JOINT)) != 0u) {
        f = ref_perturb(c, f, n);
    }
    if ((c.flags & CUR_MIRROR) != 0u) {
        f = ref_mirror(c, f);
    }
    if ((c.flags & CUR_TRANSFORM) != 0u) {
        f = ref_transform(c, f);
    }
    return f;
}

// draws episode `episode` of env `env`'s reference and augmentation, for its state s right after the reset
fn ref_begin(env: u32, episode: u32, s: EnvState) -> RefCursor {
    var c: RefCursor;
    c.env = env;
    c.episode = episode;
    let u = rand_uniform(g.seed, env + g.env_offset, episode, PURPOSE_REF, REF_KEY_ID);
    c.ref_id = min(u32(u * f32(rg.n_refs)), rg.n_refs - 1u);
    let info = ref_info[c.ref_id];
    c.speed = 1.0;
    if (rg.time_scale > 0.0) {
        c.speed = 1.0 + rg.time_scale * ref_signed(env, episode, REF_KEY_SPEED);
    }
    if (rg.mirror_prob > 0.0 && rand_uniform(g.seed, env + g.env_offset, episode, PURPOSE_REF, REF_KEY_MIRROR) < rg.mirror_prob) {
        c.flags |= CUR_MIRROR;
    }
    if (rg.wrist_pos_offset > 0.0) {
        let h = rg.wrist_pos_offset;
        let k = REF_KEY_WRIST_POS;
        c.wrist_off_pos = vec4<f32>(h * ref_signed(env, episode, k), h * ref_signed(env, episode, k + 1u), h * ref_signed(env, episode, k + 2u), 0.0);
    }
    if (rg.wrist_rot_offset > 0.0) {
        let h = rg.wrist_rot_offset;
        let k = REF_KEY_WRIST_ROT;
        c.wrist_off_rot = vec4<f32>(h * ref_signed(env, episode, k), h * ref_signed(env, episode, k + 1u), h * ref_signed(env, episode, k + 2u), 0.0);
    }
    if (rg.wrist_pos_offset > 0.0 || rg.wrist_rot_offset > 0.0 || rg.wrist_pos_noise > 0.0) {
        c.flags |= CUR_WRIST;
    }
    if (rg.joint_offset > 0.0 || rg.joint_noise > 0.0) {
        c.flags |= CUR_JOINT;
    }
    // the reference's first object pose after the mirror (which keeps its position)
    let p0 = info.obj0_pos.xyz;
    var r0 = info.obj0_rot;
    if ((c.flags & CUR_MIRROR) != 0u) {
        r0 = ref_mirror_quat(r0);
    }
    c.d_rot = vec4<f32>(0.0, 0.0, 0.0, 1.0);
    if (rg.reground != 0u) {
        // D = T_env · T_ref(0)⁻¹: q_D = q_env ⊗ q_ref⁻¹, t_D = p_env − R_D p_ref
        let dr = quat_normalize(quat_mul(s.obj_rot, quat_conj(r0)));
        c.d_rot = dr;
        c.d_pos = vec4<f32>(s.obj_pos.xyz - quat_rotate(dr, p0), 0.0);
        c.flags |= CUR_TRANSFORM;
    } else if (rg.translate_xy > 0.0 || rg.rotate_z > 0.0) {
        var th = 0.0;
        if (rg.rotate_z > 0.0) {
            th = rg.rotate_z * ref_signed(env, episode, REF_KEY_ROTATE);
        }
        var t = vec3<f32>(0.0);
        if (rg.translate_xy > 0.0) {
            let h = rg.translate_xy;
            t = vec3<f32>(h * ref_signed(env, episode, REF_KEY_TRANSLATE), h * ref_signed(env, episode, REF_KEY_TRANSLATE + 1u), 0.0);
        }
        let dr = quat_from_axis_angle(vec3<f32>(0.0, 0.0, 1.0), th);
        // rotation about the vertical axis through (x0, y0), then the shift: t_D = c + t − R_D c
        let cxy = vec3<f32>(p0.x, p0.y, 0.0);
        c.d_rot = dr;
        c.d_pos = vec4<f32>(cxy + t - quat_rotate(dr, cxy), 0.0);
        c.flags |= CUR_TRANSFORM;
    }
    c.start_pos = s.wrist_pos;
    c.start_rot = s.wrist_rot;
    if (rg.reinterp != 0u) {
        c.flags |= CUR_REINTERP;
        if (rg.reinterp_steps > 0u) {
            c.seg_steps = rg.reinterp_steps;
        } else {
            // round(first segment / speed), at least 1
            c.seg_steps = max(u32(floor(f32(info.first_segment_steps) / c.speed + 0.5)), 1u);
        }
    }
    return c;
}

// the augmented reference at env step step + k
fn ref_sample(c: RefCursor, step: u32, k: u32) -> RefFrame {
    let n = step + k;
    var f = ref_augmented(c, n);
    if ((c.flags & CUR_REINTERP) != 0u && n < c.seg_steps) {
        let e = ref_augmented(c, c.seg_steps);
        let a = f32(n) / f32(c.seg_steps);
        let sp = c.start_pos.xyz;
        // p = p_start + (p_end − p_start)·α, q = slerp(q_start, q_end, α)
        let wp = sp + (e.wrist_pos.xyz - sp) * a;
        let wr = ref_slerp(c.start_rot, e.wrist_rot, a);
        // fingertips carried with the wrist: p' = w' + (q' ⊗ q⁻¹)(p − w)
        let rel = quat_mul(wr, quat_conj(f.wrist_rot));
        let w = f.wrist_pos.xyz;
        for (var t = 0u; t < rg.n_tips; t++) {
            f.tips[t] = vec4<f32>(wp + quat_rotate(rel, f.tips[t].xyz - w), 0.0);
        }
        f.wrist_pos = vec4<f32>(wp, 0.0);
        f.wrist_rot = wr;
    }
    return f;
}

// an object pose of the reference's records (p, q) carried through the episode's augmentation: D ·
// mirror(p, q) (the reference's hand perturbation and re-interpolation leave the object alone)
fn ref_object_augmented(c: RefCursor, pos: vec3<f32>, rot: vec4<f32>) -> RefPose {
    var p = pos;
    var q = rot;
    if ((c.flags & CUR_MIRROR) != 0u) {
        // p.y → 2·y0 − p.y, as ref_mirror does it
        p.y = 2.0 * ref_info[c.ref_id].obj0_pos.y - p.y;
        q = ref_mirror_quat(q);
    }
    if ((c.flags & CUR_TRANSFORM) != 0u) {
        let dr = c.d_rot;
        p = quat_rotate(dr, p) + c.d_pos.xyz;
        q = quat_normalize(quat_mul(dr, q));
    }
    return RefPose(p, q);
}

// the object's first pose in the episode's augmented reference: D · mirror(T_obj,ref(0))
fn ref_object_start(c: RefCursor) -> RefPose {
    let info = ref_info[c.ref_id];
    return ref_object_augmented(c, info.obj0_pos.xyz, info.obj0_rot);
}

// the object's final pose in the episode's augmented reference: the object that
// ref_sample gives from the last frame on (the last record's), without building the whole frame
fn ref_object_end(c: RefCursor) -> RefPose {
    let info = ref_info[c.ref_id];
    let b = ref_record(info, info.n_frames - 1u);
    return ref_object_augmented(c, ref_vec3(b + rg.off_obj_pos), ref_vec4(b + rg.off_obj_rot));
}
