//! End to end on procedural objects (issue #4): `fit` (fast preset, default part range)
//! → Steps 2–3 → `evaluate`. The laptop — the page's default example, one revolute
//! hinge — must come out with the exact tree (TED 0), the right joint type, the hinge
//! axis within 5° and its pivot within 2 % of the object size, for four generator seeds.
//!
//! The other procedural objects (cabinet, arm, hand, quadruped) do not meet this yet;
//! the README's accuracy section lists where each stands. The cabinet is held to what
//! it reaches now (three of its four parts, two joints of the right type); the
//! quadruped with generator seed 0 must have its exact tree and all eight hinges within
//! 5° and a pivot error of 2 (six before near-parallel hinges were tied), and with the
//! default preset generator seed 3 all eight within 5° and generator seed 5 all eight
//! within 5° and a pivot error of 2.

use gsart::eval::joint_error::JointErrors;
use gsart::eval::Metrics;
use gsart::pipeline::{evaluate, fit, Control, FitOptions, Quality};
use gsart::synth::{generate, ObjectKind, SynthOptions};

/// Generates `kind` with generator seed `seed`, fits it (fast preset, default part
/// range) and evaluates it: the result's part count and the metrics.
fn fit_and_evaluate(kind: ObjectKind, seed: u64) -> (usize, Metrics) {
    let opts = FitOptions {
        quality: Quality::Fast,
        ..Default::default()
    };
    generate_fit_evaluate(
        &SynthOptions {
            seed,
            ..SynthOptions::new(kind)
        },
        &opts,
    )
}

/// Generates `so`, fits it with `opts` and evaluates it: the result's part count and
/// the metrics.
fn generate_fit_evaluate(so: &SynthOptions, opts: &FitOptions) -> (usize, Metrics) {
    let out = generate(so).expect("generate");
    let fitted = fit(&out.sequence, opts, &|_| Control::Continue).expect("fit");
    let m = evaluate(&fitted.result, &out.sequence, &out.gt).expect("evaluate");
    (fitted.result.parts, m)
}

