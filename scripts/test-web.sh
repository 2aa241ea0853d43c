#!/usr/bin/env bash
# The browser test: builds the demo (scripts/build-web.sh), serves it on
# localhost and drives headless Chromium (Debian's, installed here when
# missing; WebGPU on SwiftShader) through it with puppeteer-core (pinned in
# web/test/package-lock.json). Screenshots go to target/web-test/. A
# missing browser or WebGPU adapter fails; nothing is skipped.
set -euo pipefail
cd "$(dirname "$0")/.."

if ! command -v chromium >/dev/null; then
  echo "installing chromium"
  sudo=""; [ "$(id -u)" = 0 ] || sudo="sudo"
  $sudo apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq chromium >/dev/null
fi
if ! command -v node >/dev/null || ! command -v npm >/dev/null; then
  echo "installing nodejs and npm"
  sudo=""; [ "$(id -u)" = 0 ] || sudo="sudo"
  $sudo apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq nodejs npm >/dev/null
fi
bash scripts/build-web.sh
(cd web/test && npm ci --no-audit --no-fund --silent)
node web/test/browser.mjs target/web target/web-test
