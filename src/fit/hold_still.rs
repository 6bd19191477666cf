//! Gaussians held still where the clouds say they do not move (an addition to the
//! paper's optimisation).
//!
//! Every occluded frame shows the object from another side, and a Gaussian's motion is
//! found from the few points it sees there. One-sided views can slide over each other:
//! the occluded losses reward motions that make the frames overlap, and a part that
//! never moves (a robot's base) gets a wrong motion in many frames (bench-dev occluded
//! panda_gripper, fast: its hand half a turn off in one frame and 0.03–0.1 away in
//! most others). Every part posed relative to it then inherits the error.
//!
//! The raw clouds tell a still part apart without any motion: where it is, every
//! frame's points lie on the surface that the other frames' points sample. So for each
//! Gaussian two families of motions are compared on its region (its frame-0 points):
//! its own motions and no motion at all. A family carries every frame's points back
//! to frame 0 and keeps those that land in the region (within the occluded search's
//! inlier radius of the Gaussian's frame-0 points, and nearer to them than to any
//! other Gaussian's); its *agreement* is the share of them that
//! lands within `AGREE_R2` of a point carried from another frame t' ≥ 1 (frame 0 is
//! no target, since the region is made of its points). Labels play no part, so wrong
//! motions do not vouch for themselves. A Gaussian is held still in
//! every frame when no motion agrees `MARGIN` better than its own motions.
//!
//! Full input has its own case (`hold_spinning_root`): a root that is symmetric about
//! an axis (the procedural arm's cylindrical base) can turn about it at no cost to the
//! fit, and the pose search then lets it turn with the child that really turns about
//! that axis (arm generator seed 1: the base's Gaussians turned up to 23° with the
//! shoulder). Every part posed relative to it inherits the turn, so the root is held
//! still when no motion fits its points as well as its own.

use glam::{DMat3, DVec3, Vec3};

use super::fitter::Data;
use super::gaussians::Params;
use super::pose_init::{relative_motion, set_relative_pose};
use super::pose_search::{frame0_start, Motion};
use crate::geom::knn::Grid;

/// Squared radius (normalised units²) of a Gaussian's region around its frame-0
/// points: the occluded search's inlier radius. The region ends where another
/// Gaussian's points are nearer (`Region`): within the radius alone, a thin link's
/// region reaches into the body beside its pivot, whose points agree without motion
/// but disagree once the link's motions carry them about the pivot, so the link was
/// held still and merged into the body (bench-dev occluded, fast, seeds 0–4: RI 0.807
/// → 0.818, the legged robots most; docs/DEVELOPMENT.md, session 46).
const REGION_R2: f32 = 1e-3;

/// Squared radius within which two frames' carried points agree: about one point
/// spacing of the occluded frames (0.007–0.011). Bench-dev occluded, fast, means of
/// seeds 0–2 (RI / recon / flow / TED): 2e-4 gave 0.715 / 13.35 / 15.74 / 5.38, 1e-4
/// 0.718 / 12.70 / 14.92 / 4.86, 4e-5 0.700 / 12.51 / 14.38 / 4.96 (without the hold
/// 0.701 / 14.73 / 17.55 / 5.52).
const AGREE_R2: f32 = 1e-4;

/// Agreement (a share) by which no motion must beat the Gaussian's own motions: a
/// part that moves a little (panda_gripper's fingers) agrees about as well either way,
/// and held still it merges into its parent. Same runs: a margin of 0 gave 0.697 /
/// 12.63 / 14.47 / 5.00, 0.1 gave 0.708 / 13.38 / 16.07 / 5.38.
const MARGIN: f64 = 0.05;

/// Frame-0 points sampled for the regions.
const POINTS: usize = 2048;

/// `hold_spinning_root`: a point is off the cloud beyond this squared distance
/// (normalised units², 0.02: two to five point spacings of the procedural and
/// bench-dev frames at 4096 points).
const SPIN_OFF_R2: f32 = 4e-4;

/// `hold_spinning_root`: without motion, at most this share more of the root's points
/// may be off the cloud than with its own motion, in every frame.
const SPIN_SLACK: f64 = 0.02;

