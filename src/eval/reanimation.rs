//! Re-animation error of SPEC §5: can the predicted articulated model reach novel
//! (held-out) poses?
//!
//! Exact definition. Let c be the result's canonical frame, `x` its observed points
//! with predicted part `a(x)` and ground-truth part `g(x)`. For every ground-truth part
//! g with points, its anchor is the point of part g nearest to the centroid of part g.
//! For every held-out pose h:
//! - the ground-truth position of a point is `y_h(x) = heldout_poses[h][g] · inv(poses[c][g]) · x`;
//! - the predicted model's joint states q (one per joint) are fitted to minimise the
//!   mean over anchors of `‖T_{a(x)}(q) · x − y_h(x)‖²` with the root pose fixed at the
//!   result's root pose of frame 0 (the benchmark's held-out root pose is frame 0's):
//!   Adam (lr 0.1, β = (0.9, 0.999), ε = 1e-8, 200 steps, analytic gradients of the
//!   forward kinematics) from q = 0 (the canonical configuration) as SPEC §5 says;
//! - the error is the mean over *all* points of `‖T_{a(x)}(q) · x − y_h(x)‖`.
//!
//! The reported value is 100 × the mean over held-out poses.
//!
//! Deviation (default [`IkOptions`]): Adam from zero alone leaves even the exact
//! ground-truth model far from held-out poses with large joint angles (measured on
//! bench-dev: finger_edu 1.16, xarm7 2.26, talos 0.14 — the optimiser falls into local
//! minima of the anchor loss and 200 steps at lr 0.1 do not settle), which measures
//! the optimiser, not the model. So the same Adam run is also started from a
//! sequential initialisation (joints in tree order, each set by a 1-D grid search on
//! the anchors of its child part), both runs are polished with Levenberg–Marquardt on
//! the same anchor loss, and the run with the lower anchor loss is kept. Nothing but
//! the anchors (one point per GT part) guides the fit. [`IkOptions::spec_strict`] gives
//! the plain SPEC protocol.

use glam::{DMat4, DVec3, Vec3};
use nalgebra::{DMatrix, DVector};

use crate::geom::se3::rigid_inverse;
use crate::io::gt::{GroundTruth, JointType};
use crate::kinematics::chain::Chain;
use crate::{Error, Result};

const BETA1: f64 = 0.9;
const BETA2: f64 = 0.999;
const EPS: f64 = 1e-8;
/// Grid of the sequential initialisation for revolute joints.
const INIT_GRID: usize = 72;

/// How joint states are fitted to the anchors.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IkOptions {
    /// Adam learning rate (SPEC: 0.1).
    pub lr: f64,
    /// Adam steps (SPEC: 200).
    pub steps: usize,
    /// Also start from the sequential tree-order initialisation (deviation, see module doc).
    pub sequential_init: bool,
    /// Levenberg–Marquardt iterations after Adam (0: none).
    pub polish_iterations: usize,
}

impl Default for IkOptions {
    fn default() -> Self {
        IkOptions {
            lr: 0.1,
            steps: 200,
            sequential_init: true,
            polish_iterations: 30,
        }
    }
}

impl IkOptions {
    /// The plain SPEC §5 protocol: Adam lr 0.1, 200 steps, from zero, nothing else.
    pub fn spec_strict() -> Self {
        IkOptions {
            sequential_init: false,
            polish_iterations: 0,
            ..Self::default()
        }
    }
}

/// One anchor: a canonical point and its predicted part.
struct Anchor {
    x: DVec3,
    part: usize,
}

/// Re-animation error (×100, mean over held-out poses) of the predicted `chain` whose
/// root pose at frame 0 is `root_pose0`, on canonical `points` with predicted labels
/// `pred` and ground-truth labels `gt_labels`, against the held-out poses of `gt`.
/// `canonical` is the result's canonical frame. Default [`IkOptions`].
pub fn reanimation_error(
    chain: &Chain,
    root_pose0: &DMat4,
    gt: &GroundTruth,
    canonical: usize,
    points: &[Vec3],
    pred: &[u32],
    gt_labels: &[u32],
) -> Result<f64> {
    let per_pose = reanimation_errors_with(
        chain,
        root_pose0,
        gt,
        canonical,
        points,
        pred,
        gt_labels,
        &IkOptions::default(),
    )?;
    Ok(per_pose.iter().sum::<f64>() / per_pose.len() as f64)
}

