//! PLY reader/writer: round trips in all three formats, arbitrary layouts, extra
//! elements and list properties, meshes sampled by area, and the benchmark frames.

mod io_common;

use glam::Vec3;
use gsart::io::gt::GroundTruth;
use gsart::io::ply::{read_ply, read_ply_from, sample_mesh, write_ply};
use gsart::io::sequence::Frame;
use io_common::*;

#[test]
fn round_trip_all_three_formats() {
    let pts = blob(100);
    let labels: Vec<u32> = (0..100).map(|i| (i * 7 % 5) as u32).collect();
    // The writer's two formats.
    for ascii in [true, false] {
        let mut bytes = Vec::new();
        write_ply(&mut bytes, &pts, Some(&labels), ascii).unwrap();
        let c = read_ply(&bytes, "w.ply").unwrap();
        assert_eq!(c.points, pts, "ascii = {ascii}");
        assert_eq!(c.labels.as_deref(), Some(&labels[..]));
        // Streaming gives the same.
        let s = read_ply_from(&bytes[..], "w.ply").unwrap();
        assert_eq!(s, c);
    }
    // All three through the test encoder.
    for f in FORMATS {
        let bytes = encode(
            f,
            &[El {
                name: "vertex",
                rows: vertex_rows(&pts, Some(&labels)),
            }],
        );
        let c = read_ply(&bytes, "e.ply").unwrap();
        assert_eq!(c.points, pts, "{f}");
        assert_eq!(c.labels.as_deref(), Some(&labels[..]), "{f}");
    }
}

#[test]
fn binary_writer_matches_the_benchmark_layout() {
    let pts = blob(3);
    let mut bytes = Vec::new();
    write_ply(&mut bytes, &pts, Some(&[0, 1, 2]), false).unwrap();
    let text = String::from_utf8_lossy(&bytes);
    let header_end = text.find("end_header\n").unwrap() + "end_header\n".len();
    let header = &text[..header_end];
    assert!(header.starts_with("ply\nformat binary_little_endian 1.0\n"));
    assert!(header.contains(
        "element vertex 3\nproperty float x\nproperty float y\nproperty float z\nproperty int part\nend_header\n"
    ));
    assert_eq!(bytes.len() - header_end, 3 * 16);
    let rec = &bytes[header_end + 16..header_end + 32];
    assert_eq!(f32::from_le_bytes(rec[0..4].try_into().unwrap()), pts[1].x);
    assert_eq!(i32::from_le_bytes(rec[12..16].try_into().unwrap()), 1);
}

#[test]
fn any_property_order_and_type() {
    // double z first, uchar colour, int16 label named `label`, float y, int x.
    let rows: Vec<Vec<V>> = (0..20)
        .map(|i| {
            vec![
                V::S("double", "z", 0.125 * i as f64),
                V::S("uchar", "red", 200.0),
                V::S("int16", "label", (i % 4) as f64),
                V::S("float32", "y", -1.5 + i as f64),
                V::S("int", "x", (i * i) as f64),
                V::S("uint8", "alpha", 7.0),
            ]
        })
        .collect();
    for f in FORMATS {
        let bytes = encode(
            f,
            &[El {
                name: "vertex",
                rows: rows.clone(),
            }],
        );
        let c = read_ply(&bytes, "o.ply").unwrap();
        assert_eq!(c.points.len(), 20);
        for (i, p) in c.points.iter().enumerate() {
            assert_eq!(
                *p,
                Vec3::new((i * i) as f32, -1.5 + i as f32, 0.125 * i as f32),
                "{f} vertex {i}"
            );
        }
        let l = c.labels.unwrap();
        assert_eq!(l, (0..20).map(|i| (i % 4) as u32).collect::<Vec<_>>());
    }
    // Every scalar type for the coordinates, both endians.
    for ty in [
        "char", "uchar", "short", "ushort", "int", "uint", "float", "double", "int8", "uint16",
        "uint32", "float64",
    ] {
        for f in FORMATS {
            let rows: Vec<Vec<V>> = (0..5)
                .map(|i| {
                    vec![
                        V::S(ty, "x", i as f64),
                        V::S(ty, "y", 2.0 * i as f64),
                        V::S(ty, "z", 100.0),
                    ]
                })
                .collect();
            let c = read_ply(
                &encode(
                    f,
                    &[El {
                        name: "vertex",
                        rows,
                    }],
                ),
                "t.ply",
            )
            .unwrap();
            assert_eq!(c.points[4], Vec3::new(4.0, 8.0, 100.0), "{ty} {f}");
            assert!(c.labels.is_none());
        }
    }
}

