//! The equilibrium of a spring network by Newton's method (Ma et al. 2012, eqs. 3-4): solve
//! `H dx = -∇E` with the sparse stiffness `H`, step along `dx` with a backtracking line
//! search on the energy, and stop when the largest vertex move `max_v |dx_v|` is below a
//! tolerance (a length: the caller scales it by the mesh size).
//!
//! - Stiffness: the exact spring blocks of [`super::energy`], with the transverse stiffness
//!   of compressed springs clamped at zero ([`Definiteness::Clamped`]) while the iterates are
//!   far from equilibrium, so that `H` is positive semi-definite and `dx` a descent direction.
//!   Once a full Newton step was accepted and was shorter than `exact_below` (or from the
//!   start, for a predicted start), the iterations use the exact `H` (quadratic convergence
//!   at a stable equilibrium, where the exact `H` is positive definite); where it is not (its
//!   factorization fails, conjugate gradients meet negative curvature, or the step is not a
//!   descent direction), that iteration uses the clamped one. A clamped `H` that is singular
//!   (a vertex free to turn about its only spring, say) is shifted by a small multiple of the
//!   identity, growing until it factors; [`NewtonReport::regularized`] counts how often. Exact
//!   steps that stop shrinking close to the tolerance end the solve too (the rounding floor:
//!   see [`NewtonReport::at_rounding_floor`]).
//! - Linear solves: conjugate gradients on the current `H`, preconditioned by the sparse
//!   Cholesky factorization (faer) of a recent `H`, to a relative residual (the forcing term
//!   of inexact Newton). With a factorization of the current `H` that is a direct solve; the
//!   caller refactorizes at each new start point ([`Newton::refresh`]) and the solver when
//!   CG needed many iterations, so the following iterations, whose `H` differs little, cost
//!   a few triangular solves each instead of a factorization (measured on the Man-size
//!   benchmark: a factorization costs 10 to 17 solves, and each step of a warm-started
//!   sequence takes one factorization and about 5 CG iterations). The factorization is in
//!   single precision (it only preconditions; CG runs in double), in double where single
//!   precision fails.
//! - Boundary conditions: fixed vertices keep their positions. Their rows and columns of `H`
//!   become the identity and their gradient entries zero (the paper's Dirichlet replacement),
//!   so the matrix pattern never changes: one symbolic factorization serves every iteration,
//!   every blend and every set of held collision vertices.
//! - Ordering: the vertex graph (3 unknowns per vertex kept together) by geometric nested
//!   dissection or minimum degree, whichever predicts fewer flops, postordered.
//!
//! All sums run in a fixed order, every decision depends on counts, never on timings, and the
//! factorization is faer's (deterministic for a given thread count), so the same inputs give
//! the same bytes.

use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::linalg::cholesky::llt::factor::LltRegularization;
use faer::perm::PermRef;
use faer::sparse::linalg::cholesky::{factorize_symbolic_cholesky, CholeskySymbolicParams, LltRef, SymbolicCholesky, SymmetricOrdering};
use faer::sparse::{SparseColMat, SparseColMatRef, SymbolicSparseColMat};
use faer::{Conj, Mat, Par, Side};

use super::energy::{spring_hessian, Definiteness, SpringSystem};
use super::springs::Springs;
use crate::algorithms::geometry::{norm, Point};
use crate::algorithms::physics::cholesky::PARALLEL_FACTOR_FLOPS;
use crate::algorithms::physics::ordering::{expand, minimum_degree, nested_dissection, postorder, predicted_cost, Graph};
use crate::support::budget::Budget;
use crate::support::error::{Error, Result};

/// When to stop and when to trust the exact Hessian.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NewtonSettings {
    /// Stop when the largest vertex move of a Newton step is at most this length.
    pub tolerance: f64,
    /// Newton iterations at most.
    pub max_iterations: usize,
    /// Use the exact Hessian after a full step shorter than this length.
    pub exact_below: f64,
    /// Use the exact Hessian from the first iteration (a start known to be close, such as a
    /// predicted one).
    pub start_exact: bool,
    /// Relative residual at which the linear solves stop (the forcing term of inexact Newton:
    /// the error of a step shrinks at least by this factor, on top of Newton's quadratic rate).
    pub forcing: f64,
    /// The time the solve may take (checked every iteration: an equilibrium may take many).
    pub budget: Budget,
}

