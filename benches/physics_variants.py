#!/usr/bin/env python3
"""Knock-out variants of the simulator's WGSL module, to see where a GPU spends the env step.

    benches/physics_module.sh HEAD > head.wgsl
    benches/physics_variants.py head.wgsl variants/
    VARIANTS_WGSL="$(ls variants/*.wgsl)" benches/gpu_suite.sh --bin ./dextrain   # step "variants"

Each variant is the module with one part of the hand–object contact pass switched off. A part
"never run" keeps its code behind a test on a uniform that is always false at run time
(`g.n_colliders > 1000u`), so the compiler keeps it and its cost is its running alone; a part
"gone" is cut off by an early return, so its code goes too. On the H200 (2026-11-29) the swept
search and the second pass cost by running; on lavapipe (2026-11-30) the narrow phase's code costs
~1.8x by its presence alone (BENCHMARKS.md "Where lavapipe's step goes"). The knock-outs change
the physics (the bench's contacts differ): they time parts, they are not physics to train with.
A "twice" variant runs one part twice, in a loop whose count (2) and whose argument's offset
(0.0) are runtime values, and keeps the last result: the physics is the module's to every digit,
and the time it adds is that part's own (on the H200, 2026-12-01: the narrow phases 24 % of the
env step, BENCHMARKS.md "The GPU window of 2026-12-01").

Exits with status 1, naming the variant, when the module no longer holds the text a variant
patches (the shader changed: this script follows it).
"""

import re
import sys
from pathlib import Path

# a runtime false that no compiler can fold away (the bench scene has 17 colliders)
NEVER = "g.n_colliders > 1000u"
# a runtime 2 and a runtime 0.0 (the "twice" variants)
TWICE = "select(2u, 1u, g.n_colliders > 1000u)"
ZERO = "select(0.0, 1.0, g.n_colliders > 1000u)"

