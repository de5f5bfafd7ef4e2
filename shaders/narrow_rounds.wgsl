// narrow_rounds.wgsl — the physics step's hand–object narrow phases shared out over the workgroup.
// GPU only, no CPU twin: physics.rs steps one env at a time and runs each pair's query where it
// solves the pair; the shader posts a pass's queries, runs all of the workgroup's in one round
// (narrow_phase_round) and solves with their contacts (physics.wgsl: contacts_and_forces), the
// same queries with the same arguments, so the same contacts.
//
// Why: one invocation steps one env, and a warp runs a branch when any of its envs takes it.
// Walking each env's own list of pairs, a warp of 32 envs ran as many narrow phases as its
// busiest env had (16.1 a substep on the bench scene, where an env needs 7.9), and most rounds
// ran both the palm box's code (separating axes, clipping, projections) and the finger
// capsules' (BENCHMARKS.md "Each env's own list of queries"). Shared out, a workgroup of 64 envs
// runs its ~500 queries of a substep in about as many rounds as their number over 64, the box
// colliders' queries first so that most warps run one shape's code. The workgroup's size is
// WORKGROUP_SIZE, which the simulator sets by the batch (32 to 512 envs: gpu/shaders.rs,
// step_workgroup_size; as written, 64).

// The queries' slots: per env, two regions (0: the pairs at the substep's poses, kept for the
// whole substep; 1: a pass's swept searches) of n_colliders slots of 4 vec4, one per collider.
// A slot holds the query — (the collider's centre, the margin), its rotation, (the object's
// origin, 0), its rotation — until the round overwrites it with the contact — (normal, depth),
// (point, spring_count), (spread_diag, the margin), (spread_off, 0).
@group(0) @binding(24) var<storage, read_write> narrow_queries: array<vec4<f32>>;

// the invocation's index in its workgroup, its env, and whether that env is in the batch (an
// invocation past the batch takes part in every round and posts no query)
var<private> lane: u32;
var<private> lane_env: u32;
var<private> in_batch: bool;
// the hand's box colliders (bit ci % 32 of word ci / 32): their queries run first in a round
var<private> box_colliders: array<u32, REVISIT_WORDS>;

// each invocation's queries of the round: its box colliders' and its other colliders' bit lists
var<workgroup> wg_boxes: array<array<u32, REVISIT_WORDS>, WORKGROUP_SIZE>;
var<workgroup> wg_others: array<array<u32, REVISIT_WORDS>, WORKGROUP_SIZE>;
// invocation e's first query among the round's box queries, and among the others'; entry
// WORKGROUP_SIZE: their counts
var<workgroup> wg_first_box: array<u32, WORKGROUP_SIZE + 1u>;
var<workgroup> wg_first_other: array<u32, WORKGROUP_SIZE + 1u>;

// the first of the 4 vec4 of collider ci's slot in region `region` of env `env`
fn query_slot(env: u32, region: u32, ci: u32) -> u32 {
    return ((env * 2u + region) * g.n_colliders + ci) * 4u;
}

// the invocation's env's query of collider ci (at cp) against the object at `frame`, within
// margin, into its slot of region `region`
fn post_query(region: u32, ci: u32, cp: ColliderPose, frame: ObjectFrame, margin: f32) {
    let s = query_slot(lane_env, region, ci);
    narrow_queries[s] = vec4<f32>(cp.pos, margin);
    narrow_queries[s + 1u] = cp.rot;
    narrow_queries[s + 2u] = vec4<f32>(frame.pos, 0.0);
    narrow_queries[s + 3u] = frame.rot;
}

// the contact the round found for the invocation's env's query of collider ci in region `region`
fn query_contact(region: u32, ci: u32) -> Contact {
    let s = query_slot(lane_env, region, ci);
    let a = narrow_queries[s];
    let b = narrow_queries[s + 1u];
    var c: Contact;
    c.depth = a.w;
    c.normal = a.xyz;
    c.point = b.xyz;
    c.spring_count = b.w;
    c.spread_diag = narrow_queries[s + 2u].xyz;
    c.spread_off = narrow_queries[s + 3u].xyz;
    return c;
}

// the margin of that query
fn query_margin(region: u32, ci: u32) -> f32 {
    return narrow_queries[query_slot(lane_env, region, ci) + 2u].w;
}

// the box colliders' list (once per invocation, before the first round)
fn find_box_colliders() {
    for (var w = 0u; w < REVISIT_WORDS; w++) {
        box_colliders[w] = 0u;
    }
    for (var ci = 0u; ci < g.n_colliders; ci++) {
        if (colliders[ci].shape == SHAPE_BOX) {
            box_colliders[ci / 32u] |= 1u << (ci % 32u);
        }
    }
}

