//! Step-1 driver: working clouds from a sequence, the default part-count range,
//! occlusion detection, one candidate end to end, and model selection over several
//! m (one thread per candidate natively, sequential in wasm where the page runs one
//! candidate per Web Worker instead).

use glam::Vec3;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

use super::fitter::{self, Data, FitConfig, FlowField};
use super::flow::OtFlow;
use super::hold_still;
use super::schedule::Schedule;
use super::start_frame::{self, FrameOrder};
use super::whole_motion::{self, WholeMotion};
use super::{Step1Result, Timings};
use crate::io::sequence::Sequence;
use crate::normalisation::Normalisation;
use crate::pipeline::{Control, FitOptions, Occlusion, Progress, Quality};
use crate::{Error, Result};

/// Total points over all frames from which a sequence counts as "robot-sized"
/// (the paper's RoboArt: 10 × 4096; Sapien: 4 × 512). Occluded robot sequences
/// (~10 × 800 visible points) still count as robots.
const ROBOT_TOTAL_POINTS: usize = 6000;

/// Whether the paper's small-object schedule and part range apply. Robot-sized means
/// dense full frames (≥ 3000 points each, like RoboArt's 4096; a 2048-point laptop is
/// small), or occluded frames (point counts vary by > 15 %) that add up to
/// `ROBOT_TOTAL_POINTS`, like Occluded-RoboArt's ~10 × 800 visible points.
pub fn is_small(seq: &Sequence, working_size: usize) -> bool {
    let sizes: Vec<usize> = seq
        .frames
        .iter()
        .map(|f| f.points.len().min(working_size.max(1)))
        .collect();
    let total: usize = sizes.iter().sum();
    let max = sizes.iter().copied().max().unwrap_or(0);
    let min = sizes.iter().copied().min().unwrap_or(0);
    let dense = max >= ROBOT_FRAME_POINTS;
    let occluded_robot = (min as f64) < 0.85 * max as f64 && total >= ROBOT_TOTAL_POINTS;
    !(dense || occluded_robot)
}

/// Points per full frame from which a sequence counts as robot-sized.
const ROBOT_FRAME_POINTS: usize = 3000;

/// Default inclusive range of m: 10–15 for robot-sized sequences, 3–7 for small or
/// sparse ones (see `is_small`).
pub fn default_part_range(seq: &Sequence) -> (usize, usize) {
    if is_small(seq, FitOptions::default().working_size) {
        (3, 7)
    } else {
        (10, 15)
    }
}

/// Working clouds: frames above `working_size` randomly downsampled (seeded, input
/// order kept), then without their flying pixels (`geom::outliers`, judged on the
/// downsampled cloud, so the cost stays that of the working size). Returns the clouds
/// and the kept indices per frame.
pub fn working_clouds(
    seq: &Sequence,
    working_size: usize,
    seed: u64,
) -> (Vec<Vec<Vec3>>, Vec<Vec<u32>>) {
    let mut rng = StdRng::seed_from_u64(seed ^ 0x005E_ED0F_C10D);
    let mut clouds = Vec::with_capacity(seq.frames.len());
    let mut kept = Vec::with_capacity(seq.frames.len());
    for f in &seq.frames {
        let n = f.points.len();
        let mut idx: Vec<u32> = (0..n as u32).collect();
        if working_size > 0 && n > working_size {
            for i in 0..working_size {
                let j = rng.random_range(i..n);
                idx.swap(i, j);
            }
            idx.truncate(working_size);
            idx.sort_unstable();
        }
        let cloud: Vec<Vec3> = idx.iter().map(|&i| f.points[i as usize]).collect();
        let isolated = crate::geom::outliers::isolated(&cloud);
        let (idx, cloud): (Vec<u32>, Vec<Vec3>) = idx
            .into_iter()
            .zip(cloud)
            .zip(&isolated)
            .filter(|(_, &i)| !i)
            .map(|(pair, _)| pair)
            .unzip();
        clouds.push(cloud);
        kept.push(idx);
    }
    (clouds, kept)
}

/// Occlusion detection for `Occlusion::Auto`, true for single-view input:
/// - the frames' point counts differ (the smallest input frame has < 85 % of the
///   largest's points): what one camera sees varies from frame to frame, while
///   whole-surface samples of one object have (nearly) equal counts. Judged on the
///   input frames' `sizes`, not the working clouds', which downsampling to the working
///   size gives equal counts when every frame is above it;
/// - or every frame looks like one camera's view (`geom::layers`): fewer than
///   [`SINGLE_VIEW_LAYERED`] of its points hidden behind others from its best view.
///   For input saved at a fixed count per frame. Only from [`SINGLE_VIEW_MIN_POINTS`]
///   points per frame: sparser thin objects look one-layered.
pub fn detect_occlusion(sizes: &[usize], clouds: &[Vec<Vec3>]) -> bool {
    let max = sizes.iter().copied().max().unwrap_or(0);
    let min = sizes.iter().copied().min().unwrap_or(0);
    if max > 0 && (min as f64) < 0.85 * max as f64 {
        return true;
    }
    !clouds.is_empty()
        && clouds.iter().all(|c| c.len() >= SINGLE_VIEW_MIN_POINTS)
        && clouds.iter().all(|c| {
            let step = c.len().div_ceil(SINGLE_VIEW_MIN_POINTS).max(1);
            let pts: Vec<Vec3> = c.iter().step_by(step).copied().collect();
            crate::geom::layers::layered_fraction(&pts).is_some_and(|f| f < SINGLE_VIEW_LAYERED)
        })
}

/// A frame is one camera's view when less than this fraction of its points is
/// hidden behind others from its best view (`geom::layers::layered_fraction`).
/// Measured, the largest over a sequence's frames: bench-dev occluded 0.020–0.034 and
/// procedural occluded 0.008–0.072; bench-dev partial (each part seen from one
/// camera, parts overlapping) 0.074–0.219; bench-dev full 0.240–0.379, procedural
/// full (at 1024 and more points per frame) 0.259–0.491.
pub const SINGLE_VIEW_LAYERED: f64 = 0.1;

/// Frames need this many points for the single-view test (and it looks at this many).
/// Below it a thin part's two sides fall within one layer: the 4 × 512 laptop (full
/// surface) has no frame above 0.062 on generator seed 1.
pub const SINGLE_VIEW_MIN_POINTS: usize = 1024;

fn validate(seq: &Sequence) -> Result<()> {
    if seq.frames.len() < 2 {
        return Err(Error::Sequence(format!(
            "Step 1 needs at least 2 frames, got {}",
            seq.frames.len()
        )));
    }
    for f in &seq.frames {
        if f.points.len() < 16 {
            return Err(Error::input(
                &f.name,
                format!("only {} points (at least 16 needed)", f.points.len()),
            ));
        }
        if f.points.iter().any(|p| !p.is_finite()) {
            return Err(Error::input(&f.name, "non-finite coordinates"));
        }
    }
    Ok(())
}

