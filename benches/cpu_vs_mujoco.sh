#!/usr/bin/env bash
# dextrain's CPU backend vs MuJoCo 4.0 on the peer scene, one after the other on the same machine.
# Needs the release binary (cargo build --release) and MuJoCo in /tmp/peers/venv
# (python3 -m venv /tmp/peers/venv && /tmp/peers/venv/bin/pip install mujoco==4.0.0 numpy).
# Prints one JSON line per tool and a summary line with the ratio of CPU-µs per env step.
set -euo pipefail
here=$(cd "$(dirname "$0")/.." && pwd)
peers=${PEERS_DIR:-$here/../shared/peers}
envs=${ENVS:-1024}
dex=$("$here/target/release/dextrain" bench --backend cpu --envs "$envs" --chunks 10 --seconds 5)
echo "$dex"
mj=$(/tmp/peers/venv/bin/python "$peers/mujoco_step_bench.py" --n-envs "$envs" --no-batch 2>/dev/null)
echo "$mj"
python3 - "$dex" "$mj" <<'PY'
import json, sys
d, m = json.loads(sys.argv[1]), json.loads(sys.argv[2])
dex_us = d["cpu_us_per_env_step"]["median"]
mj_us = m["rollout"][0]["cpu_us_per_physics_step"]["median"] * 4  # decimation 4
print(json.dumps({"dextrain_cpu_us_per_env_step": dex_us, "mujoco_cpu_us_per_env_step": mj_us,
                  "speedup": mj_us / dex_us, "dextrain_contacts_per_physics_step": d["contacts_per_physics_step"],
                  "mujoco_contacts_per_physics_step": m["rollout"][0]["replay_check"]["mean_ncon"]}))
PY
