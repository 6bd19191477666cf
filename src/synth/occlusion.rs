//! Visibility of a point cloud from a camera: hidden point removal (Katz, Tal, Basri
//! 2007, "Direct visibility of point sets"): spherical flipping about the camera, then
//! a point is visible iff its flipped image is a vertex of the convex hull of the
//! flipped set and the camera (the hull: [`crate::geom::hull`]). Should the hull fail
//! numerically, a z-buffer splat test is used instead (reported through [`Method`]).

use glam::DVec3;

use crate::geom::hull::hull_vertices;

/// Radius factor of the spherical flipping, × the largest camera distance (as bench-dev).
pub const HPR_RADIUS_FACTOR: f64 = 100.0;

/// How visibility was decided.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Method {
    HiddenPointRemoval,
    ZBuffer,
}

/// Visibility mask of `points` seen from `camera`.
pub fn visible(points: &[DVec3], camera: DVec3) -> (Vec<bool>, Method) {
    match hpr(points, camera, HPR_RADIUS_FACTOR) {
        Some(v) => (v, Method::HiddenPointRemoval),
        None => (zbuffer(points, camera), Method::ZBuffer),
    }
}

/// Hidden point removal; `None` when the hull could not be built.
pub fn hpr(points: &[DVec3], camera: DVec3, radius_factor: f64) -> Option<Vec<bool>> {
    let q: Vec<DVec3> = points.iter().map(|p| *p - camera).collect();
    let max_d = q.iter().map(|v| v.length()).fold(0.0, f64::max);
    if max_d <= 0.0 {
        return None;
    }
    let r = radius_factor * max_d;
    let mut flipped: Vec<DVec3> = q
        .iter()
        .map(|v| {
            let l = v.length();
            if l > 0.0 {
                *v + *v * (2.0 * (r - l) / l)
            } else {
                *v
            }
        })
        .collect();
    flipped.push(DVec3::ZERO); // the camera
    let on_hull = hull_vertices(&flipped)?;
    Some(on_hull[..points.len()].to_vec())
}

/// Fallback visibility: perspective z-buffer with splats about the point spacing.
pub fn zbuffer(points: &[DVec3], camera: DVec3) -> Vec<bool> {
    let n = points.len();
    if n == 0 {
        return Vec::new();
    }
    let centroid = points.iter().copied().sum::<DVec3>() / n as f64;
    let fwd = (centroid - camera).normalize_or(DVec3::X);
    let (right, up) = fwd.any_orthonormal_pair();
    let proj: Vec<(f64, f64, f64)> = points
        .iter()
        .map(|p| {
            let v = *p - camera;
            let z = v.dot(fwd).max(1e-9);
            (v.dot(right) / z, v.dot(up) / z, z)
        })
        .collect();
    let (mut lo_u, mut hi_u, mut lo_v, mut hi_v) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for &(u, v, _) in &proj {
        lo_u = lo_u.min(u);
        hi_u = hi_u.max(u);
        lo_v = lo_v.min(v);
        hi_v = hi_v.max(v);
    }
    // Coarse cells (about a dozen points each) so that no cell of a front surface is
    // empty, which would let points behind it through.
    let res = ((n as f64 / 12.0).sqrt().ceil() as usize).clamp(4, 512);
    let su = (hi_u - lo_u).max(1e-12) / res as f64;
    let sv = (hi_v - lo_v).max(1e-12) / res as f64;
    let cell = |u: f64, v: f64| {
        let i = (((u - lo_u) / su) as usize).min(res - 1);
        let j = (((v - lo_v) / sv) as usize).min(res - 1);
        (i, j)
    };
    let mut depth = vec![f64::INFINITY; res * res];
    for &(u, v, z) in &proj {
        let (i, j) = cell(u, v);
        let d = &mut depth[j * res + i];
        *d = d.min(z);
    }
    let (zmin, zmax) = proj
        .iter()
        .fold((f64::MAX, f64::MIN), |(a, b), p| (a.min(p.2), b.max(p.2)));
    let tol = 0.01 * (zmax - zmin).max(1e-12);
    proj.iter()
        .map(|&(u, v, z)| {
            let (i, j) = cell(u, v);
            // Hidden when its own cell holds a clearly nearer point; "clearly" allows for
            // a surface inclined within the cell (two cell widths of depth).
            let cell_world = 2.0 * su.max(sv) * z;
            z <= depth[j * res + i] + tol.max(cell_world)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Libm;
    use rand::{rngs::StdRng, Rng, SeedableRng};

    #[test]
    fn hpr_sees_the_near_side_of_a_sphere() {
        let mut rng = StdRng::seed_from_u64(5);
        let pts: Vec<DVec3> = (0..4000)
            .map(|_| {
                let z: f64 = rng.random::<f64>() * 2.0 - 1.0;
                let phi = rng.random::<f64>() * std::f64::consts::TAU;
                let s = (1.0 - z * z).sqrt();
                DVec3::new(s * phi.lcos(), s * phi.lsin(), z) * 0.4
            })
            .collect();
        let cam = DVec3::new(0.0, 0.0, 2.0);
        let vis = hpr(&pts, cam, HPR_RADIUS_FACTOR).unwrap();
        let mut near_seen = 0;
        let mut near = 0;
        for (p, v) in pts.iter().zip(&vis) {
            if p.z < -0.05 {
                assert!(!v, "far side point {p} visible");
            }
            if p.z > 0.2 {
                near += 1;
                near_seen += *v as usize;
            }
        }
        assert!(near_seen as f64 > 0.95 * near as f64, "{near_seen}/{near}");
        let zb = zbuffer(&pts, cam);
        // splats leak at the silhouette only
        let far = pts.iter().filter(|p| p.z < -0.1).count();
        let far_seen = pts
            .iter()
            .zip(&zb)
            .filter(|(p, &v)| p.z < -0.1 && v)
            .count();
        assert!(far_seen * 20 < far, "{far_seen}/{far}");
        assert!(zb.iter().filter(|&&v| v).count() > 1000);
    }
}
