//! Merging over-segmented parts (paper supplement, "Part merging").
//!
//! The paper uses Oᵢᵏ = Tᵢᵏ⁺¹ (Tᵢᵏ)⁻¹, the world motion of part i between consecutive
//! frames, and L_merge(i,j) = Σₖ ‖(Oᵢᵏ)⁻¹ Oⱼᵏ − I‖²_F. **Deviation:** we use the motion
//! between *every* pair of frames, Oᵢ^{kl} = Tᵢˡ (Tᵢᵏ)⁻¹, and
//! L_merge(i,j) = (1/K) Σₖ Σₗ ‖(Oᵢ^{kl})⁻¹ Oⱼ^{kl} − I‖²_F. For a static pair both are 0 and
//! pose noise of variance σ² contributes about 2σ²K to both, but a slow joint whose
//! consecutive steps are small (bench-dev panda_gripper: fingers sliding 0.11 object
//! sizes over 10 frames) scores 0.009 with consecutive steps — below 3e-2, so it would be
//! merged away — and 0.041 with all frame pairs; every other bench-dev joint scores
//! ≥ 1.1. It is also independent of the frame order.
//! Neighbouring parts (see [`super::spatial`]: points within the
//! neighbour radius, median over frames) are merged greedily, lowest L_merge first,
//! while it is below the threshold (3e-2, translations in normalised object units as in
//! the paper), recomputing after each merge.
//!
//! A merged part's pose is the pose of its member with the most points: the members
//! move together by construction, and the largest member's pose was fitted to the most
//! data (a Kabsch re-fit would need point correspondences across frames, which
//! independently sampled frames do not have).
//!
//! Afterwards, tiny parts (fewer than `min_fraction` of all points, or fewer than
//! `min_points`) are reassigned to the neighbouring part whose motion explains them best
//! (lowest L_merge); a tiny part without a non-tiny neighbour goes to the nearest one.

use glam::DMat4;

use super::screw::dev_from_identity;
use super::spatial::PairDistances;
use crate::geom::se3::rigid_inverse;

/// Options of the merging step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MergeOptions {
    /// L_merge threshold (paper: 3e-2).
    pub threshold: f64,
    /// Parts with fewer than this fraction of all points are reassigned.
    pub min_fraction: f64,
    /// Parts with fewer points than this (over all frames) are reassigned.
    pub min_points: usize,
}

impl Default for MergeOptions {
    fn default() -> Self {
        MergeOptions {
            threshold: 3e-2,
            min_fraction: 0.005,
            min_points: 12,
        }
    }
}

/// What happened to a part.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct MergeEvent {
    /// `merge` (static pair), `reassign` (tiny part), `still` (a joint that does not
    /// move) or `invisible` (a joint the clouds do not show, `invisible_joints`).
    pub kind: &'static str,
    /// Input parts of the group that was absorbed, and of the group it joined.
    pub from: Vec<usize>,
    pub into: Vec<usize>,
    /// L_merge between the two groups (∞ if there was no motion to compare).
    pub loss: f64,
}

/// Result of merging.
#[derive(Debug, Clone)]
pub struct MergeOutcome {
    /// Input part → merged part.
    pub map: Vec<u32>,
    /// Number of merged parts.
    pub parts: usize,
    /// Members (input parts) of each merged part.
    pub members: Vec<Vec<usize>>,
    /// `poses[k][p]` of the merged parts.
    pub poses: Vec<Vec<DMat4>>,
    pub log: Vec<MergeEvent>,
}

/// L_merge between two parts given their per-frame poses `poses[k][.]` (all frame
/// pairs, see the module doc).
pub fn merge_loss(poses: &[Vec<DMat4>], i: usize, j: usize) -> f64 {
    let k = poses.len();
    if k == 0 {
        return 0.0;
    }
    let mut s = 0.0;
    for a in poses {
        let (ii, ij) = (rigid_inverse(&a[i]), rigid_inverse(&a[j]));
        for b in poses {
            let oi = b[i] * ii;
            let oj = b[j] * ij;
            s += dev_from_identity(&(rigid_inverse(&oi) * oj));
        }
    }
    s / k as f64
}

/// The paper's literal L_merge with consecutive motions, Σₖ ‖(Oᵢᵏ)⁻¹ Oⱼᵏ − I‖²_F (for
/// comparison; see the module doc for why [`merge_loss`] is used).
pub fn merge_loss_consecutive(poses: &[Vec<DMat4>], i: usize, j: usize) -> f64 {
    poses
        .windows(2)
        .map(|w| {
            let oi = w[1][i] * rigid_inverse(&w[0][i]);
            let oj = w[1][j] * rigid_inverse(&w[0][j]);
            dev_from_identity(&(rigid_inverse(&oi) * oj))
        })
        .sum()
}

