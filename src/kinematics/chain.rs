//! Forward kinematics: the one convention used everywhere (page sliders, CLI
//! `articulate`, metrics, inverse kinematics of the re-animation error).
//!
//! Joint j has a unit axis ω and a pivot p (world frame at the reference frame);
//! its twist is S = (ω, −ω×p) for revolute and (0, ω) for prismatic joints. A part's
//! pose at joint states q is
//! `T_p(q) = root_motion · Π_{joints on the path root→p, in that order} exp([S_j] q_j)`.

use glam::{DMat3, DMat4, DVec3};

use crate::io::gt::{GroundTruth, JointType};
use crate::io::result::FitResult;
use crate::{Error, Result};

/// How far from unit length an axis may be before it is rejected (it is renormalised
/// otherwise): files written by other tools carry rounding.
const AXIS_UNIT_TOLERANCE: f64 = 1e-3;

/// The 1-DOF joint connecting a part to its parent.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JointSpec {
    pub joint_type: JointType,
    /// Unit axis, world frame at the reference frame.
    pub axis: DVec3,
    /// A point on the axis (revolute); the joint origin (prismatic, unused by FK).
    pub pivot: DVec3,
}

/// A kinematic tree of parts with at most one joint per non-root part.
/// Parts without a joint are rigidly attached to their parent.
#[derive(Debug, Clone, PartialEq)]
pub struct Chain {
    parent: Vec<i64>,
    /// `joints[p]`: the joint between part p and its parent (`None` for the root and
    /// for rigidly attached parts).
    joints: Vec<Option<JointSpec>>,
    /// Parts in an order where every parent precedes its children (root first).
    order: Vec<usize>,
    root: usize,
}

/// `exp([S] q)` in closed form (Rodrigues) for a unit axis.
pub fn screw_exp(joint_type: JointType, axis: DVec3, pivot: DVec3, q: f64) -> DMat4 {
    match joint_type {
        JointType::Revolute => {
            let r = DMat3::from_axis_angle(axis, q);
            // exp of (ω, −ω×p) is a rotation about the line through p: t = p − R p.
            let t = pivot - r * pivot;
            DMat4::from_cols(
                r.x_axis.extend(0.0),
                r.y_axis.extend(0.0),
                r.z_axis.extend(0.0),
                t.extend(1.0),
            )
        }
        JointType::Prismatic => DMat4::from_translation(axis * q),
    }
}

fn checked_axis(axis: DVec3, what: &str) -> Result<DVec3> {
    let n = axis.length();
    if !n.is_finite() || (n - 1.0).abs() > AXIS_UNIT_TOLERANCE {
        return Err(Error::InvalidArgument(format!(
            "{what}: axis {axis:?} is not a unit vector (length {n})"
        )));
    }
    Ok(axis / n)
}

impl Chain {
    /// Build a chain from a parent array and per-part joints. Validates: one root,
    /// parents in range, no cycles, finite unit axes and finite pivots.
    pub fn new(parent: Vec<i64>, joints: Vec<Option<JointSpec>>) -> Result<Chain> {
        let n = parent.len();
        let bad = |m: String| Error::InvalidArgument(format!("kinematic tree: {m}"));
        if n == 0 {
            return Err(bad("no parts".into()));
        }
        if joints.len() != n {
            return Err(bad(format!("{} parts but {} joint slots", n, joints.len())));
        }
        let mut root = None;
        let mut children: Vec<Vec<usize>> = vec![Vec::new(); n];
        for (p, &pa) in parent.iter().enumerate() {
            if pa < 0 {
                if pa != -1 {
                    return Err(bad(format!("part {p} has parent {pa}")));
                }
                if root.replace(p).is_some() {
                    return Err(bad("more than one root (parent −1)".into()));
                }
            } else if pa as u64 >= n as u64 || pa as usize == p {
                return Err(bad(format!("part {p} has invalid parent {pa}")));
            } else {
                children[pa as usize].push(p);
            }
        }
        let root = root.ok_or_else(|| bad("no root (parent −1)".into()))?;
        let mut order = Vec::with_capacity(n);
        order.push(root);
        let mut i = 0;
        while i < order.len() {
            order.extend_from_slice(&children[order[i]]);
            i += 1;
        }
        if order.len() != n {
            return Err(bad("the parent relation has a cycle".into()));
        }
        let mut joints = joints;
        if joints[root].is_some() {
            return Err(bad(format!("the root part {root} has a joint")));
        }
        for (p, j) in joints.iter_mut().enumerate() {
            if let Some(j) = j {
                j.axis = checked_axis(j.axis, &format!("joint of part {p}"))?;
                if !j.pivot.is_finite() {
                    return Err(bad(format!("joint of part {p} has a non-finite pivot")));
                }
            }
        }
        Ok(Chain {
            parent,
            joints,
            order,
            root,
        })
    }

