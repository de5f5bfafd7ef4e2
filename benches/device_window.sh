#!/usr/bin/env bash
# One call of a lent GPU machine: installs the carried Vulkan and GL libraries where the machine
# lacks a Vulkan loader, unpacks the carried binary and runs benches/gpu_suite.sh's steps, then packs
# every result into one tarball under $OUT (only a few files come back from a call).
#     (here)     cargo build --release && benches/device_pack.sh device
#     (device)   benches/device_window.sh device      # the device tool's run, carry ["device"]
# Environment: STEPS (default "shader_stats env baseline variants"; then, in a second call,
# "learner train profile scale": the rest of the figures), VARIANTS_WGSL (default: the variants of
# device/variants/ not yet timed on an H200), and whatever gpu_suite.sh reads (ENVS, BENCH_S,
# TRAIN_PPO_S, …). On an H200 (2026-12-01) a bench run at 65,536 envs took ~12 s with BENCH_S 2:
# "baseline variants" with 5 variants over 2 rounds 172 s, "shader_stats env variants learner
# train" with 3 variants, ENVS "4096 16384", TRAIN_PPO_S 30, TRAIN_SAC_S 20 and TRAIN_PPO_HOST_S 10
# 291 s; a machine's start ~30 s more. The defaults: ENVS "16384 65536", BENCH_S 2,
# BASELINE_ROUNDS 3, TRAIN_PPO_S 60, TRAIN_SAC_S 40, TRAIN_PPO_HOST_S 15, and gpu_suite.sh's
# TRAIN_PROFILE_S 20 and TRAIN_SCALE_S 40: by those times the second call at the defaults takes
# ~470 s (291 s + 55 s of longer runs + the profiled run + two 40 s runs at 16,384 and 65,536 envs
# with their start-up), under a call's 10 minutes.
set -uo pipefail
dir=${1:-device}
out=${OUT:-device_out}
mkdir -p "$out"
log="$out/window.log"
if [ ! -f "$dir/dextrain.gz" ]; then
    echo "device_window.sh: no $dir/dextrain.gz (benches/device_pack.sh $dir makes it)" >&2
    exit 2
fi
{
    echo "device_window.sh: $(cat "$dir/commit" 2>/dev/null || echo '?') against $(cat "$dir/baseline_commit" 2>/dev/null || echo '?'), $(date -u +%FT%TZ)"
    nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader 2>&1 || true
    # the Vulkan loader and the GL vendor libraries, where the machine has none
    if ! ldconfig -p | grep -q 'libvulkan.so.1'; then
        for f in "$dir"/debs/*.deb; do dpkg -x "$f" /; done
        ldconfig
        echo "installed: $(ls "$dir"/debs | tr '\n' ' ')"
    fi
} >"$log" 2>&1
gunzip -c "$dir/dextrain.gz" >"$out/dextrain.bin" && chmod +x "$out/dextrain.bin"
baseline=$(ls "$dir"/*.wgsl 2>/dev/null | grep -v '/head.wgsl$' | head -n 1)
# the variants the step times by default: those not yet timed on an H200 at the default batch,
# 65,536 envs (the knock-outs, the "twice" variants, the module before the rounds and the
# workgroup sizes were, on 2026-12-01: BENCHMARKS.md "The GPU window of 2026-12-01" and "The
# step's workgroup size"; VARIANTS_WGSL names any of device/variants/ to time them again). The
# small batch's memory variants want a call of their own at the lift configs' 2,048 envs:
#     STEPS="shader_stats variants" BASELINE_ENVS=2048 BASELINE_ROUNDS=2 BENCH_S=1 \
#         VARIANTS_WGSL="$(ls device/variants/wg32_*.wgsl)" benches/device_window.sh device
default_variants=$(ls "$dir"/variants/collider_words_*.wgsl "$dir"/variants/wg512_*.wgsl 2>/dev/null | tr '\n' ' ')
STEPS=${STEPS:-shader_stats env baseline variants} ENVS=${ENVS:-16384 65536} BENCH_S=${BENCH_S:-2} BASELINE_ROUNDS=${BASELINE_ROUNDS:-3} \
    TRAIN_PPO_S=${TRAIN_PPO_S:-60} TRAIN_SAC_S=${TRAIN_SAC_S:-40} TRAIN_PPO_HOST_S=${TRAIN_PPO_HOST_S:-15} \
    BASELINE_WGSL=${BASELINE_WGSL:-$baseline} VARIANTS_WGSL=${VARIANTS_WGSL:-$default_variants} \
    benches/gpu_suite.sh --bin "$out/dextrain.bin" --out "$out/suite" "${@:2}" >>"$log" 2>&1
status=$?
echo "gpu_suite.sh exit $status" >>"$log"
rm -f "$out/dextrain.bin"
rm -rf "$out/suite/runs/"*/checkpoints
tar czf "$out/results.tgz" -C "$out" window.log suite
echo "device_window.sh: $out/results.tgz ($(du -k "$out/results.tgz" | cut -f1) KiB), gpu_suite.sh exit $status"
tail -n 25 "$log"
exit "$status"
