//! Linear assignment (the paper's bipartite matching for the EMD loss): the
//! shortest-augmenting-path algorithm of Jonker–Volgenant in Crouse's rectangular
//! form (the one scipy's `linear_sum_assignment` uses). Dense, O(n_rows² n_cols)
//! worst case; the fit calls it on subsamples of a few hundred points.

/// Reusable workspace so repeated solves do not allocate.
#[derive(Debug, Default, Clone)]
pub struct Lap {
    u: Vec<f64>,
    v: Vec<f64>,
    shortest: Vec<f64>,
    path: Vec<usize>,
    row4col: Vec<usize>,
    col4row: Vec<usize>,
    remaining: Vec<usize>,
    sr: Vec<bool>,
    sc: Vec<bool>,
}

const NONE: usize = usize::MAX;

impl Lap {
    /// Solves min Σ cost[i][col(i)] over injective row→column maps for a row-major
    /// `rows × cols` cost matrix with `rows ≤ cols`. Returns the column of each row
    /// in `out`. Returns false if the problem is infeasible (non-finite costs).
    pub fn solve(&mut self, cost: &[f64], rows: usize, cols: usize, out: &mut Vec<usize>) -> bool {
        out.clear();
        if rows == 0 {
            return true;
        }
        if rows > cols || cost.len() != rows * cols {
            return false;
        }
        self.u.clear();
        self.u.resize(rows, 0.0);
        self.v.clear();
        self.v.resize(cols, 0.0);
        self.shortest.resize(cols, 0.0);
        self.path.clear();
        self.path.resize(cols, NONE);
        self.row4col.clear();
        self.row4col.resize(cols, NONE);
        self.col4row.clear();
        self.col4row.resize(rows, NONE);
        self.sr.resize(rows, false);
        self.sc.resize(cols, false);
        if rows == cols {
            self.column_reduction(cost, cols);
        }
        for cur in 0..rows {
            if self.col4row[cur] != NONE {
                continue;
            }
            let Some((sink, minval)) = self.augment(cost, rows, cols, cur) else {
                return false;
            };
            self.u[cur] += minval;
            for i in 0..rows {
                if self.sr[i] && i != cur {
                    self.u[i] += minval - self.shortest[self.col4row[i]];
                }
            }
            for j in 0..cols {
                if self.sc[j] {
                    self.v[j] -= minval - self.shortest[j];
                }
            }
            let mut j = sink;
            loop {
                let i = self.path[j];
                self.row4col[j] = i;
                std::mem::swap(&mut self.col4row[i], &mut j);
                if i == cur {
                    break;
                }
            }
        }
        out.extend_from_slice(&self.col4row);
        true
    }

    /// Jonker–Volgenant's column reduction (square problems): v_j = min_i c_ij, and
    /// each column's cheapest row takes it if still free. The duals stay feasible
    /// and these pairs tight, so the augmentations that follow (only for the rows
    /// left free) end at the same optimum; about half the rows need none. Skipped
    /// when a cost is not finite (`augment` then reports the problem). Not for
    /// rectangular problems: there unmatched columns need v_j ≤ 0.
    fn column_reduction(&mut self, cost: &[f64], n: usize) {
        self.shortest[..n]
            .iter_mut()
            .for_each(|x| *x = f64::INFINITY);
        // Row-major scan: shortest = column minima, path = their rows.
        for i in 0..n {
            let row = &cost[i * n..(i + 1) * n];
            for (j, &c) in row.iter().enumerate() {
                if !c.is_finite() {
                    return;
                }
                if c < self.shortest[j] {
                    self.shortest[j] = c;
                    self.path[j] = i;
                }
            }
        }
        for j in 0..n {
            self.v[j] = self.shortest[j];
            let i = self.path[j];
            if self.col4row[i] == NONE {
                self.col4row[i] = j;
                self.row4col[j] = i;
            }
        }
    }

