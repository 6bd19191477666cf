//! Binary STL of a triangle mesh: the link meshes of the URDF export (`io::urdf`), in
//! the format every URDF tool reads (ROS, PyBullet, MuJoCo's compiler, trimesh).

use glam::{DVec3, Vec3};

/// A binary STL of `triangles` over `vertices`, each vertex moved by `offset` (into the
/// link's frame). Facet normals come from the winding (counter-clockwise seen from
/// outside), as the format asks.
pub fn binary_stl(vertices: &[DVec3], triangles: &[[u32; 3]], offset: DVec3) -> Vec<u8> {
    let mut out = Vec::with_capacity(84 + 50 * triangles.len());
    let mut header = [b' '; 80];
    let title = b"gsart link mesh (convex hull of the part's points)";
    header[..title.len()].copy_from_slice(title);
    out.extend_from_slice(&header);
    out.extend_from_slice(&(triangles.len() as u32).to_le_bytes());
    let put = |out: &mut Vec<u8>, v: Vec3| {
        for x in v.to_array() {
            out.extend_from_slice(&x.to_le_bytes());
        }
    };
    for t in triangles {
        let [a, b, c] =
            t.map(|i| vertices.get(i as usize).copied().unwrap_or(DVec3::ZERO) + offset);
        put(&mut out, (b - a).cross(c - a).normalize_or_zero().as_vec3());
        for p in [a, b, c] {
            put(&mut out, p.as_vec3());
        }
        out.extend_from_slice(&0u16.to_le_bytes());
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_tetrahedron_reads_back() {
        let v = [DVec3::ZERO, DVec3::X, DVec3::Y, DVec3::Z];
        let t = [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]];
        let b = binary_stl(&v, &t, DVec3::new(1.0, 0.0, 0.0));
        assert_eq!(b.len(), 84 + 4 * 50);
        assert_eq!(u32::from_le_bytes(b[80..84].try_into().unwrap()), 4);
        let f = |o: usize| f32::from_le_bytes(b[o..o + 4].try_into().unwrap());
        // First facet: normal −z (outward for the face on z = 0), first vertex the
        // origin moved by the offset.
        assert_eq!([f(84), f(88), f(92)], [0.0, 0.0, -1.0]);
        assert_eq!([f(96), f(100), f(104)], [1.0, 0.0, 0.0]);
    }
}