/// Merge static neighbouring parts, then reassign tiny parts.
/// `counts[p]`: points labelled p over all frames.
pub fn merge_parts(
    poses: &[Vec<DMat4>],
    counts: &[usize],
    dist: &PairDistances,
    opts: &MergeOptions,
) -> MergeOutcome {
    let n = counts.len();
    let mut members: Vec<Vec<usize>> = (0..n).map(|p| vec![p]).collect();
    let mut active = vec![true; n];
    let mut log = Vec::new();
    let rep = |m: &[usize]| largest_member(m, counts);
    let group_dist = |a: &[usize], b: &[usize]| -> f64 {
        let mut d = f64::INFINITY;
        for &i in a {
            for &j in b {
                d = d.min(dist.get(i, j));
            }
        }
        d
    };
    let r2 = dist.radius * dist.radius;
    let count = |m: &[usize]| -> usize { m.iter().map(|&p| counts[p]).sum() };

    // Greedy static merging. Parts without points never merge here (no neighbours).
    loop {
        let mut best: Option<(f64, usize, usize)> = None;
        for a in 0..n {
            if !active[a] || count(&members[a]) == 0 {
                continue;
            }
            for b in a + 1..n {
                if !active[b] || count(&members[b]) == 0 {
                    continue;
                }
                if group_dist(&members[a], &members[b]) > r2 {
                    continue;
                }
                let l = merge_loss(poses, rep(&members[a]), rep(&members[b]));
                if l < opts.threshold && best.is_none_or(|(bl, _, _)| l < bl) {
                    best = Some((l, a, b));
                }
            }
        }
        let Some((l, a, b)) = best else { break };
        log.push(MergeEvent {
            kind: "merge",
            from: members[b].clone(),
            into: members[a].clone(),
            loss: l,
        });
        let mb = std::mem::take(&mut members[b]);
        members[a].extend(mb);
        members[a].sort_unstable();
        active[b] = false;
    }

    // Tiny parts, smallest first.
    let total: usize = counts.iter().sum();
    let min_count = ((opts.min_fraction * total as f64).ceil() as usize).max(opts.min_points);
    let mut tiny: Vec<usize> = (0..n)
        .filter(|&g| active[g] && count(&members[g]) < min_count)
        .collect();
    let any_big = (0..n).any(|g| active[g] && count(&members[g]) >= min_count);
    if any_big {
        tiny.sort_by_key(|&g| (count(&members[g]), g));
        for g in tiny {
            let big: Vec<usize> = (0..n)
                .filter(|&h| h != g && active[h] && count(&members[h]) >= min_count)
                .collect();
            let near: Vec<usize> = big
                .iter()
                .copied()
                .filter(|&h| group_dist(&members[g], &members[h]) <= r2)
                .collect();
            let target = if near.is_empty() {
                // No neighbour: the nearest part (or, if g has no points at all, the
                // part whose motion is most similar).
                let mut best = (f64::INFINITY, f64::INFINITY, big[0]);
                for &h in &big {
                    let d = group_dist(&members[g], &members[h]);
                    let l = merge_loss(poses, rep(&members[g]), rep(&members[h]));
                    if (d, l) < (best.0, best.1) {
                        best = (d, l, h);
                    }
                }
                best.2
            } else {
                let mut best = (f64::INFINITY, near[0]);
                for &h in &near {
                    let l = merge_loss(poses, rep(&members[g]), rep(&members[h]));
                    if l < best.0 {
                        best = (l, h);
                    }
                }
                best.1
            };
            log.push(MergeEvent {
                kind: "reassign",
                from: members[g].clone(),
                into: members[target].clone(),
                loss: merge_loss(poses, rep(&members[g]), rep(&members[target])),
            });
            let mg = std::mem::take(&mut members[g]);
            // The target keeps its representative: tiny parts never outweigh it.
            members[target].extend(mg);
            members[target].sort_unstable();
            active[g] = false;
        }
    }

    // Renumber by smallest input member (deterministic).
    let mut groups: Vec<Vec<usize>> = (0..n)
        .filter(|&g| active[g])
        .map(|g| members[g].clone())
        .collect();
    groups.sort_by_key(|m| m[0]);
    let mut map = vec![0u32; n];
    for (gi, m) in groups.iter().enumerate() {
        for &p in m {
            map[p] = gi as u32;
        }
    }
    let reps: Vec<usize> = groups.iter().map(|m| rep(m)).collect();
    let merged_poses = poses
        .iter()
        .map(|f| reps.iter().map(|&r| f[r]).collect())
        .collect();
    MergeOutcome {
        map,
        parts: groups.len(),
        members: groups,
        poses: merged_poses,
        log,
    }
}

/// The member of a group with the most points (`counts[p]`), the first among equals:
/// the part whose pose a merged group takes.
pub(crate) fn largest_member(members: &[usize], counts: &[usize]) -> usize {
    let mut best = members[0];
    for &p in members {
        if counts[p] > counts[best] {
            best = p;
        }
    }
    best
}

