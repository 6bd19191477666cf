//! Spin-free hinges for rotationally symmetric parts (an addition to Step 3).
//!
//! A part that looks the same at any turn about one of its own axes `u` (a
//! capsule, a cylinder: the procedural quadruped's shanks) shows in each frame only
//! where `u` points and where its centre is; a turn about `u` moves its points along
//! its own surface. Step 1's poses carry such turns at random, and the hinge fitted to
//! them comes out tilted towards `u`: a turn about the tilted axis swings `u` nearly as
//! the true hinge does and adds a spin the clouds cannot see (procedural quadruped,
//! generator seed 1: three shanks' axes 22–48° off at pivot errors below 2, with a
//! reconstruction error of 0.32). Over a swing of half a radian the two hinges put the
//! part's far end less than a point spacing apart, so the clouds do not decide.
//!
//! The hinge perpendicular to `u` that carries `u` through the same directions is the
//! one that adds no invisible spin: its axis is the normal of the plane the images of
//! `u` span (made exactly perpendicular to `u`), its states the turns of `u` within
//! that plane, and its pivot the point that carries the part's centre where the fitted
//! joint does (`screw::fit_pivot`). It replaces a hinge tilted at least
//! `MIN_TILT_DEG` towards `u` when the part and its descendants fit the frames' clouds
//! (trimmed, as `observed::trimmed_fit`) within a slack of it; the part's children keep
//! their motion, their joints fitted again. `kinematics::build` then refines the model
//! once more and keeps the change only if it still fits (`KEEP_SLACK`).

use glam::{DMat4, DVec3, Vec3};
use nalgebra::{Matrix3, SymmetricEigen, Vector3};

use super::chain::screw_exp;
use super::flips::{median, principal_axes, spin_axes};
use super::observed::{points_by_part, trimmed_fit, POLISH_KEEP};
use super::project::bfs_order;
use super::screw::{
    fit_prismatic, fit_revolute, padded_limits, pivot_carrying, turns_carrying, unwrap_angles,
};
use crate::geom::knn::Grid;
use crate::geom::se3::{from_row_major, rigid_inverse, to_row_major};
use crate::io::gt::JointType;
use crate::io::result::{FitResult, ResultJoint};

/// A spin-free hinge is proposed when its summed trimmed fit to the clouds is at most
/// this many times the fitted hinge's (before the refinement polishes its pivot and
/// states): a pre-filter, since the hinge it replaces was refined and the poses turned
/// to follow it, so a hinge turned by up to 90° starts behind. Procedural quadruped,
/// generator seed 5: a thigh hinged along its own long axis (88° off) had a spin-free
/// proposal at 1.52×, refused at the former 1.5. Generator seeds 0–7, fast: 3 (or 10)
/// against 1.5 gave mean axis errors 9.2° against 12.6° (seed 5's four leg joints 88,
/// 81, 55, 63° → 59, 12, 8, 13°), reconstruction 0.442 against 0.456; bench-dev full
/// fast seeds 0–1 within 0.008 on every metric, joints in the bar 34 → 35 ...
pub const PROPOSE_SLACK: f64 = 3.0;
/// ... and kept when, after that refinement, its fit is at most this many times the
/// fitted hinge's.
pub const KEEP_SLACK: f64 = 1.25;
/// Least turn (radians) of the symmetry axis's images for a plane to be fitted.
const MIN_TURN: f64 = 0.1;
/// Least spread of the images along their plane (middle eigenvalue of their scatter
/// over the number of frames).
const MIN_SPREAD: f64 = 1e-3;
/// A hinge already within this angle (radians, 1°) of the spin-free one is left alone.
const SAME_AXIS: f64 = 0.0175;
/// Only a hinge tilted at least this far (degrees) from the plane perpendicular to
/// the symmetry axis is replaced: a spin that large is Step 1's artefact, while a
/// smaller tilt is as often the real hinge seen through a noisy segmentation
/// (bench-dev full solo12, fast, seed 0: with tilts of 5–10° taken away, axes went
/// 3.3 → 11.7°, 4.5 → 5.6° and 6.1 → 11.1°).
const MIN_TILT_DEG: f64 = 15.0;
/// Parts with fewer canonical points are left alone.
const MIN_POINTS: usize = 24;

