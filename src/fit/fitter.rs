//! The Step-1 optimisation of one candidate m: warm-up on the first frame, then per
//! iteration one Adam step on L_MLE + L_sep at a random frame k and one on the
//! transfer losses (Chamfer, then EMD after the switch, flow; or the occluded-input
//! variants) without L_MLE. Runs single-threaded; model selection runs several.

use glam::{DVec3, Vec3};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

use super::adam::Adam;
use super::flow::SceneFlow;
use super::gaussians::{Gauss, GradAcc, Params, TransferSrc};
use super::init;
use super::losses::{chamfer, emd, flow, mle, sep};
use super::motion_seg::{self, MotionSegOpts};
use super::pose_init::{self, PoseInitOpts};
use super::pose_search::{self, PoseSearchOpts};
use super::schedule::Schedule;
use crate::geom::assignment::Lap;
use crate::geom::knn::Grid;
use crate::pipeline::{Control, Progress, Stage};
use crate::{Error, Result};

/// The working clouds of a sequence with their static nearest-neighbour indices.
#[derive(Debug, Clone)]
pub struct Data {
    pub frames32: Vec<Vec<Vec3>>,
    pub frames: Vec<Vec<DVec3>>,
    pub grids: Vec<Grid>,
    /// Per frame, the earlier frame the occluded search poses it from (`t − 1` unless
    /// set; see `start_frame::FrameOrder`).
    pub track_from: Vec<usize>,
    /// The pose search's distance cap and, per frame, the places beyond it (built
    /// by `pose_search` on first use, then shared by its searches and candidates).
    pub(crate) search_cap: std::sync::OnceLock<pose_search::SearchCap>,
}

impl Data {
    pub fn new(frames32: Vec<Vec<Vec3>>) -> Self {
        let frames = frames32
            .iter()
            .map(|f| f.iter().map(|p| p.as_dvec3()).collect())
            .collect();
        let grids = frames32.iter().map(|f| Grid::new(f)).collect();
        let track_from = (0..frames32.len()).map(|t| t.saturating_sub(1)).collect();
        Data {
            frames32,
            frames,
            grids,
            track_from,
            search_cap: std::sync::OnceLock::new(),
        }
    }
    pub fn k(&self) -> usize {
        self.frames.len()
    }
}

/// Loss weights (λ). `sep` multiplies the paper's ratio (see `losses` docs).
#[derive(Debug, Clone, PartialEq)]
pub struct Weights {
    pub mle: f64,
    pub sep: f64,
    pub cd: f64,
    pub emd: f64,
    pub flow: f64,
    pub split: f64,
}

impl Default for Weights {
    fn default() -> Self {
        Weights {
            mle: 1.0,
            sep: 1.0,
            cd: 1.0,
            emd: 0.3,
            flow: 1.0,
            split: 1.0,
        }
    }
}

/// Everything that configures one candidate's fit.
#[derive(Debug, Clone)]
pub struct FitConfig {
    pub sched: Schedule,
    pub occlusion: bool,
    pub seed: u64,
    pub weights: Weights,
    pub alpha: f64,
    /// Call the progress callback every this many iterations.
    pub report_every: usize,
    /// Attach a snapshot every this many iterations (0 = never).
    pub snapshot_every: usize,
    /// Tracking initialisation (see `track_init`); off by default: measured worse
    /// (lower Chamfer, higher reconstruction error). false = every frame starts as frame 0.
    pub track_init: bool,
    /// MLE iterations per frame in the tracking initialisation.
    pub track_iters: usize,
    /// Per-frame pose initialisation from tracked correspondences
    /// (`pose_init::init_poses`); full (non-occluded) input only. None = off.
    /// On by default: measured (Fast, m = 12, so101/solo12/finger_edu full) mean
    /// reconstruction error 7.52 → 4.69, flow error 8.16 → 4.55.
    pub pose_init: Option<PoseInitOpts>,
    /// Global pose search after the pose initialisation
    /// (`pose_search::search_poses`; on occluded input `occluded_search`, when
    /// `PoseSearchOpts::occluded`). None = off.
    /// On by default: measured (Fast, true part count, bench-dev full) mean Step-1
    /// reconstruction error 7.30 → 1.59 before the main loop.
    pub pose_search: Option<PoseSearchOpts>,
    /// Motion re-segmentation rounds after the pose search
    /// (`motion_seg::resegment`, each followed by a new search); used only with
    /// `pose_search`. None = off.
    pub motion_seg: Option<MotionSegOpts>,
    /// After the main loop, a copy of the Gaussians goes on for this many iterations
    /// of the same losses at the preset's learning rate (`Schedule::lr`, not the
    /// search's polishing rate); `fit_candidate_segmented` returns it as the model
    /// that segments the frames, while the poses stay the main loop's. 0 = off. Meant
    /// for occluded input (see `select`): there the searched, rigidly moving
    /// Gaussians give the better part poses, but Gaussians that follow each frame's
    /// visible points label them better.
    pub segment_iters: usize,
    /// Initial centres on the start frame's medial-axis estimate
    /// (`init::initial_params_medial`; `FitOptions::medial_init`); ignored on
    /// occluded input.
    pub medial_init: bool,
}

impl FitConfig {
    pub fn new(sched: Schedule, occlusion: bool, seed: u64) -> Self {
        let motion_seg = MotionSegOpts {
            rounds: sched.reseg_rounds,
            ..Default::default()
        };
        FitConfig {
            sched,
            occlusion,
            seed,
            weights: Weights::default(),
            alpha: 0.5,
            track_init: false,
            track_iters: 100,
            pose_init: Some(PoseInitOpts::default()),
            pose_search: Some(PoseSearchOpts::default()),
            motion_seg: Some(motion_seg),
            segment_iters: 0,
            medial_init: false,
            report_every: 10,
            snapshot_every: 50,
        }
    }
}

