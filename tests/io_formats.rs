//! Frames in the formats besides PLY (PCD, NumPy `.npy`/`.npz`, text tables, OBJ)
//! read back as the same points and labels, whether one file holds a frame or the
//! whole sequence; NumPy's own files (written by numpy itself when python3 has it,
//! as `npm test` sees to) read as numpy wrote them; and `gsart fit` fits a sequence
//! given as one `.npz`.

use std::path::{Path, PathBuf};
use std::process::Command;

use glam::Vec3;
use gsart::io::npy::write_npy;
use gsart::io::npz::write_npz;
use gsart::io::pcd::lzf_compress;
use gsart::io::sequence::{Frame, Sequence};
use gsart::synth::{generate, write_sequence_dir, ObjectKind, SynthOptions};

mod python_common;

fn temp_dir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("gsart_formats_{tag}_{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn frames() -> Vec<Frame> {
    generate(&SynthOptions {
        frames: 4,
        points: 300,
        seed: 3,
        ..SynthOptions::new(ObjectKind::Laptop)
    })
    .unwrap()
    .sequence
    .frames
}

fn f32_le(points: &[Vec3]) -> Vec<u8> {
    points
        .iter()
        .flat_map(|p| p.to_array())
        .flat_map(|v| v.to_le_bytes())
        .collect()
}

fn labels_of(f: &Frame) -> &[u32] {
    f.labels.as_deref().unwrap()
}

const PCD_HEAD: &str = "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS x y z label\nSIZE 4 4 4 4\nTYPE F F F U\nCOUNT 1 1 1 1\n";

fn pcd(f: &Frame, data: &str) -> Vec<u8> {
    let n = f.points.len();
    let mut out = format!(
        "{PCD_HEAD}WIDTH {n}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\nDATA {data}\n"
    )
    .into_bytes();
    let l = labels_of(f);
    match data {
        "ascii" => {
            for (p, l) in f.points.iter().zip(l) {
                out.extend_from_slice(format!("{} {} {} {l}\n", p.x, p.y, p.z).as_bytes());
            }
        }
        "binary" => {
            for (p, l) in f.points.iter().zip(l) {
                out.extend_from_slice(&f32_le(&[*p]));
                out.extend_from_slice(&l.to_le_bytes());
            }
        }
        _ => {
            let mut soa = Vec::new();
            for c in 0..3 {
                f.points
                    .iter()
                    .for_each(|p| soa.extend_from_slice(&p[c].to_le_bytes()));
            }
            l.iter()
                .for_each(|l| soa.extend_from_slice(&l.to_le_bytes()));
            let packed = lzf_compress(&soa);
            out.extend_from_slice(&(packed.len() as u32).to_le_bytes());
            out.extend_from_slice(&(soa.len() as u32).to_le_bytes());
            out.extend_from_slice(&packed);
        }
    }
    out
}

fn check(dir: &Path, frames: &[Frame], with_labels: bool) {
    let seq = Sequence::from_dir(dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display()));
    assert_eq!(seq.frames.len(), frames.len(), "{}", dir.display());
    for (a, b) in seq.frames.iter().zip(frames) {
        assert_eq!(a.points, b.points, "{} {}", dir.display(), a.name);
        if with_labels {
            assert_eq!(a.labels, b.labels, "{} {}", dir.display(), a.name);
        } else {
            assert_eq!(a.labels, None);
        }
    }
}

