#!/usr/bin/env bash
# Installs what is missing, builds the wasm package (skips what is up to date) and serves the page on 127.0.0.1.
# Usage: npm start [-- PORT]   (or PORT=8080 npm start)
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
bash scripts/build-web.sh
exec node scripts/serve.mjs "$@"
