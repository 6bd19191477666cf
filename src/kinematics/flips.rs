//! Half-turn flips and spins of nearly symmetric parts (an addition to Step 2).
//!
//! Step 1's pose search can put a nearly symmetric link (a capsule-like forearm) half a
//! turn about one of its own axes in some frames: its points still land on its surface,
//! so the clouds barely tell the two poses apart, but the point correspondences — and
//! with them reconstruction and flow — are wrong, and the relative motion to its parent
//! no longer has one degree of freedom (bench-dev so101, seed 0: the lower arm 180° off
//! in frames 3–8, its hinge axis then 88° off). A link symmetric about an axis (a
//! capsule, a cylinder: the procedural quadruped's shanks) can take any turn about it
//! (quadruped seed 2: shanks up to 160° off, hinge axes up to 84° off). The kinematic
//! chain tells the poses apart: relative to its parent, a link turns (or slides) along
//! one fixed screw.
//!
//! Walking the tree from the root, each child's motion at each frame may be replaced by
//! its half-turn about one of its principal axes (through its centroid at the canonical
//! frame), polished by trimmed ICP as the reported poses are, when that pose fits the
//! frame's cloud about as well (`DATA_SLACK`); and, for a principal axis the part looks
//! the same about (`spin_axes`), by its turn about that axis that follows a given screw
//! (`spin_for`). Which frames take which is decided by a consensus screw: every frame's
//! current relative motion to the parent proposes a screw, and so does the cone traced
//! by a symmetry axis (`cone_hinge`, which its turns do not change; and the great
//! circle it follows, `great_circle_hinge`, preferred when it scores nearly as well,
//! since turns about the symmetry axis blur the scores); each proposal is
//! scored over all frames with the best variant per frame (the worst
//! `OUTLIER_FRACTION` of frames left out, as in the screw fit), and under the best one
//! a frame switches when its 1-DOF residual drops `SWITCH_GAIN`-fold from above
//! `MIN_SWITCH_RESIDUAL`. The switches are kept only when the child's full screw fit
//! (`screw::fit_screw`) improves `KEEP_GAIN`-fold. Parents are repaired before their
//! children, so a child is judged against its parent's repaired motion; the root,
//! which has no parent, is held still where it is still in most frames
//! (`still_root`). After its turns, each child's pose in every frame is searched
//! again along the consensus screw, and about its axis through the pivot the frames
//! that follow it agree on (`refit_pivot`, `joint_sweep`). Measured effects and the variants
//! tried are in docs/DEVELOPMENT.md ("Half-turn repair", "Joint sweep").

use crate::math::Libm;
use glam::{DMat3, DMat4, DVec3, Vec3};
use nalgebra::{Matrix3, SymmetricEigen};

use super::joint_sweep::sweep_child;
use super::observed::{points_by_part, polish_pose, trimmed_fit, POLISH_KEEP};
use super::project::bfs_order;
use super::screw::{
    dev_from_identity, fit_pivot, fit_screw, log_rotation, one_dof_loss, project_angle, PartExtent,
    OUTLIER_FRACTION,
};
use crate::geom::knn::Grid;
use crate::geom::se3::{rigid, rigid_inverse};
use crate::io::gt::JointType;

/// A half-turned pose may fit its frame's cloud (trimmed mean squared distance) this
/// many times worse than the current one and still be considered.
pub const DATA_SLACK: f64 = 1.5;
/// A frame takes a half-turned pose when its 1-DOF residual under the consensus
/// screw is this many times lower than the current pose's.
pub const SWITCH_GAIN: f64 = 4.0;
/// … and when its current residual is above this (‖R − I‖²_F of a 13° turn): below
/// it the current motion already follows the screw, and a half-turn about the joint's
/// own axis (a link spinning about its long axis) is as good by chance (xarm7's true
/// motions took one).
pub const MIN_SWITCH_RESIDUAL: f64 = 0.1;
/// The switches are kept when the child's L_1DOF drops this many times.
pub const KEEP_GAIN: f64 = 1.2;
/// Turns (degrees) a part must look the same under to count as symmetric about an
/// axis (a capsule, a cylinder): three, so a part with a few-fold symmetry does not.
const SPIN_PROBES: [f64; 3] = [40.0, 90.0, 135.0];
/// A part turned about a symmetry axis may fit itself this many times worse than it
/// fits the frames' clouds (self-fits of capsule-like links are 1–2.5 times their
/// cloud fits, other axes' 4–40 times on the procedural quadruped).
const SPIN_SLACK: f64 = 3.0;
/// Least spread (second eigenvalue of the axis images' scatter) for a cone fit.
const CONE_SPREAD: f64 = 1e-3;
/// A great-circle hinge (`great_circle_hinge`) needs the axis images within this
/// mean squared distance of a plane through the origin ((sin 5°)²) …
const GREAT_CIRCLE_MSE: f64 = 7.6e-3;
/// … and that distance below this share of their spread along the plane, so that
/// images bunched about one direction (a hinge along the symmetry axis) propose none.
const GREAT_CIRCLE_FLAT: f64 = 0.1;
/// The best great-circle hinge is the consensus when its score is within this factor
/// of the best score (see `great_circle_hinge`). Procedural quadruped, seed 0: the
/// legs' great circles scored 1.0–1.9× the best; on exact motions the best scores
/// about 0 and the great circle (its axis read from a sampled symmetry axis) does not
/// win.
const GREAT_CIRCLE_PREFERENCE: f64 = 2.0;
/// A refitted pivot closer than this share of the child's RMS radius to the proposed
/// one, across the axis, is the same hinge (`refit_pivot`).
const SAME_PIVOT: f64 = 0.25;
/// Parts with fewer canonical points are left alone (their axes are noise).
const MIN_POINTS: usize = 24;
/// Rotation (radians) below which a relative motion proposes no hinge axis.
const MIN_TURN: f64 = 0.1;
/// Translation (fit units) below which a relative motion proposes no slide axis.
const MIN_SLIDE: f64 = 1e-3;

/// One replaced motion: `motions[frame][part]` became (about) `old · flip`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Flip {
    pub frame: usize,
    pub part: usize,
    /// The rigid map of the canonical frame applied after the old motion: a half-turn,
    /// a turn about a symmetry axis, or the change to the swept pose.
    pub flip: DMat4,
    /// The new motion came from the sweep along the joint (`joint_sweep`), not from a
    /// turn.
    pub swept: bool,
}

