//! Step 3 refinement (paper §3.3): joint axes, pivots, per-frame states and the root
//! motion are refined through forward kinematics so that the canonical frame's
//! segmented points, moved to every frame t, match the observed cloud Xᵗ.
//!
//! Loss: Σₜ L_CD(FK_t(X_c), Xᵗ) + λ·L_EMD over t ≠ c (λ = 0.3), with L_CD the
//! bidirectional squared Chamfer (means, nearest neighbours through `geom::knn::Grid`)
//! on seeded subsamples and L_EMD the mean squared
//! distance under the optimal one-to-one assignment (`geom::assignment::Lap`, exact
//! linear assignment) between the first `emd_sample` points of both subsamples. The
//! assignment is recomputed every `emd_every` iterations and held fixed in between (its
//! loss is then an upper bound of the EMD, and the gradient is that of the fixed
//! matching); the acceptance test always uses a fresh assignment.
//!
//! **Deviation: λ defaults to 0 (Chamfer only).** Frames are sampled independently, so
//! a one-to-one matching between two subsamples is noisy at the scale of the subsample
//! spacing. Measured on bench-dev with joints perturbed by 4°/0.015 (tests/kin_noisy.rs):
//! Chamfer only brings so101's median axis error 4.0° → 2.0° and pivot 0.017 → 0.005 (xarm7:
//! 4.0° → 3.5°, 0.015 → 0.002), whereas +0.3·EMD makes so101 worse (median axis 4.0° → 6.0°
//! with 192 points / refresh every 20 iterations, 4.0° → 6.1° with 384 / 10 at 4× the
//! time). Set `lambda_emd = 0.3` to reproduce the paper's loss.
//!
//! Gradients are analytic: the Chamfer gradient on each moved point gives every part a
//! world wrench (Σ y×g, Σ g); a joint parameter perturbs its subtree by a twist
//! Ad_{T_parent} ξ, so its derivative is the subtree wrench paired with ξ (pulled into
//! the joint's frame). Root motion is parametrised per frame as Tr(u)·Rot(φ)·root₀.
//! Adam (lr 1.5e-2 as in the paper) with a cosine decay to 10% so the last iterations
//! settle instead of jittering at the step size, plus a small prior that keeps revolute
//! axes near their projection where the data do not see them (see `axis_prior`).
//!
//! Sample size: 2048 points per frame (smaller frames whole); 200 iterations. The Chamfer's sampling noise hides small errors: on the procedural
//! laptop (2048-point frames) 384 points left a 2 % pivot error (refinement rejected;
//! axis 2.7°, pivot 2.1 %), 1024 points 2.3 % (seed 3), the whole frames 0.7° / 0.5 %
//! (loss identical at 200 and 500 iterations). Session 30, 4096-point frames, end to
//! end, 1024 → 2048 points: the procedural quadruped (fast, generator seeds 0–3) 8 →
//! 14 of its 32 joints within 5° and a pivot error of 2, recon 0.48 → 0.42, flow 0.50
//! → 0.44; bench-dev full, means of seeds 0–2, fast recon 0.762 → 0.755, flow 0.728 →
//! 0.703, balanced 0.703 → 0.691, 0.671 → 0.649, joints in that bar 47 and 49 of 162
//! both. The whole 4096-point frames did better on the quadruped (16 of 32) but worse
//! on bench-dev's joints (47 → 41 fast), since the acceptance test below then sees
//! the points it was refined on. Twice the points cost about twice the refinement
//! (nearly all of it nearest-neighbour queries; bench-dev full balanced, seven robots
//! two at a time, 125 → 136 s).
//!
//! The refined model is kept only if it lowers the loss on a second seeded subsample
//! (independent of the first when frames hold more points than the sample).

use crate::math::Libm;
use glam::{DMat3, DMat4, DVec3, Vec3};
use rand::{rngs::StdRng, seq::index::sample, SeedableRng};
use serde::Serialize;

use super::chain::screw_exp;
use super::project::bfs_order;
use super::screw::{padded_limits, unwrap_angles};
use crate::geom::assignment::Lap;
use crate::geom::knn::{Grid, LastMatches};
use crate::geom::se3::{from_row_major, to_row_major};
use crate::io::gt::JointType;
use crate::io::result::FitResult;
use crate::pipeline::{Control, Progress, Stage};

