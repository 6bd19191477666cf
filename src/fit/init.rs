//! Initialisation: farthest-point sampled centres on the first frame, identity
//! rotations, isotropic scales from the cloud's extent and m; every frame starts
//! equal to the first. (The warm-up on the first frame runs in the fitter.)

use crate::math::Libm;
use glam::{DVec3, Vec3};

use super::gaussians::Params;
use crate::geom::fps::farthest_point_sampling;

/// As `initial_params`, with the centres farthest-point sampled on the cloud's medial
/// axis estimate (`medial::contract`) instead of on the cloud.
pub fn initial_params_medial(first: &[Vec3], m: usize, frames: usize) -> Params {
    let medial = super::medial::contract(first, &super::medial::MedialOpts::default());
    params_on(first, &medial, m, frames)
}

/// Initial parameters for m Gaussians on `first` (frame 0's working points).
pub fn initial_params(first: &[Vec3], m: usize, frames: usize) -> Params {
    params_on(first, first, m, frames)
}

/// m Gaussians scaled for the cloud `first`, centred on farthest-point samples of
/// `sites` (the cloud itself, or points derived from it).
fn params_on(first: &[Vec3], sites: &[Vec3], m: usize, frames: usize) -> Params {
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
    let idx = farthest_point_sampling(sites, m, 0);
    for i in 0..m {
        let c = idx
            .get(i)
            .map(|&j| sites[j].as_dvec3())
            .unwrap_or(DVec3::ZERO);
        p.set_log_scale(i, DVec3::splat(s0));
        for k in 0..frames {
            p.set_center(k, i, c);
        }
    }
    p
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Libm;

    /// Two capped-cylinder surfaces (radius 0.04) meeting at a right angle, like a
    /// bent limb.
    fn elbow() -> Vec<Vec3> {
        let golden = std::f32::consts::PI * (3.0 - 5f32.sqrt());
        (0..4000)
            .map(|i| {
                let t = (i % 2000) as f32 / 2000.0;
                let a = golden * i as f32;
                let (u, v) = (0.04 * a.lcos(), 0.04 * a.lsin());
                if i < 2000 {
                    Vec3::new(u, v, t)
                } else {
                    Vec3::new(t, u, v)
                }
            })
            .collect()
    }

    /// Distance from the nearer of the two cylinders' axes.
    fn off_axis(p: DVec3) -> f64 {
        (p.x * p.x + p.y * p.y)
            .sqrt()
            .min((p.y * p.y + p.z * p.z).sqrt())
    }

    #[test]
    fn medial_centres_lie_inside_thin_parts_and_surface_ones_on_them() {
        let pts = elbow();
        let (m, k) = (8, 3);
        let medial = initial_params_medial(&pts, m, k);
        let surface = initial_params(&pts, m, k);
        let mean_off =
            |p: &Params| (0..m).map(|i| off_axis(p.center(0, i))).sum::<f64>() / m as f64;
        assert!(mean_off(&surface) > 0.03, "surface {}", mean_off(&surface));
        for i in 0..m {
            assert!(
                off_axis(medial.center(0, i)) < 0.015,
                "{:?}",
                medial.center(0, i)
            );
            // Every frame starts as the first, scales as the surface initialisation's.
            assert_eq!(medial.center(2, i), medial.center(0, i));
            assert_eq!(medial.log_scale(i), surface.log_scale(i));
        }
    }
}
