//! The global step: with the projections fixed, W is quadratic in the keyframe unknowns, with
//! a Hessian that does not depend on the iteration. It is assembled and factorized once.
//!
//! Structure: per sample, `∂f/∂u_j = c_j M + l_j L` (see [`super::objective`]), so in the
//! `M⁻¹` norm the Hessian block of time slots (σ, σ') is
//!
//! ```text
//! Σ_s dτ (c_σ M + l_σ L) M⁻¹ (c_σ' M + l_σ' L)
//!   = C_MM[σ,σ'] M + C_ML[σ,σ'] L + C_KK[σ,σ'] L M⁻¹ L
//! ```
//!
//! with three small dense matrices over time slots and three fixed sparse matrices over
//! nodes (`M⁻¹` in the middle of `L M⁻¹ L` skips the supports, whose rows W leaves out). The proximal regularization `(1/h⁴) Σ dτ Bᵀ M B` adds `C_KK / h⁴` to `C_MM`
//! (in the M⁻¹ norm of W, 1/h⁴ is the weight whose units make h a time). The
//! matrix restricted to the free unknowns is written straight into compressed columns in
//! node-major order (rows come out sorted; no triplet sort), and the three coordinates are
//! three right-hand sides of one factorization.
//!
//! Cost: `L M⁻¹ L` couples nodes two rings apart, so the factor fills in heavily (50M entries
//! for 25k unknowns on a 2.6k-node body). Every node's free slots stay together: the
//! fill-reducing order is found on the node graph ([`fill_reducing_order_of`]), the numeric
//! factorization is supernodal over faer's symbolic analysis, the two halves of the
//! elimination tree on two threads above 1 G predicted flops ([`Cholesky::refactor`]), and the
//! solves sweep the factor once per direction for all three coordinates, on two threads
//! ([`Cholesky::solve_rows3`]).
//!
//! Bounded: the factor's size and time are predicted from the symbolic count before anything
//! is allocated ([`fill_reducing_order_of`]), and when the predicted peak is over the memory
//! budget the step is solved by preconditioned conjugate gradients instead (per-key block
//! Jacobi, warm-started from the previous solution; see [`crate::algorithms::physics::pcg`]): slower per
//! iteration, but in memory that grows like the matrix, not like its factor.
//!
//! The step itself is the minimizer of the quadratic model plus the proximal term around the
//! current iterate `q`: `q + Δ` with `(H + P) Δ = -∇W`. At a fixed point `∇W = 0`, so the
//! regularization never moves the fixed point; it only damps the path to it.

mod assembly;
mod cost_model;
mod fill_order;
mod iterative;
#[cfg(test)]
mod tests;

pub use assembly::assemble;
pub use cost_model::{choose, memory_bytes, predicted_peak_bytes, ModalSize, BYTES_PER_FACTOR_ENTRY};
pub use fill_order::{fill_reducing_order_of, FillReducingOrder, NodeOrders, KEY_SEPARATOR_MAX_GAIN, KEY_SEPARATOR_MIN_KEYS};
pub use iterative::CgLog;

use faer::Par;

use crate::algorithms::geometry::Point;
use crate::algorithms::physics::cholesky::{Cholesky, PARALLEL_FACTOR_FLOPS};
use crate::algorithms::physics::ordering::{Cost, FillOrdering};
use crate::algorithms::spacetime::modal::{ModalStep, Modes};
use crate::algorithms::spacetime::objective::Objective;
use crate::algorithms::spacetime::time_coefficients::{proximal_weight, TimeCoefficients};
use crate::algorithms::spacetime::unknowns::Unknowns;
use crate::support::budget::Budget;
use crate::support::error::{Error, Result};
use assembly::*;
use cost_model::*;
use fill_order::*;
use iterative::*;