/// Options of the refinement.
#[derive(Debug, Clone, PartialEq)]
pub struct RefineOptions {
    pub iters: usize,
    pub lr: f64,
    /// Points sampled per frame (source and target) ...
    pub sample: usize,
    /// ... unless every frame has at most this many points: then all of them (an
    /// exact Chamfer without sampling noise, see the module doc).
    pub whole_up_to: usize,
    /// Also refine the root motion.
    pub root: bool,
    pub seed: u64,
    /// EMD weight λ (0 disables the EMD term; the paper uses 0.3 — see the module doc
    /// for why the default is 0).
    pub lambda_emd: f64,
    /// Points per frame in the EMD assignment.
    pub emd_sample: usize,
    /// Iterations between assignment refreshes.
    pub emd_every: usize,
    /// Weight per frame of the axis prior w·(1 − (â·â₀)²) that keeps each joint axis near
    /// its projection unless the data pull it away. Without it a joint whose axis the
    /// Chamfer barely sees (a limb turning about its own long axis) drifts: measured on
    /// bench-dev talos with near-exact poses (tests/kin_noisy.rs), 1.2° → 13° at a loss
    /// change of 1 %. At 1e-4 the prior costs 1.2e-6 for a 2° correction, against the
    /// 5e-4 the procedural laptop's 2° correction gains.
    pub axis_prior: f64,
    /// Groups of joints (indices into the result's joints) whose axes stay parallel:
    /// after every step each group's axes are set to their sign-aligned mean
    /// (`kinematics::parallel`). Empty: every axis free.
    pub ties: Vec<Vec<usize>>,
    /// Members of `ties` whose axes follow their group's direction without weighing
    /// in it (`parallel::followers`).
    pub tie_followers: Vec<usize>,
    /// Joints (indices) whose axes the axis prior leaves free.
    pub free_axes: Vec<usize>,
}

impl Default for RefineOptions {
    fn default() -> Self {
        RefineOptions {
            iters: 200,
            lr: 1.5e-2,
            sample: 2048,
            whole_up_to: 2048,
            axis_prior: 1e-4,
            root: true,
            seed: 0,
            lambda_emd: 0.0,
            emd_sample: 192,
            emd_every: 20,
            ties: Vec::new(),
            tie_followers: Vec::new(),
            free_axes: Vec::new(),
        }
    }
}

/// Outcome of the refinement.
#[derive(Debug, Clone, Serialize)]
pub struct RefineReport {
    /// Loss on the evaluation subsample before and after.
    pub loss_before: f64,
    pub loss_after: f64,
    /// Whether the refined parameters were kept.
    pub accepted: bool,
    pub iters: usize,
    pub uses_emd: bool,
}

/// The chain being refined (flat parameter vector + structure).
#[derive(Debug, Clone)]
pub(crate) struct Model {
    pub k: usize,
    pub c: usize,
    pub parts: usize,
    pub order: Vec<usize>,
    pub parent: Vec<i64>,
    /// Joint index per part (None for the root).
    pub joint_of: Vec<Option<usize>>,
    pub types: Vec<JointType>,
    pub root0: Vec<DMat4>,
    pub refine_root: bool,
}

// Parameter layout: per joint j: [axis(3), pivot(3), states(k)], then per frame t:
// [u(3), φ(3)] of the root.
impl Model {
    pub(crate) fn joint_base(&self, j: usize) -> usize {
        j * (6 + self.k)
    }
    fn root_base(&self, t: usize) -> usize {
        self.types.len() * (6 + self.k) + 6 * t
    }
    pub fn len(&self) -> usize {
        self.root_base(self.k)
    }
    fn v3(x: &[f64], i: usize) -> DVec3 {
        DVec3::new(x[i], x[i + 1], x[i + 2])
    }
    fn root_pose(&self, x: &[f64], t: usize) -> DMat4 {
        let b = self.root_base(t);
        let u = Self::v3(x, b);
        let phi = Self::v3(x, b + 3);
        DMat4::from_translation(u) * DMat4::from_mat3(rot_vec(phi)) * self.root0[t]
    }
    fn joint_params(&self, x: &[f64], j: usize) -> (DVec3, DVec3) {
        let b = self.joint_base(j);
        (Self::v3(x, b), Self::v3(x, b + 3))
    }
    /// Part poses at frame t.
    pub fn poses(&self, x: &[f64], t: usize) -> Vec<DMat4> {
        let mut out = vec![DMat4::IDENTITY; self.parts];
        for &p in &self.order {
            match self.joint_of[p] {
                None => out[p] = self.root_pose(x, t),
                Some(j) => {
                    let (a, piv) = self.joint_params(x, j);
                    let q = x[self.joint_base(j) + 6 + t];
                    let axis = a.normalize_or(DVec3::Z);
                    out[p] = out[self.parent[p] as usize] * screw_exp(self.types[j], axis, piv, q);
                }
            }
        }
        out
    }
}

fn rot_vec(phi: DVec3) -> DMat3 {
    let th = phi.length();
    if th < 1e-300 {
        DMat3::IDENTITY
    } else {
        DMat3::from_axis_angle(phi / th, th)
    }
}

fn skew(v: DVec3) -> DMat3 {
    DMat3::from_cols(
        DVec3::new(0.0, v.z, -v.y),
        DVec3::new(-v.z, 0.0, v.x),
        DVec3::new(v.y, -v.x, 0.0),
    )
}

/// SO(3) left Jacobian: exp(φ + δ) ≈ exp(J_l(φ) δ) exp(φ).
fn left_jacobian(phi: DVec3) -> DMat3 {
    let th = phi.length();
    let k = skew(phi);
    let (a, b) = if th < 1e-4 {
        (0.5 - th * th / 24.0, 1.0 / 6.0 - th * th / 120.0)
    } else {
        (
            (1.0 - th.lcos()) / (th * th),
            (th - th.lsin()) / (th * th * th),
        )
    };
    DMat3::IDENTITY + k * a + k * k * b
}

