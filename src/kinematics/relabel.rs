//! Motion-consistent labels: after the joints are fitted, a point belongs to the part
//! whose motion carries it onto the other frames' clouds. The Gaussians' Mahalanobis
//! segmentation mislabels points near a joint (an ellipsoid's tail reaches into the
//! next link), and those points then move with the wrong part.

use glam::{DMat4, Mat3, Vec3};

use crate::geom::knn::Grid;

/// Options of `relabel`.
#[derive(Debug, Clone, Copy)]
pub struct RelabelOpts {
    /// Squared distances are capped here (in units of the object size²), so a frame
    /// where the point is hidden or far off does not dominate. Measured (bench-dev
    /// full, fast): mean RI 0.885 at 4e-4, 0.886 at 1e-3 and 3e-3.
    pub cap: f64,
    /// A point changes part only when the other part's cost is below this factor of
    /// its current part's cost. Measured (bench-dev full, fast): mean RI 0.882 at 0.3,
    /// 0.886 at 0.5 (cap 1e-3), 0.875 at 0.8 (cap 4e-4; too eager: points at a joint
    /// fit both parts).
    pub margin: f64,
    /// At most this many other frames are compared (evenly spread).
    pub frames: usize,
}

impl Default for RelabelOpts {
    fn default() -> Self {
        RelabelOpts {
            cap: 1e-3,
            margin: 0.5,
            frames: 9,
        }
    }
}

/// Relabels every frame's points (`labels[k][i]` for `clouds[k][i]`) by the part
/// whose motion (`poses[t][p]`, frame t's pose of part p) best carries the point
/// onto the clouds of the other frames. `grids[k]` indexes `clouds[k]` (built once by
/// the caller, which measures the coverage on them too). `size` is the object's size in
/// the clouds' units. Returns the number of changed labels.
pub fn relabel(
    clouds: &[&[Vec3]],
    grids: &[Grid],
    labels: &mut [Vec<u32>],
    poses: &[Vec<DMat4>],
    size: f64,
    opts: &RelabelOpts,
) -> usize {
    let kk = clouds.len();
    let parts = poses.first().map_or(0, Vec::len);
    if kk < 2 || parts < 2 || labels.len() != kk || grids.len() != kk {
        return 0;
    }
    let cap2 = (opts.cap * size * size) as f32;
    let mut changed = 0;
    for k in 0..kk {
        if labels[k].len() != clouds[k].len() {
            continue;
        }
        // Other frames, evenly spread.
        let step = (kk - 1).div_ceil(opts.frames.max(1)).max(1);
        let others: Vec<usize> = (0..kk).filter(|&t| t != k).step_by(step).collect();
        // Per part and other frame: the motion frame k → t, in f32.
        let motions: Vec<Vec<(Mat3, Vec3)>> = (0..parts)
            .map(|p| {
                let inv = poses[k][p].inverse();
                others
                    .iter()
                    .map(|&t| {
                        let m = (poses[t][p] * inv).as_mat4();
                        (Mat3::from_mat4(m), m.w_axis.truncate())
                    })
                    .collect()
            })
            .collect();
        for (i, x) in clouds[k].iter().enumerate() {
            let cur = labels[k][i] as usize;
            if cur >= parts {
                continue;
            }
            // The current part's cost, then the others only while they can still
            // beat it by the margin (most points fit their part and stop at once).
            let cost_of = |p: usize, bound: f32| -> f32 {
                let mut sum = 0.0f32;
                for ((r, c), &t) in motions[p].iter().zip(&others) {
                    // Only a distance below what is left of the bound can matter, so
                    // the search is capped there too: fewer cells, the same decision
                    // (frames of many points, where this runs over every input point).
                    let left = bound - sum;
                    let cap = cap2.min(left);
                    let d2 = grids[t].nearest_d2_capped(*r * *x + *c, cap);
                    if cap < cap2 && d2 >= cap {
                        return bound;
                    }
                    sum += d2;
                    if sum >= bound {
                        break;
                    }
                }
                sum
            };
            let bound = (opts.margin * cost_of(cur, f32::INFINITY) as f64) as f32;
            let mut best: Option<(usize, f32)> = None;
            for p in (0..parts).filter(|&p| p != cur) {
                let c = cost_of(p, best.map_or(bound, |b| b.1.min(bound)));
                if c < bound && best.is_none_or(|b| c < b.1) {
                    best = Some((p, c));
                }
            }
            if let Some((p, _)) = best {
                labels[k][i] = p as u32;
                changed += 1;
            }
        }
    }
    changed
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn points_move_to_the_part_whose_motion_they_follow() {
        // Two bars along x meeting at the origin; the right one turns 90° about z in
        // frame 1. A few right-bar points start labelled as the left bar.
        let mut cloud = Vec::new();
        for i in 0..200 {
            let x = -1.0 + i as f32 / 100.0;
            cloud.push(Vec3::new(x, 0.0, 0.0));
        }
        let lab: Vec<u32> = cloud.iter().map(|p| (p.x > 0.0) as u32).collect();
        let turn = DMat4::from_rotation_z(std::f64::consts::FRAC_PI_2);
        let moved: Vec<Vec3> = cloud
            .iter()
            .zip(&lab)
            .map(|(p, &l)| {
                if l == 1 {
                    turn.as_mat4().transform_point3(*p)
                } else {
                    *p
                }
            })
            .collect();
        let mut labels = vec![lab.clone(), lab.clone()];
        for l in labels[0].iter_mut().skip(120).take(10) {
            *l = 0;
        }
        let poses = vec![vec![DMat4::IDENTITY; 2], vec![DMat4::IDENTITY, turn]];
        let grids = [Grid::new(&cloud), Grid::new(&moved)];
        let n = relabel(
            &[cloud.as_slice(), moved.as_slice()],
            &grids,
            &mut labels,
            &poses,
            2.0,
            &Default::default(),
        );
        assert_eq!(labels[0], lab);
        assert_eq!(n, 10);
        // Points at the joint fit both motions: they keep their label.
        assert_eq!(labels[1], lab);
    }
}
