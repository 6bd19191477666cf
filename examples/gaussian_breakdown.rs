//! Development tool: where a result's Step-1 Gaussians sit. Every canonical-frame
//! point is given to its nearest Gaussian (smallest Mahalanobis distance, as Step 1
//! segments), and for each Gaussian this prints the part it was merged into, how many
//! of its points each ground-truth part holds (a Gaussian holding two parts straddles
//! a joint, and no single motion explains it), and its largest turn (degrees) and
//! centre displacement from the canonical frame over the sequence.
//!
//! Usage: `cargo run --release --example gaussian_breakdown -- RESULT.json SEQ_DIR`

use gsart::math::Libm;
use std::path::Path;

use glam::{DMat3, DVec3};
use gsart::fit::gaussians::{argmin_maha, Gauss};
use gsart::io::gt::GroundTruth;
use gsart::io::result::FitResult;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [res_path, dir, ..] = args.as_slice() else {
        eprintln!("usage: gaussian_breakdown RESULT.json SEQ_DIR");
        std::process::exit(2);
    };
    let dir = Path::new(dir);
    let result = FitResult::from_json(&std::fs::read_to_string(res_path).unwrap(), res_path)
        .expect("result");
    let gt_text = std::fs::read_to_string(dir.join("gt.json")).expect("gt.json");
    let gt = GroundTruth::from_json(&gt_text, "gt.json").expect("gt");
    let c = result.canonical_frame;
    let name = &gt.frames[c];
    let frame =
        gsart::io::ply::read_ply(&std::fs::read(dir.join(name)).expect("ply"), name).expect("ply");
    let labels = frame.labels.expect("ground-truth part labels in the frame");
    let Some(gaussians) = result.gaussians.as_ref() else {
        eprintln!("{res_path}: the result has no Gaussians");
        std::process::exit(1);
    };
    // The result stores rotations row-major and scales as standard deviations.
    let rotation = |g: &gsart::io::result::ResultGaussian, t: usize| {
        DMat3::from_cols_array(&g.rotation[t]).transpose()
    };
    let at = |t: usize| -> Vec<Gauss> {
        gaussians
            .iter()
            .map(|g| {
                let s = DVec3::from(g.scale);
                let log_s = DVec3::new(s.x.lln(), s.y.lln(), s.z.lln());
                Gauss::new(rotation(g, t), DVec3::from(g.center[t]), log_s)
            })
            .collect()
    };
    let g0 = at(c);
    let parts = labels.iter().max().map_or(0, |&l| l as usize + 1);
    let mut counts = vec![vec![0usize; parts]; gaussians.len()];
    for (x, &l) in frame.points.iter().zip(&labels) {
        counts[argmin_maha(&g0, x.as_dvec3()).0][l as usize] += 1;
    }
    println!(
        "gaussian  part | points per ground-truth part 0..{parts} | max turn (deg), max shift"
    );
    for (i, g) in gaussians.iter().enumerate() {
        let (mut turn, mut shift) = (0.0f64, 0.0f64);
        for t in 0..result.frames {
            let d = rotation(g, t) * rotation(g, c).transpose();
            let cos = ((d.x_axis.x + d.y_axis.y + d.z_axis.z - 1.0) / 2.0).clamp(-1.0, 1.0);
            turn = turn.max(cos.lacos().to_degrees());
            shift = shift.max((DVec3::from(g.center[t]) - DVec3::from(g.center[c])).length());
        }
        let row: Vec<String> = counts[i].iter().map(|n| format!("{n:5}")).collect();
        println!(
            "{i:8}  {:4} | {} | {turn:6.1} {shift:.3}",
            g.part,
            row.join("")
        );
    }
}
