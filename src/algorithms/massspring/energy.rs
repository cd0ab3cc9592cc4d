//! The elastic energy of a spring network, its gradient and its stiffness (Hessian) blocks.
//!
//! One spring `q` joins vertices `i < j` with rest length `r` and constant `k`:
//!
//! ```text
//! E_q = k/2 (l - r)²,   d = x_i - x_j,  l = |d|,  u = d / l
//! ∂E_q/∂x_i = k (l - r) u = -∂E_q/∂x_j                       (minus the force on i)
//! ∂²E_q/∂x_i² = k [ u uᵀ + (1 - r/l) (I - u uᵀ) ] =: K_q
//! ∂²E_q/∂x_i∂x_j = -K_q,   ∂²E_q/∂x_j² = K_q
//! ```
//!
//! (The paper's eq. 5 is this `K_q` garbled by extraction: `k (1 - r/l) I + k (r/l) u uᵀ`
//! is the same matrix.) Along the spring `K_q` has the eigenvalue `k`; across it, `k (1 - r/l)`
//! twice, which is negative when the spring is compressed (`l < r`): a compressed spring
//! buckles sideways, and the assembled stiffness is then indefinite. [`Definiteness::Clamped`]
//! replaces that transverse coefficient by `max(0, 1 - r/l)`, which makes every spring block
//! positive semi-definite (the smallest change that does, in the Frobenius norm) and leaves
//! stretched springs exact; near an equilibrium the clamped amount `k (r/l - 1)` is of the
//! order of the strain, so Newton keeps converging fast, and [`super::newton`] switches to the
//! exact matrix once the steps are small.

use crate::algorithms::geometry::{dot, norm, sub, Point};
use crate::algorithms::physics::mat3::Mat3;

/// The springs of a system with their current rest lengths and constants, one entry each.
#[derive(Debug, Clone, Copy)]
pub struct SpringSystem<'a> {
    /// `[i, j]` with `i < j`.
    pub ends: &'a [[u32; 2]],
    /// Rest length `r` of each spring, in the mesh's units.
    pub rest: &'a [f64],
    /// Spring constant `k` of each spring.
    pub stiffness: &'a [f64],
}

/// How the transverse stiffness of compressed springs enters the Hessian.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Definiteness {
    /// The exact Hessian (indefinite where springs are compressed).
    Exact,
    /// Transverse coefficient `max(0, 1 - r/l)`: positive semi-definite.
    Clamped,
}

/// A spring shorter than this fraction of its rest length counts as collapsed: its direction is
/// undefined (the energy is not differentiable at length 0).
const MIN_LENGTH_FRACTION: f64 = 1e-12;

/// Energy of one spring.
#[inline]
pub(crate) fn spring_energy(d: Point, rest: f64, k: f64) -> f64 {
    let e = norm(d) - rest;
    0.5 * k * e * e
}

/// `∂E_q/∂x_i` of one spring with `d = x_i - x_j`.
#[inline]
pub(crate) fn spring_gradient(d: Point, rest: f64, k: f64) -> Point {
    let l = norm(d);
    if l == 0.0 {
        // No direction: a spring of rest length 0 has no force, any other one is at a kink.
        return [0.0; 3];
    }
    let s = k * (1.0 - rest / l);
    [s * d[0], s * d[1], s * d[2]]
}

/// The block `K_q = ∂²E_q/∂x_i²` of one spring with `d = x_i - x_j` (symmetric).
#[inline]
pub(crate) fn spring_hessian(d: Point, rest: f64, k: f64, definiteness: Definiteness) -> Mat3 {
    let l = dot(d, d).sqrt();
    if l <= MIN_LENGTH_FRACTION * rest || l == 0.0 {
        // Rest length 0 (a harmonic system, exactly k I) or a collapsed spring, whose exact
        // Hessian has no direction and a transverse part -> -inf: k I keeps it positive.
        return [[k, 0.0, 0.0], [0.0, k, 0.0], [0.0, 0.0, k]];
    }
    let mut transverse = 1.0 - rest / l;
    if definiteness == Definiteness::Clamped {
        transverse = transverse.max(0.0);
    }
    // k [ t I + (1 - t) u uᵀ ]
    let a = k * transverse;
    let b = k * (1.0 - transverse) / (l * l);
    let mut h = [[0.0; 3]; 3];
    for r in 0..3 {
        for c in 0..3 {
            h[r][c] = b * d[r] * d[c];
        }
        h[r][r] += a;
    }
    h
}

