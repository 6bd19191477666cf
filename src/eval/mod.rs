//! Metrics of SPEC §5 (Reart-compatible): Rand index, reconstruction and flow
//! error, tree edit distance, re-animation error.

pub mod motion_error;
pub mod rand_index;
pub mod tree_edit;
