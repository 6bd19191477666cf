//! The small fit shared by the native golden test (`fit_golden.rs`) and its wasm copy
//! (`wasm_common`): the same seed must give the same labels on both platforms.

use gsart::pipeline::{fit_step1_single, Control, FitOptions, Quality};
use gsart::synth::{generate, ObjectKind, SynthOptions};

/// Step-1 labels (all frames, concatenated) of a small procedural laptop fit.
pub fn small_fit_labels() -> Vec<u32> {
    let mut so = SynthOptions::new(ObjectKind::Laptop);
    so.frames = 3;
    so.points = 200;
    so.seed = 5;
    let s = generate(&so).expect("generate");
    let opts = FitOptions {
        quality: Quality::Fast,
        iters: Some(120),
        seed: 9,
        ..Default::default()
    };
    let r = fit_step1_single(&s.sequence, 3, &opts, &mut |_| Control::Continue).expect("fit");
    r.labels.concat()
}

pub const GOLDEN: &str = include_str!("../data/small_fit_labels.json");
