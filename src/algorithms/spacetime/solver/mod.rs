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
//! When W decreased by less than `tolerance × (W + negligible × S)` over the last [`WINDOW`](super::settings::WINDOW)
//! quasi-Newton iterations. S is the force scale ([`Evaluation::force_scale`](super::objective::Evaluation::force_scale)): the residual
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
//! With [`Settings::coarse_samples`](super::settings::Settings::coarse_samples) the whole solve first runs with that many samples per
//! interval (to [`Settings::coarse_tolerance`](super::settings::Settings::coarse_tolerance)); the unknowns (key positions and velocities)
//! do not depend on the samples, so its result is a warm start for the solve at
//! [`Settings::samples`](super::settings::Settings::samples), which goes straight to quasi-Newton (fresh curvature pairs) on the
//! coarse phase's factorized matrix (a preconditioner: any positive definite model serves, and
//! one factorization is saved). The warm start is taken only where W at the configured samples
//! is below the first guess's, so that W never increases; [`Log::energy`] is W at the
//! configured samples only. Off by default (measured in `formats/scene.md`: the coarse phase
//! takes about as many iterations as a single-phase solve, so it saves 20-40% of the cost on
//! the paper scenes and nothing on a 20-key body). Not with obstacles or moving key times.
//!
//! # Gauss-Newton steps
//!
//! With [`Settings::step`](super::settings::Settings::step) = [`Step::GaussNewton`](super::settings::Step::GaussNewton), each quasi-Newton-phase iteration first
//! tries the truncated Gauss-Newton step of [`super::gauss_newton`]: `H d = -g` with `H` the
//! Gauss-Newton Hessian of W (the projections' Jacobians included), solved by CG to the
//! Eisenstat-Walker forcing tolerance, at most [`GAUSS_NEWTON_CG`](super::settings::GAUSS_NEWTON_CG) products. The same line
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
//! 0.04%, DINO 0.20% against 0.72%). So [`Step::Auto`](super::settings::Step::Auto) (the default) keeps L-BFGS.
//!
//! # Key times
//!
//! With [`Settings::timing`](super::settings::Settings::timing), the quasi-Newton phase runs on the keyframe unknowns and the
//! interval lengths together: the exact `∂W/∂T_i` comes with the exact gradient (same
//! projection Jacobians), the initial inverse Hessian is the global step's factorization for
//! the keys and the held-keys curvature `∂²W/∂T_i²` ([`super::timing`]) for the times, and the
//! curvature pairs learn how the keys absorb a change of timing (the reduced curvature is far
//! below the held-keys one: 199 vs 3219 on a free fall). So every quasi-Newton iteration is also
//! a timing step, and the times and keys settle together. The factorization depends on the
//! times; it is refactorized (on its kept symbolic analysis) only when an interval has moved by
//! more than [`REFACTOR_CHANGE`](super::settings::REFACTOR_CHANGE) since the last factorization, and is a valid preconditioner
//! in between (the line search keeps W from increasing whatever it is).
//!
//! # Obstacles
//!
//! With [`Settings::contacts`](super::settings::Settings::contacts), every node stays outside every obstacle at every key and every
//! frame ([`super::contact`]). The checks a step would cross join an active set held by hard
//! constraints ([`super::active_set`]); a check leaves it when its multiplier says the
//! obstacle would have to pull.

mod log;
mod phases;
mod predict;

use std::time::Instant;

use super::objective::Objective;
use super::sampling::{sample_counts, samples, TimeSlots};
use super::settings::Settings;
use super::trajectory::Trajectory;
use super::unknowns::KeyConstraints;
use crate::algorithms::geometry::Point;
use crate::algorithms::physics::elastic::Elastic;
use crate::support::error::Result;
use phases::{solve_from, Warm};

pub use log::{IterationSplit, Log};
pub use predict::{predicted_iterations, IterationEstimate};

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