/// Prepared inputs shared by every candidate.
pub struct Prepared {
    /// Input → fit units (`data` is in fit units; results are mapped back).
    pub norm: Normalisation,
    /// The working clouds in visiting order (`order`), tracked as it says.
    pub data: Data,
    /// Per input frame (input order): the working points' indices in the frame.
    pub working: Vec<Vec<u32>>,
    pub occluded: bool,
    /// The order Step 1 visits the frames in: from frame 0 on full input, from the
    /// frame with the most input points on occluded input (`start_frame`).
    pub order: FrameOrder,
    pub sched: Schedule,
    pub flow: Option<FlowField>,
    /// On occluded input, the whole object's motion (`whole_motion`) when it moves as
    /// a whole: `data` holds the frames brought back by it.
    pub whole: Option<WholeMotion>,
}

/// Whether the (non-learned) flow loss is used on full (non-occluded) input.
/// Ablation (Fast, m = 12, so101/solo12/finger_edu full): with flow mean
/// reconstruction error 7.52 vs 7.71 and flow error 8.16 vs 8.66 without — a small
/// gain, kept. Not used on occluded input (frames do not correspond).
pub const USE_FLOW: bool = true;

/// Whether the fit of `seq` with `opts` uses the occluded losses: `opts.occlusion`,
/// or for `Auto` the detection on the input sizes and the normalised working clouds
/// `clouds` (`detect_occlusion`).
fn occlusion_used(seq: &Sequence, opts: &FitOptions, clouds: &[Vec<Vec3>]) -> bool {
    match opts.occlusion {
        Occlusion::On => true,
        Occlusion::Off => false,
        Occlusion::Auto => {
            // Input frame sizes, before downsampling.
            let sizes: Vec<usize> = seq.frames.iter().map(|f| f.points.len()).collect();
            detect_occlusion(&sizes, clouds)
        }
    }
}

/// Normalisation and the normalised working clouds with their kept indices.
fn normalised_working(seq: &Sequence, opts: &FitOptions) -> (Normalisation, WorkingClouds) {
    let norm = Normalisation::of(seq);
    let (mut clouds, working) = working_clouds(seq, opts.working_size, opts.seed);
    for c in &mut clouds {
        norm.points_to_fit(c);
    }
    (norm, (clouds, working))
}

type WorkingClouds = (Vec<Vec<Vec3>>, Vec<Vec<u32>>);

/// Whether a fit of `seq` with `opts` will run as occluded (what `prepare` decides).
pub fn will_be_occluded(seq: &Sequence, opts: &FitOptions) -> Result<bool> {
    validate(seq)?;
    match opts.occlusion {
        Occlusion::On => Ok(true),
        Occlusion::Off => Ok(false),
        Occlusion::Auto => {
            let (_, (clouds, _)) = normalised_working(seq, opts);
            Ok(occlusion_used(seq, opts, &clouds))
        }
    }
}

pub fn prepare(seq: &Sequence, opts: &FitOptions) -> Result<Prepared> {
    validate(seq)?;
    let (norm, (mut clouds, working)) = normalised_working(seq, opts);
    let sizes: Vec<usize> = seq.frames.iter().map(|f| f.points.len()).collect();
    let occluded = occlusion_used(seq, opts, &clouds);
    let mut sched = Schedule::preset(opts.quality, is_small(seq, opts.working_size));
    if let Some(it) = opts.iters {
        sched = sched.with_iters(it);
    }
    let order = if occluded {
        FrameOrder::from_start(sizes.len(), start_frame::most_points(&sizes))
    } else if opts.from_last_frame {
        FrameOrder::from_start(sizes.len(), sizes.len().saturating_sub(1))
    } else {
        FrameOrder::identity(sizes.len())
    };
    let whole = if occluded {
        whole_motion::bring_back_clouds(&mut clouds, order.start(), &norm)
    } else {
        None
    };
    let mut data = Data::new(order.permute(clouds));
    data.track_from = order.track_from();
    let flow = (USE_FLOW && !occluded)
        .then(|| FlowField::compute(&data, &OtFlow::default(), 256, opts.seed));
    Ok(Prepared {
        norm,
        data,
        working,
        occluded,
        order,
        sched,
        flow,
        whole,
    })
}

/// The last `Prepared` of a worker, reused while the sequence and the options that
/// shape it stay the same: a page worker fits several candidates of one sequence in
/// turn, and preparing (working clouds, grids, scene flow) took ~0.3 s per
/// candidate in wasm.
#[derive(Default)]
pub struct PrepareCache {
    last: Option<(u64, std::rc::Rc<Prepared>)>,
}

impl PrepareCache {
    /// The prepared inputs for `seq` and `opts`, computed only when they differ from
    /// the last call's (by a hash of every point, the frame names and the options
    /// `prepare` reads; the part range does not matter).
    pub fn get(&mut self, seq: &Sequence, opts: &FitOptions) -> Result<std::rc::Rc<Prepared>> {
        use std::hash::{Hash, Hasher};
        let mut h = std::collections::hash_map::DefaultHasher::new();
        for f in &seq.frames {
            f.name.hash(&mut h);
            f.points.len().hash(&mut h);
            for p in &f.points {
                for v in p.to_array() {
                    v.to_bits().hash(&mut h);
                }
            }
        }
        (
            opts.quality,
            opts.iters,
            opts.occlusion,
            opts.seed,
            opts.working_size,
            opts.from_last_frame,
        )
            .hash(&mut h);
        let key = h.finish();
        if let Some((k, prep)) = &self.last {
            if *k == key {
                return Ok(prep.clone());
            }
        }
        // Drop the old one first: only one sequence is kept.
        self.last = None;
        let prep = std::rc::Rc::new(prepare(seq, opts)?);
        self.last = Some((key, prep.clone()));
        Ok(prep)
    }
}

