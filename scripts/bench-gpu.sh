#!/usr/bin/env bash
# The benchmark on a hardware GPU through its Vulkan driver (e.g. NVIDIA):
#   scripts/bench-gpu.sh [OUT_DIR] [BINARY]
# On the first adapter whose name matches $GPU_NAME (default "nvidia"):
#  1. the default run (thesis scene, friction-net, every step solved to
#     1e-3 with multigrid, 200 steps: the sphere's whole pass) at each grid
#     of $GOAL_GRIDS (default 1024), report run_N.json: the issue's goal is
#     60 steps a second at 1024² (each run cut at $RUN_TIMEOUT seconds,
#     default 600); then the same run with --no-subgroups, the solver's
#     sums through workgroup memory alone, into run_N_no_subgroups.json,
#     and with --vectors vec4, the solver's vectors a vec4 each rather
#     than packed, into run_N_vec4.json;
#  2. the short step (issue 67): the default run at each grid of
#     $SHORT_GRIDS (default "32 64"), its solves run whole in one
#     workgroup (short_N.json) and as a chain of dispatches
#     (short_N_chain.json, --whole-solve-nodes 0): the issue asks for a
#     64² step under 1 ms;
#  3. the thesis scene with self-contact (scenes/thesis.toml, 200 steps)
#     at each grid of $SELF_CONTACT_GRIDS (default "512 1024"), report
#     self_contact_N.json: issue 65 asks that it run finite;
#  4. `wgcloth bench --gpu-only`: every variant from 32² to 1024², the
#     networks' throughput, the sphere period and the batched worlds (1 to
#     1,024 worlds of the 32² run as one GpuSim against as many separate
#     ones: the issue asks for 5,000 world-steps a second), into
#     bench.json, bench.png and bench.txt.
# Both take $SUBSTEPS solves a step (default 1: the thesis's step, the one
# the goal names and the H200 figures in BENCHMARKS.md timed; 0 takes the
# scene's own, which keep the sphere within half the cloth's spacing a
# solve: 17 at 1024², 17 times the work).
# Everything printed also goes to OUT_DIR/log.txt (default target/bench-gpu),
# a line a row, so a run cut short still says how far it got.
# BINARY is a wgcloth built elsewhere (a machine with a GPU but no Rust
# toolchain); without it the script builds one. It refuses a software
# adapter: that is what `wgcloth bench` on lavapipe measures.
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-target/bench-gpu}
bin=${2:-}
name=${GPU_NAME:-nvidia}
goal_grids=${GOAL_GRIDS:-1024}
substeps=${SUBSTEPS:-1}

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
exec > >(tee -a "$out/log.txt") 2>&1
# A run of one step first: it names the adapter, or says why none matches.
"$bin" run --backend gpu --grid 8 --steps 1 --report "$out/probe.json" >/dev/null
adapter=$(sed -n 's/.*"adapter": *"\([^"]*\)".*/\1/p' "$out/probe.json")
case "$adapter" in
  *Cpu*) echo "error: '$adapter' is a software adapter; set GPU_NAME to a hardware one"; exit 2 ;;
esac
echo "adapter: $adapter"
for n in $goal_grids; do
  for variant in "" --no-subgroups "--vectors vec4"; do
    echo "== default run, ${n}² ${variant}"
    case "$variant" in
      "") report=$out/run_$n.json ;;
      --no-subgroups) report=$out/run_${n}_no_subgroups.json ;;
      *) report=$out/run_${n}_vec4.json ;;
    esac
    # A run that fails or outlasts $RUN_TIMEOUT seconds leaves the bench to run.
    if ! timeout "${RUN_TIMEOUT:-600}" "$bin" run --backend gpu --scene sphere --grid "$n" --steps 200 \
      --substeps "$substeps" $variant --report "$report"; then
      echo "the ${n}² run ${variant} failed or outlasted ${RUN_TIMEOUT:-600} s"
    fi
  done
done
for n in ${SHORT_GRIDS:-32 64}; do
  for variant in "" "--whole-solve-nodes 0"; do
    echo "== the short step, ${n}² ${variant}"
    case "$variant" in
      "") report=$out/short_$n.json ;;
      *) report=$out/short_${n}_chain.json ;;
    esac
    if ! timeout "${RUN_TIMEOUT:-600}" "$bin" run --backend gpu --scene sphere --grid "$n" --steps 200 \
      $variant --report "$report"; then
      echo "the ${n}² short-step run ${variant} failed or outlasted ${RUN_TIMEOUT:-600} s"
    fi
  done
done
for n in ${SELF_CONTACT_GRIDS:-512 1024}; do
  echo "== thesis scene with self-contact, ${n}²"
  if ! timeout "${RUN_TIMEOUT:-600}" "$bin" run --backend gpu --config scenes/thesis.toml --grid "$n" \
    --steps 200 --report "$out/self_contact_$n.json"; then
    echo "the ${n}² self-contact run failed or outlasted ${RUN_TIMEOUT:-600} s"
  fi
done
echo "== wgcloth bench --gpu-only"
"$bin" bench --gpu-only --substeps "$substeps" --report "$out/bench.json" --plot "$out/bench.png" | tee "$out/bench.txt"