/// How a solve went.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct NewtonReport {
    /// Newton iterations (each one assembly and one linear solve).
    pub iterations: usize,
    /// Iterations whose step came from the exact Hessian.
    pub exact_iterations: usize,
    /// Exact Hessians found indefinite (by the factorization or by conjugate gradients), whose
    /// iteration then used the clamped one.
    pub exact_failures: usize,
    /// Numeric factorizations that needed a diagonal shift to succeed.
    pub regularized: usize,
    /// Numeric factorizations (including failed attempts).
    pub factorizations: usize,
    /// Preconditioned conjugate-gradient iterations (one triangular solve pair each).
    pub cg_iterations: usize,
    /// Step halvings of the line search, summed over the iterations.
    pub halvings: usize,
    /// Largest vertex move of the last Newton step (before the line search scaled it).
    pub last_step: f64,
    /// Energy at the returned positions.
    pub energy: f64,
    /// The last step was at most the tolerance, or stalled at the rounding floor.
    pub converged: bool,
    /// Converged by stalling: exact Newton steps stopped shrinking within `FLOOR_FACTOR` of the
    /// tolerance, which is where rounding in the forces (sums of terms that cancel at
    /// equilibrium) limits the accuracy of the step.
    pub at_rounding_floor: bool,
    /// Seconds in numeric factorizations.
    pub factor_seconds: f64,
    /// Seconds in triangular solves (applying the preconditioner).
    pub solve_seconds: f64,
    /// Wall-clock seconds of the whole solve: factorizations and triangular solves, plus the
    /// rest (assembly, gradients, energies, matrix-vector products).
    pub seconds: f64,
}

impl NewtonReport {
    /// Add the work of another solve (counts and times; the outcome fields are `other`'s).
    pub fn absorb(&mut self, other: &NewtonReport) {
        self.iterations += other.iterations;
        self.exact_iterations += other.exact_iterations;
        self.exact_failures += other.exact_failures;
        self.regularized += other.regularized;
        self.factorizations += other.factorizations;
        self.cg_iterations += other.cg_iterations;
        self.halvings += other.halvings;
        self.factor_seconds += other.factor_seconds;
        self.solve_seconds += other.solve_seconds;
        self.seconds += other.seconds;
        self.last_step = other.last_step;
        self.energy = other.energy;
        self.converged = other.converged;
        self.at_rounding_floor = other.at_rounding_floor;
    }
}

/// An exact Newton step that does not halve the previous one and is within this factor of the
/// tolerance is rounding noise: the iterates are as accurate as the arithmetic allows.
const FLOOR_FACTOR: f64 = 1e2;

/// Conjugate-gradient iterations before the preconditioner is refreshed and the solve redone.
const CG_MAX: usize = 40;

/// A solve that needed more iterations than this refreshes the factorization before the next.
const CG_REFRESH: usize = 12;

/// How a preconditioned conjugate-gradient solve ended.
enum Cg {
    Converged(usize),
    NegativeCurvature,
    NotConverged,
}

/// The stiffness pattern of a spring network, its fill-reducing order and symbolic Cholesky
/// factorization, reused by every solve on that network.
///
/// Linear solves: preconditioned conjugate gradients on the current stiffness, preconditioned
/// by the Cholesky factorization of a recent one (refactorized when CG needs many iterations,
/// or detects negative curvature in a clamped matrix). With the factorization of the current
/// matrix this is a direct solve (one CG iteration); along a sequence of nearby equilibria
/// (Newton iterations, warm-started blends) the factorization of an earlier stiffness keeps CG
/// to a few iterations, each a pair of triangular solves, several times cheaper than a numeric
/// factorization.
pub struct Newton {
    vertex_count: usize,
    /// Lower triangle, compressed columns, unknown `3 v + c` for coordinate `c` of vertex `v`
    /// (a copy of the matrix's column pointers, for slot arithmetic while values are mutated).
    col_ptr: Vec<usize>,
    /// The matrix, values overwritten by every assembly (its pattern never changes).
    a: SparseColMat<usize, f64>,
    /// Per spring `[i, j]`: the offset of `j` among the later neighbours of `i` (the position of
    /// block `(j, i)` in the columns of `i`).
    block_offset: Vec<usize>,
    factor: Factor,
    /// The factor holds a stiffness of this network (at first it holds the identity).
    factored: bool,
    /// Refactorize before the next solve.
    stale: bool,
    /// The fill-reducing ordering chosen (nested dissection or minimum degree, on the vertex
    /// graph).
    pub ordering: &'static str,
    /// Predicted floating-point operations of one numeric factorization in that ordering.
    pub predicted_flops: f64,
    // Work arrays.
    gradient: Vec<Point>,
    trial: Vec<Point>,
    rhs: Vec<f64>,
    dx: Vec<f64>,
    r: Vec<f64>,
    z: Vec<f64>,
    p: Vec<f64>,
    hp: Vec<f64>,
}