    /// The chain of a result (`tree` and `joints`, frame c). Fails when the result has
    /// no tree, or when a joint disagrees with the tree.
    pub fn from_result(result: &FitResult) -> Result<Chain> {
        let tree = result
            .tree
            .as_ref()
            .ok_or_else(|| Error::InvalidArgument("the result has no kinematic tree".into()))?;
        let n = result.parts;
        if tree.parent.len() != n {
            return Err(Error::InvalidArgument(format!(
                "result tree has {} parents for {} parts",
                tree.parent.len(),
                n
            )));
        }
        if tree.root >= n || tree.parent[tree.root] != -1 {
            return Err(Error::InvalidArgument(format!(
                "result tree root {} is not a part with parent −1",
                tree.root
            )));
        }
        let mut joints: Vec<Option<JointSpec>> = vec![None; n];
        for j in result.joints.iter().flatten() {
            if j.child >= n || j.parent >= n {
                return Err(Error::InvalidArgument(format!(
                    "joint {}→{} refers to a part ≥ {n}",
                    j.parent, j.child
                )));
            }
            if tree.parent[j.child] != j.parent as i64 {
                return Err(Error::InvalidArgument(format!(
                    "joint {}→{} disagrees with the tree (parent of {} is {})",
                    j.parent, j.child, j.child, tree.parent[j.child]
                )));
            }
            if joints[j.child].is_some() {
                return Err(Error::InvalidArgument(format!(
                    "part {} has two joints",
                    j.child
                )));
            }
            joints[j.child] = Some(JointSpec {
                joint_type: j.joint_type,
                axis: DVec3::from(j.axis),
                pivot: DVec3::from(j.pivot),
            });
        }
        Chain::new(tree.parent.clone(), joints)
    }

    /// The chain of a ground truth, with axes and pivots at frame 0 (world). With
    /// `root_motion = poses[t][root]·inv(poses[0][root])` and states `q_t − q_0` it
    /// reproduces `poses[t][p]·inv(poses[0][p])`.
    pub fn from_gt(gt: &GroundTruth) -> Result<Chain> {
        let joints = gt
            .joints
            .iter()
            .map(|j| {
                j.as_ref().map(|j| JointSpec {
                    joint_type: j.joint_type,
                    axis: j.axis_world_frame0,
                    pivot: j.pivot_world_frame0,
                })
            })
            .collect();
        Chain::new(gt.parent.clone(), joints)
    }

    pub fn num_parts(&self) -> usize {
        self.parent.len()
    }
    pub fn root(&self) -> usize {
        self.root
    }
    pub fn parent(&self) -> &[i64] {
        &self.parent
    }
    pub fn joints(&self) -> &[Option<JointSpec>] {
        &self.joints
    }
    /// Parts with every parent before its children.
    pub fn order(&self) -> &[usize] {
        &self.order
    }

    /// Part poses at joint states `states[p]` (the state of the joint whose child is
    /// part p; entries of the root and of jointless parts are ignored).
    pub fn part_poses(&self, root_motion: &DMat4, states: &[f64]) -> Result<Vec<DMat4>> {
        let mut out = vec![DMat4::IDENTITY; self.num_parts()];
        self.part_poses_into(root_motion, states, &mut out)?;
        Ok(out)
    }

