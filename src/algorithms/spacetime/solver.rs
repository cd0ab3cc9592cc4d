//! The spacetime projective-dynamics iteration: local step, residuals, global step, repeat;
//! then quasi-Newton on the exact W, over the key times too when they are optimized.
//!
//! Starts from the keyframes joined with zero velocities (the hermite baseline), moved out of
//! any obstacle. W is recorded per iteration. It cannot grow: a step that would raise it is
//! halved, and the solve stops where no step lowers it. A NaN is an error naming the
//! iteration, never a result.
//!
//! # When it stops
//!
//! When W decreased by less than `tolerance × (W + negligible × S)` over the last [`WINDOW`]
//! quasi-Newton iterations. S is the force scale ([`Evaluation::force_scale`]): the residual
//! `f = M (ẍ + α ẋ) - M g + (L x - J p)` is a sum of three forces, and S is W with each of
//! them squared on its own, `Σ dτ ½ (|M (ẍ + α ẋ)|² + |M g|² + |L x - J p|²)_{M⁻¹}`. So
//! `0 <= W <= 3 S`, and `W / S` is the squared size of what the forces fail to cancel relative
//! to the forces themselves: a number free of units and of the first guess.
//!
//! - Where the keys cannot be joined by exact dynamics (every paper scene but the bounces),
//!   W levels off at a sizeable part of S (measured `W / S` 0.3 to 1.0 at the stop), the floor
//!   `negligible × S` (1e-3 S) is far below W, and the rule is the relative rate: W fell by
//!   less than `tolerance` of itself. It does not depend on how bad the first guess was (a test
//!   against the initial W stops a solve that started far away early, and one that started
//!   close never).
//! - Where they can (a free fall fitted exactly: BALL, SPOT, a ballistic jump), W goes to 0 and
//!   keeps falling by a large fraction of itself, so a relative rate never fires. Below the
//!   floor W is negligible against the forces of the scene: the rule then asks for a decrease
//!   below `tolerance × negligible × S` over the window, which (W never being negative) it
//!   meets at the latest a window after `W <= tolerance × negligible × S` (by default 1e-6 S:
//!   a residual force of 1e-3 of the forces); a slow solve stops earlier, once its progress
//!   over the window is that small.
//!
//! The log carries the decrease of that last window and a prediction of what is left (the
//! decreases of the last two windows extrapolated as a geometric series; the iteration
//! converges linearly there), both relative to `W + negligible × S`, and S. The defaults are
//! chosen by measurement (see `formats/scene.md`).
//!
//! # Coarse to fine
//!
//! With [`Settings::coarse_samples`] the whole solve first runs with that many samples per
//! interval (to [`Settings::coarse_tolerance`]); the unknowns (key positions and velocities)
//! do not depend on the samples, so its result is a warm start for the solve at
//! [`Settings::samples`], which goes straight to quasi-Newton (fresh curvature pairs) on the
//! coarse phase's factorized matrix (a preconditioner: any positive definite model serves, and
//! one factorization is saved). The warm start is taken only where W at the configured samples
//! is below the first guess's, so that W never increases; [`Log::energy`] is W at the
//! configured samples only. Off by default (measured in `formats/scene.md`: the coarse phase
//! takes about as many iterations as a single-phase solve, so it saves 20-40% of the cost on
//! the paper scenes and nothing on a 20-key body). Not with obstacles or moving key times.
//!
//! # Gauss-Newton steps
//!
//! With [`Settings::step`] = [`Step::GaussNewton`], each quasi-Newton-phase iteration first
//! tries the truncated Gauss-Newton step of [`super::gauss_newton`]: `H d = -g` with `H` the
//! Gauss-Newton Hessian of W (the projections' Jacobians included), solved by CG to the
//! Eisenstat-Walker forcing tolerance, at most [`GAUSS_NEWTON_CG`] products. The same line
//! search on W takes it (W never increases); where it fails, the L-BFGS step is taken instead.
//! CG is preconditioned by the L-BFGS inverse Hessian, the curvature pairs of the last steps
//! on the model Hessian's factor (Morales & Nocedal's automatic preconditioning): the factor
//! alone (the global step's matrix is `H` without the projections' Jacobians, stiffer along
//! bending and twisting) left CG at its cap on 52 of TWIST's 54 steps.
//!
//! Measured side by side (1 thread, `benches/convergence.rs` with `STEPS=1`, load 9 to 15 on
//! 2 cores): it halves the iterations or better, not the cost. A product with `H` costs about
//! 0.6 of an iteration (two stiffness and two projection-Jacobian passes per sample, against
//! one of each and the projections themselves), and a step takes 3 to 8 products.
//!
//! | scene | quasi-Newton: iterations, CPU s | Gauss-Newton: iterations, CPU s (CG products) |
//! |---|---:|---:|
//! | TWIST | 98, 3.59 | 66, 7.55 (199) |
//! | DINO | 130, 5.24 | 38, 9.91 |
//! | the demo | 117, 0.80 | 54, 1.23 (177) |
//! | a 20-key body on 400 nodes (`KEY20-small`) | 98, 14.1 | 65, 33.4 |
//! | the scale benchmark's 20-key 2.6k body (`KEY20-2.6k`) | 202, 175 | 72, 391 (578) |
//!
//! Both stop within the 2% of the W reached at 1e-8 (Gauss-Newton closer: TWIST 0.00% against
//! 0.04%, DINO 0.20% against 0.72%). So [`Step::Auto`] (the default) keeps L-BFGS.
//!
//! # Key times
//!
//! With [`Settings::timing`], the quasi-Newton phase runs on the keyframe unknowns and the
//! interval lengths together: the exact `∂W/∂T_i` comes with the exact gradient (same
//! projection Jacobians), the initial inverse Hessian is the global step's factorization for
//! the keys and the held-keys curvature `∂²W/∂T_i²` ([`super::timing`]) for the times, and the
//! curvature pairs learn how the keys absorb a change of timing (the reduced curvature is far
//! below the held-keys one: 199 vs 3219 on a free fall). So every quasi-Newton iteration is also
//! a timing step, and the times and keys settle together. The factorization depends on the
//! times; it is refactorized (on its kept symbolic analysis) only when an interval has moved by
//! more than [`REFACTOR_CHANGE`] since the last factorization, and is a valid preconditioner
//! in between (the line search keeps W from increasing whatever it is).
//!
//! # Obstacles
//!
//! With [`Settings::contacts`], every node stays outside every obstacle at every key and every
//! frame ([`super::contact`]). The checks a step would cross join an active set held by hard
//! constraints ([`super::active_set`]); a check leaves it when its multiplier says the
//! obstacle would have to pull.

use std::cell::RefCell;
use std::collections::BTreeSet;
use std::time::Instant;

use super::active_set::{Preconditioner, Projection, Row, RowKind};
use super::contact::{At, Check, Contacts};
use super::gauss_newton::{truncated_cg, CgEnd, Forcing, TruncatedCg};
use super::global_step::{CgLog, GlobalStep};
use super::objective::{Evaluation, Objective, Projections};
use super::quasi_newton::{dot, Lbfgs};
use super::sampling::{sample_counts, samples, TimeSlots};
use super::tangent_step::TangentStep;
use super::timing::{safe_curvature, Blocks, ProjectionMode, Timing, TimingSettings};
use super::trajectory::Trajectory;
use super::unknowns::{KeyConstraints, Unknowns};
use crate::algorithms::geometry::Point;
use crate::algorithms::physics::elastic::Elastic;
use crate::support::budget::Budget;
use crate::support::error::{Error, Result};

