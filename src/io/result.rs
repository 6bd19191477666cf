//! The result format (`gsart fit --out`, the page's export), version 1.
//!
//! Readers accept any file with the required keys and ignore keys they do not know
//! (other tools write it too). Matrices are 16 numbers, row-major.

use glam::{DMat3, DMat4, DVec3};
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

/// A Gaussian's placement in one frame (`ResultGaussian::rotation`, row-major, and
/// `center`) moved by the rigid motion `by`.
pub fn moved_placement(by: &DMat4, rotation: &[f64; 9], center: &[f64; 3]) -> ([f64; 9], [f64; 3]) {
    let r = DMat3::from_mat4(*by) * DMat3::from_cols_array(rotation).transpose();
    let c = by.transform_point3(DVec3::from_array(*center));
    (r.transpose().to_cols_array(), c.to_array())
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
    /// This joint follows another (URDF `<mimic>`; `kinematics::mimic`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mimic: Option<Mimic>,
}

/// A joint's coupling to a leader: `state = multiplier · leader's state + offset`.
#[derive(Debug, Clone, Copy, Serialize, Deserialize, PartialEq)]
pub struct Mimic {
    /// The leader, named by its child part (as joints are everywhere: `joint_P`).
    pub joint: usize,
    pub multiplier: f64,
    pub offset: f64,
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
    /// The canonical frame's input points (same order as `labels[canonical_frame]`), so a
    /// shared result can be viewed and re-posed without the input files.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub points: Option<Vec<[f32; 3]>>,
    /// Free-form provenance: options, chosen m, timings, notes (e.g. downsampling).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub info: Option<serde_json::Value>,
}

use crate::geom::se3::{from_row_major, rigid_inverse, to_row_major};
use crate::io::gt::GroundTruth;

impl FitResult {
    /// Whether the fit used the occluded losses (`info.occlusion_used`), when recorded.
    pub fn occlusion_used(&self) -> Option<bool> {
        self.info.as_ref()?.get("occlusion_used")?.as_bool()
    }

    /// Parse and validate a result file. `file` names the source in errors.
    /// Unknown keys are ignored (other tools write this format too).
    pub fn from_json(text: &str, file: &str) -> crate::Result<FitResult> {
        let r: FitResult = serde_json::from_str(text)
            .map_err(|e| crate::Error::input(file, format!("not a valid result file: {e}")))?;
        r.validate(file)?;
        Ok(r)
    }

    /// Pretty-printed JSON of the result.
    pub fn to_json(&self) -> String {
        // Serialising plain numbers and strings cannot fail.
        serde_json::to_string_pretty(self).unwrap_or_default()
    }

