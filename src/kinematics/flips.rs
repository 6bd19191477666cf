//! Half-turn flips of nearly symmetric parts (an addition to Step 2).
//!
//! Step 1's pose search can put a nearly symmetric link (a capsule-like forearm) half a
//! turn about one of its own axes in some frames: its points still land on its surface,
//! so the clouds barely tell the two poses apart, but the point correspondences — and
//! with them reconstruction and flow — are wrong, and the relative motion to its parent
//! no longer has one degree of freedom (bench-dev so101, seed 0: the lower arm 180° off
//! in frames 3–8, its hinge axis then 88° off). The kinematic chain tells the two poses
//! apart: relative to its parent, a link turns (or slides) along one fixed screw.
//!
//! Walking the tree from the root, each child's motion at each frame may be replaced by
//! its half-turn about one of its principal axes (through its centroid at the canonical
//! frame), polished by trimmed ICP as the reported poses are, when that pose fits the
//! frame's cloud about as well (`DATA_SLACK`). Which frames take it is decided by a consensus screw: every frame's
//! current relative motion to the parent proposes a screw, each proposal is scored over
//! all frames with the best variant per frame (the worst `OUTLIER_FRACTION` of frames
//! left out, as in the screw fit), and under the best one a frame switches when its
//! 1-DOF residual drops `SWITCH_GAIN`-fold from above `MIN_SWITCH_RESIDUAL`. The
//! switches are kept only when the child's full screw fit (`screw::fit_screw`) improves
//! `KEEP_GAIN`-fold. Parents are repaired before their children, so a child is judged
//! against its parent's repaired motion. Measured effects and the variants tried are in
//! the README ("Half-turn repair").

use glam::{DMat3, DMat4, DVec3, Vec3};
use nalgebra::{Matrix3, SymmetricEigen};

use super::observed::{points_by_part, trimmed_fit, POLISH_KEEP, POLISH_ROUNDS};
use super::project::bfs_order;
use super::screw::{
    fit_pivot, fit_screw, log_rotation, one_dof_loss, project_angle, PartExtent, OUTLIER_FRACTION,
};
use crate::fit::pose_init::trimmed_icp;
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
    /// The half-turn, a rigid map of the canonical frame.
    pub flip: DMat4,
}

/// Half-turns about the three principal axes of `pts` through their centroid.
fn half_turns(pts: &[DVec3]) -> Vec<DMat4> {
    let n = pts.len() as f64;
    let c = pts.iter().copied().sum::<DVec3>() / n;
    let mut m = Matrix3::<f64>::zeros();
    for p in pts {
        let d = *p - c;
        for i in 0..3 {
            for j in 0..3 {
                m[(i, j)] += d[i] * d[j];
            }
        }
    }
    let e = SymmetricEigen::new(m);
    (0..3)
        .map(|k| {
            let v = e.eigenvectors.column(k);
            let axis = DVec3::new(v[0], v[1], v[2]).normalize_or_zero();
            let r = DMat3::from_axis_angle(axis, std::f64::consts::PI);
            rigid(r, c - r * c)
        })
        .collect()
}

/// A screw proposed by one relative motion: (type, axis, pivot).
type Hypothesis = (JointType, DVec3, DVec3);

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

/// 1-DOF residual of relative motion `q` under a screw, at its best state.
fn residual(q: &DMat4, (jt, axis, pivot): Hypothesis) -> f64 {
    let s = match jt {
        JointType::Revolute => project_angle(axis, &DMat3::from_mat4(*q)),
        JointType::Prismatic => q.w_axis.truncate().dot(axis),
    };
    one_dof_loss(std::slice::from_ref(q), jt, axis, pivot, &[s])
}

/// Sum of `res` without its largest `OUTLIER_FRACTION`.
fn trimmed_sum(res: &mut [f64]) -> f64 {
    let drop = (res.len() as f64 * OUTLIER_FRACTION).floor() as usize;
    res.sort_by(|a, b| a.total_cmp(b));
    res[..res.len() - drop].iter().sum()
}

