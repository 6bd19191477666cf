//! Joint sweep: a part's pose in each frame searched again along its joint (an
//! addition to Step 2, run by `flips::Repair` for every child, once per parent).
//!
//! Step 1 poses every Gaussian without knowing the kinematic tree, and its search
//! keeps a tracked or neighbouring motion unless a clearly better one is found, so a
//! small link can end up in a pose that fits its frame's cloud worse than the true one
//! (bench-dev laikago, fast, seed 0: a shank folded the wrong way in frame 6, fitting
//! its cloud 2× worse than the true pose). Once the tree is known, the joint narrows
//! the search to one degree of freedom: with the consensus screw of the child's
//! relative motion to its parent (`flips`: every frame's motion proposes a screw, the
//! one most frames follow wins), the state along it is swept in every frame (a full
//! turn for a hinge; for a slide, the frames' range widened by half its span on each
//! side). The best local minima of the cloud fit are polished by trimmed ICP, as the
//! reported poses are, and the best polished pose replaces the current one when it
//! fits the frame's cloud `SWITCH_FIT` times better (trimmed mean squared distance)
//! than the current pose polished the same way, and lies elsewhere (its points
//! further from the polished current pose, on average, than that pose's typical
//! distance to the cloud) — a pose from another basin, not the polish alone. Parents
//! are swept before their children, so a child is judged against its parent's new
//! motion. On full input only, like the rest of the repair.

use glam::{DMat4, DVec3, Vec3};

use super::flips::{state_of, turn_about, Flip, Hypothesis};
use super::observed::{polish_pose, trimmed_fit, POLISH_KEEP};
use crate::geom::knn::Grid;
use crate::geom::se3::rigid_inverse;
use crate::io::gt::JointType;

/// A swept pose replaces the current one when, both polished, its fit to the
/// frame's cloud is below this fraction of the current pose's. Measured (bench-dev
/// full, fast, seeds 0–4; recon / flow / TED / re-animation): 0.8: 0.873 / 0.879 /
/// 2.34 / 2.33; 1.0 (any better fit): 0.846 / 0.835 / 2.46 / 2.34; without the sweep
/// 0.959 / 0.997 / 2.26 / 2.51.
pub const SWITCH_FIT: f64 = 0.8;
/// Steps of the coarse sweep along a joint (5° for a hinge).
const STEPS: usize = 72;
/// Fine steps per coarse step about each local minimum.
const FINE_STEPS: usize = 10;
/// Local minima of the coarse sweep that are refined and polished.
const CANDIDATES: usize = 3;
/// Points of the part scored during the sweep (an even subsample); the polish and
/// the comparison with the current pose use all of them.
const PROBE: usize = 256;
/// Least slide range (fit units) swept for a prismatic joint.
const MIN_SLIDE: f64 = 1e-3;

/// Relative motion along screw (type, unit axis, a point on a hinge's axis) at state
/// `s` (radians or length).
fn along((jt, axis, pivot): Hypothesis, s: f64) -> DMat4 {
    match jt {
        JointType::Revolute => turn_about(axis, s, pivot),
        JointType::Prismatic => DMat4::from_translation(axis * s),
    }
}

