//! Steps 2–3 on every bench-dev `full/` sequence with ground-truth labels and poses as
//! input: the tree must match the ground truth (TED 0 up to the root choice), every
//! joint type must be right, axes within 5°, revolute pivots within 2% of the object
//! size, and no two distinct ground-truth parts may be merged.

use glam::DMat4;
use gsart::io::gt::GroundTruth;
use gsart::io::result::FitResult;
use gsart::kinematics::chain::Chain;
use gsart::kinematics::{build_articulated, KinOptions};
use gsart::pipeline::Control;

mod kin_common;
use kin_common::{evaluate, load, sequences, Errors, Seq, BENCH};

fn run(seq: &Seq, opts: &KinOptions) -> (FitResult, gsart::kinematics::KinReport, f64) {
    let t0 = std::time::Instant::now();
    let (res, rep) = build_articulated(
        &seq.points,
        &seq.labels,
        &seq.gt.poses,
        0,
        opts,
        &|| 0.0,
        &mut |_| Control::Continue,
    )
    .unwrap();
    (res, rep, t0.elapsed().as_secs_f64())
}

/// The result validates, and its poses are `Chain` forward kinematics of its joints.
fn assert_fk_consistent(name: &str, res: &FitResult) {
    res.validate(name).unwrap();
    let chain = Chain::from_result(res).unwrap();
    for k in 0..res.frames {
        let poses = chain
            .part_poses(&res.root_pose(k).unwrap(), &res.joint_states(k))
            .unwrap();
        for (p, m) in poses.iter().enumerate() {
            assert!(
                m.abs_diff_eq(res.pose(k, p).unwrap(), 1e-9),
                "{name} frame {k} part {p}"
            );
        }
    }
}

fn check(
    seq: &Seq,
    res: &FitResult,
    rep: &gsart::kinematics::KinReport,
    fk_exact: bool,
    failures: &mut Vec<String>,
) -> Errors {
    let merged_ok = rep.parts == seq.gt.num_parts
        && rep
            .merge_map
            .iter()
            .enumerate()
            .all(|(i, &m)| m as usize == i);
    if !merged_ok {
        failures.push(format!(
            "{}: merged distinct parts {:?}",
            seq.name, rep.merge_log
        ));
    }
    if fk_exact {
        assert_fk_consistent(&seq.name, res);
    } else {
        res.validate(&seq.name).unwrap();
    }
    let e = evaluate(seq, res);
    if e.tree_mismatch != 0 || e.type_errors != 0 || e.max_axis_deg > 5.0 || e.max_pivot > 0.02 {
        failures.push(format!(
            "{}: tree {} types {} axis {} pivot {}",
            seq.name, e.tree_mismatch, e.type_errors, e.max_axis_deg, e.max_pivot
        ));
    }
    e
}

#[test]
fn gt_input_recovers_tree_and_joints() {
    let seqs = sequences();
    if seqs.is_empty() {
        eprintln!("skip: {BENCH} not present");
        return;
    }
    let mut failures = Vec::new();
    for dir in seqs {
        let seq = load(&dir);
        // Projection only, poses not polished: exact on exact input.
        let opts = KinOptions {
            refine: None,
            polish: false,
            ..Default::default()
        };
        let (res, rep, secs) = run(&seq, &opts);
        let e = check(&seq, &res, &rep, true, &mut failures);
        // Exact true motions need no repair (`kinematics::flips`).
        if rep.flips != 0 {
            failures.push(format!(
                "{}: {} turns repaired on true motions",
                seq.name, rep.flips
            ));
        }
        eprintln!(
            "{:<18} projection: parts {:>2}/{:<2} root {:>2} tree-mismatch {} type-errors {} max-axis {:.4}° max-pivot {:.5} spacing {:.4} merges {} ({secs:.2}s)",
            seq.name, rep.parts, seq.gt.num_parts, e.root, e.tree_mismatch, e.type_errors,
            e.max_axis_deg, e.max_pivot, rep.spacing, rep.merge_log.len()
        );
        // Output poses are the chain's forward kinematics and match the observed motion.
        for t in 0..res.frames {
            for p in 0..res.parts {
                let m = gsart::geom::se3::from_row_major(&res.poses[t][p]);
                let obs: DMat4 =
                    seq.gt.poses[t][p] * gsart::geom::se3::rigid_inverse(&seq.gt.poses[0][p]);
                assert!(m.abs_diff_eq(obs, 1e-6), "{} frame {t} part {p}", seq.name);
            }
        }
        // With refinement (Chamfer against the observed clouds).
        let (res, rep, secs) = run(&seq, &KinOptions::default());
        // With the polish, the repair may turn a symmetric link back about its axis
        // where the ICP polish spun it (a flat direction of its fit: laikago, solo12
        // and talos, 13–22°); the poses must still end up on the truth (below).
        // The reported poses are not all the refined chain's: where the refinement
        // moved a part off its observed motion (the true one here) and the data agree,
        // the observed motion is reported, then every pose is polished against the
        // clouds (`kinematics::observed`). They stay close to the truth.
        let e = check(&seq, &res, &rep, false, &mut failures);
        // Mean displacement ×100 of the canonical points between the reported and the
        // true motion (the reconstruction error with ground-truth labels).
        let (mut sum, mut n) = (0.0f64, 0usize);
        for t in 0..res.frames {
            for (x, &l) in seq.points[0].iter().zip(&seq.labels[0]) {
                let p = l as usize;
                let m = gsart::geom::se3::from_row_major(&res.poses[t][p]);
                let obs: DMat4 =
                    seq.gt.poses[t][p] * gsart::geom::se3::rigid_inverse(&seq.gt.poses[0][p]);
                let x = x.as_dvec3();
                sum += (m.transform_point3(x) - obs.transform_point3(x)).length();
                n += 1;
            }
        }
        let off = 100.0 * sum / n.max(1) as f64;
        if off > 0.2 {
            failures.push(format!(
                "{}: reported poses {off:.3} off the truth",
                seq.name
            ));
        }
        let r = rep.refine.as_ref().unwrap();
        eprintln!(
            "{:<18} refined:    accepted {} loss {:.6} -> {:.6} max-axis {:.4}° max-pivot {:.5} poses replaced {} off the truth {off:.3} ({secs:.2}s)",
            seq.name, r.accepted, r.loss_before, r.loss_after, e.max_axis_deg, e.max_pivot, rep.poses_replaced
        );
    }
    assert!(failures.is_empty(), "{failures:#?}");
}

