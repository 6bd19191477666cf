//! Long sequences: Steps 1–3 run on evenly spaced key frames, and every other frame is
//! fitted afterwards with the articulated model they found (`kinematics::track`: its
//! root motion and joint states, started between its neighbouring key frames). Step 1's
//! time grows with the number of frames; the tracking costs a fraction of it per frame.

use glam::{DMat4, DQuat, Vec3};

use crate::geom::knn::Grid;
use crate::geom::se3::{from_row_major, to_row_major};
use crate::io::result::{moved_placement, FitResult};
use crate::io::sequence::Sequence;
use crate::kinematics::observed::{
    points_by_part, polish_frame, POLISH_GAIN, POLISH_KEEP, POLISH_ROUNDS,
};
use crate::kinematics::track::{track, Configuration, TrackOptions};
use crate::normalisation::Normalisation;
use crate::pipeline::{Control, Progress};

/// Key frames fitted on sequences longer than this (the default; `FitOptions::key_frames`).
/// Measured on 60-frame procedural sequences (balanced, generator seeds 0 and 1, CPU
/// time; joints in the bar of 5° and a pivot error of 2): the quadruped, every frame
/// 277 / 236 s with 6 / 7 of its 8 joints in the bar, 20 key frames 84 / 79 s with 8 / 5,
/// 12 key frames 51 / 41 s with 0 / 3; the arm 241 / 254 s, 66 / 260 s (a second and a
/// third attempt) and 51 / 147 s, 2 joints in the bar in all three. README, "Long
/// sequences".
pub const DEFAULT_KEY_FRAMES: usize = 20;

/// `n` frame indices of `0..k` spread evenly, the first and the last among them; every
/// frame when `k ≤ n` (or `n < 2`).
pub fn choose(k: usize, n: usize) -> Vec<usize> {
    if k <= n || n < 2 {
        return (0..k).collect();
    }
    // Rounded positions of n points spread over 0..=k−1: distinct since k > n.
    (0..n)
        .map(|i| ((i * (k - 1)) as f64 / (n - 1) as f64).round() as usize)
        .collect()
}

/// The frames `keys` of `seq`, in order.
pub fn sub_sequence(seq: &Sequence, keys: &[usize]) -> Sequence {
    Sequence {
        frames: keys.iter().map(|&t| seq.frames[t].clone()).collect(),
    }
}

/// What [`extend`] measured.
#[derive(Debug, Clone, PartialEq)]
pub struct Extension {
    pub tracked: usize,
    pub seconds: f64,
    /// Median over the key frames and over the tracked frames of each frame's squared
    /// Chamfer distance (both directions, means) to the model moved to it, in the units
    /// of the fit: a tracked frame the model follows as well as a key frame scores alike.
    pub key_chamfer: f64,
    pub tracked_chamfer: f64,
}

/// The most canonical points a tracked frame's polish moves (every n-th of a denser
/// frame). Four times the default working size: on 60 frames of 100 000 points
/// (procedural quadruped, fast) the tracking took 14.8 s with every point, 6.7 s with
/// these, 6.0 s with 4096, and recon 0.503 / 0.508 / 0.516.
const POLISH_POINTS: usize = 16384;

