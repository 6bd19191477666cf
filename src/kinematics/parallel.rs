//! Parallel joint axes (an addition to Step 3). Made objects put their joints on
//! parallel axes far more often than a few degrees apart: a quadruped's hips and knees,
//! the pitch joints of an arm's shoulder and elbow, a finger's flexion joints, a
//! cabinet's drawers. Each joint's axis is fitted to its own part's motion, and a
//! part turned through half a radian, or a link that is nearly round about its own
//! axis, leaves that axis 5–10° off although the clouds cannot tell the two apart.
//!
//! Joints that are related — two joints of one parent part, or a joint and its child
//! part's joint — of one type, whose axes lie within `MAX_ANGLE_DEG` of each other,
//! form a group (joined transitively). Parallel axes stay parallel at every state: a
//! sibling pair's axes are both fixed in their parent, and a child's axis parallel to
//! its parent joint's is turned only about itself. `kinematics::build` refines the
//! model with each group's axes tied to their mean direction
//! (`RefineOptions::ties`) and keeps the groups only where the model still fits the
//! clouds as well as without them.

use glam::{DMat3, DMat4, DVec3};
use petgraph::unionfind::UnionFind;

use super::flips::principal_axes;
use super::screw::{
    padded_limits, pivot_carrying, project_angle, relative_motions, turns_carrying, unwrap_angles,
    zeroed_at,
};
use crate::io::result::ResultJoint;
use crate::math::Libm;

/// Axes within this angle (degrees) of a related joint's are tried as parallel.
pub const MAX_ANGLE_DEG: f64 = 10.0;

/// A joint outside every group whose axis lies within this angle (degrees) of a
/// related kept group's tied direction is tried on that direction (`followers`), and
/// related groups whose directions lie within it are tried as one (`joined_groups`).
pub const FOLLOW_ANGLE_DEG: f64 = 30.0;

/// A revolute joint outside every group after the followers, with an axis within this
/// angle (degrees) of a related kept group's tied direction, is tried on that
/// direction with its states and pivot found anew (`kinematics::build`).
pub const FAR_FOLLOW_ANGLE_DEG: f64 = 90.0;

/// Groups (two or more joints, indices into `joints`) of related joints of one type
/// whose axes lie within `max_deg` of each other, joined transitively; each group
/// sorted, groups in order of their first member.
pub fn parallel_groups(joints: &[ResultJoint], max_deg: f64) -> Vec<Vec<usize>> {
    let n = joints.len();
    let min_cos = max_deg.to_radians().lcos();
    let mut sets = UnionFind::<usize>::new(n);
    for a in 0..n {
        for b in a + 1..n {
            let (ja, jb) = (&joints[a], &joints[b]);
            if !related(ja, jb) || ja.joint_type != jb.joint_type {
                continue;
            }
            let (u, v) = (unit(ja.axis), unit(jb.axis));
            if u.dot(v).abs() >= min_cos {
                sets.union(a, b);
            }
        }
    }
    let labels = sets.into_labeling();
    let mut groups: Vec<Vec<usize>> = Vec::new();
    for i in 0..n {
        if let Some(g) = groups.iter_mut().find(|g| labels[g[0]] == labels[i]) {
            g.push(i);
        } else {
            groups.push(vec![i]);
        }
    }
    groups.retain(|g| g.len() >= 2);
    groups
}

fn related(a: &ResultJoint, b: &ResultJoint) -> bool {
    a.parent == b.parent || a.child == b.parent || b.child == a.parent
}

