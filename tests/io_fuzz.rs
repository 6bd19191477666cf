//! Property tests: no input, random or a mutated valid file, can panic the PLY reader
//! (bytes or streaming) or the frame loader; valid files always read back.

mod io_common;

use gsart::io::ply::{read_ply, read_ply_from};
use gsart::io::sequence::Frame;
use io_common::*;
use proptest::prelude::*;

/// A handful of valid files covering the formats, lists, extra elements and meshes.
fn seeds() -> Vec<Vec<u8>> {
    let mut out = Vec::new();
    for f in FORMATS {
        let pts = blob(24);
        let labels: Vec<u32> = (0..24).map(|i| i % 3).collect();
        out.push(encode(
            f,
            &[El {
                name: "vertex",
                rows: vertex_rows(&pts, Some(&labels)),
            }],
        ));
        let vertex = El {
            name: "vertex",
            rows: pts
                .iter()
                .enumerate()
                .map(|(i, p)| {
                    vec![
                        V::S("double", "z", p.z as f64),
                        V::L(
                            "uchar",
                            "int",
                            "nb",
                            (0..(i % 3)).map(|k| k as f64).collect(),
                        ),
                        V::S("short", "x", (p.x * 100.0).round() as f64),
                        V::S("float", "y", p.y as f64),
                    ]
                })
                .collect(),
        };
        let face = El {
            name: "face",
            rows: (0..6)
                .map(|i| {
                    vec![V::L(
                        "uchar",
                        "uint",
                        "vertex_indices",
                        vec![i as f64, (i + 1) as f64, (i + 5) as f64],
                    )]
                })
                .collect(),
        };
        let extra = El {
            name: "extra",
            rows: vec![vec![V::S("int", "a", 1.0)]],
        };
        out.push(encode(f, &[extra, vertex, face]));
    }
    out
}

/// Reading must return (Ok or Err), never panic, and the two paths must agree.
fn exercise(bytes: &[u8]) {
    let a = read_ply(bytes, "fuzz.ply");
    let b = read_ply_from(bytes, "fuzz.ply");
    match (&a, &b) {
        (Ok(x), Ok(y)) => assert_eq!(x, y),
        (Err(x), Err(y)) => assert_eq!(x.to_string(), y.to_string()),
        _ => panic!("bytes and streaming readers disagree"),
    }
    if let Err(e) = &a {
        assert!(
            e.to_string().starts_with("fuzz.ply"),
            "error does not name the file: {e}"
        );
    }
    let _ = Frame::from_bytes("fuzz.ply", bytes, 64, 1);
}

fn header_line() -> impl Strategy<Value = String> {
    prop_oneof![
        Just("element vertex 4294967295".to_string()),
        Just("element vertex 18446744073709551615".to_string()),
        Just("element vertex 0".to_string()),
        Just("element face 3".to_string()),
        Just("element huge 99999999999".to_string()),
        Just("property list uint uint vertex_indices".to_string()),
        Just("property list uchar float x".to_string()),
        Just("property double part".to_string()),
        Just("property char z".to_string()),
        Just("format binary_big_endian 1.0".to_string()),
        Just("format ascii 1.0".to_string()),
        Just("format binary_little_endian 1.0".to_string()),
        Just("end_header".to_string()),
        Just(String::new()),
        "[a-z_ 0-9]{0,30}",
    ]
}

fn mutation() -> impl Strategy<Value = Mutation> {
    prop_oneof![
        any::<usize>().prop_map(Mutation::Truncate),
        (any::<usize>(), any::<u8>()).prop_map(|(a, b)| Mutation::Flip(a, b)),
        (
            any::<usize>(),
            proptest::collection::vec(any::<u8>(), 1..16)
        )
            .prop_map(|(a, d)| Mutation::Insert(a, d)),
        (0usize..12, header_line()).prop_map(|(i, t)| Mutation::Line(i, t)),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 8000, failure_persistence: None, ..ProptestConfig::default() })]

    #[test]
    fn random_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..512)) {
        exercise(&bytes);
    }

    #[test]
    fn random_bytes_after_a_header_never_panic(
        fmt in 0usize..3,
        body in proptest::collection::vec(any::<u8>(), 0..400),
    ) {
        let mut b = format!(
            "ply\nformat {} 1.0\nelement vertex 20\nproperty float x\nproperty list uchar int l\nproperty float y\nproperty float z\nproperty int part\nelement face 2\nproperty list uchar int vertex_indices\nend_header\n",
            FORMATS[fmt]
        ).into_bytes();
        b.extend_from_slice(&body);
        exercise(&b);
    }

    #[test]
    fn mutated_valid_files_never_panic(
        which in 0usize..6,
        ms in proptest::collection::vec(mutation(), 1..4),
    ) {
        let base = seeds().swap_remove(which);
        exercise(&apply(base, &ms));
    }
}

#[test]
fn seeds_are_valid() {
    for s in seeds() {
        read_ply(&s, "seed.ply").unwrap();
    }
}