/// Bidirectional squared Chamfer (means) between `y` and `x`, with its gradient on `y`
/// written into `g`. `xg` indexes `x`; `yg` is scratch, rebuilt on `y`.
fn chamfer(
    y: &[Vec3],
    x: &[Vec3],
    xg: &Grid,
    yg: &mut Grid,
    g: &mut [Vec3],
    mut hints: Option<&mut FrameHints>,
) -> f64 {
    g.iter_mut().for_each(|v| *v = Vec3::ZERO);
    if y.is_empty() || x.is_empty() {
        return 0.0;
    }
    let (ny, nx) = (y.len() as f32, x.len() as f32);
    let mut loss = 0.0f64;
    if let Some(h) = hints.as_deref_mut() {
        h.to_target.fit(y.len());
        h.to_model.fit(x.len());
    }
    for (i, yi) in y.iter().enumerate() {
        let nn = match hints.as_deref_mut() {
            Some(h) => h.to_target.nearest(xg, i, *yi, |j| x[j]),
            None => xg.nearest(*yi),
        };
        if let Some((j, d)) = nn {
            loss += d as f64 / ny as f64;
            g[i] = (*yi - x[j as usize]) * (2.0 / ny);
        }
    }
    yg.rebuild(y);
    for (m, xm) in x.iter().enumerate() {
        let nn = match hints.as_deref_mut() {
            Some(h) => h.to_model.nearest(yg, m, *xm, |j| y[j]),
            None => yg.nearest(*xm),
        };
        if let Some((i, d)) = nn {
            loss += d as f64 / nx as f64;
            g[i as usize] += (y[i as usize] - *xm) * (2.0 / nx);
        }
    }
    loss
}

/// Each query point's nearest point at the last evaluation, per frame: between two
/// Adam steps the model's points move little, so the old match bounds the search
/// (`Grid::nearest_hinted`; the same nearest points, measured faster).
#[derive(Default)]
pub(crate) struct Hints {
    frames: Vec<FrameHints>,
}

#[derive(Default)]
pub(crate) struct FrameHints {
    /// Model point → target point.
    to_target: LastMatches,
    /// Target point → model point.
    to_model: LastMatches,
}

/// Sampled data of the refinement: source points (frame c) with parts, targets per frame.
pub(crate) struct Data {
    pub src: Vec<DVec3>,
    pub src_part: Vec<usize>,
    pub targets: Vec<Vec<Vec3>>,
    /// Nearest-neighbour index of each frame's targets.
    pub grids: Vec<Grid>,
}

/// A fixed EMD matching: `lambda` and, per frame, the target index (into
/// `targets[t]`) of each of the first source points.
pub(crate) struct Matching {
    pub lambda: f64,
    pub cols: Vec<Vec<usize>>,
}

/// Optimal one-to-one matching of the first `n` moved source points to the first `n`
/// target points of every frame t ≠ c.
pub(crate) fn assign(
    m: &Model,
    x: &[f64],
    d: &Data,
    n: usize,
    lambda: f64,
    lap: &mut Lap,
) -> Matching {
    let mut cols = vec![Vec::new(); m.k];
    let mut cost = Vec::new();
    for (t, out) in cols.iter_mut().enumerate() {
        if t == m.c {
            continue;
        }
        let n = n.min(d.src.len()).min(d.targets[t].len());
        let poses = m.poses(x, t);
        cost.clear();
        for i in 0..n {
            let y = poses[d.src_part[i]].transform_point3(d.src[i]).as_vec3();
            cost.extend(
                d.targets[t][..n]
                    .iter()
                    .map(|q| y.distance_squared(*q) as f64),
            );
        }
        if !lap.solve(&cost, n, n, out) {
            out.clear();
        }
    }
    Matching { lambda, cols }
}

