//! Limited-memory BFGS on the exact W, with the constant global-step matrix as the initial
//! inverse Hessian (the quasi-Newton projective dynamics of Liu, Bouaziz & Kavan 2017, here on
//! the spacetime objective). Each direction costs one solve with the factorization the
//! local/global iteration already has. Vectors are flat: the keyframe unknowns' coordinates,
//! then the interval lengths when the key times are optimized too (the curvature pairs then
//! carry the coupling of times and keys: a secant update across timing steps).

use std::collections::VecDeque;

pub(super) fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

fn axpy(alpha: f64, x: &[f64], y: &mut [f64]) {
    for (yi, xi) in y.iter_mut().zip(x) {
        *yi += alpha * xi;
    }
}

/// The curvature pairs of the last few steps.
#[derive(Debug, Clone)]
pub struct Lbfgs {
    memory: usize,
    /// (s, y, 1 / yᵀs), newest last.
    pairs: VecDeque<(Vec<f64>, Vec<f64>, f64)>,
}

impl Lbfgs {
    pub fn new(memory: usize) -> Lbfgs {
        Lbfgs { memory, pairs: VecDeque::with_capacity(memory) }
    }

    /// Record a step `s = q₊ - q` and gradient change `y = g₊ - g`; pairs without positive
    /// curvature are skipped so the implied Hessian stays positive definite.
    pub fn push(&mut self, s: Vec<f64>, y: Vec<f64>) {
        let sy = dot(&s, &y);
        // Written so that NaN curvature is also skipped.
        let positive_curvature = sy > 1e-12 * dot(&s, &s).sqrt() * dot(&y, &y).sqrt();
        if !positive_curvature {
            return;
        }
        if self.pairs.len() == self.memory {
            self.pairs.pop_front();
        }
        self.pairs.push_back((s, y, 1.0 / sy));
    }

    pub fn clear(&mut self) {
        self.pairs.clear();
    }

    pub fn is_empty(&self) -> bool {
        self.pairs.is_empty()
    }

    /// The descent direction `-H g` by the two-loop recursion, with `H₀` applied by
    /// `precondition` (in place).
    pub fn direction(&self, g: &[f64], precondition: impl Fn(&mut [f64])) -> Vec<f64> {
        let mut q = g.to_vec();
        let mut alphas = Vec::with_capacity(self.pairs.len());
        for (s, y, rho) in self.pairs.iter().rev() {
            let a = rho * dot(s, &q);
            axpy(-a, y, &mut q);
            alphas.push(a);
        }
        precondition(&mut q);
        for ((s, y, rho), a) in self.pairs.iter().zip(alphas.iter().rev()) {
            let b = rho * dot(y, &q);
            axpy(a - b, s, &mut q);
        }
        q.iter_mut().for_each(|v| *v = -*v);
        q
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn minimizes_a_quadratic_in_at_most_its_dimension_plus_one_steps() {
        // W = ½ xᵀ A x - bᵀ x with a diagonal A on 6 unknowns; H₀ = I.
        let a = [4.0, 1.0, 9.0, 2.0, 3.0, 0.5];
        let b = [1.0, -2.0, 0.5, 3.0, -1.0, 2.0];
        let grad = |x: &[f64]| -> Vec<f64> { (0..6).map(|i| a[i] * x[i] - b[i]).collect() };
        let mut x = vec![0.0; 6];
        let mut lbfgs = Lbfgs::new(10);
        let mut g = grad(&x);
        for _ in 0..7 {
            if dot(&g, &g).sqrt() < 1e-12 {
                break;
            }
            let d = lbfgs.direction(&g, |_| {});
            // Exact line search on the quadratic.
            let ad: Vec<f64> = (0..6).map(|i| a[i] * d[i]).collect();
            let t = -dot(&g, &d) / dot(&d, &ad);
            let s: Vec<f64> = d.iter().map(|v| v * t).collect();
            axpy(1.0, &s, &mut x);
            let g_new = grad(&x);
            let y: Vec<f64> = g_new.iter().zip(&g).map(|(p, q)| p - q).collect();
            lbfgs.push(s, y);
            g = g_new;
        }
        assert!(dot(&g, &g).sqrt() < 1e-10, "gradient {g:?}");
    }
}