/// What the precomputation built, for the report and the benchmark.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GlobalStats {
    /// Free unknowns per coordinate.
    pub unknowns: usize,
    /// Stored entries of the lower triangle of the matrix.
    pub matrix_nnz: usize,
    /// Stored entries of the Cholesky factor.
    pub factor_nnz: usize,
    /// The fill-reducing ordering that was used (see `fill_reducing_order_of`).
    pub ordering: &'static str,
    /// Coefficients and assembly of the matrix.
    pub assemble_seconds: f64,
    /// Ordering, symbolic analysis and numeric factorization (or the preconditioner's).
    pub factor_seconds: f64,
    /// The direct factor's predicted peak memory in bytes (see `predicted_peak_bytes`), and
    /// its predicted factorization time.
    pub predicted_bytes: f64,
    /// See `predicted_bytes`.
    pub predicted_seconds: f64,
    /// `"direct"` (sparse Cholesky), or `"iterative"` when the predicted peak was over the
    /// memory budget or the predicted time of the iterative step was lower (`choose`).
    pub linear_solver: &'static str,
    /// The iterative step's predicted peak memory and time (see `choose`).
    pub predicted_iterative_bytes: f64,
    /// See `predicted_iterative_bytes`.
    pub predicted_iterative_seconds: f64,
    /// The modal step's predicted peak memory and time (see `choose`; 0 when there are no unknowns).
    pub predicted_modal_bytes: f64,
    /// See `predicted_modal_bytes`.
    pub predicted_modal_seconds: f64,
}

/// The global step's three ways to invert its matrix.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Method {
    /// Sparse Cholesky of the assembled matrix.
    Direct,
    /// The body's vibration modes ([`super::modal`]).
    Modal,
    /// Conjugate gradients with the per-key blocks.
    Iterative,
}

/// How the global step is inverted.
enum Inverse {
    Direct(Box<Cholesky>),
    Modal(Box<ModalStep>),
    Iterative(Box<Iterative>),
}

/// The normal matrix of the free unknowns, factorized: solves the global step.
pub struct GlobalStep {
    unknowns: Unknowns,
    /// None when there are no unknowns.
    cholesky: Option<Inverse>,
    /// The budget it was built under, its memory resolved to bytes.
    budget: Budget,
    /// Which time-slot pairs the matrix couples ([`coupling`]): the matrix pattern depends on
    /// the time coefficients only through this, so equal couplings mean equal patterns.
    coupling: Vec<(bool, bool)>,
    /// What the precomputation built.
    pub stats: GlobalStats,
}

/// How [`GlobalStep::retime`] rebuilt the factorization.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Retimed {
    /// Seconds assembling the matrix (0 for the modal step, whose modes do not change).
    pub assemble_seconds: f64,
    /// Seconds refactorizing it (for the modal step: rebuilding its per-mode systems).
    pub factor_seconds: f64,
    /// Numeric refactorization on the kept symbolic analysis (false: a fresh factorization,
    /// because a time coefficient cancelled exactly and the pattern changed).
    pub reused_symbolic: bool,
}

impl GlobalStep {
    /// Assemble and factorize under the default budget (60% of the available memory, no time
    /// limit). `regularization` is the proximal time scale h (0 = off).
    pub fn new(objective: &Objective, unknowns: Unknowns, regularization: f64) -> Result<GlobalStep> {
        GlobalStep::within(objective, unknowns, regularization, &Budget::default())
    }

    /// Assemble, and factorize when the predicted peak fits in the budget's memory
    /// ([`memory_bytes`]); otherwise prepare the iterative step. Err when the step is predicted
    /// to take longer than the budget's time left.
    pub fn within(objective: &Objective, unknowns: Unknowns, regularization: f64, budget: &Budget) -> Result<GlobalStep> {
        GlobalStep::build(objective, unknowns, regularization, budget, None)
    }

