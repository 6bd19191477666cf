//! The dynamic Gaussian model: parameters (shared log-scales, per-frame 6D rotations
//! and centres), per-frame evaluated Gaussians, Mahalanobis distances, hard
//! segmentation, the rigid transfer H_{k→t} and the gradient accumulator that
//! collects dL/dR, dL/dμ, dL/dlog s and maps them back to the flat parameters.

use crate::math::Libm;
use glam::{DMat3, DMat4, DVec3, Vec3};

use super::rot6d;
use crate::pipeline::Snapshot;

/// Public f32 model (API shared with the rest of the pipeline and the page).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct GaussianModel {
    pub m: usize,
    pub frames: usize,
    /// Per Gaussian, natural log of the three standard deviations.
    pub log_scale: Vec<[f32; 3]>,
    /// Per frame k and Gaussian i at [k*m+i]: 6D rotation.
    pub rot6d: Vec<[f32; 6]>,
    /// Per frame k and Gaussian i at [k*m+i]: centre.
    pub center: Vec<[f32; 3]>,
}

impl GaussianModel {
    /// Part pose T_i^k = [R_i^k | μ_i^k] (local Gaussian frame → world at frame k).
    pub fn pose(&self, k: usize, i: usize) -> DMat4 {
        let g = self.gauss(k, i);
        DMat4::from_cols(
            g.r.x_axis.extend(0.0),
            g.r.y_axis.extend(0.0),
            g.r.z_axis.extend(0.0),
            g.mu.extend(1.0),
        )
    }

    fn gauss(&self, k: usize, i: usize) -> Gauss {
        let j = k * self.m + i;
        let a: Vec<f64> = self.rot6d[j].iter().map(|&v| v as f64).collect();
        let c = self.center[j];
        let s = self.log_scale[i];
        Gauss::new(
            rot6d::to_matrix(&a),
            DVec3::new(c[0] as f64, c[1] as f64, c[2] as f64),
            DVec3::new(s[0] as f64, s[1] as f64, s[2] as f64),
        )
    }

    /// Evaluated Gaussians of frame k.
    pub fn frame_gaussians(&self, k: usize) -> Vec<Gauss> {
        (0..self.m).map(|i| self.gauss(k, i)).collect()
    }

    /// Hard segmentation of `points` at frame k: index of the Gaussian with the
    /// smallest squared Mahalanobis distance.
    pub fn segment(&self, k: usize, points: &[Vec3]) -> Vec<u32> {
        let gs = self.frame_gaussians(k);
        points
            .iter()
            .map(|p| argmin_maha(&gs, p.as_dvec3()).0 as u32)
            .collect()
    }

    /// A display snapshot of frame k with the labels of `points`.
    pub fn snapshot(&self, k: usize, points: &[Vec3]) -> Snapshot {
        let gs = self.frame_gaussians(k);
        let mut s = Snapshot {
            frame: k,
            centers: Vec::with_capacity(self.m * 3),
            rotations: Vec::with_capacity(self.m * 9),
            scales: Vec::with_capacity(self.m * 3),
            labels: points
                .iter()
                .map(|p| argmin_maha(&gs, p.as_dvec3()).0 as u32)
                .collect(),
        };
        for g in &gs {
            s.centers.extend(g.mu.to_array().map(|v| v as f32));
            // Row-major 3×3.
            let rt = g.r.transpose().to_cols_array();
            s.rotations.extend(rt.map(|v| v as f32));
            s.scales
                .extend((DVec3::ONE / g.inv_s).to_array().map(|v| v as f32));
        }
        s
    }
}

/// One Gaussian evaluated at one frame.
#[derive(Debug, Clone, Copy)]
pub struct Gauss {
    pub r: DMat3,
    pub mu: DVec3,
    pub inv_s: DVec3,
    /// Σ_a log s_a (= ½ log det Σ).
    pub log_s_sum: f64,
}

impl Gauss {
    pub fn new(r: DMat3, mu: DVec3, log_s: DVec3) -> Self {
        Gauss {
            r,
            mu,
            inv_s: DVec3::new((-log_s.x).lexp(), (-log_s.y).lexp(), (-log_s.z).lexp()),
            log_s_sum: log_s.x + log_s.y + log_s.z,
        }
    }

    /// Squared Mahalanobis distance of x and the local coordinates y = Rᵀ(x − μ).
    #[inline]
    pub fn maha(&self, x: DVec3) -> (f64, DVec3) {
        let y = self.r.transpose() * (x - self.mu);
        let z = y * self.inv_s;
        (z.dot(z), y)
    }
}

/// (argmin i, its squared Mahalanobis distance).
#[inline]
pub fn argmin_maha(gs: &[Gauss], x: DVec3) -> (usize, f64) {
    let mut best = (0, f64::INFINITY);
    for (i, g) in gs.iter().enumerate() {
        let (m, _) = g.maha(x);
        if m < best.1 {
            best = (i, m);
        }
    }
    best
}

/// Offsets of the parameter blocks in the flat parameter vector.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Layout {
    pub m: usize,
    pub frames: usize,
}