/// One replaced hinge, for the report.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct SpinFree {
    pub child: usize,
    /// Angle (degrees) between the fitted and the spin-free axis.
    pub turned_deg: f64,
    /// Summed trimmed fits to the clouds, fitted and spin-free hinge.
    pub fit_before: f64,
    pub fit_after: f64,
}

/// Replaces the hinge of every revolute joint whose child (one that `only` lets
/// through) is symmetric about one of its axes by the spin-free hinge, where that fits
/// the clouds `points` (`grids`: theirs) within `slack` of the fitted one, summed over
/// the child and its descendants. A child's own children keep their motion in the
/// world: their joints are fitted again (`screw::fit_revolute`, `fit_prismatic`) to
/// their motion relative to the child's new one, so the turn the child loses, which
/// only they showed, comes out of their joints. Parents go first. Updates axes,
/// pivots, states, limits (padded by `limit_pad`) and the subtree's poses.
pub fn spin_free_hinges(
    result: &mut FitResult,
    points: &[Vec<Vec3>],
    grids: &[Grid],
    limit_pad: f64,
    slack: f64,
    only: &dyn Fn(usize) -> bool,
) -> Vec<SpinFree> {
    let c = result.canonical_frame;
    let Some(tree) = result.tree.as_ref() else {
        return Vec::new();
    };
    let parent = tree.parent.clone();
    let k = result.poses.len().min(points.len()).min(grids.len());
    let parts = result.parts;
    if c >= k || result.labels.len() <= c || parent.len() != parts || result.joints.is_none() {
        return Vec::new();
    }
    let by_part = points_by_part(&points[c], &result.labels[c], parts);
    let mut poses: Vec<Vec<DMat4>> = result.poses[..k]
        .iter()
        .map(|f| f.iter().map(from_row_major).collect())
        .collect();
    let mut joints = result.joints.clone().unwrap_or_default();
    let mut buf = Vec::new();
    let mut changes = Vec::new();
    for ch in bfs_order(&parent) {
        let Some(ji) = joints.iter().position(|j| j.child == ch) else {
            continue;
        };
        let jt = &joints[ji];
        let pa = jt.parent;
        if jt.joint_type != JointType::Revolute
            || pa >= parts
            || !only(ch)
            || by_part[ch].len() < MIN_POINTS
        {
            continue;
        }
        let sub = subtree(&parent, ch);
        let pts = &by_part[ch];
        let (axis, pivot) = (DVec3::from(jt.axis), DVec3::from(jt.pivot));
        let mut own: Vec<f64> = (0..k)
            .map(|t| trimmed_fit(&grids[t], pts, &poses[t][ch], POLISH_KEEP, &mut buf))
            .collect();
        let (cen, axes) = principal_axes(pts);
        let sym = spin_axes(pts, cen, &axes, median(&mut own));
        let [u] = sym.as_slice() else {
            continue; // not symmetric, or about several axes (a ball)
        };
        let rel: Vec<DMat4> = (0..k)
            .map(|t| screw_exp(JointType::Revolute, axis, pivot, jt.state[t]))
            .collect();
        let Some((mut a2, p2, mut s2)) = spin_free(&rel, *u, cen, c, pivot) else {
            continue;
        };
        if a2.dot(axis) < 0.0 {
            a2 = -a2;
            s2.iter_mut().for_each(|s| *s = -*s);
        }
        if (90.0 - axis.angle_between(*u).to_degrees()).abs() < MIN_TILT_DEG
            || a2.angle_between(axis) < SAME_AXIS
        {
            continue;
        }
        // The candidate: the new hinge, the children's joints fitted again.
        let mut cand = joints.clone();
        set_joint(&mut cand[ji], a2, p2, s2, limit_pad);
        let mut new_poses = poses.clone();
        for (t, f) in new_poses.iter_mut().enumerate() {
            f[ch] = poses[t][pa] * screw_exp(JointType::Revolute, a2, p2, cand[ji].state[t]);
        }
        for gj in cand.iter_mut().filter(|j| j.parent == ch) {
            let g = gj.child;
            let rel: Vec<DMat4> = (0..k)
                .map(|t| rigid_inverse(&new_poses[t][ch]) * poses[t][g])
                .collect();
            let (a, p, s) = match gj.joint_type {
                JointType::Revolute => {
                    let (a, p, s, _) = fit_revolute(&rel, DVec3::from(gj.pivot));
                    (a, p, s)
                }
                JointType::Prismatic => {
                    let (a, s, _) = fit_prismatic(&rel);
                    (a, DVec3::from(gj.pivot), s)
                }
            };
            set_joint(gj, a, p, s, limit_pad);
        }
        // The subtree's poses by forward kinematics from the child down.
        for &d in sub.iter().skip(1) {
            let Some(j) = cand.iter().find(|j| j.child == d) else {
                continue;
            };
            let (jt2, a, p) = (j.joint_type, DVec3::from(j.axis), DVec3::from(j.pivot));
            for (f, &q) in new_poses.iter_mut().zip(&j.state) {
                f[d] = f[j.parent] * screw_exp(jt2, a, p, q);
            }
        }
        let (before, after) = (
            parts_fit(&grids[..k], &by_part, &sub, |t, p| poses[t][p]),
            parts_fit(&grids[..k], &by_part, &sub, |t, p| new_poses[t][p]),
        );
        if after.is_nan() || after > slack * before {
            continue;
        }
        changes.push(SpinFree {
            child: ch,
            turned_deg: a2.angle_between(axis).to_degrees(),
            fit_before: before,
            fit_after: after,
        });
        for (out, f) in result.poses.iter_mut().zip(&new_poses) {
            for &d in &sub {
                out[d] = to_row_major(&f[d]);
            }
        }
        poses = new_poses;
        joints = cand;
    }
    result.joints = Some(joints);
    changes
}

