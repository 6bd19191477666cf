//! Smooth random joint trajectories: a few random knots per joint, spread evenly over
//! the sequence, joined by cosine interpolation. Between two knots the curve is
//! monotone, so it never leaves the joint's range; every joint is made to move over a
//! visible part of its range.

use crate::math::Libm;
use rand::Rng;

/// Share of a joint's range that its trajectory must cover over the sequence.
const MIN_COVERAGE: f64 = 0.35;

/// States of one joint for `frames` frames, within `range`.
pub fn smooth_states(rng: &mut impl Rng, frames: usize, range: (f64, f64)) -> Vec<f64> {
    let (lo, hi) = range;
    if frames == 0 {
        return Vec::new();
    }
    if frames == 1 {
        return vec![lo + (hi - lo) * rng.random::<f64>()];
    }
    // 2 knots for very short sequences, up to 4 (3 segments) for long ones.
    let knots = (frames / 3 + 1).clamp(2, 4);
    let mut values = vec![0.0; knots];
    // Resampling is bounded; the last draw is used as is (still smooth and in range).
    for _ in 0..32 {
        for v in values.iter_mut() {
            *v = lo + (hi - lo) * rng.random::<f64>();
        }
        let (mn, mx) = values
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
                (a.min(v), b.max(v))
            });
        if mx - mn >= MIN_COVERAGE * (hi - lo) {
            break;
        }
    }
    let span = (frames - 1) as f64;
    let seg = span / (knots - 1) as f64;
    (0..frames)
        .map(|t| {
            let x = t as f64 / seg;
            let i = (x.floor() as usize).min(knots - 2);
            let f = (x - i as f64).clamp(0.0, 1.0);
            let w = 0.5 - 0.5 * (std::f64::consts::PI * f).lcos();
            (values[i] * (1.0 - w) + values[i + 1] * w).clamp(lo, hi)
        })
        .collect()
}

/// A uniformly random state within `range` (held-out poses).
pub fn random_state(rng: &mut impl Rng, range: (f64, f64)) -> f64 {
    range.0 + (range.1 - range.0) * rng.random::<f64>()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{rngs::StdRng, SeedableRng};

    #[test]
    fn stays_in_range_moves_and_is_smooth() {
        let mut rng = StdRng::seed_from_u64(7);
        for frames in [2, 4, 10, 30] {
            for _ in 0..50 {
                let s = smooth_states(&mut rng, frames, (-1.0, 2.0));
                assert_eq!(s.len(), frames);
                assert!(s.iter().all(|&v| (-1.0..=2.0).contains(&v)));
                let mx = s.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
                let mn = s.iter().cloned().fold(f64::INFINITY, f64::min);
                assert!(mx - mn >= MIN_COVERAGE * 3.0 - 1e-9, "{s:?}");
                if frames >= 10 {
                    // knots are >= 3 frames apart: one step swings at most half the range
                    for w in s.windows(2) {
                        assert!((w[1] - w[0]).abs() <= 0.5 * 3.0 + 1e-9, "{s:?}");
                    }
                }
            }
        }
    }

    #[test]
    fn seeded() {
        let a = smooth_states(&mut StdRng::seed_from_u64(3), 10, (0.0, 1.0));
        let b = smooth_states(&mut StdRng::seed_from_u64(3), 10, (0.0, 1.0));
        let c = smooth_states(&mut StdRng::seed_from_u64(4), 10, (0.0, 1.0));
        assert_eq!(a, b);
        assert_ne!(a, c);
    }
}
