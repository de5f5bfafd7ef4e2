// Row blocks stacked into one tensor: Tensor::cat(parts, 0) of contiguous f32 tensors [n_k, D]
// into out [Σ n_k, D], several parts per launch (src/learn/kernels/cat_rows.rs), where cat
// launches a copy kernel per part. Launched on burn's command stream (cubecl binds the buffers in
// order, then the launch's constants as a uniform). A template: cat_rows.rs writes in (at the
// markers that begin with a dollar sign) the launch's number of parts, a binding per part and the
// accessor that picks part k's binding by its index. Part k's entries are a contiguous range of
// out's, from its first entry on; each workgroup copies 256 entries of one part.

const CAT_WORKGROUP: u32 = 256u;
// the parts of this launch
const GROUP: u32 = $GROUPu;

struct CatLaunch {
    // per part: (its entries, its first entry in out, its first workgroup, 0)
    parts: array<vec4<u32>, GROUP>,
}

$BINDINGS

$ACCESSORS

@compute @workgroup_size(256, 1, 1)
fn cat_rows(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let w = wid.y * nwg.x + wid.x; // workgroups numbered along x then y
    // the part whose workgroups hold w: the last that starts at or before it (the same for the
    // whole workgroup)
    var k = 0u;
    for (var j = 1u; j < GROUP; j++) {
        if cl.parts[j].z <= w {
            k = j;
        }
    }
    let i = (w - cl.parts[k].z) * CAT_WORKGROUP + lid; // the entry of part k
    if i < cl.parts[k].x {
        cat_out[cl.parts[k].y + i] = cat_part(k, i);
    }
}
