//! Tracking frames with a fitted articulated model: each frame's root motion and joint
//! states are fitted through forward kinematics, with the joints' axes and pivots held
//! as fitted. The loss is the Step-3 refinement's (`refine`): the squared Chamfer
//! between the canonical frame's segmented points, moved by the chain, and the frame.
//!
//! Long sequences are fitted on key frames (`crate::key_frames`) and the frames between
//! them tracked here, each started from its neighbouring key frames' configurations.

use glam::{DMat4, Vec3};
use rand::{rngs::StdRng, SeedableRng};

use super::build::progress_to;
use super::refine::{build_data, loss_grad, model_from_result, Adam, Hints};
use crate::geom::se3::to_row_major;
use crate::io::result::FitResult;
use crate::pipeline::{Control, Progress, Stage};

/// Options of the tracking.
#[derive(Debug, Clone, PartialEq)]
pub struct TrackOptions {
    /// Adam iterations (all frames at once: their parameters do not interact).
    pub iters: usize,
    /// Adam's step size; the refinement's.
    pub lr: f64,
    /// Points sampled per frame, and from the canonical frame: the refinement's. The
    /// Chamfer's sampling noise shows in the poses (procedural laptop, 36 frames of
    /// 2048 points on 12 key frames, mean pose error of the tracked frames against the
    /// key frames' 0.43: 1024 points 0.92, the whole 2048 0.46; 100 or 400 iterations
    /// alike).
    pub sample: usize,
    pub seed: u64,
}

impl Default for TrackOptions {
    fn default() -> Self {
        TrackOptions {
            iters: 100,
            lr: 1.5e-2,
            sample: 2048,
            seed: 0,
        }
    }
}

/// A frame's configuration of the chain: the root's motion from the canonical frame and
/// one state per joint of the result (radians or lengths), with the part poses they give.
#[derive(Debug, Clone, PartialEq)]
pub struct Configuration {
    pub root: DMat4,
    pub states: Vec<f64>,
    /// Every part's motion from the canonical frame (forward kinematics).
    pub poses: Vec<DMat4>,
}