    /// Allocation-free [`Chain::part_poses`]: writes into `out` (length = parts).
    pub fn part_poses_into(
        &self,
        root_motion: &DMat4,
        states: &[f64],
        out: &mut [DMat4],
    ) -> Result<()> {
        let n = self.num_parts();
        if states.len() != n || out.len() != n {
            return Err(Error::InvalidArgument(format!(
                "forward kinematics: {} parts but {} states and {} outputs",
                n,
                states.len(),
                out.len()
            )));
        }
        for &p in &self.order {
            let base = if p == self.root {
                *root_motion
            } else {
                // `order` puts parents first, so out[parent] is final.
                out[self.parent[p] as usize]
            };
            out[p] = match &self.joints[p] {
                Some(j) => base * screw_exp(j.joint_type, j.axis, j.pivot, states[p]),
                None => base,
            };
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rev(axis: DVec3, pivot: DVec3) -> Option<JointSpec> {
        Some(JointSpec {
            joint_type: JointType::Revolute,
            axis,
            pivot,
        })
    }

    #[test]
    fn revolute_exp_rotates_about_pivot() {
        let m = screw_exp(
            JointType::Revolute,
            DVec3::Z,
            DVec3::new(1.0, 0.0, 0.0),
            std::f64::consts::FRAC_PI_2,
        );
        // The pivot stays; (2,0,0) goes to (1,1,0).
        assert!(m
            .transform_point3(DVec3::new(1.0, 0.0, 0.0))
            .abs_diff_eq(DVec3::new(1.0, 0.0, 0.0), 1e-12));
        assert!(m
            .transform_point3(DVec3::new(2.0, 0.0, 0.0))
            .abs_diff_eq(DVec3::new(1.0, 1.0, 0.0), 1e-12));
    }

    #[test]
    fn prismatic_exp_translates() {
        let m = screw_exp(
            JointType::Prismatic,
            DVec3::Y,
            DVec3::new(5.0, 5.0, 5.0),
            0.3,
        );
        assert!(m
            .transform_point3(DVec3::ZERO)
            .abs_diff_eq(DVec3::new(0.0, 0.3, 0.0), 1e-15));
    }

    #[test]
    fn two_link_planar_arm() {
        // Root 0, part 1 about z through origin, part 2 about z through (1,0,0).
        let chain = Chain::new(
            vec![-1, 0, 1],
            vec![
                None,
                rev(DVec3::Z, DVec3::ZERO),
                rev(DVec3::Z, DVec3::new(1.0, 0.0, 0.0)),
            ],
        )
        .unwrap();
        let h = std::f64::consts::FRAC_PI_2;
        let poses = chain.part_poses(&DMat4::IDENTITY, &[0.0, h, h]).unwrap();
        // Tip of link 2 at (2,0,0) ends at (−1,1,0) after +90° at both joints.
        let tip = poses[2].transform_point3(DVec3::new(2.0, 0.0, 0.0));
        assert!(tip.abs_diff_eq(DVec3::new(-1.0, 1.0, 0.0), 1e-12), "{tip}");
        // Root motion composes on the left.
        let rm = DMat4::from_translation(DVec3::new(0.0, 0.0, 3.0));
        let poses = chain.part_poses(&rm, &[0.0, h, h]).unwrap();
        let tip = poses[2].transform_point3(DVec3::new(2.0, 0.0, 0.0));
        assert!(tip.abs_diff_eq(DVec3::new(-1.0, 1.0, 3.0), 1e-12));
    }

    #[test]
    fn rejects_bad_trees() {
        let j = rev(DVec3::Z, DVec3::ZERO);
        assert!(Chain::new(vec![-1, 2, 1], vec![None, j, j]).is_err()); // cycle
        assert!(Chain::new(vec![-1, 5], vec![None, j]).is_err()); // out of range
        assert!(Chain::new(vec![-1, -1], vec![None, None]).is_err()); // two roots
        assert!(Chain::new(vec![0, 0], vec![None, None]).is_err()); // no root
        assert!(Chain::new(
            vec![-1, 0],
            vec![None, rev(DVec3::new(0.0, 0.0, 2.0), DVec3::ZERO)]
        )
        .is_err());
        assert!(Chain::new(vec![-1, 0], vec![None, rev(DVec3::Z, DVec3::NAN)]).is_err());
        assert!(Chain::new(vec![-1, 0], vec![None]).is_err());
        assert!(Chain::new(vec![], vec![]).is_err());
        let c = Chain::new(vec![-1, 0], vec![None, j]).unwrap();
        assert!(c.part_poses(&DMat4::IDENTITY, &[0.0]).is_err());
    }

    #[test]
    fn slightly_non_unit_axis_is_renormalised() {
        let c = Chain::new(
            vec![-1, 0],
            vec![None, rev(DVec3::new(0.0, 0.0, 1.0004), DVec3::ZERO)],
        )
        .unwrap();
        let a = c.joints()[1].unwrap().axis;
        assert!((a.length() - 1.0).abs() < 1e-15);
    }
}