/// The global pose search (`fit::pose_search`) runs only when every working frame
/// has at least this many points: on sparser frames it has not been shown to help.
/// Measured end to end, generator seeds 0–3, mean RI / reconstruction / TED /
/// re-animation without → with the search (session 22):
/// - laptop 4 × 512 (SPEC §7's "object" workload): balanced 0.658 / 4.92 / 4.00 /
///   4.90 → 0.944 / 1.77 / 0.00 / 0.69; fast 0.798 / 3.21 / 2.25 / 4.67 → 0.935 /
///   1.83 / 0.00 / 0.84;
/// - cabinet 4 × 512: balanced 0.575 / 8.13 / 4.00 / 9.69 → 0.564 / 5.42 / 1.25 /
///   5.98; fast 0.593 / 7.50 / 2.75 / 7.04 → 0.546 / 4.90 / 2.25 / 5.17;
/// - arm, quadruped and hand 4 × 512 (seeds 0–1; 7–13 parts, more than the range
///   3–7 of such sparse input can hold): balanced 0.779 / 2.80 / 4.50 / 4.44 →
///   0.756 / 2.72 / 6.17 / 5.94.
///
/// At 4 × 256 it helps the laptop too (fast: RI 0.626 → 0.872, TED 5.0 → 0.5) but
/// costs the cabinet RI (0.580 → 0.477), so the bound stays at 512. In session 3, before
/// the flip guard and the sparse distance cap, the search had cost the 4 × 512 laptop
/// (RI 0.725 → 0.505), and the bound was 1024. Denser frames always had it: 10 × 2048
/// laptop 0.97 / 1.43 with vs 0.84 / 1.70 without (fast).
pub const SEARCH_MIN_POINTS: usize = 512;

/// The same bound for occluded input, whose frames show about half the points: the
/// occluded search (`fit::occluded_search`) is measured on bench-dev's occluded
/// frames (407–1347 points); below this it has not been tried.
pub const OCCLUDED_SEARCH_MIN_POINTS: usize = 400;

/// On occluded input the frames other than the canonical one are labelled by a copy
/// of the searched and polished Gaussians that went on for this many iterations of
/// the same losses at the preset's learning rate (`FitConfig::segment_iters`);
/// the poses, Steps 2–3 and the canonical frame's labels stay the polished model's.
/// The polished Gaussians move rigidly with their search poses, so in a frame that
/// shows another side of a part they sit where the part is, not on its visible
/// points, and those points go to a neighbour; the copy follows each frame's points.
/// Measured (bench-dev occluded, mean RI, the other metrics unchanged; with the
/// polish then at 1e-4, see `fitter`'s occluded polish): fast, seeds
/// 0–4, 0.718 → 0.755 (every robot higher); balanced, seeds 0–2, 0.752 → 0.783 (five
/// robots higher, panda_gripper 0.793 → 0.789, so101 0.784 → 0.761); partial, fast,
/// seeds 0–1, 0.749 → 0.789. Length: fast, seeds 0–2, 500 / 1100 / 2000 iterations
/// 0.756 / 0.762 / 0.755; balanced 1100 against its preset's remaining 2700: 0.783
/// against 0.777. Letting Steps 2–3 use the copy's labels too (merges, the canonical
/// points) gave more RI (fast 0.767, balanced 0.793) but worse poses (balanced recon
/// 6.60 → 7.56, flow 7.05 → 8.31). See docs/DEVELOPMENT.md, session 29.
pub const SEGMENT_ITERS: usize = 1100;

/// Most fits per candidate part count (`FitOptions::restarts`).
pub const MAX_RESTARTS: usize = 16;

/// Whether `n` fits per candidate part count is allowed (1 to `MAX_RESTARTS`).
pub fn restarts_allowed(n: usize) -> bool {
    (1..=MAX_RESTARTS).contains(&n)
}

/// Seed of restart `r` of a fit with seed `seed` (restart 0 is the fit itself).
pub fn restart_seed(seed: u64, r: usize) -> u64 {
    seed.wrapping_add((r as u64).wrapping_mul(0x1_0000))
}

/// Runs one candidate m on prepared data: `FitOptions::restarts` (or the preset's)
/// fits from their own seeds, keeping the one with the lowest final Chamfer. Progress
/// counts through the restarts in turn.
pub fn run_candidate(
    prep: &Prepared,
    m: usize,
    opts: &FitOptions,
    cb: &mut dyn FnMut(&Progress) -> Control,
) -> Result<Step1Result> {
    let restarts = opts.restarts.unwrap_or(1);
    if !restarts_allowed(restarts) {
        return Err(Error::InvalidArgument(format!(
            "restarts {restarts}: expected 1 to {MAX_RESTARTS} fits per part count"
        )));
    }
    let mut fit = |r: usize| {
        let mut report = |p: &Progress| {
            cb(&Progress {
                iter: r * p.total + p.iter,
                total: restarts * p.total,
                ..p.clone()
            })
        };
        fit_once(prep, m, opts, restart_seed(opts.seed, r), &mut report)
    };
    let mut best = fit(0)?;
    let (mut secs, mut iterations) = (best.timings.total_s, best.iterations);
    for r in 1..restarts {
        let res = fit(r)?;
        secs += res.timings.total_s;
        iterations += res.iterations;
        if res.final_chamfer < best.final_chamfer {
            best = res;
        }
    }
    best.restarts = restarts;
    best.timings = Timings {
        total_s: secs,
        per_candidate: vec![(m, secs, iterations)],
    };
    Ok(best)
}

/// One fit of candidate m from `seed`.
fn fit_once(
    prep: &Prepared,
    m: usize,
    opts: &FitOptions,
    seed: u64,
    cb: &mut dyn FnMut(&Progress) -> Control,
) -> Result<Step1Result> {
    let mut cfg = FitConfig::new(prep.sched.clone(), prep.occluded, seed);
    cfg.medial_init = opts.medial_init;
    let fewest = prep.data.frames.iter().map(Vec::len).min().unwrap_or(0);
    let min_points = if prep.occluded {
        OCCLUDED_SEARCH_MIN_POINTS
    } else {
        SEARCH_MIN_POINTS
    };
    if fewest < min_points {
        cfg.pose_search = None;
        cfg.motion_seg = None;
    }
    // After the global search the main loop only polishes: a fraction of the
    // preset's iterations (`Schedule::searched_divisor`, on occluded input
    // `occluded_divisor`; unless the caller set a count).
    let searched = cfg
        .pose_search
        .as_ref()
        .is_some_and(|o| !prep.occluded || o.occluded);
    if searched && opts.iters.is_none() {
        let divisor = if prep.occluded {
            cfg.sched.occluded_divisor
        } else {
            cfg.sched.searched_divisor
        };
        cfg.sched = cfg
            .sched
            .clone()
            .with_iters((cfg.sched.iters / divisor).max(100));
    }
    if searched && prep.occluded {
        cfg.segment_iters = SEGMENT_ITERS;
    }
    #[cfg(not(target_arch = "wasm32"))]
    let t0 = std::time::Instant::now();
    // Snapshots go out in input units and input frame numbers.
    let start = prep.order.start();
    let mut report = |p: &Progress| match &p.snapshot {
        Some(s) if !prep.norm.is_identity() || start != 0 || prep.whole.is_some() => {
            let mut s = s.clone();
            prep.norm.snapshot_to_input(&mut s);
            s.frame = prep.order.order.get(s.frame).copied().unwrap_or(s.frame);
            if let Some(w) = &prep.whole {
                w.carry_snapshot(&mut s);
            }
            cb(&Progress {
                snapshot: Some(s),
                ..p.clone()
            })
        }
        _ => cb(p),
    };
    let (mut params, segmenter, stats) =
        fitter::fit_candidate_segmented(&prep.data, m, &cfg, prep.flow.as_ref(), &mut report)?;
    // Model selection compares the candidates as fitted: on occluded input the
    // Chamfer rewards the sliding views that `hold_still` undoes (bench-dev occluded
    // solo12, m = 15: 5.3e-4 as fitted, 8.0e-4 held, and m = 10 then won).
    let chamfer = fitter::final_chamfer(&prep.data, &params, prep.occluded, 1024);
    let held = if prep.occluded {
        hold_still::hold_still(&prep.data, &mut params)
    } else {
        hold_still::hold_spinning_root(&prep.data, &mut params)
    };
    #[cfg(not(target_arch = "wasm32"))]
    let secs = t0.elapsed().as_secs_f64();
    #[cfg(target_arch = "wasm32")]
    let secs = 0.0;
    let mut result = candidate_result(prep, &params, chamfer, m, stats.iterations, secs);
    // Only occluded input has a segmenter: held still as the posed Gaussians are, by
    // its own motion.
    if let Some(mut seg) = segmenter {
        hold_still::hold_still(&prep.data, &mut seg);
        result.segmenter = Some(to_input(prep, seg.to_model()));
    }
    Ok(Step1Result {
        held_still: held,
        medial_init: cfg.medial_init.then_some(!prep.occluded),
        ..result
    })
}

