//! Forward kinematics against every bench-dev ground truth: a ground truth converted to
//! a result reproduces the ground-truth relative poses (canonical frames 0 and 4), and
//! the frame-0 chain of the ground truth does too.

#![allow(clippy::needless_range_loop)] // parallel arrays indexed by part

use std::path::PathBuf;

use glam::DMat4;
use gsart::geom::se3::{from_row_major, rigid_inverse};
use gsart::io::gt::GroundTruth;
use gsart::io::result::FitResult;
use gsart::kinematics::chain::Chain;

const BENCH: &str = "/work/shared/bench-dev/full";

fn sequences() -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(BENCH)
        .expect("bench-dev/full is readable")
        .map(|e| e.unwrap().path())
        .filter(|p| p.join("gt.json").is_file())
        .collect();
    v.sort();
    assert!(v.len() >= 7, "expected the seven bench-dev sequences");
    v
}

fn max_abs(a: &DMat4, b: &DMat4) -> f64 {
    (*a - *b)
        .to_cols_array()
        .iter()
        .fold(0.0f64, |m, x| m.max(x.abs()))
}

#[test]
fn gt_as_result_reproduces_relative_poses() {
    for dir in sequences() {
        let f = dir.join("gt.json");
        let gt = GroundTruth::from_json(&std::fs::read_to_string(&f).unwrap(), "gt.json").unwrap();
        let k = gt.num_frames();
        for c in [0usize, 4] {
            let labels = vec![Vec::new(); k];
            let r = FitResult::from_ground_truth(&gt, labels, c).unwrap();
            // Round trip through the file format on the way.
            let r = FitResult::from_json(&r.to_json(), "r.json").unwrap();
            let chain = Chain::from_result(&r).unwrap();
            let mut worst = 0.0f64;
            for t in 0..k {
                let poses = chain
                    .part_poses(&r.root_pose(t).unwrap(), &r.joint_states(t))
                    .unwrap();
                for p in 0..gt.num_parts {
                    let want = gt.poses[t][p] * rigid_inverse(&gt.poses[c][p]);
                    worst = worst.max(max_abs(&poses[p], &want));
                    worst = worst.max(max_abs(&from_row_major(&r.poses[t][p]), &want));
                }
            }
            println!("{} c={c}: max FK error {worst:.2e}", dir.display());
            assert!(worst < 1e-5, "{}: c={c} FK error {worst}", dir.display());
        }
        // The frame-0 chain of the ground truth itself.
        let chain = Chain::from_gt(&gt).unwrap();
        for t in 0..k {
            let root = gt.parent.iter().position(|&x| x == -1).unwrap();
            let rm = gt.poses[t][root] * rigid_inverse(&gt.poses[0][root]);
            let q: Vec<f64> = gt
                .joints
                .iter()
                .map(|j| j.as_ref().map_or(0.0, |j| j.states[t] - j.states[0]))
                .collect();
            let poses = chain.part_poses(&rm, &q).unwrap();
            for p in 0..gt.num_parts {
                let want = gt.poses[t][p] * rigid_inverse(&gt.poses[0][p]);
                assert!(max_abs(&poses[p], &want) < 1e-5);
            }
        }
    }
}
