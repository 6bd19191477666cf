//! 1-DOF screw fits of the relative motion of two parts (paper supplement,
//! "Kinematic tree estimation"): the best revolute (fixed axis and pivot, one angle per
//! frame) and the best prismatic (fixed axis, one displacement per frame) explanation of
//! a sequence of relative poses, and the deviation L_1DOF = Σₖ ‖Qₖ Sₖ⁻¹ − I‖²_F.
//!
//! Relative motions are taken with respect to the canonical frame c:
//! Qₖ = (Aᵢᵏ)⁻¹ Aⱼᵏ with Aᵖᵏ = Tₚᵏ (Tₚᶜ)⁻¹. For a parent i and child j joined by a
//! 1-DOF joint, Qₖ = exp([S] qₖ) with a twist S that is *fixed* in world coordinates at
//! frame c. (The paper writes L_1DOF with consecutive motions Oᵏ; the world-frame axis of
//! (Oᵢᵏ)⁻¹Oⱼᵏ moves with the parent, so a fixed-axis fit only holds in the canonical
//! form used here. For a static parent both forms agree.)
//!
//! **Deviations:** L_1DOF sums the frames left after setting aside the worst-explained
//! fifth (`OUTLIER_FRACTION`), and the tree may take a hinge fit restarted from each
//! frame's own turn (`revolute_restart`): a Step-1 pose flipped half a turn in one frame
//! otherwise decides a pair's fit.

use crate::math::Libm;
use glam::{DMat3, DMat4, DQuat, DVec3};
use nalgebra::{Matrix3, SymmetricEigen, Vector3};

use super::chain::screw_exp;
use crate::geom::se3::rigid_inverse;
use crate::io::gt::JointType;

/// Rotation angle (rad) below which a pair counts as not rotating when types tie.
const STATIC_ANGLE: f64 = 1e-3;

/// Type test (Occam): a prismatic joint that fits is kept unless the revolute one
/// explains the child's points this many times better (RMS point residual, see [`point_rms`]). A
/// revolute joint has two more parameters (pivot), and with a far pivot it imitates a
/// slide while also absorbing the pose noise of a small child part, so the plain
/// L_1DOF comparison calls every noisy slide revolute (bench-dev panda_gripper's
/// fingers came out as revolute joints with states up to 0.35 rad).
const REVOLUTE_GAIN: f64 = 2.0;

/// A slide "fits" when its RMS point residual is at most this many child radii (the
/// synthetic arm's broken pose fits had 6–12 radii, noisy gripper slides ≤ 1.2).
const SLIDE_FIT: f64 = 2.0;

/// ... and only when the revolute's angle range (peak to peak) stays below this: a
/// slide's relative rotation is pose noise (≤ 0.75 rad on panda_gripper's small
/// fingers), while a real hinge whose poses fit it poorly still turns far (finger_edu's
/// distal joint: 3.1 rad, rr ≈ pr ≈ 1.7 radii).
const SLIDE_MAX_TURN: f64 = 1.0;

/// Centroid and RMS radius of a part's points at the canonical frame.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct PartExtent {
    pub centre: DVec3,
    pub radius: f64,
}

/// The best 1-DOF explanation of a relative motion sequence.
#[derive(Debug, Clone, PartialEq)]
pub struct ScrewFit {
    pub joint_type: JointType,
    /// Unit axis (world, canonical frame).
    pub axis: DVec3,
    /// A point on a revolute axis (the one nearest the pair's reference point); the
    /// reference point itself for prismatic joints.
    pub pivot: DVec3,
    /// State per frame (radians or length), 0 where the relative motion is the identity.
    pub states: Vec<f64>,
    /// L_1DOF of the chosen type.
    pub loss: f64,
    pub loss_revolute: f64,
    pub loss_prismatic: f64,
}

/// Qₖ = (Aᵢᵏ)⁻¹ Aⱼᵏ for every frame, Aᵖᵏ = Tₚᵏ (Tₚᶜ)⁻¹ (`poses[k][p]`).
pub fn relative_motions(poses: &[Vec<DMat4>], i: usize, j: usize, canonical: usize) -> Vec<DMat4> {
    let ic = rigid_inverse(&poses[canonical][i]);
    let jc = rigid_inverse(&poses[canonical][j]);
    poses
        .iter()
        .map(|f| {
            let ai = f[i] * ic;
            let aj = f[j] * jc;
            rigid_inverse(&ai) * aj
        })
        .collect()
}