/// Loss and gradient with respect to the flat parameters (Chamfer, plus the EMD of a
/// fixed matching if given).
pub(crate) fn loss_grad(
    m: &Model,
    x: &[f64],
    d: &Data,
    matching: Option<&Matching>,
    grad: Option<&mut [f64]>,
    mut hints: Option<&mut Hints>,
) -> f64 {
    if let Some(h) = hints.as_deref_mut() {
        h.frames.resize_with(m.k, FrameHints::default);
    }
    let mut gbuf = vec![0.0; if grad.is_some() { m.len() } else { 0 }];
    let mut y = vec![Vec3::ZERO; d.src.len()];
    let mut g = vec![Vec3::ZERO; d.src.len()];
    let mut ygrid = Grid::default();
    let mut total = 0.0;
    for t in 0..m.k {
        if t == m.c {
            continue;
        }
        let tgt = &d.targets[t];
        let poses = m.poses(x, t);
        for (i, (s, &p)) in d.src.iter().zip(&d.src_part).enumerate() {
            y[i] = poses[p].transform_point3(*s).as_vec3();
        }
        let fh = hints.as_deref_mut().map(|h| &mut h.frames[t]);
        total += chamfer(&y, tgt, &d.grids[t], &mut ygrid, &mut g, fh);
        if let Some(mt) = matching {
            let cols = &mt.cols[t];
            let w = mt.lambda / cols.len().max(1) as f64;
            for (i, &j) in cols.iter().enumerate() {
                let diff = y[i] - tgt[j];
                total += w * diff.length_squared() as f64;
                g[i] += diff * (2.0 * w) as f32;
            }
        }
        if gbuf.is_empty() {
            continue;
        }
        // Wrench per part, then per subtree (children after parents in `order`).
        let mut tau = vec![DVec3::ZERO; m.parts];
        let mut f = vec![DVec3::ZERO; m.parts];
        for ((yi, gi), &p) in y.iter().zip(&g).zip(&d.src_part) {
            let (yd, gd) = (yi.as_dvec3(), gi.as_dvec3());
            tau[p] += yd.cross(gd);
            f[p] += gd;
        }
        for &p in m.order.iter().rev() {
            if m.parent[p] >= 0 {
                let a = m.parent[p] as usize;
                let (tp, fp) = (tau[p], f[p]);
                tau[a] += tp;
                f[a] += fp;
            }
        }
        for &p in &m.order {
            match m.joint_of[p] {
                None => {
                    if m.refine_root && t != m.c {
                        let b = m.root_base(t);
                        let u = Model::v3(x, b);
                        let phi = Model::v3(x, b + 3);
                        let gu = f[p];
                        let gphi = left_jacobian(phi).transpose() * (tau[p] - u.cross(f[p]));
                        gbuf[b..b + 3].copy_from_slice(&gu.to_array());
                        gbuf[b + 3..b + 6].copy_from_slice(&gphi.to_array());
                    }
                }
                Some(j) => {
                    let ta = poses[m.parent[p] as usize];
                    let ra = DMat3::from_mat4(ta);
                    let tr = ta.w_axis.truncate();
                    let tl = ra.transpose() * (tau[p] + f[p].cross(tr));
                    let fl = ra.transpose() * f[p];
                    let b = m.joint_base(j);
                    let (a, piv) = m.joint_params(x, j);
                    let an = a.length().max(1e-12);
                    let w = a / an;
                    let q = x[b + 6 + t];
                    let proj = |v: DVec3| (v - w * w.dot(v)) / an;
                    match m.types[j] {
                        JointType::Revolute => {
                            let r = DMat3::from_axis_angle(w, q);
                            let gq = tl.dot(w) + fl.dot(piv.cross(w));
                            let gp = (DMat3::IDENTITY - r).transpose() * fl;
                            let gw = left_jacobian(w * q).transpose() * (tl + fl.cross(piv)) * q;
                            let ga = proj(gw);
                            for i in 0..3 {
                                gbuf[b + i] += ga[i];
                                gbuf[b + 3 + i] += gp[i];
                            }
                            gbuf[b + 6 + t] = gq;
                        }
                        JointType::Prismatic => {
                            let ga = proj(fl * q);
                            for i in 0..3 {
                                gbuf[b + i] += ga[i];
                            }
                            gbuf[b + 6 + t] = fl.dot(w);
                        }
                    }
                }
            }
        }
    }
    if let Some(out) = grad {
        out.copy_from_slice(&gbuf);
    }
    total
}

/// Makes the axes of each group in `ties` parallel: each is set to the group's
/// `parallel::tied_direction` (from its states' ranges; `followers` weigh nothing),
/// keeping its own sense and length. Out-of-range indices are ignored.
pub(crate) fn tie_axes(m: &Model, x: &mut [f64], ties: &[Vec<usize>], followers: &[usize]) {
    let n = m.types.len();
    // Runs after every Adam step: no allocation.
    for group in ties {
        let members = || group.iter().copied().filter(|&j| j < n);
        let axes = members().map(|j| {
            let b = m.joint_base(j);
            let states = super::parallel::weighing_states(j, followers, &x[b + 6..b + 6 + m.k]);
            (Model::v3(x, b), states)
        });
        let Some((dir, senses)) = super::parallel::tied_direction(axes) else {
            continue;
        };
        for (j, s) in members().zip(senses) {
            let b = m.joint_base(j);
            let v = dir * s * Model::v3(x, b).length().max(1e-12);
            x[b..b + 3].copy_from_slice(&v.to_array());
        }
    }
}

/// Axis prior Σⱼ w·(1 − (âⱼ·â⁰ⱼ)²) over revolute joints (unit axes, sign-free); adds its
/// gradient to `grad`. Slides are left free: a slide's axis shows directly in the
/// displacement of its whole part (bench-dev panda_gripper: the refinement corrects the
/// projected finger axes from 29° to 3.5° median, which the prior would block), whereas a
/// hinge about a part's own symmetry axis is invisible to the Chamfer.
pub(crate) fn axis_prior(
    m: &Model,
    x: &[f64],
    x0: &[f64],
    w: f64,
    free: &[usize],
    grad: &mut [f64],
) -> f64 {
    if w <= 0.0 {
        return 0.0;
    }
    let mut total = 0.0;
    for j in 0..m.types.len() {
        if m.types[j] != JointType::Revolute || free.contains(&j) {
            continue;
        }
        let b = m.joint_base(j);
        let a = Model::v3(x, b);
        let a0 = Model::v3(x0, b).normalize_or(DVec3::Z);
        let n = a.length().max(1e-12);
        let u = a / n;
        let c = u.dot(a0);
        total += w * (1.0 - c * c);
        // d(1 − c²)/da = −2c (a0 − c u)/|a|
        let g = (a0 - u * c) * (-2.0 * w * c / n);
        for i in 0..3 {
            grad[b + i] += g[i];
        }
    }
    total
}