/// Solver settings.
#[derive(Debug, Clone, PartialEq)]
pub struct Settings {
    /// Residual samples per interval.
    pub samples: usize,
    /// Residual samples on an interval that begins or ends at a contact.
    pub contact_samples: usize,
    /// Iterations (of both phases together) before the solve gives up.
    pub max_iterations: usize,
    /// Stop when W decreased by less than `tolerance × (W + negligible × S)` over the last
    /// [`WINDOW`] quasi-Newton iterations (S: the force scale, module documentation).
    pub tolerance: f64,
    /// The part of the force scale S below which W counts as zero in the stopping rule (0: the
    /// purely relative rule, which never fires where W can reach 0).
    pub negligible: f64,
    /// Proximal time scale h (0 = off).
    pub regularization: f64,
    /// Rayleigh mass damping α (D = α M), per second.
    pub damping: f64,
    /// Gravitational acceleration.
    pub gravity: Point,
    /// The memory the global step may use (its direct factor's predicted peak; past it the
    /// step is solved iteratively) and the time the solve may take.
    pub budget: Budget,
    /// Optimize the key times too, under these constraints (`max_iterations` and `tolerance`
    /// of [`TimingSettings`] are those of [`Timing::optimize_times`], not used here).
    pub timing: Option<TimingSettings>,
    /// Obstacles the nodes may not enter.
    pub contacts: Option<Contacts>,
    /// The quasi-Newton phase's model Hessian (its preconditioner). Default: auto, which keeps
    /// the projective one wherever a key moves beyond `LINEAR_REGIME` (every Table 1 scene
    /// and the demo) and takes the tangent one for small motions about the rest shape, where
    /// the projective one stalls: on the cyclic bar L-BFGS preconditioned by `L` lowers W at
    /// the first guess's times by 0.26% in 670 iterations, against the 8.8% the tangent model
    /// finds in one, and the stopping rule then rightly ends a solve that is not moving.
    pub model_hessian: ModelHessian,
    /// How the global step is inverted; `None`: the cheapest predicted within the memory
    /// budget (`super::global_step::choose`).
    pub global_step: Option<super::global_step::Method>,
    /// Residual samples per interval of the coarse phase (0: none; module documentation,
    /// "Coarse to fine"). Not used with obstacles or optimized key times, nor when it is not
    /// below `samples`.
    pub coarse_samples: usize,
    /// The coarse phase's own `tolerance` (its stopping rule is the fine one's otherwise).
    pub coarse_tolerance: f64,
    /// The quasi-Newton phase's step: L-BFGS, or a Gauss-Newton step solved by truncated CG
    /// ([`Step`]).
    pub step: Step,
}

/// The step of the quasi-Newton phase (module documentation, "Gauss-Newton steps").
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Step {
    /// L-BFGS on the exact W, preconditioned by the model Hessian.
    QuasiNewton,
    /// A truncated Gauss-Newton step (module `gauss_newton`), preconditioned by the model
    /// Hessian, falling back to the L-BFGS step where its line search fails. Not with obstacles
    /// or moving key times (L-BFGS is used there).
    GaussNewton,
    /// [`Step::GaussNewton`] where it was measured to win (nowhere yet: every scene measured costs more), else [`Step::QuasiNewton`]
    /// ([`Step::resolve`]).
    Auto,
}

/// The default of [`Settings::step`].
pub const DEFAULT_STEP: Step = Step::Auto;

/// CG iterations (products with the Gauss-Newton Hessian) per Gauss-Newton step at most.
pub const GAUSS_NEWTON_CG: usize = 20;

impl Step {
    /// The step taken: `Auto` decided, and L-BFGS wherever Gauss-Newton does not apply.
    pub fn resolve(self, settings: &Settings) -> Step {
        if settings.contacts.is_some() || settings.timing.is_some() {
            return Step::QuasiNewton;
        }
        match self {
            // Measured: Gauss-Newton cuts the iterations 1.5 to 3.4x but costs 1.5 to 2.4x the CPU time
            // (module documentation, "Gauss-Newton steps").
            Step::Auto => Step::QuasiNewton,
            other => other,
        }
    }
}

/// The quasi-Newton phase's initial inverse Hessian.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ModelHessian {
    /// [`ModelHessian::Tangent`] when every key stays within `LINEAR_REGIME` of the body's
    /// size of its rest shape (where the rest tangent stiffness is the body's) and its
    /// factorization succeeds, else [`ModelHessian::Projective`].
    Auto,
    /// The global step's matrix (projective stiffness `L`), factorized anyway for phase 1.
    Projective,
    /// The same normal matrix with the rest tangent stiffness (`super::tangent_step`);
    /// not with obstacles (the projective one is used there).
    Tangent,
}

/// How far (relative to the body's bounding-box diagonal) every key may be from the rest shape
/// for [`ModelHessian::Auto`] to choose the tangent model.
pub const LINEAR_REGIME: f64 = 0.01;

impl ModelHessian {
    /// The model for `keys` on `elastic`: `Auto` decided.
    pub fn resolve(self, elastic: &Elastic, keys: &KeyConstraints) -> ModelHessian {
        if self != ModelHessian::Auto {
            return self;
        }
        let size = crate::algorithms::geometry::bbox_diagonal(&elastic.rest);
        let far = keys
            .positions
            .iter()
            .flatten()
            .zip(elastic.rest.iter().cycle())
            .map(|(p, r)| crate::algorithms::geometry::norm(crate::algorithms::geometry::sub(*p, *r)))
            .fold(0.0, f64::max);
        if far <= LINEAR_REGIME * size {
            ModelHessian::Tangent
        } else {
            ModelHessian::Projective
        }
    }
}

impl Settings {
    /// The settings of an unconstrained solve with these samples and material.
    pub fn new(samples: usize, damping: f64, gravity: Point) -> Settings {
        Settings {
            samples,
            contact_samples: 2 * samples,
            max_iterations: DEFAULT_MAX_ITERATIONS,
            tolerance: DEFAULT_TOLERANCE,
            negligible: NEGLIGIBLE,
            regularization: 0.1,
            damping,
            gravity,
            budget: Budget::default(),
            timing: None,
            contacts: None,
            model_hessian: ModelHessian::Auto,
            global_step: None,
            coarse_samples: DEFAULT_COARSE_SAMPLES,
            coarse_tolerance: DEFAULT_COARSE_TOLERANCE,
            step: DEFAULT_STEP,
        }
    }

    /// The samples of the coarse phase, when one runs (module documentation, "Coarse to fine").
    pub fn coarse_phase(&self) -> Option<usize> {
        (self.coarse_samples > 0 && self.coarse_samples < self.samples && self.contacts.is_none() && self.timing.is_none())
            .then_some(self.coarse_samples)
    }
}

/// The default of [`Settings::coarse_samples`] (measured: see `formats/scene.md`).
pub const DEFAULT_COARSE_SAMPLES: usize = 0;
/// The default of [`Settings::coarse_tolerance`].
pub const DEFAULT_COARSE_TOLERANCE: f64 = 1e-3;

/// The default of [`Settings::tolerance`] (measured: see `formats/scene.md`).
pub const DEFAULT_TOLERANCE: f64 = 1e-3;
/// The default of [`Settings::negligible`] (module documentation).
pub const NEGLIGIBLE: f64 = 1e-3;
/// The default of [`Settings::max_iterations`].
pub const DEFAULT_MAX_ITERATIONS: usize = 1000;
/// Iterations over which the stopping rule measures the decrease of W.
pub const WINDOW: usize = 10;
/// The local/global phase hands over to quasi-Newton when an iteration lowers W by less than
/// this fraction of W.
const PHASE1_SWITCH: f64 = 1e-2;
/// Relative change of an interval since the last factorization that triggers a refactorization.
pub const REFACTOR_CHANGE: f64 = 0.1;
/// Largest relative change of an interval in one step.
const MAX_INTERVAL_CHANGE: f64 = 0.5;
/// Penetration allowed at a trial point, relative to the body's size (the linearized steps
/// keep the active checks to second order when the times move).
const CLEARANCE_TOLERANCE: f64 = 1e-6;

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
    /// W's decrease over the last [`WINDOW`] iterations when the solve stopped, relative to
    /// the stopping rule's reference `W + negligible × S`.
    pub last_decrease: f64,
    /// The predicted further decrease of W, relative to the same reference, had the iteration
    /// gone on (the last two windows' decreases extrapolated geometrically; `None` when they
    /// do not shrink, or the solve stopped before two windows).
    pub predicted_remaining: Option<f64>,
    /// The force scale S at the final iterate ([`Evaluation::force_scale`]): `W / S` is the
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
/// solve_seconds`. Timing only: nothing here changes a result.
#[derive(Debug, Clone, Default, PartialEq)]
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

/// A finished solve.
#[derive(Debug, Clone)]
pub struct Solved {
    /// The optimized trajectory of every node (at the optimized times, when they are).
    pub trajectory: Trajectory,
    /// What the iteration did.
    pub log: Log,
}

/// The initial guess: the input keyframes with zero velocities. In a loop the last key is the
/// first.
pub fn initial_trajectory(keys: &KeyConstraints) -> Trajectory {
    let mut positions = keys.positions.clone();
    if keys.cyclic {
        let first = positions[0].clone();
        *positions.last_mut().expect("keys") = first;
    }
    Trajectory::with_zero_velocities(keys.times.clone(), positions)
}