/// ‖M − I‖²_F.
pub fn dev_from_identity(m: &DMat4) -> f64 {
    let d = *m - DMat4::IDENTITY;
    d.to_cols_array().iter().map(|v| v * v).sum()
}

/// A joint's limits: its state range widened by `pad` of its length on each side.
pub fn padded_limits(states: &[f64], pad: f64) -> [f64; 2] {
    let (lo, hi) = state_range(states);
    let w = (hi - lo) * pad;
    [lo - w, hi + w]
}

/// (min, max) of a joint's states.
pub fn state_range(states: &[f64]) -> (f64, f64) {
    states
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &s| {
            (lo.min(s), hi.max(s))
        })
}

/// The part of relative motion `q` a joint at state `s` leaves unexplained: Q S(s)⁻¹.
fn unexplained(q: &DMat4, joint_type: JointType, axis: DVec3, pivot: DVec3, s: f64) -> DMat4 {
    *q * rigid_inverse(&screw_exp(joint_type, axis, pivot, s))
}

/// L_1DOF of a given joint for relative motions `rel`.
pub fn one_dof_loss(
    rel: &[DMat4],
    joint_type: JointType,
    axis: DVec3,
    pivot: DVec3,
    states: &[f64],
) -> f64 {
    residuals(rel, joint_type, axis, pivot, states).iter().sum()
}

fn rot(m: &DMat4) -> DMat3 {
    DMat3::from_mat4(*m)
}

fn to_na(m: &DMat3) -> Matrix3<f64> {
    Matrix3::from_column_slice(&m.to_cols_array())
}

/// Principal direction of Σ w vvᵀ (unit), or `None` if all vectors vanish.
fn principal_direction(vs: &[DVec3]) -> Option<DVec3> {
    let mut m = Matrix3::<f64>::zeros();
    for v in vs {
        let x = Vector3::new(v.x, v.y, v.z);
        m += x * x.transpose();
    }
    if m.trace() <= 1e-24 {
        return None;
    }
    let e = SymmetricEigen::new(m);
    let mut best = 0;
    for k in 1..3 {
        if e.eigenvalues[k] > e.eigenvalues[best] {
            best = k;
        }
    }
    let c = e.eigenvectors.column(best);
    Some(canonical_sign(DVec3::new(c[0], c[1], c[2]).normalize()))
}

/// Sign convention for axes: the first sufficiently non-zero component positive
/// (deterministic output; joints are compared up to sign anyway).
fn canonical_sign(a: DVec3) -> DVec3 {
    for c in a.to_array() {
        if c.abs() > 1e-9 {
            return if c < 0.0 { -a } else { a };
        }
    }
    a
}

/// Rotation vector (axis·angle, angle in [0, π]) of a rotation matrix.
pub fn log_rotation(r: &DMat3) -> DVec3 {
    let q = DQuat::from_mat3(r).normalize();
    let (axis, angle) = q.to_axis_angle();
    let angle = if angle > std::f64::consts::PI {
        angle - 2.0 * std::f64::consts::PI
    } else {
        angle
    };
    if angle.abs() < 1e-15 {
        DVec3::ZERO
    } else {
        axis * angle
    }
}

/// Angle θ about unit `axis` whose rotation is closest (Frobenius) to `r`.
pub(crate) fn project_angle(axis: DVec3, r: &DMat3) -> f64 {
    // R(θ) = I + sinθ K + (1−cosθ) K²; maximise tr(R(θ)ᵀ r) = const + α sinθ − β cosθ.
    let k = DMat3::from_cols(
        DVec3::new(0.0, axis.z, -axis.y),
        DVec3::new(-axis.z, 0.0, axis.x),
        DVec3::new(axis.y, -axis.x, 0.0),
    );
    let k2 = k * k;
    let frob = |a: &DMat3, b: &DMat3| -> f64 {
        a.x_axis.dot(b.x_axis) + a.y_axis.dot(b.y_axis) + a.z_axis.dot(b.z_axis)
    };
    let alpha = frob(&k, r);
    let beta = frob(&k2, r);
    alpha.latan2(-beta)
}