#[test]
fn every_format_reads_back_the_same_frames() {
    let frames = frames();
    let n = frames[0].points.len();
    assert!(frames.iter().all(|f| f.points.len() == n));
    let per_frame = |tag: &str, ext: &str, bytes: &dyn Fn(&Frame) -> Vec<u8>| {
        let dir = temp_dir(tag);
        for (k, f) in frames.iter().enumerate() {
            std::fs::write(dir.join(format!("f{k}.{ext}")), bytes(f)).unwrap();
        }
        // A note beside the frames is not a frame: the frames' format comes first.
        std::fs::write(dir.join("notes.txt"), "captured on a turntable\n").unwrap();
        dir
    };
    check(
        &per_frame("pcd_ascii", "pcd", &|f| pcd(f, "ascii")),
        &frames,
        true,
    );
    check(
        &per_frame("pcd_bin", "pcd", &|f| pcd(f, "binary")),
        &frames,
        true,
    );
    check(
        &per_frame("pcd_lzf", "pcd", &|f| pcd(f, "binary_compressed")),
        &frames,
        true,
    );
    check(
        &per_frame("csv", "csv", &|f| {
            let mut s = String::from("x,y,z,part\n");
            for (p, l) in f.points.iter().zip(labels_of(f)) {
                s += &format!("{},{},{},{l}\n", p.x, p.y, p.z);
            }
            s.into_bytes()
        }),
        &frames,
        true,
    );
    check(
        &per_frame("xyz", "xyz", &|f| {
            f.points
                .iter()
                .map(|p| format!("{} {} {}\n", p.x, p.y, p.z))
                .collect::<String>()
                .into_bytes()
        }),
        &frames,
        false,
    );
    check(
        &per_frame("npy", "npy", &|f| {
            write_npy("<f4", &[n, 3], &f32_le(&f.points))
        }),
        &frames,
        false,
    );

    // The whole sequence in one file: a (T, N, 3) stack, or an archive with labels.
    let all: Vec<Vec3> = frames.iter().flat_map(|f| f.points.clone()).collect();
    let dir = temp_dir("stack");
    std::fs::write(
        dir.join("walk.npy"),
        write_npy("<f4", &[frames.len(), n, 3], &f32_le(&all)),
    )
    .unwrap();
    check(&dir, &frames, false);
    let seq = Sequence::from_files(&[dir.join("walk.npy")]).unwrap();
    assert_eq!(seq.frames[3].name, "walk.npy[3]");
    let labels: Vec<u8> = frames
        .iter()
        .flat_map(|f| labels_of(f).to_vec())
        .flat_map(|l| (l as i64).to_le_bytes())
        .collect();
    let dir = temp_dir("npz");
    let npz = write_npz(
        &[
            (
                "points",
                write_npy("<f4", &[frames.len(), n, 3], &f32_le(&all)),
            ),
            ("labels", write_npy("<i8", &[frames.len(), n], &labels)),
        ],
        true,
    );
    std::fs::write(dir.join("walk.npz"), &npz).unwrap();
    check(&dir, &frames, true);

    // The page's loader: one entry a frame, a bad file beside them named.
    let loaded = Sequence::from_named_bytes(
        vec![
            ("walk.npz".into(), npz),
            (
                "broken.pcd".into(),
                b"FIELDS x y z\nPOINTS 9\nDATA ascii\n".to_vec(),
            ),
        ],
        Default::default(),
    );
    let names: Vec<&str> = loaded.iter().map(|(n, _)| n.as_str()).collect();
    assert_eq!(
        names,
        [
            "broken.pcd",
            "walk.npz[0]",
            "walk.npz[1]",
            "walk.npz[2]",
            "walk.npz[3]"
        ]
    );
    let e = loaded[0].1.as_ref().unwrap_err().to_string();
    assert!(e.starts_with("broken.pcd: truncated"), "{e}");
    assert_eq!(Sequence::from_loaded(loaded).unwrap().frames.len(), 4);
}

#[test]
fn an_obj_mesh_is_sampled_like_a_ply_mesh() {
    let dir = temp_dir("obj");
    // A unit cube, quads, moved along x from frame to frame.
    let faces = "f 1 2 3 4\nf 5 8 7 6\nf 1 5 6 2\nf 2 6 7 3\nf 3 7 8 4\nf 5 1 4 8\n";
    for k in 0..3 {
        let mut s = String::from("o cube\n");
        // The vertex order of `faces`: the bottom's corners 1-4 round, then the top's.
        for c in 0..8 {
            let (x, y) = [(0., 0.), (1., 0.), (1., 1.), (0., 1.)][c & 3];
            s += &format!("v {} {y} {}\n", x + k as f32, c >> 2);
        }
        s += faces;
        std::fs::write(dir.join(format!("cube{k}.obj")), s).unwrap();
    }
    let seq = Sequence::from_dir(&dir).unwrap();
    assert_eq!(seq.frames.len(), 3);
    for (k, f) in seq.frames.iter().enumerate() {
        assert_eq!(f.points.len(), 4096);
        let lo = f.points.iter().fold(Vec3::MAX, |a, &p| a.min(p));
        let hi = f.points.iter().fold(Vec3::MIN, |a, &p| a.max(p));
        assert!(
            (lo - Vec3::new(k as f32, 0., 0.)).abs().max_element() < 0.02,
            "{lo}"
        );
        assert!(
            (hi - Vec3::new(k as f32 + 1., 1., 1.)).abs().max_element() < 0.02,
            "{hi}"
        );
        // Every point on the surface: one coordinate at a face.
        for p in &f.points {
            let q = *p - Vec3::new(k as f32, 0., 0.);
            let d = q
                .to_array()
                .iter()
                .map(|&c| c.abs().min((c - 1.).abs()))
                .fold(f32::MAX, f32::min);
            assert!(d < 1e-5, "{q}");
        }
    }
}

