//! Medial-axis estimate of a dense cloud by Laplacian-based contraction (Cao et al.
//! 2010, as the paper's supplement initialises its Gaussian centres): the points are
//! pulled towards their neighbours' mean with a weight that grows every iteration,
//! while an attraction to their previous positions keeps them from collapsing at once;
//! thin structures shrink onto their skeleton (a capsule onto its axis), thick ones
//! onto a medial sheet. Farthest-point samples of the contracted points then place
//! the Gaussians inside the parts instead of on their surface.
//!
//! Each iteration solves the least-squares system of the paper's reference,
//! `[W_L·L; W_H] X = [0; W_H·X_t]`, i.e. `(W_L² LᵀL + W_H² I) X = W_H² X_t`, by
//! conjugate gradients. `L` is the uniform Laplacian of the k-nearest-neighbour graph
//! of the original points (fixed through the iterations, as the original one-ring
//! is in Cao et al.), rather than their cotangent Laplacian of a local Delaunay
//! triangulation: it needs no triangulation and contracts the same way on the even
//! samplings here. The cloud is first reduced to `MedialOpts::points` farthest-point
//! samples, so the graph is built by brute force in O(n·k) memory (about 20 ms a
//! contraction natively, from a 4096-point frame).

use glam::{DVec3, Vec3};

use crate::geom::fps::farthest_point_sampling;

/// An iteration that leaves the total neighbourhood spread below this share of the
/// last is thinning the cloud …
const THINNING: f64 = 0.8;
/// … and once one has, an iteration above this share ends the contraction (see
/// `contract`). On a capsule-like cylinder (radius 3 point spacings) the shares run
/// 0.96, 0.95, 0.82, 0.64, 0.87, 0.94, then 0.65 and 0.14 as its length collapses.
const PLATEAU: f64 = 0.9;

/// Options of [`contract`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MedialOpts {
    /// Points contracted (farthest-point samples of the cloud).
    pub points: usize,
    /// Neighbours per point in the Laplacian's graph.
    pub k: usize,
    /// Initial contraction weight W_L (W_H is 1).
    pub contraction: f64,
    /// Factor W_L grows by every iteration (Cao et al.'s s_L = 3).
    pub amplification: f64,
    /// Most iterations (fewer when the cloud stops thinning).
    pub iterations: usize,
}

impl Default for MedialOpts {
    fn default() -> Self {
        MedialOpts {
            points: 1024,
            k: 10,
            contraction: 1.0,
            amplification: 3.0,
            iterations: 10,
        }
    }
}

/// The k nearest other points of every point (brute force; n is at most a few
/// thousand).
fn knn_graph(x: &[DVec3], k: usize) -> Vec<Vec<usize>> {
    let n = x.len();
    let k = k.min(n.saturating_sub(1));
    let mut d: Vec<(f64, usize)> = Vec::with_capacity(n);
    (0..n)
        .map(|i| {
            d.clear();
            d.extend(
                (0..n)
                    .filter(|&j| j != i)
                    .map(|j| (x[i].distance_squared(x[j]), j)),
            );
            if k < d.len() {
                d.select_nth_unstable_by(k, |a, b| a.0.total_cmp(&b.0));
            }
            d[..k].iter().map(|&(_, j)| j).collect()
        })
        .collect()
}

/// Mean squared distance of every point to its neighbours.
fn spreads(nb: &[Vec<usize>], x: &[DVec3]) -> Vec<f64> {
    nb.iter()
        .enumerate()
        .map(|(i, ns)| {
            ns.iter().map(|&j| x[i].distance_squared(x[j])).sum::<f64>() / ns.len().max(1) as f64
        })
        .collect()
}

/// `out = (wl² LᵀL + diag(wh2)) v` for the uniform Laplacian
/// `(Lv)_i = v_i − mean_{j∈N(i)} v_j`.
fn apply(
    nb: &[Vec<usize>],
    wl2: f64,
    wh2: &[f64],
    v: &[DVec3],
    lv: &mut [DVec3],
    out: &mut [DVec3],
) {
    for (i, ns) in nb.iter().enumerate() {
        let mean = ns.iter().fold(DVec3::ZERO, |a, &j| a + v[j]) / ns.len().max(1) as f64;
        lv[i] = v[i] - mean;
    }
    for (i, o) in out.iter_mut().enumerate() {
        *o = wh2[i] * v[i] + wl2 * lv[i];
    }
    for (i, ns) in nb.iter().enumerate() {
        let w = wl2 * lv[i] / ns.len().max(1) as f64;
        for &j in ns {
            out[j] -= w;
        }
    }
}

