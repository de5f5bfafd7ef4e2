#!/usr/bin/env bash
# Learning benchmark of the README's main job: configs/lift_cube_cpu.toml with seeds 0, 1, 2, each
# run stopped (with a checkpoint, by SIGINT) after 10 minutes of wall time, then evaluated on 200
# fresh episodes. Prints one JSON line per seed: env steps and wall time when the success rate first
# reached 90 % (per iteration, and as the mean over the last 10 iterations), and the eval report.
#   benches/lift_cpu_learning.sh            (from the repository root, after cargo build --release)
set -euo pipefail
cd "$(dirname "$0")/.."
bin=${DEXTRAIN:-target/release/dextrain}
for s in ${SEEDS:-0 1 2}; do
    timeout -s INT "${BUDGET_S:-600}" "$bin" train configs/lift_cube_cpu.toml --set seed="$s" \
        --name "bench_lift_s$s" --force --quiet > "runs/bench_lift_s$s.log" 2>&1 || true
    "$bin" eval "runs/bench_lift_s$s" --episodes 200 > "runs/bench_lift_s$s.eval.json" 2>/dev/null
    python3 - "$s" <<'PY'
import csv, json, sys
s = sys.argv[1]
rows = list(csv.DictReader(open(f"runs/bench_lift_s{s}/metrics.csv")))
def first(pred):
    for i, r in enumerate(rows):
        if pred(i):
            return {"iteration": int(r["iteration"]), "env_steps": int(float(r["env_steps"])), "time_s": round(float(r["time_s"]), 1)}
    return None
def rate(i):
    n = float(rows[i]["episode/count"])
    return float(rows[i]["episode/success_rate"]) if n > 0 else None
def window(i, k=10):
    lo = max(0, i - k + 1)
    num = sum(float(r["episode/count"]) * float(r["episode/success_rate"]) for r in rows[lo:i + 1] if float(r["episode/count"]) > 0)
    den = sum(float(r["episode/count"]) for r in rows[lo:i + 1])
    return num / den if den > 0 and i >= k - 1 else 0.0
ev = json.load(open(f"runs/bench_lift_s{s}.eval.json"))
last = rows[-1]
print(json.dumps({
    "seed": int(s),
    "iterations": int(last["iteration"]), "env_steps": int(float(last["env_steps"])), "time_s": round(float(last["time_s"]), 1),
    "first_iteration_success_ge_0.9": first(lambda i: (rate(i) or 0) >= 0.9),
    "first_10_iteration_mean_success_ge_0.9": first(lambda i: window(i) >= 0.9),
    "eval_200_episodes": {k: ev[k] for k in ["iteration", "success_rate", "terminated_rate", "episode_length", "final_lift_height_m", "peak_penetration_mm", "frac_frames_penetration_over_1mm"]},
}))
PY
done
