//! The result format (`gsart fit --out`, the page's export), version 1.
//!
//! Readers accept any file with the required keys and ignore keys they do not know
//! (other tools write it too). Matrices are 16 numbers, row-major.

use serde::{Deserialize, Serialize};

use crate::io::gt::JointType;

pub const FORMAT: &str = "gsart-result";
pub const VERSION: u32 = 1;

/// One Gaussian of the Step-1 model.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct ResultGaussian {
    /// Part (after merging) this Gaussian belongs to.
    pub part: usize,
    /// Shared scale (standard deviations along the local axes, not log).
    pub scale: [f64; 3],
    /// Per-frame rotation, 9 numbers row-major.
    pub rotation: Vec<[f64; 9]>,
    /// Per-frame centre.
    pub center: Vec<[f64; 3]>,
}

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct ResultTree {
    pub root: usize,
    /// Parent per part, −1 for the root.
    pub parent: Vec<i64>,
}

#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct ResultJoint {
    pub child: usize,
    pub parent: usize,
    #[serde(rename = "type")]
    pub joint_type: JointType,
    /// Unit axis, world frame at the canonical frame.
    pub axis: [f64; 3],
    /// A point on a revolute axis (world, canonical frame); the joint origin for prismatic.
    pub pivot: [f64; 3],
    /// State per frame; 0 at the canonical frame.
    pub state: Vec<f64>,
    pub limits: [f64; 2],
}

/// A fitted (or ground-truth-derived) articulated model of one sequence.
#[derive(Debug, Clone, Serialize, Deserialize, PartialEq)]
pub struct FitResult {
    pub format: String,
    pub version: u32,
    pub frames: usize,
    pub canonical_frame: usize,
    pub parts: usize,
    /// `labels[k][n]`: part of input point n of frame k, for every input point.
    pub labels: Vec<Vec<u32>>,
    /// `poses[k][p]`: row-major 4×4 mapping part p's points from frame c to frame k.
    pub poses: Vec<Vec<[f64; 16]>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gaussians: Option<Vec<ResultGaussian>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tree: Option<ResultTree>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub joints: Option<Vec<ResultJoint>>,
    /// Root part pose per frame (maps frame c to frame k).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub root_motion: Option<Vec<[f64; 16]>>,
    /// Free-form provenance: options, chosen m, timings, notes (e.g. downsampling).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub info: Option<serde_json::Value>,
}
