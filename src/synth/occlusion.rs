//! Visibility of a point cloud from a camera: hidden point removal (Katz, Tal, Basri
//! 2007, "Direct visibility of point sets"): spherical flipping about the camera, then
//! a point is visible iff its flipped image is a vertex of the convex hull of the
//! flipped set and the camera. The 3D hull is an in-house quickhull (f64, deterministic,
//! no hashing), because the crates available either panic on degenerate input or do
//! not report which input points are hull vertices. Should the hull fail numerically,
//! a z-buffer splat test is used instead (reported through [`Method`]).

use glam::DVec3;

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

#[derive(Debug, Clone)]
struct Face {
    v: [usize; 3],
    n: DVec3,
    d: f64,
    /// Neighbour across edge `v[i] → v[(i+1)%3]`.
    nb: [usize; 3],
    outside: Vec<usize>,
    alive: bool,
}

impl Face {
    fn new(pts: &[DVec3], v: [usize; 3]) -> Face {
        let n = (pts[v[1]] - pts[v[0]])
            .cross(pts[v[2]] - pts[v[0]])
            .normalize_or_zero();
        Face {
            v,
            n,
            d: n.dot(pts[v[0]]),
            nb: [usize::MAX; 3],
            outside: Vec::new(),
            alive: true,
        }
    }
    fn dist(&self, p: DVec3) -> f64 {
        self.n.dot(p) - self.d
    }
}

/// Mask of the points that are vertices of their convex hull (quickhull with
/// adjacency-ordered horizons). `None` for fewer than 4 points, a flat set, or a
/// numerical failure of the hull topology.
pub fn hull_vertices(pts: &[DVec3]) -> Option<Vec<bool>> {
    let tris = hull_triangles(pts)?;
    let mut mask = vec![false; pts.len()];
    for t in &tris {
        for &v in t {
            mask[v] = true;
        }
    }
    Some(mask)
}

