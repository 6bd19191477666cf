#!/usr/bin/env bash
# Runs every test: native (unit + integration), the core's wasm tests in headless
# Chromium (page thread and dedicated worker), the viewer's wasm tests, and the page
# tests driving the real page in headless Chromium. Installs what is missing first.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh

export CHROMEDRIVER=/usr/bin/chromedriver
start=$(date +%s)
step() { echo; echo "=== $* ($(( $(date +%s) - start )) s)"; }

step "native tests"
cargo test --all-targets

step "wasm tests in headless Chromium"
wasm_tests=()
for f in tests/wasm_*.rs; do [ -e "$f" ] && wasm_tests+=(--test "$(basename "$f" .rs)"); done
if [ ${#wasm_tests[@]} -gt 0 ]; then
  cargo test --target wasm32-unknown-unknown "${wasm_tests[@]}"
fi

step "build the page"
bash scripts/build-web.sh

step "page tests in headless Chromium"
mkdir -p test-artifacts
node --test --test-concurrency=1 tests/page/

step "all tests passed"
