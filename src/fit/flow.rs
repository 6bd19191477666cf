//! Non-learned scene flow (deviation from the paper's pre-trained network, which
//! cannot be shipped): optimal-transport matching of equal-size random subsamples
//! of two consecutive frames (exact linear assignment on squared distances), the
//! flow of every other point taken from its nearest sampled neighbour. Behind the
//! `SceneFlow` trait so a learned estimator can be plugged in.

use glam::{DVec3, Vec3};
use rand::{Rng, SeedableRng};

use super::losses::emd;
use crate::geom::assignment::Lap;
use crate::geom::knn::Grid;

/// Estimates per-point 3D motion of `from` towards `to`.
pub trait SceneFlow: Sync {
    /// One flow vector per point of `from`. `None` if it cannot be estimated.
    fn estimate(&self, from: &[Vec3], to: &[Vec3], seed: u64) -> Option<Vec<Vec3>>;
}

/// Optimal-transport (assignment) flow on `n`-point subsamples.
#[derive(Debug, Clone, Copy)]
pub struct OtFlow {
    pub n: usize,
}

impl Default for OtFlow {
    fn default() -> Self {
        OtFlow { n: 384 }
    }
}

impl SceneFlow for OtFlow {
    fn estimate(&self, from: &[Vec3], to: &[Vec3], seed: u64) -> Option<Vec<Vec3>> {
        let n = self.n.min(from.len()).min(to.len());
        if n == 0 {
            return None;
        }
        let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
        let pick = |len: usize, rng: &mut rand::rngs::StdRng| -> Vec<usize> {
            // Partial Fisher–Yates: n distinct indices.
            let mut idx: Vec<usize> = (0..len).collect();
            for i in 0..n {
                let j = rng.random_range(i..len);
                idx.swap(i, j);
            }
            idx.truncate(n);
            idx
        };
        let ia = pick(from.len(), &mut rng);
        let ib = pick(to.len(), &mut rng);
        let a: Vec<DVec3> = ia.iter().map(|&i| from[i].as_dvec3()).collect();
        let b: Vec<DVec3> = ib.iter().map(|&i| to[i].as_dvec3()).collect();
        let mut sigma = Vec::new();
        if !emd::assign(&a, &b, &mut Lap::default(), &mut Vec::new(), &mut sigma) {
            return None;
        }
        let flows: Vec<Vec3> = (0..n).map(|s| (b[sigma[s]] - a[s]).as_vec3()).collect();
        let sampled: Vec<Vec3> = ia.iter().map(|&i| from[i]).collect();
        let grid = Grid::new(&sampled);
        Some(
            from.iter()
                .map(|p| {
                    grid.nearest(*p)
                        .map(|(j, _)| flows[j as usize])
                        .unwrap_or(Vec3::ZERO)
                })
                .collect(),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recovers_a_translation() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(2);
        let from: Vec<Vec3> = (0..500)
            .map(|_| {
                Vec3::new(
                    rng.random_range(-0.5..0.5),
                    rng.random_range(-0.5..0.5),
                    rng.random_range(-0.5..0.5),
                )
            })
            .collect();
        let shift = Vec3::new(0.05, -0.02, 0.01);
        let to: Vec<Vec3> = from.iter().map(|p| *p + shift).collect();
        let f = OtFlow { n: 500 }.estimate(&from, &to, 1).unwrap();
        let mean = f.iter().fold(Vec3::ZERO, |a, b| a + *b) / f.len() as f32;
        assert!((mean - shift).length() < 5e-3, "{mean:?}");
    }
}
