//! What a solve did: the solver's log and where its iterations' time went.

use serde::{Deserialize, Serialize};

use super::super::global_step::CgLog;

/// What the iteration did.
#[derive(Debug, Clone, PartialEq)]
pub struct Log {
    /// Iterations taken (steps accepted).
    pub iterations: usize,
    /// W after each iteration, starting with the initial guess (the hermite baseline).
    pub energy: Vec<f64>,
    /// Wall-clock seconds for the whole solve.
    pub seconds: f64,
    /// Seconds spent assembling and factorizing before the first iteration.
    pub precompute_seconds: f64,
    /// Mean seconds per iteration (local step, residuals, global step).
    pub iteration_seconds: f64,
    /// Free unknowns per coordinate.
    pub unknowns: usize,
    /// Steps halved because the full step would have increased W.
    pub halvings: usize,
    /// Whether W settled (or nothing was left to optimize) within the iteration budget.
    pub converged: bool,
    /// Why the iteration stopped, in words.
    pub stop_reason: String,
    /// How the global step was solved: `direct` or `iterative` (over the memory budget).
    pub linear_solver: String,
    /// W's decrease over the last [`WINDOW`](super::super::settings::WINDOW) iterations when the solve stopped, relative to
    /// the stopping rule's reference `W + negligible × S`.
    pub last_decrease: f64,
    /// The predicted further decrease of W, relative to the same reference, had the iteration
    /// gone on (the last two windows' decreases extrapolated geometrically; `None` when they
    /// do not shrink, or the solve stopped before two windows).
    pub predicted_remaining: Option<f64>,
    /// The force scale S at the final iterate ([`Evaluation::force_scale`](super::super::objective::Evaluation::force_scale)): `W / S` is the
    /// squared relative size of the residual force.
    pub force_scale: f64,
    /// Quasi-Newton iterations that moved the key times.
    pub timing_iterations: usize,
    /// With the key times optimized: the key times after each iteration, starting with the
    /// given ones (one entry per entry of `energy`); empty otherwise.
    pub times: Vec<Vec<f64>>,
    /// Numeric refactorizations of the global step for new key times.
    pub refactorizations: usize,
    /// Node-obstacle checks held on an obstacle at the end.
    pub active_contacts: usize,
    /// The smallest distance of any node to any obstacle at any check instant (none without
    /// obstacles).
    pub clearance: Option<f64>,
    /// How the iterative global step's CG solves went (none for a direct step).
    pub conjugate_gradients: Option<CgLog>,
    /// Iterations of the coarse phase (0 when none ran); they are in `iterations`, not in
    /// `energy`, whose entries are W at the configured samples: the initial guess, the coarse
    /// phase's result, then one per fine iteration.
    pub coarse_iterations: usize,
    /// Samples per interval of the coarse phase (0 when none ran).
    pub coarse_samples: usize,
    /// Where the iterations' time went: W's evaluations and the global step's solves.
    pub split: IterationSplit,
}

/// Where a solve's iterations spend their time (wall seconds summed over the solve, the first
/// guess's evaluation included, the precompute not): what an iteration costs, taken apart.
/// The remainder of the iterations' time (the L-BFGS two-loop recursion, gathering and
/// scattering the unknowns, Gauss-Newton products) is `iteration time - evaluation_seconds -
/// solve_seconds`. Timing only: nothing here changes a result. The stage file and the report
/// hold it as is (`solver.iteration_split`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct IterationSplit {
    /// Evaluations of W (the local step and the residuals): the first guess, every trial
    /// point of every line search.
    pub evaluations: usize,
    /// How many of them also formed the projections' Jacobians and the exact gradient (the
    /// quasi-Newton phase's).
    pub exact_evaluations: usize,
    /// Seconds in those evaluations.
    pub evaluation_seconds: f64,
    /// Solves with the global step's matrix or the quasi-Newton model (one per local/global
    /// step and per quasi-Newton direction, one per three active rows).
    pub solves: usize,
    /// Seconds in those solves.
    pub solve_seconds: f64,
}
