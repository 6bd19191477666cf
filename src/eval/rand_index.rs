//! Rand index between two labellings of the same points, from the contingency table
//! (no N² pair matrix): with n_ij the points labelled i by one and j by the other,
//! a_i, b_j the marginals and C(x) = x(x−1)/2,
//! `RI = 1 + (2 Σ C(n_ij) − Σ C(a_i) − Σ C(b_j)) / C(n)`.

use crate::{Error, Result};

fn pairs(x: u64) -> u64 {
    x * x.saturating_sub(1) / 2
}

/// Σ C(run length) over runs of equal values of `key(x)` in a slice sorted by `key`.
fn run_pairs(sorted: &[u64], key: impl Fn(u64) -> u64) -> u64 {
    let mut total = 0;
    let mut i = 0;
    while i < sorted.len() {
        let k = key(sorted[i]);
        let mut j = i + 1;
        while j < sorted.len() && key(sorted[j]) == k {
            j += 1;
        }
        total += pairs((j - i) as u64);
        i = j;
    }
    total
}

/// Standard (unadjusted) Rand index of `pred` against `gt` (same length). Fewer than
/// two points: 1 (no pair disagrees).
pub fn rand_index(pred: &[u32], gt: &[u32]) -> Result<f64> {
    if pred.len() != gt.len() {
        return Err(Error::InvalidArgument(format!(
            "Rand index: {} predicted labels for {} ground-truth labels",
            pred.len(),
            gt.len()
        )));
    }
    let n = pred.len() as u64;
    if n < 2 {
        return Ok(1.0);
    }
    // One buffer, sorted twice: (pred, gt) gives n_ij and a_i, (gt, pred) gives b_j.
    let mut keys: Vec<u64> = pred
        .iter()
        .zip(gt)
        .map(|(&a, &b)| ((a as u64) << 32) | b as u64)
        .collect();
    keys.sort_unstable();
    let nij = run_pairs(&keys, |k| k);
    let ai = run_pairs(&keys, |k| k >> 32);
    for k in keys.iter_mut() {
        *k = k.rotate_left(32);
    }
    keys.sort_unstable();
    let bj = run_pairs(&keys, |k| k >> 32);
    let total = pairs(n) as f64;
    Ok(1.0 + (2.0 * nij as f64 - ai as f64 - bj as f64) / total)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Direct O(N²) definition, for checking.
    fn brute(a: &[u32], b: &[u32]) -> f64 {
        let n = a.len();
        let mut agree = 0usize;
        let mut total = 0usize;
        for i in 0..n {
            for j in i + 1..n {
                total += 1;
                if (a[i] == a[j]) == (b[i] == b[j]) {
                    agree += 1;
                }
            }
        }
        agree as f64 / total as f64
    }

    #[test]
    fn hand_checked_cases() {
        // Identical up to renaming: 1.
        assert_eq!(rand_index(&[0, 0, 1, 1], &[5, 5, 2, 2]).unwrap(), 1.0);
        // All in one cluster vs all separate: every pair disagrees.
        assert_eq!(rand_index(&[0, 0, 0], &[0, 1, 2]).unwrap(), 0.0);
        // [0,0,1,1] vs [0,1,1,1]: pairs (01 02 03 12 13 23):
        // same-in-a: T F F F F T ; same-in-b: F F F T T T -> agree on 02,03,23 = 3/6.
        assert!((rand_index(&[0, 0, 1, 1], &[0, 1, 1, 1]).unwrap() - 0.5).abs() < 1e-15);
        assert_eq!(rand_index(&[3], &[7]).unwrap(), 1.0);
        assert!(rand_index(&[0, 1], &[0]).is_err());
    }

    #[test]
    fn matches_pairwise_definition() {
        let mut s = 12345u64;
        let mut next = |m: u32| {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((s >> 33) as u32) % m
        };
        for _ in 0..20 {
            let n = 50 + next(100) as usize;
            let a: Vec<u32> = (0..n).map(|_| next(5)).collect();
            let b: Vec<u32> = (0..n).map(|_| next(7) * 1000).collect();
            let fast = rand_index(&a, &b).unwrap();
            assert!((fast - brute(&a, &b)).abs() < 1e-12);
        }
    }
}
