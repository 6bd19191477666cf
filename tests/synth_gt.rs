//! Ground-truth consistency of the procedural generator for every object kind:
//! the joint model reproduces the poses, points move rigidly with their part's pose,
//! normalisation, occlusion subsets, held-out poses, determinism and gt.json round trip.

use glam::{DMat3, DMat4, DQuat, DVec3, Vec3};
use gsart::geom::se3::rigid_inverse;
use gsart::io::gt::{GroundTruth, JointType};
use gsart::io::sequence::Frame;
use gsart::synth::shapes::surface_distance;
use gsart::synth::{generate, gt_json, ObjectKind, SynthOptions, SynthOutput};

fn opts(kind: ObjectKind, seed: u64) -> SynthOptions {
    SynthOptions {
        seed,
        ..SynthOptions::new(kind)
    }
}

fn gen(o: &SynthOptions) -> SynthOutput {
    match generate(o) {
        Ok(x) => x,
        Err(e) => panic!("generate {o:?}: {e}"),
    }
}

/// Joint motion from the gt alone (parent-frame axis/pivot recovered at frame 0).
fn motion(ty: JointType, axis: DVec3, pivot: DVec3, q: f64) -> DMat4 {
    match ty {
        JointType::Revolute => {
            DMat4::from_translation(pivot)
                * DMat4::from_quat(DQuat::from_axis_angle(axis, q))
                * DMat4::from_translation(-pivot)
        }
        JointType::Prismatic => DMat4::from_translation(axis * q),
    }
}

/// Rebuild every pose from the parent pose, the joint's frame-0 axis/pivot and its
/// states; returns the largest entry error over frames and held-out poses.
fn joint_model_error(gt: &GroundTruth) -> f64 {
    let mut worst = 0.0f64;
    for (p, j) in gt.joints.iter().enumerate() {
        let Some(j) = j else {
            assert_eq!(p, 0, "only the root has no joint");
            continue;
        };
        assert_eq!(j.part, p);
        assert_eq!(gt.parent[p], j.parent_part as i64);
        assert!(j.parent_part < p, "parents precede children");
        assert!((j.axis_world_frame0.length() - 1.0).abs() < 1e-9);
        let par0 = gt.poses[0][j.parent_part];
        let inv_par0 = rigid_inverse(&par0);
        let axis = DMat3::from_mat4(inv_par0) * j.axis_world_frame0;
        let pivot = inv_par0.transform_point3(j.pivot_world_frame0);
        let m0 = motion(j.joint_type, axis, pivot, j.states[0]);
        // child_in_parent_at_zero from frame 0
        let c0 = rigid_inverse(&m0) * inv_par0 * gt.poses[0][p];
        let mut check = |parent: DMat4, child: DMat4, q: f64| {
            let pred = parent * motion(j.joint_type, axis, pivot, q) * c0;
            let e = (pred - child)
                .to_cols_array()
                .iter()
                .fold(0.0f64, |a, v| a.max(v.abs()));
            worst = worst.max(e);
        };
        for t in 0..gt.num_frames() {
            check(gt.poses[t][j.parent_part], gt.poses[t][p], j.states[t]);
        }
        for (h, poses) in gt.heldout_poses.iter().enumerate() {
            check(poses[j.parent_part], poses[p], j.heldout_states[h]);
        }
    }
    worst
}

fn bbox(frames: &[Frame]) -> (Vec3, Vec3) {
    let mut lo = Vec3::splat(f32::INFINITY);
    let mut hi = Vec3::splat(f32::NEG_INFINITY);
    for f in frames {
        for p in &f.points {
            lo = lo.min(*p);
            hi = hi.max(*p);
        }
    }
    (lo, hi)
}

fn labels(f: &Frame) -> &[u32] {
    f.labels.as_deref().unwrap_or(&[])
}

