//! Gaussians held still on occluded input (an addition to the paper's optimisation).
//!
//! Every occluded frame shows the object from another side, and a Gaussian's motion is
//! found from the few points it sees there. One-sided views can slide over each other:
//! the occluded losses reward motions that make the frames overlap, and a part that
//! never moves (a robot's base) gets a wrong motion in many frames (bench-dev occluded
//! panda_gripper, fast: its hand half a turn off in one frame and 0.03–0.1 away in
//! most others). Every part posed relative to it then inherits the error.
//!
//! The raw clouds tell a still part apart without any motion: where it is, every
//! frame's points lie on the surface that the other frames' points sample. So for each
//! Gaussian two families of motions are compared on its region (its frame-0 points):
//! its own motions and no motion at all. A family carries every frame's points back
//! to frame 0 and keeps those that land in the region (within the occluded search's
//! inlier radius of the frame-0 points); its *agreement* is the share of them that
//! lands within `AGREE_R2` of a point carried from another frame t' ≥ 1 (frame 0 is
//! no target, since the region is made of its points). Labels play no part, so wrong
//! motions do not vouch for themselves. A Gaussian is held still in
//! every frame when no motion agrees `MARGIN` better than its own motions.

use glam::{DMat3, DVec3, Vec3};

use super::fitter::Data;
use super::gaussians::Params;
use super::pose_init::{relative_motion, set_relative_pose};
use super::pose_search::{frame0_start, Motion};
use crate::geom::knn::Grid;

/// Squared radius (normalised units²) of a Gaussian's region around its frame-0
/// points: the occluded search's inlier radius.
const REGION_R2: f32 = 1e-3;

/// Squared radius within which two frames' carried points agree: about one point
/// spacing of the occluded frames (0.007–0.011). Bench-dev occluded, fast, means of
/// seeds 0–2 (RI / recon / flow / TED): 2e-4 gave 0.715 / 13.35 / 15.74 / 5.38, 1e-4
/// 0.718 / 12.70 / 14.92 / 4.86, 4e-5 0.700 / 12.51 / 14.38 / 4.96 (without the hold
/// 0.701 / 14.73 / 17.55 / 5.52).
const AGREE_R2: f32 = 1e-4;

/// Agreement (a share) by which no motion must beat the Gaussian's own motions: a
/// part that moves a little (panda_gripper's fingers) agrees about as well either way,
/// and held still it merges into its parent. Same runs: a margin of 0 gave 0.697 /
/// 12.63 / 14.47 / 5.00, 0.1 gave 0.708 / 13.38 / 16.07 / 5.38.
const MARGIN: f64 = 0.05;

/// Frame-0 points sampled for the regions.
const POINTS: usize = 2048;

/// Agreement of the motions `rel[t]` (frame 0 → t) on `region` (module doc).
fn agreement(data: &Data, region: &Grid, rel: &[Motion]) -> f64 {
    let carried: Vec<Vec<Vec3>> = data
        .frames
        .iter()
        .zip(rel)
        .map(|(frame, &(r, c))| {
            let (ri, ci) = (r.transpose(), -(r.transpose() * c));
            frame
                .iter()
                .map(|y| (ri * *y + ci).as_vec3())
                .filter(|x| region.nearest_d2_capped(*x, REGION_R2) < REGION_R2)
                .collect()
        })
        .collect();
    // Frame 0 is no target: the region is made of its points.
    let targets: Vec<Grid> = carried[1..].iter().map(|c| Grid::new(c)).collect();
    let (mut agree, mut total) = (0usize, 0usize);
    for (t, pts) in carried.iter().enumerate() {
        total += pts.len();
        agree += pts
            .iter()
            .filter(|x| {
                targets.iter().enumerate().any(|(s, g)| {
                    s + 1 != t && !g.is_empty() && g.nearest_d2_capped(**x, AGREE_R2) < AGREE_R2
                })
            })
            .count();
    }
    agree as f64 / total.max(1) as f64
}

