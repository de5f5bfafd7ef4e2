// physics.wgsl — one env step of one env per invocation (decimation × substeps).
// CPU twin: src/env/physics.rs (same function names, same order, same arithmetic; its `Scratch` is
// the var<private> memory below). The model is described at the top of the twin.

// ---- per-invocation working memory (the twin's Scratch, EnvState, EnvParams, Targets) ----
var<private> st: EnvState;
var<private> prm: EnvParams;
var<private> tg: Targets;
var<private> link_pos: array<vec3<f32>, MAX_LINKS>;
var<private> link_rot: array<vec4<f32>, MAX_LINKS>;
var<private> link_v: array<vec3<f32>, MAX_LINKS>;
var<private> link_w: array<vec3<f32>, MAX_LINKS>;
// each joint this substep: its axis in the world (hand_kinematics) and the change of its velocity
// (independent joints only; physics.rs: Scratch::dqd): the servos' part first, then each hand
// contact's as it is solved. One array of both, not two: a GPU compiler keeps a private array of
// at most 256 bytes in registers (RADV's does, expanding each dynamic index into it), and 32
// joints' dqd alone is 128 bytes; one array of 512 bytes goes to scratch memory, and the physics
// step is ~8 % fewer instructions on RADV's compiler (BENCHMARKS.md "What a GPU's compiler makes
// of the physics kernel")
struct JointNow {
    axis: vec3<f32>,
    dqd: f32,
}
var<private> joint_now: array<JointNow, MAX_JOINTS>;
var<private> wrist_dv: vec3<f32>;
var<private> wrist_dw: vec3<f32>;
var<private> obj_f: vec3<f32>;
var<private> obj_t: vec3<f32>;
var<private> obj_d: array<f32, 36>;
var<private> tip_force: array<f32, 6>;
var<private> max_pen_ho: f32;
var<private> max_pen: f32;
var<private> n_contacts: u32;
var<private> n_contacts_ho: u32;
var<private> link_contact: array<u32, 2>;
// physics.rs: MAX_REACTIONS. Hand–object pairs per substep whose force on the hand follows the
// object's motion in its implicit solve
const MAX_REACTIONS: u32 = 16u;
// the hand–object pairs that pushed this substep (physics.rs: Scratch::reactions, Reaction):
// the link, the collider, (the point, the depth of the contact solved), (normal, a), (δv₀, b),
// (δω₀, b_r), (the manifold's spread diagonal, its spring count), the spread's (xy, xz, yz).
// One array of structs (1.7 kB, in scratch memory), not an array per field: RADV's compiler kept
// each field's array of ≤ 256 bytes in registers and expanded every dynamic index into it, which
// made the physics step 1.8× its size there (71.5 k instructions against 40.3 k, spilled VGPRs
// 15.5 k against 4.6 k; BENCHMARKS.md "What a GPU's compiler makes of the physics kernel")
struct Reaction {
    link: u32,
    collider: u32,
    point: vec4<f32>,
    normal: vec4<f32>,
    dv0: vec4<f32>,
    dw0: vec4<f32>,
    spread_d: vec4<f32>,
    spread_o: vec3<f32>,
}
var<private> reactions: array<Reaction, MAX_REACTIONS>;
var<private> n_reactions: u32;
// index of this env's first contact spring in `springs`
var<private> spring_base: u32;

// physics.rs: Contact. spring_count: how many point springs it stands for (1 at one point);
// spread_diag, spread_off: the manifold's spread about the point (zero at one point)
struct Contact {
    depth: f32,
    normal: vec3<f32>,
    point: vec3<f32>,
    spring_count: f32,
    spread_diag: vec3<f32>,
    spread_off: vec3<f32>,
}

// a contact at one point (physics.rs: Contact::at)
fn contact_at(depth: f32, normal: vec3<f32>, point: vec3<f32>) -> Contact {
    return Contact(depth, normal, point, 1.0, vec3<f32>(0.0), vec3<f32>(0.0));
}

struct ContactForce {
    force: vec3<f32>,
    spring: vec3<f32>,
    tdamp: f32,
}

// hand_contact_force's result: the force, the spring, and the object's normal and tangential damping
struct HandContactForce {
    force: vec3<f32>,
    spring: vec3<f32>,
    ndamp: f32,
    tdamp: f32,
}

struct SupportPoint {
    pos: vec3<f32>,
    radius: f32,
}

struct Projection {
    point: vec3<f32>,
    inside: bool,
}

struct InsideNormal {
    normal: vec3<f32>,
    dist: f32,
}

struct ColliderPose {
    pos: vec3<f32>,
    rot: vec4<f32>,
}

fn sgn(x: f32) -> f32 {
    if (x < 0.0) {
        return -1.0;
    }
    return 1.0;
}

fn clamp_norm(v: vec3<f32>, max_len: f32) -> vec3<f32> {
    let l = length(v);
    if (l > max_len) {
        return v * (max_len / l);
    }
    return v;
}

fn hand_kinematics() {
    link_pos[0] = st.wrist_pos.xyz;
    link_rot[0] = st.wrist_rot;
    link_v[0] = st.wrist_vel.xyz;
    link_w[0] = st.wrist_angvel.xyz;
    for (var j = 0u; j < g.n_joints; j++) {
        let jd = joints[j];
        let p = jd.parent_link;
        // most URDF joint frames are not turned from their parent's: the product with the
        // identity is the parent's rotation (to the bit, but for the sign of a zero)
        var frame_rot = link_rot[p];
        if (any(jd.origin_rot != vec4<f32>(0.0, 0.0, 0.0, 1.0))) {
            frame_rot = quat_mul(link_rot[p], jd.origin_rot);
        }
        let o = link_pos[p] + quat_rotate(link_rot[p], jd.origin_pos.xyz);
        let axis = quat_rotate(frame_rot, jd.axis.xyz);
        joint_now[j].axis = axis;
        link_pos[j + 1u] = o;
        link_rot[j + 1u] = quat_mul_axis_angle(frame_rot, jd.axis.xyz, st.q[j]);
        // ω_child = ω_parent + a q̇;  v_child = v_parent + ω_parent × (o − p_parent)
        link_w[j + 1u] = link_w[p] + axis * st.qd[j];
        link_v[j + 1u] = link_v[p] + cross(link_w[p], o - link_pos[p]);
    }
}

// physics.rs: quat_mul_axis_angle. quat_mul(a, quat_from_axis_angle(axis, angle)); for an axis
// along ±x, ±y or ±z of its frame (most URDF joints), the terms its zeros make zero left out
fn quat_mul_axis_angle(a: vec4<f32>, axis: vec3<f32>, angle: f32) -> vec4<f32> {
    let sn = sin(0.5 * angle);
    let c = cos(0.5 * angle);
    // b = (axis·sin(θ/2), cos(θ/2)); quat_mul's rows with b's zero entries dropped, the others
    // summed in its order
    if (axis.y == 0.0 && axis.z == 0.0 && abs(axis.x) == 1.0) {
        let bx = axis.x * sn;
        return vec4<f32>(a.w * bx + a.x * c, a.y * c + a.z * bx, -(a.y * bx) + a.z * c, a.w * c - a.x * bx);
    }
    if (axis.x == 0.0 && axis.z == 0.0 && abs(axis.y) == 1.0) {
        let by = axis.y * sn;
        return vec4<f32>(a.x * c - a.z * by, a.w * by + a.y * c, a.x * by + a.z * c, a.w * c - a.y * by);
    }
    if (axis.x == 0.0 && axis.y == 0.0 && abs(axis.z) == 1.0) {
        let bz = axis.z * sn;
        return vec4<f32>(a.x * c + a.y * bz, -(a.x * bz) + a.y * c, a.w * bz + a.z * c, a.w * c - a.z * bz);
    }
    return quat_mul(a, vec4<f32>(axis * sn, c));
}

fn link_point_velocity(l: u32, x: vec3<f32>) -> vec3<f32> {
    return link_v[l] + cross(link_w[l], x - link_pos[l]);
}

fn object_support_point(code: u32, size: vec3<f32>, k: u32) -> SupportPoint {
    if (code == SHAPE_SPHERE) {
        return SupportPoint(vec3<f32>(0.0), size.x);
    }
    if (code == SHAPE_BOX) {
        let sx = select(-size.x, size.x, (k & 1u) != 0u);
        let sy = select(-size.y, size.y, (k & 2u) != 0u);
        let sz = select(-size.z, size.z, (k & 4u) != 0u);
        return SupportPoint(vec3<f32>(sx, sy, sz), 0.0);
    }
    if (code == SHAPE_CAPSULE) {
        let z = select(size.y, -size.y, k == 0u);
        return SupportPoint(vec3<f32>(0.0, 0.0, z), size.x);
    }
    // cylinder: 8 points on the rim of each cap
    let a = 0.7853982 * f32(k % 8u);
    let z = select(size.y, -size.y, k < 8u);
    return SupportPoint(vec3<f32>(size.x * cos(a), size.x * sin(a), z), 0.0);
}

fn object_num_support(code: u32) -> u32 {
    if (code == SHAPE_SPHERE) {
        return 1u;
    }
    if (code == SHAPE_BOX) {
        return 8u;
    }
    if (code == SHAPE_CAPSULE) {
        return 2u;
    }
    return 16u;
}

fn object_project(code: u32, size: vec3<f32>, p: vec3<f32>) -> Projection {
    if (code == SHAPE_BOX) {
        let c = clamp(p, -size, size);
        let inside = abs(p.x) <= size.x && abs(p.y) <= size.y && abs(p.z) <= size.z;
        return Projection(c, inside);
    }
    if (code == SHAPE_CYLINDER) {
        let z = clamp(p.z, -size.y, size.y);
        let rho = sqrt(p.x * p.x + p.y * p.y);
        let inside = rho <= size.x && abs(p.z) <= size.y;
        let k = select(1.0, size.x / rho, rho > size.x);
        return Projection(vec3<f32>(p.x * k, p.y * k, z), inside);
    }
    // sphere (axis half length 0) and capsule: distance to the axis segment
    let hl = select(0.0, size.y, code == SHAPE_CAPSULE);
    let c = vec3<f32>(0.0, 0.0, clamp(p.z, -hl, hl));
    let d = p - c;
    let l = length(d);
    if (l <= size.x) {
        return Projection(p, true);
    }
    return Projection(c + d * (size.x / l), false);
}

fn object_inside_normal(code: u32, size: vec3<f32>, p: vec3<f32>) -> InsideNormal {
    if (code == SHAPE_BOX) {
        let dx = size.x - abs(p.x);
        let dy = size.y - abs(p.y);
        let dz = size.z - abs(p.z);
        if (dx <= dy && dx <= dz) {
            return InsideNormal(vec3<f32>(sgn(p.x), 0.0, 0.0), dx);
        }
        if (dy <= dz) {
            return InsideNormal(vec3<f32>(0.0, sgn(p.y), 0.0), dy);
        }
        return InsideNormal(vec3<f32>(0.0, 0.0, sgn(p.z)), dz);
    }
    if (code == SHAPE_CYLINDER) {
        let rho = sqrt(p.x * p.x + p.y * p.y);
        let dr = size.x - rho;
        let dz = size.y - abs(p.z);
        if (dz < dr || rho < 1e-9) {
            return InsideNormal(vec3<f32>(0.0, 0.0, sgn(p.z)), dz);
        }
        return InsideNormal(vec3<f32>(p.x / rho, p.y / rho, 0.0), dr);
    }
    let hl = select(0.0, size.y, code == SHAPE_CAPSULE);
    let d = p - vec3<f32>(0.0, 0.0, clamp(p.z, -hl, hl));
    let l = length(d);
    if (l < 1e-9) {
        return InsideNormal(vec3<f32>(1.0, 0.0, 0.0), size.x);
    }
    return InsideNormal(d / l, size.x - l);
}

struct BoxPush {
    normal: vec3<f32>,
    dist: f32,
    point: vec3<f32>,
}

fn segment_box_push(a: vec3<f32>, b: vec3<f32>, h: vec3<f32>) -> BoxPush {
    var best_d = 1e30;
    var best_n = vec3<f32>(0.0, 0.0, 1.0);
    var best_p = a;
    for (var i = 0u; i < 3u; i++) {
        for (var side = 0u; side < 2u; side++) {
            let s = select(-1.0, 1.0, side == 0u);
            // the endpoint deepest along −s·eᵢ and how far it must move along s·eᵢ to reach the face
            let deep = select(b, a, s * a[i] <= s * b[i]);
            let d = h[i] - s * deep[i];
            if (d < best_d) {
                best_d = d;
                var n = vec3<f32>(0.0);
                n[i] = s;
                best_n = n;
                var p = clamp(deep, -h, h);
                p[i] = s * h[i];
                best_p = p;
            }
        }
    }
    return BoxPush(best_n, best_d, best_p);
}

