//! Thin wasm glue (cfg wasm32): the worker API and the wgpu viewer.

pub mod api;
pub mod bench;
pub mod viewer;
