//! Step 1: dynamic 3D Gaussians fitted to the sequence (model, losses with their
//! gradients, optimiser, initialisation, schedule, model selection).

pub mod adam;
pub mod candidate_bytes;
pub mod fitter;
pub mod flow;
pub mod gaussians;
pub mod hold_still;
pub mod init;
pub mod losses;
pub mod medial;
pub mod motion_seg;
pub mod occluded_search;
pub mod pose_init;
pub mod pose_search;
pub mod rot6d;
pub mod schedule;
pub mod select;
pub mod start_frame;
pub mod whole_motion;

pub use gaussians::GaussianModel;

/// Wall-clock timings of a Step-1 run (native only; zero in wasm, where the
/// caller measures time itself).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Timings {
    /// Total seconds of the whole Step 1 (all candidates).
    pub total_s: f64,
    /// Per candidate: (m, seconds, iterations).
    pub per_candidate: Vec<(usize, f64, usize)>,
}

/// Result of Step 1 (the selected candidate).
#[derive(Debug, Clone)]
pub struct Step1Result {
    /// The model, in input units.
    pub model: GaussianModel,
    /// Input → fit units the candidate was fitted in (Steps 2–3 run in the same).
    pub norm: crate::normalisation::Normalisation,
    /// Per frame, per working point: Gaussian index.
    pub labels: Vec<Vec<u32>>,
    /// Per frame: indices of the working points in the input frame (identity when
    /// the frame was not downsampled).
    pub working: Vec<Vec<u32>>,
    /// Model-selection Chamfer of the selected candidate (`fitter::final_chamfer`).
    pub final_chamfer: f64,
    pub occlusion_used: bool,
    /// The frame the Gaussians were placed on (`start_frame`): the result's canonical
    /// frame.
    pub canonical: usize,
    pub iterations: usize,
    pub m: usize,
    /// Every candidate tried: (m, final Chamfer).
    pub candidates: Vec<(usize, f64)>,
    /// Fits per candidate (the best of them stands for its m).
    pub restarts: usize,
    /// `FitOptions::medial_init` if it was asked for: whether the centres started on the
    /// medial-axis estimate (not on occluded input).
    pub medial_init: Option<bool>,
    /// Gaussians held still in every frame (`hold_still`: on occluded input, and on full
    /// input a root whose turn the clouds cannot see).
    pub held_still: usize,
    pub timings: Timings,
    /// On occluded input, the Gaussians that label the input points of the frames
    /// other than the canonical one in the result (`pipeline::finish`;
    /// `select::SEGMENT_ITERS`). `model` gives the poses, `labels` and the canonical
    /// frame's labels.
    pub segmenter: Option<GaussianModel>,
    /// On occluded input, the whole object's motion when it moves as a whole
    /// (`whole_motion`): the model is of the frames brought back by it.
    pub whole: Option<whole_motion::WholeMotion>,
}
