//! Limited-memory BFGS on the exact W, with the constant global-step matrix as the initial
//! inverse Hessian (the quasi-Newton projective dynamics of Liu, Bouaziz & Kavan 2017, here on
//! the spacetime objective). Each direction costs one solve with the factorization the
//! local/global iteration already has.

use std::collections::VecDeque;

use crate::mesh::Point;

fn dot(a: &[Point], b: &[Point]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x[0] * y[0] + x[1] * y[1] + x[2] * y[2]).sum()
}

fn axpy(alpha: f64, x: &[Point], y: &mut [Point]) {
    for (yi, xi) in y.iter_mut().zip(x) {
        for d in 0..3 {
            yi[d] += alpha * xi[d];
        }
    }
}

/// The curvature pairs of the last few steps.
#[derive(Debug, Clone)]
pub struct Lbfgs {
    memory: usize,
    /// (s, y, 1 / yᵀs), newest last.
    pairs: VecDeque<(Vec<Point>, Vec<Point>, f64)>,
}

impl Lbfgs {
    pub fn new(memory: usize) -> Lbfgs {
        Lbfgs { memory, pairs: VecDeque::with_capacity(memory) }
    }

    /// Record a step `s = q₊ - q` and gradient change `y = g₊ - g`; pairs without positive
    /// curvature are skipped so the implied Hessian stays positive definite.
    pub fn push(&mut self, s: Vec<Point>, y: Vec<Point>) {
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
    pub fn direction(&self, g: &[Point], precondition: impl Fn(&mut [Point])) -> Vec<Point> {
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
        q.iter_mut().for_each(|v| *v = [-v[0], -v[1], -v[2]]);
        q
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn minimizes_a_quadratic_in_at_most_its_dimension_plus_one_steps() {
        // W = ½ xᵀ A x - bᵀ x on 2 "points" (6 unknowns) with a diagonal A; H₀ = I.
        let a = [4.0, 1.0, 9.0, 2.0, 3.0, 0.5];
        let b = [1.0, -2.0, 0.5, 3.0, -1.0, 2.0];
        let grad = |x: &[Point]| -> Vec<Point> {
            (0..2).map(|p| [0, 1, 2].map(|d| a[3 * p + d] * x[p][d] - b[3 * p + d])).collect()
        };
        let mut x = vec![[0.0; 3]; 2];
        let mut lbfgs = Lbfgs::new(10);
        let mut g = grad(&x);
        for _ in 0..7 {
            let d = lbfgs.direction(&g, |_| {});
            // Exact line search on the quadratic.
            let ad: Vec<Point> = (0..2).map(|p| [0, 1, 2].map(|k| a[3 * p + k] * d[p][k])).collect();
            let t = -dot(&g, &d) / dot(&d, &ad);
            let s: Vec<Point> = d.iter().map(|v| v.map(|c| c * t)).collect();
            axpy(1.0, &s, &mut x);
            let g_new = grad(&x);
            let y: Vec<Point> = g_new.iter().zip(&g).map(|(p, q)| [p[0] - q[0], p[1] - q[1], p[2] - q[2]]).collect();
            lbfgs.push(s, y);
            g = g_new;
        }
        assert!(dot(&g, &g).sqrt() < 1e-10, "gradient {g:?}");
    }
}
