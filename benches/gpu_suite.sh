#!/usr/bin/env bash
# Every GPU figure of dextrain in one command, for a short window on a GPU machine (issue 16).
#
# Needs only the release binary and a Vulkan driver (no Rust toolchain, no Python): copy
# target/release/dextrain, configs/ and this script to the machine, then, from the folder holding
# configs/,
#     benches/gpu_suite.sh --bin ./dextrain --out results/
# It writes results/gpu_suite.json (one JSON object) and one log per step beside it. It stops at
# once, with dextrain's account of what Vulkan found, when the adapter does not start. Steps:
#   1. env-only throughput of the contact-rich bench scene (`dextrain bench --backend gpu`) at
#      4 k, 16 k, 64 k and 256 k envs (every env step uploads the targets and reads the step
#      statistics back, as an RL loop does), with the simulator's device bytes per env;
#   1b. the same scene at OBJ_ENVS (65536) envs with the cube, the 3-piece bottle and the 16-piece mug
#      (configs/bench_{cube,bottle,mug16}.toml): what a compound object costs per env step;
#   2. the learner updates on the GPU at the peers' shapes (`bench --ppo` / `bench --sac --device gpu`),
#      the PPO bench again with acting's forward passes one kernel per MLP at any batch
#      (`DEXTRAIN_MLP_FORWARD=fused`; the default leaves the peer networks' 4096 rows to a product
#      per layer: which is faster for the policy inference and the rollout), SAC's gradient step of the
#      shipped SAC configs' shape (`--n-step 3 --critic-layer-norm`, 1024 envs, batch 2048), and the
#      PPO minibatch's products with each matmul routine (`bench --matmul`);
#   3. PPO training on configs/lift_cube_gpu.toml for TRAIN_PPO_S seconds (SIGINT: the run stops at
#      the end of its iteration with a checkpoint), then SAC on configs/lift_cube_sac_gpu.toml for
#      TRAIN_SAC_S seconds: env-steps/s with the learner, the best success rate and the wall time
#      and env steps of the first iteration at >= 90 % success, and the host<->GPU bytes of its last
#      iteration (`time/host_bytes`: the PPO run keeps its rollouts on the device); then PPO again for
#      TRAIN_PPO_HOST_S seconds with `train.device_rollouts = false` (observations through the host
#      every env step: what the device-resident rollouts save). Each run's summary line gives its
#      device memory (the simulator's buffers and burn's reserved pool, and their sum per env).
#      Step "profile": the PPO lift again for TRAIN_PROFILE_S seconds with `--gpu-profile`
#      (`gpu_profile_ppo_lift`: the GPU time of each kernel of ours and of each stretch of the
#      learner's work, from timestamp queries; docs/gpu.md "Where a GPU's time goes").
#      Step "scale": the PPO lift at the batches of SCALE_SHAPES (ENVSxSTEPS, default "16384x32
#      65536x24": lift_cube_gpu.toml's shape when issue 33 asked for >= 1 M env-steps/s with the
#      learner, and the batch where the env-only bench peaks) for TRAIN_SCALE_S seconds each
#      (`train_ppo_scale`): the throughput with the learner where the batch fills the GPU (the
#      shipped config's 2,048 envs leave most of an H200's multiprocessors idle).
#   4. (step "baseline", only with BASELINE_WGSL set: a simulator WGSL module, common + reset +
#      physics, as `benches/physics_module.sh COMMIT` writes it) the env-only bench at BASELINE_ENVS
#      envs with the built-in physics and with that module (`bench --physics-wgsl`), alternated over
#      BASELINE_ROUNDS rounds, and the median of the rounds' ratios: what a physics change costs on
#      this GPU against the commit it is measured from (issue 36: f7d02e5, the physics before its
#      contacts).
#   5. (step "variants", only with VARIANTS_WGSL set: space-separated simulator modules, e.g. the
#      knock-outs `benches/physics_variants.py MODULE DIR` writes) the env-only bench at
#      BASELINE_ENVS envs with the built-in physics, then with each module, over BASELINE_ROUNDS
#      rounds, and each module's median ratio of rates: where this GPU spends the env step.
#   6. (step "shader_stats", run first) what the adapter's Vulkan compiler makes of the kernels
#      (`dextrain bench --shader-stats`: registers, code size, and on AMD's compiler spills and
#      scratch): the built-in simulator's and task layer's, then each module of BASELINE_WGSL and
#      VARIANTS_WGSL; seconds. A driver that reports none (lavapipe) gives {"module", "error"}
#      entries.
# On an H200 the default steps take ~10 minutes and the baseline step ~2.5 more (estimates from the
# steps' parts timed in earlier windows, the suite not yet run whole there): where one command
# may run less (a device window's call), split them with STEPS, e.g. STEPS="env baseline" then
# STEPS="objects learner train".
# --quick runs the same steps at tiny sizes (any adapter, lavapipe included) so that the script
# can be checked anywhere. Environment: ENVS (space-separated env counts), TRAIN_PPO_S, TRAIN_SAC_S, TRAIN_PPO_HOST_S,
# TRAIN_PROFILE_S (the profiled PPO lift's seconds), TRAIN_SCALE_S and SCALE_SHAPES (step "scale"),
# BENCH_S (least timed seconds per env-only point), OBJ_ENVS, ADAPTER (gpu or gpu:NAME, default gpu),
# STEPS (the steps to run, default "shader_stats env objects learner train profile scale", plus "baseline" when BASELINE_WGSL is
# set and "variants" when VARIANTS_WGSL is; the others' JSON values are null), BASELINE_WGSL,
# VARIANTS_WGSL, BASELINE_ENVS, BASELINE_ROUNDS.
set -uo pipefail

