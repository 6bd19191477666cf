//! Joint projection (paper §3.3): project the part poses onto the kinematic chain.
//!
//! Walking the tree from the root, each child b of a parent a gets the 1-DOF screw that
//! best explains Qᵏ = (Âₐᵏ)⁻¹ A_bᵏ, where A_bᵏ = T_bᵏ (T_bᶜ)⁻¹ is the observed motion of b
//! from the canonical frame c and Âₐᵏ is the parent's pose *as produced by the chain
//! so far* (not the observed one): errors then do not accumulate down the chain, and the
//! output poses are exactly the forward kinematics of the output joints
//! (root_motion · Π exp([Sⱼ] qⱼ)).

use glam::DMat4;
use serde::Serialize;

use super::chain::screw_exp;
use super::screw::{fit_screw_as, one_dof_loss, padded_limits, PartExtent};
use crate::geom::se3::{rigid_inverse, to_row_major};
use crate::io::gt::JointType;
use crate::io::result::{FitResult, ResultJoint, ResultTree, FORMAT, VERSION};

/// How well a joint explains its part's observed motion.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct JointResidual {
    pub child: usize,
    pub parent: usize,
    pub joint_type: JointType,
    /// L_1DOF of the chosen type, and of both types.
    pub loss: f64,
    pub loss_revolute: f64,
    pub loss_prismatic: f64,
}

/// Motions Aₚᵏ = Tₚᵏ (Tₚᶜ)⁻¹ of every part from the canonical frame (`[k][p]`).
pub fn motions_from_canonical(poses: &[Vec<DMat4>], canonical: usize) -> Vec<Vec<DMat4>> {
    let inv: Vec<DMat4> = poses[canonical].iter().map(rigid_inverse).collect();
    poses
        .iter()
        .map(|f| f.iter().zip(&inv).map(|(t, i)| *t * *i).collect())
        .collect()
}

/// Parts in breadth-first order from the root (parents before children).
pub fn bfs_order(parent: &[i64]) -> Vec<usize> {
    let n = parent.len();
    let mut order: Vec<usize> = (0..n).filter(|&p| parent[p] < 0).collect();
    let mut i = 0;
    while i < order.len() {
        let a = order[i] as i64;
        order.extend((0..n).filter(|&b| parent[b] == a));
        i += 1;
    }
    order
}

