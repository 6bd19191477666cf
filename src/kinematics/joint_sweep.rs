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
//! side). A hinge is swept a second time about the same axis through the pivot the
//! frames that follow it agree on (`flips::refit_pivot`): the consensus screw comes
//! from one frame, whose pivot can be far enough off that no swept pose starts in
//! the true pose's basin (bench-dev so101, balanced, seed 0: the wrist, 0.05 off,
//! half a turn wrong in three frames). The best local minima of the cloud fit are polished by trimmed ICP, as the
//! reported poses are. A polished pose from another basin (its points further from the
//! current pose, polished the same way, on average, than that pose's typical distance
//! to the cloud) may replace the current pose when it fits the frame's cloud (trimmed
//! mean squared distance) within 1 / `SWITCH_FIT` of the frame's best fit; the
//! current pose stays allowed unless a swept pose fits `SWITCH_FIT` times better than
//! it. Among the allowed poses, each frame takes the one on the path through the
//! frames with the least sum of squared changes of state between consecutive frames
//! (`smoothest`; squared, so one jump costs more than the steps that make it up;
//! each replaced pose adds `MIN_SMOOTHING`, so a path must be clearly smoother):
//! where the clouds cannot tell poses apart (a link that looks about the same at any
//! turn about its own hinge, as bench-dev xarm7's last one does), the joint's
//! trajectory decides, the frames of a sequence being in time order. Parents are
//! swept before their children, so a child is judged against its parent's new
//! motion. On full input only, like the rest of the repair.

use glam::{DMat4, DVec3, Vec3};

use super::flips::{replace, state_of, turn_about, Flip, Hypothesis};
use super::observed::{polish_pose, trimmed_fit, trimmed_fit_capped, POLISH_KEEP};
use crate::geom::knn::Grid;
use crate::geom::se3::rigid_inverse;
use crate::io::gt::JointType;

/// The current pose must be replaced when a swept pose's fit to the frame's cloud
/// (both polished) is below this fraction of its fit, and a swept pose may replace
/// it when its fit is within the inverse of this of the frame's best. Measured
/// (bench-dev full, fast, seeds 0–4; recon / flow / TED / re-animation) when the
/// best swept pose replaced the current one (before `smoothest`): 0.8: 0.873 /
/// 0.879 / 2.34 / 2.33; 1.0 (any better fit): 0.846 / 0.835 / 2.46 / 2.34; without
/// the sweep 0.959 / 0.997 / 2.26 / 2.51. With `smoothest` (squared changes and
/// `MIN_SMOOTHING`): 0.834 / 0.788 / 2.31 / 2.26; without `MIN_SMOOTHING` 0.807 /
/// 0.764 / 2.29 / 2.27; with the sum of absolute changes 0.809 / 0.780 / 2.40 /
/// 2.29, and with it allowing only poses within 1 / 0.9 of the best (the current
/// pose still within 1 / 0.8) 0.829 / 0.779 / 2.31 / 2.28.
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
/// A replaced pose must lower the path's sum of squared state changes by this much
/// (a step of half a radian, or of half the part's RMS radius along a slide): on
/// exact motions, a link that looks the same at any turn about its hinge (bench-dev
/// xarm7's last one) is left where it is, not moved to a slightly smoother path.
const MIN_SMOOTHING: f64 = 0.25;
/// Squared distance (fit units: a tenth of the object's size) at which the coarse
/// sweep's fit caps each point's distance to the cloud. Most of a full turn puts the
/// part far from the cloud, where an uncapped query grows shells of cells until it
/// meets a point (the coarse sweep was 14 % of a full fit's CPU, the fine sweep about
/// the minima 4 %); capped, a far pose still scores far above a near one. Measured
/// (fast, fit seed 0): bench-dev full, procedural laptop, cabinet, arm and quadruped
/// (generator seeds 0–3) give the same results bit for bit as uncapped, in less CPU
/// (DEVELOPMENT, session 36). The fine sweep is not capped.
const COARSE_CAP2: f32 = 0.01;
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
    let fit = |s: f64, cap2: f32, buf: &mut Vec<f64>| {
        trimmed_fit_capped(grid, pts, &(*pa * along(h, s)), POLISH_KEEP, cap2, buf)
    };
    // A full turn wraps around; a slide's sweep has two ends.
    let n = if revolute { STEPS } else { STEPS + 1 };
    let f: Vec<f64> = (0..n)
        .map(|i| fit(lo + step * i as f64, COARSE_CAP2, buf))
        .collect();
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
                let v = fit(s, f32::INFINITY, buf);
                if v < best.0 {
                    best = (v, s);
                }
            }
            along(h, best.1)
        })
        .collect()
}