#[test]
fn every_kind_has_consistent_ground_truth() {
    // Each object as designed and in a random orientation (`random_rotation`).
    for (kind, random_rotation) in ObjectKind::ALL
        .into_iter()
        .flat_map(|k| [(k, false), (k, true)])
    {
        let o = SynthOptions {
            random_rotation,
            ..opts(kind, 7)
        };
        let out = gen(&o);
        let gt = &out.gt;
        let model = kind.model();
        let np = gt.num_parts;
        assert_eq!(np, model.num_parts());
        match kind {
            ObjectKind::Laptop => assert_eq!(np, 2),
            ObjectKind::Cabinet => {
                assert_eq!(np, 4);
                let prismatic = gt
                    .joints
                    .iter()
                    .flatten()
                    .filter(|j| j.joint_type == JointType::Prismatic)
                    .count();
                assert_eq!(prismatic, 2);
            }
            ObjectKind::Arm => assert_eq!(np, 7),
            ObjectKind::Hand => assert!(np >= 12),
            ObjectKind::Quadruped => assert!(np >= 9),
        }
        assert_eq!(gt.num_frames(), o.frames);
        assert_eq!(out.sequence.frames.len(), o.frames);
        assert_eq!(out.heldout.len(), o.heldout);
        assert_eq!(gt.heldout_poses.len(), o.heldout);

        // 1. joint model
        let err = joint_model_error(gt);
        assert!(err < 1e-6, "{kind}: joint model error {err}");

        // 2. normalisation
        let (lo, hi) = bbox(&out.sequence.frames);
        assert!(
            lo.min_element() >= -0.5 && hi.max_element() <= 0.5,
            "{kind}: {lo} {hi}"
        );
        let longest = (hi - lo).max_element();
        assert!(
            (longest - 1.0).abs() < 1e-3,
            "{kind}: longest side {longest}"
        );

        // 3. labels cover all parts, counts right
        for f in out.sequence.frames.iter().chain(&out.heldout) {
            assert_eq!(f.points.len(), o.points);
            let l = labels(f);
            assert_eq!(l.len(), f.points.len());
            for p in 0..np as u32 {
                assert!(l.contains(&p), "{kind}: part {p} missing in {}", f.name);
            }
        }

        // 4. points lie exactly on their part's surface (model shapes, part frame)
        let s = out.info.scale;
        let mut worst = 0.0f64;
        let held = gt.heldout_poses.iter();
        for (f, poses) in out
            .sequence
            .frames
            .iter()
            .zip(&gt.poses)
            .chain(out.heldout.iter().zip(held))
        {
            for (x, &l) in f.points.iter().zip(labels(f)) {
                let p = l as usize;
                let y = rigid_inverse(&poses[p]).transform_point3(x.as_dvec3()) / s;
                let d = model.parts[p]
                    .prims
                    .iter()
                    .map(|q| surface_distance(q, y))
                    .fold(f64::INFINITY, f64::min);
                worst = worst.max(d * s);
            }
        }
        // f32 coordinates: ~1e-7 of the unit object
        assert!(worst < 1e-5, "{kind}: point off its surface by {worst}");

        // 5. mapped back to frame 0 with poses[0][p] inv(poses[t][p]), part points land
        //    on the frame-0 cloud of the same part (no correspondence, so nearest point)
        let f0 = &out.sequence.frames[0];
        for t in 1..gt.num_frames() {
            let ft = &out.sequence.frames[t];
            for p in 0..np {
                let back = gt.poses[0][p] * rigid_inverse(&gt.poses[t][p]);
                let ref0: Vec<DVec3> = f0
                    .points
                    .iter()
                    .zip(labels(f0))
                    .filter(|(_, &l)| l as usize == p)
                    .map(|(x, _)| x.as_dvec3())
                    .collect();
                let mut sum = 0.0;
                let mut n = 0;
                for (x, _) in ft
                    .points
                    .iter()
                    .zip(labels(ft))
                    .filter(|(_, &l)| l as usize == p)
                {
                    let y = back.transform_point3(x.as_dvec3());
                    let d = ref0
                        .iter()
                        .map(|r| r.distance_squared(y))
                        .fold(f64::INFINITY, f64::min)
                        .sqrt();
                    sum += d;
                    n += 1;
                }
                let mean = sum / n.max(1) as f64;
                // baseline: spacing of the frame-0 samples themselves (nearest other point)
                let mut self_sum = 0.0;
                for (i, a) in ref0.iter().enumerate() {
                    let d = ref0
                        .iter()
                        .enumerate()
                        .filter(|(k, _)| *k != i)
                        .map(|(_, r)| r.distance_squared(*a))
                        .fold(f64::INFINITY, f64::min)
                        .sqrt();
                    self_sum += d;
                }
                let spacing = self_sum / ref0.len().max(1) as f64;
                assert!(
                    mean < 2.0 * spacing + 1e-3,
                    "{kind}: frame {t} part {p} mean back-mapped distance {mean}, spacing {spacing}"
                );
            }
        }

        // 6. held-out poses share frame 0's root pose
        for poses in &gt.heldout_poses {
            assert!(poses[0].abs_diff_eq(gt.poses[0][0], 1e-12));
        }
        // every joint moves over the sequence
        for j in gt.joints.iter().flatten() {
            let mx = j.states.iter().cloned().fold(f64::MIN, f64::max);
            let mn = j.states.iter().cloned().fold(f64::MAX, f64::min);
            assert!(mx - mn > 1e-3, "{kind}: joint {} does not move", j.name);
            assert_eq!(j.heldout_states.len(), o.heldout);
        }
    }
}

