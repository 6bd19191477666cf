//! L_MLE = −mean_n log Σ_i G_i(x_n): negative log-likelihood of the points under an
//! equal-weight mixture of the frame's normalised Gaussians (log-sum-exp).

use crate::math::Libm;
use glam::DVec3;

use crate::fit::gaussians::{Gauss, GradAcc};

const HALF_LOG_2PI3: f64 = 1.5 * 1.837_877_066_409_345_5; // 1.5·ln(2π)

/// Loss on `points` at frame k, weighted by `w`; gradient into `acc` when given.
pub fn mle(
    gs: &[Gauss],
    k: usize,
    points: &[DVec3],
    w: f64,
    mut acc: Option<&mut GradAcc>,
    scratch: &mut Vec<(f64, DVec3)>,
) -> f64 {
    if points.is_empty() || gs.is_empty() {
        return 0.0;
    }
    let inv_n = w / points.len() as f64;
    let mut total = 0.0;
    for &x in points {
        scratch.clear();
        let mut mx = f64::NEG_INFINITY;
        for g in gs {
            let (m, y) = g.maha(x);
            let lg = -0.5 * m - g.log_s_sum - HALF_LOG_2PI3;
            mx = mx.max(lg);
            scratch.push((lg, y));
        }
        let mut s = 0.0;
        for e in scratch.iter_mut() {
            e.0 = (e.0 - mx).lexp();
            s += e.0;
        }
        total -= mx + s.lln();
        if let Some(acc) = acc.as_deref_mut() {
            for (i, &(e, y)) in scratch.iter().enumerate() {
                let r = e / s * inv_n;
                if r < 1e-300 {
                    continue;
                }
                acc.maha_backward(k, i, &gs[i], x, y, 0.5 * r);
                acc.d_ls[i] += DVec3::splat(r);
            }
        }
    }
    total * inv_n
}
