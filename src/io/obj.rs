//! Wavefront OBJ files (`.obj`): vertices (`v x y z`), and faces (`f`), which make
//! the file a mesh whose surface is sampled as a PLY mesh's is. Texture and normal
//! indices (`f 1/1/1 …`), negative (relative) indices and polygons (fan-triangulated)
//! are read; other statements (`vt`, `vn`, `o`, `g`, `usemtl`, …) are skipped.

use glam::Vec3;

use super::ply::PlyCloud;
use crate::error::{Error, Result};

fn input(file: &str, problem: impl Into<String>) -> Error {
    Error::input(file, problem)
}

/// Reads an OBJ's vertices and triangles.
pub fn read_obj(bytes: &[u8], file: &str) -> Result<PlyCloud> {
    let text = std::str::from_utf8(bytes).map_err(|_| {
        input(
            file,
            "not an OBJ file: the file is binary (or not UTF-8 text)",
        )
    })?;
    let mut points = Vec::new();
    let mut faces: Vec<[u32; 3]> = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let n = i + 1;
        let mut words = line.split_whitespace();
        match words.next() {
            Some("v") => {
                let mut c = [0f32; 3];
                for slot in &mut c {
                    let w = words
                        .next()
                        .ok_or_else(|| input(file, format!("line {n}: a vertex needs x y z")))?;
                    *slot = w
                        .parse()
                        .map_err(|_| input(file, format!("line {n}: '{w}' is not a number")))?;
                }
                if c.iter().any(|v| !v.is_finite()) {
                    return Err(input(file, format!("line {n}: non-finite vertex")));
                }
                points.push(Vec3::from(c));
            }
            Some("f") => {
                let mut idx = Vec::new();
                for w in words {
                    let first = w.split('/').next().unwrap_or("");
                    let k: i64 = first.parse().map_err(|_| {
                        input(file, format!("line {n}: '{w}' is not a vertex index"))
                    })?;
                    // 1-based; negative counts back from the last vertex so far.
                    let at = if k > 0 {
                        k - 1
                    } else {
                        points.len() as i64 + k
                    };
                    if k == 0 || at < 0 || at >= points.len() as i64 {
                        return Err(input(
                            file,
                            format!(
                                "line {n}: vertex index {k} is out of range ({} vertices so far)",
                                points.len()
                            ),
                        ));
                    }
                    idx.push(at as u32);
                }
                if idx.len() < 3 {
                    return Err(input(
                        file,
                        format!("line {n}: a face needs at least 3 vertices"),
                    ));
                }
                for j in 1..idx.len() - 1 {
                    faces.push([idx[0], idx[j], idx[j + 1]]);
                }
            }
            _ => {}
        }
    }
    if points.is_empty() {
        return Err(input(
            file,
            "not an OBJ file, or one without vertices (no 'v x y z' lines)",
        ));
    }
    Ok(PlyCloud {
        points,
        labels: None,
        faces: (!faces.is_empty()).then_some(faces),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn vertices_and_polygons() {
        let c = read_obj(
            b"# cube corner\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvn 0 0 1\nf 1//1 2//1 3//1 4//1\nf -4 -3 -2\n",
            "q.obj",
        )
        .unwrap();
        assert_eq!(c.points.len(), 4);
        assert_eq!(c.faces, Some(vec![[0, 1, 2], [0, 2, 3], [0, 1, 2]]));
        let cloud = read_obj(b"v 0 0 0\nv 1 2 3\n", "p.obj").unwrap();
        assert_eq!(cloud.faces, None);
    }

    #[test]
    fn bad_files_are_named() {
        let e = |b: &[u8]| read_obj(b, "m.obj").unwrap_err().to_string();
        assert!(e(b"v 0 0\n").contains("line 1: a vertex needs x y z"));
        assert!(e(b"v 0 0 0\nf 1 2 3\n").contains("line 2: vertex index 2 is out of range"));
        assert!(e(b"ply\nformat ascii 1.0\n").contains("without vertices"));
        assert!(e(b"v 0 0 0\nv 0 0 1\nf 1 2\n").contains("at least 3"));
    }
}
