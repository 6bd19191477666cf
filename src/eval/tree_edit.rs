//! Tree edit distance between kinematic trees, as Reart computes it: node labels are
//! ignored (relabel cost 0), inserting or deleting a node costs 1, and the trees are
//! unordered — the distance is the minimum, over every ordering of the children of
//! every node of *both* trees, of the ordered Zhang–Shasha edit distance.
//!
//! What is implemented, exactly: each tree's distinct ordered shapes are enumerated
//! (children permuted, orderings that give the same ordered shape counted once, since
//! labels are ignored), then Zhang–Shasha runs on every pair of shapes, stopping early
//! when the lower bound |n₁ − n₂| is reached. Kinematic trees (≤ ~20 parts, few
//! distinct sibling shapes) have a handful of shapes; trees with too many orderings are
//! refused with an error rather than answered approximately.

use std::collections::BTreeSet;

use crate::kinematics::chain::Chain;
use crate::{Error, Result};

/// Most distinct ordered shapes enumerated per tree.
const MAX_SHAPES: usize = 20_000;
/// Most (shape, shape) pairs evaluated with Zhang–Shasha.
const MAX_PAIRS: usize = 2_000_000;

/// Unordered, unlabelled tree edit distance (unit insert/delete) between the trees
/// given by parent arrays (−1 for the root).
pub fn tree_edit_distance(parent_a: &[i64], parent_b: &[i64]) -> Result<usize> {
    let sa = ordered_shapes(parent_a)?;
    let sb = ordered_shapes(parent_b)?;
    if sa.len().saturating_mul(sb.len()) > MAX_PAIRS {
        return Err(Error::InvalidArgument(format!(
            "tree edit distance: {} × {} child orderings is too many to compare exactly",
            sa.len(),
            sb.len()
        )));
    }
    let lower = parent_a.len().abs_diff(parent_b.len());
    let pa: Vec<Postorder> = sa.iter().map(|s| Postorder::parse(s)).collect();
    let pb: Vec<Postorder> = sb.iter().map(|s| Postorder::parse(s)).collect();
    let mut zs = ZhangShasha::default();
    let mut best = usize::MAX;
    for a in &pa {
        for b in &pb {
            best = best.min(zs.distance(a, b));
            if best == lower {
                return Ok(best);
            }
        }
    }
    Ok(best)
}

/// Every distinct ordered shape of the tree, as balanced parentheses (a node is `(`,
/// its children's shapes in order, `)`).
fn ordered_shapes(parent: &[i64]) -> Result<Vec<Vec<u8>>> {
    // Validates: one root, parents in range, no cycle.
    let chain = Chain::new(parent.to_vec(), vec![None; parent.len()])?;
    let n = parent.len();
    let mut children: Vec<Vec<usize>> = vec![Vec::new(); n];
    for &p in chain.order().iter().skip(1) {
        children[parent[p] as usize].push(p);
    }
    // Bottom-up: shapes[v] (sorted, distinct) and canon[v] = the unordered canonical
    // code (children's codes sorted), which groups interchangeable children.
    let mut shapes: Vec<Vec<Vec<u8>>> = vec![Vec::new(); n];
    let mut canon: Vec<Vec<u8>> = vec![Vec::new(); n];
    for &v in chain.order().iter().rev() {
        let mut kids = children[v].clone();
        kids.sort_by(|&a, &b| canon[a].cmp(&canon[b]));
        let mut code = vec![b'('];
        for &k in &kids {
            code.extend_from_slice(&canon[k]);
        }
        code.push(b')');
        canon[v] = code;

        // Estimate before enumerating: distinct class permutations × shape choices.
        let mut estimate: f64 = 1.0;
        for (i, &k) in kids.iter().enumerate() {
            estimate *= (i + 1) as f64 * shapes[k].len() as f64;
        }
        if estimate > (MAX_SHAPES as f64) * 50.0 {
            return Err(Error::InvalidArgument(format!(
                "tree edit distance: the tree has too many child orderings (part {v})"
            )));
        }
        let mut set: BTreeSet<Vec<u8>> = BTreeSet::new();
        // Class index per child position; next_permutation enumerates the distinct
        // arrangements of the multiset of classes.
        let mut classes: Vec<usize> = Vec::with_capacity(kids.len());
        let mut reps: Vec<usize> = Vec::new();
        for &k in &kids {
            if reps.last().is_none_or(|&r| canon[r] != canon[k]) {
                reps.push(k);
            }
            classes.push(reps.len() - 1);
        }
        loop {
            // Cartesian product of shape choices along this arrangement.
            let mut choice = vec![0usize; classes.len()];
            loop {
                let mut s = vec![b'('];
                for (pos, &cl) in classes.iter().enumerate() {
                    s.extend_from_slice(&shapes[reps[cl]][choice[pos]]);
                }
                s.push(b')');
                set.insert(s);
                if set.len() > MAX_SHAPES {
                    return Err(Error::InvalidArgument(
                        "tree edit distance: the tree has too many child orderings".into(),
                    ));
                }
                // Odometer over choices.
                let mut pos = 0;
                while pos < choice.len() {
                    choice[pos] += 1;
                    if choice[pos] < shapes[reps[classes[pos]]].len() {
                        break;
                    }
                    choice[pos] = 0;
                    pos += 1;
                }
                if pos == choice.len() {
                    break;
                }
            }
            if !next_permutation(&mut classes) {
                break;
            }
        }
        shapes[v] = set.into_iter().collect();
    }
    Ok(std::mem::take(&mut shapes[chain.root()]))
}