/// Points of a part must not be buried inside a non-adjacent part, nor inside an
/// adjacent one away from their shared revolute pivot.
#[test]
fn no_gross_self_intersection() {
    for kind in ObjectKind::ALL {
        let model = kind.model();
        for seed in 0..3 {
            let out = gen(&SynthOptions {
                points: 2048,
                ..opts(kind, seed)
            });
            let s = out.info.scale;
            let gt = &out.gt;
            let held = gt.heldout_poses.iter();
            let mut buried = 0usize;
            let mut total = 0usize;
            for (f, poses) in out
                .sequence
                .frames
                .iter()
                .zip(&gt.poses)
                .chain(out.heldout.iter().zip(held))
            {
                let inv: Vec<DMat4> = poses.iter().map(rigid_inverse).collect();
                for (x, &l) in f.points.iter().zip(labels(f)) {
                    let p = l as usize;
                    total += 1;
                    for (q, part) in model.parts.iter().enumerate() {
                        if q == p {
                            continue;
                        }
                        let adjacent =
                            (part.parent == Some(p)) || (model.parts[p].parent == Some(q));
                        if adjacent {
                            let child = if part.parent == Some(p) { q } else { p };
                            let Some(j) = gt.joints[child].as_ref() else {
                                continue;
                            };
                            if j.joint_type == JointType::Revolute {
                                // pivot of that joint in the world at this pose
                                let par = gt.parent[child] as usize;
                                let piv_par = rigid_inverse(&gt.poses[0][par])
                                    .transform_point3(j.pivot_world_frame0);
                                let piv = poses[par].transform_point3(piv_par);
                                if piv.distance(x.as_dvec3()) < 0.1 {
                                    continue;
                                }
                            }
                        }
                        let y = inv[q].transform_point3(x.as_dvec3()) / s;
                        if part.prims.iter().any(|pr| pr.contains(y, 0.004)) {
                            buried += 1;
                            break;
                        }
                    }
                }
            }
            let frac = buried as f64 / total as f64;
            assert!(
                frac < 0.002,
                "{kind} seed {seed}: {buried}/{total} points inside other parts"
            );
        }
    }
}

