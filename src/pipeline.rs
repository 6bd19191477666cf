//! The three steps end to end (Step 1 Gaussians with model selection, Step 2 tree,
//! Step 3 joints), with progress reporting and cancellation through a callback.
//! Nothing here depends on the browser: the worker and the CLI both drive it.

use serde::{Deserialize, Serialize};

/// Occlusion handling (partial / occluded input losses of the supplement).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum Occlusion {
    #[default]
    Auto,
    On,
    Off,
}

/// Quality dial: iteration schedule presets.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum Quality {
    Fast,
    #[default]
    Balanced,
    Paper,
}

/// Options of a fitting job.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(default)]
pub struct FitOptions {
    /// Inclusive range of Gaussian counts m to try; `None` = chosen from the data.
    pub parts: Option<(usize, usize)>,
    pub quality: Quality,
    /// Overrides the preset's Step-1 iteration count.
    pub iters: Option<usize>,
    pub occlusion: Occlusion,
    pub seed: u64,
    /// Frames larger than this are downsampled for the fit.
    pub working_size: usize,
}

impl Default for FitOptions {
    fn default() -> Self {
        FitOptions {
            parts: None,
            quality: Quality::Balanced,
            iters: None,
            occlusion: Occlusion::Auto,
            seed: 0,
            working_size: 4096,
        }
    }
}

/// Pipeline stage, for progress bars.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Stage {
    Load,
    Init,
    Gaussians,
    Select,
    Tree,
    Joints,
    Done,
}

/// A snapshot of the Gaussians for live display (f32, structure of arrays).
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct Snapshot {
    /// Frame the snapshot shows.
    pub frame: usize,
    /// m × 3 centres.
    pub centers: Vec<f32>,
    /// m × 9 rotations, row-major.
    pub rotations: Vec<f32>,
    /// m × 3 scales (standard deviations).
    pub scales: Vec<f32>,
    /// Per point of `frame` (working cloud), Gaussian index.
    pub labels: Vec<u32>,
}

/// A progress report.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Progress {
    pub stage: Stage,
    /// Candidate part count this report is about (Step 1), if any.
    pub m: Option<usize>,
    pub iter: usize,
    pub total: usize,
    /// Named loss values at this iteration.
    pub losses: Vec<(String, f64)>,
    pub snapshot: Option<Snapshot>,
}

/// What the callback tells the pipeline.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Control {
    Continue,
    Cancel,
}

/// Step 1 for one candidate part count m (what one wasm worker runs).
pub fn fit_step1_single(
    seq: &crate::io::sequence::Sequence,
    m: usize,
    opts: &FitOptions,
    cb: &mut dyn FnMut(&Progress) -> Control,
) -> crate::Result<crate::fit::Step1Result> {
    let prep = crate::fit::select::prepare(seq, opts)?;
    crate::fit::select::run_candidate(&prep, m, opts, cb)
}

/// Step 1 with model selection over the part-count range (one thread per
/// candidate natively; sequential in wasm).
pub fn fit_step1(
    seq: &crate::io::sequence::Sequence,
    opts: &FitOptions,
    cb: &(dyn Fn(&Progress) -> Control + Sync),
) -> crate::Result<crate::fit::Step1Result> {
    crate::fit::select::select(seq, opts, cb)
}

/// Default inclusive range of part counts chosen from the data.
pub fn default_part_range(seq: &crate::io::sequence::Sequence) -> (usize, usize) {
    crate::fit::select::default_part_range(seq)
}
