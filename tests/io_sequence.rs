//! Sequences: folders and file lists in natural order, browser buffers, downsampling,
//! and a million-point frame through the streaming path.

use gsart::math::Libm;
mod io_common;

use std::collections::HashSet;
use std::time::Instant;

use glam::Vec3;
use gsart::geom::fps::farthest_point_sampling;
use gsart::io::ply::{read_ply_from, write_ply};
use gsart::io::sequence::{gt_path, Downsample, LoadOptions, Sequence};
use io_common::*;

fn write(path: &std::path::Path, pts: &[Vec3], labels: Option<&[u32]>, ascii: bool) {
    let mut f = std::io::BufWriter::new(std::fs::File::create(path).unwrap());
    write_ply(&mut f, pts, labels, ascii).unwrap();
}

#[test]
fn folder_in_natural_order_ignoring_heldout_and_other_files() {
    let dir = temp_dir("folder");
    for (i, name) in ["f10.ply", "f2.ply", "f1.ply", "F11.PLY"]
        .iter()
        .enumerate()
    {
        write(&dir.join(name), &blob(20 + i), None, i % 2 == 0);
    }
    std::fs::create_dir_all(dir.join("heldout")).unwrap();
    write(&dir.join("heldout/f0.ply"), &blob(99), None, false);
    std::fs::write(dir.join("notes.txt"), "not a frame").unwrap();
    std::fs::write(dir.join("gt.json"), "{}").unwrap();
    let seq = Sequence::from_dir(&dir).unwrap();
    let names: Vec<&str> = seq.frames.iter().map(|f| f.name.as_str()).collect();
    assert_eq!(names, ["F11.PLY", "f1.ply", "f2.ply", "f10.ply"]);
    assert_eq!(seq.frames[3].points.len(), 20);
    assert_eq!(gt_path(&dir), Some(dir.join("gt.json")));
    assert_eq!(gt_path(&dir.join("heldout")), None);
    // A file list is sorted the same way whatever order it is given in.
    let seq2 = Sequence::from_files(&[dir.join("f10.ply"), dir.join("f2.ply"), dir.join("f1.ply")])
        .unwrap();
    let names2: Vec<&str> = seq2.frames.iter().map(|f| f.name.as_str()).collect();
    assert_eq!(names2, ["f1.ply", "f2.ply", "f10.ply"]);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn meshes_in_a_sequence_are_sampled_per_frame() {
    let mesh = tetra();
    let opts = LoadOptions {
        mesh_samples: 300,
        seed: 5,
    };
    let r = Sequence::from_named_bytes(
        vec![("a.ply".into(), mesh.clone()), ("b.ply".into(), mesh)],
        opts,
    );
    let seq = Sequence::from_loaded(r).unwrap();
    assert_eq!(seq.frames[0].points.len(), 300);
    // Independent samples per frame, but deterministic for the seed.
    assert_ne!(seq.frames[0].points, seq.frames[1].points);
    let mesh = tetra();
    let r2 = Sequence::from_named_bytes(
        vec![("a.ply".into(), mesh.clone()), ("b.ply".into(), mesh)],
        opts,
    );
    assert_eq!(
        Sequence::from_loaded(r2).unwrap().frames[1].points,
        seq.frames[1].points
    );
}

fn tetra() -> Vec<u8> {
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
    encode("binary_little_endian", &[vertex, face])
}

fn random_cloud(n: usize, seed: u64) -> Vec<Vec3> {
    use rand::{Rng, SeedableRng};
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    (0..n)
        .map(|_| Vec3::new(rng.random(), rng.random(), rng.random::<f32>() * 0.3))
        .collect()
}

#[test]
fn downsampling_both_methods() {
    let frames = [
        ("a.ply".to_string(), random_cloud(5000, 1)),
        ("b.ply".to_string(), random_cloud(300, 2)),
        ("c.ply".to_string(), random_cloud(2000, 3)),
    ];
    let files: Vec<(String, Vec<u8>)> = frames
        .iter()
        .map(|(n, p)| {
            let labels: Vec<u32> = (0..p.len() as u32).collect();
            let mut b = Vec::new();
            write_ply(&mut b, p, Some(&labels), false).unwrap();
            (n.clone(), b)
        })
        .collect();
    let seq =
        Sequence::from_loaded(Sequence::from_named_bytes(files, LoadOptions::default())).unwrap();
    for method in [Downsample::Farthest, Downsample::Random] {
        let d = seq.downsample(1000, method, 42);
        assert!(d.any_downsampled());
        assert_eq!(d.original_sizes, [5000, 300, 2000]);
        let sizes: Vec<usize> = d.sequence.frames.iter().map(|f| f.points.len()).collect();
        assert_eq!(sizes, [1000, 300, 1000], "{method:?}");
        for (k, kept) in d.kept.iter().enumerate() {
            assert!(kept.windows(2).all(|w| w[0] < w[1]), "ascending and unique");
            let f = &d.sequence.frames[k];
            // Labels were the input indices, so they must equal the kept indices.
            let l: Vec<usize> = f
                .labels
                .as_ref()
                .unwrap()
                .iter()
                .map(|&v| v as usize)
                .collect();
            assert_eq!(&l, kept);
            for (j, &i) in kept.iter().enumerate() {
                assert_eq!(f.points[j], seq.frames[k].points[i]);
            }
        }
        // Deterministic for a seed, different for another.
        let again = seq.downsample(1000, method, 42);
        assert_eq!(again.kept, d.kept);
        let other = seq.downsample(1000, method, 43);
        assert_ne!(other.kept[0], d.kept[0]);
        let note = d.note().unwrap();
        assert!(
            note.contains("2 of 3 frames") && note.contains("a.ply 5000 → 1000"),
            "{note}"
        );
    }
    // Farthest-point sampling covers space more evenly than random sampling: the
    // largest distance from any input point to the kept set is smaller.
    let cover = |kept: &[usize]| {
        let pts = &seq.frames[0].points;
        pts.iter()
            .map(|p| {
                kept.iter()
                    .map(|&i| p.distance_squared(pts[i]))
                    .fold(f32::INFINITY, f32::min)
            })
            .fold(0.0f32, f32::max)
    };
    let fps = seq.downsample(200, Downsample::Farthest, 1);
    let rnd = seq.downsample(200, Downsample::Random, 1);
    assert!(cover(&fps.kept[0]) < 0.5 * cover(&rnd.kept[0]));
    // Nothing to do when everything fits.
    let none = seq.downsample(10_000, Downsample::Farthest, 0);
    assert!(!none.any_downsampled() && none.note().is_none());
}

#[test]
fn streaming_downsampled_load_equals_load_then_downsample() {
    let dir = temp_dir("stream-eq");
    let mut paths = Vec::new();
    for k in 0..3 {
        let p = dir.join(format!("frame_{k}.ply"));
        write(
            &p,
            &random_cloud(3000 + 500 * k, 10 + k as u64),
            None,
            k == 1,
        );
        paths.push(p);
    }
    let a = Sequence::from_files_downsampled(&paths, 1024, Downsample::Farthest, 9).unwrap();
    let b = Sequence::from_files(&paths)
        .unwrap()
        .downsample(1024, Downsample::Farthest, 9);
    assert_eq!(a.kept, b.kept);
    assert_eq!(a.original_sizes, [3000, 3500, 4000]);
    for (x, y) in a.sequence.frames.iter().zip(&b.sequence.frames) {
        assert_eq!(x.points, y.points);
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Writes a 1M-point binary frame: a unit sphere shell (golden-angle spiral) shifted
/// by `k`, labelled 1 on its upper half.
fn write_sphere(path: &std::path::Path, n: usize, k: usize) {
    let pts: Vec<Vec3> = (0..n)
        .map(|i| {
            let t = i as f32 * 2.399_963;
            let z = 1.0 - 2.0 * (i as f32 + 0.5) / n as f32;
            let r = (1.0 - z * z).sqrt();
            Vec3::new(r * t.lcos() + k as f32, r * t.lsin(), z)
        })
        .collect();
    let labels: Vec<u32> = pts.iter().map(|p| (p.z > 0.0) as u32).collect();
    write(path, &pts, Some(&labels), false);
}

/// Peak resident memory of this process (Linux), in MiB.
fn peak_rss_mib() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb / 1024.0)
}

#[test]
fn million_point_frames_stream_and_downsample() {
    let dir = temp_dir("million");
    let n = 1_000_000;
    let paths: Vec<_> = (0..2)
        .map(|k| {
            let p = dir.join(format!("big_{k}.ply"));
            write_sphere(&p, n, k);
            p
        })
        .collect();
    // The bare reader on the streaming path.
    let t = Instant::now();
    let f = std::fs::File::open(&paths[0]).unwrap();
    let c = read_ply_from(f, "big_0.ply").unwrap();
    let read_s = t.elapsed().as_secs_f64();
    assert_eq!(c.points.len(), n);
    assert_eq!(
        c.labels
            .as_ref()
            .unwrap()
            .iter()
            .filter(|&&l| l == 1)
            .count(),
        n / 2
    );
    drop(c);
    // Load + farthest-point downsampling of both frames.
    let t = Instant::now();
    let d = Sequence::from_files_downsampled(&paths, 4096, Downsample::Farthest, 3).unwrap();
    let load_s = t.elapsed().as_secs_f64();
    eprintln!("1M-point frame: read {read_s:.2} s; 2 frames read + FPS to 4096: {load_s:.2} s");
    assert_eq!(d.original_sizes, [n, n]);
    for f in &d.sequence.frames {
        assert_eq!(f.points.len(), 4096);
        let both = f
            .labels
            .as_ref()
            .unwrap()
            .iter()
            .collect::<HashSet<_>>()
            .len();
        assert_eq!(both, 2);
        // Even coverage of a unit sphere: 4096 FPS points are ~0.05 apart; random
        // sampling would put some pairs far closer.
        let min_d = f
            .points
            .iter()
            .enumerate()
            .flat_map(|(i, a)| f.points[i + 1..].iter().map(move |b| a.distance(*b)))
            .fold(f32::INFINITY, f32::min);
        assert!(min_d > 0.02, "{min_d}");
    }
    assert!(d.note().unwrap().contains("2 of 2 frames"));
    if let Some(mib) = peak_rss_mib() {
        eprintln!("peak RSS of the test process: {mib:.0} MiB");
        assert!(mib < 2048.0, "{mib} MiB");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The SPEC's memory bound with ten 1M-point frames (slow: run with `--ignored`).
#[test]
#[ignore]
fn ten_million_point_frames_fit_in_2_gib() {
    let dir = temp_dir("ten-million");
    let paths: Vec<_> = (0..10)
        .map(|k| {
            let p = dir.join(format!("frame_{k}.ply"));
            write_sphere(&p, 1_000_000, k);
            p
        })
        .collect();
    let t = Instant::now();
    let d = Sequence::from_files_downsampled(&paths, 4096, Downsample::Farthest, 0).unwrap();
    eprintln!(
        "10 x 1M points loaded + FPS: {:.2} s",
        t.elapsed().as_secs_f64()
    );
    assert_eq!(d.sequence.len(), 10);
    let t = Instant::now();
    let full = Sequence::from_files(&paths).unwrap();
    let d2 = full.downsample(4096, Downsample::Farthest, 0);
    eprintln!(
        "10 x 1M points loaded whole, then FPS: {:.2} s",
        t.elapsed().as_secs_f64()
    );
    assert_eq!(d.kept, d2.kept);
    let mib = peak_rss_mib().unwrap_or(0.0);
    eprintln!("peak RSS: {mib:.0} MiB");
    assert!(mib < 2048.0);
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn fps_is_exact_on_a_large_cloud() {
    // The blocked implementation against a direct O(N·n) loop.
    let pts = random_cloud(20_000, 77);
    let got = farthest_point_sampling(&pts, 64, 5);
    let mut d = vec![f32::INFINITY; pts.len()];
    let mut cur = 5;
    let mut want = vec![];
    for _ in 0..64 {
        want.push(cur);
        d[cur] = -1.0;
        let s = pts[cur];
        let mut best = (f32::NEG_INFINITY, 0);
        for (i, p) in pts.iter().enumerate() {
            let (dx, dy, dz) = (p.x - s.x, p.y - s.y, p.z - s.z);
            d[i] = d[i].min(dx * dx + dy * dy + dz * dz);
            if d[i] > best.0 {
                best = (d[i], i);
            }
        }
        cur = best.1;
    }
    assert_eq!(got, want);
}

#[test]
fn benchmark_folders_load_as_sequences() {
    let Some(root) = bench_dev() else { return };
    let dir = root.join("xarm7_00");
    if !dir.is_dir() {
        eprintln!("note: {} missing, skipped", dir.display());
        return;
    }
    let seq = Sequence::from_dir(&dir).unwrap();
    assert_eq!(seq.len(), 10);
    assert_eq!(seq.frames[0].name, "frame_000.ply");
    assert_eq!(seq.frames[9].name, "frame_009.ply");
    assert!(seq.has_labels());
    assert!(gt_path(&dir).is_some());
    let d = seq.downsample(4096, Downsample::Farthest, 0);
    assert!(!d.any_downsampled());
}