impl Layout {
    #[inline]
    pub fn ls(&self, i: usize) -> usize {
        3 * i
    }
    #[inline]
    pub fn rot(&self, k: usize, i: usize) -> usize {
        3 * self.m + 6 * (k * self.m + i)
    }
    #[inline]
    pub fn cen(&self, k: usize, i: usize) -> usize {
        3 * self.m + 6 * self.frames * self.m + 3 * (k * self.m + i)
    }
    pub fn len(&self) -> usize {
        3 * self.m + 9 * self.frames * self.m
    }
    pub fn is_empty(&self) -> bool {
        self.m == 0
    }
}

/// f64 parameters the optimiser works on (flat, see [`Layout`]).
#[derive(Debug, Clone)]
pub struct Params {
    pub layout: Layout,
    pub x: Vec<f64>,
}

impl Params {
    pub fn new(m: usize, frames: usize) -> Self {
        let layout = Layout { m, frames };
        let mut x = vec![0.0; layout.len()];
        for k in 0..frames {
            for i in 0..m {
                let o = layout.rot(k, i);
                x[o..o + 6].copy_from_slice(&rot6d::IDENTITY_6D);
            }
        }
        Params { layout, x }
    }

    pub fn log_scale(&self, i: usize) -> DVec3 {
        let o = self.layout.ls(i);
        DVec3::new(self.x[o], self.x[o + 1], self.x[o + 2])
    }

    pub fn center(&self, k: usize, i: usize) -> DVec3 {
        let o = self.layout.cen(k, i);
        DVec3::new(self.x[o], self.x[o + 1], self.x[o + 2])
    }

    pub fn set_center(&mut self, k: usize, i: usize, c: DVec3) {
        let o = self.layout.cen(k, i);
        self.x[o..o + 3].copy_from_slice(&c.to_array());
    }

    pub fn set_log_scale(&mut self, i: usize, s: DVec3) {
        let o = self.layout.ls(i);
        self.x[o..o + 3].copy_from_slice(&s.to_array());
    }

    pub fn gauss(&self, k: usize, i: usize) -> Gauss {
        let o = self.layout.rot(k, i);
        Gauss::new(
            rot6d::to_matrix(&self.x[o..o + 6]),
            self.center(k, i),
            self.log_scale(i),
        )
    }

    /// Evaluates the Gaussians of frame k into `out` (length m).
    pub fn frame_into(&self, k: usize, out: &mut Vec<Gauss>) {
        out.clear();
        out.extend((0..self.layout.m).map(|i| self.gauss(k, i)));
    }

    /// Copies frame `src`'s rotations and centres to every frame.
    pub fn broadcast_frame(&mut self, src: usize) {
        let l = self.layout;
        for k in 0..l.frames {
            if k == src {
                continue;
            }
            for i in 0..l.m {
                let (a, b) = (l.rot(src, i), l.rot(k, i));
                let v: [f64; 6] = self.x[a..a + 6].try_into().unwrap_or(rot6d::IDENTITY_6D);
                self.x[b..b + 6].copy_from_slice(&v);
                let c = self.center(src, i);
                self.set_center(k, i, c);
            }
        }
    }

    pub fn to_model(&self) -> GaussianModel {
        let l = self.layout;
        let f = |o: usize, n: usize| -> Vec<f32> {
            self.x[o..o + n].iter().map(|&v| v as f32).collect()
        };
        let mut g = GaussianModel {
            m: l.m,
            frames: l.frames,
            log_scale: Vec::with_capacity(l.m),
            rot6d: Vec::with_capacity(l.m * l.frames),
            center: Vec::with_capacity(l.m * l.frames),
        };
        for i in 0..l.m {
            let v = f(l.ls(i), 3);
            g.log_scale.push([v[0], v[1], v[2]]);
        }
        for k in 0..l.frames {
            for i in 0..l.m {
                let r = f(l.rot(k, i), 6);
                g.rot6d.push([r[0], r[1], r[2], r[3], r[4], r[5]]);
                let c = f(l.cen(k, i), 3);
                g.center.push([c[0], c[1], c[2]]);
            }
        }
        g
    }
}

/// Accumulates gradients w.r.t. the evaluated quantities (R, μ per frame and
/// Gaussian, log s per Gaussian) and maps them to the flat parameters.
#[derive(Debug, Clone)]
pub struct GradAcc {
    pub layout: Layout,
    pub d_r: Vec<DMat3>,
    pub d_mu: Vec<DVec3>,
    pub d_ls: Vec<DVec3>,
}

impl GradAcc {
    pub fn new(layout: Layout) -> Self {
        let n = layout.m * layout.frames;
        GradAcc {
            layout,
            d_r: vec![DMat3::ZERO; n],
            d_mu: vec![DVec3::ZERO; n],
            d_ls: vec![DVec3::ZERO; layout.m],
        }
    }

    pub fn zero(&mut self) {
        self.d_r.iter_mut().for_each(|v| *v = DMat3::ZERO);
        self.d_mu.iter_mut().for_each(|v| *v = DVec3::ZERO);
        self.d_ls.iter_mut().for_each(|v| *v = DVec3::ZERO);
    }

