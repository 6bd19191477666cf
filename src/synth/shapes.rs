//! Surface primitives (boxes, capsules, closed cylinders, spheres) with their areas,
//! uniform surface sampling and strict inside tests. A part is a union of primitives;
//! sampling a union uniformly = sample a primitive by area, a point on it, and reject
//! points strictly inside another primitive of the same part.

use glam::{DQuat, DVec3};
use rand::Rng;
use std::f64::consts::PI;

use crate::math::Libm;

/// One closed surface in a part's local frame.
#[derive(Debug, Clone, PartialEq)]
pub enum Primitive {
    /// Oriented box: centre, half extents along its own axes, orientation.
    Box {
        center: DVec3,
        half: DVec3,
        rot: DQuat,
    },
    /// Segment `a`–`b` swept by a ball of radius `r`.
    Capsule {
        a: DVec3,
        b: DVec3,
        r: f64,
    },
    /// Closed cylinder (with both end disks) from `a` to `b`.
    Cylinder {
        a: DVec3,
        b: DVec3,
        r: f64,
    },
    Sphere {
        center: DVec3,
        r: f64,
    },
}

/// Axis-aligned box from its min and max corners.
pub fn aabb(min: [f64; 3], max: [f64; 3]) -> Primitive {
    let lo = DVec3::from(min);
    let hi = DVec3::from(max);
    Primitive::Box {
        center: (lo + hi) * 0.5,
        half: (hi - lo).abs() * 0.5,
        rot: DQuat::IDENTITY,
    }
}

pub fn capsule(a: [f64; 3], b: [f64; 3], r: f64) -> Primitive {
    Primitive::Capsule {
        a: DVec3::from(a),
        b: DVec3::from(b),
        r,
    }
}

pub fn cylinder(a: [f64; 3], b: [f64; 3], r: f64) -> Primitive {
    Primitive::Cylinder {
        a: DVec3::from(a),
        b: DVec3::from(b),
        r,
    }
}

pub fn sphere(c: [f64; 3], r: f64) -> Primitive {
    Primitive::Sphere {
        center: DVec3::from(c),
        r,
    }
}

fn unit_dir(rng: &mut impl Rng) -> DVec3 {
    let z: f64 = rng.random::<f64>() * 2.0 - 1.0;
    let phi = rng.random::<f64>() * 2.0 * PI;
    let s = (1.0 - z * z).max(0.0).sqrt();
    DVec3::new(s * phi.lcos(), s * phi.lsin(), z)
}

impl Primitive {
    pub fn area(&self) -> f64 {
        match *self {
            Primitive::Box { half: h, .. } => 8.0 * (h.x * h.y + h.y * h.z + h.x * h.z),
            Primitive::Capsule { a, b, r } => 2.0 * PI * r * a.distance(b) + 4.0 * PI * r * r,
            Primitive::Cylinder { a, b, r } => 2.0 * PI * r * a.distance(b) + 2.0 * PI * r * r,
            Primitive::Sphere { r, .. } => 4.0 * PI * r * r,
        }
    }