#[test]
fn numpy_files_read_as_numpy_wrote_them() {
    if !python_common::python_has("numpy") {
        return;
    }
    let frames = frames();
    let n = frames[0].points.len();
    let dir = temp_dir("numpy");
    let all: Vec<Vec3> = frames.iter().flat_map(|f| f.points.clone()).collect();
    std::fs::write(dir.join("points.f32"), f32_le(&all)).unwrap();
    let labels: Vec<u8> = frames
        .iter()
        .flat_map(|f| labels_of(f).to_vec())
        .flat_map(|l| l.to_le_bytes())
        .collect();
    std::fs::write(dir.join("labels.u32"), labels).unwrap();
    let t = frames.len();
    let script = format!(
        r#"
import numpy as np, os
os.chdir({dir:?})
p = np.fromfile("points.f32", dtype="<f4").reshape({t}, {n}, 3)
l = np.fromfile("labels.u32", dtype="<u4").reshape({t}, {n})
for name in ["stack", "f64_fortran", "big_endian", "savez", "compressed", "padded"]:
    os.makedirs(name, exist_ok=True)
np.save("stack/walk.npy", p)
np.save("f64_fortran/walk.npy", np.asfortranarray(p.astype(np.float64)))
np.save("big_endian/walk.npy", p.astype(">f4"))
np.savez("savez/walk.npz", *[p[k] for k in range({t})])
np.savez_compressed("compressed/walk.npz", points=p, labels=l.astype(np.int32), colors=np.zeros_like(p))
q = np.full(({t}, {n} + 5, 3), np.nan, dtype=np.float32)
q[:, :{n}] = p
np.save("padded/walk.npy", q)
"#,
        dir = dir.to_str().unwrap()
    );
    let out = Command::new("python3")
        .args(["-c", &script])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    for (sub, with_labels) in [
        ("stack", false),
        ("f64_fortran", false),
        ("big_endian", false),
        ("savez", false),
        ("compressed", true),
        ("padded", false),
    ] {
        check(&dir.join(sub), &frames, with_labels);
    }
}

#[test]
fn a_sequence_in_one_npz_is_fitted() {
    let out = generate(&SynthOptions {
        frames: 6,
        points: 1024,
        seed: 0,
        ..SynthOptions::new(ObjectKind::Laptop)
    })
    .unwrap();
    // The benchmark folder's gt.json, with the frames as one archive instead of PLYs.
    let dir = temp_dir("fit");
    write_sequence_dir(&out, &dir).unwrap();
    let frames = &out.sequence.frames;
    let n = frames[0].points.len();
    let all: Vec<Vec3> = frames.iter().flat_map(|f| f.points.clone()).collect();
    let labels: Vec<u8> = frames
        .iter()
        .flat_map(|f| labels_of(f).to_vec())
        .flat_map(|l| (l as i32).to_le_bytes())
        .collect();
    for entry in std::fs::read_dir(&dir).unwrap() {
        let p = entry.unwrap().path();
        if p.extension().is_some_and(|e| e == "ply") {
            std::fs::remove_file(p).unwrap();
        }
    }
    std::fs::write(
        dir.join("scan.npz"),
        write_npz(
            &[
                (
                    "points",
                    write_npy("<f4", &[frames.len(), n, 3], &f32_le(&all)),
                ),
                ("labels", write_npy("<i4", &[frames.len(), n], &labels)),
            ],
            true,
        ),
    )
    .unwrap();
    let result = dir.join("result.json");
    let ply_out = dir.join("parts");
    std::fs::create_dir_all(&ply_out).unwrap();
    let run = Command::new(env!("CARGO_BIN_EXE_gsart"))
        .args([
            "fit",
            dir.to_str().unwrap(),
            "--quality",
            "fast",
            "--quiet",
            "--out",
        ])
        .arg(&result)
        .arg("--ply-out")
        .arg(&ply_out)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "{stderr}");
    let eval = Command::new(env!("CARGO_BIN_EXE_gsart"))
        .args(["eval"])
        .arg(&result)
        .arg(&dir)
        .output()
        .unwrap();
    assert!(
        eval.status.success(),
        "{}",
        String::from_utf8_lossy(&eval.stderr)
    );
    let m: serde_json::Value = serde_json::from_slice(&eval.stdout).unwrap();
    let ri = m["mean_ri"].as_f64().unwrap();
    assert!(ri >= 0.9, "RI {ri}: {m}");
    let mut names: Vec<String> = std::fs::read_dir(&ply_out)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    assert_eq!(
        names,
        (0..6)
            .map(|k| format!("scan_{k}_parts.ply"))
            .collect::<Vec<_>>()
    );
}
