#!/usr/bin/env bash
# The browser demo into target/web/: index.html, the JS glue, the .wasm and
# the shipped weights. Serve it with `python3 -m http.server -d target/web`.
# Installs the wasm32 target and wasm-bindgen-cli (pinned to the
# wasm-bindgen in Cargo.lock) where they are missing.
set -euo pipefail
cd "$(dirname "$0")/.."

rustup target list --installed 2>/dev/null | grep -q '^wasm32-unknown-unknown$' ||
  rustup target add wasm32-unknown-unknown
version=$(awk '/^name = "wasm-bindgen"$/ { getline; gsub(/[^0-9.]/, ""); print; exit }' Cargo.lock)
if ! wasm-bindgen --version 2>/dev/null | grep -q " $version\$"; then
  echo "installing wasm-bindgen-cli $version"
  cargo install wasm-bindgen-cli --version "$version"
fi

cargo build --release -p wgcloth-web --target wasm32-unknown-unknown
rm -rf target/web
mkdir -p target/web
wasm-bindgen --target web --no-typescript --out-dir target/web \
  target/wasm32-unknown-unknown/release/wgcloth_web.wasm
cp web/index.html target/web/
cp crates/wgcloth/weights/*.safetensors target/web/
ls -l target/web