    /// Checks the invariants a reader relies on: format and version, sizes of
    /// `labels`, `poses`, `tree`, `joints`, `root_motion`, label ranges and finite numbers.
    pub fn validate(&self, file: &str) -> crate::Result<()> {
        let bad = |p: String| Err(crate::Error::input(file, p));
        if self.format != FORMAT {
            return bad(format!("format is {:?}, expected {FORMAT:?}", self.format));
        }
        if self.version != VERSION {
            return bad(format!(
                "version {} is not supported (expected {VERSION})",
                self.version
            ));
        }
        let (k, p) = (self.frames, self.parts);
        if k == 0 || p == 0 {
            return bad(format!("frames = {k} and parts = {p} must be positive"));
        }
        if self.canonical_frame >= k {
            return bad(format!(
                "canonical_frame {} is not below frames {k}",
                self.canonical_frame
            ));
        }
        if self.labels.len() != k {
            return bad(format!(
                "labels has {} frames, expected {k}",
                self.labels.len()
            ));
        }
        for (f, l) in self.labels.iter().enumerate() {
            if let Some(&x) = l.iter().find(|&&x| x as usize >= p) {
                return bad(format!("labels[{f}] contains part {x} ≥ parts {p}"));
            }
        }
        if self.poses.len() != k {
            return bad(format!(
                "poses has {} frames, expected {k}",
                self.poses.len()
            ));
        }
        for (f, ps) in self.poses.iter().enumerate() {
            if ps.len() != p {
                return bad(format!("poses[{f}] has {} parts, expected {p}", ps.len()));
            }
            if ps.iter().flatten().any(|x| !x.is_finite()) {
                return bad(format!("poses[{f}] contains a non-finite number"));
            }
        }
        if let Some(t) = &self.tree {
            if t.parent.len() != p || t.root >= p || t.parent[t.root] != -1 {
                return bad(format!(
                    "tree: {} parents for {p} parts, root {}",
                    t.parent.len(),
                    t.root
                ));
            }
            if let Some(&x) = t.parent.iter().find(|&&x| x < -1 || x >= p as i64) {
                return bad(format!("tree: parent {x} out of range"));
            }
        }
        for (i, j) in self.joints.iter().flatten().enumerate() {
            if j.child >= p || j.parent >= p {
                return bad(format!(
                    "joints[{i}]: child {} / parent {} not below parts {p}",
                    j.child, j.parent
                ));
            }
            if j.state.len() != k {
                return bad(format!(
                    "joints[{i}]: state has {} entries, expected {k}",
                    j.state.len()
                ));
            }
            if j.axis
                .iter()
                .chain(&j.pivot)
                .chain(&j.state)
                .any(|x| !x.is_finite())
            {
                return bad(format!("joints[{i}] contains a non-finite number"));
            }
        }
        if let Some(rm) = &self.root_motion {
            if rm.len() != k {
                return bad(format!("root_motion has {} frames, expected {k}", rm.len()));
            }
        }
        if let Some(g) = &self.gaussians {
            if let Some((i, _)) = g
                .iter()
                .enumerate()
                .find(|(_, g)| g.part >= p || g.rotation.len() != k || g.center.len() != k)
            {
                return bad(format!("gaussians[{i}] has a bad part or frame count"));
            }
        }
        Ok(())
    }

    /// Pose of part `p` at frame `k` (maps frame c to frame k). Panics never: out of
    /// range gives `None`.
    pub fn pose(&self, k: usize, p: usize) -> Option<DMat4> {
        self.poses.get(k)?.get(p).map(from_row_major)
    }

    /// Root pose at frame `k`: `root_motion[k]` when present, else the tree root's
    /// (or part 0's) entry of `poses[k]`.
    pub fn root_pose(&self, k: usize) -> Option<DMat4> {
        if let Some(rm) = &self.root_motion {
            return rm.get(k).map(from_row_major);
        }
        let root = self.tree.as_ref().map_or(0, |t| t.root);
        self.pose(k, root)
    }

    /// Joint states at frame `k`, indexed by child part (0 for parts without a joint),
    /// as [`crate::kinematics::chain::Chain::part_poses`] takes them.
    pub fn joint_states(&self, k: usize) -> Vec<f64> {
        let mut q = vec![0.0; self.parts];
        for j in self.joints.iter().flatten() {
            if let (Some(slot), Some(&s)) = (q.get_mut(j.child), j.state.get(k)) {
                *slot = s;
            }
        }
        q
    }

