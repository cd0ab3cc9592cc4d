//! The spacetime projective-dynamics iteration: local step, residuals, global step, repeat.
//!
//! Starts from the keyframes joined with zero velocities (the hermite baseline). Each
//! iteration evaluates W at the current trajectory with fresh projections, stops if W has
//! settled (change below `tolerance × W₀`), and otherwise takes one step (see [`solve`]). W is
//! recorded per iteration. It cannot grow: a step that would raise it is halved, and the solve
//! stops where no step lowers it. A NaN is an error naming the iteration, never a result.

use std::time::Instant;

use super::global_step::GlobalStep;
use super::objective::{Evaluation, Objective};
use super::quasi_newton::Lbfgs;
use super::sampling::{samples, TimeSlots};
use super::trajectory::Trajectory;
use super::unknowns::{KeyConstraints, Unknowns};
use crate::error::{Error, Result};
use crate::mesh::Point;
use crate::physics::elastic::Elastic;

/// Solver settings.
#[derive(Debug, Clone, PartialEq)]
pub struct Settings {
    /// Residual samples per interval.
    pub samples: usize,
    /// Iterations (of both phases together) before the solve gives up.
    pub max_iterations: usize,
    /// Stop when W changes by less than `tolerance × W₀` in one iteration.
    pub tolerance: f64,
    /// Proximal time scale h (0 = off).
    pub regularization: f64,
    /// Rayleigh mass damping α (D = α M), per second.
    pub damping: f64,
    /// Gravitational acceleration.
    pub gravity: Point,
}

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
}