# name -> (what it times, [(text in the module, its replacement)])
VARIANTS = {
    "no_hand_object": (
        "the hand-object pairs never queried (their code kept): the rest of the env step",
        [("                        if (object_in_reach(cd, cpos, opos, margin, obj.radius)) {\n                            near_obj[ci / 32u] |= bit;",
          f"                        if (object_in_reach(cd, cpos, opos, margin, obj.radius) && {NEVER}) {{\n                            near_obj[ci / 32u] |= bit;")],
    ),
    "no_hand_object_code": (
        "the hand-object pairs never queried and the narrow phase's code gone",
        [("                        if (object_in_reach(cd, cpos, opos, margin, obj.radius)) {\n                            near_obj[ci / 32u] |= bit;",
          f"                        if (object_in_reach(cd, cpos, opos, margin, obj.radius) && {NEVER}) {{\n                            near_obj[ci / 32u] |= bit;"),
         ("fn collide_hand_object_at(ci: u32, cp: ColliderPose, opos: vec3<f32>, orot: vec4<f32>, margin: f32, obj: ObjectShape) -> Contact {\n",
          "fn collide_hand_object_at(ci: u32, cp: ColliderPose, opos: vec3<f32>, orot: vec4<f32>, margin: f32, obj: ObjectShape) -> Contact {\n"
          "    return contact_at(-1.0, vec3<f32>(0.0, 0.0, 1.0), opos);\n")],
    ),
    "no_swept_search": (
        "the first pass's swept searches never run",
        [("                    let t = swept_test(ci, query_contact(0u, ci), h, ocom, vel, w);\n                    if (t.search) {",
          f"                    let t = swept_test(ci, query_contact(0u, ci), h, ocom, vel, w);\n                    if (t.search && (stage == 2u || {NEVER})) {{")],
    ),
    "no_second_pass": (
        "no pair revisited by the second pass (the arriving pass kept)",
        [("revisit[ci / 32u] |= bit;\n                                    any_revisit = true;",
          f"revisit[ci / 32u] |= select(0u, bit, {NEVER});\n                                    any_revisit = any_revisit || {NEVER};")],
    ),
    "no_arriving_pass": (
        "the arriving pass never runs",
        [("                n0 = n_reactions;",
          f"                n0 = select(0u, n_reactions, {NEVER});")],
    ),
    # "twice": a part run twice with the same result (the loop's count and the argument's offset
    # are runtime values no compiler can fold: 2 and 0), so the time a variant adds is that
    # part's own, with the physics unchanged
    "queries_twice": (
        "every hand-object narrow phase of the rounds run twice",
        [("    let c = collide_hand_object_at(ci, ColliderPose(a.xyz, rot), o.xyz, orot, a.w, obj);\n",
          f"    var c: Contact;\n    for (var rep = 0u; rep < {TWICE}; rep++) {{\n"
          f"        c = collide_hand_object_at(ci, ColliderPose(a.xyz, rot), o.xyz, orot, a.w + f32(rep) * {ZERO}, obj);\n    }}\n")],
    ),
    "mobility_twice": (
        "the hand's mobility at every solved contact computed twice (the walks up the chain)",
        [("    let w = hand_mobility(l, c.point, c.normal, h);\n",
          f"    var w: vec2<f32>;\n    for (var rep = 0u; rep < {TWICE}; rep++) {{\n"
          f"        w = hand_mobility(l, c.point, c.normal, h + f32(rep) * {ZERO});\n    }}\n")],
    ),
    "object_solve_twice": (
        "the object's 6 x 6 velocity solve run twice",
        [("                let v = object_velocity_change(h);\n",
          f"                var v: ObjectVelocity;\n                for (var rep = 0u; rep < {TWICE}; rep++) {{\n"
          f"                    v = object_velocity_change(h + f32(rep) * {ZERO});\n                }}\n")],
    ),
}
# the collider bit lists of one word where the module has 8 (room for 256 colliders): the
# simulator sizes them by the model's hand (gpu/shaders.rs, collider_words; the bench hand's 17
# colliders take one), so this times that against the module as written
VARIANTS["collider_words_1"] = (
    "the collider bit lists of one word (32 colliders; the bench hand has 17)",
    [("const REVISIT_WORDS: u32 = 8u;", "const REVISIT_WORDS: u32 = 1u;")],
)
# "workgroup_N": the step (and the reset) at N invocations a workgroup where the built-in module
# has 64 (the simulator dispatches a module's entry points by their own sizes): the same physics,
# the narrow-phase rounds shared out over N envs. A driver may cap the registers by the size (a
# workgroup of 512 on a multiprocessor of 64 k registers leaves each invocation at most 128), and
# a small batch spreads over more or fewer multiprocessors (2,048 envs are 32 workgroups of 64,
# 64 of 32)
for size in (32, 128, 256, 512):
    VARIANTS[f"workgroup_{size}"] = (
        f"the step and the reset at {size} invocations a workgroup (the rounds over {size} envs)",
        [("const WORKGROUP_SIZE: u32 = 64u;", f"const WORKGROUP_SIZE: u32 = {size}u;"),
         ("@compute @workgroup_size(64)\nfn reset_main(", f"@compute @workgroup_size({size})\nfn reset_main("),
         ("@compute @workgroup_size(64)\nfn step_main(", f"@compute @workgroup_size({size})\nfn step_main(")],
    )

