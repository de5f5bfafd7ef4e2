#!/usr/bin/env bash
# SAC against PPO on one task at an equal env-step budget (issue 15). Both configs run 256 envs ×
# 24 env steps per iteration, so ITERS iterations are the same env steps for both. For each seed:
# train PPO, train SAC, evaluate both on the same EPISODES fresh episodes, print one JSON line per
# run: env steps, wall time, the first iteration at ≥ 90 % training success (lift), the eval's
# success and object errors (reference kinds: also open-loop replay's).
#   TASK=lift ITERS=600 SEEDS="0 1 2" benches/sac_vs_ppo.sh         (after cargo build --release)
#   TASK=residual_joint ITERS=250 SEEDS=0 benches/sac_vs_ppo.sh
# Extra overrides for the SAC run: SAC_SETS="sim.num_envs=128 sac.updates_per_step=2" (then the
# budgets differ; the JSON says each run's env steps).
set -euo pipefail
cd "$(dirname "$0")/.."
bin=${DEXTRAIN:-target/release/dextrain}
runs=$(realpath -m "${RUNS_DIR:-runs}")
iters=${ITERS:-300}
episodes=${EPISODES:-64}
task=${TASK:-lift}
case "$task" in
    lift) ppo_cfg=configs/lift_cube_cpu.toml; sac_cfg=configs/lift_cube_sac_cpu.toml; baseline=() ;;
    residual_joint) ppo_cfg=configs/residual_joint_cube.toml; sac_cfg=configs/residual_joint_sac.toml; baseline=(--baseline open-loop) ;;
    *) echo "TASK must be lift or residual_joint, not $task" >&2; exit 2 ;;
esac
sac_sets=()
for kv in ${SAC_SETS:-}; do sac_sets+=(--set "$kv"); done
mkdir -p "$runs"
for s in ${SEEDS:-0}; do
    for algo in ppo sac; do
        run="${task}_${algo}_s$s"
        if [ "$algo" = ppo ]; then cfg=$ppo_cfg; extra=(); else cfg=$sac_cfg; extra=("${sac_sets[@]}"); fi
        "$bin" train "$cfg" --set seed="$s" --set train.iterations="$iters" "${extra[@]}" --name "$run" \
            --runs-dir "$runs" --force --quiet >"$runs/$run.log" 2>&1
        "$bin" eval "$runs/$run" --episodes "$episodes" "${baseline[@]}" >"$runs/$run.eval.json" 2>/dev/null
        python3 - "$task" "$algo" "$s" "$runs/$run" <<'PY'
import csv, json, sys
task, algo, seed, run = sys.argv[1], sys.argv[2], int(sys.argv[3]), sys.argv[4]
rows = list(csv.DictReader(open(f"{run}/metrics.csv")))
ev = json.load(open(f"{run}.eval.json"))
def first_at(level):
    for r in rows:
        if float(r["episode/count"]) > 0 and float(r["episode/success_rate"]) >= level:
            return {"iteration": int(r["iteration"]), "env_steps": int(float(r["env_steps"])), "time_s": round(float(r["time_s"]), 1)}
    return None
def summary(d):
    out = {"success_rate": d["success_rate"]}
    for k in ["terminal_obj_pos_err_m", "terminal_obj_rot_err_deg", "ote_m", "final_lift_height_m"]:
        if d.get(k) is not None:
            out[k] = d[k]["mean"]
    return out
curve = [{"env_steps": int(float(r["env_steps"])), "time_s": round(float(r["time_s"]), 1), "success_rate": float(r["episode/success_rate"])}
         for i, r in enumerate(rows) if (i + 1) % 25 == 0]
last = rows[-1]
out = {"task": task, "algorithm": algo, "seed": seed, "iterations": int(last["iteration"]), "env_steps": int(float(last["env_steps"])),
       "time_s": round(float(last["time_s"]), 1), "first_iteration_ge_90": first_at(0.9), "curve": curve,
       "eval": {"episodes": ev["episodes"], "policy": summary(ev)}}
if ev.get("baseline"):
    out["eval"]["open_loop"] = summary(ev["baseline"])
print(json.dumps(out))
PY
    done
done
