//! Convex hulls: an in-house quickhull (f64, deterministic, no hashing), because the
//! crates available either panic on degenerate input or do not report which input
//! points are hull vertices. Used by hidden point removal (`synth::occlusion`, which
//! needs the vertex mask) and by the URDF export (`io::urdf`), which gives every link
//! its part's hull as a mesh, with the solid hull's mass properties as its inertia.

use glam::{DMat3, DVec3, Vec3};

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

/// A closed convex triangle mesh: its vertices only, triangles wound counter-clockwise
/// seen from outside.
#[derive(Debug, Clone, PartialEq)]
pub struct Hull {
    pub vertices: Vec<DVec3>,
    pub triangles: Vec<[u32; 3]>,
}

/// Mass properties of a solid of mass 1 and uniform density: the centre of mass and
/// the inertia tensor about it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MassProperties {
    pub volume: f64,
    pub center: DVec3,
    pub inertia: DMat3,
}

/// Most vertices a mesh hull keeps (`convex_hull`): about twice as many triangles, some
/// 100 KB of STL a link. The hull of a dense scan's curved part has tens of thousands.
pub const MAX_HULL_VERTICES: usize = 1000;

/// The convex hull of `points` as a mesh of at most [`MAX_HULL_VERTICES`] vertices, or
/// `None` when they span no volume (fewer than four points, all on one plane or line) or
/// the hull fails. A hull with more vertices is built again from that many of them,
/// spread by farthest-point sampling, so it stays inside the full hull and close to it.
pub fn convex_hull(points: &[Vec3]) -> Option<Hull> {
    let hull = mesh_hull(points)?;
    if hull.vertices.len() <= MAX_HULL_VERTICES {
        return Some(hull);
    }
    let vertices: Vec<Vec3> = hull.vertices.iter().map(|v| v.as_vec3()).collect();
    let keep = crate::geom::fps::farthest_point_sampling(&vertices, MAX_HULL_VERTICES, 0);
    let kept: Vec<Vec3> = keep.iter().map(|&i| vertices[i]).collect();
    mesh_hull(&kept).or(Some(hull))
}

/// The hull of `points` as a mesh of its vertices, however many.
fn mesh_hull(points: &[Vec3]) -> Option<Hull> {
    let pts: Vec<DVec3> = points.iter().map(|p| p.as_dvec3()).collect();
    let tris = hull_triangles(&pts)?;
    // Keep the vertices the triangles use, in input order (deterministic).
    let mut index = vec![u32::MAX; pts.len()];
    for t in &tris {
        for &v in t {
            index[v] = 0;
        }
    }
    let mut vertices = Vec::new();
    for (i, slot) in index.iter_mut().enumerate() {
        if *slot == 0 {
            *slot = vertices.len() as u32;
            vertices.push(pts[i]);
        }
    }
    let triangles = tris
        .iter()
        .map(|t| [index[t[0]], index[t[1]], index[t[2]]])
        .collect();
    Some(Hull {
        vertices,
        triangles,
    })
}