/// Sets `motions[t][b]` to `mo`, which is the old motion followed by `flip` (a map of
/// the canonical frame), and returns the replacement.
pub(crate) fn replace(
    motions: &mut [Vec<DMat4>],
    (t, b): (usize, usize),
    mo: DMat4,
    flip: DMat4,
    swept: bool,
) -> Flip {
    motions[t][b] = mo;
    Flip {
        frame: t,
        part: b,
        flip,
        swept,
    }
}

/// Σ (p − mean)(p − mean)ᵀ over `pts`.
fn scatter(pts: &[DVec3], mean: DVec3) -> Matrix3<f64> {
    pts.iter().fold(Matrix3::zeros(), |m, p| {
        let d = *p - mean;
        let v = nalgebra::Vector3::new(d.x, d.y, d.z);
        m + v * v.transpose()
    })
}

/// Median of `v` (reordered); `v` must not be empty.
pub(crate) fn median(v: &mut [f64]) -> f64 {
    let mid = v.len() / 2;
    *v.select_nth_unstable_by(mid, |x, y| x.total_cmp(y)).1
}

/// Whether moving `pts` by `mo` fits a frame's cloud (`grid`; none: not measured)
/// within `DATA_SLACK` of `fit_now`, the current pose's fit.
fn fits_cloud(
    grid: Option<&Grid>,
    pts: &[DVec3],
    mo: &DMat4,
    fit_now: f64,
    buf: &mut Vec<f64>,
) -> bool {
    grid.is_some_and(|g| trimmed_fit(g, pts, mo, POLISH_KEEP, buf) <= DATA_SLACK * fit_now)
}

/// Centroid and unit principal axes of `pts`.
pub(crate) fn principal_axes(pts: &[DVec3]) -> (DVec3, [DVec3; 3]) {
    let c = pts.iter().copied().sum::<DVec3>() / pts.len() as f64;
    let e = SymmetricEigen::new(scatter(pts, c));
    let axis = |k: usize| {
        let v = e.eigenvectors.column(k);
        DVec3::new(v[0], v[1], v[2]).normalize_or_zero()
    };
    (c, [axis(0), axis(1), axis(2)])
}

/// The turn by `angle` about the line through `c` along unit `axis`.
pub(crate) fn turn_about(axis: DVec3, angle: f64, c: DVec3) -> DMat4 {
    let r = DMat3::from_axis_angle(axis, angle);
    rigid(r, c - r * c)
}

/// Half-turns about three principal axes through the centroid `c`.
fn half_turns(c: DVec3, axes: &[DVec3; 3]) -> Vec<DMat4> {
    axes.iter()
        .map(|&a| turn_about(a, std::f64::consts::PI, c))
        .collect()
}

/// Principal axes about which `pts` look the same at any turn: turned by each of
/// `SPIN_PROBES` they fit themselves (trimmed mean squared distance) within
/// `SPIN_SLACK` of `noise`, the part's typical fit to the frames' clouds.
pub(crate) fn spin_axes(pts: &[DVec3], c: DVec3, axes: &[DVec3; 3], noise: f64) -> Vec<DVec3> {
    let own = Grid::new(&pts.iter().map(|p| p.as_vec3()).collect::<Vec<_>>());
    let mut buf = Vec::new();
    axes.iter()
        .copied()
        .filter(|&a| {
            SPIN_PROBES.iter().all(|&deg: &f64| {
                let s = turn_about(a, deg.to_radians(), c);
                trimmed_fit(&own, pts, &s, POLISH_KEEP, &mut buf) <= SPIN_SLACK * noise
            })
        })
        .collect()
}

/// The hinge that carries a part's symmetry axis `a` (through `c`) as the relative
/// motions `rel` do, whatever the part's turn about that axis: the images `R a` lie
/// on a cone about the hinge axis, and the centroid's images (which the turn does
/// not move) fix the pivot. None when the images do not spread around a cone.
fn cone_hinge(rel: &[DMat4], a: DVec3, c: DVec3, reference: DVec3) -> Option<Hypothesis> {
    let b = axis_images(rel, a);
    if b.iter().all(|x| x.angle_between(a) < MIN_TURN) {
        return None;
    }
    let mean = b.iter().copied().sum::<DVec3>() / b.len() as f64;
    let e = SymmetricEigen::new(scatter(&b, mean));
    let mut idx = [0usize, 1, 2];
    idx.sort_by(|&i, &j| e.eigenvalues[i].total_cmp(&e.eigenvalues[j]));
    // The images must span a plane (a circle), not a line (two directions only).
    if e.eigenvalues[idx[1]] < CONE_SPREAD {
        return None;
    }
    let v = e.eigenvectors.column(idx[0]);
    hinge_about(rel, &b, DVec3::new(v[0], v[1], v[2]), a, c, reference)
}

/// The hinge that carries symmetry axis `a` about a great circle: its axis is normal
/// to the plane through the origin that the images `R a` lie in, as for a link across
/// its hinge (an elbow, a knee). None unless the images lie that flat
/// (`GREAT_CIRCLE_MSE`, `GREAT_CIRCLE_FLAT`).
///
/// Why it is needed, and preferred by `consensus`: a part symmetric about `a` may take
/// any turn about `a` (`spin_for`), so a hinge axis anywhere in the plane of the true
/// axis and `a` explains its motions about as well, and the scores cannot tell them
/// apart. Over a short swing the cone fit cannot either: the images trace a short arc
/// whose curvature is noise. Procedural quadruped, generator seed 0, fast: the
/// hind-left thigh swings 35° at most, and Step 1 also turned it 7–22° about its own
/// long axis. Its cone came out 37° off the hinge, with a score of 0.0042, while the
/// one hinge proposed within 4° of the truth scored 0.0091 (others, 15–22° off,
/// 0.0045–0.0085); the great circle reads only where `a` points, which the cloud
/// does show.
fn great_circle_hinge(rel: &[DMat4], a: DVec3, c: DVec3, reference: DVec3) -> Option<Hypothesis> {
    let b = axis_images(rel, a);
    // Two turned images at least, or one stray frame makes any set flat.
    if b.iter().filter(|x| x.angle_between(a) >= MIN_TURN).count() < 2 {
        return None;
    }
    let e = SymmetricEigen::new(scatter(&b, DVec3::ZERO));
    let mut idx = [0usize, 1, 2];
    idx.sort_by(|&i, &j| e.eigenvalues[i].total_cmp(&e.eigenvalues[j]));
    let (off, along) = (e.eigenvalues[idx[0]], e.eigenvalues[idx[1]]);
    if off > GREAT_CIRCLE_MSE * b.len() as f64 || off > GREAT_CIRCLE_FLAT * along {
        return None;
    }
    let v = e.eigenvectors.column(idx[0]);
    hinge_about(rel, &b, DVec3::new(v[0], v[1], v[2]), a, c, reference)
}