/// Triangles of the convex hull (outward counter-clockwise), see [`hull_vertices`].
pub fn hull_triangles(pts: &[DVec3]) -> Option<Vec<[usize; 3]>> {
    let n = pts.len();
    if n < 4 || pts.iter().any(|p| !p.is_finite()) {
        return None;
    }
    let scale: f64 = (0..3)
        .map(|a| pts.iter().map(|p| p[a].abs()).fold(0.0, f64::max))
        .sum();
    let eps = 3.0 * f64::EPSILON * scale * 4.0;

    // Initial tetrahedron from the axis extremes.
    let mut ext = [0usize; 6];
    for (i, p) in pts.iter().enumerate() {
        for a in 0..3 {
            if p[a] < pts[ext[2 * a]][a] {
                ext[2 * a] = i;
            }
            if p[a] > pts[ext[2 * a + 1]][a] {
                ext[2 * a + 1] = i;
            }
        }
    }
    let (mut i0, mut i1, mut best) = (0, 0, -1.0);
    for a in 0..6 {
        for b in a + 1..6 {
            let d = pts[ext[a]].distance_squared(pts[ext[b]]);
            if d > best {
                best = d;
                i0 = ext[a];
                i1 = ext[b];
            }
        }
    }
    if best.sqrt() <= eps {
        return None;
    }
    let dir = (pts[i1] - pts[i0]).normalize();
    let (mut i2, mut best) = (0, -1.0);
    for (i, p) in pts.iter().enumerate() {
        let v = *p - pts[i0];
        let d = (v - dir * v.dot(dir)).length_squared();
        if d > best {
            best = d;
            i2 = i;
        }
    }
    if best.sqrt() <= eps {
        return None;
    }
    let nrm = (pts[i1] - pts[i0]).cross(pts[i2] - pts[i0]).normalize();
    let (mut i3, mut best) = (0, 0.0f64);
    for (i, p) in pts.iter().enumerate() {
        let d = nrm.dot(*p - pts[i0]);
        if d.abs() > best.abs() {
            best = d;
            i3 = i;
        }
    }
    if best.abs() <= eps {
        return None;
    }
    // Faces must face away from the fourth vertex.
    let (a, b, c, d) = if best > 0.0 {
        (i0, i2, i1, i3)
    } else {
        (i0, i1, i2, i3)
    };
    let mut faces: Vec<Face> = [[a, b, c], [a, c, d], [a, d, b], [b, d, c]]
        .iter()
        .map(|v| Face::new(pts, *v))
        .collect();
    for f in 0..4 {
        for e in 0..3 {
            let (u, w) = (faces[f].v[e], faces[f].v[(e + 1) % 3]);
            let g = (0..4).find(|&g| {
                g != f && (0..3).any(|k| faces[g].v[k] == w && faces[g].v[(k + 1) % 3] == u)
            })?;
            faces[f].nb[e] = g;
        }
    }
    for (i, p) in pts.iter().enumerate() {
        if i == a || i == b || i == c || i == d {
            continue;
        }
        if let Some(f) = faces.iter_mut().find(|f| f.dist(*p) > eps) {
            f.outside.push(i);
        }
    }

    let mut visible_stamp: Vec<usize> = vec![usize::MAX; 4];
    let mut horizon: Vec<(usize, usize)> = Vec::new();
    let mut stack: Vec<(usize, usize, usize)> = Vec::new();
    let mut orphans: Vec<usize> = Vec::new();
    let mut cursor = 0;
    let mut iteration = 0usize;
    let max_iterations = 4 * n + 16;
    while cursor < faces.len() {
        if !faces[cursor].alive || faces[cursor].outside.is_empty() {
            cursor += 1;
            continue;
        }
        iteration += 1;
        if iteration > max_iterations {
            return None;
        }
        // Farthest outside point of this face; the first one on ties (deterministic).
        let f0 = cursor;
        let mut eye = faces[f0].outside[0];
        let mut far = faces[f0].dist(pts[eye]);
        for &i in &faces[f0].outside[1..] {
            let d = faces[f0].dist(pts[i]);
            if d > far {
                far = d;
                eye = i;
            }
        }
        let e = pts[eye];
        // Visible faces by depth-first search over adjacency; the horizon comes out as
        // an ordered loop of edges (face, edge index).
        horizon.clear();
        stack.clear();
        let mut visible_faces = vec![f0];
        visible_stamp[f0] = iteration;
        stack.push((f0, 0, 0));
        while let Some(top) = stack.last_mut() {
            if top.1 == 3 {
                stack.pop();
                continue;
            }
            let edge = (top.2 + top.1) % 3;
            top.1 += 1;
            let f = top.0;
            let g = faces[f].nb[edge];
            if g >= faces.len() || !faces[g].alive {
                return None;
            }
            if visible_stamp[g] == iteration {
                continue;
            }
            if faces[g].dist(e) > eps {
                visible_stamp[g] = iteration;
                visible_faces.push(g);
                let back = (0..3).find(|&k| faces[g].nb[k] == f)?;
                stack.push((g, 0, (back + 1) % 3));
            } else {
                horizon.push((f, edge));
            }
        }
        // The horizon must be one closed loop: edge j ends where edge j+1 starts.
        let h = horizon.len();
        if h < 3 {
            return None;
        }
        let loop_edges: Vec<(usize, usize, usize)> = horizon
            .iter()
            .map(|&(f, ed)| (faces[f].v[ed], faces[f].v[(ed + 1) % 3], faces[f].nb[ed]))
            .collect();
        for k in 0..h {
            if loop_edges[k].1 != loop_edges[(k + 1) % h].0 {
                return None;
            }
        }
        // New faces (a, b, eye) over the horizon edges a → b.
        let first = faces.len();
        for (k, &(u, w, across)) in loop_edges.iter().enumerate() {
            let mut nf = Face::new(pts, [u, w, eye]);
            if nf.n == DVec3::ZERO {
                return None;
            }
            nf.nb = [across, first + (k + 1) % h, first + (k + h - 1) % h];
            // The face across now borders the new face on its edge w → u.
            let slot =
                (0..3).find(|&s| faces[across].v[s] == w && faces[across].v[(s + 1) % 3] == u)?;
            faces[across].nb[slot] = first + k;
            faces.push(nf);
            visible_stamp.push(usize::MAX);
        }
        // Retire visible faces and hand their outside points to the new faces.
        orphans.clear();
        for &f in &visible_faces {
            faces[f].alive = false;
            orphans.append(&mut faces[f].outside);
        }
        for &i in &orphans {
            if i == eye {
                continue;
            }
            let p = pts[i];
            for nf in faces[first..].iter_mut() {
                if nf.dist(p) > eps {
                    nf.outside.push(i);
                    break;
                }
            }
        }
    }
    Some(faces.iter().filter(|f| f.alive).map(|f| f.v).collect())
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

    fn random_ball(n: usize, seed: u64) -> Vec<DVec3> {
        let mut rng = StdRng::seed_from_u64(seed);
        let mut v = Vec::new();
        while v.len() < n {
            let p = DVec3::new(
                rng.random::<f64>() * 2.0 - 1.0,
                rng.random::<f64>() * 2.0 - 1.0,
                rng.random::<f64>() * 2.0 - 1.0,
            );
            if p.length() < 1.0 {
                v.push(p);
            }
        }
        v
    }

    /// Brute force: a point is a hull vertex iff some plane through it has all other
    /// points on one side — checked against every face built from the mask.
    fn assert_valid_hull(pts: &[DVec3], mask: &[bool]) {
        let hull: Vec<DVec3> = pts
            .iter()
            .zip(mask)
            .filter(|(_, &m)| m)
            .map(|(p, _)| *p)
            .collect();
        assert!(hull.len() >= 4);
        // every non-vertex must not be extreme in a set of probe directions
        let mut rng = StdRng::seed_from_u64(99);
        for _ in 0..500 {
            let d = DVec3::new(
                rng.random::<f64>() - 0.5,
                rng.random::<f64>() - 0.5,
                rng.random::<f64>() - 0.5,
            )
            .normalize();
            let best_all = pts.iter().map(|p| p.dot(d)).fold(f64::MIN, f64::max);
            let best_hull = hull.iter().map(|p| p.dot(d)).fold(f64::MIN, f64::max);
            assert!((best_all - best_hull).abs() < 1e-12);
        }
    }

    #[test]
    fn cube_corners_are_the_hull() {
        let mut pts = random_ball(200, 1)
            .into_iter()
            .map(|p| p * 0.5)
            .collect::<Vec<_>>();
        for i in 0..8 {
            pts.push(DVec3::new(
                if i & 1 == 0 { -1.0 } else { 1.0 },
                if i & 2 == 0 { -1.0 } else { 1.0 },
                if i & 4 == 0 { -1.0 } else { 1.0 },
            ));
        }
        let mask = hull_vertices(&pts).unwrap();
        assert_eq!(mask.iter().filter(|&&m| m).count(), 8);
        assert!(mask[200..].iter().all(|&m| m));
    }

    #[test]
    fn ball_and_sphere_hulls_are_valid() {
        let pts = random_ball(3000, 2);
        let mask = hull_vertices(&pts).unwrap();
        assert_valid_hull(&pts, &mask);
        // points on a sphere are all hull vertices
        let sphere: Vec<DVec3> = pts.iter().map(|p| p.normalize() * 300.0).collect();
        let mask = hull_vertices(&sphere).unwrap();
        assert_valid_hull(&sphere, &mask);
        assert!(mask.iter().filter(|&&m| m).count() > 2950);
    }

    /// Full validity: a closed 2-manifold (every directed edge once, its reverse once,
    /// Euler V − E + F = 2) with every point on the inner side of every face.
    fn assert_closed_convex(pts: &[DVec3], tris: &[[usize; 3]]) {
        let mut edges: Vec<(usize, usize)> = tris
            .iter()
            .flat_map(|t| [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])])
            .collect();
        edges.sort_unstable();
        assert!(
            edges.windows(2).all(|w| w[0] != w[1]),
            "repeated directed edge"
        );
        for &(a, b) in &edges {
            assert!(edges.binary_search(&(b, a)).is_ok(), "open edge");
        }
        let mut verts: Vec<usize> = tris.iter().flatten().copied().collect();
        verts.sort_unstable();
        verts.dedup();
        let (v, e, f) = (
            verts.len() as i64,
            edges.len() as i64 / 2,
            tris.len() as i64,
        );
        assert_eq!(v - e + f, 2);
        let scale = pts
            .iter()
            .map(|p| p.abs().max_element())
            .fold(0.0, f64::max);
        for t in tris {
            let n = (pts[t[1]] - pts[t[0]])
                .cross(pts[t[2]] - pts[t[0]])
                .normalize();
            for p in pts {
                assert!(n.dot(*p - pts[t[0]]) < 1e-9 * scale);
            }
        }
    }

    #[test]
    fn hulls_of_flipped_clouds_are_closed_and_convex() {
        // the HPR use case: a cloud flipped about a camera, plus the camera
        let mut rng = StdRng::seed_from_u64(8);
        for trial in 0..4 {
            let pts: Vec<DVec3> = random_ball(1500, 20 + trial)
                .into_iter()
                .map(|p| p * DVec3::new(0.5, 0.1, 0.3))
                .collect();
            let cam = DVec3::new(rng.random::<f64>() - 0.5, 2.0, rng.random::<f64>() - 0.5);
            let r = HPR_RADIUS_FACTOR * 2.5;
            let mut flipped: Vec<DVec3> = pts
                .iter()
                .map(|p| {
                    let v = *p - cam;
                    v + v * (2.0 * (r - v.length()) / v.length())
                })
                .collect();
            flipped.push(DVec3::ZERO);
            let tris = hull_triangles(&flipped).unwrap();
            assert_closed_convex(&flipped, &tris);
        }
        let ball = random_ball(2000, 3);
        assert_closed_convex(&ball, &hull_triangles(&ball).unwrap());
    }

    #[test]
    fn flat_sets_are_rejected() {
        let pts: Vec<DVec3> = (0..50)
            .map(|i| DVec3::new(i as f64, (i * i % 7) as f64, 0.0))
            .collect();
        assert!(hull_vertices(&pts).is_none());
    }

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