/// Lexicographic next permutation (distinct arrangements of a multiset).
fn next_permutation(a: &mut [usize]) -> bool {
    if a.len() < 2 {
        return false;
    }
    let mut i = a.len() - 1;
    while i > 0 && a[i - 1] >= a[i] {
        i -= 1;
    }
    if i == 0 {
        return false;
    }
    let mut j = a.len() - 1;
    while a[j] <= a[i - 1] {
        j -= 1;
    }
    a.swap(i - 1, j);
    a[i..].reverse();
    true
}

/// An ordered tree in postorder: `lml[i]` = leftmost leaf descendant of node i,
/// `keyroots` ascending.
struct Postorder {
    lml: Vec<usize>,
    keyroots: Vec<usize>,
}

impl Postorder {
    fn parse(shape: &[u8]) -> Postorder {
        let mut lml = Vec::with_capacity(shape.len() / 2);
        let mut stack = Vec::new();
        for &ch in shape {
            if ch == b'(' {
                // A node's leftmost leaf gets the next postorder index.
                stack.push(lml.len());
            } else if let Some(first) = stack.pop() {
                lml.push(first);
            }
        }
        let n = lml.len();
        let mut seen = vec![false; n];
        let mut keyroots = Vec::new();
        for i in (0..n).rev() {
            if !seen[lml[i]] {
                seen[lml[i]] = true;
                keyroots.push(i);
            }
        }
        keyroots.reverse();
        Postorder { lml, keyroots }
    }
}

/// Zhang–Shasha with unit insert/delete and free relabelling; scratch buffers reused.
#[derive(Default)]
struct ZhangShasha {
    td: Vec<usize>,
    fd: Vec<usize>,
}