/// Precomputed scene flow: per frame k, fixed sample points and their estimated
/// motion to k+1 and k−1.
#[derive(Debug, Clone, Default)]
pub struct FlowField {
    pub idx: Vec<Vec<usize>>,
    pub fwd: Vec<Option<Vec<DVec3>>>,
    pub bwd: Vec<Option<Vec<DVec3>>>,
}

impl FlowField {
    /// Estimates flows between consecutive frames on `n` points per frame.
    pub fn compute(data: &Data, est: &dyn SceneFlow, n: usize, seed: u64) -> Self {
        let kk = data.k();
        let mut ff = FlowField {
            idx: vec![Vec::new(); kk],
            fwd: vec![None; kk],
            bwd: vec![None; kk],
        };
        for k in 0..kk {
            let len = data.frames32[k].len();
            let step = (len / n.max(1)).max(1);
            ff.idx[k] = (0..len).step_by(step).take(n).collect();
        }
        for k in 0..kk {
            for (dir, t) in [(0, k + 1), (1, k.wrapping_sub(1))] {
                if t >= kk {
                    continue;
                }
                let seed = seed ^ ((k * kk + t) as u64).wrapping_mul(0x9E37_79B9);
                if let Some(f) = est.estimate(&data.frames32[k], &data.frames32[t], seed) {
                    let v: Vec<DVec3> = ff.idx[k].iter().map(|&i| f[i].as_dvec3()).collect();
                    if dir == 0 {
                        ff.fwd[k] = Some(v);
                    } else {
                        ff.bwd[k] = Some(v);
                    }
                }
            }
        }
        ff
    }
}

/// Fixed EMD correspondence of one iteration (re-used for a few uses).
#[derive(Debug, Clone, Default)]
pub struct EmdPair {
    pub t: usize,
    /// Full mode: rows = points of the source frame, cols = points of frame t.
    /// Occluded mode: rows = points of frame t, cols = fused points (frame, index).
    pub rows: Vec<usize>,
    pub cols: Vec<(usize, usize)>,
    pub sigma: Vec<usize>,
    pub uses: usize,
}

/// The random draws of one transfer step, so the loss is a deterministic
/// function of the parameters (used by the gradient tests too).
#[derive(Debug, Clone, Default)]
pub struct PlanB {
    pub k: usize,
    pub occluded: bool,
    /// Full: src[k] is the source batch. Occluded: src[j] is the batch of frame j.
    pub src: Vec<Vec<usize>>,
    /// Per frame: subsample for the reverse (Full) / observed-to-fusion (Occluded) Chamfer.
    pub rev: Vec<Vec<usize>>,
    pub use_cd: bool,
    pub emd: Vec<EmdPair>,
    pub flow: bool,
    /// Occluded: half membership per frame for the split-half regulariser.
    pub split: Option<Vec<bool>>,
}

/// Named loss values of a transfer step.
#[derive(Debug, Clone, Copy, Default)]
pub struct LossesB {
    pub cd: f64,
    pub emd: f64,
    pub flow: f64,
    pub split: f64,
}

/// Scratch buffers reused across iterations.
#[derive(Debug, Default)]
pub struct Ws {
    pub gs: Vec<Vec<Gauss>>,
    srcs: Vec<TransferSrc>,
    owner: Vec<usize>,
    pts: Vec<DVec3>,
    moved: Vec<DVec3>,
    gmoved: Vec<DVec3>,
    q: Vec<DVec3>,
    a: Vec<DVec3>,
    b: Vec<DVec3>,
    amap: Vec<usize>,
    bmap: Vec<usize>,
    ga: Vec<DVec3>,
    gb: Vec<DVec3>,
    grid: Grid,
    grid2: Grid,
    buf32: Vec<Vec3>,
    scratch: Vec<(f64, DVec3)>,
    lap: Lap,
    cost: Vec<f64>,
}

impl Ws {
    pub fn eval_all(&mut self, params: &Params) {
        let kk = params.layout.frames;
        self.gs.resize_with(kk, Vec::new);
        for k in 0..kk {
            params.frame_into(k, &mut self.gs[k]);
        }
    }
}

/// Step A: L_MLE + L_sep at frame k on `batch` (indices into frame k).
/// Expects `ws.gs[k]` evaluated. Returns (mle, sep).
pub fn loss_a(
    data: &Data,
    k: usize,
    batch: &[usize],
    cfg: &FitConfig,
    ws: &mut Ws,
    mut acc: Option<&mut GradAcc>,
) -> (f64, f64) {
    ws.pts.clear();
    ws.pts.extend(batch.iter().map(|&i| data.frames[k][i]));
    let gs = &ws.gs[k];
    let l_mle = mle::mle(
        gs,
        k,
        &ws.pts,
        cfg.weights.mle,
        acc.as_deref_mut(),
        &mut ws.scratch,
    );
    let n_ref = data.frames[k].len().max(1) as f64;
    let l_sep = sep::sep(gs, k, cfg.alpha, cfg.weights.sep / n_ref, acc);
    (l_mle, l_sep * n_ref / cfg.weights.sep.max(1e-300))
}

fn prep_srcs(gs: &[Gauss], pts: &[DVec3], idx: &[usize], srcs: &mut Vec<TransferSrc>) {
    srcs.clear();
    srcs.extend(idx.iter().map(|&i| TransferSrc::new(gs, pts[i])));
}

fn move_srcs(gs: &[Gauss], srcs: &[TransferSrc], out: &mut Vec<DVec3>) {
    out.clear();
    out.extend(srcs.iter().map(|s| s.moved(gs)));
}

fn backward_srcs(
    acc: &mut GradAcc,
    gs: &[Vec<Gauss>],
    k: usize,
    t: usize,
    srcs: &[TransferSrc],
    g: &[DVec3],
) {
    for (s, gv) in srcs.iter().zip(g) {
        if *gv != DVec3::ZERO {
            let i = s.label as usize;
            acc.transfer_backward(k, t, i, s, &gs[k][i], &gs[t][i], *gv);
        }
    }
}