/// Joints outside every one of `groups` that may follow one: of the group's type,
/// related to one of its members, with an axis within `max_deg` of the group's tied
/// direction (the nearest such group). Two or more joints agreeing within
/// `MAX_ANGLE_DEG` outvote an outlier whose own swing left its axis 10–25° off
/// (procedural quadruped: a shank beside its tied thigh and the other legs); the
/// follower takes the group's direction without weighing in it, so a real outlier
/// cannot pull the group (bench-dev talos, session 44). Joined transitively (a joint
/// related to a follower may follow too). Returns (joint, group index) pairs in joint
/// order.
pub fn followers(
    joints: &[ResultJoint],
    groups: &[Vec<usize>],
    max_deg: f64,
) -> Vec<(usize, usize)> {
    let min_cos = max_deg.to_radians().lcos();
    let dirs = group_directions(joints, groups, &[]);
    // Joined transitively: a shank may follow once its thigh does.
    let mut member: Vec<Option<usize>> = vec![None; joints.len()];
    for (gi, g) in groups.iter().enumerate() {
        for &j in g {
            if let Some(m) = member.get_mut(j) {
                *m = Some(gi);
            }
        }
    }
    let mut out = Vec::new();
    loop {
        let mut joined = false;
        for (j, joint) in joints.iter().enumerate() {
            if member[j].is_some() {
                continue;
            }
            let a = unit(joint.axis);
            let best = dirs
                .iter()
                .enumerate()
                .filter_map(|(gi, d)| {
                    let d = (*d)?;
                    let ok = joints.iter().zip(&member).any(|(k, m)| {
                        *m == Some(gi) && k.joint_type == joint.joint_type && related(k, joint)
                    });
                    let c = a.dot(d).abs();
                    (ok && c >= min_cos).then_some((gi, c))
                })
                .max_by(|x, y| x.1.total_cmp(&y.1));
            if let Some((gi, _)) = best {
                member[j] = Some(gi);
                out.push((j, gi));
                joined = true;
            }
        }
        if !joined {
            break;
        }
    }
    out.sort_unstable();
    out
}

fn unit(a: [f64; 3]) -> DVec3 {
    DVec3::from_array(a).normalize_or_zero()
}

/// The states joint `j`'s weight in its group's `tied_direction` comes from: none for
/// a follower, which weighs nothing there.
pub(crate) fn weighing_states<'a>(j: usize, followers: &[usize], states: &'a [f64]) -> &'a [f64] {
    if followers.contains(&j) {
        &[]
    } else {
        states
    }
}

/// Joint `j`'s axis and the states its weight comes from (`weighing_states`).
fn weighed<'a>(joints: &'a [ResultJoint], j: usize, followers: &[usize]) -> (DVec3, &'a [f64]) {
    let states = weighing_states(j, followers, &joints[j].state);
    (DVec3::from_array(joints[j].axis), states)
}

/// The tied direction of each group (`tied_direction`, `followers` weighing nothing).
fn group_directions(
    joints: &[ResultJoint],
    groups: &[Vec<usize>],
    followers: &[usize],
) -> Vec<Option<DVec3>> {
    groups
        .iter()
        .map(|g| {
            let axes = g.iter().map(|&j| weighed(joints, j, followers));
            tied_direction(axes).map(|(d, _)| d)
        })
        .collect()
}

/// Unions of `groups` whose tied directions lie within `max_deg` of each other and
/// that are related (a member of one related to a member of the other, one type):
/// each group's own joints agreed within `MAX_ANGLE_DEG`, while two groups fitted
/// apart (a quadruped's front legs 3.5° and its hind legs 7.4° off, 10.9° apart) may
/// still be one. `None` when no two groups join.
pub fn joined_groups(
    joints: &[ResultJoint],
    groups: &[Vec<usize>],
    followers: &[usize],
    max_deg: f64,
) -> Option<Vec<Vec<usize>>> {
    let min_cos = max_deg.to_radians().lcos();
    let dirs = group_directions(joints, groups, followers);
    let mut sets = UnionFind::<usize>::new(groups.len());
    let mut any = false;
    for a in 0..groups.len() {
        for b in a + 1..groups.len() {
            let (Some(da), Some(db)) = (dirs[a], dirs[b]) else {
                continue;
            };
            let linked = groups[a].iter().any(|&x| {
                groups[b].iter().any(|&y| {
                    joints[x].joint_type == joints[y].joint_type && related(&joints[x], &joints[y])
                })
            });
            if linked && da.dot(db).abs() >= min_cos && sets.union(a, b) {
                any = true;
            }
        }
    }
    if !any {
        return None;
    }
    let labels = sets.into_labeling();
    let mut out: Vec<Vec<usize>> = Vec::new();
    let mut first: Vec<(usize, usize)> = Vec::new();
    for (gi, g) in groups.iter().enumerate() {
        if let Some(&(_, oi)) = first.iter().find(|(l, _)| *l == labels[gi]) {
            out[oi].extend_from_slice(g);
        } else {
            first.push((labels[gi], out.len()));
            out.push(g.clone());
        }
    }
    Some(out)
}

