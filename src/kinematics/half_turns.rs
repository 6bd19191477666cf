//! Joint states half a turn off their path (an addition to Step 3).
//!
//! A round link (a capsule-like shank) looks the same after half a turn about an axis
//! through its centre. Step 1 can pose it end over end in some frames, and the
//! refinement, which follows the clouds, then settles its hinge with the pivot near
//! the link's centre, where those frames' states half a turn off cover the same points
//! (procedural quadruped, generator seed 5: a shank's states 0 … −0.46, then −3.55,
//! −3.54, then −0.73; its pivot 8.6 off, its thigh's 6.1). At that pivot the clouds do
//! prefer the flipped states, so no frame can be mended alone: the joint is proposed
//! anew, its jumps of about half a turn taken back (bench-dev's and the procedural
//! quadruped's and hand's joints move at most 0.73 rad between frames) and its pivot
//! the one about which those states carry the link's centroid where its Step-1 poses
//! carry it (an end-over-end turn about the centre leaves the centroid in place).
//! `kinematics::build` refines the model from there and keeps it only when it fits the
//! clouds as well as before, so a joint that truly turns more than a quarter turn
//! between frames (the procedural arm's, up to 2.6 rad) keeps its states.

use std::f64::consts::PI;

use glam::{DMat4, DVec3};

use super::screw::{padded_limits, pivot_carrying, relative_motions, zeroed_at};
use crate::io::gt::JointType;
use crate::io::result::FitResult;

/// A jump between frames counts as a flip when it lies within this many radians of an
/// odd number of half turns (the link's own motion between the frames comes on top).
/// The flips seen were 2.81–3.12 rad; a spurious piece of bench-dev panda_gripper
/// (fast, seed 1) jumps 1.64 rad, and taking that for a flip moved the gripper's tied
/// prismatic axes 3.1° → 5.9°.
pub const FLIP_TOLERANCE: f64 = 1.0;

/// `states` with every jump between frames that lies within `FLIP_TOLERANCE` of an odd
/// number of half turns taken back by those half turns, and whole turns unwrapped, 0 at
/// frame `c`.
pub fn continuous_halves(states: &[f64], c: usize) -> Vec<f64> {
    let mut out = states.to_vec();
    for k in 1..out.len() {
        let d = out[k] - out[k - 1];
        let halves = (d / PI).round();
        let flip = halves.rem_euclid(2.0) == 1.0 && (d - halves * PI).abs() <= FLIP_TOLERANCE;
        let back = if flip {
            halves
        } else {
            2.0 * (d / (2.0 * PI)).round()
        };
        out[k] -= back * PI;
    }
    zeroed_at(out, c)
}

/// Whether `a` and `b` differ by an odd number of half turns somewhere.
fn half_a_turn_apart(a: &[f64], b: &[f64]) -> bool {
    a.iter()
        .zip(b)
        .any(|(x, y)| ((x - y) / PI).round().rem_euclid(2.0) == 1.0)
}