/// The objective of `keys` on `elastic` with these settings, at the keys' times.
pub fn objective<'a>(elastic: &'a Elastic, keys: &KeyConstraints, settings: &Settings) -> Objective<'a> {
    let slots = keys.slots();
    let counts = sample_counts(&keys.times, settings.samples, settings.contact_samples);
    Objective {
        elastic,
        samples: samples(&keys.times, &counts, &slots),
        slots,
        damping: settings.damping,
        gravity: settings.gravity,
        supports: keys.supports(elastic.node_count()),
        time_gradient: false,
    }
}

/// The hermite baseline (the initial guess, see [`initial_trajectory`]) and its W, so that
/// methods compare on one scale.
pub fn baseline(elastic: &Elastic, keys: &KeyConstraints, settings: &Settings) -> (Trajectory, f64) {
    let trajectory = initial_trajectory(keys);
    let objective = objective(elastic, keys, settings);
    let w = objective.evaluate(&trajectory, &objective.local_step(&trajectory, false)).value;
    (trajectory, w)
}

/// Add a per-slot step to the trajectory (every key sharing a slot gets the same value).
pub fn apply_step(tr: &mut Trajectory, slots: &TimeSlots, delta: &[Vec<Point>], scale: f64) {
    for (s, ds) in delta.iter().enumerate() {
        let position = slots.is_position(s);
        for k in slots.keys_of(s) {
            let target = if position { &mut tr.positions[k] } else { &mut tr.velocities[k] };
            for (x, d) in target.iter_mut().zip(ds) {
                for c in 0..3 {
                    x[c] += scale * d[c];
                }
            }
        }
    }
}

/// Halvings of a step that would increase W before it is given up.
const MAX_HALVINGS: usize = 8;

/// Directions blocked at once in a row (each adding a row to the active set) before a phase
/// gives up.
const MAX_HOLDS: usize = 50;

/// Rounds of [`Solver::make_feasible`]'s projection (each adds the checks still inside).
const MAX_FEASIBILITY_ROUNDS: usize = 50;

/// Curvature pairs kept by the quasi-Newton phase. More do not pay: 16 to 64 pairs reach the
/// 20-key body's stopping W no sooner, and cost 1.2 ms and 4.9 MB a pair there (README,
/// "Production-size surfaces").
const LBFGS_MEMORY: usize = 8;

/// How a phase of the iteration ended.
#[derive(Debug, Clone, PartialEq)]
enum PhaseEnd {
    /// W settled (the relative decrease in the stopping rule's measure).
    Settled(f64),
    /// No step along the phase's direction decreased W.
    Stalled,
    /// The iteration budget ran out.
    OutOfIterations,
}

/// The current iterate and the history of W.
struct Iterate {
    tr: Trajectory,
    eval: Evaluation,
    energy: Vec<f64>,
    halvings: usize,
    /// Checks held on their obstacle.
    active: BTreeSet<Check>,
    /// Interval variables held at their minimum length.
    at_minimum: Vec<bool>,
    /// Quasi-Newton iterations that moved the times.
    timing_iterations: usize,
    refactorizations: usize,
    /// The key times after each iteration (when they are optimized).
    times: Vec<Vec<f64>>,
    /// Gauss-Newton steps taken, their products with the Gauss-Newton Hessian, and the CG
    /// solves stopped by the iteration cap.
    gauss_newton: (usize, usize, usize),
}

/// Optimize keyframe positions and velocities (and key times). `on_iteration(k, W, floor)`
/// reports progress: W at iteration k and the stopping rule's floor `negligible × S` there.
///
/// Two phases share one factorized matrix:
///
/// 1. The paper's local/global step (`Solver::local_global`): the minimizer of the quadratic
///    model of W with frozen projections (plus the proximal term, and the active contacts as
///    hard constraints). It is fast far from the solution but it is not a descent direction of
///    W everywhere (its stiffness is `L`, not `∇²E`), and near its fixed point it turns W back
///    up.
/// 2. Once an iteration lowers W by less than 1% or stops decreasing it: L-BFGS on the exact W
///    (whose gradient differentiates the projections), with the same matrix as initial
///    inverse Hessian (`Solver::quasi_newton`), over the key times too when asked.
///
/// In both, a step that would not decrease W is halved until it does (the trial's local step
/// is the next iteration's, so an accepted step costs nothing extra). W never increases, and
/// the regularization never moves a fixed point. The solve stops when phase 2 settles
/// (module documentation) or stalls, or after `max_iterations` in all.
///
/// With [`Settings::coarse_phase`], all this runs twice: first with the coarse samples to
/// their own tolerance, then with the configured samples from there (module documentation,
/// "Coarse to fine").
pub fn solve(elastic: &Elastic, keys: &KeyConstraints, settings: &Settings, on_iteration: &dyn Fn(usize, f64, f64)) -> Result<Solved> {
    let Some(samples) = settings.coarse_phase() else {
        return Ok(solve_from(elastic, keys, settings, None, on_iteration)?.0);
    };
    let start = Instant::now();
    let coarse_settings = Settings { samples, tolerance: settings.coarse_tolerance, coarse_samples: 0, ..settings.clone() };
    let (coarse, _, factors) = solve_from(elastic, keys, &coarse_settings, None, on_iteration)?;
    let n = coarse.log.iterations;
    // The fine phase's W at the configured samples starts over at the first guess (reported,
    // not counted): its iteration k is the whole solve's `n + k - 1`.
    let fine_settings = Settings { max_iterations: settings.max_iterations.saturating_sub(n), ..settings.clone() };
    let label = format!("{n} coarse iterations at {samples} samples per interval, then ");
    let warm = Warm { trajectory: &coarse.trajectory, label, factors: Some(factors) };
    let (fine, warm, _) = solve_from(elastic, keys, &fine_settings, Some(warm), &|k, w, floor| {
        if k > 0 {
            on_iteration(n + k - 1, w, floor);
        }
    })?;
    let mut log = fine.log;
    log.iterations += n - usize::from(warm);
    log.coarse_iterations = n;
    log.coarse_samples = samples;
    log.halvings += coarse.log.halvings;
    log.precompute_seconds += coarse.log.precompute_seconds;
    let (c, f) = (&coarse.log.split, &mut log.split);
    f.evaluations += c.evaluations;
    f.exact_evaluations += c.exact_evaluations;
    f.evaluation_seconds += c.evaluation_seconds;
    f.solves += c.solves;
    f.solve_seconds += c.solve_seconds;
    log.seconds = start.elapsed().as_secs_f64();
    if !warm {
        log.stop_reason += &format!("; the coarse phase's result ({n} iterations at {samples} samples per interval) was not below the first guess at {} samples, so the fine phase started from the first guess", settings.samples);
    }
    Ok(Solved { trajectory: fine.trajectory, log })
}

/// [`solve`] from `start` instead of the first guess when W is lower there: an earlier
/// solution of the same body whose keys have since moved (`blendsim bake --from`), with the
/// prescribed values already the new keys'. The solve then goes straight to the quasi-Newton
/// phase and stops by the same rule, so its result is a cold solve's within the stopping
/// tolerance. Not with obstacles, moving key times or a coarse phase (a cold solve then).
pub fn solve_starting(
    elastic: &Elastic,
    keys: &KeyConstraints,
    settings: &Settings,
    start: &Trajectory,
    on_iteration: &dyn Fn(usize, f64, f64),
) -> Result<Solved> {
    let fits =
        start.times == keys.times && start.positions.len() == keys.times.len() && start.positions.iter().all(|p| p.len() == elastic.node_count());
    if !fits || settings.coarse_phase().is_some() || settings.timing.is_some() || settings.contacts.is_some() {
        return solve(elastic, keys, settings, on_iteration);
    }
    let label = "the previous bake's solution with the keys' edits, then ".to_string();
    let (mut solved, warm, _) = solve_from(elastic, keys, settings, Some(Warm { trajectory: start, label, factors: None }), on_iteration)?;
    if !warm {
        solved.log.stop_reason += "; the previous bake's solution was not below the first guess, so the solve started from the first guess";
    }
    Ok(solved)
}