impl Newton {
    /// Analyse the network: pattern, order (from the vertex `coords`, e.g. target 0) and
    /// symbolic factorization.
    pub fn new(springs: &Springs, coords: &[Point]) -> Newton {
        let n = springs.vertex_count;
        assert_eq!(coords.len(), n);
        // Later neighbours of every vertex, in spring order (springs are sorted by ends).
        let mut later = vec![0usize; n];
        let mut block_offset = Vec::with_capacity(springs.len());
        for &[i, _] in &springs.ends {
            block_offset.push(later[i as usize]);
            later[i as usize] += 1;
        }
        let mut col_ptr = Vec::with_capacity(3 * n + 1);
        col_ptr.push(0);
        for v in 0..n {
            for c in 0..3 {
                col_ptr.push(col_ptr.last().unwrap() + (3 - c) + 3 * later[v]);
            }
        }
        let mut row_idx = vec![0usize; *col_ptr.last().unwrap()];
        let mut fill = col_ptr.clone();
        for v in 0..n {
            for c in 0..3 {
                for r in c..3 {
                    row_idx[fill[3 * v + c]] = 3 * v + r;
                    fill[3 * v + c] += 1;
                }
            }
        }
        for &[i, j] in &springs.ends {
            for c in 0..3 {
                for r in 0..3 {
                    row_idx[fill[3 * i as usize + c]] = 3 * j as usize + r;
                    fill[3 * i as usize + c] += 1;
                }
            }
        }
        // Order the vertex graph.
        let adjacency = springs.adjacency();
        let mut xadj = vec![0usize];
        let mut adj = Vec::new();
        for list in &adjacency {
            adj.extend_from_slice(list);
            xadj.push(adj.len());
        }
        let graph = Graph { xadj, adj };
        let weights = vec![3usize; n];
        let dissection = nested_dissection(&graph, coords);
        let degree = minimum_degree(&graph);
        let (cost_nd, cost_md) = (predicted_cost(&graph, &dissection, &weights), predicted_cost(&graph, &degree, &weights));
        let (order, ordering, cost) = if cost_nd.flops <= cost_md.flops {
            (dissection, "nested dissection (vertices)", cost_nd)
        } else {
            (degree, "minimum degree (vertices)", cost_md)
        };
        let block_start: Vec<usize> = (0..=n).map(|v| 3 * v).collect();
        let perm = expand(&postorder(&graph, &order), &block_start);
        // A fixed split (not the pool's), so the factor's bytes do not depend on the thread count.
        let par = if cost.flops > PARALLEL_FACTOR_FLOPS { crate::algorithms::physics::fixed_par::par() } else { Par::Seq };
        // The symbolic analysis needs values only to finish the first numeric factorization:
        // the identity on the full pattern.
        let mut values = vec![0.0; row_idx.len()];
        for u in 0..3 * n {
            values[col_ptr[u]] = 1.0;
        }
        // The pattern is sorted and in bounds by construction; the checked constructor verifies.
        let a = SparseColMat::new(SymbolicSparseColMat::new_checked(3 * n, 3 * n, col_ptr.clone(), None, row_idx), values);
        let factor = Factor::new(&a, &perm, par);
        Newton {
            vertex_count: n,
            col_ptr,
            a,
            block_offset,
            factor,
            factored: false,
            stale: false,
            ordering,
            predicted_flops: cost.flops,
            gradient: vec![[0.0; 3]; n],
            trial: vec![[0.0; 3]; n],
            rhs: vec![0.0; 3 * n],
            dx: vec![0.0; 3 * n],
            r: vec![0.0; 3 * n],
            z: vec![0.0; 3 * n],
            p: vec![0.0; 3 * n],
            hp: vec![0.0; 3 * n],
        }
    }

    /// Factorize again at the next linear solve: the caller is at a new start point, which the
    /// following iterations stay near. (Keeping a factorization across blends costs more than
    /// it saves: on the Man-size benchmark a factorization costs about 10 to 17 CG iterations,
    /// and a warm step takes 5.4 CG iterations with a factorization at its start point, but
    /// 22.7 CG and 0.54 factorizations when it refactorizes every other blend. Rotating the
    /// kept factorization to the iterates, `R H⁰⁻¹ Rᵀ` with `R` the per-vertex best-fit
    /// rotations of each vertex's spring neighbourhood (a spring's stiffness block turns with
    /// it), helps but not enough: every other blend 13.4 CG and 0.54 factorizations per step,
    /// 0.031 CPU seconds against 0.022 with a factorization per blend; every third 17.7 and
    /// 0.37; kept until CG slows down 20.8 and 0.29, and on the Face-size model 31.1 and 0.80
    /// against 16.2 and 1.26. Between blends more changes than the rotation: the rest
    /// lengths, hence every spring's tension and stiffness.)
    pub fn refresh(&mut self) {
        self.stale = true;
    }

    /// Entries stored in the Cholesky factor.
    pub fn factor_nnz(&self) -> usize {
        self.factor.nnz()
    }