/// Absorbs each `(child, parent)` pair of merged parts into one part (a joint that does
/// not move, `build::still_joints`, or one the clouds do not show,
/// `invisible_joints`), renumbering the parts in order; `kind` names the reason in the
/// log. A part's pose becomes that of its largest input member, as in [`merge_parts`];
/// `input_poses[k][g]` are the input parts' poses and `counts[g]` their point counts.
pub fn absorb(
    out: &MergeOutcome,
    pairs: &[(usize, usize)],
    input_poses: &[Vec<DMat4>],
    counts: &[usize],
    kind: &'static str,
) -> MergeOutcome {
    // Union-find over merged parts.
    let mut up: Vec<usize> = (0..out.parts).collect();
    fn find(up: &mut [usize], mut a: usize) -> usize {
        while up[a] != a {
            up[a] = up[up[a]];
            a = up[a];
        }
        a
    }
    let mut log = out.log.clone();
    for &(c, p) in pairs {
        let (a, b) = (find(&mut up, c), find(&mut up, p));
        if a != b {
            log.push(MergeEvent {
                kind,
                from: out.members[a].clone(),
                into: out.members[b].clone(),
                loss: 0.0,
            });
            up[a] = b;
        }
    }
    let mut new_index = vec![usize::MAX; out.parts];
    let mut members: Vec<Vec<usize>> = Vec::new();
    for q in 0..out.parts {
        let r = find(&mut up, q);
        if new_index[r] == usize::MAX {
            new_index[r] = members.len();
            members.push(Vec::new());
        }
        let ni = new_index[r];
        members[ni].extend(out.members[q].iter().copied());
    }
    for m in &mut members {
        m.sort_unstable();
    }
    let mut map = vec![0u32; out.map.len()];
    for (ni, m) in members.iter().enumerate() {
        for &g in m {
            map[g] = ni as u32;
        }
    }
    let largest: Vec<usize> = members.iter().map(|m| largest_member(m, counts)).collect();
    let poses = input_poses
        .iter()
        .map(|f| largest.iter().map(|&g| f[g]).collect())
        .collect();
    MergeOutcome {
        map,
        parts: members.len(),
        members,
        poses,
        log,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DVec3;

    fn dist_all_neighbours(n: usize) -> PairDistances {
        PairDistances {
            parts: n,
            min_sq: (0..n * n)
                .map(|i| if i / n == i % n { 0.0 } else { 1e-4 })
                .collect(),
            spacing: 0.01,
            radius: 0.04,
        }
    }

    #[test]
    fn static_pairs_merge_and_moving_parts_stay() {
        // parts 0 and 2 move together, part 1 rotates, part 3 is tiny and moves
        // closest to 1 (but not static to it).
        let k = 5;
        let poses: Vec<Vec<DMat4>> = (0..k)
            .map(|t| {
                let a = DMat4::from_translation(DVec3::new(0.01 * t as f64, 0.0, 0.0));
                let b = DMat4::from_rotation_z(0.2 * t as f64);
                let c = DMat4::from_rotation_z(0.3 * t as f64);
                vec![a, b, a * DMat4::from_translation(DVec3::Y), c]
            })
            .collect();
        let d = dist_all_neighbours(4);
        let out = merge_parts(&poses, &[1000, 800, 500, 3], &d, &MergeOptions::default());
        assert_eq!(out.parts, 2);
        assert_eq!(out.map, vec![0, 1, 0, 1]);
        assert_eq!(out.members, vec![vec![0, 2], vec![1, 3]]);
        assert_eq!(out.log[0].kind, "merge");
        assert_eq!(out.log[1].kind, "reassign");
        assert_eq!(out.poses[2][1], poses[2][1]);
    }

    #[test]
    fn far_parts_do_not_merge() {
        let poses = vec![vec![DMat4::IDENTITY; 2]; 3];
        let mut d = dist_all_neighbours(2);
        d.min_sq = vec![0.0, 1.0, 1.0, 0.0];
        let out = merge_parts(&poses, &[100, 100], &d, &MergeOptions::default());
        assert_eq!(out.parts, 2);
    }

    #[test]
    fn absorb_joins_pairs_and_keeps_the_largest_members_pose() {
        // four merged parts over six input parts; absorb 3 into 1 and 1 into 0.
        let k = 3;
        let poses: Vec<Vec<DMat4>> = (0..k)
            .map(|t| {
                (0..6)
                    .map(|g| DMat4::from_translation(DVec3::new(g as f64, t as f64, 0.0)))
                    .collect()
            })
            .collect();
        let counts = [10, 50, 5, 20, 7, 30];
        let out = MergeOutcome {
            map: vec![0, 1, 2, 3, 0, 1],
            parts: 4,
            members: vec![vec![0, 4], vec![1, 5], vec![2], vec![3]],
            poses: vec![vec![DMat4::IDENTITY; 4]; k],
            log: Vec::new(),
        };
        let a = absorb(&out, &[(3, 1), (1, 0)], &poses, &counts, "still");
        assert_eq!(a.parts, 2);
        assert_eq!(a.map, vec![0, 0, 1, 0, 0, 0]);
        assert_eq!(a.members, vec![vec![0, 1, 3, 4, 5], vec![2]]);
        // part 0's largest member is input part 1 (50 points)
        assert_eq!(a.poses[2][0], poses[2][1]);
        assert_eq!(a.poses[1][1], poses[1][2]);
        assert_eq!(a.log.len(), 2);
        assert!(a.log.iter().all(|e| e.kind == "still"));
    }
}
