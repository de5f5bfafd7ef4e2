#!/usr/bin/env bash
# The scripted grasp of every YCB object of ../shared/objects (issue 36, item 4): `dextrain traj
# synth` on configs/grasp_lift.toml's scene (dexhand16, mu = 1) with each object in place of the
# cube at its YCB dataset mass, then `dextrain replay` of the reference written (1 env, CPU).
# The wrist starts where grasp_lift.toml puts it (0.25 m up) unless the open hand there would
# overlap the object (the 25 cm bleach cleanser): then 0.15 m above its top.
# Needs the release binary (cargo build --release).
#     benches/ycb_grasps.sh [OBJECTS_DIR]     (from the checkout; default ../shared/objects)
#     GRASP=envelope benches/ycb_grasps.sh    (only the enveloping grasp: `traj synth --grasp envelope`)
# Prints one JSON line per object: which grasp synth kept (its status line's first words), the
# replay's lift, peak penetration, terminal object error, and synth's warning when none passed.
set -euo pipefail
here=$(cd "$(dirname "$0")/.." && pwd)
cd "$here"
bin=${BIN:-target/release/dextrain}
objects=$(cd "${1:-../shared/objects}" && pwd)
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
# folder, YCB dataset mass (kg), object height (m, the mesh's z extent: for the start height)
while read -r name mass height; do
    dir="$objects/$name"
    [ -d "$dir" ] || { echo "{\"object\":\"$name\",\"error\":\"$dir does not exist\"}"; continue; }
    if [ -f "$dir/model.urdf" ]; then geom="urdf = \"$dir/model.urdf\""; else geom="mesh = \"$dir/collision.obj\""; fi
    z=$(python3 -c "print(max(0.25, $height + 0.15) if $height > 0.22 else 0.25)")
    cat >"$tmp/$name.toml" <<TOML
seed = 0
[sim]
backend = "cpu"
num_envs = 1
[hand]
urdf = "$here/configs/hands/dexhand16.urdf"
[wrist]
init_pos = [0.0, 0.0, $z]
[object]
$geom
mass = $mass
friction = 1.0
TOML
    if ! "$bin" traj synth "$tmp/$name.toml" --grasp "${GRASP:-antipodal}" --out "$tmp/$name.mcap" >"$tmp/$name.synth" 2>&1; then
        python3 -c 'import json, sys; print(json.dumps({"object": sys.argv[1], "error": open(sys.argv[2]).read().strip()}))' "$name" "$tmp/$name.synth"
        continue
    fi
    "$bin" replay "$tmp/$name.toml" --traj "$tmp/$name.mcap" 2>/dev/null | tail -1 >"$tmp/$name.replay"
    python3 - "$name" "$mass" "$z" "$tmp/$name.synth" "$tmp/$name.replay" <<'PY'
import json, sys
name, mass, z, synth, replay = sys.argv[1:6]
lines = open(synth).read().strip().splitlines()
kept = next((l for l in lines if l.startswith(("antipodal grasp:", "enveloping grasp:"))), None)
warning = next((l for l in lines if l.startswith("warning:")), None)
r = json.loads(open(replay).read())
print(json.dumps({
    "object": name, "mass_kg": float(mass), "wrist_start_z_m": float(z),
    "grasp": kept.split(":")[0] if kept else "none passed",
    "variant": kept.split("variant ")[1].split(" ")[0] if kept else None,
    "lift_m": round(r["object_lift_m"], 4), "peak_penetration_mm": round(r["peak_penetration_mm"], 2),
    "terminal_object_pos_err_m": round(r["terminal_object_pos_err_m"], 4),
    "warning": warning,
}))
PY
done <<'LIST'
003_cracker_box 0.411 0.21
005_tomato_soup_can 0.349 0.10
006_mustard_bottle 0.603 0.19
010_potted_meat_can 0.370 0.08
011_banana 0.066 0.04
021_bleach_cleanser 1.131 0.25
025_mug 0.118 0.08
035_power_drill 0.895 0.19
037_scissors 0.082 0.02
061_foam_brick 0.028 0.05
LIST