fn sample_points(pts: &[Vec3], n: usize, rng: &mut StdRng) -> Vec<usize> {
    if pts.len() <= n {
        (0..pts.len()).collect()
    } else {
        let mut v = sample(rng, pts.len(), n).into_vec();
        v.sort_unstable();
        v
    }
}

pub(crate) fn build_data(
    result: &FitResult,
    points: &[Vec<Vec3>],
    n: usize,
    rng: &mut StdRng,
) -> Data {
    let c = result.canonical_frame;
    let idx = sample_points(&points[c], n, rng);
    let src = idx.iter().map(|&i| points[c][i].as_dvec3()).collect();
    let src_part = idx.iter().map(|&i| result.labels[c][i] as usize).collect();
    let targets: Vec<Vec<Vec3>> = points
        .iter()
        .map(|f| sample_points(f, n, rng).into_iter().map(|i| f[i]).collect())
        .collect();
    let grids = targets.iter().map(|t| Grid::new(t)).collect();
    Data {
        src,
        src_part,
        targets,
        grids,
    }
}

/// Model and initial parameters from a projected result.
pub(crate) fn model_from_result(
    result: &FitResult,
    refine_root: bool,
) -> crate::Result<(Model, Vec<f64>)> {
    let bad = |s: &str| crate::Error::InvalidArgument(format!("refinement: {s}"));
    let tree = result.tree.as_ref().ok_or_else(|| bad("no tree"))?;
    let joints = result.joints.as_ref().ok_or_else(|| bad("no joints"))?;
    let root_motion = result
        .root_motion
        .as_ref()
        .ok_or_else(|| bad("no root motion"))?;
    let (k, n) = (result.frames, result.parts);
    if tree.parent.len() != n || root_motion.len() != k || result.canonical_frame >= k {
        return Err(bad("inconsistent result"));
    }
    let mut joint_of = vec![None; n];
    for (j, jt) in joints.iter().enumerate() {
        if jt.child >= n || jt.state.len() != k || tree.parent[jt.child] != jt.parent as i64 {
            return Err(bad("joint does not match the tree"));
        }
        joint_of[jt.child] = Some(j);
    }
    let order = bfs_order(&tree.parent);
    if order.len() != n || (0..n).any(|p| (p == tree.root) == joint_of[p].is_some()) {
        return Err(bad("every non-root part needs exactly one joint"));
    }
    let m = Model {
        k,
        c: result.canonical_frame,
        parts: n,
        order,
        parent: tree.parent.clone(),
        joint_of,
        types: joints.iter().map(|j| j.joint_type).collect(),
        root0: root_motion.iter().map(from_row_major).collect(),
        refine_root,
    };
    let mut x = vec![0.0; m.len()];
    for (j, jt) in joints.iter().enumerate() {
        let b = m.joint_base(j);
        x[b..b + 3].copy_from_slice(&jt.axis);
        x[b + 3..b + 6].copy_from_slice(&jt.pivot);
        x[b + 6..b + 6 + k].copy_from_slice(&jt.state);
    }
    Ok((m, x))
}

/// Refine `result` (a projected chain) in place against the observed working points
/// `points[k]` (the same clouds whose labels are `result.labels`).
pub fn refine(
    result: &mut FitResult,
    points: &[Vec<Vec3>],
    opts: &RefineOptions,
    limit_pad: f64,
    progress: &mut dyn FnMut(&Progress) -> Control,
) -> crate::Result<RefineReport> {
    let (m, x0) = model_from_result(result, opts.root)?;
    if points.len() != m.k
        || points
            .iter()
            .zip(&result.labels)
            .any(|(p, l)| p.len() != l.len())
    {
        return Err(crate::Error::InvalidArgument(
            "refinement: points do not match the result's labels".into(),
        ));
    }
    let mut rng = StdRng::seed_from_u64(opts.seed);
    let largest = points.iter().map(Vec::len).max().unwrap_or(0);
    let n = if largest <= opts.whole_up_to {
        largest
    } else {
        opts.sample
    };
    let train = build_data(result, points, n, &mut rng);
    // With frames no larger than the sample both subsamples are the whole clouds:
    // evaluate on the training data instead of building it again.
    let whole = largest <= n;
    let eval_own = (!whole).then(|| build_data(result, points, n, &mut rng));
    let eval = eval_own.as_ref().unwrap_or(&train);
    let mut lap = Lap::default();
    let use_emd = opts.lambda_emd > 0.0 && opts.emd_sample > 0;
    let eval_loss = |x: &[f64], lap: &mut Lap| {
        let mt = use_emd.then(|| assign(&m, x, eval, opts.emd_sample, opts.lambda_emd, lap));
        loss_grad(&m, x, eval, mt.as_ref(), None, None)
    };
    let loss_before = eval_loss(&x0, &mut lap);
    let mut matching = None;

    let mut x = x0.clone();
    tie_axes(&m, &mut x, &opts.ties, &opts.tie_followers);
    let mut adam = Adam::new(x.len());
    let mut g = vec![0.0; x.len()];
    let prior_w = opts.axis_prior * (m.k.saturating_sub(1)) as f64;
    let mut hints = Hints::default();
    for it in 0..opts.iters {
        if use_emd && it % opts.emd_every.max(1) == 0 {
            matching = Some(assign(
                &m,
                &x,
                &train,
                opts.emd_sample,
                opts.lambda_emd,
                &mut lap,
            ));
        }
        let loss = loss_grad(
            &m,
            &x,
            &train,
            matching.as_ref(),
            Some(&mut g),
            Some(&mut hints),
        ) + axis_prior(&m, &x, &x0, prior_w, &opts.free_axes, &mut g);
        adam.step(&mut x, &g, it, opts.iters, opts.lr);
        tie_axes(&m, &mut x, &opts.ties, &opts.tie_followers);
        if it % 25 == 0 || it + 1 == opts.iters {
            let losses = vec![("refine".to_string(), loss)];
            super::build::progress_to(progress, Stage::Joints, it, opts.iters, losses)?;
        }
    }
    let loss_after = eval_loss(&x, &mut lap);
    let accepted = loss_after.is_finite() && loss_after < loss_before;
    if accepted {
        write_back(result, &m, &x, limit_pad);
    }
    Ok(RefineReport {
        loss_before,
        loss_after,
        accepted,
        iters: opts.iters,
        uses_emd: use_emd,
    })
}