impl Hull {
    /// The solid hull's mass properties at mass 1, or `None` if it encloses no volume.
    ///
    /// Each triangle with the vertices' mean `o` spans a tetrahedron of signed volume
    /// V = (a−o)·((b−o)×(c−o))/6, centroid o + (a+b+c−3o)/4 and second moment
    /// ∫ x xᵀ dV = V/20 (Σ vᵢvᵢᵀ + (Σ vᵢ)(Σ vᵢ)ᵀ) over its corners relative to `o`
    /// (one of which is 0); the sums over the triangles are the solid's.
    pub fn mass_properties(&self) -> Option<MassProperties> {
        let n = self.vertices.len();
        if n < 4 {
            return None;
        }
        let o = self.vertices.iter().copied().sum::<DVec3>() / n as f64;
        let (mut vol, mut first, mut second) = (0.0, DVec3::ZERO, DMat3::ZERO);
        let outer = |u: DVec3| DMat3::from_cols(u * u.x, u * u.y, u * u.z);
        for t in &self.triangles {
            let [a, b, c] = t.map(|i| self.vertices[i as usize] - o);
            let v = a.dot(b.cross(c)) / 6.0;
            let s = a + b + c;
            vol += v;
            first += s * (v / 4.0);
            second += (outer(a) + outer(b) + outer(c) + outer(s)) * (v / 20.0);
        }
        if vol.is_nan() || vol <= 0.0 {
            return None;
        }
        let com = first / vol;
        // Second moment about the centre of mass, per unit mass.
        let c = second * (1.0 / vol) - outer(com);
        let inertia = DMat3::from_diagonal(DVec3::splat(c.x_axis.x + c.y_axis.y + c.z_axis.z)) - c;
        Some(MassProperties {
            volume: vol,
            center: o + com,
            inertia,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
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
            let r = crate::synth::occlusion::HPR_RADIUS_FACTOR * 2.5;
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

    /// The eight corners of an axis-aligned box with sides `s` centred at `c`, and
    /// points inside it.
    fn box_points(c: Vec3, s: Vec3) -> Vec<Vec3> {
        let mut pts = Vec::new();
        for k in 0..50 {
            let t = k as f32 / 50.0 - 0.5;
            pts.push(c + Vec3::new(t * 0.9, -t * 0.8, t * 0.3) * s);
        }
        for i in 0..8 {
            let sign = Vec3::new(
                if i & 1 == 0 { -0.5 } else { 0.5 },
                if i & 2 == 0 { -0.5 } else { 0.5 },
                if i & 4 == 0 { -0.5 } else { 0.5 },
            );
            pts.push(c + sign * s);
        }
        pts
    }

    #[test]
    fn the_hull_mesh_of_a_box_is_the_box() {
        let (c, s) = (Vec3::new(0.1, -0.2, 0.3), Vec3::new(0.4, 0.2, 0.1));
        let h = convex_hull(&box_points(c, s)).unwrap();
        assert_eq!(h.vertices.len(), 8, "inner points are not vertices");
        assert_eq!(h.triangles.len(), 12);
        let tris: Vec<[usize; 3]> = h.triangles.iter().map(|t| t.map(|i| i as usize)).collect();
        assert_closed_convex(&h.vertices, &tris);
    }

    #[test]
    fn a_box_hull_has_the_box_mass_properties() {
        let (c, s) = (Vec3::new(0.1, -0.2, 0.3), Vec3::new(0.4, 0.2, 0.1));
        let m = convex_hull(&box_points(c, s))
            .unwrap()
            .mass_properties()
            .unwrap();
        let s = s.as_dvec3();
        assert!((m.volume - s.x * s.y * s.z).abs() < 1e-7, "{}", m.volume);
        assert!((m.center - c.as_dvec3()).length() < 1e-7, "{}", m.center);
        // A unit-mass box: diagonal (b² + c²) / 12 and its turns.
        let want = DMat3::from_diagonal(
            DVec3::new(
                s.y * s.y + s.z * s.z,
                s.x * s.x + s.z * s.z,
                s.x * s.x + s.y * s.y,
            ) / 12.0,
        );
        assert!(
            m.inertia.abs_diff_eq(want, 1e-7),
            "{} against {want}",
            m.inertia
        );
    }

    #[test]
    fn a_turned_solid_has_the_turned_inertia() {
        // A ball's hull: the inertia of a unit-mass ball is 2r²/5 about any axis; a
        // stretched and turned one has R diag Rᵀ with the stretched moments.
        let r = DMat3::from_rotation_z(0.7) * DMat3::from_rotation_x(-0.4);
        let scale = DVec3::new(0.3, 0.1, 0.05);
        let pts: Vec<Vec3> = random_ball(4000, 11)
            .iter()
            .map(|p| (r * (p.normalize() * scale) + DVec3::new(0.2, 0.0, -0.1)).as_vec3())
            .collect();
        let m = convex_hull(&pts).unwrap().mass_properties().unwrap();
        let e = |a: f64, b: f64| (a * a + b * b) / 5.0;
        let want =
            r * DMat3::from_diagonal(DVec3::new(
                e(scale.y, scale.z),
                e(scale.x, scale.z),
                e(scale.x, scale.y),
            )) * r.transpose();
        // The hull of 4000 points on the ellipsoid is a little inside it.
        let rel = (m.inertia - want)
            .to_cols_array()
            .iter()
            .map(|x| x.abs())
            .fold(0.0, f64::max)
            / want.x_axis.x;
        assert!(rel < 0.02, "{} against {want}", m.inertia);
        assert!((m.center - DVec3::new(0.2, 0.0, -0.1)).length() < 1e-3);
        let vol = 4.0 / 3.0 * std::f64::consts::PI * scale.x * scale.y * scale.z;
        assert!(
            (m.volume / vol - 1.0).abs() < 0.02,
            "{} against {vol}",
            m.volume
        );
    }

    #[test]
    fn a_dense_curved_hull_is_thinned_to_the_cap() {
        let pts: Vec<Vec3> = random_ball(20_000, 4)
            .iter()
            .map(|p| (p.normalize() * DVec3::new(0.3, 0.1, 0.05)).as_vec3())
            .collect();
        let full = mesh_hull(&pts).unwrap();
        assert!(
            full.vertices.len() > 5 * MAX_HULL_VERTICES,
            "{}",
            full.vertices.len()
        );
        let h = convex_hull(&pts).unwrap();
        assert!(h.vertices.len() <= MAX_HULL_VERTICES);
        let tris: Vec<[usize; 3]> = h.triangles.iter().map(|t| t.map(|i| i as usize)).collect();
        assert_closed_convex(&h.vertices, &tris);
        let (vf, vh) = (
            full.mass_properties().unwrap().volume,
            h.mass_properties().unwrap().volume,
        );
        assert!(vh <= vf && vh > 0.97 * vf, "thinned {vh} against {vf}");
    }

    #[test]
    fn flat_or_tiny_point_sets_have_no_hull_mesh() {
        assert!(convex_hull(&[]).is_none());
        assert!(convex_hull(&[Vec3::ZERO, Vec3::X, Vec3::Y]).is_none());
        let flat: Vec<Vec3> = (0..30)
            .map(|k| Vec3::new((k % 6) as f32, (k / 6) as f32, 0.0) * 0.1)
            .collect();
        assert!(convex_hull(&flat).is_none());
    }
}