/// Angles in (−π, π] made continuous from frame to frame (each within π of the one
/// before), then shifted by a whole number of turns so that the frame nearest zero
/// stays there (the canonical frame's 0). A hinge turning past ±π otherwise gets states
/// like −0.9, 3.7, −2.7 and limits spanning more than a turn (the joint's slider).
pub fn unwrap_angles(mut a: Vec<f64>) -> Vec<f64> {
    use std::f64::consts::{PI, TAU};
    let Some(origin) = (0..a.len()).min_by(|&i, &j| a[i].abs().total_cmp(&a[j].abs())) else {
        return a;
    };
    for k in 1..a.len() {
        let d = a[k] - a[k - 1];
        a[k] -= TAU * ((d + PI) / TAU).floor();
    }
    let shift = TAU * (a[origin] / TAU).round();
    for v in &mut a {
        *v -= shift;
    }
    a
}

/// Per frame, the turn about unit `axis` from `u` to `images[k]` (both taken into the
/// plane perpendicular to the axis only through the cross and dot products), unwrapped
/// and 0 at frame `c`: a hinge's states from where it carries one direction.
pub(crate) fn turns_carrying(images: &[DVec3], u: DVec3, axis: DVec3, c: usize) -> Vec<f64> {
    let raw = images
        .iter()
        .map(|d| {
            let d = *d - d.dot(axis) * axis;
            u.cross(d).dot(axis).latan2(u.dot(d))
        })
        .collect();
    zeroed_at(unwrap_angles(raw), c)
}

/// `states` shifted so that frame `c`'s is 0 (unchanged when there is no frame `c`).
pub(crate) fn zeroed_at(mut states: Vec<f64>, c: usize) -> Vec<f64> {
    let s0 = states.get(c).copied().unwrap_or(0.0);
    states.iter_mut().for_each(|s| *s -= s0);
    states
}

/// The pivot about which turns by `states` about unit `axis` carry the point `cen` as
/// the relative motions `rel` do (`fit_pivot`; `reference` fixes its component along
/// the axis).
pub(crate) fn pivot_carrying(
    rel: &[DMat4],
    axis: DVec3,
    states: &[f64],
    cen: DVec3,
    reference: DVec3,
) -> DVec3 {
    let rs: Vec<DMat3> = states
        .iter()
        .map(|&s| DMat3::from_axis_angle(axis, s))
        .collect();
    let ts: Vec<DVec3> = rel
        .iter()
        .zip(&rs)
        .map(|(m, r)| m.transform_point3(cen) - *r * cen)
        .collect();
    fit_pivot(&rs, &ts, reference)
}

/// Point p minimising Σ‖(I − Rₖ) p − tₖ‖², taking the component of every
/// unconstrained direction (at least the axis) from `reference`.
pub(crate) fn fit_pivot(rs: &[DMat3], ts: &[DVec3], reference: DVec3) -> DVec3 {
    let mut m = Matrix3::<f64>::zeros();
    let mut b = Vector3::<f64>::zeros();
    for (r, t) in rs.iter().zip(ts) {
        let a = to_na(&(DMat3::IDENTITY - *r));
        m += a.transpose() * a;
        b += a.transpose() * Vector3::new(t.x, t.y, t.z);
    }
    let e = SymmetricEigen::new(m);
    let lmax = e.eigenvalues.iter().fold(0.0f64, |a, &v| a.max(v));
    let c = Vector3::new(reference.x, reference.y, reference.z);
    let mut p = c;
    if lmax > 0.0 {
        for k in 0..3 {
            let l = e.eigenvalues[k];
            if l > 1e-9 * lmax {
                let u = e.eigenvectors.column(k).into_owned();
                p += u * ((u.dot(&b) - l * u.dot(&c)) / l);
            }
        }
    }
    DVec3::new(p[0], p[1], p[2])
}