#[test]
fn laptop_tree_and_hinge_are_exact_for_every_seed() {
    let mut failures = Vec::new();
    for seed in 0..4 {
        let (_, m) = fit_and_evaluate(ObjectKind::Laptop, seed);
        let j = m.joints.as_ref().expect("joint errors");
        eprintln!(
            "laptop seed {seed}: RI {:.3} recon {:.2} TED {:?} joints found {}/{} types {} axis {:?}° pivot {:?}",
            m.mean_ri,
            m.reconstruction_error,
            m.tree_edit_distance,
            j.found,
            j.joints,
            j.type_correct,
            j.max_axis_deg,
            j.max_pivot_error
        );
        let ok = m.tree_edit_distance == Some(0)
            && j.joints == 1
            && j.found == 1
            && j.type_correct == 1
            && j.within_bar == 1
            && m.mean_ri >= 0.9;
        if !ok {
            failures.push(format!("seed {seed}: {m:?}"));
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}

/// SPEC §7's "object" workload: the laptop as 4 frames of 512 points, fitted with the
/// default preset (balanced, part range 3–7). Such sparse frames now get the global pose
/// search too (`select::SEARCH_MIN_POINTS`); without it balanced picked 4–7 parts and
/// nothing merged (generator seed 0: RI 0.619, TED 5). Measured with it: RI 0.938–0.980,
/// TED 0 on generator seeds 0–3.
#[test]
fn sparse_laptop_with_the_default_preset() {
    let mut failures = Vec::new();
    for seed in 0..4 {
        let so = SynthOptions {
            seed,
            frames: 4,
            points: 512,
            ..SynthOptions::new(ObjectKind::Laptop)
        };
        let (_, m) = generate_fit_evaluate(&so, &FitOptions::default());
        let j = m.joints.as_ref().expect("joint errors");
        eprintln!(
            "sparse laptop seed {seed}: RI {:.3} TED {:?} types {}/{}",
            m.mean_ri, m.tree_edit_distance, j.type_correct, j.joints
        );
        if m.tree_edit_distance != Some(0) || j.type_correct != 1 || m.mean_ri < 0.88 {
            failures.push(format!("seed {seed}: {m:?}"));
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}

/// The fit does not depend on the input's units or placement: the laptop in millimetres,
/// 5 m off the origin, gives the metre fit's segmentation and hinge, in millimetres.
#[test]
fn fit_is_the_same_in_millimetres_far_from_the_origin() {
    use gsart::io::gt::JointType;
    use gsart::normalisation::Normalisation;
    let out = generate(&SynthOptions::new(ObjectKind::Laptop)).expect("generate");
    let opts = FitOptions {
        quality: Quality::Fast,
        ..Default::default()
    };
    let to_mm = Normalisation {
        center: glam::DVec3::new(5000.0, -3000.0, 200.0),
        scale: 1000.0,
    };
    let mut mm = out.sequence.clone();
    for f in &mut mm.frames {
        for p in &mut f.points {
            *p = to_mm.point_to_input(p.as_dvec3()).as_vec3();
        }
    }
    let metre = fit(&out.sequence, &opts, &|_| Control::Continue).expect("fit in metres");
    let milli = fit(&mm, &opts, &|_| Control::Continue).expect("fit in millimetres");
    let (a, b) = (&metre.result, &milli.result);
    assert_eq!(a.parts, b.parts);
    let total: usize = a.labels.iter().map(Vec::len).sum();
    let same: usize = a
        .labels
        .iter()
        .zip(&b.labels)
        .map(|(x, y)| x.iter().zip(y).filter(|(p, q)| p == q).count())
        .sum();
    assert!(
        same as f64 >= 0.99 * total as f64,
        "labels agree on {same} of {total} points"
    );
    // The metre fit's joints and poses, taken to millimetres, are the millimetre fit's.
    let mut expect = a.clone();
    to_mm.result_to_input(&mut expect);
    let (ja, jb) = (
        expect.joints.as_ref().expect("joints"),
        b.joints.as_ref().expect("joints"),
    );
    assert_eq!(ja.len(), jb.len());
    for (x, y) in ja.iter().zip(jb) {
        assert_eq!(x.joint_type, y.joint_type);
        let cos = glam::DVec3::from_array(x.axis).dot(glam::DVec3::from_array(y.axis));
        assert!(cos.abs() > 0.9995, "axes {:?} vs {:?}", x.axis, y.axis);
        if x.joint_type == JointType::Revolute {
            // Pivots lie anywhere on the axis: compare their distance off the other axis.
            let d = glam::DVec3::from_array(y.pivot) - glam::DVec3::from_array(x.pivot);
            let off = (d - d.dot(glam::DVec3::from_array(x.axis))
                * glam::DVec3::from_array(x.axis))
            .length();
            assert!(
                off < 5.0,
                "pivots {:?} vs {:?} ({off} mm apart)",
                x.pivot,
                y.pivot
            );
        }
    }
    // Poses move the canonical points to the same places (to 0.5 % of the object size).
    use gsart::geom::se3::from_row_major;
    let c = b.canonical_frame;
    let mut worst = 0.0f64;
    for (fa, fb) in expect.poses.iter().zip(&b.poses) {
        for (x, &part) in mm.frames[c].points.iter().zip(&b.labels[c]) {
            let (pa, pb) = (
                from_row_major(&fa[part as usize]),
                from_row_major(&fb[part as usize]),
            );
            let x = x.as_dvec3();
            worst = worst.max((pa.transform_point3(x) - pb.transform_point3(x)).length());
        }
    }
    assert!(worst < 5.0, "poses place a point {worst} mm apart");
    let (ga, gb) = (
        a.gaussians.as_ref().expect("gaussians"),
        b.gaussians.as_ref().expect("gaussians"),
    );
    for (x, y) in ga.iter().zip(gb) {
        for (sa, sb) in x.scale.iter().zip(&y.scale) {
            assert!(
                (sb / (1000.0 * sa) - 1.0).abs() < 0.01,
                "scales {sa} m vs {sb} mm"
            );
        }
    }
}

/// The cabinet (two drawers and a door on a static body of thin panels, 2048 points
/// per frame) comes apart into its moving parts. Until the pose search's distance cap
/// followed the point spacing, a correct pose scored barely better than a wrong one
/// on these sparse panels and every m came out as one rigid body (RI 0.448, TED 3).
#[test]
fn cabinet_comes_apart_into_its_moving_parts() {
    let (parts, m) = fit_and_evaluate(ObjectKind::Cabinet, 3);
    let j = m.joints.as_ref().expect("joint errors");
    eprintln!(
        "cabinet: parts {parts} RI {:.3} recon {:.2} TED {:?} joints found {}/{} types {}",
        m.mean_ri, m.reconstruction_error, m.tree_edit_distance, j.found, j.joints, j.type_correct,
    );
    assert!(parts >= 3, "{parts} parts");
    assert!(m.mean_ri >= 0.65, "RI {}", m.mean_ri);
    assert!(j.type_correct >= 2, "{j:?}");
}

/// The quadruped (generator seeds 0 and 5): the right tree, and its legs' hinges along
/// their true axes. Its legs are capsules, which Step 1 leaves turned about their own
/// long axes, and over their short swings (the hind-left thigh: 35° at most) that turn
/// mixed into the hinge axes (up to 64° off) until the repair preferred the hinge that
/// carries a leg's axis about a great circle (`flips::great_circle_hinge`). Six of seed
/// 0's eight hinges met the bar (axis ≤ 5°, pivot ≤ 2) once the refinement
/// sampled 2048 points a frame (four with 1024: pivots 4.1 and 2.6, axes 5.6° and
/// 10.3°); all eight since near-parallel hinges are tied (`kinematics::parallel`: axes
/// 1.8–10.3° → 1.2–1.9°). Seed 5's eight came out 1.2–58° off (none in the bar) until
/// the spin-free hinges' axes were left free of the refinement's axis prior and a
/// related outlier could follow a tied group (session 45: all eight at 1.1°).
#[test]
fn quadruped_legs_hinge_about_their_true_axes() {
    let mut failures = Vec::new();
    for seed in [0, 5] {
        let (parts, m) = fit_and_evaluate(ObjectKind::Quadruped, seed);
        let j = m.joints.as_ref().expect("joint errors");
        let axes: Vec<f64> = j.per_joint.iter().filter_map(|x| x.axis_deg).collect();
        let pivots: Vec<Option<f64>> = j.per_joint.iter().map(|x| x.pivot_error).collect();
        eprintln!(
            "quadruped seed {seed}: parts {parts} RI {:.3} recon {:.2} TED {:?} joints found {}/{} types {} axes {axes:.1?}° pivots {pivots:.2?}",
            m.mean_ri, m.reconstruction_error, m.tree_edit_distance, j.found, j.joints, j.type_correct,
        );
        if m.tree_edit_distance != Some(0)
            || (j.found, j.type_correct) != (8, 8)
            || j.within_bar != 8
        {
            failures.push(format!(
                "seed {seed}: TED {:?}, {} found, {} types right, {} of 8 within 5° and a pivot error of 2: axes {axes:.1?}, pivots {pivots:.1?}",
                m.tree_edit_distance, j.found, j.type_correct, j.within_bar
            ));
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}

/// The quadruped with generator seed `seed` fitted with the default preset (balanced):
/// its joint errors, axis errors (degrees), pivot errors and tree edit distance, printed.
fn balanced_quadruped_joints(
    seed: u64,
) -> (JointErrors, Vec<f64>, Vec<Option<f64>>, Option<usize>) {
    let (parts, m) = generate_fit_evaluate(
        &SynthOptions {
            seed,
            ..SynthOptions::new(ObjectKind::Quadruped)
        },
        &FitOptions::default(),
    );
    let j = m.joints.clone().expect("joint errors");
    let axes: Vec<f64> = j.per_joint.iter().filter_map(|x| x.axis_deg).collect();
    let pivots: Vec<Option<f64>> = j.per_joint.iter().map(|x| x.pivot_error).collect();
    eprintln!(
        "quadruped seed {seed}, balanced: parts {parts} RI {:.3} TED {:?} joints found {}/{} axes {axes:.1?}° pivots {pivots:.2?}",
        m.mean_ri, m.tree_edit_distance, j.found, j.joints,
    );
    (j, axes, pivots, m.tree_edit_distance)
}

/// The quadruped with the default preset (balanced), generator seed 3: every hinge
/// along its true axis. Four of its eight hinges came out tied parallel within 2.4° and
/// the other four 45–85° off, hinged about their own round link's long axis (a thigh's
/// states spanning 2.5 rad where the leg swings 0.7), too far for the followers of a
/// tied group (30°) until far followers were tried with their states and pivots found
/// anew along the group's direction (`parallel::reproject`, session 47: all eight at
/// 2.7°, six within the pivot bar of 2; session 48's half turns: eight). The tied
/// refinement also left a piece of the body on a hinge of its own spanning 0.05 rad,
/// a tenth part (RI 0.830, TED 1), until joints were checked for motion again after
/// the repairs (session 59: 9 parts, RI 0.902, TED 0, seven in the bar).
#[test]
fn quadruped_round_links_far_off_their_axes_follow_the_tied_legs() {
    let (j, axes, pivots, ted) = balanced_quadruped_joints(3);
    assert_eq!(ted, Some(0), "{j:?}");
    assert_eq!((j.found, j.type_correct), (8, 8), "{j:?}");
    assert!(axes.iter().all(|&a| a <= 5.0), "axes {axes:.1?}");
    assert!(
        j.within_bar >= 6,
        "{} of 8 in the bar: pivots {pivots:.2?}",
        j.within_bar
    );
}

/// The quadruped with generator seed 5 (default preset): every hinge within the bar.
/// Step 1 posed a round shank end over end in two frames, and the refinement settled
/// its hinge with the pivot near the shank's centre and the states there half a turn
/// off (−0.46, then −3.55, −3.54, then −0.73): pivots 8.6 off, its thigh's 6.1, six of
/// eight in the bar, until such joints were proposed anew with continuous states
/// (`kinematics::half_turns`, session 48: all eight, pivots within 1.1).
#[test]
fn quadruped_links_posed_end_over_end_keep_their_hinges() {
    let (j, axes, pivots, _) = balanced_quadruped_joints(5);
    assert_eq!((j.found, j.type_correct), (8, 8), "{j:?}");
    assert!(axes.iter().all(|&a| a <= 5.0), "axes {axes:.1?}");
    assert!(
        pivots.iter().all(|p| p.is_some_and(|p| p <= 2.0)),
        "pivots {pivots:.2?}"
    );
}

/// The quadruped with generator seed 1: every thigh keeps a part of its own. A Step-1
/// Gaussian holding half a front thigh and half the body fitted the body's motion
/// within the snap ratio (2.91 against 3) and was snapped onto it, so that thigh
/// joined the body (RI 0.892, TED 1) until the snap refused Gaussians straddling two
/// parts (`pose_search::straddles`; measured since: RI 0.920, TED 0, 8 of 8 joints).
#[test]
fn quadruped_thighs_keep_their_parts() {
    let (parts, m) = fit_and_evaluate(ObjectKind::Quadruped, 1);
    let j = m.joints.as_ref().expect("joint errors");
    eprintln!(
        "quadruped seed 1: parts {parts} RI {:.3} TED {:?} joints found {}/{} types {}",
        m.mean_ri, m.tree_edit_distance, j.found, j.joints, j.type_correct,
    );
    assert_eq!(m.tree_edit_distance, Some(0), "{m:?}");
    assert_eq!((j.found, j.type_correct), (8, 8), "{j:?}");
    assert!(m.mean_ri >= 0.9, "RI {}", m.mean_ri);
}
