//! The spacetime projective-dynamics iteration: local step, residuals, global step, repeat.
//!
//! Starts from the keyframes joined with zero velocities (the hermite baseline). Each
//! iteration evaluates W at the current trajectory with fresh projections, stops if W has
//! settled (change below `tolerance × W₀`), and otherwise takes one step (see [`solve`]). W is
//! recorded per iteration. It cannot grow: a step that would raise it is halved, and the solve
//! stops where no step lowers it. A NaN is an error naming the iteration, never a result.

use std::time::Instant;

use super::global_step::{GlobalStats, GlobalStep};
use super::objective::{Evaluation, Objective};
use super::quasi_newton::Lbfgs;
use super::sampling::{samples, TimeSlots};
use super::trajectory::Trajectory;
use super::unknowns::Unknowns;
use crate::error::{Error, Result};
use crate::mesh::Point;
use crate::physics::elastic::Elastic;
use crate::scene::Method;
use crate::stage::{KeyPoses, SolverLog};

/// Solver settings (from the scene's `[solver]` and `[material]`).
#[derive(Debug, Clone, PartialEq)]
pub struct Settings {
    pub samples: usize,
    pub max_iterations: usize,
    pub tolerance: f64,
    /// Proximal time scale h (0 = off).
    pub regularization: f64,
    pub damping: f64,
    pub gravity: Point,
}

impl Settings {
    pub fn from_scene(scene: &crate::scene::Scene) -> Settings {
        Settings {
            samples: scene.solver.samples,
            max_iterations: scene.solver.max_iterations,
            tolerance: scene.solver.tolerance,
            regularization: scene.solver.regularization,
            damping: scene.material.damping,
            gravity: scene.material.gravity,
        }
    }
}

/// A finished solve.
#[derive(Debug, Clone)]
pub struct Solved {
    pub trajectory: Trajectory,
    pub log: SolverLog,
    pub stats: GlobalStats,
}

/// The initial guess: the input keyframes with zero velocities. In a loop the last key is the
/// first.
pub fn initial_trajectory(keys: &KeyPoses) -> Trajectory {
    let mut positions = keys.positions.clone();
    if keys.cyclic {
        let first = positions[0].clone();
        *positions.last_mut().expect("keys") = first;
    }
    Trajectory::with_zero_velocities(keys.times.clone(), positions)
}