/// A joint's weight in its group's mean direction: the square of its state range. A
/// hinge seen over a wider swing has a better determined axis (procedural quadruped,
/// fast, generator seeds 0–3, the found axes set to their group's mean without a
/// refinement: median axis error 3.3° → 1.9° with equal weights, 1.4° with these).
pub fn weight(states: &[f64]) -> f64 {
    let (lo, hi) = states
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &q| {
            (lo.min(q), hi.max(q))
        });
    if hi > lo {
        (hi - lo) * (hi - lo) + 1e-12
    } else {
        1e-12
    }
}

/// The tied direction of a group of axes (each with its joint's states): their mean
/// weighted by `weight`, every axis flipped to agree with the first; and each axis's
/// sense against it (±1), which the tied axis keeps. `None` for an empty group.
/// `tie_axes` and the refinement's ties (`refine::RefineOptions::ties`) both use it.
pub fn tied_direction<'a>(
    axes: impl Iterator<Item = (DVec3, &'a [f64])>,
) -> Option<(DVec3, Vec<f64>)> {
    let mut reference = None;
    let mut senses = Vec::new();
    let mut sum = DVec3::ZERO;
    for (a, states) in axes {
        let a = a.normalize_or(DVec3::Z);
        let r = *reference.get_or_insert(a);
        let s = if a.dot(r) < 0.0 { -1.0 } else { 1.0 };
        senses.push(s);
        sum += a * s * weight(states);
    }
    let reference = reference?;
    Some((sum.normalize_or(reference), senses))
}

/// Sets the axes of each group to its `tied_direction`, as the refinement's ties do
/// (`followers` weigh nothing in it); pivots and states are left to the refinement.
pub fn tie_axes(joints: &mut [ResultJoint], groups: &[Vec<usize>], followers: &[usize]) {
    for g in groups {
        let axes = g.iter().map(|&j| weighed(joints, j, followers));
        let Some((dir, senses)) = tied_direction(axes) else {
            continue;
        };
        for (&j, s) in g.iter().zip(senses) {
            joints[j].axis = (dir * s).to_array();
        }
    }
}