/// Repairs half-turn flips in `motions[t][p]` (frame `canonical` → t, at least two
/// frames), walking the tree `parent` from its root. `points`/`labels`: the canonical
/// frame's points and their parts; `frames[t]`: every frame's cloud; `extents[p]`: the
/// parts' centroids and radii (screw fits). Returns the replaced motions.
pub fn repair_flips(
    motions: &mut [Vec<DMat4>],
    parent: &[i64],
    canonical: usize,
    points: &[Vec3],
    labels: &[u32],
    frames: &[Vec<Vec3>],
    extents: &[PartExtent],
) -> Vec<Flip> {
    let parts = parent.len();
    let k = motions.len();
    let by_part = points_by_part(points, labels, parts);
    let grids: Vec<Option<Grid>> = frames
        .iter()
        .enumerate()
        .map(|(t, c)| (t != canonical && !c.is_empty()).then(|| Grid::new(c)))
        .collect();
    let mut flips = Vec::new();
    let (mut dst, mut buf) = (Vec::new(), Vec::new());
    for b in bfs_order(parent) {
        let Ok(a) = usize::try_from(parent[b]) else {
            continue;
        };
        let pts = &by_part[b];
        if pts.len() < MIN_POINTS || extents.len() <= b {
            continue;
        }
        let turns = half_turns(pts);
        // Per frame: (half-turn or None, motion, relative motion to the parent).
        let mut variants: Vec<Vec<(Option<DMat4>, DMat4, DMat4)>> = Vec::with_capacity(k);
        for (t, frame) in motions.iter().enumerate() {
            let cur = frame[b];
            let inv_a = rigid_inverse(&frame[a]);
            let mut v = vec![(None, cur, inv_a * cur)];
            if let (Some(grid), Some(cloud)) =
                (grids.get(t).and_then(Option::as_ref), frames.get(t))
            {
                let fit_now = trimmed_fit(grid, pts, &cur, POLISH_KEEP, &mut buf);
                for f in &turns {
                    let start = cur * *f;
                    let from = (DMat3::from_mat4(start), start.w_axis.truncate());
                    let (r, tr) = trimmed_icp(
                        grid,
                        |j| cloud[j].as_dvec3(),
                        pts,
                        from,
                        POLISH_ROUNDS,
                        POLISH_KEEP,
                        &mut dst,
                    );
                    let mo = rigid(r, tr);
                    if trimmed_fit(grid, pts, &mo, POLISH_KEEP, &mut buf) <= DATA_SLACK * fit_now {
                        v.push((Some(*f), mo, inv_a * mo));
                    }
                }
            }
            variants.push(v);
        }
        if variants.iter().all(|v| v.len() == 1) {
            continue;
        }
        let reference = extents[b].centre;
        let mut hyps = Vec::new();
        // Only current motions propose screws: a half-turned one would propose the
        // half-turn itself as the joint's motion (a symmetric panda finger "hinged"
        // half a turn in one frame explains that frame exactly).
        for (t, v) in variants.iter().enumerate() {
            if t != canonical {
                hypotheses(&v[0].2, reference, &mut hyps);
            }
        }
        let mut res = Vec::with_capacity(k);
        let score = |h: Hypothesis, res: &mut Vec<f64>| {
            res.clear();
            for (t, v) in variants.iter().enumerate() {
                if t != canonical {
                    res.push(
                        v.iter()
                            .map(|x| residual(&x.2, h))
                            .fold(f64::INFINITY, f64::min),
                    );
                }
            }
            trimmed_sum(res)
        };
        let Some(best) = hyps
            .iter()
            .map(|&h| (h, score(h, &mut res)))
            .min_by(|x, y| x.1.total_cmp(&y.1))
            .map(|x| x.0)
        else {
            continue;
        };
        // Each frame's variant under the consensus screw.
        let choice: Vec<usize> = variants
            .iter()
            .map(|v| {
                let r: Vec<f64> = v.iter().map(|x| residual(&x.2, best)).collect();
                let (j, rj) = r
                    .iter()
                    .enumerate()
                    .min_by(|x, y| x.1.total_cmp(y.1))
                    .map_or((0, 0.0), |(j, &rj)| (j, rj));
                if j > 0 && SWITCH_GAIN * rj < r[0] && r[0] > MIN_SWITCH_RESIDUAL {
                    j
                } else {
                    0
                }
            })
            .collect();
        if choice.iter().all(|&j| j == 0) {
            continue;
        }
        let rel = |pick: &dyn Fn(usize) -> usize| -> Vec<DMat4> {
            variants
                .iter()
                .enumerate()
                .map(|(t, v)| v[pick(t)].2)
                .collect()
        };
        let before = fit_screw(&rel(&|_| 0), extents[b]).loss;
        let after = fit_screw(&rel(&|t| choice[t]), extents[b]).loss;
        if KEEP_GAIN * after >= before {
            continue;
        }
        for (t, &j) in choice.iter().enumerate() {
            if let (true, (Some(f), mo, _)) = (j > 0, variants[t][j]) {
                motions[t][b] = mo;
                flips.push(Flip {
                    frame: t,
                    part: b,
                    flip: f,
                });
            }
        }
    }
    flips
}