/// Holds still (module doc) every Gaussian that no motion explains clearly better
/// than its own motions; frame 0 is left unchanged. Returns the number held.
pub fn hold_still(data: &Data, params: &mut Params) -> usize {
    let kk = data.k();
    // With two frames no frame t ≥ 1 has another to agree with.
    if kk < 3 {
        return 0;
    }
    let Some((g0, groups)) = frame0_start(data, params, POINTS) else {
        return 0;
    };
    let still: Vec<Motion> = vec![(DMat3::IDENTITY, DVec3::ZERO); kk];
    let mut held = 0;
    for (i, group) in groups.iter().enumerate() {
        if group.len() < 3 {
            continue;
        }
        let region = Grid::new(&group.iter().map(|p| p.as_vec3()).collect::<Vec<_>>());
        let own: Vec<Motion> = (0..kk)
            .map(|t| relative_motion(&g0[i], &params.gauss(t, i)))
            .collect();
        if agreement(data, &region, &still) > agreement(data, &region, &own) + MARGIN {
            for (t, &mo) in still.iter().enumerate().skip(1) {
                set_relative_pose(params, t, i, &g0[i], mo);
            }
            held += 1;
        }
    }
    held
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::occluded_search::tests::occluded_hinge;
    use crate::fit::pose_search::tests::oracle_params;

    /// `occluded_search`'s hinge (a base and an arm turning about z, seen from a
    /// different direction in every frame), every frame moved as a whole by
    /// `carry(t)`. Returns the frames and frame 0's labels.
    fn seen_hinge(angles: &[f64], carry: impl Fn(usize) -> DVec3) -> (Vec<Vec<Vec3>>, Vec<u32>) {
        let (mut frames, lab0) = occluded_hinge(angles);
        for (t, f) in frames.iter_mut().enumerate() {
            let shift = carry(t).as_vec3();
            f.iter_mut().for_each(|p| *p += shift);
        }
        (frames, lab0)
    }

    /// Oracle Gaussians (base 0, arm 1) with the arm's true motions and the base
    /// moved by `base(t)` instead of its true motion `carry(t)`.
    fn posed(
        frames: &[Vec<Vec3>],
        lab0: &[u32],
        angles: &[f64],
        carry: impl Fn(usize) -> DVec3,
        base: impl Fn(usize) -> DVec3,
    ) -> Params {
        let mut params = oracle_params(&frames[0], lab0, 2, angles.len());
        let (b0, a0) = (params.gauss(0, 0), params.gauss(0, 1));
        for (t, a) in angles.iter().enumerate().skip(1) {
            let r = DMat3::from_axis_angle(DVec3::Z, *a);
            let shift = carry(t) - carry(0);
            set_relative_pose(&mut params, t, 1, &a0, (r, shift - r * carry(0) + carry(0)));
            set_relative_pose(&mut params, t, 0, &b0, (DMat3::IDENTITY, base(t)));
        }
        params
    }

    const ANGLES: [f64; 5] = [0.0, 0.9, -1.2, 0.5, 1.4];

    #[test]
    fn a_still_base_with_wrong_motions_is_held_still() {
        let (frames, lab0) = seen_hinge(&ANGLES, |_| DVec3::ZERO);
        let data = Data::new(frames.clone());
        // The base slid 0.04–0.07 along its faces in frames 1–4.
        let wrong = |t: usize| DVec3::new(0.04 + 0.01 * t as f64, 0.02, 0.0);
        let mut params = posed(&frames, &lab0, &ANGLES, |_| DVec3::ZERO, wrong);
        let arm_before: Vec<_> = (0..ANGLES.len()).map(|t| params.gauss(t, 1)).collect();
        assert_eq!(hold_still(&data, &mut params), 1);
        let b0 = params.gauss(0, 0);
        for (t, arm) in arm_before.iter().enumerate() {
            let b = params.gauss(t, 0);
            assert!(b.mu.distance(b0.mu) < 1e-9, "frame {t}: base not held");
            assert!(b.r.abs_diff_eq(b0.r, 1e-9), "frame {t}: base turned");
            // The moving arm keeps its (right) motion.
            assert_eq!(params.gauss(t, 1).mu, arm.mu, "frame {t}: arm changed");
        }
    }

    #[test]
    fn a_base_that_really_moves_keeps_its_motion() {
        // The whole hinge is carried 0.06 further along x in every frame, and the
        // Gaussians follow it: no motion explains nothing here.
        let carry = |t: usize| DVec3::new(0.06 * t as f64, 0.0, 0.0);
        let (frames, lab0) = seen_hinge(&ANGLES, carry);
        let data = Data::new(frames.clone());
        let mut params = posed(&frames, &lab0, &ANGLES, carry, carry);
        let before = params.x.clone();
        assert_eq!(hold_still(&data, &mut params), 0);
        assert_eq!(params.x, before);
    }
}