/// Relative motions on screw `h` whose poses (`pa` times them) are the best local
/// minima of the fit of `pts` to the cloud in `grid`, at most `CANDIDATES`, best
/// first; `states`: the frames' states, which set a slide's range.
fn sweep(
    grid: &Grid,
    pts: &[DVec3],
    pa: &DMat4,
    h: Hypothesis,
    states: &[f64],
    buf: &mut Vec<f64>,
) -> Vec<DMat4> {
    let revolute = h.0 == JointType::Revolute;
    let (lo, step) = if revolute {
        (-std::f64::consts::PI, std::f64::consts::TAU / STEPS as f64)
    } else {
        let lo = states.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = states.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let span = (hi - lo).max(MIN_SLIDE);
        (lo - 0.5 * span, 2.0 * span / STEPS as f64)
    };
    if !lo.is_finite() {
        return Vec::new();
    }
    let fit =
        |s: f64, buf: &mut Vec<f64>| trimmed_fit(grid, pts, &(*pa * along(h, s)), POLISH_KEEP, buf);
    // A full turn wraps around; a slide's sweep has two ends.
    let n = if revolute { STEPS } else { STEPS + 1 };
    let f: Vec<f64> = (0..n).map(|i| fit(lo + step * i as f64, buf)).collect();
    let mut minima: Vec<(f64, usize)> = (0..n)
        .filter(|&i| {
            let (l, r) = if revolute {
                ((i + n - 1) % n, (i + 1) % n)
            } else {
                (i.saturating_sub(1), (i + 1).min(n - 1))
            };
            f[i] <= f[l] && f[i] <= f[r]
        })
        .map(|i| (f[i], i))
        .collect();
    minima.sort_by(|a, b| a.0.total_cmp(&b.0));
    minima
        .iter()
        .take(CANDIDATES)
        .map(|&(_, i)| {
            let centre = lo + step * i as f64;
            let mut best = (f64::INFINITY, centre);
            for k in 0..=2 * FINE_STEPS {
                let s = centre + step * (k as f64 / FINE_STEPS as f64 - 1.0);
                let v = fit(s, buf);
                if v < best.0 {
                    best = (v, s);
                }
            }
            along(h, best.1)
        })
        .collect()
}

