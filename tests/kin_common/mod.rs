//! Shared helpers of the kinematics integration tests: bench-dev sequence loading
//! (through `io::ply::read_ply`) and the tree/joint error evaluation.
#![allow(dead_code)]

use std::path::{Path, PathBuf};

use glam::{DVec3, Vec3};
use gsart::io::gt::GroundTruth;
use gsart::io::result::FitResult;
use gsart::kinematics::screw::{axis_angle_deg, point_line_distance};
use gsart::kinematics::tree::reroot;

pub const BENCH: &str = "/work/shared/bench-dev/full";

/// Points and ground-truth labels of a bench-dev PLY frame (the crate's reader).
pub fn read_bench_ply(path: &Path) -> (Vec<Vec3>, Vec<u32>) {
    let bytes = std::fs::read(path).unwrap();
    let cloud = gsart::io::ply::read_ply(&bytes, &path.to_string_lossy()).unwrap();
    let labels = cloud
        .labels
        .expect("bench-dev frames carry a `part` property");
    (cloud.points, labels)
}

pub struct Seq {
    pub name: String,
    pub gt: GroundTruth,
    pub points: Vec<Vec<Vec3>>,
    pub labels: Vec<Vec<u32>>,
}

pub fn load(dir: &Path) -> Seq {
    let text = std::fs::read_to_string(dir.join("gt.json")).unwrap();
    let gt = GroundTruth::from_json(&text, "gt.json").unwrap();
    let (points, labels) = gt
        .frames
        .iter()
        .map(|f| read_bench_ply(&dir.join(f)))
        .unzip();
    Seq {
        name: dir.file_name().unwrap().to_string_lossy().into_owned(),
        gt,
        points,
        labels,
    }
}

pub fn sequences() -> Vec<PathBuf> {
    let Ok(rd) = std::fs::read_dir(BENCH) else {
        return vec![];
    };
    let mut v: Vec<PathBuf> = rd.flatten().map(|e| e.path()).collect();
    v.sort();
    v
}

pub struct Errors {
    pub tree_mismatch: usize,
    pub root: usize,
    pub type_errors: usize,
    pub max_axis_deg: f64,
    pub max_pivot: f64,
    /// Per matched joint: (child, axis error °, pivot error).
    pub per_joint: Vec<(usize, f64, f64)>,
}

/// Tree, joint-type, axis and pivot errors of a result against the ground truth.
pub fn evaluate(seq: &Seq, res: &FitResult) -> Errors {
    let gt = &seq.gt;
    let tree = res.tree.as_ref().unwrap();
    let gt_rerooted = reroot(&gt.parent, tree.root);
    let tree_mismatch = gt_rerooted
        .iter()
        .zip(&tree.parent)
        .filter(|(a, b)| a != b)
        .count();
    let mut type_errors = 0;
    let mut max_axis_deg: f64 = 0.0;
    let mut max_pivot: f64 = 0.0;
    let mut per_joint = Vec::new();
    let c = res.canonical_frame;
    for j in res.joints.as_ref().unwrap() {
        // The ground-truth joint of this (undirected) edge.
        let g = if gt.parent[j.child] == j.parent as i64 {
            gt.joints[j.child].as_ref()
        } else if gt.parent[j.parent] == j.child as i64 {
            gt.joints[j.parent].as_ref()
        } else {
            None
        };
        let Some(g) = g else { continue };
        if g.joint_type != j.joint_type {
            type_errors += 1;
            continue;
        }
        // GT axis/pivot are at frame 0; move them to the canonical frame with the
        // parent part's motion.
        let m = gt.poses[c][g.parent_part]
            * gsart::geom::se3::rigid_inverse(&gt.poses[0][g.parent_part]);
        let gaxis = m.transform_vector3(g.axis_world_frame0);
        let gpivot = m.transform_point3(g.pivot_world_frame0);
        let axis = DVec3::from(j.axis);
        let pivot = DVec3::from(j.pivot);
        let ad = axis_angle_deg(axis, gaxis);
        max_axis_deg = max_axis_deg.max(ad);
        let mut pd = 0.0;
        if g.joint_type == gsart::io::gt::JointType::Revolute {
            let d = point_line_distance(pivot, gpivot, gaxis)
                .max(point_line_distance(gpivot, pivot, axis));
            max_pivot = max_pivot.max(d);
            pd = d;
        }
        per_joint.push((j.child, ad, pd));
    }
    Errors {
        tree_mismatch,
        root: tree.root,
        type_errors,
        max_axis_deg,
        max_pivot,
        per_joint,
    }
}