/// [`reanimation_error`] per held-out pose (×100 each), with explicit IK options.
/// Fails when there are no held-out poses or the inputs disagree.
#[allow(clippy::too_many_arguments)]
pub fn reanimation_errors_with(
    chain: &Chain,
    root_pose0: &DMat4,
    gt: &GroundTruth,
    canonical: usize,
    points: &[Vec3],
    pred: &[u32],
    gt_labels: &[u32],
    opts: &IkOptions,
) -> Result<Vec<f64>> {
    let n = points.len();
    let parts = chain.num_parts();
    if n == 0 || pred.len() != n || gt_labels.len() != n {
        return Err(Error::InvalidArgument(format!(
            "re-animation error: {n} points, {} predicted and {} ground-truth labels",
            pred.len(),
            gt_labels.len()
        )));
    }
    if gt.heldout_poses.is_empty() {
        return Err(Error::InvalidArgument(
            "re-animation error: the ground truth has no held-out poses".into(),
        ));
    }
    if canonical >= gt.num_frames() {
        return Err(Error::InvalidArgument(format!(
            "re-animation error: canonical frame {canonical} ≥ {} frames",
            gt.num_frames()
        )));
    }
    if pred.iter().any(|&l| l as usize >= parts)
        || gt_labels.iter().any(|&l| l as usize >= gt.num_parts)
    {
        return Err(Error::InvalidArgument(
            "re-animation error: a label is out of range".into(),
        ));
    }
    if gt.heldout_poses.iter().any(|h| h.len() != gt.num_parts) {
        return Err(Error::InvalidArgument(
            "re-animation error: a held-out pose does not have a pose per part".into(),
        ));
    }

    // Anchors: per GT part the point nearest to the part's centroid.
    let g_parts = gt.num_parts;
    let mut sum = vec![DVec3::ZERO; g_parts];
    let mut count = vec![0usize; g_parts];
    for (p, &g) in points.iter().zip(gt_labels) {
        sum[g as usize] += p.as_dvec3();
        count[g as usize] += 1;
    }
    let mut nearest: Vec<Option<(f64, usize)>> = vec![None; g_parts];
    for (i, (p, &g)) in points.iter().zip(gt_labels).enumerate() {
        let g = g as usize;
        let d = (p.as_dvec3() - sum[g] / count[g] as f64).length_squared();
        if nearest[g].is_none_or(|(best, _)| d < best) {
            nearest[g] = Some((d, i));
        }
    }
    let (anchors, anchor_gt): (Vec<Anchor>, Vec<usize>) = nearest
        .iter()
        .enumerate()
        .filter_map(|(g, a)| {
            a.map(|(_, i)| {
                (
                    Anchor {
                        x: points[i].as_dvec3(),
                        part: pred[i] as usize,
                    },
                    g,
                )
            })
        })
        .unzip();

    let gt_inv_c: Vec<DMat4> = gt.poses[canonical].iter().map(rigid_inverse).collect();
    let mut gt_rel = vec![DMat4::IDENTITY; g_parts];
    let mut ik = Ik {
        chain,
        root: *root_pose0,
        anchors: &anchors,
        targets: vec![DVec3::ZERO; anchors.len()],
        poses: vec![DMat4::IDENTITY; parts],
        grad: vec![0.0; parts],
    };
    let mut out = Vec::with_capacity(gt.heldout_poses.len());
    for held in &gt.heldout_poses {
        for ((r, h), ic) in gt_rel.iter_mut().zip(held).zip(&gt_inv_c) {
            *r = *h * *ic;
        }
        for (t, (a, &g)) in ik.targets.iter_mut().zip(anchors.iter().zip(&anchor_gt)) {
            *t = gt_rel[g].transform_point3(a.x);
        }
        let mut q = vec![0.0; parts];
        ik.adam(&mut q, opts)?;
        ik.polish(&mut q, opts.polish_iterations)?;
        if opts.sequential_init {
            let mut q2 = ik.sequential_init()?;
            ik.adam(&mut q2, opts)?;
            ik.polish(&mut q2, opts.polish_iterations)?;
            if ik.loss(&q2)? < ik.loss(&q)? {
                q = q2;
            }
        }
        chain.part_poses_into(root_pose0, &q, &mut ik.poses)?;
        let mut err = 0.0;
        for ((p, &a), &g) in points.iter().zip(pred).zip(gt_labels) {
            let x = p.as_dvec3();
            err += (ik.poses[a as usize].transform_point3(x)
                - gt_rel[g as usize].transform_point3(x))
            .length();
        }
        out.push(100.0 * err / n as f64);
    }
    Ok(out)
}