/// Sweeps child `b` of part `a` along screw `h` in every frame (module doc),
/// replacing `motions[t][b]` (frame canonical → t) where the swept pose fits
/// clearly better. `pts`: the child's canonical points; `frames[t]`: every frame's
/// cloud and `grids[t]` its grid (none for the canonical frame). Returns the
/// replaced motions, each as the rigid map of the canonical frame applied after the
/// old motion.
#[allow(clippy::too_many_arguments)]
pub(crate) fn sweep_child(
    motions: &mut [Vec<DMat4>],
    a: usize,
    b: usize,
    h: Hypothesis,
    pts: &[DVec3],
    frames: &[Vec<Vec3>],
    grids: &[Option<Grid>],
    dst: &mut Vec<DVec3>,
    buf: &mut Vec<f64>,
) -> Vec<Flip> {
    let states: Vec<f64> = motions
        .iter()
        .map(|m| state_of(&(rigid_inverse(&m[a]) * m[b]), h))
        .collect();
    let step = pts.len().div_ceil(PROBE).max(1);
    let probe: Vec<DVec3> = pts.iter().step_by(step).copied().collect();
    let mut out = Vec::new();
    for (t, cloud) in frames.iter().enumerate() {
        let Some(grid) = grids.get(t).and_then(Option::as_ref) else {
            continue;
        };
        let (pa, cur) = (motions[t][a], motions[t][b]);
        let polish = |start: DMat4, dst: &mut Vec<DVec3>, buf: &mut Vec<f64>| {
            let mo = polish_pose(grid, cloud, pts, &start, dst);
            (trimmed_fit(grid, pts, &mo, POLISH_KEEP, buf), mo)
        };
        // The current pose is judged polished as the candidates are, so that a
        // candidate must come from a better basin, not just from the polish.
        let (fit_now, now) = polish(cur, dst, buf);
        let mut best: Option<(f64, DMat4)> = None;
        for q in sweep(grid, &probe, &pa, h, &states, buf) {
            let (f, mo) = polish(pa * q, dst, buf);
            if best.is_none_or(|x| f < x.0) {
                best = Some((f, mo));
            }
        }
        if let Some((f, mo)) = best {
            // Another basin: the part's points sit further from the polished current
            // pose, on average, than the current fit's typical distance.
            let moved = pts
                .iter()
                .map(|x| mo.transform_point3(*x).distance(now.transform_point3(*x)))
                .sum::<f64>()
                / pts.len() as f64;
            if f < SWITCH_FIT * fit_now && moved > fit_now.sqrt() {
                motions[t][b] = mo;
                out.push(Flip {
                    frame: t,
                    part: b,
                    flip: rigid_inverse(&cur) * mo,
                    swept: true,
                });
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kinematics::flips::repair_flips;
    use crate::kinematics::flips::tests::{posed, rod_extents, scene_sampled, turn};

    /// Largest distance between the rod's points moved by `mo` and by `truth`.
    fn rod_error(pts: &[glam::Vec3], labels: &[u32], mo: &DMat4, truth: &DMat4) -> f64 {
        pts.iter()
            .zip(labels)
            .filter(|(_, &l)| l == 1)
            .map(|(x, _)| {
                let x = x.as_dvec3();
                mo.transform_point3(x).distance(truth.transform_point3(x))
            })
            .fold(0.0, f64::max)
    }

    #[test]
    fn a_link_folded_the_wrong_way_is_swept_back_onto_its_hinge() {
        let (pts, labels) = scene_sampled(Some(200));
        let hinge = |q: f64| turn(DVec3::Y, q, DVec3::new(0.0, 0.0, 0.12));
        let states = [0.0, 0.3, 0.6, 0.9, 1.1, 0.8, 0.5, 0.2];
        let truth: Vec<DMat4> = states.iter().map(|&q| hinge(q)).collect();
        // Every frame samples the scene afresh, as a scanner would.
        let frames = posed(&truth, |t| scene_sampled(Some(200 + t as u64)));
        let mut motions: Vec<Vec<DMat4>> =
            truth.iter().map(|m| vec![DMat4::IDENTITY, *m]).collect();
        let extents = rod_extents();
        // True motions fit as well as anything on the hinge: nothing is replaced.
        let before = motions.clone();
        assert!(
            repair_flips(&mut motions, &[-1, 0], 0, &pts, &labels, &frames, &extents).is_empty()
        );
        assert_eq!(motions, before);
        // Frame 4 folded the other way, frame 6 knocked off its hinge.
        motions[4][1] = hinge(-1.1);
        motions[6][1] = DMat4::from_translation(DVec3::new(0.08, 0.0, 0.0)) * truth[6];
        let swept = repair_flips(&mut motions, &[-1, 0], 0, &pts, &labels, &frames, &extents);
        let mut fixed: Vec<usize> = swept.iter().map(|f| f.frame).collect();
        fixed.sort_unstable();
        assert_eq!(fixed, vec![4, 6]);
        // Within a sixth of the rod's radius at every rod point (the polish fits a
        // fresh sample of a nearly symmetric rod).
        for t in [4, 6] {
            let err = rod_error(&pts, &labels, &motions[t][1], &truth[t]);
            assert!(err < 0.005, "frame {t}: rod points off by up to {err}");
        }
    }

    #[test]
    fn a_slide_is_swept_back_into_place() {
        let (pts, labels) = scene_sampled(Some(300));
        let slide = |x: f64| DMat4::from_translation(DVec3::new(x, 0.0, 0.0));
        let states = [0.0, 0.05, 0.1, 0.15, 0.2, 0.15, 0.1, 0.05];
        let truth: Vec<DMat4> = states.iter().map(|&x| slide(x)).collect();
        let frames = posed(&truth, |t| scene_sampled(Some(300 + t as u64)));
        let mut motions: Vec<Vec<DMat4>> =
            truth.iter().map(|m| vec![DMat4::IDENTITY, *m]).collect();
        // Frames 2 and 5 with the rod lying on the base (a pose the polish keeps).
        let lying = turn(
            DVec3::Y,
            std::f64::consts::FRAC_PI_2,
            DVec3::new(0.0, 0.0, 0.12),
        );
        motions[2][1] = truth[2] * lying;
        motions[5][1] = truth[5] * lying;
        let extents = rod_extents();
        let swept = repair_flips(&mut motions, &[-1, 0], 0, &pts, &labels, &frames, &extents);
        let mut fixed: Vec<usize> = swept.iter().filter(|f| f.swept).map(|f| f.frame).collect();
        fixed.sort_unstable();
        assert_eq!(fixed, vec![2, 5]);
        // Within a third of the rod's radius (it lay half a rod's length away).
        for t in [2, 5] {
            let err = rod_error(&pts, &labels, &motions[t][1], &truth[t]);
            assert!(err < 0.01, "frame {t}: rod points off by up to {err}");
        }
    }
}
