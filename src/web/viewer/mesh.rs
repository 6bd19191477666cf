//! Small CPU-built meshes for the viewer: the unit icosphere the Gaussians are
//! instanced from, and cylinders, cones and spheres for joint axes and arrows.

use glam::Vec3;

/// Vertex of the lit mesh / line pipelines: position, normal, packed RGBA8.
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(C)]
pub struct MeshVertex {
    pub pos: [f32; 3],
    pub normal: [f32; 3],
    pub color: u32,
}

/// Unit icosphere (vertices on the unit sphere, so they double as normals)
/// with `subdivisions` rounds of 4-way splitting; triangles wind outwards (CCW).
pub fn icosphere(subdivisions: u32) -> (Vec<[f32; 3]>, Vec<u16>) {
    let t = (1.0 + 5f32.sqrt()) / 2.0;
    let mut verts: Vec<Vec3> = [
        [-1.0, t, 0.0],
        [1.0, t, 0.0],
        [-1.0, -t, 0.0],
        [1.0, -t, 0.0],
        [0.0, -1.0, t],
        [0.0, 1.0, t],
        [0.0, -1.0, -t],
        [0.0, 1.0, -t],
        [t, 0.0, -1.0],
        [t, 0.0, 1.0],
        [-t, 0.0, -1.0],
        [-t, 0.0, 1.0],
    ]
    .iter()
    .map(|v| Vec3::from_array(*v).normalize())
    .collect();
    let mut tris: Vec<[u16; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..subdivisions {
        let mut cache = std::collections::HashMap::new();
        let mut midpoint = |a: u16, b: u16, verts: &mut Vec<Vec3>| -> u16 {
            let key = (a.min(b), a.max(b));
            *cache.entry(key).or_insert_with(|| {
                verts.push(((verts[a as usize] + verts[b as usize]) * 0.5).normalize());
                (verts.len() - 1) as u16
            })
        };
        let mut next = Vec::with_capacity(tris.len() * 4);
        for [a, b, c] in tris {
            let ab = midpoint(a, b, &mut verts);
            let bc = midpoint(b, c, &mut verts);
            let ca = midpoint(c, a, &mut verts);
            next.extend_from_slice(&[[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
        }
        tris = next;
    }
    (
        verts.iter().map(|v| v.to_array()).collect(),
        tris.into_iter().flatten().collect(),
    )
}

/// Two unit vectors perpendicular to `d` (unit) and to each other.
fn perpendiculars(d: Vec3) -> (Vec3, Vec3) {
    let helper = if d.x.abs() < 0.9 { Vec3::X } else { Vec3::Y };
    let u = d.cross(helper).normalize();
    (u, d.cross(u))
}

const SEGMENTS: usize = 10;

fn push_tri(out: &mut Vec<MeshVertex>, p: [Vec3; 3], n: [Vec3; 3], color: u32) {
    for k in 0..3 {
        out.push(MeshVertex {
            pos: p[k].to_array(),
            normal: n[k].to_array(),
            color,
        });
    }
}

/// Open cylinder from `a` to `b` (triangle list, CCW outwards).
pub fn cylinder(out: &mut Vec<MeshVertex>, a: Vec3, b: Vec3, radius: f32, color: u32) {
    let Some(d) = (b - a).try_normalize() else {
        return;
    };
    let (u, v) = perpendiculars(d);
    for i in 0..SEGMENTS {
        let t0 = i as f32 / SEGMENTS as f32 * std::f32::consts::TAU;
        let t1 = (i + 1) as f32 / SEGMENTS as f32 * std::f32::consts::TAU;
        let n0 = u * t0.cos() + v * t0.sin();
        let n1 = u * t1.cos() + v * t1.sin();
        let (a0, a1) = (a + n0 * radius, a + n1 * radius);
        let (b0, b1) = (b + n0 * radius, b + n1 * radius);
        push_tri(out, [a0, a1, b1], [n0, n1, n1], color);
        push_tri(out, [a0, b1, b0], [n0, n1, n0], color);
    }
}

/// Cone with its base disk centred at `base` and its tip at `tip`.
pub fn cone(out: &mut Vec<MeshVertex>, base: Vec3, tip: Vec3, radius: f32, color: u32) {
    let axis = tip - base;
    let Some(d) = axis.try_normalize() else {
        return;
    };
    let h = axis.length();
    let (u, v) = perpendiculars(d);
    for i in 0..SEGMENTS {
        let t0 = i as f32 / SEGMENTS as f32 * std::f32::consts::TAU;
        let t1 = (i + 1) as f32 / SEGMENTS as f32 * std::f32::consts::TAU;
        let r0 = u * t0.cos() + v * t0.sin();
        let r1 = u * t1.cos() + v * t1.sin();
        // Side normal tilts towards the tip by the cone's slope.
        let n0 = (r0 * h + d * radius).normalize();
        let n1 = (r1 * h + d * radius).normalize();
        let (p0, p1) = (base + r0 * radius, base + r1 * radius);
        push_tri(out, [p0, p1, tip], [n0, n1, (n0 + n1).normalize()], color);
        push_tri(out, [base, p1, p0], [-d, -d, -d], color);
    }
}

/// Sphere at `center` from a unit icosphere.
pub fn sphere(
    out: &mut Vec<MeshVertex>,
    unit: &(Vec<[f32; 3]>, Vec<u16>),
    center: Vec3,
    radius: f32,
    color: u32,
) {
    let (verts, idx) = unit;
    for tri in idx.chunks_exact(3) {
        let n = [0, 1, 2].map(|k| Vec3::from_array(verts[tri[k] as usize]));
        push_tri(out, n.map(|n| center + n * radius), n, color);
    }
}

/// Unlit line segment (two vertices of a line list).
pub fn line(out: &mut Vec<MeshVertex>, a: Vec3, b: Vec3, color: u32) {
    for p in [a, b] {
        out.push(MeshVertex {
            pos: p.to_array(),
            normal: [0.0, 0.0, 1.0],
            color,
        });
    }
}
