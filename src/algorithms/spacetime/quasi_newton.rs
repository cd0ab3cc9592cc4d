//! Limited-memory BFGS on the exact W, with the constant global-step matrix as the initial
//! inverse Hessian (the quasi-Newton projective dynamics of Liu, Bouaziz & Kavan 2017, here on
//! the spacetime objective). Each direction costs one solve with the factorization the
//! local/global iteration already has. Vectors are flat: the keyframe unknowns' coordinates,
//! then the interval lengths when the key times are optimized too (the curvature pairs then
//! carry the coupling of times and keys: a secant update across timing steps).
//!
//! # The scale of H₀
//!
//! The global step's matrix resists rotating the elements, so it is stiffer than W's Hessian
//! along the slow (bending, twisting) motions, and the preconditioned direction is too short:
//! every accepted step measures the curvature along its direction (`sᵀy / t²` for the step
//! `s = t d`), and with it the step a quadratic model would have taken, `t* = -gᵀd t² / sᵀy`,
//! which is 1.3 to 4.7 on TWIST and the demo (measured, not 1). With `Lbfgs::scaled`, `H₀` is
//! multiplied by the product of these ratios (kept within [`H0_SCALE_RANGE`]), so the next
//! direction's `H₀` part is as long as the last one should have been. Scaling `H₀` leaves the
//! pairs' secant equations intact. It is Shanno and Phua's scaling (Nocedal & Wright, eq. 7.20,
//! `sᵀy / yᵀH₀y`) measured along the step instead, which costs no solve with `H₀`; both cut the
//! iterations alike where it helps.

use std::collections::VecDeque;

pub(super) fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

fn axpy(alpha: f64, x: &[f64], y: &mut [f64]) {
    for (yi, xi) in y.iter_mut().zip(x) {
        *yi += alpha * xi;
    }
}

/// The range the learned scale of `H₀` is kept in (module documentation).
pub const H0_SCALE_RANGE: (f64, f64) = (0.1, 10.0);

/// The curvature pairs of the last few steps, and the scale of `H₀`.
#[derive(Debug, Clone)]
pub struct Lbfgs {
    memory: usize,
    /// (s, y, 1 / yᵀs), newest last.
    pairs: VecDeque<(Vec<f64>, Vec<f64>, f64)>,
    /// Whether `h0_scale` learns from the steps.
    scaled: bool,
    /// The factor on `H₀`, within [`H0_SCALE_RANGE`]; 1 when not `scaled`. Kept by [`Lbfgs::clear`].
    h0_scale: f64,
}

/// `sᵀy` when the pair has positive curvature (so the implied Hessian stays positive definite);
/// written so that NaN curvature fails too.
fn positive_curvature(s: &[f64], y: &[f64]) -> Option<f64> {
    let sy = dot(s, y);
    (sy > 1e-12 * dot(s, s).sqrt() * dot(y, y).sqrt()).then_some(sy)
}

impl Lbfgs {
    /// Up to `memory` pairs; `scaled`: learn the scale of `H₀` from the steps (module
    /// documentation).
    pub fn new(memory: usize, scaled: bool) -> Lbfgs {
        Lbfgs { memory, pairs: VecDeque::with_capacity(memory), scaled, h0_scale: 1.0 }
    }

    /// The factor `H₀` is multiplied by in [`Lbfgs::direction`].
    #[cfg(test)]
    pub fn h0_scale(&self) -> f64 {
        self.h0_scale
    }

    /// Record a step `s = q₊ - q`, the fraction `t` of the direction it took, the gradient
    /// change `y = g₊ - g` and the gradient `g` at its start; pairs without positive curvature
    /// are skipped so the implied Hessian stays positive definite (and do not rescale `H₀`).
    pub fn push(&mut self, s: Vec<f64>, y: Vec<f64>, t: f64, g: &[f64]) {
        let Some(sy) = positive_curvature(&s, &y) else { return };
        if self.scaled {
            // The step along d = s / t that the curvature sᵀy / t² calls for: -gᵀd t² / sᵀy.
            let best = -dot(g, &s) * t / sy;
            if best.is_finite() && best > 0.0 {
                self.h0_scale = (self.h0_scale * best).clamp(H0_SCALE_RANGE.0, H0_SCALE_RANGE.1);
            }
        }
        self.store(s, y, sy);
    }