/// Measurement: smallest L_merge over ground-truth joints, paper form vs the one used.
#[test]
fn merge_margins() {
    use gsart::kinematics::merge::{merge_loss, merge_loss_consecutive};
    for dir in sequences() {
        let text = std::fs::read_to_string(dir.join("gt.json")).unwrap();
        let gt = GroundTruth::from_json(&text, "gt.json").unwrap();
        let (mut a, mut c) = (f64::INFINITY, f64::INFINITY);
        for p in 1..gt.num_parts {
            let q = gt.parent[p] as usize;
            a = a.min(merge_loss_consecutive(&gt.poses, q, p));
            c = c.min(merge_loss(&gt.poses, q, p));
        }
        eprintln!(
            "{:?}: min L_merge over GT joints: consecutive {a:.4} all-pairs {c:.4}",
            dir.file_name().unwrap()
        );
        assert!(c > 3e-2, "{dir:?}: a ground-truth joint would be merged");
    }
}

/// so101 with ground-truth labels and poses, but the lower arm (part 3, a nearly
/// symmetric link) turned half a turn about its long axis in frames 3–8, as Step 1's
/// pose search sometimes finds it: the half-turn repair (`kinematics::flips`) puts it
/// back, and the tree, joints and reported poses are those of the true motion. Without
/// the repair they are not.
#[test]
fn half_turned_link_is_repaired() {
    use glam::{DMat3, DVec3};
    let dir = std::path::Path::new(BENCH).join("so101_00");
    if !dir.exists() {
        eprintln!("skip: {dir:?} not present");
        return;
    }
    let mut seq = load(&dir);
    let part = 3;
    let pts: Vec<DVec3> = seq.points[0]
        .iter()
        .zip(&seq.labels[0])
        .filter(|(_, &l)| l == part)
        .map(|(x, _)| x.as_dvec3())
        .collect();
    let c = pts.iter().copied().sum::<DVec3>() / pts.len() as f64;
    let mut cov = nalgebra::Matrix3::<f64>::zeros();
    for x in &pts {
        let d = nalgebra::Vector3::new(x.x - c.x, x.y - c.y, x.z - c.z);
        cov += d * d.transpose();
    }
    let e = nalgebra::SymmetricEigen::new(cov);
    let (long, _) = e
        .eigenvalues
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.total_cmp(b.1))
        .unwrap();
    let v = e.eigenvectors.column(long);
    let r = DMat3::from_axis_angle(
        DVec3::new(v[0], v[1], v[2]).normalize(),
        std::f64::consts::PI,
    );
    let flip = DMat4::from_mat3(r) * DMat4::from_translation(-c);
    let flip = DMat4::from_translation(c) * flip;
    let truth = seq.gt.poses.clone();
    let p = part as usize;
    let t0 = gsart::geom::se3::rigid_inverse(&truth[0][p]);
    for t in 3..=8 {
        seq.gt.poses[t][p] = truth[t][p] * t0 * flip * truth[0][p];
    }
    // Reported poses' mean displacement ×100 from the true motion over part 3's points.
    let off = |res: &FitResult| {
        let (mut sum, mut n) = (0.0f64, 0usize);
        for (poses, true_poses) in res.poses.iter().zip(&truth) {
            for (x, &l) in seq.points[0].iter().zip(&seq.labels[0]) {
                if l != part {
                    continue;
                }
                let m = gsart::geom::se3::from_row_major(&poses[p]);
                let obs: DMat4 = true_poses[p] * t0;
                sum += (m.transform_point3(x.as_dvec3()) - obs.transform_point3(x.as_dvec3()))
                    .length();
                n += 1;
            }
        }
        100.0 * sum / n as f64
    };
    let (res, rep, _) = run(&seq, &KinOptions::default());
    let mut failures = Vec::new();
    let e = check(&seq, &res, &rep, false, &mut failures);
    eprintln!(
        "repaired: flips {} tree-mismatch {} max-axis {:.3}° part 3 off {:.3}",
        rep.flips,
        e.tree_mismatch,
        e.max_axis_deg,
        off(&res)
    );
    assert!(failures.is_empty(), "{failures:#?}");
    assert_eq!(rep.flips, 6);
    assert!(off(&res) < 0.5, "{}", off(&res));
    let no_repair = KinOptions {
        flips: false,
        ..Default::default()
    };
    let (res, _, _) = run(&seq, &no_repair);
    eprintln!("without the repair: part 3 off {:.3}", off(&res));
    // 2.58 before near-parallel axes were tied (session 44), 1.93 since: the tie
    // straightens part of the half-turned link's hinge, the repair the rest (0.08).
    assert!(off(&res) > 1.5, "{}", off(&res));
}