#[test]
fn extra_elements_and_list_properties_are_skipped() {
    let pts = blob(30);
    for f in FORMATS {
        let camera = El {
            name: "camera",
            rows: vec![vec![
                V::S("float", "view_px", 1.0),
                V::S("double", "view_py", 2.0),
            ]],
        };
        // A list property inside the vertex element, of varying length, between x and y.
        let vertex = El {
            name: "vertex",
            rows: pts
                .iter()
                .enumerate()
                .map(|(i, p)| {
                    vec![
                        V::S("float", "x", p.x as f64),
                        V::L(
                            "uchar",
                            "int",
                            "neighbours",
                            (0..(i % 4)).map(|k| k as f64).collect(),
                        ),
                        V::S("float", "y", p.y as f64),
                        V::S("float", "z", p.z as f64),
                        V::S("ushort", "part", (i % 3) as f64),
                    ]
                })
                .collect(),
        };
        let edge = El {
            name: "edge",
            rows: vec![
                vec![V::S("int", "vertex1", 0.0), V::S("int", "vertex2", 1.0)],
                vec![V::S("int", "vertex1", 2.0), V::S("int", "vertex2", 3.0)],
            ],
        };
        let material = El {
            name: "material",
            rows: vec![vec![
                V::L("int", "float", "coeffs", vec![0.5, 0.25, 1.0]),
                V::S("uchar", "id", 3.0),
            ]],
        };
        let bytes = encode(f, &[camera, vertex, edge, material]);
        let c = read_ply(&bytes, "x.ply").unwrap();
        assert_eq!(c.points, pts, "{f}");
        assert_eq!(c.labels.unwrap()[5], 2, "{f}");
        assert!(c.faces.is_none(), "{f}");
    }
}

fn tetra_mesh(format: &str, with_extra: bool) -> Vec<u8> {
    let verts = [
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, 0.0, 1.0],
    ];
    let vertex = El {
        name: "vertex",
        rows: verts
            .iter()
            .enumerate()
            .map(|(i, v)| {
                vec![
                    V::S("float", "x", v[0]),
                    V::S("float", "y", v[1]),
                    V::S("float", "z", v[2]),
                    V::S("int", "part", i as f64),
                ]
            })
            .collect(),
    };
    let tri = |a: f64, b: f64, c: f64| {
        let mut r = vec![];
        if with_extra {
            r.push(V::S("uchar", "flags", 1.0));
        }
        r.push(V::L("uchar", "int", "vertex_indices", vec![a, b, c]));
        if with_extra {
            r.push(V::L("uchar", "float", "texcoord", vec![0.0; 6]));
        }
        r
    };
    let face = El {
        name: "face",
        rows: vec![
            tri(0.0, 1.0, 2.0),
            tri(0.0, 1.0, 3.0),
            tri(0.0, 2.0, 3.0),
            tri(1.0, 2.0, 3.0),
        ],
    };
    encode(format, &[vertex, face])
}

