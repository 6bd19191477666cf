//! Ground truth in the benchmark format (`gt.json`, see `../shared/bench-dev/README.md`):
//! part tree, per-frame part poses, joints with per-frame states, held-out poses.
//! The procedural generator writes the same format.

use glam::{DMat4, DVec3};
use serde::{Deserialize, Serialize};

use crate::geom::se3::{from_nested, to_nested};

/// Joint type of a 1-DOF joint.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum JointType {
    Revolute,
    Prismatic,
}

/// The joint connecting a part to its parent.
#[derive(Debug, Clone)]
pub struct GtJoint {
    pub part: usize,
    pub parent_part: usize,
    pub name: String,
    pub joint_type: JointType,
    /// Unit axis, world frame at frame 0.
    pub axis_world_frame0: DVec3,
    /// A point on the axis, world frame at frame 0.
    pub pivot_world_frame0: DVec3,
    /// State per frame (radians or normalised length).
    pub states: Vec<f64>,
    /// State per held-out pose.
    pub heldout_states: Vec<f64>,
}

/// Ground truth of one sequence.
#[derive(Debug, Clone)]
pub struct GroundTruth {
    pub sequence: String,
    pub num_parts: usize,
    /// Parent part per part, −1 for the root.
    pub parent: Vec<i64>,
    /// `poses[t][p]`: world pose of part p at frame t.
    pub poses: Vec<Vec<DMat4>>,
    /// `joints[p]`: `None` for the root.
    pub joints: Vec<Option<GtJoint>>,
    /// Held-out frame files (relative to the sequence folder) and their poses `[h][p]`.
    pub heldout_frames: Vec<String>,
    pub heldout_poses: Vec<Vec<DMat4>>,
    /// `full`, `occluded` or `partial` when known.
    pub variant: String,
    /// Frame file names in time order.
    pub frames: Vec<String>,
}

// ---- serde mirror of gt.json (unknown keys are ignored) ----

#[derive(Debug, Serialize, Deserialize)]
pub(crate) struct RawJoint {
    pub part: usize,
    pub parent_part: usize,
    #[serde(default)]
    pub name: String,
    #[serde(rename = "type")]
    pub joint_type: JointType,
    pub axis_world_frame0: [f64; 3],
    pub pivot_world_frame0: [f64; 3],
    pub states: Vec<f64>,
    #[serde(default)]
    pub heldout_states: Vec<f64>,
}

#[derive(Debug, Default, Serialize, Deserialize)]
pub(crate) struct RawHeldout {
    #[serde(default)]
    pub frames: Vec<String>,
    #[serde(default)]
    pub poses: Vec<Vec<[[f64; 4]; 4]>>,
}

#[derive(Debug, Serialize, Deserialize)]
pub(crate) struct RawGt {
    #[serde(default)]
    pub format_version: u32,
    #[serde(default)]
    pub sequence: String,
    pub num_parts: usize,
    pub parent: Vec<i64>,
    pub poses: Vec<Vec<[[f64; 4]; 4]>>,
    pub joints: Vec<Option<RawJoint>>,
    #[serde(default)]
    pub heldout: RawHeldout,
    #[serde(default)]
    pub variant: String,
    #[serde(default)]
    pub frames: Vec<String>,
}

impl GroundTruth {
    /// Parse `gt.json` text. `file` names the source in errors.
    pub fn from_json(text: &str, file: &str) -> crate::Result<Self> {
        let raw: RawGt = serde_json::from_str(text)
            .map_err(|e| crate::Error::input(file, format!("not a valid gt.json: {e}")))?;
        Self::from_raw(raw, file)
    }

    pub(crate) fn from_raw(raw: RawGt, file: &str) -> crate::Result<Self> {
        let bad = |p: String| crate::Error::input(file, p);
        let p = raw.num_parts;
        if p == 0 || raw.parent.len() != p || raw.joints.len() != p {
            return Err(bad(format!(
                "num_parts {} but {} parents and {} joints",
                p,
                raw.parent.len(),
                raw.joints.len()
            )));
        }
        if raw.poses.iter().any(|f| f.len() != p) {
            return Err(bad(
                "a frame of `poses` does not have num_parts entries".into()
            ));
        }
        let k = raw.poses.len();
        let joints = raw
            .joints
            .into_iter()
            .map(|j| {
                j.map(|j| GtJoint {
                    part: j.part,
                    parent_part: j.parent_part,
                    name: j.name,
                    joint_type: j.joint_type,
                    axis_world_frame0: DVec3::from(j.axis_world_frame0),
                    pivot_world_frame0: DVec3::from(j.pivot_world_frame0),
                    states: j.states,
                    heldout_states: j.heldout_states,
                })
            })
            .collect::<Vec<_>>();
        for j in joints.iter().flatten() {
            if j.part >= p || j.parent_part >= p || j.states.len() != k {
                return Err(bad(format!("joint of part {} is inconsistent", j.part)));
            }
        }
        Ok(GroundTruth {
            sequence: raw.sequence,
            num_parts: p,
            parent: raw.parent,
            poses: raw
                .poses
                .iter()
                .map(|f| f.iter().map(from_nested).collect())
                .collect(),
            joints,
            heldout_frames: raw.heldout.frames,
            heldout_poses: raw
                .heldout
                .poses
                .iter()
                .map(|f| f.iter().map(from_nested).collect())
                .collect(),
            variant: raw.variant,
            frames: raw.frames,
        })
    }

    /// Serialise in the benchmark format (the subset of keys this crate reads, plus
    /// `format_version`); used by the procedural generator.
    pub fn to_json(&self) -> String {
        let raw = RawGt {
            format_version: 1,
            sequence: self.sequence.clone(),
            num_parts: self.num_parts,
            parent: self.parent.clone(),
            poses: self
                .poses
                .iter()
                .map(|f| f.iter().map(to_nested).collect())
                .collect(),
            joints: self
                .joints
                .iter()
                .map(|j| {
                    j.as_ref().map(|j| RawJoint {
                        part: j.part,
                        parent_part: j.parent_part,
                        name: j.name.clone(),
                        joint_type: j.joint_type,
                        axis_world_frame0: j.axis_world_frame0.to_array(),
                        pivot_world_frame0: j.pivot_world_frame0.to_array(),
                        states: j.states.clone(),
                        heldout_states: j.heldout_states.clone(),
                    })
                })
                .collect(),
            heldout: RawHeldout {
                frames: self.heldout_frames.clone(),
                poses: self
                    .heldout_poses
                    .iter()
                    .map(|f| f.iter().map(to_nested).collect())
                    .collect(),
            },
            variant: self.variant.clone(),
            frames: self.frames.clone(),
        };
        // Serialising plain numbers and strings cannot fail.
        serde_json::to_string_pretty(&raw).unwrap_or_default()
    }

    pub fn num_frames(&self) -> usize {
        self.poses.len()
    }
}
