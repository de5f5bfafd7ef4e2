#!/usr/bin/env bash
# dextrain's contacts against statics and MuJoCo 4.0 (issue 36): the five scenes of
# `dextrain bench --contacts` (slide, tilt, tip, rest, squeeze), the same scenes in MuJoCo
# (benches/contact_fidelity_mujoco.py, with its default options and with the elliptic cone and
# no-slip iterations), and, given a trained lift run, the learned grasp's penetration and force.
# Needs the release binary (cargo build --release) and MuJoCo in /tmp/peers/venv
# (python3 -m venv /tmp/peers/venv && /tmp/peers/venv/bin/pip install mujoco==4.0.0 numpy).
#     benches/contact_fidelity.sh [RUN]      (from the checkout; RUN: a lift run to evaluate)
# Prints one JSON object: each scene's statics answer, dextrain's and MuJoCo's figures, and whether
# dextrain is within the issue's tolerance (slip force 5 %, slip angle 1°, tipping force 10 %,
# drift 0.1 mm, squeeze penetration 1 mm and no slip over 1 mm while lifted).
set -euo pipefail
here=$(cd "$(dirname "$0")/.." && pwd)
cd "$here"
bin=${BIN:-target/release/dextrain}
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
"$bin" bench --contacts --backend "${BACKEND:-cpu}" >"$tmp/dextrain.json"
/tmp/peers/venv/bin/python benches/contact_fidelity_mujoco.py "$tmp/dextrain.json" >"$tmp/mujoco.json"
echo '{}' >"$tmp/eval.json"
if [ $# -ge 1 ]; then
    "$bin" eval "$1" --episodes 64 --backend cpu >"$tmp/eval.json"
fi
python3 - "$tmp/dextrain.json" "$tmp/mujoco.json" "$tmp/eval.json" <<'PY'
import json, sys
d, m, e = (json.loads(open(p).read().strip().splitlines()[-1]) for p in sys.argv[1:4])
mj, ms = m["default"], m["elliptic_noslip"]
def within(x, tol):
    return x is not None and abs(x) <= tol
out = {"dextrain_backend": d["backend"], "mujoco": m["version"], "scenes": d["scenes"]}
out["slide"] = {"expected_n": d["slide"]["expected_n"], "dextrain_n": d["slide"]["slip_force_n"],
                "mujoco_n": mj["slide"]["slip_force_n"], "mujoco_elliptic_noslip_n": ms["slide"]["slip_force_n"],
                "dextrain_error": d["slide"]["error"], "within_5_percent": within(d["slide"]["error"], 0.05)}
out["tilt"] = {"expected_deg": d["tilt"]["expected_deg"], "dextrain_deg": d["tilt"]["slip_angle_deg"],
               "mujoco_deg": mj["tilt"]["slip_angle_deg"], "mujoco_elliptic_noslip_deg": ms["tilt"]["slip_angle_deg"],
               "dextrain_error_deg": d["tilt"]["error_deg"], "within_1_deg": within(d["tilt"]["error_deg"], 1.0)}
out["tip"] = {"expected_n": d["tip"]["expected_n"], "dextrain_n": d["tip"]["tip_force_n"],
              "mujoco_n": mj["tip"]["tip_force_n"], "mujoco_elliptic_noslip_n": ms["tip"]["tip_force_n"],
              "dextrain_error": d["tip"]["error"], "within_10_percent": within(d["tip"]["error"], 0.10)}
out["rest"] = {"dextrain_drift_mm": d["rest"]["drift_mm"], "mujoco_drift_mm": mj["rest"]["drift_mm"],
               "dextrain_sink_mm": d["rest"]["sink_mm"], "mujoco_sink_mm": mj["rest"]["sink_mm"],
               "within_0_1_mm": d["rest"]["drift_mm"] < 0.1}
out["squeeze"] = [{"force_n": a["force_n"], "dextrain": a, "mujoco": b, "mujoco_elliptic_noslip": c,
                   "penetration_within_1_mm": a["peak_penetration_mm"] <= 1.0,
                   "held": a["slip_mm"] is not None and a["slip_mm"] < 1.0}
                  for a, b, c in zip(d["squeeze"], mj["squeeze"], ms["squeeze"])]
if e:
    out["learned_lift"] = {k: e.get(k) for k in ("run", "iteration", "episodes", "success_rate", "peak_penetration_mm",
                                                 "episode_peak_penetration_mm", "frac_frames_penetration_over_1mm", "mean_fingertip_force_n")}
print(json.dumps(out))
PY