/// Adam (β 0.9 / 0.999) with the refinement's cosine decay of the step size to 10 % over
/// `iters`, so the last iterations settle instead of jittering at the step size.
pub(crate) struct Adam {
    mo: Vec<f64>,
    ve: Vec<f64>,
}

impl Adam {
    pub(crate) fn new(n: usize) -> Self {
        Adam {
            mo: vec![0.0; n],
            ve: vec![0.0; n],
        }
    }

    /// One step on `x` along gradient `g` at iteration `it` of `iters`.
    pub(crate) fn step(&mut self, x: &mut [f64], g: &[f64], it: usize, iters: usize, lr: f64) {
        let (b1, b2, eps) = (0.9f64, 0.999f64, 1e-8);
        let lr = lr
            * (0.1 + 0.9 * 0.5 * (1.0 + (std::f64::consts::PI * it as f64 / iters as f64).lcos()));
        let (c1, c2) = (1.0 - b1.powi(it as i32 + 1), 1.0 - b2.powi(it as i32 + 1));
        for i in 0..x.len() {
            self.mo[i] = b1 * self.mo[i] + (1.0 - b1) * g[i];
            self.ve[i] = b2 * self.ve[i] + (1.0 - b2) * g[i] * g[i];
            x[i] -= lr * (self.mo[i] / c1) / ((self.ve[i] / c2).sqrt() + eps);
        }
    }
}

