//! Steps 2–3 on bench-dev sequences with *imperfect* Step-1-like input: every part pose
//! gets independent noise (rotation σ = 0.3° per axis, translation σ = 0.001 object
//! sizes; at 3× that, split halves exceed the paper's merge threshold 3e-2 — printed) and the largest part is over-segmented into two halves with independently
//! noisy poses. The halves must be merged back, the tree and joint types must be
//! right, and axes/pivots close. Prints projection-only vs refined errors.

use gsart::math::Libm;
mod kin_common;

use glam::{DMat4, DVec3};
use gsart::geom::se3::rigid_inverse;
use gsart::kinematics::merge::merge_loss;
use gsart::kinematics::refine::RefineOptions;
use gsart::kinematics::{build_articulated, KinOptions};
use gsart::pipeline::Control;
use kin_common::{evaluate, load, sequences, Seq};
use rand::{rngs::StdRng, Rng, SeedableRng};

/// Pose noise: rotation σ per axis (degrees) and translation σ (object sizes).
const ROT_DEG: f64 = 0.3;
const TRANS: f64 = 0.001;

fn gauss(rng: &mut StdRng) -> f64 {
    // Box–Muller
    let u: f64 = rng.random_range(1e-12..1.0);
    let v: f64 = rng.random();
    (-2.0 * u.lln()).sqrt() * (2.0 * std::f64::consts::PI * v).lcos()
}

fn noise(rng: &mut StdRng, rot_deg: f64, trans: f64) -> DMat4 {
    let w = DVec3::new(gauss(rng), gauss(rng), gauss(rng)) * rot_deg.to_radians();
    let t = DVec3::new(gauss(rng), gauss(rng), gauss(rng)) * trans;
    let r = if w.length() > 0.0 {
        DMat4::from_axis_angle(w.normalize(), w.length())
    } else {
        DMat4::IDENTITY
    };
    DMat4::from_translation(t) * r
}

/// Noisy poses with the largest part split in two (new label = num_parts).
fn degrade(
    seq: &Seq,
    seed: u64,
    rot_deg: f64,
    trans: f64,
) -> (Vec<Vec<u32>>, Vec<Vec<DMat4>>, usize) {
    let mut rng = StdRng::seed_from_u64(seed);
    let n = seq.gt.num_parts;
    let mut counts = vec![0usize; n];
    for l in seq.labels.iter().flatten() {
        counts[*l as usize] += 1;
    }
    let big = (0..n).max_by_key(|&p| counts[p]).unwrap();
    // split plane: through the part's centroid at frame 0, normal x
    let mut cx: f64 = 0.0;
    let mut cn: f64 = 0.0;
    for (pts, ls) in seq.points.iter().zip(&seq.labels).take(1) {
        for (x, &l) in pts.iter().zip(ls) {
            if l as usize == big {
                cx += x.x as f64;
                cn += 1.0;
            }
        }
    }
    cx /= cn.max(1.0);
    let labels = seq
        .points
        .iter()
        .zip(&seq.labels)
        .enumerate()
        .map(|(k, (pts, ls))| {
            let back = seq.gt.poses[0][big] * rigid_inverse(&seq.gt.poses[k][big]);
            pts.iter()
                .zip(ls)
                .map(|(x, &l)| {
                    if l as usize == big && back.transform_point3(x.as_dvec3()).x > cx {
                        n as u32
                    } else {
                        l
                    }
                })
                .collect()
        })
        .collect();
    let poses = seq
        .gt
        .poses
        .iter()
        .map(|f| {
            let mut v: Vec<DMat4> = f
                .iter()
                .map(|m| noise(&mut rng, rot_deg, trans) * *m)
                .collect();
            v.push(noise(&mut rng, rot_deg, trans) * f[big]);
            v
        })
        .collect();
    (labels, poses, big)
}

