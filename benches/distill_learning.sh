#!/usr/bin/env bash
# Distillation learning benchmark (issue 13): on residual_task under DexRefine's randomisation
# table, a teacher with the privileged encoder (configs/residual_task_teacher.toml, PPO), then its
# students by online DAgger (configs/residual_task_student.toml) — the default one, one with
# λ2 = 0 (no latent loss) and one without history (H = 1: the GRU sees only the current step).
# Each student is evaluated beside its teacher on the same 64 episodes (`dextrain eval
# --baseline teacher`), and the default student is also exported and played from the export
# alone (`dextrain play`). Prints one JSON line per student: wall times and env steps of teacher
# and student, success and terminal error of both, the student's share of the teacher's success,
# the latent error, and play's success on the same seeds.
#   benches/distill_learning.sh                     (from the repository root, after cargo build --release)
#   SEEDS="0" STUDENTS="student" RUNS_DIR=/tmp/runs benches/distill_learning.sh
set -euo pipefail
cd "$(dirname "$0")/.."
bin=${DEXTRAIN:-target/release/dextrain}
runs=$(realpath -m "${RUNS_DIR:-runs}")
episodes=${EPISODES:-64}
# name | extra --set overrides of the student config (space-separated)
table=$(cat <<'TABLE'
student|
student_no_latent|distill.lambda_latent=0
student_no_history|distill.history_len=1
TABLE
)
mkdir -p "$runs"
for s in ${SEEDS:-0 1 2}; do
    teacher="bench_rtt_s$s"
    if [ ! -f "$runs/$teacher/checkpoints/1000/manifest.json" ]; then
        "$bin" train configs/residual_task_teacher.toml --set seed="$s" --name "$teacher" --runs-dir "$runs" --force --quiet > "$runs/$teacher.log" 2>&1
    fi
    for name in ${STUDENTS:-student student_no_latent student_no_history}; do
        line=$(grep "^$name|" <<<"$table") || { echo "unknown student $name" >&2; exit 2; }
        sets=(--set seed="$s" --set "distill.teacher=\"$runs/$teacher\"")
        for kv in $(cut -d'|' -f2 <<<"$line"); do sets+=(--set "$kv"); done
        run="bench_${name}_s$s"
        "$bin" train configs/residual_task_student.toml "${sets[@]}" --name "$run" --runs-dir "$runs" --force --quiet > "$runs/$run.log" 2>&1
        "$bin" eval "$runs/$run" --episodes "$episodes" --baseline teacher > "$runs/$run.eval.json" 2>/dev/null
        play=""
        if [ "$name" = student ]; then
            "$bin" export "$runs/$run" --verify > "$runs/$run.export.json" 2>/dev/null
            "$bin" play "$runs/$run/export/policy.json" --episodes "$episodes" > "$runs/$run.play.json" 2>/dev/null
            play="$runs/$run.play.json"
        fi
        python3 - "$name" "$s" "$runs" "$run" "$teacher" "$play" <<'PY'
import csv, json, sys
name, s, runs, run, teacher, play = sys.argv[1], int(sys.argv[2]), sys.argv[3], sys.argv[4], sys.argv[5], sys.argv[6]
def last(r):
    rows = list(csv.DictReader(open(f"{runs}/{r}/metrics.csv")))
    return rows[-1]
ev = json.load(open(f"{runs}/{run}.eval.json"))
st, te = ev, ev["baseline"]
def pick(d):
    return {"success_rate": d["success_rate"], "terminal_obj_pos_err_mm": d["terminal_obj_pos_err_m"]["mean"] * 1e3,
            "terminal_obj_rot_err_deg": d["terminal_obj_rot_err_deg"]["mean"], "ote_mm": d["ote_m"]["mean"] * 1e3,
            "ooe_deg": d["ooe_deg"]["mean"], "episode_return": d["episode_return"]["mean"]}
tl, sl = last(teacher), last(run)
out = {
    "student": name, "seed": s,
    "teacher": {"iterations": int(tl["iteration"]), "env_steps": int(float(tl["env_steps"])), "time_s": round(float(tl["time_s"]), 1)},
    "distill": {"iterations": int(sl["iteration"]), "env_steps": int(float(sl["env_steps"])), "time_s": round(float(sl["time_s"]), 1)},
    "eval_episodes": ev["episodes"],
    "student_eval": pick(st), "teacher_eval": pick(te),
    "success_share": st["success_rate"] / te["success_rate"] if te["success_rate"] > 0 else None,
    "latent_error": st.get("latent_error", {}).get("mean"),
}
if play:
    p = json.load(open(play))
    out["play_success_rate"] = p["success_rate"]
    out["play_terminal_obj_pos_err_mm"] = p["terminal_obj_pos_err_m"]["mean"] * 1e3
print(json.dumps(out))
PY
    done
done