/// The objective of `keys` on `elastic` with these settings.
pub fn objective<'a>(elastic: &'a Elastic, keys: &KeyPoses, settings: &Settings) -> Objective<'a> {
    let slots = TimeSlots { keys: keys.times.len(), cyclic: keys.cyclic };
    Objective {
        elastic,
        samples: samples(&keys.times, settings.samples, &slots),
        slots,
        damping: settings.damping,
        gravity: settings.gravity,
    }
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
/// 1. The paper's local/global step: the minimizer of the quadratic model of W with frozen
///    projections (plus the proximal term). It is fast far from the solution but it is not a
///    descent direction of W everywhere (its stiffness is `L`, not `∇²E`), and near its fixed
///    point it turns W back up.
/// 2. Once that step settles or stops decreasing W: L-BFGS on the exact W (whose gradient
///    differentiates the projections), with the same matrix as initial inverse Hessian.
///
/// In both, a step that would increase W is halved until W decreases (the trial's local step
/// is the next iteration's, so an accepted step costs nothing extra). W never increases, and
/// the regularization never moves a fixed point. The solve stops when phase 2 settles or
/// stalls, or after `max_iterations` in all.
pub fn solve(elastic: &Elastic, keys: &KeyPoses, settings: &Settings, on_iteration: &dyn Fn(usize, f64)) -> Result<Solved> {
    let start = Instant::now();
    let objective = objective(elastic, keys, settings);
    let unknowns = Unknowns::new(keys, elastic.node_count());
    let global = GlobalStep::new(&objective, unknowns, settings.regularization)?;
    let precompute_seconds = start.elapsed().as_secs_f64();

    let evaluate = |tr: &Trajectory, iteration: usize, exact: bool| -> Result<Evaluation> {
        let eval = objective.evaluate(tr, &objective.local_step(tr, exact));
        if !eval.value.is_finite() {
            return Err(Error::general(
                format!("the spacetime energy W became {} at iteration {iteration}", eval.value),
                "check the keyframes for flat or inverted tets, and lower [solver] regularization (h) to damp the steps",
            ));
        }
        Ok(eval)
    };
    let t_iterations = Instant::now();
    let tr = initial_trajectory(keys);
    let eval = evaluate(&tr, 0, false)?;
    on_iteration(0, eval.value);
    let w0 = eval.value;
    let mut it = Iterate { tr, eval, energy: vec![w0], halvings: 0 };

    let settled = |energy: &[f64], since: usize| -> Option<f64> {
        let k = energy.len();
        (k >= since + 2).then(|| (energy[k - 2] - energy[k - 1]).abs() / w0).filter(|c| *c < settings.tolerance)
    };
    // Take `delta` (per slot) from the current iterate, halving until W decreases; the scale
    // of the accepted step, if any.
    let line_search = |it: &mut Iterate, delta: &[Vec<Point>], exact: bool| -> Result<Option<f64>> {
        let w = *it.energy.last().expect("initial value");
        let mut scale = 1.0;
        for halving in 0..=MAX_HALVINGS {
            let mut trial = it.tr.clone();
            apply_step(&mut trial, &objective.slots, delta, scale);
            let trial_eval = evaluate(&trial, it.energy.len(), exact)?;
            if trial_eval.value <= w {
                it.halvings += halving;
                it.tr = trial;
                it.eval = trial_eval;
                on_iteration(it.energy.len(), it.eval.value);
                it.energy.push(it.eval.value);
                return Ok(Some(scale));
            }
            scale *= 0.5;
        }
        it.halvings += MAX_HALVINGS;
        Ok(None)
    };
    let budget_left = |it: &Iterate| it.energy.len() <= settings.max_iterations;

    let (converged, stop_reason) = if global.unknowns().count() == 0 {
        (true, "nothing to optimize: every keyframe position and velocity is fixed".to_string())
    } else if w0 == 0.0 {
        (true, "W is zero: the keyframes are already physically exact".to_string())
    } else {
        // Phase 1: the local/global step.
        let phase1 = loop {
            if let Some(change) = settled(&it.energy, 0) {
                break PhaseEnd::Settled(change);
            }
            if !budget_left(&it) {
                break PhaseEnd::OutOfIterations;
            }
            let delta = global.step(&it.eval.gradient);
            if line_search(&mut it, &delta, false)?.is_none() {
                break PhaseEnd::Stalled;
            }
        };
        let local_global_iterations = it.energy.len() - 1;
        // Phase 2: L-BFGS on the exact W.
        let phase2 = if phase1 == PhaseEnd::OutOfIterations {
            PhaseEnd::OutOfIterations
        } else {
            it.eval = evaluate(&it.tr, it.energy.len(), true)?;
            let since = it.energy.len() - 1;
            let mut lbfgs = Lbfgs::new(LBFGS_MEMORY);
            let exact_gradient = |it: &Iterate| global.gather(it.eval.exact_gradient.as_ref().expect("exact phase"));
            let mut g = exact_gradient(&it);
            loop {
                if let Some(change) = settled(&it.energy, since) {
                    break PhaseEnd::Settled(change);
                }
                if !budget_left(&it) {
                    break PhaseEnd::OutOfIterations;
                }
                let mut d = lbfgs.direction(&g, |x| global.apply_inverse(x));
                let mut accepted = line_search(&mut it, &global.scatter(&d), true)?;
                if accepted.is_none() && !lbfgs.is_empty() {
                    // Restart from the preconditioned gradient.
                    lbfgs.clear();
                    d = lbfgs.direction(&g, |x| global.apply_inverse(x));
                    accepted = line_search(&mut it, &global.scatter(&d), true)?;
                }
                let Some(scale) = accepted else { break PhaseEnd::Stalled };
                // The step taken is `scale d`; the gradient change is measured.
                let g_new = exact_gradient(&it);
                let step = d.iter().map(|v| crate::mesh::scale(*v, scale)).collect();
                lbfgs.push(step, difference(&g_new, &g));
                g = g_new;
            }
        };
        let phases = format!("{local_global_iterations} local/global + {} quasi-Newton iterations", it.energy.len() - 1 - local_global_iterations);
        match phase2 {
            PhaseEnd::Settled(change) => {
                (true, format!("W changed by {change:.3e} of its initial value, below the tolerance {} ({phases})", settings.tolerance))
            }
            PhaseEnd::Stalled => (true, format!("W is stationary: no step along its quasi-Newton direction decreases it ({phases})")),
            PhaseEnd::OutOfIterations => {
                (false, format!("stopped after max_iterations = {} before W settled ({phases})", settings.max_iterations))
            }
        }
    };
    let iterations = it.energy.len() - 1;
    let iteration_time = t_iterations.elapsed().as_secs_f64();
    let log = SolverLog {
        method: Method::Spacetime,
        iterations,
        energy: it.energy,
        seconds: start.elapsed().as_secs_f64(),
        precompute_seconds,
        iteration_seconds: iteration_time / (iterations + 1) as f64,
        unknowns: global.stats.unknowns,
        halvings: it.halvings,
        converged,
        stop_reason,
    };
    Ok(Solved { trajectory: it.tr, log, stats: global.stats })
}

fn difference(a: &[Point], b: &[Point]) -> Vec<Point> {
    a.iter().zip(b).map(|(x, y)| crate::mesh::sub(*x, *y)).collect()
}