// physics.rs: segment_box_closest. The point of segment [a, b] nearest a box of half extents h
// (box frame), exactly: the root of the piecewise-linear, non-decreasing slope of the squared
// distance, between its last kink (or 0) where it is ≤ 0 and its first (or 1) where it is > 0.
fn segment_box_closest(a: vec3<f32>, b: vec3<f32>, h: vec3<f32>) -> vec3<f32> {
    let u = b - a;
    var t_lo = 0.0;
    var t_hi = 1.0;
    var s_lo = segment_box_slope(a, u, h, 0.0);
    var s_hi = segment_box_slope(a, u, h, 1.0);
    if (s_lo >= 0.0) {
        return a;
    }
    if (s_hi <= 0.0) {
        return b;
    }
    for (var i = 0u; i < 3u; i++) {
        if (abs(u[i]) < 1e-12) {
            continue;
        }
        for (var side = 0u; side < 2u; side++) {
            let face = select(-h[i], h[i], side == 0u);
            let t = (face - a[i]) / u[i];
            if (t > t_lo && t < t_hi) {
                let st_ = segment_box_slope(a, u, h, t);
                if (st_ <= 0.0) {
                    t_lo = t;
                    s_lo = st_;
                } else {
                    t_hi = t;
                    s_hi = st_;
                }
            }
        }
    }
    // the slope is linear on [t_lo, t_hi]: its root
    let t = t_lo + (t_hi - t_lo) * (-s_lo / (s_hi - s_lo));
    return a + u * t;
}

// physics.rs: segment_box_slope. Σᵢ uᵢ · sign(pᵢ) · max(|pᵢ| − hᵢ, 0) at p = a + t u.
fn segment_box_slope(a: vec3<f32>, u: vec3<f32>, h: vec3<f32>, t: f32) -> f32 {
    let p = a + u * t;
    var s = 0.0;
    for (var i = 0u; i < 3u; i++) {
        s += u[i] * sgn(p[i]) * max(abs(p[i]) - h[i], 0.0);
    }
    return s;
}

fn segment_closest(a: vec3<f32>, b: vec3<f32>, p: vec3<f32>) -> vec3<f32> {
    let ab = b - a;
    let l2 = dot(ab, ab);
    if (l2 < 1e-18) {
        return a;
    }
    return a + ab * clamp(dot(p - a, ab) / l2, 0.0, 1.0);
}

fn box_project(c: vec3<f32>, r: vec4<f32>, h: vec3<f32>, p: vec3<f32>) -> vec3<f32> {
    let local = quat_rotate(quat_conj(r), p - c);
    return c + quat_rotate(r, clamp(local, -h, h));
}

// closest point of the triangle (a, b, c) to p (Ericson §5.1.5: vertex, edge, then face regions)
fn triangle_closest(p: vec3<f32>, a: vec3<f32>, b: vec3<f32>, c: vec3<f32>) -> vec3<f32> {
    let ab = b - a;
    let ac = c - a;
    let ap = p - a;
    let d1 = dot(ab, ap);
    let d2 = dot(ac, ap);
    if (d1 <= 0.0 && d2 <= 0.0) {
        return a;
    }
    let bp = p - b;
    let d3 = dot(ab, bp);
    let d4 = dot(ac, bp);
    if (d3 >= 0.0 && d4 <= d3) {
        return b;
    }
    let vc = d1 * d4 - d3 * d2;
    if (vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0) {
        return a + ab * (d1 / (d1 - d3));
    }
    let cp = p - c;
    let d5 = dot(ab, cp);
    let d6 = dot(ac, cp);
    if (d6 >= 0.0 && d5 <= d6) {
        return c;
    }
    let vb = d5 * d2 - d1 * d6;
    if (vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0) {
        return a + ac * (d2 / (d2 - d6));
    }
    let va = d3 * d6 - d5 * d4;
    if (va <= 0.0 && d4 - d3 >= 0.0 && d5 - d6 >= 0.0) {
        return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
    }
    let denom = 1.0 / (va + vb + vc);
    return a + ab * (vb * denom) + ac * (vc * denom);
}

// vertex k of hull piece pd (piece frame, scaled): after its F planes and F triangles
fn hull_vertex(pd: PieceDesc, scale: f32, k: u32) -> vec3<f32> {
    return hulls[pd.hull_first + 2u * pd.hull_faces + k].xyz * scale;
}

// closest point of the solid hull to p; outside, the nearest triangle among those p is in front of
fn hull_project(pd: PieceDesc, scale: f32, p: vec3<f32>) -> Projection {
    let base = pd.hull_first;
    let nf = pd.hull_faces;
    var inside = true;
    var best = p;
    var best_d2 = 1e30;
    for (var f = 0u; f < nf; f++) {
        let pl = hulls[base + f];
        if (dot(pl.xyz, p) - scale * pl.w > 0.0) {
            inside = false;
            let t = hulls[base + nf + f];
            let a = hull_vertex(pd, scale, u32(t.x));
            let b = hull_vertex(pd, scale, u32(t.y));
            let c = hull_vertex(pd, scale, u32(t.z));
            let q = triangle_closest(p, a, b, c);
            let dq = p - q;
            let d2 = dot(dq, dq);
            if (d2 < best_d2) {
                best_d2 = d2;
                best = q;
            }
        }
    }
    return Projection(best, inside);
}

// the segment [a, b] pushed out of the hull along a face normal (SAT on the hull's faces)
fn segment_hull_push(pd: PieceDesc, scale: f32, a: vec3<f32>, b: vec3<f32>) -> BoxPush {
    var best_d = 1e30;
    var best_n = vec3<f32>(0.0, 0.0, 1.0);
    var best_p = a;
    for (var f = 0u; f < pd.hull_faces; f++) {
        let pl = hulls[pd.hull_first + f];
        let n = pl.xyz;
        let deep = select(b, a, dot(n, a) <= dot(n, b));
        let d = scale * pl.w - dot(n, deep);
        if (d < best_d) {
            best_d = d;
            best_n = n;
            best_p = deep + n * d;
        }
    }
    return BoxPush(best_n, best_d, best_p);
}

// closest point of an object piece (a primitive of scaled size, or its hull) to p
fn piece_project(pd: PieceDesc, scale: f32, size: vec3<f32>, p: vec3<f32>) -> Projection {
    if (pd.shape == SHAPE_HULL) {
        return hull_project(pd, scale, p);
    }
    return object_project(pd.shape, size, p);
}

fn collider_pose(ci: u32) -> ColliderPose {
    return ColliderPose(collider_centre(ci), collider_rotation(ci));
}

// physics.rs: collider_centre. The centre of collider_pose alone (the contact pass turns only the
// colliders near the object or the table)
fn collider_centre(ci: u32) -> vec3<f32> {
    let cd = colliders[ci];
    return link_pos[cd.link] + quat_rotate(link_rot[cd.link], cd.pos.xyz);
}

// physics.rs: collider_rotation. The rotation of collider_pose alone
fn collider_rotation(ci: u32) -> vec4<f32> {
    let cd = colliders[ci];
    return quat_mul(link_rot[cd.link], cd.rot);
}

fn bounding_radius(code: u32, size: vec3<f32>) -> f32 {
    if (code == SHAPE_SPHERE) {
        return size.x;
    }
    if (code == SHAPE_BOX) {
        return length(size);
    }
    if (code == SHAPE_CAPSULE) {
        return size.x + size.y;
    }
    return sqrt(size.x * size.x + size.y * size.y);
}

struct PiecePose {
    pos: vec3<f32>,
    rot: vec4<f32>,
    size: vec3<f32>,
}

// world pose and scaled size of an object piece: centre = p_obj + R_obj (s c), rotation = R_obj R_piece
fn piece_pose(pd: PieceDesc) -> PiecePose {
    return piece_pose_at(pd, prm.obj_scale, st.obj_pos.xyz, st.obj_rot);
}

// physics.rs: piece_pose_at. piece_pose with the object's frame at opos, orot (its lengths scaled
// by scale: the env's, which a narrow phase run for another env of the workgroup passes)
fn piece_pose_at(pd: PieceDesc, scale: f32, opos: vec3<f32>, orot: vec4<f32>) -> PiecePose {
    let pos = opos + quat_rotate(orot, pd.pos.xyz * scale);
    return PiecePose(pos, quat_mul(orot, pd.rot), pd.size.xyz * scale);
}

// the object's centre of mass (world): p_obj + R_obj c
fn object_com() -> vec3<f32> {
    return st.obj_pos.xyz + quat_rotate(st.obj_rot, prm.obj_com.xyz);
}

// physics.rs: speculative_margin_at. CONTACT_MARGIN, or how far hand collider ci (its centre at
// cpos) and the object's points can close within the substep: h (|v_rel at its centre| +
// r |ω_link − ω_obj|)
fn speculative_margin_at(ci: u32, cpos: vec3<f32>, h: f32, ocom: vec3<f32>, ovel: vec3<f32>, ow: vec3<f32>) -> f32 {
    let cd = colliders[ci];
    let l = cd.link;
    let v = link_point_velocity(l, cpos) - (ovel + cross(ow, cpos - ocom));
    let r = bounding_radius(cd.shape, cd.size.xyz);
    return max(h * (length(v) + r * length(link_w[l] - ow)), CONTACT_MARGIN);
}

// an env's object as the narrow phase needs it (physics.rs reads it from EnvParams): which of the
// run's objects, its scale and its bounding sphere's radius (EnvParams::obj_com.w). The narrow
// phase takes it as an argument, not from the invocation's own `prm`: an invocation runs queries
// of other envs of its workgroup (narrow_rounds.wgsl)
struct ObjectShape {
    index: u32,
    scale: f32,
    radius: f32,
}

// physics.rs: collide_hand_object_at. The deepest contact of hand collider ci (at cp) over the
// object's pieces (the object `obj`, its frame at opos, orot; bounding spheres grown by margin
// first)
fn collide_hand_object_at(ci: u32, cp: ColliderPose, opos: vec3<f32>, orot: vec4<f32>, margin: f32, obj: ObjectShape) -> Contact {
    let cd = colliders[ci];
    let rc = bounding_radius(cd.shape, cd.size.xyz) + margin;
    var best = contact_at(-1.0, vec3<f32>(0.0, 0.0, 1.0), opos);
    if (!object_in_reach(cd, cp.pos, opos, margin, obj.radius)) {
        return best;
    }
    let od = objects[obj.index];
    // the collider's centre in the object frame: each piece's bounding sphere is tested there
    let c_obj = quat_rotate(quat_conj(orot), cp.pos - opos);
    for (var k = 0u; k < od.n_pieces; k++) {
        let pd = pieces[od.first_piece + k];
        let r = rc + pd.pos.w * obj.scale;
        let dp = c_obj - pd.pos.xyz * obj.scale;
        if (dot(dp, dp) > r * r) {
            continue;
        }
        // (physics.rs takes a piece whose frame is the object's in the object's frame directly; here
        // that shortcut made the bench scene's envs blow up on lavapipe, cause not found; with each
        // env's own list of queries (2026-11-30) it no longer does, but steps 0.67x as fast on
        // lavapipe: left out)
        let pp = piece_pose_at(pd, obj.scale, opos, orot);
        let c = collide_collider_piece(cd, cp, pd, obj.scale, pp.pos, pp.rot, margin);
        if (c.depth > best.depth) {
            best = c;
        }
    }
    return best;
}

// physics.rs: object_in_reach. collide_hand_object_at's first test: the collider's bounding
// sphere, grown by margin, meets the object's (radius obj_radius; a NaN pose passes, on to the
// narrow phase); the contact pass takes it first, to leave a far collider unturned
fn object_in_reach(cd: ColliderDesc, cpos: vec3<f32>, opos: vec3<f32>, margin: f32, obj_radius: f32) -> bool {
    let reach = bounding_radius(cd.shape, cd.size.xyz) + margin + obj_radius;
    let dc = cpos - opos;
    return !(dot(dc, dc) > reach * reach);
}

// physics.rs: SWEPT_TOLERANCE
const SWEPT_TOLERANCE: f32 = 3.0e-4;

// the object's frame (its origin and rotation)
struct ObjectFrame {
    pos: vec3<f32>,
    rot: vec4<f32>,
}

// physics.rs: object_frame_at_end. The object's frame at the end of the substep if it keeps its
// velocities (its centre of mass ocom moving at ovel, turning at ow), as integrate_object moves it:
// the frame turns about the centre of mass
fn object_frame_at_end(h: f32, ocom: vec3<f32>, ovel: vec3<f32>, ow: vec3<f32>) -> ObjectFrame {
    let rot = quat_integrate(st.obj_rot, ow, h);
    return ObjectFrame(ocom + ovel * h - quat_rotate(rot, prm.obj_com.xyz), rot);
}

// physics.rs: collider_pose_at_end. Collider pose cp (on link l) at the end of the substep: it
// moves with its link
fn collider_pose_at_end(l: u32, cp: ColliderPose, h: f32) -> ColliderPose {
    return ColliderPose(cp.pos + link_point_velocity(l, cp.pos) * h, quat_integrate(cp.rot, link_w[l], h));
}

// physics.rs: swept_test. Whether the swept search of hand collider ci's contact c (at the
// substep's poses, against the object's velocities ovel, ow) may find a contact deeper than c
// would be by the end of the substep, and c's own depth by then (c_end)
struct SweptTest {
    search: bool,
    c_end: f32,
}