bin=target/release/dextrain
out=gpu_suite_out
quick=0
while [ $# -gt 0 ]; do
    case "$1" in
        --bin) bin=$2; shift 2 ;;
        --out) out=$2; shift 2 ;;
        --quick) quick=1; shift ;;
        *) echo "gpu_suite.sh: unknown argument '$1' (expected --bin PATH, --out DIR, --quick)" >&2; exit 2 ;;
    esac
done
mkdir -p "$out"
adapter=${ADAPTER:-gpu}
if [ "$quick" = 1 ]; then
    envs=${ENVS:-"64 128"}; profile_s=${TRAIN_PROFILE_S:-10}; scale_s=${TRAIN_SCALE_S:-10}; scale_shapes=${SCALE_SHAPES:-"128x4"}; ppo_s=${TRAIN_PPO_S:-20}; sac_s=${TRAIN_SAC_S:-20}; ppo_host_s=${TRAIN_PPO_HOST_S:-10}; bench_s=${BENCH_S:-0.5}; obj_envs=${OBJ_ENVS:-64}
    small=(--set sim.num_envs=64 --set train.steps_per_env=4 --set 'policy.actor_hidden=[32]' --set 'policy.critic_hidden=[32]')
    sac_small=(--set sac.batch_size=64 --set sac.learning_starts=8 --set sac.buffer_capacity=64)
    scale_small=(--set 'policy.actor_hidden=[32]' --set 'policy.critic_hidden=[32]')  # (the batch from SCALE_SHAPES)
    baseline_envs=${BASELINE_ENVS:-64}; baseline_rounds=${BASELINE_ROUNDS:-1}
    ppo_sizes=(--envs 64 --iters 1); sac_sizes=(--envs 64 --iters 1 --batch 256 --gradient-steps 2); matmul_sizes=()  # (every routine compiles its kernels: minutes on lavapipe)
    sac_lift_sizes=("${sac_sizes[@]}")
else
    envs=${ENVS:-"4096 16384 65536 262144"}; profile_s=${TRAIN_PROFILE_S:-20}; scale_s=${TRAIN_SCALE_S:-40}; scale_shapes=${SCALE_SHAPES:-"16384x32 65536x24"}; ppo_s=${TRAIN_PPO_S:-210}; sac_s=${TRAIN_SAC_S:-90}; ppo_host_s=${TRAIN_PPO_HOST_S:-30}; bench_s=${BENCH_S:-5}; obj_envs=${OBJ_ENVS:-65536}
    small=(); sac_small=(); scale_small=(); ppo_sizes=(--iters 3); sac_sizes=(--iters 3); matmul_sizes=(--iters 3)
    # configs/lift_cube_sac_gpu.toml's shape: 1024 envs, batch 2048 (with --n-step 3 --critic-layer-norm below)
    sac_lift_sizes=(--envs 1024 --batch 2048 --iters 3)
    baseline_envs=${BASELINE_ENVS:-65536}; baseline_rounds=${BASELINE_ROUNDS:-3}
fi
runs=$out/runs
mkdir -p "$runs"

