//! Initialisation: farthest-point sampled centres on the first frame, identity
//! rotations, isotropic scales from the cloud's extent and m; every frame starts
//! equal to the first. (The warm-up on the first frame runs in the fitter.)

use glam::{DVec3, Vec3};

use super::gaussians::Params;

/// Farthest-point sampling (local until `geom::fps` lands): n indices, starting at `start`.
pub fn farthest_point_sampling(points: &[Vec3], n: usize, start: usize) -> Vec<usize> {
    let n = n.min(points.len());
    let mut out = Vec::with_capacity(n);
    if n == 0 {
        return out;
    }
    let mut d = vec![f32::INFINITY; points.len()];
    let mut cur = start.min(points.len() - 1);
    for _ in 0..n {
        out.push(cur);
        let c = points[cur];
        let mut best = (0, -1.0f32);
        for (j, p) in points.iter().enumerate() {
            let dj = d[j].min(p.distance_squared(c));
            d[j] = dj;
            if dj > best.1 {
                best = (j, dj);
            }
        }
        cur = best.0;
    }
    out
}

/// Initial parameters for m Gaussians on `first` (frame 0's working points).
pub fn initial_params(first: &[Vec3], m: usize, frames: usize) -> Params {
    let mut p = Params::new(m, frames);
    let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
    for q in first {
        lo = lo.min(*q);
        hi = hi.max(*q);
    }
    let ext = (hi - lo).max_element().max(1e-6) as f64;
    // A part of an m-part object spans roughly ext / m^(1/3); a Gaussian covering it
    // has σ about a quarter of that.
    let s0 = (ext / (m.max(1) as f64).cbrt() * 0.25).ln();
    let idx = farthest_point_sampling(first, m, 0);
    for i in 0..m {
        let c = idx
            .get(i)
            .map(|&j| first[j].as_dvec3())
            .unwrap_or(DVec3::ZERO);
        p.set_log_scale(i, DVec3::splat(s0));
        for k in 0..frames {
            p.set_center(k, i, c);
        }
    }
    p
}