fn swept_test(ci: u32, c: Contact, h: f32, ocom: vec3<f32>, ovel: vec3<f32>, ow: vec3<f32>) -> SweptTest {
    if (c.depth <= -1.0) {
        return SweptTest(false, 0.0);
    }
    let cd = colliders[ci];
    let l = cd.link;
    // v_hand − v_object at the contact along n: its separating speed
    let c_end = c.depth - h * dot(link_point_velocity(l, c.point) - (ovel + cross(ow, c.point - ocom)), c.normal);
    // no feature gets deeper than c's own prediction by more than h·2r·|ω_link − ω_obj|: nothing
    // to find within the tolerance, or where even so nothing would be touching by then
    let sweep = h * 2.0 * bounding_radius(cd.shape, cd.size.xyz) * length(link_w[l] - ow);
    return SweptTest(!(sweep <= SWEPT_TOLERANCE || c_end + sweep <= 0.0), c_end);
}

// physics.rs: swept_contact_from_end. The contact `end` that the swept search found at the end of
// the substep for link l, taken back to the start of the substep along the relative motion: its
// point with the object, its depth d = d_end + h·(v_rel·n)
fn swept_contact_from_end(l: u32, end: Contact, h: f32, ocom: vec3<f32>, ovel: vec3<f32>, ow: vec3<f32>) -> Contact {
    let x = end.point - (ovel + cross(ow, end.point - ocom)) * h;
    let v_rel = link_point_velocity(l, x) - (ovel + cross(ow, x - ocom));
    var out = end;
    out.depth = end.depth + h * dot(v_rel, end.normal);
    out.point = x;
    return out;
}

// physics.rs: swept_end_contact. The swept search's contact `end` (found at the end of the
// substep for link l), taken back to the substep's start, where it is deeper than c_end (the
// pair's own contact's depth by then) by more than SWEPT_TOLERANCE; found false where not (or
// where the narrow phase found none)
struct SweptEnd {
    found: bool,
    c: Contact,
}

fn swept_end_contact(l: u32, end: Contact, c_end: f32, h: f32, ocom: vec3<f32>, ovel: vec3<f32>, ow: vec3<f32>) -> SweptEnd {
    if (end.depth <= -1.0 || end.depth <= c_end + SWEPT_TOLERANCE) {
        return SweptEnd(false, end);
    }
    return SweptEnd(true, swept_contact_from_end(l, end, h, ocom, ovel, ow));
}

// a hand collider against object piece pd (lengths scaled by scale, at opos, orot); apart by
// more than margin, depth −1
fn collide_collider_piece(cd: ColliderDesc, cp: ColliderPose, pd: PieceDesc, scale: f32, opos: vec3<f32>, orot: vec4<f32>, margin: f32) -> Contact {
    let oinv = quat_conj(orot);
    // collider in the object's frame
    return collide_collider_piece_in(cd, quat_rotate(oinv, cp.pos - opos), quat_mul(oinv, cp.rot), pd, scale, opos, orot, margin);
}

// physics.rs: collide_collider_piece_in. collide_collider_piece with the collider's centre c_o and
// rotation r_o in the piece's frame
fn collide_collider_piece_in(cd: ColliderDesc, c_o: vec3<f32>, r_o: vec4<f32>, pd: PieceDesc, scale: f32, opos: vec3<f32>, orot: vec4<f32>, margin: f32) -> Contact {
    let code = pd.shape;
    let size = pd.size.xyz * scale;
    var out = contact_at(0.0, vec3<f32>(0.0), vec3<f32>(0.0));
    // the piece farther from the collider's centre than the collider reaches (with the margin):
    // no contact
    let y0 = piece_project(pd, scale, size, c_o).point;
    let reach = bounding_radius(cd.shape, cd.size.xyz) + margin;
    let d0 = c_o - y0;
    if (dot(d0, d0) > reach * reach) {
        out.depth = -1.0;
        return out;
    }
    if (cd.shape == SHAPE_BOX) {
        let h = cd.size.xyz;
        // two boxes overlapping over every separating axis, least along one of the hand box's
        // faces: box_box_contact; else the support points below (physics.rs: collide_collider_piece)
        var sat = BoxSeparation(1.0, vec3<f32>(0.0, 0.0, 1.0), 0u);
        if (code == SHAPE_BOX) {
            sat = box_box_separation(c_o, r_o, h, size, margin);
        }
        // a box piece apart along an axis by more than the margin: at least that far apart, out
        // of reach (other pieces have no separation)
        if (code == SHAPE_BOX && sat.sep > margin) {
            out.depth = -1.0;
            return out;
        }
        if (sat.sep <= 0.0 && sat.k < 3u) {
            let bb = box_box_contact(c_o, r_o, h, size, sat.axis, sat.k);
            if (bb.depth > 0.0) {
                return piece_contact_to_world(bb, opos, orot);
            }
        }
        var x = c_o;
        for (var it = 0u; it < BOX_PROJ_ITERS; it++) {
            let y = piece_project(pd, scale, size, x).point;
            let x_next = box_project(c_o, r_o, h, y);
            // a fixed point: every further round returns the same x
            if (all(x_next == x)) {
                break;
            }
            x = x_next;
        }
        let y = piece_project(pd, scale, size, x).point;
        // y and the piece's support points (box_piece_contact)
        let bc = box_piece_contact(pd, scale, size, c_o, r_o, h, y);
        var depth = bc.depth;
        // the normal in the object's frame
        var normal = quat_rotate(r_o, bc.n_local);
        // apart by the projections, from a box piece: no more than the boxes' separation over
        // their separating axes where those find them apart (physics.rs: collide_collider_piece)
        if (depth < 0.0 && code == SHAPE_BOX) {
            if (sat.sep > 0.0 && sat.sep < -depth) {
                depth = -sat.sep;
                normal = sat.axis;
            }
        }
        // overlapping least along an edge pair, deeper than the support points and projections
        // find: the edges' own contact (physics.rs)
        if (code == SHAPE_BOX && sat.sep <= 0.0 && sat.k >= 6u && -sat.sep > depth) {
            return piece_contact_to_world(box_edge_contact(c_o, r_o, h, size, sat.axis, -sat.sep, sat.k), opos, orot);
        }
        out.depth = depth;
        out.normal = quat_rotate(orot, normal);
        out.point = opos + quat_rotate(orot, bc.point);
        return out;
    }
    // sphere or capsule collider: a segment swept by a radius
    let hl = select(0.0, cd.size.y, cd.shape == SHAPE_CAPSULE);
    let axis = quat_rotate(r_o, vec3<f32>(0.0, 0.0, hl));
    let a = c_o - axis;
    let b = c_o + axis;
    var x: vec3<f32>;
    if (code == SHAPE_BOX) {
        x = segment_box_closest(a, b, size);
    } else {
        x = segment_closest(a, b, vec3<f32>(0.0));
        for (var it = 0u; it < PROJ_ITERS; it++) {
            let y = piece_project(pd, scale, size, x).point;
            x = segment_closest(a, b, y);
        }
    }
    let pr = piece_project(pd, scale, size, x);
    let y = pr.point;
    let rc = cd.size.x;
    var n = vec3<f32>(0.0, 0.0, 1.0);
    var surf = y;
    if (pr.inside && code == SHAPE_BOX) {
        let bp = segment_box_push(a, b, size);
        n = bp.normal;
        out.depth = rc + bp.dist;
        surf = bp.point;
    } else if (pr.inside && code == SHAPE_HULL) {
        let hp = segment_hull_push(pd, scale, a, b);
        n = hp.normal;
        out.depth = rc + hp.dist;
        surf = hp.point;
    } else if (pr.inside) {
        let ins = object_inside_normal(code, size, x);
        n = ins.normal;
        out.depth = rc + ins.dist;
        surf = x + ins.normal * ins.dist;
    } else {
        let d = x - y;
        let l = length(d);
        out.depth = rc - l;
        if (l > 1e-12) {
            n = d / l;
        }
    }
    // a capsule lying along a box piece's face: the ends of its segment's part over the face are
    // two point springs (capsule_face_contact)
    if (code == SHAPE_BOX && hl > 0.0 && out.depth > 0.0) {
        let line = capsule_face_contact(a, b, rc, size, n);
        if (line.spring_count > 1.0) {
            return piece_contact_to_world(line, opos, orot);
        }
    }
    out.normal = quat_rotate(orot, n);
    out.point = opos + quat_rotate(orot, surf);
    return out;
}

struct BoxFace {
    n: vec3<f32>,
    dist: f32,
}

// The face of a box nearest a point v inside it (box frame; d = h − |v|): the push out through it
// and the point's distance to it (CPU twin: nearest_box_face).
fn nearest_box_face(v: vec3<f32>, d: vec3<f32>) -> BoxFace {
    if (d.x <= d.y && d.x <= d.z) {
        return BoxFace(vec3<f32>(-sgn(v.x), 0.0, 0.0), d.x);
    }
    if (d.y <= d.z) {
        return BoxFace(vec3<f32>(0.0, -sgn(v.y), 0.0), d.y);
    }
    return BoxFace(vec3<f32>(0.0, 0.0, -sgn(v.z)), d.z);
}

// The weight (m) of the piece's nearest point y where a hand box's contact point moves toward the
// piece's support points deeper than y.
const DEEP_BLEND: f32 = 1.0e-4;

struct BoxPieceContact {
    depth: f32,
    n_local: vec3<f32>,
    point: vec3<f32>,
}

// The contact of a hand box (centre c_o, rotation r_o, half extents h, in the piece frame) with
// piece pd, given the piece's point y nearest the box: the deepest of y (inside the box) and the
// piece's support points inside it, each at its nearest face, gives the depth and the face; the
// point is the average of y (weight DEEP_BLEND) and that face's support points deeper than y's
// depth past it, weighted by how much deeper (CPU twin: box_piece_contact).
fn box_piece_contact(pd: PieceDesc, scale: f32, size: vec3<f32>, c_o: vec3<f32>, r_o: vec4<f32>, h: vec3<f32>, y: vec3<f32>) -> BoxPieceContact {
    let inv = quat_conj(r_o);
    let ly = quat_rotate(inv, y - c_o);
    let dy = h - abs(ly);
    var depth = -1.0;
    var n = vec3<f32>(0.0, 0.0, 1.0);
    if (dy.x >= 0.0 && dy.y >= 0.0 && dy.z >= 0.0) {
        let f = nearest_box_face(ly, dy);
        n = f.n;
        depth = f.dist;
    }
    // the piece's bounding sphere apart from the box: no support point inside it
    let gap = max(abs(quat_rotate(inv, -c_o)) - h, vec3<f32>(0.0));
    let radius = pd.pos.w * scale;
    if (dot(gap, gap) > radius * radius) {
        return box_gap_contact(h, ly, y);
    }
    let y_depth = depth;
    for (var k = 0u; k < pd.n_support; k++) {
        let sp = box_frame_support(pd, scale, size, inv, c_o, k);
        let dd = h - abs(sp.pos);
        let f = nearest_box_face(sp.pos, dd);
        if (dd.x >= -sp.radius && dd.y >= -sp.radius && dd.z >= -sp.radius && f.dist + sp.radius > depth) {
            depth = f.dist + sp.radius;
            n = f.n;
        }
    }
    if (depth < 0.0) {
        return box_gap_contact(h, ly, y);
    }
    // no support point deeper than y: the point is y
    if (depth == y_depth) {
        return BoxPieceContact(depth, n, y);
    }
    // y's depth past that face (negative outside it) sets the floor
    let floor = max(dot(h, abs(n)) + dot(n, ly), 0.0);
    var wsum = DEEP_BLEND;
    var psum = y * DEEP_BLEND;
    for (var k = 0u; k < pd.n_support; k++) {
        let sp = box_frame_support(pd, scale, size, inv, c_o, k);
        let dd = h - abs(sp.pos);
        let f = nearest_box_face(sp.pos, dd);
        let w = f.dist + sp.radius - floor;
        if (dd.x >= -sp.radius && dd.y >= -sp.radius && dd.z >= -sp.radius && all(f.n == n) && w > 0.0) {
            wsum += w;
            psum += (c_o + quat_rotate(r_o, sp.pos + n * sp.radius)) * w;
        }
    }
    return BoxPieceContact(depth, n, psum / wsum);
}

struct BoxSeparation {
    sep: f32,
    axis: vec3<f32>,
    k: u32,
}

// physics.rs: EDGE_AXIS_BIAS
const EDGE_AXIS_BIAS: f32 = 1.0e-4;

// physics.rs: EDGE_AXIS_SHARE (an edge axis must also overlap 10 % less than the best face)
const EDGE_AXIS_SHARE: f32 = 0.1;

