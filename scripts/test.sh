#!/usr/bin/env bash
# The whole test suite, exactly as CI runs it (.ci/run calls this script).
# Needs the Rust toolchain; installs rustfmt/clippy and, when no Vulkan
# driver is present, Mesa's lavapipe (software Vulkan) for the GPU tests.
set -euo pipefail
cd "$(dirname "$0")/.."
export CARGO_TERM_COLOR=never

if ! { ls /usr/share/vulkan/icd.d/*.json && ldconfig -p | grep -q libvulkan.so.1; } >/dev/null 2>&1; then
  echo "no Vulkan driver: installing mesa-vulkan-drivers (lavapipe)"
  sudo=""; [ "$(id -u)" = 0 ] || sudo="sudo"
  $sudo apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq mesa-vulkan-drivers libvulkan1 >/dev/null
fi
# Fill fresh GPU allocations with garbage so reads of unwritten memory show.
export LVP_POISON_MEMORY=true

for component in rustfmt clippy; do
  rustup component list --installed 2>/dev/null | grep -q "^$component" || rustup component add "$component"
done

cargo fmt --all --check
cargo clippy --release --workspace --all-targets --features wgcloth-cli/viewer -- -D warnings
# The library alone, with its default features, as an app gets it: no CLI,
# training, image or plotting crate in its tree, and it builds by itself.
bash scripts/check-library.sh
# With the viewer's feature, as clippy checks it: one build for the tests
# and every example, the viewer's included (run below).
cargo test --release --workspace --features wgcloth-cli/viewer
# The embedding example (the crate docs' example) on a default-limits device.
cargo run --release -p wgcloth --example embed
# The library in a real browser: the demo page in headless Chromium's WebGPU.
bash scripts/test-web.sh
# The Python package as a user installs it (pip builds it with maturin),
# in a virtual environment of its own, checked by pytest against the
# `wgcloth` command built above.
if ! python3 -c "import ensurepip, venv" >/dev/null 2>&1; then
  echo "no Python venv module: installing python3-venv"
  sudo=""; [ "$(id -u)" = 0 ] || sudo="sudo"
  $sudo apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq python3-venv python3-pip >/dev/null
fi
python3 -m venv target/py
target/py/bin/pip install --quiet --disable-pip-version-check "./crates/wgcloth-py[test]"
WGCLOTH_BIN="$PWD/target/release/wgcloth" target/py/bin/python -m pytest -q crates/wgcloth-py/tests

# The interactive viewer (examples/viewer.rs, feature `viewer`, built by
# the tests above): without a display it must fail with one clear line and
# exit code 2; with Xvfb here it must run a few frames.
set +e
message=$(env -u DISPLAY -u WAYLAND_DISPLAY target/release/examples/viewer 2>&1)
code=$?
set -e
if [ "$code" != 2 ] || ! grep -q "no display" <<<"$message"; then
  echo "viewer without a display: exit $code: $message"
  exit 1
fi
if command -v xvfb-run >/dev/null; then
  xvfb-run -a target/release/examples/viewer --grid 16 --frames 30
fi
echo "viewer: ok"
