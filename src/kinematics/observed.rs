//! The observed motion of each merged part, and which poses the result reports.
//!
//! Step 1 moves every point with its own Gaussian. After merging, a part's *observed*
//! motion at frame t is the rigid transform that best carries the part's canonical
//! points to where their Gaussians put them (Kabsch over the part's points). The
//! articulated model (tree, joints, refinement) reproduces that motion only as well as
//! the tree is right: a wrong parent makes the projected chain bend every descendant,
//! and the Chamfer refinement then turns even a static root to make up for it (so101,
//! m = 10: a base that never moves turned 13–45° per frame). The result's `poses`
//! therefore keep the model's pose of a part only where it agrees with the observed
//! motion (a denoised version of it, as on panda_gripper's slides) and the observed
//! motion elsewhere; the joints and the root motion stay the model's.

use glam::{DMat3, DMat4, DVec3, Vec3};

use crate::fit::pose_init::{kabsch, trimmed_icp, trimmed_mean};
use crate::geom::knn::Grid;
use crate::geom::se3::{from_row_major, rigid, rigid_inverse, to_row_major};
use crate::io::result::FitResult;

/// The model's pose of a part at a frame is kept when, over the part's canonical
/// points, it is within this RMS distance of the observed motion (fraction of the
/// object's size, the longest side of the canonical points' bounding box).
pub const AGREE_TOL: f64 = 0.01;

/// … or within this many mean point spacings, when that is larger: on sparse clouds
/// the Gaussians' motion is only known to about a spacing, and the joint model is the
/// better estimate (procedural laptop 4 × 512, spacing 0.029: reconstruction error
/// 1.57 with the model's poses, 2.74 with the observed motion beyond 1 %). Dense
/// robots (spacing ≈ 0.0045) are unaffected.
pub const AGREE_SPACINGS: f64 = 2.0;

/// `observed[t][p]`: the rigid map from frame `canonical` to frame t that best fits the
/// Step-1 motion of merged part p's canonical points. `points`/`labels` are the working
/// clouds with Step-1 labels, `poses[t][g]` the Step-1 poses (only relative motion
/// matters), `map[g]` the merged part of Step-1 part g. Parts with fewer than three
/// canonical points move with their largest Step-1 member's pose instead
/// (`fallback[t][p]`).
pub fn observed_motion(
    points: &[Vec3],
    labels: &[u32],
    poses: &[Vec<DMat4>],
    map: &[u32],
    canonical: usize,
    fallback: &[Vec<DMat4>],
) -> Vec<Vec<DMat4>> {
    let k = poses.len();
    let parts = fallback.first().map_or(0, Vec::len);
    let inv_c: Vec<DMat4> = poses[canonical].iter().map(rigid_inverse).collect();
    // Points of each merged part (canonical frame) with their Step-1 part.
    let mut members: Vec<Vec<(DVec3, usize)>> = vec![Vec::new(); parts];
    for (x, &g) in points.iter().zip(labels) {
        let g = g as usize;
        if let Some(&p) = map.get(g) {
            if (p as usize) < parts && g < inv_c.len() {
                members[p as usize].push((x.as_dvec3(), g));
            }
        }
    }
    let mut out = fallback.to_vec();
    for (p, pts) in members.iter().enumerate() {
        if pts.len() < 3 {
            continue;
        }
        let a: Vec<DVec3> = pts.iter().map(|(x, _)| *x).collect();
        let w = vec![1.0; a.len()];
        for (t, frame) in out.iter_mut().enumerate().take(k) {
            if t == canonical {
                frame[p] = DMat4::IDENTITY;
                continue;
            }
            let b: Vec<DVec3> = pts
                .iter()
                .map(|(x, g)| (poses[t][*g] * inv_c[*g]).transform_point3(*x))
                .collect();
            if let Some((r, tr)) = kabsch(&a, &b, &w) {
                frame[p] = rigid(r, tr);
            }
        }
    }
    out
}

