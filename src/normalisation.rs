//! The similarity that takes an input sequence to the units the fit works in.
//!
//! The method's distance constants and step sizes (the pose search's cap, Adam's
//! learning rates for centres, the re-segmentation cap, stopping tolerances) are
//! absolute lengths, tuned on objects about the size of the unit box, like bench-dev.
//! A sequence in other units — millimetres, or far from the origin — is fitted in
//! "fit units": `x_fit = (x − center) / scale`, where the longest side of the bounding
//! box over all frames (stray outliers left out) is brought into `SIDE_MIN..=SIDE_MAX`
//! and a box away from the origin is centred. The pipeline maps everything it reports (snapshots, the Step-1
//! model, the result) back to input units.
//!
use crate::math::Libm;
use glam::{DMat3, DMat4, DVec3, Vec3};

use crate::io::sequence::Sequence;

/// Longest sides (over all frames) the fit takes as they are: the range of bench-dev's
/// robots (0.855–1.0), on which the step sizes were tuned. Larger or smaller objects
/// are scaled to the nearer end. Measured (xarm7, longest side 0.855, fast, seeds
/// 0–5): fitted as it is, mean reconstruction error 1.60, TED 1.5; scaled to side 1,
/// 3.24 and 3.3 — Adam's steps are absolute lengths, and scaling the learning rates by
/// the same factor recovered most of it (1.78). So within this range the fit is not
/// rescaled, and a result in other units differs from it at seed-noise level only.
const SIDE_MIN: f64 = 0.85;
const SIDE_MAX: f64 = 1.0;

/// `x_fit = (x − center) / scale`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Normalisation {
    pub center: DVec3,
    pub scale: f64,
}

impl Default for Normalisation {
    fn default() -> Self {
        Self::IDENTITY
    }
}

/// Points sampled (evenly over all frames) to find the quantile box.
const BOX_SAMPLE: usize = 65_536;
/// Fraction of the sample at each end of each axis the quantile box leaves out.
const BOX_QUANTILE: f64 = 1e-3;
/// Points farther than this × the quantile box's longest side outside that box are
/// stray outliers. On bench-dev every point lies within 7 % (thin limb tips are a small
/// fraction of the points), so there the box is the plain bounding box.
const BOX_MARGIN: f64 = 0.25;

/// The bounding box of the object's points over all frames, without stray outliers: a
/// single point metres away (a scanner artefact) would otherwise set the scale.
fn object_box(seq: &Sequence) -> (DVec3, DVec3) {
    let total: usize = seq.frames.iter().map(|f| f.points.len()).sum();
    let stride = total.div_ceil(BOX_SAMPLE).max(1);
    let mut axes: [Vec<f32>; 3] = Default::default();
    for p in seq
        .frames
        .iter()
        .flat_map(|f| &f.points)
        .step_by(stride)
        .filter(|p| p.is_finite())
    {
        for (a, v) in axes.iter_mut().zip(p.to_array()) {
            a.push(v);
        }
    }
    let mut qlo = DVec3::splat(f64::NEG_INFINITY);
    let mut qhi = DVec3::splat(f64::INFINITY);
    // Too few points to tell an outlier: the plain bounding box.
    if let Some(n) = axes[0].len().checked_sub(1).filter(|&n| n >= 64) {
        // At least one sample left out at each end, so a lone stray point in a small
        // cloud is caught too.
        let k = ((BOX_QUANTILE * n as f64).ceil() as usize)
            .max(1)
            .min(n / 2);
        let (i_lo, i_hi) = (k, n - k);
        for (d, a) in axes.iter_mut().enumerate() {
            let lo = *a.select_nth_unstable_by(i_lo, f32::total_cmp).1 as f64;
            let hi = *a.select_nth_unstable_by(i_hi, f32::total_cmp).1 as f64;
            qlo[d] = lo;
            qhi[d] = hi;
        }
        let reach = BOX_MARGIN * (qhi - qlo).max_element();
        qlo -= DVec3::splat(reach);
        qhi += DVec3::splat(reach);
    }
    let mut lo = DVec3::splat(f64::INFINITY);
    let mut hi = DVec3::splat(f64::NEG_INFINITY);
    for p in seq.frames.iter().flat_map(|f| &f.points) {
        let p = p.as_dvec3();
        if p.is_finite() && p.cmpge(qlo).all() && p.cmple(qhi).all() {
            lo = lo.min(p);
            hi = hi.max(p);
        }
    }
    (lo, hi)
}

impl Normalisation {
    pub const IDENTITY: Normalisation = Normalisation {
        center: DVec3::ZERO,
        scale: 1.0,
    };