    /// Entries of the lower triangle of the stiffness matrix.
    pub fn matrix_nnz(&self) -> usize {
        self.a.val().len()
    }

    /// Move the free vertices of `x` to an equilibrium of `system` (which must be the network
    /// this was built for); vertices with `fixed[v]` stay where they are. Fails only when the
    /// network is singular beyond repair or the iterates stop being finite.
    pub fn solve(&mut self, system: &SpringSystem, x: &mut [Point], fixed: &[bool], settings: &NewtonSettings) -> Result<NewtonReport> {
        let start = std::time::Instant::now();
        assert_eq!(system.ends.len(), self.block_offset.len(), "the network this solver was built for");
        assert!(x.len() == self.vertex_count && fixed.len() == self.vertex_count);
        let n = self.vertex_count;
        let mut report = NewtonReport::default();
        let mut energy = system.energy(x);
        let mut exact = settings.start_exact;
        let mut previous_step = f64::INFINITY;
        for _ in 0..settings.max_iterations {
            settings.budget.check_time("mass-spring blend", || format!("after {} Newton iterations of an equilibrium", report.iterations))?;
            let mut gradient = std::mem::take(&mut self.gradient);
            system.gradient(x, &mut gradient);
            for v in 0..n {
                for c in 0..3 {
                    self.rhs[3 * v + c] = if fixed[v] { 0.0 } else { -gradient[v][c] };
                }
            }
            self.gradient = gradient;
            let used = self.direction(system, x, fixed, exact, settings.forcing, &mut report)?;
            if used == Definiteness::Exact {
                report.exact_iterations += 1;
            }
            let dx = &self.dx;
            let mut step: f64 = 0.0;
            let mut slope = 0.0;
            for v in 0..n {
                step = step.max(norm([dx[3 * v], dx[3 * v + 1], dx[3 * v + 2]]));
            }
            for u in 0..3 * n {
                slope -= self.rhs[u] * dx[u];
            }
            report.iterations += 1;
            report.last_step = step;
            if !step.is_finite() {
                return Err(Error::general(
                    "the mass-spring equilibrium diverged (a Newton step is not finite)",
                    "check the targets for coincident or degenerate vertices, and that the fixed vertices or anchor hold the body",
                ));
            }
            let stalled = used == Definiteness::Exact && step <= FLOOR_FACTOR * settings.tolerance && step > 0.5 * previous_step;
            previous_step = step;
            if step <= settings.tolerance || stalled {
                for v in 0..n {
                    for c in 0..3 {
                        x[v][c] += dx[3 * v + c];
                    }
                }
                energy = system.energy(x);
                report.converged = true;
                report.at_rounding_floor = step > settings.tolerance;
                break;
            }
            // Backtracking (Armijo) on the energy. Near the solution the decrease falls below
            // the rounding of E (a sum of nonnegative terms): allow that much slack.
            let slack = 16.0 * f64::EPSILON * energy;
            let mut s = 1.0;
            let mut accepted = false;
            for _ in 0..60 {
                for v in 0..n {
                    self.trial[v] = std::array::from_fn(|c| x[v][c] + s * dx[3 * v + c]);
                }
                let e = system.energy(&self.trial);
                if e <= energy + 1e-4 * s * slope + slack {
                    x.copy_from_slice(&self.trial);
                    energy = e;
                    accepted = true;
                    break;
                }
                s *= 0.5;
                report.halvings += 1;
            }
            if !accepted {
                // No decrease along a descent direction: the energy is flat to rounding here.
                break;
            }
            exact = s == 1.0 && step < settings.exact_below;
        }
        report.energy = energy;
        report.seconds = start.elapsed().as_secs_f64();
        Ok(report)
    }

    /// Solve `H d = b` on the free vertices for the stiffness `H` at `x` (exact where it is
    /// positive definite there, else clamped), with `b` given per vertex in `rhs` and replaced
    /// by `d` (fixed vertices get 0). The tangent of a family of equilibria uses this.
    pub(crate) fn linear_solve(
        &mut self,
        system: &SpringSystem,
        x: &[Point],
        fixed: &[bool],
        rhs: &mut [Point],
        tolerance: f64,
    ) -> Result<NewtonReport> {
        let start = std::time::Instant::now();
        let mut report = NewtonReport::default();
        for v in 0..self.vertex_count {
            for c in 0..3 {
                self.rhs[3 * v + c] = if fixed[v] { 0.0 } else { rhs[v][c] };
            }
        }
        let used = self.direction(system, x, fixed, true, tolerance, &mut report)?;
        if used == Definiteness::Exact {
            report.exact_iterations += 1;
        }
        for v in 0..self.vertex_count {
            rhs[v] = std::array::from_fn(|c| self.dx[3 * v + c]);
        }
        report.seconds = start.elapsed().as_secs_f64();
        Ok(report)
    }

