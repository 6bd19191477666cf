//! Farthest-point sampling (FPS): picks `n` of `N` points, each the one farthest from
//! those already picked. Used to downsample large frames to the working size and to
//! spread initial Gaussians over a cloud.
//!
//! Exact (the same indices as the textbook O(N·n) loop, ties to the lowest index) but
//! much faster on large clouds: points are sorted along a Morton curve into blocks of
//! [`BLOCK`] with a bounding box and the block's largest current distance; a new
//! sample only revisits blocks whose box is closer than that largest distance, which
//! after the first few samples is a small neighbourhood. Memory is O(N).

use glam::Vec3;

/// Points per block; a few hundred keeps the per-sample block scan cheap and the
/// revisited blocks tight.
const BLOCK: usize = 256;

/// Returns `min(n, points.len())` indices into `points`, in selection order, starting
/// with `start` (clamped to the last point). Selected points are never repeated, even
/// when the cloud has duplicates.
pub fn farthest_point_sampling(points: &[Vec3], n: usize, start: usize) -> Vec<usize> {
    let total = points.len();
    let n = n.min(total);
    if n == 0 {
        return Vec::new();
    }
    let start = start.min(total - 1);
    if total <= 4 * BLOCK {
        naive(points, n, start)
    } else {
        blocked(points, n, start)
    }
}

/// The textbook loop; the reference the blocked version must match.
fn naive(points: &[Vec3], n: usize, start: usize) -> Vec<usize> {
    let mut d = vec![f32::INFINITY; points.len()];
    let mut out = Vec::with_capacity(n);
    let mut cur = start;
    loop {
        out.push(cur);
        d[cur] = -1.0;
        if out.len() == n {
            return out;
        }
        let s = points[cur];
        let mut best = f32::NEG_INFINITY;
        let mut arg = 0;
        for (i, (p, di)) in points.iter().zip(d.iter_mut()).enumerate() {
            let dx = p.x - s.x;
            let dy = p.y - s.y;
            let dz = p.z - s.z;
            let dist = dx * dx + dy * dy + dz * dz;
            if dist < *di {
                *di = dist;
            }
            if *di > best {
                best = *di;
                arg = i;
            }
        }
        cur = arg;
    }
}

/// Interleaves the low 10 bits of `v` with two zero bits between each.
fn spread10(v: u32) -> u32 {
    let mut x = v & 0x3ff;
    x = (x | (x << 16)) & 0x030000ff;
    x = (x | (x << 8)) & 0x0300f00f;
    x = (x | (x << 4)) & 0x030c30c3;
    x = (x | (x << 2)) & 0x09249249;
    x
}

struct Block {
    lo: Vec3,
    hi: Vec3,
    /// Largest current distance in the block (−1 when all its points are selected).
    maxd: f32,
    /// Position (in sorted order) of that point, ties to the lowest original index.
    arg: usize,
}

