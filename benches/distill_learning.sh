#!/usr/bin/env bash
# Distillation learning benchmark (issue 13). TASK=residual_task (default): under DexRefine's
# randomisation table, a teacher with the privileged encoder (configs/residual_task_teacher.toml,
# PPO), then its students by online DAgger (configs/residual_task_student.toml) — the default one,
# one with λ2 = 0 (no latent loss) and one without history (H = 1: the GRU sees only the current
# step). TASK=lift: the same on the lift task (configs/lift_teacher.toml; the student is that config
# with train.algorithm = "distill" and [distill]'s defaults, LIFT_STUDENT_ITERS iterations).
# Each student is evaluated beside its teacher on the same episodes (`dextrain eval --baseline
# teacher`), and the default student is also exported and played from the export alone (`dextrain
# play`). Prints one JSON line per student: wall times and env steps of teacher and student, success
# (and for residual_task the object errors) of both, the student's share of the teacher's success,
# the latent error, and play's success on the same seeds. A teacher run already finished under
# RUNS_DIR is reused.
#   benches/distill_learning.sh                     (from the repository root, after cargo build --release)
#   SEEDS="0" STUDENTS="student" RUNS_DIR=/tmp/runs benches/distill_learning.sh
#   TASK=lift TEACHER_ITERS=600 SEEDS=0 STUDENTS=student benches/distill_learning.sh
set -euo pipefail
cd "$(dirname "$0")/.."
bin=${DEXTRAIN:-target/release/dextrain}
runs=$(realpath -m "${RUNS_DIR:-runs}")
episodes=${EPISODES:-64}
task=${TASK:-residual_task}
case "$task" in
    residual_task)
        teacher_cfg=configs/residual_task_teacher.toml; teacher_iters=1000
        student_cfg=configs/residual_task_student.toml; student_sets=() ;;
    lift)
        teacher_cfg=configs/lift_teacher.toml; teacher_iters=1500
        student_cfg=configs/lift_teacher.toml
        student_sets=(--set 'train.algorithm="distill"' --set "train.iterations=${LIFT_STUDENT_ITERS:-150}" --set distill.epochs=2) ;;
    *) echo "TASK must be residual_task or lift, not $task" >&2; exit 2 ;;
esac
teacher_iters=${TEACHER_ITERS:-$teacher_iters}   # the teacher's PPO iterations (default: its config's)
# name | extra --set overrides of the student config (space-separated)
table=$(cat <<'TABLE'
student|
student_no_latent|distill.lambda_latent=0
student_no_history|distill.history_len=1
TABLE
)
mkdir -p "$runs"
for s in ${SEEDS:-0 1 2}; do
    teacher="bench_${task}_teacher_s$s"
    if [ ! -f "$runs/$teacher/checkpoints/$teacher_iters/manifest.json" ]; then
        "$bin" train "$teacher_cfg" --set seed="$s" --set train.iterations="$teacher_iters" --name "$teacher" --runs-dir "$runs" --force --quiet > "$runs/$teacher.log" 2>&1
    fi
    for name in ${STUDENTS:-student student_no_latent student_no_history}; do
        line=$(grep "^$name|" <<<"$table") || { echo "unknown student $name" >&2; exit 2; }
        sets=("${student_sets[@]}" --set seed="$s" --set "distill.teacher=\"$runs/$teacher\"")
        for kv in $(cut -d'|' -f2 <<<"$line"); do sets+=(--set "$kv"); done
        run="bench_${task}_${name}_s$s"
        "$bin" train "$student_cfg" "${sets[@]}" --name "$run" --runs-dir "$runs" --force --quiet > "$runs/$run.log" 2>&1
        "$bin" eval "$runs/$run" --episodes "$episodes" --baseline teacher > "$runs/$run.eval.json" 2>/dev/null
        play=""
        if [ "$name" = student ]; then
            "$bin" export "$runs/$run" --verify > "$runs/$run.export.json" 2>/dev/null
            "$bin" play "$runs/$run/export/policy.json" --episodes "$episodes" > "$runs/$run.play.json" 2>/dev/null
            play="$runs/$run.play.json"
        fi
        python3 - "$task" "$name" "$s" "$runs" "$run" "$teacher" "$play" <<'PY'
import csv, json, sys
task, name, s, runs, run, teacher, play = sys.argv[1], sys.argv[2], int(sys.argv[3]), sys.argv[4], sys.argv[5], sys.argv[6], sys.argv[7]
def last(r):
    rows = list(csv.DictReader(open(f"{runs}/{r}/metrics.csv")))
    return rows[-1]
ev = json.load(open(f"{runs}/{run}.eval.json"))
st, te = ev, ev["baseline"]
def pick(d):
    out = {"success_rate": d["success_rate"], "episode_return": d["episode_return"]["mean"]}
    if "ote_m" in d:  # the reference kinds' errors (lift reports none)
        out.update({"terminal_obj_pos_err_mm": d["terminal_obj_pos_err_m"]["mean"] * 1e3,
                    "terminal_obj_rot_err_deg": d["terminal_obj_rot_err_deg"]["mean"], "ote_mm": d["ote_m"]["mean"] * 1e3,
                    "ooe_deg": d["ooe_deg"]["mean"]})
    return out
tl, sl = last(teacher), last(run)
out = {
    "task": task, "student": name, "seed": s,
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
    if "terminal_obj_pos_err_m" in p:
        out["play_terminal_obj_pos_err_mm"] = p["terminal_obj_pos_err_m"]["mean"] * 1e3
print(json.dumps(out))
PY
    done
done