/// Replaces the result's pose of part p at frame t by `observed[t][p]` where the two
/// disagree by more than `tol` (RMS over the part's canonical points `points` with
/// result labels `labels`, same units as the points) and the observed motion carries
/// the part's points closer to frame t's cloud `frames[t]` (mean squared distance to
/// the nearest point, capped at (5·tol)²). Where the model is right and the Gaussians'
/// motion is merely noisy, the model fits the data better and stays. Returns how many
/// (part, frame) poses were replaced.
pub fn keep_faithful_poses(
    result: &mut FitResult,
    observed: &[Vec<DMat4>],
    points: &[Vec3],
    labels: &[u32],
    frames: &[Vec<Vec3>],
    tol: f64,
) -> usize {
    let by_part = points_by_part(points, labels, result.parts);
    let cap2 = (25.0 * tol * tol) as f32;
    let mut replaced = 0;
    for (t, frame) in result.poses.iter_mut().enumerate() {
        let Some(cloud) = frames.get(t).filter(|c| !c.is_empty()) else {
            continue;
        };
        let mut grid: Option<Grid> = None;
        for (p, pose) in frame.iter_mut().enumerate() {
            let (Some(obs), Some(pts)) = (observed.get(t).and_then(|f| f.get(p)), by_part.get(p))
            else {
                continue;
            };
            if pts.is_empty() {
                continue;
            }
            let model = from_row_major(pose);
            let ms = pts
                .iter()
                .map(|x| {
                    model
                        .transform_point3(*x)
                        .distance_squared(obs.transform_point3(*x))
                })
                .sum::<f64>()
                / pts.len() as f64;
            if ms.sqrt() <= tol {
                continue;
            }
            let grid = grid.get_or_insert_with(|| Grid::new(cloud));
            let fit = |m: &DMat4| {
                pts.iter()
                    .map(|x| grid.nearest_d2_capped(m.transform_point3(*x).as_vec3(), cap2) as f64)
                    .sum::<f64>()
            };
            if fit(obs) < fit(&model) {
                *pose = to_row_major(obs);
                replaced += 1;
            }
        }
    }
    replaced
}

/// Last step for the result's poses: trimmed ICP of every part's canonical points
/// (`points`, result labels `labels`) to frame t's cloud `frames[t]`, from the chosen
/// pose, for every frame but the canonical one — `rounds` rounds of nearest neighbours
/// and Kabsch on the `keep` fraction of closest pairs. A whole part's points pin its pose
/// better than each Gaussian's few did. The polished pose is taken only when it fits
/// the trimmed distances `POLISH_GAIN` better: a flat part (the laptop's lid) slides
/// in its own plane under ICP without fitting better, and its hinge pose stays.
/// Parts with fewer than 16 points keep their pose.
pub fn polish_poses(
    result: &mut FitResult,
    points: &[Vec3],
    labels: &[u32],
    frames: &[Vec<Vec3>],
    rounds: usize,
    keep: f64,
) {
    let mut motions: Vec<Vec<DMat4>> = result
        .poses
        .iter()
        .map(|f| f.iter().map(from_row_major).collect())
        .collect();
    polish_motions(
        &mut motions,
        result.canonical_frame,
        points,
        labels,
        frames,
        rounds,
        keep,
        POLISH_GAIN,
    );
    for (f, m) in result.poses.iter_mut().zip(&motions) {
        for (pose, mo) in f.iter_mut().zip(m) {
            *pose = to_row_major(mo);
        }
    }
}