/// Step B: the transfer losses of `plan`. Expects every frame of `ws.gs` evaluated.
pub fn loss_b(
    data: &Data,
    plan: &PlanB,
    cfg: &FitConfig,
    ff: Option<&FlowField>,
    ws: &mut Ws,
    mut acc: Option<&mut GradAcc>,
) -> LossesB {
    if plan.occluded {
        return loss_b_occluded(data, plan, cfg, ws, acc);
    }
    let w = &cfg.weights;
    let k = plan.k;
    let kk = data.k();
    let mut out = LossesB::default();
    let gs = std::mem::take(&mut ws.gs);
    if plan.use_cd {
        prep_srcs(&gs[k], &data.frames[k], &plan.src[k], &mut ws.srcs);
        for t in (0..kk).filter(|&t| t != k) {
            move_srcs(&gs[t], &ws.srcs, &mut ws.moved);
            ws.gmoved.clear();
            ws.gmoved.resize(ws.moved.len(), DVec3::ZERO);
            out.cd += chamfer::directed(
                &ws.moved,
                &data.frames[t],
                &data.grids[t],
                w.cd,
                Some(&mut ws.gmoved),
                None,
            );
            chamfer::index(&mut ws.grid, &ws.moved, &mut ws.buf32);
            ws.q.clear();
            ws.q.extend(plan.rev[t].iter().map(|&i| data.frames[t][i]));
            out.cd +=
                chamfer::directed(&ws.q, &ws.moved, &ws.grid, w.cd, None, Some(&mut ws.gmoved));
            if let Some(acc) = acc.as_deref_mut() {
                backward_srcs(acc, &gs, k, t, &ws.srcs, &ws.gmoved);
            }
        }
    }
    for pair in &plan.emd {
        let t = pair.t;
        ws.pts.clear();
        ws.pts.extend(pair.rows.iter().map(|&i| data.frames[k][i]));
        ws.srcs.clear();
        ws.srcs
            .extend(ws.pts.iter().map(|&x| TransferSrc::new(&gs[k], x)));
        move_srcs(&gs[t], &ws.srcs, &mut ws.moved);
        ws.q.clear();
        ws.q.extend(pair.cols.iter().map(|&(_, i)| data.frames[t][i]));
        ws.gmoved.clear();
        ws.gmoved.resize(ws.moved.len(), DVec3::ZERO);
        out.emd += emd::emd(
            &ws.moved,
            &ws.q,
            &pair.sigma,
            w.emd,
            Some(&mut ws.gmoved),
            None,
        );
        if let Some(acc) = acc.as_deref_mut() {
            backward_srcs(acc, &gs, k, t, &ws.srcs, &ws.gmoved);
        }
    }
    if let (true, Some(ff)) = (plan.flow, ff) {
        prep_srcs(&gs[k], &data.frames[k], &ff.idx[k], &mut ws.srcs);
        ws.pts.clear();
        ws.pts.extend(ff.idx[k].iter().map(|&i| data.frames[k][i]));
        for (t, est) in [(k + 1, &ff.fwd[k]), (k.wrapping_sub(1), &ff.bwd[k])] {
            let Some(est) = est else { continue };
            if t >= kk {
                continue;
            }
            move_srcs(&gs[t], &ws.srcs, &mut ws.moved);
            ws.gmoved.clear();
            ws.gmoved.resize(ws.moved.len(), DVec3::ZERO);
            out.flow += flow::flow(&ws.moved, &ws.pts, est, w.flow, Some(&mut ws.gmoved));
            if let Some(acc) = acc.as_deref_mut() {
                backward_srcs(acc, &gs, k, t, &ws.srcs, &ws.gmoved);
            }
        }
    }
    ws.gs = gs;
    out
}

