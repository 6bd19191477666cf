//! Finite-difference checks of every Step-1 loss through the whole chain: flat
//! parameters → 6D rotations / log-scales / centres → Mahalanobis segmentation →
//! transfer H_{k→t} → point losses. f64 throughout; central differences with
//! h = 1e-6; relative error < 1e-3 (absolute floor 1e-6 for near-zero entries).
//! Segmentation and nearest neighbours are piecewise constant, so random clouds
//! are used where no tie flips at ±h (checked by the loss being smooth: a flip
//! would show as a large mismatch).

use glam::{DVec3, Vec3};
use gsart::fit::fitter::{self, Data, EmdPair, FitConfig, FlowField, PlanB, Ws};
use gsart::fit::gaussians::{GradAcc, Params};
use gsart::fit::losses::emd;
use gsart::fit::schedule::Schedule;
use gsart::geom::assignment::Lap;
use gsart::pipeline::Quality;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

fn cloud(rng: &mut StdRng, n: usize, shift: Vec3) -> Vec<Vec3> {
    (0..n)
        .map(|_| {
            Vec3::new(
                rng.random_range(-0.5..0.5),
                rng.random_range(-0.3..0.3),
                rng.random_range(-0.2..0.2),
            ) + shift
        })
        .collect()
}

fn setup(kk: usize, m: usize) -> (Data, Params, StdRng) {
    let mut rng = StdRng::seed_from_u64(11);
    let frames: Vec<Vec<Vec3>> = (0..kk)
        .map(|k| cloud(&mut rng, 60, Vec3::new(0.05 * k as f32, 0.0, 0.02)))
        .collect();
    let data = Data::new(frames);
    let mut p = Params::new(m, kk);
    for v in p.x.iter_mut() {
        *v += rng.random_range(-0.15..0.15);
    }
    for i in 0..m {
        p.set_log_scale(i, DVec3::new(-1.5 + 0.1 * i as f64, -1.8, -2.0));
        for k in 0..kk {
            let c = DVec3::new(-0.4 + 0.8 * i as f64 / (m - 1) as f64, 0.03 * k as f64, 0.0);
            p.set_center(
                k,
                i,
                c + DVec3::new(
                    rng.random_range(-0.05..0.05),
                    rng.random_range(-0.05..0.05),
                    0.0,
                ),
            );
        }
    }
    (data, p, rng)
}

fn check(p: &Params, f: &dyn Fn(&Params, Option<&mut GradAcc>) -> f64, what: &str) {
    let mut acc = GradAcc::new(p.layout);
    let base = f(p, Some(&mut acc));
    assert!(base.is_finite() && base != 0.0, "{what}: loss {base}");
    let mut g = vec![0.0; p.x.len()];
    acc.to_flat(p, &mut g);
    let h = 1e-6;
    let mut worst: f64 = 0.0;
    let mut nonzero = 0;
    for (j, &gj) in g.iter().enumerate() {
        let mut a = p.clone();
        a.x[j] += h;
        let mut b = p.clone();
        b.x[j] -= h;
        let fd = (f(&a, None) - f(&b, None)) / (2.0 * h);
        let err = (fd - gj).abs() / fd.abs().max(gj.abs()).max(1e-6);
        if fd.abs() > 1e-9 {
            nonzero += 1;
        }
        worst = worst.max(err);
        assert!(err < 1e-3, "{what}: param {j}: fd {fd} analytic {gj}");
    }
    assert!(
        nonzero > 10,
        "{what}: only {nonzero} parameters influence the loss"
    );
    eprintln!(
        "{what}: worst relative error {worst:.2e} over {} params",
        p.x.len()
    );
}

fn cfg(occluded: bool) -> FitConfig {
    FitConfig::new(Schedule::preset(Quality::Fast, true), occluded, 0)
}

#[test]
fn mle_and_sep_gradients() {
    let (data, p, _) = setup(3, 4);
    let batch: Vec<usize> = (0..60).collect();
    for (what, wm, ws_) in [("mle", 1.0, 0.0), ("sep", 0.0, 60.0)] {
        let mut c = cfg(false);
        c.weights.mle = wm;
        c.weights.sep = ws_;
        let f = |p: &Params, acc: Option<&mut GradAcc>| {
            let mut ws = Ws::default();
            ws.eval_all(p);
            let (a, b) = fitter::loss_a(&data, 1, &batch, &c, &mut ws, acc);
            wm * a + ws_ / 60.0 * b
        };
        check(&p, &f, what);
    }
}

fn plan_full(data: &Data, rng: &mut StdRng, k: usize) -> PlanB {
    let kk = data.k();
    let mut plan = PlanB {
        k,
        src: vec![Vec::new(); kk],
        rev: vec![Vec::new(); kk],
        ..Default::default()
    };
    plan.src[k] = (0..40).map(|_| rng.random_range(0..60)).collect();
    for t in 0..kk {
        plan.rev[t] = (0..30).map(|_| rng.random_range(0..60)).collect();
    }
    plan
}

