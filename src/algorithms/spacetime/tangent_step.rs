//! The tangent model Hessian of W: the global step's normal matrix with the rest tangent
//! stiffness `K = ∇²E(X)` in place of the projective matrix `L`,
//!
//! ```text
//! Σ_s dτ (c_σ M + l_σ K) M⁻¹ (c_σ' M + l_σ' K)
//!   = C_MM[σ,σ'] M + C_ML[σ,σ'] K + C_KK[σ,σ'] K M⁻¹ K
//! ```
//!
//! (the same time coefficients as [`super::global_step`], `M⁻¹` in the middle skipping the
//! supports). `L` also resists rotating the elements, so it resists bending far more than the
//! body does (about 55 times on a cantilever): preconditioned by it, L-BFGS barely moves the
//! slow bending modes and the solve stalls above the minimum. About the rest shape, with
//! small displacements and rotations, `K` is the true stiffness, this matrix is the
//! Gauss-Newton Hessian of W, and at a trajectory whose residual vanishes (the body resting)
//! it is W's exact Hessian (tested by finite differences).
//!
//! `K` couples the three coordinates, so unlike the global step this is one system of
//! `3 × unknowns` (node-major, `3u + d`), factorized once by sparse Cholesky (faer's AMD
//! ordering) and refactorized numerically on the kept symbolic analysis when the key times
//! move. No proximal term: it is meant to be a Newton model, and the line search keeps W
//! from increasing.

use faer::sparse::{SparseColMat, SymbolicSparseColMat};
use faer::Par;

use super::objective::Objective;
use super::time_coefficients::TimeCoefficients;
use super::unknowns::Unknowns;
use crate::algorithms::geometry::Point;
use crate::algorithms::physics::cholesky::Cholesky;
use crate::algorithms::physics::csr::Csr;
use crate::algorithms::physics::ordering::FillOrdering;
use crate::algorithms::physics::vibration::{rest_stiffness, RestStiffness};
use crate::support::error::{Error, Result};

/// The factorized tangent model Hessian of the free unknowns.
pub struct TangentStep {
    /// `K` over every node's coordinates.
    k: Csr,
    /// `K M⁻¹ K` (supports skipped in the middle).
    kmk: Csr,
    /// Which slot pairs share a sample (the pattern; the values depend on the key times).
    coupled: Vec<bool>,
    /// The lower triangle as last assembled (kept for [`TangentStep::apply`]).
    lower: SparseColMat<usize, f64>,
    cholesky: Cholesky,
}

fn singular() -> Error {
    Error::general(
        "the tangent model Hessian of the spacetime energy is singular: some motion costs nothing",
        "fix some vertices at one key (`fixed`), or set [solver] model_hessian = \"projective\"",
    )
}

impl TangentStep {
    /// Assemble and factorize at the times of `objective`.
    pub fn new(objective: &Objective, unknowns: &Unknowns) -> Result<TangentStep> {
        let el = objective.elastic;
        let k = rest_stiffness(el, RestStiffness::Tangent);
        let inv_mass: Vec<f64> = (0..3 * el.node_count()).map(|r| if objective.supports[r / 3] { 0.0 } else { 1.0 / el.mass[r / 3] }).collect();
        let kmk = k.sandwich_diagonal(&inv_mass);
        let n = objective.slots.count();
        let mut coupled = vec![false; n * n];
        for s in &objective.samples {
            for a in s.slots {
                for b in s.slots {
                    coupled[a * n + b] = true;
                }
            }
        }
        let coefficients = TimeCoefficients::new(objective, 0.0);
        let lower = assemble(&k, &kmk, &coupled, el, unknowns, &coefficients);
        let cholesky = Cholesky::factor(&lower, &FillOrdering::Amd, Par::Seq).map_err(|_| singular())?;
        Ok(TangentStep { k, kmk, coupled, lower, cholesky })
    }

    /// Refactorize for new key times (`objective` at those times), on the kept pattern.
    pub fn retime(&mut self, objective: &Objective, unknowns: &Unknowns) -> Result<()> {
        let coefficients = TimeCoefficients::new(objective, 0.0);
        self.lower = assemble(&self.k, &self.kmk, &self.coupled, objective.elastic, unknowns, &coefficients);
        self.cholesky.refactor(&self.lower).map_err(|_| singular())
    }

