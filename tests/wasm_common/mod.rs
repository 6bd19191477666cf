//! The core's checks run inside headless Chromium (included by `wasm_core_page.rs`,
//! on the page thread, and `wasm_core_worker.rs`, in a dedicated worker): the same
//! code paths as the native tests, compiled to wasm32.

use glam::Vec3;
use gsart::eval::rand_index::rand_index;
use gsart::eval::tree_edit::tree_edit_distance;
use gsart::io::ply::{read_ply, write_ply};
use gsart::io::result::FitResult;
use gsart::kinematics::chain::Chain;
use gsart::synth::{generate, ObjectKind, SynthOptions};
use wasm_bindgen_test::wasm_bindgen_test;

#[wasm_bindgen_test]
fn ply_round_trip_and_errors_in_wasm() {
    let points: Vec<Vec3> = (0..64)
        .map(|i| {
            let t = i as f32 * 0.1;
            Vec3::new(t.sin(), t.cos(), 0.01 * i as f32 * (i % 3) as f32)
        })
        .collect();
    let labels: Vec<u32> = (0..64).map(|i| (i % 4) as u32).collect();
    for ascii in [false, true] {
        let mut bytes = Vec::new();
        write_ply(&mut bytes, &points, Some(&labels), ascii).unwrap();
        let cloud = read_ply(&bytes, "round.ply").unwrap();
        assert_eq!(cloud.points, points);
        assert_eq!(cloud.labels.as_deref(), Some(&labels[..]));
        // A truncated body names the file and says what is wrong.
        let cut = &bytes[..bytes.len() - 20];
        let err = read_ply(cut, "cut.ply").unwrap_err().to_string();
        assert!(err.contains("cut.ply"), "{err}");
    }
    let err = read_ply(b"PK\x03\x04 not a ply", "archive.zip")
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("archive.zip") && err.to_lowercase().contains("zip"),
        "{err}"
    );
}

/// The other frame formats in wasm, as the page's loader reads them: a NumPy stack
/// in a deflated `.npz` (miniz_oxide) and an LZF-packed PCD give the same frames.
#[wasm_bindgen_test]
fn numpy_and_pcd_frames_in_wasm() {
    use gsart::io::npy::write_npy;
    use gsart::io::npz::write_npz;
    use gsart::io::pcd::lzf_compress;
    use gsart::io::sequence::{LoadOptions, Sequence};
    use gsart::math::Libm;
    let frames: Vec<Vec<Vec3>> = (0..3)
        .map(|k| {
            (0..64)
                .map(|i| {
                    let t = i as f32 * 0.1;
                    Vec3::new(t.lsin() + k as f32, t.lcos(), 0.01 * (i % 7) as f32)
                })
                .collect()
        })
        .collect();
    let le = |v: &[Vec3]| -> Vec<u8> {
        v.iter()
            .flat_map(|p| p.to_array())
            .flat_map(|c| c.to_le_bytes())
            .collect()
    };
    let all: Vec<Vec3> = frames.concat();
    let npz = write_npz(
        &[("points", write_npy("<f4", &[3, 64, 3], &le(&all)))],
        true,
    );
    let mut soa = Vec::new();
    for c in 0..3 {
        frames[1]
            .iter()
            .for_each(|p| soa.extend_from_slice(&p[c].to_le_bytes()));
    }
    let packed = lzf_compress(&soa);
    let mut pcd =
        b"FIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH 64\nPOINTS 64\nDATA binary_compressed\n"
            .to_vec();
    pcd.extend_from_slice(&(packed.len() as u32).to_le_bytes());
    pcd.extend_from_slice(&(soa.len() as u32).to_le_bytes());
    pcd.extend_from_slice(&packed);
    let loaded = Sequence::from_named_bytes(
        vec![("walk.npz".into(), npz), ("one.pcd".into(), pcd)],
        LoadOptions::default(),
    );
    let names: Vec<&str> = loaded.iter().map(|(n, _)| n.as_str()).collect();
    assert_eq!(
        names,
        ["one.pcd", "walk.npz[0]", "walk.npz[1]", "walk.npz[2]"]
    );
    let seq = Sequence::from_loaded(loaded).unwrap();
    assert_eq!(seq.frames[0].points, frames[1]);
    for k in 0..3 {
        assert_eq!(seq.frames[k + 1].points, frames[k]);
    }
}

