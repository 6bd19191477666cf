//! Lower bounds of nearest-point distances without a search, for the pose search's
//! coarse scoring: per marked cell of a `CapMask`, the distance from the cell's centre
//! to the nearest point. The distance to a cloud is 1-Lipschitz, so that distance less
//! the way from the centre to a place bounds the place's distance from below.
//!
//! Why: the search scores 2048 candidate poses per Gaussian and frame by the capped
//! distances of 48 probe points, and a third of a balanced fit's time went to those
//! grid queries. Summing bounds first drops most candidates without a query.
//!
//! A cell is measured the first time a query lands in it (a robot's frames have
//! 40 000–170 000 marked cells, and a search visits a part of them), and it remembers
//! its nearest point: the search removes the points each posed Gaussian explains (its
//! `claim`), and the cells whose nearest point went are measured again when next
//! asked (`forget`), so the bounds stay close to the distances of the points left.

use std::cell::Cell;

use glam::Vec3;

use super::cap_mask::{CapMask, Place};
use super::knn::Grid;

/// `nearest` of a cell with no point within `reach` of its centre.
const NONE: u32 = u32::MAX;

/// `nearest` of a cell not measured (since its nearest point went).
const UNMEASURED: u32 = u32::MAX - 1;

/// Centre distances of a mask's marked cells to a cloud (the mask's, or a subset),
/// measured on demand.
#[derive(Debug, Clone, Default)]
pub struct CapBound {
    /// Per slot: the centre's distance to the nearest point in steps of `step`,
    /// rounded down (a byte: every frame of every candidate's search keeps its own);
    /// `u8::MAX` (`reach`) when none is nearer.
    dist: Vec<Cell<u8>>,
    /// Per slot: that point's index in the mask's cloud, `NONE` or `UNMEASURED`.
    nearest: Vec<Cell<u32>>,
    reach: f32,
    step: f32,
    /// Absolute margin for the f32 rounding of the distances (the coordinates' scale).
    eps: f32,
}

impl CapBound {
    /// Bounds for `mask` (built with `radius`), every cell still to be measured.
    pub fn new(mask: &CapMask, radius: f32) -> Self {
        let reach = radius * 1.01 + mask.half_diagonal();
        let n = mask.slots();
        CapBound {
            dist: vec![Cell::new(u8::MAX); n],
            nearest: vec![Cell::new(UNMEASURED); n],
            reach,
            step: reach / u8::MAX as f32,
            eps: 1e-5 * (mask.scale() + reach),
        }
    }

    /// Whether there are no bounds (`default`): `lower_distance` is then 0 wherever a
    /// point may lie within the radius.
    pub fn is_empty(&self) -> bool {
        self.dist.is_empty()
    }

    /// `None` when `q` is certainly farther than the mask's radius from every point;
    /// otherwise a lower bound of its distance to the nearest point of the cloud
    /// `grid` indexes (its point `j` is point `orig[j]` of the mask's cloud).
    #[inline]
    pub fn lower_distance(
        &self,
        mask: &CapMask,
        grid: &Grid,
        orig: &[u32],
        q: Vec3,
    ) -> Option<f32> {
        match mask.place(q) {
            Place::Far => None,
            Place::Near(s, centre) if s < self.dist.len() => {
                if self.nearest[s].get() == UNMEASURED {
                    self.measure(grid, orig, s, centre);
                }
                let d = self.dist[s].get() as f32 * self.step - q.distance(centre);
                Some((d * (1.0 - 1e-4) - self.eps).max(0.0))
            }
            _ => Some(0.0),
        }
    }

    fn measure(&self, grid: &Grid, orig: &[u32], s: usize, centre: Vec3) {
        let (d, i) = grid.nearest_capped(centre, self.reach * self.reach).map_or(
            (u8::MAX, NONE),
            |(j, d2)| {
                let steps = (d2.sqrt() / self.step).min(u8::MAX as f32) as u8;
                (steps, orig[j as usize])
            },
        );
        self.dist[s].set(d);
        self.nearest[s].set(i);
    }