#[cfg(test)]
mod tests {
    use super::*;

    fn turn(axis: DVec3, angle: f64, pivot: DVec3) -> DMat4 {
        let r = DMat3::from_axis_angle(axis.normalize(), angle);
        rigid(r, pivot - r * pivot)
    }

    /// A base box and a rod hinged on it; the rod has a small knob so it is only
    /// nearly symmetric about its long axis.
    fn scene() -> (Vec<Vec3>, Vec<u32>) {
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
                let a = j as f32 * std::f32::consts::TAU / 12.0;
                pts.push(Vec3::new(
                    0.03 * a.cos(),
                    0.03 * a.sin(),
                    0.12 + i as f32 * 0.0125,
                ));
                labels.push(1);
            }
        }
        for j in 0..6 {
            pts.push(Vec3::new(0.04, 0.0, 0.55 + j as f32 * 0.01));
            labels.push(1);
        }
        (pts, labels)
    }

    #[test]
    fn a_half_turned_link_is_put_back_on_its_hinge() {
        let (pts, labels) = scene();
        let hinge = |q: f64| turn(DVec3::Y, q, DVec3::new(0.0, 0.0, 0.12));
        let states = [0.0, 0.3, 0.6, 0.9, 1.1, 0.8, 0.5, 0.2];
        let truth: Vec<DMat4> = states.iter().map(|&q| hinge(q)).collect();
        let frames: Vec<Vec<Vec3>> = truth
            .iter()
            .map(|m| {
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
            .collect();
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
        let extents = vec![
            PartExtent::default(),
            PartExtent {
                centre: DVec3::new(0.0, 0.0, 0.37),
                radius: 0.15,
            },
        ];
        let flips = repair_flips(&mut motions, &[-1, 0], 0, &pts, &labels, &frames, &extents);
        let mut fixed: Vec<usize> = flips.iter().map(|f| f.frame).collect();
        fixed.sort_unstable();
        assert_eq!(fixed, vec![3, 4, 5, 6]);
        for (t, m) in truth.iter().enumerate() {
            let err = (motions[t][1] - *m)
                .to_cols_array()
                .iter()
                .fold(0.0f64, |a, v| a.max(v.abs()));
            assert!(err < 0.02, "frame {t}: {err}");
        }
        // Motions that already follow the hinge are left alone.
        let before = motions.clone();
        assert!(
            repair_flips(&mut motions, &[-1, 0], 0, &pts, &labels, &frames, &extents).is_empty()
        );
        assert_eq!(motions, before);
    }
}
