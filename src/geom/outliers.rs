//! Flying pixels: points with no other point of their frame nearby.
//!
//! A depth camera throws a few points off the surface (mixed pixels at depth edges,
//! multipath). No part's motion explains them, so they pull the fit's Chamfer and
//! transport terms, and they count as "unexplained" in the measure the balanced preset
//! uses to decide whether to fit again (`kinematics::coverage`): with 2 % of such
//! points every bench-dev robot was fitted three times (docs/DEVELOPMENT.md, session
//! 58). A point is isolated when no other point of its frame lies within
//! [`ISOLATED_SPACINGS`] point spacings; isolated points are left out of the working
//! clouds and of the coverage measure, and are labelled like every other point.

use super::knn::{point_spacing, Grid};

/// A point is isolated when no other point of its frame lies within this many point
/// spacings (the frame's median nearest-neighbour distance). Exact surface samples
/// are not at 5: no point of bench-dev's full frames or of the procedural objects'
/// (generator seed 0) is (at 4 spacings, 1–10 of each robot's 40 960), while about half
/// of the points thrown 5–15 % of the size off the surface are (the others land near
/// another surface). Sparse one-sided views have a few (bench-dev occluded: 1–14 of
/// 6 000–11 000 a sequence).
pub const ISOLATED_SPACINGS: f64 = 5.0;

/// At most this share of a frame is taken for flying pixels: a frame with more
/// isolated points is too sparse for the spacing to mean much, and is left whole.
pub const MAX_ISOLATED_SHARE: f64 = 0.1;

/// Which points of `points` (one frame, indexed by `grid`, its point spacing
/// `spacing`: `knn::point_spacing`) are isolated (module doc). All `false` when the
/// frame is too small to tell or more than [`MAX_ISOLATED_SHARE`] of it would be.
pub fn isolated_in(points: &[glam::Vec3], grid: &Grid, spacing: f64) -> Vec<bool> {
    let mut out = vec![false; points.len()];
    if points.len() < 16 {
        return out;
    }
    let reach = (ISOLATED_SPACINGS * spacing) as f32;
    if reach.is_nan() || reach <= 0.0 {
        return out;
    }
    let r2 = reach * reach;
    let mut count = 0;
    for (o, p) in out.iter_mut().zip(points) {
        // The point itself is indexed: it needs one more within reach.
        *o = !grid.at_least_within(*p, r2, 2);
        count += usize::from(*o);
    }
    if count as f64 > MAX_ISOLATED_SHARE * points.len() as f64 {
        out.fill(false);
    }
    out
}

/// [`isolated_in`] with the frame's own index and spacing.
pub fn isolated(points: &[glam::Vec3]) -> Vec<bool> {
    isolated_in(points, &Grid::new(points), point_spacing(points))
}

/// How many of a frame's `points` lie farther than [`ISOLATED_SPACINGS`] spacings of
/// the working cloud (`points` at `kept`) from every working point: the flying pixels
/// the fit left out (for the result's note; a point dropped only by downsampling has
/// working points around it).
pub fn left_out(points: &[glam::Vec3], kept: &[u32]) -> usize {
    let working: Vec<glam::Vec3> = kept
        .iter()
        .filter_map(|&i| points.get(i as usize).copied())
        .collect();
    if working.len() == points.len() || working.len() < 2 {
        return 0;
    }
    let reach = (ISOLATED_SPACINGS * point_spacing(&working)) as f32;
    let grid = Grid::new(&working);
    // The nearest query starts at the point's own cell, where a point on the surface
    // finds a working point at once: this runs over every input point, which may be
    // many more than the working size.
    points
        .iter()
        .filter(|&&p| grid.nearest_capped(p, reach * reach).is_none())
        .count()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Libm;
    use glam::Vec3;

    /// A 40 × 40 sheet, spacing 0.01, in the z = 0 plane.
    fn sheet() -> Vec<Vec3> {
        (0..1600)
            .map(|i| Vec3::new((i % 40) as f32 * 0.01, (i / 40) as f32 * 0.01, 0.0))
            .collect()
    }

    #[test]
    fn points_far_off_the_surface_are_isolated_and_the_surface_is_not() {
        let mut pts = sheet();
        pts.push(Vec3::new(0.2, 0.2, 0.1)); // 10 spacings above the sheet
        pts.push(Vec3::new(0.2, 0.2, 0.04)); // 4 spacings: near enough
        pts.push(Vec3::new(-0.2, 0.5, 0.3));
        let iso = isolated(&pts);
        assert!(iso[..1600].iter().all(|&x| !x));
        assert_eq!(&iso[1600..], &[true, false, true]);
        // Two flying pixels side by side vouch for each other.
        pts.push(Vec3::new(-0.2, 0.5, 0.305));
        let iso = isolated(&pts);
        assert!(!iso[1602] && !iso[1603]);
    }

    #[test]
    fn the_points_left_out_are_counted_and_downsampling_alone_leaves_none_out() {
        let mut pts = sheet();
        pts.push(Vec3::new(0.2, 0.2, 0.1));
        pts.push(Vec3::new(-0.2, 0.5, 0.3));
        let iso = isolated(&pts);
        let kept: Vec<u32> = (0..pts.len() as u32)
            .filter(|&i| !iso[i as usize])
            .collect();
        assert_eq!(left_out(&pts, &kept), 2);
        // Every other sheet point, the flying pixels among the dropped ones: those two.
        let half: Vec<u32> = (0..1600).step_by(2).collect();
        assert_eq!(left_out(&pts, &half), 2);
        let all: Vec<u32> = (0..pts.len() as u32).collect();
        assert_eq!(left_out(&pts, &all), 0);
    }

    #[test]
    fn a_frame_that_is_mostly_isolated_is_left_whole() {
        // 200 points of a sheet and 40 scattered far apart: 17 % isolated.
        let mut pts: Vec<Vec3> = sheet().into_iter().take(200).collect();
        pts.extend((0..40).map(|i| Vec3::new(1.0 + i as f32 * 0.5, 3.0, -2.0)));
        assert!(isolated(&pts).iter().all(|&x| !x));
        // Ten of them are 4 %: taken.
        pts.truncate(210);
        assert_eq!(isolated(&pts).iter().filter(|&&x| x).count(), 10);
        assert!(
            isolated(&pts[..10]).iter().all(|&x| !x),
            "too few points to tell"
        );
    }

    #[test]
    fn at_least_within_counts_like_brute_force() {
        let pts: Vec<Vec3> = (0..500)
            .map(|i| {
                let f = i as f32;
                Vec3::new(
                    (f * 0.37).lsin(),
                    (f * 0.11).lcos(),
                    (f * 0.07).lsin() * 0.5,
                )
            })
            .collect();
        let grid = Grid::new(&pts);
        for (qi, q) in [
            Vec3::ZERO,
            Vec3::new(0.5, -0.2, 0.1),
            Vec3::new(3.0, 0.0, 0.0),
        ]
        .into_iter()
        .chain(pts.iter().copied().step_by(37))
        .enumerate()
        {
            for r in [0.01f32, 0.05, 0.2, 0.6] {
                let brute = pts
                    .iter()
                    .filter(|p| p.distance_squared(q) <= r * r)
                    .count();
                for n in [1, 2, 5, 40] {
                    assert_eq!(
                        grid.at_least_within(q, r * r, n),
                        brute >= n,
                        "query {qi}, r {r}, n {n}: {brute} within"
                    );
                }
            }
        }
    }
}