/// Occluded-input transfer losses at frame t = plan.k (supplement).
fn loss_b_occluded(
    data: &Data,
    plan: &PlanB,
    cfg: &FitConfig,
    ws: &mut Ws,
    mut acc: Option<&mut GradAcc>,
) -> LossesB {
    let w = &cfg.weights;
    let t = plan.k;
    let kk = data.k();
    let mut out = LossesB::default();
    let gs = std::mem::take(&mut ws.gs);
    // Fusion of the other frames moved to t (owner frame per point).
    ws.srcs.clear();
    ws.owner.clear();
    for j in (0..kk).filter(|&j| j != t) {
        for &i in &plan.src[j] {
            ws.srcs.push(TransferSrc::new(&gs[j], data.frames[j][i]));
            ws.owner.push(j);
        }
    }
    ws.moved.clear();
    ws.moved
        .extend(ws.srcs.iter().zip(&ws.owner).map(|(s, _)| s.moved(&gs[t])));
    let n_mov = ws.moved.len();
    ws.gmoved.clear();
    ws.gmoved.resize(n_mov, DVec3::ZERO);
    if plan.use_cd && n_mov > 0 {
        chamfer::index(&mut ws.grid, &ws.moved, &mut ws.buf32);
        ws.q.clear();
        ws.q.extend(plan.rev[t].iter().map(|&i| data.frames[t][i]));
        out.cd += chamfer::directed(&ws.q, &ws.moved, &ws.grid, w.cd, None, Some(&mut ws.gmoved));
    }
    if let Some(split) = &plan.split {
        // Halves: moved points by their owner's half, plus frame t's own batch.
        ws.a.clear();
        ws.b.clear();
        ws.amap.clear();
        ws.bmap.clear();
        for n in 0..n_mov {
            if split[ws.owner[n]] {
                ws.a.push(ws.moved[n]);
                ws.amap.push(n);
            } else {
                ws.b.push(ws.moved[n]);
                ws.bmap.push(n);
            }
        }
        for &i in &plan.src[t] {
            let x = data.frames[t][i];
            if split[t] {
                ws.a.push(x);
                ws.amap.push(usize::MAX);
            } else {
                ws.b.push(x);
                ws.bmap.push(usize::MAX);
            }
        }
        if !ws.a.is_empty() && !ws.b.is_empty() {
            ws.ga.clear();
            ws.ga.resize(ws.a.len(), DVec3::ZERO);
            ws.gb.clear();
            ws.gb.resize(ws.b.len(), DVec3::ZERO);
            chamfer::index(&mut ws.grid, &ws.b, &mut ws.buf32);
            chamfer::index(&mut ws.grid2, &ws.a, &mut ws.buf32);
            out.split += chamfer::directed(
                &ws.a,
                &ws.b,
                &ws.grid,
                w.split,
                Some(&mut ws.ga),
                Some(&mut ws.gb),
            );
            out.split += chamfer::directed(
                &ws.b,
                &ws.a,
                &ws.grid2,
                w.split,
                Some(&mut ws.gb),
                Some(&mut ws.ga),
            );
            for (n, g) in ws.amap.iter().zip(&ws.ga) {
                if *n != usize::MAX {
                    ws.gmoved[*n] += *g;
                }
            }
            for (n, g) in ws.bmap.iter().zip(&ws.gb) {
                if *n != usize::MAX {
                    ws.gmoved[*n] += *g;
                }
            }
        }
    }
    if let Some(acc) = acc.as_deref_mut() {
        for n in 0..n_mov {
            let g = ws.gmoved[n];
            if g != DVec3::ZERO {
                let (j, s) = (ws.owner[n], &ws.srcs[n]);
                let i = s.label as usize;
                acc.transfer_backward(j, t, i, s, &gs[j][i], &gs[t][i], g);
            }
        }
    }
    for pair in &plan.emd {
        ws.q.clear();
        ws.q.extend(pair.rows.iter().map(|&i| data.frames[t][i]));
        ws.srcs.clear();
        ws.srcs.extend(
            pair.cols
                .iter()
                .map(|&(j, i)| TransferSrc::new(&gs[j], data.frames[j][i])),
        );
        move_srcs(&gs[t], &ws.srcs, &mut ws.moved);
        ws.gmoved.clear();
        ws.gmoved.resize(ws.moved.len(), DVec3::ZERO);
        out.emd += emd::emd(
            &ws.q,
            &ws.moved,
            &pair.sigma,
            w.emd,
            None,
            Some(&mut ws.gmoved),
        );
        if let Some(acc) = acc.as_deref_mut() {
            for (n, &(j, _)) in pair.cols.iter().enumerate() {
                let g = ws.gmoved[n];
                if g != DVec3::ZERO {
                    let s = &ws.srcs[n];
                    let i = s.label as usize;
                    acc.transfer_backward(j, t, i, s, &gs[j][i], &gs[t][i], g);
                }
            }
        }
    }
    ws.gs = gs;
    out
}

fn sample(rng: &mut StdRng, len: usize, n: usize, out: &mut Vec<usize>) {
    out.clear();
    if len == 0 {
        return;
    }
    out.extend((0..n).map(|_| rng.random_range(0..len)));
}

/// n distinct indices (partial Fisher–Yates over a scratch permutation).
fn sample_distinct(
    rng: &mut StdRng,
    len: usize,
    n: usize,
    perm: &mut Vec<usize>,
    out: &mut Vec<usize>,
) {
    let n = n.min(len);
    perm.clear();
    perm.extend(0..len);
    for i in 0..n {
        let j = rng.random_range(i..len);
        perm.swap(i, j);
    }
    out.clear();
    out.extend_from_slice(&perm[..n]);
}

/// Timing-free statistics of a candidate's run.
#[derive(Debug, Clone, Default)]
pub struct FitStats {
    pub iterations: usize,
    pub emd_solves: usize,
    pub last: Vec<(String, f64)>,
}

/// Fits m Gaussians to `data`. `cb` is called every `cfg.report_every` iterations;
/// returning `Control::Cancel` ends the fit with `Error::Cancelled`.
pub fn fit_candidate(
    data: &Data,
    m: usize,
    cfg: &FitConfig,
    ff: Option<&FlowField>,
    cb: &mut dyn FnMut(&Progress) -> Control,
) -> Result<(Params, FitStats)> {
    fit_candidate_segmented(data, m, cfg, ff, cb).map(|(p, _, s)| (p, s))
}