#[test]
fn meshes_are_read_and_sampled() {
    for f in FORMATS {
        for extra in [false, true] {
            let bytes = tetra_mesh(f, extra);
            let c = read_ply(&bytes, "m.ply").unwrap();
            assert!(c.is_mesh());
            assert_eq!(c.faces.as_ref().unwrap().len(), 4, "{f}");
            assert_eq!(c.faces.as_ref().unwrap()[3], [1, 2, 3]);
            // As a frame: the surface is sampled to the requested count and validated.
            let frame = Frame::from_bytes("m.ply", &bytes, 500, 7).unwrap();
            assert_eq!(frame.points.len(), 500);
            assert_eq!(frame.labels.as_ref().unwrap().len(), 500);
            for p in &frame.points {
                // On the tetrahedron's surface: on a coordinate plane or on x+y+z=1.
                let on = p.min_element().abs() < 1e-6 || (p.x + p.y + p.z - 1.0).abs() < 1e-5;
                assert!(on && p.min_element() > -1e-6, "{p}");
            }
        }
    }
    // `vertex_index` naming and a quad (fan-triangulated).
    let vertex = El {
        name: "vertex",
        rows: [
            [0.0, 0.0, 0.0],
            [2.0, 0.0, 0.0],
            [2.0, 1.0, 0.0],
            [0.0, 1.0, 0.0],
        ]
        .iter()
        .map(|v| {
            vec![
                V::S("double", "x", v[0]),
                V::S("double", "y", v[1]),
                V::S("double", "z", v[2]),
            ]
        })
        .collect(),
    };
    let face = El {
        name: "face",
        rows: vec![vec![V::L(
            "uint8",
            "uint32",
            "vertex_index",
            vec![0.0, 1.0, 2.0, 3.0],
        )]],
    };
    let c = read_ply(&encode("binary_big_endian", &[vertex, face]), "q.ply").unwrap();
    assert_eq!(c.faces.unwrap(), vec![[0, 1, 2], [0, 2, 3]]);
}

#[test]
fn mesh_sampling_follows_area() {
    // Two disjoint triangles, areas 1 and 3, labelled 0 and 1 by their first vertex.
    let points = vec![
        Vec3::new(0.0, 0.0, 0.0),
        Vec3::new(1.0, 0.0, 0.0),
        Vec3::new(0.0, 2.0, 0.0),
        Vec3::new(5.0, 0.0, 1.0),
        Vec3::new(8.0, 0.0, 1.0),
        Vec3::new(5.0, 2.0, 1.0),
    ];
    let labels = [0, 0, 0, 1, 1, 1];
    let faces = [[0, 1, 2], [3, 4, 5]];
    let n = 40_000;
    let (pts, l) = sample_mesh(&points, &faces, Some(&labels), n, 11, "two.ply").unwrap();
    let l = l.unwrap();
    let ones = l.iter().filter(|&&v| v == 1).count() as f64 / n as f64;
    assert!(
        (ones - 0.75).abs() < 0.01,
        "fraction on the big triangle {ones}"
    );
    for (p, &lab) in pts.iter().zip(&l) {
        // Each point is inside the triangle its label says.
        let (o, w, h) = if lab == 0 {
            (Vec3::ZERO, 1.0, 2.0)
        } else {
            (Vec3::new(5.0, 0.0, 1.0), 3.0, 2.0)
        };
        let q = *p - o;
        assert!(
            q.z.abs() < 1e-6 && q.x >= -1e-6 && q.y >= -1e-6 && q.x / w + q.y / h <= 1.0 + 1e-5,
            "{p}"
        );
    }
    // Uniform within a triangle: about a quarter of the small triangle's points lie
    // below half its height... (the region y < 1 holds 3/4 of its area).
    let small: Vec<&Vec3> = pts
        .iter()
        .zip(&l)
        .filter(|(_, &v)| v == 0)
        .map(|(p, _)| p)
        .collect();
    let low = small.iter().filter(|p| p.y < 1.0).count() as f64 / small.len() as f64;
    assert!((low - 0.75).abs() < 0.02, "{low}");
    // Seeded: same seed, same points; other seed, other points.
    let (again, _) = sample_mesh(&points, &faces, None, n, 11, "two.ply").unwrap();
    assert_eq!(again, pts);
    let (other, _) = sample_mesh(&points, &faces, None, n, 12, "two.ply").unwrap();
    assert_ne!(other, pts);
}