/// The images `R a` of axis `a` under the relative motions `rel`.
fn axis_images(rel: &[DMat4], a: DVec3) -> Vec<DVec3> {
    rel.iter().map(|q| DMat3::from_mat4(*q) * a).collect()
}

/// The hinge about axis direction `u` that turns `a` to its images `b` (one per
/// relative motion in `rel`), with the pivot fitted to the centroid `c`'s images
/// (which a turn about `a` does not move).
fn hinge_about(
    rel: &[DMat4],
    b: &[DVec3],
    u: DVec3,
    a: DVec3,
    c: DVec3,
    reference: DVec3,
) -> Option<Hypothesis> {
    let u = u.normalize_or_zero();
    let (mut rs, mut ts) = (Vec::new(), Vec::new());
    for (q, bt) in rel.iter().zip(b) {
        let r = DMat3::from_axis_angle(u, cone_angle(u, a, *bt)?);
        rs.push(r);
        ts.push(q.transform_point3(c) - r * c);
    }
    Some((JointType::Revolute, u, fit_pivot(&rs, &ts, reference)))
}

/// The turn about unit `u` taking `a`'s component across `u` to `b`'s; None when
/// either lies (almost) along `u`.
fn cone_angle(u: DVec3, a: DVec3, b: DVec3) -> Option<f64> {
    let (pa, pb) = (a - a.dot(u) * u, b - b.dot(u) * u);
    if pa.length() < 1e-3 || pb.length() < 1e-3 {
        return None;
    }
    Some(u.dot(pa.cross(pb)).latan2(pa.dot(pb)))
}

/// The turn about the symmetry axis `a` (through `c`) that brings relative motion
/// `q` closest to the screw `h`: the state is read off the axis image `R a`, which
/// the turn does not change. None when the screw cannot tell (its axis along `a`).
fn spin_for(q: &DMat4, (jt, axis, _): Hypothesis, a: DVec3, c: DVec3) -> Option<DMat4> {
    let rq = DMat3::from_mat4(*q);
    let target = match jt {
        JointType::Revolute => DMat3::from_axis_angle(axis, cone_angle(axis, a, rq * a)?),
        JointType::Prismatic => DMat3::IDENTITY,
    };
    Some(turn_about(
        a,
        project_angle(a, &(rq.transpose() * target)),
        c,
    ))
}

/// A frame's pose of a part: (the half-turn or spin applied, if any; the motion; the
/// relative motion to the parent).
type Variant = (Option<DMat4>, DMat4, DMat4);

/// A screw proposed by one relative motion: (type, axis, pivot).
pub(crate) type Hypothesis = (JointType, DVec3, DVec3);

/// Screws proposed by relative motion `q`: the hinge about its rotation axis (through
/// the point of it nearest `reference`) when it turns by more than `MIN_TURN`, and the
/// slide along its translation when that exceeds `MIN_SLIDE`.
fn hypotheses(q: &DMat4, reference: DVec3, out: &mut Vec<Hypothesis>) {
    let r = DMat3::from_mat4(*q);
    let t = q.w_axis.truncate();
    let w = log_rotation(&r);
    if w.length() > MIN_TURN {
        let axis = w.normalize();
        out.push((JointType::Revolute, axis, fit_pivot(&[r], &[t], reference)));
    }
    if t.length() > MIN_SLIDE {
        out.push((JointType::Prismatic, t.normalize(), reference));
    }
}

/// Hinge `h` with its pivot fitted again (`fit_pivot`, axis kept) over every frame
/// whose relative motion of child `b` to parent `a` follows it (residual below
/// `MIN_SWITCH_RESIDUAL`, a turn above `MIN_TURN`) and was not just switched; `None`
/// for a slide, with fewer than two such frames, or when the new pivot lies within
/// `SAME_PIVOT` of the child's RMS `radius` of the old one across the axis (sweeping
/// that hinge again finds the same poses: fast, the eight full `gsart bench`
/// sequences, steps 2–3 18.4 → 15.0 s; bench-dev full metrics within ±0.015).
///
/// The consensus screw is proposed by one frame, and its residual hardly weighs the
/// pivot (a pivot 0.05 off moves a 0.4 rad turn's child by 0.02, a squared residual
/// of 4e-4 against 0.015 for a 5° tilt of the axis), so its pivot can be as far off
/// as the one frame's pose noise allows: bench-dev so101 (full, balanced, seed 0),
/// the wrist's hinge proposed 0.05 off, the sweep along it then could not reach the
/// true pose in the three frames where the wrist was half a turn off. The pivot of
/// several frames is steadier; frames that were switched followed the proposal by
/// construction, so they are left out.
pub(crate) fn refit_pivot(
    motions: &[Vec<DMat4>],
    (a, b): (usize, usize),
    h: Hypothesis,
    switched: &[Flip],
    radius: f64,
) -> Option<Hypothesis> {
    let (jt, axis, pivot) = h;
    if jt != JointType::Revolute {
        return None;
    }
    let (mut rs, mut ts) = (Vec::new(), Vec::new());
    for (t, m) in motions.iter().enumerate() {
        if switched.iter().any(|f| f.frame == t) {
            continue;
        }
        let q = rigid_inverse(&m[a]) * m[b];
        let s = state_of(&q, h);
        if s.abs() > MIN_TURN && residual(&q, h) < MIN_SWITCH_RESIDUAL {
            rs.push(DMat3::from_axis_angle(axis, s));
            ts.push(q.w_axis.truncate());
        }
    }
    if rs.len() < 2 {
        return None;
    }
    // The residual hardly weighs translation, so a frame knocked off the hinge can
    // pass it: fitted again without the frames the first fit explains worst.
    let first = fit_pivot(&rs, &ts, pivot);
    let miss: Vec<f64> = rs
        .iter()
        .zip(&ts)
        .map(|(r, t)| ((DMat3::IDENTITY - *r) * first - *t).length_squared())
        .collect();
    let keep = super::screw::inliers(&miss);
    let (rs, ts): (Vec<DMat3>, Vec<DVec3>) = rs
        .iter()
        .zip(&ts)
        .zip(&keep)
        .filter(|x| *x.1)
        .map(|((r, t), _)| (*r, *t))
        .unzip();
    if rs.len() < 2 {
        return None;
    }
    let new = fit_pivot(&rs, &ts, pivot);
    let d = new - pivot;
    let across = (d - d.dot(axis) * axis).length();
    (across >= SAME_PIVOT * radius).then_some((jt, axis, new))
}

