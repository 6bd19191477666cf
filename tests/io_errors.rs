//! Every kind of bad input gets an error naming the file and the problem.

mod io_common;

use glam::Vec3;
use gsart::io::ply::{read_ply, write_ply};
use gsart::io::sequence::{Frame, LoadOptions, Sequence};
use gsart::Error;
use io_common::*;

/// Loads `bytes` as a frame named `name` and returns the error text, checking it is
/// an input error that names the file and contains every `needle`.
fn fails(name: &str, bytes: &[u8], needles: &[&str]) -> String {
    let err = match Frame::from_bytes(name, bytes, 4096, 0) {
        Ok(f) => panic!("{name}: expected an error, got {} points", f.points.len()),
        Err(e) => e,
    };
    assert!(matches!(err, Error::Input { .. }), "{name}: {err:?}");
    let text = err.to_string();
    assert!(
        text.contains(name),
        "message does not name the file: {text}"
    );
    for n in needles {
        assert!(text.contains(n), "message {text:?} lacks {n:?}");
    }
    text
}

fn good(n: usize, format: &str) -> Vec<u8> {
    encode(
        format,
        &[El {
            name: "vertex",
            rows: vertex_rows(&blob(n), None),
        }],
    )
}

fn header_then(body: &str) -> Vec<u8> {
    format!("ply\nformat ascii 1.0\n{body}").into_bytes()
}

#[test]
fn not_a_ply() {
    fails(
        "notes.ply",
        b"hello, this is plain text\nnothing more\n",
        &["not a PLY file"],
    );
    fails("empty.ply", b"", &["empty"]);
    fails(
        "bin.ply",
        &[0u8, 1, 2, 3, 4, 5, 250, 251],
        &["not a PLY file"],
    );
    fails("short.ply", b"pl", &["header"]);
}

#[test]
fn zip_obj_and_friends_are_named() {
    let mut zip = b"PK\x03\x04\x14\x00\x00\x00\x08\x00".to_vec();
    zip.extend_from_slice(&[0u8; 40]);
    fails(
        "frames.ply",
        &zip,
        &["this looks like a ZIP archive, not a PLY file"],
    );
    fails(
        "mesh.ply",
        b"# Blender OBJ\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
        &["OBJ", "not a PLY file"],
    );
    fails("m2.ply", b"v 0.1 0.2 0.3\nv 1 2 3\n", &["OBJ"]);
    fails("gz.ply", &[0x1f, 0x8b, 8, 0, 0, 0], &["gzip"]);
    fails("s.ply", b"solid cube\nfacet normal 0 0 1\n", &["STL"]);
}

#[test]
fn malformed_headers() {
    fails(
        "a.ply",
        b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n",
        &["end_header"],
    );
    fails(
        "b.ply",
        &header_then("element vertex 2\nproperty float x\nbanana 3\nend_header\n"),
        &["malformed header", "banana"],
    );
    fails(
        "c.ply",
        &header_then("property float x\nelement vertex 2\nend_header\n"),
        &["before any 'element'"],
    );
    fails(
        "d.ply",
        &header_then("element vertex many\nend_header\n"),
        &["invalid count 'many'"],
    );
    fails(
        "e.ply",
        b"ply\nelement vertex 1\nproperty float x\nend_header\n",
        &["no 'format' line"],
    );
    fails(
        "f.ply",
        &header_then("element vertex 2\nproperty float\nend_header\n"),
        &["malformed header"],
    );
    fails(
        "g.ply",
        &header_then("element vertex 2\nproperty list float int idx\nend_header\n"),
        &["count type"],
    );
    fails(
        "h.ply",
        &header_then("element vertex 1\nelement vertex 1\nend_header\n"),
        &["declared twice"],
    );
}

#[test]
fn unknown_format_and_type() {
    fails(
        "fmt.ply",
        b"ply\nformat binary_middle_endian 1.0\nelement vertex 1\nproperty float x\nend_header\n",
        &["unknown PLY format 'binary_middle_endian'"],
    );
    fails(
        "ver.ply",
        b"ply\nformat ascii 2.0\nelement vertex 1\nproperty float x\nend_header\n",
        &["version '2.0'"],
    );
    fails(
        "ty.ply",
        &header_then("element vertex 1\nproperty float128 x\nend_header\n"),
        &["unknown property type 'float128'"],
    );
}

