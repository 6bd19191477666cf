//! Coupled joints (URDF `<mimic>`): a joint whose state follows another's over every
//! frame, `q_follower = multiplier · q_leader + offset`, as a parallel gripper's two
//! fingers (bench-dev panda_gripper) or a linkage's coupled hinges do.
//!
//! Step 3 fits each joint's states freely, so a coupling shows only in the states. A
//! joint is taken to follow another when both have the same parent and the same type,
//! their axes lie within [`MAX_AXIS_DEG`] of each other, both move, and the
//! least-squares line through their states leaves a residual (RMS) of at most
//! [`MAX_RESIDUAL`] of the states' range, both ways round. The result then says so
//! (`ResultJoint::mimic`): the URDF writes `<mimic>`, and the page moves a follower
//! with its leader. The per-frame states stay the fitted ones (they explain the frames
//! best); the coupling says how the model is re-posed.
//!
//! Why these rules: over ten frames, smooth joint trajectories often look coupled by
//! chance. On bench-dev's truth (full, 476 ordered joint pairs) the best chance line
//! leaves 3.6 % of the range (xarm7's joints 1 and 3); the procedural objects'
//! trajectories (four knots each, `synth::trajectory`) are flatter still: 1.43 % for
//! two parallel hinges of different legs of the quadruped (generator seed 3) and of
//! the hand. Fitted models add their own: the first rule without the same parent
//! coupled a hip and a knee of three of five laikago fits (2.8–3.5 %). Among siblings
//! with the same type and axes within 10°, the best chance pair leaves 7.25 % (two
//! hips of the procedural quadruped, seed 0; bench-dev's 16.9 %), and the panda
//! gripper's fingers, the one true coupling, leave 0 in the truth and 1.4–2.7 % as
//! fitted (full, balanced, seeds 0, 1 and 3; seeds 2 and 4 split a finger), while the
//! best other sibling pair of 70 bench-dev fits (full and occluded) leaves 7.8 %. A
//! chain's coupled hinges (an underactuated finger's) are therefore not
//! found: their states cannot be told from chance over ten frames.

use glam::DVec3;
use serde::Serialize;

use crate::io::result::{Mimic, ResultJoint};
use crate::math::Libm;

/// Largest RMS residual of the line through two joints' states, as a fraction of the
/// follower's (and, the other way round, the leader's) state range.
pub const MAX_RESIDUAL: f64 = 0.035;
/// Largest angle between the axes of coupled joints (either direction).
pub const MAX_AXIS_DEG: f64 = 10.0;
/// A coupling needs this many frames: through fewer states any two joints fit a line.
pub const MIN_FRAMES: usize = 4;
/// A joint moves when its states span at least this many degrees (revolute) ...
pub const MIN_RANGE_DEG: f64 = 3.0;
/// ... or this fraction of the object's size (prismatic).
pub const MIN_RANGE_SIZE: f64 = 0.01;

/// A coupling found, with the evidence for the notes.
#[derive(Debug, Clone, Copy, Serialize, PartialEq)]
pub struct Coupling {
    /// Follower's and leader's child parts.
    pub child: usize,
    pub leader: usize,
    pub multiplier: f64,
    pub offset: f64,
    /// RMS residual as a fraction of the follower's state range.
    pub residual: f64,
}

/// Least-squares line `y ≈ a·x + b`: (a, b, RMS residual). `None` when x is constant.
fn line(x: &[f64], y: &[f64]) -> Option<(f64, f64, f64)> {
    let n = x.len() as f64;
    let (mx, my) = (x.iter().sum::<f64>() / n, y.iter().sum::<f64>() / n);
    let sxx: f64 = x.iter().map(|v| (v - mx) * (v - mx)).sum();
    if sxx <= f64::EPSILON {
        return None;
    }
    let sxy: f64 = x.iter().zip(y).map(|(u, v)| (u - mx) * (v - my)).sum();
    let a = sxy / sxx;
    let b = my - a * mx;
    let ss: f64 = x.iter().zip(y).map(|(u, v)| (v - a * u - b).powi(2)).sum();
    Some((a, b, (ss / n).sqrt()))
}