# the JSON value of a command's last line on stdout, or null (its .log, stderr, says why)
json_of() {
    local line
    line=$(tail -n 1 "$1" 2>/dev/null)
    case "$line" in
        \{*\}) printf '%s' "$line" ;;
        *) printf 'null' ;;
    esac
}

# the env-only rate in a bench's JSON, or 0
rate_of() {
    tail -n 1 "$1" 2>/dev/null | grep -o '"env_steps_per_s":{[^}]*"median":[0-9.e+-]*' | grep -o '[0-9.e+-]*$' || echo 0
}
# the median of numbers on stdin, one a line (null for none)
median_of() {
    sort -g | awk 'NF { v[n++] = $1 } END { if (n == 0) print "null"; else if (n % 2) print v[(n - 1) / 2]; else print (v[n / 2 - 1] + v[n / 2]) / 2 }'
}

# the summary line a training run printed (its last JSON line: env backend, learner device, device
# memory), or null
run_json() {
    local line
    line=$(grep '^{' "$1" 2>/dev/null | tail -n 1)
    case "$line" in
        \{*\}) printf '%s' "$line" ;;
        *) printf 'null' ;;
    esac
}

# a training run's summary from its metrics.csv: rows, env steps, wall time, env-steps/s of the
# last row, best success and the first row at >= 90 % success
train_summary() {
    local csv=$1
    [ -f "$csv" ] || { printf 'null'; return; }
    awk -F, 'NR == 1 { for (i = 1; i <= NF; i++) col[$i] = i; next }
        { rows++; steps = $col["env_steps"]; t = $col["time_s"]; fps = $col["fps"]; s = $col["episode/success_rate"] + 0
          if (s > best) best = s
          if (s >= 0.9 && first_it == "") { first_it = $col["iteration"]; first_steps = steps; first_t = t }
          bytes = ("time/host_bytes" in col) ? $col["time/host_bytes"] : "null"
          gpu = ""
          n = split("gpu/kernels_per_step gpu/submissions_per_step gpu/syncs_per_step gpu/kernels_per_update gpu/submissions_per_update gpu/syncs_per_update", names, " ")
          for (k = 1; k <= n; k++) { key = names[k]; sub("gpu/", "", key); gpu = gpu sprintf("%s\"%s\": %s", k > 1 ? ", " : "", key, (names[k] in col) ? $col[names[k]] : "null") } }
        END { printf "{\"iterations\": %d, \"env_steps\": %s, \"time_s\": %s, \"env_steps_per_s_last\": %s, \"best_success\": %s, \"first_90_iteration\": %s, \"first_90_env_steps\": %s, \"first_90_time_s\": %s, \"host_bytes_last_iteration\": %s, \"gpu_counts_last_iteration\": {%s}}",
              rows, steps + 0, t + 0, fps + 0, best + 0, first_it == "" ? "null" : first_it, first_it == "" ? "null" : first_steps, first_it == "" ? "null" : first_t, bytes == "" ? "null" : bytes, gpu }' "$csv"
}

# a training run stopped by SIGINT $2 seconds after it started training (it finishes its iteration,
# writes its checkpoint and exits)
train_for() {
    local name=$1 secs=$2 cfg=$3; shift 3
    "$bin" train "$cfg" --name "$name" --runs-dir "$runs" --force --quiet "$@" >"$out/$name.log" 2>&1 &
    local pid=$!
    local waited=0
    # the seconds count from the run's banner (its set-up done and its Ctrl-C handler installed)
    while kill -0 "$pid" 2>/dev/null && ! grep -q '^dextrain train:' "$out/$name.log"; do sleep 0.2; done
    while kill -0 "$pid" 2>/dev/null && [ "$waited" -lt "$secs" ]; do sleep 1; waited=$((waited + 1)); done
    kill -INT "$pid" 2>/dev/null
    wait "$pid"
    echo "exit $?" >>"$out/$name.log"
}

baseline_wgsl=${BASELINE_WGSL:-}
variants_wgsl=${VARIANTS_WGSL:-}
steps=" ${STEPS:-shader_stats env objects learner train profile scale${baseline_wgsl:+ baseline}${variants_wgsl:+ variants}} "
runs_step() { case "$steps" in *" $1 "*) return 0 ;; *) return 1 ;; esac; }

