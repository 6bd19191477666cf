//! Development tool: runs the Step-1 pose initialisation and global pose search with
//! Gaussians placed on the ground-truth parts of frame 0 (an oracle segmentation),
//! and prints per frame and part the mean point error (×100) of the found poses
//! against the ground truth — separating search failures from segmentation ones.
//!
//! Usage: `cargo run --release --example pose_search_oracle -- SEQ_DIR [--no-search] [--no-init] [--occ]`
//!
//! With `OCCSC=1` in the environment each part's error is followed by `[found/true]`:
//! how many of frame t's points (soft count, the occluded search's inlier radius) the
//! part's frame-0 points explain under the found and under the true motion. Where
//! the true motion explains more, the occluded search missed a better-scoring pose
//! (bench-dev occluded xarm7, frame 6: 36 against 135 and 9 against 214 for two links).

use gsart::math::Libm;
use std::path::Path;

use glam::{DMat3, DVec3, Vec3};
use gsart::fit::fitter::Data;
use gsart::fit::gaussians::Params;
use gsart::fit::{pose_init, pose_search};
use gsart::io::gt::GroundTruth;
use nalgebra::Matrix3;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let dir = Path::new(&args[0]);
    let no_search = args.iter().any(|a| a == "--no-search");
    let no_init = args.iter().any(|a| a == "--no-init");
    let gt_text = std::fs::read_to_string(dir.join("gt.json")).expect("gt.json");
    let gt = GroundTruth::from_json(&gt_text, "gt.json").expect("gt");
    let mut frames = Vec::new();
    let mut labels0 = Vec::new();
    for (k, name) in gt.frames.iter().enumerate() {
        let bytes = std::fs::read(dir.join(name)).expect("ply");
        let c = gsart::io::ply::read_ply(&bytes, name).expect("ply");
        if k == 0 {
            labels0 = c.labels.clone().expect("labels");
        }
        frames.push(c.points);
    }
    let kk = frames.len();
    let np = gt.poses[0].len();
    let data = Data::new(frames.clone());
    let mut params = Params::new(np, kk);
    for p in 0..np {
        let pts: Vec<DVec3> = frames[0]
            .iter()
            .zip(&labels0)
            .filter(|(_, &l)| l as usize == p)
            .map(|(x, _)| x.as_dvec3())
            .collect();
        let c = pts.iter().fold(DVec3::ZERO, |s, x| s + *x) / pts.len().max(1) as f64;
        let mut cov = Matrix3::<f64>::zeros();
        for x in &pts {
            let d = *x - c;
            let v = nalgebra::Vector3::new(d.x, d.y, d.z);
            cov += v * v.transpose();
        }
        cov /= pts.len().max(1) as f64;
        let e = cov.symmetric_eigen();
        let col = |j: usize| {
            DVec3::new(
                e.eigenvectors[(0, j)],
                e.eigenvectors[(1, j)],
                e.eigenvectors[(2, j)],
            )
        };
        let mut r = DMat3::from_cols(col(0), col(1), col(2));
        if r.determinant() < 0.0 {
            r = DMat3::from_cols(col(0), col(1), -col(2));
        }
        let s = DVec3::new(e.eigenvalues[0], e.eigenvalues[1], e.eigenvalues[2])
            .max(DVec3::splat(1e-8));
        params.set_log_scale(p, DVec3::new(s.x.lln(), s.y.lln(), s.z.lln()) * 0.5);
        let o = params.layout.rot(0, p);
        params.x[o..o + 6].copy_from_slice(&[
            r.x_axis.x, r.x_axis.y, r.x_axis.z, r.y_axis.x, r.y_axis.y, r.y_axis.z,
        ]);
        params.set_center(0, p, c);
    }
    params.broadcast_frame(0);
    let t0 = std::time::Instant::now();
    if !no_init {
        pose_init::init_poses(&data, &mut params, &Default::default(), 1);
    }
    if !no_search {
        let mut o = pose_search::PoseSearchOpts::default();
        let get = |k: &str| {
            args.iter()
                .position(|a| a == k)
                .and_then(|i| args.get(i + 1))
                .and_then(|v| v.parse::<usize>().ok())
        };
        o.rotations = get("--rot").unwrap_or(o.rotations);
        o.top = get("--top").unwrap_or(o.top);
        o.icp = get("--icp").unwrap_or(o.icp);
        o.probe = get("--probe").unwrap_or(o.probe);
        o.pivots = get("--pivots").unwrap_or(o.pivots);
        o.exclusive = !args.iter().any(|a| a == "--no-excl");
        let getf = |k: &str| {
            args.iter()
                .position(|a| a == k)
                .and_then(|i| args.get(i + 1))
                .and_then(|v| v.parse::<f64>().ok())
        };
        o.keep_ratio = getf("--keep").unwrap_or(o.keep_ratio);
        o.rigid_ratio = getf("--rigid").unwrap_or(o.rigid_ratio);
        o.keep = getf("--trim").unwrap_or(o.keep);
        o.snap_ratio = 0.0;
        if args.iter().any(|a| a == "--occ") {
            gsart::fit::occluded_search::search_poses_occluded(&data, &mut params, &o, &mut |_| {
                Ok(())
            })
            .expect("search");
        } else {
            pose_search::search_poses(&data, &mut params, &o, &mut |_| Ok(())).expect("search");
        }
    }
    eprintln!("search {:.2} s", t0.elapsed().as_secs_f64());
    let model = params.to_model();
    // Each part's frame-0 points, and for `OCCSC` an index over them.
    let parts0: Vec<Vec<Vec3>> = (0..np)
        .map(|p| {
            frames[0]
                .iter()
                .zip(&labels0)
                .filter(|(_, &l)| l as usize == p)
                .map(|(x, _)| *x)
                .collect()
        })
        .collect();
    let occsc = std::env::var("OCCSC").is_ok();
    let grids0: Vec<gsart::geom::knn::Grid> = if occsc {
        parts0
            .iter()
            .map(|g| gsart::geom::knn::Grid::new(g))
            .collect()
    } else {
        Vec::new()
    };
    let mut total = 0.0;
    for t in 1..kk {
        let mut line = format!("t{t}:");
        let mut ft = 0.0;
        for (p, own) in parts0.iter().enumerate() {
            let pm = model.pose(t, p) * gsart::geom::se3::rigid_inverse(&model.pose(0, p));
            let gm = gt.poses[t][p] * gsart::geom::se3::rigid_inverse(&gt.poses[0][p]);
            let e: f64 = own
                .iter()
                .map(|x| {
                    let x = x.as_dvec3();
                    (pm.transform_point3(x) - gm.transform_point3(x)).length()
                })
                .sum();
            line += &format!(" {:.1}", 100.0 * e / own.len().max(1) as f64);
            if std::env::var("SCORES").is_ok() {
                let g: Vec<DVec3> = own.iter().map(|x| x.as_dvec3()).step_by(4).collect();
                let mo = |m: glam::DMat4| (DMat3::from_mat4(m), m.w_axis.truncate());
                let mut b = Vec::new();
                let tg = pose_search::Target::frame(&data, t);
                let sp = pose_search::score(&tg, &g, mo(pm), 0.8, &mut b);
                let sg = pose_search::score(&tg, &g, mo(gm), 0.8, &mut b);
                line += &format!("[{:.2}/{:.2}]", sp * 1e4, sg * 1e4);
            }
            if occsc {
                let grid = &grids0[p];
                let ex = |m: glam::DMat4| -> f64 {
                    let inv = gsart::geom::se3::rigid_inverse(&m);
                    frames[t]
                        .iter()
                        .map(|y| {
                            let x = inv.transform_point3(y.as_dvec3()).as_vec3();
                            grid.nearest_capped(x, 1e-3)
                                .map_or(0.0, |(_, d)| 1.0 - d as f64 / 1e-3)
                        })
                        .sum()
                };
                line += &format!("[{:.0}/{:.0}]", ex(pm), ex(gm));
            }
            ft += e;
        }
        total += ft / frames[0].len() as f64;
        eprintln!("{line}");
    }
    println!(
        "{} mean recon {:.3}",
        dir.display(),
        100.0 * total / kk as f64
    );
}
