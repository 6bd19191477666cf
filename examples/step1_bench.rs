//! Step-1 measurement on bench-dev sequences: mean Rand index of the Step-1 labels,
//! reconstruction and flow error of the Step-1 part poses (SPEC §5, canonical frame
//! 0), ms per iteration and wall time.
//!
//! Usage: `cargo run --release --example step1_bench -- DIR... [--quality fast|balanced|paper]
//! [--iters N] [--m M | --parts LO-HI] [--occlusion auto|on|off] [--seed S] [--no-emd] ...`

use std::path::Path;

use glam::{DVec3, Vec3};
use gsart::fit::fitter::{FitConfig, Weights};
use gsart::fit::select;
use gsart::io::gt::GroundTruth;
use gsart::io::sequence::{Frame, Sequence};
use gsart::pipeline::{Control, FitOptions, Occlusion, Quality};

fn read_bench_ply(path: &Path) -> (Vec<Vec3>, Vec<u32>) {
    let bytes = std::fs::read(path).expect("read ply");
    let c = gsart::io::ply::read_ply(&bytes, &path.display().to_string()).expect("ply");
    let labels = c.labels.expect("part labels");
    (c.points, labels)
}

pub fn load(dir: &Path) -> (Sequence, GroundTruth) {
    let gt_text = std::fs::read_to_string(dir.join("gt.json")).expect("gt.json");
    let gt = GroundTruth::from_json(&gt_text, "gt.json").expect("gt");
    let frames = gt
        .frames
        .iter()
        .map(|name| {
            let (points, labels) = read_bench_ply(&dir.join(name));
            Frame {
                name: name.clone(),
                points,
                labels: Some(labels),
            }
        })
        .collect();
    (Sequence { frames }, gt)
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mut dirs = Vec::new();
    let mut opts = FitOptions::default();
    let mut fixed_m: Option<usize> = None;
    let mut weights = Weights::default();
    let mut lr: Option<f64> = None;
    let mut notrack = true;
    let mut with_flow = false;
    let mut batch: Option<usize> = None;
    let mut emd_n: Option<usize> = None;
    let mut refresh: Option<usize> = None;
    let mut pose: Option<gsart::fit::pose_init::PoseInitOpts> = Some(Default::default());
    let mut search: Option<gsart::fit::pose_search::PoseSearchOpts> = Some(Default::default());
    let mut mseg: Option<gsart::fit::motion_seg::MotionSegOpts> = Some(Default::default());
    // Re-segmentation rounds: the quality preset's unless --ms-rounds is given.
    let mut ms_rounds: Option<usize> = None;
    let mut i = 0;
    while i < args.len() {
        let a = args[i].as_str();
        let mut val = || {
            i += 1;
            args[i].clone()
        };
        match a {
            "--quality" => {
                opts.quality = match val().as_str() {
                    "fast" => Quality::Fast,
                    "paper" => Quality::Paper,
                    _ => Quality::Balanced,
                }
            }
            "--iters" => opts.iters = Some(val().parse().expect("iters")),
            "--m" => fixed_m = Some(val().parse().expect("m")),
            "--parts" => {
                let v = val();
                let (a, b) = v.split_once('-').expect("LO-HI");
                opts.parts = Some((a.parse().expect("lo"), b.parse().expect("hi")));
            }
            "--occlusion" => {
                opts.occlusion = match val().as_str() {
                    "on" => Occlusion::On,
                    "off" => Occlusion::Off,
                    _ => Occlusion::Auto,
                }
            }
            "--seed" => opts.seed = val().parse().expect("seed"),
            "--no-mle" => weights.mle = 0.0,
            "--no-emd" => weights.emd = 0.0,
            "--no-cd" => weights.cd = 0.0,
            "--no-sep" => weights.sep = 0.0,
            "--no-split" => weights.split = 0.0,
            "--lr" => lr = Some(val().parse().expect("lr")),
            "--batch" => batch = Some(val().parse().expect("batch")),
            "--emd-n" => emd_n = Some(val().parse().expect("emd-n")),
            "--refresh" => refresh = Some(val().parse().expect("refresh")),
            "--flow" => weights.flow = val().parse().expect("flow"),
            "--track" => notrack = false,
            "--no-pose-init" => pose = None,
            "--no-search" => search = None,
            "--no-mseg" => mseg = None,
            "--ms-rounds" => ms_rounds = Some(val().parse().expect("ms-rounds")),
            "--ms-on" => mseg = Some(Default::default()),
            "--ps-on" => search = Some(Default::default()),
            "--ms-near" => {
                if let Some(o) = mseg.as_mut() {
                    o.nearest = val().parse().expect("ms-near")
                }
            }
            "--ps-rot" => {
                if let Some(o) = search.as_mut() {
                    o.rotations = val().parse().expect("ps-rot")
                }
            }
            "--ps-top" => {
                if let Some(o) = search.as_mut() {
                    o.top = val().parse().expect("ps-top")
                }
            }
            "--ps-probe" => {
                if let Some(o) = search.as_mut() {
                    o.probe = val().parse().expect("ps-probe")
                }
            }
            "--ps-rigid" => {
                if let Some(o) = search.as_mut() {
                    o.rigid_ratio = val().parse().expect("ps-rigid")
                }
            }
            "--ps-ficp" => {
                if let Some(o) = search.as_mut() {
                    o.final_icp = val().parse().expect("ps-ficp")
                }
            }
            "--ps-keep" => {
                if let Some(o) = search.as_mut() {
                    o.keep_ratio = val().parse().expect("ps-keep")
                }
            }
            "--ps-noflip" => {
                if let Some(o) = search.as_mut() {
                    o.flip_guard = false
                }
            }
            "--ps-snap" => {
                if let Some(o) = search.as_mut() {
                    o.snap_ratio = val().parse().expect("ps-snap")
                }
            }
            "--ps-occl" => {
                if let Some(o) = search.as_mut() {
                    o.occluded = true
                }
            }
            "--ps-no-excl" => {
                if let Some(o) = search.as_mut() {
                    o.exclusive = false
                }
            }
            "--ps-pivots" => {
                if let Some(o) = search.as_mut() {
                    o.pivots = val().parse().expect("ps-pivots")
                }
            }
            "--pi-refine" => {
                pose.get_or_insert_with(Default::default).refine_every =
                    val().parse().expect("refine")
            }
            "--pi-icp" => {
                pose.get_or_insert_with(Default::default).icp = val().parse().expect("icp")
            }
            "--pi-keep" => {
                pose.get_or_insert_with(Default::default).keep = val().parse().expect("keep")
            }
            "--pi-flow-n" => {
                pose.get_or_insert_with(Default::default).flow_n = val().parse().expect("n")
            }
            "--with-flow" => with_flow = true,
            "--sep" => weights.sep = val().parse().expect("sep"),
            _ => dirs.push(a.to_string()),
        }
        i += 1;
    }
    println!("seq,m,occl,iters,ri,recon,flow,ms_per_it,total_s,final_cd,candidates");
    let mut sums = [0.0f64; 4];
    for d in &dirs {
        let (seq, gt) = load(Path::new(d));
        let t0 = std::time::Instant::now();
        let res = match fixed_m {
            Some(m) => {
                let prep = select::prepare(&seq, &opts).expect("prepare");
                let mut cfg = FitConfig::new(prep.sched.clone(), prep.occluded, opts.seed);
                cfg.weights = weights.clone();
                cfg.track_init = !notrack;
                cfg.pose_init = pose;
                cfg.pose_search = search;
                cfg.motion_seg = mseg.map(|mut o| {
                    o.rounds = ms_rounds.unwrap_or(prep.sched.reseg_rounds);
                    o
                });
                if let Some(v) = lr {
                    cfg.sched.lr = v;
                    if let Some(o) = cfg.pose_search.as_mut() {
                        o.main_lr = v;
                    }
                }
                if let Some(v) = batch {
                    cfg.sched.batch = v;
                }
                if let Some(v) = emd_n {
                    cfg.sched.emd_n = v;
                }
                if let Some(v) = refresh {
                    cfg.sched.emd_refresh = v;
                }
                let ff = with_flow.then(|| {
                    gsart::fit::fitter::FlowField::compute(
                        &prep.data,
                        &gsart::fit::flow::OtFlow::default(),
                        256,
                        opts.seed,
                    )
                });
                let (params, stats) = gsart::fit::fitter::fit_candidate(
                    &prep.data,
                    m,
                    &cfg,
                    ff.as_ref().or(prep.flow.as_ref()),
                    &mut |_| Control::Continue,
                )
                .expect("fit");
                let chamfer =
                    gsart::fit::fitter::final_chamfer(&prep.data, &params, prep.occluded, 1024);
                select::candidate_result(&prep, &params, chamfer, m, stats.iterations, 0.0)
            }
            None => gsart::pipeline::fit_step1(&seq, &opts, &|_| Control::Continue).expect("fit"),
        };
        let secs = t0.elapsed().as_secs_f64();
        if std::env::var("VERBOSE").as_deref() == Ok("3") {
            // L_merge between Gaussians with the same / different majority GT part.
            let gl0 = seq.frames[0].labels.as_ref().expect("labels");
            let lab0 = res.model.segment(0, &seq.frames[0].points);
            let m = res.model.m;
            let mut maj = vec![std::collections::HashMap::<u32, usize>::new(); m];
            for (a, g) in lab0.iter().zip(gl0) {
                *maj[*a as usize].entry(*g).or_default() += 1;
            }
            let major: Vec<u32> = maj
                .iter()
                .map(|h| h.iter().max_by_key(|e| *e.1).map_or(u32::MAX, |e| *e.0))
                .collect();
            let poses: Vec<Vec<glam::DMat4>> = (0..seq.frames.len())
                .map(|t| (0..m).map(|i| res.model.pose(t, i)).collect())
                .collect();
            let (mut same, mut diff) = (Vec::new(), f64::INFINITY);
            for i in 0..m {
                for j in (i + 1)..m {
                    let l = gsart::kinematics::merge::merge_loss(&poses, i, j);
                    if major[i] == major[j] {
                        same.push(format!("{i}-{j}(p{}):{l:.4}", major[i]));
                    } else {
                        diff = diff.min(l);
                    }
                }
            }
            eprintln!(
                "same-part L_merge: {} | min different-part {diff:.4}",
                same.join(" ")
            );
        }
        let kk = seq.frames.len();
        // Mean RI over frames.
        let mut ri = 0.0;
        for k in 0..kk {
            let gl = seq.frames[k].labels.as_ref().expect("labels");
            let gl: Vec<u32> = res.working[k].iter().map(|&j| gl[j as usize]).collect();
            let r = gsart::eval::rand_index::rand_index(&res.labels[k], &gl).expect("ri");
            if std::env::var("VERBOSE").is_ok() {
                eprintln!("frame {k}: RI {r:.3}");
            }
            ri += r;
        }
        ri /= kk as f64;
        // Reconstruction / flow error on canonical frame 0.
        let pts = &seq.frames[0].points;
        let gl0 = seq.frames[0].labels.as_ref().expect("labels");
        let pred0 = res.model.segment(0, pts);
        let mut recon = 0.0;
        let mut flow = 0.0;
        let mut prev: Option<(Vec<DVec3>, Vec<DVec3>)> = None;
        for t in 0..kk {
            let mut p_t = Vec::with_capacity(pts.len());
            let mut y_t = Vec::with_capacity(pts.len());
            let mut e = 0.0;
            for (n, x) in pts.iter().enumerate() {
                let x = x.as_dvec3();
                let a = pred0[n] as usize;
                let g = gl0[n] as usize;
                let pm =
                    res.model.pose(t, a) * gsart::geom::se3::rigid_inverse(&res.model.pose(0, a));
                let gm = gt.poses[t][g] * gsart::geom::se3::rigid_inverse(&gt.poses[0][g]);
                let p = pm.transform_point3(x);
                let y = gm.transform_point3(x);
                e += (p - y).length();
                p_t.push(p);
                y_t.push(y);
            }
            recon += e / pts.len() as f64;
            if std::env::var("VERBOSE").as_deref() == Ok("2") {
                // Per predicted part: point count, mean error, majority GT label.
                let m = res.model.m;
                let mut cnt = vec![0usize; m];
                let mut err = vec![0.0; m];
                let mut maj = vec![std::collections::HashMap::<u32, usize>::new(); m];
                for (n, x) in pts.iter().enumerate() {
                    let a = pred0[n] as usize;
                    cnt[a] += 1;
                    err[a] += (p_t[n] - y_t[n]).length();
                    *maj[a].entry(gl0[n]).or_default() += 1;
                    let _ = x;
                }
                let desc: Vec<String> = (0..m)
                    .map(|a| {
                        let g = maj[a].iter().max_by_key(|e| *e.1).map_or(99, |e| *e.0);
                        format!(
                            "{a}:{}/{}/{:.1}",
                            g,
                            cnt[a],
                            100.0 * err[a] / cnt[a].max(1) as f64
                        )
                    })
                    .collect();
                eprintln!("  t{t} parts(gt/n/err): {}", desc.join(" "));
            }
            if std::env::var("VERBOSE").is_ok() {
                eprintln!("frame {t}: recon {:.3}", e / pts.len() as f64 * 100.0);
            }
            if let Some((pp, yp)) = &prev {
                let mut f = 0.0;
                for n in 0..pts.len() {
                    f += ((p_t[n] - pp[n]) - (y_t[n] - yp[n])).length();
                }
                flow += f / pts.len() as f64;
            }
            prev = Some((p_t, y_t));
        }
        recon = recon / kk as f64 * 100.0;
        flow = flow / (kk - 1) as f64 * 100.0;
        let iters: usize = res
            .timings
            .per_candidate
            .iter()
            .map(|c| c.2)
            .sum::<usize>()
            .max(res.iterations);
        let ms_it = secs * 1000.0 / iters.max(1) as f64;
        let name = Path::new(d)
            .components()
            .rev()
            .take(2)
            .map(|c| c.as_os_str().to_string_lossy().to_string())
            .collect::<Vec<_>>();
        println!(
            "{}/{},{},{},{},{:.4},{:.3},{:.3},{:.3},{:.1},{:.5},{:?}",
            name[1],
            name[0],
            res.m,
            res.occlusion_used,
            res.iterations,
            ri,
            recon,
            flow,
            ms_it,
            secs,
            res.final_chamfer,
            res.candidates
        );
        sums[0] += ri;
        sums[1] += recon;
        sums[2] += flow;
        sums[3] += 1.0;
    }
    if sums[3] > 0.0 {
        println!(
            "MEAN,,,,{:.4},{:.3},{:.3}",
            sums[0] / sums[3],
            sums[1] / sums[3],
            sums[2] / sums[3]
        );
    }
}
