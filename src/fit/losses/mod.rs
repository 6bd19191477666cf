//! Loss terms of Step 1. Each takes evaluated Gaussians or point sets and returns
//! its value, adding its analytic gradient to the caller's accumulators. Point-level
//! losses (Chamfer, EMD, flow) return dL/dpoint; the caller chains it through the
//! transfer (`GradAcc::transfer_backward`) and the 6D map.
//!
//! Normalisation (documented deviation from the paper's raw sums): every term is a
//! mean over its points (and, for the transfer terms, summed over target frames), so
//! the value — and Adam's effective step — does not depend on the subsample size.
//! Adam is invariant to a global scale of the loss in one step, so only the relative
//! weights within a step matter; the separation term is weighted by 1/N (N the frame's
//! point count) to keep the paper's ratio of Σ-over-points MLE to L_sep.

pub mod chamfer;
pub mod emd;
pub mod flow;
pub mod mle;
pub mod sep;