/// A follower's joint taken onto its tied axis from afar: its state in each frame is
/// the turn about the new axis that carries the child's longest principal direction
/// (its canonical points `pts`) where the observed relative motion (the merged parts'
/// poses `poses`) carries it, and its pivot the point about which those turns best
/// carry the child's centroid. The states fitted about the old axis mean nothing about
/// the new one, and a round link's Step-1 poses spin about its own axis by any
/// amount: the direction of that axis and the centroid are what the clouds show. A
/// child whose principal direction lies within 30° of the axis has its states from
/// the whole rotation instead (`project_angle`).
pub fn reproject(
    joint: &mut ResultJoint,
    poses: &[Vec<DMat4>],
    pts: &[DVec3],
    canonical: usize,
    limit_pad: f64,
) {
    let axis = DVec3::from_array(joint.axis).normalize_or(DVec3::Z);
    let parts = poses.first().map_or(0, |f| f.len());
    if joint.parent >= parts || joint.child >= parts || pts.len() < 3 {
        return;
    }
    let rel = relative_motions(poses, joint.parent, joint.child, canonical);
    let (c, dirs) = principal_axes(pts);
    let spread = |d: &DVec3| pts.iter().map(|p| (*p - c).dot(*d).powi(2)).sum::<f64>();
    let d0 = dirs
        .into_iter()
        .max_by(|a, b| spread(a).total_cmp(&spread(b)))
        .unwrap_or(DVec3::Z);
    let u0 = d0 - axis * d0.dot(axis);
    let states = if u0.length() < 0.5 {
        let raw = rel
            .iter()
            .map(|q| project_angle(axis, &DMat3::from_mat4(*q)))
            .collect();
        zeroed_at(unwrap_angles(raw), canonical)
    } else {
        let images: Vec<DVec3> = rel.iter().map(|q| q.transform_vector3(d0)).collect();
        turns_carrying(&images, u0, axis, canonical)
    };
    let pivot = pivot_carrying(&rel, axis, &states, c, DVec3::from_array(joint.pivot));
    joint.pivot = pivot.to_array();
    joint.limits = padded_limits(&states, limit_pad);
    joint.state = states;
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::gt::JointType;

    fn joint(child: usize, parent: usize, t: JointType, axis: [f64; 3]) -> ResultJoint {
        ResultJoint {
            mimic: None,
            child,
            parent,
            joint_type: t,
            axis,
            pivot: [0.0; 3],
            state: vec![0.0, 0.3],
            limits: [0.0, 0.3],
        }
    }

    fn tilted(deg: f64) -> [f64; 3] {
        let r = deg.to_radians();
        [r.lsin(), r.lcos(), 0.0]
    }

    #[test]
    fn related_near_parallel_joints_of_one_type_are_grouped() {
        use JointType::{Prismatic as P, Revolute as R};
        // Body 0 with two legs (1 → 2 and 3 → 4) on y, a tail 5 on z, a sliding
        // part 6 on y, and a leg joint 7 → 8 beyond leg 1's knee but unrelated to it.
        let joints = vec![
            joint(1, 0, R, tilted(3.0)),
            joint(2, 1, R, tilted(-4.0)),
            joint(3, 0, R, [0.0, -1.0, 0.05]), // opposite sense, ~3° off
            joint(4, 3, R, tilted(25.0)),      // too far from its parent's
            joint(5, 0, R, [0.0, 0.0, 1.0]),   // perpendicular
            joint(6, 0, P, [0.0, 1.0, 0.0]),   // another type
            joint(8, 7, R, [0.0, 1.0, 0.0]),   // not related to any
        ];
        let groups = parallel_groups(&joints, MAX_ANGLE_DEG);
        assert_eq!(groups, vec![vec![0, 1, 2]]);
    }

    #[test]
    fn a_related_outlier_follows_a_group_and_its_child_joint_after_it() {
        use JointType::{Prismatic as P, Revolute as R};
        // Body 0: legs 1 and 3 tied on y; leg 5 hinged 20° off with its knee 6 25° off
        // (related to the group only through leg 5); a tail 7 at 40°; a slide 8 on y;
        // a joint 10 → 11 on y related to none.
        let joints = vec![
            joint(1, 0, R, tilted(2.0)),
            joint(3, 0, R, tilted(-2.0)),
            joint(5, 0, R, tilted(20.0)),
            joint(6, 5, R, tilted(-25.0)),
            joint(7, 0, R, tilted(40.0)),
            joint(8, 0, P, tilted(0.0)),
            joint(11, 10, R, tilted(0.0)),
        ];
        let groups = parallel_groups(&joints, MAX_ANGLE_DEG);
        assert_eq!(groups, vec![vec![0, 1]]);
        assert_eq!(
            followers(&joints, &groups, FOLLOW_ANGLE_DEG),
            vec![(2, 0), (3, 0)]
        );
        // Tied, the followers take the group's direction and leave it where it was.
        let mut tied = joints.clone();
        tie_axes(&mut tied, &[vec![0, 1, 2, 3]], &[2, 3]);
        for j in &tied[..4] {
            assert!(j.axis[0].abs() < 1e-9 && (j.axis[1].abs() - 1.0).abs() < 1e-9);
        }
        // At 15° neither follows.
        assert!(followers(&joints, &groups, 15.0).is_empty());
    }

    #[test]
    fn related_groups_fitted_apart_join() {
        use JointType::Revolute as R;
        // Body 0: front legs 1, 2 at +4°, hind legs 3, 4 at −8° (12° apart); a chain
        // 10 → 11 → 12 on y related to neither.
        let joints = vec![
            joint(1, 0, R, tilted(4.0)),
            joint(2, 0, R, tilted(4.5)),
            joint(3, 0, R, tilted(-8.0)),
            joint(4, 0, R, tilted(-7.5)),
            joint(11, 10, R, tilted(0.0)),
            joint(12, 11, R, tilted(0.5)),
        ];
        let groups = vec![vec![0, 1], vec![2, 3], vec![4, 5]];
        assert_eq!(
            joined_groups(&joints, &groups, &[], FOLLOW_ANGLE_DEG),
            Some(vec![vec![0, 1, 2, 3], vec![4, 5]])
        );
        assert_eq!(joined_groups(&joints, &groups, &[], MAX_ANGLE_DEG), None);
    }

    #[test]
    fn a_wider_swing_weighs_more() {
        let mut joints = vec![
            joint(1, 0, JointType::Revolute, tilted(4.0)),
            joint(2, 0, JointType::Revolute, tilted(-4.0)),
        ];
        joints[1].state = vec![0.0, 0.9];
        tie_axes(&mut joints, &[vec![0, 1]], &[]);
        // Weights 0.09 and 0.81: the mean leans towards the second axis.
        let got = joints[0].axis[0].latan2(joints[0].axis[1]).to_degrees();
        assert!(got < -2.0 && got > -4.0, "{got}°");
        assert_eq!(joints[0].axis, joints[1].axis);
    }

    #[test]
    fn tied_axes_are_the_mean_direction_each_in_its_own_sense() {
        let mut joints = vec![
            joint(1, 0, JointType::Revolute, tilted(4.0)),
            joint(2, 0, JointType::Revolute, {
                let a = tilted(-2.0);
                [-a[0], -a[1], -a[2]]
            }),
        ];
        tie_axes(&mut joints, &[vec![0, 1]], &[]);
        let want = tilted(1.0);
        for (i, w) in want.iter().enumerate() {
            assert!((joints[0].axis[i] - w).abs() < 1e-12);
            assert!((joints[1].axis[i] + w).abs() < 1e-12);
        }
    }

    #[test]
    fn a_far_follower_gets_the_turns_of_its_link_about_the_new_axis() {
        use crate::geom::se3::rigid;
        // A round leg (part 1, below the hip at (0.3, 0, 0)) swings about y from a
        // still body (part 0); its Step-1 poses also spin it about its own long axis
        // by any amount, and its joint was fitted about another axis.
        let hip = DVec3::new(0.3, 0.0, 0.0);
        let swing = [0.0, 0.3, -0.2, 0.5, 0.1];
        let spin = [0.0, 1.9, -2.4, 0.7, 3.0];
        // Rings of 8 points about a long axis tilted out of the swing's plane: it is
        // exactly the leg's principal direction, and a spin about it is not a turn
        // about z (which the whole rotation's turn about y would ignore).
        let leg_axis = DVec3::new(0.0, 0.6, -0.8);
        let side = DVec3::X;
        let up = leg_axis.cross(side);
        let leg: Vec<DVec3> = (0..48)
            .map(|i| {
                let a = (i % 8) as f64 * std::f64::consts::FRAC_PI_4;
                let along = 0.02 + 0.03 * (i / 8) as f64;
                hip + leg_axis * along + (side * a.lcos() + up * a.lsin()) * 0.03
            })
            .collect();
        let centre = leg.iter().copied().sum::<DVec3>() / leg.len() as f64;
        let poses: Vec<Vec<DMat4>> = swing
            .iter()
            .zip(&spin)
            .map(|(&q, &s)| {
                let about = |axis: DVec3, angle: f64, at: DVec3| {
                    let r = DMat3::from_axis_angle(axis, angle);
                    rigid(r, at - r * at)
                };
                let m = about(DVec3::Y, q, hip) * about(leg_axis, s, centre);
                vec![DMat4::IDENTITY, m]
            })
            .collect();
        let mut joint = ResultJoint {
            mimic: None,
            child: 1,
            parent: 0,
            joint_type: JointType::Revolute,
            // Already tied to the group's direction (sense reversed), the pivot and
            // states still the old fit's.
            axis: [0.0, -1.0, 0.0],
            pivot: [0.25, 0.04, -0.1],
            state: spin.to_vec(),
            limits: [-2.4, 3.0],
        };
        reproject(&mut joint, &poses, &leg, 0, 0.0);
        for (got, want) in joint.state.iter().zip(&swing) {
            assert!((got + want).abs() < 1e-9, "{:?}", joint.state);
        }
        // On the hip's line along y (its y taken from the old pivot).
        let p = DVec3::from_array(joint.pivot);
        assert!((p - DVec3::new(0.3, 0.04, 0.0)).length() < 1e-9, "{p}");
        assert!((joint.limits[0] + 0.5).abs() < 1e-9 && (joint.limits[1] - 0.2).abs() < 1e-9);
    }
}