/// [`polish_poses`] on motions `motions[t][p]` (frame `canonical` → t); a polished
/// pose is taken when it fits `gain` better.
#[allow(clippy::too_many_arguments)]
pub fn polish_motions(
    motions: &mut [Vec<DMat4>],
    canonical: usize,
    points: &[Vec3],
    labels: &[u32],
    frames: &[Vec<Vec3>],
    rounds: usize,
    keep: f64,
    gain: f64,
) {
    let by_part = points_by_part(points, labels, motions.first().map_or(0, Vec::len));
    let mut bufs = (Vec::new(), Vec::new());
    for (t, frame) in motions.iter_mut().enumerate() {
        let Some(cloud) = frames.get(t).filter(|c| !c.is_empty()) else {
            continue;
        };
        if t == canonical {
            continue;
        }
        let grid = Grid::new(cloud);
        polish_frame(
            frame,
            &by_part,
            &grid,
            cloud,
            (rounds, keep, gain),
            &mut bufs,
        );
    }
}

/// One frame of [`polish_motions`]: each part's motion in `frame` polished against
/// `cloud` (`grid` its grid) with (rounds, kept fraction, gain) `settings`; `by_part`
/// are the canonical points of each part ([`points_by_part`]), `bufs` scratch space.
pub(crate) fn polish_frame(
    frame: &mut [DMat4],
    by_part: &[Vec<DVec3>],
    grid: &Grid,
    cloud: &[Vec3],
    (rounds, keep, gain): (usize, f64, f64),
    (dst, buf): &mut (Vec<DVec3>, Vec<f64>),
) {
    for (pose, pts) in frame.iter_mut().zip(by_part) {
        if pts.len() < 16 {
            continue;
        }
        let start = *pose;
        let mo = icp_pose(grid, cloud, pts, &start, (rounds, keep), dst);
        let before = trimmed_fit(grid, pts, &start, keep, buf);
        if trimmed_fit(grid, pts, &mo, keep, buf) < (1.0 - gain) * before {
            *pose = mo;
        }
    }
}

/// The points of each of `parts` parts (labels out of range are skipped).
pub(crate) fn points_by_part(points: &[Vec3], labels: &[u32], parts: usize) -> Vec<Vec<DVec3>> {
    let mut by_part: Vec<Vec<DVec3>> = vec![Vec::new(); parts];
    for (x, &l) in points.iter().zip(labels) {
        if let Some(v) = by_part.get_mut(l as usize) {
            v.push(x.as_dvec3());
        }
    }
    by_part
}

/// `start` moved by trimmed ICP of `pts` against `cloud` (`grid` its grid), with
/// (rounds, kept fraction) `rounds_keep`.
fn icp_pose(
    grid: &Grid,
    cloud: &[Vec3],
    pts: &[DVec3],
    start: &DMat4,
    (rounds, keep): (usize, f64),
    dst: &mut Vec<DVec3>,
) -> DMat4 {
    let from = (DMat3::from_mat4(*start), start.w_axis.truncate());
    let (r, tr) = trimmed_icp(grid, |j| cloud[j].as_dvec3(), pts, from, rounds, keep, dst);
    rigid(r, tr)
}

/// `start` polished against `cloud` (`grid` its grid) by trimmed ICP of `pts`, as the
/// reported poses are (`POLISH_ROUNDS`, `POLISH_KEEP`).
pub(crate) fn polish_pose(
    grid: &Grid,
    cloud: &[Vec3],
    pts: &[DVec3],
    start: &DMat4,
    dst: &mut Vec<DVec3>,
) -> DMat4 {
    icp_pose(grid, cloud, pts, start, (POLISH_ROUNDS, POLISH_KEEP), dst)
}

/// Mean of the `keep` fraction of smallest squared distances from the moved points to
/// the cloud.
pub(crate) fn trimmed_fit(
    grid: &Grid,
    pts: &[DVec3],
    mo: &DMat4,
    keep: f64,
    buf: &mut Vec<f64>,
) -> f64 {
    trimmed_fit_capped(grid, pts, mo, keep, f32::INFINITY, buf)
}