/// A fitted candidate as a `Step1Result`: its model (in input units), the labels of
/// the working clouds, and the model-selection Chamfer `chamfer` (a mean squared
/// distance, given in fit units, reported in input units²). `secs` is the caller's
/// timing.
pub fn candidate_result(
    prep: &Prepared,
    params: &super::gaussians::Params,
    chamfer: f64,
    m: usize,
    iterations: usize,
    secs: f64,
) -> Step1Result {
    let final_chamfer = chamfer * prep.norm.scale * prep.norm.scale;
    let fitted = params.to_model();
    let labels = prep.order.unpermute(
        prep.data
            .frames32
            .iter()
            .enumerate()
            .map(|(k, f)| fitted.segment(k, f))
            .collect(),
    );
    let model = to_input(prep, fitted);
    Step1Result {
        model,
        norm: prep.norm,
        labels,
        working: prep.working.clone(),
        final_chamfer,
        occlusion_used: prep.occluded,
        canonical: prep.order.start(),
        iterations,
        m,
        candidates: vec![(m, final_chamfer)],
        restarts: 1,
        medial_init: None,
        held_still: 0,
        segmenter: None,
        whole: prep.whole.clone(),
        timings: Timings {
            total_s: secs,
            per_candidate: vec![(m, secs, iterations)],
        },
    }
}

/// A model fitted on `prep`, put in input frame order and input units.
fn to_input(prep: &Prepared, mut model: super::GaussianModel) -> super::GaussianModel {
    unpermute_model(&mut model, &prep.order);
    prep.norm.model_to_input(&mut model);
    model
}

/// Puts a model fitted in visiting order back in input frame order.
fn unpermute_model(model: &mut super::GaussianModel, order: &FrameOrder) {
    fn back<T: Clone>(v: &[T], m: usize, order: &FrameOrder) -> Vec<T> {
        order
            .unpermute(v.chunks(m.max(1)).map(<[T]>::to_vec).collect())
            .concat()
    }
    model.rot6d = back(&model.rot6d, model.m, order);
    model.center = back(&model.center, model.m, order);
}

/// The part counts a quality tries in `lo..=hi`: all of them, except Fast, which
/// tries only the two ends (10–15 → 10, 15): model selection is the largest
/// multiplier of a fit's time, and on two cores two candidates take one round where
/// four take two. Measured (each m fitted alone, fast, end to end, then the
/// lowest-Chamfer rule applied to each list): on bench-dev full the rule picks m = 10 or
/// 15 on all seven robots from {10, 12, 14, 15} as from {10, 15}, so the means are the
/// same (RI 0.874, recon 1.02, flow 1.01, TED 2.00, re-animation 2.32; all six m: RI
/// 0.873, TED 2.14). Procedural (seed 3): the same m on laptop, cabinet, hand and
/// quadruped; the arm takes 15 instead of 14 (RI 0.825 → 0.842, TED 5 both). Earlier
/// (session 5) every other m of the range had replaced all of them: the same m on six of
/// the seven robots (talos 13 → 14: RI 0.880 → 0.851).
///
/// On `occluded` input Fast tries every m too: there a candidate's fit often fails
/// (bench-dev occluded, fast, seed 0, each m alone: laikago's final Chamfers for m =
/// 10–15 are 6.7, 12.3, 10.3, 14.1, 6.8 and 6.2e-4), so more candidates give the
/// lowest-Chamfer rule more good fits to choose from, and occluded fits are quick
/// (1.4–2.4 s per sequence for the two ends). Measured, end to end, RI / recon / flow
/// / TED / re-animation: bench-dev occluded, fast, seeds 0–4 (means over the seven
/// robots and the seeds), 0.778 / 7.28 / 7.89 / 4.54 / 5.57 → 0.786 / 6.76 / 7.22 /
/// 4.37 / 5.18 (RI higher on four of the five seeds); procedural occluded (the five
/// objects, generator seeds 0–3, fit seed 0) 0.720 / 7.68 / 5.51 / 4.30 / 4.19 →
/// 0.721 / 7.37 / 4.84 / 4.30 / 3.83. See docs/DEVELOPMENT.md, session 33.
///
/// An empty range or one starting at 0 is an error.
pub fn candidate_parts(
    lo: usize,
    hi: usize,
    quality: Quality,
    occluded: bool,
) -> Result<Vec<usize>> {
    if lo == 0 || lo > hi {
        return Err(Error::InvalidArgument(format!(
            "part range {lo}..={hi} is empty or starts at 0"
        )));
    }
    Ok(match quality {
        Quality::Fast if lo < hi && !occluded => vec![lo, hi],
        Quality::Fast if lo == hi => vec![lo],
        Quality::Fast | Quality::Balanced | Quality::Paper => (lo..=hi).collect(),
    })
}

/// A larger m whose final Chamfer ends above this multiple of the smallest m's has
/// failed: more Gaussians can always fit at least as well (see [`extra_candidate`]).
pub const FAILED_RATIO: f64 = 1.5;