/// [`fit_candidate`], also returning the Gaussians that segment the frames when
/// `cfg.segment_iters > 0` (see `FitConfig::segment_iters`).
pub fn fit_candidate_segmented(
    data: &Data,
    m: usize,
    cfg: &FitConfig,
    ff: Option<&FlowField>,
    cb: &mut dyn FnMut(&Progress) -> Control,
) -> Result<(Params, Option<Params>, FitStats)> {
    let kk = data.k();
    if kk < 2 || m == 0 {
        return Err(Error::InvalidArgument(format!(
            "Step 1 needs ≥ 2 frames and m ≥ 1 (got {kk} frames, m = {m})"
        )));
    }
    if data.frames.iter().any(|f| f.len() < m.max(2)) {
        return Err(Error::Sequence(format!(
            "every frame needs at least {} points for m = {m}",
            m.max(2)
        )));
    }
    let sched = &cfg.sched;
    let mut rng = StdRng::seed_from_u64(cfg.seed ^ (m as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15));
    let mut params = if cfg.medial_init && !cfg.occlusion {
        init::initial_params_medial(&data.frames32[0], m, kk)
    } else {
        init::initial_params(&data.frames32[0], m, kk)
    };
    let n = params.layout.len();
    let mut acc = GradAcc::new(params.layout);
    let mut flat = vec![0.0; n];
    let mut adam = Adam::new(n, sched.warmup_lr);
    let mut ws = Ws::default();
    let mut batch = Vec::new();
    let mut perm = Vec::new();
    let mut stats = FitStats::default();
    let report = |stage: Stage,
                  it: usize,
                  total: usize,
                  losses: Vec<(String, f64)>,
                  params: &Params,
                  snap: bool,
                  cb: &mut dyn FnMut(&Progress) -> Control|
     -> Result<()> {
        let snapshot = snap.then(|| params.to_model().snapshot(0, &data.frames32[0]));
        let p = Progress {
            stage,
            m: Some(m),
            iter: it,
            total,
            losses,
            snapshot,
        };
        match cb(&p) {
            Control::Cancel => Err(Error::Cancelled),
            Control::Continue => Ok(()),
        }
    };
    let every = cfg.report_every.max(1);
    // Warm-up on the first frame: MLE + sep set scales and centres.
    for it in 0..sched.warmup {
        ws.gs.resize_with(kk, Vec::new);
        params.frame_into(0, &mut ws.gs[0]);
        sample(&mut rng, data.frames[0].len(), sched.batch, &mut batch);
        acc.zero();
        let (lm, ls) = loss_a(data, 0, &batch, cfg, &mut ws, Some(&mut acc));
        acc.to_flat(&params, &mut flat);
        // Only frame 0 is being fitted: keep the other frames untouched.
        adam.step(&mut params.x, &flat);
        if it % every == 0 {
            report(
                Stage::Init,
                it,
                sched.warmup,
                vec![("mle".into(), lm), ("sep".into(), ls)],
                &params,
                cfg.snapshot_every > 0 && it % cfg.snapshot_every == 0,
                cb,
            )?;
        }
    }
    params.broadcast_frame(0);
    if cfg.track_init {
        track_init(data, &mut params, cfg, &mut rng, &mut ws)?;
    }
    if let (Some(o), false) = (&cfg.pose_init, cfg.occlusion) {
        pose_init::init_poses(data, &mut params, o, cfg.seed ^ m as u64);
    }
    let search = cfg
        .pose_search
        .as_ref()
        .filter(|o| !cfg.occlusion || o.occluded);
    if let Some(o) = search {
        let rounds = cfg.motion_seg.as_ref().map_or(0, |ms| ms.rounds);
        let total = (rounds + 1) * m;
        for round in 0..=rounds {
            if round > 0 {
                if let Some(ms) = &cfg.motion_seg {
                    motion_seg::resegment(data, &mut params, ms);
                }
            }
            // The live view shows the Gaussians the round starts from (the search
            // itself reports no snapshots: it holds the parameters).
            report(
                Stage::Init,
                round * m,
                total,
                Vec::new(),
                &params,
                cfg.snapshot_every > 0,
                cb,
            )?;
            // Progress (and a chance to cancel) after every Gaussian searched.
            let mut tick = |done: usize| -> Result<()> {
                let p = Progress {
                    stage: Stage::Init,
                    m: Some(m),
                    iter: round * m + done,
                    total,
                    losses: Vec::new(),
                    snapshot: None,
                };
                match cb(&p) {
                    Control::Cancel => Err(Error::Cancelled),
                    Control::Continue => Ok(()),
                }
            };
            let o = PoseSearchOpts {
                rotations: if round > 0 {
                    sched.later_rotations
                } else {
                    o.rotations
                },
                ..*o
            };
            if cfg.occlusion {
                super::occluded_search::search_poses_occluded(data, &mut params, &o, &mut tick)?;
            } else {
                pose_search::search_poses(data, &mut params, &o, &mut tick)?;
            }
        }
    }
    adam.reset();
    // On occluded input the main loop after the search (its 100 or 300 polishing
    // iterations) runs at the preset's learning rate (2e-3) with the Chamfer only, not at
    // the search's `PoseSearchOpts::main_lr` (1e-4) with the EMD after a third. The
    // occluded search leaves poses much further off than the full-input one (mean pose
    // error 10.3 against 0.8 with Gaussians on the true parts), which a polish at 1e-4
    // barely moves. Measured with the segmenting copy
    // (`select::SEGMENT_ITERS`), bench-dev occluded RI / recon / flow / TED /
    // re-animation: fast, seeds 0–4, 0.755 / 7.43 / 8.19 / 4.83 / 6.16 → 0.778 / 7.28 /
    // 7.89 / 4.54 / 5.57; balanced, seeds 0–2, 0.783 / 6.60 / 7.05 / 4.19 / 5.29 → 0.795 /
    // 6.61 / 7.24 / 3.95 / 4.86; procedural occluded (five objects, generator seeds 0–3,
    // fast) 0.695 / 8.55 / 6.48 / 4.90 / 4.45 → 0.720 / 7.68 / 5.51 / 4.30 / 4.19. With the
    // EMD switch kept: fast 0.777 / 7.07 / 7.90 / 4.31 / 5.44, balanced 0.788 / 7.15 /
    // 7.70 / 4.43 / 4.97.
    let occluded_polish = cfg.occlusion && search.is_some();
    let main_lr = match search {
        Some(o) if !occluded_polish => o.main_lr,
        _ => sched.lr,
    };
    adam.lr = main_lr;
    let mut emd_cache: Vec<Option<EmdPair>> = vec![None; if cfg.occlusion { kk } else { kk * kk }];
    let mut plan = PlanB {
        occluded: cfg.occlusion,
        src: vec![Vec::new(); kk],
        rev: vec![Vec::new(); kk],
        ..Default::default()
    };
    let mut lb = LossesB::default();
    let (mut lm, mut ls) = (0.0, 0.0);
    let mut terms = Terms::default();
    let segment_iters = cfg.segment_iters;
    let total = sched.iters + segment_iters;
    // The segmenting phase switches to EMD at the preset's fraction of its length.
    let segment_emd = segment_iters * sched.emd_start / sched.iters.max(1);
    let mut posed: Option<Params> = None;
    for it in 0..total {
        if it == sched.iters && segment_iters > 0 {
            posed = Some(params.clone());
            adam.reset();
            adam.lr = sched.lr;
        }
        if let (Some(o), false) = (&cfg.pose_init, cfg.occlusion) {
            if o.refine_every > 0 && it > 0 && it % o.refine_every == 0 {
                pose_init::refine_poses(data, &mut params, o);
            }
        }
        let k = rng.random_range(0..kk);
        // Step A.
        ws.eval_all(&params);
        sample(&mut rng, data.frames[k].len(), sched.batch, &mut batch);
        acc.zero();
        (lm, ls) = loss_a(data, k, &batch, cfg, &mut ws, Some(&mut acc));
        acc.to_flat(&params, &mut flat);
        adam.step(&mut params.x, &flat);
        // Step B.
        ws.eval_all(&params);
        let use_emd = if it >= sched.iters {
            it - sched.iters >= segment_emd
        } else {
            it >= sched.emd_start && !occluded_polish
        } && cfg.weights.emd > 0.0;
        plan.k = k;
        plan.use_cd = !use_emd && cfg.weights.cd > 0.0;
        plan.flow = ff.is_some() && cfg.weights.flow > 0.0;
        plan.emd.clear();
        if cfg.occlusion {
            let per = (sched.batch / (kk - 1)).max(32);
            for j in 0..kk {
                sample(&mut rng, data.frames[j].len(), per, &mut plan.src[j]);
            }
            sample(
                &mut rng,
                data.frames[k].len(),
                sched.batch,
                &mut plan.rev[k],
            );
            let mut half: Vec<bool> = (0..kk).map(|j| j % 2 == 0).collect();
            for j in (1..kk).rev() {
                let r = rng.random_range(0..=j);
                half.swap(j, r);
            }
            plan.split = (cfg.weights.split > 0.0).then_some(half);
            if use_emd {
                let pair = emd_pair_occluded(
                    data,
                    &mut emd_cache,
                    k,
                    sched,
                    &mut rng,
                    &mut ws,
                    &mut perm,
                    &mut stats,
                );
                plan.emd.push(pair);
            }
        } else {
            sample(
                &mut rng,
                data.frames[k].len(),
                sched.batch,
                &mut plan.src[k],
            );
            for t in 0..kk {
                if t != k {
                    sample(
                        &mut rng,
                        data.frames[t].len(),
                        sched.batch,
                        &mut plan.rev[t],
                    );
                }
            }
            plan.split = None;
            if use_emd {
                for t in (0..kk).filter(|&t| t != k) {
                    let pair = emd_pair_full(
                        data,
                        &mut emd_cache,
                        k,
                        t,
                        sched,
                        &mut rng,
                        &mut ws,
                        &mut perm,
                        &mut stats,
                    );
                    plan.emd.push(pair);
                }
            }
        }
        acc.zero();
        lb = loss_b(data, &plan, cfg, ff, &mut ws, Some(&mut acc));
        terms = Terms {
            cd: plan.use_cd,
            emd: use_emd,
            flow: plan.flow,
            split: plan.split.is_some(),
        };
        acc.to_flat(&params, &mut flat);
        adam.step(&mut params.x, &flat);
        // Return the EMD correspondences to the cache.
        for pair in plan.emd.drain(..) {
            let slot = if cfg.occlusion {
                pair.t
            } else {
                k * kk + pair.t
            };
            emd_cache[slot] = Some(pair);
        }
        stats.iterations = it + 1;
        if it % every == 0 || it + 1 == total {
            let snap = cfg.snapshot_every > 0 && it % cfg.snapshot_every == 0;
            report(
                Stage::Gaussians,
                it,
                total,
                named(lm, ls, &lb, terms),
                &params,
                snap,
                cb,
            )?;
        }
    }
    stats.last = named(lm, ls, &lb, terms);
    // The main loop's Gaussians give the poses; the copy that went on segments.
    let segmenter = posed.map(|p| std::mem::replace(&mut params, p));
    if let Some(o) = search {
        if o.snap_ratio > 0.0 {
            pose_search::snap_rigid(
                data,
                &mut params,
                o.points,
                o.snap_ratio,
                o.keep,
                !cfg.occlusion,
            );
        }
    }
    Ok((params, segmenter, stats))
}