    /// The normalisation of a sequence, from the bounding box over its points (stray
    /// outliers excluded, see `object_box`): scale = longest side / the nearest side in
    /// `SIDE_MIN..=SIDE_MAX` (1 inside that range or for a box of zero size); centre =
    /// the box's middle when that lies more than half a side from the origin, else the
    /// origin.
    pub fn of(seq: &Sequence) -> Self {
        let (lo, hi) = object_box(seq);
        if !(lo.is_finite() && hi.is_finite()) {
            return Self::IDENTITY;
        }
        let side = (hi - lo).max_element();
        if !(side > 0.0 && side.is_finite()) {
            return Self::IDENTITY;
        }
        let mid = 0.5 * (lo + hi);
        // Data around the origin stays where it is (translation does not change the
        // fit; it only costs f32 precision far from the origin).
        let center = if mid.abs().max_element() > 0.5 * side {
            mid
        } else {
            DVec3::ZERO
        };
        Normalisation {
            center,
            scale: side / side.clamp(SIDE_MIN, SIDE_MAX),
        }
    }

    pub fn is_identity(&self) -> bool {
        *self == Self::IDENTITY
    }

    /// An input point in fit units.
    #[inline]
    pub fn point_to_fit(&self, p: Vec3) -> Vec3 {
        ((p.as_dvec3() - self.center) / self.scale).as_vec3()
    }

    /// A point in fit units back in input units.
    #[inline]
    pub fn point_to_input(&self, p: DVec3) -> DVec3 {
        p * self.scale + self.center
    }

    /// Input points to fit units, in place (untouched when the map is the identity).
    pub fn points_to_fit(&self, pts: &mut [Vec3]) {
        if self.is_identity() {
            return;
        }
        for p in pts {
            *p = self.point_to_fit(*p);
        }
    }

    /// A length (scale, prismatic state, distance) in fit units back in input units.
    #[inline]
    pub fn length_to_input(&self, d: f64) -> f64 {
        d * self.scale
    }

    /// A frame placement `[R | μ]` (local → world, e.g. a Gaussian's pose) from input
    /// to fit units: the rotation stays, the origin moves with the points.
    pub fn placement_to_fit(&self, m: &DMat4) -> DMat4 {
        let r = DMat3::from_mat4(*m);
        let t = m.w_axis.truncate();
        DMat4::from_mat3_translation(r, (t - self.center) / self.scale)
    }

    /// A rigid motion `x ↦ R x + t` of points (e.g. a part's pose from the canonical
    /// frame to frame k) from fit to input units: `x ↦ R x + s t + c − R c`.
    pub fn motion_to_input(&self, m: &DMat4) -> DMat4 {
        let r = DMat3::from_mat4(*m);
        let t = m.w_axis.truncate();
        DMat4::from_mat3_translation(r, t * self.scale + self.center - r * self.center)
    }

    /// A rigid motion of points from input to fit units (the inverse of
    /// [`Self::motion_to_input`]): `x ↦ R x + (t + R c − c) / s`.
    pub fn motion_to_fit(&self, m: &DMat4) -> DMat4 {
        let r = DMat3::from_mat4(*m);
        let t = m.w_axis.truncate();
        DMat4::from_mat3_translation(r, (t + r * self.center - self.center) / self.scale)
    }

    /// The Step-1 model from fit to input units (centres moved and scaled, log-scales
    /// shifted by ln s, rotations unchanged).
    pub fn model_to_input(&self, model: &mut crate::fit::GaussianModel) {
        if self.is_identity() {
            return;
        }
        let ln_s = self.scale.lln() as f32;
        for s in &mut model.log_scale {
            for v in s {
                *v += ln_s;
            }
        }
        for c in &mut model.center {
            let p = self.point_to_input(DVec3::new(c[0] as f64, c[1] as f64, c[2] as f64));
            *c = p.as_vec3().to_array();
        }
    }

    /// A live-display snapshot from fit to input units.
    pub fn snapshot_to_input(&self, snap: &mut crate::pipeline::Snapshot) {
        if self.is_identity() {
            return;
        }
        for c in snap.centers.chunks_exact_mut(3) {
            let p = self.point_to_input(DVec3::new(c[0] as f64, c[1] as f64, c[2] as f64));
            c.copy_from_slice(&p.as_vec3().to_array());
        }
        for s in &mut snap.scales {
            *s = (*s as f64 * self.scale) as f32;
        }
    }

    /// A result's poses, root motion and joints from input to fit units (the inverse of
    /// [`Self::result_to_input`]; the Gaussians and points are left as they are).
    pub fn result_to_fit(&self, r: &mut crate::io::result::FitResult) {
        self.result_map(
            r,
            Self::motion_to_fit,
            |p| (p - self.center) / self.scale,
            |d| d / self.scale,
        );
    }

