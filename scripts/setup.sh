#!/usr/bin/env bash
# Installs everything the project needs, skipping what is already there (idempotent):
# the wasm32 Rust target, wasm-bindgen-cli pinned to the crate's version, Debian's
# Chromium + ChromeDriver, the npm packages (playwright-core, binaryen/wasm-opt), and
# yourdfpy and numpy from PyPI (the URDF export is checked with a standard parser, the
# NumPy frame reader against files numpy itself writes).
set -euo pipefail
cd "$(dirname "$0")/.."

WASM_BINDGEN_VERSION=$(sed -n 's/^wasm-bindgen = "=\([0-9.]*\)"/\1/p' Cargo.toml)
SUDO=""
[ "$(id -u)" = 0 ] || SUDO="sudo"

if ! rustup target list --installed | grep -qx wasm32-unknown-unknown; then
  echo "setup: adding the wasm32-unknown-unknown target"
  rustup target add wasm32-unknown-unknown
fi

if ! wasm-bindgen --version 2>/dev/null | grep -q " $WASM_BINDGEN_VERSION\$"; then
  echo "setup: installing wasm-bindgen-cli $WASM_BINDGEN_VERSION (a few minutes, once)"
  # --locked fails to resolve for this version; pin the version only.
  cargo install wasm-bindgen-cli --version "$WASM_BINDGEN_VERSION"
fi

if [ ! -x /usr/bin/chromium ] || [ ! -x /usr/bin/chromedriver ]; then
  echo "setup: installing Debian's chromium and chromium-driver"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq chromium chromium-driver
fi

if [ ! -d node_modules/playwright-core ] || [ ! -d node_modules/binaryen ] || [ package.json -nt node_modules/.package-lock.json ]; then
  echo "setup: npm packages"
  if [ -f package-lock.json ]; then npm ci --no-audit --no-fund; else npm install --no-audit --no-fund; fi
fi
if ! python3 -c "import yourdfpy, numpy" >/dev/null 2>&1; then
  echo "setup: pip install yourdfpy numpy (a standard URDF parser, and numpy's own files, for the tests)"
  python3 -m pip install --quiet yourdfpy numpy
fi
echo "setup: ready"
