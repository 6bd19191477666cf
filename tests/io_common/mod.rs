//! Helpers shared by the io integration tests: a tiny PLY encoder that can express
//! any layout (types, orders, lists, extra elements) in all three formats,
//! temporary folders, and the property tests' mutations of valid files.
#![allow(dead_code)]

use gsart::math::Libm;
use std::path::PathBuf;

use glam::Vec3;

/// One value of a record: scalar `(type, name, value)` or list `(count type, item type, name, items)`.
#[derive(Clone, Debug)]
pub enum V {
    S(&'static str, &'static str, f64),
    L(&'static str, &'static str, &'static str, Vec<f64>),
}

/// An element; its header is taken from the first row (all rows share the layout).
pub struct El {
    pub name: &'static str,
    pub rows: Vec<Vec<V>>,
}

fn put(out: &mut Vec<u8>, ty: &str, v: f64, big: bool) {
    macro_rules! b {
        ($x:expr) => {
            if big {
                out.extend_from_slice(&$x.to_be_bytes())
            } else {
                out.extend_from_slice(&$x.to_le_bytes())
            }
        };
    }
    match ty {
        "char" | "int8" => b!(v as i8),
        "uchar" | "uint8" => b!(v as u8),
        "short" | "int16" => b!(v as i16),
        "ushort" | "uint16" => b!(v as u16),
        "int" | "int32" => b!(v as i32),
        "uint" | "uint32" => b!(v as u32),
        "float" | "float32" => b!(v as f32),
        "double" | "float64" => b!(v),
        other => panic!("test encoder: unknown type {other}"),
    }
}

/// Encodes elements as a PLY file in `format` (`ascii`, `binary_little_endian`, `binary_big_endian`).
pub fn encode(format: &str, els: &[El]) -> Vec<u8> {
    encode_with_counts(format, els, None)
}

/// Like [`encode`] but with the declared counts overridden (to make lying headers).
pub fn encode_with_counts(format: &str, els: &[El], counts: Option<&[u64]>) -> Vec<u8> {
    let mut h = format!("ply\nformat {format} 1.0\ncomment test file\n");
    for (ei, e) in els.iter().enumerate() {
        let count = counts.map(|c| c[ei]).unwrap_or(e.rows.len() as u64);
        h.push_str(&format!("element {} {}\n", e.name, count));
        if let Some(first) = e.rows.first() {
            for v in first {
                match v {
                    V::S(t, n, _) => h.push_str(&format!("property {t} {n}\n")),
                    V::L(ct, it, n, _) => h.push_str(&format!("property list {ct} {it} {n}\n")),
                }
            }
        }
    }
    h.push_str("end_header\n");
    let mut out = h.into_bytes();
    let big = format == "binary_big_endian";
    for e in els {
        for row in &e.rows {
            if format == "ascii" {
                let mut toks = Vec::new();
                for v in row {
                    match v {
                        V::S(_, _, x) => toks.push(format!("{x}")),
                        V::L(_, _, _, xs) => {
                            toks.push(format!("{}", xs.len()));
                            toks.extend(xs.iter().map(|x| format!("{x}")));
                        }
                    }
                }
                out.extend_from_slice(toks.join(" ").as_bytes());
                out.push(b'\n');
            } else {
                for v in row {
                    match v {
                        V::S(t, _, x) => put(&mut out, t, *x, big),
                        V::L(ct, it, _, xs) => {
                            put(&mut out, ct, xs.len() as f64, big);
                            for x in xs {
                                put(&mut out, it, *x, big);
                            }
                        }
                    }
                }
            }
        }
    }
    out
}

/// A non-degenerate test cloud (a twisted blob), deterministic.
pub fn blob(n: usize) -> Vec<Vec3> {
    (0..n)
        .map(|i| {
            let f = i as f32;
            Vec3::new(
                (f * 0.37).lsin(),
                (f * 0.71).lcos() * 0.8,
                (f * 1.13).lsin() * 0.5 + f * 1e-3,
            )
        })
        .collect()
}

/// Simple `float x y z [int part]` vertex rows.
pub fn vertex_rows(points: &[Vec3], labels: Option<&[u32]>) -> Vec<Vec<V>> {
    points
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let mut r = vec![
                V::S("float", "x", p.x as f64),
                V::S("float", "y", p.y as f64),
                V::S("float", "z", p.z as f64),
            ];
            if let Some(l) = labels {
                r.push(V::S("int", "part", l[i] as f64));
            }
            r
        })
        .collect()
}

pub const FORMATS: [&str; 3] = ["ascii", "binary_little_endian", "binary_big_endian"];

/// A fresh, empty temporary folder unique to this process and `tag`.
pub fn temp_dir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("gsart-io-test-{}-{tag}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).expect("create temp dir");
    d
}

/// The benchmark folder (`shared/` beside the repository, or the session's copy), if
/// this machine has it.
pub fn bench_dev() -> Option<PathBuf> {
    let candidates = [
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/bench-dev/full"),
        PathBuf::from("/work/shared/bench-dev/full"),
    ];
    let found = candidates.iter().find(|p| p.is_dir()).cloned();
    if found.is_none() {
        eprintln!("note: no shared/bench-dev/full folder here; skipping the bench-dev checks");
    }
    found
}

/// A change to a valid file, for the property tests: cut, flip a byte, insert bytes,
/// or (PLY) replace header line `i`.
#[derive(Debug, Clone)]
pub enum Mutation {
    Truncate(usize),
    Flip(usize, u8),
    Insert(usize, Vec<u8>),
    /// Replace header line `i` (0-based) with the given text.
    Line(usize, String),
}

pub fn apply(mut bytes: Vec<u8>, ms: &[Mutation]) -> Vec<u8> {
    for m in ms {
        let n = bytes.len().max(1);
        match m {
            Mutation::Truncate(at) => bytes.truncate(at % n),
            Mutation::Flip(at, x) => {
                if !bytes.is_empty() {
                    let i = at % bytes.len();
                    bytes[i] ^= *x | 1;
                }
            }
            Mutation::Insert(at, data) => {
                let i = at % (bytes.len() + 1);
                bytes.splice(i..i, data.iter().copied());
            }
            Mutation::Line(i, text) => {
                let end = bytes
                    .windows(11)
                    .position(|w| w == b"end_header\n")
                    .map_or(0, |p| p + 11);
                let header = String::from_utf8_lossy(&bytes[..end]).into_owned();
                let mut lines: Vec<String> = header.lines().map(str::to_string).collect();
                if !lines.is_empty() {
                    let k = i % lines.len();
                    lines[k] = text.clone();
                    let mut new = lines.join("\n").into_bytes();
                    new.push(b'\n');
                    new.extend_from_slice(&bytes[end..]);
                    bytes = new;
                }
            }
        }
    }
    bytes
}
