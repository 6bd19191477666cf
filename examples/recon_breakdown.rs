//! Where a result's reconstruction error comes from: for every ground-truth part, its
//! share of the canonical points, the predicted part most of them got (and how many),
//! and the mean error ×100 of its points per frame (SPEC §5 reconstruction error).
//!
//! With `--step1`, the poses are the Step-1 Gaussians' instead of the result's (each
//! part moves with its largest Gaussian), to separate Step 1 from Steps 2–3.
//!
//! With `--rot`, the per-frame columns are the rotation error (degrees) of the main
//! predicted part's motion instead of the point error.
//!
//! Usage: `cargo run --release --example recon_breakdown -- RESULT.json SEQ_DIR [--step1] [--rot]`

use gsart::math::Libm;
use std::path::Path;

use glam::{DMat4, DVec3};
use gsart::geom::se3::{from_row_major, rigid_inverse};
use gsart::io::gt::GroundTruth;
use gsart::io::result::FitResult;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (res_path, dir) = match args.as_slice() {
        [r, d, ..] => (r.clone(), Path::new(d).to_path_buf()),
        _ => {
            eprintln!("usage: recon_breakdown RESULT.json SEQ_DIR");
            std::process::exit(2);
        }
    };
    let result =
        FitResult::from_json(&std::fs::read_to_string(&res_path).unwrap(), &res_path).unwrap();
    let gt = GroundTruth::from_json(
        &std::fs::read_to_string(dir.join("gt.json")).unwrap(),
        "gt.json",
    )
    .unwrap();
    let c = result.canonical_frame;
    let bytes = std::fs::read(dir.join(&gt.frames[c])).unwrap();
    let cloud = gsart::io::ply::read_ply(&bytes, "canonical").unwrap();
    let gl = cloud.labels.unwrap();
    let pred = &result.labels[c];
    let step1 = args.iter().any(|a| a == "--step1");
    let rot = args.iter().any(|a| a == "--rot");
    let mut poses: Vec<Vec<DMat4>> = (0..result.frames)
        .map(|t| result.poses[t].iter().map(from_row_major).collect())
        .collect();
    if step1 {
        let gs = result.gaussians.as_ref().expect("result has no Gaussians");
        for p in 0..result.parts {
            let vol = |g: &gsart::io::result::ResultGaussian| g.scale.iter().product::<f64>();
            let Some(g) = gs
                .iter()
                .filter(|g| g.part == p)
                .max_by(|a, b| vol(a).total_cmp(&vol(b)))
            else {
                continue;
            };
            let frame = |t: usize| {
                let r = glam::DMat3::from_cols_array(&g.rotation[t]).transpose();
                DMat4::from_rotation_translation(
                    glam::DQuat::from_mat3(&r),
                    DVec3::from_array(g.center[t]),
                )
            };
            let inv0 = rigid_inverse(&frame(c));
            for (t, f) in poses.iter_mut().enumerate() {
                f[p] = frame(t) * inv0;
            }
        }
    }
    let k = result.frames;
    let gp = gt.num_parts;
    let mut err = vec![vec![0.0f64; k]; gp];
    let mut count = vec![0usize; gp];
    let mut conf = vec![vec![0usize; result.parts]; gp];
    for (i, x) in cloud.points.iter().enumerate() {
        let g = gl[i] as usize;
        let a = pred[i] as usize;
        count[g] += 1;
        conf[g][a] += 1;
        let x = x.as_dvec3();
        for t in 0..k {
            let p = poses[t][a].transform_point3(x);
            let y: DMat4 = gt.poses[t][g] * rigid_inverse(&gt.poses[c][g]);
            let y: DVec3 = y.transform_point3(x);
            err[g][t] += (p - y).length();
        }
    }
    let n = cloud.points.len() as f64;
    let mut total = 0.0;
    println!("gt part  share  main pred (frac)  mean err  contrib | per frame");
    for g in 0..gp {
        if count[g] == 0 {
            continue;
        }
        let (a, ca) = conf[g].iter().enumerate().max_by_key(|x| x.1).unwrap();
        let per: Vec<f64> = err[g].iter().map(|e| 100.0 * e / count[g] as f64).collect();
        let mean = per.iter().sum::<f64>() / k as f64;
        let contrib = mean * count[g] as f64 / n;
        total += contrib;
        let pf: Vec<String> = if rot {
            // rotation error (degrees) of the main predicted part's motion per frame
            (0..k)
                .map(|t| {
                    let pm: DMat4 = poses[t][a];
                    let gm: DMat4 = gt.poses[t][g] * rigid_inverse(&gt.poses[c][g]);
                    let r = glam::DMat3::from_mat4(pm).transpose() * glam::DMat3::from_mat4(gm);
                    let cos = ((r.x_axis.x + r.y_axis.y + r.z_axis.z - 1.0) / 2.0).clamp(-1.0, 1.0);
                    format!("{:5.0}", cos.lacos().to_degrees())
                })
                .collect()
        } else {
            per.iter().map(|v| format!("{v:5.1}")).collect()
        };
        println!(
            "{g:7}  {:5.3}  {a:3} ({:4.2})        {mean:7.2}  {contrib:6.2} | {}",
            count[g] as f64 / n,
            *ca as f64 / count[g] as f64,
            pf.join(" ")
        );
    }
    println!("total reconstruction error {total:.3}");
    // Flow error split by label: a point counts as well labelled when its
    // predicted part's majority ground-truth part is its own.
    let mut major = vec![0usize; result.parts];
    for (a, m) in major.iter_mut().enumerate() {
        *m = (0..gp).max_by_key(|&g| conf[g][a]).unwrap_or(0);
    }
    let (mut fw, mut fm, mut nw) = (0.0, 0.0, 0usize);
    for (i, x) in cloud.points.iter().enumerate() {
        let (g, a) = (gl[i] as usize, pred[i] as usize);
        let x = x.as_dvec3();
        let mut e = 0.0;
        for t in 0..k - 1 {
            let dp = poses[t + 1][a].transform_point3(x) - poses[t][a].transform_point3(x);
            let y =
                |t: usize| (gt.poses[t][g] * rigid_inverse(&gt.poses[c][g])).transform_point3(x);
            e += (dp - (y(t + 1) - y(t))).length();
        }
        let e = 100.0 * e / (k - 1) as f64;
        if major[a] == g {
            fw += e;
            nw += 1;
        } else {
            fm += e;
        }
    }
    println!(
        "flow: well-labelled {:.3} of points contribute {:.3}, mislabelled contribute {:.3} (mean over mislabelled {:.2})",
        nw as f64 / n,
        fw / n,
        fm / n,
        fm / (n - nw as f64).max(1.0)
    );
}