/// Fits the configuration of each of `frames` from `starts` (one per frame), for the
/// articulated `model` (tree, joints and root motion, in the units of the points).
/// `canonical` are the points of the model's canonical frame, `labels` their parts.
/// Progress is reported as `Stage::Track`; a cancel stops it.
pub fn track(
    model: &FitResult,
    canonical: &[Vec3],
    labels: &[u32],
    frames: &[Vec<Vec3>],
    starts: &[Configuration],
    opts: &TrackOptions,
    progress: &mut dyn FnMut(&Progress) -> Control,
) -> crate::Result<Vec<Configuration>> {
    let bad = |s: &str| crate::Error::InvalidArgument(format!("tracking: {s}"));
    let joints = model
        .joints
        .as_ref()
        .ok_or_else(|| bad("the model has no joints"))?;
    let c = model.canonical_frame;
    let root_c = model
        .root_motion
        .as_ref()
        .and_then(|r| r.get(c))
        .ok_or_else(|| bad("the model has no root motion"))?;
    if frames.len() != starts.len() || starts.iter().any(|s| s.states.len() != joints.len()) {
        return Err(bad("one start per frame, one state per joint"));
    }
    if canonical.len() != labels.len() || labels.iter().any(|&l| l as usize >= model.parts) {
        return Err(bad("one part below the part count per canonical point"));
    }
    if frames.is_empty() {
        return Ok(Vec::new());
    }
    // A model of the canonical frame (frame 0) and the frames to track: the chain's
    // parameter layout, with the key frames' structure and the starts' states.
    let (k, tracked) = (1 + frames.len(), frames.len());
    let mut joints = joints.clone();
    for (j, jt) in joints.iter_mut().enumerate() {
        jt.state = std::iter::once(0.0)
            .chain(starts.iter().map(|s| s.states[j]))
            .collect();
    }
    let chain = FitResult {
        frames: k,
        canonical_frame: 0,
        // Only the canonical frame's labels are read (`build_data`).
        labels: std::iter::once(labels.to_vec())
            .chain(std::iter::repeat_n(Vec::new(), tracked))
            .collect(),
        poses: Vec::new(),
        joints: Some(joints),
        root_motion: Some(
            std::iter::once(*root_c)
                .chain(starts.iter().map(|s| to_row_major(&s.root)))
                .collect(),
        ),
        gaussians: None,
        points: None,
        info: None,
        ..model.clone()
    };
    let (m, mut x) = model_from_result(&chain, true)?;
    let points: Vec<Vec<Vec3>> = std::iter::once(canonical.to_vec())
        .chain(frames.iter().cloned())
        .collect();
    let mut rng = StdRng::seed_from_u64(opts.seed);
    let data = build_data(&chain, &points, opts.sample, &mut rng);
    drop(points);

    let mut adam = Adam::new(x.len());
    let mut g = vec![0.0; x.len()];
    let mut hints = Hints::default();
    for it in 0..opts.iters {
        let loss = loss_grad(&m, &x, &data, None, Some(&mut g), Some(&mut hints));
        // The joints' axes and pivots stay as the key frames fitted them.
        for j in 0..m.types.len() {
            let b = m.joint_base(j);
            g[b..b + 6].fill(0.0);
        }
        adam.step(&mut x, &g, it, opts.iters, opts.lr);
        if it % 10 == 0 || it + 1 == opts.iters {
            let losses = vec![("track".to_string(), loss / tracked as f64)];
            progress_to(progress, Stage::Track, it, opts.iters, losses)?;
        }
    }
    let root = m.order[0];
    Ok((1..k)
        .map(|t| {
            let poses = m.poses(&x, t);
            Configuration {
                root: poses[root],
                states: (0..m.types.len())
                    .map(|j| x[m.joint_base(j) + 6 + t])
                    .collect(),
                poses,
            }
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::gt::JointType;
    use crate::io::result::{ResultJoint, ResultTree, FORMAT, VERSION};
    use glam::{DQuat, DVec3};
    use rand::Rng;

    /// A slab (part 0) with a rod (part 1) hinged on its edge about z, and a block
    /// (part 2) sliding along the rod's axis x.
    fn object() -> (Vec<Vec3>, Vec<u32>) {
        let mut rng = StdRng::seed_from_u64(3);
        let mut pts = Vec::new();
        let mut labels = Vec::new();
        for _ in 0..600 {
            pts.push(Vec3::new(
                rng.random_range(-0.4..0.0),
                rng.random_range(-0.2..0.2),
                rng.random_range(-0.05..0.05),
            ));
            labels.push(0);
        }
        for _ in 0..300 {
            pts.push(Vec3::new(
                rng.random_range(0.0..0.4),
                rng.random_range(-0.03..0.03),
                rng.random_range(-0.03..0.03),
            ));
            labels.push(1);
        }
        for _ in 0..200 {
            pts.push(Vec3::new(
                rng.random_range(0.1..0.2),
                rng.random_range(-0.08..0.08),
                rng.random_range(-0.08..0.08),
            ));
            labels.push(2);
        }
        (pts, labels)
    }

    fn model() -> FitResult {
        FitResult {
            format: FORMAT.into(),
            version: VERSION,
            frames: 1,
            canonical_frame: 0,
            parts: 3,
            labels: vec![vec![]],
            poses: vec![vec![to_row_major(&DMat4::IDENTITY); 3]],
            gaussians: None,
            tree: Some(ResultTree {
                root: 0,
                parent: vec![-1, 0, 1],
            }),
            joints: Some(vec![
                ResultJoint {
                    mimic: None,
                    child: 1,
                    parent: 0,
                    joint_type: JointType::Revolute,
                    axis: [0.0, 0.0, 1.0],
                    pivot: [0.0, 0.0, 0.0],
                    state: vec![0.0],
                    limits: [0.0, 0.0],
                },
                ResultJoint {
                    mimic: None,
                    child: 2,
                    parent: 1,
                    joint_type: JointType::Prismatic,
                    axis: [1.0, 0.0, 0.0],
                    pivot: [0.0; 3],
                    state: vec![0.0],
                    limits: [0.0, 0.0],
                },
            ]),
            root_motion: Some(vec![to_row_major(&DMat4::IDENTITY)]),
            points: None,
            info: None,
        }
    }

    fn configuration(model: &FitResult, root: DMat4, states: Vec<f64>) -> Configuration {
        let mut one = model.clone();
        for (jt, &q) in one.joints.as_mut().unwrap().iter_mut().zip(&states) {
            jt.state = vec![q];
        }
        one.root_motion = Some(vec![to_row_major(&root)]);
        let (m, x) = model_from_result(&one, true).unwrap();
        let poses = m.poses(&x, 0);
        Configuration {
            root,
            states,
            poses,
        }
    }

    #[test]
    fn tracking_finds_each_frames_states_and_root_motion_from_a_start_nearby() {
        let model = model();
        let (pts, labels) = object();
        let truth = [
            (0.5, 0.08, DVec3::new(0.05, -0.02, 0.0), 0.2),
            (-0.4, 0.15, DVec3::new(-0.03, 0.04, 0.02), -0.15),
        ];
        let mut frames = Vec::new();
        let mut starts = Vec::new();
        let mut wanted = Vec::new();
        for &(q1, q2, shift, turn) in &truth {
            let root = DMat4::from_rotation_translation(DQuat::from_rotation_y(turn), shift);
            let c = configuration(&model, root, vec![q1, q2]);
            frames.push(
                pts.iter()
                    .zip(&labels)
                    .map(|(p, &l)| c.poses[l as usize].transform_point3(p.as_dvec3()).as_vec3())
                    .collect::<Vec<_>>(),
            );
            // Started 0.15 rad, 0.03 and a few degrees of root motion off.
            let start_root = DMat4::from_rotation_translation(
                DQuat::from_rotation_y(turn - 0.06),
                shift + DVec3::new(0.02, 0.0, -0.01),
            );
            starts.push(configuration(
                &model,
                start_root,
                vec![q1 + 0.15, q2 - 0.03],
            ));
            wanted.push(c);
        }
        let opts = TrackOptions {
            iters: 150,
            ..Default::default()
        };
        let got = track(&model, &pts, &labels, &frames, &starts, &opts, &mut |_| {
            Control::Continue
        })
        .unwrap();
        for (g, w) in got.iter().zip(&wanted) {
            assert!(
                (g.states[0] - w.states[0]).abs() < 0.02,
                "{:?} {:?}",
                g.states,
                w.states
            );
            assert!(
                (g.states[1] - w.states[1]).abs() < 0.005,
                "{:?} {:?}",
                g.states,
                w.states
            );
            // Poses agree with the states (forward kinematics), and with the truth.
            for (pg, pw) in g.poses.iter().zip(&w.poses) {
                let d = pts
                    .iter()
                    .map(|p| {
                        (pg.transform_point3(p.as_dvec3()) - pw.transform_point3(p.as_dvec3()))
                            .length()
                    })
                    .fold(0.0f64, f64::max);
                assert!(d < 0.01, "part moved {d} off");
            }
        }
    }

    #[test]
    fn the_canonical_frame_tracks_back_to_rest_and_a_cancel_stops() {
        let model = model();
        let (pts, labels) = object();
        let start = configuration(&model, DMat4::IDENTITY, vec![0.3, 0.05]);
        let frames = vec![pts.clone()];
        let got = track(
            &model,
            &pts,
            &labels,
            &frames,
            std::slice::from_ref(&start),
            &TrackOptions::default(),
            &mut |_| Control::Continue,
        )
        .unwrap();
        // The frame is the canonical one: every state goes back to 0, on the same axes.
        assert!(
            got[0].states.iter().all(|q| q.abs() < 0.01),
            "{:?}",
            got[0].states
        );
        let r = track(
            &model,
            &pts,
            &labels,
            &frames,
            &[start],
            &TrackOptions::default(),
            &mut |_| Control::Cancel,
        );
        assert!(matches!(r, Err(crate::Error::Cancelled)));
    }
}
