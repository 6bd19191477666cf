//! wasm-bindgen API over the core for the page and its workers: PLY parsing,
//! built-in examples, one Step-1 candidate per worker, finishing (selection and
//! Steps 2–3), metrics, re-posing through forward kinematics, and exports.
//! Only conversions live here; every decision is made by the core.

use wasm_bindgen::prelude::*;

/// Installs the panic hook so a bug shows a readable message in the console.
#[wasm_bindgen(start)]
pub fn start() {
    console_error_panic_hook::set_once();
}

/// Crate version, shown in the page footer.
#[wasm_bindgen]
pub fn version() -> String {
    env!("CARGO_PKG_VERSION").to_string()
}