start=$(date +%s)
echo "gpu_suite: adapter $adapter, env counts $envs, quick=$quick" >&2
# the adapter first: without it every step would fail and the JSON would be all nulls; dextrain's
# message says what Vulkan found (the loader, the drivers, the packages that usually fix it)
if ! "$bin" bench --backend "$adapter" --envs 64 --chunks 1 --seconds 0 >"$out/adapter_probe.json" 2>"$out/adapter_probe.log"; then
    echo "gpu_suite: stopped: no usable GPU adapter ($adapter):" >&2
    grep -v XDG_RUNTIME_DIR "$out/adapter_probe.log" >&2
    exit 1
fi
# the last line a command wrote on stderr, as a JSON string's contents
error_of() {
    grep -v XDG_RUNTIME_DIR "$1" 2>/dev/null | tail -n 1 | sed 's/\\/\\\\/g; s/"/\\"/g'
}
stats_json=null
if runs_step shader_stats; then
    echo "gpu_suite: shader statistics of the kernels" >&2
    stats_json=""
    i=0
    for m in builtin ${baseline_wgsl:-} ${variants_wgsl:-}; do
        i=$((i + 1))
        if [ "$m" = builtin ]; then
            "$bin" bench --shader-stats --backend "$adapter" >"$out/shader_stats_$i.json" 2>"$out/shader_stats_$i.log"
        else
            "$bin" bench --shader-stats --backend "$adapter" --physics-wgsl "$m" >"$out/shader_stats_$i.json" 2>"$out/shader_stats_$i.log"
        fi
        entry=$(json_of "$out/shader_stats_$i.json")
        [ "$entry" = null ] && entry="{\"module\": \"$m\", \"error\": \"$(error_of "$out/shader_stats_$i.log")\"}"
        stats_json="$stats_json${stats_json:+, }$entry"
    done
    stats_json="[$stats_json]"
fi
env_json=""
runs_step env || envs=""
for n in $envs; do
    echo "gpu_suite: env-only bench at $n envs" >&2
    "$bin" bench --backend "$adapter" --envs "$n" --chunks 5 --seconds "$bench_s" >"$out/env_$n.json" 2>"$out/env_$n.log"
    env_json="$env_json${env_json:+, }$(json_of "$out/env_$n.json")"
done
obj_json=""
objects="cube bottle mug16"
runs_step objects || objects=""
for o in $objects; do
    echo "gpu_suite: env-only bench with the $o at $obj_envs envs" >&2
    "$bin" bench configs/bench_$o.toml --backend "$adapter" --envs "$obj_envs" --chunks 5 --seconds "$bench_s" >"$out/object_$o.json" 2>"$out/object_$o.log"
    obj_json="$obj_json${obj_json:+, }$(json_of "$out/object_$o.json")"
done
baseline_json=null
if runs_step baseline; then
    if [ -z "$baseline_wgsl" ] || [ ! -f "$baseline_wgsl" ]; then
        echo "gpu_suite: step baseline needs BASELINE_WGSL, a simulator WGSL module file (benches/physics_module.sh COMMIT > FILE); got '$baseline_wgsl'" >&2
        exit 2
    fi
    rounds_json=""
    for r in $(seq 1 "$baseline_rounds"); do
        echo "gpu_suite: built-in physics against $baseline_wgsl at $baseline_envs envs, round $r" >&2
        "$bin" bench --backend "$adapter" --envs "$baseline_envs" --chunks 5 --seconds "$bench_s" >"$out/baseline_builtin_$r.json" 2>"$out/baseline_builtin_$r.log"
        "$bin" bench --backend "$adapter" --envs "$baseline_envs" --chunks 5 --seconds "$bench_s" --physics-wgsl "$baseline_wgsl" >"$out/baseline_module_$r.json" 2>"$out/baseline_module_$r.log"
        rounds_json="$rounds_json${rounds_json:+, }{\"builtin\": $(json_of "$out/baseline_builtin_$r.json"), \"baseline\": $(json_of "$out/baseline_module_$r.json")}"
    done
    # each round's ratio of env-steps/s, baseline over built-in (the built-in's cost in the
    # baseline's units), and their median
    median=$(for r in $(seq 1 "$baseline_rounds"); do
        echo "$(rate_of "$out/baseline_module_$r.json") $(rate_of "$out/baseline_builtin_$r.json")" | awk '{ if ($1 > 0 && $2 > 0) printf "%.4f\n", $1 / $2 }'
    done | median_of)
    baseline_json="{\"module\": \"$baseline_wgsl\", \"envs\": $baseline_envs, \"cost_ratio_median\": $median, \"rounds\": [$rounds_json]}"
