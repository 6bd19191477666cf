//! Directed squared Chamfer term: mean over a of min_b |a − b|², with gradients to
//! either side. Bidirectional, one-directional (occluded input) and split-half
//! fusion losses are sums of directed terms.

use glam::DVec3;

use crate::geom::knn::Grid;

/// mean_{a} min_{b} |a − b|² · w. `b_grid` must index `b` (same order, as f32).
/// Gradients (when given) are added to `ga` (per a) and `gb` (per b).
pub fn directed(
    a: &[DVec3],
    b: &[DVec3],
    b_grid: &Grid,
    w: f64,
    mut ga: Option<&mut [DVec3]>,
    mut gb: Option<&mut [DVec3]>,
) -> f64 {
    if a.is_empty() || b.is_empty() {
        return 0.0;
    }
    let s = w / a.len() as f64;
    let mut total = 0.0;
    for (ia, &p) in a.iter().enumerate() {
        let Some((j, _)) = b_grid.nearest(p.as_vec3()) else {
            return 0.0;
        };
        let d = p - b[j as usize];
        total += d.length_squared();
        let g = d * (2.0 * s);
        if let Some(ga) = ga.as_deref_mut() {
            ga[ia] += g;
        }
        if let Some(gb) = gb.as_deref_mut() {
            gb[j as usize] -= g;
        }
    }
    total * s
}

/// Rebuilds `grid` over `pts` (f64 → f32 through `buf`).
pub fn index(grid: &mut Grid, pts: &[DVec3], buf: &mut Vec<glam::Vec3>) {
    buf.clear();
    buf.extend(pts.iter().map(|p| p.as_vec3()));
    grid.rebuild(buf);
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    #[test]
    fn gradient_matches_finite_differences() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(5);
        let mut r = || {
            DVec3::new(
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
            )
        };
        let a: Vec<DVec3> = (0..40).map(|_| r()).collect();
        let b: Vec<DVec3> = (0..30).map(|_| r()).collect();
        let f = |a: &[DVec3], b: &[DVec3]| {
            let mut g = Grid::default();
            index(&mut g, b, &mut Vec::new());
            directed(a, b, &g, 1.7, None, None)
        };
        let mut ga = vec![DVec3::ZERO; a.len()];
        let mut gb = vec![DVec3::ZERO; b.len()];
        let mut g = Grid::default();
        index(&mut g, &b, &mut Vec::new());
        directed(&a, &b, &g, 1.7, Some(&mut ga), Some(&mut gb));
        let h = 1e-6;
        for i in 0..a.len() {
            for c in 0..3 {
                let (mut ap, mut am) = (a.clone(), a.clone());
                ap[i][c] += h;
                am[i][c] -= h;
                let fd = (f(&ap, &b) - f(&am, &b)) / (2.0 * h);
                assert!((fd - ga[i][c]).abs() <= 1e-3 * fd.abs().max(1e-3));
            }
        }
        for i in 0..b.len() {
            for c in 0..3 {
                let (mut bp, mut bm) = (b.clone(), b.clone());
                bp[i][c] += h;
                bm[i][c] -= h;
                let fd = (f(&a, &bp) - f(&a, &bm)) / (2.0 * h);
                assert!((fd - gb[i][c]).abs() <= 1e-3 * fd.abs().max(1e-3));
            }
        }
    }
}
