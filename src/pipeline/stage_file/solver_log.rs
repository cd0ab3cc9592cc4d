//! The solver's record in a solution: iterations, times, what stopped it (`solver` in
//! `solution.json` and the report).

use serde::{Deserialize, Serialize};

use crate::algorithms::spacetime::solver::{self, IterationSplit};
use crate::pipeline::scene::Method;

/// What the solver did.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SolverLog {
    /// The method that made the trajectory.
    pub method: Method,
    /// Iterations taken (0 for `hermite`).
    pub iterations: usize,
    /// W after each iteration, starting with the initial guess (the hermite baseline).
    pub energy: Vec<f64>,
    /// Wall-clock seconds for the whole solve.
    pub seconds: f64,
    /// Seconds spent assembling and factorizing before the first iteration.
    pub precompute_seconds: f64,
    /// Mean seconds per iteration (local step, residuals, global step).
    pub iteration_seconds: f64,
    /// Free unknowns per coordinate (keyframe positions and velocities).
    pub unknowns: usize,
    /// Steps halved because the full step would have increased W.
    pub halvings: usize,
    /// Whether W settled within the iteration budget (always for `hermite`).
    pub converged: bool,
    /// Why the iteration stopped, in words.
    pub stop_reason: String,
    /// How the global step was solved: `direct` (sparse Cholesky) or `iterative` (conjugate
    /// gradients, when the factor would not fit in the memory budget).
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub linear_solver: String,
    /// W's relative decrease over the last iterations of the stopping rule's window.
    #[serde(default)]
    pub last_decrease: f64,
    /// The predicted further decrease of W (relative to the final W) had the solve gone on,
    /// when the last windows' decreases shrink geometrically.
    #[serde(default)]
    pub predicted_remaining: Option<f64>,
    /// The force scale S at the solution (spacetime only): W with the forces the residual is
    /// the sum of (inertia and damping, gravity, elasticity) squared one by one; `W / S` is the
    /// squared relative size of the residual force.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub force_scale: Option<f64>,
    /// The force scale S at each iterate of `energy` (spacetime only; the last is
    /// `force_scale`): the stopping rule's floor is `settings::NEGLIGIBLE` S at each iteration.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub force_scales: Vec<f64>,
    /// The key times given to the solver.
    #[serde(default)]
    pub input_times: Vec<f64>,
    /// The key times of the solution: the optimized ones with `optimize_timing`, else the
    /// input ones (the trajectory's, repeated here for the report).
    #[serde(default)]
    pub times: Vec<f64>,
    /// Iterations that moved the key times (with `optimize_timing`).
    #[serde(default)]
    pub timing_iterations: usize,
    /// Refactorizations of the global step for new key times.
    #[serde(default)]
    pub refactorizations: usize,
    /// Node-obstacle checks held on an obstacle at the end.
    #[serde(default)]
    pub active_contacts: usize,
    /// The smallest distance of a node to an obstacle over keys and frames (with obstacles).
    #[serde(default)]
    pub clearance: Option<f64>,
    /// How the iterative global step's conjugate-gradient solves went (iterative only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub conjugate_gradients: Option<CgSummary>,
    /// Iterations of the coarse phase, included in `iterations` (0: none ran; spacetime's
    /// `[solver] coarse_samples`). `energy` holds W at `samples` only: the first guess, the
    /// coarse phase's result, then one entry per fine iteration.
    #[serde(default)]
    pub coarse_iterations: usize,
    /// Samples per interval of the coarse phase (0: none ran).
    #[serde(default)]
    pub coarse_samples: usize,
    /// Where the spacetime iterations' time went: W's evaluations and the global step's solves.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub iteration_split: Option<IterationSplit>,
}

impl SolverLog {
    /// The log of a method that does not iterate the spacetime solver (`hermite`, `fit`, and
    /// `mass-spring`, which then sets its own iteration counts): W when it is evaluated, the
    /// wall time, the free unknowns and why it stopped; the key `times` are kept as given.
    pub fn closed_form(method: Method, energy: Vec<f64>, seconds: f64, unknowns: usize, stop_reason: String, times: Vec<f64>) -> SolverLog {
        SolverLog {
            method,
            iterations: 0,
            energy,
            seconds,
            precompute_seconds: 0.0,
            iteration_seconds: 0.0,
            unknowns,
            halvings: 0,
            converged: true,
            stop_reason,
            linear_solver: String::new(),
            last_decrease: 0.0,
            predicted_remaining: None,
            force_scale: None,
            force_scales: Vec::new(),
            input_times: times.clone(),
            times,
            timing_iterations: 0,
            refactorizations: 0,
            active_contacts: 0,
            clearance: None,
            conjugate_gradients: None,
            coarse_iterations: 0,
            coarse_samples: 0,
            iteration_split: None,
        }
    }

    /// The log of a spacetime solve: the solver's own `log`, the key times given to it and
    /// those of its solution, and the force scale S at each iterate (the progress callback's).
    pub fn spacetime(log: solver::Log, input_times: Vec<f64>, times: Vec<f64>, force_scales: Vec<f64>) -> SolverLog {
        let split = log.split;
        SolverLog {
            method: Method::Spacetime,
            iterations: log.iterations,
            seconds: log.seconds,
            precompute_seconds: log.precompute_seconds,
            iteration_seconds: log.iteration_seconds,
            unknowns: log.unknowns,
            halvings: log.halvings,
            converged: log.converged,
            linear_solver: log.linear_solver,
            last_decrease: log.last_decrease,
            predicted_remaining: log.predicted_remaining,
            force_scale: Some(log.force_scale),
            force_scales,
            input_times,
            times,
            timing_iterations: log.timing_iterations,
            refactorizations: log.refactorizations,
            active_contacts: log.active_contacts,
            clearance: log.clearance,
            conjugate_gradients: log.conjugate_gradients.map(|c| CgSummary {
                solves: c.solves,
                iterations: c.iterations,
                capped: c.capped,
                max_iterations: c.max_iterations,
                tolerance: c.tolerance,
                worst_residual: c.worst_residual,
            }),
            coarse_iterations: log.coarse_iterations,
            coarse_samples: log.coarse_samples,
            iteration_split: Some(split),
            stop_reason: log.stop_reason,
            energy: log.energy,
        }
    }
}

/// The conjugate-gradient solves of an iterative global step.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CgSummary {
    /// Global-step solves (one per iteration of the solver, and per constraint projection).
    pub solves: usize,
    /// CG iterations over all solves.
    pub iterations: usize,
    /// Solves that stopped at `max_iterations` with the residual above `tolerance`.
    pub capped: usize,
    /// The iteration cap of one solve.
    pub max_iterations: usize,
    /// The relative residual a solve stops at.
    pub tolerance: f64,
    /// The largest final relative residual of any solve.
    pub worst_residual: f64,
}