/// A finished solve.
#[derive(Debug, Clone)]
pub struct Solved {
    /// The optimized trajectory of every node.
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

/// The objective of `keys` on `elastic` with these settings.
pub fn objective<'a>(elastic: &'a Elastic, keys: &KeyConstraints, settings: &Settings) -> Objective<'a> {
    let slots = TimeSlots { keys: keys.times.len(), cyclic: keys.cyclic };
    Objective {
        elastic,
        samples: samples(&keys.times, settings.samples, &slots),
        slots,
        damping: settings.damping,
        gravity: settings.gravity,
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
        for k in slots.keys_of(s) {
            let target = if s % 2 == 0 { &mut tr.positions[k] } else { &mut tr.velocities[k] };
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

/// Curvature pairs kept by the quasi-Newton phase.
const LBFGS_MEMORY: usize = 8;

/// How a phase of the iteration ended.
#[derive(Debug, Clone, PartialEq)]
enum PhaseEnd {
    /// W changed by less than `tolerance × W₀` in one iteration.
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
}

/// Optimize keyframe positions and velocities. `on_iteration(k, W)` reports progress.
///
/// Two phases share one factorized matrix:
///
/// 1. The paper's local/global step ([`Solver::local_global`]): the minimizer of the quadratic
///    model of W with frozen projections (plus the proximal term). It is fast far from the
///    solution but it is not a descent direction of W everywhere (its stiffness is `L`, not
///    `∇²E`), and near its fixed point it turns W back up.
/// 2. Once that step settles or stops decreasing W: L-BFGS on the exact W (whose gradient
///    differentiates the projections), with the same matrix as initial inverse Hessian
///    ([`Solver::quasi_newton`]).
///
/// In both, a step that would increase W is halved until W decreases (the trial's local step
/// is the next iteration's, so an accepted step costs nothing extra). W never increases, and
/// the regularization never moves a fixed point. The solve stops when phase 2 settles or
/// stalls, or after `max_iterations` in all.
pub fn solve(elastic: &Elastic, keys: &KeyConstraints, settings: &Settings, on_iteration: &dyn Fn(usize, f64)) -> Result<Solved> {
    let start = Instant::now();
    let objective = objective(elastic, keys, settings);
    let unknowns = Unknowns::new(keys, elastic.node_count());
    let global = GlobalStep::new(&objective, unknowns, settings.regularization)?;
    let precompute_seconds = start.elapsed().as_secs_f64();
    let solver = Solver { objective, global, settings, on_iteration };

    let t_iterations = Instant::now();
    let tr = initial_trajectory(keys);
    let eval = solver.evaluate(&tr, 0, false)?;
    on_iteration(0, eval.value);
    let mut it = Iterate { tr, energy: vec![eval.value], eval, halvings: 0 };
    let (converged, stop_reason) = solver.iterate(&mut it)?;
    let iterations = it.energy.len() - 1;
    let iteration_time = t_iterations.elapsed().as_secs_f64();
    let log = Log {
        iterations,
        energy: it.energy,
        seconds: start.elapsed().as_secs_f64(),
        precompute_seconds,
        iteration_seconds: iteration_time / (iterations + 1) as f64,
        unknowns: solver.global.stats.unknowns,
        halvings: it.halvings,
        converged,
        stop_reason,
    };
    Ok(Solved { trajectory: it.tr, log })
}

/// The objective and the factorized global step of one solve.
struct Solver<'a> {
    objective: Objective<'a>,
    global: GlobalStep,
    settings: &'a Settings,
    on_iteration: &'a dyn Fn(usize, f64),
}

impl Solver<'_> {
    /// W at `tr` with fresh projections (and the exact gradient when `exact`); a non-finite W
    /// is an error naming the iteration.
    fn evaluate(&self, tr: &Trajectory, iteration: usize, exact: bool) -> Result<Evaluation> {
        let eval = self.objective.evaluate(tr, &self.objective.local_step(tr, exact));
        if !eval.value.is_finite() {
            return Err(Error::general(
                format!("the spacetime energy W became {} at iteration {iteration}", eval.value),
                "check the keyframes for flat or inverted tets, and lower [solver] regularization (h) to damp the steps",
            ));
        }
        Ok(eval)
    }

    /// The relative change of W in the last iteration, if the phase that began at iteration
    /// `since` has taken one and it is below the tolerance.
    fn settled(&self, energy: &[f64], since: usize) -> Option<f64> {
        let k = energy.len();
        (k >= since + 2).then(|| (energy[k - 2] - energy[k - 1]).abs() / energy[0]).filter(|c| *c < self.settings.tolerance)
    }

    fn budget_left(&self, it: &Iterate) -> bool {
        it.energy.len() <= self.settings.max_iterations
    }

    /// Take `delta` (per slot) from the current iterate, halving until W decreases; the scale
    /// of the accepted step, if any.
    fn line_search(&self, it: &mut Iterate, delta: &[Vec<Point>], exact: bool) -> Result<Option<f64>> {
        let w = *it.energy.last().expect("initial value");
        let mut scale = 1.0;
        for halving in 0..=MAX_HALVINGS {
            let mut trial = it.tr.clone();
            apply_step(&mut trial, &self.objective.slots, delta, scale);
            let trial_eval = self.evaluate(&trial, it.energy.len(), exact)?;
            if trial_eval.value <= w {
                it.halvings += halving;
                it.tr = trial;
                it.eval = trial_eval;
                (self.on_iteration)(it.energy.len(), it.eval.value);
                it.energy.push(it.eval.value);
                return Ok(Some(scale));
            }
            scale *= 0.5;
        }
        it.halvings += MAX_HALVINGS;
        Ok(None)
    }

    /// Both phases, or none when there is nothing to optimize: whether the solve converged,
    /// and why it stopped.
    fn iterate(&self, it: &mut Iterate) -> Result<(bool, String)> {
        if self.global.unknowns().count() == 0 {
            return Ok((true, "nothing to optimize: every keyframe position and velocity is fixed".to_string()));
        }
        if it.energy[0] == 0.0 {
            return Ok((true, "W is zero: the keyframes are already physically exact".to_string()));
        }
        let phase1 = self.local_global(it)?;
        let local_global_iterations = it.energy.len() - 1;
        let phase2 = if phase1 == PhaseEnd::OutOfIterations { PhaseEnd::OutOfIterations } else { self.quasi_newton(it)? };
        let phases = format!("{local_global_iterations} local/global + {} quasi-Newton iterations", it.energy.len() - 1 - local_global_iterations);
        let tolerance = self.settings.tolerance;
        Ok(match phase2 {
            PhaseEnd::Settled(change) => {
                (true, format!("W changed by {change:.3e} of its initial value, below the tolerance {tolerance} ({phases})"))
            }
            PhaseEnd::Stalled => (true, format!("W is stationary: no step along its quasi-Newton direction decreases it ({phases})")),
            PhaseEnd::OutOfIterations => {
                (false, format!("stopped after max_iterations = {} before W settled ({phases})", self.settings.max_iterations))
            }
        })
    }

    /// Phase 1: the paper's local/global step, while it decreases W.
    fn local_global(&self, it: &mut Iterate) -> Result<PhaseEnd> {
        loop {
            if let Some(change) = self.settled(&it.energy, 0) {
                return Ok(PhaseEnd::Settled(change));
            }
            if !self.budget_left(it) {
                return Ok(PhaseEnd::OutOfIterations);
            }
            let delta = self.global.step(&it.eval.gradient);
            if self.line_search(it, &delta, false)?.is_none() {
                return Ok(PhaseEnd::Stalled);
            }
        }
    }

    /// Phase 2: L-BFGS on the exact W, preconditioned by the global step's matrix.
    fn quasi_newton(&self, it: &mut Iterate) -> Result<PhaseEnd> {
        let global = &self.global;
        it.eval = self.evaluate(&it.tr, it.energy.len(), true)?;
        let since = it.energy.len() - 1;
        let mut lbfgs = Lbfgs::new(LBFGS_MEMORY);
        let exact_gradient = |it: &Iterate| global.gather(it.eval.exact_gradient.as_ref().expect("exact phase"));
        let mut g = exact_gradient(it);
        loop {
            if let Some(change) = self.settled(&it.energy, since) {
                return Ok(PhaseEnd::Settled(change));
            }
            if !self.budget_left(it) {
                return Ok(PhaseEnd::OutOfIterations);
            }
            let mut d = lbfgs.direction(&g, |x| global.apply_inverse(x));
            let mut accepted = self.line_search(it, &global.scatter(&d), true)?;
            if accepted.is_none() && !lbfgs.is_empty() {
                // Restart from the preconditioned gradient.
                lbfgs.clear();
                d = lbfgs.direction(&g, |x| global.apply_inverse(x));
                accepted = self.line_search(it, &global.scatter(&d), true)?;
            }
            let Some(scale) = accepted else { return Ok(PhaseEnd::Stalled) };
            // The step taken is `scale d`; the gradient change is measured.
            let g_new = exact_gradient(it);
            let step = d.iter().map(|v| crate::mesh::scale(*v, scale)).collect();
            lbfgs.push(step, difference(&g_new, &g));
            g = g_new;
        }
    }
}

fn difference(a: &[Point], b: &[Point]) -> Vec<Point> {
    a.iter().zip(b).map(|(x, y)| crate::mesh::sub(*x, *y)).collect()
}