/// Where a solve may start: the coarse phase's result or an earlier bake's solution, the words
/// that say so in the stop reason, and the coarse phase's factorized matrices, the fine
/// quasi-Newton phase's preconditioner (any positive definite model serves there; the
/// curvature pairs learn the rest, and W's line search keeps every step a descent).
struct Warm<'t> {
    trajectory: &'t Trajectory,
    label: String,
    factors: Option<Factors>,
}

/// The factorized matrices of a solve: the global step and the tangent model Hessian.
struct Factors {
    global: GlobalStep,
    tangent: Option<TangentStep>,
}

/// One solve at `settings.samples`, from the first guess, or from `warm` when W is lower there
/// (then straight to the quasi-Newton phase, on the warm start's matrices); whether it started
/// from `warm`, and the matrices, for a next solve to reuse.
fn solve_from(
    elastic: &Elastic,
    keys: &KeyConstraints,
    settings: &Settings,
    warm: Option<Warm>,
    on_iteration: &dyn Fn(usize, f64, f64),
) -> Result<(Solved, bool, Factors)> {
    let start = Instant::now();
    let blocks = settings.timing.as_ref().map(|t| Blocks::new(&keys.times, t)).transpose()?;
    let objective = objective(elastic, keys, settings);
    // Only without obstacles (whose first guess is moved out of them first): W at the first
    // guess and at the warm start, on this solve's samples.
    let mut first = None;
    let mut reused = None;
    if let Some(warm) = warm.filter(|_| settings.contacts.is_none()) {
        let at = |tr: &Trajectory, k| finite(objective.evaluate(tr, &objective.local_step(tr, false)), k);
        let guess = initial_trajectory(keys);
        let (e0, e1) = (at(&guess, 0)?, at(warm.trajectory, 1)?);
        if e1.value < e0.value {
            first = Some((e0, Some((warm.trajectory.clone(), e1, warm.label))));
            reused = warm.factors;
        } else {
            first = Some((e0, None));
        }
    }
    let t_factors = Instant::now();
    let Factors { global, tangent } = match reused {
        Some(factors) => factors,
        None => factors(elastic, keys, settings, &objective)?,
    };
    let precompute_seconds = t_factors.elapsed().as_secs_f64();
    let timing = Timing::new(elastic, keys, settings);
    // The optimized interval lengths: every interval of positive length.
    let mut vars = vec![None; keys.times.len() - 1];
    let mut intervals = Vec::new();
    if blocks.is_some() {
        for (i, var) in vars.iter_mut().enumerate() {
            if keys.times[i + 1] > keys.times[i] {
                *var = Some(intervals.len());
                intervals.push(i);
            }
        }
    }
    let lower: Vec<f64> =
        intervals.iter().map(|&i| settings.timing.as_ref().map_or(0.0, |t| t.min_interval.min(keys.times[i + 1] - keys.times[i]))).collect();
    let size = crate::algorithms::geometry::bbox_diagonal(&elastic.rest);
    let mut solver = Solver {
        timing,
        global,
        tangent,
        settings,
        on_iteration,
        blocks,
        vars,
        intervals,
        lower,
        curvature: Vec::new(),
        factored_times: keys.times.clone(),
        clearance_tolerance: CLEARANCE_TOLERANCE * size,
        projections: RefCell::new(std::array::from_fn(|_| Projections { targets: Vec::new(), jacobians: None })),
        split: RefCell::default(),
    };

    let t_iterations = Instant::now();
    let mut tr = initial_trajectory(keys);
    let mut active = BTreeSet::new();
    if let Some(contacts) = &settings.contacts {
        solver.make_feasible(contacts, &mut tr, &mut active)?;
    }
    let (eval, warm) = match first {
        Some(first) => first,
        None => (solver.evaluate(&tr, 0, false)?, None),
    };
    on_iteration(0, eval.value, settings.negligible * eval.force_scale);
    let at_minimum = vec![false; solver.intervals.len()];
    let times = if solver.blocks.is_some() { vec![tr.times.clone()] } else { Vec::new() };
    let mut it = Iterate {
        tr,
        energy: vec![eval.value],
        eval,
        halvings: 0,
        active,
        at_minimum,
        timing_iterations: 0,
        refactorizations: 0,
        times,
        gauss_newton: (0, 0, 0),
    };
    let mut label = String::new();
    if let Some((tr, eval, words)) = warm {
        on_iteration(1, eval.value, settings.negligible * eval.force_scale);
        it.energy.push(eval.value);
        (it.tr, it.eval, label) = (tr, eval, words);
    }
    let warm = it.energy.len() - 1;
    let (converged, stop_reason) = solver.iterate(&mut it, &label)?;
    let iterations = it.energy.len() - 1;
    let iteration_time = t_iterations.elapsed().as_secs_f64();
    let force_scale = it.eval.force_scale;
    // The stopping rule's windows, after the warm start's step from the first guess.
    let (last_decrease, predicted_remaining) = prediction(&it.energy[warm..], settings.negligible * force_scale);
    let clearance = settings.contacts.as_ref().map(|c| c.clearance(&c.snapshot(&it.tr, &solver.timing.slots)));
    let log = Log {
        iterations,
        seconds: start.elapsed().as_secs_f64(),
        precompute_seconds,
        iteration_seconds: iteration_time / (iterations + 1) as f64,
        unknowns: solver.global.stats.unknowns,
        halvings: it.halvings,
        converged,
        stop_reason,
        linear_solver: solver.global.stats.linear_solver.to_string(),
        last_decrease,
        predicted_remaining,
        timing_iterations: it.timing_iterations,
        times: it.times,
        refactorizations: it.refactorizations,
        active_contacts: it.active.len(),
        clearance,
        conjugate_gradients: solver.global.cg_log(),
        force_scale,
        energy: it.energy,
        coarse_iterations: 0,
        coarse_samples: 0,
        split: solver.split.take(),
    };
    Ok((Solved { trajectory: it.tr, log }, warm == 1, Factors { global: solver.global, tangent: solver.tangent }))
}

/// The global step of `objective` and, when the settings ask for it, the tangent model Hessian.
fn factors(elastic: &Elastic, keys: &KeyConstraints, settings: &Settings, objective: &Objective) -> Result<Factors> {
    let unknowns = Unknowns::new(keys, elastic.node_count());
    let global = GlobalStep::build(objective, unknowns, settings.regularization, &settings.budget, settings.global_step)?;
    let global_unknowns = global.unknowns();
    // The active-set projection solves with the preconditioner per coordinate: with obstacles
    // the quasi-Newton phase keeps the global step's matrix.
    let tangent = match settings.model_hessian.resolve(elastic, keys) {
        _ if global_unknowns.count() == 0 || settings.contacts.is_some() => None,
        // Chosen: its errors are the solve's.
        ModelHessian::Tangent if settings.model_hessian == ModelHessian::Tangent => Some(TangentStep::new(objective, global_unknowns)?),
        // Guessed: without the proximal term a free drift can cost nothing, and then the
        // global step's matrix (which has it) is kept.
        ModelHessian::Tangent => TangentStep::new(objective, global_unknowns).ok(),
        _ => None,
    };
    Ok(Factors { global, tangent })
}

/// `eval`, or an error naming the iteration when W is not finite.
fn finite(eval: Evaluation, iteration: usize) -> Result<Evaluation> {
    if !eval.value.is_finite() {
        return Err(Error::general(
            format!("the spacetime energy W became {} at iteration {iteration}", eval.value),
            "check the keyframes for flat or inverted tets, and lower [solver] regularization (h) to damp the steps",
        ));
    }
    Ok(eval)
}

/// The decrease of W over the last window, and the geometric extrapolation of the last two
/// windows' decreases (module documentation), both relative to `W + floor`.
fn prediction(energy: &[f64], floor: f64) -> (f64, Option<f64>) {
    let k = energy.len() - 1;
    let w = energy[k] + floor;
    if w <= 0.0 || k == 0 {
        return (0.0, None);
    }
    let window = WINDOW.min(k);
    let last = energy[k - window] - energy[k];
    if k < 2 * WINDOW {
        return (last / w, None);
    }
    let before = energy[k - 2 * WINDOW] - energy[k - WINDOW];
    let ratio = last / before;
    let remaining = (before > 0.0 && ratio < 1.0).then(|| last * ratio / (1.0 - ratio) / w);
    (last / w, remaining)
}