/// 1-DOF residual of relative motion `q` under a screw, at its best state.
fn residual(q: &DMat4, h: Hypothesis) -> f64 {
    let (jt, axis, pivot) = h;
    one_dof_loss(std::slice::from_ref(q), jt, axis, pivot, &[state_of(q, h)])
}

/// State of relative motion `q` along screw `h` (angle or slide).
pub(crate) fn state_of(q: &DMat4, (jt, axis, _): Hypothesis) -> f64 {
    match jt {
        JointType::Revolute => project_angle(axis, &DMat3::from_mat4(*q)),
        JointType::Prismatic => q.w_axis.truncate().dot(axis),
    }
}

/// Sum of `res` without its largest `OUTLIER_FRACTION`.
fn trimmed_sum(res: &mut [f64]) -> f64 {
    let drop = (res.len() as f64 * OUTLIER_FRACTION).floor() as usize;
    res.sort_by(|a, b| a.total_cmp(b));
    res[..res.len() - drop].iter().sum()
}

/// The root is the part that moves least (Step 2), and a half-turn or a turn about a
/// symmetry axis of it is invisible in the clouds: when the root is still in most
/// frames, a frame where it turned takes the variant (half-turn, or the turn about a
/// symmetry axis back to no rotation, if it fits the cloud: `fits_cloud`) that moves it
/// `SWITCH_GAIN` times less. A root that moves in most frames (a carried object) is
/// left alone. Writes the chosen motions and returns them as flips.
fn still_root(
    motions: &mut [Vec<DMat4>],
    b: usize,
    variants: &[Vec<Variant>],
    spins: &[DVec3],
    c: DVec3,
    canonical: usize,
    fits_cloud: &mut dyn FnMut(usize, &DMat4) -> bool,
) -> Vec<Flip> {
    let mut moved: Vec<f64> = variants
        .iter()
        .map(|v| dev_from_identity(&v[0].1))
        .collect();
    if median(&mut moved) > MIN_SWITCH_RESIDUAL {
        return Vec::new();
    }
    let still = (JointType::Prismatic, DVec3::Z, DVec3::ZERO);
    let mut out = Vec::new();
    for (t, v) in variants.iter().enumerate() {
        let cur = v[0].1;
        let d0 = dev_from_identity(&cur);
        if t == canonical || d0 <= MIN_SWITCH_RESIDUAL {
            continue;
        }
        let mut cands: Vec<(DMat4, DMat4)> = v[1..]
            .iter()
            .filter_map(|x| x.0.map(|f| (f, x.1)))
            .collect();
        for &s in spins {
            if let Some(f) = spin_for(&cur, still, s, c) {
                let mo = cur * f;
                if fits_cloud(t, &mo) {
                    cands.push((f, mo));
                }
            }
        }
        if let Some(&(f, mo)) = cands
            .iter()
            .min_by(|x, y| dev_from_identity(&x.1).total_cmp(&dev_from_identity(&y.1)))
        {
            if SWITCH_GAIN * dev_from_identity(&mo) < d0 {
                out.push(replace(motions, (t, b), mo, f, false));
            }
        }
    }
    out
}

/// Repairs half-turns and turns about symmetry axes (module doc) in `motions[t][p]`
/// (frame `canonical` → t, at least two frames), walking the tree `parent` from its
/// root. `points`/`labels`: the canonical frame's points and their parts; `frames[t]`:
/// every frame's cloud; `extents[p]`: the parts' centroids and radii (screw fits).
/// Returns the replaced motions.
pub fn repair_flips(
    motions: &mut [Vec<DMat4>],
    parent: &[i64],
    canonical: usize,
    points: &[Vec3],
    labels: &[u32],
    frames: &[Vec<Vec3>],
    extents: &[PartExtent],
) -> Vec<Flip> {
    Repair::new(canonical, points, labels, frames, parent.len()).run(motions, parent, extents)
}

/// The repair's data for one sequence, kept over repeated rounds (`repair_flips`
/// runs one round): the parts' canonical points, every frame's grid, and which
/// parent each child was last swept under (`joint_sweep`), so a round after the tree
/// changed sweeps only the children whose parent changed.
pub struct Repair<'a> {
    canonical: usize,
    frames: &'a [Vec<Vec3>],
    by_part: Vec<Vec<DVec3>>,
    grids: Vec<Option<Grid>>,
    swept_under: Vec<Option<usize>>,
}

impl<'a> Repair<'a> {
    pub fn new(
        canonical: usize,
        points: &[Vec3],
        labels: &[u32],
        frames: &'a [Vec<Vec3>],
        parts: usize,
    ) -> Self {
        Repair {
            canonical,
            frames,
            by_part: points_by_part(points, labels, parts),
            grids: frames
                .iter()
                .enumerate()
                .map(|(t, c)| (t != canonical && !c.is_empty()).then(|| Grid::new(c)))
                .collect(),
            swept_under: vec![None; parts],
        }
    }

