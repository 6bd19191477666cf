//! Is a point cloud one camera's view? Along every ray from the camera a single-view
//! scan (a depth sensor's frame, hidden point removal) holds at most the first
//! surface, so seen from its camera hardly any point lies behind another in the same
//! image cell. A whole-surface sample has a near and a far side from every direction:
//! about half its points are behind others. [`layered_fraction`] is the fraction of
//! points hidden behind another one, from the direction that hides the fewest.
//!
//! From at most 1024 points per frame it separates bench-dev's occluded frames from
//! its whole surfaces by a wide margin; sparse thin objects look one-layered. The
//! measurements and the threshold are at `fit::select::SINGLE_VIEW_LAYERED`.

use crate::math::Libm;
use glam::{DVec3, Vec3};

use super::knn::point_spacing;

/// Image cell, × the cloud's median point spacing.
const CELL: f64 = 2.5;
/// A point more than this (× spacing) behind the nearest point of its cell is hidden.
const LAYER_GAP: f64 = 4.0;
/// Directions tried over the sphere before the local refinement.
const DIRECTIONS: usize = 600;

/// Near-uniform points on the unit sphere.
fn fibonacci(n: usize) -> Vec<DVec3> {
    let ga = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    (0..n)
        .map(|i| {
            let z = 1.0 - (2.0 * i as f64 + 1.0) / n as f64;
            let r = (1.0 - z * z).max(0.0).sqrt();
            let a = ga * i as f64;
            DVec3::new(r * a.lcos(), r * a.lsin(), z)
        })
        .collect()
}

/// Reusable buffers of one cloud's views.
struct Views {
    /// The points about their centroid.
    points: Vec<DVec3>,
    cell: f64,
    gap: f64,
    xy: Vec<(f64, f64)>,
    depth: Vec<f64>,
    near: Vec<f64>,
    index: Vec<usize>,
}

impl Views {
    /// Points hidden behind another point of their cell, looking along `-v`.
    fn hidden(&mut self, v: DVec3) -> usize {
        let (u, w) = v.any_orthonormal_pair();
        self.xy.clear();
        self.depth.clear();
        let (mut lo, mut hi) = ((f64::MAX, f64::MAX), (f64::MIN, f64::MIN));
        for d in &self.points {
            let q = (d.dot(u), d.dot(w));
            lo = (lo.0.min(q.0), lo.1.min(q.1));
            hi = (hi.0.max(q.0), hi.1.max(q.1));
            self.xy.push(q);
            self.depth.push(-d.dot(v));
        }
        // At most 512 cells a side (a coarser cell only on very elongated clouds).
        let cell = self.cell.max((hi.0 - lo.0).max(hi.1 - lo.1) / 511.0);
        let nx = ((hi.0 - lo.0) / cell) as usize + 1;
        let ny = ((hi.1 - lo.1) / cell) as usize + 1;
        self.near.clear();
        self.near.resize(nx * ny, f64::INFINITY);
        self.index.clear();
        for (q, &z) in self.xy.iter().zip(&self.depth) {
            let i = (((q.0 - lo.0) / cell) as usize).min(nx - 1);
            let j = (((q.1 - lo.1) / cell) as usize).min(ny - 1);
            let c = j * nx + i;
            self.near[c] = self.near[c].min(z);
            self.index.push(c);
        }
        self.index
            .iter()
            .zip(&self.depth)
            .filter(|(&c, &z)| z > self.near[c] + self.gap)
            .count()
    }
}

/// The fraction of `points` hidden behind another point of their image cell, seen
/// from the direction that hides the fewest (module doc); `None` below 16 points or
/// for a degenerate cloud. About 8 ms for 1024 points.
pub fn layered_fraction(points: &[Vec3]) -> Option<f64> {
    if points.len() < 16 {
        return None;
    }
    let h = point_spacing(points);
    if !(h > 0.0 && h.is_finite()) {
        return None;
    }
    let centre = points.iter().map(|p| p.as_dvec3()).sum::<DVec3>() / points.len() as f64;
    let mut views = Views {
        points: points.iter().map(|p| p.as_dvec3() - centre).collect(),
        cell: CELL * h,
        gap: LAYER_GAP * h,
        xy: Vec::with_capacity(points.len()),
        depth: Vec::with_capacity(points.len()),
        near: Vec::new(),
        index: Vec::with_capacity(points.len()),
    };
    let mut best = fibonacci(DIRECTIONS)
        .into_iter()
        .map(|v| (views.hidden(v), v))
        .min_by_key(|b| b.0)?;
    // Local refinement: eight neighbours on a ring, halving it when none is better.
    let mut step = (4.0 * std::f64::consts::PI / DIRECTIONS as f64).sqrt();
    for _ in 0..6 {
        let (u, w) = best.1.any_orthonormal_pair();
        let mut improved = false;
        for k in 0..8 {
            let a = k as f64 * std::f64::consts::FRAC_PI_4;
            let v = (best.1 + step * (a.lcos() * u + a.lsin() * w)).normalize();
            let s = views.hidden(v);
            if s < best.0 {
                best = (s, v);
                improved = true;
            }
        }
        if !improved {
            step *= 0.5;
        }
    }
    Some(best.0 as f64 / points.len() as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Points spread evenly over a unit sphere.
    fn sphere(n: usize) -> Vec<DVec3> {
        fibonacci(n)
    }

    fn f32s(v: &[DVec3]) -> Vec<Vec3> {
        v.iter().map(|p| p.as_vec3()).collect()
    }

    #[test]
    fn a_whole_sphere_is_two_layers_and_one_side_of_it_is_one() {
        let all = sphere(2000);
        let whole = layered_fraction(&f32s(&all)).unwrap();
        assert!(whole > 0.3, "whole sphere {whole}");
        // What a camera 3 radii out (about +x) sees: the cap where p · ĉ > 1/3.
        let cam = DVec3::new(1.0, 0.3, -0.2).normalize();
        let seen: Vec<DVec3> = all
            .iter()
            .copied()
            .filter(|p| p.dot(cam) > 1.0 / 3.0)
            .collect();
        let one = layered_fraction(&f32s(&seen)).unwrap();
        assert!(one < 0.03, "one side {one}");
        // Two spheres, one seen in front of the other: the far one's hidden part is
        // missing, so the view is still one layer.
        let far: Vec<DVec3> = seen
            .iter()
            .map(|p| *p * 0.5 - cam * 2.0 + DVec3::Y * 0.4)
            .collect();
        let both: Vec<DVec3> = seen.iter().copied().chain(far).collect();
        let pair = layered_fraction(&f32s(&both)).unwrap();
        assert!(pair < 0.2, "pair {pair}");
    }

    #[test]
    fn too_few_or_identical_points_give_no_answer() {
        assert!(layered_fraction(&f32s(&sphere(10))).is_none());
        assert!(layered_fraction(&[Vec3::ONE; 40]).is_none());
    }
}
