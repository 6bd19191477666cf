//! Global pose search per Gaussian and frame (an addition to the paper's local
//! optimisation): robot sequences move links by up to 180° between frames, far
//! beyond what gradient descent or frame-to-frame tracking follow. The object is
//! articulated, so a Gaussian's motion is mostly a rotation about a point it shares
//! with a neighbour. The search poses the Gaussians one at a time in the order of a
//! maximum spanning tree of frame 0's contact graph, starting from the Gaussian that
//! best stays in place; every other Gaussian, in every frame t ≥ 1, tries 2048
//! rotations (uniform on SO(3)) about its contact point with its posed neighbour
//! (carried to frame t by that neighbour's pose), plus the neighbour's own motion
//! and its current pose. Candidates are scored by the trimmed one-sided Chamfer of
//! the Gaussian's frame-0 points to frame t; the best few are refined by trimmed ICP.
//! Priors then prefer the current (tracked) pose and the neighbour's motion when
//! they fit nearly as well, and a coordinate descent on the bidirectional Chamfer of
//! all moved Gaussians picks one candidate per Gaussian and frame.
//!
//! Later Gaussians are matched only to the frame points that the Gaussians posed
//! before them do not explain (`exclusive`): a small or flat piece otherwise fits
//! equally well on another part's surface. After the main loop, `snap_rigid` gives
//! touching Gaussians that move as one body exactly one motion, so the merge of
//! Step 2 joins them; on full input not a link that carries a neighbour's joint
//! (`carries`, which borrows Step 2's 1-DOF screw fit).
//!
//! Measured (bench-dev full, Fast): with Gaussians placed on the true parts
//! (`examples/pose_search_oracle.rs`) the mean pose error of xarm7 / so101 /
//! finger_edu / talos is 0.7 / 1.2 / 1.0 / 1.0 (22.2 / 7.2 / 6.6 / 4.9 with tracking
//! alone); with the fitted segmentation and the true part count, the mean over the
//! seven sequences is 1.59 before the main loop (7.30 without the search).
//! Candidates are first scored on 48 probe points, summing lower bounds of their
//! distances before any grid query (`coarse_top`, `geom::cap_bound`): the same
//! candidates are kept, at less cost.
//! Runs before the main loop (allocations outside the hot path).

use crate::math::Libm;
use glam::{DMat3, DMat4, DQuat, DVec3, Vec3};

use crate::geom::cap_bound::CapBound;
use crate::geom::cap_mask::CapMask;
use crate::geom::knn::point_spacing;
use crate::geom::knn::Grid;
use crate::geom::se3::rigid;
use crate::kinematics::screw::{fit_prismatic, fit_revolute, relative_motions};
use crate::Result;

use super::fitter::Data;
use super::gaussians::{Gauss, Params};
use super::pose_init::{
    frame0_groups, relative_motion, set_relative_pose, trimmed_icp, trimmed_mean,
};

/// Options of the pose search.
#[derive(Debug, Clone, Copy)]
pub struct PoseSearchOpts {
    /// Frame-0 points used (subsample of the working cloud).
    pub points: usize,
    /// Rotations sampled uniformly on SO(3) (super-Fibonacci spiral). The fitter
    /// uses `Schedule::later_rotations` instead after a motion re-segmentation.
    pub rotations: usize,
    /// Points per Gaussian used for the coarse score of every candidate.
    pub probe: usize,
    /// Best coarse candidates refined by ICP.
    pub top: usize,
    /// ICP rounds per refined candidate (on a subsample).
    pub icp: usize,
    /// ICP rounds of the best candidate on all its points.
    pub final_icp: usize,
    /// Fraction of residuals kept by the trimmed score and Kabsch.
    pub keep: f64,
    /// Posed neighbours whose contact points serve as pivots (strongest first).
    pub pivots: usize,
    /// Main-loop learning rate when the poses come from the search (instead of
    /// the paper's 2e-3): the loop then only polishes, and Adam's normalised
    /// steps random-walk at the scale of the rate. Measured (Fast, m = true part
    /// count, bench-dev full): mean reconstruction error 1.59 with no main loop,
    /// 2.36 after it at 5e-4; on laikago/solo12/talos/finger_edu 1.76 at 1e-4
    /// vs 1.64 without the loop and 3.04 at 5e-4.
    pub main_lr: f64,
    /// A Gaussian keeps its strongest neighbour's motion when that fits within
    /// this factor of the best found score (0 = off).
    pub rigid_ratio: f64,
    /// The current (tracked) pose is kept when it fits within this factor of the
    /// best found score (0 = off).
    pub keep_ratio: f64,
    /// Later Gaussians are matched only to frame points not explained by the
    /// Gaussians posed before them.
    pub exclusive: bool,
    /// After the main loop, touching Gaussians take each other's motion when it
    /// fits within this factor in every frame (`snap_rigid`; 0 = off).
    pub snap_ratio: f64,
    /// Also on occluded input (parts may be missing from frames), where the fitter
    /// runs `occluded_search` (scored from frame t's points to a growing template)
    /// instead of this search. Measured (bench-dev occluded, Fast, end to end, mean
    /// of seeds 0 and 1) against no search: tree edit distance 10.1 → 5.4,
    /// re-animation error 11.8 → 8.3, reconstruction 16.4 → 14.8, flow 18.4 → 17.7,
    /// mean RI 0.744 → 0.720. (This search itself, forced on occluded input: RI
    /// 0.741, reconstruction 19.3.)
    pub occluded: bool,
    /// Flip guard: when the chosen pose turned more than 90° from the previous
    /// frame's, a candidate within `keep_ratio` of the best (or the previous pose,
    /// polished by ICP) that stays within 45° of it is taken instead, and the
    /// coverage selection may only pick alternatives within 90° of the choice. Half
    /// of a flat lid fits equally well a half turn apart; the procedural laptop
    /// (seed 0) had both lid Gaussians flipped in 4 of 10 frames, and Steps 2–3
    /// then built a wrong chain (reconstruction 11).
    pub flip_guard: bool,
}

impl Default for PoseSearchOpts {
    fn default() -> Self {
        PoseSearchOpts {
            points: 1024,
            rotations: 2048,
            probe: 48,
            top: 12,
            icp: 6,
            final_icp: 6,
            keep: 0.8,
            pivots: 1,
            main_lr: 1e-4,
            rigid_ratio: 1.5,
            keep_ratio: 1.25,
            exclusive: true,
            snap_ratio: 3.0,
            occluded: true,
            flip_guard: true,
        }
    }
}

/// `n` rotations spread uniformly over SO(3): Alexa's super-Fibonacci spirals
/// (CVPR 2022), deterministic and without clustering.
pub fn uniform_rotations(n: usize) -> Vec<DMat3> {
    let phi = std::f64::consts::SQRT_2;
    let psi = 1.533_751_168_755_204_3;
    (0..n)
        .map(|i| {
            let s = i as f64 + 0.5;
            let r = (s / n as f64).sqrt();
            let big_r = (1.0 - s / n as f64).sqrt();
            let a = std::f64::consts::TAU * s / phi;
            let b = std::f64::consts::TAU * s / psi;
            let q = DQuat::from_xyzw(
                r * a.lsin(),
                r * a.lcos(),
                big_r * b.lsin(),
                big_r * b.lcos(),
            );
            DMat3::from_quat(q.normalize())
        })
        .collect()
}

/// A rigid motion x ↦ r x + c.
pub type Motion = (DMat3, DVec3);

/// Flip guard thresholds (radians): a jump beyond `FLIP_ANGLE` from the previous
/// frame's rotation is suspect; candidates within `STAY_ANGLE` of it may replace it.
const FLIP_ANGLE: f64 = std::f64::consts::FRAC_PI_2;
const STAY_ANGLE: f64 = std::f64::consts::FRAC_PI_4;

/// Angle (radians) of the rotation between `a` and `b`.
pub(crate) fn rotation_angle(a: DMat3, b: DMat3) -> f64 {
    let m = (a.transpose() * b).to_cols_array();
    ((m[0] + m[4] + m[8] - 1.0) / 2.0).clamp(-1.0, 1.0).lacos()
}