    /// A complete result from a ground truth: poses relative to frame `canonical`,
    /// the tree, joints moved to the canonical frame with states relative to it, and
    /// the root motion. `labels` are the per-frame point labels to store.
    pub fn from_ground_truth(
        gt: &GroundTruth,
        labels: Vec<Vec<u32>>,
        canonical: usize,
    ) -> crate::Result<FitResult> {
        let k = gt.num_frames();
        let p = gt.num_parts;
        if canonical >= k {
            return Err(crate::Error::InvalidArgument(format!(
                "canonical frame {canonical} but the ground truth has {k} frames"
            )));
        }
        if labels.len() != k {
            return Err(crate::Error::InvalidArgument(format!(
                "{} label frames for {k} ground-truth frames",
                labels.len()
            )));
        }
        let root =
            gt.parent.iter().position(|&x| x == -1).ok_or_else(|| {
                crate::Error::InvalidArgument("ground truth has no root part".into())
            })?;
        let inv_c: Vec<DMat4> = gt.poses[canonical].iter().map(rigid_inverse).collect();
        let poses: Vec<Vec<[f64; 16]>> = gt
            .poses
            .iter()
            .map(|f| {
                f.iter()
                    .zip(&inv_c)
                    .map(|(m, ic)| to_row_major(&(*m * *ic)))
                    .collect()
            })
            .collect();
        let mut joints = Vec::new();
        for j in gt.joints.iter().flatten() {
            if j.parent_part >= p || j.part >= p || j.states.len() != k {
                return Err(crate::Error::InvalidArgument(format!(
                    "ground-truth joint of part {} is inconsistent",
                    j.part
                )));
            }
            // The axis is fixed in the parent part: carry it from frame 0 to frame c.
            let m = gt.poses[canonical][j.parent_part] * rigid_inverse(&gt.poses[0][j.parent_part]);
            let axis = m.transform_vector3(j.axis_world_frame0).normalize();
            let pivot = m.transform_point3(j.pivot_world_frame0);
            let sc = j.states[canonical];
            let state: Vec<f64> = j.states.iter().map(|s| s - sc).collect();
            let lo = state.iter().copied().fold(f64::INFINITY, f64::min);
            let hi = state.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            joints.push(ResultJoint {
                mimic: None,
                child: j.part,
                parent: j.parent_part,
                joint_type: j.joint_type,
                axis: axis.to_array(),
                pivot: pivot.to_array(),
                state,
                limits: [lo, hi],
            });
        }
        let root_motion = poses.iter().map(|f| f[root]).collect();
        Ok(FitResult {
            format: FORMAT.to_string(),
            version: VERSION,
            frames: k,
            canonical_frame: canonical,
            parts: p,
            labels,
            poses,
            gaussians: None,
            tree: Some(ResultTree {
                root,
                parent: gt.parent.clone(),
            }),
            joints: Some(joints),
            root_motion: Some(root_motion),
            points: None,
            info: Some(serde_json::json!({ "source": "ground truth", "sequence": gt.sequence })),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn minimal() -> String {
        let id = "[1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1]";
        format!(
            r#"{{"format":"gsart-result","version":1,"frames":2,"canonical_frame":0,"parts":2,
            "labels":[[0,1,1],[1,0]],"poses":[[{id},{id}],[{id},{id}]],
            "some_future_key":{{"x":[1,2,3]}},"tree":{{"root":0,"parent":[-1,0],"extra":true}},
            "joints":[{{"child":1,"parent":0,"type":"revolute","axis":[0,0,1],"pivot":[0,0,0],
              "state":[0,0.5],"limits":[0,0.5],"confidence":0.9}}]}}"#
        )
    }

    #[test]
    fn reads_with_unknown_keys_and_round_trips() {
        let r = FitResult::from_json(&minimal(), "r.json").unwrap();
        assert_eq!(r.parts, 2);
        assert_eq!(r.labels[0], vec![0, 1, 1]);
        assert_eq!(r.joints.as_ref().unwrap()[0].state, vec![0.0, 0.5]);
        assert_eq!(r.joint_states(1), vec![0.0, 0.5]);
        let back = FitResult::from_json(&r.to_json(), "r2.json").unwrap();
        assert_eq!(back, r);
    }

    #[test]
    fn rejects_inconsistent_files() {
        let ok = minimal();
        let cases = [
            ok.replace("gsart-result", "other"),
            ok.replace("\"version\":1", "\"version\":2"),
            ok.replace("[[0,1,1],[1,0]]", "[[0,1,1]]"),
            ok.replace("[[0,1,1],[1,0]]", "[[0,1,2],[1,0]]"),
            ok.replace("\"canonical_frame\":0", "\"canonical_frame\":2"),
            ok.replace("\"state\":[0,0.5]", "\"state\":[0]"),
            ok.replace("\"child\":1", "\"child\":2"),
            ok.replace("\"parent\":[-1,0]", "\"parent\":[-1]"),
            ok.replace("\"parts\":2", "\"parts\":3"),
            "{".to_string(),
        ];
        for c in &cases {
            let e = FitResult::from_json(c, "bad.json");
            assert!(e.is_err(), "accepted: {c}");
            assert!(e.unwrap_err().to_string().starts_with("bad.json:"));
        }
    }
}