/// Proposes every revolute joint whose states leave their path by half a turn anew
/// (see the module doc): its flips taken back (`continuous_halves`), and the pivot that carries the child's
/// centroid (`by_part`: every part's canonical points) as the merged parts' Step-1
/// poses `poses` do. Returns the joints proposed anew; the result's poses are left to
/// the refinement.
pub fn settle_half_turns(
    result: &mut FitResult,
    poses: &[Vec<DMat4>],
    by_part: &[Vec<DVec3>],
    limit_pad: f64,
) -> Vec<usize> {
    let c = result.canonical_frame;
    let parts = poses.first().map_or(0, |f| f.len());
    let mut anew = Vec::new();
    let Some(js) = result.joints.as_mut() else {
        return anew;
    };
    for (j, joint) in js.iter_mut().enumerate() {
        if joint.joint_type != JointType::Revolute || joint.state.len() != poses.len() {
            continue;
        }
        let states = continuous_halves(&joint.state, c);
        let pts = by_part.get(joint.child).map_or(&[][..], |v| &v[..]);
        if !half_a_turn_apart(&states, &joint.state)
            || joint.parent >= parts
            || joint.child >= parts
            || pts.is_empty()
        {
            continue;
        }
        let centroid = pts.iter().copied().sum::<DVec3>() / pts.len() as f64;
        let rel = relative_motions(poses, joint.parent, joint.child, c);
        let axis = DVec3::from_array(joint.axis).normalize_or(DVec3::Z);
        let reference = DVec3::from_array(joint.pivot);
        joint.pivot = pivot_carrying(&rel, axis, &states, centroid, reference).to_array();
        anew.push(j);
        joint.limits = padded_limits(&states, limit_pad);
        joint.state = states;
    }
    anew
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::se3::to_row_major;
    use crate::io::result::{ResultJoint, ResultTree};
    use crate::kinematics::flips::turn_about;

    #[test]
    fn states_are_made_continuous_modulo_half_a_turn() {
        let s = continuous_halves(&[0.0, 0.2, 3.3, 3.4, 0.5, 6.9, -2.5], 0);
        let want = [0.0, 0.2, 3.3 - PI, 3.4 - PI, 0.5, 6.9 - 2.0 * PI, -2.5 + PI];
        for (g, w) in s.iter().zip(want) {
            assert!((g - w).abs() < 1e-12, "{s:?}");
        }
        // A jump well short of half a turn is a motion, not a flip: it stays.
        let s = continuous_halves(&[0.0, -0.45, -2.09, -2.42, -2.0 + 2.0 * PI], 0);
        let want = [0.0, -0.45, -2.09, -2.42, -2.0];
        for (g, w) in s.iter().zip(want) {
            assert!((g - w).abs() < 1e-12, "{s:?}");
        }
        // Zero at the canonical frame.
        let s = continuous_halves(&[0.3, 3.6, 3.5], 1);
        assert!(
            s[1].abs() < 1e-12 && (s[0] - (0.3 + PI - 3.6)).abs() < 1e-12,
            "{s:?}"
        );
    }

    #[test]
    fn a_link_posed_end_over_end_gets_its_swing_and_hip_back() {
        // A still body (part 0) and a round leg (part 1) hanging below the hip at
        // (0.3, 0, 0), swinging about y. Step 1 posed the leg end over end (half a turn
        // about its centre) in frames 2 and 3, and the refinement followed: the joint's
        // pivot sits at the leg's centre, its states half a turn off in those frames.
        let hip = DVec3::new(0.3, 0.0, 0.0);
        let swing = [0.0, 0.3, -0.2, 0.5, 0.1];
        let flipped = [false, false, true, true, false];
        let leg: Vec<DVec3> = (0..40)
            .map(|i| hip - DVec3::Z * (0.02 + 0.004 * i as f64) + DVec3::X * 0.01)
            .collect();
        let centre = leg.iter().copied().sum::<DVec3>() / leg.len() as f64;
        let half = |f: bool| if f { PI } else { 0.0 };
        let poses: Vec<Vec<DMat4>> = swing
            .iter()
            .zip(flipped)
            .map(|(&q, f)| {
                vec![
                    DMat4::IDENTITY,
                    turn_about(DVec3::Y, q, hip) * turn_about(DVec3::X, half(f), centre),
                ]
            })
            .collect();
        let mut result = FitResult {
            format: crate::io::result::FORMAT.to_string(),
            version: crate::io::result::VERSION,
            frames: 5,
            canonical_frame: 0,
            parts: 2,
            labels: vec![Vec::new(); 5],
            poses: poses
                .iter()
                .map(|f| f.iter().map(to_row_major).collect())
                .collect(),
            gaussians: None,
            tree: Some(ResultTree {
                root: 0,
                parent: vec![-1, 0],
            }),
            joints: None,
            root_motion: None,
            points: None,
            info: None,
        };
        result.joints = Some(vec![ResultJoint {
            mimic: None,
            child: 1,
            parent: 0,
            joint_type: JointType::Revolute,
            axis: [0.0, 1.0, 0.0],
            pivot: centre.to_array(),
            state: swing
                .iter()
                .zip(flipped)
                .map(|(&q, f)| q + half(f))
                .collect(),
            limits: [-0.2, 0.5 + PI],
        }]);
        let by_part = vec![vec![DVec3::new(0.3, 0.0, 0.1)], leg];
        let anew = settle_half_turns(&mut result, &poses, &by_part, 0.0);
        assert_eq!(anew, vec![0]);
        let joint = &result.joints.as_ref().unwrap()[0];
        for (got, want) in joint.state.iter().zip(&swing) {
            assert!((got - want).abs() < 1e-9, "{:?}", joint.state);
        }
        let p = DVec3::from_array(joint.pivot);
        assert!((p - hip).length() < 1e-9, "{p}");
        assert!((joint.limits[0] + 0.2).abs() < 1e-9 && (joint.limits[1] - 0.5).abs() < 1e-9);
        // A joint already on its path is left alone.
        assert!(settle_half_turns(&mut result, &poses, &by_part, 0.0).is_empty());
    }
}