    /// `x <- H⁻¹ x` on the free unknowns (one 3-vector per unknown).
    pub fn apply_inverse(&self, x: &mut [Point]) {
        let mut rhs = faer::Mat::<f64>::from_fn(3 * x.len(), 1, |r, _| x[r / 3][r % 3]);
        self.cholesky.solve_in_place(rhs.as_mut());
        for (r, v) in x.iter_mut().flat_map(|p| p.iter_mut()).enumerate() {
            *v = rhs[(r, 0)];
        }
    }

    /// `H x` on the free unknowns (for checks).
    #[cfg(test)]
    pub fn apply(&self, x: &[Point]) -> Vec<Point> {
        let mut out = vec![[0.0; 3]; x.len()];
        let (cols, rows, vals) = (self.lower.symbolic().col_ptr(), self.lower.symbolic().row_idx(), self.lower.val());
        let at = |i: usize| x[i / 3][i % 3];
        for c in 0..3 * x.len() {
            for p in cols[c]..cols[c + 1] {
                let (r, v) = (rows[p], vals[p]);
                out[r / 3][r % 3] += v * at(c);
                if r != c {
                    out[c / 3][c % 3] += v * at(r);
                }
            }
        }
        out
    }
}

/// The lower triangle of the tangent model Hessian over the free unknowns' coordinates. The
/// pattern depends only on `coupled` (every structurally present entry is stored, zero or not),
/// so a refactorization can reuse the symbolic analysis.
fn assemble(
    k: &Csr,
    kmk: &Csr,
    coupled: &[bool],
    el: &crate::algorithms::physics::elastic::Elastic,
    unknowns: &Unknowns,
    c: &TimeCoefficients,
) -> SparseColMat<usize, f64> {
    let n = c.slots;
    let dim = 3 * unknowns.count();
    let mut col_ptr = Vec::with_capacity(dim + 1);
    col_ptr.push(0usize);
    let (mut rows, mut vals) = (Vec::new(), Vec::new());
    let mut column: Vec<(usize, f64)> = Vec::new();
    // Unknowns are numbered node-major, so columns come in order node by node, slot by slot.
    for b in 0..unknowns.nodes {
        for s2 in 0..n {
            let Some(u2) = unknowns.get(b, s2) else { continue };
            for e in 0..3 {
                let col = 3 * u2 + e;
                column.clear();
                // KMK's pattern holds K's and the diagonal's.
                for (j, kmk_v) in kmk.row(3 * b + e) {
                    let (a, d) = (j / 3, j % 3);
                    let (k_v, m_v) = (k.get(3 * b + e, j), if j == 3 * b + e { el.mass[b] } else { 0.0 });
                    for s1 in 0..n {
                        let at = s1 * n + s2;
                        if !coupled[at] {
                            continue;
                        }
                        let Some(u1) = unknowns.get(a, s1) else { continue };
                        let row = 3 * u1 + d;
                        if row >= col {
                            column.push((row, c.mm[at] * m_v + c.ml[at] * k_v + c.kk[at] * kmk_v));
                        }
                    }
                }
                column.sort_unstable_by_key(|&(r, _)| r);
                rows.extend(column.iter().map(|&(r, _)| r));
                vals.extend(column.iter().map(|&(_, v)| v));
                col_ptr.push(rows.len());
            }
        }
    }
    SparseColMat::new(SymbolicSparseColMat::new_checked(dim, dim, col_ptr, None, rows), vals)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::algorithms::physics::elastic::{Elastic, Material};
    use crate::algorithms::spacetime::settings::Settings;
    use crate::algorithms::spacetime::solver::{apply_step, objective};
    use crate::algorithms::spacetime::trajectory::Trajectory;
    use crate::algorithms::spacetime::unknowns::KeyConstraints;
    use crate::algorithms::testing::cube_mesh;
    use crate::support::testing::Rng;

    /// The exact gradient of W on the free unknowns.
    fn gradient(obj: &Objective, unknowns: &Unknowns, tr: &Trajectory) -> Vec<Point> {
        let g = obj.evaluate(tr, &obj.local_step(tr, true)).exact_gradient.expect("asked for");
        let mut out = vec![[0.0; 3]; unknowns.count()];
        for (s, values) in g.iter().enumerate() {
            for (a, v) in values.iter().enumerate() {
                if let Some(i) = unknowns.get(a, s) {
                    out[i] = *v;
                }
            }
        }
        out
    }

    #[test]
    fn is_the_exact_hessian_of_w_at_rest() {
        // At rest with zero velocities and no gravity every residual vanishes, so W's Hessian
        // is exactly Jᵀ M⁻¹ J with J = c M + l ∇²E(X): the tangent model. Central differences
        // of the exact gradient along random directions, damped, open and cyclic, with and
        // without supports (the bottom face held in position and velocity).
        let mesh = cube_mesh(2);
        let el = Elastic::new(&mesh, &Material { stiffness: 70.0, volume: 40.0, density: 1.0 }).unwrap();
        let n = el.node_count();
        let bottom: Vec<u32> = (0..n as u32).filter(|&a| mesh.positions[a as usize][1] == 0.0).collect();
        for (cyclic, supports) in [(false, true), (true, true), (true, false)] {
            let times = vec![0.0, 0.4, 1.0];
            let fixed = if supports { vec![bottom.clone(); 3] } else { vec![bottom.clone(), Vec::new(), Vec::new()] };
            let fixed_velocity = if supports { fixed.clone() } else { vec![Vec::new(); 3] };
            let keys = KeyConstraints { times: times.clone(), positions: vec![el.rest.clone(); 3], fixed, fixed_velocity, cyclic };
            let settings = Settings { damping: 0.7, ..Settings::new(6, 0.0, [0.0; 3]) };
            let obj = objective(&el, &keys, &settings);
            let unknowns = Unknowns::new(&keys, n);
            let step = TangentStep::new(&obj, &unknowns).unwrap();
            let rest = Trajectory::with_zero_velocities(times, vec![el.rest.clone(); 3]);
            let mut rng = Rng::new(7);
            for _ in 0..3 {
                let v: Vec<Point> = (0..unknowns.count()).map(|_| [rng.next(), rng.next(), rng.next()]).collect();
                let mut delta = vec![vec![[0.0; 3]; n]; obj.slots.count()];
                for (s, ds) in delta.iter_mut().enumerate() {
                    for (a, d) in ds.iter_mut().enumerate() {
                        if let Some(i) = unknowns.get(a, s) {
                            *d = v[i];
                        }
                    }
                }
                let h = 1e-5;
                let (mut plus, mut minus) = (rest.clone(), rest.clone());
                apply_step(&mut plus, &obj.slots, &delta, h);
                apply_step(&mut minus, &obj.slots, &delta, -h);
                let (gp, gm) = (gradient(&obj, &unknowns, &plus), gradient(&obj, &unknowns, &minus));
                let hv = step.apply(&v);
                let scale = hv.iter().flatten().fold(0.0f64, |m, x| m.max(x.abs()));
                let worst = gp
                    .iter()
                    .zip(&gm)
                    .zip(&hv)
                    .flat_map(|((p, m), h_v)| (0..3).map(move |d| ((p[d] - m[d]) / (2.0 * h) - h_v[d]).abs()))
                    .fold(0.0, f64::max);
                assert!(worst < 1e-6 * scale, "cyclic={cyclic}, supports={supports}: {worst:e} of {scale:e}");
                // And the factor inverts it.
                let mut back = hv.clone();
                step.apply_inverse(&mut back);
                let error = back.iter().zip(&v).flat_map(|(b, x)| (0..3).map(move |d| (b[d] - x[d]).abs())).fold(0.0, f64::max);
                assert!(error < 1e-8, "H⁻¹ H v - v: {error:e}");
            }
        }
    }

    #[test]
    fn refactorizes_for_new_times_as_a_fresh_build() {
        let mesh = cube_mesh(2);
        let el = Elastic::new(&mesh, &Material { stiffness: 70.0, volume: 40.0, density: 1.0 }).unwrap();
        let n = el.node_count();
        let bottom: Vec<u32> = (0..n as u32).filter(|&a| mesh.positions[a as usize][1] == 0.0).collect();
        let keys = |times: Vec<f64>| KeyConstraints {
            times,
            positions: vec![el.rest.clone(); 3],
            fixed: vec![bottom.clone(); 3],
            fixed_velocity: vec![Vec::new(); 3],
            cyclic: false,
        };
        let settings = Settings::new(6, 0.2, [0.0; 3]);
        let (a, b) = (keys(vec![0.0, 0.4, 1.0]), keys(vec![0.0, 0.7, 1.3]));
        let unknowns = Unknowns::new(&a, n);
        let mut step = TangentStep::new(&objective(&el, &a, &settings), &unknowns).unwrap();
        step.retime(&objective(&el, &b, &settings), &unknowns).unwrap();
        let fresh = TangentStep::new(&objective(&el, &b, &settings), &unknowns).unwrap();
        let mut rng = Rng::new(3);
        let v: Vec<Point> = (0..unknowns.count()).map(|_| [rng.next(), rng.next(), rng.next()]).collect();
        let (mut x, mut y) = (v.clone(), v.clone());
        step.apply_inverse(&mut x);
        fresh.apply_inverse(&mut y);
        assert_eq!(step.apply(&v), fresh.apply(&v));
        let error = x.iter().zip(&y).flat_map(|(p, q)| (0..3).map(move |d| (p[d] - q[d]).abs())).fold(0.0, f64::max);
        assert!(error < 1e-12 * x.iter().flatten().fold(0.0f64, |m, v| m.max(v.abs())), "{error:e}");
    }

    #[test]
    fn w_along_a_newton_step_on_a_small_cantilever_loop_is_the_model_quadratic() {
        // A clamped bar (4 x 1 x 1, a cube mesh stretched) bent by 1e-3 of its length half a
        // loop later, away from rest and with a large residual: W along the step -H⁻¹ g is the
        // model's parabola W₀ + t gᵀd + ½ t² dᵀHd (the tangent model is W's Hessian there too,
        // to the order of the motion), so the full step is the best one along it.
        let mut mesh = cube_mesh(3);
        for p in mesh.positions.iter_mut() {
            p[0] *= 4.0;
        }
        let el = Elastic::new(&mesh, &Material { stiffness: 7.7e6, volume: 1.7e7, density: 1000.0 }).unwrap();
        let n = el.node_count();
        let clamp: Vec<u32> = (0..n as u32).filter(|&a| mesh.positions[a as usize][0] == 0.0).collect();
        let bent: Vec<Point> = el.rest.iter().map(|p| [p[0], p[1] + 4e-3 * (p[0] / 4.0).powi(2), p[2]]).collect();
        for duration in [0.05, 0.2] {
            let times = vec![0.0, 0.5 * duration, duration];
            let all: Vec<u32> = (0..n as u32).collect();
            let keys = KeyConstraints {
                times: times.clone(),
                positions: vec![el.rest.clone(), bent.clone(), el.rest.clone()],
                fixed: vec![clamp.clone(), all, clamp.clone()],
                fixed_velocity: vec![clamp.clone(); 3],
                cyclic: true,
            };
            let settings = Settings::new(10, 0.0, [0.0; 3]);
            let obj = objective(&el, &keys, &settings);
            let unknowns = Unknowns::new(&keys, n);
            let step = TangentStep::new(&obj, &unknowns).unwrap();
            let tr = crate::algorithms::spacetime::solver::initial_trajectory(&keys);
            let w = |t: &Trajectory| obj.evaluate(t, &obj.local_step(t, false)).value;
            let g = gradient(&obj, &unknowns, &tr);
            let mut d: Vec<Point> = g.iter().map(|v| crate::algorithms::geometry::scale(*v, -1.0)).collect();
            step.apply_inverse(&mut d);
            let mut delta = vec![vec![[0.0; 3]; n]; obj.slots.count()];
            for (s, ds) in delta.iter_mut().enumerate() {
                for (a, x) in ds.iter_mut().enumerate() {
                    if let Some(i) = unknowns.get(a, s) {
                        *x = d[i];
                    }
                }
            }
            let flat = |v: &[Point]| -> Vec<f64> { v.iter().flatten().copied().collect() };
            let gd: f64 = flat(&g).iter().zip(flat(&d)).map(|(a, b)| a * b).sum();
            let dhd: f64 = flat(&d).iter().zip(flat(&step.apply(&d))).map(|(a, b)| a * b).sum();
            let w0 = w(&tr);
            for t in [0.25, 0.5, 1.0] {
                let mut moved = tr.clone();
                apply_step(&mut moved, &obj.slots, &delta, t);
                let (measured, model) = (w(&moved), w0 + t * gd + 0.5 * t * t * dhd);
                assert!((measured - model).abs() < 1e-3 * -gd, "D {duration}, t {t}: W {measured} vs the model's {model} (from {w0})");
            }
        }
    }
}