    /// After points were removed from the cloud (`kept[i]`: point i of the mask's
    /// cloud is still in it): the cells whose nearest point went are measured again
    /// when next asked. (A cell with none within reach stays so.)
    pub fn forget(&mut self, kept: &[bool]) {
        for n in &self.nearest {
            let i = n.get();
            if i < UNMEASURED && !kept[i as usize] {
                n.set(UNMEASURED);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::knn::tests::brute;
    use crate::math::Libm;
    use rand::{Rng, SeedableRng};

    fn patch(rng: &mut rand::rngs::StdRng, n: usize) -> Vec<Vec3> {
        (0..n)
            .map(|_| {
                let (u, v): (f32, f32) = (rng.random_range(-0.5..0.5), rng.random_range(-0.5..0.5));
                Vec3::new(u, v, 0.2 * (u * 3.0).lsin() * v)
            })
            .collect()
    }

    #[test]
    fn bounds_never_exceed_the_distance_and_follow_removed_points() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(5);
        let pts = patch(&mut rng, 3000);
        let radius = 0.0316f32;
        let mask = CapMask::new(&pts, radius);
        let all: Vec<u32> = (0..pts.len() as u32).collect();
        let grid = Grid::new(&pts);
        let queries: Vec<Vec3> = (0..20_000)
            .map(|_| {
                Vec3::new(
                    rng.random_range(-0.6..0.6),
                    rng.random_range(-0.6..0.6),
                    rng.random_range(-0.1..0.1),
                )
            })
            .collect();
        let mut bound = CapBound::new(&mask, radius);
        for q in &queries {
            match bound.lower_distance(&mask, &grid, &all, *q) {
                None => assert!(brute(&pts, *q).sqrt() > radius, "{q}: far"),
                Some(b) => assert!(b <= brute(&pts, *q).sqrt(), "{q}: {b}"),
            }
        }
        // Remove the points with x < 0, as the search's claim does.
        let kept: Vec<bool> = pts.iter().map(|p| p.x >= 0.0).collect();
        let orig: Vec<u32> = all.iter().copied().filter(|&i| kept[i as usize]).collect();
        let rest: Vec<Vec3> = orig.iter().map(|&i| pts[i as usize]).collect();
        let rest_grid = Grid::new(&rest);
        let stale = bound.clone();
        bound.forget(&kept);
        let cap = |d: f32| (d * d).min(radius * radius);
        let (mut sum_d, mut sum_fresh, mut sum_stale) = (0.0, 0.0, 0.0);
        for q in &queries {
            let left = brute(&rest, *q).sqrt();
            let fresh = bound.lower_distance(&mask, &rest_grid, &orig, *q);
            // The stale bounds are those of the whole cloud: never measured again.
            let old = stale.lower_distance(&mask, &grid, &all, *q);
            if let (Some(b), Some(a)) = (fresh, old) {
                assert!(b <= left, "{q}: {b} / {left}");
                sum_d += cap(left);
                sum_fresh += cap(b);
                sum_stale += cap(a);
            }
        }
        // Capped as the search caps them, the bounds measured again carry most of the
        // squared distances to the remaining points; the stale ones, of the whole
        // cloud, much less (they are low wherever points went).
        assert!(sum_fresh > 0.5 * sum_d, "{sum_fresh} of {sum_d}");
        assert!(
            sum_stale < 0.8 * sum_fresh,
            "{sum_stale} against {sum_fresh}"
        );
    }

    #[test]
    fn an_empty_bound_bounds_nothing() {
        let pts = vec![Vec3::ZERO, Vec3::X * 0.1];
        let mask = CapMask::new(&pts, 0.05);
        let grid = Grid::new(&pts);
        let none = CapBound::default();
        assert_eq!(
            none.lower_distance(&mask, &grid, &[0, 1], Vec3::ZERO),
            Some(0.0)
        );
        assert_eq!(
            none.lower_distance(&mask, &grid, &[0, 1], Vec3::splat(5.0)),
            None
        );
    }
}