/// [`trimmed_fit`] with each squared distance capped at `cap2`: a point farther than
/// that stops its search there (`Grid::nearest_d2_capped`), which is what makes a
/// query far from the cloud cheap.
pub(crate) fn trimmed_fit_capped(
    grid: &Grid,
    pts: &[DVec3],
    mo: &DMat4,
    keep: f64,
    cap2: f32,
    buf: &mut Vec<f64>,
) -> f64 {
    buf.clear();
    buf.extend(
        pts.iter()
            .map(|x| grid.nearest_d2_capped(mo.transform_point3(*x).as_vec3(), cap2) as f64),
    );
    if buf.is_empty() {
        return 0.0;
    }
    trimmed_mean(buf, keep)
}

/// Relative improvement of the trimmed fit a polished pose needs. Measured (fast,
/// 10 rounds, keep 0.8; bench-dev full at the selected m / procedural seed 3):
/// gain 0: recon 1.055, laptop 0.59; 0.05: 1.071, laptop 0.45; 0.1: 1.088; without
/// the polish: 1.264, laptop 0.44.
pub const POLISH_GAIN: f64 = 0.05;

/// ICP rounds and kept fraction of the pose polish (`KinOptions::polish`).
pub const POLISH_ROUNDS: usize = 10;
pub const POLISH_KEEP: f64 = 0.8;