/// The target cloud of one frame for the search: the frame's points not yet
/// claimed by an already posed Gaussian (all of them without `exclusive`).
pub struct Target<'a> {
    pts: Vec<DVec3>,
    /// Index in the frame of each of `pts`.
    orig: Vec<u32>,
    grid: Grid,
    /// Places farther than the cap from all of the frame's points (exact for the
    /// claimed-down cloud too: removing points only moves them farther).
    far: &'a CapMask,
    /// Lower bounds of the distances to `pts` (measured on demand, again where
    /// points were claimed).
    bound: CapBound,
    /// The sequence's squared-distance cap (`SearchCap`).
    cap2: f64,
    /// Per frame point: still free.
    free: Vec<bool>,
}

impl<'a> Target<'a> {
    /// All of frame `t`'s points.
    pub fn frame(data: &'a Data, t: usize) -> Self {
        let cap = search_cap(data);
        Target {
            pts: data.frames[t].clone(),
            orig: (0..data.frames[t].len() as u32).collect(),
            grid: data.grids[t].clone(),
            far: &cap.masks[t],
            bound: if cap.masks[t].slots() <= BOUND_CELLS_PER_POINT * data.frames32[t].len() {
                CapBound::new(&cap.masks[t], (cap.cap2 as f32).sqrt())
            } else {
                CapBound::default()
            },
            cap2: cap.cap2,
            free: vec![true; data.frames[t].len()],
        }
    }

    /// Removes the frame points within `r` of `moved` (a posed Gaussian's points)
    /// and re-indexes the rest; keeps everything when too few would remain.
    fn claim(&mut self, data: &Data, t: usize, moved: &[DVec3], r: f64) {
        if moved.is_empty() {
            return;
        }
        let m32: Vec<Vec3> = moved.iter().map(|p| p.as_vec3()).collect();
        let g = Grid::new(&m32);
        let r2 = (r * r) as f32;
        let mut free = self.free.clone();
        for (j, y) in data.frames32[t].iter().enumerate() {
            if free[j] && g.nearest_d2_capped(*y, r2) < r2 {
                free[j] = false;
            }
        }
        let left = free.iter().filter(|f| **f).count();
        if left < data.frames[t].len() / 10 {
            return;
        }
        self.free = free;
        self.pts.clear();
        self.orig.clear();
        let mut p32 = Vec::with_capacity(left);
        for (j, f) in self.free.iter().enumerate() {
            if *f {
                self.pts.push(data.frames[t][j]);
                self.orig.push(j as u32);
                p32.push(data.frames32[t][j]);
            }
        }
        self.grid.rebuild(&p32);
        self.bound.forget(&self.free);
    }

    /// Squared distance from `x` to the nearest free point, capped.
    #[inline]
    fn capped_d2(&self, x: Vec3) -> f64 {
        capped_d2(self.far, self.cap2, &self.grid, x)
    }

    /// A lower bound of `capped_d2(x)` without a grid query (`CapBound`; exact where
    /// `x` is beyond the cap).
    #[inline]
    fn lower_d2(&self, x: Vec3) -> f64 {
        match self
            .bound
            .lower_distance(self.far, &self.grid, &self.orig, x)
        {
            None => self.cap2,
            Some(d) => (d * d).min(self.cap2 as f32) as f64,
        }
    }
}

/// A frame's candidates are scored with the lower bounds (`coarse_top`) only when its
/// cap mask has at most this many marked cells per point: every cell a probe lands in
/// costs a grid query to measure, so where the cap's cells cover much of the surface
/// the bounds cost what they save, and their memory. Marked cells per point of the
/// first frame, and CPU time with the bounds against without (one fit each, balanced,
/// seed 0, the same minute): bench-dev so101 9.3 (−13 %), laikago 19 (−8 %),
/// panda_gripper 47 (+5 %, peak 21 → 40 MB); the procedural quadruped 32 (+2 %), hand
/// 40 (−3 %), laptop 82 (about +5 %, 16 → 33 MB).
const BOUND_CELLS_PER_POINT: usize = 25;

/// Squared distance from `x` to the nearest point of `grid`, capped at `cap2`; `far`
/// (a mask of the same cloud or a superset, built for that cap) answers places
/// beyond the cap at once.
#[inline]
fn capped_d2(far: &CapMask, cap2: f64, grid: &Grid, x: Vec3) -> f64 {
    if far.far(x) {
        return cap2;
    }
    grid.nearest_d2_capped(x, cap2 as f32) as f64
}

/// Squared distances (normalised units) are capped at least here in the search's
/// scores and the coverage selection, so one far-off point does not dominate.
const CAP2: f64 = 1e-3;

/// On sparse clouds the cap grows to this many point spacings (frame 0's median
/// nearest-neighbour distance): a fixed cap below the spacing makes a correct pose
/// score nearly as badly as a wrong one. Bench-dev's robots (4096 points, spacing
/// 0.006–0.010) keep `CAP2`; the procedural cabinet (2048 points on many panels,
/// spacing 0.027) gets 0.005.
const CAP_SPACINGS: f64 = 2.6;

/// The search's squared-distance cap for one sequence and, per frame, the places
/// farther than it from every point (built once per prepared sequence).
#[derive(Debug, Clone)]
pub struct SearchCap {
    pub(crate) cap2: f64,
    masks: Vec<CapMask>,
}

fn search_cap(data: &Data) -> &SearchCap {
    data.search_cap.get_or_init(|| {
        let spacing = data.frames32.first().map_or(0.0, |f| point_spacing(f));
        let cap2 = CAP2.max((CAP_SPACINGS * spacing).powi(2));
        let r = (cap2 as f32).sqrt();
        SearchCap {
            cap2,
            masks: data.frames32.iter().map(|f| CapMask::new(f, r)).collect(),
        }
    })
}

/// Trimmed mean squared distance (each capped, `SearchCap`) from the moved points to
/// the target.
pub fn score(tg: &Target, pts: &[DVec3], mo: Motion, keep: f64, buf: &mut Vec<f64>) -> f64 {
    buf.clear();
    for p in pts {
        let x = mo.0 * *p + mo.1;
        buf.push(tg.capped_d2(x.as_vec3()));
    }
    if buf.is_empty() {
        return f64::INFINITY;
    }
    trimmed_mean(buf, keep)
}

/// Trimmed ICP of `pts` to the target from `mo`.
fn icp(tg: &Target, pts: &[DVec3], mo: Motion, rounds: usize, keep: f64) -> Motion {
    let mut dst = Vec::with_capacity(pts.len());
    trimmed_icp(&tg.grid, |j| tg.pts[j], pts, mo, rounds, keep, &mut dst)
}

/// Frame-0 contact graph of the Gaussians: `w[i][j]` counts subsampled points of
/// `i` whose nearest point of another Gaussian is `j` and closer than `radius`;
/// `b[i][j]` is the mean midpoint of those pairs (the contact point).
/// Gaussians without contact still get a pivot: `b[i][j]` is then the midpoint of
/// the closest pair and `d2[i][j]` its squared distance (for the visiting order).
pub(crate) struct Contacts {
    pub(crate) w: Vec<Vec<usize>>,
    pub(crate) b: Vec<Vec<DVec3>>,
    pub(crate) d2: Vec<Vec<f64>>,
}