/// Fraction of the frames (rounded down) a fit may set aside as outliers: the frames
/// whose relative pose the first fit explains worst are left out of the second fit
/// and of its L_1DOF. One flipped Step-1 pose (a symmetric link found half a turn
/// off in one frame) otherwise dominates both the axis (the rotation logs are
/// weighted by angle²) and the loss, and the spanning tree then prefers a wrong
/// parent (bench-dev xarm7: the gripper's true parent 23.2 vs a wrong one 17.8).
/// With ground-truth poses every residual is zero and nothing changes.
pub const OUTLIER_FRACTION: f64 = 0.2;

/// Per-frame residuals ‖Qₖ Sₖ⁻¹ − I‖²_F of a joint.
fn residuals(rel: &[DMat4], jt: JointType, axis: DVec3, pivot: DVec3, states: &[f64]) -> Vec<f64> {
    rel.iter()
        .zip(states)
        .map(|(q, &s)| dev_from_identity(&unexplained(q, jt, axis, pivot, s)))
        .collect()
}

/// Frames kept after dropping the `OUTLIER_FRACTION` with the largest residuals.
pub(crate) fn inliers(res: &[f64]) -> Vec<bool> {
    let drop = (res.len() as f64 * OUTLIER_FRACTION).floor() as usize;
    let mut keep = vec![true; res.len()];
    if drop == 0 {
        return keep;
    }
    let mut order: Vec<usize> = (0..res.len()).collect();
    order.sort_by(|&a, &b| res[b].total_cmp(&res[a]));
    for &k in order.iter().take(drop) {
        keep[k] = false;
    }
    keep
}

/// Σ of the kept frames' residuals, scaled to all frames (comparable across pairs).
fn trimmed_loss(res: &[f64], keep: &[bool]) -> f64 {
    let kept = keep.iter().filter(|k| **k).count().max(1);
    let sum: f64 = res
        .iter()
        .zip(keep)
        .filter(|(_, k)| **k)
        .map(|(r, _)| r)
        .sum();
    sum * res.len() as f64 / kept as f64
}

/// Revolute fit on the kept frames (states for every frame).
fn revolute_on(rel: &[DMat4], keep: &[bool], reference: DVec3) -> (DVec3, DVec3, Vec<f64>) {
    let logs: Vec<DVec3> = rel
        .iter()
        .zip(keep)
        .filter(|(_, k)| **k)
        .map(|(q, _)| log_rotation(&rot(q)))
        .collect();
    let axis = principal_direction(&logs).unwrap_or(DVec3::Z);
    revolute_about(rel, keep, axis, reference)
}

/// Revolute joint about the unit `axis`: states by projection (every frame), pivot by
/// least squares over the kept frames.
fn revolute_about(
    rel: &[DMat4],
    keep: &[bool],
    axis: DVec3,
    reference: DVec3,
) -> (DVec3, DVec3, Vec<f64>) {
    let states = unwrap_angles(rel.iter().map(|q| project_angle(axis, &rot(q))).collect());
    let (rs, ts): (Vec<DMat3>, Vec<DVec3>) = rel
        .iter()
        .zip(&states)
        .zip(keep)
        .filter(|(_, k)| **k)
        .map(|((q, &s), _)| (DMat3::from_axis_angle(axis, s), q.w_axis.truncate()))
        .unzip();
    let pivot = fit_pivot(&rs, &ts, reference);
    (axis, pivot, states)
}

/// The kinematic tree takes a revolute fit started from one frame's own turn
/// (`revolute_restart`) instead of `fit_revolute`'s when its trimmed L_1DOF is below
/// this fraction of that fit's (`tree::pair_costs`). Any lower loss would not do: the
/// least of ten starts is as often a hinge fitted to the frames a two-joint pair happens
/// to share. With the restart in every hinge fit (bench-dev full, fast, seeds 0–4): any
/// lower loss TED 1.66 → 1.77 and joints in the bar 76 → 62, 0.5 1.63 and 74, 0.25 1.63
/// and 77; in the tree's costs alone at 0.25 (kept) 1.63 and 76, balanced 1.91 → 1.86
/// (docs/DEVELOPMENT.md, session 42).
pub const RESTART_GAIN: f64 = 0.25;