/// Which transfer-step terms an iteration used.
#[derive(Debug, Clone, Copy, Default)]
struct Terms {
    cd: bool,
    emd: bool,
    flow: bool,
    split: bool,
}

/// The losses of an iteration, by name, for progress reports: L_MLE and L_sep, then only
/// the transfer-step terms it used (Chamfer *or* EMD, after the switch), so that a
/// term that was not computed is not shown as 0 (the page plots the Chamfer, then the
/// EMD).
fn named(lm: f64, ls: f64, lb: &LossesB, terms: Terms) -> Vec<(String, f64)> {
    let mut out = vec![("mle".into(), lm), ("sep".into(), ls)];
    let used = [
        ("chamfer", lb.cd, terms.cd),
        ("emd", lb.emd, terms.emd),
        ("flow", lb.flow, terms.flow),
        ("split", lb.split, terms.split),
    ];
    out.extend(
        used.into_iter()
            .filter(|&(_, _, on)| on)
            .map(|(name, v, _)| (name.to_string(), v)),
    );
    out
}

#[allow(clippy::too_many_arguments)]
fn emd_pair_full(
    data: &Data,
    cache: &mut [Option<EmdPair>],
    k: usize,
    t: usize,
    sched: &Schedule,
    rng: &mut StdRng,
    ws: &mut Ws,
    perm: &mut Vec<usize>,
    stats: &mut FitStats,
) -> EmdPair {
    let kk = data.k();
    let slot = k * kk + t;
    if let Some(mut p) = cache[slot].take() {
        if p.uses < sched.emd_refresh {
            p.uses += 1;
            return p;
        }
    }
    let mut p = EmdPair {
        t,
        ..Default::default()
    };
    sample_distinct(rng, data.frames[k].len(), sched.emd_n, perm, &mut p.rows);
    let mut cols = Vec::new();
    sample_distinct(rng, data.frames[t].len(), p.rows.len(), perm, &mut cols);
    p.cols = cols.into_iter().map(|i| (t, i)).collect();
    let gs = &ws.gs;
    ws.a.clear();
    ws.a.extend(
        p.rows
            .iter()
            .map(|&i| TransferSrc::new(&gs[k], data.frames[k][i]).moved(&gs[t])),
    );
    ws.b.clear();
    ws.b.extend(p.cols.iter().map(|&(_, i)| data.frames[t][i]));
    if !emd::assign(&ws.a, &ws.b, &mut ws.lap, &mut ws.cost, &mut p.sigma) {
        p.rows.clear();
        p.cols.clear();
        p.sigma.clear();
    }
    stats.emd_solves += 1;
    p.uses = 1;
    p
}

