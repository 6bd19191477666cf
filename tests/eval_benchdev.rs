//! Metrics on the bench-dev sequences: the ground truth converted to a result must
//! score perfectly (RI 1, reconstruction 0, flow 0, TED 0, re-animation ≈ 0), and
//! damaged results must score worse.

use std::path::{Path, PathBuf};

use glam::Vec3;
use gsart::eval::{evaluate, Metrics};
use gsart::io::gt::GroundTruth;
use gsart::io::result::FitResult;

const BENCH: &str = "/work/shared/bench-dev";

/// Test-only reader of the fixed bench-dev binary layout (header, then records of
/// x, y, z f32 LE + part i32 LE), until the crate's PLY reader lands.
fn read_bench_ply(path: &Path) -> (Vec<Vec3>, Vec<u32>) {
    let bytes = std::fs::read(path).unwrap();
    let marker = b"end_header\n";
    let start = bytes
        .windows(marker.len())
        .position(|w| w == marker)
        .expect("PLY header")
        + marker.len();
    let header = std::str::from_utf8(&bytes[..start]).unwrap();
    assert!(header.contains("binary_little_endian"));
    let n: usize = header
        .lines()
        .find_map(|l| l.strip_prefix("element vertex "))
        .unwrap()
        .trim()
        .parse()
        .unwrap();
    let body = &bytes[start..];
    assert_eq!(body.len(), 16 * n);
    let f = |o: usize| f32::from_le_bytes(body[o..o + 4].try_into().unwrap());
    let mut pts = Vec::with_capacity(n);
    let mut lab = Vec::with_capacity(n);
    for i in 0..n {
        let o = 16 * i;
        pts.push(Vec3::new(f(o), f(o + 4), f(o + 8)));
        lab.push(i32::from_le_bytes(body[o + 12..o + 16].try_into().unwrap()) as u32);
    }
    (pts, lab)
}

struct Seq {
    name: String,
    gt: GroundTruth,
    points: Vec<Vec<Vec3>>,
    labels: Vec<Vec<u32>>,
}

fn load(variant: &str) -> Vec<Seq> {
    let mut dirs: Vec<PathBuf> = std::fs::read_dir(Path::new(BENCH).join(variant))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.join("gt.json").is_file())
        .collect();
    dirs.sort();
    assert!(dirs.len() >= 7);
    dirs.iter()
        .map(|d| {
            let gt = GroundTruth::from_json(
                &std::fs::read_to_string(d.join("gt.json")).unwrap(),
                "gt.json",
            )
            .unwrap();
            let (points, labels) = gt.frames.iter().map(|f| read_bench_ply(&d.join(f))).unzip();
            Seq {
                name: d.file_name().unwrap().to_string_lossy().into_owned(),
                gt,
                points,
                labels,
            }
        })
        .collect()
}

fn eval(s: &Seq, r: &FitResult) -> Metrics {
    let c = r.canonical_frame;
    evaluate(r, &s.gt, &s.points[c], &s.labels[c], &s.labels).unwrap()
}

#[test]
fn ground_truth_scores_perfectly_full() {
    for s in load("full") {
        for c in [0usize, 4] {
            let r = FitResult::from_ground_truth(&s.gt, s.labels.clone(), c).unwrap();
            let t = std::time::Instant::now();
            let m = eval(&s, &r);
            println!(
                "{} c={c}: {m:?} ({:.0} ms)",
                s.name,
                t.elapsed().as_secs_f64() * 1e3
            );
            assert_eq!(m.mean_ri, 1.0);
            assert_eq!(m.canonical_ri, 1.0);
            assert!(m.reconstruction_error < 1e-4, "{}", s.name);
            assert!(m.flow_error < 1e-4, "{}", s.name);
            assert_eq!(m.tree_edit_distance, Some(0));
            let re = m.reanimation_error.unwrap();
            assert!(re < 0.05, "{} c={c}: re-animation {re}", s.name);
        }
    }
}