#[test]
fn occluded_frames_are_strict_visible_subsets() {
    for kind in ObjectKind::ALL {
        let full = gen(&opts(kind, 11));
        let occ = gen(&SynthOptions {
            occluded: true,
            ..opts(kind, 11)
        });
        assert_eq!(occ.gt.variant, "occluded");
        assert_eq!(
            occ.info.occlusion_method,
            Some(gsart::synth::occlusion::Method::HiddenPointRemoval)
        );
        assert_eq!(occ.info.cameras.len(), full.sequence.frames.len());
        for (t, (f, o)) in full
            .sequence
            .frames
            .iter()
            .zip(&occ.sequence.frames)
            .enumerate()
        {
            let idx = &occ.info.visible[t];
            assert_eq!(idx.len(), o.points.len());
            assert!(idx.windows(2).all(|w| w[0] < w[1]), "same order");
            for (k, &i) in idx.iter().enumerate() {
                assert_eq!(o.points[k], f.points[i as usize]);
                assert_eq!(labels(o)[k], labels(f)[i as usize]);
            }
            let frac = o.points.len() as f64 / f.points.len() as f64;
            assert!(
                frac < 0.9 && frac > 0.15,
                "{kind} frame {t}: visible fraction {frac}"
            );
            let cam = occ.info.cameras[t];
            assert!((cam.length() - 2.0).abs() < 1e-9);
        }
        // held-out clouds stay full; poses identical to the full variant
        for (a, b) in full.heldout.iter().zip(&occ.heldout) {
            assert_eq!(a.points, b.points);
        }
        assert_eq!(full.gt.poses, occ.gt.poses);
    }
}

#[test]
fn visible_points_face_the_camera() {
    // Seen from a camera, a visible point should mostly be nearer than the object's
    // centre plane; hidden ones mostly farther.
    let full = gen(&opts(ObjectKind::Cabinet, 3));
    let occ = gen(&SynthOptions {
        occluded: true,
        ..opts(ObjectKind::Cabinet, 3)
    });
    for (t, f) in full.sequence.frames.iter().enumerate() {
        let cam = occ.info.cameras[t];
        let dir = cam.normalize();
        let mut vis = vec![false; f.points.len()];
        for &i in &occ.info.visible[t] {
            vis[i as usize] = true;
        }
        let mean = |want: bool| {
            let v: Vec<f64> = f
                .points
                .iter()
                .zip(&vis)
                .filter(|(_, &x)| x == want)
                .map(|(p, _)| p.as_dvec3().dot(dir))
                .collect();
            v.iter().sum::<f64>() / v.len().max(1) as f64
        };
        assert!(mean(true) > mean(false) + 0.1, "frame {t}");
    }
}

#[test]
fn deterministic_for_a_seed() {
    for kind in ObjectKind::ALL {
        let a = gen(&SynthOptions {
            occluded: true,
            ..opts(kind, 5)
        });
        let b = gen(&SynthOptions {
            occluded: true,
            ..opts(kind, 5)
        });
        let c = gen(&SynthOptions {
            occluded: true,
            ..opts(kind, 6)
        });
        for (x, y) in a.sequence.frames.iter().zip(&b.sequence.frames) {
            assert_eq!(x.points, y.points);
            assert_eq!(x.labels, y.labels);
        }
        assert_eq!(a.gt.poses, b.gt.poses);
        assert_eq!(a.gt.to_json(), b.gt.to_json());
        assert_eq!(gt_json(&a), gt_json(&b));
        assert_ne!(a.sequence.frames[0].points, c.sequence.frames[0].points);
        assert_ne!(a.gt.poses, c.gt.poses);
    }
}