    /// A point uniformly distributed on the surface.
    pub fn sample(&self, rng: &mut impl Rng) -> DVec3 {
        match *self {
            Primitive::Box { center, half, rot } => {
                // Faces come in pairs: pick a pair by area, then a side.
                let areas = [half.y * half.z, half.x * half.z, half.x * half.y];
                let total = areas[0] + areas[1] + areas[2];
                let u = rng.random::<f64>() * total;
                let axis = if u < areas[0] {
                    0
                } else if u < areas[0] + areas[1] {
                    1
                } else {
                    2
                };
                let side = if rng.random::<bool>() { 1.0 } else { -1.0 };
                let mut q = DVec3::new(
                    (rng.random::<f64>() * 2.0 - 1.0) * half.x,
                    (rng.random::<f64>() * 2.0 - 1.0) * half.y,
                    (rng.random::<f64>() * 2.0 - 1.0) * half.z,
                );
                q[axis] = side * half[axis];
                center + rot * q
            }
            Primitive::Capsule { a, b, r } => {
                let len = a.distance(b);
                let side = 2.0 * PI * r * len;
                let caps = 4.0 * PI * r * r;
                let axis = if len > 0.0 { (b - a) / len } else { DVec3::Z };
                if rng.random::<f64>() * (side + caps) < side {
                    let (e1, e2) = axis.any_orthonormal_pair();
                    let t = rng.random::<f64>();
                    let phi = rng.random::<f64>() * 2.0 * PI;
                    a + (b - a) * t + (e1 * phi.lcos() + e2 * phi.lsin()) * r
                } else {
                    // A uniform direction split by hemisphere gives both caps uniformly.
                    let d = unit_dir(rng);
                    let c = if d.dot(axis) >= 0.0 { b } else { a };
                    c + d * r
                }
            }
            Primitive::Cylinder { a, b, r } => {
                let len = a.distance(b);
                let side = 2.0 * PI * r * len;
                let caps = 2.0 * PI * r * r;
                let axis = if len > 0.0 { (b - a) / len } else { DVec3::Z };
                let (e1, e2) = axis.any_orthonormal_pair();
                let phi = rng.random::<f64>() * 2.0 * PI;
                let radial = e1 * phi.lcos() + e2 * phi.lsin();
                if rng.random::<f64>() * (side + caps) < side {
                    a + (b - a) * rng.random::<f64>() + radial * r
                } else {
                    let rho = r * rng.random::<f64>().sqrt();
                    let c = if rng.random::<bool>() { b } else { a };
                    c + radial * rho
                }
            }
            Primitive::Sphere { center, r } => center + unit_dir(rng) * r,
        }
    }

    /// True when `p` is inside by more than `margin` (surface points of this primitive
    /// are never inside it).
    pub fn contains(&self, p: DVec3, margin: f64) -> bool {
        match *self {
            Primitive::Box { center, half, rot } => {
                let q = rot.inverse() * (p - center);
                q.x.abs() < half.x - margin
                    && q.y.abs() < half.y - margin
                    && q.z.abs() < half.z - margin
            }
            Primitive::Capsule { a, b, r } => seg_dist(p, a, b) < r - margin,
            Primitive::Cylinder { a, b, r } => {
                let len = a.distance(b);
                if len <= 0.0 {
                    return false;
                }
                let axis = (b - a) / len;
                let t = (p - a).dot(axis);
                let radial = (p - a - axis * t).length();
                t > margin && t < len - margin && radial < r - margin
            }
            Primitive::Sphere { center, r } => p.distance(center) < r - margin,
        }
    }

    /// Corners / extreme points bounding the primitive (for sizes and tests).
    pub fn bounds(&self) -> (DVec3, DVec3) {
        match *self {
            Primitive::Box { center, half, rot } => {
                let mut lo = DVec3::splat(f64::INFINITY);
                let mut hi = DVec3::splat(f64::NEG_INFINITY);
                for i in 0..8 {
                    let s = DVec3::new(
                        if i & 1 == 0 { -1.0 } else { 1.0 },
                        if i & 2 == 0 { -1.0 } else { 1.0 },
                        if i & 4 == 0 { -1.0 } else { 1.0 },
                    );
                    let c = center + rot * (half * s);
                    lo = lo.min(c);
                    hi = hi.max(c);
                }
                (lo, hi)
            }
            Primitive::Capsule { a, b, r } | Primitive::Cylinder { a, b, r } => {
                (a.min(b) - DVec3::splat(r), a.max(b) + DVec3::splat(r))
            }
            Primitive::Sphere { center, r } => (center - DVec3::splat(r), center + DVec3::splat(r)),
        }
    }
}

