//! Initialisation: farthest-point sampled centres on the first frame, identity
//! rotations, isotropic scales from the cloud's extent and m; every frame starts
//! equal to the first. (The warm-up on the first frame runs in the fitter.)

use crate::math::Libm;
use glam::{DVec3, Vec3};

use super::gaussians::Params;
use crate::geom::fps::farthest_point_sampling;

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
    let s0 = (ext / (m.max(1) as f64).lcbrt() * 0.25).lln();
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