# The env's private arrays (hypotheses for a small batch's latency-bound step; docs/gpu.md "The
# physics kernel's memory"). Each starts from the module the simulator builds for the batch, so
# that it differs from its control in one thing: "wgN_words1" is the built-in at N invocations
# and one-word lists (what the simulator builds for the bench scene at 2,048 envs, N = 32, and at
# 65,536, N = 512: a control, expected at ~1.00 of the built-in); "_links17" sizes the links'
# private arrays to the bench hand's 17 links where the text has room for 33 (the links'
# poses, rotations and velocities: 2.1 kB of local memory per invocation → 1.1 kB; on RADV's
# compiler it backfires, the smaller arrays kept in registers: 34.1 k instructions against
# 23.7 k; NVIDIA's untried); "_shared" moves the two arrays each contact's solve walks — the
# links' positions and the joints' axes and velocity changes, read at every joint of a chain by
# hand_mobility, apply_hand_force and hand_point_velocity_change — from private (local) memory
# into workgroup memory, one row per invocation (33.8 kB a workgroup of 32 with the rounds'
# lists, under the H200's 48 kB and over lavapipe's 32 kB; 25 kB with 17 links). The same
# physics in all: the bench's contacts are the built-in's.
SIZED = lambda size: [
    ("const WORKGROUP_SIZE: u32 = 64u;", f"const WORKGROUP_SIZE: u32 = {size}u;"),
    ("@compute @workgroup_size(64)\nfn reset_main(", f"@compute @workgroup_size({size})\nfn reset_main("),
    ("@compute @workgroup_size(64)\nfn step_main(", f"@compute @workgroup_size({size})\nfn step_main("),
    ("const REVISIT_WORDS: u32 = 8u;", "const REVISIT_WORDS: u32 = 1u;"),
]
LINKS_17 = [("const MAX_LINKS: u32 = 33u;", "const MAX_LINKS: u32 = 17u;")]
SHARED = [
    ("var<private> link_pos: array<vec3<f32>, MAX_LINKS>;",
     "var<workgroup> wg_link_pos: array<array<vec3<f32>, MAX_LINKS>, WORKGROUP_SIZE>;"),
    ("var<private> joint_now: array<JointNow, MAX_JOINTS>;",
     "var<workgroup> wg_joint_now: array<array<JointNow, MAX_JOINTS>, WORKGROUP_SIZE>;"),
    (re.compile(r"\blink_pos\["), "wg_link_pos[lane]["),
    (re.compile(r"\bjoint_now\["), "wg_joint_now[lane]["),
]
for size in (32, 512):
    VARIANTS[f"wg{size}_words1"] = (f"the built-in at {size} invocations and one-word lists (the control)", SIZED(size))
    VARIANTS[f"wg{size}_words1_links17"] = (f"the same, the links' private arrays of 17 (the bench hand's links)", SIZED(size) + LINKS_17)
VARIANTS["wg32_words1_shared"] = (
    "the built-in at 32, the links' positions and the joints' axes and velocity changes in workgroup memory",
    SIZED(32) + SHARED,
)
VARIANTS["wg32_words1_links17_shared"] = (
    "the same with the links' arrays of 17",
    SIZED(32) + LINKS_17 + SHARED,
)


def main() -> int:
    if len(sys.argv) != 3:
        print("physics_variants.py: expected MODULE OUT_DIR (MODULE: benches/physics_module.sh COMMIT > MODULE)", file=sys.stderr)
        return 2
    module = Path(sys.argv[1])
    out = Path(sys.argv[2])
    try:
        text = module.read_text()
    except OSError as e:
        print(f"physics_variants.py: {module}: {e.strerror}", file=sys.stderr)
        return 2
    out.mkdir(parents=True, exist_ok=True)
    for name, (what, patches) in VARIANTS.items():
        v = text
        for old, new in patches:
            # a pattern replaces every match (at least one), a text exactly one
            if isinstance(old, re.Pattern):
                v, n = old.subn(new, v)
                if n == 0:
                    print(f"physics_variants.py: {module}: variant {name}: expected the pattern {old.pattern!r}, found none (the shader changed)", file=sys.stderr)
                    return 1
                continue
            if v.count(old) != 1:
                first = old.strip().splitlines()[0]
                print(f"physics_variants.py: {module}: variant {name}: expected the text {first!r} once, found it {v.count(old)} times (the shader changed)", file=sys.stderr)
                return 1
            v = v.replace(old, new)
        (out / f"{name}.wgsl").write_text(v)
        print(f"{out / (name + '.wgsl')}: {what}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