    /// [`GlobalStep::within`], inverted by `method` when given (whatever the cost model says).
    pub fn build(objective: &Objective, unknowns: Unknowns, regularization: f64, budget: &Budget, method: Option<Method>) -> Result<GlobalStep> {
        let forced = method;
        // Resolved once: a rebuild for new key times chooses under the same bytes.
        let bytes = memory_bytes(budget);
        let budget = budget.with_max_memory(bytes);
        let proximal = proximal_weight(objective, regularization);
        if proximal == 0.0 && unknowns.count() > 0 && !unknowns.any_position_fixed() {
            // Singular by construction; a factorization may still pass on roundoff pivots.
            return Err(Error::general(
                "the spacetime system is singular: no keyframe position is held and regularization = 0, so moving the whole animation costs nothing",
                "fix some vertices at one key (`fixed`), or set [solver] regularization > 0 (e.g. 0.1)",
            ));
        }
        let t0 = std::time::Instant::now();
        let coefficients = TimeCoefficients::new(objective, proximal);
        let dim = unknowns.count();
        if dim == 0 {
            let stats = GlobalStats {
                unknowns: 0,
                matrix_nnz: 0,
                factor_nnz: 0,
                ordering: "none",
                assemble_seconds: 0.0,
                factor_seconds: 0.0,
                predicted_bytes: 0.0,
                predicted_seconds: 0.0,
                linear_solver: "none",
                predicted_iterative_bytes: 0.0,
                predicted_iterative_seconds: 0.0,
                predicted_modal_bytes: 0.0,
                predicted_modal_seconds: 0.0,
            };
            return Ok(GlobalStep { unknowns, cholesky: None, budget, coupling: coupling(&coefficients), stats });
        }
        let a = assemble(objective, &unknowns, &coefficients);
        let assemble_seconds = t0.elapsed().as_secs_f64();
        let t1 = std::time::Instant::now();
        // One node graph and its two orders for both candidates' orders.
        let node_orders = NodeOrders::new(&a, &unknowns, &objective.elastic.rest);
        let (block_order, block_cost) = key_block_order(&node_orders, &unknowns);
        let size = modal_size(objective, &unknowns);
        // The key-separator order only where the direct step could use it: even cut by
        // KEY_SEPARATOR_MAX_GAIN and factorized at the parallel rate, would the node order's
        // cost make the direct step the choice? When not, the choice below is the same with or
        // without it.
        let could_be_direct = |node: &Cost| match forced {
            Some(m) => m == Method::Direct,
            None => {
                let optimistic = Cost { flops: node.flops / KEY_SEPARATOR_MAX_GAIN, entries: node.entries / KEY_SEPARATOR_MAX_GAIN };
                choose(&optimistic, &block_cost, Some(&size), true, bytes).0 == Method::Direct
            }
        };
        let order = fill_reducing_order_of(&a, &unknowns, &node_orders, could_be_direct);
        drop(node_orders);
        // Two threads pay off only for large factorizations.
        let parallel = order.cost.flops > PARALLEL_FACTOR_FLOPS;
        let par = if parallel { Par::rayon(0) } else { Par::Seq };
        let (
            mut method,
            [(predicted_seconds, predicted_bytes), (predicted_modal_seconds, predicted_modal_bytes), (predicted_iterative_seconds, predicted_iterative_bytes)],
        ) = choose(&order.cost, &block_cost, Some(&size), parallel, bytes);
        if let Some(forced) = forced {
            method = forced;
        }
        let singular = || {
            Error::general(
                "the spacetime system is singular: some motion (e.g. drifting or spinning freely) costs nothing",
                "fix some vertices at one key (`fixed`), or set [solver] regularization > 0 (e.g. 0.1)",
            )
        };
        let (solver_name, predicted) = match method {
            Method::Direct => ("the solve's global steps (a sparse factorization and its solves)", predicted_seconds),
            Method::Modal => ("the solve's global steps (the body's vibration modes)", predicted_modal_seconds),
            Method::Iterative => ("the solve's global steps (conjugate gradients)", predicted_iterative_seconds),
        };
        budget.check_predicted_time(predicted, solver_name)?;
        let matrix_nnz = a.compute_nnz();
        // The modes never read the assembled matrix: free it before their dense matrices.
        let a = (method != Method::Modal).then_some(a);
        let mut modal = None;
        if method == Method::Modal {
            // A failed eigendecomposition (or a mode that costs nothing) falls back to the
            // next best way.
            // faer's kernels split by a fixed count, not the pool's: the same bytes on any thread count.
            let par = crate::algorithms::physics::fixed_par::par();
            modal =
                Modes::new(objective.elastic, &objective.supports, par).and_then(|modes| ModalStep::new(modes, &coefficients, &unknowns, par)).ok();
            if modal.is_none() {
                if forced.is_some() {
                    return Err(singular());
                }
                method = if predicted_bytes <= bytes as f64 && predicted_seconds <= predicted_iterative_seconds {
                    Method::Direct
                } else {
                    Method::Iterative
                };
            }
        }
        let (inverse, factor_nnz, ordering, linear_solver) = match method {
            Method::Direct => {
                let a = a.unwrap_or_else(|| assemble(objective, &unknowns, &coefficients));
                let cholesky = Cholesky::factor(&a, &FillOrdering::Custom(order.perm), par).map_err(|_| singular())?;
                let nnz = cholesky.factor_nnz();
                (Inverse::Direct(Box::new(cholesky)), nnz, order.name, "direct")
            }
            Method::Modal => (Inverse::Modal(Box::new(modal.expect("built above"))), 0, "vibration modes", "modal"),
            Method::Iterative => {
                let a = a.unwrap_or_else(|| assemble(objective, &unknowns, &coefficients));
                let iterative = Iterative::new(&a, KroneckerSum::new(objective, &unknowns, &coefficients), &block_order).map_err(|_| singular())?;
                let nnz = iterative.preconditioner.factor_nnz();
                (Inverse::Iterative(Box::new(iterative)), nnz, "per-key blocks (preconditioner)", "iterative")
            }
        };
        let stats = GlobalStats {
            unknowns: dim,
            matrix_nnz,
            factor_nnz,
            ordering,
            assemble_seconds,
            factor_seconds: t1.elapsed().as_secs_f64(),
            predicted_bytes,
            predicted_seconds,
            linear_solver,
            predicted_iterative_bytes,
            predicted_iterative_seconds,
            predicted_modal_bytes,
            predicted_modal_seconds,
        };
        Ok(GlobalStep { unknowns, cholesky: Some(inverse), budget, coupling: coupling(&coefficients), stats })
    }