fn seg_dist(p: DVec3, a: DVec3, b: DVec3) -> f64 {
    let ab = b - a;
    let l2 = ab.length_squared();
    let t = if l2 > 0.0 {
        ((p - a).dot(ab) / l2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    p.distance(a + ab * t)
}

/// Distance from `p` to the primitive's surface (exact for all kinds; used by tests).
pub fn surface_distance(prim: &Primitive, p: DVec3) -> f64 {
    match *prim {
        Primitive::Box { center, half, rot } => {
            let q = rot.inverse() * (p - center);
            let d = q.abs() - half;
            let outside = d.max(DVec3::ZERO).length();
            let inside = d.x.max(d.y).max(d.z).min(0.0);
            (outside + inside).abs()
        }
        Primitive::Capsule { a, b, r } => (seg_dist(p, a, b) - r).abs(),
        Primitive::Cylinder { a, b, r } => {
            let len = a.distance(b);
            let axis = if len > 0.0 { (b - a) / len } else { DVec3::Z };
            let t = (p - a).dot(axis) - len * 0.5;
            let radial = (p - a - axis * (t + len * 0.5)).length();
            let d = glam::DVec2::new(radial - r, t.abs() - len * 0.5);
            let outside = d.max(glam::DVec2::ZERO).length();
            let inside = d.x.max(d.y).min(0.0);
            (outside + inside).abs()
        }
        Primitive::Sphere { center, r } => (p.distance(center) - r).abs(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{rngs::StdRng, SeedableRng};

    fn prims() -> Vec<Primitive> {
        vec![
            Primitive::Box {
                center: DVec3::new(0.1, 0.2, 0.3),
                half: DVec3::new(0.3, 0.1, 0.05),
                rot: DQuat::from_rotation_z(0.4),
            },
            capsule([0.0, 0.0, 0.0], [0.0, 0.5, 0.2], 0.07),
            cylinder([0.1, 0.0, 0.0], [0.1, 0.0, 0.4], 0.1),
            sphere([0.0, 0.0, 1.0], 0.2),
        ]
    }

    #[test]
    fn samples_lie_on_surface_and_not_inside() {
        let mut rng = StdRng::seed_from_u64(1);
        for p in prims() {
            for _ in 0..2000 {
                let x = p.sample(&mut rng);
                assert!(surface_distance(&p, x) < 1e-9, "{p:?} {x}");
                assert!(!p.contains(x, 1e-9));
                let (lo, hi) = p.bounds();
                assert!(x.cmpge(lo - 1e-9).all() && x.cmple(hi + 1e-9).all());
            }
        }
    }

    #[test]
    fn areas_match_closed_forms() {
        let b = aabb([0.0, 0.0, 0.0], [1.0, 2.0, 3.0]);
        assert!((b.area() - 22.0).abs() < 1e-12);
        let s = sphere([0.0; 3], 1.0);
        assert!((s.area() - 4.0 * PI).abs() < 1e-12);
        let c = cylinder([0.0; 3], [0.0, 0.0, 2.0], 1.0);
        assert!((c.area() - 6.0 * PI).abs() < 1e-12);
    }

    #[test]
    fn capsule_cap_and_side_sampling_is_area_proportional() {
        // Side area equals cap area when len = 2r: half the samples on each.
        let c = capsule([0.0; 3], [0.0, 0.0, 0.2], 0.1);
        let mut rng = StdRng::seed_from_u64(3);
        let n = 20000;
        let side = (0..n)
            .filter(|_| {
                let x = c.sample(&mut rng);
                x.z > 1e-9
                    && x.z < 0.2 - 1e-9
                    && ((x.x * x.x + x.y * x.y).sqrt() - 0.1).abs() < 1e-9
            })
            .count();
        let frac = side as f64 / n as f64;
        assert!((frac - 0.5).abs() < 0.02, "{frac}");
    }

    #[test]
    fn contains_is_strict() {
        let b = aabb([0.0, 0.0, 0.0], [1.0, 1.0, 1.0]);
        assert!(b.contains(DVec3::splat(0.5), 1e-9));
        assert!(!b.contains(DVec3::new(1.0, 0.5, 0.5), 1e-9));
        assert!(!b.contains(DVec3::new(1.5, 0.5, 0.5), 1e-9));
    }
}