    /// Minimize `Σ k_q/2 |x_i - x_j|²` over the free vertices (every rest length 0): the
    /// harmonic extension of the fixed vertices' values, weighted by the spring constants.
    /// Used on displacement fields to start solves in a nearby pose.
    pub fn harmonic(&mut self, ends: &[[u32; 2]], stiffness: &[f64], x: &mut [Point], fixed: &[bool]) -> Result<()> {
        let zero = vec![0.0; ends.len()];
        let system = SpringSystem { ends, rest: &zero, stiffness };
        // The energy is quadratic: one Newton step is exact (to the CG tolerance).
        let settings =
            NewtonSettings { tolerance: 0.0, max_iterations: 1, exact_below: 0.0, start_exact: true, forcing: 1e-10, budget: Budget::default() };
        self.solve(&system, x, fixed, &settings).map(|_| ())
    }

    /// `dx = H⁻¹ rhs` on the free unknowns, `H` exact when `exact` and positive definite, else
    /// clamped. Returns the matrix used.
    fn direction(
        &mut self,
        system: &SpringSystem,
        x: &[Point],
        fixed: &[bool],
        exact: bool,
        tolerance: f64,
        report: &mut NewtonReport,
    ) -> Result<Definiteness> {
        let mut used = if exact { Definiteness::Exact } else { Definiteness::Clamped };
        self.assemble(system, x, fixed, used);
        if !self.factored || self.stale {
            self.refactor(system, x, fixed, &mut used, report)?;
        }
        let mut fresh = false;
        for _ in 0..4 {
            match self.cg(fixed, tolerance, if fresh { 4 * CG_MAX } else { CG_MAX }, report) {
                Cg::Converged(k) => {
                    self.stale = k > CG_REFRESH;
                    // A positive definite H gives a descent direction; an exact H that CG found
                    // no negative curvature in may still be indefinite: check.
                    let descent: f64 = self.rhs.iter().zip(&self.dx).map(|(b, d)| b * d).sum();
                    if used == Definiteness::Exact && (descent.is_nan() || descent <= 0.0) {
                        report.exact_failures += 1;
                        used = Definiteness::Clamped;
                        self.assemble(system, x, fixed, used);
                        continue;
                    }
                    return Ok(used);
                }
                Cg::NegativeCurvature if used == Definiteness::Exact => {
                    report.exact_failures += 1;
                    used = Definiteness::Clamped;
                    self.assemble(system, x, fixed, used);
                }
                Cg::NegativeCurvature | Cg::NotConverged => {
                    self.refactor(system, x, fixed, &mut used, report)?;
                    fresh = true;
                }
            }
        }
        Err(Error::general(
            "the mass-spring stiffness system could not be solved (conjugate gradients failed with a fresh factorization)",
            "check the targets for non-finite, coincident or degenerate vertices",
        ))
    }

    /// Factorize the assembled matrix: as is if positive definite; an exact one that is not is
    /// reassembled clamped; a clamped one that is not is shifted.
    fn refactor(&mut self, system: &SpringSystem, x: &[Point], fixed: &[bool], used: &mut Definiteness, report: &mut NewtonReport) -> Result<()> {
        let start = std::time::Instant::now();
        report.factorizations += 1;
        let mut ok = self.factor.factor(&self.a);
        if !ok && *used == Definiteness::Exact {
            report.exact_failures += 1;
            *used = Definiteness::Clamped;
            self.assemble(system, x, fixed, *used);
            report.factorizations += 1;
            ok = self.factor.factor(&self.a);
        }
        if !ok {
            report.regularized += 1;
            report.factorizations += self.factor_shifted(fixed)?;
        }
        self.factored = true;
        self.stale = false;
        report.factor_seconds += start.elapsed().as_secs_f64();
        Ok(())
    }

    /// Preconditioned conjugate gradients for `A dx = rhs` from `dx = 0`, the preconditioner
    /// being the current factorization with fixed unknowns projected out.
    fn cg(&mut self, fixed: &[bool], tolerance: f64, max: usize, report: &mut NewtonReport) -> Cg {
        let m = 3 * self.vertex_count;
        self.dx.fill(0.0);
        self.r.copy_from_slice(&self.rhs);
        let norm_b = dot(&self.rhs, &self.rhs).sqrt();
        if norm_b == 0.0 {
            return Cg::Converged(0);
        }
        self.precondition(fixed, report);
        self.p.copy_from_slice(&self.z);
        let mut rz = dot(&self.r, &self.z);
        for k in 1..=max {
            report.cg_iterations += 1;
            symmetric_product(&self.a, &self.p, &mut self.hp);
            let php = dot(&self.p, &self.hp);
            if php.is_nan() || php <= 0.0 {
                return Cg::NegativeCurvature;
            }
            let alpha = rz / php;
            for u in 0..m {
                self.dx[u] += alpha * self.p[u];
                self.r[u] -= alpha * self.hp[u];
            }
            if dot(&self.r, &self.r).sqrt() <= tolerance * norm_b {
                return Cg::Converged(k);
            }
            self.precondition(fixed, report);
            let rz_next = dot(&self.r, &self.z);
            let beta = rz_next / rz;
            rz = rz_next;
            for u in 0..m {
                self.p[u] = self.z[u] + beta * self.p[u];
            }
        }
        Cg::NotConverged
    }