// physics.rs: box_box_separation. The largest separation of a box (c, r, ha) from the axis-aligned
// box hb at the origin over the 15 separating axes (each box's faces, then edge × edge; near-parallel
// edges skipped), that axis from the second box to the first, and its index (0–2 the first box's
// faces, 3–5 the second's, 6 + 3i + j edge i × edge j; an edge axis only where it beats the faces'
// best by EDGE_AXIS_BIAS and EDGE_AXIS_SHARE of its overlap): > 0 a lower bound on their
// distance, ≤ 0 they overlap (SAT); as soon as an axis taken separates them by more than
// apart_beyond, that axis
fn box_box_separation(c: vec3<f32>, r: vec4<f32>, ha: vec3<f32>, hb: vec3<f32>, apart_beyond: f32) -> BoxSeparation {
    // the first box's axes (the second's are x̂, ŷ, ẑ)
    let a = quat_axes(r);
    var best = BoxSeparation(-3.0e38, vec3<f32>(0.0, 0.0, 1.0), 0u);
    for (var k = 0u; k < 15u; k++) {
        // the axis l, 1/|l|, each box's half-width along l times |l| (physics.rs)
        var l: vec3<f32>;
        var inv_len = 1.0;
        var ra: f32;
        if (k < 3u) {
            l = a[k];
            ra = ha[k];
        } else if (k < 6u) {
            let j = k - 3u;
            l = vec3<f32>(0.0);
            l[j] = 1.0;
            ra = ha.x * abs(a[0][j]) + ha.y * abs(a[1][j]) + ha.z * abs(a[2][j]);
        } else {
            let i = (k - 6u) / 3u;
            let j = (k - 6u) % 3u;
            var e = vec3<f32>(0.0);
            e[j] = 1.0;
            l = cross(a[i], e);
            // |aᵢ × ê_j|² = 1 − (aᵢ)_j²: parallel edges skipped
            let len2 = 1.0 - a[i][j] * a[i][j];
            if (len2 < 1e-8) {
                continue;
            }
            // a_m·(aᵢ × ê_j): 0 for m = i, ± the third axis's component j otherwise
            let i1 = (i + 1u) % 3u;
            let i2 = (i + 2u) % 3u;
            ra = ha[i1] * abs(a[i2][j]) + ha[i2] * abs(a[i1][j]);
            inv_len = 1.0 / sqrt(len2);
        }
        var rb = hb.x * abs(l.x) + hb.y * abs(l.y) + hb.z * abs(l.z);
        if (k >= 3u && k < 6u) {
            rb = hb[k - 3u];
        }
        let t = dot(c, l);
        let sep = (abs(t) - ra - rb) * inv_len;
        // an edge axis must beat the faces' best by the bias and a share of its overlap (−sep)
        let bias = select(0.0, EDGE_AXIS_BIAS + EDGE_AXIS_SHARE * max(-best.sep, 0.0), k >= 6u);
        if (sep > best.sep + bias) {
            best = BoxSeparation(sep, select(-l, l, t >= 0.0) * inv_len, k);
            if (best.sep > apart_beyond) {
                return best;
            }
        }
    }
    return best;
}

struct ClippedPolygon {
    q: array<vec3<f32>, 8>,
    n: u32,
}

// physics.rs: clip_polygon. Sutherland–Hodgman: the part of polygon poly where sign·q[t] ≤ lim
fn clip_polygon(poly: ClippedPolygon, t: u32, sign: f32, lim: f32) -> ClippedPolygon {
    var out: ClippedPolygon;
    out.n = 0u;
    if (poly.n == 0u) {
        return out;
    }
    var prev = poly.q[poly.n - 1u];
    // how far past the line (inside ≤ 0)
    var dp = sign * prev[t] - lim;
    for (var i = 0u; i < poly.n; i++) {
        let cur = poly.q[i];
        let dc = sign * cur[t] - lim;
        if ((dc <= 0.0) != (dp <= 0.0) && out.n < 8u) {
            // the edge crosses the line: prev + (cur − prev)·dp / (dp − dc)
            out.q[out.n] = prev + (cur - prev) * (dp / (dp - dc));
            out.n += 1u;
        }
        if (dc <= 0.0 && out.n < 8u) {
            out.q[out.n] = cur;
            out.n += 1u;
        }
        prev = cur;
        dp = dc;
    }
    return out;
}

// physics.rs: box_box_contact. A hand box (c, r, ha, in the piece frame) overlapping a box piece
// (hb at the origin) least along its own face k < 3 (axis: piece → hand box), in the piece frame:
// the piece's incident face clipped to that face stands for the points below it (depth max dᵢ,
// point Σ dᵢ xᵢ / Σ dᵢ on the piece's face, spring_count Σ dᵢ / max dᵢ, their spread). Depth −1
// where no point is below.
fn box_box_contact(c: vec3<f32>, r: vec4<f32>, ha: vec3<f32>, hb: vec3<f32>, axis: vec3<f32>, k: u32) -> Contact {
    let a = array<vec3<f32>, 3>(quat_rotate(r, vec3<f32>(1.0, 0.0, 0.0)), quat_rotate(r, vec3<f32>(0.0, 1.0, 0.0)), quat_rotate(r, vec3<f32>(0.0, 0.0, 1.0)));
    let e = array<vec3<f32>, 3>(vec3<f32>(1.0, 0.0, 0.0), vec3<f32>(0.0, 1.0, 0.0), vec3<f32>(0.0, 0.0, 1.0));
    // the reference face: the hand box's face k toward the piece (outward −axis)
    let nref = -axis;
    // the incident face: the piece's face whose outward normal is most against nref
    var j = 0u;
    for (var m = 1u; m < 3u; m++) {
        if (abs(nref[m]) > abs(nref[j])) {
            j = m;
        }
    }
    let f = e[j] * (-hb[j] * sgn(nref[j]));
    let eu = e[(j + 1u) % 3u] * hb[(j + 1u) % 3u];
    let ev = e[(j + 2u) % 3u] * hb[(j + 2u) % 3u];
    // its corners in the hand box's frame, in order around the face
    var poly: ClippedPolygon;
    poly.n = 4u;
    let corners = array<vec3<f32>, 4>(f + eu + ev, f - eu + ev, f - eu - ev, f + eu - ev);
    for (var m = 0u; m < 4u; m++) {
        let d = corners[m] - c;
        poly.q[m] = vec3<f32>(dot(d, a[0]), dot(d, a[1]), dot(d, a[2]));
    }
    // clipped to the hand box face's rectangle along its two other axes
    let t1 = (k + 1u) % 3u;
    let t2 = (k + 2u) % 3u;
    // (in a loop: one call site, one inlined copy; the order of physics.rs's four calls)
    for (var e = 0u; e < 4u; e++) {
        let t = select(t1, t2, e >= 2u);
        poly = clip_polygon(poly, t, select(1.0, -1.0, (e & 1u) == 1u), ha[t]);
    }
    // each point's depth below the hand box's face: dᵢ = h_k − s·q_k
    let s_ref = sgn(dot(nref, a[k]));
    var springs = Manifold(0.0, 0.0, vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0));
    for (var m = 0u; m < poly.n; m++) {
        let q = poly.q[m];
        let d = ha[k] - s_ref * q[k];
        if (d > 0.0) {
            // back in the piece frame, on the piece's incident face
            manifold_add(&springs, c + a[0] * q.x + a[1] * q.y + a[2] * q.z, d);
        }
    }
    return manifold_contact(springs, axis, c);
}

// physics.rs: Manifold. The point springs of one contact as they are gathered: Σ dᵢ, max dᵢ,
// Σ dᵢ xᵢ, Σ dᵢ xᵢ xᵢᵀ (diagonal, then xy, xz, yz)
struct Manifold {
    dsum: f32,
    dmax: f32,
    xsum: vec3<f32>,
    xx_diag: vec3<f32>,
    xx_off: vec3<f32>,
}

// physics.rs: box_edge_contact. A hand box (c, r, ha, in the piece frame) overlapping a box piece
// (hb at the origin) least along edge axis k ≥ 6 (its edge i × the piece's edge j; axis from the
// piece to the hand box, overlap along it): the two edges along those directions that reach
// furthest into each other, met at the piece's edge's point nearest the hand box's edge
fn box_edge_contact(c: vec3<f32>, r: vec4<f32>, ha: vec3<f32>, hb: vec3<f32>, axis: vec3<f32>, overlap: f32, k: u32) -> Contact {
    let a = quat_axes(r);
    let i = (k - 6u) / 3u;
    let j = (k - 6u) % 3u;
    // the middle of the hand box's edge along aᵢ furthest toward the piece (against the axis)
    var pa = c;
    for (var m = 0u; m < 3u; m++) {
        if (m != i) {
            pa -= a[m] * (ha[m] * sgn(dot(a[m], axis)));
        }
    }
    // the middle of the piece's edge along ê_j furthest toward the hand box (along the axis)
    var pb = vec3<f32>(0.0);
    for (var m = 0u; m < 3u; m++) {
        if (m != j) {
            pb[m] = hb[m] * sgn(axis[m]);
        }
    }
    // the lines' nearest points pa + s aᵢ, pb + t ê_j (physics.rs), each kept on its edge
    let d = pa - pb;
    let b = a[i][j];
    let da = dot(a[i], d);
    let db = d[j];
    let s = clamp((b * db - da) / (1.0 - b * b), -ha[i], ha[i]);
    let t = clamp(db + s * b, -hb[j], hb[j]);
    var x = pb;
    x[j] += t;
    return contact_at(overlap, axis, x);
}

// physics.rs: Manifold::add. A point spring at x, d deep
fn manifold_add(m: ptr<function, Manifold>, x: vec3<f32>, d: f32) {
    (*m).dsum += d;
    (*m).dmax = max((*m).dmax, d);
    (*m).xsum += x * d;
    (*m).xx_diag += x * x * d;
    (*m).xx_off += vec3<f32>(x.x * x.y, x.x * x.z, x.y * x.z) * d;
}

// physics.rs: Manifold::contact. The contact standing for the springs (depth −1 at `empty` where
// there are none): depth max dᵢ, point Σ dᵢ xᵢ / Σ dᵢ, spring count Σ dᵢ / max dᵢ, spread
fn manifold_contact(m: Manifold, normal: vec3<f32>, empty: vec3<f32>) -> Contact {
    if (m.dsum <= 0.0) {
        return contact_at(-1.0, normal, empty);
    }
    let p = m.xsum / m.dsum;
    // C = Σ wᵢ xᵢ xᵢᵀ − p pᵀ
    let spread_diag = max(m.xx_diag / m.dsum - p * p, vec3<f32>(0.0));
    let spread_off = m.xx_off / m.dsum - vec3<f32>(p.x * p.y, p.x * p.z, p.y * p.z);
    return Contact(m.dmax, normal, p, m.dsum / m.dmax, spread_diag, spread_off);
}

// physics.rs: capsule_face_contact. A capsule (segment a–b, radius rc, piece frame) against the face
// of a box piece (h) with outward normal n (a box axis, else none): the ends of the segment's part
// over the face, each a point spring rc − its height over the face deep
fn capsule_face_contact(a: vec3<f32>, b: vec3<f32>, rc: f32, h: vec3<f32>, n: vec3<f32>) -> Contact {
    let none = contact_at(-1.0, n, a);
    let na = abs(n);
    var i = 2u;
    if (na.x >= na.y && na.x >= na.z) {
        i = 0u;
    } else if (na.y >= na.z) {
        i = 1u;
    }
    if (na[i] < 0.9999) {
        return none;
    }
    let s = sgn(n[i]);
    // the segment's parameter range over the face's rectangle
    let d = b - a;
    var t0 = 0.0;
    var t1 = 1.0;
    for (var m = 1u; m < 3u; m++) {
        let t = (i + m) % 3u;
        if (abs(d[t]) < 1e-12) {
            if (abs(a[t]) > h[t]) {
                return none;
            }
        } else {
            let u0 = (-h[t] - a[t]) / d[t];
            let u1 = (h[t] - a[t]) / d[t];
            t0 = max(t0, min(u0, u1));
            t1 = min(t1, max(u0, u1));
        }
    }
    if (t0 >= t1) {
        return none;
    }
    var springs = Manifold(0.0, 0.0, vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0));
    let ts = array<f32, 2>(t0, t1);
    for (var m = 0u; m < 2u; m++) {
        var x = a + d * ts[m];
        // depth: rc less the end's height over the face
        let dk = rc - (s * x[i] - h[i]);
        if (dk <= 0.0) {
            continue;
        }
        // on the face
        x[i] = s * h[i];
        manifold_add(&springs, x, dk);
    }
    return manifold_contact(springs, n, a);
}

// physics.rs: piece_contact_to_world. Contact c in the frame of a piece at opos, orot, in the world
fn piece_contact_to_world(c: Contact, opos: vec3<f32>, orot: vec4<f32>) -> Contact {
    let qi = quat_conj(orot);
    // column j of R C Rᵀ: R C (Rᵀ eⱼ)
    let c0 = quat_rotate(orot, spread_mul(c.spread_diag, c.spread_off, quat_rotate(qi, vec3<f32>(1.0, 0.0, 0.0))));
    let c1 = quat_rotate(orot, spread_mul(c.spread_diag, c.spread_off, quat_rotate(qi, vec3<f32>(0.0, 1.0, 0.0))));
    let c2 = quat_rotate(orot, spread_mul(c.spread_diag, c.spread_off, quat_rotate(qi, vec3<f32>(0.0, 0.0, 1.0))));
    return Contact(c.depth, quat_rotate(orot, c.normal), opos + quat_rotate(orot, c.point), c.spring_count, vec3<f32>(c0.x, c1.y, c2.z), vec3<f32>(c1.x, c2.x, c2.y));
}

