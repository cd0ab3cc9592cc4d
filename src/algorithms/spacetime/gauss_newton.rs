//! Gauss-Newton steps on W, solved by truncated preconditioned conjugate gradients.
//!
//! W is a sum of squares, `W = Σ_s dτ_s ½ |f_s|²_{M⁻¹}`, so its Gauss-Newton Hessian is
//! `H = Σ_s dτ_s J_sᵀ M⁻¹ J_s` with `J_s = ∂f_s/∂u` the residual's derivative in the keyframe
//! unknowns, projections included: per slot `j` of the sample's interval
//! `∂f_s/∂u_j = c_j M + l_j K_s`, where `K_s = L - J DP_s dF` is the elastic stiffness at the
//! sample (`∇²E`, symmetric: the objective's exact gradient uses the same operator). It is what
//! W's Hessian keeps when the residual's own curvature (`f · ∂²f`) is dropped, positive
//! semidefinite by construction, and the global step's matrix is `H` with `DP = 0` (plus the
//! proximal term): the natural preconditioner, already factorized.
//!
//! `H v` is matrix-free, one pass like the gradient: per sample `δf_s = M δa_s + K_s δx_s`
//! (`δx_s = Σ_j l_j v_j`, `δa_s = Σ_j c_j v_j`, zero at supports), then per slot
//! `Σ_s dτ_s (c_σ δf_s + l_σ K_s M⁻¹ δf_s)`.
//!
//! The step solves `H d = -g` by [`truncated_cg`]: preconditioned CG from `d = 0`, stopped at
//! the Eisenstat-Walker forcing tolerance ([`Forcing`]), after a few iterations, or on
//! non-positive curvature. Every CG iterate is a descent direction of W (CG from zero on a
//! positive definite system), so the solver's line search on W applies unchanged.

use rayon::prelude::*;

use super::objective::{Objective, Projections};
use super::quasi_newton::dot;
use super::sampling::Sample;
use crate::algorithms::geometry::Point;
use crate::algorithms::physics::projection::JacobianBatch;

impl Objective<'_> {
    /// `K_s u = L u - J DP_s[dF(u)]` at one sample (its projection Jacobians `jac`).
    fn sample_stiffness(&self, jac: &[JacobianBatch], u: &[Point]) -> Vec<Point> {
        let el = self.elastic;
        let n = el.node_count();
        let mut lu = vec![[0.0; 3]; n];
        el.stiffness.mul_points_sequential(u, &mut lu);
        let mut jp = vec![[0.0; 3]; n];
        el.apply_jacobians_sequential(jac, u, &mut jp);
        for (a, b) in lu.iter_mut().zip(&jp) {
            for d in 0..3 {
                a[d] -= b[d];
            }
        }
        lu
    }

    /// `δf_s = ∂f_s/∂u · v` at sample `s` (projection Jacobians `jac`) for the per-slot
    /// direction `v` (`[slot][node]`): `M δa + K_s δx`, zero at supports.
    pub(crate) fn residual_derivative(&self, s: &Sample, jac: &[JacobianBatch], v: &[Vec<Point>]) -> Vec<Point> {
        let el = self.elastic;
        let n = el.node_count();
        let (c, l) = self.coefficients(s);
        let (mut dx, mut da) = (vec![[0.0; 3]; n], vec![[0.0; 3]; n]);
        for j in 0..4 {
            let vj = &v[s.slots[j]];
            for a in 0..n {
                for d in 0..3 {
                    dx[a][d] += l[j] * vj[a][d];
                    da[a][d] += c[j] * vj[a][d];
                }
            }
        }
        let mut df = self.sample_stiffness(jac, &dx);
        for a in 0..n {
            if self.supports[a] {
                df[a] = [0.0; 3];
                continue;
            }
            for d in 0..3 {
                df[a][d] += el.mass[a] * da[a][d];
            }
        }
        df
    }

    /// The Gauss-Newton product `H v = Σ_s dτ_s J_sᵀ M⁻¹ J_s v` per slot (fixed entries
    /// included: callers mask them), with the projection Jacobians of `p` (module
    /// documentation). Sums in sample order: the same bytes for any thread count.
    pub(crate) fn gauss_newton_product(&self, p: &Projections, v: &[Vec<Point>]) -> Vec<Vec<Point>> {
        let jacobians = p.jacobians.as_ref().expect("the Gauss-Newton product needs the projection Jacobians");
        let el = self.elastic;
        let n = el.node_count();
        // Per sample: δf and K M⁻¹ δf.
        let per_sample: Vec<(Vec<Point>, Vec<Point>)> = self
            .samples
            .par_iter()
            .zip(jacobians.par_iter())
            .map(|(s, jac)| {
                let df = self.residual_derivative(s, jac, v);
                let scaled: Vec<Point> = df.iter().zip(&el.mass).map(|(f, m)| crate::algorithms::geometry::scale(*f, 1.0 / m)).collect();
                let kf = self.sample_stiffness(jac, &scaled);
                (df, kf)
            })
            .collect();
        (0..self.slots.count())
            .into_par_iter()
            .map(|slot| {
                let mut out = vec![[0.0; 3]; n];
                for (s, (df, kf)) in self.samples.iter().zip(&per_sample) {
                    let (c, l) = self.coefficients(s);
                    let (mut cs, mut ls) = (0.0, 0.0);
                    for j in (0..4).filter(|&j| s.slots[j] == slot) {
                        cs += c[j];
                        ls += l[j];
                    }
                    if cs == 0.0 && ls == 0.0 {
                        continue;
                    }
                    let (cs, ls) = (s.weight * cs, s.weight * ls);
                    for a in 0..n {
                        for d in 0..3 {
                            out[a][d] += cs * df[a][d] + ls * kf[a][d];
                        }
                    }
                }
                out
            })
            .collect()
    }
}

