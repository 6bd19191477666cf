//! GSArt: articulated models (part segmentation, part poses, a kinematic tree of
//! 1-DOF joints) from a sequence of 3D point clouds, fitted with dynamic 3D Gaussians.
//!
//! The core (everything but `web`) is platform-free: it compiles for the host and
//! for `wasm32-unknown-unknown`, and never touches browser types.

#[cfg(not(target_arch = "wasm32"))]
pub mod bench;
pub mod bench_step1;
pub mod edit;
pub mod error;
pub mod eval;
pub mod fit;
pub mod geom;
pub mod io;
pub mod key_frames;
pub mod kinematics;
pub mod math;
pub mod normalisation;
pub mod pipeline;
pub mod synth;

#[cfg(target_arch = "wasm32")]
pub mod web;

pub use error::{Error, Result};
