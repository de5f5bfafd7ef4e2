#!/usr/bin/env bash
# Learning benchmarks of the reference-following kinds (issue 4) on the perturbed references of
# configs/refs/perturbed/. For each run: `dextrain train CONFIG --set seed=S [--set …]` for ITERS
# iterations, then `dextrain eval --episodes 64 --baseline open-loop` (the policy and open-loop
# replay on the same seeds). Prints one JSON line per run: wall time and env steps, the learning
# curve of the training episodes' OTE / success, and the eval report's policy and replay figures
# with the cut in terminal object error.
#   benches/residual_learning.sh                 (from the repository root, after cargo build --release)
#   RUNS="residual_task" SEEDS="0" ITERS=100 benches/residual_learning.sh
# RUNS names entries of the table below (default: all of them).
set -euo pipefail
cd "$(dirname "$0")/.."
bin=${DEXTRAIN:-target/release/dextrain}
iters=${ITERS:-1000}
episodes=${EPISODES:-64}
# name | config | extra --set overrides (space-separated)
table=$(cat <<'EOF'
residual_joint|configs/residual_joint_cube.toml|
residual_task|configs/residual_task_cube.toml|
track|configs/track_cube.toml|
track_no_ro|configs/track_cube.toml|task.rewards.object_following=0
EOF
)
mkdir -p runs
for name in ${RUNS:-residual_joint residual_task track track_no_ro}; do
    line=$(grep "^$name|" <<<"$table") || { echo "unknown run $name" >&2; exit 2; }
    cfg=$(cut -d'|' -f2 <<<"$line")
    sets=()
    for kv in $(cut -d'|' -f3 <<<"$line"); do sets+=(--set "$kv"); done
    for s in ${SEEDS:-0 1 2}; do
        run="bench_${name}_s$s"
        "$bin" train "$cfg" --set seed="$s" "${sets[@]}" --name "$run" --force --quiet \
            --stop-after "$iters" > "runs/$run.log" 2>&1
        "$bin" eval "runs/$run" --episodes "$episodes" --baseline open-loop > "runs/$run.eval.json" 2>/dev/null
        python3 - "$name" "$s" "$run" <<'PY'
import csv, json, sys
name, s, run = sys.argv[1], int(sys.argv[2]), sys.argv[3]
rows = list(csv.DictReader(open(f"runs/{run}/metrics.csv")))
ev = json.load(open(f"runs/{run}.eval.json"))
def window(i, key, k=20):
    # episode-weighted mean of a per-iteration episode metric over iterations i-k+1..i
    num = den = 0.0
    for r in rows[max(0, i - k + 1):i + 1]:
        n = float(r["episode/count"])
        if n > 0 and r.get(key, "nan") != "nan":
            num += n * float(r[key])
            den += n
    return num / den if den > 0 else None
def first(pred):
    for i, r in enumerate(rows):
        if i >= 19 and pred(i):
            return {"iteration": int(r["iteration"]), "env_steps": int(float(r["env_steps"])), "time_s": round(float(r["time_s"]), 1)}
    return None
curve = []
for i in range(99, len(rows), 100):
    curve.append({"iteration": int(rows[i]["iteration"]), "time_s": round(float(rows[i]["time_s"]), 1),
                  "success_rate": window(i, "episode/success_rate"), "return": window(i, "episode/return")})
keys = ["success_rate", "ote_m", "ooe_deg", "terminal_obj_pos_err_m", "terminal_obj_rot_err_deg", "terminated_rate", "mean_fingertip_force_n", "peak_penetration_mm"]
def pick(d):
    out = {}
    for k in keys:
        v = d[k]
        out[k] = v if not isinstance(v, dict) else {"mean": v["mean"], "std": v["std"]}
    return out
pol, base = pick(ev), pick(ev["baseline"])
te, tb = pol["terminal_obj_pos_err_m"]["mean"], base["terminal_obj_pos_err_m"]["mean"]
last = rows[-1]
print(json.dumps({
    "run": name, "seed": s, "iterations": int(last["iteration"]), "env_steps": int(float(last["env_steps"])),
    "time_s": round(float(last["time_s"]), 1),
    "first_20_iteration_success_ge_0.5": first(lambda i: (window(i, "episode/success_rate") or 0) >= 0.5),
    "training_curve": curve,
    "eval": {"episodes": ev["episodes"], "policy": pol, "open_loop": base,
             "terminal_error_cut": (tb - te) / tb if tb > 0 else None},
}))
PY
    done
done