/// From a start (axis, pivot, states): the frames it explains worst are set aside
/// (`OUTLIER_FRACTION`) and the rest fitted again. Returns the fit and its trimmed loss.
fn trimmed_revolute(
    rel: &[DMat4],
    start: (DVec3, DVec3, Vec<f64>),
    reference: DVec3,
) -> (DVec3, DVec3, Vec<f64>, f64) {
    let jt = JointType::Revolute;
    let (axis, pivot, states) = start;
    let keep = inliers(&residuals(rel, jt, axis, pivot, &states));
    let (axis, pivot, states) = revolute_on(rel, &keep, reference);
    let loss = trimmed_loss(&residuals(rel, jt, axis, pivot, &states), &keep);
    (axis, pivot, states, loss)
}

/// Best revolute joint: axis = principal direction of the rotation vectors (weighted
/// by angle²), angles by projection onto the axis, pivot by linear least squares;
/// fitted again without the worst frames (`OUTLIER_FRACTION`).
/// Returns (axis, pivot, states, trimmed loss).
pub fn fit_revolute(rel: &[DMat4], reference: DVec3) -> (DVec3, DVec3, Vec<f64>, f64) {
    let all = vec![true; rel.len()];
    trimmed_revolute(rel, revolute_on(rel, &all, reference), reference)
}

/// The revolute fit of `fit_revolute` started instead from each turning frame's own
/// axis, the one with the least trimmed loss (None when no frame turns). Weighted by
/// angle², one frame turned half a turn about another axis (a symmetric link flipped by
/// Step 1) sets `fit_revolute`'s first axis; the frames that follow the true hinge are
/// then the worst explained and set aside, and the fit keeps the flip.
pub fn revolute_restart(rel: &[DMat4], reference: DVec3) -> Option<(DVec3, DVec3, Vec<f64>, f64)> {
    let all = vec![true; rel.len()];
    rel.iter()
        .map(|q| log_rotation(&rot(q)))
        .filter(|log| log.length() > STATIC_ANGLE)
        .map(|log| {
            let axis = canonical_sign(log.normalize());
            trimmed_revolute(rel, revolute_about(rel, &all, axis, reference), reference)
        })
        .min_by(|a, b| a.3.total_cmp(&b.3))
}

/// Prismatic fit on the kept frames (states for every frame).
fn prismatic_on(rel: &[DMat4], keep: &[bool]) -> (DVec3, Vec<f64>) {
    let ts: Vec<DVec3> = rel
        .iter()
        .zip(keep)
        .filter(|(_, k)| **k)
        .map(|(q, _)| q.w_axis.truncate())
        .collect();
    let axis = principal_direction(&ts).unwrap_or(DVec3::Z);
    let states: Vec<f64> = rel.iter().map(|q| q.w_axis.truncate().dot(axis)).collect();
    (axis, states)
}

/// Best prismatic joint: axis = principal direction of the translations, states by
/// projection; fitted again without the worst frames. Returns (axis, states, trimmed
/// loss).
pub fn fit_prismatic(rel: &[DMat4]) -> (DVec3, Vec<f64>, f64) {
    let jt = JointType::Prismatic;
    let all = vec![true; rel.len()];
    let (axis, states) = prismatic_on(rel, &all);
    let keep = inliers(&residuals(rel, jt, axis, DVec3::ZERO, &states));
    let (axis, states) = prismatic_on(rel, &keep);
    let loss = trimmed_loss(&residuals(rel, jt, axis, DVec3::ZERO, &states), &keep);
    (axis, states, loss)
}

/// Best 1-DOF screw (revolute or prismatic) for the relative motions `rel`.
/// `reference` is a point near the pair (e.g. the child's centroid at frame c): the
/// revolute pivot is the point of the axis nearest to it and the prismatic "pivot"
/// (joint origin) is the reference itself.
///
/// Type rule: the lower L_1DOF wins; when both are within numerical noise of each other
/// the pair is treated as revolute if it rotates at all (max angle > 1e-3 rad) and
/// prismatic otherwise.
pub fn fit_screw(rel: &[DMat4], child: PartExtent) -> ScrewFit {
    fit_screw_as(rel, child, None)
}