#[test]
fn benchmark_frames_read_with_labels_in_range() {
    let Some(root) = bench_dev() else { return };
    let mut seen = 0;
    let mut dirs: Vec<_> = std::fs::read_dir(&root)
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .collect();
    dirs.sort();
    for dir in dirs {
        let frame = dir.join("frame_000.ply");
        if !frame.is_file() {
            continue;
        }
        let bytes = std::fs::read(&frame).unwrap();
        let c = read_ply(&bytes, &frame.display().to_string()).unwrap();
        assert_eq!(c.points.len(), 4096, "{}", frame.display());
        let labels = c.labels.expect("bench frames carry part labels");
        let gt_text = std::fs::read_to_string(dir.join("gt.json")).unwrap();
        let num_parts = match GroundTruth::from_json(&gt_text, "gt.json") {
            Ok(gt) => gt.num_parts,
            Err(_) => serde_json::from_str::<serde_json::Value>(&gt_text).unwrap()["num_parts"]
                .as_u64()
                .unwrap() as usize,
        };
        assert!(
            labels.iter().all(|&l| (l as usize) < num_parts),
            "{}",
            frame.display()
        );
        // The streaming path agrees with the bytes path.
        let f = std::fs::File::open(&frame).unwrap();
        let s = read_ply_from(f, "s").unwrap();
        assert_eq!(s.points, c.points);
        seen += 1;
    }
    assert!(seen > 0, "bench-dev present but no frame_000.ply found");
}

/// A reader that hands out at most `step` bytes per call, like a slow pipe.
struct Trickle<'a> {
    data: &'a [u8],
    step: usize,
}

impl std::io::Read for Trickle<'_> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.step.min(buf.len()).min(self.data.len());
        buf[..n].copy_from_slice(&self.data[..n]);
        self.data = &self.data[n..];
        Ok(n)
    }
}

#[test]
fn streaming_survives_short_reads_and_chunk_boundaries() {
    // More records than one decode chunk (64 KiB / 16 B = 4096), lists and all formats.
    let pts = blob(9000);
    let labels: Vec<u32> = (0..9000).map(|i| i % 11).collect();
    for f in FORMATS {
        let bytes = encode(
            f,
            &[El {
                name: "vertex",
                rows: vertex_rows(&pts, Some(&labels)),
            }],
        );
        for step in [1, 7, 4096, 100_000] {
            let c = read_ply_from(Trickle { data: &bytes, step }, "t.ply").unwrap();
            assert_eq!(c.points, pts, "{f} step {step}");
            assert_eq!(c.labels.as_deref(), Some(&labels[..]));
        }
        // Truncation detected the same way through a trickle.
        let e = read_ply_from(
            Trickle {
                data: &bytes[..bytes.len() - 20],
                step: 3,
            },
            "t.ply",
        )
        .unwrap_err();
        assert!(e.to_string().contains("truncated"), "{e}");
    }
    // Recognising a ZIP does not depend on how much each read returns.
    let e = read_ply_from(
        Trickle {
            data: b"PK\x03\x04xxxx",
            step: 1,
        },
        "z.ply",
    )
    .unwrap_err();
    assert!(
        e.to_string()
            .contains("z.ply: this looks like a ZIP archive"),
        "{e}"
    );
}

#[test]
fn header_variants_are_accepted() {
    // CRLF line endings, obj_info and comments, blank and indented lines.
    let text = "ply\r\nformat ascii 1.0\r\ncomment made on windows\r\nobj_info scanner v2\r\n\r\nelement vertex 16\r\n  property float x\r\nproperty float y\r\nproperty float z\r\nend_header\r\n";
    let mut b = text.as_bytes().to_vec();
    for p in blob(16) {
        b.extend_from_slice(format!("{} {} {}\r\n", p.x, p.y, p.z).as_bytes());
    }
    let c = read_ply(&b, "crlf.ply").unwrap();
    assert_eq!(c.points, blob(16));
    // Binary after a CRLF end_header.
    let mut b = "ply\r\nformat binary_little_endian 1.0\r\nelement vertex 16\r\nproperty float x\r\nproperty float y\r\nproperty float z\r\nend_header\r\n"
        .as_bytes()
        .to_vec();
    for p in blob(16) {
        for v in [p.x, p.y, p.z] {
            b.extend_from_slice(&v.to_le_bytes());
        }
    }
    assert_eq!(read_ply(&b, "crlf.ply").unwrap().points, blob(16));
}