pub(crate) fn contacts(groups: &[Vec<DVec3>]) -> Contacts {
    let m = groups.len();
    let all: Vec<(usize, DVec3)> = groups
        .iter()
        .enumerate()
        .flat_map(|(i, g)| g.iter().map(move |p| (i, *p)))
        .collect();
    // Spacing: median nearest-neighbour distance in the subsample.
    let mut nn: Vec<f64> = all
        .iter()
        .enumerate()
        .map(|(a, (_, p))| {
            all.iter()
                .enumerate()
                .filter(|(b, _)| *b != a)
                .map(|(_, (_, q))| p.distance_squared(*q))
                .fold(f64::INFINITY, f64::min)
        })
        .collect();
    let mid = nn.len() / 2;
    let spacing = if nn.is_empty() {
        0.0
    } else {
        *nn.select_nth_unstable_by(mid, |a, b| a.total_cmp(b)).1
    }
    .sqrt();
    let r2 = (2.5 * spacing).powi(2);
    let mut w = vec![vec![0usize; m]; m];
    let mut b = vec![vec![DVec3::ZERO; m]; m];
    let mut d2 = vec![vec![f64::INFINITY; m]; m];
    let mut closest = vec![vec![DVec3::ZERO; m]; m];
    for (i, p) in &all {
        let best = all
            .iter()
            .filter(|(j, _)| j != i)
            .map(|(j, q)| (*j, *q, p.distance_squared(*q)))
            .min_by(|a, b| a.2.total_cmp(&b.2));
        if let Some((j, q, d)) = best {
            if d < d2[*i][j] {
                d2[*i][j] = d;
                closest[*i][j] = (*p + q) * 0.5;
            }
            if d <= r2 {
                w[*i][j] += 1;
                b[*i][j] += (*p + q) * 0.5;
            }
        }
    }
    // Symmetrise: a contact seen from either side.
    for i in 0..m {
        for j in (i + 1)..m {
            let (dd, c) = if d2[i][j] <= d2[j][i] {
                (d2[i][j], closest[i][j])
            } else {
                (d2[j][i], closest[j][i])
            };
            d2[i][j] = dd;
            d2[j][i] = dd;
            // The pivot: the mean contact midpoint, else the closest pair's.
            let n = w[i][j] + w[j][i];
            let pivot = if n > 0 {
                (b[i][j] + b[j][i]) / n as f64
            } else {
                c
            };
            w[i][j] = n;
            w[j][i] = n;
            b[i][j] = pivot;
            b[j][i] = pivot;
        }
    }
    Contacts { w, b, d2 }
}

/// The order in which the Gaussians after `root` are posed: Prim's order over the
/// contact weights (strongest contact with the posed set first, ties to the lowest
/// index); a Gaussian without any contact comes when it is the closest to the posed set.
pub(crate) fn visiting_order(con: &Contacts, root: usize) -> Vec<usize> {
    let m = con.w.len();
    let mut posed = vec![false; m];
    posed[root] = true;
    let mut order = Vec::with_capacity(m.saturating_sub(1));
    for _ in 1..m {
        let mut next = None;
        let mut best = (0usize, f64::NEG_INFINITY);
        for j in (0..m).filter(|&j| !posed[j]) {
            let w = (0..m)
                .filter(|&i| posed[i])
                .map(|i| con.w[i][j])
                .max()
                .unwrap_or(0);
            let d = (0..m)
                .filter(|&i| posed[i])
                .map(|i| con.d2[i][j])
                .fold(f64::INFINITY, f64::min);
            if next.is_none() || w > best.0 || (w == best.0 && w == 0 && -d > best.1) {
                best = (w, -d);
                next = Some(j);
            }
        }
        let Some(j) = next else { break };
        posed[j] = true;
        order.push(j);
    }
    order
}

/// The posed Gaussians (other than `j`) whose contact points with `j` serve as
/// pivots: the `n` (at least one) strongest contacts, then the closest.
pub(crate) fn pivot_neighbours(con: &Contacts, posed: &[bool], j: usize, n: usize) -> Vec<usize> {
    let mut nbrs: Vec<usize> = (0..posed.len()).filter(|&i| posed[i] && i != j).collect();
    nbrs.sort_by(|&a, &b| {
        con.w[b][j]
            .cmp(&con.w[a][j])
            .then(con.d2[a][j].total_cmp(&con.d2[b][j]))
    });
    nbrs.truncate(n.max(1));
    nbrs
}

/// The root is chosen among Gaussians with at least this many frame-0 points: half
/// the median count (at least 3), so a tiny piece that happens to stay put is not it.
pub(crate) fn root_min_size(groups: &[Vec<DVec3>]) -> usize {
    let mut sizes: Vec<usize> = groups.iter().map(Vec::len).collect();
    sizes.sort_unstable();
    sizes.get(sizes.len() / 2).map_or(3, |s| (s / 2).max(3))
}

/// What both searches start from: the frame-0 Gaussians and each one's frame-0 points
/// (a subsample of at most `points`); `None` when there is nothing to search (one
/// frame, no Gaussian, or an empty frame 0).
pub(crate) fn frame0_start(
    data: &Data,
    params: &Params,
    points: usize,
) -> Option<(Vec<Gauss>, Vec<Vec<DVec3>>)> {
    if data.k() < 2 || params.layout.m == 0 || data.frames[0].is_empty() {
        return None;
    }
    let mut g0: Vec<Gauss> = Vec::new();
    params.frame_into(0, &mut g0);
    let groups = frame0_groups(data, &g0, points);
    Some((g0, groups))
}

/// Searches every Gaussian's pose in frames t ≥ 1 (see the module doc) and writes
/// the chosen ones into `params`; frame 0 is left unchanged. `tick(done)` is called
/// after each Gaussian; an error from it (a cancel) stops the search.
#[allow(clippy::needless_range_loop)] // t indexes frames in several arrays
pub fn search_poses(
    data: &Data,
    params: &mut Params,
    opts: &PoseSearchOpts,
    tick: &mut dyn FnMut(usize) -> Result<()>,
) -> Result<()> {
    let Some((g0, groups)) = frame0_start(data, params, opts.points) else {
        return Ok(());
    };
    let (kk, m) = (data.k(), g0.len());
    let probes: Vec<Vec<DVec3>> = groups
        .iter()
        .map(|g| {
            let s = (g.len() / opts.probe.max(1)).max(1);
            g.iter().step_by(s).copied().collect()
        })
        .collect();
    let con = contacts(&groups);
    let rots = uniform_rotations(opts.rotations);
    let mut buf = Vec::new();
    let mut gts: Vec<Vec<Gauss>> = vec![Vec::new(); kk];
    for (t, g) in gts.iter_mut().enumerate() {
        params.frame_into(t, g);
    }
    // Relative motions frame 0 → t, per Gaussian, as they are decided.
    let mut rel: Vec<Vec<Motion>> = (0..m)
        .map(|i| {
            (0..kk)
                .map(|t| relative_motion(&g0[i], &gts[t][i]))
                .collect()
        })
        .collect();
    let mut targets: Vec<Target> = (0..kk).map(|t| Target::frame(data, t)).collect();
    // Root: among Gaussians with at least half the median point count, the one
    // whose best of {identity, current} fits best over the frames.
    let min_size = root_min_size(&groups);
    let mut root = None;
    let mut root_score = f64::INFINITY;
    for i in (0..m).filter(|&i| groups[i].len() >= min_size) {
        let mut s = 0.0;
        for t in 1..kk {
            let id = (DMat3::IDENTITY, DVec3::ZERO);
            let a = score(&targets[t], &groups[i], id, opts.keep, &mut buf);
            let b = score(&targets[t], &groups[i], rel[i][t], opts.keep, &mut buf);
            s += a.min(b);
        }
        if s < root_score {
            root_score = s;
            root = Some(i);
        }
    }
    let Some(root) = root else { return Ok(()) };
    // Refined candidates per Gaussian and frame, best alone first.
    let mut pool: Vec<Vec<Vec<Motion>>> = (0..m)
        .map(|i| (0..kk).map(|t| vec![rel[i][t]]).collect())
        .collect();
    let mut posed = vec![false; m];
    posed[root] = true;
    for t in 1..kk {
        let id = (DMat3::IDENTITY, DVec3::ZERO);
        let cands = [id, rel[root][t]];
        pool[root][t] = refine_all(&targets[t], &groups[root], &cands, opts, &mut buf);
        rel[root][t] = pool[root][t][0];
        if opts.exclusive {
            claim(
                &mut targets[t],
                data,
                t,
                &groups[root],
                rel[root][t],
                &mut buf,
            );
        }
    }
    for (done, j) in visiting_order(&con, root).into_iter().enumerate() {
        posed[j] = true;
        tick(done + 2)?;
        if groups[j].len() < 3 {
            continue;
        }
        let nbrs = pivot_neighbours(&con, &posed, j, opts.pivots);
        // Probe points farthest from the main pivot first: they move most under a
        // wrong rotation, so the coarse score's early exit comes sooner.
        let mut probe = probes[j].clone();
        if let Some(&i) = nbrs.first() {
            let b = con.b[i][j];
            probe.sort_by(|p, q| q.distance_squared(b).total_cmp(&p.distance_squared(b)));
        }
        let mut cands: Vec<Motion> = Vec::with_capacity(2 + nbrs.len() * (1 + rots.len()));
        for t in 1..kk {
            cands.clear();
            cands.push(rel[j][t]);
            for &i in &nbrs {
                let (ri, ci) = rel[i][t];
                cands.push((ri, ci));
                let pivot = con.b[i][j];
                let moved = ri * pivot + ci;
                for r in &rots {
                    cands.push((*r, moved - *r * pivot));
                }
            }
            let tg = &targets[t];
            let mut found = search_one(tg, &groups[j], &probe, &cands, opts, &mut buf);
            // Occam: move rigidly with the strongest touching neighbour unless the
            // search found a clearly better fit. Symmetric pieces (a half of a
            // cylindrical link) otherwise take any of their equally good poses, and
            // Gaussians of one part get different motions that the merge of Step 2
            // cannot reunite.
            let s_best = score(tg, &groups[j], found[0], opts.keep, &mut buf);
            if let (Some(&i), true) = (nbrs.first(), opts.rigid_ratio > 0.0) {
                if con.w[i][j] > 0 {
                    let s_nb = score(tg, &groups[j], rel[i][t], opts.keep, &mut buf);
                    if s_nb <= opts.rigid_ratio * s_best {
                        found.insert(0, rel[i][t]);
                    }
                }
            }
            // Temporal consistency: the tracked pose stays unless clearly beaten, so
            // a symmetric piece (a flat lid) is not flipped onto an equally good but
            // wrong pose.
            let s_cur = score(tg, &groups[j], cands[0], opts.keep, &mut buf);
            if opts.keep_ratio > 0.0 && s_cur <= opts.keep_ratio * s_best {
                found.insert(0, cands[0]);
            }
            if opts.flip_guard {
                let prev = if t == 1 {
                    (DMat3::IDENTITY, DVec3::ZERO)
                } else {
                    rel[j][t - 1]
                };
                guard_flip(tg, &groups[j], &mut found, prev, s_best, opts, &mut buf);
            }
            rel[j][t] = found[0];
            pool[j][t] = found;
            if opts.exclusive {
                claim(&mut targets[t], data, t, &groups[j], rel[j][t], &mut buf);
            }
        }
    }
    for t in 1..kk {
        let frame_pool: Vec<Vec<Motion>> =
            (0..m).map(|i| std::mem::take(&mut pool[i][t])).collect();
        let sel = select_by_coverage(data, t, &groups, &frame_pool, opts.points);
        for i in 0..m {
            set_relative_pose(params, t, i, &g0[i], frame_pool[i][sel[i]]);
        }
    }
    Ok(())
}