/// Sweeps child `b` of part `a` along each of `screws` (the consensus screw first,
/// which sets the frames' states, then the same axis through other pivots) in every
/// frame (module doc),
/// replacing `motions[t][b]` (frame canonical → t) where a swept pose fits clearly
/// better, or about as well and on a clearly smoother path of states. `pts`: the
/// child's canonical points; `frames[t]`: every frame's cloud and `grids[t]` its grid
/// (none for the canonical frame). Returns the replaced motions, each as the rigid
/// map of the canonical frame applied after the old motion.
#[allow(clippy::too_many_arguments)]
pub(crate) fn sweep_child(
    motions: &mut [Vec<DMat4>],
    a: usize,
    b: usize,
    screws: &[Hypothesis],
    pts: &[DVec3],
    frames: &[Vec<Vec3>],
    grids: &[Option<Grid>],
    dst: &mut Vec<DVec3>,
    buf: &mut Vec<f64>,
) -> Vec<Flip> {
    let Some(&h) = screws.first() else {
        return Vec::new();
    };
    let states: Vec<f64> = motions
        .iter()
        .map(|m| state_of(&(rigid_inverse(&m[a]) * m[b]), h))
        .collect();
    let step = pts.len().div_ceil(PROBE).max(1);
    let probe: Vec<DVec3> = pts.iter().step_by(step).copied().collect();
    let revolute = h.0 == JointType::Revolute;
    // A slide's states are compared in units of the part's size, a hinge's in radians.
    let scale = if revolute { 1.0 } else { rms_radius(pts) };
    // Per frame, the poses it may take: the current one first, then the swept poses
    // from other basins that fit the cloud within 1 / SWITCH_FIT of the frame's best.
    let mut options: Vec<Vec<Choice>> = Vec::with_capacity(motions.len());
    for (t, cloud) in frames.iter().enumerate() {
        let (pa, cur) = (motions[t][a], motions[t][b]);
        let mine = Choice {
            mo: cur,
            state: states[t] / scale,
            cost: 0.0,
        };
        let Some(grid) = grids.get(t).and_then(Option::as_ref) else {
            options.push(vec![mine]);
            continue;
        };
        let polish = |start: DMat4, dst: &mut Vec<DVec3>, buf: &mut Vec<f64>| {
            let mo = polish_pose(grid, cloud, pts, &start, dst);
            (trimmed_fit(grid, pts, &mo, POLISH_KEEP, buf), mo)
        };
        // The current pose is judged polished as the candidates are, so that a
        // candidate must come from a better basin, not just from the polish.
        let (fit_now, now) = polish(cur, dst, buf);
        let mut swept: Vec<(f64, DMat4)> = Vec::new();
        let starts: Vec<DMat4> = screws
            .iter()
            .flat_map(|&g| sweep(grid, &probe, &pa, g, &states, buf))
            .collect();
        for q in starts {
            let (f, mo) = polish(pa * q, dst, buf);
            // Another basin: the part's points sit further from the polished current
            // pose, on average, than the current fit's typical distance.
            let moved = pts
                .iter()
                .map(|x| mo.transform_point3(*x).distance(now.transform_point3(*x)))
                .sum::<f64>()
                / pts.len() as f64;
            if moved > fit_now.sqrt() {
                swept.push((f, mo));
            }
        }
        let best = swept.iter().map(|x| x.0).fold(fit_now, f64::min);
        let mut opts = Vec::new();
        if SWITCH_FIT * fit_now <= best {
            opts.push(mine);
        }
        let inv_pa = rigid_inverse(&pa);
        opts.extend(
            swept
                .iter()
                .filter(|x| SWITCH_FIT * x.0 <= best)
                .map(|&(_, mo)| Choice {
                    mo,
                    state: state_of(&(inv_pa * mo), h) / scale,
                    cost: MIN_SMOOTHING,
                }),
        );
        if opts.is_empty() {
            // Fits that do not compare (not finite): keep the pose.
            opts.push(mine);
        }
        options.push(opts);
    }
    let path = smoothest(&options, revolute);
    let mut out = Vec::new();
    for (t, (opts, &i)) in options.iter().zip(&path).enumerate() {
        let cur = motions[t][b];
        let mo = opts[i].mo;
        if mo != cur {
            out.push(replace(motions, (t, b), mo, rigid_inverse(&cur) * mo, true));
        }
    }
    out
}

/// A pose a frame may take in the sweep: the motion and its state along the screw.
#[derive(Clone, Copy)]
struct Choice {
    mo: DMat4,
    /// Radians for a hinge; for a slide, in units of the part's RMS radius.
    state: f64,
    /// Added to the path's cost when taken: 0 for the current pose.
    cost: f64,
}