fn write_back(result: &mut FitResult, m: &Model, x: &[f64], limit_pad: f64) {
    let k = m.k;
    if let Some(joints) = result.joints.as_mut() {
        for (j, jt) in joints.iter_mut().enumerate() {
            let b = m.joint_base(j);
            let (a, piv) = m.joint_params(x, j);
            let axis = a.normalize_or(DVec3::Z);
            jt.axis = axis.to_array();
            // keep the pivot where it was along the (new) axis' normal plane
            jt.pivot = piv.to_array();
            jt.state = x[b + 6..b + 6 + k].to_vec();
            jt.state[m.c] = 0.0;
            if jt.joint_type == JointType::Revolute {
                // Whole turns change no pose; keep the states continuous (sensible limits).
                jt.state = unwrap_angles(std::mem::take(&mut jt.state));
            }
            jt.limits = padded_limits(&jt.state, limit_pad);
        }
    }
    let poses: Vec<Vec<DMat4>> = (0..k).map(|t| m.poses(x, t)).collect();
    let root = m.order[0];
    result.root_motion = Some(poses.iter().map(|f| to_row_major(&f[root])).collect());
    result.poses = poses
        .iter()
        .map(|f| f.iter().map(to_row_major).collect())
        .collect();
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::result::{ResultJoint, ResultTree, FORMAT, VERSION};
    use rand::Rng;

    fn toy() -> (FitResult, Vec<Vec<Vec3>>) {
        let k = 3;
        let mut rng = StdRng::seed_from_u64(5);
        let n = 60;
        let pts: Vec<Vec3> = (0..n)
            .map(|_| Vec3::new(rng.random(), rng.random(), rng.random()) - 0.5)
            .collect();
        let labels: Vec<u32> = (0..n).map(|i| (i % 3) as u32).collect();
        let joints = vec![
            ResultJoint {
                mimic: None,
                child: 1,
                parent: 0,
                joint_type: JointType::Revolute,
                axis: [0.2, 0.9, 0.3],
                pivot: [0.1, -0.1, 0.2],
                state: vec![0.0, 0.4, -0.3],
                limits: [-0.3, 0.4],
            },
            ResultJoint {
                mimic: None,
                child: 2,
                parent: 1,
                joint_type: JointType::Prismatic,
                axis: [0.8, 0.1, -0.2],
                pivot: [0.0; 3],
                state: vec![0.0, 0.1, 0.2],
                limits: [0.0, 0.2],
            },
        ];
        let root_motion = (0..k)
            .map(|t| {
                to_row_major(&DMat4::from_rotation_translation(
                    glam::DQuat::from_rotation_y(0.1 * t as f64),
                    DVec3::new(0.05 * t as f64, 0.0, 0.02),
                ))
            })
            .collect();
        let res = FitResult {
            format: FORMAT.into(),
            version: VERSION,
            frames: k,
            canonical_frame: 0,
            parts: 3,
            labels: vec![labels; k],
            poses: vec![vec![[0.0; 16]; 3]; k],
            gaussians: None,
            tree: Some(ResultTree {
                root: 0,
                parent: vec![-1, 0, 1],
            }),
            joints: Some(joints),
            root_motion: Some(root_motion),
            points: None,
            info: None,
        };
        // observed frames: the source moved by a slightly different chain + fresh noise
        let (m, mut x) = model_from_result(&res, true).unwrap();
        x[2] += 0.05;
        x[7] += 0.1;
        let frames = (0..k)
            .map(|t| {
                let p = m.poses(&x, t);
                pts.iter()
                    .zip(&res.labels[0])
                    .map(|(s, &l)| p[l as usize].transform_point3(s.as_dvec3()).as_vec3())
                    .collect()
            })
            .collect();
        (res, frames)
    }

    #[test]
    fn axis_prior_gradient_matches_finite_differences() {
        let (res, _) = toy();
        let (m, x0) = model_from_result(&res, true).unwrap();
        let mut x = x0.clone();
        for j in 0..m.types.len() {
            let b = m.joint_base(j);
            x[b] += 0.2;
            x[b + 1] -= 0.1;
            x[b + 2] *= 1.3; // not unit: the prior must see only the direction
        }
        let w = 0.7;
        let mut g = vec![0.0; m.len()];
        let p = axis_prior(&m, &x, &x0, w, &[], &mut g);
        assert!(p > 0.0);
        assert!(axis_prior(&m, &x0, &x0, w, &[], &mut vec![0.0; m.len()]) < 1e-12);
        let h = 1e-6;
        for i in 0..m.len() {
            let mut xp = x.clone();
            xp[i] += h;
            let mut xm = x.clone();
            xm[i] -= h;
            let mut scratch = vec![0.0; m.len()];
            let fd = (axis_prior(&m, &xp, &x0, w, &[], &mut scratch)
                - axis_prior(&m, &xm, &x0, w, &[], &mut scratch))
                / (2.0 * h);
            let err = (fd - g[i]).abs() / (1e-6 + fd.abs().max(g[i].abs()));
            assert!(err < 1e-5, "param {i}: fd {fd} analytic {}", g[i]);
        }
        // The toy's one hinge left free (`RefineOptions::free_axes`): no cost, no pull.
        let mut gf = vec![0.0; m.len()];
        assert_eq!(axis_prior(&m, &x, &x0, w, &[0], &mut gf), 0.0);
        assert!(gf.iter().all(|&v| v == 0.0));
    }

    #[test]
    fn gradient_matches_finite_differences() {
        let (res, frames) = toy();
        let (m, mut x) = model_from_result(&res, true).unwrap();
        // move root parameters away from 0 so the left Jacobian is exercised
        let rb = m.root_base(1);
        x[rb..rb + 6].copy_from_slice(&[0.01, -0.02, 0.03, 0.1, -0.2, 0.15]);
        let mut rng = StdRng::seed_from_u64(1);
        let d = build_data(&res, &frames, 1000, &mut rng);
        // a fixed matching of the first 40 points, as during the optimisation
        let mt = assign(&m, &x, &d, 40, 0.3, &mut Lap::default());
        assert!(mt
            .cols
            .iter()
            .enumerate()
            .all(|(t, c)| t == m.c || c.len() == 40));
        let mt = Some(&mt);
        let mut g = vec![0.0; m.len()];
        loss_grad(&m, &x, &d, mt, Some(&mut g), None);
        let h = 1e-4;
        let mut worst: f64 = 0.0;
        for i in 0..m.len() {
            let is_c_state = (0..2).any(|j| i == m.joint_base(j) + 6 + m.c);
            let is_c_root = i >= m.root_base(m.c) && i < m.root_base(m.c) + 6;
            let mut xp = x.clone();
            xp[i] += h;
            let mut xm = x.clone();
            xm[i] -= h;
            let fd = (loss_grad(&m, &xp, &d, mt, None, None)
                - loss_grad(&m, &xm, &d, mt, None, None))
                / (2.0 * h);
            if is_c_state || is_c_root {
                // the canonical frame has no loss term: both must be 0
                assert!(
                    fd.abs() < 1e-9 && g[i] == 0.0,
                    "param {i}: fd {fd} g {}",
                    g[i]
                );
                continue;
            }
            let err = (fd - g[i]).abs() / (1e-3 + fd.abs().max(g[i].abs()));
            worst = worst.max(err);
            assert!(err < 2e-3, "param {i}: fd {fd} analytic {}", g[i]);
        }
        assert!(worst < 2e-3);
    }

    #[test]
    fn refinement_lowers_the_loss_and_keeps_fk_consistent() {
        let (mut res, frames) = toy();
        let (m0, x0) = model_from_result(&res, true).unwrap();
        let before: Vec<Vec<DMat4>> = (0..3).map(|t| m0.poses(&x0, t)).collect();
        res.poses = before
            .iter()
            .map(|f| f.iter().map(to_row_major).collect())
            .collect();
        let opts = RefineOptions {
            iters: 200,
            sample: 60,
            ..Default::default()
        };
        let rep = refine(&mut res, &frames, &opts, 0.0, &mut |_| Control::Continue).unwrap();
        assert!(rep.accepted, "{rep:?}");
        assert!(rep.loss_after < 0.5 * rep.loss_before, "{rep:?}");
        let (m1, x1) = model_from_result(&res, true).unwrap();
        for t in 0..3 {
            let p = m1.poses(&x1, t);
            for (a, b) in p.iter().zip(&res.poses[t]) {
                assert!(a.abs_diff_eq(from_row_major(b), 1e-9));
            }
        }
    }

    /// Two legs hinged to a body about parallel axes (y), each leg a slab 0.4 long;
    /// the model starts with the legs' axes 6° off either way. Refined with the two
    /// joints tied, both axes come out exactly parallel and nearer y than they started.
    #[test]
    fn tied_axes_stay_parallel_through_the_refinement() {
        let k = 5;
        let mut rng = StdRng::seed_from_u64(9);
        let mut pts = Vec::new();
        let mut labels = Vec::new();
        for i in 0..900 {
            let part = i % 3;
            let u = Vec3::new(rng.random(), rng.random(), rng.random());
            let p = match part {
                0 => Vec3::new(0.6 * u.x - 0.3, 0.3 * u.y - 0.15, 0.1 * u.z),
                1 => Vec3::new(-0.3 + 0.05 * u.x, 0.1 * u.y - 0.05, -0.4 * u.z),
                _ => Vec3::new(0.25 + 0.05 * u.x, 0.1 * u.y - 0.05, -0.4 * u.z),
            };
            pts.push(p);
            labels.push(part as u32);
        }
        let hinge = |child: usize, x: f64, axis: DVec3, state: Vec<f64>| ResultJoint {
            mimic: None,
            child,
            parent: 0,
            joint_type: JointType::Revolute,
            axis: axis.to_array(),
            pivot: [x, 0.0, 0.0],
            state,
            limits: [-0.8, 0.8],
        };
        let states1: Vec<f64> = (0..k).map(|t| 0.35 * t as f64 - 0.7).collect();
        let states2: Vec<f64> = (0..k).map(|t| 0.7 - 0.3 * t as f64).collect();
        let zero = |s: &[f64]| s.iter().map(|q| q - s[0]).collect::<Vec<f64>>();
        let truth = [
            hinge(1, -0.275, DVec3::Y, zero(&states1)),
            hinge(2, 0.275, DVec3::Y, zero(&states2)),
        ];
        let tilt = |deg: f64| DVec3::new(deg.to_radians().lsin(), deg.to_radians().lcos(), 0.0);
        let start = [
            hinge(1, -0.275, tilt(6.0), zero(&states1)),
            hinge(2, 0.275, tilt(-6.0), zero(&states2)),
        ];
        let result = |joints: &[ResultJoint]| FitResult {
            format: FORMAT.into(),
            version: VERSION,
            frames: k,
            canonical_frame: 0,
            parts: 3,
            labels: vec![labels.clone(); k],
            poses: vec![vec![[0.0; 16]; 3]; k],
            gaussians: None,
            tree: Some(ResultTree {
                root: 0,
                parent: vec![-1, 0, 0],
            }),
            joints: Some(joints.to_vec()),
            root_motion: Some(vec![to_row_major(&DMat4::IDENTITY); k]),
            points: None,
            info: None,
        };
        let (m, x) = model_from_result(&result(&truth), false).unwrap();
        let frames: Vec<Vec<Vec3>> = (0..k)
            .map(|t| {
                let p = m.poses(&x, t);
                pts.iter()
                    .zip(&labels)
                    .map(|(s, &l)| p[l as usize].transform_point3(s.as_dvec3()).as_vec3())
                    .collect()
            })
            .collect();
        let mut res = result(&start);
        let opts = RefineOptions {
            root: false,
            ties: vec![vec![0, 1]],
            ..Default::default()
        };
        let rep = refine(&mut res, &frames, &opts, 0.0, &mut |_| Control::Continue).unwrap();
        assert!(rep.accepted, "{rep:?}");
        let js = res.joints.as_ref().unwrap();
        let (a, b) = (DVec3::from_array(js[0].axis), DVec3::from_array(js[1].axis));
        assert!(a.dot(b).abs() > 1.0 - 1e-12, "{a} vs {b}");
        let off = a.dot(DVec3::Y).abs().min(1.0).lacos().to_degrees();
        assert!(off < 2.0, "tied axis {off}° off y (started 6° off)");
    }
}