fn assert_same_gt(a: &GroundTruth, b: &GroundTruth) {
    assert_eq!(a.sequence, b.sequence);
    assert_eq!(a.num_parts, b.num_parts);
    assert_eq!(a.parent, b.parent);
    assert_eq!(a.poses, b.poses);
    assert_eq!(a.heldout_poses, b.heldout_poses);
    assert_eq!(a.heldout_frames, b.heldout_frames);
    assert_eq!(a.frames, b.frames);
    assert_eq!(a.variant, b.variant);
    for (x, y) in a.joints.iter().zip(&b.joints) {
        match (x, y) {
            (None, None) => {}
            (Some(x), Some(y)) => {
                assert_eq!(x.part, y.part);
                assert_eq!(x.parent_part, y.parent_part);
                assert_eq!(x.name, y.name);
                assert_eq!(x.joint_type, y.joint_type);
                assert_eq!(x.axis_world_frame0, y.axis_world_frame0);
                assert_eq!(x.pivot_world_frame0, y.pivot_world_frame0);
                assert_eq!(x.states, y.states);
                assert_eq!(x.heldout_states, y.heldout_states);
            }
            _ => panic!("joint presence differs"),
        }
    }
}

#[test]
fn gt_json_round_trips() {
    for kind in ObjectKind::ALL {
        let out = gen(&SynthOptions {
            occluded: true,
            ..opts(kind, 2)
        });
        let plain = GroundTruth::from_json(&out.gt.to_json(), "gt.json").unwrap();
        assert_same_gt(&out.gt, &plain);
        let rich_text = gt_json(&out);
        let rich = GroundTruth::from_json(&rich_text, "gt.json").unwrap();
        assert_same_gt(&out.gt, &rich);
        // the extra benchmark keys are there and consistent
        let v: serde_json::Value = serde_json::from_str(&rich_text).unwrap();
        assert_eq!(
            v["parts"].as_array().map(|a| a.len()),
            Some(out.gt.num_parts)
        );
        assert_eq!(
            v["points_per_frame"][0].as_u64(),
            Some(out.sequence.frames[0].points.len() as u64)
        );
        assert!(v["occlusion"]["camera_positions"].is_array());
        let j1 = &v["joints"][1];
        assert!(j1["axis_parent"].is_array() && j1["child_in_parent_at_zero"].is_array());
        // joint model with the parent-frame keys of the file
        let cip = &j1["child_in_parent_at_zero"];
        let rows: [[f64; 4]; 4] = serde_json::from_value(cip.clone()).unwrap();
        let c = gsart::geom::se3::from_nested(&rows);
        let axis: [f64; 3] = serde_json::from_value(j1["axis_parent"].clone()).unwrap();
        let pivot: [f64; 3] = serde_json::from_value(j1["pivot_parent"].clone()).unwrap();
        let j = out.gt.joints[1].as_ref().unwrap();
        let par = j.parent_part;
        for t in 0..out.gt.num_frames() {
            let pred = out.gt.poses[t][par]
                * motion(
                    j.joint_type,
                    DVec3::from(axis),
                    DVec3::from(pivot),
                    j.states[t],
                )
                * c;
            assert!(
                pred.abs_diff_eq(out.gt.poses[t][1], 1e-9),
                "{kind} frame {t}"
            );
        }
    }
}

#[test]
fn options_are_validated_and_names_parse() {
    for name in gsart::synth::example_names() {
        let k: ObjectKind = name.parse().unwrap();
        assert_eq!(k.to_string(), *name);
    }
    assert!("robot".parse::<ObjectKind>().is_err());
    assert!(generate(&SynthOptions {
        frames: 1,
        ..SynthOptions::default()
    })
    .is_err());
    assert!(generate(&SynthOptions {
        points: 3,
        ..SynthOptions::default()
    })
    .is_err());
    let small = gen(&SynthOptions {
        frames: 2,
        points: 64,
        heldout: 0,
        ..SynthOptions::default()
    });
    assert_eq!(small.sequence.frames.len(), 2);
    assert!(small.heldout.is_empty() && small.gt.heldout_poses.is_empty());
}