    /// Record a step `s` and gradient change `y` (skipped without positive curvature) without
    /// learning `H₀`'s scale from it: for steps that did not come from [`Lbfgs::direction`].
    pub(crate) fn push_pair(&mut self, s: Vec<f64>, y: Vec<f64>) {
        if let Some(sy) = positive_curvature(&s, &y) {
            self.store(s, y, sy);
        }
    }

    /// Keep the pair (with `1 / sᵀy`), dropping the oldest beyond the memory.
    fn store(&mut self, s: Vec<f64>, y: Vec<f64>, sy: f64) {
        if self.pairs.len() == self.memory {
            self.pairs.pop_front();
        }
        self.pairs.push_back((s, y, 1.0 / sy));
    }

    /// Forget every curvature pair (the learned scale of `H₀` is kept).
    pub fn clear(&mut self) {
        self.pairs.clear();
    }

    /// Whether no curvature pair is stored (the direction is then `H₀`'s alone).
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
        if self.h0_scale != 1.0 {
            q.iter_mut().for_each(|v| *v *= self.h0_scale);
        }
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
        let mut lbfgs = Lbfgs::new(10, false);
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
            lbfgs.push(s, y, t, &g);
            g = g_new;
        }
        assert!(dot(&g, &g).sqrt() < 1e-10, "gradient {g:?}");
    }

    /// A preconditioner 1 to 30 times too stiff, spread over the modes (the global step's
    /// matrix is up to about that much stiffer than W's Hessian, module documentation), unit
    /// first steps halved until W decreases (the solver's line search): the learned scale of
    /// `H₀` lengthens the steps and takes fewer iterations than `H₀` as given (measured: 31
    /// against 48, the scale settling at 3.2).
    #[test]
    fn a_learned_h0_scale_takes_fewer_iterations_under_a_too_stiff_preconditioner() {
        let n = 60;
        let a: Vec<f64> = (0..n).map(|i| 100f64.powf(i as f64 / (n - 1) as f64)).collect();
        let stiff: Vec<f64> = (0..n).map(|i| 30f64.powf(((7 * i) % n) as f64 / (n - 1) as f64)).collect();
        let b: Vec<f64> = (0..n).map(|i| (i as f64).cos()).collect();
        let w = |x: &[f64]| -> f64 { (0..n).map(|i| 0.5 * a[i] * x[i] * x[i] - b[i] * x[i]).sum() };
        let w_min = w(&(0..n).map(|i| b[i] / a[i]).collect::<Vec<_>>());
        let run = |scaled: bool| -> (usize, f64) {
            let mut lbfgs = Lbfgs::new(8, scaled);
            let mut x = vec![0.0; n];
            let mut g: Vec<f64> = b.iter().map(|v| -v).collect();
            let w0 = w(&x);
            for k in 1..5000 {
                let d = lbfgs.direction(&g, |q| q.iter_mut().enumerate().for_each(|(i, v)| *v /= stiff[i] * a[i]));
                let wx = w(&x);
                let mut t = 1.0;
                while w(&x.iter().zip(&d).map(|(p, q)| p + t * q).collect::<Vec<_>>()) >= wx {
                    t *= 0.5;
                }
                let s: Vec<f64> = d.iter().map(|v| v * t).collect();
                axpy(1.0, &s, &mut x);
                let g_new: Vec<f64> = (0..n).map(|i| a[i] * x[i] - b[i]).collect();
                let y: Vec<f64> = g_new.iter().zip(&g).map(|(p, q)| p - q).collect();
                lbfgs.push(s, y, t, &g);
                g = g_new;
                if w(&x) - w_min <= 1e-10 * (w0 - w_min) {
                    return (k, lbfgs.h0_scale());
                }
            }
            panic!("no convergence (scaled: {scaled})");
        };
        let (given, unit) = run(false);
        let (learned, scale) = run(true);
        println!("iterations to 1e-10 of the initial gap: H0 as given {given} (scale {unit}), learned {learned} (scale {scale:.3})");
        assert_eq!(unit, 1.0);
        assert!(scale > 1.0 && scale <= H0_SCALE_RANGE.1, "the too-stiff preconditioner is scaled up: {scale}");
        assert!(learned < given, "learned scale {learned} iterations, given {given}");
    }
}
