#!/usr/bin/env bash
# The simulator's WGSL module of a commit, as `dextrain bench --physics-wgsl FILE` reads it: the
# commit's shaders/common.wgsl, shaders/reset.wgsl, shaders/physics.wgsl and, from the commit that
# shared the narrow phases out over the workgroup on, shaders/narrow_rounds.wgsl, joined with a
# newline between (as the binary joins its own), on stdout. Run in a clone holding the commit:
#     benches/physics_module.sh f7d02e5 > f7d02e5.wgsl
# (f7d02e5: the physics before issue 36's contacts; a module without the rounds binds as
# today's does less their binding, `narrow_queries`).
set -euo pipefail
if [ $# -ne 1 ]; then
    echo "physics_module.sh: expected one argument, a commit (e.g. f7d02e5)" >&2
    exit 2
fi
commit=$1
for f in common reset physics; do
    if ! git show "$commit:shaders/$f.wgsl" 2>/dev/null; then
        echo "physics_module.sh: $commit has no shaders/$f.wgsl (is it a commit of this repository?)" >&2
        exit 1
    fi
    [ "$f" = physics ] || echo
done
if git cat-file -e "$commit:shaders/narrow_rounds.wgsl" 2>/dev/null; then
    echo
    git show "$commit:shaders/narrow_rounds.wgsl"
fi