#[test]
fn sensor_noise_and_flying_pixels_perturb_the_frames_only() {
    let clean = gen(&opts(ObjectKind::Laptop, 3));
    let (sigma, share) = (0.004, 0.02);
    let noisy = gen(&SynthOptions {
        noise: sigma,
        outliers: share,
        ..opts(ObjectKind::Laptop, 3)
    });
    // The same object, poses, labels and held-out clouds: only the frame points move.
    assert_same_gt(&clean.gt, &noisy.gt);
    for (a, b) in clean.heldout.iter().zip(&noisy.heldout) {
        assert_eq!(a.points, b.points);
    }
    let (mut offsets, mut thrown, mut n) = (Vec::new(), 0usize, 0usize);
    for (a, b) in clean.sequence.frames.iter().zip(&noisy.sequence.frames) {
        assert_eq!(a.labels, b.labels);
        assert_eq!(a.points.len(), b.points.len());
        for (p, q) in a.points.iter().zip(&b.points) {
            let d = (*q - *p).as_dvec3();
            n += 1;
            if d.length() > 0.04 {
                // A flying pixel: 5–15 % of the size off, plus the noise.
                assert!(d.length() < 0.15 + 6.0 * sigma, "{d}");
                thrown += 1;
            } else {
                offsets.extend([d.x, d.y, d.z]);
            }
        }
    }
    let rms = (offsets.iter().map(|x| x * x).sum::<f64>() / offsets.len() as f64).sqrt();
    assert!(
        (rms - sigma).abs() < 0.05 * sigma,
        "noise rms {rms} for σ {sigma}"
    );
    let got = thrown as f64 / n as f64;
    assert!((got - share).abs() < 0.005, "{thrown} of {n} thrown");
    // Deterministic for a seed, and written down in gt.json.
    let again = gen(&SynthOptions {
        noise: sigma,
        outliers: share,
        ..opts(ObjectKind::Laptop, 3)
    });
    assert_eq!(
        noisy.sequence.frames[4].points,
        again.sequence.frames[4].points
    );
    let gt: serde_json::Value = serde_json::from_str(&gt_json(&noisy)).unwrap();
    assert_eq!(gt["sensor_noise"]["sigma"], sigma);
    assert_eq!(gt["sensor_noise"]["outlier_fraction"], share);
    let gt_clean: serde_json::Value = serde_json::from_str(&gt_json(&clean)).unwrap();
    assert!(gt_clean.get("sensor_noise").is_none());
    // Out-of-range settings are refused.
    for (noise, outliers) in [
        (-0.1, 0.0),
        (0.2, 0.0),
        (f64::NAN, 0.0),
        (0.0, 0.6),
        (0.0, -1.0),
    ] {
        let e = generate(&SynthOptions {
            noise,
            outliers,
            ..SynthOptions::default()
        });
        assert!(e.is_err(), "noise {noise}, outliers {outliers} accepted");
    }
}

/// `SynthOptions::turn`: frame t is the still object's frame turned 4t° about z, points
/// and poses alike (frame 0 and the held-out poses unturned), recorded in `gt.json`.
#[test]
fn a_turntable_turns_every_frame_its_points_and_poses() {
    let still = gen(&opts(ObjectKind::Quadruped, 3));
    let turned = gen(&SynthOptions {
        turn: 4.0,
        ..opts(ObjectKind::Quadruped, 3)
    });
    for (t, (a, b)) in still
        .sequence
        .frames
        .iter()
        .zip(&turned.sequence.frames)
        .enumerate()
    {
        let w = DMat4::from_rotation_z((4.0 * t as f64).to_radians());
        assert_eq!(a.points.len(), b.points.len());
        for (p, q) in a.points.iter().zip(&b.points) {
            assert!(w.transform_point3(p.as_dvec3()).distance(q.as_dvec3()) < 1e-5);
        }
        assert_eq!(a.labels, b.labels);
        for (p, q) in still.gt.poses[t].iter().zip(&turned.gt.poses[t]) {
            assert!((w * *p).abs_diff_eq(*q, 1e-12), "frame {t}");
        }
    }
    assert_eq!(still.gt.heldout_poses, turned.gt.heldout_poses);
    let json: serde_json::Value = serde_json::from_str(&gt_json(&turned)).unwrap();
    assert_eq!(json["base_motion"]["degrees_per_frame"], 4.0);
    let json: serde_json::Value = serde_json::from_str(&gt_json(&still)).unwrap();
    assert_eq!(json["base_motion"], "none");
    assert!(generate(&SynthOptions {
        turn: 31.0,
        ..opts(ObjectKind::Laptop, 0)
    })
    .is_err());
}