// physics.rs: spread_mul. C·x for C given as its diagonal and (xy, xz, yz)
fn spread_mul(d: vec3<f32>, o: vec3<f32>, x: vec3<f32>) -> vec3<f32> {
    return vec3<f32>(d.x * x.x + o.x * x.y + o.y * x.z, o.x * x.x + d.y * x.y + o.z * x.z, o.y * x.x + o.z * x.y + d.z * x.z);
}

// physics.rs: spread_matrix. A manifold's rotational stiffness about its centre,
// b (tr C·I − C) + (a − b) [n]× C [n]×ᵀ, as its columns
fn spread_matrix(d: vec3<f32>, o: vec3<f32>, n: vec3<f32>, a: f32, b: f32) -> array<vec3<f32>, 3> {
    let tr = d.x + d.y + d.z;
    var cols: array<vec3<f32>, 3>;
    for (var i = 0u; i < 3u; i++) {
        var x = vec3<f32>(0.0);
        x[i] = 1.0;
        cols[i] = (x * tr - spread_mul(d, o, x)) * b - cross(n, spread_mul(d, o, cross(n, x))) * (a - b);
    }
    return cols;
}

// physics.rs: box_gap_contact. A hand box apart from a piece: the gap between y and the box's
// point nearest it as a negative depth, along the line between them (a speculative contact).
fn box_gap_contact(h: vec3<f32>, ly: vec3<f32>, y: vec3<f32>) -> BoxPieceContact {
    let d = clamp(ly, -h, h) - ly;
    let gap = length(d);
    if (gap > 1e-9) {
        return BoxPieceContact(-gap, d / gap, y);
    }
    return BoxPieceContact(-1.0, vec3<f32>(0.0, 0.0, 1.0), y);
}

// Support point k of piece pd in a hand box's frame and its radius (CPU twin: box_frame_support).
fn box_frame_support(pd: PieceDesc, scale: f32, size: vec3<f32>, inv: vec4<f32>, c_o: vec3<f32>, k: u32) -> SupportPoint {
    let sp = piece_support_point(pd, scale, size, k);
    return SupportPoint(quat_rotate(inv, sp.pos - c_o), sp.radius);
}

// Support point k of piece pd in its own frame and its radius: a primitive's, or a hull's vertex
// (CPU twin: piece_support_point).
fn piece_support_point(pd: PieceDesc, scale: f32, size: vec3<f32>, k: u32) -> SupportPoint {
    if (pd.shape == SHAPE_HULL) {
        return SupportPoint(hull_vertex(pd, scale, k), 0.0);
    }
    return object_support_point(pd.shape, size, k);
}

// physics.rs: collide_hand_table_at. The contact of hand collider ci (at cp) with the table
fn collide_hand_table_at(ci: u32, cp: ColliderPose) -> Contact {
    let cd = colliders[ci];
    var low = cp.pos;
    var r = cd.size.x;
    if (cd.shape == SHAPE_CAPSULE) {
        let axis = quat_rotate(cp.rot, vec3<f32>(0.0, 0.0, cd.size.y));
        low = select(cp.pos + axis, cp.pos - axis, axis.z > 0.0);
    } else if (cd.shape == SHAPE_BOX) {
        r = 0.0;
        for (var k = 0u; k < 8u; k++) {
            let corner = object_support_point(SHAPE_BOX, cd.size.xyz, k).pos;
            let w = cp.pos + quat_rotate(cp.rot, corner);
            if (w.z < low.z || k == 0u) {
                low = w;
            }
        }
    }
    return contact_at(r - low.z, vec3<f32>(0.0, 0.0, 1.0), vec3<f32>(low.x, low.y, 0.0));
}

// support point k of object piece pd (scaled size, hull scaled by scale, at ppos, prot) against
// the table: a primitive's support points, a hull's vertices
fn collide_piece_table(pd: PieceDesc, scale: f32, size: vec3<f32>, ppos: vec3<f32>, prot: vec4<f32>, k: u32) -> Contact {
    let sp = piece_support_point(pd, scale, size, k);
    let w = ppos + quat_rotate(prot, sp.pos);
    return contact_at(sp.radius - w.z, vec3<f32>(0.0, 0.0, 1.0), vec3<f32>(w.x, w.y, 0.0));
}

fn contact_force(c: Contact, vrel: vec3<f32>, anchor: vec3<f32>, k: f32, kt: f32, damp: f32, mu: f32, h: f32) -> ContactForce {
    let n = c.normal;
    let vn = dot(vrel, n);
    let vt = vrel - n * vn;
    // Fn = max(k·depth − c·vn, 0)
    let fn_ = max(k * c.depth - damp * vn, 0.0);
    if (fn_ <= 0.0) {
        return ContactForce(vec3<f32>(0.0), vec3<f32>(0.0), 0.0);
    }
    // spring kept in the tangent plane, stretched by the tangential slip: s ← s − (s·n)n + vt h
    let spring = anchor - n * dot(anchor, n) + vt * h;
    // Ft = −kt s − ct vt, with ct = c
    let ft = -kt * spring - damp * vt;
    let ft_len = length(ft);
    let limit = mu * fn_;
    if (ft_len > limit) {
        // sliding: the friction force sits on the cone and the spring carries it
        let f_slide = ft * (limit / ft_len);
        let vt_len = length(vt);
        let b = select(kt * h + damp, min(limit / vt_len, kt * h + damp), vt_len > 1e-6);
        return ContactForce(n * fn_ + f_slide, -f_slide / kt, b);
    }
    return ContactForce(n * fn_ + ft, spring, kt * h + damp);
}

struct Torsion {
    torque: vec3<f32>,
    damping: f32,
}

const TORSION_EPS: f32 = 0.05;

fn torsion_torque(n: vec3<f32>, w_rel: vec3<f32>, fn_: f32, mu: f32, radius: f32) -> Torsion {
    let wn = dot(w_rel, n);
    // b = μ Fn r / max(|ω·n|, ε);  τ = −b (ω·n) n
    let b = mu * fn_ * radius / max(abs(wn), TORSION_EPS);
    return Torsion(n * (-b * wn), b);
}

// physics.rs: CONTACT_MARGIN. How far apart (m) a hand collider and the object or table may be for
// their contact to be solved: a gap that closes within the substep pushes already.
const CONTACT_MARGIN: f32 = 0.003;

// the hand's mass and rotational inertia about the wrist, as the wrist moves (physics.rs: wrist_mass_inertia)
fn wrist_mass_inertia() -> vec2<f32> {
    return vec2<f32>(g.hand_mass * prm.hand_mass_scale + g.wrist_added_mass, g.hand_inertia * prm.hand_mass_scale + g.wrist_added_inertia);
}

struct JointLead {
    joint: u32,
    mult: f32,
}

// the coordinate that moves joint j (itself, or its mimic leader) and its multiplier (physics.rs: joint_lead)
fn joint_lead(j: u32) -> JointLead {
    if (joints[j].mimic_leader != NO_JOINT) {
        return JointLead(joints[j].mimic_leader, joints[j].mimic_mult);
    }
    return JointLead(j, 1.0);
}

// a joint coordinate's inertia as a contact impulse meets it: I + h·d (physics.rs: joint_impulse_inertia)
fn joint_impulse_inertia(j: u32, h: f32) -> f32 {
    let jd = joints[j];
    return jd.armature + jd.link_inertia * prm.hand_mass_scale + h * jd.damping * prm.kd_scale;
}

// physics.rs: apply_hand_force. Δq̇_L += h·m_j·aⱼ·((x − oⱼ) × F) / (I_L + h·d_L) up the chain,
// Δv_w += h·F / m_w, Δω_w += h·(x − p_w) × F / I_w.
fn apply_hand_force(l: u32, x: vec3<f32>, f: vec3<f32>, h: f32) {
    let mi = wrist_mass_inertia();
    wrist_dv += f * (h / mi.x);
    wrist_dw += cross(x - link_pos[0], f) * (h / mi.y);
    var link = l;
    while (link > 0u) {
        let j = link - 1u;
        let ld = joint_lead(j);
        let tq = dot(joint_now[j].axis, cross(x - link_pos[link], f));
        joint_now[ld.joint].dqd += h * ld.mult * tq / joint_impulse_inertia(ld.joint, h);
        link = joints[j].parent_link;
    }
}

// physics.rs: apply_hand_torque. Δq̇_L += h·m_j·aⱼ·T / (I_L + h·d_L) up the chain, Δω_w += h·T / I_w.
fn apply_hand_torque(l: u32, tq: vec3<f32>, h: f32) {
    let mi = wrist_mass_inertia();
    wrist_dw += tq * (h / mi.y);
    var link = l;
    while (link > 0u) {
        let j = link - 1u;
        let ld = joint_lead(j);
        joint_now[ld.joint].dqd += h * ld.mult * dot(joint_now[j].axis, tq) / joint_impulse_inertia(ld.joint, h);
        link = joints[j].parent_link;
    }
}

// physics.rs: hand_point_velocity_change. Δv = Δv_w + Δω_w × (x − p_w) + Σ_chain m_j·Δq̇_L·aⱼ × (x − oⱼ).
fn hand_point_velocity_change(l: u32, x: vec3<f32>) -> vec3<f32> {
    var dv = wrist_dv + cross(wrist_dw, x - link_pos[0]);
    var link = l;
    while (link > 0u) {
        let j = link - 1u;
        let ld = joint_lead(j);
        dv += cross(joint_now[j].axis, x - link_pos[link]) * (ld.mult * joint_now[ld.joint].dqd);
        link = joints[j].parent_link;
    }
    return dv;
}

// physics.rs: hand_mobility. The hand's mobility (1/kg) at x on link l along the unit normal n, and
// summed over all directions: w_u = 1/m_w + |(x − p_w) × u|²/I_w + Σ_L (J_L·u)²/(I_L + h·d_L),
// J_L = Σ_{k in chain, lead(k) = L} m_k · a_k × (x − o_k). Returns (w_n, trace).
fn hand_mobility(l: u32, x: vec3<f32>, n: vec3<f32>, h: f32) -> vec2<f32> {
    let mi = wrist_mass_inertia();
    let r0 = x - link_pos[0];
    let rn = cross(r0, n);
    // the wrist: translation along u, rotation about the wrist
    let wrist_n = 1.0 / mi.x + dot(rn, rn) / mi.y;
    let wrist_tr = 3.0 / mi.x + 2.0 * dot(r0, r0) / mi.y;
    var w_n = wrist_n;
    var w_tr = wrist_tr;
    // no follower on the chain (the common case): every joint is its own coordinate, J_j = a_j × r
    var link = l;
    var coupled = false;
    while (link > 0u) {
        let j = link - 1u;
        if (joints[j].mimic_leader != NO_JOINT) {
            coupled = true;
            break;
        }
        let jac = cross(joint_now[j].axis, x - link_pos[link]);
        let inv_i = 1.0 / joint_impulse_inertia(j, h);
        w_n += dot(jac, n) * dot(jac, n) * inv_i;
        w_tr += dot(jac, jac) * inv_i;
        link = joints[j].parent_link;
    }
    if (!coupled) {
        return vec2<f32>(w_n, w_tr);
    }
    w_n = wrist_n;
    w_tr = wrist_tr;
    link = l;
    while (link > 0u) {
        let j = link - 1u;
        let lj = joint_lead(j).joint;
        // J_L over the whole chain, counted once: at the chain joint nearest the tip that L moves
        var first = true;
        var jac = vec3<f32>(0.0);
        var k_link = l;
        while (k_link > 0u) {
            let k = k_link - 1u;
            let lk = joint_lead(k);
            if (lk.joint == lj) {
                if (k_link > link) {
                    first = false;
                }
                jac += cross(joint_now[k].axis, x - link_pos[k_link]) * lk.mult;
            }
            k_link = joints[k].parent_link;
        }
        if (first) {
            let inv_i = 1.0 / joint_impulse_inertia(lj, h);
            w_n += dot(jac, n) * dot(jac, n) * inv_i;
            w_tr += dot(jac, jac) * inv_i;
        }
        link = joints[j].parent_link;
    }
    return vec2<f32>(w_n, w_tr);
}