    /// `z = P⁻¹ r` with the fixed unknowns zeroed (so the iterates never move them).
    fn precondition(&mut self, fixed: &[bool], report: &mut NewtonReport) {
        let start = std::time::Instant::now();
        self.factor.solve(&self.r, &mut self.z);
        for v in 0..self.vertex_count {
            if fixed[v] {
                self.z[3 * v..3 * v + 3].fill(0.0);
            }
        }
        report.solve_seconds += start.elapsed().as_secs_f64();
    }

    /// The lower triangle of `H` (or its clamped form) with identity rows for fixed vertices.
    fn assemble(&mut self, system: &SpringSystem, x: &[Point], fixed: &[bool], definiteness: Definiteness) {
        let (cp, values) = (&self.col_ptr, self.a.val_mut());
        values.fill(0.0);
        for (q, &[i, j]) in system.ends.iter().enumerate() {
            let (i, j) = (i as usize, j as usize);
            let (fi, fj) = (fixed[i], fixed[j]);
            if fi && fj {
                continue;
            }
            let d = crate::algorithms::geometry::sub(x[i], x[j]);
            let h = spring_hessian(d, system.rest[q], system.stiffness[q], definiteness);
            for c in 0..3 {
                for r in c..3 {
                    if !fi {
                        values[cp[3 * i + c] + (r - c)] += h[r][c];
                    }
                    if !fj {
                        values[cp[3 * j + c] + (r - c)] += h[r][c];
                    }
                }
                if !fi && !fj {
                    let start = cp[3 * i + c] + (3 - c) + 3 * self.block_offset[q];
                    for r in 0..3 {
                        values[start + r] = -h[r][c];
                    }
                }
            }
        }
        for v in 0..self.vertex_count {
            if fixed[v] {
                for c in 0..3 {
                    values[cp[3 * v + c]] = 1.0;
                }
            }
        }
    }

    /// Factor `H + μ I` (free rows) for growing `μ`, starting from a tiny fraction of the
    /// largest diagonal entry. Returns the factorizations it took.
    fn factor_shifted(&mut self, fixed: &[bool]) -> Result<usize> {
        let diagonal_max = (0..3 * self.vertex_count).map(|u| self.a.val()[self.col_ptr[u]].abs()).fold(0.0, f64::max);
        let mut shift = 1e-12 * diagonal_max.max(f64::MIN_POSITIVE);
        for attempt in 1..=8 {
            for v in (0..self.vertex_count).filter(|&v| !fixed[v]) {
                for c in 0..3 {
                    self.a.val_mut()[self.col_ptr[3 * v + c]] += shift;
                }
            }
            if self.factor.factor(&self.a) {
                return Ok(attempt);
            }
            shift *= 100.0;
        }
        Err(Error::general(
            "the mass-spring stiffness matrix cannot be factorized even with a diagonal shift",
            "check the targets for non-finite or coincident vertices",
        ))
    }
}

/// A numeric Cholesky factorization on a fixed symbolic analysis, kept in single precision
/// when that succeeds: it only preconditions conjugate gradients run in double precision, so
/// its rounding costs an iteration or two, while its factorization and solves move half the
/// bytes and use twice the SIMD lanes. A matrix single precision cannot factor (positive
/// definite, but too ill-conditioned for 24 bits) is factored in double.
struct Factor {
    symbolic: SymbolicCholesky<usize>,
    par: Par,
    single: Vec<f32>,
    /// Allocated on first use.
    double: Vec<f64>,
    matrix_single: Vec<f32>,
    precision: Precision,
    rhs_single: Mat<f32>,
    rhs_double: Mat<f64>,
    /// Work space of the numeric factorizations and solves, kept between calls (the
    /// factorization's can be tens of megabytes).
    memory: MemBuffer,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Precision {
    Single,
    Double,
}

impl Factor {
    /// Analyse the pattern of `a` (lower triangle) in the order `perm` (`perm[k]` = the unknown
    /// eliminated k-th); numeric factorizations run on `par`, solves sequentially (faster for
    /// one right-hand side on two cores).
    fn new(a: &SparseColMat<usize, f64>, perm: &[usize], par: Par) -> Factor {
        let n = a.nrows();
        let mut inverse = vec![0usize; n];
        for (k, &p) in perm.iter().enumerate() {
            inverse[p] = k;
        }
        let ordering = SymmetricOrdering::Custom(PermRef::new_checked(perm, &inverse, n));
        let symbolic = factorize_symbolic_cholesky(a.symbolic(), Side::Lower, ordering, CholeskySymbolicParams::default())
            .expect("symbolic Cholesky of a well-formed pattern");
        Factor {
            single: vec![0.0; symbolic.len_val()],
            double: Vec::new(),
            matrix_single: vec![0.0; a.val().len()],
            precision: Precision::Single,
            rhs_single: Mat::zeros(n, 1),
            rhs_double: Mat::zeros(n, 1),
            memory: MemBuffer::new(StackReq::any_of(&[
                symbolic.factorize_numeric_llt_scratch::<f64>(par, Default::default()),
                symbolic.solve_in_place_scratch::<f64>(1, Par::Seq),
            ])),
            symbolic,
            par,
        }
    }

