//! Per-frame labels on occluded input, refined by classification EM.
//!
//! On occluded input each frame shows one side of every part, and the Gaussians that
//! label it (Step 1's segmenting copy, `fit::select::SEGMENT_ITERS`) are posed from
//! the motion search, which is often far off there (tens of degrees). Their labels
//! follow the parts roughly but cut them in the wrong places. Here a frame's Gaussian
//! labels are the start of a hard (classification) EM of a Gaussian mixture on that
//! frame's points alone: each Gaussian gets the mean, covariance and share of the
//! points it holds, every point goes to the Gaussian under which it is most likely,
//! and this repeats until no label changes. The Gaussians then fit the side the frame
//! shows. It only moves boundaries between Gaussians the frame already has, so it
//! cannot find a part the labels missed.
//!
//! Measured (bench-dev occluded, fast, seeds 0–4; `gsart synth NAME --occluded`,
//! generator seeds 0–3, fast), mean RI before → after:
//! - with the Gaussians (this): bench-dev 0.769 → 0.784, panda_gripper 0.790 → 0.826,
//!   no robot lower by more than 0.001; procedural 0.722 → 0.729, the cabinet 0.719 →
//!   0.712;
//! - with one Gaussian per merged part instead: bench-dev 0.769 → 0.799, but
//!   panda_gripper 0.790 → 0.710 and the procedural cabinet 0.719 → 0.601: one
//!   Gaussian cannot model a hollow box or a hand plate, and a spurious extra part on
//!   it grows over half of it. Not kept.
//! - from the polished Gaussians' own labels, without the copy (1100 fewer iterations
//!   a candidate, Step 1 0.5–1.1 s faster a sequence): bench-dev fast 0.784 as well,
//!   balanced (seeds 0–2) 0.824 against 0.818, procedural 0.733, but partial (fast,
//!   seeds 0–1) 0.795 against 0.805, solo12 partial 0.766 → 0.694 and occluded 0.673 →
//!   0.663. Not kept: the copy's labels are the safer start.
//!
//! On full input, where the labels come from motions that fit, a per-frame mixture
//! cuts parts by shape instead of motion (one Gaussian per part, a prototype: bench-dev
//! full, fast, seed 0, mean RI 0.904 → 0.897); it is not used there.

use crate::fit::gaussians::outer;
use crate::math::Libm;
use glam::{DMat3, DVec3, Vec3};

/// Covariance floor of [`refine_frame`], in squared point spacings of the frame
/// (a standard deviation of half a spacing): no Gaussian gets thinner than the
/// sampling, which a single row of points would otherwise be (with a floor of 1e-5
/// squared fit units a flat strip's second Gaussian ended as one row of points).
/// Bench-dev occluded (fast, seeds 0–4) mean RI 0.783 with that fixed floor, 0.784 at
/// 0.25 spacings², 0.785 at 1; procedural occluded 0.730, 0.729, 0.727.
const FLOOR_SPACINGS: f64 = 0.25;
/// Most rounds of [`refine_frame`], a bound on its cost (a round is one pass
/// over a frame's points and the Gaussians); most frames settle before it.
const MAX_ROUNDS: usize = 30;

/// An occluded frame's Gaussian labels (`g`, one per point, each below `m`) refined
/// on the frame's own points, with the floor and round bound above.
pub fn refine_frame(points: &[Vec3], g: &mut [u32], m: usize) {
    let spacing = crate::geom::knn::point_spacing(points);
    refine_labels(points, g, m, FLOOR_SPACINGS * spacing * spacing, MAX_ROUNDS);
}

/// A Gaussian holding fewer points than this in a frame takes no part in the EM there
/// (its covariance would be meaningless); its points go to the others.
const MIN_POINTS: usize = 8;

/// One component of the classification likelihood.
struct Component {
    mean: DVec3,
    inv_cov: DMat3,
    /// ln det Σ − 2 ln(share): the cost of a point at the mean.
    offset: f64,
}