/// [`fit_screw`] with the type given (`Some`, a joint type chosen by hand,
/// `crate::edit`) instead of decided by the type rule.
pub fn fit_screw_as(rel: &[DMat4], child: PartExtent, given: Option<JointType>) -> ScrewFit {
    let reference = child.centre;
    let (ra, rp, rs, rl) = fit_revolute(rel, reference);
    let (pa, ps, pl) = fit_prismatic(rel);
    if let Some(jt) = given {
        let revolute = jt == JointType::Revolute;
        return ScrewFit {
            joint_type: jt,
            axis: if revolute { ra } else { pa },
            pivot: if revolute { rp } else { reference },
            states: if revolute { rs } else { ps },
            loss: if revolute { rl } else { pl },
            loss_revolute: rl,
            loss_prismatic: pl,
        };
    }
    let tie = (rl - pl).abs() <= 1e-9 + 1e-6 * rl.max(pl);
    let rotates = rel
        .iter()
        .any(|q| log_rotation(&rot(q)).length() > STATIC_ANGLE);
    let rr = point_rms(rel, JointType::Revolute, ra, rp, &rs, child);
    let pr = point_rms(rel, JointType::Prismatic, pa, DVec3::ZERO, &ps, child);
    // The Occam test applies only when the slide explains the child within its own
    // size; for a pair whose poses fit neither joint the paper's rule decides.
    let (lo, hi) = state_range(&rs);
    let slide_fits = pr <= SLIDE_FIT * child.radius && hi - lo <= SLIDE_MAX_TURN;
    let revolute = if tie {
        rotates
    } else if slide_fits && pr <= REVOLUTE_GAIN * rr {
        false
    } else {
        rl < pl
    };
    if revolute {
        ScrewFit {
            joint_type: JointType::Revolute,
            axis: ra,
            pivot: rp,
            states: rs,
            loss: rl,
            loss_revolute: rl,
            loss_prismatic: pl,
        }
    } else {
        ScrewFit {
            joint_type: JointType::Prismatic,
            axis: pa,
            pivot: reference,
            states: ps,
            loss: pl,
            loss_revolute: rl,
            loss_prismatic: pl,
        }
    }
}

/// RMS displacement of the child's points left unexplained by a joint: for each frame
/// the residual motion D = Qₖ Sₖ⁻¹ moves a body of centroid c and RMS radius ρ by
/// ‖D c − c‖² + ρ²/3 · ‖R_D − I‖²_F on average (isotropic body); the root mean over frames.
pub fn point_rms(
    rel: &[DMat4],
    joint_type: JointType,
    axis: DVec3,
    pivot: DVec3,
    states: &[f64],
    child: PartExtent,
) -> f64 {
    let n = rel.len().max(1) as f64;
    let sum: f64 = rel
        .iter()
        .zip(states)
        .map(|(q, &s)| {
            let d = unexplained(q, joint_type, axis, pivot, s);
            let r = rot(&d) - DMat3::IDENTITY;
            let frob =
                r.x_axis.length_squared() + r.y_axis.length_squared() + r.z_axis.length_squared();
            (d.transform_point3(child.centre) - child.centre).length_squared()
                + child.radius * child.radius / 3.0 * frob
        })
        .sum();
    (sum / n).sqrt()
}

/// Angle between two axes up to sign, in degrees.
pub fn axis_angle_deg(a: DVec3, b: DVec3) -> f64 {
    let c = (a.normalize().dot(b.normalize())).abs().min(1.0);
    c.lacos().to_degrees()
}