/// Sets a joint's axis, pivot, states (0 at frame c, kept continuous for a revolute
/// joint) and limits.
fn set_joint(j: &mut ResultJoint, axis: DVec3, pivot: DVec3, states: Vec<f64>, limit_pad: f64) {
    let states = match j.joint_type {
        JointType::Revolute => unwrap_angles(states),
        JointType::Prismatic => states,
    };
    j.limits = padded_limits(&states, limit_pad);
    j.axis = axis.to_array();
    j.pivot = pivot.to_array();
    j.state = states;
}

/// Part `p` and its descendants, parents before children.
fn subtree(parent: &[i64], p: usize) -> Vec<usize> {
    let mut out = vec![p];
    let mut i = 0;
    while i < out.len() {
        let q = out[i] as i64;
        out.extend((0..parent.len()).filter(|&r| parent[r] == q));
        i += 1;
    }
    out
}

/// Summed trimmed fit (as `observed::trimmed_fit`) of the canonical points of part
/// `p` and its descendants (`by_part`: the canonical points of every part), moved by
/// the result's poses, to every frame's cloud (`grids`).
pub fn subtree_fit(result: &FitResult, grids: &[Grid], by_part: &[Vec<DVec3>], p: usize) -> f64 {
    let Some(tree) = result.tree.as_ref() else {
        return 0.0;
    };
    let k = grids.len().min(result.poses.len());
    parts_fit(&grids[..k], by_part, &subtree(&tree.parent, p), |t, q| {
        from_row_major(&result.poses[t][q])
    })
}

/// Σ over `parts` and frames t of the trimmed fit of the part's points moved by
/// `pose(t, part)` to frame t's cloud (`grids[t]`).
fn parts_fit(
    grids: &[Grid],
    by_part: &[Vec<DVec3>],
    parts: &[usize],
    pose: impl Fn(usize, usize) -> DMat4,
) -> f64 {
    let mut buf = Vec::new();
    parts
        .iter()
        .map(|&q| {
            grids
                .iter()
                .enumerate()
                .map(|(t, g)| trimmed_fit(g, &by_part[q], &pose(t, q), POLISH_KEEP, &mut buf))
                .sum::<f64>()
        })
        .sum()
}