    fn nnz(&self) -> usize {
        self.symbolic.len_val()
    }

    /// Factorize `a` (same pattern); false when it is not numerically positive definite.
    fn factor(&mut self, a: &SparseColMat<usize, f64>) -> bool {
        for (s, &d) in self.matrix_single.iter_mut().zip(a.val()) {
            *s = d as f32;
        }
        let single = SparseColMatRef::new(a.symbolic(), &self.matrix_single);
        if numeric(&self.symbolic, &mut self.single, single, self.par, &mut self.memory) {
            self.precision = Precision::Single;
            return true;
        }
        if self.double.is_empty() {
            self.double = vec![0.0; self.symbolic.len_val()];
        }
        self.precision = Precision::Double;
        numeric(&self.symbolic, &mut self.double, a.as_ref(), self.par, &mut self.memory)
    }

    /// `z = A⁻¹ r` with the current factor.
    fn solve(&mut self, r: &[f64], z: &mut [f64]) {
        let stack = MemStack::new(&mut self.memory);
        match self.precision {
            Precision::Single => {
                for (u, &v) in r.iter().enumerate() {
                    self.rhs_single[(u, 0)] = v as f32;
                }
                LltRef::new(&self.symbolic, &self.single).solve_in_place_with_conj(Conj::No, self.rhs_single.as_mut(), Par::Seq, stack);
                for (u, v) in z.iter_mut().enumerate() {
                    *v = self.rhs_single[(u, 0)] as f64;
                }
            }
            Precision::Double => {
                for (u, &v) in r.iter().enumerate() {
                    self.rhs_double[(u, 0)] = v;
                }
                LltRef::new(&self.symbolic, &self.double).solve_in_place_with_conj(Conj::No, self.rhs_double.as_mut(), Par::Seq, stack);
                for (u, v) in z.iter_mut().enumerate() {
                    *v = self.rhs_double[(u, 0)];
                }
            }
        }
    }
}

/// One numeric LLᵀ factorization into `values`; false when not positive definite.
fn numeric<T: faer::traits::ComplexField>(
    symbolic: &SymbolicCholesky<usize>,
    values: &mut [T],
    a: SparseColMatRef<'_, usize, T>,
    par: Par,
    memory: &mut MemBuffer,
) -> bool
where
    T::Real: Default,
{
    symbolic.factorize_numeric_llt(values, a, Side::Lower, LltRegularization::default(), par, MemStack::new(memory), Default::default()).is_ok()
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// `y = A x` for a symmetric `A` stored as its lower triangle.
fn symmetric_product(a: &SparseColMat<usize, f64>, x: &[f64], y: &mut [f64]) {
    let (cp, ri, val) = (a.symbolic().col_ptr(), a.symbolic().row_idx(), a.val());
    y.fill(0.0);
    for c in 0..x.len() {
        let xc = x[c];
        let mut acc = 0.0;
        for k in cp[c]..cp[c + 1] {
            let (r, v) = (ri[k], val[k]);
            y[r] += v * xc;
            if r != c {
                acc += v * x[r];
            }
        }
        y[c] += acc;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::algorithms::geometry::sub;
    use crate::algorithms::massspring::energy::Definiteness;
    use crate::algorithms::massspring::springs::{Bending, Springs};
    use crate::algorithms::massspring::testing::hessian_columns;
    use crate::algorithms::procedural::icosphere;
    use crate::support::testing::Rng;

    #[test]
    fn assembled_matrix_is_the_hessian_with_identity_rows_for_fixed_vertices() {
        let sphere = icosphere(1);
        let n = sphere.positions.len();
        let springs = Springs::build(n, &sphere.triangles, &[], Bending::Hinge);
        let mut rng = Rng::new(1);
        let x: Vec<Point> = sphere.positions.iter().map(|p| p.map(|c| c + rng.uniform(-0.1, 0.1))).collect();
        let rest: Vec<f64> = springs.lengths(&sphere.positions);
        let stiffness: Vec<f64> = rest.iter().map(|r| 1.0 / r).collect();
        let sys = SpringSystem { ends: &springs.ends, rest: &rest, stiffness: &stiffness };
        let mut newton = Newton::new(&springs, &sphere.positions);
        let fixed: Vec<bool> = (0..n).map(|v| v % 5 == 0).collect();
        for definiteness in [Definiteness::Exact, Definiteness::Clamped] {
            newton.assemble(&sys, &x, &fixed, definiteness);
            let a = &newton.a;
            // Dense lower triangle -> full symmetric matrix.
            let mut dense = vec![vec![0.0; 3 * n]; 3 * n];
            let (cp, ri) = (a.symbolic().col_ptr(), a.symbolic().row_idx());
            for c in 0..3 * n {
                for k in cp[c]..cp[c + 1] {
                    dense[ri[k]][c] = a.val()[k];
                    dense[c][ri[k]] = a.val()[k];
                }
            }
            hessian_columns(&sys, &x, definiteness, |v, c, hv| {
                for w in 0..n {
                    for r in 0..3 {
                        let expected = if fixed[v] || fixed[w] {
                            if (v, c) == (w, r) {
                                1.0
                            } else {
                                0.0
                            }
                        } else {
                            hv[w][r]
                        };
                        assert!((dense[3 * w + r][3 * v + c] - expected).abs() < 1e-12, "({w},{r}),({v},{c})");
                    }
                }
            });
        }
    }

    #[test]
    fn equilibrium_has_zero_force_on_free_vertices_and_keeps_fixed_ones() {
        // A sphere whose springs grow towards the top (incompatible rest lengths, as in a
        // blend): Newton finds a point where the free vertices feel no force.
        let sphere = icosphere(2);
        let n = sphere.positions.len();
        let springs = Springs::build(n, &sphere.triangles, &[], Bending::Hinge);
        let rest: Vec<f64> = springs
            .ends
            .iter()
            .zip(springs.lengths(&sphere.positions))
            .map(|(&[i, j], r)| r * (1.0 + 0.1 * (sphere.positions[i as usize][2] + sphere.positions[j as usize][2])))
            .collect();
        let stiffness: Vec<f64> = rest.iter().map(|r| 1.0 / r).collect();
        let sys = SpringSystem { ends: &springs.ends, rest: &rest, stiffness: &stiffness };
        let fixed: Vec<bool> = sphere.positions.iter().map(|p| p[2] < -0.8).collect();
        let mut x = sphere.positions.clone();
        let mut newton = Newton::new(&springs, &sphere.positions);
        let settings =
            NewtonSettings { tolerance: 1e-12, max_iterations: 100, exact_below: 1e-2, start_exact: false, forcing: 1e-8, budget: Budget::default() };
        let report = newton.solve(&sys, &mut x, &fixed, &settings).unwrap();
        assert!(report.converged, "{report:?}");
        assert!(report.exact_iterations > 0, "the exact Hessian is used near the end: {report:?}");
        let mut g = vec![[0.0; 3]; n];
        sys.gradient(&x, &mut g);
        for v in 0..n {
            if fixed[v] {
                assert_eq!(x[v], sphere.positions[v]);
            } else {
                assert!(norm(g[v]) < 1e-10, "vertex {v}: {:?}", g[v]);
            }
        }
        assert!(report.energy < sys.energy(&sphere.positions));
    }

    #[test]
    fn harmonic_extension_of_a_constant_is_that_constant() {
        // A translation of the held vertices extends to the same translation of all (with any
        // spring weights), in one factorization.
        let sphere = icosphere(2);
        let n = sphere.positions.len();
        let springs = Springs::build(n, &sphere.triangles, &[], Bending::None);
        let stiffness: Vec<f64> = springs.lengths(&sphere.positions).iter().map(|r| 1.0 / r).collect();
        let fixed: Vec<bool> = (0..n).map(|v| v % 7 == 0).collect();
        let mut u: Vec<Point> = (0..n).map(|v| if fixed[v] { [0.3, -1.0, 2.0] } else { [0.0; 3] }).collect();
        let mut newton = Newton::new(&springs, &sphere.positions);
        newton.harmonic(&springs.ends, &stiffness, &mut u, &fixed).unwrap();
        // To the accuracy of the conjugate gradients (relative residual 1e-10).
        for p in &u {
            assert!(norm(sub(*p, [0.3, -1.0, 2.0])) < 1e-9, "{p:?}");
        }
    }
}