/// The Eisenstat-Walker forcing terms (their "choice 2", with its safeguard): the CG solve of
/// step `k` stops when its residual is below `η_k` times the gradient (in the preconditioner's
/// norm), `η_k = γ (|g_k| / |g_{k-1}|)^α`, kept at least `γ η_{k-1}^α` while that is above 0.1
/// (so one lucky step does not make the next solve needlessly exact) and within
/// [[`Forcing::MIN`], [`Forcing::MAX`]].
#[derive(Debug, Clone)]
pub struct Forcing {
    eta: f64,
    last_gradient: Option<f64>,
}

impl Default for Forcing {
    fn default() -> Forcing {
        Forcing { eta: Forcing::MAX, last_gradient: None }
    }
}

impl Forcing {
    /// The loosest forcing term, and the first step's.
    pub const MAX: f64 = 0.5;
    /// The tightest forcing term.
    pub const MIN: f64 = 1e-3;
    const GAMMA: f64 = 0.9;
    const ALPHA: f64 = 2.0;

    /// The forcing term for a step from a point whose gradient has norm `gradient`.
    pub fn next(&mut self, gradient: f64) -> f64 {
        if let Some(last) = self.last_gradient.filter(|&l| l > 0.0) {
            let mut eta = Self::GAMMA * (gradient / last).powf(Self::ALPHA);
            let safeguard = Self::GAMMA * self.eta.powf(Self::ALPHA);
            if safeguard > 0.1 {
                eta = eta.max(safeguard);
            }
            self.eta = if eta.is_finite() { eta.clamp(Self::MIN, Self::MAX) } else { Self::MAX };
        }
        self.last_gradient = Some(gradient);
        self.eta
    }
}

/// How a truncated CG solve ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CgEnd {
    /// The residual fell below the forcing tolerance.
    Converged,
    /// The iteration cap.
    Capped,
    /// A direction of non-positive curvature (the iterate before it is returned; the
    /// preconditioned steepest descent direction when it is the first).
    NegativeCurvature,
}

/// A truncated CG solve: the direction, the products with `H` it took, and how it ended.
#[derive(Debug, Clone)]
pub struct TruncatedCg {
    /// The approximate solution `d` of `H d = -g` (a descent direction).
    pub direction: Vec<f64>,
    /// Products with `H` taken.
    pub products: usize,
    /// Why the solve stopped.
    pub end: CgEnd,
}

