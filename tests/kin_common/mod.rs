//! Shared helpers of the kinematics integration tests: a test-only reader of the fixed
//! bench-dev PLY layout and a sequence loader.
#![allow(dead_code)]

use std::path::{Path, PathBuf};

use glam::Vec3;
use gsart::io::gt::GroundTruth;

pub const BENCH: &str = "/work/shared/bench-dev/full";

/// Test-only reader of the fixed bench-dev binary layout (x y z f32, part i32).
pub fn read_bench_ply(path: &Path) -> (Vec<Vec3>, Vec<u32>) {
    let bytes = std::fs::read(path).unwrap();
    let marker = b"end_header\n";
    let start = bytes
        .windows(marker.len())
        .position(|w| w == marker)
        .unwrap()
        + marker.len();
    let header = std::str::from_utf8(&bytes[..start]).unwrap();
    assert!(header.contains("binary_little_endian"), "{path:?}");
    let n: usize = header
        .lines()
        .find_map(|l| l.strip_prefix("element vertex "))
        .unwrap()
        .trim()
        .parse()
        .unwrap();
    let body = &bytes[start..];
    assert_eq!(body.len(), n * 16);
    let f = |o: usize| f32::from_le_bytes(body[o..o + 4].try_into().unwrap());
    let mut pts = Vec::with_capacity(n);
    let mut lab = Vec::with_capacity(n);
    for i in 0..n {
        let o = i * 16;
        pts.push(Vec3::new(f(o), f(o + 4), f(o + 8)));
        lab.push(i32::from_le_bytes(body[o + 12..o + 16].try_into().unwrap()) as u32);
    }
    (pts, lab)
}

pub struct Seq {
    pub name: String,
    pub gt: GroundTruth,
    pub points: Vec<Vec<Vec3>>,
    pub labels: Vec<Vec<u32>>,
}

pub fn load(dir: &Path) -> Seq {
    let text = std::fs::read_to_string(dir.join("gt.json")).unwrap();
    let gt = GroundTruth::from_json(&text, "gt.json").unwrap();
    let (points, labels) = gt
        .frames
        .iter()
        .map(|f| read_bench_ply(&dir.join(f)))
        .unzip();
    Seq {
        name: dir.file_name().unwrap().to_string_lossy().into_owned(),
        gt,
        points,
        labels,
    }
}

pub fn sequences() -> Vec<PathBuf> {
    let Ok(rd) = std::fs::read_dir(BENCH) else {
        return vec![];
    };
    let mut v: Vec<PathBuf> = rd.flatten().map(|e| e.path()).collect();
    v.sort();
    v
}