// the k-th collider (from 0, in order) of bit list `list`
fn kth_in_list(list: array<u32, REVISIT_WORDS>, k: u32) -> u32 {
    var left = k;
    for (var w = 0u; w < REVISIT_WORDS; w++) {
        var bits = list[w];
        let n = countOneBits(bits);
        if (left < n) {
            for (var i = 0u; i < left; i++) {
                // the lowest bit cleared
                bits &= bits - 1u;
            }
            return w * 32u + firstTrailingBit(bits);
        }
        left -= n;
    }
    return NO_COLLIDER;
}

// the invocation e whose queries hold query t of the box colliders' (boxes) or the others':
// first[e] <= t < first[e + 1] for first = wg_first_box or wg_first_other, where first[0] = 0 <=
// t < first[WORKGROUP_SIZE] (WGSL passes no pointer to workgroup memory: the flag picks the array)
fn query_owner(boxes: bool, t: u32) -> u32 {
    var lo = 0u;
    var hi = WORKGROUP_SIZE;
    while (hi - lo > 1u) {
        let mid = (lo + hi) / 2u;
        if (select(wg_first_other[mid], wg_first_box[mid], boxes) <= t) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    return lo;
}

// runs the query in collider ci's slot of region `region` of env `env` and writes its contact
// there (the env's object from `params`: its own invocation's `prm` is not this one's)
fn run_query(env: u32, region: u32, ci: u32) {
    let s = query_slot(env, region, ci);
    let a = narrow_queries[s];
    let rot = narrow_queries[s + 1u];
    let o = narrow_queries[s + 2u];
    let orot = narrow_queries[s + 3u];
    let obj = ObjectShape(params[env].obj_index, params[env].obj_scale, params[env].obj_com.w);
    let c = collide_hand_object_at(ci, ColliderPose(a.xyz, rot), o.xyz, orot, a.w, obj);
    narrow_queries[s] = vec4<f32>(c.normal, c.depth);
    narrow_queries[s + 1u] = vec4<f32>(c.point, c.spring_count);
    narrow_queries[s + 2u] = vec4<f32>(c.spread_diag, a.w);
    narrow_queries[s + 3u] = vec4<f32>(c.spread_off, 0.0);
}

// One round: every invocation of the workgroup calls it at the same point with the colliders
// whose queries it posted in region `region` (`list`); the workgroup's queries, the box
// colliders' first, are shared out over its invocations (query t by invocation t % WORKGROUP_SIZE), and on
// return each invocation's slots hold its contacts. Called in uniform control flow only (its
// barriers).
fn narrow_phase_round(region: u32, list: array<u32, REVISIT_WORDS>) {
    var n_box = 0u;
    var n_other = 0u;
    for (var w = 0u; w < REVISIT_WORDS; w++) {
        let boxes = list[w] & box_colliders[w];
        let others = list[w] & ~box_colliders[w];
        wg_boxes[lane][w] = boxes;
        wg_others[lane][w] = others;
        n_box += countOneBits(boxes);
        n_other += countOneBits(others);
    }
    wg_first_box[lane] = n_box;
    wg_first_other[lane] = n_other;
    // the posted queries and the lists seen by the whole workgroup
    storageBarrier();
    workgroupBarrier();
    if (lane == 0u) {
        // the counts into each invocation's first query (an exclusive prefix sum)
        var sb = 0u;
        var so = 0u;
        for (var e = 0u; e < WORKGROUP_SIZE; e++) {
            let cb = wg_first_box[e];
            wg_first_box[e] = sb;
            sb += cb;
            let co = wg_first_other[e];
            wg_first_other[e] = so;
            so += co;
        }
        wg_first_box[WORKGROUP_SIZE] = sb;
        wg_first_other[WORKGROUP_SIZE] = so;
    }
    workgroupBarrier();
    let total_box = wg_first_box[WORKGROUP_SIZE];
    let total = total_box + wg_first_other[WORKGROUP_SIZE];
    let first_env = lane_env - lane;
    for (var t = lane; t < total; t += WORKGROUP_SIZE) {
        // the query's env (first_env + e) and collider; one call of the narrow phase (each call
        // site is a copy of it in the kernel)
        var e = 0u;
        var ci = 0u;
        if (t < total_box) {
            e = query_owner(true, t);
            ci = kth_in_list(wg_boxes[e], t - wg_first_box[e]);
        } else {
            e = query_owner(false, t - total_box);
            ci = kth_in_list(wg_others[e], t - total_box - wg_first_other[e]);
        }
        run_query(first_env + e, region, ci);
    }
    // the contacts seen by their envs' invocations, and the workgroup's lists free for the next
    // round
    storageBarrier();
    workgroupBarrier();
}
