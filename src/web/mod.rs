//! Thin wasm glue (cfg wasm32): the worker API and the wgpu viewer.

pub mod api;
pub mod bench;
// Rendering only: no fit result depends on the bits of its trigonometry.
#[allow(clippy::disallowed_methods)]
pub mod viewer;