/// Inverse kinematics on the anchors of one held-out pose, with scratch buffers.
struct Ik<'a> {
    chain: &'a Chain,
    root: DMat4,
    anchors: &'a [Anchor],
    targets: Vec<DVec3>,
    poses: Vec<DMat4>,
    grad: Vec<f64>,
}

impl Ik<'_> {
    /// Mean over anchors of the squared distance to the target.
    fn loss(&mut self, q: &[f64]) -> Result<f64> {
        self.chain.part_poses_into(&self.root, q, &mut self.poses)?;
        Ok(self.loss_at_poses())
    }

    fn loss_at_poses(&self) -> f64 {
        let s: f64 = self
            .anchors
            .iter()
            .zip(&self.targets)
            .map(|(a, t)| (self.poses[a.part].transform_point3(a.x) - *t).length_squared())
            .sum();
        s / self.anchors.len().max(1) as f64
    }

    /// Derivative of the world position `y` of a point on part `part` with respect to
    /// the state of every joint on the path to the root: calls `f(joint part, dy)`.
    fn for_each_derivative(&self, part: usize, y: DVec3, mut f: impl FnMut(usize, DVec3)) {
        let parent = self.chain.parent();
        let mut p = part;
        while parent[p] >= 0 {
            let pp = parent[p] as usize;
            if let Some(j) = &self.chain.joints()[p] {
                // The joint's current world axis is the parent's pose applied to it.
                let axis = self.poses[pp].transform_vector3(j.axis);
                let dy = match j.joint_type {
                    JointType::Revolute => axis.cross(y - self.poses[pp].transform_point3(j.pivot)),
                    JointType::Prismatic => axis,
                };
                f(p, dy);
            }
            p = pp;
        }
    }

    /// Gradient of [`Ik::loss`] into `self.grad`, at the poses in `self.poses`.
    fn gradient(&mut self) {
        let mut grad = std::mem::take(&mut self.grad);
        grad.fill(0.0);
        let scale = 2.0 / self.anchors.len().max(1) as f64;
        for (a, t) in self.anchors.iter().zip(&self.targets) {
            let y = self.poses[a.part].transform_point3(a.x);
            let r = (y - *t) * scale;
            self.for_each_derivative(a.part, y, |p, dy| grad[p] += r.dot(dy));
        }
        self.grad = grad;
    }

    fn adam(&mut self, q: &mut [f64], opts: &IkOptions) -> Result<()> {
        let n = q.len();
        let mut m1 = vec![0.0; n];
        let mut m2 = vec![0.0; n];
        for step in 1..=opts.steps {
            self.chain.part_poses_into(&self.root, q, &mut self.poses)?;
            self.gradient();
            let b1 = 1.0 - BETA1.powi(step as i32);
            let b2 = 1.0 - BETA2.powi(step as i32);
            for i in 0..n {
                let g = self.grad[i];
                m1[i] = BETA1 * m1[i] + (1.0 - BETA1) * g;
                m2[i] = BETA2 * m2[i] + (1.0 - BETA2) * g * g;
                q[i] -= opts.lr * (m1[i] / b1) / ((m2[i] / b2).sqrt() + EPS);
            }
        }
        Ok(())
    }

    /// Levenberg–Marquardt on the anchor residuals.
    fn polish(&mut self, q: &mut [f64], iterations: usize) -> Result<()> {
        let n = q.len();
        let rows = 3 * self.anchors.len();
        if iterations == 0 || rows == 0 {
            return Ok(());
        }
        let mut lambda = 1e-3;
        let mut current = self.loss(q)?;
        let mut trial = vec![0.0; n];
        for _ in 0..iterations {
            // self.poses holds FK(q) here.
            let mut jac = DMatrix::<f64>::zeros(rows, n);
            let mut res = DVector::<f64>::zeros(rows);
            for (i, (a, t)) in self.anchors.iter().zip(&self.targets).enumerate() {
                let y = self.poses[a.part].transform_point3(a.x);
                let r = y - *t;
                for k in 0..3 {
                    res[3 * i + k] = r[k];
                }
                self.for_each_derivative(a.part, y, |p, dy| {
                    for k in 0..3 {
                        jac[(3 * i + k, p)] = dy[k];
                    }
                });
            }
            let jtj = jac.transpose() * &jac;
            let jtr = jac.transpose() * &res;
            let mut improved = false;
            while lambda < 1e12 {
                let mut a = jtj.clone();
                for d in 0..n {
                    a[(d, d)] += lambda * (jtj[(d, d)] + 1e-12) + 1e-15;
                }
                let Some(chol) = a.cholesky() else {
                    lambda *= 10.0;
                    continue;
                };
                let delta = chol.solve(&jtr);
                for d in 0..n {
                    trial[d] = q[d] - delta[d];
                }
                let l = self.loss(&trial)?;
                if l < current {
                    q.copy_from_slice(&trial);
                    current = l;
                    lambda = (lambda * 0.1).max(1e-12);
                    improved = true;
                    break;
                }
                lambda *= 10.0;
            }
            // Leave self.poses at FK(q) for the next Jacobian.
            self.loss(q)?;
            if !improved || current < 1e-24 {
                break;
            }
        }
        Ok(())
    }

    /// Joints in tree order, each set by a 1-D search on the anchors of its child part
    /// (or of its whole subtree when the child's anchors lie on the axis), the joints
    /// below it still at 0.
    fn sequential_init(&mut self) -> Result<Vec<f64>> {
        let chain = self.chain;
        let n = chain.num_parts();
        let mut q = vec![0.0; n];
        // in_subtree[p][a]: anchor a's part lies in the subtree of part p.
        let parent = chain.parent();
        let in_subtree = |p: usize, mut a: usize| loop {
            if a == p {
                return true;
            }
            if parent[a] < 0 {
                return false;
            }
            a = parent[a] as usize;
        };
        let mut chosen: Vec<usize> = Vec::new();
        for &p in chain.order().iter().skip(1) {
            let Some(j) = chain.joints()[p] else { continue };
            chain.part_poses_into(&self.root, &q, &mut self.poses)?;
            let pp = parent[p] as usize;
            let axis = self.poses[pp].transform_vector3(j.axis);
            let pivot = self.poses[pp].transform_point3(j.pivot);
            // Anchors directly on the child part and off the axis, else the subtree's.
            chosen.clear();
            for (i, a) in self.anchors.iter().enumerate() {
                if a.part == p {
                    let y = self.poses[p].transform_point3(a.x);
                    let off = (y - pivot).cross(axis).length();
                    if j.joint_type == JointType::Prismatic || off > 1e-3 {
                        chosen.push(i);
                    }
                }
            }
            if chosen.is_empty() {
                chosen.extend(
                    (0..self.anchors.len()).filter(|&i| in_subtree(p, self.anchors[i].part)),
                );
            }
            if chosen.is_empty() {
                continue;
            }
            match j.joint_type {
                JointType::Prismatic => {
                    // Every chosen point moves by q·axis: least squares in closed form.
                    let s: f64 = chosen
                        .iter()
                        .map(|&i| {
                            let a = &self.anchors[i];
                            (self.targets[i] - self.poses[a.part].transform_point3(a.x)).dot(axis)
                        })
                        .sum();
                    q[p] = s / chosen.len() as f64;
                }
                JointType::Revolute => {
                    let mut best = (f64::INFINITY, 0.0);
                    for k in 0..INIT_GRID {
                        let theta = -std::f64::consts::PI
                            + 2.0 * std::f64::consts::PI * k as f64 / INIT_GRID as f64;
                        q[p] = theta;
                        chain.part_poses_into(&self.root, &q, &mut self.poses)?;
                        let l: f64 = chosen
                            .iter()
                            .map(|&i| {
                                let a = &self.anchors[i];
                                (self.poses[a.part].transform_point3(a.x) - self.targets[i])
                                    .length_squared()
                            })
                            .sum();
                        if l < best.0 {
                            best = (l, theta);
                        }
                    }
                    q[p] = best.1;
                }
            }
        }
        Ok(q)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kinematics::chain::JointSpec;

    fn two_link() -> Chain {
        Chain::new(
            vec![-1, 0, 1],
            vec![
                None,
                Some(JointSpec {
                    joint_type: JointType::Revolute,
                    axis: DVec3::Z,
                    pivot: DVec3::ZERO,
                }),
                Some(JointSpec {
                    joint_type: JointType::Prismatic,
                    axis: DVec3::X,
                    pivot: DVec3::ZERO,
                }),
            ],
        )
        .unwrap()
    }

    #[test]
    fn gradient_matches_finite_differences() {
        let chain = two_link();
        let anchors = vec![
            Anchor {
                x: DVec3::new(0.5, 0.2, 0.1),
                part: 1,
            },
            Anchor {
                x: DVec3::new(1.0, -0.3, 0.0),
                part: 2,
            },
        ];
        let mut ik = Ik {
            chain: &chain,
            root: DMat4::from_translation(DVec3::new(0.1, 0.0, 0.0)),
            anchors: &anchors,
            targets: vec![DVec3::new(0.1, 0.4, 0.1), DVec3::new(0.2, 0.9, -0.1)],
            poses: vec![DMat4::IDENTITY; 3],
            grad: vec![0.0; 3],
        };
        let q = [0.0, 0.7, 0.2];
        ik.loss(&q).unwrap();
        ik.gradient();
        let g = ik.grad.clone();
        for i in 1..3 {
            let h = 1e-6;
            let mut qp = q;
            qp[i] += h;
            let mut qm = q;
            qm[i] -= h;
            let fd = (ik.loss(&qp).unwrap() - ik.loss(&qm).unwrap()) / (2.0 * h);
            assert!((fd - g[i]).abs() < 1e-6, "joint {i}: {fd} vs {}", g[i]);
        }
        assert_eq!(g[0], 0.0);
        // Levenberg–Marquardt drives a reachable target to zero loss.
        let truth = [0.0, -2.5, 0.15];
        ik.loss(&truth).unwrap();
        let reach: Vec<DVec3> = anchors
            .iter()
            .map(|a| ik.poses[a.part].transform_point3(a.x))
            .collect();
        ik.targets = reach;
        let mut q0 = ik.sequential_init().unwrap();
        ik.polish(&mut q0, 30).unwrap();
        assert!(ik.loss(&q0).unwrap() < 1e-20);
        assert!((q0[1] - truth[1]).abs() < 1e-8 && (q0[2] - truth[2]).abs() < 1e-8);
    }

    fn gt_for(chain: &Chain, states: &[Vec<f64>], held: &[Vec<f64>]) -> GroundTruth {
        let fk = |q: &Vec<f64>| chain.part_poses(&DMat4::IDENTITY, q).unwrap();
        GroundTruth {
            sequence: "t".into(),
            num_parts: 3,
            parent: vec![-1, 0, 1],
            poses: states.iter().map(fk).collect(),
            joints: vec![None, None, None],
            heldout_frames: vec![],
            heldout_poses: held.iter().map(fk).collect(),
            variant: "full".into(),
            frames: vec![],
        }
    }

    fn cloud() -> (Vec<Vec3>, Vec<u32>) {
        let mut pts = Vec::new();
        let mut lab = Vec::new();
        for i in 0..30 {
            let s = i as f32 / 30.0;
            pts.push(Vec3::new(-0.2 + 0.1 * s, 0.05 * s, 0.0));
            lab.push(0);
            pts.push(Vec3::new(0.1 + 0.3 * s, 0.02, 0.01 * s));
            lab.push(1);
            pts.push(Vec3::new(0.5 + 0.2 * s, -0.03, 0.02));
            lab.push(2);
        }
        (pts, lab)
    }

    #[test]
    fn exact_model_reanimates_and_wrong_model_does_not() {
        let chain = two_link();
        let gt = gt_for(
            &chain,
            &[vec![0.0, 0.0, 0.0], vec![0.0, 0.3, 0.05]],
            &[vec![0.0, 0.8, 0.1], vec![0.0, -0.5, 0.02]],
        );
        let (pts, lab) = cloud();
        let e = reanimation_error(&chain, &DMat4::IDENTITY, &gt, 0, &pts, &lab, &lab).unwrap();
        assert!(e < 0.05, "exact model: {e}");
        // A model whose part 2 is welded to part 1 cannot slide it.
        let welded = Chain::new(vec![-1, 0, 1], vec![None, chain.joints()[1], None]).unwrap();
        let e2 = reanimation_error(&welded, &DMat4::IDENTITY, &gt, 0, &pts, &lab, &lab).unwrap();
        assert!(e2 > 1.0, "welded model: {e2}");
    }

    #[test]
    fn rejects_bad_inputs() {
        let chain = two_link();
        let mut gt = gt_for(&chain, &[vec![0.0; 3], vec![0.0; 3]], &[vec![0.0; 3]]);
        let (pts, lab) = cloud();
        assert!(
            reanimation_error(&chain, &DMat4::IDENTITY, &gt, 0, &pts, &lab[1..], &lab).is_err()
        );
        assert!(reanimation_error(&chain, &DMat4::IDENTITY, &gt, 5, &pts, &lab, &lab).is_err());
        let bad: Vec<u32> = lab.iter().map(|&l| l + 3).collect();
        assert!(reanimation_error(&chain, &DMat4::IDENTITY, &gt, 0, &pts, &bad, &lab).is_err());
        gt.heldout_poses.clear();
        assert!(reanimation_error(&chain, &DMat4::IDENTITY, &gt, 0, &pts, &lab, &lab).is_err());
    }
}
