//! L_sep = (1/m) Σ_i exp(−α min_{j≠i} M(μ_j, G_i)): keeps Gaussians apart so each
//! models one rigid part (hard min, gradient through the minimising pair).

use crate::fit::gaussians::{Gauss, GradAcc};
use crate::math::Libm;

/// Loss at frame k weighted by `w`; gradient into `acc` when given.
pub fn sep(gs: &[Gauss], k: usize, alpha: f64, w: f64, mut acc: Option<&mut GradAcc>) -> f64 {
    let m = gs.len();
    if m < 2 {
        return 0.0;
    }
    let mut total = 0.0;
    for i in 0..m {
        let mut best = (usize::MAX, f64::INFINITY);
        for (j, gj) in gs.iter().enumerate() {
            if j != i {
                let (d, _) = gs[i].maha(gj.mu);
                if d < best.1 {
                    best = (j, d);
                }
            }
        }
        let (j, d) = best;
        let e = (-alpha * d).lexp() * w / m as f64;
        total += e;
        if let Some(acc) = acc.as_deref_mut() {
            let (_, y) = gs[i].maha(gs[j].mu);
            let gx = acc.maha_backward(k, i, &gs[i], gs[j].mu, y, -alpha * e);
            let jj = acc.idx(k, j);
            acc.d_mu[jj] += gx;
        }
    }
    total
}
