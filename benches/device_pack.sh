#!/usr/bin/env bash
# Packs what a lent GPU machine needs for benches/device_window.sh into one git-ignored folder
# (default device/), to be named in the device tool's `carry`: the stripped, gzipped release
# binary, the Vulkan loader's and the GL vendor libraries' Debian packages (the bare machine has
# the NVIDIA driver but not these: without libglvnd0/libegl1 wgpu finds no adapter), the simulator
# module of BASELINE_COMMIT (default f7d02e5, the physics before issue 36's contacts), the
# knock-out variants of today's module (benches/physics_variants.py) and PREVIOUS_COMMIT's module
# (default af98c83, before the narrow-phase rounds) beside them.
#     cargo build --release && benches/device_pack.sh [DIR]
# Run from the repository root, on the machine with the toolchain (it needs `apt-get download`).
set -euo pipefail
dir=${1:-device}
baseline=${BASELINE_COMMIT:-f7d02e5}
bin=target/release/dextrain
if [ ! -x "$bin" ]; then
    echo "device_pack.sh: no $bin: run cargo build --release first" >&2
    exit 1
fi
if [ -n "$(find src shaders -newer "$bin" -print -quit)" ]; then
    echo "device_pack.sh: $bin is older than the sources: run cargo build --release first" >&2
    exit 1
fi
rm -rf "$dir"
mkdir -p "$dir/debs" "$dir/variants"
strip -o "$dir/dextrain" "$bin"
gzip -9 "$dir/dextrain"
(cd "$dir/debs" && apt-get download -q libvulkan1 libegl1 libglvnd0 libopengl0 libgl1 libglx0 libgles2 >/dev/null)
benches/physics_module.sh "$baseline" >"$dir/$baseline.wgsl"
benches/physics_module.sh HEAD >"$dir/head.wgsl"
benches/physics_variants.py "$dir/head.wgsl" "$dir/variants" >/dev/null
# the module before the narrow phases were shared out over the workgroup (each env walking its own
# list of queries), timed against today's by the suite's step `variants` like the knock-outs
previous=${PREVIOUS_COMMIT:-af98c83}
benches/physics_module.sh "$previous" >"$dir/variants/before_rounds_$previous.wgsl"
echo "$baseline" >"$dir/baseline_commit"
git rev-parse --short HEAD >"$dir/commit"
size=$(du -sm "$dir" | cut -f1)
echo "device_pack.sh: $dir ($size MiB; the carry limit is 64 MiB): $(ls "$dir" | tr '\n' ' ')"
if [ "$size" -gt 63 ]; then
    echo "device_pack.sh: $dir is over the 64 MiB a device call carries" >&2
    exit 1
fi