/// The result `key`, fitted on the frames `keys` of `seq` ([`sub_sequence`]), extended
/// to every frame of `seq`: each frame between key frames gets the root motion and
/// joint states the articulated model fits it with, started from the interpolation of
/// its neighbouring key frames' configurations; its part poses by forward kinematics
/// (on full input polished as the key frames' are), its points labelled by the nearest point of the canonical frame so moved, and the
/// Gaussians carried by their parts. `clock` gives seconds.
pub fn extend(
    seq: &Sequence,
    keys: &[usize],
    key: FitResult,
    opts: &TrackOptions,
    clock: &dyn Fn() -> f64,
    progress: &mut dyn FnMut(&Progress) -> Control,
) -> crate::Result<(FitResult, Extension)> {
    let start = clock();
    let bad = |s: String| crate::Error::InvalidArgument(format!("key frames: {s}"));
    let k = seq.frames.len();
    if key.frames != keys.len() || keys.windows(2).any(|w| w[0] >= w[1]) || keys.is_empty() {
        return Err(bad(format!(
            "{} key frames for a result of {}",
            keys.len(),
            key.frames
        )));
    }
    if keys[keys.len() - 1] >= k || keys[0] != 0 || keys[keys.len() - 1] != k - 1 {
        return Err(bad("the first and the last frame must be key frames".into()));
    }
    if key.joints.is_none() || key.root_motion.is_none() {
        return Err(bad("the result has no joints".into()));
    }
    let c_key = key.canonical_frame;
    let c = keys[c_key];
    let canonical_input = &seq.frames[c].points;
    let canonical_labels = &key.labels[c_key];
    if canonical_labels.len() != canonical_input.len() {
        return Err(bad(
            "the canonical frame's labels do not match its points".into()
        ));
    }

    // The tracking runs in fit units, like Steps 2–3.
    let norm = Normalisation::of(seq);
    let mut fit_key = key.clone();
    norm.result_to_fit(&mut fit_key);
    let fit_roots: Vec<DMat4> = fit_key
        .root_motion
        .iter()
        .flatten()
        .map(from_row_major)
        .collect();
    let fit_joints = fit_key.joints.as_ref().map_or(&[][..], |j| &j[..]);
    let to_fit =
        |pts: &[Vec3]| -> Vec<Vec3> { pts.iter().map(|&p| norm.point_to_fit(p)).collect() };
    let canonical = to_fit(canonical_input);

    let tracked: Vec<usize> = (0..k).filter(|t| keys.binary_search(t).is_err()).collect();
    let starts: Vec<Configuration> = tracked
        .iter()
        .map(|&t| {
            // keys holds 0 and k − 1, so a tracked frame lies strictly between two.
            let b = keys.partition_point(|&s| s < t);
            let (ia, ib) = (b - 1, b);
            let w = (t - keys[ia]) as f64 / (keys[ib] - keys[ia]) as f64;
            Configuration {
                root: interpolate(&fit_roots[ia], &fit_roots[ib], w),
                states: fit_joints
                    .iter()
                    .map(|j| (1.0 - w) * j.state[ia] + w * j.state[ib])
                    .collect(),
                poses: Vec::new(),
            }
        })
        .collect();
    let frames: Vec<Vec<Vec3>> = tracked
        .iter()
        .map(|&t| to_fit(&seq.frames[t].points))
        .collect();
    let mut found = track(
        &fit_key,
        &canonical,
        canonical_labels,
        &frames,
        &starts,
        opts,
        progress,
    )?;
    let occluded = key.occlusion_used().unwrap_or(true);

    // Per frame of `seq`: the index into the key result or into the tracked frames.
    enum Source {
        Key(usize),
        Tracked(usize),
    }
    let source = |t: usize| match keys.binary_search(&t) {
        Ok(i) => Source::Key(i),
        Err(_) => Source::Tracked(tracked.binary_search(&t).unwrap_or(0)),
    };
    // One pass over the frames in fit units, with one grid of each frame's points. On
    // full input Steps 2–3 polish every key frame's part poses by trimmed ICP to its
    // cloud (`observed::polish_poses`, taken where it fits clearly better): a tracked
    // frame gets the same. Its points then take the part of the nearest canonical point
    // moved to the frame, and every frame's Chamfer to the model is measured for the
    // report.
    // The polish moves at most `POLISH_POINTS` canonical points (every n-th): a dense
    // frame's hundred thousand points pose a part little better, at many times the cost.
    let stride = canonical.len().div_ceil(POLISH_POINTS).max(1);
    let (polish_points, polish_labels): (Vec<Vec3>, Vec<u32>) = canonical
        .iter()
        .zip(canonical_labels)
        .step_by(stride)
        .map(|(&p, &l)| (p, l))
        .unzip();
    let by_part = points_by_part(&polish_points, &polish_labels, fit_key.parts);
    let polish = (POLISH_ROUNDS, POLISH_KEEP, POLISH_GAIN);
    let mut bufs = (Vec::new(), Vec::new());
    let mut moved = vec![Vec3::ZERO; canonical.len()];
    let (mut model_grid, mut frame_grid) = (Grid::default(), Grid::default());
    let mut fit_poses: Vec<Vec<DMat4>> = Vec::with_capacity(k);
    let mut labels = Vec::with_capacity(k);
    let mut key_cd = Vec::with_capacity(keys.len());
    let mut tracked_cd = Vec::with_capacity(tracked.len());
    for t in 0..k {
        let key_points;
        let (pts, mut poses, key_index) = match source(t) {
            Source::Key(i) => {
                key_points = to_fit(&seq.frames[t].points);
                let poses = fit_key.poses[i].iter().map(from_row_major).collect();
                (&key_points[..], poses, Some(i))
            }
            Source::Tracked(i) => (&frames[i][..], std::mem::take(&mut found[i].poses), None),
        };
        frame_grid.rebuild(pts);
        if !occluded && key_index.is_none() && !pts.is_empty() {
            polish_frame(&mut poses, &by_part, &frame_grid, pts, polish, &mut bufs);
        }
        for ((y, x), &l) in moved.iter_mut().zip(&canonical).zip(canonical_labels) {
            *y = poses[l as usize].transform_point3(x.as_dvec3()).as_vec3();
        }
        model_grid.rebuild(&moved);
        let cd = chamfer((&moved, &model_grid), (pts, &frame_grid));
        match key_index {
            Some(i) => {
                key_cd.push(cd);
                labels.push(key.labels[i].clone());
            }
            None => {
                tracked_cd.push(cd);
                labels.push(
                    pts.iter()
                        .map(|&p| {
                            model_grid
                                .nearest(p)
                                .map_or(0, |(i, _)| canonical_labels[i as usize])
                        })
                        .collect(),
                );
            }
        }
        fit_poses.push(poses);
    }
    drop(frames);

    let mut out = FitResult {
        frames: k,
        canonical_frame: c,
        poses: fit_poses
            .iter()
            .map(|f| f.iter().map(to_row_major).collect())
            .collect(),
        root_motion: Some(
            (0..k)
                .map(|t| match source(t) {
                    Source::Key(i) => to_row_major(&fit_roots[i]),
                    Source::Tracked(i) => to_row_major(&found[i].root),
                })
                .collect(),
        ),
        joints: Some(
            fit_joints
                .iter()
                .enumerate()
                .map(|(j, jt)| {
                    let state: Vec<f64> = (0..k)
                        .map(|t| match source(t) {
                            Source::Key(i) => jt.state[i],
                            Source::Tracked(i) => found[i].states[j],
                        })
                        .collect();
                    // The key frames' limits (padded as Steps 2–3 pad them), widened to
                    // the tracked states.
                    let (lo, hi) = state
                        .iter()
                        .fold((jt.limits[0], jt.limits[1]), |(lo, hi), &q| {
                            (lo.min(q), hi.max(q))
                        });
                    crate::io::result::ResultJoint {
                        state,
                        limits: [lo, hi],
                        ..jt.clone()
                    }
                })
                .collect(),
        ),
        labels: Vec::new(),
        ..fit_key
    };
    norm.result_to_input(&mut out);

    out.labels = labels;
    // The Gaussians move with their parts: poses[t] · poses[c]⁻¹ carries a Gaussian of
    // the canonical frame (poses[c] is the identity up to rounding).
    if let (Some(gs), Some(kg)) = (out.gaussians.as_mut(), key.gaussians.as_ref()) {
        let poses: Vec<Vec<DMat4>> = out
            .poses
            .iter()
            .map(|f| f.iter().map(from_row_major).collect())
            .collect();
        for (g, kg) in gs.iter_mut().zip(kg) {
            let (mut rot, mut cen) = (Vec::with_capacity(k), Vec::with_capacity(k));
            for t in 0..k {
                let (r, m) = match source(t) {
                    Source::Key(i) => (kg.rotation[i], kg.center[i]),
                    Source::Tracked(_) => {
                        let p = poses[t][g.part] * poses[c][g.part].inverse();
                        moved_placement(&p, &kg.rotation[c_key], &kg.center[c_key])
                    }
                };
                rot.push(r);
                cen.push(m);
            }
            g.rotation = rot;
            g.center = cen;
        }
    }
    out.validate("result")?;
    let report = Extension {
        tracked: tracked.len(),
        seconds: clock() - start,
        key_chamfer: median(&mut key_cd),
        tracked_chamfer: median(&mut tracked_cd),
    };
    Ok((out, report))
}