/// Flip guard (see `PoseSearchOpts::flip_guard`): when `found[0]` turned more than
/// `FLIP_ANGLE` from the previous frame's motion `prev`, the candidate within
/// `keep_ratio` of `s_best` closest to `prev` (within `STAY_ANGLE`) goes first, the
/// previous motion polished by ICP included; then only alternatives within
/// `FLIP_ANGLE` of the choice stay for the coverage selection.
fn guard_flip(
    tg: &Target,
    pts: &[DVec3],
    found: &mut Vec<Motion>,
    prev: Motion,
    s_best: f64,
    opts: &PoseSearchOpts,
    buf: &mut Vec<f64>,
) {
    if rotation_angle(found[0].0, prev.0) > FLIP_ANGLE {
        // The previous frame's pose carried over and polished is a candidate too
        // (the coarse search may not have kept it).
        found.push(icp(tg, pts, prev, opts.final_icp, opts.keep));
        let lim = opts.keep_ratio.max(1.0) * s_best;
        let mut stay: Option<(usize, f64)> = None;
        for (k, mo) in found.iter().enumerate() {
            let a = rotation_angle(mo.0, prev.0);
            if a < STAY_ANGLE
                && stay.is_none_or(|(_, b)| a < b)
                && score(tg, pts, *mo, opts.keep, buf) <= lim
            {
                stay = Some((k, a));
            }
        }
        if let Some((k, _)) = stay {
            let mo = found.remove(k);
            found.insert(0, mo);
        }
    }
    let chosen = found[0].0;
    found.retain(|mo| rotation_angle(mo.0, chosen) <= FLIP_ANGLE);
}

/// Marks the frame points explained by Gaussian points `pts` moved by `mo` as
/// taken: within 3× their median residual (clamped to 0.01–0.05), so later
/// Gaussians cannot also land on them (a small flat piece otherwise fits anywhere
/// on another part's surface).
fn claim(tg: &mut Target, data: &Data, t: usize, pts: &[DVec3], mo: Motion, buf: &mut Vec<f64>) {
    let moved: Vec<DVec3> = pts.iter().map(|p| mo.0 * *p + mo.1).collect();
    buf.clear();
    buf.extend(moved.iter().map(|x| tg.capped_d2(x.as_vec3())));
    if buf.is_empty() {
        return;
    }
    let mid = buf.len() / 2;
    let med = buf
        .select_nth_unstable_by(mid, |a, b| a.total_cmp(b))
        .1
        .sqrt();
    tg.claim(data, t, &moved, (3.0 * med).clamp(0.01, 0.05));
}

/// ICP-refines each candidate on at most `REFINE_PTS` of the points, then the
/// best once more on all of them; returns the refined motions, best first.
fn refine_all(
    tg: &Target,
    pts: &[DVec3],
    cands: &[Motion],
    opts: &PoseSearchOpts,
    buf: &mut Vec<f64>,
) -> Vec<Motion> {
    let step = (pts.len() / REFINE_PTS).max(1);
    let small: Vec<DVec3> = pts.iter().step_by(step).copied().collect();
    let mut out: Vec<(f64, Motion)> = cands
        .iter()
        .map(|c| {
            let r = icp(tg, &small, *c, opts.icp, opts.keep);
            (score(tg, &small, r, opts.keep, buf), r)
        })
        .collect();
    out.sort_by(|a, b| a.0.total_cmp(&b.0));
    // The winner is refined on all points.
    if let Some(first) = out.first_mut() {
        first.1 = icp(tg, pts, first.1, opts.final_icp, opts.keep);
    }
    out.into_iter().map(|(_, r)| r).collect()
}

/// Points per candidate in the ICP refinement of `refine_all`.
const REFINE_PTS: usize = 96;

/// Coarse-scores all candidates on the probe points and ICP-refines the `top`
/// best plus the first candidate (the current pose, always kept).
fn search_one(
    tg: &Target,
    pts: &[DVec3],
    probe: &[DVec3],
    cands: &[Motion],
    opts: &PoseSearchOpts,
    buf: &mut Vec<f64>,
) -> Vec<Motion> {
    let top = opts.top.min(cands.len().saturating_sub(1));
    let mut chosen: Vec<Motion> = vec![cands[0]];
    chosen.extend(
        coarse_top(tg, probe, cands, top)
            .into_iter()
            .map(|n| cands[n]),
    );
    refine_all(tg, pts, &chosen, opts, buf)
}

/// The `top` candidates after the first (indices into `cands`) with the lowest sum of
/// capped squared distances of the probe points, ascending (ties in index order).
fn coarse_top(tg: &Target, probe: &[DVec3], cands: &[Motion], top: usize) -> Vec<usize> {
    // Early exit once a candidate cannot enter the current top list (most cannot).
    // The sum of lower bounds comes first (`CapBound`): it drops most candidates
    // without a grid query, and the same ones, since a bound never exceeds the
    // capped distance. `rest[k]` sums the bounds of probe points k.., so a partial
    // exact sum plus the rest's bounds bounds the whole and stops the exact pass early.
    let mut scored: Vec<(f64, usize)> = Vec::with_capacity(top + 1);
    let mut bound = f64::INFINITY;
    let mut rest = vec![0.0; probe.len() + 1];
    let bounded = !tg.bound.is_empty();
    'cands: for (n, c) in cands.iter().enumerate().skip(1) {
        let mut low = 0.0;
        for (k, p) in probe.iter().enumerate().filter(|_| bounded) {
            let l = tg.lower_d2((c.0 * *p + c.1).as_vec3());
            rest[k] = l;
            low += l;
            if low >= bound {
                continue 'cands;
            }
        }
        for k in (0..probe.len()).rev() {
            rest[k] += rest[k + 1];
        }
        let mut sum = 0.0;
        for (k, p) in probe.iter().enumerate() {
            let x = c.0 * *p + c.1;
            sum += tg.capped_d2(x.as_vec3());
            // The partial sum plus the rest's bounds adds in another order than the
            // whole; the factor covers that rounding, so the test never drops a
            // candidate that the whole sum would keep.
            if sum >= bound || (sum + rest[k + 1]) * (1.0 - 1e-12) >= bound {
                continue 'cands;
            }
        }
        let at = scored.partition_point(|e| e.0 <= sum);
        scored.insert(at, (sum, n));
        scored.truncate(top);
        if scored.len() == top {
            bound = scored[top - 1].0;
        }
    }
    scored.into_iter().map(|(_, n)| n).collect()
}