/// `hold_spinning_root`: the root's own motion must carry its points this many point
/// spacings on average (over its points and frames), so a root that is already still
/// up to noise is left as it is. The least-moving group's mean displacement was at most
/// 2.1 spacings on bench-dev full (fast, seed 0: talos, 0.015) and below 1 on the
/// procedural laptop and cabinet; 3–12 on the arm, whose base turned with its shoulder.
const SPIN_SPACINGS: f64 = 4.0;

/// Gaussians sharing one motion in every frame (the snap gives a rigid group one
/// motion), each group listed once, in order of its first member.
fn motion_groups(rel: &[Vec<Motion>]) -> Vec<Vec<usize>> {
    let same = |a: &[Motion], b: &[Motion]| {
        a.iter()
            .zip(b)
            .all(|(x, y)| x.0.abs_diff_eq(y.0, 1e-9) && x.1.abs_diff_eq(y.1, 1e-9))
    };
    let mut group_of = vec![usize::MAX; rel.len()];
    let mut groups: Vec<Vec<usize>> = Vec::new();
    for i in 0..rel.len() {
        if group_of[i] != usize::MAX {
            continue;
        }
        let members: Vec<usize> = (i..rel.len())
            .filter(|&j| group_of[j] == usize::MAX && same(&rel[i], &rel[j]))
            .collect();
        for &j in &members {
            group_of[j] = groups.len();
        }
        groups.push(members);
    }
    groups
}

/// Full input: the group of Gaussians that moves least (the root; among the groups
/// holding at least a tenth of the frame-0 points) is held still in every frame when
/// its motion carries its points `SPIN_SPACINGS` point spacings on average, yet without
/// motion no more than `SPIN_SLACK` more of them leave the cloud (`SPIN_OFF_R2`) in any
/// frame than with it: the motion is a turn the clouds cannot see. Frame 0 is left
/// unchanged. Returns the number of Gaussians held.
pub fn hold_spinning_root(data: &Data, params: &mut Params) -> usize {
    let kk = data.k();
    let Some((g0, points)) = frame0_start(data, params, POINTS) else {
        return 0;
    };
    let m = g0.len();
    let rel: Vec<Vec<Motion>> = (0..m)
        .map(|i| {
            (0..kk)
                .map(|t| relative_motion(&g0[i], &params.gauss(t, i)))
                .collect()
        })
        .collect();
    let total: usize = points.iter().map(Vec::len).sum();
    // Mean displacement of a group's frame-0 points over frames t >= 1.
    let displacement = |group: &[usize]| {
        let (mut sum, mut n) = (0.0, 0usize);
        for &i in group {
            for &(r, c) in &rel[i][1..] {
                sum += points[i]
                    .iter()
                    .map(|x| (r * *x + c - *x).length())
                    .sum::<f64>();
                n += points[i].len();
            }
        }
        sum / n.max(1) as f64
    };
    let Some((root, n, moved)) = motion_groups(&rel)
        .into_iter()
        .map(|g| {
            let n: usize = g.iter().map(|&i| points[i].len()).sum();
            (g, n)
        })
        .filter(|&(_, n)| n * 10 >= total)
        .map(|(g, n)| {
            let d = displacement(&g);
            (g, n, d)
        })
        .min_by(|a, b| a.2.total_cmp(&b.2))
    else {
        return 0;
    };
    if moved < SPIN_SPACINGS * crate::geom::knn::point_spacing(&data.frames32[0]) {
        return 0;
    }
    for (t, grid) in data.grids.iter().enumerate().skip(1) {
        let off = |carry: &dyn Fn(usize, DVec3) -> DVec3| {
            let mut count = 0usize;
            for &i in &root {
                count += points[i]
                    .iter()
                    .filter(|x| {
                        let y = carry(i, **x).as_vec3();
                        grid.nearest_d2_capped(y, SPIN_OFF_R2) >= SPIN_OFF_R2
                    })
                    .count();
            }
            count as f64 / n.max(1) as f64
        };
        let own = off(&|i, x| rel[i][t].0 * x + rel[i][t].1);
        if off(&|_, x| x) > own + SPIN_SLACK {
            return 0;
        }
    }
    for &i in &root {
        for t in 1..kk {
            set_relative_pose(params, t, i, &g0[i], (DMat3::IDENTITY, DVec3::ZERO));
        }
    }
    root.len()
}

