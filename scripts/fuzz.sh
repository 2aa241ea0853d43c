#!/usr/bin/env bash
# Fuzzes the loaders (TARGETs, default all: weights obj config) for
# SECONDS each (default 600), one after another, from fuzz/seeds.
#   scripts/fuzz.sh [SECONDS [TARGET...]]
# Needs a nightly toolchain and cargo-fuzz:
#   rustup toolchain install nightly && cargo install cargo-fuzz
# New inputs go to fuzz/corpus/TARGET; a crash goes to fuzz/artifacts/TARGET
# and stops that target with its reproduction command; the others still run.
set -euo pipefail
cd "$(dirname "$0")/../fuzz"
seconds=${1:-600}
shift || true
targets=("$@")
[ ${#targets[@]} -gt 0 ] || targets=(weights obj config)
# -s none: our code and the loaders are safe Rust, so no AddressSanitizer;
# -a keeps debug assertions (integer overflow) on.
cargo +nightly fuzz build -s none -a
crashed=()
for target in "${targets[@]}"; do
    mkdir -p "corpus/$target"
    dict=()
    [ -f "dicts/$target.dict" ] && dict=("-dict=dicts/$target.dict")
    echo "== $target, $seconds s"
    cargo +nightly fuzz run -s none -a "$target" "corpus/$target" "seeds/$target" -- \
        -max_total_time="$seconds" -max_len=16384 -timeout=10 -print_final_stats=1 "${dict[@]}" \
        || crashed+=("$target")
done
if [ ${#crashed[@]} -gt 0 ]; then
    echo "crashed: ${crashed[*]} (inputs in fuzz/artifacts; fix, then keep each in fuzz/regressions/TARGET)"
    exit 1
fi