/// The span of a joint's states.
fn range(q: &[f64]) -> f64 {
    let (lo, hi) = super::screw::state_range(q);
    hi - lo
}

/// The couplings among `joints` (an earlier joint of the list leads: the result's joints
/// are in the order of their child parts). `size`: the object's size, for the
/// prismatic range; `exclude`: child parts whose joints follow none and lead none
/// (unlinked by hand).
pub fn find_couplings(joints: &[ResultJoint], size: f64, exclude: &[usize]) -> Vec<Coupling> {
    let cos_max = MAX_AXIS_DEG.to_radians().lcos();
    let moves = |j: &ResultJoint| {
        let min = match j.joint_type {
            crate::io::gt::JointType::Revolute => MIN_RANGE_DEG.to_radians(),
            crate::io::gt::JointType::Prismatic => MIN_RANGE_SIZE * size,
        };
        j.state.len() >= MIN_FRAMES
            && j.state.iter().all(|v| v.is_finite())
            && range(&j.state) >= min
            && !exclude.contains(&j.child)
    };
    let mut taken = vec![false; joints.len()];
    let mut out = Vec::new();
    for (i, lead) in joints.iter().enumerate() {
        if taken[i] || !moves(lead) {
            continue;
        }
        let axis = DVec3::from(lead.axis).normalize_or_zero();
        for (k, f) in joints.iter().enumerate().skip(i + 1) {
            if taken[k]
                || f.parent != lead.parent
                || f.joint_type != lead.joint_type
                || f.state.len() != lead.state.len()
                || !moves(f)
                || DVec3::from(f.axis).normalize_or_zero().dot(axis).abs() < cos_max
            {
                continue;
            }
            let (Some((a, b, r)), Some((_, _, r_back))) =
                (line(&lead.state, &f.state), line(&f.state, &lead.state))
            else {
                continue;
            };
            let rel = r / range(&f.state);
            if rel <= MAX_RESIDUAL && r_back / range(&lead.state) <= MAX_RESIDUAL {
                taken[k] = true;
                out.push(Coupling {
                    child: f.child,
                    leader: lead.child,
                    multiplier: a,
                    offset: b,
                    residual: rel,
                });
            }
        }
    }
    out
}

/// Writes `couplings` into the joints (and clears every other joint's coupling).
pub fn apply(joints: &mut [ResultJoint], couplings: &[Coupling]) {
    for j in joints.iter_mut() {
        j.mimic = couplings
            .iter()
            .find(|c| c.child == j.child)
            .map(|c| Mimic {
                joint: c.leader,
                multiplier: c.multiplier,
                offset: c.offset,
            });
    }
}