#[test]
fn truncated_bodies_say_expected_and_read() {
    for f in FORMATS {
        let full = good(100, f);
        // Cut in the middle of the 43rd record (binary: 12 bytes per record).
        let header_len = full.windows(11).position(|w| w == b"end_header\n").unwrap() + 11;
        let cut = if f == "ascii" {
            // after 42 full lines
            let mut lines = 0;
            let mut at = header_len;
            while lines < 42 {
                if full[at] == b'\n' {
                    lines += 1;
                }
                at += 1;
            }
            at
        } else {
            header_len + 42 * 12 + 5
        };
        let text = fails(
            "cut.ply",
            &full[..cut],
            &["truncated", "100 vertices", "42"],
        );
        assert!(text.contains("only 42"), "{text}");
    }
    // Truncated in a later element.
    let mut bytes = tetra_like_with_faces("binary_little_endian");
    bytes.truncate(bytes.len() - 3);
    fails("faces.ply", &bytes, &["truncated", "'face'"]);
}

fn tetra_like_with_faces(format: &str) -> Vec<u8> {
    let vertex = El {
        name: "vertex",
        rows: [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
        ]
        .iter()
        .map(|v| {
            vec![
                V::S("float", "x", v[0]),
                V::S("float", "y", v[1]),
                V::S("float", "z", v[2]),
            ]
        })
        .collect(),
    };
    let face = El {
        name: "face",
        rows: [
            [0.0, 1.0, 2.0],
            [0.0, 1.0, 3.0],
            [0.0, 2.0, 3.0],
            [1.0, 2.0, 3.0],
        ]
        .iter()
        .map(|t| vec![V::L("uchar", "int", "vertex_indices", t.to_vec())])
        .collect(),
    };
    encode(format, &[vertex, face])
}

#[test]
fn header_body_mismatch() {
    let el = |n| El {
        name: "vertex",
        rows: vertex_rows(&blob(n), None),
    };
    // The header promises fewer vertices than the body holds.
    for f in FORMATS {
        let bytes = encode_with_counts(f, &[el(50)], Some(&[40]));
        fails("more.ply", &bytes, &["header/body mismatch"]);
    }
    // Ascii record with an extra value / a missing value / a word.
    fails(
        "extra.ply",
        &header_then("element vertex 2\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 2 3\n4 5 6 7\n"),
        &["header/body mismatch", "record 1", "more values"],
    );
    fails(
        "few.ply",
        &header_then("element vertex 2\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 2 3\n4 5\n"),
        &["header/body mismatch", "too few values"],
    );
    fails(
        "word.ply",
        &header_then("element vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 two 3\n"),
        &["'two'"],
    );
    // A binary body declared as ascii.
    let mut bin = good(20, "binary_little_endian");
    let pos = bin
        .windows(20)
        .position(|w| w == b"binary_little_endian")
        .unwrap();
    bin.splice(pos..pos + 20, b"ascii".iter().copied());
    fails("bin_as_ascii.ply", &bin, &["vertex"]);
    // Face index beyond the vertices.
    let vertex = El {
        name: "vertex",
        rows: vertex_rows(&blob(20), None),
    };
    let face = El {
        name: "face",
        rows: vec![vec![V::L(
            "uchar",
            "int",
            "vertex_indices",
            vec![0.0, 1.0, 25.0],
        )]],
    };
    fails(
        "idx.ply",
        &encode("ascii", &[vertex, face]),
        &["vertex 25", "only 20 vertices"],
    );
}

#[test]
fn no_vertices_and_missing_coordinates() {
    fails(
        "nov.ply",
        &header_then("element face 0\nproperty list uchar int vertex_indices\nend_header\n"),
        &["no 'vertex' element"],
    );
    fails(
        "zero.ply",
        &header_then(
            "element vertex 0\nproperty float x\nproperty float y\nproperty float z\nend_header\n",
        ),
        &["0 vertices"],
    );
    let rows: Vec<Vec<V>> = (0..20)
        .map(|i| {
            vec![
                V::S("float", "x", i as f64),
                V::S("float", "y", 1.0),
                V::S("float", "nz", 0.0),
            ]
        })
        .collect();
    for f in FORMATS {
        fails(
            "noz.ply",
            &encode(
                f,
                &[El {
                    name: "vertex",
                    rows: rows.clone(),
                }],
            ),
            &["no 'z' property", "nz"],
        );
    }
}