    /// A result's poses, root motion and joints from fit to input units (labels,
    /// axes and revolute states need no change; the Gaussians and points are written
    /// from input-unit data by the pipeline).
    pub fn result_to_input(&self, r: &mut crate::io::result::FitResult) {
        self.result_map(
            r,
            Self::motion_to_input,
            |p| self.point_to_input(p),
            |d| self.length_to_input(d),
        );
    }

    /// Maps a result's poses and root motion by `motion`, its pivots by `point` and its
    /// prismatic states and limits by `length`.
    fn result_map(
        &self,
        r: &mut crate::io::result::FitResult,
        motion: fn(&Self, &DMat4) -> DMat4,
        point: impl Fn(DVec3) -> DVec3,
        length: impl Fn(f64) -> f64,
    ) {
        use crate::geom::se3::{from_row_major, to_row_major};
        use crate::io::gt::JointType;
        if self.is_identity() {
            return;
        }
        let motion = |m: &mut [f64; 16]| *m = to_row_major(&motion(self, &from_row_major(m)));
        r.poses.iter_mut().flatten().for_each(motion);
        if let Some(root) = &mut r.root_motion {
            root.iter_mut().for_each(motion);
        }
        for j in r.joints.iter_mut().flatten() {
            j.pivot = point(DVec3::from_array(j.pivot)).to_array();
            if j.joint_type == JointType::Prismatic {
                j.state.iter_mut().for_each(|q| *q = length(*q));
                j.limits = j.limits.map(&length);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::sequence::Frame;

    fn seq(points: Vec<Vec<Vec3>>) -> Sequence {
        Sequence {
            frames: points
                .into_iter()
                .enumerate()
                .map(|(k, points)| Frame {
                    name: format!("f{k}"),
                    points,
                    labels: None,
                })
                .collect(),
        }
    }

    #[test]
    fn unit_sized_boxes_stay_and_others_map_into_the_range() {
        let unit = seq(vec![
            vec![Vec3::new(-0.5, -0.2, 0.0), Vec3::new(0.5, 0.1, 0.3)],
            vec![Vec3::new(0.0, 0.0, -0.5), Vec3::new(0.1, 0.2, 0.5)],
        ]);
        assert!(Normalisation::of(&unit).is_identity());

        let mm = seq(vec![
            vec![Vec3::new(1000.0, 0.0, 0.0), Vec3::new(3000.0, 500.0, 0.0)],
            vec![Vec3::new(1500.0, 200.0, 100.0)],
        ]);
        let n = Normalisation::of(&mm);
        assert!((n.scale - 2000.0).abs() < 1e-9);
        assert!((n.center - DVec3::new(2000.0, 250.0, 50.0)).length() < 1e-9);
        let mut fit = mm.frames[0].points.clone();
        n.points_to_fit(&mut fit);
        assert!((fit[0] - Vec3::new(-0.5, -0.125, -0.025)).length() < 1e-6);
        assert!((fit[1] - Vec3::new(0.5, 0.125, -0.025)).length() < 1e-6);
        for &p in &mm.frames[0].points {
            let back = n.point_to_input(n.point_to_fit(p).as_dvec3());
            assert!((back - p.as_dvec3()).length() < 1e-3);
        }

        // Unit-box-sized data near the origin is fitted as it is; smaller objects are
        // scaled up to the range; metre data far away is only moved.
        let arm = seq(vec![
            vec![Vec3::new(-0.40, 0.0, 0.1)],
            vec![Vec3::new(0.5, 0.3, 0.0)],
        ]);
        assert!(Normalisation::of(&arm).is_identity());
        let small = seq(vec![vec![Vec3::ZERO], vec![Vec3::new(0.5, 0.1, 0.0)]]);
        let n = Normalisation::of(&small);
        assert_eq!(n.center, DVec3::ZERO);
        assert!((n.scale - 0.5 / SIDE_MIN).abs() < 1e-12);
        let far = seq(vec![
            vec![Vec3::new(100.0, 0.0, 0.0)],
            vec![Vec3::new(100.9, 0.2, 0.0)],
        ]);
        let n = Normalisation::of(&far);
        assert_eq!(n.scale, 1.0);
        assert!((n.center - DVec3::new(100.45, 0.1, 0.0)).length() < 1e-5);

        // A stray point far away does not set the size.
        let mut stray = seq(vec![
            (0..200)
                .map(|i| Vec3::new(i as f32 / 199.0 - 0.5, 0.0, 0.0))
                .collect(),
            (0..200)
                .map(|i| Vec3::new(0.0, i as f32 / 398.0, 0.0))
                .collect(),
        ]);
        assert!(Normalisation::of(&stray).is_identity());
        stray.frames[1].points.push(Vec3::new(40.0, 0.0, 0.0));
        assert!(Normalisation::of(&stray).is_identity());

        // Degenerate: one repeated point keeps the scale.
        let one = seq(vec![vec![Vec3::splat(7.0)], vec![Vec3::splat(7.0)]]);
        assert_eq!(Normalisation::of(&one).scale, 1.0);
    }

    /// A motion fitted in fit units, mapped back, moves input points exactly as the
    /// fit-unit motion moves their fit-unit images; a placement maps consistently.
    #[test]
    fn motions_and_placements_commute_with_the_normalisation() {
        let n = Normalisation {
            center: DVec3::new(3.0, -2.0, 10.0),
            scale: 250.0,
        };
        let rot = DMat3::from_axis_angle(DVec3::new(1.0, 2.0, -0.5).normalize(), 0.7);
        let m_fit = DMat4::from_mat3_translation(rot, DVec3::new(0.1, -0.3, 0.2));
        let m_in = n.motion_to_input(&m_fit);
        for x in [DVec3::new(1.0, 2.0, 3.0), DVec3::new(-40.0, 7.0, 100.0)] {
            let x_fit = (x - n.center) / n.scale;
            let via_fit = n.point_to_input(m_fit.transform_point3(x_fit));
            assert!((m_in.transform_point3(x) - via_fit).length() < 1e-9);
        }
        // And back: `motion_to_fit` undoes `motion_to_input`.
        let back = n.motion_to_fit(&m_in);
        assert!(back.abs_diff_eq(m_fit, 1e-12), "{back:?} vs {m_fit:?}");
        let place_in = DMat4::from_mat3_translation(rot, DVec3::new(50.0, 60.0, -70.0));
        let place_fit = n.placement_to_fit(&place_in);
        let local = DVec3::new(0.01, 0.02, -0.03);
        let a = n.point_to_input(place_fit.transform_point3(local));
        let b = place_in.transform_point3(local * n.scale);
        assert!((a - b).length() < 1e-9);
    }

    /// `result_to_fit` undoes `result_to_input`: poses, root motion, pivots and the
    /// prismatic states and limits come back; axes and revolute states never change.
    #[test]
    fn a_result_goes_to_fit_units_and_back() {
        use crate::geom::se3::to_row_major;
        use crate::io::gt::JointType;
        use crate::io::result::{FitResult, ResultJoint, FORMAT, VERSION};
        let n = Normalisation {
            center: DVec3::new(3.0, -2.0, 10.0),
            scale: 250.0,
        };
        let pose = to_row_major(&DMat4::from_mat3_translation(
            DMat3::from_rotation_x(0.3),
            DVec3::new(0.1, 0.2, -0.3),
        ));
        let joint = |joint_type, state: Vec<f64>| ResultJoint {
            child: 1,
            parent: 0,
            joint_type,
            axis: [0.0, 0.6, 0.8],
            pivot: [0.1, -0.2, 0.3],
            limits: [state[0], state[1]],
            state,
            mimic: None,
        };
        let fit = FitResult {
            format: FORMAT.into(),
            version: VERSION,
            frames: 2,
            canonical_frame: 0,
            parts: 2,
            labels: vec![vec![], vec![]],
            poses: vec![vec![pose; 2]; 2],
            gaussians: None,
            tree: None,
            joints: Some(vec![
                joint(JointType::Revolute, vec![0.0, 0.5]),
                joint(JointType::Prismatic, vec![0.0, 0.25]),
            ]),
            root_motion: Some(vec![pose; 2]),
            points: None,
            info: None,
        };
        let mut r = fit.clone();
        n.result_to_input(&mut r);
        let j = r.joints.as_ref().unwrap();
        assert_eq!(j[0].state, vec![0.0, 0.5]);
        assert_eq!(j[1].state, vec![0.0, 62.5]);
        assert_eq!(j[1].axis, [0.0, 0.6, 0.8]);
        n.result_to_fit(&mut r);
        let close = |a: &[f64], b: &[f64]| a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-9);
        for (a, b) in r.poses.iter().flatten().zip(fit.poses.iter().flatten()) {
            assert!(close(a, b), "{a:?} vs {b:?}");
        }
        for (a, b) in r.joints.unwrap().iter().zip(fit.joints.as_ref().unwrap()) {
            assert!(close(&a.pivot, &b.pivot) && close(&a.state, &b.state));
            assert!(close(&a.limits, &b.limits));
        }
    }
}