/// Factor by which another candidate must beat the preferred one in the coverage
/// selection.
const SWITCH_MARGIN: f64 = 1.0;

/// Chooses one motion per Gaussian from its pool for frame `t` by coordinate
/// descent on the bidirectional Chamfer between the union of the moved groups and
/// frame t's cloud: the one-sided search cannot see frame-t points that no
/// Gaussian explains (a link folded onto another part scores well alone).
fn select_by_coverage(
    data: &Data,
    t: usize,
    groups: &[Vec<DVec3>],
    pool: &[Vec<Motion>],
    targets: usize,
) -> Vec<usize> {
    let m = groups.len();
    let ft = &data.frames[t];
    let step = (ft.len() / targets.max(1)).max(1);
    let ys: Vec<DVec3> = ft.iter().step_by(step).copied().collect();
    let ny = ys.len();
    let npts: usize = groups.iter().map(Vec::len).sum::<usize>().max(1);
    // fwd[j][c]: Σ capped squared distance of group j moved by candidate c to frame t.
    // rev[j][c][y]: capped squared distance of target y to group j moved by c.
    let mut fwd: Vec<Vec<f64>> = Vec::with_capacity(m);
    let mut rev: Vec<Vec<Vec<f64>>> = Vec::with_capacity(m);
    let mut moved = Vec::new();
    let cap = search_cap(data);
    let (far, cap2) = (&cap.masks[t], cap.cap2);
    for j in 0..m {
        let mut fj = Vec::with_capacity(pool[j].len());
        let mut rj = Vec::with_capacity(pool[j].len());
        for &(r, c) in &pool[j] {
            moved.clear();
            moved.extend(groups[j].iter().map(|p| r * *p + c));
            let f: f64 = moved
                .iter()
                .map(|x| capped_d2(far, cap2, &data.grids[t], x.as_vec3()))
                .sum();
            fj.push(f);
            // Targets outside the moved group's box grown by the cap are at the cap:
            // a Gaussian covers a small part of the frame, so most skip the scan.
            let reach = DVec3::splat(cap2.sqrt());
            let (lo, hi) = moved.iter().fold(
                (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY)),
                |(lo, hi), x| (lo.min(*x), hi.max(*x)),
            );
            let (lo, hi) = (lo - reach, hi + reach);
            rj.push(
                ys.iter()
                    .map(|y| {
                        if y.cmplt(lo).any() || y.cmpgt(hi).any() {
                            return cap2;
                        }
                        moved
                            .iter()
                            .map(|x| x.distance_squared(*y))
                            .fold(cap2, f64::min)
                    })
                    .collect(),
            );
        }
        fwd.push(fj);
        rev.push(rj);
    }
    let mut sel = vec![0usize; m];
    let mut others = vec![0.0; ny];
    for _pass in 0..3 {
        let mut changed = false;
        for j in 0..m {
            if pool[j].len() < 2 {
                continue;
            }
            for (y, o) in others.iter_mut().enumerate() {
                *o = (0..m)
                    .filter(|&i| i != j && !pool[i].is_empty())
                    .map(|i| rev[i][sel[i]][y])
                    .fold(cap2, f64::min);
            }
            let fwd_others: f64 = (0..m)
                .filter(|&i| i != j && !pool[i].is_empty())
                .map(|i| fwd[i][sel[i]])
                .sum();
            let mut best = (f64::INFINITY, sel[j]);
            for c in 0..pool[j].len() {
                let r: f64 = others.iter().zip(&rev[j][c]).map(|(a, b)| a.min(*b)).sum();
                let s = (fwd_others + fwd[j][c]) / npts as f64 + r / ny.max(1) as f64;
                // The first candidate (the preferred one) yields only to a clearly
                // better one: near-ties are symmetric alternatives.
                let s = if c == 0 { s / SWITCH_MARGIN } else { s };
                if s < best.0 {
                    best = (s, c);
                }
            }
            if best.1 != sel[j] {
                sel[j] = best.1;
                changed = true;
            }
        }
        if !changed {
            break;
        }
    }
    sel
}

/// Makes touching Gaussians that move as one rigid body move identically: Gaussian
/// j takes neighbour i's motion when that motion explains j's frame-0 points in
/// every frame t ≥ 1 within `ratio` of j's own fit (trimmed one-sided Chamfer, as in
/// the search). Greedy, best-explained pair first, until nothing changes. Their
/// L_merge is then exactly 0, so the merge of Step 2 joins them; without this,
/// independent pose noise keeps over-segmented pieces of one part apart. With
/// `carry`, a cluster that carries a neighbour's joint (`carries`) or that has a
/// member straddling two parts (`straddles`) keeps its motion.
/// The fitter asks for it on full input only: on occluded input the motions are too
/// noisy for the 1-DOF fits to tell (bench-dev occluded, Fast, seed 0: mean RI 0.737
/// → 0.714 and reconstruction error 12.6 → 13.2 with it).
/// Returns the number of snaps.
#[allow(clippy::needless_range_loop)] // t indexes frames in several arrays
pub fn snap_rigid(
    data: &Data,
    params: &mut Params,
    points: usize,
    ratio: f64,
    keep: f64,
    carry: bool,
) -> usize {
    let kk = data.k();
    let m = params.layout.m;
    if kk < 2 || m < 2 || data.frames[0].is_empty() {
        return 0;
    }
    let mut gs: Vec<Vec<Gauss>> = vec![Vec::new(); kk];
    for (t, g) in gs.iter_mut().enumerate() {
        params.frame_into(t, g);
    }
    let g0 = gs[0].clone();
    let groups = frame0_groups(data, &g0, points);
    let con = contacts(&groups);
    let mut rel: Vec<Vec<Motion>> = (0..m)
        .map(|i| {
            (0..kk)
                .map(|t| relative_motion(&g0[i], &gs[t][i]))
                .collect()
        })
        .collect();
    let targets: Vec<Target> = (0..kk).map(|t| Target::frame(data, t)).collect();
    let mut buf = Vec::new();
    // Own fit per Gaussian and frame (unchanged by snapping others).
    let own: Vec<Vec<f64>> = (0..m)
        .map(|j| {
            (0..kk)
                .map(|t| score(&targets[t], &groups[j], rel[j][t], keep, &mut buf))
                .collect()
        })
        .collect();
    // Clusters of Gaussians sharing one motion (that of the cluster's first member).
    let mut cluster: Vec<usize> = (0..m).collect();
    let mut snapped = 0;
    loop {
        // The touching pair of clusters (A moving with B) whose worst member-frame
        // ratio is lowest.
        let mut best: Option<(f64, usize, usize)> = None;
        for ca in 0..m {
            let members: Vec<usize> = (0..m).filter(|&j| cluster[j] == ca).collect();
            if members.is_empty() {
                continue;
            }
            for cb in (0..m).filter(|&c| c != ca) {
                let touching = members
                    .iter()
                    .any(|&j| (0..m).any(|i| cluster[i] == cb && con.w[i][j] > 0));
                if !touching {
                    continue;
                }
                let mut worst: f64 = 0.0;
                'check: for &j in members.iter().filter(|&&j| groups[j].len() >= 3) {
                    for t in 1..kk {
                        let s = score(&targets[t], &groups[j], rel[cb][t], keep, &mut buf);
                        // Floor: a perfect own fit must not make every ratio infinite.
                        worst = worst.max(s / own[j][t].max(1e-7));
                        if worst > ratio {
                            break 'check;
                        }
                    }
                }
                if worst > ratio || best.is_some_and(|b| worst >= b.0) {
                    continue;
                }
                // Refusals, checked only for a pair that would be the best so far.
                let keeps_motion = carry
                    && (carries(&con, &cluster, &groups, &rel, ca, cb)
                        || members
                            .iter()
                            .any(|&j| straddles(&targets, &groups[j], &rel[j], &rel[cb])));
                if !keeps_motion {
                    best = Some((worst, ca, cb));
                }
            }
        }
        let Some((_, ca, cb)) = best else { break };
        for j in 0..m {
            if cluster[j] == ca {
                cluster[j] = cb;
                for t in 1..kk {
                    rel[j][t] = rel[cb][t];
                    set_relative_pose(params, t, j, &g0[j], rel[cb][t]);
                }
            }
        }
        snapped += 1;
    }
    snapped
}