/// Distance from point `x` to the line through `p` with unit direction `d`.
pub fn point_line_distance(x: DVec3, p: DVec3, d: DVec3) -> f64 {
    let v = x - p;
    (v - d * v.dot(d)).length()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{rngs::StdRng, Rng, SeedableRng};

    /// A part of radius 0.1 centred at `c`.
    fn body(c: DVec3) -> PartExtent {
        PartExtent {
            centre: c,
            radius: 0.1,
        }
    }

    fn noisy(m: DMat4, rng: &mut StdRng, sigma: f64) -> DMat4 {
        let w = DVec3::new(
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
        ) * sigma;
        let t = DVec3::new(
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
        ) * sigma;
        let r = if w.length() > 0.0 {
            DMat4::from_axis_angle(w.normalize(), w.length())
        } else {
            DMat4::IDENTITY
        };
        DMat4::from_translation(t) * r * m
    }

    fn sequence(
        jt: JointType,
        axis: DVec3,
        pivot: DVec3,
        states: &[f64],
        rng: &mut StdRng,
        sigma: f64,
    ) -> Vec<DMat4> {
        states
            .iter()
            .map(|&s| noisy(screw_exp(jt, axis, pivot, s), rng, sigma))
            .collect()
    }

    #[test]
    fn angles_unwrap_across_a_half_turn() {
        let a = unwrap_angles(vec![0.0, -0.93, 3.72, -2.65, 3.54, -2.83]);
        let tau = std::f64::consts::TAU;
        let want = [0.0, -0.93, 3.72 - tau, -2.65, 3.54 - tau, -2.83];
        for (x, y) in a.iter().zip(want) {
            assert!((x - y).abs() < 1e-12, "{a:?}");
        }
        // The zero (canonical) frame stays at zero when it is not the first.
        let a = unwrap_angles(vec![3.0, -3.1, 0.0, 0.5]);
        let want = [3.0 - tau, -3.1, 0.0, 0.5];
        for (x, y) in a.iter().zip(want) {
            assert!((x - y).abs() < 1e-12, "{a:?}");
        }
        assert!(unwrap_angles(Vec::new()).is_empty());
    }

    #[test]
    fn revolute_exact_recovery() {
        let mut rng = StdRng::seed_from_u64(1);
        let axis = DVec3::new(0.3, -0.5, 0.8).normalize();
        let pivot = DVec3::new(0.1, 0.2, -0.3);
        let states = [0.0, 0.3, -0.4, 0.9, 1.4, -1.1];
        let rel = sequence(JointType::Revolute, axis, pivot, &states, &mut rng, 0.0);
        let f = fit_screw(&rel, body(DVec3::ZERO));
        assert_eq!(f.joint_type, JointType::Revolute);
        assert!(f.loss < 1e-20, "{}", f.loss);
        assert!(axis_angle_deg(f.axis, axis) < 1e-6);
        assert!(point_line_distance(f.pivot, pivot, axis) < 1e-9);
        let sign = f.axis.dot(axis).signum();
        for (a, b) in f.states.iter().zip(states) {
            assert!((a - sign * b).abs() < 1e-9);
        }
        assert!(f.loss_prismatic > 0.1);
    }

    #[test]
    fn prismatic_exact_recovery() {
        let mut rng = StdRng::seed_from_u64(2);
        let axis = DVec3::new(-0.2, 0.9, 0.1).normalize();
        let states = [0.0, 0.1, 0.05, -0.2, 0.3];
        let rel = sequence(
            JointType::Prismatic,
            axis,
            DVec3::ZERO,
            &states,
            &mut rng,
            0.0,
        );
        let f = fit_screw(&rel, body(DVec3::new(0.5, 0.5, 0.5)));
        assert_eq!(f.joint_type, JointType::Prismatic);
        assert!(f.loss < 1e-20);
        assert!(axis_angle_deg(f.axis, axis) < 1e-6);
        let sign = f.axis.dot(axis).signum();
        for (a, b) in f.states.iter().zip(states) {
            assert!((a - sign * b).abs() < 1e-12);
        }
        assert!(f.loss_revolute > f.loss);
    }

    #[test]
    fn noisy_recovery_is_approximate() {
        let mut rng = StdRng::seed_from_u64(3);
        let axis = DVec3::new(1.0, 1.0, 0.2).normalize();
        let pivot = DVec3::new(-0.2, 0.0, 0.4);
        let states: Vec<f64> = (0..10).map(|k| 0.8 * (k as f64 * 0.7).lsin()).collect();
        let rel = sequence(JointType::Revolute, axis, pivot, &states, &mut rng, 0.005);
        let f = fit_screw(&rel, body(pivot + axis * 0.3));
        assert_eq!(f.joint_type, JointType::Revolute);
        assert!(
            axis_angle_deg(f.axis, axis) < 1.5,
            "{}",
            axis_angle_deg(f.axis, axis)
        );
        assert!(point_line_distance(f.pivot, pivot, axis) < 0.02);
        assert!(f.loss < 0.01);

        let pstates: Vec<f64> = (0..10).map(|k| 0.2 * (k as f64 * 0.5).lcos()).collect();
        let rel = sequence(JointType::Prismatic, axis, pivot, &pstates, &mut rng, 0.003);
        let f = fit_screw(&rel, body(pivot));
        assert_eq!(f.joint_type, JointType::Prismatic);
        assert!(axis_angle_deg(f.axis, axis) < 2.0);
    }

    #[test]
    fn a_restart_sets_one_half_turned_frame_aside() {
        // bench-dev so101, balanced, seed 2: the upper arm, hinged to the shoulder about
        // a horizontal axis, came out of Step 1 half a turn about the vertical in one
        // frame.
        let mut rng = StdRng::seed_from_u64(7);
        let axis = DVec3::new(0.7, 0.7, 0.0).normalize();
        let pivot = DVec3::new(0.0, 0.0, 0.3);
        let states = [0.0, 0.8, 1.14, -0.7, -0.73, 0.28, -0.78, -0.76, -0.64, -0.2];
        let mut rel = sequence(JointType::Revolute, axis, pivot, &states, &mut rng, 0.01);
        let flip = DMat4::from_translation(pivot)
            * DMat4::from_axis_angle(DVec3::Z, 3.11)
            * DMat4::from_translation(-pivot);
        rel[3] = flip * rel[3];
        // Started from all frames, the fit takes the half-turn's axis.
        let first = fit_revolute(&rel, pivot);
        assert!(axis_angle_deg(first.0, axis) > 30.0, "{}", first.0);
        let (a, p, s, loss) = revolute_restart(&rel, pivot).unwrap();
        assert!(loss < RESTART_GAIN * first.3, "{loss} vs {}", first.3);
        assert!(axis_angle_deg(a, axis) < 2.0, "{a}");
        assert!(point_line_distance(p, pivot, axis) < 0.02, "{p}");
        let sign = a.dot(axis).signum();
        for (k, (x, y)) in s.iter().zip(states).enumerate() {
            assert!(
                k == 3 || (x - sign * y).abs() < 0.05,
                "frame {k}: {x} vs {y}"
            );
        }
        // The trimmed loss is the noise's, not the half-turn's (‖R − I‖²_F ≈ 8).
        assert!(loss < 0.05, "{loss}");
    }

    /// A slide whose small child wobbles by up to ±0.2 rad about its own centre stays
    /// prismatic, although a revolute with a far pivot has the lower L_1DOF; a hinge
    /// that turns far with the same wobble stays revolute.
    #[test]
    fn noisy_slide_of_a_small_part_stays_prismatic() {
        let mut rng = StdRng::seed_from_u64(4);
        let c = DVec3::new(0.2, 0.1, 0.0);
        let child = PartExtent {
            centre: c,
            radius: 0.05,
        };
        let mut wobble = || {
            let w = DVec3::new(
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
            ) * 0.2
                / 3f64.sqrt();
            DMat4::from_translation(c)
                * DMat4::from_axis_angle(w.normalize(), w.length())
                * DMat4::from_translation(-c)
        };
        let slide: Vec<DMat4> = (0..10)
            .map(|k| {
                let q = 0.1 * (k as f64 * 0.6).lsin();
                screw_exp(JointType::Prismatic, DVec3::Y, DVec3::ZERO, q) * wobble()
            })
            .collect();
        let f = fit_screw(&slide, child);
        assert!(f.loss_revolute < f.loss_prismatic, "{f:?}");
        assert_eq!(f.joint_type, JointType::Prismatic);
        assert!(axis_angle_deg(f.axis, DVec3::Y) < 10.0, "{f:?}");

        let hinge: Vec<DMat4> = (0..10)
            .map(|k| {
                let q = 1.2 * (k as f64 * 0.6).lsin();
                let pivot = c + DVec3::X * 0.05;
                screw_exp(JointType::Revolute, DVec3::Z, pivot, q) * wobble()
            })
            .collect();
        assert_eq!(fit_screw(&hinge, child).joint_type, JointType::Revolute);
    }

    #[test]
    fn static_pair_is_revolute_only_if_rotating() {
        let rel = vec![DMat4::IDENTITY; 4];
        let f = fit_screw(&rel, body(DVec3::ZERO));
        assert_eq!(f.joint_type, JointType::Prismatic);
        assert!(f.loss < 1e-20);
        assert!(f.states.iter().all(|s| s.abs() < 1e-12));
    }
}