#[test]
fn ground_truth_scores_perfectly_occluded() {
    for s in load("occluded") {
        // Canonical frame: the one with the most points (whole parts may vanish).
        let c = (0..s.points.len())
            .max_by_key(|&k| s.points[k].len())
            .unwrap();
        let r = FitResult::from_ground_truth(&s.gt, s.labels.clone(), c).unwrap();
        let m = eval(&s, &r);
        println!("{} (occluded) c={c}: {m:?}", s.name);
        assert_eq!(m.mean_ri, 1.0);
        assert!(m.reconstruction_error < 1e-4 && m.flow_error < 1e-4);
        assert_eq!(m.tree_edit_distance, Some(0));
        assert!(m.reanimation_error.unwrap() < 0.05, "{}", s.name);
    }
}

#[test]
fn damaged_results_score_worse() {
    let seqs = load("full");
    let s = seqs.iter().find(|s| s.name.starts_with("xarm7")).unwrap();
    let c = 0;
    let good = FitResult::from_ground_truth(&s.gt, s.labels.clone(), c).unwrap();

    // Step-1-only result: no tree, no joints.
    let mut step1 = good.clone();
    step1.tree = None;
    step1.joints = None;
    step1.root_motion = None;
    let m = eval(s, &step1);
    assert_eq!(m.tree_edit_distance, None);
    assert_eq!(m.reanimation_error, None);
    assert_eq!(m.mean_ri, 1.0);

    // Merge the last part into its parent everywhere (labels and poses).
    let last = (s.gt.num_parts - 1) as u32;
    let parent = s.gt.parent[last as usize] as u32;
    let mut merged = good.clone();
    for l in merged.labels.iter_mut().flatten() {
        if *l == last {
            *l = parent;
        }
    }
    let m = eval(s, &merged);
    println!("merged last part: {m:?}");
    assert!(m.mean_ri < 1.0 && m.canonical_ri < 1.0);
    assert!(m.reconstruction_error > 0.01 && m.flow_error > 0.01);
    assert!(m.reanimation_error.unwrap() > 0.05);

    // Drop the last part from the tree: TED 1.
    let mut pruned = good.clone();
    let p = good.parts - 1;
    pruned.parts = p;
    pruned.labels = merged.labels.clone();
    pruned.poses.iter_mut().for_each(|f| f.truncate(p));
    pruned.tree.as_mut().unwrap().parent.truncate(p);
    pruned.joints.as_mut().unwrap().retain(|j| j.child < p);
    let m = eval(s, &pruned);
    assert_eq!(m.tree_edit_distance, Some(1));

    // A wrong joint axis: the poses are still right, re-animation is not.
    let mut tilted = good.clone();
    let j = &mut tilted.joints.as_mut().unwrap()[0];
    j.axis = [j.axis[1], j.axis[2], j.axis[0]];
    let m = eval(s, &tilted);
    println!("tilted first joint: {m:?}");
    assert!(m.reconstruction_error < 1e-4);
    assert!(m.reanimation_error.unwrap() > 0.5);
}

#[test]
fn reanimation_protocols_on_ground_truth() {
    // The plain SPEC protocol (Adam from zero) vs the default, per held-out pose.
    use gsart::eval::reanimation::{reanimation_errors_with, IkOptions};
    use gsart::kinematics::chain::Chain;
    for s in load("full") {
        let c = 0;
        let r = FitResult::from_ground_truth(&s.gt, s.labels.clone(), c).unwrap();
        let ch = Chain::from_result(&r).unwrap();
        let run = |o: &IkOptions| {
            reanimation_errors_with(
                &ch,
                &r.root_pose(0).unwrap(),
                &s.gt,
                c,
                &s.points[c],
                &s.labels[c],
                &s.labels[c],
                o,
            )
            .unwrap()
        };
        let strict = run(&IkOptions::spec_strict());
        let default = run(&IkOptions::default());
        println!(
            "{}: spec-strict {strict:.4?}  default {default:.6?}",
            s.name
        );
        assert!(default.iter().all(|&e| e < 0.05));
        assert!(default.iter().zip(&strict).all(|(d, s)| *d <= *s + 1e-9));
    }
}
