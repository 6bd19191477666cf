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
    /// Points per cloud in one EMD assignment. Exact LAPJV on subsamples, each
    /// (source, target) pair's assignment reused for `emd_refresh` uses: with 256
    /// points and refresh 3 the solver took 76 % of the run time (perf); 128 / 4
    /// costs ~13× less and the EMD-vs-no-EMD ablation showed no accuracy difference
    /// at this size.
    pub emd_n: usize,
    /// An EMD assignment of a frame pair is re-solved every this many uses.
    pub emd_refresh: usize,
    /// Motion re-segmentation rounds after the global pose search, each followed by
    /// a new search (`fit::motion_seg`). Measured (bench-dev full, the seven robots
    /// at their selected part counts, end to end): Fast with 1 / 2 / 3 rounds mean
    /// recon 1.82 / 1.08 / 0.98, TED 2.29 / 2.57 / 2.57, RI 0.881 / 0.893 / 0.890;
    /// Balanced with 2 / 3 rounds recon 1.11 / 0.93, flow 1.27 / 1.01, TED 3.00 /
    /// 2.14, re-animation 3.20 / 2.92, RI 0.887 / 0.892. A round costs about a third
    /// of the search.
    pub reseg_rounds: usize,
    /// Rotations tried per Gaussian and frame by the pose searches after a
    /// re-segmentation (the first search tries 2048). Measured (bench-dev full, Fast,
    /// default selection; mean RI / recon / flow / TED / re-animation, s per
    /// sequence natively): 2048: 0.889 / 1.06 / 1.21 / 2.86 / 3.07, 13.1 s; 1024:
    /// 0.876 / 1.01 / 1.03 / 2.14 / 2.30, 10.9 s; 512: 0.857 / 1.06 / 1.18 / 3.14 /
    /// 2.83, 10.2 s.
    pub later_rotations: usize,
    /// Divides `iters` when the global pose search ran: the main loop then only
    /// polishes. Measured (bench-dev full, Step-1 poses, true part count, Fast):
    /// 300 iterations recon / flow / RI 1.67 / 1.70 / 0.798 vs 1.65 / 1.66 / 0.796
    /// with 1200; Fast end to end (with 1024 later rotations) 100 instead of 300
    /// iterations: 0.874 / 1.02 / 1.01 / 2.00 / 2.32 vs 0.876 / 1.01 / 1.03 / 2.14 /
    /// 2.30, 9.8 instead of 10.9 s per sequence. Balanced end to end, 300 instead of
    /// 750 iterations (session 7): RI 0.888 vs 0.891, recon 0.85 vs 0.83, flow 0.85 vs
    /// 0.85, TED 2.43 vs 2.57, re-animation 2.65 vs 2.51 — differences at the level
    /// of seed noise — for about a fifth less time per candidate.
    pub searched_divisor: usize,
    /// `searched_divisor` on occluded input, where the polish after the occluded search
    /// also sets how well the Gaussians follow each frame's visible side (fewer merges,
    /// finer labels; docs/DEVELOPMENT.md, sessions 39 and 43). Fast polishes a quarter
    /// of its preset there, 300 iterations on robot-sized input like balanced, at no
    /// measurable cost (the occluded polish is a one-way Chamfer on 512 points; 14 fits
    /// took 4.95 s against 4.92 s a sequence): bench-dev occluded, fast, seeds 0–4, mean
    /// RI / recon / flow / TED / re-animation with 100 iterations 0.784 / 6.77 / 7.50 /
    /// 4.37 / 5.09, with 300 0.807 / 6.76 / 7.49 / 4.37 / 5.28; bench-dev partial (the
    /// sequences fitted as occluded) 0.798 / 7.96 / 8.81 / 4.91 / 7.01 → 0.809 / 8.06 /
    /// 8.89 / 5.14 / 7.09; procedural occluded (generator seeds 0–3) 0.729 / 7.72 / 5.21
    /// / 4.45 / 4.10 → 0.722 / 6.94 / 4.69 / 4.90 / 3.65.
    pub occluded_divisor: usize,
}

impl Schedule {
    /// Preset for a quality level (Paper = the supplement's counts; Balanced and
    /// Fast measured on bench-dev: Balanced 3000 its gave mean RI 0.861 / recon 10.0
    /// vs Fast 1200 its 0.846 / 10.4 on so101 m = 9 — little gain for 2.5× time); `small` = sparse/small object (the paper's Sapien
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
        let reseg_rounds = match q {
            Quality::Fast => 2,
            Quality::Balanced | Quality::Paper => 3,
        };
        let (later_rotations, searched_divisor, occluded_divisor) = match q {
            Quality::Fast => (1024, 12, 4),
            Quality::Balanced => (2048, 10, 10),
            Quality::Paper => (2048, 4, 4),
        };
        Schedule {
            later_rotations,
            searched_divisor,
            occluded_divisor,
            iters,
            emd_start,
            warmup: 200,
            lr: 2e-3,
            warmup_lr: 1e-2,
            batch: 512,
            emd_n: 128,
            emd_refresh: 4,
            reseg_rounds,
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
