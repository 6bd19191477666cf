//! Motion re-segmentation of frame 0 (an addition to the paper's optimisation, used
//! between global pose searches): the Gaussians are first placed by geometry alone
//! (farthest-point sampling and the frame-0 warm-up), so one Gaussian often
//! straddles two rigid parts and no single motion explains it. Given every
//! Gaussian's motion over the frames, each frame-0 point is given to the nearby
//! Gaussian whose motion carries it closest to the observed clouds of all frames;
//! each Gaussian's frame-0 centre, rotation and scale are then re-estimated from the
//! moments of its points, keeping its motions. The pose search that follows works
//! on groups that move rigidly.

use crate::math::Libm;
use glam::{DMat3, DVec3};
use nalgebra::{Matrix3, Vector3};

use super::fitter::Data;
use super::gaussians::{Gauss, Params};
use super::pose_init::{relative_motion, set_relative_pose};

/// Options of the re-segmentation.
#[derive(Debug, Clone, Copy)]
pub struct MotionSegOpts {
    /// Frame-0 points used.
    pub points: usize,
    /// Gaussians (nearest by Mahalanobis distance in frame 0) a point may join.
    pub nearest: usize,
    /// Squared-distance cap per frame (normalised units²): a frame where the
    /// point's part is hidden or mis-posed costs at most this.
    pub cap2: f64,
    /// Minimum points for a Gaussian to be re-estimated (others keep their shape).
    pub min_points: usize,
    /// Rounds of re-segmentation, each followed by a new pose search.
    pub rounds: usize,
}

impl Default for MotionSegOpts {
    fn default() -> Self {
        MotionSegOpts {
            points: 2048,
            nearest: 4,
            cap2: 0.01,
            min_points: 8,
            rounds: 2,
        }
    }
}