impl ZhangShasha {
    fn distance(&mut self, a: &Postorder, b: &Postorder) -> usize {
        let (n1, n2) = (a.lml.len(), b.lml.len());
        self.td.clear();
        self.td.resize(n1 * n2, 0);
        let w = n2 + 1;
        self.fd.clear();
        self.fd.resize((n1 + 1) * w, 0);
        for &i in &a.keyroots {
            for &j in &b.keyroots {
                let (li, lj) = (a.lml[i], b.lml[j]);
                // fd indices are offset by one: row r ↔ forest a[li..li+r).
                let rows = i - li + 1;
                let cols = j - lj + 1;
                for r in 0..=rows {
                    self.fd[r * w] = r;
                }
                for c in 0..=cols {
                    self.fd[c] = c;
                }
                for r in 1..=rows {
                    let x = li + r - 1;
                    for c in 1..=cols {
                        let y = lj + c - 1;
                        let del = self.fd[(r - 1) * w + c] + 1;
                        let ins = self.fd[r * w + c - 1] + 1;
                        let v = if a.lml[x] == li && b.lml[y] == lj {
                            let v = del.min(ins).min(self.fd[(r - 1) * w + c - 1]);
                            self.td[x * n2 + y] = v;
                            v
                        } else {
                            let (pr, pc) = (a.lml[x] - li, b.lml[y] - lj);
                            del.min(ins).min(self.fd[pr * w + pc] + self.td[x * n2 + y])
                        };
                        self.fd[r * w + c] = v;
                    }
                }
            }
        }
        self.td[(n1 - 1) * n2 + n2 - 1]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ted(a: &[i64], b: &[i64]) -> usize {
        let d = tree_edit_distance(a, b).unwrap();
        assert_eq!(d, tree_edit_distance(b, a).unwrap(), "not symmetric");
        d
    }

    #[test]
    fn hand_checked_pairs() {
        let chain3 = [-1, 0, 1];
        let star3 = [-1, 0, 0];
        assert_eq!(ted(&chain3, &chain3), 0);
        assert_eq!(ted(&[-1], &[-1]), 0);
        // Chain of 3 vs root with 2 children: delete one node and insert one.
        assert_eq!(ted(&chain3, &star3), 2);
        // Adding a leaf.
        assert_eq!(ted(&chain3, &[-1, 0, 1, 2]), 1);
        assert_eq!(ted(&star3, &[-1, 0, 0, 0]), 1);
        // Same tree with parts numbered differently and children in another order.
        assert_eq!(ted(&[-1, 0, 1, 0], &[-1, 0, 0, 2]), 0);
        // r(A(a1,a2), b) vs r(x,y,z): delete A (a1, a2 become children of r).
        assert_eq!(ted(&[-1, 0, 1, 1, 0], &[-1, 0, 0, 0]), 1);
        // r(b, A(a1,a2)) too: the orderings are free.
        assert_eq!(ted(&[-1, 0, 0, 2, 2], &[-1, 0, 0, 0]), 1);
        // Single node vs chain of 4: insert 3.
        assert_eq!(ted(&[-1], &[-1, 0, 1, 2]), 3);
        // Quadruped (body + 4 legs of 3) vs the same with one leg a part short.
        let quad: Vec<i64> = vec![-1, 0, 1, 2, 0, 4, 5, 0, 7, 8, 0, 10, 11];
        let short: Vec<i64> = vec![-1, 0, 1, 0, 3, 4, 0, 6, 7, 0, 9, 10];
        assert_eq!(ted(&quad, &quad), 0);
        assert_eq!(ted(&quad, &short), 1);
        // Quadruped vs chain of 13: the best mapping keeps root + one leg (4 nodes)
        // and one more leg hanging below... only a chain maps into a chain: 13 − 4 = 9
        // deletions of leg parts, then 9 insertions to reach 13 nodes.
        let chain13: Vec<i64> = (0..13).map(|i| i as i64 - 1).collect();
        assert_eq!(ted(&quad, &chain13), 2 * 9);
    }

    #[test]
    fn ordered_zhang_shasha_known_values() {
        let mut zs = ZhangShasha::default();
        let p = |s: &str| Postorder::parse(s.as_bytes());
        assert_eq!(zs.distance(&p("(()())"), &p("(()())")), 0);
        assert_eq!(zs.distance(&p("((()))"), &p("(()())")), 2);
        // Ordered: r(A(a,b), c) vs r(c, A(a,b)) costs, unlike unordered (0).
        assert!(zs.distance(&p("((()())())"), &p("(()(()()))")) > 0);
        assert_eq!(zs.distance(&p("()"), &p("((()))")), 2);
    }

    #[test]
    fn rejects_invalid_trees() {
        assert!(tree_edit_distance(&[-1, 2, 1], &[-1]).is_err());
        assert!(tree_edit_distance(&[], &[-1]).is_err());
        assert!(tree_edit_distance(&[-1, -1], &[-1]).is_err());
    }

    #[test]
    fn star_of_many_distinct_children_is_refused_not_approximated() {
        // Root with 10 children chains of lengths 1..=10: 10! orderings.
        let mut parent = vec![-1i64];
        for len in 1..=10 {
            let mut prev = 0i64;
            for _ in 0..len {
                parent.push(prev);
                prev = parent.len() as i64 - 1;
            }
        }
        assert!(tree_edit_distance(&parent, &[-1]).is_err());
    }
}
