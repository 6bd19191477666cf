//! Property tests of the readers besides PLY (PCD, NumPy, OBJ, text tables): no input,
//! random or a mutated valid file, can panic them, and every error names the file.

use glam::Vec3;
use gsart::io::npy::write_npy;
use gsart::io::npz::write_npz;
use gsart::io::pcd::lzf_compress;
use gsart::io::sequence::Frame;
use gsart::math::Libm;
use proptest::prelude::*;

mod io_common;
use io_common::{apply, Mutation};

fn points() -> Vec<Vec3> {
    (0..24)
        .map(|i| {
            let t = i as f32 * 0.3;
            Vec3::new(t.lsin(), t.lcos(), 0.1 * (i % 5) as f32)
        })
        .collect()
}

fn f32_le(v: &[Vec3]) -> Vec<u8> {
    v.iter()
        .flat_map(|p| p.to_array())
        .flat_map(|c| c.to_le_bytes())
        .collect()
}

/// Valid files of every format, named so the extension picks the reader.
fn seeds() -> Vec<(&'static str, Vec<u8>)> {
    let p = points();
    let n = p.len();
    let stack: Vec<Vec3> = p.iter().chain(&p).copied().collect();
    let labels: Vec<u8> = (0..2 * n as i32)
        .flat_map(|i| (i % 3).to_le_bytes())
        .collect();
    let head = format!(
        "# .PCD v0.7\nVERSION 0.7\nFIELDS x y z label\nSIZE 4 4 4 4\nTYPE F F F U\nCOUNT 1 1 1 1\nWIDTH {n}\nHEIGHT 1\nPOINTS {n}\n"
    );
    let mut ascii = format!("{head}DATA ascii\n");
    let mut binary = format!("{head}DATA binary\n").into_bytes();
    let mut soa = Vec::new();
    for (i, q) in p.iter().enumerate() {
        ascii += &format!("{} {} {} {}\n", q.x, q.y, q.z, i % 3);
        binary.extend_from_slice(&f32_le(&[*q]));
        binary.extend_from_slice(&(i as u32 % 3).to_le_bytes());
    }
    for c in 0..3 {
        p.iter()
            .for_each(|q| soa.extend_from_slice(&q[c].to_le_bytes()));
    }
    (0..n as u32).for_each(|i| soa.extend_from_slice(&(i % 3).to_le_bytes()));
    let packed = lzf_compress(&soa);
    let mut compressed = format!("{head}DATA binary_compressed\n").into_bytes();
    compressed.extend_from_slice(&(packed.len() as u32).to_le_bytes());
    compressed.extend_from_slice(&(soa.len() as u32).to_le_bytes());
    compressed.extend_from_slice(&packed);
    let csv: String = std::iter::once("x,y,z,part\n".to_string())
        .chain(
            p.iter()
                .enumerate()
                .map(|(i, q)| format!("{},{},{},{}\n", q.x, q.y, q.z, i % 3)),
        )
        .collect();
    let mut obj: String = p
        .iter()
        .map(|q| format!("v {} {} {}\n", q.x, q.y, q.z))
        .collect();
    obj += "f 1 2 3\nf 4/1/1 5/1/1 6/1/1 7/1/1\nf -1 -2 -3\n";
    vec![
        ("s.npy", write_npy("<f4", &[2, n, 3], &f32_le(&stack))),
        (
            "s.npz",
            write_npz(
                &[
                    ("points", write_npy("<f4", &[2, n, 3], &f32_le(&stack))),
                    ("labels", write_npy("<i4", &[2, n], &labels)),
                ],
                true,
            ),
        ),
        (
            "s.npz",
            write_npz(
                &[
                    ("arr_0", write_npy("<f4", &[n, 3], &f32_le(&p))),
                    ("arr_1", write_npy("<f4", &[n, 3], &f32_le(&p))),
                ],
                false,
            ),
        ),
        ("s.pcd", ascii.into_bytes()),
        ("s.pcd", binary),
        ("s.pcd", compressed),
        ("s.csv", csv.into_bytes()),
        ("s.obj", obj.into_bytes()),
    ]
}

/// Reading returns Ok or an error naming the file; it never panics.
fn exercise(name: &str, bytes: &[u8]) {
    if let Err(e) = Frame::all_from_bytes(name, bytes, 64, 1) {
        assert!(
            e.to_string().starts_with(name),
            "error does not name the file: {e}"
        );
    }
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
    ]
}

const NAMES: [&str; 6] = ["r.npy", "r.npz", "r.pcd", "r.csv", "r.obj", "r.xyz"];

proptest! {
    #![proptest_config(ProptestConfig { cases: 4000, failure_persistence: None, ..ProptestConfig::default() })]

    #[test]
    fn random_bytes_never_panic(which in 0usize..6, bytes in proptest::collection::vec(any::<u8>(), 0..512)) {
        exercise(NAMES[which], &bytes);
    }

    #[test]
    fn random_bodies_after_valid_headers_never_panic(which in 0usize..4, body in proptest::collection::vec(any::<u8>(), 0..400)) {
        let mut b = match which {
            0 => write_npy("<f8", &[3, 5, 3], &[]),
            1 => b"FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nPOINTS 20\nDATA binary\n".to_vec(),
            2 => b"FIELDS x y z label\nSIZE 8 8 8 2\nTYPE F F F I\nCOUNT 1 1 1 1\nPOINTS 20\nDATA binary_compressed\n".to_vec(),
            _ => b"FIELDS x y z\nPOINTS 20\nDATA ascii\n".to_vec(),
        };
        b.extend_from_slice(&body);
        exercise(if which == 0 { "h.npy" } else { "h.pcd" }, &b);
    }

    #[test]
    fn mutated_valid_files_never_panic(which in 0usize..8, ms in proptest::collection::vec(mutation(), 1..4)) {
        let (name, base) = seeds().swap_remove(which);
        exercise(name, &apply(base, &ms));
    }
}

#[test]
fn seeds_are_valid() {
    for (name, s) in seeds() {
        let frames = Frame::all_from_bytes(name, &s, 64, 1).unwrap_or_else(|e| panic!("{e}"));
        assert!(!frames.is_empty());
    }
}