    /// One round of the repair (`repair_flips`) under tree `parent`.
    pub fn run(
        &mut self,
        motions: &mut [Vec<DMat4>],
        parent: &[i64],
        extents: &[PartExtent],
    ) -> Vec<Flip> {
        let mut flips = Vec::new();
        let (mut dst, mut buf) = (Vec::new(), Vec::new());
        for b in bfs_order(parent) {
            // The root's motion is taken relative to the still world.
            let a = usize::try_from(parent[b]).ok();
            let pts = &self.by_part[b];
            if pts.len() < MIN_POINTS || extents.len() <= b {
                continue;
            }
            let part = PartFrames::new(
                motions,
                a,
                b,
                pts,
                self.frames,
                &self.grids,
                self.canonical,
                (&mut dst, &mut buf),
            );
            let Some(a) = a else {
                flips.extend(part.still_root(motions, b, &mut buf));
                continue;
            };
            let Some(best) = part.consensus(extents[b].centre, &mut buf) else {
                continue;
            };
            let switched = part.switch(motions, b, best, extents[b], &mut buf);
            // Then each frame's pose is searched again along the consensus screw, and
            // along it through the pivot the frames that follow it agree on, once per
            // parent.
            let sweep = self.swept_under[b] != Some(a);
            let screws: Vec<Hypothesis> = if sweep {
                let radius = extents[b].radius;
                std::iter::once(best)
                    .chain(refit_pivot(motions, (a, b), best, &switched, radius))
                    .collect()
            } else {
                Vec::new()
            };
            flips.extend(switched);
            if sweep {
                self.swept_under[b] = Some(a);
                flips.extend(sweep_child(
                    motions,
                    a,
                    b,
                    &screws,
                    pts,
                    self.frames,
                    &self.grids,
                    &mut dst,
                    &mut buf,
                ));
            }
        }
        flips
    }
}

/// One part's poses in a round of the repair: its canonical points (centroid `c`),
/// its symmetry axes, every frame's variants (the current pose first, then the
/// half-turns that fit the cloud) and the current pose's fit to each frame's cloud.
struct PartFrames<'r> {
    pts: &'r [DVec3],
    c: DVec3,
    spins: Vec<DVec3>,
    variants: Vec<Vec<Variant>>,
    fits: Vec<f64>,
    grids: &'r [Option<Grid>],
    canonical: usize,
}

impl<'r> PartFrames<'r> {
    /// Part `b`'s variants in every frame, relative to parent `a` (none: the world).
    #[allow(clippy::too_many_arguments)]
    fn new(
        motions: &[Vec<DMat4>],
        a: Option<usize>,
        b: usize,
        pts: &'r [DVec3],
        frames: &[Vec<Vec3>],
        grids: &'r [Option<Grid>],
        canonical: usize,
        (dst, buf): (&mut Vec<DVec3>, &mut Vec<f64>),
    ) -> Self {
        let k = motions.len();
        let (c, axes) = principal_axes(pts);
        let turns = half_turns(c, &axes);
        let mut variants: Vec<Vec<Variant>> = Vec::with_capacity(k);
        let mut fits = vec![f64::INFINITY; k];
        for (t, frame) in motions.iter().enumerate() {
            let cur = frame[b];
            let inv_a = a.map_or(DMat4::IDENTITY, |a| rigid_inverse(&frame[a]));
            let mut v = vec![(None, cur, inv_a * cur)];
            if let (Some(grid), Some(cloud)) =
                (grids.get(t).and_then(Option::as_ref), frames.get(t))
            {
                let fit_now = trimmed_fit(grid, pts, &cur, POLISH_KEEP, buf);
                fits[t] = fit_now;
                for f in &turns {
                    let mo = polish_pose(grid, cloud, pts, &(cur * *f), dst);
                    if fits_cloud(Some(grid), pts, &mo, fit_now, buf) {
                        v.push((Some(*f), mo, inv_a * mo));
                    }
                }
            }
            variants.push(v);
        }
        let mut measured: Vec<f64> = fits.iter().copied().filter(|f| f.is_finite()).collect();
        let spins = if measured.is_empty() {
            Vec::new()
        } else {
            spin_axes(pts, c, &axes, median(&mut measured))
        };
        PartFrames {
            pts,
            c,
            spins,
            variants,
            fits,
            grids,
            canonical,
        }
    }

    /// Whether pose `mo` fits frame `t`'s cloud about as well as the current pose.
    fn fits(&self, t: usize, mo: &DMat4, buf: &mut Vec<f64>) -> bool {
        fits_cloud(self.grids[t].as_ref(), self.pts, mo, self.fits[t], buf)
    }

    /// The root's repair (`still_root`).
    fn still_root(&self, motions: &mut [Vec<DMat4>], b: usize, buf: &mut Vec<f64>) -> Vec<Flip> {
        still_root(
            motions,
            b,
            &self.variants,
            &self.spins,
            self.c,
            self.canonical,
            &mut |t, mo| self.fits(t, mo, buf),
        )
    }

    /// Frame `t`'s candidates under screw `h`: its variants, and its turn about each
    /// symmetry axis that follows `h` (when it still fits the cloud).
    fn candidates(&self, t: usize, h: Hypothesis, out: &mut Vec<Variant>, buf: &mut Vec<f64>) {
        out.clear();
        out.extend_from_slice(&self.variants[t]);
        let (cur, rel) = (self.variants[t][0].1, self.variants[t][0].2);
        for &s in &self.spins {
            if let Some(f) = spin_for(&rel, h, s, self.c) {
                let mo = cur * f;
                if self.fits(t, &mo, buf) {
                    out.push((Some(f), mo, rel * f));
                }
            }
        }
    }

    /// The relative motions to the parent, as they are.
    fn current(&self) -> Vec<DMat4> {
        self.variants.iter().map(|v| v[0].2).collect()
    }