    #[inline]
    pub fn idx(&self, k: usize, i: usize) -> usize {
        k * self.layout.m + i
    }

    /// Backward of M = |Rᵀ(x − μ) ⊙ inv_s|² for Gaussian (k, i) given dL/dM;
    /// returns dL/dx (for when x itself depends on parameters).
    #[inline]
    pub fn maha_backward(
        &mut self,
        k: usize,
        i: usize,
        g: &Gauss,
        x: DVec3,
        y: DVec3,
        gm: f64,
    ) -> DVec3 {
        let z = y * g.inv_s;
        let gy = z * g.inv_s * (2.0 * gm);
        let d = x - g.mu;
        let j = self.idx(k, i);
        self.d_r[j] += outer(d, gy);
        let gx = g.r * gy;
        self.d_mu[j] -= gx;
        self.d_ls[i] += z * z * (-2.0 * gm);
        gx
    }

    /// Backward of the transfer x_t = R_t y + μ_t with y = R_kᵀ(x − μ_k) for the
    /// point's Gaussian i, given dL/dx_t.
    #[inline]
    #[allow(clippy::too_many_arguments)]
    pub fn transfer_backward(
        &mut self,
        k: usize,
        t: usize,
        i: usize,
        src: &TransferSrc,
        gk: &Gauss,
        gt: &Gauss,
        g: DVec3,
    ) {
        let jt = self.idx(t, i);
        self.d_r[jt] += outer(g, src.y);
        self.d_mu[jt] += g;
        let gy = gt.r.transpose() * g;
        let jk = self.idx(k, i);
        self.d_r[jk] += outer(src.d, gy);
        self.d_mu[jk] -= gk.r * gy;
    }

    /// Writes dL/dθ for the flat parameters (overwrites `out`).
    pub fn to_flat(&self, params: &Params, out: &mut [f64]) {
        let l = self.layout;
        out.iter_mut().for_each(|v| *v = 0.0);
        for i in 0..l.m {
            let o = l.ls(i);
            out[o..o + 3].copy_from_slice(&self.d_ls[i].to_array());
        }
        for k in 0..l.frames {
            for i in 0..l.m {
                let j = self.idx(k, i);
                let o = l.rot(k, i);
                if self.d_r[j] != DMat3::ZERO {
                    rot6d::backward(&params.x[o..o + 6], &self.d_r[j], &mut out[o..o + 6]);
                }
                let c = l.cen(k, i);
                out[c..c + 3].copy_from_slice(&self.d_mu[j].to_array());
            }
        }
    }
}

/// a bᵀ as a column-major matrix (column c = a · b_c).
#[inline]
pub fn outer(a: DVec3, b: DVec3) -> DMat3 {
    DMat3::from_cols(a * b.x, a * b.y, a * b.z)
}

/// A source point prepared for transfer: its label, local coordinates and offset
/// from its Gaussian's centre at the source frame.
#[derive(Debug, Clone, Copy, Default)]
pub struct TransferSrc {
    pub label: u32,
    pub y: DVec3,
    pub d: DVec3,
}

impl TransferSrc {
    /// Segments x with the frame's Gaussians and records the transfer data.
    #[inline]
    pub fn new(gs: &[Gauss], x: DVec3) -> Self {
        let (i, _) = argmin_maha(gs, x);
        let g = &gs[i];
        let d = x - g.mu;
        TransferSrc {
            label: i as u32,
            y: g.r.transpose() * d,
            d,
        }
    }

    /// Position at the target frame given the target frame's Gaussians.
    #[inline]
    pub fn moved(&self, gt: &[Gauss]) -> DVec3 {
        let g = &gt[self.label as usize];
        g.r * self.y + g.mu
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn transfer_matches_pose_formula() {
        let mut p = Params::new(2, 2);
        let l = p.layout;
        p.x[l.rot(1, 0)..l.rot(1, 0) + 6].copy_from_slice(&[0.8, 0.6, 0.0, -0.6, 0.8, 0.1]);
        p.set_center(1, 0, DVec3::new(0.1, 0.2, 0.3));
        p.set_center(0, 1, DVec3::new(5.0, 0.0, 0.0));
        p.set_center(1, 1, DVec3::new(5.0, 0.0, 0.0));
        let model = p.to_model();
        let x = DVec3::new(0.3, -0.2, 0.1);
        let g0: Vec<Gauss> = (0..2).map(|i| p.gauss(0, i)).collect();
        let g1: Vec<Gauss> = (0..2).map(|i| p.gauss(1, i)).collect();
        let src = TransferSrc::new(&g0, x);
        assert_eq!(src.label, 0);
        let via_pose = model.pose(1, 0) * crate::geom::se3::rigid_inverse(&model.pose(0, 0));
        let a = via_pose.transform_point3(x);
        assert!((a - src.moved(&g1)).length() < 1e-6);
        assert_eq!(
            model.segment(0, &[x.as_vec3(), Vec3::new(5.0, 0.1, 0.0)]),
            vec![0, 1]
        );
    }
}