    /// Rebuild for new key times, `objective` holding the samples at those times: the time
    /// coefficients and the matrix values change, the pattern does not (unless a coefficient
    /// cancels exactly), so the factor is recomputed numerically on the kept ordering and
    /// symbolic analysis. With a changed pattern it falls back to [`GlobalStep::new`].
    pub fn retime(&mut self, objective: &Objective, regularization: f64) -> Result<Retimed> {
        let t0 = std::time::Instant::now();
        let proximal = proximal_weight(objective, regularization);
        let coefficients = TimeCoefficients::new(objective, proximal);
        if let Some(Inverse::Modal(modal)) = self.cholesky.as_mut() {
            // The modes do not depend on the times: only the per-mode systems change.
            modal.retime(&coefficients).map_err(|_| {
                Error::general(
                    "the spacetime system became singular at the new key times",
                    "keep [solver] regularization > 0, or raise the minimum interval length",
                )
            })?;
            return Ok(Retimed { assemble_seconds: 0.0, factor_seconds: t0.elapsed().as_secs_f64(), reused_symbolic: true });
        }
        let Some(Inverse::Direct(cholesky)) = self.cholesky.as_mut().filter(|_| coupling(&coefficients) == self.coupling) else {
            *self = GlobalStep::within(objective, self.unknowns.clone(), regularization, &self.budget)?;
            let s = self.stats;
            return Ok(Retimed { assemble_seconds: s.assemble_seconds, factor_seconds: s.factor_seconds, reused_symbolic: false });
        };
        let a = assemble(objective, &self.unknowns, &coefficients);
        let assemble_seconds = t0.elapsed().as_secs_f64();
        let t1 = std::time::Instant::now();
        cholesky.refactor(&a).map_err(|_| {
            Error::general(
                "the spacetime system became singular at the new key times",
                "keep [solver] regularization > 0, or raise the minimum interval length",
            )
        })?;
        Ok(Retimed { assemble_seconds, factor_seconds: t1.elapsed().as_secs_f64(), reused_symbolic: true })
    }

    /// How the iterative step's CG solves went (None for a direct step).
    pub(crate) fn cg_log(&self) -> Option<CgLog> {
        match &self.cholesky {
            Some(Inverse::Iterative(it)) => Some(*it.log.lock().expect("no panic while solving")),
            _ => None,
        }
    }

    /// The free unknowns and their order.
    pub fn unknowns(&self) -> &Unknowns {
        &self.unknowns
    }

    /// The free entries of a per-slot array, in unknown order ([`Unknowns::gather`]).
    pub fn gather(&self, per_slot: &[Vec<Point>]) -> Vec<Point> {
        self.unknowns.gather(per_slot)
    }

    /// A per-slot array from free entries ([`Unknowns::scatter`]).
    pub fn scatter(&self, free: &[Point]) -> Vec<Vec<Point>> {
        self.unknowns.scatter(free)
    }

    /// `x <- (H + P)⁻¹ x` on free entries, the three coordinates as three right-hand sides.
    pub fn apply_inverse(&self, x: &mut [Point]) {
        match &self.cholesky {
            None => {}
            Some(Inverse::Direct(chol)) => chol.solve_rows3(x),
            Some(Inverse::Modal(modal)) => modal.solve(&self.unknowns, x),
            Some(Inverse::Iterative(it)) => it.solve(x),
        }
    }

    /// The step `Δ = -(H + P)⁻¹ ∇W` per slot (zero at fixed entries).
    pub fn step(&self, gradient: &[Vec<Point>]) -> Vec<Vec<Point>> {
        let mut g = self.gather(gradient);
        self.apply_inverse(&mut g);
        g.iter_mut().for_each(|v| *v = crate::algorithms::geometry::scale(*v, -1.0));
        self.scatter(&g)
    }
}