/// `SynthOptions::random_rotation`: every frame is the designed object's frame turned by
/// the drawn rotation (the same samples, normalised again), the joint axes turn with it,
/// the rotation is uniform-looking across seeds, and `gt.json` records it.
#[test]
fn a_random_rotation_turns_the_whole_object() {
    let still = gen(&opts(ObjectKind::Arm, 2));
    let turned = gen(&SynthOptions {
        random_rotation: true,
        ..opts(ObjectKind::Arm, 2)
    });
    let r = turned.info.rotation.expect("the rotation drawn");
    assert!(still.info.rotation.is_none());
    assert!((r.determinant() - 1.0).abs() < 1e-12);
    assert!((r * r.transpose()).abs_diff_eq(DMat3::IDENTITY, 1e-12));
    // Design coordinates x: still p = s (x − c), turned q = s' (R x − c').
    let (s, c) = (still.info.scale, still.info.center);
    let (s2, c2) = (turned.info.scale, turned.info.center);
    let design_to_turned = |p: DVec3| s2 * (r * (p / s + c) - c2);
    for (a, b) in still.sequence.frames.iter().zip(&turned.sequence.frames) {
        assert_eq!(a.labels, b.labels);
        for (p, q) in a.points.iter().zip(&b.points) {
            let e = design_to_turned(p.as_dvec3()).distance(q.as_dvec3());
            assert!(e < 1e-5, "{}: {e}", b.name);
        }
    }
    for (a, b) in still.gt.joints.iter().zip(&turned.gt.joints) {
        let (Some(a), Some(b)) = (a, b) else {
            assert!(a.is_none() && b.is_none());
            continue;
        };
        assert!((r * a.axis_world_frame0).distance(b.axis_world_frame0) < 1e-9);
        let pivot = design_to_turned(a.pivot_world_frame0);
        assert!(pivot.distance(b.pivot_world_frame0) < 1e-9);
        assert_eq!(a.states, b.states, "revolute states do not scale");
    }
    // Different seeds, different orientations, none of them near the identity.
    let angles: Vec<f64> = (0..6)
        .map(|seed| {
            let o = SynthOptions {
                random_rotation: true,
                ..opts(ObjectKind::Laptop, seed)
            };
            let rot = gen(&o).info.rotation.expect("rotation");
            glam::DQuat::from_mat3(&rot).angle_between(glam::DQuat::IDENTITY)
        })
        .collect();
    assert!(angles.iter().all(|a| *a > 1e-3), "{angles:?}");
    assert!(
        angles.windows(2).all(|w| (w[0] - w[1]).abs() > 1e-6),
        "{angles:?}"
    );
    let json: serde_json::Value = serde_json::from_str(&gt_json(&turned)).unwrap();
    assert_eq!(json["random_rotation"], true);
    let m = &json["rotation"]["matrix"];
    for i in 0..3 {
        for j in 0..3 {
            let v = m[i][j].as_f64().expect("matrix entry");
            assert!((v - r.col(j)[i]).abs() < 1e-12);
        }
    }
    let json: serde_json::Value = serde_json::from_str(&gt_json(&still)).unwrap();
    assert_eq!(json["random_rotation"], false);
    assert!(json.get("rotation").is_none());
}