impl SpringSystem<'_> {
    /// Total energy at `x` (summed in spring order: the same bytes every run).
    pub fn energy(&self, x: &[Point]) -> f64 {
        let mut e = 0.0;
        for (q, &[i, j]) in self.ends.iter().enumerate() {
            e += spring_energy(sub(x[i as usize], x[j as usize]), self.rest[q], self.stiffness[q]);
        }
        e
    }

    /// `∂E/∂x` into `g` (overwritten).
    pub fn gradient(&self, x: &[Point], g: &mut [Point]) {
        g.fill([0.0; 3]);
        for (q, &[i, j]) in self.ends.iter().enumerate() {
            let (i, j) = (i as usize, j as usize);
            let f = spring_gradient(sub(x[i], x[j]), self.rest[q], self.stiffness[q]);
            for c in 0..3 {
                g[i][c] += f[c];
                g[j][c] -= f[c];
            }
        }
    }

    /// The assembled Hessian applied to `v`: `out = H v` (tests and diagnostics).
    pub fn hessian_apply(&self, x: &[Point], v: &[Point], definiteness: Definiteness, out: &mut [Point]) {
        out.fill([0.0; 3]);
        for (q, &[i, j]) in self.ends.iter().enumerate() {
            let (i, j) = (i as usize, j as usize);
            let h = spring_hessian(sub(x[i], x[j]), self.rest[q], self.stiffness[q], definiteness);
            let dv = sub(v[i], v[j]);
            for r in 0..3 {
                let hv = h[r][0] * dv[0] + h[r][1] * dv[1] + h[r][2] * dv[2];
                out[i][r] += hv;
                out[j][r] -= hv;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::algorithms::massspring::testing::hessian_columns;
    use crate::support::testing::Rng;

    /// Central differences of `f` along coordinate `c` of vertex `v`.
    fn central(x: &[Point], v: usize, c: usize, h: f64, f: impl Fn(&[Point]) -> f64) -> f64 {
        let (mut xp, mut xm) = (x.to_vec(), x.to_vec());
        xp[v][c] += h;
        xm[v][c] -= h;
        (f(&xp) - f(&xm)) / (2.0 * h)
    }

    #[test]
    fn single_spring_gradient_and_hessian_match_finite_differences() {
        let mut rng = Rng::new(7);
        for case in 0..200 {
            let d = [rng.uniform(-1.0, 1.0), rng.uniform(-1.0, 1.0), rng.uniform(-1.0, 1.0)];
            let l = norm(d);
            // Stretched, compressed and near-rest springs.
            let rest = l * [0.5, 1.5, 1.0 + 1e-3, 0.999][case % 4];
            let k = rng.uniform(0.1, 3.0);
            let e = |d: Point| spring_energy(d, rest, k);
            let g = spring_gradient(d, rest, k);
            let h = spring_hessian(d, rest, k, Definiteness::Exact);
            let step = 1e-6;
            for c in 0..3 {
                let (mut dp, mut dm) = (d, d);
                dp[c] += step;
                dm[c] -= step;
                let fd = (e(dp) - e(dm)) / (2.0 * step);
                assert!((fd - g[c]).abs() <= 1e-7 * (1.0 + g[c].abs()), "case {case}: dE/dd{c} {} vs {fd}", g[c]);
                let (gp, gm) = (spring_gradient(dp, rest, k), spring_gradient(dm, rest, k));
                for r in 0..3 {
                    let fd = (gp[r] - gm[r]) / (2.0 * step);
                    assert!((fd - h[r][c]).abs() <= 1e-6 * (1.0 + h[r][c].abs()), "case {case}: H[{r}][{c}] {} vs {fd}", h[r][c]);
                }
            }
        }
    }

    #[test]
    fn transverse_eigenvalue_is_negative_exactly_when_compressed_and_clamping_removes_it() {
        let d = [0.3, -0.4, 1.2];
        let l = norm(d);
        let across = [0.4, 0.3, 0.0]; // perpendicular to d
        let quad = |h: &Mat3, v: Point| (0..3).map(|r| v[r] * (0..3).map(|c| h[r][c] * v[c]).sum::<f64>()).sum::<f64>();
        for (rest, negative) in [(1.5 * l, true), (0.5 * l, false)] {
            let exact = spring_hessian(d, rest, 2.0, Definiteness::Exact);
            let clamped = spring_hessian(d, rest, 2.0, Definiteness::Clamped);
            let expected = 2.0 * (1.0 - rest / l) * dot(across, across);
            assert!((quad(&exact, across) - expected).abs() < 1e-12);
            assert_eq!(quad(&exact, across) < 0.0, negative);
            assert!(quad(&clamped, across) >= 0.0);
            // Along the spring both are k.
            let u = [d[0] / l, d[1] / l, d[2] / l];
            assert!((quad(&exact, u) - 2.0).abs() < 1e-12 && (quad(&clamped, u) - 2.0).abs() < 1e-12);
            if !negative {
                assert_eq!(exact, clamped, "a stretched spring is not modified");
            }
        }
    }

    /// A small random network (a jittered grid with diagonals): the assembled gradient and
    /// Hessian of the whole system against central differences of the energy and gradient.
    #[test]
    fn system_gradient_and_hessian_match_finite_differences() {
        let mut rng = Rng::new(11);
        let n = 12;
        let x: Vec<Point> = (0..n).map(|_| [rng.uniform(0.0, 1.0), rng.uniform(0.0, 1.0), rng.uniform(0.0, 1.0)]).collect();
        let mut ends = Vec::new();
        for i in 0..n as u32 {
            for j in i + 1..n as u32 {
                if (i + 2 * j) % 3 != 0 {
                    ends.push([i, j]);
                }
            }
        }
        let rest: Vec<f64> = ends.iter().map(|&[i, j]| norm(sub(x[i as usize], x[j as usize])) * rng.uniform(0.6, 1.4)).collect();
        let stiffness: Vec<f64> = rest.iter().map(|r| 1.0 / r).collect();
        let sys = SpringSystem { ends: &ends, rest: &rest, stiffness: &stiffness };
        let mut g = vec![[0.0; 3]; n];
        sys.gradient(&x, &mut g);
        let h = 1e-6;
        for v in 0..n {
            for c in 0..3 {
                let fd = central(&x, v, c, h, |y| sys.energy(y));
                assert!((fd - g[v][c]).abs() < 1e-7 * (1.0 + g[v][c].abs()), "dE/dx[{v}][{c}]: {} vs {fd}", g[v][c]);
            }
        }
        // Column (v, c) of H = d g / d x[v][c].
        hessian_columns(&sys, &x, Definiteness::Exact, |v, c, hv| {
            let (mut xp, mut xm) = (x.clone(), x.clone());
            xp[v][c] += h;
            xm[v][c] -= h;
            let (mut gp, mut gm) = (vec![[0.0; 3]; n], vec![[0.0; 3]; n]);
            sys.gradient(&xp, &mut gp);
            sys.gradient(&xm, &mut gm);
            for w in 0..n {
                for r in 0..3 {
                    let fd = (gp[w][r] - gm[w][r]) / (2.0 * h);
                    assert!((fd - hv[w][r]).abs() < 1e-6 * (1.0 + hv[w][r].abs()), "H[({w},{r}),({v},{c})]: {} vs {fd}", hv[w][r]);
                }
            }
        });
    }

    #[test]
    fn rigid_motion_costs_no_energy_and_no_force() {
        let mut rng = Rng::new(3);
        let x: Vec<Point> = (0..6).map(|_| [rng.uniform(0.0, 1.0), rng.uniform(0.0, 1.0), rng.uniform(0.0, 1.0)]).collect();
        let ends: Vec<[u32; 2]> = (0..6u32).flat_map(|i| (i + 1..6).map(move |j| [i, j])).collect();
        let rest: Vec<f64> = ends.iter().map(|&[i, j]| norm(sub(x[i as usize], x[j as usize]))).collect();
        let stiffness: Vec<f64> = rest.iter().map(|r| 1.0 / r).collect();
        let sys = SpringSystem { ends: &ends, rest: &rest, stiffness: &stiffness };
        let (s, c) = 1.1f64.sin_cos();
        let moved: Vec<Point> = x.iter().map(|p| [c * p[0] - s * p[2] + 3.0, p[1] - 2.0, s * p[0] + c * p[2]]).collect();
        assert!(sys.energy(&moved) < 1e-28);
        let mut g = vec![[0.0; 3]; 6];
        sys.gradient(&moved, &mut g);
        assert!(g.iter().flatten().all(|v| v.abs() < 1e-13), "{g:?}");
    }
}