// physics.rs: hand_contact_force. A hand contact's force, solved implicitly on the hand's side:
// Fn = (k·d − K·(vrel + dv)·n) / (1 + h·w_n·K),  Ft = −(kt·s + Kt·(vrel + dv)t) / (1 + h·w_t·Kt),
// K = k·h + c, Kt = kt·h + c, Ft limited to μ·Fn.
fn hand_contact_force(c: Contact, vrel: vec3<f32>, dv: vec3<f32>, anchor: vec3<f32>, k: f32, kt: f32, damp: f32, mu: f32, h: f32, w_n: f32, w_t: f32) -> HandContactForce {
    let n = c.normal;
    let vp = vrel + dv;
    let vn = dot(vp, n);
    let kn = k * h + damp;
    // Fn = (k·d − K·vn) / (1 + h·w_n·K)
    let fn_ = max((k * c.depth - kn * vn) / (1.0 + h * w_n * kn), 0.0);
    if (fn_ <= 0.0) {
        return HandContactForce(vec3<f32>(0.0), vec3<f32>(0.0), 0.0, 0.0);
    }
    let a = kn / (1.0 + h * w_n * kn);
    // spring kept in the tangent plane, stretched by the slip now: s ← s − (s·n)n + vt h
    let vt_now = vrel - n * dot(vrel, n);
    let spring = anchor - n * dot(anchor, n) + vt_now * h;
    let vt = vp - n * vn;
    let ktn = kt * h + damp;
    // Ft = −(kt·s + Kt·vt) / (1 + h·w_t·Kt)
    let ft = -(spring * kt + vt * ktn) / (1.0 + h * w_t * ktn);
    let b_stick = ktn / (1.0 + h * w_t * ktn);
    let ft_len = length(ft);
    let limit = mu * fn_;
    if (ft_len > limit) {
        // sliding: the friction force sits on the cone and the spring carries it
        let f_slide = ft * (limit / ft_len);
        let vt_len = length(vt);
        let b = select(b_stick, min(limit / vt_len, b_stick), vt_len > 1e-6);
        return HandContactForce(n * fn_ + f_slide, -f_slide / kt, a, b);
    }
    return HandContactForce(n * fn_ + ft, spring, a, b_stick);
}

fn apply_object_torque(tq: vec3<f32>, n: vec3<f32>, b: f32) {
    obj_t += tq;
    for (var row = 0u; row < 3u; row++) {
        for (var col = 0u; col < 3u; col++) {
            obj_d[(3u + row) * 6u + 3u + col] += b * n[row] * n[col];
        }
    }
}

// physics.rs: apply_object_spread. A manifold's resistance to turning e into the object's implicit
// damping, and its linearisation E·dw into its torque
fn apply_object_spread(e: array<vec3<f32>, 3>, dw: vec3<f32>) {
    obj_t += e[0] * dw.x + e[1] * dw.y + e[2] * dw.z;
    for (var col = 0u; col < 3u; col++) {
        for (var row = 0u; row < 3u; row++) {
            obj_d[(3u + row) * 6u + 3u + col] += e[col][row];
        }
    }
}

// f at x on the object (centre of mass com), and Σ JᵀDJ with D = a nnᵀ + b (I − nnᵀ), J = [I, −[r]×]
fn apply_object_force(com: vec3<f32>, x: vec3<f32>, f: vec3<f32>, n: vec3<f32>, a: f32, b: f32) {
    let r = x - com;
    obj_f += f;
    obj_t += cross(r, f);
    var dm: array<vec3<f32>, 3>;
    for (var i = 0u; i < 3u; i++) {
        var e = vec3<f32>(0.0);
        e[i] = 1.0;
        dm[i] = e * b + n * ((a - b) * n[i]);
    }
    // A_vv = D, A_vw = −D[r]×, A_wv = [r]× D, A_ww = −[r]× D [r]×
    for (var i = 0u; i < 3u; i++) {
        var e = vec3<f32>(0.0);
        e[i] = 1.0;
        let d_col = dm[i];
        let rd_col = cross(r, d_col);
        let rxe = cross(r, e);
        let drx_col = dm[0] * rxe.x + dm[1] * rxe.y + dm[2] * rxe.z;
        let rdrx_col = cross(r, drx_col);
        for (var row = 0u; row < 3u; row++) {
            obj_d[row * 6u + i] += d_col[row];
            obj_d[row * 6u + 3u + i] -= drx_col[row];
            obj_d[(3u + row) * 6u + i] += rd_col[row];
            obj_d[(3u + row) * 6u + 3u + i] -= rdrx_col[row];
        }
    }
}

// physics.rs: solve_hand_contact. Hand contact c on link l against a body whose contact point moves
// at v_other, spring slot `slot` (xyz: the tangential spring, w: 1 while the pair touches); the
// force is applied to the hand for the contacts after.
fn solve_hand_contact(slot: u32, l: u32, c: Contact, v_other: vec3<f32>, damp: f32, mu: f32, h: f32) -> HandContactForce {
    let cf = solve_hand_contact_from(springs[slot].xyz, l, c, v_other, damp, mu, h);
    springs[slot] = hand_spring_after(c, cf);
    return cf;
}

// physics.rs: solve_hand_contact_from. solve_hand_contact from the tangential spring `anchor`,
// leaving the spring slots alone (cf.spring: the spring it leaves)
fn solve_hand_contact_from(anchor: vec3<f32>, l: u32, c: Contact, v_other: vec3<f32>, damp: f32, mu: f32, h: f32) -> HandContactForce {
    let vrel = link_point_velocity(l, c.point) - v_other;
    let dv = hand_point_velocity_change(l, c.point);
    let w = hand_mobility(l, c.point, c.normal, h);
    // a manifold of point springs in parallel: their stiffness, friction spring and damping add up
    let n_s = c.spring_count;
    let cf = hand_contact_force(c, vrel, dv, anchor, g.hand_contact_k * n_s, g.hand_contact_kt * n_s, damp * n_s, mu, h, w.x, w.y - w.x);
    if (dot(cf.force, c.normal) > 0.0) {
        apply_hand_force(l, c.point, cf.force, h);
    }
    return cf;
}

// physics.rs: hand_spring_after. What a hand contact's spring slot keeps once contact c is solved
// to cf: the spring while it pushes (w: 1); else none, still flagged as touching where c is in
fn hand_spring_after(c: Contact, cf: HandContactForce) -> vec4<f32> {
    if (dot(cf.force, c.normal) > 0.0) {
        return vec4<f32>(cf.spring, 1.0);
    }
    return vec4<f32>(0.0, 0.0, 0.0, select(0.0, 1.0, c.depth > 0.0));
}

// physics.rs: hand_object_force. The object's side of hand–object contact c of collider ci (the
// hand's solve cf), its torsional friction against the object's spin w_obj, and the statistics;
// dv_point, dw: the predicted velocities' distance from the present ones (the force is
// linearised about the predicted ones). (The penetration statistics: contacts_and_forces.)
fn hand_object_force(ci: u32, c: Contact, cf: HandContactForce, ocom: vec3<f32>, w_obj: vec3<f32>, dv_point: vec3<f32>, dw: vec3<f32>, mu: f32, h: f32) {
    let l = colliders[ci].link;
    let n = c.normal;
    let fn_ = dot(cf.force, n);
    if (fn_ > 0.0) {
        // D·δv with D = a nnᵀ + b (I − nnᵀ)
        let dvn = dot(dv_point, n);
        let lin = n * (cf.ndamp * dvn) + (dv_point - n * dvn) * cf.tdamp;
        apply_object_force(ocom, c.point, lin - cf.force, n, cf.ndamp, cf.tdamp);
        if (c.spring_count > 1.0) {
            // a manifold's points resist the object's turning about their centre: + E·δω
            apply_object_spread(spread_matrix(c.spread_diag, c.spread_off, n, cf.ndamp, cf.tdamp), dw);
        }
        let tor = torsion_torque(n, link_w[l] - w_obj, fn_, mu, g.torsion_radius);
        apply_hand_torque(l, tor.torque, h);
        apply_object_torque(n * (tor.damping * dot(n, dw)) - tor.torque, n, tor.damping);
        if (n_reactions < MAX_REACTIONS) {
            reactions[n_reactions] = Reaction(l, ci, vec4<f32>(c.point, c.depth), vec4<f32>(n, cf.ndamp), vec4<f32>(dv_point, cf.tdamp), vec4<f32>(dw, tor.damping), vec4<f32>(c.spread_diag, c.spring_count), c.spread_off);
            n_reactions += 1u;
        }
        link_contact[l / 32u] |= 1u << (l % 32u);
        let tip = colliders[ci].tip;
        if (tip != NO_JOINT) {
            tip_force[tip] += fn_;
        }
    }
    if (fn_ > 0.0 || c.depth > 0.0) {
        n_contacts += 1u;
        n_contacts_ho += 1u;
    }
}

// next_in_list's answer for an empty list
const NO_COLLIDER: u32 = 0xffffffffu;

// physics.rs: next_in_list. The first collider of bit list `list` (bit ci % 32 of word ci / 32)
// from word `word` on, taken off the list (`word` left at its word); NO_COLLIDER once it is empty.
fn next_in_list(list: ptr<function, array<u32, REVISIT_WORDS>>, word: ptr<function, u32>) -> u32 {
    while (*word < REVISIT_WORDS && (*list)[*word] == 0u) {
        *word += 1u;
    }
    if (*word >= REVISIT_WORDS) {
        return NO_COLLIDER;
    }
    let bits = (*list)[*word];
    // the lowest bit cleared
    (*list)[*word] = bits & (bits - 1u);
    return *word * 32u + firstTrailingBit(bits);
}