/// One more part count to try after the candidates `(m, final Chamfer)` (ordered by
/// m) of a Fast fit of full input over the data's default range: when the top of the
/// range failed (its Chamfer above [`FAILED_RATIO`] × the bottom's), the fit tries
/// `hi + (hi − lo)` (10–15 → 20). More Gaussians than parts do little harm (static
/// neighbours merge, as the paper notes) while too few cannot be repaired, and a failed
/// top leaves only the bottom to choose. Measured (fast, full, fit seeds 0–4, 35 fits
/// of the seven bench-dev robots): it fired three times. Talos, seed 0 (13 parts; m =
/// 15 ended at 1.52e-3 against m = 10's 5.0e-4): m = 20 reached 4.4e-4 and won, RI /
/// recon / flow / TED / re-animation 0.858 / 1.34 / 1.15 / 6 / 4.02 → 0.927 / 0.97 /
/// 1.18 / 1 / 1.77; finger_edu seed 1 (m = 20: 1.8e-3) and xarm7 seed 1 (3.6e-4
/// against 2.5e-4) kept their results. It never fired on the procedural objects
/// (generator seeds 0–3, fit seed 0). Balanced and Paper try the whole range, and an
/// explicit range (`default_range` false) is the user's to keep.
pub fn extra_candidate(
    cands: &[(usize, f64)],
    quality: Quality,
    occluded: bool,
    default_range: bool,
) -> Option<usize> {
    match cands {
        [(lo, bottom), (hi, top)]
            if quality == Quality::Fast
                && !occluded
                && default_range
                && hi > lo
                && bottom.is_finite()
                && (!top.is_finite() || *top > FAILED_RATIO * bottom) =>
        {
            Some(hi + (hi - lo))
        }
        _ => None,
    }
}

/// Candidate list from the options (or the data): what `select_all` fits.
pub fn candidates(seq: &Sequence, opts: &FitOptions) -> Result<Vec<usize>> {
    let (lo, hi) = opts.parts.unwrap_or_else(|| default_part_range(seq));
    candidate_parts(lo, hi, opts.quality, will_be_occluded(seq, opts)?)
}

/// Model selection: every candidate m, keeping the lowest final Chamfer (ties: smaller m).
pub fn select(
    seq: &Sequence,
    opts: &FitOptions,
    cb: &(dyn Fn(&Progress) -> Control + Sync),
) -> Result<Step1Result> {
    select_all(seq, opts, cb)?
        .into_iter()
        .next()
        .ok_or_else(|| Error::InvalidArgument("no candidate part count".into()))
}

/// Every candidate m, fitted, ordered by final Chamfer (lowest first; ties: smaller m).
/// Each carries the whole candidate list and the timings of all of them.
pub fn select_all(
    seq: &Sequence,
    opts: &FitOptions,
    cb: &(dyn Fn(&Progress) -> Control + Sync),
) -> Result<Vec<Step1Result>> {
    #[cfg(not(target_arch = "wasm32"))]
    let t0 = std::time::Instant::now();
    let prep = prepare(seq, opts)?;
    let (lo, hi) = opts.parts.unwrap_or_else(|| default_part_range(seq));
    let ms = candidate_parts(lo, hi, opts.quality, prep.occluded)?;
    let mut results = run_all(&prep, &ms, opts, cb)
        .into_iter()
        .collect::<Result<Vec<Step1Result>>>()?;
    if results.is_empty() {
        return Err(Error::InvalidArgument("no candidate part count".into()));
    }
    let mut cands: Vec<(usize, f64)> = results.iter().map(|r| (r.m, r.final_chamfer)).collect();
    if let Some(up) = extra_candidate(&cands, opts.quality, prep.occluded, opts.parts.is_none()) {
        // Beyond the range asked for, a fit that cannot run (frames with fewer than `up`
        // points) leaves the range's candidates as they are; a cancel still cancels.
        for r in run_all(&prep, &[up], opts, cb) {
            match r {
                Ok(r) => {
                    cands.push((r.m, r.final_chamfer));
                    results.push(r);
                }
                Err(Error::Cancelled) => return Err(Error::Cancelled),
                Err(_) => {}
            }
        }
    }
    let per: Vec<(usize, f64, usize)> = results
        .iter()
        .flat_map(|r| r.timings.per_candidate.iter().copied())
        .collect();
    // Stable: equal Chamfers keep the candidate order (smaller m first).
    results.sort_by(|a, b| a.final_chamfer.total_cmp(&b.final_chamfer));
    #[cfg(not(target_arch = "wasm32"))]
    let total = t0.elapsed().as_secs_f64();
    #[cfg(target_arch = "wasm32")]
    let total = 0.0;
    for r in &mut results {
        r.candidates = cands.clone();
        r.timings = Timings {
            total_s: total,
            per_candidate: per.clone(),
        };
    }
    Ok(results)
}

#[cfg(target_arch = "wasm32")]
fn run_all(
    prep: &Prepared,
    ms: &[usize],
    opts: &FitOptions,
    cb: &(dyn Fn(&Progress) -> Control + Sync),
) -> Vec<Result<Step1Result>> {
    let mut out = Vec::new();
    for &m in ms {
        let r = run_candidate(prep, m, opts, &mut |p| cb(p));
        let stop = matches!(r, Err(Error::Cancelled));
        out.push(r);
        if stop {
            break;
        }
    }
    out
}

#[cfg(not(target_arch = "wasm32"))]
fn run_all(
    prep: &Prepared,
    ms: &[usize],
    opts: &FitOptions,
    cb: &(dyn Fn(&Progress) -> Control + Sync),
) -> Vec<Result<Step1Result>> {
    use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
    use std::sync::Mutex;
    let threads = std::thread::available_parallelism()
        .map(|n| n.get())
        .unwrap_or(1)
        .min(ms.len())
        .max(1);
    let next = AtomicUsize::new(0);
    let cancelled = AtomicBool::new(false);
    let slots: Vec<Mutex<Option<Result<Step1Result>>>> =
        ms.iter().map(|_| Mutex::new(None)).collect();
    std::thread::scope(|s| {
        for _ in 0..threads {
            s.spawn(|| loop {
                let j = next.fetch_add(1, Ordering::SeqCst);
                if j >= ms.len() {
                    break;
                }
                let r = if cancelled.load(Ordering::SeqCst) {
                    Err(Error::Cancelled)
                } else {
                    run_candidate(prep, ms[j], opts, &mut |p| {
                        if cancelled.load(Ordering::SeqCst) {
                            return Control::Cancel;
                        }
                        let c = cb(p);
                        if c == Control::Cancel {
                            cancelled.store(true, Ordering::SeqCst);
                        }
                        c
                    })
                };
                if let Ok(mut g) = slots[j].lock() {
                    *g = Some(r);
                }
            });
        }
    });
    slots
        .into_iter()
        .map(|m| {
            m.into_inner()
                .ok()
                .flatten()
                .unwrap_or(Err(Error::Cancelled))
        })
        .collect()
}