    /// The consensus screw: of the screws the current relative motions (and the cones
    /// of the symmetry axes) propose, the one with the least trimmed sum over the
    /// frames of the best candidate's residual. `reference`: the part's centre.
    fn consensus(&self, reference: DVec3, buf: &mut Vec<f64>) -> Option<Hypothesis> {
        let mut hyps = Vec::new();
        // Only current motions propose screws: a half-turned one would propose the
        // half-turn itself as the joint's motion (a symmetric panda finger "hinged"
        // half a turn in one frame explains that frame exactly). A part symmetric
        // about an axis also proposes the hinge its axis follows.
        for (t, v) in self.variants.iter().enumerate() {
            if t != self.canonical {
                hypotheses(&v[0].2, reference, &mut hyps);
            }
        }
        let current = self.current();
        hyps.extend(
            self.spins
                .iter()
                .filter_map(|&s| cone_hinge(&current, s, self.c, reference)),
        );
        // The great circles come last, so they are the tail of `scored` below.
        let first_circle = hyps.len();
        hyps.extend(
            self.spins
                .iter()
                .filter_map(|&s| great_circle_hinge(&current, s, self.c, reference)),
        );
        let (mut res, mut cand) = (Vec::with_capacity(self.variants.len()), Vec::new());
        let mut score = |h: Hypothesis| {
            res.clear();
            for t in 0..self.variants.len() {
                if t != self.canonical {
                    self.candidates(t, h, &mut cand, buf);
                    res.push(
                        cand.iter()
                            .map(|x| residual(&x.2, h))
                            .fold(f64::INFINITY, f64::min),
                    );
                }
            }
            trimmed_sum(&mut res)
        };
        let scored: Vec<(Hypothesis, f64)> = hyps.iter().map(|&h| (h, score(h))).collect();
        let least = |x: &&(Hypothesis, f64), y: &&(Hypothesis, f64)| x.1.total_cmp(&y.1);
        let best = scored.iter().min_by(least)?;
        let circle = scored[first_circle..].iter().min_by(least);
        match circle {
            Some(g) if g.1 <= GREAT_CIRCLE_PREFERENCE * best.1 => Some(g.0),
            _ => Some(best.0),
        }
    }

