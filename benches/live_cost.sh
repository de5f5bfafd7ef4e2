#!/usr/bin/env bash
# The live view's cost on the README's main job (configs/lift_cube_cpu.toml, CPU backend): the same
# run of ITERATIONS iterations, ROUNDS times each way, interleaved: without --live, with --live and
# no client, and with --live and a client watching (tests/live_client.py --count-only: it subscribes
# to every channel and counts the messages without decoding them). Prints one JSON line: per way,
# the median over the rounds of the run's median iteration time (time/collect_s + time/learn_s
# from metrics.csv); per watched run, the live view's own time (`live.busy_s` of the summary) as a
# fraction of the run's time, the messages and bytes the client got, and the time per scene.
#   benches/live_cost.sh [ITERATIONS=40] [ROUNDS=3]   (from the repository root, after cargo build --release)
set -euo pipefail
cd "$(dirname "$0")/.."
bin=${DEXTRAIN:-target/release/dextrain}
iters=${1:-40}
rounds=${2:-3}
out=$(mktemp -d)
sets=(--set sim.backend=cpu --set train.device=cpu --set "train.iterations=$iters" --set train.plot_interval=0 --set train.save_interval=100000)
for r in $(seq "$rounds"); do
    for way in off idle watched; do
        name="live_cost_${way}_$r"
        case $way in
            off) "$bin" train configs/lift_cube_cpu.toml "${sets[@]}" --name "$name" --runs-dir "$out" --quiet > "$out/$name.json" 2> "$out/$name.err" ;;
            idle) "$bin" train configs/lift_cube_cpu.toml "${sets[@]}" --name "$name" --runs-dir "$out" --quiet --live=127.0.0.1:0 > "$out/$name.json" 2> "$out/$name.err" ;;
            watched)
                "$bin" train configs/lift_cube_cpu.toml "${sets[@]}" --name "$name" --runs-dir "$out" --quiet --live=127.0.0.1:0 --live-wait > "$out/$name.json" 2> "$out/$name.err" &
                pid=$!
                url=""
                for _ in $(seq 600); do
                    url=$(grep -o 'ws://[0-9.]*:[0-9]*' "$out/$name.err" | head -1 || true)
                    [ -n "$url" ] && break
                    sleep 0.1
                done
                python3 tests/live_client.py "$url" --count-only --timeout 3600 > "$out/$name.client.json"
                wait "$pid" ;;
        esac
    done
done
python3 - "$out" "$rounds" <<'PY'
import csv, json, statistics, sys
out, rounds = sys.argv[1], int(sys.argv[2])
def iteration_times(name):
    rows = list(csv.DictReader(open(f"{out}/{name}/metrics.csv")))
    return [float(r["time/collect_s"]) + float(r["time/learn_s"]) for r in rows]
res = {"config": "configs/lift_cube_cpu.toml", "iterations": None, "rounds": rounds, "ways": {}}
for way in ["off", "idle", "watched"]:
    per_run = []
    live = []
    for r in range(1, rounds + 1):
        name = f"live_cost_{way}_{r}"
        t = iteration_times(name)
        res["iterations"] = len(t)
        per_run.append(statistics.median(t))
        s = json.loads(open(f"{out}/{name}.json").read().strip().splitlines()[-1])
        if way == "watched":
            c = json.load(open(f"{out}/{name}.client.json"))
            l = s["live"]
            live.append({"busy_s": round(l["busy_s"], 4), "busy_frac_of_run": round(l["busy_s"] / s["time_s"], 5), "scene_messages": l["scene_messages"],
                         "ms_per_scene": round(1e3 * l["busy_s"] / max(l["scene_messages"], 1), 3), "client_counts": c["counts"], "client_bytes": c["bytes"]})
        elif way == "idle":
            live.append({"scene_messages": s["live"]["scene_messages"], "metrics_messages": s["live"]["metrics_messages"]})
    res["ways"][way] = {"median_iteration_s": round(statistics.median(per_run), 4), "per_run_median_iteration_s": [round(x, 4) for x in per_run], "live": live}
off = res["ways"]["off"]["median_iteration_s"]
for way in ["idle", "watched"]:
    res["ways"][way]["iteration_time_ratio_to_off"] = round(res["ways"][way]["median_iteration_s"] / off, 4)
print(json.dumps(res))
PY
rm -rf "$out"