#[wasm_bindgen_test]
fn metrics_in_wasm() {
    assert_eq!(rand_index(&[0, 0, 1, 1], &[5, 5, 7, 7]).unwrap(), 1.0);
    // one pair of six disagrees: {a,b} together in pred, apart in gt
    let ri = rand_index(&[0, 0, 1, 1], &[0, 1, 2, 2]).unwrap();
    assert!((ri - 5.0 / 6.0).abs() < 1e-12, "{ri}");
    assert_eq!(tree_edit_distance(&[-1, 0, 1], &[-1, 0, 1]).unwrap(), 0);
    assert_eq!(tree_edit_distance(&[-1, 0, 1], &[-1, 0, 0]).unwrap(), 2);
}

#[wasm_bindgen_test]
fn ground_truth_forward_kinematics_in_wasm() {
    for kind in [ObjectKind::Laptop, ObjectKind::Cabinet, ObjectKind::Arm] {
        let mut o = SynthOptions::new(kind);
        o.frames = 4;
        o.points = 512;
        let s = generate(&o).unwrap();
        let labels: Vec<Vec<u32>> = s
            .sequence
            .frames
            .iter()
            .map(|f| f.labels.clone().unwrap())
            .collect();
        let r = FitResult::from_ground_truth(&s.gt, labels, 1).unwrap();
        let chain = Chain::from_result(&r).unwrap();
        for k in 0..r.frames {
            let poses = chain
                .part_poses(&r.root_pose(k).unwrap(), &r.joint_states(k))
                .unwrap();
            for (p, pose) in poses.iter().enumerate() {
                let want = r.pose(k, p).unwrap();
                assert!(pose.abs_diff_eq(want, 1e-5), "{kind:?} frame {k} part {p}");
            }
        }
    }
}

#[path = "../common_small_fit/mod.rs"]
mod common_small_fit;

/// The same small Step-1 fit as the native golden test: identical labels in wasm.
#[wasm_bindgen_test]
fn small_fit_gives_the_native_labels_in_wasm() {
    let labels = common_small_fit::small_fit_labels();
    let golden: Vec<u32> = serde_json::from_str(common_small_fit::GOLDEN).unwrap();
    assert_eq!(labels, golden);
}

/// A Step-1 candidate sent as bytes (how the page moves the runner-up to the other
/// worker) finishes in wasm exactly as the original does.
#[wasm_bindgen_test]
fn a_candidate_moved_as_bytes_finishes_the_same_in_wasm() {
    use gsart::fit::candidate_bytes::{from_bytes, to_bytes};
    use gsart::pipeline::{Control, FitOptions, Quality};
    let seq = generate(&SynthOptions {
        frames: 4,
        points: 512,
        heldout: 0,
        ..SynthOptions::new(ObjectKind::Laptop)
    })
    .unwrap()
    .sequence;
    let opts = FitOptions {
        quality: Quality::Fast,
        iters: Some(40),
        ..FitOptions::default()
    };
    let r = gsart::pipeline::fit_step1_single(&seq, 3, &opts, &mut |_| Control::Continue).unwrap();
    let copy = from_bytes(&to_bytes(&r)).unwrap();
    let finish = |s| {
        gsart::pipeline::finish(&seq, s, &|| 0.0, &mut |_| Control::Continue)
            .unwrap()
            .result
            .to_json()
    };
    assert_eq!(finish(copy), finish(r));
}