    /// Under the consensus screw `best`, each frame takes the candidate with the
    /// least residual when it lowers the current one `SWITCH_GAIN`-fold from above
    /// `MIN_SWITCH_RESIDUAL`; the switches are written to `motions[t][b]` when they
    /// lower the child's screw fit `KEEP_GAIN`-fold. Returns them.
    fn switch(
        &self,
        motions: &mut [Vec<DMat4>],
        b: usize,
        best: Hypothesis,
        extent: PartExtent,
        buf: &mut Vec<f64>,
    ) -> Vec<Flip> {
        let mut cand = Vec::new();
        let chosen: Vec<Variant> = (0..self.variants.len())
            .map(|t| {
                self.candidates(t, best, &mut cand, buf);
                let r: Vec<f64> = cand.iter().map(|x| residual(&x.2, best)).collect();
                let (j, rj) = r
                    .iter()
                    .enumerate()
                    .min_by(|x, y| x.1.total_cmp(y.1))
                    .map_or((0, 0.0), |(j, &rj)| (j, rj));
                if t != self.canonical
                    && j > 0
                    && SWITCH_GAIN * rj < r[0]
                    && r[0] > MIN_SWITCH_RESIDUAL
                {
                    cand[j]
                } else {
                    cand[0]
                }
            })
            .collect();
        let keep = !chosen.iter().all(|x| x.0.is_none()) && {
            let before = fit_screw(&self.current(), extent).loss;
            let after_rel: Vec<DMat4> = chosen.iter().map(|x| x.2).collect();
            KEEP_GAIN * fit_screw(&after_rel, extent).loss < before
        };
        if !keep {
            return Vec::new();
        }
        chosen
            .iter()
            .enumerate()
            .filter_map(|(t, x)| x.0.map(|f| replace(motions, (t, b), x.1, f, false)))
            .collect()
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    pub(crate) fn turn(axis: DVec3, angle: f64, pivot: DVec3) -> DMat4 {
        let r = DMat3::from_axis_angle(axis.normalize(), angle);
        rigid(r, pivot - r * pivot)
    }

    /// A base box and a rod hinged on it; the rod has a small knob so it is only
    /// nearly symmetric about its long axis.
    fn scene() -> (Vec<Vec3>, Vec<u32>) {
        scene_sampled(None)
    }

    /// `scene` with the rod's points drawn at random (`seed`; none: on a regular grid),
    /// as an independent sample of the same surface.
    pub(crate) fn scene_sampled(seed: Option<u64>) -> (Vec<Vec3>, Vec<u32>) {
        use rand::{Rng, SeedableRng};
        let mut rng = seed.map(rand::rngs::SmallRng::seed_from_u64);
        let mut pts = Vec::new();
        let mut labels = Vec::new();
        for i in 0..10 {
            for j in 0..10 {
                for z in [0.0, 0.1] {
                    pts.push(Vec3::new(i as f32 * 0.04 - 0.2, j as f32 * 0.04 - 0.2, z));
                    labels.push(0);
                }
            }
        }
        // Rod along +z from (0, 0, 0.12), radius 0.03, length 0.5.
        for i in 0..40 {
            for j in 0..12 {
                let (a, z) = match rng.as_mut() {
                    Some(r) => (
                        r.random::<f32>() * std::f32::consts::TAU,
                        r.random::<f32>() * 0.4875,
                    ),
                    None => (j as f32 * std::f32::consts::TAU / 12.0, i as f32 * 0.0125),
                };
                pts.push(Vec3::new(0.03 * a.lcos(), 0.03 * a.lsin(), 0.12 + z));
                labels.push(1);
            }
        }
        for j in 0..6 {
            pts.push(Vec3::new(0.04, 0.0, 0.55 + j as f32 * 0.01));
            labels.push(1);
        }
        (pts, labels)
    }

    /// Frame `t`'s cloud: `sample(t)` with the rod moved by `truth[t]`.
    pub(crate) fn posed(
        truth: &[DMat4],
        sample: impl Fn(usize) -> (Vec<Vec3>, Vec<u32>),
    ) -> Vec<Vec<Vec3>> {
        truth
            .iter()
            .enumerate()
            .map(|(t, m)| {
                let (pts, labels) = sample(t);
                pts.iter()
                    .zip(&labels)
                    .map(|(x, &l)| {
                        if l == 0 {
                            *x
                        } else {
                            m.transform_point3(x.as_dvec3()).as_vec3()
                        }
                    })
                    .collect()
            })
            .collect()
    }

    /// Every frame's rod motion within 0.02 (largest matrix entry) of the truth.
    fn assert_on_truth(motions: &[Vec<DMat4>], truth: &[DMat4]) {
        for (t, m) in truth.iter().enumerate() {
            let err = (motions[t][1] - *m)
                .to_cols_array()
                .iter()
                .fold(0.0f64, |a, v| a.max(v.abs()));
            assert!(err < 0.02, "frame {t}: {err}");
        }
    }

    /// The base's and the rod's extents for the screw fits.
    pub(crate) fn rod_extents() -> Vec<PartExtent> {
        vec![
            PartExtent::default(),
            PartExtent {
                centre: DVec3::new(0.0, 0.0, 0.37),
                radius: 0.15,
            },
        ]
    }

    #[test]
    fn the_pivot_is_fitted_again_over_the_frames_that_follow_the_hinge() {
        let pivot = DVec3::new(0.0, 0.0, 0.12);
        let hinge = |q: f64| turn(DVec3::Y, q, pivot);
        let states = [0.0, 0.3, 0.6, 0.9, 1.1, 0.8, 0.5, 0.2];
        let mut motions: Vec<Vec<DMat4>> = states
            .iter()
            .map(|&q| vec![DMat4::IDENTITY, hinge(q)])
            .collect();
        // Frame 5 was just switched and frame 2 turns about another axis: neither
        // counts. Frame 6 is knocked off the hinge by less than the residual notices:
        // the second fit leaves it out.
        motions[5][1] = DMat4::from_translation(DVec3::new(0.3, 0.0, 0.0)) * hinge(0.8);
        motions[2][1] = turn(DVec3::X, 0.6, DVec3::ZERO);
        motions[6][1] = DMat4::from_translation(DVec3::new(0.08, 0.0, 0.0)) * hinge(0.5);
        let switched = [Flip {
            frame: 5,
            part: 1,
            flip: DMat4::IDENTITY,
            swept: false,
        }];
        // Proposed 0.05 off the pivot across the axis (and 0.2 along it, which stays).
        let proposed = pivot + DVec3::new(0.05, 0.2, -0.03);
        let h = (JointType::Revolute, DVec3::Y, proposed);
        let radius = 0.15;
        let (jt, axis, p) = refit_pivot(&motions, (0, 1), h, &switched, radius).unwrap();
        assert_eq!((jt, axis), (JointType::Revolute, DVec3::Y));
        assert!((p - DVec3::new(0.0, 0.2, 0.12)).length() < 1e-9, "{p}");
        // A slide keeps its screw, and so does a hinge followed by one frame only, or
        // one proposed within a quarter of the child's radius of its pivot.
        let slide = (JointType::Prismatic, DVec3::X, proposed);
        assert!(refit_pivot(&motions, (0, 1), slide, &[], radius).is_none());
        assert!(refit_pivot(&motions[..2], (0, 1), h, &[], radius).is_none());
        let near = (
            JointType::Revolute,
            DVec3::Y,
            pivot + DVec3::new(0.03, 0.2, 0.0),
        );
        assert!(refit_pivot(&motions, (0, 1), near, &switched, radius).is_none());
    }

    #[test]
    fn a_half_turned_link_is_put_back_on_its_hinge() {
        let (pts, labels) = scene();
        let hinge = |q: f64| turn(DVec3::Y, q, DVec3::new(0.0, 0.0, 0.12));
        let states = [0.0, 0.3, 0.6, 0.9, 1.1, 0.8, 0.5, 0.2];
        let truth: Vec<DMat4> = states.iter().map(|&q| hinge(q)).collect();
        let frames = posed(&truth, |_| (pts.clone(), labels.clone()));
        // Frames 3–6 flipped half a turn about the rod's own axis.
        let spin = turn(DVec3::Z, std::f64::consts::PI, DVec3::ZERO);
        let mut motions: Vec<Vec<DMat4>> = truth
            .iter()
            .enumerate()
            .map(|(t, m)| {
                let m = if (3..=6).contains(&t) { *m * spin } else { *m };
                vec![DMat4::IDENTITY, m]
            })
            .collect();
        let extents = rod_extents();
        let flips = repair_flips(&mut motions, &[-1, 0], 0, &pts, &labels, &frames, &extents);
        let mut fixed: Vec<usize> = flips.iter().map(|f| f.frame).collect();
        fixed.sort_unstable();
        assert_eq!(fixed, vec![3, 4, 5, 6]);
        assert_on_truth(&motions, &truth);
        // Motions that already follow the hinge are left alone.
        let before = motions.clone();
        assert!(
            repair_flips(&mut motions, &[-1, 0], 0, &pts, &labels, &frames, &extents).is_empty()
        );
        assert_eq!(motions, before);
    }

    /// The rod hinged about y at `states`, its motions also turned about its own axis
    /// by `spins`; every frame samples the rod afresh (from `seed`), as a scanner would.
    struct SpunRod {
        pts: Vec<Vec3>,
        labels: Vec<u32>,
        truth: Vec<DMat4>,
        frames: Vec<Vec<Vec3>>,
        motions: Vec<Vec<DMat4>>,
    }

    fn spun_rod(seed: u64, states: &[f64], spins: &[f64]) -> SpunRod {
        let (pts, labels) = scene_sampled(Some(seed));
        let hinge = |q: f64| turn(DVec3::Y, q, DVec3::new(0.0, 0.0, 0.12));
        let truth: Vec<DMat4> = states.iter().map(|&q| hinge(q)).collect();
        let frames = posed(&truth, |t| scene_sampled(Some(seed + t as u64)));
        let motions = truth
            .iter()
            .zip(spins)
            .map(|(m, &s)| vec![DMat4::IDENTITY, *m * turn(DVec3::Z, s, DVec3::ZERO)])
            .collect();
        SpunRod {
            pts,
            labels,
            truth,
            frames,
            motions,
        }
    }

    #[test]
    fn a_spun_rod_is_turned_back_onto_its_hinge() {
        // The rod (nearly symmetric: its knob is a tenth of a percent of its points)
        // turned about its own axis by an arbitrary angle in every frame: only the
        // hinge tells the turns apart.
        let states = [0.0, 0.3, 0.6, 0.9, 1.1, 0.8, 0.5, 0.2];
        let spins = [0.0, 1.0, -2.0, 2.8, 0.5, -1.2, 1.7, -0.6];
        let SpunRod {
            pts,
            labels,
            truth,
            frames,
            mut motions,
        } = spun_rod(100, &states, &spins);
        let extents = rod_extents();
        let before = fit_screw(
            &motions.iter().map(|m| m[1]).collect::<Vec<_>>(),
            extents[1],
        );
        let flips = repair_flips(&mut motions, &[-1, 0], 0, &pts, &labels, &frames, &extents);
        let mut fixed: Vec<usize> = flips.iter().map(|f| f.frame).collect();
        fixed.sort_unstable();
        assert_eq!(fixed, (1..8).collect::<Vec<_>>());
        assert_on_truth(&motions, &truth);
        let after = fit_screw(
            &motions.iter().map(|m| m[1]).collect::<Vec<_>>(),
            extents[1],
        );
        assert!(
            after.axis.cross(DVec3::Y).length() < 0.01,
            "axis {}",
            after.axis
        );
        assert!(
            after.loss < 1e-3 * before.loss,
            "{} vs {}",
            after.loss,
            before.loss
        );
    }

    #[test]
    fn a_rod_spun_on_a_short_swing_keeps_its_hinge_axis() {
        // As Step 1 leaves a capsule-like leg: a short swing (at most 0.35 rad) and, in
        // every frame, a turn about the rod's own axis. Over such a short arc a turn
        // about the rod's axis mixes into any hinge axis between it and the true one
        // (53° off here without the great circle); the hinge that carries the rod's
        // axis about a great circle does not.
        let states = [0.0, 0.1, 0.2, 0.3, 0.35, 0.25, 0.15, 0.05];
        let spins = [0.0, 0.3, -0.4, 0.35, 0.5, -0.3, 0.45, -0.35];
        let SpunRod {
            pts,
            labels,
            frames,
            mut motions,
            ..
        } = spun_rod(700, &states, &spins);
        let extents = rod_extents();
        repair_flips(&mut motions, &[-1, 0], 0, &pts, &labels, &frames, &extents);
        let after = fit_screw(
            &motions.iter().map(|m| m[1]).collect::<Vec<_>>(),
            extents[1],
        );
        let deg = after.axis.cross(DVec3::Y).length().lasin().to_degrees();
        assert!(deg < 2.0, "axis {} is {deg}° off", after.axis);
    }

    #[test]
    fn a_great_circle_needs_images_that_spread_flat() {
        let a = DVec3::Z;
        let c = DVec3::new(0.0, 0.0, 0.3);
        let about = |axis: DVec3, qs: &[f64]| -> Vec<DMat4> {
            qs.iter().map(|&q| turn(axis, q, DVec3::ZERO)).collect()
        };
        // A swing about y carries z about the great circle across y.
        let swing = about(DVec3::Y, &[0.0, 0.1, 0.2, 0.3, 0.2]);
        let (jt, u, _) = great_circle_hinge(&swing, a, c, c).unwrap();
        assert_eq!(jt, JointType::Revolute);
        assert!(u.cross(DVec3::Y).length() < 1e-9, "{u}");
        // A hinge along the symmetry axis, wobbling a little, proposes none: one stray
        // frame, or several in all directions. Nor does a hinge slanted to it (a small
        // circle).
        let mut roll = about(DVec3::Z, &[0.0, 1.0, 2.0, 3.0]);
        roll.push(turn(DVec3::X, 0.12, DVec3::ZERO));
        assert!(great_circle_hinge(&roll, a, c, c).is_none());
        roll.push(turn(DVec3::Y, 0.15, DVec3::ZERO));
        roll.push(turn(
            DVec3::new(1.0, -1.0, 0.0).normalize(),
            0.13,
            DVec3::ZERO,
        ));
        assert!(great_circle_hinge(&roll, a, c, c).is_none());
        let slant = DVec3::new(0.0, 1.0, 1.0).normalize();
        let cone = about(slant, &[0.0, 0.5, 1.0, 1.5, 2.0]);
        assert!(great_circle_hinge(&cone, a, c, c).is_none());
    }

    #[test]
    fn a_still_root_turned_half_a_turn_is_put_back() {
        // The base (a grid the same under a half-turn about its vertical axis) still,
        // the rod on its hinge; the base's Step-1 pose half a turn off in frames 2 and 5.
        let (pts, labels) = scene();
        let hinge = |q: f64| turn(DVec3::Y, q, DVec3::new(0.0, 0.0, 0.12));
        let states = [0.0, 0.3, 0.6, 0.9, 1.1, 0.8, 0.5, 0.2];
        let truth: Vec<DMat4> = states.iter().map(|&q| hinge(q)).collect();
        let frames = posed(&truth, |_| (pts.clone(), labels.clone()));
        let flip = turn(
            DVec3::Z,
            std::f64::consts::PI,
            DVec3::new(-0.02, -0.02, 0.05),
        );
        let mut motions: Vec<Vec<DMat4>> = truth
            .iter()
            .enumerate()
            .map(|(t, m)| {
                let base = if t == 2 || t == 5 {
                    flip
                } else {
                    DMat4::IDENTITY
                };
                vec![base, *m]
            })
            .collect();
        let extents = rod_extents();
        let flips = repair_flips(&mut motions, &[-1, 0], 0, &pts, &labels, &frames, &extents);
        let mut fixed: Vec<(usize, usize)> = flips.iter().map(|f| (f.part, f.frame)).collect();
        fixed.sort_unstable();
        assert_eq!(fixed, vec![(0, 2), (0, 5)]);
        for (t, m) in motions.iter().enumerate() {
            assert!(
                dev_from_identity(&m[0]) < 1e-4,
                "frame {t}: base {:?}",
                m[0]
            );
        }
        assert_on_truth(&motions, &truth);
        // A root that moves in most frames is left alone.
        let mut moving: Vec<Vec<DMat4>> = truth
            .iter()
            .enumerate()
            .map(|(t, m)| {
                let base = if t == 0 { DMat4::IDENTITY } else { flip };
                vec![base, base * *m]
            })
            .collect();
        let frames = posed(&moving.iter().map(|m| m[1]).collect::<Vec<_>>(), |_| {
            (pts.clone(), labels.clone())
        });
        let frames: Vec<Vec<Vec3>> = frames
            .iter()
            .enumerate()
            .map(|(t, f)| {
                f.iter()
                    .zip(&labels)
                    .map(|(x, &l)| {
                        if l == 0 {
                            moving[t][0].transform_point3(x.as_dvec3()).as_vec3()
                        } else {
                            *x
                        }
                    })
                    .collect()
            })
            .collect();
        assert!(
            repair_flips(&mut moving, &[-1, 0], 0, &pts, &labels, &frames, &extents).is_empty()
        );
    }
}