#[allow(clippy::too_many_arguments)]
fn emd_pair_occluded(
    data: &Data,
    cache: &mut [Option<EmdPair>],
    t: usize,
    sched: &Schedule,
    rng: &mut StdRng,
    ws: &mut Ws,
    perm: &mut Vec<usize>,
    stats: &mut FitStats,
) -> EmdPair {
    let kk = data.k();
    if let Some(mut p) = cache[t].take() {
        if p.uses < sched.emd_refresh {
            p.uses += 1;
            return p;
        }
    }
    let mut p = EmdPair {
        t,
        ..Default::default()
    };
    sample_distinct(rng, data.frames[t].len(), sched.emd_n, perm, &mut p.rows);
    // The fusion is a superset: take more columns than rows.
    let per = ((p.rows.len() * 3) / (2 * (kk - 1))).max(8);
    let mut tmp = Vec::new();
    for j in (0..kk).filter(|&j| j != t) {
        sample_distinct(rng, data.frames[j].len(), per, perm, &mut tmp);
        p.cols.extend(tmp.iter().map(|&i| (j, i)));
    }
    if p.cols.len() < p.rows.len() {
        p.rows.truncate(p.cols.len());
    }
    let gs = &ws.gs;
    ws.a.clear();
    ws.a.extend(p.rows.iter().map(|&i| data.frames[t][i]));
    ws.b.clear();
    ws.b.extend(
        p.cols
            .iter()
            .map(|&(j, i)| TransferSrc::new(&gs[j], data.frames[j][i]).moved(&gs[t])),
    );
    if !emd::assign(&ws.a, &ws.b, &mut ws.lap, &mut ws.cost, &mut p.sigma) {
        p.rows.clear();
        p.cols.clear();
        p.sigma.clear();
    }
    stats.emd_solves += 1;
    p.uses = 1;
    p
}

/// Final Chamfer used for model selection, evaluated the same way for every
/// candidate: Full — bidirectional Chamfer between H_{k→t}(X^k) and X^t averaged
/// over all ordered pairs k ≠ t; Occluded — one-directional from X^t to the fusion
/// of the other frames moved to t, averaged over t. Fixed strided subsamples of
/// `n` points, so it is deterministic.
pub fn final_chamfer(data: &Data, params: &Params, occluded: bool, n: usize) -> f64 {
    let kk = data.k();
    let mut ws = Ws::default();
    ws.eval_all(params);
    let strided = |len: usize, n: usize| -> Vec<usize> {
        let step = (len / n.max(1)).max(1);
        (0..len).step_by(step).take(n).collect()
    };
    let mut total = 0.0;
    let mut count = 0usize;
    let mut srcs = Vec::new();
    let mut moved = Vec::new();
    let mut grid = Grid::default();
    let mut buf = Vec::new();
    if occluded {
        let per = (n / (kk - 1)).max(16);
        for t in 0..kk {
            moved.clear();
            for j in (0..kk).filter(|&j| j != t) {
                prep_srcs(
                    &ws.gs[j],
                    &data.frames[j],
                    &strided(data.frames[j].len(), per),
                    &mut srcs,
                );
                moved.extend(srcs.iter().map(|s| s.moved(&ws.gs[t])));
            }
            chamfer::index(&mut grid, &moved, &mut buf);
            let q: Vec<DVec3> = strided(data.frames[t].len(), n)
                .iter()
                .map(|&i| data.frames[t][i])
                .collect();
            total += chamfer::directed(&q, &moved, &grid, 1.0, None, None);
            count += 1;
        }
    } else {
        for k in 0..kk {
            prep_srcs(
                &ws.gs[k],
                &data.frames[k],
                &strided(data.frames[k].len(), n),
                &mut srcs,
            );
            for t in (0..kk).filter(|&t| t != k) {
                move_srcs(&ws.gs[t], &srcs, &mut moved);
                let mut c =
                    chamfer::directed(&moved, &data.frames[t], &data.grids[t], 1.0, None, None);
                chamfer::index(&mut grid, &moved, &mut buf);
                let q: Vec<DVec3> = strided(data.frames[t].len(), n)
                    .iter()
                    .map(|&i| data.frames[t][i])
                    .collect();
                c += chamfer::directed(&q, &moved, &grid, 1.0, None, None);
                total += c;
                count += 1;
            }
        }
    }
    total / count.max(1) as f64
}

/// The four rotations that map an axis-aligned ellipsoid onto itself.
const FLIPS: [[f64; 3]; 4] = [
    [1.0, 1.0, 1.0],
    [1.0, -1.0, -1.0],
    [-1.0, 1.0, -1.0],
    [-1.0, -1.0, 1.0],
];