    fn augment(
        &mut self,
        cost: &[f64],
        rows: usize,
        cols: usize,
        start: usize,
    ) -> Option<(usize, f64)> {
        let mut minval = 0.0;
        self.remaining.clear();
        self.remaining.extend((0..cols).rev());
        self.sr[..rows].iter_mut().for_each(|x| *x = false);
        self.sc[..cols].iter_mut().for_each(|x| *x = false);
        self.shortest[..cols]
            .iter_mut()
            .for_each(|x| *x = f64::INFINITY);
        let mut i = start;
        loop {
            let mut index = NONE;
            let mut lowest = f64::INFINITY;
            self.sr[i] = true;
            let row = &cost[i * cols..(i + 1) * cols];
            let ui = self.u[i];
            for (it, &j) in self.remaining.iter().enumerate() {
                let r = minval + row[j] - ui - self.v[j];
                if r < self.shortest[j] {
                    self.path[j] = i;
                    self.shortest[j] = r;
                }
                let s = self.shortest[j];
                if s < lowest || (s == lowest && self.row4col[j] == NONE) {
                    lowest = s;
                    index = it;
                }
            }
            minval = lowest;
            if !minval.is_finite() || index == NONE {
                return None;
            }
            let j = self.remaining[index];
            self.sc[j] = true;
            self.remaining.swap_remove(index);
            if self.row4col[j] == NONE {
                return Some((j, minval));
            }
            i = self.row4col[j];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    fn brute(cost: &[f64], rows: usize, cols: usize) -> f64 {
        // All injective maps by recursion (small sizes only).
        fn rec(cost: &[f64], rows: usize, cols: usize, r: usize, used: &mut Vec<bool>) -> f64 {
            if r == rows {
                return 0.0;
            }
            let mut best = f64::INFINITY;
            for c in 0..cols {
                if !used[c] {
                    used[c] = true;
                    best = best.min(cost[r * cols + c] + rec(cost, rows, cols, r + 1, used));
                    used[c] = false;
                }
            }
            best
        }
        rec(cost, rows, cols, 0, &mut vec![false; cols])
    }

    #[test]
    fn optimal_on_random_square_and_rectangular() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(1);
        let mut lap = Lap::default();
        let mut out = Vec::new();
        for &(r, c) in &[(1, 1), (3, 3), (5, 5), (6, 6), (3, 6), (4, 7), (7, 7)] {
            for _ in 0..20 {
                let cost: Vec<f64> = (0..r * c).map(|_| rng.random_range(0.0..10.0)).collect();
                assert!(lap.solve(&cost, r, c, &mut out));
                let mut seen = vec![false; c];
                let mut total = 0.0;
                for (i, &j) in out.iter().enumerate() {
                    assert!(!seen[j]);
                    seen[j] = true;
                    total += cost[i * c + j];
                }
                assert!((total - brute(&cost, r, c)).abs() < 1e-9);
            }
        }
    }

    #[test]
    fn column_reduction_reaches_the_plain_optimum() {
        // Square point-matching problems (the EMD's shape) solved with the column
        // reduction, against the same costs plus one prohibitive column (rectangular,
        // so solved by augmentations alone): the same assignment.
        let mut rng = rand::rngs::StdRng::seed_from_u64(9);
        let mut lap = Lap::default();
        let (mut a, mut b) = (Vec::new(), Vec::new());
        for n in [2usize, 17, 64, 200] {
            let pts = |rng: &mut rand::rngs::StdRng| -> Vec<[f64; 3]> {
                (0..n)
                    .map(|_| {
                        [
                            rng.random_range(-1.0..1.0),
                            rng.random_range(-1.0..1.0),
                            rng.random_range(-1.0..1.0),
                        ]
                    })
                    .collect()
            };
            let (x, y) = (pts(&mut rng), pts(&mut rng));
            let d2 =
                |p: &[f64; 3], q: &[f64; 3]| (0..3).map(|k| (p[k] - q[k]).powi(2)).sum::<f64>();
            let square: Vec<f64> = x
                .iter()
                .flat_map(|p| y.iter().map(move |q| d2(p, q)))
                .collect();
            let wide: Vec<f64> = x
                .iter()
                .flat_map(|p| y.iter().map(move |q| d2(p, q)).chain([1e9]))
                .collect();
            assert!(lap.solve(&square, n, n, &mut a));
            assert!(lap.solve(&wide, n, n + 1, &mut b));
            assert_eq!(a, b, "n = {n}");
        }
        // Many ties (small integer costs): several optima, the same optimal total.
        for n in [5usize, 30, 90] {
            let square: Vec<f64> = (0..n * n).map(|_| rng.random_range(0..4) as f64).collect();
            let wide: Vec<f64> = (0..n)
                .flat_map(|i| square[i * n..(i + 1) * n].iter().copied().chain([1e9]))
                .collect();
            assert!(lap.solve(&square, n, n, &mut a));
            assert!(lap.solve(&wide, n, n + 1, &mut b));
            let total = |c: &[f64], w: usize, x: &[usize]| -> f64 {
                x.iter().enumerate().map(|(i, &j)| c[i * w + j]).sum()
            };
            let mut seen = vec![false; n];
            a.iter().for_each(|&j| seen[j] = true);
            assert!(seen.iter().all(|s| *s), "a permutation");
            assert_eq!(total(&square, n, &a), total(&wide, n + 1, &b), "n = {n}");
        }
    }

    #[test]
    fn rejects_bad_shapes_and_nan() {
        let mut lap = Lap::default();
        let mut out = Vec::new();
        assert!(!lap.solve(&[1.0, 2.0], 2, 1, &mut out));
        assert!(!lap.solve(
            &[f64::NAN, f64::INFINITY, f64::INFINITY, f64::INFINITY],
            2,
            2,
            &mut out
        ));
    }
}
