//! The core's wasm checks inside a dedicated Web Worker of headless Chromium (where
//! the page's fitting jobs run).
#![cfg(target_arch = "wasm32")]
wasm_bindgen_test::wasm_bindgen_test_configure!(run_in_dedicated_worker);
mod wasm_common;