/// Solve `H d = -g` approximately by preconditioned CG from `d = 0`: `h(v)` is `H v`,
/// `precondition(r)` applies `P⁻¹` in place (positive definite); stop when
/// `|r|_{P⁻¹} <= forcing |g|_{P⁻¹}`, after `max_iterations` products, or when a search
/// direction has non-positive curvature. Every iterate satisfies `gᵀd < 0` (for `g ≠ 0`).
pub fn truncated_cg(
    h: impl Fn(&[f64]) -> Vec<f64>,
    precondition: impl Fn(&mut [f64]),
    g: &[f64],
    forcing: f64,
    max_iterations: usize,
) -> TruncatedCg {
    let mut d = vec![0.0; g.len()];
    let mut r: Vec<f64> = g.iter().map(|v| -v).collect();
    let mut z = r.clone();
    precondition(&mut z);
    let mut rz = dot(&r, &z);
    let target = forcing * rz.max(0.0).sqrt();
    let mut p = z.clone();
    let mut products = 0;
    loop {
        if products == max_iterations {
            return TruncatedCg { direction: d, products, end: CgEnd::Capped };
        }
        let hp = h(&p);
        products += 1;
        let curvature = dot(&p, &hp);
        // Written so that NaN curvature also stops.
        if curvature.is_nan() || curvature <= 1e-14 * dot(&p, &p).sqrt() * dot(&hp, &hp).sqrt() {
            if products == 1 {
                // The preconditioned gradient: still a descent direction.
                d = p;
            }
            return TruncatedCg { direction: d, products, end: CgEnd::NegativeCurvature };
        }
        let alpha = rz / curvature;
        for i in 0..d.len() {
            d[i] += alpha * p[i];
            r[i] -= alpha * hp[i];
        }
        z.clone_from(&r);
        precondition(&mut z);
        let rz_new = dot(&r, &z);
        if rz_new.max(0.0).sqrt() <= target {
            return TruncatedCg { direction: d, products, end: CgEnd::Converged };
        }
        let beta = rz_new / rz;
        rz = rz_new;
        for i in 0..p.len() {
            p[i] = z[i] + beta * p[i];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn truncated_cg_solves_a_positive_definite_system_and_descends_at_every_cap() {
        // A = B Bᵀ + I on 12 unknowns, a Jacobi preconditioner.
        let n = 12;
        let b: Vec<f64> = (0..n * n).map(|k| ((k * 37 % 17) as f64 - 8.0) / 8.0).collect();
        let a: Vec<f64> = (0..n * n)
            .map(|k| (0..n).map(|m| b[(k / n) * n + m] * b[(k % n) * n + m]).sum::<f64>() + if k / n == k % n { 1.0 } else { 0.0 })
            .collect();
        let h = |v: &[f64]| -> Vec<f64> { (0..n).map(|i| (0..n).map(|j| a[i * n + j] * v[j]).sum()).collect() };
        let jacobi = |r: &mut [f64]| r.iter_mut().enumerate().for_each(|(i, x)| *x /= a[i * n + i]);
        let g: Vec<f64> = (0..n).map(|i| (i as f64).sin() + 0.5).collect();
        let exact = truncated_cg(h, jacobi, &g, 1e-12, 100);
        assert_eq!(exact.end, CgEnd::Converged);
        assert!(exact.products <= n + 2, "{} products", exact.products);
        let residual: f64 = h(&exact.direction).iter().zip(&g).map(|(x, y)| (x + y).powi(2)).sum::<f64>().sqrt();
        assert!(residual < 1e-9 * dot(&g, &g).sqrt(), "residual {residual}");
        for cap in 1..6 {
            let t = truncated_cg(h, jacobi, &g, 1e-12, cap);
            assert_eq!((t.end, t.products), (CgEnd::Capped, cap));
            assert!(dot(&g, &t.direction) < 0.0, "cap {cap}: not a descent direction");
        }
    }

    #[test]
    fn truncated_cg_stops_on_negative_curvature_with_a_descent_direction() {
        // H = -I: the first direction has negative curvature; the preconditioned gradient is
        // returned.
        let g = [1.0, -2.0, 0.5];
        let t = truncated_cg(|v| v.iter().map(|x| -x).collect(), |_| {}, &g, 0.1, 10);
        assert_eq!((t.end, t.products), (CgEnd::NegativeCurvature, 1));
        assert_eq!(t.direction, vec![-1.0, 2.0, -0.5]);
    }

    #[test]
    fn forcing_terms_follow_the_gradient_ratio_within_bounds() {
        let mut f = Forcing::default();
        assert_eq!(f.next(1.0), Forcing::MAX);
        // A tenfold decrease: 0.9 * 0.01 = 0.009, but the safeguard 0.9 * 0.5² = 0.225 > 0.1 holds.
        assert!((f.next(0.1) - 0.225).abs() < 1e-15);
        // Another: 0.009 against the safeguard 0.9 * 0.225² = 0.0456 (below 0.1: not applied).
        assert!((f.next(0.01) - 0.009).abs() < 1e-15);
        // Far faster: floored at MIN (0.9e-6; the safeguard 0.9 * 0.009² is below 0.1).
        assert_eq!(f.next(1e-5), Forcing::MIN);
        // Stagnation: capped at MAX.
        assert_eq!(f.next(2e-5), Forcing::MAX);
    }

    use super::super::settings::Settings;
    use super::super::solver::{apply_step, objective};
    use super::super::tests::{bottom, keys, material, settings, wobbly, Nodes};
    use super::super::trajectory::Trajectory;
    use crate::algorithms::physics::elastic::Elastic;
    use crate::algorithms::testing::cube_mesh;
    use crate::support::testing::Rng;

    /// `f_s` at `tr` with fresh projections, written out from its definition (the objective's
    /// own is private): `M (ẍ + α ẋ - g) + L x - J p(x)`, zero at supports.
    fn residual(obj: &Objective, tr: &Trajectory, s: &Sample) -> Vec<Point> {
        let el = obj.elastic;
        let n = el.node_count();
        let i = s.interval;
        let u = [&tr.positions[i], &tr.velocities[i], &tr.positions[i + 1], &tr.velocities[i + 1]];
        let (c, l) = obj.coefficients(s);
        let (mut x, mut acc) = (vec![[0.0; 3]; n], vec![[0.0; 3]; n]);
        for j in 0..4 {
            for a in 0..n {
                for d in 0..3 {
                    x[a][d] += l[j] * u[j][a][d];
                    acc[a][d] += c[j] * u[j][a][d];
                }
            }
        }
        let (mut lx, mut jp) = (vec![[0.0; 3]; n], vec![[0.0; 3]; n]);
        el.stiffness.mul_points_sequential(&x, &mut lx);
        el.projected_forces_sequential(&x, &mut jp);
        (0..n)
            .map(|a| if obj.supports[a] { [0.0; 3] } else { [0, 1, 2].map(|d| el.mass[a] * (acc[a][d] - obj.gravity[d]) + lx[a][d] - jp[a][d]) })
            .collect()
    }

    fn random_direction(rng: &mut Rng, slots: usize, n: usize) -> Vec<Vec<Point>> {
        (0..slots).map(|_| (0..n).map(|_| [rng.next(), rng.next(), rng.next()]).collect()).collect()
    }

    /// The wobbly cube's keys (damped, with gravity), open or cyclic, with the bottom face a
    /// support (held in position and velocity at every key) when `supports`.
    fn wobbly_keys(rest: &[Point], tr: &Trajectory, cyclic: bool, supports: bool) -> super::super::unknowns::KeyConstraints {
        let mut k = keys(tr.times.clone(), tr.positions.clone(), vec![Nodes::default(); 4], cyclic);
        if supports {
            k.fixed = vec![bottom(rest); 4];
            k.fixed_velocity = k.fixed.clone();
        }
        k
    }

    /// `J_s v` (projections differentiated) equals central differences of the residual of every
    /// sample along a random direction, open and cyclic, with and without supports.
    #[test]
    fn residual_derivative_matches_finite_differences_of_the_residual() {
        let mesh = cube_mesh(2);
        let el = Elastic::new(&mesh, &material()).unwrap();
        let n = mesh.positions.len();
        let mut rng = Rng::new(7);
        for (cyclic, supports) in [(false, false), (true, false), (false, true)] {
            let tr = wobbly(&mesh.positions, cyclic);
            let k = wobbly_keys(&mesh.positions, &tr, cyclic, supports);
            let s = Settings { damping: 0.7, gravity: [0.0, -4.0, 1.0], samples: 3, ..settings() };
            let obj = objective(&el, &k, &s);
            let p = obj.local_step(&tr, true);
            let jac = p.jacobians.as_ref().unwrap();
            let v = random_direction(&mut rng, obj.slots.count(), n);
            let h = 1e-6;
            let (mut plus, mut minus) = (tr.clone(), tr.clone());
            apply_step(&mut plus, &obj.slots, &v, h);
            apply_step(&mut minus, &obj.slots, &v, -h);
            let mut worst: f64 = 0.0;
            for (sample, j) in obj.samples.iter().zip(jac) {
                let df = obj.residual_derivative(sample, j, &v);
                let (fp, fm) = (residual(&obj, &plus, sample), residual(&obj, &minus, sample));
                let scale = df.iter().map(|x| crate::algorithms::geometry::norm(*x)).fold(0.0, f64::max);
                for a in 0..n {
                    for d in 0..3 {
                        let fd = (fp[a][d] - fm[a][d]) / (2.0 * h);
                        worst = worst.max((fd - df[a][d]).abs() / scale);
                    }
                }
            }
            assert!(worst < 1e-6, "cyclic {cyclic}, supports {supports}: relative error {worst:e}");
        }
    }

    /// `H v` equals `Σ_s dτ_s J_sᵀ M⁻¹ J_s v` with every `J_s` assembled densely, column by
    /// column (one unit direction per slot, node and coordinate), on a one-cell cube; the dense
    /// `H` is symmetric.
    #[test]
    fn gauss_newton_product_is_the_dense_jt_j() {
        let mesh = cube_mesh(1);
        let el = Elastic::new(&mesh, &material()).unwrap();
        let n = mesh.positions.len();
        let tr = wobbly(&mesh.positions, false);
        let k = wobbly_keys(&mesh.positions, &tr, false, false);
        let s = Settings { damping: 0.7, gravity: [0.0, -4.0, 1.0], samples: 2, ..settings() };
        let obj = objective(&el, &k, &s);
        let p = obj.local_step(&tr, true);
        let jac = p.jacobians.as_ref().unwrap();
        let slots = obj.slots.count();
        let dim = 3 * n * slots;
        let unit = |c: usize| {
            let mut v = vec![vec![[0.0; 3]; n]; slots];
            v[c / (3 * n)][(c / 3) % n][c % 3] = 1.0;
            v
        };
        // Dense H, column by column.
        let mut dense = vec![0.0; dim * dim];
        for (sample, j) in obj.samples.iter().zip(jac) {
            let columns: Vec<Vec<Point>> = (0..dim).map(|c| obj.residual_derivative(sample, j, &unit(c))).collect();
            for r in 0..dim {
                for c in 0..dim {
                    let mut sum = 0.0;
                    for a in 0..n {
                        for d in 0..3 {
                            sum += columns[r][a][d] * columns[c][a][d] / el.mass[a];
                        }
                    }
                    dense[r * dim + c] += sample.weight * sum;
                }
            }
        }
        let big = dense.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        for r in 0..dim {
            for c in 0..r {
                assert!((dense[r * dim + c] - dense[c * dim + r]).abs() <= 1e-12 * big);
            }
        }
        let mut rng = Rng::new(3);
        let v = random_direction(&mut rng, slots, n);
        let hv = obj.gauss_newton_product(&p, &v);
        let flat: Vec<f64> = v.iter().flatten().flatten().copied().collect();
        let mut worst: f64 = 0.0;
        let scale = hv.iter().flatten().flatten().fold(0.0f64, |m, x| m.max(x.abs()));
        for r in 0..dim {
            let expected: f64 = (0..dim).map(|c| dense[r * dim + c] * flat[c]).sum();
            worst = worst.max((expected - hv[r / (3 * n)][(r / 3) % n][r % 3]).abs() / scale);
        }
        assert!(worst < 1e-12, "relative error {worst:e}");
    }

    /// The solver with Gauss-Newton steps: every step lowers W, the steps are Gauss-Newton
    /// ones, and it settles where L-BFGS does (the wobbly cube's keys, bottom face held, damped,
    /// with gravity); `Auto` and moving key times keep L-BFGS.
    #[test]
    fn gauss_newton_steps_lower_w_to_the_quasi_newton_minimum() {
        use super::super::settings::Step;
        use super::super::solver::solve;
        let mesh = cube_mesh(2);
        let el = Elastic::new(&mesh, &material()).unwrap();
        let tr = wobbly(&mesh.positions, false);
        let mut k = wobbly_keys(&mesh.positions, &tr, false, false);
        k.fixed = vec![(0..mesh.positions.len() as u32).filter(|&a| mesh.positions[a as usize][1] == 0.0).collect(); 4];
        let base = Settings { damping: 0.7, gravity: [0.0, -4.0, 1.0], samples: 4, tolerance: 1e-7, ..settings() };
        let run = |step| solve(&el, &k, &Settings { step, ..base.clone() }, &|_, _, _| {}).unwrap().log;
        let (qn, gn) = (run(Step::QuasiNewton), run(Step::GaussNewton));
        assert!(qn.converged && gn.converged, "{} / {}", qn.stop_reason, gn.stop_reason);
        assert!(gn.stop_reason.contains("Gauss-Newton steps") && !qn.stop_reason.contains("Gauss-Newton"), "{}", gn.stop_reason);
        assert!(gn.energy.windows(2).all(|w| w[1] < w[0]), "W rose: {:?}", gn.energy);
        let (wq, wg) = (*qn.energy.last().unwrap(), *gn.energy.last().unwrap());
        assert!((wg - wq).abs() <= 1e-4 * wq, "W {wg:e} (Gauss-Newton) against {wq:e} (L-BFGS)");
        assert_eq!(Step::Auto.resolve(&base), Step::QuasiNewton);
        let timed = Settings { timing: Some(Default::default()), step: Step::GaussNewton, ..base.clone() };
        assert_eq!(timed.step.resolve(&timed), Step::QuasiNewton);
    }

    /// Where the residual vanishes (a rotated body in free fall, undamped: `f = M (g - g) + 0`),
    /// W's Hessian is its Gauss-Newton part: `H v` equals central differences of the exact
    /// gradient along random directions.
    #[test]
    fn gauss_newton_product_is_the_hessian_where_the_residual_vanishes() {
        let mesh = cube_mesh(2);
        let el = Elastic::new(&mesh, &material()).unwrap();
        let n = mesh.positions.len();
        let g = [0.0, -9.81, 0.0];
        let (angle, v0) = (0.7f64, [0.5, 2.0, -1.0]);
        let rotated: Vec<Point> = mesh
            .positions
            .iter()
            .map(|p| {
                let (s, c) = angle.sin_cos();
                [c * p[0] - s * p[1], s * p[0] + c * p[1], p[2]]
            })
            .collect();
        let times = vec![0.0, 0.4, 0.7, 1.2];
        let at = |t: f64| -> (Vec<Point>, Vec<Point>) {
            let x = rotated.iter().map(|p| [0, 1, 2].map(|d| p[d] + v0[d] * t + 0.5 * g[d] * t * t)).collect();
            (x, vec![[0, 1, 2].map(|d| v0[d] + g[d] * t); n])
        };
        let tr = Trajectory {
            times: times.clone(),
            positions: times.iter().map(|&t| at(t).0).collect(),
            velocities: times.iter().map(|&t| at(t).1).collect(),
        };
        let k = keys(times, tr.positions.clone(), vec![Nodes::default(); 4], false);
        let s = Settings { damping: 0.0, gravity: g, samples: 3, ..settings() };
        let obj = objective(&el, &k, &s);
        let p = obj.local_step(&tr, true);
        let e = obj.evaluate(&tr, &p);
        assert!(e.value < 1e-20 * e.force_scale, "the residual vanishes: W {:e}, S {:e}", e.value, e.force_scale);
        let gradient = |t: &Trajectory| obj.evaluate(t, &obj.local_step(t, true)).exact_gradient.unwrap();
        let mut rng = Rng::new(11);
        for _ in 0..3 {
            let v = random_direction(&mut rng, obj.slots.count(), n);
            let hv = obj.gauss_newton_product(&p, &v);
            let h = 1e-5;
            let (mut plus, mut minus) = (tr.clone(), tr.clone());
            apply_step(&mut plus, &obj.slots, &v, h);
            apply_step(&mut minus, &obj.slots, &v, -h);
            let (gp, gm) = (gradient(&plus), gradient(&minus));
            let scale = hv.iter().flatten().flatten().fold(0.0f64, |m, x| m.max(x.abs()));
            let mut worst: f64 = 0.0;
            for slot in 0..hv.len() {
                for a in 0..n {
                    for d in 0..3 {
                        let fd = (gp[slot][a][d] - gm[slot][a][d]) / (2.0 * h);
                        worst = worst.max((fd - hv[slot][a][d]).abs() / scale);
                    }
                }
            }
            assert!(worst < 1e-6, "relative error {worst:e}");
        }
    }
}
