//! The continuous 6D rotation representation (Zhou et al.): two 3-vectors a1, a2
//! mapped to a rotation by Gram–Schmidt, b1 = a1/|a1|, b2 = normalise(a2 − (b1·a2) b1),
//! b3 = b1 × b2, R = [b1 b2 b3] (columns). With its hand-derived backward pass.

use glam::{DMat3, DVec3};

/// Identity rotation in 6D form.
pub const IDENTITY_6D: [f64; 6] = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0];

/// Rotation matrix (columns b1, b2, b3) of a 6D vector [a1; a2].
/// Degenerate inputs (zero or parallel columns) fall back to a valid rotation.
pub fn to_matrix(a: &[f64]) -> DMat3 {
    let a1 = DVec3::new(a[0], a[1], a[2]);
    let a2 = DVec3::new(a[3], a[4], a[5]);
    let b1 = a1.try_normalize().unwrap_or(DVec3::X);
    let u2 = a2 - b1 * b1.dot(a2);
    let b2 = u2
        .try_normalize()
        .unwrap_or_else(|| b1.any_orthonormal_vector());
    DMat3::from_cols(b1, b2, b1.cross(b2))
}

/// Given dL/dR (same column layout as `to_matrix`), adds dL/da to `out` (6 values).
pub fn backward(a: &[f64], g: &DMat3, out: &mut [f64]) {
    let a1 = DVec3::new(a[0], a[1], a[2]);
    let a2 = DVec3::new(a[3], a[4], a[5]);
    let n1 = a1.length();
    if n1 < 1e-12 {
        return;
    }
    let b1 = a1 / n1;
    let u2 = a2 - b1 * b1.dot(a2);
    let n2 = u2.length();
    if n2 < 1e-12 {
        return;
    }
    let b2 = u2 / n2;
    let (g1, g2, g3) = (g.x_axis, g.y_axis, g.z_axis);
    // b3 = b1 × b2.
    let mut gb1 = g1 + b2.cross(g3);
    let gb2 = g2 + g3.cross(b1);
    // b2 = u2 / |u2|.
    let gu2 = (gb2 - b2 * b2.dot(gb2)) / n2;
    // u2 = a2 − (b1·a2) b1.
    let ga2 = gu2 - b1 * b1.dot(gu2);
    gb1 -= a2 * b1.dot(gu2) + gu2 * b1.dot(a2);
    // b1 = a1 / |a1|.
    let ga1 = (gb1 - b1 * b1.dot(gb1)) / n1;
    out[0] += ga1.x;
    out[1] += ga1.y;
    out[2] += ga1.z;
    out[3] += ga2.x;
    out[4] += ga2.y;
    out[5] += ga2.z;
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn orthonormal_and_identity() {
        let r = to_matrix(&IDENTITY_6D);
        assert!((r - DMat3::IDENTITY).abs_diff_eq(DMat3::ZERO, 1e-15));
        let r = to_matrix(&[0.3, -1.2, 0.5, 2.0, 0.1, -0.7]);
        assert!((r.transpose() * r).abs_diff_eq(DMat3::IDENTITY, 1e-12));
        assert!((r.determinant() - 1.0).abs() < 1e-12);
        let r = to_matrix(&[0.0; 6]);
        assert!((r.determinant() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn backward_matches_finite_differences() {
        let a = [0.3, -1.2, 0.5, 2.0, 0.1, -0.7];
        // L = Σ W ⊙ R for a fixed weight matrix W.
        let w = DMat3::from_cols_array(&[0.3, -0.5, 1.1, 0.7, 0.2, -0.9, 1.3, -0.4, 0.6]);
        let loss = |a: &[f64]| {
            let r = to_matrix(a);
            (0..3).map(|c| r.col(c).dot(w.col(c))).sum::<f64>()
        };
        let mut g = [0.0; 6];
        backward(&a, &w, &mut g);
        for j in 0..6 {
            let h = 1e-6;
            let mut ap = a;
            ap[j] += h;
            let mut am = a;
            am[j] -= h;
            let fd = (loss(&ap) - loss(&am)) / (2.0 * h);
            assert!(
                (fd - g[j]).abs() <= 1e-3 * fd.abs().max(1e-3),
                "j={j} fd={fd} an={}",
                g[j]
            );
        }
    }
}