#[cfg(test)]
mod size_rule_tests {
    use super::*;
    use crate::io::sequence::Frame;
    use crate::math::Libm;

    fn seq(sizes: &[usize]) -> Sequence {
        Sequence {
            frames: sizes
                .iter()
                .map(|&n| Frame {
                    points: vec![glam::Vec3::ZERO; n],
                    ..Default::default()
                })
                .collect(),
        }
    }

    #[test]
    fn fast_tries_the_two_ends_of_the_range_on_full_input() {
        let parts = |lo, hi, q, occluded| candidate_parts(lo, hi, q, occluded).unwrap();
        assert_eq!(parts(10, 15, Quality::Fast, false), vec![10, 15]);
        assert_eq!(parts(3, 7, Quality::Fast, false), vec![3, 7]);
        assert_eq!(parts(2, 3, Quality::Fast, false), vec![2, 3]);
        assert_eq!(parts(5, 5, Quality::Fast, false), vec![5]);
        assert_eq!(parts(5, 5, Quality::Fast, true), vec![5]);
        for occluded in [false, true] {
            let all = (10..=15).collect::<Vec<_>>();
            assert_eq!(parts(10, 15, Quality::Balanced, occluded), all);
            assert_eq!(parts(3, 7, Quality::Paper, occluded), vec![3, 4, 5, 6, 7]);
        }
        assert_eq!(
            parts(10, 15, Quality::Fast, true),
            (10..=15).collect::<Vec<_>>()
        );
        assert!(candidate_parts(0, 3, Quality::Fast, false).is_err());
        assert!(candidate_parts(4, 3, Quality::Fast, true).is_err());
    }

    #[test]
    fn a_failed_top_of_the_default_range_brings_one_more_candidate_above_it() {
        let fast = Quality::Fast;
        // m = 15 ended 3× above m = 10 (talos, fast, seed 0): try m = 20.
        let failed = [(10, 5.0e-4), (15, 1.52e-3)];
        assert_eq!(extra_candidate(&failed, fast, false, true), Some(20));
        assert_eq!(
            extra_candidate(&[(3, 1e-3), (7, 2e-3)], fast, false, true),
            Some(11)
        );
        // A top that fitted (within the ratio, or better) brings none.
        assert_eq!(
            extra_candidate(&[(10, 5.0e-4), (15, 7.4e-4)], fast, false, true),
            None
        );
        assert_eq!(
            extra_candidate(&[(10, 5.0e-4), (15, 2e-4)], fast, false, true),
            None
        );
        // Only Fast on full input over the default range, with its two ends.
        assert_eq!(
            extra_candidate(&failed, Quality::Balanced, false, true),
            None
        );
        assert_eq!(extra_candidate(&failed, fast, true, true), None);
        assert_eq!(extra_candidate(&failed, fast, false, false), None);
        assert_eq!(extra_candidate(&failed[..1], fast, false, true), None);
        let three = [(10, 5.0e-4), (12, 1e-3), (15, 1.52e-3)];
        assert_eq!(extra_candidate(&three, fast, false, true), None);
        // A top that did not end finite failed too; a bottom that did not is no reference.
        assert_eq!(
            extra_candidate(&[(10, 5.0e-4), (15, f64::NAN)], fast, false, true),
            Some(20)
        );
        assert_eq!(
            extra_candidate(&[(10, f64::NAN), (15, 1e-3)], fast, false, true),
            None
        );
    }

    #[test]
    fn fast_tries_every_part_count_when_the_frames_are_fitted_as_occluded() {
        // Frame sizes that differ by more than 15 % are detected as occluded.
        let cloud = |n: usize| -> Vec<glam::Vec3> {
            (0..n)
                .map(|i| glam::Vec3::new(i as f32, (i * i % 7) as f32, (i % 3) as f32))
                .collect()
        };
        let frames = |sizes: &[usize]| Sequence {
            frames: sizes
                .iter()
                .map(|&n| Frame {
                    points: cloud(n),
                    ..Default::default()
                })
                .collect(),
        };
        let opts = FitOptions {
            quality: Quality::Fast,
            parts: Some((3, 6)),
            ..FitOptions::default()
        };
        let uneven = frames(&[300, 200, 300]);
        let even = frames(&[300, 300, 300]);
        assert!(will_be_occluded(&uneven, &opts).unwrap());
        assert!(!will_be_occluded(&even, &opts).unwrap());
        assert_eq!(candidates(&uneven, &opts).unwrap(), vec![3, 4, 5, 6]);
        assert_eq!(candidates(&even, &opts).unwrap(), vec![3, 6]);
        // The option decides over the detection.
        let off = FitOptions {
            occlusion: Occlusion::Off,
            ..opts.clone()
        };
        assert_eq!(candidates(&uneven, &off).unwrap(), vec![3, 6]);
        let on = FitOptions {
            occlusion: Occlusion::On,
            ..opts
        };
        assert_eq!(candidates(&even, &on).unwrap(), vec![3, 4, 5, 6]);
        // Input the fit would refuse is refused here too.
        assert!(candidates(&frames(&[300]), &on).is_err());
    }

    #[test]
    fn prepare_cache_reuses_only_the_same_sequence_and_options() {
        let mk = |shift: f32| Sequence {
            frames: (0..3)
                .map(|k| Frame {
                    name: format!("{k}.ply"),
                    points: (0..200)
                        .map(|i| {
                            let a = i as f32 * 0.1 + k as f32 * 0.05;
                            glam::Vec3::new(a.lcos(), a.lsin(), i as f32 * 0.01 + shift)
                        })
                        .collect(),
                    ..Default::default()
                })
                .collect(),
        };
        let opts = FitOptions::default();
        let mut cache = PrepareCache::default();
        let a = cache.get(&mk(0.0), &opts).unwrap();
        let b = cache.get(&mk(0.0), &opts).unwrap();
        assert!(std::rc::Rc::ptr_eq(&a, &b));
        // Another part range: same preparation.
        let ranged = FitOptions {
            parts: Some((2, 3)),
            ..opts.clone()
        };
        assert!(std::rc::Rc::ptr_eq(
            &a,
            &cache.get(&mk(0.0), &ranged).unwrap()
        ));
        // Moved points or another seed: prepared again.
        let c = cache.get(&mk(1e-3), &opts).unwrap();
        assert!(!std::rc::Rc::ptr_eq(&a, &c));
        let seeded = FitOptions { seed: 7, ..opts };
        assert!(!std::rc::Rc::ptr_eq(
            &c,
            &cache.get(&mk(1e-3), &seeded).unwrap()
        ));
    }