// physics.rs: contacts_and_forces, then arriving_contacts and the object's velocity change
// (substep). Every contact of the substep and the object's velocities at its end.
//
// The hand–object narrow phases are not run where each pair is solved, one env per invocation:
// a warp runs a branch when any of its envs takes it, so walking each env's own pairs it ran as
// many narrow phases as its busiest env had, and both the palm box's and the capsules' code in
// most of them (BENCHMARKS.md "Each env's own list of queries"). Each pass instead posts its
// queries (narrow_rounds.wgsl: post_query), the workgroup shares out all of its envs' queries
// of the pass over its invocations, the box colliders' first (narrow_phase_round), and each env
// then solves its pairs in the order physics.rs does with the contacts found (query_contact).
// Four rounds a substep: the first pass's pairs at the substep's poses, their swept searches,
// the second pass's swept searches, the arriving pass's; each query has the arguments and the
// arithmetic physics.rs gives it, so the contacts are its. Every invocation of the workgroup
// reaches each round (an env past the batch, `in_batch` false, posts none), and the env's own work
// between them is behind `in_batch`.
fn contacts_and_forces(h: f32) -> ObjectVelocity {
    let k = g.contact_k;
    let kt = g.contact_kt;
    // the object's velocities are those of its centre of mass
    let ocom = object_com();
    let ovel = st.obj_vel.xyz;
    let ow = st.obj_angvel.xyz;
    let mu_ho = 0.5 * (prm.hand_friction + prm.obj_friction);
    let mu_ht = 0.5 * (prm.hand_friction + prm.table_friction);
    let mu_ot = 0.5 * (prm.obj_friction + prm.table_friction);
    let opos = st.obj_pos.xyz;
    let orot = st.obj_rot;
    let obj = ObjectShape(prm.obj_index, prm.obj_scale, prm.obj_com.w);
    // the colliders near the object (near_obj) or the table (near_tab), the rest's springs cleared
    var near_obj: array<u32, REVISIT_WORDS>;
    var near_tab: array<u32, REVISIT_WORDS>;
    // the first pass's pairs whose swept search runs (swept), the second pass's (swept2), the
    // arriving pass's (arriving_list)
    var swept: array<u32, REVISIT_WORDS>;
    var swept2: array<u32, REVISIT_WORDS>;
    var arriving_list: array<u32, REVISIT_WORDS>;
    // hand–object pairs within the margin that did not push: solved again once the object's
    // velocity this substep is predicted (bit ci % 32 of word ci / 32). Their contacts at the
    // substep's poses are the first round's, kept in its slots (physics.rs keeps the first
    // REVISIT_CACHE of them and finds the rest again: the same contacts)
    var revisit: array<u32, REVISIT_WORDS>;
    var any_revisit = false;
    // the object's predicted (pred) and solved (u) velocities at the end of the substep, and its
    // frame at the end of the substep for them (pend, uend)
    var pred = ObjectVelocity(vec3<f32>(0.0), vec3<f32>(0.0));
    var pend = ObjectFrame(opos, orot);
    var u = pred;
    var n0 = 0u;
    // one call site of the rounds (a driver inlines the narrow phase at each): stage s solves
    // the pairs of the rounds before it and posts the queries of round s, stage 4 the last
    // solves; every invocation runs each stage (an env past the batch only its rounds)
    for (var stage = 0u; stage < 5u; stage++) {
        if (in_batch) {
            // whether the stage needs the object's velocity change solved
            var solve_object = false;
            switch stage {
                case 0u: {
                    for (var ci = 0u; ci < g.n_colliders; ci++) {
                        let cd = colliders[ci];
                        let r_c = bounding_radius(cd.shape, cd.size.xyz);
                        let cpos = collider_centre(ci);
                        let margin = speculative_margin_at(ci, cpos, h, ocom, ovel, ow);
                        let bit = 1u << (ci % 32u);
                        if (object_in_reach(cd, cpos, opos, margin, obj.radius)) {
                            near_obj[ci / 32u] |= bit;
                            // the pair's query at the substep's poses (the collider's pose once for
                            // the margin, the narrow phase, the swept search and the table)
                            let cp = collider_pose(ci);
                            post_query(0u, ci, cp, ObjectFrame(opos, orot), speculative_margin_at(ci, cp.pos, h, ocom, ovel, ow));
                        } else {
                            springs[spring_base + ci] = vec4<f32>(0.0);
                        }
                        // the collider's lowest point is at least r_c below its centre: a 1 mm
                        // allowance over the margin for the rounding of collide_hand_table_at
                        if (g.hand_table != 0u && cpos.z <= r_c + CONTACT_MARGIN + 1.0e-3) {
                            near_tab[ci / 32u] |= bit;
                        } else if (g.hand_table != 0u) {
                            springs[spring_base + g.n_colliders + ci] = vec4<f32>(0.0);
                        }
                    }
                }
                case 1u: {
                    // the first pass's swept searches: below, at the call site they share with
                    // the second pass's
                }
                case 2u: {
                    // the first pass: the colliders of either list, in order
                    var jobs: array<u32, REVISIT_WORDS>;
                    for (var w = 0u; w < REVISIT_WORDS; w++) {
                        jobs[w] = near_obj[w] | near_tab[w];
                    }
                    var word = 0u;
                    loop {
                        let ci = next_in_list(&jobs, &word);
                        if (ci == NO_COLLIDER) {
                            break;
                        }
                        let bit = 1u << (ci % 32u);
                        let l = colliders[ci].link;
                        // hand–object: a touching pair, or one apart by less than the speculative
                        // margin (at the end of the substep where the object's turn brings a
                        // feature in elsewhere)
                        if ((near_obj[ci / 32u] & bit) != 0u) {
                            let raw = query_contact(0u, ci);
                            let margin = query_margin(0u, ci);
                            var c = raw;
                            if ((swept[ci / 32u] & bit) != 0u) {
                                let t = swept_test(ci, raw, h, ocom, ovel, ow);
                                let found = query_contact(1u, ci);
                                if (found.depth > -1.0 && found.depth > t.c_end + SWEPT_TOLERANCE) {
                                    c = swept_contact_from_end(l, found, h, ocom, ovel, ow);
                                }
                            }
                            // the statistics' penetration: the pair's overlap at the substep's
                            // poses, not a swept contact's depth (physics.rs)
                            max_pen_ho = max(max_pen_ho, raw.depth);
                            max_pen = max(max_pen, raw.depth);
                            if (c.depth > -margin) {
                                let cf = solve_hand_contact(spring_base + ci, l, c, ovel + cross(ow, c.point - ocom), prm.obj_contact_c, mu_ho, h);
                                if (dot(cf.force, c.normal) > 0.0) {
                                    hand_object_force(ci, c, cf, ocom, ow, vec3<f32>(0.0), vec3<f32>(0.0), mu_ho, h);
                                } else {
                                    revisit[ci / 32u] |= bit;
                                    any_revisit = true;
                                }
                            } else {
                                springs[spring_base + ci] = vec4<f32>(0.0);
                            }
                        }
                        // hand–table
                        if ((near_tab[ci / 32u] & bit) != 0u) {
                            let c2 = collide_hand_table_at(ci, collider_pose(ci));
                            if (c2.depth > -CONTACT_MARGIN) {
                                let cf = solve_hand_contact(spring_base + g.n_colliders + ci, l, c2, vec3<f32>(0.0), prm.hand_table_c, mu_ht, h);
                                if (dot(cf.force, c2.normal) > 0.0 || c2.depth > 0.0) {
                                    n_contacts += 1u;
                                    max_pen = max(max_pen, c2.depth);
                                }
                            } else {
                                springs[spring_base + g.n_colliders + ci] = vec4<f32>(0.0);
                            }
                        }
                    }
                    // object–table: every support point of every piece, in order (spring slots 0..
                    // of the object); a piece whose bounding sphere is above the table has none
                    // touching (its springs are cleared)
                    let od = objects[prm.obj_index];
                    var kp = 0u;
                    let above = st.obj_pos.z > prm.obj_com.w;
                    for (var pi = 0u; pi < od.n_pieces; pi++) {
                        let pd = pieces[od.first_piece + pi];
                        var pp = PiecePose(vec3<f32>(0.0, 0.0, 1.0), vec4<f32>(0.0, 0.0, 0.0, 1.0), vec3<f32>(0.0));
                        if (!above) {
                            pp = piece_pose(pd);
                        }
                        if (above || pp.pos.z > pd.pos.w * prm.obj_scale) {
                            for (var j = 0u; j < pd.n_support; j++) {
                                springs[spring_base + 2u * g.n_colliders + kp] = vec4<f32>(0.0);
                                kp += 1u;
                            }
                            continue;
                        }
                        for (var j = 0u; j < pd.n_support; j++) {
                            let ki = spring_base + 2u * g.n_colliders + kp;
                            kp += 1u;
                            let c = collide_piece_table(pd, prm.obj_scale, pp.size, pp.pos, pp.rot, j);
                            if (c.depth > 0.0) {
                                let vo = ovel + cross(ow, c.point - ocom);
                                let cf = contact_force(c, vo, springs[ki].xyz, k, kt, prm.obj_contact_c, mu_ot, h);
                                springs[ki] = vec4<f32>(cf.spring, 1.0);
                                let a = select(0.0, k * h + prm.obj_contact_c, dot(cf.force, c.normal) > 0.0);
                                apply_object_force(ocom, c.point, cf.force, c.normal, a, cf.tdamp);
                                let tor = torsion_torque(c.normal, ow, dot(cf.force, c.normal), mu_ot, g.torsion_radius);
                                apply_object_torque(tor.torque, c.normal, tor.damping);
                                n_contacts += 1u;
                                max_pen = max(max_pen, c.depth);
                            } else {
                                springs[ki] = vec4<f32>(0.0);
                            }
                        }
                    }
                    // the second pass needs the object's predicted velocities
                    solve_object = any_revisit;
                }
                default: {
                    // stage 3: the second pass's pairs (those revisited, in collider order, against
                    // the predicted velocities); stage 4: the arriving pass's (in the order they
                    // pushed, against the solved ones). One loop for both, so that the kernel holds
                    // one copy of the solve (a driver inlines one at each call)
                    let arriving = stage == 4u;
                    var vel = pred.vel;
                    var w = pred.w;
                    if (arriving) {
                        vel = u.vel;
                        w = u.w;
                    }
                    var any_push = false;
                    var list = revisit;
                    var word = 0u;
                    var i = 0u;
                    loop {
                        // the pair's collider, its contact before the search (the first round's, or
                        // the one it pushed with) and whether a round searched it
                        var ci = 0u;
                        var base: Contact;
                        var searched = false;
                        if (!arriving) {
                            ci = next_in_list(&list, &word);
                            if (ci == NO_COLLIDER) {
                                break;
                            }
                            base = query_contact(0u, ci);
                            searched = (swept2[ci / 32u] & (1u << (ci % 32u))) != 0u;
                        } else {
                            if (i >= n0) {
                                break;
                            }
                            let r = reactions[i];
                            i++;
                            ci = r.collider;
                            if ((arriving_list[ci / 32u] & (1u << (ci % 32u))) == 0u) {
                                continue;
                            }
                            base = contact_at(r.point.w, r.normal.xyz, r.point.xyz);
                            searched = true;
                        }
                        let l = colliders[ci].link;
                        var c = base;
                        if (searched) {
                            let t = swept_test(ci, base, h, ocom, vel, w);
                            let found = query_contact(1u, ci);
                            // an arriving feature that would not be touching by the end of the
                            // substep needs no contact
                            if (arriving && found.depth <= 0.0) {
                                continue;
                            }
                            let se = swept_end_contact(l, found, t.c_end, h, ocom, vel, w);
                            if (se.found) {
                                c = se.c;
                            } else if (arriving) {
                                continue;
                            }
                        }
                        let v_other = vel + cross(w, c.point - ocom);
                        // an arriving contact has no friction spring (it starts from none and keeps
                        // none)
                        var anchor = vec3<f32>(0.0);
                        if (!arriving) {
                            anchor = springs[spring_base + ci].xyz;
                        }
                        let cf = solve_hand_contact_from(anchor, l, c, v_other, prm.obj_contact_c, mu_ho, h);
                        if (!arriving) {
                            springs[spring_base + ci] = hand_spring_after(c, cf);
                        }
                        // the object's force linearised about the velocities the pair was solved
                        // against: + D·J·(u_p − u₀)
                        let dv_point = (vel - ovel) + cross(w - ow, c.point - ocom);
                        hand_object_force(ci, c, cf, ocom, w, dv_point, w - ow, mu_ho, h);
                        any_push = any_push || dot(cf.force, c.normal) > 0.0;
                    }
                    // the object's velocities at the end of the substep: after the second pass its
                    // prediction when none of its pairs pushed (nothing the implicit solve reads
                    // has changed since); after the arriving pass solved again where one of its
                    // pushed
                    solve_object = any_push;
                    if (!arriving) {
                        u = pred;
                        solve_object = !any_revisit || any_push;
                    }
                }
            }
            // the object's velocity change, one call site (a driver inlines a copy of the 6 × 6
            // solve at each): stage 2's prediction for the second pass, stages 3's and 4's
            if (solve_object) {
                let v = object_velocity_change(h);
                if (stage == 2u) {
                    pred = v;
                } else {
                    u = v;
                }
            }
            if (stage == 1u || (stage == 2u && any_revisit)) {
                // the swept searches, one call site (a driver inlines the test and the posting at
                // each): where the object's turn may bring a feature deeper than the pair's own
                // contact would be by the end of the substep, the pair at the end of the substep.
                // Stage 1: the first pass's pairs near the object, for the object's velocities at
                // the start of the substep; stage 2: the second pass's (physics.rs:
                // contacts_and_forces: the pairs that did not push, against the object's velocity
                // at the end of the substep as the forces so far make it), for those
                var vel = ovel;
                var w = ow;
                var list = near_obj;
                if (stage == 2u) {
                    vel = pred.vel;
                    w = pred.w;
                    list = revisit;
                }
                let end = object_frame_at_end(h, ocom, vel, w);
                var searched: array<u32, REVISIT_WORDS>;
                var word = 0u;
                loop {
                    let ci = next_in_list(&list, &word);
                    if (ci == NO_COLLIDER) {
                        break;
                    }
                    let t = swept_test(ci, query_contact(0u, ci), h, ocom, vel, w);
                    if (t.search) {
                        searched[ci / 32u] |= 1u << (ci % 32u);
                        post_query(1u, ci, collider_pose_at_end(colliders[ci].link, collider_pose(ci), h), end, query_margin(0u, ci));
                    }
                }
                if (stage == 1u) {
                    swept = searched;
                } else {
                    pend = end;
                    swept2 = searched;
                }
            }
            if (stage == 3u) {
                // the arriving pass (physics.rs: arriving_contacts): the pairs that pushed before
                // it whose solved spin differs enough from the one they were found with (the
                // features' order by depth at the end of the substep changes with the object's
                // turn alone, by at most h·2r·|Δω|) and whose swept test against u passes,
                // searched at the end of the substep for u. A collider pushes once a substep, so
                // each has one slot
                n0 = n_reactions;
                var have_uend = false;
                var uend = pend;
                for (var k = 0u; k < n0; k++) {
                    let r = reactions[k];
                    let cj = r.collider;
                    let cd = colliders[cj];
                    if (h * 2.0 * bounding_radius(cd.shape, cd.size.xyz) * length((u.w - ow) - r.dw0.xyz) > SWEPT_TOLERANCE) {
                        let t = swept_test(cj, contact_at(r.point.w, r.normal.xyz, r.point.xyz), h, ocom, u.vel, u.w);
                        if (t.search) {
                            if (!have_uend) {
                                uend = object_frame_at_end(h, ocom, u.vel, u.w);
                                have_uend = true;
                            }
                            arriving_list[cj / 32u] |= 1u << (cj % 32u);
                            post_query(1u, cj, collider_pose_at_end(cd.link, collider_pose(cj), h), uend, CONTACT_MARGIN);
                        }
                    }
                }
            }
        }
        if (stage < 4u) {
            // the round's colliders: those whose queries the stage posted
            var posted = near_obj;
            if (stage == 1u) {
                posted = swept;
            } else if (stage == 2u) {
                posted = swept2;
            } else if (stage == 3u) {
                posted = arriving_list;
            }
            narrow_phase_round(select(1u, 0u, stage == 0u), posted);
        }
    }
    return u;
}