/// A Gaussian straddles two parts (`straddles`) when at least this share of its
/// points follows its own motion and not its neighbour's.
const STRADDLE_SHARE: f64 = 0.1;
/// ... where a point "does not follow" a motion when it ends, mean per frame, beyond
/// this fraction of the search's squared cap from the frame's cloud ...
const STRADDLE_FAR: f64 = 0.25;
/// ... and this many times farther than under its own motion.
const STRADDLE_RATIO: f64 = 4.0;

/// Whether Gaussian points `pts` straddle a part moving with `own` and one moving
/// with `other`: a share of them (`STRADDLE_SHARE`) lands on the frames only under
/// `own`. Such a Gaussian fits `other` within the snap ratio through its other
/// points, and snapping it there takes the part it straddles into `other`'s: on the
/// procedural quadruped (generator seed 1) a Gaussian holding half a thigh and half
/// the body was snapped onto the body at ratio 2.91, and the thigh lost its part.
fn straddles(targets: &[Target], pts: &[DVec3], own: &[Motion], other: &[Motion]) -> bool {
    let kk = targets.len();
    if kk < 2 || pts.is_empty() {
        return false;
    }
    let far = STRADDLE_FAR * targets[0].cap2 * (kk - 1) as f64;
    let moving = pts
        .iter()
        .filter(|p| {
            let (mut so, mut sb) = (0.0, 0.0);
            for t in 1..kk {
                so += targets[t].capped_d2((own[t].0 * **p + own[t].1).as_vec3());
                sb += targets[t].capped_d2((other[t].0 * **p + other[t].1).as_vec3());
            }
            sb > far && sb > STRADDLE_RATIO * so
        })
        .count();
    moving as f64 >= STRADDLE_SHARE * pts.len() as f64
}

/// A link must turn at least this much (radians, in some frame) relative to the
/// Gaussian it would snap to before it can count as carrying a joint (`carries`):
/// below it, the two motions differ by pose noise, and so do their neighbours' fits.
/// On bench-dev and the procedural quadruped the spurious carries turned 3–12°, the
/// housings of solo12's hips 25–53°.
const CARRY_MIN_TURN: f64 = 0.3;

/// A touching Gaussian must fit a joint this much better relative to the link than
/// relative to the Gaussian the link would snap to (`carries`).
const CARRY_RATIO: f64 = 0.5;