#[test]
fn chamfer_emd_flow_gradients_through_transfer() {
    let (data, p, mut rng) = setup(3, 4);
    let k = 1;
    // Chamfer.
    let mut plan = plan_full(&data, &mut rng, k);
    plan.use_cd = true;
    let c = cfg(false);
    let f = |p: &Params, acc: Option<&mut GradAcc>| {
        let mut ws = Ws::default();
        ws.eval_all(p);
        let l = fitter::loss_b(&data, &plan, &c, None, &mut ws, acc);
        l.cd
    };
    check(&p, &f, "chamfer");
    // EMD with a fixed optimal assignment per target frame.
    let mut plan = plan_full(&data, &mut rng, k);
    let mut ws = Ws::default();
    ws.eval_all(&p);
    for t in (0..3).filter(|&t| t != k) {
        let rows: Vec<usize> = (0..20).collect();
        let cols: Vec<usize> = (20..40).collect();
        let a: Vec<DVec3> = rows
            .iter()
            .map(|&i| {
                gsart::fit::gaussians::TransferSrc::new(&ws.gs[k], data.frames[k][i])
                    .moved(&ws.gs[t])
            })
            .collect();
        let b: Vec<DVec3> = cols.iter().map(|&i| data.frames[t][i]).collect();
        let mut sigma = Vec::new();
        assert!(emd::assign(
            &a,
            &b,
            &mut Lap::default(),
            &mut Vec::new(),
            &mut sigma
        ));
        plan.emd.push(EmdPair {
            t,
            rows,
            cols: cols.into_iter().map(|i| (t, i)).collect(),
            sigma,
            uses: 1,
        });
    }
    let f = |p: &Params, acc: Option<&mut GradAcc>| {
        let mut ws = Ws::default();
        ws.eval_all(p);
        fitter::loss_b(&data, &plan, &c, None, &mut ws, acc).emd
    };
    check(&p, &f, "emd");
    // Flow towards k+1 and k−1 with an arbitrary estimate.
    let mut ff = FlowField {
        idx: vec![(0..30).collect(); 3],
        fwd: vec![None; 3],
        bwd: vec![None; 3],
    };
    ff.fwd[k] = Some(
        (0..30)
            .map(|i| DVec3::new(0.01 * i as f64, -0.02, 0.03))
            .collect(),
    );
    ff.bwd[k] = Some(
        (0..30)
            .map(|i| DVec3::new(-0.05, 0.001 * i as f64, 0.0))
            .collect(),
    );
    let mut plan = plan_full(&data, &mut rng, k);
    plan.flow = true;
    let f = |p: &Params, acc: Option<&mut GradAcc>| {
        let mut ws = Ws::default();
        ws.eval_all(p);
        fitter::loss_b(&data, &plan, &c, Some(&ff), &mut ws, acc).flow
    };
    check(&p, &f, "flow");
}

#[test]
fn occluded_losses_gradients() {
    let (data, p, mut rng) = setup(4, 3);
    let t = 2;
    let kk = 4;
    let mut plan = PlanB {
        k: t,
        occluded: true,
        src: vec![Vec::new(); kk],
        rev: vec![Vec::new(); kk],
        ..Default::default()
    };
    for j in 0..kk {
        plan.src[j] = (0..20).map(|_| rng.random_range(0..60)).collect();
    }
    plan.rev[t] = (0..30).map(|_| rng.random_range(0..60)).collect();
    let c = cfg(true);
    // One-directional Chamfer to the fusion.
    let mut pc = plan.clone();
    pc.use_cd = true;
    let f = |p: &Params, acc: Option<&mut GradAcc>| {
        let mut ws = Ws::default();
        ws.eval_all(p);
        fitter::loss_b(&data, &pc, &c, None, &mut ws, acc).cd
    };
    check(&p, &f, "occluded chamfer");
    // Split-half fusion regulariser.
    let mut ps = plan.clone();
    ps.split = Some(vec![true, false, true, false]);
    let f = |p: &Params, acc: Option<&mut GradAcc>| {
        let mut ws = Ws::default();
        ws.eval_all(p);
        fitter::loss_b(&data, &ps, &c, None, &mut ws, acc).split
    };
    check(&p, &f, "split-half");
    // EMD of the observed points into the fusion (rectangular assignment).
    let mut pe = plan.clone();
    let mut ws = Ws::default();
    ws.eval_all(&p);
    let rows: Vec<usize> = (0..15).collect();
    let cols: Vec<(usize, usize)> = [0usize, 1, 3]
        .iter()
        .flat_map(|&j| (0..8).map(move |i| (j, i * 3)))
        .collect();
    let a: Vec<DVec3> = rows.iter().map(|&i| data.frames[t][i]).collect();
    let b: Vec<DVec3> = cols
        .iter()
        .map(|&(j, i)| {
            gsart::fit::gaussians::TransferSrc::new(&ws.gs[j], data.frames[j][i]).moved(&ws.gs[t])
        })
        .collect();
    let mut sigma = Vec::new();
    assert!(emd::assign(
        &a,
        &b,
        &mut Lap::default(),
        &mut Vec::new(),
        &mut sigma
    ));
    pe.emd.push(EmdPair {
        t,
        rows,
        cols,
        sigma,
        uses: 1,
    });
    let f = |p: &Params, acc: Option<&mut GradAcc>| {
        let mut ws = Ws::default();
        ws.eval_all(p);
        fitter::loss_b(&data, &pe, &c, None, &mut ws, acc).emd
    };
    check(&p, &f, "occluded emd");
}