/// A Gaussian's region (module doc): the places within `REGION_R2` of one of its
/// frame-0 points and nearer to its points than to any other Gaussian's. `all` indexes
/// every Gaussian's frame-0 points, `owner[j]` is the Gaussian of point j.
struct Region<'a> {
    all: &'a Grid,
    owner: &'a [usize],
    gaussian: usize,
}

impl Region<'_> {
    fn contains(&self, x: Vec3) -> bool {
        self.all
            .nearest_capped(x, REGION_R2)
            .is_some_and(|(j, d2)| d2 < REGION_R2 && self.owner[j as usize] == self.gaussian)
    }
}

/// Agreement of the motions `rel[t]` (frame 0 → t) on `region` (module doc).
fn agreement(data: &Data, region: &Region, rel: &[Motion]) -> f64 {
    let carried: Vec<Vec<Vec3>> = data
        .frames
        .iter()
        .zip(rel)
        .map(|(frame, &(r, c))| {
            let (ri, ci) = (r.transpose(), -(r.transpose() * c));
            frame
                .iter()
                .map(|y| (ri * *y + ci).as_vec3())
                .filter(|x| region.contains(*x))
                .collect()
        })
        .collect();
    // Frame 0 is no target: the region is made of its points.
    let targets: Vec<Grid> = carried[1..].iter().map(|c| Grid::new(c)).collect();
    let (mut agree, mut total) = (0usize, 0usize);
    for (t, pts) in carried.iter().enumerate() {
        total += pts.len();
        agree += pts
            .iter()
            .filter(|x| {
                targets.iter().enumerate().any(|(s, g)| {
                    s + 1 != t && !g.is_empty() && g.nearest_d2_capped(**x, AGREE_R2) < AGREE_R2
                })
            })
            .count();
    }
    agree as f64 / total.max(1) as f64
}

