//! wasm export of the Step-1 iteration benchmark (`bench/wasm-vs-native.mjs` calls it
//! in a dedicated Web Worker, like the page's fits): the same
//! `crate::bench_step1::run` as `gsart bench --step1-only`, timed with
//! `performance.now()` (available in windows and workers alike).

use serde::Serialize;
use wasm_bindgen::prelude::*;

#[wasm_bindgen]
extern "C" {
    // The global `performance` object exists in both a window and a worker.
    #[wasm_bindgen(js_namespace = performance, js_name = now)]
    fn performance_now() -> f64;
}

/// Fits candidate `m` of `workload` ("robot" or "object") for `iters` Step-1
/// iterations with `seed` and returns the timings as a plain object:
/// `{workload, object, frames, points, m, seed, iterations, ms_total, ms_prepare,
/// ms_warmup_init, ms_loop, ms_per_iter, ms_finish, final_chamfer, labels_hash}`.
#[wasm_bindgen]
pub fn bench_step1(workload: &str, m: usize, iters: usize, seed: u64) -> Result<JsValue, JsError> {
    let clock = || performance_now();
    let r = crate::bench_step1::run(workload, m, iters, seed, &clock)
        .map_err(|e| JsError::new(&e.to_string()))?;
    // json_compatible: a plain object, and the f64 Chamfer keeps every bit.
    r.serialize(&serde_wasm_bindgen::Serializer::json_compatible())
        .map_err(|e| JsError::new(&format!("internal: cannot convert to JS: {e}")))
}