fi
variants_json=null
if runs_step variants; then
    for m in $variants_wgsl; do
        if [ ! -f "$m" ]; then
            echo "gpu_suite: step variants needs VARIANTS_WGSL, simulator WGSL module files (benches/physics_variants.py); no file '$m'" >&2
            exit 2
        fi
    done
    rounds_json=""
    for r in $(seq 1 "$baseline_rounds"); do
        echo "gpu_suite: built-in physics and $(echo $variants_wgsl | wc -w) variant modules at $baseline_envs envs, round $r" >&2
        "$bin" bench --backend "$adapter" --envs "$baseline_envs" --chunks 5 --seconds "$bench_s" >"$out/variants_builtin_$r.json" 2>"$out/variants_builtin_$r.log"
        mods_json=""
        i=0
        for m in $variants_wgsl; do
            i=$((i + 1))
            "$bin" bench --backend "$adapter" --envs "$baseline_envs" --chunks 5 --seconds "$bench_s" --physics-wgsl "$m" >"$out/variant_${i}_$r.json" 2>"$out/variant_${i}_$r.log"
            mods_json="$mods_json${mods_json:+, }$(json_of "$out/variant_${i}_$r.json")"
        done
        rounds_json="$rounds_json${rounds_json:+, }{\"builtin\": $(json_of "$out/variants_builtin_$r.json"), \"variants\": [$mods_json]}"
    done
    # each module's rate over the built-in's of its round (above 1: the part it switches off costs
    # that factor), the median over the rounds
    ratios_json=""
    i=0
    for m in $variants_wgsl; do
        i=$((i + 1))
        median=$(for r in $(seq 1 "$baseline_rounds"); do
            echo "$(rate_of "$out/variant_${i}_$r.json") $(rate_of "$out/variants_builtin_$r.json")" | awk '{ if ($1 > 0 && $2 > 0) printf "%.4f\n", $1 / $2 }'
        done | median_of)
        ratios_json="$ratios_json${ratios_json:+, }{\"module\": \"$m\", \"rate_ratio_median\": $median}"
    done
    variants_json="{\"envs\": $baseline_envs, \"ratios\": [$ratios_json], \"rounds\": [$rounds_json]}"
