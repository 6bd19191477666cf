//! A generated sequence written as a benchmark folder reads back identically with the
//! crate's own readers (PLY frames, held-out clouds, gt.json).

use std::path::PathBuf;

use gsart::io::gt::GroundTruth;
use gsart::io::ply::read_ply;
use gsart::io::sequence::Sequence;
use gsart::synth::{
    generate, write_sequence_dir, write_sequence_dir_with, ObjectKind, SynthOptions,
};

fn temp_dir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("gsart_synth_{tag}_{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

#[test]
fn written_folder_reads_back() {
    for (ascii, occluded) in [(false, true), (true, false)] {
        let out = generate(&SynthOptions {
            occluded,
            frames: 4,
            points: 512,
            seed: 9,
            ..SynthOptions::new(ObjectKind::Cabinet)
        })
        .unwrap();
        let dir = temp_dir(if ascii { "ascii" } else { "bin" });
        write_sequence_dir_with(&out, &dir, ascii).unwrap();

        let names: Vec<String> = Sequence::frame_files_in(&dir)
            .unwrap()
            .iter()
            .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
            .collect();
        assert_eq!(names, out.gt.frames);
        let seq = Sequence::from_dir(&dir).unwrap();
        assert_eq!(seq.frames.len(), out.sequence.frames.len());
        for (a, b) in seq.frames.iter().zip(&out.sequence.frames) {
            assert_eq!(a.points, b.points);
            assert_eq!(a.labels, b.labels);
        }
        for (name, f) in out.gt.heldout_frames.iter().zip(&out.heldout) {
            let bytes = std::fs::read(dir.join(name)).unwrap();
            let c = read_ply(&bytes, name).unwrap();
            assert_eq!(c.points, f.points);
            assert_eq!(c.labels, f.labels);
        }
        if !ascii {
            // bench-dev records: 3 x f32 + i32 = 16 bytes per point
            let bytes = std::fs::read(dir.join("frame_000.ply")).unwrap();
            let text = String::from_utf8_lossy(&bytes);
            let end = text.find("end_header\n").unwrap() + "end_header\n".len();
            assert!(text[..end].contains("format binary_little_endian 1.0"));
            assert!(text[..end].contains("property int part"));
            assert_eq!(bytes.len() - end, 16 * out.sequence.frames[0].points.len());
        }
        let gt = GroundTruth::from_json(
            &std::fs::read_to_string(dir.join("gt.json")).unwrap(),
            "gt.json",
        )
        .unwrap();
        assert_eq!(gt.poses, out.gt.poses);
        assert_eq!(gt.heldout_poses, out.gt.heldout_poses);
        assert_eq!(gt.variant, if occluded { "occluded" } else { "full" });
        std::fs::remove_dir_all(&dir).unwrap();
    }
}

#[test]
fn unwritable_target_is_a_typed_error() {
    let out = generate(&SynthOptions {
        frames: 2,
        points: 64,
        ..SynthOptions::new(ObjectKind::Laptop)
    })
    .unwrap();
    // a regular file where the folder should be
    let file = temp_dir("file");
    std::fs::write(&file, b"x").unwrap();
    let err = write_sequence_dir(&out, &file).unwrap_err();
    assert!(
        err.to_string().contains(&file.display().to_string()),
        "{err}"
    );
    std::fs::remove_file(&file).unwrap();
}