    #[test]
    fn dense_single_view_frames_are_detected_as_occluded_before_downsampling() {
        // Frames of 900, 600 and 750 points (one camera each would see that much
        // more or less), all above a working size of 256: the working clouds have
        // equal counts, the input frames do not.
        let frames = |sizes: &[usize]| {
            frames_of(sizes, |_, i, n| {
                let a = i as f32 * 2.399_963;
                let z = 1.0 - 2.0 * (i as f32 + 0.5) / n as f32;
                let r = (1.0 - z * z).max(0.0).sqrt();
                glam::Vec3::new(r * a.lcos(), r * a.lsin(), z)
            })
        };
        let opts = FitOptions {
            working_size: 256,
            ..FitOptions::default()
        };
        let varied = prepare(&frames(&[900, 600, 750]), &opts).unwrap();
        assert!(varied.data.frames.iter().all(|f| f.len() == 256));
        assert!(varied.occluded);
        assert!(!prepare(&frames(&[900, 880, 900]), &opts).unwrap().occluded);
        // Below the working size the counts speak for themselves, as before.
        assert!(prepare(&frames(&[200, 120, 180]), &opts).unwrap().occluded);
        let off = FitOptions {
            occlusion: Occlusion::Off,
            ..opts
        };
        assert!(!prepare(&frames(&[900, 600, 750]), &off).unwrap().occluded);
    }

    #[test]
    fn single_view_frames_of_equal_counts_are_detected_as_occluded() {
        // What a camera 3 radii from a unit sphere sees (the cap within acos(1/3) of
        // its direction), n points evenly spread over it.
        let cap = |n: usize, dir: glam::DVec3| -> Vec<glam::Vec3> {
            let d = dir.normalize();
            let (u, w) = d.any_orthonormal_pair();
            (0..n)
                .map(|i| {
                    let z = 1.0 - (2.0 / 3.0) * (i as f64 + 0.5) / n as f64;
                    let r = (1.0 - z * z).sqrt();
                    let phi = i as f64 * 2.399_963;
                    (d * z + u * (r * phi.lcos()) + w * (r * phi.lsin())).as_vec3()
                })
                .collect()
        };
        let seq = |n: usize, whole: bool| Sequence {
            frames: (0..4)
                .map(|k| {
                    let dir = glam::DVec3::new(1.0, 0.4 * k as f64, -0.3 * k as f64);
                    let mut points = cap(n, dir);
                    if whole {
                        points.extend(cap(n, -dir));
                        points.extend(cap(n / 2, dir.cross(glam::DVec3::Z)));
                        points.extend(cap(n / 2, -dir.cross(glam::DVec3::Z)));
                    }
                    Frame {
                        name: format!("{k}.ply"),
                        points,
                        ..Default::default()
                    }
                })
                .collect(),
        };
        let opts = FitOptions::default();
        // 1200 points in every frame: the counts say nothing, the views do.
        assert!(prepare(&seq(1200, false), &opts).unwrap().occluded);
        // The whole sphere (3600 points a frame) is two layers from every side.
        assert!(!prepare(&seq(1200, true), &opts).unwrap().occluded);
        // Below 1024 points a frame the view is not judged.
        assert!(!prepare(&seq(800, false), &opts).unwrap().occluded);
    }

    /// A bent strip moving over three frames (too few points for the pose search: the
    /// plain gradient fit, quick), prepared with a short fast fit's options.
    fn quick_strip() -> (Prepared, FitOptions) {
        let opts = FitOptions {
            quality: Quality::Fast,
            iters: Some(40),
            ..FitOptions::default()
        };
        (prepare(&bent_strip(&[240; 3]), &opts).unwrap(), opts)
    }

    #[test]
    fn restarts_keep_the_lowest_chamfer_of_their_seeds() {
        let (prep, opts) = quick_strip();
        let single = |r: usize| {
            let o = FitOptions {
                seed: restart_seed(opts.seed, r),
                restarts: Some(1),
                ..opts.clone()
            };
            run_candidate(&prep, 2, &o, &mut |_| Control::Continue).unwrap()
        };
        let (a, b) = (single(0), single(1));
        assert_ne!(
            a.final_chamfer, b.final_chamfer,
            "the seeds must give different fits"
        );
        let winner = if b.final_chamfer < a.final_chamfer {
            &b
        } else {
            &a
        };
        let mut last = (0, 0);
        let two = FitOptions {
            restarts: Some(2),
            ..opts.clone()
        };
        let best = run_candidate(&prep, 2, &two, &mut |p| {
            assert!(p.iter <= p.total);
            last = (p.iter, p.total);
            Control::Continue
        })
        .unwrap();
        assert_eq!(best.final_chamfer, winner.final_chamfer);
        assert_eq!(best.labels, winner.labels);
        assert_eq!(best.restarts, 2);
        assert_eq!(best.iterations, winner.iterations);
        assert_eq!(best.timings.per_candidate[0].2, a.iterations + b.iterations);
        // Progress ran through both fits: the last report is in the second half.
        assert!(2 * last.0 >= last.1, "{last:?}");
        // Zero or too many fits are refused, not run.
        for n in [0, MAX_RESTARTS + 1] {
            let o = FitOptions {
                restarts: Some(n),
                ..opts.clone()
            };
            assert!(run_candidate(&prep, 2, &o, &mut |_| Control::Continue).is_err());
        }
        // One restart is the plain fit.
        assert_eq!(restart_seed(7, 0), 7);
    }

    #[test]
    fn the_medial_initialisation_changes_the_start_and_is_recorded() {
        let (prep, opts) = quick_strip();
        let run = |medial_init: bool| {
            let o = FitOptions {
                medial_init,
                ..opts.clone()
            };
            run_candidate(&prep, 2, &o, &mut |_| Control::Continue).unwrap()
        };
        let (points, medial) = (run(false), run(true));
        assert_eq!(points.medial_init, None);
        assert_eq!(medial.medial_init, Some(true));
        assert_ne!(points.final_chamfer, medial.final_chamfer);
    }

    /// Frames of `n[k]` points, point i of frame k at `point(k, i, n[k])`.
    fn frames_of(n: &[usize], point: impl Fn(usize, usize, usize) -> glam::Vec3) -> Sequence {
        Sequence {
            frames: n
                .iter()
                .enumerate()
                .map(|(k, &n)| Frame {
                    name: format!("{k}.ply"),
                    points: (0..n).map(|i| point(k, i, n)).collect(),
                    ..Default::default()
                })
                .collect(),
        }
    }