#[test]
fn non_finite_coordinates_name_the_vertex() {
    fails(
        "nan.ply",
        &header_then("element vertex 3\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 2 3\n4 5 6\n7 nan 9\n"),
        &["non-finite", "vertex 2"],
    );
    for f in ["binary_little_endian", "binary_big_endian"] {
        let mut pts = blob(30);
        pts[17].y = f32::INFINITY;
        let bytes = encode(
            f,
            &[El {
                name: "vertex",
                rows: vertex_rows(&pts, None),
            }],
        );
        fails("inf.ply", &bytes, &["non-finite", "vertex 17"]);
    }
    // A double too large for f32 is not finite after conversion either.
    let rows: Vec<Vec<V>> = (0..20)
        .map(|i| {
            vec![
                V::S("double", "x", if i == 4 { 1e300 } else { i as f64 }),
                V::S("double", "y", 1.0),
                V::S("double", "z", (i * i) as f64),
            ]
        })
        .collect();
    fails(
        "big.ply",
        &encode(
            "binary_little_endian",
            &[El {
                name: "vertex",
                rows,
            }],
        ),
        &["vertex 4"],
    );
}

#[test]
fn too_few_points_and_degenerate_clouds() {
    fails(
        "few.ply",
        &good(15, "binary_little_endian"),
        &["too few points: 15", "16"],
    );
    let same = vec![Vec3::new(0.3, 0.2, 0.1); 50];
    let mut b = Vec::new();
    write_ply(&mut b, &same, None, false).unwrap();
    fails("same.ply", &b, &["degenerate", "identical"]);
    // A tilted plane (not axis aligned).
    let plane: Vec<Vec3> = (0..200)
        .map(|i| {
            let (u, v) = ((i % 17) as f32 * 0.1, (i / 17) as f32 * 0.13);
            Vec3::new(u, v, 0.3 * u - 0.7 * v + 2.0)
        })
        .collect();
    let mut b = Vec::new();
    write_ply(&mut b, &plane, None, true).unwrap();
    fails("plane.ply", &b, &["degenerate", "plane"]);
    // A line.
    let line: Vec<Vec3> = (0..40)
        .map(|i| Vec3::new(1.0, 2.0, 3.0) * i as f32)
        .collect();
    let mut b = Vec::new();
    write_ply(&mut b, &line, None, false).unwrap();
    fails("line.ply", &b, &["degenerate"]);
    // A thin but real 3D object is fine: a 1 m board 1 mm thick.
    let board: Vec<Vec3> = (0..400)
        .map(|i| {
            Vec3::new(
                (i % 20) as f32 * 0.05,
                (i / 20 % 20) as f32 * 0.05,
                (i % 2) as f32 * 0.001,
            )
        })
        .collect();
    let mut b = Vec::new();
    write_ply(&mut b, &board, None, false).unwrap();
    Frame::from_bytes("board.ply", &b, 4096, 0).unwrap();
    // A mesh whose faces have no area.
    let vertex = El {
        name: "vertex",
        rows: vertex_rows(&[Vec3::ZERO, Vec3::X, Vec3::X * 2.0], None),
    };
    let face = El {
        name: "face",
        rows: vec![vec![V::L(
            "uchar",
            "int",
            "vertex_indices",
            vec![0.0, 1.0, 2.0],
        )]],
    };
    fails(
        "flat.ply",
        &encode("ascii", &[vertex, face]),
        &["zero total area"],
    );
}