fi
# a step that did not run reports null, never an earlier run's files
ppo_json=null; ppo_fused_json=null; sac_json=null; sac_lift_json=null; matmul_json=null; train_ppo=null; train_sac=null; train_host=null; ppo_run=null; sac_run=null
if runs_step learner; then
    echo "gpu_suite: learner updates" >&2
    "$bin" bench --ppo --device "$adapter" "${ppo_sizes[@]}" >"$out/ppo_update.json" 2>"$out/ppo_update.log"
    # the same with acting's forward passes one kernel per MLP whatever the batch (the default,
    # auto, leaves the peer networks at 4096 rows to a product per layer: which is faster here)
    DEXTRAIN_MLP_FORWARD=fused "$bin" bench --ppo --device "$adapter" "${ppo_sizes[@]}" >"$out/ppo_update_fused.json" 2>"$out/ppo_update_fused.log"
    if [ ${#matmul_sizes[@]} -gt 0 ]; then
        "$bin" bench --matmul --device "$adapter" "${matmul_sizes[@]}" >"$out/matmul.json" 2>"$out/matmul.log"
    fi
    "$bin" bench --sac --device "$adapter" "${sac_sizes[@]}" >"$out/sac_update.json" 2>"$out/sac_update.log"
    # the gradient step of the shipped SAC configs' shape: 3-step returns, LayerNorm critics
    "$bin" bench --sac --device "$adapter" "${sac_lift_sizes[@]}" --n-step 3 --critic-layer-norm >"$out/sac_update_lift.json" 2>"$out/sac_update_lift.log"
    ppo_json=$(json_of "$out/ppo_update.json"); ppo_fused_json=$(json_of "$out/ppo_update_fused.json"); sac_json=$(json_of "$out/sac_update.json"); [ ${#matmul_sizes[@]} -gt 0 ] && matmul_json=$(json_of "$out/matmul.json")
    sac_lift_json=$(json_of "$out/sac_update_lift.json")
fi
if runs_step train; then
    echo "gpu_suite: PPO lift for ${ppo_s}s" >&2
    train_for gpu_ppo "$ppo_s" configs/lift_cube_gpu.toml --set sim.backend="$adapter" --set train.device="$adapter" "${small[@]}"
    echo "gpu_suite: SAC lift for ${sac_s}s" >&2
    train_for gpu_sac "$sac_s" configs/lift_cube_sac_gpu.toml --set sim.backend="$adapter" --set train.device="$adapter" "${small[@]}" "${sac_small[@]}"
    echo "gpu_suite: PPO lift through the host for ${ppo_host_s}s" >&2
    train_for gpu_ppo_host "$ppo_host_s" configs/lift_cube_gpu.toml --set sim.backend="$adapter" --set train.device="$adapter" --set train.device_rollouts=false "${small[@]}"
    train_ppo=$(train_summary "$runs/gpu_ppo/metrics.csv"); train_sac=$(train_summary "$runs/gpu_sac/metrics.csv")
    train_host=$(train_summary "$runs/gpu_ppo_host/metrics.csv")
    ppo_run=$(run_json "$out/gpu_ppo.log"); sac_run=$(run_json "$out/gpu_sac.log")
fi
profile_json=null
if runs_step profile; then
    # where the lift's iteration spends the GPU's time (docs/gpu.md "Where a GPU's time goes"):
    # each kernel of ours and each stretch of the learner's work, from timestamp queries
    echo "gpu_suite: PPO lift with --gpu-profile for ${profile_s}s" >&2
    train_for gpu_ppo_profiled "$profile_s" configs/lift_cube_gpu.toml --gpu-profile --set sim.backend="$adapter" --set train.device="$adapter" "${small[@]}"
    profile_json=$(json_of "$runs/gpu_ppo_profiled/gpu_profile.json")
fi
scale_json=null
if runs_step scale; then
    # the PPO lift at larger batches than the shipped config's (the quick suite's networks small)
    scale_json=""
    for shape in $scale_shapes; do
        n=${shape%x*}; t=${shape#*x}
        case "$n$t" in *[!0-9]*|'') echo "gpu_suite: SCALE_SHAPES wants ENVSxSTEPS words (e.g. 16384x32); got '$shape'" >&2; exit 2 ;; esac
        echo "gpu_suite: PPO lift at $n envs x $t steps for ${scale_s}s" >&2
        train_for "gpu_ppo_scale_$n" "$scale_s" configs/lift_cube_gpu.toml --set sim.backend="$adapter" --set train.device="$adapter" --set sim.num_envs="$n" --set train.steps_per_env="$t" "${scale_small[@]}"
        scale_json="$scale_json${scale_json:+, }{\"envs\": $n, \"steps_per_env\": $t, \"train\": $(train_summary "$runs/gpu_ppo_scale_$n/metrics.csv"), \"run\": $(run_json "$out/gpu_ppo_scale_$n.log")}"
    done
    scale_json="[$scale_json]"
fi
driver=$( (nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader 2>/dev/null || echo unknown) | head -n 1)
{
    printf '{"suite": "dextrain_gpu", "quick": %s, "date": "%s", "driver": "%s", "wall_s": %s,\n' \
        "$([ "$quick" = 1 ] && echo true || echo false)" "$(date -u +%FT%TZ)" "$driver" "$(($(date +%s) - start))"
    printf ' "env_only": [%s],\n' "$env_json"
    printf ' "objects": [%s],\n' "$obj_json"
    printf ' "ppo_update": %s,\n "ppo_update_fused": %s,\n "sac_update": %s,\n "sac_update_lift": %s,\n "matmul_routines": %s,\n' "$ppo_json" "$ppo_fused_json" "$sac_json" "$sac_lift_json" "$matmul_json"
    printf ' "train_ppo": %s,\n "train_sac": %s,\n "train_ppo_host_path": %s,\n' "$train_ppo" "$train_sac" "$train_host"
    printf ' "train_ppo_run": %s,\n "train_sac_run": %s,\n' "$ppo_run" "$sac_run"
    printf ' "gpu_profile_ppo_lift": %s,\n' "$profile_json"
    printf ' "train_ppo_scale": %s,\n' "$scale_json"
    printf ' "physics_baseline": %s,\n' "$baseline_json"
    printf ' "physics_variants": %s,\n' "$variants_json"
    printf ' "shader_stats": %s}\n' "$stats_json"
} >"$out/gpu_suite.json"
cat "$out/gpu_suite.json"
