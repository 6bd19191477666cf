//! Adam (Kingma & Ba) on a flat f64 parameter vector, PyTorch's defaults
//! (β1 = 0.9, β2 = 0.999, ε = 1e-8). One optimiser is shared by the two
//! alternating steps of an iteration, as a single PyTorch optimiser would be.

#[derive(Debug, Clone)]
pub struct Adam {
    pub lr: f64,
    pub beta1: f64,
    pub beta2: f64,
    pub eps: f64,
    m: Vec<f64>,
    v: Vec<f64>,
    t: i32,
}

impl Adam {
    pub fn new(n: usize, lr: f64) -> Self {
        Adam {
            lr,
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-8,
            m: vec![0.0; n],
            v: vec![0.0; n],
            t: 0,
        }
    }

    /// Forgets the moments (used after the warm-up).
    pub fn reset(&mut self) {
        self.m.iter_mut().for_each(|v| *v = 0.0);
        self.v.iter_mut().for_each(|v| *v = 0.0);
        self.t = 0;
    }

    /// One update x ← x − lr · m̂ / (√v̂ + ε). Non-finite gradients are skipped
    /// (treated as zero) so one degenerate point cannot poison the parameters.
    pub fn step(&mut self, x: &mut [f64], g: &[f64]) {
        self.t = self.t.saturating_add(1);
        let b1t = 1.0 - self.beta1.powi(self.t);
        let b2t = 1.0 - self.beta2.powi(self.t);
        for j in 0..x.len() {
            let gj = if g[j].is_finite() { g[j] } else { 0.0 };
            self.m[j] = self.beta1 * self.m[j] + (1.0 - self.beta1) * gj;
            self.v[j] = self.beta2 * self.v[j] + (1.0 - self.beta2) * gj * gj;
            let mh = self.m[j] / b1t;
            let vh = self.v[j] / b2t;
            x[j] -= self.lr * mh / (vh.sqrt() + self.eps);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn minimises_a_quadratic() {
        let mut x = vec![3.0, -2.0];
        let mut a = Adam::new(2, 0.05);
        for _ in 0..2000 {
            let g = vec![2.0 * (x[0] - 1.0), 8.0 * (x[1] + 0.5)];
            a.step(&mut x, &g);
        }
        assert!(
            (x[0] - 1.0).abs() < 1e-2 && (x[1] + 0.5).abs() < 1e-2,
            "{x:?}"
        );
    }
}
