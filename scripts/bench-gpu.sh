#!/usr/bin/env bash
# The benchmark on a hardware GPU through its Vulkan driver (e.g. NVIDIA):
#   scripts/bench-gpu.sh [OUT_DIR] [BINARY]
# runs `wgcloth bench` (32² to 256², and 512² and 1024² since the adapter
# is not a CPU) on the first adapter whose name matches $GPU_NAME (default
# "nvidia"), writing bench.json, bench.png and bench.txt into OUT_DIR
# (default target/bench-gpu). BINARY is a wgcloth built elsewhere (a machine
# with a GPU but no Rust toolchain); without it the script builds one.
# It refuses to run on a software adapter: that is what `wgcloth bench` on
# lavapipe measures.
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-target/bench-gpu}
bin=${2:-}
name=${GPU_NAME:-nvidia}

if [ -z "$bin" ]; then
  cargo build --release -p wgcloth-cli
  bin=target/release/wgcloth
fi
[ -x "$bin" ] || { echo "error: $bin is not an executable wgcloth"; exit 2; }

# NVIDIA's Vulkan ICD where a container mounts the driver outside the
# loader's search path.
for icd in /usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json /usr/share/vulkan/icd.d/nvidia_icd.json; do
  if [ -z "${VK_DRIVER_FILES:-}" ] && [ -f "$icd" ]; then
    export VK_DRIVER_FILES=$icd
  fi
done
export WGPU_BACKEND=${WGPU_BACKEND:-vulkan}
export WGPU_ADAPTER_NAME=$name

mkdir -p "$out"
# A run of one step first: it names the adapter, or says why none matches.
"$bin" run --backend gpu --grid 8 --steps 1 --report "$out/probe.json" >/dev/null
adapter=$(sed -n 's/.*"adapter": *"\([^"]*\)".*/\1/p' "$out/probe.json")
case "$adapter" in
  *Cpu*) echo "error: '$adapter' is a software adapter; set GPU_NAME to a hardware one"; exit 2 ;;
esac
echo "adapter: $adapter"
"$bin" bench --report "$out/bench.json" --plot "$out/bench.png" | tee "$out/bench.txt"
