#!/usr/bin/env bash
# The library crate as an app depends on it (default features): it builds
# on its own, its normal dependency tree stays within 90 crates, and none of
# the crates that belong to the CLI or the training side is in it; its
# docs build cleanly; and it builds for the browser (wasm32 with wgpu's
# WebGPU backend, as a web app would enable it).
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release -p wgcloth
tree=$(cargo tree -p wgcloth -e normal --prefix none | sort -u)
count=$(wc -l <<<"$tree")
echo "wgcloth's normal dependency tree: $count crates"
if [ "$count" -gt 90 ]; then
  echo "more than 90 crates"
  exit 1
fi
for banned in candle-core candle-nn tokenizers clap image gif png indicatif tobj env_logger euc openusd pyo3 numpy; do
  if grep -q "^$banned v" <<<"$tree"; then
    echo "the library's tree holds $banned"
    exit 1
  fi
done
# Every public item documented (#![warn(missing_docs)] in lib.rs, an
# error under clippy's -D warnings), and the docs build without a warning.
RUSTDOCFLAGS="-D warnings" cargo doc --release -p wgcloth --no-deps

rustup target list --installed 2>/dev/null | grep -q '^wasm32-unknown-unknown$' ||
  rustup target add wasm32-unknown-unknown
cargo build --release -p wgcloth --target wasm32-unknown-unknown --features wgpu/webgpu
