//! Procedural articulated objects (laptop, cabinet, arm, hand, quadruped) written in
//! the benchmark format, with occluded variants and held-out poses.