/// Longest side of the points' bounding box (the object's size).
pub fn object_size(points: &[Vec3]) -> f64 {
    let (lo, hi) = points.iter().fold(
        (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
        |(lo, hi), p| (lo.min(*p), hi.max(*p)),
    );
    if points.is_empty() {
        0.0
    } else {
        (hi - lo).max_element() as f64
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DQuat;

    /// A two-frame, two-part result with these canonical labels and poses.
    fn result_with(labels: &[u32], poses: Vec<Vec<[f64; 16]>>) -> FitResult {
        FitResult {
            format: crate::io::result::FORMAT.to_string(),
            version: crate::io::result::VERSION,
            frames: 2,
            canonical_frame: 0,
            parts: 2,
            labels: vec![labels.to_vec(); 2],
            poses,
            gaussians: None,
            tree: None,
            joints: None,
            root_motion: None,
            points: None,
            info: None,
        }
    }

    fn rigid(axis: DVec3, angle: f64, t: DVec3) -> DMat4 {
        DMat4::from_rotation_translation(DQuat::from_axis_angle(axis.normalize(), angle), t)
    }

    #[test]
    fn observed_motion_fits_the_members_motions() {
        // Two Step-1 parts on one merged part, moving almost alike: the observed motion
        // is their least-squares compromise; frame 0 is canonical.
        let a = rigid(DVec3::Z, 0.3, DVec3::new(0.1, 0.0, 0.0));
        let b = rigid(DVec3::Z, 0.32, DVec3::new(0.1, 0.0, 0.0));
        let poses = vec![vec![DMat4::IDENTITY; 2], vec![a, b]];
        let pts: Vec<Vec3> = (0..40)
            .map(|i| {
                Vec3::new(
                    (i % 7) as f32 * 0.1,
                    (i % 5) as f32 * 0.1,
                    (i % 3) as f32 * 0.1,
                )
            })
            .collect();
        let labels: Vec<u32> = (0..40).map(|i| (i % 2) as u32).collect();
        let fallback = vec![vec![DMat4::IDENTITY; 1]; 2];
        let obs = observed_motion(&pts, &labels, &poses, &[0, 0], 0, &fallback);
        assert_eq!(obs[0][0], DMat4::IDENTITY);
        let (_, rot, _) = obs[1][0].to_scale_rotation_translation();
        let angle = rot.to_axis_angle().1;
        assert!((angle - 0.31).abs() < 0.005, "angle {angle}");
        // A single member's motion is reproduced exactly.
        let obs = observed_motion(&pts, &[0; 40], &poses, &[0, 0], 0, &fallback);
        assert!(obs[1][0].abs_diff_eq(a, 1e-9));
    }

    #[test]
    fn only_disagreeing_poses_are_replaced() {
        let pts: Vec<Vec3> = (0..30)
            .map(|i| Vec3::new((i % 3) as f32, (i % 5) as f32 * 0.5, (i % 2) as f32))
            .collect();
        let labels: Vec<u32> = (0..30).map(|i| (i % 2) as u32).collect();
        let near = rigid(DVec3::X, 0.001, DVec3::ZERO);
        let far = rigid(DVec3::X, 0.5, DVec3::ZERO);
        let mut result = result_with(&labels, vec![vec![to_row_major(&DMat4::IDENTITY); 2]; 2]);
        // Frame 1's cloud: part 0 where the model puts it, part 1 where the observed
        // motion puts it (the model got part 1 wrong).
        let frame1: Vec<Vec3> = pts
            .iter()
            .zip(&labels)
            .map(|(x, &l)| {
                if l == 1 {
                    far.transform_point3(x.as_dvec3()).as_vec3()
                } else {
                    *x
                }
            })
            .collect();
        let frames = vec![pts.clone(), frame1];
        let observed = vec![vec![DMat4::IDENTITY; 2], vec![near, far]];
        let n = keep_faithful_poses(&mut result, &observed, &pts, &labels, &frames, 0.05);
        assert_eq!(n, 1);
        assert_eq!(result.poses[1][0], to_row_major(&DMat4::IDENTITY));
        assert_eq!(result.poses[1][1], to_row_major(&far));
        // A disagreement the data do not support is not taken: with a cloud where the
        // model is right, nothing is replaced.
        result.poses[1][1] = to_row_major(&DMat4::IDENTITY);
        let frames = vec![pts.clone(), pts.clone()];
        assert_eq!(
            keep_faithful_poses(&mut result, &observed, &pts, &labels, &frames, 0.05),
            0
        );
        assert!((object_size(&pts) - 2.0).abs() < 1e-6);
    }

    #[test]
    fn polish_pulls_a_misplaced_part_back_and_leaves_a_fitting_plate() {
        // Part 0: a box surface, frame 1 moved by a known motion but reported 0.1 rad off.
        // Part 1: a flat plate, reported exactly.
        let mut pts = Vec::new();
        let mut labels = Vec::new();
        for i in 0..20 {
            for j in 0..20 {
                let (u, v) = (i as f32 / 19.0, j as f32 / 19.0);
                for p in [
                    Vec3::new(u, v, 0.0),
                    Vec3::new(u, v, 0.6),
                    Vec3::new(u, 0.0, v * 0.6),
                    Vec3::new(0.0, u, v * 0.6),
                ] {
                    pts.push(p * 0.3);
                    labels.push(0);
                }
                pts.push(Vec3::new(2.0 + u, v, 0.0) * 0.3);
                labels.push(1);
            }
        }
        let truth = rigid(DVec3::new(0.3, 1.0, 0.2), 0.5, DVec3::new(0.05, 0.0, 0.02));
        let frame1: Vec<Vec3> = pts
            .iter()
            .map(|x| truth.transform_point3(x.as_dvec3()).as_vec3())
            .collect();
        let off = truth * rigid(DVec3::Z, 0.1, DVec3::ZERO);
        let mut result = result_with(
            &labels,
            vec![
                vec![to_row_major(&DMat4::IDENTITY); 2],
                vec![to_row_major(&off), to_row_major(&truth)],
            ],
        );
        let before = result.poses.clone();
        polish_poses(
            &mut result,
            &pts,
            &labels,
            &[pts.clone(), frame1],
            POLISH_ROUNDS,
            POLISH_KEEP,
        );
        let fixed = from_row_major(&result.poses[1][0]);
        assert!(fixed.abs_diff_eq(truth, 1e-3), "{fixed:?}");
        assert_eq!(result.poses[1][1], before[1][1]);
        assert_eq!(result.poses[0], before[0]);
    }
}