// The servos' part of the substep, before the contacts (physics.rs: hand_servo): each independent
// joint's velocity change from its servo, the wrist's from its controller.
fn hand_servo(h: f32) {
    let n = g.n_joints;
    for (var j = 0u; j < n; j++) {
        let jd = joints[j];
        joint_now[j].dqd = 0.0;
        if (jd.mimic_leader != NO_JOINT) {
            continue;
        }
        let lo = jd.lower * prm.limit_scale;
        let hi = jd.upper * prm.limit_scale;
        let inertia = jd.armature + jd.link_inertia * prm.hand_mass_scale;
        let qd = st.qd[j];
        let goal = clamp(tg.q[j], lo, hi);
        // τ_pd = clamp(kp (q* − q) − kd q̇, ±effort)
        let tau_pd = clamp(jd.kp * prm.kp_scale * (goal - st.q[j]) - jd.kd * prm.kd_scale * qd, -jd.effort, jd.effort);
        // Coulomb friction, regularised over 0.01 rad/s
        let tau_f = -jd.friction * clamp(qd / 0.01, -1.0, 1.0);
        // joint damping implicit: q̇' = (q̇ + h τ / I) / (1 + h d / I)
        joint_now[j].dqd = (qd + h * (tau_pd + tau_f) / inertia) / (1.0 + h * jd.damping * prm.kd_scale / inertia) - qd;
    }
    // wrist: F = clamp(kp (p* − p) − kd v, Fmax); the hand's weight is compensated
    let mi = wrist_mass_inertia();
    let vel = st.wrist_vel.xyz;
    let w = st.wrist_angvel.xyz;
    let f_pd = clamp_norm(g.wrist_kp_lin * (tg.wrist_pos.xyz - st.wrist_pos.xyz) - g.wrist_kd_lin * vel, g.wrist_force_limit);
    let t_pd = clamp_norm(g.wrist_kp_rot * quat_error(tg.wrist_rot, st.wrist_rot) - g.wrist_kd_rot * w, g.wrist_torque_limit);
    wrist_dv = f_pd * (h / mi.x);
    wrist_dw = t_pd * (h / mi.y);
}

// physics.rs: integrate_hand. Velocities change by dqd, wrist_dv, wrist_dw (servos and contacts);
// then the speed and position limits, positions, followers.
fn integrate_hand(h: f32) {
    let n = g.n_joints;
    for (var j = 0u; j < n; j++) {
        let jd = joints[j];
        if (jd.mimic_leader != NO_JOINT) {
            continue;
        }
        let lo = jd.lower * prm.limit_scale;
        let hi = jd.upper * prm.limit_scale;
        var qd = clamp(st.qd[j] + joint_now[j].dqd, -jd.velocity, jd.velocity);
        var qn = st.q[j] + h * qd;
        if (qn < lo) {
            qn = lo;
            qd = max(qd, 0.0);
        }
        if (qn > hi) {
            qn = hi;
            qd = min(qd, 0.0);
        }
        st.q[j] = qn;
        st.qd[j] = qd;
    }
    for (var j = 0u; j < n; j++) {
        let jd = joints[j];
        if (jd.mimic_leader != NO_JOINT) {
            let l = jd.mimic_leader;
            st.q[j] = jd.mimic_mult * st.q[l] + jd.mimic_offset;
            st.qd[j] = jd.mimic_mult * st.qd[l];
        }
    }
    let vel_n = st.wrist_vel.xyz + wrist_dv;
    let w_n = st.wrist_angvel.xyz + wrist_dw;
    st.wrist_vel = vec4<f32>(vel_n, 0.0);
    st.wrist_angvel = vec4<f32>(w_n, 0.0);
    st.wrist_pos = vec4<f32>(st.wrist_pos.xyz + vel_n * h, 0.0);
    st.wrist_rot = quat_integrate(st.wrist_rot, w_n, h);
}

fn solve6(a: array<f32, 36>, b: array<f32, 6>) -> array<f32, 6> {
    var l: array<f32, 36>;
    for (var i = 0u; i < 6u; i++) {
        for (var j = 0u; j <= i; j++) {
            var sum = a[i * 6u + j];
            for (var k = 0u; k < j; k++) {
                sum -= l[i * 6u + k] * l[j * 6u + k];
            }
            if (i == j) {
                l[i * 6u + i] = sqrt(max(sum, 1e-20));
            } else {
                l[i * 6u + j] = sum / l[j * 6u + j];
            }
        }
    }
    var y: array<f32, 6>;
    for (var i = 0u; i < 6u; i++) {
        var sum = b[i];
        for (var k = 0u; k < i; k++) {
            sum -= l[i * 6u + k] * y[k];
        }
        y[i] = sum / l[i * 6u + i];
    }
    var x: array<f32, 6>;
    for (var ii = 0u; ii < 6u; ii++) {
        let i = 5u - ii;
        var sum = y[i];
        for (var k = i + 1u; k < 6u; k++) {
            sum -= l[k * 6u + i] * x[k];
        }
        x[i] = sum / l[i * 6u + i];
    }
    return x;
}

// R diag(ib) Rᵀ: column c is Σₖ ibₖ (rₖ)_c rₖ (physics.rs)
fn world_inertia(rot: vec4<f32>, ib: vec3<f32>) -> mat3x3<f32> {
    let r = quat_axes(rot);
    var m: mat3x3<f32>;
    for (var c = 0u; c < 3u; c++) {
        m[c] = r[0] * (ib.x * r[0][c]) + r[1] * (ib.y * r[1][c]) + r[2] * (ib.z * r[2][c]);
    }
    return m;
}

// the object's velocities at the end of the substep (object_velocity_change)
struct ObjectVelocity {
    vel: vec3<f32>,
    w: vec3<f32>,
}

// physics.rs: object_velocity_change. The object's velocities at the end of the substep under gravity
// and the contact forces so far, linearly implicit: (M + h Σ JᵀDJ) Δu = h f.
fn object_velocity_change(h: f32) -> ObjectVelocity {
    let mass = prm.obj_inertia.w;
    let ib = prm.obj_inertia.xyz;
    let rot = st.obj_rot;
    // the principal frame in the world: R_obj R_principal
    let prot = quat_mul(rot, objects[prm.obj_index].principal_rot);
    let com = object_com();
    let w = st.obj_angvel.xyz;
    // gyroscopic: ω ← ω − h I⁻¹ (ω × Iω), rescaled so that ωᵀIω is unchanged
    let inertia = world_inertia(prot, ib);
    let iw = inertia * w;
    let e0 = dot(w, iw);
    var wg = w - h * (world_inertia(prot, 1.0 / ib) * cross(w, iw));
    let e1 = dot(wg, inertia * wg);
    if (e1 > 1e-20) {
        wg *= sqrt(e0 / e1);
    }
    // A = M + h Σ JᵀDJ
    var a: array<f32, 36>;
    for (var i = 0u; i < 36u; i++) {
        a[i] = h * obj_d[i];
    }
    for (var i = 0u; i < 3u; i++) {
        a[i * 6u + i] += mass;
        let col = inertia[i];
        for (var row = 0u; row < 3u; row++) {
            a[(3u + row) * 6u + 3u + i] += col[row];
        }
    }
    let gz = -(g.gravity + prm.added_gravity) * mass;
    // the external force at its point of the object, and its moment about the centre of mass
    let ext = prm.ext_force.xyz;
    let at = st.obj_pos.xyz + quat_rotate(rot, prm.ext_point.xyz);
    let f = obj_f + ext + vec3<f32>(0.0, 0.0, gz);
    let tq = obj_t + cross(at - com, ext);
    let du = solve6(a, array<f32, 6>(h * f.x, h * f.y, h * f.z, h * tq.x, h * tq.y, h * tq.z));
    return ObjectVelocity(st.obj_vel.xyz + vec3<f32>(du[0], du[1], du[2]), wg + vec3<f32>(du[3], du[4], du[5]));
}

// The hand's side of the object's implicit solve (physics.rs: react_to_object_motion): each pushing
// pair's link takes D·(J·Δu − δv₀) at the contact point and b_r·n·(n·Δω − n·δω₀) about the normal
fn react_to_object_motion(u: ObjectVelocity, h: f32) {
    let com = object_com();
    let dv = u.vel - st.obj_vel.xyz;
    let dw = u.w - st.obj_angvel.xyz;
    for (var i = 0u; i < n_reactions; i++) {
        let r = reactions[i];
        let x = r.point.xyz;
        let l = r.link;
        let n = r.normal.xyz;
        // J·Δu − δv₀: the contact point's velocity change past the one linearised about
        let du = dv + cross(dw, x - com) - r.dv0.xyz;
        let dun = dot(du, n);
        // D·(J·Δu − δv₀) with D = a nnᵀ + b (I − nnᵀ)
        let f = n * (r.normal.w * dun) + (du - n * dun) * r.dv0.w;
        apply_hand_force(l, x, f, h);
        // the torsion's damping: b_r n (n·Δω − n·δω₀)
        var tq = n * (r.dw0.w * (dot(n, dw) - dot(n, r.dw0.xyz)));
        if (r.spread_d.w > 1.0) {
            // a manifold's resistance to the object's turning: E (Δω − δω₀)
            let e = spread_matrix(r.spread_d.xyz, r.spread_o, n, r.normal.w, r.dv0.w);
            let x = dw - r.dw0.xyz;
            tq += e[0] * x.x + e[1] * x.y + e[2] * x.z;
        }
        apply_hand_torque(l, tq, h);
    }
}

// the object's pose from its velocities at the end of the substep (physics.rs: integrate_object)
fn integrate_object(u: ObjectVelocity, h: f32) {
    let vel_n = u.vel;
    let w_n = u.w;
    let com = object_com();
    // the centre of mass moves with v, the frame turns about it: p_obj = com − R c
    let rot_n = quat_integrate(st.obj_rot, w_n, h);
    st.obj_vel = vec4<f32>(vel_n, 0.0);
    st.obj_angvel = vec4<f32>(w_n, 0.0);
    st.obj_pos = vec4<f32>(com + vel_n * h - quat_rotate(rot_n, prm.obj_com.xyz), 0.0);
    st.obj_rot = rot_n;
}

// (every invocation of the workgroup runs it, for contacts_and_forces' rounds; an env past the
// batch does nothing else)
fn substep(h: f32) {
    if (in_batch) {
        hand_kinematics();
        obj_f = vec3<f32>(0.0);
        obj_t = vec3<f32>(0.0);
        for (var i = 0u; i < 36u; i++) {
            obj_d[i] = 0.0;
        }
        n_reactions = 0u;
        hand_servo(h);
    }
    // the contacts and the object's velocities at the end of the substep (with the features its
    // solved motion brings in at the pushing pairs: physics.rs, substep)
    let u = contacts_and_forces(h);
    if (in_batch) {
        react_to_object_motion(u, h);
        integrate_hand(h);
        integrate_object(u, h);
    }
}

fn is_finite3(v: vec3<f32>) -> bool {
    // NaN fails every comparison; ±inf fails the bound
    return all(abs(v) < vec3<f32>(3.0e38));
}

fn state_is_sane() -> bool {
    var ok = is_finite3(st.wrist_pos.xyz) && is_finite3(st.wrist_vel.xyz) && is_finite3(st.wrist_angvel.xyz);
    ok = ok && is_finite3(st.obj_pos.xyz) && is_finite3(st.obj_vel.xyz) && is_finite3(st.obj_angvel.xyz);
    for (var j = 0u; j < g.n_joints; j++) {
        ok = ok && abs(st.q[j]) < 3.0e38 && abs(st.qd[j]) < 3.0e38;
    }
    ok = ok && all(abs(st.wrist_rot) < vec4<f32>(3.0e38)) && all(abs(st.obj_rot) < vec4<f32>(3.0e38));
    ok = ok && length(st.obj_pos.xyz) < g.max_distance && length(st.wrist_pos.xyz) < g.max_distance;
    ok = ok && length(st.obj_vel.xyz) < g.max_speed && length(st.wrist_vel.xyz) < g.max_speed;
    ok = ok && length(st.obj_angvel.xyz) < 100.0 * g.max_speed && length(st.wrist_angvel.xyz) < 100.0 * g.max_speed;
    return ok;
}

fn env_step(env: u32) -> StepStats {
    var out: StepStats;
    let h = g.dt / f32(g.substeps);
    let n_sub = g.decimation * g.substeps;
    for (var i = 0u; i < n_sub; i++) {
        substep(h);
    }
    if (!in_batch) {
        return out;
    }
    st.time += g.dt * f32(g.decimation);
    st.step += 1u;
    for (var i = 0u; i < MAX_TIPS; i++) {
        out.tip_force[i] = tip_force[i] / f32(n_sub);
    }
    out.max_pen_ho = max_pen_ho;
    out.max_pen = max_pen;
    out.contacts = n_contacts;
    out.contacts_ho = n_contacts_ho;
    out.link_contact = link_contact;
    out.table_contact = 0u;
    for (var ci = 0u; ci < g.n_colliders; ci++) {
        if (springs[spring_base + g.n_colliders + ci].w > 0.0) {
            out.table_contact = 1u;
        }
    }
    out.bad_reset = 0u;
    if (!state_is_sane()) {
        let episode = st.episode + 1u;
        let bad = st.bad_resets + 1u;
        prm = reset_params(env, episode);
        st = reset_state(prm, env, episode, bad);
        clear_springs(env);
        out.bad_reset = 1u;
    }
    return out;
}

// Every invocation of the workgroup steps through env_step, an env past the batch too (in_batch
// false): the substeps' narrow-phase rounds (narrow_rounds.wgsl) take the whole workgroup.
@compute @workgroup_size(64)
fn step_main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let env = env_index(gid, nwg);
    lane = lid;
    lane_env = env;
    in_batch = env < g.n_envs;
    find_box_colliders();
    if (in_batch) {
        st = states[env];
        prm = params[env];
        tg = targets[env];
        spring_base = env * g.n_springs;
    }
    let out = env_step(env);
    if (in_batch) {
        states[env] = st;
        params[env] = prm;
        stats[env] = out;
    }
}
