//! L_EMD: mean squared distance under the optimal one-to-one assignment of the rows
//! `a` to distinct columns `b` (|a| ≤ |b|; equal sizes give the classic EMD, more
//! columns give the occluded-input variant that matches the observed points into a
//! superset). The assignment is solved exactly by `geom::assignment` and may be
//! reused for a few iterations (the caller decides); the gradient treats it as fixed.

use glam::DVec3;

use crate::geom::assignment::Lap;

/// Solves the assignment of `a` into `b` on squared distances. Returns false if
/// it could not be solved (sizes or non-finite points).
pub fn assign(
    a: &[DVec3],
    b: &[DVec3],
    lap: &mut Lap,
    cost: &mut Vec<f64>,
    out: &mut Vec<usize>,
) -> bool {
    cost.clear();
    for p in a {
        cost.extend(b.iter().map(|q| p.distance_squared(*q)));
    }
    lap.solve(cost, a.len(), b.len(), out)
}

/// mean_i |a_i − b_{σ(i)}|² · w with gradients to both sides when given.
pub fn emd(
    a: &[DVec3],
    b: &[DVec3],
    sigma: &[usize],
    w: f64,
    mut ga: Option<&mut [DVec3]>,
    mut gb: Option<&mut [DVec3]>,
) -> f64 {
    if a.is_empty() || sigma.len() != a.len() {
        return 0.0;
    }
    let s = w / a.len() as f64;
    let mut total = 0.0;
    for (i, (&p, &j)) in a.iter().zip(sigma).enumerate() {
        let d = p - b[j];
        total += d.length_squared();
        let g = d * (2.0 * s);
        if let Some(ga) = ga.as_deref_mut() {
            ga[i] += g;
        }
        if let Some(gb) = gb.as_deref_mut() {
            gb[j] -= g;
        }
    }
    total * s
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    #[test]
    fn gradient_matches_finite_differences_and_assignment_is_optimal() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(9);
        let mut r = || {
            DVec3::new(
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
            )
        };
        let a: Vec<DVec3> = (0..6).map(|_| r()).collect();
        let b: Vec<DVec3> = (0..8).map(|_| r()).collect();
        let mut sigma = Vec::new();
        assert!(assign(
            &a,
            &b,
            &mut Lap::default(),
            &mut Vec::new(),
            &mut sigma
        ));
        // Optimal: the loss under σ is ≤ the loss of any single swap/replacement.
        let base = emd(&a, &b, &sigma, 1.0, None, None);
        for i in 0..a.len() {
            for j in 0..b.len() {
                let mut s2 = sigma.clone();
                if let Some(o) = s2.iter().position(|&c| c == j) {
                    s2.swap(i, o);
                } else {
                    s2[i] = j;
                }
                assert!(emd(&a, &b, &s2, 1.0, None, None) >= base - 1e-12);
            }
        }
        let mut ga = vec![DVec3::ZERO; a.len()];
        let mut gb = vec![DVec3::ZERO; b.len()];
        emd(&a, &b, &sigma, 0.3, Some(&mut ga), Some(&mut gb));
        let h = 1e-6;
        for i in 0..a.len() {
            for c in 0..3 {
                let (mut ap, mut am) = (a.clone(), a.clone());
                ap[i][c] += h;
                am[i][c] -= h;
                let fd = (emd(&ap, &b, &sigma, 0.3, None, None)
                    - emd(&am, &b, &sigma, 0.3, None, None))
                    / (2.0 * h);
                assert!((fd - ga[i][c]).abs() <= 1e-3 * fd.abs().max(1e-3));
            }
        }
        for j in 0..b.len() {
            for c in 0..3 {
                let (mut bp, mut bm) = (b.clone(), b.clone());
                bp[j][c] += h;
                bm[j][c] -= h;
                let fd = (emd(&a, &bp, &sigma, 0.3, None, None)
                    - emd(&a, &bm, &sigma, 0.3, None, None))
                    / (2.0 * h);
                assert!((fd - gb[j][c]).abs() <= 1e-3 * fd.abs().max(1e-3));
            }
        }
    }
}