/// [`extend`] with the tracking's default options (seeded), recording what it did in the
/// result: `info.key_frames` (the key frames, the tracked count, the seconds and the
/// median Chamfers) and a note, added to `info.notes` and returned.
pub fn extend_recorded(
    seq: &Sequence,
    keys: &[usize],
    key: FitResult,
    seed: u64,
    clock: &dyn Fn() -> f64,
    progress: &mut dyn FnMut(&Progress) -> Control,
) -> crate::Result<(FitResult, String)> {
    let opts = TrackOptions {
        seed,
        ..Default::default()
    };
    let (mut result, ext) = extend(seq, keys, key, &opts, clock, progress)?;
    let note = format!(
        "long sequence: Steps 1–3 fitted {} key frames ({}); the other {} frames were tracked with the articulated model in {:.1} s (median Chamfer of the model to a tracked frame {:.2e}, to a key frame {:.2e})",
        keys.len(),
        keys.iter().map(usize::to_string).collect::<Vec<_>>().join(", "),
        ext.tracked,
        ext.seconds,
        ext.tracked_chamfer,
        ext.key_chamfer
    );
    if let Some(info) = result.info.as_mut().and_then(|i| i.as_object_mut()) {
        info.insert(
            "key_frames".into(),
            serde_json::json!({
                "frames": keys,
                "tracked": ext.tracked,
                "seconds": ext.seconds,
                "key_chamfer": ext.key_chamfer,
                "tracked_chamfer": ext.tracked_chamfer,
            }),
        );
        if let Some(serde_json::Value::Array(n)) = info.get_mut("notes") {
            n.push(note.clone().into());
        }
    }
    Ok((result, note))
}

