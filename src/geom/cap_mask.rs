//! Cap mask: a bitset over a fine grid that marks the places within a fixed radius of
//! some point of a cloud, so a capped nearest-neighbour query (`Grid::nearest_d2_capped`)
//! from anywhere else can return the cap without a search.
//!
//! Why: the global pose search scores thousands of candidate poses per Gaussian and
//! frame by capped distances, and most probe points of a wrong pose land in empty space,
//! where the grid query still scans the (empty) cells of its cap's box. The mask is exact:
//! a cell is left unmarked only when no point lies within the radius of any place in it,
//! so removing points from the cloud later (the search's `claim`) keeps it valid.
//!
//! Each marked cell also has a slot, its rank among the marked cells (`Place::Near`), so
//! data per marked cell (`cap_bound`'s distances) needs no array over the whole box.

use glam::Vec3;

use super::knn::clamped_cell;

/// Cells per radius along each axis: finer cells mark less empty space near the
/// surface, at the cost of more bits and more marking per point.
const CELLS_PER_RADIUS: f32 = 4.0;

/// At most this many cells (bits); coarser cells beyond that (still exact).
const MAX_CELLS: usize = 1 << 25;

#[derive(Debug, Clone, Default)]
pub struct CapMask {
    min: Vec3,
    cell: f32,
    inv_cell: f32,
    dims: [usize; 3],
    bits: Vec<u64>,
    /// Marked cells before each word of `bits`: a marked cell's slot is its rank
    /// among the marked cells (`Place::Near`), so per-cell data can be kept for the
    /// marked cells alone.
    rank: Vec<u32>,
    /// Number of marked cells.
    marked: usize,
}

/// Where a place lies for a mask (`CapMask::place`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Place {
    /// Certainly farther than the radius from every point.
    Far,
    /// In the marked cell with this slot; `Vec3` is the cell's centre.
    Near(usize, Vec3),
    /// Not known (an empty mask, a non-finite place).
    Unknown,
}

impl CapMask {
    /// Marks every cell that has a place within `radius` of one of `points`. Empty or
    /// non-finite input gives a mask that marks everything (no query skipped).
    pub fn new(points: &[Vec3], radius: f32) -> Self {
        let finite = points.iter().all(|p| p.is_finite());
        if points.is_empty() || !finite || !(radius > 0.0 && radius.is_finite()) {
            return CapMask::default();
        }
        let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
        for p in points {
            lo = lo.min(*p);
            hi = hi.max(*p);
        }
        let ext = hi - lo;
        // A margin for rounding: a place unmarked is farther than `radius` from every
        // point even after the cell arithmetic's f32 error.
        let reach = radius * 1.001 + 1e-6 * (ext.max_element() + radius);
        let min = lo - Vec3::splat(reach);
        let span = ext + Vec3::splat(2.0 * reach);
        let mut cell = radius / CELLS_PER_RADIUS;
        let dims_for = |cell: f32| {
            [
                ((span.x / cell) as usize).saturating_add(1),
                ((span.y / cell) as usize).saturating_add(1),
                ((span.z / cell) as usize).saturating_add(1),
            ]
        };
        // Counted in f64: a cloud far larger than the radius (e.g. millimetre units)
        // would overflow a 32-bit usize (wasm) before the cells are coarsened.
        let count = |d: [usize; 3]| d[0] as f64 * d[1] as f64 * d[2] as f64;
        let mut dims = dims_for(cell);
        while count(dims) > MAX_CELLS as f64 {
            cell *= 1.26;
            dims = dims_for(cell);
        }
        let total = dims[0] * dims[1] * dims[2];
        let mut mask = CapMask {
            min,
            cell,
            inv_cell: 1.0 / cell,
            dims,
            bits: vec![0; total.div_ceil(64)],
            rank: Vec::new(),
            marked: 0,
        };
        let r2 = reach * reach;
        for p in points {
            let a = mask.coords(*p - Vec3::splat(reach));
            let b = mask.coords(*p + Vec3::splat(reach));
            // Squared distance from p to cell i's slab along an axis.
            let gap = |axis: usize, i: usize| {
                let s = min[axis] + i as f32 * cell;
                let d = (s - p[axis]).max(p[axis] - s - cell).max(0.0);
                d * d
            };
            for z in a[2]..=b[2] {
                let gz = gap(2, z);
                for y in a[1]..=b[1] {
                    let gzy = gz + gap(1, y);
                    if gzy > r2 {
                        continue;
                    }
                    // The row's cells within reach: those whose x-slab is within w of
                    // p — one run of bits, set word by word.
                    let w = (r2 - gzy).sqrt();
                    let x0 = mask.coords(Vec3::new(p.x - w, p.y, p.z))[0];
                    let x1 = mask.coords(Vec3::new(p.x + w, p.y, p.z))[0];
                    let row = (z * dims[1] + y) * dims[0];
                    mask.set_run(row + x0, row + x1);
                }
            }
        }
        for word in &mask.bits {
            mask.rank.push(mask.marked as u32);
            mask.marked += word.count_ones() as usize;
        }
        mask
    }

    /// Number of marked cells (slots).
    pub fn slots(&self) -> usize {
        self.marked
    }

    /// The largest absolute coordinate of the mask's box (the scale of its rounding).
    pub fn scale(&self) -> f32 {
        let far = self.min
            + Vec3::new(
                self.dims[0] as f32,
                self.dims[1] as f32,
                self.dims[2] as f32,
            ) * self.cell;
        self.min.abs().max(far.abs()).max_element()
    }

    /// Half the diagonal of a cell: how far a place in a cell can be from its centre.
    pub fn half_diagonal(&self) -> f32 {
        0.5 * 3f32.sqrt() * self.cell
    }

