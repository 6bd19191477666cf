//! Long sequences (`gsart::key_frames`): Steps 1–3 on key frames, the other frames
//! tracked with the articulated model. The procedural laptop over 36 frames, fitted on
//! 12 key frames, must come out as fitted on its key frames alone — exact tree, the
//! hinge within 5° and a pivot error of 2, RI ≥ 0.9 — on every one of its 36 frames, and
//! the tracked frames' poses must be as close to the truth as the key frames'.

use gsart::geom::se3::from_row_major;
use gsart::pipeline::{evaluate, fit, Control, FitOptions, Quality};
use gsart::synth::{generate, ObjectKind, SynthOptions};

#[test]
fn a_long_laptop_sequence_fitted_on_key_frames_is_right_on_every_frame() {
    let out = generate(&SynthOptions {
        frames: 36,
        ..SynthOptions::new(ObjectKind::Laptop)
    })
    .expect("generate");
    let opts = FitOptions {
        quality: Quality::Fast,
        key_frames: 12,
        ..Default::default()
    };
    let fitted = fit(&out.sequence, &opts, &|_| Control::Continue).expect("fit");
    let r = &fitted.result;
    assert_eq!(r.frames, 36);
    assert_eq!(r.labels.len(), 36);
    let keys = gsart::key_frames::choose(36, 12);
    let info = r.info.as_ref().expect("info");
    assert_eq!(info["key_frames"]["tracked"], 24);
    assert_eq!(
        info["key_frames"]["frames"],
        serde_json::to_value(&keys).unwrap()
    );
    assert!(fitted.notes.iter().any(|n| n.starts_with("long sequence")));

    let m = evaluate(r, &out.sequence, &out.gt).expect("evaluate");
    let j = m.joints.as_ref().expect("joint errors");
    eprintln!(
        "laptop, 36 frames on 12 key frames: RI {:.3} recon {:.3} flow {:.3} TED {:?} axis {:?}° pivot {:?}",
        m.mean_ri, m.reconstruction_error, m.flow_error, m.tree_edit_distance, j.max_axis_deg, j.max_pivot_error
    );
    assert_eq!(m.tree_edit_distance, Some(0));
    assert_eq!((j.type_correct, j.within_bar), (1, 1));
    assert!(m.mean_ri >= 0.9, "{m:?}");

    // Each frame's pose error: the mean displacement (×100) of the canonical points of
    // each true part between the predicted and the true motion of that part, where the
    // prediction is the pose of the part most of its points went to.
    let c = r.canonical_frame;
    let pts = &out.sequence.frames[c].points;
    let truth = out.sequence.frames[c].labels.as_ref().expect("labels");
    let pred = &r.labels[c];
    let err = |t: usize| {
        let mut sum = 0.0;
        for (i, p) in pts.iter().enumerate() {
            let g = truth[i] as usize;
            let gt = out.gt.poses[t][g] * out.gt.poses[c][g].inverse();
            let pr = from_row_major(&r.poses[t][pred[i] as usize]);
            sum += (gt.transform_point3(p.as_dvec3()) - pr.transform_point3(p.as_dvec3())).length();
        }
        100.0 * sum / pts.len() as f64
    };
    let mean = |ts: &mut dyn Iterator<Item = usize>| {
        let v: Vec<f64> = ts.map(err).collect();
        v.iter().sum::<f64>() / v.len() as f64
    };
    let key = mean(&mut keys.iter().copied().filter(|&t| t != c));
    let tracked = mean(&mut (0..36).filter(|t| !keys.contains(t)));
    eprintln!("pose error: key frames {key:.3}, tracked frames {tracked:.3}");
    assert!(
        tracked <= 1.5 * key + 0.1,
        "key {key:.3}, tracked {tracked:.3}"
    );
}