/// The rigid motion a share `w` of the way from `a` to `b` (rotation by slerp,
/// translation linearly).
fn interpolate(a: &DMat4, b: &DMat4, w: f64) -> DMat4 {
    let (_, ra, ta) = a.to_scale_rotation_translation();
    let (_, rb, tb) = b.to_scale_rotation_translation();
    DMat4::from_rotation_translation(DQuat::slerp(ra, rb, w), ta.lerp(tb, w))
}

/// Bidirectional squared Chamfer (means) between `model` and `pts`, each with its grid.
fn chamfer((model, grid): (&[Vec3], &Grid), (pts, pg): (&[Vec3], &Grid)) -> f64 {
    if model.is_empty() || pts.is_empty() {
        return 0.0;
    }
    let to_model: f64 = pts
        .iter()
        .filter_map(|&p| grid.nearest(p).map(|(_, d)| d as f64))
        .sum::<f64>()
        / pts.len() as f64;
    let to_pts: f64 = model
        .iter()
        .filter_map(|&y| pg.nearest(y).map(|(_, d)| d as f64))
        .sum::<f64>()
        / model.len() as f64;
    to_model + to_pts
}

fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;

    #[test]
    fn key_frames_spread_evenly_with_both_ends() {
        assert_eq!(choose(5, 12), vec![0, 1, 2, 3, 4]);
        assert_eq!(choose(13, 12).len(), 12);
        let keys = choose(60, 12);
        assert_eq!(keys.len(), 12);
        assert_eq!((keys[0], keys[11]), (0, 59));
        assert!(keys.windows(2).all(|w| w[1] > w[0] && w[1] - w[0] <= 6));
        assert_eq!(choose(60, 1), (0..60).collect::<Vec<_>>());
    }

    #[test]
    fn interpolation_is_halfway_in_angle_and_position() {
        let a = DMat4::IDENTITY;
        let b = DMat4::from_rotation_translation(
            DQuat::from_rotation_z(1.0),
            DVec3::new(0.2, 0.0, -0.4),
        );
        let h = interpolate(&a, &b, 0.5);
        let (_, r, t) = h.to_scale_rotation_translation();
        // acos near 1 resolves angles to about 1e-8.
        assert!(r.angle_between(DQuat::from_rotation_z(0.5)) < 1e-6);
        assert!((t - DVec3::new(0.1, 0.0, -0.2)).length() < 1e-12);
    }
}