fn blocked(points: &[Vec3], n: usize, start: usize) -> Vec<usize> {
    let total = points.len();
    let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
    for p in points {
        lo = lo.min(*p);
        hi = hi.max(*p);
    }
    let ext = (hi - lo).max(Vec3::splat(f32::MIN_POSITIVE));
    let scale = Vec3::splat(1023.0) / ext;
    let mut keyed: Vec<(u32, u32)> = points
        .iter()
        .enumerate()
        .map(|(i, p)| {
            // Non-finite inputs land in cell 0; they stay valid indices either way.
            let q = ((*p - lo) * scale).clamp(Vec3::ZERO, Vec3::splat(1023.0));
            let code =
                spread10(q.x as u32) | (spread10(q.y as u32) << 1) | (spread10(q.z as u32) << 2);
            (code, i as u32)
        })
        .collect();
    keyed.sort_unstable();
    let orig: Vec<u32> = keyed.iter().map(|&(_, i)| i).collect();
    drop(keyed);
    let xs: Vec<f32> = orig.iter().map(|&i| points[i as usize].x).collect();
    let ys: Vec<f32> = orig.iter().map(|&i| points[i as usize].y).collect();
    let zs: Vec<f32> = orig.iter().map(|&i| points[i as usize].z).collect();
    let mut d = vec![f32::INFINITY; total];
    let mut blocks: Vec<Block> = (0..total.div_ceil(BLOCK))
        .map(|b| {
            let r = b * BLOCK..((b + 1) * BLOCK).min(total);
            let (mut l, mut h) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
            for j in r.clone() {
                let p = Vec3::new(xs[j], ys[j], zs[j]);
                l = l.min(p);
                h = h.max(p);
            }
            Block {
                lo: l,
                hi: h,
                maxd: f32::INFINITY,
                arg: r.start,
            }
        })
        .collect();

    let mut out = Vec::with_capacity(n);
    let mut cur = orig.iter().position(|&i| i as usize == start).unwrap_or(0);
    loop {
        out.push(orig[cur] as usize);
        d[cur] = -1.0;
        if out.len() == n {
            return out;
        }
        let (sx, sy, sz) = (xs[cur], ys[cur], zs[cur]);
        let home = cur / BLOCK;
        for (b, blk) in blocks.iter_mut().enumerate() {
            // Squared distance from the sample to the box, summed in the same order as
            // the point distances so that it is a lower bound in floating point too.
            let gx = (blk.lo.x - sx).max(sx - blk.hi.x).max(0.0);
            let gy = (blk.lo.y - sy).max(sy - blk.hi.y).max(0.0);
            let gz = (blk.lo.z - sz).max(sz - blk.hi.z).max(0.0);
            let lb = gx * gx + gy * gy + gz * gz;
            if lb >= blk.maxd && b != home {
                continue;
            }
            let r = b * BLOCK..((b + 1) * BLOCK).min(total);
            let (bx, by, bz, bd) = (
                &xs[r.clone()],
                &ys[r.clone()],
                &zs[r.clone()],
                &mut d[r.clone()],
            );
            let mut m = f32::NEG_INFINITY;
            for j in 0..bd.len() {
                let dx = bx[j] - sx;
                let dy = by[j] - sy;
                let dz = bz[j] - sz;
                let dist = dx * dx + dy * dy + dz * dz;
                let v = if dist < bd[j] { dist } else { bd[j] };
                bd[j] = v;
                m = if v > m { v } else { m };
            }
            let mut arg = r.start;
            let mut arg_orig = u32::MAX;
            for (j, &v) in bd.iter().enumerate() {
                let o = orig[r.start + j];
                if v == m && o < arg_orig {
                    arg_orig = o;
                    arg = r.start + j;
                }
            }
            blk.maxd = m;
            blk.arg = arg;
        }
        let mut best = &blocks[0];
        for blk in &blocks[1..] {
            if blk.maxd > best.maxd || (blk.maxd == best.maxd && orig[blk.arg] < orig[best.arg]) {
                best = blk;
            }
        }
        cur = best.arg;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::rngs::StdRng;
    use rand::{Rng, SeedableRng};

    fn cloud(n: usize, seed: u64) -> Vec<Vec3> {
        let mut rng = StdRng::seed_from_u64(seed);
        (0..n)
            .map(|_| {
                Vec3::new(
                    rng.random(),
                    rng.random::<f32>() * 0.5,
                    rng.random::<f32>() * 2.0,
                )
            })
            .collect()
    }

    #[test]
    fn blocked_matches_naive() {
        for (n_pts, seed) in [(3000, 1), (5000, 2), (1025, 3)] {
            let pts = cloud(n_pts, seed);
            let a = naive(&pts, 300, 17);
            let b = blocked(&pts, 300, 17);
            assert_eq!(a, b, "N = {n_pts}");
        }
    }

    #[test]
    fn duplicates_and_ties_match_and_never_repeat() {
        // A grid with many duplicate points: lots of exact ties.
        let mut pts = Vec::new();
        for i in 0..1500 {
            let k = i % 125;
            pts.push(Vec3::new(
                (k % 5) as f32,
                ((k / 5) % 5) as f32,
                (k / 25) as f32,
            ));
        }
        let a = naive(&pts, 400, 0);
        let b = blocked(&pts, 400, 0);
        assert_eq!(a, b);
        let mut s = b.clone();
        s.sort_unstable();
        s.dedup();
        assert_eq!(s.len(), 400);
        // The first 125 picks cover each distinct grid position once.
        let distinct: std::collections::HashSet<[i32; 3]> = b[..125]
            .iter()
            .map(|&i| pts[i].to_array().map(|v| v as i32))
            .collect();
        assert_eq!(distinct.len(), 125);
    }

    #[test]
    fn edge_cases() {
        let pts = cloud(10, 4);
        assert!(farthest_point_sampling(&pts, 0, 0).is_empty());
        assert!(farthest_point_sampling(&[], 5, 0).is_empty());
        let all = farthest_point_sampling(&pts, 50, 99);
        assert_eq!(all.len(), 10);
        assert_eq!(all[0], 9);
        // The second pick is the farthest from the first.
        let s = pts[all[0]];
        let far = (0..10)
            .max_by(|&a, &b| pts[a].distance(s).total_cmp(&pts[b].distance(s)))
            .unwrap();
        assert_eq!(all[1], far);
    }
}