    /// A strip of `n[k]` points whose half beyond x = 0.5 curls up more in every frame.
    fn bent_strip(n: &[usize]) -> Sequence {
        frames_of(n, |k, i, _| {
            let u = (i % 40) as f32 / 40.0;
            let v = (i / 40) as f32 * 0.02;
            let a = if u > 0.5 {
                (u - 0.5) * k as f32 * 0.8
            } else {
                0.0
            };
            glam::Vec3::new(
                u.min(0.5) + (u - 0.5).max(0.0) * a.lcos(),
                v,
                (u - 0.5).max(0.0) * a.lsin(),
            )
        })
    }

    /// After the pose search the main loop only polishes: fast a twelfth of its preset
    /// on full input, but on occluded input a quarter, as long as balanced on
    /// robot-sized input; then the segmenting copy's iterations.
    #[test]
    fn fast_polishes_occluded_frames_as_long_as_balanced() {
        // Robot-sized (`is_small` false: point counts varying by more than 15 %, 6000
        // in all), so both presets take their robot schedules.
        let seq = bent_strip(&[1600, 1400, 2000, 1500]);
        assert!(!is_small(&seq, 4096));
        let iterations = |quality, occlusion| {
            let opts = FitOptions {
                quality,
                occlusion,
                ..FitOptions::default()
            };
            let prep = prepare(&seq, &opts).unwrap();
            let r = run_candidate(&prep, 2, &opts, &mut |_| Control::Continue).unwrap();
            r.iterations
        };
        assert_eq!(iterations(Quality::Fast, Occlusion::Off), 100);
        assert_eq!(iterations(Quality::Balanced, Occlusion::Off), 300);
        assert_eq!(
            iterations(Quality::Fast, Occlusion::On),
            300 + SEGMENT_ITERS
        );
        assert_eq!(
            iterations(Quality::Balanced, Occlusion::On),
            300 + SEGMENT_ITERS
        );
    }

    #[test]
    fn occluded_step1_starts_from_the_frame_with_the_most_points() {
        // At least `OCCLUDED_SEARCH_MIN_POINTS` a frame, so the search poses the frames.
        let seq = bent_strip(&[480, 440, 640, 560]);
        let opts = FitOptions {
            quality: Quality::Fast,
            iters: Some(40),
            occlusion: Occlusion::On,
            ..FitOptions::default()
        };
        let prep = prepare(&seq, &opts).unwrap();
        assert_eq!(prep.order.order, vec![2, 3, 1, 0]);
        assert_eq!(prep.data.frames32[0].len(), 640);
        assert_eq!(prep.data.track_from, vec![0, 0, 0, 2]);
        let r = run_candidate(&prep, 2, &opts, &mut |_| Control::Continue).unwrap();
        assert_eq!(r.canonical, 2);
        // Labels and model are back in input order: every frame's labels are the
        // model's segmentation of that frame, with that frame's poses, and each
        // frame's poses fit its own (differently bent) strip better than the other
        // frames' poses do.
        let maha = |model: &super::super::GaussianModel, j: usize, pts: &[glam::Vec3]| {
            let gs = model.frame_gaussians(j);
            pts.iter()
                .map(|p| super::super::gaussians::argmin_maha(&gs, p.as_dvec3()).1)
                .sum::<f64>()
                / pts.len() as f64
        };
        for (k, f) in seq.frames.iter().enumerate() {
            assert_eq!(r.labels[k], r.model.segment(k, &f.points), "frame {k}");
            let own = maha(&r.model, k, &f.points);
            for j in (0..4usize).filter(|&j| j.abs_diff(k) >= 2) {
                let other = maha(&r.model, j, &f.points);
                assert!(
                    own < other,
                    "frame {k}: own poses {own}, frame {j}'s {other}"
                );
            }
        }
        // Steps 2–3 take it as the canonical frame. Its points are labelled by the
        // posed model, the other frames' by the segmenting copy, refined on each
        // frame's points (`kinematics::frame_gmm`).
        let (model, seg) = (r.model.clone(), r.segmenter.clone().expect("a segmenter"));
        let m = model.m;
        let out = crate::pipeline::finish(&seq, r, &|| 0.0, &mut |_| Control::Continue).unwrap();
        let res = &out.result;
        assert_eq!(res.canonical_frame, 2);
        for (k, f) in seq.frames.iter().enumerate() {
            let mut want = if k == 2 { &model } else { &seg }.segment(k, &f.points);
            if k != 2 {
                crate::kinematics::frame_gmm::refine_frame(&f.points, &mut want, m);
            }
            let want: Vec<u32> = want
                .into_iter()
                .map(|g| out.kin.merge_map[g as usize])
                .collect();
            assert_eq!(res.labels[k], want, "frame {k}");
        }
        // The two label differently, so the check above tells them apart.
        let differ = (0..4).any(|k| {
            let pts = &seq.frames[k].points;
            model.segment(k, pts) != seg.segment(k, pts)
        });
        assert!(differ);
        assert_eq!(res.points.as_ref().map(Vec::len), Some(640));
        for p in 0..res.parts {
            let d = res.pose(2, p).unwrap() - glam::DMat4::IDENTITY;
            assert!(d.to_cols_array().iter().all(|v| v.abs() < 1e-9), "part {p}");
        }
        // Full input keeps frame 0 and time order.
        let full = prepare(
            &seq,
            &FitOptions {
                occlusion: Occlusion::Off,
                ..opts
            },
        )
        .unwrap();
        assert_eq!(full.order, FrameOrder::identity(4));
        assert_eq!(full.data.track_from, vec![0, 0, 1, 2]);
        // Unless asked to start from the last frame (the balanced preset's third
        // attempt): the frames backwards, each tracked from the one after it, and the
        // last frame is the canonical one.
        let last_opts = FitOptions {
            occlusion: Occlusion::Off,
            from_last_frame: true,
            ..opts
        };
        let last = prepare(&seq, &last_opts).unwrap();
        assert_eq!(last.order.order, vec![3, 2, 1, 0]);
        assert_eq!(last.data.track_from, vec![0, 0, 1, 2]);
        let r = run_candidate(&last, 2, &last_opts, &mut |_| Control::Continue).unwrap();
        assert_eq!(r.canonical, 3);
        for (k, f) in seq.frames.iter().enumerate() {
            assert_eq!(r.labels[k], r.model.segment(k, &f.points), "frame {k}");
        }
    }

    #[test]
    fn part_range_follows_density_and_occlusion() {
        assert_eq!(default_part_range(&seq(&[4096; 10])), (10, 15)); // RoboArt
        assert_eq!(default_part_range(&seq(&[512; 4])), (3, 7)); // Sapien
        assert_eq!(default_part_range(&seq(&[2048; 10])), (3, 7)); // a dense small object
        let occluded = [800, 650, 900, 1000, 700, 820, 760, 900, 640, 880];
        assert_eq!(default_part_range(&seq(&occluded)), (10, 15)); // Occluded-RoboArt
    }
}
