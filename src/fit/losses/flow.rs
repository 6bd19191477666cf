//! L_flow: mean |(H_{k→t}(x) − x) − g(x)|² over points x of frame k with an
//! estimated scene flow g(x) towards an adjacent frame t (k ± 1).

use glam::DVec3;

/// `moved[n]` = H_{k→t}(x_n); gradient dL/dmoved added to `gm` when given.
pub fn flow(
    moved: &[DVec3],
    src: &[DVec3],
    est: &[DVec3],
    w: f64,
    mut gm: Option<&mut [DVec3]>,
) -> f64 {
    if moved.is_empty() {
        return 0.0;
    }
    let s = w / moved.len() as f64;
    let mut total = 0.0;
    for n in 0..moved.len() {
        let d = moved[n] - src[n] - est[n];
        total += d.length_squared();
        if let Some(gm) = gm.as_deref_mut() {
            gm[n] += d * (2.0 * s);
        }
    }
    total * s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gradient_matches_finite_differences() {
        let moved: Vec<DVec3> = (0..5)
            .map(|i| DVec3::new(i as f64 * 0.3, 0.1, -0.2 * i as f64))
            .collect();
        let src: Vec<DVec3> = (0..5)
            .map(|i| DVec3::new(0.1, i as f64 * 0.2, 0.3))
            .collect();
        let est: Vec<DVec3> = (0..5)
            .map(|i| DVec3::new(-0.05 * i as f64, 0.2, 0.0))
            .collect();
        let mut g = vec![DVec3::ZERO; 5];
        flow(&moved, &src, &est, 0.7, Some(&mut g));
        let h = 1e-6;
        for n in 0..5 {
            for c in 0..3 {
                let (mut p, mut q) = (moved.clone(), moved.clone());
                p[n][c] += h;
                q[n][c] -= h;
                let fd =
                    (flow(&p, &src, &est, 0.7, None) - flow(&q, &src, &est, 0.7, None)) / (2.0 * h);
                assert!((fd - g[n][c]).abs() <= 1e-3 * fd.abs().max(1e-3));
            }
        }
    }
}