#[test]
fn noisy_oversegmented_input() {
    let seqs = sequences();
    if seqs.is_empty() {
        eprintln!("skip: bench-dev not present");
        return;
    }
    let mut failures = Vec::new();
    for dir in seqs {
        let seq = load(&dir);
        let (labels, poses, big) = degrade(&seq, 11, ROT_DEG, TRANS);
        let n = seq.gt.num_parts;
        // Measurement: L_merge of the split halves at this noise and at 3× it.
        let l_split = merge_loss(&poses, big, n);
        let (_, poses3, _) = degrade(&seq, 11, 3.0 * ROT_DEG, 3.0 * TRANS);
        eprintln!(
            "{:<18} L_merge(split halves) = {l_split:.4} (noise ×3: {:.4})",
            seq.name,
            merge_loss(&poses3, big, n)
        );
        for refine in [None, Some(RefineOptions::default())] {
            let refined = refine.is_some();
            let opts = KinOptions {
                refine,
                ..Default::default()
            };
            let t0 = std::time::Instant::now();
            let (res, rep) =
                build_articulated(&seq.points, &labels, &poses, 0, &opts, &|| 0.0, &mut |_| {
                    Control::Continue
                })
                .unwrap();
            let secs = t0.elapsed().as_secs_f64();
            let merged_back = rep.parts == n
                && (0..n).all(|p| rep.merge_map[p] as usize == p)
                && rep.merge_map[n] as usize == big;
            if !merged_back {
                failures.push(format!("{}: merge map {:?}", seq.name, rep.merge_map));
                continue;
            }
            let e = evaluate(&seq, &res);
            let rr = rep
                .refine
                .as_ref()
                .map(|r| {
                    format!(
                        "accepted {} loss {:.5}->{:.5}",
                        r.accepted, r.loss_before, r.loss_after
                    )
                })
                .unwrap_or_default();
            eprintln!(
                "{:<18} {}: tree-mismatch {} type-errors {} max-axis {:.3}° max-pivot {:.4} {rr} ({secs:.1}s)",
                seq.name,
                if refined { "refined   " } else { "projection" },
                e.tree_mismatch, e.type_errors, e.max_axis_deg, e.max_pivot
            );
            // Axis bound 6°: the tree and joints are built from each part's motion
            // polished by ICP against the clouds, which on these near-exact poses adds a
            // few degrees of spin to thin links (worst axis, projection: laikago 1.3° →
            // 5.1°, solo12 1.1° → 3.7°) while on real Step-1 output it finds more joints
            // (bench-dev: 36 → 38 of 54, types 35 → 38, TED 2.86 → 2.57).
            if e.tree_mismatch != 0
                || e.type_errors != 0
                || e.max_axis_deg > 6.0
                || e.max_pivot > 0.02
            {
                failures.push(format!(
                    "{} refined={refined}: tree {} types {} axis {:.2} pivot {:.4}",
                    seq.name, e.tree_mismatch, e.type_errors, e.max_axis_deg, e.max_pivot
                ));
            }
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}

/// Refinement repairs a perturbed chain: joints of the exact projection are perturbed
/// (axes tilted 4°, revolute pivots moved 0.015 off the axis, states ± 0.05) and the
/// refinement against the observed clouds must be accepted and, for revolute chains,
/// reduce the median axis error and halve the median pivot error.
#[test]
fn refinement_repairs_perturbed_joints() {
    let seqs: Vec<_> = sequences()
        .into_iter()
        .filter(|d| {
            let n = d.file_name().unwrap().to_string_lossy().into_owned();
            n.starts_with("xarm7") || n.starts_with("panda_gripper") || n.starts_with("so101")
        })
        .collect();
    if seqs.is_empty() {
        eprintln!("skip: bench-dev not present");
        return;
    }
    let mut rng = StdRng::seed_from_u64(3);
    for dir in seqs {
        let seq = load(&dir);
        let opts = KinOptions {
            refine: None,
            ..Default::default()
        };
        let (mut res, _) = build_articulated(
            &seq.points,
            &seq.labels,
            &seq.gt.poses,
            0,
            &opts,
            &|| 0.0,
            &mut |_| Control::Continue,
        )
        .unwrap();
        for j in res.joints.as_mut().unwrap() {
            let a = DVec3::from(j.axis);
            let perp = a.any_orthonormal_vector();
            let tilt = DMat4::from_axis_angle(perp, 4f64.to_radians());
            j.axis = tilt.transform_vector3(a).normalize().to_array();
            let other = a.cross(perp);
            j.pivot = (DVec3::from(j.pivot) + other * 0.015).to_array();
            for (k, s) in j.state.iter_mut().enumerate() {
                if k != res.canonical_frame {
                    *s += 0.05 * gauss(&mut rng);
                }
            }
        }
        let before = evaluate(&seq, &res);
        let t0 = std::time::Instant::now();
        let rep = gsart::kinematics::refine::refine(
            &mut res,
            &seq.points,
            &RefineOptions::default(),
            0.0,
            &mut |_| Control::Continue,
        )
        .unwrap();
        let after = evaluate(&seq, &res);
        eprintln!(
            "{:<18} perturbed: axis {:.3}° pivot {:.4} -> refined: axis {:.3}° pivot {:.4}; loss {:.5} -> {:.5} accepted {} ({:.1}s)",
            seq.name,
            before.max_axis_deg,
            before.max_pivot,
            after.max_axis_deg,
            after.max_pivot,
            rep.loss_before,
            rep.loss_after,
            rep.accepted,
            t0.elapsed().as_secs_f64()
        );
        let fmt = |e: &kin_common::Errors| {
            e.per_joint
                .iter()
                .map(|(c, a, p)| format!("{c}:{a:.1}°/{p:.3}"))
                .collect::<Vec<_>>()
                .join(" ")
        };
        eprintln!(
            "   per joint before: {}\n   per joint after:  {}",
            fmt(&before),
            fmt(&after)
        );
        assert!(
            rep.accepted && rep.loss_after < rep.loss_before,
            "{}",
            seq.name
        );
        // Median over joints: Chamfer cannot see a rotation about a (near-)symmetric
        // link's own axis (xarm7/so101 wrist roll) nor a prismatic axis tilt smaller than
        // the point spacing (panda fingers), so the worst joint may not improve.
        let median = |e: &kin_common::Errors, f: fn(&(usize, f64, f64)) -> f64| {
            let mut v: Vec<f64> = e.per_joint.iter().map(f).collect();
            v.sort_by(|a, b| a.total_cmp(b));
            v[v.len() / 2]
        };
        let revolute = before.per_joint.iter().any(|j| j.2 > 0.0);
        if revolute {
            assert!(
                median(&after, |j| j.1) < median(&before, |j| j.1),
                "{}",
                seq.name
            );
            assert!(
                median(&after, |j| j.2) < 0.5 * median(&before, |j| j.2),
                "{}",
                seq.name
            );
        }
    }
}