/// The iterations left before the stopping rule stops a solve whose W went through `energy`
/// (one entry per iteration, the first guess first), for a progress estimate: the same
/// geometric extrapolation of the last two windows' decreases as [`Log::predicted_remaining`],
/// run forward until the window's decrease falls to `tolerance` of the W it levels off at plus
/// `floor` (the stopping rule's `negligible × S`). `None` before two windows, or when the
/// decreases do not shrink (or W heads to zero with no floor, where a relative rule has no
/// predictable end); `Some(0)` once the last window is within tolerance.
pub fn predicted_iterations(energy: &[f64], tolerance: f64, floor: f64) -> Option<usize> {
    let k = energy.len().checked_sub(1)?;
    if k < 2 * WINDOW {
        return None;
    }
    let last = energy[k - WINDOW] - energy[k];
    let before = energy[k - 2 * WINDOW] - energy[k - WINDOW];
    if last <= tolerance * (energy[k] + floor) {
        return Some(0);
    }
    let ratio = last / before;
    if !(before > 0.0 && ratio > 0.0 && ratio < 1.0) {
        return None;
    }
    // Decreases over a sliding window shrink by `ratio` every WINDOW iterations; the rule's
    // reference `W + floor` levels off at `settled` (W's limit clamped at 0: W is never negative).
    let settled = (energy[k] - last * ratio / (1.0 - ratio)).max(0.0) + floor;
    if settled.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
        return None;
    }
    let windows = (tolerance * settled / last).ln() / ratio.ln();
    Some((WINDOW as f64 * windows).ceil().max(0.0) as usize)
}

/// The predicted total iteration count of a running solve, for its progress bar: the median
/// of the last WINDOW `predicted_iterations`, shown only while most of them exist. After a
/// stall W can speed up again (a buckling, a contact settling); the few windows whose decrease
/// shrinks again right after it extrapolate from one uncertain ratio and can be off by 4x, so
/// a total waits for a majority of the window to agree rather than show one of them.
#[derive(Debug, Default)]
pub struct IterationEstimate {
    energy: Vec<f64>,
    totals: std::collections::VecDeque<Option<usize>>,
    shown: Option<usize>,
}

impl IterationEstimate {
    /// Record iteration `k`'s `w` and the stopping rule's `floor` (the arguments of
    /// `solve`'s `on_iteration`), and return the predicted total (at least `k`, at most
    /// `max_iterations`), or `None` while nothing reliable is predicted.
    pub fn update(&mut self, k: usize, w: f64, floor: f64, tolerance: f64, max_iterations: usize) -> Option<usize> {
        self.energy.push(w);
        self.totals.push_back(predicted_iterations(&self.energy, tolerance, floor).map(|left| (k + left).min(max_iterations)));
        if self.totals.len() > WINDOW {
            self.totals.pop_front();
        }
        let mut known: Vec<usize> = self.totals.iter().flatten().copied().collect();
        known.sort_unstable();
        if self.totals.len() == WINDOW && 2 * known.len() > WINDOW {
            self.shown = Some(known[known.len() / 2].max(k));
        } else if self.shown.is_some_and(|n| n < k) {
            // The last total stands until it is passed.
            self.shown = None;
        }
        self.shown
    }
}

/// The objective, the factorized global step and the constraints of one solve.
struct Solver<'a> {
    timing: Timing<'a>,
    global: GlobalStep,
    /// The tangent model Hessian, when the quasi-Newton phase uses it.
    tangent: Option<TangentStep>,
    settings: &'a Settings,
    on_iteration: &'a dyn Fn(usize, f64, f64),
    /// The fixed-sum blocks of intervals, when the times are optimized.
    blocks: Option<Blocks>,
    /// `vars[i]`: the variable of interval `i`, if its length is optimized.
    vars: Vec<Option<usize>>,
    /// The interval of each variable.
    intervals: Vec<usize>,
    /// The smallest length of each variable.
    lower: Vec<f64>,
    /// `D_T`: the inverse held-keys curvature of each variable.
    curvature: Vec<f64>,
    /// The key times the global step was last factorized at.
    factored_times: Vec<f64>,
    /// Penetration allowed at a trial point (absolute).
    clearance_tolerance: f64,
    /// The local step's buffers, kept between evaluations (`[0]` without the Jacobians, `[1]`
    /// with them): every trial point fills them again instead of allocating them.
    projections: RefCell<[Projections; 2]>,
    /// The evaluations' and solves' count and time ([`Log::split`]).
    split: RefCell<IterationSplit>,
}

/// A step of both kinds of variables: the keyframe unknowns (flat, three per unknown) and the
/// interval variables.
fn split(z: &[f64], unknowns: usize) -> (&[f64], &[f64]) {
    z.split_at(3 * unknowns)
}