    /// Sets bits `a..=b`.
    fn set_run(&mut self, a: usize, b: usize) {
        let (wa, wb) = (a / 64, b / 64);
        let lo = u64::MAX << (a % 64);
        let hi = u64::MAX >> (63 - b % 64);
        if wa == wb {
            self.bits[wa] |= lo & hi;
        } else {
            self.bits[wa] |= lo;
            for w in &mut self.bits[wa + 1..wb] {
                *w = u64::MAX;
            }
            self.bits[wb] |= hi;
        }
    }

    #[inline]
    fn coords(&self, p: Vec3) -> [usize; 3] {
        clamped_cell(p, self.min, self.inv_cell, self.dims)
    }

    /// Whether `q` is certainly farther than the radius from every point (false when
    /// unsure, e.g. for a mask of nothing or a non-finite query).
    #[inline]
    pub fn far(&self, q: Vec3) -> bool {
        matches!(self.locate(q), Located::Far)
    }

    /// Where `q` lies: beyond the radius, in a marked cell, or not known.
    #[inline]
    pub fn place(&self, q: Vec3) -> Place {
        match self.locate(q) {
            Located::Far => Place::Far,
            Located::Unknown => Place::Unknown,
            Located::Marked([x, y, z], i) => {
                let (w, b) = (i / 64, i % 64);
                let below = self.bits[w] & ((1u64 << b) - 1);
                let slot = self.rank[w] as usize + below.count_ones() as usize;
                let corner = Vec3::new(x as f32, y as f32, z as f32);
                Place::Near(slot, self.min + (corner + 0.5) * self.cell)
            }
        }
    }

    #[inline]
    fn locate(&self, q: Vec3) -> Located {
        if self.bits.is_empty() {
            return Located::Unknown;
        }
        let f = (q - self.min) * self.inv_cell;
        if !f.is_finite() {
            return Located::Unknown;
        }
        if f.cmplt(Vec3::ZERO).any() {
            return Located::Far;
        }
        let (x, y, z) = (f.x as usize, f.y as usize, f.z as usize);
        if x >= self.dims[0] || y >= self.dims[1] || z >= self.dims[2] {
            return Located::Far;
        }
        let i = (z * self.dims[1] + y) * self.dims[0] + x;
        if self.bits[i / 64] & (1 << (i % 64)) == 0 {
            return Located::Far;
        }
        Located::Marked([x, y, z], i)
    }
}

/// `CapMask::locate`'s answer: a marked cell with its coordinates and index.
enum Located {
    Far,
    Unknown,
    Marked([usize; 3], usize),
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::knn::Grid;
    use crate::math::Libm;
    use rand::{Rng, SeedableRng};

    #[test]
    fn far_places_are_farther_than_the_radius_and_near_ones_are_kept() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(3);
        // A curved surface patch, like a frame of a scan.
        let pts: Vec<Vec3> = (0..3000)
            .map(|_| {
                let (u, v): (f32, f32) = (rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0));
                Vec3::new(u, v, 0.3 * (u * 2.0).lsin() * v)
            })
            .collect();
        let grid = Grid::new(&pts);
        for radius in [0.01f32, 0.0316, 0.1] {
            let mask = CapMask::new(&pts, radius);
            let cap2 = radius * radius;
            let (mut skipped, mut near_far) = (0, 0);
            for _ in 0..20_000 {
                let q = Vec3::new(
                    rng.random_range(-1.3..1.3),
                    rng.random_range(-1.3..1.3),
                    rng.random_range(-0.6..0.6),
                );
                let d2 = grid.nearest_d2_capped(q, cap2);
                if mask.far(q) {
                    // Exact: the capped query gives the cap there.
                    assert_eq!(d2, cap2, "radius {radius}, query {q}");
                    skipped += 1;
                } else if d2 == cap2 {
                    near_far += 1;
                }
            }
            // Most places beyond the cap are recognised.
            assert!(
                skipped > 5 * near_far,
                "radius {radius}: {skipped} vs {near_far}"
            );
        }
    }

    #[test]
    fn a_cloud_much_larger_than_the_radius_gets_coarser_cells() {
        // Millimetre-scale input against the pose search's normalised cap.
        let mut rng = rand::rngs::StdRng::seed_from_u64(9);
        let pts: Vec<Vec3> = (0..2000)
            .map(|_| {
                Vec3::new(
                    rng.random_range(-400.0..400.0),
                    rng.random_range(-300.0..300.0),
                    rng.random_range(-5.0..5.0),
                )
            })
            .collect();
        let radius = 0.0316f32;
        let mask = CapMask::new(&pts, radius);
        assert!(mask.bits.len() * 64 <= 2 * MAX_CELLS);
        let grid = Grid::new(&pts);
        for p in pts.iter().take(200) {
            // On a point: never far.
            assert!(!mask.far(*p));
            let q = *p + Vec3::new(0.0, 0.0, 50.0);
            if mask.far(q) {
                assert_eq!(grid.nearest_d2_capped(q, radius * radius), radius * radius);
            }
        }
    }

    #[test]
    fn empty_or_bad_input_skips_nothing() {
        let m = CapMask::new(&[], 0.1);
        assert!(!m.far(Vec3::ZERO));
        let m = CapMask::new(&[Vec3::new(f32::NAN, 0.0, 0.0)], 0.1);
        assert!(!m.far(Vec3::ONE));
        let m = CapMask::new(&[Vec3::ZERO], 0.1);
        assert!(!m.far(Vec3::splat(0.05)));
        assert!(m.far(Vec3::splat(0.2)));
        assert!(!m.far(Vec3::new(f32::NAN, 0.0, 0.0)));
    }
}