/// Whether cluster `ca` carries a joint, so that it must keep its own motion although
/// cluster `cb`'s explains its points nearly as well. A link that turns about its own
/// axis of symmetry (the cylindrical housing of a quadruped's hip) fits its parent's
/// motion within the snap ratio, but the link it carries (the thigh) then moves with
/// two degrees of freedom relative to the parent. So: `ca` turns by at least
/// `CARRY_MIN_TURN` relative to `cb`, and some Gaussian of a third cluster touching
/// `ca` moves about a 1-DOF joint (revolute or prismatic, Step 2's screw fit)
/// relative to `ca` with less than `CARRY_RATIO` of the loss relative to `cb`.
fn carries(
    con: &Contacts,
    cluster: &[usize],
    groups: &[Vec<DVec3>],
    rel: &[Vec<Motion>],
    ca: usize,
    cb: usize,
) -> bool {
    // Every member of a cluster moves with the cluster's motion (`rel[ca]`, `rel[cb]`).
    let kk = rel[ca].len();
    let turn = (0..kk)
        .map(|t| rotation_angle(rel[ca][t].0, rel[cb][t].0))
        .fold(0.0, f64::max);
    if turn < CARRY_MIN_TURN {
        return false;
    }
    let m = cluster.len();
    // The motions as poses (frame 0 at rest), for Step 2's relative motions.
    let poses: Vec<Vec<DMat4>> = (0..kk)
        .map(|t| rel.iter().map(|r| rigid(r[t].0, r[t].1)).collect())
        .collect();
    (0..m)
        .filter(|&c| cluster[c] != ca && cluster[c] != cb && groups[c].len() >= 3)
        .filter(|&c| (0..m).any(|j| cluster[j] == ca && con.w[j][c] > 0))
        .any(|c| {
            let centre = groups[c].iter().copied().sum::<DVec3>() / groups[c].len() as f64;
            let one_dof = |p: usize| {
                let q = relative_motions(&poses, p, c, 0);
                fit_revolute(&q, centre).3.min(fit_prismatic(&q).2)
            };
            one_dof(ca) < CARRY_RATIO * one_dof(cb)
        })
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use glam::Vec3;
    use rand::{Rng, SeedableRng};

    /// A hinge: a fixed box along −x and an arm along +x turning about the z
    /// axis through the origin by `angle`; points sampled independently per call.
    /// Returns the points and their link (0 base, 1 arm).
    pub(crate) fn hinge(angle: f64, n: usize, seed: u64) -> (Vec<Vec3>, Vec<u32>) {
        let (pts, lab, _) = hinge_with_normals(angle, n, seed);
        (pts, lab)
    }

    /// `hinge`, with each point's outward face normal.
    pub(crate) fn hinge_with_normals(
        angle: f64,
        n: usize,
        seed: u64,
    ) -> (Vec<Vec3>, Vec<u32>, Vec<Vec3>) {
        let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
        let r = DMat3::from_axis_angle(DVec3::Z, angle);
        let mut pts = Vec::with_capacity(n);
        let mut lab = Vec::with_capacity(n);
        let mut normals = Vec::with_capacity(n);
        for _ in 0..n {
            let arm = rng.random_bool(0.5);
            // The arm is a bar with a nub off its axis, so no rotation maps it
            // onto itself (a plain box has 180° symmetries).
            let (lo, hi) = if arm && rng.random_bool(0.3) {
                (DVec3::new(0.33, 0.04, 0.0), DVec3::new(0.45, 0.16, 0.08))
            } else if arm {
                (DVec3::new(0.02, -0.04, -0.04), DVec3::new(0.45, 0.04, 0.04))
            } else {
                (
                    DVec3::new(-0.45, -0.08, -0.03),
                    DVec3::new(-0.02, 0.08, 0.03),
                )
            };
            // A point on the box surface (scanned objects are surfaces).
            let mut u = DVec3::new(rng.random(), rng.random(), rng.random());
            let axis = rng.random_range(0..3);
            let high = !rng.random_bool(0.5);
            u[axis] = if high { 1.0 } else { 0.0 };
            let p = lo + (hi - lo) * u;
            let mut nrm = DVec3::ZERO;
            nrm[axis] = if high { 1.0 } else { -1.0 };
            pts.push(if arm { r * p } else { p }.as_vec3());
            normals.push(if arm { r * nrm } else { nrm }.as_vec3());
            lab.push(arm as u32);
        }
        (pts, lab, normals)
    }

    /// Gaussians fitted to each label's frame-0 points (moments), all frames equal.
    pub(crate) fn oracle_params(f0: &[Vec3], lab: &[u32], m: usize, kk: usize) -> Params {
        let mut params = Params::new(m, kk);
        for i in 0..m {
            let pts: Vec<DVec3> = f0
                .iter()
                .zip(lab)
                .filter(|(_, &l)| l as usize == i)
                .map(|(p, _)| p.as_dvec3())
                .collect();
            let c = pts.iter().fold(DVec3::ZERO, |s, p| s + *p) / pts.len() as f64;
            let var =
                pts.iter().fold(DVec3::ZERO, |s, p| s + (*p - c) * (*p - c)) / pts.len() as f64;
            params.set_log_scale(i, DVec3::new(var.x.lln(), var.y.lln(), var.z.lln()) * 0.5);
            params.set_center(0, i, c);
        }
        params.broadcast_frame(0);
        params
    }

    pub(crate) fn angle(a: DMat3, b: DMat3) -> f64 {
        rotation_angle(a, b)
    }

    #[test]
    fn bounded_coarse_scores_keep_the_same_candidates_after_claims() {
        let frames: Vec<Vec<Vec3>> = [0.0, 0.7]
            .iter()
            .enumerate()
            .map(|(t, a)| hinge(*a, 3000, 11 + t as u64).0)
            .collect();
        let (f0, lab0) = hinge(0.0, 3000, 11);
        let data = Data::new(frames);
        let mut tg = Target::frame(&data, 1);
        assert!(!tg.bound.is_empty(), "3000-point frames are bounded");
        let mut buf = Vec::new();
        // The base is posed first and its points claimed, as the search does.
        let base: Vec<DVec3> = f0
            .iter()
            .zip(&lab0)
            .filter(|(_, &l)| l == 0)
            .map(|(p, _)| p.as_dvec3())
            .collect();
        claim(
            &mut tg,
            &data,
            1,
            &base,
            (DMat3::IDENTITY, DVec3::ZERO),
            &mut buf,
        );
        assert!(tg.pts.len() < 2000, "claimed: {} left", tg.pts.len());
        // A bound never exceeds the capped distance to the points left.
        let mut rng = rand::rngs::StdRng::seed_from_u64(4);
        for _ in 0..20_000 {
            let x = Vec3::new(
                rng.random_range(-0.55..0.55),
                rng.random_range(-0.55..0.55),
                rng.random_range(-0.2..0.2),
            );
            assert!(tg.lower_d2(x) <= tg.capped_d2(x), "{x}");
        }
        // The arm's probe points under rotations about the hinge (and the truth).
        let probe: Vec<DVec3> = f0
            .iter()
            .zip(&lab0)
            .filter(|(_, &l)| l == 1)
            .step_by(30)
            .map(|(p, _)| p.as_dvec3())
            .collect();
        let mut cands: Vec<Motion> = vec![(DMat3::IDENTITY, DVec3::ZERO)];
        cands.extend(uniform_rotations(512).into_iter().map(|r| (r, DVec3::ZERO)));
        cands.push((DMat3::from_axis_angle(DVec3::Z, 0.7), DVec3::ZERO));
        let sums: Vec<f64> = cands
            .iter()
            .map(|c| {
                probe
                    .iter()
                    .map(|p| tg.capped_d2((c.0 * *p + c.1).as_vec3()))
                    .sum()
            })
            .collect();
        let mut want: Vec<usize> = (1..cands.len()).collect();
        want.sort_by(|&a, &b| sums[a].total_cmp(&sums[b]).then(a.cmp(&b)));
        want.truncate(12);
        assert_eq!(coarse_top(&tg, &probe, &cands, 12), want);
        assert_eq!(want[0], cands.len() - 1, "the true pose scores best");
    }

    #[test]
    fn finds_a_large_rotation_about_the_contact() {
        // The arm turns by 109° and −115° (without passing through the base): far outside
        // any local method's reach.
        let angles = [0.0, 1.9, -2.0];
        let frames: Vec<(Vec<Vec3>, Vec<u32>)> = angles
            .iter()
            .enumerate()
            .map(|(k, a)| hinge(*a, 3000, 40 + k as u64))
            .collect();
        let data = Data::new(frames.iter().map(|f| f.0.clone()).collect());
        let mut params = oracle_params(&frames[0].0, &frames[0].1, 2, angles.len());
        // Thin links roll slowly about their long axis under ICP: converge fully.
        let opts = PoseSearchOpts {
            final_icp: 24,
            ..Default::default()
        };
        search_poses(&data, &mut params, &opts, &mut |_| Ok(())).unwrap();
        for (t, a) in angles.iter().enumerate().skip(1) {
            let want = DMat3::from_axis_angle(DVec3::Z, *a);
            let (base, arm) = (params.gauss(t, 0), params.gauss(t, 1));
            let g0 = params.gauss(0, 1);
            let got = arm.r * g0.r.transpose();
            assert!(
                angle(base.r, params.gauss(0, 0).r) < 0.05,
                "frame {t}: base moved"
            );
            let err = angle(got, want).to_degrees();
            assert!(err < 5.0, "frame {t}: arm rotation error {err}°");
            // The arm's centre follows the hinge.
            let c = want * g0.mu;
            assert!(
                arm.mu.distance(c) < 0.02,
                "frame {t}: centre {:?} vs {c:?}",
                arm.mu
            );
        }
    }

    #[test]
    fn the_cap_follows_the_point_spacing_on_sparse_clouds() {
        // 3000 points on the hinge: spacing ~0.005, the fixed cap; 100 points:
        // spacing ~0.027, about the fixed cap's radius (0.032).
        let dense = Data::new(vec![hinge(0.0, 3000, 1).0]);
        let sparse = Data::new(vec![hinge(0.0, 100, 1).0]);
        assert_eq!(search_cap(&dense).cap2, CAP2);
        let s = point_spacing(&sparse.frames32[0]);
        assert!(s > 0.5 * CAP2.sqrt(), "spacing {s}");
        let want = (CAP_SPACINGS * s).powi(2);
        assert!((search_cap(&sparse).cap2 - want).abs() < 1e-12);
        // The masks answer for that cap: a place just beyond it is far.
        let tg = Target::frame(&sparse, 0);
        let p = sparse.frames32[0][0] + Vec3::new(0.0, 0.0, 1.05 * want.sqrt() as f32);
        if sparse.grids[0].nearest_d2_capped(p, 1.0) as f64 > want {
            assert_eq!(tg.capped_d2(p), want);
        }
    }

    #[test]
    fn uniform_rotations_cover_so3() {
        let rots = uniform_rotations(512);
        for r in &rots {
            assert!((r.determinant() - 1.0).abs() < 1e-9);
        }
        // Every rotation of a fixed random set is within 45° of a sample.
        let probe = uniform_rotations(97);
        for p in probe {
            let q = DMat3::from_axis_angle(DVec3::new(0.3, -0.5, 0.8).normalize(), 1.1) * p;
            let best = rots
                .iter()
                .map(|r| {
                    let m = (r.transpose() * q).to_cols_array();
                    ((m[0] + m[4] + m[8] - 1.0) / 2.0).clamp(-1.0, 1.0).lacos()
                })
                .fold(f64::INFINITY, f64::min);
            assert!(best.to_degrees() < 45.0, "{}", best.to_degrees());
        }
    }
    #[test]
    #[allow(clippy::needless_range_loop)]
    fn snap_joins_pieces_of_one_part_but_not_a_joint() {
        // Base split into two Gaussians with slightly different (noisy) motions, and
        // the arm on its hinge: the base pieces must end with one motion, the arm
        // must keep its own.
        let angles = [0.0, 0.9, -1.2, 1.6];
        let frames: Vec<(Vec<Vec3>, Vec<u32>)> = angles
            .iter()
            .enumerate()
            .map(|(k, a)| hinge(*a, 3000, 80 + k as u64))
            .collect();
        let data = Data::new(frames.iter().map(|f| f.0.clone()).collect());
        let (f0, lab) = (&frames[0].0, &frames[0].1);
        let split: Vec<u32> = f0
            .iter()
            .zip(lab)
            .map(|(p, &l)| if l == 1 { 2 } else { (p.x > -0.25) as u32 })
            .collect();
        let mut params = oracle_params(f0, &split, 3, angles.len());
        let g0: Vec<Gauss> = (0..3).map(|i| params.gauss(0, i)).collect();
        for (t, a) in angles.iter().enumerate().skip(1) {
            let noise =
                DMat3::from_axis_angle(DVec3::new(0.2, 1.0, 0.3).normalize(), 0.01 * t as f64);
            set_relative_pose(&mut params, t, 0, &g0[0], (noise, DVec3::ZERO));
            set_relative_pose(
                &mut params,
                t,
                1,
                &g0[1],
                (DMat3::IDENTITY, DVec3::new(0.0, 0.002, 0.0)),
            );
            set_relative_pose(
                &mut params,
                t,
                2,
                &g0[2],
                (DMat3::from_axis_angle(DVec3::Z, *a), DVec3::ZERO),
            );
        }
        let n = snap_rigid(&data, &mut params, 1024, 3.0, 0.8, true);
        assert_eq!(n, 1, "one snap (the two base pieces)");
        let rel = |i: usize, t: usize| relative_motion(&params.gauss(0, i), &params.gauss(t, i));
        for t in 1..angles.len() {
            let (a, b) = (rel(0, t), rel(1, t));
            assert!(
                angle(a.0, b.0) < 1e-9 && a.1.distance(b.1) < 1e-9,
                "frame {t}"
            );
            let arm = rel(2, t);
            let want = DMat3::from_axis_angle(DVec3::Z, angles[t]);
            assert!(angle(arm.0, want) < 1e-9, "frame {t}: the arm moved");
        }
    }

    #[test]
    fn snap_keeps_a_gaussian_that_straddles_the_hinge() {
        // Gaussian 0: the far two thirds of the fixed box. Gaussian 1 straddles the
        // hinge: the near third of the box and the arm's first 0.1, posed with the
        // arm's motion. Gaussian 2: the rest of the arm, posed 0.2 rad off. The box's
        // motion explains most of Gaussian 1's points, so without the straddle test
        // Gaussian 1 is snapped onto the box and the arm's root goes with it.
        let angles = [0.0, 0.9, -1.2, 1.6];
        let frames: Vec<(Vec<Vec3>, Vec<u32>)> = angles
            .iter()
            .enumerate()
            .map(|(k, a)| hinge(*a, 3000, 90 + k as u64))
            .collect();
        let data = Data::new(frames.iter().map(|f| f.0.clone()).collect());
        let f0 = &frames[0].0;
        let split: Vec<u32> = f0
            .iter()
            .map(|p| {
                if p.x < -0.3 {
                    0
                } else if p.x < 0.12 {
                    1
                } else {
                    2
                }
            })
            .collect();
        let mut params = oracle_params(f0, &split, 3, angles.len());
        let g0: Vec<Gauss> = (0..3).map(|i| params.gauss(0, i)).collect();
        for (t, a) in angles.iter().enumerate().skip(1) {
            let arm = (DMat3::from_axis_angle(DVec3::Z, *a), DVec3::ZERO);
            set_relative_pose(&mut params, t, 1, &g0[1], arm);
            let off = (DMat3::from_axis_angle(DVec3::Z, *a + 0.2), DVec3::ZERO);
            set_relative_pose(&mut params, t, 2, &g0[2], off);
        }
        let still = |p: &Params, i: usize| {
            (1..angles.len()).all(|t| {
                let r = relative_motion(&p.gauss(0, i), &p.gauss(t, i));
                angle(r.0, DMat3::IDENTITY) < 1e-9
            })
        };
        let mut without = params.clone();
        snap_rigid(&data, &mut without, 1024, 3.0, 0.8, false);
        assert!(
            still(&without, 1),
            "the straddler was expected to snap onto the box"
        );
        snap_rigid(&data, &mut params, 1024, 3.0, 0.8, true);
        assert!(
            !still(&params, 1),
            "the straddler must keep a moving motion"
        );
        assert!(still(&params, 0));
    }

    /// A hip: a fixed base box along −x, a cylindrical housing turning about its own
    /// axis (x, through the origin) by `a`, and a leg hanging from the housing that
    /// also turns about y through (0.06, 0, −0.05) by `b`. Points sampled
    /// independently per call; labels 0 base, 1 housing, 2 leg.
    fn hip(a: f64, b: f64, n: usize, seed: u64) -> (Vec<Vec3>, Vec<u32>) {
        let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
        let ra = DMat3::from_axis_angle(DVec3::X, a);
        let pivot = DVec3::new(0.06, 0.0, -0.05);
        let rb = DMat3::from_axis_angle(DVec3::Y, b);
        let boxed = |rng: &mut rand::rngs::StdRng, lo: DVec3, hi: DVec3| {
            let mut u = DVec3::new(rng.random(), rng.random(), rng.random());
            u[rng.random_range(0..3)] = if rng.random_bool(0.5) { 1.0 } else { 0.0 };
            lo + (hi - lo) * u
        };
        let mut pts = Vec::with_capacity(n);
        let mut lab = Vec::with_capacity(n);
        for _ in 0..n {
            let part = rng.random_range(0..3u32);
            let p = match part {
                0 => boxed(
                    &mut rng,
                    DVec3::new(-0.45, -0.08, -0.03),
                    DVec3::new(-0.02, 0.08, 0.03),
                ),
                1 => {
                    // Side or cap of a cylinder of radius 0.05 along x, 0–0.12.
                    let th = rng.random::<f64>() * std::f64::consts::TAU;
                    if rng.random_bool(0.7) {
                        let x = rng.random::<f64>() * 0.12;
                        ra * DVec3::new(x, 0.05 * th.lcos(), 0.05 * th.lsin())
                    } else {
                        let r = 0.05 * rng.random::<f64>().sqrt();
                        let x = if rng.random_bool(0.5) { 0.0 } else { 0.12 };
                        ra * DVec3::new(x, r * th.lcos(), r * th.lsin())
                    }
                }
                _ => {
                    let q = boxed(
                        &mut rng,
                        DVec3::new(0.03, -0.03, -0.4),
                        DVec3::new(0.09, 0.03, -0.06),
                    );
                    ra * (rb * (q - pivot) + pivot)
                }
            };
            pts.push(p.as_vec3());
            lab.push(part);
        }
        (pts, lab)
    }

    #[test]
    #[allow(clippy::needless_range_loop)]
    fn snap_keeps_a_housing_that_carries_a_joint() {
        // The housing fits the base's motion as well as its own (it turns about its
        // axis of symmetry), but the leg moves about one hinge relative to the
        // housing and about two relative to the base: the housing must keep its motion.
        let states = [
            (0.0, 0.0),
            (0.5, -0.4),
            (-0.4, 0.6),
            (0.3, 0.9),
            (-0.6, -0.5),
        ];
        let frames: Vec<(Vec<Vec3>, Vec<u32>)> = states
            .iter()
            .enumerate()
            .map(|(k, &(a, b))| hip(a, b, 3000, 90 + k as u64))
            .collect();
        let data = Data::new(frames.iter().map(|f| f.0.clone()).collect());
        let (f0, lab) = (&frames[0].0, &frames[0].1);
        let mut params = oracle_params(f0, lab, 3, states.len());
        let g0: Vec<Gauss> = (0..3).map(|i| params.gauss(0, i)).collect();
        let pivot = DVec3::new(0.06, 0.0, -0.05);
        for (t, &(a, b)) in states.iter().enumerate().skip(1) {
            let ra = DMat3::from_axis_angle(DVec3::X, a);
            let rleg = ra * DMat3::from_axis_angle(DVec3::Y, b);
            set_relative_pose(&mut params, t, 0, &g0[0], (DMat3::IDENTITY, DVec3::ZERO));
            set_relative_pose(&mut params, t, 1, &g0[1], (ra, DVec3::ZERO));
            set_relative_pose(&mut params, t, 2, &g0[2], (rleg, ra * pivot - rleg * pivot));
        }
        // The premise: the base's motion explains the housing within the snap ratio.
        let groups = frame0_groups(&data, &g0, 1024);
        let tg = Target::frame(&data, 3);
        let mut buf = Vec::new();
        let id = (DMat3::IDENTITY, DVec3::ZERO);
        let ra = (DMat3::from_axis_angle(DVec3::X, states[3].0), DVec3::ZERO);
        let (s_base, s_own) = (
            score(&tg, &groups[1], id, 0.8, &mut buf),
            score(&tg, &groups[1], ra, 0.8, &mut buf),
        );
        assert!(s_base < 3.0 * s_own, "base {s_base} own {s_own}");
        // Without the carry test it is snapped onto the base.
        assert_eq!(
            snap_rigid(&data, &mut params.clone(), 1024, 3.0, 0.8, false),
            1
        );
        assert_eq!(snap_rigid(&data, &mut params, 1024, 3.0, 0.8, true), 0);
        let r1 = relative_motion(&params.gauss(0, 1), &params.gauss(3, 1));
        assert!(angle(r1.0, ra.0) < 1e-9, "the housing lost its motion");
    }
}