/// Project `poses[k][p]` (world poses of the merged parts) onto the tree `parent`
/// (exactly one root, −1). `extents[p]`: centroid and radius of part p at frame c (places pivots,
/// scales the type test).
/// `limit_pad`: joint limits are [min, max] of the states widened by this fraction of
/// their range on each side. `given_types[p]`: the type of the joint whose child is p
/// when chosen by hand (`crate::edit`), else decided by the type rule (`None`, or an
/// empty slice for all). Returns the complete result (labels as given) and the
/// per-joint residuals.
pub fn project_joints(
    poses: &[Vec<DMat4>],
    parent: &[i64],
    canonical: usize,
    extents: &[PartExtent],
    labels: Vec<Vec<u32>>,
    limit_pad: f64,
    given_types: &[Option<JointType>],
) -> crate::Result<(FitResult, Vec<JointResidual>)> {
    let n = parent.len();
    let k = poses.len();
    let order = bfs_order(parent);
    let roots: Vec<usize> = (0..n).filter(|&p| parent[p] < 0).collect();
    if roots.len() != 1 || order.len() != n || canonical >= k {
        return Err(crate::Error::InvalidArgument(format!(
            "joint projection needs a tree with one root over {n} parts and a canonical frame < {k}"
        )));
    }
    let root = roots[0];
    let observed = motions_from_canonical(poses, canonical);
    let mut fk: Vec<Vec<DMat4>> = vec![vec![DMat4::IDENTITY; n]; k];
    for (f, o) in fk.iter_mut().zip(&observed) {
        f[root] = o[root];
    }
    let mut joints = Vec::new();
    let mut residuals = Vec::new();
    for &b in order.iter().skip(1) {
        let a = parent[b] as usize;
        let rel: Vec<DMat4> = (0..k)
            .map(|t| rigid_inverse(&fk[t][a]) * observed[t][b])
            .collect();
        let mut fit = fit_screw_as(&rel, extents[b], given_types.get(b).copied().flatten());
        fit.states[canonical] = 0.0;
        let loss = one_dof_loss(&rel, fit.joint_type, fit.axis, fit.pivot, &fit.states);
        for (f, &s) in fk.iter_mut().zip(&fit.states) {
            f[b] = f[a] * screw_exp(fit.joint_type, fit.axis, fit.pivot, s);
        }
        residuals.push(JointResidual {
            child: b,
            parent: a,
            joint_type: fit.joint_type,
            loss,
            loss_revolute: fit.loss_revolute,
            loss_prismatic: fit.loss_prismatic,
        });
        joints.push(ResultJoint {
            mimic: None,
            child: b,
            parent: a,
            joint_type: fit.joint_type,
            axis: fit.axis.to_array(),
            pivot: fit.pivot.to_array(),
            limits: padded_limits(&fit.states, limit_pad),
            state: fit.states,
        });
    }
    joints.sort_by_key(|j| j.child);
    residuals.sort_by_key(|r| r.child);
    let result = FitResult {
        format: FORMAT.to_string(),
        version: VERSION,
        frames: k,
        canonical_frame: canonical,
        parts: n,
        labels,
        poses: fk
            .iter()
            .map(|f| f.iter().map(to_row_major).collect())
            .collect(),
        gaussians: None,
        tree: Some(ResultTree {
            root,
            parent: parent.to_vec(),
        }),
        joints: Some(joints),
        root_motion: Some(fk.iter().map(|f| to_row_major(&f[root])).collect()),
        points: None,
        info: None,
    };
    Ok((result, residuals))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::se3::from_row_major;
    use glam::DVec3;

    #[test]
    fn projection_reproduces_an_exact_chain() {
        // root moves, 1 revolute on 0, 2 prismatic on 1
        let k = 4;
        let ax1 = DVec3::new(0.0, 0.6, 0.8);
        let pv1 = DVec3::new(0.1, 0.0, 0.0);
        let ax2 = DVec3::new(1.0, 0.0, 0.0);
        let base = DMat4::from_translation(DVec3::new(0.3, 0.2, 0.1));
        let poses: Vec<Vec<DMat4>> = (0..k)
            .map(|t| {
                let s = t as f64;
                let r = DMat4::from_translation(DVec3::Z * 0.05 * s) * base;
                let m1 = screw_exp(JointType::Revolute, ax1, pv1, 0.3 * s);
                let m2 = screw_exp(JointType::Prismatic, ax2, DVec3::ZERO, 0.1 * s);
                let a0 = DMat4::from_translation(DVec3::Z * 0.05 * s);
                vec![r, a0 * m1 * base, a0 * m1 * m2 * base]
            })
            .collect();
        let (res, resid) = project_joints(
            &poses,
            &[-1, 0, 1],
            0,
            &[PartExtent::default(); 3],
            vec![vec![]; k],
            0.0,
            &[],
        )
        .unwrap();
        assert!(resid.iter().all(|r| r.loss < 1e-18));
        let joints = res.joints.as_ref().unwrap();
        assert_eq!(joints[0].joint_type, JointType::Revolute);
        assert_eq!(joints[1].joint_type, JointType::Prismatic);
        let c = motions_from_canonical(&poses, 0);
        for (rf, cf) in res.poses.iter().zip(&c) {
            for (r, m) in rf.iter().zip(cf) {
                assert!(from_row_major(r).abs_diff_eq(*m, 1e-9));
            }
        }
        // A type given by hand is the type the joint gets, with its own (worse) fit.
        let given = [None, Some(JointType::Prismatic), None];
        let (typed, resid) = project_joints(
            &poses,
            &[-1, 0, 1],
            0,
            &[PartExtent::default(); 3],
            vec![vec![]; k],
            0.0,
            &given,
        )
        .unwrap();
        let joints = typed.joints.as_ref().unwrap();
        assert_eq!(joints[0].joint_type, JointType::Prismatic);
        assert!(
            resid[0].loss > 1e-6,
            "a hinge fitted as a slide leaves a residual"
        );
    }
}