/// Solves `(wl² LᵀL + diag(wh2)) X = b` by conjugate gradients from `x` (the three
/// coordinates at once: the matrix acts on each alike).
fn solve(nb: &[Vec<usize>], wl2: f64, wh2: &[f64], b: &[DVec3], x: &mut [DVec3]) {
    let n = b.len();
    let (mut lv, mut ap) = (vec![DVec3::ZERO; n], vec![DVec3::ZERO; n]);
    apply(nb, wl2, wh2, x, &mut lv, &mut ap);
    let mut r: Vec<DVec3> = b.iter().zip(&ap).map(|(b, a)| *b - *a).collect();
    let mut p = r.clone();
    let dot = |a: &[DVec3], b: &[DVec3]| a.iter().zip(b).map(|(x, y)| x.dot(*y)).sum::<f64>();
    let b2 = dot(b, b).max(1e-300);
    let mut rr = dot(&r, &r);
    for _ in 0..4 * n.max(8) {
        if rr <= 1e-20 * b2 {
            break;
        }
        apply(nb, wl2, wh2, &p, &mut lv, &mut ap);
        let alpha = rr / dot(&p, &ap).max(1e-300);
        for i in 0..n {
            x[i] += alpha * p[i];
            r[i] -= alpha * ap[i];
        }
        let rr_new = dot(&r, &r);
        let beta = rr_new / rr;
        rr = rr_new;
        for i in 0..n {
            p[i] = r[i] + beta * p[i];
        }
    }
}

/// Contracted farthest-point samples of `points` (see the module doc); fewer than
/// k + 1 points come back as they are.
pub fn contract(points: &[Vec3], opts: &MedialOpts) -> Vec<Vec3> {
    let idx = farthest_point_sampling(points, opts.points, 0);
    let x0: Vec<DVec3> = idx.iter().map(|&i| points[i].as_dvec3()).collect();
    if x0.len() <= opts.k {
        return x0.iter().map(|p| p.as_vec3()).collect();
    }
    let nb = knn_graph(&x0, opts.k);
    let spread0 = spreads(&nb, &x0);
    let mut x = x0;
    let mut wl = opts.contraction;
    let mut spread = spread0.clone();
    let mut last: f64 = spread0.iter().sum();
    let mut thinned = false;
    for _ in 0..opts.iterations {
        // Cao et al.'s attraction W_H,i = sqrt(A⁰_i / A_i), with the neighbourhood's
        // mean squared spread for the one-ring area: contracted points hold still
        // while thick regions go on contracting.
        let wh2: Vec<f64> = spread
            .iter()
            .zip(&spread0)
            .map(|(s, s0)| (s0 / s.max(1e-12 * s0.max(1e-300))).sqrt())
            .collect();
        let b: Vec<DVec3> = x.iter().zip(&wh2).map(|(p, w)| *w * *p).collect();
        solve(&nb, wl * wl, &wh2, &b, &mut x);
        wl *= opts.amplification;
        // Stop once the cloud has thinned (the spread fell by a fifth in one
        // iteration) and then stopped thinning: the cross-sections are gone, and
        // going on would only shorten the skeleton.
        spread = spreads(&nb, &x);
        let total: f64 = spread.iter().sum();
        let step = total / last.max(1e-300);
        last = total;
        thinned |= step < THINNING;
        if thinned && step > PLATEAU {
            break;
        }
    }
    x.iter().map(|p| p.as_vec3()).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Libm;

    /// Points on the surface of a capped cylinder about the z axis.
    fn cylinder(radius: f32, length: f32, n: usize) -> Vec<Vec3> {
        let golden = std::f32::consts::PI * (3.0 - 5f32.sqrt());
        (0..n)
            .map(|i| {
                let z = length * (i as f32 + 0.5) / n as f32;
                let a = golden * i as f32;
                Vec3::new(radius * a.lcos(), radius * a.lsin(), z)
            })
            .collect()
    }

    #[test]
    fn a_cylinder_contracts_onto_its_axis_and_keeps_its_length() {
        let pts = cylinder(0.05, 1.0, 3000);
        let out = contract(&pts, &MedialOpts::default());
        assert_eq!(out.len(), 1024);
        let radial: f32 = out
            .iter()
            .map(|p| (p.x * p.x + p.y * p.y).sqrt())
            .sum::<f32>()
            / out.len() as f32;
        let (lo, hi) = out
            .iter()
            .fold((f32::MAX, f32::MIN), |(l, h), p| (l.min(p.z), h.max(p.z)));
        assert!(radial < 0.01, "mean distance from the axis {radial}");
        assert!(hi - lo > 0.7, "axial extent {}", hi - lo);
    }

    #[test]
    fn the_system_is_solved() {
        let x: Vec<DVec3> = (0..50)
            .map(|i| DVec3::new(i as f64 * 0.1, (i as f64 * 0.7).lsin(), 0.3))
            .collect();
        let nb = knn_graph(&x, 4);
        let mut sol = x.clone();
        let wh2: Vec<f64> = (0..50).map(|i| 1.0 + (i % 3) as f64).collect();
        solve(&nb, 9.0, &wh2, &x, &mut sol);
        let (mut lv, mut ax) = (vec![DVec3::ZERO; 50], vec![DVec3::ZERO; 50]);
        apply(&nb, 9.0, &wh2, &sol, &mut lv, &mut ax);
        let err = ax
            .iter()
            .zip(&x)
            .map(|(a, b)| a.distance(*b))
            .fold(0.0, f64::max);
        assert!(err < 1e-8, "residual {err}");
    }

    #[test]
    fn tiny_clouds_come_back_unchanged() {
        let pts = vec![Vec3::ZERO, Vec3::X, Vec3::Y];
        assert_eq!(contract(&pts, &MedialOpts::default()).len(), 3);
    }
}