/// Joint states (indexed by child part) with every follower's state set from its
/// leader's, as the page and `gsart articulate` re-pose a model.
pub fn follow(joints: &[ResultJoint], states: &mut [f64]) {
    for j in joints {
        if let Some(m) = j.mimic {
            if let (Some(&q), true) = (states.get(m.joint), j.child < states.len()) {
                states[j.child] = m.multiplier * q + m.offset;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::gt::JointType;

    fn joint(child: usize, t: JointType, axis: [f64; 3], state: Vec<f64>) -> ResultJoint {
        ResultJoint {
            child,
            parent: 0,
            joint_type: t,
            axis,
            pivot: [0.0; 3],
            state,
            limits: [-1.0, 1.0],
            mimic: None,
        }
    }

    fn wave(k: usize, f: f64, p: f64) -> Vec<f64> {
        (0..k).map(|t| 0.3 * (f * t as f64 + p).lsin()).collect()
    }

    #[test]
    fn mirrored_fingers_are_coupled_and_independent_joints_are_not() {
        let q = wave(10, 0.7, 0.2);
        // The second finger slides the other way along the same line, with a little noise.
        let noisy: Vec<f64> = q
            .iter()
            .enumerate()
            .map(|(t, v)| -v + 0.002 * ((t * 7 % 5) as f64 - 2.0))
            .collect();
        let joints = vec![
            joint(1, JointType::Prismatic, [0.0, 1.0, 0.0], q.clone()),
            joint(2, JointType::Prismatic, [0.0, -1.0, 0.0], noisy),
            // Same states but another type, and a hinge with another motion.
            joint(3, JointType::Revolute, [0.0, 1.0, 0.0], q.clone()),
            joint(4, JointType::Revolute, [0.0, 1.0, 0.0], wave(10, 1.3, 1.0)),
        ];
        let c = find_couplings(&joints, 1.0, &[]);
        assert_eq!(c.len(), 1, "{c:?}");
        assert_eq!((c[0].child, c[0].leader), (2, 1));
        assert!((c[0].multiplier + 1.0).abs() < 0.02, "{c:?}");
        assert!(c[0].offset.abs() < 0.01 && c[0].residual < 0.01, "{c:?}");

        let mut joints = joints;
        apply(&mut joints, &c);
        assert_eq!(joints[1].mimic.map(|m| m.joint), Some(1));
        assert!(joints.iter().filter(|j| j.mimic.is_some()).count() == 1);
        let mut states = vec![0.0, 0.25, 0.0, 0.1, 0.2];
        follow(&joints, &mut states);
        assert!((states[2] + 0.25).abs() < 0.01, "{states:?}");
        assert_eq!(states[3], 0.1);
    }

    #[test]
    fn couplings_need_parallel_axes_motion_frames_and_no_exclusion() {
        let q = wave(10, 0.7, 0.2);
        let pair = |axis: [f64; 3], state: Vec<f64>| {
            vec![
                joint(1, JointType::Revolute, [0.0, 0.0, 1.0], state.clone()),
                joint(2, JointType::Revolute, axis, state),
            ]
        };
        assert_eq!(
            find_couplings(&pair([0.0, 0.0, 1.0], q.clone()), 1.0, &[]).len(),
            1
        );
        // 20° apart.
        let tilted = [0.0, 20f64.to_radians().lsin(), 20f64.to_radians().lcos()];
        assert!(find_couplings(&pair(tilted, q.clone()), 1.0, &[]).is_empty());
        // Still joints (1° of travel), and too few frames.
        let still: Vec<f64> = q.iter().map(|v| v * 0.05).collect();
        assert!(find_couplings(&pair([0.0, 0.0, 1.0], still), 1.0, &[]).is_empty());
        assert!(find_couplings(&pair([0.0, 0.0, 1.0], q[..3].to_vec()), 1.0, &[]).is_empty());
        // Unlinked by hand.
        assert!(find_couplings(&pair([0.0, 0.0, 1.0], q.clone()), 1.0, &[2]).is_empty());
        // Joints of different parents (a chain's, or two legs') are not coupled.
        let mut legs = pair([0.0, 0.0, 1.0], q.clone());
        legs[1].parent = 1;
        assert!(find_couplings(&legs, 1.0, &[]).is_empty());
        // States off their line by 10 % of the range are not coupled.
        let off: Vec<f64> = q
            .iter()
            .enumerate()
            .map(|(t, v)| v + if t % 2 == 0 { 0.1 } else { -0.1 })
            .collect();
        let (_, _, r) = line(&q, &off).unwrap();
        assert!(r / range(&off) > 0.1, "{}", r / range(&off));
        let mut noisy = pair([0.0, 0.0, 1.0], q.clone());
        noisy[1].state = off;
        assert!(find_couplings(&noisy, 1.0, &[]).is_empty());
    }

    #[test]
    fn the_line_fit_is_exact_on_a_line() {
        let x = [0.0, 1.0, 2.0, 4.0];
        let y = [1.0, 3.0, 5.0, 9.0];
        let (a, b, r) = line(&x, &y).unwrap();
        assert!((a - 2.0).abs() < 1e-12 && (b - 1.0).abs() < 1e-12 && r < 1e-12);
        assert!(line(&[1.0; 4], &y).is_none());
    }
}