#[test]
fn negative_and_invalid_labels() {
    let pts = blob(20);
    let mut labels: Vec<f64> = (0..20).map(|i| (i % 3) as f64).collect();
    labels[9] = -1.0;
    let rows: Vec<Vec<V>> = pts
        .iter()
        .zip(&labels)
        .map(|(p, &l)| {
            vec![
                V::S("float", "x", p.x as f64),
                V::S("float", "y", p.y as f64),
                V::S("float", "z", p.z as f64),
                V::S("int", "part", l),
            ]
        })
        .collect();
    for f in FORMATS {
        fails(
            "neg.ply",
            &encode(
                f,
                &[El {
                    name: "vertex",
                    rows: rows.clone(),
                }],
            ),
            &["negative part label -1", "vertex 9"],
        );
    }
    fails(
        "frac.ply",
        &header_then("element vertex 1\nproperty float x\nproperty float y\nproperty float z\nproperty float part\nend_header\n1 2 3 0.5\n"),
        &["not a non-negative integer"],
    );
}

#[test]
fn path_errors_name_the_path() {
    let dir = temp_dir("errors");
    let bad = dir.join("frame_1.ply");
    std::fs::write(&bad, b"PK\x03\x04rest").unwrap();
    let ok = dir.join("frame_0.ply");
    std::fs::write(&ok, good(30, "binary_little_endian")).unwrap();
    let e = Sequence::from_files(&[ok.clone(), bad.clone()])
        .unwrap_err()
        .to_string();
    assert!(
        e.contains(&bad.display().to_string()) && e.contains("ZIP"),
        "{e}"
    );
    let missing = dir.join("nope.ply");
    let e = Sequence::from_files(&[ok.clone(), missing.clone()]).unwrap_err();
    assert!(
        matches!(e, Error::Io { .. }) && e.to_string().contains("nope.ply"),
        "{e}"
    );
    // A folder without frame files (a JSON is none).
    let empty = dir.join("empty");
    std::fs::create_dir_all(&empty).unwrap();
    std::fs::write(empty.join("gt.json"), b"{}").unwrap();
    let e = Sequence::from_dir(&empty).unwrap_err().to_string();
    assert!(
        e.contains("no frame files (.ply, .pcd") && e.contains("empty"),
        "{e}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_single_frame_is_not_a_sequence() {
    let dir = temp_dir("single");
    std::fs::write(dir.join("only.ply"), good(30, "ascii")).unwrap();
    let e = Sequence::from_dir(&dir).unwrap_err().to_string();
    assert!(
        e.contains("a sequence needs at least 2 frames, got 1"),
        "{e}"
    );
    assert!(e.contains("only.ply"), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn browser_files_fail_individually() {
    let files = vec![
        ("f10.ply".to_string(), good(40, "binary_big_endian")),
        ("f2.ply".to_string(), b"v 1 2 3\n".to_vec()),
        ("f1.ply".to_string(), good(50, "ascii")),
        ("f3.ply".to_string(), good(60, "binary_little_endian")),
    ];
    let results = Sequence::from_named_bytes(files, LoadOptions::default());
    let names: Vec<&str> = results.iter().map(|(n, _)| n.as_str()).collect();
    assert_eq!(names, ["f1.ply", "f2.ply", "f3.ply", "f10.ply"]);
    let e = results[1].1.as_ref().unwrap_err().to_string();
    assert!(e.contains("f2.ply") && e.contains("OBJ"), "{e}");
    assert!(results[0].1.is_ok() && results[2].1.is_ok() && results[3].1.is_ok());
    let seq = Sequence::from_loaded(results).unwrap();
    assert_eq!(
        seq.frames
            .iter()
            .map(|f| f.points.len())
            .collect::<Vec<_>>(),
        [50, 60, 40]
    );
    assert_eq!(seq.frames[2].name, "f10.ply");

    // Only one good file left: the sequence error says so.
    let results = Sequence::from_named_bytes(
        vec![
            ("a.ply".into(), good(20, "ascii")),
            ("b.ply".into(), Vec::new()),
        ],
        LoadOptions::default(),
    );
    let e = Sequence::from_loaded(results).unwrap_err().to_string();
    assert!(e.contains("at least 2 frames, got 1"), "{e}");
}

#[test]
fn read_ply_alone_reports_structure_errors() {
    let e = read_ply(b"PK\x03\x04", "z.zip").unwrap_err().to_string();
    assert_eq!(e, "z.zip: this looks like a ZIP archive, not a PLY file (unzip it and load the frames inside; a NumPy archive loads named .npz)");
}