/// Re-segments frame 0 by motion and re-estimates the Gaussians' frame-0 shapes
/// (see the module doc). Returns the number of sampled points that changed
/// Gaussian.
#[allow(clippy::needless_range_loop)] // t indexes frames in several arrays
pub fn resegment(data: &Data, params: &mut Params, opts: &MotionSegOpts) -> usize {
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
    // Relative motions frame 0 → t.
    let rel: Vec<Vec<(DMat3, DVec3)>> = (0..m)
        .map(|i| {
            (0..kk)
                .map(|t| relative_motion(&g0[i], &gs[t][i]))
                .collect()
        })
        .collect();
    let f0 = &data.frames[0];
    let step = (f0.len() / opts.points.max(1)).max(1);
    let nearest = opts.nearest.clamp(1, m);
    let mut sums = vec![DVec3::ZERO; m];
    let mut outer = vec![Matrix3::<f64>::zeros(); m];
    let mut counts = vec![0usize; m];
    let mut assigned: Vec<(usize, DVec3)> = Vec::new();
    let mut changed = 0;
    let mut near: Vec<(f64, usize)> = Vec::with_capacity(m);
    for x in f0.iter().step_by(step) {
        near.clear();
        near.extend(g0.iter().enumerate().map(|(i, g)| (g.maha(*x).0, i)));
        near.select_nth_unstable_by(nearest - 1, |a, b| a.0.total_cmp(&b.0));
        let home = near[..nearest]
            .iter()
            .min_by(|a, b| a.0.total_cmp(&b.0))
            .map_or(0, |e| e.1);
        let mut best = (f64::INFINITY, home);
        for &(_, i) in &near[..nearest] {
            let mut c = 0.0;
            for t in 1..kk {
                let (r, tr) = rel[i][t];
                let y = r * *x + tr;
                c += data.grids[t].nearest_d2_capped(y.as_vec3(), opts.cap2 as f32) as f64;
                if c >= best.0 {
                    break;
                }
            }
            // Ties (e.g. two Gaussians of one part) stay with the geometric choice.
            if c < best.0 - 1e-12 || (c <= best.0 && i == home) {
                best = (c, i);
            }
        }
        let i = best.1;
        if i != home {
            changed += 1;
        }
        assigned.push((i, *x));
        sums[i] += *x;
        counts[i] += 1;
    }
    let means: Vec<DVec3> = (0..m).map(|i| sums[i] / counts[i].max(1) as f64).collect();
    for (i, x) in &assigned {
        let d = *x - means[*i];
        let v = Vector3::new(d.x, d.y, d.z);
        outer[*i] += v * v.transpose();
    }
    for i in 0..m {
        if counts[i] < opts.min_points {
            continue;
        }
        let cov = outer[i] / counts[i] as f64;
        let e = cov.symmetric_eigen();
        let col = |j: usize| {
            DVec3::new(
                e.eigenvectors[(0, j)],
                e.eigenvectors[(1, j)],
                e.eigenvectors[(2, j)],
            )
        };
        let mut r = DMat3::from_cols(col(0), col(1), col(2));
        if r.determinant() < 0.0 {
            r = DMat3::from_cols(col(0), col(1), -col(2));
        }
        // σ from the moments, floored so flat parts keep a usable thickness.
        let floor = 1e-3_f64.powi(2);
        let var = DVec3::new(e.eigenvalues[0], e.eigenvalues[1], e.eigenvalues[2])
            .max(DVec3::splat(floor));
        let log_s = DVec3::new(var.x.lln(), var.y.lln(), var.z.lln()) * 0.5;
        let new0 = Gauss::new(r, means[i], log_s);
        params.set_log_scale(i, log_s);
        for t in 0..kk {
            let mo = if t == 0 {
                (DMat3::IDENTITY, DVec3::ZERO)
            } else {
                rel[i][t]
            };
            set_relative_pose(params, t, i, &new0, mo);
        }
    }
    changed
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::gaussians::argmin_maha;
    use crate::fit::pose_init::set_relative_pose;
    use crate::fit::pose_search::tests::{hinge, oracle_params};
    use glam::Vec3;

    fn agreement(params: &Params, f0: &[Vec3], lab: &[u32]) -> f64 {
        let mut g0 = Vec::new();
        params.frame_into(0, &mut g0);
        let ok = f0
            .iter()
            .zip(lab)
            .filter(|(p, &l)| argmin_maha(&g0, p.as_dvec3()).0 == l as usize)
            .count();
        ok as f64 / f0.len() as f64
    }

    #[test]
    fn moves_a_straddling_boundary_to_the_hinge() {
        // Correct motions, but the frame-0 Gaussians are fitted to a split 0.15
        // into the arm (the base Gaussian straddles the joint): re-segmentation by
        // motion must move the boundary back to the hinge.
        let angles = [0.0, 1.2, -0.9, 2.0];
        let frames: Vec<(Vec<Vec3>, Vec<u32>)> = angles
            .iter()
            .enumerate()
            .map(|(k, a)| hinge(*a, 3000, 60 + k as u64))
            .collect();
        let data = Data::new(frames.iter().map(|f| f.0.clone()).collect());
        let (f0, lab) = (&frames[0].0, &frames[0].1);
        let wrong: Vec<u32> = f0.iter().map(|p| (p.x > 0.15) as u32).collect();
        let mut params = oracle_params(f0, &wrong, 2, angles.len());
        let g0: Vec<Gauss> = (0..2).map(|i| params.gauss(0, i)).collect();
        for (t, a) in angles.iter().enumerate().skip(1) {
            set_relative_pose(&mut params, t, 0, &g0[0], (DMat3::IDENTITY, DVec3::ZERO));
            set_relative_pose(
                &mut params,
                t,
                1,
                &g0[1],
                (DMat3::from_axis_angle(DVec3::Z, *a), DVec3::ZERO),
            );
        }
        let before = agreement(&params, f0, lab);
        let opts = MotionSegOpts::default();
        let changed = resegment(&data, &mut params, &opts);
        resegment(&data, &mut params, &opts);
        let after = agreement(&params, f0, lab);
        assert!(changed > 0);
        assert!(before < 0.9, "before {before}");
        // As good as Gaussians fitted to the true labels (their Mahalanobis
        // boundary is not exactly the hinge either).
        let oracle = agreement(&oracle_params(f0, lab, 2, 1), f0, lab);
        assert!(
            after > oracle - 0.01 && after > before + 0.1,
            "after {after}, before {before}, oracle {oracle}"
        );
        // The motions are kept: frame t's Gaussian is frame 0's moved by them.
        let (a0, a1) = (params.gauss(0, 1), params.gauss(1, 1));
        let want = DMat3::from_axis_angle(DVec3::Z, angles[1]);
        assert!((a1.mu - want * a0.mu).length() < 1e-9);
    }
}
