//! Metrics of SPEC §5 (Reart-compatible): Rand index, reconstruction and flow
//! error, tree edit distance, re-animation error, plus joint accuracy (type, axis,
//! pivot; issue #4); [`evaluate`] computes them all.

pub mod joint_error;
pub mod motion_error;
pub mod rand_index;
pub mod reanimation;
pub mod tree_edit;

use glam::Vec3;
use serde::{Deserialize, Serialize};

use crate::io::gt::GroundTruth;
use crate::io::result::FitResult;
use crate::kinematics::chain::Chain;
use crate::{Error, Result};

/// All metrics of one result against its ground truth. Errors are ×100 (percent of
/// the object's size on normalised data).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Metrics {
    /// Rand index per frame, averaged over all frames.
    pub mean_ri: f64,
    /// Rand index on the canonical frame.
    pub canonical_ri: f64,
    pub reconstruction_error: f64,
    pub flow_error: f64,
    /// `None` when the result has no tree (Step 1 only) or the tree could not be
    /// compared exactly (see `notes`).
    pub tree_edit_distance: Option<usize>,
    /// `None` when the result has no joints or the ground truth no held-out poses.
    pub reanimation_error: Option<f64>,
    /// Joint type, axis and pivot accuracy; `None` when the result has no joints.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub joints: Option<joint_error::JointErrors>,
    /// Why an optional metric is absent.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub notes: Vec<String>,
}

impl Metrics {
    /// One line for a terminal: the five metrics and the joint accuracy (what `gsart
    /// fit` prints; `gsart eval` gives every field as JSON). An absent metric is "–".
    pub fn summary(&self) -> String {
        let opt = |v: Option<String>| v.unwrap_or_else(|| "–".into());
        let mut s = format!(
            "mean RI {:.3} (canonical frame {:.3}) · recon {:.3} · flow {:.3} · TED {} · re-animation {}",
            self.mean_ri,
            self.canonical_ri,
            self.reconstruction_error,
            self.flow_error,
            opt(self.tree_edit_distance.map(|t| t.to_string())),
            opt(self.reanimation_error.map(|r| format!("{r:.3}"))),
        );
        if let Some(j) = &self.joints {
            s += &format!(
                " · joints: {} of {} found, {} of the right type, {} in the bar (axis ≤ {}°, pivot ≤ {})",
                j.found,
                j.joints,
                j.type_correct,
                j.within_bar,
                joint_error::AXIS_BAR_DEG,
                joint_error::PIVOT_BAR,
            );
        }
        s
    }
}

/// Evaluate `result` against `gt`. `canonical_points` and `canonical_labels` are the
/// observed points of the result's canonical frame with their ground-truth labels
/// (in the order of `result.labels[c]`); `frame_labels[k]` are the ground-truth labels
/// of every point of frame k (in the order of `result.labels[k]`), for the mean RI.
pub fn evaluate(
    result: &FitResult,
    gt: &GroundTruth,
    canonical_points: &[Vec3],
    canonical_labels: &[u32],
    frame_labels: &[Vec<u32>],
) -> Result<Metrics> {
    let k = result.frames;
    let c = result.canonical_frame;
    if gt.num_frames() != k || result.labels.len() != k || frame_labels.len() != k || c >= k {
        return Err(Error::Sequence(format!(
            "the result has {k} frames (labels for {}), the ground truth {} and {} label frames were given",
            result.labels.len(),
            gt.num_frames(),
            frame_labels.len()
        )));
    }
    let pred_c = &result.labels[c];
    if pred_c.len() != canonical_points.len() || canonical_labels.len() != canonical_points.len() {
        return Err(Error::Sequence(format!(
            "canonical frame {c}: {} points, {} ground-truth and {} predicted labels",
            canonical_points.len(),
            canonical_labels.len(),
            pred_c.len()
        )));
    }
    let mut ri_sum = 0.0;
    for (t, (pred, truth)) in result.labels.iter().zip(frame_labels).enumerate() {
        ri_sum += rand_index::rand_index(pred, truth)
            .map_err(|e| Error::Sequence(format!("frame {t}: {e}")))?;
    }
    let mean_ri = ri_sum / k as f64;
    let canonical_ri = rand_index::rand_index(pred_c, canonical_labels)?;
    let motion =
        motion_error::motion_errors(result, gt, canonical_points, pred_c, canonical_labels)?;

    let mut notes = Vec::new();
    let chain = match &result.tree {
        Some(_) => Some(Chain::from_result(result)?),
        None => None,
    };
    let tree_edit_distance = match &chain {
        Some(ch) => match tree_edit::tree_edit_distance(ch.parent(), &gt.parent) {
            Ok(d) => Some(d),
            Err(e) => {
                notes.push(e.to_string());
                None
            }
        },
        None => {
            notes.push("no kinematic tree in the result: no tree edit distance".into());
            None
        }
    };
    let reanimation_error = match (&chain, &result.joints) {
        (Some(ch), Some(_)) if !gt.heldout_poses.is_empty() => {
            let root0 = result
                .root_pose(0)
                .ok_or_else(|| Error::Sequence("the result has no root pose at frame 0".into()))?;
            Some(reanimation::reanimation_error(
                ch,
                &root0,
                gt,
                c,
                canonical_points,
                pred_c,
                canonical_labels,
            )?)
        }
        (Some(_), Some(_)) => {
            notes.push("no held-out poses in the ground truth: no re-animation error".into());
            None
        }
        _ => {
            notes.push("no joints in the result: no re-animation error".into());
            None
        }
    };
    let joints = match &result.joints {
        Some(_) => Some(joint_error::joint_errors(
            result,
            gt,
            canonical_points,
            pred_c,
            canonical_labels,
        )?),
        None => None,
    };
    Ok(Metrics {
        mean_ri,
        canonical_ri,
        reconstruction_error: motion.reconstruction,
        flow_error: motion.flow,
        tree_edit_distance,
        reanimation_error,
        joints,
        notes,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_summary_names_every_metric_and_the_joints_in_the_bar() {
        let mut m = Metrics {
            mean_ri: 0.93049,
            canonical_ri: 0.9,
            reconstruction_error: 0.3,
            flow_error: 0.28,
            tree_edit_distance: Some(1),
            reanimation_error: None,
            joints: Some(joint_error::JointErrors {
                joints: 6,
                found: 4,
                type_correct: 3,
                max_axis_deg: Some(7.0),
                max_pivot_error: Some(1.0),
                within_bar: 2,
                per_joint: Vec::new(),
            }),
            notes: Vec::new(),
        };
        assert_eq!(
            m.summary(),
            "mean RI 0.930 (canonical frame 0.900) · recon 0.300 · flow 0.280 · TED 1 · \
             re-animation – · joints: 4 of 6 found, 3 of the right type, 2 in the bar \
             (axis ≤ 5°, pivot ≤ 2)"
        );
        m.joints = None;
        m.tree_edit_distance = None;
        assert!(
            m.summary().ends_with("TED – · re-animation –"),
            "{}",
            m.summary()
        );
    }
}