/// Refines `labels` (one per point of `points`, each below `components`) in place by
/// classification EM (module docs): at most `max_iters` rounds, stopping when no label
/// changes. `floor` is added to every covariance's diagonal (squared input units), so
/// a flat or tiny component stays a proper Gaussian. Returns the rounds that changed
/// labels.
pub fn refine_labels(
    points: &[Vec3],
    labels: &mut [u32],
    components: usize,
    floor: f64,
    max_iters: usize,
) -> usize {
    if points.len() != labels.len() || components < 2 {
        return 0;
    }
    let mut comps: Vec<Option<Component>> = Vec::with_capacity(components);
    let mut sums = vec![(DVec3::ZERO, DMat3::ZERO, 0usize); components];
    let mut rounds = 0;
    for _ in 0..max_iters {
        // M-step: each component's mean, covariance and share.
        sums.iter_mut()
            .for_each(|s| *s = (DVec3::ZERO, DMat3::ZERO, 0));
        for (x, &l) in points.iter().zip(labels.iter()) {
            if let Some(s) = sums.get_mut(l as usize) {
                let x = x.as_dvec3();
                s.0 += x;
                s.1 += outer(x, x);
                s.2 += 1;
            }
        }
        let n = points.len() as f64;
        comps.clear();
        comps.extend(sums.iter().map(|&(sum, sq, cnt)| {
            if cnt < MIN_POINTS {
                return None;
            }
            let c = cnt as f64;
            let mean = sum / c;
            let cov =
                sq * (1.0 / c) - outer(mean, mean) + DMat3::from_diagonal(DVec3::splat(floor));
            let det = cov.determinant();
            (det > 0.0 && det.is_finite()).then(|| Component {
                mean,
                inv_cov: cov.inverse(),
                offset: det.lln() - 2.0 * (c / n).lln(),
            })
        }));
        if comps.iter().all(Option::is_none) {
            break;
        }
        // E-step (hard): every point to its most likely component.
        let mut changed = false;
        for (x, l) in points.iter().zip(labels.iter_mut()) {
            let x = x.as_dvec3();
            let best = comps
                .iter()
                .enumerate()
                .filter_map(|(p, c)| {
                    let c = c.as_ref()?;
                    let d = x - c.mean;
                    Some((p, d.dot(c.inv_cov * d) + c.offset))
                })
                .min_by(|a, b| a.1.total_cmp(&b.1))
                .map(|(p, _)| p as u32);
            if let Some(b) = best {
                if b != *l {
                    *l = b;
                    changed = true;
                }
            }
        }
        if !changed {
            break;
        }
        rounds += 1;
    }
    rounds
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// Points of an L: a bar along x (part 0, x in [0, 1], y in [0, 0.2]) and a bar
    /// along y standing on its end (part 1, x in [0.8, 1], y in [0.2, 1.2]); z in
    /// [0, 0.2] for both.
    fn ell(n: usize) -> (Vec<Vec3>, Vec<u32>) {
        let mut rng = rand::rngs::StdRng::seed_from_u64(3);
        let mut pts = Vec::new();
        let mut truth = Vec::new();
        for i in 0..n {
            let p = (i % 2) as u32;
            let (u, v, w) = (
                rng.random::<f32>(),
                rng.random::<f32>(),
                rng.random::<f32>() * 0.2,
            );
            pts.push(if p == 0 {
                Vec3::new(u, 0.2 * v, w)
            } else {
                Vec3::new(0.8 + 0.2 * v, 0.2 + u, w)
            });
            truth.push(p);
        }
        (pts, truth)
    }

    fn wrong(l: &[u32], truth: &[u32]) -> usize {
        l.iter().zip(truth).filter(|(a, b)| a != b).count()
    }

    #[test]
    fn a_boundary_cut_in_the_wrong_place_moves_to_where_the_parts_meet() {
        let (pts, truth) = ell(2000);
        // Labels cut at y = 0.5 instead of 0.2: the standing bar's lowest 30 % sits in
        // part 0.
        let mut labels: Vec<u32> = pts.iter().map(|p| u32::from(p.y >= 0.5)).collect();
        let before = wrong(&labels, &truth);
        assert!(before > 250, "{before}");
        let rounds = refine_labels(&pts, &mut labels, 2, 1e-6, 30);
        let after = wrong(&labels, &truth);
        assert!(rounds > 0);
        assert!(after < before / 5, "{before} → {after} mislabelled");
    }

    #[test]
    fn right_labels_stay_and_tiny_parts_give_their_points_away() {
        let (pts, truth) = ell(2000);
        let mut labels = truth.clone();
        // Part 2 holds three points: too few for a covariance.
        labels[0] = 2;
        labels[2] = 2;
        labels[4] = 2;
        refine_labels(&pts, &mut labels, 3, 1e-6, 30);
        assert!(labels.iter().all(|&l| l < 2));
        let w = wrong(&labels, &truth);
        // Only where the bars meet (the corner fits either Gaussian) may labels move.
        assert!(w < 100, "{w} mislabelled");
    }

    #[test]
    fn with_a_floor_of_the_spacing_no_gaussian_shrinks_to_a_row_of_points() {
        // A flat strip, 40 columns × 12 rows, its middle columns 20–28 held by the
        // second Gaussian (so the segmenting copy left frame 0 of
        // `select`'s bent-strip test): nothing in the shape says where to cut.
        let pts: Vec<Vec3> = (0..480)
            .map(|i| Vec3::new((i % 40) as f32 * 0.025, (i / 40) as f32 * 0.02, 0.0))
            .collect();
        let start: Vec<u32> = (0..480)
            .map(|i| u32::from((20..=28).contains(&(i % 40))))
            .collect();
        let columns = |l: &[u32]| {
            let mut c: Vec<usize> = (0..480).filter(|&i| l[i] == 1).map(|i| i % 40).collect();
            c.sort_unstable();
            c.dedup();
            c.len()
        };
        // A floor far below the spacing: the second Gaussian ends as one column of
        // points, thinner than the sampling, and holds on to it.
        let mut thin = start.clone();
        refine_labels(&pts, &mut thin, 2, 1e-7, 30);
        assert!(columns(&thin) <= 2, "{} columns", columns(&thin));
        // With half a spacing as the floor's deviation it cannot.
        let spacing = crate::geom::knn::point_spacing(&pts);
        let mut labels = start;
        refine_labels(&pts, &mut labels, 2, FLOOR_SPACINGS * spacing * spacing, 30);
        let c = columns(&labels);
        assert!(c == 0 || c >= 3, "{c} columns");
    }

    #[test]
    fn mismatched_input_is_left_alone() {
        let (pts, _) = ell(10);
        let mut labels = vec![0u32; 9];
        assert_eq!(refine_labels(&pts, &mut labels, 2, 1e-6, 30), 0);
        assert!(labels.iter().all(|&l| l == 0));
    }
}