/// Tracking initialisation (an addition to the paper's init, for the large motions
/// between frames of robot sequences): frame by frame, start frame t from frame
/// t−1, fit its centres and rotations to X^t with L_MLE + L_sep (scales frozen),
/// then resolve each Gaussian's ellipsoid symmetry (the 4 axis flips, plus keeping
/// frame t−1's rotation) by the one-directional Chamfer of the Gaussian's frame t−1
/// points moved to t.
fn track_init(
    data: &Data,
    params: &mut Params,
    cfg: &FitConfig,
    rng: &mut StdRng,
    ws: &mut Ws,
) -> Result<()> {
    let kk = data.k();
    let l = params.layout;
    let m = l.m;
    let mut acc = GradAcc::new(l);
    let mut flat = vec![0.0; l.len()];
    let mut batch = Vec::new();
    let mut srcs: Vec<TransferSrc> = Vec::new();
    let mut prev: Vec<Gauss> = Vec::new();
    for t in 1..kk {
        // Start from the previous frame.
        for i in 0..m {
            let (a, b) = (l.rot(t - 1, i), l.rot(t, i));
            for j in 0..6 {
                params.x[b + j] = params.x[a + j];
            }
            let c = params.center(t - 1, i);
            params.set_center(t, i, c);
        }
        params.frame_into(t - 1, &mut prev);
        let mut adam = Adam::new(l.len(), cfg.sched.warmup_lr);
        ws.gs.resize_with(kk, Vec::new);
        for _ in 0..cfg.track_iters {
            params.frame_into(t, &mut ws.gs[t]);
            sample(rng, data.frames[t].len(), cfg.sched.batch, &mut batch);
            acc.zero();
            loss_a(data, t, &batch, cfg, ws, Some(&mut acc));
            acc.d_ls.iter_mut().for_each(|v| *v = DVec3::ZERO);
            acc.to_flat(params, &mut flat);
            adam.step(&mut params.x, &flat);
        }
        // Symmetry resolution per Gaussian.
        params.frame_into(t, &mut ws.gs[t]);
        let step = (data.frames[t - 1].len() / 512).max(1);
        srcs.clear();
        srcs.extend(
            (0..data.frames[t - 1].len())
                .step_by(step)
                .map(|n| TransferSrc::new(&prev, data.frames[t - 1][n])),
        );
        for (i, pg) in prev.iter().enumerate() {
            let g = ws.gs[t][i];
            let mut cands: Vec<glam::DMat3> = FLIPS
                .iter()
                .map(|f| g.r * glam::DMat3::from_diagonal(DVec3::from_array(*f)))
                .collect();
            cands.push(pg.r);
            let mut best = (f64::INFINITY, g.r);
            for r in cands {
                let mut sum = 0.0;
                let mut cnt = 0usize;
                for s in srcs.iter().filter(|s| s.label as usize == i) {
                    let x = r * s.y + g.mu;
                    if let Some((j, _)) = data.grids[t].nearest(x.as_vec3()) {
                        sum += x.distance_squared(data.frames[t][j as usize]);
                        cnt += 1;
                    }
                }
                let score = if cnt == 0 { 0.0 } else { sum / cnt as f64 };
                if score < best.0 {
                    best = (score, r);
                }
            }
            let o = l.rot(t, i);
            let r = best.1;
            let v = [
                r.x_axis.x, r.x_axis.y, r.x_axis.z, r.y_axis.x, r.y_axis.y, r.y_axis.z,
            ];
            params.x[o..o + 6].copy_from_slice(&v);
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Libm;
    use crate::pipeline::{Control, Quality};

    /// Frames of a strip whose half beyond x = 0.5 curls up more in every frame, each
    /// frame seen from another side (only the points of some rows: one-sided views).
    fn occluded_strip() -> Vec<Vec<Vec3>> {
        (0..4)
            .map(|k| {
                (0..800)
                    .filter(|i| (i / 40 + k) % 3 != 0)
                    .map(|i| {
                        let u = (i % 40) as f32 / 40.0;
                        let v = (i / 40) as f32 * 0.02;
                        let a = (u - 0.5).max(0.0) * k as f32 * 0.8;
                        Vec3::new(
                            u.min(0.5) + (u - 0.5).max(0.0) * a.lcos(),
                            v,
                            (u - 0.5).max(0.0) * a.lsin(),
                        )
                    })
                    .collect()
            })
            .collect()
    }

    fn mle_over_frames(data: &Data, params: &Params) -> f64 {
        let (mut gs, mut scratch) = (Vec::new(), Vec::new());
        (0..data.k())
            .map(|k| {
                params.frame_into(k, &mut gs);
                super::mle::mle(&gs, k, &data.frames[k], 1.0, None, &mut scratch)
            })
            .sum()
    }

    #[test]
    fn the_segmenting_copy_goes_on_while_the_poses_stay_the_main_loops() {
        let data = Data::new(occluded_strip());
        let sched = Schedule::preset(Quality::Fast, false).with_iters(40);
        let mut cfg = FitConfig::new(sched, true, 3);
        let go = &mut |_: &Progress| Control::Continue;
        let (plain, none, _) = fit_candidate_segmented(&data, 3, &cfg, None, go).unwrap();
        assert!(none.is_none());
        cfg.segment_iters = 200;
        let (posed, seg, stats) = fit_candidate_segmented(&data, 3, &cfg, None, go).unwrap();
        assert_eq!(posed.x, plain.x, "the main loop's Gaussians are unchanged");
        assert_eq!(stats.iterations, 240);
        let seg = seg.expect("a segmenting copy");
        let (before, after) = (mle_over_frames(&data, &posed), mle_over_frames(&data, &seg));
        assert!(after < before, "L_MLE over the frames {before} → {after}");
    }
}
