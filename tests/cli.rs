//! The `gsart` binary end to end: `truth` + `eval` on bench-dev (the ground truth
//! scores perfectly), `fit` + `eval` on an occluded bench-dev robot, `synth` writes a
//! readable sequence, `articulate` re-poses a result, `edit` joins parts, chooses a
//! joint's type and the root and refuses an unlink of a joint that follows none, bad
//! input gives a one-line error naming the file, an output that cannot be written fails before the fit, a
//! reader closing the output pipe early is no crash, a poorly explained balanced fit
//! is done again from another seed, and `bench` reports a sequence's metrics and its
//! joints in the bar.

use std::path::{Path, PathBuf};
use std::process::Command;

fn gsart(args: &[&str]) -> (bool, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_gsart"))
        .args(args)
        .output()
        .expect("run gsart");
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

fn bench_dev() -> Option<PathBuf> {
    ["../shared/bench-dev", "/work/shared/bench-dev"]
        .iter()
        .map(PathBuf::from)
        .find(|p| p.is_dir())
}

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("gsart-cli-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

#[test]
fn ground_truth_as_result_scores_perfectly_on_bench_dev() {
    let Some(root) = bench_dev() else {
        eprintln!("skip: bench-dev not present");
        return;
    };
    let dir = tmp("truth");
    for seq in [
        "full/xarm7_00",
        "full/panda_gripper_00",
        "occluded/solo12_00",
    ] {
        let seq_dir = root.join(seq);
        let out = dir.join("gt.json");
        let (ok, _, err) = gsart(&[
            "truth",
            seq_dir.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ]);
        assert!(ok, "{err}");
        let (ok, stdout, err) = gsart(&["eval", out.to_str().unwrap(), seq_dir.to_str().unwrap()]);
        assert!(ok, "{err}");
        let m: serde_json::Value = serde_json::from_str(&stdout).unwrap();
        assert_eq!(m["mean_ri"], 1.0, "{seq}: {m}");
        assert_eq!(m["canonical_ri"], 1.0, "{seq}: {m}");
        assert!(
            m["reconstruction_error"].as_f64().unwrap() < 1e-9,
            "{seq}: {m}"
        );
        assert!(m["flow_error"].as_f64().unwrap() < 1e-9, "{seq}: {m}");
        assert_eq!(m["tree_edit_distance"], 0, "{seq}: {m}");
        let j = &m["joints"];
        assert!(j["joints"].as_u64().unwrap() > 0, "{seq}: {m}");
        assert_eq!(j["within_bar"], j["joints"], "{seq}: {m}");
    }
}

/// `gsart fit` (fast) of bench-dev's `occluded/NAME_00` into a scratch folder, then
/// `gsart eval` of it; None when bench-dev is not present.
fn fit_and_eval_occluded(name: &str) -> Option<serde_json::Value> {
    let Some(root) = bench_dev() else {
        eprintln!("skip: bench-dev not present");
        return None;
    };
    let seq = root.join(format!("occluded/{name}_00"));
    let out = tmp(&format!("occluded_{name}")).join("fit.json");
    let (ok, _, err) = gsart(&[
        "fit",
        seq.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--quality",
        "fast",
        "--quiet",
    ]);
    assert!(ok, "{err}");
    let (ok, stdout, err) = gsart(&["eval", out.to_str().unwrap(), seq.to_str().unwrap()]);
    assert!(ok, "{err}");
    Some(serde_json::from_str(&stdout).unwrap())
}

/// Occluded input gets its own pose search (`fit::occluded_search`). Measured on
/// occluded so101 (fast, seeds 0 / 1): tree edit distance 3 / 3 and re-animation
/// error 8.6 / 5.4 with it, 9 / 10 and 16.4 / 17.2 without any search (the
/// behaviour before). Seed 0 with session 37's code (libm everywhere, as the page):
/// tree edit distance 6, re-animation error 4.9.
#[test]
fn occluded_robot_fit_recovers_most_of_the_tree() {
    let Some(m) = fit_and_eval_occluded("so101") else {
        return;
    };
    let ted = m["tree_edit_distance"].as_u64().unwrap();
    let reanim = m["reanimation_error"].as_f64().unwrap();
    assert!(ted <= 6, "tree edit distance {ted}: {m}");
    assert!(reanim <= 12.0, "re-animation error {reanim}: {m}");
}

/// On occluded input the refinement leaves a still root where it is: refined, the root
/// moved the whole object to make frame c's view overlap each frame's view of another
/// side. Occluded panda_gripper (fast, seed 0): reconstruction error 7.86 with the root
/// refined, 3.01 without.
#[test]
fn occluded_gripper_keeps_its_hand_where_it_was_seen() {
    let Some(m) = fit_and_eval_occluded("panda_gripper") else {
        return;
    };
    let recon = m["reconstruction_error"].as_f64().unwrap();
    assert!(recon <= 5.0, "reconstruction error {recon}: {m}");
}

/// `gsart synth laptop` (`frames` frames of `points` points) into `dir/laptop`; returns
/// its path.
fn synth_laptop(dir: &Path, frames: usize, points: usize) -> PathBuf {
    let seq = dir.join("laptop");
    let (frames, points) = (frames.to_string(), points.to_string());
    let (ok, _, err) = gsart(&[
        "synth",
        "laptop",
        "--out",
        seq.to_str().unwrap(),
        "--frames",
        &frames,
        "--points",
        &points,
    ]);
    assert!(ok, "{err}");
    seq
}

/// `gsart synth laptop` (3 frames of 256 points) into `dir/laptop`, then `gsart truth`
/// of it into `dir/r.json`; returns both paths.
fn laptop_truth(dir: &Path) -> (PathBuf, PathBuf) {
    let seq = synth_laptop(dir, 3, 256);
    assert!(seq.join("frame_002.ply").is_file() && seq.join("gt.json").is_file());
    let result = dir.join("r.json");
    let (ok, _, err) = gsart(&[
        "truth",
        seq.to_str().unwrap(),
        "--out",
        result.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    (seq, result)
}

#[test]
fn synth_then_articulate() {
    let dir = tmp("synth");
    let (_, result) = laptop_truth(&dir);
    let posed = dir.join("posed.ply");
    let run = |q: &str| {
        let (ok, _, err) = gsart(&[
            "articulate",
            result.to_str().unwrap(),
            "--states",
            q,
            "--out",
            posed.to_str().unwrap(),
        ]);
        assert!(ok, "{err}");
        gsart::io::ply::read_ply(&std::fs::read(&posed).unwrap(), "posed.ply").unwrap()
    };
    let rest = run("0");
    let opened = run("-0.8");
    assert_eq!(rest.points.len(), 256);
    // Only the lid (part 1) moves.
    let labels = rest.labels.clone().unwrap();
    let moved = |part: u32| {
        rest.points
            .iter()
            .zip(&opened.points)
            .zip(&labels)
            .filter(|(_, &l)| l == part)
            .map(|((a, b), _)| a.distance(*b))
            .fold(0.0f32, f32::max)
    };
    assert!(moved(0) < 1e-6, "base moved {}", moved(0));
    assert!(moved(1) > 0.05, "lid did not move");
    // Wrong number of states: a clear error naming the result file.
    let (ok, _, err) = gsart(&[
        "articulate",
        result.to_str().unwrap(),
        "--states",
        "0,0,0",
        "--out",
        posed.to_str().unwrap(),
    ]);
    assert!(
        !ok && err.contains("r.json") && err.contains("joint"),
        "{err}"
    );
}

/// `gsart edit`: the laptop's ground truth with its lid joined to its base is one part
/// without joints, written with its URDF and metrics; a join naming no part is one line;
/// `--joint-type` makes the lid's hinge a slide; `--root` turns the hinge round.
#[test]
fn edit_joins_parts() {
    let dir = tmp("edit");
    let (seq, result) = laptop_truth(&dir);
    let (out, urdf) = (dir.join("edited.json"), dir.join("joined.urdf"));
    // `gsart edit RESULT SEQ ARGS… --out OUT`: success, stderr, and the edited result.
    let edit = |args: &[&str]| {
        let mut all = vec![
            "edit",
            result.to_str().unwrap(),
            seq.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ];
        all.extend_from_slice(args);
        let (ok, _, err) = gsart(&all);
        let r = ok.then(|| {
            gsart::io::result::FitResult::from_json(
                &std::fs::read_to_string(&out).unwrap(),
                "edited.json",
            )
            .unwrap()
        });
        (r, err)
    };
    let (r, err) = edit(&["--join", "0,1", "--urdf", urdf.to_str().unwrap(), "--quiet"]);
    let r = r.unwrap_or_else(|| panic!("{err}"));
    assert!(
        err.contains("2 parts → 1 part") && err.contains("metrics:"),
        "{err}"
    );
    assert_eq!(r.parts, 1);
    assert!(std::fs::read_to_string(&urdf).unwrap().contains("<robot"));
    let (r, err) = edit(&["--join", "0,7"]);
    assert!(
        r.is_none() && err.starts_with("gsart: ") && err.contains("part 7 does not exist"),
        "{err}"
    );
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    // The lid's hinge made a slide: the result says so.
    let (r, err) = edit(&["--joint-type", "1=prismatic", "--quiet"]);
    let joints = r.unwrap_or_else(|| panic!("{err}")).joints.unwrap();
    assert_eq!(joints.len(), 1);
    assert_eq!(joints[0].joint_type, gsart::io::gt::JointType::Prismatic);
    let (r, err) = edit(&["--joint-type", "1=hinge"]);
    assert!(
        r.is_none() && err.contains("--joint-type 1=hinge: expected PART=revolute"),
        "{err}"
    );
    // The lid made the root: the hinge turns round.
    let (r, err) = edit(&["--root", "1", "--quiet"]);
    let r = r.unwrap_or_else(|| panic!("{err}"));
    assert_eq!(r.tree.as_ref().unwrap().root, 1);
    let j = &r.joints.as_ref().unwrap()[0];
    assert_eq!((j.parent, j.child), (1, 0));
    assert_eq!(j.joint_type, gsart::io::gt::JointType::Revolute);
    // The laptop's one hinge follows no other joint: nothing to unlink.
    let (r, err) = edit(&["--unlink", "1"]);
    assert!(
        r.is_none() && err.contains("unlink part 1: its joint does not follow another"),
        "{err}"
    );
    let report = dir.join("kin.json");
    let (r, err) = edit(&["--unlink", "1", "--report", report.to_str().unwrap()]);
    assert!(
        r.is_none() && err.contains("--report: an edit that only unlinks"),
        "{err}"
    );
}

#[test]
fn bad_input_is_one_clear_line() {
    let dir = tmp("bad");
    let a = dir.join("a.ply");
    std::fs::write(&a, b"PK\x03\x04 zip bytes").unwrap();
    let b = dir.join("b.ply");
    std::fs::write(
        &b,
        b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nend_header\n",
    )
    .unwrap();
    let out = dir.join("r.json");
    let (ok, _, err) = gsart(&[
        "fit",
        a.to_str().unwrap(),
        b.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(!ok);
    assert!(
        err.starts_with("gsart: ") && err.contains("a.ply") && err.contains("ZIP"),
        "{err}"
    );
    assert!(!Path::new(&out).exists());
}

#[test]
fn an_output_that_cannot_be_written_fails_before_the_fit() {
    // The input folder does not exist either: the outputs are checked first, so a
    // long fit never ends in a write error.
    let dir = tmp("unwritable");
    let ok_out = dir.join("r.json");
    let missing = dir.join("no_such_folder").join("r.json");
    let (ok_s, missing_s) = (ok_out.to_str().unwrap(), missing.to_str().unwrap());
    let dir_s = dir.to_str().unwrap();
    let file = dir.join("a_file");
    std::fs::write(&file, b"not a folder").unwrap();
    let file_s = file.to_str().unwrap();
    for (args, flag) in [
        (vec!["--out", missing_s], "--out"),
        (vec!["--out", dir_s], "--out"),
        (vec!["--out", ok_s, "--urdf", missing_s], "--urdf"),
        (vec!["--out", ok_s, "--report", missing_s], "--report"),
        (vec!["--out", ok_s, "--ply-out", file_s], "--ply-out"),
    ] {
        let mut all = vec!["fit", "missing_dir_is_not_read"];
        all.extend(args);
        let (ok, _, err) = gsart(&all);
        assert!(!ok);
        assert!(
            err.starts_with("gsart: ") && err.contains(flag) && err.lines().count() == 1,
            "{all:?}: {err}"
        );
        assert!(!err.contains("missing_dir_is_not_read"), "{err}");
        assert!(!ok_out.exists(), "the probe leaves no file behind");
    }
    let (ok, _, err) = gsart(&["bench", "--json", missing_s]);
    assert!(
        !ok && err.contains("--json") && err.contains("does not exist"),
        "{err}"
    );
}

/// `gsart bench --seq` on a small synthetic laptop: one table row with the metrics and
/// the joints in issue #4's bar, and the same row in the JSON report.
#[test]
fn bench_reports_a_sequence_with_its_joints_in_the_bar() {
    let dir = tmp("bench");
    let seq = synth_laptop(&dir, 4, 512);
    let json = dir.join("bench.json");
    let (ok, table, err) = gsart(&[
        "bench",
        "--quality",
        "fast",
        "--seq",
        seq.to_str().unwrap(),
        "--json",
        json.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    let header = table
        .lines()
        .find(|l| l.starts_with("| run "))
        .expect(&table);
    assert!(
        header.trim_end().ends_with("| joints in the bar |"),
        "{table}"
    );
    let row = table.lines().find(|l| l.contains("laptop")).expect(&table);
    let cells: Vec<&str> = row.split('|').map(str::trim).collect();
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let rows = report["rows"].as_array().unwrap();
    assert_eq!(rows.len(), 1, "{report}");
    let bar = &rows[0]["joints_within_bar"];
    assert_eq!(bar[1], 1, "the laptop has one joint: {report}");
    let within = bar[0].as_u64().unwrap();
    assert!(within <= 1, "{report}");
    assert_eq!(cells[cells.len() - 2], format!("{within} of 1"), "{row}");
    assert!(rows[0]["mean_ri"].as_f64().unwrap() > 0.5, "{report}");
}

#[test]
fn the_urdf_comes_with_its_link_meshes_or_boxes() {
    let dir = tmp("urdf");
    let seq = synth_laptop(&dir, 4, 512);
    let out = dir.join("r.json");
    let fit = |urdf: &Path, geometry: &str| {
        let (ok, _, err) = gsart(&[
            "fit",
            seq.to_str().unwrap(),
            "--quality",
            "fast",
            "--parts",
            "2..3",
            "--out",
            out.to_str().unwrap(),
            "--urdf",
            urdf.to_str().unwrap(),
            "--urdf-geometry",
            geometry,
            "--quiet",
        ]);
        assert!(ok, "{err}");
        err
    };
    let urdf = dir.join("lap.urdf");
    let err = fit(&urdf, "hull");
    let text = std::fs::read_to_string(&urdf).unwrap();
    let parts = serde_json::from_str::<serde_json::Value>(&std::fs::read_to_string(&out).unwrap())
        .unwrap()["parts"]
        .as_u64()
        .unwrap() as usize;
    assert!(
        err.contains(&format!("and {parts} link meshes in")),
        "{err}"
    );
    for p in 0..parts {
        let name = format!("lap_meshes/part_{p}.stl");
        assert!(
            text.contains(&format!("<mesh filename=\"{name}\"/>")),
            "{text}"
        );
        // A binary STL: 80-byte header, a count, 50 bytes a triangle.
        let stl = std::fs::read(dir.join(&name)).unwrap();
        let n = u32::from_le_bytes(stl[80..84].try_into().unwrap()) as usize;
        assert!(
            n >= 4 && stl.len() == 84 + 50 * n,
            "{name}: {} bytes, {n} triangles",
            stl.len()
        );
    }
    assert!(!text.contains("<box"), "{text}");
    let boxes = dir.join("boxes.urdf");
    fit(&boxes, "box");
    let text = std::fs::read_to_string(&boxes).unwrap();
    assert_eq!(text.matches("<box size=").count(), 2 * parts, "{text}");
    assert!(!dir.join("boxes_meshes").exists());
    let (ok, _, err) = gsart(&[
        "fit",
        seq.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--urdf-geometry",
        "ball",
    ]);
    assert!(!ok && err.contains("ball"), "{err}");
}

/// `gsart fit` refuses `flag value` before reading its input, naming the flag.
fn fit_refuses(name: &str, flag: &str, value: &str) {
    let out = tmp(name).join("r.json");
    let (ok, _, err) = gsart(&[
        "fit",
        "missing_dir_is_not_read",
        flag,
        value,
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(!ok, "{flag} {value} accepted");
    assert!(err.starts_with("gsart: ") && err.contains(flag), "{err}");
}

#[test]
fn restarts_must_be_one_to_sixteen() {
    fit_refuses("restarts", "--restarts", "0");
    fit_refuses("restarts", "--restarts", "17");
}

#[test]
fn key_frames_must_be_zero_or_at_least_two() {
    fit_refuses("key_frames", "--key-frames", "1");
}

/// A sequence longer than `--key-frames` is fitted on its key frames and the others
/// tracked: every frame is in the result and in the segmented PLYs, and the note says so.
#[test]
fn a_long_sequence_is_fitted_on_key_frames() {
    let dir = tmp("key_frames_fit");
    let seq = synth_laptop(&dir, 8, 512);
    let (out, plys) = (dir.join("r.json"), dir.join("ply"));
    let (ok, _, err) = gsart(&[
        "fit",
        seq.to_str().unwrap(),
        "--quality",
        "fast",
        "--parts",
        "2..3",
        "--key-frames",
        "4",
        "--out",
        out.to_str().unwrap(),
        "--ply-out",
        plys.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    assert!(
        err.contains("long sequence: Steps 1–3 fitted 4 key frames (0, 2, 5, 7); the other 4 frames were tracked"),
        "{err}"
    );
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    assert_eq!(r["frames"], 8);
    assert_eq!(r["info"]["key_frames"]["tracked"], 4);
    assert_eq!(std::fs::read_dir(&plys).unwrap().count(), 8);
}

#[test]
fn a_reader_that_closes_the_pipe_early_is_not_a_crash() {
    // `gsart eval … | head -1`: the rest of the output is not wanted, and `println!`
    // would panic on the closed pipe (exit code 101).
    let dir = tmp("pipe");
    let (seq, result) = laptop_truth(&dir);
    let mut child = Command::new(env!("CARGO_BIN_EXE_gsart"))
        .args(["eval", result.to_str().unwrap(), seq.to_str().unwrap()])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("run gsart");
    drop(child.stdout.take());
    let out = child.wait_with_output().expect("wait for gsart");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{:?}: {err}", out.status);
    assert!(!err.contains("panicked"), "{err}");
}

/// A balanced fit whose model leaves more than `pipeline::RETRY_UNEXPLAINED` of the
/// points unexplained is done once more from `pipeline::retry_seed`, and the kept
/// attempt is the one the second look's rule picks, and when that still leaves more
/// than the bound the fit is done a third time from the last frame
/// (`pipeline::third_wanted`); a well explained fit is not done again. The procedural
/// cabinet (generator seed 0, 10 × 2048) at m = 3–4 leaves 1.35 % from fit seed 0; the
/// laptop 0.27 %.
#[test]
fn a_poorly_explained_balanced_fit_is_done_again_from_another_seed() {
    let dir = tmp("retry");
    let fit = |kind: &str| -> serde_json::Value {
        let seq = dir.join(kind);
        let (ok, _, err) = gsart(&["synth", kind, "--seed", "0", "--out", seq.to_str().unwrap()]);
        assert!(ok, "{err}");
        let out = dir.join(format!("{kind}.json"));
        let (ok, _, err) = gsart(&[
            "fit",
            seq.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--parts",
            "3..4",
        ]);
        assert!(ok, "{err}");
        assert_eq!(
            err.contains("note: second attempt"),
            kind == "cabinet",
            "{err}"
        );
        // The progress bar says when the whole fit starts again, once per attempt.
        for n in [2, 3] {
            assert_eq!(
                err.matches(&format!("attempt {n}: the model so far leaves much"))
                    .count(),
                usize::from(kind == "cabinet"),
                "{err}"
            );
        }
        assert!(!err.contains("attempt 4:"), "{err}");
        // The bar follows Step 1 over both part counts, to the end of every attempt's.
        let attempts = if kind == "cabinet" { 3 } else { 1 };
        assert!(err.contains("0/2 part counts done, m = 3"), "{err}");
        assert!(
            err.matches("2/2 part counts done").count() >= attempts,
            "{err}"
        );
        serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap()
    };
    let cabinet = fit("cabinet");
    let info = &cabinet["info"];
    let retry = &info["retry"];
    let (s1, u1) = (
        retry["first"][0].as_u64(),
        retry["first"][1].as_f64().unwrap(),
    );
    let (s2, u2) = (
        retry["second"][0].as_u64(),
        retry["second"][1].as_f64().unwrap(),
    );
    assert_eq!(s1, Some(0), "{retry}");
    assert_eq!(s2, Some(gsart::pipeline::retry_seed(0)), "{retry}");
    assert!(u1 > gsart::pipeline::RETRY_UNEXPLAINED, "{retry}");
    let second = u1 > gsart::pipeline::SECOND_LOOK_RATIO * u2;
    assert_eq!(retry["taken"].as_u64(), if second { s2 } else { s1 });
    let secs = retry["step1_seconds"]
        .as_array()
        .expect("both attempts' Step-1 times");
    assert!(secs.len() == 2 && secs.iter().all(|t| t.as_f64().is_some_and(|t| t > 0.0)));
    let kept = info["unexplained"].as_f64().unwrap();
    let notes = info["notes"].as_array().unwrap();
    assert!(notes
        .iter()
        .any(|n| n.as_str().is_some_and(|n| n.starts_with("second attempt"))));
    // The attempt kept still leaves more than the bound unexplained, so the fit was done
    // a third time from the last frame (`pipeline::third_wanted`), kept by the same rule.
    let third = &info["third"];
    let (k, u3) = (
        third["kept"].as_f64().unwrap(),
        third["third"].as_f64().unwrap(),
    );
    assert_eq!(k, if second { u2 } else { u1 }, "{third}");
    let take = k > gsart::pipeline::SECOND_LOOK_RATIO * u3;
    assert_eq!(third["taken"], if take { "third" } else { "kept" });
    assert_eq!(kept, if take { u3 } else { k });
    assert!(third["step1_seconds"].as_f64().is_some_and(|t| t > 0.0));
    let canonical = cabinet["canonical_frame"].as_u64().unwrap();
    assert_eq!(canonical, if take { 9 } else { 0 });
    assert!(notes
        .iter()
        .any(|n| n.as_str().is_some_and(|n| n.starts_with("third attempt"))));
    let laptop = fit("laptop");
    assert!(laptop["info"]["unexplained"].as_f64().unwrap() <= gsart::pipeline::RETRY_UNEXPLAINED);
    assert!(laptop["info"].get("retry").is_none());
}

/// `gsart synth --noise/--outliers` writes perturbed frames and says so in gt.json;
/// out-of-range values are refused with the reason.
#[test]
fn synth_adds_sensor_noise_and_flying_pixels() {
    let dir = tmp("synth_noise");
    let seq = dir.join("laptop");
    let args = |noise: &str, outliers: &str| {
        gsart(&[
            "synth",
            "laptop",
            "--out",
            seq.to_str().unwrap(),
            "--frames",
            "2",
            "--points",
            "256",
            "--noise",
            noise,
            "--outliers",
            outliers,
        ])
    };
    let (ok, _, err) = args("0.003", "0.01");
    assert!(ok, "{err}");
    let gt: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(seq.join("gt.json")).unwrap()).unwrap();
    assert_eq!(gt["sensor_noise"]["sigma"], 0.003);
    assert_eq!(gt["sensor_noise"]["outlier_fraction"], 0.01);
    let (ok, _, err) = args("0.5", "0");
    assert!(
        !ok && err.contains("noise must be between 0 and 0.1"),
        "{err}"
    );
    let (ok, _, err) = args("0", "0.9");
    assert!(
        !ok && err.contains("outliers must be between 0 and 0.5"),
        "{err}"
    );
}

/// Flying pixels (`geom::outliers`) are left out of the fit, counted in
/// `info.isolated` and named in a note, and labelled like every other point.
#[test]
fn flying_pixels_are_left_out_of_the_fit_and_labelled() {
    let dir = tmp("flying_pixels");
    let seq = dir.join("arm");
    let (ok, _, err) = gsart(&[
        "synth",
        "arm",
        "--out",
        seq.to_str().unwrap(),
        "--frames",
        "3",
        "--outliers",
        "0.02",
    ]);
    assert!(ok, "{err}");
    let out = dir.join("r.json");
    let (ok, _, err) = gsart(&[
        "fit",
        seq.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--quality",
        "fast",
        "--parts",
        "3..3",
    ]);
    assert!(ok, "{err}");
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    let counts = |key: &str| -> Vec<u64> {
        r["info"][key]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_u64().unwrap())
            .collect()
    };
    let (isolated, working) = (counts("isolated"), counts("working_sizes"));
    // About 82 of each frame's 4096 points were thrown 5–15 % of the size off; most
    // land more than 5 point spacings from the arm.
    assert_eq!(isolated.len(), 3);
    for (i, w) in isolated.iter().zip(&working) {
        assert!((30..=90).contains(i), "{isolated:?}");
        assert_eq!(i + w, 4096, "{isolated:?} {working:?}");
    }
    let notes = r["info"]["notes"].to_string();
    assert!(notes.contains("flying pixels"), "{notes}");
    assert!(!notes.contains("downsampled"), "{notes}");
    for frame in r["labels"].as_array().unwrap() {
        assert_eq!(frame.as_array().unwrap().len(), 4096);
    }
}
