//! Metrics of SPEC §5 (Reart-compatible): Rand index, reconstruction and flow
//! error, tree edit distance, re-animation error.
