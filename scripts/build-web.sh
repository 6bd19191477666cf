#!/usr/bin/env bash
# Builds the wasm package the page loads (www/pkg): cargo (release, wasm32) →
# wasm-bindgen (--target web) → wasm-opt -O3 (npm binaryen; Debian's wasm-opt is broken).
# Each step is skipped when its output is newer than its input, so a second run is quick.
set -euo pipefail
cd "$(dirname "$0")/.."

WASM_BINDGEN_VERSION=0.2.130
OUT=www/pkg
RAW=target/wasm32-unknown-unknown/release/gsart.wasm
# GSART_SIMD=1: the wasm simd128 variant, measured by bench/wasm-vs-native.mjs (not the
# page's build), into target/pkg-simd with its own target dir so the default cache stays.
SIMD_OPT=()
if [ "${GSART_SIMD:-0}" = 1 ]; then
  OUT=target/pkg-simd
  export CARGO_TARGET_DIR=target/simd
  export CARGO_TARGET_WASM32_UNKNOWN_UNKNOWN_RUSTFLAGS="-C target-feature=+simd128"
  RAW=$CARGO_TARGET_DIR/wasm32-unknown-unknown/release/gsart.wasm
  SIMD_OPT=(--enable-simd)
fi
STAMP=$OUT/.built-from

die() { echo "build-web: $*" >&2; exit 1; }

command -v cargo >/dev/null || die "cargo not found (install Rust: https://rustup.rs)"
if command -v rustup >/dev/null && ! rustup target list --installed | grep -qx wasm32-unknown-unknown; then
  die "the wasm32 target is missing: run 'rustup target add wasm32-unknown-unknown' (or npm run setup)"
fi
command -v wasm-bindgen >/dev/null || die "wasm-bindgen not found: cargo install wasm-bindgen-cli --version $WASM_BINDGEN_VERSION"
have=$(wasm-bindgen --version | awk '{print $2}')
[ "$have" = "$WASM_BINDGEN_VERSION" ] || die "wasm-bindgen $have installed, the crate needs $WASM_BINDGEN_VERSION: cargo install wasm-bindgen-cli --version $WASM_BINDGEN_VERSION --force"
WASM_OPT=node_modules/.bin/wasm-opt
[ -x "$WASM_OPT" ] || die "wasm-opt not found in node_modules: run 'npm install'"

echo "build-web: cargo build --release --target wasm32-unknown-unknown --lib"
cargo build --release --target wasm32-unknown-unknown --lib

# Skip bindgen + wasm-opt when the raw module did not change since the last build.
sum=$(cksum < "$RAW" | awk '{print $1"-"$2}')
if [ -f "$STAMP" ] && [ -f "$OUT/gsart_bg.wasm" ] && [ -f "$OUT/gsart.js" ] && [ "$(cat "$STAMP")" = "$sum" ]; then
  echo "build-web: $OUT is up to date"
  exit 0
fi

echo "build-web: wasm-bindgen --target web --out-dir $OUT"
rm -rf "$OUT.tmp"
wasm-bindgen --target web --no-typescript --out-dir "$OUT.tmp" "$RAW"

echo "build-web: wasm-opt -O3"
# Features the stable wasm32 target emits by default; wasm-opt must be told about them.
"$WASM_OPT" -O3 "${SIMD_OPT[@]}" \
  --enable-bulk-memory --enable-nontrapping-float-to-int --enable-sign-ext \
  --enable-mutable-globals --enable-reference-types --enable-multivalue \
  "$OUT.tmp/gsart_bg.wasm" -o "$OUT.tmp/gsart_bg.opt.wasm"
mv "$OUT.tmp/gsart_bg.opt.wasm" "$OUT.tmp/gsart_bg.wasm"
echo "$sum" > "$OUT.tmp/.built-from"
rm -rf "$OUT"
mv "$OUT.tmp" "$OUT"
size=$(wc -c < "$OUT/gsart_bg.wasm")
gz=$(gzip -c "$OUT/gsart_bg.wasm" | wc -c)
echo "build-web: $OUT/gsart_bg.wasm $((size / 1024)) KiB ($((gz / 1024)) KiB gzip)"
