//! Reconstruction error and flow error (EPE) of SPEC §5.
//!
//! The points are the canonical frame's observed points `x` (frame c of the result),
//! each with its predicted part `a` and its ground-truth part `g`. At frame t:
//! - predicted position `p_t = poses[t][a] · x` (the result's pose of the predicted part),
//! - ground-truth position `y_t = gt.poses[t][g] · inv(gt.poses[c][g]) · x`.
//!
//! Reconstruction error = 100 · mean over all K frames t of mean over points of
//! `‖p_t − y_t‖` (frame c contributes 0 when the result has identity there).
//! Flow error (end-point error) = 100 · mean over the K−1 consecutive pairs t→t+1 of
//! mean over points of `‖(p_{t+1} − p_t) − (y_{t+1} − y_t)‖`.

use glam::{DMat4, DVec3, Vec3};

use crate::geom::se3::{from_row_major, rigid_inverse};
use crate::io::gt::GroundTruth;
use crate::io::result::FitResult;
use crate::{Error, Result};

/// Both errors, ×100.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MotionErrors {
    pub reconstruction: f64,
    pub flow: f64,
}

/// Reconstruction and flow error of `result` against `gt` on the canonical points
/// `points` with predicted labels `pred` and ground-truth labels `gt_labels`.
pub fn motion_errors(
    result: &FitResult,
    gt: &GroundTruth,
    points: &[Vec3],
    pred: &[u32],
    gt_labels: &[u32],
) -> Result<MotionErrors> {
    let k = result.frames;
    let c = result.canonical_frame;
    let n = points.len();
    if n == 0 || pred.len() != n || gt_labels.len() != n {
        return Err(Error::InvalidArgument(format!(
            "motion errors: {n} points, {} predicted and {} ground-truth labels",
            pred.len(),
            gt_labels.len()
        )));
    }
    if k < 2 || gt.num_frames() != k || result.poses.len() != k || c >= k {
        return Err(Error::InvalidArgument(format!(
            "motion errors: result has {k} frames (canonical {c}), ground truth {}",
            gt.num_frames()
        )));
    }
    if let Some(&l) = pred.iter().find(|&&l| l as usize >= result.parts) {
        return Err(Error::InvalidArgument(format!(
            "motion errors: predicted part {l} ≥ {} parts",
            result.parts
        )));
    }
    if let Some(&l) = gt_labels.iter().find(|&&l| l as usize >= gt.num_parts) {
        return Err(Error::InvalidArgument(format!(
            "motion errors: ground-truth part {l} ≥ {} parts",
            gt.num_parts
        )));
    }
    let gt_inv_c: Vec<DMat4> = gt.poses[c].iter().map(rigid_inverse).collect();
    let mut pred_t: Vec<DMat4> = vec![DMat4::IDENTITY; result.parts];
    let mut gt_t: Vec<DMat4> = vec![DMat4::IDENTITY; gt.num_parts];
    // Positions at the previous frame, for the flow.
    let mut prev_p = vec![DVec3::ZERO; n];
    let mut prev_y = vec![DVec3::ZERO; n];
    let (mut recon_sum, mut flow_sum) = (0.0f64, 0.0f64);
    for t in 0..k {
        if result.poses[t].len() != result.parts {
            return Err(Error::InvalidArgument(format!(
                "motion errors: poses[{t}] has {} parts",
                result.poses[t].len()
            )));
        }
        for (m, r) in pred_t.iter_mut().zip(&result.poses[t]) {
            *m = from_row_major(r);
        }
        for ((m, g), ic) in gt_t.iter_mut().zip(&gt.poses[t]).zip(&gt_inv_c) {
            *m = *g * *ic;
        }
        let (mut recon, mut flow) = (0.0f64, 0.0f64);
        for i in 0..n {
            let x = points[i].as_dvec3();
            let p = pred_t[pred[i] as usize].transform_point3(x);
            let y = gt_t[gt_labels[i] as usize].transform_point3(x);
            recon += (p - y).length();
            if t > 0 {
                flow += ((p - prev_p[i]) - (y - prev_y[i])).length();
            }
            prev_p[i] = p;
            prev_y[i] = y;
        }
        recon_sum += recon / n as f64;
        flow_sum += flow / n as f64;
    }
    Ok(MotionErrors {
        reconstruction: 100.0 * recon_sum / k as f64,
        flow: 100.0 * flow_sum / (k - 1) as f64,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::se3::to_row_major;
    use crate::io::result::{FORMAT, VERSION};

    fn gt_two_parts(shift: f64) -> GroundTruth {
        // Part 0 fixed, part 1 translates by `shift`·t along x; 3 frames.
        let poses = (0..3)
            .map(|t| {
                vec![
                    DMat4::IDENTITY,
                    DMat4::from_translation(DVec3::new(shift * t as f64, 0.0, 0.0)),
                ]
            })
            .collect();
        GroundTruth {
            sequence: "t".into(),
            num_parts: 2,
            parent: vec![-1, 0],
            poses,
            joints: vec![None, None],
            heldout_frames: vec![],
            heldout_poses: vec![],
            variant: "full".into(),
            frames: vec![],
        }
    }

    fn result_from(poses: Vec<Vec<DMat4>>) -> FitResult {
        let k = poses.len();
        let p = poses[0].len();
        FitResult {
            format: FORMAT.into(),
            version: VERSION,
            frames: k,
            canonical_frame: 0,
            parts: p,
            labels: vec![vec![]; k],
            poses: poses
                .iter()
                .map(|f| f.iter().map(to_row_major).collect())
                .collect(),
            gaussians: None,
            tree: None,
            joints: None,
            root_motion: None,
            points: None,
            info: None,
        }
    }

    #[test]
    fn perfect_prediction_is_zero() {
        let gt = gt_two_parts(0.1);
        let r = result_from(gt.poses.clone());
        let pts = [Vec3::ZERO, Vec3::X];
        let e = motion_errors(&r, &gt, &pts, &[0, 1], &[0, 1]).unwrap();
        assert!(e.reconstruction.abs() < 1e-12 && e.flow.abs() < 1e-12);
    }

    #[test]
    fn static_prediction_hand_checked() {
        // Predict nothing moves: the moving point is off by 0.1·t at frame t.
        let gt = gt_two_parts(0.1);
        let r = result_from(vec![vec![DMat4::IDENTITY; 2]; 3]);
        let pts = [Vec3::ZERO, Vec3::X];
        let e = motion_errors(&r, &gt, &pts, &[0, 1], &[0, 1]).unwrap();
        // recon: frames 0,1,2 -> mean over 2 points: 0, 0.05, 0.1 -> mean 0.05 -> ×100 = 5
        assert!((e.reconstruction - 5.0).abs() < 1e-9, "{e:?}");
        // flow: each step the moving point's GT flow is 0.1, predicted 0: mean 0.05 ×100 = 5
        assert!((e.flow - 5.0).abs() < 1e-9, "{e:?}");
    }

    #[test]
    fn wrong_labels_cost_motion() {
        // Right poses, the moving point assigned to the static part.
        let gt = gt_two_parts(0.2);
        let r = result_from(gt.poses.clone());
        let pts = [Vec3::ZERO, Vec3::X];
        let e = motion_errors(&r, &gt, &pts, &[0, 0], &[0, 1]).unwrap();
        // recon: 0, 0.1, 0.2 -> 0.1 -> 10 ; flow: 0.1 per step -> 10
        assert!((e.reconstruction - 10.0).abs() < 1e-9);
        assert!((e.flow - 10.0).abs() < 1e-9);
    }

    #[test]
    fn rejects_mismatched_inputs() {
        let gt = gt_two_parts(0.1);
        let r = result_from(gt.poses.clone());
        assert!(motion_errors(&r, &gt, &[Vec3::ZERO], &[0, 1], &[0]).is_err());
        assert!(motion_errors(&r, &gt, &[Vec3::ZERO], &[2], &[0]).is_err());
        assert!(motion_errors(&r, &gt, &[Vec3::ZERO], &[0], &[9]).is_err());
        assert!(motion_errors(&r, &gt, &[], &[], &[]).is_err());
    }
}
