//! End to end on procedural objects (issue #4): `fit` (fast preset, default part range)
//! → Steps 2–3 → `evaluate`. The laptop — the page's default example, one revolute
//! hinge — must come out with the exact tree (TED 0), the right joint type, the hinge
//! axis within 5° and its pivot within 2 % of the object size, for four generator seeds.
//!
//! The other procedural objects (cabinet, arm, hand, quadruped) do not meet this yet;
//! the README's accuracy section lists where each stands.

use gsart::pipeline::{evaluate, fit, Control, FitOptions, Quality};
use gsart::synth::{generate, ObjectKind, SynthOptions};

#[test]
fn laptop_tree_and_hinge_are_exact_for_every_seed() {
    let mut failures = Vec::new();
    for seed in 0..4 {
        let out = generate(&SynthOptions {
            seed,
            ..SynthOptions::new(ObjectKind::Laptop)
        })
        .expect("generate");
        let opts = FitOptions {
            quality: Quality::Fast,
            ..Default::default()
        };
        let fitted = fit(&out.sequence, &opts, &|_| Control::Continue).expect("fit");
        let m = evaluate(&fitted.result, &out.sequence, &out.gt).expect("evaluate");
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
            && j.max_axis_deg.is_some_and(|a| a <= 5.0)
            && j.max_pivot_error.is_some_and(|p| p <= 2.0)
            && m.mean_ri >= 0.9;
        if !ok {
            failures.push(format!("seed {seed}: {m:?}"));
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}