/// RMS distance of `pts` from their centroid (at least 1e-6).
fn rms_radius(pts: &[DVec3]) -> f64 {
    if pts.is_empty() {
        return 1.0;
    }
    let c = pts.iter().copied().sum::<DVec3>() / pts.len() as f64;
    let r = (pts.iter().map(|p| p.distance_squared(c)).sum::<f64>() / pts.len() as f64).sqrt();
    r.max(1e-6)
}

/// Absolute difference of two states, a hinge's taken the short way round (≤ π).
fn state_gap(x: f64, y: f64, revolute: bool) -> f64 {
    let d = x - y;
    if revolute {
        (d + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI
    } else {
        d
    }
    .abs()
}

/// One option per frame (indices into `options[t]`, each non-empty) with the least
/// sum of the options' costs and the squared state changes between consecutive
/// frames (dynamic programming); ties keep the earlier option. Squared: with
/// the sum of changes, a hinge swinging back and forth (a cabinet door) lost to one
/// jump onto a pose that fits as well and stays put (the door folded onto the body).
fn smoothest(options: &[Vec<Choice>], revolute: bool) -> Vec<usize> {
    let k = options.len();
    if k == 0 {
        return Vec::new();
    }
    let mut cost: Vec<Vec<f64>> = vec![options[0].iter().map(|o| o.cost).collect()];
    let mut back: Vec<Vec<usize>> = vec![vec![0; options[0].len()]];
    for t in 1..k {
        let (c, b): (Vec<f64>, Vec<usize>) = options[t]
            .iter()
            .map(|o| {
                argmin(
                    options[t - 1]
                        .iter()
                        .zip(&cost[t - 1])
                        .map(|(p, &c)| c + o.cost + state_gap(o.state, p.state, revolute).powi(2)),
                )
            })
            .unzip();
        cost.push(c);
        back.push(b);
    }
    let mut path = vec![0; k];
    path[k - 1] = argmin(cost[k - 1].iter().copied()).1;
    for t in (1..k).rev() {
        path[t - 1] = back[t][path[t]];
    }
    path
}

/// The least value and its index, the first of equal ones ((∞, 0) when none is
/// below infinity).
fn argmin(values: impl Iterator<Item = f64>) -> (f64, usize) {
    values.enumerate().fold(
        (f64::INFINITY, 0),
        |acc, (i, x)| if x < acc.0 { (x, i) } else { acc },
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kinematics::flips::repair_flips;
    use crate::kinematics::flips::tests::{posed, rod_extents, scene_sampled, turn};
    use crate::kinematics::screw::PartExtent;

    /// The frames of `flips`, in order.
    fn frames_of(flips: &[Flip]) -> Vec<usize> {
        let mut f: Vec<usize> = flips.iter().map(|f| f.frame).collect();
        f.sort_unstable();
        f
    }

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
        assert_eq!(frames_of(&swept), vec![4, 6]);
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

    #[test]
    fn a_second_pivot_reaches_a_fold_the_first_one_cannot() {
        let (pts, labels) = scene_sampled(Some(500));
        let pivot = DVec3::new(0.0, 0.0, 0.12);
        let hinge = |q: f64| turn(DVec3::Y, q, pivot);
        let states = [0.0, 0.3, 0.6, 0.9, 1.1, 0.8, 0.5, 0.2];
        let truth: Vec<DMat4> = states.iter().map(|&q| hinge(q)).collect();
        let frames = posed(&truth, |t| scene_sampled(Some(500 + t as u64)));
        let grids: Vec<Option<Grid>> = frames
            .iter()
            .enumerate()
            .map(|(t, c)| (t != 0).then(|| Grid::new(c)))
            .collect();
        let rod: Vec<DVec3> = pts
            .iter()
            .zip(&labels)
            .filter(|(_, &l)| l == 1)
            .map(|(x, _)| x.as_dvec3())
            .collect();
        // Frame 4 folded the other way.
        let mut start: Vec<Vec<DMat4>> = truth.iter().map(|m| vec![DMat4::IDENTITY, *m]).collect();
        start[4][1] = hinge(-1.1);
        // The hinge proposed a tenth off its pivot, and through the true one.
        let off = (
            JointType::Revolute,
            DVec3::Y,
            pivot + DVec3::new(0.1, 0.0, 0.0),
        );
        let on = (JointType::Revolute, DVec3::Y, pivot);
        let run = |screws: &[Hypothesis]| {
            let mut motions = start.clone();
            let (mut dst, mut buf) = (Vec::new(), Vec::new());
            let swept = sweep_child(
                &mut motions,
                0,
                1,
                screws,
                &rod,
                &frames,
                &grids,
                &mut dst,
                &mut buf,
            );
            (
                frames_of(&swept),
                rod_error(&pts, &labels, &motions[4][1], &truth[4]),
            )
        };
        // Along the proposed pivot alone the fold stays.
        let (_, err) = run(&[off]);
        assert!(
            err > 0.1,
            "the proposed pivot alone reached the fold: {err}"
        );
        // With the second pivot it is swept back.
        let (fixed, err) = run(&[off, on]);
        assert_eq!(fixed, vec![4]);
        assert!(err < 0.005, "rod points off by up to {err}");
    }

    /// A base box and a flat bar lying across a hinge (the z axis) at height 0.2:
    /// half a turn about the hinge maps the bar onto itself. `seed` draws the bar's
    /// points afresh.
    fn propeller(seed: u64) -> (Vec<glam::Vec3>, Vec<u32>) {
        use rand::{Rng, SeedableRng};
        let mut rng = rand::rngs::SmallRng::seed_from_u64(seed);
        let mut pts = Vec::new();
        let mut labels = Vec::new();
        for i in 0..10 {
            for j in 0..10 {
                for z in [0.0, 0.1] {
                    pts.push(glam::Vec3::new(
                        i as f32 * 0.04 - 0.2,
                        j as f32 * 0.04 - 0.2,
                        z,
                    ));
                    labels.push(0);
                }
            }
        }
        for _ in 0..300 {
            let (x, y): (f32, f32) = (rng.random(), rng.random());
            pts.push(glam::Vec3::new(0.4 * x - 0.2, 0.04 * y - 0.02, 0.2));
            labels.push(1);
        }
        (pts, labels)
    }

    #[test]
    fn a_state_the_clouds_cannot_tell_follows_its_neighbours() {
        let (pts, labels) = propeller(400);
        let hinge = |q: f64| turn(DVec3::Z, q, DVec3::ZERO);
        let states = [0.0, 0.2, 0.4, 0.6, 0.8, 0.6, 0.4, 0.2];
        let truth: Vec<DMat4> = states.iter().map(|&q| hinge(q)).collect();
        let frames = posed(&truth, |t| propeller(400 + t as u64));
        let mut motions: Vec<Vec<DMat4>> =
            truth.iter().map(|m| vec![DMat4::IDENTITY, *m]).collect();
        // Frames 3 and 4 half a turn off about the hinge: the clouds fit as well.
        motions[3][1] = hinge(states[3] + std::f64::consts::PI);
        motions[4][1] = hinge(states[4] + std::f64::consts::PI);
        let extents = vec![
            PartExtent::default(),
            PartExtent {
                centre: DVec3::new(0.0, 0.0, 0.2),
                radius: 0.2,
            },
        ];
        let swept = repair_flips(&mut motions, &[-1, 0], 0, &pts, &labels, &frames, &extents);
        assert_eq!(frames_of(&swept), vec![3, 4]);
        for t in [3, 4] {
            let err = rod_error(&pts, &labels, &motions[t][1], &truth[t]);
            assert!(err < 0.01, "frame {t}: bar points off by up to {err}");
        }
    }

    #[test]
    fn the_smoothest_path_takes_the_least_state_change() {
        let o = |s: &[f64]| -> Vec<Choice> {
            s.iter()
                .enumerate()
                .map(|(i, &state)| Choice {
                    mo: DMat4::IDENTITY,
                    state,
                    // The first option is the current pose.
                    cost: if i == 0 { 0.0 } else { MIN_SMOOTHING },
                })
                .collect()
        };
        // Each frame's second option is half a turn off.
        let opts = vec![o(&[0.0]), o(&[0.1, 3.2]), o(&[3.3, 0.2]), o(&[0.3])];
        assert_eq!(smoothest(&opts, true), vec![0, 0, 1, 0]);
        // A hinge's states wrap: 3.1 and −3.1 are 0.08 apart.
        let opts = vec![o(&[3.1]), o(&[0.0, -3.1])];
        assert_eq!(smoothest(&opts, true), vec![0, 1]);
        // A slide's do not.
        let opts = vec![o(&[3.1]), o(&[0.0, -3.1])];
        assert_eq!(smoothest(&opts, false), vec![0, 0]);
        // Ties keep the first option (the current pose).
        let opts = vec![o(&[0.0]), o(&[0.5, -0.5])];
        assert_eq!(smoothest(&opts, true), vec![0, 0]);
        // A replacement that smooths the path by less than `MIN_SMOOTHING` is not
        // taken (0.36 + 0.16 against 0.25 + 0.25 + 0.25).
        let opts = vec![o(&[0.0]), o(&[0.6, 0.5]), o(&[1.0])];
        assert_eq!(smoothest(&opts, true), vec![0, 0, 0]);
        assert!(smoothest(&[], true).is_empty());
    }
}
