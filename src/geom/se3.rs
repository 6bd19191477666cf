//! Rigid transforms. Poses are `glam::DMat4` (f64, column-major in memory, acting on
//! column vectors); files store them as 16 numbers row-major or as nested 4×4 lists.

use glam::{DMat3, DMat4, DVec3};

/// 16 numbers, row-major, as in the result format.
pub fn to_row_major(m: &DMat4) -> [f64; 16] {
    m.transpose().to_cols_array()
}

/// Inverse of [`to_row_major`].
pub fn from_row_major(a: &[f64; 16]) -> DMat4 {
    DMat4::from_cols_array(a).transpose()
}

/// Nested `[[f64; 4]; 4]` row-major (as in `gt.json`).
pub fn from_nested(rows: &[[f64; 4]; 4]) -> DMat4 {
    DMat4::from_cols_array_2d(rows).transpose()
}

pub fn to_nested(m: &DMat4) -> [[f64; 4]; 4] {
    m.transpose().to_cols_array_2d()
}

/// The rigid transform x ↦ r x + t.
pub fn rigid(r: DMat3, t: DVec3) -> DMat4 {
    DMat4::from_cols(
        r.x_axis.extend(0.0),
        r.y_axis.extend(0.0),
        r.z_axis.extend(0.0),
        t.extend(1.0),
    )
}

/// Inverse of a rigid transform (cheaper and more exact than a general inverse).
pub fn rigid_inverse(m: &DMat4) -> DMat4 {
    let rt = DMat3::from_mat4(*m).transpose();
    rigid(rt, -(rt * m.w_axis.truncate()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn row_major_round_trip() {
        let a: [f64; 16] = [
            1., 2., 3., 4., 5., 6., 7., 8., 9., 10., 11., 12., 0., 0., 0., 1.,
        ];
        let m = from_row_major(&a);
        // row 0, column 3 is the x translation
        assert_eq!(m.w_axis.x, 4.0);
        assert_eq!(to_row_major(&m), a);
    }

    #[test]
    fn rigid_inverse_is_inverse() {
        let m = DMat4::from_rotation_translation(
            glam::DQuat::from_axis_angle(DVec3::new(1.0, 2.0, 3.0).normalize(), 0.7),
            DVec3::new(0.3, -0.2, 1.0),
        );
        let p = m * rigid_inverse(&m);
        assert!(p.abs_diff_eq(DMat4::IDENTITY, 1e-12));
    }
}