/// The spin-free hinge (unit axis, pivot, unwrapped states with 0 at frame `c`) that
/// carries the symmetry axis `u` and the centre `cen` as the relative motions `rel`
/// do; None when the images of `u` do not spread over a plane. `reference` fixes the
/// pivot's free component along the axis.
fn spin_free(
    rel: &[DMat4],
    u: DVec3,
    cen: DVec3,
    c: usize,
    reference: DVec3,
) -> Option<(DVec3, DVec3, Vec<f64>)> {
    let images: Vec<DVec3> = rel
        .iter()
        .map(|m| m.transform_vector3(u).normalize())
        .collect();
    if images.iter().all(|d| d.angle_between(u) < MIN_TURN) {
        return None;
    }
    let scatter = images.iter().fold(Matrix3::<f64>::zeros(), |s, d| {
        let v = Vector3::new(d.x, d.y, d.z);
        s + v * v.transpose()
    });
    let e = SymmetricEigen::new(scatter);
    let mut order = [0usize, 1, 2];
    order.sort_by(|&i, &j| e.eigenvalues[i].total_cmp(&e.eigenvalues[j]));
    if e.eigenvalues[order[1]] < MIN_SPREAD * images.len() as f64 {
        return None;
    }
    let n = e.eigenvectors.column(order[0]);
    let n = DVec3::new(n[0], n[1], n[2]);
    // Exactly perpendicular to u, so that u's images stay on one great circle.
    let axis = (n - n.dot(u) * u).try_normalize()?;
    let states = turns_carrying(&images, u, axis, c);
    let pivot = pivot_carrying(rel, axis, &states, cen, reference);
    Some((axis, pivot, states))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::result::{ResultTree, FORMAT, VERSION};
    use crate::kinematics::flips::tests::{posed, turn};
    use crate::math::Libm;
    use rand::{rngs::StdRng, Rng, SeedableRng};

    const PIVOT: DVec3 = DVec3::new(0.0, 0.0, 0.12);
    const STATES: [f64; 8] = [0.0, 0.15, 0.3, 0.45, 0.3, 0.1, -0.1, -0.25];

    /// A still base slab (part 0) and a rod along +z from `PIVOT` (part 1, radius
    /// 0.03, length 0.45), its surface drawn at random (`seed`).
    fn scene(seed: u64) -> (Vec<Vec3>, Vec<u32>) {
        let mut rng = StdRng::seed_from_u64(seed);
        let mut pts = Vec::new();
        let mut labels = Vec::new();
        for i in 0..12 {
            for j in 0..12 {
                pts.push(Vec3::new(
                    i as f32 * 0.035 - 0.2,
                    j as f32 * 0.035 - 0.2,
                    0.1,
                ));
                labels.push(0);
            }
        }
        for _ in 0..500 {
            let a = rng.random::<f32>() * std::f32::consts::TAU;
            let z = 0.12 + rng.random::<f32>() * 0.45;
            pts.push(Vec3::new(0.03 * a.lcos(), 0.03 * a.lsin(), z));
            labels.push(1);
        }
        (pts, labels)
    }

    /// Clouds of the rod swinging about y through `PIVOT`, and a result whose hinge is
    /// tilted by `tilt` degrees towards the rod, with states that swing the rod about
    /// as far (the turn about the rod the tilt adds is invisible).
    fn tilted(tilt: f64) -> (FitResult, Vec<Vec<Vec3>>) {
        let k = STATES.len();
        let (pts, labels) = scene(0);
        let truth: Vec<DMat4> = STATES.iter().map(|&q| turn(DVec3::Y, q, PIVOT)).collect();
        let frames = posed(&truth, |t| scene(t as u64 + 1));
        let mut frames = frames;
        frames[0] = pts;
        let b = tilt.to_radians();
        let axis = DVec3::new(0.0, b.lcos(), b.lsin());
        let state: Vec<f64> = STATES.iter().map(|s| s / b.lcos()).collect();
        let poses = state
            .iter()
            .map(|&q| {
                vec![
                    to_row_major(&DMat4::IDENTITY),
                    to_row_major(&turn(axis, q, PIVOT)),
                ]
            })
            .collect();
        let res = FitResult {
            format: FORMAT.into(),
            version: VERSION,
            frames: k,
            canonical_frame: 0,
            parts: 2,
            labels: frames.iter().map(|_| labels.clone()).collect(),
            poses,
            gaussians: None,
            tree: Some(ResultTree {
                root: 0,
                parent: vec![-1, 0],
            }),
            joints: Some(vec![ResultJoint {
                mimic: None,
                child: 1,
                parent: 0,
                joint_type: JointType::Revolute,
                axis: axis.to_array(),
                pivot: PIVOT.to_array(),
                limits: padded_limits(&state, 0.0),
                state,
            }]),
            root_motion: None,
            points: None,
            info: None,
        };
        (res, frames)
    }

    fn parts_of(res: &FitResult, frames: &[Vec<Vec3>]) -> Vec<Vec<DVec3>> {
        points_by_part(&frames[0], &res.labels[0], res.parts)
    }

    #[test]
    fn a_symmetric_leaf_on_a_tilted_hinge_gets_the_perpendicular_one() {
        let (mut res, frames) = tilted(35.0);
        let grids: Vec<Grid> = frames.iter().map(|f| Grid::new(f)).collect();
        let before = subtree_fit(&res, &grids, &parts_of(&res, &frames), 1);
        let changes = spin_free_hinges(&mut res, &frames, &grids, 0.0, PROPOSE_SLACK, &|_| true);
        assert_eq!(changes.len(), 1, "{changes:?}");
        let j = &res.joints.as_ref().unwrap()[0];
        let axis = DVec3::from(j.axis);
        // Within a few degrees: the plane fitted to the images of an arc of the tilted
        // hinge's cone leans with the arc's curvature when the swing is lopsided (here
        // 4°); in the pipeline the refinement that follows polishes it.
        assert!(
            axis.angle_between(DVec3::Y).to_degrees() < 5.0,
            "axis {axis:?}"
        );
        let p = DVec3::from(j.pivot);
        assert!(
            p.x.abs() < 0.01 && (p.z - PIVOT.z).abs() < 0.01,
            "pivot {p:?}"
        );
        for (a, b) in j.state.iter().zip(STATES) {
            assert!((a - b).abs() < 0.03, "state {a} vs {b}");
        }
        // The poses follow the new joint, and fit the clouds no worse.
        let fk = turn(axis, j.state[3], p);
        assert!(from_row_major(&res.poses[3][1]).abs_diff_eq(fk, 1e-9));
        assert!(subtree_fit(&res, &grids, &parts_of(&res, &frames), 1) <= before * 1.01);
    }

    #[test]
    fn a_slightly_tilted_hinge_is_left_alone() {
        let (mut res, frames) = tilted(0.6 * MIN_TILT_DEG);
        let grids: Vec<Grid> = frames.iter().map(|f| Grid::new(f)).collect();
        let joints = res.joints.clone();
        assert!(
            spin_free_hinges(&mut res, &frames, &grids, 0.0, PROPOSE_SLACK, &|_| true).is_empty()
        );
        assert_eq!(res.joints, joints);
    }

    #[test]
    fn a_tilted_hinge_with_spin_becomes_the_perpendicular_one() {
        // A rod along z (centre at the origin, hinge at its top end z = 0.1) swings
        // about y; the "fitted" motions add a spin about the rod's own axis.
        let pivot = DVec3::new(0.0, 0.0, 0.1);
        let states = [0.0, 0.1, 0.25, 0.4, 0.3, -0.1, -0.2];
        let rel: Vec<DMat4> = states
            .iter()
            .enumerate()
            .map(|(i, &q)| {
                let spin = DMat4::from_rotation_z(0.7 * (i as f64).lsin());
                turn(DVec3::Y, q, pivot) * spin
            })
            .collect();
        let (axis, p, s) = spin_free(&rel, DVec3::Z, DVec3::ZERO, 0, pivot).unwrap();
        assert!(axis.cross(DVec3::Y).length() < 1e-9, "axis {axis:?}");
        let sign = axis.dot(DVec3::Y).signum();
        for (a, b) in s.iter().zip(states) {
            assert!((a * sign - b).abs() < 1e-9, "{a} vs {b}");
        }
        // The pivot lies on the true hinge line (x = 0, z = 0.1).
        assert!(p.x.abs() < 1e-9 && (p.z - 0.1).abs() < 1e-9, "pivot {p:?}");
    }

    #[test]
    fn a_roll_about_the_symmetry_axis_proposes_no_hinge() {
        let rel: Vec<DMat4> = (0..6)
            .map(|i| DMat4::from_rotation_z(0.3 * i as f64))
            .collect();
        assert!(spin_free(&rel, DVec3::Z, DVec3::ZERO, 0, DVec3::ZERO).is_none());
    }
}