impl<'a> Solver<'a> {
    fn objective(&self, times: &[f64]) -> Objective<'a> {
        let mut o = self.timing.objective(times);
        o.time_gradient = self.blocks.is_some();
        o
    }

    /// The stopping rule's floor `negligible × S` at the current iterate.
    fn floor(&self, it: &Iterate) -> f64 {
        self.settings.negligible * it.eval.force_scale
    }

    fn unknown_count(&self) -> usize {
        self.global.unknowns().count()
    }

    /// W at `tr` with fresh projections (and the exact gradients when `exact`); a non-finite W
    /// is an error naming the iteration.
    fn evaluate(&self, tr: &Trajectory, iteration: usize, exact: bool) -> Result<Evaluation> {
        let start = Instant::now();
        let objective = self.objective(&tr.times);
        let eval = objective.evaluate_fresh(tr, exact, &mut self.projections.borrow_mut()[exact as usize]);
        let mut split = self.split.borrow_mut();
        split.evaluations += 1;
        split.exact_evaluations += usize::from(exact);
        split.evaluation_seconds += start.elapsed().as_secs_f64();
        finite(eval, iteration)
    }

    /// `x ← A⁻¹ x` with the global step's matrix, timed ([`Log::split`]).
    fn global_solve(&self, x: &mut [Point]) {
        self.timed_solve(|| self.global.apply_inverse(x));
    }

    /// Run one solve and count it and its wall time in [`Log::split`].
    fn timed_solve(&self, solve: impl FnOnce()) {
        let start = Instant::now();
        solve();
        let mut split = self.split.borrow_mut();
        split.solves += 1;
        split.solve_seconds += start.elapsed().as_secs_f64();
    }

    /// The joint gradient of an exact evaluation: the free unknowns' (flat), then the interval
    /// variables'.
    fn joint_gradient(&self, eval: &Evaluation, times: bool) -> Vec<f64> {
        let g = self.global.gather(eval.exact_gradient.as_ref().expect("exact phase"));
        let mut z: Vec<f64> = g.as_flattened().to_vec();
        if let Some(t) = eval.time_gradient.as_ref().filter(|_| times) {
            z.extend(self.intervals.iter().map(|&i| t[i]));
        }
        z
    }

    /// Whether another iteration fits in `max_iterations`; an error once `--max-time` is spent.
    fn budget_left(&self, it: &Iterate) -> Result<bool> {
        self.settings
            .budget
            .check_time("solve", || format!("after {} iterations (W {:.4e})", it.energy.len() - 1, it.energy.last().copied().unwrap_or(f64::NAN)))?;
        Ok(it.energy.len() <= self.settings.max_iterations)
    }

    /// The rows held in a step: the fixed sums of interval blocks, the intervals at their
    /// minimum, and the active contacts (linearized at the current iterate; with `times`, the
    /// contacts' dependence on the interval lengths too).
    fn rows(&self, it: &Iterate, times: bool) -> Vec<Row> {
        let mut rows = Vec::new();
        if times {
            if let Some(blocks) = &self.blocks {
                for (block, fixed_sum) in &blocks.blocks {
                    if *fixed_sum && !block.is_empty() {
                        let t = block.iter().filter_map(|&i| self.vars[i]).map(|j| (j, 1.0)).collect();
                        rows.push(Row { kind: RowKind::Sum, u: Vec::new(), normal: [0.0; 3], t });
                    }
                }
            }
            for (j, _) in it.at_minimum.iter().enumerate().filter(|(_, &b)| b) {
                rows.push(Row { kind: RowKind::Bound(j), u: Vec::new(), normal: [0.0; 3], t: vec![(j, 1.0)] });
            }
        }
        if let Some(contacts) = &self.settings.contacts {
            let no_times = vec![None; self.vars.len()];
            let vars = if times { &self.vars } else { &no_times };
            for (index, &check) in it.active.iter().enumerate() {
                if let Some((row, _)) = contacts.row(check, &it.tr, self.global.unknowns(), vars, RowKind::Contact(index)) {
                    rows.push(row);
                }
            }
        }
        rows
    }

    /// The quasi-Newton phase's initial inverse Hessian on the keyframe unknowns.
    fn model_inverse(&self, x: &mut [Point]) {
        match &self.tangent {
            Some(t) => self.timed_solve(|| t.apply_inverse(x)),
            None => self.global_solve(x),
        }
    }

    /// The step preconditioner restricted to the rows of `it` (with the times when `times`):
    /// the global step's, or the quasi-Newton model's when `model`.
    fn projection(&self, it: &Iterate, times: bool, model: bool) -> Projection {
        let solve = |x: &mut [Point]| if model { self.model_inverse(x) } else { self.global_solve(x) };
        let d_t: &[f64] = if times { &self.curvature } else { &[] };
        Projection::new(self.rows(it, times), &Preconditioner { unknowns: self.unknown_count(), solve: &solve, times: d_t })
    }

    fn preconditioner<'s>(&'s self, solve: &'s dyn Fn(&mut [Point]), times: bool) -> Preconditioner<'s> {
        Preconditioner { unknowns: self.unknown_count(), solve, times: if times { &self.curvature } else { &[] } }
    }

    /// Release the inequality rows whose multiplier (for the gradient `g`) is negative: the
    /// objective pulls away from them. Returns whether any was released. Checks in `keep`
    /// (just blocked) stay one more iteration.
    fn release(&self, it: &mut Iterate, projection: &Projection, lambda: &[f64], keep: Option<Check>) -> bool {
        let checks: Vec<Check> = it.active.iter().copied().collect();
        let mut released = false;
        let scale = lambda.iter().fold(0.0f64, |m, l| m.max(l.abs()));
        for (row, &l) in projection.rows.iter().zip(lambda) {
            if !(row.kind.is_inequality() && l < -1e-12 * scale) {
                continue;
            }
            match row.kind {
                RowKind::Contact(index) if Some(checks[index]) != keep => {
                    it.active.remove(&checks[index]);
                    released = true;
                }
                RowKind::Bound(j) => {
                    it.at_minimum[j] = false;
                    released = true;
                }
                _ => {}
            }
        }
        released
    }

    /// Move the initial guess out of the obstacles. First every key pose: a node whose
    /// position is free and inside an obstacle is put on the nearest point of its surface
    /// (a keyframe sculpted into the floor becomes a contact pose); a held one is an error
    /// naming the key's time and how deep the deepest held node is. Then the in-betweens:
    /// the smallest step (in the global step's metric) that puts every penetrating node on
    /// the surface, the projected nodes kept there, repeated while the step pushes others in.
    fn make_feasible(&self, contacts: &Contacts, tr: &mut Trajectory, active: &mut BTreeSet<Check>) -> Result<()> {
        let unknowns = self.global.unknowns();
        let slots = &self.timing.slots;
        let tolerance = 0.5 * self.clearance_tolerance;
        // (depth, node, obstacle) of the deepest held node, and how many are held inside, per key.
        let mut held: Vec<(usize, f64, usize, usize, usize)> = Vec::new();
        for k in 0..tr.key_count() {
            let s = slots.position(k);
            if slots.keys_of(s).next() != Some(k) {
                continue;
            }
            let mut deepest: Option<(f64, usize, usize)> = None;
            let mut count = 0;
            for node in 0..tr.positions[k].len() {
                for (o, obstacle) in contacts.obstacles.iter().enumerate() {
                    let x = tr.positions[k][node];
                    let d = obstacle.distance(x);
                    if d >= -tolerance {
                        continue;
                    }
                    if unknowns.get(node, s).is_some() {
                        let p = obstacle.project(x);
                        for key in slots.keys_of(s) {
                            tr.positions[key][node] = p;
                        }
                        active.insert(Check { at: At::Key(k), node: node as u32, obstacle: o as u16 });
                    } else {
                        count += 1;
                        if deepest.is_none_or(|(depth, _, _)| -d > depth) {
                            deepest = Some((-d, node, o));
                        }
                    }
                }
            }
            if let Some((depth, node, o)) = deepest {
                held.push((k, depth, node, o, count));
            }
        }
        if let Some(&(k, depth, node, o, count)) = held.first() {
            let others = if held.len() > 1 {
                format!(" (and the keys at {} s)", held[1..].iter().map(|h| format!("{:.4}", tr.times[h.0])).collect::<Vec<_>>().join(", "))
            } else {
                String::new()
            };
            return Err(Error::general(
                format!(
                    "the keyframe at t = {:.4} s holds {count} node(s) inside obstacle {} (a {}), node {node} deepest, by {depth:.4e}{others}; held positions cannot be moved out",
                    tr.times[k],
                    o + 1,
                    match contacts.obstacles[o] {
                        super::obstacles::Obstacle::Plane { .. } => "plane",
                        super::obstacles::Obstacle::Sphere { .. } => "sphere",
                    },
                ),
                "move that keyframe's mesh out of the obstacle, or free its vertices at that key (`fixed`) so the solver puts them on the surface",
            ));
        }
        let no_times = vec![None; self.vars.len()];
        for _ in 0..MAX_FEASIBILITY_ROUNDS {
            let snap = contacts.snapshot(tr, slots);
            let inside: Vec<(Check, f64)> = contacts.each(&snap).filter(|(_, _, d)| *d < -tolerance).map(|(c, _, d)| (c, d)).collect();
            if inside.is_empty() {
                return Ok(());
            }
            for &(check, d) in &inside {
                if contacts.row(check, tr, unknowns, &no_times, RowKind::Sum).is_none() {
                    let t = snap.instants.iter().find(|i| i.0 == check.at).map_or(f64::NAN, |i| i.1);
                    return Err(Error::general(
                        format!("node {} is inside obstacle {} by {:.4e} at t = {t:.4} s between the keys, and nothing there may move (the positions and velocities around it are held)", check.node, check.obstacle + 1, -d),
                        "move the keyframes around that time out of the obstacle, or free their vertices or velocities (`fixed`, `fixed_velocity`)",
                    ));
                }
                active.insert(check);
            }
            let mut rows = Vec::new();
            let mut targets = Vec::new();
            for (index, &check) in active.iter().enumerate() {
                if let Some((row, d)) = contacts.row(check, tr, unknowns, &no_times, RowKind::Contact(index)) {
                    rows.push(row);
                    targets.push(-d.min(0.0));
                } else {
                    targets.push(0.0);
                }
            }
            let solve = |x: &mut [Point]| self.global_solve(x);
            let h0 = self.preconditioner(&solve, false);
            let projection = Projection::new(rows, &h0);
            let kept: Vec<f64> = projection
                .rows
                .iter()
                .map(|r| match r.kind {
                    RowKind::Contact(index) => targets[index],
                    _ => 0.0,
                })
                .collect();
            let step = projection.correction(&kept, 3 * self.unknown_count());
            let (u, _) = split(&step, self.unknown_count());
            let points: Vec<Point> = u.as_chunks::<3>().0.to_vec();
            apply_step(tr, slots, &self.global.scatter(&points), 1.0);
        }
        Err(Error::general(
            "the first guess cannot be moved out of the obstacles: every correction pushes other nodes in",
            "check that the obstacles leave room for the body at every key and between them",
        ))
    }

    /// Both phases, or none when there is nothing to optimize: whether the solve converged,
    /// and why it stopped. After a warm start (`it` past the first guess; `label` says where it
    /// came from) the local/global phase is left out: its fixed point is not W's minimum, and
    /// the warm start is near the latter.
    fn iterate(&mut self, it: &mut Iterate, label: &str) -> Result<(bool, String)> {
        if self.unknown_count() == 0 && self.intervals.is_empty() {
            return Ok((true, "nothing to optimize: every keyframe position and velocity is fixed".to_string()));
        }
        if it.energy[0] == 0.0 {
            return Ok((true, "W is zero: the keyframes are already physically exact".to_string()));
        }
        let warm = it.energy.len() - 1;
        let phase1 = if self.unknown_count() > 0 && warm == 0 { self.local_global(it)? } else { PhaseEnd::Stalled };
        let local_global_iterations = it.energy.len() - 1 - warm;
        let mut phase2 = if phase1 == PhaseEnd::OutOfIterations { PhaseEnd::OutOfIterations } else { self.quasi_newton(it, false)? };
        if self.blocks.is_some() && phase2 != PhaseEnd::OutOfIterations {
            // The keys first settle at the given times, then keys and times move together: only
            // at settled keys is the held-keys time gradient the gradient of the reduced W (the
            // W of the best keys for those times, part 1's measurement); far from them it
            // mostly measures how bad the first guess is.
            phase2 = self.quasi_newton(it, true)?;
        }
        let mut phases = format!(
            "{label}{local_global_iterations} local/global + {} quasi-Newton iterations",
            it.energy.len() - 1 - warm - local_global_iterations
        );
        if self.tangent.is_some() {
            phases += ", preconditioned by the tangent model Hessian";
        }
        if it.gauss_newton.0 > 0 {
            phases += &format!(
                ", {} of them Gauss-Newton steps ({} CG products, {} solves capped at {GAUSS_NEWTON_CG})",
                it.gauss_newton.0, it.gauss_newton.1, it.gauss_newton.2
            );
        }
        if self.blocks.is_some() {
            phases += &format!(", {} moving the key times, {} refactorizations", it.timing_iterations, it.refactorizations);
        }
        let tolerance = self.settings.tolerance;
        Ok(match phase2 {
            PhaseEnd::Settled(change) => {
                let (w, scale) = (*it.energy.last().expect("W"), it.eval.force_scale);
                let of = if self.settings.negligible > 0.0 && scale > 0.0 {
                    format!("of W + {:e} S (W = {:.2e} S, S the force scale)", self.settings.negligible, w / scale)
                } else {
                    "of itself".to_string()
                };
                (true, format!("W decreased by {change:.3e} {of} over the last {WINDOW} iterations, below the tolerance {tolerance} ({phases})"))
            }
            PhaseEnd::Stalled => (true, format!("W is stationary: no step along its quasi-Newton direction decreases it ({phases})")),
            PhaseEnd::OutOfIterations => {
                (false, format!("stopped after max_iterations = {} before W settled ({phases})", self.settings.max_iterations))
            }
        })
    }

    /// Phase 1: the paper's local/global step (with the active contacts held), while it
    /// decreases W by at least [`PHASE1_SWITCH`] of W per iteration.
    fn local_global(&self, it: &mut Iterate) -> Result<PhaseEnd> {
        let (mut blocked, mut holds) = (None, 0);
        loop {
            if !self.budget_left(it)? {
                return Ok(PhaseEnd::OutOfIterations);
            }
            let mut d: Vec<f64> = self.global.gather(&it.eval.gradient).as_flattened().to_vec();
            let mut projection = self.projection(it, false, false);
            let solve = |x: &mut [Point]| self.global_solve(x);
            let h0 = self.preconditioner(&solve, false);
            let g = d.clone();
            let lambda = projection.apply(&mut d, &h0);
            if self.release(it, &projection, &lambda, blocked) {
                projection = self.projection(it, false, false);
                d.clone_from(&g);
                projection.apply(&mut d, &h0);
            }
            d.iter_mut().for_each(|x| *x = -*x);
            let w = *it.energy.last().expect("initial W");
            let step = match self.line_search(it, &d, false, 1.0)? {
                Outcome::Taken(step) => step,
                Outcome::Held(stop) => {
                    blocked = held_check(stop);
                    holds += 1;
                    if holds > MAX_HOLDS {
                        return Ok(PhaseEnd::Stalled);
                    }
                    continue;
                }
                Outcome::Failed => return Ok(PhaseEnd::Stalled),
            };
            holds = 0;
            blocked = step.blocked;
            let w_new = *it.energy.last().expect("accepted");
            let reference = w_new + self.floor(it);
            if (w - w_new) < PHASE1_SWITCH * reference {
                return Ok(PhaseEnd::Settled((w - w_new) / reference));
            }
        }
    }

    /// Phase 2: L-BFGS on the exact W (and the key times), preconditioned by the global
    /// step's matrix and the held-keys time curvature, restricted to the active rows.
    fn quasi_newton(&mut self, it: &mut Iterate, times: bool) -> Result<PhaseEnd> {
        it.eval = self.evaluate(&it.tr, it.energy.len(), true)?;
        if times {
            self.update_curvature(&it.tr, &it.eval);
        }
        let since = it.energy.len() - 1;
        // H₀'s scale is learned from the steps (`quasi_newton`), except with obstacles: their
        // active set re-projects H₀ and clears the pairs, and a scale learned under one set
        // misleads the next (measured: SPOT 502 iterations scaled, 383 as given;
        // `formats/scene.md`, "The scale of H₀").
        let mut lbfgs = Lbfgs::new(LBFGS_MEMORY, self.settings.contacts.is_none());
        let mut g = self.joint_gradient(&it.eval, times);
        let (mut blocked, mut holds) = (None, 0);
        let gauss_newton = !times && self.settings.step.resolve(self.settings) == Step::GaussNewton;
        let mut forcing = Forcing::default();
        loop {
            let k = it.energy.len() - 1;
            if k >= since + WINDOW {
                let w = it.energy[k];
                let change = (it.energy[k - WINDOW] - w) / (w + self.floor(it));
                if change <= self.settings.tolerance {
                    return Ok(PhaseEnd::Settled(change));
                }
            }
            if !self.budget_left(it)? {
                return Ok(PhaseEnd::OutOfIterations);
            }
            let solve = |x: &mut [Point]| self.model_inverse(x);
            let h0 = self.preconditioner(&solve, times);
            let mut projection = self.projection(it, times, true);
            if projection.rows.iter().any(|r| r.kind.is_inequality()) {
                let mut pg = g.clone();
                let lambda = projection.apply(&mut pg, &h0);
                if self.release(it, &projection, &lambda, blocked) {
                    projection = self.projection(it, times, true);
                }
            }
            let precondition = |q: &mut [f64]| {
                projection.apply(q, &h0);
            };
            let mut gauss_newton_step = None;
            if gauss_newton {
                // CG is preconditioned by the L-BFGS inverse Hessian (the curvature pairs of the
                // last steps on top of the model's): the model alone is too stiff along the slow
                // motions, and CG then ran into its cap on 52 of TWIST's 54 steps (measured;
                // module documentation).
                let lbfgs_precondition = |q: &mut [f64]| {
                    let d = lbfgs.direction(q, precondition);
                    q.iter_mut().zip(&d).for_each(|(a, b)| *a = -b);
                };
                let cg = self.gauss_newton_direction(it, &g, &lbfgs_precondition, forcing.next(dot(&g, &g).sqrt()));
                it.gauss_newton.1 += cg.products;
                it.gauss_newton.2 += usize::from(cg.end == CgEnd::Capped);
                if dot(&g, &cg.direction) < 0.0 {
                    if let Outcome::Taken(step) = self.line_search(it, &cg.direction, true, 1.0)? {
                        it.gauss_newton.0 += 1;
                        gauss_newton_step = Some((cg.direction, step));
                    }
                }
            }
            let (d, outcome) = match gauss_newton_step {
                Some((d, step)) => (d, Outcome::Taken(step)),
                None => {
                    let mut d = lbfgs.direction(&g, precondition);
                    // Not a descent direction (or NaN): start over from the preconditioned gradient.
                    if dot(&g, &d).partial_cmp(&0.0) != Some(std::cmp::Ordering::Less) {
                        lbfgs.clear();
                        d = lbfgs.direction(&g, precondition);
                    }
                    let mut outcome = self.line_search(it, &d, true, 1.0)?;
                    if matches!(outcome, Outcome::Failed) && !lbfgs.is_empty() {
                        // Restart from the preconditioned gradient.
                        lbfgs.clear();
                        d = lbfgs.direction(&g, precondition);
                        outcome = self.line_search(it, &d, true, 1.0)?;
                    }
                    (d, outcome)
                }
            };
            let step = match outcome {
                Outcome::Taken(step) => step,
                Outcome::Held(stop) => {
                    blocked = held_check(stop);
                    lbfgs.clear();
                    holds += 1;
                    if holds > MAX_HOLDS {
                        return Ok(PhaseEnd::Stalled);
                    }
                    continue;
                }
                Outcome::Failed => return Ok(PhaseEnd::Stalled),
            };
            holds = 0;
            blocked = step.blocked;
            if step.added {
                // The new row shrinks the subspace the curvature pairs live in.
                lbfgs.clear();
            }
            let g_new = self.joint_gradient(&it.eval, times);
            let s: Vec<f64> = d.iter().map(|v| v * step.scale).collect();
            let y: Vec<f64> = g_new.iter().zip(&g).map(|(a, b)| a - b).collect();
            if gauss_newton {
                // A Gauss-Newton step's length says nothing of H₀'s scale.
                lbfgs.push_pair(s, y);
            } else {
                lbfgs.push(s, y, step.scale, &g);
            }
            g = g_new;
            if times && step.moved_times {
                it.timing_iterations += 1;
                let moved = it.tr.times.windows(2).zip(self.factored_times.windows(2)).any(|(a, b)| {
                    let (now, then) = (a[1] - a[0], b[1] - b[0]);
                    then > 0.0 && ((now - then) / then).abs() > REFACTOR_CHANGE
                });
                if moved {
                    let objective = self.objective(&it.tr.times);
                    self.global.retime(&objective, self.settings.regularization)?;
                    if let Some(tangent) = self.tangent.as_mut() {
                        tangent.retime(&objective, self.global.unknowns())?;
                    }
                    self.factored_times.clone_from(&it.tr.times);
                    self.update_curvature(&it.tr, &it.eval);
                    it.refactorizations += 1;
                }
            }
        }
    }

    /// The truncated Gauss-Newton step at the current iterate (the keyframe unknowns only):
    /// `H d = -g` by CG preconditioned with `precondition`, to the relative residual `forcing`,
    /// with the projection Jacobians of the iterate's exact evaluation (the kept buffer: the
    /// last exact evaluation is the accepted iterate's).
    fn gauss_newton_direction(&self, it: &Iterate, g: &[f64], precondition: &dyn Fn(&mut [f64]), forcing: f64) -> TruncatedCg {
        let objective = self.objective(&it.tr.times);
        let buffers = self.projections.borrow();
        let projections = &buffers[1];
        let product = |v: &[f64]| -> Vec<f64> {
            let points: Vec<Point> = v.as_chunks::<3>().0.to_vec();
            let hv = objective.gauss_newton_product(projections, &self.global.scatter(&points));
            self.global.gather(&hv).as_flattened().to_vec()
        };
        truncated_cg(product, precondition, g, forcing, GAUSS_NEWTON_CG)
    }

    /// `D_T` from the held-keys curvature of W at `tr` (made positive where it is not).
    fn update_curvature(&mut self, tr: &Trajectory, eval: &Evaluation) {
        let d = self.timing.derivatives(tr, ProjectionMode::Fresh);
        let gradient = eval.time_gradient.as_ref().expect("time gradient");
        let lengths: Vec<f64> = tr.times.windows(2).map(|w| w[1] - w[0]).collect();
        let h = safe_curvature(gradient, &d.curvature, &lengths);
        self.curvature = self.intervals.iter().map(|&i| 1.0 / h[i]).collect();
    }

    /// Take the step `d` (flat unknowns, then interval variables when `times`) from the
    /// current iterate, halving until W decreases and every check stays outside; the accepted
    /// step, if any. The first trial is `limit`, or less where an interval would change by more
    /// than half or pass its minimum, or a check would enter an obstacle: the interval or check
    /// that stops it joins the active set if the step is taken whole.
    fn line_search(&self, it: &mut Iterate, d: &[f64], exact: bool, limit: f64) -> Result<Outcome> {
        let nu = self.unknown_count();
        let (du, dt_vars) = split(d, nu);
        let du_points: Vec<Point> = du.as_chunks::<3>().0.to_vec();
        let du_slots = self.global.scatter(&du_points);
        let mut dt = vec![0.0; it.tr.times.len() - 1];
        for (j, &i) in self.intervals.iter().enumerate().take(dt_vars.len()) {
            dt[i] = dt_vars[j];
        }
        let moves_times = dt.iter().any(|&x| x != 0.0);
        // Caps: interval changes and minimum lengths.
        let mut scale = limit;
        let mut stop: Option<Stop> = None;
        for (j, &i) in self.intervals.iter().enumerate().take(dt_vars.len()) {
            let (len, step) = (it.tr.times[i + 1] - it.tr.times[i], dt_vars[j]);
            if step == 0.0 {
                continue;
            }
            scale = scale.min(MAX_INTERVAL_CHANGE * len / step.abs());
            if step < 0.0 {
                let to_bound = (len - self.lower[j]).max(0.0) / -step;
                if to_bound < scale {
                    scale = to_bound;
                    stop = Some(Stop::Bound(j));
                }
            }
        }
        // Contacts: the first check the step would push in.
        let contacts = self.settings.contacts.as_ref();
        if let Some(contacts) = contacts {
            let snap = contacts.snapshot(&it.tr, &self.timing.slots);
            let mut direction = Trajectory {
                times: it.tr.times.clone(),
                positions: vec![vec![[0.0; 3]; it.tr.vertex_count()]; it.tr.key_count()],
                velocities: vec![vec![[0.0; 3]; it.tr.vertex_count()]; it.tr.key_count()],
            };
            apply_step(&mut direction, &self.timing.slots, &du_slots, 1.0);
            let motion = contacts.motion(&snap, &it.tr, &direction, &dt);
            let active = |c: Check| it.active.contains(&c);
            if let Some((alpha, check)) = contacts.blocking(&snap, &motion, &active, scale) {
                scale = alpha;
                stop = Some(Stop::Contact(check));
            }
        }
        if scale <= 0.0 {
            // Blocked at once: hold what blocks, and let the next direction go around it.
            return Ok(if self.hold(it, stop) { Outcome::Held(stop) } else { Outcome::Failed });
        }
        let w = *it.energy.last().expect("initial value");
        let first = scale;
        for halving in 0..=MAX_HALVINGS {
            let mut trial = it.tr.clone();
            apply_step(&mut trial, &self.timing.slots, &du_slots, scale);
            if moves_times {
                let blocks = self.blocks.as_ref().expect("times are optimized");
                trial.times = blocks.times(&it.tr.times, &dt, scale);
            }
            if let Some(contacts) = contacts {
                let clearance = contacts.clearance(&contacts.snapshot(&trial, &self.timing.slots));
                if clearance < -self.clearance_tolerance {
                    scale *= 0.5;
                    continue;
                }
            }
            let trial_eval = self.evaluate(&trial, it.energy.len(), exact)?;
            // Strictly lower: a step that changes nothing is no progress (W is stationary).
            if trial_eval.value < w {
                it.halvings += halving;
                it.tr = trial;
                it.eval = trial_eval;
                (self.on_iteration)(it.energy.len(), it.eval.value, self.settings.negligible * it.eval.force_scale);
                it.energy.push(it.eval.value);
                if self.blocks.is_some() {
                    it.times.push(it.tr.times.clone());
                }
                let whole = scale == first;
                let blocked = if whole { stop } else { None };
                let added = whole && self.hold(it, blocked);
                let check = match blocked {
                    Some(Stop::Contact(c)) => Some(c),
                    _ => None,
                };
                return Ok(Outcome::Taken(Accepted { scale, blocked: check, added, moved_times: moves_times }));
            }
            scale *= 0.5;
        }
        it.halvings += MAX_HALVINGS;
        Ok(Outcome::Failed)
    }

    /// Add what stopped a step to the active set; whether anything was added.
    fn hold(&self, it: &mut Iterate, stop: Option<Stop>) -> bool {
        match stop {
            Some(Stop::Bound(j)) => !std::mem::replace(&mut it.at_minimum[j], true),
            Some(Stop::Contact(c)) => it.active.insert(c),
            None => false,
        }
    }
}

/// The check in a stop, if it is one.
fn held_check(stop: Option<Stop>) -> Option<Check> {
    match stop {
        Some(Stop::Contact(c)) => Some(c),
        _ => None,
    }
}

/// What stopped a step short of its full length.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Stop {
    Bound(usize),
    Contact(Check),
}

/// What a line search did.
enum Outcome {
    /// A step was taken.
    Taken(Accepted),
    /// No step: what blocks the direction at once joined the active set.
    Held(Option<Stop>),
    /// No step decreases W.
    Failed,
}

/// An accepted step.
struct Accepted {
    /// The fraction of the direction taken.
    scale: f64,
    /// The check that stopped it, now held.
    blocked: Option<Check>,
    /// Whether a row joined the active set.
    added: bool,
    /// Whether the step moved the key times.
    moved_times: bool,
}