/// Holds still (module doc) every Gaussian that no motion explains clearly better
/// than its own motions; frame 0 is left unchanged. Returns the number held.
pub fn hold_still(data: &Data, params: &mut Params) -> usize {
    let kk = data.k();
    // With two frames no frame t ≥ 1 has another to agree with.
    if kk < 3 {
        return 0;
    }
    let Some((g0, groups)) = frame0_start(data, params, POINTS) else {
        return 0;
    };
    let still: Vec<Motion> = vec![(DMat3::IDENTITY, DVec3::ZERO); kk];
    let all = Grid::new(
        &groups
            .iter()
            .flatten()
            .map(|p| p.as_vec3())
            .collect::<Vec<_>>(),
    );
    let owner: Vec<usize> = groups
        .iter()
        .enumerate()
        .flat_map(|(i, g)| std::iter::repeat_n(i, g.len()))
        .collect();
    let mut held = 0;
    for (i, group) in groups.iter().enumerate() {
        if group.len() < 3 {
            continue;
        }
        let region = Region {
            all: &all,
            owner: &owner,
            gaussian: i,
        };
        let own: Vec<Motion> = (0..kk)
            .map(|t| relative_motion(&g0[i], &params.gauss(t, i)))
            .collect();
        if agreement(data, &region, &still) > agreement(data, &region, &own) + MARGIN {
            for (t, &mo) in still.iter().enumerate().skip(1) {
                set_relative_pose(params, t, i, &g0[i], mo);
            }
            held += 1;
        }
    }
    held
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::occluded_search::tests::occluded_hinge;
    use crate::fit::pose_search::tests::oracle_params;
    use crate::math::Libm;

    /// `occluded_search`'s hinge (a base and an arm turning about z, seen from a
    /// different direction in every frame), every frame moved as a whole by
    /// `carry(t)`. Returns the frames and frame 0's labels.
    fn seen_hinge(angles: &[f64], carry: impl Fn(usize) -> DVec3) -> (Vec<Vec<Vec3>>, Vec<u32>) {
        let (mut frames, lab0) = occluded_hinge(angles);
        for (t, f) in frames.iter_mut().enumerate() {
            let shift = carry(t).as_vec3();
            f.iter_mut().for_each(|p| *p += shift);
        }
        (frames, lab0)
    }

    /// Oracle Gaussians (base 0, arm 1) with the arm's true motions and the base
    /// moved by `base(t)` instead of its true motion `carry(t)`.
    fn posed(
        frames: &[Vec<Vec3>],
        lab0: &[u32],
        angles: &[f64],
        carry: impl Fn(usize) -> DVec3,
        base: impl Fn(usize) -> DVec3,
    ) -> Params {
        let mut params = oracle_params(&frames[0], lab0, 2, angles.len());
        let (b0, a0) = (params.gauss(0, 0), params.gauss(0, 1));
        for (t, a) in angles.iter().enumerate().skip(1) {
            let r = DMat3::from_axis_angle(DVec3::Z, *a);
            let shift = carry(t) - carry(0);
            set_relative_pose(&mut params, t, 1, &a0, (r, shift - r * carry(0) + carry(0)));
            set_relative_pose(&mut params, t, 0, &b0, (DMat3::IDENTITY, base(t)));
        }
        params
    }

    const ANGLES: [f64; 5] = [0.0, 0.9, -1.2, 0.5, 1.4];

    #[test]
    fn a_still_base_with_wrong_motions_is_held_still() {
        let (frames, lab0) = seen_hinge(&ANGLES, |_| DVec3::ZERO);
        let data = Data::new(frames.clone());
        // The base slid 0.04–0.07 along its faces in frames 1–4.
        let wrong = |t: usize| DVec3::new(0.04 + 0.01 * t as f64, 0.02, 0.0);
        let mut params = posed(&frames, &lab0, &ANGLES, |_| DVec3::ZERO, wrong);
        let arm_before: Vec<_> = (0..ANGLES.len()).map(|t| params.gauss(t, 1)).collect();
        assert_eq!(hold_still(&data, &mut params), 1);
        assert_base_held(&params, &arm_before);
    }

    /// Gaussian 0 (the base) has frame 0's pose in every frame, and Gaussian 1 (the
    /// moving arm) kept its (right) poses `arm`.
    fn assert_base_held(params: &Params, arm: &[crate::fit::gaussians::Gauss]) {
        let b0 = params.gauss(0, 0);
        for (t, a) in arm.iter().enumerate() {
            let b = params.gauss(t, 0);
            assert!(b.mu.distance(b0.mu) < 1e-9, "frame {t}: base not held");
            assert!(b.r.abs_diff_eq(b0.r, 1e-9), "frame {t}: base turned");
            assert_eq!(params.gauss(t, 1).mu, a.mu, "frame {t}: arm changed");
        }
    }

    #[test]
    fn a_base_that_really_moves_keeps_its_motion() {
        // The whole hinge is carried 0.06 further along x in every frame, and the
        // Gaussians follow it: no motion explains nothing here.
        let carry = |t: usize| DVec3::new(0.06 * t as f64, 0.0, 0.0);
        let (frames, lab0) = seen_hinge(&ANGLES, carry);
        let data = Data::new(frames.clone());
        let mut params = posed(&frames, &lab0, &ANGLES, carry, carry);
        let before = params.x.clone();
        assert_eq!(hold_still(&data, &mut params), 0);
        assert_eq!(params.x, before);
    }

    /// A still slab (part 0, 0.15 × 0.15 × 0.02) and a thin rod (part 1, radius 0.012,
    /// 0.3 long) hanging from its edge and swinging about the edge by `swing[t]`, every
    /// frame sampled anew. Returns the frames and frame 0's labels.
    fn slab_and_rod(swing: &[f64]) -> (Vec<Vec<Vec3>>, Vec<u32>) {
        use rand::{Rng, SeedableRng};
        let mut rng = rand::rngs::StdRng::seed_from_u64(9);
        let pivot = DVec3::new(0.3, 0.0, 0.0);
        let (mut frames, mut lab0) = (Vec::new(), Vec::new());
        for (t, &a) in swing.iter().enumerate() {
            let turn = DMat3::from_axis_angle(DVec3::Y, a);
            let mut f = Vec::new();
            for _ in 0..6000 {
                let (p, l) = if rng.random_bool(0.9) {
                    let u = DVec3::new(rng.random(), rng.random(), rng.random());
                    let p = DVec3::new(0.15, -0.075, -0.02) + DVec3::new(0.15, 0.15, 0.02) * u;
                    (p, 0)
                } else {
                    let phi = rng.random::<f64>() * std::f64::consts::TAU;
                    let z = -0.3 * rng.random::<f64>();
                    let p = pivot + DVec3::new(0.012 * phi.lcos(), 0.012 * phi.lsin(), z);
                    (pivot + turn * (p - pivot), 1)
                };
                f.push(p.as_vec3());
                if t == 0 {
                    lab0.push(l);
                }
            }
            frames.push(f);
        }
        (frames, lab0)
    }

    #[test]
    fn a_thin_link_swinging_beside_a_still_body_keeps_its_motion() {
        // Within the inlier radius alone, the rod's region reaches into the slab beside
        // its pivot: without motion those slab points agree, while the rod's own
        // swung-away points leave the region; with the rod's motion they are carried
        // about the pivot and disagree. No motion then agreed better (0.84 against
        // 0.74; 0.29 against 0.71 within the rod's own cell) and the rod was held still.
        let swing = [0.0, 1.2, -0.8, 1.5, 0.6];
        let (frames, lab0) = slab_and_rod(&swing);
        let data = Data::new(frames.clone());
        let mut params = oracle_params(&frames[0], &lab0, 2, swing.len());
        let rod0 = params.gauss(0, 1);
        let pivot = DVec3::new(0.3, 0.0, 0.0);
        // The rod's motions as an occluded search finds them: a few degrees off.
        for (t, &a) in swing.iter().enumerate().skip(1) {
            let r = DMat3::from_axis_angle(DVec3::Y, a + [0.0, 0.07, -0.07, 0.14, -0.14][t]);
            set_relative_pose(&mut params, t, 1, &rod0, (r, pivot - r * pivot));
        }
        let before = params.x.clone();
        assert_eq!(hold_still(&data, &mut params), 0);
        assert_eq!(params.x, before);
    }

    #[test]
    fn a_region_ends_where_another_gaussians_points_are_nearer() {
        let pts = [
            Vec3::ZERO,
            Vec3::new(0.02, 0.0, 0.0),
            Vec3::new(0.04, 0.0, 0.0),
        ];
        let all = Grid::new(&pts);
        let owner = [0, 0, 1];
        let region = Region {
            all: &all,
            owner: &owner,
            gaussian: 0,
        };
        assert!(region.contains(Vec3::new(0.0, 0.01, 0.0)));
        assert!(region.contains(Vec3::new(0.025, 0.0, 0.0)));
        // Within the radius of its points, but nearer the other Gaussian's.
        assert!(!region.contains(Vec3::new(0.035, 0.0, 0.0)));
        // Beyond the radius of every point.
        assert!(!region.contains(Vec3::new(0.0, 0.05, 0.0)));
    }

    /// A turntable: a cylindrical base (radius 0.25, symmetric about z) and a bar with a
    /// nub 0.05 above it turning about z by `arm[t]`, every frame sampled anew. Returns
    /// the frames and frame 0's labels (0 base, 1 bar).
    fn turntable(arm: &[f64], base_shift: impl Fn(usize) -> DVec3) -> (Vec<Vec<Vec3>>, Vec<u32>) {
        use rand::{Rng, SeedableRng};
        let mut rng = rand::rngs::StdRng::seed_from_u64(5);
        let mut frames = Vec::new();
        let mut lab0 = Vec::new();
        for (t, &a) in arm.iter().enumerate() {
            let turn = DMat3::from_axis_angle(DVec3::Z, a);
            let mut f = Vec::new();
            for _ in 0..3000 {
                let (p, l) = if rng.random_bool(0.5) {
                    // Cylinder surface: side or one of the two caps, by area.
                    let phi = rng.random::<f64>() * std::f64::consts::TAU;
                    let p = if rng.random_bool(0.3) {
                        DVec3::new(
                            0.25 * phi.lcos(),
                            0.25 * phi.lsin(),
                            -0.1 * rng.random::<f64>(),
                        )
                    } else {
                        let rad = 0.25 * rng.random::<f64>().sqrt();
                        let z = if rng.random_bool(0.5) { 0.0 } else { -0.1 };
                        DVec3::new(rad * phi.lcos(), rad * phi.lsin(), z)
                    };
                    (p + base_shift(t), 0)
                } else {
                    // Bar along x with a nub off its axis, so no turn maps it onto itself.
                    let (lo, hi) = if rng.random_bool(0.3) {
                        (DVec3::new(0.3, 0.04, 0.1), DVec3::new(0.42, 0.14, 0.16))
                    } else {
                        (DVec3::new(0.0, -0.04, 0.05), DVec3::new(0.45, 0.04, 0.11))
                    };
                    let u = DVec3::new(rng.random(), rng.random(), rng.random());
                    let mut p = lo + (hi - lo) * u;
                    // Onto the box surface: snap one random coordinate to a face.
                    match rng.random_range(0..3) {
                        0 => p.x = if rng.random_bool(0.5) { lo.x } else { hi.x },
                        1 => p.y = if rng.random_bool(0.5) { lo.y } else { hi.y },
                        _ => p.z = if rng.random_bool(0.5) { lo.z } else { hi.z },
                    }
                    (turn * p + base_shift(t), 1)
                };
                f.push(p.as_vec3());
                if t == 0 {
                    lab0.push(l);
                }
            }
            frames.push(f);
        }
        (frames, lab0)
    }

    const ARM: [f64; 4] = [0.0, 0.8, -1.0, 1.2];

    /// Oracle Gaussians on the turntable: the bar with its true motion, the base turned
    /// by `spin[t]` about its axis and carried by `shift(t)`.
    fn turntable_params(
        frames: &[Vec<Vec3>],
        lab0: &[u32],
        spin: &[f64],
        shift: impl Fn(usize) -> DVec3,
    ) -> Params {
        let mut params = oracle_params(&frames[0], lab0, 2, ARM.len());
        let (b0, a0) = (params.gauss(0, 0), params.gauss(0, 1));
        for t in 1..ARM.len() {
            let r = DMat3::from_axis_angle(DVec3::Z, ARM[t]);
            set_relative_pose(&mut params, t, 1, &a0, (r, shift(t) - r * shift(0)));
            let s = DMat3::from_axis_angle(DVec3::Z, spin[t]);
            set_relative_pose(&mut params, t, 0, &b0, (s, shift(t) - s * shift(0)));
        }
        params
    }

    #[test]
    fn a_symmetric_root_turning_with_its_child_is_held_still() {
        let (frames, lab0) = turntable(&ARM, |_| DVec3::ZERO);
        let data = Data::new(frames.clone());
        // The base turned along with the bar, by 70 % of its turn: the clouds cannot see it.
        let spin: Vec<f64> = ARM.iter().map(|a| 0.7 * a).collect();
        let mut params = turntable_params(&frames, &lab0, &spin, |_| DVec3::ZERO);
        let bar: Vec<_> = (0..ARM.len()).map(|t| params.gauss(t, 1)).collect();
        assert_eq!(hold_spinning_root(&data, &mut params), 1);
        assert_base_held(&params, &bar);
    }

    #[test]
    fn a_root_that_moves_or_is_still_up_to_noise_is_left_alone() {
        // Carried along x with everything else: without motion it leaves the cloud.
        let shift = |t: usize| DVec3::new(0.08 * t as f64, 0.0, 0.0);
        let (frames, lab0) = turntable(&ARM, shift);
        let data = Data::new(frames.clone());
        let spin = [0.0; 4];
        let mut params = turntable_params(&frames, &lab0, &spin, shift);
        let before = params.x.clone();
        assert_eq!(hold_spinning_root(&data, &mut params), 0);
        assert_eq!(params.x, before);
        // Turned by under a degree: a root still up to noise keeps its poses.
        let (frames, lab0) = turntable(&ARM, |_| DVec3::ZERO);
        let data = Data::new(frames.clone());
        let spin = [0.0, 0.01, -0.01, 0.015];
        let mut params = turntable_params(&frames, &lab0, &spin, |_| DVec3::ZERO);
        let before = params.x.clone();
        assert_eq!(hold_spinning_root(&data, &mut params), 0);
        assert_eq!(params.x, before);
    }
}
