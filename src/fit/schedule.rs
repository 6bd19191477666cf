//! Iteration schedules: the paper's counts and the faster presets, plus the
//! per-iteration sizes (subsamples) that set the cost of one iteration.

use crate::pipeline::Quality;

#[derive(Debug, Clone, PartialEq)]
pub struct Schedule {
    /// Step-1 iterations (each = one MLE+sep step and one transfer step).
    pub iters: usize,
    /// Iteration from which EMD replaces Chamfer.
    pub emd_start: usize,
    /// Warm-up iterations on the first frame (MLE + sep only).
    pub warmup: usize,
    pub lr: f64,
    pub warmup_lr: f64,
    /// Source points per iteration (MLE batch and transferred points).
    pub batch: usize,
    /// Points per cloud in one EMD assignment.
    pub emd_n: usize,
    /// An EMD assignment of a frame pair is re-solved every this many uses.
    pub emd_refresh: usize,
}

impl Schedule {
    /// Preset for a quality level; `small` = sparse/small object (the paper's Sapien
    /// schedule), otherwise the robot schedule.
    pub fn preset(q: Quality, small: bool) -> Self {
        let (iters, emd_start) = match (q, small) {
            (Quality::Paper, false) => (15_000, 5_000),
            (Quality::Paper, true) => (2_500, 1_000),
            (Quality::Balanced, false) => (3_000, 1_000),
            (Quality::Balanced, true) => (1_500, 600),
            (Quality::Fast, false) => (1_200, 400),
            (Quality::Fast, true) => (800, 300),
        };
        Schedule {
            iters,
            emd_start,
            warmup: 200,
            lr: 2e-3,
            warmup_lr: 1e-2,
            batch: 512,
            emd_n: 128,
            emd_refresh: 4,
        }
    }

    /// Overrides the iteration count keeping the EMD switch at the same fraction.
    pub fn with_iters(mut self, iters: usize) -> Self {
        let frac = self.emd_start as f64 / self.iters.max(1) as f64;
        self.iters = iters;
        self.emd_start = (iters as f64 * frac).round() as usize;
        self
    }
}
