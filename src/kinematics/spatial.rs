//! Pairwise spatial proximity of segmented parts: L_spatial (minimum squared distance
//! between the points of two parts) and the neighbour relation used by merging.
//!
//! Per frame, pairs closer than a search radius are found exactly with a uniform grid
//! (cell = radius, 27-cell search); pairs farther apart get an upper-bound estimate from
//! a brute-force pass over at most [`FAR_SAMPLE`] points per part (they are far anyway, and
//! their L_spatial only needs to be large). A pair's value is the **median over frames**
//! of the per-frame minimum, so a transient contact in one frame (two legs touching)
//! does not make parts neighbours. Frames where one of the two parts has no points are
//! skipped.
//!
//! Radius: `RADIUS_SPACINGS` × the point spacing (median nearest-neighbour distance of
//! a sample of the canonical frame) — parts joined by a joint touch, so their gap is on
//! the order of the sampling spacing; the radius leaves room for sampling irregularity.

use std::collections::HashMap;

use glam::Vec3;

use crate::geom::knn::point_spacing;

/// Search radius in units of the point spacing.
pub const RADIUS_SPACINGS: f64 = 4.0;
/// Points per part used for the far-pair estimate.
pub const FAR_SAMPLE: usize = 192;

/// Pairwise distances between parts.
#[derive(Debug, Clone)]
pub struct PairDistances {
    pub parts: usize,
    /// `min_sq[i * parts + j]`: median over frames of the per-frame minimum squared
    /// distance between points of parts i and j (∞ if never both present; 0 on the diagonal).
    pub min_sq: Vec<f64>,
    /// Median nearest-neighbour distance of the canonical frame.
    pub spacing: f64,
    /// Neighbour radius (`RADIUS_SPACINGS` × spacing).
    pub radius: f64,
}

impl PairDistances {
    pub fn get(&self, i: usize, j: usize) -> f64 {
        self.min_sq[i * self.parts + j]
    }
    /// Whether parts i ≠ j come within the neighbour radius.
    pub fn neighbours(&self, i: usize, j: usize) -> bool {
        i != j && self.get(i, j) <= self.radius * self.radius
    }
}

fn cell(p: Vec3, inv: f32) -> (i32, i32, i32) {
    (
        (p.x * inv).floor() as i32,
        (p.y * inv).floor() as i32,
        (p.z * inv).floor() as i32,
    )
}

/// Per-frame minimum squared distances between all part pairs (∞ if a part is absent).
fn frame_min_sq(points: &[Vec3], labels: &[u32], parts: usize, radius: f32) -> Vec<f64> {
    let mut out = vec![f64::INFINITY; parts * parts];
    let inv = 1.0 / radius;
    let mut grid: HashMap<(i32, i32, i32), Vec<u32>> = HashMap::new();
    for (n, p) in points.iter().enumerate() {
        grid.entry(cell(*p, inv)).or_default().push(n as u32);
    }
    let r2 = radius * radius;
    for (n, p) in points.iter().enumerate() {
        let a = labels[n] as usize;
        let (cx, cy, cz) = cell(*p, inv);
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    if let Some(list) = grid.get(&(cx + dx, cy + dy, cz + dz)) {
                        for &m in list {
                            let b = labels[m as usize] as usize;
                            if b <= a {
                                continue;
                            }
                            let d = p.distance_squared(points[m as usize]);
                            if d <= r2 && (d as f64) < out[a * parts + b] {
                                out[a * parts + b] = d as f64;
                            }
                        }
                    }
                }
            }
        }
    }
    // Far pairs: estimate from a subsample of each part.
    let mut members: Vec<Vec<Vec3>> = vec![Vec::new(); parts];
    for (p, &l) in points.iter().zip(labels) {
        members[l as usize].push(*p);
    }
    let sample: Vec<Vec<Vec3>> = members
        .iter()
        .map(|m| {
            let step = m.len().div_ceil(FAR_SAMPLE).max(1);
            m.iter().step_by(step).copied().collect()
        })
        .collect();
    for a in 0..parts {
        for b in a + 1..parts {
            if out[a * parts + b].is_finite() || sample[a].is_empty() || sample[b].is_empty() {
                continue;
            }
            let mut best = f32::INFINITY;
            for p in &sample[a] {
                for q in &sample[b] {
                    best = best.min(p.distance_squared(*q));
                }
            }
            out[a * parts + b] = (best as f64).max(r2 as f64);
        }
    }
    for a in 0..parts {
        for b in 0..a {
            out[a * parts + b] = out[b * parts + a];
        }
        out[a * parts + a] = 0.0;
    }
    out
}

/// Pairwise distances over all frames (`labels[k][n] < parts`; the caller validates).
pub fn pair_distances(
    points: &[Vec<Vec3>],
    labels: &[Vec<u32>],
    parts: usize,
    canonical: usize,
) -> PairDistances {
    let spacing = point_spacing(&points[canonical]).max(1e-6);
    let radius = RADIUS_SPACINGS * spacing;
    let per_frame: Vec<Vec<f64>> = points
        .iter()
        .zip(labels)
        .map(|(p, l)| frame_min_sq(p, l, parts, radius as f32))
        .collect();
    let mut min_sq = vec![f64::INFINITY; parts * parts];
    let mut vals = Vec::with_capacity(points.len());
    for i in 0..parts * parts {
        vals.clear();
        vals.extend(per_frame.iter().map(|f| f[i]).filter(|v| v.is_finite()));
        if vals.is_empty() {
            continue;
        }
        vals.sort_by(|a, b| a.total_cmp(b));
        // Lower median: with an even count the closer of the two middle frames.
        min_sq[i] = vals[(vals.len() - 1) / 2];
    }
    PairDistances {
        parts,
        min_sq,
        spacing,
        radius,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grid_matches_brute_force_and_far_pairs_are_far() {
        // Three clusters on a line: 0 and 1 touch (gap 0.01), 2 is far.
        let mut pts = Vec::new();
        let mut lab = Vec::new();
        for i in 0..50 {
            let x = i as f32 * 0.01;
            pts.push(Vec3::new(x, 0.0, 0.0));
            lab.push(0);
            pts.push(Vec3::new(x + 0.51, 0.0, 0.0));
            lab.push(1);
            pts.push(Vec3::new(x + 2.0, 0.0, 0.0));
            lab.push(2);
        }
        let d = pair_distances(&[pts], &[lab], 3, 0);
        assert!((d.spacing - 0.01).abs() < 1e-4);
        assert!((d.get(0, 1) - 0.0004f64).abs() < 1e-6); // gap 0.02 (0.49 → 0.51)
        assert!(d.neighbours(0, 1));
        assert!(!d.neighbours(1, 2));
        assert!(d.get(1, 2) >= 1.0 && d.get(1, 2) < 1.1);
        assert_eq!(d.get(1, 2), d.get(2, 1));
    }
}
